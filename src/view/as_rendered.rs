//! What a frame's file holds as rendered, read for the page: a pass whole (the page's
//! comparison against the frame before relighting, `rendered.bin`), and every channel of
//! one pixel with its material (the page's pixel inspector, `pixel.json`).
//!
//! Both read the file the render wrote through the crate's EXR reader, which converts
//! halves to f32 exactly: the inspector shows the values the file holds, not the page's
//! preview of them. A pixel reads only the block of scan lines that holds it.

use crate::scene::exr_read::{ChannelDirectory, ChannelFile};
use crate::scene::exr_zip::{Target, LINES_PER_BLOCK};
use crate::scene::{GBufferFile, Reading, Scene, SceneError};
use crate::transfer::TransferHeader;
use std::path::Path;

/// What a read of a frame's file is called in its errors.
const WHAT: &str = "a rendered frame";

/// The passes the page compares its own against, each with its channels in the file the
/// render wrote (`render::pass_channels`): the beauty, the colour passes, the visibility
/// term.
pub const PASSES: [(&str, &[&str]); 6] = [
    ("beauty", &["R", "G", "B"]),
    ("diffuse", &["diffuse.R", "diffuse.G", "diffuse.B"]),
    ("specular", &["specular.R", "specular.G", "specular.B"]),
    ("environment", &["environment.R", "environment.G", "environment.B"]),
    ("indirect", &["indirect.R", "indirect.G", "indirect.B"]),
    ("visibility", &["visibility.Y"]),
];

/// The channels of [`PASSES`] `pass`, or `None` for a name that is none of them.
pub fn pass_channels(pass: &str) -> Option<&'static [&'static str]> {
    PASSES.iter().find(|(name, _)| *name == pass).map(|(_, channels)| *channels)
}

/// The passes of [`PASSES`] whose channels `file`'s headers list.
pub fn passes_in(file: &Path) -> Vec<&'static str> {
    let Ok(meta) = exr::meta::MetaData::read_from_file(file, false) else {
        return Vec::new();
    };
    let directory = ChannelDirectory::new(&meta.headers);
    PASSES
        .iter()
        .filter(|(_, channels)| channels.iter().all(|c| directory.find(c).is_some()))
        .map(|(name, _)| *name)
        .collect()
}

/// `channels` of `file`, `channels.len()` values per pixel, at the pixels `shown` (row-major
/// indices of the whole frame) in their order.
pub fn pass_at(file: &Path, channels: &[&str], shown: &[usize]) -> Result<Vec<f32>, SceneError> {
    let exr = ChannelFile::read(file, WHAT, channels[0])?;
    let (width, height) = exr.size();
    let count = channels.len();
    let mut values = vec![0.0f32; width * height * count];
    let named = channels.iter().enumerate().map(|(k, name)| (name.to_string(), k)).collect();
    exr.fill(file, WHAT, &mut [Target { values: &mut values, stride: count, channels: named }])?;
    Ok(shown.iter().flat_map(|&i| values[i * count..(i + 1) * count].iter().copied()).collect())
}

/// Whether the inspector shows channel `name`: every channel but the transfer layers'
/// (the SH vectors, the glossy lookup, the turned Sun lamps and the horizons), which are
/// inputs of the relight rather than values of the image.
fn inspected(name: &str) -> bool {
    !["sh_", "glossy_", "sun_lamps_", "horizon"].iter().any(|prefix| name.starts_with(prefix))
}

/// Every channel of `file` at pixel (`x`, `y`) that the inspector shows, by full name in
/// the file's order, as the file holds it (halves converted exactly); `Ok(None)` where the
/// pixel lies outside the frame.
pub fn channels_at(file: &Path, x: usize, y: usize) -> Result<Option<Vec<(String, f32)>>, SceneError> {
    let meta =
        exr::meta::MetaData::read_from_file(file, false).map_err(|e| crate::scene::error::exr_error(file, WHAT, e))?;
    let names: Vec<String> = ChannelDirectory::new(&meta.headers).names.into_iter().filter(|n| inspected(n)).collect();
    let Some(first) = names.first() else {
        return Ok(Some(Vec::new()));
    };
    let exr = ChannelFile::open(file, WHAT, first)?;
    let (width, height) = exr.size();
    if x >= width || y >= height {
        return Ok(None);
    }
    // The block of scan lines that holds row `y`: only its bytes are read and decoded.
    let top = y / LINES_PER_BLOCK * LINES_PER_BLOCK;
    let lines = top..(top + LINES_PER_BLOCK).min(height);
    let count = names.len();
    let mut values = vec![0.0f32; lines.len() * width * count];
    let named = names.iter().cloned().zip(0..).collect();
    exr.fill_lines(file, WHAT, lines, &mut [Target { values: &mut values, stride: count, channels: named }])?;
    let pixel = &values[((y - top) * width + x) * count..][..count];
    Ok(Some(names.into_iter().zip(pixel.iter().copied()).collect()))
}

/// The material of the frame's pixel (`x`, `y`): the material index of each of its
/// G-buffer samples (one, or `supersample`^2 of a supersampled scene), read from the
/// G-buffer of the scene the header names, and the type of each in its material table.
pub fn materials_at(header: &TransferHeader, x: usize, y: usize) -> Result<Vec<(u32, &'static str)>, SceneError> {
    let scene = Scene::load_description(&header.scene)?;
    let file = scene.gbuffer.resolve(&scene.dir, header.frame);
    let gbuffer = GBufferFile::open(&file, &scene.channels, false, Reading::InBands)?;
    let n = scene.supersample.max(1);
    let (rows, columns) = (y * n..(y + 1) * n, x * n..(x + 1) * n);
    if rows.end > gbuffer.height || columns.end > gbuffer.width {
        return Err(SceneError::invalid(
            &file,
            format!("is {}x{}, which holds no samples of pixel ({x}, {y})", gbuffer.width, gbuffer.height),
        ));
    }
    let top = rows.start / LINES_PER_BLOCK * LINES_PER_BLOCK;
    let end = rows.end.div_ceil(LINES_PER_BLOCK) * LINES_PER_BLOCK;
    let read = gbuffer.read_rows(&scene.materials, top..end.min(gbuffer.height))?;
    let type_of = |m: u32| match m {
        0 => "background",
        m => scene.materials.get(&m).map_or("unknown", |material| material.type_name()),
    };
    Ok(rows
        .flat_map(|row| columns.clone().map(move |column| (row, column)))
        .map(|(row, column)| read.material[(row - top) * gbuffer.width + column])
        .map(|m| (m, type_of(m)))
        .collect())
}
