//! Frames shaded, resolved and written in bands of rows, so that the memory a frame takes
//! is that of a band whatever its size (`logsh render --band-rows`).
//!
//! A band is shaded as a frame of its own rows and a margin of rows above and below it:
//! every step that reads a pixel's neighbours finds them there. Those steps are the
//! resolve of a supersampled frame (Blackman-Harris reaches a pixel beyond its own
//! samples), the visibility grid's interpolation between the blocks around a pixel, and
//! the bounce light's interpolation between the nodes of its stride. Bands start on rows
//! where the EXR's blocks, the camera's pixels, the grid's blocks and the bounce's nodes
//! all start, so each row a band keeps is shaded from the same inputs as in the whole
//! frame. What the bounce light summarises of the whole frame (its surroundings) is
//! surveyed band by band first ([`SurroundingsPlan::surveyed`]), and so is the check that
//! the G-buffer lies on the frame's height map. The outputs are byte-identical to those
//! of the frame shaded whole; the test suite compares them.
//!
//! The EXR is written a band at a time ([`exr_zip::write_in_bands`]); the PNG preview's
//! 8-bit pixels are kept until the last band.

use super::{pass_channels, shade_frame, FramePasses, SequenceOptions};
use crate::executor::{Bounce, Executor};
use crate::scene::output::{self, OutputChannel};
use crate::scene::{exr_zip, BuriedCount, Frame, OpenFrame, Scene};
use crate::shade::bounce::{Surroundings, SurroundingsPlan};
use crate::shade::ShadingSettings;
use crate::transfer::GBufferDigest;
use anyhow::Context;
use std::ops::Range;
use std::path::PathBuf;

/// G-buffer samples per band by default: frames up to this size are shaded whole. A band
/// of it with transfer layers holds about 3 GB.
pub const BAND_SAMPLES: usize = 1 << 22;

/// One band: the G-buffer rows it keeps, and those it reads and shades (the rows kept and
/// the margins).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Band {
    pub read: Range<usize>,
    pub keep: Range<usize>,
}

/// The bands of a `width` x `height` G-buffer of `supersample` samples per pixel along
/// each axis shaded with `settings`: `None` where the frame is shaded whole
/// (`band_rows` 0, or a frame no larger than a band). `band_rows`: G-buffer rows per
/// band, rounded up to where bands may start ([module doc](self)); by default as many as
/// make [`BAND_SAMPLES`].
pub fn bands(
    width: usize,
    height: usize,
    supersample: usize,
    settings: &ShadingSettings,
    band_rows: Option<usize>,
) -> Option<Vec<Band>> {
    let rows = match band_rows {
        Some(0) => return None,
        Some(rows) => rows,
        None if width * height <= BAND_SAMPLES => return None,
        None => BAND_SAMPLES / width.max(1),
    };
    let n = supersample.max(1);
    let stride = if settings.bounce.bounces > 0 { settings.bounce.stride.max(1) * n } else { 1 };
    let grid = settings.visibility_grid.max(1) * n;
    let start_every = lcm(exr_zip::LINES_PER_BLOCK * n, lcm(stride, grid));
    let round_up = |rows: usize| rows.div_ceil(start_every).max(1) * start_every;
    let rows = round_up(rows);
    if rows >= height {
        return None;
    }
    // Blackman-Harris reaches `ceil(0.75 n) + 1` samples past a pixel's own, the grid a
    // block on each side, the bounce the node after a pixel's.
    let margin = round_up((2 * n + 2).max(stride).max(2 * grid));
    Some(
        (0..height.div_ceil(rows))
            .map(|k| {
                let keep = k * rows..((k + 1) * rows).min(height);
                let read = keep.start.saturating_sub(margin)..(keep.end + margin).min(height);
                Band { read, keep }
            })
            .collect(),
    )
}

fn lcm(a: usize, b: usize) -> usize {
    let gcd = |mut a: usize, mut b: usize| {
        while b != 0 {
            (a, b) = (b, a % b);
        }
        a
    };
    a / gcd(a, b) * b
}

