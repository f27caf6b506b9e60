//! Visibility on a coarser grid (`--visibility-grid`): NS09 (Section 7) and SN08
//! (Section 8) compute visibility at a fraction of the pixels and shade with the
//! full-resolution normals, which is how they reach their frame rates.
//!
//! Here the two costly parts of a pixel's log visibility, the height field's horizons
//! (SN08's march, one tangent per azimuth) and the sphere caps' log vector, are computed
//! at one surface pixel of each `g x g` block, and each pixel takes their mean over the
//! four blocks around it: weighted bilinearly, and by how alike the two points are, so
//! that visibility does not leak across an edge:
//!
//! - the same object (a sphere of the pixel's own object follows the self-shadowing
//!   rule);
//! - normals within about 25 degrees: `max(n . n_b, 0)^8`, 0.46 at 25 degrees;
//! - the block's point near the pixel's tangent plane: `exp(-(r / 0.2)^2)`, `r` the sine
//!   of the elevation of the block's point seen from the pixel, 0 on a plane, about 1
//!   across a depth edge.
//!
//! Horizons are averaged as the tangents of their elevations, which the slices are built
//! from (a wall at 75 degrees between neighbours at 60 comes out at 70 where its angle's
//! mean is 67.5; one arctangent and one tangent per azimuth and pixel cost more than
//! the rest of the interpolation). Each block also turns its horizons into the height
//! field's log vector, its own tangent plane folded in ([`ShadingKernel::heightfield_log`]),
//! and a pixel takes the vectors' weighted mean in place of turning its own slices,
//! wherever its blocks' normals lie within about 6 degrees of its own (blended into its
//! own slices out to 10 degrees, so that nothing jumps; a prefiltered glossy lobe's
//! specular occlusion still reads the horizons, unfolded): the slices and their turn
//! were a sixth of a grid pixel's time on the dunes, and the tangent planes of normals
//! within the likeness's 25 degrees fold almost the same bands (against Cycles, the dunes
//! at 2 and 4 moved from 0.0231 and 0.0233 to 0.0233 and 0.0239). A pixel whose four
//! blocks weigh less than [`MIN_WEIGHT`] in all (an edge of its own, water's reflected
//! points) is computed alone. The tangent plane, the ground plane, the BRDF lobe, the
//! exponentiation and the suns' and lamps' disks stay per pixel.
//!
//! The GPU executor runs the same steps: the blocks' points ([`BlockPoints`]) are chosen
//! here, a pre-pass computes their horizons and caps on the device (`grid_visibility` in
//! `shaders/shade.wgsl`), and each pixel interpolates them there (`grid_at`), with the
//! weights' constants below.

use super::kernel::{Caps, Occluders, ShadingKernel, SurfacePoint};
use super::settings::MAX_DIRECTIONS;
use super::PixelWork;
use crate::scene::{Frame, Material};
use crate::sh::{coefficient_count, Real, MAX_COEFFICIENTS};
use crate::vector::dot;
use rayon::prelude::*;
use std::collections::BTreeMap;

/// Least total weight of a pixel's blocks under which it is computed alone.
pub const MIN_WEIGHT: f64 = 1e-3;

/// The horizons and caps of one surface pixel per block of a frame.
pub struct VisibilityGrid {
    size: usize,
    /// Blocks along x and y.
    blocks: [usize; 2],
    /// Per block, the point its visibility was computed at (`None`: no surface pixel).
    points: Vec<Option<SurfacePoint>>,
    /// Azimuths per block (0 without a height field).
    directions: usize,
    /// Per block, the tangents of its horizons' elevations.
    tangents: Vec<f64>,
    /// Coefficients per block (0 without blockers).
    count: usize,
    /// Per block, its caps' log vector.
    caps: Vec<f64>,
    /// Per block, the height field's log vector, the tangent plane of the block's normal
    /// folded in (`count_field` coefficients, 0 without a height field).
    fields: Vec<f64>,
    count_field: usize,
}

