//! The scene's Sun lamps turned with the map in a relight (`logsh relight --sun-lamps
//! turn`, the default), as `logsh render --light-rotation` turns them.
//!
//! A Sun lamp is shaded sharp at render time, its shadows included, into the `lamps_*`
//! layers with the point lamps: no transfer vector holds it. Its part of them is written
//! apart too (`sun_lamps_*`), and a relight that turns the map shades the frame's Sun
//! lamps again, turned, from the scene the frame was rendered from (its G-buffer,
//! blockers and height field, the settings the header records) with the render's own
//! kernel. The layers then hold
//!
//! ```text
//! lamps = lamps - sun_lamps + Sun lamps turned
//! ```
//!
//! which is the render's `lamps_*` under the turned light but for the half floats of the
//! file (the Sun lamps as rendered cancel to their rounding, 2^-11 of their light). Water
//! that mirrors a Sun lamp is read along its mirror direction, as the render reads it.
//!
//! The suns a render takes out of a map (`--sharp-lights auto`) are shaded the same way,
//! from the relight's own light ([`super::RelightLight::sharp_suns`]), and added to
//! `lamps_*`, as the render adds them to its passes; no layer holds them as rendered, and
//! water reads them in the map it mirrors.

use super::layers::{TransferFrame, TransferHeader};
use crate::heightfield::{HorizonAgainst, HorizonPyramid, HorizonsUnder};
use crate::scene::{Frame, HeightMap, Material, Scene, SceneError, SunLight};
use crate::sh::Real;
use crate::shade::blocker_tree::BlockerTree;
use crate::shade::frame::suns_along;
use crate::shade::sun::{Planes, SunDisk};
use crate::shade::sun_shadow::SunShadows;
use crate::shade::{
    pixel_source, FramePlan, KnownAlongSun, Occluders, PixelSource, PlannedKernel, ShadingKernel, ShadingSettings,
    Terrain,
};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::{Arc, Mutex};

/// How far a scene's Sun lamp may be from the header's record of it, in degrees of
/// azimuth or elevation, and still be the lamp the frame was rendered with.
const SAME_LAMP_DEGREES: f64 = 1e-6;

/// The scene a frame was rendered from, with its light turned as it was for the render:
/// what shades the frame's Sun lamps again, turned further by a relight.
pub struct SunLampTurn {
    scene: Scene,
    settings: ShadingSettings,
    /// The last frame's height map and its filtered pyramid, which the frames after it
    /// share where the scene's height map is one for all frames.
    pyramid: Mutex<Option<(Arc<HeightMap>, Arc<HorizonPyramid>)>>,
}

/// A frame's Sun lamps made ready to turn ([`SunLampTurn::prepare`]): its frame of the
/// scene read and checked against what the frame records, its kernel and blockers'
/// hierarchy planned, and its height field's pyramid filtered, which every turn of the
/// frame shares (the viewer's turns of one frame).
pub struct SunLampFrame {
    /// The frame of the scene, its point lamps taken out.
    scene_frame: Frame,
    kernel: Arc<PlannedKernel>,
    blockers: BlockerTree,
    sun_shadows: SunShadows,
    pyramid: Option<Arc<HorizonPyramid>>,
}

impl SunLampTurn {
    /// Loads the scene that `header` (of `file`) was rendered from. Fails, naming `file`,
    /// where the header does not record the render's settings or the scene cannot be read
    /// (`logsh relight` then offers to keep the lamps: [`offering_to_keep`]).
    pub fn new(header: &TransferHeader, file: &Path) -> Result<Self, SceneError> {
        let Some(settings) = header.settings else {
            return Err(SceneError::invalid(
                file,
                "its header does not record the render's settings, which shading its sharp lights again needs: render it again with this logsh",
            ));
        };
        let mut scene = Scene::load(&header.scene).map_err(|e| {
            SceneError::invalid(
                file,
                format!("its sharp lights (its Sun lamps turned with the map, the suns taken out of its map) are shaded again from the scene it was rendered from, which cannot be read: {e}"),
            )
        })?;
        scene.turn_light(header.light_turn)?;
        // The lamps' light reads their disks, the blockers, the horizon march and the
        // glossy lobes' shape, none of the environment's tables: the two of those that are
        // searched for (the depths fitted to each cap and band, each Phong lobe's eps) are
        // not, for the same bits (`cmp` of relit frames). They were most of a turning
        // relight's first frame: the Sun-lamp scene at `--quality ultra`, one frame, 2
        // cores, 0.61 s to 0.12 to 0.14 s for its Sun lamps.
        let settings = ShadingSettings {
            sharp_lights: false,
            fitted_depths: false,
            phong_epsilon: Some(settings.epsilon),
            ..settings
        };
        Ok(Self { scene, settings, pyramid: Mutex::new(None) })
    }

