//! `logsh view` as a black box: the server answers on 127.0.0.1 with the page and a
//! frame's data, and in a real headless browser (Chromium) the page loads and relights the
//! frame as `logsh relight` does, fits it to the window and zooms it, inspects a pixel's
//! values as its file holds them, compares it with the frame as rendered and with Cycles,
//! hides the controls with nothing to act on, and takes the keyboard. The screenshots
//! find the frame by the colour of the window around it.
//!
//! Without a browser each browser test says on stderr that it did not run, and passes,
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

    /// The first frame's meta.json.
    fn meta(&self) -> serde_json::Value {
        let (status, body) = self.request("GET", "/frame/0/meta.json");
        assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
        serde_json::from_slice(&body).unwrap()
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
    let meta = server.meta();
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
    // The passes as rendered, and one pixel as the file holds it.
    let passes = serde_json::json!(["beauty", "diffuse", "specular", "environment", "indirect", "visibility"]);
    assert_eq!(meta["rendered"], passes);
    assert_eq!(server.request("GET", "/frame/0/rendered.bin?pass=beauty").1.len(), 4 * 3 * 240 * 135);
    assert_eq!(server.request("GET", "/frame/0/rendered.bin?pass=visibility").1.len(), 4 * 240 * 135);
    let (status, body) = server.request("GET", "/frame/0/rendered.bin?pass=sh_diffuse");
    assert_eq!(status, 404);
    assert!(
        String::from_utf8_lossy(&body).contains("the passes are beauty, diffuse"),
        "{}",
        String::from_utf8_lossy(&body)
    );
    let (status, pixel) = server.request("GET", "/frame/0/pixel.json?x=120&y=80");
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&pixel));
    let pixel: serde_json::Value = serde_json::from_slice(&pixel).unwrap();
    let names: Vec<&str> = pixel["channels"].as_array().unwrap().iter().map(|c| c[0].as_str().unwrap()).collect();
    assert!(names.contains(&"R") && names.contains(&"visibility.Y") && names.contains(&"P.X"), "{names:?}");
    assert!(!names.iter().any(|n| n.starts_with("sh_")), "no transfer layer: {names:?}");
    assert_eq!(pixel["material"]["samples"][0]["type"], "diffuse", "{pixel}");
    assert_eq!(server.request("GET", "/frame/0/pixel.json?x=120").0, 400, "no y");
    let (status, body) = server.request("GET", "/frame/0/pixel.json?x=240&y=0");
    assert_eq!((status, String::from_utf8_lossy(&body).as_ref()), (404, "no pixel (240, 0): the frame is 240x135"));
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
    let meta = server.meta();
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
    assert!(server.meta()["sun_lamps_kept"].as_str().unwrap().contains("cannot be read"));
    assert_eq!(server.request("GET", "/frame/0/sharp_lights.bin?rotation=75").0, 409);
    std::fs::rename(dir.path().join("moved.json"), &description).unwrap();
    assert_eq!(server.meta()["sun_lamps_kept"], serde_json::Value::Null, "the scene put back");
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

/// The browser's screenshot of `url`, a window of `width` x `height` CSS pixels at one
/// device pixel each, after the page's script and fetches have run.
fn screenshot(browser: &Path, url: &str, width: usize, height: usize, file: &Path) -> image::RgbaImage {
    screenshot_and_page(browser, url, [width, height], 1, file).0
}

/// [`screenshot`] on a screen of `density` device pixels per CSS pixel, with the browser's
/// dump of the page's DOM, taken before the screenshot (whose window the browser sizes
/// again just before it: the page draws the frame again for it).
fn screenshot_and_page(
    browser: &Path,
    url: &str,
    [width, height]: [usize; 2],
    density: u32,
    file: &Path,
) -> (image::RgbaImage, String) {
    let output = settled_page(
        browser,
        &[
            "--hide-scrollbars",
            &format!("--force-device-scale-factor={density}"),
            &format!("--window-size={width},{height}"),
            &format!("--screenshot={}", file.display()),
            url,
        ],
    );
    assert!(file.is_file(), "no screenshot: {}", String::from_utf8_lossy(&output.stderr));
    (image::open(file).unwrap().to_rgba8(), String::from_utf8_lossy(&output.stdout).into_owned())
}

/// The headless browser run with `args` (the page's URL last), its DOM dumped once its
/// script and fetches have run. The browser's virtual time does not always wait for the
/// server to shade the sharp lights again: while the page says a turn is on its way
/// (`data-turning` on its status line), the page is loaded again, up to four times; the
/// server keeps the frame it prepared, so later turns come sooner.
fn settled_page(browser: &Path, args: &[&str]) -> std::process::Output {
    let mut tries = 0;
    loop {
        let output = Command::new(browser)
            .args(["--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=30000", "--dump-dom"])
            .args(args)
            .output()
            .unwrap();
        tries += 1;
        if tries == 4 || !String::from_utf8_lossy(&output.stdout).contains("data-turning=") {
            return output;
        }
        eprintln!("the page's sharp lights were still on their way; loading it again");
    }
}

