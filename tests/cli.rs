//! The command line as a black box: exit codes, outputs, and the wording of errors.
use std::path::Path;

use crate::support::cli::{assert_fails_with, logsh, stderr_of, FAILED, REFUSED_WHILE_PARSING};

/// A small sphere-over-plane scene written by `logsh example`.
fn example_scene(dir: &Path) -> std::path::PathBuf {
    let scene = dir.join("scene");
    logsh().args(["example", "spheres", "--width", "48", "--height", "27", "--out"]).arg(&scene).assert().success();
    scene
}

#[test]
fn shade_writes_exr_and_png() {
    let dir = tempfile::tempdir().unwrap();
    let scene = example_scene(dir.path());
    let out = dir.path().join("out");
    let output = logsh().arg("shade").arg(&scene).arg("--out").arg(&out).output().unwrap();
    assert!(output.status.success(), "{}", stderr_of(&output));
    assert!(stderr_of(&output).contains("shaded frame 1 (48x27)"));
    assert!(out.join("beauty.0001.exr").is_file());
    assert!(out.join("beauty.0001.png").is_file());
    let png = image::open(out.join("beauty.0001.png")).unwrap();
    assert_eq!((png.width(), png.height()), (48, 27));
}

#[test]
fn every_exponentiation_and_order_runs() {
    let dir = tempfile::tempdir().unwrap();
    let scene = example_scene(dir.path());
    for exp in ["hyb", "ol", "series", "quad", "exact"] {
        for order in ["3", "8"] {
            let out = dir.path().join(format!("out-{exp}-{order}"));
            let output = logsh()
                .arg("shade")
                .arg(&scene)
                .args(["--exp", exp, "--order", order, "--ratio-attenuation", "on", "--precision", "f64", "--out"])
                .arg(&out)
                .output()
                .unwrap();
            assert!(output.status.success(), "--exp {exp} --order {order}: {}", stderr_of(&output));
        }
    }
}

#[test]
fn bad_flags_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let scene = example_scene(dir.path());
    let out = dir.path().join("out");
    assert_fails_with(
        &logsh().arg("shade").arg(&scene).args(["--order", "9"]).arg("--out").arg(&out).output().unwrap(),
        FAILED,
        &["--order 9"],
    );
    assert_fails_with(
        &logsh().arg("shade").arg(&scene).args(["--epsilon", "0"]).arg("--out").arg(&out).output().unwrap(),
        FAILED,
        &["--epsilon 0"],
    );
    assert_fails_with(
        &logsh().arg("shade").arg(&scene).args(["--directions", "2"]).arg("--out").arg(&out).output().unwrap(),
        FAILED,
        &["--directions 2"],
    );
    assert_fails_with(
        &logsh().arg("shade").arg(&scene).args(["--exp", "fast"]).output().unwrap(),
        REFUSED_WHILE_PARSING,
        &["--exp"],
    );
    assert!(!out.exists(), "nothing is written when the flags are wrong");
}

#[test]
fn bad_scenes_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nowhere");
    assert_fails_with(&logsh().arg("shade").arg(&missing).output().unwrap(), FAILED, &["error:", "nowhere"]);

    let scene = example_scene(dir.path());
    let json = scene.join("scene.json");
    let original = std::fs::read_to_string(&json).unwrap();

    std::fs::write(&json, original.replacen("\"version\": 1", "\"version\": 1,\n  \"colour\": 3", 1)).unwrap();
    assert_fails_with(&logsh().arg("shade").arg(&scene).output().unwrap(), FAILED, &["scene.json", "colour"]);

    std::fs::write(&json, "{\n  \"version\": 1,\n  \"gbuffer\": \n}").unwrap();
    assert_fails_with(&logsh().arg("shade").arg(&scene).output().unwrap(), FAILED, &["scene.json:4:1"]);

    std::fs::write(&json, &original).unwrap();
    std::fs::write(
        scene.join("blockers.0001.json"),
        r#"{"frame": 1, "spheres": [{"center": [0, 0, 2], "radius": -1}]}"#,
    )
    .unwrap();
    assert_fails_with(&logsh().arg("shade").arg(&scene).output().unwrap(), FAILED, &["blockers.0001.json", "radius"]);

    std::fs::remove_file(scene.join("gbuffer.0001.exr")).unwrap();
    assert_fails_with(&logsh().arg("shade").arg(&scene).output().unwrap(), FAILED, &["gbuffer.0001.exr"]);
}

