//! The march of [`HorizonPyramid::horizon_elevations`] over sixteen azimuths at once, in
//! two groups of eight AVX2 and FMA lanes: the default settings' bicubic B-spline levels
//! and maximum over steps. Each lane is one azimuth; its 16 taps are four rows of four
//! contiguous samples of the padded level, and a lane stops after its own last step (the
//! scalar march's `t_far` and step table) or once no later step can raise its horizon.
//! The march of [`HorizonPyramid::horizons_against`] turns it about: one azimuth (a sun's)
//! from eight receivers (a frame's pixels), a receiver per lane ([`tangents_along`]).
//!
//! Positions are f32 grid units, and a level read is the weighted sum of its taps'
//! heights above the receiver term `f_L(x)` (read in f32, eight levels per pass), so no
//! two large sums cancel. `f_L(x)` itself is read again above that base the same way,
//! with the same operations, so a plane still gives exactly its own elevation and a flat
//! surface exactly 0. Against the f64 march the horizons differ by the f32 rounding of the
//! positions (the pyramid's tests).
//!
//! The per-step helpers are `#[inline(always)]` without target features of their own, so
//! that each build of `march_sixteen` (`crate::x86`) inlines them with its own registers;
//! like every function here, they run only where the processor has AVX2 and FMA.

use super::{HorizonPyramid, PaddedLevel, PyramidLevel, MAX_LEVELS, MAX_STEPS};
use crate::x86::{with_wide_registers, WIDE_REGISTERS};
use std::arch::x86_64::*;

/// Most azimuths a march takes (`HorizonSettings::directions`).
const MAX_AZIMUTHS: usize = 1024;

const SIXTH: f32 = 1.0 / 6.0;
const TWO_THIRDS: f32 = 2.0 / 3.0;

/// Whether a pyramid of `levels` can be marched here: AVX2 and FMA, every padded
/// level's samples addressable by a 32-bit index, and every grid coordinate exact in
/// f32 (so that a coordinate clamped to the last sample truncates to it).
pub fn available(levels: &[PyramidLevel]) -> bool {
    *crate::x86::AVX2_FMA
        && levels
            .iter()
            .all(|l| (l.columns + 3) * (l.rows + 3) < i32::MAX as usize && l.columns <= 1 << 24 && l.rows <= 1 << 24)
}

/// Writes the tangents of the horizon elevations of every azimuth (at least 0) into
/// `out` from `(x, y)`, `above` the surface.
///
/// # Safety
/// The processor has AVX2 and FMA, and [`available`] holds for `pyramid`'s levels.
pub unsafe fn horizons(pyramid: &HorizonPyramid, x: f64, y: f64, above: f64, out: &mut [f64]) {
    // The march's scratch arrays sized for a usual pyramid where it fits, so that a
    // point does not clear the 12 KB the largest take.
    let usual = pyramid.levels.len() <= 64 && out.len() <= 64 && pyramid.steps.len() <= 128;
    let wide = *WIDE_REGISTERS;
    if usual {
        horizons_within::<64, 64, 128>(pyramid, x, y, above, wide, out)
    } else {
        horizons_within::<MAX_LEVELS, MAX_AZIMUTHS, MAX_STEPS>(pyramid, x, y, above, wide, out)
    }
}

/// [`horizons`] for at most `LEVELS` levels, `AZIMUTHS` azimuths and `STEPS` steps,
/// marched by the build with AVX-512VL's registers where `wide` (`crate::x86`).
///
/// # Safety
/// As [`horizons`], and the processor has AVX-512F and AVX-512VL where `wide`.
#[target_feature(enable = "avx2,fma")]
pub unsafe fn horizons_within<const LEVELS: usize, const AZIMUTHS: usize, const STEPS: usize>(
    pyramid: &HorizonPyramid,
    x: f64,
    y: f64,
    above: f64,
    wide: bool,
    out: &mut [f64],
) {
    // Per level, the receiver's grid coordinates, the base the taps are read above
    // (`f_L(x)` in f32) and the receiver read above it plus `h`, filled eight levels at
    // a time up to the last level a step reads.
    let mut receiver = Receiver { origin: [[0.0f32; 2]; LEVELS], base: [0.0f32; LEVELS], start: [0.0f32; LEVELS] };
    let mut read = 0;
    // The steps each azimuth takes: every step up to `t_far` and the first one past it,
    // as the scalar march. Azimuths are marched sixteen at a time in two groups of
    // eight lanes (`march_sixteen`).
    let w = out.len();
    if w == 0 {
        return;
    }
    // Each azimuth as (steps << 16) | azimuth. Sixteen march together and their groups
    // merge once eight lanes hold the marching ones, so only more than sixteen need
    // sorting by step count (sixteen of like lengths together).
    let mut order = [0u32; AZIMUTHS];
    step_counts(pyramid, x, y, &mut order[..w]);
    for (k, key) in order[..w].iter_mut().enumerate() {
        *key = *key << 16 | k as u32;
    }
    if w > 16 {
        order[..w].sort_unstable();
    }
    // Every level the longest march reads, then the highest tangent any step from j
    // on can reach ([`step_ceilings`]): a lane stops once its horizon is above it, with
    // the same tangent as the whole march.
    let longest = order[..w].iter().max().map_or(0, |key| key >> 16);
    let last_level = pyramid.steps[..longest as usize].last().map_or(0, |s| s.level);
    while read <= last_level {
        receivers(pyramid, x, y, above as f32, read, &mut receiver);
        read += 8;
    }
    let mut ceilings = [0.0f32; STEPS];
    step_ceilings(pyramid, &receiver, &mut ceilings[..longest as usize]);
    for sixteen in order[..w].chunks(16) {
        if wide {
            march_sixteen_wide(pyramid, &receiver, &ceilings, sixteen, out);
        } else {
            march_sixteen(pyramid, &receiver, &ceilings, sixteen, out);
        }
    }
}

