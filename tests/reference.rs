//! The ground-truth renderer against closed forms: sphere-over-plane shadows, an
//! unoccluded plane, height-field horizons of a wall and a V valley, and an
//! environment-map scene in both light modes.
//!
//! `cargo test --test suite reference:: -- --nocapture` prints the measured figures.

use crate::support;
use logsh::heightfield::HeightField;
use logsh::logsh::Lobe;
use logsh::reference::{
    integrate_point, render_reference, sample_point, Integration, LightModel, LobeTerm, ReferenceError, ReferenceFrame,
    ReferenceLight, ReferenceOccluders, ReferenceOptions, TexelSampler,
};
use logsh::scene::{EnvironmentMap, Light, Material, Scene, Sphere};
use logsh::shade::ShadeError;
use logsh::synth::{
    analytic_placements, example_scene, sphere_over_plane, ExampleOptions, SphereOverPlane, PLANE_MATERIAL,
    SPHERE_MATERIAL,
};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

fn options(tolerance: f64, max_level: u32) -> ReferenceOptions {
    ReferenceOptions {
        light: ReferenceLight::EnvironmentMap,
        integration: Integration::Auto,
        tolerance,
        max_level,
        ..Default::default()
    }
}

fn render(scene: &Scene, frame: &logsh::scene::Frame, options: &ReferenceOptions) -> ReferenceFrame {
    let rows = AtomicUsize::new(0);
    let last = AtomicUsize::new(0);
    let out = render_reference(scene, frame, options, &|done| {
        rows.fetch_add(1, Ordering::Relaxed);
        last.fetch_max(done, Ordering::Relaxed);
    })
    .expect("reference renders");
    assert_eq!(rows.load(Ordering::Relaxed), frame.gbuffer.height, "one progress call per row");
    assert_eq!(last.load(Ordering::Relaxed), frame.gbuffer.height, "progress reaches the row count");
    assert!(out.rgba.iter().all(|p| p.iter().all(|v| v.is_finite())), "non-finite pixel");
    out
}

#[test]
fn sphere_over_plane_matches_the_closed_form() {
    let dir = tempfile::tempdir().unwrap();
    let (mut sum, mut count, mut worst) = (0.0, 0usize, 0.0f64);
    let start = Instant::now();
    let mut pixels = 0;
    for (i, spheres) in analytic_placements().into_iter().enumerate() {
        let spec = SphereOverPlane { spheres, width: 48, height: 27, ..Default::default() };
        let path = dir.path().join(format!("s{i}"));
        sphere_over_plane(&path, &spec).unwrap();
        let scene = Scene::load(&path).unwrap();
        let frame = scene.frame(1).unwrap();
        let expected = spec.expected_image(&frame.gbuffer);
        let out = render(&scene, &frame, &options(1e-3, 8));
        pixels += out.width * out.height;
        let (mut s, mut n, mut w) = (0.0, 0usize, 0.0f64);
        for (px, e) in out.rgba.iter().zip(&expected) {
            if let Some(e) = e {
                let err = (px[0] as f64 - e).abs();
                s += err;
                n += 1;
                w = w.max(err);
            }
        }
        println!(
            "placement {i}: {n} plane pixels, mean abs error {:.2e}, max {:.2e}; unconverged {}, max estimate {:.2e}",
            s / n as f64,
            w,
            out.unconverged_pixels,
            out.max_estimated_error
        );
        assert!(n > 300, "too few plane pixels with a closed form: {n}");
        sum += s;
        count += n;
        worst = worst.max(w);
    }
    let mean = sum / count as f64;
    let elapsed = start.elapsed().as_secs_f64();
    println!(
        "sphere over plane: mean abs error {mean:.2e}, max {worst:.2e} over {count} pixels; {:.1} ms per pixel (wall, all cores)",
        1e3 * elapsed / pixels as f64
    );
    assert!(mean <= 0.01, "mean abs error {mean}");
    assert!(worst <= 0.01, "max abs error {worst}");
}

#[test]
fn unoccluded_plane_is_its_albedo() {
    let (_dir, scene) = support::open_plane(24, 14);
    let frame = scene.frame(1).unwrap();
    let out = render(&scene, &frame, &options(1e-4, 6));
    let mut worst = 0.0f64;
    let mut n = 0;
    for (px, &m) in out.rgba.iter().zip(&frame.gbuffer.material) {
        if m == PLANE_MATERIAL {
            n += 1;
            for c in &px[..3] {
                worst = worst.max((*c as f64 - 1.0).abs());
            }
            assert_eq!(px[3], 1.0);
        } else {
            assert_eq!(m, 0);
            assert_eq!(px[3], 0.0, "background alpha");
            assert_eq!(px[..3], [1.0, 1.0, 1.0], "background is the constant light");
        }
    }
    println!("unoccluded plane: {n} pixels, max |value - 1| {worst:.2e}");
    assert!(n > 100);
    assert!(worst <= 1e-3, "unoccluded plane off by {worst}");
}

