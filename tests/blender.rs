//! The Blender exporter end to end, with Blender as a Python module (pip's `bpy`): build
//! a small scene (`blender_scripts/scenes/tiny.py`: ground, water patch, a still and a
//! moving sphere, grey World), export two frames with the script's defaults, read them
//! with the scene reader, shade them with `logsh shade`.
//!
//! The interpreter is the one named by `LOGSH_BPY_PYTHON` (`.ci/bpy-setup` makes one in
//! `.venv-bpy`). Unset, or unable to import bpy, each test prints why it is skipped and
//! passes, unless `LOGSH_REQUIRE_BPY=1`, where that is a failure (CI sets both).
use crate::support;

use assert_cmd::Command;
use exr::prelude::{read, FlatSamples, ReadChannels, ReadLayers};
use logsh::scene::{Scene, Sphere};
use logsh::shade::ShadingSettings;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Output;

const REPO: &str = env!("CARGO_MANIFEST_DIR");

/// The bpy interpreter, or `None` (with a printed reason) when these tests are skipped.
fn bpy_python() -> Option<PathBuf> {
    let required = std::env::var("LOGSH_REQUIRE_BPY").is_ok_and(|v| v == "1");
    let skip = |why: String| {
        assert!(!required, "LOGSH_REQUIRE_BPY=1 but {why}");
        // Written to the stderr handle itself, which the test harness does not capture, so
        // that the skip shows in a plain `cargo test` run.
        let line = format!(
            "tests/blender.rs skipped: {why}; set LOGSH_BPY_PYTHON to a Python that imports bpy (see .ci/bpy-setup)\n"
        );
        let _ = std::io::Write::write_all(&mut std::io::stderr(), line.as_bytes());
        None
    };
    let Some(python) = std::env::var_os("LOGSH_BPY_PYTHON") else {
        return skip("LOGSH_BPY_PYTHON is not set".into());
    };
    let python = PathBuf::from(python);
    match std::process::Command::new(&python).args(["-c", "import bpy"]).output() {
        Ok(o) if o.status.success() => Some(python),
        Ok(o) => skip(format!("{} cannot import bpy: {}", python.display(), String::from_utf8_lossy(&o.stderr).trim())),
        Err(e) => skip(format!("{} cannot be run: {e}", python.display())),
    }
}

fn run_python(python: &Path, script: &str, args: &[&Path]) -> Output {
    let mut command = std::process::Command::new(python);
    command.arg(Path::new(REPO).join(script));
    for a in args {
        command.arg(a);
    }
    command.output().unwrap()
}

/// Saves `path`: an empty factory scene (with `bpy` and `math` imported) after the bpy
/// statements `scene`.
fn make_blend(python: &Path, path: &Path, scene: &str) {
    let script = format!(
        "import bpy, math; bpy.ops.wm.read_factory_settings(use_empty=True); {scene}; \
         bpy.ops.wm.save_as_mainfile(filepath={:?})",
        path.to_str().unwrap()
    );
    assert_ok(&std::process::Command::new(python).args(["-c", &script]).output().unwrap(), "making a .blend");
}

/// Exports frame 1 of `blend` into `out` at `resolution` ("WxH").
fn export_frame_1(python: &Path, blend: &Path, out: &Path, resolution: &str) -> Output {
    let (resolution, frames) = (Path::new(resolution), Path::new("1-1"));
    let args = [Path::new("--blend"), blend, Path::new("--out"), out, Path::new("--resolution"), resolution];
    run_python(python, "blender_scripts/export_scene.py", &[&args[..], &[Path::new("--frames"), frames]].concat())
}

/// [`export_frame_1`] with `--sun-shadow-resolution sun_shadows`.
fn export_frame_1_with_sun_shadows(
    python: &Path,
    blend: &Path,
    out: &Path,
    resolution: &str,
    sun_shadows: &str,
) -> Output {
    let (resolution, frames) = (Path::new(resolution), Path::new("1-1"));
    let args = [Path::new("--blend"), blend, Path::new("--out"), out, Path::new("--resolution"), resolution];
    let options = [Path::new("--frames"), frames, Path::new("--sun-shadow-resolution"), Path::new(sun_shadows)];
    run_python(python, "blender_scripts/export_scene.py", &[&args[..], &options].concat())
}

fn assert_ok(output: &Output, what: &str) {
    assert!(
        output.status.success(),
        "{what} failed:\n{}\n{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
}

/// Builds the tiny scene and exports it into `dir/scene`.
fn export_tiny(python: &Path, dir: &Path) -> PathBuf {
    let blend = dir.join("tiny.blend");
    assert_ok(&run_python(python, "blender_scripts/scenes/tiny.py", &[Path::new("--save"), &blend]), "tiny.py");
    let scene = dir.join("scene");
    let output = run_python(
        python,
        "blender_scripts/export_scene.py",
        &[Path::new("--blend"), &blend, Path::new("--out"), &scene],
    );
    assert_ok(&output, "export_scene.py");
    let log = String::from_utf8_lossy(&output.stdout);
    assert!(log.contains("volume error"), "the export prints each fit's error:\n{log}");
    // An existing scene is never written over.
    let again = run_python(
        python,
        "blender_scripts/export_scene.py",
        &[Path::new("--blend"), &blend, Path::new("--out"), &scene],
    );
    assert_eq!(again.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&again.stderr).contains("already holds a scene"));
    scene
}

/// Every channel of an EXR by full name (part name prefixed in multi-part files).
fn raw_channels(file: &Path) -> HashMap<String, Vec<f32>> {
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .from_file(file)
        .unwrap();
    let mut out = HashMap::new();
    for layer in &image.layer_data {
        let part = layer.attributes.layer_name.as_ref().map(|t| t.to_string()).unwrap_or_default();
        for channel in &layer.channel_data.list {
            let name = channel.name.to_string();
            let full =
                if part.is_empty() || name.starts_with(&format!("{part}.")) { name } else { format!("{part}.{name}") };
            let values = match &channel.sample_data {
                FlatSamples::F32(v) => v.clone(),
                FlatSamples::F16(v) => v.iter().map(|h| h.to_f32()).collect(),
                FlatSamples::U32(v) => v.iter().map(|&u| u as f32).collect(),
            };
            out.insert(full, values);
        }
    }
    out
}

#[test]
fn tiny_scene_exports_reads_and_shades() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let scene_dir = export_tiny(&python, dir.path());
    let scene = Scene::load(&scene_dir).unwrap();
    assert_eq!(scene.frame_numbers(usize::MAX), [1, 2]);

    // Blender 5's multi-part G-buffer names the index "Material Index"; the reflection
    // G-buffer is written in Blender 4's single-part layout ("IndexMA"): one scene reads both.
    let gbuffer = raw_channels(&scene_dir.join("gbuffer.0001.exr"));
    let reflection = raw_channels(&scene_dir.join("reflection.0001.exr"));
    let index = &gbuffer["ViewLayer.Material Index.X"];
    assert!(reflection.contains_key("ViewLayer.IndexMA.X"));
    // Data passes are not blended at edges: material indices are exactly whole everywhere.
    for (i, &m) in index.iter().enumerate() {
        assert_eq!(m, m.round(), "pixel {i}: material index {m} is not whole");
    }

    let mut frames = Vec::new();
    for number in 1..=2 {
        let frame = scene.frame(number).unwrap();
        let g = &frame.gbuffer;
        assert_eq!([g.width, g.height], [64, 36]);
        let surface: Vec<usize> = (0..g.material.len()).filter(|&i| g.material[i] != 0).collect();
        assert!(surface.len() > g.material.len() / 2, "most of the frame is geometry");
        // Normals are unit length within half-float-like rounding (1e-3).
        for &i in &surface {
            let n = g.normal[i];
            let length = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            assert!((length - 1.0).abs() < 1e-3, "pixel {i}: normal {n:?} has length {length}");
        }
        let water: Vec<u32> =
            scene.materials.iter().filter(|(_, m)| m.type_name() == "water").map(|(&i, _)| i).collect();
        assert_eq!(water.len(), 1);
        let reflection = frame.reflection.as_ref().unwrap();
        let water_pixels = g.material.iter().filter(|&&m| m == water[0]).count();
        let reflected_surface =
            (0..g.material.len()).filter(|&i| g.material[i] == water[0] && reflection.material[i] != 0).count();
        assert!(water_pixels > 20, "the water patch is in view ({water_pixels} pixels)");
        assert!(reflected_surface > 0, "some water pixels mirror a ball");
        frames.push(frame);
    }

    // Each UV sphere becomes one sphere within 1 % of its radius; blockers follow the
    // animation: the still ball's sphere stays, the moving ball's moves by its keyframed
    // offset (1, 1.5, 0.8) -> (1, -1, 1.5), radius unchanged.
    let (a, b) = (&frames[0].blockers, &frames[1].blockers);
    assert_eq!(a.len(), 2, "{a:?}");
    assert_eq!(b.len(), 2, "{b:?}");
    let fits = |s: &Sphere, c: [f64; 3], r: f64| {
        let d = ((s.center[0] - c[0]).powi(2) + (s.center[1] - c[1]).powi(2) + (s.center[2] - c[2]).powi(2)).sqrt();
        d <= 0.01 * r && (s.radius - r).abs() <= 0.01 * r
    };
    let still = a.iter().position(|s| fits(s, [-1.5, 0.0, 1.0], 1.0)).expect("the still ball's sphere");
    let moving = a.iter().position(|s| fits(s, [1.0, 1.5, 0.8], 0.8)).expect("the moving ball's sphere");
    assert_ne!(still, moving);
    let delta = [0.0, -2.5, 0.7];
    for (k, shift) in [(still, [0.0; 3]), (moving, delta)] {
        let (s, t) = (&a[k], &b[k]);
        assert!((s.radius - t.radius).abs() < 1e-5);
        for axis in 0..3 {
            assert!((t.center[axis] - s.center[axis] - shift[axis]).abs() < 1e-4, "sphere {k}: {s:?} -> {t:?}");
        }
    }

    // The spheres and the G-buffer's Object Index pass name the same objects: the pixels of
    // each ball carry its spheres' object index, the ground none of them.
    let g = &frames[0].gbuffer;
    let objects = g.object.as_ref().expect("the G-buffer has an object index pass");
    assert!(a.iter().all(|s| s.object != 0) && a[still].object != a[moving].object);
    for (k, centre) in [(still, [-1.5, 0.0, 1.0]), (moving, [1.0, 1.5, 0.8])] {
        let on_ball = (0..g.material.len())
            .filter(|&i| {
                let p = g.position[i].map(f64::from);
                let d = ((p[0] - centre[0]).powi(2) + (p[1] - centre[1]).powi(2) + (p[2] - centre[2]).powi(2)).sqrt();
                g.material[i] != 0 && (d - a[k].radius).abs() < 0.02
            })
            .collect::<Vec<_>>();
        assert!(!on_ball.is_empty(), "ball {k} is in view");
        assert!(on_ball.iter().all(|&i| objects[i] == a[k].object), "ball {k}'s pixels carry its object index");
    }

    // logsh shades both frames.
    for number in ["1", "2"] {
        let out = dir.path().join("out");
        let output = crate::support::cli::logsh()
            .args(["shade"])
            .arg(&scene_dir)
            .args(["--frame", number, "--out"])
            .arg(&out)
            .output()
            .unwrap();
        assert_ok(&output, "logsh shade");
        let png = image::open(out.join(format!("beauty.000{number}.png"))).unwrap().to_rgb8();
        assert_eq!(png.dimensions(), (64, 36));
    }
}

#[test]
fn export_fails_clearly() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    // No camera: nothing to export.
    let blend = dir.path().join("no_camera.blend");
    make_blend(&python, &blend, "bpy.ops.mesh.primitive_cube_add()");
    let out = dir.path().join("out");
    let output = run_python(
        &python,
        "blender_scripts/export_scene.py",
        &[Path::new("--blend"), &blend, Path::new("--out"), &out],
    );
    assert_eq!(output.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("error: the scene has no camera"), "{stderr}");

    // An Area lamp: logsh would leave it out, so the export stops and names it, leaving no
    // output directory behind.
    let blend = dir.path().join("area.blend");
    make_blend(
        &python,
        &blend,
        "bpy.ops.mesh.primitive_cube_add(); \
         bpy.ops.object.camera_add(location=(6, -6, 4)); bpy.context.scene.camera = bpy.context.object; \
         bpy.ops.object.light_add(type='AREA'); bpy.context.object.name = 'Panel'",
    );
    let output = run_python(
        &python,
        "blender_scripts/export_scene.py",
        &[Path::new("--blend"), &blend, Path::new("--out"), &out],
    );
    assert_eq!(output.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("error: light \"Panel\" is an Area lamp"), "{stderr}");
    assert!(!out.exists(), "a failed export left {} behind", out.display());

    // No .blend at all.
    let output = run_python(&python, "blender_scripts/export_scene.py", &[Path::new("--out"), &out]);
    assert_eq!(output.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&output.stderr).contains("error: no .blend given"));
}

