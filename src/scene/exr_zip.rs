//! The blocks of a ZIP-compressed scan-line EXR, encoded for every EXR logsh writes and
//! decoded for a frame with transfer layers and for a G-buffer, any number of parts; the
//! `exr` crate still writes the header and the block table, and reads them.
//!
//! The format is OpenEXR's (`ImfZip.cpp`, "Technical introduction to OpenEXR"): a block
//! holds 16 scan lines (ZIP) or one (ZIPS), each line its channels in name order, each
//! channel its samples little-endian; its bytes are split into the even and the odd ones,
//! each byte replaced by its difference from the previous plus 128, and the result
//! deflated in a zlib stream. A block that does not shrink is stored as it is, which every
//! reader recognises by its length.
//!
//! Why not the crate's encoder and decoder: it deflates with `miniz_oxide` at level 4,
//! and it copies every channel into a buffer of its own on the way in and out; zlib-rs at
//! the same level writes files within 1.3 % of its sizes in about half its time
//! (docs/performance-log.md). Here channels
//! are read in place from pixel-major data ([`OutputChannel::stride`]) and decoded
//! straight into it ([`Target`]); docs/performance-log.md times both ends.

use exr::block::chunk::{Chunk, CompressedBlock, CompressedScanLineBlock};
use exr::block::writer::ChunksWriter;
use exr::meta::attribute::{ChannelDescription, IntegerBounds, SampleType as ExrSampleType};
use exr::meta::header::{Header, ImageAttributes, LayerAttributes};
use exr::meta::BlockDescription;
use exr::prelude::{f16, Compression, LineOrder, SmallVec};
use half::slice::HalfFloatSliceExt;
use rayon::prelude::*;
use std::io::Write;

use super::error::{exr_error, SceneError};
use std::path::Path;

/// Where a channel lies in a file: its part, and its place in that part's channel list.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct PartChannel {
    pub part: usize,
    pub channel: usize,
}

/// How a channel is stored (`logsh render --colour-type`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SampleType {
    /// 16-bit float: half the size, 11 significant bits, plenty for colour (relative error below 5e-4).
    Half,
    /// 32-bit float: for data (positions, normals) that needs its precision.
    Float,
}

/// One output channel: full name, storage type, values row-major from the top row,
/// pixel `i`'s at `values[i * stride]` (a channel of pixel-major data is written from it
/// without a copy).
pub struct OutputChannel<'a> {
    pub name: String,
    pub sample_type: SampleType,
    pub values: &'a [f32],
    pub stride: usize,
}

impl<'a> OutputChannel<'a> {
    /// A channel of one value per pixel.
    pub fn new(name: &str, sample_type: SampleType, values: &'a [f32]) -> Self {
        Self { name: name.to_string(), sample_type, values, stride: 1 }
    }

    /// Value `offset` of each pixel's `stride` values in `values`.
    pub fn interleaved(name: String, sample_type: SampleType, values: &'a [f32], stride: usize, offset: usize) -> Self {
        Self { name, sample_type, values: values.get(offset..).unwrap_or_default(), stride }
    }

    /// The channels `layer.<name>` (plain `<name>` for an empty layer) of pixel-major
    /// `values`, each pixel's values in the order of `names`.
    pub fn layer(layer: &str, names: &[&str], values: &'a [f32], sample_type: SampleType) -> Vec<Self> {
        let name = |channel: &str| if layer.is_empty() { channel.to_string() } else { format!("{layer}.{channel}") };
        (names.iter().enumerate())
            .map(|(k, channel)| Self::interleaved(name(channel), sample_type, values, names.len(), k))
            .collect()
    }

    /// The channel's rows `rows` of an image `width` pixels wide, without a copy.
    pub fn rows(&self, width: usize, rows: std::ops::Range<usize>) -> OutputChannel<'a> {
        let at = |row: usize| (row * width * self.stride).min(self.values.len());
        let values = &self.values[at(rows.start)..at(rows.end)];
        OutputChannel { name: self.name.clone(), sample_type: self.sample_type, values, stride: self.stride }
    }

    /// The number of pixels `values` holds (none at a stride of 0, which is refused).
    pub fn pixels(&self) -> usize {
        if self.stride == 0 {
            0
        } else {
            self.values.len().div_ceil(self.stride)
        }
    }
}

/// Scan lines per block of ZIP (OpenEXR's `ZIP_COMPRESSION`).
pub const LINES_PER_BLOCK: usize = 16;

/// The most bytes deflate can pack into one (258-byte matches of the last byte, each in
/// two bits): a block cannot decode to more than this times its size.
pub const MOST_DEFLATED: usize = 1032;

/// zlib's level: 4 keeps the `exr` crate's sizes (within 1.3 %) at half its time.
const LEVEL: u32 = 4;

/// Writes `channels` (each `width * height` values, row-major from the top row; names
/// distinct) into `out` as one ZIP-compressed scan-line part with `attributes`. The
/// blocks are encoded in parallel, then written in order.
pub fn write(
    out: impl Write + std::io::Seek,
    width: usize,
    height: usize,
    channels: &[OutputChannel],
    attributes: LayerAttributes,
) -> exr::error::UnitResult {
    let names: Vec<(String, SampleType)> = channels.iter().map(|c| (c.name.clone(), c.sample_type)).collect();
    write_in_bands(out, width, height, &names, attributes, |bands| bands.write_rows(0, channels))
}

