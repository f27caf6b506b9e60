//! logsh against Cycles on exported Blender scenes: shades a scene's first frame at the
//! `default`, `high` and `ultra` presets, at `default` with every cap and slice at `log(eps)`
//! (`--fitted-depths off`), with ratio attenuation, without the
//! overlap floor and without clusters (and, where `--sharp-lights` takes suns out of the
//! map, `default` and `high` without that; under a map, `default` with its projection
//! windowed), and compares each with the direct-lighting Cycles render stored beside it
//! (`cycles.NNNN.exr`, written by `blender_scripts/render_cycles.py` with the exported
//! material table turned back into Cycles shaders, so that both sides use the same albedo,
//! specular colour and lobe width).
//!
//!     cargo run --release --example cycles_compare -- gbuffers/dunes gbuffers/wrecking_ball
//!
//! With `--reference TOLERANCE`, also the ground-truth renderer (`logsh reference`: exact
//! visibility of the same proxies, the environment importance-sampled to `TOLERANCE`):
//! the proxy floor, what the sphere proxies alone cost against the meshes.
//!
//! With `--noise DIR`, the same measure between the stored render and a second one of the
//! same scene with another seed, `DIR/<scene name>/cycles.NNNN.exr`
//! (`render_cycles.py --seed 1`): the Cycles noise floor under these figures.
//!
//! Error: mean over non-background pixels and over R, G, B of |logsh - Cycles| divided by
//! the unoccluded value, the radiance an open, upward-facing white diffuse floor receives
//! from the scene's light and suns (`(1/pi) * integral of L max(w.z, 0)`), so that 0.01 reads as
//! 1% of an unshadowed white floor whatever the light's brightness. Albedo is not divided
//! out: both renders carry the same albedo, and dividing would blow up dark materials and
//! mix the diffuse and specular parts of Phong pixels. Also printed: the 95th percentile
//! and the mean signed difference (positive: logsh brighter).

use exr::prelude::read_first_rgba_layer_from_file;
use logsh::reference::{render_reference, ReferenceOptions};
use logsh::scene::{Light, Material, Scene};
use logsh::shade::shade_frame;
use logsh::shade::sharp_lights::extract_suns;
use logsh::shade::{GlossyMethod, LightWindow, Quality, ShadingSettings};
use std::path::{Path, PathBuf};

fn unoccluded_value(light: &Light) -> [f64; 3] {
    match light {
        Light::Constant(c) => c.map(|v| v as f64),
        Light::Environment { map, strength } => {
            let mut sum = [0.0; 3];
            for row in 0..map.height {
                let v = 1.0 - (row as f64 + 0.5) / map.height as f64;
                let cos_theta = (std::f64::consts::PI * (1.0 - v)).cos();
                if cos_theta <= 0.0 {
                    continue;
                }
                let weight = cos_theta * map.texel_solid_angle(row) / std::f64::consts::PI * *strength as f64;
                for column in 0..map.width {
                    let t = map.texels[row * map.width + column];
                    for k in 0..3 {
                        sum[k] += weight * t[k] as f64;
                    }
                }
            }
            sum
        }
        Light::Sh(_) => {
            panic!("an SH light has no map to integrate; compare scenes with an environment or constant light")
        }
    }
}

