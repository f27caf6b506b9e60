//! The light's detail a sphere's cap hides: what log-SH's order-n product leaves out.
//!
//! A receiver under a blocker's cap `C` gets `int V L max(n . w, 0)`; log-SH takes the light
//! at order n, `L_n`, so the blocked part of `L - L_n` (the bands from n on) stays lit.
//! Per cap this is `int_C (L - L_n)(w) max(n . w, 0) dw`, which for a cap above the
//! receiver's tangent plane is `n . M(d, alpha)`, `M` the first moment of `L - L_n` over
//! the cap about `d` of radius `alpha`. `M` is tabulated once per light on a grid of
//! directions and radii; the kernel sums each cap's `n . M` and takes it, over pi, from
//! the diffuse light (`ShadingKernel::hidden_detail` in `super::kernel`), the GPU pass the
//! same from the same table (`hidden_detail` in `shaders/shade.wgsl`).
//!
//! Accuracy: against a fine polar integration over caps of 0.15 to 0.8 rad under a map
//! with a patch twenty times its sky, within 5.5 % of the largest detail, most caps within
//! 1 to 3 % (`tests` below). Against Cycles: docs/method/materials.md, "The detail a cap
//! hides".

use std::f64::consts::{PI, TAU};

use rayon::prelude::*;

use crate::scene::light::{atan2_fast, EnvironmentMap};

/// Columns of the table's directions (its rows are half as many).
pub(crate) const COLUMNS: usize = 64;
pub(crate) const ROWS: usize = COLUMNS / 2;
/// Radii from 0 to [`MAX_RADIUS`], both included.
pub(crate) const RADII: usize = 33;
pub(crate) const MAX_RADIUS: f64 = PI / 2.0;
/// The light's samples: an equirectangular grid of this many columns.
const SOURCE_COLUMNS: usize = 128;
const SOURCE_ROWS: usize = SOURCE_COLUMNS / 2;

/// The smallest sine of a cap's radius whose detail is read: a smaller cap (under 5.7
/// degrees, 0.031 sr) hides too little of it to tell. Reading every cap instead moved
/// `cones`, `glossy`, `primitives`, `textured` and `primitives_hdri_sun` by at most 0.0001
/// against Cycles as authored, and cost `cones` a fifth more of its shading stage (37.4
/// against 30.6 ms on the CPU, median of five alternating `logsh bench` runs).
pub(crate) const MIN_RATIO: f64 = 0.1;

/// `M(d, alpha)` on a grid of directions and radii, per colour channel.
#[derive(Clone, Debug)]
pub(crate) struct CapDetail {
    /// `moments[(radius * ROWS + row) * COLUMNS + column][3 * channel + axis]`.
    moments: Vec<[f32; 9]>,
}

fn direction(theta: f64, phi: f64) -> [f64; 3] {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    [st * cp, st * sp, ct]
}

/// The direction at fractional row `y` and column `x` of the light's samples.
fn source_direction(y: f64, x: f64) -> [f64; 3] {
    direction(PI * y / SOURCE_ROWS as f64, TAU * x / SOURCE_COLUMNS as f64)
}

/// The centre of the table's cell at `row`, `column`.
fn table_direction(row: usize, column: usize) -> [f64; 3] {
    direction(PI * (row as f64 + 0.5) / ROWS as f64, TAU * (column as f64 + 0.5) / COLUMNS as f64)
}

impl CapDetail {
    /// The cap of the sphere at `centre` of `radius` as its detail is read from `p` with
    /// normal `n`: its direction, angular radius, and how much of its detail it hides
    /// where the tangent plane cuts it. `n . M` counts the part of a cut cap below the
    /// plane with a negative cosine, where the receiver gets no light at all, so the
    /// detail fades as the centre sinks towards the plane, by `sin(elevation) /
    /// sin(alpha)` (measured against Cycles as authored: `cones`, whose objects' own caps
    /// are mostly cut, 0.0078 with the whole moment, 0.0077 faded, 0.0075 without any
    /// detail; `glossy` 0.0059 either way). `None` for a cap behind the plane, at the
    /// receiver or below [`MIN_RATIO`].
    pub(crate) fn cap_seen(p: [f64; 3], n: [f64; 3], centre: [f64; 3], radius: f64) -> Option<([f64; 3], f64, f64)> {
        let d = [centre[0] - p[0], centre[1] - p[1], centre[2] - p[2]];
        let distance = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let ratio = (radius / distance).min(1.0);
        if !(distance > 0.0 && ratio >= MIN_RATIO) {
            return None;
        }
        let direction = d.map(|c| c / distance);
        let elevation = n[0] * direction[0] + n[1] * direction[1] + n[2] * direction[2];
        (elevation > 0.0).then(|| (direction, ratio.asin(), (elevation / ratio).min(1.0)))
    }

