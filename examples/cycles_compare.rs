//! logsh against Cycles on exported Blender scenes: shades a scene's first frame at the
//! `default`, `high` and `ultra` presets, at `default` with every cap and slice at `log(eps)`
//! (`--fitted-depths off`), with ratio attenuation, without the
//! overlap floor and without clusters (and, where `--sharp-lights` takes suns out of the
//! map, `default` and `high` without that; under a map, `default` with its projection
//! windowed), and compares each with the Cycles renders stored beside it, each a truth
//! of its own (`blender_scripts/render_cycles.py` writes them):
//!
//! - `cycles.NNNN.exr`, the truth for the method: direct light, with the exported material
//!   table turned back into Cycles shaders, so that both sides use the same albedo,
//!   specular colour and lobe width;
//! - `authored.NNNN.exr` (`--as-authored`), the truth for the user with direct light
//!   only: the .blend's own materials, which the colour passes bring to logsh;
//! - `cycles_bdefault.NNNN.exr` (`--bounces default`), converted materials with
//!   Blender's own light paths: the truth for bounce light, apart from the materials;
//! - `authored_bdefault.NNNN.exr` (`--as-authored --bounces default`), the user's own
//!   render, bounce light included.
//!
//! Every run shades as `logsh render` does, bounce light included (the preset's
//! `--bounces`); the `--bounces 0` rows (`default`, `high`, `ultra`) are the direct light
//! alone, to be read against the direct-light truths.
//!
//!     cargo run --release --example cycles_compare -- gbuffers/dunes gbuffers/wrecking_ball
//!
//! With `--reference TOLERANCE`, also the ground-truth renderer (`logsh reference`: exact
//! visibility of the same proxies, the environment importance-sampled to `TOLERANCE`):
//! the proxy floor, what the sphere proxies alone cost against the meshes.
//!
//! With `--settings "FLAGS"` (repeatable), also a row shaded with `logsh shade`'s shading
//! flags, such as `--settings "--bounces 0 --level-step 8 --level-offset 8"`.
//!
//! With `--noise DIR`, the same measure between the stored render and a second one of the
//! same scene with another seed, `DIR/<scene name>/cycles.NNNN.exr`
//! (`render_cycles.py --seed 1`): the Cycles noise floor under these figures.
//!
//! Error: [`logsh::compare`]'s, the mean over non-background pixels and over R, G, B of
//! |logsh - Cycles| divided by the radiance an open white floor receives from the scene's
//! light (a point lamp's share averaged over the frame). Also printed: the 95th percentile
//! and the mean signed difference (positive: logsh brighter); and the plain mean absolute
//! difference over non-background pixels and R, G, B, the figure the issues quote. Where
//! many background pixels differ from the truth, as a surface the G-buffer lacks would
//! make them, it says so on stderr.

use logsh::compare::{frame_error, read_rgb, unoccluded_value};
use logsh::executor::{Executor, ShadeJob};
use logsh::reference::{render_reference, ReferenceOptions};
use logsh::scene::{Frame, Light, Material, Scene};
use logsh::shade::bounce::BounceSettings;
use logsh::shade::sharp_lights::extract_suns;
use logsh::shade::{GlossyMethod, LightWindow, Quality, ShadedFrame, ShadingSettings};
use logsh::timing::StageTimings;
use std::path::PathBuf;

/// The Cycles renders compared against, where present: file stem and what it is.
const TRUTHS: [(&str, &str); 4] = [
    ("cycles", "direct light, converted materials"),
    ("cycles_bdefault", "converted materials, Blender's light paths"),
    ("authored", "as authored, direct light"),
    ("authored_bdefault", "as authored, Blender's light paths"),
];

/// The command line: the scene directories and what to add to each one's table.
struct Options {
    dirs: Vec<PathBuf>,
    quick: bool,
    noise: Option<PathBuf>,
    reference_tolerance: Option<f64>,
    /// Rows of their own: `logsh shade`'s shading flags, one string each, and their settings.
    flagged: Vec<(String, ShadingSettings)>,
}

const USAGE: &str =
    "usage: cycles_compare [--quick] [--noise DIR] [--reference TOLERANCE] [--settings FLAGS]... SCENE_DIR...";

/// Prints `error: message` and ends the process with status 1.
fn fail(message: impl std::fmt::Display) -> ! {
    eprintln!("error: {message}");
    std::process::exit(1);
}

