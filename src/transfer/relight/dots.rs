//! The dot products of a relight: a pixel's transfer vectors with the light's SH
//! vector per colour channel, in eight partial sums, portable or in AVX2 registers with
//! fused multiply-adds, and the open lobes' light along a pixel's glossy direction.

use super::RelightLight;
use crate::sh::basis::funk_hecke_factor;
use crate::sh::{coefficient_count, eval_basis, MAX_COEFFICIENTS};
use crate::transfer::layers::TransferFrame;
use crate::transfer::lobe_code;

/// Partial sums of a pixel's dot products.
pub(super) const DOT_LANES: usize = 8;

/// An SH vector per colour channel in blocks of [`DOT_LANES`], zero-padded: the pixels'
/// dot products sum eight partial sums, which vectorises.
pub(super) type Blocks = [Vec<[f32; DOT_LANES]>; 3];

/// `sh` per channel in [`Blocks`].
pub(super) fn blocks_of(sh: &[Vec<f32>; 3]) -> Blocks {
    sh.each_ref().map(|channel| {
        channel.chunks(DOT_LANES).map(|chunk| std::array::from_fn(|i| chunk.get(i).copied().unwrap_or(0.0))).collect()
    })
}

/// The light `sh` convolved with an open lobe whose exponentiated ZH about +Z is `open`
/// ([`crate::transfer::PrefilteredLobe::open`]): `sqrt(4 pi / (2l + 1)) open_l L_lm`.
pub(super) fn open_light_blocks(sh: &[Vec<f32>; 3], open: &[f64]) -> Blocks {
    let band = |k: usize| (k as f64).sqrt() as usize;
    let scale = |l: usize| (funk_hecke_factor(l) * open[l]) as f32;
    blocks_of(&sh.each_ref().map(|channel| channel.iter().enumerate().map(|(k, &v)| scale(band(k)) * v).collect()))
}

/// `max(open(R) . L, 0)` per colour channel, the open lobe's light along `direction`
/// (the specular occlusion's denominator, [`crate::shade::kernel::open_lit`]), from
/// [`open_light_blocks`]: a zonal lobe turned to `R` is `sqrt(4 pi / (2l + 1)) open_l
/// y_lm(R)` (paper 000, Eq. 5), so its dot product with `L` is the blocks dotted with the
/// basis at `R`, the same sum grouped otherwise (to 1e-6 of it, tested).
///
/// # Safety
/// The processor has what `D` needs ([`Dots::dot`]).
#[inline(always)]
pub(super) unsafe fn open_light<D: Dots>(blocks: &Blocks, order: usize, direction: [f64; 3]) -> [f32; 3] {
    let mut basis = [0.0f32; MAX_COEFFICIENTS];
    let count = coefficient_count(order);
    eval_basis(order, direction.map(|v| v as f32), &mut basis[..count]);
    // SAFETY: the caller holds `D`'s contract.
    unsafe { D::dot(blocks, &basis[..count]) }
}

/// How a pixel's transfer vectors are dotted with the light.
pub(super) trait Dots: Sized {
    /// `transfer . L` per channel, clamped at 0, `L` in `blocks`.
    ///
    /// # Safety
    /// The processor has the features the implementation uses (AVX2 and FMA for
    /// `Avx2Dots`).
    unsafe fn dot(blocks: &Blocks, transfer: &[f32]) -> [f32; 3];

    /// [`Dots::dot`] of each of `transfers` (of one length).
    ///
    /// # Safety
    /// As [`Dots::dot`].
    #[inline(always)]
    unsafe fn dots<const K: usize>(blocks: &Blocks, transfers: [&[f32]; K]) -> [[f32; 3]; K] {
        // SAFETY: the caller holds `Self`'s contract.
        transfers.map(|transfer| unsafe { Self::dot(blocks, transfer) })
    }

    /// The open lobes' light ([`open_light`]) of the pixels of the chunk from pixel
    /// `first` on that weigh their prefiltered lobe by SH (`glossy_weight.Y > 0`), into
    /// `open[j]` for pixel `first + j` (the other entries are left).
    ///
    /// # Safety
    /// As [`Dots::dot`].
    unsafe fn open_lights(frame: &TransferFrame, light: &RelightLight, first: usize, open: &mut [[f32; 3]]) {
        // SAFETY: the caller holds `Self`'s contract.
        unsafe { open_lights_one_by_one::<Self>(frame, light, first, open) }
    }
}