/// The colour of the window around the frame (`#viewport` in src/view/page/head.html).
const AROUND_THE_FRAME: [u8; 3] = [0x11, 0x11, 0x13];

/// Where a screenshot of the page shows the frame, `[left, top, width, height]`: the rows
/// from the first that holds a pixel not of the colour around the frame to the next that
/// holds none, and the columns of such pixels in them. The frame must leave a row of that
/// colour below it, above the panel of controls.
fn frame_in(shot: &image::RgbaImage) -> [u32; 4] {
    let around = |x: u32, y: u32| shot.get_pixel(x, y).0[..3] == AROUND_THE_FRAME;
    let holds_frame = |y: u32| (0..shot.width()).any(|x| !around(x, y));
    let top = (0..shot.height()).find(|&y| holds_frame(y)).expect("a frame in the screenshot");
    let bottom = (top..shot.height()).find(|&y| !holds_frame(y)).expect("the window's colour below the frame");
    let columns: Vec<u32> = (0..shot.width()).filter(|&x| (top..bottom).any(|y| !around(x, y))).collect();
    let (left, right) = (columns[0], columns[columns.len() - 1] + 1);
    [left, top, right - left, bottom - top]
}

/// The window in which [`frame_shot`] shows a frame at one frame pixel per screen pixel.
const WINDOW: [usize; 2] = [960, 640];

/// The frame the page at `url` shows, cut from a screenshot of it in [`WINDOW`] at one
/// frame pixel per screen pixel (`zoom=1`, added to the address).
fn frame_shot(browser: &Path, url: &str, file: &Path) -> image::RgbaImage {
    frame_shot_and_page(browser, url, file).0
}

/// [`frame_shot`], with the dump of the page's DOM.
fn frame_shot_and_page(browser: &Path, url: &str, file: &Path) -> (image::RgbaImage, String) {
    let url = format!("{url}{}zoom=1", if url.contains('?') { "&" } else { "?" });
    let (shot, dom) = screenshot_and_page(browser, &url, WINDOW, 1, file);
    let [left, top, width, height] = frame_in(&shot);
    (image::imageops::crop_imm(&shot, left, top, width, height).to_image(), dom)
}

/// Mean absolute difference in 8-bit levels between the frame shown (`shot`, of the same
/// size) and `preview` over `preview`'s opaque (surface) pixels.
fn difference(shot: &image::RgbaImage, preview: &image::RgbaImage) -> f64 {
    assert_eq!(shot.dimensions(), preview.dimensions(), "the frame shown has the preview's size");
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
    let shot = frame_shot(browser, url, &dir.join("shown.png"));
    let (to_relit, to_unlike) = (difference(&shot, relit), difference(&shot, unlike));
    println!("screenshot of {url}: {to_relit:.2} levels from logsh relight, {to_unlike:.2} from {name}");
    assert!(to_relit < 1.5, "the page differs from logsh relight by {to_relit:.2} levels");
    assert!(to_unlike > 3.0 * to_relit, "the page must differ from {name}: {to_unlike:.2} levels from it");
    let shot = frame_shot(browser, &format!("{url}&dragging=1&proxy=1"), &dir.join("dragged.png"));
    let during = difference(&shot, relit);
    assert!(during < 1.5, "during a drag the page differs from logsh relight by {during:.2} levels");
}

/// The page's status line at `url` once its script and fetches have run (the browser's
/// dump of the page's DOM).
fn status_line(browser: &Path, url: &str) -> String {
    let output = settled_page(browser, &[url]);
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
    let meta = server.meta();
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
    let meta = server.meta();
    let why = meta["sun_lamps_kept"].as_str().expect("a reason").to_string();
    assert!(why.contains("cannot be read"), "{why}");
    assert_eq!(server.request("GET", "/frame/0/sharp_lights.bin?rotation=75").0, 409);
    let url = format!("{}?rotation=75", server.address);
    let kept = status_line(&browser, &url);
    println!("kept: {kept}");
    assert!(kept.contains("the scene's Sun lamp stays as rendered here") && kept.contains("cannot be read"), "{kept}");
    let shot = frame_shot(&browser, &url, &dir.path().join("kept.png"));
    let to_kept = difference(&shot, &preview("keep"));
    assert!(to_kept < 1.5, "the page differs from logsh relight --sun-lamps keep by {to_kept:.2} levels");
    server.stop();
}

