//! Scene format v1: every bad input gives the documented error naming the file and the
//! problem; the light follows Blender's environment orientation; outputs are written
//! atomically and never over an input.

use exr::prelude::{AnyChannel, AnyChannels, Encoding, FlatSamples, Image, Layer, LayerAttributes, WritableImage};
use logsh::scene::light::{direction_to_equirectangular, equirectangular_to_direction};
use logsh::scene::output::{write_exr_rgba, write_png_preview};
use logsh::scene::{EnvironmentMap, Light, Scene, SceneError};
use logsh::scene::{ViewSpec, ViewTransform};
use logsh::synth::{self, GBufferLayout, SphereOverPlane};
use std::f64::consts::PI;
use std::path::Path;

/// A valid 32x18 sphere-over-plane scene (materials 1 and 2) to break.
fn base_scene() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let spec = SphereOverPlane { width: 32, height: 18, layout: GBufferLayout::Blender5, ..SphereOverPlane::default() };
    synth::sphere_over_plane(dir.path(), &spec).unwrap();
    dir
}

fn edit_json(path: &Path, f: impl FnOnce(&mut serde_json::Value)) {
    let mut v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    f(&mut v);
    std::fs::write(path, serde_json::to_string_pretty(&v).unwrap()).unwrap();
}

/// A single-part EXR with the given f32 channels.
fn write_raw_exr(path: &Path, width: usize, height: usize, channels: Vec<(&str, Vec<f32>)>) {
    let list: Vec<AnyChannel<FlatSamples>> =
        channels.into_iter().map(|(n, d)| AnyChannel::new(n, FlatSamples::F32(d))).collect();
    let layer = Layer::new(
        (width, height),
        LayerAttributes::default(),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(list.into_iter().collect()),
    );
    Image::from_layer(layer).write().to_file(path).unwrap();
}

/// G-buffer channels of a plane seen from above: index `index(x, y)` per pixel.
fn gbuffer_channels(w: usize, h: usize, index: impl Fn(usize, usize) -> f32) -> Vec<(&'static str, Vec<f32>)> {
    let n = w * h;
    vec![
        ("ViewLayer.Position.X", vec![0.0; n]),
        ("ViewLayer.Position.Y", vec![0.0; n]),
        ("ViewLayer.Position.Z", vec![0.0; n]),
        ("ViewLayer.Normal.X", vec![0.0; n]),
        ("ViewLayer.Normal.Y", vec![0.0; n]),
        ("ViewLayer.Normal.Z", vec![1.0; n]),
        ("ViewLayer.IndexMA.X", (0..n).map(|i| index(i % w, i / w)).collect()),
    ]
}

fn frame_error(dir: &Path) -> SceneError {
    Scene::load(dir).and_then(|s| s.frame(1)).expect_err("the frame must be refused")
}

fn assert_mentions(err: &SceneError, parts: &[&str]) {
    let text = err.to_string();
    for p in parts {
        assert!(text.contains(p), "error {text:?} should mention {p:?}");
    }
}

#[test]
fn missing_file_is_named() {
    let dir = base_scene();
    std::fs::remove_file(dir.path().join("gbuffer.0001.exr")).unwrap();
    let err = frame_error(dir.path());
    assert!(matches!(err, SceneError::MissingFile { .. }), "{err:?}");
    assert_mentions(&err, &["gbuffer.0001.exr", "file not found"]);

    std::fs::remove_file(dir.path().join("scene.json")).unwrap();
    let err = Scene::load(dir.path()).unwrap_err();
    assert_mentions(&err, &["scene.json", "file not found"]);
}

#[test]
fn missing_channel_lists_what_was_found() {
    let dir = base_scene();
    let mut channels = gbuffer_channels(32, 18, |_, _| 1.0);
    channels.retain(|(n, _)| *n != "ViewLayer.Normal.Y");
    write_raw_exr(&dir.path().join("gbuffer.0001.exr"), 32, 18, channels);
    let err = frame_error(dir.path());
    assert!(matches!(err, SceneError::MissingChannel { .. }), "{err:?}");
    assert_mentions(
        &err,
        &["gbuffer.0001.exr", "missing channel \"ViewLayer.Normal.Y\"", "found:", "\"ViewLayer.Normal.X\""],
    );
}

#[test]
fn blender4_index_name_and_channel_overrides() {
    let dir = base_scene();
    // Blender 4 naming is found without configuration.
    write_raw_exr(&dir.path().join("gbuffer.0001.exr"), 32, 18, gbuffer_channels(32, 18, |x, _| (x % 2) as f32));
    let f = Scene::load(dir.path()).unwrap().frame(1).unwrap();
    assert_eq!(&f.gbuffer.material[..4], &[0, 1, 0, 1]);
    assert!(f.gbuffer.uv.is_none(), "no UV channels: uv is None");

    // Overrides: custom names, and UV named in an override is required.
    let n = 32 * 18;
    let custom = vec![
        ("P.X", vec![0.0; n]),
        ("P.Y", vec![0.0; n]),
        ("P.Z", vec![0.0; n]),
        ("N.X", vec![0.0; n]),
        ("N.Y", vec![0.0; n]),
        ("N.Z", vec![1.0; n]),
        ("idx", vec![2.0; n]),
    ];
    write_raw_exr(&dir.path().join("gbuffer.0001.exr"), 32, 18, custom);
    edit_json(&dir.path().join("scene.json"), |v| {
        v["channels"] = serde_json::json!({"position": ["P.X", "P.Y", "P.Z"], "normal": ["N.X", "N.Y", "N.Z"], "material_index": "idx"});
    });
    let f = Scene::load(dir.path()).unwrap().frame(1).unwrap();
    assert!(f.gbuffer.material.iter().all(|&m| m == 2));
    edit_json(&dir.path().join("scene.json"), |v| v["channels"]["uv"] = serde_json::json!(["T.U", "T.V"]));
    assert_mentions(&frame_error(dir.path()), &["missing channel \"T.U\""]);
    edit_json(&dir.path().join("scene.json"), |v| v["channels"]["colour"] = serde_json::json!("x"));
    assert_mentions(&Scene::load(dir.path()).unwrap_err(), &["scene.json", "unknown field `colour`"]);
}

