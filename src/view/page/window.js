// ---- The window: the frame drawn at its zoom and pan, for the device's pixels ----

// The frame's place in the window, in device pixels: its zoom (device pixels per frame
// pixel), the window's size, and where the frame's top-left corner falls, whole pixels,
// so that a whole zoom shows every frame pixel as a square of the same size.
function geometry() {
  const canvas = $("frame");
  const f = state.frame;
  const width = canvas.width, height = canvas.height;
  const source = f ? f.meta.source : { width: 1, height: 1, stride: 1 };
  const fit = Math.min(width / source.width, height / source.height);
  const zoom = state.zoom ?? fit;
  const [cx, cy] = state.zoom !== null && state.center ? state.center : [source.width / 2, source.height / 2];
  return {
    zoom, fit, width, height, source,
    left: Math.round(width / 2 - cx * zoom), top: Math.round(height / 2 - cy * zoom),
  };
}

// The frame's pixel under the window's point (client coordinates), as a pixel of the
// frame itself: the one the preview shows there (every `stride`-th of a frame larger
// than 1920x1080). `null` outside the frame.
function pixelAt(clientX, clientY) {
  const f = state.frame;
  if (!f) return null;
  const g = geometry(), bounds = $("frame").getBoundingClientRect(), dpr = window.devicePixelRatio || 1;
  const sx = ((clientX - bounds.left) * dpr - g.left) / g.zoom, sy = ((clientY - bounds.top) * dpr - g.top) / g.zoom;
  if (!(sx >= 0 && sy >= 0 && sx < g.source.width && sy < g.source.height)) return null;
  const stride = g.source.stride;
  return [Math.floor(sx / stride) * stride, Math.floor(sy / stride) * stride];
}

// Sizes the frame's canvas to the window's device pixels (high-DPI screens, zoomed
// pages, a window resized or moved to another screen) and draws it again.
function resize(devicePixels) {
  const canvas = $("frame"), viewport = $("viewport"), dpr = window.devicePixelRatio || 1;
  const [width, height] = devicePixels || [Math.round(viewport.clientWidth * dpr), Math.round(viewport.clientHeight * dpr)];
  if (canvas.width !== width || canvas.height !== height) { canvas.width = width; canvas.height = height; }
  sizeEnvironment();
  present();
}

// Draws the composed image into the window at the zoom and pan: pixels as squares where
// magnified (no smoothing), filtered where shrunk; then the wipe's line and the pixel the
// inspector shows.
function present() {
  const canvas = $("frame");
  const context = canvas.getContext("2d");
  context.setTransform(1, 0, 0, 1, 0, 0);
  context.clearRect(0, 0, canvas.width, canvas.height);
  const f = state.frame;
  if (f && composed) {
    const g = geometry(), scale = g.zoom * g.source.stride;
    context.imageSmoothingEnabled = scale < 1;
    context.imageSmoothingQuality = "high";
    // Each composed pixel over its `step` x `step` block of the preview; the last
    // column's and row's blocks cut at the frame's edge.
    const step = composed.step;
    context.drawImage(imageCanvas, 0, 0, f.meta.width / step, f.meta.height / step, g.left, g.top, f.meta.width * scale, f.meta.height * scale);
    if (state.view.startsWith("wipe-") && reference(f)) {
      const x = g.left + Math.round(state.wipe * f.meta.width) * scale;
      context.fillStyle = "#ff0";
      context.fillRect(Math.round(x), g.top, Math.max(1, Math.round(window.devicePixelRatio || 1)), f.meta.height * scale);
    }
    const shown = inspected && (inspected.pinned || inspected.hover) ? inspected : null;
    if (shown) {
      const x = g.left + shown.x * g.zoom, y = g.top + shown.y * g.zoom, size = Math.max(scale, 1);
      context.lineWidth = Math.max(1, Math.round(window.devicePixelRatio || 1));
      context.strokeStyle = shown.pinned ? "#f4f" : "rgba(255, 255, 255, 0.7)";
      if (size >= 6) {
        context.strokeRect(x - 0.5 * context.lineWidth, y - 0.5 * context.lineWidth, size + context.lineWidth, size + context.lineWidth);
      } else {
        const c = 8 * context.lineWidth;
        context.beginPath();
        context.moveTo(x + size / 2 - c, y + size / 2); context.lineTo(x + size / 2 - 3, y + size / 2);
        context.moveTo(x + size / 2 + 3, y + size / 2); context.lineTo(x + size / 2 + c, y + size / 2);
        context.moveTo(x + size / 2, y + size / 2 - c); context.lineTo(x + size / 2, y + size / 2 - 3);
        context.moveTo(x + size / 2, y + size / 2 + 3); context.lineTo(x + size / 2, y + size / 2 + c);
        context.stroke();
      }
    }
    const percent = Math.round(100 * g.zoom * 10) / 10;
    $("zoom-value").textContent = `${percent} %${state.zoom === null ? " (fit)" : ""}`;
    $("frame").dataset.zoom = String(g.zoom);
  }
}

