//! Whole pixels against closed-form answers on analytic scenes in format v1, shaded
//! through the same reader and kernel as `logsh shade`.

use crate::support;
use logsh::reference::{render_reference, ReferenceOptions};
use logsh::scene::{Scene, Sphere};
use logsh::shade::{ShadedFrame, ShadingSettings};
use logsh::synth::{
    analytic_placements, example_scene, sphere_over_plane, ExampleOptions, GBufferLayout, SphereOverPlane,
};
use std::path::Path;

/// Writes and loads a sphere-over-plane scene; returns the scene, its frame and the
/// closed-form value per pixel (None off the plane or where the formula does not hold).
fn analytic_scene(dir: &Path, spec: &SphereOverPlane) -> (Scene, logsh::scene::Frame, Vec<Option<f64>>) {
    sphere_over_plane(dir, spec).expect("write scene");
    let scene = Scene::load(dir).expect("load scene");
    let frame = scene.frame(1).expect("load frame");
    let expected = spec.expected_image(&frame.gbuffer);
    (scene, frame, expected)
}

/// Mean and max absolute error of the red channel over the pixels with an answer.
fn errors(shaded: &ShadedFrame, expected: &[Option<f64>], scale: f64) -> (f64, f64, usize) {
    let (mut sum, mut max, mut count) = (0.0, 0.0f64, 0);
    for (px, e) in shaded.rgba.iter().zip(expected) {
        if let Some(e) = e {
            let err = (px[0] as f64 - scale * e).abs();
            sum += err;
            max = max.max(err);
            count += 1;
        }
    }
    (sum / count as f64, max, count)
}

/// Bounds on the mean absolute error over sphere-over-plane scenes with default settings
/// (unoccluded value 1): the acceptance bounds, 0.10 at order 4 and 0.06 at order 8, and
/// the same at the neighbouring orders. Measured (`examples/sphere_accuracy.rs`): 0.021,
/// 0.017, 0.025, 0.011, 0.008, 0.007 for orders 3 to 8; `cargo test --test suite
/// shading:: -- --nocapture` prints this test's own figures.
fn mean_error_bound(order: usize) -> f64 {
    if order <= 4 {
        0.10
    } else {
        0.06
    }
}

#[test]
fn sphere_over_plane_meets_the_error_bounds_at_every_order() {
    let dir = tempfile::tempdir().unwrap();
    let scenes: Vec<_> = analytic_placements()
        .into_iter()
        .enumerate()
        .map(|(i, spheres)| {
            let spec = SphereOverPlane { spheres, width: 96, height: 54, ..Default::default() };
            analytic_scene(&dir.path().join(format!("s{i}")), &spec)
        })
        .collect();
    for order in 3..=8 {
        let settings = ShadingSettings::for_order(order);
        let (mut sum, mut count, mut worst) = (0.0, 0, 0.0f64);
        for (scene, frame, expected) in &scenes {
            let shaded = support::cpu_beauty(scene, frame, &settings).unwrap();
            let (mean, max, n) = errors(&shaded, expected, 1.0);
            assert!(n > 500, "too few plane pixels with a closed form: {n}");
            sum += mean * n as f64;
            count += n;
            worst = worst.max(max);
        }
        let mean = sum / count as f64;
        println!("order {order}: eps {}, mean abs error {mean:.4}, max {worst:.4}", settings.epsilon);
        assert!(
            mean <= mean_error_bound(order),
            "order {order}: mean abs error {mean:.4} > {}",
            mean_error_bound(order)
        );
    }
}

#[test]
fn unoccluded_plane_comes_out_as_its_albedo() {
    // No blockers: the answer is the albedo. The band-limited, clamped log lobe misses it
    // by a few percent (docs/design.md measured 1.03 at order 4, eps 0.1). Measured with the
    // defaults: 0.983, 1.026, 1.040, 1.009, 1.013, 1.019 for orders 3 to 8 (this test prints
    // them with --nocapture); the bound is the worst, rounded up.
    let unoccluded_tolerance = |_order: usize| 0.05;
    let dir = tempfile::tempdir().unwrap();
    for layout in [GBufferLayout::Blender5, GBufferLayout::Blender4] {
        let spec = SphereOverPlane { spheres: vec![], width: 32, height: 18, layout, ..Default::default() };
        let path = dir.path().join(format!("{layout:?}"));
        sphere_over_plane(&path, &spec).unwrap();
        // Give the plane a coloured albedo.
        let file = path.join("scene.json");
        let mut json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
        json["materials"]["1"]["albedo"] = serde_json::json!([0.5, 0.25, 1.0]);
        std::fs::write(&file, serde_json::to_string_pretty(&json).unwrap()).unwrap();
        let scene = Scene::load(&path).unwrap();
        let frame = scene.frame(1).unwrap();
        for order in 3..=8 {
            let shaded = support::cpu_beauty(&scene, &frame, &ShadingSettings::for_order(order)).unwrap();
            let plane: Vec<&[f32; 4]> =
                shaded.rgba.iter().zip(&frame.gbuffer.material).filter(|(_, &m)| m == 1).map(|(p, _)| p).collect();
            assert!(!plane.is_empty());
            let unoccluded = plane[0][2] as f64;
            println!("{layout:?} order {order}: unoccluded {unoccluded:.4}");
            assert!(
                (unoccluded - 1.0).abs() <= unoccluded_tolerance(order),
                "order {order}: unoccluded value {unoccluded}"
            );
            for px in plane {
                assert_close!(
                    px[..3],
                    [0.5 * unoccluded, 0.25 * unoccluded, unoccluded],
                    1e-4,
                    "albedo scaling at order {order}"
                );
                assert_eq!(px[3], 1.0);
            }
        }
    }
}

