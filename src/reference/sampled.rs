//! The reference integral by importance sampling: light x exact visibility x BRDF at one
//! point, estimated from directions drawn from the environment map and from each BRDF
//! lobe, combined by multiple importance sampling (Veach and Guibas 1995, the balance
//! heuristic with equal sample counts per strategy: `f(w) / sum_k p_k(w)` averaged over
//! every sample of every strategy, unbiased wherever some `p_k(w) > 0` covers `f(w) > 0`,
//! which the lobe strategies do alone).
//!
//! Visibility is the same exact test as the meridian integrator's ([`super::integrate`]):
//! the tangent plane, every sphere cap, and the height field's exact horizon along the
//! sample's azimuth. Only the light and the BRDF are sampled; no shadow boundary is
//! approximated.
//!
//! # Samples and the error estimate
//!
//! Each strategy draws from the 2D Sobol' (0,2)-sequence, randomised by a digital shift
//! (an XOR per dimension); [`REPLICATES`] independent shifts give independent unbiased
//! estimates whose spread is the error estimate: twice the standard error of their mean
//! (about a 95 % interval), largest channel. Level `k` uses `BASE_POINTS * 2^k` points
//! per strategy and replicate. A pilot at level 1 predicts the level that reaches the
//! tolerance (error taken to fall like `N^-1/2`); the pixel's value is then a fresh
//! estimate at that level, with new randomisations, so that the decision to stop is
//! independent of the samples it stops on (stopping on an estimate's own spread biased
//! sphere-over-plane by +4e-4: replicates agree more often when they are brighter). The
//! shifts are seeded per pixel, so a render is reproducible.
//!
//! # The environment strategy
//!
//! A texel is drawn with probability proportional to the largest channel of the
//! brightest texel among it and its 8 neighbours (the bilinear lookup of a direction in
//! one texel's extent reads those neighbours) times its solid angle, then a direction
//! uniformly over the texel's extent on the sphere: density `P(texel) / Omega(texel)`.

use super::integrate::{lobe_sum, unit, LightModel, LobeTerm, PointEstimate, PreparedPoint, ReferenceOccluders};
use crate::heightfield::horizon_reaches_within;
use crate::logsh::Lobe;
use crate::scene::light::direction_to_equirectangular;
use crate::scene::{EnvironmentMap, Light, SunLight};
use crate::vector::{dot, frame_around};
use std::f64::consts::{PI, TAU};

/// Independent randomisations whose spread estimates the error.
pub const REPLICATES: usize = 8;
/// Points per strategy and replicate at level 0.
pub const BASE_POINTS: usize = 16;

/// Texel distribution of an environment map for importance sampling (see the module doc).
#[derive(Clone, Debug)]
pub struct TexelSampler {
    width: usize,
    height: usize,
    /// `row_cdf[r]`: probability of rows `< r` (`height + 1` entries, the last 1).
    row_cdf: Vec<f64>,
    /// Per row, `width + 1` cumulative probabilities of the columns, within the row.
    column_cdf: Vec<f64>,
    /// Probability of each texel, row-major.
    texel_probability: Vec<f64>,
    /// Solid angle of a texel of each row.
    texel_solid_angle: Vec<f64>,
}

impl TexelSampler {
    /// The sampler of `light`, when it is an environment map with some radiance.
    pub fn of(light: &LightModel) -> Option<TexelSampler> {
        match light {
            LightModel::Direct(Light::Environment { map, strength }) if *strength > 0.0 => Self::new(map),
            _ => None,
        }
    }

    /// `None` for a black map.
    pub fn new(map: &EnvironmentMap) -> Option<TexelSampler> {
        let (width, height) = (map.width, map.height);
        let brightest = |r: usize, c: usize| {
            let t = map.texels[r * width + c];
            f64::from(t[0].max(t[1]).max(t[2]))
        };
        let texel_solid_angle: Vec<f64> = (0..height).map(|r| map.texel_solid_angle(r)).collect();
        let mut weight = vec![0.0; width * height];
        for r in 0..height {
            for c in 0..width {
                let mut w: f64 = 0.0;
                for dr in [-1i64, 0, 1] {
                    let rr = (r as i64 + dr).clamp(0, height as i64 - 1) as usize;
                    for dc in [-1i64, 0, 1] {
                        let cc = (c as i64 + dc).rem_euclid(width as i64) as usize;
                        w = w.max(brightest(rr, cc));
                    }
                }
                weight[r * width + c] = w * texel_solid_angle[r];
            }
        }
        let total: f64 = weight.iter().sum();
        if !(total > 0.0 && total.is_finite()) {
            return None;
        }
        let texel_probability: Vec<f64> = weight.iter().map(|w| w / total).collect();
        let mut row_cdf = Vec::with_capacity(height + 1);
        let mut column_cdf = Vec::with_capacity(height * (width + 1));
        let mut acc = 0.0;
        row_cdf.push(0.0);
        for r in 0..height {
            let row = &texel_probability[r * width..(r + 1) * width];
            let row_total: f64 = row.iter().sum();
            let mut within = 0.0;
            column_cdf.push(0.0);
            for &p in row {
                within += p;
                column_cdf.push(if row_total > 0.0 { within / row_total } else { 0.0 });
            }
            acc += row_total;
            row_cdf.push(acc);
        }
        Some(TexelSampler { width, height, row_cdf, column_cdf, texel_probability, texel_solid_angle })
    }

