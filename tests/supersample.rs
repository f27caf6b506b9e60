//! Supersampled G-buffers (`supersample` in scene.json) resolved to the camera's pixels:
//! an edge's resolved alpha against the coverage a far finer sampling gives, the passes
//! still adding up to the beauty, position and normal from the nearest sample, and bad
//! sizes refused.

use crate::support;

use logsh::synth::{self, ExampleOptions, SynthScene};
use std::path::{Path, PathBuf};
use support::exr_channels as channels;

use crate::support::cli::run as logsh;

/// The synthetic dunes (terrain, water, blockers, a sky above the horizon) at 48x27.
fn dunes() -> SynthScene {
    synth::example("dunes", ExampleOptions { width: 48, height: 27, ..Default::default() }).unwrap()
}

fn write(dir: &Path, name: &str, scene: &SynthScene, supersample: u32) -> PathBuf {
    let out = dir.join(name);
    synth::write_scene_supersampled(&out, scene, supersample).unwrap();
    out
}

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Each pixel's share of surface (material not 0), from `fine` x `fine` samples per pixel.
fn coverage(scene: &SynthScene, fine: u32) -> Vec<f64> {
    let mut frame = scene.frames[0].clone();
    let [width, height] = frame.camera.resolution.map(|r| r as usize);
    frame.camera.resolution = frame.camera.resolution.map(|r| r * fine);
    let (g, _) = scene.render_frame(&frame);
    let fine = fine as usize;
    let mut share = vec![0.0; width * height];
    for (i, &m) in g.material.iter().enumerate() {
        if m != 0 {
            let (x, y) = (i % g.width / fine, i / g.width / fine);
            share[y * width + x] += 1.0 / (fine * fine) as f64;
        }
    }
    share
}

/// The target's measure on geometry: the mean absolute error of the edge pixels' alpha
/// against their coverage (16 x 16 samples) is at most half the point-sampled frame's.
#[test]
fn edges_resolve_to_their_coverage() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dunes();
    let truth = coverage(&scene, 16);
    let edges: Vec<usize> = (0..truth.len()).filter(|&i| truth[i] > 0.02 && truth[i] < 0.98).collect();
    assert!(edges.len() > 20, "the frame must have a horizon to test: {} edge pixels", edges.len());
    let mut errors = Vec::new();
    for n in [1, 2, 4] {
        let scene_dir = write(dir.path(), &format!("n{n}"), &scene, n);
        let out = dir.path().join(format!("out{n}"));
        logsh(&["render", path(&scene_dir), "--out", path(&out), "--progress", "none", "--device", "cpu"]);
        let alpha = &channels(&out.join("render.0001.exr"))["A"];
        assert_eq!(alpha.len(), truth.len(), "resolved to the camera's 48x27");
        let error = edges.iter().map(|&i| (f64::from(alpha[i]) - truth[i]).abs()).sum::<f64>() / edges.len() as f64;
        println!("{n}x{n} samples: edge alpha {error:.4} from the coverage over {} edge pixels", edges.len());
        errors.push(error);
    }
    assert!(errors[1] <= 0.5 * errors[0], "2x2 samples must halve the point-sampled edge error: {errors:?}");
    assert!(errors[2] <= 0.5 * errors[1] + 0.01, "4x4 samples must improve on 2x2: {errors:?}");
}

#[test]
fn resolved_passes_add_up_and_data_is_the_nearest_sample() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dunes();
    let scene_dir = write(dir.path(), "n2", &scene, 2);
    for filter in ["box", "blackman-harris"] {
        let out = dir.path().join(filter);
        logsh(&[
            "render",
            path(&scene_dir),
            "--out",
            path(&out),
            "--progress",
            "none",
            "--device",
            "cpu",
            "--colour-type",
            "float",
            "--pixel-filter",
            filter,
        ]);
        let c = channels(&out.join("render.0001.exr"));
        for (k, name) in ["R", "G", "B"].iter().enumerate() {
            let beauty = &c[*name];
            for i in 0..beauty.len() {
                let sum = c[&format!("diffuse.{name}")][i]
                    + c[&format!("specular.{name}")][i]
                    + c[&format!("environment.{name}")][i]
                    + c[&format!("indirect.{name}")][i];
                assert!(
                    (beauty[i] - sum).abs() <= 1e-5 * (1.0 + sum.abs()),
                    "{filter} channel {k} pixel {i}: {} vs {sum}",
                    beauty[i]
                );
            }
        }
        // P and N: the sample at (2x + 1, 2y + 1) of the 96x54 G-buffer.
        let g = logsh::scene::Scene::load(&scene_dir).unwrap().frame(1).unwrap().gbuffer;
        let p = &c["P.X"];
        for (x, y) in [(0, 0), (17, 9), (47, 26)] {
            assert_eq!(p[y * 48 + x], g.position[(2 * y + 1) * 96 + 2 * x + 1][0], "{filter}: P of pixel ({x}, {y})");
        }
    }
    // shade and reference resolve too.
    let shaded = dir.path().join("shaded");
    logsh(&["shade", path(&scene_dir), "--out", path(&shaded), "--device", "cpu", "--pixel-filter", "blackman-harris"]);
    assert_eq!(channels(&shaded.join("beauty.0001.exr"))["R"].len(), 48 * 27);
    let png = image::open(shaded.join("beauty.0001.png")).unwrap();
    assert_eq!((png.width(), png.height()), (48, 27));
}

