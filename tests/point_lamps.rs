//! Point lamps (scene.json `point`, Blender's Point lamp): a sphere or, with Soft Falloff, a
//! disk facing the receiver, shaded as a disk of directions per pixel with only the
//! occluders nearer than the lamp (src/shade/sun.rs, src/scene/light.rs `PointLight`).

use crate::support;

use logsh::scene::{HeightMap, Light, PointLight, Scene, Sphere};
use logsh::shade::sun::cap_overlap;
use logsh::shade::ShadingSettings;
use logsh::synth::{sphere_over_plane, SphereOverPlane, PLANE_MATERIAL};
use std::f64::consts::PI;
use std::sync::Arc;
use support::sharp::{assert_finite, load_with_lights, PlaneComparison};

fn unit(v: [f64; 3]) -> ([f64; 3], f64) {
    let length = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    (v.map(|c| c / length), length)
}

/// The white plane's radiance at `p` (normal +Z) under `lamp`, behind `blockers`: the
/// irradiance of the lamp's cap, `pi L sin^2(a) cos(theta)` (exact for a cap above the
/// horizon), times the share of the cap no sphere covers (closed-form cap overlap; the
/// blockers must not overlap each other's caps), over pi. Only spheres nearer than the lamp
/// count.
fn expected_plane(p: [f64; 3], lamp: &PointLight, blockers: &[Sphere]) -> f64 {
    expected_on(p, [0.0, 0.0, 1.0], lamp, blockers)
}

/// [`expected_plane`] for a white plane of unit normal `n` through `p`.
fn expected_on(p: [f64; 3], n: [f64; 3], lamp: &PointLight, blockers: &[Sphere]) -> f64 {
    let (axis, d) = unit([0, 1, 2].map(|k| lamp.position[k] - p[k]));
    let (r, d2) = (lamp.radius, d * d);
    let (sin2, spread) = if lamp.soft_falloff { (r * r / (d2 + r * r), d2 + r * r) } else { (r * r / d2, d2) };
    let half_angle = sin2.sqrt().asin();
    let disk = 2.0 * PI * (1.0 - half_angle.cos());
    let mut visible = 1.0;
    for sphere in blockers {
        let (b, distance) = unit([0, 1, 2].map(|k| sphere.center[k] - p[k]));
        if distance - sphere.radius >= d {
            continue;
        }
        let gamma = (axis[0] * b[0] + axis[1] * b[1] + axis[2] * b[2]).clamp(-1.0, 1.0).acos();
        visible -= cap_overlap(half_angle, (sphere.radius / distance).asin(), gamma) / disk;
    }
    let cos_theta = axis[0] * n[0] + axis[1] * n[1] + axis[2] * n[2];
    f64::from(lamp.power) / (4.0 * PI * spread) * cos_theta / PI * visible
}

/// A lamp a few degrees wide behind a sphere, over a plane: the shadow on the plane,
/// penumbra included, against the closed-form cap overlap, for the sphere lamp and the
/// Soft Falloff disk, from the fast path and from the reference.
#[test]
fn lamp_behind_a_sphere_matches_the_closed_form() {
    let dir = tempfile::tempdir().unwrap();
    let sphere = Sphere::new([0.0, 0.0, 1.5], 0.8);
    let spec = SphereOverPlane { spheres: vec![sphere], width: 96, height: 54, ..Default::default() };
    sphere_over_plane(dir.path(), &spec).unwrap();
    let scene = Scene::load(dir.path()).unwrap();
    let mut frame = scene.frame(1).unwrap();
    frame.light = Arc::new(Light::Constant([0.0; 3]));
    for soft_falloff in [false, true] {
        let lamp = PointLight { position: [1.0, 1.2, 4.5], radius: 0.3, power: 400.0, color: [1.0; 3], soft_falloff };
        frame.points = vec![lamp];
        PlaneComparison::measure(&scene, &frame, |p| {
            (expected_plane(p, &lamp, &[sphere]), expected_plane(p, &lamp, &[]))
        })
        .assert_close(&format!("lamp (soft falloff {soft_falloff}) over sphere and plane"));
    }
}

