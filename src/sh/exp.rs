//! SH exponentiation `exp*(f)`: the order-n projection of `exp(f(w))` for an order-n
//! log vector `f` (paper 000, Eq. 9; Ren et al. 2006, "SHEXP", Sections 4-5).
//!
//! Four executors of one definition:
//! - [`ExactExp`]: quadrature. The reference for tests and for the ground truth.
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
use std::f64::consts::PI;

/// `y_0`, the constant value of the DC basis function.
pub const Y0: f64 = 0.28209479177387814; // 1 / (2 sqrt(pi))

/// The SH vector of the constant function 1 has `ONE_DC` as its only non-zero entry.
pub const ONE_DC: f64 = 3.5449077018110318; // 2 sqrt(pi)

/// How `exp*` is computed per pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ExpMethod {
    /// Quadrature: exact up to the grid's resolution; slow (thousands of exp per pixel).
    Exact,
    /// DC isolation and the product series.
    Series,
    /// Optimal linear (one table lookup, no product).
    Ol,
    /// Scale, OL, square (the paper's choice).
    Hyb,
}

/// Splits `f` into its DC factor `exp(f_0 y_0)` and its non-DC part, returning the factor
/// and the magnitude `|f^|`; `hat` receives `f^`.
fn isolate_dc<T: Real>(f: &[T], hat: &mut [T]) -> (T, T) {
    hat.copy_from_slice(f);
    hat[0] = T::zero();
    let magnitude = hat.iter().fold(T::zero(), |acc, &c| acc + c * c).sqrt();
    ((f[0] * T::of(Y0)).exp(), magnitude)
}

/// Exact exponentiation by quadrature on a fixed grid, with the basis tabulated at its
/// nodes. The default grid (`6n + 16` Gauss nodes in `cos theta`, twice as many azimuths)
/// agrees with a grid twice as fine to 1e-10 relative for `|f^| <= 8` and to 1e-6 for
/// `|f^| <= 16` at orders 3-8 (see the tests), which bounds its error.
#[derive(Clone, Debug)]
pub struct ExactExp {
    order: usize,
    weights: Vec<f64>,
    basis: Vec<f64>, // node-major, order^2 values per node
}

impl ExactExp {
    pub fn new(order: usize) -> Self {
        Self::with_grid(order, 6 * order + 16)
    }

    pub fn with_grid(order: usize, nz: usize) -> Self {
        let quadrature = SphereQuadrature::gauss(nz);
        let count = coefficient_count(order);
        let mut basis = vec![0.0; quadrature.len() * count];
        for (node, d) in quadrature.directions.iter().enumerate() {
            eval_basis(order, *d, &mut basis[node * count..(node + 1) * count]);
        }
        Self { order, weights: quadrature.weights, basis }
    }

    pub fn order(&self) -> usize {
        self.order
    }

    /// `out = exp*(f)`.
    pub fn exp<T: Real>(&self, f: &[T], out: &mut [T]) {
        let count = coefficient_count(self.order);
        let mut acc = [0.0f64; MAX_COEFFICIENTS];
        let f64s: Vec<f64> = f[..count].iter().map(|c| c.to_f64().unwrap_or(f64::NAN)).collect();
        for (node, w) in self.weights.iter().enumerate() {
            let y = &self.basis[node * count..(node + 1) * count];
            let value: f64 = y.iter().zip(&f64s).map(|(a, b)| a * b).sum();
            let e = w * value.exp();
            for (a, b) in acc.iter_mut().zip(y) {
                *a += e * b;
            }
        }
        for (o, a) in out[..count].iter_mut().zip(acc.iter()) {
            *o = T::of(*a);
        }
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
    /// Magnitude spacing between table nodes.
    pub step: f64,
    pub a: Vec<f64>,
    pub b: Vec<f64>,
}

/// Largest magnitude the OL table covers and its number of intervals.
pub const OL_MAX_MAGNITUDE: f64 = 32.0;
pub const OL_INTERVALS: usize = 128;

impl OlTable {
    /// Fits the table from training log vectors (any magnitude; their DC is ignored and
    /// their non-DC part is normalised to 1).
    pub fn fit(order: usize, training: &[Vec<f64>]) -> Self {
        // The fit needs integrals of exp(m g), not projections: a coarser grid than
        // ExactExp's default keeps the fit under 0.2 s at order 8 and changes a, b by
        // less than 1e-6 for m <= 8 (the coefficients HYB uses).
        let exact = ExactExp::with_grid(order, 3 * order + 12);
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
        let step = OL_MAX_MAGNITUDE / OL_INTERVALS as f64;
        let mut a = vec![1.0; OL_INTERVALS + 1];
        let mut b = vec![1.0; OL_INTERVALS + 1];
        let mut scaled = vec![0.0; count];
        for node in 1..=OL_INTERVALS {
            let m = node as f64 * step;
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
        Self { order, step, a, b }
    }

    /// `(a(m), b(m))` by linear interpolation.
    pub fn coefficients<T: Real>(&self, magnitude: T) -> (T, T) {
        let x = (magnitude.to_f64().unwrap_or(0.0) / self.step).max(0.0);
        let i = (x.floor() as usize).min(OL_INTERVALS - 1);
        let t = (x - i as f64).min(1.0);
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

/// HYB scales `f^` down until its magnitude is at most this before applying OL. The OL
/// fit is near-exact for small magnitudes, and each squaring costs one SH product.
pub const HYB_MAGNITUDE: f64 = 1.0;

/// Most squarings HYB will do (`|f^|` up to `2^20` times [`HYB_MAGNITUDE`]); a larger
/// magnitude is clamped, which keeps the result finite.
pub const HYB_MAX_SQUARINGS: u32 = 20;

/// HYB (SHEXP Section 5): with `p` the smallest integer such that
/// `|f^| / 2^p <= HYB_MAGNITUDE`, `exp*(f^) ~ (OL(f^ / 2^p))^(2^p)` with `p` truncated
/// SH products, times the exact DC factor.
pub fn exp_hyb<T: Real>(tensor: &TriplingTensor, ol: &OlTable, f: &[T], out: &mut [T]) {
    exp_hyb_with(tensor, ol, HYB_MAGNITUDE, f, out)
}

/// [`exp_hyb`] with its own scaling threshold (for measuring the trade).
pub fn exp_hyb_with<T: Real>(tensor: &TriplingTensor, ol: &OlTable, threshold: f64, f: &[T], out: &mut [T]) {
    let count = coefficient_count(tensor.order());
    let mut hat = [T::zero(); MAX_COEFFICIENTS];
    let (dc_factor, magnitude) = isolate_dc(&f[..count], &mut hat[..count]);
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
    let mut squared = [T::zero(); MAX_COEFFICIENTS];
    for _ in 0..squarings {
        tensor.product(&value[..count], &value[..count], &mut squared[..count]);
        value[..count].copy_from_slice(&squared[..count]);
    }
    for i in 0..count {
        out[i] = dc_factor * value[i];
    }
}
