//! SN08's multi-resolution horizon search (Snyder & Nowrouzezahrai 2008, "Fast Soft
//! Self-Shadowing on Dynamic Height Fields", Sections 4 and 6), as used by paper 000
//! Section 4.1 for height-field self-shadowing and cast shadows.
//!
//! # Indexing
//!
//! SN08 numbers levels coarse to fine (its `f_{N-1}` is the original map). Here level
//! 0 is the original map and level `j` is coarser, with target spacing
//! `Delta_j = Delta_0 b^j`, `b = 2^(1/k)` (SN08 Section 4, "level step k"): our `j`
//! is SN08's `N - 1 - i`.
//!
//! # What is built (once per frame, [`HorizonPyramid::new`])
//!
//! - Level `j` is a corner-registered grid over the same rectangle with
//!   `ceil((n - 1)/b^j) + 1` samples per axis (at least 2; an axis with one sample
//!   keeps one), so its spacing is at most `Delta_0 b^j`. Levels stop at the first
//!   one that is 2 samples wide on every axis; SN08's count
//!   `N = ceil(k log2 n) + 1` is the same up to rounding.
//! - Level `j > 0` samples the level-0 samples prefiltered by a separable tent whose
//!   radius is the level's spacing (clamp-to-edge at the borders, which is the flat
//!   continuation). A tent of one output spacing is the ideal prefilter of linear
//!   ("bilinear") decimation; SN08 Section 6 reaches each level by successive bilinear
//!   decimations instead (a compounded kernel of comparable width; not measured
//!   here). We filter each level directly from level 0 so no rounding compounds.
//! - Levels are stored at their own resolution, each a flat `Vec<f32>` with its size
//!   and spacing (GPU-friendly). SN08 Section 6 resamples every level back to full
//!   resolution with a bicubic B-spline and reads it bilinearly; that costs
//!   `N` full-size maps (41 x 4 MB for a 1024^2 map), so instead the bicubic B-spline
//!   is evaluated at query time from the level's own samples (16 taps, or 4 taps via
//!   the [SH05] bilinear trick on hardware that filters f32). The result is the same
//!   B-spline surface SN08's pre-pass samples, without its final bilinear resampling.
//!
//! # The march (per query point and azimuth, [`HorizonPyramid::horizon_elevations`])
//!
//! Steps at distances `d_j = l Delta_0 b^j` (SN08 Eq. 2 with `l = 1`; `Delta_0` the
//! finer level-0 spacing), `j` starting at `round(k log2 first_step)` (SN08 starts at
//! `j = 0`, one spacing; the default starts half a spacing out), each reading level
//! `L(j) = clamp(j - ceil(k o), 0, N - 1)` (SN08's level offset `o`; SN08's text
//! clamps with `max`, evidently meaning `min` in its indexing):
//!
//! `omega_j = atan((f_L(x + d_j u) - f_L(x) - h) / d_j)`   (SN08 Eq. 2-3)
//!
//! Self-intersection: the receiver term is `f_L(x)`, the *same level's*
//! reconstruction under the query point (SN08 Eq. 2), not the point's own z. Every
//! level reproduces a plane exactly (tent and B-spline weights are symmetric and sum
//! to 1) away from the map's border, so on any plane, tilted or not, `omega_j` is
//! exactly the plane's elevation along `u` and a point on the surface never shadows
//! itself, however coarse the level. The point's own z enters only through
//! `h = max(z - H(x), 0)`, its height above the level-0 (bilinear) surface (paper 000
//! Section 4.1, "Height Field Cast Shadows": project onto the height field and offset
//! by the height above it). A height-field pixel has `h ~ 0`; a G-buffer position a
//! little *below* the bilinear surface (the mesh's triangles differ from it by up to
//! a fraction of the cell's curvature) is clamped to `h = 0` instead of being buried,
//! and one a little above lowers the nearest steps' tangents by `h / d_j`, which
//! matters only for `h` comparable to the first step (half a spacing).
//!
//! Over scale, either the maximum of the cubic B-spline through the `omega_j`
//! (SN08 Eq. 4-5, sampled at knots and midpoints with weights {1/6, 2/3, 1/6} and
//! {1/48, 23/48, 23/48, 1/48}, SN08 Section 6; end values replicated), or the
//! maximum over the steps with one arctangent (SN08 Section 6's environment-light
//! speed-up, the default), clamped at 0 (SN08, after Eq. 5; exact here, see the
//! parent module's doc).
//!
//! The march stops after the first step beyond `t_far`, the distance after which the
//! ray's clamped footprint stops moving (the flat continuation is then constant and
//! its horizon contribution decreases with distance), and never takes more than
//! [`HorizonPyramid::max_steps`] steps; the step table reaches 16 map diagonals, so
//! points up to ~15 diagonals outside the map still see it. Beyond the last step
//! taken, the constant continuation's `atan((c - z)/t)` is read at the first step
//! past `t_far`, up to a factor `b` farther than its true maximum at `t_far`.
//!
//! # Cost
//!
//! Per query: one level read per level used (the receiver terms, shared by all
//! azimuths), then per azimuth one level read per step, about
//! `k log2(t_far / (first_step Delta_0)) + 1` steps: 37 on average for a 129^2 map
//! with the defaults, 41 levels and at most 64 steps for 1025^2. A level read is 16
//! samples (bicubic B-spline) or 4 (bilinear). Building costs about `4 n^2`
//! multiply-adds per level and `gamma(k) = 1/(1 - 2^(-2/k))` times the map's memory
//! (3.4x at k = 4, SN08 Section 4); 92 ms for a 1025^2 map on 2 cores.
//!
//! A march with the maximum over steps stops once no later step can raise its horizon
//! (each level's highest and lowest samples bound its reads), and one along a single
//! azimuth, a sun's, once the horizon is known to lie below or above the disk
//! ([`HorizonPyramid::horizon_against`]); it then reads only the receiver terms of the
//! levels its steps reached. The horizons are the same to the bit.

use super::{bilinear, HeightField, HeightFieldError};
use rayon::prelude::*;
use std::sync::OnceLock;

/// Most pyramid levels a query supports (the per-query cache of receiver heights is
/// a stack array of this size, so queries never allocate).
pub const MAX_LEVELS: usize = 384;
/// Most march steps per direction (the per-direction scale samples live in a stack
/// array of this size).
pub const MAX_STEPS: usize = 512;

