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

mod relight;
mod shared;

pub use relight::relight;
use shared::describe_sun;

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
            glossy: args.glossy,
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
    use crate::render::{check_outputs, render_sequence, SequenceOptions};
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
        check_recordable_paths(&scene)?;
    }
    let frames = frames_to_render(args, &scene)?;
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
    report_rendered(&outcomes, started, &args.out)
}

/// The transfer header records the scene's folder, map and LUT as JSON text, which holds
/// no path that is not Unicode: refused before any frame is shaded.
fn check_recordable_paths(scene: &Scene) -> Result<()> {
    let dir = std::path::absolute(&scene.dir).unwrap_or_else(|_| scene.dir.clone());
    let recorded = serde_json::to_string(&(
        &dir,
        scene.light_source(scene.default_frame())?,
        scene.view.absolute_spec(&scene.dir),
    ));
    match recorded {
        Ok(_) => Ok(()),
        Err(e) => Err(anyhow!(
            "{}: --transfer records the scene's folder and files in each frame's header, and one of their paths is \
             not Unicode ({e}): rename it",
            dir.display()
        )),
    }
}

/// The frames `--frames` asks for, or the scene's own. A frame outside the scene's range
/// is refused; one inside it that the export skipped (scene.json's `frames.list`: a
/// Frame Step) is left out with a note, so that a farm's chunk `1-10` of a shot exported
/// every second frame renders its five, unless none of the frames asked for is there.
fn frames_to_render(args: &crate::cli::RenderArgs, scene: &Scene) -> Result<Vec<i64>> {
    let limit = crate::render::frames::MAX_FRAMES;
    let Some(spec) = &args.frames else {
        let count = scene.frames.as_ref().map_or(1, |range| range.count());
        if count > limit as i128 {
            return Err(anyhow!(
                "{}: the scene's frames {} are {count} frames, more than {limit} in one run; choose some with --frames",
                scene.scene_file().display(),
                scene.frames.as_ref().map(|range| range.describe()).unwrap_or_default(),
            ));
        }
        return Ok(scene.frame_numbers(limit));
    };
    let Some(range) = &scene.frames else { return Ok(spec.frames.clone()) };
    let listed = |frames: Vec<&i64>| {
        let first = frames.iter().take(5).map(|f| f.to_string()).collect::<Vec<_>>().join(", ");
        match frames.len() {
            0..=5 => first,
            more => format!("{first} and {} more", more - 5),
        }
    };
    let outside: Vec<&i64> = spec.frames.iter().filter(|f| !(range.start..=range.end).contains(*f)).collect();
    if !outside.is_empty() {
        return Err(anyhow!(
            "--frames {}: frame(s) {} outside the scene's frames {}-{} ({})",
            spec.text,
            listed(outside),
            range.start,
            range.end,
            scene.scene_file().display()
        ));
    }
    let (held, skipped): (Vec<i64>, Vec<i64>) = spec.frames.iter().partition(|&&f| range.contains(f));
    if !skipped.is_empty() {
        let what = format!(
            "frame(s) {} not among the scene's frames {} ({})",
            listed(skipped.iter().collect()),
            range.describe(),
            scene.scene_file().display()
        );
        if held.is_empty() {
            return Err(anyhow!("--frames {}: {what}", spec.text));
        }
        eprintln!("render: leaving out {what}");
    }
    Ok(held)
}

/// Says how many frames were rendered, skipped and failed, and fails naming each failure.
fn report_rendered(outcomes: &[crate::render::FrameOutcome], started: Instant, out: &Path) -> Result<()> {
    use crate::render::FrameStatus;
    let failed: Vec<_> = outcomes.iter().filter(|o| o.failed()).collect();
    let skipped = outcomes.iter().filter(|o| matches!(o.status, FrameStatus::Skipped { .. })).count();
    let rendered = outcomes.len() - failed.len() - skipped;
    eprintln!(
        "{rendered} frame(s) rendered, {skipped} skipped, {} failed in {:.1} s: {}",
        failed.len(),
        started.elapsed().as_secs_f64(),
        out.display()
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