/// A pixel's horizons and caps, interpolated ([`VisibilityGrid::at`]).
pub struct GridVisibility {
    horizons: [f64; MAX_DIRECTIONS],
    caps: [f64; MAX_COEFFICIENTS],
    field: [f64; MAX_COEFFICIENTS],
    directions: usize,
    count: usize,
    /// Coefficients of `field`: 0 without a height field or where `field_weight` is 0.
    count_field: usize,
    /// How much the pixel takes `field` rather than turn its own horizons: 1 where its
    /// blocks' normals all lie within [`FIELD_NORMAL_COSINES`]' first of its own, 0
    /// beyond the second or where a block folds its tangent plane where the pixel does
    /// not (or the other way round), linear in between.
    field_weight: f64,
}

impl GridVisibility {
    pub fn new() -> Self {
        Self {
            horizons: [0.0; MAX_DIRECTIONS],
            caps: [0.0; MAX_COEFFICIENTS],
            field: [0.0; MAX_COEFFICIENTS],
            directions: 0,
            count: 0,
            count_field: 0,
            field_weight: 0.0,
        }
    }

    /// Where the kernel takes the pixel's horizons and caps from.
    pub fn caps(&self) -> Caps<'_> {
        Caps::Grid {
            caps: (self.count > 0).then(|| &self.caps[..self.count]),
            horizons: (self.directions > 0).then(|| &self.horizons[..self.directions]),
            heightfield: (self.count_field > 0).then(|| (&self.field[..self.count_field], self.field_weight)),
        }
    }
}

impl Default for GridVisibility {
    fn default() -> Self {
        Self::new()
    }
}

/// Whether pixel `i` of `frame` is a surface the grid serves: shaded where it is (not
/// water, whose pixels shade the points they reflect).
pub(crate) fn is_direct_surface(materials: &BTreeMap<u32, Material>, frame: &Frame, i: usize) -> bool {
    let m = frame.gbuffer.material[i];
    m != 0 && !matches!(materials.get(&m), Some(Material::Water { .. }) | None)
}

/// The surface pixel each `size x size` block of a frame computes its visibility at: the
/// one nearest the block's centre pixel that the grid serves ([`is_direct_surface`]).
pub struct BlockPoints {
    /// Blocks along x and y.
    pub blocks: [usize; 2],
    /// Per block, row by row, its point (`None`: no surface pixel).
    pub points: Vec<Option<SurfacePoint>>,
}

impl BlockPoints {
    /// The blocks of `frame` (`work` gives each pixel's point).
    pub fn new(
        frame: &Frame,
        materials: &BTreeMap<u32, Material>,
        size: usize,
        work: impl Fn(usize, usize) -> PixelWork + Sync,
    ) -> Self {
        let g = &frame.gbuffer;
        let blocks = [g.width.div_ceil(size), g.height.div_ceil(size)];
        let point_of = |bx: usize, by: usize| {
            let centre = [(bx * size + size / 2).min(g.width - 1), (by * size + size / 2).min(g.height - 1)];
            let mut pixels: Vec<[usize; 2]> = (by * size..((by + 1) * size).min(g.height))
                .flat_map(|y| (bx * size..((bx + 1) * size).min(g.width)).map(move |x| [x, y]))
                .collect();
            pixels.sort_by_key(|&[x, y]| x.abs_diff(centre[0]).pow(2) + y.abs_diff(centre[1]).pow(2));
            pixels.into_iter().find(|&[x, y]| is_direct_surface(materials, frame, g.index(x, y))).and_then(|[x, y]| {
                match work(x, y) {
                    PixelWork::Shade { point, .. } => Some(point),
                    PixelWork::Fixed(_) => None,
                }
            })
        };
        let points =
            (0..blocks[0] * blocks[1]).into_par_iter().map(|b| point_of(b % blocks[0], b / blocks[0])).collect();
        Self { blocks, points }
    }
}

