//! Real spherical-harmonic basis at any order, in f32 or f64.
//!
//! Conventions, stated once for the whole crate:
//! - World space is Blender's: right-handed, Z up. `theta` is the polar angle from +Z,
//!   `phi` the azimuth from +X towards +Y.
//! - An order-`n` expansion holds bands `l = 0..n`, so `n * n` coefficients, stored band
//!   after band at `index(l, m) = l * (l + 1) + m` (paper 000, Eq. 4).
//! - Real, orthonormal basis without the Condon-Shortley phase:
//!   `y_l^m = sqrt(2) K_l^m P_l^m(cos theta) cos(m phi)` for `m > 0`,
//!   `y_l^0 = K_l^0 P_l(cos theta)`,
//!   `y_l^m = sqrt(2) K_l^|m| P_l^|m|(cos theta) sin(|m| phi)` for `m < 0`,
//!   with `K_l^m = sqrt((2l + 1) / (4 pi) * (l - m)! / (l + m)!)`. Band 1 is therefore
//!   `sqrt(3 / 4 pi) * (y, z, x)`.
//! - A spherical function `f` has coefficients `f_i = integral of f y_i` over the sphere
//!   (paper 000, Eq. 3), so the constant 1 is `[2 sqrt(pi), 0, ...]` and the integral of
//!   a product of two band-limited functions is the dot product of their vectors.

use num_traits::{Float, FloatConst, FromPrimitive};
use std::fmt::Debug;

/// The scalar types the SH code runs in: f32 (the GPU's precision) and f64 (tables and
/// reference values).
pub trait Real: Float + FloatConst + FromPrimitive + Debug + Send + Sync + Default + 'static {
    /// Converts an f64 constant or table entry.
    fn of(x: f64) -> Self {
        Self::from_f64(x).expect("every f64 converts to f32 or f64")
    }

    /// `values` themselves where `Self` is f32, so that the f32 throughput path reads them
    /// in place; `None` otherwise.
    fn as_f32_slice(_values: &[Self]) -> Option<&[f32]> {
        None
    }

    /// [`Real::as_f32_slice`], to write in place.
    fn as_f32_slice_mut(_values: &mut [Self]) -> Option<&mut [f32]> {
        None
    }
}
impl Real for f32 {
    fn as_f32_slice(values: &[f32]) -> Option<&[f32]> {
        Some(values)
    }

    fn as_f32_slice_mut(values: &mut [f32]) -> Option<&mut [f32]> {
        Some(values)
    }
}
impl Real for f64 {}

/// Lowest and highest supported orders. The math is defined for any order; the tables
/// and the shading kernels are tested from 3 to 8.
pub const MIN_ORDER: usize = 3;
pub const MAX_ORDER: usize = 8;
/// Coefficients of the highest supported order, for fixed-size per-pixel buffers.
pub const MAX_COEFFICIENTS: usize = MAX_ORDER * MAX_ORDER;

/// Number of coefficients of an order-`order` expansion.
pub const fn coefficient_count(order: usize) -> usize {
    order * order
}

/// Position of `(l, m)` in a coefficient vector, `-l <= m <= l`.
pub const fn index(l: usize, m: i32) -> usize {
    ((l * (l + 1)) as isize + m as isize) as usize
}

/// Normalisation `K_l^m` for `m >= 0` (from a table for the bands the kernels use: it is
/// read per blocker and pixel).
pub fn normalisation(l: usize, m: usize) -> f64 {
    if l < TABULATED_BANDS && m <= l {
        FACTORS.normalisation[l][m]
    } else {
        computed_normalisation(l, m)
    }
}

fn computed_normalisation(l: usize, m: usize) -> f64 {
    let mut ratio = 1.0; // (l - m)! / (l + m)!
    for k in (l - m + 1)..=(l + m) {
        ratio /= k as f64;
    }
    ((2 * l + 1) as f64 / (4.0 * std::f64::consts::PI) * ratio).sqrt()
}

/// The factor of the real basis function `y_l^m`: `K_l^|m|`, times `sqrt(2)` for
/// `m != 0` (what [`eval_basis`] multiplies `P_l^|m|` and `cos`/`sin(m phi)` by).
pub fn real_normalisation(l: usize, m: i64) -> f64 {
    let k = normalisation(l, m.unsigned_abs() as usize);
    if m == 0 {
        k
    } else {
        std::f64::consts::SQRT_2 * k
    }
}