/// One receiver of [`tangents_along`]: where it is, how far `above` the surface, and
/// how many steps it takes (the scalar march's count, `t_far` and the reach).
#[derive(Clone, Copy)]
pub struct AlongReceiver {
    pub x: f64,
    pub y: f64,
    pub above: f64,
    pub taken: usize,
}

/// The receivers of [`tangents_along`] at up to eight finite `points` marched along
/// `dir` over at most the first `within` steps: each one's height above the level-0
/// surface ([`HorizonPyramid::height_at`]'s bilinear read, at least 0) and its step
/// count ([`HorizonPyramid::steps_marched`]'s), four points per instruction in f64 with
/// the scalar code's operations in its order, so the same bits. The per-point reads
/// and step searches were a tenth of a turn of the Sun-lamp scene's lamps. False,
/// `out` unset, where a grid coordinate is not a number (an extent of zero width),
/// which the scalar code then reads.
///
/// # Safety
/// The processor has AVX2 and FMA (no fused operation is used).
#[target_feature(enable = "avx2,fma")]
pub unsafe fn along_receivers(
    pyramid: &HorizonPyramid,
    points: &[[f64; 3]],
    dir: [f64; 2],
    within: usize,
    out: &mut [AlongReceiver; 8],
) -> bool {
    let Some(&last_point) = points.last() else { return true };
    let level = &pyramid.levels[0];
    let samples = [level.columns, level.rows];
    let zero = _mm256_setzero_pd();
    // Halves of four points, those past the last repeating it: one for a single
    // point (a shade marches each pixel's own).
    let halves = points.len().div_ceil(4).min(2);
    let point = |k: usize| *points.get(k).unwrap_or(&last_point);
    let coordinate = |half: usize, axis: usize| {
        let at = |lane: usize| point(4 * half + lane)[axis];
        _mm256_set_pd(at(3), at(2), at(1), at(0))
    };
    let mut heights = [zero; 2];
    let mut t_far = [zero; 2];
    for half in 0..halves {
        let xy = [coordinate(half, 0), coordinate(half, 1)];
        // Per axis, each point's cell and its fraction (`grid_coordinate`, `cell`).
        let mut cells = [(zero, zero); 2];
        for axis in 0..2 {
            let n = samples[axis];
            if n <= 1 {
                continue;
            }
            let last = _mm256_set1_pd((n - 1) as f64);
            let (min, max) = (pyramid.min[axis], pyramid.max[axis]);
            let unclamped = _mm256_mul_pd(
                _mm256_div_pd(_mm256_sub_pd(xy[axis], _mm256_set1_pd(min)), _mm256_set1_pd(max - min)),
                last,
            );
            // `clamp(0, last)`: each operand order returns what `f64::clamp` does,
            // a -0 and a NaN included.
            let grid = _mm256_min_pd(last, _mm256_max_pd(zero, unclamped));
            if _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_UNORD_Q>(grid, grid)) != 0 {
                return false;
            }
            // `floor as usize`, at most `n - 2`, as a float (+0 for -0).
            let index = _mm256_add_pd(_mm256_min_pd(_mm256_set1_pd((n - 2) as f64), _mm256_floor_pd(grid)), zero);
            cells[axis] = (index, _mm256_sub_pd(grid, index));
        }
        // The four samples about each point, by row and column.
        let (mut columns, mut rows) = ([0.0f64; 4], [0.0f64; 4]);
        _mm256_storeu_pd(columns.as_mut_ptr(), cells[0].0);
        _mm256_storeu_pd(rows.as_mut_ptr(), cells[1].0);
        let mut corners = [[0.0f64; 4]; 4];
        for lane in 0..4 {
            let (i0, j0) = (columns[lane] as usize, rows[lane] as usize);
            let (i1, j1) = ((i0 + 1).min(samples[0] - 1), (j0 + 1).min(samples[1] - 1));
            let h = |i: usize, j: usize| f64::from(level.heights[j * samples[0] + i]);
            [corners[0][lane], corners[1][lane], corners[2][lane], corners[3][lane]] =
                [h(i0, j0), h(i1, j0), h(i0, j1), h(i1, j1)];
        }
        let [h00, h10, h01, h11] = corners.map(|c| _mm256_loadu_pd(c.as_ptr()));
        let (fx, fy) = (cells[0].1, cells[1].1);
        let bottom = _mm256_add_pd(h00, _mm256_mul_pd(fx, _mm256_sub_pd(h10, h00)));
        let top = _mm256_add_pd(h01, _mm256_mul_pd(fx, _mm256_sub_pd(h11, h01)));
        heights[half] = _mm256_add_pd(bottom, _mm256_mul_pd(fy, _mm256_sub_pd(top, bottom)));
        // `far_distance`: `dir` is every point's, so its signs are too.
        for axis in (0..2).filter(|&axis| samples[axis] > 1) {
            let edge = match dir[axis] {
                d if d > 0.0 => pyramid.max[axis],
                d if d < 0.0 => pyramid.min[axis],
                _ => continue,
            };
            let t = _mm256_div_pd(_mm256_sub_pd(_mm256_set1_pd(edge), xy[axis]), _mm256_set1_pd(dir[axis]));
            t_far[half] = _mm256_max_pd(t, t_far[half]);
        }
    }
    // The steps no farther than `t_far` (they lie in order of distance), counted.
    let mut before_far = [zero; 2];
    let farthest = _mm256_max_pd(t_far[0], t_far[1]);
    for step in &pyramid.steps[..within] {
        let distance = _mm256_set1_pd(step.distance);
        if _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_LE_OQ>(distance, farthest)) == 0 {
            break;
        }
        for half in 0..halves {
            let within_far = _mm256_and_pd(_mm256_cmp_pd::<_CMP_LE_OQ>(distance, t_far[half]), _mm256_set1_pd(1.0));
            before_far[half] = _mm256_add_pd(before_far[half], within_far);
        }
    }
    let (mut counts, mut lifted) = ([0.0f64; 8], [0.0f64; 8]);
    for half in 0..halves {
        _mm256_storeu_pd(counts[4 * half..].as_mut_ptr(), before_far[half]);
        _mm256_storeu_pd(lifted[4 * half..].as_mut_ptr(), heights[half]);
    }
    for (lane, (receiver, p)) in out.iter_mut().zip(points).enumerate() {
        let taken = (counts[lane] as usize + 1).min(within);
        *receiver = AlongReceiver { x: p[0], y: p[1], above: (p[2] - lifted[lane]).max(0.0), taken };
    }
    true
}

