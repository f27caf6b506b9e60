//! Reader of scene format v1 (the contract in `docs/design.md`, "Scene format v1"), and the
//! writers of output images.
//!
//! A scene is a directory with `scene.json`. [`Scene::load`] parses and validates it and
//! reads what is the same for every frame (the light, a height map whose path has no
//! `#`); [`Scene::frame`] reads one frame's G-buffers, camera and blockers.
//!
//! # Rules enforced while reading
//!
//! - Every JSON object denies unknown keys; the error names the key, the file, the line
//!   and the column. `version` must be 1 (checked before anything else, so a newer file
//!   says "unsupported version" rather than "unknown key").
//! - Paths are relative to the scene directory and must stay inside it (no `..` above
//!   it, no absolute path elsewhere; see `paths`). A run of `#` is the frame number,
//!   zero-padded to the run's length (`####` and frame 7 give `0007`); a path without `#`
//!   is shared by all frames.
//! - Materials: keys are material indices as decimal strings, at least 1 (0 is the
//!   background). Types and their keys: `heightfield` {`albedo`}, `water` {`tint`},
//!   `diffuse` {`albedo`}, `phong` {`albedo`, `specular`, `exponent`}; every key of the
//!   type is required, colours are three finite numbers `>= 0`, `exponent > 0`.
//! - Light: exactly one of `{"environment": path, "strength": s, "rotation": [x, y, z]}`
//!   (`strength` optional, default 1, finite and `>= 0`; `rotation` optional, Euler XYZ in
//!   degrees as Blender's Mapping node of type Point: the radiance along `d` is the map's
//!   along `R d`, the map resampled once on reading), `{"constant": [r, g, b]}` or `{"sh": [[r, g, b], ...]}`
//!   with a perfect-square count of triples. See [`light`] for the map orientation.
//! - Sharp lights: an optional list `"lights"` beside `light`, of
//!   `{"type": "sun", "direction": [x, y, z], "angle": degrees, "strength": s, "color":
//!   [r, g, b]}` in Blender's units: `direction` points towards the sun (any length but
//!   0), `angle` is the disk's angular diameter (Blender's Sun "Angle", in `(0, 180]`),
//!   `strength` the irradiance on a surface facing it (Blender's Sun "Strength", W/m^2,
//!   finite and `>= 0`), `color` optional (default white); and of `{"type": "point",
//!   "position": [x, y, z], "radius": r, "power": p, "color": [r, g, b], "soft_falloff":
//!   b}`, a Blender Point lamp: world position, Radius (metres, `>= 0`), Power (watts,
//!   finite and `>= 0`), `color` optional (default white), Soft Falloff optional (default
//!   true, Blender's default; see [`PointLight`]). At most [`MAX_SUNS`] entries.
//! - Per frame: an optional `per_frame`, a path with `#`, one file per frame with what
//!   changes from frame to frame: lamps, the World's strength, rotation or colour, the
//!   height map's rectangle ([`per_frame`]).
//! - Ground: an optional `{"height": z}`, an infinite horizontal plane at world Z `z` that
//!   hides everything below the horizontal from receivers above it (a flat floor the
//!   exporter found); not together with `heightfield`.
//! - View: an optional `view` object, the colour management the PNG previews apply
//!   (see [`view`]).
//! - Supersample: an optional `supersample`, 1 to [`MAX_SUPERSAMPLE`]: the G-buffers hold
//!   that many samples per camera pixel along each axis, and the camera's `resolution`
//!   times it must be their size ([`crate::shade::resolve`]).
//! - Colour passes: an optional `colour_passes` (default false). True: the G-buffer holds
//!   Blender's Diffuse Color and Glossy Color passes, which multiply the light through
//!   the diffuse and the glossy lobe per pixel in place of the table's `albedo` and
//!   `specular` (and of a water pixel's `tint`); the table still gives each material's
//!   type and lobe width, and the colours of the points seen in a reflection G-buffer
//!   without such passes ([`gbuffer`], "Colour passes"). Their channels may be renamed
//!   under `"channels"` (`diffuse_colour`, `glossy_colour`), which is an error without
//!   `colour_passes`.
//! - G-buffers: see [`gbuffer`] for channel names, layouts and per-pixel checks.
//!
//! # Channel-name overrides
//!
//! `scene.json` may hold `"channels"`, an object with any of these keys (each one
//! replaces the default for both the G-buffer and the reflection G-buffer):
//!
//! ```json
//! "channels": {
//!   "position": ["P.X", "P.Y", "P.Z"],
//!   "normal": ["N.X", "N.Y", "N.Z"],
//!   "uv": ["UV.U", "UV.V"],
//!   "material_index": "IndexMA.X",
//!   "diffuse_colour": ["DiffCol.R", "DiffCol.G", "DiffCol.B"],
//!   "glossy_colour": ["GlossCol.R", "GlossCol.G", "GlossCol.B"]
//! }
//! ```
//!
//! Names are full dotted names (`<part name>.<channel>` for multi-part files, see
//! [`gbuffer`]). Defaults: `ViewLayer.Position.{X,Y,Z}`, `ViewLayer.Normal.{X,Y,Z}`,
//! `ViewLayer.UV.{U,V}` and `ViewLayer.Material Index.X`, falling back to
//! `ViewLayer.IndexMA.X` (Blender 4). The default UV channels are optional (UV is not
//! used by shading; absent, [`GBuffer::uv`] is `None`); UV channels named in an override
//! are required.
//!
//! # Outputs
//!
//! [`output`] writes linear EXR and sRGB PNG files atomically. Before writing, call
//! [`Scene::check_output_path`]: it refuses any path that is, or for some frame would be,
//! one of the scene's inputs.