/// A Sun lamp becomes a `sun` light of scene.json (direction towards it, Angle, Strength,
/// Color), and logsh shades the scene with it.
#[test]
fn sun_lamp_exports_as_a_sun_light() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let blend = dir.path().join("sun.blend");
    make_blend(
        &python,
        &blend,
        "bpy.ops.mesh.primitive_plane_add(size=8); bpy.ops.mesh.primitive_cube_add(location=(0, 0, 1)); \
         bpy.ops.object.camera_add(location=(7, -7, 5), rotation=(math.radians(63), 0, math.radians(45))); \
         bpy.context.scene.camera = bpy.context.object; \
         bpy.ops.object.light_add(type='SUN', rotation=(math.radians(40), 0, math.radians(30))); \
         sun = bpy.context.object.data; sun.energy = 3.5; sun.angle = math.radians(2); sun.color = (1, 0.9, 0.8); \
         w = bpy.data.worlds.new('World'); bpy.context.scene.world = w; w.use_nodes = True; \
         w.node_tree.nodes['Background'].inputs['Color'].default_value = (0.2, 0.2, 0.2, 1)",
    );
    let out = dir.path().join("scene");
    let output = export_frame_1(&python, &blend, &out, "48x27");
    assert_ok(&output, "exporting a scene with a Sun lamp");
    let scene = Scene::load(&out).unwrap();
    // The plane under the cube is the ground.
    assert!(scene.ground.is_some_and(|z| z.abs() < 1e-6), "ground {:?}", scene.ground);
    assert_eq!(scene.suns.len(), 1);
    let sun = scene.suns[0];
    let (a, b) = (40f64.to_radians(), 30f64.to_radians());
    let expected = [a.sin() * b.sin(), -a.sin() * b.cos(), a.cos()];
    for k in 0..3 {
        assert!((sun.direction[k] - expected[k]).abs() < 1e-5, "direction {:?}, expected {expected:?}", sun.direction);
    }
    assert!((sun.half_angle - 1f64.to_radians()).abs() < 1e-6);
    assert_eq!(sun.strength, 3.5);
    assert!((sun.color[1] - 0.9).abs() < 1e-6 && (sun.color[2] - 0.8).abs() < 1e-6);
    let shaded = dir.path().join("shaded");
    let output = crate::support::cli::logsh()
        .args(["shade", "--device", "cpu", "--out"])
        .arg(&shaded)
        .arg(&out)
        .output()
        .unwrap();
    assert_ok(&output, "logsh shade");
}

/// Each sun gets a shadow map of the blockers' own surfaces (`sun_shadows` of
/// blockers.####.json, `exporter.py`): a 2 m cube standing on a plane under a Sun lamp 30
/// degrees from vertical. The entry's axis is the lamp's direction as scene.json has it,
/// `right`, `up` and `axis` are orthonormal and right-handed, and the plane lies beyond the
/// cube towards the sun; the image is one scan-line part of float `Z` and `Zfar`, square
/// texels, 1024 along its longer side, the cube's outline 2 texels inside its edges. The
/// ray through every texel centre enters and leaves the cube (slab test) at the texel's `Z`
/// and `Zfar` within 0.1 mm, and misses it where `Z` is 1e9 or more: the plane, flat and
/// without spheres, is not in the map. The texels over points of the top and of the two lit
/// sides hold those points' `(origin - x) . axis` within 1.5 texels' worth of the face's
/// slope (the texel centre lies within 0.71 texel of the point, and the depth changes by
/// tan(angle between the face's normal and the axis) per metre across the map). Without
/// maps (`--sun-shadow-resolution 0`) the key is left out; 32 stops the export.
#[test]
fn sun_shadow_map_holds_the_blockers_depth() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let blend = dir.path().join("cube.blend");
    make_blend(
        &python,
        &blend,
        "bpy.ops.mesh.primitive_plane_add(size=8); bpy.ops.mesh.primitive_cube_add(size=2, location=(0, 0, 1)); \
         bpy.ops.object.camera_add(location=(7, -7, 5), rotation=(math.radians(63), 0, math.radians(45))); \
         bpy.context.scene.camera = bpy.context.object; \
         bpy.ops.object.light_add(type='SUN', rotation=(math.radians(30), 0, math.radians(40))); \
         w = bpy.data.worlds.new('World'); bpy.context.scene.world = w; w.use_nodes = True; \
         w.node_tree.nodes['Background'].inputs['Color'].default_value = (0.2, 0.2, 0.2, 1)",
    );
    let out = dir.path().join("scene");
    assert_ok(&export_frame_1(&python, &blend, &out, "32x18"), "exporting a cube under a Sun lamp");
    let json =
        |file: &Path| -> serde_json::Value { serde_json::from_str(&std::fs::read_to_string(file).unwrap()).unwrap() };
    let (description, blockers) = (json(&out.join("scene.json")), json(&out.join("blockers.0001.json")));
    let maps = blockers["sun_shadows"].as_array().expect("blockers.0001.json has sun_shadows");
    assert_eq!(maps.len(), 1, "{maps:?}");
    let map = &maps[0];
    assert_eq!(map["image"], "sun_shadow.0001.0.exr");
    assert_eq!(map["axis"], description["lights"][0]["direction"], "the axis is the sun's direction as written");
    let vector = |key: &str| -> [f64; 3] { serde_json::from_value(map[key].clone()).unwrap() };
    let (axis, origin, right, up) = (vector("axis"), vector("origin"), vector("right"), vector("up"));
    let [w, h]: [f64; 2] = serde_json::from_value(map["size"].clone()).unwrap();
    let dot = |p: [f64; 3], q: [f64; 3]| p[0] * q[0] + p[1] * q[1] + p[2] * q[2];
    let sub = |p: [f64; 3], q: [f64; 3]| [p[0] - q[0], p[1] - q[1], p[2] - q[2]];
    let cross =
        |p: [f64; 3], q: [f64; 3]| [p[1] * q[2] - p[2] * q[1], p[2] * q[0] - p[0] * q[2], p[0] * q[1] - p[1] * q[0]];
    let (a, b) = (30f64.to_radians(), 40f64.to_radians());
    let lamp = [a.sin() * b.sin(), -a.sin() * b.cos(), a.cos()];
    for k in 0..3 {
        assert!((axis[k] - lamp[k]).abs() < 1e-6, "axis {axis:?}, lamp {lamp:?}");
    }
    for (what, value, expected) in [
        ("right . right", dot(right, right), 1.0),
        ("up . up", dot(up, up), 1.0),
        ("right . up", dot(right, up), 0.0),
        ("right . axis", dot(right, axis), 0.0),
        ("up . axis", dot(up, axis), 0.0),
        ("(right x up) . axis", dot(cross(right, up), axis), 1.0),
    ] {
        assert!((value - expected).abs() < 1e-6, "{what} = {value}");
    }

    let image = out.join("sun_shadow.0001.0.exr");
    let meta = exr::meta::MetaData::read_from_file(&image, false).unwrap();
    assert_eq!(meta.headers.len(), 1, "one part");
    let header = &meta.headers[0];
    assert_eq!(header.blocks, exr::meta::BlockDescription::ScanLines);
    let names: Vec<String> = header.channels.list.iter().map(|c| c.name.to_string()).collect();
    assert_eq!(names, ["Z", "Zfar"]);
    assert!(header.channels.list.iter().all(|c| c.sample_type == exr::meta::attribute::SampleType::F32));
    let (nx, ny) = (header.layer_size.width(), header.layer_size.height());

    // The cube [-1, 1] x [-1, 1] x [0, 2]: the plane beyond it, square texels, 2 of them
    // between its outline and the edges along the longer side and at least 2 along the
    // other, whose texels are ceil(1024 x its span / the longer span), margins included.
    let corners: Vec<[f64; 3]> = (0..8)
        .map(|k| {
            [
                if k & 1 == 0 { -1.0 } else { 1.0 },
                if k & 2 == 0 { -1.0 } else { 1.0 },
                if k & 4 == 0 { 0.0 } else { 2.0 },
            ]
        })
        .collect();
    assert!(corners.iter().all(|&x| dot(sub(x, origin), axis) < 0.0), "the plane lies beyond the cube");
    let texel = w / nx as f64;
    assert!((h / ny as f64 - texel).abs() < 1e-9 * texel, "texels of {texel} x {} m", h / ny as f64);
    assert_eq!(nx.max(ny), 1024);
    let span = |v: [f64; 3]| {
        let along: Vec<f64> = corners.iter().map(|&x| dot(sub(x, origin), v)).collect();
        (along.iter().copied().fold(f64::INFINITY, f64::min), along.iter().copied().fold(f64::NEG_INFINITY, f64::max))
    };
    let ((u0, u1), (v0, v1)) = (span(right), span(up));
    let margins = [(u0 + w / 2.0) / texel, (w / 2.0 - u1) / texel, (v0 + h / 2.0) / texel, (h / 2.0 - v1) / texel];
    assert!(margins.iter().all(|&m| m > 2.0 - 1e-6), "margins of {margins:?} texels");
    let longer = if nx >= ny { &margins[..2] } else { &margins[2..] };
    assert!(longer.iter().all(|&m| (m - 2.0).abs() < 1e-6), "margins of {margins:?} texels");
    let (short, extent) = if nx >= ny { (ny as f64, v1 - v0) } else { (nx as f64, u1 - u0) };
    let wanted = (extent + 4.0 * texel) / texel;
    assert!(short >= wanted - 1e-6 && short < wanted + 1.0, "{short} texels along the shorter side, for {wanted}");

    let channels = raw_channels(&image);
    let (z, zfar) = (&channels["Z"], &channels["Zfar"]);
    assert_eq!(z.len(), nx * ny);
    // The ray from texel (i, j)'s centre c meets the point c - axis d at depth d.
    let centre = |i: usize, j: usize| -> [f64; 3] {
        let (s, t) = (((i as f64 + 0.5) / nx as f64 - 0.5) * w, (0.5 - (j as f64 + 0.5) / ny as f64) * h);
        [0, 1, 2].map(|k| origin[k] + right[k] * s + up[k] * t)
    };
    let slab = |c: [f64; 3]| -> Option<(f64, f64)> {
        let (lo, hi) = ([-1.0, -1.0, 0.0], [1.0, 1.0, 2.0]);
        let (mut near, mut far) = (f64::NEG_INFINITY, f64::INFINITY);
        for k in 0..3 {
            let (t0, t1) = ((c[k] - lo[k]) / axis[k], (c[k] - hi[k]) / axis[k]);
            near = near.max(t0.min(t1));
            far = far.min(t0.max(t1));
        }
        (near <= far).then_some((near, far))
    };
    let (mut hits, mut outline, mut worst) = (0usize, 0usize, 0f64);
    for j in 0..ny {
        for i in 0..nx {
            let at = j * nx + i;
            let border = i < 2 || j < 2 || i >= nx - 2 || j >= ny - 2;
            assert!(!border || z[at] >= 1e9, "texel ({i}, {j}) of the margin holds Z {}", z[at]);
            match slab(centre(i, j)) {
                Some((near, far)) if z[at] < 1e9 => {
                    hits += 1;
                    worst = worst.max((f64::from(z[at]) - near).abs()).max((f64::from(zfar[at]) - far).abs());
                }
                None if z[at] >= 1e9 => {}
                _ => outline += 1,
            }
        }
    }
    println!("{nx}x{ny} texels of {:.3} mm: {hits} on the cube, depths within {worst:.2e} m", 1000.0 * texel);
    assert!(worst < 1e-4, "Z or Zfar off the cube's by {worst} m");
    assert!(outline <= 8, "{outline} texels hit or miss the cube where the ray through their centre does not");
    // The cube's outline covers 4 (|ax| + |ay| + |az|) square metres of the plane.
    let area = 4.0 * (axis[0].abs() + axis[1].abs() + axis[2].abs());
    assert!((hits as f64 * texel * texel / area - 1.0).abs() < 0.01, "{hits} texels for {area} m2");
    let tan = |normal: [f64; 3]| {
        let c = dot(normal, axis).abs();
        (1.0 - c * c).sqrt() / c
    };
    let top = [0.0, 0.0, 1.0];
    for (x, normal) in [
        ([0.0, 0.0, 2.0], top),
        ([0.5, 0.5, 2.0], top),
        ([-0.6, 0.3, 2.0], top),
        ([1.0, 0.0, 1.0], [1.0, 0.0, 0.0]),
        ([0.0, -1.0, 1.0], [0.0, -1.0, 0.0]),
    ] {
        let d = sub(x, origin);
        let i = ((dot(d, right) / w + 0.5) * nx as f64).floor() as usize;
        let j = ((0.5 - dot(d, up) / h) * ny as f64).floor() as usize;
        let (got, expected, tolerance) =
            (f64::from(z[j * nx + i]), dot(sub(origin, x), axis), 1.5 * texel * tan(normal));
        assert!(
            (got - expected).abs() <= tolerance,
            "{x:?}: texel ({i}, {j}) holds Z {got}, the point {expected} (±{tolerance})"
        );
    }

    // No maps: no key, no image; a resolution out of range stops the export.
    let (none, refused) = (dir.path().join("no_maps"), dir.path().join("refused"));
    for (target, resolution) in [(&none, "0"), (&refused, "32")] {
        let output = export_frame_1_with_sun_shadows(&python, &blend, target, "32x18", resolution);
        if resolution == "0" {
            assert_ok(&output, "exporting without sun shadow maps");
        } else {
            assert_eq!(output.status.code(), Some(1));
            let stderr = String::from_utf8_lossy(&output.stderr);
            assert!(stderr.contains("error: sun shadow resolution 32 is neither 0"), "{stderr}");
        }
    }
    assert!(json(&none.join("blockers.0001.json")).get("sun_shadows").is_none());
    assert!(!none.join("sun_shadow.0001.0.exr").exists());
    assert!(!refused.exists(), "a refused export left {} behind", refused.display());
}

