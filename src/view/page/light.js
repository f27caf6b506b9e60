"use strict";
// The relight of logsh's transfer layers (src/transfer/mod.rs, "Layers"): per pixel and
// colour channel, diffuse = albedo max(T_d . L, 0) + lamps, specular = colour G + lamps,
// the light L turned about Z by rotating its SH vector and the maps read along Rz(-turn) R;
// the suns taken out of the map, and the Sun lamps, shaded sharp by the server (src/view).
const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
const PASSES = ["beauty", "diffuse", "specular", "environment", "indirect", "visibility"];
const VIEWS = ["relit", "wipe-rendered", "diff-rendered", "wipe-cycles", "diff-cycles"];
// zoom: frame pixels per device pixel, or null to fit the window; center: the frame's
// point (in its own pixels, not the preview's) at the middle of the window; inspect: the
// pixel pinned in the inspector.
const state = {
  frame: null, index: 0, rotation: 0, strength: 1, exposure: 0, pass: "beauty", view: "relit", diff: "abs",
  wipe: 0.5, zoom: null, center: null, inspect: null, dragging: false,
};
let pending = false;

function rotateZ(coeffs, order, angle) {
  const out = Float64Array.from(coeffs);
  for (let l = 1; l < order; l++) {
    for (let m = 1; m <= l; m++) {
      const c = Math.cos(m * angle), s = Math.sin(m * angle);
      const ip = l * (l + 1) + m, im = l * (l + 1) - m;
      const a = out[ip], b = out[im];
      out[ip] = a * c - b * s;
      out[im] = a * s + b * c;
    }
  }
  return out;
}

// Where an equirectangular map is read along (x, y, z), as src/scene/light.rs's
// BilinearTaps: u across from azimuth 180° (the left edge) going west, v up from the nadir.
function mapPlace(x, y, z, out, at) {
  const len = Math.hypot(x, y, z);
  let u = 0, v = 0;
  if (len > 0) {
    u = (Math.atan2(y, x) - Math.PI) / (-2 * Math.PI);
    v = (Math.acos(Math.min(1, Math.max(-1, z / len))) - Math.PI) / -Math.PI;
  }
  out[at] = u;
  out[at + 1] = v;
}

// Bilinear read of an equirectangular map at (u, v) (`mapPlace`): columns wrap, rows
// clamp; the zenith is the first row. A turn of the light about Z by `turn` moves a
// direction's u by turn / 2 pi and leaves its v, so a turned read needs no trigonometry.
// `poles`: the grid's first and last rows lie on the zenith and the nadir
// (src/transfer/relight's sample_from_pole_to_pole), not half a row from them.
function lookup(map, u, v, out, poles = false) {
  const w = map.width, h = map.height, t = map.texels;
  const fx = u * w - 0.5;
  const fy = Math.min(h - 1, Math.max(0, poles ? (1 - v) * (h - 1) : (1 - v) * h - 0.5));
  const x0 = Math.floor(fx), y0 = Math.floor(fy);
  const tx = fx - x0, ty = fy - y0;
  const c0 = ((x0 % w) + w) % w, c1 = (((x0 + 1) % w) + w) % w;
  const r0 = y0, r1 = Math.min(y0 + 1, h - 1);
  for (let k = 0; k < 3; k++) {
    const top = t[3 * (r0 * w + c0) + k] * (1 - tx) + t[3 * (r0 * w + c1) + k] * tx;
    const bottom = t[3 * (r1 * w + c0) + k] * (1 - tx) + t[3 * (r1 * w + c1) + k] * tx;
    out[k] = top * (1 - ty) + bottom * ty;
  }
}

