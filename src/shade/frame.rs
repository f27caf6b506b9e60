//! The frame walk both executors share: what a frame must satisfy before it is shaded,
//! and what each pixel is (the background from the light, water through the reflection
//! G-buffer, or a surface point to shade).

use super::point::SurfacePoint;
use super::settings::SettingsError;
use crate::heightfield::{HeightField, HeightFieldError};
use crate::scene::{Frame, GBuffer, Material, Scene, SceneError};
use std::collections::BTreeMap;

/// A shaded frame: linear RGBA, row-major from the top row. Alpha is 1 where a surface
/// was shaded and 0 on the background.
#[derive(Clone, Debug)]
pub struct ShadedFrame {
    pub width: usize,
    pub height: usize,
    pub rgba: Vec<[f32; 4]>,
}

#[derive(Debug, thiserror::Error)]
pub enum ShadeError {
    #[error(transparent)]
    Settings(#[from] SettingsError),
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error("height field of {file}: {cause}")]
    HeightField { file: String, cause: HeightFieldError },
    #[error(
        "{file}: {count} pixel(s) have water materials but scene.json has no \"reflection_gbuffer\" to shade them with"
    )]
    WaterWithoutReflection { file: String, count: usize },
    #[error("{file}: material {material} is phong but scene.json has no \"camera\" to take the view direction from")]
    PhongWithoutCamera { file: String, material: u32 },
    #[error(
        "{file}: pixel ({x}, {y}) reflects material {material}, which is water; water seen in water is not supported"
    )]
    WaterInWater { file: String, x: usize, y: usize, material: u32 },
}

impl ShadeError {
    /// A height field of `scene` refused by the height-field module.
    pub fn height_field(scene: &Scene, cause: HeightFieldError) -> Self {
        Self::HeightField { file: height_map_file(scene), cause }
    }
}

/// The name of the scene's height map, for messages.
fn height_map_file(scene: &Scene) -> String {
    scene.heightfield.as_ref().map(|h| h.heights.0.clone()).unwrap_or_default()
}

/// The frame's height field, validated, if the scene has one (the fast path builds its
/// pyramid on it, the reference its exact horizons).
pub fn height_field(scene: &Scene, frame: &Frame) -> Result<Option<HeightField>, ShadeError> {
    frame
        .height_map
        .as_ref()
        .map(|map| {
            HeightField::new(map.heights.clone(), map.columns, map.rows, map.min, map.max)
                .map_err(|cause| ShadeError::height_field(scene, cause))
        })
        .transpose()
}

/// What the materials present in the frame need from the scene: the checks every
/// shading of a frame (fast path and reference) makes first.
pub fn check_frame(scene: &Scene, frame: &Frame) -> Result<(), ShadeError> {
    let g = &frame.gbuffer;
    let file = g.file.display().to_string();
    // The pixels are looked up only for a kind of material the scene has: a relight's turn
    // of its Sun lamps checks its frame at each turn, and a lookup per pixel took 0.1 to
    // 0.3 ms of each turn of the Sun-lamp scene's lamps (320x180, no water).
    let has = |kind: fn(&Material) -> bool| scene.materials.values().any(kind);
    let (water, phong) = (has(|m| matches!(m, Material::Water { .. })), has(|m| matches!(m, Material::Phong { .. })));
    let water_pixels = if water {
        g.material.iter().filter(|&&m| matches!(scene.materials.get(&m), Some(Material::Water { .. }))).count()
    } else {
        0
    };
    if water_pixels > 0 && frame.reflection.is_none() {
        return Err(ShadeError::WaterWithoutReflection { file, count: water_pixels });
    }
    if frame.camera.is_none() && phong {
        let seen = g.material.iter().chain(frame.reflection.iter().flat_map(|r| r.material.iter()));
        for &m in seen {
            if matches!(scene.materials.get(&m), Some(Material::Phong { .. })) {
                return Err(ShadeError::PhongWithoutCamera { file, material: m });
            }
        }
    }
    if let Some(reflection) = frame.reflection.as_ref().filter(|_| water) {
        for (i, &m) in reflection.material.iter().enumerate() {
            let is_water_pixel = matches!(scene.materials.get(&g.material[i]), Some(Material::Water { .. }));
            if is_water_pixel && matches!(scene.materials.get(&m), Some(Material::Water { .. })) {
                let file = reflection.file.display().to_string();
                return Err(ShadeError::WaterInWater { file, x: i % g.width, y: i / g.width, material: m });
            }
        }
    }
    Ok(())
}

/// The unit normal of a G-buffer normal, or +Z where it is degenerate.
pub fn unit_or_up(n: [f32; 3]) -> [f64; 3] {
    let n = n.map(f64::from);
    let length = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    if length > 1e-12 {
        n.map(|c| c / length)
    } else {
        [0.0, 0.0, 1.0]
    }
}

/// The eye position, or a point far along the normal when the scene has no camera (only
/// diffuse shading is possible then, and it ignores the eye).
fn eye(frame: &Frame, p: [f64; 3], n: [f64; 3]) -> [f64; 3] {
    match &frame.camera {
        Some(camera) => camera.position,
        None => [p[0] + n[0], p[1] + n[1], p[2] + n[2]],
    }
}