#[test]
fn size_mismatch_between_buffers() {
    let dir = base_scene();
    let small = SphereOverPlane { width: 16, height: 9, ..SphereOverPlane::default() };
    let s = small.scene();
    let (g, _) = s.render_frame(&s.frames[0]);
    synth::write_gbuffer_exr(&dir.path().join("reflection.0001.exr"), &g, GBufferLayout::Blender5).unwrap();
    edit_json(&dir.path().join("scene.json"), |v| v["reflection_gbuffer"] = serde_json::json!("reflection.####.exr"));
    let err = frame_error(dir.path());
    assert!(matches!(err, SceneError::SizeMismatch { .. }), "{err:?}");
    assert_mentions(&err, &["reflection.0001.exr", "16x9", "32x18", "gbuffer.0001.exr"]);

    // The camera's resolution must match too.
    let dir = base_scene();
    edit_json(&dir.path().join("camera.0001.json"), |v| v["resolution"] = serde_json::json!([64, 36]));
    assert_mentions(&frame_error(dir.path()), &["camera.0001.json", "64x36", "32x18"]);
}

#[test]
fn malformed_json_gives_file_and_line() {
    let dir = base_scene();
    std::fs::write(dir.path().join("scene.json"), "{\n  \"version\": 1,\n  \"gbuffer\": \"g.exr\" \"oops\"\n}\n")
        .unwrap();
    let err = Scene::load(dir.path()).unwrap_err();
    match &err {
        SceneError::Json { line, .. } => assert_eq!(*line, 3),
        other => panic!("{other:?}"),
    }
    assert_mentions(&err, &["scene.json:3:"]);
}

#[test]
fn unknown_keys_are_named() {
    let dir = base_scene();
    edit_json(&dir.path().join("scene.json"), |v| v["frobnicate"] = serde_json::json!(1));
    assert_mentions(&Scene::load(dir.path()).unwrap_err(), &["scene.json", "unknown field `frobnicate`"]);

    let dir = base_scene();
    edit_json(&dir.path().join("scene.json"), |v| v["materials"]["1"]["albdo"] = serde_json::json!([1, 1, 1]));
    assert_mentions(&Scene::load(dir.path()).unwrap_err(), &["unknown field `albdo`"]);

    let dir = base_scene();
    edit_json(&dir.path().join("scene.json"), |v| v["materials"]["1"]["tint"] = serde_json::json!([1, 1, 1]));
    assert_mentions(&Scene::load(dir.path()).unwrap_err(), &["material 1", "\"tint\" does not belong to type diffuse"]);

    let dir = base_scene();
    edit_json(&dir.path().join("camera.0001.json"), |v| v["fov"] = serde_json::json!(40));
    assert_mentions(&frame_error(dir.path()), &["camera.0001.json", "unknown field `fov`"]);

    let dir = base_scene();
    edit_json(&dir.path().join("blockers.0001.json"), |v| v["spheres"][0]["radus"] = serde_json::json!(1));
    assert_mentions(&frame_error(dir.path()), &["blockers.0001.json", "unknown field `radus`"]);
}

#[test]
fn scene_level_validation() {
    type Edit = Box<dyn Fn(&mut serde_json::Value)>;
    let cases: Vec<(Edit, &[&str])> = vec![
        (Box::new(|v| v["version"] = serde_json::json!(2)), &["unsupported scene format version 2"]),
        (
            Box::new(|v| v["materials"]["0"] = serde_json::json!({"type": "diffuse", "albedo": [1, 1, 1]})),
            &["material index 0"],
        ),
        (
            Box::new(|v| v["materials"]["x"] = serde_json::json!({"type": "diffuse", "albedo": [1, 1, 1]})),
            &["material key \"x\""],
        ),
        (
            Box::new(|v| {
                v["materials"]["3"] =
                    serde_json::json!({"type": "phong", "albedo": [0, 0, 0], "specular": [1, 1, 1], "exponent": 0})
            }),
            &["material 3", "exponent 0 must be > 0"],
        ),
        (
            Box::new(|v| {
                v["materials"]["3"] = serde_json::json!({"type": "phong", "albedo": [0, 0, 0], "specular": [1, 1, 1]})
            }),
            &["needs key \"exponent\""],
        ),
        (
            Box::new(|v| {
                v["materials"]["3"] = serde_json::json!(
                    {"type": "phong", "albedo": [0, 0, 0], "specular": [1, 1, 1], "exponent": 8, "fresnel": 1.5}
                )
            }),
            &["material 3", "fresnel 1.5 is not a reflectance from 0 to 1"],
        ),
        (
            Box::new(|v| {
                v["materials"]["3"] = serde_json::json!({"type": "diffuse", "albedo": [1, 1, 1], "fresnel": 0.04})
            }),
            &["material 3", "\"fresnel\" does not belong to type diffuse"],
        ),
        (
            Box::new(|v| v["materials"]["3"] = serde_json::json!({"type": "diffuse", "albedo": [1, -1, 1]})),
            &["negative"],
        ),
        (
            Box::new(|v| v["materials"]["3"] = serde_json::json!({"type": "metal", "albedo": [1, 1, 1]})),
            &["unknown type \"metal\""],
        ),
        (Box::new(|v| v["light"] = serde_json::json!({"sh": [[1, 1, 1], [0, 0, 0], [0, 0, 0]]})), &["3 coefficients"]),
        (Box::new(|v| v["light"] = serde_json::json!({"constant": [1, 1, 1], "sh": [[1, 1, 1]]})), &["exactly one of"]),
        (Box::new(|v| v["light"] = serde_json::json!({"environment": "nope.exr"})), &["nope.exr", "file not found"]),
        (Box::new(|v| v["frames"] = serde_json::json!({"start": 5, "end": 1})), &["start 5 is after end 1"]),
        (
            Box::new(|v| v["frames"] = serde_json::json!({"start": 1, "end": 9, "list": [1, 5, 5, 9]})),
            &["sorted and without repeats", "5 before 5"],
        ),
        (
            Box::new(|v| v["frames"] = serde_json::json!({"start": 1, "end": 9, "list": [2, 9]})),
            &["list must begin with start (1)"],
        ),
        (Box::new(|v| v["frames"] = serde_json::json!({"start": 1, "end": 9, "list": []})), &["list must begin"]),
        (
            Box::new(|v| v["heightfield"] = serde_json::json!({"heights": "h.exr", "min": [0, 0], "max": [0, 1]})),
            &["min", "below max"],
        ),
    ];
    for (edit, parts) in cases {
        let dir = base_scene();
        edit_json(&dir.path().join("scene.json"), |v| edit(v));
        let err = Scene::load(dir.path()).unwrap_err();
        assert_mentions(&err, parts);
    }
}

