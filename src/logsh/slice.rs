//! NLP log-visibility of one azimuthal slice (paper 000, Eq. 15-16; NS09 Section 4),
//! generalised from the order-4 closed form to any order.

use crate::sh::basis::{legendre, nlp_scale, Real};

/// Writes the `order` NLP coefficients of the log visibility of a slice whose horizon lies
/// at elevation `sigma` (radians above the horizontal): `log(eps)` for polar angles
/// `theta > pi/2 - sigma`, 0 above (Eq. 15):
/// `v_l = log(eps) * integral_{-1}^{sin sigma} P^_l(z) dz`.
/// With `integral P_l = (P_{l+1} - P_{l-1}) / (2l + 1)` (the lower limit cancels because
/// `P_{l+1}(-1) = P_{l-1}(-1)`), this is closed form at every order and reproduces Eq. 16
/// at order 4. Exact up to rounding; `sigma` may lie anywhere in `[-pi/2, pi/2]`.
pub fn nlp_slice<T: Real>(order: usize, log_epsilon: T, sigma: T, out: &mut [T]) {
    nlp_slice_of_sine(order, log_epsilon, sigma.sin(), out);
}

/// [`nlp_slice`] given `sin sigma` (clamped to `[-1, 1]`) rather than `sigma`.
pub fn nlp_slice_of_sine<T: Real>(order: usize, log_epsilon: T, sine: T, out: &mut [T]) {
    let s = sine.max(-T::one()).min(T::one());
    let mut p = [T::zero(); crate::sh::MAX_ORDER + 2];
    legendre(order + 1, s, &mut p);
    for l in 0..order {
        let integral = if l == 0 { s + T::one() } else { (p[l + 1] - p[l - 1]) / T::of((2 * l + 1) as f64) };
        out[l] = log_epsilon * T::of(nlp_scale(l)) * integral;
    }
}