/// A terrain pixel on an incline of slope angle `t`, with its own normal, sees the sky
/// where its tangent plane and the horizontal both let it through (the incline's far
/// continuation lies at the horizon downhill): a cosine-weighted share of `(1 + cos t) / 2`
/// (the reference matches it in `tests/reference.rs`). The kernel is held to that share of
/// the open plane's value, which carries the order's own bias. With the downhill wedge
/// between the tangent plane and the horizontal at full depth, as the bands once started
/// at the horizontal, the default preset read 0.970 and 0.864 of the open plane at 10 and
/// 30 degrees against the exact 0.992 and 0.933; it reads 0.992 and 0.922.
#[test]
fn an_incline_takes_the_share_of_its_tilted_plane() {
    let (_dir, mut scene) = support::open_plane(32, 18);
    scene.materials.insert(20, logsh::scene::Material::Heightfield { albedo: [1.0; 3] });
    let flat = scene.frame(1).unwrap();
    let settings = ShadingSettings::default();
    let open = support::cpu_beauty(&scene, &flat, &settings).unwrap();
    let open_value = open.rgba.iter().zip(&flat.gbuffer.material).find(|(_, &m)| m == 1).map(|(p, _)| p[0]).unwrap();
    for degrees in [10.0f64, 30.0] {
        let slope = degrees.to_radians().tan();
        let (min, max) = ([-200.0, -200.0], [200.0, 200.0]);
        let map = logsh::scene::HeightMap::from_fn(65, 65, min, max, |x, _| slope * x);
        let mut frame = flat.clone();
        let length = (1.0 + slope * slope).sqrt();
        let g = &mut frame.gbuffer;
        let on_plane: Vec<usize> = (0..g.material.len()).filter(|&i| g.material[i] == 1).collect();
        for i in on_plane {
            let [x, y, _] = g.position[i];
            g.position[i] = [x, y, (slope * f64::from(x)) as f32];
            g.normal[i] = [(-slope / length) as f32, 0.0, (1.0 / length) as f32];
            g.material[i] = 20;
        }
        frame.height_map = Some(std::sync::Arc::new(map));
        let shaded = support::cpu_beauty(&scene, &frame, &settings).unwrap();
        let shares: Vec<f64> = shaded
            .rgba
            .iter()
            .zip(&frame.gbuffer.material)
            .filter(|(_, &m)| m == 20)
            .map(|(p, _)| f64::from(p[0] / open_value))
            .collect();
        let mean = shares.iter().sum::<f64>() / shares.len() as f64;
        let exact = (1.0 + degrees.to_radians().cos()) / 2.0;
        println!("incline of {degrees} deg: {} pixels, mean share {mean:.4}, exact {exact:.4}", shares.len());
        assert!(shares.len() > 100 && (mean - exact).abs() <= 0.015, "{degrees} deg: {mean} against {exact}");
    }
}

#[test]
fn f32_and_f64_kernels_agree() {
    // The f32 kernel is what a GPU runs; rounding in sums of a few tens of log vectors and
    // up to six squarings stays below this.
    const PRECISION_TOLERANCE: f64 = 2e-3;
    let dir = tempfile::tempdir().unwrap();
    let spec = SphereOverPlane { spheres: analytic_placements().concat(), width: 48, height: 27, ..Default::default() };
    let (scene, frame, _) = analytic_scene(dir.path(), &spec);
    for order in [3, 4, 8] {
        let mut settings = ShadingSettings::for_order(order);
        let single = support::cpu_beauty(&scene, &frame, &settings).unwrap();
        settings.precision = logsh::shade::Precision::F64;
        let double = support::cpu_beauty(&scene, &frame, &settings).unwrap();
        let a: Vec<f32> = single.rgba.iter().flatten().copied().collect();
        let b: Vec<f32> = double.rgba.iter().flatten().copied().collect();
        assert_close!(a, b, PRECISION_TOLERANCE, "f32 against f64 at order {order}");
    }
}