// Sets the zoom about a point of the window (device pixels from its top-left corner;
// its middle by default), which keeps the frame's point under it.
function zoomTo(zoom, about) {
  const g = geometry();
  zoom = Math.min(64, Math.max(1 / 64, zoom));
  const [px, py] = about || [g.width / 2, g.height / 2];
  const sx = (px - g.left) / g.zoom, sy = (py - g.top) / g.zoom;
  state.zoom = zoom;
  state.center = [(g.width / 2 - px) / zoom + sx, (g.height / 2 - py) / zoom + sy];
  present();
  remember();
}
function fitWindow() { state.zoom = null; state.center = null; present(); remember(); }
// Pans by (dx, dy) device pixels.
function panBy(dx, dy) {
  const g = geometry();
  const [cx, cy] = state.zoom !== null && state.center ? state.center : [g.source.width / 2, g.source.height / 2];
  state.zoom = g.zoom;
  state.center = [cx - dx / g.zoom, cy - dy / g.zoom];
  present();
  remember();
}

// ---- The pixel inspector ----

// The pixel inspected: {x, y} in the frame's own pixels, pinned or under the cursor, and
// what its file holds there (`pixel.json`) once it comes.
let inspected = null;
let pixelRequest = null;
function inspect(x, y, pinned) {
  const f = state.frame;
  if (!f) return;
  const same = inspected && inspected.x === x && inspected.y === y && inspected.frame === f;
  inspected = same ? Object.assign(inspected, { pinned, hover: !pinned }) : { x, y, pinned, hover: !pinned, frame: f, file: null };
  state.inspect = pinned ? [x, y] : null;
  if (!same) askPixel();
  showInspector();
  present();
  remember();
}
function unpin() {
  inspected = null;
  state.inspect = null;
  showInspector();
  present();
  remember();
}
// Asks for the inspected pixel as its file holds it, one request at a time: the pixel
// reached meanwhile is asked for next.
function askPixel() {
  if (pixelRequest) return;
  const asked = inspected;
  if (!asked || asked.file) return;
  pixelRequest = get(`frame/${asked.frame.index}/pixel.json?x=${asked.x}&y=${asked.y}`).then((r) => r.json()).then((file) => {
    asked.file = file;
  }).catch((e) => {
    asked.file = { error: e.message };
  }).finally(() => {
    pixelRequest = null;
    if (inspected !== asked) askPixel();
    showInspector();
  });
}

// A value to at least 4 significant digits (5 are shown): whole numbers as they are.
const digits = (v) => (Number.isInteger(v) && Math.abs(v) < 1e6 ? String(v) : v.toPrecision(5));

