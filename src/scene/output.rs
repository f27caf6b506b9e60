//! Writing output images: linear float EXR (single- and multi-layer) and an sRGB 8-bit
//! PNG preview.
//!
//! Every write is atomic and durable: the image goes to a temporary file in the
//! destination's directory (`.<name>.<pid>.<n>.tmp`), flushed to the disk, then renamed
//! over the destination, and the directory flushed after it; so a reader never sees half a
//! file, a failed write leaves the old file in place, and a power loss or a killed node
//! leaves the old file or the new one, never a renamed file of zeros. A process killed
//! mid-write leaves its temporary file, which [`remove_leftovers`] clears. These
//! functions do not know the scene; call [`super::Scene::check_output_path`] first so
//! that no input is ever overwritten.
//!
//! Multi-layer EXR: one part, channels named `<layer>.<channel>`, the way
//! Blender's compositor and Nuke read compositing passes.
//!
//! Names: the beauty is plain `R`, `G`, `B`, `A` (Blender reads it as the Combined pass,
//! Nuke as `rgba`); every other pass is `<pass>.<channel>`, which Blender's multilayer
//! reader splits at the last dot into pass and channel (`imb_exr_split_channel_name` in
//! `source/blender/imbuf/intern/openexr/openexr_api.cc`) and Nuke reads as layer
//! `<pass>`. One part rather than Blender 5's part per pass, because every reader of
//! multilayer files accepts it (Blender 4 and 5, Nuke, oiiotool, the `exr` crate).
//! Compression ZIP (16 scan lines per block), lossless.

pub use super::exr_zip::{OutputChannel, SampleType};
use exr::meta::attribute::{AttributeValue, Text};
use exr::prelude::LayerAttributes;
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Why an output image could not be written.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error("{}: cannot write: {cause}", .file.display())]
    Io { file: PathBuf, cause: std::io::Error },
    #[error("{}: cannot encode the image: {message}", .file.display())]
    Encode { file: PathBuf, message: String },
    #[error("{}: {count} pixel values given for a {width}x{height} image", .file.display())]
    SizeMismatch { file: PathBuf, width: usize, height: usize, count: usize },
}

static COUNTER: AtomicU64 = AtomicU64::new(0);

/// Writes through `write(temp_path)` and renames the temporary file onto `path`.
pub fn write_atomically<E>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
    wrap: impl FnOnce(E) -> OutputError,
) -> Result<(), OutputError> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "output".into());
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let temp = dir.join(format!(".{name}.{}.{n}.tmp", std::process::id()));
    if let Err(e) = write(&temp) {
        let _ = std::fs::remove_file(&temp);
        return Err(wrap(e));
    }
    let renamed = std::fs::OpenOptions::new()
        .write(true)
        .open(&temp)
        .and_then(|file| file.sync_all())
        .and_then(|()| std::fs::rename(&temp, path));
    if let Err(cause) = renamed {
        let _ = std::fs::remove_file(&temp);
        return Err(OutputError::Io { file: path.to_path_buf(), cause });
    }
    sync_directory(&dir).map_err(|cause| OutputError::Io { file: path.to_path_buf(), cause })
}

/// Flushes a directory's entries (the rename of [`write_atomically`]) to the disk. Only
/// Unix opens a directory as a file; elsewhere the rename is left to the file system.
fn sync_directory(dir: &Path) -> std::io::Result<()> {
    #[cfg(unix)]
    std::fs::File::open(dir)?.sync_all()?;
    #[cfg(not(unix))]
    let _ = dir;
    Ok(())
}