/// The prefiltered lobe of pixel `i` of `frame` where it weighs the lobe by SH.
#[inline(always)]
pub(super) fn sh_weighted_lobe(frame: &TransferFrame, i: usize) -> Option<usize> {
    let code = frame.glossy_lobe[i];
    (code >= lobe_code::PREFILTERED && frame.glossy_weight[i][1] > 0.0)
        .then_some((code - lobe_code::PREFILTERED) as usize)
}

/// Eight partial sums in portable lanes.
pub(super) struct PortableDots;

impl Dots for PortableDots {
    #[inline(always)]
    unsafe fn dot(blocks: &Blocks, transfer: &[f32]) -> [f32; 3] {
        let mut sum = [[0.0f32; DOT_LANES]; 3];
        for (b, chunk) in transfer.chunks(DOT_LANES).enumerate() {
            let mut t = [0.0f32; DOT_LANES];
            t[..chunk.len()].copy_from_slice(chunk);
            for c in 0..3 {
                for lane in 0..DOT_LANES {
                    sum[c][lane] += t[lane] * blocks[c][b][lane];
                }
            }
        }
        let total = |lanes: &[f32; DOT_LANES]| {
            let mut s = 0.0f32;
            for v in lanes {
                s += v;
            }
            s.max(0.0)
        };
        [total(&sum[0]), total(&sum[1]), total(&sum[2])]
    }
}

/// The same partial sums in AVX2 registers with fused multiply-adds, the three channels
/// reduced together.
#[cfg(target_arch = "x86_64")]
pub(super) struct Avx2Dots;

#[cfg(target_arch = "x86_64")]
impl Dots for Avx2Dots {
    /// Written with the intrinsics directly (no function of its own with the features),
    /// so that it is inlined into [`relight_chunk_avx2`], which has them.
    #[inline(always)]
    unsafe fn dot(blocks: &Blocks, transfer: &[f32]) -> [f32; 3] {
        use std::arch::x86_64::*;
        // SAFETY: the caller's processor has AVX2 and FMA (the trait's contract).
        unsafe {
            let [acc] = avx2_products(blocks, [transfer]);
            // [r01 r23 g01 g23 | ...], [b01 b23 0 0 | ...], then [r g b 0] per half.
            let rg = _mm256_hadd_ps(acc[0], acc[1]);
            let b0 = _mm256_hadd_ps(acc[2], _mm256_setzero_ps());
            let rgb = _mm256_hadd_ps(rg, b0);
            let sum =
                _mm_max_ps(_mm_add_ps(_mm256_castps256_ps128(rgb), _mm256_extractf128_ps::<1>(rgb)), _mm_setzero_ps());
            let mut out = [0.0f32; 4];
            _mm_storeu_ps(out.as_mut_ptr(), sum);
            [out[0], out[1], out[2]]
        }
    }

    /// The products of every transfer accumulated as for [`Dots::dot`]
    /// ([`avx2_products`]), then reduced eight sums at a time in one transposition, each
    /// sum added in [`Dots::dot`]'s order (so with the same bits) in fewer instructions. No closures: they would not inherit
    /// [`relight_chunk_avx2`]'s features, and each intrinsic in them would be a call.
    #[inline(always)]
    unsafe fn dots<const K: usize>(blocks: &Blocks, transfers: [&[f32]; K]) -> [[f32; 3]; K] {
        use std::arch::x86_64::*;
        // SAFETY: the caller's processor has AVX2 and FMA (the trait's contract).
        unsafe {
            let acc = avx2_products(blocks, transfers);
            let mut sums = [[0.0f32; 3]; K];
            for (group, out) in acc.as_flattened().chunks(8).zip(sums.as_flattened_mut().chunks_mut(8)) {
                let mut eight = [_mm256_setzero_ps(); 8];
                eight[..group.len()].copy_from_slice(group);
                // [a0 a1 a0 a1 | ...] pairs, then [a0 a1 a2 a3 | a0 a1 a2 a3] per half of
                // each accumulator's lanes, then the halves added.
                let pairs = [
                    _mm256_hadd_ps(eight[0], eight[1]),
                    _mm256_hadd_ps(eight[2], eight[3]),
                    _mm256_hadd_ps(eight[4], eight[5]),
                    _mm256_hadd_ps(eight[6], eight[7]),
                ];
                let quads = [_mm256_hadd_ps(pairs[0], pairs[1]), _mm256_hadd_ps(pairs[2], pairs[3])];
                let low = _mm256_permute2f128_ps::<0x20>(quads[0], quads[1]);
                let high = _mm256_permute2f128_ps::<0x31>(quads[0], quads[1]);
                let total = _mm256_max_ps(_mm256_add_ps(low, high), _mm256_setzero_ps());
                let mut values = [0.0f32; 8];
                _mm256_storeu_ps(values.as_mut_ptr(), total);
                out.copy_from_slice(&values[..out.len()]);
            }
            sums
        }
    }