    /// Shades the Sun lamps of `frame` (read from `file`) again, turned `degrees` about Z
    /// on top of the render's turn, and moves its `lamps_*` layers from the lamps as
    /// rendered (`sun_lamps_*`) to them.
    pub fn apply(&self, frame: &mut TransferFrame, file: &Path, degrees: f64) -> Result<(), SceneError> {
        self.shade_again(frame, file, Some(degrees), &[])
    }

    /// Shades again what of `frame`'s light (read from `file`) is sharp, from the scene:
    /// its Sun lamps turned `degrees` beyond the render where given (else they stay as
    /// rendered), and `suns`, the suns a render would take out of a relight's map
    /// ([`super::RelightLight::sharp_suns`]; no layer holds them as rendered), which are
    /// added to its `lamps_*` layers as the render adds them to its passes.
    pub fn shade_again(
        &self,
        frame: &mut TransferFrame,
        file: &Path,
        degrees: Option<f64>,
        suns: &[SunLight],
    ) -> Result<(), SceneError> {
        let prepared = self.prepare(frame, file)?;
        [frame.lamps_diffuse, frame.lamps_specular] =
            self.sharp_lights_at(&prepared, frame, file, degrees, suns, None)?;
        Ok(())
    }

    /// The `lamps_*` layers (diffuse, specular) of `frame` with its Sun lamps turned
    /// `degrees` ([`Self::apply`]), the frame left as it is (`logsh view` turns them from
    /// the rendered ones at each turn of its page).
    pub fn turned_lamps(
        &self,
        frame: &TransferFrame,
        file: &Path,
        degrees: f64,
    ) -> Result<[Vec<[f32; 3]>; 2], SceneError> {
        self.turned_prepared(&self.prepare(frame, file)?, frame, file, degrees)
    }

    /// The frame of the scene that `frame` (read from `file`) was rendered from, read and
    /// checked to be the one it was rendered from (its size, its Sun lamps, and the
    /// lamps, materials, G-buffer, blockers and terrain the header records), with its
    /// height field's pyramid: what [`Self::turned_prepared`] turns.
    pub fn prepare(&self, frame: &TransferFrame, file: &Path) -> Result<SunLampFrame, SceneError> {
        let number = frame.header.frame;
        let mut scene_frame = self.scene.frame(number).map_err(|e| {
            SceneError::invalid(
                file,
                format!(
                    "its sharp lights are shaded again from frame {number} of its scene, which cannot be read: {e}"
                ),
            )
        })?;
        let g = &scene_frame.gbuffer;
        if (g.width, g.height) != (frame.width, frame.height) {
            return Err(SceneError::invalid(
                file,
                format!(
                    "it is {}x{} but frame {} of its scene {} is {}x{} now: the scene changed since the render",
                    frame.width,
                    frame.height,
                    frame.header.frame,
                    self.scene.dir.display(),
                    g.width,
                    g.height
                ),
            ));
        }
        let rendered: Vec<[f64; 2]> = scene_frame.suns.iter().map(SunLight::azimuth_elevation).collect();
        let same = rendered.len() == frame.header.sun_lamps.len()
            && rendered
                .iter()
                .zip(&frame.header.sun_lamps)
                .all(|(a, b)| (a[0] - b[0]).abs() <= SAME_LAMP_DEGREES && (a[1] - b[1]).abs() <= SAME_LAMP_DEGREES);
        if !same {
            return Err(SceneError::invalid(
                file,
                format!(
                    "its scene {} has other Sun lamps ({}) than it was rendered with ({})",
                    self.scene.dir.display(),
                    describe_sun_lamps(&rendered),
                    describe_sun_lamps(&frame.header.sun_lamps)
                ),
            ));
        }
        if let Some(recorded) = frame.header.sun_lamp_inputs {
            let changed = SunLampInputs::of(&self.scene, &scene_frame).differing(&recorded);
            if !changed.is_empty() {
                return Err(SceneError::invalid(
                    file,
                    format!(
                        "its scene {} has changed since frame {} was rendered from it ({}), and its sharp lights would be shaded again from that",
                        self.scene.dir.display(),
                        frame.header.frame,
                        changed.join(", ")
                    ),
                ));
            }
        }
        scene_frame.points.clear();
        let plan = self.plan(&scene_frame, file)?;
        let pyramid = match (&scene_frame.height_map, &plan.terrain) {
            (Some(map), Some(terrain)) => Some(self.pyramid_of(map, terrain, &plan.settings)),
            _ => None,
        };
        let (kernel, blockers, sun_shadows) = (plan.kernel.clone(), plan.blockers, plan.sun_shadows);
        Ok(SunLampFrame { scene_frame, kernel, blockers, sun_shadows, pyramid })
    }