/// The map marks the scene's point lamps where they lie as seen from the middle of the
/// frame's surface, and its caption counts them: lamps 100 km away along +x, -y and +z lie
/// at azimuth 0, -90 and elevation 90 (within 0.01 degree of the closed form, whatever the
/// middle, which the cones' frame holds within a few metres of the origin).
/// Where the scene cannot be read, none is marked and the page says why.
#[test]
fn the_map_marks_point_lamps_where_they_lie() {
    let dir = tempfile::tempdir().unwrap();
    let lamp =
        |position: [f64; 3]| serde_json::json!({"type": "point", "position": position, "radius": 0.1, "power": 10.0});
    let lamps = serde_json::json!([lamp([1e5, 0.0, 0.0]), lamp([0.0, -1e5, 0.0]), lamp([0.0, 0.0, 1e5])]);
    let frames = rendered_cones(dir.path(), lamps, false);
    let server = Server::start(&frames);
    let meta = server.meta();
    let directions: Vec<[f64; 2]> = serde_json::from_value(meta["point_lamp_directions"].clone()).unwrap();
    assert_eq!(directions.len(), 3, "{directions:?}");
    let near = |found: f64, expected: f64| (found - expected).abs() < 0.01;
    let [along_x, along_y, above] = [directions[0], directions[1], directions[2]];
    assert!(near(along_x[0], 0.0) && near(along_x[1], 0.0), "{along_x:?}");
    assert!(near(along_y[0], -90.0) && near(along_y[1], 0.0), "{along_y:?}");
    assert!(near(above[1], 90.0), "{above:?}");
    if let Some(browser) = required_browser("the_map_marks_point_lamps_where_they_lie") {
        let dom = page(&browser, &format!("{}?rotation=60", server.address));
        assert!(dom.contains("3 point lamps, fixed, seen from the frame's middle (square)"), "{dom}");
    }
    server.stop();

    let scene = dir.path().join("cones");
    std::fs::rename(scene.join("scene.json"), scene.join("scene.json.moved")).unwrap();
    let server = Server::start(&frames);
    let meta = server.meta();
    assert_eq!(meta["point_lamp_directions"], serde_json::json!([]));
    let notes = meta["notes"].to_string();
    assert!(notes.contains("point lamps are not marked on the map") && notes.contains("scene.json"), "{notes}");
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
    let shown = server.meta();
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
    let held = server.meta();
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
    let shot = frame_shot(&browser, &url, &dir.path().join("held.png"));
    let to_soft = difference(&shot, &preview("soft"));
    assert!(to_soft < 1.5, "the page differs from logsh relight --sharp-lights off by {to_soft:.2} levels");
    // Put back: shaded sharp again.
    std::fs::rename(scene.join("scene.json.moved"), scene.join("scene.json")).unwrap();
    assert_eq!(server.meta()["sharp_suns"].as_array().map(Vec::len), Some(1), "the scene put back");
    server.stop();

    // Rendered with the sun held in SH: the page holds it so, as `logsh relight` does.
    let off = dir.path().join("off");
    let render = ["render", scene.to_str().unwrap(), "--frames", "1", "--transfer", "--sharp-lights", "off"];
    run(&[&render[..], &["--progress", "none", "--out", off.to_str().unwrap()]].concat());
    let server = Server::start(&off);
    let held = server.meta();
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
    let shot = frame_shot(&browser, &url("rotation=75"), &dir.path().join("shot.png"));
    let (to_turned, to_unturned) = (difference(&shot, &preview("75")), difference(&shot, &preview("0")));
    println!("screenshot at 75 degrees: {to_turned:.2} levels from logsh relight at 75, {to_unturned:.2} from 0");
    assert!(to_turned < 1.5, "the page's relight differs from logsh relight by {to_turned:.2} levels");
    assert!(to_unturned > 3.0 * to_turned, "the page must turn the light: {to_unturned:.2} from the unturned frame");
    // A turn past the slider's range is the same turn.
    let around = frame_shot(&browser, &url("rotation=435"), &dir.path().join("around.png"));
    assert_eq!(difference(&around, &preview("75")), to_turned, "435 degrees are 75");
    // The wipe shows Cycles' render on the right.
    let wiped = frame_shot(&browser, &url("rotation=75&wipe=0"), &dir.path().join("wiped.png"));
    assert!(difference(&wiped, &preview("75")) > to_turned + 1.0, "the wipe must show the Cycles render");
    // Interactive rates, timed by the server's clock (reported, not asserted): turns in
    // full, turns while dragged (at half resolution here), strength changes.
    // A browser short of CPU may dump the page before its benchmark ends: it is run again.
    let bench = || frame_shot_and_page(&browser, &url("bench=5&proxy=2"), &dir.path().join("bench.png"));
    let (mut benched, mut dom) = bench();
    let mut runs = 1;
    while !dom.contains("<title>logsh view: benchmarked</title>") && runs < 3 {
        (benched, dom) = bench();
        runs += 1;
    }
    // The drags over, the frame is lit in full at the last turn and strength (109 deg, 1.3).
    let settled = frame_shot(&browser, &url("rotation=109&strength=1.3"), &dir.path().join("settled.png"));
    assert_eq!(difference(&benched, &settled), 0.0, "after a drag the page lights the frame in full");
    let log = server.stop();
    let timings: Vec<&str> = log.lines().filter(|l| l.contains("in the browser took")).collect();
    assert_eq!(timings.len(), 3 * runs, "three timings reported by each of {runs} runs: {log}");
    for timing in timings {
        println!("{timing}");
        let _ = std::io::stderr().write_all(format!("tests/view.rs: {timing}\n").as_bytes());
    }
}

