//! `logsh view`: a local web page that shows the frames of a render and relights them in
//! the browser from their transfer layers ([`crate::transfer`]).
//!
//! The server ([`server`]) listens on 127.0.0.1 only, within bounds on connections,
//! header sizes and time, answers requests addressed to 127.0.0.1, `localhost` or `[::1]`
//! only, and GET requests only:
//!
//! | path | body |
//! |---|---|
//! | `/` | the page (`page/`: its markup and four scripts, one page: the frame fitted to the window, a panel of controls below it, the relight in JavaScript) |
//! | `/frames.json` | the frames of the directory: file names, those found at start sorted, then those written since appended (`Viewer::listed`) |
//! | `/frame/<i>/meta.json` | size (of a preview at most 1920x1080: `PREVIEW_SIZE`), order, the light's SH vector, the lobes, the layout of the next two; the passes `rendered.bin` has, why there is no Cycles render where there is none, the suns' and Sun lamps' directions, and the point lamps' as seen from the middle of the frame |
//! | `/frame/<i>/pixels.bin` | the transfer layers, little-endian f32, one array after another |
//! | `/frame/<i>/maps.bin` | the maps the glossy lookups read ([`RelightLight::sampled_maps`]), then the scene's view transform LUT ([`crate::scene::view`]) |
//! | `/frame/<i>/cycles.bin` | the Cycles render of the frame as RGB f32, where one is found |
//! | `/frame/<i>/rendered.bin?pass=NAME` | the frame's pass `NAME` as rendered (`beauty`, `diffuse`, `specular`, `environment`, `indirect`: RGB; `visibility`: one value), f32 at the preview's pixels, read from its file ([`as_rendered`]) |
//! | `/frame/<i>/pixel.json?x=X&y=Y` | pixel (`X`, `Y`) of the frame (its own pixels, not the preview's) as its file holds it: every channel but the transfer layers, by full name; and the material index and type of each of its G-buffer samples, or why they cannot be read |
//! | `/frame/<i>/sharp_lights.bin?rotation=DEG` | the light turned `DEG` about Z, shaded again as `logsh relight` shades it ([`SunLampTurn`]), RGB f32: where the frame has Sun lamps, the `lamps_diffuse` then `lamps_specular` layers with them turned; then, where the page's light has suns taken out of its map (`sharp_suns`), their diffuse then specular light, turned |
//! | `/bench/start`, `/bench/end?runs=N&what=W&page_ms=T` | the page's `?bench=N` mode: the server prints the time between the two, and the page's own where its clock moved |
//!
//! The page keeps its state in its address (`history.replaceState`; its "link to this
//! view" is that address), so that a view can be shared, and takes its first state from
//! it:
//!
//! | parameter | state |
//! |---|---|
//! | `frame=I` | the frame, its index in `frames.json` from 0 |
//! | `pass=NAME` | `beauty`, `diffuse`, `specular`, `environment`, `indirect`, `visibility` |
//! | `view=V` | `relit`; `wipe-rendered`, `diff-rendered` against the pass as rendered; `wipe-cycles`, `diff-cycles` against the Cycles render (the beauty). A view with nothing to compare against is the relit frame; `wipe=F` alone is `wipe-cycles` |
//! | `diff=abs` or `signed` | the difference's kind: absolute per channel, or the mean over R, G, B on a diverging map (blue below, red above, black at zero) |
//! | `wipe=F` | where the wipe is, 0 to 1 of the frame's width |
//! | `rotation=DEG`, `strength=S`, `exposure=EV` | the light's turn about Z (any angle, wrapped into -180 to 180), its strength, the exposure added to the scene's |
//! | `zoom=Z` | device pixels per frame pixel (absent: fitted to the window) |
//! | `center=X,Y` | with `zoom`, the frame's point at the middle of the window, in frame pixels |
//! | `inspect=X,Y` | the pixel pinned in the inspector, in frame pixels |
//! | `keys=K,...` | keys pressed once the frame is shown (`KeyboardEvent.key` names, `Shift+` before one held): a view scripted |
//! | `bench=N`, `proxy=N`, `dragging=1` | timing (below): N relights of each kind; a drag's step fixed at N; the frame as while the rotation is held |
//!
//! The page fits the frame to the window's device pixels (its canvas sized by
//! `devicePixelRatio` and again when the window changes), shows frame pixels as squares
//! when magnified (drawn without smoothing), zooms with the wheel and the keys, pans by
//! dragging, and inspects the pixel under the cursor or pinned: its coordinates, its passes
//! relit by the page, and its channels and material from `pixel.json`, to 5 significant
//! digits. Against a reference it shows the mean and 95th percentile of the per-pixel
//! absolute error (the mean over R, G, B, linear) over the preview's pixels. A small
//! equirectangular view of the light's map turns with the rotation and turns it when
//! dragged, the suns and Sun lamps marked. Every control is in the Tab order and has keys
//! (`aria-keyshortcuts`; `?` shows them). Controls with nothing to act on (no Cycles
//! render, one frame, no bounce light) are hidden, and the page says why.
//!
//! The page turns the light about Z by rotating its SH vector (exact, [`crate::sh::rotate_z`])
//! and reading the maps along `Rz(-turn) R`; strength scales the environment (its
//! suns shaded sharp included), exposure
//! adds to the scene's, and the image is shown through the scene's view transform as the
//! PNG previews are. It lights a frame once per turn and recombines it for the other
//! sliders, and only draws it again for zoom and pan; while a slider is dragged, at one
//! pixel in 2 x 2 or 4 x 4 (`?proxy=N` fixes the step), in full once it is let go. Its
//! status line says what a relight took by the page's clock (`performance.now()`), and
//! nothing of a time where nothing was relit or the clock did not move (a headless
//! browser's virtual time). It is the relight of [`crate::transfer::relight`]
//! but for the maps, read from grids at most [`crate::transfer::SAMPLED_MAP_WIDTH`] wide,
//! and the open lobes' light, from a 64 x 32 grid: a preview, for which `logsh relight`
//! gives the frame.
//!
//! The sharp lights are shaded by the server, as `logsh relight` shades them: the
//! frame's Sun lamps, and the suns that a render under `--sharp-lights auto` (the
//! default) takes out of its map, whose residual the page's SH vector and glossy maps
//! then hold ([`RelightLight::with_sharp_suns`]). The map's suns come with the frame's
//! layers at the render's turn (`suns_diffuse`, `suns_specular`), shaded at the shown
//! pixels. At each turn, the page asks for them and the Sun lamps turned
//! (`sharp_lights.bin`: the scene shaded again, a sun's share of a render), one turn at a
//! time, and shows them at the last turn shaded (the render's before any) until they
//! come: during a drag they follow it a turn of the server's behind. Where the scene cannot be read, the Sun
//! lamps stay as rendered and the map's suns are held in SH (soft shadows, as
//! `logsh relight --sharp-lights off` holds them), and the page says why.