    /// A direction for the point `(u1, u2)` of the unit square (the remainders of the two
    /// discrete choices place it within the texel, so the square's stratification
    /// carries over).
    fn sample(&self, u1: f64, u2: f64) -> [f64; 3] {
        let row = pick(&self.row_cdf, u1);
        let v1 = remainder(&self.row_cdf, row, u1);
        let columns = &self.column_cdf[row * (self.width + 1)..(row + 1) * (self.width + 1)];
        let column = pick(columns, u2);
        let v2 = remainder(columns, column, u2);
        let (z0, z1) =
            ((PI * row as f64 / self.height as f64).cos(), (PI * (row + 1) as f64 / self.height as f64).cos());
        let z = z0 + (z1 - z0) * v1;
        // Column c spans u in [c, c + 1] / width, and phi = pi - 2 pi u
        // (`equirectangular_to_direction`).
        let phi = PI - TAU * (column as f64 + v2) / self.width as f64;
        let s = (1.0 - z * z).max(0.0).sqrt();
        [s * phi.cos(), s * phi.sin(), z]
    }

    /// Density of [`Self::sample`] in direction `w` (unit), per steradian.
    fn density(&self, w: [f64; 3]) -> f64 {
        let [u, v] = direction_to_equirectangular(w);
        let row = (((1.0 - v) * self.height as f64) as usize).min(self.height - 1);
        let column = ((u * self.width as f64) as usize).min(self.width - 1);
        self.texel_probability[row * self.width + column] / self.texel_solid_angle[row]
    }
}

/// The same integral as [`super::integrate_point`] by importance sampling :
/// directions drawn from `environment` (the light's texel sampler, if it has one) and from
/// every lobe, with the same exact visibility. `seed` fixes the randomisation.
#[allow(clippy::too_many_arguments)]
pub fn sample_point(
    occluders: ReferenceOccluders,
    light: &LightModel,
    environment: Option<&TexelSampler>,
    p: [f64; 3],
    n: [f64; 3],
    terms: &[LobeTerm],
    tolerance: f64,
    max_level: u32,
    seed: u64,
) -> PointEstimate {
    PreparedPoint::new(occluders, p, n, terms)
        .map_or_else(|exact| exact, |point| sample_prepared(&point, light, environment, tolerance, max_level, seed))
}

/// The sharp lights' part of the integral (each sun's disk, exact visibility), by
/// sampling the disks ; added to either integration's environment part.
#[allow(clippy::too_many_arguments)]
pub fn sample_suns(
    occluders: ReferenceOccluders,
    suns: &[crate::scene::SunLight],
    p: [f64; 3],
    n: [f64; 3],
    terms: &[LobeTerm],
    tolerance: f64,
    max_level: u32,
    seed: u64,
) -> PointEstimate {
    if suns.is_empty() {
        return PointEstimate::exact([0.0; 3]);
    }
    PreparedPoint::new(occluders, p, n, terms)
        .map_or_else(|exact| exact, |point| sample_prepared_suns(&point, suns, tolerance, max_level, seed))
}

