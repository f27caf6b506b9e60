//! The GPU pass against the CPU path, its oracle: every sample scene, analytic scenes
//! written for the test, every order and exponentiation, the generic program, tiling and
//! a frame of 8192 x 8192.
//!
//! Tolerance: 0.002 per pixel and channel, relative to the value of an unoccluded white
//! diffuse receiver under the scene's light (1 for a white sky). Both sides run in f32;
//! they differ by the order of sums and by the GPU's transcendental functions.
//!
//! Without an adapter these tests say so and pass, unless `LOGSH_REQUIRE_GPU=1` (which
//! `.ci/run` sets after installing lavapipe): then they fail.
use crate::support;

use logsh::gpu::{Gpu, GpuError, Specialisation};
use logsh::scene::{Frame, GBuffer, Material, Scene};
use logsh::sh::ExpMethod;
use logsh::shade::{GlossyMethod, ShadedFrame, ShadingSettings};
use logsh::sweep::unoccluded_value;
use logsh::synth::{self, ExampleOptions, SphereOverPlane};
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

const TOLERANCE: f64 = 0.002;

/// The adapter, once per test binary; `None` (and a line saying so) without one, unless
/// `LOGSH_REQUIRE_GPU=1`.
pub(crate) fn gpu() -> Option<&'static Gpu> {
    static GPU: OnceLock<Option<Gpu>> = OnceLock::new();
    GPU.get_or_init(|| match Gpu::new() {
        Ok(gpu) => {
            eprintln!("GPU tests on {}", gpu.adapter());
            Some(gpu)
        }
        Err(e) => {
            if std::env::var("LOGSH_REQUIRE_GPU").is_ok_and(|v| v == "1") {
                panic!("LOGSH_REQUIRE_GPU=1 but there is no adapter: {e}");
            }
            eprintln!("GPU tests skipped: {e}");
            None
        }
    })
    .as_ref()
}

struct Difference {
    worst: f64,
    mean: f64,
    worst_pixel: usize,
}

/// Per-pixel difference of two frames over RGB and alpha, in units of the unoccluded value.
fn difference(a: &ShadedFrame, b: &ShadedFrame, unit: f64) -> Difference {
    assert_eq!((a.width, a.height), (b.width, b.height));
    let (mut worst, mut sum, mut worst_pixel) = (0.0f64, 0.0f64, 0);
    for (i, (p, q)) in a.rgba.iter().zip(&b.rgba).enumerate() {
        for c in 0..4 {
            let d = f64::from((p[c] - q[c]).abs()) / unit;
            assert!(d.is_finite(), "pixel {i} channel {c}: {} vs {}", p[c], q[c]);
            sum += d;
            if d > worst {
                worst = d;
                worst_pixel = i;
            }
        }
    }
    Difference { worst, mean: sum / (a.rgba.len() * 4) as f64, worst_pixel }
}

/// Shades `frame` on both executors and checks the tolerance. `None` when the adapter is
/// lavapipe and it refused the settings as beyond its loop budget (the refusal is what
/// keeps its images from being silently wrong); the caller decides whether that is fine.
fn check_parity(gpu: &Gpu, scene: &Scene, frame: &Frame, settings: &ShadingSettings, what: &str) -> Option<Difference> {
    let on_gpu = match support::gpu_beauty(gpu, scene, frame, settings) {
        Err(e @ GpuError::LoopBudget { .. }) if gpu.is_lavapipe() => {
            eprintln!("{what}: refused by lavapipe ({e})");
            return None;
        }
        other => other.unwrap_or_else(|e| panic!("{what}: gpu: {e}")),
    };
    let cpu = support::cpu_beauty(scene, frame, settings).unwrap_or_else(|e| panic!("{what}: cpu: {e}"));
    let unit = unoccluded_value(&frame.light).max(1e-12);
    let d = difference(&on_gpu, &cpu, unit);
    eprintln!("{what}: worst {:.2e}, mean {:.2e}", d.worst, d.mean);
    assert!(
        d.worst <= TOLERANCE,
        "{what}: pixel {} ({}, {}) differs by {:.4} (> {TOLERANCE}): gpu {:?}, cpu {:?}",
        d.worst_pixel,
        d.worst_pixel % cpu.width,
        d.worst_pixel / cpu.width,
        d.worst,
        on_gpu.rgba[d.worst_pixel],
        cpu.rgba[d.worst_pixel]
    );
    Some(d)
}

fn sample_scenes() -> Vec<PathBuf> {
    let mut scenes: Vec<PathBuf> = std::fs::read_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("gbuffers"))
        .expect("gbuffers/")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("scene.json").is_file())
        .collect();
    scenes.sort();
    assert!(!scenes.is_empty(), "no sample scenes in gbuffers/");
    scenes
}

fn frame_numbers(scene: &Scene) -> Vec<i64> {
    scene.frame_numbers(usize::MAX)
}

#[test]
fn sample_scenes_match_the_cpu_path_at_default_settings() {
    let Some(gpu) = gpu() else { return };
    for dir in sample_scenes() {
        let scene = Scene::load(&dir).expect("sample scene loads");
        for number in frame_numbers(&scene) {
            let frame = scene.frame(number).expect("sample frame loads");
            let what = format!("{} frame {number}", dir.display());
            check_parity(gpu, &scene, &frame, &ShadingSettings::default(), &what)
                .unwrap_or_else(|| panic!("{what}: the default settings must fit every adapter"));
        }
    }
}