/// The horizon tangents of up to eight `receivers` along one azimuth `dir`, one
/// receiver per lane, into `out` (`-inf` for a lane that takes no step).
///
/// Each lane reads its levels as [`horizons`] does: its receiver terms (the same
/// operations as [`receivers`], one level for eight receivers rather than eight levels
/// for one) and its steps' B-spline reads above them, in f32. The terms of a level are
/// read once the march reaches it, as the f64 march reads them, and a lane stops as
/// that march against a band stops: once no later step can rise above its horizon (the
/// ceiling of its level's steps from its own terms, of later levels from their relief,
/// [`LaneStep::later`]), once its horizon and every later step are at or below
/// `band[0]`, or once its horizon reaches `band[1]` (the band's bounds as tangents,
/// rounded outwards to f32); `band[2]` is the lowest horizon ([`lowest_horizon`]),
/// which no step need pass. A stop where no later step can change the answer leaves
/// each lane's tangent what it would be marched alone, whatever lanes beside it.
///
/// # Safety
/// The processor has AVX2 and FMA, [`available`] holds for `pyramid`'s levels, and
/// every receiver's `taken` is at most the step count.
#[target_feature(enable = "avx2,fma")]
pub unsafe fn tangents_along(
    pyramid: &HorizonPyramid,
    receivers: &[AlongReceiver],
    dir: [f64; 2],
    band: [f32; 3],
    out: &mut [f32; 8],
) {
    const MARGIN: f32 = 1e-5;
    let (mut xs, mut ys, mut above, mut taken) = ([0.0f64; 8], [0.0f64; 8], [0.0f32; 8], [0i32; 8]);
    for (lane, receiver) in receivers.iter().take(8).enumerate() {
        (xs[lane], ys[lane], above[lane]) = (receiver.x, receiver.y, receiver.above as f32);
        taken[lane] = receiver.taken as i32;
    }
    let longest = taken.iter().max().map_or(0, |&t| t as usize);
    let load = |values: &[f32; 8]| _mm256_loadu_ps(values.as_ptr());
    let abs = |v: __m256| _mm256_andnot_ps(_mm256_set1_ps(-0.0), v);
    let (taken, above) = (_mm256_loadu_si256(taken.as_ptr().cast()), load(&above));
    let (dx, dy) = (_mm256_set1_ps(dir[0] as f32), _mm256_set1_ps(dir[1] as f32));
    let (below, top, margin) = (_mm256_set1_ps(band[0]), _mm256_set1_ps(band[1]), _mm256_set1_ps(MARGIN));
    let (zero, floor) = (_mm256_setzero_ps(), _mm256_set1_ps(band[2]));
    // The current level's receiver terms, and the highest any of its reads rises above
    // them (its peak less the terms, with the margin of `step_ceilings`).
    let (mut level, mut u0, mut v0, mut base, mut start, mut rise) = (usize::MAX, zero, zero, zero, zero, zero);
    let mut max_tan = _mm256_set1_ps(f32::NEG_INFINITY);
    for (j, step) in pyramid.lane_steps[..longest].iter().enumerate() {
        if step.level != level {
            level = step.level;
            let (scale, padded) = (pyramid.grid_scales[level], &pyramid.padded[level]);
            let (mut u, mut v) = ([0.0f32; 8], [0.0f32; 8]);
            for lane in 0..8 {
                u[lane] = ((xs[lane] - pyramid.min[0]) * scale[0]) as f32;
                v[lane] = ((ys[lane] - pyramid.min[1]) * scale[1]) as f32;
            }
            (u0, v0) = (load(&u), load(&v));
            // `receivers`' base and start: the taps' sum above 0 is their sum.
            base = rise_lanes(padded, u0, v0, zero);
            start = _mm256_add_ps(rise_lanes(padded, u0, v0, base), above);
            let peak = _mm256_set1_ps(padded.peak);
            let terms = _mm256_add_ps(_mm256_add_ps(abs(peak), abs(base)), abs(start));
            rise = _mm256_fmadd_ps(margin, terms, _mm256_sub_ps(_mm256_sub_ps(peak, base), start));
        }
        // rise / d over the level's steps: largest at the nearest if positive, else the farthest.
        let nearest = _mm256_mul_ps(rise, _mm256_set1_ps(step.inv_distance));
        let farthest = _mm256_mul_ps(rise, _mm256_set1_ps(step.level_last_inv_distance));
        let this_level = _mm256_blendv_ps(farthest, nearest, _mm256_cmp_ps::<_CMP_GT_OQ>(rise, zero));
        let this_level = _mm256_fmadd_ps(margin, abs(this_level), this_level);
        let ceiling = _mm256_max_ps(this_level, _mm256_set1_ps(step.later));
        let known = _mm256_max_ps(max_tan, floor);
        let rising = _mm256_cmp_ps::<_CMP_LT_OQ>(known, ceiling);
        let settled_below =
            _mm256_and_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(known, below), _mm256_cmp_ps::<_CMP_LE_OQ>(ceiling, below));
        let under_top = _mm256_cmp_ps::<_CMP_LT_OQ>(max_tan, top);
        let taking = _mm256_castsi256_ps(_mm256_cmpgt_epi32(taken, _mm256_set1_epi32(j as i32)));
        let marching = _mm256_and_ps(_mm256_and_ps(_mm256_andnot_ps(settled_below, rising), under_top), taking);
        if _mm256_movemask_ps(marching) == 0 {
            break;
        }
        let u = _mm256_fmadd_ps(_mm256_set1_ps(step.reach[0]), dx, u0);
        let v = _mm256_fmadd_ps(_mm256_set1_ps(step.reach[1]), dy, v0);
        let climb = _mm256_sub_ps(rise_lanes(&pyramid.padded[level], u, v, base), start);
        let tangent = _mm256_mul_ps(climb, _mm256_set1_ps(step.inv_distance));
        max_tan = _mm256_blendv_ps(max_tan, _mm256_max_ps(max_tan, tangent), marching);
    }
    _mm256_storeu_ps(out.as_mut_ptr(), max_tan);
}

