// The page (docs/web.md): opens a .prtpack and a Radiance .hdr (file inputs, drag and drop, or
// ?pack=URL&env=URL), relights the pack with the WebAssembly runtime and draws it (viewer.js).
// Dragging rotates the environment: preview lighting and PBI frames of `budget` terms while it
// moves, frames until PBI has converged when it stops, then nothing until the next change.
// Dragging with the right button orbits the camera about its target: a diffuse pack is only
// drawn again, a glossy pack (prt_runtime_is_glossy) is relit towards the new eye, a glossy vertex
// pack (BRDF terms) has its last frame's terms combined again for it (prt_runtime_reshade).
// Figures are kept in window.prtStats and shown in #stats; window.prtPage has the test hooks.
import {loadRuntimeModule, Pack} from './runtime.js';
import {parseRadianceHdr} from './hdr.js';
import {MeshView, ImageView} from './viewer.js';

const params = new URLSearchParams(location.search);
const $ = (id) => document.getElementById(id);
const kKeptFrames = 600;

const stats = {
  state: 'empty', error: null, pack: null, env: null, samples: 0, triangles: 0, isImage: false,
  isGlossy: false, cubemapSize: 0, coefficients: 0, budget: 100, exposure: 1, rotationDeg: 0,
  orbitDeg: 0, lastOrbitMs: null, orbitFps: null, eye: null, target: null,
  converged: false, preview: false, lastFrameAt: null, convergeMs: null, previewSetupMs: null, loadToFirstFrameMs: null, openMs: null, exactRelightMs: null, lastFrameMs: null,
  lastRelightMs: null, lastRotateMs: null, frames: [], dragFps: null, dragFrames: 0,
  bytesDownloaded: 0, memoryBytes: 0, wasmHeapBytes: 0,
  // Milestones of a URL load, ms after the page's navigation started (performance.now()).
  load: {scriptStart: null, fetched: null, mapParsed: null, moduleReady: null, opened: null,
         viewReady: null, environmentSet: null, firstFrame: null},
};
stats.load.scriptStart = performance.now();
window.prtStats = stats;

const app = {
  M: null, pack: null, packName: null, env: null, envName: null, view: null, angle: 0,
  appliedAngle: 0, dragging: false, preview: false, framesLeft: 0, needsRender: false,
  drag: null, envSet: false, firstFrameDone: false,
  // The orbit: the pack camera's eye turned by `orbit` radians about the vertical through its
  // target (prt-view's window, view_window_main.cpp Orbit).
  camera: null, orbit: 0, appliedOrbit: 0, orbiting: null,
};

function setState(s) {
  stats.state = s;
  document.body.dataset.state = s;
}

function showError(msg) {
  const el = $('error');
  el.textContent = msg;
  el.hidden = false;
  stats.error = msg;
  setState('error');
  console.error(msg);
  updateStatsText();
}

function clearError() {
  $('error').hidden = true;
  stats.error = null;
}

function median(xs) {
  if (!xs.length) return null;
  const s = [...xs].sort((a, b) => a - b);
  return s[Math.floor(s.length / 2)];
}

function fmt(x, digits = 2) {
  return x == null ? '–' : x.toFixed(digits);
}

function measureDownloads() {
  let bytes = 0;
  for (const e of performance.getEntriesByType('navigation')) bytes += e.encodedBodySize || 0;
  for (const e of performance.getEntriesByType('resource')) bytes += e.encodedBodySize || 0;
  stats.bytesDownloaded = bytes;
}

