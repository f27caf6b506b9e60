//! The pyramid's numerics below the march: the cubic B-spline that reconstructs a
//! level (SN08 Section 4), the tent filter that decimates level 0 into the others, and
//! the rounding up of a horizon kept as an f32 bound.

use rayon::prelude::*;

/// The least f32 above `x` (`f32::next_up`, which this crate's Rust version lacks).
pub(super) fn next_up(x: f32) -> f32 {
    if x.is_nan() || x == f32::INFINITY {
        return x;
    }
    if x == 0.0 {
        return f32::from_bits(1);
    }
    let bits = x.to_bits();
    f32::from_bits(if x > 0.0 { bits + 1 } else { bits - 1 })
}

/// The least f32 at or above `x` (a horizon tangent kept as a bound,
/// [`HorizonsBetween`](super::HorizonsBetween)); `NaN` for `NaN`.
pub(super) fn f32_at_least(x: f64) -> f32 {
    let rounded = x as f32;
    if f64::from(rounded) < x {
        next_up(rounded)
    } else {
        rounded
    }
}

/// Uniform cubic B-spline basis at fraction `t` (SN08 Section 4, after Eq. 4).
#[inline]
pub(super) fn bspline_weights(t: f64) -> [f64; 4] {
    let t2 = t * t;
    let t3 = t2 * t;
    let s = 1.0 - t;
    const SIXTH: f64 = 1.0 / 6.0;
    [s * s * s * SIXTH, (0.5 * t3 - t2) + 4.0 * SIXTH, (-0.5 * t3 + 0.5 * (t2 + t)) + SIXTH, t3 * SIXTH]
}

/// Clamped sample indices and weights of the cubic B-spline at grid coordinate `u`
/// (already clamped to `[0, n - 1]`); replicating edge samples makes the surface
/// constant beyond the edge.
#[inline]
pub(super) fn bspline_taps(u: f64, n: usize) -> ([usize; 4], [f64; 4]) {
    if n <= 1 {
        return ([0; 4], [0.25; 4]);
    }
    // `u` is clamped to `[0, n - 1]`: truncation (an integer conversion, not a libm
    // call) is its floor.
    let i = u as isize;
    let w = bspline_weights(u - i as f64);
    let last = (n - 1) as isize;
    (std::array::from_fn(|t| (i - 1 + t as isize).clamp(0, last) as usize), w)
}

/// Maximum over `tau in [0, m - 1]` of the cubic B-spline through `omega` (SN08 Eq.
/// 4-5), sampled at the knots and at the midpoints between knots (SN08 Section 6),
/// with end values replicated. This approximates (from below) the spline's true
/// maximum; the spline itself lies below the largest sample, which is part of
/// SN08's filtering bias.
pub(super) fn bspline_max(omega: &[f64]) -> f64 {
    let m = omega.len();
    let at = |i: isize| omega[i.clamp(0, m as isize - 1) as usize];
    let mut best = f64::NEG_INFINITY;
    for i in 0..m as isize {
        let knot = (at(i - 1) + 4.0 * at(i) + at(i + 1)) / 6.0;
        best = best.max(knot);
        if i + 1 < m as isize {
            let mid = (at(i - 1) + 23.0 * (at(i) + at(i + 1)) + at(i + 2)) / 48.0;
            best = best.max(mid);
        }
    }
    best
}

/// Level samples of size `size` from the level-0 samples (size `n`): separable tent
/// prefilter of radius one output spacing, clamp-to-edge (module doc).
pub(super) fn decimate(heights: &[f32], n: [usize; 2], size: [usize; 2]) -> Vec<f32> {
    let wx = tent_weights(n[0], size[0]);
    let wy = tent_weights(n[1], size[1]);
    // Pass 1 along x: n[1] rows of size[0].
    let mut tmp = vec![0.0f64; n[1] * size[0]];
    tmp.par_chunks_mut(size[0]).enumerate().for_each(|(row, out)| {
        let line = &heights[row * n[0]..(row + 1) * n[0]];
        for (o, taps) in out.iter_mut().zip(&wx) {
            *o = taps.iter().map(|&(i, w)| w * f64::from(line[i])).sum();
        }
    });
    // Pass 2 along y.
    let mut out = vec![0.0f32; size[0] * size[1]];
    out.par_chunks_mut(size[0]).zip(wy.par_iter()).for_each(|(line, taps)| {
        for (c, o) in line.iter_mut().enumerate() {
            *o = taps.iter().map(|&(r, w)| w * tmp[r * size[0] + c]).sum::<f64>() as f32;
        }
    });
    out
}

/// Per output sample, the (input index, weight) taps of a tent of radius one output
/// spacing, in input-index units, clamped to the input, normalised.
pub(super) fn tent_weights(n_in: usize, n_out: usize) -> Vec<Vec<(usize, f64)>> {
    if n_out <= 1 || n_in <= 1 {
        return vec![vec![(0, 1.0)]; n_out.max(1)];
    }
    let ratio = (n_in - 1) as f64 / (n_out - 1) as f64;
    let last = (n_in - 1) as isize;
    (0..n_out)
        .map(|i| {
            let c = i as f64 * ratio;
            let lo = (c - ratio).ceil() as isize;
            let hi = (c + ratio).floor() as isize;
            let mut taps: Vec<(usize, f64)> = (lo..=hi)
                .filter_map(|m| {
                    let w = 1.0 - (m as f64 - c).abs() / ratio;
                    (w > 1e-12).then(|| (m.clamp(0, last) as usize, w))
                })
                .collect();
            let total: f64 = taps.iter().map(|t| t.1).sum();
            for t in &mut taps {
                t.1 /= total;
            }
            taps
        })
        .collect()
}
