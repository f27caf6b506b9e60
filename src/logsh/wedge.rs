//! The wedge interpolation operator M_lin (paper 000, Eq. 18-23).

use crate::sh::basis::{coefficient_count, eval_basis_spherical, legendre, nlp_scale, Real};
use crate::sh::quadrature::gauss_legendre_on;
use crate::sh::rotation::{rotate_z_with, z_rotation_phases};
use std::f64::consts::PI;

/// `M_lin` for one order and one wedge width `dphi = 2 pi / W`: an `n^2 x 2n` matrix that
/// maps the NLP log vectors of a wedge's two border slices `[v_i, v_{i+1}]` to the SH
/// log vector of the canonical wedge `0 <= phi <= dphi`, with the slices interpolated
/// linearly in `phi` inside the wedge and zero (visibility 1) outside (Eq. 19-23).
///
/// Entries are integrated by Gauss-Legendre in `theta` (64 nodes on [0, pi]) and in `phi`
/// (32 nodes on [0, dphi]); the integrands are smooth, so the entries are exact to about
/// 1e-13 at orders up to 8 (checked in the tests against a direct quadrature of Eq. 18).
#[derive(Clone, Debug)]
pub struct WedgeOperator {
    pub order: usize,
    pub directions: usize,
    /// Row-major, `order^2` rows of `2 * order` columns.
    pub matrix: Vec<f64>,
}

impl WedgeOperator {
    pub fn new(order: usize, directions: usize) -> Self {
        assert!(directions >= 3, "a wedge operator needs at least 3 azimuthal directions");
        let count = coefficient_count(order);
        let columns = 2 * order;
        let dphi = 2.0 * PI / directions as f64;
        let thetas: Vec<(f64, f64)> = gauss_legendre_on(64, 0.0, PI).collect();
        let phis: Vec<(f64, f64)> = gauss_legendre_on(32, 0.0, dphi).collect();
        let mut matrix = vec![0.0; count * columns];
        let mut y = vec![0.0; count];
        let mut p = vec![0.0; order];
        for &(theta, wt) in &thetas {
            legendre(order, theta.cos(), &mut p);
            for &(phi, wp) in &phis {
                eval_basis_spherical(order, theta, phi, &mut y);
                let alpha = phi / dphi; // Eq. 22
                let w = wt * wp * theta.sin();
                for (i, yi) in y.iter().enumerate() {
                    let row = &mut matrix[i * columns..(i + 1) * columns];
                    for j in 0..order {
                        let nlp = nlp_scale(j) * p[j];
                        row[j] += w * (1.0 - alpha) * nlp * yi; // Eq. 23, first half
                        row[order + j] += w * alpha * nlp * yi; // second half
                    }
                }
            }
        }
        Self { order, directions, matrix }
    }

    /// Width of one wedge in radians.
    pub fn wedge_width(&self) -> f64 {
        2.0 * PI / self.directions as f64
    }

    /// Adds the log-SH visibility of a full turn of wedges to `acc` from the NLP slices
    /// `slices[k * order..(k + 1) * order]` at azimuths `phi_k = k * dphi`: wedge `k`
    /// interpolates slices `k` and `k + 1 (mod W)` and is rotated about z by `phi_k`
    /// (Eq. 20, then the z-rotation of Section 4.1).
    pub fn accumulate<T: Real>(&self, slices: &[T], acc: &mut [T]) {
        let n = self.order;
        let count = coefficient_count(n);
        let columns = 2 * n;
        let w = self.directions;
        let step = z_rotation_phases::<T>(n, T::of(self.wedge_width()));
        let mut phases = z_rotation_phases::<T>(n, T::zero());
        let mut wedge = [T::zero(); crate::sh::MAX_COEFFICIENTS];
        // The operator in `T` once per call, column by column: a wedge is then a sum of
        // columns scaled by its slices' values, which vectorises over the coefficients (each
        // coefficient's sum is taken in the same order as a row's dot product).
        let mut columns_t = [T::zero(); crate::sh::MAX_COEFFICIENTS * 2 * crate::sh::MAX_ORDER];
        let columns_t = &mut columns_t[..count * columns];
        for i in 0..count {
            for j in 0..columns {
                columns_t[j * count + i] = T::of(self.matrix[i * columns + j]);
            }
        }
        for k in 0..w {
            let first = &slices[k * n..(k + 1) * n];
            let second = &slices[((k + 1) % w) * n..((k + 1) % w + 1) * n];
            let wedge = &mut wedge[..count];
            wedge.fill(T::zero());
            for j in 0..n {
                let (a, b) = (&columns_t[j * count..(j + 1) * count], &columns_t[(n + j) * count..(n + j + 1) * count]);
                let (f, s) = (first[j], second[j]);
                for i in 0..count {
                    wedge[i] = wedge[i] + a[i] * f + b[i] * s;
                }
            }
            rotate_z_with(n, &mut wedge[..count], &phases[..n]);
            for (a, v) in acc[..count].iter_mut().zip(&wedge[..count]) {
                *a = *a + *v;
            }
            // Advance the rotation by one wedge: phase_m(k+1) = phase_m(k) * step_m.
            for m in 0..n {
                let (c, s) = phases[m];
                let (cs, ss) = step[m];
                phases[m] = (c * cs - s * ss, s * cs + c * ss);
            }
        }
    }
}