function updateStatsText() {
  const pbi = stats.frames.filter((f) => f.terms > 0).map((f) => f.relightMs);
  const rot = stats.frames.filter((f) => f.rotateMs > 0).map((f) => f.rotateMs);
  const glossy = stats.frames.filter((f) => f.glossy).map((f) => f.totalMs);
  const kind = stats.isImage ? ' (image pack)' : stats.isGlossy ? ' (glossy pack)' : '';
  const lines = [
    `pack         ${stats.pack ?? '–'}`,
    `environment  ${stats.env ?? '–'}`,
    `samples      ${stats.samples}${kind}, ` +
        `${stats.triangles} triangles, n = ${stats.cubemapSize}`,
    stats.isGlossy ? 'term budget  – (glossy: triple products towards the eye every frame)'
                   : `term budget  ${stats.budget} of ${stats.coefficients} (PBI)`,
    `exposure     ${stats.exposure}`,
    `rotation     ${fmt(stats.rotationDeg, 1)}°, orbit ${fmt(stats.orbitDeg, 1)}°`,
    `frame time   ${fmt(stats.lastFrameMs)} ms (relight ${fmt(stats.lastRelightMs)} ms, ` +
        `rotate ${fmt(stats.lastRotateMs)} ms)`,
    stats.isGlossy ? `glossy frame ${fmt(median(glossy))} ms median of ${glossy.length}`
                   : `PBI frame    ${fmt(median(pbi))} ms median of ${pbi.length}`,
    `rotate       ${fmt(median(rot))} ms median of ${rot.length} (env → cubemap)`,
    `exact        ${fmt(stats.exactRelightMs)} ms`,
    `drag fps     ${fmt(stats.dragFps, 1)}`,
    `open         ${fmt(stats.openMs, 0)} ms`,
    `first frame  ${fmt(stats.loadToFirstFrameMs, 0)} ms after page load`,
    `downloaded   ${(stats.bytesDownloaded / 1e6).toFixed(2)} MB`,
    `memory       ${(stats.memoryBytes / 1048576).toFixed(1)} MiB in the handle, ` +
        `${(stats.wasmHeapBytes / 1048576).toFixed(0)} MiB wasm heap`,
  ];
  if (stats.error) lines.push(`error        ${stats.error}`);
  $('stats').textContent = lines.join('\n');
}

function recordFrame(f) {
  stats.frames.push(f);
  if (stats.frames.length > kKeptFrames) stats.frames.shift();
  stats.lastFrameMs = f.totalMs;
  stats.lastRelightMs = f.relightMs;
  stats.lastRotateMs = f.rotateMs;
}

// ---- Loading ---------------------------------------------------------------------------------

async function fetchBytes(url) {
  const r = await fetch(url);
  if (!r.ok) throw new Error(`${url}: HTTP ${r.status} ${r.statusText}`);
  return new Uint8Array(await r.arrayBuffer());
}

async function openPack(bytes, name) {
  if (app.pack) {
    app.pack.close();
    app.pack = null;
  }
  app.envSet = false;
  app.M = app.M ?? await loadRuntimeModule();
  const t0 = performance.now();
  try {
    app.pack = new Pack(app.M, bytes);
  } catch (e) {
    throw new Error(`Cannot open ${name}: ${e.message}`);
  }
  stats.openMs = performance.now() - t0;
  stats.load.opened = performance.now();
  app.packName = name;
  stats.pack = name;
  stats.samples = app.pack.samples;
  stats.triangles = app.pack.triangles;
  stats.isImage = app.pack.isImage;
  stats.isGlossy = app.pack.isGlossy;
  stats.cubemapSize = app.pack.cubemapSize;
  stats.coefficients = app.pack.coefficients;
  $('budget').max = String(app.pack.coefficients);
  makeView();
  stats.load.viewReady = performance.now();
}

function makeView() {
  const pack = app.pack;
  const cam = pack.camera();
  app.camera = cam;
  app.appliedOrbit = 0;  // the runtime's eye is the pack camera's after opening
  const width = Number(params.get('width')) || cam.width;
  const height = Number(params.get('height')) || cam.height;
  const gl = $('gl');
  const img = $('image');
  if (pack.isImage) {
    gl.hidden = true;
    img.hidden = false;
    app.view = new ImageView(img, cam, pack.imageBackground(), pack.imageCoverage());
  } else {
    img.hidden = true;
    gl.hidden = false;
    if (!app.meshView) {
      app.meshView = new MeshView(gl, {...cam, width, height}, pack.positions(),
                                  pack.triangleIndices());
    } else {  // a second pack: a fresh WebGL view on a fresh canvas
      app.meshView.dispose();
      const fresh = gl.cloneNode();
      gl.replaceWith(fresh);
      attachDrag(fresh);
      app.meshView = new MeshView(fresh, {...cam, width, height}, pack.positions(),
                                  pack.triangleIndices());
    }
    app.view = app.meshView;
  }
  app.view.setExposure(stats.exposure);
  if (app.env) app.view.setEnvironment(app.env);
  applyOrbit();
}

