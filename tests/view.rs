//! `logsh view` as a black box: the server answers on 127.0.0.1 with the page and a
//! frame's data, and in a real headless browser (Chromium) the page loads and relights the
//! frame as `logsh relight` does.
//!
//! Without a browser the browser test says on stderr that it did not run, and passes,
//! unless `LOGSH_REQUIRE_BROWSER=1` (which `.ci/run` sets once it has installed Debian's
//! `chromium`).

use crate::support;

use assert_cmd::cargo::cargo_bin;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

/// A running `logsh view`, stopped when dropped.
struct Server {
    child: Child,
    address: String,
}

impl Server {
    fn start(dir: &Path) -> Self {
        let mut child = Command::new(cargo_bin("logsh"))
            .args(["view", dir.to_str().unwrap(), "--port", "0", "--no-open"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap()).read_line(&mut line).unwrap();
        let address = line.split_whitespace().find(|w| w.starts_with("http://")).expect(&line).to_string();
        assert!(address.starts_with("http://127.0.0.1:"), "served on the loopback only: {address}");
        Self { child, address }
    }

    /// Status and body of `method path`.
    fn request(&self, method: &str, path: &str) -> (u16, Vec<u8>) {
        Self::request_to(&self.address, method, path)
    }

    /// [`Self::request`] to the server at `address`, from any thread.
    fn request_to(address: &str, method: &str, path: &str) -> (u16, Vec<u8>) {
        let host = address.trim_start_matches("http://").trim_end_matches('/');
        let mut stream = TcpStream::connect(host).unwrap();
        write!(stream, "{method} {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n").unwrap();
        let mut response = Vec::new();
        stream.read_to_end(&mut response).unwrap();
        let split = response.windows(4).position(|w| w == b"\r\n\r\n").expect("a header");
        let head = String::from_utf8_lossy(&response[..split]).into_owned();
        let status = head.split_whitespace().nth(1).unwrap().parse().unwrap();
        (status, response[split + 4..].to_vec())
    }

    /// Stops the server and returns what it printed on stderr.
    fn stop(mut self) -> String {
        let _ = self.child.kill();
        let mut stderr = String::new();
        self.child.stderr.take().unwrap().read_to_string(&mut stderr).unwrap();
        stderr
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn run(args: &[&str]) {
    let output = Command::new(cargo_bin("logsh")).args(args).output().unwrap();
    assert!(output.status.success(), "logsh {args:?}: {}", String::from_utf8_lossy(&output.stderr));
}

/// `gbuffers/cones` (whose directory holds a Cycles render) rendered with its transfer,
/// under a map whose light comes mostly from a warm patch low in the south-east, so that
/// turning it moves the shadows and reflections, and shown through a view transform's LUT;
/// with the scene.json's `lights` set to `lights`; where `sun`, the map holds a sun too,
/// one texel bright at azimuth 120 deg, elevation 40 deg, most of its light.
fn rendered_cones(dir: &Path, lights: serde_json::Value, sun: bool) -> PathBuf {
    let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("gbuffers/cones");
    let scene = dir.join("cones");
    support::copy_scene(&sample, &scene);
    let (width, height) = (128usize, 64usize);
    let mut rgb = [vec![0.0f32; width * height], vec![0.0f32; width * height], vec![0.0f32; width * height]];
    let (azimuth, elevation) = (120f64.to_radians(), 40f64.to_radians());
    let [u, v] = logsh::scene::light::direction_to_equirectangular([
        elevation.cos() * azimuth.cos(),
        elevation.cos() * azimuth.sin(),
        elevation.sin(),
    ]);
    let sun_texel = sun.then_some((((1.0 - v) * height as f64) as usize, (u * width as f64) as usize));
    for row in 0..height {
        for column in 0..width {
            let patch = (40..52).contains(&column) && (20..28).contains(&row);
            let sky = 1.0 - row as f32 / height as f32;
            let texel = if sun_texel == Some((row, column)) {
                [5e4, 4.6e4, 4e4]
            } else if patch {
                [12.0, 7.0, 2.5]
            } else {
                [0.15 * sky, 0.25 * sky, 0.6 * sky]
            };
            for k in 0..3 {
                rgb[k][row * width + column] = texel[k];
            }
        }
    }
    let map = scene.join("patch.exr");
    logsh::scene::output::write_exr_channels(&map, width, height, &[("R", &rgb[0]), ("G", &rgb[1]), ("B", &rgb[2])])
        .unwrap();
    // A view transform given by its LUT, as the exporter writes one: a tone curve
    // `x / (1 + x)` per channel through sRGB, sampled on 9^3 points over 2^-8 to 2^4.
    let (n, range) = (9usize, [-8.0f32, 4.0]);
    let curve = |i: usize| {
        let x = (range[0] + (range[1] - range[0]) * i as f32 / (n - 1) as f32).exp2();
        logsh::scene::output::linear_to_srgb(x / (1.0 + x))
    };
    let mut lut = [vec![0.0f32; n * n * n], vec![0.0f32; n * n * n], vec![0.0f32; n * n * n]];
    for b in 0..n {
        for g in 0..n {
            for r in 0..n {
                let i = b * n * n + g * n + r;
                (lut[0][i], lut[1][i], lut[2][i]) = (curve(r), curve(g), curve(b));
            }
        }
    }
    logsh::scene::output::write_exr_channels(
        &scene.join("view_lut.exr"),
        n * n,
        n,
        &[("R", &lut[0]), ("G", &lut[1]), ("B", &lut[2])],
    )
    .unwrap();
    let file = scene.join("scene.json");
    let mut json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
    json["light"] = serde_json::json!({"environment": "patch.exr"});
    json["view"] = serde_json::json!({"transform": "Filmic", "exposure": 0.5,
        "lut": {"file": "view_lut.exr", "size": n, "log2_range": range}});
    json["lights"] = lights;
    std::fs::write(&file, serde_json::to_string_pretty(&json).unwrap()).unwrap();
    let out = dir.join("frames");
    run(&[
        "render",
        scene.to_str().unwrap(),
        "--frames",
        "1",
        "--out",
        out.to_str().unwrap(),
        "--transfer",
        "--progress",
        "none",
    ]);
    out
}

#[test]
fn the_server_answers_the_page_and_a_frames_data() {
    let dir = tempfile::tempdir().unwrap();
    let frames = rendered_cones(dir.path(), serde_json::json!([]), false);
    let server = Server::start(&frames);
    let (status, page) = server.request("GET", "/");
    assert_eq!(status, 200);
    assert!(String::from_utf8_lossy(&page).contains("<canvas"), "the page");
    let (_, names) = server.request("GET", "/frames.json");
    assert_eq!(serde_json::from_slice::<Vec<String>>(&names).unwrap(), ["render.0001.exr"]);
    let (status, meta) = server.request("GET", "/frame/0/meta.json");
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&meta));
    let meta: serde_json::Value = serde_json::from_slice(&meta).unwrap();
    assert_eq!(
        (meta["width"].as_u64(), meta["height"].as_u64(), meta["order"].as_u64()),
        (Some(240), Some(135), Some(4))
    );
    assert_eq!(meta["cycles"], true, "the scene directory's cycles.0001.exr is found");
    assert_eq!(meta["light"].as_array().unwrap().len(), 3);
    assert_eq!(meta["suns_in_sh"], serde_json::json!([]), "the patch is too wide to be a sun");
    assert_eq!(meta["sun_lamps"], 0, "the cones have no Sun lamp for the page to turn");
    let floats: u64 = meta["pixels"].as_array().unwrap().iter().map(|l| l["components"].as_u64().unwrap()).sum();
    let (_, pixels) = server.request("GET", "/frame/0/pixels.bin");
    assert_eq!(pixels.len() as u64, 4 * floats * 240 * 135, "every layer of the layout");
    let (_, cycles) = server.request("GET", "/frame/0/cycles.bin");
    assert_eq!(cycles.len(), 4 * 3 * 240 * 135);
    assert_eq!(meta["sharp_suns"], serde_json::json!([]), "nor a sun for the server to shade");
    let (status, body) = server.request("GET", "/frame/0/sharp_lights.bin?rotation=75");
    assert_eq!(
        (status, String::from_utf8_lossy(&body).as_ref()),
        (404, "this frame has no Sun lamp and its map no sun")
    );
    let (status, body) = server.request("GET", "/frame/1/meta.json");
    assert_eq!(
        (status, String::from_utf8_lossy(&body).as_ref()),
        (404, "no frame 1: the directory has 1, numbered 0 to 0")
    );
    assert_eq!(server.request("GET", "/../Cargo.toml").0, 404);
    assert_eq!(server.request("POST", "/").0, 405);
    // While the server runs: the frame rendered again at order 3, a Cycles render of
    // another size beside it (the scene's moved away), and the scene's LUT moved away.
    // The page gets the new frame, says why it has no wipe, and shows the frame in the
    // Standard view transform, saying so.
    let scene = dir.path().join("cones");
    let again = dir.path().join("again");
    let render = Command::new(cargo_bin("logsh"))
        .args(["render", scene.to_str().unwrap(), "--out", again.to_str().unwrap(), "--frames", "1"])
        .args(["--order", "3", "--transfer", "--progress", "none", "--device", "cpu"])
        .output()
        .unwrap();
    assert!(render.status.success(), "{}", String::from_utf8_lossy(&render.stderr));
    std::fs::copy(again.join("render.0001.exr"), frames.join("render.0001.exr")).unwrap();
    let zeros = vec![0.0f32; 64];
    logsh::scene::output::write_exr_channels(
        &frames.join("cycles.0001.exr"),
        8,
        8,
        &[("R", &zeros), ("G", &zeros), ("B", &zeros)],
    )
    .unwrap();
    std::fs::rename(scene.join("cycles.0001.exr"), scene.join("cycles.moved")).unwrap();
    std::fs::rename(scene.join("view_lut.exr"), scene.join("view_lut.moved")).unwrap();
    let (status, meta) = server.request("GET", "/frame/0/meta.json");
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&meta));
    let meta: serde_json::Value = serde_json::from_slice(&meta).unwrap();
    assert_eq!((meta["order"].as_u64(), &meta["cycles"]), (Some(3), &serde_json::json!(false)));
    let notes = meta["notes"].to_string();
    assert!(notes.contains("no wipe against Cycles") && notes.contains("is 8x8, the frame 240x135"), "{notes}");
    assert!(notes.contains("Standard view transform") && notes.contains("view_lut.exr"), "{notes}");
    // Frames written while the server runs (a sequence still rendering) are listed after
    // those found at start, which keep their indices, even where a name sorts first; a
    // frame asked for past the list is looked for; one removed stays listed and says so.
    // The Cycles render written beside the frames above holds no transfer: not a frame.
    std::fs::copy(again.join("render.0001.exr"), frames.join("render.0000.exr")).unwrap();
    let (_, names) = server.request("GET", "/frames.json");
    assert_eq!(serde_json::from_slice::<Vec<String>>(&names).unwrap(), ["render.0001.exr", "render.0000.exr"]);
    assert_eq!(server.request("GET", "/frame/1/meta.json").0, 200);
    std::fs::copy(again.join("render.0001.exr"), frames.join("render.0002.exr")).unwrap();
    let (status, meta) = server.request("GET", "/frame/2/meta.json");
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&meta));
    let (status, body) = server.request("GET", "/frame/3/meta.json");
    assert_eq!(
        (status, String::from_utf8_lossy(&body).as_ref()),
        (404, "no frame 3: the directory has 3, numbered 0 to 2")
    );
    std::fs::remove_file(frames.join("render.0001.exr")).unwrap();
    let (status, body) = server.request("GET", "/frame/0/meta.json");
    let body = String::from_utf8_lossy(&body);
    assert_eq!(status, 500, "{body}");
    assert!(body.contains("render.0001.exr"), "the missing frame named: {body}");
    let (_, names) = server.request("GET", "/frames.json");
    assert_eq!(
        serde_json::from_slice::<Vec<String>>(&names).unwrap(),
        ["render.0001.exr", "render.0000.exr", "render.0002.exr"]
    );
    server.stop();
}