/// Point lamps become `point` lights of scene.json (world position, Radius, Power times
/// 2^Exposure, Color, Soft Falloff), and logsh shades them as Cycles renders them: a
/// plane and a cube under a sphere lamp and a Soft Falloff one, against Cycles at 256
/// samples (mean absolute error over the non-background pixels, relative to their mean).
/// A lamp setting logsh does not model stops the export with the lamp's name.
#[test]
fn point_lamps_export_and_shade_as_cycles_renders_them() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let blend = dir.path().join("lamps.blend");
    let scene_setup = "bpy.ops.mesh.primitive_plane_add(size=10); bpy.ops.mesh.primitive_cube_add(location=(0, 0, 0.5)); \
         bpy.ops.object.camera_add(location=(6, -6, 5), rotation=(math.radians(58), 0, math.radians(45))); \
         bpy.context.scene.camera = bpy.context.object; \
         bpy.ops.object.light_add(type='POINT', location=(1.5, -1.0, 2.5)); key = bpy.context.object; \
         key.name = 'Key'; key.data.energy = 150; key.data.exposure = 1.0; key.data.shadow_soft_size = 0.3; \
         key.data.color = (1, 0.9, 0.8); \
         bpy.ops.object.light_add(type='POINT', location=(-2.0, 1.5, 1.2)); fill = bpy.context.object; \
         fill.name = 'Fill'; fill.data.energy = 80; fill.data.shadow_soft_size = 0.1; fill.data.use_soft_falloff = False; \
         w = bpy.data.worlds.new('World'); bpy.context.scene.world = w; w.use_nodes = True; \
         w.node_tree.nodes['Background'].inputs['Color'].default_value = (0.05, 0.05, 0.05, 1)";
    make_blend(&python, &blend, scene_setup);
    let out = dir.path().join("scene");
    assert_ok(&export_frame_1(&python, &blend, &out, "64x36"), "exporting a scene with Point lamps");
    let scene = Scene::load(&out).unwrap();
    assert_eq!(scene.points.len(), 2, "{:?}", scene.points);
    let key = scene.points.iter().find(|p| p.soft_falloff).expect("the Soft Falloff lamp");
    let fill = scene.points.iter().find(|p| !p.soft_falloff).expect("the sphere lamp");
    assert!((key.position[0] - 1.5).abs() < 1e-6 && (key.position[2] - 2.5).abs() < 1e-6, "{key:?}");
    assert!((key.radius - 0.3).abs() < 1e-6 && (fill.radius - 0.1).abs() < 1e-6);
    assert_eq!((key.power, fill.power), (300.0, 80.0), "Exposure 1 doubles the Key's power");
    assert!((key.color[1] - 0.9).abs() < 1e-6);

    let shaded = dir.path().join("shaded");
    let output = crate::support::cli::logsh()
        .args(["shade", "--device", "cpu", "--out"])
        .arg(&shaded)
        .arg(&out)
        .output()
        .unwrap();
    assert_ok(&output, "logsh shade");
    let truth = dir.path().join("truth");
    let (samples, resolution) = (Path::new("256"), Path::new("64x36"));
    let args = [Path::new("--blend"), &blend, Path::new("--out"), &truth, Path::new("--samples"), samples];
    let output = run_python(
        &python,
        "blender_scripts/render_cycles.py",
        &[&args[..], &[Path::new("--resolution"), resolution]].concat(),
    );
    assert_ok(&output, "render_cycles.py");
    let logsh = raw_channels(&shaded.join("beauty.0001.exr"));
    let cycles = raw_channels(&truth.join("cycles.0001.exr"));
    let material = &scene.frame(1).unwrap().gbuffer.material;
    let (mut difference, mut sum, mut n) = (0.0f64, 0.0f64, 0usize);
    for channel in ["R", "G", "B"] {
        for (i, &m) in material.iter().enumerate() {
            if m != 0 {
                difference += f64::from((logsh[channel][i] - cycles[channel][i]).abs());
                sum += f64::from(cycles[channel][i]);
                n += 1;
            }
        }
    }
    let (error, mean) = (difference / n as f64, sum / n as f64);
    println!("point lamps against Cycles at 256 samples: mean abs error {error:.4}, mean {mean:.3}");
    // Measured 0.044 of the mean (the cube's sphere proxies and Cycles' noise at 256
    // samples); a lamp dropped, or its power off by a factor of 2, is far above 0.08.
    assert!(error <= 0.08 * mean, "mean abs error {error} against a mean of {mean}");

    // A lamp whose Temperature sets its colour stops the export, naming it.
    let blend = dir.path().join("warm.blend");
    make_blend(&python, &blend, &format!("{scene_setup}; key.data.use_temperature = True"));
    let refused = dir.path().join("refused");
    let output = export_frame_1(&python, &blend, &refused, "16x9");
    assert_eq!(output.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("error: Point lamp \"Key\" takes its colour from Temperature"), "{stderr}");
    assert!(!refused.exists());
}

/// A Mapping node in front of the World's Environment Texture becomes the light's
/// `rotation` (a Texture-type mapping as its inverse), and one that would bend directions
/// (a Location) stops the export.
#[test]
fn world_mapping_rotation_exports() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        ("POINT", "(0, 0, 0)", Some([0.0, 0.0, 70.0])),
        ("TEXTURE", "(0, 0, 0)", Some([0.0, 0.0, -70.0])),
        ("POINT", "(1, 0, 0)", None),
    ];
    for (i, (kind, location, expected)) in cases.into_iter().enumerate() {
        let blend = dir.path().join(format!("mapped{i}.blend"));
        make_blend(
            &python,
            &blend,
            &format!("bpy.ops.mesh.primitive_plane_add(size=8); \
             bpy.ops.object.camera_add(location=(0, -9, 6), rotation=(math.radians(60), 0, 0)); \
             bpy.context.scene.camera = bpy.context.object; \
             w = bpy.data.worlds.new('World'); bpy.context.scene.world = w; w.use_nodes = True; n = w.node_tree.nodes; \
             tex = n.new('ShaderNodeTexEnvironment'); tex.image = bpy.data.images.new('sky', 16, 8, float_buffer=True); \
             coord = n.new('ShaderNodeTexCoord'); m = n.new('ShaderNodeMapping'); m.vector_type = '{kind}'; \
             m.inputs['Location'].default_value = {location}; \
             m.inputs['Rotation'].default_value = (0, 0, math.radians(70)); \
             w.node_tree.links.new(coord.outputs['Generated'], m.inputs['Vector']); \
             w.node_tree.links.new(m.outputs['Vector'], tex.inputs['Vector']); \
             w.node_tree.links.new(tex.outputs['Color'], n['Background'].inputs['Color'])"),
        );
        let out = dir.path().join(format!("scene{i}"));
        let output = export_frame_1(&python, &blend, &out, "32x18");
        match expected {
            Some(rotation) => {
                assert_ok(&output, "exporting a mapped World");
                let json: serde_json::Value =
                    serde_json::from_str(&std::fs::read_to_string(out.join("scene.json")).unwrap()).unwrap();
                let got: Vec<f64> =
                    json["light"]["rotation"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
                for k in 0..3 {
                    assert!((got[k] - rotation[k]).abs() < 1e-4, "{kind}: rotation {got:?}, expected {rotation:?}");
                }
                Scene::load(&out).unwrap();
            }
            None => {
                assert_eq!(output.status.code(), Some(1));
                let stderr = String::from_utf8_lossy(&output.stderr);
                assert!(stderr.contains("Mapping node has a Location"), "{stderr}");
                assert!(!out.exists());
            }
        }
    }
}

/// A sun in the World's environment map, behind a Mapping rotation, gets a shadow map as a
/// Sun lamp does: the exporter finds it by logsh's rule, turns it as the Mapping node
/// turns the map, and logsh's own sun, taken out of the map, is within the degree a map
/// serves a sun by, so that the cube's shadow changes with the map.
#[test]
fn an_environment_maps_sun_gets_a_shadow_map() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let blend = dir.path().join("hdri_sun.blend");
    // The sun 2 degrees wide at azimuth -40, elevation 35 in the map's frame; the Mapping
    // node turns the map by (20, 0, 70) degrees.
    let (azimuth, elevation) = ((-40f64).to_radians(), 35f64.to_radians());
    let in_map = [elevation.cos() * azimuth.cos(), elevation.cos() * azimuth.sin(), elevation.sin()];
    let scene = format!(
            "import numpy as np, sys; sys.path.insert(0, {scenes:?}); from common import environment_world, sky_directions; \
             d = sky_directions(512); \
             rgb = 0.5 + 400.0 * (d @ {in_map:?} > math.cos(math.radians(2)))[..., None] * np.ones(3); \
             w = environment_world('sky', {sky:?}, rgb, 1.0); n = w.node_tree.nodes; \
             coord = n.new('ShaderNodeTexCoord'); m = n.new('ShaderNodeMapping'); \
             m.inputs['Rotation'].default_value = (math.radians(20), 0, math.radians(70)); \
             w.node_tree.links.new(coord.outputs['Generated'], m.inputs['Vector']); \
             w.node_tree.links.new(m.outputs['Vector'], n['Environment Texture'].inputs['Vector']); \
             bpy.ops.mesh.primitive_plane_add(size=8); bpy.ops.mesh.primitive_cube_add(size=2, location=(0, 0, 1)); \
             bpy.ops.object.camera_add(location=(7, -7, 5), rotation=(math.radians(63), 0, math.radians(45))); \
             bpy.context.scene.camera = bpy.context.object",
            scenes = Path::new(REPO).join("blender_scripts/scenes"),
            in_map = in_map.map(|c| (c * 1e9).round() / 1e9),
            sky = dir.path().join("sky.exr"),
    );
    make_blend(&python, &blend, &scene);
    let (with_map, without) = (dir.path().join("with_map"), dir.path().join("without"));
    assert_ok(&export_frame_1(&python, &blend, &with_map, "48x27"), "exporting a cube under an HDRI sun");
    // The axis of the export's one shadow map.
    let the_maps_axis = |scene: &Path| -> [f64; 3] {
        let blockers: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(scene.join("blockers.0001.json")).unwrap()).unwrap();
        let maps = blockers["sun_shadows"].as_array().expect("blockers.0001.json has sun_shadows");
        assert_eq!(maps.len(), 1, "one map: {maps:?}");
        serde_json::from_value(maps[0]["axis"].clone()).unwrap()
    };
    let axis = the_maps_axis(&with_map);
    let angle =
        |p: [f64; 3], q: [f64; 3]| (p[0] * q[0] + p[1] * q[1] + p[2] * q[2]).clamp(-1.0, 1.0).acos().to_degrees();
    // The radiance along d is the map's along R d: the sun lies along R^T times its place
    // in the map.
    let r = logsh::scene::light::euler_xyz([20f64.to_radians(), 0.0, 70f64.to_radians()]);
    let world = [0, 1, 2].map(|j| (0..3).map(|i| r[i][j] * in_map[i]).sum::<f64>());
    println!("the map's axis is {:.3} degrees from the sun", angle(axis, world));
    assert!(
        angle(axis, world) < 0.5,
        "the map's axis {axis:?} is {} degrees from the sun {world:?}",
        angle(axis, world)
    );

    let render = |scene: &Path, out: &Path| {
        let output = Command::cargo_bin("logsh")
            .unwrap()
            .args(["render", "--frames", "1", "--bounces", "0", "--progress", "none", "--device", "cpu"])
            .arg(scene)
            .arg("--out")
            .arg(out)
            .output()
            .unwrap();
        assert_ok(&output, "logsh render");
    };
    render(&with_map, &dir.path().join("shaded_with_map"));
    // logsh's sun, taken out of the map as the scene's light turns it.
    let frame = Scene::load(&with_map).unwrap().frame(1).unwrap();
    let split = logsh::shade::sharp_lights::decomposition(&frame.light).expect("an environment map");
    assert_eq!(split.suns.len(), 1, "logsh takes one sun out of the map");
    let taken = split.suns[0].direction;
    println!("logsh's sun is {:.4} degrees from the map's axis", angle(axis, taken));
    assert!(angle(axis, taken) < 0.2, "logsh's sun {taken:?} is {} degrees from the map's axis", angle(axis, taken));

    // The same frame without maps shades the sun through the cube's spheres.
    let output = export_frame_1_with_sun_shadows(&python, &blend, &without, "48x27", "0");
    assert_ok(&output, "exporting without sun shadow maps");
    render(&without, &dir.path().join("shaded_without"));
    let beauty = |shaded: &str| support::exr_channels(&dir.path().join(shaded).join("render.0001.exr"));
    let (mapped, spheres) = (beauty("shaded_with_map"), beauty("shaded_without"));
    let differs = ["R", "G", "B"]
        .iter()
        .flat_map(|c| mapped[*c].iter().zip(&spheres[*c]))
        .filter(|(a, b)| a.is_finite() && b.is_finite() && (*a - *b).abs() > 0.01)
        .count();
    assert!(differs > 0, "the shadow map changes no pixel: logsh took the sun's shadows from the spheres");

    // A Sun lamp set along the map's sun (0.2 degrees off): one map, the lamp's, serves
    // both.
    let lamp = dir.path().join("with_lamp.blend");
    let (theta, phi) = (world[2].acos() + 0.2f64.to_radians(), world[0].atan2(-world[1]));
    make_blend(&python, &lamp, &format!("{scene}; bpy.ops.object.light_add(type='SUN', rotation=({theta}, 0, {phi}))"));
    let with_lamp = dir.path().join("with_lamp");
    assert_ok(&export_frame_1(&python, &lamp, &with_lamp, "48x27"), "exporting the cube under an HDRI sun and a lamp");
    let axis = the_maps_axis(&with_lamp);
    assert!((angle(axis, world) - 0.2).abs() < 0.05, "the lamp's map, {} degrees from the sun", angle(axis, world));
}

