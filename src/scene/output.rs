//! Writing output images: linear float EXR (single- and multi-layer) and an sRGB 8-bit
//! PNG preview.
//!
//! Every write is atomic: the image goes to a temporary file in the destination's
//! directory (`.<name>.<pid>.<n>.tmp`), which is then renamed over the destination, so a
//! reader never sees half a file and a failed write leaves the old file in place. These
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
    std::fs::rename(&temp, path).map_err(|source| {
        let _ = std::fs::remove_file(&temp);
        OutputError::Io { file: path.to_path_buf(), cause: source }
    })
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

    /// The number of pixels `values` holds (none at a stride of 0, which is refused).
    fn pixels(&self) -> usize {
        if self.stride == 0 {
            0
        } else {
            self.values.len().div_ceil(self.stride)
        }
    }
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
    write_atomically(
        path,
        |temp| {
            let file = std::fs::File::create(temp).map_err(exr::error::Error::from)?;
            super::exr_zip::write(std::io::BufWriter::new(file), width, height, channels, layer_attributes)
        },
        |e| OutputError::Encode { file: path.to_path_buf(), message: e.to_string() },
    )
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
    write_atomically(
        path,
        |temp| {
            image::save_buffer_with_format(
                temp,
                &bytes,
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