#[test]
fn sample_scenes_match_at_every_preset() {
    let Some(gpu) = gpu() else { return };
    for dir in sample_scenes() {
        let scene = Scene::load(&dir).expect("sample scene loads");
        let frame = scene.frame(scene.default_frame()).expect("sample frame loads");
        for quality in [logsh::shade::Quality::Draft, logsh::shade::Quality::High, logsh::shade::Quality::Ultra] {
            check_parity(gpu, &scene, &frame, &quality.settings(), &format!("{} {quality:?}", dir.display()));
        }
    }
}

/// A small procedural dunes scene (height field, blockers, Phong, water, environment map)
/// written to a temporary directory.
fn small_dunes(dir: &Path) -> Scene {
    synth::example_scene("dunes", dir, ExampleOptions { width: 64, height: 36, ..Default::default() })
        .expect("write dunes");
    Scene::load(dir).expect("load dunes")
}

/// [`small_dunes`] with a checker texture's colour passes (`SynthScene::checker`).
/// The spheres example at 64x36 (blockers alone), written into `dir`.
fn small_spheres(dir: &Path) -> Scene {
    synth::example_scene("spheres", dir, ExampleOptions { width: 64, height: 36, ..Default::default() })
        .expect("write spheres");
    Scene::load(dir).unwrap()
}

/// A sun towards (0.4, -0.5, 0.6) of `degrees` half-angle, strength 3, warm white.
fn tilted_sun(degrees: f64) -> logsh::scene::SunLight {
    let d = [0.4f64, -0.5, 0.6];
    let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    logsh::scene::SunLight {
        direction: d.map(|c| c / l),
        half_angle: degrees.to_radians(),
        strength: 3.0,
        color: [1.0, 0.9, 0.8],
    }
}

fn textured_dunes(dir: &Path) -> Scene {
    let mut scene = synth::example("dunes", ExampleOptions { width: 64, height: 36, ..Default::default() }).unwrap();
    scene.checker = Some(synth::Checker { cell: 1.5, dark: 0.2 });
    synth::write_scene(dir, &scene).expect("write textured dunes");
    Scene::load(dir).expect("load textured dunes")
}

#[test]
fn every_order_and_exponentiation_matches() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let scene = small_dunes(dir.path());
    let frame = scene.frame(scene.default_frame()).unwrap();
    let mut compared = 0;
    // The glossy lobe in log-SH, as every exponentiation shades it: the prefiltered lobe's
    // cone test and second march would put most of these beyond lavapipe's loop budget,
    // and `suns_and_sharp_glossy_match` and `every_knob_matches` compare it.
    for order in 3..=8 {
        for exp in [ExpMethod::Quad, ExpMethod::Exact, ExpMethod::Ol, ExpMethod::Hyb, ExpMethod::Series] {
            let settings = ShadingSettings { exp, glossy: GlossyMethod::Sh, ..ShadingSettings::for_order(order) };
            compared += check_parity(gpu, &scene, &frame, &settings, &format!("dunes 64x36 order {order} {exp:?}"))
                .is_some() as usize;
        }
    }
    assert!(compared >= 15, "only {compared} of 30 configurations compared");
}

#[test]
fn every_knob_matches() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let scene = small_dunes(dir.path());
    let frame = scene.frame(scene.default_frame()).unwrap();
    let base = ShadingSettings::default();
    let mut bilinear = base;
    bilinear.horizon.reconstruction = logsh::heightfield::LevelReconstruction::Bilinear;
    let mut spline_max = base;
    spline_max.horizon.scale_max = logsh::heightfield::ScaleMax::BSpline;
    let mut wide = base;
    wide.horizon.directions = 48;
    wide.horizon.level_step = 2.0;
    let cases = [
        ("ratio attenuation", ShadingSettings { ratio_attenuation: true, ..base }),
        ("depths at log(eps)", ShadingSettings { fitted_depths: false, ..base }),
        ("no tangent occlusion", ShadingSettings { tangent_occlusion: false, ..base }),
        ("eps 0.01", ShadingSettings { epsilon: 0.01, ..base }),
        ("phong eps 0.2", ShadingSettings { phong_epsilon: Some(0.2), ..base }),
        ("prefiltered phong lobe", ShadingSettings { glossy: GlossyMethod::Phong, ..base }),
        ("glossy in log-SH", ShadingSettings { glossy: GlossyMethod::Sh, ..base }),
        ("bilinear levels", bilinear),
        ("b-spline scale max", spline_max),
        ("W 48, k 2", wide),
    ];
    for (what, settings) in cases {
        check_parity(gpu, &scene, &frame, &settings, &format!("dunes 64x36 {what}"));
    }
}

