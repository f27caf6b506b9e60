//! Adaptive shading of a supersampled frame: every sample is shaded only where a pixel's
//! samples differ (material, object, normal or depth: an edge); a pixel whose samples
//! agree is shaded once, at the mean of its samples' positions and normals (the pixel's
//! centre, on the surface they share), and that result stands for all of them. A shadow
//! or highlight edge across a surface is not a geometric edge: its pixels are shaded once,
//! as a point-sampled frame shades them.
//!
//! The samples to shade are packed into a compact frame of their own (surface samples
//! only, row after row of a near-square G-buffer, the reflection G-buffer packed
//! alike), which either executor shades as it shades any frame: the camera only gives the
//! eye's position to surface points, so nothing depends on where a sample sits in the
//! packed frame. Background samples are the light along their own camera rays, computed
//! here. The results are then scattered back to every sample, and the frame resolved as
//! any supersampled frame ([`super::resolve`]).

use super::compositing::ShadedPasses;
use super::frame::{pixel_work, unit_or_up, PixelWork};
use crate::scene::gbuffer::SurfaceColours;
use crate::scene::{Frame, GBuffer, Material};
use std::collections::BTreeMap;

/// Largest angle between a pixel's sample normals for them to agree: cos 8 degrees. Below
/// it, log-SH visibility (order 8 at most) and the diffuse lobe change by under 1 %.
const NORMALS_AGREE: f32 = 0.990;

/// Largest distance of a pixel's samples from the tangent plane of its centre sample,
/// relative to that sample's distance from the eye, for them to agree: a depth edge (an
/// object in front of another of the same material) is far off the plane, a smooth
/// surface seen at a grazing angle on it.
const DEPTHS_AGREE: f32 = 0.01;

/// Which samples of a supersampled frame are shaded, and which result each one takes.
pub struct Selection {
    /// The packed frame of the samples to shade.
    pub packed: Frame,
    /// Per sample of the frame (row-major): the packed sample it takes, or `None` for the
    /// background.
    source: Vec<Option<u32>>,
    /// How many samples are shaded, and how many the frame has.
    pub shaded: usize,
    pub samples: usize,
}

/// Whether the samples `block` (indices into `g`) agree (module doc).
fn agree(g: &GBuffer, reflection: Option<&GBuffer>, eye: [f32; 3], block: &[usize], centre: usize) -> bool {
    let material = g.material[centre];
    let distance = |p: [f32; 3]| ((p[0] - eye[0]).powi(2) + (p[1] - eye[1]).powi(2) + (p[2] - eye[2]).powi(2)).sqrt();
    let same = |buffer: &GBuffer, i: usize| {
        if buffer.material[i] != buffer.material[centre] || buffer.object_at(i) != buffer.object_at(centre) {
            return false;
        }
        if buffer.material[i] == 0 {
            return true;
        }
        let (n, m) = (unit_or_up(buffer.normal[i]), unit_or_up(buffer.normal[centre]));
        let cosine = (n[0] * m[0] + n[1] * m[1] + n[2] * m[2]) as f32;
        let (p, c) = (buffer.position[i], buffer.position[centre]);
        let off_plane =
            ((p[0] - c[0]) as f64 * m[0] + (p[1] - c[1]) as f64 * m[1] + (p[2] - c[2]) as f64 * m[2]) as f32;
        cosine >= NORMALS_AGREE && off_plane.abs() <= DEPTHS_AGREE * distance(c).max(f32::MIN_POSITIVE)
    };
    block.iter().all(|&i| same(g, i) && (material == 0 || reflection.is_none_or(|r| same(r, i))))
}

/// The samples of `frame` (`frame.supersample` per pixel along each axis) to shade.
pub fn select(frame: &Frame) -> Selection {
    let g = &frame.gbuffer;
    let n = frame.supersample;
    let (width, height) = (g.width / n, g.height / n);
    let eye = frame.camera.as_ref().map_or([0.0; 3], |c| c.position.map(|v| v as f32));
    let mut source = vec![None; g.material.len()];
    let mut picked: Vec<Pick> = Vec::new();
    let mut block = Vec::with_capacity(n * n);
    for y in 0..height {
        for x in 0..width {
            block.clear();
            for j in 0..n {
                for i in 0..n {
                    block.push(g.index(x * n + i, y * n + j));
                }
            }
            let centre = g.index(x * n + n / 2, y * n + n / 2);
            if agree(g, frame.reflection.as_ref(), eye, &block, centre) {
                if g.material[centre] != 0 {
                    let packed = picked.len() as u32;
                    picked.push(Pick::Mean(block.clone()));
                    block.iter().for_each(|&b| source[b] = Some(packed));
                }
                continue;
            }
            for &i in &block {
                if g.material[i] != 0 {
                    source[i] = Some(picked.len() as u32);
                    picked.push(Pick::Sample(i));
                }
            }
        }
    }
    let shaded = picked.len();
    Selection { packed: pack(frame, &picked), source, shaded, samples: g.material.len() }
}

/// What one packed sample is made of.
enum Pick {
    /// A sample of the frame.
    Sample(usize),
    /// The mean of a pixel's samples that agree: mean position, normalised mean normal,
    /// mean colours, the first sample's material and object.
    Mean(Vec<usize>),
}