#[test]
fn a_directory_without_transfer_layers_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let output = Command::new(cargo_bin("logsh"))
        .args(["view", dir.path().to_str().unwrap(), "--no-open", "--port", "0"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("--transfer") && stderr.contains(dir.path().to_str().unwrap()), "{stderr}");
}

/// A frame's Sun-lamp turn refused for a scene that cannot be read, or that changed since
/// the render, is tried again at the next request, and turns once the scene is put back;
/// turns asked for together, before the frame was ever read, read it once and agree.
#[test]
fn a_refused_sun_lamp_turn_is_tried_again_and_first_turns_agree() {
    let dir = tempfile::tempdir().unwrap();
    let sun = serde_json::json!([{"type": "sun", "direction": [0.5, -0.5, 0.7], "angle": 1.0, "strength": 2.0}]);
    let frames = rendered_cones(dir.path(), sun, false);
    let description = dir.path().join("cones/scene.json");
    let original = std::fs::read_to_string(&description).unwrap();
    let meta = |server: &Server| -> serde_json::Value {
        serde_json::from_slice(&server.request("GET", "/frame/0/meta.json").1).unwrap()
    };

    // Twelve first turns at once: one read of the frame, the same lamps for each.
    let server = Server::start(&frames);
    let turns: Vec<_> = (0..12)
        .map(|_| {
            let (address, path) = (server.address.clone(), "/frame/0/sharp_lights.bin?rotation=75");
            std::thread::spawn(move || Server::request_to(&address, "GET", path))
        })
        .collect();
    let turned: Vec<(u16, Vec<u8>)> = turns.into_iter().map(|t| t.join().unwrap()).collect();
    assert!(turned.iter().all(|(status, lamps)| *status == 200 && *lamps == turned[0].1), "twelve turns at once");
    server.stop();

    // The scene's description gone when the frame is first read: kept, and said why.
    std::fs::rename(&description, dir.path().join("moved.json")).unwrap();
    let server = Server::start(&frames);
    assert!(meta(&server)["sun_lamps_kept"].as_str().unwrap().contains("cannot be read"));
    assert_eq!(server.request("GET", "/frame/0/sharp_lights.bin?rotation=75").0, 409);
    std::fs::rename(dir.path().join("moved.json"), &description).unwrap();
    assert_eq!(meta(&server)["sun_lamps_kept"], serde_json::Value::Null, "the scene put back");
    assert!(server.request("GET", "/frame/0/sharp_lights.bin?rotation=75") == turned[0], "turned as before");
    server.stop();

    // The lamp made stronger before the first turn: refused, then turned once put back.
    std::fs::write(&description, original.replace("\"strength\": 2.0", "\"strength\": 3.0")).unwrap();
    assert_ne!(std::fs::read_to_string(&description).unwrap(), original, "the lamp made stronger");
    let server = Server::start(&frames);
    let (status, why) = server.request("GET", "/frame/0/sharp_lights.bin?rotation=75");
    assert_eq!(status, 500, "{}", String::from_utf8_lossy(&why));
    assert!(String::from_utf8_lossy(&why).contains("its Sun lamps' light"), "{}", String::from_utf8_lossy(&why));
    std::fs::write(&description, &original).unwrap();
    assert!(server.request("GET", "/frame/0/sharp_lights.bin?rotation=75") == turned[0], "turned once put back");
    server.stop();
}