    /// The filtered pyramid of a frame's height map `map`, planned as `terrain`: the last
    /// frame's where the map is the same (the scene's one map for all frames), else
    /// filtered anew.
    fn pyramid_of(&self, map: &Arc<HeightMap>, terrain: &Terrain, settings: &ShadingSettings) -> Arc<HorizonPyramid> {
        let mut last = self.pyramid.lock().unwrap_or_else(|p| p.into_inner());
        if let Some((_, pyramid)) = last.as_ref().filter(|(built, _)| Arc::ptr_eq(built, map)) {
            return pyramid.clone();
        }
        let pyramid = Arc::new(terrain.horizon_pyramid(settings));
        *last = Some((map.clone(), pyramid.clone()));
        pyramid
    }

    /// The frame's kernel with the lamps as rendered and no point lamp, which the frames
    /// and turns after it share ([`FramePlan`]'s cache); the
    /// turned lamps are shaded through it.
    fn plan<'a>(&'a self, scene_frame: &'a Frame, file: &Path) -> Result<FramePlan<'a>, SceneError> {
        FramePlan::new(&self.scene, scene_frame, &self.settings)
            .map_err(|e| SceneError::invalid(file, format!("its sharp lights cannot be shaded again: {e}")))
    }

    /// [`Self::turned_lamps`] of `prepared`, made ready from `frame` (of `file`) by
    /// [`Self::prepare`].
    pub fn turned_prepared(
        &self,
        prepared: &SunLampFrame,
        frame: &TransferFrame,
        file: &Path,
        degrees: f64,
    ) -> Result<[Vec<[f32; 3]>; 2], SceneError> {
        self.turned_at(prepared, frame, file, degrees, None)
    }

    /// [`Self::turned_prepared`] at `pixels` alone (indices into the frame's rows), in
    /// their order, or at every pixel for `None`: the viewer's preview of a frame wider
    /// than it shows one pixel in `stride^2` of it ([`crate::view`]), and shades only those.
    pub fn turned_at(
        &self,
        prepared: &SunLampFrame,
        frame: &TransferFrame,
        file: &Path,
        degrees: f64,
        pixels: Option<&[usize]>,
    ) -> Result<[Vec<[f32; 3]>; 2], SceneError> {
        self.sharp_lights_at(prepared, frame, file, Some(degrees), &[], pixels)
    }

    /// The `lamps_*` layers of `frame` (read from `file`), made ready by
    /// [`Self::prepare`], at `pixels` (or whole), with its Sun lamps turned `degrees` where
    /// given and `suns` added ([`Self::shade_again`]).
    pub fn sharp_lights_at(
        &self,
        prepared: &SunLampFrame,
        frame: &TransferFrame,
        file: &Path,
        degrees: Option<f64>,
        suns: &[SunLight],
        pixels: Option<&[usize]>,
    ) -> Result<[Vec<[f32; 3]>; 2], SceneError> {
        self.shaded_onto(prepared, frame, file, degrees, suns, pixels, true)
    }

