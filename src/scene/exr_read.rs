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
//! The full name of a channel is therefore the stored name when it already starts with
//! `<part name>.`, and `<part name>.<channel>` otherwise; the stored name is also kept
//! as an alias (first part wins), so that `R` finds an environment map's red channel in
//! any layout ([`ChannelDirectory`]).

use super::error::{check_image_size, exr_error, SceneError};
use super::exr_zip;
pub(crate) use super::exr_zip::PartChannel;
use exr::meta::header::Header;
use exr::prelude::{read, FlatSamples, ReadChannels, ReadLayers};
use half::slice::HalfFloatSliceExt;
use rayon::prelude::*;
use std::collections::HashMap;
use std::path::Path;

/// Every channel of a file by its full dotted name (the module doc), and by its name as
/// stored where no full name is the same.
pub(crate) struct ChannelDirectory {
    /// Full dotted names in file order, each once (without aliases), for error messages.
    pub names: Vec<String>,
    found: HashMap<String, PartChannel>,
}

impl ChannelDirectory {
    pub fn new(headers: &[Header]) -> Self {
        let mut directory = ChannelDirectory { names: Vec::new(), found: HashMap::new() };
        let mut aliases = Vec::new();
        for (part, header) in headers.iter().enumerate() {
            let prefix = header.own_attributes.layer_name.as_ref().map(|t| t.to_string()).filter(|p| !p.is_empty());
            for (channel, description) in header.channels.list.iter().enumerate() {
                let stored = description.name.to_string();
                let full = match &prefix {
                    Some(p) if !stored.starts_with(&format!("{p}.")) => format!("{p}.{stored}"),
                    _ => stored.clone(),
                };
                let at = PartChannel { part, channel };
                if !directory.found.contains_key(&full) {
                    directory.found.insert(full.clone(), at);
                    directory.names.push(full.clone());
                }
                if stored != full {
                    aliases.push((stored, at));
                }
            }
        }
        for (alias, at) in aliases {
            directory.found.entry(alias).or_insert(at);
        }
        directory
    }

    pub fn find(&self, name: &str) -> Option<PartChannel> {
        self.found.get(name).copied()
    }

    /// The error for a channel the file lacks, listing those it has.
    pub fn missing(&self, file: &Path, name: &str) -> SceneError {
        SceneError::MissingChannel { file: file.to_path_buf(), channel: name.to_string(), found: self.names.clone() }
    }
}

/// The error for a channel whose part is not the size the channels taken must have.
pub(crate) fn size_mismatch(file: &Path, name: &str, found: (usize, usize), expected: (usize, usize)) -> SceneError {
    SceneError::invalid(
        file,
        format!(
            "channel \"{name}\" is {}x{} but the other channels are {}x{}",
            found.0, found.1, expected.0, expected.1
        ),
    )
}

/// The channels of one EXR file, all of the same size, kept as stored and converted to
/// f32 when taken (a frame with transfer layers holds about 90 channels, of which a
/// reader takes some: converting all of them first doubled the memory a read touched).
pub(crate) struct ExrChannels {
    pub width: usize,
    pub height: usize,
    pub directory: ChannelDirectory,
    /// Each part's channels, in the order of its channel list.
    data: Vec<Vec<FlatSamples>>,
    sizes: Vec<(usize, usize)>,
}

impl ExrChannels {
    /// Reads every channel of every part. The size of every part is checked against the
    /// limits before its pixels are allocated.
    pub fn read(file: &Path, what: &str) -> Result<Self, SceneError> {
        let (bytes, meta) = read_with_headers(file, what)?;
        Self::decode(file, what, &bytes, &meta.headers)
    }