#[test]
fn frames_outside_the_range_are_refused() {
    let dir = base_scene();
    let scene = Scene::load(dir.path()).unwrap();
    let err = scene.frame(2).unwrap_err();
    assert!(matches!(err, SceneError::FrameOutOfRange { frame: 2, .. }), "{err:?}");
    assert!(err.to_string().contains("not one of the scene's frames (1-1)"), "{err}");
    edit_json(&dir.path().join("scene.json"), |v| {
        v.as_object_mut().unwrap().remove("frames");
    });
    assert_eq!(Scene::load(dir.path()).unwrap().default_frame(), 1);
}

#[test]
fn negative_radius_and_non_finite_blockers() {
    let dir = base_scene();
    edit_json(&dir.path().join("blockers.0001.json"), |v| v["spheres"][0]["radius"] = serde_json::json!(-1.0));
    let err = frame_error(dir.path());
    assert_mentions(&err, &["blockers.0001.json", "sphere 0", "negative radius -1"]);

    // JSON has no NaN: the file is malformed, and the error points at the line.
    let dir = base_scene();
    let path = dir.path().join("blockers.0001.json");
    std::fs::write(&path, "{\"frame\": 1,\n \"spheres\": [{\"center\": [0, 0, 2],\n   \"radius\": NaN}]}").unwrap();
    let err = frame_error(dir.path());
    assert!(matches!(err, SceneError::Json { line: 3, .. }), "{err:?}");
    assert_mentions(&err, &["blockers.0001.json:3:"]);

    // Overflowing numbers are refused too.
    std::fs::write(&path, "{\"frame\": 1, \"spheres\": [{\"center\": [0, 1e999, 2], \"radius\": 1}]}").unwrap();
    assert_mentions(&frame_error(dir.path()), &["blockers.0001.json"]);

    std::fs::write(&path, "{\"frame\": 2, \"spheres\": []}").unwrap();
    assert_mentions(&frame_error(dir.path()), &["says frame 2 but was read for frame 1"]);
}

