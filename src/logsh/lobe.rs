//! Log-ZH of the BRDF lobes (paper 000, Section 5 and Eq. 27), clamped relative to the
//! lobe's peak.
//!
//! The paper clamps the lobe itself, `log(max(f, eps))`. The diffuse lobe `cos/pi` never
//! exceeds 0.32, so with the paper's `eps = 0.2` most of it is clamped and an unoccluded
//! plane comes out 1.59 instead of 1 at order 4 (docs/design.md, "Measured already"). Here the
//! clamp is relative to the peak: `log(max(f / f_max, eps)) + log(f_max)`, the constant
//! going into the DC term, so `eps` means the same thing for every lobe and every
//! normalisation.

use crate::memo::Memo;
use crate::sh::basis::{legendre, Real};
use crate::sh::quadrature::gauss_legendre_on;
use std::f64::consts::PI;

/// A BRDF lobe about +Z.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Lobe {
    /// `max(cos theta, 0) / pi`, aligned with the normal.
    Diffuse,
    /// `(r + 1) / (2 pi) max(cos theta, 0)^r`, aligned with the reflected view vector
    /// (Eq. 27: no cosine factor).
    Phong { exponent: f64 },
}

impl Lobe {
    /// `(r, f_max)`: the power of `cos theta` and the lobe's peak value.
    fn shape(self) -> (f64, f64) {
        match self {
            Lobe::Diffuse => (1.0, 1.0 / PI),
            Lobe::Phong { exponent } => (exponent, (exponent + 1.0) / (2.0 * PI)),
        }
    }

    /// The lobe's peak value `f_max` (along its axis).
    pub fn peak(self) -> f64 {
        self.shape().1
    }

    /// The lobe's value at `cos theta = z` (for quadrature checks and the reference).
    pub fn value(self, z: f64) -> f64 {
        let (r, peak) = self.shape();
        if z <= 0.0 {
            0.0
        } else {
            peak * z.powf(r)
        }
    }

    /// The clamped log lobe `log(max(f / f_max, eps)) + log(f_max)` at `cos theta = z`.
    pub fn clamped_log(self, z: f64, epsilon: f64) -> f64 {
        let (_, peak) = self.shape();
        (self.value(z) / peak).max(epsilon).ln() + peak.ln()
    }
}

/// Number of Gauss nodes for the smooth part of the lobe integral; with the substitution
/// `z = e^t` the integrand `t e^t P_l(e^t)` is entire, so 96 nodes give about 1e-14 even
/// for `eps = 1e-6` (a span of 14 in `t`).
const LOBE_NODES: usize = 96;

/// ZH coefficients `g_l = 2 pi K_l integral g(z) P_l(z) dz` of the clamped log lobe, with
/// `g = (log eps + c)` for `z <= z_c = eps^(1/r)` and `r log z + c` above, `c = log f_max`.
/// The constant parts use the closed form `integral P_l`; the `log z` part is integrated
/// with `z = e^t`. Exact to about 1e-13 for `1e-6 <= eps < 1` and `1 <= r <= 1024`.
pub fn lobe_log_zh(order: usize, lobe: Lobe, epsilon: f64) -> Vec<f64> {
    let (r, peak) = lobe.shape();
    let c = peak.ln();
    let log_eps = epsilon.ln();
    let t_min = log_eps / r; // log z_c
    let z_c = t_min.exp();
    let mut p_low = vec![0.0; order + 1];
    legendre(order + 1, z_c, &mut p_low);
    let mut p = vec![0.0; order];
    let mut log_part = vec![0.0; order];
    for (t, w) in gauss_legendre_on(LOBE_NODES, t_min, 0.0) {
        let z = t.exp();
        legendre(order, z, &mut p);
        for l in 0..order {
            log_part[l] += w * r * t * z * p[l];
        }
    }
    (0..order)
        .map(|l| {
            // integral_{-1}^{z_c} P_l and integral_{z_c}^{1} P_l.
            let (below, above) = if l == 0 {
                (z_c + 1.0, 1.0 - z_c)
            } else {
                let below = (p_low[l + 1] - p_low[l - 1]) / (2 * l + 1) as f64;
                (below, -below)
            };
            let k = ((2 * l + 1) as f64 / (4.0 * PI)).sqrt();
            2.0 * PI * k * ((log_eps + c) * below + c * above + log_part[l])
        })
        .collect()
}

