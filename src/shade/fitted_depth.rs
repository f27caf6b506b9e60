//! The log depth of a sphere's cap and of a height-field slice's horizon band, fitted per
//! size so that one of them shades a diffuse receiver as the exact answer does
//! (`--fitted-depths`, on by default).
//!
//! Paper 000 gives every cap (Eq. 26) and every slice (Eq. 15) the depth `log(eps)`. At
//! order n they are band-limited before `exp*`, and how much light they then take depends
//! on their size:
//! - A cap, or a band of horizon, narrower than the order resolves is smeared into a
//!   shallow dip, where `exp` is nearly linear. What it then takes from a diffuse receiver
//!   is its depth times its cosine-weighted solid angle (the bands a clamped cosine holds
//!   survive truncation), so the right depth tends to -1. At `log(0.1) = -2.3`, every
//!   small or distant blocker and every low horizon takes 2.3 times the light it blocks:
//!   on Blender scenes the whole floor came out 0.02-0.05 of an open floor too dark at
//!   order 4 against converged Cycles, and no eps fitted both them and the analytic
//!   scenes.
//! - A wide cap or a high horizon stays deep enough that the exponential and the overlap
//!   floor clamp it at about `eps`.
//!
//! So the depth is fitted per size, on a white diffuse receiver facing +Z under a
//! constant light, shaded as [`super::ShadingKernel`] shades it (tangent plane, diffuse
//! lobe, `exp*` with the overlap floor), relative to the open receiver, in the
//! least-squares sense, with the depth in `[log(eps), 0)`:
//! - caps per angular radius `alpha`, against the unblocked share `1 - `
//!   [`cap_form_factor`] over cap centres from the zenith down to the horizon (the kernel
//!   sees every cap whose centre is above the tangent plane). At order 4, eps 0.1: -0.97
//!   for small caps, -1.5 at 30 degrees, `log(eps)` from about 57 degrees on;
//! - horizon bands per width `w` above the receiver's tangent plane, the horizontal for
//!   this receiver (what lies below stays at `log(eps)`: the surface itself), against
//!   `cos^2 w`, the unblocked share under a horizon at `w` all around, through the
//!   kernel's own wedge operator. A tilted receiver's bands start at its own tangent
//!   plane, below the horizontal on its downhill side (`add_horizon_slices`); started at
//!   the horizontal, the wedge between them stayed at full depth and darkened every slope
//!   (`dunes`' sand 0.040 of an open floor too dark against Cycles' direct light, 0.023
//!   after).
//! - The depth a band needs depends on how much of the azimuth circle the horizons cover,
//!   not only on its width: a band along a few azimuths is smeared across the others at
//!   order n, and `exp` takes it more nearly linearly, as it takes a narrow cap. So the
//!   band table has a row per coverage (all W azimuths, half, a quarter, down to one,
//!   [`band_coverages`]), each fitted under horizons at `w` along that share of the
//!   azimuths, open along the rest, against their exact share. A pixel reads the rows
//!   either side of its own coverage ([`horizon_coverage`]: the mean of `sin^2` of its
//!   bands' widths over the largest), interpolated in log coverage. A slope's bands start
//!   at its tangent plane, so even under a uniform horizon they cover a crescent: at
//!   order 4, a slope of 30 to 40 degrees under a horizon at 20 degrees took 4 to 5 % too
//!   little light with the all-around row alone, and takes within 2 % of the exact share
//!   with its coverage's (`a_slope_under_a_raised_horizon_takes_its_share`). At order 4:
//!   -2.3 for a 60-degree band all around, -1.75 along half the azimuths, -0.9 along one.
//!
//! Both executors read the same tables (`T_CAP_DEPTH`, `T_BAND_DEPTH` and
//! `T_BAND_COVERAGE` on the GPU).

use super::exponentiator::Exponentiator;
use crate::logsh::minimise::scan_then_golden;
use crate::logsh::{cap_log_zh, lobe_log_zh, nlp_slice, nlp_slice_of_sine, Lobe, WedgeOperator};
use crate::memo::Memo;
use crate::sh::{add_rotated_zonal, coefficient_count, ExpMethod, Real, MAX_COEFFICIENTS};
use rayon::prelude::*;
use std::f64::consts::FRAC_PI_2;
use std::sync::Arc;

/// Intervals of each table over its angle (a cap's radius, a band's width) in
/// `[0, pi/2]`: 1.4 degrees apart.
pub const DEPTH_INTERVALS: usize = 64;

/// Cap elevations fitted per radius.
const ELEVATIONS: usize = 8;

/// The shallowest log depth searched: a cap or band always takes some light (an eps
/// above `e^-0.05` searches nothing but `log(eps)`).
const SHALLOWEST: f64 = -0.05;

/// The depths searched at `epsilon`: from `log(eps)` to [`SHALLOWEST`].
fn depth_range(epsilon: f64) -> (f64, f64) {
    (epsilon.ln(), SHALLOWEST.max(epsilon.ln()))
}

/// What the fitted tables depend on: the order, eps, whether the tangent plane is
/// clamped, `exp*` (method and HYB threshold, as bits so that it hashes) and the height
/// field's azimuthal directions (0 without one).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct DepthKey {
    pub order: usize,
    pub epsilon_bits: u64,
    pub tangent_occlusion: bool,
    pub exp: ExpMethod,
    pub hyb_threshold_bits: u64,
    pub directions: usize,
}

/// The fitted log depths, `DEPTH_INTERVALS + 1` of each.
#[derive(Clone, Debug, PartialEq)]
pub struct FittedDepths {
    /// Per cap radius.
    pub caps: Vec<f64>,
    /// Per horizon band width, one row per coverage of [`band_coverages`] (rows of
    /// `DEPTH_INTERVALS + 1`, concatenated); `log(eps)` throughout without a height field.
    pub bands: Vec<f64>,
}

