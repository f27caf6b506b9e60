//! Everything that happens to a frame before its pixels, built once and consumed by both
//! executors: the settings validated, the frame checked against the materials it shows,
//! the height field read and its pyramid planned, the suns taken out of the light
//! ([`super::sharp_lights`]), the rest projected, and the kernel's tables built at the
//! chosen precision.
//!
//! What stays per executor is only what runs on it: the CPU filters the pyramid with
//! rayon and shades rows ([`super::cpu`]), computing each prefiltered texel the first
//! time a pixel reads it; the GPU filters the same plan with the same taps, computes the
//! texels its pixels will read ([`ShadingKernel::prepare_glossy`]) and composes its
//! program from the same kernel tables (`src/gpu/`).

use super::blocker_tree::BlockerTree;
use super::frame::{check_frame, height_field, ShadeError};
use super::kernel::ShadingKernel;
use super::settings::{Precision, ShadingSettings};
use super::sun_shadow::SunShadows;
use crate::heightfield::{HeightField, HorizonPyramid, PyramidPlan};
use crate::scene::{Frame, Light, Material, PointLight, Scene, SunLight};
use crate::sh::Real;
use crate::timing::StageTimings;
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// The height field of a frame and the plan of its pyramid (level sizes, march steps,
/// azimuths), before any level is filtered.
pub struct Terrain {
    pub field: HeightField,
    pub pyramid: PyramidPlan,
}

impl Terrain {
    /// The pyramid filtered on the CPU.
    pub fn horizon_pyramid(&self, settings: &ShadingSettings) -> HorizonPyramid {
        HorizonPyramid::from_plan(&self.field, &self.pyramid, settings.horizon)
    }
}

/// What a frame contains that the shading must handle; a program or loop for a feature
/// the frame lacks is never run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct FrameContents {
    pub heightfield: bool,
    pub blockers: bool,
    /// A Phong material is declared (a second exponentiation per glossy point).
    pub phong: bool,
    /// A Phong material's glossy term reads a prefiltered environment
    /// ([`super::glossy`]).
    pub prefiltered: bool,
    /// Sharp lights ([`super::sun`]) light the frame.
    pub suns: bool,
}

/// The kernel at the precision the settings ask for.
pub enum PlannedKernel {
    F32(ShadingKernel<f32>),
    F64(ShadingKernel<f64>),
}

/// One frame, ready for its pixels.
pub struct FramePlan<'a> {
    pub scene: &'a Scene,
    pub frame: &'a Frame,
    pub settings: ShadingSettings,
    pub contents: FrameContents,
    /// `Some` when the scene has a height map.
    pub terrain: Option<Terrain>,
    /// Shared with the frames before it whose kernel is the same (`lighting`).
    pub kernel: Arc<PlannedKernel>,
    /// The frame's sphere blockers as a hierarchy.
    pub blockers: BlockerTree,
    /// The suns' shadow maps of the blocker meshes, ready to march.
    pub sun_shadows: SunShadows,
    /// The sharp lights the kernel shades: the scene's, then those taken out of its map.
    pub suns: Vec<SunLight>,
    /// How many of `suns` came out of the environment map, and each one's share of its power.
    pub extracted_shares: Vec<f64>,
    /// The plan's own cost, as the stage "tables".
    pub timings: StageTimings,
}