/// An EXR's channels by name, as [`write_raw_exr`] takes them.
type Channels = Vec<(&'static str, Vec<f32>)>;

/// A sun's shadow map in the blockers file: read with both depths, and each way it can be
/// wrong refused, naming the file and what is wrong.
#[test]
fn sun_shadow_maps_are_read_and_checked() {
    let entry = || {
        serde_json::json!({"image": "sun.exr", "axis": [0.0, 0.0, 1.00005], "origin": [0.0, 0.0, 5.0],
            "right": [1.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0], "size": [4.0, 2.0]})
    };
    let with_map = |map: serde_json::Value, channels: Channels| {
        let dir = base_scene();
        write_raw_exr(&dir.path().join("sun.exr"), 4, 2, channels);
        edit_json(&dir.path().join("blockers.0001.json"), |v| v["sun_shadows"] = serde_json::json!([map]));
        dir
    };
    let depths = || vec![("Z", vec![1.0, 2.0, 1e10, 1e10, 1.0, 2.0, 3.0, 4.0]), ("Zfar", vec![5.0; 8])];

    let dir = with_map(entry(), depths());
    let frame = Scene::load(dir.path()).unwrap().frame(1).unwrap();
    let map = &frame.sun_shadows[0];
    assert_eq!((map.columns, map.rows, map.depths[1], map.far_depths[0]), (4, 2, 2.0, 5.0));
    // Read unit (the exporter writes Blender's single-precision direction), it serves its
    // sun, and a sun up to 1 degree from it.
    let tilted = |degrees: f64| [0.0, degrees.to_radians().sin(), degrees.to_radians().cos()];
    assert!(map.serves([0.0, 0.0, 1.0]) && map.serves(tilted(0.9)) && !map.serves(tilted(1.1)));

    let mut skewed = entry();
    skewed["up"] = serde_json::json!([0.0, 0.6, 0.8]);
    let mut outside = entry();
    outside["image"] = serde_json::json!("../sun.exr");
    let mut stretched = entry();
    stretched["size"] = serde_json::json!([4.0, 3.0]);
    let mut flat = entry();
    flat["size"] = serde_json::json!([4.0, 0.0]);
    let inverted = vec![("Z", vec![3.0; 8]), ("Zfar", vec![2.0; 8])];
    let not_a_number = vec![("Z", vec![f32::NAN; 8]), ("Zfar", vec![2.0; 8])];
    let cases: Vec<(serde_json::Value, Channels, &[&str])> = vec![
        (skewed, depths(), &["blockers.0001.json", "sun_shadows[0]", "orthogonal"]),
        (outside, depths(), &["sun_shadows[0].image", "inside the scene directory"]),
        (stretched, depths(), &["sun_shadows[0]", "not square"]),
        (flat, depths(), &["sun_shadows[0]", "\"size\"", "positive"]),
        (entry(), vec![("Z", vec![1.0; 8])], &["sun.exr", "Zfar"]),
        (entry(), inverted, &["sun.exr", "texel (0, 0)", "Zfar 2 lies above Z 3"]),
        (entry(), not_a_number, &["sun.exr", "Z at texel (0, 0)"]),
    ];
    for (map, channels, parts) in cases {
        let dir = with_map(map, channels);
        assert_mentions(&frame_error(dir.path()), parts);
    }
}

#[test]
fn fractional_and_unknown_material_indices() {
    let dir = base_scene();
    let g = dir.path().join("gbuffer.0001.exr");
    write_raw_exr(&g, 32, 18, gbuffer_channels(32, 18, |x, y| if (x, y) == (3, 2) { 1.5 } else { 1.0 }));
    let err = frame_error(dir.path());
    assert!(matches!(err, SceneError::MaterialIndex { x: 3, y: 2, .. }), "{err:?}");
    assert_mentions(&err, &["gbuffer.0001.exr", "pixel (3, 2)", "1.5", "not a whole number"]);

    // Within 1e-3 of a whole number is accepted and rounded.
    write_raw_exr(&g, 32, 18, gbuffer_channels(32, 18, |_, _| 2.0004));
    assert!(Scene::load(dir.path()).unwrap().frame(1).unwrap().gbuffer.material.iter().all(|&m| m == 2));

    write_raw_exr(&g, 32, 18, gbuffer_channels(32, 18, |x, y| if (x, y) == (5, 7) { 7.0 } else { 0.0 }));
    assert_mentions(
        &frame_error(dir.path()),
        &["pixel (5, 7)", "material index 7", "not in the material table", "1, 2"],
    );

    write_raw_exr(&g, 32, 18, gbuffer_channels(32, 18, |_, _| -1.0));
    assert_mentions(&frame_error(dir.path()), &["pixel (0, 0)", "is negative"]);
}

#[test]
fn non_finite_position_on_a_surface_pixel() {
    let dir = base_scene();
    let mut channels = gbuffer_channels(32, 18, |x, _| if x < 4 { 0.0 } else { 1.0 });
    channels[0].1[1] = f32::NAN; // pixel (1, 0) is background: ignored
    channels[0].1[32 + 6] = f32::INFINITY; // pixel (6, 1) is a surface
    write_raw_exr(&dir.path().join("gbuffer.0001.exr"), 32, 18, channels);
    let err = frame_error(dir.path());
    assert!(matches!(err, SceneError::NonFinite { .. }), "{err:?}");
    assert_mentions(&err, &["gbuffer.0001.exr", "position", "pixel (6, 1)"]);
}

#[test]
fn absurd_sizes_are_refused_before_allocation() {
    let dir = base_scene();
    let w = 16385;
    write_raw_exr(&dir.path().join("gbuffer.0001.exr"), w, 1, vec![("ViewLayer.Position.X", vec![0.0; w])]);
    let err = frame_error(dir.path());
    assert!(matches!(err, SceneError::TooLarge { width: 16385, height: 1, .. }), "{err:?}");
    assert_mentions(&err, &["gbuffer.0001.exr", "16385 x 1", "too large"]);
}

#[test]
fn water_pixels_need_a_reflection_buffer() {
    let dir = base_scene();
    edit_json(&dir.path().join("scene.json"), |v| {
        v["materials"]["2"] = serde_json::json!({"type": "water", "tint": [1, 1, 1]})
    });
    assert_mentions(&frame_error(dir.path()), &["is water (material 2)", "reflection_gbuffer"]);
}

// ---- light -------------------------------------------------------------------------

/// Independent statement of Blender's mapping (Cycles `direction_to_equirectangular`,
/// `v = 0` at the bottom row): the texel of the file (row 0 on top) that direction `d`
/// falls in.
fn blender_texel(d: [f64; 3], w: usize, h: usize) -> (usize, usize) {
    let u = 0.5 - d[1].atan2(d[0]) / (2.0 * PI);
    let v = 1.0 - d[2].acos() / PI;
    (((u * w as f64) as usize).min(w - 1), (((1.0 - v) * h as f64) as usize).min(h - 1))
}

#[test]
fn equirectangular_mapping_is_blenders() {
    // Zenith on the top row, +X in the centre column, +Y at a quarter, -Y at three quarters.
    assert!(direction_to_equirectangular([0.0, 0.0, 1.0])[1] > 0.999);
    assert_eq!(direction_to_equirectangular([1.0, 0.0, 0.0]), [0.5, 0.5]);
    assert!((direction_to_equirectangular([0.0, 1.0, 0.0])[0] - 0.25).abs() < 1e-12);
    assert!((direction_to_equirectangular([0.0, -1.0, 0.0])[0] - 0.75).abs() < 1e-12);
    for d in [[0.3, -0.5, 0.8], [-0.7, 0.1, -0.2], [0.0, 0.6, 0.8]] {
        let l: f64 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        let d = d.map(|x: f64| x / l.sqrt());
        let [u, v] = direction_to_equirectangular(d);
        let back = equirectangular_to_direction(u, v);
        for k in 0..3 {
            assert!((back[k] - d[k]).abs() < 1e-12);
        }
    }
}

/// A map bright only in a small patch around a known direction projects to an SH vector
/// whose band-1 part `(y_{1,1}, y_{1,-1}, y_{1,0}) ~ (x, y, z)` points that way.
#[test]
fn environment_orientation_through_sh() {
    let (w, h) = (256, 128);
    let dir = tempfile::tempdir().unwrap();
    for target in [[0.0, 1.0, 0.0], [1.0, 0.0, 1.0], [-0.5, -0.8, 0.3], [0.2, 0.3, -0.9]] {
        let n = (target.iter().map(|x: &f64| x * x).sum::<f64>()).sqrt();
        let d = target.map(|x| x / n);
        let (cx, cy) = blender_texel(d, w, h);
        let mut texels = vec![[0.0f32; 3]; w * h];
        for dy in 0..2 {
            for dx in 0..2 {
                texels[(cy + dy).min(h - 1) * w + (cx + dx) % w] = [5.0, 5.0, 5.0];
            }
        }
        let path = dir.path().join("sky.exr");
        synth::write_environment_exr(&path, w, h, &texels).unwrap();
        let map = EnvironmentMap::read(&path).unwrap();
        assert!(map.lookup(d)[0] > 0.5, "lookup towards {d:?} sees the bright patch");
        let light = Light::Environment { map, strength: 2.0 };
        let sh = light.sh_coefficients(2);
        let band1 = [sh[3][0], sh[1][0], sh[2][0]];
        let len = band1.iter().map(|x| x * x).sum::<f64>().sqrt();
        let cos = (band1[0] * d[0] + band1[1] * d[1] + band1[2] * d[2]) / len;
        // The patch's centre sits within one texel (1.4 degrees) of d.
        assert!(cos > (3.0f64).to_radians().cos(), "target {d:?}: band 1 {band1:?}, cos {cos}");
    }
}

#[test]
fn constant_map_projects_to_its_dc_term() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sky.exr");
    synth::write_environment_exr(&path, 64, 32, &vec![[1.0, 0.5, 0.25]; 64 * 32]).unwrap();
    let light = Light::Environment { map: EnvironmentMap::read(&path).unwrap(), strength: 1.0 };
    let sh = light.sh_coefficients(3);
    let dc = 2.0 * PI.sqrt();
    // The basis is integrated exactly over each texel, so a constant map gives its DC
    // term alone, to rounding (1e-12).
    assert!((sh[0][0] - dc).abs() < 1e-12 && (sh[0][1] - 0.5 * dc).abs() < 1e-12, "{:?}", sh[0]);
    for c in &sh[1..] {
        assert!(c.iter().all(|v| v.abs() < 1e-12), "{c:?}");
    }
    assert_eq!(light.radiance([0.3, 0.2, -0.9]), [1.0, 0.5, 0.25]);
}

