//! SH exponentiation `exp*(f)`: the order-n projection of `exp(f(w))` for an order-n
//! log vector `f` (paper 000, Eq. 9; Ren et al. 2006, "SHEXP", Sections 4-5).
//!
//! Five executors of one definition:
//! - [`ExactExp`]: quadrature. On a fine grid ([`ExactExp::new`]) it is the reference for
//!   tests and for the ground truth; on the coarse grid of [`ExactExp::fast`] (`2n + 2`
//!   Gauss nodes in `cos theta`) it is the `quad` method, which costs about as much per
//!   pixel as HYB and, having no truncated products, is far more accurate
//!   (`examples/exp_accuracy.rs`).
//! - [`exp_series`]: DC isolation, then the Taylor series with truncated SH products.
//! - [`OlTable::exp`]: optimal linear, `exp*(f^) ~ a(|f^|) 1 + b(|f^|) f^`.
//! - [`exp_hyb`]: HYB, scale `f^` by `2^-p` until `|f^| <= HYB_MAGNITUDE`, OL, then square
//!   `p` times with the SH product.
//!
//! All four isolate the DC term first: with `f = f_0 y_0 + f^`, `exp*(f) = exp(f_0 y_0) exp*(f^)`,
//! and `y_0 = 1 / (2 sqrt(pi))` is a constant, so the factor is exact (SHEXP Eq. 12).
//! Magnitudes `|f^|` are Euclidean norms of the coefficient vectors, i.e. L2 norms of the
//! functions over the sphere.

use super::basis::{coefficient_count, eval_basis, Real, MAX_COEFFICIENTS};
use super::product::TriplingTensor;
use super::quadrature::SphereQuadrature;
use crate::memo::Memo;
use std::f64::consts::PI;
use std::sync::Arc;

/// `y_0`, the constant value of the DC basis function.
pub const Y0: f64 = 0.28209479177387814; // 1 / (2 sqrt(pi))

/// The SH vector of the constant function 1 has `ONE_DC` as its only non-zero entry.
pub const ONE_DC: f64 = 3.5449077018110318; // 2 sqrt(pi)

/// How `exp*` is computed per pixel (`--exp`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, clap::ValueEnum, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ExpMethod {
    /// Quadrature on a coarse (2n+2)-node grid: within 1e-5 of exact.
    Quad,
    /// Scale until small, optimal linear, square back (the paper's choice); 2-4x faster than quad, less accurate.
    Hyb,
    /// Optimal linear only (one table lookup, no product): fastest, least accurate at large magnitudes.
    Ol,
    /// DC isolation and the product series.
    Series,
    /// Quadrature on a fine grid: reference quality, slow (thousands of exp per pixel).
    Exact,
}

/// Splits `f` into its DC factor `exp(f_0 y_0)` and its non-DC part, returning the factor
/// and the magnitude `|f^|`; `hat` receives `f^`.
fn isolate_dc<T: Real>(f: &[T], hat: &mut [T]) -> (T, T) {
    hat.copy_from_slice(f);
    hat[0] = T::zero();
    let magnitude = hat.iter().fold(T::zero(), |acc, &c| acc + c * c).sqrt();
    ((f[0] * T::of(Y0)).exp(), magnitude)
}

/// Largest log value [`ExactExp::exp`] exponentiates: above the log of any lobe peak the
/// tool forms (`log((1024 + 1) / 2 pi) = 5.1`).
pub const MAX_LOG_VALUE: f64 = 8.0;

/// Exact exponentiation by quadrature on a fixed grid, with the basis tabulated at its
/// nodes. The default grid (`6n + 16` Gauss nodes in `cos theta`, twice as many azimuths)
/// agrees with a grid twice as fine to 1e-10 relative for `|f^| <= 8` and to 1e-6 for
/// `|f^| <= 16` at orders 3-8 (see the tests), which bounds its error.
#[derive(Clone, Debug)]
pub struct ExactExp {
    order: usize,
    /// Gauss nodes in `cos theta`; the grid has twice as many azimuths, row by row.
    rows: usize,
    weights: Vec<f64>,
    basis: Vec<f64>, // node-major, order^2 values per node
}

impl ExactExp {
    pub fn new(order: usize) -> Self {
        Self::with_grid(order, 6 * order + 16)
    }