use crate::scene::SunLight;
use crate::scene::ViewTransform;
use crate::shade::bounce::IndirectParts;
use crate::transfer::{RelightLight, RelightOptions, SunLampFrame, SunLampTurn, TransferFrame};
use anyhow::{anyhow, Context, Result};
use rayon::prelude::*;
use std::borrow::Cow;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

mod as_rendered;
mod point_lamps;
mod server;

use server::Response;

/// The page, with its script inline.
const PAGE: &str = concat!(
    // The markup and its style.
    include_str!("page/head.html"),
    // The relight: SH rotation, map lookups, the view transform, the passes composed.
    include_str!("page/light.js"),
    // The window (fit, zoom, pan), the pixel inspector and the light's map.
    include_str!("page/window.js"),
    // The sharp lights, the frame shown, the address and the sequence.
    include_str!("page/frame.js"),
    // Keys, the pointer, the state from the address, and the start.
    include_str!("page/controls.js"),
    include_str!("page/tail.html"),
);

/// What `logsh view` serves.
pub struct Viewer {
    /// The directory served.
    dir: PathBuf,
    /// Its frames with transfer layers, each at the index it was first listed at
    /// ([`Self::listed`]).
    frames: Mutex<Vec<PathBuf>>,
    /// The bodies of the frames last asked for (at most [`KEPT_FRAMES`]), newest last.
    built: Mutex<Vec<(FrameStamp, Arc<FrameBodies>)>>,
    /// When the page's benchmark started ([`PAGE`]'s `?bench=N`).
    bench: Mutex<Option<std::time::Instant>>,
    /// Held while a frame's bodies are built, so that requests that come together build
    /// them once (twenty at once each built their own: 7 to 8 times as slow, and 880 MB).
    building: Mutex<()>,
}

/// The responses of one frame.
struct FrameBodies {
    /// The frame's header, which names the scene its G-buffer is read from.
    header: crate::transfer::TransferHeader,
    /// The frame's width and height (its preview's may be smaller: [`PREVIEW_SIZE`]).
    size: [usize; 2],
    meta: String,
    pixels: Vec<u8>,
    maps: Vec<u8>,
    cycles: Option<Vec<u8>>,
    /// The Cycles renders looked for and how each was written (or `None` for one not
    /// there): one added or written again is read.
    cycles_files: Vec<(PathBuf, Option<Written>)>,
    /// What turns the frame's sharp lights, where it has Sun lamps or its map suns.
    sharp: Option<SharpLights>,
}

/// A frame's sharp lights, to be turned at the page's request (`sharp_lights.bin`): its
/// Sun lamps, and the suns taken out of its map.
struct SharpLights {
    file: PathBuf,
    /// The frame without its transfer and colour layers: its header and lamps.
    lamps: TransferFrame,
    /// The pixels the page shows ([`preview_pixels`]).
    shown: Vec<usize>,
    /// The suns taken out of the map at the render's turn, which the page's light does
    /// not hold; empty where it holds them (`suns_in_sh`).
    suns: Vec<SunLight>,
    /// The scene loaded to shade them, or why it cannot be (the page then keeps the Sun
    /// lamps as rendered, holds the map's suns in SH, and says why; [`Viewer::bodies`]
    /// tries again at the frame's next request).
    turn: std::result::Result<Arc<SunLampTurn>, String>,
    /// The frame's scene frame, read and checked at its first turn, with the scene that
    /// read it, which the turns after it share rather than reading the G-buffer and
    /// filtering the pyramid at every turn.
    /// Held while it is read, so that turns asked for together read it once.
    prepared: Mutex<Option<(Arc<SunLampTurn>, Arc<SunLampFrame>)>>,
}

impl SharpLights {
    /// The lamps of `frame` (read from `file`), its other layers dropped, and the map's
    /// `suns`, turned by `turn`; `prepared` where the frame was made ready for it.
    fn new(
        file: &Path,
        mut frame: TransferFrame,
        shown: Vec<usize>,
        suns: Vec<SunLight>,
        turn: std::result::Result<Arc<SunLampTurn>, String>,
        prepared: Option<Arc<SunLampFrame>>,
    ) -> Self {
        frame.diffuse = Vec::new();
        frame.unoccluded = Vec::new();
        (frame.heightfield, frame.blockers, frame.specular) = (None, None, None);
        frame.albedo = Vec::new();
        frame.specular_colour = Vec::new();
        frame.glossy_lobe = Vec::new();
        frame.glossy_direction = Vec::new();
        frame.glossy_weight = Vec::new();
        frame.diffuse_normal = None;
        let prepared = turn.as_ref().ok().zip(prepared).map(|(turn, prepared)| (turn.clone(), prepared));
        Self { file: file.to_path_buf(), lamps: frame, shown, suns, turn, prepared: Mutex::new(prepared) }
    }