/// Debian's Chromium, or another Chromium-based browser on the PATH.
fn browser() -> Option<PathBuf> {
    ["chromium", "chromium-browser", "google-chrome", "google-chrome-stable"].iter().find_map(|name| {
        let found = Command::new("which").arg(name).output().ok()?;
        found.status.success().then(|| PathBuf::from(String::from_utf8_lossy(&found.stdout).trim()))
    })
}

/// The browser's screenshot of `url`, `width` x `height` pixels, after the page's script
/// and fetches have run.
fn screenshot(browser: &Path, url: &str, width: usize, height: usize, file: &Path) -> image::RgbaImage {
    let output = Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--hide-scrollbars",
            "--force-device-scale-factor=1",
            &format!("--window-size={width},{height}"),
            "--virtual-time-budget=30000",
            &format!("--screenshot={}", file.display()),
            url,
        ])
        .output()
        .unwrap();
    assert!(file.is_file(), "no screenshot: {}", String::from_utf8_lossy(&output.stderr));
    image::open(file).unwrap().to_rgba8()
}

/// Mean absolute difference in 8-bit levels between the screenshot's top-left corner and
/// `preview` over `preview`'s opaque (surface) pixels.
fn difference(shot: &image::RgbaImage, preview: &image::RgbaImage) -> f64 {
    let mut sum = 0.0;
    let mut count = 0;
    for (x, y, p) in preview.enumerate_pixels() {
        if p[3] == 255 {
            let s = shot.get_pixel(x, y);
            sum += (0..3).map(|k| (f64::from(s[k]) - f64::from(p[k])).abs()).sum::<f64>() / 3.0;
            count += 1;
        }
    }
    sum / count as f64
}

