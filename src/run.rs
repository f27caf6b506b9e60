//! What each command does, between parsed options and the library.

use crate::cli::{BenchArgs, ExampleArgs, ExampleName, ReferenceArgs, ShadeArgs, SweepArgs};
use crate::executor::{Executor, ShadeJob};
use crate::reference::{render_reference, ReferenceLight, ReferenceOptions};
use crate::scene::{output, Scene};
use crate::shade::ShadedFrame;
use crate::timing::StageTimings;
use anyhow::{anyhow, Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::path::Path;
use std::time::Instant;

/// `logsh shade`.
pub fn shade(args: &ShadeArgs) -> Result<()> {
    let settings = args.shading.settings()?;
    let mut scene = Scene::load(&args.scene)?;
    scene.turn_light(args.shading.light_rotation)?;
    let frame_number = args.frame.unwrap_or_else(|| scene.default_frame());
    let frame = scene.frame(frame_number)?;
    print_sharp_lights(&frame.light, &settings);
    let executor = Executor::select(args.shading.device, &settings)?;
    print_notices(&executor);
    let started = Instant::now();
    let job = ShadeJob { resolving: Some(args.shading.resolving()), ..ShadeJob::new(&scene, &frame, &settings) };
    let mut timings = StageTimings::default();
    let shaded = executor.shade::<ShadedFrame>(&job, &mut timings);
    print_notices(&executor);
    let shaded = shaded?;
    let elapsed = started.elapsed();
    let stem = format!("beauty.{frame_number:04}");
    let (width, height) = (shaded.width, shaded.height);
    write_image(&scene, &args.out, &stem, (width, height), &shaded.rgba, None)?;
    eprintln!(
        "shaded frame {frame_number} ({width}x{height}{}) at order {}, eps {}, {:?} on {} in {:.2} s: {}, {}",
        match timings.samples {
            Some((shaded, all)) => format!(", {0}x{0} samples per pixel, {shaded} of {all} shaded", scene.supersample),
            None if scene.supersample > 1 => format!(", {0}x{0} samples per pixel, all shaded", scene.supersample),
            None => String::new(),
        },
        settings.order,
        settings.epsilon,
        settings.exp,
        timings.device,
        elapsed.as_secs_f64(),
        args.out.join(format!("{stem}.exr")).display(),
        args.out.join(format!("{stem}.png")).display()
    );
    Ok(())
}

/// Says which suns `--sharp-lights auto` takes out of an environment map: the
/// decomposition the first frame's plan then takes them from
/// ([`crate::shade::sharp_lights::decomposition`]).
fn print_sharp_lights(light: &std::sync::Arc<crate::scene::Light>, settings: &crate::shade::ShadingSettings) {
    let crate::scene::Light::Environment { map, .. } = light.as_ref() else {
        return;
    };
    let Some(split) = settings.sharp_lights.then(|| crate::shade::sharp_lights::decomposition(light)).flatten() else {
        return;
    };
    for (sun, share) in split.suns.iter().zip(&split.shares) {
        eprintln!(
            "sharp lights: took a sun out of {}: {} (--sharp-lights off keeps it in SH)",
            map.file.display(),
            describe_sun(sun, *share)
        );
    }
}

/// Where a sun taken out of a map is, its width and its share of the map's light.
fn describe_sun(sun: &crate::scene::SunLight, share: f64) -> String {
    let [azimuth, elevation] = sun.azimuth_elevation();
    format!(
        "azimuth {azimuth:.1} deg, elevation {elevation:.1} deg, {:.2} deg wide, {:.0}% of its light",
        2.0 * sun.half_angle.to_degrees(),
        100.0 * share
    )
}

/// Prints what the executor has to say about where frames are shaded.
fn print_notices(executor: &Executor) {
    for notice in executor.take_notices() {
        eprintln!("{notice}");
    }
}

/// Writes `<stem>.exr` (linear RGBA) and `<stem>.png` (the scene's preview) into `dir`,
/// after checking that neither is one of the scene's inputs; a frame of a supersampled
/// scene's samples is resolved to the camera's resolution with `filter` first (`None`:
/// the image is at the camera's resolution already). Returns the size written.
fn write_image(
    scene: &Scene,
    dir: &Path,
    stem: &str,
    (width, height): (usize, usize),
    rgba: &[[f32; 4]],
    filter: Option<crate::shade::PixelFilter>,
) -> Result<(usize, usize)> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create output directory {}", dir.display()))?;
    let exr = dir.join(format!("{stem}.exr"));
    let png = dir.join(format!("{stem}.png"));
    for path in [&exr, &png] {
        scene.check_output_path(path)?;
    }
    let n = scene.supersample;
    let resolved;
    let (width, height, rgba) = if let Some(filter) = filter.filter(|_| n > 1) {
        resolved = crate::shade::Resolve::new(n, width / n, height / n, filter).filter(rgba);
        (width / n, height / n, resolved.as_slice())
    } else {
        (width, height, rgba)
    };
    output::write_exr_rgba(&exr, width, height, rgba)?;
    output::write_png_preview(&png, width, height, rgba, &scene.view)?;
    Ok((width, height))
}