/// A glossy plane under a constant white light, nothing in the way: the reference's
/// GGX lobe (the default `--glossy ggx`) integrates to the albedo the kernel's split sum
/// is scaled by (`albedo_table`, GGX's albedo over `n . v`, 33 entries), for a rough and a
/// sharper lobe. Measured: 1.4e-4 and 2.1e-3 of the albedo on average, 6.6e-4 and 2.5e-3
/// at worst.
#[test]
fn an_unoccluded_ggx_plane_reflects_its_albedo() {
    use logsh::shade::glossy::{albedo_lookup, albedo_table, ggx_alpha, SharpLobe};
    let (_dir, mut scene) = support::open_plane(32, 18);
    for exponent in [2.0f32, 40.0] {
        scene.materials.insert(PLANE_MATERIAL, Material::Phong { albedo: [0.0; 3], specular: [1.0; 3], exponent });
        let frame = scene.frame(1).unwrap();
        let out = render(&scene, &frame, &options(1e-4, 8));
        let table = albedo_table(SharpLobe::Ggx { alpha: ggx_alpha(f64::from(exponent)) });
        let (mut sum, mut worst, mut pixels) = (0.0, 0.0f64, 0usize);
        for (i, &m) in frame.gbuffer.material.iter().enumerate() {
            if m != PLANE_MATERIAL {
                continue;
            }
            let point = logsh::shade::frame::surface_at(&frame.gbuffer, i, None, &frame);
            let to_eye = [0, 1, 2].map(|k| point.view_origin[k] - point.position[k]);
            let n_v = to_eye[2] / to_eye.iter().map(|c| c * c).sum::<f64>().sqrt();
            let expected = albedo_lookup(&table, n_v);
            let error = (f64::from(out.rgba[i][0]) - expected).abs() / expected;
            sum += error;
            worst = worst.max(error);
            pixels += 1;
        }
        let mean = sum / pixels as f64;
        println!("GGX plane, exponent {exponent}: {pixels} pixels, mean {mean:.1e}, worst {worst:.1e} of the albedo");
        assert!(pixels > 100 && mean <= 3e-3 && worst <= 1e-2, "exponent {exponent}: mean {mean}, worst {worst}");
    }
}

/// A flat height field with a raised region, and the diffuse integral at a point:
/// `fraction(field, p)` = integral of V max(z, 0)/pi under constant white light.
fn diffuse_fraction(field: &HeightField, spheres: &[Sphere], p: [f64; 3], n: [f64; 3]) -> (f64, f64) {
    let light = Light::Constant([1.0; 3]);
    let model = LightModel::new(&light, &ReferenceLight::EnvironmentMap).unwrap();
    let term = LobeTerm { lobe: Lobe::Diffuse, axis: n, scale: [1.0; 3], ggx: None };
    let occ = ReferenceOccluders { spheres, field: Some(field), receiver_object: 0, ground: None };
    let e = integrate_point(occ, &model, p, n, &[term], 1e-4, 10);
    assert!(e.converged, "did not converge: {e:?}");
    (e.rgb[0], e.error)
}

fn field_from(columns: usize, rows: usize, min: [f64; 2], max: [f64; 2], f: impl Fn(f64, f64) -> f64) -> HeightField {
    let map = logsh::scene::HeightMap::from_fn(columns, rows, min, max, f);
    HeightField::new(map.heights, columns, rows, min, max).unwrap()
}

