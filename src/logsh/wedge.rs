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
    /// The full turn ([`WedgeTurn`]) in f64.
    turn: Vec<f64>,
}

/// A full turn of `W` wedges as one `order^2 x (W order)` matrix: wedge `k`'s operator
/// rotated about z by `phi_k` (Eq. 20 and the z-rotation of Section 4.1), its first half
/// applied to slice `k` and its second half to slice `k + 1 (mod W)`, summed per slice.
/// Stored column by column (`order^2` values per slice coefficient, padded with zeros to a
/// multiple of eight so that `lanes` reads whole registers), so that a turn is a sum of
/// columns scaled by the slices' values, which vectorises over the coefficients. Equal to
/// the wedge-by-wedge sum up to rounding.
#[derive(Clone, Debug)]
pub struct WedgeTurn<T> {
    order: usize,
    count: usize,
    /// Values per stored column: `count` rounded up to a multiple of eight.
    stride: usize,
    columns: Vec<T>,
}

impl<T: Real> WedgeTurn<T> {
    /// Adds the log-SH visibility of the turn to `acc` from the NLP slices
    /// `slices[k * order..(k + 1) * order]` at azimuths `phi_k = k * dphi`.
    pub fn accumulate(&self, slices: &[T], acc: &mut [T]) {
        self.accumulate_from(0, slices, acc);
    }

    /// [`Self::accumulate`] for the slices of a run of azimuths from `first` on: the turn is
    /// linear in its slices, so the runs of a full turn add up to it.
    pub fn accumulate_from(&self, first: usize, slices: &[T], acc: &mut [T]) {
        let count = self.count;
        let acc = &mut acc[..count];
        #[cfg(target_arch = "x86_64")]
        if count <= lanes::MAX_COUNT && *crate::x86::AVX2 {
            let columns = T::as_f32_slice(&self.columns);
            if let (Some(columns), Some(slices), Some(acc)) =
                (columns, T::as_f32_slice(slices), T::as_f32_slice_mut(acc))
            {
                // SAFETY: the processor has AVX2; `columns` holds a column of `stride`
                // values per slice coefficient of the turn.
                unsafe { lanes::accumulate(columns, first * self.order, slices, acc) };
                return;
            }
        }
        self.accumulate_columns(first, slices, acc);
    }

    /// [`Self::accumulate_from`] column by column.
    fn accumulate_columns(&self, first: usize, slices: &[T], acc: &mut [T]) {
        let count = self.count;
        let columns = &self.columns[first * self.order * self.stride..];
        for (column, &s) in columns.chunks_exact(self.stride).zip(slices) {
            for (a, c) in acc[..count].iter_mut().zip(&column[..count]) {
                *a = *a + *c * s;
            }
        }
    }
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
        let turn = full_turn(order, directions, &matrix);
        Self { order, directions, matrix, turn }
    }

    /// The full turn in `T` ([`WedgeTurn`]).
    pub fn turn<T: Real>(&self) -> WedgeTurn<T> {
        let count = coefficient_count(self.order);
        let stride = count.div_ceil(8) * 8;
        let mut columns = vec![T::zero(); self.turn.len() / count * stride];
        for (to, from) in columns.chunks_exact_mut(stride).zip(self.turn.chunks_exact(count)) {
            for (t, &v) in to.iter_mut().zip(from) {
                *t = T::of(v);
            }
        }
        WedgeTurn { order: self.order, count, stride, columns }
    }

    /// Width of one wedge in radians.
    pub fn wedge_width(&self) -> f64 {
        2.0 * PI / self.directions as f64
    }

    /// Adds the log-SH visibility of a full turn of wedges to `acc` from the NLP slices
    /// `slices[k * order..(k + 1) * order]` at azimuths `phi_k = k * dphi`: wedge `k`
    /// interpolates slices `k` and `k + 1 (mod W)` and is rotated about z by `phi_k`
    /// (Eq. 20, then the z-rotation of Section 4.1). Per call it converts the turn to `T`;
    /// a caller that accumulates many turns keeps one [`Self::turn`].
    pub fn accumulate<T: Real>(&self, slices: &[T], acc: &mut [T]) {
        self.turn::<T>().accumulate(slices, acc);
    }
}

/// [`WedgeTurn::accumulate_from`] in f32 AVX2 registers: the sum stays in up to eight
/// registers over all the columns, where the plain loop stores and reloads it per column.
/// The same products and sums in the same order, so the same result bit for bit.
#[cfg(target_arch = "x86_64")]
mod lanes {
    /// Most coefficients summed (order 8).
    pub const MAX_COUNT: usize = 64;