// The inspector's table: the pixel relit at the page's light (its passes, as the page
// computes them), then as its file holds it (every channel but the transfer layers: the
// beauty, the passes, the visibility terms, the colours, the lamps, P and N), and its
// material from the G-buffer.
function showInspector() {
  const box = $("inspector");
  const f = state.frame;
  if (!inspected || !f || inspected.frame !== f) { box.hidden = true; box.textContent = ""; return; }
  const { x, y } = inspected;
  const stride = f.meta.source.stride;
  const i = (y / stride) * f.meta.width + x / stride;
  const rows = [];
  const row = (name, values, source, channels) => {
    const cells = values.map((v, k) => `<td data-key="${source}:${channels[k]}">${digits(v)}</td>`).join("");
    rows.push(`<tr><th>${name}</th>${cells}</tr>`);
  };
  const group = (name) => rows.push(`<tr class="group"><th colspan="5">${name}</th></tr>`);
  // The pixel relit on its own, in full whatever the step a drag shows.
  const { at, visibility } = lighter(f, state.rotation);
  const d = [0, 0, 0], g = [0, 0, 0], rgb = [0, 0, 0];
  at(i, d, g);
  const { albedo, specular_colour } = f.layers;
  const diffuse = d.map((v, k) => albedo[3 * i + k] * v), reflected = g.map((v, k) => specular_colour[3 * i + k] * v);
  const lamps = lampsOf(f);
  group(`relit at ${state.rotation}°, strength ${state.strength.toFixed(2)}`);
  for (const pass of PASSES) {
    if (pass === "indirect" && !f.layers.indirect) continue;
    passer(pass, f, lamps)(i, diffuse, reflected, pass === "visibility" ? visibility(i) : 1, rgb);
    if (pass === "visibility") row(pass, [rgb[0]], "relit", [pass]);
    else row(pass, rgb, "relit", ["R", "G", "B"].map((c) => `${pass}.${c}`));
  }
  const file = inspected.file;
  if (!file) {
    group("as rendered: reading the file");
  } else if (file.error) {
    group(`as rendered: ${file.error}`);
  } else {
    group(`as rendered (${f.meta.file})`);
    // The file's channels by layer, each layer's in RGBA or XYZ order.
    const layers = new Map();
    for (const [name, value] of file.channels) {
      const dot = name.lastIndexOf(".");
      const layer = dot < 0 ? "" : name.slice(0, dot), channel = name.slice(dot + 1);
      if (!layers.has(layer)) layers.set(layer, []);
      layers.get(layer).push([channel, value, name]);
    }
    const place = (c) => { const k = "RGBAXYZ".indexOf(c); return k < 0 ? 9 : k; };
    const order = ["", "diffuse", "specular", "environment", "indirect", "indirect_heightfield", "indirect_blockers",
      "visibility", "visibility_heightfield", "visibility_blockers", "albedo", "specular_colour", "lamps_diffuse", "lamps_specular", "P", "N"];
    const names = [...layers.keys()].sort((a, b) => {
      const ka = order.indexOf(a), kb = order.indexOf(b);
      return (ka < 0 ? 99 : ka) - (kb < 0 ? 99 : kb) || a.localeCompare(b);
    });
    for (const layer of names) {
      const channels = layers.get(layer).sort((a, b) => place(a[0]) - place(b[0]));
      row(layer || "beauty (RGBA)", channels.map((c) => c[1]), "file", channels.map((c) => c[2]));
    }
    const material = file.material;
    const text = material.samples
      ? [...new Set(material.samples.map((s) => `${s.index} (${s.type})`))].join(", ")
        + (material.samples.length > 1 ? ` over ${material.samples.length} samples` : "")
      : `not read: ${material.unread}`;
    rows.push(`<tr><th>material</th><td colspan="4" style="text-align:left" id="inspected-material">${escapeHtml(text)}</td></tr>`);
  }
  const where = `pixel (${x}, ${y}) of ${f.meta.source.width} x ${f.meta.source.height}${inspected.pinned ? ", pinned" : ""}`;
  box.innerHTML = `<table><caption id="inspected" data-x="${x}" data-y="${y}">${where}</caption>${rows.join("")}</table>`;
  box.hidden = false;
  // Kept on the side of the window away from the pixel.
  const g2 = geometry();
  box.classList.toggle("left", g2.left + x * g2.zoom > g2.width / 2);
}
const escapeHtml = (text) => text.replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" })[c]);

// ---- The environment as turned ----

// Sizes the environment's canvas to the device's pixels.
function sizeEnvironment() {
  const canvas = $("environment"), dpr = window.devicePixelRatio || 1;
  const width = Math.round(canvas.clientWidth * dpr), height = Math.round(canvas.clientHeight * dpr);
  if (width > 0 && (canvas.width !== width || canvas.height !== height)) { canvas.width = width; canvas.height = height; }
  drawEnvironment();
}