#[test]
fn height_field_wall_and_valley_match_closed_forms() {
    // A wall along +x: heights 0 for x <= 1, ramping over one cell to H at x = 1.25, H
    // beyond (the flat continuation makes it infinite in y and beyond the map in x). Its
    // top edge, at distance D = 1.25, is the horizon: tan(sigma) = (H - z) cos(phi) / D
    // for cos(phi) > 0, 0 elsewhere. Cosine-weighted unoccluded fraction:
    // 1 - (1/2pi) int sin^2(sigma) dphi = 1/2 + 1/(2 sqrt(1 + k^2)), k = (H - z)/D.
    let h = 2.0;
    let wall = field_from(65, 9, [-8.0, -8.0], [8.0, 8.0], |x, _| if x > 1.1 { h } else { 0.0 });
    let distance = 1.25;
    let cases =
        [("foot of the wall", 0.0), ("cast shadow, 0.5 above the ground", 0.5), ("cast shadow, 1.5 above", 1.5)];
    for (what, z) in cases {
        let k: f64 = (h - z) / distance;
        let expected = 0.5 + 0.5 / (1.0 + k * k).sqrt();
        let (got, estimate) = diffuse_fraction(&wall, &[], [0.0, 0.0, z], [0.0, 0.0, 1.0]);
        println!(
            "wall, {what}: reference {got:.6}, closed form {expected:.6}, error {:.1e} (estimate {estimate:.1e})",
            (got - expected).abs()
        );
        assert!((got - expected).abs() <= 0.01, "{what}: {got} vs {expected}");
    }

    // A V valley h = |x| tan(beta): from the bottom every azimuth sees the slope itself,
    // tan(sigma) = tan(beta) |cos(phi)|, and the fraction is cos(beta).
    for beta_deg in [20.0f64, 45.0, 60.0] {
        let t = beta_deg.to_radians().tan();
        let valley = field_from(33, 5, [-4.0, -4.0], [4.0, 4.0], |x, _| x.abs() * t);
        let expected = beta_deg.to_radians().cos();
        let (got, estimate) = diffuse_fraction(&valley, &[], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
        println!("V valley, beta {beta_deg}: reference {got:.6}, closed form {expected:.6}, error {:.1e} (estimate {estimate:.1e})", (got - expected).abs());
        assert!((got - expected).abs() <= 0.01, "valley {beta_deg}: {got} vs {expected}");
    }

    // A terrain pixel on an incline h = s x, with the surface's own normal: the surface
    // must not shadow its own point. Uphill the horizon is the incline itself (the far
    // edge continues flat at the same elevation); downhill the flat continuation far
    // below gives horizon 0. So V = [n.w > 0][w_z > 0] and the cosine-weighted fraction
    // is that of a plane tilted by t = atan(s) under the upper hemisphere, (1 + cos t)/2.
    for slope in [0.3f64, 1.0] {
        let incline = field_from(41, 41, [-100.0, -100.0], [100.0, 100.0], |x, _| slope * x);
        let l = (1.0 + slope * slope).sqrt();
        let n = [-slope / l, 0.0, 1.0 / l];
        let expected = 0.5 * (1.0 + 1.0 / l);
        let (got, estimate) = diffuse_fraction(&incline, &[], [0.3, 0.7, slope * 0.3], n);
        println!(
            "incline {slope}: reference {got:.6}, closed form {expected:.6}, error {:.1e} (estimate {estimate:.1e})",
            (got - expected).abs()
        );
        assert!((got - expected).abs() <= 0.01, "incline {slope}: {got} vs {expected}");
    }
}

#[test]
fn receivers_on_and_inside_spheres() {
    let light = Light::Constant([1.0; 3]);
    let model = LightModel::new(&light, &ReferenceLight::EnvironmentMap).unwrap();
    let sphere = Sphere::new([0.0, 0.0, 2.0], 1.0);
    let occ =
        ReferenceOccluders { spheres: std::slice::from_ref(&sphere), field: None, receiver_object: 0, ground: None };
    let term = |n: [f64; 3]| [LobeTerm { lobe: Lobe::Diffuse, axis: n, scale: [1.0; 3], ggx: None }];
    // The top of the sphere, its own normal, rounded slightly inside: unshadowed.
    let top = [0.0, 0.0, 3.0 - 1e-7];
    let e = integrate_point(occ, &model, top, [0.0, 0.0, 1.0], &term([0.0, 0.0, 1.0]), 1e-5, 8);
    assert!((e.rgb[0] - 1.0).abs() < 1e-5, "sphere top self-shadows: {e:?}");
    // Its side, normal along +x: the sphere is exactly its own tangent plane.
    let side = [1.0, 0.0, 2.0];
    let e = integrate_point(occ, &model, side, [1.0, 0.0, 0.0], &term([1.0, 0.0, 0.0]), 1e-5, 8);
    assert!((e.rgb[0] - 1.0).abs() < 1e-5, "sphere side self-shadows: {e:?}");
    // Inside: black.
    let e = integrate_point(occ, &model, [0.0, 0.0, 2.2], [0.0, 0.0, 1.0], &term([0.0, 0.0, 1.0]), 1e-5, 8);
    assert_eq!(e.rgb, [0.0; 3]);
}

#[test]
fn dunes_render_in_both_light_modes() {
    let dir = tempfile::tempdir().unwrap();
    example_scene("dunes", dir.path(), ExampleOptions { width: 32, height: 18, ..Default::default() }).unwrap();
    let scene = Scene::load(dir.path()).unwrap();
    let frame = scene.frame(1).unwrap();
    let start = Instant::now();
    let full = render(&scene, &frame, &options(1e-2, 3));
    let t_full = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let sh = render(
        &scene,
        &frame,
        &ReferenceOptions { light: ReferenceLight::ShProjected { order: 8 }, ..options(1e-2, 3) },
    );
    let t_sh = start.elapsed().as_secs_f64();
    let (mut sum, mut n, mut worst, mut mean_value) = (0.0, 0usize, 0.0f64, 0.0);
    for ((a, b), &m) in full.rgba.iter().zip(&sh.rgba).zip(&frame.gbuffer.material) {
        if m != 0 {
            for c in 0..3 {
                let d = (a[c] - b[c]).abs() as f64;
                sum += d;
                worst = worst.max(d);
                mean_value += a[c] as f64;
            }
            n += 3;
        }
    }
    println!(
        "dunes 32x18: map {t_full:.1} s (unconverged {}, max estimate {:.2e}), SH-8 {t_sh:.1} s (unconverged {}, max estimate {:.2e})",
        full.unconverged_pixels, full.max_estimated_error, sh.unconverged_pixels, sh.max_estimated_error
    );
    println!(
        "dunes: |map - SH8| over surface pixels: mean {:.3e}, max {:.3e} (mean surface value {:.3})",
        sum / n as f64,
        worst,
        mean_value / n as f64
    );
    assert!(n > 0);
}

#[test]
fn sh_light_matches_eval_expansion() {
    let order = 8;
    let coefficients: Vec<[f64; 3]> = (0..order * order)
        .map(|i| [0.5 / (1.0 + i as f64), ((i * 7) % 5) as f64 - 2.0, (i as f64 * 0.37).sin()])
        .collect();
    let light = Light::Sh(coefficients.clone());
    let model = LightModel::new(&light, &ReferenceLight::EnvironmentMap).unwrap();
    for d in [[0.0f64, 0.0, 1.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.3, -0.5, 0.812404], [-0.7, 0.2, -0.685565]] {
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let d = [d[0] / l, d[1] / l, d[2] / l];
        let got = model.radiance(d);
        for k in 0..3 {
            let c: Vec<f64> = coefficients.iter().map(|c| c[k]).collect();
            let want = logsh::sh::eval_expansion(order, &c, d);
            assert!((got[k] - want).abs() <= 1e-12 * (1.0 + want.abs()), "{d:?} channel {k}: {} vs {want}", got[k]);
        }
    }
}

#[test]
fn errors_name_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let spec = SphereOverPlane { width: 8, height: 6, ..Default::default() };
    sphere_over_plane(dir.path(), &spec).unwrap();
    let scene = Scene::load(dir.path()).unwrap();
    let frame = scene.frame(1).unwrap();
    for bad in [options(0.0, 4), options(f64::NAN, 4), options(1e-3, 1)] {
        let e = render_reference(&scene, &frame, &bad, &|_| {}).unwrap_err();
        assert!(matches!(e, ReferenceError::Options(_)), "{e}");
        println!("{e}");
    }
    let bad = ReferenceOptions { light: ReferenceLight::ShProjected { order: 0 }, ..options(1e-3, 3) };
    assert!(render_reference(&scene, &frame, &bad, &|_| {}).is_err());
    // Water without a reflection G-buffer (the loader refuses that file, so edit the
    // loaded scene), and phong without a camera.
    let mut water = scene.clone();
    water.materials.insert(PLANE_MATERIAL, Material::Water { tint: [1.0; 3] });
    let e = render_reference(&water, &frame, &options(1e-3, 3), &|_| {}).unwrap_err();
    println!("{e}");
    assert!(matches!(e, ReferenceError::Frame(ShadeError::WaterWithoutReflection { .. })), "{e}");
    assert!(e.to_string().contains("reflection_gbuffer"));
    let mut phong = scene.clone();
    phong.materials.insert(PLANE_MATERIAL, Material::Phong { albedo: [0.5; 3], specular: [0.5; 3], exponent: 8.0 });
    let mut no_camera = frame.clone();
    no_camera.camera = None;
    let e = render_reference(&phong, &no_camera, &options(1e-3, 3), &|_| {}).unwrap_err();
    println!("{e}");
    assert!(matches!(e, ReferenceError::Frame(ShadeError::PhongWithoutCamera { material: PLANE_MATERIAL, .. })), "{e}");
}