impl<'a> FramePlan<'a> {
    /// Validates and prepares `frame` of `scene`: every error a frame can have is
    /// reported here, before any pixel is shaded on either executor.
    pub fn new(scene: &'a Scene, frame: &'a Frame, settings: &ShadingSettings) -> Result<Self, ShadeError> {
        let started = Instant::now();
        settings.validate()?;
        check_frame(scene, frame)?;
        let (settings, lighting) = &marched_with(settings, scene, frame);
        let terrain = match height_field(scene, frame)? {
            Some(field) => {
                let pyramid = PyramidPlan::new(&field, settings.horizon)
                    .map_err(|cause| ShadeError::height_field(scene, cause))?;
                Some(Terrain { field, pyramid })
            }
            None => None,
        };
        let contents = FrameContents {
            heightfield: terrain.is_some(),
            blockers: !frame.blockers.is_empty(),
            phong: scene.materials.values().any(|m| matches!(m, Material::Phong { .. })),
            prefiltered: false,
            suns: false,
        };
        let (kernel, suns, extracted_shares) =
            (lighting.kernel.clone(), lighting.suns.clone(), lighting.extracted_shares.clone());
        let contents = FrameContents {
            prefiltered: match kernel.as_ref() {
                PlannedKernel::F32(kernel) => kernel.has_prefiltered_glossy(),
                PlannedKernel::F64(kernel) => kernel.has_prefiltered_glossy(),
            },
            suns: !suns.is_empty() || !frame.points.is_empty(),
            ..contents
        };
        let blockers = BlockerTree::new(&frame.blockers, settings.cluster_ratio);
        let sun_shadows = SunShadows::new(&frame.sun_shadows);
        let mut timings = StageTimings::default();
        timings.add_wall("tables", started);
        Ok(Self {
            scene,
            frame,
            settings: *settings,
            contents,
            terrain,
            kernel,
            blockers,
            sun_shadows,
            suns,
            extracted_shares,
            timings,
        })
    }
}

/// `settings` as `frame` is shaded with them ([`ShadingSettings::for_frame`]): the march
/// takes the lamps' levels where sharp lights (Sun or point lamps, suns taken out of the
/// map) light its height field. What `logsh sweep` records of a frame's march.
pub fn frame_settings(settings: &ShadingSettings, scene: &Scene, frame: &Frame) -> ShadingSettings {
    marched_with(settings, scene, frame).0
}

/// The luminance (Rec. 709) of the light `frame`'s kernel holds in SH, the light its
/// visibility pass is weighted by: the bounce's leak scale weighs the covered share the
/// same way ([`super::bounce::SkyWeighting`]).
pub fn environment_luminance(settings: &ShadingSettings, scene: &Scene, frame: &Frame) -> Vec<f64> {
    let lighting = marched_with(settings, scene, frame).1;
    match &*lighting.kernel {
        PlannedKernel::F32(kernel) => kernel.light_luminance(),
        PlannedKernel::F64(kernel) => kernel.light_luminance(),
    }
}

/// [`frame_settings`] and the frame's lighting, which takes the map's suns out: the
/// kernel reads no level of the march, so it is built before they are chosen.
fn marched_with(settings: &ShadingSettings, scene: &Scene, frame: &Frame) -> (ShadingSettings, Arc<Lighting>) {
    let terrain = frame.height_map.is_some();
    let lighting = lighting(settings, scene, frame, terrain);
    let sharp_lights = !lighting.suns.is_empty() || !frame.points.is_empty();
    (settings.for_frame(sharp_lights && terrain), lighting)
}

/// What a frame's kernel is built from, at either precision.
struct KernelInputs<'a> {
    settings: &'a ShadingSettings,
    /// The materials as the kernel shades them ([`Scene::kernel_materials`]).
    materials: &'a BTreeMap<u32, Material>,
    /// [`super::glossy::lamp_fresnel`].
    lamp_fresnel: &'a BTreeMap<u32, f64>,
    colour_passes: bool,
    frame: &'a Frame,
    /// The SH projection of `residual`.
    light: &'a [[f64; 3]],
    /// The light with its suns taken out.
    residual: &'a Light,
    heightfield: bool,
    suns: &'a [SunLight],
    blockers: bool,
}

impl KernelInputs<'_> {
    /// The kernel's tables.
    fn kernel<T: Real>(&self) -> ShadingKernel<T> {
        ShadingKernel::new(
            self.settings,
            self.materials,
            self.lamp_fresnel,
            self.colour_passes,
            self.light,
            self.residual,
            self.heightfield,
            self.blockers,
            self.suns,
            &self.frame.points,
            self.frame.ground,
        )
    }
}

