//! The pyramid before and around its samples: the settings of the search, the plan of
//! levels and steps, a level's samples and the bounds that stop a march early, and the
//! bounds a relight keeps of a pixel's horizons (module doc of [`super`]).

#![allow(clippy::wildcard_imports)]

use super::filter::tent_weights;
use super::*;

/// Most pyramid levels a query supports (the per-query cache of receiver heights is
/// a stack array of this size, so queries never allocate).
pub const MAX_LEVELS: usize = 384;
/// Most march steps per direction (the per-direction scale samples live in a stack
/// array of this size).
pub const MAX_STEPS: usize = 512;

/// SN08 Eq. 2's `l`: step distance in units of the level's sample spacing. SN08 uses 1.
pub(super) const DISTANCE_IN_SPACINGS: f64 = 1.0;
/// The step table reaches this many map diagonals (see the module doc).
pub(super) const REACH_IN_DIAGONALS: f64 = 16.0;

/// How a pyramid level is read between its samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LevelReconstruction {
    /// Bicubic uniform B-spline of the level's samples (SN08 Section 4 and Figure 9:
    /// smooth reconstruction is needed to avoid shadow artifacts). 16 taps.
    BicubicBSpline,
    /// Bilinear interpolation of the level's samples. 4 taps; cheaper, C0 only.
    Bilinear,
}

/// How the horizon is taken over scale.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ScaleMax {
    /// Maximum of the cubic B-spline through the per-step angles (SN08 Eq. 4-5),
    /// sampled at knots and midpoints (SN08 Section 6).
    BSpline,
    /// Maximum over the steps only, one arctangent per direction (SN08 Section 6's
    /// speed-up for environment lighting).
    Steps,
}

/// The elevations between which a horizon matters, as the tangents of their bounds
/// ([`HorizonPyramid::horizon_against`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ElevationBand {
    /// A horizon at or below the elevation of this tangent is all one.
    pub below: f64,
    /// A horizon at or above the elevation of this tangent is all one.
    pub above: f64,
}

impl ElevationBand {
    /// Every elevation matters: the march finds the horizon.
    pub const ALL: ElevationBand = ElevationBand { below: f64::NEG_INFINITY, above: f64::INFINITY };

    /// Where a march's largest step tangent `t` puts the horizon, `max(atan t, atan
    /// floor)` ([`lowest_horizon`]): a horizon at or below the foot hides what one marched
    /// to its end there would, and one at or above the top the same (the band's
    /// definition).
    pub(super) fn against(self, t: f64, floor: f64) -> HorizonAgainst {
        let known = t.max(floor);
        if t >= self.above {
            HorizonAgainst::Above
        } else if known <= self.below {
            HorizonAgainst::Below
        } else {
            HorizonAgainst::At(known.atan())
        }
    }
}

/// The tangent below which no horizon marched within `reach` lies: 0 for an unbounded
/// march (the flat continuation's horizon tends to the horizontal, SN08 after Eq. 5),
/// none for a light at a finite distance, whose horizon is the highest surface before it,
/// below the horizontal too (thesis Section 4.3.1, Eq. 4.23: a lamp low in a valley is
/// seen from the slopes above it that face it).
pub fn lowest_horizon(reach: f64) -> f64 {
    if reach.is_finite() {
        f64::NEG_INFINITY
    } else {
        0.0
    }
}

/// Where a horizon lies against an [`ElevationBand`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum HorizonAgainst {
    /// At or below the band's foot.
    Below,
    /// At or above its top.
    Above,
    /// This elevation, in radians (it may lie outside the band).
    At(f64),
}

impl HorizonAgainst {
    /// The elevation of a horizon marched against [`ElevationBand::ALL`].
    pub(super) fn elevation(self) -> f64 {
        match self {
            HorizonAgainst::At(horizon) => horizon,
            HorizonAgainst::Below => 0.0,
            HorizonAgainst::Above => std::f64::consts::FRAC_PI_2,
        }
    }
}