/// A progress bar on a terminal, nothing otherwise (logs stay clean).
fn progress_bar(total: usize, what: &str) -> ProgressBar {
    let bar = ProgressBar::with_draw_target(
        Some(total as u64),
        if std::io::stderr().is_terminal() { ProgressDrawTarget::stderr() } else { ProgressDrawTarget::hidden() },
    );
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} {elapsed}<{eta}").expect("valid template"),
    );
    bar.set_message(what.to_string());
    bar
}

/// `logsh reference`.
pub fn reference(args: &ReferenceArgs) -> Result<()> {
    let scene = Scene::load(&args.scene)?;
    let frame_number = args.frame.unwrap_or_else(|| scene.default_frame());
    let frame = scene.frame(frame_number)?;
    let height = frame.gbuffer.height;
    for (light, stem) in [
        (ReferenceLight::EnvironmentMap, format!("reference.{frame_number:04}")),
        (ReferenceLight::ShProjected { order: args.sh_order }, format!("reference_sh.{frame_number:04}")),
    ] {
        let options = ReferenceOptions {
            light: light.clone(),
            integration: args.integration,
            tolerance: args.tolerance,
            max_level: args.max_level,
            bounces: args.bounces,
            bounce_samples: args.bounce_samples,
        };
        let bar = progress_bar(height, &format!("reference ({light:?})"));
        let started = Instant::now();
        let image = render_reference(&scene, &frame, &options, &|rows| bar.set_position(rows as u64))?;
        bar.finish_and_clear();
        write_image(&scene, &args.out, &stem, (image.width, image.height), &image.rgba, Some(args.pixel_filter))?;
        eprintln!(
            "{stem}: {:?} light, {:?}, {:.1} s, {} pixel(s) above the tolerance {} (largest error estimate {:.2e})",
            light,
            image.integration,
            started.elapsed().as_secs_f64(),
            image.unconverged_pixels,
            args.tolerance,
            image.max_estimated_error
        );
    }
    Ok(())
}