// The pack camera's eye turned by `radians` about the vertical through its target.
function orbitEye(radians) {
  const {eye, target} = app.camera;
  const dx = eye[0] - target[0], dz = eye[2] - target[2];
  const c = Math.cos(radians), s = Math.sin(radians);
  return [target[0] + c * dx + s * dz, eye[1], target[2] - s * dx + c * dz];
}

// The orbit into the view and the runtime (an image pack's view is fixed).
function applyOrbit() {
  if (app.pack.isImage) return;
  const eye = orbitEye(app.orbit);
  app.view.setEye(eye);
  app.pack.setEye(eye);
  app.appliedOrbit = app.orbit;
  stats.orbitDeg = ((app.orbit * 180) / Math.PI) % 360;
  stats.eye = eye;
  stats.target = app.camera.target;
}

function setEnvironment(env, name) {
  app.env = env;
  app.envName = name;
  stats.env = `${name} (${env.width}×${env.height})`;
  if (app.view) app.view.setEnvironment(env);
}

// Both inputs present: the environment into the runtime and the first frame, exact.
function start() {
  if (!app.pack || !app.env) {
    updateStatsText();
    return;
  }
  app.pack.setEnvironment(app.env.rgb, app.env.width, app.env.height);
  if (!app.firstFrameDone) stats.load.environmentSet = performance.now();
  app.pack.setRotationY(app.angle);
  app.appliedAngle = app.angle;
  app.view.setRotation(app.angle);
  app.envSet = true;
  exactFrame();
  if (!app.firstFrameDone) {
    app.firstFrameDone = true;
    stats.loadToFirstFrameMs = performance.now();
    stats.load.firstFrame = stats.loadToFirstFrameMs;
  }
  // The preview's weights are built at its first use after a new map (about one full
  // resampling): build them now, so that the first frame of a drag is as fast as the others.
  const t0 = performance.now();
  app.pack.setPreview(true);
  app.pack.setPreview(false);
  stats.previewSetupMs = performance.now() - t0;
  convergeSilently();
  stats.memoryBytes = app.pack.memoryBytes();
  stats.wasmHeapBytes = app.M.HEAPU8.length;
  setState('ready');
  measureDownloads();
  updateStatsText();
}

function exactFrame() {
  const t0 = performance.now();
  const rgb = app.pack.relight(0);
  const t1 = performance.now();
  app.view.setRadiance(rgb);
  app.view.render();
  const t2 = performance.now();
  stats.exactRelightMs = t1 - t0;
  stats.lastFrameAt = t2;
  stats.converged = true;
  recordFrame({terms: 0, rotateMs: 0, relightMs: t1 - t0, drawMs: t2 - t1, totalMs: t2 - t0,
               preview: false});
  // An exact frame leaves the runtime's PBI state where it was: the next PBI frames go on
  // from it.
  app.framesLeft = 0;
}

// PBI starts from no light (at the first PBI frame, and again at a new budget): its first frames
// under still lighting are dark. Run them here, without drawing, until PBI holds the exact
// lighting (⌈6n²/N⌉ frames, each cheap when the lighting is still), so that a drag's frames only
// spend their terms on the rotation's change. The view keeps showing the exact frame.
function convergeSilently() {
  if (app.pack.isGlossy) return;  // every glossy frame is whole: nothing to converge
  const t0 = performance.now();
  for (let i = 0; i < framesToConverge(); ++i) app.pack.relight(stats.budget);
  stats.convergeMs = performance.now() - t0;
}

async function loadFromUrl() {
  const packUrl = params.get('pack');
  const envUrl = params.get('env');
  if (!packUrl && !envUrl) return;
  setState('loading');
  try {
    const [packBytes, envBytes] = await Promise.all([
      packUrl ? fetchBytes(packUrl) : null, envUrl ? fetchBytes(envUrl) : null,
      loadRuntimeModule().then(() => (stats.load.moduleReady = performance.now()))]);
    stats.load.fetched = performance.now();
    if (envBytes) setEnvironment(parseRadianceHdr(envBytes.buffer, envUrl), envUrl);
    stats.load.mapParsed = performance.now();
    if (packBytes) await openPack(packBytes, packUrl);
    start();
  } catch (e) {
    showError(e.message);
  }
}

