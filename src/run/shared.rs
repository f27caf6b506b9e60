//! What several commands share: the output directory they create, and how a sun taken
//! out of a map is described.

use anyhow::{Context, Result};
use std::path::Path;

/// Where a sun taken out of a map is, its width and its share of the map's light.
pub(super) fn describe_sun(sun: &crate::scene::SunLight, share: f64) -> String {
    let [azimuth, elevation] = sun.azimuth_elevation();
    format!(
        "azimuth {azimuth:.1} deg, elevation {elevation:.1} deg, {:.2} deg wide, {:.0}% of its light",
        2.0 * sun.half_angle.to_degrees(),
        100.0 * share
    )
}

/// An output directory, created if it is not there; one created for a run that then
/// wrote nothing into it (its first frame refused) is removed again when this is dropped.
pub(super) struct CreatedDirectory<'a>(Option<&'a Path>);

impl<'a> CreatedDirectory<'a> {
    pub(super) fn new(dir: &'a Path) -> Result<Self> {
        let created = !dir.exists();
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create output directory {}", dir.display()))?;
        Ok(Self(created.then_some(dir)))
    }
}

impl Drop for CreatedDirectory<'_> {
    fn drop(&mut self) {
        // Removes an empty directory only.
        if let Some(dir) = self.0 {
            let _ = std::fs::remove_dir(dir);
        }
    }
}