/// `logsh sweep`.
pub fn sweep(args: &SweepArgs) -> Result<()> {
    let scene = Scene::load(&args.scene)?;
    let frame_number = args.frame.unwrap_or_else(|| scene.default_frame());
    let frame = scene.frame(frame_number)?;
    let options = ReferenceOptions {
        light: ReferenceLight::EnvironmentMap,
        integration: args.integration,
        tolerance: args.tolerance,
        ..Default::default()
    };
    let bar = progress_bar(frame.gbuffer.height, "reference");
    let reference = render_reference(&scene, &frame, &options, &|rows| bar.set_position(rows as u64))?;
    bar.finish_and_clear();
    write_image(
        &scene,
        &args.out,
        &format!("reference.{frame_number:04}"),
        (reference.width, reference.height),
        &reference.rgba,
        Some(crate::shade::PixelFilter::Box),
    )?;
    let executor = Executor::select(args.device, &crate::shade::ShadingSettings::default())?;
    print_notices(&executor);
    eprintln!("sweep: shading on {}", executor.describe());
    let bar = progress_bar(crate::sweep::configurations().len(), "sweep");
    let rows = crate::sweep::run(&executor, &scene, &frame, &reference.rgba, args.repeats, &|done, _| {
        bar.set_position(done as u64)
    });
    bar.finish_and_clear();
    print_notices(&executor);
    let rows = rows?;
    let name = args.scene.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "scene".into());
    let files = [
        ("sweep.csv", crate::sweep::to_csv(&rows)),
        ("sweep.json", serde_json::to_string_pretty(&rows)?),
        ("sweep.svg", crate::sweep::chart(&rows, &name).to_svg()),
    ];
    for (file, text) in files {
        let path = args.out.join(file);
        scene.check_output_path(&path)?;
        output::write_text(&path, &text)?;
    }
    println!("{:<18} {:<8} {:>10} {:>9} {:>9} {:>9}", "knob", "value", "ms/frame", "mean", "p99", "rmse");
    for r in &rows {
        println!(
            "{:<18} {:<8} {:>10.1} {:>9.4} {:>9.4} {:>9.4}",
            r.knob, r.value, r.milliseconds, r.mean_abs, r.p99_abs, r.rmse
        );
    }
    eprintln!(
        "reference: {} pixel(s) above the tolerance {}; wrote sweep.csv, sweep.json, sweep.svg to {}",
        reference.unconverged_pixels,
        args.tolerance,
        args.out.display()
    );
    Ok(())
}

/// `logsh example`.
pub fn example(args: &ExampleArgs) -> Result<()> {
    let name = match args.name {
        ExampleName::Dunes => "dunes",
        ExampleName::Spheres => "spheres",
    };
    let existing = args.out.join(crate::scene::SCENE_FILE);
    if existing.exists() {
        return Err(anyhow!(
            "{} already holds a scene; remove it or choose another --out (an existing scene is never overwritten)",
            args.out.display()
        ));
    }
    if !(1..=crate::scene::MAX_SUPERSAMPLE as u32).contains(&args.supersample) {
        return Err(anyhow!("--supersample {}: give 1 to {}", args.supersample, crate::scene::MAX_SUPERSAMPLE));
    }
    let options = crate::synth::ExampleOptions { width: args.width, height: args.height, ..Default::default() };
    crate::synth::example(name, options)
        .and_then(|scene| crate::synth::write_scene_supersampled(&args.out, &scene, args.supersample))
        .with_context(|| format!("cannot write example scene {name} to {}", args.out.display()))?;
    eprintln!("wrote example scene {name} to {}", args.out.display());
    Ok(())
}

/// `logsh bench`.
pub fn bench(args: &BenchArgs) -> Result<()> {
    let settings = args.shading.settings()?;
    let mut scene = Scene::load(&args.scene)?;
    scene.turn_light(args.shading.light_rotation)?;
    let frame_number = args.frame.unwrap_or_else(|| scene.default_frame());
    let frame = scene.frame(frame_number)?;
    let executor = Executor::select(args.shading.device, &settings)?;
    print_notices(&executor);
    let report = crate::bench::measure(&executor, &scene, &frame, &settings, args.specialise, args.repeats);
    print_notices(&executor);
    let report = report?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.table());
    }
    Ok(())
}