/// Prints `error: message` and the usage line, and ends the process with status 2.
fn usage_error(message: impl std::fmt::Display) -> ! {
    eprintln!("error: {message}\n{USAGE}");
    std::process::exit(2);
}

fn options() -> Options {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    if args.iter().any(|a| a == "--help" || a == "-h") {
        println!(
            "Shades exported Blender scenes at logsh's presets and compares each with the Cycles \
             renders stored beside it (cycles, cycles_bdefault, authored, authored_bdefault .NNNN.exr).\n\n{USAGE}\n\n\
             --quick               of the presets, `default` alone (with and without bounce light)\n\
             --noise DIR           also the Cycles noise floor, against DIR/<scene>/cycles.NNNN.exr\n\
             --reference TOL       also `logsh reference`, converged to TOL per pixel\n\
             --settings FLAGS      also a row shaded with these `logsh shade` flags (repeatable)"
        );
        std::process::exit(0);
    }
    let mut value = |flag: &str| {
        args.iter().position(|a| a == flag).map(|i| {
            let Some(value) = args.get(i + 1).cloned() else { usage_error(format!("{flag} needs a value")) };
            args.drain(i..i + 2);
            value
        })
    };
    let noise = value("--noise").map(PathBuf::from);
    let reference_tolerance = value("--reference").map(|t| {
        t.parse::<f64>()
            .ok()
            .filter(|t| *t > 0.0)
            .unwrap_or_else(|| usage_error(format!("--reference {t}: not a positive tolerance")))
    });
    let mut flagged = Vec::new();
    while let Some(flags) = value("--settings") {
        let settings = settings_of(&flags).unwrap_or_else(|e| usage_error(format!("--settings {flags:?}: {e}")));
        flagged.push((flags, settings));
    }
    let quick = args.iter().position(|a| a == "--quick").map(|i| args.remove(i)).is_some();
    if let Some(unknown) = args.iter().find(|a| a.starts_with("--")) {
        usage_error(format!("unknown option {unknown}"));
    }
    let dirs: Vec<PathBuf> = args.into_iter().map(PathBuf::from).collect();
    if dirs.is_empty() {
        usage_error("no scene directory given");
    }
    Options { dirs, quick, noise, reference_tolerance, flagged }
}

