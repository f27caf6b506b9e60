//! The SH product through the tripling tensor (paper 000, Eq. 6).

use super::basis::{coefficient_count, eval_basis, Real};
use super::quadrature::SphereQuadrature;
use crate::memo::Memo;
use std::sync::Arc;

/// Non-zero entries of `Gamma_ijk = integral of y_i y_j y_k` for `i, j, k < order^2`,
/// computed by the crate itself with a quadrature that is exact for the degree-`3(n-1)`
/// integrand; entries below `1e-12` in magnitude are zero by the selection rules and are
/// dropped. Stored by output index `i`, each as `(j, k, Gamma_ijk)` with `j <= k`.
#[derive(Clone, Debug)]
pub struct TriplingTensor {
    order: usize,
    rows: Vec<Vec<(u16, u16, f64)>>,
}

/// Entries smaller than this are zero up to quadrature rounding (the rule is exact, so
/// the computed zeros come out near 1e-16).
const TENSOR_ZERO: f64 = 1e-12;

impl TriplingTensor {
    /// [`TriplingTensor::new`], built once per order and process ([`crate::memo`]).
    pub fn shared(order: usize) -> Arc<Self> {
        static TENSORS: Memo<usize, TriplingTensor> = Memo::new();
        TENSORS.get_or_build(order, || Self::new(order))
    }

    pub fn new(order: usize) -> Self {
        let count = coefficient_count(order);
        let quadrature = SphereQuadrature::for_products(order);
        let mut dense = vec![0.0f64; count * count * count];
        let mut y = vec![0.0f64; count];
        for (d, w) in quadrature.directions.iter().zip(&quadrature.weights) {
            eval_basis(order, *d, &mut y);
            for i in 0..count {
                let wi = w * y[i];
                for j in 0..count {
                    let wij = wi * y[j];
                    let row = &mut dense[(i * count + j) * count..(i * count + j + 1) * count];
                    for (k, entry) in row.iter_mut().enumerate() {
                        *entry += wij * y[k];
                    }
                }
            }
        }
        let rows = (0..count)
            .map(|i| {
                let mut row = Vec::new();
                for j in 0..count {
                    for k in j..count {
                        let g = dense[(i * count + j) * count + k];
                        if g.abs() > TENSOR_ZERO {
                            row.push((j as u16, k as u16, g));
                        }
                    }
                }
                row
            })
            .collect();
        Self { order, rows }
    }

    pub fn order(&self) -> usize {
        self.order
    }

    /// Number of stored entries (with `j <= k`).
    /// Per output coefficient `i`, the entries `(j, k, gamma_ijk)` with `j <= k`.
    pub fn rows(&self) -> &[Vec<(u16, u16, f64)>] {
        &self.rows
    }

    pub fn entry_count(&self) -> usize {
        self.rows.iter().map(Vec::len).sum()
    }

    /// Order-`n` projection of the product of two order-`n` functions, `out = f * g`.
    /// Exact for the truncated product: the bands above `n - 1` that a true product
    /// carries are dropped.
    pub fn product<T: Real>(&self, f: &[T], g: &[T], out: &mut [T]) {
        for (i, row) in self.rows.iter().enumerate() {
            let mut sum = T::zero();
            for &(j, k, gamma) in row {
                let (j, k) = (j as usize, k as usize);
                let pair = if j == k { f[j] * g[k] } else { f[j] * g[k] + f[k] * g[j] };
                sum = sum + T::of(gamma) * pair;
            }
            out[i] = sum;
        }
    }
}
