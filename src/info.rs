//! `logsh info`: what an EXR file holds (parts, layers, channels, sizes, sample types),
//! read from its headers and chunk offsets alone, so that a damaged, cut short or enormous
//! file is described or refused without reading its pixels.

use crate::scene::SceneError;
use exr::io::{PeekRead, Tracking};
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

/// Reads the headers of `file`, and its chunk offsets and last chunk's size, to refuse a
/// file that ends before its pixels do (`check_complete`).
pub fn describe(file: &Path) -> Result<ExrInfo, SceneError> {
    let bytes = std::fs::metadata(file).map_err(|e| SceneError::io(file, "the EXR file", e))?.len();
    let opened = std::fs::File::open(file).map_err(|e| SceneError::io(file, "the EXR file", e))?;
    let mut read = PeekRead::new(Tracking::new(std::io::BufReader::new(opened)));
    let meta = exr::meta::MetaData::read_from_buffered(&mut read, false)
        .map_err(|e| crate::scene::error::exr_error(file, "the EXR file", e))?;
    check_complete(file, &meta, &mut read, bytes)?;
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

/// Refuses `file` (`bytes` long, its headers `meta` read from `read`, which stands where
/// they end) where a chunk of pixels starts past its end or its last chunk ends past it:
/// a file cut short (a copy or a write interrupted) has whole headers and offset tables,
/// and only a read of its pixels would find it out. The offset tables follow the headers,
/// eight bytes per chunk; a chunk starts with its part number in a multi-part file, then
/// its line (or four tile coordinates) and its byte count (OpenEXR's file layout). Deep
/// parts, whose chunks say more, are checked by their offsets alone.
fn check_complete(
    file: &Path,
    meta: &exr::meta::MetaData,
    read: &mut PeekRead<Tracking<std::io::BufReader<std::fs::File>>>,
    bytes: u64,
) -> Result<(), SceneError> {
    let cut = |what: String| {
        SceneError::invalid(file, format!("the file ends early ({bytes} bytes): {what}; write or copy it again"))
    };
    // Saturating: a header's tile count may be absurd.
    let chunks = meta.headers.iter().fold(0u64, |sum, h| sum.saturating_add(h.chunk_count as u64));
    let tables_end = (read.byte_position() as u64).saturating_add(chunks.saturating_mul(8));
    if tables_end > bytes {
        return Err(cut(format!("its {chunks} chunk offsets end at byte {tables_end}")));
    }
    let mut last: Option<(u64, &exr::meta::header::Header)> = None;
    for header in meta.headers.iter() {
        for _ in 0..header.chunk_count {
            let mut offset = [0u8; 8];
            std::io::Read::read_exact(read, &mut offset).map_err(|e| SceneError::io(file, "the EXR file", e))?;
            let offset = u64::from_le_bytes(offset);
            if offset >= bytes {
                return Err(cut(format!("a chunk of pixels starts at byte {offset}")));
            }
            if last.is_none_or(|(at, _)| offset > at) {
                last = Some((offset, header));
            }
        }
    }
    let Some((offset, header)) = last.filter(|(_, header)| !header.deep) else {
        return Ok(());
    };
    let part_number = if meta.requirements.is_multilayer() { 4 } else { 0 };
    let coordinates = match header.blocks {
        exr::meta::BlockDescription::ScanLines => 4,
        exr::meta::BlockDescription::Tiles(_) => 16,
    };
    let size_at = offset + part_number + coordinates;
    let mut size = [0u8; 4];
    read.skip_to(size_at as usize)
        .and_then(|()| std::io::Read::read_exact(read, &mut size))
        .map_err(|_| cut(format!("its last chunk of pixels, at byte {offset}, is cut short")))?;
    let end = size_at + 4 + u64::from(u32::from_le_bytes(size));
    if end > bytes {
        return Err(cut(format!("its last chunk of pixels, at byte {offset}, ends at byte {end}")));
    }
    Ok(())
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

#[cfg(test)]
mod tests {
    use super::*;
    use exr::prelude::*;

    fn layer(name: &str, blocks: Blocks) -> Layer<AnyChannels<FlatSamples>> {
        let encoding = Encoding { compression: Compression::ZIP16, blocks, line_order: LineOrder::Increasing };
        let samples = |k: usize| FlatSamples::F32((0..61 * 47).map(|i| ((i * k) % 13) as f32).collect());
        let channels = AnyChannels::sort(
            [AnyChannel::new("R", samples(7)), AnyChannel::new("G", samples(3))].into_iter().collect(),
        );
        Layer::new((61, 47), LayerAttributes::named(name), encoding, channels)
    }

    /// A file cut short anywhere after its headers, by one byte or by half, is refused
    /// with the cut named, and a whole one is described: one part of scan lines, tiles,
    /// and two parts.
    #[test]
    fn a_file_cut_short_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let (lines, tiles) = (Blocks::ScanLines, Blocks::Tiles(Vec2(16, 16)));
        let files = [("lines", 1), ("tiles", 1), ("parts", 2)].map(|(name, parts)| {
            let file = dir.path().join(format!("{name}.exr"));
            let blocks = if name == "tiles" { tiles } else { lines };
            let layers: Vec<_> = ["a", "b"][..parts].iter().map(|name| layer(name, blocks)).collect();
            Image::from_layers(ImageAttributes::new(IntegerBounds::from_dimensions((61, 47))), layers)
                .write()
                .to_file(&file)
                .unwrap();
            (file, parts)
        });
        for (file, parts) in &files {
            let whole = std::fs::read(file).unwrap();
            let info = describe(file).unwrap();
            assert_eq!(info.parts.len(), *parts, "{}", file.display());
            let headers = exr::meta::MetaData::read_from_file(file, false).unwrap();
            let chunks: usize = headers.headers.iter().map(|h| h.chunk_count).sum();
            assert!(chunks > 2, "{}: {chunks} chunks", file.display());
            for kept in [whole.len() - 1, whole.len() - 20, whole.len() / 2] {
                let cut = dir.path().join("cut.exr");
                std::fs::write(&cut, &whole[..kept]).unwrap();
                let error = describe(&cut).unwrap_err().to_string();
                assert!(
                    error.contains("cut.exr") && error.contains("ends early"),
                    "{}, {kept} bytes: {error}",
                    file.display()
                );
            }
        }
    }
}
