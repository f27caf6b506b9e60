//! `logsh relight`: frames with transfer layers relit under a light turned, scaled or
//! swapped ([`crate::transfer::relight`]), each frame read, relit and written in three
//! threads that overlap.

use super::shared::{describe_sun, CreatedDirectory};
use crate::cli::{RelightArgs, SharpLights, SunLamps};
use crate::render::progress::{reporter, Command, Progress};
use crate::render::{FrameOutcome, FrameStatus};
use crate::scene::{output, LightSource, Scene, ViewTransform};
use crate::shade::ShadedPasses;
use crate::transfer::{
    offering_soft_suns, offering_to_keep, relight_reusing, RelightLight, RelightOptions, SunLampTurn, TransferFrame,
    TransferHeader,
};
use anyhow::{anyhow, Result};
use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// `logsh relight`.
pub fn relight(args: &RelightArgs) -> Result<()> {
    if args.out.exists() && !args.out.is_dir() {
        return Err(anyhow!("--out {}: exists and is not a directory", args.out.display()));
    }
    if !args.light_rotation.is_finite() {
        return Err(anyhow!("--light-rotation {} is not a finite number of degrees", args.light_rotation));
    }
    let planned = PlannedOutputs::of(args)?;
    let _out = CreatedDirectory::new(&args.out)?;
    let started = Instant::now();
    let total = args.frames.len();
    let mut progress = reporter(args.progress, Command::Relight);
    progress.start(total);
    let mut relighter = FrameRelighter::new(args);
    let mut outcomes: Vec<Option<FrameOutcome>> = vec![None; total];
    let (reading, relit, written) =
        relight_in_threads(args, &planned.outputs, &mut relighter, progress.as_mut(), &mut outcomes);
    report_outcomes(args, &planned.numbers, relit, written, progress.as_mut(), outcomes)?;
    relighter.print_summary(args, started.elapsed().as_secs_f64(), reading);
    Ok(())
}

/// Each frame's number, where its header reads (as its reports give it), and its
/// outputs (EXR, PNG preview, light description), none of which is an input.
struct PlannedOutputs {
    numbers: Vec<Option<i64>>,
    outputs: Vec<[PathBuf; 3]>,
}

impl PlannedOutputs {
    fn of(args: &RelightArgs) -> Result<Self> {
        let canonical = |p: &Path| std::fs::canonicalize(p).ok();
        // What the relight reads: the frames, --light, and by each frame's header the map
        // it was lit with, its view's LUT, and the files of the scene it was rendered from
        // (its Sun lamps are shaded again from them). A frame whose header does not read
        // is refused when it is read.
        let mut inputs: Vec<PathBuf> = args.frames.iter().chain(&args.light).filter_map(|p| canonical(p)).collect();
        let mut scenes: Vec<Scene> = Vec::new();
        // Scenes whose scene.json does not read, which name no file: nothing is written
        // into their folders.
        let mut unread = Vec::new();
        let mut numbers: Vec<Option<i64>> = vec![None; args.frames.len()];
        for (number, file) in numbers.iter_mut().zip(&args.frames) {
            let Ok(header) = TransferFrame::read_header(file) else { continue };
            *number = Some(header.frame);
            if let LightSource::Environment { file, .. } = &header.light {
                inputs.extend(canonical(file));
            }
            if let Some(lut) = header.view.as_ref().and_then(|view| view.lut.as_ref()) {
                inputs.extend(canonical(&lut.file));
            }
            if !scenes.iter().any(|scene| scene.dir == header.scene) {
                match Scene::load_description(&header.scene) {
                    Ok(scene) => scenes.push(scene),
                    Err(e) => unread.extend(canonical(&header.scene).map(|dir| (dir, e))),
                }
            }
        }
        if let Some((dir, e)) =
            canonical(&args.out).and_then(|out| unread.into_iter().find(|(dir, _)| out.starts_with(dir)))
        {
            return Err(anyhow!(
                "--out {}: lies in the scene {} its frames were rendered from, whose scene.json does not read ({e}), \
                 so which of its files must not be written over is unknown; choose another --out",
                args.out.display(),
                dir.display()
            ));
        }
        let mut outputs: Vec<[PathBuf; 3]> = Vec::new();
        for file in &args.frames {
            let name = file.file_name().ok_or_else(|| anyhow!("{}: not a file", file.display()))?;
            let exr = args.out.join(name).with_extension("exr");
            let [png, json] = [exr.with_extension("png"), exr.with_extension("light.json")];
            for output in [&exr, &png, &json] {
                if canonical(output).is_some_and(|existing| inputs.contains(&existing)) {
                    return Err(anyhow!("{}: would be written over an input; choose another --out", output.display()));
                }
                for scene in &scenes {
                    scene.check_output_path(output).map_err(|e| anyhow!("{e}; choose another --out"))?;
                }
            }
            if outputs.iter().any(|[e, _, _]| *e == exr) {
                return Err(anyhow!("{}: two frames would be written to the same file", exr.display()));
            }
            outputs.push([exr, png, json]);
        }
        Ok(Self { numbers, outputs })
    }
}

