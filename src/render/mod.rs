//! `logsh render`: shade a sequence of frames, each into a multi-layer EXR of compositing
//! passes and a PNG preview, frame after frame (pixels in parallel within a frame).
//!
//! A farm runs this unattended, so one bad frame costs only itself: its error is recorded
//! and the next frame starts; a panic inside a frame is caught and reported the same way.
//! Outputs are written atomically and flushed to the disk (a killed run or node leaves
//! whole files or none, [`output::write_atomically`]), which is what makes
//! `--skip-existing` a safe resume: a frame counts as done when its EXR is whole (its
//! header reads, every chunk lies inside the file, the last one decodes) and so is its
//! PNG. The temporary files of a killed run are removed when the next one starts.
//!
//! # The output of a frame (`<name>.NNNN.exr`, one part, ZIP)
//!
//! | channels | type | what |
//! |---|---|---|
//! | `R`, `G`, `B`, `A` | colour | beauty = diffuse + specular + environment + indirect; alpha 1 on surfaces |
//! | `diffuse.{R,G,B}` | colour | the diffuse term |
//! | `specular.{R,G,B}` | colour | the Phong term (and water's mirror of the sky) |
//! | `environment.{R,G,B}` | colour | the light seen directly on the background |
//! | `indirect.{R,G,B}` | colour | bounce light: `indirect_heightfield` + `indirect_blockers` |
//! | `indirect_heightfield.{R,G,B}` | colour | bounce light from the terrain (height field or ground plane) |
//! | `indirect_blockers.{R,G,B}` | colour | bounce light from the sphere blockers |
//! | `visibility.Y` | colour | height field and blockers together |
//! | `visibility_heightfield.Y` | colour | the height field alone |
//! | `visibility_blockers.Y` | colour | the sphere blockers alone |
//! | `P.{X,Y,Z}`, `N.{X,Y,Z}` | float | world position and normal of the G-buffer |
//!
//! "colour" is half by default (`--colour-type float` stores f32); see
//! [`crate::shade::compositing`] and docs/design.md for the pass definitions. With
//! `--transfer` the file also holds the transfer layers of [`crate::transfer`] and their
//! header, and the frame is shaded on the CPU.

pub mod bands;
pub mod frames;
pub mod progress;

use crate::executor::{Bounce, Executor, ShadeJob};
use crate::scene::output::{write_exr_layers, OutputChannel, SampleType};
use crate::scene::{output, Scene, SceneError};
use crate::shade::{ShadedPasses, ShadingSettings};
use crate::timing::StageTimings;
use anyhow::Context;
use progress::Progress;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What a render of a sequence needs beyond the scene.
#[derive(Clone, Debug)]
pub struct SequenceOptions {
    /// Frames in render order.
    pub frames: Vec<i64>,
    /// Output directory.
    pub out: PathBuf,
    /// File name stem: `<name>.NNNN.exr` and `<name>.NNNN.png`.
    pub name: String,
    /// Leave frames whose outputs are complete untouched.
    pub skip_existing: bool,
    /// Storage of the colour passes.
    pub colour: SampleType,
    /// Add the transfer layers ([`crate::transfer`]), shading on the CPU.
    pub transfer: bool,
    /// How a supersampled scene is shaded and resolved ([`crate::shade::resolve`]).
    pub resolving: crate::shade::Resolving,
    /// G-buffer rows per band of a frame shaded in bands ([`bands`]); 0: every frame
    /// whole; `None`: bands of [`bands::BAND_SAMPLES`] samples, smaller frames whole.
    pub band_rows: Option<usize>,
    pub settings: ShadingSettings,
}

/// What became of one frame.
#[derive(Clone, Debug)]
pub enum FrameStatus {
    /// Rendered (relit), in `seconds` of reading, shading (relighting) and writing.
    Done {
        seconds: f64,
        outputs: Vec<PathBuf>,
    },
    /// Left as it was: its outputs were complete (`--skip-existing`).
    Skipped {
        outputs: Vec<PathBuf>,
    },
    Failed {
        error: String,
    },
    /// Not reached: a relight stops at its first failed frame.
    Stopped,
}

#[derive(Clone, Debug)]
pub struct FrameOutcome {
    /// The frame's number: the scene's, or the one a relit frame's header records (`None`
    /// where it does not read).
    pub frame: Option<i64>,
    /// The file a relight read the frame from (a render reads its frames from a scene).
    pub input: Option<PathBuf>,
    pub status: FrameStatus,
}

