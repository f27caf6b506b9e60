//! Height-field horizons: the geometry half of the height-field log visibility
//! (docs/design.md, "Pipeline per pixel", step 2).
//!
//! # Conventions
//!
//! - World space is Blender's: right-handed, Z up. The height field lies over the
//!   axis-aligned rectangle `min..max` in XY; heights are world Z.
//! - The height map holds `columns x rows` f32 samples, row-major, first row at
//!   `min.y`, first column at `min.x`, corner-registered: sample (i = column, j = row)
//!   sits at `min + (max - min) * (i / (columns - 1), j / (rows - 1))`
//!   (docs/design.md, "Scene format v1"). A map with one column (or one row) is constant
//!   across x (or y); a 1x1 map is an infinite plane.
//! - The level-0 surface is the **bilinear** interpolant of the samples
//!   ([`HeightField::height_at`]). Bilinear is exact at the samples, is what a
//!   quad mesh built from the map looks like up to the choice of triangle diagonal,
//!   and makes the exact reference [`brute_force_horizon`] cheap (the surface along a
//!   ray is piecewise quadratic).
//! - Beyond the rectangle the terrain continues flat: the query coordinate is clamped
//!   to the rectangle ("clamp to edge"), so outside it the height is the height of the
//!   nearest point of the rectangle's border.
//! - Azimuths phi are measured from +X towards +Y; azimuth k of W is
//!   `phi_k = 2 pi k / W`.
//! - A *horizon elevation* sigma is the angle from the horizontal plane up to the
//!   highest terrain point seen along an azimuth: directions with elevation below
//!   sigma (polar angle theta from +Z greater than `pi/2 - sigma`) are blocked.
//!   Because the terrain continues flat to infinity, the horizon seen from a point on
//!   or above the terrain is never below 0 (far away, the flat continuation is seen
//!   at an elevation tending to 0), so horizons lie in `[0, pi/2)`. This is also why
//!   SN08 (Section 4, after Eq. 5) may clamp its estimate at 0 without losing anything.
//!
//! # Contents
//!
//! - [`HeightField`]: the validated level-0 samples and the level-0 surface.
//! - [`HorizonPyramid`]: the multi-resolution horizon search of Snyder &
//!   Nowrouzezahrai 2008 (SN08, Sections 4 and 6), the fast path used for shading.
//! - [`brute_force_horizon`]: the exact horizon of the level-0 surface, for tests and
//!   for the ground-truth renderer.

mod pyramid;
mod reference;

pub use pyramid::{
    decimation_taps, lowest_horizon, ElevationBand, HorizonAgainst, HorizonPyramid, HorizonSettings, HorizonsBetween,
    HorizonsUnder, LevelReconstruction, MarchStep, PyramidLevel, PyramidPlan, ScaleMax, HORIZON_SECTORS, MAX_LEVELS,
    MAX_STEPS,
};
pub use reference::{brute_force_horizon, horizon_reaches, horizon_reaches_within};

/// What can be wrong with a height map or with horizon settings.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HeightFieldError {
    /// A size of zero (docs/design.md requires at least one sample).
    #[error("height map is {columns} x {rows}: it needs at least one column and one row")]
    EmptyMap { columns: usize, rows: usize },
    /// The sample vector does not have `columns * rows` entries.
    #[error("height map has {len} samples but is declared {columns} x {rows} ({expected} samples)")]
    SizeMismatch { columns: usize, rows: usize, expected: usize, len: usize },
    /// A NaN or infinite height.
    #[error("height map sample at column {column}, row {row} is not finite ({value})")]
    NonFiniteHeight { column: usize, row: usize, value: f32 },
    /// `min` / `max` are not finite, or `min >= max` on an axis.
    #[error(
        "height field rectangle min {min:?} .. max {max:?} is invalid: both must be finite with min < max on x and y"
    )]
    BadRectangle { min: [f64; 2], max: [f64; 2] },
    /// A [`HorizonSettings`] field out of its range.
    #[error("horizon setting `{name}` = {value} is out of range: {expected}")]
    BadSetting { name: &'static str, value: f64, expected: &'static str },
    /// The map is so large (or `level_step` so high) that the march would exceed the
    /// fixed step budget that keeps queries allocation-free.
    #[error(
        "height map needs {needed} {what}, more than the supported {limit}: lower `level_step` or the map resolution"
    )]
    TooLarge { what: &'static str, needed: usize, limit: usize },
}

/// A validated height map: level-0 samples and the rectangle they cover.
#[derive(Debug, Clone)]
pub struct HeightField {
    heights: Vec<f32>,
    columns: usize,
    rows: usize,
    min: [f64; 2],
    max: [f64; 2],
    /// The highest sample: no point of the surface is above it.
    highest: f64,
}