/// The blocker tree's paths on both executors: a cloud of 400 small spheres over the
/// `spheres` sample (clusters seen as one cap, negligible ones dropped, subtrees behind the
/// tangent plane skipped), and object indices on pixels and spheres (own spheres that hold
/// a receiver cast nothing on it), with the overlap floor on and off. 400 keeps the
/// frame within lavapipe's loop budget, so the comparison runs there too.
#[test]
fn blocker_tree_and_own_spheres_match() {
    let Some(gpu) = gpu() else { return };
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("gbuffers/spheres");
    let scene = Scene::load(&dir).unwrap();
    let mut frame = scene.frame(scene.default_frame()).unwrap();
    let mut rng = support::TestRng(0x9e37_79b9_7f4a_7c15);
    let objects = frame.gbuffer.material.clone();
    for (k, sphere) in frame.blockers.iter_mut().enumerate() {
        sphere.object = 1 + k as u32 % 3;
    }
    for _ in 0..400 {
        let centre = [rng.next() * 8.0 - 4.0, rng.next() * 8.0 - 4.0, 2.0 + 2.0 * rng.next()];
        frame.blockers.push(logsh::scene::Sphere::new(centre, 0.01 + 0.03 * rng.next()));
    }
    frame.gbuffer.object = Some(objects);
    // The cloud is seen through clusters: from the ground, fewer caps than spheres.
    let tree = logsh::shade::blocker_tree::BlockerTree::new(&frame.blockers, ShadingSettings::default().cluster_ratio);
    let mut caps = 0;
    tree.visit([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 0, |_, _| caps += 1);
    assert!(caps < frame.blockers.len() / 2, "{caps} caps seen of {} spheres", frame.blockers.len());
    for overlap_floor in [true, false] {
        let settings = ShadingSettings { overlap_floor, ..ShadingSettings::default() };
        let what = format!("cloud, overlap floor {overlap_floor}");
        check_parity(gpu, &scene, &frame, &settings, &what).unwrap_or_else(|| panic!("{what}: must fit lavapipe"));
    }
}

#[test]
fn analytic_scenes_match() {
    let Some(gpu) = gpu() else { return };
    for (i, spheres) in synth::analytic_placements().into_iter().enumerate() {
        let dir = tempfile::tempdir().unwrap();
        let spec = SphereOverPlane { spheres, width: 96, height: 54, ..Default::default() };
        synth::sphere_over_plane(dir.path(), &spec).expect("write analytic scene");
        let scene = Scene::load(dir.path()).unwrap();
        let frame = scene.frame(1).unwrap();
        let orders: &[usize] = if i == 0 { &[3, 4, 5, 6, 7, 8] } else { &[4] };
        for &order in orders {
            check_parity(
                gpu,
                &scene,
                &frame,
                &ShadingSettings::for_order(order),
                &format!("sphere over plane {i} order {order}"),
            );
        }
    }
}

#[test]
fn generic_program_gives_the_specialised_image() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let scene = small_dunes(dir.path());
    let spheres = small_spheres(&dir.path().join("spheres"));
    for scene in [&scene, &spheres] {
        let frame = scene.frame(scene.default_frame()).unwrap();
        let settings = ShadingSettings::default();
        let (specialised, _) = support::gpu_beauty_timed(gpu, scene, &frame, &settings, Specialisation::Full).unwrap();
        for less in [Specialisation::Order, Specialisation::None] {
            let (generic, _) = support::gpu_beauty_timed(gpu, scene, &frame, &settings, less).unwrap();
            let d = difference(&generic, &specialised, unoccluded_value(&frame.light));
            assert!(d.worst <= 1e-4, "{}: {less:?} differs by {}", scene.dir.display(), d.worst);
        }
    }
}

/// A device and queue the test makes itself, as an application embedding logsh would,
/// with WebGPU's default limits rather than the adapter's and no timestamps.
fn own_device() -> Gpu {
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default())).unwrap();
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("the test's own device"),
        required_limits: wgpu::Limits::default(),
        ..Default::default()
    }))
    .unwrap();
    Gpu::from_device(adapter.get_info(), device, queue)
}

#[test]
fn tiles_give_the_untiled_image() {
    let Some(_) = gpu() else { return };
    let tiled = own_device().with_max_tile_points(1000);
    let dir = tempfile::tempdir().unwrap();
    let scene = small_dunes(dir.path());
    let frame = scene.frame(scene.default_frame()).unwrap();
    let settings = ShadingSettings::default();
    let whole = support::gpu_beauty(gpu().unwrap(), &scene, &frame, &settings).unwrap();
    let pieces = support::gpu_beauty(&tiled, &scene, &frame, &settings).unwrap();
    assert_eq!(tiled.tile_points(64 * 36), 1000);
    assert_eq!(whole.rgba, pieces.rgba, "three tiles of 1000 points and one frame-sized tile differ");
}

/// One `Gpu` shared by eight frames at once over two scenes (two programs compiled at once
/// on a device that has none yet), from eight threads and then from eight jobs of a pool of
/// four: every frame equals the same frame shaded alone, bit for bit. Frames take turns on
/// the device; shading at once, 16 threads never finished on an NVIDIA H200 (docs/guide/gpu.md).
#[test]
fn frames_from_many_threads_take_turns() {
    let Some(_) = gpu() else { return };
    let shared = own_device();
    let samples = Path::new(env!("CARGO_MANIFEST_DIR")).join("gbuffers");
    let scenes = [Scene::load(&samples.join("spheres")).unwrap(), Scene::load(&samples.join("cones")).unwrap()];
    let frames: Vec<Frame> = scenes.iter().map(|s| s.frame(s.default_frame()).unwrap()).collect();
    let settings = ShadingSettings::default();
    let shade = |i: usize| (i % 2, support::gpu_beauty(&shared, &scenes[i % 2], &frames[i % 2], &settings).unwrap());
    let from_threads: Vec<(usize, ShadedFrame)> = std::thread::scope(|threads| {
        let shading: Vec<_> = (0..8).map(|i| threads.spawn(move || shade(i))).collect();
        shading.into_iter().map(|t| t.join().unwrap()).collect()
    });
    let pool = rayon::ThreadPoolBuilder::new().num_threads(4).build().unwrap();
    let from_jobs: Vec<(usize, ShadedFrame)> = pool.install(|| (0..8usize).into_par_iter().map(shade).collect());
    let alone: Vec<ShadedFrame> = scenes
        .iter()
        .zip(&frames)
        .map(|(s, f)| support::gpu_beauty(gpu().unwrap(), s, f, &settings).unwrap())
        .collect();
    for (k, shaded) in from_threads.iter().chain(&from_jobs) {
        assert_eq!(shaded.rgba, alone[*k].rgba, "scene {k}: a frame shaded beside seven others differs");
    }
}