/// A 64 x 32 sky with a dim gradient, a bright warm patch 20 degrees up and a small very
/// bright spot (the kind of feature importance sampling must find).
fn patchy_sky() -> Light {
    patchy_sky_of(64, 32)
}

/// [`patchy_sky`] at another resolution (a multiple of 64 x 32): the same patch, the spot
/// one texel.
fn patchy_sky_of(width: usize, height: usize) -> Light {
    let k = width / 64;
    let texels = (0..width * height)
        .map(|i| {
            let (c, r) = (i % width, i / width);
            let sky = 0.2 + 0.6 * (1.0 - r as f32 / height as f32);
            if (10 * k..14 * k).contains(&r) && (20 * k..28 * k).contains(&c) {
                [6.0, 4.0, 2.0]
            } else if r == 6 * k && c == 45 * k {
                [200.0, 200.0, 180.0]
            } else {
                [sky * 0.8, sky * 0.9, sky]
            }
        })
        .collect();
    Light::Environment { map: EnvironmentMap { file: "patchy.exr".into(), width, height, texels }, strength: 1.0 }
}

/// Importance sampling against the deterministic meridians on the same points: a map
/// with a bright patch and spot, two spheres (one half over the patch), a diffuse and a
/// Phong lobe, with and without a height field. The sampled value must lie within three
/// of its own error estimates (plus the meridians' tolerance) of the meridians' value,
/// and its estimate must be honest (not above 3e-3 at this sample budget).
#[test]
fn sampled_matches_meridians_under_a_map() {
    let light = patchy_sky();
    let model = LightModel::new(&light, &ReferenceLight::EnvironmentMap).unwrap();
    let sampler = TexelSampler::of(&model).expect("a lit map has a sampler");
    let spheres = [Sphere::new([0.8, -0.3, 0.9], 0.5), Sphere::new([-1.5, 1.0, 0.4], 0.4)];
    let field =
        field_from(33, 33, [-4.0, -4.0], [4.0, 4.0], |x, y| (if x > 2.0 { 0.8 * (x - 2.0) } else { 0.0 }) + 0.05 * y);
    let p = [0.0, 0.0, 0.0];
    let n = [0.1f64, -0.2, 0.97];
    let view_reflected = [0.35f64, 0.1, 0.93];
    let terms = [
        LobeTerm { lobe: Lobe::Diffuse, axis: n, scale: [0.8, 0.7, 0.6], ggx: None },
        LobeTerm { lobe: Lobe::Phong { exponent: 40.0 }, axis: view_reflected, scale: [0.3, 0.3, 0.3], ggx: None },
    ];
    for (what, field) in [("spheres", None), ("spheres and terrain", Some(&field))] {
        let occ = ReferenceOccluders { spheres: &spheres, field, receiver_object: 0, ground: None };
        let lifted = [p[0], p[1], field.map_or(0.0, |f| f.height_at(0.0, 0.0)) + 1e-9];
        let start = Instant::now();
        let exact = integrate_point(occ, &model, lifted, n, &terms, 1e-4, 8);
        let t_exact = start.elapsed().as_secs_f64();
        let start = Instant::now();
        let sampled = sample_point(occ, &model, Some(&sampler), lifted, n, &terms, 1e-3, 8, 7);
        let t_sampled = start.elapsed().as_secs_f64();
        let worst = (0..3).map(|k| (sampled.rgb[k] - exact.rgb[k]).abs()).fold(0.0, f64::max);
        println!(
            "{what}: meridians {:?} ({t_exact:.2} s, {} evaluations), sampled {:?} +- {:.1e} ({t_sampled:.2} s, {} samples), |diff| {worst:.1e}",
            exact.rgb, exact.evaluations, sampled.rgb, sampled.error, sampled.evaluations
        );
        assert!(exact.converged, "{what}: meridians did not converge: {exact:?}");
        assert!(sampled.error <= 3e-3, "{what}: sampled error estimate {}", sampled.error);
        assert!(worst <= 3.0 * sampled.error + 1e-4, "{what}: sampled off by {worst}, estimate {}", sampled.error);
    }
}