/// The frame of the samples `picked`, row after row of a near-square G-buffer padded with
/// background.
fn pack(frame: &Frame, picked: &[Pick]) -> Frame {
    let width = (picked.len() as f64).sqrt().ceil().max(1.0) as usize;
    let height = picked.len().div_ceil(width).max(1);
    let take = |buffer: &GBuffer| {
        let mut packed = GBuffer {
            file: buffer.file.clone(),
            width,
            height,
            position: vec![[0.0; 3]; width * height],
            normal: vec![[0.0, 0.0, 1.0]; width * height],
            uv: None,
            material: vec![0; width * height],
            object: buffer.object.as_ref().map(|_| vec![0; width * height]),
            colours: buffer.colours.as_ref().map(|_| SurfaceColours {
                diffuse: vec![[0.0; 3]; width * height],
                glossy: vec![[0.0; 3]; width * height],
            }),
            first_row: 0,
        };
        for (k, pick) in picked.iter().enumerate() {
            let samples = match pick {
                Pick::Sample(i) => std::slice::from_ref(i),
                Pick::Mean(block) => block.as_slice(),
            };
            let first = samples[0];
            let mean = |values: &[[f32; 3]]| {
                let mut sum = [0.0f64; 3];
                for &i in samples {
                    for c in 0..3 {
                        sum[c] += f64::from(values[i][c]);
                    }
                }
                sum.map(|v| (v / samples.len() as f64) as f32)
            };
            packed.position[k] = mean(&buffer.position);
            packed.normal[k] = unit_or_up(mean(&buffer.normal)).map(|c| c as f32);
            packed.material[k] = buffer.material[first];
            if let (Some(out), Some(object)) = (&mut packed.object, &buffer.object) {
                out[k] = object[first];
            }
            if let (Some(out), Some(colours)) = (&mut packed.colours, &buffer.colours) {
                out.diffuse[k] = mean(&colours.diffuse);
                out.glossy[k] = mean(&colours.glossy);
            }
        }
        packed
    };
    let mut camera = frame.camera.clone();
    if let Some(c) = &mut camera {
        c.resolution = [width as u32, height as u32];
    }
    Frame {
        gbuffer: take(&frame.gbuffer),
        reflection: frame.reflection.as_ref().map(take),
        camera,
        supersample: 1,
        ..frame.clone()
    }
}

impl Selection {
    /// The background colour (alpha 0) of sample `i` of `frame`.
    fn background(materials: &BTreeMap<u32, Material>, frame: &Frame, i: usize) -> [f32; 4] {
        let g = &frame.gbuffer;
        match pixel_work(materials, frame, i % g.width, i / g.width) {
            PixelWork::Fixed(colour) => colour,
            PixelWork::Shade { .. } => unreachable!("a background sample is never shaded"),
        }
    }

    /// The beauty of every sample of `frame` from the packed frame's `rgba`.
    pub fn scatter_rgba(&self, materials: &BTreeMap<u32, Material>, frame: &Frame, rgba: &[[f32; 4]]) -> Vec<[f32; 4]> {
        (0..self.samples)
            .map(|i| match self.source[i] {
                Some(k) => rgba[k as usize],
                None => Self::background(materials, frame, i),
            })
            .collect()
    }

    /// Every pass of every sample of `frame` from the packed frame's `passes`; position and
    /// normal are the frame's own.
    pub fn scatter_passes(
        &self,
        materials: &BTreeMap<u32, Material>,
        frame: &Frame,
        passes: &ShadedPasses,
    ) -> ShadedPasses {
        let g = &frame.gbuffer;
        let count = self.samples;
        let mut out = ShadedPasses {
            width: g.width,
            height: g.height,
            beauty: Vec::with_capacity(count),
            diffuse: Vec::with_capacity(count),
            specular: Vec::with_capacity(count),
            environment: Vec::with_capacity(count),
            indirect: Vec::with_capacity(count),
            indirect_heightfield: Vec::with_capacity(count),
            indirect_blockers: Vec::with_capacity(count),
            visibility: Vec::with_capacity(count),
            visibility_heightfield: Vec::with_capacity(count),
            visibility_blockers: Vec::with_capacity(count),
            position: g.position.as_slice().into(),
            normal: g.normal.as_slice().into(),
        };
        for i in 0..count {
            match self.source[i] {
                Some(k) => {
                    let k = k as usize;
                    out.beauty.push(passes.beauty[k]);
                    out.diffuse.push(passes.diffuse[k]);
                    out.specular.push(passes.specular[k]);
                    out.environment.push(passes.environment[k]);
                    out.indirect.push(passes.indirect[k]);
                    out.indirect_heightfield.push(passes.indirect_heightfield[k]);
                    out.indirect_blockers.push(passes.indirect_blockers[k]);
                    out.visibility.push(passes.visibility[k]);
                    out.visibility_heightfield.push(passes.visibility_heightfield[k]);
                    out.visibility_blockers.push(passes.visibility_blockers[k]);
                }
                None => {
                    let sky = Self::background(materials, frame, i);
                    out.beauty.push(sky);
                    out.diffuse.push([0.0; 3]);
                    out.specular.push([0.0; 3]);
                    out.environment.push([sky[0], sky[1], sky[2]]);
                    out.indirect.push([0.0; 3]);
                    out.indirect_heightfield.push([0.0; 3]);
                    out.indirect_blockers.push([0.0; 3]);
                    out.visibility.push(1.0);
                    out.visibility_heightfield.push(1.0);
                    out.visibility_blockers.push(1.0);
                }
            }
        }
        out
    }
}
