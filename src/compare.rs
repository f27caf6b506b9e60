//! The measure every comparison with Cycles uses (`examples/cycles_compare.rs`,
//! `examples/cycles_timing.rs`, the tables of docs/accuracy.md): mean absolute error over the
//! non-background pixels and over R, G, B, divided by the unoccluded value, the radiance an
//! open, upward-facing white diffuse floor receives from the scene's light, suns and lamps,
//! so that 0.01 reads as 1 % of an unshadowed white floor whatever the light's brightness.
//! Albedo is not divided out: both renders carry the same albedo, and dividing would blow
//! up dark materials and mix the diffuse and specular parts of Phong pixels.

use crate::scene::{Frame, Light, SceneError};
use exr::prelude::read_first_rgba_layer_from_file;
use std::f64::consts::PI;
use std::path::Path;

/// `(1/pi) * integral of L max(w.z, 0)` for the frame's light and suns (each sun's
/// irradiance times the cosine at its centre, exact to 2e-5 for a disk a degree wide),
/// plus each point lamp's share of the same floor averaged over the frame's
/// non-background pixels, each pixel's position taken as the floor's. `None` for an `sh`
/// light, which has no map to integrate.
pub fn unoccluded_value(frame: &Frame) -> Option<[f64; 3]> {
    let mut sum = match frame.light.as_ref() {
        Light::Constant(c) => c.map(f64::from),
        Light::Environment { map, strength } => {
            let mut sum = [0.0; 3];
            for row in 0..map.height {
                let v = 1.0 - (row as f64 + 0.5) / map.height as f64;
                let cos_theta = (PI * (1.0 - v)).cos();
                if cos_theta <= 0.0 {
                    continue;
                }
                let weight = cos_theta * map.texel_solid_angle(row) / PI * f64::from(*strength);
                for column in 0..map.width {
                    let t = map.texels[row * map.width + column];
                    for k in 0..3 {
                        sum[k] += weight * f64::from(t[k]);
                    }
                }
            }
            sum
        }
        Light::Sh(_) => return None,
    };
    for sun in &frame.suns {
        let power = sun.disk_integral();
        for k in 0..3 {
            sum[k] += power[k] * sun.direction[2].max(0.0) / PI;
        }
    }
    let g = &frame.gbuffer;
    let floors: Vec<[f64; 3]> =
        (0..g.material.len()).filter(|&i| g.material[i] != 0).map(|i| g.position[i].map(f64::from)).collect();
    for lamp in &frame.points {
        for p in &floors {
            let (disk, _) = lamp.seen_from(*p, [0.0, 0.0, 1.0]);
            let power = disk.disk_integral();
            for k in 0..3 {
                sum[k] += power[k] * disk.direction[2].max(0.0) / PI / floors.len() as f64;
            }
        }
    }
    Some(sum)
}

/// The first RGBA layer of an EXR as RGB: width, height and pixels, row-major from the
/// top row.
pub fn read_rgb(path: &Path) -> Result<(usize, usize, Vec<[f32; 3]>), SceneError> {
    let image = read_first_rgba_layer_from_file(
        path,
        |size, _| (size.width(), vec![[0.0f32; 3]; size.width() * size.height()]),
        |(width, pixels), position, (r, g, b, _a): (f32, f32, f32, f32)| {
            pixels[position.y() * *width + position.x()] = [r, g, b];
        },
    )
    .map_err(|e| crate::scene::error::exr_error(path, "the image", e))?;
    let size = image.layer_data.size;
    Ok((size.width(), size.height(), image.layer_data.channel_data.pixels.1))
}

/// One image against the truth over a frame's non-background pixels.
#[derive(Clone, Debug)]
pub struct FrameError {
    pub pixels: usize,
    /// Mean over the pixels of the mean over R, G, B of `|image - truth| / unoccluded`.
    pub mean: f64,
    /// 95th percentile of the per-pixel errors.
    pub p95: f64,
    /// Mean signed difference (positive: the image is brighter).
    pub signed: f64,
    /// Per-pixel errors, in the order of the frame's non-background pixels.
    pub per_pixel: Vec<f64>,
}

/// `image` against `truth` (both row-major RGB of the frame's size) over the pixels
/// whose material is not 0.
pub fn frame_error(material: &[u32], image: &[[f32; 3]], truth: &[[f32; 3]], unoccluded: [f64; 3]) -> FrameError {
    let mut per_pixel = Vec::new();
    let mut signed = 0.0;
    for (i, &m) in material.iter().enumerate() {
        if m == 0 {
            continue;
        }
        let mut e = 0.0;
        for k in 0..3 {
            let d = (f64::from(image[i][k]) - f64::from(truth[i][k])) / unoccluded[k];
            e += d.abs() / 3.0;
            signed += d / 3.0;
        }
        per_pixel.push(e);
    }
    let pixels = per_pixel.len();
    let count = pixels.max(1) as f64;
    let mean = per_pixel.iter().sum::<f64>() / count;
    let mut sorted = per_pixel.clone();
    sorted.sort_by(|a, b| a.total_cmp(b));
    let p95 = sorted.get((0.95 * pixels.saturating_sub(1) as f64).round() as usize).copied().unwrap_or(0.0);
    FrameError { pixels, mean, p95, signed: signed / count, per_pixel }
}