impl HeightField {
    /// Validates and wraps a height map (conventions in the module doc).
    ///
    /// Errors: zero `columns` or `rows`, `heights.len() != columns * rows`, a
    /// non-finite height, or a rectangle that is not finite with `min < max` on both
    /// axes (also for 1xN maps: the rectangle still says where the map lies).
    pub fn new(
        heights: Vec<f32>,
        columns: usize,
        rows: usize,
        min: [f64; 2],
        max: [f64; 2],
    ) -> Result<Self, HeightFieldError> {
        if columns == 0 || rows == 0 {
            return Err(HeightFieldError::EmptyMap { columns, rows });
        }
        let expected = columns.saturating_mul(rows);
        if heights.len() != expected {
            return Err(HeightFieldError::SizeMismatch { columns, rows, expected, len: heights.len() });
        }
        if let Some(index) = heights.iter().position(|h| !h.is_finite()) {
            return Err(HeightFieldError::NonFiniteHeight {
                column: index % columns,
                row: index / columns,
                value: heights[index],
            });
        }
        let rectangle_ok = (0..2).all(|a| min[a].is_finite() && max[a].is_finite() && min[a] < max[a]);
        if !rectangle_ok {
            return Err(HeightFieldError::BadRectangle { min, max });
        }
        let highest = heights.iter().fold(f64::NEG_INFINITY, |m, &h| m.max(f64::from(h)));
        Ok(Self { heights, columns, rows, min, max, highest })
    }

    /// Number of samples along x.
    pub fn columns(&self) -> usize {
        self.columns
    }

    /// Number of samples along y.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// World XY of sample (column 0, row 0).
    pub fn min(&self) -> [f64; 2] {
        self.min
    }

    /// World XY of sample (last column, last row).
    pub fn max(&self) -> [f64; 2] {
        self.max
    }

    /// The highest sample, which bounds the bilinear surface and its continuation.
    pub fn highest(&self) -> f64 {
        self.highest
    }

    /// The level-0 samples, row-major.
    pub fn heights(&self) -> &[f32] {
        &self.heights
    }

    /// World distance between neighbouring samples along x and y; 0 along an axis
    /// with a single sample (the map is constant along it).
    pub fn spacing(&self) -> [f64; 2] {
        let n = [self.columns, self.rows];
        std::array::from_fn(|a| if n[a] > 1 { (self.max[a] - self.min[a]) / (n[a] - 1) as f64 } else { 0.0 })
    }

    /// Surface height at world `(x, y)`: the bilinear interpolant of the samples,
    /// with the flat (clamp-to-edge) continuation outside the rectangle. Exact at the
    /// samples. A NaN coordinate gives NaN.
    pub fn height_at(&self, x: f64, y: f64) -> f64 {
        bilinear(&self.heights, self.columns, self.rows, self.min, self.max, x, y)
    }

    /// Unit upward normal of the surface at world `(x, y)`, from central differences of
    /// [`Self::height_at`] one sample spacing apart (+Z along an axis with one sample).
    pub fn normal_at(&self, x: f64, y: f64) -> [f64; 3] {
        let spacing = self.spacing();
        let (hx, hy) = (spacing[0].max(1e-9), spacing[1].max(1e-9));
        let dx = (self.height_at(x + hx, y) - self.height_at(x - hx, y)) / (2.0 * hx);
        let dy = (self.height_at(x, y + hy) - self.height_at(x, y - hy)) / (2.0 * hy);
        let length = (dx * dx + dy * dy + 1.0).sqrt();
        [-dx / length, -dy / length, 1.0 / length]
    }
}

/// Continuous grid coordinate of world coordinate `v` on an axis with `n` samples
/// over `[min, max]`, clamped to `[0, n - 1]` (the flat continuation).
#[inline]
pub(crate) fn grid_coordinate(v: f64, min: f64, max: f64, n: usize) -> f64 {
    if n <= 1 {
        return 0.0;
    }
    let last = (n - 1) as f64;
    ((v - min) / (max - min) * last).clamp(0.0, last)
}

/// Bilinear interpolation of a row-major grid at world `(x, y)`, clamped to the
/// rectangle. Shared by [`HeightField::height_at`] and the pyramid's level 0 so both
/// see the same surface.
#[inline]
pub(crate) fn bilinear(
    heights: &[f32],
    columns: usize,
    rows: usize,
    min: [f64; 2],
    max: [f64; 2],
    x: f64,
    y: f64,
) -> f64 {
    let u = grid_coordinate(x, min[0], max[0], columns);
    let v = grid_coordinate(y, min[1], max[1], rows);
    if u.is_nan() || v.is_nan() {
        return f64::NAN;
    }
    let (i0, fx) = cell(u, columns);
    let (j0, fy) = cell(v, rows);
    let i1 = (i0 + 1).min(columns - 1);
    let j1 = (j0 + 1).min(rows - 1);
    let h = |i: usize, j: usize| f64::from(heights[j * columns + i]);
    let bottom = h(i0, j0) + fx * (h(i1, j0) - h(i0, j0));
    let top = h(i0, j1) + fx * (h(i1, j1) - h(i0, j1));
    bottom + fy * (top - bottom)
}

/// Cell index and fraction of a clamped grid coordinate `u` in `[0, n - 1]`.
#[inline]
fn cell(u: f64, n: usize) -> (usize, f64) {
    if n <= 1 {
        return (0, 0.0);
    }
    let i = (u.floor() as usize).min(n - 2);
    (i, u - i as f64)
}