#[test]
fn bad_supersampling_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dunes();
    let scene_dir = write(dir.path(), "n2", &scene, 2);
    let refuse = |json_edit: &dyn Fn(&mut serde_json::Value), needles: &[&str]| {
        let file = scene_dir.join("scene.json");
        let original = std::fs::read_to_string(&file).unwrap();
        let mut json: serde_json::Value = serde_json::from_str(&original).unwrap();
        json_edit(&mut json);
        std::fs::write(&file, serde_json::to_string(&json).unwrap()).unwrap();
        let output = crate::support::cli::logsh()
            .args(["shade", path(&scene_dir), "--out", path(&dir.path().join("out")), "--device", "cpu"])
            .output()
            .unwrap();
        std::fs::write(&file, original).unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(1), "{stderr}");
        for needle in needles {
            assert!(stderr.contains(needle), "{needle:?} not in {stderr}");
        }
    };
    refuse(&|j| j["supersample"] = serde_json::json!(5), &["scene.json", "supersample", "5"]);
    refuse(&|j| j["supersample"] = serde_json::json!(0), &["scene.json", "supersample"]);
    // The G-buffer is twice the camera's size, not three times.
    refuse(&|j| j["supersample"] = serde_json::json!(3), &["camera.0001.json", "gbuffer.0001.exr"]);
    let output = crate::support::cli::logsh()
        .args(["render", path(&scene_dir), "--out", path(&dir.path().join("t")), "--transfer", "--progress", "none"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("--transfer") && stderr.contains("supersampled"), "{stderr}");

    // A visibility grid needs the samples side by side: refused with the adaptive
    // selection, shaded with --every-sample.
    let grid = ["shade", path(&scene_dir), "--device", "cpu", "--visibility-grid", "2", "--out"];
    let output = crate::support::cli::logsh().args(grid).arg(dir.path().join("grid")).output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("--visibility-grid 2") && stderr.contains("--every-sample"), "{stderr}");
    logsh(&[&grid[..], &[path(&dir.path().join("grid")), "--every-sample"]].concat());
}

/// Adaptive shading (the default) against shading every sample: the same resolved image
/// to well within the shading's own error, from a fraction of the samples.
#[test]
fn adaptive_shading_matches_every_sample_from_fewer() {
    let dir = tempfile::tempdir().unwrap();
    let scene_dir = write(dir.path(), "n2", &dunes(), 2);
    let scene = logsh::scene::Scene::load(&scene_dir).unwrap();
    let frame = scene.frame(1).unwrap();
    let executor = logsh::executor::Executor::cpu();
    let settings = logsh::shade::ShadingSettings::default();
    let shade = |every_sample| {
        let resolving = logsh::shade::Resolving { every_sample, ..Default::default() };
        support::resolved_beauty(&executor, &scene, &frame, &settings, resolving).unwrap()
    };
    let ((adaptive, timings), (every, _)) = (shade(false), shade(true));
    let (shaded, all) = timings.samples.expect("adaptive shading counts its samples");
    assert_eq!(all, 96 * 54);
    let floor = logsh::compare::unoccluded_value(&frame).unwrap();
    let rgb = |f: &logsh::shade::ShadedFrame| f.rgba.iter().map(|p| [p[0], p[1], p[2]]).collect::<Vec<_>>();
    let material =
        logsh::scene::Scene::load(&write(dir.path(), "n1", &dunes(), 1)).unwrap().frame(1).unwrap().gbuffer.material;
    let error = logsh::compare::frame_error(&material, &rgb(&adaptive), &rgb(&every), floor);
    println!(
        "adaptive: {shaded} of {all} samples shaded; {:.5} from every sample (95th percentile {:.4})",
        error.mean, error.p95
    );
    assert!(shaded < all / 2, "{shaded} of {all}");
    // Measured 5.6e-4 here and 8e-5 at 480x270 (fewer pixels straddle a shadow edge):
    // interior pixels shaded at their centre against the mean of their samples, a shadow
    // edge inside a pixel once.
    assert!(error.mean <= 2e-3, "adaptive differs from every sample by {}", error.mean);
}
