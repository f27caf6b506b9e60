//! `logsh render` and `logsh info` as a black box: a three-frame shot rendered into
//! multi-layer EXRs whose passes add up to the beauty, resuming after a killed run, and
//! every bad input ending in a non-zero exit with the file named and no panic.

use exr::prelude::{read_all_flat_layers_from_file, FlatSamples};
use logsh::scene::Camera;
use logsh::synth::{self, ExampleOptions};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Stdio;

use crate::support::cli::{assert_fails_with, logsh, stderr_of, FAILED, REFUSED_WHILE_PARSING};

/// The dune sample (height field, blockers, water, a Phong sphere, a sky map) with a
/// third frame whose camera has moved: per-frame cameras and blockers both change.
fn three_frame_scene(dir: &Path, width: u32, height: u32) -> PathBuf {
    let mut scene = synth::example("dunes", ExampleOptions { width, height, ..Default::default() }).unwrap();
    let mut third = scene.frames[1].clone();
    third.number = 3;
    third.camera = Camera::look_at([2.0, -15.0, 5.5], [0.0, 0.0, 0.5], [0.0, 0.0, 1.0], 24.0, 36.0, [width, height]);
    scene.frames.push(third);
    let out = dir.join("shot");
    synth::write_scene(&out, &scene).unwrap();
    out
}