/// Relights the frames of `args` into `outputs`, reporting each frame once written:
/// returns the seconds spent reading, the relight's result (with the index of the frame
/// that failed) and the writer's.
///
/// The next frame is read and the last one written while a frame is relit (one each: at
/// most two frames' transfer layers in memory). A frame that fails stops the sequence
/// once the frames before it are written. Each frame is read into the memory of the one
/// relit before it, and relit into that of the passes written before it
/// (`read_reusing`, `relight_reusing`). A frame is reported once written, from this
/// thread, as `render` reports.
fn relight_in_threads(
    args: &RelightArgs,
    outputs: &[[PathBuf; 3]],
    relighter: &mut FrameRelighter,
    progress: &mut dyn Progress,
    outcomes: &mut [Option<FrameOutcome>],
) -> (f64, Result<(), (usize, anyhow::Error)>, Result<()>) {
    let total = args.frames.len();
    std::thread::scope(|threads| {
        let (read_tx, read_rx) = std::sync::mpsc::sync_channel(0);
        let (write_tx, write_rx) = std::sync::mpsc::sync_channel::<Relit>(0);
        let (done_tx, done_rx) = std::sync::mpsc::channel::<(usize, FrameOutcome)>();
        let (spare_frame_tx, spare_frame_rx) = std::sync::mpsc::channel::<TransferFrame>();
        let (spare_passes_tx, spare_passes_rx) = std::sync::mpsc::channel::<ShadedPasses>();
        let reader = threads.spawn(move || {
            let mut reading = 0.0;
            for file in &args.frames {
                let t = Instant::now();
                let frame = TransferFrame::read_reusing(file, spare_frame_rx.try_recv().ok());
                let seconds = t.elapsed().as_secs_f64();
                reading += seconds;
                if read_tx.send((frame, seconds)).is_err() {
                    break;
                }
            }
            reading
        });
        let writer = threads.spawn(move || -> Result<()> {
            for relit in write_rx {
                let (index, outcome, passes, written) = write_relit(args, outputs, relit);
                done_tx.send((index, outcome)).ok();
                written?;
                // The relight may have finished: then the passes are dropped here.
                spare_passes_tx.send(passes).ok();
            }
            Ok(())
        });
        let mut report = |(index, outcome): (usize, FrameOutcome), progress: &mut dyn Progress| {
            progress.frame_finished(&outcome, index, total);
            outcomes[index] = Some(outcome);
        };
        let mut at = 0;
        let mut relit = || -> Result<()> {
            for (k, (file, (frame, read_seconds))) in args.frames.iter().zip(&read_rx).enumerate() {
                at = k;
                let mut frame = frame?;
                progress.frame_started(frame.header.frame, k);
                let t = Instant::now();
                let spare = spare_passes_rx.try_recv().ok();
                let (passes, view, description) = relighter.relight(file, &mut frame, spare, progress)?;
                let seconds = read_seconds + t.elapsed().as_secs_f64();
                let number = frame.header.frame;
                if write_tx.send(Relit { index: k, frame: number, passes, view, description, seconds }).is_err() {
                    break;
                }
                // The reader may have finished: then the frame is dropped here.
                spare_frame_tx.send(frame).ok();
                while let Ok(done) = done_rx.try_recv() {
                    report(done, progress);
                }
            }
            Ok(())
        };
        let relit = relit().map_err(|e| (at, e));
        // The reader stops at its next frame, the writer after its last.
        drop(read_rx);
        drop(write_tx);
        let written = writer.join().expect("the writer does not panic");
        for done in done_rx {
            report(done, progress);
        }
        let reading = reader.join().expect("the reader does not panic");
        (reading, relit, written)
    })
}