/// Removes the temporary files that writes of `outputs` left in their directories when
/// their process was killed (`.<name>.<pid>.<n>.tmp` of a process that no longer runs);
/// returns what it removed.
pub fn remove_leftovers(outputs: &[PathBuf]) -> Vec<PathBuf> {
    let mut removed = Vec::new();
    let mut by_directory: std::collections::BTreeMap<PathBuf, Vec<String>> = Default::default();
    for path in outputs {
        let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new(".")).to_path_buf();
        if let Some(name) = path.file_name() {
            by_directory.entry(dir).or_default().push(format!(".{}.", name.to_string_lossy()));
        }
    }
    for (dir, prefixes) in by_directory {
        let Ok(entries) = std::fs::read_dir(&dir) else { continue };
        for entry in entries.flatten() {
            let file = entry.file_name().to_string_lossy().into_owned();
            let Some(rest) = prefixes.iter().find_map(|p| file.strip_prefix(p.as_str())) else { continue };
            let Some(pid) = rest.strip_suffix(".tmp").and_then(|r| r.split('.').next()?.parse::<u32>().ok()) else {
                continue;
            };
            if !process_runs(pid) && std::fs::remove_file(entry.path()).is_ok() {
                removed.push(entry.path());
            }
        }
    }
    removed
}

/// Whether process `pid` runs: on Unix, whether a signal could be sent to it (`kill` with
/// no signal); elsewhere every process counts as running, so its files stay.
fn process_runs(pid: u32) -> bool {
    #[cfg(unix)]
    {
        let Ok(pid) = libc::pid_t::try_from(pid) else { return false };
        // SAFETY: signal 0 sends nothing; it only checks that the process exists.
        unsafe { libc::kill(pid, 0) == 0 || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM) }
    }
    #[cfg(not(unix))]
    {
        let _ = pid;
        true
    }
}

/// The header of an EXR written by [`write_exr_layers`] where the file is whole: its
/// header reads, every chunk of its offset table lies inside the file, and its last chunk
/// decodes. `None` for a file cut short by a crash, or one of zeros.
pub fn whole_exr(path: &Path) -> Option<exr::meta::MetaData> {
    whole_exr_checked(path).ok().flatten()
}

fn whole_exr_checked(path: &Path) -> std::io::Result<Option<exr::meta::MetaData>> {
    use exr::block::reader::{ChunksReader, Reader};
    use std::io::{BufRead, Read, Seek, SeekFrom};
    let mut file = std::io::BufReader::new(std::fs::File::open(path)?);
    let length = file.get_ref().metadata()?.len();
    let Ok(reader) = Reader::read_from_buffered(&mut file, true) else { return Ok(None) };
    let meta = reader.meta_data().clone();
    let [header] = meta.headers.as_slice() else { return Ok(None) };
    let (chunks, height) = (header.chunk_count as u64, header.layer_size.height());
    let last = reader.filter_chunks(true, |_, _, block| block.pixel_position.y() + block.pixel_size.height() == height);
    if !last.is_ok_and(|last| last.decompress_sequential(true, |_, _| Ok(())).is_ok()) {
        return Ok(None);
    }
    // The offset table follows the header: the magic number and version (8 bytes), then
    // attributes (name, type, a 4-byte size, the value) up to an empty name.
    file.seek(SeekFrom::Start(8))?;
    loop {
        let mut name = Vec::new();
        file.read_until(0, &mut name)?;
        if name.as_slice() == [0] {
            break;
        }
        let mut kind = Vec::new();
        file.read_until(0, &mut kind)?;
        let mut size = [0u8; 4];
        file.read_exact(&mut size)?;
        if name.last() != Some(&0) || kind.last() != Some(&0) {
            return Ok(None);
        }
        file.seek_relative(i64::from(u32::from_le_bytes(size)))?;
    }
    let mut offsets = vec![0u8; 8 * chunks as usize];
    file.read_exact(&mut offsets)?;
    for offset in offsets.chunks_exact(8).map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes"))) {
        // A scan-line chunk: its first line (4 bytes), its size (4 bytes), its data.
        let mut head = [0u8; 8];
        if offset.checked_add(8).is_none_or(|end| end > length) {
            return Ok(None);
        }
        file.seek(SeekFrom::Start(offset))?;
        file.read_exact(&mut head)?;
        if offset + 8 + u64::from(u32::from_le_bytes(head[4..].try_into().expect("4 bytes"))) > length {
            return Ok(None);
        }
    }
    Ok(Some(meta))
}