/// The opening tag of the page's element `id` in a dump of its DOM.
fn tag_of<'a>(dom: &'a str, id: &str) -> &'a str {
    let at = dom.find(&format!("id=\"{id}\"")).unwrap_or_else(|| panic!("no element {id} in the page: {dom}"));
    let start = dom[..at].rfind('<').unwrap();
    &dom[start..at + dom[at..].find('>').unwrap() + 1]
}

/// Whether the page's element `id` is hidden.
fn is_hidden(dom: &str, id: &str) -> bool {
    tag_of(dom, id).contains(" hidden")
}

/// The text of the page's element `id`, up to its first child element.
fn text_of(dom: &str, id: &str) -> String {
    let tag = tag_of(dom, id);
    let rest = &dom[dom.find(tag).unwrap() + tag.len()..];
    rest[..rest.find('<').unwrap()].replace("&amp;", "&").replace("&lt;", "<").replace("&gt;", ">")
}

/// The value of `attribute` in the page's element `id`.
fn attribute_of(dom: &str, id: &str, attribute: &str) -> Option<String> {
    let tag = tag_of(dom, id);
    let at = tag.find(&format!(" {attribute}=\""))? + attribute.len() + 3;
    Some(tag[at..at + tag[at..].find('"').unwrap()].replace("&amp;", "&"))
}

/// The page's DOM at `url` once its script and fetches have run ([`settled_page`]).
fn page(browser: &Path, url: &str) -> String {
    String::from_utf8_lossy(&settled_page(browser, &[url]).stdout).into_owned()
}

/// In a 1280x900 window the page fits the frame to the window: it covers at least 60 % of
/// it (the panel of controls lies below the frame), on a screen of one device pixel per
/// CSS pixel and of two. Magnified, each frame pixel is a block of its colour (nearest
/// neighbour): sampled anywhere in its block, the screen shows the frame pixel as the page
/// shows it at one frame pixel per screen pixel. A zoom (`zoom=Z`, and the keys + - 1 0)
/// shows Z screen pixels per frame pixel, `center=X,Y` at the middle of the window.
/// The cones are 240x135, of the shape of 960x540: fitted, both cover the same share.
#[test]
fn the_frame_fits_the_window_and_zooms() {
    let Some(browser) = required_browser("the_frame_fits_the_window_and_zooms") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let frames = rendered_cones(dir.path(), serde_json::json!([]), false);
    let server = Server::start(&frames);
    let one = frame_shot(&browser, &server.address, &dir.path().join("one.png"));
    assert_eq!(one.dimensions(), (240, 135), "at one frame pixel per screen pixel");
    // Each frame pixel at `scale` screen pixels per frame pixel from (left, top), sampled at
    // a fifth and at four fifths of its block: one colour over the block.
    let shows_blocks = |shot: &image::RgbaImage, [left, top]: [u32; 2], scale: f64| -> usize {
        let mut wrong = 0;
        for (i, j, p) in one.enumerate_pixels() {
            for at in [0.2, 0.8] {
                let (x, y) = (left + ((i as f64 + at) * scale) as u32, top + ((j as f64 + at) * scale) as u32);
                if (x, y) < shot.dimensions() && shot.get_pixel(x, y).0[..3] != p.0[..3] {
                    wrong += 1;
                }
            }
        }
        wrong
    };
    for density in [1, 2] {
        let file = dir.path().join(format!("fit{density}.png"));
        let (shot, dom) = screenshot_and_page(&browser, &server.address, [1280, 900], density, &file);
        let [left, top, width, height] = frame_in(&shot);
        let covered = f64::from(width * height) / f64::from(shot.width() * shot.height());
        println!("fitted at {density} device pixels per CSS pixel: {width}x{height} at ({left}, {top}), {:.1} % of the window", 100.0 * covered);
        assert!(covered >= 0.6, "the frame covers {:.1} % of the window", 100.0 * covered);
        assert_eq!(shot.width(), 1280 * density, "the screenshot in device pixels");
        let scale = f64::from(width) / 240.0;
        assert!((f64::from(height) / 135.0 - scale).abs() < 0.01, "{width}x{height}: the frame's shape kept");
        let wrong = shows_blocks(&shot, [left, top], scale);
        assert_eq!(wrong, 0, "{wrong} samples of the fitted frame are not their frame pixel's colour");
        assert!(text_of(&dom, "zoom-value").contains("(fit)"), "{}", text_of(&dom, "zoom-value"));
    }
    // A zoom given, by the address and by the keys: Z screen pixels per frame pixel.
    for (query, zoom) in [("zoom=2", 2), ("zoom=4&center=100,67", 4), ("zoom=1&keys=%2B,%2B", 4), ("zoom=4&keys=-", 2)]
    {
        let url = format!("{}?{query}", server.address);
        let shot = screenshot(&browser, &url, 1280, 900, &dir.path().join("zoom.png"));
        let [left, top, width, height] = frame_in(&shot);
        println!("{query}: {width}x{height} at ({left}, {top})");
        assert_eq!((width, height), (240 * zoom, 135 * zoom), "{query}");
        assert_eq!(shows_blocks(&shot, [left, top], f64::from(zoom)), 0, "{query}: each frame pixel a block");
        if query.contains("center") {
            assert_eq!(left, 640 - 100 * 4, "{query}: frame pixel 100 at the middle of the window");
        }
    }
    // One frame pixel per screen pixel (1), fitted again (0).
    let shot = screenshot(&browser, &format!("{}?zoom=3&keys=1", server.address), 1280, 900, &dir.path().join("k.png"));
    assert_eq!(frame_in(&shot)[2..], [240, 135], "the key 1");
    let shot = screenshot(&browser, &format!("{}?zoom=3&keys=0", server.address), 1280, 900, &dir.path().join("k.png"));
    assert_eq!(frame_in(&shot)[2], 1280, "the key 0 fits the frame again");
    server.stop();
}