#[test]
fn receivers_inside_and_touching_blockers_stay_finite() {
    // Spheres cutting through the plane, touching it, and one centred on it: plane pixels
    // inside a blocker see it as a hemisphere; nothing may be NaN or blow up.
    let dir = tempfile::tempdir().unwrap();
    let s = |center: [f64; 3], radius: f64| Sphere::new(center, radius);
    let spec = SphereOverPlane {
        spheres: vec![s([0.0, 0.0, 0.5], 1.0), s([2.5, 0.0, 1.0], 1.0), s([-2.5, 0.0, 0.0], 0.8)],
        width: 64,
        height: 36,
        ..Default::default()
    };
    let (scene, frame, _) = analytic_scene(dir.path(), &spec);
    for order in [3, 8] {
        for epsilon in [1e-6, 0.9] {
            for ratio in [false, true] {
                let mut settings = ShadingSettings::for_order(order);
                settings.epsilon = epsilon;
                settings.ratio_attenuation = ratio;
                let shaded = support::cpu_beauty(&scene, &frame, &settings).unwrap();
                for px in &shaded.rgba {
                    assert!(
                        px.iter().all(|c| c.is_finite() && *c >= 0.0 && *c < 10.0),
                        "order {order}, eps {epsilon}: {px:?}"
                    );
                }
            }
        }
    }
}

#[test]
fn sample_scene_with_height_field_water_and_phong_shades_finite() {
    let dir = tempfile::tempdir().unwrap();
    example_scene("dunes", dir.path(), ExampleOptions { width: 64, height: 36, ..Default::default() }).unwrap();
    let scene = Scene::load(dir.path()).unwrap();
    for number in scene.frame_numbers(usize::MAX) {
        let frame = scene.frame(number).unwrap();
        let shaded = support::cpu_beauty(&scene, &frame, &ShadingSettings::default()).unwrap();
        let mut surface = 0;
        for (px, &m) in shaded.rgba.iter().zip(&frame.gbuffer.material) {
            assert!(px.iter().all(|c| c.is_finite() && *c >= 0.0), "frame {number}: {px:?}");
            assert_eq!(px[3], if m == 0 { 0.0 } else { 1.0 });
            surface += (m != 0) as usize;
        }
        assert!(surface > 0);
    }
}

/// The synthetic dunes (terrain, water, glossy blockers, a sky) at `width` x `height`,
/// written into `dir/name` with colour passes of a checker of 1.5 m cells whose odd cells
/// are `dark` times the table's colours.
fn dunes_scene(dir: &Path, name: &str, width: u32, height: u32, dark: f32) -> Scene {
    let mut scene = logsh::synth::example("dunes", ExampleOptions { width, height, ..Default::default() }).unwrap();
    scene.checker = Some(logsh::synth::Checker { cell: 1.5, dark });
    let out = dir.join(name);
    logsh::synth::write_scene(&out, &scene).unwrap();
    Scene::load(&out).unwrap()
}

/// Each pixel's shade divided by the same pixel's with a uniform texture, where the
/// latter is not dark: the checker's factor (1, 0.2, or 0.04 for water reflecting a dark
/// cell in a dark cell).
fn ratios(textured: &[[f32; 4]], plain: &[[f32; 4]]) -> Vec<f64> {
    let luminance = |c: &[f32; 4]| f64::from(c[0] + c[1] + c[2]);
    textured.iter().zip(plain).filter(|(_, p)| luminance(p) > 1e-3).map(|(t, p)| luminance(t) / luminance(p)).collect()
}