/// The point lamps' part of the integral: each lamp's disk as seen from `p`
/// ([`crate::scene::PointLight::seen_from`]), sampled as [`sample_suns`] samples a sun's,
/// with only the occluders nearer than the lamp; `tolerance` is shared between them.
#[allow(clippy::too_many_arguments)]
pub fn sample_lamps(
    occluders: ReferenceOccluders,
    lamps: &[crate::scene::PointLight],
    p: [f64; 3],
    n: [f64; 3],
    terms: &[LobeTerm],
    tolerance: f64,
    max_level: u32,
    seed: u64,
) -> PointEstimate {
    let mut total = PointEstimate::exact([0.0; 3]);
    let share = tolerance / lamps.len().max(1) as f64;
    for (i, lamp) in lamps.iter().enumerate() {
        let (disk, reach) = lamp.seen_from(p, unit(n).unwrap_or([0.0, 0.0, 1.0]));
        let seed = seed ^ (i as u64 + 1).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        let one = PreparedPoint::within(occluders, p, n, terms, reach).map_or_else(
            |exact| exact,
            |mut point| {
                // A lamp above the ground plane sends no light through it (a ray towards
                // the part of its sphere below the plane would; none in practice).
                let lamp_height = point.p[2] + disk.direction[2] * reach;
                point.above_ground &= occluders.ground.is_none_or(|z| lamp_height <= z);
                sample_prepared_suns(&point, &[disk], share, max_level, seed)
            },
        );
        total = total.plus(&one);
    }
    total
}

/// The index `i` with `cdf[i] <= u < cdf[i + 1]`, skipping empty bins.
fn pick(cdf: &[f64], u: f64) -> usize {
    let bins = cdf.len() - 1;
    let i = cdf.partition_point(|&c| c <= u).saturating_sub(1).min(bins - 1);
    // `u` can sit on the top of the last non-empty bin only through rounding.
    (0..=i).rev().find(|&j| cdf[j + 1] > cdf[j]).unwrap_or(i)
}

fn remainder(cdf: &[f64], i: usize, u: f64) -> f64 {
    let width = cdf[i + 1] - cdf[i];
    if width > 0.0 {
        ((u - cdf[i]) / width).clamp(0.0, 1.0 - f64::EPSILON)
    } else {
        0.5
    }
}

/// Where one strategy draws its directions.
enum Strategy<'a> {
    Environment(&'a TexelSampler),
    /// `(r + 1)/(2 pi) cos^r` about the axis (`r = 1`: the cosine lobe).
    Lobe {
        exponent: f64,
        axis: [f64; 3],
        e1: [f64; 3],
        e2: [f64; 3],
    },
}

impl<'a> Strategy<'a> {
    fn lobe(term: &LobeTerm) -> Strategy<'a> {
        let exponent = match term.lobe {
            Lobe::Diffuse => 1.0,
            Lobe::Phong { exponent } => exponent,
        };
        let (e1, e2) = frame_around(term.axis);
        Strategy::Lobe { exponent, axis: term.axis, e1, e2 }
    }

    fn sample(&self, u1: f64, u2: f64) -> [f64; 3] {
        match self {
            Strategy::Environment(sampler) => sampler.sample(u1, u2),
            Strategy::Lobe { exponent, axis, e1, e2 } => {
                let z = u1.powf(1.0 / (exponent + 1.0));
                let s = (1.0 - z * z).max(0.0).sqrt();
                let (sp, cp) = (TAU * u2).sin_cos();
                [0, 1, 2].map(|k| s * cp * e1[k] + s * sp * e2[k] + z * axis[k])
            }
        }
    }

    fn density(&self, w: [f64; 3]) -> f64 {
        match self {
            Strategy::Environment(sampler) => sampler.density(w),
            Strategy::Lobe { exponent, axis, .. } => {
                let z = dot(*axis, w);
                if z > 0.0 {
                    (exponent + 1.0) / TAU * z.powf(*exponent)
                } else {
                    0.0
                }
            }
        }
    }
}

/// Point `index` of the 2D Sobol' sequence (its first dimension is van der Corput's),
/// digitally shifted by `shift`.
fn sobol_02(index: u32, shift: [u32; 2]) -> (f64, f64) {
    let first = index.reverse_bits() ^ shift[0];
    let mut second = shift[1];
    let (mut v, mut n) = (1u32 << 31, index);
    while n != 0 {
        if n & 1 == 1 {
            second ^= v;
        }
        n >>= 1;
        v ^= v >> 1;
    }
    let unit = |x: u32| (f64::from(x) + 0.5) / 4_294_967_296.0;
    (unit(first), unit(second))
}

