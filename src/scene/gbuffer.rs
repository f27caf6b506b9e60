//! G-buffer EXR files: world position, normal, UV and material index per pixel.
//!
//! Both layouts Blender writes are read (see the `exr_read` notes): Blender 5's one part
//! per pass (part `ViewLayer.Position`, channels `ViewLayer.Position.X` ...) and Blender
//! 4's single part with dotted names. Channels are looked up by full dotted name.
//!
//! Pixel order: row-major, row 0 is the top row of the image (the first scan line of the
//! EXR file), the same order the output images are written in.
//!
//! Per-pixel checks, each an error naming the file, the pixel `(x, y)` and the value:
//! - the material index must lie within 1e-3 of a whole number, be `>= 0`, and be 0
//!   (background) or a key of the material table; it is rounded to that whole number;
//! - on every non-background pixel, position and normal must be finite. Background
//!   pixels are not checked (their position and normal are never read).

use super::error::SceneError;
use super::exr_read::ChannelFile;
use super::exr_zip::Target;
use super::Material;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The `"channels"` object of `scene.json`; every key optional.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelOverrides {
    pub position: Option<[String; 3]>,
    pub normal: Option<[String; 3]>,
    pub uv: Option<[String; 2]>,
    pub material_index: Option<String>,
    pub object_index: Option<String>,
}

/// The full channel names the G-buffer reader looks up.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ChannelNames {
    pub position: [String; 3],
    pub normal: [String; 3],
    pub uv: [String; 2],
    /// True when `uv` came from an override, which makes the UV channels required.
    pub uv_required: bool,
    /// Tried in order; the first present is used.
    pub material_index: Vec<String>,
    /// Tried in order; the first present is used. Optional unless overridden.
    pub object_index: Vec<String>,
    /// True when `object_index` came from an override, which makes it required.
    pub object_index_required: bool,
}

/// Blender's default channel names for view layer `ViewLayer`.
pub const POSITION: [&str; 3] = ["ViewLayer.Position.X", "ViewLayer.Position.Y", "ViewLayer.Position.Z"];
pub const NORMAL: [&str; 3] = ["ViewLayer.Normal.X", "ViewLayer.Normal.Y", "ViewLayer.Normal.Z"];
pub const UV: [&str; 2] = ["ViewLayer.UV.U", "ViewLayer.UV.V"];
/// Blender 5 name of the material index pass.
pub const MATERIAL_INDEX_BLENDER5: &str = "ViewLayer.Material Index.X";
/// Blender 4 name of the material index pass.
pub const MATERIAL_INDEX_BLENDER4: &str = "ViewLayer.IndexMA.X";
/// Blender 5 name of the object index pass.
pub const OBJECT_INDEX_BLENDER5: &str = "ViewLayer.Object Index.X";
/// Blender 4 name of the object index pass.
pub const OBJECT_INDEX_BLENDER4: &str = "ViewLayer.IndexOB.X";

impl Default for ChannelNames {
    fn default() -> Self {
        Self::from_overrides(None)
    }
}

impl ChannelNames {
    pub fn from_overrides(o: Option<&ChannelOverrides>) -> Self {
        let o = o.cloned().unwrap_or_default();
        let owned = |a: &[&str]| -> Vec<String> { a.iter().map(|s| s.to_string()).collect() };
        let three = |a: [&str; 3]| -> [String; 3] { owned(&a).try_into().expect("three names") };
        Self {
            position: o.position.unwrap_or_else(|| three(POSITION)),
            normal: o.normal.unwrap_or_else(|| three(NORMAL)),
            uv_required: o.uv.is_some(),
            uv: o.uv.unwrap_or_else(|| owned(&UV).try_into().expect("two names")),
            material_index: match o.material_index {
                Some(m) => vec![m],
                None => owned(&[MATERIAL_INDEX_BLENDER5, MATERIAL_INDEX_BLENDER4]),
            },
            object_index_required: o.object_index.is_some(),
            object_index: match o.object_index {
                Some(m) => vec![m],
                None => owned(&[OBJECT_INDEX_BLENDER5, OBJECT_INDEX_BLENDER4]),
            },
        }
    }
}

/// One G-buffer, validated.
#[derive(Clone, Debug, PartialEq)]
pub struct GBuffer {
    /// The file it was read from.
    pub file: PathBuf,
    pub width: usize,
    pub height: usize,
    /// World position (Blender world: Z up), row-major from the top row.
    pub position: Vec<[f32; 3]>,
    /// World normal as stored (not renormalised).
    pub normal: Vec<[f32; 3]>,
    /// `None` when the file has no UV channels (UV is not used by shading).
    pub uv: Option<Vec<[f32; 2]>>,
    /// Material index, 0 = background.
    pub material: Vec<u32>,
    /// Object index (Blender's Object Index pass, the `object` of the blocker spheres),
    /// 0 = no object; `None` when the file has no such channel.
    pub object: Option<Vec<u32>>,
}