impl VisibilityGrid {
    /// Computes the horizons and caps of each `size x size` block of `frame` at its
    /// surface pixel nearest the block's centre pixel (`work` gives each pixel's point).
    pub fn new<T: Real>(
        kernel: &ShadingKernel<T>,
        occluders: Occluders,
        frame: &Frame,
        materials: &BTreeMap<u32, Material>,
        size: usize,
        work: impl Fn(usize, usize) -> PixelWork + Sync,
    ) -> Self {
        let BlockPoints { blocks, points } = BlockPoints::new(frame, materials, size, work);
        let directions = occluders.horizons.map_or(0, |pyramid| pyramid.settings().directions);
        let mut tangents = vec![0.0; points.len() * directions];
        if let Some(pyramid) = occluders.horizons {
            tangents.par_chunks_mut(directions).zip(&points).for_each(|(out, point)| {
                if let Some(point) = point {
                    pyramid.horizon_tangents(point.position, out);
                }
            });
        }
        let count_field = if directions > 0 { coefficient_count(kernel.order()) } else { 0 };
        let mut fields = vec![0.0; points.len() * count_field];
        if count_field > 0 {
            fields.par_chunks_mut(count_field).zip(tangents.par_chunks(directions)).zip(&points).for_each(
                |((out, tangents), point)| {
                    if let Some(point) = point {
                        let field = kernel.heightfield_log(tangents, point.normal);
                        for (o, c) in out.iter_mut().zip(&field) {
                            *o = c.to_f64().unwrap_or(0.0);
                        }
                    }
                },
            );
        }
        let count = if occluders.blockers.is_some() { coefficient_count(kernel.order()) } else { 0 };
        let mut caps = vec![0.0; points.len() * count];
        if let Some(tree) = occluders.blockers {
            // Eight blocks a packet where the kernel can ([`ShadingKernel::sum_caps`]).
            caps.par_chunks_mut(count * 64).zip(points.par_chunks(64)).for_each(|(out, run)| {
                let present: Vec<SurfacePoint> = run.iter().flatten().copied().collect();
                let sums = kernel.sum_caps(Some(tree), &present);
                let mut k = 0;
                for (out, point) in out.chunks_mut(count).zip(run) {
                    let Some(point) = point else { continue };
                    match sums.of(k) {
                        Caps::Summed(sum) => {
                            for (o, &c) in out.iter_mut().zip(sum) {
                                *o = f64::from(c);
                            }
                        }
                        _ => {
                            let mut acc = [T::zero(); MAX_COEFFICIENTS];
                            kernel.add_blocker_caps(
                                tree,
                                point.position,
                                point.normal,
                                point.object,
                                &mut acc[..count],
                                None,
                            );
                            for (o, c) in out.iter_mut().zip(&acc[..count]) {
                                *o = c.to_f64().unwrap_or(0.0);
                            }
                        }
                    }
                    k += 1;
                }
            });
        }
        Self { size, blocks, points, directions, tangents, count, caps, fields, count_field }
    }