/// An 8192 x 8192 frame: the spheres sample's 320 x 180 pixels in the middle of a
/// background of 67 million pixels. Tiled within the adapter's limits, background from
/// the light, the middle equal to the sample frame shaded on the CPU.
#[test]
fn frame_of_8192_squared_is_shaded_in_tiles() {
    let Some(gpu) = gpu() else { return };
    let scene = Scene::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("gbuffers/spheres")).unwrap();
    let small = scene.frame(scene.default_frame()).unwrap();
    let settings = ShadingSettings::for_order(3);
    let expected = support::cpu_beauty(&scene, &small, &settings).unwrap();
    const SIDE: usize = 8192;
    let (w, h) = (small.gbuffer.width, small.gbuffer.height);
    let (x0, y0) = ((SIDE - w) / 2, (SIDE - h) / 2);
    let mut g = GBuffer {
        file: small.gbuffer.file.clone(),
        width: SIDE,
        height: SIDE,
        position: vec![[0.0; 3]; SIDE * SIDE],
        normal: vec![[0.0, 0.0, 1.0]; SIDE * SIDE],
        uv: None,
        material: vec![0; SIDE * SIDE],
        object: None,
        colours: None,
        first_row: 0,
    };
    for y in 0..h {
        for x in 0..w {
            let (i, j) = (y * w + x, (y0 + y) * SIDE + x0 + x);
            g.position[j] = small.gbuffer.position[i];
            g.normal[j] = small.gbuffer.normal[i];
            g.material[j] = small.gbuffer.material[i];
        }
    }
    let mut big = small.clone();
    big.gbuffer = g;
    if let Some(camera) = big.camera.as_mut() {
        camera.resolution = [SIDE as u32, SIDE as u32];
    }
    let tiles = (SIDE * SIDE).div_ceil(gpu.tile_points(SIDE * SIDE));
    eprintln!("8192 x 8192 in {tiles} tile(s) of {} points", gpu.tile_points(SIDE * SIDE));
    let shaded = support::gpu_beauty(gpu, &scene, &big, &settings).expect("8192 x 8192 frame");
    assert_eq!((shaded.width, shaded.height), (SIDE, SIDE));
    let unit = unoccluded_value(&small.light);
    let mut worst = 0.0f64;
    for y in 0..h {
        for x in 0..w {
            let (i, j) = (y * w + x, (y0 + y) * SIDE + x0 + x);
            if small.gbuffer.material[i] != 0 {
                for c in 0..4 {
                    worst = worst.max(f64::from((shaded.rgba[j][c] - expected.rgba[i][c]).abs()) / unit);
                }
            }
        }
    }
    assert!(worst <= TOLERANCE, "8192 x 8192: shaded middle differs by {worst}");
    let corner = shaded.rgba[0];
    assert!(corner[3] == 0.0 && corner[..3].iter().all(|c| c.is_finite() && *c >= 0.0), "corner {corner:?}");
}

/// The loop-budget guard: on lavapipe, settings beyond its budget are refused with a
/// message, never shaded wrong; every other adapter shades them.
#[test]
fn settings_beyond_lavapipes_loop_budget_are_refused_there() {
    let Some(gpu) = gpu() else { return };
    let scene = Scene::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("gbuffers/spheres")).unwrap();
    let frame = scene.frame(scene.default_frame()).unwrap();
    let settings = ShadingSettings { exp: ExpMethod::Exact, ..ShadingSettings::for_order(8) };
    match support::gpu_beauty(gpu, &scene, &frame, &settings) {
        Err(GpuError::LoopBudget { needed, limit, .. }) => {
            assert!(gpu.is_lavapipe() && needed > limit);
        }
        Ok(shaded) => assert!(!gpu.is_lavapipe(), "lavapipe shaded {} pixels beyond its budget", shaded.rgba.len()),
        Err(e) => panic!("{e}"),
    }
}

/// `logsh render`'s passes: diffuse, specular, environment, beauty and the three
/// visibility terms, GPU against CPU, with and without colour passes.
#[test]
fn compositing_passes_match() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let mut scenes = vec![small_dunes(dir.path()), textured_dunes(&dir.path().join("textured"))];
    scenes.extend(sample_scenes().iter().map(|d| Scene::load(d).unwrap()));
    for scene in &scenes {
        let frame = scene.frame(scene.default_frame()).unwrap();
        let settings = ShadingSettings::default();
        if scene.colour_passes() {
            check_parity(gpu, scene, &frame, &settings, "textured dunes, beauty");
        }
        let cpu = support::cpu_passes(scene, &frame, &settings).unwrap();
        let on_gpu = support::gpu_passes(gpu, scene, &frame, &settings).unwrap();
        let unit = unoccluded_value(&frame.light).max(1e-12) as f32;
        let rgb = |v: &[[f32; 3]]| v.iter().flat_map(|c| c.iter().map(|x| x / unit)).collect::<Vec<f32>>();
        let rgba = |v: &[[f32; 4]]| v.iter().flat_map(|c| c.iter().map(|x| x / unit)).collect::<Vec<f32>>();
        let what = scene.dir.display();
        assert_close!(rgba(&on_gpu.beauty), rgba(&cpu.beauty), TOLERANCE, "{what}: beauty");
        assert_close!(rgb(&on_gpu.diffuse), rgb(&cpu.diffuse), TOLERANCE, "{what}: diffuse");
        assert_close!(rgb(&on_gpu.specular), rgb(&cpu.specular), TOLERANCE, "{what}: specular");
        assert_close!(rgb(&on_gpu.environment), rgb(&cpu.environment), TOLERANCE, "{what}: environment");
        assert_close!(on_gpu.visibility, cpu.visibility, TOLERANCE, "{what}: visibility");
        assert_close!(
            on_gpu.visibility_heightfield,
            cpu.visibility_heightfield,
            TOLERANCE,
            "{what}: visibility_heightfield"
        );
        assert_close!(on_gpu.visibility_blockers, cpu.visibility_blockers, TOLERANCE, "{what}: visibility_blockers");
    }
}