/// The browser, or `None` after saying, past the test harness's capture, that the test
/// `test` did not run (a skipped browser test is never silent); with
/// `LOGSH_REQUIRE_BROWSER=1`, a browser or a failure.
fn required_browser(test: &str) -> Option<PathBuf> {
    let found = browser();
    if found.is_none() {
        if std::env::var("LOGSH_REQUIRE_BROWSER").is_ok_and(|v| v == "1") {
            panic!("LOGSH_REQUIRE_BROWSER=1 but no Chromium is installed");
        }
        let _ = std::io::stderr().write_all(
            format!(
                "tests/view.rs: the headless browser test {test} DID NOT RUN: no chromium (apt-get install chromium)\n"
            )
            .as_bytes(),
        );
    }
    found
}

/// The page at `url` (screenshots into `dir`) shows `relit`, the preview of `logsh
/// relight`: within 1.5 levels of it and more than three times as far from `unlike` (a
/// preview it must not show, named); and, held in a drag (`dragging=1`, in full with
/// `proxy=1`), within 1.5 levels of `relit` still.
fn assert_page_shows(
    browser: &Path,
    url: &str,
    dir: &Path,
    relit: &image::RgbaImage,
    (unlike, name): (&image::RgbaImage, &str),
) {
    let shot = screenshot(browser, url, 480, 400, &dir.join("shown.png"));
    let (to_relit, to_unlike) = (difference(&shot, relit), difference(&shot, unlike));
    println!("screenshot of {url}: {to_relit:.2} levels from logsh relight, {to_unlike:.2} from {name}");
    assert!(to_relit < 1.5, "the page differs from logsh relight by {to_relit:.2} levels");
    assert!(to_unlike > 3.0 * to_relit, "the page must differ from {name}: {to_unlike:.2} levels from it");
    let shot = screenshot(browser, &format!("{url}&dragging=1&proxy=1"), 480, 400, &dir.join("dragged.png"));
    let during = difference(&shot, relit);
    assert!(during < 1.5, "during a drag the page differs from logsh relight by {during:.2} levels");
}