    /// The light of `suns` alone (diffuse, specular), as [`Self::sharp_lights_at`] adds
    /// it to `frame`'s `lamps_*` layers at `pixels` (or whole): `logsh view` scales it
    /// with the map's strength, which the frame's lamps do not follow.
    pub fn suns_at(
        &self,
        prepared: &SunLampFrame,
        frame: &TransferFrame,
        file: &Path,
        suns: &[SunLight],
        pixels: Option<&[usize]>,
    ) -> Result<[Vec<[f32; 3]>; 2], SceneError> {
        self.shaded_onto(prepared, frame, file, None, suns, pixels, false)
    }

    /// [`Self::sharp_lights_at`], onto `frame`'s `lamps_*` layers where `onto_lamps`, else
    /// onto black.
    #[allow(clippy::too_many_arguments)]
    fn shaded_onto(
        &self,
        prepared: &SunLampFrame,
        frame: &TransferFrame,
        file: &Path,
        degrees: Option<f64>,
        suns: &[SunLight],
        pixels: Option<&[usize]>,
        onto_lamps: bool,
    ) -> Result<[Vec<[f32; 3]>; 2], SceneError> {
        let scene_frame = &prepared.scene_frame;
        // Whole turns taken out first, exactly, as for the map ([`super::RelightOptions::source`]).
        let turned: Vec<SunLight> = match degrees {
            Some(degrees) => scene_frame.suns.iter().map(|sun| sun.turned(degrees)).collect(),
            None => Vec::new(),
        };
        let rendered = match (degrees, &frame.sun_lamps_diffuse, &frame.sun_lamps_specular) {
            (None, _, _) => None,
            (Some(_), Some(diffuse), Some(specular)) => Some([diffuse, specular]),
            (Some(_), _, _) => {
                return Err(SceneError::invalid(file, "holds no sun_lamps_diffuse and sun_lamps_specular to turn"))
            }
        };
        let layers = [&frame.lamps_diffuse, &frame.lamps_specular].into_iter().chain(rendered.into_iter().flatten());
        let shortest = layers.map(Vec::len).min().unwrap_or(0);
        if let Some(&outside) = pixels.into_iter().flatten().find(|&&i| i >= shortest) {
            return Err(SceneError::invalid(file, format!("has no pixel {outside} to shade its sharp lights at")));
        }
        // The layers at `pixels`, or whole; the rendered ones are only read.
        fn taken<'a>(layer: &'a [[f32; 3]], pixels: Option<&[usize]>) -> Cow<'a, [[f32; 3]]> {
            match pixels {
                Some(pixels) => Cow::Owned(pixels.iter().map(|&i| layer[i]).collect()),
                None => Cow::Borrowed(layer),
            }
        }
        let onto = |layer: &[[f32; 3]]| match onto_lamps {
            true => taken(layer, pixels).into_owned(),
            false => vec![[0.0; 3]; pixels.map_or(layer.len(), <[usize]>::len)],
        };
        let (mut diffuse, mut specular) = (onto(&frame.lamps_diffuse), onto(&frame.lamps_specular));
        let rendered = rendered.map(|layers| layers.map(|layer| taken(layer, pixels)));
        let lamps = Lamps {
            width: frame.width,
            pixels,
            diffuse: &mut diffuse,
            specular: &mut specular,
            rendered: rendered.as_ref().map(|[diffuse, specular]| [&diffuse[..], &specular[..]]),
            horizons: frame.horizons.as_deref().map(|layer| (layer, frame.horizon_sectors())),
        };
        let shaded = Shaded {
            materials: &self.scene.materials,
            frame: scene_frame,
            blockers: &prepared.blockers,
            sun_shadows: &prepared.sun_shadows,
            pyramid: prepared.pyramid.as_deref(),
        };
        match prepared.kernel.as_ref() {
            PlannedKernel::F32(kernel) => move_lamps(kernel, shaded, &turned, suns, lamps),
            PlannedKernel::F64(kernel) => move_lamps(kernel, shaded, &turned, suns, lamps),
        }
        Ok([diffuse, specular])
    }
}