/// Writes one ZIP-compressed scan-line part of the channels `names` (distinct, with
/// their sample types) as `fill` hands it bands of rows ([`BandSink::write_rows`]), from
/// the top, every row once: a frame of any height is written holding one band at a time.
/// An error of `fill` stops the writing and is returned.
pub fn write_in_bands<W: Write + std::io::Seek>(
    out: W,
    width: usize,
    height: usize,
    names: &[(String, SampleType)],
    attributes: LayerAttributes,
    fill: impl FnOnce(&mut BandSink<W>) -> exr::error::UnitResult,
) -> exr::error::UnitResult {
    let mut sorted: Vec<(String, SampleType)> = names.to_vec();
    sorted.sort_by(|a, b| a.0.as_bytes().cmp(b.0.as_bytes()));
    let descriptions = sorted
        .iter()
        .map(|(name, sample_type)| {
            let kind = match sample_type {
                SampleType::Half => ExrSampleType::F16,
                SampleType::Float => ExrSampleType::F32,
            };
            ChannelDescription::named(name.as_str(), kind)
        })
        .collect::<SmallVec<_>>();
    let header = Header::new(exr::meta::attribute::Text::default(), (width, height), descriptions)
        .with_encoding(Compression::ZIP16, BlockDescription::ScanLines, LineOrder::Increasing)
        .with_attributes(attributes)
        .with_shared_attributes(ImageAttributes::new(IntegerBounds::from_dimensions((width, height))));
    exr::block::write(out, std::iter::once(header).collect(), true, |_, writer| {
        let mut sink = BandSink { writer, width, height, names: sorted, next_row: 0 };
        fill(&mut sink)?;
        if sink.next_row != height {
            return Err(invalid(format!("{} of {height} rows were written", sink.next_row)));
        }
        Ok(())
    })
}

fn invalid(message: String) -> exr::error::Error {
    exr::error::Error::Invalid(message.into())
}

/// Where [`write_in_bands`] takes its bands.
pub struct BandSink<'w, W> {
    writer: &'w mut exr::block::writer::ChunkWriter<W>,
    width: usize,
    height: usize,
    names: Vec<(String, SampleType)>,
    next_row: usize,
}

impl<W: Write + std::io::Seek> BandSink<'_, W> {
    /// Writes the rows from `first_row` on, as many as `channels` hold: the next rows of
    /// the part, a whole number of blocks (or the rest of the part), the part's channels
    /// (in any order). The band's blocks are encoded in parallel, then written in order.
    pub fn write_rows(&mut self, first_row: usize, channels: &[OutputChannel]) -> exr::error::UnitResult {
        let mut sorted: Vec<&OutputChannel> = channels.iter().collect();
        sorted.sort_by(|a, b| a.name.as_bytes().cmp(b.name.as_bytes()));
        let same = sorted.len() == self.names.len()
            && sorted.iter().zip(&self.names).all(|(c, (name, kind))| c.name == *name && c.sample_type == *kind);
        if !same {
            return Err(invalid("a band's channels are not the part's".into()));
        }
        let rows = sorted.first().map_or(0, |c| c.values.len().div_ceil(c.stride.max(1)) / self.width.max(1));
        let end = first_row + rows;
        if first_row != self.next_row || end > self.height || (end % LINES_PER_BLOCK != 0 && end != self.height) {
            return Err(invalid(format!("rows {first_row}..{end} do not continue the part's {} rows", self.next_row)));
        }
        let (width, first_block) = (self.width, first_row / LINES_PER_BLOCK);
        let chunks: Vec<Chunk> = (first_block..end.div_ceil(LINES_PER_BLOCK))
            .into_par_iter()
            .map(|block| {
                let lines = block * LINES_PER_BLOCK..((block + 1) * LINES_PER_BLOCK).min(end);
                let y_coordinate = lines.start as i32;
                let raw = block_bytes(&sorted, width, lines.start - first_row..lines.end - first_row);
                Chunk {
                    layer_index: 0,
                    compressed_block: CompressedBlock::ScanLine(CompressedScanLineBlock {
                        y_coordinate,
                        compressed_pixels_le: compress(raw),
                    }),
                }
            })
            .collect();
        for (index, chunk) in (first_block..).zip(chunks) {
            self.writer.write_chunk(index, chunk)?;
        }
        self.next_row = end;
        Ok(())
    }
}
/// The largest finite half float.
const HALF_MAX: f32 = 65504.0;

/// The uncompressed bytes of the scan lines `rows`: each line its channels in order.
fn block_bytes(channels: &[&OutputChannel], width: usize, rows: std::ops::Range<usize>) -> Vec<u8> {
    let bytes_per_pixel: usize = channels.iter().map(|c| sample_bytes(c.sample_type)).sum();
    let mut raw = Vec::with_capacity(bytes_per_pixel * width * rows.len());
    let (mut line, mut halves) = (vec![0.0f32; width], vec![f16::ZERO; width]);
    for y in rows {
        for channel in channels {
            let stride = channel.stride;
            let values = channel.values[y * width * stride..].iter().step_by(stride);
            for (v, &value) in line.iter_mut().zip(values) {
                *v = value;
            }
            match channel.sample_type {
                SampleType::Half => {
                    // A value beyond half's range is written as its largest finite value
                    // (65504), not as infinity: a file stays finite, and a transfer layer
                    // reads back (a relight refuses infinities). `--colour-type float`
                    // keeps such values.
                    for v in &mut line {
                        *v = v.clamp(-HALF_MAX, HALF_MAX);
                    }
                    halves.convert_from_f32_slice(&line);
                    raw.extend(halves.iter().flat_map(|h| h.to_le_bytes()));
                }
                SampleType::Float => raw.extend(line.iter().flat_map(|v| v.to_le_bytes())),
            }
        }
    }
    raw
}