pub mod camera;
pub mod error;
pub(crate) mod exr_read;
pub(crate) mod exr_zip;
pub mod format;
pub mod frame;
pub mod gbuffer;
pub mod heightmap;
pub mod light;
pub mod output;
mod paths;
pub mod per_frame;
pub mod sun_shadow;
pub mod view;

pub use camera::{Camera, FrameBlockers, Sphere};
pub use error::{SceneError, MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE};
use format::*;
pub use frame::{BuriedCount, Frame, OpenFrame};
pub use gbuffer::{ChannelNames, GBuffer, GBufferFile, Reading};
pub use heightmap::HeightMap;
pub use light::{EnvironmentMap, Light, LightSource, PointLight, SunLight, MAX_SUNS};
pub use sun_shadow::SunShadowMap;
pub use view::{ViewSpec, ViewTransform};

use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Name of the scene description inside a scene directory.
pub const SCENE_FILE: &str = "scene.json";

/// A material of the table in `scene.json`; see `docs/design.md` for what each type means.
#[derive(Clone, Debug, PartialEq)]
pub enum Material {
    /// Diffuse, on the height-field surface, with its self-shadowing.
    Heightfield { albedo: [f32; 3] },
    /// Shaded as the point of the reflection G-buffer, times `tint`.
    Water { tint: [f32; 3] },
    /// Lambertian.
    Diffuse { albedo: [f32; 3] },
    /// Diffuse `albedo` plus a normalised Phong lobe (paper 000, Eq. 27).
    Phong { albedo: [f32; 3], specular: [f32; 3], exponent: f32 },
}

impl Material {
    /// The colours of the table as Blender's Diffuse Color and Glossy Color passes carry
    /// them ([`gbuffer`], "Colour passes"): the albedo and the specular colour, a water
    /// tint on the glossy pass, black where a lobe is absent.
    pub fn pass_colours(&self) -> ([f32; 3], [f32; 3]) {
        match *self {
            Material::Diffuse { albedo } | Material::Heightfield { albedo } => (albedo, [0.0; 3]),
            Material::Phong { albedo, specular, .. } => (albedo, specular),
            Material::Water { tint } => ([0.0; 3], tint),
        }
    }

    /// The type name used in `scene.json`.
    pub fn type_name(&self) -> &'static str {
        match self {
            Material::Heightfield { .. } => "heightfield",
            Material::Water { .. } => "water",
            Material::Diffuse { .. } => "diffuse",
            Material::Phong { .. } => "phong",
        }
    }
}

/// The scene's frames from `"frames"`: every frame from `start` to `end` (inclusive), or
/// only those of `list` where the export skipped some (Blender's frame step, or a list of
/// frames given to the exporter).
#[derive(Clone, Debug, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameRange {
    pub start: i64,
    pub end: i64,
    /// The frames exported, sorted and distinct, from `start` to `end`.
    #[serde(default)]
    pub list: Option<Vec<i64>>,
}

impl FrameRange {
    /// Whether `frame` is one of the scene's.
    pub fn contains(&self, frame: i64) -> bool {
        match &self.list {
            Some(list) => list.binary_search(&frame).is_ok(),
            None => (self.start..=self.end).contains(&frame),
        }
    }