/// Fits the tables of `key`, or returns the ones this process already fitted: once per
/// setting, not once per frame.
pub fn fitted_depths(key: DepthKey, exp: &Exponentiator) -> Arc<FittedDepths> {
    static FITTED: Memo<DepthKey, FittedDepths> = Memo::new();
    FITTED.get_or_build(key, || {
        let epsilon = f64::from_bits(key.epsilon_bits);
        let bands = if key.directions == 0 {
            vec![epsilon.ln(); DEPTH_INTERVALS + 1]
        } else {
            fit_band_depths(key.order, epsilon, exp, &WedgeOperator::new(key.order, key.directions))
        };
        FittedDepths { caps: fit_cap_depths(key.order, epsilon, key.tangent_occlusion, exp), bands }
    })
}

/// `DEPTH_INTERVALS + 1` log depths at `alpha = k pi / (2 DEPTH_INTERVALS)` for
/// `order`, with the tangent plane (when clamped) and the diffuse lobe at `epsilon` and
/// `exp*` computed by `exp`.
pub fn fit_cap_depths(order: usize, epsilon: f64, tangent_occlusion: bool, exp: &Exponentiator) -> Vec<f64> {
    let receiver = DiffuseReceiver::new(order, epsilon, tangent_occlusion, exp);
    let open = receiver.shade(None);
    (0..=DEPTH_INTERVALS)
        .into_par_iter()
        .map(|k| {
            // Radius 0 takes the smallest nonzero one's depth: the limit, where the cap's
            // share is linear in its depth.
            let alpha = FRAC_PI_2 * k.max(1) as f64 / DEPTH_INTERVALS as f64;
            let unblocked: Vec<(f64, f64)> = (0..ELEVATIONS)
                .map(|j| {
                    let beta = FRAC_PI_2 * (j as f64 + 0.5) / ELEVATIONS as f64;
                    (beta, 1.0 - cap_form_factor(alpha, beta))
                })
                .collect();
            let squared_error = |depth: f64| {
                unblocked
                    .iter()
                    .map(|&(beta, share)| (receiver.shade(Some(Cap { depth, alpha, beta })) / open - share).powi(2))
                    .sum::<f64>()
            };
            minimise(squared_error, depth_range(epsilon))
        })
        .collect()
}

/// The sectors the band table has a row for with `directions` azimuths: how many of them
/// the horizons span, from all of them halving down to one.
fn band_sectors(directions: usize) -> impl Iterator<Item = usize> {
    std::iter::successors(Some(directions), |&s| (s > 1).then_some(s / 2))
}

/// The horizon coverage of each row of the band table with `directions` azimuths: the
/// share of them its sector spans ([`band_sectors`]).
pub fn band_coverages(directions: usize) -> Vec<f64> {
    band_sectors(directions).map(|s| s as f64 / directions as f64).collect()
}

/// Rows of `DEPTH_INTERVALS + 1` log depths of a horizon band at widths `w = k pi / (2
/// DEPTH_INTERVALS)` for `order`, through `wedge`, with the diffuse lobe at `epsilon`, one
/// per coverage of [`band_coverages`]: horizons at `w` along that share of the azimuths,
/// open along the rest, against their exact unblocked share.
pub fn fit_band_depths(order: usize, epsilon: f64, exp: &Exponentiator, wedge: &WedgeOperator) -> Vec<f64> {
    let receiver = DiffuseReceiver::new(order, epsilon, false, exp);
    let log_epsilon = epsilon.ln();
    let directions = wedge.directions;
    let mut open_slice = [0.0; crate::sh::MAX_ORDER];
    nlp_slice(order, log_epsilon, 0.0, &mut open_slice[..order]);
    let sector_bowl = |depth: f64, width: f64, sector: usize| {
        let mut slice = [0.0; crate::sh::MAX_ORDER];
        banded_slice(order, log_epsilon, &[depth; 2], 0.0, width, &mut slice[..order]);
        let slices: Vec<f64> = (0..directions)
            .flat_map(|k| if k < sector { slice[..order].to_vec() } else { open_slice[..order].to_vec() })
            .collect();
        let mut visibility = [0.0; MAX_COEFFICIENTS];
        wedge.accumulate(&slices, &mut visibility[..coefficient_count(order)]);
        receiver.shade_with(&visibility)
    };
    // The cosine-weighted share horizons at `width` along `sector` azimuths block, the
    // elevation falling linearly to 0 across the wedges at either end.
    let blocked = |width: f64, sector: usize| {
        let full = width.sin().powi(2);
        if sector >= directions {
            return full;
        }
        let ramp = 0.5 - (2.0 * width).sin() / (4.0 * width);
        ((sector - 1) as f64 * full + 2.0 * ramp) / directions as f64
    };
    let open = sector_bowl(log_epsilon, 0.0, directions);
    band_sectors(directions)
        .flat_map(|sector| {
            (0..=DEPTH_INTERVALS)
                .into_par_iter()
                .map(|k| {
                    // Width 0 takes the smallest nonzero one's depth, as a cap's radius does.
                    let width = FRAC_PI_2 * k.max(1) as f64 / DEPTH_INTERVALS as f64;
                    let unblocked = 1.0 - blocked(width, sector);
                    minimise(
                        |depth| (sector_bowl(depth, width, sector) / open - unblocked).powi(2),
                        depth_range(epsilon),
                    )
                })
                .collect::<Vec<f64>>()
        })
        .collect()
}

/// The share of the azimuths a pixel's horizons cover: the mean of `sin^2` of its bands'
/// widths over the largest (1 for a bowl, `1 / W` for one azimuth's band alone), from the
/// tangents of each band's `bases` and top `sigmas`.
pub fn horizon_coverage(bases: &[f64], sigmas: &[f64]) -> f64 {
    let (mut sum, mut most) = (0.0f64, 0.0f64);
    for (&base, &sigma) in bases.iter().zip(sigmas) {
        let width = (sigma.atan() - base.atan()).max(0.0);
        let blocked = width.sin().powi(2);
        sum += blocked;
        most = most.max(blocked);
    }
    if most > 0.0 {
        sum / (most * bases.len() as f64)
    } else {
        1.0
    }
}