fn sample_bytes(kind: SampleType) -> usize {
    match kind {
        SampleType::Half => 2,
        SampleType::Float => 4,
    }
}

/// OpenEXR's ZIP encoding of a block's bytes (the module doc), or the bytes as they are
/// where that is not smaller.
fn compress(raw: Vec<u8>) -> Vec<u8> {
    let predicted = predict(&raw);
    let mut encoder =
        flate2::write::ZlibEncoder::new(Vec::with_capacity(raw.len() / 4), flate2::Compression::new(LEVEL));
    let deflated = encoder.write_all(&predicted).and_then(|()| encoder.finish());
    match deflated {
        Ok(deflated) if deflated.len() < raw.len() => deflated,
        // A `Vec` sink cannot fail; either way the raw bytes are a valid block.
        _ => raw,
    }
}

/// The even bytes, then the odd ones, each as its difference from the one before plus
/// 128 (wrapping): OpenEXR's byte reordering and predictor.
fn predict(raw: &[u8]) -> Vec<u8> {
    let mut out = vec![0u8; raw.len()];
    let (evens, odds) = out.split_at_mut(raw.len().div_ceil(2));
    for (i, pair) in raw.chunks(2).enumerate() {
        evens[i] = pair[0];
        if let [_, odd] = pair {
            odds[i] = *odd;
        }
    }
    let mut previous = out.first().copied().unwrap_or(0);
    for byte in out.iter_mut().skip(1) {
        let current = *byte;
        *byte = current.wrapping_sub(previous).wrapping_add(128);
        previous = current;
    }
    out
}

/// Where the samples of some channels go, as f32: channel `name` at `offset` fills
/// `values[pixel * stride + offset]` for every pixel, row-major from the top row.
pub struct Target<'a> {
    pub values: &'a mut [f32],
    pub stride: usize,
    pub channels: Vec<(String, usize)>,
}

/// Whether [`read_into`] decodes the part `header`: scan lines, uncompressed or ZIP, no
/// subsampling.
pub fn decodes(header: &Header) -> bool {
    matches!(header.compression, Compression::ZIP16 | Compression::ZIP1 | Compression::Uncompressed)
        && header.blocks == BlockDescription::ScanLines
        && !header.deep
        && header.channels.list.iter().all(|c| c.sampling == exr::math::Vec2(1, 1))
}