impl FrameOutcome {
    pub fn failed(&self) -> bool {
        matches!(self.status, FrameStatus::Failed { .. })
    }

    /// How reports name the frame: by its file where it was read from one, else by number.
    pub fn label(&self) -> String {
        match (&self.input, self.frame) {
            (Some(input), _) => input.display().to_string(),
            (None, Some(frame)) => format!("frame {frame}"),
            (None, None) => "a frame".into(),
        }
    }
}

/// The EXR and the PNG of `frame`: `<out>/<name>.NNNN.{exr,png}` (frame zero-padded to 4).
pub fn frame_outputs(out: &Path, name: &str, frame: i64) -> [PathBuf; 2] {
    ["exr", "png"].map(|ext| out.join(format!("{name}.{frame:04}.{ext}")))
}

/// Refuses, before anything is rendered, an output of any frame that is an input of the
/// scene, and a `name` that is not a plain file name.
pub fn check_outputs(scene: &Scene, options: &SequenceOptions) -> Result<(), SceneError> {
    let plain =
        !options.name.is_empty() && !options.name.contains(['/', '\\']) && options.name != "." && options.name != "..";
    if !plain {
        return Err(SceneError::invalid(
            &options.out,
            format!("--name \"{}\" must be a plain file name stem, without separators", options.name),
        ));
    }
    for &frame in &options.frames {
        for path in frame_outputs(&options.out, &options.name, frame) {
            scene.check_output_path(&path)?;
        }
    }
    Ok(())
}

/// True when both outputs are whole ([`output::whole_exr`], [`output::png_is_whole`])
/// and the EXR records transfer layers where `transfer` asks for them (a frame rendered
/// without is rendered again).
pub fn is_complete(outputs: &[PathBuf; 2], transfer: bool) -> bool {
    let [exr, png] = outputs;
    output::whole_exr(exr).is_some_and(|meta| !transfer || crate::transfer::holds_transfer(&meta))
        && output::png_is_whole(png)
}

