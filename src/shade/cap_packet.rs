//! The sphere blockers' log visibility of eight receivers at once: paper 000's caps
//! (Eq. 24-26) rotated to each receiver's view of them (Funk-Hecke, Eq. 5) and summed,
//! for a packet of receivers that share one walk of the blocker tree.
//!
//! The walk is [`BlockerTree::visit`]'s, in f32 as the WGSL pass takes it
//! (`shaders/logsh.wgsl`, `visit_blockers`) over the same node array
//! ([`BlockerTree::f32_nodes`]): every node is tested in eight lanes, one receiver each,
//! and the packet goes down into a node when some lane does. A lane is at node `i` when its
//! own walk would visit `i` next; in the depth-first order with skip links, every lane not
//! at `i` is already at or past `skip(i)`, so the packet moves to `i + 1` when a lane goes
//! down and to `skip(i)` otherwise, and visits exactly the union of the lanes' walks. A
//! cap that some lane sees is evaluated in all eight (its angular radius, fitted depth,
//! closed-form ZH and basis at each receiver's direction to it) and added to the lanes
//! that see it.
//!
//! Receivers shaded one after another along a row see nearly the same caps, so the packet
//! costs little more than one walk: on the sample scenes it visits 1.1 to 1.5 times the
//! nodes of one receiver's walk for eight receivers. It sums what the scalar path sums
//! ([`super::ShadingKernel::add_visibility`] with blockers only, less its tangent and
//! ground planes), to f32 rounding (`tests` below).
//!
//! Where the processor lacks AVX2 and FMA, [`CapPacket::sum`] declines and the kernel
//! walks per receiver.

use super::blocker_tree::{BlockerTree, BEHIND_TOLERANCE, NEGLIGIBLE_RATIO};
use super::fitted_depth::DEPTH_INTERVALS;
use crate::gpu_layout::GpuBlockerNode;
use crate::logsh::OWN_SPHERE_REACH;
use crate::sh::MAX_COEFFICIENTS;

/// Receivers in one packet.
pub const LANES: usize = 8;

/// One receiver of a packet, in f32 as the lanes read it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Receiver {
    pub position: [f32; 3],
    /// Unit normal.
    pub normal: [f32; 3],
    /// Object index (0: none); its own spheres that hold it cast nothing on it.
    pub object: u32,
}

/// What a packet's caps are evaluated with: the kernel's order, fitted cap depths and
/// ratio attenuation, and the frame's tree.
#[derive(Clone, Copy, Debug)]
pub struct CapPacket<'a> {
    pub nodes: &'a [GpuBlockerNode],
    pub cluster_ratio: f32,
    pub order: usize,
    /// Each cap's log depth per angular radius, `DEPTH_INTERVALS + 1` entries over
    /// `[0, pi/2]` ([`super::fitted_depth::depth_at`]).
    pub cap_depths: &'a [f32],
    /// `log(eps)`, where an overlapped cap's depth ends
    /// ([`super::fitted_depth::overlapped_depth`]).
    pub log_epsilon: f32,
    pub ratio_attenuation: bool,
}

impl<'a> CapPacket<'a> {
    pub fn new(
        tree: &'a BlockerTree,
        order: usize,
        cap_depths: &'a [f32],
        log_epsilon: f32,
        ratio_attenuation: bool,
    ) -> Self {
        let cluster_ratio = tree.cluster_ratio as f32;
        Self { nodes: tree.f32_nodes(), cluster_ratio, order, cap_depths, log_epsilon, ratio_attenuation }
    }

    /// Whether [`Self::sum`] runs here: the processor has AVX2 and FMA.
    pub fn available() -> bool {
        #[cfg(target_arch = "x86_64")]
        return *crate::x86::AVX2_FMA;
        #[cfg(not(target_arch = "x86_64"))]
        false
    }