/// [`tangents_along`]'s tangent for one receiver with no stop: every step it takes,
/// read as a lane reads it (the tests' check that the stops change no bit).
#[cfg(test)]
#[target_feature(enable = "avx2,fma")]
pub unsafe fn every_step_along(pyramid: &HorizonPyramid, receiver: AlongReceiver, dir: [f64; 2]) -> f32 {
    let lane = |v: __m256| {
        let mut values = [0.0f32; 8];
        _mm256_storeu_ps(values.as_mut_ptr(), v);
        values[0]
    };
    let (dx, dy) = (_mm256_set1_ps(dir[0] as f32), _mm256_set1_ps(dir[1] as f32));
    let mut max_tan = f32::NEG_INFINITY;
    for step in &pyramid.lane_steps[..receiver.taken] {
        let (scale, padded) = (pyramid.grid_scales[step.level], &pyramid.padded[step.level]);
        let u0 = _mm256_set1_ps(((receiver.x - pyramid.min[0]) * scale[0]) as f32);
        let v0 = _mm256_set1_ps(((receiver.y - pyramid.min[1]) * scale[1]) as f32);
        let base = rise_lanes(padded, u0, v0, _mm256_setzero_ps());
        let start = _mm256_add_ps(rise_lanes(padded, u0, v0, base), _mm256_set1_ps(receiver.above as f32));
        let u = _mm256_fmadd_ps(_mm256_set1_ps(step.reach[0]), dx, u0);
        let v = _mm256_fmadd_ps(_mm256_set1_ps(step.reach[1]), dy, v0);
        let climb = _mm256_sub_ps(rise_lanes(padded, u, v, base), start);
        max_tan = max_tan.max(lane(_mm256_mul_ps(climb, _mm256_set1_ps(step.inv_distance))));
    }
    max_tan
}