/// What a frame's Sun lamps, and the suns taken out of its map, are shaded from, each
/// part as a CRC-32 of its values: the transfer header records them at render time, and
/// a relight shades them again only from a scene whose parts are the same (an edited
/// lamp, material or G-buffer would light the frame otherwise than its other layers do).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SunLampInputs {
    /// The Sun lamps as rendered: direction, angle, strength and colour.
    pub lamps: u32,
    /// The scene's material table.
    pub materials: u32,
    /// The frame's camera and G-buffer, and the water's reflection G-buffer.
    pub gbuffer: u32,
    /// The frame's blocker spheres.
    pub blockers: u32,
    /// The height map, its extent, and the ground plane.
    pub terrain: u32,
}

/// The CRC-32 of a frame's camera and G-buffers that [`SunLampInputs::gbuffer`] records:
/// each part (the camera; each G-buffer's positions, normals, materials and objects) its
/// length in bytes and its bytes, added band after band of rows.
#[derive(Clone)]
pub struct GBufferDigest {
    camera: Option<Vec<u8>>,
    /// Per part, its length so far and the CRC of its bytes so far.
    parts: Vec<(usize, crc32fast::Hasher)>,
}

impl GBufferDigest {
    /// The digest of `frame`'s camera, before any of its rows.
    pub fn new(frame: &Frame) -> Self {
        let camera = frame.camera.as_ref().map(|camera| {
            let mut values = camera.position.to_vec();
            values.extend(camera.matrix_world.as_flattened());
            values.extend([camera.lens_mm, camera.sensor_width_mm]);
            values.iter().flat_map(|v| v.to_le_bytes()).collect()
        });
        Self { camera, parts: Vec::new() }
    }

    /// Adds the G-buffer rows of `frame` (the whole frame, or its next band).
    pub fn add(&mut self, frame: &Frame) {
        let mut parts: Vec<&[u8]> = Vec::new();
        for g in [Some(&frame.gbuffer), frame.reflection.as_ref()].into_iter().flatten() {
            let object = g.object.as_deref().unwrap_or(&[]);
            parts.extend([
                bytemuck::cast_slice(&g.position),
                bytemuck::cast_slice(&g.normal),
                bytemuck::cast_slice(&g.material),
                bytemuck::cast_slice(object),
            ]);
        }
        if self.parts.is_empty() {
            self.parts = parts.iter().map(|_| (0, crc32fast::Hasher::new())).collect();
        }
        for ((length, hasher), part) in self.parts.iter_mut().zip(parts) {
            *length += part.len();
            hasher.update(part);
        }
    }

    pub fn finish(&self) -> u32 {
        let mut hasher = crc32fast::Hasher::new();
        if let Some(camera) = &self.camera {
            hasher.update(&camera.len().to_le_bytes());
            hasher.update(camera);
        }
        for (length, part) in &self.parts {
            hasher.update(&length.to_le_bytes());
            hasher.combine(part);
        }
        hasher.finalize()
    }
}

impl SunLampInputs {
    /// The parts of `frame` of `scene`, its Sun lamps as they are (after any turn).
    pub fn of(scene: &Scene, frame: &Frame) -> Self {
        let sum = |parts: &[&[u8]]| {
            let mut hasher = crc32fast::Hasher::new();
            for part in parts {
                hasher.update(&part.len().to_le_bytes());
                hasher.update(part);
            }
            hasher.finalize()
        };
        let f64s = |values: &[f64]| values.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>();
        let lamps: Vec<f64> = frame
            .suns
            .iter()
            .flat_map(|sun| {
                let [r, g, b] = sun.color.map(f64::from);
                [sun.direction[0], sun.direction[1], sun.direction[2], sun.half_angle, f64::from(sun.strength), r, g, b]
            })
            .collect();
        // Debug prints every float so that it reads back exactly.
        let materials = format!("{:?}", scene.materials);
        let mut digest = GBufferDigest::new(frame);
        digest.add(frame);
        let spheres: Vec<f64> = frame
            .blockers
            .iter()
            .flat_map(|s| [s.center[0], s.center[1], s.center[2], s.radius, f64::from(s.object)])
            .collect();
        let ground = f64s(&frame.ground.into_iter().collect::<Vec<_>>());
        let terrain = match &frame.height_map {
            Some(map) => {
                let extent = f64s(&[map.min[0], map.min[1], map.max[0], map.max[1], map.columns as f64]);
                sum(&[bytemuck::cast_slice(&map.heights), &extent, &ground])
            }
            None => sum(&[&ground]),
        };
        Self {
            lamps: sum(&[&f64s(&lamps)]),
            materials: sum(&[materials.as_bytes()]),
            gbuffer: digest.finish(),
            blockers: sum(&[&f64s(&spheres)]),
            terrain,
        }
    }