/// Renders `options.frames` in order, reporting to `progress`; never stops early.
///
/// Reading, shading and writing overlap: a reader thread reads the frame after the one
/// being shaded, and a writer thread writes the one before it (EXR and PNG). The stages
/// hand frames over without a queue, so each is one frame ahead or behind and at most
/// three frames are in memory, and a sequence takes about the longest of the three stages
/// per frame rather than their sum. Frames are still reported in order, as their outputs
/// are complete; a frame's time is the sum of its reading, shading and writing, each timed
/// on its own thread.
pub fn render_sequence(
    executor: &Executor,
    scene: &Scene,
    options: &SequenceOptions,
    progress: &mut dyn Progress,
) -> Vec<FrameOutcome> {
    let total = options.frames.len();
    progress.start(total);
    let outputs: Vec<PathBuf> =
        options.frames.iter().flat_map(|&frame| frame_outputs(&options.out, &options.name, frame)).collect();
    let leftovers = output::remove_leftovers(&outputs);
    if let Some(first) = leftovers.first() {
        progress.notice(&format!(
            "removed {} temporary file(s) a killed render left in {}",
            leftovers.len(),
            first.parent().unwrap_or(Path::new(".")).display()
        ));
    }
    let mut outcomes = Vec::with_capacity(total);
    std::thread::scope(|threads| {
        let (read_tx, read_rx) = std::sync::mpsc::sync_channel::<Job<Read>>(0);
        let (write_tx, write_rx) = std::sync::mpsc::sync_channel::<Job<Shaded>>(0);
        let (done_tx, done_rx) = std::sync::mpsc::channel::<(usize, FrameOutcome)>();
        threads.spawn(move || {
            for (index, &frame) in options.frames.iter().enumerate() {
                let outputs = frame_outputs(&options.out, &options.name, frame);
                let started = Instant::now();
                let work = if options.skip_existing && is_complete(&outputs, options.transfer) {
                    Read::Skipped
                } else {
                    Read::Frame(guarded(|| read_frame(scene, frame, options)))
                };
                let seconds = started.elapsed().as_secs_f64();
                if read_tx.send(Job { index, frame, outputs, seconds, work }).is_err() {
                    break;
                }
            }
        });
        threads.spawn(move || {
            for job in write_rx {
                let status = match job.work {
                    Shaded::Skipped => FrameStatus::Skipped { outputs: job.outputs.to_vec() },
                    Shaded::Failed(error) => FrameStatus::Failed { error },
                    Shaded::Written => FrameStatus::Done { seconds: job.seconds, outputs: job.outputs.to_vec() },
                    Shaded::Passes(shaded) => {
                        let started = Instant::now();
                        match guarded(|| write_frame(scene, job.frame, options, &job.outputs, &shaded)) {
                            Ok(()) => FrameStatus::Done {
                                seconds: job.seconds + started.elapsed().as_secs_f64(),
                                outputs: job.outputs.to_vec(),
                            },
                            Err(e) => FrameStatus::Failed { error: format!("{e:#}") },
                        }
                    }
                };
                if done_tx.send((job.index, FrameOutcome { frame: Some(job.frame), input: None, status })).is_err() {
                    break;
                }
            }
        });
        let mut report = |(index, outcome): (usize, FrameOutcome), progress: &mut dyn Progress| {
            progress.frame_finished(&outcome, index, total);
            outcomes.push(outcome);
        };
        for job in read_rx {
            progress.frame_started(job.frame, job.index);
            let started = Instant::now();
            let work = match job.work {
                Read::Skipped => Shaded::Skipped,
                Read::Frame(Err(e)) => Shaded::Failed(format!("{e:#}")),
                Read::Frame(Ok(ReadFrame::InBands(opened, bands))) => {
                    let written =
                        guarded(|| bands::render_in_bands(executor, scene, &opened, &bands, options, &job.outputs));
                    match written {
                        Ok(()) => Shaded::Written,
                        Err(e) => Shaded::Failed(format!("{e:#}")),
                    }
                }
                Read::Frame(Ok(ReadFrame::Whole(data))) => {
                    let shaded = guarded(|| shade_frame(executor, scene, &data, options, Bounce::OfFrame));
                    match shaded {
                        Ok(shaded) => Shaded::Passes(Box::new(shaded)),
                        Err(e) => Shaded::Failed(format!("{e:#}")),
                    }
                }
            };
            for notice in executor.take_notices() {
                progress.notice(&notice.0);
            }
            let Job { index, frame, outputs, seconds, .. } = job;
            let seconds = seconds + started.elapsed().as_secs_f64();
            if write_tx.send(Job { index, frame, outputs, seconds, work }).is_err() {
                break;
            }
            while let Ok(done) = done_rx.try_recv() {
                report(done, progress);
            }
        }
        drop(write_tx);
        for done in done_rx {
            report(done, progress);
        }
    });
    progress.finish(&outcomes);
    outcomes
}

/// One frame on its way through the stages of [`render_sequence`].
struct Job<W> {
    index: usize,
    frame: i64,
    outputs: [PathBuf; 2],
    /// The time its stages so far took.
    seconds: f64,
    work: W,
}

/// What the reader hands on: a frame whose outputs are complete (`--skip-existing`), or
/// the frame read.
enum Read {
    Skipped,
    Frame(anyhow::Result<ReadFrame>),
}

/// A frame read whole, or opened to be read, shaded and written in bands ([`bands`]),
/// which the shading stage does itself.
enum ReadFrame {
    Whole(Box<crate::scene::Frame>),
    InBands(Box<crate::scene::OpenFrame>, Vec<bands::Band>),
}

/// Frame `frame` of `scene`, whole, or opened for its bands where it is larger than one.
fn read_frame(scene: &Scene, frame: i64, options: &SequenceOptions) -> anyhow::Result<ReadFrame> {
    let (width, height) = bands::gbuffer_size(scene, frame)?;
    Ok(match bands::bands(width, height, scene.supersample, &options.settings, options.band_rows) {
        None => ReadFrame::Whole(Box::new(scene.frame(frame)?)),
        Some(bands) => {
            let opened = scene.open_frame(frame, crate::scene::Reading::InBands)?;
            ReadFrame::InBands(Box::new(opened), bands)
        }
    })
}

/// What the shading hands on to the writer.
enum Shaded {
    Skipped,
    Failed(String),
    /// Shaded and written in bands.
    Written,
    Passes(Box<FramePasses>),
}

/// A shaded frame's passes, and its transfer layers with `--transfer`.
struct FramePasses {
    passes: ShadedPasses,
    transfer: Option<crate::transfer::TransferFrame>,
}