/// The sampled integration on the analytic sphere-over-plane frames against the closed
/// form: unbiased (mean signed error within noise) and within its estimates.
#[test]
fn sampled_sphere_over_plane_matches_the_closed_form() {
    let dir = tempfile::tempdir().unwrap();
    let spheres = analytic_placements().into_iter().nth(1).unwrap();
    let spec = SphereOverPlane { spheres, width: 32, height: 18, ..Default::default() };
    sphere_over_plane(dir.path(), &spec).unwrap();
    let scene = Scene::load(dir.path()).unwrap();
    let frame = scene.frame(1).unwrap();
    let expected = spec.expected_image(&frame.gbuffer);
    let sampled = ReferenceOptions { integration: Integration::Sampled, ..options(2e-3, 7) };
    let out = render(&scene, &frame, &sampled);
    assert_eq!(out.integration, Integration::Sampled);
    let (mut signed, mut abs, mut n, mut outside) = (0.0, 0.0, 0usize, 0usize);
    for ((px, e), &estimate) in out.rgba.iter().zip(&expected).zip(&out.estimated_error) {
        if let Some(e) = e {
            let d = px[0] as f64 - e;
            signed += d;
            abs += d.abs();
            n += 1;
            outside += usize::from(d.abs() > 2.0 * estimate as f64 + 1e-6);
        }
    }
    println!(
        "sampled sphere over plane: {n} pixels, mean signed {:.1e}, mean abs {:.1e}, {outside} beyond twice their estimate, {} unconverged",
        signed / n as f64,
        abs / n as f64,
        out.unconverged_pixels
    );
    assert!(n > 200);
    assert!((signed / n as f64).abs() <= 1e-4, "biased: mean signed {}", signed / n as f64);
    assert!(abs / n as f64 <= 1.5e-3, "mean abs {}", abs / n as f64);
    // Two standard errors cover about 95 % of pixels; allow for the estimate's own noise.
    assert!(outside * 10 <= n, "{outside} of {n} pixels beyond twice their estimate");
}