    /// These inputs with the G-buffer's sum taken over the whole frame, `digest`, where
    /// they were taken from a band of it ([`crate::render::bands`]).
    pub fn with_gbuffer(self, digest: &GBufferDigest) -> Self {
        Self { gbuffer: digest.finish(), ..self }
    }

    /// The parts in which `self` and `other` differ, named for a message.
    fn differing(&self, other: &Self) -> Vec<&'static str> {
        let parts = [
            (self.lamps != other.lamps, "its Sun lamps' light"),
            (self.materials != other.materials, "its materials"),
            (self.gbuffer != other.gbuffer, "the frame's G-buffer or camera"),
            (self.blockers != other.blockers, "the frame's blockers"),
            (self.terrain != other.terrain, "its height field or ground"),
        ];
        parts.into_iter().filter(|(differs, _)| *differs).map(|(_, name)| name).collect()
    }
}

/// `error`, of [`SunLampTurn::new`] or [`SunLampTurn::apply`], with what `logsh relight`
/// offers instead.
pub fn offering_to_keep(error: SceneError) -> SceneError {
    offering(error, "relight with --sun-lamps keep to leave the Sun lamps as rendered")
}

/// `error` of a relight that shades the suns taken out of its map, with the flag that
/// holds them in SH instead.
pub fn offering_soft_suns(error: SceneError) -> SceneError {
    offering(error, "relight with --sharp-lights off to hold the map's suns in SH (soft shadows)")
}

/// `error` with `instead` after its message, where it names a file.
fn offering(error: SceneError, instead: &str) -> SceneError {
    match error {
        SceneError::Invalid { file, message } => SceneError::Invalid { file, message: format!("{message}; {instead}") },
        other => other,
    }
}

/// Sun lamps by azimuth and elevation, for a message.
pub fn describe_sun_lamps(lamps: &[[f64; 2]]) -> String {
    if lamps.is_empty() {
        return "none".into();
    }
    let each =
        lamps.iter().map(|[azimuth, elevation]| format!("azimuth {azimuth:.1} deg, elevation {elevation:.1} deg"));
    each.collect::<Vec<_>>().join("; ")
}

/// A frame's `lamps_*` layers and its `sun_lamps_*` (`rendered`, diffuse and specular),
/// at every pixel, rows of `width`, or at `pixels` alone; its `horizon` layer where it
/// holds one (every pixel's), with its sectors of azimuths.
struct Lamps<'a> {
    width: usize,
    pixels: Option<&'a [usize]>,
    diffuse: &'a mut [[f32; 3]],
    specular: &'a mut [[f32; 3]],
    /// The Sun lamps' part of `diffuse` and `specular` as rendered, where they turn.
    rendered: Option<[&'a [[f32; 3]]; 2]>,
    horizons: Option<(&'a [f32], usize)>,
}

/// Pixels shaded together: their horizons along each turned lamp are marched eight at a
/// time ([`HorizonPyramid::horizons_against`]) before each is shaded.
const CHUNK: usize = 256;

/// What a frame's Sun lamps are shaded from beside its kernel: the scene's materials, the
/// frame of the scene, its blockers' hierarchy and its height field's pyramid.
#[derive(Clone, Copy)]
struct Shaded<'a> {
    materials: &'a BTreeMap<u32, Material>,
    frame: &'a Frame,
    blockers: &'a BlockerTree,
    sun_shadows: &'a SunShadows,
    pyramid: Option<&'a HorizonPyramid>,
}