/// The exporter finds the suns in an environment map that logsh takes out of it
/// (`environment_suns` in the exporter's world.py against
/// `shade::sharp_lights::extract_suns`), on maps made for it: two suns, a sun across the
/// map's seam, one near the zenith, a bright area too wide to be a sun and a disc too dim.
#[test]
fn the_exporter_finds_the_suns_logsh_takes_out_of_a_map() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let script = format!(
        "import json, math, sys; import numpy as np; sys.path.insert(0, {scripts:?}); sys.path.insert(0, {scenes:?})
from common import sky_directions
from logsh_exporter.exr import write_exr
from logsh_exporter.world import environment_suns
d = sky_directions(512)
def towards(azimuth, elevation):
    a, e = math.radians(azimuth), math.radians(elevation)
    return np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
def disc(azimuth, elevation, degrees, radiance):
    return radiance * (d @ towards(azimuth, elevation) > math.cos(math.radians(degrees)))
sky = 0.3 + 0.4 * np.clip(d[..., 2], 0.0, 1.0)
cases = {{
    'two_suns': sky + disc(30, 40, 1.5, 300.0) + disc(-120, 15, 1.0, 500.0),
    'seam': sky + disc(180, 25, 1.5, 300.0),
    'zenith': sky + disc(0, 88, 1.5, 300.0),
    'window': sky + disc(60, 30, 25.0, 40.0),
    'dim': sky + disc(60, 30, 1.5, 10.0),
}}
found = {{}}
for name, radiance in cases.items():
    path = {dir:?} + '/' + name + '.exr'
    write_exr(path, {{c: (radiance * [1.0, 0.9, 0.8][k]).astype(np.float32) for k, c in enumerate('RGB')}})
    found[name] = environment_suns(path)
print('SUNS ' + json.dumps(found))",
        scripts = Path::new(REPO).join("blender_scripts"),
        scenes = Path::new(REPO).join("blender_scripts/scenes"),
        dir = dir.path(),
    );
    let output = std::process::Command::new(&python).args(["-c", &script]).output().unwrap();
    assert_ok(&output, "environment_suns");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let line = stdout.lines().find_map(|l| l.strip_prefix("SUNS ")).expect("the suns printed");
    let found: HashMap<String, Vec<[f64; 3]>> = serde_json::from_str(line).unwrap();
    let angle =
        |p: [f64; 3], q: [f64; 3]| (p[0] * q[0] + p[1] * q[1] + p[2] * q[2]).clamp(-1.0, 1.0).acos().to_degrees();
    for (name, expected) in [("two_suns", 2), ("seam", 1), ("zenith", 1), ("window", 0), ("dim", 0)] {
        let map = logsh::scene::EnvironmentMap::read(&dir.path().join(format!("{name}.exr"))).unwrap();
        let taken = logsh::shade::sharp_lights::extract_suns(&map, 1.0).suns;
        let exporter = &found[name];
        assert_eq!(taken.len(), expected, "{name}: logsh takes {} suns", taken.len());
        assert_eq!(exporter.len(), expected, "{name}: the exporter finds {exporter:?}");
        for (sun, &direction) in taken.iter().zip(exporter) {
            let apart = angle(sun.direction, direction);
            println!("{name}: the exporter's sun {apart:.4} degrees from logsh's");
            assert!(
                apart < 0.05,
                "{name}: the exporter's sun {direction:?} is {apart} degrees from logsh's {:?}",
                sun.direction
            );
        }
    }
}

/// A Sky Texture World is baked by Cycles into the scene's map without its sun disc, and
/// the disc becomes a sun light of Blender's Sun Size towards the Sky Texture's sun (Sun
/// Elevation 30 degrees, Sun Rotation 0 and 120), of the same strength however turned.
#[test]
fn sky_texture_bakes_and_its_sun_is_a_sun_light() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let mut strengths = Vec::new();
    for rotation in [0.0f64, 120.0] {
        let blend = dir.path().join(format!("sky {rotation}.blend"));
        make_blend(
            &python,
            &blend,
            &format!(
                "bpy.ops.mesh.primitive_plane_add(size=8); bpy.ops.mesh.primitive_cube_add(location=(0, 0, 1)); \
                 bpy.ops.object.camera_add(location=(0, -9, 6), rotation=(math.radians(60), 0, 0)); \
                 bpy.context.scene.camera = bpy.context.object; \
                 w = bpy.data.worlds.new('World'); bpy.context.scene.world = w; w.use_nodes = True; n = w.node_tree.nodes; \
                 sky = n.new('ShaderNodeTexSky'); sky.sun_elevation = math.radians(30); \
                 sky.sun_rotation = math.radians({rotation}); \
                 w.node_tree.links.new(sky.outputs['Color'], n['Background'].inputs['Color'])"
            ),
        );
        let out = dir.path().join(format!("scene {rotation}"));
        let output = export_frame_1(&python, &blend, &out, "32x18");
        assert_ok(&output, "exporting a Sky Texture World");
        let stdout = String::from_utf8_lossy(&output.stdout);
        assert!(stdout.contains("World (Sky Texture) baked by Cycles"), "{stdout}");
        assert!(!out.join("sky_sun_with.tmp.exr").exists(), "the sun's window renders are removed");
        let scene = Scene::load(&out).unwrap();
        assert_eq!(scene.suns.len(), 1, "the Sky Texture's sun is a sun light: {stdout}");
        let sun = scene.suns[0];
        let (e, r) = (30f64.to_radians(), rotation.to_radians());
        let expected = [e.cos() * r.sin(), e.cos() * r.cos(), e.sin()];
        let cos = (0..3).map(|k| sun.direction[k] * expected[k]).sum::<f64>();
        assert!(
            cos > 0.1f64.to_radians().cos(),
            "rotation {rotation}: sun towards {:?}, expected {expected:?}",
            sun.direction
        );
        assert!((sun.half_angle.to_degrees() * 2.0 - 0.545).abs() < 0.01, "Blender's Sun Size");
        strengths.push(sun.strength);
        let output = crate::support::cli::logsh()
            .args(["shade", "--device", "cpu", "--out"])
            .arg(dir.path().join(format!("shaded {rotation}")))
            .arg(&out)
            .output()
            .unwrap();
        assert_ok(&output, "logsh shade");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(!stderr.contains("took a sun out"), "the map holds no sun any more: {stderr}");
        assert!(matches!(scene.frame(1).unwrap().light.as_ref(), logsh::scene::Light::Environment { .. }));
    }
    // The same sun wherever it is turned: the window found it both times.
    assert!((strengths[0] / strengths[1] - 1.0).abs() < 0.01, "sun strengths {strengths:?}");
}

/// The `dunes` sample built and exported small: the height map lies where the G-buffer
/// sees the terrain, and the sky map is oriented as the World's (the brightest texel is
/// the sun the builder placed), which ties the exporter's conventions to the reader's.
#[test]
fn dunes_height_map_and_sky_match_blender() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let blend = dir.path().join("dunes.blend");
    assert_ok(&run_python(&python, "blender_scripts/scenes/dunes.py", &[Path::new("--save"), &blend]), "dunes.py");
    let scene_dir = dir.path().join("scene");
    // Without colour passes, so that the terrain's material is `heightfield` (with them a
    // Principled BSDF is `phong` wherever it is).
    let options =
        ["--frames", "1", "--resolution", "64x36", "--heightmap-size", "97", "--no-colour-passes"].map(Path::new);
    let mut args = vec![Path::new("--blend"), &blend, Path::new("--out"), &scene_dir];
    args.extend(options);
    assert_ok(&run_python(&python, "blender_scripts/export_scene.py", &args), "export_scene.py");

    let scene = Scene::load(&scene_dir).unwrap();
    let frame = scene.frame(1).unwrap();
    let map = frame.height_map.as_ref().unwrap();
    assert_eq!([map.columns, map.rows], [97, 97]);
    let terrain = scene.materials.iter().find(|(_, m)| m.type_name() == "heightfield").map(|(&i, _)| i).unwrap();
    let g = &frame.gbuffer;
    let gaps: Vec<f64> = (0..g.material.len())
        .filter(|&i| g.material[i] == terrain)
        .map(|i| {
            let p = g.position[i];
            (map.height_at(p[0] as f64, p[1] as f64) - p[2] as f64).abs()
        })
        .collect();
    assert!(gaps.len() > 500, "terrain in view ({} pixels)", gaps.len());
    let mean = gaps.iter().sum::<f64>() / gaps.len() as f64;
    let worst = gaps.iter().cloned().fold(0.0, f64::max);
    // The map samples the mesh's vertices; bilinear and the mesh's triangles differ inside
    // a cell by the cell's twist (measured: mean 0.002, max 0.011 with cells 0.29 wide).
    assert!(mean < 0.005 && worst < 0.03, "height map vs G-buffer: mean {mean:.4}, max {worst:.4}");

    let logsh::scene::Light::Environment { map: sky, .. } = frame.light.as_ref() else {
        panic!("an environment light")
    };
    let brightest = (0..sky.texels.len()).max_by(|&a, &b| sky.texels[a][0].total_cmp(&sky.texels[b][0])).unwrap();
    let (u, v) = (
        ((brightest % sky.width) as f64 + 0.5) / sky.width as f64,
        1.0 - ((brightest / sky.width) as f64 + 0.5) / sky.height as f64,
    );
    let d = logsh::scene::light::equirectangular_to_direction(u, v);
    let sun = [-0.5, 0.6, 0.35]; // sun_direction in blender_scripts/scenes/dunes.py
    let length: f64 = sun[0] * sun[0] + sun[1] * sun[1] + sun[2] * sun[2];
    let cos = (d[0] * sun[0] + d[1] * sun[1] + d[2] * sun[2]) / length.sqrt();
    // One texel of a 256-wide map is 1.4 degrees: the sun lands within two.
    assert!(cos > (3.0f64.to_radians()).cos(), "brightest texel at {d:?}, sun at {sun:?}");
    let out = dir.path().join("out");
    let output = crate::support::cli::logsh().arg("shade").arg(&scene_dir).arg("--out").arg(&out).output().unwrap();
    assert_ok(&output, "logsh shade");
}

/// The exporter's sphere fit on Blender's primitives (`tests/support/fit_primitives.py`):
/// a UV sphere is one sphere within 1 % of its radius; the other primitives stay within
/// the volume errors measured when the fit was made (cube 0.27 with 4 spheres, cone 0.35
/// with 7, its thin tip the hardest part, torus 0.155 with 16), with a margin, and so do
/// they, with the same spheres, mirrored by a negative scale, which turns their triangles'
/// winding over (it once made the fit take a mirrored mesh's inside for its outside: one
/// sphere where there were 7, reaching through the ground).
#[test]
fn primitives_fit_their_volume() {
    let Some(python) = bpy_python() else { return };
    let output = run_python(&python, "tests/support/fit_primitives.py", &[]);
    assert_ok(&output, "fit_primitives.py");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let line = stdout.lines().rev().find(|l| l.starts_with('{')).expect("a JSON line");
    let fits: serde_json::Value = serde_json::from_str(line).unwrap();
    let sphere = &fits["uv_sphere"];
    assert_eq!(sphere["count"], 1, "{sphere}");
    let radius = sphere["radii"][0].as_f64().unwrap();
    assert!((radius - 1.0).abs() <= 0.01, "UV sphere radius {radius}");
    let centre: Vec<f64> = sphere["centres"][0].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert!(centre.iter().all(|c| c.abs() <= 0.01), "UV sphere centre {centre:?}");
    for (name, most_error, most_spheres) in [("cube", 0.32, 16), ("cone", 0.45, 16), ("torus", 0.2, 16)] {
        for name in [name.to_string(), format!("{name}_mirrored")] {
            let fit = &fits[&name];
            let error = fit["error"].as_f64().unwrap();
            let count = fit["count"].as_u64().unwrap();
            assert!(error <= most_error, "{name}: volume error {error} > {most_error}: {fit}");
            assert!((1..=most_spheres).contains(&count), "{name}: {count} spheres");
        }
        // These primitives are symmetric under their mirror: the same solid, its faces
        // wound the other way, takes the same fit.
        let (plain, mirrored) = (&fits[name], &fits[&format!("{name}_mirrored")]);
        assert_eq!(plain["count"], mirrored["count"], "{name}: {plain}\nmirrored: {mirrored}");
        let error = |fit: &serde_json::Value| fit["error"].as_f64().unwrap();
        assert!((error(plain) - error(mirrored)).abs() <= 0.03, "{name}: {plain}\nmirrored: {mirrored}");
    }
}