/// Whether a PNG is whole: its signature opens it and its `IEND` chunk closes it.
pub fn png_is_whole(path: &Path) -> bool {
    const SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];
    const IEND: [u8; 12] = [0, 0, 0, 0, b'I', b'E', b'N', b'D', 0xae, 0x42, 0x60, 0x82];
    std::fs::read(path).is_ok_and(|bytes| bytes.starts_with(&SIGNATURE) && bytes.ends_with(&IEND))
}

fn check_len(path: &Path, width: usize, height: usize, count: usize) -> Result<(), OutputError> {
    if width.checked_mul(height) != Some(count) || width == 0 || height == 0 {
        return Err(OutputError::SizeMismatch { file: path.to_path_buf(), width, height, count });
    }
    Ok(())
}

/// Writes linear RGBA as a float EXR with channels `R`, `G`, `B`, `A` (ZIP compression),
/// row 0 the top row.
pub fn write_exr_rgba(path: &Path, width: usize, height: usize, rgba: &[[f32; 4]]) -> Result<(), OutputError> {
    check_len(path, width, height, rgba.len())?;
    let channel = |k: usize| rgba.iter().map(|p| p[k]).collect::<Vec<f32>>();
    let (r, g, b, a) = (channel(0), channel(1), channel(2), channel(3));
    write_exr_channels(path, width, height, &[("R", &r), ("G", &g), ("B", &b), ("A", &a)])
}

/// Writes any named f32 channels into one single-part EXR (ZIP compression); names may
/// be dotted (`shadow.R`) for multi-layer outputs.
pub fn write_exr_channels(
    path: &Path,
    width: usize,
    height: usize,
    channels: &[(&str, &[f32])],
) -> Result<(), OutputError> {
    for (_, data) in channels {
        check_len(path, width, height, data.len())?;
    }
    let list: Vec<OutputChannel> =
        channels.iter().map(|(name, values)| OutputChannel::new(name, SampleType::Float, values)).collect();
    write_exr_layers(path, width, height, &list, &[])
}

/// Writes `channels` as one ZIP-compressed part, atomically (see the module doc), with
/// `attributes` as text attributes of the part (Latin-1 text).
/// Channel names must be distinct; they are sorted in the file, as EXR requires.
pub fn write_exr_layers(
    path: &Path,
    width: usize,
    height: usize,
    channels: &[OutputChannel],
    attributes: &[(&str, String)],
) -> Result<(), OutputError> {
    for c in channels {
        check_len(path, width, height, c.pixels())?;
    }
    let layer_attributes = text_attributes(path, attributes)?;
    write_atomically(
        path,
        |temp| {
            let file = std::fs::File::create(temp).map_err(exr::error::Error::from)?;
            super::exr_zip::write(std::io::BufWriter::new(file), width, height, channels, layer_attributes)
        },
        |e| OutputError::Encode { file: path.to_path_buf(), message: e.to_string() },
    )
}

/// `attributes` as an EXR part's text attributes (Latin-1 text), for `path`'s errors.
pub fn text_attributes(path: &Path, attributes: &[(&str, String)]) -> Result<LayerAttributes, OutputError> {
    let mut layer_attributes = LayerAttributes::default();
    for (name, value) in attributes {
        let text = |s: &str| {
            Text::new_or_none(s).ok_or_else(|| OutputError::Encode {
                file: path.to_path_buf(),
                message: format!("attribute {name} is not Latin-1 text"),
            })
        };
        layer_attributes.other.insert(text(name)?, AttributeValue::Text(text(value)?));
    }
    Ok(layer_attributes)
}