/// `lamps += turned + suns - rendered` per pixel of `lamps`, the Sun lamps `turned` and
/// the map's `suns` shaded by `kernel` from `shaded`, a chunk of pixels at a time
/// ([`chunk_known`]). Water mirrors the Sun lamps alone (the map's suns are in the map
/// it reads).
fn move_lamps<T: Real>(
    kernel: &ShadingKernel<T>,
    shaded: Shaded,
    turned: &[SunLight],
    suns: &[SunLight],
    lamps: Lamps,
) {
    let disks: Vec<SunDisk> = turned.iter().chain(suns).map(SunDisk::new).collect();
    let occluders = Occluders::of(shaded.blockers, shaded.pyramid, shaded.sun_shadows);
    let (blockers, pyramid) = (occluders.blockers, occluders.horizons);
    // The tinted turned light in place of the rendered (tinted when written).
    let moved = |lamps: &mut [f32; 3], rendered: [f32; 3], tint: [f32; 3], turned: [f32; 3]| {
        for k in 0..3 {
            lamps[k] = (lamps[k] - rendered[k] + tint[k] * turned[k]).max(0.0);
        }
    };
    let (width, pixels) = (lamps.width, lamps.pixels);
    let (horizons, sectors) = lamps.horizons.map_or((None, 0), |(layer, sectors)| (Some(layer), sectors));
    // Per disk, whether the render's horizons bound a pixel's below its foot, made once
    // for every chunk: where the frame keeps them and the field may rise into the disk.
    let under: Vec<Option<HorizonsUnder>> = disks
        .iter()
        .map(|disk| {
            let (pyramid, along) = (pyramid?, disk.disk.march_band()?);
            let marched = horizons.is_some() && pyramid.may_rise_into(along.azimuth, along.band);
            let between = marched.then(|| pyramid.horizons_between(along.azimuth, sectors)).flatten();
            between.map(|between| between.under(along.band.below))
        })
        .collect();
    // Nothing to take out where the Sun lamps do not turn.
    let unturned;
    let [rendered_diffuse, rendered_specular] = match lamps.rendered {
        Some(rendered) => rendered,
        None => {
            unturned = vec![[0.0f32; 3]; lamps.diffuse.len()];
            [&unturned[..], &unturned[..]]
        }
    };
    let chunks = lamps.diffuse.par_chunks_mut(CHUNK).zip(lamps.specular.par_chunks_mut(CHUNK));
    let rendered = rendered_diffuse.par_chunks(CHUNK).zip(rendered_specular.par_chunks(CHUNK));
    chunks.zip(rendered).enumerate().for_each(|(c, ((diffuse, specular), (rendered_diffuse, rendered_specular)))| {
        let indices: Vec<usize> =
            (c * CHUNK..c * CHUNK + diffuse.len()).map(|k| pixels.map_or(k, |pixels| pixels[k])).collect();
        let sources: Vec<PixelSource> =
            indices.iter().map(|&i| pixel_source(shaded.materials, shaded.frame, i % width, i / width)).collect();
        let found: Vec<&[f32]> = match horizons {
            Some(layer) => indices.iter().map(|&i| &layer[i * sectors..(i + 1) * sectors]).collect(),
            None => Vec::new(),
        };
        let known = chunk_known(pyramid, blockers, &disks, &sources, &found, &under);
        for (i, source) in sources.iter().enumerate() {
            let (d, s, rd, rs) = (&mut diffuse[i], &mut specular[i], rendered_diffuse[i], rendered_specular[i]);
            match *source {
                PixelSource::Surface { ref point, tint } => {
                    let known = &known[i * disks.len()..(i + 1) * disks.len()];
                    if let Some((lit_d, lit_s)) = kernel.sun_lamps_lit(occluders, point, &disks, Some(known)) {
                        moved(d, rd, tint.diffuse, lit_d);
                        moved(s, rs, tint.specular, lit_s);
                    }
                }
                PixelSource::WaterSky { tint, mirror } => moved(s, rs, tint, suns_along(turned, mirror)),
                PixelSource::Background { .. } | PixelSource::WaterLamp { .. } => {}
            }
        }
    });
}

/// Pixels whose receivers are bounded together, in a chunk's order, to ask whether a
/// blocker can reach each disk from any of them ([`chunk_known`]): 16 consecutive pixels
/// of a row leave 88 % of the Sun-lamp scene's three turned lamps' walks of the blockers
/// out, against 72 % for 64 and 92 % for 4.
const GROUP: usize = 16;