    /// How many frames the scene has.
    pub fn count(&self) -> i128 {
        match &self.list {
            Some(list) => list.len() as i128,
            None => i128::from(self.end) - i128::from(self.start) + 1,
        }
    }

    /// The scene's frames, in order (at most `limit` of them, so that an absurd range
    /// cannot fill memory: check [`Self::count`] first).
    pub fn numbers(&self, limit: usize) -> Vec<i64> {
        match &self.list {
            Some(list) => list.iter().copied().take(limit).collect(),
            None => (self.start..=self.end).take(limit).collect(),
        }
    }

    /// The frames as a user reads them: `1-24`, or `1, 5, 9` (the first few of a long list).
    pub fn describe(&self) -> String {
        match &self.list {
            Some(list) if list.len() > 8 => format!(
                "{} ... {} ({} frames from {} to {})",
                list[..4].iter().map(i64::to_string).collect::<Vec<_>>().join(", "),
                list[list.len() - 1],
                list.len(),
                self.start,
                self.end
            ),
            Some(list) => list.iter().map(i64::to_string).collect::<Vec<_>>().join(", "),
            None => format!("{}-{}", self.start, self.end),
        }
    }

    /// What is wrong with the range, if anything.
    fn problem(&self) -> Option<String> {
        if self.start > self.end {
            return Some(format!("frames: start {} is after end {}", self.start, self.end));
        }
        let list = self.list.as_ref()?;
        if list.first() != Some(&self.start) || list.last() != Some(&self.end) {
            return Some(format!(
                "frames: list must begin with start ({}) and end with end ({}), found {:?} ... {:?}",
                self.start,
                self.end,
                list.first(),
                list.last()
            ));
        }
        list.windows(2)
            .find(|w| w[0] >= w[1])
            .map(|w| format!("frames: list must be sorted and without repeats, found {} before {}", w[0], w[1]))
    }
}

/// A path of `scene.json`, possibly with `#` runs standing for the frame number.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PathTemplate(pub String);

impl PathTemplate {
    /// True when the path changes with the frame.
    pub fn is_per_frame(&self) -> bool {
        self.0.contains('#')
    }

    /// The path of `frame`: each run of `#` becomes the frame number zero-padded to the
    /// run's length (a longer number is written in full; a negative one keeps its sign
    /// within the width).
    pub fn for_frame(&self, frame: i64) -> String {
        let mut out = String::new();
        let mut chars = self.0.chars().peekable();
        while let Some(c) = chars.next() {
            if c == '#' {
                let mut width = 1;
                while chars.peek() == Some(&'#') {
                    chars.next();
                    width += 1;
                }
                out.push_str(&format!("{frame:0width$}"));
            } else {
                out.push(c);
            }
        }
        out
    }

    /// The file of `frame` inside `dir`.
    pub fn resolve(&self, dir: &Path, frame: i64) -> PathBuf {
        dir.join(self.for_frame(frame))
    }

    /// True when `candidate` (a path relative to the scene directory, components already
    /// normalised) is this template for some frame number.
    fn matches_any_frame(&self, candidate: &str) -> bool {
        fn go(t: &[char], c: &[char]) -> bool {
            match t.first() {
                None => c.is_empty(),
                Some('#') => {
                    let run = t.iter().take_while(|&&ch| ch == '#').count();
                    let rest = &t[run..];
                    let mut start = 0;
                    if c.first() == Some(&'-') {
                        start = 1;
                    }
                    let digits = c[start..].iter().take_while(|ch| ch.is_ascii_digit()).count();
                    (1..=digits).any(|n| start + n >= run && go(rest, &c[start + n..]))
                }
                Some(&ch) => c.first() == Some(&ch) && go(&t[1..], &c[1..]),
            }
        }
        let t: Vec<char> = self.0.chars().collect();
        let c: Vec<char> = candidate.chars().collect();
        go(&t, &c)
    }
}

/// The `heightfield` object of `scene.json`.
#[derive(Clone, Debug, PartialEq)]
pub struct HeightfieldSpec {
    pub heights: PathTemplate,
    pub min: [f64; 2],
    pub max: [f64; 2],
    pub channel: Option<String>,
}

