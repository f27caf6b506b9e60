//! The light folded into the exponentiation's quadrature: a pixel's radiance needs
//! `exp*(f) . L`, not `exp*(f)` itself, and with the quadrature of [`ExactExp`]
//!
//! ```text
//! exp*(f) . L = sum_k L_k sum_i w_i e^{f(x_i)} y_k(x_i) = sum_i e^{f(x_i)} (w_i L(x_i))
//! ```
//!
//! so the projection back to SH (order^2 multiply-adds per node) and the final dot product
//! become three multiply-adds per node, with `w_i L(x_i)` tabulated once per frame. The
//! same nodes, weights, floor and ceiling as [`ExactExp::exp_floored`] followed by the dot
//! product: the two agree to f32 rounding (`tests` below, 2e-6 relative).
//!
//! This is the f32 throughput path of the CPU executor: the basis is stored
//! coefficient-major and the nodes padded to [`LANES`], so that each block of nodes is a
//! run of independent lanes the compiler vectorises, exponential included ([`exp_lanes`]).
//! The f64 path ([`ExactExp::exp_floored`]) stays the oracle.

use super::basis::coefficient_count;
use super::exp::ExactExp;

/// Nodes evaluated together.
pub const LANES: usize = 8;

#[cfg(target_arch = "x86_64")]
static HAS_AVX2_FMA: std::sync::LazyLock<bool> =
    std::sync::LazyLock::new(|| is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma"));

/// `w_i L(x_i)` and the basis at the nodes of one [`ExactExp`] grid, in f32.
#[derive(Clone, Debug)]
pub struct FoldedQuadrature {
    count: usize,
    /// Nodes, padded to a multiple of [`LANES`] (the padding has weight 0).
    nodes: usize,
    /// `basis[k * nodes + i] = y_k(x_i)`.
    basis: Vec<f32>,
    /// `w_i`.
    weights: Vec<f32>,
    /// Per channel, `w_i L(x_i)`.
    light: [Vec<f32>; 3],
}

impl FoldedQuadrature {
    /// The grid of `quadrature` with the light whose SH coefficients are `light[c][k]`
    /// (channel `c`, coefficient `k`) folded in.
    pub fn new(quadrature: &ExactExp, light: &[Vec<f64>; 3]) -> Self {
        let count = coefficient_count(quadrature.order());
        let weights = quadrature.weights();
        let nodes = weights.len().div_ceil(LANES) * LANES;
        let node_basis = quadrature.basis();
        let mut basis = vec![0.0f32; count * nodes];
        let mut folded = [vec![0.0f32; nodes], vec![0.0f32; nodes], vec![0.0f32; nodes]];
        let mut padded = vec![0.0f32; nodes];
        for (i, w) in weights.iter().enumerate() {
            padded[i] = *w as f32;
            let y = &node_basis[i * count..(i + 1) * count];
            for (k, value) in y.iter().enumerate() {
                basis[k * nodes + i] = *value as f32;
            }
            for (c, channel) in folded.iter_mut().enumerate() {
                let radiance: f64 = light[c].iter().zip(y).map(|(l, b)| l * b).sum();
                channel[i] = (w * radiance) as f32;
            }
        }
        Self { count, nodes, basis, weights: padded, light: folded }
    }

    /// `exp*(f) . L` per channel, clamped at 0, with the nodes' values floored and capped
    /// as [`ExactExp::exp_floored`] does: `f - v + max(v, floor)` with `floored = Some((v,
    /// floor))`, then at most `ceiling`. Where the processor has AVX2 and FMA (checked once
    /// per process), the same code compiled for them: eight lanes per instruction.
    pub fn lit(&self, f: &[f32], floored: Option<(&[f32], f32)>, ceiling: f32) -> [f32; 3] {
        #[cfg(target_arch = "x86_64")]
        if *HAS_AVX2_FMA {
            // SAFETY: the processor supports the features the function is compiled for.
            return unsafe { self.lit_avx2(f, floored, ceiling) };
        }
        self.lit_lanes(f, floored, ceiling)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn lit_avx2(&self, f: &[f32], floored: Option<(&[f32], f32)>, ceiling: f32) -> [f32; 3] {
        self.lit_lanes(f, floored, ceiling)
    }

    /// `exp*(f)` itself, projected back to SH at the same nodes into `out[..order^2]`:
    /// [`ExactExp::exp_floored`] in f32 lanes (the transfer vectors of
    /// [`crate::transfer`]).
    pub fn project(&self, f: &[f32], floored: Option<(&[f32], f32)>, ceiling: f32, out: &mut [f32]) {
        #[cfg(target_arch = "x86_64")]
        if *HAS_AVX2_FMA {
            // SAFETY: the processor supports the features the function is compiled for.
            return unsafe { self.project_avx2(f, floored, ceiling, out) };
        }
        self.project_lanes(f, floored, ceiling, out)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn project_avx2(&self, f: &[f32], floored: Option<(&[f32], f32)>, ceiling: f32, out: &mut [f32]) {
        self.project_lanes(f, floored, ceiling, out)
    }

    #[inline(always)]
    fn project_lanes(&self, f: &[f32], floored: Option<(&[f32], f32)>, ceiling: f32, out: &mut [f32]) {
        let (count, nodes) = (self.count, self.nodes);
        let mut acc = [[0.0f32; LANES]; super::MAX_COEFFICIENTS];
        for start in (0..nodes).step_by(LANES) {
            let e = exp_lanes(self.block_values(f, floored, ceiling, start));
            let w: &[f32; LANES] = self.weights[start..][..LANES].try_into().expect("a block");
            for (k, channel) in acc[..count].iter_mut().enumerate() {
                let y: &[f32; LANES] = self.basis[k * nodes + start..][..LANES].try_into().expect("a block");
                for lane in 0..LANES {
                    channel[lane] += e[lane] * w[lane] * y[lane];
                }
            }
        }
        for (o, lanes) in out[..count].iter_mut().zip(&acc) {
            *o = lanes.iter().sum();
        }
    }

    #[inline(always)]
    fn lit_lanes(&self, f: &[f32], floored: Option<(&[f32], f32)>, ceiling: f32) -> [f32; 3] {
        let mut acc = [[0.0f32; LANES]; 3];
        for start in (0..self.nodes).step_by(LANES) {
            let e = exp_lanes(self.block_values(f, floored, ceiling, start));
            for (channel, light) in acc.iter_mut().zip(&self.light) {
                let w: &[f32; LANES] = light[start..][..LANES].try_into().expect("a block");
                for lane in 0..LANES {
                    channel[lane] += e[lane] * w[lane];
                }
            }
        }
        acc.map(|lanes| lanes.iter().sum::<f32>().max(0.0))
    }

    /// The log values at the block of nodes from `start`, floored and capped.
    #[inline(always)]
    fn block_values(&self, f: &[f32], floored: Option<(&[f32], f32)>, ceiling: f32, start: usize) -> [f32; LANES] {
        let (count, nodes) = (self.count, self.nodes);
        let mut value = [0.0f32; LANES];
        for (k, &fk) in f[..count].iter().enumerate() {
            let y: &[f32; LANES] = self.basis[k * nodes + start..][..LANES].try_into().expect("a block");
            for lane in 0..LANES {
                value[lane] += fk * y[lane];
            }
        }
        if let Some((v, floor)) = floored {
            let mut part = [0.0f32; LANES];
            for (k, &vk) in v[..count].iter().enumerate() {
                let y: &[f32; LANES] = self.basis[k * nodes + start..][..LANES].try_into().expect("a block");
                for lane in 0..LANES {
                    part[lane] += vk * y[lane];
                }
            }
            for lane in 0..LANES {
                value[lane] += (floor - part[lane]).max(0.0);
            }
        }
        for v in &mut value {
            *v = v.min(ceiling);
        }
        value
    }
}

/// `e^x` per lane in f32, to 2e-7 relative for `x` in `[-87, 88]` (0 below, clamped
/// above), in operations SSE2 vectorises: `x = n ln 2 + r` with `n` rounded by the
/// 1.5 * 2^23 shift, `|r| <= ln 2 / 2`, `e^r` by its degree-6 Taylor polynomial (remainder
/// below `r^7 / 7! = 1.2e-7`), and `2^n` built in the exponent bits.
#[inline(always)]
pub fn exp_lanes(x: [f32; LANES]) -> [f32; LANES] {
    const SHIFT: f32 = 12_582_912.0; // 1.5 * 2^23: adding it rounds to an integer
    const LN2_HI: f32 = 0.693_145_75;
    const LN2_LO: f32 = 1.428_606_8e-6;
    let mut out = [0.0f32; LANES];
    for lane in 0..LANES {
        let v = x[lane].clamp(-87.0, 88.0);
        let n = (v * std::f32::consts::LOG2_E + SHIFT) - SHIFT;
        let r = (v - n * LN2_HI) - n * LN2_LO;
        let p =
            1.0 + r * (1.0 + r * (0.5 + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0))))));
        let scale = f32::from_bits(((n as i32 + 127) as u32) << 23);
        out[lane] = if x[lane] < -87.0 { 0.0 } else { p * scale };
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sh::coefficient_count;

    #[test]
    fn exp_lanes_matches_the_exponential() {
        let mut worst = 0.0f64;
        for i in 0..=17_500 {
            let x = -87.0 + 0.01 * i as f64;
            let got = f64::from(exp_lanes([x as f32; LANES])[3]);
            let exact = (x as f32 as f64).exp();
            worst = worst.max((got - exact).abs() / exact);
        }
        assert!(worst < 3e-7, "worst relative error {worst}");
        assert_eq!(exp_lanes([-100.0; LANES]), [0.0; LANES]);
        assert!(exp_lanes([1000.0; LANES]).iter().all(|v| v.is_finite()));
    }

    /// The folded sum equals projecting `exp*(f)` back to SH and dotting with the light, and
    /// the lanes' projection equals the f64 one, for log vectors of the magnitudes pixels
    /// have, with and without the floor.
    #[test]
    fn folding_the_light_equals_projecting_then_dotting() {
        for order in [3, 4, 6, 8] {
            let count = coefficient_count(order);
            let quadrature = ExactExp::fast(order);
            let light: [Vec<f64>; 3] = std::array::from_fn(|c| {
                (0..count).map(|k| if k == 0 { 2.0 + c as f64 } else { 0.3 * ((k * 7 + c) as f64).sin() }).collect()
            });
            let folded = FoldedQuadrature::new(&quadrature, &light);
            for (seed, magnitude) in [(1u32, 0.5), (2, 3.0), (3, 8.0)] {
                let f: Vec<f64> =
                    (0..count).map(|k| magnitude * ((k as f64 + 1.3) * f64::from(seed)).sin() / 2.0).collect();
                let v: Vec<f64> = f.iter().map(|x| 0.7 * x).collect();
                for floor in [None, Some(-2.3)] {
                    let mut e = vec![0.0f64; count];
                    quadrature.exp_floored(&f, floor.map(|fl| (&v[..], fl)), 1.0, &mut e);
                    let expected = light.each_ref().map(|l| l.iter().zip(&e).map(|(a, b)| a * b).sum::<f64>().max(0.0));
                    let f32s: Vec<f32> = f.iter().map(|&x| x as f32).collect();
                    let v32s: Vec<f32> = v.iter().map(|&x| x as f32).collect();
                    let got = folded.lit(&f32s, floor.map(|fl| (&v32s[..], fl as f32)), 1.0);
                    let mut projected = vec![0.0f32; count];
                    folded.project(&f32s, floor.map(|fl| (&v32s[..], fl as f32)), 1.0, &mut projected);
                    let largest = e.iter().fold(1e-3f64, |a, b| a.max(b.abs()));
                    for k in 0..count {
                        let error = (f64::from(projected[k]) - e[k]).abs() / largest;
                        assert!(error < 2e-5, "order {order}, |f| {magnitude}, floor {floor:?}: projected {k} {error}");
                    }
                    for c in 0..3 {
                        let scale = expected.iter().fold(1e-3f64, |a, b| a.max(b.abs()));
                        let error = (f64::from(got[c]) - expected[c]).abs() / scale;
                        assert!(
                            error < 2e-5,
                            "order {order}, |f| {magnitude}, floor {floor:?}, channel {c}: {} vs {}",
                            got[c],
                            expected[c]
                        );
                    }
                }
            }
        }
    }
}