async function loadFiles(files) {
  clearError();
  setState('loading');
  try {
    for (const f of files) {
      const bytes = new Uint8Array(await f.arrayBuffer());
      if (/\.(hdr|pic)$/i.test(f.name)) {
        setEnvironment(parseRadianceHdr(bytes.buffer, f.name), f.name);
      } else {
        await openPack(bytes, f.name);
      }
    }
    if (app.pack && app.env) {
      start();
    } else {
      setState('empty');
      updateStatsText();
    }
  } catch (e) {
    showError(e.message);
  }
}

// ---- Interaction and the frame loop ----------------------------------------------------------

function attachDrag(canvas) {
  canvas.addEventListener('contextmenu', (ev) => ev.preventDefault());
  canvas.addEventListener('pointerdown', (ev) => {
    if (!app.envSet) return;
    canvas.setPointerCapture(ev.pointerId);
    if (ev.button === 2) {  // the right button orbits the camera
      if (!app.pack.isImage) {
        app.orbiting = {x0: ev.clientX, orbit0: app.orbit, t0: performance.now(), frames: 0};
      }
      return;
    }
    app.dragging = true;
    app.drag = {x0: ev.clientX, angle0: app.angle, t0: performance.now(), frames: 0};
    if (!app.preview) {
      app.pack.setPreview(true);  // resampled from the reduced map while the user drags
      app.preview = true;
    }
  });
  canvas.addEventListener('pointermove', (ev) => {
    if (app.orbiting) {
      const w = canvas.clientWidth || canvas.width;
      app.orbit = app.orbiting.orbit0 + (2 * Math.PI * (ev.clientX - app.orbiting.x0)) / w;
      return;
    }
    if (!app.dragging) return;
    const w = canvas.clientWidth || canvas.width;
    app.angle = app.drag.angle0 + (2 * Math.PI * (ev.clientX - app.drag.x0)) / w;
  });
  const end = () => {
    if (app.orbiting) {
      const dt = (performance.now() - app.orbiting.t0) / 1000;
      if (dt > 0 && app.orbiting.frames > 0) stats.orbitFps = app.orbiting.frames / dt;
      app.orbiting = null;
      return;
    }
    if (!app.dragging) return;
    app.dragging = false;
    const dt = (performance.now() - app.drag.t0) / 1000;
    if (dt > 0 && app.drag.frames > 0) {
      stats.dragFps = app.drag.frames / dt;
      stats.dragFrames = app.drag.frames;
    }
    // Back to the full map: the lighting changes once more, PBI converges to the exact frame.
    app.pack.setPreview(false);
    app.preview = false;
    app.framesLeft = framesToConverge();
    stats.converged = false;
    stats.preview = false;
  };
  canvas.addEventListener('pointerup', end);
  canvas.addEventListener('pointercancel', end);
}

function framesToConverge() {
  // A glossy frame is whole: one frame after the preview ends, on the full map.
  if (app.pack && app.pack.isGlossy) return 1;
  // Under still lighting PBI reaches the exact radiance within ⌈6n²/N⌉ frames (runtime.md).
  return Math.ceil(stats.coefficients / stats.budget) + 1;
}