/// The `light` object of `scene.json`, before any file is read.
#[derive(Clone, Debug, PartialEq)]
pub enum LightSpec {
    /// `rotation`: Euler XYZ in degrees, as Blender's Mapping node (type Point) in front of
    /// the Environment Texture: the radiance along `d` is the map's along `R d`.
    Environment {
        path: PathTemplate,
        strength: f32,
        rotation: [f64; 3],
    },
    Constant([f32; 3]),
    Sh(Vec<[f64; 3]>),
}

/// Most G-buffer samples per camera pixel along each axis (`supersample`).
pub const MAX_SUPERSAMPLE: usize = 4;

/// A loaded and validated `scene.json`.
#[derive(Clone, Debug)]
pub struct Scene {
    /// The scene directory.
    pub dir: PathBuf,
    pub frames: Option<FrameRange>,
    pub gbuffer: PathTemplate,
    pub reflection_gbuffer: Option<PathTemplate>,
    pub camera: Option<PathTemplate>,
    pub blockers: Option<PathTemplate>,
    pub heightfield: Option<HeightfieldSpec>,
    /// World Z of an infinite horizontal ground plane that occludes (`ground` in
    /// scene.json): everything below the horizontal, for a receiver above it.
    pub ground: Option<f64>,
    /// Material table by index (all `>= 1`).
    pub materials: BTreeMap<u32, Material>,
    /// The reflectance at normal incidence of the `phong` materials whose entry gives it
    /// (`fresnel`): what their Fresnel term starts from ([`crate::shade::glossy::Fresnel`]).
    pub fresnel: BTreeMap<u32, f64>,
    pub light_spec: LightSpec,
    /// Suns beside `light` (from `lights`).
    pub suns: Vec<SunLight>,
    /// Point lamps (from `lights`); `--light-rotation` leaves them where they are.
    pub points: Vec<PointLight>,
    /// Degrees the whole light is turned about Z on top of scene.json (`--light-rotation`).
    pub light_turn: f64,
    pub channels: ChannelNames,
    /// How previews show the linear image (`view` in scene.json; Standard without it).
    pub view: ViewTransform,
    /// G-buffer samples per camera pixel along each axis (`supersample`, 1 to
    /// [`MAX_SUPERSAMPLE`]): the G-buffers are this many times the camera's resolution,
    /// and the outputs are resolved back to it ([`crate::shade::resolve`]).
    pub supersample: usize,
    /// One file per frame with what changes from frame to frame: lamps, the World, the
    /// height map's rectangle (`per_frame` in scene.json; [`per_frame`]).
    pub per_frame: Option<PathTemplate>,
    /// With the CRC-32 of the map's file as it was read ([`light::file_crc`]).
    static_light: Option<(Arc<Light>, Option<u32>)>,
    static_height_map: Option<Arc<HeightMap>>,
}

// ---- the JSON schema of scene.json ------------------------------------------------

impl Scene {
    /// Reads and validates `dir/scene.json`, and the light and height map when they are
    /// the same for every frame.
    pub fn load(dir: &Path) -> Result<Scene, SceneError> {
        let mut scene = Self::load_description(dir)?;
        let frame = scene.default_frame();
        if !matches!(&scene.light_spec, LightSpec::Environment { path, .. } if path.is_per_frame()) {
            let (light, crc) = scene.read_light(frame)?;
            scene.static_light = Some((Arc::new(light), crc));
        }
        if let Some(h) = &scene.heightfield {
            if !h.heights.is_per_frame() {
                scene.static_height_map = Some(Arc::new(scene.read_height_map(frame, None)?));
            }
        }
        Ok(scene)
    }

