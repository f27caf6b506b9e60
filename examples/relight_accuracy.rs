//! How a relight compares with shading again (`logsh relight` against `logsh render`),
//! in accuracy and in time, one run per scene:
//!
//! ```text
//! cargo run --release --example relight_accuracy -- [--rotation DEG] [--repeats N] [--device cpu|gpu|auto]
//!     [--relight-threads T] [--fresh-passes] [--keep-sun-lamps] [--sharp-suns] SCENE...
//! ```
//!
//! Per scene (its first frame): the transfer is rendered with `--sharp-lights off`,
//! written as `logsh render --transfer` writes it (half floats) and read back, then relit
//! with the light turned by `DEG`. It is compared with a fresh shade of the turned light,
//! with `--sharp-lights off` (what a relight equals: the target is 0.002) and with the
//! default `auto` (what relighting does to the suns taken out of a map). Errors are
//! `logsh::compare`'s: mean absolute over non-background pixels, RGB, over the open white
//! floor; "worst" is the largest pixel's. Times are the medians of `N` runs of the
//! shading call and of the relight call, taking turns (each after an untimed run of
//! itself), as the frames of a sequence run them (the light and the kernel built once),
//! and the first run of each, cold, both reading their light: the relight with its light
//! read, turned, projected and prefiltered, the shade with its map read and turned as a
//! scene's loading does, then its tables; reading the transfer file and the G-buffer is
//! not counted. Each relight writes into the passes of the one before, as `logsh relight`
//! does in a sequence once its first frames are written; `--fresh-passes` allocates each
//! relight's passes anew, as a first frame's are (the allocator may hand back the memory
//! just freed). `--relight-threads T` relights on a pool of its own of `T` threads
//! (rayon's global pool, one thread per core, by default). Where the light turns and the
//! frame has Sun lamps, each relight shades them again turned, as `logsh relight` does
//! by default (`--sun-lamps turn`), and its time counts that; `--keep-sun-lamps` leaves
//! them as rendered (`--sun-lamps keep`). The turn shades them from the frame of the scene
//! the frame was rendered from, its G-buffer read and checked against the header's record
//! ([`SunLampTurn::prepare`]): like the shade's read of that same G-buffer, that read is
//! not counted, and is printed apart (the median of `N` reads).
//!
//! `--sharp-suns` renders the transfer and shades with `--sharp-lights auto` instead, and
//! relights as `logsh relight` does by default: the suns taken out of the turned map
//! shaded again from the scene in each relight, counted, its residual in SH (the first
//! column is then against the default shade).
//!
//! The shade runs where `--device` puts it (`cpu` by default; `logsh render`
//! takes `auto`, a hardware GPU where there is one); the relight runs on the CPU, as `logsh
//! relight` does. Where the scene directory holds a converged Cycles render of the frame
//! (`cycles.NNNN.exr`, `blender_scripts/render_cycles.py`), the relit frame and the
//! default shade are also compared with it; turned by `DEG`, with
//! `cycles-turned-DEG.NNNN.exr`, Cycles' render of the .blend that
//! `blender_scripts/turn_light.py` turns by `DEG`.

use logsh::compare::{frame_error, unoccluded_value};
use logsh::executor::{DeviceChoice, Executor, ShadeJob};
use logsh::scene::output::SampleType;
use logsh::scene::{EnvironmentMap, LightSource, Scene};
use logsh::shade::{ShadedPasses, ShadingSettings};
use logsh::timing::StageTimings;
use logsh::transfer::{relight_reusing, shade_with_transfer, RelightLight, RelightOptions, SunLampTurn, TransferFrame};
use std::path::PathBuf;
use std::time::Instant;