/// `blender_scripts/relight_compositor.py` builds the diffuse relight in Blender's
/// compositor from a frame's transfer layers; turned 40 degrees there, it equals `logsh
/// relight --light-rotation 40`'s diffuse term before logsh corrects it to the map's
/// irradiance (`albedo max(sh_diffuse . L, 0) + lamps_diffuse` with that relight's light;
/// it turns the map by resampling it, the compositor the SH vector exactly), whether its
/// light.json comes from an unturned relight or from that turned one (which it turns back
/// first, as docs/compositing.md's example has it). A light of another order than the
/// frame's is refused, both named.
#[test]
fn the_compositor_recipe_relights_the_diffuse_pass() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let frames = dir.path().join("frames");
    let logsh = |args: &[&str]| {
        let output = crate::support::cli::logsh().args(args).output().unwrap();
        assert_ok(&output, &format!("logsh {args:?}"));
    };
    let cones = Path::new(REPO).join("gbuffers/cones");
    let path = |p: &Path| p.to_str().unwrap().to_string();
    logsh(&["render", &path(&cones), "--frames", "1", "--out", &path(&frames), "--transfer", "--progress", "none"]);
    let frame = frames.join("render.0001.exr");
    let (unturned, turned) = (dir.path().join("relit0"), dir.path().join("relit40"));
    logsh(&["relight", &path(&frame), "--out", &path(&unturned)]);
    logsh(&["relight", &path(&frame), "--light-rotation", "40", "--out", &path(&turned)]);
    let composite = |light: &Path, name: &str| {
        let out = dir.path().join(name);
        let args = [frame.as_path(), light, Path::new("--rotation"), Path::new("40"), Path::new("--write"), &out];
        assert_ok(&run_python(&python, "blender_scripts/relight_compositor.py", &args), "relight_compositor.py");
        raw_channels(&out)
    };
    let blender = composite(&unturned.join("render.0001.light.json"), "composite.exr");
    let (relit, before) =
        (raw_channels(&turned.join("render.0001.exr")), raw_channels(&unturned.join("render.0001.exr")));
    let floor = logsh::compare::unoccluded_value(&Scene::load(&cones).unwrap().frame(1).unwrap()).unwrap();
    let mean = |a: &HashMap<String, Vec<f32>>, b: &HashMap<String, Vec<f32>>| {
        let mut sum = 0.0;
        for (k, c) in ["R", "G", "B"].iter().enumerate() {
            let (x, y) = (&a[*c], &b[&format!("diffuse.{c}")]);
            sum += x.iter().zip(y).map(|(p, q)| f64::from((p - q).abs())).sum::<f64>() / x.len() as f64 / floor[k];
        }
        sum / 3.0
    };
    // The relight at 40 degrees' diffuse term before its correction, from the frame's
    // layers and that relight's light.json (its light, turned).
    let layers = raw_channels(&frame);
    let description: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(turned.join("render.0001.light.json")).unwrap()).unwrap();
    let light: Vec<[f64; 3]> = serde_json::from_value(description["sh"].clone()).unwrap();
    let uncorrected: HashMap<String, Vec<f32>> = ["R", "G", "B"]
        .iter()
        .enumerate()
        .map(|(c, name)| {
            let (albedo, lamps) = (&layers[&format!("albedo.{name}")], &layers[&format!("lamps_diffuse.{name}")]);
            let values = (0..albedo.len())
                .map(|i| {
                    let dot: f64 = (0..light.len())
                        .map(|k| {
                            let channel = format!("sh_diffuse_{}.{}", k - k % 4, ["R", "G", "B", "A"][k % 4]);
                            f64::from(layers[&channel][i]) * light[k][c]
                        })
                        .sum();
                    (f64::from(albedo[i]) * dot.max(0.0) + f64::from(lamps[i])) as f32
                })
                .collect();
            (format!("diffuse.{name}"), values)
        })
        .collect();
    let (to_turned, to_unturned) = (mean(&blender, &uncorrected), mean(&blender, &before));
    println!(
        "Blender's compositor turned 40 degrees: {to_turned:.5} from logsh relight at 40 before its correction, \
         {:.5} after it, {to_unturned:.5} from 0",
        mean(&blender, &relit)
    );
    assert!(to_turned <= 2e-3, "the compositor's relight differs from logsh relight by {to_turned}");
    assert!(to_unturned > 3.0 * to_turned, "the compositor must turn the light: {to_unturned}");
    // From the turned relight's light.json, turned back first: the same composite.
    let from_turned = composite(&turned.join("render.0001.light.json"), "from_turned.exr");
    let again = mean(&from_turned, &uncorrected);
    println!("from the light.json of the relight at 40 degrees: {again:.5} from logsh relight at 40");
    assert!(again <= 2e-3, "from the turned light, the compositor's relight differs by {again}");
    // A light of order 3 on a frame of order 4: refused, both named.
    let low = dir.path().join("order3");
    logsh(&["render", &path(&cones), "--frames", "1", "--order", "3", "--out", &path(&low), "--transfer"]);
    logsh(&["relight", &path(&low.join("render.0001.exr")), "--out", &path(&low.join("relit"))]);
    let light = low.join("relit/render.0001.light.json");
    let output = run_python(&python, "blender_scripts/relight_compositor.py", &[frame.as_path(), light.as_path()]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success() && stderr.contains("order 3") && stderr.contains("order 4"), "{stderr}");
    // `--save` onto the frame it reads: refused, the frame untouched.
    let before = std::fs::read(&frame).unwrap();
    let light = unturned.join("render.0001.light.json");
    let args = [frame.as_path(), light.as_path(), Path::new("--save"), frame.as_path()];
    let output = run_python(&python, "blender_scripts/relight_compositor.py", &args);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success() && stderr.contains("over an input"), "{stderr}");
    assert_eq!(std::fs::read(&frame).unwrap(), before, "the frame is untouched");
    // `--write` of the frame's name without `.exr`, to which Blender would add it, and
    // with a '#', which Blender would number: refused, the frame untouched.
    for named in [frames.join("render.0001"), frames.join("render.####.exr")] {
        let args = [frame.as_path(), light.as_path(), Path::new("--write"), named.as_path()];
        let output = run_python(&python, "blender_scripts/relight_compositor.py", &args);
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(!output.status.success() && stderr.contains("--write"), "{}: {stderr}", named.display());
        assert_eq!(std::fs::read(&frame).unwrap(), before, "the frame is untouched by {}", named.display());
    }
    // A frame cut short in its header: refused at once (the header's reader looped at the
    // end of the file before).
    let cut = dir.path().join("cut.exr");
    std::fs::write(&cut, &before[..2000]).unwrap();
    let mut child = std::process::Command::new(&python)
        .arg(Path::new(REPO).join("blender_scripts/relight_compositor.py"))
        .args([&cut, &light])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let started = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if started.elapsed().as_secs() > 120 {
            child.kill().ok();
            panic!("relight_compositor.py still reads a cut frame after two minutes");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let output = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success() && stderr.contains("cut.exr") && stderr.contains("ends early"), "{stderr}");

    // An `sh` light, relit turned 40: its light.json records the turn, which the compositor
    // takes back first (it turned the light twice, to 80 degrees, before).
    let scene = dir.path().join("cones_sh");
    support::copy_scene(&cones, &scene);
    let description = scene.join("scene.json");
    let mut json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&description).unwrap()).unwrap();
    let mut sh = vec![[0.0f64; 3]; 25];
    (sh[0], sh[1], sh[3], sh[5], sh[22]) = ([1.0; 3], [0.2, 0.3, 0.1], [0.8, 0.6, 0.5], [0.2; 3], [0.1, 0.2, 0.1]);
    json["light"] = serde_json::json!({ "sh": sh });
    std::fs::write(&description, json.to_string()).unwrap();
    let sh_frames = dir.path().join("sh_frames");
    logsh(&["render", &path(&scene), "--frames", "1", "--out", &path(&sh_frames), "--transfer", "--progress", "none"]);
    let frame = sh_frames.join("render.0001.exr");
    let turned = dir.path().join("sh_relit40");
    logsh(&["relight", &path(&frame), "--light-rotation", "40", "--out", &path(&turned)]);
    let out = dir.path().join("sh_composite.exr");
    let light = turned.join("render.0001.light.json");
    let args = [frame.as_path(), &light, Path::new("--rotation"), Path::new("40"), Path::new("--write"), &out];
    assert_ok(&run_python(&python, "blender_scripts/relight_compositor.py", &args), "relight_compositor.py");
    let sh_mean = mean(&raw_channels(&out), &raw_channels(&turned.join("render.0001.exr")));
    println!("an sh light from the light.json of the relight at 40 degrees: {sh_mean:.5} from logsh relight at 40");
    assert!(sh_mean <= 2e-3, "the compositor's relight of an sh light differs by {sh_mean}");
}

/// The PNG preview applies the scene's exposure and view transform as Blender shows them:
/// logsh's preview of its own linear beauty against Blender's `save_render` of the same
/// EXR with the .blend's colour management, under a sky bright enough to turn a plain sRGB
/// preview white.
#[test]
fn previews_follow_the_scenes_view_transform() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    for (transform, look, exposure) in
        [("AgX", "None", -1.5), ("Filmic", "Medium High Contrast", -2.5), ("Standard", "None", -4.0)]
    {
        let blend = dir.path().join(format!("{transform}.blend"));
        let setup = format!(
            "bpy.ops.mesh.primitive_plane_add(size=10); bpy.ops.mesh.primitive_uv_sphere_add(location=(0, 0, 1)); \
             bpy.ops.object.camera_add(location=(6, -6, 5), rotation=(math.radians(58), 0, math.radians(45))); \
             s = bpy.context.scene; s.camera = bpy.context.object; \
             w = bpy.data.worlds.new('World'); s.world = w; w.use_nodes = True; \
             w.node_tree.nodes['Background'].inputs['Color'].default_value = (0.6, 0.75, 1.0, 1); \
             w.node_tree.nodes['Background'].inputs['Strength'].default_value = 12.0; \
             s.view_settings.view_transform = '{transform}'; s.view_settings.look = '{look}'; \
             s.view_settings.exposure = {exposure}"
        );
        make_blend(&python, &blend, &setup);
        let scene = dir.path().join(transform);
        assert_ok(&export_frame_1(&python, &blend, &scene, "48x27"), "exporting");
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(scene.join("scene.json")).unwrap()).unwrap();
        assert_eq!(json["view"]["transform"], transform);
        assert_eq!(json["view"]["lut"].is_object(), transform != "Standard", "{}", json["view"]);
        let shaded = dir.path().join(format!("{transform}-shaded"));
        let output = crate::support::cli::logsh()
            .args(["shade", "--device", "cpu", "--out"])
            .arg(&shaded)
            .arg(&scene)
            .output()
            .unwrap();
        assert_ok(&output, "logsh shade");
        let blender_png = dir.path().join(format!("{transform}-blender.png"));
        let script = format!(
            "import bpy; bpy.ops.wm.open_mainfile(filepath={:?}); s = bpy.context.scene; \
             i = bpy.data.images.load({:?}); s.render.image_settings.file_format = 'PNG'; \
             s.render.image_settings.color_depth = '8'; s.render.image_settings.color_mode = 'RGB'; \
             i.save_render({:?}, scene=s)",
            blend.to_str().unwrap(),
            shaded.join("beauty.0001.exr").to_str().unwrap(),
            blender_png.to_str().unwrap()
        );
        assert_ok(&std::process::Command::new(&python).args(["-c", &script]).output().unwrap(), "save_render");
        let ours = image::open(shaded.join("beauty.0001.png")).unwrap().to_rgba8();
        let theirs = image::open(&blender_png).unwrap().to_rgb8();
        let (mut sum, mut worst, mut level) = (0.0f64, 0u8, 0.0f64);
        for (a, b) in ours.pixels().zip(theirs.pixels()) {
            assert_eq!(a[3], 255, "an opaque preview, as Blender's film is");
            for k in 0..3 {
                let d = a[k].abs_diff(b[k]);
                sum += f64::from(d);
                worst = worst.max(d);
                level += f64::from(a[k]);
            }
        }
        let count = 3.0 * f64::from(ours.width() * ours.height());
        let (mean, level) = (sum / count, level / count);
        println!("{transform} ({look}, exposure {exposure}): preview {mean:.3} levels from Blender's, worst {worst}, mean level {level:.0}");
        assert!(mean <= 1.0 && worst <= 6, "{transform}: mean {mean} levels, worst {worst}");
        assert!(level < 240.0, "{transform}: the preview must not be white ({level:.0})");
    }
}

/// `export_scene.py --supersample 2`: G-buffers (and the reflection G-buffer) at twice the
/// camera's size, `supersample` in scene.json, and logsh resolving its outputs to the
/// camera's size; the resolved edge pixels carry partial alpha, the point-sampled ones not.
#[test]
fn supersampled_export_resolves_to_the_camera() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let blend = dir.path().join("tiny.blend");
    assert_ok(&run_python(&python, "blender_scripts/scenes/tiny.py", &[Path::new("--save"), &blend]), "tiny.py");
    let mut alphas = Vec::new();
    for n in ["1", "2"] {
        let scene_dir = dir.path().join(format!("n{n}"));
        let args = [Path::new("--resolution"), Path::new("32x18"), Path::new("--frames"), Path::new("1-1")];
        let more =
            [Path::new("--blend"), &blend, Path::new("--out"), &scene_dir, Path::new("--supersample"), Path::new(n)];
        assert_ok(&run_python(&python, "blender_scripts/export_scene.py", &[&args[..], &more[..]].concat()), "export");
        let scene = Scene::load(&scene_dir).unwrap();
        let frame = scene.frame(1).unwrap();
        let k: usize = n.parse().unwrap();
        assert_eq!(scene.supersample, k);
        assert_eq!((frame.gbuffer.width, frame.gbuffer.height), (32 * k, 18 * k));
        if let Some(r) = &frame.reflection {
            assert_eq!((r.width, r.height), (32 * k, 18 * k), "the reflection G-buffer is supersampled too");
        }
        let shaded = dir.path().join(format!("shaded{n}"));
        let output = crate::support::cli::logsh()
            .args(["shade", "--device", "cpu", "--out"])
            .arg(&shaded)
            .arg(&scene_dir)
            .output()
            .unwrap();
        assert_ok(&output, "logsh shade");
        let alpha = raw_channels(&shaded.join("beauty.0001.exr"))["A"].clone();
        assert_eq!(alpha.len(), 32 * 18, "resolved to the camera's 32x18");
        alphas.push(alpha);
    }
    let partial = |a: &[f32]| a.iter().filter(|&&v| v > 0.01 && v < 0.99).count();
    println!("edge pixels with partial alpha: point-sampled {}, 2x2 {}", partial(&alphas[0]), partial(&alphas[1]));
    assert_eq!(partial(&alphas[0]), 0);
    assert!(partial(&alphas[1]) > 5, "the resolved frame has anti-aliased edges");
}