/// Pixel `i` of `buffer` as a point to shade, seen from `view_origin` (the frame's eye when
/// `None`).
pub fn surface_at(buffer: &GBuffer, i: usize, view_origin: Option<[f64; 3]>, frame: &Frame) -> SurfacePoint {
    let position = buffer.position[i].map(f64::from);
    let normal = unit_or_up(buffer.normal[i]);
    SurfacePoint {
        position,
        normal,
        view_origin: view_origin.unwrap_or_else(|| eye(frame, position, normal)),
        material: buffer.material[i],
        object: buffer.object_at(i),
    }
}

/// The Sun lamps' radiance along `mirror`: each disk's radiance where the direction falls
/// inside it.
pub fn mirrored_suns(frame: &Frame, mirror: [f64; 3]) -> [f32; 3] {
    suns_along(&frame.suns, mirror)
}

/// The radiance of those of `suns` whose disk holds the direction `mirror` (what
/// [`mirrored_suns`] reads for a frame's Sun lamps).
pub fn suns_along(suns: &[crate::scene::SunLight], mirror: [f64; 3]) -> [f32; 3] {
    let mut out = [0.0f32; 3];
    let dir = crate::vector::normalize(mirror);
    for sun in suns {
        if crate::vector::dot(dir, sun.direction) >= sun.half_angle.cos() {
            let radiance = sun.strength / (std::f64::consts::PI * sun.half_angle.sin().powi(2)) as f32;
            for (o, c) in out.iter_mut().zip(sun.color) {
                *o += radiance * c;
            }
        }
    }
    out
}

/// The radiance of the nearest point lamp that the mirror ray from `origin` along
/// `mirror` meets before the surface of the reflection G-buffer's pixel `i`, if any.
pub fn mirrored_lamp(
    frame: &Frame,
    origin: [f64; 3],
    mirror: [f64; 3],
    reflection: &GBuffer,
    i: usize,
) -> Option<[f32; 3]> {
    let dir = crate::vector::normalize(mirror);
    let surface = (reflection.material[i] != 0).then(|| {
        let p = reflection.position[i].map(f64::from);
        (0..3).map(|k| (p[k] - origin[k]).powi(2)).sum::<f64>().sqrt()
    });
    frame
        .points
        .iter()
        .filter_map(|lamp| lamp.hit_along(origin, dir).map(|t| (t, lamp)))
        .filter(|(t, _)| surface.is_none_or(|s| *t < s))
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, lamp)| lamp.radiance())
}

/// What a shaded point's diffuse and specular passes are multiplied by: white, but for
/// water (its tint, with the reflected point's own colours where the kernel shades it
/// white) and where the G-buffer carries Blender's colour passes (the pixel's Diffuse
/// Color and Glossy Color, the kernel's materials then white:
/// [`Scene::kernel_materials`](crate::scene::Scene::kernel_materials)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tint {
    pub diffuse: [f32; 3],
    pub specular: [f32; 3],
}

impl Tint {
    pub const WHITE: Tint = Tint { diffuse: [1.0; 3], specular: [1.0; 3] };

    /// This tint times `colour` on both passes.
    pub fn times(self, colour: [f32; 3]) -> Self {
        let times = |c: [f32; 3]| [0, 1, 2].map(|k| c[k] * colour[k]);
        Tint { diffuse: times(self.diffuse), specular: times(self.specular) }
    }

    /// `diffuse` and `specular` tinted.
    pub fn apply(&self, diffuse: [f32; 3], specular: [f32; 3]) -> ([f32; 3], [f32; 3]) {
        let tinted = |t: [f32; 3], c: [f32; 3]| [0, 1, 2].map(|k| t[k] * c[k]);
        (tinted(self.diffuse, diffuse), tinted(self.specular, specular))
    }

    /// The tinted sum `diffuse + specular` as RGBA with alpha 1: where both passes take
    /// the same colour, that colour times the sum (the bits of a tint of one colour).
    pub fn beauty(&self, diffuse: [f32; 3], specular: [f32; 3]) -> [f32; 4] {
        if self.diffuse == self.specular {
            let t = self.diffuse;
            [
                t[0] * (diffuse[0] + specular[0]),
                t[1] * (diffuse[1] + specular[1]),
                t[2] * (diffuse[2] + specular[2]),
                1.0,
            ]
        } else {
            let (d, s) = self.apply(diffuse, specular);
            [d[0] + s[0], d[1] + s[1], d[2] + s[2], 1.0]
        }
    }
}

/// What one pixel needs from an executor.
#[derive(Clone, Copy, Debug)]
pub enum PixelWork {
    /// A colour known without shading: the background (alpha 0), or water mirroring the
    /// sky (alpha 1).
    Fixed([f32; 4]),
    /// A point to shade, its passes multiplied by `tint`, alpha 1.
    Shade { point: SurfacePoint, tint: Tint },
}

