//! A whole frame shaded into compositing passes (`logsh render`): the same pixels as
//! [`shade_frame`](super::shade_frame), split so that a compositor can rebuild the beauty
//! and grade each part (docs/design.md, "Compositing passes").
//!
//! Per pixel, `beauty = diffuse + specular + environment`, summed in f32 in that order:
//! - `diffuse`, `specular`: [`PixelPasses`] of the surface; for water, of the point in the
//!   reflection G-buffer times the tint (water reflecting the sky puts `tint * sky` in
//!   `specular`, a mirror reflection);
//! - `environment`: the light seen directly on background pixels (the camera's ray
//!   direction; black without a camera), 0 elsewhere.
//!
//! The beauty equals `shade_frame`'s image exactly except on water pixels, where
//! `tint * (d + s)` and `tint * d + tint * s` can differ in the last bit.
//! Visibility terms are 1 on the background and, for water, those of the reflected point.

use super::frame::{check_frame, pixel_work, pyramid, PixelWork, ShadeError};
use super::kernel::{Occluders, PixelPasses, ShadingKernel};
use super::settings::ShadingSettings;
use crate::scene::{Frame, Scene};
use crate::sh::Real;
use rayon::prelude::*;

/// A shaded frame by pass, row-major from the top row; every vector has `width * height`
/// entries.
#[derive(Clone, Debug)]
pub struct ShadedPasses {
    pub width: usize,
    pub height: usize,
    /// Linear RGB, alpha 1 where a surface was shaded and 0 on the background.
    pub beauty: Vec<[f32; 4]>,
    pub diffuse: Vec<[f32; 3]>,
    pub specular: Vec<[f32; 3]>,
    pub environment: Vec<[f32; 3]>,
    /// Height field and blockers together ([`PixelPasses::visibility`]).
    pub visibility: Vec<f32>,
    pub visibility_heightfield: Vec<f32>,
    pub visibility_blockers: Vec<f32>,
    /// World position and normal of the G-buffer, passed through unchanged.
    pub position: Vec<[f32; 3]>,
    pub normal: Vec<[f32; 3]>,
}

/// One pixel of [`ShadedPasses`].
#[derive(Clone, Copy)]
struct Pixel {
    passes: PixelPasses,
    environment: [f32; 3],
    alpha: f32,
}

/// Shades one frame of `scene` into passes; the checks and errors are `shade_frame`'s.
pub fn shade_frame_passes(scene: &Scene, frame: &Frame, settings: &ShadingSettings) -> Result<ShadedPasses, ShadeError> {
    settings.validate().map_err(ShadeError::Settings)?;
    check_frame(scene, frame)?;
    let pyramid = pyramid(scene, frame, settings)?;
    let light = frame.light.sh_coefficients(settings.order);
    let occluders = Occluders { blockers: &frame.blockers, horizons: pyramid.as_ref() };
    let pixels = if settings.double_precision {
        let kernel = ShadingKernel::<f64>::new(settings, &scene.materials, &light, pyramid.is_some());
        shade_pixels(&kernel, occluders, frame)
    } else {
        let kernel = ShadingKernel::<f32>::new(settings, &scene.materials, &light, pyramid.is_some());
        shade_pixels(&kernel, occluders, frame)
    };
    let g = &frame.gbuffer;
    let scalar = |f: fn(&PixelPasses) -> f32| pixels.iter().map(|p| f(&p.passes)).collect::<Vec<f32>>();
    Ok(ShadedPasses {
        width: g.width,
        height: g.height,
        beauty: pixels
            .iter()
            .map(|p| {
                let (d, s, e) = (p.passes.diffuse, p.passes.specular, p.environment);
                [d[0] + s[0] + e[0], d[1] + s[1] + e[1], d[2] + s[2] + e[2], p.alpha]
            })
            .collect(),
        diffuse: pixels.iter().map(|p| p.passes.diffuse).collect(),
        specular: pixels.iter().map(|p| p.passes.specular).collect(),
        environment: pixels.iter().map(|p| p.environment).collect(),
        visibility: scalar(|q| q.visibility),
        visibility_heightfield: scalar(|q| q.visibility_heightfield),
        visibility_blockers: scalar(|q| q.visibility_blockers),
        position: g.position.clone(),
        normal: g.normal.clone(),
    })
}

fn shade_pixels<T: Real>(kernel: &ShadingKernel<T>, occluders: Occluders, frame: &Frame) -> Vec<Pixel> {
    let width = frame.gbuffer.width;
    let blank = Pixel { passes: PixelPasses::UNSHADED, environment: [0.0; 3], alpha: 0.0 };
    let mut pixels = vec![blank; width * frame.gbuffer.height];
    pixels.par_chunks_mut(width).enumerate().for_each(|(y, row)| {
        for (x, out) in row.iter_mut().enumerate() {
            *out = shade_pixel(kernel, occluders, frame, x, y);
        }
    });
    pixels
}

/// The pixel `shade_frame` computes, by pass (its `shade_pixel`, branch for branch).
fn shade_pixel<T: Real>(kernel: &ShadingKernel<T>, occluders: Occluders, frame: &Frame, x: usize, y: usize) -> Pixel {
    match pixel_work(kernel.materials(), frame, x, y) {
        // The background is the environment pass; water mirroring the sky is specular.
        PixelWork::Fixed(colour) => {
            let rgb = [colour[0], colour[1], colour[2]];
            if colour[3] == 0.0 {
                Pixel { passes: PixelPasses::UNSHADED, environment: rgb, alpha: 0.0 }
            } else {
                Pixel { passes: PixelPasses { specular: rgb, ..PixelPasses::UNSHADED }, environment: [0.0; 3], alpha: 1.0 }
            }
        }
        PixelWork::Shade { point, tint } => {
            let seen = kernel.shade_passes(occluders, &point);
            let tinted = |c: [f32; 3]| [0, 1, 2].map(|k| tint[k] * c[k]);
            let passes = PixelPasses { diffuse: tinted(seen.diffuse), specular: tinted(seen.specular), ..seen };
            Pixel { passes, environment: [0.0; 3], alpha: 1.0 }
        }
    }
}