#[test]
fn inputs_are_never_written_over() {
    let dir = tempfile::tempdir().unwrap();
    let scene = example_scene(dir.path());
    // A scene whose G-buffer is named like the output: shading into its own directory
    // must refuse rather than replace the input.
    std::fs::rename(scene.join("gbuffer.0001.exr"), scene.join("beauty.0001.exr")).unwrap();
    let json = scene.join("scene.json");
    let text = std::fs::read_to_string(&json).unwrap().replace("gbuffer.####.exr", "beauty.####.exr");
    std::fs::write(&json, text).unwrap();
    let before = std::fs::read(scene.join("beauty.0001.exr")).unwrap();
    assert_fails_with(
        &logsh().arg("shade").arg(&scene).arg("--out").arg(&scene).output().unwrap(),
        FAILED,
        &["beauty.0001.exr"],
    );
    assert_eq!(std::fs::read(scene.join("beauty.0001.exr")).unwrap(), before);
    // And `logsh example` does not overwrite a scene.
    assert_fails_with(
        &logsh().args(["example", "spheres", "--out"]).arg(&scene).output().unwrap(),
        FAILED,
        &["already holds a scene"],
    );
}

#[test]
fn device_gpu_without_an_adapter_fails_and_auto_falls_back() {
    let dir = tempfile::tempdir().unwrap();
    let scene = example_scene(dir.path());
    // No Metal adapter exists off Apple machines; on one, this test has nothing to check.
    if cfg!(target_os = "macos") {
        return;
    }
    let out = dir.path().join("out");
    let gpu = logsh()
        .env("WGPU_BACKEND", "metal")
        .args(["shade", "--device", "gpu"])
        .arg(&scene)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(gpu.status.code(), Some(1), "{}", stderr_of(&gpu));
    assert!(stderr_of(&gpu).contains("no GPU adapter found"), "{}", stderr_of(&gpu));
    assert!(!out.join("beauty.0001.exr").exists());
    let auto = logsh()
        .env("WGPU_BACKEND", "metal")
        .args(["shade", "--device", "auto"])
        .arg(&scene)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(auto.status.success(), "{}", stderr_of(&auto));
    let lines: Vec<String> =
        stderr_of(&auto).lines().filter(|l| l.contains("--device auto")).map(String::from).collect();
    assert_eq!(lines.len(), 1, "one line says why the CPU is used: {lines:?}");
    assert!(lines[0].contains("shading on the CPU") && lines[0].contains("no GPU adapter"), "{}", lines[0]);
    assert!(stderr_of(&auto).contains("on cpu"));
    assert!(out.join("beauty.0001.exr").is_file());
}

#[test]
fn bench_prints_stages_as_a_table_and_as_json() {
    let dir = tempfile::tempdir().unwrap();
    let scene = example_scene(dir.path());
    // Direct light alone: the executor's own stages.
    let args = ["bench", "--device", "cpu", "--repeats", "2", "--bounces", "0"];
    let table = logsh().args(args).arg(&scene).output().unwrap();
    assert!(table.status.success(), "{}", stderr_of(&table));
    let text = String::from_utf8_lossy(&table.stdout);
    for word in ["stage", "tables", "shade", "frame", "Mpixel/s", "median of 2 run(s)"] {
        assert!(text.contains(word), "no {word:?} in\n{text}");
    }
    // With bounce light (the default preset's), the shading and the bounce.
    let table = logsh().args(["bench", "--device", "cpu", "--repeats", "2"]).arg(&scene).output().unwrap();
    assert!(table.status.success(), "{}", stderr_of(&table));
    let text = String::from_utf8_lossy(&table.stdout);
    for word in ["shade", "bounce", "frame"] {
        assert!(text.contains(word), "no {word:?} in\n{text}");
    }
    let json = logsh().args(["bench", "--device", "cpu", "--repeats", "1", "--json"]).arg(&scene).output().unwrap();
    assert!(json.status.success(), "{}", stderr_of(&json));
    let report: serde_json::Value = serde_json::from_slice(&json.stdout).expect("bench --json prints JSON");
    assert_eq!(report["width"], 48);
    assert!(report["stages"]
        .as_array()
        .is_some_and(|s| s.iter().any(|s| s["name"] == "shade" && s["milliseconds"].as_f64().unwrap() > 0.0)));
    assert!(report["megapixels_per_second"].as_f64().unwrap() > 0.0);
    // The CPU has no program to specialise: neither the table nor the JSON claims one.
    assert!(!text.contains("program"), "GPU wording on the CPU:\n{text}");
    assert!(report["specialisation"].is_null(), "{}", report["specialisation"]);
}