/// The RGBA pixels of an EXR `logsh shade` wrote.
fn read_rgba(path: &Path) -> Vec<[f32; 4]> {
    use exr::prelude::*;
    let image = read_first_rgba_layer_from_file(
        path,
        |resolution, _| (resolution.width(), vec![[0.0f32; 4]; resolution.width() * resolution.height()]),
        |(width, pixels): &mut (usize, Vec<[f32; 4]>), position, (r, g, b, a): (f32, f32, f32, f32)| {
            pixels[position.y() * *width + position.x()] = [r, g, b, a];
        },
    )
    .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    image.layer_data.channel_data.pixels.1
}

/// The done-when of the GPU pass: `logsh shade --device gpu` against `--device cpu` on
/// every sample scene, through the command line and the written EXRs.
#[test]
fn shade_on_the_gpu_matches_the_cpu_through_the_command_line() {
    let Some(_) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    for scene in sample_scenes() {
        let mut images = Vec::new();
        for device in ["gpu", "cpu"] {
            let out = dir.path().join(format!("{}-{device}", scene.file_name().unwrap().to_string_lossy()));
            let output = crate::support::cli::logsh()
                .args(["shade", "--device", device])
                .arg(&scene)
                .arg("--out")
                .arg(&out)
                .output()
                .unwrap();
            let stderr = String::from_utf8_lossy(&output.stderr);
            assert!(output.status.success(), "{stderr}");
            assert!(stderr.contains(&format!("on {device}")), "{stderr}");
            let frame = Scene::load(&scene).unwrap().default_frame();
            images.push(read_rgba(&out.join(format!("beauty.{frame:04}.exr"))));
        }
        let light = Scene::load(&scene).unwrap().frame(1).map(|f| unoccluded_value(&f.light)).unwrap_or(1.0);
        let scale =
            |v: &[[f32; 4]]| v.iter().flat_map(|c| c.iter().map(|x| f64::from(*x) / light)).collect::<Vec<f64>>();
        assert_close!(
            scale(&images[0]),
            scale(&images[1]),
            TOLERANCE,
            "{}: --device gpu vs --device cpu",
            scene.display()
        );
    }
}

/// A ground plane (`ground` in scene.json) under the spheres sample: the hemisphere below
/// the horizontal for receivers above it, in the beauty and in the passes' unoccluded
/// term, on both executors.
#[test]
fn ground_plane_matches() {
    let Some(gpu) = gpu() else { return };
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("gbuffers/spheres");
    let scene = Scene::load(&dir).unwrap();
    let mut frame = scene.frame(scene.default_frame()).unwrap();
    let lowest = frame.gbuffer.position.iter().zip(&frame.gbuffer.material).filter(|(_, &m)| m != 0);
    let ground = lowest.map(|(p, _)| f64::from(p[2])).fold(f64::INFINITY, f64::min);
    frame.ground = Some(ground);
    let settings = ShadingSettings::default();
    let without = support::cpu_beauty(&scene, &Frame { ground: None, ..frame.clone() }, &settings).unwrap();
    let with = support::cpu_beauty(&scene, &frame, &settings).unwrap();
    let changed = with.rgba.iter().zip(&without.rgba).filter(|(a, b)| (a[0] - b[0]).abs() > 1e-3).count();
    assert!(changed > 100, "the ground changes the spheres' pixels ({changed} changed)");
    check_parity(gpu, &scene, &frame, &settings, "spheres over a ground plane").expect("fits lavapipe's budget");
    let cpu = support::cpu_passes(&scene, &frame, &settings).unwrap();
    let on_gpu = support::gpu_passes(gpu, &scene, &frame, &settings).unwrap();
    assert_close!(on_gpu.visibility, cpu.visibility, TOLERANCE, "ground plane: visibility");
    assert_close!(on_gpu.visibility_blockers, cpu.visibility_blockers, TOLERANCE, "ground plane: visibility_blockers");
}