#[test]
fn constant_light_sh_is_dc_only() {
    let light = Light::Constant([1.0, 2.0, 0.5]);
    let sh = light.sh_coefficients(4);
    assert_eq!(sh.len(), 16);
    let k = 2.0 * PI.sqrt();
    assert!((sh[0][0] - k).abs() < 1e-12 && (sh[0][1] - 2.0 * k).abs() < 1e-12 && (sh[0][2] - 0.5 * k).abs() < 1e-12);
    assert!(sh[1..].iter().all(|c| *c == [0.0; 3]));
    assert_eq!(light.radiance([0.0, 0.0, 1.0]), [1.0, 2.0, 0.5]);
}

#[test]
fn sh_light_is_padded_truncated_and_clamped() {
    let dir = base_scene();
    let coeffs = serde_json::json!([[1, 1, 1], [0, 0, 0], [0.5, 0.5, 0.5], [0, 0, 0]]);
    edit_json(&dir.path().join("scene.json"), |v| v["light"] = serde_json::json!({"sh": coeffs}));
    let scene = Scene::load(dir.path()).unwrap();
    let light = scene.light(1).unwrap();
    let sh = light.sh_coefficients(3);
    assert_eq!(sh.len(), 9);
    assert_eq!(sh[2], [0.5; 3]);
    assert!(sh[4..].iter().all(|c| *c == [0.0; 3]));
    assert_eq!(light.sh_coefficients(1), vec![[1.0; 3]]);
    // 1 * y00 + 0.5 * y10(z): y00 = 0.2821, y10 at +Z = 0.4886, at -Z = -0.4886.
    let up = light.radiance([0.0, 0.0, 1.0])[0] as f64;
    let y00 = 0.5 / PI.sqrt();
    let y10 = (3.0 / (4.0 * PI)).sqrt();
    assert!((up - (y00 + 0.5 * y10)).abs() < 1e-6, "{up}");
    let strong_down = Light::Sh(vec![[0.1; 3], [0.0; 3], [1.0; 3], [0.0; 3]]);
    assert_eq!(strong_down.radiance([0.0, 0.0, -1.0]), [0.0; 3], "clamped to >= 0");
}

// ---- outputs -----------------------------------------------------------------------