function tick() {
  requestAnimationFrame(tick);
  if (!app.envSet || stats.state === 'error' || app.spinning) return;
  try {
    const glossy = app.pack.isGlossy;
    const rotate = app.angle !== app.appliedAngle;
    const orbit = app.orbit !== app.appliedOrbit;
    let orbitMs = 0;
    if (orbit) {
      const t = performance.now();
      applyOrbit();
      orbitMs = performance.now() - t;
      stats.lastOrbitMs = orbitMs;
      if (app.orbiting) ++app.orbiting.frames;
      // A diffuse pack's radiance does not change; a glossy vertex pack's terms are combined
      // for the new eye by the next relight.
      if (!glossy && !(app.pack.brdfTerms > 1)) app.needsRender = true;
    }
    // A glossy pack relights when the view or the lighting changed (each frame is whole); a
    // diffuse one while PBI frames remain or the lighting is dragged.
    const relight = glossy ? rotate || orbit || app.framesLeft > 0
                           : rotate || app.framesLeft > 0 || app.dragging;
    // A glossy vertex pack's orbit step under still lighting: its terms combined again for the
    // new eye (prt_runtime_reshade), no relight.
    const reshade = !relight && orbit && app.pack.brdfTerms > 1;
    if (relight) {
      const t0 = performance.now();
      if (rotate) {
        app.pack.setRotationY(app.angle);
        app.appliedAngle = app.angle;
        app.view.setRotation(app.angle);
        stats.rotationDeg = ((app.angle * 180) / Math.PI) % 360;
        app.framesLeft = framesToConverge();
      }
      const t1 = performance.now();
      const terms = glossy ? 0 : stats.budget;
      const rgb = app.pack.relight(terms);
      const t2 = performance.now();
      app.view.setRadiance(rgb);
      app.view.render();
      const t3 = performance.now();
      recordFrame({terms, rotateMs: rotate ? t1 - t0 : 0, relightMs: t2 - t1, drawMs: t3 - t2,
                   totalMs: t3 - t0 + orbitMs, preview: app.preview, orbit, glossy});
      if (app.dragging) ++app.drag.frames;
      if (!app.dragging && app.framesLeft > 0) --app.framesLeft;
      stats.lastFrameAt = t3;
      stats.converged = !app.dragging && app.framesLeft === 0;
      stats.preview = app.preview;
      app.needsRender = false;
      updateStatsText();
    } else if (reshade) {
      const t0 = performance.now();
      app.view.setRadiance(app.pack.reshade());
      const t1 = performance.now();
      app.view.render();
      const t2 = performance.now();
      recordFrame({terms: 0, rotateMs: 0, relightMs: t1 - t0, drawMs: t2 - t1,
                   totalMs: t2 - t0 + orbitMs, preview: app.preview, orbit, glossy});
      app.needsRender = false;
      updateStatsText();
    } else if (app.needsRender) {
      const t0 = performance.now();
      app.view.render();
      const t1 = performance.now();
      if (orbit) {  // a diffuse pack's orbit step: drawn again, nothing relit
        recordFrame({terms: 0, rotateMs: 0, relightMs: 0, drawMs: t1 - t0,
                     totalMs: t1 - t0 + orbitMs, preview: false, orbit, glossy});
      }
      app.needsRender = false;
      updateStatsText();
    }
  } catch (e) {
    showError(e.message);
  }
}

function readControls() {
  const e = Number($('exposure').value);
  if (e > 0 && Number.isFinite(e)) {
    stats.exposure = e;
    if (app.view) app.view.setExposure(e);
    app.needsRender = true;
  }
  const b = Math.round(Number($('budget').value));
  const maxB = stats.coefficients || Infinity;
  if (b >= 1 && b <= maxB && b !== stats.budget) {
    stats.budget = b;  // the runtime restarts PBI from no light at a new budget
    if (app.envSet && !app.dragging) {
      try {
        convergeSilently();
      } catch (e) {
        showError(e.message);
      }
    } else {
      app.framesLeft = app.envSet ? framesToConverge() : 0;
      stats.converged = app.framesLeft === 0;
    }
  }
  updateStatsText();
}

// ---- Test and measurement hooks (web/test/page_test.mjs, docs/web.md) -------------------------

// A lat-long map at half the width and height, each pixel the mean of 2 × 2 (for timing only).
function halveMap(m) {
  const w = m.width >> 1, h = m.height >> 1;
  const rgb = new Float32Array(3 * w * h);
  for (let y = 0; y < h; ++y) {
    for (let x = 0; x < w; ++x) {
      for (let c = 0; c < 3; ++c) {
        const at = (xx, yy) => m.rgb[3 * (yy * m.width + xx) + c];
        rgb[3 * (y * w + x) + c] = 0.25 * (at(2 * x, 2 * y) + at(2 * x + 1, 2 * y) +
                                           at(2 * x, 2 * y + 1) + at(2 * x + 1, 2 * y + 1));
      }
    }
  }
  return {width: w, height: h, rgb};
}