/// A ground plane hides the lower hemisphere from a receiver above it: facing sideways
/// under a constant white light, a diffuse receiver gets exactly half its open value; a
/// point on the ground itself is left to its tangent plane.
#[test]
fn ground_plane_hides_the_lower_hemisphere() {
    let light = Light::Constant([1.0; 3]);
    let model = LightModel::new(&light, &ReferenceLight::EnvironmentMap).unwrap();
    let occ = ReferenceOccluders { spheres: &[], field: None, receiver_object: 0, ground: Some(0.0) };
    let side = [1.0, 0.0, 0.0];
    let term = [LobeTerm { lobe: Lobe::Diffuse, axis: side, scale: [1.0; 3], ggx: None }];
    let by_meridians = integrate_point(occ, &model, [0.0, 0.0, 1.0], side, &term, 1e-5, 8);
    assert!((by_meridians.rgb[0] - 0.5).abs() < 1e-4, "{by_meridians:?}");
    let sampled = sample_point(occ, &model, None, [0.0, 0.0, 1.0], side, &term, 1e-3, 8, 3);
    assert!((sampled.rgb[0] - 0.5).abs() < 3e-3, "{sampled:?}");
    let up = [LobeTerm { lobe: Lobe::Diffuse, axis: [0.0, 0.0, 1.0], scale: [1.0; 3], ggx: None }];
    let on_ground = integrate_point(occ, &model, [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], &up, 1e-5, 8);
    assert!((on_ground.rgb[0] - 1.0).abs() < 1e-4, "{on_ground:?}");
}

/// The prefiltered glossy term and its log-SH specular occlusion (`--glossy phong`,
/// src/shade/glossy.rs) against the reference's exact integral of the same Phong lobe
/// (the reference's `--glossy phong`),
/// cut by the tangent plane, on a mirror-like plane (exponent 300) reflecting a sphere
/// and a patchy sky. Measured, in units of the unoccluded white floor: 0.003 on average
/// (the sphere's reflection black where the truth is, by the cone test of the lobe's
/// core; log-SH's occlusion alone left it at 0.4 and the frame at 0.07), against 0.62 for
/// the lobe in log-SH, which order 4 blurs into a dull blob.
#[test]
fn prefiltered_glossy_and_its_occlusion_match_the_reference() {
    use logsh::shade::{GlossyMethod, ShadingSettings};
    let dir = tempfile::tempdir().unwrap();
    let spec = SphereOverPlane {
        spheres: vec![Sphere::new([0.0, 1.0, 1.2], 1.0)],
        width: 64,
        height: 36,
        camera_position: [0.0, -8.0, 4.0],
        ..Default::default()
    };
    sphere_over_plane(dir.path(), &spec).unwrap();
    let mut scene = Scene::load(dir.path()).unwrap();
    scene.materials.insert(PLANE_MATERIAL, Material::Phong { albedo: [0.0; 3], specular: [1.0; 3], exponent: 300.0 });
    let mut frame = scene.frame(1).unwrap();
    frame.light = std::sync::Arc::new(patchy_sky_of(256, 128));
    let truth = render(&scene, &frame, &ReferenceOptions { glossy: GlossyMethod::Phong, ..options(2e-3, 7) });
    let unit = {
        let Light::Environment { map, .. } = frame.light.as_ref() else { unreachable!() };
        let mut sum = 0.0;
        for row in 0..map.height / 2 {
            let z = (std::f64::consts::PI * (row as f64 + 0.5) / map.height as f64).cos();
            let omega = map.texel_solid_angle(row);
            sum += (0..map.width).map(|c| f64::from(map.texels[row * map.width + c][1]) * z * omega).sum::<f64>();
        }
        sum / std::f64::consts::PI
    };
    let error = |glossy: GlossyMethod| {
        let settings = ShadingSettings { glossy, ..ShadingSettings::default() };
        let shaded = support::cpu_beauty(&scene, &frame, &settings).unwrap();
        let (mut sum, mut n) = (0.0, 0usize);
        for (i, &m) in frame.gbuffer.material.iter().enumerate() {
            if m == PLANE_MATERIAL {
                sum += (0..3).map(|k| (shaded.rgba[i][k] - truth.rgba[i][k]).abs() as f64).sum::<f64>() / 3.0;
                n += 1;
            }
        }
        sum / n as f64 / unit
    };
    let (prefiltered, in_sh) = (error(GlossyMethod::Phong), error(GlossyMethod::Sh));
    println!("glossy plane against the reference: prefiltered {prefiltered:.4}, log-SH lobe {in_sh:.4}");
    assert!(prefiltered < 0.01, "prefiltered glossy off by {prefiltered}");
    assert!(in_sh > 0.3, "the log-SH lobe was expected to blur: {in_sh}");
}

