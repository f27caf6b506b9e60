//! The height map of the terrain, read raw and validated; horizons are built elsewhere.
//!
//! Layout (`docs/design.md`): sample `(i, j)` (column `i`, row `j`) of a `columns x rows` map
//! lies at `min + (max - min) * (i / (columns - 1), j / (rows - 1))` (corner-registered);
//! row 0 is the first scan line of the EXR file and lies at `min.y`. Beyond the
//! rectangle the terrain continues flat at the height of its nearest edge sample.

use super::error::SceneError;
use super::exr_read::ExrChannels;
use std::path::Path;

/// How far below a height map, in sample spacings, a G-buffer's surface may lie before
/// it is counted as buried ([`HeightMap::buried_share`]).
pub const BURIED_DEPTH: f64 = 1.0;

/// The largest share of a frame's surface pixels that may lie buried under its height
/// map: beyond it the map is not the frame's terrain ([`HeightMap::buried_share`]).
pub const MOST_BURIED: f64 = 0.1;

/// A corner-registered height map over the rectangle `min..max` in world XY.
#[derive(Clone, Debug, PartialEq)]
pub struct HeightMap {
    /// `heights[row * columns + column]`, world Z.
    pub heights: Vec<f32>,
    pub columns: usize,
    pub rows: usize,
    pub min: [f64; 2],
    pub max: [f64; 2],
}

impl HeightMap {
    /// Reads a one-channel EXR, or the channel `channel` of any EXR. Every sample must be
    /// finite, `min < max` on both axes, and the map at least 2 x 2.
    pub fn read(file: &Path, channel: Option<&str>, min: [f64; 2], max: [f64; 2]) -> Result<HeightMap, SceneError> {
        let mut exr = ExrChannels::read(file, "the height map")?;
        let name = match channel {
            Some(c) => c.to_string(),
            None => {
                if exr.directory.names.len() != 1 {
                    return Err(SceneError::invalid(
                        file,
                        format!(
                            "the height map has {} channels ({}); name one with \"channel\" in the heightfield object",
                            exr.directory.names.len(),
                            exr.directory.names.join(", ")
                        ),
                    ));
                }
                exr.directory.names[0].clone()
            }
        };
        exr.use_size_of(&name);
        let heights = exr.take(file, &name)?;
        let map = HeightMap { heights, columns: exr.width, rows: exr.height, min, max };
        map.validate(file)?;
        Ok(map)
    }

    fn validate(&self, file: &Path) -> Result<(), SceneError> {
        if self.columns < 2 || self.rows < 2 {
            return Err(SceneError::invalid(
                file,
                format!("the height map is {}x{}; it needs at least 2x2 samples", self.columns, self.rows),
            ));
        }
        if !(self.min[0] < self.max[0] && self.min[1] < self.max[1]) {
            return Err(SceneError::invalid(file, format!("min {:?} must be below max {:?}", self.min, self.max)));
        }
        if let Some(i) = self.heights.iter().position(|h| !h.is_finite()) {
            return Err(SceneError::NonFinite {
                file: file.to_path_buf(),
                what: format!("height sample (column {}, row {})", i % self.columns, i / self.columns),
            });
        }
        Ok(())
    }

    /// Samples `f(x, y)` on the corner-registered grid.
    pub fn from_fn(
        columns: usize,
        rows: usize,
        min: [f64; 2],
        max: [f64; 2],
        f: impl Fn(f64, f64) -> f64,
    ) -> HeightMap {
        let mut heights = Vec::with_capacity(columns * rows);
        for j in 0..rows {
            for i in 0..columns {
                let (x, y) = Self::sample_xy(columns, rows, min, max, i, j);
                heights.push(f(x, y) as f32);
            }
        }
        HeightMap { heights, columns, rows, min, max }
    }

    fn sample_xy(columns: usize, rows: usize, min: [f64; 2], max: [f64; 2], i: usize, j: usize) -> (f64, f64) {
        (
            min[0] + (max[0] - min[0]) * i as f64 / (columns - 1) as f64,
            min[1] + (max[1] - min[1]) * j as f64 / (rows - 1) as f64,
        )
    }

    /// Spacing of the samples in x and y.
    pub fn cell_size(&self) -> [f64; 2] {
        [(self.max[0] - self.min[0]) / (self.columns - 1) as f64, (self.max[1] - self.min[1]) / (self.rows - 1) as f64]
    }

    /// Bilinear height at world `(x, y)`, clamped to the edge beyond the rectangle: the
    /// same interpolant the horizon march and the reference see
    /// ([`crate::heightfield::HeightField::height_at`]).
    pub fn height_at(&self, x: f64, y: f64) -> f64 {
        crate::heightfield::bilinear(&self.heights, self.columns, self.rows, self.min, self.max, x, y)
    }

    /// The share of the surface pixels of `gbuffer` over the map's rectangle that lie
    /// more than [`BURIED_DEPTH`] sample spacings below it: none can, where the map is
    /// the frame's terrain (an opaque surface hides what lies under it from a camera
    /// above). The exported canyon's steep walls, whose mesh the bilinear map cuts
    /// corners of, reach 0.63 spacings below it; a swell exported as it was on another
    /// frame puts 37 to 53 % of its pixels deeper. `None` without such pixels.
    pub fn buried_share(&self, gbuffer: &super::GBuffer) -> Option<f64> {
        let (pixels, buried) = self.buried_pixels(gbuffer);
        (pixels > 0).then(|| buried as f64 / pixels as f64)
    }

    /// The surface pixels of `gbuffer` over the map, and how many of them lie buried
    /// ([`Self::buried_share`]).
    pub fn buried_pixels(&self, gbuffer: &super::GBuffer) -> (usize, usize) {
        let depth = BURIED_DEPTH * self.cell_size()[0].max(self.cell_size()[1]);
        let over = |p: &[f32; 3]| {
            let [x, y] = [f64::from(p[0]), f64::from(p[1])];
            (self.min[0]..=self.max[0]).contains(&x) && (self.min[1]..=self.max[1]).contains(&y)
        };
        let (mut pixels, mut buried) = (0usize, 0usize);
        for (p, _) in gbuffer.position.iter().zip(&gbuffer.material).filter(|&(p, &m)| m != 0 && over(p)) {
            pixels += 1;
            buried += usize::from(self.height_at(f64::from(p[0]), f64::from(p[1])) - f64::from(p[2]) > depth);
        }
        (pixels, buried)
    }

    /// Lowest and highest sample.
    pub fn range(&self) -> (f64, f64) {
        let lo = self.heights.iter().fold(f32::INFINITY, |a, &b| a.min(b)) as f64;
        let hi = self.heights.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b)) as f64;
        (lo, hi)
    }
}