/// Blender's colour passes multiply the light through each lobe per pixel: a checker
/// texture of the table's colours times 1 and 0.2 shades every pixel as a uniform
/// texture of the table's colours does, times its cell's factor (water's tint and its
/// reflected point's colours both), on the fast path and in the reference renderer; so
/// the texture is in the image.
#[test]
fn colour_passes_carry_a_texture_into_the_shade() {
    let dir = tempfile::tempdir().unwrap();
    let plain = dunes_scene(dir.path(), "plain", 48, 27, 1.0);
    let textured = dunes_scene(dir.path(), "textured", 48, 27, 0.2);
    assert!(textured.colour_passes() && plain.colour_passes());
    let settings = ShadingSettings::default();
    let shade = |scene: &Scene| support::cpu_beauty(scene, &scene.frame(1).unwrap(), &settings).unwrap().rgba;
    let factors = ratios(&shade(&textured), &shade(&plain));
    let near = |f: f64, to: f64| (f - to).abs() <= 1e-4 * to.max(0.04);
    let bad: Vec<&f64> = factors.iter().filter(|&&f| !near(f, 1.0) && !near(f, 0.2) && !near(f, 0.04)).collect();
    assert!(
        bad.is_empty(),
        "{} of {} pixels are not the table's times 1, 0.2 or 0.04: {:?}",
        bad.len(),
        factors.len(),
        &bad[..bad.len().min(8)]
    );
    let (light, dark) =
        (factors.iter().filter(|&&f| near(f, 1.0)).count(), factors.iter().filter(|&&f| near(f, 0.2)).count());
    eprintln!("{light} light and {dark} dark pixels of {}", factors.len());
    assert!(light > 200 && dark > 200, "the checker shows: {light} light and {dark} dark pixels");

    let options = ReferenceOptions { tolerance: 2e-2, max_level: 3, ..Default::default() };
    let plain = dunes_scene(dir.path(), "plain small", 16, 9, 1.0);
    let textured = dunes_scene(dir.path(), "textured small", 16, 9, 0.2);
    let reference = |scene: &Scene| render_reference(scene, &scene.frame(1).unwrap(), &options, &|_| {}).unwrap().rgba;
    let factors = ratios(&reference(&textured), &reference(&plain));
    let bad: Vec<&f64> = factors.iter().filter(|&&f| !near(f, 1.0) && !near(f, 0.2) && !near(f, 0.04)).collect();
    assert!(bad.is_empty(), "reference: {} of {} pixels off the checker's factors: {bad:?}", bad.len(), factors.len());
    assert!(factors.iter().filter(|&&f| near(f, 0.2)).count() > 20, "reference: the checker shows");
}

/// `--visibility-grid` (the height field's horizons and the sphere caps computed once per
/// block and interpolated, `src/shade/visibility_grid.rs`) against visibility at every
/// pixel: on the dunes sample (height field, blockers, water, Phong) and on the analytic
/// sphere over a plane, whose closed form it must still meet. Mean differences relative
/// to the open value; no visibility leaks across the sphere's silhouette onto the plane.
#[test]
fn visibility_grid_follows_per_pixel_visibility() {
    let dir = tempfile::tempdir().unwrap();
    example_scene("dunes", dir.path(), ExampleOptions { width: 96, height: 54, ..Default::default() }).unwrap();
    let scene = Scene::load(dir.path()).unwrap();
    let frame = scene.frame(1).unwrap();
    let per_pixel = support::cpu_beauty(&scene, &frame, &ShadingSettings::default()).unwrap();
    let open = logsh::compare::unoccluded_value(&frame).expect("a map");
    let unit = (open[0] + open[1] + open[2]) / 3.0;
    for (grid, bound) in [(2, 0.004), (4, 0.01)] {
        let settings = ShadingSettings { visibility_grid: grid, ..ShadingSettings::default() };
        let gridded = support::cpu_beauty(&scene, &frame, &settings).unwrap();
        let (mut sum, mut count) = (0.0, 0usize);
        for ((a, b), &m) in gridded.rgba.iter().zip(&per_pixel.rgba).zip(&frame.gbuffer.material) {
            assert!(a.iter().all(|v| v.is_finite()), "grid {grid}: a pixel is not finite");
            if m != 0 {
                sum += (0..3).map(|c| f64::from((a[c] - b[c]).abs())).sum::<f64>() / 3.0;
                count += 1;
            }
        }
        let mean = sum / count as f64 / unit;
        println!("dunes, visibility grid {grid}: mean difference from every pixel {mean:.2e} of the open value");
        assert!(mean <= bound, "grid {grid}: mean difference {mean}");
    }

    let spec = SphereOverPlane {
        spheres: vec![Sphere::new([0.0, 0.0, 1.2], 1.0)],
        width: 96,
        height: 54,
        ..Default::default()
    };
    let (scene, frame, expected) = analytic_scene(dir.path().join("spheres").as_path(), &spec);
    let per_pixel = errors(&support::cpu_beauty(&scene, &frame, &ShadingSettings::default()).unwrap(), &expected, 1.0);
    for grid in [2, 4] {
        let settings = ShadingSettings { visibility_grid: grid, ..ShadingSettings::default() };
        let (mean, max, count) = errors(&support::cpu_beauty(&scene, &frame, &settings).unwrap(), &expected, 1.0);
        println!("sphere over plane, grid {grid}: mean {mean:.4} max {max:.4} over {count} pixels (every pixel: {:.4} {:.4})", per_pixel.0, per_pixel.1);
        // The mean stays; the largest error grows where the contact shadow under the
        // sphere changes fastest, a block's visibility standing for its neighbours'
        // (measured: 0.097 at grid 2 and 0.18 at grid 4, against 0.039 at every pixel).
        let most = if grid == 2 { 0.15 } else { 0.25 };
        assert!(mean <= per_pixel.0 + 0.002 && max <= most, "grid {grid}: mean {mean}, max {max}");
    }
}