/// SN08 Eq. 2's `l`: step distance in units of the level's sample spacing. SN08 uses 1.
const DISTANCE_IN_SPACINGS: f64 = 1.0;
/// The step table reaches this many map diagonals (see the module doc).
const REACH_IN_DIAGONALS: f64 = 16.0;

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
    fn against(self, t: f64, floor: f64) -> HorizonAgainst {
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
    fn elevation(self) -> f64 {
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
struct PaddedLevel {
    /// Samples per padded row, `columns + 3`.
    stride: usize,
    /// `rows + 3` padded rows; sample `(i, j)` of the level at `(j + 1) * stride + i + 1`.
    samples: Vec<f32>,
    /// The highest sample: no B-spline read of the level (nonnegative weights summing to
    /// 1) rises above it.
    peak: f32,
    /// The last grid coordinate along x and y, `columns - 1` and `rows - 1`.
    last: [f32; 2],
}

impl PaddedLevel {
    /// `level` padded, `peak` its highest sample ([`HorizonPyramid::peaks`]).
    fn new(level: &PyramidLevel, peak: f32) -> Self {
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
struct ClimbBound {
    /// Slopes `[along x, along y]` per world unit such that a read's rise along a unit
    /// azimuth `d` is at most the largest `a |d_x| + b |d_y|` of them ([`slopes_by_bucket`],
    /// reduced to the corners of their upper-right hull).
    corners: Vec<[f64; 2]>,
    /// At least the rounding of a step tangent, in the lanes' f32 (far more than the f64
    /// march's), the largest over the levels: 64 ulp of a level's relief for the reads'
    /// sums, and 8 ulp of its grid coordinates' size times its steepest differences for
    /// where they read, over its nearest step.
    rounding: f64,
}

impl ClimbBound {
    /// The bound of `levels` as the step table `steps` reads them, `peaks` their lowest
    /// and highest samples.
    fn new(levels: &[PyramidLevel], peaks: &[[f64; 2]], steps: &[MarchStep]) -> Self {
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
const SLOPE_BUCKETS: usize = 4096;

/// Per cell `(i, j)` of `level` (reads at grid coordinates in `[i, i + 1) x [j, j + 1)`),
/// the largest differences between neighbouring samples among those its reads weigh, along
/// x and along y, per world unit: a bicubic B-spline read's derivative along x is a convex
/// combination of the 3x4 x-differences of its 4x4 taps (a quadratic B-spline's weights
/// times a cubic's), so it is at most the largest of them, and the same along y; a
/// bilinear read's are among them. Taps past the edges repeat the edge samples, as the
/// reads' do. The cells are gathered by their slope along x into [`SLOPE_BUCKETS`], each
/// the largest of both slopes of its cells (so at least each of them, and at most 1/4095
/// of the steepest along x above); with the level's largest differences along x and y.
fn slopes_by_bucket(level: &PyramidLevel) -> (Vec<[f64; 2]>, [f64; 2]) {
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
    fn row(values: &[f64], columns: usize, j: usize) -> &[f64] {
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
fn upper_right_corners(mut points: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
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
struct LaneStep {
    /// The step's distance in grid units of its level along x and y.
    reach: [f32; 2],
    /// `1 / d_j`.
    inv_distance: f32,
    /// `1 / d` of the last step of its level.
    level_last_inv_distance: f32,
    /// At least the tangent of any step of a later level from any receiver, in the
    /// lanes' f32 arithmetic: each such step's level's relief over its distance, the
    /// largest, with the margin of the lanes' ceilings (1e-5 of the terms, far above f32's
    /// rounding of a read's few dozen operations); `-inf` for the last level's steps.
    later: f32,
    /// The level it reads.
    level: usize,
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
const CEILING_MARGIN: f64 = 1e-9;

/// A receiver's terms `f_L(x)` (SN08 Eq. 2), one per level, read as a march first needs
/// them and kept for the azimuths after it: a march that stops early reads few levels.
struct ReceiverTerms {
    terms: [f64; MAX_LEVELS],
    /// Levels `0..read` are read (a march's steps read their levels in order).
    read: usize,
}

impl ReceiverTerms {
    fn new() -> Self {
        Self { terms: [0.0; MAX_LEVELS], read: 0 }
    }

    /// The term of `level` of `pyramid` at `(x, y)`, the same point at every call.
    #[inline]
    fn term(&mut self, pyramid: &HorizonPyramid, level: usize, x: f64, y: f64) -> f64 {
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
/// frame (the three lamps' at their default heights in 12.0 to 13.3 ms against 10.9 to
/// 11.5 ms for four, 2 cores).
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
    margins: Vec<f64>,
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
    foot: f64,
    /// How many sectors a receiver's horizons hold.
    count: usize,
    /// The sectors whose margin is below the foot, with it.
    sectors: Vec<(usize, f64)>,
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
fn bounds_at(p: [f64; 3], found: &[f32], count: usize) -> bool {
    found.len() == count && p.iter().all(|v| v.is_finite())
}

/// A sector's bound from its highest tangent `t`: `max(t, 0)` plus its `margin`, infinite
/// for a `t` that is not a number, which bounds nothing (`f32::max` would make it 0).
fn sector_bound(t: f32, margin: f64) -> f64 {
    if t.is_nan() {
        f64::INFINITY
    } else {
        f64::from(t.max(0.0)) + margin
    }
}

/// The multi-resolution pyramid of one height field plus the march tables.
#[derive(Clone, Debug)]
pub struct HorizonPyramid {
    settings: HorizonSettings,
    min: [f64; 2],
    max: [f64; 2],
    levels: Vec<PyramidLevel>,
    /// Per level and axis, grid units per world unit, `(n - 1) / (max - min)` (0 on an axis
    /// with one sample): a level read multiplies instead of dividing.
    grid_scales: Vec<[f64; 2]>,
    /// Per level, its lowest and highest samples, between which every read of it lies.
    peaks: Vec<[f64; 2]>,
    /// Per step, the first later step of a coarser level (or the step count).
    level_ends: Vec<usize>,
    /// Per step `j`, at least the tangent of every step from `j` on from any receiver:
    /// each step's level's relief (highest less lowest sample) over its distance, the
    /// largest from `j` on, with [`CEILING_MARGIN`].
    relief_ceilings: Vec<f64>,
    /// How steeply the reads of the levels the step table reads rise: what
    /// [`Self::steepest_climb`] bounds every step's tangent by, made at its first call (a
    /// frame with no sun does not pay for it).
    climbs: OnceLock<ClimbBound>,
    /// Whether [`Self::horizon_elevations`] marches in AVX2 lanes (`lanes`): decided once,
    /// when the pyramid is built.
    in_lanes: bool,
    /// The levels with their edge samples replicated around them, for the lanes (empty
    /// where they do not run).
    padded: Vec<PaddedLevel>,
    /// The step table in the lanes' terms (empty where they do not run).
    lane_steps: Vec<LaneStep>,
    /// `cos phi_k` and `sin phi_k` apart, zeros after the last azimuth up to a multiple of
    /// sixteen, for the lanes (empty where they do not run).
    lane_directions: [Vec<f64>; 2],
    steps: Vec<MarchStep>,
    /// `(cos phi_k, sin phi_k)`.
    directions: Vec<[f64; 2]>,
}

impl HorizonPyramid {
    /// Builds the pyramid levels and step table (module doc, "What is built").
    /// Cost: about `4 n_x n_y` multiply-adds per level, levels built in parallel.
    pub fn new(field: &HeightField, settings: HorizonSettings) -> Result<Self, HeightFieldError> {
        Ok(Self::from_plan(field, &PyramidPlan::new(field, settings)?, settings))
    }

    /// Filters the levels of `plan`, made for `field` with `settings`.
    pub fn from_plan(field: &HeightField, plan: &PyramidPlan, settings: HorizonSettings) -> Self {
        let n = [field.columns(), field.rows()];
        let (min, max) = (field.min(), field.max());
        let levels: Vec<PyramidLevel> = plan
            .sizes
            .par_iter()
            .enumerate()
            .map(|(j, &size)| {
                let spacing: [f64; 2] =
                    std::array::from_fn(|a| if size[a] > 1 { (max[a] - min[a]) / (size[a] - 1) as f64 } else { 0.0 });
                let heights = if j == 0 { field.heights().to_vec() } else { decimate(field.heights(), n, size) };
                PyramidLevel { columns: size[0], rows: size[1], spacing, heights }
            })
            .collect();
        let grid_scales: Vec<[f64; 2]> = levels
            .iter()
            .map(|l| {
                let n = [l.columns, l.rows];
                std::array::from_fn(|a| if n[a] > 1 { (n[a] - 1) as f64 / (max[a] - min[a]) } else { 0.0 })
            })
            .collect();
        let peaks: Vec<[f64; 2]> = levels
            .iter()
            .map(|l| {
                let heights = l.heights.iter().map(|&h| f64::from(h));
                heights.fold([f64::INFINITY, f64::NEG_INFINITY], |[low, high], h| [low.min(h), high.max(h)])
            })
            .collect();
        let level_ends: Vec<usize> = (0..plan.steps.len())
            .map(|j| {
                (j..plan.steps.len()).find(|&k| plan.steps[k].level > plan.steps[j].level).unwrap_or(plan.steps.len())
            })
            .collect();
        let mut relief_ceilings = vec![f64::NEG_INFINITY; plan.steps.len()];
        let mut highest = f64::NEG_INFINITY;
        for (step, ceiling) in plan.steps.iter().zip(relief_ceilings.iter_mut()).rev() {
            let [low, high] = peaks[step.level];
            let tangent = (high - low + CEILING_MARGIN * (high.abs() + low.abs())) * step.inv_distance;
            highest = highest.max(tangent + CEILING_MARGIN * tangent.abs());
            *ceiling = highest;
        }
        #[cfg(target_arch = "x86_64")]
        let in_lanes = settings.reconstruction == LevelReconstruction::BicubicBSpline
            && settings.scale_max == ScaleMax::Steps
            && lanes::available(&levels);
        #[cfg(not(target_arch = "x86_64"))]
        let in_lanes = false;
        let padded = if in_lanes {
            levels.par_iter().zip(&peaks).map(|(level, &[_, peak])| PaddedLevel::new(level, peak as f32)).collect()
        } else {
            Vec::new()
        };
        let (steps, directions) = (plan.steps.clone(), plan.directions.clone());
        let lane_steps = if in_lanes {
            steps
                .iter()
                .enumerate()
                .map(|(j, step): (usize, &MarchStep)| {
                    const MARGIN: f64 = 1e-5;
                    let level_end: usize = level_ends[j];
                    let later = steps[level_end..].iter().fold(f64::NEG_INFINITY, |highest, later: &MarchStep| {
                        let [low, high] = peaks[later.level];
                        let tangent = (high - low + MARGIN * (high.abs() + low.abs())) * later.inv_distance;
                        highest.max(tangent + MARGIN * tangent.abs())
                    });
                    LaneStep {
                        reach: grid_scales[step.level].map(|scale: f64| (step.distance * scale) as f32),
                        inv_distance: step.inv_distance as f32,
                        level_last_inv_distance: steps[level_end - 1].inv_distance as f32,
                        later: later as f32,
                        level: step.level,
                    }
                })
                .collect()
        } else {
            Vec::new()
        };
        let lane_directions: [Vec<f64>; 2] = std::array::from_fn(|a| {
            let mut axis: Vec<f64> = directions.iter().map(|d: &[f64; 2]| d[a]).collect();
            axis.resize(if in_lanes { directions.len().div_ceil(16) * 16 } else { 0 }, 0.0);
            axis
        });
        Self {
            settings,
            min,
            max,
            levels,
            grid_scales,
            peaks,
            level_ends,
            relief_ceilings,
            climbs: OnceLock::new(),
            in_lanes,
            padded,
            lane_steps,
            lane_directions,
            steps,
            directions,
        }
    }

    /// The settings it was built with.
    pub fn settings(&self) -> &HorizonSettings {
        &self.settings
    }

    /// The levels, finest (the original map) first.
    pub fn levels(&self) -> &[PyramidLevel] {
        &self.levels
    }

    /// The march's step table, nearest first.
    pub fn steps(&self) -> &[MarchStep] {
        &self.steps
    }

    /// The most steps one direction can take (the length of [`Self::steps`]).
    pub fn max_steps(&self) -> usize {
        self.steps.len()
    }

    /// `(cos phi_k, sin phi_k)` of the W azimuths.
    pub fn directions(&self) -> &[[f64; 2]] {
        &self.directions
    }

    /// Level-0 (bilinear) surface height, the same as [`HeightField::height_at`].
    pub fn height_at(&self, x: f64, y: f64) -> f64 {
        let l0 = &self.levels[0];
        bilinear(&l0.heights, l0.columns, l0.rows, self.min, self.max, x, y)
    }

    /// Number of march steps taken along azimuth `k` from `(x, y)`; the per-query
    /// cost is this many level reads per direction plus one read per level.
    pub fn steps_taken(&self, x: f64, y: f64, k: usize) -> usize {
        let t_far = self.far_distance(x, y, self.directions[k]);
        self.steps.iter().take_while(|s| s.distance <= t_far).count().saturating_add(1).min(self.steps.len())
    }

    /// Horizon elevations (radians, in `[0, pi/2)`) seen from world point `p` along the
    /// W azimuths `phi_k = 2 pi k / W`, written to `out[..W]`.
    ///
    /// `p` is on the terrain (height-field pixels) or above it (cast shadows on other
    /// objects, paper 000 Section 4.1); a point below the level-0 surface is treated
    /// as lying on it (its height above is clamped at 0). A non-finite `p` gives 0
    /// (unoccluded) everywhere rather than NaN. Allocation-free and `&self`, so it
    /// can run per pixel under rayon.
    ///
    /// # Panics
    /// If `out.len() < W`.
    pub fn horizon_elevations(&self, p: [f64; 3], out: &mut [f64]) {
        #[cfg(target_arch = "x86_64")]
        if self.in_lanes && self.horizon_tangents_in_lanes(p, out) {
            for o in out[..self.settings.directions].iter_mut() {
                *o = o.atan();
            }
            return;
        }
        self.horizon_elevations_marched(p, out);
    }

    /// The tangents of [`Self::horizon_elevations`] (each `>= 0`): what the march finds
    /// before its one arctangent per azimuth, for a caller that needs sines and
    /// differences of the elevations rather than the angles.
    pub fn horizon_tangents(&self, p: [f64; 3], out: &mut [f64]) {
        #[cfg(target_arch = "x86_64")]
        if self.in_lanes && self.horizon_tangents_in_lanes(p, out) {
            return;
        }
        self.horizon_elevations_marched(p, out);
        for o in out[..self.settings.directions].iter_mut() {
            *o = o.tan();
        }
    }

    /// The lanes' march (`lanes`) into `out` as tangents; `false` (nothing written) for a
    /// point the lanes leave to the f64 march (non-finite, or an empty step table).
    #[cfg(target_arch = "x86_64")]
    fn horizon_tangents_in_lanes(&self, p: [f64; 3], out: &mut [f64]) -> bool {
        let w = self.settings.directions;
        assert!(out.len() >= w, "horizon_elevations: out has {} slots but W = {}", out.len(), w);
        if !self.marchable(&p) {
            return false;
        }
        let (x, y, above) = self.receiver_of(&p);
        // SAFETY: `lanes::available` checked the processor's features and the levels'
        // sizes when the pyramid was built.
        unsafe { lanes::horizons(self, x, y, above, &mut out[..w]) };
        true
    }

    /// [`Self::horizon_elevations`] by the f64 march, one azimuth after another.
    fn horizon_elevations_marched(&self, p: [f64; 3], out: &mut [f64]) {
        let w = self.settings.directions;
        assert!(out.len() >= w, "horizon_elevations: out has {} slots but W = {}", out.len(), w);
        let out = &mut out[..w];
        if !self.marchable(&p) {
            out.fill(0.0);
            return;
        }
        let (x, y, above) = self.receiver_of(&p);

        // Receiver term f_L(x) of SN08 Eq. 2, once per level, shared by all azimuths.
        let mut receiver = ReceiverTerms::new();
        for (k, out_k) in out.iter_mut().enumerate() {
            let dir = self.directions[k];
            *out_k = self.march(x, y, above, &mut receiver, dir, f64::INFINITY, ElevationBand::ALL).elevation();
        }
    }

    /// The horizon elevation from `p` along one azimuth, unit `dir` in the xy plane: the
    /// same march as [`Self::horizon_elevations`] (SN08's swath, here a single azimuth, as
    /// its Section 6 does for a key light), over the steps no farther than `reach` (the
    /// horizontal distance to a local light, paper 002; infinite for a sun). 0 for a
    /// non-finite `p` or an empty pyramid.
    pub fn horizon_along(&self, p: [f64; 3], dir: [f64; 2], reach: f64) -> f64 {
        self.horizon_against(p, dir, reach, ElevationBand::ALL).elevation()
    }

    /// [`Self::horizon_along`], told where it matters: a sun's disk needs the horizon
    /// only between its lowest and highest directions (below, it hides none of the disk;
    /// above, all of it), so the march stops once it knows the horizon is outside `band`.
    ///
    /// Where the environment's horizons are marched in lanes, so is this one, in the same
    /// f32 arithmetic ([`Self::horizons_against`]); the f64 march otherwise.
    pub fn horizon_against(&self, p: [f64; 3], dir: [f64; 2], reach: f64, band: ElevationBand) -> HorizonAgainst {
        let mut out = [HorizonAgainst::Below];
        self.horizons_against(&[p], dir, reach, band, &mut out);
        out[0]
    }

    /// [`Self::horizon_against`] from each of `points` along the one azimuth `dir`, into
    /// `out`: a frame's pixels against one sun. Where the environment's horizons are
    /// marched in lanes, eight receivers are marched at once, one per lane, each with the
    /// bits it gets alone (so a pixel's horizon does not depend on the pixels marched
    /// beside it, nor on whether it was marched with any). The Sun-lamp scene's frame
    /// (320x180, a Sun lamp at 50 deg over a height field): its turned lamps' horizons
    /// took 65 % of their shading marched one pixel at a time in f64, and the turn took 47
    /// ms; marched so, 24 ms (2 cores, the frame read beforehand).
    pub fn horizons_against(
        &self,
        points: &[[f64; 3]],
        dir: [f64; 2],
        reach: f64,
        band: ElevationBand,
        out: &mut [HorizonAgainst],
    ) {
        assert_eq!(points.len(), out.len(), "horizons_against: one answer per point");
        let marchable = |p: &[f64; 3]| dir.iter().all(|v| v.is_finite()) && self.marchable(p);
        if !self.may_rise_into(dir, band) {
            for (p, out) in points.iter().zip(out) {
                *out = if marchable(p) { HorizonAgainst::Below } else { HorizonAgainst::At(0.0) };
            }
            return;
        }
        #[cfg(target_arch = "x86_64")]
        if self.in_lanes {
            // The band's bounds rounded outwards to f32, so that a lane that stops at one
            // stops where the f64 comparison would.
            let outwards = |bound: f64, down: bool| {
                let rounded = bound as f32;
                match f64::from(rounded) {
                    r if down && r > bound => -next_up(-rounded),
                    r if !down && r < bound => next_up(rounded),
                    _ => rounded,
                }
            };
            let floor = lowest_horizon(reach);
            let lane_band = [outwards(band.below, true), outwards(band.above, false), floor as f32];
            let within = self.steps_within(reach);
            let mut eight = [[0.0f64; 3]; 8];
            let mut slots = [usize::MAX; 8];
            let mut filled = 0;
            let flush = |eight: &[[f64; 3]], slots: &[usize], out: &mut [HorizonAgainst]| {
                let mut receivers = [lanes::AlongReceiver { x: 0.0, y: 0.0, above: 0.0, taken: 0 }; 8];
                // SAFETY: `in_lanes` means `lanes::available` held when the pyramid was
                // built; the points are finite.
                if !unsafe { lanes::along_receivers(self, eight, dir, within, &mut receivers) } {
                    for (receiver, p) in receivers.iter_mut().zip(eight) {
                        let (x, y, above) = self.receiver_of(p);
                        *receiver = lanes::AlongReceiver { x, y, above, taken: self.steps_marched(x, y, dir, within) };
                    }
                }
                let mut tangents = [0.0f32; 8];
                // SAFETY: as above, and each `taken` is a step count.
                unsafe { lanes::tangents_along(self, &receivers[..eight.len()], dir, lane_band, &mut tangents) };
                for (&slot, tangent) in slots.iter().zip(tangents) {
                    out[slot] = band.against(f64::from(tangent), floor);
                }
            };
            for (k, p) in points.iter().enumerate() {
                if !marchable(p) {
                    out[k] = HorizonAgainst::At(0.0);
                    continue;
                }
                eight[filled] = *p;
                slots[filled] = k;
                filled += 1;
                if filled == 8 {
                    flush(&eight, &slots, out);
                    filled = 0;
                }
            }
            if filled > 0 {
                flush(&eight[..filled], &slots[..filled], out);
            }
            return;
        }
        for (p, out) in points.iter().zip(out) {
            *out = match marchable(p) {
                true => {
                    let (x, y, above) = self.receiver_of(p);
                    self.march(x, y, above, &mut ReceiverTerms::new(), dir, reach, band)
                }
                false => HorizonAgainst::At(0.0),
            };
        }
    }

    /// Whether a horizon marched along the unit azimuth `dir` may reach `band`: not where
    /// no step can rise to its foot from any receiver ([`Self::steepest_climb`]), and
    /// [`Self::horizons_against`] then answers without marching: each horizon is below the
    /// band, as the march would find (a sun over a field gentler than its elevation), and
    /// `At(0.0)` off the field. The bound is at least 0, so a foot at or below the horizon
    /// (the environment's whole band, a sun on the horizon) neither asks for it nor makes
    /// it.
    pub fn may_rise_into(&self, dir: [f64; 2], band: ElevationBand) -> bool {
        !(band.below > 0.0 && self.steepest_climb(dir) < band.below)
    }

    /// Whether a horizon marched along any azimuth may reach `band` ([`Self::may_rise_into`]
    /// for some unit azimuth): a Sun lamp turned about the vertical keeps its band, so
    /// where this is false no turn of it marches the field. Each corner's `a |d_x| + b
    /// |d_y|` is at most `hypot(a, b)` over unit `d` (Cauchy-Schwarz), with the same
    /// margins as [`Self::steepest_climb`].
    pub fn may_rise_at_any_azimuth(&self, band: ElevationBand) -> bool {
        !(band.below > 0.0 && self.climb_bound(|[a, b]| a.hypot(*b)) < band.below)
    }

    /// At least the tangent of every step along the unit azimuth `dir` from any receiver, on
    /// the field or above it: a step's climb is its level's read less the receiver's read
    /// of that level and its height above the surface, and a read rises along `dir` at
    /// most by its cell's slopes weighted by `|dir|` (`slopes_by_bucket`; clamping to the
    /// field's edges only shortens the way), so by the steepest cell's. With the rounding
    /// of the tangents (`ClimbBound`). Where it is below a sun's disk, the field casts
    /// no shadow on it. The Sun-lamp scene's field (256x256) climbs at most 0.39, 0.49 and
    /// 0.43 along its lamp and the two added in the "Several Sun lamps" of docs/performance-log.md, turned 75
    /// deg (elevations 50, 35 and 25 deg, 2 deg disks whose feet are at tangents 1.15, 0.67
    /// and 0.44); the largest differences of each level along x and along y, of any two
    /// cells, would give 0.44, 0.57 and 0.50. For a `dir` of another length, the bound is
    /// that length times the unit one's, with the same rounding ([`HorizonsBetween`]).
    pub fn steepest_climb(&self, dir: [f64; 2]) -> f64 {
        self.climb_bound(|[a, b]| a * dir[0].abs() + b * dir[1].abs())
    }

    /// The largest `rise` of the climb bound's corners ([`ClimbBound`]), with a relative
    /// margin of 1e-6 for its rounding and the rounding of the tangents.
    fn climb_bound(&self, rise: impl Fn(&[f64; 2]) -> f64) -> f64 {
        let climbs = self.climbs.get_or_init(|| ClimbBound::new(&self.levels, &self.peaks, &self.steps));
        let steepest = climbs.corners.iter().map(rise).fold(0.0, f64::max);
        steepest + 1e-6 * steepest + climbs.rounding
    }

    /// What the horizons a shade found at a receiver ([`Self::horizon_tangents`], kept as
    /// the highest of each of `sectors` runs of azimuths, [`Self::sector_maxima`]) bound
    /// along the unit azimuth `dir` ([`HorizonsBetween`]): `None` where the horizon is the
    /// B-spline over scale (not the steps' maximum), `dir` is not finite, the step table
    /// is empty or `sectors` is not 1 to W.
    pub fn horizons_between(&self, dir: [f64; 2], sectors: usize) -> Option<HorizonsBetween> {
        let (steps, finite) = (self.settings.scale_max == ScaleMax::Steps, dir.iter().all(|v| v.is_finite()));
        if !steps || self.steps.is_empty() || !finite || !(1..=self.directions.len()).contains(&sectors) {
            return None;
        }
        let mut margins = vec![f64::INFINITY; sectors];
        for (k, u) in self.directions.iter().enumerate() {
            let margin = &mut margins[self.sector_of(k, sectors)];
            *margin = margin.min(self.steepest_climb([dir[0] - u[0], dir[1] - u[1]]));
        }
        // `steepest_climb` holds the rounding of one march's tangent; this, the other's.
        let rounding = self.climbs.get().map_or(f64::INFINITY, |climbs| climbs.rounding);
        Some(HorizonsBetween { margins: margins.into_iter().map(|margin| margin + rounding).collect() })
    }

    /// How many sectors of the W azimuths a relight keeps a pixel's horizons in
    /// ([`HORIZON_SECTORS`], or W where fewer).
    pub fn horizon_sectors(&self) -> usize {
        HORIZON_SECTORS.min(self.directions.len())
    }

    /// The sector of azimuth `k`: `k S / W` of `S = sectors`, each a run of neighbouring
    /// azimuths.
    fn sector_of(&self, k: usize, sectors: usize) -> usize {
        k * sectors / self.directions.len()
    }

    /// The highest of each sector's horizon `tangents` (W of them, [`Self::horizon_tangents`]),
    /// rounded up to f32, into `out` (one per sector): what a relight keeps of them.
    pub fn sector_maxima(&self, tangents: &[f64], out: &mut [f32]) {
        let mut highest = [f64::NEG_INFINITY; HORIZON_SECTORS];
        for (k, &tangent) in tangents.iter().enumerate().take(self.directions.len()) {
            let sector = &mut highest[self.sector_of(k, self.horizon_sectors())];
            // NaN kept (`f64::max` would drop it), where it bounds nothing.
            *sector = if tangent.is_nan() || sector.is_nan() { f64::NAN } else { sector.max(tangent) };
        }
        for (out, &sector) in out.iter_mut().zip(&highest[..self.horizon_sectors()]) {
            *out = f32_at_least(sector);
        }
    }

    /// Whether a march from `p` reads the pyramid: every query answers a point it does not
    /// (non-finite, or an empty step table) as unoccluded.
    fn marchable(&self, p: &[f64; 3]) -> bool {
        !self.steps.is_empty() && p.iter().all(|v| v.is_finite())
    }

    /// A query point as a march takes it: its ground position and its height above the
    /// level-0 surface, 0 for a point below it (paper 000 Section 4.1's receivers above
    /// the terrain).
    fn receiver_of(&self, p: &[f64; 3]) -> (f64, f64, f64) {
        let (x, y) = (p[0], p[1]);
        (x, y, (p[2] - self.height_at(x, y)).max(0.0))
    }

    /// How many steps lie within `reach` (the steps lie in order of distance).
    fn steps_within(&self, reach: f64) -> usize {
        self.steps.partition_point(|step| step.distance <= reach)
    }

    /// How many steps the march from `(x, y)` along `dir` takes: of the first `within`,
    /// those up to the first past the point where its footprint stops moving.
    fn steps_marched(&self, x: f64, y: f64, dir: [f64; 2], within: usize) -> usize {
        let t_far = self.far_distance(x, y, dir);
        let before_far = self.steps[..within].partition_point(|step| step.distance <= t_far);
        (before_far + 1).min(within)
    }

    /// One azimuth's march from `(x, y)`, `above` the surface, over the steps no farther
    /// than `reach`, its receiver terms read into `receiver` as the steps need them.
    ///
    /// The horizon is `max(atan(t), 0)`, `t` the largest step tangent, so a step whose
    /// tangent is at most `max(t so far, 0)` leaves it as it is, to the bit: the march
    /// stops where no step from there on can rise above that ([`Self::step_ceiling`]), or
    /// above the foot of `band` while `t` is below it, or where `t` passes the band's
    /// top. The B-spline over scale reads every step.
    #[allow(clippy::too_many_arguments)]
    fn march(
        &self,
        x: f64,
        y: f64,
        above: f64,
        receiver: &mut ReceiverTerms,
        dir: [f64; 2],
        reach: f64,
        band: ElevationBand,
    ) -> HorizonAgainst {
        let marched = self.steps_marched(x, y, dir, self.steps_within(reach));
        let steps = &self.steps[..marched];
        let floor = lowest_horizon(reach);
        let tangent = |step: &MarchStep, start: f64| {
            let q = self.sample_level(step.level, x + step.distance * dir[0], y + step.distance * dir[1]);
            (q - start - above) * step.inv_distance
        };
        let horizon = match self.settings.scale_max {
            ScaleMax::Steps => {
                let mut max_tan = f64::NEG_INFINITY;
                for (j, step) in steps.iter().enumerate() {
                    let start = receiver.term(self, step.level, x, y);
                    let (known, ceiling) = (max_tan.max(floor), self.step_ceiling(j, marched, start, above));
                    if known >= ceiling {
                        break;
                    }
                    if known <= band.below && ceiling <= band.below {
                        return HorizonAgainst::Below;
                    }
                    max_tan = max_tan.max(tangent(step, start));
                    if max_tan >= band.above {
                        return HorizonAgainst::Above;
                    }
                }
                max_tan.atan()
            }
            ScaleMax::BSpline => {
                let mut omega = [0.0f64; MAX_STEPS];
                for (omega, step) in omega.iter_mut().zip(steps) {
                    *omega = tangent(step, receiver.term(self, step.level, x, y)).atan();
                }
                bspline_max(&omega[..marched])
            }
        };
        HorizonAgainst::At(horizon.max(floor.atan()))
    }

    /// At least the tangent of every step from `j` to `marched`, the receiver's term at
    /// step `j`'s level `start`, `above` the surface. A level's read lies between its
    /// lowest and highest samples (bilinear and B-spline weights are nonnegative and sum
    /// to 1): the steps of `j`'s level rise at most to its highest sample above `start`,
    /// those of later levels at most their level's relief ([`Self::relief_ceilings`]),
    /// whose receiver terms need not be read. The margin, 1e-9 of the terms, is far above
    /// f64's rounding of a read's few dozen operations.
    fn step_ceiling(&self, j: usize, marched: usize, start: f64, above: f64) -> f64 {
        let step = &self.steps[j];
        let level_end = self.level_ends[j].min(marched);
        let peak = self.peaks[step.level][1];
        let rise = peak - start - above + CEILING_MARGIN * (peak.abs() + start.abs() + above);
        // rise / d over the level's steps: largest at the nearest if positive, else the farthest.
        let inv_distance = if rise > 0.0 { step.inv_distance } else { self.steps[level_end - 1].inv_distance };
        let tangent = rise * inv_distance;
        let this_level = tangent + CEILING_MARGIN * tangent.abs();
        match self.relief_ceilings.get(level_end) {
            Some(&later) if level_end < marched => this_level.max(later),
            _ => this_level,
        }
    }

    /// Ray distance after which the clamped footprint of `(x, y) + t dir` stops
    /// moving (see `reference.rs`).
    fn far_distance(&self, x: f64, y: f64, dir: [f64; 2]) -> f64 {
        let l0 = &self.levels[0];
        let n = [l0.columns, l0.rows];
        let p = [x, y];
        let mut t_far: f64 = 0.0;
        for a in 0..2 {
            if n[a] > 1 {
                let t = if dir[a] > 0.0 {
                    (self.max[a] - p[a]) / dir[a]
                } else if dir[a] < 0.0 {
                    (self.min[a] - p[a]) / dir[a]
                } else {
                    0.0
                };
                t_far = t_far.max(t);
            }
        }
        t_far
    }

    /// Reads level `level` at world `(x, y)` with the configured reconstruction and
    /// the flat continuation.
    #[inline]
    fn sample_level(&self, level: usize, x: f64, y: f64) -> f64 {
        let l = &self.levels[level];
        match self.settings.reconstruction {
            LevelReconstruction::Bilinear => bilinear(&l.heights, l.columns, l.rows, self.min, self.max, x, y),
            LevelReconstruction::BicubicBSpline => {
                let scale = self.grid_scales[level];
                let u = ((x - self.min[0]) * scale[0]).clamp(0.0, (l.columns - 1) as f64);
                let v = ((y - self.min[1]) * scale[1]).clamp(0.0, (l.rows - 1) as f64);
                // Away from the edges no tap is clamped: four contiguous samples per row
                // (the same sum as below, in the same order).
                let (i, j) = (u as usize, v as usize);
                if i >= 1 && j >= 1 && i + 2 < l.columns && j + 2 < l.rows {
                    let wx = bspline_weights(u - i as f64);
                    let wy = bspline_weights(v - j as f64);
                    let mut sum = 0.0;
                    for (r, w) in wy.iter().enumerate() {
                        let start = (j - 1 + r) * l.columns + i - 1;
                        let line: &[f32; 4] = l.heights[start..start + 4].try_into().expect("four taps");
                        let mut s = 0.0;
                        for (c, &h) in line.iter().enumerate() {
                            s += wx[c] * f64::from(h);
                        }
                        sum += w * s;
                    }
                    return sum;
                }
                let (ix, wx) = bspline_taps(u, l.columns);
                let (iy, wy) = bspline_taps(v, l.rows);
                let mut sum = 0.0;
                for (r, &row) in iy.iter().enumerate() {
                    let line = &l.heights[row * l.columns..(row + 1) * l.columns];
                    let mut s = 0.0;
                    for (c, &col) in ix.iter().enumerate() {
                        s += wx[c] * f64::from(line[col]);
                    }
                    sum += wy[r] * s;
                }
                sum
            }
        }
    }
}

/// The march of [`HorizonPyramid::horizon_elevations`] over sixteen azimuths at once, in
/// two groups of eight AVX2 and FMA lanes: the default settings' bicubic B-spline levels
/// and maximum over steps. Each lane is one azimuth; its 16 taps are four rows of four
/// contiguous samples of the padded level, and a lane stops after its own last step (the
/// scalar march's `t_far` and step table) or once no later step can raise its horizon.
/// The march of [`HorizonPyramid::horizons_against`] turns it about: one azimuth (a sun's)
/// from eight receivers (a frame's pixels), a receiver per lane ([`tangents_along`]).
///
/// Positions are f32 grid units, and a level read is the weighted sum of its taps'
/// heights above the receiver term `f_L(x)` (read in f32, eight levels per pass), so no
/// two large sums cancel. `f_L(x)` itself is read again above that base the same way,
/// with the same operations, so a plane still gives exactly its own elevation and a flat
/// surface exactly 0. Against the f64 march the horizons differ by the f32 rounding of the
/// positions (`tests` below).
///
/// The per-step helpers are `#[inline(always)]` without target features of their own, so
/// that each build of `march_sixteen` (`crate::x86`) inlines them with its own registers;
/// like every function here, they run only where the processor has AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
mod lanes {
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
            && levels.iter().all(|l| {
                (l.columns + 3) * (l.rows + 3) < i32::MAX as usize && l.columns <= 1 << 24 && l.rows <= 1 << 24
            })
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
            let at: [*const f32; 8] =
                std::array::from_fn(|k| rows[k].offset((first[k] + r as i32 * strides[k]) as isize));
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
}

/// The least f32 above `x` (`f32::next_up`, which this crate's Rust version lacks).
fn next_up(x: f32) -> f32 {
    if x.is_nan() || x == f32::INFINITY {
        return x;
    }
    if x == 0.0 {
        return f32::from_bits(1);
    }
    let bits = x.to_bits();
    f32::from_bits(if x > 0.0 { bits + 1 } else { bits - 1 })
}

/// The least f32 at or above `x` (a horizon tangent kept as a bound,
/// [`HorizonsBetween`]); `NaN` for `NaN`.
fn f32_at_least(x: f64) -> f32 {
    let rounded = x as f32;
    if f64::from(rounded) < x {
        next_up(rounded)
    } else {
        rounded
    }
}

/// Uniform cubic B-spline basis at fraction `t` (SN08 Section 4, after Eq. 4).
#[inline]
fn bspline_weights(t: f64) -> [f64; 4] {
    let t2 = t * t;
    let t3 = t2 * t;
    let s = 1.0 - t;
    const SIXTH: f64 = 1.0 / 6.0;
    [s * s * s * SIXTH, (0.5 * t3 - t2) + 4.0 * SIXTH, (-0.5 * t3 + 0.5 * (t2 + t)) + SIXTH, t3 * SIXTH]
}

/// Clamped sample indices and weights of the cubic B-spline at grid coordinate `u`
/// (already clamped to `[0, n - 1]`); replicating edge samples makes the surface
/// constant beyond the edge.
#[inline]
fn bspline_taps(u: f64, n: usize) -> ([usize; 4], [f64; 4]) {
    if n <= 1 {
        return ([0; 4], [0.25; 4]);
    }
    // `u` is clamped to `[0, n - 1]`: truncation (an integer conversion, not a libm
    // call) is its floor.
    let i = u as isize;
    let w = bspline_weights(u - i as f64);
    let last = (n - 1) as isize;
    (std::array::from_fn(|t| (i - 1 + t as isize).clamp(0, last) as usize), w)
}

/// Maximum over `tau in [0, m - 1]` of the cubic B-spline through `omega` (SN08 Eq.
/// 4-5), sampled at the knots and at the midpoints between knots (SN08 Section 6),
/// with end values replicated. This approximates (from below) the spline's true
/// maximum; the spline itself lies below the largest sample, which is part of
/// SN08's filtering bias.
fn bspline_max(omega: &[f64]) -> f64 {
    let m = omega.len();
    let at = |i: isize| omega[i.clamp(0, m as isize - 1) as usize];
    let mut best = f64::NEG_INFINITY;
    for i in 0..m as isize {
        let knot = (at(i - 1) + 4.0 * at(i) + at(i + 1)) / 6.0;
        best = best.max(knot);
        if i + 1 < m as isize {
            let mid = (at(i - 1) + 23.0 * (at(i) + at(i + 1)) + at(i + 2)) / 48.0;
            best = best.max(mid);
        }
    }
    best
}

/// Level samples of size `size` from the level-0 samples (size `n`): separable tent
/// prefilter of radius one output spacing, clamp-to-edge (module doc).
fn decimate(heights: &[f32], n: [usize; 2], size: [usize; 2]) -> Vec<f32> {
    let wx = tent_weights(n[0], size[0]);
    let wy = tent_weights(n[1], size[1]);
    // Pass 1 along x: n[1] rows of size[0].
    let mut tmp = vec![0.0f64; n[1] * size[0]];
    tmp.par_chunks_mut(size[0]).enumerate().for_each(|(row, out)| {
        let line = &heights[row * n[0]..(row + 1) * n[0]];
        for (o, taps) in out.iter_mut().zip(&wx) {
            *o = taps.iter().map(|&(i, w)| w * f64::from(line[i])).sum();
        }
    });
    // Pass 2 along y.
    let mut out = vec![0.0f32; size[0] * size[1]];
    out.par_chunks_mut(size[0]).zip(wy.par_iter()).for_each(|(line, taps)| {
        for (c, o) in line.iter_mut().enumerate() {
            *o = taps.iter().map(|&(r, w)| w * tmp[r * size[0] + c]).sum::<f64>() as f32;
        }
    });
    out
}

/// Per output sample, the (input index, weight) taps of a tent of radius one output
/// spacing, in input-index units, clamped to the input, normalised.
fn tent_weights(n_in: usize, n_out: usize) -> Vec<Vec<(usize, f64)>> {
    if n_out <= 1 || n_in <= 1 {
        return vec![vec![(0, 1.0)]; n_out.max(1)];
    }
    let ratio = (n_in - 1) as f64 / (n_out - 1) as f64;
    let last = (n_in - 1) as isize;
    (0..n_out)
        .map(|i| {
            let c = i as f64 * ratio;
            let lo = (c - ratio).ceil() as isize;
            let hi = (c + ratio).floor() as isize;
            let mut taps: Vec<(usize, f64)> = (lo..=hi)
                .filter_map(|m| {
                    let w = 1.0 - (m as f64 - c).abs() / ratio;
                    (w > 1e-12).then(|| (m.clamp(0, last) as usize, w))
                })
                .collect();
            let total: f64 = taps.iter().map(|t| t.1).sum();
            for t in &mut taps {
                t.1 /= total;
            }
            taps
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One azimuth's march reading every step and every receiver term: what the march's
    /// early stops must give, to the bit.
    fn march_every_step(pyramid: &HorizonPyramid, p: [f64; 3], dir: [f64; 2], reach: f64) -> f64 {
        every_step_tangent(pyramid, p, dir, reach).atan().max(lowest_horizon(reach).atan())
    }

    /// The largest tangent of [`march_every_step`]'s steps.
    fn every_step_tangent(pyramid: &HorizonPyramid, p: [f64; 3], dir: [f64; 2], reach: f64) -> f64 {
        let (x, y) = (p[0], p[1]);
        let above = (p[2] - pyramid.height_at(x, y)).max(0.0);
        let t_far = pyramid.far_distance(x, y, dir);
        let mut max_tan = f64::NEG_INFINITY;
        for step in &pyramid.steps {
            if step.distance > reach {
                break;
            }
            let q = pyramid.sample_level(step.level, x + step.distance * dir[0], y + step.distance * dir[1]);
            let start = pyramid.sample_level(step.level, x, y);
            max_tan = max_tan.max((q - start - above) * step.inv_distance);
            if step.distance > t_far {
                break;
            }
        }
        max_tan
    }

    /// The bumps of the test fields, by sample column and row (45 x 31 samples over
    /// `[-4, 5] x [-3, 3]`, [`test_field`]), about zero.
    fn bumps(x: f32, y: f32) -> f32 {
        1.5 * (0.6 * x).sin() * (0.35 * y).cos() + 0.8 * (0.21 * x + 0.13 * y).sin()
    }

    /// A 45 x 31 field over `[-4, 5] x [-3, 3]` of `height` by sample column and row (9/44
    /// apart along x, 6/30 along y), and 61 points on it, just above it, above it and
    /// outside it.
    fn test_field(height: impl Fn(f32, f32) -> f32) -> (HeightField, Vec<[f64; 3]>) {
        let (columns, rows) = (45, 31);
        let heights = (0..columns * rows).map(|i| height((i % columns) as f32, (i / columns) as f32)).collect();
        let field = HeightField::new(heights, columns, rows, [-4.0, -3.0], [5.0, 3.0]).unwrap();
        let points = (0..61)
            .map(|i| {
                let (x, y) = (-4.5 + 0.17 * i as f64, -3.2 + 0.61 * ((i * 7) % 11) as f64);
                [x, y, field.height_at(x, y) + [0.0, 0.02, 0.3, 1.5][i % 4]]
            })
            .collect();
        (field, points)
    }

    /// A pyramid of a bumpy field 50 above zero, and 61 points on it, just above it, above
    /// it and outside it, for the single-azimuth marches.
    fn bumpy_field_and_points() -> (HorizonPyramid, Vec<[f64; 3]>) {
        let (field, points) = test_field(|x, y| bumps(x, y) + 50.0);
        (HorizonPyramid::new(&field, HorizonSettings::default()).unwrap(), points)
    }

    /// The lanes' largest tangent over every step that the march from `p` along `dir` takes
    /// within its first `within` steps ([`lanes::every_step_along`]).
    #[cfg(target_arch = "x86_64")]
    fn lanes_every_step(pyramid: &HorizonPyramid, p: [f64; 3], dir: [f64; 2], within: usize) -> f64 {
        assert!(pyramid.in_lanes, "the lanes march this pyramid");
        let above = (p[2] - pyramid.height_at(p[0], p[1])).max(0.0);
        let taken = pyramid.steps_marched(p[0], p[1], dir, within);
        let receiver = lanes::AlongReceiver { x: p[0], y: p[1], above, taken };
        // SAFETY: the pyramid marches in lanes, so the processor has AVX2 and FMA.
        f64::from(unsafe { lanes::every_step_along(pyramid, receiver, dir) })
    }

    /// The march's stops (no later step can raise the horizon; it is known to lie below or
    /// above a band) change no horizon: points on, above and outside a bumpy field, 24
    /// azimuths, three reaches, four bands, each kind of stop seen.
    #[test]
    fn the_march_stops_early_without_changing_a_bit() {
        let (pyramid, points) = bumpy_field_and_points();
        let bands = [(0.0, 0.05), (0.1, 0.3), (0.5, 0.9), (1.0, 1.4)];
        let (mut below, mut above, mut at) = (0, 0, 0);
        for &p in &points[..60] {
            let (x, y) = (p[0], p[1]);
            let lift = (p[2] - pyramid.height_at(x, y)).max(0.0);
            let f64_march = |dir, reach, band| pyramid.march(x, y, lift, &mut ReceiverTerms::new(), dir, reach, band);
            for k in 0..24 {
                let dir = (k as f64 * std::f64::consts::TAU / 24.0).sin_cos();
                let dir = [dir.1, dir.0];
                for reach in [f64::INFINITY, 2.0, 0.3] {
                    let every = march_every_step(&pyramid, p, dir, reach);
                    let whole = f64_march(dir, reach, ElevationBand::ALL).elevation();
                    assert_eq!(whole.to_bits(), every.to_bits(), "{p:?} {dir:?}");
                    for (low, high) in bands {
                        let band = ElevationBand { below: f64::tan(low), above: f64::tan(high) };
                        match f64_march(dir, reach, band) {
                            HorizonAgainst::Below => {
                                assert!(every <= low + 1e-12, "{every} is above {low}");
                                below += 1;
                            }
                            HorizonAgainst::Above => {
                                assert!(every >= high - 1e-12, "{every} is below {high}");
                                above += 1;
                            }
                            HorizonAgainst::At(horizon) => {
                                assert_eq!(horizon.to_bits(), every.to_bits());
                                at += 1;
                            }
                        }
                    }
                }
            }
        }
        assert!(below > 0 && above > 0 && at > 0, "below {below}, above {above}, at {at}");
    }

    /// Per cell of `level`, the largest differences between neighbouring samples of its
    /// 4x4 taps along x and along y per world unit, taps past the edges repeating the
    /// edge samples, one cell and tap at a time: what [`slopes_by_bucket`] gathers.
    fn cell_slopes(level: &PyramidLevel) -> Vec<[f64; 2]> {
        let (columns, rows) = (level.columns, level.rows);
        let at = |i: isize, j: isize| {
            let (i, j) = (i.clamp(0, columns as isize - 1) as usize, j.clamp(0, rows as isize - 1) as usize);
            f64::from(level.heights[j * columns + i])
        };
        let per_unit = level.spacing.map(|spacing| if spacing > 0.0 { 1.0 / spacing } else { 0.0 });
        let mut slopes = Vec::with_capacity(columns * rows);
        for j in 0..rows as isize {
            for i in 0..columns as isize {
                let (mut along_x, mut along_y) = (0.0f64, 0.0f64);
                for tap_j in j - 1..=j + 2 {
                    for tap_i in i - 1..=i + 1 {
                        along_x = along_x.max((at(tap_i + 1, tap_j) - at(tap_i, tap_j)).abs());
                    }
                }
                for tap_i in i - 1..=i + 2 {
                    for tap_j in j - 1..=j + 1 {
                        along_y = along_y.max((at(tap_i, tap_j + 1) - at(tap_i, tap_j)).abs());
                    }
                }
                slopes.push([along_x * per_unit[0], along_y * per_unit[1]]);
            }
        }
        slopes
    }

    /// No step climbs more steeply than [`HorizonPyramid::steepest_climb`] says: the f64
    /// march's and the lanes' tangents over every step, from points on, just above, above
    /// and outside a bumpy field, a gentle one and a plane rising 0.4 along x and 0.25 along
    /// y, 24 azimuths. On the plane the bound is tight (the steepest step within 10 % of it
    /// where the azimuth climbs both axes; the coarser levels' edges climb a little more
    /// steeply than the plane), and the bound over every azimuth
    /// ([`HorizonPyramid::may_rise_at_any_azimuth`]) is at least each one's and below the
    /// same ceilings. Where the bound lies below a band's foot,
    /// `horizons_against` answers `Below` without a march, and the f64 march, stops and
    /// all, finds the horizon there too (below the foot or at it, which hide none of a disk
    /// alike).
    #[test]
    fn no_step_climbs_more_steeply_than_the_levels_slopes() {
        // A field's heights by sample column and row (9/44 apart along x, 6/30 along y).
        type Heights = fn(f32, f32) -> f32;
        let fields: [(&str, Heights, f64); 3] = [
            ("bumpy", |x, y| bumps(x, y) + 50.0, f64::INFINITY),
            ("gentle", |x, y| 0.05 * bumps(x, y) + 50.0, 0.3),
            ("plane", |x, y| 0.4 * (9.0 / 44.0) * x + 0.25 * (6.0 / 30.0) * y + 50.0, 0.65 + 1e-3),
        ];
        let mut answered_early = 0;
        for (name, height, steepest) in fields {
            let (field, points) = test_field(height);
            let pyramid = HorizonPyramid::new(&field, HorizonSettings::default()).unwrap();
            for k in 0..24 {
                let dir = (k as f64 * std::f64::consts::TAU / 24.0 + 0.1).sin_cos();
                let dir = [dir.1, dir.0];
                let bound = pyramid.steepest_climb(dir);
                assert!(bound < steepest, "{name}: climbs {bound} along {dir:?}");
                // The hull's corners give the steepest cell of any level read, within the
                // buckets' width.
                let read = |l: usize| pyramid.steps.iter().any(|step| step.level == l);
                let cells = pyramid
                    .levels
                    .iter()
                    .enumerate()
                    .filter(|&(l, _)| read(l))
                    .flat_map(|(_, level)| cell_slopes(level));
                let steepest_cell = cells.map(|[a, b]| a * dir[0].abs() + b * dir[1].abs()).fold(0.0, f64::max);
                let rounding = pyramid.climbs.get().expect("made by steepest_climb").rounding;
                assert!(
                    steepest_cell + rounding <= bound,
                    "{name} {dir:?}: a cell climbs {steepest_cell}, above {bound}"
                );
                assert!(
                    bound <= steepest_cell * (1.0 + 1e-6) + rounding + 1e-12,
                    "{name} {dir:?}: {bound} for {steepest_cell}"
                );
                let mut steepest_step = f64::NEG_INFINITY;
                for &p in &points {
                    let marched = every_step_tangent(&pyramid, p, dir, f64::INFINITY);
                    assert!(marched <= bound, "{name} {p:?} {dir:?}: a step climbs {marched}, above {bound}");
                    steepest_step = steepest_step.max(marched);
                    #[cfg(target_arch = "x86_64")]
                    if pyramid.in_lanes {
                        let lane = lanes_every_step(&pyramid, p, dir, pyramid.steps.len());
                        assert!(lane <= bound, "{name} {p:?} {dir:?}: a lane's step climbs {lane}, above {bound}");
                    }
                }
                if name == "plane" && dir[0] > 0.0 && dir[1] > 0.0 {
                    assert!(steepest_step >= 0.9 * bound, "{dir:?}: {steepest_step} against {bound}");
                }
                // Any azimuth's bound is at least this one's, and within the field's ceiling.
                let any_azimuth = pyramid.climb_bound(|[a, b]| a.hypot(*b));
                assert!(bound <= any_azimuth && any_azimuth < steepest, "{name} {dir:?}: {bound}, {any_azimuth}");
                let foot = |below: f64| ElevationBand { below, above: f64::INFINITY };
                assert!(pyramid.may_rise_at_any_azimuth(foot(bound)), "{name} {dir:?}");
                assert!(!pyramid.may_rise_at_any_azimuth(foot(any_azimuth * (1.0 + 1e-9))), "{name}");
                let band = ElevationBand { below: bound * (1.0 + 1e-9), above: f64::INFINITY };
                let mut early = vec![HorizonAgainst::At(-1.0); points.len()];
                pyramid.horizons_against(&points, dir, f64::INFINITY, band, &mut early);
                assert!(early.iter().all(|&h| h == HorizonAgainst::Below), "{name} {dir:?}: {early:?}");
                for &p in &points {
                    let lift = (p[2] - pyramid.height_at(p[0], p[1])).max(0.0);
                    match pyramid.march(p[0], p[1], lift, &mut ReceiverTerms::new(), dir, f64::INFINITY, band) {
                        HorizonAgainst::Below => {}
                        HorizonAgainst::At(horizon) => assert!(horizon.tan() <= band.below, "{name} {p:?} {dir:?}"),
                        HorizonAgainst::Above => panic!("{name} {p:?} {dir:?}: marched above the band"),
                    }
                }
                answered_early += 1;
            }
        }
        assert_eq!(answered_early, 72);
    }

    /// The horizons found along the W azimuths, kept as their sectors' highest, bound every
    /// step along any other azimuth ([`HorizonsBetween`]): the f64 march's and the lanes'
    /// largest step tangents, from points on, just above, above and outside a bumpy field
    /// and a gentle one, along 48 azimuths between the W = 16, are at most the bound, and a
    /// march against a band whose foot is the bound finds the horizon at or below it. On
    /// the gentle field (climbing at most 0.3, every azimuth within 11.25 deg of one of the
    /// W) the bound is within 0.25 of the steepest step (0.064 from all sixteen azimuths).
    /// Kept as quarters (frames written before sixteen sectors), they bound it too. A point
    /// that is not finite, horizons of another count, one not a number and the B-spline
    /// over scale bound nothing, nor do 0 sectors or more than W; a sector with a horizon
    /// not a number keeps it.
    #[test]
    fn the_horizons_found_bound_those_between_their_azimuths() {
        for (name, scale) in [("bumpy", 1.0f32), ("gentle", 0.05)] {
            let (field, points) = test_field(|x, y| scale * bumps(x, y) + 50.0);
            let pyramid = HorizonPyramid::new(&field, HorizonSettings::default()).unwrap();
            let (w, sectors) = (pyramid.directions().len(), pyramid.horizon_sectors());
            assert_eq!((w, sectors), (16, HORIZON_SECTORS));
            let mut loosest = 0.0f64;
            for k in 0..48 {
                let dir = (k as f64 * std::f64::consts::TAU / 48.0 + 0.05).sin_cos();
                let dir = [dir.1, dir.0];
                let between = pyramid.horizons_between(dir, sectors).expect("the steps' maximum");
                let between_quarters = pyramid.horizons_between(dir, 4).expect("four sectors of sixteen");
                let mut bounds = Vec::with_capacity(points.len());
                for &p in &points {
                    let mut tangents = [0.0f64; 64];
                    pyramid.horizon_tangents(p, &mut tangents[..w]);
                    let mut found = vec![0.0f32; sectors];
                    pyramid.sector_maxima(&tangents[..w], &mut found);
                    for (k, &tangent) in tangents[..w].iter().enumerate() {
                        assert!(f64::from(found[k * sectors / w]) >= tangent, "{name} {p:?}: sector of azimuth {k}");
                    }
                    let bound = between.tangent_at_most(p, &found);
                    // At the bound, just above it (the next f64, the bound being > 0), and two feet.
                    for foot in [bound, f64::from_bits(bound.to_bits() + 1), 0.3, 0.0] {
                        assert_eq!(between.under(foot).holds(p, &found), bound < foot, "{name} {p:?}: {foot}");
                    }
                    let marched = every_step_tangent(&pyramid, p, dir, f64::INFINITY);
                    assert!(marched <= bound, "{name} {p:?} {dir:?}: a step climbs {marched}, above {bound}");
                    loosest = loosest.max(bound - marched.max(0.0));
                    // Kept as quarters, as frames were before sixteen sectors: the highest of
                    // each run of four azimuths bounds the march too, less tightly.
                    let quarters: Vec<f32> = found
                        .chunks(sectors / 4)
                        .map(|run| run.iter().copied().fold(f32::NEG_INFINITY, f32::max))
                        .collect();
                    let by_quarters = between_quarters.tangent_at_most(p, &quarters);
                    assert!(marched <= by_quarters && bound <= by_quarters, "{name} {p:?} {dir:?}: {by_quarters}");
                    #[cfg(target_arch = "x86_64")]
                    if pyramid.in_lanes {
                        let lane = lanes_every_step(&pyramid, p, dir, pyramid.steps.len());
                        assert!(lane <= bound, "{name} {p:?} {dir:?}: a lane's step climbs {lane}, above {bound}");
                    }
                    bounds.push(bound);
                }
                for (&p, &bound) in points.iter().zip(&bounds) {
                    let band = ElevationBand { below: bound, above: f64::INFINITY };
                    match pyramid.horizon_against(p, dir, f64::INFINITY, band) {
                        HorizonAgainst::Below => {}
                        HorizonAgainst::At(horizon) => assert!(horizon.tan() <= bound, "{name} {p:?} {dir:?}"),
                        HorizonAgainst::Above => panic!("{name} {p:?} {dir:?}: marched above the bound"),
                    }
                }
            }
            if name == "gentle" {
                assert!(loosest < 0.25, "the gentle field's bound is {loosest} above a horizon");
            }
            let between = pyramid.horizons_between([1.0, 0.0], sectors).unwrap();
            let (p, flat) = (points[0], vec![0.0f32; sectors]);
            assert!(between.tangent_at_most(p, &flat).is_finite());
            assert_eq!(between.tangent_at_most([f64::NAN, 0.0, 0.0], &flat), f64::INFINITY);
            assert_eq!(between.tangent_at_most(p, &flat[1..]), f64::INFINITY);
            let mut not_a_number = flat.clone();
            not_a_number.fill(f32::NAN);
            assert_eq!(between.tangent_at_most(p, &not_a_number), f64::INFINITY);
            let under = between.under(f64::INFINITY);
            assert!(under.holds(p, &flat) && !under.holds(p, &flat[1..]) && !under.holds(p, &not_a_number));
            assert!(!under.holds([f64::NAN, 0.0, 0.0], &flat));
            let mut kept = vec![0.0f32; sectors];
            let first_not_a_number: Vec<f64> = (0..w).map(|k| if k == 0 { f64::NAN } else { 0.1 }).collect();
            pyramid.sector_maxima(&first_not_a_number, &mut kept);
            assert!(kept[0].is_nan() && kept[1..].iter().all(|&t| t >= 0.1), "{kept:?}");
            let bspline = HorizonSettings { scale_max: ScaleMax::BSpline, ..HorizonSettings::default() };
            assert!(HorizonPyramid::new(&field, bspline).unwrap().horizons_between([1.0, 0.0], sectors).is_none());
            assert!(
                pyramid.horizons_between([1.0, 0.0], 0).is_none() && pyramid.horizons_between([1.0, 0.0], 17).is_none()
            );
        }
    }

    /// `f32_at_least` is the least f32 at or above an f64.
    #[test]
    fn f32_at_least_rounds_up() {
        for x in [0.0f64, 1e-300, 0.1, 1.0 / 3.0, 0.7, 1e10, 3.5e38, 1e300] {
            let up = f32_at_least(x);
            assert!(f64::from(up) >= x, "{x} -> {up}");
            assert!(up == 0.0 || f64::from(-next_up(-up)) < x, "{x} -> {up}: a smaller f32 holds it");
        }
        assert_eq!(f32_at_least(0.5), 0.5);
        assert_eq!(f32_at_least(f64::INFINITY), f32::INFINITY);
        assert!(f32_at_least(f64::NAN).is_nan());
    }

    /// `next_up` steps to the adjacent f32: above `x`, with nothing between.
    #[test]
    fn next_up_is_the_least_f32_above() {
        for x in [0.0f32, -0.0, 1e-45, -1e-45, 1.0, -1.0, 0.7, -3.3e7, f32::MAX, f32::NEG_INFINITY] {
            let up = next_up(x);
            assert!(up > x, "{x} -> {up}");
            let between = ((f64::from(x) + f64::from(up)) / 2.0) as f32;
            assert!(x == f32::MAX || x == f32::NEG_INFINITY || between == x || between == up, "{x} -> {up}");
        }
        assert_eq!(next_up(f32::NEG_INFINITY), -f32::MAX);
        assert_eq!(next_up(f32::INFINITY), f32::INFINITY);
        assert!(next_up(f32::NAN).is_nan());
    }

    /// One azimuth's march from many receivers in lanes ([`HorizonPyramid::horizons_against`],
    /// where the processor has AVX2): its stops change no bit of a lane's tangent marched
    /// over every step; a receiver gets the same bits alone as among others, whichever lanes
    /// it shares; and the horizon is the f64 march's within 1e-5 rad. Points on, above and
    /// outside a bumpy field, 24 azimuths, three reaches, four bands, each kind of stop seen.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_lanes_march_one_azimuth_from_many_receivers() {
        let (pyramid, points) = bumpy_field_and_points();
        if !pyramid.in_lanes {
            eprintln!("skipped: the processor lacks AVX2 or FMA");
            return;
        }
        let bits = |a: HorizonAgainst| match a {
            HorizonAgainst::Below => (0, 0),
            HorizonAgainst::Above => (1, 0),
            HorizonAgainst::At(h) => (2, h.to_bits()),
        };
        let bands = [(0.0, 0.05), (0.1, 0.3), (0.5, 0.9), (1.0, 1.4)];
        let (mut below, mut above, mut at, mut worst) = (0, 0, 0, 0.0f64);
        for k in 0..24 {
            let dir = (k as f64 * std::f64::consts::TAU / 24.0).sin_cos();
            let dir = [dir.1, dir.0];
            for reach in [f64::INFINITY, 2.0, 0.3] {
                let every: Vec<f64> = points
                    .iter()
                    .map(|&p| {
                        lanes_every_step(&pyramid, p, dir, pyramid.steps_within(reach))
                            .max(lowest_horizon(reach))
                            .atan()
                    })
                    .collect();
                for (p, every) in points.iter().zip(&every) {
                    worst = worst.max((every - march_every_step(&pyramid, *p, dir, reach)).abs());
                }
                for band in [ElevationBand::ALL]
                    .into_iter()
                    .chain(bands.map(|(low, high)| ElevationBand { below: f64::tan(low), above: f64::tan(high) }))
                {
                    let mut together = vec![HorizonAgainst::Below; points.len()];
                    pyramid.horizons_against(&points, dir, reach, band, &mut together);
                    // Alone, and among others in another grouping (every third left out).
                    let alone: Vec<HorizonAgainst> =
                        points.iter().map(|&p| pyramid.horizon_against(p, dir, reach, band)).collect();
                    let thirds: Vec<[f64; 3]> = points.iter().copied().skip(1).step_by(3).collect();
                    let mut regrouped = vec![HorizonAgainst::Below; thirds.len()];
                    pyramid.horizons_against(&thirds, dir, reach, band, &mut regrouped);
                    for (i, (got, every)) in together.iter().zip(&every).enumerate() {
                        assert_eq!(bits(*got), bits(alone[i]), "{:?} {dir:?}", points[i]);
                        if i % 3 == 1 {
                            assert_eq!(bits(*got), bits(regrouped[i / 3]), "{:?} {dir:?}", points[i]);
                        }
                        match *got {
                            HorizonAgainst::Below => {
                                assert!(*every <= band.below.atan() + 1e-12, "{every} is above the band");
                                below += 1;
                            }
                            HorizonAgainst::Above => {
                                assert!(*every >= band.above.atan() - 1e-12, "{every} is below the band");
                                above += 1;
                            }
                            HorizonAgainst::At(horizon) => {
                                assert_eq!(horizon.to_bits(), every.to_bits(), "{:?} {dir:?}", points[i]);
                                at += 1;
                            }
                        }
                    }
                }
            }
        }
        assert!(below > 0 && above > 0 && at > 0, "below {below}, above {above}, at {at}");
        assert!(worst < 1e-5, "worst horizon difference {worst} rad");
        eprintln!("worst horizon difference between one azimuth's lanes and the f64 march: {worst:.1e} rad");
    }

    /// The receivers of one azimuth's lanes, four points per instruction, against the
    /// scalar height read and step search, bit for bit: points on, above, outside and at
    /// the edges of a bumpy field and of a field of one row, groups of one to eight, 26
    /// azimuths (the axes among them, where `dir` has a zero) and three reaches.
    #[test]
    fn the_lanes_receivers_are_the_scalar_ones() {
        let (bumpy, mut points) = bumpy_field_and_points();
        if !bumpy.in_lanes {
            eprintln!("skipped: the processor lacks AVX2 or FMA");
            return;
        }
        points.extend([[-4.0, -3.0, 50.0], [5.0, 3.0, 49.0], [5.0, -3.0, 60.0], [-4.0, 3.0, 0.0], [0.5, 0.0, 1e6]]);
        let row: Vec<f32> = (0..23).map(|i| (0.4 * i as f32).sin() + 0.1 * i as f32).collect();
        let one_row = HeightField::new(row, 23, 1, [-2.0, 1.0], [3.0, 2.0]).unwrap();
        let one_row = HorizonPyramid::new(&one_row, HorizonSettings::default()).unwrap();
        let mut compared = 0;
        for pyramid in [&bumpy, &one_row] {
            let azimuths = (0..24).map(|k| (k as f64 * std::f64::consts::TAU / 24.0 + 0.1).sin_cos());
            let dirs: Vec<[f64; 2]> = azimuths.map(|(s, c)| [c, s]).chain([[1.0, 0.0], [0.0, -1.0]]).collect();
            for dir in dirs {
                for reach in [f64::INFINITY, 2.0, 0.3] {
                    let within = pyramid.steps_within(reach);
                    for count in 1..=8 {
                        for group in points.chunks(count) {
                            let mut got = [lanes::AlongReceiver { x: 0.0, y: 0.0, above: -1.0, taken: 0 }; 8];
                            // SAFETY: the pyramid marches in lanes, so the processor has AVX2 and FMA.
                            assert!(unsafe { lanes::along_receivers(pyramid, group, dir, within, &mut got) });
                            for (p, got) in group.iter().zip(&got) {
                                let above = (p[2] - pyramid.height_at(p[0], p[1])).max(0.0);
                                let taken = pyramid.steps_marched(p[0], p[1], dir, within);
                                assert_eq!((got.x, got.y), (p[0], p[1]));
                                assert_eq!(got.above.to_bits(), above.to_bits(), "{p:?} {dir:?}");
                                assert_eq!(got.taken, taken, "{p:?} {dir:?} {reach}");
                                compared += 1;
                            }
                        }
                    }
                }
            }
        }
        assert!(compared > 10_000, "{compared} receivers compared");
    }

    /// The eight-lane march (where the processor has AVX2) against the f64 march, azimuth by
    /// azimuth: points on and above a bumpy field, outside it, near its edges, and on a map
    /// with one row, at 16 and at 13 azimuths (a part-filled last chunk).
    #[test]
    fn the_lanes_march_as_the_f64_march_does() {
        let (columns, rows) = (37, 29);
        let heights: Vec<f32> = (0..columns * rows)
            .map(|i| {
                let (x, y) = ((i % columns) as f32, (i / columns) as f32);
                3.0 * (0.7 * x).sin() * (0.4 * y).cos() + 0.05 * x + 100.0
            })
            .collect();
        let field = HeightField::new(heights, columns, rows, [-3.0, -2.0], [4.0, 3.0]).unwrap();
        let strip =
            HeightField::new((0..9).map(|i| (i as f32 * 0.9).sin()).collect(), 9, 1, [0.0, 0.0], [2.0, 0.5]).unwrap();
        let mut worst = 0.0f64;
        for (field, points) in [
            (
                &field,
                vec![
                    (0.1, 0.2, 0.0),
                    (-2.9, 2.95, 0.0),
                    (3.0, -1.5, 0.3),
                    (0.7, 2.9, 2.0),
                    (6.0, 0.0, 0.1),
                    (-40.0, 9.0, 0.0),
                ],
            ),
            (&strip, vec![(1.0, 0.25, 0.0), (0.05, 0.0, 0.2), (3.0, 1.0, 0.0)]),
        ] {
            for directions in [16, 13, 5, 40] {
                let settings = HorizonSettings { directions, ..HorizonSettings::default() };
                let pyramid = HorizonPyramid::new(field, settings).unwrap();
                for &(x, y, lift) in &points {
                    let p = [x, y, field.height_at(x, y) + lift];
                    let mut got = vec![0.0; directions];
                    pyramid.horizon_elevations(p, &mut got);
                    let mut receiver = ReceiverTerms::new();
                    let above = (p[2] - pyramid.height_at(x, y)).max(0.0);
                    for (k, g) in got.iter().enumerate() {
                        let expected = pyramid
                            .march(x, y, above, &mut receiver, pyramid.directions[k], f64::INFINITY, ElevationBand::ALL)
                            .elevation();
                        worst = worst.max((g - expected).abs());
                    }
                }
            }
        }
        assert!(worst < 1e-5, "worst horizon difference {worst} rad");
        eprintln!("worst horizon difference between the lanes and the f64 march: {worst:.1e} rad");
    }

    /// Both builds of the lanes' march (`crate::x86`), where the processor runs both, give
    /// the same horizons bit for bit, and the scratch arrays' two sizes too.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn both_builds_of_the_lanes_march_agree() {
        if !(lanes::available(&[]) && *crate::x86::WIDE_REGISTERS) {
            eprintln!("skipped: the processor lacks AVX2, FMA, AVX-512F or AVX-512VL");
            return;
        }
        let (columns, rows) = (41, 33);
        let heights: Vec<f32> = (0..columns * rows)
            .map(|i| {
                let (x, y) = ((i % columns) as f32, (i / columns) as f32);
                2.0 * (0.5 * x).sin() * (0.3 * y).cos() + 0.4 * (1.3 * x + 0.7 * y).sin()
            })
            .collect();
        let field = HeightField::new(heights, columns, rows, [-4.0, -3.0], [4.0, 3.0]).unwrap();
        let mut raised = 0;
        for directions in [16, 7, 33] {
            let pyramid =
                HorizonPyramid::new(&field, HorizonSettings { directions, ..HorizonSettings::default() }).unwrap();
            for &(x, y, above) in &[(0.3, -0.2, 0.0), (3.9, 2.5, 0.05), (-3.0, 1.0, 0.4), (9.0, -7.0, 0.0)] {
                let mut results = [[0.0f64; 40]; 4];
                // SAFETY: AVX2, FMA, AVX-512F and AVX-512VL were checked above.
                unsafe {
                    lanes::horizons_within::<64, 64, 128>(&pyramid, x, y, above, false, &mut results[0][..directions]);
                    lanes::horizons_within::<64, 64, 128>(&pyramid, x, y, above, true, &mut results[1][..directions]);
                    lanes::horizons_within::<MAX_LEVELS, 1024, MAX_STEPS>(
                        &pyramid,
                        x,
                        y,
                        above,
                        false,
                        &mut results[2][..directions],
                    );
                    lanes::horizons_within::<MAX_LEVELS, 1024, MAX_STEPS>(
                        &pyramid,
                        x,
                        y,
                        above,
                        true,
                        &mut results[3][..directions],
                    );
                }
                for other in &results[1..] {
                    assert_eq!(results[0], *other, "at ({x}, {y}) with {directions} azimuths");
                }
                raised += results[0][..directions].iter().filter(|&&t| t > 0.0).count();
            }
        }
        assert!(raised > 0, "no horizon above the plane");
    }
}