/// [`lobe_log_zh`] converted to the working precision.
pub fn lobe_log_zh_as<T: Real>(order: usize, lobe: Lobe, epsilon: f64) -> Vec<T> {
    lobe_log_zh(order, lobe, epsilon).into_iter().map(T::of).collect()
}

/// ZH coefficients of the lobe itself (not its log): `2 pi K_l integral f(z) P_l(z) dz`,
/// with `z = e^t` so that sharp Phong lobes (`z^1024`) are resolved: the integrand
/// `f_max e^((r+1) t) P_l(e^t)` is smooth on `t in [-60 / (r + 1), 0]`, beyond which it is
/// below `e^-60`. Exact to about 1e-13.
pub fn lobe_zh(order: usize, lobe: Lobe) -> Vec<f64> {
    let (r, peak) = lobe.shape();
    let mut p = vec![0.0; order];
    let mut out = vec![0.0; order];
    for (t, w) in gauss_legendre_on(LOBE_NODES, -60.0 / (r + 1.0), 0.0) {
        let z = t.exp();
        legendre(order, z, &mut p);
        let value = peak * ((r + 1.0) * t).exp();
        for l in 0..order {
            out[l] += w * value * p[l];
        }
    }
    (0..order).map(|l| 2.0 * PI * ((2 * l + 1) as f64 / (4.0 * PI)).sqrt() * out[l]).collect()
}

/// L2 distance between the lobe's order-n SH projection and the exact exponential of its
/// clamped log-SH lobe (the error paper 000's Figure 6 plots, for the peak-relative
/// clamp).
pub fn lobe_exp_error(order: usize, lobe: Lobe, epsilon: f64, exact: &crate::sh::ExactExp) -> f64 {
    let truth = lobe_zh(order, lobe);
    let log_zh = lobe_log_zh(order, lobe, epsilon);
    let mut f = vec![0.0; order * order];
    crate::sh::rotate_zonal(order, &log_zh, [0.0, 0.0, 1.0], &mut f);
    let mut e = vec![0.0; order * order];
    exact.exp(&f, &mut e);
    (0..order).map(|l| (e[crate::sh::index(l, 0)] - truth[l]).powi(2)).sum::<f64>().sqrt()
}

/// [`optimal_lobe_epsilon`] on [`crate::sh::ExactExp::new`]'s grid, searched once per
/// order and lobe in a process ([`crate::memo`]).
pub fn shared_optimal_lobe_epsilon(order: usize, lobe: Lobe) -> f64 {
    static FOUND: Memo<(usize, Option<u64>), f64> = Memo::new();
    let shape = match lobe {
        Lobe::Diffuse => None,
        Lobe::Phong { exponent } => Some(exponent.to_bits()),
    };
    *FOUND.get_or_build((order, shape), || optimal_lobe_epsilon(order, lobe, &crate::sh::ExactExp::shared(order, true)))
}

/// Range searched by [`optimal_lobe_epsilon`].
pub const LOBE_EPSILON_RANGE: (f64, f64) = (1e-3, 0.9);

/// The eps in [`LOBE_EPSILON_RANGE`] minimising [`lobe_exp_error`]: a scan of 25
/// log-spaced values, then golden-section refinement around the best (the error is not
/// unimodal over the whole range, see `docs/epsilon/`). About 40 exponentiations.
pub fn optimal_lobe_epsilon(order: usize, lobe: Lobe, exact: &crate::sh::ExactExp) -> f64 {
    let (lo, hi) = (LOBE_EPSILON_RANGE.0.ln(), LOBE_EPSILON_RANGE.1.ln());
    let error = |log_eps: f64| lobe_exp_error(order, lobe, log_eps.exp(), exact);
    let found = super::minimise::scan_then_golden(error, (lo, hi), 24, 14);
    let (refined, (best, best_error)) = (found.refined, found.best_scanned);
    if error(refined) <= best_error {
        refined.exp()
    } else {
        best.exp()
    }
}