/// `logsh render`.
pub fn render(args: &crate::cli::RenderArgs) -> Result<()> {
    use crate::render::progress::{reporter, Command};
    use crate::render::{check_outputs, render_sequence, FrameStatus, SequenceOptions};
    let settings = args.shading.settings()?;
    if args.threads == Some(0) {
        return Err(anyhow!("--threads 0: give at least 1, or leave it out for one thread per core"));
    }
    if args.transfer {
        crate::transfer::check_grid(&settings)?;
    }
    let mut scene = Scene::load(&args.scene)?;
    scene.turn_light(args.shading.light_rotation)?;
    if args.transfer {
        // The transfer header records the scene's folder, map and LUT as JSON text, which
        // holds no path that is not Unicode: refused before any frame is shaded.
        let dir = std::path::absolute(&scene.dir).unwrap_or_else(|_| scene.dir.clone());
        let recorded = serde_json::to_string(&(
            &dir,
            scene.light_source(scene.default_frame())?,
            scene.view.absolute_spec(&scene.dir),
        ));
        if let Err(e) = recorded {
            return Err(anyhow!(
                "{}: --transfer records the scene's folder and files in each frame's header, and one of their paths \
                 is not Unicode ({e}): rename it",
                dir.display()
            ));
        }
    }
    let frames: Vec<i64> = match &args.frames {
        Some(spec) => spec.frames.clone(),
        None => {
            let range = scene.frame_numbers();
            let count = i128::from(*range.end()) - i128::from(*range.start()) + 1;
            if count > crate::render::frames::MAX_FRAMES as i128 {
                return Err(anyhow!(
                    "{}: the scene's frames {}-{} are {count} frames, more than {} in one run; choose some with --frames",
                    scene.scene_file().display(),
                    range.start(),
                    range.end(),
                    crate::render::frames::MAX_FRAMES
                ));
            }
            range.collect()
        }
    };
    if let Some(range) = scene.frames {
        let outside: Vec<String> =
            frames.iter().filter(|f| !(range.start..=range.end).contains(*f)).take(5).map(|f| f.to_string()).collect();
        if !outside.is_empty() {
            return Err(anyhow!(
                "--frames {}: frame(s) {} outside the scene's frames {}-{} ({})",
                args.frames.as_ref().map(|s| s.text.as_str()).unwrap_or_default(),
                outside.join(", "),
                range.start,
                range.end,
                scene.scene_file().display()
            ));
        }
    }
    if args.out.exists() && !args.out.is_dir() {
        return Err(anyhow!("--out {}: exists and is not a directory", args.out.display()));
    }
    let options = SequenceOptions {
        frames,
        out: args.out.clone(),
        name: args.name.clone(),
        skip_existing: args.skip_existing,
        colour: args.colour_type,
        transfer: args.transfer,
        resolving: args.shading.resolving(),
        band_rows: args.band_rows,
        settings,
    };
    if args.transfer && scene.supersample > 1 {
        return Err(anyhow!(
            "{}: --transfer writes one transfer per pixel and this scene is supersampled ({n}x{n} samples per \
             pixel); render its transfer from a scene exported without --supersample",
            scene.scene_file().display(),
            n = scene.supersample
        ));
    }
    check_outputs(&scene, &options)?;
    // A frame's light that cannot be read fails that frame, in the sequence below.
    if let Some(light) = options.frames.first().and_then(|&first| scene.light(first).ok()) {
        print_sharp_lights(&light, &settings);
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create output directory {}", args.out.display()))?;
    let executor = if args.transfer {
        if args.shading.device == crate::executor::DeviceChoice::Gpu {
            return Err(anyhow!("--transfer: the transfer layers are computed on the CPU; leave out --device gpu"));
        }
        Executor::cpu()
    } else {
        Executor::select(args.shading.device, &settings)?
    };
    print_notices(&executor);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads.unwrap_or(0))
        .build()
        .context("cannot start the worker threads")?;
    let mut progress = reporter(args.progress, Command::Render);
    let started = Instant::now();
    let outcomes = pool.install(|| {
        eprintln!("render: shading on {}", executor.describe());
        render_sequence(&executor, &scene, &options, progress.as_mut())
    });
    let failed: Vec<_> = outcomes.iter().filter(|o| o.failed()).collect();
    let skipped = outcomes.iter().filter(|o| matches!(o.status, FrameStatus::Skipped { .. })).count();
    let rendered = outcomes.len() - failed.len() - skipped;
    eprintln!(
        "{rendered} frame(s) rendered, {skipped} skipped, {} failed in {:.1} s: {}",
        failed.len(),
        started.elapsed().as_secs_f64(),
        args.out.display()
    );
    if failed.is_empty() {
        return Ok(());
    }
    let list: Vec<String> = failed
        .iter()
        .map(|o| match &o.status {
            FrameStatus::Failed { error } => format!("  {}: {error}", o.label()),
            _ => unreachable!("filtered on failures"),
        })
        .collect();
    Err(anyhow!("{} of {} frame(s) failed:\n{}", failed.len(), outcomes.len(), list.join("\n")))
}