/// The band table for a pixel whose horizons cover `coverage` of the azimuths: the rows of
/// [`fit_band_depths`] either side of it, interpolated in `log(coverage)`, into `out`.
pub fn band_depths_for<T: Real>(rows: &[T], coverages: &[f64], coverage: f64, out: &mut [T]) {
    let width = DEPTH_INTERVALS + 1;
    let row = |r: usize| &rows[r * width..(r + 1) * width];
    debug_assert_eq!(rows.len(), coverages.len() * width, "one row of widths per coverage");
    let last = coverages.len() - 1;
    if coverage >= coverages[0] || last == 0 {
        out.copy_from_slice(row(0));
        return;
    }
    let r = coverages.iter().position(|&c| c <= coverage).unwrap_or(last).max(1);
    let (hi, lo) = (coverages[r - 1], coverages[r]);
    let t = ((coverage.max(lo) / lo).ln() / (hi / lo).ln()).clamp(0.0, 1.0);
    let t = T::of(t);
    for ((o, &a), &b) in out.iter_mut().zip(row(r)).zip(row(r - 1)) {
        *o = a + t * (b - a);
    }
}

/// The log depth for an angle (a cap's radius, a band's width, radians), interpolated
/// linearly in a fitted table: the lookup both executors make (`fitted_depth` in
/// `shaders/sh.wgsl`).
pub fn depth_at<T: Real>(log_depths: &[T], angle: T) -> T {
    let intervals = log_depths.len() - 1;
    let x = (angle / T::of(FRAC_PI_2)).max(T::zero()).min(T::one()) * T::of(intervals as f64);
    let k = x.to_usize().unwrap_or(0).min(intervals - 1);
    let t = x - T::of(k as f64);
    log_depths[k] + t * (log_depths[k + 1] - log_depths[k])
}

/// The depth of a cap of fitted depth `depth` whose sphere owns `share` of its solid
/// angle ([`super::blocker_tree::overlap_shares`]): `depth (1 - lambda (1 - share))`, with
/// `lambda = (log(eps) - depth) / (log(eps) - shallowest)` in `[0, 1]`, `shallowest` the
/// table's depth for the smallest caps. A narrow cap (`lambda` 1), which `exp` takes
/// linearly, blocks `share` of what it would alone, so overlapping narrow caps together
/// take their union; a wide one (`lambda` 0, the depth `log(eps)`) keeps its depth, as
/// the overlap floor already clamps where several cover a direction. The WGSL pass and
/// the packets compute the same (`overlapped_depth` in `shaders/logsh.wgsl`).
#[inline(always)]
pub fn overlapped_depth<T: Real>(depth: T, share: T, log_epsilon: T, shallowest: T) -> T {
    let range = log_epsilon - shallowest;
    if !(range < T::zero()) {
        return depth;
    }
    let lambda = ((log_epsilon - depth) / range).max(T::zero()).min(T::one());
    depth * (T::one() - lambda * (T::one() - share))
}

/// The log visibility of one azimuthal slice whose horizon lies at elevation `sigma`:
/// `log(eps)` up to `base` (the tangent plane's elevation, or the horizontal where the
/// tangent plane is not folded in), and the band from `base` to `sigma` at the depth
/// `bands` fits for its width (paper 000 Eq. 15 with two depths; `nlp_slice` is linear in
/// its depth). With every band at `log(eps)` it is [`nlp_slice`] itself.
pub fn banded_slice<T: Real>(order: usize, log_epsilon: T, bands: &[T], base: T, sigma: T, out: &mut [T]) {
    if sigma <= base {
        nlp_slice(order, log_epsilon, sigma, out);
        return;
    }
    let mut below = [T::zero(); crate::sh::MAX_ORDER];
    nlp_slice(order, T::one(), base, &mut below[..order]);
    nlp_slice(order, T::one(), sigma, out);
    let depth = depth_at(bands, sigma - base);
    for (o, b) in out[..order].iter_mut().zip(&below[..order]) {
        *o = log_epsilon * *b + depth * (*o - *b);
    }
}

/// [`banded_slice`] with `base` and `sigma` given by their tangents (each in
/// `(-pi/2, pi/2)`), as the horizon march and the tangent plane give them: the sines come
/// from the tangents and the band's width from their difference, one arctangent where
/// [`banded_slice`] takes three trigonometric functions.
pub fn banded_slice_of_tangents<T: Real>(
    order: usize,
    log_epsilon: T,
    bands: &[T],
    base: f64,
    sigma: f64,
    out: &mut [T],
) {
    let sine = |t: f64| if t.abs() < 1e150 { t / (1.0 + t * t).sqrt() } else { t.signum() };
    if sigma <= base {
        nlp_slice_of_sine(order, log_epsilon, T::of(sine(sigma)), out);
        return;
    }
    let mut below = [T::zero(); crate::sh::MAX_ORDER];
    nlp_slice_of_sine(order, T::one(), T::of(sine(base)), &mut below[..order]);
    nlp_slice_of_sine(order, T::one(), T::of(sine(sigma)), out);
    // The difference of the two angles, by the tangent of a difference where that
    // formula holds (the band narrower than pi/2; always where base >= 0).
    let below_product = 1.0 + sigma * base;
    let width = if below_product > 0.0 && below_product.is_finite() {
        ((sigma - base) / below_product).atan()
    } else {
        sigma.atan() - base.atan()
    };
    let depth = depth_at(bands, T::of(width.max(0.0)));
    for (o, b) in out[..order].iter_mut().zip(&below[..order]) {
        *o = log_epsilon * *b + depth * (*o - *b);
    }
}