/// Channel values as f32 and the type they were stored as, by full name.
type Channels = HashMap<String, (Vec<f32>, &'static str)>;

/// Every channel of an EXR, with the image size.
fn channels(path: &Path) -> (usize, usize, Channels) {
    let image = read_all_flat_layers_from_file(path).unwrap();
    assert_eq!(image.layer_data.len(), 1, "one part");
    let layer = &image.layer_data[0];
    let map = layer
        .channel_data
        .list
        .iter()
        .map(|c| {
            let (values, kind) = match &c.sample_data {
                FlatSamples::F16(v) => (v.iter().map(|h| h.to_f32()).collect(), "half"),
                FlatSamples::F32(v) => (v.clone(), "float"),
                FlatSamples::U32(v) => (v.iter().map(|&u| u as f32).collect(), "uint"),
            };
            (c.name.to_string(), (values, kind))
        })
        .collect();
    (layer.size.0, layer.size.1, map)
}

const PASS_CHANNELS: &[&str] = &[
    "R",
    "G",
    "B",
    "A",
    "diffuse.R",
    "diffuse.G",
    "diffuse.B",
    "specular.R",
    "specular.G",
    "specular.B",
    "environment.R",
    "environment.G",
    "environment.B",
    "indirect.R",
    "indirect.G",
    "indirect.B",
    "indirect_heightfield.R",
    "indirect_heightfield.G",
    "indirect_heightfield.B",
    "indirect_blockers.R",
    "indirect_blockers.G",
    "indirect_blockers.B",
    "visibility.Y",
    "visibility_heightfield.Y",
    "visibility_blockers.Y",
    "P.X",
    "P.Y",
    "P.Z",
    "N.X",
    "N.Y",
    "N.Z",
];

#[test]
fn three_frames_render_to_passes_that_add_up() {
    let dir = tempfile::tempdir().unwrap();
    let scene = three_frame_scene(dir.path(), 64, 36);
    let out = dir.path().join("out");
    let output = logsh()
        .arg("render")
        .arg(&scene)
        .args(["--frames", "1-3", "--colour-type", "float", "--progress", "lines", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(output.status.success(), "{}", stderr_of(&output));
    assert!(stderr_of(&output).contains("3 frame(s) rendered, 0 skipped, 0 failed"), "{}", stderr_of(&output));

    for frame in 1..=3 {
        let exr = out.join(format!("render.{frame:04}.exr"));
        let (w, h, c) = channels(&exr);
        assert_eq!((w, h), (64, 36));
        let mut names: Vec<&str> = c.keys().map(|s| s.as_str()).collect();
        names.sort();
        let mut expected = PASS_CHANNELS.to_vec();
        expected.sort();
        assert_eq!(names, expected);
        // Stored as float (--colour-type float), the sums are exact: the beauty is the
        // direct passes plus the bounce, and the bounce its two parts.
        for (k, ch) in ["R", "G", "B"].iter().enumerate() {
            for (i, beauty) in c[*ch].0.iter().enumerate() {
                let indirect = c[&format!("indirect.{ch}")].0[i];
                let sum = c[&format!("diffuse.{ch}")].0[i]
                    + c[&format!("specular.{ch}")].0[i]
                    + c[&format!("environment.{ch}")].0[i]
                    + indirect;
                assert_eq!(sum, *beauty, "frame {frame} pixel {i} channel {k}");
                let parts = c[&format!("indirect_heightfield.{ch}")].0[i] + c[&format!("indirect_blockers.{ch}")].0[i];
                assert_eq!(parts, indirect, "frame {frame} pixel {i} channel {k}: the bounce's parts");
            }
        }
        // Something of every kind of shading is in the frame, bounce light from the
        // height field and from the blockers included.
        let positive = |name: &str| c[name].0.iter().filter(|&&v| v > 1e-4).count();
        assert!(positive("specular.G") > 0 && positive("environment.G") > 0 && positive("diffuse.G") > 0);
        assert!(positive("indirect_heightfield.G") > 0 && positive("indirect_blockers.G") > 0);
        for name in ["indirect.R", "indirect.G", "indirect.B"] {
            assert!(c[name].0.iter().all(|v| v.is_finite() && *v >= 0.0), "{name} negative or not finite");
        }
        let shadowed = |name: &str| c[name].0.iter().filter(|&&v| v < 0.9).count();
        assert!(shadowed("visibility_heightfield.Y") > 0, "the dunes shadow themselves");
        assert!(shadowed("visibility_blockers.Y") > 0, "the spheres cast shadows");
        for name in ["visibility.Y", "visibility_heightfield.Y", "visibility_blockers.Y"] {
            assert!(c[name].0.iter().all(|v| v.is_finite() && *v >= 0.0 && *v <= 1.2), "{name} out of range");
        }
        // P and N are the G-buffer's, bit for bit.
        let g = logsh::scene::Scene::load(&scene).unwrap().frame(frame).unwrap().gbuffer;
        for (k, axis) in ["X", "Y", "Z"].iter().enumerate() {
            assert!(c[&format!("P.{axis}")].0.iter().zip(&g.position).all(|(a, p)| a.to_bits() == p[k].to_bits()));
            assert!(c[&format!("N.{axis}")].0.iter().zip(&g.normal).all(|(a, n)| a.to_bits() == n[k].to_bits()));
        }
        assert_eq!(c["P.X"].1, "float");
        assert!(out.join(format!("render.{frame:04}.png")).is_file());
    }

    // The beauty is `logsh shade`'s image (water pixels up to rounding of tint * (d + s)).
    let shaded = dir.path().join("shaded");
    logsh().arg("shade").arg(&scene).args(["--frame", "3", "--out"]).arg(&shaded).assert().success();
    let (_, _, single) = channels(&shaded.join("beauty.0003.exr"));
    let (_, _, layered) = channels(&out.join("render.0003.exr"));
    for ch in ["R", "G", "B", "A"] {
        for (a, b) in single[ch].0.iter().zip(&layered[ch].0) {
            assert!((a - b).abs() <= 1e-6 * a.abs().max(1.0), "{ch}: {a} vs {b}");
        }
    }

    // Half colour (the default): the sum holds to half precision.
    let half = dir.path().join("half");
    logsh()
        .arg("render")
        .arg(&scene)
        .args(["--frames", "2", "--progress", "none", "--out"])
        .arg(&half)
        .assert()
        .success();
    let (_, _, c) = channels(&half.join("render.0002.exr"));
    assert_eq!(c["R"].1, "half");
    assert_eq!(c["P.X"].1, "float");
    for ch in ["R", "G", "B"] {
        for i in 0..c[ch].0.len() {
            let sum = c[&format!("diffuse.{ch}")].0[i]
                + c[&format!("specular.{ch}")].0[i]
                + c[&format!("environment.{ch}")].0[i]
                + c[&format!("indirect.{ch}")].0[i];
            assert!((sum - c[ch].0[i]).abs() <= 2e-3 * c[ch].0[i].abs().max(1e-2), "{ch} {i}");
        }
    }

    // `logsh info` lists the layers and types.
    let output = logsh().arg("info").arg(out.join("render.0001.exr")).output().unwrap();
    let text = String::from_utf8_lossy(&output.stdout);
    assert!(output.status.success());
    for needle in ["64 x 36", "ZIP16", "diffuse", "B G R", "visibility_heightfield", "P ", "X Y Z", "float"] {
        assert!(text.contains(needle), "{needle:?} in {text}");
    }
    let output = logsh().args(["info", "--json"]).arg(half.join("render.0002.exr")).output().unwrap();
    let json: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(json[0]["parts"][0]["channels"].as_array().unwrap().len(), PASS_CHANNELS.len());
}

fn modified_and_bytes(path: &Path) -> (std::time::SystemTime, Vec<u8>) {
    (std::fs::metadata(path).unwrap().modified().unwrap(), std::fs::read(path).unwrap())
}

#[test]
fn skip_existing_leaves_finished_frames_untouched() {
    let dir = tempfile::tempdir().unwrap();
    let scene = three_frame_scene(dir.path(), 32, 18);
    let out = dir.path().join("out");
    let render = |extra: &[&str]| {
        logsh().arg("render").arg(&scene).args(["--progress", "json", "--out"]).arg(&out).args(extra).output().unwrap()
    };
    assert!(render(&[]).status.success());
    let files: Vec<PathBuf> =
        (1..=3).flat_map(|f| ["exr", "png"].map(|e| out.join(format!("render.{f:04}.{e}")))).collect();
    let before: Vec<_> = files.iter().map(|f| modified_and_bytes(f)).collect();
    std::thread::sleep(std::time::Duration::from_millis(20));
    std::fs::remove_file(&files[3]).unwrap(); // frame 2's PNG: frame 2 is incomplete.

    let output = render(&["--skip-existing"]);
    assert!(output.status.success(), "{}", stderr_of(&output));
    let events: Vec<serde_json::Value> =
        String::from_utf8_lossy(&output.stdout).lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let statuses: Vec<&str> =
        events.iter().filter(|e| e["event"] == "frame").map(|e| e["status"].as_str().unwrap()).collect();
    assert_eq!(statuses, ["skipped", "rendered", "skipped"]);
    assert_eq!(events.last().unwrap()["event"], "done");
    for (i, file) in files.iter().enumerate() {
        let after = modified_and_bytes(file);
        assert_eq!(after.1, before[i].1, "{} has the same bytes", file.display());
        if !(2..4).contains(&i) {
            assert_eq!(after.0, before[i].0, "{} untouched", file.display());
        }
    }
}

#[test]
fn a_killed_render_resumes_to_identical_frames() {
    let dir = tempfile::tempdir().unwrap();
    let scene = three_frame_scene(dir.path(), 160, 90);
    let full = dir.path().join("full");
    let resumed = dir.path().join("resumed");
    let bin = assert_cmd::cargo::cargo_bin("logsh");
    let args = |out: &Path| -> Vec<std::ffi::OsString> {
        vec![
            "render".into(),
            scene.clone().into(),
            "--progress".into(),
            "json".into(),
            "--threads".into(),
            "1".into(),
            "--out".into(),
            out.into(),
        ]
    };
    assert!(std::process::Command::new(&bin).args(args(&full)).output().unwrap().status.success());

    // Kill the render as soon as its first frame is on disk.
    let mut child = std::process::Command::new(&bin)
        .args(args(&resumed))
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut reader = std::io::BufReader::new(child.stdout.take().unwrap());
    let mut line = String::new();
    loop {
        line.clear();
        assert!(std::io::BufRead::read_line(&mut reader, &mut line).unwrap() > 0, "render ended before a frame");
        if line.contains("\"event\":\"frame\"") {
            break;
        }
    }
    child.kill().unwrap();
    let status = child.wait().unwrap();
    assert!(!status.success(), "the render was killed mid-sequence");
    let finished = (1..=3).filter(|f| resumed.join(format!("render.{f:04}.png")).exists()).count();
    assert!((1..3).contains(&finished), "{finished} frame(s) finished before the kill");
    let first = modified_and_bytes(&resumed.join("render.0001.exr"));

    let output = std::process::Command::new(&bin).args(args(&resumed)).arg("--skip-existing").output().unwrap();
    assert!(output.status.success(), "{}", stderr_of(&output));
    assert_eq!(modified_and_bytes(&resumed.join("render.0001.exr")).0, first.0, "frame 1 was not rendered again");
    for f in 1..=3 {
        for ext in ["exr", "png"] {
            let name = format!("render.{f:04}.{ext}");
            assert_eq!(std::fs::read(full.join(&name)).unwrap(), std::fs::read(resumed.join(&name)).unwrap(), "{name}");
        }
    }
}

/// SIGKILL at five points spread over a render (mid-read, mid-shade, mid-write), each
/// followed by a resume with `--skip-existing`: every frame ends byte-identical to an
/// uninterrupted render, and no temporary file is left. Then outputs a crash could leave
/// (an EXR of zeros, one cut short, a PNG cut short) are rendered again, not skipped.
#[test]
fn kills_at_any_point_resume_to_identical_frames() {
    let dir = tempfile::tempdir().unwrap();
    let scene = three_frame_scene(dir.path(), 320, 180);
    let bin = assert_cmd::cargo::cargo_bin("logsh");
    let render = |out: &Path| {
        let mut command = std::process::Command::new(&bin);
        command.arg("render").arg(&scene).args(["--progress", "none", "--threads", "1", "--out"]).arg(out);
        command.arg("--skip-existing").stdout(Stdio::null()).stderr(Stdio::piped());
        command
    };
    let full = dir.path().join("full");
    let started = std::time::Instant::now();
    assert!(render(&full).output().unwrap().status.success());
    let whole = started.elapsed();
    let names: Vec<String> = (1..=3).flat_map(|f| ["exr", "png"].map(|e| format!("render.{f:04}.{e}"))).collect();
    let same_as_full = |out: &Path, what: &str| {
        for name in &names {
            let (a, b) = (std::fs::read(full.join(name)).unwrap(), std::fs::read(out.join(name)));
            assert!(b.as_ref().is_ok_and(|b| *b == a), "{what}: {name} differs from the uninterrupted render");
        }
        let entries = std::fs::read_dir(out).unwrap().flatten();
        let temporary: Vec<_> = entries.filter(|e| e.file_name().to_string_lossy().ends_with(".tmp")).collect();
        assert!(temporary.is_empty(), "{what}: temporary files left: {temporary:?}");
    };
    for (k, fraction) in [0.1, 0.3, 0.5, 0.7, 0.9].into_iter().enumerate() {
        let out = dir.path().join(format!("killed-{k}"));
        let mut child = render(&out).spawn().unwrap();
        std::thread::sleep(whole.mul_f64(fraction));
        let _ = child.kill(); // SIGKILL on Unix
        child.wait().unwrap();
        let resumed = render(&out).output().unwrap();
        assert!(resumed.status.success(), "{}", stderr_of(&resumed));
        same_as_full(&out, &format!("killed at {fraction} of the render"));
    }

    let out = dir.path().join("damaged");
    assert!(render(&out).output().unwrap().status.success());
    let exr = |f: u32| out.join(format!("render.{f:04}.exr"));
    let length = std::fs::metadata(exr(2)).unwrap().len() as usize;
    std::fs::write(exr(1), vec![0u8; length]).unwrap();
    std::fs::write(exr(2), &std::fs::read(exr(2)).unwrap()[..length - 100]).unwrap();
    let png = out.join("render.0003.png");
    let bytes = std::fs::read(&png).unwrap();
    std::fs::write(&png, &bytes[..bytes.len() / 2]).unwrap();
    std::fs::write(out.join(".render.0003.exr.4194303.0.tmp"), b"left by a killed run").unwrap();
    let resumed = render(&out).output().unwrap();
    assert!(resumed.status.success(), "{}", stderr_of(&resumed));
    assert!(stderr_of(&resumed).contains("removed 1 temporary file(s)"), "{}", stderr_of(&resumed));
    same_as_full(&out, "damaged outputs");
}

/// Stops the local Slurm cluster of [`the_slurm_job_array_renders_on_a_local_cluster`]
/// when dropped.
struct LocalCluster(PathBuf);

impl Drop for LocalCluster {
    fn drop(&mut self) {
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("farm/slurm/local-cluster.sh");
        let _ = std::process::Command::new("bash").arg(script).arg("stop").arg(&self.0).output();
    }
}

/// The farm path on a real Slurm cluster: `farm/slurm/local-cluster.sh` starts one node
/// on this machine, the repository's sbatch job array renders a three-frame shot, one
/// array task per frame, to the bytes of a plain `logsh render`; with frame 2's G-buffer
/// cut short, its task fails with the file named in its log and the others render.
/// Skipped, with the reason, where the cluster cannot start (no Slurm, not root), unless
/// `LOGSH_REQUIRE_SLURM=1` (which `.ci/run` sets once it has installed Slurm): then that
/// is a failure.
#[test]
fn the_slurm_job_array_renders_on_a_local_cluster() {
    let required = std::env::var("LOGSH_REQUIRE_SLURM").is_ok_and(|v| v == "1");
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let cluster = dir.path().join("cluster");
    let started = std::process::Command::new("bash")
        .arg(repo.join("farm/slurm/local-cluster.sh"))
        .arg("start")
        .arg(&cluster)
        .output()
        .unwrap();
    let _stop = LocalCluster(cluster.clone());
    if !started.status.success() {
        let why = stderr_of(&started);
        assert!(!required, "LOGSH_REQUIRE_SLURM=1 but the local cluster did not start: {why}");
        let line = format!("tests/render_cli.rs: the Slurm test skipped: {}\n", why.trim());
        let _ = std::io::Write::write_all(&mut std::io::stderr(), line.as_bytes());
        return;
    }
    let bin = assert_cmd::cargo::cargo_bin("logsh");
    let submit = |scene: &Path, out: &Path| {
        std::fs::create_dir_all(out).unwrap();
        std::process::Command::new("timeout")
            .args(["300", "sbatch", "--wait", "--array=0-2", "--cpus-per-task=1", "--mem=1M", "--time=5"])
            .arg(format!("--output={}/logsh-%A_%a.log", out.display()))
            .arg(repo.join("farm/slurm/logsh-render.sbatch"))
            .env("SLURM_CONF", cluster.join("slurm.conf"))
            .env("SCENE", scene)
            .env("OUT", out)
            .env("FIRST", "1")
            .env("LAST", "3")
            .env("CHUNK", "1")
            .env("LOGSH", &bin)
            .output()
            .unwrap()
    };
    let log_of = |out: &Path, task: u32| {
        let name = std::fs::read_dir(out)
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .find(|n| n.starts_with("logsh-") && n.ends_with(&format!("_{task}.log")))
            .unwrap_or_else(|| panic!("no log of array task {task} in {}", out.display()));
        std::fs::read_to_string(out.join(name)).unwrap()
    };

    let shot = three_frame_scene(dir.path(), 64, 36);
    let plain = dir.path().join("plain");
    let output = logsh().arg("render").arg(&shot).args(["--progress", "none", "--out"]).arg(&plain).output().unwrap();
    assert!(output.status.success(), "{}", stderr_of(&output));
    let farmed = dir.path().join("farmed");
    let output = submit(&shot, &farmed);
    assert!(output.status.success(), "sbatch: {}\n{}", stderr_of(&output), log_of(&farmed, 0));
    for f in 1..=3 {
        for ext in ["exr", "png"] {
            let name = format!("render.{f:04}.{ext}");
            let (a, b) = (std::fs::read(plain.join(&name)).unwrap(), std::fs::read(farmed.join(&name)));
            assert!(b.is_ok_and(|b| b == a), "{name}: the array task's frame differs from logsh render's");
        }
    }

    let gbuffer = shot.join("gbuffer.0002.exr");
    let bytes = std::fs::read(&gbuffer).unwrap();
    std::fs::write(&gbuffer, &bytes[..bytes.len() / 2]).unwrap();
    let broken = dir.path().join("broken");
    let output = submit(&shot, &broken);
    assert!(!output.status.success(), "the array failed: one of its tasks did");
    let log = log_of(&broken, 1);
    assert!(log.contains("gbuffer.0002.exr") && log.contains("1 failed"), "task 1's log:\n{log}");
    for f in [1, 3] {
        assert!(broken.join(format!("render.{f:04}.exr")).is_file(), "frame {f} rendered beside the failure");
    }
}

/// Flamenco's authoring API as its documentation defines it, stubbed for Node: a script
/// that loads a job type, checks its settings, compiles a job of `settings` and prints the
/// tasks as JSON. `frameChunker` splits a frame list into chunks of consecutive frames,
/// written `a-b` (or `a` alone).
const FLAMENCO_STUB: &str = r#"
const fs = require("fs"), vm = require("vm");
const [file, settings] = [process.argv[1], JSON.parse(process.argv[2])]; // node -e: no script path
function frameChunker(frames, size) {
    const all = [];
    for (const part of frames.split(",")) {
        const [a, b] = part.split("-").map(Number);
        for (let f = a; f <= (b === undefined ? a : b); f++) all.push(f);
    }
    const chunks = [];
    for (let i = 0; i < all.length; i += size) {
        const c = all.slice(i, i + size);
        chunks.push(c.length > 1 ? `${c[0]}-${c[c.length - 1]}` : `${c[0]}`);
    }
    return chunks;
}
const author = {
    Task: (name, type) => ({ name, type, commands: [], addCommand(c) { this.commands.push(c); } }),
    Command: (type, parameters) => ({ type, parameters }),
};
const tasks = [];
const job = { settings, addTask: (t) => tasks.push(t) };
const context = { author, frameChunker, job, console };
vm.createContext(context);
vm.runInContext(fs.readFileSync(file, "utf8") + "\nthis.JOB_TYPE = JOB_TYPE; compileJob(job);", context);
for (const s of context.JOB_TYPE.settings) {
    if (!["string", "int32", "float", "bool"].includes(s.type)) throw new Error(`setting ${s.key}: type ${s.type}`);
    if (s.required && !(s.key in settings)) throw new Error(`required setting ${s.key} missing`);
}
console.log(JSON.stringify(tasks));
"#;

/// The Flamenco job type (`farm/flamenco/logsh-render.js`) parsed and compiled by Node
/// with Flamenco's authoring API stubbed ([`FLAMENCO_STUB`]); its tasks' commands, run as
/// a Worker runs `exec` commands, render a three-frame shot in chunks of two to the bytes
/// of a plain `logsh render`. Skipped without `node`, unless `LOGSH_REQUIRE_NODE=1`
/// (which `.ci/run` sets once it has installed Debian's nodejs).
#[test]
fn the_flamenco_job_type_compiles_to_tasks_that_render() {
    let node_runs = std::process::Command::new("node").arg("--version").output().is_ok_and(|o| o.status.success());
    if !node_runs {
        let required = std::env::var("LOGSH_REQUIRE_NODE").is_ok_and(|v| v == "1");
        assert!(!required, "LOGSH_REQUIRE_NODE=1 but there is no node");
        let line = b"tests/render_cli.rs: the Flamenco test skipped: no node (apt-get install nodejs)\n";
        let _ = std::io::Write::write_all(&mut std::io::stderr(), line);
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let shot = three_frame_scene(dir.path(), 32, 18);
    let (plain, farmed) = (dir.path().join("plain"), dir.path().join("farmed"));
    assert!(logsh()
        .arg("render")
        .arg(&shot)
        .args(["--progress", "none", "--out"])
        .arg(&plain)
        .output()
        .unwrap()
        .status
        .success());
    let bin = assert_cmd::cargo::cargo_bin("logsh");
    let settings = serde_json::json!({
        "scene_dir": shot, "frames": "1-3", "chunk_size": 2, "render_output": farmed,
        "quality": "default", "extra_args": "--threads 1", "logsh_exe": bin,
    });
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("farm/flamenco/logsh-render.js");
    let output = std::process::Command::new("node")
        .args(["-e", FLAMENCO_STUB])
        .arg(&script)
        .arg(settings.to_string())
        .output()
        .unwrap();
    assert!(output.status.success(), "node: {}", stderr_of(&output));
    let tasks: Vec<serde_json::Value> = serde_json::from_slice(&output.stdout).unwrap();
    let names: Vec<&str> = tasks.iter().map(|t| t["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["logsh-1-2", "logsh-3"]);
    for task in &tasks {
        for command in task["commands"].as_array().unwrap() {
            assert_eq!(command["type"], "exec");
            let parameters = &command["parameters"];
            let args: Vec<&str> = parameters["args"].as_array().unwrap().iter().map(|a| a.as_str().unwrap()).collect();
            let run = std::process::Command::new(parameters["exe"].as_str().unwrap()).args(&args).output().unwrap();
            assert!(run.status.success(), "{args:?}: {}", stderr_of(&run));
        }
    }
    for f in 1..=3 {
        for ext in ["exr", "png"] {
            let name = format!("render.{f:04}.{ext}");
            let (a, b) = (std::fs::read(plain.join(&name)).unwrap(), std::fs::read(farmed.join(&name)));
            assert!(b.is_ok_and(|b| b == a), "{name}: the Flamenco tasks' frame differs from logsh render's");
        }
    }
}

#[test]
fn one_bad_frame_fails_alone_and_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let scene = three_frame_scene(dir.path(), 32, 18);
    let out = dir.path().join("out");
    // A truncated G-buffer in the middle of the shot.
    let gbuffer = scene.join("gbuffer.0002.exr");
    let bytes = std::fs::read(&gbuffer).unwrap();
    std::fs::write(&gbuffer, &bytes[..bytes.len() / 2]).unwrap();
    // A negative radius in the last frame.
    std::fs::write(
        scene.join("blockers.0003.json"),
        r#"{"frame": 3, "spheres": [{"center": [0, 0, 2], "radius": -1}]}"#,
    )
    .unwrap();
    let output = logsh().arg("render").arg(&scene).args(["--progress", "lines", "--out"]).arg(&out).output().unwrap();
    assert_fails_with(
        &output,
        FAILED,
        &[
            "2 of 3 frame(s) failed",
            "frame 2: ",
            "gbuffer.0002.exr",
            "frame 3: ",
            "blockers.0003.json",
            "negative radius",
        ],
    );
    assert!(out.join("render.0001.exr").is_file(), "the good frame is rendered");
    assert!(!out.join("render.0002.exr").exists() && !out.join("render.0003.exr").exists());
    let leftovers: Vec<_> = std::fs::read_dir(&out).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(leftovers.len(), 2, "no temporary files left: {leftovers:?}");
}

#[test]
fn bad_scenes_end_with_the_file_named() {
    let dir = tempfile::tempdir().unwrap();
    let scene = three_frame_scene(dir.path(), 32, 18);
    let out = dir.path().join("out");
    let render = || logsh().arg("render").arg(&scene).arg("--out").arg(&out).output().unwrap();
    let json = scene.join("scene.json");
    let original = std::fs::read_to_string(&json).unwrap();

    std::fs::write(&json, original.replacen("\"version\": 1", "\"version\": 1,\n  \"colour\": 3", 1)).unwrap();
    assert_fails_with(&render(), FAILED, &["scene.json", "unknown field `colour`"]);

    std::fs::write(&json, "{\n  \"version\": 1,\n  \"gbuffer\": [\n}").unwrap();
    assert_fails_with(&render(), FAILED, &["scene.json:4:1"]);

    std::fs::write(&json, original.replace("gbuffer.####.exr", "../elsewhere/gbuffer.####.exr")).unwrap();
    assert_fails_with(&render(), FAILED, &["scene.json", "\"gbuffer\"", "climbs out of the scene directory"]);

    std::fs::write(&json, original.replace("\"sky.exr\"", "\"/etc/sky.exr\"")).unwrap();
    assert_fails_with(&render(), FAILED, &["scene.json", "\"light.environment\"", "absolute and outside"]);

    std::fs::write(&json, &original).unwrap();
    std::fs::remove_file(scene.join("gbuffer.0001.exr")).unwrap();
    assert_fails_with(&render(), FAILED, &["1 of 3 frame(s) failed", "gbuffer.0001.exr", "file not found"]);

    std::fs::write(scene.join("camera.0002.json"), "{\"frame\": 2,").unwrap();
    assert_fails_with(&render(), FAILED, &["2 of 3 frame(s) failed", "camera.0002.json:1:"]);
    assert!(out.join("render.0003.exr").is_file());
}

#[test]
fn flags_and_outputs_are_checked_before_rendering() {
    let dir = tempfile::tempdir().unwrap();
    let scene = three_frame_scene(dir.path(), 32, 18);
    let out = dir.path().join("out");
    let render = |args: &[&str], out: &Path| {
        logsh().arg("render").arg(&scene).args(args).arg("--out").arg(out).output().unwrap()
    };

    assert_fails_with(
        &render(&["--frames", "1-3x0"], &out),
        REFUSED_WHILE_PARSING,
        &["--frames", "step must be at least 1"],
    );
    assert_fails_with(&render(&["--frames", "1,,3"], &out), REFUSED_WHILE_PARSING, &["--frames", "empty item"]);
    assert_fails_with(
        &render(&["--frames", "2-9"], &out),
        FAILED,
        &["frame(s) 4, 5, 6, 7, 8 and 1 more outside the scene's frames 1-3"],
    );
    assert_fails_with(&render(&["--order", "12"], &out), FAILED, &["--order 12"]);
    assert_fails_with(&render(&["--threads", "0"], &out), FAILED, &["--threads 0"]);
    assert_fails_with(&render(&["--name", "../x"], &out), FAILED, &["--name"]);
    assert!(!out.exists(), "nothing is created when the command is refused");

    // A scene claiming every frame there is needs --frames.
    let json = scene.join("scene.json");
    let original = std::fs::read_to_string(&json).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&original).unwrap();
    v["frames"] = serde_json::json!({"start": i64::MIN, "end": i64::MAX});
    std::fs::write(&json, v.to_string()).unwrap();
    assert_fails_with(&render(&[], &out), FAILED, &["scene.json", "choose some with --frames"]);
    std::fs::write(&json, &original).unwrap();

    // Outputs named like an input are refused before any frame is shaded.
    let before = std::fs::read(scene.join("gbuffer.0002.exr")).unwrap();
    assert_fails_with(
        &render(&["--name", "gbuffer"], &scene),
        FAILED,
        &["gbuffer.0001.exr", "refusing to write over an input"],
    );
    assert_eq!(std::fs::read(scene.join("gbuffer.0002.exr")).unwrap(), before);
    assert_fails_with(&render(&[], &scene.join("scene.json")), FAILED, &["scene.json", "not a directory"]);

    // Frame specs the way farms write them.
    let output = render(&["--frames", "3,1..2x1", "--progress", "json"], &out);
    assert!(output.status.success(), "{}", stderr_of(&output));
    let frames: Vec<i64> = String::from_utf8_lossy(&output.stdout)
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter(|e| e["event"] == "frame")
        .map(|e| e["frame"].as_i64().unwrap())
        .collect();
    assert_eq!(frames, [3, 1, 2]);
}

/// A scene whose export skipped frames (Blender's frame step, or a list of frames) lists
/// the ones it holds, and `logsh render` without `--frames` renders those alone.
#[test]
fn a_scene_with_frames_skipped_renders_the_frames_it_holds() {
    let dir = tempfile::tempdir().unwrap();
    let scene = three_frame_scene(dir.path(), 16, 9);
    for file in ["gbuffer.0002.exr", "camera.0002.json", "blockers.0002.json"] {
        std::fs::remove_file(scene.join(file)).unwrap();
    }
    let json = scene.join("scene.json");
    let mut v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    v["frames"] = serde_json::json!({"start": 1, "end": 3, "list": [1, 3]});
    std::fs::write(&json, v.to_string()).unwrap();
    let out = dir.path().join("out");
    let output = logsh().arg("render").arg(&scene).args(["--progress", "json", "--out"]).arg(&out).output().unwrap();
    assert!(output.status.success(), "{}", stderr_of(&output));
    let frames: Vec<i64> = String::from_utf8_lossy(&output.stdout)
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter(|e| e["event"] == "frame")
        .map(|e| e["frame"].as_i64().unwrap())
        .collect();
    assert_eq!(frames, [1, 3]);
    assert!(out.join("render.0003.exr").is_file() && !out.join("render.0002.exr").exists());
    // A farm's chunk over the range renders what the scene holds; a frame it lacks alone
    // is refused.
    let chunk = dir.path().join("chunk");
    let output = logsh().arg("render").arg(&scene).args(["--frames", "2-3", "--out"]).arg(&chunk).output().unwrap();
    assert!(output.status.success(), "{}", stderr_of(&output));
    assert!(stderr_of(&output).contains("frame(s) 2 not among the scene's frames 1, 3"), "{}", stderr_of(&output));
    assert!(chunk.join("render.0003.exr").is_file() && !chunk.join("render.0002.exr").exists());
    let again =
        logsh().arg("render").arg(&scene).args(["--frames", "2", "--out"]).arg(dir.path().join("again")).output();
    assert_fails_with(&again.unwrap(), FAILED, &["scene.json", "frame(s) 2 not among the scene's frames 1, 3"]);
}

#[test]
fn info_refuses_what_is_not_an_exr() {
    let dir = tempfile::tempdir().unwrap();
    let garbage = dir.path().join("garbage.exr");
    std::fs::write(&garbage, b"v/1\x01\x02\x00\x00 not an exr at all").unwrap();
    assert_fails_with(
        &logsh().arg("info").arg(&garbage).output().unwrap(),
        FAILED,
        &["garbage.exr", "not a readable image"],
    );
    assert_fails_with(
        &logsh().arg("info").arg(dir.path().join("none.exr")).output().unwrap(),
        FAILED,
        &["none.exr", "file not found"],
    );
}

/// An EXR header claiming 100000 x 100000 pixels: refused by size, before the pixels.
#[test]
fn huge_headers_are_refused_before_allocation() {
    let dir = tempfile::tempdir().unwrap();
    let scene = three_frame_scene(dir.path(), 32, 18);
    let file = scene.join("gbuffer.0001.exr");
    let mut bytes = std::fs::read(&file).unwrap();
    let key = b"dataWindow\0box2i\0";
    let mut patched = 0;
    let mut at = 0;
    while let Some(i) = bytes[at..].windows(key.len()).position(|w| w == key) {
        let start = at + i + key.len() + 4; // after the attribute size
        bytes[start + 8..start + 12].copy_from_slice(&99_999i32.to_le_bytes());
        bytes[start + 12..start + 16].copy_from_slice(&99_999i32.to_le_bytes());
        patched += 1;
        at = start;
    }
    assert!(patched > 0);
    std::fs::write(&file, &bytes).unwrap();
    let out = dir.path().join("out");
    let output = logsh().arg("render").arg(&scene).args(["--frames", "1", "--out"]).arg(&out).output().unwrap();
    assert_fails_with(&output, FAILED, &["gbuffer.0001.exr", "100000 x 100000 pixels is too large"]);
    let output = logsh().arg("info").arg(&file).output().unwrap();
    assert!(!stderr_of(&output).contains("panicked"), "{}", stderr_of(&output));
}

#[test]
fn a_bar_that_cannot_be_drawn_falls_back_to_lines() {
    let dir = tempfile::tempdir().unwrap();
    let scene = three_frame_scene(dir.path(), 16, 9);
    let out = dir.path().join("out");
    // Standard error is a pipe here, where no bar can be drawn.
    let output = logsh()
        .arg("render")
        .arg(&scene)
        .args(["--frames", "1-2", "--device", "cpu", "--progress", "bar", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(output.status.success(), "{}", stderr_of(&output));
    for line in ["frame 1 (1/2) rendered", "frame 2 (2/2) rendered"] {
        assert!(stderr_of(&output).contains(line), "no {line:?} in\n{}", stderr_of(&output));
    }
}

/// A frame shaded, resolved and written in bands of rows (`--band-rows`) is byte for
/// byte the frame shaded whole: with bounce light (whose surroundings summarise the
/// whole frame), transfer layers, a visibility grid, a supersampled G-buffer under both
/// pixel filters, and on the GPU where there is one.
#[test]
fn frames_in_bands_are_byte_identical_to_frames_shaded_whole() {
    let dir = tempfile::tempdir().unwrap();
    let plain = three_frame_scene(dir.path(), 96, 80);
    let scene = synth::example("dunes", ExampleOptions { width: 48, height: 40, ..Default::default() }).unwrap();
    let supersampled = dir.path().join("supersampled");
    synth::write_scene_supersampled(&supersampled, &scene, 2).unwrap();
    let mut cases: Vec<(&Path, Vec<&str>)> = vec![
        (&plain, vec![]),
        (&plain, vec!["--transfer"]),
        (&plain, vec!["--visibility-grid", "2", "--bounces", "1"]),
        (&supersampled, vec![]),
        (&supersampled, vec!["--pixel-filter", "blackman-harris", "--every-sample", "--visibility-grid", "2"]),
    ];
    if crate::gpu::gpu().is_some() {
        cases.push((&plain, vec!["--device", "gpu"]));
    }
    for (k, (scene, flags)) in cases.into_iter().enumerate() {
        let render = |band_rows: &str| {
            let out = dir.path().join(format!("case{k}-{band_rows}"));
            let output = logsh()
                .arg("render")
                .arg(scene)
                .args(["--frames", "1", "--progress", "none", "--band-rows", band_rows, "--out"])
                .arg(&out)
                .args(&flags)
                .output()
                .unwrap();
            assert!(output.status.success(), "{flags:?} --band-rows {band_rows}: {}", stderr_of(&output));
            out
        };
        let (whole, bands) = (render("0"), render("16"));
        for name in ["render.0001.exr", "render.0001.png"] {
            let same = std::fs::read(whole.join(name)).unwrap() == std::fs::read(bands.join(name)).unwrap();
            assert!(same, "{name} {flags:?}: in bands of 16 rows it is not the frame shaded whole");
        }
    }
}

/// A bad pixel in a band is named by its place in the frame, and the frame fails
/// without leaving an output.
#[test]
fn a_bad_pixel_in_a_band_is_named_in_the_frame() {
    let dir = tempfile::tempdir().unwrap();
    let scene = three_frame_scene(dir.path(), 64, 48);
    let file = scene.join("gbuffer.0001.exr");
    let names = logsh::scene::ChannelNames::default();
    let materials = logsh::scene::Scene::load(&scene).unwrap().materials;
    let mut g = logsh::scene::GBuffer::read(&file, &names, &materials, false).unwrap();
    let bad = (0..g.material.len()).rev().find(|&i| g.material[i] != 0).expect("a surface pixel");
    g.normal[bad][1] = f32::NAN;
    synth::write_gbuffer_exr(&file, &g, synth::GBufferLayout::Blender5).unwrap();
    let out = dir.path().join("out");
    let output = logsh()
        .arg("render")
        .arg(&scene)
        .args(["--frames", "1", "--progress", "none", "--band-rows", "16", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let pixel = format!("pixel ({}, {})", bad % g.width, bad / g.width);
    assert_fails_with(&output, FAILED, &["gbuffer.0001.exr", &pixel]);
    assert!(!out.join("render.0001.exr").exists() && !out.join("render.0001.png").exists());
}