    /// The `quad` method's grid: `2n + 2` Gauss nodes in `cos theta`, `4n + 4` azimuths.
    /// Measured relative L2 error against the fine grid, worst over 48 training-like
    /// vectors: at most 1e-4 for `|f^| <= 2` and 0.005 (order 4) to 0.025 (order 8) at
    /// `|f^| = 8`, where HYB is off by 0.8 (`examples/exp_accuracy.rs`).
    pub fn fast(order: usize) -> Self {
        Self::with_grid(order, Self::fast_nodes(order))
    }

    /// Gauss nodes in `cos theta` of [`ExactExp::fast`].
    pub fn fast_nodes(order: usize) -> usize {
        2 * order + 2
    }

    /// [`ExactExp::new`] or [`ExactExp::fast`] (`fine`), built once per order and process
    /// ([`crate::memo`]).
    pub fn shared(order: usize, fine: bool) -> Arc<Self> {
        static GRIDS: Memo<(usize, bool), ExactExp> = Memo::new();
        GRIDS.get_or_build((order, fine), || if fine { Self::new(order) } else { Self::fast(order) })
    }

    pub fn with_grid(order: usize, nz: usize) -> Self {
        let quadrature = SphereQuadrature::gauss(nz);
        let count = coefficient_count(order);
        let mut basis = vec![0.0; quadrature.len() * count];
        for (node, d) in quadrature.directions.iter().enumerate() {
            eval_basis(order, *d, &mut basis[node * count..(node + 1) * count]);
        }
        Self { order, rows: nz, weights: quadrature.weights, basis }
    }

    pub fn order(&self) -> usize {
        self.order
    }

    /// Gauss nodes in `cos theta` ([`SphereQuadrature::gauss`]): the nodes are these rows
    /// of `2 * rows` azimuths each, row by row.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Quadrature weights, one per node.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// The basis at the nodes, node-major: `order^2` values per node.
    pub fn basis(&self) -> &[f64] {
        &self.basis
    }

    /// `out = exp*(f)`, with node values clamped at [`MAX_LOG_VALUE`]; see
    /// [`ExactExp::exp_below`].
    pub fn exp<T: Real>(&self, f: &[T], out: &mut [T]) {
        self.exp_below(f, MAX_LOG_VALUE, out)
    }

    /// `out = exp*(min(f, ceiling))`: node values above `ceiling` are clamped to it before
    /// exponentiation. When the caller knows the true function never exceeds `ceiling`
    /// (a log visibility is at most 0, a log lobe at most the log of its peak), anything
    /// above it is band-limiting ringing, which exponentiation would amplify without
    /// bound (thousands of overlapping caps, or eps = 1e-6, ring past f64's range); the
    /// clamp bounds the result by `exp(ceiling)` times the light while leaving every
    /// node below the ceiling exact.
    pub fn exp_below<T: Real>(&self, f: &[T], ceiling: f64, out: &mut [T]) {
        self.exp_floored(f, None, ceiling, out)
    }

    /// [`exp_below`](Self::exp_below), with the part `v` of `f` floored at `floor` at every
    /// node when `floored = Some((v, floor))`: the node value is `f - v + max(v, floor)`.
    /// With `v` the log visibility and `floor = log(eps)`, a direction behind several
    /// clamped terms (overlapping caps, a cap and the tangent plane) is clamped once, as
    /// the exact visibility `max(product of the terms, eps)` would be, instead of once per
    /// term (paper 000, Section 4.2).
    pub fn exp_floored<T: Real>(&self, f: &[T], floored: Option<(&[T], f64)>, ceiling: f64, out: &mut [T]) {
        let count = coefficient_count(self.order);
        let mut acc = [0.0f64; MAX_COEFFICIENTS];
        let mut f64s = [0.0f64; MAX_COEFFICIENTS];
        for (a, c) in f64s.iter_mut().zip(&f[..count]) {
            *a = c.to_f64().unwrap_or(f64::NAN);
        }
        let mut v64s = [0.0f64; MAX_COEFFICIENTS];
        if let Some((v, _)) = floored {
            for (a, c) in v64s.iter_mut().zip(&v[..count]) {
                *a = c.to_f64().unwrap_or(f64::NAN);
            }
        }
        let floored64 = floored.map(|(_, floor)| (&v64s[..count], floor));
        for (y, e) in self.weighted_exps(&f64s[..count], floored64, ceiling) {
            for (a, b) in acc.iter_mut().zip(y) {
                *a += e * b;
            }
        }
        for (o, a) in out[..count].iter_mut().zip(acc.iter()) {
            *o = T::of(*a);
        }
    }

