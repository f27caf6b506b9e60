//! The scene's colour management, as the PNG previews and the viewer apply it: Blender's
//! view transform (Standard, AgX, Filmic, ...), look, exposure and gamma, so that a
//! preview looks as Blender shows the same linear image.
//!
//! `scene.json`'s optional `view` object (the exporter writes it):
//!
//! ```json
//! "view": {"transform": "AgX", "look": "None", "exposure": 0.0, "gamma": 1.0,
//!          "display": "sRGB", "transparent": false,
//!          "lut": {"file": "view_lut.exr", "size": 33, "log2_range": [-16.0, 8.0]}}
//! ```
//!
//! Without it, or for `Standard` with no look, gamma 1 and an sRGB display, a preview is
//! the linear colour times `2^exposure` through the sRGB transfer function, clamped.
//! Anything else needs the `lut`: Blender's own transform sampled by the exporter (through
//! `Image.save_render`, at exposure 0) on a `size^3` grid of linear RGB, each axis
//! `2^t` for `t` evenly spaced over `log2_range`, stored as an EXR of `size^2` columns
//! (`r + size g`) by `size` rows (`b`). A preview reads it trilinearly in `log2` after
//! applying the exposure; below the range a channel takes the grid's first plane (the
//! transforms are black there), above it the last. `transparent` (Film > Transparent)
//! keeps the background's alpha at 0; otherwise the preview is opaque and shows the sky, as
//! Blender's render does.

use super::error::SceneError;
use super::exr_read::ExrChannels;
use super::output::linear_to_srgb;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The `view` object of scene.json.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ViewSpec {
    pub transform: String,
    #[serde(default = "no_look")]
    pub look: String,
    #[serde(default)]
    pub exposure: f32,
    #[serde(default = "unit_gamma")]
    pub gamma: f32,
    #[serde(default = "srgb_display")]
    pub display: String,
    #[serde(default)]
    pub transparent: bool,
    pub lut: Option<LutSpec>,
}

fn no_look() -> String {
    "None".into()
}

fn unit_gamma() -> f32 {
    1.0
}

fn srgb_display() -> String {
    "sRGB".into()
}

/// Where a view transform's sampled grid is, and how it was sampled.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LutSpec {
    /// Relative to the scene directory in scene.json; absolute in a transfer header.
    pub file: PathBuf,
    pub size: usize,
    pub log2_range: [f32; 2],
}

/// Largest LUT side accepted (129^3 samples).
pub const MAX_LUT_SIZE: usize = 129;

/// A view transform sampled on a grid ([`LutSpec`]).
#[derive(Debug)]
pub struct ViewLut {
    pub size: usize,
    pub log2_range: [f32; 2],
    /// `values[(b * size + g) * size + r]`, display-referred.
    pub values: Vec<[f32; 3]>,
}

/// How linear colour becomes a preview's display colour.
#[derive(Clone, Debug)]
pub struct ViewTransform {
    /// The spec it was read from (`None`: the default Standard transform).
    pub spec: Option<ViewSpec>,
    pub exposure: f32,
    /// Keep the background transparent in previews.
    pub transparent: bool,
    lut: Option<Arc<ViewLut>>,
}

impl Default for ViewTransform {
    fn default() -> Self {
        Self { spec: None, exposure: 0.0, transparent: false, lut: None }
    }
}

impl ViewTransform {
    /// The preview transform of a frame with transfer layers (`logsh relight`, `logsh
    /// view`), `spec` its header's with the LUT's file absolute, `frame` the frame's file:
    /// where the LUT cannot be read (the frames moved away from their scene), the
    /// Standard transform at the scene's exposure, with the reason to say aloud. Only the
    /// preview depends on it; the EXRs are linear.
    pub fn for_preview(spec: Option<&ViewSpec>, frame: &Path) -> (Self, Option<String>) {
        let Some(spec) = spec else { return (Self::default(), None) };
        match Self::load(spec, Path::new("/"), frame) {
            Ok(view) => (view, None),
            Err(e) => {
                let standard = ViewSpec {
                    transform: "Standard".into(),
                    look: "None".into(),
                    gamma: 1.0,
                    display: "sRGB".into(),
                    lut: None,
                    ..spec.clone()
                };
                let view = Self::load(&standard, Path::new("/"), frame).unwrap_or_default();
                let reason = format!(
                    "its preview is shown with the Standard view transform, not the scene's {} ({e})",
                    spec.transform
                );
                (view, Some(reason))
            }
        }
    }

    /// Reads `spec`'s LUT, relative to `dir` (a scene directory) when its file is; `file`
    /// is the description to name in errors.
    pub fn load(spec: &ViewSpec, dir: &Path, file: &Path) -> Result<Self, SceneError> {
        if !(spec.exposure.is_finite() && spec.gamma.is_finite() && spec.gamma > 0.0) {
            return Err(SceneError::invalid(file, "\"view\": exposure and gamma must be finite, gamma > 0"));
        }
        let standard =
            spec.transform == "Standard" && spec.look == "None" && spec.gamma == 1.0 && spec.display == "sRGB";
        let lut = match (&spec.lut, standard) {
            (Some(lut), _) => Some(Arc::new(ViewLut::read(lut, dir, file)?)),
            (None, true) => None,
            (None, false) => {
                return Err(SceneError::invalid(
                    file,
                    format!(
                        "\"view\": the {} view transform (look {}, gamma {}, display {}) needs its \"lut\", which the \
                         exporter writes",
                        spec.transform, spec.look, spec.gamma, spec.display
                    ),
                ))
            }
        };
        Ok(Self { spec: Some(spec.clone()), exposure: spec.exposure, transparent: spec.transparent, lut })
    }