/// The channels of `file` at pixel (`x`, `y`) by full name, read by the `exr` crate.
fn exr_pixel(file: &Path, x: usize, y: usize) -> Vec<(String, f32)> {
    let width = exr::meta::MetaData::read_from_file(file, false).unwrap().headers[0].layer_size.width();
    let mut channels: Vec<(String, f32)> =
        support::exr_channels(file).into_iter().map(|(name, values)| (name, values[y * width + x])).collect();
    channels.sort_by(|a, b| a.0.cmp(&b.0));
    channels
}

/// The material index of the G-buffer `file` (Blender's pass, a part of its own) at pixel
/// (`x`, `y`), read by the `exr` crate.
fn gbuffer_material(file: &Path, x: usize, y: usize) -> u32 {
    use exr::prelude::{read_all_flat_layers_from_file, FlatSamples};
    let image = read_all_flat_layers_from_file(file).unwrap();
    for layer in &image.layer_data {
        let part = layer.attributes.layer_name.as_ref().map(|n| n.to_string()).unwrap_or_default();
        for channel in &layer.channel_data.list {
            let name = channel.name.to_string();
            if name.ends_with("Material Index.X") || (part.ends_with("Material Index") && name == "X") {
                let width = layer.size.width();
                let value = match &channel.sample_data {
                    FlatSamples::F32(v) => v[y * width + x],
                    FlatSamples::F16(v) => v[y * width + x].to_f32(),
                    FlatSamples::U32(v) => v[y * width + x] as f32,
                };
                return value.round() as u32;
            }
        }
    }
    panic!("{}: no material index", file.display());
}

/// The value the inspector shows under `key` (`file:diffuse.R`, `relit:beauty.G`).
fn inspected(dom: &str, key: &str) -> Option<f64> {
    let at = dom.find(&format!("data-key=\"{key}\">"))? + key.len() + 12;
    dom[at..at + dom[at..].find('<').unwrap()].parse().ok()
}

/// A value shown to 5 significant digits is within half a unit of its fifth digit: 5e-5 of
/// it.
const FIVE_DIGITS: f64 = 5e-5;

