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
//!   pixels are not checked (their position and normal are never read);
//! - where the scene takes its colours from the G-buffer (`"colour_passes": true`), the
//!   Diffuse Color and Glossy Color passes must be present in the G-buffer, and on every
//!   non-background pixel finite and `>= 0`. The reflection G-buffer's are read where
//!   present.
//!
//! # Colour passes
//!
//! Cycles' Diffuse Color and Glossy Color passes hold, per pixel, what Blender's own
//! evaluation of the material multiplies the light through each lobe by: textures,
//! vertex colours and every node in front of the BSDF, and for a Principled BSDF the
//! layering of its parts (Cycles' `bsdf_albedo`: the diffuse weight is the base colour
//! times `1 - metallic`, times `1 -` the specular layer's albedo; the glossy weight is the
//! directional albedo of the Fresnel-weighted specular layer at this pixel's view angle,
//! whose F0 is the base colour for a metal). Blender 5 names them `Diffuse Color` and
//! `Glossy Color`, Blender 4 `DiffCol` and `GlossCol`; both are read.

use super::error::SceneError;
use super::exr_read::ChannelFile;
use super::exr_zip::Target;
use super::Material;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::ops::Range;
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
    pub diffuse_colour: Option<[String; 3]>,
    pub glossy_colour: Option<[String; 3]>,
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
    /// The colour passes, each tried in order ([`module doc`](self)): `None` where the
    /// scene's colours come from its material table.
    pub colours: Option<ColourChannels>,
}

/// The channel names of the Diffuse Color and Glossy Color passes, each list tried in
/// order; the first whose channels are present is used.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ColourChannels {
    pub diffuse: Vec<[String; 3]>,
    pub glossy: Vec<[String; 3]>,
}

/// Blender 5's and Blender 4's names of the Diffuse Color pass, in view layer `ViewLayer`.
pub const DIFFUSE_COLOUR: [[&str; 3]; 2] = [
    ["ViewLayer.Diffuse Color.R", "ViewLayer.Diffuse Color.G", "ViewLayer.Diffuse Color.B"],
    ["ViewLayer.DiffCol.R", "ViewLayer.DiffCol.G", "ViewLayer.DiffCol.B"],
];
/// Blender 5's and Blender 4's names of the Glossy Color pass.
pub const GLOSSY_COLOUR: [[&str; 3]; 2] = [
    ["ViewLayer.Glossy Color.R", "ViewLayer.Glossy Color.G", "ViewLayer.Glossy Color.B"],
    ["ViewLayer.GlossCol.R", "ViewLayer.GlossCol.G", "ViewLayer.GlossCol.B"],
];

/// Per pixel, what the light through each lobe is multiplied by ([module doc](self),
/// "Colour passes"): row-major from the top row, as the G-buffer's other passes.
#[derive(Clone, Debug, PartialEq)]
pub struct SurfaceColours {
    pub diffuse: Vec<[f32; 3]>,
    pub glossy: Vec<[f32; 3]>,
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
    /// The names of a scene's G-buffers: `colour_passes` where its colours come from them.
    pub fn new(o: Option<&ChannelOverrides>, colour_passes: bool) -> Self {
        let three = |a: &[&str; 3]| a.map(str::to_string);
        let names = |given: &Option<[String; 3]>, defaults: &[[&str; 3]; 2]| match given {
            Some(given) => vec![given.clone()],
            None => defaults.iter().map(three).collect(),
        };
        let colours = colour_passes.then(|| {
            let o = o.cloned().unwrap_or_default();
            ColourChannels {
                diffuse: names(&o.diffuse_colour, &DIFFUSE_COLOUR),
                glossy: names(&o.glossy_colour, &GLOSSY_COLOUR),
            }
        });
        Self { colours, ..Self::from_overrides(o) }
    }

    /// The names of a scene whose colours come from its material table.
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
            colours: None,
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
    /// Blender's colour passes ([module doc](self)), where the scene reads them and the
    /// file has them.
    pub colours: Option<SurfaceColours>,
    /// The image row its first row is: 0, unless it holds a band of the rows of a larger
    /// image ([`GBufferFile::read_rows`]).
    pub first_row: usize,
}