    /// Reads and validates `dir/scene.json` alone, no map read: what names the scene's
    /// files ([`Self::check_output_path`]).
    pub fn load_description(dir: &Path) -> Result<Scene, SceneError> {
        if dir.is_file() {
            let blend = dir.extension().is_some_and(|e| e.eq_ignore_ascii_case("blend"));
            let what = if blend {
                "is a .blend file; logsh reads the scene directory exported from it: \
                 `blender -b scene.blend -P blender_scripts/export_scene.py -- --out DIR`, then give DIR"
            } else {
                "is a file; give the scene directory that holds scene.json"
            };
            return Err(SceneError::NotASceneDirectory { path: dir.to_path_buf(), what: what.into() });
        }
        let file = dir.join(SCENE_FILE);
        let text = std::fs::read_to_string(&file).map_err(|e| SceneError::io(&file, "the scene description", e))?;
        let probe: VersionProbe = serde_json::from_str(&text).map_err(|e| SceneError::json(&file, e))?;
        match &probe.version {
            None => return Err(SceneError::invalid(&file, "missing key \"version\" (this logsh reads version 1)")),
            Some(v) if v.as_u64() == Some(1) => {}
            Some(v) => return Err(SceneError::Version { file: file.clone(), found: v.to_string() }),
        }
        let raw: SceneFile = serde_json::from_str(&text).map_err(|e| SceneError::json(&file, e))?;
        raw.check_paths_inside(&file, dir)?;

        if let Some(problem) = raw.frames.as_ref().and_then(FrameRange::problem) {
            return Err(SceneError::invalid(&file, problem));
        }
        let (mut materials, mut fresnel) = (BTreeMap::new(), BTreeMap::new());
        for (key, m) in &raw.materials {
            let (index, material, reflectance) = parse_material(&file, key, m)?;
            if materials.insert(index, material).is_some() {
                return Err(SceneError::invalid(&file, format!("material {index} is defined twice")));
            }
            if let Some(reflectance) = reflectance {
                fresnel.insert(index, reflectance);
            }
        }
        let heightfield = match raw.heightfield {
            None => None,
            Some(h) => {
                for v in h.min.iter().chain(h.max.iter()) {
                    if !v.is_finite() {
                        return Err(SceneError::NonFinite { file: file.clone(), what: "heightfield min/max".into() });
                    }
                }
                if !(h.min[0] < h.max[0] && h.min[1] < h.max[1]) {
                    return Err(SceneError::invalid(
                        &file,
                        format!("heightfield: min {:?} must be below max {:?} in x and y", h.min, h.max),
                    ));
                }
                Some(HeightfieldSpec { heights: PathTemplate(h.heights), min: h.min, max: h.max, channel: h.channel })
            }
        };
        let ground = match raw.ground {
            None => None,
            Some(g) if !g.height.is_finite() => {
                return Err(SceneError::NonFinite { file: file.clone(), what: "ground height".into() })
            }
            Some(_) if heightfield.is_some() => {
                return Err(SceneError::invalid(
                    &file,
                    "\"ground\" and \"heightfield\" both say what is below the scene; keep one",
                ))
            }
            Some(g) => Some(g.height),
        };
        let light_spec = parse_light(&file, &raw.light)?;
        let (suns, points) = per_frame::parse_lamps(&file, &raw.lights.unwrap_or_default())?;
        let per_frame = raw.per_frame.map(PathTemplate);
        if per_frame.as_ref().is_some_and(|t| !t.is_per_frame()) {
            return Err(SceneError::invalid(
                &file,
                "\"per_frame\" must name one file per frame: a path with # for the frame number",
            ));
        }
        let colour_passes = raw.colour_passes.unwrap_or(false);
        if let Some(named) = raw.channels.as_ref().filter(|_| !colour_passes) {
            for (key, given) in [("diffuse_colour", &named.diffuse_colour), ("glossy_colour", &named.glossy_colour)] {
                if given.is_some() {
                    return Err(SceneError::invalid(
                        &file,
                        format!("\"channels\" names \"{key}\" but \"colour_passes\" is not true, so nothing reads it"),
                    ));
                }
            }
        }
        let channels = ChannelNames::new(raw.channels.as_ref(), colour_passes);
        let view = match &raw.view {
            Some(spec) => ViewTransform::load(spec, dir, &file)?,
            None => ViewTransform::default(),
        };
        let supersample = raw.supersample.unwrap_or(1) as usize;
        if !(1..=MAX_SUPERSAMPLE).contains(&supersample) {
            return Err(SceneError::invalid(
                &file,
                format!("\"supersample\": {supersample} is not from 1 to {MAX_SUPERSAMPLE}"),
            ));
        }

        let scene = Scene {
            dir: dir.to_path_buf(),
            frames: raw.frames,
            gbuffer: PathTemplate(raw.gbuffer),
            reflection_gbuffer: raw.reflection_gbuffer.map(PathTemplate),
            camera: raw.camera.map(PathTemplate),
            blockers: raw.blockers.map(PathTemplate),
            heightfield,
            ground,
            materials,
            fresnel,
            light_spec,
            suns,
            points,
            light_turn: 0.0,
            channels,
            view,
            supersample,
            per_frame,
            static_light: None,
            static_height_map: None,
        };
        Ok(scene)
    }

