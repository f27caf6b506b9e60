//! The quadrature of [`ExactExp`] in separable form, as the GPU program sums it
//! (`shaders/exp_quad.wgsl`). The grid is a product of Gauss rows in `cos theta` and
//! uniform azimuths `phi_j = (j + 1/2) 2 pi / N`, and every real SH basis function is a
//! row factor times `cos(m phi)` or `sin(m phi)` (`src/sh/basis.rs`:
//! `y_{l,m} = R_lm(z) cos(m phi)`, `y_{l,-m} = R_lm(z) sin(m phi)`), so at node `(a, j)`
//!
//! ```text
//! f(x_aj) = sum_m C_m(a) cos(m phi_j) + S_m(a) sin(m phi_j),
//! C_m(a) = sum_l R_lm(z_a) f_{l,m},   S_m(a) = sum_l R_lm(z_a) f_{l,-m}
//! ```
//!
//! `C` and `S` cost `order^2` multiply-adds per row, and each node then sums over `m` by
//! Clenshaw's recurrence (`4 (order - 1)` operations and no table read) instead of
//! `order^2` multiply-adds, each reading the basis table: the `quad` grid has `2n + 2`
//! rows of `4n + 4` nodes, so at order 4 a pixel reads 100 table values per function
//! instead of 3200, and at order 8 it does a quarter of the arithmetic. The nodes, weights,
//! floor and ceiling are [`ExactExp::exp_floored`]'s and the light is folded in as in
//! [`super::FoldedQuadrature`]; the tests below check the node values against the
//! tabulated basis.

use super::basis::{coefficient_count, eval_basis};
use super::exp::ExactExp;
use super::quadrature::gauss_legendre;

/// The tables of one [`ExactExp`] grid in separable form, in f32, with the light folded in.
#[derive(Clone, Debug)]
pub struct SeparableQuadrature {
    /// Gauss rows in `cos theta`.
    pub rows: usize,
    /// Azimuths per row.
    pub azimuths: usize,
    /// Per row, `R_lm(z_a)` for `m = 0..order` and, within `m`, `l = m..order`:
    /// `order (order + 1) / 2` values.
    pub row_factors: Vec<f32>,
    /// `(cos phi_j, sin phi_j)` per azimuth.
    pub azimuth_cos_sin: Vec<[f32; 2]>,
    /// Per node (row by row), `w_i L(x_i)` per channel.
    pub node_light: Vec<[f32; 3]>,
}

impl SeparableQuadrature {
    /// The grid of `quadrature` with the light whose SH coefficients are `light[c][k]`
    /// (channel `c`, coefficient `k`) folded in.
    pub fn new(quadrature: &ExactExp, light: &[Vec<f64>; 3]) -> Self {
        let order = quadrature.order();
        let count = coefficient_count(order);
        let rows = quadrature.rows();
        let azimuths = quadrature.weights().len() / rows;
        let (zs, _) = gauss_legendre(rows);
        let mut row_factors = Vec::with_capacity(rows * order * (order + 1) / 2);
        let mut y = vec![0.0f64; count];
        for z in zs {
            // At phi = 0, y_{l,m} = R_lm(z) for m >= 0.
            eval_basis(order, [(1.0 - z * z).max(0.0).sqrt(), 0.0, z], &mut y);
            for m in 0..order {
                row_factors.extend((m..order).map(|l| y[l * (l + 1) + m] as f32));
            }
        }
        let step = 2.0 * std::f64::consts::PI / azimuths as f64;
        let azimuth_cos_sin = (0..azimuths)
            .map(|j| {
                let (sin, cos) = ((j as f64 + 0.5) * step).sin_cos();
                [cos as f32, sin as f32]
            })
            .collect();
        let node_light = quadrature
            .basis()
            .chunks(count)
            .zip(quadrature.weights())
            .map(|(y, w)| {
                std::array::from_fn(|c| (w * y.iter().zip(&light[c]).map(|(a, b)| a * b).sum::<f64>()) as f32)
            })
            .collect();
        Self { rows, azimuths, row_factors, azimuth_cos_sin, node_light }
    }

    /// `f` at every node of `row`, in the order and arithmetic of
    /// `shaders/exp_quad.wgsl`: the row's `C` and `S`, then Clenshaw's recurrence per
    /// azimuth.
    #[cfg(test)]
    fn row_values(&self, order: usize, f: &[f32], row: usize) -> Vec<f32> {
        let width = order * (order + 1) / 2;
        let factors = &self.row_factors[row * width..(row + 1) * width];
        let (mut c, mut s) = (vec![0.0f32; order], vec![0.0f32; order]);
        let mut next = factors.iter();
        for m in 0..order {
            for l in m..order {
                let r = *next.next().unwrap();
                c[m] += r * f[l * (l + 1) + m];
                if m > 0 {
                    s[m] += r * f[l * (l + 1) - m];
                }
            }
        }
        self.azimuth_cos_sin
            .iter()
            .map(|&[cos, sin]| {
                let (mut b1, mut b2, mut d1, mut d2) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
                for m in (1..order).rev() {
                    let b = c[m] + 2.0 * cos * b1 - b2;
                    let d = s[m] + 2.0 * cos * d1 - d2;
                    (b2, b1, d2, d1) = (b1, b, d1, d);
                }
                c[0] + b1 * cos - b2 + d1 * sin
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Row factors and Clenshaw's recurrence give every node's value as the tabulated
    /// basis does, to f32 rounding, at every order on the `quad` grid and a finer one.
    #[test]
    fn separable_node_values_equal_the_tabulated_basis() {
        for order in 2..=8 {
            for quadrature in [ExactExp::fast(order), ExactExp::with_grid(order, 3 * order + 1)] {
                let count = coefficient_count(order);
                let light: [Vec<f64>; 3] =
                    std::array::from_fn(|c| (0..count).map(|k| 1.0 / (1.0 + (k + c) as f64)).collect());
                let separable = SeparableQuadrature::new(&quadrature, &light);
                assert_eq!(separable.rows * separable.azimuths, quadrature.weights().len());
                let f: Vec<f32> = (0..count).map(|k| 2.5 * ((k as f32 + 0.4) * 1.7).sin()).collect();
                let scale: f32 = f.iter().map(|v| v.abs()).sum();
                for row in 0..separable.rows {
                    let values = separable.row_values(order, &f, row);
                    for (j, value) in values.iter().enumerate() {
                        let node = row * separable.azimuths + j;
                        let y = &quadrature.basis()[node * count..(node + 1) * count];
                        let exact: f64 = y.iter().zip(&f).map(|(a, &b)| a * f64::from(b)).sum();
                        let error = (f64::from(*value) - exact).abs();
                        assert!(error < 2e-6 * f64::from(scale), "order {order}, node {node}: {value} vs {exact}");
                    }
                }
                for (node, folded) in separable.node_light.iter().enumerate() {
                    let y = &quadrature.basis()[node * count..(node + 1) * count];
                    let w = quadrature.weights()[node];
                    for (c, value) in folded.iter().enumerate() {
                        let exact: f64 = w * y.iter().zip(&light[c]).map(|(a, b)| a * b).sum::<f64>();
                        assert!((f64::from(*value) - exact).abs() < 1e-6 * (1.0 + exact.abs()));
                    }
                }
            }
        }
    }
}