// The light's map (the grid the mirror lookups read: the residual where suns were taken
// out) turned by the rotation, equirectangular with the zenith on top and azimuth 180°
// at the left edge as in the map's file, through the exposure and strength; the suns
// shaded sharp marked by filled discs, those held in SH by rings, the scene's Sun lamps
// by diamonds, each where the turn puts it.
function drawEnvironment() {
  const canvas = $("environment"), f = state.frame;
  const context = canvas.getContext("2d");
  if (!f) return;
  const W = canvas.width, H = canvas.height, grid = f.grids[0];
  const image = context.createImageData(W, H), data = image.data;
  const shift = state.rotation / 360, gain = Math.pow(2, f.view.exposure + state.exposure) * state.strength;
  const rgb = [0, 0, 0], shown = [0, 0, 0];
  for (let y = 0; y < H; y++) {
    const row = Math.min(grid.height - 1, Math.floor(((y + 0.5) / H) * grid.height));
    for (let x = 0; x < W; x++) {
      let u = (x + 0.5) / W + shift;
      u -= Math.floor(u);
      const texel = 3 * (row * grid.width + Math.min(grid.width - 1, Math.floor(u * grid.width)));
      for (let k = 0; k < 3; k++) rgb[k] = grid.texels[texel + k] * gain;
      display(f.view, rgb, shown);
      const b = 4 * (y * W + x);
      data[b] = shown[0]; data[b + 1] = shown[1]; data[b + 2] = shown[2]; data[b + 3] = 255;
    }
  }
  context.putImageData(image, 0, 0);
  const dpr = window.devicePixelRatio || 1;
  const place = (azimuth, elevation) => {
    let u = (180 - (azimuth + state.rotation)) / 360;
    u -= Math.floor(u);
    return [u * W, ((90 - elevation) / 180) * H];
  };
  const meta = f.meta;
  context.lineWidth = 1.5 * dpr;
  for (const sun of meta.sharp_suns) {
    const [x, y] = place(sun.azimuth, sun.elevation);
    context.beginPath(); context.arc(x, y, 4 * dpr, 0, 2 * Math.PI);
    context.fillStyle = "#ffe14a"; context.fill(); context.strokeStyle = "#000"; context.stroke();
  }
  for (const sun of meta.suns_in_sh) {
    const [x, y] = place(sun.azimuth, sun.elevation);
    context.beginPath(); context.arc(x, y, 5 * dpr, 0, 2 * Math.PI);
    context.strokeStyle = "#ffa040"; context.stroke();
  }
  for (const [azimuth, elevation] of meta.sun_lamp_directions || []) {
    const [x, y] = place(azimuth, elevation), r = 5 * dpr;
    context.beginPath(); context.moveTo(x, y - r); context.lineTo(x + r, y); context.lineTo(x, y + r); context.lineTo(x - r, y); context.closePath();
    context.fillStyle = "#fff"; context.fill(); context.strokeStyle = "#000"; context.stroke();
  }
  // The point lamps stay where they are as the map turns.
  const points = meta.point_lamp_directions || [];
  for (const [azimuth, elevation] of points) {
    const [x, y] = place(azimuth - state.rotation, elevation), r = 4 * dpr;
    context.fillStyle = "#9cf"; context.fillRect(x - r, y - r, 2 * r, 2 * r);
    context.strokeStyle = "#000"; context.strokeRect(x - r, y - r, 2 * r, 2 * r);
  }
  const marks = [
    meta.sharp_suns.length ? `${meta.sharp_suns.length} sun${meta.sharp_suns.length > 1 ? "s" : ""} shaded sharp (disc)` : "",
    meta.suns_in_sh.length ? `${meta.suns_in_sh.length} held in SH (ring)` : "",
    meta.sun_lamps ? `${meta.sun_lamps} Sun lamp${meta.sun_lamps > 1 ? "s" : ""} (diamond)` : "",
    points.length ? `${points.length} point lamp${points.length > 1 ? "s" : ""}, fixed, seen from the frame's middle (square)` : "",
  ].filter(Boolean);
  $("light-caption").textContent = `the environment turned ${state.rotation}°` + (marks.length ? `: ${marks.join(", ")}` : "");
  canvas.setAttribute("aria-valuenow", String(state.rotation));
}