/// The share of a diffuse receiver's light a cap of angular radius `alpha` at elevation
/// `beta` from its normal blocks: `integral over the cap of max(cos theta, 0) / pi`,
/// `sin^2(alpha) cos(beta)` when the cap lies wholly above the tangent plane. Midpoint
/// rule in polar coordinates about the cap's axis, exact to about 1e-5.
pub fn cap_form_factor(alpha: f64, beta: f64) -> f64 {
    if alpha + beta <= FRAC_PI_2 {
        return alpha.sin().powi(2) * beta.cos();
    }
    let (rings, sectors) = (96, 192);
    let (sin_beta, cos_beta) = beta.sin_cos();
    let cos_phi: Vec<f64> =
        (0..sectors).map(|j| (std::f64::consts::TAU * (j as f64 + 0.5) / sectors as f64).cos()).collect();
    let mut sum = 0.0;
    for i in 0..rings {
        let rho = alpha * (i as f64 + 0.5) / rings as f64;
        let (sin_rho, cos_rho) = rho.sin_cos();
        for cos_phi in &cos_phi {
            // The direction at (rho, phi) about the axis (sin beta, 0, cos beta): its z.
            let z = cos_rho * cos_beta - sin_rho * cos_phi * sin_beta;
            sum += z.max(0.0) * sin_rho;
        }
    }
    sum * (alpha / rings as f64) * (std::f64::consts::TAU / sectors as f64) / std::f64::consts::PI
}

/// One cap: its log depth, angular radius and elevation from the receiver's normal.
#[derive(Clone, Copy)]
struct Cap {
    depth: f64,
    alpha: f64,
    beta: f64,
}

/// A white diffuse receiver facing +Z under a constant unit light, shaded as the kernel
/// shades it.
struct DiffuseReceiver<'a> {
    order: usize,
    log_epsilon: f64,
    tangent: Option<Vec<f64>>,
    diffuse: Vec<f64>,
    log_peak: f64,
    exp: &'a Exponentiator,
}

impl<'a> DiffuseReceiver<'a> {
    fn new(order: usize, epsilon: f64, tangent_occlusion: bool, exp: &'a Exponentiator) -> Self {
        let tangent = tangent_occlusion.then(|| {
            let mut zonal = vec![0.0; order];
            cap_log_zh(order, epsilon.ln(), FRAC_PI_2, &mut zonal);
            zonal
        });
        Self {
            order,
            log_epsilon: epsilon.ln(),
            tangent,
            diffuse: lobe_log_zh(order, Lobe::Diffuse, epsilon),
            log_peak: Lobe::Diffuse.peak().ln(),
            exp,
        }
    }

    /// The radiance it sends, with one cap or none.
    fn shade(&self, cap: Option<Cap>) -> f64 {
        let order = self.order;
        let count = coefficient_count(order);
        let mut visibility = [0.0; MAX_COEFFICIENTS];
        if let Some(tangent) = &self.tangent {
            add_rotated_zonal(order, tangent, 1.0, [0.0, 0.0, -1.0], &mut visibility[..count]);
        }
        if let Some(Cap { depth, alpha, beta }) = cap {
            let mut zonal = [0.0; crate::sh::MAX_ORDER];
            cap_log_zh(order, depth, alpha, &mut zonal[..order]);
            add_rotated_zonal(order, &zonal[..order], 1.0, [beta.sin(), 0.0, beta.cos()], &mut visibility[..count]);
        }
        self.shade_with(&visibility)
    }

    /// The radiance it sends under the log visibility `visibility` (`order^2` entries,
    /// zero-padded to `MAX_COEFFICIENTS`).
    fn shade_with(&self, visibility: &[f64; MAX_COEFFICIENTS]) -> f64 {
        let count = coefficient_count(self.order);
        let mut f = *visibility;
        add_rotated_zonal(self.order, &self.diffuse, 1.0, [0.0, 0.0, 1.0], &mut f[..count]);
        let first = self.exp.exp_first(&f[..count], Some((&visibility[..count], self.log_epsilon)), self.log_peak);
        // A constant unit light has the single coefficient sqrt(4 pi).
        first * (4.0 * std::f64::consts::PI).sqrt()
    }
}

/// The minimum of `error` over `range`: a scan of 12 steps, then golden-section search
/// around the best to 1e-3 of the range.
fn minimise(error: impl Fn(f64) -> f64, range: (f64, f64)) -> f64 {
    scan_then_golden(error, range, 12, 11).refined
}

/// [`banded_slice_of_tangents`] for a run of azimuths in f32: `bases[k]` and `sigmas[k]`
/// give slice `k`, written to `out[k * order..(k + 1) * order]`. Where the processor has
/// AVX2 and FMA, eight azimuths per pass (`slice_lanes`: the same formulas, the band's
/// width by an arctangent polynomial good to 2e-7 rad, which the fitted table, 1.4
/// degrees between entries, cannot tell); elsewhere one by one.
pub fn banded_slices_of_tangents(
    order: usize,
    log_epsilon: f32,
    bands: &[f32],
    bases: &[f64],
    sigmas: &[f64],
    out: &mut [f32],
) {
    #[cfg(target_arch = "x86_64")]
    if *crate::x86::AVX2_FMA && bands.len() == DEPTH_INTERVALS + 1 && (1..=crate::sh::MAX_ORDER).contains(&order) {
        for ((base, sigma), out) in bases.chunks(8).zip(sigmas.chunks(8)).zip(out.chunks_mut(8 * order)) {
            // SAFETY: the processor has AVX2 and FMA, and AVX-512F and AVX-512VL for the wide
            // build; the table has its DEPTH_INTERVALS + 1 entries.
            unsafe {
                if *crate::x86::WIDE_REGISTERS {
                    slice_lanes::slices_wide(order, log_epsilon, bands, base, sigma, out)
                } else {
                    slice_lanes::slices(order, log_epsilon, bands, base, sigma, out)
                }
            };
        }
        return;
    }
    for (k, (base, sigma)) in bases.iter().zip(sigmas).enumerate() {
        banded_slice_of_tangents(order, log_epsilon, bands, *base, *sigma, &mut out[k * order..(k + 1) * order]);
    }
}