/// Shades `opened` in `bands` and writes its EXR and PNG (`outputs`), as
/// [`super::render_sequence`] would write the frame shaded whole.
pub fn render_in_bands(
    executor: &Executor,
    scene: &Scene,
    opened: &OpenFrame,
    bands: &[Band],
    options: &SequenceOptions,
    outputs: &[PathBuf; 2],
) -> anyhow::Result<()> {
    let Survey { surroundings, digest } = survey(executor, scene, opened, bands, options)?;
    let (width, height) = opened.size();
    let n = scene.supersample.max(1);
    let (out_width, out_height) = (width / n, height / n);
    let mut preview = Vec::with_capacity(out_width * out_height * 4);
    let [exr, png] = outputs;
    let shade = |band: &Band| -> anyhow::Result<FramePasses> {
        let frame = opened.rows(scene, band.read.clone())?;
        let mut shaded = shade_frame(executor, scene, &frame, options, Bounce::Given(surroundings.as_ref()))?;
        if let (Some(transfer), Some(digest)) = (&mut shaded.transfer, &digest) {
            let inputs = transfer.header.sun_lamp_inputs.take();
            transfer.header.sun_lamp_inputs = inputs.map(|inputs| inputs.with_gbuffer(digest));
        }
        Ok(shaded)
    };
    // The first band is shaded before the file is opened: it names the channels, and
    // with transfer layers the header.
    let first = shade(&bands[0])?;
    let channel_names: Vec<(String, output::SampleType)> =
        channels(&first, options).iter().map(|c| (c.name.clone(), c.sample_type)).collect();
    let attributes = match &first.transfer {
        Some(transfer) => {
            let text = transfer.header_text().map_err(|message| anyhow::anyhow!("{}: {message}", exr.display()))?;
            vec![(crate::transfer::TRANSFER_ATTRIBUTE, text)]
        }
        None => Vec::new(),
    };
    let layer_attributes = output::text_attributes(exr, &attributes)?;
    let first_header = first.transfer.as_ref().map(|transfer| transfer.header.clone());
    let mut failure = None;
    let written = output::write_atomically(
        exr,
        |temp| {
            let file = std::fs::File::create(temp).map_err(exr::error::Error::from)?;
            exr_zip::write_in_bands(
                std::io::BufWriter::new(file),
                out_width,
                out_height,
                &channel_names,
                layer_attributes,
                |sink| {
                    let mut shaded = Some(first);
                    for band in bands {
                        let passes = match shaded.take().map_or_else(|| shade(band), Ok) {
                            Ok(passes) => passes,
                            Err(error) => {
                                failure = Some(error);
                                return Err(exr::error::Error::Aborted);
                            }
                        };
                        if let (Some(transfer), Some(header)) = (&passes.transfer, &first_header) {
                            if transfer.header != *header {
                                failure = Some(anyhow::anyhow!(
                                    "internal error (please report): band {}..{} records another transfer header",
                                    band.keep.start,
                                    band.keep.end
                                ));
                                return Err(exr::error::Error::Aborted);
                            }
                        }
                        let kept = (band.keep.start - band.read.start) / n..(band.keep.end - band.read.start) / n;
                        let band_channels: Vec<OutputChannel> =
                            channels(&passes, options).iter().map(|c| c.rows(out_width, kept.clone())).collect();
                        sink.write_rows(band.keep.start / n, &band_channels)?;
                        let beauty = &passes.passes.beauty[kept.start * out_width..kept.end * out_width];
                        preview.extend(output::preview_bytes(beauty, &scene.view));
                    }
                    Ok(())
                },
            )
        },
        |e| output::OutputError::Encode { file: exr.to_path_buf(), message: e.to_string() },
    );
    if let Some(error) = failure {
        return Err(error);
    }
    written?;
    output::write_png_bytes(png, out_width, out_height, &preview)
        .with_context(|| format!("frame {}: cannot write the preview", opened.number))?;
    Ok(())
}