/// The steps each azimuth takes into `taken`: every step up to `t_far` and the first
/// one past it, as the scalar march ([`HorizonPyramid::far_distance`]'s operations),
/// sixteen azimuths at a time in four registers, their steps counted in one pass.
#[target_feature(enable = "avx2,fma")]
unsafe fn step_counts(pyramid: &HorizonPyramid, x: f64, y: f64, taken: &mut [u32]) {
    let level = &pyramid.levels[0];
    let moving = [level.columns > 1, level.rows > 1];
    let (point, zero) = ([x, y], _mm256_setzero_pd());
    for (sixteen, counts) in taken.chunks_mut(16).enumerate() {
        let t_far: [__m256d; 4] = std::array::from_fn(|quarter| {
            let first = 16 * sixteen + 4 * quarter;
            let mut t_far = zero;
            for a in (0..2).filter(|&a| moving[a]) {
                let d = _mm256_loadu_pd(pyramid.lane_directions[a][first..][..4].as_ptr());
                let p = _mm256_set1_pd(point[a]);
                let ahead = _mm256_sub_pd(_mm256_set1_pd(pyramid.max[a]), p);
                let behind = _mm256_sub_pd(_mm256_set1_pd(pyramid.min[a]), p);
                let edge = _mm256_blendv_pd(behind, ahead, _mm256_cmp_pd::<_CMP_GT_OQ>(d, zero));
                let t = _mm256_blendv_pd(_mm256_div_pd(edge, d), zero, _mm256_cmp_pd::<_CMP_EQ_OQ>(d, zero));
                t_far = _mm256_max_pd(t_far, t);
            }
            t_far
        });
        let mut farthest = [0.0f64; 4];
        let highest = _mm256_max_pd(_mm256_max_pd(t_far[0], t_far[1]), _mm256_max_pd(t_far[2], t_far[3]));
        _mm256_storeu_pd(farthest.as_mut_ptr(), highest);
        let farthest = farthest.into_iter().fold(0.0, f64::max);
        let mut within = [_mm256_setzero_si256(); 4];
        for step in pyramid.steps.iter().take_while(|step| step.distance <= farthest) {
            let distance = _mm256_set1_pd(step.distance);
            for (within, t_far) in within.iter_mut().zip(&t_far) {
                let inside = _mm256_cmp_pd::<_CMP_LE_OQ>(distance, *t_far);
                *within = _mm256_sub_epi64(*within, _mm256_castpd_si256(inside));
            }
        }
        let mut lanes = [0i64; 16];
        for (quarter, within) in within.iter().enumerate() {
            _mm256_storeu_si256(lanes[4 * quarter..].as_mut_ptr().cast(), *within);
        }
        for (count, within) in counts.iter_mut().zip(lanes) {
            *count = (within as usize + 1).min(pyramid.steps.len()) as u32;
        }
    }
}

/// Eight azimuths marched in lanes: their directions, step counts, running maximum
/// tangents and keys (`u32::MAX` in an unused lane).
#[derive(Clone, Copy)]
struct Group {
    dx: __m256,
    dy: __m256,
    taken: __m256i,
    max_tan: __m256,
    keys: [u32; 8],
}

impl Group {
    /// The azimuths of up to eight `keys`; unused lanes take no step.
    #[target_feature(enable = "avx2,fma")]
    unsafe fn new(pyramid: &HorizonPyramid, keys: &[u32]) -> Self {
        let (mut dx, mut dy, mut taken, mut lanes) = ([0.0f32; 8], [0.0f32; 8], [0i32; 8], [u32::MAX; 8]);
        for (lane, &key) in keys.iter().enumerate() {
            let dir = pyramid.directions[(key & 0xffff) as usize];
            (dx[lane], dy[lane]) = (dir[0] as f32, dir[1] as f32);
            taken[lane] = (key >> 16) as i32;
            lanes[lane] = key;
        }
        Self::from_lanes(dx, dy, taken, [f32::NEG_INFINITY; 8], lanes)
    }

    /// The group whose lanes hold these values.
    #[target_feature(enable = "avx2,fma")]
    unsafe fn from_lanes(dx: [f32; 8], dy: [f32; 8], taken: [i32; 8], max_tan: [f32; 8], keys: [u32; 8]) -> Self {
        Self {
            dx: _mm256_loadu_ps(dx.as_ptr()),
            dy: _mm256_loadu_ps(dy.as_ptr()),
            taken: _mm256_loadu_si256(taken.as_ptr().cast()),
            max_tan: _mm256_loadu_ps(max_tan.as_ptr()),
            keys,
        }
    }

