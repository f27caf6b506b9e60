//! Procedural scene writer: format v1 scenes made by ray casting analytic primitives.
//!
//! Used for the sample scenes and for tests with known answers. A [`SynthScene`] lists
//! materials, a light, an optional terrain and, per frame, a camera and objects;
//! [`write_scene`] ray casts each frame through a pinhole camera (Blender conventions,
//! see [`crate::scene::camera`]) and writes what the Blender exporter would:
//!
//! - `gbuffer.####.exr`: Position, Normal (f32), UV (U, V, A as f16), material index
//!   (f32) and a flat-shaded Combined pass (f16), ZIP-compressed, in the chosen
//!   [`GBufferLayout`]: Blender 5's one part per pass (`ViewLayer.Material Index`) or
//!   Blender 4's single part (`ViewLayer.IndexMA`);
//! - `reflection.####.exr` when a material is water: the surface seen along the mirrored
//!   view ray from each water pixel;
//! - `camera.####.json`, `blockers.####.json` (every sphere object is also a blocker);
//! - `heightmap.exr` (one f32 channel `Y`) when there is a terrain;
//! - `sky.exr` (f32 R, G, B) for a [`SynthLight::Sky`], in Blender's environment
//!   orientation (see [`crate::scene::light`]);
//! - `scene.json`.
//!
//! Named samples: [`example_scene`] (`"dunes"`, `"spheres"`); the analytic test scene
//! [`sphere_over_plane`] with its closed-form answer [`SphereOverPlane::expected_at`].

pub mod raycast;
pub mod sun_shadow;

pub use raycast::{render_gbuffer, render_reflection, trace, Hit, Object, Shape};
pub use sun_shadow::sun_shadow_map;

use crate::scene::camera::blockers_json;
use crate::scene::gbuffer::{SurfaceColours, MATERIAL_INDEX_BLENDER4, MATERIAL_INDEX_BLENDER5};
use crate::scene::light::equirectangular_to_direction;
use crate::scene::output::{write_atomically, OutputError};
use crate::scene::{Camera, GBuffer, HeightMap, Material, Sphere};
use exr::prelude::{
    f16, AnyChannel, AnyChannels, Blocks, Compression, Encoding, FlatSamples, Image, ImageAttributes, IntegerBounds,
    Layer, LayerAttributes, LineOrder, Text, WritableImage,
};
use serde_json::json;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Why a synthetic scene could not be written.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    #[error(transparent)]
    Output(#[from] OutputError),
    #[error("{}: cannot write: {cause}", .file.display())]
    Io { file: PathBuf, cause: std::io::Error },
    #[error("unknown example scene \"{name}\" (known: {})", EXAMPLE_NAMES.join(", "))]
    UnknownScene { name: String },
    #[error("invalid synthetic scene: {0}")]
    Invalid(String),
}

/// Which EXR layout the G-buffers are written in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum GBufferLayout {
    /// One part per pass, part `ViewLayer.Position` with channels `ViewLayer.Position.X`
    /// ..., material index `ViewLayer.Material Index.X`.
    #[default]
    Blender5,
    /// One part, dotted channel names, material index `ViewLayer.IndexMA.X`.
    Blender4,
}

/// A procedural sky: a gradient from horizon to zenith, a darker ground and a sun disk
/// with a soft (Gaussian) edge.
#[derive(Clone, Debug, PartialEq)]
pub struct Sky {
    pub width: usize,
    pub height: usize,
    pub zenith: [f32; 3],
    pub horizon: [f32; 3],
    pub ground: [f32; 3],
    /// Unit direction towards the sun.
    pub sun_direction: [f64; 3],
    pub sun_radiance: [f32; 3],
    /// Angular radius (radians) of the sun's Gaussian falloff.
    pub sun_radius: f64,
}

impl Default for Sky {
    fn default() -> Self {
        let (az, el) = (60f64.to_radians(), 35f64.to_radians());
        Sky {
            width: 128,
            height: 64,
            zenith: [0.25, 0.42, 0.85],
            horizon: [0.85, 0.9, 1.0],
            ground: [0.18, 0.16, 0.14],
            sun_direction: [el.cos() * az.cos(), el.cos() * az.sin(), el.sin()],
            sun_radiance: [60.0, 55.0, 48.0],
            sun_radius: 4f64.to_radians(),
        }
    }
}