/// Knobs of the horizon search. Defaults are chosen by measurement: see the table
/// on [`HorizonSettings::default`].
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HorizonSettings {
    /// W: number of azimuths `phi_k = 2 pi k / W` (paper 000 Section 4.1; SN08 uses
    /// 16-32 for environment light). 1..=1024.
    pub directions: usize,
    /// k: levels per halving of resolution, `b = 2^(1/k)` (SN08 Section 4). 0.5..=16.
    pub level_step: f64,
    /// o: level offset; step `j` reads level `j - ceil(k o)`, i.e. a level `2^o` times
    /// finer than its distance calls for (SN08 Section 4). Larger is sharper and
    /// closer to the exact horizon, at no extra steps but less prefiltering. 0..=16.
    pub level_offset: f64,
    /// Distance of the first march step, in level-0 sample spacings, snapped to the
    /// step grid `b^j`. SN08 starts at one spacing (Eq. 2 with `l = 1` at the finest
    /// level); starting below it resolves horizons closer than one cell (ridges,
    /// peaks) at `k log2(1/first_step)` extra steps per direction. 1/64..=8.
    pub first_step: f64,
    /// How a level is read between its samples.
    pub reconstruction: LevelReconstruction,
    /// How the maximum over scale is taken.
    pub scale_max: ScaleMax,
}

impl Default for HorizonSettings {
    /// W = 16, k = 4, o = 3, first step 1/2 spacing, bicubic B-spline levels, max
    /// over steps.
    ///
    /// Chosen from `measure_error_vs_settings` in `tests/heightfield.rs`
    /// (`cargo test --release --test suite heightfield::measure -- --ignored --nocapture`):
    /// horizon error against [`super::brute_force_horizon`] in radians at 16
    /// azimuths, on four 65^2-129^2 scenes (rough terrain of RMS slope ~1 with points
    /// on and 0.1 above it, a cone, a sine grating, one-sample-thick walls). Mean
    /// |error| (all scenes are biased low, by about the mean), steps per direction:
    ///
    /// | setting                              | rough | cone  | grating | walls | steps |
    /// |--------------------------------------|-------|-------|---------|-------|-------|
    /// | SN08 typical: k 4, o 2, f 1, spline  | 0.082 | 0.019 | 0.024   | 0.147 | 33    |
    /// | **default**: k 4, o 3, f 1/2, steps  | 0.046 | 0.007 | 0.009   | 0.115 | 37    |
    /// | k 2, o 2, f 1, bilinear, steps       | 0.066 | 0.014 | 0.019   | 0.136 | 17    |
    /// | k 4, o 3, f 1/2, bilinear, steps     | 0.032 | 0.005 | 0.006   | 0.098 | 37    |
    /// | k 8, o 4, f 1/4, steps               | 0.030 | 0.004 | 0.004   | 0.090 | 80    |
    ///
    /// - o: error falls with o on every scene at no extra steps (o 2 -> 3: -25..-55 %);
    ///   at o = 4 the walls scene's "wobble" (error variation as the receiver slides,
    ///   the aliasing SN08 Figure 3 warns of) rises by 15 %, so o = 3.
    /// - k: k = 8 halves little more error at twice the steps; k <= 2 is worse at
    ///   equal o (k = 1 misses features between its octave-spaced steps).
    /// - first step 1/2 (4 extra steps) cuts the worst case on rough terrain from
    ///   0.73 to 0.53 rad (horizons closer than one cell: ridges and peaks).
    /// - Max over steps instead of the B-spline over scale: lower error (the spline
    ///   lies below its largest sample) and 25 % faster, as SN08 Section 6 advises
    ///   for environment light, which is what this tool shades.
    /// - Bilinear levels are more accurate still in these means and 1.4x faster, but
    ///   wobble more on thin walls (+15 %), SN08 Figure 9's artifact; bicubic stays
    ///   the default and bilinear is the cheaper choice.
    /// - W: linear interpolation between azimuths (paper 000 Eq. 19) alone costs
    ///   0.024 / 0.013 / 0.003 / 0.026 rad mean at W = 16 (0.051 / 0.042 / 0.012 /
    ///   0.047 at W = 8), below the march's own error, so more azimuths buy little
    ///   until the march is finer; W = 16 is SN08's low end for environment light.
    fn default() -> Self {
        Self {
            directions: 16,
            level_step: 4.0,
            level_offset: 3.0,
            first_step: 0.5,
            reconstruction: LevelReconstruction::BicubicBSpline,
            scale_max: ScaleMax::Steps,
        }
    }
}