/// A lamp low in front of a slope lies below the horizontal of the receivers above it,
/// yet lights the slope, which faces it: the horizon is marched up to the lamp, below the
/// horizontal too (thesis Section 4.3.1, Eq. 4.23). A sphere between them casts a
/// penumbra. The CPU path and the reference against the closed form of the lamp's cap
/// over the tilted plane.
#[test]
fn a_lamp_below_a_slope_that_faces_it_lights_it() {
    const SLOPE: f64 = 0.5;
    let (_dir, scene) = support::open_plane(96, 54);
    let mut frame = scene.frame(1).unwrap();
    frame.light = Arc::new(Light::Constant([0.0; 3]));
    // The plane z = SLOPE x, as a height field and in the G-buffer.
    let (n, _) = unit([-SLOPE, 0.0, 1.0]);
    let g = &mut frame.gbuffer;
    for (i, &m) in g.material.iter().enumerate() {
        if m == PLANE_MATERIAL {
            let [x, y, _] = g.position[i];
            g.position[i] = [x, y, (SLOPE * f64::from(x)) as f32];
            g.normal[i] = n.map(|c| c as f32);
        }
    }
    // 33 x 33 samples hold the plane exactly (bilinear reads of a linear function), and
    // the reference crosses a quarter of the cells 129 x 129 gave it, for the same figures.
    frame.height_map = Some(Arc::new(HeightMap::from_fn(33, 33, [-20.0, -20.0], [20.0, 20.0], |x, _| SLOPE * x)));
    let lamp = PointLight {
        position: [-9.0, 0.0, SLOPE * -9.0 + 1.5],
        radius: 0.1,
        power: 20000.0,
        color: [1.0; 3],
        soft_falloff: false,
    };
    let sphere = Sphere::new([-5.0, 0.0, SLOPE * -5.0 + 0.6], 0.3);
    (frame.points, frame.blockers) = (vec![lamp], vec![sphere]);
    let above_the_lamp = frame
        .gbuffer
        .material
        .iter()
        .zip(&frame.gbuffer.position)
        .filter(|&(&m, p)| m == PLANE_MATERIAL && f64::from(p[2]) > lamp.position[2] + 0.5)
        .count();
    assert!(above_the_lamp > 2000, "too few receivers above the lamp's horizontal: {above_the_lamp}");
    PlaneComparison::measure(&scene, &frame, |p| (expected_on(p, n, &lamp, &[sphere]), expected_on(p, n, &lamp, &[])))
        .assert_close("lamp below the slope it faces");
}

/// A sphere above a low lamp casts nothing on the plane below the lamp: only what is
/// nearer than the lamp blocks it (paper 002's horizon up to the light's distance). The
/// same sphere below the lamp shadows the plane.
#[test]
fn only_what_is_nearer_than_the_lamp_blocks_it() {
    let dir = tempfile::tempdir().unwrap();
    let sphere = Sphere::new([0.0, 0.0, 3.0], 0.8);
    let spec = SphereOverPlane { spheres: vec![sphere], width: 64, height: 36, ..Default::default() };
    sphere_over_plane(dir.path(), &spec).unwrap();
    let scene = Scene::load(dir.path()).unwrap();
    let mut frame = scene.frame(1).unwrap();
    frame.light = Arc::new(Light::Constant([0.0; 3]));
    for (height, shadowed) in [(1.0, false), (5.0, true)] {
        let lamp =
            PointLight { position: [0.0, 0.0, height], radius: 0.1, power: 100.0, color: [1.0; 3], soft_falloff: true };
        frame.points = vec![lamp];
        let shaded = support::cpu_beauty(&scene, &frame, &ShadingSettings::default()).unwrap();
        let (mut worst, mut darkest) = (0.0f64, f64::INFINITY);
        for (i, &m) in frame.gbuffer.material.iter().enumerate() {
            let p = frame.gbuffer.position[i].map(f64::from);
            // Plane pixels whose lamp cap stays well above the horizon.
            let (axis, _) = unit([0, 1, 2].map(|k| lamp.position[k] - p[k]));
            if m != PLANE_MATERIAL || axis[2] < 0.2 {
                continue;
            }
            let open = expected_plane(p, &lamp, &[]);
            let relative = f64::from(shaded.rgba[i][0]) / open;
            worst = worst.max((relative - 1.0).abs());
            darkest = darkest.min(relative);
        }
        println!("lamp at height {height}: plane pixels within {worst:.1e} of the open plane, darkest {darkest:.3}");
        if shadowed {
            assert!(darkest < 0.05, "the sphere between lamp and plane casts no shadow: darkest {darkest}");
        } else {
            assert!(worst < 3e-3, "a sphere beyond the lamp shadowed the plane: {worst}");
        }
    }
}