/// `work`, with a panic inside it caught and turned into an error naming it, so that one
/// frame's failure costs only that frame.
fn guarded<T>(work: impl FnOnce() -> anyhow::Result<T>) -> anyhow::Result<T> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(work)) {
        Ok(result) => result,
        Err(panic) => Err(anyhow::anyhow!("internal error (please report): {}", panic_message(&panic))),
    }
}

fn panic_message(panic: &Box<dyn std::any::Any + Send>) -> String {
    panic
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic without a message".into())
}

/// Shades one frame read from `scene` (or a band of one, [`bands`]), its bounce light
/// from `bounce`.
fn shade_frame(
    executor: &Executor,
    scene: &Scene,
    data: &crate::scene::Frame,
    options: &SequenceOptions,
    bounce: Bounce,
) -> anyhow::Result<FramePasses> {
    let settings = &options.settings;
    Ok(if options.transfer {
        let (mut passes, transfer) = crate::transfer::shade_with_transfer(scene, data, settings)?;
        if let Some(indirect) = executor.bounce(bounce, scene, data, settings, &passes.visibility)? {
            passes.add_indirect(indirect);
        }
        FramePasses { passes, transfer: Some(transfer) }
    } else {
        let job = ShadeJob { resolving: Some(options.resolving), bounce, ..ShadeJob::new(scene, data, settings) };
        let passes = executor.shade(&job, &mut StageTimings::default())?;
        FramePasses { passes, transfer: None }
    })
}

/// Writes one shaded frame: its EXR, then its PNG preview.
fn write_frame(
    scene: &Scene,
    frame: i64,
    options: &SequenceOptions,
    outputs: &[PathBuf; 2],
    shaded: &FramePasses,
) -> anyhow::Result<()> {
    let [exr, png] = outputs;
    let passes = &shaded.passes;
    match &shaded.transfer {
        Some(transfer) => write_passes_with_transfer(exr, passes, transfer, options.colour)?,
        None => write_passes(exr, passes, options.colour)?,
    }
    output::write_png_preview(png, passes.width, passes.height, &passes.beauty, &scene.view)
        .with_context(|| format!("frame {frame}: cannot write the preview"))?;
    Ok(())
}

/// The channels of the table in the module doc, in that order, read in place from the
/// passes.
pub fn pass_channels(passes: &ShadedPasses, colour: SampleType) -> Vec<OutputChannel<'_>> {
    let (rgb, xyz) = (["R", "G", "B"], ["X", "Y", "Z"]);
    let mut channels = OutputChannel::layer("", &["R", "G", "B", "A"], passes.beauty.as_flattened(), colour);
    for (layer, values) in [
        ("diffuse", &passes.diffuse),
        ("specular", &passes.specular),
        ("environment", &passes.environment),
        ("indirect", &passes.indirect),
        ("indirect_heightfield", &passes.indirect_heightfield),
        ("indirect_blockers", &passes.indirect_blockers),
    ] {
        channels.extend(OutputChannel::layer(layer, &rgb, values.as_flattened(), colour));
    }
    channels.extend(OutputChannel::layer("P", &xyz, passes.position.as_flattened(), SampleType::Float));
    channels.extend(OutputChannel::layer("N", &xyz, passes.normal.as_flattened(), SampleType::Float));
    for (layer, values) in [
        ("visibility", &passes.visibility),
        ("visibility_heightfield", &passes.visibility_heightfield),
        ("visibility_blockers", &passes.visibility_blockers),
    ] {
        channels.extend(OutputChannel::layer(layer, &["Y"], values, colour));
    }
    channels
}

/// Writes the multi-layer EXR of one frame.
pub fn write_passes(path: &Path, passes: &ShadedPasses, colour: SampleType) -> Result<(), output::OutputError> {
    write_exr_layers(path, passes.width, passes.height, &pass_channels(passes, colour), &[])
}

/// Writes the multi-layer EXR of one frame with its transfer layers and their header
/// ([`crate::transfer`]).
pub fn write_passes_with_transfer(
    path: &Path,
    passes: &ShadedPasses,
    transfer: &crate::transfer::TransferFrame,
    colour: SampleType,
) -> Result<(), output::OutputError> {
    let mut channels = pass_channels(passes, colour);
    channels.extend(transfer.channels(colour));
    let text =
        transfer.header_text().map_err(|message| output::OutputError::Encode { file: path.to_path_buf(), message })?;
    let attributes = [(crate::transfer::TRANSFER_ATTRIBUTE, text)];
    write_exr_layers(path, passes.width, passes.height, &channels, &attributes)
}