/// The page's status line at `url` once its script and fetches have run (the browser's
/// dump of the page's DOM).
fn status_line(browser: &Path, url: &str) -> String {
    let output = Command::new(browser)
        .args(["--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=30000", "--dump-dom", url])
        .output()
        .unwrap();
    let dom = String::from_utf8_lossy(&output.stdout);
    let start = dom.find("id=\"status\"").unwrap_or_else(|| {
        panic!("no status line in the page: {dom} (the browser said: {})", String::from_utf8_lossy(&output.stderr))
    });
    let text = &dom[start..];
    let text = &text[text.find('>').unwrap() + 1..];
    text[..text.find('<').unwrap()].to_string()
}

/// A frame rendered with a Sun lamp: turned in the page, the lamp turns with the map as
/// `logsh relight` turns it (the server shades it again, `sharp_lights.bin`), and the status
/// line says so; unturned, it says nothing of it. Where the scene the frame was rendered
/// from cannot be read, the lamp stays as rendered, and the status line says why.
#[test]
fn the_page_turns_a_sun_lamp_with_the_map() {
    let Some(browser) = required_browser("the_page_turns_a_sun_lamp_with_the_map") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let sun = serde_json::json!([{"type": "sun", "direction": [0.5, -0.5, 0.7], "angle": 1.0, "strength": 2.0}]);
    let frames = rendered_cones(dir.path(), sun, false);
    let frame = frames.join("render.0001.exr");
    for (name, lamps) in [("turn", "turn"), ("keep", "keep")] {
        let out = dir.path().join(name);
        let args = ["relight", frame.to_str().unwrap(), "--light-rotation", "75", "--sun-lamps", lamps, "--out"];
        run(&[&args[..], &[out.to_str().unwrap()]].concat());
    }
    let preview = |name: &str| image::open(dir.path().join(name).join("render.0001.png")).unwrap().to_rgba8();
    let server = Server::start(&frames);
    let (_, meta) = server.request("GET", "/frame/0/meta.json");
    let meta: serde_json::Value = serde_json::from_slice(&meta).unwrap();
    assert_eq!((&meta["sun_lamps"], &meta["sun_lamps_kept"]), (&serde_json::json!(1), &serde_json::Value::Null));
    let (status, lamps) = server.request("GET", "/frame/0/sharp_lights.bin?rotation=75");
    assert_eq!((status, lamps.len()), (200, 4 * 6 * 240 * 135), "both lamps layers, RGB f32");
    // Turned again from the scene frame its first turn read: the same bits, and turned on.
    assert!(server.request("GET", "/frame/0/sharp_lights.bin?rotation=75").1 == lamps, "turned 75 deg again");
    assert!(server.request("GET", "/frame/0/sharp_lights.bin?rotation=40").1 != lamps, "turned 40 deg");
    assert_eq!(server.request("GET", "/frame/0/sharp_lights.bin").0, 400, "no rotation");
    assert_eq!(server.request("GET", "/frame/0/sharp_lights.bin?rotation=inf").0, 400);
    let url = format!("{}?rotation=75", server.address);
    // The lamp turned, and following the rotation while it is held.
    assert_page_shows(&browser, &url, dir.path(), &preview("turn"), (&preview("keep"), "--sun-lamps keep"));
    // The page says the lamp is as rendered until the server's turned lamps arrive; a
    // browser short of CPU may dump the page before they do, so it is read again.
    let mut turned = status_line(&browser, &url);
    for _ in 0..3 {
        if turned.contains("the scene's Sun lamp turned with the map") {
            break;
        }
        turned = status_line(&browser, &url);
    }
    println!("turned: {turned}");
    assert!(turned.contains("the scene's Sun lamp turned with the map"), "{turned}");
    let unturned = status_line(&browser, &server.address);
    assert!(unturned.contains("relit") && !unturned.contains("Sun lamp"), "{unturned}");
    server.stop();

    // The scene's description gone (its map stays): the lamp stays as rendered, and the
    // page says why.
    let scene = dir.path().join("cones");
    std::fs::rename(scene.join("scene.json"), scene.join("scene.json.moved")).unwrap();
    let server = Server::start(&frames);
    let (_, meta) = server.request("GET", "/frame/0/meta.json");
    let meta: serde_json::Value = serde_json::from_slice(&meta).unwrap();
    let why = meta["sun_lamps_kept"].as_str().expect("a reason").to_string();
    assert!(why.contains("cannot be read"), "{why}");
    assert_eq!(server.request("GET", "/frame/0/sharp_lights.bin?rotation=75").0, 409);
    let url = format!("{}?rotation=75", server.address);
    let kept = status_line(&browser, &url);
    println!("kept: {kept}");
    assert!(kept.contains("the scene's Sun lamp stays as rendered here") && kept.contains("cannot be read"), "{kept}");
    let shot = screenshot(&browser, &url, 480, 400, &dir.path().join("kept.png"));
    let to_kept = difference(&shot, &preview("keep"));
    assert!(to_kept < 1.5, "the page differs from logsh relight --sun-lamps keep by {to_kept:.2} levels");
    server.stop();
}