/// [`depth_at`] in eight AVX2 lanes, for angles in `[0, pi/2]`, from a table of
/// `DEPTH_INTERVALS + 1` depths: what the packets of caps and the lanes of slices read.
///
/// # Safety
/// The processor has AVX2 and FMA, and `depths` has `DEPTH_INTERVALS + 1` entries.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(crate) unsafe fn depth_at_lanes(depths: &[f32], angle: std::arch::x86_64::__m256) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    let intervals = DEPTH_INTERVALS as f32;
    let unit = _mm256_min_ps(
        _mm256_max_ps(_mm256_mul_ps(angle, _mm256_set1_ps(std::f32::consts::FRAC_2_PI)), _mm256_setzero_ps()),
        _mm256_set1_ps(1.0),
    );
    let x = _mm256_mul_ps(unit, _mm256_set1_ps(intervals));
    let k = _mm256_min_epi32(_mm256_cvttps_epi32(x), _mm256_set1_epi32(DEPTH_INTERVALS as i32 - 1));
    let t = _mm256_sub_ps(x, _mm256_cvtepi32_ps(k));
    let below = _mm256_i32gather_ps::<4>(depths.as_ptr(), k);
    let above = _mm256_i32gather_ps::<4>(depths.as_ptr(), _mm256_add_epi32(k, _mm256_set1_epi32(1)));
    _mm256_fmadd_ps(t, _mm256_sub_ps(above, below), below)
}

#[cfg(target_arch = "x86_64")]
mod slice_lanes {
    use super::depth_at_lanes;
    use crate::sh::basis::nlp_scale;
    use crate::x86::with_wide_registers;
    use std::arch::x86_64::*;

    /// Tangents beyond this are clamped to it (f32 squares them; the sine is 1 - 5e-37).
    const STEEPEST: f32 = 1e18;

    with_wide_registers! {
        /// Up to eight slices: `super::banded_slice_of_tangents` per lane.
        ///
        /// # Safety
        /// The processor has AVX2 and FMA (and AVX-512F and AVX-512VL for `slices_wide`),
        /// and `bands` has `DEPTH_INTERVALS + 1` entries.
        pub unsafe fn slices / slices_wide(
            order: usize,
            log_epsilon: f32,
            bands: &[f32],
            bases: &[f64],
            sigmas: &[f64],
            out: &mut [f32],
        ) {
            let count = bases.len();
            let lanes = |values: &[f64]| {
                let mut v = [0.0f32; 8];
                for (o, x) in v.iter_mut().zip(values) {
                    *o = (*x as f32).clamp(-STEEPEST, STEEPEST);
                }
                _mm256_loadu_ps(v.as_ptr())
            };
            let (base, sigma) = (lanes(bases), lanes(sigmas));
            let one = _mm256_set1_ps(1.0);
            let sine = |t: __m256| _mm256_div_ps(t, _mm256_sqrt_ps(_mm256_fmadd_ps(t, t, one)));
            let banded = _mm256_cmp_ps::<_CMP_GT_OQ>(sigma, base);
            // The band's width from tan(sigma - base) where there is a band; a band wider than
            // pi/2 (a negative base below a steep horizon) takes the widest depth, as the
            // table's clamp gives it on the scalar path.
            let below_product = _mm256_fmadd_ps(sigma, base, one);
            let tangent = _mm256_div_ps(_mm256_sub_ps(sigma, base), below_product);
            let narrow = _mm256_cmp_ps::<_CMP_GT_OQ>(below_product, _mm256_setzero_ps());
            let width = _mm256_blendv_ps(
                _mm256_set1_ps(std::f32::consts::FRAC_PI_2),
                atan(_mm256_and_ps(_mm256_and_ps(banded, narrow), tangent)),
                narrow,
            );
            let depth = depth_at_lanes(bands, width);
            let (below, above) = (legendre(sine(base), order), legendre(sine(sigma), order));
            let log_epsilon = _mm256_set1_ps(log_epsilon);
            let mut slice = [_mm256_setzero_ps(); crate::sh::MAX_ORDER];
            for (l, out) in slice.iter_mut().enumerate().take(order) {
                // nlp_scale(l) times the integral of P^_l up to sin(angle) (nlp_slice).
                let scale = _mm256_set1_ps(nlp_scale(l) as f32);
                let integral = |p: &[__m256; crate::sh::MAX_ORDER + 2], s: __m256| {
                    let value = if l == 0 {
                        _mm256_add_ps(s, one)
                    } else {
                        _mm256_mul_ps(_mm256_sub_ps(p[l + 1], p[l - 1]), _mm256_set1_ps(1.0 / (2 * l + 1) as f32))
                    };
                    _mm256_mul_ps(scale, value)
                };
                let (b, a) = (integral(&below.0, below.1), integral(&above.0, above.1));
                let banded_value = _mm256_fmadd_ps(log_epsilon, b, _mm256_mul_ps(depth, _mm256_sub_ps(a, b)));
                *out = _mm256_blendv_ps(_mm256_mul_ps(log_epsilon, a), banded_value, banded);
            }
            for (l, values) in slice.iter().enumerate().take(order) {
                let mut v = [0.0f32; 8];
                _mm256_storeu_ps(v.as_mut_ptr(), *values);
                for (k, value) in v.iter().enumerate().take(count) {
                    out[k * order + l] = *value;
                }
            }
        }
    }