const srgbCurve = (x) => {
  x = x > 0 ? (x < 1 ? x : 1) : 0;
  const s = x <= 0.0031308 ? 12.92 * x : 1.055 * Math.pow(x, 1 / 2.4) - 0.055;
  return Math.floor(s * 255 + 0.5);
};
// The 8-bit sRGB level of a linear value: the curve above, found by bisection over the
// 255 linear values where its level steps up (each the smallest double the curve puts on
// that level), so the same level as the curve without a power per channel.
const srgbSteps = (() => {
  const steps = new Float64Array(256);
  for (let level = 1; level < 256; level++) {
    let low = 0, high = 1;
    for (;;) {
      const middle = (low + high) / 2;
      if (middle <= low || middle >= high) break;
      if (srgbCurve(middle) >= level) high = middle; else low = middle;
    }
    steps[level] = high;
  }
  return steps;
})();
// The level at each 1/4096 of the linear range, from which a value's level is at most two
// steps up (the curve rises at most 12.92 x 255 levels per unit, 0.8 per 1/4096).
const SRGB_CELLS = 4096;
const srgbCells = (() => {
  const cells = new Uint8Array(SRGB_CELLS + 1);
  let level = 0;
  for (let cell = 0; cell <= SRGB_CELLS; cell++) {
    while (level < 255 && cell / SRGB_CELLS >= srgbSteps[level + 1]) level++;
    cells[cell] = level;
  }
  return cells;
})();
const srgb = (x) => {
  if (!(x > 0)) return 0;
  if (x >= 1) return 255;
  let level = srgbCells[Math.floor(x * SRGB_CELLS)];
  while (level < 255 && x >= srgbSteps[level + 1]) level++;
  return level;
};

// The scene's view transform (src/scene/view.rs): Standard is the sRGB curve; any other
// is the exporter's LUT, read trilinearly in log2 of each channel. Writes 8-bit RGB.
function display(view, rgb, out) {
  const lut = view.lut;
  if (!lut) {
    for (let k = 0; k < 3; k++) out[k] = srgb(rgb[k]);
    return;
  }
  const n = lut.size, lo = lut.log2_range[0], hi = lut.log2_range[1], t = lut.values;
  const index = lutIndex, frac = lutFrac, weights = lutWeights, offsets = lutOffsets;
  for (let k = 0; k < 3; k++) {
    const c = rgb[k];
    let x = c > 0 ? (Math.log2(c) - lo) / (hi - lo) : 0;
    x = (x < 0 ? 0 : x > 1 ? 1 : x) * (n - 1);
    const i = Math.min(Math.floor(x), n - 2);
    index[k] = i;
    frac[k] = x - i;
  }
  // The eight corners' weights and places once for the three channels.
  let j = 0;
  for (let db = 0; db < 2; db++) for (let dg = 0; dg < 2; dg++) for (let dr = 0; dr < 2; dr++) {
    weights[j] = (dr ? frac[0] : 1 - frac[0]) * (dg ? frac[1] : 1 - frac[1]) * (db ? frac[2] : 1 - frac[2]);
    offsets[j] = 3 * (((index[2] + db) * n + index[1] + dg) * n + index[0] + dr);
    j++;
  }
  for (let k = 0; k < 3; k++) {
    let v = 0;
    for (let j = 0; j < 8; j++) v += weights[j] * t[offsets[j] + k];
    out[k] = Math.floor((v < 0 ? 0 : v > 1 ? 1 : v) * 255 + 0.5);
  }
}
const lutIndex = [0, 0, 0], lutFrac = [0, 0, 0], lutWeights = new Float64Array(8), lutOffsets = new Int32Array(8);
const lum = (c) => 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];

async function get(path) {
  const r = await fetch(path);
  if (!r.ok) throw new Error(`${path}: ${r.status} ${await r.text()}`);
  return r;
}

async function loadFrame(index) {
  const at = (what) => get(`frame/${index}/${what}`);
  const meta = await (await at("meta.json")).json();
  const pixels = await (await at("pixels.bin")).arrayBuffer();
  const maps = await (await at("maps.bin")).arrayBuffer();
  const n = meta.width * meta.height;
  const layers = {};
  for (const p of meta.pixels) layers[p.name] = new Float32Array(pixels, 4 * p.offset, n * p.components);
  const grids = meta.maps.map((m) => ({ width: m.width, height: m.height, texels: new Float32Array(maps, 4 * m.offset, 3 * m.width * m.height) }));
  const lut = meta.view.lut;
  const view = { exposure: meta.view.exposure, lut: lut && { size: lut.size, log2_range: lut.log2_range, values: new Float32Array(maps, 4 * lut.offset, 3 * lut.size ** 3) } };
  let cycles = null;
  if (meta.cycles) cycles = new Float32Array(await (await at("cycles.bin")).arrayBuffer());
  // The passes as rendered, asked for when a view compares against one (`rendered`).
  return { index, meta, layers, grids, cycles, view, rendered: {}, turnedLamps: null, turning: null, lampError: null, failedAt: null };
}