    /// Every channel of `file`, read as `bytes`, whose parts' headers are `headers`.
    fn decode(file: &Path, what: &str, bytes: &[u8], headers: &[Header]) -> Result<Self, SceneError> {
        check_parts(file, headers)?;
        let image = read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .all_layers()
            .all_attributes()
            .from_buffered(std::io::Cursor::new(bytes))
            .map_err(|e| exr_error(file, what, e))?;
        // The crate reads a layer per header and a channel per entry of its list, in order.
        let sizes: Vec<(usize, usize)> = image.layer_data.iter().map(|layer| (layer.size.0, layer.size.1)).collect();
        let data: Vec<Vec<FlatSamples>> = image
            .layer_data
            .into_iter()
            .map(|layer| layer.channel_data.list.into_iter().map(|channel| channel.sample_data).collect())
            .collect();
        let (width, height) = sizes.first().copied().unwrap_or_default();
        Ok(ExrChannels { width, height, directory: ChannelDirectory::new(headers), data, sizes })
    }

    pub fn has(&self, name: &str) -> bool {
        self.directory.find(name).is_some()
    }

    /// The channel's values, row after row from the top row of the image. All channels
    /// taken from one file must have the size of the first one taken, which becomes
    /// `width` x `height`.
    pub fn take(&mut self, file: &Path, name: &str) -> Result<Vec<f32>, SceneError> {
        let samples = self.samples(file, name)?;
        let mut out = vec![0.0f32; samples.len()];
        samples_to_f32(samples, 0, &mut out);
        Ok(out)
    }

    /// The channel as stored, checked to exist and to have the reference size.
    fn samples(&self, file: &Path, name: &str) -> Result<&FlatSamples, SceneError> {
        let at = self.directory.find(name).ok_or_else(|| self.directory.missing(file, name))?;
        let size = self.sizes[at.part];
        if size != (self.width, self.height) {
            return Err(size_mismatch(file, name, size, (self.width, self.height)));
        }
        Ok(&self.data[at.part][at.channel])
    }

    /// Makes the size of `name`'s part the reference size for later `take` calls.
    pub fn use_size_of(&mut self, name: &str) {
        if let Some(at) = self.directory.find(name) {
            (self.width, self.height) = self.sizes[at.part];
        }
    }
}

/// `file`'s bytes and its headers.
pub(crate) fn read_with_headers(file: &Path, what: &str) -> Result<(Vec<u8>, exr::meta::MetaData), SceneError> {
    let bytes = std::fs::read(file).map_err(|e| SceneError::io(file, what, e))?;
    let meta = exr::meta::MetaData::read_from_buffered(std::io::Cursor::new(&bytes), false)
        .map_err(|e| exr_error(file, what, e))?;
    Ok((bytes, meta))
}

/// Refuses a file with no parts, a part too large to allocate, or deep data.
fn check_parts(file: &Path, headers: &[Header]) -> Result<(), SceneError> {
    if headers.is_empty() {
        return Err(SceneError::Image { file: file.to_path_buf(), message: "the file has no image parts".into() });
    }
    for header in headers {
        check_image_size(file, header.layer_size.0, header.layer_size.1)?;
        if header.deep {
            return Err(SceneError::Image {
                file: file.to_path_buf(),
                message: "deep EXR data is not supported".into(),
            });
        }
    }
    Ok(())
}