impl HorizonSettings {
    /// Checks every field's range.
    pub fn validate(&self) -> Result<(), HeightFieldError> {
        if !(1..=1024).contains(&self.directions) {
            return Err(HeightFieldError::BadSetting {
                name: "directions",
                value: self.directions as f64,
                expected: "an integer in 1..=1024",
            });
        }
        if !(self.level_step.is_finite() && (0.5..=16.0).contains(&self.level_step)) {
            return Err(HeightFieldError::BadSetting {
                name: "level_step",
                value: self.level_step,
                expected: "a number in 0.5..=16",
            });
        }
        if !(self.level_offset.is_finite() && (0.0..=16.0).contains(&self.level_offset)) {
            return Err(HeightFieldError::BadSetting {
                name: "level_offset",
                value: self.level_offset,
                expected: "a number in 0..=16",
            });
        }
        if !(self.first_step.is_finite() && (1.0 / 64.0..=8.0).contains(&self.first_step)) {
            return Err(HeightFieldError::BadSetting {
                name: "first_step",
                value: self.first_step,
                expected: "a number in 1/64..=8",
            });
        }
        Ok(())
    }
}

/// A pyramid before any sample is filtered: the level sizes, the march's step table and
/// the azimuths. [`HorizonPyramid::new`] filters the levels on the CPU; the GPU pre-pass
/// filters them from the same plan with the same taps ([`decimation_taps`]).
#[derive(Clone, Debug)]
pub struct PyramidPlan {
    /// Samples per axis of each level, level 0 (the map) first.
    pub sizes: Vec<[usize; 2]>,
    pub steps: Vec<MarchStep>,
    /// `(cos phi_k, sin phi_k)`.
    pub directions: Vec<[f64; 2]>,
}

impl PyramidPlan {
    pub fn new(field: &HeightField, settings: HorizonSettings) -> Result<Self, HeightFieldError> {
        settings.validate()?;
        let n = [field.columns(), field.rows()];
        let (min, max) = (field.min(), field.max());
        let spacing0 = field.spacing();
        let b = 2f64.powf(1.0 / settings.level_step);

        // Level sizes: ceil((n - 1)/b^j) + 1, at least 2, until 2 on every moving axis.
        let mut sizes: Vec<[usize; 2]> = vec![n];
        while sizes.last().is_some_and(|s| (0..2).any(|a| s[a] > 2)) {
            let j = sizes.len() as i32;
            let scale = b.powi(j);
            let size: [usize; 2] = std::array::from_fn(|a| {
                if n[a] <= 2 {
                    n[a]
                } else {
                    (((n[a] - 1) as f64 / scale - 1e-9).ceil() as usize + 1).max(2)
                }
            });
            sizes.push(size);
            if sizes.len() > MAX_LEVELS {
                return Err(HeightFieldError::TooLarge {
                    what: "pyramid levels",
                    needed: sizes.len(),
                    limit: MAX_LEVELS,
                });
            }
        }

        // Step table. A 1x1 map (no moving axis) is an infinite plane: no steps.
        let base = spacing0.iter().copied().filter(|&s| s > 0.0).fold(f64::INFINITY, f64::min);
        let mut steps = Vec::new();
        if base.is_finite() {
            let diagonal = (max[0] - min[0]).hypot(max[1] - min[1]);
            let reach = REACH_IN_DIAGONALS * diagonal;
            let offset = (settings.level_step * settings.level_offset - 1e-9).ceil().max(0.0) as i64;
            let first = (settings.level_step * settings.first_step.log2()).round() as i64;
            let top = sizes.len() as i64 - 1;
            let mut j = first;
            loop {
                let distance = DISTANCE_IN_SPACINGS * base * b.powf(j as f64);
                let level = (j - offset).clamp(0, top) as usize;
                steps.push(MarchStep { distance, inv_distance: 1.0 / distance, level });
                if distance >= reach {
                    break;
                }
                j += 1;
                if steps.len() >= MAX_STEPS {
                    return Err(HeightFieldError::TooLarge {
                        what: "march steps",
                        needed: steps.len() + 1,
                        limit: MAX_STEPS,
                    });
                }
            }
        }

        let w = settings.directions;
        let directions = (0..w)
            .map(|k| {
                let phi = std::f64::consts::TAU * k as f64 / w as f64;
                [phi.cos(), phi.sin()]
            })
            .collect();
        Ok(Self { sizes, steps, directions })
    }
}