/// Bounce light of a sphere over a bright plane (the ground plane at the plane's height,
/// a white sky): logsh's one bounce (the surroundings shaded, then gathered:
/// `logsh::shade::bounce`) against the reference's paths over the same proxies
/// (`logsh reference --bounces 1`), pixel by pixel: the plane lit by the sphere around
/// its shadow, the sphere's underside lit by the plane. `-- --nocapture` prints the
/// figures.
#[test]
fn a_sphere_over_a_bright_plane_bounces_as_the_reference_does() {
    let (truth, ours, abs) = bounce_of_a_sphere_over_a_plane(&[], 256, |_| true);
    assert!(truth > 0.01, "the reference's bounce is there: {truth}");
    assert!((ours - truth).abs() <= 0.1 * truth, "mean bounce {ours} against {truth}");
    assert!(abs <= 0.25 * truth, "mean abs difference {abs} against a mean bounce of {truth}");
}

/// The same with a mirror metal sphere (albedo 0, specular 0.9): the plane around it is
/// lit by the sky the sphere mirrors, which the fast path takes as the mirror ball's
/// mean (`SphereLight` in `logsh::shade::bounce`) and the reference traces exactly
/// along each mirrored ray. Over the plane's pixels; 1024 paths per receiver, since few
/// of them meet the sphere (the mean absolute difference was 0.0047 at 256 and 0.0032 at
/// 1024: much of it is the reference's own noise).
#[test]
fn a_mirror_sphere_over_a_bright_plane_bounces_as_the_reference_does() {
    let mirror = Material::Phong { albedo: [0.0; 3], specular: [0.9; 3], exponent: 2000.0 };
    let (truth, ours, abs) =
        bounce_of_a_sphere_over_a_plane(&[(SPHERE_MATERIAL, mirror.clone())], 1024, |m| m == PLANE_MATERIAL);
    assert!(truth > 0.01, "the reference's bounce is there: {truth}");
    assert!((ours - truth).abs() <= 0.1 * truth, "mean bounce {ours} against {truth}");
    assert!(abs <= 0.3 * truth, "mean abs difference {abs} against a mean bounce of {truth}");
    // The plane (white) without blue: no material of the table has an albedo in every
    // channel, so the sphere's points are shaded with a white material of their own
    // (`PointMaterial` in `logsh::shade::bounce`), not with the plane's; the green
    // bounce is the same.
    let plane = Material::Diffuse { albedo: [1.0, 1.0, 0.0] };
    let (_, without_blue, _) =
        bounce_of_a_sphere_over_a_plane(&[(SPHERE_MATERIAL, mirror), (PLANE_MATERIAL, plane)], 16, |m| {
            m == PLANE_MATERIAL
        });
    assert!((without_blue - ours).abs() <= 1e-4 * ours, "{without_blue} against {ours}");
}

/// One bounce of the sphere-over-plane scene, with `materials` in place of the scene's
/// and the sphere its own object, the reference's paths `bounce_samples` per receiver:
/// the reference's mean bounce, logsh's, and their mean absolute difference, green
/// channel, over the pixels whose material `counted` accepts.
fn bounce_of_a_sphere_over_a_plane(
    materials: &[(u32, Material)],
    bounce_samples: usize,
    counted: impl Fn(u32) -> bool,
) -> (f64, f64, f64) {
    use logsh::executor::Executor;
    use logsh::shade::bounce::BounceSettings;
    use logsh::shade::ShadingSettings;
    let dir = tempfile::tempdir().unwrap();
    let spec = SphereOverPlane { width: 32, height: 18, ..SphereOverPlane::default() };
    sphere_over_plane(dir.path(), &spec).unwrap();
    let mut scene = Scene::load(dir.path()).unwrap();
    scene.ground = Some(0.0);
    scene.materials.extend(materials.iter().cloned());
    let mut frame = scene.frame(1).unwrap();
    frame.ground = Some(0.0);
    // The sphere is object 1, so that its pixels give the blocker its reflectances.
    frame.blockers.iter_mut().for_each(|b| b.object = 1);
    frame.gbuffer.object = Some(frame.gbuffer.material.iter().map(|&m| u32::from(m == SPHERE_MATERIAL)).collect());
    let started = Instant::now();
    let direct = render(&scene, &frame, &options(1e-3, 6));
    let traced = render(&scene, &frame, &ReferenceOptions { bounces: 1, bounce_samples, ..options(1e-3, 6) });
    println!("reference with one bounce: {:.1} s", started.elapsed().as_secs_f64());
    let bounce = BounceSettings { bounces: 1, stride: 1, ..BounceSettings::DEFAULT };
    let settings = ShadingSettings { bounce, ..Default::default() };
    let passes = support::rendered_passes(&Executor::cpu(), &scene, &frame, &settings).unwrap();
    let g = &frame.gbuffer;
    let (mut truth, mut ours, mut abs, mut count) = (0.0, 0.0, 0.0, 0usize);
    let mut worst = (0.0f64, 0usize);
    for i in (0..g.material.len()).filter(|&i| g.material[i] != 0 && counted(g.material[i])) {
        let reference = f64::from(traced.rgba[i][1] - direct.rgba[i][1]);
        let logsh = f64::from(passes.indirect[i][1]);
        let d = (logsh - reference).abs();
        (truth, ours, abs, count) = (truth + reference, ours + logsh, abs + d, count + 1);
        if d > worst.0 {
            worst = (d, i);
        }
    }
    let n = count as f64;
    println!(
        "bounce over {count} pixels: reference mean {:.4}, logsh mean {:.4}, mean abs difference {:.4}, worst {:.4} at pixel {}",
        truth / n,
        ours / n,
        abs / n,
        worst.0,
        worst.1
    );
    (truth / n, ours / n, abs / n)
}