impl Sky {
    /// Radiance towards unit direction `d`.
    pub fn radiance(&self, d: [f64; 3]) -> [f32; 3] {
        let mut c = if d[2] >= 0.0 {
            let t = d[2].sqrt() as f32;
            [0, 1, 2].map(|k| self.horizon[k] * (1.0 - t) + self.zenith[k] * t)
        } else {
            self.ground
        };
        let s = self.sun_direction;
        let cos = (d[0] * s[0] + d[1] * s[1] + d[2] * s[2]).clamp(-1.0, 1.0);
        let angle = cos.acos();
        let w = (-(angle / self.sun_radius).powi(2) / 2.0).exp() as f32;
        for (c, s) in c.iter_mut().zip(self.sun_radiance) {
            *c += w * s;
        }
        c
    }

    /// The map's texels, row 0 the zenith, in Blender's orientation.
    pub fn texels(&self) -> Vec<[f32; 3]> {
        let mut out = Vec::with_capacity(self.width * self.height);
        for row in 0..self.height {
            for col in 0..self.width {
                let u = (col as f64 + 0.5) / self.width as f64;
                let v = 1.0 - (row as f64 + 0.5) / self.height as f64;
                out.push(self.radiance(equirectangular_to_direction(u, v)));
            }
        }
        out
    }
}

/// The light a synthetic scene declares.
#[derive(Clone, Debug, PartialEq)]
pub enum SynthLight {
    /// `{"constant": [r, g, b]}`.
    Constant([f32; 3]),
    /// `{"environment": "sky.exr", "strength": 1}` with the sky written as an EXR.
    Sky(Sky),
}

/// One frame: camera and objects. Every [`Shape::Sphere`] object is also a blocker.
#[derive(Clone, Debug)]
pub struct SynthFrame {
    pub number: i64,
    pub camera: Camera,
    pub objects: Vec<Object>,
}

impl SynthFrame {
    /// The sphere blockers of this frame.
    pub fn blockers(&self) -> Vec<Sphere> {
        self.objects
            .iter()
            .filter_map(|o| match o.shape {
                Shape::Sphere { center, radius } => Some(Sphere::new(center, radius)),
                _ => None,
            })
            .collect()
    }
}

/// A whole synthetic scene; frame numbers must be consecutive.
#[derive(Clone, Debug)]
pub struct SynthScene {
    pub layout: GBufferLayout,
    pub materials: BTreeMap<u32, Material>,
    pub light: SynthLight,
    /// The terrain and its material: written as `heightmap.exr`, and ray cast as a
    /// [`Shape::Terrain`] in every frame.
    pub terrain: Option<(Arc<HeightMap>, u32)>,
    pub frames: Vec<SynthFrame>,
    /// Colour passes: where given, the G-buffers carry Blender's Diffuse Color and Glossy
    /// Color passes ([`crate::scene::gbuffer`]) of this checker texture over every
    /// material, and scene.json says `colour_passes`.
    pub checker: Option<Checker>,
}

impl SynthScene {
    fn water_materials(&self) -> Vec<u32> {
        self.materials.iter().filter(|(_, m)| matches!(m, Material::Water { .. })).map(|(&i, _)| i).collect()
    }

    /// The G-buffer and (when a material is water) reflection G-buffer of `frame`, as
    /// [`write_scene`] writes them.
    pub fn render_frame(&self, frame: &SynthFrame) -> (GBuffer, Option<GBuffer>) {
        let mut objects = frame.objects.clone();
        if let Some((map, material)) = &self.terrain {
            objects.push(Object { shape: Shape::Terrain(map.clone()), material: *material });
        }
        let mut primary = render_gbuffer(&objects, &frame.camera);
        let water = self.water_materials();
        let mut reflection = (!water.is_empty()).then(|| render_reflection(&objects, &primary, &frame.camera, &water));
        if let Some(checker) = self.checker {
            for g in std::iter::once(&mut primary).chain(reflection.as_mut()) {
                g.colours = Some(checker_colours(g, &self.materials, checker));
            }
        }
        (primary, reflection)
    }
}

