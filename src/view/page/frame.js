// ---- Sharp lights ----

// The frame's sharp lights as shown: the lamps layers, and the light of the suns taken out
// of its map (before strength), at the render's turn; turned, once the server has shaded
// them so (`sharp_lights.bin`), at the last turn it shaded: while a drag goes on, or the
// next turn is on its way, they lag the rotation by a turn of the server's.
function lampsOf(f) {
  const turned = f.turnedLamps;
  if (turned && state.rotation !== 0) return turned;
  const { lamps_diffuse, lamps_specular, suns_diffuse, suns_specular } = f.layers;
  return { diffuse: lamps_diffuse, specular: lamps_specular, sunsDiffuse: suns_diffuse, sunsSpecular: suns_specular };
}
// Whether the server turns the frame's Sun lamps, and its map's suns.
const turnsLamps = (meta) => meta.sun_lamps > 0 && !meta.sun_lamps_kept;
const turnsSuns = (meta) => meta.sharp_suns.length > 0;
// Asks the server for the frame's sharp lights turned to `rotation`, as `logsh relight`
// turns them (the scene shaded again: a sun's share of a render), and shows the frame again
// with them when they come. One turn at a time: the frame shown again then asks for the
// rotation reached meanwhile, so a drag's sharp lights follow it a turn of the server's
// behind. A turn that failed is not asked for again.
function turnSharpLights(f, rotation) {
  const { meta } = f;
  if (!(turnsLamps(meta) || turnsSuns(meta)) || rotation === 0 || f.turning !== null) return;
  if (f.turnedLamps && f.turnedLamps.rotation === rotation) return;
  if (f.lampError && f.failedAt === rotation) return;
  f.turning = rotation;
  const started = performance.now();
  fetch(`frame/${f.index}/sharp_lights.bin?rotation=${rotation}`).then(async (r) => {
    if (!r.ok) throw new Error(`${r.status} ${await r.text()}`);
    const values = new Float32Array(await r.arrayBuffer());
    const n = 3 * meta.width * meta.height;
    // The lamps' two layers where the Sun lamps turn, then the suns' two.
    const lamps = turnsLamps(meta), layers = (lamps ? 2 : 0) + (turnsSuns(meta) ? 2 : 0);
    if (values.length !== layers * n) throw new Error(`${values.length} values where ${layers * n} were due`);
    const layer = (j) => values.subarray(j * n, (j + 1) * n);
    const suns = turnsSuns(meta) ? (lamps ? 2 : 0) : -1;
    f.turnedLamps = {
      rotation,
      diffuse: lamps ? layer(0) : f.layers.lamps_diffuse, specular: lamps ? layer(1) : f.layers.lamps_specular,
      sunsDiffuse: suns >= 0 ? layer(suns) : undefined, sunsSpecular: suns >= 0 ? layer(suns + 1) : undefined,
      ms: performance.now() - started,
    };
    f.lampError = null;
  }).catch((e) => {
    f.lampError = e.message;
    f.failedAt = rotation;
  }).finally(() => {
    f.turning = null;
    if (state.frame === f) { metrics = null; schedule(); }
  });
}
// How the frame's turned sharp lights stand at the rotation shown: "now" (shaded at it),
// "failed" (turning to it failed), "behind" (shaded at an earlier turn, the next on its
// way) or "rendered" (none turned yet).
function turnedState(f) {
  const turned = f.turnedLamps;
  if (turned && turned.rotation === state.rotation) return "now";
  if (f.lampError && f.failedAt === state.rotation) return "failed";
  return turned ? "behind" : "rendered";
}
// A time the page measured, or nothing where its clock did not move (a headless
// browser's virtual time stands still while the page computes).
const took = (ms) => (ms > 0 ? ` in ${ms.toFixed(0)} ms` : "");
// What the status line says of the suns of the map: shaded sharp by the server, turned
// with the map or where the render put them until they come; or held in SH, and why.
function sunsNote(f) {
  const { meta } = f;
  const held = meta.suns_in_sh, sharp = meta.sharp_suns;
  if (held.length) {
    const shares = held.map((sun) => `${Math.round(100 * sun.share)}%`).join(" and ");
    return `; the light's ${held.length > 1 ? "suns" : "sun"} (${shares} of it) held in SH here, so soft shadows (${meta.suns_in_sh_why})`;
  }
  if (!sharp.length) return "";
  const suns = `the map's ${sharp.length > 1 ? "suns" : "sun"}`, them = sharp.length > 1 ? "them" : "it";
  if (state.rotation === 0) return `; ${suns} shaded sharp by logsh`;
  switch (turnedState(f)) {
    case "now":
      // The time once, with the Sun lamps' where they came with them.
      return `; ${suns} shaded sharp by logsh, turned with the map`
        + (turnsLamps(meta) || !(f.turnedLamps.ms > 0) ? "" : ` (shaded again${took(f.turnedLamps.ms)})`);
    case "failed": return `; ${suns} shaded sharp, not at this turn: turning ${them} failed: ${f.lampError}`;
    case "behind": return `; ${suns} shaded sharp at ${f.turnedLamps.rotation}° until shaded again at this turn`;
    default: return `; ${suns} shaded sharp where the render put ${them} until shaded again turned`;
  }
}
// What the status line says of the scene's Sun lamps, once the map is turned.
function sunLampNote(f) {
  const { meta } = f;
  if (!meta.sun_lamps || state.rotation === 0) return "";
  const one = meta.sun_lamps === 1;
  const lamps = `the scene's ${one ? "Sun lamp" : "Sun lamps"}`, stay = one ? "stays" : "stay";
  if (meta.sun_lamps_kept) return `; ${lamps} ${stay} as rendered here: ${meta.sun_lamps_kept}`;
  switch (turnedState(f)) {
    case "now": return `; ${lamps} turned with the map (shaded again by logsh${took(f.turnedLamps.ms)})`;
    case "failed": return `; ${lamps} not turned to this turn: turning ${one ? "it" : "them"} failed: ${f.lampError}`;
    case "behind": return `; ${lamps} turned to ${f.turnedLamps.rotation}° until shaded again at this turn`;
    default: return `; ${lamps} as rendered until ${one ? "it is" : "they are"} shaded again turned`;
  }
}