    /// `sharp_lights.bin` at `degrees` beyond the render's turn, at the shown pixels: the
    /// lamps' layers with the Sun lamps turned, where the frame has some, then the map's
    /// suns' light turned, where the page's light does not hold them.
    fn turned(&self, degrees: f64) -> Response {
        let turn = match &self.turn {
            Ok(turn) => turn,
            Err(why) => return Response::error(409, why),
        };
        let lamps = !self.lamps.header.sun_lamps.is_empty();
        if !lamps && self.suns.is_empty() {
            return Response::error(409, "the map's suns are held in SH here: they cannot be shaded from the scene");
        }
        let (turn, prepared) = {
            let mut prepared = self.prepared.lock().unwrap_or_else(|p| p.into_inner());
            match prepared.as_ref() {
                Some(both) => both.clone(),
                // Checked again at each turn until it passes, the scene loaded again where
                // it fails: a scene put back since it was loaded is then seen.
                None => match turn.prepare(&self.lamps, &self.file).map(|frame| (turn.clone(), frame)).or_else(|e| {
                    let fresh = SunLampTurn::new(&self.lamps.header, &self.file).map_err(|_| e)?;
                    fresh.prepare(&self.lamps, &self.file).map(|frame| (Arc::new(fresh), frame))
                }) {
                    Ok((turn, frame)) => prepared.insert((turn, Arc::new(frame))).clone(),
                    Err(e) => return Response::error(500, &e.to_string()),
                },
            }
        };
        // Shaded at the shown pixels alone: one in `stride^2` of a frame wider than the
        // preview. The map's suns apart, which the page scales with its strength.
        let (frame, file, shown) = (&self.lamps, &self.file, Some(&self.shown[..]));
        let turned_suns: Vec<SunLight> = self.suns.iter().map(|sun| sun.turned(degrees)).collect();
        let layers = lamps
            .then(|| turn.turned_at(&prepared, frame, file, degrees, shown))
            .into_iter()
            .chain((!turned_suns.is_empty()).then(|| turn.suns_at(&prepared, frame, file, &turned_suns, shown)))
            .collect::<std::result::Result<Vec<_>, _>>();
        match layers {
            Ok(layers) => {
                let mut body = Vec::new();
                for layer in layers.iter().flatten() {
                    put_f32s(&mut body, layer.as_flattened());
                }
                Response::ok("application/octet-stream", body)
            }
            Err(e) => Response::error(500, &e.to_string()),
        }
    }
}