/// A frame whose map holds a sun, rendered with it taken out and shaded sharp (the
/// default): the page shows it sharp as `logsh relight` does, turned with the map by the
/// server (`sharp_lights.bin`) and scaled by the page's strength, and says so. Where the
/// scene the frame was rendered from cannot be read, the page holds the sun in SH, as
/// `logsh relight --sharp-lights off` does, and says why.
#[test]
fn the_page_shades_a_map_sun_sharp() {
    let Some(browser) = required_browser("the_page_shades_a_map_sun_sharp") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let frames = rendered_cones(dir.path(), serde_json::json!([]), true);
    let frame = frames.join("render.0001.exr");
    for (name, sharp) in [("sharp", "auto"), ("soft", "off")] {
        let turned = ["--light-rotation", "75", "--strength", "1.5", "--sharp-lights", sharp];
        let out = dir.path().join(name);
        run(&[&["relight", frame.to_str().unwrap()][..], &turned, &["--out", out.to_str().unwrap()]].concat());
    }
    let preview = |name: &str| image::open(dir.path().join(name).join("render.0001.png")).unwrap().to_rgba8();
    let server = Server::start(&frames);
    let meta = |server: &Server| -> serde_json::Value {
        serde_json::from_slice(&server.request("GET", "/frame/0/meta.json").1).unwrap()
    };
    let shown = meta(&server);
    let suns = shown["sharp_suns"].as_array().expect("the map's suns");
    assert_eq!((suns.len(), &shown["suns_in_sh"]), (1, &serde_json::json!([])), "{shown}");
    let azimuth = suns[0]["azimuth"].as_f64().unwrap();
    assert!((azimuth - 120.0).abs() < 2.0, "the sun at azimuth {azimuth}");
    let layers: Vec<&str> = shown["pixels"].as_array().unwrap().iter().map(|l| l["name"].as_str().unwrap()).collect();
    assert!(layers.contains(&"suns_diffuse") && layers.contains(&"suns_specular"), "{layers:?}");
    let (status, suns) = server.request("GET", "/frame/0/sharp_lights.bin?rotation=75");
    assert_eq!((status, suns.len()), (200, 4 * 6 * 240 * 135), "the suns' two layers, RGB f32");
    assert!(server.request("GET", "/frame/0/sharp_lights.bin?rotation=75").1 == suns, "turned 75 deg again");
    assert!(server.request("GET", "/frame/0/sharp_lights.bin?rotation=40").1 != suns, "turned 40 deg");
    let url = format!("{}?rotation=75&strength=1.5", server.address);
    // The sun shaded sharp, and following the rotation while it is held.
    assert_page_shows(&browser, &url, dir.path(), &preview("sharp"), (&preview("soft"), "the sun held in SH"));
    let status = status_line(&browser, &url);
    println!("sharp: {status}");
    assert!(status.contains("the map's sun shaded sharp by logsh, turned with the map"), "{status}");
    server.stop();

    // The scene's description gone (its map stays): the sun held in SH, and said why.
    let scene = dir.path().join("cones");
    std::fs::rename(scene.join("scene.json"), scene.join("scene.json.moved")).unwrap();
    let server = Server::start(&frames);
    let held = meta(&server);
    assert_eq!(
        (held["sharp_suns"].as_array().map(Vec::len), held["suns_in_sh"].as_array().map(Vec::len)),
        (Some(0), Some(1))
    );
    let why = held["suns_in_sh_why"].as_str().expect("a reason").to_string();
    assert!(why.contains("cannot be read"), "{why}");
    assert_eq!(server.request("GET", "/frame/0/sharp_lights.bin?rotation=75").0, 409);
    let url = format!("{}?rotation=75&strength=1.5", server.address);
    let status = status_line(&browser, &url);
    println!("held: {status}");
    assert!(status.contains("held in SH here, so soft shadows") && status.contains("cannot be read"), "{status}");
    let shot = screenshot(&browser, &url, 480, 400, &dir.path().join("held.png"));
    let to_soft = difference(&shot, &preview("soft"));
    assert!(to_soft < 1.5, "the page differs from logsh relight --sharp-lights off by {to_soft:.2} levels");
    // Put back: shaded sharp again.
    std::fs::rename(scene.join("scene.json.moved"), scene.join("scene.json")).unwrap();
    assert_eq!(meta(&server)["sharp_suns"].as_array().map(Vec::len), Some(1), "the scene put back");
    server.stop();

    // Rendered with the sun held in SH: the page holds it so, as `logsh relight` does.
    let off = dir.path().join("off");
    let render = ["render", scene.to_str().unwrap(), "--frames", "1", "--transfer", "--sharp-lights", "off"];
    run(&[&render[..], &["--progress", "none", "--out", off.to_str().unwrap()]].concat());
    let server = Server::start(&off);
    let held = meta(&server);
    assert_eq!(
        (held["sharp_suns"].as_array().map(Vec::len), held["suns_in_sh"].as_array().map(Vec::len)),
        (Some(0), Some(1))
    );
    assert!(held["suns_in_sh_why"].as_str().is_some_and(|why| why.contains("--sharp-lights off")), "{held}");
    assert_eq!(server.request("GET", "/frame/0/sharp_lights.bin?rotation=75").0, 404, "nothing sharp to turn");
    server.stop();
}