/// The pixel inspector (`inspect=X,Y`) shows the pixel as the frame's file holds it: every
/// channel but the transfer layers (the beauty, the passes, the visibility terms, the
/// colours, the lamps, P and N), each the EXR's value (read here by the `exr` crate) to 5
/// significant digits, and the material index of its G-buffer sample; and the pixel relit
/// at the page's light, as `logsh relight` relights it. A surface of each material and
/// the background, the frame's corners.
#[test]
fn the_inspector_shows_the_files_values() {
    let Some(browser) = required_browser("the_inspector_shows_the_files_values") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let frames = rendered_cones(dir.path(), serde_json::json!([]), false);
    let frame = frames.join("render.0001.exr");
    let turned = dir.path().join("turned");
    run(&["relight", frame.to_str().unwrap(), "--light-rotation", "75", "--out", turned.to_str().unwrap()]);
    let gbuffer = dir.path().join("cones/gbuffer.0001.exr");
    let scene: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("cones/scene.json")).unwrap()).unwrap();
    let materials_json = &scene["materials"];
    let server = Server::start(&frames);
    let mut materials = std::collections::BTreeSet::new();
    // The largest difference of a value shown from the file's, relative to the value.
    let mut worst = 0.0f64;
    for (x, y) in [(120, 80), (30, 100), (160, 60), (100, 45), (0, 0), (239, 134), (200, 10), (50, 120)] {
        let dom = page(&browser, &format!("{}?inspect={x},{y}&rotation=75", server.address));
        assert_eq!(
            (attribute_of(&dom, "inspected", "data-x"), attribute_of(&dom, "inspected", "data-y")),
            (Some(x.to_string()), Some(y.to_string()))
        );
        let channels = exr_pixel(&frame, x, y);
        let mut shown = 0;
        for (name, value) in &channels {
            if ["sh_", "glossy_", "sun_lamps_", "horizon"].iter().any(|p| name.starts_with(p)) {
                assert_eq!(inspected(&dom, &format!("file:{name}")), None, "{name} is a transfer layer");
                continue;
            }
            let seen = inspected(&dom, &format!("file:{name}")).unwrap_or_else(|| panic!("({x}, {y}): no {name}"));
            let value = f64::from(*value);
            if value != 0.0 {
                worst = worst.max((seen - value).abs() / value.abs());
            }
            assert!(
                (seen - value).abs() <= FIVE_DIGITS * value.abs(),
                "({x}, {y}) {name}: the inspector shows {seen}, the file holds {value}"
            );
            shown += 1;
        }
        assert!(shown >= 40, "({x}, {y}): {shown} channels shown");
        let material = gbuffer_material(&gbuffer, x, y);
        materials.insert(material);
        let said = text_of(&dom, "inspected-material");
        assert!(
            said.starts_with(&format!("{material} (")),
            "({x}, {y}): material {material}, the inspector says {said}"
        );
        // Relit at 75 degrees: as logsh relight, whose file holds halves (a relative
        // precision of 2^-11), shown to 5 digits; a Phong surface's reflection to 0.2 %,
        // the page reading its open lobe's light from a 64 x 32 grid (1.25e-3 at its
        // worst here).
        let phong = materials_json[material.to_string().as_str()]["type"] == "phong";
        let page_grids = if phong { 2e-3 } else { 0.0 };
        let relit = exr_pixel(&turned.join("render.0001.exr"), x, y);
        for channel in ["R", "G", "B"] {
            let expected = f64::from(relit.iter().find(|(name, _)| name == channel).unwrap().1);
            let seen = inspected(&dom, &format!("relit:beauty.{channel}")).unwrap();
            let tolerance = (2f64.powi(-11) + page_grids) * expected.abs() + FIVE_DIGITS * seen.abs();
            assert!(
                (seen - expected).abs() <= tolerance,
                "({x}, {y}) beauty.{channel} relit at 75 degrees: the inspector shows {seen}, logsh relight {expected}"
            );
        }
    }
    println!("the inspector's values differ from the file's by {worst:.2e} of them at most");
    assert!(materials.len() >= 3, "background and two materials at least: {materials:?}");
    server.stop();
}

/// The difference view against the frame as rendered (`view=diff-rendered`) is zero for
/// the frame under its own light: black, and its error within f32 rounding, pass by pass;
/// so is the difference from a Cycles render that is the frame's own beauty
/// (`diff-cycles`). Turned, the light makes both differ, in both signs.
#[test]
fn the_difference_from_the_frame_itself_is_zero() {
    let Some(browser) = required_browser("the_difference_from_the_frame_itself_is_zero") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    rendered_cones(dir.path(), serde_json::json!([]), false);
    // Its passes written as f32: what the page relights from, to the page's f64 sums.
    let frames = dir.path().join("float");
    let scene = dir.path().join("cones");
    let render = ["render", scene.to_str().unwrap(), "--frames", "1", "--transfer", "--colour-type", "float"];
    run(&[&render[..], &["--progress", "none", "--out", frames.to_str().unwrap()]].concat());
    // The frame's own beauty as its Cycles render.
    let beauty = support::exr_channels(&frames.join("render.0001.exr"));
    let [r, g, b] = ["R", "G", "B"].map(|c| beauty[c].clone());
    logsh::scene::output::write_exr_channels(
        &frames.join("cycles.0001.exr"),
        240,
        135,
        &[("R", &r), ("G", &g), ("B", &b)],
    )
    .unwrap();
    let server = Server::start(&frames);
    // Sums of a few products of f32 values below 4, in f64 here and in f32 by the render.
    const F32_ROUNDING: f64 = 1e-6;
    let error = |dom: &str| -> (f64, f64) {
        let value = |what| attribute_of(dom, "metrics", what).and_then(|v| v.parse().ok()).expect(dom);
        (value("data-mean"), value("data-p95"))
    };
    for query in [
        "view=diff-rendered",
        "view=diff-rendered&pass=diffuse",
        "view=diff-rendered&pass=specular",
        "view=diff-rendered&pass=visibility",
        "view=diff-cycles",
        "view=diff-rendered&diff=signed",
    ] {
        let url = format!("{}?{query}", server.address);
        let (shot, dom) =
            screenshot_and_page(&browser, &format!("{url}&zoom=1"), WINDOW, 1, &dir.path().join("same.png"));
        let (mean, p95) = error(&dom);
        println!("{query}: mean {mean:.3e}, p95 {p95:.3e}");
        assert!(mean <= F32_ROUNDING && p95 <= F32_ROUNDING, "{query}: mean {mean:.3e}, p95 {p95:.3e}");
        let [left, top, width, height] = frame_in(&shot);
        assert_eq!((width, height), (240, 135), "{query}: the frame is all black");
        let lit = (0..height)
            .flat_map(|y| (0..width).map(move |x| (x, y)))
            .filter(|&(x, y)| shot.get_pixel(left + x, top + y).0[..3] != [0, 0, 0])
            .count();
        assert_eq!(lit, 0, "{query}: {lit} pixels of the difference are not black");
    }
    for query in ["view=diff-rendered&rotation=75", "view=diff-cycles&rotation=75"] {
        let url = format!("{}?{query}&diff=signed&zoom=1", server.address);
        let (shot, dom) = screenshot_and_page(&browser, &url, WINDOW, 1, &dir.path().join("turned.png"));
        let (mean, p95) = error(&dom);
        println!("{query}: mean {mean:.3e}, p95 {p95:.3e}");
        assert!(mean > 1e-3 && p95 > mean, "{query}: turned 75 degrees, the frame differs: mean {mean:.3e}");
        let [left, top, width, height] = frame_in(&shot);
        let pixels: Vec<[u8; 3]> = (0..height)
            .flat_map(|y| (0..width).map(move |x| (x, y)))
            .map(|(x, y)| {
                let p = shot.get_pixel(left + x, top + y).0;
                [p[0], p[1], p[2]]
            })
            .collect();
        let (bluer, redder) = (
            pixels.iter().filter(|p| p[2] > p[0].saturating_add(20)).count(),
            pixels.iter().filter(|p| p[0] > p[2].saturating_add(20)).count(),
        );
        println!("{query}: {bluer} pixels below, {redder} above");
        assert!(bluer > 500 && redder > 500, "{query}: both signs shown: {bluer} below, {redder} above");
    }
    server.stop();
}