/// A checker texture on a Principled BSDF arrives as Blender evaluates it: the export
/// carries Cycles' Diffuse Color and Glossy Color passes (scene.json `colour_passes`),
/// the ground's Diffuse Color takes the checker's two colours, and logsh's shade of the
/// light cells is brighter than of the dark ones by about their ratio (0.8 / 0.1); the
/// table gives the material's reflectance at normal incidence (`fresnel`). With
/// `--no-colour-passes` the ground is one colour again.
#[test]
fn textured_materials_shade_as_blender_evaluates_them() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let blend = dir.path().join("checker.blend");
    make_blend(
        &python,
        &blend,
        "bpy.ops.mesh.primitive_plane_add(size=8); \
         m = bpy.data.materials.new('checker'); m.use_nodes = True; t = m.node_tree; \
         c = t.nodes.new('ShaderNodeTexChecker'); c.inputs['Scale'].default_value = 3.0; \
         c.inputs['Color1'].default_value = (0.8, 0.8, 0.8, 1); c.inputs['Color2'].default_value = (0.1, 0.1, 0.1, 1); \
         t.links.new(c.outputs['Color'], t.nodes['Principled BSDF'].inputs['Base Color']); \
         bpy.context.object.data.materials.append(m); \
         bpy.ops.object.camera_add(location=(0, 0, 9)); bpy.context.scene.camera = bpy.context.object; \
         w = bpy.data.worlds.new('World'); bpy.context.scene.world = w; w.use_nodes = True; \
         w.node_tree.nodes['Background'].inputs['Color'].default_value = (0.5, 0.5, 0.5, 1)",
    );
    let out = dir.path().join("scene");
    assert_ok(&export_frame_1(&python, &blend, &out, "48x27"), "exporting a textured ground");
    let scene = Scene::load(&out).unwrap();
    assert!(scene.colour_passes(), "the export says colour_passes");
    // What the passes cannot carry: the reflectance at normal incidence of the
    // Principled BSDF's IOR 1.5 at Specular IOR Level 0.5, which its texture leaves alone.
    let fresnel: Vec<f64> = scene.fresnel.values().copied().collect();
    assert!(fresnel.len() == 1 && (fresnel[0] - 0.04).abs() < 1e-6, "fresnel {fresnel:?}");
    let frame = scene.frame(1).unwrap();
    let colours = frame.gbuffer.colours.as_ref().expect("the G-buffer holds the colour passes");
    let shaded = support::cpu_beauty(&scene, &frame, &ShadingSettings::default()).unwrap();
    let (mut light, mut dark) = (Vec::new(), Vec::new());
    for (i, d) in colours.diffuse.iter().enumerate() {
        if frame.gbuffer.material[i] != 0 {
            let grey = shaded.rgba[i][0] + shaded.rgba[i][1] + shaded.rgba[i][2];
            match d[0] {
                v if v > 0.5 => light.push(grey),
                v if v < 0.2 => dark.push(grey),
                v => panic!("pixel {i}: Diffuse Color {v} is neither of the checker's colours (times the layering)"),
            }
        }
    }
    assert!(light.len() > 100 && dark.len() > 100, "{} light and {} dark pixels", light.len(), dark.len());
    let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len() as f32;
    let ratio = mean(&light) / mean(&dark);
    eprintln!("light cells {:.4}, dark cells {:.4}: ratio {ratio:.2}", mean(&light), mean(&dark));
    assert!((4.0..9.0).contains(&ratio), "light cells are {ratio:.2} times as bright as dark ones");

    let plain = dir.path().join("plain");
    let args =
        [Path::new("--blend"), &blend, Path::new("--out"), &plain, Path::new("--resolution"), Path::new("48x27")];
    let output = run_python(
        &python,
        "blender_scripts/export_scene.py",
        &[&args[..], &[Path::new("--no-colour-passes")]].concat(),
    );
    assert_ok(&output, "exporting without colour passes");
    let warned = String::from_utf8_lossy(&output.stdout);
    assert!(warned.contains("material \"checker\": its Base Color is driven by nodes"), "{warned}");
    let scene = Scene::load(&plain).unwrap();
    assert!(!scene.colour_passes() && scene.frame(1).unwrap().gbuffer.colours.is_none());
    assert!(scene.fresnel.is_empty(), "the converted material has no Fresnel term: {:?}", scene.fresnel);
}

/// The exporter's `--frames` reads a spec as `logsh render --frames` does: ranges counting
/// down, `:` steps and negative frames included (the same frames, sorted); a malformed
/// spec is refused by both.
#[test]
fn the_exporter_reads_frame_specs_as_logsh_does() {
    let Some(python) = bpy_python() else { return };
    let specs =
        ["7", "1-5", "12-10", "1-10x3", "1-10:4", "10-1x3", "-2-1", "-5--3", "-3..-1", " 1, 5 ,10-12", "1..9x4"];
    let bad = ["", "1,,2", "7x2", "1-5x0", "a", "1-2000000"];
    let script = format!(
        "import sys, json, argparse; sys.path.insert(0, {:?}); from export_scene import frame_range\n\
         def read(spec):\n    try: return frame_range(spec)\n    except argparse.ArgumentTypeError: return None\n\
         print(json.dumps([read(s) for s in {:?}]))",
        Path::new(REPO).join("blender_scripts").to_str().unwrap(),
        specs.iter().chain(&bad).collect::<Vec<_>>(),
    );
    let output = std::process::Command::new(&python).args(["-c", &script]).output().unwrap();
    assert_ok(&output, "frame_range");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let line = stdout.lines().rev().find(|l| l.starts_with('[')).expect("a JSON line");
    let read: Vec<Option<Vec<i64>>> = serde_json::from_str(line).unwrap();
    for (spec, exported) in specs.iter().chain(&bad).zip(read) {
        let logsh = spec.parse::<logsh::render::frames::FrameSpec>().ok().map(|s| {
            let mut frames = s.frames;
            frames.sort();
            frames
        });
        assert_eq!(exported, logsh, "spec {spec:?}");
    }
}

/// The exporter sees the scene as Cycles renders it, not as the viewport shows it: a
/// cylinder lifted 1 m by a Displace modifier shown in renders only has its spheres
/// lifted with it, and a cube subdivided at its Render level only (Viewport 0, Render 3)
/// is fitted as the near-sphere it renders as; a Render Region is left out (the whole
/// frame is exported, which the camera describes); a material Geometry Nodes set (Set
/// Material) has its index, while geometry they make without one stops the export with
/// the object's name, as does hair.
#[test]
fn the_export_follows_the_render_not_the_viewport() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let blend = dir.path().join("render.blend");
    let setup = "bpy.ops.mesh.primitive_plane_add(size=20); \
         bpy.ops.mesh.primitive_cylinder_add(radius=0.5, depth=1, location=(-2, 0, 0.5)); c = bpy.context.object; \
         c.name = 'lifted'; d = c.modifiers.new('lift', 'DISPLACE'); d.direction = 'Z'; d.strength = 2.0; \
         d.mid_level = 0.5; d.show_viewport = False; \
         bpy.ops.mesh.primitive_cube_add(size=1.6, location=(2, 0, 0.8)); b = bpy.context.object; b.name = 'rounded'; \
         m = b.modifiers.new('subdivision', 'SUBSURF'); m.levels = 0; m.render_levels = 3; \
         pink = bpy.data.materials.new('pink'); \
         pink.node_tree.nodes['Principled BSDF'].inputs['Base Color'].default_value = (0.9, 0.3, 0.5, 1); \
         bpy.ops.mesh.primitive_plane_add(size=0.1, location=(0, 0, 0.01)); h = bpy.context.object; h.name = 'host'; \
         g = bpy.data.node_groups.new('box', 'GeometryNodeTree'); \
         g.interface.new_socket('Geometry', in_out='INPUT', socket_type='NodeSocketGeometry'); \
         g.interface.new_socket('Geometry', in_out='OUTPUT', socket_type='NodeSocketGeometry'); \
         o = g.nodes.new('NodeGroupOutput'); k = g.nodes.new('GeometryNodeMeshCube'); \
         k.inputs['Size'].default_value = (1, 1, 1); t = g.nodes.new('GeometryNodeTransform'); \
         t.inputs['Translation'].default_value = (0, 0, 0.5); g.links.new(k.outputs['Mesh'], t.inputs['Geometry']); \
         s = g.nodes.new('GeometryNodeSetMaterial'); s.inputs['Material'].default_value = pink; \
         g.links.new(t.outputs['Geometry'], s.inputs['Geometry']); g.links.new(s.outputs['Geometry'], o.inputs['Geometry']); \
         h.modifiers.new('box', 'NODES').node_group = g; \
         bpy.ops.object.camera_add(location=(0, 0, 12)); bpy.context.scene.camera = bpy.context.object; \
         r = bpy.context.scene.render; r.use_border = True; r.use_crop_to_border = True; \
         r.border_min_x, r.border_max_x, r.border_min_y, r.border_max_y = 0.2, 0.6, 0.3, 0.8; \
         w = bpy.data.worlds.new('World'); bpy.context.scene.world = w";
    make_blend(&python, &blend, setup);
    let out = dir.path().join("scene");
    let output = export_frame_1(&python, &blend, &out, "48x32");
    assert_ok(&output, "export_scene.py");
    let scene = Scene::load(&out).unwrap();
    let frame = scene.frame(1).unwrap();
    assert_eq!([frame.gbuffer.width, frame.gbuffer.height], [48, 32], "the Render Region is left out");
    let log = String::from_utf8_lossy(&output.stdout);
    // The spheres about x, where the cylinder (x = -2) and the cube (x = 2) stand.
    let spheres_at =
        |x: f64| -> Vec<&Sphere> { frame.blockers.iter().filter(|s| (s.center[0] - x).abs() < 1.0).collect() };
    let lifted = spheres_at(-2.0);
    assert!(!lifted.is_empty() && lifted.iter().all(|s| s.center[2] - s.radius > 0.5), "lifted: {lifted:?}");
    let rounded = spheres_at(2.0);
    assert!(log.contains("rounded: 1 sphere(s)"), "the cube subdivided at render is one sphere: {rounded:?}\n{log}");
    // The Set Material's cube, seen from above at the frame's centre.
    let centre = frame.gbuffer.index(24, 16);
    let index = frame.gbuffer.material[centre];
    let colours = frame.gbuffer.colours.as_ref().expect("colour passes");
    assert!(index != 0 && (colours.diffuse[centre][1] - 0.3).abs() < 0.02, "{index}: {:?}", colours.diffuse[centre]);

    // Geometry Nodes geometry with no material, and hair, stop the export by name.
    for (name, change, says) in [
        ("bare", "s.inputs['Material'].default_value = None", "object \"host\": "),
        (
            "hair",
            "p = c.modifiers.new('fur', 'PARTICLE_SYSTEM').particle_system; p.settings.type = 'HAIR'",
            "object \"lifted\" has hair (particle system \"fur\")",
        ),
    ] {
        let blend = dir.path().join(format!("{name}.blend"));
        make_blend(&python, &blend, &format!("{setup}; {change}"));
        let out = dir.path().join(name);
        let output = export_frame_1(&python, &blend, &out, "48x32");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(1), "{name}: the export stops: {stderr}");
        assert!(stderr.contains(says), "{name}: {stderr}");
    }
}