function base64(bytes) {
  let s = '';
  for (let i = 0; i < bytes.length; i += 8192) {
    s += String.fromCharCode(...bytes.subarray(i, i + 8192));
  }
  return btoa(s);
}

window.prtPage = {
  /** Which pixels the mesh covers (base64 of one byte per pixel, rows from the top). */
  meshMask() {
    return base64(app.view.meshMask());
  },
  /** The radiance drawn now, 3 floats per sample (a copy, as a plain array). */
  radiance() {
    return Array.from(app.view.radiance ? app.view.radiance.array : app.view.rgb);
  },
  /**
   * A glossy pack's steps timed as prt-runtime-bench times them (docs/runtime.md, "Glossy
   * packs"): an orbit step (set_eye 0.02 rad further about the target, relight) and a rotation
   * step in preview (set_rotation_y 0.01 rad further, relight), `frames` each after 2 untimed;
   * also the same with upload and drawing. Medians in ms. Leaves the view as it found it.
   */
  glossyBenchmark({frames = 20} = {}) {
    const p = app.pack;
    const o0 = app.orbit, a0 = app.angle;
    const run = (step, draw) => {
      const t = [];
      for (let f = 0; f < frames + 2; ++f) {
        const t0 = performance.now();
        step(f);
        const rgb = p.relight(0);
        if (draw) {
          app.view.setRadiance(rgb);
          app.view.render();
        }
        if (f >= 2) t.push(performance.now() - t0);
      }
      return median(t);
    };
    const orbit = (f) => p.setEye(orbitEye(o0 + 0.02 * f));
    const rotate = (f) => p.setRotationY(a0 + 0.01 * f);
    const out = {samples: stats.samples, n: stats.cubemapSize, frames};
    out.orbitStepMs = run(orbit, false);
    out.orbitStepDrawnMs = run(orbit, true);
    p.setEye(orbitEye(o0));
    p.setPreview(true);
    out.rotationStepPreviewMs = run(rotate, false);
    out.rotationStepPreviewDrawnMs = run(rotate, true);
    p.setPreview(false);
    out.rotationStepExactMs = run(rotate, false);
    p.setPreview(app.preview);
    p.setRotationY(a0);
    applyOrbit();
    exactFrame();
    return out;
  },
  /** An image pack's drawn pixels: {width, height, rgb: base64 of RGB bytes, rows from the top}. */
  imagePixels() {
    const v = app.view;
    return {width: v.width, height: v.height, rgb: base64(v.pixels())};
  },
  /**
   * Times the runtime in this page as bench/runtime_bench.cpp times the native C API: frames of
   * `terms` (0 exact, else PBI restarted from no light) under a rotating environment (rotate by
   * 0.01 rad, untimed, then time the relight; the first 2 frames warm up), and set_rotation_y
   * alone with the full map and with preview; and set_rotation_y from the map averaged down to
   * each width of `mapWidths` (where the rotation's time goes: docs/web.md, "Figures"). Medians
   * in ms. Leaves the view as it found it.
   */
  benchmark({frames = 30, budgets = [0, 30, 100, 300], mapWidths = []} = {}) {
    const p = app.pack;
    const a0 = app.angle;
    const time = (fn) => {
      const t0 = performance.now();
      fn();
      return performance.now() - t0;
    };
    const out = {budget: stats.budget, samples: stats.samples, n: stats.cubemapSize, frames,
                 relightMs: {}};
    for (const terms of budgets) {
      p.setLightingMode(0);  // NWA then PBI: restarts PBI from no light
      p.setLightingMode(2);
      const t = [];
      for (let f = 0; f < frames + 2; ++f) {
        p.setRotationY(a0 + 0.01 * f);
        const ms = time(() => p.relight(terms));
        if (f >= 2) t.push(ms);
      }
      out.relightMs[terms] = median(t);
    }
    for (const preview of [false, true]) {
      p.setPreview(preview);
      const t = Array.from({length: frames}, (_, f) => time(() => p.setRotationY(a0 + 0.01 * f)));
      out[preview ? 'rotatePreviewMs' : 'rotateFullMs'] = median(t);
    }
    p.setPreview(false);
    out.rotateByMapWidthMs = {};
    let map = app.env;
    for (const w of [...mapWidths].sort((x, y) => y - x)) {
      while (map.width > w && map.height >= 4) map = halveMap(map);
      p.setEnvironment(map.rgb, map.width, map.height);
      const t = Array.from({length: 10}, (_, f) => time(() => p.setRotationY(a0 + 0.01 * f)));
      out.rotateByMapWidthMs[map.width] = median(t);
    }
    if (mapWidths.length) p.setEnvironment(app.env.rgb, app.env.width, app.env.height);
    p.setPreview(app.preview);
    p.setRotationY(a0);
    exactFrame();
    convergeSilently();
    return out;
  },
  /**
   * The page's own loop rotating the environment, as a drag does but without input events: every
   * animation frame for `ms` turns the map by `step` radians in preview (set_rotation_y), relights
   * one PBI frame of the budget and draws it (`relight` false: only the background turns and the
   * frame is drawn; `draw` false: nothing is drawn). Resolves to fps and per-frame medians in
   * ms; then the page converges on the full map as after a drag.
   */
  spin({ms = 3000, step = 0.02, relight = true, draw = true} = {}) {
    const p = app.pack;
    app.spinning = true;
    p.setPreview(true);
    app.preview = true;
    const split = {rotate: [], relight: [], draw: []};
    let n = 0;
    const t0 = performance.now();
    return new Promise((resolve, reject) => {
      const frame = () => {
        try {
          const t1 = performance.now();
          app.angle += step;
          if (relight) p.setRotationY(app.angle);
          const t2 = performance.now();
          if (relight) app.view.setRadiance(p.relight(stats.budget));
          const t3 = performance.now();
          app.view.setRotation(app.angle);
          if (draw) app.view.render();
          const t4 = performance.now();
          split.rotate.push(t2 - t1);
          split.relight.push(t3 - t2);
          split.draw.push(t4 - t3);
          ++n;
          if (t4 - t0 < ms) {
            requestAnimationFrame(frame);
            return;
          }
          const seconds = (performance.now() - t0) / 1000;
          p.setPreview(false);
          app.preview = false;
          if (relight) {
            app.appliedAngle = app.angle;
          } else {
            app.appliedAngle = NaN;  // the lighting is behind the view: the loop catches up
          }
          app.framesLeft = framesToConverge();
          stats.converged = false;
          app.spinning = false;
          resolve({fps: n / seconds, frames: n, rotateMs: median(split.rotate),
                   relightMs: median(split.relight), drawMs: median(split.draw)});
        } catch (e) {
          app.spinning = false;
          reject(e);
        }
      };
      requestAnimationFrame(frame);
    });
  },
};

