// ---- Keys and the pointer ----

const PASS_KEYS = { p: 1, P: -1 }, VIEW_KEYS = { v: 1, V: -1 };
// The next of `options` (a select's shown ones) after `value`, `by` steps on.
function cycle(select, by) {
  const shown = [...select.options].filter((o) => !o.hidden && !o.disabled).map((o) => o.value);
  if (!shown.length) return null;
  const at = shown.indexOf(select.value);
  return shown[(at + by + shown.length) % shown.length];
}
function onKey(e) {
  if (e.ctrlKey || e.metaKey || e.altKey) return;
  const target = e.target;
  // Sliders and lists take their own keys.
  if (target.tagName === "INPUT" || target.tagName === "SELECT") return;
  const f = state.frame, key = e.key;
  const done = () => e.preventDefault();
  const pinnedMove = { h: [-1, 0], j: [0, 1], k: [0, -1], l: [1, 0], H: [-10, 0], J: [0, 10], K: [0, -10], L: [10, 0] }[key];
  const g = geometry(), pan = Math.round(Math.min(g.width, g.height) / 8);
  if (key === "?") { toggleHelp(); return done(); }
  if (key === "Escape") { $("help").hidden = true; if (inspected) unpin(); return done(); }
  if (!f) return;
  if (e.shiftKey && key.startsWith("Arrow")) {
    const [dx, dy] = { ArrowLeft: [pan, 0], ArrowRight: [-pan, 0], ArrowUp: [0, pan], ArrowDown: [0, -pan] }[key];
    panBy(dx, dy);
    return done();
  }
  switch (key) {
    case "ArrowLeft": askFrame(Math.max(0, state.index - 1), true); return done();
    case "ArrowRight": askFrame(Math.min(frameNames.length - 1, state.index + 1), true); return done();
    case "Home": askFrame(0, true); return done();
    case "End": askFrame(frameNames.length - 1, true); return done();
    case "+": case "=": zoomTo(g.zoom * 2); return done();
    case "-": case "_": zoomTo(g.zoom / 2); return done();
    case "1": zoomTo(1); return done();
    case "0": case "f": fitWindow(); return done();
    case "[": setSlider("rotation", state.rotation - 5); return done();
    case "]": setSlider("rotation", state.rotation + 5); return done();
    case "{": setSlider("rotation", state.rotation - 45); return done();
    case "}": setSlider("rotation", state.rotation + 45); return done();
    case "s": setSlider("strength", Math.round(10 * state.strength - 1) / 10); return done();
    case "S": setSlider("strength", Math.round(10 * state.strength + 1) / 10); return done();
    case "e": setSlider("exposure", Math.round(2 * state.exposure - 1) / 2); return done();
    case "E": setSlider("exposure", Math.round(2 * state.exposure + 1) / 2); return done();
    case "r": setSlider("rotation", 0); setSlider("strength", 1); setSlider("exposure", 0); return done();
    case ",": if (!$("wipe-control").hidden) setSlider("wipe", Math.max(0, state.wipe - 0.05)); return done();
    case ".": if (!$("wipe-control").hidden) setSlider("wipe", Math.min(1, state.wipe + 0.05)); return done();
    case "d": if (!$("diff-control").hidden) choose("diff", state.diff === "abs" ? "signed" : "abs"); return done();
    case "i": {
      if (inspected && inspected.pinned) { unpin(); return done(); }
      const at = (lastPointer && pixelAt(lastPointer[0], lastPointer[1])) || centrePixel();
      if (at) inspect(at[0], at[1], true);
      return done();
    }
  }
  if (key in PASS_KEYS && !$("pass").disabled) { const next = cycle($("pass"), PASS_KEYS[key]); if (next) choose("pass", next); return done(); }
  if (key in VIEW_KEYS && !$("view-control").hidden) { const next = cycle($("view"), VIEW_KEYS[key]); if (next) choose("view", next); return done(); }
  if (pinnedMove && inspected && inspected.pinned) {
    const stride = f.meta.source.stride, source = f.meta.source;
    const x = Math.max(0, Math.min(source.width - 1, inspected.x + pinnedMove[0] * stride));
    const y = Math.max(0, Math.min(source.height - 1, inspected.y + pinnedMove[1] * stride));
    inspect(Math.floor(x / stride) * stride, Math.floor(y / stride) * stride, true);
    return done();
  }
}
// The frame's pixel at the middle of the window.
function centrePixel() {
  const bounds = $("frame").getBoundingClientRect();
  return pixelAt(bounds.left + bounds.width / 2, bounds.top + bounds.height / 2);
}
// Sets one of the lists (pass, view, diff).
function choose(key, value) {
  state[key] = value;
  $(key).value = value;
  if (state.frame) showControls(state.frame);
  schedule();
  remember();
}
function toggleHelp() { $("help").hidden = !$("help").hidden; }