    /// The table for `map` times `strength`, less its order-`order` projection `light`
    /// (`order^2` RGB coefficients), hiding the lower hemisphere where `ground` is set.
    pub(crate) fn new(map: &EnvironmentMap, strength: f32, order: usize, light: &[[f64; 3]], sky_only: bool) -> Self {
        let channels: [Vec<f64>; 3] = [0, 1, 2].map(|c| light.iter().map(|rgb| rgb[c]).collect());
        // The rows of the light's samples that count: all, or the upper hemisphere's.
        let rows = if sky_only { SOURCE_ROWS / 2 } else { SOURCE_ROWS };
        // Each sample's solid angle times `L - L_n`, per channel, and its direction.
        let samples: Vec<([f64; 3], [f64; 3])> = (0..rows * SOURCE_COLUMNS)
            .into_par_iter()
            .map(|index| {
                let (row, column) = (index / SOURCE_COLUMNS, index % SOURCE_COLUMNS);
                let w = source_direction(row as f64 + 0.5, column as f64 + 0.5);
                let (t0, t1) = (PI * row as f64 / SOURCE_ROWS as f64, PI * (row + 1) as f64 / SOURCE_ROWS as f64);
                let area = (t0.cos() - t1.cos()) * TAU / SOURCE_COLUMNS as f64;
                // The map's mean over the sample's cell, from 4 x 4 bilinear reads.
                let mut mean = [0.0f64; 3];
                for i in 0..4 {
                    for j in 0..4 {
                        let (y, x) = (row as f64 + (i as f64 + 0.5) / 4.0, column as f64 + (j as f64 + 0.5) / 4.0);
                        for (m, v) in mean.iter_mut().zip(map.lookup(source_direction(y, x))) {
                            *m += f64::from(v) / 16.0;
                        }
                    }
                }
                let detail = [0, 1, 2].map(|c| {
                    (mean[c] * f64::from(strength) - crate::sh::eval_expansion(order, &channels[c], w)) * area
                });
                (w, detail)
            })
            .collect();
        let step = MAX_RADIUS / (RADII - 1) as f64;
        // The table's directions of one row share their angles to the samples, turned by
        // whole columns: the radius bin of each sample from the row's first direction.
        let per_row: Vec<Vec<[f32; 9]>> = (0..ROWS)
            .into_par_iter()
            .map(|row| {
                let first = table_direction(row, 0);
                let bins: Vec<u8> = samples
                    .iter()
                    .map(|(w, _)| {
                        let angle = (first[0] * w[0] + first[1] * w[1] + first[2] * w[2]).clamp(-1.0, 1.0).acos();
                        if angle >= MAX_RADIUS {
                            u8::MAX
                        } else {
                            (angle / step).ceil() as u8
                        }
                    })
                    .collect();
                let turn = SOURCE_COLUMNS / COLUMNS;
                let mut out = vec![[0.0f32; 9]; RADII * COLUMNS];
                for column in 0..COLUMNS {
                    let mut rings = [[[0.0f64; 3]; 3]; RADII];
                    for (index, (w, detail)) in samples.iter().enumerate() {
                        let (source_row, source_column) = (index / SOURCE_COLUMNS, index % SOURCE_COLUMNS);
                        let relative = (source_column + SOURCE_COLUMNS - column * turn) % SOURCE_COLUMNS;
                        let bin = bins[source_row * SOURCE_COLUMNS + relative];
                        if bin == u8::MAX {
                            continue;
                        }
                        let ring = &mut rings[usize::from(bin)];
                        for c in 0..3 {
                            for k in 0..3 {
                                ring[c][k] += detail[c] * w[k];
                            }
                        }
                    }
                    // Each radius holds the rings inside it.
                    let mut inside = [[0.0f64; 3]; 3];
                    for (radius, ring) in rings.iter().enumerate() {
                        for c in 0..3 {
                            for k in 0..3 {
                                inside[c][k] += ring[c][k];
                            }
                        }
                        out[radius * COLUMNS + column] = std::array::from_fn(|i| inside[i / 3][i % 3] as f32);
                    }
                }
                out
            })
            .collect();
        let mut moments = vec![[0.0f32; 9]; RADII * ROWS * COLUMNS];
        for (row, values) in per_row.into_iter().enumerate() {
            for radius in 0..RADII {
                let at = (radius * ROWS + row) * COLUMNS;
                moments[at..at + COLUMNS].copy_from_slice(&values[radius * COLUMNS..(radius + 1) * COLUMNS]);
            }
        }
        Self { moments }
    }