    /// Whether the G-buffer's colour passes multiply the light through each lobe per
    /// pixel (`"colour_passes": true`), in place of the material table's colours.
    pub fn colour_passes(&self) -> bool {
        self.channels.colours.is_some()
    }

    /// The material table as the kernel shades it: the table itself, or, where the
    /// colours come from the G-buffer's passes ([`Self::colour_passes`]), every colour
    /// white, so that the kernel's passes are the light through each lobe and the
    /// passes multiply them per pixel ([`crate::shade::Tint`]). A black albedo or
    /// specular stays black: a lobe the table says is absent is not shaded.
    pub fn kernel_materials(&self) -> BTreeMap<u32, Material> {
        if !self.colour_passes() {
            return self.materials.clone();
        }
        let white = |c: [f32; 3]| if c == [0.0; 3] { c } else { [1.0; 3] };
        let whitened = |m: &Material| match *m {
            Material::Heightfield { albedo } => Material::Heightfield { albedo: white(albedo) },
            Material::Diffuse { albedo } => Material::Diffuse { albedo: white(albedo) },
            Material::Phong { albedo, specular, exponent } => {
                Material::Phong { albedo: white(albedo), specular: white(specular), exponent }
            }
            Material::Water { tint } => Material::Water { tint: white(tint) },
        };
        self.materials.iter().map(|(&i, m)| (i, whitened(m))).collect()
    }

    /// Path of `scene.json`.
    pub fn scene_file(&self) -> PathBuf {
        self.dir.join(SCENE_FILE)
    }

    /// The frame to shade when none is given: `frames.start`, or 1.
    pub fn default_frame(&self) -> i64 {
        self.frames.as_ref().map_or(1, |f| f.start)
    }

    /// The scene's frame numbers (at most `limit`: [`FrameRange::count`] says how many
    /// there are), or just the default frame.
    pub fn frame_numbers(&self, limit: usize) -> Vec<i64> {
        match &self.frames {
            Some(f) => f.numbers(limit),
            None => vec![self.default_frame()],
        }
    }

    fn check_frame(&self, frame: i64) -> Result<(), SceneError> {
        match &self.frames {
            Some(f) if !f.contains(frame) => {
                Err(SceneError::FrameOutOfRange { file: self.scene_file(), frame, frames: f.describe() })
            }
            _ => Ok(()),
        }
    }

    /// Turns the scene's light (the environment and the suns) by `degrees` about Z, on
    /// top of scene.json's (`--light-rotation`): a sun at azimuth `a` moves to `a +
    /// degrees`; an `sh` light turns its coefficients ([`light::turned_sh`]).
    pub fn turn_light(&mut self, degrees: f64) -> Result<(), SceneError> {
        if !degrees.is_finite() {
            return Err(SceneError::invalid(
                &self.scene_file(),
                format!("--light-rotation {degrees} is not a finite number of degrees"),
            ));
        }
        // Whole turns taken out first, exactly (`%` is exact), so that a vast angle turns
        // as its remainder does.
        let degrees = degrees % 360.0;
        if degrees == 0.0 {
            return Ok(());
        }
        if let LightSpec::Sh(coefficients) = &self.light_spec {
            self.light_spec = LightSpec::Sh(light::turned_sh(coefficients, degrees));
        }
        self.light_turn += degrees;
        for sun in &mut self.suns {
            *sun = sun.turned(degrees);
        }
        if self.static_light.is_some() {
            let (light, crc) = self.read_light(self.default_frame())?;
            self.static_light = Some((Arc::new(light), crc));
        }
        Ok(())
    }

    /// What the light of `frame` is made from, files resolved: what a relight needs to
    /// build it again ([`crate::transfer`]).
    pub fn light_source(&self, frame: i64) -> Result<LightSource, SceneError> {
        let changed = self.changes(frame)?.light;
        Ok(match changed.as_ref().unwrap_or(&self.light_spec) {
            LightSpec::Environment { path, strength, rotation } => {
                let file = path.resolve(&self.dir, frame);
                LightSource::Environment {
                    file: std::path::absolute(&file).unwrap_or(file),
                    strength: *strength,
                    rotation: *rotation,
                    turn: self.light_turn,
                }
            }
            LightSpec::Constant(c) => LightSource::Constant(*c),
            LightSpec::Sh(v) => LightSource::Sh(v.clone()),
        })
    }

    /// The light of `frame` (shared when its path has no `#`).
    pub fn light(&self, frame: i64) -> Result<Arc<Light>, SceneError> {
        Ok(self.light_as_read(frame)?.0)
    }