    /// Eight pixels of one lobe at a time: the basis at their directions in AVX2 lanes
    /// ([`crate::shade::cap_packet::basis_lanes`]), dotted with the lobe's convolved light
    /// coefficient by coefficient. The same sum as [`open_light`], in another order (to
    /// 1e-6 of it, tested), where a pixel's own basis and dot cost about a quarter of a
    /// glossy pixel's relight.
    #[inline(always)]
    unsafe fn open_lights(frame: &TransferFrame, light: &RelightLight, first: usize, open: &mut [[f32; 3]]) {
        // SAFETY: the caller's processor has AVX2 and FMA (the trait's contract).
        unsafe {
            match frame.order() {
                3 => open_lights_in_lanes::<3>(frame, light, first, open),
                4 => open_lights_in_lanes::<4>(frame, light, first, open),
                5 => open_lights_in_lanes::<5>(frame, light, first, open),
                6 => open_lights_in_lanes::<6>(frame, light, first, open),
                7 => open_lights_in_lanes::<7>(frame, light, first, open),
                8 => open_lights_in_lanes::<8>(frame, light, first, open),
                _ => open_lights_one_by_one::<Self>(frame, light, first, open),
            }
        }
    }
}

/// Each of `transfers` (of one length) times the light `blocks`, per colour channel in
/// eight partial sums (AVX2 lanes, fused multiply-adds), the last block zero-padded: what
/// [`Avx2Dots::dot`] and [`Avx2Dots::dots`] reduce.
///
/// # Safety
/// The processor has AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) unsafe fn avx2_products<const K: usize>(
    blocks: &Blocks,
    transfers: [&[f32]; K],
) -> [[std::arch::x86_64::__m256; 3]; K] {
    use std::arch::x86_64::*;
    // SAFETY: the caller's processor has AVX2 and FMA; every load reads DOT_LANES floats
    // of a block, of a transfer or of `tail`. No closures: they would not inherit the
    // caller's features.
    unsafe {
        let mut acc = [[_mm256_setzero_ps(); 3]; K];
        let length = transfers.first().map_or(0, |t| t.len());
        let whole = length / DOT_LANES;
        for b in 0..whole {
            let light = [
                _mm256_loadu_ps(blocks[0][b].as_ptr()),
                _mm256_loadu_ps(blocks[1][b].as_ptr()),
                _mm256_loadu_ps(blocks[2][b].as_ptr()),
            ];
            for (a, transfer) in acc.iter_mut().zip(&transfers) {
                let t = _mm256_loadu_ps(transfer[b * DOT_LANES..][..DOT_LANES].as_ptr());
                for (a, l) in a.iter_mut().zip(light) {
                    *a = _mm256_fmadd_ps(t, l, *a);
                }
            }
        }
        let rest = length - whole * DOT_LANES;
        if rest > 0 {
            let light = [
                _mm256_loadu_ps(blocks[0][whole].as_ptr()),
                _mm256_loadu_ps(blocks[1][whole].as_ptr()),
                _mm256_loadu_ps(blocks[2][whole].as_ptr()),
            ];
            for (a, transfer) in acc.iter_mut().zip(&transfers) {
                let mut tail = [0.0f32; DOT_LANES];
                tail[..rest].copy_from_slice(&transfer[whole * DOT_LANES..]);
                let t = _mm256_loadu_ps(tail.as_ptr());
                for (a, l) in a.iter_mut().zip(light) {
                    *a = _mm256_fmadd_ps(t, l, *a);
                }
            }
        }
        acc
    }
}