/// A checker texture in world X and Y ([`SynthScene::checker`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Checker {
    /// The side of a cell.
    pub cell: f64,
    /// What the odd cells multiply the table's colours by (the even ones by 1).
    pub dark: f32,
}

/// The colour passes of `checker` over `g`: per pixel, the table's albedo and specular
/// colour (a water tint as its glossy colour), times 1 on even cells and `checker.dark`
/// on odd ones; black on the background.
pub fn checker_colours(g: &GBuffer, materials: &BTreeMap<u32, Material>, checker: Checker) -> SurfaceColours {
    let cell = checker.cell;
    let (diffuse, glossy) = (0..g.width * g.height)
        .map(|i| {
            let (albedo, specular) = materials.get(&g.material[i]).map_or(([0.0; 3], [0.0; 3]), Material::pass_colours);
            let p = g.position[i].map(f64::from);
            let odd = ((p[0] / cell).floor() + (p[1] / cell).floor()).rem_euclid(2.0) == 1.0;
            let scale = if odd { checker.dark } else { 1.0 };
            (albedo.map(|c| c * scale), specular.map(|c| c * scale))
        })
        .unzip();
    SurfaceColours { diffuse, glossy }
}

fn material_json(m: &Material) -> serde_json::Value {
    match m {
        Material::Heightfield { albedo } => json!({"type": "heightfield", "albedo": albedo}),
        Material::Water { tint } => json!({"type": "water", "tint": tint}),
        Material::Diffuse { albedo } => json!({"type": "diffuse", "albedo": albedo}),
        Material::Phong { albedo, specular, exponent } => {
            json!({"type": "phong", "albedo": albedo, "specular": specular, "exponent": exponent})
        }
    }
}

fn write_json(path: &Path, value: &serde_json::Value) -> Result<(), SynthError> {
    let text = serde_json::to_string_pretty(value).expect("JSON values serialise") + "\n";
    write_atomically(
        path,
        |temp| std::fs::write(temp, &text),
        |source| OutputError::Io { file: path.to_path_buf(), cause: source },
    )?;
    Ok(())
}

const ZIP: Encoding =
    Encoding { compression: Compression::ZIP16, blocks: Blocks::ScanLines, line_order: LineOrder::Increasing };

fn f32_channel(name: &str, data: Vec<f32>) -> AnyChannel<FlatSamples> {
    AnyChannel::new(name, FlatSamples::F32(data))
}

fn f16_channel(name: &str, data: impl Iterator<Item = f32>) -> AnyChannel<FlatSamples> {
    AnyChannel::new(name, FlatSamples::F16(data.map(f16::from_f32).collect()))
}

/// Writes the layers (part name, channels) as a multi-part file, or, with one unnamed
/// layer, a single-part file.
fn write_exr_layers(
    path: &Path,
    width: usize,
    height: usize,
    layers: Vec<(Option<&str>, Vec<AnyChannel<FlatSamples>>)>,
) -> Result<(), SynthError> {
    let layers: Vec<Layer<AnyChannels<FlatSamples>>> = layers
        .into_iter()
        .map(|(name, channels)| {
            let attributes = match name {
                Some(n) => LayerAttributes::named(Text::new_or_panic(n)),
                None => LayerAttributes::default(),
            };
            Layer::new((width, height), attributes, ZIP, AnyChannels::sort(channels.into_iter().collect()))
        })
        .collect();
    let image = Image::from_layers(ImageAttributes::new(IntegerBounds::from_dimensions((width, height))), layers);
    write_atomically(
        path,
        |temp| image.write().to_file(temp),
        |e| OutputError::Encode { file: path.to_path_buf(), message: e.to_string() },
    )?;
    Ok(())
}