/// The caps' hidden detail (docs/method/materials.md, "The detail a cap hides") takes
/// the light's bands beyond the order that the spheres hide, so a frame of spheres under
/// a sky with structure comes nearer the reference's exact visibility of the same
/// proxies. Measured on the dunes at 48x27, mean absolute over surface pixels and R, G, B:
/// 0.0158 with it, 0.0173 without.
#[test]
fn the_caps_hidden_detail_brings_a_frame_nearer_the_exact_visibility() {
    let dir = tempfile::tempdir().unwrap();
    example_scene("dunes", dir.path(), ExampleOptions { width: 48, height: 27, ..Default::default() }).unwrap();
    let scene = Scene::load(dir.path()).unwrap();
    let frame = scene.frame(1).unwrap();
    let exact = render(&scene, &frame, &options(3e-3, 6));
    let error = |cap_detail: bool| {
        let settings = logsh::shade::ShadingSettings {
            cap_detail,
            bounce: logsh::shade::bounce::BounceSettings::none(),
            ..logsh::shade::Quality::Default.settings()
        };
        let shaded = support::executors::cpu_beauty(&scene, &frame, &settings).unwrap();
        let (mut sum, mut count) = (0.0, 0usize);
        for ((a, b), &m) in shaded.rgba.iter().zip(&exact.rgba).zip(&frame.gbuffer.material) {
            if m != 0 {
                sum += (0..3).map(|c| f64::from((a[c] - b[c]).abs())).sum::<f64>();
                count += 3;
            }
        }
        sum / count as f64
    };
    let (with, without) = (error(true), error(false));
    println!("dunes 48x27 against the reference: {with:.4} with the caps' detail, {without:.4} without");
    assert!(with < 0.95 * without, "the detail must bring the frame nearer: {with} against {without}");
}

/// The specular occlusion of a rough lobe on a height field counts only the terrain that
/// rises above the horizontal. The lobe's part below the horizontal reads the map's lower
/// hemisphere, which is black under a height field; the occlusion used to take that part
/// out a second time. The dunes at 48x27 with the sand a rough specular layer alone
/// (GGX alpha 0.8), against the reference's exact visibility of the same terrain through
/// GGX's BRDF: the sand's mean signed difference over its mean light, -15.3 % before
/// and -2.8 % after.
#[test]
fn a_rough_lobe_on_a_height_field_is_occluded_only_above_the_horizontal() {
    let dir = tempfile::tempdir().unwrap();
    example_scene("dunes", dir.path(), ExampleOptions { width: 48, height: 27, ..Default::default() }).unwrap();
    let mut scene = Scene::load(dir.path()).unwrap();
    const SAND: u32 = 1;
    let alpha: f64 = 0.8;
    let exponent = 0.5 / (alpha * alpha) - 0.5;
    scene.materials.insert(SAND, Material::Phong { albedo: [0.0; 3], specular: [1.0; 3], exponent: exponent as f32 });
    let frame = scene.frame(1).unwrap();
    let exact = render(&scene, &frame, &options(2e-3, 6));
    let settings = logsh::shade::ShadingSettings {
        bounce: logsh::shade::bounce::BounceSettings::none(),
        ..logsh::shade::Quality::Default.settings()
    };
    let shaded = support::executors::cpu_beauty(&scene, &frame, &settings).unwrap();
    let (mut signed, mut truth) = (0.0, 0.0);
    for ((a, b), &m) in shaded.rgba.iter().zip(&exact.rgba).zip(&frame.gbuffer.material) {
        if m == SAND {
            signed += (0..3).map(|c| f64::from(a[c] - b[c])).sum::<f64>();
            truth += (0..3).map(|c| f64::from(b[c])).sum::<f64>();
        }
    }
    let relative = signed / truth;
    println!("rough sand against the reference: {:+.1} % of its light", 100.0 * relative);
    assert!(relative.abs() < 0.08, "the sand's glossy light is off by {:+.1} %", 100.0 * relative);
}