fn main() {
    let Options { dirs, quick, noise, reference_tolerance, flagged } = options();
    println!(
        "| scene | truth | settings | pixels | mean abs error | p95 | mean signed | mean abs (plain) | glossy pixels (exponent >= 50) |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    let executor = Executor::cpu();
    for dir in dirs {
        let scene = Scene::load(&dir).unwrap_or_else(|e| fail(e));
        if scene.supersample != 1 {
            fail(format!("{}: a supersampled scene; compare it with examples/edge_accuracy.rs", dir.display()));
        }
        let number = scene.default_frame();
        let frame = scene.frame(number).unwrap_or_else(|e| fail(e));
        let truths: Vec<(&str, Vec<[f32; 3]>)> = TRUTHS
            .iter()
            .filter_map(|&(stem, name)| {
                let file = dir.join(format!("{stem}.{number:04}.exr"));
                file.is_file().then(|| (name, read_rgb(&file).unwrap_or_else(|e| fail(e)).2))
            })
            .collect();
        if truths.is_empty() {
            fail(format!("{}: no Cycles render (cycles.{number:04}.exr, authored.{number:04}.exr)", dir.display()));
        }
        let (width, height) = (frame.gbuffer.width, frame.gbuffer.height);
        let unoccluded = unoccluded_value(&frame).unwrap_or_else(|| {
            fail(format!(
                "{}: an SH light has no map to integrate; compare scenes with an environment or constant light",
                dir.display()
            ))
        });
        eprintln!("{}: frame {number}, unoccluded value {unoccluded:.3?}", dir.display());
        let scene_name =
            dir.file_name().map_or_else(|| dir.display().to_string(), |n| n.to_string_lossy().into_owned());
        let mut images: Vec<(String, Vec<[f32; 3]>)> = Vec::new();
        for (name, settings) in &runs_of(&scene, &frame, quick, &flagged) {
            let job = ShadeJob::new(&scene, &frame, settings);
            let shaded: ShadedFrame = executor.shade(&job, &mut StageTimings::default()).unwrap_or_else(|e| fail(e));
            if [width, height] != [shaded.width, shaded.height] {
                fail(format!("{}: the shaded frame and the G-buffer differ in size", dir.display()));
            }
            images.push((name.clone(), shaded.rgba.iter().map(|p| [p[0], p[1], p[2]]).collect()));
        }
        if let Some(tolerance) = reference_tolerance {
            let options = ReferenceOptions { tolerance, ..Default::default() };
            let started = std::time::Instant::now();
            let truth = render_reference(&scene, &frame, &options, &|_| {}).unwrap_or_else(|e| fail(e));
            eprintln!(
                "{}: reference ({:?}) {:.1} s, {} pixel(s) above the tolerance {tolerance}",
                dir.display(),
                truth.integration,
                started.elapsed().as_secs_f64(),
                truth.unconverged_pixels
            );
            let name = "reference (exact visibility of the proxies)".to_string();
            images.push((name, truth.rgba.iter().map(|p| [p[0], p[1], p[2]]).collect()));
        }
        if let Some(noise) = &noise {
            let (_, _, second) =
                read_rgb(&noise.join(&scene_name).join(format!("cycles.{number:04}.exr"))).unwrap_or_else(|e| fail(e));
            images.push(("Cycles, another seed".to_string(), second));
        }
        if let Some((_, image)) = images.first() {
            for (truth, cycles) in &truths {
                report_missed_surfaces(&dir, truth, &frame.gbuffer.material, image, cycles);
            }
        }
        for ((truth, cycles), (name, image)) in truths.iter().flat_map(|t| images.iter().map(move |i| (t, i))) {
            if cycles.len() != width * height {
                fail(format!("{}: the {truth} render and the G-buffer differ in size", dir.display()));
            }
            let error = frame_error(&frame.gbuffer.material, image, cycles, unoccluded);
            let surface: Vec<usize> = (0..image.len()).filter(|&i| frame.gbuffer.material[i] != 0).collect();
            let plain = surface
                .iter()
                .map(|&i| (0..3).map(|k| f64::from((image[i][k] - cycles[i][k]).abs())).sum::<f64>() / 3.0)
                .sum::<f64>()
                / surface.len().max(1) as f64;
            let (count, mean, p95, signed) = (error.pixels, error.mean, error.p95, error.signed);
            let errors = error.per_pixel;
            let glossy = glossy_column(&scene, &frame.gbuffer.material, &errors);
            println!(
                "| {scene_name} | {truth} | {name} | {count} | {mean:.3} | {p95:.3} | {signed:+.3} | {plain:.4} | {glossy} |"
            );
            if std::env::var_os("LOGSH_COMPARE_BY_MATERIAL").is_some() {
                print_by_material(&frame.gbuffer.material, image, cycles, unoccluded);
            }
        }
    }
}

/// The figures are over the G-buffer's surface pixels, so a surface it lacks (geometry
/// exported without a material index, which logsh shows as background) does not count:
/// says so on stderr where more than 0.1 % of the background pixels differ from the
/// truth by more than 0.05 (the mean over R, G, B), as a surface there would.
fn report_missed_surfaces(
    dir: &std::path::Path,
    truth: &str,
    material: &[u32],
    image: &[[f32; 3]],
    cycles: &[[f32; 3]],
) {
    let background: Vec<usize> = (0..material.len()).filter(|&i| material[i] == 0).collect();
    let unlike = background
        .iter()
        .filter(|&&i| (0..3).map(|k| (image[i][k] - cycles[i][k]).abs()).sum::<f32>() / 3.0 > 0.05)
        .count();
    if unlike * 1000 > background.len() {
        eprintln!(
            "{}: {unlike} of {} background pixels differ from the {truth} render by more than 0.05: a surface the \
             G-buffer lacks may show there, which the figures leave out",
            dir.display(),
            background.len()
        );
    }
}

/// The settings `logsh shade`'s shading flags give (`--settings "--bounces 0 --level-step 8"`).
fn settings_of(flags: &str) -> Result<ShadingSettings, String> {
    #[derive(clap::Parser)]
    struct Flags {
        #[command(flatten)]
        shading: logsh::cli::ShadingArgs,
    }
    let parsed = <Flags as clap::Parser>::try_parse_from(std::iter::once("--settings").chain(flags.split_whitespace()))
        .map_err(|e| e.to_string())?;
    parsed.shading.settings().map_err(|e| e.to_string())
}

/// The last column: the mean error over the pixels of glossy materials (Phong exponent
/// 50 or more) and their count, or "-".
fn glossy_column(scene: &Scene, material: &[u32], errors: &[f64]) -> String {
    let glossy: Vec<f64> = material
        .iter()
        .filter(|&&m| m != 0)
        .zip(errors)
        .filter(|(m, _)| matches!(scene.materials.get(m), Some(Material::Phong { exponent, .. }) if *exponent >= 50.0))
        .map(|(_, e)| *e)
        .collect();
    if glossy.is_empty() {
        "-".to_string()
    } else {
        format!("{:.3} ({} px)", glossy.iter().sum::<f64>() / glossy.len() as f64, glossy.len())
    }
}

/// Each material's mean absolute and signed error, in units of the open floor
/// (`LOGSH_COMPARE_BY_MATERIAL`), on stderr.
fn print_by_material(material: &[u32], image: &[[f32; 3]], cycles: &[[f32; 3]], unoccluded: [f64; 3]) {
    let mut by_material: std::collections::BTreeMap<u32, (f64, f64, usize)> = Default::default();
    for (i, &m) in material.iter().enumerate() {
        if m == 0 {
            continue;
        }
        let entry = by_material.entry(m).or_default();
        for k in 0..3 {
            let d = (image[i][k] as f64 - cycles[i][k] as f64) / unoccluded[k] / 3.0;
            entry.0 += d.abs();
            entry.1 += d;
        }
        entry.2 += 1;
    }
    for (m, (abs, signed, n)) in by_material {
        let n_f = n as f64;
        eprintln!("    material {m}: {n} pixels, mean abs {:.3}, signed {:+.3}", abs / n_f, signed / n_f);
    }
}

/// The settings each scene is shaded with, named as the table names them: the presets
/// (only the first two with `--quick`), then by what the scene holds, then `--settings`.
fn runs_of(
    scene: &Scene,
    frame: &Frame,
    quick: bool,
    flagged: &[(String, ShadingSettings)],
) -> Vec<(String, ShadingSettings)> {
    let default = Quality::Default.settings();
    let direct = |settings: ShadingSettings| ShadingSettings { bounce: BounceSettings::none(), ..settings };
    let presets = [
        ("default", default),
        ("default, --bounces 0", direct(default)),
        ("high", Quality::High.settings()),
        ("high, --bounces 0", direct(Quality::High.settings())),
        ("ultra", Quality::Ultra.settings()),
        ("ultra, --bounces 0", direct(Quality::Ultra.settings())),
        ("default, depths at log(eps) (--fitted-depths off)", ShadingSettings { fitted_depths: false, ..default }),
        ("default, ratio attenuation", ShadingSettings { ratio_attenuation: true, ..default }),
        ("default, overlap floor off", ShadingSettings { overlap_floor: false, ..default }),
        ("default, no clusters", ShadingSettings { cluster_ratio: 0.0, ..default }),
    ];
    // Where --sharp-lights takes suns out of the map, also without that.
    let has_map_suns = match frame.light.as_ref() {
        Light::Environment { map, strength } => !extract_suns(map, *strength).suns.is_empty(),
        _ => false,
    };
    let whole_map = [
        ("default, sharp lights off", ShadingSettings { sharp_lights: false, ..default }),
        ("high, sharp lights off", ShadingSettings { sharp_lights: false, ..Quality::High.settings() }),
    ];
    // Under a map, also its SH projection windowed.
    let is_map = matches!(frame.light.as_ref(), Light::Environment { .. });
    let windowed = [
        ("default, --light-window lanczos", ShadingSettings { light_window: LightWindow::Lanczos, ..default }),
        ("default, --light-window hann", ShadingSettings { light_window: LightWindow::Hann, ..default }),
    ];
    // Where a material is glossy, also the other two ways of shading its lobe.
    let has_phong = scene.materials.values().any(|m| matches!(m, Material::Phong { .. }));
    let other_glossy = [
        ("default, --glossy phong", ShadingSettings { glossy: GlossyMethod::Phong, ..default }),
        ("default, --glossy sh", ShadingSettings { glossy: GlossyMethod::Sh, ..default }),
    ];
    (if quick { &presets[..2] } else { &presets[..] })
        .iter()
        .chain(if has_map_suns && !quick { &whole_map[..] } else { &[] })
        .chain(if has_phong { &other_glossy[..] } else { &[] })
        .chain(if is_map && !quick { &windowed[..] } else { &[] })
        .map(|&(name, settings)| (name.to_string(), settings))
        .chain(flagged.iter().cloned())
        .collect()
}