/// `logsh info`.
pub fn info(args: &crate::cli::InfoArgs) -> Result<()> {
    let mut all = Vec::new();
    for file in &args.files {
        let info = crate::info::describe(file)?;
        if !args.json {
            print!("{}", crate::info::to_text(&info));
        }
        all.push(info);
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&all)?);
    }
    Ok(())
}

/// `logsh relight`.
pub fn relight(args: &crate::cli::RelightArgs) -> Result<()> {
    use crate::cli::{SharpLights, SunLamps};
    use crate::render::progress::{reporter, Command, Progress};
    use crate::render::{FrameOutcome, FrameStatus};
    use crate::scene::ViewTransform;
    use crate::shade::ShadedPasses;
    use crate::transfer::{
        offering_soft_suns, offering_to_keep, relight_reusing, RelightLight, RelightOptions, SunLampTurn, TransferFrame,
    };
    if args.out.exists() && !args.out.is_dir() {
        return Err(anyhow!("--out {}: exists and is not a directory", args.out.display()));
    }
    if !args.light_rotation.is_finite() {
        return Err(anyhow!("--light-rotation {} is not a finite number of degrees", args.light_rotation));
    }
    let options = RelightOptions { light: args.light.clone(), rotation: args.light_rotation, strength: args.strength };
    let canonical = |p: &Path| std::fs::canonicalize(p).ok();
    // What the relight reads: the frames, --light, and by each frame's header the map it
    // was lit with, its view's LUT, and the files of the scene it was rendered from (its
    // Sun lamps are shaded again from them). A frame whose header does not read is
    // refused when it is read.
    let mut inputs: Vec<std::path::PathBuf> =
        args.frames.iter().chain(&args.light).filter_map(|p| canonical(p)).collect();
    let mut scenes: Vec<crate::scene::Scene> = Vec::new();
    // Scenes whose scene.json does not read, which name no file: nothing is written into
    // their folders.
    let mut unread = Vec::new();
    // Each frame's number, where its header reads, as its reports give it.
    let mut numbers: Vec<Option<i64>> = vec![None; args.frames.len()];
    for (number, file) in numbers.iter_mut().zip(&args.frames) {
        let Ok(header) = TransferFrame::read_header(file) else { continue };
        *number = Some(header.frame);
        if let crate::scene::LightSource::Environment { file, .. } = &header.light {
            inputs.extend(canonical(file));
        }
        if let Some(lut) = header.view.as_ref().and_then(|view| view.lut.as_ref()) {
            inputs.extend(canonical(&lut.file));
        }
        if !scenes.iter().any(|scene| scene.dir == header.scene) {
            match crate::scene::Scene::load_description(&header.scene) {
                Ok(scene) => scenes.push(scene),
                Err(e) => unread.extend(canonical(&header.scene).map(|dir| (dir, e))),
            }
        }
    }
    if let Some((dir, e)) =
        canonical(&args.out).and_then(|out| unread.into_iter().find(|(dir, _)| out.starts_with(dir)))
    {
        return Err(anyhow!(
            "--out {}: lies in the scene {} its frames were rendered from, whose scene.json does not read ({e}), so \
             which of its files must not be written over is unknown; choose another --out",
            args.out.display(),
            dir.display()
        ));
    }
    let mut outputs = Vec::new();
    for file in &args.frames {
        let name = file.file_name().ok_or_else(|| anyhow!("{}: not a file", file.display()))?;
        let exr = args.out.join(name).with_extension("exr");
        let png = exr.with_extension("png");
        let json = exr.with_extension("light.json");
        for output in [&exr, &png, &json] {
            if canonical(output).is_some_and(|existing| inputs.contains(&existing)) {
                return Err(anyhow!("{}: would be written over an input; choose another --out", output.display()));
            }
            for scene in &scenes {
                scene.check_output_path(output).map_err(|e| anyhow!("{e}; choose another --out"))?;
            }
        }
        if outputs.iter().any(|(e, _, _): &(std::path::PathBuf, _, _)| *e == exr) {
            return Err(anyhow!("{}: two frames would be written to the same file", exr.display()));
        }
        outputs.push((exr, png, json));
    }
    let _out = CreatedDirectory::new(&args.out)?;
    let started = Instant::now();
    let total = args.frames.len();
    let mut progress = reporter(args.progress, Command::Relight);
    progress.start(total);
    // Each frame's outcome once reported.
    let mut outcomes: Vec<Option<FrameOutcome>> = vec![None; total];
    let mut light: Option<RelightLight> = None;
    let mut warned = std::collections::HashSet::new();
    let (mut warned_of_lamps, mut warned_of_view) = (false, false);
    let mut sun_lamps = None;
    // Whether Sun lamps were turned, and a map's suns shaded, in any frame.
    let mut shaded_again = [false; 2];
    let (mut building, mut relighting, mut shading_lamps) = (0.0, 0.0, 0.0);
    // The next frame is read and the last one written while a frame is relit (one each:
    // at most two frames' transfer layers in memory). A frame that fails stops the
    // sequence once the frames before it are written; the first failure is reported.
    // Each frame is read into the memory of the one relit before it, and relit into that
    // of the passes written before it (`read_reusing`, `relight_reusing`). A frame is
    // reported once written, from this thread, as `render` reports.
    let (reading, relit, written) = std::thread::scope(|threads| {
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
            for Relit { index, frame, passes, view, description, seconds } in write_rx {
                let (exr, png, json) = &outputs[index];
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
                done_tx.send((index, FrameOutcome { frame: Some(frame), input, status })).ok();
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
                let source = options.source(&frame.header);
                // The suns of the map shaded sharp where the render shaded them so.
                let sharp = args.sharp_lights == SharpLights::Auto
                    && frame.header.settings.is_some_and(|settings| settings.sharp_lights);
                if !light.as_ref().is_some_and(|l| l.serves(&source, &frame.header, sharp)) {
                    let built = if sharp {
                        RelightLight::with_sharp_suns(source, &frame.header, file)?
                    } else {
                        RelightLight::new(source, &frame.header, file)?
                    };
                    warn_of_suns_in_sh(&built, &mut warned, progress.as_mut());
                    light = Some(built);
                }
                options.check_rendered_map(light.as_ref().expect("built above"), &frame.header, file)?;
                building += t.elapsed().as_secs_f64();
                let turned = options.rotation != 0.0 && !frame.header.sun_lamps.is_empty();
                if turned && args.sun_lamps == SunLamps::Keep && !warned_of_lamps {
                    warned_of_lamps = true;
                    progress.notice(&sun_lamps_kept(file, &frame.header.sun_lamps, options.rotation));
                }
                // The Sun lamps turned and the map's suns, shaded again from the scene.
                let lamps_turned = turned && args.sun_lamps == SunLamps::Turn;
                let suns = light.as_ref().expect("built above").sharp_suns();
                if lamps_turned || !suns.is_empty() {
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
                    if sun_lamps.as_ref().is_none_or(|(built, _)| *built != key) {
                        sun_lamps = Some((key, SunLampTurn::new(header, file).map_err(offering)?));
                    }
                    let (_, turn) = sun_lamps.as_ref().expect("built above");
                    let degrees = lamps_turned.then_some(options.rotation);
                    turn.shade_again(&mut frame, file, degrees, suns).map_err(offering)?;
                    shading_lamps += t.elapsed().as_secs_f64();
                    shaded_again[0] |= lamps_turned;
                    shaded_again[1] |= !suns.is_empty();
                }
                let light = light.as_ref().expect("built above");
                let r = Instant::now();
                let passes = relight_reusing(&frame, light, spare_passes_rx.try_recv().ok());
                relighting += r.elapsed().as_secs_f64();
                let (view, standard) = ViewTransform::for_preview(frame.header.view.as_ref(), file);
                if let Some(reason) = standard.filter(|_| !warned_of_view) {
                    warned_of_view = true;
                    progress.notice(&format!("relight: {}: {reason}", file.display()));
                }
                let description =
                    serde_json::to_string_pretty(&light.description(options.turn_beyond_render()))? + "\n";
                let seconds = read_seconds + t.elapsed().as_secs_f64();
                let number = frame.header.frame;
                if write_tx.send(Relit { index: k, frame: number, passes, view, description, seconds }).is_err() {
                    break;
                }
                // The reader may have finished: then the frame is dropped here.
                spare_frame_tx.send(frame).ok();
                while let Ok(done) = done_rx.try_recv() {
                    report(done, progress.as_mut());
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
            report(done, progress.as_mut());
        }
        let reading = reader.join().expect("the reader does not panic");
        (reading, relit, written)
    });
    // The relight's failure, then the frames it stops before, are reported in order after
    // the frames written.
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
    // The writer's failure is of an earlier frame than the relight's; a failure names the
    // frames it leaves out.
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
    })?;
    let (count, elapsed) = (args.frames.len(), started.elapsed().as_secs_f64());
    let per_frame = |seconds: f64| 1e3 * seconds / count as f64;
    let lamps = match shaded_again {
        [false, false] => String::new(),
        [true, false] => format!(", the Sun lamps turned {:.1} ms", per_frame(shading_lamps)),
        [false, true] => format!(", the map's suns {:.1} ms", per_frame(shading_lamps)),
        [true, true] => format!(", the Sun lamps turned and the map's suns {:.1} ms", per_frame(shading_lamps)),
    };
    eprintln!(
        "relit {count} frame(s) in {elapsed:.3} s, {:.3} s a frame (reading, relighting and writing overlap: \
         reading {:.1} ms, light {:.1} ms, relighting {:.1} ms{lamps} per frame): {}",
        elapsed / count as f64,
        per_frame(reading),
        per_frame(building),
        per_frame(relighting),
        args.out.display()
    );
    Ok(())
}