    /// Writes each receiver's summed cap log vector into `out[k][..order^2]` (at most
    /// [`LANES`] receivers). Returns `false`, writing nothing, where the processor cannot
    /// run the lanes ([`Self::available`]) or the order is outside `3..=8`.
    pub fn sum(&self, receivers: &[Receiver], out: &mut [[f32; MAX_COEFFICIENTS]]) -> bool {
        assert!(receivers.len() <= LANES && out.len() >= receivers.len(), "a packet holds at most {LANES} receivers");
        assert_eq!(self.cap_depths.len(), DEPTH_INTERVALS + 1, "one cap depth per interval end");
        #[cfg(target_arch = "x86_64")]
        if Self::available() {
            // SAFETY: the processor has AVX2 and FMA.
            unsafe {
                match self.order {
                    3 => lanes::sum::<3>(self, receivers, out),
                    4 => lanes::sum::<4>(self, receivers, out),
                    5 => lanes::sum::<5>(self, receivers, out),
                    6 => lanes::sum::<6>(self, receivers, out),
                    7 => lanes::sum::<7>(self, receivers, out),
                    8 => lanes::sum::<8>(self, receivers, out),
                    _ => return false,
                }
            }
            return true;
        }
        false
    }
}

/// The basis factors the lanes read, in f32: `R_l^m = c_l^m Q_l^m` by
/// [`crate::sh::basis`]'s upward recurrence in `l` (`Q_m^m = (2m - 1)!!`, `Q_l^m = a z
/// Q_{l-1}^m - b Q_{l-2}^m`), each `R` carrying the factor `c_l^m` of its term: the basis's
/// `K_l^m` (times `sqrt(2)` for `m > 0`) and the cap's `1 / (2l + 1)` (not at `l = 0`).
/// So `y_l^m V_l = R_l^m (P_{l-1} - P_{l+1}) Re/Im (x + iy)^m` times the cap's depth
/// factor, one multiply per term.
#[cfg(target_arch = "x86_64")]
struct LaneBasis {
    /// `R_m^m`.
    first: [f32; crate::sh::MAX_ORDER],
    /// `R_{m+1}^m / (z R_m^m)`.
    second: [f32; crate::sh::MAX_ORDER],
    /// `R_l^m = a z R_{l-1}^m - b R_{l-2}^m` for `l >= m + 2`.
    a: [[f32; crate::sh::MAX_ORDER]; crate::sh::MAX_ORDER],
    b: [[f32; crate::sh::MAX_ORDER]; crate::sh::MAX_ORDER],
    /// Legendre's `(2l - 1) / l` and `(l - 1) / l`, to band `MAX_ORDER` (the cap's closed
    /// form reads `P_{l+1}`).
    legendre: [(f32, f32); crate::sh::MAX_ORDER + 1],
}

#[cfg(target_arch = "x86_64")]
static LANE_BASIS: std::sync::LazyLock<LaneBasis> = std::sync::LazyLock::new(|| {
    use crate::sh::basis::{double_factorial_odd, normalisation};
    let c = |l: usize, m: usize| {
        let k = normalisation(l, m) * if m > 0 { std::f64::consts::SQRT_2 } else { 1.0 };
        if l == 0 {
            k
        } else {
            k / (2 * l + 1) as f64
        }
    };
    // Q_l^m = a z Q_{l-1}^m - b Q_{l-2}^m, scaled to R.
    let recurrence = |l: usize, m: usize| {
        if l < m + 2 || l >= crate::sh::MAX_ORDER {
            (0.0, 0.0)
        } else {
            let d = (l - m) as f64;
            let (a, b) = ((2 * l - 1) as f64 / d, (l + m - 1) as f64 / d);
            ((a * c(l, m) / c(l - 1, m)) as f32, (b * c(l, m) / c(l - 2, m)) as f32)
        }
    };
    LaneBasis {
        first: std::array::from_fn(|m| (c(m, m) * double_factorial_odd(m)) as f32),
        second: std::array::from_fn(|m| {
            if m + 1 < crate::sh::MAX_ORDER {
                (c(m + 1, m) * (2 * m + 1) as f64 / c(m, m)) as f32
            } else {
                0.0
            }
        }),
        a: std::array::from_fn(|l| std::array::from_fn(|m| recurrence(l, m).0)),
        b: std::array::from_fn(|l| std::array::from_fn(|m| recurrence(l, m).1)),
        legendre: std::array::from_fn(|l| {
            if l < 2 {
                (0.0, 0.0)
            } else {
                ((2 * l - 1) as f32 / l as f32, (l - 1) as f32 / l as f32)
            }
        }),
    }
});