/// The tent taps of level samples along one axis: per output sample, `(level-0 index,
/// weight)` (module doc, "What is built").
pub fn decimation_taps(n_in: usize, n_out: usize) -> Vec<Vec<(usize, f64)>> {
    tent_weights(n_in, n_out)
}

/// One pyramid level: a corner-registered grid over the field's rectangle.
#[derive(Clone, Debug)]
pub struct PyramidLevel {
    /// Samples along x.
    pub columns: usize,
    /// Samples along y.
    pub rows: usize,
    /// World distance between samples along x and y (0 on an axis with one sample).
    pub spacing: [f64; 2],
    /// Row-major heights, first row at `min.y`.
    pub heights: Vec<f32>,
}

/// A level's samples with one replicated sample before and two after each row and column,
/// so that the four taps of a B-spline read along a row are four contiguous samples
/// wherever the read falls (the same values `bspline_taps` clamps its indices to).
#[derive(Clone, Debug)]
pub(super) struct PaddedLevel {
    /// Samples per padded row, `columns + 3`.
    pub(super) stride: usize,
    /// `rows + 3` padded rows; sample `(i, j)` of the level at `(j + 1) * stride + i + 1`.
    pub(super) samples: Vec<f32>,
    /// The highest sample: no B-spline read of the level (nonnegative weights summing to
    /// 1) rises above it.
    pub(super) peak: f32,
    /// The last grid coordinate along x and y, `columns - 1` and `rows - 1`.
    pub(super) last: [f32; 2],
}

impl PaddedLevel {
    /// `level` padded, `peak` its highest sample ([`HorizonPyramid::peaks`]).
    pub(super) fn new(level: &PyramidLevel, peak: f32) -> Self {
        let (columns, rows) = (level.columns, level.rows);
        let stride = columns + 3;
        let clamp = |k: usize, n: usize| k.saturating_sub(1).min(n - 1);
        let samples = (0..(rows + 3) * stride)
            .map(|at| level.heights[clamp(at / stride, rows) * columns + clamp(at % stride, columns)])
            .collect();
        Self { stride, samples, peak, last: [(columns - 1) as f32, (rows - 1) as f32] }
    }
}

/// How steeply any read of the levels the step table reads can rise
/// ([`HorizonPyramid::steepest_climb`]).
#[derive(Clone, Debug)]
pub(super) struct ClimbBound {
    /// Slopes `[along x, along y]` per world unit such that a read's rise along a unit
    /// azimuth `d` is at most the largest `a |d_x| + b |d_y|` of them ([`slopes_by_bucket`],
    /// reduced to the corners of their upper-right hull).
    pub(super) corners: Vec<[f64; 2]>,
    /// At least the rounding of a step tangent, in the lanes' f32 (far more than the f64
    /// march's), the largest over the levels: 64 ulp of a level's relief for the reads'
    /// sums, and 8 ulp of its grid coordinates' size times its steepest differences for
    /// where they read, over its nearest step.
    pub(super) rounding: f64,
}

impl ClimbBound {
    /// The bound of `levels` as the step table `steps` reads them, `peaks` their lowest
    /// and highest samples.
    pub(super) fn new(levels: &[PyramidLevel], peaks: &[[f64; 2]], steps: &[MarchStep]) -> Self {
        let per_level: Vec<(Vec<[f64; 2]>, f64)> = levels
            .par_iter()
            .enumerate()
            .filter_map(|(l, level)| {
                let nearest = steps.iter().filter(|step| step.level == l).map(|step| step.inv_distance);
                let inv_distance = nearest.reduce(f64::max)?;
                let (slopes, steepest) = slopes_by_bucket(level);
                let [low, high] = peaks[l];
                let coordinates = level.columns.max(level.rows) as f64;
                let ulps = 64.0 * (high - low) + 8.0 * coordinates * (steepest[0] + steepest[1]);
                Some((upper_right_corners(slopes), f64::from(f32::EPSILON) * ulps * inv_distance))
            })
            .collect();
        let rounding = per_level.iter().map(|(_, rounding)| *rounding).fold(0.0, f64::max);
        let corners = upper_right_corners(per_level.into_iter().flat_map(|(corners, _)| corners).collect());
        Self { corners, rounding }
    }
}

/// How many slopes along x a level's cells are gathered into ([`slopes_by_bucket`]).
pub(super) const SLOPE_BUCKETS: usize = 4096;