#[test]
fn outputs_round_trip_atomically() {
    let dir = tempfile::tempdir().unwrap();
    let rgba: Vec<[f32; 4]> = (0..6).map(|i| [i as f32 * 0.2, 0.5, 2.0, 0.5]).collect();
    let exr_path = dir.path().join("out.exr");
    write_exr_rgba(&exr_path, 3, 2, &rgba).unwrap();
    let img = exr::prelude::read_first_flat_layer_from_file(&exr_path).unwrap();
    let names: Vec<String> = img.layer_data.channel_data.list.iter().map(|c| c.name.to_string()).collect();
    assert_eq!(names, ["A", "B", "G", "R"]);
    match &img.layer_data.channel_data.list[3].sample_data {
        FlatSamples::F32(v) => assert_eq!(v, &rgba.iter().map(|p| p[0]).collect::<Vec<_>>()),
        other => panic!("{other:?}"),
    }

    let png_path = dir.path().join("out.png");
    write_png_preview(&png_path, 3, 2, &rgba, &ViewTransform::default()).unwrap();
    let png = image::open(&png_path).unwrap().to_rgba8();
    // sRGB(0.5) = 0.7354 -> 188; 2.0 clamps to 255; opaque, as Blender's film is by default.
    assert_eq!(png.get_pixel(0, 0).0, [0, 188, 255, 255]);
    // With Film > Transparent, alpha 0.5 -> 128 (kept linear); exposure +1 doubles 0.2 to
    // 0.4, sRGB 0.665 -> 170.
    let spec: ViewSpec =
        serde_json::from_value(serde_json::json!({"transform": "Standard", "exposure": 1.0, "transparent": true}))
            .unwrap();
    let view = ViewTransform::load(&spec, dir.path(), &png_path).unwrap();
    write_png_preview(&png_path, 3, 2, &rgba, &view).unwrap();
    let png = image::open(&png_path).unwrap().to_rgba8();
    assert_eq!(png.get_pixel(1, 0).0, [170, 255, 255, 128]);
    // A larger frame (converted in parallel, in chunks of pixels): every pixel as the view
    // transform gives it, one at a time.
    let (width, height) = (97, 61);
    let ramp: Vec<[f32; 4]> =
        (0..width * height).map(|i| [i as f32 / 5000.0, (i % 97) as f32 / 40.0, 0.25, (i % 7) as f32 / 6.0]).collect();
    write_png_preview(&png_path, width, height, &ramp, &view).unwrap();
    let png = image::open(&png_path).unwrap().to_rgba8();
    let q = |v: f32| (v * 255.0 + 0.5).clamp(0.0, 255.0) as u8;
    for (i, p) in ramp.iter().enumerate() {
        let [r, g, b] = view.display([p[0], p[1], p[2]], 0.0);
        let pixel = png.get_pixel((i % width) as u32, (i / width) as u32).0;
        assert_eq!(pixel, [q(r), q(g), q(b), q(p[3])], "pixel {i}");
    }
    let leftovers: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(leftovers.len(), 2, "no temporary files left: {leftovers:?}");

    assert!(write_exr_rgba(&exr_path, 4, 2, &rgba).is_err(), "size mismatch is refused");
}

#[test]
fn outputs_never_overwrite_inputs() {
    let dir = base_scene();
    let scene = Scene::load(dir.path()).unwrap();
    let inputs = scene.input_paths(1);
    assert!(inputs.contains(&dir.path().join("gbuffer.0001.exr")) && inputs.contains(&dir.path().join("scene.json")));
    for bad in ["gbuffer.0001.exr", "gbuffer.0042.exr", "camera.0003.json", "scene.json", "./sub/../blockers.0001.json"]
    {
        let err = scene.check_output_path(&dir.path().join(bad)).unwrap_err();
        assert!(matches!(err, SceneError::OutputIsInput { .. }), "{bad}: {err:?}");
    }
    for good in ["beauty.0001.exr", "preview.png", "gbuffer.0001.png"] {
        scene.check_output_path(&dir.path().join(good)).unwrap();
    }
}

/// The per-texel projection against the crate's Gauss product quadrature of the same
/// smooth function (independent method). Tolerance 2e-3: the map holds the function's
/// value at texel centres, a piecewise-constant approximation with error of order the
/// squared texel size (1.4 degrees) per coefficient.
#[test]
fn environment_projection_matches_quadrature() {
    let f = |d: [f64; 3]| 1.0 + d[0] + 0.5 * d[1] * d[2] + 0.3 * d[1];
    let (w, h) = (256, 128);
    let mut texels = Vec::with_capacity(w * h);
    for row in 0..h {
        for col in 0..w {
            let d = equirectangular_to_direction((col as f64 + 0.5) / w as f64, 1.0 - (row as f64 + 0.5) / h as f64);
            texels.push([f(d) as f32; 3]);
        }
    }
    let map = EnvironmentMap { file: "memory".into(), width: w, height: h, texels };
    let ours = Light::Environment { map, strength: 1.0 }.sh_coefficients(4);
    let reference: Vec<f64> = logsh::sh::SphereQuadrature::gauss(24).project(4, f);
    for (i, (a, b)) in ours.iter().zip(&reference).enumerate() {
        assert!((a[0] - b).abs() < 2e-3, "coefficient {i}: {} vs {b}", a[0]);
    }
}

#[test]
fn height_map_lookup_handles_thin_maps_built_in_memory() {
    use logsh::scene::HeightMap;
    let single = HeightMap { heights: vec![2.5], columns: 1, rows: 1, min: [0.0, 0.0], max: [1.0, 1.0] };
    assert_eq!(single.height_at(0.3, 7.0), 2.5);
    let row = HeightMap { heights: vec![0.0, 1.0, 3.0], columns: 3, rows: 1, min: [0.0, 0.0], max: [2.0, 1.0] };
    assert_eq!(row.height_at(1.5, 0.5), 2.0);
    assert_eq!(row.height_at(9.0, -4.0), 3.0);
}