    /// [`Self::light`], with the CRC-32 of its map's file as it was read (`None` without
    /// a map): what a frame's transfer header records.
    pub fn light_as_read(&self, frame: i64) -> Result<(Arc<Light>, Option<u32>), SceneError> {
        self.light_changed(frame, self.changes(frame)?.light.as_ref())
    }

    /// [`Self::light_as_read`] with the frame's change of the light, `changed`, read.
    fn light_changed(&self, frame: i64, changed: Option<&LightSpec>) -> Result<(Arc<Light>, Option<u32>), SceneError> {
        match (&self.static_light, changed) {
            (Some((light, crc)), None) => Ok((light.clone(), *crc)),
            (_, changed) => {
                self.check_frame(frame)?;
                let (light, crc) = self.read_light_of(changed.unwrap_or(&self.light_spec), frame)?;
                Ok((Arc::new(light), crc))
            }
        }
    }

    /// What `frame` changes of scene.json ([`per_frame`]); nothing without `per_frame`.
    pub fn changes(&self, frame: i64) -> Result<per_frame::FrameChanges, SceneError> {
        match &self.per_frame {
            None => Ok(per_frame::FrameChanges::default()),
            Some(template) => {
                self.check_frame(frame)?;
                per_frame::FrameChanges::read(&template.resolve(&self.dir, frame), frame, &self.light_spec)
            }
        }
    }

    /// The height map of `frame`, if the scene has a height field.
    pub fn height_map(&self, frame: i64) -> Result<Option<Arc<HeightMap>>, SceneError> {
        if self.heightfield.is_none() {
            return Ok(None);
        }
        self.height_map_within(frame, self.changes(frame)?.rectangle)
    }

    /// [`Self::height_map`] with the frame's own rectangle, `rectangle`, read.
    fn height_map_within(
        &self,
        frame: i64,
        rectangle: Option<([f64; 2], [f64; 2])>,
    ) -> Result<Option<Arc<HeightMap>>, SceneError> {
        if self.heightfield.is_none() {
            return Ok(None);
        }
        if let (Some(map), None) = (&self.static_height_map, rectangle) {
            return Ok(Some(map.clone()));
        }
        self.check_frame(frame)?;
        Ok(Some(Arc::new(self.read_height_map(frame, rectangle)?)))
    }

    /// The light of `frame`, with the CRC-32 of its map's file taken just before the map
    /// is read from it.
    fn read_light(&self, frame: i64) -> Result<(Light, Option<u32>), SceneError> {
        self.read_light_of(&self.light_spec, frame)
    }

    /// [`Self::read_light`] of `spec` (scene.json's, or a frame's change of it).
    fn read_light_of(&self, spec: &LightSpec, frame: i64) -> Result<(Light, Option<u32>), SceneError> {
        match spec {
            LightSpec::Environment { path, strength, rotation } => {
                let file = path.resolve(&self.dir, frame);
                let crc = light::file_crc(&file);
                let map = EnvironmentMap::read(&file)?;
                Ok((Light::Environment { map: map.oriented(*rotation, self.light_turn), strength: *strength }, crc))
            }
            LightSpec::Constant(c) => Ok((Light::Constant(*c), None)),
            LightSpec::Sh(v) => Ok((Light::Sh(v.clone()), None)),
        }
    }

    /// The height map of `frame` over `rectangle`, scene.json's where `None`.
    fn read_height_map(&self, frame: i64, rectangle: Option<([f64; 2], [f64; 2])>) -> Result<HeightMap, SceneError> {
        let h = self.heightfield.as_ref().expect("caller checked");
        let (min, max) = rectangle.unwrap_or((h.min, h.max));
        HeightMap::read(&h.heights.resolve(&self.dir, frame), h.channel.as_deref(), min, max)
    }

    /// Every file `frame` reads, `scene.json` included.
    pub fn input_paths(&self, frame: i64) -> Vec<PathBuf> {
        self.templates().into_iter().map(|t| t.resolve(&self.dir, frame)).chain([self.scene_file()]).collect()
    }

    fn templates(&self) -> Vec<&PathTemplate> {
        let mut t = vec![&self.gbuffer];
        t.extend(self.reflection_gbuffer.iter());
        t.extend(self.camera.iter());
        t.extend(self.blockers.iter());
        t.extend(self.heightfield.iter().map(|h| &h.heights));
        t.extend(self.per_frame.iter());
        if let LightSpec::Environment { path, .. } = &self.light_spec {
            t.push(path);
        }
        t
    }