/// SplitMix64: the per-pixel, per-replicate, per-strategy shifts.
fn split_mix(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The integral of [`super::integrate_point`] at an already prepared point, by importance
/// sampling (see the module doc), to `tolerance` with at most `max_level` refinements.
/// `seed` makes the pixel's randomisation reproducible.
pub(super) fn sample_prepared(
    point: &PreparedPoint,
    light: &LightModel,
    environment: Option<&TexelSampler>,
    tolerance: f64,
    max_level: u32,
    seed: u64,
) -> PointEstimate {
    let mut strategies: Vec<Strategy> = environment.map(Strategy::Environment).into_iter().collect();
    strategies.extend(point.terms.iter().map(Strategy::lobe));
    let estimator = Estimator { point, light, strategies };
    pilot_then_fresh(tolerance, max_level, seed, 0x5a5a_5a5a_5a5a_5a5a, |level, seed| estimator.run(level, seed))
}

/// A pilot estimate at [`PILOT_LEVEL`], then a fresh one at the level it predicts for
/// `tolerance` (at most `max_level`), randomised from `seed ^ salt`. Error falls like
/// `N^-1/2` (or faster where the integrand is smooth), so the level that reaches the
/// tolerance is predicted from the pilot's; the final estimate uses fresh randomisations
/// because stopping on an estimate's own spread biases it (measured: +4e-4 on
/// sphere-over-plane, where agreeing replicates are the brighter ones).
fn pilot_then_fresh(
    tolerance: f64,
    max_level: u32,
    seed: u64,
    salt: u64,
    run: impl Fn(u32, u64) -> PointEstimate,
) -> PointEstimate {
    let pilot_level = PILOT_LEVEL.min(max_level);
    let pilot = run(pilot_level, seed);
    let needed = if pilot.error > tolerance { (pilot.error / tolerance).powi(2).log2().ceil() as u32 } else { 0 };
    let mut out = run(pilot_level.saturating_add(needed).min(max_level), split_mix(&mut (seed ^ salt)));
    out.evaluations += pilot.evaluations;
    out.converged = out.error <= tolerance;
    out
}

/// `integral over each sun's disk of L V BRDF dw`, summed over `suns`, at a prepared
/// point: directions uniform over each disk (randomised Sobol' points mapped by solid
/// angle), each with the exact visibility of [`Estimator::integrand`]. The same pilot and
/// fresh final estimate as [`sample_point`].
pub(super) fn sample_prepared_suns(
    point: &PreparedPoint,
    suns: &[SunLight],
    tolerance: f64,
    max_level: u32,
    seed: u64,
) -> PointEstimate {
    let estimator = Estimator { point, light: &LightModel::Direct(&Light::Constant([1.0; 3])), strategies: Vec::new() };
    let run = |level: u32, seed: u64| -> PointEstimate {
        let points = BASE_POINTS << level;
        let mut state = seed;
        let mut means = [[0.0f64; 3]; REPLICATES];
        for mean in &mut means {
            for sun in suns {
                let (e1, e2) = frame_around(sun.direction);
                let one_minus_cos = 1.0 - sun.half_angle.cos();
                let bits = split_mix(&mut state);
                let shift = [bits as u32, (bits >> 32) as u32];
                let mut sum = [0.0f64; 3];
                for index in 0..points {
                    let (u1, u2) = sobol_02(index as u32, shift);
                    let z = 1.0 - one_minus_cos * u1;
                    let s = (1.0 - z * z).max(0.0).sqrt();
                    let (sp, cp) = (TAU * u2).sin_cos();
                    let w = [0, 1, 2].map(|k| s * cp * e1[k] + s * sp * e2[k] + z * sun.direction[k]);
                    if let Some(value) = estimator.integrand(w) {
                        for k in 0..3 {
                            sum[k] += value[k];
                        }
                    }
                }
                let power = sun.disk_integral();
                for k in 0..3 {
                    mean[k] += power[k] * sum[k] / points as f64;
                }
            }
        }
        summarise(&means, level, points * suns.len() * REPLICATES)
    };
    pilot_then_fresh(tolerance, max_level, seed, 0xa5a5_a5a5_a5a5_a5a5, run)
}

/// The mean of the replicates and twice its standard error (largest channel).
fn summarise(means: &[[f64; 3]; REPLICATES], level: u32, evaluations: usize) -> PointEstimate {
    let estimate = [0, 1, 2].map(|k| means.iter().map(|m| m[k]).sum::<f64>() / REPLICATES as f64);
    let error = (0..3)
        .map(|k| {
            let spread: f64 = means.iter().map(|m| (m[k] - estimate[k]).powi(2)).sum();
            2.0 * (spread / (REPLICATES * (REPLICATES - 1)) as f64).sqrt()
        })
        .fold(0.0, f64::max);
    PointEstimate { rgb: estimate, error, level, converged: false, meridians: 0, evaluations }
}

/// Level of the pilot estimate that chooses the final level: `2 * BASE_POINTS` points
/// per strategy and replicate.
const PILOT_LEVEL: u32 = 1;

/// The multiple-importance-sampling estimator at one point.
struct Estimator<'a> {
    point: &'a PreparedPoint<'a>,
    light: &'a LightModel<'a>,
    strategies: Vec<Strategy<'a>>,
}

