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
//! run of independent lanes, exponential included ([`exp_lanes`]). Where the processor has
//! AVX2 and FMA the blocks run in those registers, five at a time (`lit_avx2`,
//! `project_avx2`: about 6x the portable lanes, which the compiler leaves scalar); the
//! portable lanes run elsewhere, and the two agree to f32 rounding (`tests` below). The
//! f64 path ([`ExactExp::exp_floored`]) stays the oracle.

use super::basis::coefficient_count;
use super::exp::ExactExp;

/// Nodes evaluated together.
pub const LANES: usize = 8;

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
        if *crate::x86::AVX2_FMA {
            // SAFETY: the processor supports the features the function is compiled for.
            return unsafe { self.lit_avx2(f, floored, ceiling) };
        }
        self.lit_lanes(f, floored, ceiling)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn lit_avx2(&self, f: &[f32], floored: Option<(&[f32], f32)>, ceiling: f32) -> [f32; 3] {
        use std::arch::x86_64::*;
        let mut acc = [_mm256_setzero_ps(); 3];
        self.for_each_block_avx2(f, floored, ceiling, |start, e| {
            for (channel, light) in acc.iter_mut().zip(&self.light) {
                let w = _mm256_loadu_ps(light[start..][..LANES].as_ptr());
                *channel = _mm256_fmadd_ps(e, w, *channel);
            }
        });
        acc.map(|lanes| avx2::sum(lanes).max(0.0))
    }

    /// `exp*(f)` itself, projected back to SH at the same nodes into `out[..order^2]`:
    /// [`ExactExp::exp_floored`] in f32 lanes (the transfer vectors of
    /// [`crate::transfer`]).
    pub fn project(&self, f: &[f32], floored: Option<(&[f32], f32)>, ceiling: f32, out: &mut [f32]) {
        #[cfg(target_arch = "x86_64")]
        if *crate::x86::AVX2_FMA {
            // SAFETY: the processor supports the features the function is compiled for.
            return unsafe { self.project_avx2(f, floored, ceiling, out) };
        }
        self.project_lanes(f, floored, ceiling, out)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn project_avx2(&self, f: &[f32], floored: Option<(&[f32], f32)>, ceiling: f32, out: &mut [f32]) {
        use std::arch::x86_64::*;
        let (count, nodes) = (self.count, self.nodes);
        let mut acc = [_mm256_setzero_ps(); super::MAX_COEFFICIENTS];
        self.for_each_block_avx2(f, floored, ceiling, |start, e| {
            let ew = _mm256_mul_ps(e, _mm256_loadu_ps(self.weights[start..][..LANES].as_ptr()));
            for (k, channel) in acc[..count].iter_mut().enumerate() {
                let y = _mm256_loadu_ps(self.basis[k * nodes + start..][..LANES].as_ptr());
                *channel = _mm256_fmadd_ps(ew, y, *channel);
            }
        });
        for (o, lanes) in out[..count].iter_mut().zip(&acc) {
            *o = avx2::sum(*lanes);
        }
    }

    /// `e^{f(x_i)}` of every block of nodes ([`Self::block_values`], then [`exp_lanes`]) in
    /// AVX2 registers, handed to `each(start, e)` in order. Five blocks are summed at once
    /// (the `quad` grid of order 4 is 25 blocks), so that the multiply-add chains over the
    /// coefficients overlap instead of waiting on each other; the blocks left over go
    /// together too.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn for_each_block_avx2(
        &self,
        f: &[f32],
        floored: Option<(&[f32], f32)>,
        ceiling: f32,
        mut each: impl FnMut(usize, std::arch::x86_64::__m256),
    ) {
        const GROUP: usize = 5;
        let mut start = 0;
        while start + GROUP * LANES <= self.nodes {
            for (b, e) in self.block_group_avx2::<GROUP>(f, floored, ceiling, start).into_iter().enumerate() {
                each(start + b * LANES, e);
            }
            start += GROUP * LANES;
        }
        let mut rest = |group: &[std::arch::x86_64::__m256]| {
            for (b, e) in group.iter().enumerate() {
                each(start + b * LANES, *e);
            }
        };
        match (self.nodes - start) / LANES {
            0 => {}
            1 => rest(&self.block_group_avx2::<1>(f, floored, ceiling, start)),
            2 => rest(&self.block_group_avx2::<2>(f, floored, ceiling, start)),
            3 => rest(&self.block_group_avx2::<3>(f, floored, ceiling, start)),
            _ => rest(&self.block_group_avx2::<4>(f, floored, ceiling, start)),
        }
    }

    /// `e^{f(x_i)}` of the `B` blocks of nodes from `start`, floored and capped as
    /// [`Self::block_values`] does; the log value and its floor's argument share one pass
    /// over the basis rows.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn block_group_avx2<const B: usize>(
        &self,
        f: &[f32],
        floored: Option<(&[f32], f32)>,
        ceiling: f32,
        start: usize,
    ) -> [std::arch::x86_64::__m256; B] {
        use std::arch::x86_64::*;
        let (count, nodes) = (self.count, self.nodes);
        let rows = |k: usize| -> [__m256; B] {
            let row = &self.basis[k * nodes + start..][..B * LANES];
            std::array::from_fn(|b| _mm256_loadu_ps(row[b * LANES..].as_ptr()))
        };
        let mut value = [_mm256_setzero_ps(); B];
        if let Some((v, floor)) = floored {
            let mut part = [_mm256_setzero_ps(); B];
            for (k, (&fk, &vk)) in f[..count].iter().zip(&v[..count]).enumerate() {
                let (fk, vk, y) = (_mm256_set1_ps(fk), _mm256_set1_ps(vk), rows(k));
                for b in 0..B {
                    value[b] = _mm256_fmadd_ps(fk, y[b], value[b]);
                    part[b] = _mm256_fmadd_ps(vk, y[b], part[b]);
                }
            }
            let floor = _mm256_set1_ps(floor);
            for b in 0..B {
                value[b] = _mm256_add_ps(value[b], _mm256_max_ps(_mm256_sub_ps(floor, part[b]), _mm256_setzero_ps()));
            }
        } else {
            for (k, &fk) in f[..count].iter().enumerate() {
                let (fk, y) = (_mm256_set1_ps(fk), rows(k));
                for b in 0..B {
                    value[b] = _mm256_fmadd_ps(fk, y[b], value[b]);
                }
            }
        }
        let ceiling = _mm256_set1_ps(ceiling);
        value.map(|x| avx2::exp(_mm256_min_ps(x, ceiling)))
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

/// [`exp_lanes`] and the lane sum in AVX2 and FMA registers: the same steps, with the
/// polynomial's and the range reduction's multiply-adds fused.
#[cfg(target_arch = "x86_64")]
mod avx2 {
    use std::arch::x86_64::*;

    /// [`super::exp_lanes`] on one register. `2^n` comes from the shifted sum's bits
    /// (`n` sits in its low mantissa bits), so no float-to-integer conversion is needed.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn exp(x: __m256) -> __m256 {
        const SHIFT: f32 = 12_582_912.0; // 1.5 * 2^23
        const SHIFT_BITS: i32 = 0x4b40_0000; // the bits of SHIFT
        const LN2_HI: f32 = 0.693_145_75;
        const LN2_LO: f32 = 1.428_606_8e-6;
        let below = _mm256_cmp_ps::<_CMP_LT_OQ>(x, _mm256_set1_ps(-87.0));
        // max_ps returns its second operand for a NaN, so a NaN lane becomes -87.
        let v = _mm256_min_ps(_mm256_max_ps(x, _mm256_set1_ps(-87.0)), _mm256_set1_ps(88.0));
        let shifted = _mm256_fmadd_ps(v, _mm256_set1_ps(std::f32::consts::LOG2_E), _mm256_set1_ps(SHIFT));
        let n = _mm256_sub_ps(shifted, _mm256_set1_ps(SHIFT));
        let r = _mm256_fnmadd_ps(n, _mm256_set1_ps(LN2_LO), _mm256_fnmadd_ps(n, _mm256_set1_ps(LN2_HI), v));
        let mut p = _mm256_set1_ps(1.0 / 720.0);
        for c in [1.0 / 120.0, 1.0 / 24.0, 1.0 / 6.0, 0.5, 1.0, 1.0] {
            p = _mm256_fmadd_ps(p, r, _mm256_set1_ps(c));
        }
        let exponent = _mm256_add_epi32(
            _mm256_sub_epi32(_mm256_castps_si256(shifted), _mm256_set1_epi32(SHIFT_BITS)),
            _mm256_set1_epi32(127),
        );
        let scale = _mm256_castsi256_ps(_mm256_slli_epi32::<23>(exponent));
        _mm256_andnot_ps(below, _mm256_mul_ps(p, scale))
    }

    /// The sum of the eight lanes.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn sum(x: __m256) -> f32 {
        let quad = _mm_add_ps(_mm256_castps256_ps128(x), _mm256_extractf128_ps::<1>(x));
        let pair = _mm_add_ps(quad, _mm_movehl_ps(quad, quad));
        _mm_cvtss_f32(_mm_add_ss(pair, _mm_shuffle_ps::<0b01>(pair, pair)))
    }
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
            #[cfg(target_arch = "x86_64")]
            if *crate::x86::AVX2_FMA {
                // SAFETY: the processor has AVX2 and FMA.
                let got = unsafe {
                    use std::arch::x86_64::*;
                    _mm_cvtss_f32(_mm256_castps256_ps128(avx2::exp(_mm256_set1_ps(x as f32))))
                };
                worst = worst.max((f64::from(got) - exact).abs() / exact);
            }
        }
        assert!(worst < 3e-7, "worst relative error {worst}");
        assert_eq!(exp_lanes([-100.0; LANES]), [0.0; LANES]);
        assert!(exp_lanes([1000.0; LANES]).iter().all(|v| v.is_finite()));
    }

    /// The AVX2 path (what `lit` and `project` run here when the processor has it) and the
    /// portable lanes agree to f32 rounding, at every order, with and without the floor,
    /// at a node count that is not a multiple of the AVX2 group.
    #[test]
    fn the_avx2_path_equals_the_portable_lanes() {
        #[cfg(target_arch = "x86_64")]
        if *crate::x86::AVX2_FMA {
            for order in 2..=8 {
                let count = coefficient_count(order);
                let light: [Vec<f64>; 3] =
                    std::array::from_fn(|c| (0..count).map(|k| 1.0 / (1.0 + (k + c) as f64)).collect());
                let folded = FoldedQuadrature::new(&ExactExp::fast(order), &light);
                let f: Vec<f32> = (0..count).map(|k| 2.5 * ((k as f32 + 0.4) * 1.7).sin()).collect();
                let v: Vec<f32> = f.iter().map(|x| 0.8 * x - 0.1).collect();
                for floored in [None, Some((&v[..], -2.3f32))] {
                    // SAFETY: the processor has AVX2 and FMA.
                    let (lit, mut projected) = (unsafe { folded.lit_avx2(&f, floored, 1.5) }, vec![0.0; count]);
                    let lanes = folded.lit_lanes(&f, floored, 1.5);
                    for c in 0..3 {
                        assert!(
                            (lit[c] - lanes[c]).abs() <= 2e-6 * lanes[c].abs().max(1.0),
                            "order {order}: {lit:?} {lanes:?}"
                        );
                    }
                    unsafe { folded.project_avx2(&f, floored, 1.5, &mut projected) };
                    let mut expected = vec![0.0; count];
                    folded.project_lanes(&f, floored, 1.5, &mut expected);
                    let largest = expected.iter().fold(1.0f32, |a, b| a.max(b.abs()));
                    for k in 0..count {
                        assert!((projected[k] - expected[k]).abs() <= 2e-6 * largest, "order {order}, coefficient {k}");
                    }
                }
            }
            return;
        }
        eprintln!("no AVX2 and FMA here: the portable lanes are the only path");
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