/// The real SH basis at eight directions at once ([`lanes::basis`]).
#[cfg(target_arch = "x86_64")]
pub use lanes::basis as basis_lanes;

#[cfg(target_arch = "x86_64")]
mod lanes {
    use super::{CapPacket, LaneBasis, Receiver, LANES, LANE_BASIS};
    use crate::sh::{index, MAX_COEFFICIENTS};
    use std::arch::x86_64::*;

    /// The receivers' positions and normals, one per lane.
    struct Packet {
        p: [__m256; 3],
        n: [__m256; 3],
        object: __m256i,
    }

    /// [`CapPacket::sum`] at order `N`.
    ///
    /// # Safety
    /// The processor has AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn sum<const N: usize>(packet: &CapPacket, receivers: &[Receiver], out: &mut [[f32; MAX_COEFFICIENTS]]) {
        let lane = |f: &dyn Fn(&Receiver) -> f32| {
            let mut values = [0.0f32; LANES];
            for (v, r) in values.iter_mut().zip(receivers) {
                *v = f(r);
            }
            _mm256_loadu_ps(values.as_ptr())
        };
        let mut objects = [0i32; LANES];
        for (o, r) in objects.iter_mut().zip(receivers) {
            *o = r.object as i32;
        }
        let lanes = Packet {
            p: [lane(&|r| r.position[0]), lane(&|r| r.position[1]), lane(&|r| r.position[2])],
            n: [lane(&|r| r.normal[0]), lane(&|r| r.normal[1]), lane(&|r| r.normal[2])],
            object: _mm256_loadu_si256(objects.as_ptr().cast()),
        };
        let nodes = packet.nodes;
        let end = nodes.len() as i32;
        // Each lane's next node; lanes without a receiver start done.
        let mut at = [end; LANES];
        at[..receivers.len()].fill(0);
        let mut next = _mm256_loadu_si256(at.as_ptr().cast());
        let mut acc = [_mm256_setzero_ps(); MAX_COEFFICIENTS];
        let basis: &LaneBasis = &LANE_BASIS;
        let tolerance = _mm256_set1_ps(-(1.0 - super::BEHIND_TOLERANCE as f32));
        let cluster_ratio2 = packet.cluster_ratio * packet.cluster_ratio;
        let negligible2 = (super::NEGLIGIBLE_RATIO * super::NEGLIGIBLE_RATIO) as f32;
        let mut i = 0usize;
        while i < nodes.len() {
            let node = &nodes[i];
            let skip = node.skip as usize;
            let active = _mm256_castsi256_ps(_mm256_cmpeq_epi32(next, _mm256_set1_epi32(i as i32)));
            let d = [0, 1, 2].map(|k| _mm256_sub_ps(_mm256_set1_ps(node.bounds[k]), lanes.p[k]));
            let r = _mm256_set1_ps(node.bounds[3]);
            let toward = dot(d, lanes.n);
            let behind = _mm256_cmp_ps::<_CMP_LT_OQ>(toward, _mm256_mul_ps(r, tolerance));
            let front = _mm256_andnot_ps(behind, active);
            let jump = _mm256_set1_epi32(skip as i32);
            if node.leaf != 0 {
                let reach = _mm256_set1_ps(super::OWN_SPHERE_REACH as f32 * node.equivalent[3]);
                let same = _mm256_castsi256_ps(_mm256_cmpeq_epi32(lanes.object, _mm256_set1_epi32(node.object as i32)));
                let holds = _mm256_cmp_ps::<_CMP_LE_OQ>(dot(d, d), _mm256_mul_ps(reach, reach));
                let own = if node.object != 0 { _mm256_and_ps(same, holds) } else { _mm256_setzero_ps() };
                let seen = _mm256_andnot_ps(own, front);
                if _mm256_movemask_ps(seen) != 0 {
                    add_caps::<N>(packet, basis, &lanes, node.equivalent, node.share, seen, &mut acc);
                }
                next = blend_i32(next, jump, active);
                i = skip;
                continue;
            }
            // `|d| > r` and `r <= ratio |d|`, squared (both sides are at least 0), so the
            // decision waits on no square root.
            let (squared, r2) = (dot(d, d), _mm256_mul_ps(r, r));
            let cluster = _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GT_OQ>(squared, r2),
                _mm256_cmp_ps::<_CMP_LE_OQ>(r2, _mm256_mul_ps(_mm256_set1_ps(cluster_ratio2), squared)),
            );
            let far = _mm256_and_ps(front, cluster);
            if _mm256_movemask_ps(far) != 0 {
                let e = node.equivalent;
                let q = [0, 1, 2].map(|k| _mm256_sub_ps(_mm256_set1_ps(e[k]), lanes.p[k]));
                let reach2 = _mm256_mul_ps(_mm256_set1_ps(negligible2), dot(q, q));
                let seen = _mm256_and_ps(far, _mm256_cmp_ps::<_CMP_GE_OQ>(_mm256_set1_ps(e[3] * e[3]), reach2));
                if _mm256_movemask_ps(seen) != 0 {
                    add_caps::<N>(packet, basis, &lanes, e, node.share, seen, &mut acc);
                }
            }
            let down = _mm256_andnot_ps(cluster, front);
            if _mm256_movemask_ps(down) != 0 {
                next = blend_i32(next, jump, _mm256_andnot_ps(down, active));
                next = blend_i32(next, _mm256_set1_epi32(i as i32 + 1), down);
                i += 1;
            } else {
                next = blend_i32(next, jump, active);
                i = skip;
            }
        }
        for k in 0..N * N {
            let mut values = [0.0f32; LANES];
            _mm256_storeu_ps(values.as_mut_ptr(), acc[k]);
            for (o, v) in out.iter_mut().zip(values).take(receivers.len()) {
                o[k] = v;
            }
        }
    }

    /// Adds the cap of `sphere` (centre, radius) as each lane in `seen` sees it
    /// (`crate::logsh::view_blocker`, `cap_log_zh`, `add_rotated_zonal`): culled where the
    /// centre is on or behind the tangent plane or at the receiver, a hemisphere from
    /// inside. `y_l^m` scaled by the rotated ZH `sqrt(4 pi / (2l + 1)) V_l`, which for the
    /// cap's closed form is `2 pi depth (P_{l-1} - P_{l+1}) / (2l + 1)` (`1 - x` at `l =
    /// 0`), times the ratio weight; the depth is the fitted one for the cap's radius,
    /// overlapped by the sphere's `share` ([`super::super::fitted_depth::overlapped_depth`]).
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    #[allow(clippy::too_many_arguments)]
    unsafe fn add_caps<const N: usize>(
        packet: &CapPacket,
        basis: &LaneBasis,
        lanes: &Packet,
        sphere: [f32; 4],
        share: f32,
        seen: __m256,
        acc: &mut [__m256; MAX_COEFFICIENTS],
    ) {
        let zero = _mm256_setzero_ps();
        let one = _mm256_set1_ps(1.0);
        let d = [0, 1, 2].map(|k| _mm256_sub_ps(_mm256_set1_ps(sphere[k]), lanes.p[k]));
        let squared = dot(d, d);
        let finite = _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_GT_OQ>(squared, zero),
            _mm256_cmp_ps::<_CMP_LT_OQ>(squared, _mm256_set1_ps(f32::INFINITY)),
        );
        let facing = _mm256_cmp_ps::<_CMP_GT_OQ>(dot(d, lanes.n), zero);
        // |d| and 1 / |d| correctly rounded, so the same bits on every processor (its
        // reciprocal square root estimate differs between vendors).
        let distance = _mm256_sqrt_ps(squared);
        let inverse = _mm256_div_ps(one, distance);
        let direction = d.map(|c| _mm256_mul_ps(c, inverse));
        let keep = _mm256_and_ps(_mm256_and_ps(seen, finite), facing);
        // Lanes that add nothing evaluate the basis at +Z, so no NaN reaches the sums.
        let direction = [
            _mm256_and_ps(keep, direction[0]),
            _mm256_and_ps(keep, direction[1]),
            _mm256_blendv_ps(one, direction[2], keep),
        ];
        // r / |d| divided, as the WGSL pass divides it: a receiver on the sphere (r = |d|)
        // gets exactly 1, the hemisphere a receiver inside gets. Rounded below 1 there,
        // asin would take ~sqrt(2 ulp) = 3e-4 rad off the cap, 0.5 % of a pixel's value
        // at eps 1e-6 (`tests/extremes.rs`, receivers inside and touching).
        let ratio = _mm256_min_ps(_mm256_div_ps(_mm256_set1_ps(sphere[3]), distance), one);
        let ratio = _mm256_and_ps(keep, ratio);
        let alpha = asin(ratio);
        let depth = crate::shade::fitted_depth::depth_at_lanes(packet.cap_depths, alpha);
        let range = packet.log_epsilon - packet.cap_depths[0];
        let depth = if share < 1.0 && range < 0.0 {
            // `overlapped_depth`, the share and the range the same in every lane.
            let lambda = _mm256_div_ps(_mm256_sub_ps(_mm256_set1_ps(packet.log_epsilon), depth), _mm256_set1_ps(range));
            let lambda = _mm256_min_ps(_mm256_max_ps(lambda, zero), one);
            _mm256_mul_ps(depth, _mm256_sub_ps(one, _mm256_mul_ps(lambda, _mm256_set1_ps(1.0 - share))))
        } else {
            depth
        };
        let weight = if packet.ratio_attenuation { ratio } else { one };
        let scale =
            _mm256_and_ps(keep, _mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(std::f32::consts::TAU), weight), depth));
        // cos(alpha) = sqrt(1 - ratio^2), factored so that a ratio near 1 keeps its digits.
        let x = _mm256_sqrt_ps(_mm256_mul_ps(_mm256_sub_ps(one, ratio), _mm256_add_ps(one, ratio)));
        // P_0 ..= P_N at x, then the bands' factors.
        let mut p = [one; crate::sh::MAX_ORDER + 2];
        p[1] = x;
        for l in 2..=N {
            let (a, b) = basis.legendre[l];
            p[l] = _mm256_fmsub_ps(
                _mm256_mul_ps(_mm256_set1_ps(a), x),
                p[l - 1],
                _mm256_mul_ps(_mm256_set1_ps(b), p[l - 2]),
            );
        }
        // The cap's band integrals times its depth factor; their 1 / (2l + 1) is in `R`.
        let mut band = [zero; crate::sh::MAX_ORDER];
        band[0] = _mm256_mul_ps(scale, _mm256_sub_ps(one, x));
        for l in 1..N {
            band[l] = _mm256_mul_ps(scale, _mm256_sub_ps(p[l - 1], p[l + 1]));
        }
        add_basis_terms::<N>(basis, &band, direction, acc);
    }

    /// The real SH basis to order `N` at each lane's direction: `y_k` in lane `j` of entry
    /// `k` ([`crate::sh::eval_basis`] to f32 rounding, tested), by the lanes' recurrence
    /// with the cap's `1 / (2l + 1)` taken back out.
    ///
    /// # Safety
    /// The processor has AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub unsafe fn basis<const N: usize>(direction: [__m256; 3]) -> [__m256; MAX_COEFFICIENTS] {
        // No closure: it would not inherit this function's features.
        let mut band = [_mm256_set1_ps(1.0); crate::sh::MAX_ORDER];
        for (l, b) in band.iter_mut().enumerate().skip(1) {
            *b = _mm256_set1_ps((2 * l + 1) as f32);
        }
        let mut acc = [_mm256_setzero_ps(); MAX_COEFFICIENTS];
        add_basis_terms::<N>(&LANE_BASIS, &band, direction, &mut acc);
        acc
    }

    /// The terms `band[l] R_l^m Re/Im (x + iy)^m` of the basis at each lane's direction
    /// (crate::sh::basis::eval_basis_of_order) added to `acc`, each as it is made, one `m`
    /// at a time with (cm, sm) = Re, Im (x + iy)^m.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn add_basis_terms<const N: usize>(
        basis: &LaneBasis,
        band: &[__m256; crate::sh::MAX_ORDER],
        [dx, dy, z]: [__m256; 3],
        acc: &mut [__m256; MAX_COEFFICIENTS],
    ) {
        let mut phase = (_mm256_set1_ps(1.0), _mm256_setzero_ps());
        order_m::<N, 0>(basis, band, z, &mut phase, [dx, dy], acc);
        order_m::<N, 1>(basis, band, z, &mut phase, [dx, dy], acc);
        order_m::<N, 2>(basis, band, z, &mut phase, [dx, dy], acc);
        order_m::<N, 3>(basis, band, z, &mut phase, [dx, dy], acc);
        order_m::<N, 4>(basis, band, z, &mut phase, [dx, dy], acc);
        order_m::<N, 5>(basis, band, z, &mut phase, [dx, dy], acc);
        order_m::<N, 6>(basis, band, z, &mut phase, [dx, dy], acc);
        order_m::<N, 7>(basis, band, z, &mut phase, [dx, dy], acc);
    }

    /// The terms `band[l] R_l^M Re/Im (x + iy)^M` for `l = M..N` added to `acc` (nothing for
    /// `M >= N`), `R_l^M` by its upward recurrence ([`LaneBasis`]); then `phase` advanced to
    /// `(x + iy)^{M+1}`. A function per `M`, so that every loop has constant bounds and
    /// unrolls.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn order_m<const N: usize, const M: usize>(
        basis: &LaneBasis,
        band: &[__m256; crate::sh::MAX_ORDER],
        z: __m256,
        phase: &mut (__m256, __m256),
        [dx, dy]: [__m256; 2],
        acc: &mut [__m256; MAX_COEFFICIENTS],
    ) {
        if M >= N {
            return;
        }
        let (cm, sm) = *phase;
        let mut r_prev = _mm256_setzero_ps();
        let mut r = _mm256_set1_ps(basis.first[M]);
        for l in M..N {
            if l == M + 1 {
                r_prev = r;
                r = _mm256_mul_ps(_mm256_mul_ps(z, _mm256_set1_ps(basis.second[M])), r_prev);
            } else if l > M + 1 {
                let next = _mm256_fmsub_ps(
                    _mm256_mul_ps(_mm256_set1_ps(basis.a[l][M]), z),
                    r,
                    _mm256_mul_ps(_mm256_set1_ps(basis.b[l][M]), r_prev),
                );
                r_prev = r;
                r = next;
            }
            let term = _mm256_mul_ps(band[l], r);
            if M == 0 {
                acc[index(l, 0)] = _mm256_add_ps(acc[index(l, 0)], term);
            } else {
                let (plus, minus) = (index(l, M as i32), index(l, -(M as i32)));
                acc[plus] = _mm256_fmadd_ps(term, cm, acc[plus]);
                acc[minus] = _mm256_fmadd_ps(term, sm, acc[minus]);
            }
        }
        *phase = (_mm256_fmsub_ps(cm, dx, _mm256_mul_ps(sm, dy)), _mm256_fmadd_ps(cm, dy, _mm256_mul_ps(sm, dx)));
    }

    /// `asin` of each lane in `[0, 1]`, to about 2.5e-7 relative (Cephes' `asinf`: its
    /// polynomial on `[0, 1/2]`, and `pi/2 - 2 asin(sqrt((1 - x)/2))` above).
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn asin(x: __m256) -> __m256 {
        let half = _mm256_set1_ps(0.5);
        let upper = _mm256_cmp_ps::<_CMP_GT_OQ>(x, half);
        let z_upper = _mm256_mul_ps(half, _mm256_sub_ps(_mm256_set1_ps(1.0), x));
        let z = _mm256_blendv_ps(_mm256_mul_ps(x, x), z_upper, upper);
        let s = _mm256_blendv_ps(x, _mm256_sqrt_ps(z_upper), upper);
        let mut poly = _mm256_set1_ps(4.216_32e-2);
        for c in [2.418_131e-2, 4.547_002_6e-2, 7.495_300_3e-2, 1.666_675_2e-1] {
            poly = _mm256_fmadd_ps(poly, z, _mm256_set1_ps(c));
        }
        let r = _mm256_fmadd_ps(_mm256_mul_ps(poly, z), s, s);
        let upper_value = _mm256_fnmadd_ps(_mm256_set1_ps(2.0), r, _mm256_set1_ps(std::f32::consts::FRAC_PI_2));
        _mm256_blendv_ps(r, upper_value, upper)
    }

    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn dot(a: [__m256; 3], b: [__m256; 3]) -> __m256 {
        _mm256_fmadd_ps(a[2], b[2], _mm256_fmadd_ps(a[1], b[1], _mm256_mul_ps(a[0], b[0])))
    }

    /// `value` where `mask` is set, `base` elsewhere.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn blend_i32(base: __m256i, value: __m256i, mask: __m256) -> __m256i {
        _mm256_castps_si256(_mm256_blendv_ps(_mm256_castsi256_ps(base), _mm256_castsi256_ps(value), mask))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::logsh::{cap_log_zh, training::SplitMix, view_blocker, BlockerView};
    use crate::scene::Sphere;
    use crate::sh::{add_rotated_zonal, coefficient_count};
    use crate::shade::fitted_depth::{depth_at, overlapped_depth};

    /// The packets' `log(eps)` in these tests.
    const LOG_EPSILON: f64 = -std::f64::consts::LN_10;

    /// What the kernel's walk sums for one receiver, in f64: every sphere or cluster
    /// [`BlockerTree::visit`] sees, its cap at its fitted depth, rotated and added.
    fn walked(tree: &BlockerTree, order: usize, depths: &[f64], ratio: bool, receiver: &Receiver) -> Vec<f64> {
        let (p, n) = (receiver.position.map(f64::from), receiver.normal.map(f64::from));
        let mut acc = vec![0.0; coefficient_count(order)];
        let mut zonal = vec![0.0; order];
        tree.visit(p, n, receiver.object, |sphere, share| {
            if let BlockerView::Cap { direction, alpha, weight } =
                view_blocker(p, n, sphere.center, sphere.radius, ratio)
            {
                let depth = overlapped_depth(depth_at(depths, alpha), share, LOG_EPSILON, depths[0]);
                cap_log_zh(order, depth, alpha, &mut zonal);
                add_rotated_zonal(order, &zonal, weight, direction, &mut acc);
            }
        });
        acc
    }

    /// A packet sums what each receiver's own walk sums, to f32 rounding: a cloud of small
    /// spheres (distant ones clustered) over three objects, receivers on, inside and
    /// between them, facing every way, at every order, with and without ratio attenuation
    /// and clusters, in full and part-filled packets.
    #[test]
    fn a_packet_sums_what_each_receivers_walk_sums() {
        if !CapPacket::available() {
            eprintln!("no AVX2 and FMA here: the kernel walks per receiver");
            return;
        }
        let mut rng = SplitMix(0x5eed_cafe);
        let mut next = move || rng.next();
        let mut spheres: Vec<Sphere> = (0..300)
            .map(|i| Sphere {
                center: [next() * 8.0 - 4.0, next() * 8.0 - 4.0, next() * 3.0],
                radius: 0.05 + 0.4 * next() * next(),
                object: (i % 3) as u32 + 1,
            })
            .collect();
        spheres.push(Sphere { center: [0.0, 0.0, 0.5], radius: 1.0, object: 0 });
        let depths: Vec<f64> = (0..=DEPTH_INTERVALS).map(|k| -1.0 - 1.3 * k as f64 / DEPTH_INTERVALS as f64).collect();
        let depths32: Vec<f32> = depths.iter().map(|&d| d as f32).collect();
        let mut worst = 0.0f64;
        for cluster_ratio in [0.0, 0.35] {
            let tree = BlockerTree::new(&spheres, cluster_ratio);
            for order in 3..=8 {
                for ratio in [false, true] {
                    let packet = CapPacket::new(&tree, order, &depths32, LOG_EPSILON as f32, ratio);
                    for size in [8, 5, 1] {
                        let receivers: Vec<Receiver> = (0..size)
                            .map(|k| {
                                let v = [next() * 2.0 - 1.0, next() * 2.0 - 1.0, next() * 2.0 - 1.0];
                                let length = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                                Receiver {
                                    position: [next() * 6.0 - 3.0, next() * 6.0 - 3.0, next() * 2.0].map(|c| c as f32),
                                    normal: v.map(|c| (c / length) as f32),
                                    object: (k % 4) as u32,
                                }
                            })
                            .collect();
                        let mut out = [[0.0f32; MAX_COEFFICIENTS]; LANES];
                        assert!(packet.sum(&receivers, &mut out));
                        for (receiver, got) in receivers.iter().zip(&out) {
                            let expected = walked(&tree, order, &depths, ratio, receiver);
                            let scale = expected.iter().fold(1.0f64, |a, b| a.max(b.abs()));
                            for (k, e) in expected.iter().enumerate() {
                                worst = worst.max((f64::from(got[k]) - e).abs() / scale);
                            }
                        }
                    }
                }
            }
        }
        assert!(worst < 2e-5, "worst difference {worst:e} of the largest coefficient");
        eprintln!("packets against the f64 walk: worst {worst:.1e} of the largest coefficient");
    }

    /// Degenerate receivers stay finite: at a sphere's centre (culled), on its surface,
    /// with a zero normal, and lanes left empty.
    #[test]
    fn degenerate_receivers_stay_finite() {
        if !CapPacket::available() {
            return;
        }
        let tree = BlockerTree::new(&[Sphere::new([0.0, 0.0, 1.0], 0.5), Sphere::new([3.0, 0.0, 1.0], 0.0)], 0.35);
        let depths = vec![-2.3f32; DEPTH_INTERVALS + 1];
        let packet = CapPacket::new(&tree, 4, &depths, LOG_EPSILON as f32, true);
        let receivers = [
            Receiver { position: [0.0, 0.0, 1.0], normal: [0.0, 0.0, 1.0], object: 0 },
            Receiver { position: [0.0, 0.0, 0.5], normal: [0.0, 0.0, 1.0], object: 0 },
            Receiver { position: [0.0, 0.0, 0.0], normal: [0.0, 0.0, 0.0], object: 0 },
        ];
        let mut out = [[0.0f32; MAX_COEFFICIENTS]; LANES];
        assert!(packet.sum(&receivers, &mut out));
        assert!(out.iter().flatten().all(|v| v.is_finite()), "{out:?}");
        assert!(out[0].iter().all(|&v| v == 0.0), "a receiver at the centre is culled");
        assert!(out[1][0] < -1.0, "a receiver on the surface sees a hemisphere");
    }

    /// The lanes' basis is [`crate::sh::eval_basis`]'s, to f32 rounding (4e-6 of the
    /// largest value), at every order, along 400 directions spread over the sphere, the
    /// poles and the equator included.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_lanes_basis_is_the_scalar_basis() {
        use std::arch::x86_64::*;
        if !CapPacket::available() {
            eprintln!("no AVX2 and FMA here: the lanes do not run");
            return;
        }
        let mut directions: Vec<[f32; 3]> = (0..400)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f32 + 0.5) / 400.0;
                let (r, phi) = ((1.0 - z * z).sqrt(), 2.399_963 * i as f32);
                [r * phi.cos(), r * phi.sin(), z]
            })
            .collect();
        directions.extend([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]);
        for order in crate::sh::MIN_ORDER..=crate::sh::MAX_ORDER {
            for group in directions.chunks(LANES) {
                let axis = |k: usize| {
                    let values: [f32; LANES] = std::array::from_fn(|lane| group.get(lane).map_or(0.0, |d| d[k]));
                    // SAFETY: `values` holds LANES floats; the processor has AVX2.
                    unsafe { _mm256_loadu_ps(values.as_ptr()) }
                };
                let direction = [axis(0), axis(1), axis(2)];
                // SAFETY: the processor has AVX2 and FMA.
                let lanes = unsafe {
                    match order {
                        3 => basis_lanes::<3>(direction),
                        4 => basis_lanes::<4>(direction),
                        5 => basis_lanes::<5>(direction),
                        6 => basis_lanes::<6>(direction),
                        7 => basis_lanes::<7>(direction),
                        _ => basis_lanes::<8>(direction),
                    }
                };
                let mut values = [[0.0f32; LANES]; MAX_COEFFICIENTS];
                for (v, l) in values.iter_mut().zip(lanes) {
                    // SAFETY: `v` holds LANES floats.
                    unsafe { _mm256_storeu_ps(v.as_mut_ptr(), l) };
                }
                for (lane, d) in group.iter().enumerate() {
                    let mut expected = [0.0f32; MAX_COEFFICIENTS];
                    crate::sh::eval_basis(order, *d, &mut expected);
                    let largest = expected.iter().fold(0.0f32, |a, v| a.max(v.abs()));
                    for k in 0..order * order {
                        assert!(
                            (values[k][lane] - expected[k]).abs() <= 4e-6 * largest,
                            "order {order}, direction {d:?}, coefficient {k}: {} against {}",
                            values[k][lane],
                            expected[k]
                        );
                    }
                }
            }
        }
    }
}