/// Per cell `(i, j)` of `level` (reads at grid coordinates in `[i, i + 1) x [j, j + 1)`),
/// the largest differences between neighbouring samples among those its reads weigh, along
/// x and along y, per world unit: a bicubic B-spline read's derivative along x is a convex
/// combination of the 3x4 x-differences of its 4x4 taps (a quadratic B-spline's weights
/// times a cubic's), so it is at most the largest of them, and the same along y; a
/// bilinear read's are among them. Taps past the edges repeat the edge samples, as the
/// reads' do. The cells are gathered by their slope along x into [`SLOPE_BUCKETS`], each
/// the largest of both slopes of its cells (so at least each of them, and at most 1/4095
/// of the steepest along x above); with the level's largest differences along x and y.
pub(super) fn slopes_by_bucket(level: &PyramidLevel) -> (Vec<[f64; 2]>, [f64; 2]) {
    let (columns, rows) = (level.columns, level.rows);
    let height = |i: usize, j: usize| f64::from(level.heights[j * columns + i]);
    // Each sample's difference to the next along x and along y (0 past the edge).
    let mut next = [vec![0.0f64; columns * rows], vec![0.0f64; columns * rows]];
    for j in 0..rows {
        for i in 0..columns {
            if i + 1 < columns {
                next[0][j * columns + i] = (height(i + 1, j) - height(i, j)).abs();
            }
            if j + 1 < rows {
                next[1][j * columns + i] = (height(i, j + 1) - height(i, j)).abs();
            }
        }
    }
    let steepest = next.each_ref().map(|differences| differences.iter().copied().fold(0.0, f64::max));
    pub(super) fn row(values: &[f64], columns: usize, j: usize) -> &[f64] {
        &values[j * columns..(j + 1) * columns]
    }
    let clamped = |j: isize, n: usize| j.clamp(0, n as isize - 1) as usize;
    // The largest over a cell's taps: along the difference's own axis taps `k - 1` to `k +
    // 1` (none past the edge), along the other taps `k - 1` to `k + 2` (clamped to it).
    let mut along_x = vec![0.0f64; columns * rows];
    let mut along_y = vec![0.0f64; columns * rows];
    let (mut own, mut spread) = (vec![0.0f64; columns], vec![0.0f64; columns]);
    for j in 0..rows {
        let cells = &mut along_x[j * columns..(j + 1) * columns];
        for t in j as isize - 1..=j as isize + 2 {
            for (cell, &d) in cells.iter_mut().zip(row(&next[0], columns, clamped(t, rows))) {
                *cell = cell.max(d);
            }
        }
        spread.copy_from_slice(cells);
        for (i, cell) in cells.iter_mut().enumerate() {
            *cell = spread[i.saturating_sub(1)..(i + 2).min(columns)].iter().copied().fold(0.0, f64::max);
        }
        own.fill(0.0);
        for t in j.saturating_sub(1)..(j + 2).min(rows) {
            for (o, &d) in own.iter_mut().zip(row(&next[1], columns, t)) {
                *o = o.max(d);
            }
        }
        for (i, cell) in along_y[j * columns..(j + 1) * columns].iter_mut().enumerate() {
            *cell = (i as isize - 1..=i as isize + 2).map(|t| own[clamped(t, columns)]).fold(0.0, f64::max);
        }
    }
    let per_unit = level.spacing.map(|spacing| if spacing > 0.0 { 1.0 / spacing } else { 0.0 });
    let widest = steepest[0] * per_unit[0];
    let mut buckets = vec![[0.0f64; 2]; SLOPE_BUCKETS];
    for (&a, &b) in along_x.iter().zip(&along_y) {
        let [a, b] = [a * per_unit[0], b * per_unit[1]];
        let k = if widest > 0.0 { ((a / widest) * (SLOPE_BUCKETS - 1) as f64) as usize } else { 0 };
        let bucket = &mut buckets[k.min(SLOPE_BUCKETS - 1)];
        *bucket = [bucket[0].max(a), bucket[1].max(b)];
    }
    (buckets, steepest)
}

