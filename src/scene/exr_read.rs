//! Reading every channel of an EXR file by its full dotted name, in both layouts
//! Blender writes.
//!
//! - Blender 4 (and any single-part file): one part without a name, channel names carry
//!   the whole path, `ViewLayer.Position.X`.
//! - Blender 5 writes multilayer files as multi-part files, one part per pass
//!   (`IMB_exr_write_pass` / `IMB_exr_write_end` in Blender's
//!   `source/blender/imbuf/intern/openexr/openexr_api.cc`): the part's `name` attribute is
//!   the layer and pass, `ViewLayer.Position` (with `-<view>` appended for stereo views),
//!   and the channels inside keep their full names, `ViewLayer.Position.X`. Other writers
//!   (Nuke style) name the channels inside a part without the prefix (`X`).
//!
//! The `exr` crate exposes each part as a `Layer` whose `attributes.layer_name` holds the
//! part name and whose `channel_data.list[i].name` holds the channel name as stored. The
//! full name of a channel is therefore the stored name when it already starts with
//! `<part name>.`, and `<part name>.<channel>` otherwise; the stored name is also kept
//! as an alias (first part wins), so that `R` finds an environment map's red channel in
//! any layout.

use super::error::{check_image_size, exr_error, SceneError};
use super::exr_zip;
use exr::prelude::{read, FlatSamples, ReadChannels, ReadLayers};
use half::slice::HalfFloatSliceExt;
use rayon::prelude::*;
use std::collections::HashMap;
use std::path::Path;

/// The channels of one EXR file, all of the same size, kept as stored and converted to
/// f32 when taken (a frame with transfer layers holds about 90 channels, of which a
/// reader takes some: converting all of them first doubled the memory a read touched).
pub(crate) struct ExrChannels {
    pub width: usize,
    pub height: usize,
    /// Full dotted names in file order (without aliases), for error messages.
    pub names: Vec<String>,
    channels: HashMap<String, usize>,
    data: Vec<FlatSamples>,
    sizes: Vec<[usize; 2]>,
}

impl ExrChannels {
    /// Reads every channel of every part. The size of every part is checked against the
    /// limits before its pixels are allocated.
    pub fn read(file: &Path, what: &str) -> Result<Self, SceneError> {
        let meta = exr::meta::MetaData::read_from_file(file, false).map_err(|e| exr_error(file, what, e))?;
        if meta.headers.is_empty() {
            return Err(SceneError::Image { file: file.to_path_buf(), message: "the file has no image parts".into() });
        }
        for header in meta.headers.iter() {
            check_image_size(file, header.layer_size.0, header.layer_size.1)?;
            if header.deep {
                return Err(SceneError::Image {
                    file: file.to_path_buf(),
                    message: "deep EXR data is not supported".into(),
                });
            }
        }
        let image = read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .all_layers()
            .all_attributes()
            .from_file(file)
            .map_err(|e| exr_error(file, what, e))?;

        let mut out = ExrChannels {
            width: 0,
            height: 0,
            names: Vec::new(),
            channels: HashMap::new(),
            data: Vec::new(),
            sizes: Vec::new(),
        };
        let mut aliases: Vec<(String, usize)> = Vec::new();
        for layer in image.layer_data {
            let part = layer.attributes.layer_name.as_ref().map(|t| t.to_string());
            let size = [layer.size.0, layer.size.1];
            for channel in layer.channel_data.list {
                let stored = channel.name.to_string();
                let full = match &part {
                    Some(p) if !p.is_empty() && !stored.starts_with(&format!("{p}.")) => format!("{p}.{stored}"),
                    _ => stored.clone(),
                };
                let index = out.data.len();
                out.data.push(channel.sample_data);
                out.sizes.push(size);
                if !out.channels.contains_key(&full) {
                    out.channels.insert(full.clone(), index);
                    out.names.push(full.clone());
                }
                if stored != full {
                    aliases.push((stored, index));
                }
            }
        }
        for (alias, index) in aliases {
            out.channels.entry(alias).or_insert(index);
        }
        if let Some(first) = out.sizes.first() {
            out.width = first[0];
            out.height = first[1];
        }
        Ok(out)
    }

    pub fn has(&self, name: &str) -> bool {
        self.channels.contains_key(name)
    }

    /// The channel's values, row after row from the top row of the image. All channels
    /// taken from one file must have the size of the first one taken, which becomes
    /// `width` x `height`.
    pub fn take(&mut self, file: &Path, name: &str) -> Result<Vec<f32>, SceneError> {
        let index = self.checked_index(file, name)?;
        Ok(to_f32(&self.data[index]))
    }

    /// The index of channel `name`, checked to exist and to have the reference size.
    fn checked_index(&self, file: &Path, name: &str) -> Result<usize, SceneError> {
        let Some(&index) = self.channels.get(name) else {
            return Err(SceneError::MissingChannel {
                file: file.to_path_buf(),
                channel: name.to_string(),
                found: self.names.clone(),
            });
        };
        let size = self.sizes[index];
        if size != [self.width, self.height] {
            return Err(SceneError::invalid(
                file,
                format!(
                    "channel \"{name}\" is {}x{} but the other channels are {}x{}",
                    size[0], size[1], self.width, self.height
                ),
            ));
        }
        Ok(index)
    }