    /// The table as the GPU pass reads it (`hidden_detail` in `shaders/shade.wgsl`): nine
    /// values per cell, in [`Self::at`]'s order.
    pub(crate) fn values(&self) -> impl Iterator<Item = f32> + '_ {
        self.moments.iter().flatten().copied()
    }

    /// `n . M(d, alpha)` per channel: the detail of the light a cap about `d` of radius
    /// `alpha` hides from a receiver of normal `n`.
    pub(crate) fn at(&self, d: [f64; 3], alpha: f64, n: [f64; 3]) -> [f64; 3] {
        let horizontal = (d[0] * d[0] + d[1] * d[1]).sqrt();
        let theta = atan2_fast(horizontal, d[2]);
        let phi = atan2_fast(d[1], d[0]);
        let y = (theta / PI * ROWS as f64 - 0.5).clamp(0.0, (ROWS - 1) as f64);
        let x = (phi / TAU * COLUMNS as f64 - 0.5).rem_euclid(COLUMNS as f64);
        let r = (alpha / MAX_RADIUS * (RADII - 1) as f64).clamp(0.0, (RADII - 1) as f64);
        // `rem_euclid` may round up to `COLUMNS` itself.
        let (y0, x0, r0) = (y as usize, (x as usize).min(COLUMNS - 1), r as usize);
        let (fy, fx, fr) = ((y - y0 as f64) as f32, (x - x0 as f64) as f32, (r - r0 as f64) as f32);
        let (y1, x1, r1) = ((y0 + 1).min(ROWS - 1), (x0 + 1) % COLUMNS, (r0 + 1).min(RADII - 1));
        let n = n.map(|c| c as f32);
        // Each corner's moments dotted with `n`, then blended.
        let corner = |radius: usize, row: usize, column: usize| -> [f32; 3] {
            let m = &self.moments[(radius * ROWS + row) * COLUMNS + column];
            [0, 1, 2].map(|c| n[0] * m[3 * c] + n[1] * m[3 * c + 1] + n[2] * m[3 * c + 2])
        };
        let blend = |a: [f32; 3], b: [f32; 3], t: f32| [0, 1, 2].map(|c| a[c] + t * (b[c] - a[c]));
        let plane = |radius: usize| {
            let top = blend(corner(radius, y0, x0), corner(radius, y0, x1), fx);
            let bottom = blend(corner(radius, y1, x0), corner(radius, y1, x1), fx);
            blend(top, bottom, fy)
        };
        blend(plane(r0), plane(r1), fr).map(f64::from)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::light::project_texels;

    /// A dim sky with a bright patch and a bright band: detail in every band past 4.
    fn structured_map() -> EnvironmentMap {
        let (width, height) = (256, 128);
        let texels = (0..width * height)
            .map(|i| {
                let (x, y) = ((i % width) as f64 / width as f64, (i / width) as f64 / height as f64);
                let patch = if (x - 0.3).abs() < 0.04 && (y - 0.3).abs() < 0.05 { 20.0 } else { 0.0 };
                let band = if (y - 0.42).abs() < 0.02 { 3.0 } else { 0.0 };
                let sky = 0.2 + 0.3 * (1.0 - y);
                [(sky + patch + band) as f32, (sky + 0.5 * patch) as f32, (sky + band) as f32]
            })
            .collect();
        EnvironmentMap { file: "structured".into(), width, height, texels }
    }

    /// `int_C (L - L_n)(w) (n . w) dw` by a fine polar grid over the cap.
    fn integrated(
        map: &EnvironmentMap,
        light: &[[f64; 3]],
        order: usize,
        d: [f64; 3],
        alpha: f64,
        n: [f64; 3],
    ) -> [f64; 3] {
        let (rings, sectors) = (200, 400);
        let helper = if d[2].abs() < 0.9 { [0.0, 0.0, 1.0] } else { [1.0, 0.0, 0.0] };
        let e1 = crate::vector::normalize(crate::vector::cross(helper, d));
        let e2 = crate::vector::cross(d, e1);
        let channels: [Vec<f64>; 3] = [0, 1, 2].map(|c| light.iter().map(|rgb| rgb[c]).collect());
        let mut sum = [0.0; 3];
        for i in 0..rings {
            let rho = alpha * (i as f64 + 0.5) / rings as f64;
            let (sr, cr) = rho.sin_cos();
            let area = sr * (alpha / rings as f64) * (TAU / sectors as f64);
            for j in 0..sectors {
                let (sp, cp) = (TAU * (j as f64 + 0.5) / sectors as f64).sin_cos();
                let w = [0, 1, 2].map(|k| cr * d[k] + sr * (cp * e1[k] + sp * e2[k]));
                let cosine = n[0] * w[0] + n[1] * w[1] + n[2] * w[2];
                let value = map.lookup(w);
                for c in 0..3 {
                    let projected = crate::sh::eval_expansion(order, &channels[c], w);
                    sum[c] += (f64::from(value[c]) - projected) * cosine * area;
                }
            }
        }
        sum
    }

    #[test]
    fn the_table_gives_the_detail_over_caps_above_the_tangent_plane() {
        let map = structured_map();
        let order = 4;
        let light = project_texels(&map, order);
        let table = CapDetail::new(&map, 1.0, order, &light, false);
        // The patch is near azimuth pi - 2 pi 0.3 and polar angle 0.3 pi, in the map's
        // orientation (`equirectangular_to_direction`).
        let patch = crate::scene::light::equirectangular_to_direction(0.3, 1.0 - 0.3);
        let up = [0.0, 0.0, 1.0];
        let tilted = crate::vector::normalize([patch[0], patch[1], patch[2] + 1.0]);
        let mut worst = 0.0f64;
        let mut largest = 0.0f64;
        for (d, n) in
            [(patch, up), (patch, tilted), (up, up), (tilted, tilted), (crate::vector::normalize([1.0, 1.0, 0.6]), up)]
        {
            for alpha in [0.15, 0.3, 0.5, 0.8] {
                if n[0] * d[0] + n[1] * d[1] + n[2] * d[2] < f64::sin(alpha) {
                    continue;
                }
                let want = integrated(&map, &light, order, d, alpha, n);
                let got = table.at(d, alpha, n);
                println!("d {d:.2?} n {n:.2?} alpha {alpha}: table {got:.4?}, integral {want:.4?}");
                for c in 0..3 {
                    worst = worst.max((got[c] - want[c]).abs());
                    largest = largest.max(want[c].abs());
                }
            }
        }
        // Measured: within 5.5 % of the largest detail, the worst where a cap's edge cuts
        // across the patch's, which the table's directions (5.6 degrees apart) blur; most
        // caps within 1 to 3 %.
        assert!(largest > 1.0, "the caps must hide detail: {largest}");
        assert!(worst <= 0.06 * largest, "table against the integral: {worst} of {largest}");
    }

    #[test]
    fn a_light_within_the_order_has_no_detail() {
        // A map that is its own order-2 projection: 1 + z.
        let (width, height) = (128, 64);
        let texels = (0..width * height)
            .map(|i| {
                let v = 1.0 - ((i / width) as f64 + 0.5) / height as f64;
                let z = (std::f64::consts::PI * (1.0 - v)).cos();
                [(1.0 + z) as f32; 3]
            })
            .collect();
        let map = EnvironmentMap { file: "linear".into(), width, height, texels };
        let light = project_texels(&map, 4);
        let table = CapDetail::new(&map, 1.0, 4, &light, false);
        for alpha in [0.1, 0.5, 1.2] {
            let detail = table.at(crate::vector::normalize([0.3, -0.2, 0.9]), alpha, [0.0, 0.0, 1.0]);
            assert!(detail.iter().all(|v| v.abs() < 2e-3), "alpha {alpha}: {detail:?}");
        }
    }
}