/// The points of `points` (nonnegative) that can be the largest `a x + b y` for some `x,
/// y >= 0`: those no other point dominates, then the corners of their hull, by `a`
/// decreasing.
pub(super) fn upper_right_corners(mut points: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    points.sort_by(|p, q| q[0].total_cmp(&p[0]).then(q[1].total_cmp(&p[1])));
    let mut corners: Vec<[f64; 2]> = Vec::new();
    for p in points {
        if corners.last().is_some_and(|last| p[1] <= last[1]) {
            continue;
        }
        // A corner on or inside the segment from the one before it to `p` is never the
        // largest alone.
        while let [.., o, m] = corners[..] {
            let cross = (m[0] - o[0]) * (p[1] - o[1]) - (m[1] - o[1]) * (p[0] - o[0]);
            if cross > 0.0 {
                break;
            }
            corners.pop();
        }
        corners.push(p);
    }
    corners
}

/// One march step in the lanes' f32 terms (`lanes`), from its [`MarchStep`].
#[derive(Clone, Copy, Debug)]
pub(super) struct LaneStep {
    /// The step's distance in grid units of its level along x and y.
    pub(super) reach: [f32; 2],
    /// `1 / d_j`.
    pub(super) inv_distance: f32,
    /// `1 / d` of the last step of its level.
    pub(super) level_last_inv_distance: f32,
    /// At least the tangent of any step of a later level from any receiver, in the
    /// lanes' f32 arithmetic: each such step's level's relief over its distance, the
    /// largest, with the margin of the lanes' ceilings (1e-5 of the terms, far above f32's
    /// rounding of a read's few dozen operations); `-inf` for the last level's steps.
    pub(super) later: f32,
    /// The level it reads.
    pub(super) level: usize,
}

/// One entry of the march's constant step table (SN08 Section 6 keeps `d_i`, `1/d_i`
/// in constant arrays the same way).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MarchStep {
    /// World distance from the query point, `d_j`.
    pub distance: f64,
    /// `1 / d_j`.
    pub inv_distance: f64,
    /// Pyramid level read at this step, `L(j)`.
    pub level: usize,
}

/// The margin of a march's step ceilings ([`HorizonPyramid::step_ceiling`]), relative
/// to the terms it bounds.
pub(super) const CEILING_MARGIN: f64 = 1e-9;

/// A receiver's terms `f_L(x)` (SN08 Eq. 2), one per level, read as a march first needs
/// them and kept for the azimuths after it: a march that stops early reads few levels.
pub(super) struct ReceiverTerms {
    pub(super) terms: [f64; MAX_LEVELS],
    /// Levels `0..read` are read (a march's steps read their levels in order).
    pub(super) read: usize,
}

impl ReceiverTerms {
    pub(super) fn new() -> Self {
        Self { terms: [0.0; MAX_LEVELS], read: 0 }
    }

    /// The term of `level` of `pyramid` at `(x, y)`, the same point at every call.
    #[inline]
    pub(super) fn term(&mut self, pyramid: &HorizonPyramid, level: usize, x: f64, y: f64) -> f64 {
        while self.read <= level {
            self.terms[self.read] = pyramid.sample_level(self.read, x, y);
            self.read += 1;
        }
        self.terms[level]
    }
}

/// How many sectors of azimuths a render keeps a pixel's horizons in for a relight, each
/// the highest of its azimuths' ([`HorizonPyramid::sector_maxima`]; fewer where W is
/// smaller): at the default W, each azimuth's own. Of the pixels a turn of the Sun-lamp
/// scene's three lamps lowered to 15, 20 and 12 deg would march, sixteen answer 84 to 92
/// %, eight 76 to 89 % and four 62 to 82 % ([`HorizonsBetween`]); a pixel reads only the
/// sectors that can answer ([`HorizonsUnder`]), so more cost a relight only in reading the
/// frame.
pub const HORIZON_SECTORS: usize = 16;