impl Viewer {
    /// The frames of `dir` that hold transfer layers, by file name.
    pub fn new(dir: &Path) -> Result<Self> {
        let frames = frames_in(dir, &[]).with_context(|| format!("{}: cannot list the directory", dir.display()))?;
        if frames.is_empty() {
            return Err(anyhow!(
                "{}: no frames with transfer layers; render them with `logsh render --transfer --out {}`",
                dir.display(),
                dir.display()
            ));
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            frames: Mutex::new(frames),
            built: Mutex::new(Vec::new()),
            bench: Mutex::new(None),
            building: Mutex::new(()),
        })
    }

    /// The frames as the directory holds them now: those listed before, each at its index
    /// (one since removed stays listed, and reading it says it is gone), then those
    /// written since, sorted by name. A render writing a sequence into the directory
    /// while the page is open adds its frames at the end, where a page loaded again finds
    /// them, and never moves a frame a page has asked for. A directory that cannot be
    /// listed now leaves the list as it was.
    fn listed(&self) -> Vec<PathBuf> {
        let mut frames = self.frames.lock().unwrap_or_else(|p| p.into_inner());
        if let Ok(new) = frames_in(&self.dir, &frames) {
            frames.extend(new);
        }
        frames.clone()
    }

    /// The file of frame `index`, listing the directory again if it is past the frames
    /// listed so far; or how many there are.
    fn frame_file(&self, index: usize) -> std::result::Result<PathBuf, usize> {
        let known = self.frames.lock().unwrap_or_else(|p| p.into_inner()).get(index).cloned();
        match known {
            Some(file) => Ok(file),
            None => {
                let frames = self.listed();
                frames.get(index).cloned().ok_or(frames.len())
            }
        }
    }

    /// Listens on 127.0.0.1:`port` (0: any free port) and serves until the process ends
    /// ([`server`]); `ready` receives the page's address once the socket listens.
    pub fn serve(self, port: u16, ready: impl FnOnce(&str)) -> Result<()> {
        let listener = server::bind(port)?;
        ready(&server::address(&listener)?);
        let viewer = Arc::new(self);
        server::serve(listener, move |request| match request.path {
            path if path.starts_with("/bench/") => viewer.bench(path, request.query),
            path => viewer.route(path, request.query),
        })
    }

    /// Times the page's benchmark by the server's clock and prints it.
    fn bench(&self, path: &str, query: &str) -> Response {
        let mut started = self.bench.lock().unwrap_or_else(|p| p.into_inner());
        match (path, started.take()) {
            ("/bench/start", _) => *started = Some(std::time::Instant::now()),
            ("/bench/end", Some(start)) => {
                let ms = 1e3 * start.elapsed().as_secs_f64();
                let runs: f64 = query_value(query, "runs").and_then(|n| n.parse().ok()).unwrap_or(1.0);
                // The page's own clock, which stands still under a headless browser's
                // virtual time: said only where it moved.
                let page_ms = query_value(query, "page_ms").and_then(|n| n.parse::<f64>().ok()).filter(|&ms| ms > 0.0);
                if query_value(query, "what") == Some("shown") {
                    // One drag per frame of the browser's: the first to the last is
                    // `runs - 1` frames.
                    let rate = |ms: f64| 1e3 * (runs - 1.0) / ms;
                    let page = page_ms.map_or(String::new(), |p| format!(", {:.1} by the page's clock", rate(p)));
                    eprintln!(
                        "view: {runs} rotation drags shown one per browser frame: {:.1} frames per second by the \
                         server's clock{page}",
                        rate(ms)
                    );
                    return Response::ok("text/plain", Vec::new());
                }
                let what = match query_value(query, "what") {
                    Some("dragged") => "relights while the rotation is dragged",
                    Some("strength") => "strength changes (no relight)",
                    _ => "relights",
                };
                let page = page_ms.map_or(String::new(), |p| format!(" ({:.1} ms each by the page's clock)", p / runs));
                eprintln!("view: {runs} {what} in the browser took {ms:.0} ms, {:.1} ms each{page}", ms / runs);
            }
            _ => return Response::error(404, "no benchmark started"),
        }
        Response::ok("text/plain", Vec::new())
    }

    fn route(&self, path: &str, query: &str) -> Response {
        match path {
            "/" | "/index.html" => Response::ok("text/html; charset=utf-8", PAGE.as_bytes().to_vec()),
            "/frames.json" => {
                let names: Vec<String> = self
                    .listed()
                    .iter()
                    .map(|f| f.file_name().unwrap_or_default().to_string_lossy().into_owned())
                    .collect();
                Response::ok("application/json", serde_json::to_vec(&names).expect("names serialise"))
            }
            _ => {
                let mut parts = path.trim_start_matches('/').split('/');
                let (Some("frame"), Some(index), Some(what), None) =
                    (parts.next(), parts.next(), parts.next(), parts.next())
                else {
                    return Response::error(404, "no such page");
                };
                let Ok(number) = index.parse::<usize>() else {
                    return Response::error(404, &format!("no frame {index}: frames are numbered from 0"));
                };
                let file = match self.frame_file(number) {
                    Ok(file) => file,
                    Err(count) => {
                        return Response::error(
                            404,
                            &format!("no frame {index}: the directory has {count}, numbered 0 to {}", count - 1),
                        )
                    }
                };
                let bodies = match self.bodies(number, &file) {
                    Ok(bodies) => bodies,
                    Err(e) => return Response::error(500, &format!("{e:#}")),
                };
                match what {
                    "meta.json" => Response::ok("application/json", bodies.meta.as_bytes().to_vec()),
                    "pixels.bin" => Response::ok("application/octet-stream", bodies.pixels.clone()),
                    "maps.bin" => Response::ok("application/octet-stream", bodies.maps.clone()),
                    "cycles.bin" => match &bodies.cycles {
                        Some(rgb) => Response::ok("application/octet-stream", rgb.clone()),
                        None => Response::error(404, "no Cycles render of this frame"),
                    },
                    "rendered.bin" => rendered_pass(&file, &bodies, query_value(query, "pass").unwrap_or("beauty")),
                    "pixel.json" => inspected_pixel(&file, &bodies, query),
                    "sharp_lights.bin" => {
                        let rotation = query_value(query, "rotation");
                        match (&bodies.sharp, rotation.and_then(|r| r.parse::<f64>().ok())) {
                            (None, _) => Response::error(404, "this frame has no Sun lamp and its map no sun"),
                            (_, None) => Response::error(400, "sharp_lights.bin takes ?rotation=DEG"),
                            (_, Some(degrees)) if !degrees.is_finite() => {
                                Response::error(400, "the rotation is not a number")
                            }
                            (Some(sharp), Some(degrees)) => sharp.turned(degrees),
                        }
                    }
                    _ => Response::error(404, "no such page"),
                }
            }
        }
    }

    /// Frame `index`'s responses, built on its first request and kept while it is among
    /// the last [`KEPT_FRAMES`] asked for (a 960 x 540 frame's are about 140 MB).
    fn bodies(&self, index: usize, file: &Path) -> Result<Arc<FrameBodies>> {
        let built = || self.built.lock().unwrap_or_else(|p| p.into_inner());
        // A frame written again since (rendered anew) is read again.
        let stamp = FrameStamp::of(index, file);
        let unchanged = |bodies: &FrameBodies| bodies.cycles_files.iter().all(|(path, was)| written(path) == *was);
        let kept = || built().iter().find(|(kept, bodies)| *kept == stamp && unchanged(bodies)).map(|(_, b)| b.clone());
        // Kept, unless its sharp lights could not be shaded and now can (the scene put back).
        let current = |bodies: &FrameBodies| match &bodies.sharp {
            Some(SharpLights { turn: Err(_), lamps, .. }) => SunLampTurn::new(&lamps.header, file).is_err(),
            _ => true,
        };
        if let Some(bodies) = kept().filter(|bodies| current(bodies)) {
            return Ok(bodies);
        }
        let _building = self.building.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(bodies) = kept().filter(|bodies| current(bodies)) {
            return Ok(bodies);
        }
        let frame = TransferFrame::read(file)?;
        let options = RelightOptions::default();
        let source = options.source(&frame.header);
        // The map's suns taken out where the render took them out, as `logsh relight`
        // takes them out by default.
        let sharp = frame.header.settings.is_some_and(|settings| settings.sharp_lights);
        let mut light = match sharp {
            true => RelightLight::with_sharp_suns(source.clone(), &frame.header, file)?,
            false => RelightLight::new(source.clone(), &frame.header, file)?,
        };
        options.check_rendered_map(&light, &frame.header, file)?;
        let (view, standard) = ViewTransform::for_preview(frame.header.view.as_ref(), file);
        let lamps = !frame.header.sun_lamps.is_empty();
        let turn = (lamps || !light.sharp_suns().is_empty())
            .then(|| SunLampTurn::new(&frame.header, file).map(Arc::new).map_err(|e| e.to_string()));
        let (shown, ..) = preview_pixels(frame.width, frame.height, PREVIEW_SIZE);
        // The map's suns at the render's turn, shaded at the shown pixels, or held in SH
        // where the scene cannot shade them.
        let mut suns = None;
        let mut held = match frame.header.settings {
            Some(settings) if settings.sharp_lights => None,
            Some(_) => Some("as the frame was rendered, with --sharp-lights off".to_string()),
            None => {
                Some("its header does not record the render's settings: render it again with this logsh".to_string())
            }
        };
        if let Some(turn) = turn.as_ref().filter(|_| !light.sharp_suns().is_empty()) {
            let shaded = turn.as_ref().map_err(Clone::clone).and_then(|turn| {
                let prepared = turn.prepare(&frame, file).map_err(|e| e.to_string())?;
                let layers = turn.suns_at(&prepared, &frame, file, light.sharp_suns(), Some(&shown));
                Ok((Arc::new(prepared), layers.map_err(|e| e.to_string())?))
            });
            match shaded {
                Ok(shaded) => suns = Some(shaded),
                Err(why) => {
                    eprintln!("view: {}: the map's suns are held in SH (soft shadows): {why}", file.display());
                    held = Some(format!(
                        "logsh relight shades the map's suns sharp from the scene, which fails here: {why}"
                    ));
                    light = RelightLight::new(source, &frame.header, file)?;
                }
            }
        }
        let shown_sharp = SharpShown {
            lamps_kept: turn.as_ref().filter(|_| lamps).and_then(|turn| turn.as_ref().err().map(String::as_str)),
            suns: suns.as_ref().map(|(_, layers)| layers),
            suns_held: held.as_deref(),
        };
        let mut bodies = frame_bodies(file, &frame, &light, &view, PREVIEW_SIZE, shown_sharp, standard);
        if let Some(turn) = turn {
            let sharp_suns = light.sharp_suns().to_vec();
            let prepared = suns.map(|(prepared, _)| prepared);
            bodies.sharp = Some(SharpLights::new(file, frame, shown, sharp_suns, turn, prepared));
        }
        let bodies = Arc::new(bodies);
        let mut kept = built();
        kept.retain(|(kept, _)| kept.index != index);
        kept.push((stamp, bodies.clone()));
        if kept.len() > KEPT_FRAMES {
            kept.remove(0);
        }
        Ok(bodies)
    }
}