/// The open lobes' light of the pixels of a chunk, one pixel at a time
/// ([`Dots::open_lights`]).
///
/// # Safety
/// The processor has what `D` needs ([`Dots::dot`]).
#[inline(always)]
pub(super) unsafe fn open_lights_one_by_one<D: Dots>(
    frame: &TransferFrame,
    light: &RelightLight,
    first: usize,
    open: &mut [[f32; 3]],
) {
    for (j, o) in open.iter_mut().enumerate() {
        let i = first + j;
        if let Some(lobe) = sh_weighted_lobe(frame, i) {
            let direction = frame.glossy_direction[i].map(f64::from);
            // SAFETY: the caller holds `D`'s contract.
            *o = unsafe { open_light::<D>(&light.open[lobe], frame.order(), direction) };
        }
    }
}

/// [`Avx2Dots::open_lights`] at order `N`: the pixels gathered per lobe, each lobe's
/// eight at a time.
///
/// # Safety
/// The processor has AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) unsafe fn open_lights_in_lanes<const N: usize>(
    frame: &TransferFrame,
    light: &RelightLight,
    first: usize,
    open: &mut [[f32; 3]],
) {
    use crate::shade::cap_packet::LANES;
    let lit = |lobe: usize, group: &[usize], open: &mut [[f32; 3]]| {
        let mut directions = [[0.0f32; 3]; LANES];
        for (d, &j) in directions.iter_mut().zip(group) {
            *d = frame.glossy_direction[first + j];
        }
        // SAFETY: the caller's processor has AVX2 and FMA.
        let values = unsafe { open_lights_of_lanes::<N>(&light.open[lobe], &directions) };
        for (&j, value) in group.iter().zip(values) {
            open[j] = value;
        }
    };
    let mut pending = vec![([0usize; LANES], 0usize); light.open.len()];
    for j in 0..open.len() {
        if let Some(lobe) = sh_weighted_lobe(frame, first + j) {
            let (group, count) = &mut pending[lobe];
            group[*count] = j;
            *count += 1;
            if *count == LANES {
                lit(lobe, group, open);
                *count = 0;
            }
        }
    }
    for (lobe, (group, count)) in pending.iter().enumerate() {
        if *count > 0 {
            lit(lobe, &group[..*count], open);
        }
    }
}

/// [`open_light`] of `blocks` along eight directions at once, at order `N`.
///
/// # Safety
/// The processor has AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(super) unsafe fn open_lights_of_lanes<const N: usize>(
    blocks: &Blocks,
    directions: &[[f32; 3]; crate::shade::cap_packet::LANES],
) -> [[f32; 3]; crate::shade::cap_packet::LANES] {
    use crate::shade::cap_packet::{basis_lanes, LANES};
    use std::arch::x86_64::*;
    let mut axes = [[0.0f32; LANES]; 3];
    for (lane, direction) in directions.iter().enumerate() {
        for (axis, &v) in axes.iter_mut().zip(direction) {
            axis[lane] = v;
        }
    }
    // SAFETY: each axis holds LANES floats (and no closure: it would not inherit this
    // function's features).
    let basis = unsafe {
        basis_lanes::<N>([
            _mm256_loadu_ps(axes[0].as_ptr()),
            _mm256_loadu_ps(axes[1].as_ptr()),
            _mm256_loadu_ps(axes[2].as_ptr()),
        ])
    };
    let mut lit = [_mm256_setzero_ps(); 3];
    for (k, y) in basis.iter().enumerate().take(N * N) {
        for (l, channel) in lit.iter_mut().zip(blocks) {
            *l = _mm256_fmadd_ps(_mm256_set1_ps(channel[k / DOT_LANES][k % DOT_LANES]), *y, *l);
        }
    }
    let mut values = [[0.0f32; LANES]; 3];
    for (v, l) in values.iter_mut().zip(lit) {
        // SAFETY: `v` holds LANES floats.
        unsafe { _mm256_storeu_ps(v.as_mut_ptr(), _mm256_max_ps(l, _mm256_setzero_ps())) };
    }
    std::array::from_fn(|lane| [values[0][lane], values[1][lane], values[2][lane]])
}
