//! Rotations of SH expansions: zonal functions to any direction (Funk-Hecke) and any
//! expansion about the z axis.

use super::basis::{eval_basis, eval_basis_of_order, funk_hecke_factor, index, Real, MAX_COEFFICIENTS};

/// Rotates a zonal function with ZH coefficients `zonal[l] = z_l` (the `y_l^0`
/// coefficients of a function symmetric about +Z) so that its axis points along the unit
/// vector `dir`, writing `order * order` SH coefficients (paper 000, Eq. 5:
/// `f_l^m = sqrt(4 pi / (2l + 1)) z_l y_l^m(dir)`). Exact up to rounding.
pub fn rotate_zonal<T: Real>(order: usize, zonal: &[T], dir: [T; 3], out: &mut [T]) {
    let mut y = [T::zero(); MAX_COEFFICIENTS];
    eval_basis(order, dir, &mut y);
    for l in 0..order {
        let scale = T::of(funk_hecke_factor(l)) * zonal[l];
        for i in index(l, -(l as i32))..=index(l, l as i32) {
            out[i] = scale * y[i];
        }
    }
}

/// Like [`rotate_zonal`] but adds the rotated function into `acc`, scaled by `weight`: the
/// inner loop of log-SH accumulation.
pub fn add_rotated_zonal<T: Real>(order: usize, zonal: &[T], weight: T, dir: [T; 3], acc: &mut [T]) {
    // The supported orders each get a copy with the loops' bounds known, unrolled.
    match order {
        3 => add_rotated_zonal_of_order(3, zonal, weight, dir, acc),
        4 => add_rotated_zonal_of_order(4, zonal, weight, dir, acc),
        5 => add_rotated_zonal_of_order(5, zonal, weight, dir, acc),
        6 => add_rotated_zonal_of_order(6, zonal, weight, dir, acc),
        7 => add_rotated_zonal_of_order(7, zonal, weight, dir, acc),
        8 => add_rotated_zonal_of_order(8, zonal, weight, dir, acc),
        _ => add_rotated_zonal_of_order(order, zonal, weight, dir, acc),
    }
}

#[inline(always)]
fn add_rotated_zonal_of_order<T: Real>(order: usize, zonal: &[T], weight: T, dir: [T; 3], acc: &mut [T]) {
    let (zonal, acc) = (&zonal[..order], &mut acc[..order * order]);
    let mut y = [T::zero(); MAX_COEFFICIENTS];
    eval_basis_of_order(order, dir, &mut y);
    for l in 0..order {
        let scale = weight * T::of(funk_hecke_factor(l)) * zonal[l];
        for i in index(l, -(l as i32))..=index(l, l as i32) {
            acc[i] = acc[i] + scale * y[i];
        }
    }
}

/// The cosines and sines `cos(m angle), sin(m angle)` for `m = 0..order`, by the angle
/// addition recurrence (drift below 1e-6 in f32 through m = 8).
pub fn z_rotation_phases<T: Real>(order: usize, angle: T) -> [(T, T); super::MAX_ORDER] {
    let mut phases = [(T::one(), T::zero()); super::MAX_ORDER];
    let (s, c) = angle.sin_cos();
    for m in 1..order {
        let (cp, sp) = phases[m - 1];
        phases[m] = (cp * c - sp * s, sp * c + cp * s);
    }
    phases
}

/// Rotates an expansion by `angle` about +Z in place (the function moves
/// counter-clockwise seen from above: `f'(phi) = f(phi - angle)`). Band by band, the
/// `(y_l^m, y_l^-m)` pair turns by `m * angle`. Exact up to rounding, at any order (an
/// `sh` light's may pass the kernel's [`super::MAX_ORDER`]): each `cos(m angle), sin(m
/// angle)` is taken from its own angle.
pub fn rotate_z<T: Real>(order: usize, coeffs: &mut [T], angle: T) {
    let phases: Vec<(T, T)> = (0..order)
        .map(|m| {
            let (sin, cos) = (T::of(m as f64) * angle).sin_cos();
            (cos, sin)
        })
        .collect();
    rotate_z_with(order, coeffs, &phases);
}

/// [`rotate_z`] with the phases precomputed by [`z_rotation_phases`].
pub fn rotate_z_with<T: Real>(order: usize, coeffs: &mut [T], phases: &[(T, T)]) {
    for l in 1..order {
        for m in 1..=l {
            let (c, s) = phases[m];
            let ip = index(l, m as i32);
            let im = index(l, -(m as i32));
            let (a, b) = (coeffs[ip], coeffs[im]);
            coeffs[ip] = a * c - b * s;
            coeffs[im] = a * s + b * c;
        }
    }
}