/// The sRGB transfer function (IEC 61966-2-1) of a linear value in `[0, 1]`.
pub fn linear_to_srgb(x: f32) -> f32 {
    let x = if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) };
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// Writes an 8-bit RGBA PNG preview: colour through `view` (the scene's exposure and view
/// transform, [`super::view`]), alpha linear where `view` keeps the background
/// transparent and opaque otherwise.
pub fn write_png_preview(
    path: &Path,
    width: usize,
    height: usize,
    rgba: &[[f32; 4]],
    view: &super::ViewTransform,
) -> Result<(), OutputError> {
    check_len(path, width, height, rgba.len())?;
    write_png_bytes(path, width, height, &preview_bytes(rgba, view))
}

/// The 8-bit RGBA bytes of the preview of `rgba` ([`write_png_preview`]).
pub fn preview_bytes(rgba: &[[f32; 4]], view: &super::ViewTransform) -> Vec<u8> {
    let q = |v: f32| (v * 255.0 + 0.5).clamp(0.0, 255.0) as u8;
    // In parallel: through the view transform, a 960x540 frame took 17 ms on one thread,
    // three times the PNG's encoding, and held up a sequence's writing stage.
    const PIXELS: usize = 4096;
    let mut bytes = vec![0u8; rgba.len() * 4];
    bytes.par_chunks_mut(4 * PIXELS).zip(rgba.par_chunks(PIXELS)).for_each(|(out, pixels)| {
        for (out, p) in out.chunks_exact_mut(4).zip(pixels) {
            let [r, g, b] = view.display([p[0], p[1], p[2]], 0.0);
            let alpha = if view.transparent {
                if p[3].is_nan() {
                    0.0
                } else {
                    p[3].clamp(0.0, 1.0)
                }
            } else {
                1.0
            };
            out.copy_from_slice(&[q(r), q(g), q(b), q(alpha)]);
        }
    });
    bytes
}

/// Writes `bytes`, 8-bit RGBA, as a PNG, atomically.
pub fn write_png_bytes(path: &Path, width: usize, height: usize, bytes: &[u8]) -> Result<(), OutputError> {
    check_len(path, width, height, bytes.len() / 4)?;
    write_atomically(
        path,
        |temp| {
            image::save_buffer_with_format(
                temp,
                bytes,
                width as u32,
                height as u32,
                image::ExtendedColorType::Rgba8,
                image::ImageFormat::Png,
            )
        },
        |e| OutputError::Encode { file: path.to_path_buf(), message: e.to_string() },
    )
}

/// Writes a text file (CSV, JSON, SVG) atomically.
pub fn write_text(path: &Path, text: &str) -> Result<(), OutputError> {
    write_atomically(
        path,
        |temp| std::fs::write(temp, text),
        |source| OutputError::Io { file: path.to_path_buf(), cause: source },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A channel that does not hold one value per pixel, at its stride, is refused and
    /// nothing is written; an interleaved one is written from its pixels' values.
    #[test]
    fn channels_are_checked_against_the_size_at_their_stride() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.exr");
        let pixels: Vec<f32> = (0..3 * 6).map(|i| i as f32).collect();
        let refused = |channel: OutputChannel| {
            let error = write_exr_layers(&path, 3, 2, &[channel], &[]).unwrap_err();
            assert!(matches!(error, OutputError::SizeMismatch { .. }), "{error}");
            assert!(!path.exists());
        };
        refused(OutputChannel::interleaved("Y".into(), SampleType::Float, &pixels, 0, 0));
        refused(OutputChannel::interleaved("Y".into(), SampleType::Float, &pixels, 2, 0));
        refused(OutputChannel::interleaved("Y".into(), SampleType::Float, &pixels, 3, 3));
        refused(OutputChannel::new("Y", SampleType::Float, &pixels[..5]));
        let green = OutputChannel::interleaved("G".into(), SampleType::Float, &pixels, 3, 1);
        write_exr_layers(&path, 3, 2, &[green], &[]).unwrap();
        let mut read = super::super::exr_read::ExrChannels::read(&path, "a test image").unwrap();
        assert_eq!(read.take(&path, "G").unwrap(), [1.0, 4.0, 7.0, 10.0, 13.0, 16.0]);
    }
}