    /// The lanes still marching at step `j`: those whose horizon is below `ceiling` and
    /// which take step `j`, as a mask and as a bit per lane.
    #[inline(always)]
    unsafe fn marching(&self, j: usize, ceiling: __m256) -> (__m256, u32) {
        let below = _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_max_ps(self.max_tan, _mm256_setzero_ps()), ceiling);
        let taking = _mm256_cmpgt_epi32(self.taken, _mm256_set1_epi32(j as i32));
        let mask = _mm256_and_ps(below, _mm256_castsi256_ps(taking));
        (mask, _mm256_movemask_ps(mask) as u32)
    }

    /// Writes each used lane's tangent (at least 0) to `out`.
    #[target_feature(enable = "avx2,fma")]
    unsafe fn finish(&self, out: &mut [f64]) {
        let mut tangents = [0.0f32; 8];
        _mm256_storeu_ps(tangents.as_mut_ptr(), self.max_tan);
        for (&key, t) in self.keys.iter().zip(tangents) {
            if key != u32::MAX {
                out[(key & 0xffff) as usize] = f64::from(t).max(0.0);
            }
        }
    }

    /// The lanes of `groups` still marching (`marching[g]`, at most eight in all) in one
    /// group, after writing every lane's tangent so far to `out`.
    #[target_feature(enable = "avx2,fma")]
    unsafe fn merged(groups: &[Group; 2], marching: [u32; 2], out: &mut [f64]) -> Self {
        let (mut dx, mut dy, mut taken, mut max_tan, mut keys) =
            ([0.0f32; 8], [0.0f32; 8], [0i32; 8], [f32::NEG_INFINITY; 8], [u32::MAX; 8]);
        let mut lane = 0;
        for (group, bits) in groups.iter().zip(marching) {
            group.finish(out);
            let (mut gx, mut gy, mut gt, mut gm) = ([0.0f32; 8], [0.0f32; 8], [0i32; 8], [0.0f32; 8]);
            _mm256_storeu_ps(gx.as_mut_ptr(), group.dx);
            _mm256_storeu_ps(gy.as_mut_ptr(), group.dy);
            _mm256_storeu_si256(gt.as_mut_ptr().cast(), group.taken);
            _mm256_storeu_ps(gm.as_mut_ptr(), group.max_tan);
            for from in (0..8).filter(|k| bits >> k & 1 == 1) {
                (dx[lane], dy[lane], taken[lane], max_tan[lane]) = (gx[from], gy[from], gt[from], gm[from]);
                keys[lane] = group.keys[from];
                lane += 1;
            }
        }
        Self::from_lanes(dx, dy, taken, max_tan, keys)
    }

    /// Takes step `j` (`pyramid.lane_steps[j]`) in the lanes of the mask `marching`.
    #[inline(always)]
    unsafe fn step<const LEVELS: usize>(
        &mut self,
        pyramid: &HorizonPyramid,
        receiver: &Receiver<LEVELS>,
        j: usize,
        marching: __m256,
    ) {
        let step = &pyramid.lane_steps[j];
        let level = step.level;
        let [u0, v0] = receiver.origin[level].map(|g| _mm256_set1_ps(g));
        let u = _mm256_fmadd_ps(_mm256_set1_ps(step.reach[0]), self.dx, u0);
        let v = _mm256_fmadd_ps(_mm256_set1_ps(step.reach[1]), self.dy, v0);
        let rise = rise_lanes(&pyramid.padded[level], u, v, _mm256_set1_ps(receiver.base[level]));
        let climb = _mm256_sub_ps(rise, _mm256_set1_ps(receiver.start[level]));
        let tangent = _mm256_mul_ps(climb, _mm256_set1_ps(step.inv_distance));
        self.max_tan = _mm256_blendv_ps(self.max_tan, _mm256_max_ps(self.max_tan, tangent), marching);
    }
}

with_wide_registers! {
    /// Marches up to sixteen azimuths (`keys`) in two groups of eight lanes, step by step
    /// together; once the lanes still marching fit in eight, in one. Each lane stops after
    /// its own last step or once its horizon is above `ceilings[j]` (later steps cannot
    /// raise it, so its tangent is the whole march's).
    unsafe fn march_sixteen / march_sixteen_wide<const LEVELS: usize>(
        pyramid: &HorizonPyramid,
        receiver: &Receiver<LEVELS>,
        ceilings: &[f32],
        keys: &[u32],
        out: &mut [f64],
    ) {
        let (first_keys, second_keys) = keys.split_at(keys.len().min(8));
        let last_step = keys.iter().max().map_or(0, |key| key >> 16) as usize;
        let mut first = Group::new(pyramid, first_keys);
        let mut j = 0;
        // Both groups, while more than eight lanes march.
        if !second_keys.is_empty() {
            let mut second = Group::new(pyramid, second_keys);
            loop {
                if j == last_step {
                    first.finish(out);
                    second.finish(out);
                    return;
                }
                let ceiling = _mm256_set1_ps(ceilings[j]);
                let (first_mask, first_bits) = first.marching(j, ceiling);
                let (second_mask, second_bits) = second.marching(j, ceiling);
                if first_bits.count_ones() + second_bits.count_ones() <= 8 {
                    first = Group::merged(&[first, second], [first_bits, second_bits], out);
                    break;
                }
                first.step(pyramid, receiver, j, first_mask);
                second.step(pyramid, receiver, j, second_mask);
                j += 1;
            }
        }
        while j < last_step {
            let (mask, bits) = first.marching(j, _mm256_set1_ps(ceilings[j]));
            if bits == 0 {
                break;
            }
            first.step(pyramid, receiver, j, mask);
            j += 1;
        }
        first.finish(out);
    }
}