/// Fills `targets` with the scan lines `rows` of an EXR `file` whose every part
/// [`decodes`], read from `source` (its bytes, or the file itself: only the blocks of
/// `rows` are read, seeking past the rest), decoding the blocks of the parts it takes
/// channels from in parallel straight into them; the other parts are not read. Target
/// `t`'s channel `k` lies at `found[t][k]`, in a part of `size`; each target holds
/// `stride` values for each pixel of `rows`. `rows` starts on a block's first line (a
/// multiple of [`LINES_PER_BLOCK`]) and ends on one or at the bottom.
///
/// Halves convert exactly.
pub fn read_into(
    file: &Path,
    what: &str,
    source: impl std::io::Read + std::io::Seek,
    size: (usize, usize),
    rows: std::ops::Range<usize>,
    targets: &mut [Target],
    found: &[Vec<PartChannel>],
) -> Result<(), SceneError> {
    let (width, height) = size;
    debug_assert!(rows.start % LINES_PER_BLOCK == 0 && (rows.end % LINES_PER_BLOCK == 0 || rows.end == height));
    debug_assert!(rows.end <= height);
    let reader = exr::block::read(source, false).map_err(|e| exr_error(file, what, e))?;
    let headers = reader.headers();
    if !headers.iter().all(decodes) {
        return Err(SceneError::invalid(file, "holds a part that is not ZIP or uncompressed scan lines"));
    }
    let mut parts: Vec<Part> =
        headers.iter().enumerate().map(|(p, header)| Part::new(header, p, targets.len())).collect();
    for (t, (target, found)) in targets.iter().zip(found).enumerate() {
        debug_assert_eq!(target.values.len(), width * rows.len() * target.stride);
        for ((name, offset), at) in target.channels.iter().zip(found) {
            debug_assert!(*offset < target.stride, "{name} at {offset} of a pixel's {}", target.stride);
            let part = &mut parts[at.part];
            debug_assert_eq!(part.width, width, "{name}'s part");
            let (at, kind) = part.layout[at.channel];
            part.routes[t].push(Route { at, kind, offset: *offset });
        }
    }
    let used: Vec<bool> = parts.iter().map(|part| part.routes.iter().any(|r| !r.is_empty())).collect();
    for (part, _) in parts.iter_mut().zip(&used).filter(|(_, &used)| used) {
        part.first_block = rows.start / part.lines;
        part.blocks = vec![None; rows.end.div_ceil(part.lines) - part.first_block];
    }
    let wanted = |block: &exr::block::BlockIndex| {
        let top = block.pixel_position.y();
        used[block.layer] && top < rows.end && top + block.pixel_size.y() > rows.start
    };
    let chunks = reader.filter_chunks(false, |_, _, block| wanted(&block)).map_err(|e| exr_error(file, what, e))?;
    for chunk in chunks {
        let chunk = chunk.map_err(|e| exr_error(file, what, e))?;
        let Some(part) = parts.get_mut(chunk.layer_index) else {
            return Err(SceneError::invalid(
                file,
                format!("has a block of part {}, which it lacks", chunk.layer_index),
            ));
        };
        let CompressedBlock::ScanLine(block) = chunk.compressed_block else {
            return Err(SceneError::invalid(file, format!("holds a tile in the scan lines{}", part.label)));
        };
        let index = usize::try_from(i64::from(block.y_coordinate) - i64::from(part.top))
            .ok()
            .and_then(|y| (y / part.lines).checked_sub(part.first_block));
        match index.and_then(|i| part.blocks.get_mut(i)) {
            Some(slot @ None) => *slot = Some(block.compressed_pixels_le),
            _ => {
                return Err(SceneError::invalid(
                    file,
                    format!("has a stray block at line {}{}", block.y_coordinate, part.label),
                ))
            }
        }
    }
    // Blocks are decoded in groups of rows that every part's blocks divide (ZIP's 16
    // lines, or single lines), each group's parts one after another: the parts' channels
    // may share a target's pixels.
    let group_lines = parts.iter().zip(&used).filter(|(_, &used)| used).map(|(part, _)| part.lines).max().unwrap_or(1);
    let mut per_group: Vec<Vec<PartBlock>> = (0..rows.len().div_ceil(group_lines)).map(|_| Vec::new()).collect();
    for (p, part) in parts.iter_mut().enumerate() {
        let first_block = part.first_block;
        for (slot, bytes) in std::mem::take(&mut part.blocks).into_iter().enumerate() {
            let index = first_block + slot;
            per_group[(index * part.lines - rows.start) / group_lines].push(PartBlock { part: p, index, bytes });
        }
    }
    let strides: Vec<usize> = targets.iter().map(|t| t.stride).collect();
    let mut outputs: Vec<Vec<&mut [f32]>> = per_group.iter().map(|_| Vec::with_capacity(targets.len())).collect();
    for target in targets.iter_mut() {
        for (slot, lines) in outputs.iter_mut().zip(target.values.chunks_mut(group_lines * width * target.stride)) {
            slot.push(lines);
        }
    }
    // Blocks are inflated into buffers kept from block to block (a block is 3 MB at
    // 960x540 with transfer layers: a fresh buffer per block faulted in every page of the
    // frame's 100 MB once more), taken from a pool and returned, so that no lock is held
    // while the block's lines are scattered in tasks of their own.
    let pool = std::sync::Mutex::new(Vec::<Inflater>::new());
    let most = parts.iter().flat_map(|part| part.routes.iter().map(Vec::len)).max().unwrap_or(0);
    let decoder = BlockDecoder { file, width, height, strides: &strides, pool: &pool, most };
    per_group.into_par_iter().zip(outputs).enumerate().try_for_each(|(group, (blocks, mut outputs))| {
        for PartBlock { part: p, index, bytes } in blocks {
            let part = &parts[p];
            let first = index * part.lines - rows.start - group * group_lines;
            let lines = part.lines.min(height - index * part.lines);
            let block_outputs = outputs
                .iter_mut()
                .zip(&strides)
                .map(|(out, &stride)| &mut out[first * width * stride..(first + lines) * width * stride])
                .collect();
            decoder.decode(part, index, bytes, block_outputs)?;
        }
        Ok(())
    })
}

/// Block `index` of part `part`, as stored; `None` where the file lacks it.
struct PartBlock {
    part: usize,
    index: usize,
    bytes: Option<Vec<u8>>,
}

/// A part's layout, and where the samples of the channels taken from it go.
struct Part {
    width: usize,
    /// Scan lines per block.
    lines: usize,
    /// The first line's y.
    top: i32,
    /// Each channel's byte offset in a line, and its type.
    layout: Vec<(usize, ExrSampleType)>,
    line_bytes: usize,
    /// For each target, its channels in this part.
    routes: Vec<Vec<Route>>,
    /// The compressed blocks of the lines read, from `first_block` on, where the part is
    /// read.
    blocks: Vec<Option<Vec<u8>>>,
    first_block: usize,
    /// Names the part in an error of a file of several parts.
    label: String,
}

impl Part {
    fn new(header: &Header, index: usize, targets: usize) -> Self {
        let width = header.layer_size.0;
        let mut line_bytes = 0;
        let mut layout = Vec::new();
        for channel in header.channels.list.iter() {
            layout.push((line_bytes, channel.sample_type));
            line_bytes += width * channel.sample_type.bytes_per_sample();
        }
        let label = match &header.own_attributes.layer_name {
            Some(name) => format!(" of part {index} (\"{name}\")"),
            None if index > 0 => format!(" of part {index}"),
            None => String::new(),
        };
        Part {
            width,
            lines: header.compression.scan_lines_per_block(),
            top: header.own_attributes.layer_position.y(),
            layout,
            line_bytes,
            routes: (0..targets).map(|_| Vec::new()).collect(),
            blocks: Vec::new(),
            first_block: 0,
            label,
        }
    }
}

