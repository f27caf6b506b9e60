//! The procedural scene writer: what it writes reads back identical through the scene
//! reader, in both G-buffer layouts, and its analytic scene has the expected geometry.

use logsh::scene::{Light, Material, Scene};
use logsh::synth::{
    self, example, example_scene, ExampleOptions, GBufferLayout, SphereOverPlane, PLANE_MATERIAL, SPHERE_MATERIAL,
};
use std::path::Path;

fn small(layout: GBufferLayout) -> SphereOverPlane {
    SphereOverPlane { width: 64, height: 36, layout, ..SphereOverPlane::default() }
}

fn round_trip(layout: GBufferLayout) {
    let dir = tempfile::tempdir().unwrap();
    let spec = small(layout);
    let scene_spec = spec.scene();
    let (expected, reflection) = scene_spec.render_frame(&scene_spec.frames[0]);
    assert!(reflection.is_none(), "no water, no reflection buffer");
    synth::sphere_over_plane(dir.path(), &spec).unwrap();

    let scene = Scene::load(dir.path()).unwrap();
    assert_eq!(scene.default_frame(), 1);
    let frame = scene.frame(1).unwrap();
    let g = &frame.gbuffer;
    assert_eq!((g.width, g.height), (64, 36));
    // Exact equality: f32 channels are stored as f32, UV was rounded to f16 before writing.
    assert_eq!(g.position, expected.position);
    assert_eq!(g.normal, expected.normal);
    assert_eq!(g.uv, expected.uv);
    assert_eq!(g.material, expected.material);
    assert_eq!(frame.camera.as_ref().unwrap(), &scene_spec.frames[0].camera);
    assert_eq!(frame.blockers, spec.spheres);
    assert_eq!(*frame.light, Light::Constant([1.0; 3]));
    assert!(frame.height_map.is_none() && frame.reflection.is_none());
    assert_eq!(scene.materials[&PLANE_MATERIAL], Material::Diffuse { albedo: [1.0; 3] });
}

#[test]
fn round_trip_blender5_multipart() {
    round_trip(GBufferLayout::Blender5);
}

#[test]
fn round_trip_blender4_single_part() {
    round_trip(GBufferLayout::Blender4);
}

/// The two layouts differ in the file exactly as Blender's do.
#[test]
fn layouts_match_blender_naming() {
    let dir = tempfile::tempdir().unwrap();
    for (layout, sub) in [(GBufferLayout::Blender5, "b5"), (GBufferLayout::Blender4, "b4")] {
        synth::sphere_over_plane(&dir.path().join(sub), &small(layout)).unwrap();
    }
    let meta =
        |sub: &str| exr::meta::MetaData::read_from_file(dir.path().join(sub).join("gbuffer.0001.exr"), false).unwrap();
    let b5 = meta("b5");
    let parts: Vec<String> =
        b5.headers.iter().map(|h| h.own_attributes.layer_name.as_ref().unwrap().to_string()).collect();
    assert!(parts.contains(&"ViewLayer.Position".to_string()), "{parts:?}");
    assert!(parts.contains(&"ViewLayer.Material Index".to_string()), "{parts:?}");
    let position =
        b5.headers.iter().find(|h| h.own_attributes.layer_name.as_ref().unwrap() == "ViewLayer.Position").unwrap();
    let names: Vec<String> = position.channels.list.iter().map(|c| c.name.to_string()).collect();
    assert_eq!(names, ["ViewLayer.Position.X", "ViewLayer.Position.Y", "ViewLayer.Position.Z"]);

    let b4 = meta("b4");
    assert_eq!(b4.headers.len(), 1);
    let names: Vec<String> = b4.headers[0].channels.list.iter().map(|c| c.name.to_string()).collect();
    assert!(names.contains(&"ViewLayer.IndexMA.X".to_string()), "{names:?}");
    assert!(!names.iter().any(|n| n.contains("Material Index")));
}

/// Plane pixels lie on z = 0 facing up, sphere pixels on the sphere; the default camera
/// sees no background.
#[test]
fn sphere_over_plane_geometry() {
    let spec = small(GBufferLayout::Blender5);
    let s = spec.scene();
    let (g, _) = s.render_frame(&s.frames[0]);
    let c = spec.spheres[0].center;
    let (mut plane, mut sphere) = (0, 0);
    for i in 0..g.width * g.height {
        let (p, n) = (g.position[i], g.normal[i]);
        match g.material[i] {
            PLANE_MATERIAL => {
                plane += 1;
                assert!(p[2].abs() < 1e-5 && n == [0.0, 0.0, 1.0]);
            }
            SPHERE_MATERIAL => {
                sphere += 1;
                let d =
                    ((p[0] as f64 - c[0]).powi(2) + (p[1] as f64 - c[1]).powi(2) + (p[2] as f64 - c[2]).powi(2)).sqrt();
                assert!((d - 1.0).abs() < 1e-5, "sphere pixel at distance {d}");
            }
            m => panic!("unexpected material {m}"),
        }
    }
    assert!(plane > 1000 && sphere > 50, "plane {plane}, sphere {sphere}");
}