impl GBuffer {
    /// Index of pixel `(x, y)`, `y = 0` at the top.
    pub fn index(&self, x: usize, y: usize) -> usize {
        y * self.width + x
    }

    /// Reads and validates a G-buffer file; `colours_required`: the colour passes must be
    /// there where `names` has them (the G-buffer), else they are read where present (the
    /// reflection G-buffer).
    pub fn read(
        file: &Path,
        names: &ChannelNames,
        materials: &BTreeMap<u32, Material>,
        colours_required: bool,
    ) -> Result<GBuffer, SceneError> {
        let opened = GBufferFile::open(file, names, colours_required, Reading::Whole)?;
        opened.read_rows(materials, 0..opened.height)
    }
    /// The Diffuse Color and Glossy Color of pixel `i`, where the G-buffer has them.
    pub fn colours_at(&self, i: usize) -> Option<([f32; 3], [f32; 3])> {
        self.colours.as_ref().map(|c| (c.diffuse[i], c.glossy[i]))
    }

    /// The object index of pixel `i`, 0 when the G-buffer has none.
    pub fn object_at(&self, i: usize) -> u32 {
        self.object.as_ref().map_or(0, |o| o[i])
    }
}

/// How a G-buffer file is read: whole into memory, or a band of rows at a time from the
/// file (only the band's blocks are read).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reading {
    Whole,
    InBands,
}

/// A G-buffer file opened and its channels found, read whole or a band of rows at a time
/// ([`Self::read_rows`]).
pub struct GBufferFile {
    file: PathBuf,
    channels: ChannelFile,
    pub width: usize,
    pub height: usize,
    position: [String; 3],
    normal: [String; 3],
    uv: Option<[String; 2]>,
    material_index: String,
    object_index: Option<String>,
    colours: Option<([String; 3], [String; 3])>,
}

const WHAT: &str = "a G-buffer";

impl GBufferFile {
    /// Opens `file` and finds its channels ([`GBuffer::read`]); reads its pixels now
    /// with [`Reading::Whole`], else band by band.
    pub fn open(
        file: &Path,
        names: &ChannelNames,
        colours_required: bool,
        reading: Reading,
    ) -> Result<Self, SceneError> {
        let channels = match reading {
            Reading::Whole => ChannelFile::read(file, WHAT, &names.position[0])?,
            Reading::InBands => ChannelFile::open(file, WHAT, &names.position[0])?,
        };
        let (width, height) = channels.size();
        let has_uv = names.uv_required || channels.has(&names.uv[0]) || channels.has(&names.uv[1]);
        let material_index =
            names.material_index.iter().find(|name| channels.has(name)).unwrap_or(&names.material_index[0]).clone();
        let object_index = match names.object_index.iter().find(|name| channels.has(name)) {
            None if names.object_index_required => Some(names.object_index[0].clone()),
            found => found.cloned(),
        };
        let present = |lists: &Vec<[String; 3]>| -> Option<[String; 3]> {
            match lists.iter().find(|names| names.iter().all(|name| channels.has(name))) {
                None if colours_required => Some(lists[0].clone()),
                found => found.cloned(),
            }
        };
        let colours = names.colours.as_ref().and_then(|c| Some((present(&c.diffuse)?, present(&c.glossy)?)));
        Ok(Self {
            file: file.to_path_buf(),
            channels,
            width,
            height,
            position: names.position.clone(),
            normal: names.normal.clone(),
            uv: has_uv.then(|| names.uv.clone()),
            material_index,
            object_index,
            colours,
        })
    }

    /// The width and height of the G-buffer `file`, from its headers alone.
    pub fn size(file: &Path, names: &ChannelNames) -> Result<(usize, usize), SceneError> {
        ChannelFile::size_from_headers(file, WHAT, &names.position[0])
    }

    /// The file it reads.
    pub fn file(&self) -> &Path {
        &self.file
    }