/// A frame's kernel and the sharp lights it shades, which the next frames of a sequence
/// share while the settings, the light and everything else the kernel is built from stay
/// the same: the tables (lobes, Phong eps, fitted depths, OL fit, wedge operator,
/// quadrature, the folded light) and the prefiltered texels are then built once per
/// sequence, not per frame.
pub struct Lighting {
    pub kernel: Arc<PlannedKernel>,
    /// The scene's suns, then those taken out of its map.
    pub suns: Vec<SunLight>,
    /// The share of the map's power of each sun taken out of it.
    pub extracted_shares: Vec<f64>,
}

/// What a kernel is built from, but the frame's pixels. The light is compared by
/// identity: a scene's static light is one `Arc` for all its frames, and the cache holds
/// it, so that its address cannot be reused by another.
struct LightingKey {
    settings: ShadingSettings,
    light: Arc<Light>,
    materials: BTreeMap<u32, Material>,
    lamp_fresnel: BTreeMap<u32, f64>,
    colour_passes: bool,
    suns: Vec<SunLight>,
    points: Vec<PointLight>,
    ground: Option<f64>,
    heightfield: bool,
    blockers: bool,
}

impl LightingKey {
    fn same(&self, other: &LightingKey) -> bool {
        Arc::ptr_eq(&self.light, &other.light)
            && self.settings == other.settings
            && self.materials == other.materials
            && self.lamp_fresnel == other.lamp_fresnel
            && self.colour_passes == other.colour_passes
            && self.suns == other.suns
            && self.points == other.points
            && self.ground == other.ground
            && self.heightfield == other.heightfield
            && self.blockers == other.blockers
    }
}

/// The last frame's lighting, per process.
static LAST_LIGHTING: Mutex<Option<(LightingKey, Arc<Lighting>)>> = Mutex::new(None);

/// The kernel of `frame` with `settings`: the last frame's when nothing it is built from
/// changed, else built (suns taken out of the map, the residual projected) and kept.
fn lighting(settings: &ShadingSettings, scene: &Scene, frame: &Frame, heightfield: bool) -> Arc<Lighting> {
    let key = LightingKey {
        settings: *settings,
        light: frame.light.clone(),
        materials: scene.kernel_materials(),
        lamp_fresnel: super::glossy::lamp_fresnel(scene),
        colour_passes: scene.colour_passes(),
        suns: frame.suns.clone(),
        points: frame.points.clone(),
        ground: frame.ground,
        heightfield,
        blockers: !frame.blockers.is_empty(),
    };
    let last = || LAST_LIGHTING.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some((_, lighting)) = last().as_ref().filter(|(previous, _)| previous.same(&key)) {
        return lighting.clone();
    }
    let mut suns = frame.suns.clone();
    let mut extracted_shares = Vec::new();
    let split;
    let residual = match frame.light.as_ref() {
        Light::Environment { .. } if settings.sharp_lights => {
            split = super::sharp_lights::decomposition(&frame.light).expect("the light is a map");
            suns.extend(&split.suns);
            extracted_shares = split.shares.clone();
            &split.residual
        }
        other => other,
    };
    let mut light = residual.sh_coefficients(settings.order);
    settings.light_window.apply(settings.order, &mut light);
    let inputs = KernelInputs {
        settings,
        materials: &key.materials,
        lamp_fresnel: &key.lamp_fresnel,
        colour_passes: key.colour_passes,
        frame,
        light: &light,
        residual,
        heightfield,
        suns: &suns,
        blockers: key.blockers,
    };
    let kernel = match settings.precision {
        Precision::F32 => PlannedKernel::F32(inputs.kernel()),
        Precision::F64 => PlannedKernel::F64(inputs.kernel()),
    };
    let lighting = Arc::new(Lighting { kernel: Arc::new(kernel), suns, extracted_shares });
    *last() = Some((key, lighting.clone()));
    lighting
}