/// Extreme lamps stay finite: radius 0, the most power f32 holds, a lamp on the plane,
/// under it, inside the blocker, and one so large that the scene is inside it.
#[test]
fn extreme_point_lamps_stay_finite() {
    let dir = tempfile::tempdir().unwrap();
    let spec = SphereOverPlane { width: 24, height: 14, ..Default::default() };
    sphere_over_plane(dir.path(), &spec).unwrap();
    let scene = Scene::load(dir.path()).unwrap();
    let mut frame = scene.frame(1).unwrap();
    for (position, radius, power, soft_falloff) in [
        ([0.5, 0.5, 3.0], 0.0, 1e30f32, true),
        ([0.5, 0.5, 3.0], 0.0, f32::MAX, false),
        ([0.3, -0.2, 0.0], 0.5, 1e6, false),
        ([0.3, -0.2, 0.0], 0.5, 1e6, true),
        ([0.0, 0.0, -2.0], 0.2, 1e6, true),
        ([0.0, 0.0, 2.0], 0.1, 1e6, false),
        ([0.0, 0.0, 2.0], 1e4, 1e6, false),
    ] {
        frame.points = vec![PointLight { position, radius, power, color: [1.0; 3], soft_falloff }];
        let shaded = support::cpu_beauty(&scene, &frame, &ShadingSettings::default()).unwrap();
        let what = format!("lamp at {position:?}, radius {radius}, power {power}");
        assert_finite(&shaded, &frame, position[2] < -1.0, &what);
    }
}

#[test]
fn scene_json_point_lamps_are_read_and_checked() {
    let dir = tempfile::tempdir().unwrap();
    let spec = SphereOverPlane { width: 16, height: 9, ..Default::default() };
    sphere_over_plane(dir.path(), &spec).unwrap();
    let with_lights = |lights: serde_json::Value| load_with_lights(dir.path(), lights);
    let mut scene = with_lights(serde_json::json!([
        {"type": "point", "position": [1.0, 2.0, 3.0], "radius": 0.25, "power": 500.0, "color": [1.0, 0.9, 0.8]},
        {"type": "point", "position": [0.0, 0.0, 2.0], "radius": 0.0, "power": 10.0, "soft_falloff": false},
        {"type": "sun", "direction": [0.0, 0.0, 1.0], "angle": 1.0, "strength": 4.0}
    ]))
    .unwrap();
    assert_eq!(scene.suns.len(), 1);
    assert_eq!(
        scene.points,
        vec![
            PointLight {
                position: [1.0, 2.0, 3.0],
                radius: 0.25,
                power: 500.0,
                color: [1.0, 0.9, 0.8],
                soft_falloff: true
            },
            PointLight { position: [0.0, 0.0, 2.0], radius: 0.0, power: 10.0, color: [1.0; 3], soft_falloff: false },
        ]
    );
    assert_eq!(scene.frame(1).unwrap().points, scene.points);
    // --light-rotation turns the distant light; the lamps stay where they are.
    scene.turn_light(90.0).unwrap();
    assert_eq!(scene.points[0].position, [1.0, 2.0, 3.0]);
    for (lights, says) in [
        (
            serde_json::json!([{"type": "spot", "position": [0, 0, 1], "radius": 1, "power": 1}]),
            "unknown type \"spot\"",
        ),
        (serde_json::json!([{"type": "point", "radius": 1, "power": 1}]), "point needs \"position\""),
        (serde_json::json!([{"type": "point", "position": [0, 0, 1], "power": 1}]), "point needs \"radius\""),
        (serde_json::json!([{"type": "point", "position": [0, 0, 1], "radius": -1, "power": 1}]), "radius -1"),
        (serde_json::json!([{"type": "point", "position": [0, 0, 1], "radius": 1, "power": -1}]), ">= 0"),
        (serde_json::json!([{"type": "point", "position": [0, 0, 1], "radius": 1, "power": 1e39}]), "at most"),
        (
            serde_json::json!([{"type": "point", "position": [0, 0, 1], "radius": 1, "power": 1, "angle": 2}]),
            "key \"angle\" does not belong to a point",
        ),
        (
            serde_json::json!([{"type": "sun", "direction": [0, 0, 1], "angle": 1, "strength": 1, "radius": 2}]),
            "key \"radius\" does not belong to a sun",
        ),
    ] {
        let error = with_lights(lights).unwrap_err().to_string();
        assert!(error.contains(says) && error.contains("scene.json"), "{says}: {error}");
    }
}