/// The channels of a band's passes, and its transfer layers where it has them.
fn channels<'a>(shaded: &'a FramePasses, options: &SequenceOptions) -> Vec<OutputChannel<'a>> {
    let mut channels = pass_channels(&shaded.passes, options.colour);
    if let Some(transfer) = &shaded.transfer {
        channels.extend(transfer.channels(options.colour));
    }
    channels
}

/// What a frame shaded in bands needs of the whole frame before its first band.
struct Survey {
    /// The surroundings its bounce light comes from, lit (`None`: nothing bounces).
    surroundings: Option<Surroundings>,
    /// With transfer layers, the sum of its G-buffers that their header records.
    digest: Option<GBufferDigest>,
}

/// Reads the frame's bands before any is shaded, for the check that its G-buffer lies on
/// its height map, the sum of its G-buffers (with transfer layers) and the surroundings
/// of its bounce light (which read the bands twice); the check and the sum take the
/// first reading.
fn survey(
    executor: &Executor,
    scene: &Scene,
    opened: &OpenFrame,
    bands: &[Band],
    options: &SequenceOptions,
) -> anyhow::Result<Survey> {
    let settings = &options.settings;
    let first: Frame = opened.rows(scene, bands[0].keep.clone())?;
    let mut summed = None::<(BuriedCount, Option<GBufferDigest>)>;
    let mut each_band = |visit: &mut dyn FnMut(&crate::scene::GBuffer)| -> Result<(), crate::shade::ShadeError> {
        let first_reading = summed.is_none();
        let (mut buried, mut digest) = (BuriedCount::default(), options.transfer.then(|| GBufferDigest::new(&first)));
        for band in bands {
            let frame = opened.rows(scene, band.keep.clone())?;
            if first_reading {
                opened.count_buried(&frame.gbuffer, &mut buried);
                if let Some(digest) = &mut digest {
                    digest.add(&frame);
                }
            }
            visit(&frame.gbuffer);
        }
        if first_reading {
            summed = Some((buried, digest));
        }
        Ok(())
    };
    let plan = if settings.bounce.bounces > 0 {
        SurroundingsPlan::surveyed(scene, &first, &settings.bounce, &mut each_band)?
    } else {
        if scene.heightfield.is_some() || options.transfer {
            each_band(&mut |_| {})?;
        }
        None
    };
    let (buried, digest) = summed.unwrap_or_default();
    opened.check_buried(scene, buried)?;
    let surroundings = match plan {
        Some(plan) => Some(executor.light_surroundings(scene, plan, settings)?),
        None => None,
    };
    Ok(Survey { surroundings, digest })
}

/// The G-buffer's size, from its header alone.
pub fn gbuffer_size(scene: &Scene, frame: i64) -> Result<(usize, usize), crate::scene::SceneError> {
    crate::scene::GBufferFile::size(&scene.gbuffer.resolve(&scene.dir, frame), &scene.channels)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bands_cover_every_row_once_and_start_where_blocks_and_pixels_do() {
        let mut settings = ShadingSettings::default();
        for (supersample, grid, bounces) in [(1, 1, 0), (2, 2, 2), (4, 4, 2), (3, 1, 2)] {
            settings.visibility_grid = grid;
            settings.bounce.bounces = bounces;
            let height = 1000 * supersample;
            let bands = bands(64, height, supersample, &settings, Some(100)).expect("bands");
            let mut next = 0;
            for band in &bands {
                assert_eq!(band.keep.start, next);
                next = band.keep.end;
                assert_eq!(band.keep.start % 16, 0);
                assert_eq!(band.keep.start % (supersample * grid), 0);
                assert!(band.read.start <= band.keep.start && band.read.end >= band.keep.end);
                assert_eq!(band.read.start % 16, 0);
            }
            assert_eq!(next, height);
        }
        assert_eq!(super::bands(64, 64, 1, &settings, None), None, "a small frame is shaded whole");
        assert_eq!(super::bands(8192, 8192, 1, &settings, Some(0)), None);
    }

    #[test]
    fn lcm_is_the_least_common_multiple() {
        assert_eq!(lcm(16, 6), 48);
        assert_eq!(lcm(16, 8), 16);
        assert_eq!(lcm(1, 1), 1);
    }
}