/// Bands whose factors [`eval_basis`] reads from a table rather than computing them per
/// call (the normalisation is a product of up to 2l factors and a square root; per pixel it
/// was a fifth of the CPU shading time).
const TABULATED_BANDS: usize = 2 * MAX_ORDER;

/// [`normalisation`] and [`double_factorial_odd`] for the first [`TABULATED_BANDS`]
/// bands, the same values.
struct BasisFactors {
    normalisation: [[f64; TABULATED_BANDS]; TABULATED_BANDS],
    double_factorial: [f64; TABULATED_BANDS],
    /// The upward recurrence's `(2l - 1) / (l - m)` and `(l + m - 1) / (l - m)`, so that
    /// a basis evaluation divides nothing (`m = 0` is [`legendre`]'s).
    recurrence: [[(f64, f64); TABULATED_BANDS]; TABULATED_BANDS],
    /// [`funk_hecke_factor`]'s values.
    funk_hecke: [f64; TABULATED_BANDS],
}

static FACTORS: std::sync::LazyLock<BasisFactors> = std::sync::LazyLock::new(|| BasisFactors {
    normalisation: std::array::from_fn(|l| {
        std::array::from_fn(|m| if m <= l { computed_normalisation(l, m) } else { 0.0 })
    }),
    double_factorial: std::array::from_fn(double_factorial_odd),
    recurrence: std::array::from_fn(|l| std::array::from_fn(|m| recurrence_factors(l, m))),
    funk_hecke: std::array::from_fn(computed_funk_hecke_factor),
});

/// `(2l - 1) / (l - m)` and `(l + m - 1) / (l - m)`: `Q_l^m = a z Q_{l-1}^m - b Q_{l-2}^m`
/// (0 where `l <= m`, which the recurrence never reads).
fn recurrence_factors(l: usize, m: usize) -> (f64, f64) {
    if l <= m {
        return (0.0, 0.0);
    }
    let d = (l - m) as f64;
    ((2 * l - 1) as f64 / d, (l + m - 1) as f64 / d)
}

/// Evaluates all `order * order` basis functions at the unit direction `(x, y, z)` into
/// `out[..order * order]`.
///
/// Uses `P_l^m(cos theta) = sin^m(theta) Q_l^m(z)` and
/// `sin^m(theta) (cos m phi, sin m phi) = (Re, Im) (x + i y)^m`, so no trigonometry and
/// no division: exact at the poles. Relative accuracy about 1e-15 (f64) or 1e-6 (f32)
/// through order 8.
pub fn eval_basis<T: Real>(order: usize, dir: [T; 3], out: &mut [T]) {
    assert!(out.len() >= order * order, "eval_basis: output holds fewer than order^2 values");
    // The supported orders each get a copy with the loops' bounds known, unrolled (a
    // shared dispatch taking a closure measured 5-10 % slower on blockers50/order4).
    match order {
        3 => eval_basis_of_order(3, dir, out),
        4 => eval_basis_of_order(4, dir, out),
        5 => eval_basis_of_order(5, dir, out),
        6 => eval_basis_of_order(6, dir, out),
        7 => eval_basis_of_order(7, dir, out),
        8 => eval_basis_of_order(8, dir, out),
        _ => eval_basis_of_order(order, dir, out),
    }
}

/// [`eval_basis`] inlined into its caller, so that a constant `n` unrolls its loops.
#[inline(always)]
pub(crate) fn eval_basis_of_order<T: Real>(n: usize, dir: [T; 3], out: &mut [T]) {
    let [x, y, z] = dir;
    let out = &mut out[..n * n];
    let sqrt2 = T::SQRT_2();
    let factors: &BasisFactors = &FACTORS;
    // (x + i y)^m, starting at m = 0.
    let (mut cm, mut sm) = (T::one(), T::zero());
    for m in 0..n {
        // Q_m^m = (2m - 1)!!, then the upward recurrence in l.
        let mut q_prev = T::zero();
        let mut q = T::of(if m < TABULATED_BANDS { factors.double_factorial[m] } else { double_factorial_odd(m) });
        for l in m..n {
            if l == m + 1 {
                q_prev = q;
                q = z * T::of((2 * m + 1) as f64) * q_prev;
            } else if l > m + 1 {
                let (a, b) = if l < TABULATED_BANDS { factors.recurrence[l][m] } else { recurrence_factors(l, m) };
                let next = T::of(a) * z * q - T::of(b) * q_prev;
                q_prev = q;
                q = next;
            }
            let k = T::of(if l < TABULATED_BANDS { factors.normalisation[l][m] } else { computed_normalisation(l, m) });
            if m == 0 {
                out[index(l, 0)] = k * q;
            } else {
                out[index(l, m as i32)] = sqrt2 * k * q * cm;
                out[index(l, -(m as i32))] = sqrt2 * k * q * sm;
            }
        }
        let (c, s) = (cm * x - sm * y, cm * y + sm * x);
        cm = c;
        sm = s;
    }
}