#[test]
fn the_page_relights_in_a_headless_browser() {
    let Some(browser) = required_browser("the_page_relights_in_a_headless_browser") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let frames = rendered_cones(dir.path(), serde_json::json!([]), false);
    let frame = frames.join("render.0001.exr");
    for turn in ["0", "75"] {
        run(&[
            "relight",
            frame.to_str().unwrap(),
            "--light-rotation",
            turn,
            "--out",
            dir.path().join(turn).to_str().unwrap(),
        ]);
    }
    let preview = |turn: &str| image::open(dir.path().join(turn).join("render.0001.png")).unwrap().to_rgba8();
    let server = Server::start(&frames);
    let url = |query: &str| format!("{}?{query}", server.address);
    let shot = screenshot(&browser, &url("rotation=75"), 480, 400, &dir.path().join("shot.png"));
    let (to_turned, to_unturned) = (difference(&shot, &preview("75")), difference(&shot, &preview("0")));
    println!("screenshot at 75 degrees: {to_turned:.2} levels from logsh relight at 75, {to_unturned:.2} from 0");
    assert!(to_turned < 1.5, "the page's relight differs from logsh relight by {to_turned:.2} levels");
    assert!(to_unturned > 3.0 * to_turned, "the page must turn the light: {to_unturned:.2} from the unturned frame");
    // A turn past the slider's range is the same turn.
    let around = screenshot(&browser, &url("rotation=435"), 480, 400, &dir.path().join("around.png"));
    assert_eq!(difference(&around, &preview("75")), to_turned, "435 degrees are 75");
    // The wipe shows Cycles' render on the right.
    let wiped = screenshot(&browser, &url("rotation=75&wipe=0"), 480, 400, &dir.path().join("wiped.png"));
    assert!(difference(&wiped, &preview("75")) > to_turned + 1.0, "the wipe must show the Cycles render");
    // Interactive rates, timed by the server's clock (reported, not asserted): turns in
    // full, turns while dragged (at half resolution here), strength changes.
    let benched = screenshot(&browser, &url("bench=5&proxy=2"), 480, 400, &dir.path().join("bench.png"));
    // The drags over, the frame is lit in full at the last turn and strength (109 deg, 1.3).
    let settled = screenshot(&browser, &url("rotation=109&strength=1.3"), 480, 400, &dir.path().join("settled.png"));
    let frame_size = preview("0");
    let settled = image::imageops::crop_imm(&settled, 0, 0, frame_size.width(), frame_size.height()).to_image();
    assert_eq!(difference(&benched, &settled), 0.0, "after a drag the page lights the frame in full");
    let log = server.stop();
    let timings: Vec<&str> = log.lines().filter(|l| l.contains("in the browser took")).collect();
    assert_eq!(timings.len(), 3, "three timings reported: {log}");
    for timing in timings {
        println!("{timing}");
        let _ = std::io::stderr().write_all(format!("tests/view.rs: {timing}\n").as_bytes());
    }
}