/// What no sphere fits still shadows the sun, and what renders as nothing is left out: a
/// flat roof over the ground (no spheres; its sky occlusion is not modelled) casts its
/// Sun lamp shadow through the sun shadow map, as an open sheet does (a dome: its inside
/// once took a slab of spheres out to its bounding box; Suzanne, whose eyes leave her
/// open, keeps hers); a cube keyed to scale 0 on frame 2 exports there with no spheres (it
/// once stopped the export on a singular matrix).
#[test]
fn flat_roofs_cast_sun_shadows_and_vanished_objects_export() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let blend = dir.path().join("roof.blend");
    make_blend(
        &python,
        &blend,
        "bpy.ops.mesh.primitive_plane_add(size=20); bpy.ops.mesh.primitive_plane_add(size=2, location=(0, 0, 1.2)); \
         bpy.context.object.name = 'roof'; \
         bpy.ops.mesh.primitive_cube_add(size=0.6, location=(3, 2, 0.3)); k = bpy.context.object; k.name = 'vanishing'; \
         k.keyframe_insert('scale', frame=1); k.scale = (0, 0, 0); k.keyframe_insert('scale', frame=2); \
         import bmesh; bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, location=(-3, -2, 0.5)); \
         d = bpy.context.object; d.name = 'dome'; b = bmesh.new(); b.from_mesh(d.data); \
         bmesh.ops.delete(b, geom=[v for v in b.verts if v.co.z < -1e-4], context='VERTS'); b.to_mesh(d.data); \
         bpy.ops.mesh.primitive_monkey_add(size=0.8, location=(3, -2, 0.5)); \
         bpy.ops.object.light_add(type='SUN', rotation=(math.radians(30), 0, 0)); bpy.context.object.data.energy = 3.0; \
         bpy.ops.object.camera_add(location=(0, 0, 9)); bpy.context.scene.camera = bpy.context.object; \
         w = bpy.data.worlds.new('World'); bpy.context.scene.world = w",
    );
    let out = dir.path().join("scene");
    let args = [Path::new("--blend"), &blend, Path::new("--out"), &out, Path::new("--resolution"), Path::new("48x48")];
    let output = run_python(
        &python,
        "blender_scripts/export_scene.py",
        &[&args[..], &[Path::new("--frames"), Path::new("1-2")]].concat(),
    );
    assert_ok(&output, "export_scene.py");
    let log = String::from_utf8_lossy(&output.stdout);
    assert!(log.contains("\"roof\" is flat; not a blocker, so it casts sun shadows only"), "{log}");
    // An open dome is a sheet; Suzanne, open at her eyes, is still a solid.
    assert!(log.contains("\"dome\" is an open sheet, not a solid; not a blocker"), "{log}");
    assert!(log.contains("Suzanne: ") && log.contains(" sphere(s)"), "{log}");
    let scene = Scene::load(&out).unwrap();
    // The cube's spheres on frame 1, and only Suzanne's on frame 2.
    let far_right = |frame: i64| scene.frame(frame).unwrap().blockers.iter().filter(|s| s.center[1] > 1.0).count();
    assert!(far_right(1) > 0 && far_right(2) == 0, "{} and {}", far_right(1), far_right(2));
    let shaded = dir.path().join("out");
    let output = crate::support::cli::logsh()
        .args(["render", "--frames", "1", "--bounces", "0", "--progress", "none", "--out"])
        .arg(&shaded)
        .arg(&out)
        .output()
        .unwrap();
    assert_ok(&output, "logsh render");
    let beauty = raw_channels(&shaded.join("render.0001.exr"));
    // Seen from above, the roof covers 15 pixels about the centre; the sun, 30 degrees
    // from the zenith, throws its shadow 0.7 m (5 pixels) beyond it on one side.
    let at = |x: usize, y: usize| beauty["R"][y * 48 + x];
    let beside = (9..=11).flat_map(|d| [at(24, 24 - d), at(24, 24 + d)]).fold(f32::INFINITY, f32::min);
    let open = at(2, 2);
    assert!(beside < 0.5 * open, "beside the roof {beside}, open ground {open}");
}

/// Faces whose material slot is empty render in Cycles with its default surface, and so
/// they are exported: a cylinder whose caps sit in an empty second slot, seen from above,
/// has its cap under a material with that surface's colours (Diffuse Color 0.763 and
/// Glossy Color 0.046 head on, as Cycles renders a plane with no material), not the
/// background (they once took material index 0, and logsh showed the sky there).
#[test]
fn faces_in_an_empty_material_slot_take_cycles_default_surface() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let blend = dir.path().join("slots.blend");
    make_blend(
        &python,
        &blend,
        "bpy.ops.mesh.primitive_plane_add(size=20); ground = bpy.data.materials.new('ground'); \
         bpy.context.object.data.materials.append(ground); \
         bpy.ops.mesh.primitive_cylinder_add(radius=2, depth=1, location=(0, 0, 0.5)); c = bpy.context.object; \
         red = bpy.data.materials.new('red'); red.node_tree.nodes['Principled BSDF'].inputs['Base Color'].default_value = (0.8, 0.05, 0.05, 1); \
         c.data.materials.append(red); c.data.materials.append(None); \
         [setattr(p, 'material_index', 1 if abs(p.normal.z) > 0.5 else 0) for p in c.data.polygons]; \
         bpy.ops.object.camera_add(location=(0, 0, 8)); bpy.context.scene.camera = bpy.context.object; \
         w = bpy.data.worlds.new('World'); bpy.context.scene.world = w",
    );
    let out = dir.path().join("scene");
    assert_ok(&export_frame_1(&python, &blend, &out, "32x32"), "export_scene.py");
    let scene = Scene::load(&out).unwrap();
    let frame = scene.frame(1).unwrap();
    let g = &frame.gbuffer;
    let centre = g.index(16, 16);
    let index = g.material[centre];
    assert_ne!(index, 0, "the cylinder's cap is taken for the background");
    assert!(scene.materials.contains_key(&index), "material {index} is not in the table");
    let colours = g.colours.as_ref().expect("colour passes");
    for (pass, colour, expected) in
        [("Diffuse", colours.diffuse[centre], 0.763), ("Glossy", colours.glossy[centre], 0.046)]
    {
        assert!(
            colour.iter().all(|c| (c - expected).abs() < 0.01),
            "the cap's {pass} Color {colour:?}, not {expected}"
        );
    }
}

/// What logsh cannot shade stops the export, naming the material and the node: emission,
/// transmission outside water, a Mix Shader surface; `--approximate` exports with a
/// warning each, which the summary counts.
#[test]
fn unrepresentable_materials_are_refused_by_name() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let setup = "bpy.ops.mesh.primitive_plane_add(size=8); bpy.ops.mesh.primitive_cube_add(location=(0, 0, 1)); \
                 m = bpy.data.materials.new('CASE'); m.use_nodes = True; t = m.node_tree; \
                 p = t.nodes['Principled BSDF']; bpy.context.object.data.materials.append(m); \
                 bpy.ops.object.camera_add(location=(7, -7, 5), rotation=(math.radians(63), 0, math.radians(45))); \
                 bpy.context.scene.camera = bpy.context.object; \
                 w = bpy.data.worlds.new('World'); bpy.context.scene.world = w";
    let cases = [
        ("lamp shade", "p.inputs['Emission Strength'].default_value = 4.0; p.inputs['Emission Color'].default_value = (1, 1, 1, 1)", "emits light"),
        ("frosted glass", "p.inputs['Transmission Weight'].default_value = 0.9", "has transmission"),
        (
            "mixed",
            "x = t.nodes.new('ShaderNodeMixShader'); x.name = 'Mix'; \
             t.links.new(x.outputs[0], t.nodes['Material Output'].inputs['Surface'])",
            "its surface is a Mix Shader node (\"Mix\")",
        ),
    ];
    for (name, change, says) in cases {
        let blend = dir.path().join(format!("{name}.blend"));
        make_blend(&python, &blend, &format!("{}; {change}", setup.replace("CASE", name)));
        let out = dir.path().join(name);
        let output = export_frame_1(&python, &blend, &out, "16x9");
        assert_eq!(output.status.code(), Some(1), "{name}: the export stops");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(stderr.contains(&format!("error: material \"{name}\"")) && stderr.contains(says), "{name}: {stderr}");
        assert!(!out.exists(), "{name}: a refused export left {} behind", out.display());

        let args =
            [Path::new("--blend"), &blend, Path::new("--out"), &out, Path::new("--resolution"), Path::new("16x9")];
        let output = run_python(
            &python,
            "blender_scripts/export_scene.py",
            &[&args[..], &[Path::new("--approximate")]].concat(),
        );
        assert_ok(&output, "exporting with --approximate");
        let stdout = String::from_utf8_lossy(&output.stdout);
        assert!(
            stdout.contains(&format!("warning: material \"{name}\"")) && stdout.contains("1 warning:"),
            "{name}: {stdout}"
        );
    }
}

/// Dielectric Fresnel reflectance of unpolarised light at `cos_i` into a medium of index
/// `n` from air (Fresnel's equations).
fn fresnel_dielectric(cos_i: f64, n: f64) -> f64 {
    let sin_t = (1.0 - cos_i * cos_i).max(0.0).sqrt() / n;
    let cos_t = (1.0 - sin_t * sin_t).sqrt();
    let s = (cos_i - n * cos_t) / (cos_i + n * cos_t);
    let p = (cos_t - n * cos_i) / (cos_t + n * cos_i);
    0.5 * (s * s + p * p)
}

/// Water as Blender renders it: the exported Glossy Color of clear water (IOR 1.33) is
/// Fresnel's reflectance at each pixel's view angle, within 0.005 + 3 % of the closed form
/// as it rises towards grazing angles, and logsh shades a water pixel mirroring
/// the constant sky as that reflectance times the sky.
#[test]
fn water_reflects_with_fresnel() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let blend = dir.path().join("water.blend");
    make_blend(
        &python,
        &blend,
        "bpy.ops.mesh.primitive_plane_add(size=200); \
         m = bpy.data.materials.new('lake'); m.use_nodes = True; p = m.node_tree.nodes['Principled BSDF']; \
         p.inputs['Transmission Weight'].default_value = 1.0; p.inputs['IOR'].default_value = 1.33; \
         p.inputs['Roughness'].default_value = 0.0; m['logsh_type'] = 'water'; \
         bpy.context.object.data.materials.append(m); \
         bpy.ops.object.camera_add(location=(0, -6, 1.2), rotation=(math.radians(78), 0, 0)); \
         bpy.context.scene.camera = bpy.context.object; \
         w = bpy.data.worlds.new('World'); bpy.context.scene.world = w; w.use_nodes = True; \
         w.node_tree.nodes['Background'].inputs['Color'].default_value = (0.5, 0.6, 0.7, 1)",
    );
    let out = dir.path().join("scene");
    assert_ok(&export_frame_1(&python, &blend, &out, "32x18"), "exporting a lake");
    let scene = Scene::load(&out).unwrap();
    let frame = scene.frame(1).unwrap();
    let (g, camera) = (&frame.gbuffer, frame.camera.as_ref().unwrap());
    let shaded = support::cpu_beauty(&scene, &frame, &ShadingSettings::default()).unwrap();
    let (mut worst, mut seen) = (0.0f64, Vec::new());
    for i in (0..g.material.len()).filter(|&i| g.material[i] != 0) {
        let p = g.position[i].map(f64::from);
        let d: Vec<f64> = (0..3).map(|k| p[k] - camera.position[k]).collect();
        let cos = -d[2] / (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let fresnel = fresnel_dielectric(cos, 1.33);
        let glossy = g.colours_at(i).expect("colour passes").1;
        // Relative to the closed form's own slope: at 80 degrees a thousandth of a radian
        // moves it by 1 %.
        worst = worst.max((f64::from(glossy[0]) - fresnel).abs() / (0.005 + 0.03 * fresnel));
        seen.push(fresnel);
        for (k, sky) in [0.5, 0.6, 0.7].into_iter().enumerate() {
            let expected = f64::from(glossy[k]) * sky;
            let got = f64::from(shaded.rgba[i][k]);
            assert!((got - expected).abs() < 1e-4, "pixel {i}: {got} where Glossy Color times the sky is {expected}");
        }
    }
    let (low, high) = seen.iter().fold((1.0f64, 0.0f64), |(l, h), &f| (l.min(f), h.max(f)));
    eprintln!(
        "Glossy Color against Fresnel over {} pixels ({low:.3} to {high:.3}): worst {worst:.2} of the tolerance",
        seen.len()
    );
    assert!(high > 0.3 && high - low > 0.2, "the view angles span Fresnel's rise: {low:.3} to {high:.3}");
    assert!(worst < 1.0, "the water's Glossy Color is {worst} times the tolerance from Fresnel's reflectance");
}

/// A shot rendered every second frame (Frame Step 2, frames 1 to 5) exports frames 1, 3
/// and 5, and scene.json lists them; `logsh render` without `--frames` renders those three
/// and no other.
#[test]
fn a_frame_step_exports_and_renders_every_step_th_frame() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let blend = dir.path().join("stepped.blend");
    let setup = "bpy.ops.mesh.primitive_plane_add(size=10); \
         bpy.ops.mesh.primitive_cube_add(location=(0, 0, 1)); cube = bpy.context.object; \
         cube.keyframe_insert('location', frame=1); cube.location = (1, 0, 1); \
         cube.keyframe_insert('location', frame=5); \
         bpy.ops.object.camera_add(location=(0, -9, 6), rotation=(math.radians(55), 0, 0)); \
         bpy.context.scene.camera = bpy.context.object; \
         w = bpy.data.worlds.new('World'); bpy.context.scene.world = w; w.use_nodes = True; \
         w.node_tree.nodes['Background'].inputs['Color'].default_value = (0.4, 0.5, 0.7, 1); \
         bpy.context.scene.frame_start = 1; bpy.context.scene.frame_end = 5; bpy.context.scene.frame_step = 2";
    make_blend(&python, &blend, setup);
    let out = dir.path().join("scene");
    let args = [Path::new("--blend"), &blend, Path::new("--out"), &out, Path::new("--resolution"), Path::new("16x9")];
    assert_ok(&run_python(&python, "blender_scripts/export_scene.py", &args), "exporting every second frame");
    let scene = Scene::load(&out).unwrap();
    let frames = scene.frames.clone().unwrap();
    assert_eq!((frames.start, frames.end, frames.list), (1, 5, Some(vec![1, 3, 5])));
    assert!(!out.join("gbuffer.0002.exr").exists() && out.join("gbuffer.0005.exr").is_file());

    let rendered = dir.path().join("rendered");
    let output = crate::support::cli::logsh()
        .args(["render", "--device", "cpu", "--bounces", "0", "--out"])
        .arg(&rendered)
        .arg(&out)
        .output()
        .unwrap();
    assert_ok(&output, "logsh render of the stepped shot");
    for (frame, exists) in [(1, true), (2, false), (3, true), (4, false), (5, true)] {
        assert_eq!(rendered.join(format!("render.{frame:04}.exr")).is_file(), exists, "frame {frame}");
    }
}