/// Writes one relit frame: its index, its outcome, its passes for the next frame's
/// relight to reuse, and the write's failure where it failed.
fn write_relit(
    args: &RelightArgs,
    outputs: &[[PathBuf; 3]],
    relit: Relit,
) -> (usize, FrameOutcome, ShadedPasses, Result<()>) {
    let Relit { index, frame, passes, view, description, seconds } = relit;
    let [exr, png, json] = &outputs[index];
    let t = Instant::now();
    let written = crate::render::write_passes(exr, &passes, args.colour_type)
        .and_then(|()| output::write_png_preview(png, passes.width, passes.height, &passes.beauty, &view))
        .and_then(|()| output::write_text(json, &description));
    let status = match &written {
        Ok(()) => FrameStatus::Done {
            seconds: seconds + t.elapsed().as_secs_f64(),
            outputs: vec![exr.clone(), png.clone(), json.clone()],
        },
        Err(e) => FrameStatus::Failed { error: format!("{e:#}") },
    };
    let input = Some(args.frames[index].clone());
    (index, FrameOutcome { frame: Some(frame), input, status }, passes, written.map_err(Into::into))
}

/// Reports the relight's failure, then the frames it stops before, in order after the
/// frames written; the writer's failure is of an earlier frame than the relight's, and a
/// failure names the frames it leaves out.
fn report_outcomes(
    args: &RelightArgs,
    numbers: &[Option<i64>],
    relit: Result<(), (usize, anyhow::Error)>,
    written: Result<()>,
    progress: &mut dyn Progress,
    mut outcomes: Vec<Option<FrameOutcome>>,
) -> Result<()> {
    let total = args.frames.len();
    let relit = relit.map_err(|(at, e)| {
        let status = FrameStatus::Failed { error: format!("{e:#}") };
        let outcome = FrameOutcome { frame: numbers[at], input: Some(args.frames[at].clone()), status };
        progress.frame_finished(&outcome, at, total);
        outcomes[at] = Some(outcome);
        e
    });
    for (k, outcome) in outcomes.iter_mut().enumerate().filter(|(_, o)| o.is_none()) {
        let stopped =
            FrameOutcome { frame: numbers[k], input: Some(args.frames[k].clone()), status: FrameStatus::Stopped };
        progress.frame_finished(&stopped, k, total);
        *outcome = Some(stopped);
    }
    let outcomes: Vec<FrameOutcome> = outcomes.into_iter().flatten().collect();
    progress.finish(&outcomes);
    written.and(relit).map_err(|e| {
        let stopped: Vec<String> =
            outcomes.iter().filter(|o| matches!(o.status, FrameStatus::Stopped)).map(FrameOutcome::label).collect();
        match stopped.len() {
            0 => e,
            n => anyhow!(
                "{e:#}; the relight stops there, and {n} frame(s) after it are not relit: {}",
                stopped.join(", ")
            ),
        }
    })
}

/// What carries from one frame of a relight to the next: the light, built again only
/// where a frame needs another; the scene's Sun lamps to shade again; what has been said
/// once; and the time each stage took.
struct FrameRelighter<'a> {
    args: &'a RelightArgs,
    options: RelightOptions,
    light: Option<RelightLight>,
    /// The scene, light and settings the Sun lamps were prepared for, and them.
    sun_lamps: Option<(SunLampKey, SunLampTurn)>,
    /// The maps whose suns held in SH have been named.
    warned_of_suns: HashSet<PathBuf>,
    warned_of_lamps: bool,
    warned_of_view: bool,
    /// Whether Sun lamps were turned, and a map's suns shaded, in any frame.
    shaded_again: [bool; 2],
    /// Seconds building the light, relighting, and shading the lamps again.
    building: f64,
    relighting: f64,
    shading_lamps: f64,
}