/// The value of `key` in a request's query (`a=1&b=2`), as sent.
fn query_value<'a>(query: &'a str, key: &str) -> Option<&'a str> {
    query.split('&').find_map(|pair| pair.strip_prefix(key)?.strip_prefix('='))
}

/// `rendered.bin?pass=NAME`: the frame's pass `NAME` as rendered ([`as_rendered::PASSES`]),
/// read from its file at the preview's pixels, one or three f32 per pixel.
fn rendered_pass(file: &Path, bodies: &FrameBodies, pass: &str) -> Response {
    let Some(channels) = as_rendered::pass_channels(pass) else {
        let names: Vec<&str> = as_rendered::PASSES.iter().map(|(name, _)| *name).collect();
        return Response::error(404, &format!("no pass {pass}: the passes are {}", names.join(", ")));
    };
    let (shown, ..) = preview_pixels(bodies.size[0], bodies.size[1], PREVIEW_SIZE);
    match as_rendered::pass_at(file, channels, &shown) {
        Ok(values) => {
            let mut body = Vec::new();
            put_f32s(&mut body, &values);
            Response::ok("application/octet-stream", body)
        }
        Err(e) => Response::error(404, &format!("no {pass} as rendered: {e}")),
    }
}

/// `pixel.json?x=X&y=Y`: the frame's pixel (`X`, `Y`), counted in the frame's own pixels
/// (not the preview's), as its file holds it: every channel but the transfer layers, by
/// full name in the file's order, and the material of its G-buffer samples (or why they
/// cannot be read).
fn inspected_pixel(file: &Path, bodies: &FrameBodies, query: &str) -> Response {
    let coordinate = |key| query_value(query, key).and_then(|v| v.parse::<usize>().ok());
    let (Some(x), Some(y)) = (coordinate("x"), coordinate("y")) else {
        return Response::error(400, "pixel.json takes ?x=X&y=Y, whole pixels from the top-left corner");
    };
    let [width, height] = bodies.size;
    let channels = match as_rendered::channels_at(file, x, y) {
        Ok(Some(channels)) => channels,
        Ok(None) => {
            return Response::error(404, &format!("no pixel ({x}, {y}): the frame is {width}x{height}"));
        }
        Err(e) => return Response::error(500, &e.to_string()),
    };
    let material = match as_rendered::materials_at(&bodies.header, x, y) {
        Ok(samples) => serde_json::json!({
            "samples": samples.iter().map(|(index, kind)| serde_json::json!({"index": index, "type": kind}))
                .collect::<Vec<_>>(),
        }),
        Err(e) => serde_json::json!({"unread": e.to_string()}),
    };
    let body = serde_json::json!({
        "x": x,
        "y": y,
        "channels": channels.iter().map(|(name, value)| serde_json::json!([name, value])).collect::<Vec<_>>(),
        "material": material,
    });
    Response::ok("application/json", body.to_string().into_bytes())
}