/// A terrain that moves (a Wave modifier, and a keyed drop), a keyed Point lamp and a keyed World Strength,
/// exported over two frames: one height map per frame, and a frame file per frame with
/// its lamp and World; the frames differ as Blender's do, and logsh renders both. The
/// first frame's map given to the second frame is refused as not its terrain. A Sky
/// Texture World that changes stops the export.
#[test]
fn moving_terrain_lamps_and_world_export_per_frame() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let blend = dir.path().join("moving.blend");
    let setup = "bpy.ops.mesh.primitive_grid_add(x_subdivisions=80, y_subdivisions=80, size=8); \
         sea = bpy.context.object; sea.name = 'Sea'; sea['logsh_heightfield'] = True; \
         wave = sea.modifiers.new('Wave', 'WAVE'); wave.height = 0.4; wave.width = 1.2; wave.speed = 0.6; \
         wave.use_normal = False; sea.keyframe_insert('location', frame=1); sea.location = (0, 0, -1); \
         sea.keyframe_insert('location', frame=2); \
         bpy.ops.object.camera_add(location=(0, -9, 6), rotation=(math.radians(55), 0, 0)); \
         bpy.context.scene.camera = bpy.context.object; \
         bpy.ops.object.light_add(type='POINT', location=(-1, 0, 1)); lamp = bpy.context.object; \
         lamp.name = 'Lantern'; lamp.data.energy = 200; lamp.keyframe_insert('location', frame=1); \
         lamp.location = (1.5, 0.5, 1.2); lamp.keyframe_insert('location', frame=2); \
         w = bpy.data.worlds.new('World'); bpy.context.scene.world = w; w.use_nodes = True; \
         bg = w.node_tree.nodes['Background']; bg.inputs['Color'].default_value = (0.2, 0.3, 0.5, 1); \
         bg.inputs['Strength'].default_value = 1.0; bg.inputs['Strength'].keyframe_insert('default_value', frame=1); \
         bg.inputs['Strength'].default_value = 0.5; bg.inputs['Strength'].keyframe_insert('default_value', frame=2); \
         bpy.context.scene.frame_start = 1; bpy.context.scene.frame_end = 2";
    make_blend(&python, &blend, setup);
    let out = dir.path().join("scene");
    let args = [Path::new("--blend"), &blend, Path::new("--out"), &out, Path::new("--resolution"), Path::new("48x27")];
    let output = run_python(&python, "blender_scripts/export_scene.py", &args);
    assert_ok(&output, "exporting a moving terrain, lamp and World");
    let log = String::from_utf8_lossy(&output.stdout);
    assert!(log.contains("height field \"Sea\" moves within frames 1-2"), "{log}");

    let scene = Scene::load(&out).unwrap();
    assert_eq!(scene.heightfield.as_ref().unwrap().heights.0, "heightmap.####.exr");
    assert!(scene.per_frame.is_some());
    let (one, two) = (scene.frame(1).unwrap(), scene.frame(2).unwrap());
    let (map_one, map_two) = (one.height_map.as_ref().unwrap(), two.height_map.as_ref().unwrap());
    let moved = map_one.heights.iter().zip(&map_two.heights).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(moved > 0.1, "the two frames' maps differ by at most {moved}");
    assert_eq!((one.points.len(), two.points.len()), (1, 1));
    assert!((one.points[0].position[0] + 1.0).abs() < 1e-5, "{:?}", one.points[0]);
    assert!((two.points[0].position[0] - 1.5).abs() < 1e-5, "{:?}", two.points[0]);
    let constant = |f: &logsh::scene::Frame| match *f.light {
        logsh::scene::Light::Constant(c) => c,
        ref other => panic!("a constant World, not {other:?}"),
    };
    assert!((constant(&one)[2] - 0.5).abs() < 1e-5 && (constant(&two)[2] - 0.25).abs() < 1e-5);

    let rendered = dir.path().join("rendered");
    let output = crate::support::cli::logsh()
        .args(["render", "--device", "cpu", "--frames", "1-2", "--out"])
        .arg(&rendered)
        .arg(&out)
        .output()
        .unwrap();
    assert_ok(&output, "logsh render of the moving scene");

    // Frame 1's map as frame 2's: refused, naming both files.
    std::fs::copy(out.join("heightmap.0001.exr"), out.join("heightmap.0002.exr")).unwrap();
    let text = match scene.frame(2) {
        Ok(_) => panic!("frame 1's map was taken for frame 2's terrain"),
        Err(e) => e.to_string(),
    };
    assert!(text.contains("gbuffer.0002.exr") && text.contains("not this frame's terrain"), "{text}");

    // A World logsh bakes (a Sky Texture) that changes cannot be followed.
    let blend = dir.path().join("sky.blend");
    make_blend(
        &python,
        &blend,
        &format!(
            "{setup}; sky = w.node_tree.nodes.new('ShaderNodeTexSky'); \
             w.node_tree.links.new(sky.outputs['Color'], bg.inputs['Color'])"
        ),
    );
    let refused = dir.path().join("refused");
    let args =
        [Path::new("--blend"), &blend, Path::new("--out"), &refused, Path::new("--resolution"), Path::new("16x9")];
    let output = run_python(&python, "blender_scripts/export_scene.py", &args);
    assert_eq!(output.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("the World changes within frames 1-2"), "{stderr}");
    assert!(!refused.exists());
}

/// Runs `script` (Python statements, after the add-on under `package_parent` is imported
/// and registered as Blender registers it, and `blend` is opened) with `LOGSH_BINARY` set
/// to `binary` or, where `None`, removed and `logsh` kept off PATH.
fn run_engine(python: &Path, package_parent: &Path, blend: &Path, binary: Option<&Path>, script: &str) -> Output {
    let code = format!(
        "import os, sys, time\nsys.path.insert(0, {:?})\nimport bpy\nimport logsh_exporter\n\
         from logsh_exporter import engine\nlogsh_exporter.register()\n\
         bpy.ops.wm.open_mainfile(filepath={:?})\nscene = bpy.context.scene\nscene.render.engine = 'LOGSH'\n\
         image = scene.render.image_settings\n\
         if hasattr(image, 'media_type'):\n    image.media_type = 'MULTI_LAYER_IMAGE'\n\
         image.file_format = 'OPEN_EXR_MULTILAYER'\nimage.color_depth = '32'\n{script}\n",
        package_parent.to_str().unwrap(),
        blend.to_str().unwrap()
    );
    let mut command = std::process::Command::new(python);
    command.args(["-c", &code]);
    match binary {
        Some(binary) => command.env("LOGSH_BINARY", binary),
        None => command.env_remove("LOGSH_BINARY").env("PATH", "/usr/bin:/bin"),
    };
    command.output().unwrap()
}

/// The render engine (`blender_scripts/logsh_exporter/engine.py`): F12 on the tiny scene
/// gives `logsh shade`'s beauty of the same scene exported by hand, within 1e-3, and every
/// logsh pass as a render pass; Ctrl+F12's path renders frames 1 and 2 from one export;
/// an Area lamp stops the render with its name in Blender's report.
#[test]
fn render_engine_matches_logsh_shade_and_writes_its_passes() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let blend = dir.path().join("tiny.blend");
    assert_ok(&run_python(&python, "blender_scripts/scenes/tiny.py", &[Path::new("--save"), &blend]), "tiny.py");
    let binary = Path::new(env!("CARGO_BIN_EXE_logsh"));
    let scripts = Path::new(REPO).join("blender_scripts");

    let still = dir.path().join("still.exr");
    let script = format!(
        "scene.render.filepath = {:?}\nscene.render.use_file_extension = False\n\
         bpy.ops.render.render(write_still=True)",
        still.to_str().unwrap()
    );
    assert_ok(&run_engine(&python, &scripts, &blend, Some(binary), &script), "F12 with the logsh engine");
    let scene = dir.path().join("scene");
    assert_ok(&export_frame_1(&python, &blend, &scene, "64x36"), "export_scene.py");
    let shaded = dir.path().join("shaded");
    Command::new(binary).arg("shade").arg(&scene).arg("--out").arg(&shaded).assert().success();
    let engine = raw_channels(&still);
    let by_hand = raw_channels(&shaded.join("beauty.0001.exr"));
    let mut worst = 0.0f32;
    for c in ["R", "G", "B", "A"] {
        let (a, b) = (&engine[&format!("ViewLayer.Combined.{c}")], &by_hand[c]);
        assert_eq!(a.len(), b.len(), "{c}: the engine's frame is {} pixels", a.len());
        worst = a.iter().zip(b).fold(worst, |w, (x, y)| w.max((x - y).abs()));
    }
    println!("F12 against logsh shade: worst difference {worst:.2e}");
    assert!(worst <= 1e-3, "F12's beauty is {worst} from logsh shade's");
    for pass in ["Diffuse.R", "Specular.G", "Environment.B", "Indirect.R", "Visibility.X", "Visibility Blockers.X"] {
        assert!(engine.contains_key(&format!("ViewLayer.{pass}")), "no pass {pass}: {:?}", engine.keys());
    }

    let frames = dir.path().join("frames");
    let script = format!(
        "exports = []\noriginal = engine.Job._export\n\
         engine.Job._export = lambda job, e: (exports.append(list(job.frames)), original(job, e))[1]\n\
         scene.frame_start, scene.frame_end = 1, 2\nscene.render.filepath = {:?}\n\
         bpy.ops.render.render(animation=True)\nassert exports == [[1, 2]], exports\n\
         assert engine._JOB is None, 'the work directory is removed after the render'",
        frames.join("frame.####").to_str().unwrap()
    );
    assert_ok(&run_engine(&python, &scripts, &blend, Some(binary), &script), "Ctrl+F12 with the logsh engine");
    for frame in [1, 2] {
        let channels = raw_channels(&frames.join(format!("frame.{frame:04}.exr")));
        assert!(channels.contains_key("ViewLayer.Diffuse.R"), "frame {frame}: {:?}", channels.keys());
    }

    let script = "bpy.ops.object.light_add(type='AREA')\nbpy.context.object.name = 'Panel'\n\
                  try:\n    bpy.ops.render.render(write_still=False)\nexcept RuntimeError as e:\n    \
                  print('reported:', e)\nelse:\n    sys.exit('rendered with an Area lamp')";
    let output = run_engine(&python, &scripts, &blend, Some(binary), script);
    assert_ok(&output, "F12 with an Area lamp");
    let reported = String::from_utf8_lossy(&output.stdout);
    assert!(reported.contains("reported:") && reported.contains("Panel"), "{reported}");
}

/// The extension zip (`blender_scripts/build_extension.py`, which runs Blender's own
/// `extension validate` on it) carries the logsh binary: installed by Blender's extension
/// installer (which keeps no file modes) and registered, it renders with neither
/// `LOGSH_BINARY` nor `logsh` on PATH.
#[test]
fn extension_zip_installs_and_renders() {
    let Some(python) = bpy_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let binary = Path::new(env!("CARGO_BIN_EXE_logsh"));
    let out = dir.path().join("zip");
    let built = run_python(
        &python,
        "blender_scripts/build_extension.py",
        &[Path::new("--binary"), binary, Path::new("--out"), &out],
    );
    assert_ok(&built, "build_extension.py");
    let zip = PathBuf::from(String::from_utf8_lossy(&built.stdout).trim());
    assert!(zip.starts_with(&out) && zip.extension().is_some_and(|e| e == "zip"), "{}", zip.display());

    let extensions = dir.path().join("extensions");
    let package = extensions.join("logsh_exporter");
    std::fs::create_dir(&extensions).unwrap();
    let install = format!(
        "import bpy, os, platform, subprocess, sys, tomllib\n\
         cli = os.path.join(bpy.utils.system_resource('SCRIPTS'), 'addons_core', 'bl_pkg', 'cli', 'blender_ext.py')\n\
         subprocess.run([sys.executable, cli, 'install-files', '--local-dir', {:?}, '--blender-version', \
         '%d.%d.%d' % bpy.app.version, '--python-version', platform.python_version(), {:?}], check=True)\n\
         manifest = tomllib.loads(open({:?}).read())\nassert manifest['platforms'] == ['linux-x64'], manifest\n\
         assert os.path.isfile({:?})",
        extensions.to_str().unwrap(),
        zip.to_str().unwrap(),
        package.join("blender_manifest.toml").to_str().unwrap(),
        package.join("bin/logsh").to_str().unwrap()
    );
    assert_ok(
        &std::process::Command::new(&python).args(["-c", &install]).output().unwrap(),
        "installing the zip with Blender's extension installer",
    );

    let blend = dir.path().join("tiny.blend");
    assert_ok(&run_python(&python, "blender_scripts/scenes/tiny.py", &[Path::new("--save"), &blend]), "tiny.py");
    let still = dir.path().join("still.exr");
    let script = format!(
        "scene.render.filepath = {:?}\nscene.render.use_file_extension = False\n\
         assert engine.logsh_binary() == os.path.join({:?}, 'bin', 'logsh'), engine.logsh_binary()\n\
         bpy.ops.render.render(write_still=True)",
        still.to_str().unwrap(),
        package.to_str().unwrap()
    );
    assert_ok(&run_engine(&python, &extensions, &blend, None, &script), "rendering from the installed zip");
    assert!(raw_channels(&still).contains_key("ViewLayer.Combined.R"));
}