/// What a frame's Sun lamps are shaded again from: its scene, light, turn and settings.
type SunLampKey = (PathBuf, LightSource, f64, Option<crate::shade::ShadingSettings>);

impl<'a> FrameRelighter<'a> {
    fn new(args: &'a RelightArgs) -> Self {
        let options =
            RelightOptions { light: args.light.clone(), rotation: args.light_rotation, strength: args.strength };
        Self {
            args,
            options,
            light: None,
            sun_lamps: None,
            warned_of_suns: HashSet::new(),
            warned_of_lamps: false,
            warned_of_view: false,
            shaded_again: [false; 2],
            building: 0.0,
            relighting: 0.0,
            shading_lamps: 0.0,
        }
    }

    /// `frame` (read from `file`) relit into the memory of `spare`: its passes, its
    /// preview's view transform and its light's description.
    fn relight(
        &mut self,
        file: &Path,
        frame: &mut TransferFrame,
        spare: Option<ShadedPasses>,
        progress: &mut dyn Progress,
    ) -> Result<(ShadedPasses, ViewTransform, String)> {
        let t = Instant::now();
        self.build_light(file, &frame.header, progress)?;
        self.building += t.elapsed().as_secs_f64();
        self.shade_sharp_lights_again(file, frame, progress)?;
        let light = self.light.as_ref().expect("built by build_light");
        let t = Instant::now();
        let passes = relight_reusing(frame, light, spare);
        self.relighting += t.elapsed().as_secs_f64();
        let (view, standard) = ViewTransform::for_preview(frame.header.view.as_ref(), file);
        if let Some(reason) = standard.filter(|_| !self.warned_of_view) {
            self.warned_of_view = true;
            progress.notice(&format!("relight: {}: {reason}", file.display()));
        }
        let description = serde_json::to_string_pretty(&light.description(self.options.turn_beyond_render()))? + "\n";
        Ok((passes, view, description))
    }

    /// The light of a frame with `header` (read from `file`): the one built before where
    /// it serves, or built again; then checked against the map the frame was rendered
    /// with.
    fn build_light(&mut self, file: &Path, header: &TransferHeader, progress: &mut dyn Progress) -> Result<()> {
        let source = self.options.source(header);
        // The suns of the map shaded sharp where the render shaded them so.
        let sharp = self.args.sharp_lights == SharpLights::Auto
            && header.settings.is_some_and(|settings| settings.sharp_lights);
        if !self.light.as_ref().is_some_and(|l| l.serves(&source, header, sharp)) {
            let built = if sharp {
                RelightLight::with_sharp_suns(source, header, file)?
            } else {
                RelightLight::new(source, header, file)?
            };
            warn_of_suns_in_sh(&built, &mut self.warned_of_suns, progress);
            self.light = Some(built);
        }
        self.options.check_rendered_map(self.light.as_ref().expect("built above"), header, file)?;
        Ok(())
    }

    /// The Sun lamps turned and the map's suns, shaded again from the scene where the
    /// relight turns the lamps or its light has suns shaded sharp.
    fn shade_sharp_lights_again(
        &mut self,
        file: &Path,
        frame: &mut TransferFrame,
        progress: &mut dyn Progress,
    ) -> Result<()> {
        let turned = self.options.rotation != 0.0 && !frame.header.sun_lamps.is_empty();
        if turned && self.args.sun_lamps == SunLamps::Keep && !self.warned_of_lamps {
            self.warned_of_lamps = true;
            progress.notice(&sun_lamps_kept(file, &frame.header.sun_lamps, self.options.rotation));
        }
        let lamps_turned = turned && self.args.sun_lamps == SunLamps::Turn;
        let suns = self.light.as_ref().expect("built by build_light").sharp_suns();
        if !lamps_turned && suns.is_empty() {
            return Ok(());
        }
        let t = Instant::now();
        let offering = |e| {
            let e = if lamps_turned { offering_to_keep(e) } else { e };
            if suns.is_empty() {
                e
            } else {
                offering_soft_suns(e)
            }
        };
        let header = &frame.header;
        let key = (header.scene.clone(), header.light.clone(), header.light_turn, header.settings);
        if self.sun_lamps.as_ref().is_none_or(|(built, _)| *built != key) {
            self.sun_lamps = Some((key, SunLampTurn::new(header, file).map_err(offering)?));
        }
        let (_, turn) = self.sun_lamps.as_ref().expect("built above");
        let degrees = lamps_turned.then_some(self.options.rotation);
        turn.shade_again(frame, file, degrees, suns).map_err(offering)?;
        self.shading_lamps += t.elapsed().as_secs_f64();
        self.shaded_again[0] |= lamps_turned;
        self.shaded_again[1] |= !suns.is_empty();
        Ok(())
    }