// Where each pixel's glossy lookup reads the maps at the render's turn (`mapPlace` of
// its direction R), u then v; worked out once per frame.
function glossyPlaces(f) {
  if (f.glossyPlaces) return f.glossyPlaces;
  const { glossy_direction, glossy_lobe } = f.layers;
  const places = new Float64Array(2 * glossy_lobe.length);
  for (let i = 0; i < glossy_lobe.length; i++) {
    if (glossy_lobe[i] > 0) mapPlace(glossy_direction[3 * i], glossy_direction[3 * i + 1], glossy_direction[3 * i + 2], places, 2 * i);
  }
  return (f.glossyPlaces = places);
}

// Where each pixel's diffuse light is corrected to the map's irradiance (`meta.open_diffuse`,
// src/shade/kernel/lit.rs's open_corrected_channel): the maps' place of its normal, and
// the two grids' values there at the frame's own turn, which a turn's reads are taken
// relative to; worked out once per frame.
function normalPlaces(f) {
  if (f.normalPlaces) return f.normalPlaces;
  const normals = f.layers.diffuse_normal, n = normals.length / 3;
  const { grids, meta } = f;
  const [irradiance, open] = [grids[1 + 2 * meta.lobes], grids[2 + 2 * meta.lobes]];
  const places = new Float64Array(2 * n), base = new Float32Array(6 * n), e = [0, 0, 0], o = [0, 0, 0];
  for (let i = 0; i < n; i++) {
    mapPlace(normals[3 * i], normals[3 * i + 1], normals[3 * i + 2], places, 2 * i);
    lookup(irradiance, places[2 * i], places[2 * i + 1], e, true);
    lookup(open, places[2 * i], places[2 * i + 1], o, true);
    base.set([...e, ...o], 6 * i);
  }
  return (f.normalPlaces = { places, base });
}