fn read_rgb(path: &Path) -> (usize, usize, Vec<[f32; 3]>) {
    let image = read_first_rgba_layer_from_file(
        path,
        |size, _| (size.width(), vec![[0.0f32; 3]; size.width() * size.height()]),
        |(width, pixels), position, (r, g, b, _a): (f32, f32, f32, f32)| {
            pixels[position.y() * *width + position.x()] = [r, g, b];
        },
    )
    .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let size = image.layer_data.size;
    (size.width(), size.height(), image.layer_data.channel_data.pixels.1)
}

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let noise = args.iter().position(|a| a == "--noise").map(|i| {
        let dir = PathBuf::from(args.get(i + 1).expect("--noise needs a directory"));
        args.drain(i..i + 2);
        dir
    });
    let reference_tolerance = args.iter().position(|a| a == "--reference").map(|i| {
        let tolerance: f64 = args.get(i + 1).and_then(|t| t.parse().ok()).expect("--reference needs a tolerance");
        args.drain(i..i + 2);
        tolerance
    });
    let quick = args.iter().position(|a| a == "--quick").map(|i| args.remove(i)).is_some();
    let dirs: Vec<PathBuf> = args.into_iter().map(PathBuf::from).collect();
    if dirs.is_empty() {
        eprintln!("usage: cycles_compare [--quick] [--noise DIR] [--reference TOLERANCE] SCENE_DIR...");
        std::process::exit(2);
    }
    println!("| scene | settings | pixels | mean abs error | p95 | mean signed | glossy pixels (exponent >= 50) |");
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    let default = Quality::Default.settings();
    let all_runs = [
        ("default", default),
        ("high", Quality::High.settings()),
        ("ultra", Quality::Ultra.settings()),
        ("default, depths at log(eps) (--fitted-depths off)", ShadingSettings { fitted_depths: false, ..default }),
        ("default, ratio attenuation", ShadingSettings { ratio_attenuation: true, ..default }),
        ("default, overlap floor off", ShadingSettings { overlap_floor: false, ..default }),
        ("default, no clusters", ShadingSettings { cluster_ratio: 0.0, ..default }),
    ];
    let runs = if quick { &all_runs[..1] } else { &all_runs[..] };
    for dir in dirs {
        let scene = Scene::load(&dir).unwrap_or_else(|e| panic!("{e}"));
        let number = scene.default_frame();
        let frame = scene.frame(number).unwrap_or_else(|e| panic!("{e}"));
        let (width, height, cycles) = read_rgb(&dir.join(format!("cycles.{number:04}.exr")));
        let mut unoccluded = unoccluded_value(&frame.light);
        for sun in &frame.suns {
            // A sun's disk on an open, upward-facing white floor: its irradiance times the
            // cosine at the disk's centre (exact to 2e-5 for a disk a degree wide), over pi.
            let power = sun.disk_integral();
            for k in 0..3 {
                unoccluded[k] += power[k] * sun.direction[2].max(0.0) / std::f64::consts::PI;
            }
        }
        eprintln!("{}: frame {number}, unoccluded value {unoccluded:.3?}", dir.display());
        let scene_name =
            dir.file_name().map_or_else(|| dir.display().to_string(), |n| n.to_string_lossy().into_owned());
        let mut images: Vec<(String, Vec<[f32; 3]>)> = Vec::new();
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
        let runs: Vec<&(&str, ShadingSettings)> = runs
            .iter()
            .chain(if has_map_suns && !quick { &whole_map[..] } else { &[] })
            .chain(if has_phong { &other_glossy[..] } else { &[] })
            .chain(if is_map && !quick { &windowed[..] } else { &[] })
            .collect();
        for (name, settings) in runs {
            let shaded = shade_frame(&scene, &frame, settings).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(
                [width, height],
                [shaded.width, shaded.height],
                "{}: Cycles render and G-buffer differ in size",
                dir.display()
            );
            images.push((name.to_string(), shaded.rgba.iter().map(|p| [p[0], p[1], p[2]]).collect()));
        }
        if let Some(tolerance) = reference_tolerance {
            let options = ReferenceOptions { tolerance, ..Default::default() };
            let started = std::time::Instant::now();
            let truth = render_reference(&scene, &frame, &options, &|_| {}).unwrap_or_else(|e| panic!("{e}"));
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
            let (_, _, second) = read_rgb(&noise.join(&scene_name).join(format!("cycles.{number:04}.exr")));
            images.push(("Cycles, another seed".to_string(), second));
        }
        for (name, image) in &images {
            let mut errors = Vec::new();
            let mut signed = 0.0;
            for (i, &m) in frame.gbuffer.material.iter().enumerate() {
                if m == 0 {
                    continue;
                }
                let mut e = 0.0;
                for k in 0..3 {
                    let d = (image[i][k] as f64 - cycles[i][k] as f64) / unoccluded[k];
                    e += d.abs() / 3.0;
                    signed += d / 3.0;
                }
                errors.push(e);
            }
            let count = errors.len();
            let mean = errors.iter().sum::<f64>() / count as f64;
            let glossy: Vec<f64> = frame
                .gbuffer
                .material
                .iter()
                .filter(|&&m| m != 0)
                .zip(&errors)
                .filter(|(m, _)| matches!(scene.materials.get(m), Some(Material::Phong { exponent, .. }) if *exponent >= 50.0))
                .map(|(_, e)| *e)
                .collect();
            let glossy = if glossy.is_empty() {
                "-".to_string()
            } else {
                format!("{:.3} ({} px)", glossy.iter().sum::<f64>() / glossy.len() as f64, glossy.len())
            };
            errors.sort_by(|a, b| a.total_cmp(b));
            let p95 = errors[(0.95 * (count - 1) as f64).round() as usize];
            println!(
                "| {scene_name} | {name} | {count} | {mean:.3} | {p95:.3} | {:+.3} | {glossy} |",
                signed / count as f64
            );
            if std::env::var_os("LOGSH_COMPARE_BY_MATERIAL").is_some() {
                let mut by_material: std::collections::BTreeMap<u32, (f64, f64, usize)> = Default::default();
                for (i, &m) in frame.gbuffer.material.iter().enumerate() {
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
        }
    }
}