    /// The spec with its LUT file made absolute (for a transfer header, read away from the
    /// scene directory).
    pub fn absolute_spec(&self, dir: &Path) -> Option<ViewSpec> {
        self.spec.clone().map(|mut spec| {
            if let Some(lut) = &mut spec.lut {
                let joined = dir.join(&lut.file);
                lut.file = std::path::absolute(&joined).unwrap_or(joined);
            }
            spec
        })
    }

    /// Display-referred RGB in `[0, 1]` of linear `rgb`, with `extra_exposure` stops on top
    /// of the scene's.
    pub fn display(&self, rgb: [f32; 3], extra_exposure: f32) -> [f32; 3] {
        let gain = (self.exposure + extra_exposure).exp2();
        let exposed = rgb.map(|c| if c.is_nan() { 0.0 } else { c * gain });
        match &self.lut {
            Some(lut) => lut.apply(exposed),
            None => exposed.map(linear_to_srgb),
        }
    }

    /// The LUT, which the viewer's page reads too (`None`: Standard).
    pub fn lut(&self) -> Option<&ViewLut> {
        self.lut.as_deref()
    }
}

impl ViewLut {
    fn read(spec: &LutSpec, dir: &Path, scene_file: &Path) -> Result<Self, SceneError> {
        let [lo, hi] = spec.log2_range;
        if !((2..=MAX_LUT_SIZE).contains(&spec.size) && lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(SceneError::invalid(
                scene_file,
                format!("\"view\".\"lut\": size must be 2 to {MAX_LUT_SIZE} and log2_range finite and increasing"),
            ));
        }
        let file = if spec.file.is_absolute() { spec.file.clone() } else { dir.join(&spec.file) };
        let mut exr = ExrChannels::read(&file, "the view transform's LUT")?;
        exr.use_size_of("R");
        let (n, width, height) = (spec.size, exr.width, exr.height);
        if (width, height) != (n * n, n) {
            return Err(SceneError::invalid(&file, format!("is {width}x{height}; a LUT of size {n} is {}x{n}", n * n)));
        }
        let [r, g, b] = ["R", "G", "B"].map(|c| exr.take(&file, c));
        let (r, g, b) = (r?, g?, b?);
        let mut values = vec![[0.0f32; 3]; n * n * n];
        for row in 0..n {
            for column in 0..n * n {
                let (red, green) = (column % n, column / n);
                let i = row * width + column;
                let texel = [r[i], g[i], b[i]];
                if texel.iter().any(|v| !v.is_finite()) {
                    return Err(SceneError::NonFinite {
                        file: file.clone(),
                        what: format!("LUT texel ({column}, {row})"),
                    });
                }
                values[(row * n + green) * n + red] = texel;
            }
        }
        Ok(Self { size: n, log2_range: spec.log2_range, values })
    }

    /// Trilinear in `log2` of each channel (the module doc).
    fn apply(&self, rgb: [f32; 3]) -> [f32; 3] {
        let n = self.size;
        let [lo, hi] = self.log2_range;
        let coordinate = |c: f32| {
            let t = if c > 0.0 { (c.log2() - lo) / (hi - lo) } else { 0.0 };
            let x = t.clamp(0.0, 1.0) * (n - 1) as f32;
            let i = (x.floor() as usize).min(n - 2);
            (i, x - i as f32)
        };
        let [(r0, fr), (g0, fg), (b0, fb)] = rgb.map(coordinate);
        let at = |r: usize, g: usize, b: usize| self.values[(b * n + g) * n + r];
        let mut out = [0.0f32; 3];
        for (db, wb) in [(0, 1.0 - fb), (1, fb)] {
            for (dg, wg) in [(0, 1.0 - fg), (1, fg)] {
                for (dr, wr) in [(0, 1.0 - fr), (1, fr)] {
                    let v = at(r0 + dr, g0 + dg, b0 + db);
                    let w = wr * wg * wb;
                    for k in 0..3 {
                        out[k] += w * v[k];
                    }
                }
            }
        }
        out.map(|v| v.clamp(0.0, 1.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A LUT of the identity in `log2` is read back exactly at the grid and linearly
    /// between.
    #[test]
    fn the_lut_interpolates_in_log2() {
        let n = 5;
        let range = [-4.0f32, 4.0];
        let axis = |i: usize| i as f32 / (n - 1) as f32;
        let values = (0..n * n * n).map(|i| [axis(i % n), axis(i / n % n), axis(i / (n * n))]).collect();
        let lut = ViewLut { size: n, log2_range: range, values };
        // 2^0 = 1 sits at the middle of the range: 0.5 in every channel.
        assert_eq!(lut.apply([1.0, 1.0, 1.0]), [0.5, 0.5, 0.5]);
        // Half a step up in log2 (2^1 sits at 0.625): linear in log2 between the samples.
        let v = lut.apply([2f32.powf(1.0), 2f32.powf(-4.0), 1e9]);
        assert!((v[0] - 0.625).abs() < 1e-6 && v[1].abs() < 1e-6 && v[2] == 1.0, "{v:?}");
        assert_eq!(lut.apply([0.0, -1.0, f32::NAN]), [0.0, 0.0, 0.0]);
    }
}