/// `ceilings[j]`: at least the tangent of any step from `j` on, in the arithmetic of
/// [`horizons`]. A step's tangent is its level's B-spline read above the receiver's
/// base, less the receiver's start, over the step's distance; the read is at most the
/// level's peak above the base, and the margin (1e-5 of the terms, far above f32's
/// rounding of a few operations) keeps the bound above the rounded tangent.
#[inline]
fn step_ceilings<const LEVELS: usize>(pyramid: &HorizonPyramid, receiver: &Receiver<LEVELS>, ceilings: &mut [f32]) {
    const MARGIN: f64 = 1e-5;
    let Some(last) = ceilings.len().checked_sub(1) else { return };
    // Per level, the highest read above the receiver's terms, with the margin.
    let mut rise = [0.0f64; LEVELS];
    for (level, rise) in rise.iter_mut().enumerate().take(pyramid.steps[last].level + 1) {
        let (peak, base, start) =
            (pyramid.padded[level].peak as f64, receiver.base[level] as f64, receiver.start[level] as f64);
        *rise = peak - base - start + MARGIN * (peak.abs() + base.abs() + start.abs());
    }
    let mut highest = f64::NEG_INFINITY;
    for (step, ceiling) in pyramid.steps.iter().zip(ceilings.iter_mut()).rev() {
        let tangent = rise[step.level] * step.inv_distance;
        highest = highest.max(tangent + MARGIN * tangent.abs());
        *ceiling = highest as f32;
    }
}

/// The level's bicubic B-spline at grid coordinates `(u, v)` (clamped: the flat
/// continuation), less `base`, in each lane. Each lane's four taps along a row are
/// four contiguous samples of the padded level (edge samples replicated, as
/// `bspline_taps` clamps them): eight 4-wide loads per row, transposed into the taps'
/// registers, in place of four gathers.
#[inline(always)]
unsafe fn rise_lanes(padded: &PaddedLevel, u: __m256, v: __m256, base: __m256) -> __m256 {
    let clamp = |g: __m256, last: f32| _mm256_min_ps(_mm256_max_ps(g, _mm256_setzero_ps()), _mm256_set1_ps(last));
    let (u, v) = (clamp(u, padded.last[0]), clamp(v, padded.last[1]));
    let (iu, iv) = (_mm256_cvttps_epi32(u), _mm256_cvttps_epi32(v));
    let wx = weights_lanes(_mm256_sub_ps(u, _mm256_cvtepi32_ps(iu)));
    let wy = weights_lanes(_mm256_sub_ps(v, _mm256_cvtepi32_ps(iv)));
    // Tap (iu - 1, iv - 1) of each lane is padded sample (iu, iv).
    let mut first = [0i32; 8];
    let at = _mm256_add_epi32(_mm256_mullo_epi32(iv, _mm256_set1_epi32(padded.stride as i32)), iu);
    _mm256_storeu_si256(first.as_mut_ptr().cast(), at);
    let samples = padded.samples.as_ptr();
    let mut sum = _mm256_setzero_ps();
    for (r, weight) in wy.iter().enumerate() {
        let row = samples.add(r * padded.stride);
        let taps = row_taps(row, &first);
        let mut line = _mm256_setzero_ps();
        for (c, h) in taps.iter().enumerate() {
            line = _mm256_fmadd_ps(wx[c], _mm256_sub_ps(*h, base), line);
        }
        sum = _mm256_fmadd_ps(*weight, line, sum);
    }
    sum
}

/// The four samples from `row + first[k]` of each lane `k`, as four registers of
/// eight lanes (tap `c` in register `c`): two 4x4 transposes.
#[inline(always)]
unsafe fn row_taps(row: *const f32, first: &[i32; 8]) -> [__m256; 4] {
    let load = |k: usize| _mm_loadu_ps(row.offset(first[k] as isize));
    let pair = |k: usize| _mm256_set_m128(load(k + 4), load(k));
    transpose(pair(0), pair(1), pair(2), pair(3))
}

/// Registers holding lanes `(k, k + 4)`'s four samples each, for `k = 0..4`, as four
/// registers of sample `c` in lanes `0..8`: a 4x4 transpose in each half.
#[inline(always)]
unsafe fn transpose(y0: __m256, y1: __m256, y2: __m256, y3: __m256) -> [__m256; 4] {
    let (t0, t1) = (_mm256_unpacklo_ps(y0, y1), _mm256_unpackhi_ps(y0, y1));
    let (t2, t3) = (_mm256_unpacklo_ps(y2, y3), _mm256_unpackhi_ps(y2, y3));
    [
        _mm256_shuffle_ps::<0x44>(t0, t2),
        _mm256_shuffle_ps::<0xEE>(t0, t2),
        _mm256_shuffle_ps::<0x44>(t1, t3),
        _mm256_shuffle_ps::<0xEE>(t1, t3),
    ]
}

/// The receiver's terms of one level: its grid coordinates, the base the march reads
/// the level's taps above, and its own read above that plus `h`.
pub struct Receiver<const LEVELS: usize> {
    pub origin: [[f32; 2]; LEVELS],
    pub base: [f32; LEVELS],
    pub start: [f32; LEVELS],
}