/// Point lamps on both executors, over the small dunes (height field, blockers, Phong,
/// water) and the `cones` sample (ground plane, metal cone): a Soft Falloff lamp low over
/// the terrain (its horizon cut at the lamp's distance), a sphere lamp high above, one
/// of radius 0 (the narrowest disk), and one low among the receivers.
#[test]
fn point_lamps_match() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let dunes = small_dunes(dir.path());
    let cones = Scene::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("gbuffers/cones")).unwrap();
    for (name, scene) in [("dunes 64x36", &dunes), ("cones", &cones)] {
        let mut frame = scene.frame(scene.default_frame()).unwrap();
        // Over the middle of what the frame sees, 0.3 and 3 of its extent up.
        let points = frame.gbuffer.material.iter().zip(&frame.gbuffer.position).filter(|(&m, _)| m != 0);
        let (mut low, mut high) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for (_, p) in points {
            for k in 0..3 {
                low[k] = low[k].min(f64::from(p[k]));
                high[k] = high[k].max(f64::from(p[k]));
            }
        }
        let middle = [0, 1, 2].map(|k| 0.5 * (low[k] + high[k]));
        let extent = (high[0] - low[0]).max(high[1] - low[1]);
        let lamp = |height: f64, radius: f64, power: f32, soft_falloff| logsh::scene::PointLight {
            position: [middle[0] + 0.1 * extent, middle[1], high[2] + height * extent],
            radius: radius * extent,
            power: power * (extent * extent) as f32,
            color: [1.0, 0.9, 0.8],
            soft_falloff,
        };
        // Powers that light the ground about as much as the sky does.
        frame.points = vec![lamp(0.3, 0.05, 1.0, true), lamp(3.0, 0.1, 100.0, false), lamp(1.0, 0.0, 10.0, true)];
        // And one low among the receivers, below the horizontal of those above it, whose
        // horizons are marched below the horizontal too.
        let low_lamp = logsh::scene::PointLight {
            position: [middle[0], middle[1], low[2] + 0.3 * (high[2] - low[2])],
            ..lamp(0.0, 0.02, 0.3, true)
        };
        frame.points.push(low_lamp);
        // The lamps must light the frame for the comparison to test them.
        let mean = |f: &logsh::scene::Frame| {
            let shaded = support::cpu_beauty(scene, f, &ShadingSettings::default()).unwrap();
            shaded.rgba.iter().map(|p| f64::from(p[0] + p[1] + p[2])).sum::<f64>() / shaded.rgba.len() as f64
        };
        let unlit = logsh::scene::Frame { points: Vec::new(), ..frame.clone() };
        let (with, without) = (mean(&frame), mean(&unlit));
        assert!(with > 1.3 * without, "{name}: the lamps add too little light to test: {with} against {without}");
        check_parity(gpu, scene, &frame, &within_loop_budget(), &format!("{name} with point lamps"))
            .unwrap_or_else(|| panic!("{name}: refused"));
    }
}

/// Sharp lights and sharp glossy lobes on both executors: a sun a few degrees wide over
/// the small dunes (height field, blockers, Phong, water) and over the `cones` sample
/// (ground plane, metal cone), with the glossy lobe prefiltered as GGX or Phong (each with
/// its cone test) and in log-SH. A sun's penumbra turns a disk direction from lit to
/// blocked over two patch radii (0.7 degrees here): with `asin` and `atan2` deciding the
/// shares, lavapipe's 4096-ulp inverse trigonometry moved one such pixel by 0.005; the
/// shares now come from sines (src/shade/sun.rs). With colour passes, the lamps'
/// Fresnel term is a dielectric's (reflectance 0.04) and between a dielectric's and a
/// metal's (0.3): measured, the two differ by up to 0.059 at the sphere's highlight, and
/// the executors by 1.8e-4 at most.
#[test]
fn suns_and_sharp_glossy_match() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let dunes = small_dunes(dir.path());
    let cones = Scene::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("gbuffers/cones")).unwrap();
    let sun = tilted_sun(2.0);
    let base = within_loop_budget();
    let mut lamps_levels_at_w8 = ShadingSettings::default();
    lamps_levels_at_w8.horizon.directions = 8;
    for (name, scene) in [("dunes 64x36", &dunes), ("cones", &cones)] {
        let mut frame = scene.frame(scene.default_frame()).unwrap();
        frame.suns.push(sun);
        for (what, settings) in [
            ("ggx", base),
            ("phong", ShadingSettings { glossy: GlossyMethod::Phong, ..base }),
            ("sh", ShadingSettings { glossy: GlossyMethod::Sh, ..base }),
            ("ggx, the lamps' march at W 8", lamps_levels_at_w8),
        ] {
            check_parity(gpu, scene, &frame, &settings, &format!("{name} with a sun, glossy {what}"))
                .unwrap_or_else(|| panic!("{name}: refused"));
        }
    }
    let mut textured = textured_dunes(&dir.path().join("textured"));
    let phong: Vec<u32> =
        textured.materials.iter().filter(|(_, m)| matches!(m, Material::Phong { .. })).map(|(&i, _)| i).collect();
    assert!(!phong.is_empty());
    let mut frame = textured.frame(textured.default_frame()).unwrap();
    frame.suns.push(sun);
    let mut beauties = Vec::new();
    for reflectance in [0.04, 0.3] {
        textured.fresnel = phong.iter().map(|&i| (i, reflectance)).collect();
        let what = format!("textured dunes with a sun, Fresnel from {reflectance}");
        check_parity(gpu, &textured, &frame, &base, &what).unwrap_or_else(|| panic!("{what}: refused"));
        beauties.push(support::cpu_beauty(&textured, &frame, &base).unwrap().rgba);
    }
    let moved = beauties[0].iter().zip(&beauties[1]).filter(|(a, b)| (a[1] - b[1]).abs() > 1e-3).count();
    let most = beauties[0].iter().zip(&beauties[1]).map(|(a, b)| (a[1] - b[1]).abs()).fold(0.0f32, f32::max);
    println!("the reflectance moves {moved} of {} pixels by more than 1e-3, at most {most}", beauties[0].len());
    assert!(moved >= 5 && most > 0.02, "the reflectance must show: {moved} pixels moved, at most {most}");
}

/// The default preset with the environment's march under lamps too: the lamps' finer one
/// (k 6, o 6: W 16 x 78 steps on the small dunes) is beyond lavapipe's loop budget beside
/// the dunes' blockers. `suns_and_sharp_glossy_match` compares it at W 8.
fn within_loop_budget() -> ShadingSettings {
    ShadingSettings { lamp_levels: None, ..ShadingSettings::default() }
}

