//! Multi-layer EXR output: one part, channels named `<layer>.<channel>`, the way
//! Blender's compositor and Nuke read compositing passes.
//!
//! Names: the beauty is plain `R`, `G`, `B`, `A` (Blender reads it as the Combined pass,
//! Nuke as `rgba`); every other pass is `<pass>.<channel>`, which Blender's multilayer
//! reader splits at the last dot into pass and channel (`imb_exr_split_channel_name` in
//! `source/blender/imbuf/intern/openexr/openexr_api.cc`) and Nuke reads as layer
//! `<pass>`. One part rather than Blender 5's part per pass, because every reader of
//! multilayer files accepts it (Blender 4 and 5, Nuke, oiiotool, the `exr` crate).
//! Compression ZIP (16 scan lines per block), lossless.

use super::output::{write_atomically, OutputError};
use exr::prelude::{
    f16, AnyChannel, AnyChannels, Blocks, Compression, Encoding, FlatSamples, Image, Layer, LayerAttributes, LineOrder,
    WritableImage,
};
use std::path::Path;

/// How a channel is stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SampleType {
    /// 16-bit float: 11 significant bits, plenty for colour (relative error below 5e-4).
    Half,
    /// 32-bit float: for data (positions, normals) that needs its precision.
    Float,
}

/// One output channel: full name, storage type, values row-major from the top row.
pub struct OutputChannel<'a> {
    pub name: String,
    pub sample_type: SampleType,
    pub values: &'a [f32],
}

/// Writes `channels` as one ZIP-compressed part, atomically (see [`super::output`]).
/// Channel names must be distinct; they are sorted in the file, as EXR requires.
pub fn write_exr_layers(
    path: &Path,
    width: usize,
    height: usize,
    channels: &[OutputChannel],
) -> Result<(), OutputError> {
    for c in channels {
        if width.checked_mul(height) != Some(c.values.len()) || width == 0 || height == 0 {
            return Err(OutputError::SizeMismatch { file: path.to_path_buf(), width, height, count: c.values.len() });
        }
    }
    let list: Vec<AnyChannel<FlatSamples>> = channels
        .iter()
        .map(|c| {
            let samples = match c.sample_type {
                SampleType::Half => FlatSamples::F16(c.values.iter().map(|&v| f16::from_f32(v)).collect()),
                SampleType::Float => FlatSamples::F32(c.values.to_vec()),
            };
            AnyChannel::new(c.name.as_str(), samples)
        })
        .collect();
    let layer = Layer::new(
        (width, height),
        LayerAttributes::default(),
        Encoding { compression: Compression::ZIP16, blocks: Blocks::ScanLines, line_order: LineOrder::Increasing },
        AnyChannels::sort(list.into_iter().collect()),
    );
    let image = Image::from_layer(layer);
    write_atomically(
        path,
        |temp| image.write().to_file(temp),
        |e| OutputError::Encode { file: path.to_path_buf(), message: e.to_string() },
    )
}