let lastPointer = null;
// Drag pans the frame (or moves the wipe, from its line or with Shift); a click without
// a drag pins the inspector at the pixel, or unpins it there; the wheel zooms about the
// cursor; moving over the frame inspects the pixel under the cursor unless one is pinned.
function bindPointer() {
  const viewport = $("viewport"), canvas = $("frame");
  let drag = null;
  const device = (e) => {
    const bounds = canvas.getBoundingClientRect(), dpr = window.devicePixelRatio || 1;
    return [(e.clientX - bounds.left) * dpr, (e.clientY - bounds.top) * dpr];
  };
  viewport.addEventListener("pointerdown", (e) => {
    if (e.button !== 0 || !state.frame) return;
    viewport.focus({ preventScroll: true });
    const [px] = device(e), g = geometry(), f = state.frame;
    const wipeX = g.left + state.wipe * f.meta.width * g.zoom * g.source.stride;
    const onWipe = !$("wipe-control").hidden && (e.shiftKey || Math.abs(px - wipeX) < 6 * (window.devicePixelRatio || 1));
    drag = { start: device(e), moved: false, wipe: onWipe, geometry: g };
    viewport.setPointerCapture(e.pointerId);
  });
  viewport.addEventListener("pointermove", (e) => {
    lastPointer = [e.clientX, e.clientY];
    if (drag) {
      const [px, py] = device(e);
      const dx = px - drag.start[0], dy = py - drag.start[1];
      if (!drag.moved && Math.hypot(dx, dy) < 4) return;
      drag.moved = true;
      if (drag.wipe) {
        const g = drag.geometry, width = state.frame.meta.width * g.zoom * g.source.stride;
        setSlider("wipe", Math.min(1, Math.max(0, (px - g.left) / width)));
        return;
      }
      viewport.classList.add("panning");
      const g = drag.geometry;
      const [cx, cy] = state.zoom !== null && state.center && drag.center ? drag.center : [(g.width / 2 - g.left) / g.zoom, (g.height / 2 - g.top) / g.zoom];
      drag.center = drag.center || [cx, cy];
      state.zoom = g.zoom;
      state.center = [drag.center[0] - dx / g.zoom, drag.center[1] - dy / g.zoom];
      present();
      remember();
      return;
    }
    if (inspected && inspected.pinned) return;
    const at = pixelAt(e.clientX, e.clientY);
    if (at) inspect(at[0], at[1], false);
    else if (inspected) { inspected = null; showInspector(); present(); }
  });
  const end = (e) => {
    if (!drag) return;
    viewport.classList.remove("panning");
    if (!drag.moved && e.type === "pointerup") {
      const at = pixelAt(e.clientX, e.clientY);
      if (at && inspected && inspected.pinned && inspected.x === at[0] && inspected.y === at[1]) unpin();
      else if (at) inspect(at[0], at[1], true);
    }
    drag = null;
  };
  viewport.addEventListener("pointerup", end);
  viewport.addEventListener("pointercancel", end);
  viewport.addEventListener("pointerleave", () => {
    lastPointer = null;
    if (inspected && !inspected.pinned && !drag) { inspected = null; showInspector(); present(); }
  });
  viewport.addEventListener("wheel", (e) => {
    if (!state.frame) return;
    e.preventDefault();
    const lines = e.deltaMode === 1 ? 16 : e.deltaMode === 2 ? 400 : 1;
    zoomTo(geometry().zoom * Math.pow(2, (-e.deltaY * lines) / 400), device(e));
  }, { passive: false });

  // The environment: a drag across it turns the light (its width a whole turn), the
  // arrows turn it by 5° (Shift: 45°) while it has the focus.
  const environment = $("environment");
  let turning = null;
  environment.addEventListener("pointerdown", (e) => {
    if (e.button !== 0) return;
    turning = { x: e.clientX, rotation: state.rotation };
    environment.setPointerCapture(e.pointerId);
  });
  environment.addEventListener("pointermove", (e) => {
    if (!turning) return;
    const turn = Math.round(turning.rotation - (360 * (e.clientX - turning.x)) / environment.clientWidth);
    if (wrapDegrees(turn) !== state.rotation) setSlider("rotation", turn, true);
  });
  const let_go = () => { if (turning) { turning = null; setSlider("rotation", state.rotation, false); } };
  environment.addEventListener("pointerup", let_go);
  environment.addEventListener("pointercancel", let_go);
  environment.addEventListener("keydown", (e) => {
    const by = e.shiftKey ? 45 : 5;
    if (e.key === "ArrowLeft" || e.key === "ArrowDown") setSlider("rotation", state.rotation - by);
    else if (e.key === "ArrowRight" || e.key === "ArrowUp") setSlider("rotation", state.rotation + by);
    else return;
    e.preventDefault();
    e.stopPropagation();
  });
}