/// Samples `first..first + out.len()` as f32: half floats exactly (through F16C where the
/// processor has it), 32-bit unsigned integers to the nearest f32.
fn samples_to_f32(samples: &FlatSamples, first: usize, out: &mut [f32]) {
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
/// from its blocks where [`exr_zip::decodes`] every part (what `logsh render` writes, and
/// Blender's G-buffers in its default ZIP), through [`ExrChannels`] otherwise (tiles,
/// other compressions). Only the parts holding a channel taken are decoded.
pub(crate) enum ChannelFile {
    /// `part_sizes[p]` is part `p`'s width and height.
    Blocks {
        source: BlockSource,
        part_sizes: Vec<(usize, usize)>,
        directory: ChannelDirectory,
        size: (usize, usize),
    },
    Decoded(ExrChannels),
}

/// Where [`ChannelFile::Blocks`] reads its blocks from: the file's bytes, read whole, or
/// the file itself, from which only the blocks of the lines asked for are read.
pub(crate) enum BlockSource {
    Bytes(Vec<u8>),
    File,
}

impl ChannelFile {
    /// Reads `file`, whose channels taken must all have the size of `size_of`'s part.
    pub fn read(file: &Path, what: &str, size_of: &str) -> Result<Self, SceneError> {
        let (bytes, meta) = read_with_headers(file, what)?;
        Self::new(file, what, bytes, &meta, size_of)
    }

    /// Opens `file` for reading its lines in bands ([`ChannelFile::fill_lines`]): only
    /// its headers are read now, and each band reads only its own blocks, so that the
    /// memory a frame of any size takes is that of its bands. A file whose parts the
    /// blocks do not decode (tiles, other compressions) is decoded whole.
    pub fn open(file: &Path, what: &str, size_of: &str) -> Result<Self, SceneError> {
        let meta = exr::meta::MetaData::read_from_file(file, false).map_err(|e| exr_error(file, what, e))?;
        if !meta.headers.iter().all(exr_zip::decodes) {
            let bytes = std::fs::read(file).map_err(|e| SceneError::io(file, what, e))?;
            return Self::new(file, what, bytes, &meta, size_of);
        }
        let length = std::fs::metadata(file).map_err(|e| SceneError::io(file, what, e))?.len();
        Self::blocks(file, BlockSource::File, usize::try_from(length).unwrap_or(usize::MAX), &meta, size_of)
    }

    /// The size of `size_of`'s part of `file` (its first part's where it lacks the
    /// channel), from its headers alone.
    pub fn size_from_headers(file: &Path, what: &str, size_of: &str) -> Result<(usize, usize), SceneError> {
        let meta = exr::meta::MetaData::read_from_file(file, false).map_err(|e| exr_error(file, what, e))?;
        check_parts(file, &meta.headers)?;
        let part = ChannelDirectory::new(&meta.headers).find(size_of).map_or(0, |at| at.part);
        let size = meta.headers[part].layer_size;
        Ok((size.0, size.1))
    }

    /// `file` as `bytes`, its header already read as `meta`; `size_of` names the channel
    /// whose part gives the size every channel taken must have.
    pub fn new(
        file: &Path,
        what: &str,
        bytes: Vec<u8>,
        meta: &exr::meta::MetaData,
        size_of: &str,
    ) -> Result<Self, SceneError> {
        if !meta.headers.iter().all(exr_zip::decodes) {
            let mut exr = ExrChannels::decode(file, what, &bytes, &meta.headers)?;
            exr.use_size_of(size_of);
            return Ok(Self::Decoded(exr));
        }
        let length = bytes.len();
        Self::blocks(file, BlockSource::Bytes(bytes), length, meta, size_of)
    }

    fn blocks(
        file: &Path,
        source: BlockSource,
        length: usize,
        meta: &exr::meta::MetaData,
        size_of: &str,
    ) -> Result<Self, SceneError> {
        check_parts(file, &meta.headers)?;
        // Deflate packs at most 1032 bytes into one, so a file whose pixels could not fit
        // in it is refused before they are allocated.
        let raw: usize = meta
            .headers
            .iter()
            .map(|h| (h.layer_size.0 * h.layer_size.1).saturating_mul(h.channels.bytes_per_pixel))
            .fold(0, usize::saturating_add);
        if raw / exr_zip::MOST_DEFLATED > length {
            return Err(SceneError::Image {
                file: file.to_path_buf(),
                message: format!(
                    "its pixels, {raw} bytes decoded, cannot fit in its {length} bytes; write or copy it again"
                ),
            });
        }
        let directory = ChannelDirectory::new(&meta.headers);
        let part_sizes: Vec<(usize, usize)> = meta.headers.iter().map(|h| (h.layer_size.0, h.layer_size.1)).collect();
        let size = part_sizes[directory.find(size_of).map_or(0, |at| at.part)];
        Ok(Self::Blocks { source, part_sizes, directory, size })
    }

    pub fn size(&self) -> (usize, usize) {
        match self {
            Self::Blocks { size, .. } => *size,
            Self::Decoded(exr) => (exr.width, exr.height),
        }
    }

    pub fn has(&self, name: &str) -> bool {
        match self {
            Self::Blocks { directory, .. } => directory.find(name).is_some(),
            Self::Decoded(exr) => exr.has(name),
        }
    }

    /// Fills every target with its channels ([`exr_zip::Target`]); each target holds
    /// `stride` values for each of the [`size`](Self::size)'s pixels. A channel the file
    /// lacks, or whose part is of another size, is an error naming it.
    pub fn fill(&self, file: &Path, what: &str, targets: &mut [exr_zip::Target]) -> Result<(), SceneError> {
        self.fill_lines(file, what, 0..self.size().1, targets)
    }

    /// [`fill`](Self::fill) with the scan lines `lines` only: each target holds `stride`
    /// values for each of their pixels. `lines` starts on a multiple of
    /// [`exr_zip::LINES_PER_BLOCK`] and ends on one or at the bottom.
    pub fn fill_lines(
        &self,
        file: &Path,
        what: &str,
        lines: std::ops::Range<usize>,
        targets: &mut [exr_zip::Target],
    ) -> Result<(), SceneError> {
        match self {
            Self::Blocks { source, part_sizes, directory, size } => {
                let mut parts = Vec::new();
                for target in targets.iter() {
                    let mut found = Vec::new();
                    for (name, _) in &target.channels {
                        let at = directory.find(name).ok_or_else(|| directory.missing(file, name))?;
                        let part = part_sizes[at.part];
                        if part != *size {
                            return Err(size_mismatch(file, name, part, *size));
                        }
                        found.push(at);
                    }
                    parts.push(found);
                }
                match source {
                    BlockSource::Bytes(bytes) => {
                        let source = std::io::Cursor::new(bytes.as_slice());
                        exr_zip::read_into(file, what, source, *size, lines, targets, &parts)
                    }
                    BlockSource::File => {
                        let opened = std::fs::File::open(file).map_err(|e| SceneError::io(file, what, e))?;
                        let source = std::io::BufReader::new(opened);
                        exr_zip::read_into(file, what, source, *size, lines, targets, &parts)
                    }
                }
            }
            Self::Decoded(exr) => {
                const PIXELS: usize = 256;
                let first = lines.start * exr.width;
                for target in targets {
                    for (name, offset) in &target.channels {
                        let samples = exr.samples(file, name)?;
                        let stride = target.stride;
                        target.values.par_chunks_mut(stride * PIXELS).enumerate().for_each(|(block, out)| {
                            let mut values = [0.0f32; PIXELS];
                            let values = &mut values[..out.len() / stride];
                            samples_to_f32(samples, first + block * PIXELS, values);
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

#[cfg(test)]
mod tests {
    use super::*;
    use exr::prelude::*;

    /// A Blender 5 style part (channel names prefixed), a Nuke style part (names bare),
    /// ZIP in blocks of 16 lines and of one, no compression, halves, floats and integers,
    /// and a part of another size; written by the `exr` crate with `zip` for the first two
    /// parts' compression.
    fn write_parts(file: &Path, zip: Compression) {
        let (width, height) = (37, 35);
        let value = |k: usize, i: usize| ((i * (k + 3)) % 101) as f32 / 7.0 - 5.0 + k as f32;
        let floats = |name: &str, k: usize| {
            AnyChannel::new(name, FlatSamples::F32((0..width * height).map(|i| value(k, i)).collect()))
        };
        let halves = |name: &str, k: usize| {
            AnyChannel::new(name, FlatSamples::F16((0..width * height).map(|i| f16::from_f32(value(k, i))).collect()))
        };
        let encoding =
            |compression| Encoding { compression, blocks: Blocks::ScanLines, line_order: LineOrder::Increasing };
        let layer = |name: &str, size: (usize, usize), compression, channels: Vec<AnyChannel<FlatSamples>>| {
            Layer::new(size, LayerAttributes::named(name), encoding(compression), AnyChannels::sort(channels.into()))
        };
        let ids = AnyChannel::new("id", FlatSamples::U32((0..width * height).map(|i| i as u32 * 977).collect()));
        let layers = vec![
            layer(
                "ViewLayer.Combined",
                (width, height),
                zip,
                vec![halves("ViewLayer.Combined.A", 0), halves("ViewLayer.Combined.R", 1)],
            ),
            layer(
                "ViewLayer.Position",
                (width, height),
                Compression::ZIP1,
                vec![floats("ViewLayer.Position.X", 2), floats("ViewLayer.Position.Z", 3)],
            ),
            layer("Nuke", (width, height), Compression::Uncompressed, vec![floats("X", 4), halves("Y", 5), ids]),
            layer("Small", (5, 3), zip, vec![AnyChannel::new("Q", FlatSamples::F32(vec![1.0; 15]))]),
        ];
        let image = Image::from_layers(ImageAttributes::new(IntegerBounds::from_dimensions((width, height))), layers);
        image.write().to_file(file).unwrap();
    }

    /// Channels from every kind of part, in two targets that mix them, read from the
    /// blocks where every part is ZIP or uncompressed scan lines, and through the `exr`
    /// crate where one is not: both bit for bit as [`ExrChannels`] takes them, by full
    /// name and by bare alias, and both refusing a missing channel and one of another size.
    #[test]
    fn every_layout_reads_the_same_from_the_blocks_as_through_the_crate() {
        let dir = tempfile::tempdir().unwrap();
        let first = ["ViewLayer.Position.X", "Nuke.X", "ViewLayer.Combined.A", "Nuke.id"];
        let second = ["Y", "ViewLayer.Position.Z", "ViewLayer.Combined.R"];
        for (zip, from_blocks) in [(Compression::ZIP16, true), (Compression::RLE, false)] {
            let file = dir.path().join(format!("{zip:?}.exr"));
            write_parts(&file, zip);
            let mut expected = ExrChannels::read(&file, "a test file").unwrap();
            assert_eq!(expected.directory.names.len(), 8);
            let read = || ChannelFile::read(&file, "a test file", "ViewLayer.Position.X").unwrap();
            assert_eq!(matches!(read(), ChannelFile::Blocks { .. }), from_blocks, "{zip:?}");
            assert_eq!(read().size(), (37, 35));
            assert!(read().has("Nuke.Y") && read().has("Y") && !read().has("ViewLayer.Position.Y"));

            let n = 37 * 35;
            let (mut a, mut b) = (vec![f32::NAN; 4 * n], vec![f32::NAN; 3 * n]);
            let in_order = |names: &[&str]| names.iter().map(|s| s.to_string()).zip(0..).collect::<Vec<_>>();
            let mut targets = [
                exr_zip::Target { values: &mut a, stride: 4, channels: in_order(&first) },
                exr_zip::Target { values: &mut b, stride: 3, channels: in_order(&second) },
            ];
            read().fill(&file, "a test file", &mut targets).unwrap();
            for (values, names) in [(&a, &first[..]), (&b, &second[..])] {
                for (k, name) in names.iter().enumerate() {
                    let channel = expected.take(&file, name).unwrap();
                    let bits: Vec<u32> = values.iter().skip(k).step_by(names.len()).map(|v| v.to_bits()).collect();
                    assert_eq!(bits, channel.iter().map(|v| v.to_bits()).collect::<Vec<_>>(), "{zip:?} {name}");
                }
            }

            let refused = |name: &str| {
                let mut values = vec![0.0; n];
                let mut targets = [exr_zip::Target { values: &mut values, stride: 1, channels: in_order(&[name]) }];
                read().fill(&file, "a test file", &mut targets).unwrap_err().to_string()
            };
            let error = refused("Small.Q");
            assert!(error.contains("\"Small.Q\" is 5x3 but the other channels are 37x35"), "{zip:?}: {error}");
            let error = refused("Nuke.Z");
            assert!(error.contains("\"Nuke.Z\"") && error.contains("\"Nuke.id\""), "{zip:?}: {error}");
        }
    }
}