/// Says which suns of a relight's light its render would have shaded sharp
/// ([`crate::transfer::RelightLight::suns_in_sh`]), and what to run for sharp shadows;
/// once per map of a sequence (`warned` holds the maps already named).
fn warn_of_suns_in_sh(
    light: &crate::transfer::RelightLight,
    warned: &mut std::collections::HashSet<std::path::PathBuf>,
    progress: &mut dyn crate::render::progress::Progress,
) {
    let crate::scene::LightSource::Environment { file, .. } = &light.source else {
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

/// An output directory, created if it is not there; one created for a run that then
/// wrote nothing into it (its first frame refused) is removed again when this is dropped.
struct CreatedDirectory<'a>(Option<&'a Path>);

impl<'a> CreatedDirectory<'a> {
    fn new(dir: &'a Path) -> Result<Self> {
        let created = !dir.exists();
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create output directory {}", dir.display()))?;
        Ok(Self(created.then_some(dir)))
    }
}

impl Drop for CreatedDirectory<'_> {
    fn drop(&mut self) {
        // Removes an empty directory only.
        if let Some(dir) = self.0 {
            let _ = std::fs::remove_dir(dir);
        }
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
    passes: crate::shade::ShadedPasses,
    view: crate::scene::ViewTransform,
    description: String,
    seconds: f64,
}

/// `logsh view`.
pub fn view(args: &crate::cli::ViewArgs) -> Result<()> {
    let viewer = crate::view::Viewer::new(&args.dir)?;
    let open = !args.no_open;
    viewer.serve(args.port, |address| {
        println!("logsh view: {} at {address} (Ctrl-C stops)", args.dir.display());
        let _ = std::io::Write::flush(&mut std::io::stdout());
        if open {
            if let Err(e) = open_in_browser(address) {
                eprintln!("view: cannot open a browser ({e}); open {address} in one");
            }
        }
    })
}

/// Opens `address` with the desktop's browser.
fn open_in_browser(address: &str) -> std::io::Result<()> {
    let mut command = if cfg!(target_os = "macos") {
        std::process::Command::new("open")
    } else if cfg!(windows) {
        let mut c = std::process::Command::new("cmd");
        c.args(["/C", "start", ""]);
        c
    } else {
        std::process::Command::new("xdg-open")
    };
    command.arg(address).stdout(std::process::Stdio::null()).stderr(std::process::Stdio::null()).spawn().map(|_| ())
}