/// Basis at `(theta, phi)`; see [`eval_basis`].
pub fn eval_basis_spherical<T: Real>(order: usize, theta: T, phi: T, out: &mut [T]) {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    eval_basis(order, [st * cp, st * sp, ct], out);
}

/// Evaluates an expansion at a direction: `sum_i coeffs[i] y_i(dir)`.
pub fn eval_expansion<T: Real>(order: usize, coeffs: &[T], dir: [T; 3]) -> T {
    let mut y = [T::zero(); MAX_COEFFICIENTS * 4];
    let y = &mut y[..order * order];
    eval_basis(order, dir, y);
    coeffs.iter().zip(y.iter()).fold(T::zero(), |acc, (&c, &b)| acc + c * b)
}

/// Legendre polynomials `P_0(z) ..= P_{count-1}(z)` (unnormalised, `P_l(1) = 1`).
pub fn legendre<T: Real>(count: usize, z: T, out: &mut [T]) {
    let factors: &BasisFactors = &FACTORS;
    // The last two values are carried in locals: reading them back from `out` right after
    // writing them stalls on store forwarding.
    let (mut before, mut last) = (T::zero(), T::one());
    for (l, o) in out[..count].iter_mut().enumerate() {
        let value = match l {
            0 => T::one(),
            1 => z,
            _ => {
                let (a, b) = if l < TABULATED_BANDS { factors.recurrence[l][0] } else { recurrence_factors(l, 0) };
                T::of(a) * z * last - T::of(b) * before
            }
        };
        if l > 0 {
            before = last;
        }
        last = value;
        *o = value;
    }
}

/// Normalised Legendre polynomial `P^_l = sqrt((2l + 1) / 2) P_l` (paper 000, Eq. 13):
/// orthonormal on [-1, 1], and `y_l^0 = P^_l(cos theta) / sqrt(2 pi)` (Eq. 12).
pub fn nlp_scale(l: usize) -> f64 {
    ((2 * l + 1) as f64 / 2.0).sqrt()
}

/// `sqrt(4 pi / (2l + 1))`, the Funk-Hecke factor of paper 000, Eq. 5 (from a table for
/// the bands the kernels use: it is read per blocker and pixel).
pub fn funk_hecke_factor(l: usize) -> f64 {
    if l < TABULATED_BANDS {
        FACTORS.funk_hecke[l]
    } else {
        computed_funk_hecke_factor(l)
    }
}

/// The clamped cosine's SH factor of band `l`, `A_l` (Ramamoorthi and Hanrahan 2001, Eq.
/// 8): irradiance is `E = sum_lm A_l L_lm y_lm`. `pi` and `2 pi / 3` for bands 0 and 1, 0
/// for odd bands above, and `2 pi (-1)^(l/2 - 1) / ((l + 2)(l - 1)) l! / (2^l (l/2)!^2)`
/// for even ones.
pub fn clamped_cosine_factor(l: usize) -> f64 {
    use std::f64::consts::PI;
    match l {
        0 => PI,
        1 => 2.0 * PI / 3.0,
        _ if l % 2 == 1 => 0.0,
        _ => {
            let half = l / 2;
            // l! / (2^l (l/2)!^2), a product of half ratios (2k - 1) / 2k.
            let central = (1..=half).map(|k| (2 * k - 1) as f64 / (2 * k) as f64).product::<f64>();
            let sign = if half % 2 == 1 { 1.0 } else { -1.0 };
            2.0 * PI * sign / ((l + 2) * (l - 1)) as f64 * central
        }
    }
}

fn computed_funk_hecke_factor(l: usize) -> f64 {
    (4.0 * std::f64::consts::PI / (2 * l + 1) as f64).sqrt()
}

/// `(2m - 1)!!` with `(-1)!! = 1`: `Q_m^m`, where [`eval_basis`]'s recurrence in `l`
/// starts.
pub fn double_factorial_odd(m: usize) -> f64 {
    (1..=m).fold(1.0, |acc, k| acc * (2 * k - 1) as f64)
}