/// A supersampled frame is shaded at its samples' resolution on both executors (its
/// camera scaled to the G-buffer's size on reading), then resolved by the same filter.
#[test]
fn supersampled_frames_match() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let options = logsh::synth::ExampleOptions { width: 32, height: 18, ..Default::default() };
    let synth = logsh::synth::example("dunes", options).unwrap();
    logsh::synth::write_scene_supersampled(&dir.path().join("n2"), &synth, 2).unwrap();
    let scene = Scene::load(&dir.path().join("n2")).unwrap();
    let frame = scene.frame(1).unwrap();
    let camera = frame.camera.as_ref().expect("a camera");
    assert_eq!((frame.gbuffer.width, camera.resolution), (64, [64, 36]));
    check_parity(gpu, &scene, &frame, &ShadingSettings::default(), "dunes 32x18, 2x2 samples").expect("shaded");
    // The packed frame of adaptive shading, its samples in rows of their own.
    let packed = logsh::shade::adaptive::select(&frame).packed;
    check_parity(gpu, &scene, &packed, &ShadingSettings::default(), "dunes 32x18, adaptive samples").expect("shaded");
}

/// Bounce light on the GPU executor against the CPU one: the surroundings' secondary
/// points are shaded on each (their gather runs on the CPU for both), on the dunes with
/// and without colour passes, and on a white sphere over a white ground plane under a
/// sun of 1e6 and one on the horizon, with a black sky. Every bounce pass within [`TOLERANCE`] of the unoccluded value (the sun's
/// strength where there is a sun).
#[test]
fn bounce_light_matches() {
    use logsh::executor::{DeviceChoice, Executor};
    use logsh::scene::{Light, Material, SunLight};
    use logsh::shade::bounce::BounceSettings;
    if gpu().is_none() {
        return;
    }
    let settings =
        ShadingSettings { bounce: BounceSettings { bounces: 3, ..BounceSettings::DEFAULT }, ..Default::default() };
    let on_gpu = Executor::select(DeviceChoice::Gpu, &settings).expect("the adapter");
    let dir = tempfile::tempdir().unwrap();
    let mut cases: Vec<(String, Scene, Frame, f64)> = Vec::new();
    for (name, scene) in
        [("dunes", small_dunes(&dir.path().join("d"))), ("textured dunes", textured_dunes(&dir.path().join("t")))]
    {
        let frame = scene.frame(1).unwrap();
        let unit = unoccluded_value(&frame.light);
        cases.push((name.into(), scene, frame, unit));
    }
    let spec = SphereOverPlane { width: 48, height: 27, ..SphereOverPlane::default() };
    let white = dir.path().join("white");
    synth::sphere_over_plane(&white, &spec).unwrap();
    let mut scene = Scene::load(&white).unwrap();
    for material in scene.materials.values_mut() {
        if let Material::Diffuse { albedo } = material {
            *albedo = [1.0; 3];
        }
    }
    scene.ground = Some(0.0);
    let mut frame = scene.frame(1).unwrap();
    frame.ground = Some(0.0);
    frame.light = std::sync::Arc::new(Light::Constant([0.0; 3]));
    for (elevation, strength) in [(35.0f64, 1e6f32), (0.0, 4.0)] {
        let e = elevation.to_radians();
        let mut frame = frame.clone();
        frame.suns = vec![SunLight {
            direction: [0.6 * e.cos(), 0.8 * e.cos(), e.sin()],
            half_angle: 0.0047,
            strength,
            color: [1.0; 3],
        }];
        cases.push((
            format!("white sphere over white ground, sun {strength} at {elevation} deg"),
            scene.clone(),
            frame,
            f64::from(strength),
        ));
    }
    for (name, scene, frame, unit) in &cases {
        let cpu = support::rendered_passes(&Executor::cpu(), scene, frame, &settings)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let gpu = support::rendered_passes(&on_gpu, scene, frame, &settings).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(cpu.indirect.iter().any(|v| v[1] > 0.0), "{name}: no bounce light");
        for (pass, a, b) in [
            ("indirect_heightfield", &cpu.indirect_heightfield, &gpu.indirect_heightfield),
            ("indirect_blockers", &cpu.indirect_blockers, &gpu.indirect_blockers),
        ] {
            let worst = a
                .iter()
                .zip(b)
                .flat_map(|(p, q)| (0..3).map(move |c| f64::from((p[c] - q[c]).abs())))
                .fold(0.0, f64::max)
                / unit;
            println!("{name}: {pass} worst difference {worst:.2e} of the unoccluded value");
            assert!(worst.is_finite() && worst <= TOLERANCE, "{name}: {pass} differs by {worst}");
        }
    }
}