impl Estimator<'_> {
    /// `light x visibility x BRDF` along unit `w`, or `None` where it is 0.
    fn integrand(&self, w: [f64; 3]) -> Option<[f64; 3]> {
        let point = self.point;
        let brdf = lobe_sum(&point.terms, w);
        if brdf == [0.0; 3] || !point.sees(w) {
            return None;
        }
        if let Some(field) = point.field {
            // A point lamp's reach is along the direction; the walk's is horizontal.
            let reach = point.reach * w[0].hypot(w[1]);
            if horizon_reaches_within(field, point.p, w[1].atan2(w[0]), w[2].clamp(-1.0, 1.0).asin(), reach) {
                return None;
            }
        }
        let l = self.light.radiance(w);
        Some([0, 1, 2].map(|k| l[k] * brdf[k]))
    }

    /// The estimate from `BASE_POINTS * 2^level` points per strategy and replicate, with
    /// the randomisations drawn from `seed`; its error is twice the standard error of the
    /// replicates' mean (largest channel).
    fn run(&self, level: u32, seed: u64) -> PointEstimate {
        let points = BASE_POINTS << level;
        let mut state = seed;
        let mut means = [[0.0f64; 3]; REPLICATES];
        let mut evaluations = 0;
        for mean in &mut means {
            let mut sum = [0.0f64; 3];
            for strategy in &self.strategies {
                let bits = split_mix(&mut state);
                let shift = [bits as u32, (bits >> 32) as u32];
                for index in 0..points {
                    let (u1, u2) = sobol_02(index as u32, shift);
                    let w = strategy.sample(u1, u2);
                    evaluations += 1;
                    if let Some(value) = self.integrand(w) {
                        let density: f64 = self.strategies.iter().map(|s| s.density(w)).sum();
                        if density > 0.0 {
                            for k in 0..3 {
                                sum[k] += value[k] / density;
                            }
                        }
                    }
                }
            }
            *mean = sum.map(|v| v / points as f64);
        }
        summarise(&means, level, evaluations)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sobol_points_are_a_02_net() {
        // Every 2^k x 2^(8-k) box of the first 256 unshifted points holds exactly one.
        let points: Vec<(f64, f64)> = (0..256).map(|i| sobol_02(i, [0, 0])).collect();
        for k in 0..=8 {
            let (nx, ny) = (1usize << k, 1usize << (8 - k));
            let mut seen = vec![0; 256];
            for &(x, y) in &points {
                seen[(x * nx as f64) as usize * ny + (y * ny as f64) as usize] += 1;
            }
            assert!(seen.iter().all(|&c| c == 1), "boxes {nx}x{ny}");
        }
    }

    #[test]
    fn texel_density_integrates_to_one_and_matches_the_draws() {
        let (width, height) = (16, 8);
        let texels = (0..width * height).map(|i| if i == 37 { [50.0, 10.0, 1.0] } else { [0.2, 0.3, 0.4] }).collect();
        let map = EnvironmentMap { file: "sky.exr".into(), width, height, texels };
        let sampler = TexelSampler::new(&map).unwrap();
        // The density integrated over the sphere by texels (it is constant on each).
        let total: f64 = (0..height)
            .flat_map(|r| (0..width).map(move |c| (r, c)))
            .map(|(r, c)| {
                let u = (c as f64 + 0.5) / width as f64;
                let v = 1.0 - (r as f64 + 0.5) / height as f64;
                sampler.density(crate::scene::light::equirectangular_to_direction(u, v)) * map.texel_solid_angle(r)
            })
            .sum();
        assert!((total - 1.0).abs() < 1e-12, "density integrates to {total}");
        // Draws land in texels at their probabilities: within a few points of 2^14 (a texel is
        // a box of the unit square not aligned with the net's, so its count may be a few off).
        let n = 1 << 14;
        let mut counts = vec![0usize; width * height];
        for i in 0..n {
            let (u1, u2) = sobol_02(i, [0x1234_5678, 0x9abc_def0]);
            let w = sampler.sample(u1, u2);
            let [u, v] = direction_to_equirectangular(w);
            let r = (((1.0 - v) * height as f64) as usize).min(height - 1);
            let c = ((u * width as f64) as usize).min(width - 1);
            counts[r * width + c] += 1;
        }
        for (i, &count) in counts.iter().enumerate() {
            let expected = sampler.texel_probability[i] * n as f64;
            assert!(
                (count as f64 - expected).abs() <= 4.0 + 0.02 * expected,
                "texel {i}: {count} drawn, {expected} expected"
            );
        }
    }
}
