//! Log visibility of a spherical blocker (paper 000, Eq. 24-26, Section 4.2).

use crate::sh::basis::{legendre, normalisation, Real};

/// `2 pi K_l`, `K_l = sqrt((2l+1)/(4 pi))`: the factor of band `l` in the cap's closed form.
pub fn cap_scale(l: usize) -> f64 {
    std::f64::consts::TAU * normalisation(l, 0)
}

/// Writes the `order` ZH coefficients of the log visibility of a cap of angular radius
/// `alpha` around +Z: `log(eps)` inside the cap, 0 outside (Eq. 26; the kernel passes the
/// depth fitted for `alpha` instead, [`crate::shade::fitted_depth`]):
/// `V_l = log(eps) 2 pi K_l integral_{cos alpha}^{1} P_l(z) dz`, `K_l = sqrt((2l+1)/(4 pi))`,
/// with `integral_x^1 P_l = (P_{l-1}(x) - P_{l+1}(x)) / (2l + 1)`. Closed form, exact up to
/// rounding, any order.
pub fn cap_log_zh<T: Real>(order: usize, log_epsilon: T, alpha: T, out: &mut [T]) {
    let x = alpha.cos();
    let mut p = [T::zero(); crate::sh::MAX_ORDER + 2];
    legendre(order + 1, x, &mut p);
    for l in 0..order {
        let integral = if l == 0 { T::one() - x } else { (p[l - 1] - p[l + 1]) * T::of(1.0 / (2 * l + 1) as f64) };
        out[l] = log_epsilon * T::of(cap_scale(l)) * integral;
    }
}

/// What one sphere contributes at one receiver.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BlockerView<T> {
    /// The blocker's centre lies on or behind the receiver's tangent plane
    /// (`n . d <= 0`, paper 000 end of Section 4.2): it is skipped. A receiver on the
    /// surface of the mesh a sphere approximates sees that sphere this way.
    Culled,
    /// Unit direction to the centre, angular radius of the cap, and the weight of its log
    /// vector (the ratio attenuation `r / |c - p|`, or 1).
    Cap { direction: [T; 3], alpha: T, weight: T },
}

/// Sees the sphere `(centre, radius)` from receiver `p` with normal `n` (Eq. 24).
///
/// A receiver inside or touching the sphere (`|c - p| <= r`) sees it as the hemisphere
/// around the direction to its centre (`alpha = pi/2`, the limit of Eq. 24 at the
/// surface) with ratio weight 1: the value stays finite and continuous across the
/// surface. A receiver exactly at the centre has no direction to it and is culled.
pub fn view_blocker<T: Real>(
    p: [T; 3],
    n: [T; 3],
    centre: [T; 3],
    radius: T,
    ratio_attenuation: bool,
) -> BlockerView<T> {
    let d = [centre[0] - p[0], centre[1] - p[1], centre[2] - p[2]];
    let distance = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    if distance <= T::zero() || !distance.is_finite() {
        return BlockerView::Culled;
    }
    let direction = [d[0] / distance, d[1] / distance, d[2] / distance];
    if direction[0] * n[0] + direction[1] * n[1] + direction[2] * n[2] <= T::zero() {
        return BlockerView::Culled;
    }
    let ratio = (radius / distance).min(T::one());
    let alpha = ratio.asin();
    let weight = if ratio_attenuation { ratio } else { T::one() };
    BlockerView::Cap { direction, alpha, weight }
}

/// How far from its centre, relative to its radius, a sphere of the receiver's own object
/// still holds the receiver. The exporter's proxies approximate the object's volume
/// (docs/design.md, "Blocker proxies"), so a pixel of the object lies near the boundary of
/// the union of its spheres, inside some and just outside others, by up to the fit error.
pub const OWN_SPHERE_REACH: f64 = 1.1;

/// Self-shadowing rule, the same in the CPU path, the GPU path and the reference: a
/// receiver takes no shadow from a sphere of its own object (`object != 0`) whose centre
/// lies within [`OWN_SPHERE_REACH`] radii of it. Together with the cull of spheres behind
/// the tangent plane, a convex object (every centre inside it, so behind every tangent
/// plane of its surface) shades as its tangent plane says, and a concave one (a torus,
/// Suzanne) still shadows itself through its spheres across the concavity.
pub fn own_sphere_holds(p: [f64; 3], centre: [f64; 3], radius: f64) -> bool {
    let d = [centre[0] - p[0], centre[1] - p[1], centre[2] - p[2]];
    let reach = OWN_SPHERE_REACH * radius;
    d[0] * d[0] + d[1] * d[1] + d[2] * d[2] <= reach * reach
}