/// Water mirrors a point lamp that its mirror ray meets before the reflected surface:
/// the pixel is the lamp's radiance, `power color / (4 pi^2 r^2)`, times the tint, and
/// the reflected surface is not shaded; a lamp behind that surface, or off the ray, leaves
/// the pixel to the surface.
#[test]
fn water_mirrors_a_point_lamp() {
    use logsh::shade::kernel::reflect_view;
    use logsh::shade::{pixel_work, PixelWork};
    use logsh::synth::{example_scene, ExampleOptions};
    let dir = tempfile::tempdir().unwrap();
    example_scene("dunes", dir.path(), ExampleOptions { width: 64, height: 36, ..Default::default() }).unwrap();
    let scene = Scene::load(dir.path()).unwrap();
    let mut frame = scene.frame(scene.default_frame()).unwrap();
    let g = &frame.gbuffer;
    let reflection = frame.reflection.as_ref().expect("the dunes have water");
    let water = (0..g.width * g.height)
        .find(|&i| {
            matches!(scene.materials.get(&g.material[i]), Some(logsh::scene::Material::Water { .. }))
                && reflection.material[i] != 0
        })
        .expect("water reflecting the terrain");
    let (x, y) = (water % g.width, water / g.width);
    assert!(matches!(pixel_work(&scene.materials, &frame, x, y), PixelWork::Shade { .. }));
    let point = logsh::shade::frame::surface_at(g, water, None, &frame);
    let (mirror, _) = unit(reflect_view(point.view_origin, point.position, point.normal));
    let surface = {
        let p = reflection.position[water].map(f64::from);
        unit([0, 1, 2].map(|k| p[k] - point.position[k])).1
    };
    let tint = match scene.materials[&g.material[water]] {
        logsh::scene::Material::Water { tint } => tint,
        _ => unreachable!(),
    };
    for soft_falloff in [false, true] {
        let at = |t: f64| [0, 1, 2].map(|k| point.position[k] + t * mirror[k]);
        let lamp = PointLight {
            position: at(0.5 * surface),
            radius: 0.05,
            power: 30.0,
            color: [1.0, 0.5, 0.25],
            soft_falloff,
        };
        frame.points = vec![lamp];
        let PixelWork::Fixed(lit) = pixel_work(&scene.materials, &frame, x, y) else {
            panic!("the lamp in the mirror")
        };
        let radiance = 30.0 / (4.0 * PI * PI * 0.05 * 0.05);
        for k in 0..3 {
            let expected = f64::from(tint[k]) * radiance * f64::from(lamp.color[k]);
            assert!((f64::from(lit[k]) - expected).abs() <= 1e-4 * expected, "channel {k}: {} vs {expected}", lit[k]);
        }
        for elsewhere in
            [PointLight { position: at(1.5 * surface), ..lamp }, PointLight { position: [0.0, 0.0, -50.0], ..lamp }]
        {
            frame.points = vec![elsewhere];
            assert!(matches!(pixel_work(&scene.materials, &frame, x, y), PixelWork::Shade { .. }));
        }
    }
}