#[test]
fn a_blend_file_is_refused_with_the_export_step() {
    let dir = tempfile::tempdir().unwrap();
    let blend = dir.path().join("scene.blend");
    std::fs::write(&blend, b"BLENDER").unwrap();
    for command in ["shade", "render"] {
        let output = logsh().arg(command).arg(&blend).arg("--out").arg(dir.path().join("out")).output().unwrap();
        assert_eq!(output.status.code(), Some(1));
        let error = stderr_of(&output);
        assert!(error.contains("scene.blend") && error.contains("export_scene.py"), "{command}: {error}");
        assert!(!error.contains("Not a directory"), "{command}: {error}");
    }
}

#[test]
fn an_unreadable_scene_names_its_cause_once() {
    let dir = tempfile::tempdir().unwrap();
    // A directory named like the scene file: reading it fails with one OS error.
    std::fs::create_dir_all(dir.path().join("scene.json")).unwrap();
    let output = logsh().arg("shade").arg(dir.path()).output().unwrap();
    let error = stderr_of(&output);
    let cause = error.rsplit(": ").next().unwrap_or_default().trim().to_string();
    assert!(error.contains("cannot read"), "{error}");
    assert_eq!(error.matches(&cause).count(), 1, "the cause is repeated: {error}");
}

/// `--visibility-grid`: out-of-range values are named; `--transfer` refuses it; every
/// device renders with it (tests/gpu.rs compares the GPU's grid with the CPU's).
#[test]
fn visibility_grid_is_checked_and_renders() {
    let dir = tempfile::tempdir().unwrap();
    let scene = example_scene(dir.path());
    let out = dir.path().join("out");
    for bad in ["0", "5"] {
        let mut cmd = logsh();
        cmd.arg("shade").arg(&scene).args(["--visibility-grid", bad]).arg("--out").arg(&out);
        assert_fails_with(&cmd.output().unwrap(), FAILED, &[&format!("--visibility-grid {bad} is outside 1..=4")]);
    }
    let mut transfer = logsh();
    transfer.args(["render", "--device", "cpu", "--transfer", "--visibility-grid", "2", "--progress", "none"]);
    assert_fails_with(
        &transfer.arg(&scene).arg("--out").arg(&out).output().unwrap(),
        FAILED,
        &["--visibility-grid 2", "--transfer"],
    );
    assert!(!out.exists(), "nothing is written when the flags are refused");

    let auto = logsh()
        .args(["shade", "--device", "auto", "--visibility-grid", "2"])
        .arg(&scene)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(auto.status.success(), "{}", stderr_of(&auto));
    assert!(!stderr_of(&auto).contains("--visibility-grid 2 was asked"), "{}", stderr_of(&auto));
    assert!(out.join("beauty.0001.exr").is_file());
}

/// `logsh info FILE ... | head -1`: a standard output closed early ends logsh quietly, as
/// it ends C tools (SIGPIPE), with no panic and no backtrace. The listing of 300 files
/// overflows the pipe's buffer, so a write meets the closed pipe whatever the timing.
#[test]
fn a_closed_pipe_ends_quietly() {
    let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("gbuffers/dunes/gbuffer.0001.exr");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_logsh"))
        .arg("info")
        .args(std::iter::repeat_n(&file, 300))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let output = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!stderr.contains("panicked") && !stderr.contains("Broken pipe"), "{stderr}");
    #[cfg(unix)]
    {
        use std::os::unix::process::ExitStatusExt;
        assert_eq!(output.status.signal(), Some(libc::SIGPIPE), "{:?}: {stderr}", output.status);
    }
}