/// Writes a G-buffer in `layout`. The Combined pass is a flat preview (`0.2 + 0.8 n.z`
/// grey on surfaces, black background); nothing reads it.
pub fn write_gbuffer_exr(path: &Path, g: &GBuffer, layout: GBufferLayout) -> Result<(), SynthError> {
    let comp = |k: usize, v: &[[f32; 3]]| v.iter().map(|p| p[k]).collect::<Vec<f32>>();
    let hit: Vec<f32> = g.material.iter().map(|&m| if m == 0 { 0.0 } else { 1.0 }).collect();
    let uv = g.uv.clone().unwrap_or_else(|| vec![[0.0; 2]; g.width * g.height]);
    let shade: Vec<f32> = g.normal.iter().zip(&hit).map(|(n, h)| h * (0.2 + 0.8 * n[2].max(0.0))).collect();
    let index: Vec<f32> = g.material.iter().map(|&m| m as f32).collect();
    let mut passes: Vec<(&str, Vec<AnyChannel<FlatSamples>>)> = vec![
        (
            "ViewLayer.Combined",
            vec![
                f16_channel("ViewLayer.Combined.R", shade.iter().copied()),
                f16_channel("ViewLayer.Combined.G", shade.iter().copied()),
                f16_channel("ViewLayer.Combined.B", shade.iter().copied()),
                f16_channel("ViewLayer.Combined.A", hit.iter().copied()),
            ],
        ),
        (
            "ViewLayer.Position",
            vec![
                f32_channel("ViewLayer.Position.X", comp(0, &g.position)),
                f32_channel("ViewLayer.Position.Y", comp(1, &g.position)),
                f32_channel("ViewLayer.Position.Z", comp(2, &g.position)),
            ],
        ),
        (
            "ViewLayer.Normal",
            vec![
                f32_channel("ViewLayer.Normal.X", comp(0, &g.normal)),
                f32_channel("ViewLayer.Normal.Y", comp(1, &g.normal)),
                f32_channel("ViewLayer.Normal.Z", comp(2, &g.normal)),
            ],
        ),
        (
            "ViewLayer.UV",
            vec![
                f16_channel("ViewLayer.UV.U", uv.iter().map(|p| p[0])),
                f16_channel("ViewLayer.UV.V", uv.iter().map(|p| p[1])),
                f16_channel("ViewLayer.UV.A", hit.iter().copied()),
            ],
        ),
        (
            match layout {
                GBufferLayout::Blender5 => "ViewLayer.Material Index",
                GBufferLayout::Blender4 => "ViewLayer.IndexMA",
            },
            vec![f32_channel(
                match layout {
                    GBufferLayout::Blender5 => MATERIAL_INDEX_BLENDER5,
                    GBufferLayout::Blender4 => MATERIAL_INDEX_BLENDER4,
                },
                index,
            )],
        ),
    ];
    if let Some(colours) = &g.colours {
        let (diffuse, glossy) = match layout {
            GBufferLayout::Blender5 => ("ViewLayer.Diffuse Color", "ViewLayer.Glossy Color"),
            GBufferLayout::Blender4 => ("ViewLayer.DiffCol", "ViewLayer.GlossCol"),
        };
        for (pass, values) in [(diffuse, &colours.diffuse), (glossy, &colours.glossy)] {
            let channel = |k: usize, c: &str| f32_channel(&format!("{pass}.{c}"), comp(k, values));
            passes.push((pass, vec![channel(0, "R"), channel(1, "G"), channel(2, "B")]));
        }
    }
    let layers = match layout {
        GBufferLayout::Blender5 => passes.into_iter().map(|(name, ch)| (Some(name), ch)).collect(),
        GBufferLayout::Blender4 => vec![(None, passes.into_iter().flat_map(|(_, ch)| ch).collect())],
    };
    write_exr_layers(path, g.width, g.height, layers)
}

/// Writes a height map as a one-channel (`Y`, f32) EXR, row 0 at `min.y`.
pub fn write_height_map_exr(path: &Path, map: &HeightMap) -> Result<(), SynthError> {
    write_exr_layers(path, map.columns, map.rows, vec![(None, vec![f32_channel("Y", map.heights.clone())])])
}

/// Writes an RGB f32 environment map (`R`, `G`, `B`), row 0 the zenith.
pub fn write_environment_exr(path: &Path, width: usize, height: usize, texels: &[[f32; 3]]) -> Result<(), SynthError> {
    let c = |k: usize| texels.iter().map(|t| t[k]).collect::<Vec<f32>>();
    write_exr_layers(
        path,
        width,
        height,
        vec![(None, vec![f32_channel("R", c(0)), f32_channel("G", c(1)), f32_channel("B", c(2))])],
    )
}

/// Writes the scene into `out` (created if needed); see the module doc for the files.
pub fn write_scene(out: &Path, scene: &SynthScene) -> Result<(), SynthError> {
    write_scene_supersampled(out, scene, 1)
}