    /// `P_0 ..= P_order` at `s` (clamped to `[-1, 1]`), and the clamped `s`.
    #[inline(always)]
    unsafe fn legendre(s: __m256, order: usize) -> ([__m256; crate::sh::MAX_ORDER + 2], __m256) {
        let one = _mm256_set1_ps(1.0);
        let s = _mm256_min_ps(_mm256_max_ps(s, _mm256_set1_ps(-1.0)), one);
        let mut p = [one; crate::sh::MAX_ORDER + 2];
        p[1] = s;
        for l in 2..=order {
            let (a, b) = ((2 * l - 1) as f32 / l as f32, (l - 1) as f32 / l as f32);
            p[l] = _mm256_fmsub_ps(
                _mm256_mul_ps(_mm256_set1_ps(a), s),
                p[l - 1],
                _mm256_mul_ps(_mm256_set1_ps(b), p[l - 2]),
            );
        }
        (p, s)
    }

    /// `atan` of each lane `>= 0`: `a p(a^2)` on `[0, 1]` (the polynomial of
    /// `crate::scene::light::atan2_fast`), `pi/2 - atan(1/x)` above; 2e-7 rad in f32.
    #[inline(always)]
    unsafe fn atan(x: __m256) -> __m256 {
        const P: [f32; 9] = [
            0.999_999_98,
            -0.333_330_37,
            0.199_918_72,
            -0.141_977_98,
            0.106_183_71,
            -0.074_568_55,
            0.042_137_62,
            -0.015_731_25,
            0.002_766_283_5,
        ];
        let one = _mm256_set1_ps(1.0);
        let above = _mm256_cmp_ps::<_CMP_GT_OQ>(x, one);
        let a = _mm256_blendv_ps(x, _mm256_div_ps(one, x), above);
        let t = _mm256_mul_ps(a, a);
        let mut p = _mm256_set1_ps(P[8]);
        for c in P[..8].iter().rev() {
            p = _mm256_fmadd_ps(p, t, _mm256_set1_ps(*c));
        }
        let angle = _mm256_mul_ps(p, a);
        _mm256_blendv_ps(angle, _mm256_sub_ps(_mm256_set1_ps(std::f32::consts::FRAC_PI_2), angle), above)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The slices of many azimuths at once (AVX2 lanes where present) against the f64
    /// slice of each: bands and none, below and above the horizontal, near-vertical and
    /// steeper than f32 squares, every order, a part-filled last group.
    #[test]
    fn slices_in_lanes_are_the_slices() {
        let epsilon = 0.1f64;
        let bands: Vec<f64> = (0..=DEPTH_INTERVALS).map(|k| -1.0 - 1.3 * k as f64 / DEPTH_INTERVALS as f64).collect();
        let bands32: Vec<f32> = bands.iter().map(|&b| b as f32).collect();
        let pairs = [
            (0.0, 0.3),
            (0.0, 0.0),
            (0.2, 0.1),
            (-0.4, 0.7),
            (0.5, 3.0),
            (0.0, 1e3),
            (1e20, 1e21),
            (-2.0, -1.0),
            (0.01, 0.011),
            (0.0, 57.0),
            (0.3, 0.3),
            (-3.0, 2.0),
            (-0.5, 5.0),
        ];
        let (bases, sigmas): (Vec<f64>, Vec<f64>) = pairs.iter().copied().unzip();
        let mut worst = 0.0f64;
        for order in 1..=crate::sh::MAX_ORDER {
            let mut got = vec![0.0f32; pairs.len() * order];
            banded_slices_of_tangents(order, epsilon.ln() as f32, &bands32, &bases, &sigmas, &mut got);
            for (k, (base, sigma)) in pairs.iter().enumerate() {
                let mut expected = vec![0.0f64; order];
                banded_slice_of_tangents(order, epsilon.ln(), &bands, *base, *sigma, &mut expected);
                for l in 0..order {
                    worst = worst.max((f64::from(got[k * order + l]) - expected[l]).abs());
                }
            }
        }
        // Log values of order 1 (log eps is -2.3); f32 rounding of the sines and the
        // Legendre recurrence.
        assert!(worst < 2e-5, "worst {worst:e}");
    }

    fn table(order: usize, epsilon: f64) -> Vec<f64> {
        fit_cap_depths(order, epsilon, true, &Exponentiator::new(order, ExpMethod::Quad, 1.0))
    }

    #[test]
    fn small_caps_tend_to_depth_minus_one_and_wide_ones_to_log_eps() {
        for order in [4, 6, 8] {
            let depths = table(order, 0.1);
            // The linear limit: a small cap takes its depth times its cosine-weighted
            // solid angle, so -1 takes what it blocks.
            assert!((depths[1] + 1.0).abs() < 0.25, "order {order}: small cap {}", depths[1]);
            let widest = depths[DEPTH_INTERVALS];
            assert!(widest < 0.1f64.ln() + 0.1, "order {order}: hemisphere {widest}");
            for d in &depths {
                assert!((0.1f64.ln() - 1e-9..=SHALLOWEST + 1e-9).contains(d), "order {order}: {d}");
            }
        }
    }

    #[test]
    fn a_fitted_cap_shades_closer_to_the_closed_form_than_log_eps() {
        let order = 4;
        let exp = Exponentiator::new(order, ExpMethod::Quad, 1.0);
        let depths = fit_cap_depths(order, 0.1, true, &exp);
        let receiver = DiffuseReceiver::new(order, 0.1, true, &exp);
        let open = receiver.shade(None);
        let (mut fitted, mut constant) = (0.0, 0.0);
        for degrees in [3.0, 10.0, 20.0, 35.0, 50.0] {
            let alpha: f64 = f64::to_radians(degrees);
            for beta in [0.0, 0.3, 0.6] {
                if alpha + beta > FRAC_PI_2 {
                    continue;
                }
                let closed_form = 1.0 - alpha.sin().powi(2) * f64::cos(beta);
                let at = |depth| (receiver.shade(Some(Cap { depth, alpha, beta })) / open - closed_form).abs();
                fitted += at(depth_at(&depths, alpha));
                constant += at(0.1f64.ln());
            }
        }
        assert!(fitted < 0.3 * constant, "fitted {fitted}, log eps {constant}");
    }

    #[test]
    fn the_form_factor_is_continuous_across_the_horizon_and_halves_a_side_hemisphere() {
        // A hemisphere centred on the horizon covers half the upper hemisphere.
        assert!((cap_form_factor(FRAC_PI_2, FRAC_PI_2) - 0.5).abs() < 1e-4);
        for alpha in [0.2f64, 0.6, 1.0] {
            let beta = FRAC_PI_2 - alpha;
            let above = alpha.sin().powi(2) * beta.cos();
            assert!((cap_form_factor(alpha, beta + 1e-9) - above).abs() < 1e-4, "alpha {alpha}");
        }
    }

    #[test]
    fn a_band_at_log_eps_is_the_papers_slice() {
        let order = 6;
        let log_eps = 0.1f64.ln();
        for (base, sigma) in [(0.0, 0.3), (0.2, 0.9), (0.5, 0.1), (-0.3, 0.4)] {
            let (mut banded, mut paper) = ([0.0; 6], [0.0; 6]);
            banded_slice(order, log_eps, &[log_eps; DEPTH_INTERVALS + 1], base, sigma, &mut banded);
            nlp_slice(order, log_eps, sigma, &mut paper);
            for l in 0..order {
                assert!((banded[l] - paper[l]).abs() < 1e-12, "base {base}, sigma {sigma}, l {l}");
            }
        }
    }

    #[test]
    fn a_fitted_band_shades_a_bowl_closer_than_log_eps() {
        for (order, directions) in [(4, 16), (6, 24)] {
            let exp = Exponentiator::new(order, ExpMethod::Quad, 1.0);
            let wedge = WedgeOperator::new(order, directions);
            let rows = fit_band_depths(order, 0.1, &exp, &wedge);
            let bands = &rows[..DEPTH_INTERVALS + 1];
            let receiver = DiffuseReceiver::new(order, 0.1, false, &exp);
            let bowl = |table: &[f64], width: f64| {
                let mut slice = [0.0; crate::sh::MAX_ORDER];
                banded_slice(order, 0.1f64.ln(), table, 0.0, width, &mut slice[..order]);
                let slices: Vec<f64> = (0..directions).flat_map(|_| slice[..order].to_vec()).collect();
                let mut visibility = [0.0; MAX_COEFFICIENTS];
                wedge.accumulate(&slices, &mut visibility[..coefficient_count(order)]);
                receiver.shade_with(&visibility)
            };
            let constant = [0.1f64.ln(); DEPTH_INTERVALS + 1];
            let open = bowl(&constant, 0.0);
            let (mut fitted, mut paper) = (0.0, 0.0);
            for degrees in [5.0, 10.0, 20.0, 30.0, 45.0] {
                let width = f64::to_radians(degrees);
                fitted += (bowl(bands, width) / open - width.cos().powi(2)).abs();
                paper += (bowl(&constant, width) / open - width.cos().powi(2)).abs();
            }
            assert!(fitted < 0.5 * paper, "order {order}: fitted {fitted}, log eps {paper}");
        }
    }

    /// The band table fitted at `order`, `directions` azimuths and `epsilon` (quadrature
    /// `exp*`), with the exponentiator and wedge operator it was fitted through.
    fn band_table(order: usize, directions: usize, epsilon: f64) -> (Exponentiator, WedgeOperator, Vec<f64>) {
        let exp = Exponentiator::new(order, ExpMethod::Quad, 1.0);
        let wedge = WedgeOperator::new(order, directions);
        let rows = fit_band_depths(order, epsilon, &exp, &wedge);
        (exp, wedge, rows)
    }

    /// A slope under a raised horizon: its bands start at its tangent plane, so they cover
    /// a crescent of the azimuths, not all of them. Bands at the depth for their coverage
    /// give the exact cosine-weighted share of the sky above both the horizon and the
    /// tangent plane within 2.5 %; the bowl's depths alone were up to 5 % dark.
    #[test]
    fn a_slope_under_a_raised_horizon_takes_its_share() {
        let (order, directions, epsilon) = (4, 16, 0.1f64);
        let (exp, wedge, rows) = band_table(order, directions, epsilon);
        let coverages = band_coverages(directions);
        let (log_epsilon, count) = (epsilon.ln(), coefficient_count(order));
        let diffuse = lobe_log_zh(order, Lobe::Diffuse, epsilon);
        let mut tangent = vec![0.0; order];
        cap_log_zh(order, log_epsilon, FRAC_PI_2, &mut tangent);
        let light_taken = |visibility: &[f64; MAX_COEFFICIENTS], n: [f64; 3]| {
            let mut f = *visibility;
            add_rotated_zonal(order, &diffuse, 1.0, n, &mut f[..count]);
            exp.exp_first(&f[..count], Some((&visibility[..count], log_epsilon)), Lobe::Diffuse.peak().ln())
        };
        // The kernel's slices (`add_horizon_slices`) under a horizon at `horizon` all
        // around, relative to the open receiver of the same normal.
        let share = |n: [f64; 3], horizon: f64, adapt: bool| {
            let (mut bases, mut sigmas) = (vec![0.0; directions], vec![0.0; directions]);
            for k in 0..directions {
                let (sin, cos) = (wedge.wedge_width() * k as f64).sin_cos();
                bases[k] = -(n[0] * cos + n[1] * sin) / n[2];
                sigmas[k] = horizon.tan().max(bases[k]);
            }
            let coverage = if adapt { horizon_coverage(&bases, &sigmas) } else { 1.0 };
            let mut bands = vec![0.0; DEPTH_INTERVALS + 1];
            band_depths_for(&rows, &coverages, coverage, &mut bands);
            let mut slices = vec![0.0; directions * order];
            for (k, slice) in slices.chunks_mut(order).enumerate() {
                banded_slice_of_tangents(order, log_epsilon, &bands, bases[k], sigmas[k], slice);
            }
            let mut visibility = [0.0; MAX_COEFFICIENTS];
            wedge.accumulate(&slices, &mut visibility[..count]);
            let mut open = [0.0; MAX_COEFFICIENTS];
            add_rotated_zonal(order, &tangent, 1.0, n.map(|c| -c), &mut open[..count]);
            light_taken(&visibility, n) / light_taken(&open, n)
        };
        // The exact share: the sky above both, `max(n . w, 0) / pi` by the midpoint rule.
        let exact = |n: [f64; 3], horizon: f64| {
            let (rings, sectors) = (200, 200);
            let mut sum = 0.0;
            for i in 0..rings {
                let e = horizon + (FRAC_PI_2 - horizon) * (i as f64 + 0.5) / rings as f64;
                for j in 0..sectors {
                    let a = std::f64::consts::TAU * (j as f64 + 0.5) / sectors as f64;
                    let w = [e.cos() * a.cos(), e.cos() * a.sin(), e.sin()];
                    sum += (w[0] * n[0] + w[1] * n[1] + w[2] * n[2]).max(0.0) * e.cos();
                }
            }
            sum * (FRAC_PI_2 - horizon) / rings as f64 * std::f64::consts::TAU / sectors as f64 / std::f64::consts::PI
        };
        let (mut worst, mut worst_bowl) = (0.0f64, 0.0f64);
        for horizon in [0.0f64, 5.0, 10.0, 20.0] {
            for tilt in [0.0f64, 10.0, 20.0, 30.0, 40.0] {
                let (horizon, tilt) = (horizon.to_radians(), tilt.to_radians());
                let n = [tilt.sin(), 0.0, tilt.cos()];
                let truth = exact(n, horizon);
                worst = worst.max((share(n, horizon, true) / truth - 1.0).abs());
                worst_bowl = worst_bowl.max((share(n, horizon, false) / truth - 1.0).abs());
            }
        }
        assert!(worst < 0.025 && worst_bowl > 0.04, "with coverage {worst}, bowl alone {worst_bowl}");
    }

    /// Each row of the band table fits its own coverage: horizons along that share of the
    /// azimuths, open along the rest.
    #[test]
    fn a_sector_of_horizons_takes_its_share_at_its_coverage() {
        let (_, _, rows) = band_table(4, 16, 0.1);
        let coverages = band_coverages(16);
        assert_eq!(coverages, [1.0, 0.5, 0.25, 0.125, 0.0625]);
        assert_eq!(rows.len(), coverages.len() * (DEPTH_INTERVALS + 1));
        let width = DEPTH_INTERVALS + 1;
        // One azimuth's band alone is resolved less well than a bowl, and takes a
        // shallower depth.
        let last = coverages.len() - 1;
        for k in [4, 8, 16, 32] {
            assert!(rows[last * width + k] > rows[k] + 0.15, "width {k}: {} {}", rows[last * width + k], rows[k]);
        }
        // Between rows the table interpolates in log(coverage); at a row it is that row.
        let mut out = vec![0.0; width];
        band_depths_for(&rows, &coverages, 0.25, &mut out);
        assert_eq!(out, rows[2 * width..3 * width]);
        band_depths_for(&rows, &coverages, 0.5f64.sqrt() * 0.5, &mut out);
        let halfway = 0.5 * (rows[width + 16] + rows[2 * width + 16]);
        assert!((out[16] - halfway).abs() < 1e-12);
        band_depths_for(&rows, &coverages, 0.01, &mut out);
        assert_eq!(out, rows[4 * width..]);
        // A bowl covers everything; one azimuth's band alone 1 / W.
        assert_eq!(horizon_coverage(&[0.0; 16], &[0.3; 16]), 1.0);
        let mut one = [0.0; 16];
        one[3] = 0.3;
        assert!((horizon_coverage(&[0.0; 16], &one) - 1.0 / 16.0).abs() < 1e-12);
        assert_eq!(horizon_coverage(&[0.0; 16], &[0.0; 16]), 1.0);
    }

    /// The receiver reads `exp*`'s first coefficient alone; it is the full projection's,
    /// bit for bit, so the tables are those of projecting everything.
    #[test]
    fn the_first_coefficient_alone_is_the_projections() {
        for (order, method) in [(4, ExpMethod::Quad), (6, ExpMethod::Quad), (4, ExpMethod::Exact), (4, ExpMethod::Hyb)]
        {
            let exp = Exponentiator::new(order, method, 1.0);
            let count = coefficient_count(order);
            let f: Vec<f64> = (0..count).map(|k| 1.7 * ((k as f64 + 0.3) * 2.1).sin()).collect();
            let v: Vec<f64> = f.iter().map(|x| 0.6 * x).collect();
            let mut out = vec![0.0; count];
            exp.exp(&f, Some((&v, -2.3)), 0.4, &mut out);
            assert_eq!(exp.exp_first(&f, Some((&v, -2.3)), 0.4).to_bits(), out[0].to_bits(), "{method:?}");
        }
    }

    #[test]
    fn the_lookup_interpolates_and_clamps() {
        let depths: Vec<f64> = (0..=DEPTH_INTERVALS).map(|k| -(k as f64)).collect();
        let half_step = FRAC_PI_2 / DEPTH_INTERVALS as f64 / 2.0;
        assert!((depth_at(&depths, 3.0 * half_step) + 1.5).abs() < 1e-12);
        assert_eq!(depth_at(&depths, -1.0), 0.0);
        assert_eq!(depth_at(&depths, 2.0), -(DEPTH_INTERVALS as f64));
    }
}