/// A file's size and time of last writing.
type Written = (u64, std::time::SystemTime);

/// How `file` was last written, `None` where it is not there.
fn written(file: &Path) -> Option<Written> {
    std::fs::metadata(file).ok().and_then(|m| Some((m.len(), m.modified().ok()?)))
}

/// A frame's index and how its file was written, as its responses were built from it.
#[derive(Clone, Debug, PartialEq)]
struct FrameStamp {
    index: usize,
    written: Option<Written>,
}

impl FrameStamp {
    fn of(index: usize, file: &Path) -> Self {
        Self { index, written: written(file) }
    }
}

/// How many frames' responses the server keeps.
const KEPT_FRAMES: usize = 2;

/// The EXR files of `dir` that hold transfer layers, sorted by name, but those in `listed`.
fn frames_in(dir: &Path, listed: &[PathBuf]) -> std::io::Result<Vec<PathBuf>> {
    let listed: std::collections::HashSet<&PathBuf> = listed.iter().collect();
    let mut frames: Vec<PathBuf> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr")))
        .filter(|p| !listed.contains(p))
        .filter(|p| has_transfer(p))
        .collect();
    frames.sort();
    Ok(frames)
}

/// Whether `file`'s header says it holds transfer layers.
fn has_transfer(file: &Path) -> bool {
    exr::meta::MetaData::read_from_file(file, false).is_ok_and(|meta| crate::transfer::holds_transfer(&meta))
}

/// The Cycles render of the frame, the first of [`cycles_candidates`] of its size; where
/// one is there but cannot be shown, why (the page says it).
fn cycles_render(file: &Path, frame: &TransferFrame) -> (Option<Vec<[f32; 3]>>, Option<String>) {
    let mut unused = None;
    for candidate in cycles_candidates(file, frame) {
        if !candidate.exists() {
            continue;
        }
        let why = match crate::compare::read_rgb(&candidate) {
            Ok((w, h, rgb)) if (w, h) == (frame.width, frame.height) => return (Some(rgb), None),
            Ok((w, h, _)) => format!("{} is {w}x{h}, the frame {}x{}", candidate.display(), frame.width, frame.height),
            Err(e) => format!("{} has no RGB image to show ({e})", candidate.display()),
        };
        unused.get_or_insert(format!("no wipe against Cycles: {why}"));
    }
    (None, unused)
}

/// Where the Cycles render of `frame` (read from `file`) is looked for, in order:
/// `cycles.NNNN.exr` beside the frame, then in the scene directory it was rendered from;
/// never the frame itself (a frame with transfer layers written under that name is a
/// frame, not its own wipe).
fn cycles_candidates(file: &Path, frame: &TransferFrame) -> Vec<PathBuf> {
    let name = format!("cycles.{:04}.exr", frame.header.frame);
    let itself = |candidate: &PathBuf| match (candidate.canonicalize(), file.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => candidate == file,
    };
    let beside = file.parent().map(|d| d.join(&name));
    beside.into_iter().chain([frame.header.scene.join(&name)]).filter(|candidate| !itself(candidate)).collect()
}

/// The largest frame the page is sent whole: a larger one is sent as every `stride`-th
/// pixel of every `stride`-th row, `stride` the smallest that fits (a 3840x2160 frame's
/// layers are about 1.7 GB in full, 0.4 GB so).
const PREVIEW_SIZE: [usize; 2] = [1920, 1080];

/// The pixels of a `width` x `height` frame a preview within `size` shows, row by row; its
/// size; its stride.
fn preview_pixels(width: usize, height: usize, size: [usize; 2]) -> (Vec<usize>, [usize; 2], usize) {
    let stride = width.div_ceil(size[0]).max(height.div_ceil(size[1])).max(1);
    let shown = [width.div_ceil(stride), height.div_ceil(stride)];
    let pixels = (0..shown[1]).flat_map(|y| (0..shown[0]).map(move |x| y * stride * width + x * stride)).collect();
    (pixels, shown, stride)
}

/// `values` (`components` per pixel) at `pixels`.
fn at_pixels<'a>(pixels: &'a [usize], values: &'a [f32], components: usize) -> impl Iterator<Item = f32> + 'a {
    pixels.iter().flat_map(move |&i| values[i * components..(i + 1) * components].iter().copied())
}

/// `values` appended to `bytes` as little-endian f32s, as the page reads them (a
/// `Float32Array`): their own bytes on a little-endian processor, copied whole rather
/// than a value at a time.
fn put_f32s(bytes: &mut Vec<u8>, values: &[f32]) {
    if cfg!(target_endian = "little") {
        bytes.extend_from_slice(bytemuck::cast_slice(values));
    } else {
        bytes.extend(values.iter().flat_map(|v| v.to_le_bytes()));
    }
}

/// What the page is told of a frame's sharp lights beside its layers.
#[derive(Clone, Copy, Default)]
struct SharpShown<'a> {
    /// Why the server cannot turn the frame's Sun lamps, where it cannot.
    lamps_kept: Option<&'a str>,
    /// The light of the suns taken out of the map (diffuse, specular) at the shown
    /// pixels, where the server shades them.
    suns: Option<&'a [Vec<[f32; 3]>; 2]>,
    /// Why the light holds its map's suns in SH, where it holds some.
    suns_held: Option<&'a str>,
}