impl GBuffer {
    /// Index of pixel `(x, y)`, `y = 0` at the top.
    pub fn index(&self, x: usize, y: usize) -> usize {
        y * self.width + x
    }

    /// Reads and validates a G-buffer file.
    pub fn read(file: &Path, names: &ChannelNames, materials: &BTreeMap<u32, Material>) -> Result<GBuffer, SceneError> {
        const WHAT: &str = "a G-buffer";
        let channels = ChannelFile::read(file, WHAT, &names.position[0])?;
        let (width, height) = channels.size();
        let n = width * height;
        let has_uv = names.uv_required || channels.has(&names.uv[0]) || channels.has(&names.uv[1]);
        let index_name =
            names.material_index.iter().find(|name| channels.has(name)).unwrap_or(&names.material_index[0]);
        let object_name = match names.object_index.iter().find(|name| channels.has(name)) {
            None if names.object_index_required => Some(&names.object_index[0]),
            found => found,
        };
        let (mut position, mut normal) = (vec![[0.0f32; 3]; n], vec![[0.0f32; 3]; n]);
        let mut uv = vec![[0.0f32; 2]; if has_uv { n } else { 0 }];
        let mut raw_index = vec![0.0f32; n];
        let mut raw_object = vec![0.0f32; if object_name.is_some() { n } else { 0 }];
        let in_order = |channel_names: &[String]| channel_names.iter().cloned().zip(0..).collect::<Vec<_>>();
        let mut targets = vec![
            Target { values: position.as_flattened_mut(), stride: 3, channels: in_order(&names.position) },
            Target { values: normal.as_flattened_mut(), stride: 3, channels: in_order(&names.normal) },
        ];
        if has_uv {
            targets.push(Target { values: uv.as_flattened_mut(), stride: 2, channels: in_order(&names.uv) });
        }
        targets.push(Target {
            values: &mut raw_index,
            stride: 1,
            channels: in_order(std::slice::from_ref(index_name)),
        });
        if let Some(name) = object_name {
            targets.push(Target { values: &mut raw_object, stride: 1, channels: in_order(std::slice::from_ref(name)) });
        }
        channels.fill(file, WHAT, &mut targets)?;
        let uv = has_uv.then_some(uv);
        let object =
            object_name.is_some().then(|| whole_indices(file, &raw_object, width, "object index")).transpose()?;

        let mut material = Vec::with_capacity(raw_index.len());
        for (i, &value) in raw_index.iter().enumerate() {
            let (x, y) = (i % width, i / width);
            let bad = |reason: &str| SceneError::MaterialIndex {
                file: file.to_path_buf(),
                x,
                y,
                value,
                reason: reason.to_string(),
            };
            if !value.is_finite() {
                return Err(bad("is not a finite number"));
            }
            let rounded = value.round();
            if (value - rounded).abs() > 1e-3 {
                return Err(bad("is not a whole number"));
            }
            if rounded < 0.0 {
                return Err(bad("is negative"));
            }
            if rounded > u32::MAX as f32 {
                return Err(bad("is too large"));
            }
            let m = rounded as u32;
            if m != 0 && !materials.contains_key(&m) {
                let known: Vec<String> = materials.keys().map(|k| k.to_string()).collect();
                return Err(bad(&format!(
                    "is not in the material table of scene.json (defined: {})",
                    if known.is_empty() { "none".to_string() } else { known.join(", ") }
                )));
            }
            if m != 0 {
                let (p, n) = (position[i], normal[i]);
                if p.iter().any(|v| !v.is_finite()) {
                    return Err(SceneError::NonFinite {
                        file: file.to_path_buf(),
                        what: format!("position {p:?} of pixel ({x}, {y})"),
                    });
                }
                if n.iter().any(|v| !v.is_finite()) {
                    return Err(SceneError::NonFinite {
                        file: file.to_path_buf(),
                        what: format!("normal {n:?} of pixel ({x}, {y})"),
                    });
                }
            }
            material.push(m);
        }
        Ok(GBuffer { file: file.to_path_buf(), width, height, position, normal, uv, material, object })
    }

    /// The object index of pixel `i`, 0 when the G-buffer has none.
    pub fn object_at(&self, i: usize) -> u32 {
        self.object.as_ref().map_or(0, |o| o[i])
    }
}

/// An index pass as whole numbers `>= 0`; a value off a whole number by more than 1e-3,
/// negative or not finite is an error naming the pixel.
fn whole_indices(file: &Path, raw: &[f32], width: usize, what: &str) -> Result<Vec<u32>, SceneError> {
    raw.iter()
        .enumerate()
        .map(|(i, &value)| {
            let rounded = value.round();
            if !value.is_finite() || (value - rounded).abs() > 1e-3 || rounded < 0.0 || rounded > u32::MAX as f32 {
                return Err(SceneError::invalid(
                    file,
                    format!("{what} {value} of pixel ({}, {}) is not a whole number >= 0", i % width, i / width),
                ));
            }
            Ok(rounded as u32)
        })
        .collect()
}