// ---- The state from the address ----

// The page's first state from its address (module doc of src/view/mod.rs).
function readAddress() {
  const number = (key, fallback) => (params.has(key) && Number.isFinite(Number(params.get(key))) ? Number(params.get(key)) : fallback);
  const pair = (key) => {
    const v = (params.get(key) || "").split(",").map(Number);
    return v.length === 2 && v.every(Number.isFinite) ? v : null;
  };
  for (const key of ["rotation", "strength", "exposure", "wipe"]) {
    const input = $(key);
    if (params.has(key)) input.value = key === "rotation" ? wrapDegrees(number(key, 0)) : params.get(key);
    state[key] = Number(input.value);
    $(`${key}-value`).textContent = formats[key](state[key]);
  }
  state.index = Math.max(0, Math.floor(number("frame", 0)));
  if (PASSES.includes(params.get("pass"))) state.pass = params.get("pass");
  if (VIEWS.includes(params.get("view"))) state.view = params.get("view");
  // An address from before the view list: a wipe alone is the wipe against Cycles.
  else if (params.has("wipe")) state.view = "wipe-cycles";
  if (params.get("diff") === "signed") state.diff = "signed";
  const zoom = number("zoom", NaN);
  if (zoom > 0) { state.zoom = Math.min(64, Math.max(1 / 64, zoom)); state.center = pair("center"); }
  state.inspect = pair("inspect");
  // `?dragging=1`: the frame as while the rotation is held (a test of a drag's view).
  state.dragging = params.get("dragging") === "1";
  $("diff").value = state.diff;
}