/// What decoding a block needs besides the block.
struct BlockDecoder<'a> {
    file: &'a Path,
    width: usize,
    height: usize,
    strides: &'a [usize],
    pool: &'a std::sync::Mutex<Vec<Inflater>>,
    /// The most channels a target takes from one part.
    most: usize,
}

impl BlockDecoder<'_> {
    /// Decodes block `index` of `part` into `outputs`, each target's rows of the block.
    fn decode(
        &self,
        part: &Part,
        index: usize,
        block: Option<Vec<u8>>,
        outputs: Vec<&mut [f32]>,
    ) -> Result<(), SceneError> {
        let (width, lines) = (self.width, part.lines);
        let damaged = |what: &str| SceneError::Image {
            file: self.file.to_path_buf(),
            message: format!("the block at line {}{} {what}; write or copy it again", index * lines, part.label),
        };
        let Some(block) = block else {
            return Err(damaged("is missing"));
        };
        let rows = lines.min(self.height - index * lines);
        let expected = rows * part.line_bytes;
        let pooled = || self.pool.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        let mut inflater = pooled().pop().unwrap_or_default();
        let split = if block.len() == expected {
            Split::Raw(&block)
        } else {
            let Some(inflated) = inflater.inflate(&block, expected) else {
                return Err(damaged("does not decompress"));
            };
            unpredict(inflated);
            Split::Halves(inflated)
        };
        // Each line its own task: inflating a block is serial, and a 960x540 frame's 34
        // blocks left most of 16 threads idle in their last round. On 16 threads of an
        // Intel Xeon, a 960x540 transfer frame is read into a spare in 27 to 32 ms, where
        // it took 30 to 38 ms (two alternating runs, medians of 9); on 2 threads as before.
        let mut per_line: Vec<Vec<&mut [f32]>> = (0..rows).map(|_| Vec::with_capacity(outputs.len())).collect();
        for (out, &stride) in outputs.into_iter().zip(self.strides) {
            for (slot, line) in per_line.iter_mut().zip(out.chunks_mut(width * stride)) {
                slot.push(line);
            }
        }
        // A tile of the line at a time: each channel's samples converted, then written into
        // the tile's pixels ([`scatter`]); the scratch made once per task rayon splits off,
        // not per line.
        let scratch = || (vec![0.0f32; self.most * TILE], [f16::ZERO; TILE]);
        per_line.into_par_iter().enumerate().for_each_init(scratch, |(samples, halves), (row, mut outputs)| {
            for x in (0..width).step_by(TILE) {
                let n = TILE.min(width - x);
                for ((to_target, out), &stride) in part.routes.iter().zip(outputs.iter_mut()).zip(self.strides) {
                    if to_target.is_empty() {
                        continue;
                    }
                    for (route, samples) in to_target.iter().zip(samples.chunks_exact_mut(TILE)) {
                        let at = row * part.line_bytes + route.at + x * route.kind.bytes_per_sample();
                        split.samples(at, route.kind, &mut halves[..n], &mut samples[..n]);
                    }
                    scatter(to_target, samples, &mut out[x * stride..(x + n) * stride], stride);
                }
            }
        });
        pooled().push(inflater);
        Ok(())
    }
}

/// Writes a tile's samples (route `k`'s run from `samples[k * TILE]`) into its pixels of
/// `stride` values each, every route's at its offset. Four routes at consecutive offsets
/// (a transfer vector's coefficients) are written four pixels at a time, transposed in
/// SSE2 registers (part of x86-64): one 16-byte store where there were four stores of a
/// value, the hottest instruction of a transfer frame's decoding. The same values either
/// way.
fn scatter(routes: &[Route], samples: &[f32], pixels: &mut [f32], stride: usize) {
    let n = pixels.len() / stride;
    let run = |k: usize| &samples[k * TILE..k * TILE + n];
    let mut k = 0;
    while k < routes.len() {
        let offset = routes[k].offset;
        let four = routes.get(k..k + 4).is_some_and(|r| (1..4).all(|j| r[j].offset == offset + j));
        if !four {
            for (pixel, &value) in pixels.chunks_exact_mut(stride).zip(run(k)) {
                pixel[offset] = value;
            }
            k += 1;
            continue;
        }
        let rows = [run(k), run(k + 1), run(k + 2), run(k + 3)];
        let mut i = 0;
        #[cfg(target_arch = "x86_64")]
        while i + 4 <= n {
            use std::arch::x86_64::*;
            // SAFETY: SSE2 is part of x86-64; each load reads four values of a run and
            // each store four of a pixel, both bounds-checked.
            unsafe {
                let [r0, r1, r2, r3] = rows.map(|row| _mm_loadu_ps(row[i..i + 4].as_ptr()));
                let (low01, low23) = (_mm_unpacklo_ps(r0, r1), _mm_unpacklo_ps(r2, r3));
                let (high01, high23) = (_mm_unpackhi_ps(r0, r1), _mm_unpackhi_ps(r2, r3));
                let columns = [
                    _mm_movelh_ps(low01, low23),
                    _mm_movehl_ps(low23, low01),
                    _mm_movelh_ps(high01, high23),
                    _mm_movehl_ps(high23, high01),
                ];
                for (p, column) in columns.into_iter().enumerate() {
                    let at = (i + p) * stride + offset;
                    _mm_storeu_ps(pixels[at..at + 4].as_mut_ptr(), column);
                }
            }
            i += 4;
        }
        for (pixel, i) in pixels.chunks_exact_mut(stride).zip(0..n).skip(i) {
            for (j, row) in rows.iter().enumerate() {
                pixel[offset + j] = row[i];
            }
        }
        k += 4;
    }
}