fn median(mut times: Vec<f64>) -> f64 {
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

/// `work` on `pool`, or on rayon's global pool where there is none.
fn on_pool<R: Send>(pool: Option<&rayon::ThreadPool>, work: impl FnOnce() -> R + Send) -> R {
    match pool {
        Some(pool) => pool.install(work),
        None => work(),
    }
}

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let (mut rotation, mut repeats, mut scenes) = (0.0f64, 3usize, Vec::new());
    let mut device = DeviceChoice::Cpu;
    let (mut relight_threads, mut fresh_passes, mut keep_sun_lamps, mut sharp_suns) = (None, false, false, false);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--rotation" => rotation = args.next().expect("--rotation DEG").parse()?,
            "--repeats" => repeats = args.next().expect("--repeats N").parse()?,
            "--device" => {
                device = clap::ValueEnum::from_str(&args.next().expect("--device cpu|gpu|auto"), true)
                    .map_err(|e| anyhow::anyhow!("--device: {e}"))?
            }
            "--relight-threads" => relight_threads = Some(args.next().expect("--relight-threads T").parse()?),
            "--fresh-passes" => fresh_passes = true,
            "--keep-sun-lamps" => keep_sun_lamps = true,
            "--sharp-suns" => sharp_suns = true,
            _ => scenes.push(PathBuf::from(a)),
        }
    }
    let temp = tempfile::tempdir()?;
    let settings = ShadingSettings { sharp_lights: sharp_suns, ..ShadingSettings::default() };
    let executor = Executor::select(device, &settings)?;
    let pool = match relight_threads {
        Some(threads) => Some(rayon::ThreadPoolBuilder::new().num_threads(threads).build()?),
        None => None,
    };
    println!(
        "shading on {}; relighting on cpu ({} threads, into {} passes)\n",
        executor.describe(),
        pool.as_ref().map_or_else(rayon::current_num_threads, |p| p.current_num_threads()),
        if fresh_passes { "fresh" } else { "the previous relight's" }
    );
    let sharp = if sharp_suns { "auto" } else { "off" };
    println!("| scene | size | vs shade, sharp lights {sharp} (mean / worst) | vs shade, sharp lights auto | vs Cycles: relit / shade auto | relight | shade | ratio | cold: relight / shade | ratio |");
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    for dir in &scenes {
        let scene = Scene::load(dir)?;
        let number = scene.default_frame();
        let frame = scene.frame(number)?;
        let (passes, transfer) = shade_with_transfer(&scene, &frame, &settings)?;
        let file = temp.path().join("transfer.exr");
        logsh::render::write_passes_with_transfer(&file, &passes, &transfer, SampleType::Half)?;
        let mut transfer = TransferFrame::read(&file)?;
        let options = RelightOptions { rotation, ..RelightOptions::default() };
        let started = Instant::now();
        let light = match sharp_suns {
            true => RelightLight::with_sharp_suns(options.source(&transfer.header), &transfer.header, &file)?,
            false => RelightLight::new(options.source(&transfer.header), &transfer.header, &file)?,
        };
        let building = started.elapsed().as_secs_f64();
        // The scene's Sun lamps turn with the map, and the map's suns are shaded sharp,
        // again per frame (`logsh relight --sun-lamps turn`, `--sharp-lights auto`): part
        // of each relight's time, from the lamps as rendered.
        let lamps_turned = rotation != 0.0 && !transfer.header.sun_lamps.is_empty() && !keep_sun_lamps;
        let sun_lamps = (lamps_turned || !light.sharp_suns().is_empty())
            .then(|| SunLampTurn::new(&transfer.header, &file))
            .transpose()?;
        let rendered_lamps =
            sun_lamps.as_ref().map(|_| (transfer.lamps_diffuse.clone(), transfer.lamps_specular.clone()));
        // The frame of the scene the Sun lamps are shaded from, read and checked as each
        // frame of a relight reads it.
        let mut reads = Vec::new();
        let mut prepared = None;
        for _ in 0..repeats.max(1) {
            if let Some(turn) = &sun_lamps {
                let started = Instant::now();
                prepared = Some(on_pool(pool.as_ref(), || turn.prepare(&transfer, &file))?);
                reads.push(started.elapsed().as_secs_f64());
            }
        }

        let mut turned = Scene::load(dir)?;
        turned.turn_light(rotation)?;
        let turned_frame = turned.frame(number)?;
        // What the scene's loading spent on the light the cold shade uses.
        let started = Instant::now();
        if let LightSource::Environment { file, rotation, turn, .. } = turned.light_source(number)? {
            std::hint::black_box(EnvironmentMap::read(&file)?.oriented(rotation, turn));
        }
        let shade_light = started.elapsed().as_secs_f64();
        let unoccluded = unoccluded_value(&turned_frame).expect("a map or constant light");
        // The shade and the relight take turns, so that a slower spell of a shared
        // machine falls on both. Each timed run follows an untimed one of its own, which
        // leaves its data in the caches as reading its frame does in a sequence (a
        // relight straight after a shade found the transfer evicted, and took up to twice
        // as long at 240x135).
        let (mut shade_times, mut relight_times) = (Vec::new(), Vec::new());
        let (mut truth, mut relit) = (None, None);
        let (mut cold_shade, mut cold_relight) = (0.0, 0.0);
        for round in 0..repeats {
            for timed in [false, true] {
                let started = Instant::now();
                truth = Some::<ShadedPasses>(
                    executor.shade(&ShadeJob::new(&turned, &turned_frame, &settings), &mut StageTimings::default())?,
                );
                match (round, timed) {
                    (0, false) => cold_shade = started.elapsed().as_secs_f64(),
                    (_, true) => shade_times.push(started.elapsed().as_secs_f64()),
                    _ => {}
                }
            }
            for timed in [false, true] {
                let spare = if fresh_passes { None } else { relit.take() };
                drop(relit.take());
                if let Some((diffuse, specular)) = &rendered_lamps {
                    transfer.lamps_diffuse.clone_from(diffuse);
                    transfer.lamps_specular.clone_from(specular);
                }
                let started = Instant::now();
                if let (Some(turn), Some(prepared)) = (&sun_lamps, &prepared) {
                    let (degrees, suns) = (lamps_turned.then_some(rotation), light.sharp_suns());
                    let turned = on_pool(pool.as_ref(), || {
                        turn.sharp_lights_at(prepared, &transfer, &file, degrees, suns, None)
                    })?;
                    [transfer.lamps_diffuse, transfer.lamps_specular] = turned;
                }
                relit = Some(on_pool(pool.as_ref(), || relight_reusing(&transfer, &light, spare)));
                match (round, timed) {
                    (0, false) => cold_relight = started.elapsed().as_secs_f64(),
                    (_, true) => relight_times.push(started.elapsed().as_secs_f64()),
                    _ => {}
                }
            }
        }
        let truth = truth.expect("one repeat at least");
        let relit = relit.expect("one repeat at least");
        let auto_settings = ShadingSettings::default();
        let auto: ShadedPasses =
            executor.shade(&ShadeJob::new(&turned, &turned_frame, &auto_settings), &mut StageTimings::default())?;
        let rgb = |p: &logsh::shade::ShadedPasses| p.beauty.iter().map(|c| [c[0], c[1], c[2]]).collect::<Vec<_>>();
        let material = &frame.gbuffer.material;
        let off = frame_error(material, &rgb(&relit), &rgb(&truth), unoccluded);
        let worst = off.per_pixel.iter().fold(0.0f64, |a, &b| a.max(b));
        let with_suns = frame_error(material, &rgb(&relit), &rgb(&auto), unoccluded);
        let cycles = match rotation {
            0.0 => dir.join(format!("cycles.{number:04}.exr")),
            _ => dir.join(format!("cycles-turned-{rotation}.{number:04}.exr")),
        };
        let against_cycles = match logsh::compare::read_rgb(&cycles) {
            Ok((_, _, truth)) => format!(
                "{:.4} / {:.4}",
                frame_error(material, &rgb(&relit), &truth, unoccluded).mean,
                frame_error(material, &rgb(&auto), &truth, unoccluded).mean
            ),
            _ => "-".into(),
        };
        let (cold_relight, cold_shade) = (building + cold_relight, shade_light + cold_shade);
        let (r, s) = (median(relight_times), median(shade_times));
        println!(
            "| {} | {}x{} | {:.5} / {:.4} | {:.4} | {against_cycles} | {:.2} ms | {:.1} ms | {:.0}x | {:.2} / {:.1} ms | {:.0}x |",
            dir.display(),
            frame.gbuffer.width,
            frame.gbuffer.height,
            off.mean,
            worst,
            with_suns.mean,
            1e3 * r,
            1e3 * s,
            s / r,
            1e3 * cold_relight,
            1e3 * cold_shade,
            cold_shade / cold_relight
        );
        if !reads.is_empty() {
            let read = median(reads);
            println!(
                "  (its Sun lamps' scene frame read and checked in {:.2} ms, not counted; counted, {:.2} ms, {:.0}x)",
                1e3 * read,
                1e3 * (r + read),
                s / (r + read)
            );
        }
    }
    Ok(())
}