#[test]
fn truncated_exr_says_so() {
    let dir = base_scene();
    let file = dir.path().join("gbuffer.0001.exr");
    let bytes = std::fs::read(&file).unwrap();
    for keep in [bytes.len() / 2, 200, 10] {
        std::fs::write(&file, &bytes[..keep]).unwrap();
        let err = frame_error(dir.path());
        assert!(matches!(err, SceneError::Image { .. }), "{keep} bytes: {err:?}");
        assert_mentions(&err, &["gbuffer.0001.exr"]);
    }
    std::fs::write(&file, &bytes[..bytes.len() / 2]).unwrap();
    assert_mentions(&frame_error(dir.path()), &["ends early or is damaged"]);
}

/// An edit of scene.json and the words its error must contain.
type SceneEdit = (Box<dyn Fn(&mut serde_json::Value)>, &'static [&'static str]);

#[test]
fn paths_outside_the_scene_directory_are_refused() {
    let cases: Vec<SceneEdit> = vec![
        (Box::new(|v| v["gbuffer"] = "../gbuffer.####.exr".into()), &["\"gbuffer\"", "climbs out"]),
        (Box::new(|v| v["camera"] = "cams/../../camera.####.json".into()), &["\"camera\"", "climbs out"]),
        (Box::new(|v| v["blockers"] = "/tmp/blockers.####.json".into()), &["\"blockers\"", "absolute and outside"]),
        (Box::new(|v| v["reflection_gbuffer"] = "C:\\shots\\r.exr".into()), &["\"reflection_gbuffer\"", "absolute"]),
        (
            Box::new(|v| v["heightfield"] = serde_json::json!({"heights": "../h.exr", "min": [0, 0], "max": [1, 1]})),
            &["\"heightfield.heights\"", "climbs out"],
        ),
        (Box::new(|v| v["light"] = serde_json::json!({"environment": "../../sky.exr"})), &["\"light.environment\""]),
    ];
    for (edit, parts) in cases {
        let dir = base_scene();
        edit_json(&dir.path().join("scene.json"), |v| edit(v));
        let err = Scene::load(dir.path()).unwrap_err();
        assert_mentions(&err, &["scene.json", "inside the scene directory"]);
        assert_mentions(&err, parts);
    }
    // An absolute path inside the scene directory, and `..` that stays inside, are fine.
    let dir = base_scene();
    let inside = dir.path().join("gbuffer.####.exr").display().to_string();
    std::fs::create_dir(dir.path().join("sub")).unwrap();
    edit_json(&dir.path().join("scene.json"), |v| {
        v["gbuffer"] = inside.into();
        v["camera"] = "sub/../camera.####.json".into();
    });
    Scene::load(dir.path()).unwrap().frame(1).unwrap();
}

/// `"colour_passes": true`: the G-buffer must hold the Diffuse Color and Glossy Color
/// passes (Blender 4's names found too), finite and `>= 0` on surface pixels; a missing
/// channel, NaN or a negative colour is an error naming the file, the pass and the pixel.
#[test]
fn colour_passes_are_required_and_checked() {
    let dir = base_scene();
    edit_json(&dir.path().join("scene.json"), |v| v["colour_passes"] = serde_json::json!(true));
    let err = frame_error(dir.path());
    assert!(matches!(err, SceneError::MissingChannel { .. }), "{err:?}");
    assert_mentions(&err, &["gbuffer.0001.exr", "ViewLayer.Diffuse Color.R"]);

    let with_colours = |diffuse: f32, glossy_at_6_1: f32| {
        let mut channels = gbuffer_channels(32, 18, |x, _| if x < 4 { 0.0 } else { 1.0 });
        for c in ["R", "G", "B"] {
            let name = |pass: &str| -> &'static str { Box::leak(format!("ViewLayer.{pass}.{c}").into_boxed_str()) };
            channels.push((name("DiffCol"), vec![diffuse; 32 * 18]));
            let mut glossy = vec![0.5; 32 * 18];
            glossy[32 + 6] = glossy_at_6_1;
            glossy[1] = f32::NAN; // pixel (1, 0) is background: ignored
            channels.push((name("GlossCol"), glossy));
        }
        write_raw_exr(&dir.path().join("gbuffer.0001.exr"), 32, 18, channels);
    };
    with_colours(0.25, 0.5);
    let frame = Scene::load(dir.path()).unwrap().frame(1).unwrap();
    assert_eq!(frame.gbuffer.colours_at(32 + 6), Some(([0.25; 3], [0.5; 3])));
    with_colours(0.25, f32::NAN);
    let err = frame_error(dir.path());
    assert!(matches!(err, SceneError::NonFinite { .. }), "{err:?}");
    assert_mentions(&err, &["gbuffer.0001.exr", "Glossy Color", "pixel (6, 1)"]);
    with_colours(-0.25, 0.5);
    assert_mentions(&frame_error(dir.path()), &["gbuffer.0001.exr", "Diffuse Color", "pixel (4, 0)", "negative"]);

    // Names the passes by another name; without colour_passes such a name is refused.
    with_colours(0.25, 0.5);
    edit_json(&dir.path().join("scene.json"), |v| {
        v["channels"] = serde_json::json!({"glossy_colour": ["Gloss.R", "Gloss.G", "Gloss.B"]})
    });
    assert_mentions(&frame_error(dir.path()), &["gbuffer.0001.exr", "missing channel \"Gloss.R\""]);
    edit_json(&dir.path().join("scene.json"), |v| v["colour_passes"] = serde_json::json!(false));
    let err = Scene::load(dir.path()).unwrap_err();
    assert_mentions(&err, &["scene.json", "glossy_colour", "colour_passes"]);
}