    /// The channel as stored, moved out, for a reader that converts as it rearranges;
    /// taking it again is an error.
    pub fn take_samples(&mut self, file: &Path, name: &str) -> Result<FlatSamples, SceneError> {
        let index = self.checked_index(file, name)?;
        if self.data[index].len() == 0 {
            return Err(SceneError::invalid(
                file,
                format!("channel \"{name}\" is read twice (it appears twice in the file)"),
            ));
        }
        Ok(std::mem::replace(&mut self.data[index], FlatSamples::F32(Vec::new())))
    }

    /// Makes the size of `name`'s part the reference size for later `take` calls.
    pub fn use_size_of(&mut self, name: &str) {
        if let Some(&index) = self.channels.get(name) {
            self.width = self.sizes[index][0];
            self.height = self.sizes[index][1];
        }
    }
}

/// Samples as f32 ([`samples_to_f32`]).
fn to_f32(samples: &FlatSamples) -> Vec<f32> {
    let mut out = vec![0.0f32; samples.len()];
    samples_to_f32(samples, 0, &mut out);
    out
}

/// Samples `first..first + out.len()` as f32: half floats exactly (through F16C where the
/// processor has it), 32-bit unsigned integers to the nearest f32.
pub(crate) fn samples_to_f32(samples: &FlatSamples, first: usize, out: &mut [f32]) {
    let range = first..first + out.len();
    match samples {
        FlatSamples::F16(v) => v[range].convert_to_f32_slice(out),
        FlatSamples::F32(v) => out.copy_from_slice(&v[range]),
        FlatSamples::U32(v) => {
            for (o, &u) in out.iter_mut().zip(&v[range]) {
                *o = u as f32;
            }
        }
    }
}

/// An EXR file's channels, to be decoded into place ([`ChannelFile::fill`]): straight
/// from its blocks where [`exr_zip::decodes`] its one part (what `logsh render` writes),
/// through [`ExrChannels`] otherwise (more parts, tiles, other compressions).
pub(crate) enum ChannelFile {
    Blocks { bytes: Vec<u8>, header: Box<exr::meta::header::Header> },
    Decoded(ExrChannels),
}

impl ChannelFile {
    /// `file` as `bytes`, its header already read as `meta`; `size_of` names the channel
    /// whose part gives the size every channel taken must have.
    pub fn new(
        file: &Path,
        what: &str,
        bytes: Vec<u8>,
        meta: &exr::meta::MetaData,
        size_of: &str,
    ) -> Result<Self, SceneError> {
        if let [header] = meta.headers.as_slice() {
            if exr_zip::decodes(header) {
                let (width, height) = (header.layer_size.0, header.layer_size.1);
                check_image_size(file, width, height)?;
                // Deflate packs at most 1032 bytes into one, so a file whose pixels could
                // not fit in it is refused before they are allocated.
                let raw = (width * height).saturating_mul(header.channels.bytes_per_pixel);
                if raw / exr_zip::MOST_DEFLATED > bytes.len() {
                    return Err(SceneError::Image {
                        file: file.to_path_buf(),
                        message: format!(
                            "its {width} x {height} pixels of {} bytes cannot fit in its {} bytes; write or copy it \
                             again",
                            header.channels.bytes_per_pixel,
                            bytes.len()
                        ),
                    });
                }
                return Ok(Self::Blocks { bytes, header: Box::new(header.clone()) });
            }
        }
        drop(bytes);
        let mut exr = ExrChannels::read(file, what)?;
        exr.use_size_of(size_of);
        Ok(Self::Decoded(exr))
    }

    pub fn size(&self) -> (usize, usize) {
        match self {
            Self::Blocks { header, .. } => (header.layer_size.0, header.layer_size.1),
            Self::Decoded(exr) => (exr.width, exr.height),
        }
    }

    pub fn has(&self, name: &str) -> bool {
        match self {
            Self::Blocks { header, .. } => header.channels.list.iter().any(|c| c.name.to_string() == name),
            Self::Decoded(exr) => exr.has(name),
        }
    }

    /// Fills every target with its channels ([`exr_zip::Target`]); each target holds
    /// `stride` values for each of the [`size`](Self::size)'s pixels.
    pub fn fill(self, file: &Path, what: &str, targets: &mut [exr_zip::Target]) -> Result<(), SceneError> {
        match self {
            Self::Blocks { bytes, .. } => exr_zip::read_into(file, what, &bytes, targets),
            Self::Decoded(mut exr) => {
                const PIXELS: usize = 256;
                for target in targets {
                    for (name, offset) in &target.channels {
                        let samples = exr.take_samples(file, name)?;
                        let stride = target.stride;
                        target.values.par_chunks_mut(stride * PIXELS).enumerate().for_each(|(block, out)| {
                            let mut values = [0.0f32; PIXELS];
                            let values = &mut values[..out.len() / stride];
                            samples_to_f32(&samples, block * PIXELS, values);
                            for (pixel, &value) in out.chunks_exact_mut(stride).zip(values.iter()) {
                                pixel[*offset] = value;
                            }
                        });
                    }
                }
                Ok(())
            }
        }
    }
}