/// What is known of each of `disks`' occluders at each of `sources` (pixel first, disk
/// second) before it is shaded ([`KnownAlongSun`]), found with the pixels beside it:
///
/// - the height field's horizon, below the disk where the horizons its render found at
///   the pixel (`found`, per source where given) bound it there (`under`, per disk:
///   [`crate::heightfield::HorizonsBetween`], the same answer the march gives), else
///   marched together where the pixel is a surface that its tangent plane does not
///   wholly hide the disk from (the rest are not read:
///   [`crate::shade::sun::DiskDirections::seen_against`] returns first); where the field
///   cannot rise to a disk, every surface's horizon is answered without a march, and the
///   tangent plane is not asked (6 to 7 % of a turn of the Sun-lamp scene's three lamps);
/// - whether a blocker can reach the disk from any surface of a [`GROUP`] of pixels,
///   bounded by a ball (most groups of the Sun-lamp scene see none).
fn chunk_known(
    pyramid: Option<&HorizonPyramid>,
    blockers: Option<&BlockerTree>,
    disks: &[SunDisk],
    sources: &[PixelSource],
    found: &[&[f32]],
    under: &[Option<HorizonsUnder>],
) -> Vec<KnownAlongSun> {
    let unknown = KnownAlongSun { horizon: pyramid.map(|_| HorizonAgainst::Below), blockers: blockers.is_some() };
    let mut known = vec![unknown; sources.len() * disks.len()];
    if let Some(tree) = blockers {
        for (g, group) in sources.chunks(GROUP).enumerate() {
            let points: Vec<[f64; 3]> = group
                .iter()
                .filter_map(|source| match source {
                    PixelSource::Surface { point, .. } => Some(point.position),
                    _ => None,
                })
                .collect();
            let Some((centre, spread)) = bounding_ball(&points) else { continue };
            for (s, disk) in disks.iter().enumerate() {
                let reaches = disk.disk.blockers_may_reach(tree, centre, spread);
                for i in g * GROUP..g * GROUP + group.len() {
                    known[i * disks.len() + s].blockers = reaches;
                }
            }
        }
    }
    let Some(pyramid) = pyramid else { return known };
    let tangent = Planes { tangent: true, ground: None };
    for (s, disk) in disks.iter().enumerate() {
        let Some(along) = disk.disk.march_band() else { continue };
        let marched = pyramid.may_rise_into(along.azimuth, along.band);
        let (mut points, mut at) = (Vec::with_capacity(sources.len()), Vec::with_capacity(sources.len()));
        for (i, source) in sources.iter().enumerate() {
            if let PixelSource::Surface { point, .. } = source {
                // Below the disk's foot, a horizon hides none of it (`ElevationBand`).
                if under[s].as_ref().is_some_and(|under| under.holds(point.position, found[i])) {
                    known[i * disks.len() + s].horizon = Some(HorizonAgainst::Below);
                    continue;
                }
                if !marched || !disk.disk.hidden_by_planes(tangent, point.position, point.normal) {
                    points.push(point.position);
                    at.push(i);
                }
            }
        }
        let mut horizons = vec![HorizonAgainst::Below; points.len()];
        pyramid.horizons_against(&points, along.azimuth, along.horizontal_reach, along.band, &mut horizons);
        for (i, against) in at.into_iter().zip(horizons) {
            known[i * disks.len() + s].horizon = Some(against);
        }
    }
    known
}

/// A ball holding `points` (the centre of their bounding box, and the farthest from it),
/// `None` for no points or a point not finite.
fn bounding_ball(points: &[[f64; 3]]) -> Option<([f64; 3], f64)> {
    if points.iter().flatten().any(|c| !c.is_finite()) {
        return None;
    }
    let first = *points.first()?;
    let (mut low, mut high) = (first, first);
    for p in points {
        for k in 0..3 {
            low[k] = low[k].min(p[k]);
            high[k] = high[k].max(p[k]);
        }
    }
    let centre = [0, 1, 2].map(|k| 0.5 * (low[k] + high[k]));
    let distance = |p: &[f64; 3]| (0..3).map(|k| (p[k] - centre[k]).powi(2)).sum::<f64>().sqrt();
    let spread = points.iter().map(distance).fold(0.0, f64::max);
    Some((centre, spread))
}