    /// Prints the relight's time: `elapsed` seconds in all, `reading` of them reading.
    fn print_summary(&self, args: &RelightArgs, elapsed: f64, reading: f64) {
        let count = args.frames.len();
        let per_frame = |seconds: f64| 1e3 * seconds / count as f64;
        let lamps = match self.shaded_again {
            [false, false] => String::new(),
            [true, false] => format!(", the Sun lamps turned {:.1} ms", per_frame(self.shading_lamps)),
            [false, true] => format!(", the map's suns {:.1} ms", per_frame(self.shading_lamps)),
            [true, true] => {
                format!(", the Sun lamps turned and the map's suns {:.1} ms", per_frame(self.shading_lamps))
            }
        };
        eprintln!(
            "relit {count} frame(s) in {elapsed:.3} s, {:.3} s a frame (reading, relighting and writing overlap: \
             reading {:.1} ms, light {:.1} ms, relighting {:.1} ms{lamps} per frame): {}",
            elapsed / count as f64,
            per_frame(reading),
            per_frame(self.building),
            per_frame(self.relighting),
            args.out.display()
        );
    }
}

/// Says which suns of a relight's light its render would have shaded sharp
/// ([`crate::transfer::RelightLight::suns_in_sh`]), and what to run for sharp shadows;
/// once per map of a sequence (`warned` holds the maps already named).
fn warn_of_suns_in_sh(light: &RelightLight, warned: &mut HashSet<PathBuf>, progress: &mut dyn Progress) {
    let LightSource::Environment { file, .. } = &light.source else {
        return;
    };
    if !warned.insert(file.clone()) {
        return;
    }
    for (sun, share) in light.suns_in_sh() {
        progress.notice(&format!(
            "relight: {} holds a sun ({}), which a relight keeps in SH with the rest of the map where its frame \
             was rendered with --sharp-lights off or it is relit with it: its shadows come out soft, where \
             --sharp-lights auto (the default of `logsh render` and `logsh relight`) shades it sharp from the \
             scene",
            file.display(),
            describe_sun(&sun, share)
        ));
    }
}

/// What a relight turning the map by `degrees` with `--sun-lamps keep` says of the Sun
/// lamps `sun_lamps` (azimuth and elevation, as rendered in `file`), which it keeps where
/// `logsh render --light-rotation` would turn them; once per sequence.
fn sun_lamps_kept(file: &Path, sun_lamps: &[[f64; 2]], degrees: f64) -> String {
    let (lamp, stays, its) =
        if sun_lamps.len() > 1 { ("Sun lamps", "stay", "their") } else { ("Sun lamp", "stays", "its") };
    format!(
        "relight: {}: the scene's {lamp} ({}) {stays} as rendered, with {its} shadows (--sun-lamps keep): the \
         relight turns the map alone, where `logsh render --light-rotation {degrees}` and `logsh relight \
         --sun-lamps turn` turn Sun lamps with it and move their shadows",
        file.display(),
        crate::transfer::describe_sun_lamps(sun_lamps),
    )
}

/// A relit frame on its way to `logsh relight`'s writer: its index in the command's
/// frames, its number, its passes, its preview's view transform, its light's description
/// (`<frame>.light.json`), and the seconds it took to read and relight.
struct Relit {
    index: usize,
    frame: i64,
    passes: ShadedPasses,
    view: ViewTransform,
    description: String,
    seconds: f64,
}