/// [`write_scene`] with `supersample` G-buffer samples per camera pixel along each axis,
/// as the exporter's `--supersample` writes them: the G-buffers ray cast at that multiple
/// of the cameras' resolution, the cameras as they are, `supersample` in scene.json.
pub fn write_scene_supersampled(out: &Path, scene: &SynthScene, supersample: u32) -> Result<(), SynthError> {
    let first = scene.frames.first().ok_or_else(|| SynthError::Invalid("no frames".into()))?;
    for (k, f) in scene.frames.iter().enumerate() {
        if f.number != first.number + k as i64 {
            return Err(SynthError::Invalid("frame numbers must be consecutive".into()));
        }
    }
    std::fs::create_dir_all(out).map_err(|source| SynthError::Io { file: out.to_path_buf(), cause: source })?;
    let water = !scene.water_materials().is_empty();
    let mut description = json!({
        "version": 1,
        "frames": {"start": first.number, "end": scene.frames.last().expect("non-empty").number},
        "gbuffer": "gbuffer.####.exr",
        "camera": "camera.####.json",
        "blockers": "blockers.####.json",
        "materials": scene.materials.iter().map(|(i, m)| (i.to_string(), material_json(m))).collect::<serde_json::Map<_, _>>(),
    });
    if water {
        description["reflection_gbuffer"] = json!("reflection.####.exr");
    }
    if let Some((map, _)) = &scene.terrain {
        write_height_map_exr(&out.join("heightmap.exr"), map)?;
        description["heightfield"] = json!({"heights": "heightmap.exr", "min": map.min, "max": map.max});
    }
    description["light"] = match &scene.light {
        SynthLight::Constant(c) => json!({"constant": c}),
        SynthLight::Sky(sky) => {
            write_environment_exr(&out.join("sky.exr"), sky.width, sky.height, &sky.texels())?;
            json!({"environment": "sky.exr", "strength": 1.0})
        }
    };
    if supersample > 1 {
        description["supersample"] = json!(supersample);
    }
    if scene.checker.is_some() {
        description["colour_passes"] = json!(true);
    }
    for frame in &scene.frames {
        let mut sampled = frame.clone();
        sampled.camera.resolution = frame.camera.resolution.map(|r| r * supersample);
        let (primary, reflection) = scene.render_frame(&sampled);
        let name = |stem: &str, ext: &str| out.join(format!("{stem}.{:04}.{ext}", frame.number));
        write_gbuffer_exr(&name("gbuffer", "exr"), &primary, scene.layout)?;
        if let Some(r) = &reflection {
            write_gbuffer_exr(&name("reflection", "exr"), r, scene.layout)?;
        }
        write_json(&name("camera", "json"), &frame.camera.to_json(frame.number))?;
        write_json(&name("blockers", "json"), &blockers_json(frame.number, &frame.blockers()))?;
    }
    write_json(&out.join(crate::scene::SCENE_FILE), &description)
}

// ---- the analytic test scene ------------------------------------------------------

/// A diffuse plane `z = 0` (material 1, albedo 1) under spheres (material 2), lit by
/// constant white light, seen by a camera above looking down at the origin.
#[derive(Clone, Debug, PartialEq)]
pub struct SphereOverPlane {
    pub spheres: Vec<Sphere>,
    pub width: u32,
    pub height: u32,
    pub layout: GBufferLayout,
    pub camera_position: [f64; 3],
    pub sphere_albedo: [f32; 3],
}

impl Default for SphereOverPlane {
    fn default() -> Self {
        SphereOverPlane {
            spheres: vec![Sphere::new([0.0, 0.0, 2.0], 1.0)],
            width: 320,
            height: 180,
            layout: GBufferLayout::Blender5,
            camera_position: [0.0, -8.0, 10.0],
            sphere_albedo: [0.8, 0.8, 0.8],
        }
    }
}

/// Material index of the plane in [`SphereOverPlane`].
pub const PLANE_MATERIAL: u32 = 1;
/// Material index of the spheres in [`SphereOverPlane`].
pub const SPHERE_MATERIAL: u32 = 2;