/// Fills `receiver` for levels `from..from + 8` (those the pyramid has), one level per
/// lane: the base is the level's B-spline at the receiver in f32 (within rounding of
/// `f_L(x)`, so the taps read above it are small and a constant level reads exactly 0
/// above it), and the start is the same B-spline read above the base with
/// [`rise_lanes`]' operations in its order, so that a lane's read at the receiver
/// itself cancels it exactly (a plane gives its own elevation).
#[target_feature(enable = "avx2,fma")]
unsafe fn receivers<const LEVELS: usize>(
    pyramid: &HorizonPyramid,
    x: f64,
    y: f64,
    above: f32,
    from: usize,
    receiver: &mut Receiver<LEVELS>,
) {
    let count = (pyramid.levels.len() - from).min(8);
    let (mut u, mut v, mut last_u, mut last_v) = ([0.0f32; 8], [0.0f32; 8], [0.0f32; 8], [0.0f32; 8]);
    let mut strides = [0i32; 8];
    let mut rows = [std::ptr::null::<f32>(); 8];
    for lane in 0..8 {
        // Lanes past the last level repeat it.
        let level = from + lane.min(count - 1);
        let (l, s) = (&pyramid.levels[level], pyramid.grid_scales[level]);
        u[lane] = ((x - pyramid.min[0]) * s[0]) as f32;
        v[lane] = ((y - pyramid.min[1]) * s[1]) as f32;
        (last_u[lane], last_v[lane]) = ((l.columns - 1) as f32, (l.rows - 1) as f32);
        strides[lane] = pyramid.padded[level].stride as i32;
        rows[lane] = pyramid.padded[level].samples.as_ptr();
    }
    for lane in 0..count {
        receiver.origin[from + lane] = [u[lane], v[lane]];
    }
    let load = |values: &[f32; 8]| _mm256_loadu_ps(values.as_ptr());
    let clamp = |g: __m256, last: __m256| _mm256_min_ps(_mm256_max_ps(g, _mm256_setzero_ps()), last);
    let (u, v) = (clamp(load(&u), load(&last_u)), clamp(load(&v), load(&last_v)));
    let (iu, iv) = (_mm256_cvttps_epi32(u), _mm256_cvttps_epi32(v));
    let wx = weights_lanes(_mm256_sub_ps(u, _mm256_cvtepi32_ps(iu)));
    let wy = weights_lanes(_mm256_sub_ps(v, _mm256_cvtepi32_ps(iv)));
    let stride = _mm256_loadu_si256(strides.as_ptr().cast());
    let mut first = [0i32; 8];
    _mm256_storeu_si256(first.as_mut_ptr().cast(), _mm256_add_epi32(_mm256_mullo_epi32(iv, stride), iu));
    let taps: [[__m256; 4]; 4] = std::array::from_fn(|r| {
        let at: [*const f32; 8] = std::array::from_fn(|k| rows[k].offset((first[k] + r as i32 * strides[k]) as isize));
        taps_at(&at)
    });
    let mut base = _mm256_setzero_ps();
    for (row, weight) in taps.iter().zip(&wy) {
        let mut line = _mm256_setzero_ps();
        for (h, w) in row.iter().zip(&wx) {
            line = _mm256_fmadd_ps(*w, *h, line);
        }
        base = _mm256_fmadd_ps(*weight, line, base);
    }
    let mut rise = _mm256_setzero_ps();
    for (row, weight) in taps.iter().zip(&wy) {
        let mut line = _mm256_setzero_ps();
        for (h, w) in row.iter().zip(&wx) {
            line = _mm256_fmadd_ps(*w, _mm256_sub_ps(*h, base), line);
        }
        rise = _mm256_fmadd_ps(*weight, line, rise);
    }
    let start = _mm256_add_ps(rise, _mm256_set1_ps(above));
    let (mut bases, mut starts) = ([0.0f32; 8], [0.0f32; 8]);
    _mm256_storeu_ps(bases.as_mut_ptr(), base);
    _mm256_storeu_ps(starts.as_mut_ptr(), start);
    receiver.base[from..from + count].copy_from_slice(&bases[..count]);
    receiver.start[from..from + count].copy_from_slice(&starts[..count]);
}

/// The four samples from each lane's own address `at[k]`, as four registers of eight
/// lanes (sample `c` in register `c`): [`row_taps`] with an address per lane.
#[inline(always)]
unsafe fn taps_at(at: &[*const f32; 8]) -> [__m256; 4] {
    let pair = |k: usize| _mm256_set_m128(_mm_loadu_ps(at[k + 4]), _mm_loadu_ps(at[k]));
    transpose(pair(0), pair(1), pair(2), pair(3))
}

/// The uniform cubic B-spline basis at eight fractions (`super::bspline_weights`).
#[inline(always)]
unsafe fn weights_lanes(t: __m256) -> [__m256; 4] {
    let (half, sixth) = (_mm256_set1_ps(0.5), _mm256_set1_ps(SIXTH));
    let t2 = _mm256_mul_ps(t, t);
    let t3 = _mm256_mul_ps(t2, t);
    let s = _mm256_sub_ps(_mm256_set1_ps(1.0), t);
    [
        _mm256_mul_ps(_mm256_mul_ps(_mm256_mul_ps(s, s), s), sixth),
        _mm256_add_ps(_mm256_fmsub_ps(half, t3, t2), _mm256_set1_ps(TWO_THIRDS)),
        _mm256_add_ps(_mm256_fnmadd_ps(half, t3, _mm256_mul_ps(half, _mm256_add_ps(t2, t))), sixth),
        _mm256_mul_ps(t3, sixth),
    ]
}