// What lights one pixel under the light turned by `rotation`: `at(i, d, g)` writes the
// environment's diffuse light (max(T_d . L, 0) per channel, before albedo and strength)
// into d and its reflected light (before the specular colour and strength) into g;
// `visibility(i)` the visibility term from the diffuse light `at` read last, before its
// correction to the map's irradiance (as the render's visibility pass).
function lighter(f, rotation) {
  const { meta, layers, grids } = f;
  const order = meta.order, count = order * order;
  const turn = (rotation * Math.PI) / 180;
  const [L0, L1, L2] = meta.light.map((channel) => rotateZ(channel, order, turn));
  // The maps are read along Rz(-turn) R: at u + turn / 2 pi.
  const du = turn / (2 * Math.PI);
  const places = glossyPlaces(f);
  const { diffuse, unoccluded, specular, glossy_lobe, glossy_weight } = layers;
  const lobes = meta.lobes;
  // T . L per channel, clamped at 0: each coefficient read once for the three channels.
  const dot = (layer, i, out) => {
    const base = i * count;
    let s0 = 0, s1 = 0, s2 = 0;
    for (let c = 0; c < count; c++) {
      const t = layer[base + c];
      s0 += t * L0[c];
      s1 += t * L1[c];
      s2 += t * L2[c];
    }
    out[0] = s0 > 0 ? s0 : 0;
    out[1] = s1 > 0 ? s1 : 0;
    out[2] = s2 > 0 ? s2 : 0;
  };
  const s = [0, 0, 0], m = [0, 0, 0], o = [0, 0, 0], u = [0, 0, 0], e = [0, 0, 0], raw = [0, 0, 0];
  // The diffuse light corrected as the render corrected it: E(n) / pi times log-SH's share
  // of the open receiver's light, clamped to [0, 1], where that light is not dark.
  // Both at the pixel's normal are the server's exact values at the frame's own turn, plus
  // what the turn changes in the grids there (the grids' error is in the change only).
  const corrected = meta.open_diffuse && f.layers.diffuse_normal ? normalPlaces(f) : null;
  const exact = f.layers.open_diffuse_light;
  const [irradiance, openDiffuse] = [grids[1 + 2 * lobes], grids[2 + 2 * lobes]];
  const correct = (i, d) => {
    const { places, base } = corrected;
    if (du !== 0) {
      const pu = places[2 * i] + du, pv = places[2 * i + 1];
      lookup(irradiance, pu, pv, e, true);
      lookup(openDiffuse, pu, pv, o, true);
    }
    for (let k = 0; k < 3; k++) {
      const full = exact[6 * i + k] + (du !== 0 ? e[k] - base[6 * i + k] : 0);
      const open = exact[6 * i + 3 + k] + (du !== 0 ? o[k] - base[6 * i + 3 + k] : 0);
      if (open > 1e-6) d[k] = Math.max(full, 0) * Math.min(1, Math.max(0, d[k] / open));
    }
  };
  // `lit`: whether the diffuse light is wanted (a pixel without albedo has none to show
  // but for its visibility term).
  const at = (i, d, g, lit = true) => {
    if (lit) dot(diffuse, i, d); else d[0] = d[1] = d[2] = 0;
    raw[0] = d[0]; raw[1] = d[1]; raw[2] = d[2];
    if (lit && corrected) correct(i, d);
    const code = glossy_lobe[i];
    g[0] = g[1] = g[2] = 0;
    if (code > 0) {
      const pu = places[2 * i] + du, pv = places[2 * i + 1];
      if (code === 1) {
        lookup(grids[0], pu, pv, g);
      } else if (code === 2) {
        dot(specular, i, g);
      } else {
        const j = code - 3;
        const cone = glossy_weight[2 * i], shWeight = glossy_weight[2 * i + 1];
        let ratio = 0;
        if (shWeight > 0) {
          dot(specular, i, s);
          lookup(grids[1 + lobes + j], pu, pv, o);
          const below = lum(o);
          ratio = below > 1e-12 ? Math.min(1, Math.max(0, lum(s) / below)) : 1;
        }
        lookup(grids[1 + j], pu, pv, m);
        const weight = cone + shWeight * ratio;
        for (let k = 0; k < 3; k++) g[k] = m[k] * weight;
      }
    }
  };
  const visibility = (i) => {
    dot(unoccluded, i, u);
    const below = lum(u);
    return below > 1e-12 ? lum(raw) / below : 1;
  };
  return { at, visibility };
}

// What the light's turn decides, per pixel: the environment's diffuse and reflected light
// before strength (albedo max(T_d . L, 0), colour G), and the visibility term where that
// pass is shown. It is computed once per turn; strength, exposure, the pass, the view and
// the wipe only recombine it (`compose`), zoom and pan only draw it again (`present`).
// While a slider is dragged it is computed at one pixel in `step` x `step` (`relight`),
// and in full once the slider is let go.
let lit = null;

// The lit values at every `step`-th pixel of every `step`-th row, `width` x `height` of
// them.
function light(f, rotation, step, withVisibility) {
  const { meta, layers } = f;
  const w = meta.width, h = meta.height;
  const width = Math.ceil(w / step), height = Math.ceil(h / step), n = width * height;
  const { albedo, specular_colour } = layers;
  const { at, visibility: visibilityAt } = lighter(f, rotation);
  const out = {
    frame: f, rotation, step, width, height,
    diffuse: new Float32Array(3 * n), reflected: new Float32Array(3 * n),
    visibility: withVisibility ? new Float32Array(n) : null,
  };
  const d = [0, 0, 0], g = [0, 0, 0];
  let b = 0;
  for (let y = 0; y < h; y += step) {
    for (let x = 0; x < w; x += step, b++) {
      const i = y * w + x;
      at(i, d, g, withVisibility || albedo[3 * i] !== 0 || albedo[3 * i + 1] !== 0 || albedo[3 * i + 2] !== 0);
      for (let k = 0; k < 3; k++) {
        out.diffuse[3 * b + k] = albedo[3 * i + k] * d[k];
        out.reflected[3 * b + k] = specular_colour[3 * i + k] * g[k];
      }
      if (withVisibility) out.visibility[b] = visibilityAt(i);
    }
  }
  return out;
}