    /// Refuses an output path that is `scene.json`, the view's LUT or any input of any
    /// frame (a templated input matches every frame number, inside or outside `frames`).
    /// Paths are compared where writing would put the file (`written_entry`: links
    /// and `..` resolved as the system resolves them), against each input's own entry and
    /// the file it resolves to; a templated input's directory is resolved the same way.
    pub fn check_output_path(&self, path: &Path) -> Result<(), SceneError> {
        let out = written_entry(path);
        let is =
            |input: &Path| out == written_entry(input) || std::fs::canonicalize(input).is_ok_and(|real| real == out);
        if is(&self.scene_file()) {
            return Err(SceneError::OutputIsInput { file: path.to_path_buf(), what: "the scene description".into() });
        }
        if let Some(lut) = self.view.spec.as_ref().and_then(|spec| spec.lut.as_ref()) {
            if is(&self.dir.join(&lut.file)) {
                return Err(SceneError::OutputIsInput {
                    file: path.to_path_buf(),
                    what: "the view transform's LUT".into(),
                });
            }
        }
        let dir = written_entry(&self.dir);
        for t in self.templates() {
            let template = Path::new(&t.0);
            let (folder, pattern) =
                (template.parent().unwrap_or(Path::new("")), template.file_name().and_then(|n| n.to_str()));
            let hit = match pattern {
                // The output's name against the template's, in the template's folder.
                Some(pattern) if t.is_per_frame() && !folder.to_string_lossy().contains('#') => {
                    out.file_name().and_then(|n| n.to_str()).is_some_and(|name| {
                        PathTemplate(pattern.into()).matches_any_frame(name) && is(&self.dir.join(folder).join(name))
                    })
                }
                _ if t.is_per_frame() => out.strip_prefix(&dir).ok().and_then(|rel| rel.to_str()).is_some_and(|rel| {
                    PathTemplate(normalise_relative(&t.0)).matches_any_frame(&rel.replace('\\', "/"))
                }),
                _ => is(&self.dir.join(template)),
            };
            if hit {
                return Err(SceneError::OutputIsInput { file: path.to_path_buf(), what: format!("input \"{}\"", t.0) });
            }
        }
        Ok(())
    }
}

/// Where writing `path` puts a file: its folder as the system resolves it (each
/// symbolic link resolved where it stands, so that `link/..` is the link target's parent,
/// as the system has it), and its own name unresolved (a file is written beside it and
/// renamed onto the name, which replaces a link rather than its target). Absolute; the
/// part that does not exist yet is kept as written.
fn written_entry(path: &Path) -> PathBuf {
    let abs =
        if path.is_absolute() { path.to_path_buf() } else { std::env::current_dir().unwrap_or_default().join(path) };
    let components: Vec<_> = abs.components().collect();
    let mut resolved = PathBuf::new();
    for (k, component) in components.iter().enumerate() {
        match component {
            std::path::Component::CurDir => {}
            std::path::Component::ParentDir => {
                resolved.pop();
            }
            std::path::Component::Normal(name) if k + 1 < components.len() => {
                let next = resolved.join(name);
                resolved = next.canonicalize().unwrap_or(next);
            }
            other => resolved.push(other),
        }
    }
    resolved
}

fn normalise_relative(path: &str) -> String {
    let mut parts: Vec<&str> = Vec::new();
    for p in path.split(['/', '\\']) {
        match p {
            "" | "." => {}
            ".." => {
                parts.pop();
            }
            other => parts.push(other),
        }
    }
    parts.join("/")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn templates_pad_and_match() {
        let t = PathTemplate("gbuffer.####.exr".into());
        assert_eq!(t.for_frame(7), "gbuffer.0007.exr");
        assert_eq!(t.for_frame(12345), "gbuffer.12345.exr");
        assert_eq!(PathTemplate("a_#.exr".into()).for_frame(3), "a_3.exr");
        assert_eq!(PathTemplate("sky.exr".into()).for_frame(3), "sky.exr");
        assert!(t.matches_any_frame("gbuffer.0007.exr"));
        assert!(t.matches_any_frame("gbuffer.12345.exr"));
        assert!(!t.matches_any_frame("gbuffer.007.exr"));
        assert!(!t.matches_any_frame("gbuffer.0007.png"));
    }
}