// ---- Wiring ----------------------------------------------------------------------------------

for (const [key, id] of [['exposure', 'exposure'], ['budget', 'budget']]) {
  if (params.has(key)) $(id).value = params.get(key);
}
if (params.has('rotate')) app.angle = (Number(params.get('rotate')) * Math.PI) / 180 || 0;
stats.exposure = Number($('exposure').value) || 1;
stats.budget = Math.max(1, Math.round(Number($('budget').value)) || 100);
$('exposure').addEventListener('input', readControls);
$('budget').addEventListener('change', readControls);
$('pack-file').addEventListener('change', (ev) => loadFiles([...ev.target.files]));
$('env-file').addEventListener('change', (ev) => loadFiles([...ev.target.files]));
document.addEventListener('dragover', (ev) => {
  ev.preventDefault();
  document.body.classList.add('dragover');
});
document.addEventListener('dragleave', () => document.body.classList.remove('dragover'));
document.addEventListener('drop', (ev) => {
  ev.preventDefault();
  document.body.classList.remove('dragover');
  // The environment first, so that a pack dropped with it starts at once.
  const files = [...ev.dataTransfer.files].sort((a, b) =>
    Number(/\.(hdr|pic)$/i.test(b.name)) - Number(/\.(hdr|pic)$/i.test(a.name)));
  loadFiles(files);
});
attachDrag($('gl'));
attachDrag($('image'));
updateStatsText();
requestAnimationFrame(tick);
loadFromUrl();