/// A bound on the horizon along one azimuth `u` from the horizons found at the W azimuths
/// `u_k` ([`HorizonPyramid::horizons_between`]), kept as the highest of each sector of
/// them ([`HORIZON_SECTORS`]), which answers most of a turned Sun lamp's pixels without a
/// march: a relight keeps the horizons its render found (`crate::transfer`'s `horizon`
/// layer).
///
/// Step `j` reads its level at `x + d_j u` along `u` and at `x + d_j u_k` along `u_k`, above
/// the same receiver terms. A read rises from one point to another at most by the climb
/// bound of their difference (`ClimbBound`: the steepest cell's slopes weighted by
/// `|dx|`, `|dy|`; clamping to the field's edges only shortens it), `d_j c(u - u_k)`, so
/// the two steps' tangents differ by at most `c(u - u_k)`, whatever the step. A march
/// along `u` takes a prefix of the step table (its reach, `t_far`), and every step of it
/// lies among those the march along `u_k` took or past its `t_far`, where that ray's read
/// no longer moves and its tangent is at most that of the first step past it, or
/// negative. So every step tangent along `u` is at most `max(t_k, 0) + c(u - u_k)` for
/// each `k`, `t_k` the horizon tangent along `u_k` (SN08 Section 6's maximum over the
/// steps, which the lanes find to the bit), and so at most a sector's highest `t_k` plus
/// the least `c(u - u_k)` of its azimuths; the bound is the least of those, with twice
/// the f32 rounding of a tangent (`ClimbBound::rounding`) for the two marches'
/// arithmetic. Of the pixels a turn would march over the Sun-lamp scene's field (W =
/// 16), sixteen sectors answer 98 to 100 % for its three lamps (2 deg disks at 50, 35
/// and 25 deg) turned 20, 150 and 250 deg (four 97 to 100 %), and 84 to 92 % for the
/// three lowered to 15, 20 and 12 deg turned 20, 75, 150 and 250 deg (four 62 to 82 %).
#[derive(Clone, Debug)]
pub struct HorizonsBetween {
    /// Per sector, the least `c(u - u_k)` of its azimuths, with its margins.
    pub(super) margins: Vec<f64>,
}

impl HorizonsBetween {
    /// At least the largest step tangent along the azimuth from a receiver at `p` whose
    /// sectors' highest horizon tangents are at most `found` (each `>= 0`; one per sector);
    /// infinite where `p` is not finite (a march answers it as unoccluded) or `found` is
    /// not one value per sector.
    pub fn tangent_at_most(&self, p: [f64; 3], found: &[f32]) -> f64 {
        if !bounds_at(p, found, self.margins.len()) {
            return f64::INFINITY;
        }
        let each = found.iter().zip(&self.margins).map(|(&t, &margin)| sector_bound(t, margin));
        each.fold(f64::INFINITY, f64::min)
    }

    /// The sectors that can bound a horizon below `foot`, those whose margin is: a
    /// sector's bound is its margin plus a tangent `>= 0`, so no other can. A turn asks
    /// whether [`Self::tangent_at_most`] is below a lamp's foot at every pixel, and of the
    /// W = 16 sectors one to six can answer it for the Sun-lamp scene's lamps (the
    /// azimuths nearest the lamp's; one or two for the lowest lamps).
    pub fn under(&self, foot: f64) -> HorizonsUnder {
        let sectors = self.margins.iter().enumerate().filter(|&(_, &margin)| margin < foot);
        HorizonsUnder { foot, count: self.margins.len(), sectors: sectors.map(|(s, &margin)| (s, margin)).collect() }
    }
}

/// Whether the horizons found at a receiver bound its horizon along an azimuth below a
/// foot ([`HorizonsBetween::under`]).
#[derive(Clone, Debug)]
pub struct HorizonsUnder {
    pub(super) foot: f64,
    /// How many sectors a receiver's horizons hold.
    pub(super) count: usize,
    /// The sectors whose margin is below the foot, with it.
    pub(super) sectors: Vec<(usize, f64)>,
}

impl HorizonsUnder {
    /// [`HorizonsBetween::tangent_at_most`]`(p, found) < foot`, read from the sectors that
    /// can make it so (the same answer: a value that is not a number bounds nothing).
    pub fn holds(&self, p: [f64; 3], found: &[f32]) -> bool {
        bounds_at(p, found, self.count)
            && self.sectors.iter().any(|&(s, margin)| sector_bound(found[s], margin) < self.foot)
    }
}

/// Whether the horizons `found` at `p` bound anything: `p` finite (a march answers it as
/// unoccluded) and one value per sector of `count`.
pub(super) fn bounds_at(p: [f64; 3], found: &[f32], count: usize) -> bool {
    found.len() == count && p.iter().all(|v| v.is_finite())
}

/// A sector's bound from its highest tangent `t`: `max(t, 0)` plus its `margin`, infinite
/// for a `t` that is not a number, which bounds nothing (`f32::max` would make it 0).
pub(super) fn sector_bound(t: f32, margin: f64) -> f64 {
    if t.is_nan() {
        f64::INFINITY
    } else {
        f64::from(t.max(0.0)) + margin
    }
}