impl SphereOverPlane {
    /// The scene as a one-frame [`SynthScene`] (frame 1).
    pub fn scene(&self) -> SynthScene {
        let camera = Camera::look_at(
            self.camera_position,
            [0.0, 0.0, 0.0],
            [0.0, 0.0, 1.0],
            35.0,
            36.0,
            [self.width, self.height],
        );
        let mut objects = vec![Object { shape: Shape::Plane { z: 0.0, bounds: None }, material: PLANE_MATERIAL }];
        objects.extend(self.spheres.iter().map(|s| Object {
            shape: Shape::Sphere { center: s.center, radius: s.radius },
            material: SPHERE_MATERIAL,
        }));
        SynthScene {
            layout: self.layout,
            materials: BTreeMap::from([
                (PLANE_MATERIAL, Material::Diffuse { albedo: [1.0; 3] }),
                (SPHERE_MATERIAL, Material::Diffuse { albedo: self.sphere_albedo }),
            ]),
            light: SynthLight::Constant([1.0; 3]),
            terrain: None,
            frames: vec![SynthFrame { number: 1, camera, objects }],
            checker: None,
        }
    }

    /// Exact shading of a point `p` of the plane (normal +Z, albedo 1, constant white
    /// light, the plane itself blocking the lower hemisphere): `1 - sum_i sin^2(alpha_i)
    /// cos(beta_i)`, `alpha_i = asin(r_i / |c_i - p|)` the cap's angular radius and
    /// `beta_i` the angle between the normal and `c_i - p`. `None` where that formula is
    /// not exact: a cap not entirely above the horizon (`beta + alpha > pi/2`), a point
    /// inside a sphere, or two caps overlapping.
    pub fn expected_at(&self, p: [f64; 3]) -> Option<f64> {
        let mut caps: Vec<([f64; 3], f64)> = Vec::new();
        let mut value = 1.0;
        for s in &self.spheres {
            if s.radius == 0.0 {
                continue;
            }
            let d = [s.center[0] - p[0], s.center[1] - p[1], s.center[2] - p[2]];
            let dist = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            if dist <= s.radius {
                return None;
            }
            let alpha = (s.radius / dist).asin();
            let axis = [d[0] / dist, d[1] / dist, d[2] / dist];
            let beta = axis[2].clamp(-1.0, 1.0).acos();
            if beta + alpha > std::f64::consts::FRAC_PI_2 {
                return None;
            }
            for (other, other_alpha) in &caps {
                let cos = axis[0] * other[0] + axis[1] * other[1] + axis[2] * other[2];
                if cos.clamp(-1.0, 1.0).acos() < alpha + other_alpha {
                    return None;
                }
            }
            caps.push((axis, alpha));
            value -= alpha.sin().powi(2) * beta.cos();
        }
        Some(value)
    }

    /// [`expected_at`](Self::expected_at) for every pixel of `g` that shows the plane;
    /// `None` elsewhere.
    pub fn expected_image(&self, g: &GBuffer) -> Vec<Option<f64>> {
        g.material
            .iter()
            .zip(&g.position)
            .map(|(&m, p)| if m == PLANE_MATERIAL { self.expected_at(p.map(|v| v as f64)) } else { None })
            .collect()
    }
}

/// Writes the analytic sphere-over-plane scene into `out`.
pub fn sphere_over_plane(out: &Path, spec: &SphereOverPlane) -> Result<(), SynthError> {
    write_scene(out, &spec.scene())
}

// ---- named sample scenes ----------------------------------------------------------

/// Names accepted by [`example_scene`].
pub const EXAMPLE_NAMES: &[&str] = &["dunes", "spheres"];

/// Resolution and layout of a sample scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ExampleOptions {
    pub width: u32,
    pub height: u32,
    pub layout: GBufferLayout,
}

impl Default for ExampleOptions {
    fn default() -> Self {
        ExampleOptions { width: 320, height: 180, layout: GBufferLayout::Blender5 }
    }
}

/// Builds a named sample scene (see [`EXAMPLE_NAMES`]).
pub fn example(name: &str, options: ExampleOptions) -> Result<SynthScene, SynthError> {
    match name {
        "dunes" => Ok(dunes(options)),
        "spheres" => Ok(SphereOverPlane {
            width: options.width,
            height: options.height,
            layout: options.layout,
            ..SphereOverPlane::default()
        }
        .scene()),
        other => Err(SynthError::UnknownScene { name: other.to_string() }),
    }
}

