//! A whole frame shaded into compositing passes (`logsh render`): the same pixels as
//! [`shade_frame`](super::shade_frame), split so that a compositor can rebuild the beauty
//! and grade each part (docs/design.md, "Compositing passes").
//!
//! Per pixel, `beauty = diffuse + specular + environment + indirect`, summed in f32 in that
//! order:
//! - `diffuse`, `specular`: [`PixelPasses`] of the surface times its [`Tint`] (the colour
//!   passes, where the G-buffer has them); for water, of the point in the reflection
//!   G-buffer times the tint (water reflecting the sky puts `tint * sky` in `specular`, a
//!   mirror reflection);
//! - `environment`: the light seen directly on background pixels (the camera's ray
//!   direction; black without a camera), 0 elsewhere;
//! - `indirect`: bounce light ([`super::bounce`]), `indirect_heightfield` (the terrain:
//!   height field or ground plane) plus `indirect_blockers` (the sphere blockers); 0
//!   without bounces, on water and on the background.
//!
//! The beauty equals `shade_frame`'s image exactly except on water pixels, where
//! `tint * (d + s)` and `tint * d + tint * s` can differ in the last bit.
//! Visibility terms are 1 on the background and, for water, those of the reflected point.

use super::frame::Tint;
use super::kernel::PixelPasses;
use crate::scene::Frame;

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
    /// Bounce light, the sum of the two below.
    pub indirect: Vec<[f32; 3]>,
    pub indirect_heightfield: Vec<[f32; 3]>,
    pub indirect_blockers: Vec<[f32; 3]>,
    /// Height field and blockers together ([`PixelPasses::visibility`]).
    pub visibility: Vec<f32>,
    pub visibility_heightfield: Vec<f32>,
    pub visibility_blockers: Vec<f32>,
    /// World position and normal of the G-buffer, passed through unchanged (shared, so
    /// that a relight passes a frame's through without copying them).
    pub position: std::sync::Arc<[[f32; 3]]>,
    pub normal: std::sync::Arc<[[f32; 3]]>,
}

/// One pixel of [`ShadedPasses`], as either executor produces it.
#[derive(Clone, Copy)]
pub struct Pixel {
    passes: PixelPasses,
    environment: [f32; 3],
    alpha: f32,
}

impl Pixel {
    /// A pixel of fixed colour ([`PixelWork::Fixed`](super::PixelWork::Fixed)): the background is the environment
    /// pass, water mirroring the sky is specular.
    pub fn fixed(colour: [f32; 4]) -> Self {
        let rgb = [colour[0], colour[1], colour[2]];
        if colour[3] == 0.0 {
            Pixel { passes: PixelPasses::UNSHADED, environment: rgb, alpha: 0.0 }
        } else {
            Pixel { passes: PixelPasses { specular: rgb, ..PixelPasses::UNSHADED }, environment: [0.0; 3], alpha: 1.0 }
        }
    }

    /// A shaded point's passes times its tint ([`PixelWork::Shade`](super::PixelWork::Shade)); the visibility
    /// terms are the point's own.
    pub fn shaded(seen: PixelPasses, tint: Tint) -> Self {
        let (diffuse, specular) = tint.apply(seen.diffuse, seen.specular);
        let passes = PixelPasses { diffuse, specular, ..seen };
        Pixel { passes, environment: [0.0; 3], alpha: 1.0 }
    }
}

/// The passes of a frame from its pixels, row-major from the top row.
pub fn assemble(frame: &Frame, pixels: &[Pixel]) -> ShadedPasses {
    let g = &frame.gbuffer;
    let scalar = |f: fn(&PixelPasses) -> f32| pixels.iter().map(|p| f(&p.passes)).collect::<Vec<f32>>();
    ShadedPasses {
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
        indirect: vec![[0.0; 3]; pixels.len()],
        indirect_heightfield: vec![[0.0; 3]; pixels.len()],
        indirect_blockers: vec![[0.0; 3]; pixels.len()],
        visibility: scalar(|q| q.visibility),
        visibility_heightfield: scalar(|q| q.visibility_heightfield),
        visibility_blockers: scalar(|q| q.visibility_blockers),
        position: g.position.as_slice().into(),
        normal: g.normal.as_slice().into(),
    }
}

impl ShadedPasses {
    /// Sets the bounce passes from their two parts and adds their sum to the beauty.
    pub fn add_indirect(&mut self, parts: super::bounce::IndirectParts) {
        self.indirect = parts.total();
        let super::bounce::IndirectParts { heightfield, blockers } = parts;
        for (beauty, indirect) in self.beauty.iter_mut().zip(&self.indirect) {
            for c in 0..3 {
                beauty[c] += indirect[c];
            }
        }
        self.indirect_heightfield = heightfield;
        self.indirect_blockers = blockers;
    }
}