/// [`base_scene`] with `per_frame` and frame 1's file holding `changes`, and a height field
/// whose map is per frame (`heightmap.0001.exr`, 9x9, flat at 0.5).
fn scene_with_frame_file(changes: serde_json::Value) -> tempfile::TempDir {
    let dir = base_scene();
    let map = logsh::scene::HeightMap::from_fn(9, 9, [-4.0, -4.0], [4.0, 4.0], |_, _| 0.5);
    synth::write_height_map_exr(&dir.path().join("heightmap.0001.exr"), &map).unwrap();
    edit_json(&dir.path().join("scene.json"), |v| {
        v["per_frame"] = serde_json::json!("frame.####.json");
        v["heightfield"] = serde_json::json!({"heights": "heightmap.####.exr", "min": [-4, -4], "max": [4, 4]});
    });
    std::fs::write(dir.path().join("frame.0001.json"), serde_json::to_string_pretty(&changes).unwrap()).unwrap();
    dir
}

/// A frame's file replaces scene.json's lamps, changes the World and moves the height
/// map's rectangle; without a key, scene.json's value stands.
#[test]
fn a_frame_file_changes_lamps_light_and_rectangle() {
    let lamp = serde_json::json!({"type": "point", "position": [0.5, 0.0, 0.6], "radius": 0.1, "power": 150});
    let dir = scene_with_frame_file(serde_json::json!({
        "frame": 1,
        "lights": [lamp],
        "light": {"constant": [0.25, 0.5, 0.75]},
        "heightfield": {"min": [-3, -5], "max": [5, 3]}
    }));
    let scene = Scene::load(dir.path()).unwrap();
    let frame = scene.frame(1).unwrap();
    assert_eq!(frame.points.len(), 1);
    assert_eq!(frame.points[0].position, [0.5, 0.0, 0.6]);
    assert!(frame.suns.is_empty());
    assert!(matches!(*frame.light, Light::Constant(c) if c == [0.25, 0.5, 0.75]), "{:?}", frame.light);
    let map = frame.height_map.as_ref().unwrap();
    assert_eq!((map.min, map.max), ([-3.0, -5.0], [5.0, 3.0]));
    assert!(scene.input_paths(1).iter().any(|p| p.ends_with("frame.0001.json")));

    let dir = scene_with_frame_file(serde_json::json!({"frame": 1}));
    let frame = Scene::load(dir.path()).unwrap().frame(1).unwrap();
    assert!(frame.points.is_empty());
    assert!(matches!(*frame.light, Light::Constant(c) if c == [1.0, 1.0, 1.0]), "{:?}", frame.light);
    assert_eq!(frame.height_map.as_ref().unwrap().min, [-4.0, -4.0]);
}

/// A frame file that is missing, for another frame, malformed or inconsistent with
/// scene.json is refused, naming the file; so is a per-frame height map that is missing.
#[test]
fn bad_frame_files_are_refused_naming_the_file() {
    let cases: Vec<(serde_json::Value, &[&str])> = vec![
        (serde_json::json!({"frame": 2}), &["frame.0001.json", "\"frame\" is 2"]),
        (
            serde_json::json!({"frame": 1, "heightfield": {"min": [3, -4], "max": [-3, 4]}}),
            &["frame.0001.json", "min", "below max"],
        ),
        (serde_json::json!({"frame": 1, "light": {"strength": 2}}), &["frame.0001.json", "constant"]),
        (serde_json::json!({"frame": 1, "light": {"constant": [1, -1, 1]}}), &["frame.0001.json", "negative"]),
        (
            serde_json::json!({"frame": 1, "lights": [{"type": "point", "position": [0, 0, 1], "power": 1}]}),
            &["frame.0001.json", "lights[0]", "radius"],
        ),
        (serde_json::json!({"frame": 1, "lamps": []}), &["frame.0001.json", "lamps"]),
    ];
    for (changes, parts) in cases {
        let dir = scene_with_frame_file(changes);
        assert_mentions(&frame_error(dir.path()), parts);
    }
    let dir = scene_with_frame_file(serde_json::json!({"frame": 1}));
    std::fs::remove_file(dir.path().join("frame.0001.json")).unwrap();
    assert_mentions(&frame_error(dir.path()), &["frame.0001.json", "not found"]);

    let dir = scene_with_frame_file(serde_json::json!({"frame": 1}));
    std::fs::remove_file(dir.path().join("heightmap.0001.exr")).unwrap();
    assert_mentions(&frame_error(dir.path()), &["heightmap.0001.exr", "not found"]);

    // A map that is not the frame's terrain: the plane's pixels lie 1.5 m under it.
    let dir = scene_with_frame_file(serde_json::json!({"frame": 1}));
    let buried = logsh::scene::HeightMap::from_fn(9, 9, [-4.0, -4.0], [4.0, 4.0], |_, _| 1.5);
    synth::write_height_map_exr(&dir.path().join("heightmap.0001.exr"), &buried).unwrap();
    assert_mentions(&frame_error(dir.path()), &["gbuffer.0001.exr", "heightmap.0001.exr", "not this frame's terrain"]);

    let dir = scene_with_frame_file(serde_json::json!({"frame": 1}));
    edit_json(&dir.path().join("scene.json"), |v| v["per_frame"] = serde_json::json!("frame.json"));
    assert_mentions(&Scene::load(dir.path()).unwrap_err(), &["per_frame", "#"]);
}