    /// The first coefficient of [`Self::exp_floored`] alone (the same sum, so the same
    /// value): what the fitted depths' white receiver under a constant light reads.
    pub fn exp_floored_first(&self, f: &[f64], floored: Option<(&[f64], f64)>, ceiling: f64) -> f64 {
        let mut first = 0.0f64;
        for (y, e) in self.weighted_exps(f, floored, ceiling) {
            first += e * y[0];
        }
        first
    }

    /// Per node, the basis there and `w_i e^{f(x_i)}`, the node value floored and capped
    /// as [`Self::exp_floored`] documents.
    fn weighted_exps<'a>(
        &'a self,
        f: &'a [f64],
        floored: Option<(&'a [f64], f64)>,
        ceiling: f64,
    ) -> impl Iterator<Item = (&'a [f64], f64)> + 'a {
        let count = coefficient_count(self.order);
        self.weights.iter().enumerate().map(move |(node, w)| {
            let y = &self.basis[node * count..(node + 1) * count];
            let mut value: f64 = y.iter().zip(&f[..count]).map(|(a, b)| a * b).sum();
            if let Some((v, floor)) = floored {
                let v: f64 = y.iter().zip(&v[..count]).map(|(a, b)| a * b).sum();
                value += (floor - v).max(0.0);
            }
            (y, w * value.min(ceiling).exp())
        })
    }

    /// `integral of exp(g)` and `integral of exp(g) g` over the sphere for the function
    /// with coefficients `g`: what the OL fit needs, without projecting.
    fn moments(&self, g: &[f64]) -> (f64, f64) {
        let count = coefficient_count(self.order);
        let (mut m0, mut m1) = (0.0, 0.0);
        for (node, w) in self.weights.iter().enumerate() {
            let y = &self.basis[node * count..(node + 1) * count];
            let value: f64 = y.iter().zip(g).map(|(a, b)| a * b).sum();
            let e = w * value.exp();
            m0 += e;
            m1 += e * value;
        }
        (m0, m1)
    }
}

/// The most series terms [`exp_series`] sums; with `|f^| <= 10` the terms fall below
/// 1e-12 relative well before this.
pub const SERIES_MAX_TERMS: usize = 64;

/// DC isolation and the Taylor series `sum_k f^^k / k!` with truncated products (SHEXP
/// Section 4, "DC isolation"). Each product drops the bands above `n - 1`, which is this
/// method's own error (it is not the projection of `exp(f)`). The series converges for any
/// magnitude, but its terms peak near `|f^|^|f^| / |f^|!`, so past `|f^| ~ 10` cancellation
/// costs f32 all its digits: use HYB or exact there.
pub fn exp_series<T: Real>(tensor: &TriplingTensor, f: &[T], out: &mut [T]) {
    let count = coefficient_count(tensor.order());
    let mut hat = [T::zero(); MAX_COEFFICIENTS];
    let (dc_factor, _) = isolate_dc(&f[..count], &mut hat[..count]);
    let mut term = [T::zero(); MAX_COEFFICIENTS];
    let mut next = [T::zero(); MAX_COEFFICIENTS];
    term[..count].copy_from_slice(&hat[..count]);
    let mut sum = [T::zero(); MAX_COEFFICIENTS];
    sum[..count].copy_from_slice(&hat[..count]);
    sum[0] = sum[0] + T::of(ONE_DC);
    let tolerance = T::epsilon() * T::of(0.01);
    for k in 2..=SERIES_MAX_TERMS {
        tensor.product(&term[..count], &hat[..count], &mut next[..count]);
        let inv_k = T::one() / T::of(k as f64);
        let mut term_norm = T::zero();
        let mut sum_norm = T::zero();
        for i in 0..count {
            term[i] = next[i] * inv_k;
            sum[i] = sum[i] + term[i];
            term_norm = term_norm + term[i] * term[i];
            sum_norm = sum_norm + sum[i] * sum[i];
        }
        if term_norm <= tolerance * tolerance * sum_norm {
            break;
        }
    }
    for i in 0..count {
        out[i] = dc_factor * sum[i];
    }
}

/// Optimal-linear coefficients tabulated over the magnitude `|f^|` (SHEXP Section 5,
/// "optimal linear approximation"), fitted by this crate: for every tabulated magnitude
/// `m`, `a(m)` and `b(m)` minimise `sum_s |exp*(m g_s) - a 1 - b m g_s|^2` over a
/// training set of unit-magnitude non-DC log vectors `g_s` of the kind the tool sums
/// (see `logsh::training_log_vectors`). Because every `g_s` is orthogonal to the constant
/// 1, the least-squares solution separates:
/// `a(m) = mean_s integral(exp(m g_s)) / (4 pi)` and
/// `b(m) = sum_s integral(exp(m g_s) g_s) / (S m)`,
/// both evaluated by [`ExactExp`]'s quadrature. Between nodes the table is interpolated
/// linearly; beyond the last node the last coefficients are used (HYB never goes there).
#[derive(Clone, Debug)]
pub struct OlTable {
    pub order: usize,
    /// Coefficients at the nodes of `ol_node_magnitude`.
    pub a: Vec<f64>,
    pub b: Vec<f64>,
}

/// The OL table's nodes: `OL_FINE_NODES` intervals on `[0, 1]` (HYB reads only this part,
/// where `a` and `b` curve like `1 + m^2 / (8 pi)` and a coarse linear interpolation would
/// be amplified by every squaring), then steps of 0.25 up to `OL_MAX_MAGNITUDE`; beyond it
/// the last coefficients are used.
pub const OL_FINE_NODES: usize = 64;
pub const OL_COARSE_STEP: f64 = 0.25;
pub const OL_MAX_MAGNITUDE: f64 = 32.0;

fn ol_node_magnitude(node: usize) -> f64 {
    if node <= OL_FINE_NODES {
        node as f64 / OL_FINE_NODES as f64
    } else {
        1.0 + (node - OL_FINE_NODES) as f64 * OL_COARSE_STEP
    }
}

/// Number of magnitudes the OL table holds.
pub fn ol_node_count() -> usize {
    OL_FINE_NODES + ((OL_MAX_MAGNITUDE - 1.0) / OL_COARSE_STEP).round() as usize + 1
}

/// Table position of magnitude `m`: node index and fraction towards the next node.
fn ol_position(m: f64) -> (usize, f64) {
    let last = ol_node_count() - 1;
    let x =
        if m <= 1.0 { m.max(0.0) * OL_FINE_NODES as f64 } else { OL_FINE_NODES as f64 + (m - 1.0) / OL_COARSE_STEP };
    let i = (x.floor() as usize).min(last - 1);
    (i, (x - i as f64).min(1.0))
}

impl OlTable {
    /// Fits the table from training log vectors (any magnitude; their DC is ignored and
    /// their non-DC part is normalised to 1).
    pub fn fit(order: usize, training: &[Vec<f64>]) -> Self {
        // The fit needs integrals of exp(m g), not projections, and the coefficients are
        // averages over the training set: the `quad` grid (2n + 2 nodes in z), whose
        // relative error is below 1e-4 for m <= 2 and 2.5% at m = 8, is accurate enough
        // and keeps the fit to tens of milliseconds.
        let exact = ExactExp::fast(order);
        let count = coefficient_count(order);
        let shapes: Vec<Vec<f64>> = training
            .iter()
            .filter_map(|g| {
                let mut hat = g[..count].to_vec();
                hat[0] = 0.0;
                let norm = hat.iter().map(|c| c * c).sum::<f64>().sqrt();
                (norm > 1e-12).then(|| hat.iter().map(|c| c / norm).collect())
            })
            .collect();
        assert!(!shapes.is_empty(), "OL fit needs at least one non-constant training vector");
        let nodes = ol_node_count();
        let mut a = vec![1.0; nodes];
        let mut b = vec![1.0; nodes];
        let mut scaled = vec![0.0; count];
        for node in 1..nodes {
            let m = ol_node_magnitude(node);
            let (mut sum0, mut sum1) = (0.0, 0.0);
            for g in &shapes {
                for (s, c) in scaled.iter_mut().zip(g) {
                    *s = m * c;
                }
                let (m0, m1) = exact.moments(&scaled);
                sum0 += m0;
                sum1 += m1 / m; // integral of exp(m g) g
            }
            let samples = shapes.len() as f64;
            a[node] = sum0 / (samples * 4.0 * PI);
            b[node] = sum1 / (samples * m);
        }
        Self { order, a, b }
    }

