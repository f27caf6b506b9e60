//! `logsh info`: what an EXR file holds (parts, layers, channels, sizes, sample types),
//! read from its headers alone, so that a damaged or enormous file is described or
//! refused without reading its pixels.

use crate::scene::SceneError;
use serde::Serialize;
use std::path::Path;

/// One channel of a part.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct ChannelInfo {
    /// Full name as stored (`diffuse.R`).
    pub name: String,
    /// `half`, `float` or `uint`.
    pub sample_type: &'static str,
    /// Subsampling in x and y (1, 1 for full resolution).
    pub sampling: [usize; 2],
}

/// A layer: the channels sharing a name before their last dot (`""` for `R`, `G`, ...).
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct LayerInfo {
    pub name: String,
    /// Channel names after the layer prefix, in file order.
    pub channels: Vec<String>,
    /// The types of those channels, joined when they differ (`half`, or `half+float`).
    pub sample_type: String,
}

/// One part (sub-image) of the file.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct PartInfo {
    /// The part's `name` attribute, if any (Blender 5 names one part per pass).
    pub name: Option<String>,
    pub width: usize,
    pub height: usize,
    /// Position of the data window.
    pub origin: [i32; 2],
    pub compression: String,
    /// `scan lines` or `tiles WxH`.
    pub blocks: String,
    pub deep: bool,
    pub layers: Vec<LayerInfo>,
    pub channels: Vec<ChannelInfo>,
}

#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct ExrInfo {
    pub file: String,
    pub bytes: u64,
    pub parts: Vec<PartInfo>,
}

/// Reads the headers of `file`.
pub fn describe(file: &Path) -> Result<ExrInfo, SceneError> {
    let bytes = std::fs::metadata(file).map_err(|e| SceneError::io(file, "the EXR file", e))?.len();
    let meta = exr::meta::MetaData::read_from_file(file, false)
        .map_err(|e| crate::scene::error::exr_error(file, "the EXR file", e))?;
    let parts = meta
        .headers
        .iter()
        .map(|h| {
            let channels: Vec<ChannelInfo> = h
                .channels
                .list
                .iter()
                .map(|c| ChannelInfo {
                    name: c.name.to_string(),
                    sample_type: match c.sample_type {
                        exr::meta::attribute::SampleType::F16 => "half",
                        exr::meta::attribute::SampleType::F32 => "float",
                        exr::meta::attribute::SampleType::U32 => "uint",
                    },
                    sampling: [c.sampling.0, c.sampling.1],
                })
                .collect();
            PartInfo {
                name: h.own_attributes.layer_name.as_ref().map(|t| t.to_string()),
                width: h.layer_size.0,
                height: h.layer_size.1,
                origin: [h.own_attributes.layer_position.0, h.own_attributes.layer_position.1],
                compression: format!("{:?}", h.compression),
                blocks: match h.blocks {
                    exr::meta::BlockDescription::ScanLines => "scan lines".into(),
                    exr::meta::BlockDescription::Tiles(t) => format!("tiles {}x{}", t.tile_size.0, t.tile_size.1),
                },
                deep: h.deep,
                layers: group_layers(&channels),
                channels,
            }
        })
        .collect();
    Ok(ExrInfo { file: file.display().to_string(), bytes, parts })
}

fn group_layers(channels: &[ChannelInfo]) -> Vec<LayerInfo> {
    let mut layers: Vec<(LayerInfo, Vec<&'static str>)> = Vec::new();
    for c in channels {
        let (layer, channel) = match c.name.rsplit_once('.') {
            Some((l, ch)) => (l.to_string(), ch.to_string()),
            None => (String::new(), c.name.clone()),
        };
        match layers.iter_mut().find(|(l, _)| l.name == layer) {
            Some((l, types)) => {
                l.channels.push(channel);
                if !types.contains(&c.sample_type) {
                    types.push(c.sample_type);
                }
            }
            None => layers.push((
                LayerInfo { name: layer, channels: vec![channel], sample_type: String::new() },
                vec![c.sample_type],
            )),
        }
    }
    layers
        .into_iter()
        .map(|(mut l, types)| {
            l.sample_type = types.join("+");
            l
        })
        .collect()
}

/// The human-readable listing `logsh info` prints.
pub fn to_text(info: &ExrInfo) -> String {
    let mut s = format!("{}: {} bytes, {} part(s)\n", info.file, info.bytes, info.parts.len());
    for (i, p) in info.parts.iter().enumerate() {
        s += &format!(
            "part {i}{}: {} x {} at ({}, {}), {}, {}{}, {} channel(s)\n",
            p.name.as_ref().map(|n| format!(" \"{n}\"")).unwrap_or_default(),
            p.width,
            p.height,
            p.origin[0],
            p.origin[1],
            p.compression,
            p.blocks,
            if p.deep { ", deep" } else { "" },
            p.channels.len()
        );
        for l in &p.layers {
            let name = if l.name.is_empty() { "(no layer)".to_string() } else { l.name.clone() };
            s += &format!("  {name:<28} {:<14} {}\n", l.channels.join(" "), l.sample_type);
        }
    }
    s
}