/// Frame 2 of the cones rendered with transfer layers into `frames`, beside frame 1.
fn render_second_frame(scene: &Path, frames: &Path) {
    let (scene, frames) = (scene.to_str().unwrap(), frames.to_str().unwrap());
    run(&["render", scene, "--frames", "2", "--transfer", "--progress", "none", "--out", frames]);
}

/// The controls with nothing to act on are hidden, and the page says why: without a
/// Cycles render, the views against it (and an address asking for one shows the frame
/// relit); with one frame, the frame slider; outside a wipe, the wipe; outside a
/// difference, its kind. With a Cycles render and two frames, they are shown.
#[test]
fn controls_without_a_target_are_hidden() {
    let Some(browser) = required_browser("controls_without_a_target_are_hidden") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let frames = rendered_cones(dir.path(), serde_json::json!([]), false);
    let scene = dir.path().join("cones");
    std::fs::rename(scene.join("cycles.0001.exr"), scene.join("cycles.moved")).unwrap();
    let server = Server::start(&frames);
    let url = format!("{}?view=wipe-cycles", server.address);
    let (shot, dom) = screenshot_and_page(&browser, &format!("{url}&zoom=1"), WINDOW, 1, &dir.path().join("none.png"));
    let option = |dom: &str, value: &str| -> bool {
        let at = dom.find(&format!("<option value=\"{value}\"")).unwrap();
        dom[at..at + dom[at..].find('>').unwrap()].contains(" hidden")
    };
    assert!(option(&dom, "wipe-cycles") && option(&dom, "diff-cycles"), "no Cycles render: nothing to wipe against");
    assert!(!option(&dom, "wipe-rendered") && !option(&dom, "diff-rendered"), "the frame as rendered is there");
    assert!(is_hidden(&dom, "frame-control"), "one frame: no slider");
    assert!(
        is_hidden(&dom, "wipe-control") && is_hidden(&dom, "diff-control"),
        "the frame relit: no wipe, no difference"
    );
    let notes = text_of(&dom, "notes");
    println!("notes: {notes}");
    assert!(notes.contains("no Cycles render") && notes.contains("one frame in the directory"), "{notes}");
    let relit = frame_shot(&browser, &server.address, &dir.path().join("relit.png"));
    let [left, top, width, height] = frame_in(&shot);
    let shown = image::imageops::crop_imm(&shot, left, top, width, height).to_image();
    assert_eq!(
        difference(&shown, &relit),
        0.0,
        "asked for a wipe against no Cycles render, the page shows the frame relit"
    );
    server.stop();

    // A Cycles render and a second frame.
    std::fs::rename(scene.join("cycles.moved"), scene.join("cycles.0001.exr")).unwrap();
    render_second_frame(&scene, &frames);
    let server = Server::start(&frames);
    let dom = page(&browser, &format!("{}?view=wipe-cycles", server.address));
    assert!(!option(&dom, "wipe-cycles") && !option(&dom, "diff-cycles"), "a Cycles render to wipe against");
    assert!(!is_hidden(&dom, "frame-control") && !is_hidden(&dom, "wipe-control"), "two frames, a wipe");
    assert!(is_hidden(&dom, "diff-control"), "no difference shown");
    assert!(text_of(&dom, "status").contains("the Cycles render right of the wipe"), "{}", text_of(&dom, "status"));
    let dom = page(&browser, &format!("{}?view=diff-cycles", server.address));
    assert!(is_hidden(&dom, "wipe-control") && !is_hidden(&dom, "diff-control"), "a difference: its kind, no wipe");
    server.stop();
}