/// `--visibility-grid` on both executors (the grid's pre-pass and each pixel's
/// interpolation, `grid_visibility` and `grid_at` in shaders/shade.wgsl, against
/// src/shade/visibility_grid.rs): the dunes (height field, blockers, water, Phong), with a
/// sun too and without its blockers, and the spheres example (blockers alone), at 2 and
/// 4; the compositing passes;
/// a frame in tiles, each of which reads the whole frame's grid; and an adapter that binds
/// too few storage buffers, which refuses the grid by name.
#[test]
fn visibility_grid_matches() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let dunes = small_dunes(dir.path());
    let spheres = small_spheres(&dir.path().join("spheres"));
    let mut sunlit = dunes.frame(dunes.default_frame()).unwrap();
    sunlit.suns.push(logsh::scene::SunLight {
        direction: [0.48, -0.6, 0.64],
        half_angle: 1f64.to_radians(),
        strength: 3.0,
        color: [1.0, 0.9, 0.8],
    });
    // A height field alone composes the program without the blockers' module.
    let mut bare = dunes.frame(dunes.default_frame()).unwrap();
    bare.blockers.clear();
    let cases = [
        ("dunes 64x36", &dunes, dunes.frame(dunes.default_frame()).unwrap()),
        ("dunes 64x36 with a sun", &dunes, sunlit),
        ("dunes 64x36 without blockers", &dunes, bare),
        ("spheres 64x36", &spheres, spheres.frame(spheres.default_frame()).unwrap()),
    ];
    for (name, scene, frame) in &cases {
        let unit = unoccluded_value(&frame.light).max(1e-12);
        let per_pixel = support::gpu_beauty(gpu, scene, frame, &within_loop_budget()).unwrap();
        for grid in [2, 4] {
            let settings = ShadingSettings { visibility_grid: grid, ..within_loop_budget() };
            let gridded = support::gpu_beauty(gpu, scene, frame, &settings).unwrap();
            let cpu = support::cpu_beauty(scene, frame, &settings).unwrap();
            let d = difference(&gridded, &cpu, unit);
            eprintln!("{name}, visibility grid {grid}: worst {:.2e}, mean {:.2e}", d.worst, d.mean);
            assert!(d.worst <= TOLERANCE, "{name}, grid {grid}: pixel {} differs by {}", d.worst_pixel, d.worst);
            // The grid took effect: some pixel differs from visibility at every pixel.
            let apart = difference(&gridded, &per_pixel, unit).worst;
            assert!(apart > 1e-3, "{name}, grid {grid}: within {apart} of every pixel's image");
        }
    }

    let (_, scene, frame) = &cases[0];
    let settings = ShadingSettings { visibility_grid: 2, ..ShadingSettings::default() };
    let cpu = support::cpu_passes(scene, frame, &settings).unwrap();
    let on_gpu = support::gpu_passes(gpu, scene, frame, &settings).unwrap();
    let unit = unoccluded_value(&frame.light).max(1e-12) as f32;
    let rgba = |v: &[[f32; 4]]| v.iter().flat_map(|c| c.iter().map(|x| x / unit)).collect::<Vec<f32>>();
    assert_close!(rgba(&on_gpu.beauty), rgba(&cpu.beauty), TOLERANCE, "grid 2: beauty");
    assert_close!(on_gpu.visibility, cpu.visibility, TOLERANCE, "grid 2: visibility");
    assert_close!(on_gpu.visibility_heightfield, cpu.visibility_heightfield, TOLERANCE, "grid 2: heightfield");
    assert_close!(on_gpu.visibility_blockers, cpu.visibility_blockers, TOLERANCE, "grid 2: blockers");

    let whole = support::gpu_beauty(gpu, scene, frame, &settings).unwrap();
    let tiled = Gpu::new().unwrap().with_max_tile_points(500);
    let pieces = support::gpu_beauty(&tiled, scene, frame, &settings).unwrap();
    assert_eq!(whole.rgba, pieces.rgba, "grid 2: five tiles of 500 points and one frame-sized tile differ");

    let refused =
        support::gpu_beauty(&own_device(), scene, frame, &settings).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(refused.contains("--visibility-grid 2") && refused.contains("storage buffers"), "{refused}");
}

/// A sun's shadow map on both executors (`shadow_blocked` in shaders/disk.wgsl against
/// src/shade/sun_shadow.rs): the spheres example and the small dunes (height field,
/// water, Phong) under a sun 2 degrees wide, each with the map of its spheres; the dunes'
/// map is rendered 0.7 degrees off the sun, as an HDRI's sun is found by the exporter and
/// by logsh apart, so that its rays drift through it sideways, and a second, dimmer sun
/// 0.4 degrees from the first shares it (a Sun lamp set along an HDRI's sun). The map
/// took effect: the frame differs from the spheres' own shadows.
#[test]
fn sun_shadow_maps_match() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let dunes = small_dunes(dir.path());
    let spheres = small_spheres(&dir.path().join("spheres"));
    let sun = tilted_sun(1.0);
    let turned = |degrees: f64| {
        let d = sun.direction;
        let across = logsh::vector::normalize(logsh::vector::cross(d, [0.0, 0.0, 1.0]));
        let toward = logsh::vector::cross(across, d);
        let (s, c) = degrees.to_radians().sin_cos();
        [0, 1, 2].map(|k| c * d[k] + s * toward[k])
    };
    for (name, scene, offset) in [("spheres 64x36", &spheres, 0.0), ("dunes 64x36", &dunes, 0.7)] {
        let mut frame = scene.frame(scene.default_frame()).unwrap();
        frame.suns.push(sun);
        frame.suns.push(logsh::scene::SunLight { direction: turned(offset - 0.4), strength: 0.5, ..sun });
        let by_spheres = support::cpu_beauty(scene, &frame, &within_loop_budget()).unwrap();
        let objects: Vec<synth::Object> = frame
            .blockers
            .iter()
            .map(|s| synth::Object { shape: synth::Shape::Sphere { center: s.center, radius: s.radius }, material: 1 })
            .collect();
        let map = synth::sun_shadow_map(&objects, turned(offset), 256).expect("spheres");
        frame.sun_shadows = vec![std::sync::Arc::new(map)];
        let d = check_parity(gpu, scene, &frame, &within_loop_budget(), &format!("{name} with a sun's shadow map"))
            .unwrap_or_else(|| panic!("{name}: refused"));
        assert!(d.mean.is_finite());
        let by_map = support::cpu_beauty(scene, &frame, &within_loop_budget()).unwrap();
        let unit = unoccluded_value(&frame.light).max(1e-12);
        let apart = difference(&by_map, &by_spheres, unit);
        eprintln!("{name}: the map against the spheres: worst {:.3}, mean {:.2e}", apart.worst, apart.mean);
        assert!(apart.worst > 1e-3, "{name}: the map changed nothing");
    }
}