// The passes as `logsh relight` assembles them: `(i, diffuse, reflected, visibility,
// rgb)` writes the linear RGB of pass `pass` at pixel i into `rgb`, from the environment's
// light there (`diffuse`, `reflected`, `visibility`, before strength), the lamps and the
// strength.
function passer(pass, f, lamps) {
  const { alpha, indirect } = f.layers;
  const strength = state.strength;
  const { diffuse: lampsDiffuse, specular: lampsSpecular, sunsDiffuse, sunsSpecular } = lamps;
  // The pass as a number, compared per pixel in place of its name.
  const which = PASSES.indexOf(pass);
  const [BEAUTY, DIFFUSE, SPECULAR, ENVIRONMENT, INDIRECT, VISIBILITY] = [0, 1, 2, 3, 4, 5];
  return (i, diffuse, reflected, visibility, rgb) => {
    if (which === VISIBILITY) { rgb[0] = rgb[1] = rgb[2] = visibility; return; }
    const surface = alpha[i] > 0;
    for (let k = 0; k < 3; k++) {
      const j = 3 * i + k;
      // The map's suns are the environment's: they follow its strength.
      const sunD = sunsDiffuse ? sunsDiffuse[j] : 0, sunS = sunsSpecular ? sunsSpecular[j] : 0;
      const diffusePass = (diffuse[k] + sunD) * strength + lampsDiffuse[j];
      const reflectedLight = reflected[k] * strength;
      const specularPass = surface ? reflectedLight + sunS * strength + lampsSpecular[j] : 0;
      const environmentPass = surface ? 0 : reflectedLight;
      // The render's bounce light, kept as rendered (as logsh relight keeps it).
      const indirectPass = surface && indirect ? indirect[j] : 0;
      rgb[k] = which === BEAUTY ? diffusePass + specularPass + environmentPass + indirectPass
        : which === DIFFUSE ? diffusePass
        : which === SPECULAR ? specularPass
        : which === ENVIRONMENT ? environmentPass
        : indirectPass;
    }
  };
}

// What the frame is compared against in the view shown: the Cycles render (a beauty) or
// the pass as rendered, `components` values per pixel at the preview's pixels; `null` in
// the relit view, and while the pass as rendered is on its way.
function reference(f) {
  if (state.view.endsWith("-cycles")) return f.cycles && { values: f.cycles, components: 3, name: "Cycles" };
  if (state.view.endsWith("-rendered")) {
    const got = f.rendered[shownPass(f)];
    if (!got) { fetchRendered(f, shownPass(f)); return null; }
    return got.values ? got : null;
  }
  return null;
}
// The pass shown: the beauty against Cycles, which renders no other.
const shownPass = (f) => (state.view.endsWith("-cycles") ? "beauty" : state.pass);
function fetchRendered(f, pass) {
  if (f.rendered[pass]) return f.rendered[pass].loading;
  f.rendered[pass] = {};
  return f.rendered[pass].loading = get(`frame/${f.index}/rendered.bin?pass=${pass}`).then((r) => r.arrayBuffer()).then((buffer) => {
    const values = new Float32Array(buffer);
    f.rendered[pass] = { values, components: values.length / (f.meta.width * f.meta.height), name: "as rendered" };
  }).catch((e) => {
    f.rendered[pass] = { error: e.message };
  }).finally(() => { if (state.frame === f) schedule(); });
}

// The image last composed (8-bit, every `step`-th pixel of every `step`-th row of the
// preview) and the canvas it is drawn from.
let composed = null;
const imageCanvas = document.createElement("canvas");
// The comparison's error over the frame, kept while what it compares stays the same.
let metrics = null;

// A signed difference (scaled, in -1 to 1) as a colour: blue below zero, red above, black
// at zero.
const BELOW = [0.2, 0.45, 1.0], ABOVE = [1.0, 0.3, 0.15];
function diverging(t, out) {
  const ramp = t < 0 ? BELOW : ABOVE, a = Math.min(1, Math.abs(t));
  for (let k = 0; k < 3; k++) out[k] = srgb(ramp[k] * a);
}