impl PixelWork {
    /// The points to shade among `work` (a row's pixels), in their order.
    pub fn points(work: &[PixelWork]) -> Vec<SurfacePoint> {
        work.iter()
            .filter_map(|w| match w {
                PixelWork::Shade { point, .. } => Some(*point),
                PixelWork::Fixed(_) => None,
            })
            .collect()
    }
}

/// Where a pixel's colour comes from: the frame walk shared by the CPU and GPU executors
/// and the transfer layers ([`crate::transfer`]).
#[derive(Clone, Copy, Debug)]
pub enum PixelSource {
    /// The background: the light along the camera ray (`None`: no camera, black).
    Background { ray: Option<[f64; 3]> },
    /// Water mirroring the sky along `mirror`: `tint` times the light and the scene's Sun
    /// lamps there.
    WaterSky { tint: [f32; 3], mirror: [f64; 3] },
    /// Water whose mirror ray meets a point lamp first: `tint` times its radiance.
    WaterLamp { tint: [f32; 3], radiance: [f32; 3] },
    /// A point to shade, its passes times `tint`.
    Surface { point: SurfacePoint, tint: Tint },
}

/// Background from the light along the camera ray, water through the reflection
/// G-buffer (the reflected point shaded as seen from the water surface, or the sky and
/// the Sun lamps in the mirror direction, or a point lamp the mirror ray meets first),
/// every other pixel its own surface point.
///
/// Where the G-buffer carries colour passes, a surface takes its pixel's Diffuse Color
/// and Glossy Color as its tint, and water its Glossy Color (the Fresnel reflectance at
/// its view angle) in place of its tint; a reflected point takes the reflection
/// G-buffer's colours where it has them, else its material's in the table.
pub fn pixel_source(materials: &BTreeMap<u32, Material>, frame: &Frame, x: usize, y: usize) -> PixelSource {
    let g = &frame.gbuffer;
    let i = g.index(x, y);
    let own_colours = g.colours_at(i);
    match g.material[i] {
        0 => PixelSource::Background {
            ray: frame
                .camera
                .as_ref()
                .map(|camera| camera.ray_direction(x as f64 + 0.5, (g.first_row + y) as f64 + 0.5)),
        },
        m => match materials.get(&m) {
            Some(Material::Water { tint }) => {
                let tint = own_colours.map_or(*tint, |(_, glossy)| glossy);
                let reflection = frame.reflection.as_ref().expect("checked before shading");
                let water = surface_at(g, i, None, frame);
                let mirror = super::point::reflect_view(water.view_origin, water.position, water.normal);
                // A lamp the mirror ray meets before the reflected surface (Cycles shows
                // lamps to glossy rays): the pixel is its radiance.
                if let Some(radiance) = mirrored_lamp(frame, water.position, mirror, reflection, i) {
                    return PixelSource::WaterLamp { tint, radiance };
                }
                if reflection.material[i] == 0 {
                    PixelSource::WaterSky { tint, mirror }
                } else {
                    // The kernel shades white where the colours come from the passes.
                    let seen = match (reflection.colours_at(i), own_colours) {
                        (Some((diffuse, glossy)), _) => Tint { diffuse, specular: glossy },
                        (None, Some(_)) => materials.get(&reflection.material[i]).map_or(Tint::WHITE, |m| {
                            let (diffuse, specular) = m.pass_colours();
                            Tint { diffuse, specular }
                        }),
                        (None, None) => Tint::WHITE,
                    };
                    let point = surface_at(reflection, i, Some(water.position), frame);
                    PixelSource::Surface { point, tint: seen.times(tint) }
                }
            }
            _ => {
                let tint = own_colours.map_or(Tint::WHITE, |(diffuse, glossy)| Tint { diffuse, specular: glossy });
                PixelSource::Surface { point: surface_at(g, i, None, frame), tint }
            }
        },
    }
}

/// What pixel `(x, y)` needs from an executor ([`pixel_source`]).
pub fn pixel_work(materials: &BTreeMap<u32, Material>, frame: &Frame, x: usize, y: usize) -> PixelWork {
    work_of(frame, pixel_source(materials, frame, x, y))
}

/// What a pixel of `source` needs from an executor.
pub fn work_of(frame: &Frame, source: PixelSource) -> PixelWork {
    let tinted = |tint: [f32; 3], c: [f32; 3]| [tint[0] * c[0], tint[1] * c[1], tint[2] * c[2], 1.0];
    match source {
        PixelSource::Background { ray } => {
            let sky = ray.map_or([0.0; 3], |d| frame.light.radiance(d));
            PixelWork::Fixed([sky[0], sky[1], sky[2], 0.0])
        }
        PixelSource::WaterLamp { tint, radiance } => PixelWork::Fixed(tinted(tint, radiance)),
        PixelSource::WaterSky { tint, mirror } => {
            let mut sky = frame.light.radiance(mirror);
            // The scene's Sun lamps, which the map does not hold, are mirrored too.
            for (s, sun) in sky.iter_mut().zip(mirrored_suns(frame, mirror)) {
                *s += sun;
            }
            PixelWork::Fixed(tinted(tint, sky))
        }
        PixelSource::Surface { point, tint } => PixelWork::Shade { point, tint },
    }
}