/// A zlib decoder and the buffer it inflates blocks into, kept from block to block.
struct Inflater {
    zlib: flate2::Decompress,
    inflated: Vec<u8>,
}

impl Default for Inflater {
    fn default() -> Self {
        Self { zlib: flate2::Decompress::new(true), inflated: Vec::new() }
    }
}

impl Inflater {
    /// The zlib stream `block` inflated, where it holds exactly `expected` bytes.
    fn inflate(&mut self, block: &[u8], expected: usize) -> Option<&mut [u8]> {
        self.zlib.reset(true);
        self.inflated.clear();
        self.inflated.reserve_exact(expected);
        let status = self.zlib.decompress_vec(block, &mut self.inflated, flate2::FlushDecompress::Finish);
        (matches!(status, Ok(flate2::Status::StreamEnd)) && self.inflated.len() == expected)
            .then_some(&mut self.inflated[..])
    }
}

/// Where one channel's line lies in a block, and where in its target's pixels it goes.
struct Route {
    at: usize,
    kind: ExrSampleType,
    offset: usize,
}

/// Pixels of a line decoded together: a target's channels of a tile stay in L1.
const TILE: usize = 128;

/// A block's bytes: as stored, or decoded but still split into its even and odd bytes
/// (the byte at `2i` is `even[i]`, at `2i + 1` `odd[i]`), which saves interleaving them.
enum Split<'a> {
    Raw(&'a [u8]),
    Halves(&'a [u8]),
}

impl Split<'_> {
    /// The samples of a line from byte `at` (even), as f32: halves exactly (through F16C
    /// where the processor has it), 32-bit integers to the nearest f32. `halves` is
    /// scratch of the line's length.
    fn samples(&self, at: usize, kind: ExrSampleType, halves: &mut [f16], out: &mut [f32]) {
        let n = out.len();
        match (self, kind) {
            (Split::Raw(bytes), ExrSampleType::F16) => {
                for (h, b) in halves.iter_mut().zip(bytes[at..at + 2 * n].chunks_exact(2)) {
                    *h = f16::from_bits(u16::from_le_bytes([b[0], b[1]]));
                }
                halves.convert_to_f32_slice(out);
            }
            (Split::Raw(bytes), _) => {
                for (o, b) in out.iter_mut().zip(bytes[at..at + 4 * n].chunks_exact(4)) {
                    *o = from_bits(kind, u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
                }
            }
            // A sample's low bytes are even, its high bytes odd: put back in order.
            (Split::Halves(bytes), ExrSampleType::F16) => {
                let (even, odd) = bytes.split_at(bytes.len().div_ceil(2));
                let (low, high) = (&even[at / 2..at / 2 + n], &odd[at / 2..at / 2 + n]);
                interleave(low, high, bytemuck::cast_slice_mut(halves));
                for h in halves.iter_mut() {
                    *h = f16::from_bits(u16::from_le(h.to_bits()));
                }
                halves.convert_to_f32_slice(out);
            }
            (Split::Halves(bytes), _) => {
                let (even, odd) = bytes.split_at(bytes.len().div_ceil(2));
                let (low, high) = (&even[at / 2..at / 2 + 2 * n], &odd[at / 2..at / 2 + 2 * n]);
                interleave(low, high, bytemuck::cast_slice_mut(out));
                for o in out.iter_mut() {
                    *o = from_bits(kind, u32::from_le(o.to_bits()));
                }
            }
        }
    }
}

/// `low[i]` and `high[i]` as bytes `2i` and `2i + 1` of `out`: a decoded block's split
/// bytes back in the order of its samples, 16 pairs at a time in SSE2 (part of x86-64),
/// which took a fifth of a G-buffer's read one byte at a time.
fn interleave(low: &[u8], high: &[u8], out: &mut [u8]) {
    let n = out.len() / 2;
    let (low, high) = (&low[..n], &high[..n]);
    let mut i = 0;
    #[cfg(target_arch = "x86_64")]
    while i + 16 <= n {
        use std::arch::x86_64::*;
        // SAFETY: SSE2 is part of x86-64; each load reads 16 bytes and each store writes
        // 16, all bounds-checked.
        unsafe {
            let l = _mm_loadu_si128(low[i..i + 16].as_ptr().cast());
            let h = _mm_loadu_si128(high[i..i + 16].as_ptr().cast());
            _mm_storeu_si128(out[2 * i..2 * i + 16].as_mut_ptr().cast(), _mm_unpacklo_epi8(l, h));
            _mm_storeu_si128(out[2 * i + 16..2 * i + 32].as_mut_ptr().cast(), _mm_unpackhi_epi8(l, h));
        }
        i += 16;
    }
    for j in i..n {
        out[2 * j] = low[j];
        out[2 * j + 1] = high[j];
    }
}

/// A 32-bit sample: a float as it is, an unsigned integer to the nearest f32.
fn from_bits(kind: ExrSampleType, bits: u32) -> f32 {
    if kind == ExrSampleType::U32 {
        bits as f32
    } else {
        f32::from_bits(bits)
    }
}

/// Undoes [`predict`]'s differences (the bytes stay split): a running sum of the
/// bytes less 128, wrapping, which is `128 + sum(d - 128)` from the first byte on.
fn unpredict(bytes: &mut [u8]) {
    let mut running = 128u8;
    #[cfg(target_arch = "x86_64")]
    let bytes = {
        let (vectors, rest) = bytes.split_at_mut(bytes.len() / 16 * 16);
        // SAFETY: SSE2 is part of x86-64.
        running = unsafe { unpredict_sse2(vectors, running) };
        rest
    };
    for byte in bytes {
        running = running.wrapping_add(*byte ^ 0x80);
        *byte = running;
    }
}

/// [`unpredict`] of 16 bytes at a time (`bytes.len()` a multiple of 16): the running sum
/// within a vector in four shifted adds, then the sum before it added; returns the last
/// byte. About four times the speed of one byte at a time.
///
/// # Safety
/// The processor has SSE2 (every x86-64 does).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "sse2")]
fn unpredict_sse2(bytes: &mut [u8], running: u8) -> u8 {
    use std::arch::x86_64::*;
    let (bias, mut before) = (_mm_set1_epi8(-128), _mm_set1_epi8(running as i8));
    for vector in bytes.chunks_exact_mut(16) {
        // SAFETY: `vector` holds 16 bytes.
        let mut v = unsafe { _mm_loadu_si128(vector.as_ptr().cast()) };
        v = _mm_xor_si128(v, bias);
        v = _mm_add_epi8(v, _mm_slli_si128::<1>(v));
        v = _mm_add_epi8(v, _mm_slli_si128::<2>(v));
        v = _mm_add_epi8(v, _mm_slli_si128::<4>(v));
        v = _mm_add_epi8(v, _mm_slli_si128::<8>(v));
        v = _mm_add_epi8(v, before);
        // SAFETY: as the load.
        unsafe { _mm_storeu_si128(vector.as_mut_ptr().cast(), v) };
        let high = _mm_unpackhi_epi8(v, v);
        before = _mm_shuffle_epi32::<0xff>(_mm_unpackhi_epi16(high, high));
    }
    _mm_cvtsi128_si32(before) as u8
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::exr_read::ChannelFile;

    #[test]
    fn half_max_is_the_largest_finite_half() {
        assert_eq!(HALF_MAX, f32::from(f16::MAX));
    }

    /// OpenEXR's decoder (`ImfZip.cpp`), one byte at a time: the predictor undone, then
    /// the halves interleaved.
    fn openexr_decode(predicted: &[u8]) -> Vec<u8> {
        let mut t = predicted.to_vec();
        for i in 1..t.len() {
            t[i] = t[i - 1].wrapping_add(t[i]).wrapping_sub(128);
        }
        let (evens, odds) = t.split_at(t.len().div_ceil(2));
        (0..t.len()).map(|i| if i % 2 == 0 { evens[i / 2] } else { odds[i / 2] }).collect()
    }

    #[test]
    fn the_predictor_and_its_inverse_are_openexrs() {
        for len in (0usize..70).chain([256, 1001]) {
            let raw: Vec<u8> = (0..len).map(|i| (i * 37 % 251) as u8 ^ (i >> 3) as u8).collect();
            let predicted = predict(&raw);
            assert_eq!(openexr_decode(&predicted), raw, "{len} bytes");
            // `unpredict` (16 bytes at a time, then the rest) leaves the halves split.
            let mut split = predicted.clone();
            unpredict(&mut split);
            let mut t = predicted;
            for i in 1..t.len() {
                t[i] = t[i - 1].wrapping_add(t[i]).wrapping_sub(128);
            }
            assert_eq!(split, t, "{len} bytes");
        }
        // A ramp of bytes predicts to a constant after the first of each half.
        assert_eq!(predict(&[10, 20, 11, 21, 12, 22]), vec![10, 129, 129, 136, 129, 129]);
    }

    #[test]
    fn a_block_that_does_not_shrink_is_stored_as_it_is() {
        // Bytes from a linear congruential generator do not deflate.
        let mut state = 12345u32;
        let raw: Vec<u8> = (0..64)
            .map(|_| {
                state = state.wrapping_mul(1_103_515_245).wrapping_add(12_345);
                (state >> 16) as u8
            })
            .collect();
        assert_eq!(compress(raw.clone()), raw);
        let zeros = vec![0u8; 4096];
        assert!(compress(zeros).len() < 100);
    }

    /// Writes `channels` and reads them back through the `exr` crate: the part's size,
    /// compression, attributes and channel names, and each channel as f32.
    fn round_trip(
        width: usize,
        height: usize,
        channels: &[OutputChannel],
        attributes: LayerAttributes,
    ) -> (LayerAttributes, Vec<String>, Vec<Vec<f32>>) {
        use exr::prelude::{ReadChannels as _, ReadLayers as _};
        let mut bytes = std::io::Cursor::new(Vec::new());
        write(&mut bytes, width, height, channels, attributes).unwrap();
        let image = exr::prelude::read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .all_layers()
            .all_attributes()
            .from_buffered(std::io::Cursor::new(bytes.into_inner()))
            .unwrap();
        let layer = image.layer_data.into_iter().next().unwrap();
        assert_eq!((layer.size.0, layer.size.1), (width, height));
        assert_eq!(layer.encoding.compression, Compression::ZIP16);
        let names = layer.channel_data.list.iter().map(|c| c.name.to_string()).collect();
        let values = layer.channel_data.list.iter().map(|c| c.sample_data.values_as_f32().collect()).collect();
        (layer.attributes, names, values)
    }

    /// A tile's samples land where one value at a time would put them, for routes in
    /// fours at consecutive offsets, out of order, and alone, over tiles of any length.
    #[test]
    fn the_scatter_puts_every_sample_at_its_offset() {
        let layouts: [&[usize]; 5] = [
            &[0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15],
            &[0, 1, 2, 3, 4, 5, 6, 7, 8],
            &[0, 1, 2, 3, 5, 4],
            &[1, 2, 3, 4, 0],
            &[2, 0, 1],
        ];
        for offsets in layouts {
            let stride = offsets.len();
            let routes: Vec<Route> =
                offsets.iter().map(|&offset| Route { at: 0, kind: ExrSampleType::F32, offset }).collect();
            let samples: Vec<f32> = (0..stride * TILE).map(|v| v as f32).collect();
            for n in (1..=13).chain([TILE - 1, TILE]) {
                let mut pixels = vec![f32::NAN; n * stride];
                scatter(&routes, &samples, &mut pixels, stride);
                for (i, pixel) in pixels.chunks_exact(stride).enumerate() {
                    for (k, route) in routes.iter().enumerate() {
                        assert_eq!(pixel[route.offset], samples[k * TILE + i], "offsets {offsets:?}, {n} pixels");
                    }
                }
            }
        }
    }

    /// What is written reads back through the `exr` crate, bit for bit: halves and
    /// floats, a last block of 5 lines, blocks deflated (ramps) and stored raw (noise that
    /// does not deflate), channels given out of order, and the attributes.
    #[test]
    fn a_written_part_reads_back_through_the_exr_crate() {
        let (width, height) = (7, 37);
        let mut state = 7u32;
        let noise: Vec<f32> = (0..width * height)
            .map(|_| {
                state = state.wrapping_mul(1_103_515_245).wrapping_add(12_345);
                f32::from_bits(state.rotate_left(15) ^ state)
            })
            .collect();
        let ramp: Vec<f32> = (0..width * height).map(|i| i as f32 / 64.0).collect();
        let mut attributes = LayerAttributes::default();
        let key = exr::meta::attribute::Text::from("note");
        attributes.other.insert(key.clone(), exr::meta::attribute::AttributeValue::Text("kept".into()));
        let channels = [
            OutputChannel::new("Z.V", SampleType::Float, &ramp),
            OutputChannel::new("R", SampleType::Half, &ramp),
            OutputChannel::new("A", SampleType::Float, &noise),
        ];
        let (read_attributes, names, values) = round_trip(width, height, &channels, attributes);
        let kept = matches!(&read_attributes.other[&key], exr::meta::attribute::AttributeValue::Text(t) if t == "kept");
        assert!(kept);
        assert_eq!(names, ["A", "R", "Z.V"]);
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&values[0]), bits(&noise));
        let halves: Vec<f32> = ramp.iter().map(|&v| f16::from_f32(v).to_f32()).collect();
        assert_eq!(values[1], halves);
        assert_eq!(values[2], ramp);

        let raw = block_bytes(&[&channels[2]], width, 0..LINES_PER_BLOCK);
        assert_eq!(compress(raw.clone()), raw, "the noise is stored raw");
        let only_noise = [OutputChannel::new("A", SampleType::Float, &noise)];
        let (_, _, values) = round_trip(width, height, &only_noise, LayerAttributes::default());
        assert_eq!(bits(&values[0]), bits(&noise));

        // Read back in place: the ramp's channels interleaved with the noise, pixel-major.
        let mut bytes = std::io::Cursor::new(Vec::new());
        write(&mut bytes, width, height, &channels, LayerAttributes::default()).unwrap();
        let bytes = bytes.into_inner();
        let meta = exr::meta::MetaData::read_from_buffered(std::io::Cursor::new(&bytes), false).unwrap();
        assert!(decodes(&meta.headers[0]));
        let file = Path::new("part.exr");
        let blocks = || ChannelFile::new(file, "a test part", bytes.clone(), &meta, "A").unwrap();
        assert!(matches!(blocks(), ChannelFile::Blocks { .. }));
        let mut pixels = vec![0.0f32; 3 * width * height];
        let names = [("A", 1), ("R", 2), ("Z.V", 0)].map(|(n, k)| (n.to_string(), k)).to_vec();
        let mut targets = [Target { values: &mut pixels, stride: 3, channels: names }];
        blocks().fill(file, "a test part", &mut targets).unwrap();
        for (i, pixel) in pixels.as_chunks::<3>().0.iter().enumerate() {
            assert_eq!(pixel.map(f32::to_bits), [ramp[i], noise[i], halves[i]].map(f32::to_bits), "pixel {i}");
        }
        let mut missing = [Target { values: &mut pixels, stride: 3, channels: vec![("G".into(), 0)] }];
        let error = blocks().fill(file, "a test part", &mut missing).unwrap_err().to_string();
        assert!(error.contains("part.exr") && error.contains("\"G\""), "{error}");
    }
}
