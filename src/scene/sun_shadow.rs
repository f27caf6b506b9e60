//! A sun's shadow map (`"sun_shadows"` in `blockers.####.json`): the depth of the blocker
//! meshes themselves seen from the sun, orthographically, which shades that sun's
//! visibility in place of the blockers' sphere proxies ([`crate::shade::sun_shadow`]).
//!
//! An entry is `{"image": path, "axis": [x, y, z], "origin": [x, y, z], "right": [x, y,
//! z], "up": [x, y, z], "size": [w, h]}`:
//!
//! - `axis` points towards the sun, `right` and `up` span the map's plane, all three unit
//!   and orthogonal (within 1e-4);
//! - `origin` is the centre of the plane, which lies beyond every blocker towards the sun;
//! - `size` is the width and height the image spans along `right` and `up`, in metres;
//! - `image` (relative to the scene directory) holds two channels, `Z` and `Zfar`: texel
//!   `(i, j)` (column `i` from the `-right` edge, row `j` from the `+up` edge) has its
//!   centre at `origin + right ((i + 1/2)/nx - 1/2) w + up (1/2 - (j + 1/2)/ny) h`; `Z` is
//!   the distance along `-axis` from the plane to the first blocker surface met from
//!   there, `Zfar` to the last one (where the ray leaves the blockers for good); `Z` is
//!   at least [`NOTHING_BELOW`] where the ray meets none (Blender writes 1e10), and
//!   `Zfar` is then not read. Texels are square.
//!
//! The map serves the sun whose direction is within [`SAME_SUN_RADIANS`] of its `axis`
//! ([`SunShadowMap::serves`]): a sun turned further from it (`--light-rotation`, a
//! relight) takes its shadows from the proxies again.

use super::error::{check_image_size, SceneError};
use super::exr_read::ExrChannels;
use super::paths::check_inside;
use crate::vector::{cross, dot, normalize};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// A depth of at least this means no blocker surface along the texel's ray.
pub const NOTHING_BELOW: f32 = 1e9;

/// How far a sun may be from a map's axis and still take its shadows from the map (1
/// degree). A Sun lamp's map holds the lamp's direction to rounding; a sun logsh takes
/// out of an environment map was found there by the exporter too, by the same rule but
/// on the map before its Mapping rotation resamples it, which moves it by a fraction of
/// a texel at most (under 1e-4 degrees for a sun 2 degrees wide on a 512-wide map turned
/// by (20, 0, 70) degrees). A ray off the axis walks through the map sideways
/// ([`crate::shade::sun_shadow`]), so a sun turned within this takes the meshes' shadow
/// still; beyond it, the spheres'.
pub const SAME_SUN_RADIANS: f64 = std::f64::consts::PI / 180.0;

/// At most this many shadow maps a frame.
pub const MAX_SHADOW_MAPS: usize = 16;

/// One entry of `"sun_shadows"` as written.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SunShadowEntry {
    image: String,
    axis: [f64; 3],
    origin: [f64; 3],
    right: [f64; 3],
    up: [f64; 3],
    size: [f64; 2],
}

/// A sun's shadow map, read and checked.
#[derive(Clone, Debug)]
pub struct SunShadowMap {
    pub file: PathBuf,
    /// Unit, towards the sun.
    pub axis: [f64; 3],
    /// The centre of the map's plane.
    pub origin: [f64; 3],
    /// Unit, along the image's columns and (upwards) rows.
    pub right: [f64; 3],
    pub up: [f64; 3],
    /// Metres spanned along `right` and `up`.
    pub size: [f64; 2],
    pub columns: usize,
    pub rows: usize,
    /// `Z` per texel, row 0 the `+up` edge.
    pub depths: Vec<f32>,
    /// `Zfar` per texel.
    pub far_depths: Vec<f32>,
}

