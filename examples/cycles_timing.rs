//! logsh against Cycles in time at equal error, on the same exported scene, in one run:
//! for each logsh preset, the whole `logsh shade` process timed (the median of
//! `--repeats` runs, start-up, reading, tables, shading and writing included) and its
//! error against converged Cycles; and the time Cycles needs for the same error, read off
//! a ladder of Cycles renders timed warm (`blender_scripts/render_cycles.py --ladder`:
//! one untimed 1-sample render first, so that loading Cycles' kernels is not counted).
//!
//!     bash blender_scripts/time_against_cycles.sh OUT        # builds, renders, runs this
//!     cargo run --release --example cycles_timing -- [--repeats N] [--truth STEM] DIR...
//!
//! Each DIR is an exported scene holding the converged render `cycles.NNNN.exr`, the
//! ladder's `cycles.NNNN.sK.exr` and `cycles.NNNN.timing.json`, for its first frame
//! (`--truth cycles_bdefault`: the renders with Blender's own light paths,
//! `render_cycles.py --bounces default`, the truth logsh's bounce light is held to;
//! against `cycles`, direct light, logsh shades `--bounces 0`). The
//! error is [`logsh::compare`]'s. Cycles' time at a given error is interpolated between
//! the two ladder rungs around it, linearly in log(time) against log(error); below the
//! ladder's lowest error it is extrapolated from the last rung as Monte Carlo converges,
//! time growing as error^-2 (marked `~`); above its highest error it is the 1-rung time, an
//! upper bound (marked `<=`). Timings are wall-clock seconds on this machine, in one run:
//! compare them as ratios.
//!
//! When the timing file holds denoised ladders (`render_cycles.py --ladder-denoise`: its
//! `oidn` list, OpenImageDenoise with the `ACCURATE` and the `FAST` prefilter, images
//! `cycles.NNNN.sK.oidn_accurate.exr` and `.oidn_fast.exr`), their rungs are listed too,
//! with the same error. A denoiser's error need not fall as Monte Carlo's does, so no
//! time is interpolated for them; instead the last column names, for each logsh preset,
//! the cheapest rung of every ladder (plain or denoised) whose error is at most logsh's,
//! and how much faster logsh is than it (`none` when no rung is that close).

use logsh::compare::{frame_error, read_rgb, unoccluded_value};
use logsh::scene::Scene;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

const PRESETS: [&str; 4] = ["draft", "default", "high", "ultra"];

/// One rung of a Cycles ladder.
struct Rung {
    samples: u64,
    seconds: f64,
    error: f64,
}

/// One Cycles configuration timed over a ladder: Cycles alone, or denoised.
struct Ladder {
    label: String,
    rungs: Vec<Rung>,
}

/// The fastest rung of all `ladders` whose error is at most `error`.
fn cheapest_at_most(ladders: &[Ladder], error: f64) -> Option<(&Ladder, &Rung)> {
    ladders
        .iter()
        .flat_map(|ladder| ladder.rungs.iter().map(move |rung| (ladder, rung)))
        .filter(|(_, rung)| rung.error <= error)
        .min_by(|a, b| a.1.seconds.total_cmp(&b.1.seconds))
}

/// Cycles' time at `error`, and how it was found (module doc).
fn cycles_time_at(ladder: &[Rung], error: f64) -> (f64, &'static str) {
    let mut rungs: Vec<&Rung> = ladder.iter().collect();
    rungs.sort_by_key(|r| r.samples);
    let (first, last) = (rungs[0], rungs[rungs.len() - 1]);
    if error >= first.error {
        return (first.seconds, "<= ");
    }
    for pair in rungs.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        if error <= a.error && error >= b.error {
            let t = (error.ln() - a.error.ln()) / (b.error.ln() - a.error.ln());
            return ((a.seconds.ln() + t * (b.seconds.ln() - a.seconds.ln())).exp(), "");
        }
    }
    (last.seconds * (last.error / error).powi(2), "~")
}

fn logsh_binary() -> PathBuf {
    let exe = std::env::current_exe().expect("the example's own path");
    let binary = exe.parent().and_then(Path::parent).map(|d| d.join("logsh")).expect("target directory");
    assert!(binary.is_file(), "{} is missing: run `cargo build --release` first", binary.display());
    binary
}

fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(|a, b| a.total_cmp(b));
    values[values.len() / 2]
}

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let repeats = args.iter().position(|a| a == "--repeats").map_or(3, |i| {
        let n: usize = args.get(i + 1).and_then(|n| n.parse().ok()).expect("--repeats needs a count");
        args.drain(i..i + 2);
        n.max(1)
    });
    let stem = args.iter().position(|a| a == "--truth").map_or_else(
        || "cycles".to_string(),
        |i| {
            let stem = args.get(i + 1).expect("--truth needs a file stem").clone();
            args.drain(i..i + 2);
            stem
        },
    );
    if args.is_empty() {
        eprintln!("usage: cycles_timing [--repeats N] [--truth STEM] SCENE_DIR...");
        std::process::exit(2);
    }
    let logsh = logsh_binary();
    // Against the direct-light truth, logsh shades direct light too.
    let direct_only: &[&str] = if stem == "cycles" { &["--bounces", "0"] } else { &[] };
    println!(
        "| scene | renderer | time (s) | error | Cycles at equal error (s) | logsh faster by | \
         cheapest Cycles rung at most logsh's error |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    for dir in args.iter().map(PathBuf::from) {
        let scene = Scene::load(&dir).unwrap_or_else(|e| panic!("{e}"));
        assert!(
            scene.supersample == 1,
            "{}: a supersampled scene; compare it with examples/edge_accuracy.rs",
            dir.display()
        );
        let number = scene.default_frame();
        let frame = scene.frame(number).unwrap_or_else(|e| panic!("{e}"));
        let unoccluded = unoccluded_value(&frame).expect("a scene with an environment or constant light");
        let material = &frame.gbuffer.material;
        let (_, _, truth) = read_rgb(&dir.join(format!("{stem}.{number:04}.exr"))).unwrap_or_else(|e| panic!("{e}"));
        let name = dir.file_name().map_or_else(|| dir.display().to_string(), |n| n.to_string_lossy().into_owned());
        let size = format!("{}x{}", frame.gbuffer.width, frame.gbuffer.height);

        let timing_file = dir.join(format!("{stem}.{number:04}.timing.json"));
        let timing: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(&timing_file).unwrap_or_else(|e| panic!("{}: {e}", timing_file.display())),
        )
        .unwrap_or_else(|e| panic!("{}: {e}", timing_file.display()));
        // The rungs of one ladder of the timing file: `entry` holds its `samples` and
        // `seconds`, and each image is `cycles.NNNN.sK{suffix}.exr`.
        let rungs = |entry: &serde_json::Value, suffix: &str| -> Vec<Rung> {
            let counts = entry["samples"].as_array().expect("samples");
            let seconds = entry["seconds"].as_array().expect("seconds");
            counts
                .iter()
                .zip(seconds)
                .map(|(n, s)| {
                    let samples = n.as_u64().expect("a sample count");
                    let image = dir.join(format!("{stem}.{number:04}.s{samples}{suffix}.exr"));
                    let (_, _, image) = read_rgb(&image).unwrap_or_else(|e| panic!("{e}"));
                    let error = frame_error(material, &image, &truth, unoccluded).mean;
                    Rung { samples, seconds: s.as_f64().expect("seconds"), error }
                })
                .collect()
        };
        let mut ladders = vec![Ladder { label: "Cycles".into(), rungs: rungs(&timing, "") }];
        for entry in timing["oidn"].as_array().into_iter().flatten() {
            let file = entry["name"].as_str().expect("the name of a denoised ladder");
            let prefilter = entry["prefilter"].as_str().expect("a prefilter").to_lowercase();
            ladders
                .push(Ladder { label: format!("Cycles + OIDN {prefilter}"), rungs: rungs(entry, &format!(".{file}")) });
        }
        for ladder in &ladders {
            for rung in &ladder.rungs {
                println!(
                    "| {name} {size} | {}, {} spp | {:.2} | {:.3} | | | |",
                    ladder.label, rung.samples, rung.seconds, rung.error
                );
            }
        }
        let ladder = &ladders[0].rungs;

        for preset in PRESETS {
            let out = tempfile::tempdir().expect("a temporary directory");
            let mut walls = Vec::new();
            for _ in 0..repeats {
                let started = Instant::now();
                let status = Command::new(&logsh)
                    .args(["shade", "--device", "cpu", "--quality", preset, "--frame", &number.to_string()])
                    .args(direct_only)
                    .arg("--out")
                    .arg(out.path())
                    .arg(&dir)
                    .output()
                    .expect("running logsh");
                walls.push(started.elapsed().as_secs_f64());
                assert!(status.status.success(), "logsh shade failed: {}", String::from_utf8_lossy(&status.stderr));
            }
            let wall = median(walls);
            let beauty = out.path().join(format!("beauty.{number:04}.exr"));
            let (_, _, image) = read_rgb(&beauty).unwrap_or_else(|e| panic!("{e}"));
            let error = frame_error(material, &image, &truth, unoccluded).mean;
            let (cycles, mark) = cycles_time_at(ladder, error);
            let cheapest = cheapest_at_most(&ladders, error).map_or_else(
                || "none".to_string(),
                |(ladder, rung)| {
                    format!(
                        "{}, {} spp: {:.2} s ({:.1}x)",
                        ladder.label,
                        rung.samples,
                        rung.seconds,
                        rung.seconds / wall
                    )
                },
            );
            println!(
                "| {name} {size} | logsh {preset} | {wall:.2} | {error:.3} | {mark}{cycles:.2} | {mark}{:.1}x | {cheapest} |",
                cycles / wall
            );
        }
    }
}