/// Every control is in the Tab order (none taken out of it) and names its keys
/// (`aria-keyshortcuts`), which the help lists; and the keys act (`keys=K,...` presses
/// them once the frame is shown): they turn the light as its slider does, step through a
/// sequence, change the view and pin the inspector, and the address kept for a colleague
/// (the page's link to its view) holds what they set.
#[test]
fn every_control_takes_the_keyboard() {
    let Some(browser) = required_browser("every_control_takes_the_keyboard") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let frames = rendered_cones(dir.path(), serde_json::json!([]), false);
    let scene = dir.path().join("cones");
    render_second_frame(&scene, &frames);
    let server = Server::start(&frames);
    let dom = page(&browser, &server.address);
    // The keys the help's table names, each cell's words.
    let help = &dom[dom.find("id=\"help\"").unwrap()..];
    let help = &help[..help.find("</table>").unwrap()];
    let listed: std::collections::HashSet<&str> = help
        .split("<th>")
        .skip(1)
        .flat_map(|cell| cell[..cell.find("</th>").unwrap()].split_whitespace())
        .map(|word| if word.len() > 1 { word.trim_end_matches(',') } else { word })
        .collect();
    let mut controls = 0;
    for kind in ["<input", "<select", "<button", "tabindex=\"0\""] {
        for (at, _) in dom.match_indices(kind) {
            let start = dom[..at + 1].rfind('<').unwrap();
            let tag = &dom[start..start + dom[start..].find('>').unwrap()];
            assert!(!tag.contains("tabindex=\"-1\""), "out of the Tab order: {tag}");
            let keys = tag.split("aria-keyshortcuts=\"").nth(1).map(|k| &k[..k.find('"').unwrap()]);
            let keys = keys.unwrap_or_else(|| panic!("no keys named: {tag}"));
            for key in keys.split(' ') {
                let key = key.trim_start_matches("Shift+");
                let named = match key {
                    "ArrowLeft" => "←",
                    "ArrowRight" => "→",
                    "ArrowUp" | "ArrowDown" => "arrows",
                    key => key,
                };
                assert!(listed.contains(named), "the help does not list {key} ({tag}): {listed:?}");
            }
            controls += 1;
        }
    }
    println!("{controls} controls in the Tab order, each with its keys");
    assert!(controls >= 15, "{controls} controls");

    // Three turns of 5 degrees are the rotation slider's 15, and the link keeps them.
    let keyed = frame_shot(&browser, &format!("{}?keys=],],]", server.address), &dir.path().join("keyed.png"));
    let slid = frame_shot(&browser, &format!("{}?rotation=15", server.address), &dir.path().join("slid.png"));
    assert_eq!(difference(&keyed, &slid), 0.0, "] turns the light by 5 degrees");
    let unturned = frame_shot(&browser, &server.address, &dir.path().join("unturned.png"));
    assert!(difference(&keyed, &unturned) > 0.5, "the keys turned the light");
    let dom = page(&browser, &format!("{}?keys=],],],s,v,i", server.address));
    let link = attribute_of(&dom, "share", "href").unwrap();
    println!("link: {link}");
    for kept in ["rotation=15", "strength=0.9", "view=wipe-rendered"] {
        assert!(link.contains(kept), "the link keeps {kept}: {link}");
    }
    // i pins the pixel at the middle of the window: (120, 67.5), rounded either way.
    let pinned: Vec<i64> = link
        .split("inspect=")
        .nth(1)
        .expect(&link)
        .split('&')
        .next()
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    assert!((pinned[0] - 120).abs() <= 1 && (pinned[1] - 67).abs() <= 1, "the link keeps the pinned pixel: {link}");
    assert!(text_of(&dom, "status").contains("as rendered right of the wipe"), "v: the next view");
    assert!(!is_hidden(&dom, "inspector"), "i pins the inspector");
    // A sequence: the arrows step through it, End goes to its last frame.
    for (query, shown) in [
        ("frame=1&keys=ArrowLeft", "render.0001.exr"),
        ("keys=End", "render.0002.exr"),
        ("keys=ArrowRight", "render.0002.exr"),
    ] {
        let dom = page(&browser, &format!("{}?{query}", server.address));
        assert_eq!(attribute_of(&dom, "status", "data-frame").as_deref(), Some(shown), "{query}");
    }
    server.stop();
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