// ---- Showing the frame ----

// The last full relight's time, from which a drag's step is chosen (a drag's update in
// about 40 ms), or the step `?proxy=N` fixes.
let fullMs = 0;
const dragStep = Math.max(0, Math.min(8, Math.floor(Number(params.get("proxy")) || 0)));

function relight() {
  pending = false;
  const f = state.frame;
  if (!f) return;
  const started = performance.now();
  // While a slider is dragged, the frame is lit (where the light turned) and shown at one
  // pixel in `step` x `step`; once it is let go, in full.
  const step = state.dragging ? dragStep || (fullMs > 160 ? 4 : fullMs > 40 ? 2 : 1) : 1;
  const withVisibility = shownPass(f) === "visibility";
  const fresh = !lit || lit.frame !== f || lit.rotation !== state.rotation || lit.step > step
    || (withVisibility && !lit.visibility);
  if (fresh) lit = light(f, state.rotation, step, withVisibility);
  const compared = compose(f, lit, step);
  present();
  const ms = performance.now() - started;
  if (step === 1 && fresh) fullMs = ms;
  // The comparison's error, once per lit frame, pass, reference, strength and sharp
  // lights shown.
  const of = compared && { frame: f, lit, pass: compared.pass, against: compared.against, strength: state.strength, lamps: lampsOf(f).diffuse };
  const same = (a, b) => a && b && Object.keys(b).every((key) => a[key] === b[key]);
  if (compared && !same(metrics && metrics.of, of)) metrics = { of, frame: f, ...errorStats(compared.errors), against: compared.against, pass: compared.pass };
  turnSharpLights(f, state.rotation);
  drawEnvironment();
  showStatus(f, fresh, step, ms);
  if (inspected) showInspector();
  document.title = "logsh view: ready";
}