#[test]
fn sphere_over_plane_closed_form() {
    let spec = SphereOverPlane::default();
    // Right under the sphere (centre height 2, radius 1): alpha = 30 deg, beta = 0.
    let below = spec.expected_at([0.0, 0.0, 0.0]).unwrap();
    assert!((below - 0.75).abs() < 1e-12, "{below}");
    // A sphere that cuts the plane: far away its cap crosses the horizon, no closed form.
    let low = SphereOverPlane { spheres: vec![logsh::scene::Sphere::new([0.0, 0.0, 0.5], 1.0)], ..spec.clone() };
    assert!(low.expected_at([5.0, 0.0, 0.0]).is_none());
    assert!(low.expected_at([0.0, 0.0, 0.0]).is_none(), "inside the sphere");
    // beta = 45 deg at horizontal distance 2: sin^2(alpha) = 1/8, cos(beta) = 1/sqrt(2).
    let side = spec.expected_at([2.0, 0.0, 0.0]).unwrap();
    assert!((side - (1.0 - 0.125 / 2f64.sqrt())).abs() < 1e-12, "{side}");

    let s = spec.scene();
    let (g, _) = s.render_frame(&s.frames[0]);
    let expected = spec.expected_image(&g);
    let valid = expected.iter().filter(|e| e.is_some()).count();
    assert!(valid > g.width * g.height / 4, "{valid} pixels with a closed form");
    for (e, &m) in expected.iter().zip(&g.material) {
        if let Some(v) = e {
            assert_eq!(m, PLANE_MATERIAL);
            assert!((0.75..=1.0).contains(v));
        }
    }
}

#[test]
fn dunes_sample_scene_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    let options = ExampleOptions { width: 96, height: 54, layout: GBufferLayout::Blender5 };
    example_scene("dunes", dir.path(), options).unwrap();
    let spec = example("dunes", options).unwrap();
    let scene = Scene::load(dir.path()).unwrap();
    assert_eq!(scene.frame_numbers(usize::MAX), [1, 2]);
    assert!(scene.heightfield.is_some() && scene.reflection_gbuffer.is_some());

    let mut blockers = Vec::new();
    for (k, n) in scene.frame_numbers(usize::MAX).into_iter().enumerate() {
        let f = scene.frame(n).unwrap();
        let (g, r) = spec.render_frame(&spec.frames[k]);
        assert_eq!(f.gbuffer.position, g.position);
        assert_eq!(f.gbuffer.material, g.material);
        assert_eq!(f.reflection.as_ref().unwrap().material, r.unwrap().material);
        let count = |m: u32| f.gbuffer.material.iter().filter(|&&x| x == m).count();
        for m in [0, 1, 2, 4, 5] {
            assert!(count(m) > 0, "frame {n}: no pixel of material {m}");
        }
        // Every water pixel reflects something or the sky; non-water pixels reflect nothing.
        let refl = f.reflection.as_ref().unwrap();
        for i in 0..refl.material.len() {
            if f.gbuffer.material[i] != 2 {
                assert_eq!(refl.material[i], 0);
            }
        }
        assert!(refl.material.iter().any(|&m| m != 0 && m != 2), "the water reflects some object");
        let map = f.height_map.as_ref().unwrap();
        assert_eq!((map.columns, map.rows), (161, 161));
        // Terrain pixels sit on the height map (bilinear surface the tool reads).
        for i in 0..f.gbuffer.material.len() {
            if f.gbuffer.material[i] == 1 {
                let p = f.gbuffer.position[i];
                let h = map.height_at(p[0] as f64, p[1] as f64);
                assert!((p[2] as f64 - h).abs() < 1e-3, "terrain pixel {p:?} vs height {h}");
            }
        }
        assert!(matches!(&*f.light, Light::Environment { map, .. } if map.width == 128 && map.height == 64));
        blockers.push(f.blockers.clone());
    }
    assert_eq!(blockers[0].len(), 4);
    assert_ne!(blockers[0][0].center, blockers[1][0].center, "one sphere moves between frames");
    assert_eq!(blockers[0][1..], blockers[1][1..]);
}

#[test]
fn spheres_sample_and_unknown_name() {
    let dir = tempfile::tempdir().unwrap();
    example_scene("spheres", dir.path(), ExampleOptions { width: 40, height: 24, layout: GBufferLayout::Blender4 })
        .unwrap();
    Scene::load(dir.path()).unwrap().frame(1).unwrap();
    let err = example_scene("nope", &dir.path().join("x"), ExampleOptions::default()).unwrap_err();
    assert!(err.to_string().contains("unknown example scene \"nope\""), "{err}");
    assert!(!Path::new(&dir.path().join("x")).exists());
}

/// The cone primitive: a ray down the axis hits the apex, one from the side hits the
/// slanted surface with an outward normal.
#[test]
fn cone_intersection() {
    use synth::{trace, Object, Shape};
    let cone =
        [Object { shape: Shape::Cone { base: [0.0, 0.0, 0.0], apex: [0.0, 0.0, 2.0], radius: 1.0 }, material: 3 }];
    let h = trace(&cone, [0.1, 0.0, 5.0], [0.0, 0.0, -1.0], 0.0).unwrap();
    assert!((h.t - 3.2).abs() < 1e-9, "{}", h.t);
    let h = trace(&cone, [5.0, 0.0, 1.0], [-1.0, 0.0, 0.0], 0.0).unwrap();
    assert!((h.position[0] - 0.5).abs() < 1e-9, "{:?}", h.position);
    let s5 = 5f64.sqrt();
    assert!((h.normal[0] - 2.0 / s5).abs() < 1e-9 && (h.normal[2] - 1.0 / s5).abs() < 1e-9, "{:?}", h.normal);
    let h = trace(&cone, [0.5, 0.0, -3.0], [0.0, 0.0, 1.0], 0.0).unwrap();
    assert_eq!(h.normal, [0.0, 0.0, -1.0]);
}