// The passes from the lit values, the lamps and the strength, through the exposure and
// the scene's view transform, with the reference right of the wipe, or the difference
// from it; every `step`-th pixel of every `step`-th row while a slider is dragged, which
// the window shows over its block. Returns the comparison's per-pixel error where there
// is one and `step` is 1.
function compose(f, lit, step) {
  const { meta, view } = f;
  const w = meta.width, h = meta.height;
  const width = Math.ceil(w / step), height = Math.ceil(h / step);
  const lamps = lampsOf(f);
  const gain = Math.pow(2, view.exposure + state.exposure), differenceGain = Math.pow(2, state.exposure);
  if (imageCanvas.width !== width || imageCanvas.height !== height) { imageCanvas.width = width; imageCanvas.height = height; }
  const context = imageCanvas.getContext("2d");
  if (!composed || composed.width !== width || composed.height !== height) composed = context.createImageData(width, height);
  composed.step = step;
  const data = composed.data;
  const pass = shownPass(f);
  const ref = reference(f);
  const wiping = ref && state.view.startsWith("wipe-"), differing = ref && state.view.startsWith("diff-");
  const wipeColumn = wiping ? Math.round(state.wipe * w) : w;
  const errors = ref && step === 1 ? new Float32Array(w * h) : null;
  // The lit values' step: 1, or this one.
  const litStep = lit.step, litWidth = lit.width;
  const passAt = passer(pass, f, lamps);
  const signed = state.diff === "signed", visibilityPass = pass === "visibility", lut = view.lut;
  const rgb = [0, 0, 0], other = [0, 0, 0], shown = [0, 0, 0], d = [0, 0, 0], r = [0, 0, 0];
  let b = 0;
  for (let y = 0; y < h; y += step) {
    const litRow = ((y / litStep) | 0) * litWidth;
    for (let x = 0; x < w; x += step, b += 4) {
      const i = y * w + x, j = litRow + ((x / litStep) | 0);
      for (let k = 0; k < 3; k++) { d[k] = lit.diffuse[3 * j + k]; r[k] = lit.reflected[3 * j + k]; }
      passAt(i, d, r, lit.visibility ? lit.visibility[j] : 1, rgb);
      if (ref) {
        for (let k = 0; k < 3; k++) other[k] = ref.components === 1 ? ref.values[i] : ref.values[3 * i + k];
        if (errors) errors[i] = (Math.abs(rgb[0] - other[0]) + Math.abs(rgb[1] - other[1]) + Math.abs(rgb[2] - other[2])) / 3;
      }
      if (differing) {
        if (signed) {
          diverging(((rgb[0] - other[0] + rgb[1] - other[1] + rgb[2] - other[2]) / 3) * differenceGain, shown);
        } else {
          for (let k = 0; k < 3; k++) shown[k] = srgb(Math.abs(rgb[k] - other[k]) * differenceGain);
        }
      } else {
        const value = x >= wipeColumn ? other : rgb;
        if (visibilityPass) {
          for (let k = 0; k < 3; k++) shown[k] = srgb(value[k]);
        } else {
          for (let k = 0; k < 3; k++) value[k] *= gain;
          // The sRGB curve in place where the scene has no LUT: a call per pixel is slower.
          if (lut) display(view, value, shown);
          else { shown[0] = srgb(value[0]); shown[1] = srgb(value[1]); shown[2] = srgb(value[2]); }
        }
      }
      data[b] = shown[0];
      data[b + 1] = shown[1];
      data[b + 2] = shown[2];
      data[b + 3] = 255;
    }
  }
  context.putImageData(composed, 0, 0);
  return errors && { errors, against: ref.name, pass };
}

// The mean and 95th percentile of a comparison's per-pixel errors (the mean over R, G, B
// of the absolute difference, linear).
function errorStats(errors) {
  let sum = 0;
  for (let i = 0; i < errors.length; i++) sum += errors[i];
  const sorted = Float32Array.from(errors).sort();
  return { mean: sum / errors.length, p95: sorted[Math.min(sorted.length - 1, Math.floor(0.95 * sorted.length))], pixels: errors.length };
}