/// The server's bounds (src/view/server.rs): a request naming another host, or sent from
/// another origin, gets 403 (DNS rebinding); 500 idle connections and a 10 MB header line
/// leave the page served within a second; a port already taken is said so.
#[test]
fn the_server_answers_its_own_host_only_and_within_bounds() {
    let dir = tempfile::tempdir().unwrap();
    let frames = rendered_cones(dir.path(), serde_json::json!([]), false);
    let server = Server::start(&frames);
    let host = server.address.trim_start_matches("http://").trim_end_matches('/').to_string();
    let port = host.rsplit(':').next().unwrap().to_string();
    let status_of = |head: &str| {
        let mut stream = TcpStream::connect(&host).unwrap();
        write!(stream, "GET / HTTP/1.1\r\n{head}Connection: close\r\n\r\n").unwrap();
        let mut response = Vec::new();
        stream.read_to_end(&mut response).unwrap();
        String::from_utf8_lossy(&response).split_whitespace().nth(1).unwrap_or("none").to_string()
    };
    assert_eq!(status_of("Host: evil.example.com\r\n"), "403");
    assert_eq!(status_of(&format!("Host: evil.example.com:{port}\r\n")), "403");
    assert_eq!(status_of(""), "403", "no Host");
    assert_eq!(status_of(&format!("Host: {host}\r\nOrigin: http://evil.example.com\r\n")), "403");
    assert_eq!(status_of(&format!("Host: localhost:{port}\r\nOrigin: http://{host}\r\n")), "200");
    assert_eq!(status_of(&format!("Host: {host}\r\nX-Many: {}\r\n", "a".repeat(20_000))), "431");

    let idle: Vec<TcpStream> = (0..500).map(|_| TcpStream::connect(&host).unwrap()).collect();
    let flood = {
        let host = host.clone();
        std::thread::spawn(move || {
            let mut stream = TcpStream::connect(&host).unwrap();
            let _ = stream.write_all(b"GET / HTTP/1.1\r\nX-Flood: ");
            let line = vec![b'a'; 1 << 20];
            for _ in 0..10 {
                if stream.write_all(&line).is_err() {
                    break; // the server answered 431 and closed
                }
            }
        })
    };
    std::thread::sleep(std::time::Duration::from_millis(200));
    let started = std::time::Instant::now();
    let (status, page) = server.request("GET", "/");
    let took = started.elapsed();
    println!("the page beside 500 idle connections and a 10 MB header line: {took:?}");
    assert_eq!(status, 200);
    assert!(String::from_utf8_lossy(&page).contains("<canvas"));
    assert!(took.as_secs_f64() < 1.0, "the page took {took:?} beside 500 idle connections and a 10 MB header");
    flood.join().unwrap();
    drop(idle);

    let taken = Command::new(cargo_bin("logsh"))
        .args(["view", frames.to_str().unwrap(), "--port", &port, "--no-open"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&taken.stderr);
    assert!(!taken.status.success() && stderr.contains(&format!("port {port} is taken")), "{stderr}");
    let printed = server.stop();
    assert!(!printed.contains("panicked"), "{printed}");
}