/// Writes a named sample scene into `out`.
pub fn example_scene(name: &str, out: &Path, options: ExampleOptions) -> Result<(), SynthError> {
    write_scene(out, &example(name, options)?)
}

/// Height of the dune terrain: wind-aligned ridges with a cross ripple, a basin holding
/// the water, faded to 0 towards the edges of `[-12, 12]^2` so that the flat
/// continuation beyond the map (format v1) is seamless.
pub fn dune_height(x: f64, y: f64) -> f64 {
    let phase = 0.55 * x + 0.45 * (0.35 * y).sin() + 0.15 * y;
    let ridge = 0.5 + 0.5 * phase.sin();
    let dunes = 1.1 * ridge * ridge + 0.12 * (1.7 * y + 0.6 * x).sin();
    let basin = -1.4 * (-((x - 3.5).powi(2) + (y + 2.5).powi(2)) / (2.0 * 1.7f64.powi(2))).exp();
    let fade = |t: f64| {
        let s = ((12.0 - t.abs()) / 3.0).clamp(0.0, 1.0);
        s * s * (3.0 - 2.0 * s)
    };
    (dunes + basin) * fade(x) * fade(y)
}

fn dunes(options: ExampleOptions) -> SynthScene {
    let map = Arc::new(HeightMap::from_fn(161, 161, [-12.0, -12.0], [12.0, 12.0], dune_height));
    let (sand, water, grey, glossy, red) = (1, 2, 3, 4, 5);
    let materials = BTreeMap::from([
        (sand, Material::Heightfield { albedo: [0.8, 0.7, 0.5] }),
        (water, Material::Water { tint: [0.6, 0.8, 0.9] }),
        (grey, Material::Diffuse { albedo: [0.8, 0.8, 0.8] }),
        (glossy, Material::Phong { albedo: [0.2, 0.2, 0.2], specular: [0.9, 0.9, 0.9], exponent: 16.0 }),
        (red, Material::Diffuse { albedo: [0.7, 0.2, 0.15] }),
    ]);
    let resting = |x: f64, y: f64, r: f64| Shape::Sphere { center: [x, y, map.height_at(x, y) + 0.85 * r], radius: r };
    let camera = Camera::look_at(
        [0.0, -16.0, 5.0],
        [0.0, 0.0, 0.5],
        [0.0, 0.0, 1.0],
        24.0,
        36.0,
        [options.width, options.height],
    );
    let frames = (0..2)
        .map(|k| {
            let mover_x = -3.5 + 1.0 * k as f64;
            SynthFrame {
                number: 1 + k,
                camera: camera.clone(),
                objects: vec![
                    Object {
                        shape: Shape::Plane { z: -0.45, bounds: Some(([1.0, -5.5], [6.5, 0.5])) },
                        material: water,
                    },
                    Object { shape: resting(mover_x, 1.0, 1.0), material: red },
                    Object { shape: resting(0.5, 3.5, 0.8), material: grey },
                    Object { shape: resting(-1.5, -3.0, 0.6), material: grey },
                    Object { shape: resting(4.0, 3.5, 1.2), material: glossy },
                ],
            }
        })
        .collect();
    SynthScene {
        layout: options.layout,
        materials,
        light: SynthLight::Sky(Sky::default()),
        terrain: Some((map.clone(), sand)),
        frames,
        checker: None,
    }
}

/// Sphere placements of the analytic accuracy checks (`tests/shading.rs`,
/// `examples/sphere_accuracy.rs`): single spheres from close to the plane to small and
/// high, a large offset one, and a pair whose shadows do not overlap.
pub fn analytic_placements() -> Vec<Vec<Sphere>> {
    let s = |center: [f64; 3], radius: f64| Sphere::new(center, radius);
    vec![
        vec![s([0.0, 0.0, 2.0], 1.0)],
        vec![s([0.0, 0.0, 1.3], 1.0)],
        vec![s([1.0, 0.5, 3.0], 1.5)],
        vec![s([0.0, 0.0, 4.0], 0.7)],
        vec![s([-1.5, 0.0, 1.5], 0.6), s([1.5, 0.5, 2.0], 0.9)],
    ]
}