async function main() {
  readAddress();
  for (const key of ["rotation", "strength", "exposure", "wipe"]) bind(key);
  for (const key of ["pass", "view", "diff"]) $(key).addEventListener("change", () => choose(key, $(key).value));
  $("zoom-fit").addEventListener("click", fitWindow);
  $("zoom-one").addEventListener("click", () => zoomTo(1));
  $("zoom-in").addEventListener("click", () => zoomTo(geometry().zoom * 2));
  $("zoom-out").addEventListener("click", () => zoomTo(geometry().zoom / 2));
  $("help-button").addEventListener("click", toggleHelp);
  document.addEventListener("keydown", onKey);
  bindPointer();
  // The window's size in device pixels as the browser lays it out, where it says.
  const observer = new ResizeObserver((entries) => {
    const box = entries[0].devicePixelContentBoxSize && entries[0].devicePixelContentBoxSize[0];
    resize(box ? [box.inlineSize, box.blockSize] : null);
  });
  observer.observe($("viewport"));
  // A window moved to a screen of another density.
  const watchDensity = () => matchMedia(`(resolution: ${window.devicePixelRatio}dppx)`).addEventListener("change", () => { resize(); watchDensity(); }, { once: true });
  watchDensity();
  resize();

  frameNames = await (await get("frames.json")).json();
  const slider = $("frame-index");
  slider.max = Math.max(0, frameNames.length - 1);
  slider.addEventListener("input", () => askFrame(Number(slider.value), false));
  slider.addEventListener("change", () => askFrame(Number(slider.value), true));
  // Frames written since the page loaded (a sequence still rendering) come at the end of
  // the server's list, each keeping its index: asked for again as the slider takes the
  // focus. A list that cannot be had again (the server stopped) stays as it was.
  slider.addEventListener("focus", () => fetch("frames.json").then((r) => r.json()).then((now) => {
    frameNames = now;
    slider.max = Math.max(0, now.length - 1);
    if (state.frame) showControls(state.frame);
  }).catch(() => {}));
  await showFrame(Math.min(state.index, frameNames.length - 1));
  if (state.inspect) {
    // A pixel of the frame, and one the preview shows.
    const { width, height, stride } = state.frame.meta.source;
    const [x, y] = state.inspect.map((v) => Math.floor(v / stride) * stride);
    if (x >= 0 && y >= 0 && x < width && y < height) inspect(x, y, true); else state.inspect = null;
    if (pixelRequest) await pixelRequest;
  }
  remember();
  // ?keys=K,K,...: those keys pressed once the frame is shown, each a KeyboardEvent key
  // name, with "Shift+" before it where held (a view scripted: the keys' tests).
  for (const name of (params.get("keys") || "").split(",").filter(Boolean)) {
    const shift = name.startsWith("Shift+"), key = shift ? name.slice(6) : name;
    $("viewport").dispatchEvent(new KeyboardEvent("keydown", { key, shiftKey: shift, bubbles: true }));
    // What a key asked for (a frame, the pass as rendered, a pixel's values) comes
    // before the next key.
    if (loadingFrame) await loadingFrame;
    if (state.view.endsWith("-rendered")) await fetchRendered(state.frame, shownPass(state.frame));
    if (pixelRequest) await pixelRequest;
  }
  // ?bench=N: relight N times at as many rotations and let the server time it by its own
  // clock (a headless browser's virtual time stands still while the page computes), the
  // page's own clock beside it. Then N drags of the rotation (at the step a drag takes)
  // and N of the strength (no relight: the lit values recombined). First, where the
  // page's clock moves (not under virtual time), N drags of the rotation shown one per
  // frame of the browser's (requestAnimationFrame): the rate a drag is seen at.
  const runs = Number(params.get("bench") || 0);
  if (runs > 0 && fullMs > 0) {
    await fetch("bench/start");
    const shown = await new Promise((resolve) => {
      let k = 0, first = 0;
      const next = (now) => {
        if (k === 0) first = now;
        state.dragging = true;
        state.rotation = (360 * k) / runs - 178;
        relight();
        if (++k < runs) requestAnimationFrame(next); else resolve(performance.now() - first);
      };
      requestAnimationFrame(next);
    });
    await fetch(`bench/end?runs=${runs}&what=shown&page_ms=${shown.toFixed(1)}`);
  }
  if (runs > 0) {
    const timed = async (what, change) => {
      await fetch("bench/start");
      const started = performance.now();
      for (let k = 0; k < runs; k++) { change(k); relight(); }
      const ms = performance.now() - started;
      await fetch(`bench/end?runs=${runs}&what=${what}&page_ms=${ms.toFixed(1)}`);
    };
    await timed("turns", (k) => { state.dragging = false; state.rotation = (360 * k) / runs - 180; });
    await timed("dragged", (k) => { state.dragging = true; state.rotation = (360 * k) / runs - 179; });
    await timed("strength", (k) => { state.dragging = true; state.strength = 0.5 + k / runs; });
    state.dragging = false;
    relight();
    document.title = "logsh view: benchmarked";
  }
}

function fail(e) {
  $("status").textContent = "error: " + e.message;
  document.title = "logsh view: error";
}

main().catch(fail);