/// The page's bodies of `frame`, within `size` ([`PREVIEW_SIZE`]), under `light`; with
/// what `sharp` says of its sharp lights.
fn frame_bodies(
    file: &Path,
    frame: &TransferFrame,
    light: &RelightLight,
    view: &ViewTransform,
    size: [usize; 2],
    sharp: SharpShown,
    view_standard: Option<String>,
) -> FrameBodies {
    let (shown, [width, height], stride) = preview_pixels(frame.width, frame.height, size);
    // The render's bounce light, which a relight keeps as rendered.
    let indirect = frame.bounce.as_ref().map(IndirectParts::total);
    // A layer at the shown pixels: itself where they are all of them, in order.
    let at_shown = |values, components| match stride {
        1 => Cow::Borrowed(values),
        _ => Cow::Owned(at_pixels(&shown, values, components).collect()),
    };
    let mut pixels = Vec::new();
    let mut layout = Vec::new();
    // A layer of the shown pixels, appended with its place in the layout.
    let mut put = |name: &str, components: usize, values: &[f32]| {
        let start = pixels.len() / 4;
        put_f32s(&mut pixels, values);
        layout.push(serde_json::json!({"name": name, "components": components, "offset": start}));
    };
    let count = frame.count();
    put("diffuse", count, &at_shown(&frame.diffuse, count));
    put("unoccluded", count, &at_shown(&frame.unoccluded, count));
    if let Some(specular) = &frame.specular {
        put("specular", count, &at_shown(specular, count));
    }
    for (name, values) in [
        ("albedo", &frame.albedo),
        ("specular_colour", &frame.specular_colour),
        ("lamps_diffuse", &frame.lamps_diffuse),
        ("lamps_specular", &frame.lamps_specular),
        ("glossy_direction", &frame.glossy_direction),
    ] {
        put(name, 3, &at_shown(values.as_flattened(), 3));
    }
    // The open receiver's light at each pixel's normal under the frame's own light, and
    // the normal, which the page turns with the light.
    if let Some(normals) = frame.diffuse_normal.as_ref().filter(|_| light.corrects_diffuse()) {
        let normals = at_shown(normals.as_flattened(), 3);
        let order = frame.order();
        let open: Vec<f32> = normals
            .par_chunks(3)
            .flat_map_iter(|n| {
                let n = [n[0], n[1], n[2]].map(f64::from);
                light.open_diffuse_at(order, n).unwrap_or_default().into_iter().flatten()
            })
            .collect();
        put("diffuse_normal", 3, &normals);
        put("open_diffuse_light", 6, &open);
    }
    if let Some(indirect) = &indirect {
        put("indirect", 3, &at_shown(indirect.as_flattened(), 3));
    }
    put("glossy_lobe", 1, &at_shown(&frame.glossy_lobe, 1));
    put("glossy_weight", 2, &at_shown(frame.glossy_weight.as_flattened(), 2));
    put("alpha", 1, &at_shown(&frame.alpha, 1));
    // The map's suns, shaded at the shown pixels already.
    if let Some([diffuse, specular]) = sharp.suns {
        put("suns_diffuse", 3, diffuse.as_flattened());
        put("suns_specular", 3, specular.as_flattened());
    }
    let mut maps = Vec::new();
    let mut map_layout = Vec::new();
    for map in light.sampled_maps(frame.order()) {
        map_layout.push(serde_json::json!({"width": map.width, "height": map.height, "offset": maps.len() / 4}));
        put_f32s(&mut maps, map.texels.as_flattened());
    }
    // The scene's view transform: its LUT after the maps, as one more grid.
    let lut = view.lut().map(|lut| {
        let offset = maps.len() / 4;
        put_f32s(&mut maps, lut.values.as_flattened());
        serde_json::json!({"size": lut.size, "log2_range": lut.log2_range, "offset": offset})
    });
    let (cycles, unusable_cycles) = cycles_render(file, frame);
    // Why the page has no Cycles render to compare against, where it has none.
    let no_cycles = cycles.is_none().then(|| {
        unusable_cycles.clone().unwrap_or_else(|| {
            let name = format!("cycles.{:04}.exr", frame.header.frame);
            format!("no Cycles render: no {name} beside the frame or in the scene directory it was rendered from")
        })
    });
    let cycles: Option<Vec<u8>> = cycles.as_ref().map(|rgb| {
        let mut bytes = Vec::new();
        put_f32s(&mut bytes, &at_shown(rgb.as_flattened(), 3));
        bytes
    });
    let (point_lamps, unread_lamps) = match point_lamps::point_lamp_directions(frame) {
        Ok(directions) => (directions, None),
        Err(e) => (Vec::new(), Some(format!("the scene's point lamps are not marked on the map: {e}"))),
    };
    // What the page says beside its status: why it shows what it shows.
    let notes: Vec<String> = [view_standard, unusable_cycles, unread_lamps].into_iter().flatten().collect();
    for note in &notes {
        eprintln!("view: {}: {note}", file.display());
    }
    let meta = serde_json::json!({
        "file": file.file_name().unwrap_or_default().to_string_lossy(),
        "width": width,
        "height": height,
        "source": {"width": frame.width, "height": frame.height, "stride": stride},
        "order": frame.order(),
        "light": light.sh(),
        "lobes": frame.header.lobes.len(),
        // The grids end with the open receiver's irradiance and light, by which the page
        // corrects the diffuse light as the render did.
        "open_diffuse": frame.diffuse_normal.is_some() && light.corrects_diffuse(),
        "pixels": layout,
        "maps": map_layout,
        "cycles": cycles.is_some(),
        "no_cycles": no_cycles,
        // The passes as rendered that the page can compare its own with (`rendered.bin`).
        "rendered": as_rendered::passes_in(file),
        "view": {"exposure": view.exposure, "transparent": view.transparent, "lut": lut},
        // The suns taken out of the map, shaded by the server (`suns_*` layers,
        // `sharp_lights.bin`).
        "sharp_suns": light.sharp_suns().iter().map(|sun| {
            let [azimuth, elevation] = sun.azimuth_elevation();
            serde_json::json!({"azimuth": azimuth, "elevation": elevation})
        }).collect::<Vec<_>>(),
        // The suns a render would take out of the map, which the page holds in SH, and why.
        "suns_in_sh": light.suns_in_sh().iter().map(|(sun, share)| {
            let [azimuth, elevation] = sun.azimuth_elevation();
            serde_json::json!({"azimuth": azimuth, "elevation": elevation, "share": share})
        }).collect::<Vec<_>>(),
        "suns_in_sh_why": sharp.suns_held,
        // The scene's Sun lamps, which the page asks the server for turned
        // (`sharp_lights.bin`).
        "sun_lamps": frame.header.sun_lamps.len(),
        // Their directions as rendered, azimuth and elevation in degrees.
        "sun_lamp_directions": frame.header.sun_lamps,
        "sun_lamps_kept": sharp.lamps_kept,
        // The scene's point lamps, which stay where they are as the map turns: azimuth and
        // elevation in degrees from the middle of the frame's surface.
        "point_lamp_directions": point_lamps,
        "notes": notes,
    });
    let cycles_files = cycles_candidates(file, frame).into_iter().map(|path| (path.clone(), written(&path))).collect();
    FrameBodies {
        header: frame.header.clone(),
        size: [frame.width, frame.height],
        meta: meta.to_string(),
        pixels,
        maps,
        cycles,
        cycles_files,
        sharp: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame with transfer layers written as `cycles.NNNN.exr` is not its own wipe; beside
    /// another frame of that number, it is that frame's.
    #[test]
    fn a_frame_named_as_a_cycles_render_is_not_its_own_wipe() {
        let (dir, transfer, _) = crate::transfer::relit_dunes();
        let named = dir.path().join(format!("cycles.{:04}.exr", transfer.header.frame));
        std::fs::copy(dir.path().join("transfer.exr"), &named).unwrap();
        // The scene was written into the same directory: both places are the frame.
        assert_eq!(transfer.header.scene.canonicalize().ok(), dir.path().canonicalize().ok());
        assert_eq!(cycles_candidates(&named, &transfer), Vec::<PathBuf>::new());
        let beside = cycles_candidates(&dir.path().join("transfer.exr"), &transfer);
        assert_eq!(beside.first(), Some(&named), "{beside:?}");
    }

    /// A frame larger than the preview's size is sent as every `stride`-th pixel of every
    /// `stride`-th row, each layer's values those of its pixel; one within it, whole.
    #[test]
    fn a_large_frame_is_sent_as_a_preview_of_its_pixels() {
        let (dir, transfer, light) = crate::transfer::relit_dunes();
        let file = dir.path().join("transfer.exr");
        let view = ViewTransform::default();
        let floats = |bodies: &FrameBodies| -> Vec<f32> {
            bodies.pixels.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect()
        };
        let layer = |bodies: &FrameBodies, name: &str| -> (usize, usize) {
            let meta: serde_json::Value = serde_json::from_str(&bodies.meta).unwrap();
            let entry = meta["pixels"].as_array().unwrap().iter().find(|l| l["name"] == name).unwrap().clone();
            (entry["offset"].as_u64().unwrap() as usize, entry["components"].as_u64().unwrap() as usize)
        };
        // 96x54 within 40x30: every third pixel (54 / 30 needs 2, 96 / 40 needs 3), 32x18.
        let preview = frame_bodies(&file, &transfer, &light, &view, [40, 30], SharpShown::default(), None);
        let meta: serde_json::Value = serde_json::from_str(&preview.meta).unwrap();
        assert_eq!((meta["width"].as_u64(), meta["height"].as_u64()), (Some(32), Some(18)));
        assert_eq!(meta["source"], serde_json::json!({"width": 96, "height": 54, "stride": 3}));
        let values = floats(&preview);
        let (offset, count) = layer(&preview, "diffuse");
        let mut distinct = std::collections::HashSet::new();
        for (y, x) in (0..18).flat_map(|y| (0..32).map(move |x| (y, x))) {
            let shown = &values[offset + (y * 32 + x) * count..][..count];
            let source = (3 * y) * 96 + 3 * x;
            assert_eq!(
                shown,
                &transfer.diffuse[source * count..][..count],
                "preview ({x}, {y}) is ({}, {})",
                3 * x,
                3 * y
            );
            distinct.insert(shown[0].to_bits());
        }
        assert!(distinct.len() > 100, "the frame varies from pixel to pixel: {} values", distinct.len());
        let (offset, _) = layer(&preview, "alpha");
        assert_eq!(values.len(), offset + 32 * 18, "alpha, the last layer, ends the body");
        // Within the preview's size: whole.
        let whole = frame_bodies(&file, &transfer, &light, &view, PREVIEW_SIZE, SharpShown::default(), None);
        let (offset, count) = layer(&whole, "diffuse");
        assert_eq!(&floats(&whole)[offset..offset + 96 * 54 * count], &transfer.diffuse[..]);
    }
}