    /// `(a(m), b(m))` by linear interpolation.
    pub fn coefficients<T: Real>(&self, magnitude: T) -> (T, T) {
        let (i, t) = ol_position(magnitude.to_f64().unwrap_or(0.0));
        let a = self.a[i] + t * (self.a[i + 1] - self.a[i]);
        let b = self.b[i] + t * (self.b[i + 1] - self.b[i]);
        (T::of(a), T::of(b))
    }

    /// `out = exp*(f)` by DC isolation and OL.
    pub fn exp<T: Real>(&self, f: &[T], out: &mut [T]) {
        let count = coefficient_count(self.order);
        let mut hat = [T::zero(); MAX_COEFFICIENTS];
        let (dc_factor, magnitude) = isolate_dc(&f[..count], &mut hat[..count]);
        self.exp_non_dc(&hat[..count], magnitude, out);
        for o in out[..count].iter_mut() {
            *o = *o * dc_factor;
        }
    }

    fn exp_non_dc<T: Real>(&self, hat: &[T], magnitude: T, out: &mut [T]) {
        let (a, b) = self.coefficients(magnitude);
        for (o, h) in out.iter_mut().zip(hat) {
            *o = b * *h;
        }
        out[0] = a * T::of(ONE_DC);
    }
}

/// Default HYB threshold: `f^` is scaled down until its magnitude is at most this before
/// OL. Each halving costs one SH product per pixel; OL's error at the threshold (0.6% at
/// 0.25, 10% at 1.0, order 4) is amplified by every squaring (`examples/exp_accuracy.rs`).
pub const HYB_MAGNITUDE: f64 = 0.25;

/// Most squarings HYB will do (`|f^|` up to `2^24` times the threshold); a larger
/// magnitude is clamped, which keeps the result finite.
pub const HYB_MAX_SQUARINGS: u32 = 24;

/// HYB (SHEXP Section 5) with the default threshold; see [`exp_hyb_with`].
pub fn exp_hyb<T: Real>(tensor: &TriplingTensor, ol: &OlTable, f: &[T], out: &mut [T]) {
    exp_hyb_with(tensor, ol, HYB_MAGNITUDE, f, out)
}

/// HYB with its own threshold: with `p` the smallest integer such that
/// `|f^| / 2^p <= threshold`, `exp*(f) ~ (exp(f_0 y_0 / 2^p) OL(f^ / 2^p))^(2^p)` with `p`
/// truncated SH products. The DC factor is split over the squarings rather than applied
/// at the end, so every intermediate stays near the magnitude of the result and f32 does
/// not overflow when hundreds of caps pile up (the end result is the same in exact
/// arithmetic).
pub fn exp_hyb_with<T: Real>(tensor: &TriplingTensor, ol: &OlTable, threshold: f64, f: &[T], out: &mut [T]) {
    let count = coefficient_count(tensor.order());
    let mut hat = [T::zero(); MAX_COEFFICIENTS];
    hat[..count].copy_from_slice(&f[..count]);
    hat[0] = T::zero();
    let magnitude = hat[..count].iter().fold(T::zero(), |acc, &c| acc + c * c).sqrt();
    let mut squarings = 0u32;
    let mut scale = T::one();
    let limit = T::of(threshold);
    while magnitude * scale > limit && squarings < HYB_MAX_SQUARINGS {
        scale = scale * T::of(0.5);
        squarings += 1;
    }
    for h in hat[..count].iter_mut() {
        *h = *h * scale;
    }
    let mut value = [T::zero(); MAX_COEFFICIENTS];
    ol.exp_non_dc(&hat[..count], magnitude * scale, &mut value[..count]);
    let dc_share = (f[0] * T::of(Y0) * scale).exp();
    for v in value[..count].iter_mut() {
        *v = *v * dc_share;
    }
    let mut squared = [T::zero(); MAX_COEFFICIENTS];
    for _ in 0..squarings {
        tensor.product(&value[..count], &value[..count], &mut squared[..count]);
        value[..count].copy_from_slice(&squared[..count]);
    }
    out[..count].copy_from_slice(&value[..count]);
}