impl SunShadowMap {
    /// Reads entry `index` of `"sun_shadows"` in `blockers` (the frame's blockers file),
    /// its image relative to `dir`.
    pub fn read(entry: &SunShadowEntry, index: usize, blockers: &Path, dir: &Path) -> Result<Self, SceneError> {
        let key = format!("sun_shadows[{index}]");
        let vectors = [("axis", entry.axis), ("origin", entry.origin), ("right", entry.right), ("up", entry.up)];
        for (name, v) in vectors {
            if v.iter().any(|c| !c.is_finite()) {
                return Err(SceneError::NonFinite { file: blockers.to_path_buf(), what: format!("{key}.{name}") });
            }
        }
        let unit = |v: [f64; 3]| (dot(v, v).sqrt() - 1.0).abs() <= 1e-4;
        let handed = cross(entry.right, entry.up);
        let orthonormal = unit(entry.axis)
            && unit(entry.right)
            && unit(entry.up)
            && dot(entry.axis, entry.right).abs() <= 1e-4
            && dot(entry.axis, entry.up).abs() <= 1e-4
            && dot(entry.right, entry.up).abs() <= 1e-4
            && dot(handed, entry.axis) > 0.0;
        if !orthonormal {
            return Err(SceneError::invalid(
                blockers,
                format!("{key}: \"axis\", \"right\" and \"up\" must be unit, orthogonal and right x up = axis"),
            ));
        }
        if !entry.size.iter().all(|s| s.is_finite() && *s > 0.0) {
            return Err(SceneError::invalid(blockers, format!("{key}: \"size\" {:?} must be positive", entry.size)));
        }
        check_inside(blockers, dir, &format!("{key}.image"), &entry.image)?;
        let file = dir.join(&entry.image);
        let mut channels = ExrChannels::read(&file, "a sun's shadow map")?;
        let (columns, rows) = (channels.width, channels.height);
        check_image_size(&file, columns, rows)?;
        let depths = channels.take(&file, "Z")?;
        let far_depths = channels.take(&file, "Zfar")?;
        for (name, values) in [("Z", &depths), ("Zfar", &far_depths)] {
            if let Some(at) = values.iter().position(|z| !z.is_finite()) {
                return Err(SceneError::NonFinite {
                    file,
                    what: format!("{name} at texel ({}, {})", at % columns, at / columns),
                });
            }
        }
        let inverted = depths.iter().zip(&far_depths).position(|(z, far)| *z < NOTHING_BELOW && far < z);
        if let Some(at) = inverted {
            return Err(SceneError::invalid(
                &file,
                format!(
                    "texel ({}, {}): Zfar {} lies above Z {}",
                    at % columns,
                    at / columns,
                    far_depths[at],
                    depths[at]
                ),
            ));
        }
        let (texel_x, texel_y) = (entry.size[0] / columns as f64, entry.size[1] / rows as f64);
        if (texel_x / texel_y - 1.0).abs() > 1e-3 {
            return Err(SceneError::invalid(
                blockers,
                format!(
                    "{key}: texels of {texel_x} x {texel_y} m (size {:?} over {columns} x {rows} texels) are not square",
                    entry.size
                ),
            ));
        }
        // Unit to the rounding of f64, as the sun's direction is once read.
        Ok(Self {
            file,
            axis: normalize(entry.axis),
            origin: entry.origin,
            right: normalize(entry.right),
            up: normalize(entry.up),
            size: entry.size,
            columns,
            rows,
            depths,
            far_depths,
        })
    }

    /// The side of a texel, in metres.
    pub fn texel(&self) -> f64 {
        self.size[0] / self.columns as f64
    }

    /// Whether the map is the one of a sun towards unit `direction`.
    pub fn serves(&self, direction: [f64; 3]) -> bool {
        dot(self.axis, direction) >= SAME_SUN_RADIANS.cos()
    }
}

/// Reads every entry of a frame's `"sun_shadows"`.
pub fn read_sun_shadows(
    entries: &[SunShadowEntry],
    blockers: &Path,
    dir: &Path,
) -> Result<Vec<SunShadowMap>, SceneError> {
    if entries.len() > MAX_SHADOW_MAPS {
        return Err(SceneError::invalid(
            blockers,
            format!("{} sun shadow maps is more than the {MAX_SHADOW_MAPS} a frame may hold", entries.len()),
        ));
    }
    entries.iter().enumerate().map(|(i, entry)| SunShadowMap::read(entry, i, blockers, dir)).collect()
}