// The status line: the frame, its size, what was relit and in how long as the page's
// clock measured it (nothing where nothing was relit, no time where the clock did not
// move), what the view shows, the sharp lights; then the comparison's error, and why
// controls are hidden.
function showStatus(f, fresh, step, ms) {
  const { meta } = f;
  const source = meta.source;
  const size = source.stride > 1
    ? `${source.width} x ${source.height} shown at 1/${source.stride} (${meta.width} x ${meta.height}; logsh relight gives it whole)`
    : `${meta.width} x ${meta.height}`;
  const how = fresh ? `, relit${step > 1 ? ` at 1/${step} resolution` : ""}${ms > 0 ? ` in ${ms.toFixed(1)} ms` : ""}` : "";
  const ref = reference(f);
  const against = state.view.endsWith("-cycles") ? "the Cycles render" : `the ${shownPass(f)} as rendered`;
  const unread = state.view.endsWith("-rendered") && (f.rendered[shownPass(f)] || {}).error;
  const view = unread ? `, ${against} cannot be read: ${unread}`
    : !ref ? (state.view === "relit" ? "" : `, ${against} on its way`)
    : state.view.startsWith("wipe-") ? `, ${against} right of the wipe`
    : `, ${state.diff === "signed" ? "signed" : "absolute"} difference from ${against}`;
  const status = $("status");
  status.textContent = `${meta.file}: ${size}, order ${meta.order}${how}${view}` + sunsNote(f) + sunLampNote(f);
  if (fresh && ms > 0) status.dataset.relightMs = ms.toFixed(2); else delete status.dataset.relightMs;
  status.dataset.frame = meta.file;
  // A turn of the sharp lights on its way: the status line will change when it comes.
  if (f.turning !== null) status.dataset.turning = String(f.turning); else delete status.dataset.turning;
  const line = $("metrics");
  if (ref && metrics && metrics.frame === f) {
    line.hidden = false;
    line.textContent = `relit ${metrics.pass} − ${metrics.against === "Cycles" ? "Cycles" : "as rendered"}, over ${metrics.pixels} pixels`
      + ` (linear, the mean of |R|, |G|, |B|): mean ${digits(metrics.mean)}, p95 ${digits(metrics.p95)}`
      + (step > 1 ? " (at the drag's last full relight)" : "");
    line.dataset.mean = String(metrics.mean);
    line.dataset.p95 = String(metrics.p95);
  } else {
    line.hidden = !(state.view !== "relit");
    line.textContent = state.view === "relit" ? "" : "no error yet: the reference is on its way";
    delete line.dataset.mean;
    delete line.dataset.p95;
  }
  const hiddenWhy = targets(f).why;
  const notes = [...hiddenWhy, ...meta.notes.filter((n) => n !== meta.no_cycles)];
  $("notes").hidden = !notes.length;
  $("notes").textContent = notes.join("; ");
}

// Which controls have something to act on in frame `f`, which are hidden, and why.
function targets(f) {
  const { meta } = f;
  const rendered = meta.rendered || [];
  const frames = frameNames.length;
  const why = [];
  const has = {
    frames: frames > 1,
    cycles: !!f.cycles,
    rendered: rendered.includes(state.pass),
    indirect: !!f.layers.indirect,
  };
  if (!has.frames) why.push("one frame in the directory: no frame slider");
  if (!has.cycles) why.push(`${meta.no_cycles || "no Cycles render"}: no wipe or difference against Cycles`);
  if (!has.rendered) why.push(`the frame's file holds no ${state.pass} as rendered: no comparison with it`);
  if (!has.indirect) why.push("no bounce light rendered: no indirect pass");
  return { has, why };
}

// Shows the controls that have something to act on and hides the others.
function showControls(f) {
  const { has } = targets(f);
  $("frame-control").hidden = !has.frames;
  const views = { relit: true, "wipe-rendered": has.rendered, "diff-rendered": has.rendered, "wipe-cycles": has.cycles, "diff-cycles": has.cycles };
  for (const option of $("view").options) { option.hidden = option.disabled = !views[option.value]; }
  if (!views[state.view]) state.view = "relit";
  $("view").value = state.view;
  $("view-control").hidden = !Object.entries(views).some(([view, shown]) => view !== "relit" && shown);
  for (const option of $("pass").options) {
    const shown = option.value !== "indirect" || has.indirect;
    option.hidden = option.disabled = !shown;
  }
  if (state.pass === "indirect" && !has.indirect) state.pass = "beauty";
  // Cycles renders the beauty alone.
  $("pass").disabled = state.view.endsWith("-cycles");
  $("pass").title = $("pass").disabled ? "Cycles renders the beauty only: the beauty is compared" : "";
  $("pass").value = shownPass(f);
  $("wipe-control").hidden = !state.view.startsWith("wipe-");
  $("diff-control").hidden = !state.view.startsWith("diff-");
}