    /// The horizons, caps and height-field vector of pixel `(x, y)`, whose point is
    /// `point`, interpolated into `out` (module doc); the horizons only where the pixel
    /// blends its own slices in or `wants_horizons` (its material reads them for its
    /// specular occlusion). `false` where no block is like it (the pixel is then computed
    /// alone).
    pub fn at(&self, x: usize, y: usize, point: &SurfacePoint, wants_horizons: bool, out: &mut GridVisibility) -> bool {
        let size = self.size as f64;
        // Block coordinates of the pixel, block `b`'s point standing at its centre pixel.
        let half = (self.size / 2) as f64;
        let (u, v) = ((x as f64 - half) / size, (y as f64 - half) / size);
        let (b0, c0) = (u.floor(), v.floor());
        let (tu, tv) = (u - b0, v - c0);
        // The blocks like the pixel, and their weights.
        let mut like = [(0usize, 0.0f64); 4];
        let mut found = 0;
        let mut total = 0.0;
        // The least `n . n_b` of the blocks, -1 where one folds its tangent plane where the
        // pixel does not (an upward normal folds).
        let mut least_cosine = 1.0f64;
        for (db, wu) in [(0.0, 1.0 - tu), (1.0, tu)] {
            for (dc, wv) in [(0.0, 1.0 - tv), (1.0, tv)] {
                let (b, c) = (b0 + db, c0 + dc);
                let bilinear = wu * wv;
                if bilinear <= 0.0 || b < 0.0 || c < 0.0 {
                    continue;
                }
                let (b, c) = (b as usize, c as usize);
                if b >= self.blocks[0] || c >= self.blocks[1] {
                    continue;
                }
                let block = c * self.blocks[0] + b;
                let Some(other) = &self.points[block] else { continue };
                let weight = bilinear * likeness(point, other);
                if weight <= 0.0 {
                    continue;
                }
                total += weight;
                like[found] = (block, weight);
                found += 1;
                let folds_alike = (other.normal[2] > 0.0) == (point.normal[2] > 0.0);
                least_cosine = least_cosine.min(if folds_alike { dot(point.normal, other.normal) } else { -1.0 });
            }
        }
        if total < MIN_WEIGHT {
            return false;
        }
        let [near, far] = FIELD_NORMAL_COSINES;
        out.field_weight = ((least_cosine - far) / (near - far)).clamp(0.0, 1.0);
        out.count_field = if out.field_weight > 0.0 { self.count_field } else { 0 };
        // The horizons only where the pixel turns its own slices or reads them otherwise.
        let directions = if out.field_weight < 1.0 || wants_horizons { self.directions } else { 0 };
        out.horizons[..directions].fill(0.0);
        out.caps[..self.count].fill(0.0);
        out.field[..out.count_field].fill(0.0);
        for &(block, weight) in &like[..found] {
            let weight = weight / total;
            let tangents = &self.tangents[block * self.directions..block * self.directions + directions];
            for (h, t) in out.horizons.iter_mut().zip(tangents) {
                *h += weight * t;
            }
            for (a, c) in out.caps.iter_mut().zip(&self.caps[block * self.count..(block + 1) * self.count]) {
                *a += weight * c;
            }
            let field = &self.fields[block * self.count_field..block * self.count_field + out.count_field];
            for (a, c) in out.field.iter_mut().zip(field) {
                *a += weight * c;
            }
        }
        (out.directions, out.count) = (directions, self.count);
        true
    }
}

/// The least `n . n_b` of a pixel's blocks at or above which it takes their height-field
/// vectors whole (about 6 degrees), and under which it turns its own horizons (about 10
/// degrees): a block's vector folds its own tangent plane in (module doc).
pub const FIELD_NORMAL_COSINES: [f64; 2] = [0.995, 0.985];

/// The power of `n . n_b` in a block's likeness (module doc): 0.46 at 25 degrees.
pub const NORMAL_POWER: i32 = 8;
/// The sine of the elevation of a block's point off the pixel's tangent plane at which
/// its likeness falls by `1 / e` (module doc).
pub const PLANE_WIDTH: f64 = 0.2;

/// How alike two points are for their visibility (module doc): 0 to 1.
fn likeness(point: &SurfacePoint, other: &SurfacePoint) -> f64 {
    if point.object != other.object {
        return 0.0;
    }
    let normals = dot(point.normal, other.normal).max(0.0).powi(NORMAL_POWER);
    let d = [0, 1, 2].map(|k| other.position[k] - point.position[k]);
    let distance = dot(d, d).sqrt();
    let off_plane = if distance > 0.0 { dot(point.normal, d).abs() / distance } else { 0.0 };
    normals * (-(off_plane / PLANE_WIDTH).powi(2)).exp()
}
