//! Quadrature over the sphere: the independent second method every closed form in the
//! crate is checked against, and the way the tables are projected.
//!
//! A product rule: Gauss-Legendre in `z = cos theta` times the uniform (trapezoid) rule in
//! `phi`. With `nz` nodes in z and `nphi >= 2 * nz` in phi it integrates every spherical
//! polynomial of degree `< 2 * nz` exactly (up to rounding, about 1e-14), so products of up
//! to three order-`n` basis functions need only `nz >= 3n / 2`.

use super::basis::{eval_basis, Real};
use crate::memo::Memo;

/// Gauss-Legendre nodes and weights on [-1, 1], by Newton's iteration on `P_count`.
/// Nodes and weights are accurate to about 1e-15 for any count up to several thousand.
/// Each count's rule is worked out once per process ([`crate::memo`]).
pub fn gauss_legendre(count: usize) -> (Vec<f64>, Vec<f64>) {
    static RULES: Memo<usize, (Vec<f64>, Vec<f64>)> = Memo::new();
    let rule = RULES.get_or_build(count, || newton_gauss_legendre(count));
    (rule.0.clone(), rule.1.clone())
}

fn newton_gauss_legendre(count: usize) -> (Vec<f64>, Vec<f64>) {
    let mut nodes = vec![0.0; count];
    let mut weights = vec![0.0; count];
    let n = count as f64;
    for i in 0..count.div_ceil(2) {
        // Tricomi's initial guess, then Newton.
        let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n + 0.5)).cos();
        let mut derivative = 1.0;
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0, x);
            for k in 2..=count {
                let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            if count == 1 {
                p0 = 1.0;
                p1 = x;
            }
            derivative = n * (x * p1 - p0) / (x * x - 1.0);
            let step = p1 / derivative;
            x -= step;
            if step.abs() < 1e-16 {
                break;
            }
        }
        let w = 2.0 / ((1.0 - x * x) * derivative * derivative);
        nodes[i] = x;
        weights[i] = w;
        nodes[count - 1 - i] = -x;
        weights[count - 1 - i] = w;
    }
    (nodes, weights)
}

/// Gauss-Legendre rule mapped onto `[a, b]`.
pub fn gauss_legendre_on(count: usize, a: f64, b: f64) -> impl Iterator<Item = (f64, f64)> {
    let (nodes, weights) = gauss_legendre(count);
    let half = 0.5 * (b - a);
    let mid = 0.5 * (a + b);
    nodes.into_iter().zip(weights).map(move |(x, w)| (mid + half * x, half * w))
}

/// A set of directions and weights whose weighted sum approximates an integral over the
/// unit sphere.
#[derive(Clone, Debug)]
pub struct SphereQuadrature {
    pub directions: Vec<[f64; 3]>,
    pub weights: Vec<f64>,
}

impl SphereQuadrature {
    /// Product rule with `nz` Gauss-Legendre nodes in `cos theta` and `2 * nz` azimuths.
    pub fn gauss(nz: usize) -> Self {
        Self::gauss_with(nz, 2 * nz)
    }

    /// Product rule with `nz` Gauss-Legendre nodes in `cos theta` and `nphi` azimuths.
    pub fn gauss_with(nz: usize, nphi: usize) -> Self {
        let (zs, wz) = gauss_legendre(nz);
        let dphi = 2.0 * std::f64::consts::PI / nphi as f64;
        let mut directions = Vec::with_capacity(nz * nphi);
        let mut weights = Vec::with_capacity(nz * nphi);
        for (z, w) in zs.iter().zip(&wz) {
            let s = (1.0 - z * z).max(0.0).sqrt();
            for j in 0..nphi {
                let phi = (j as f64 + 0.5) * dphi;
                directions.push([s * phi.cos(), s * phi.sin(), *z]);
                weights.push(w * dphi);
            }
        }
        Self { directions, weights }
    }

    /// Number of nodes in z that makes projection of an order-`order` function times a
    /// smooth factor exact to rounding for the products the crate forms (degree `3(n-1)`),
    /// with margin.
    pub fn for_products(order: usize) -> Self {
        Self::gauss(3 * order / 2 + 2)
    }

    pub fn len(&self) -> usize {
        self.weights.len()
    }

    pub fn is_empty(&self) -> bool {
        self.weights.is_empty()
    }

    /// Integral of `f` over the sphere.
    pub fn integrate(&self, mut f: impl FnMut([f64; 3]) -> f64) -> f64 {
        self.directions.iter().zip(&self.weights).map(|(d, w)| w * f(*d)).sum()
    }

    /// Order-`order` projection of `f` (paper 000, Eq. 3).
    pub fn project<T: Real>(&self, order: usize, mut f: impl FnMut([f64; 3]) -> f64) -> Vec<T> {
        let count = order * order;
        let mut acc = vec![0.0f64; count];
        let mut y = vec![0.0f64; count];
        for (d, w) in self.directions.iter().zip(&self.weights) {
            let value = f(*d);
            if value == 0.0 {
                continue;
            }
            eval_basis(order, *d, &mut y);
            for (a, b) in acc.iter_mut().zip(&y) {
                *a += w * value * b;
            }
        }
        acc.into_iter().map(T::of).collect()
    }
}