function schedule() {
  if (!pending) { pending = true; requestAnimationFrame(relight); }
}

// ---- The address: the view's state, kept for a colleague to open ----

let rememberTimer = null;
// Writes the state into the address (history.replaceState, at most every 200 ms: browsers
// throttle more).
function remember() {
  if (rememberTimer !== null || params.has("bench")) return;
  rememberTimer = setTimeout(() => {
    rememberTimer = null;
    const kept = new URLSearchParams();
    const put = (key, value, fallback) => { if (value !== fallback) kept.set(key, value); };
    put("frame", String(state.index), "0");
    put("pass", state.pass, "beauty");
    put("view", state.view, "relit");
    put("diff", state.diff, "abs");
    if (state.view.startsWith("wipe-")) put("wipe", String(state.wipe), "0.5");
    put("rotation", String(state.rotation), "0");
    put("strength", String(state.strength), "1");
    put("exposure", String(state.exposure), "0");
    if (state.zoom !== null) {
      kept.set("zoom", String(Math.round(state.zoom * 1e4) / 1e4));
      if (state.center) kept.set("center", state.center.map((v) => Math.round(v * 10) / 10).join(","));
    }
    if (state.inspect) kept.set("inspect", state.inspect.join(","));
    for (const key of ["proxy", "dragging"]) if (params.has(key)) kept.set(key, params.get(key));
    // Commas kept as they are, the pairs readable.
    const query = kept.toString().replace(/%2C/g, ",");
    history.replaceState(null, "", query ? `?${query}` : location.pathname);
    $("share").href = location.href;
  }, 200);
}

// A turn of any angle, in the slider's range.
const wrapDegrees = (v) => ((((v + 180) % 360) + 360) % 360) - 180;
// The sliders of the light: `input` while one moves (a drag: the frame at a coarser
// step), `change` once it is let go.
const formats = {
  rotation: (v) => `${v}°`, strength: (v) => `${v.toFixed(2)}x`, exposure: (v) => `${v.toFixed(1)} EV`,
  wipe: (v) => `${Math.round(100 * v)} %`,
};
function bind(key) {
  const input = $(key);
  const update = (dragging) => {
    state[key] = Number(input.value);
    state.dragging = dragging;
    $(`${key}-value`).textContent = formats[key](state[key]);
    schedule();
    remember();
  };
  input.addEventListener("input", () => update(true));
  input.addEventListener("change", () => update(false));
}
// Sets a slider's value (clamped and stepped by the input) and shows it.
function setSlider(key, value, dragging = false) {
  const input = $(key);
  input.value = key === "rotation" ? wrapDegrees(value) : value;
  state[key] = Number(input.value);
  state.dragging = dragging;
  $(`${key}-value`).textContent = formats[key](state[key]);
  schedule();
  remember();
}

// ---- The sequence ----

let frameNames = [];
let loading = null;
// Shows frame `index`, its layers asked for now (the server builds them on the first
// request); the frame shown stays until they come.
async function showFrame(index) {
  index = Math.max(0, Math.min(frameNames.length - 1, index));
  state.index = index;
  $("frame-index").value = index;
  $("frame-name").textContent = frameNames[index] || "";
  remember();
  const asked = loading = index;
  $("status").textContent = `loading ${frameNames[index]}`;
  const f = await loadFrame(index);
  if (asked !== loading) return;
  state.frame = f;
  metrics = null;
  showControls(f);
  // The reference the view compares against, with the frame.
  if (state.view.endsWith("-rendered")) await fetchRendered(f, state.pass);
  if (inspected) inspect(inspected.x, inspected.y, inspected.pinned);
  relight();
}
let frameTimer = null;
// A frame asked for while the slider moves, once it rests for 150 ms.
let loadingFrame = null;
function askFrame(index, now) {
  clearTimeout(frameTimer);
  $("frame-index").value = index;
  $("frame-name").textContent = frameNames[index] || "";
  const go = () => (loadingFrame = showFrame(index).catch(fail));
  if (now) go(); else frameTimer = setTimeout(go, 150);
}