    /// `acc += sum_c column (first_column + c) * slices[c]`, the columns of `acc.len()`
    /// values padded to a multiple of eight ([`super::WedgeTurn`]).
    ///
    /// # Safety
    /// The processor has AVX2, and `columns` holds every column read.
    pub unsafe fn accumulate(columns: &[f32], first_column: usize, slices: &[f32], acc: &mut [f32]) {
        match acc.len().div_ceil(8) {
            1 => accumulate_in::<1>(columns, first_column, slices, acc),
            2 => accumulate_in::<2>(columns, first_column, slices, acc),
            3 => accumulate_in::<3>(columns, first_column, slices, acc),
            4 => accumulate_in::<4>(columns, first_column, slices, acc),
            5 => accumulate_in::<5>(columns, first_column, slices, acc),
            6 => accumulate_in::<6>(columns, first_column, slices, acc),
            7 => accumulate_in::<7>(columns, first_column, slices, acc),
            _ => accumulate_in::<8>(columns, first_column, slices, acc),
        }
    }

    /// [`accumulate`] with `acc` in `V` registers of eight.
    #[target_feature(enable = "avx2")]
    unsafe fn accumulate_in<const V: usize>(columns: &[f32], first_column: usize, slices: &[f32], acc: &mut [f32]) {
        use std::arch::x86_64::*;
        let mut values = [0.0f32; MAX_COUNT];
        values[..acc.len()].copy_from_slice(acc);
        let mut sum: [__m256; V] = std::array::from_fn(|v| _mm256_loadu_ps(values[8 * v..].as_ptr()));
        let stride = 8 * V;
        let columns = &columns[first_column * stride..][..slices.len() * stride];
        for (column, &s) in columns.chunks_exact(stride).zip(slices) {
            let s = _mm256_set1_ps(s);
            for (v, sum) in sum.iter_mut().enumerate() {
                *sum = _mm256_add_ps(*sum, _mm256_mul_ps(_mm256_loadu_ps(column[8 * v..].as_ptr()), s));
            }
        }
        for (v, sum) in sum.iter().enumerate() {
            _mm256_storeu_ps(values[8 * v..].as_mut_ptr(), *sum);
        }
        let count = acc.len();
        acc.copy_from_slice(&values[..count]);
    }
}

/// The columns of [`WedgeTurn`] for `matrix` at `order` and `directions`, in f64.
fn full_turn(order: usize, directions: usize, matrix: &[f64]) -> Vec<f64> {
    let (n, count) = (order, coefficient_count(order));
    let columns = 2 * n;
    let dphi = 2.0 * PI / directions as f64;
    let mut turn = vec![0.0; directions * n * count];
    let mut column = vec![0.0; count];
    for k in 0..directions {
        let phases = z_rotation_phases::<f64>(n, dphi * k as f64);
        for j in 0..columns {
            for (i, c) in column.iter_mut().enumerate() {
                *c = matrix[i * columns + j];
            }
            rotate_z_with(n, &mut column, &phases[..n]);
            // The first half weighs slice k, the second slice k + 1.
            let slice = if j < n { k * n + j } else { ((k + 1) % directions) * n + (j - n) };
            for (t, c) in turn[slice * count..(slice + 1) * count].iter_mut().zip(&column) {
                *t += c;
            }
        }
    }
    turn
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The f32 turn in registers gives the column-by-column sum bit for bit, at every order
    /// (counts that fill eight lanes and counts that do not) and from a run's first column.
    #[test]
    fn the_turn_in_registers_sums_as_the_columns_do() {
        for order in 1..=crate::sh::MAX_ORDER {
            let directions = 16;
            let turn = WedgeOperator::new(order, directions).turn::<f32>();
            let slices: Vec<f32> = (0..directions * order).map(|i| ((i * 37 % 23) as f32 - 11.0) * 0.173).collect();
            let start: Vec<f32> = (0..order * order).map(|i| (i as f32 * 0.61).sin()).collect();
            for (first, run) in [(0, directions), (8, 8), (3, 5)] {
                let run_slices = &slices[first * order..(first + run) * order];
                let (mut fast, mut plain) = (start.clone(), start.clone());
                turn.accumulate_from(first, run_slices, &mut fast);
                turn.accumulate_columns(first, run_slices, &mut plain);
                assert_eq!(fast, plain, "order {order}, run of {run} from {first}");
            }
        }
    }
}