    /// The image rows `rows` (starting on a multiple of 16, ending on one or at the
    /// bottom), validated as [`GBuffer::read`] validates a whole file; errors name pixels
    /// by their place in the image.
    pub fn read_rows(&self, materials: &BTreeMap<u32, Material>, rows: Range<usize>) -> Result<GBuffer, SceneError> {
        let (file, width) = (self.file.as_path(), self.width);
        let n = width * rows.len();
        let mut colours = self
            .colours
            .as_ref()
            .map(|_| SurfaceColours { diffuse: vec![[0.0f32; 3]; n], glossy: vec![[0.0f32; 3]; n] });
        let (mut position, mut normal) = (vec![[0.0f32; 3]; n], vec![[0.0f32; 3]; n]);
        let mut uv = vec![[0.0f32; 2]; if self.uv.is_some() { n } else { 0 }];
        let mut raw_index = vec![0.0f32; n];
        let mut raw_object = vec![0.0f32; if self.object_index.is_some() { n } else { 0 }];
        let in_order = |channel_names: &[String]| channel_names.iter().cloned().zip(0..).collect::<Vec<_>>();
        let mut targets = vec![
            Target { values: position.as_flattened_mut(), stride: 3, channels: in_order(&self.position) },
            Target { values: normal.as_flattened_mut(), stride: 3, channels: in_order(&self.normal) },
        ];
        if let Some(names) = &self.uv {
            targets.push(Target { values: uv.as_flattened_mut(), stride: 2, channels: in_order(names) });
        }
        targets.push(Target {
            values: &mut raw_index,
            stride: 1,
            channels: in_order(std::slice::from_ref(&self.material_index)),
        });
        if let Some(name) = &self.object_index {
            targets.push(Target { values: &mut raw_object, stride: 1, channels: in_order(std::slice::from_ref(name)) });
        }
        if let (Some((diffuse, glossy)), Some(colours)) = (&self.colours, &mut colours) {
            targets.push(Target { values: colours.diffuse.as_flattened_mut(), stride: 3, channels: in_order(diffuse) });
            targets.push(Target { values: colours.glossy.as_flattened_mut(), stride: 3, channels: in_order(glossy) });
        }
        self.channels.fill_lines(file, WHAT, rows.clone(), &mut targets)?;
        let uv = self.uv.is_some().then_some(uv);
        let object = self
            .object_index
            .is_some()
            .then(|| whole_indices(file, &raw_object, width, rows.start, "object index"))
            .transpose()?;

        let mut material = Vec::with_capacity(raw_index.len());
        for (i, &value) in raw_index.iter().enumerate() {
            let (x, y) = (i % width, rows.start + i / width);
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
                if let Some(colours) = &colours {
                    for (pass, c) in [("Diffuse Color", colours.diffuse[i]), ("Glossy Color", colours.glossy[i])] {
                        if c.iter().any(|v| !v.is_finite()) {
                            return Err(SceneError::NonFinite {
                                file: file.to_path_buf(),
                                what: format!("{pass} {c:?} of pixel ({x}, {y})"),
                            });
                        }
                        if c.iter().any(|&v| v < 0.0) {
                            return Err(SceneError::invalid(
                                file,
                                format!("{pass} {c:?} of pixel ({x}, {y}) is negative; a colour is >= 0"),
                            ));
                        }
                    }
                }
            }
            material.push(m);
        }
        Ok(GBuffer {
            file: file.to_path_buf(),
            width,
            height: rows.len(),
            position,
            normal,
            uv,
            material,
            object,
            colours,
            first_row: rows.start,
        })
    }
}

/// An index pass as whole numbers `>= 0`; a value off a whole number by more than 1e-3,
/// negative or not finite is an error naming the pixel.
fn whole_indices(file: &Path, raw: &[f32], width: usize, first_row: usize, what: &str) -> Result<Vec<u32>, SceneError> {
    raw.iter()
        .enumerate()
        .map(|(i, &value)| {
            let rounded = value.round();
            if !value.is_finite() || (value - rounded).abs() > 1e-3 || rounded < 0.0 || rounded > u32::MAX as f32 {
                return Err(SceneError::invalid(
                    file,
                    format!(
                        "{what} {value} of pixel ({}, {}) is not a whole number >= 0",
                        i % width,
                        first_row + i / width
                    ),
                ));
            }
            Ok(rounded as u32)
        })
        .collect()
}
