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
//! (3.4x at k = 4, SN08 Section 4).
//!
//! A march with the maximum over steps stops once no later step can raise its horizon
//! (each level's highest and lowest samples bound its reads), and one along a single
//! azimuth, a sun's, once the horizon is known to lie below or above the disk
//! ([`HorizonPyramid::horizon_against`]); it then reads only the receiver terms of the
//! levels its steps reached. The horizons are the same to the bit.

use super::{bilinear, HeightField, HeightFieldError};
use rayon::prelude::*;
use std::sync::OnceLock;

mod filter;
mod plan;

use filter::{bspline_max, bspline_taps, bspline_weights, decimate, f32_at_least, next_up};
pub use plan::*;

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
    /// beside it, nor on whether it was marched with any).
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

// The march in AVX2 lanes ([`lanes`]).
#[cfg(target_arch = "x86_64")]
mod lanes;

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
