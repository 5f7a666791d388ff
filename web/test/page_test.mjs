// The web page's test (ctest web_page; docs/web.md "The test"): Debian's headless Chromium, driven
// by puppeteer-core, over build-wasm/site with a small pack.
//  (a) the page's image of the pack (its baked camera, exact lighting, the same exposure) matches
//      prt-view's PNG of the same view and lighting on the mesh's pixels: mean |difference| at
//      most 1 % of full scale (2.55 of 255) and 99 % of the pixels within 10/255 in every channel,
//      over the mesh's pixels less a one-pixel border (edges rasterise differently);
//  (b) a corrupt pack shows the runtime's error message on the page (no blank canvas, no hang),
//      and so does a truncated .hdr (the page's reader's message);
//  (c) frame times come back from the page (window.prtStats and the #stats text) after a drag
//      that rotates the environment (preview and PBI frames), and the page converges after it;
//  (d) an image pack and the map chosen through the page's file inputs: the pack is drawn as an
//      image (2D canvas), its pixels within the tolerance of (a) of prt-view's image of it;
//  (e) an orbit step (right-button drag) on the diffuse pack draws it again from the new eye
//      without relighting it (its radiance unchanged);
//  (f) a glossy pack (visibility, relit by triple products towards the eye): its image from the
//      pack's camera against prt-view's within the tolerance of (a); an orbit step relights it
//      (its radiance changes) and the page's image from the new eye matches prt-view's image
//      towards the same eye (--prt-view runs it), and the glossy frame times are reported.
// With --measure it prints the figures of docs/web.md instead (prtPage.benchmark(), load to first
// frame, bytes downloaded, fps while dragging) and checks nothing; --screenshot PATH then saves
// the whole page after the drag (docs/images/web-runtime.png).
//
// node web/test/page_test.mjs --site build-wasm/site --pack P.prtpack --env E.hdr
//     [--reference prt-view.png --exposure E --corrupt C.prtpack --out-dir DIR]
//     [--image-pack I.prtpack --image-reference prt-view-image.png] [--bad-env TRUNCATED.hdr]
//     [--glossy-pack G.prtpack --glossy-reference prt-view-glossy.png --prt-view PRT_VIEW]
//     [--terms-pack T.prtpack --terms-reference prt-view-terms.png]
//     [--measure [--screenshot PATH]]
import {execFileSync} from 'node:child_process';
import {createServer} from 'node:http';
import {readFileSync, writeFileSync, mkdirSync, existsSync, statSync} from 'node:fs';
import {extname, join, resolve, normalize} from 'node:path';
import puppeteer from 'puppeteer-core';
import {decodePng} from './png.mjs';

const kMeanTolerance = 0.01;     // mean |page − prt-view| over mesh pixels, fraction of 255
const kPixelTolerance = 10;      // per channel, out of 255 ...
const kPixelFraction = 0.99;     // ... for at least this fraction of the mesh pixels

function parseArgs(argv) {
  const a = {chromium: '/usr/bin/chromium', exposure: '1', outDir: 'web_page_out', timeout: 90};
  for (let i = 2; i < argv.length; ++i) {
    const k = argv[i];
    if (k === '--measure') a.measure = true;
    else if (k.startsWith('--')) a[k.slice(2).replace(/-(\w)/g, (_, c) => c.toUpperCase())] = argv[++i];
    else throw new Error(`unknown argument ${k}`);
  }
  for (const k of ['site', 'pack', 'env']) if (!a[k]) throw new Error(`--${k} is required`);
  return a;
}

const kTypes = {'.html': 'text/html', '.js': 'text/javascript', '.mjs': 'text/javascript',
                '.css': 'text/css', '.wasm': 'application/wasm'};

// The site, plus the test's files under /data/<name>.
function serve(site, files) {
  const server = createServer((req, res) => {
    const path = decodeURIComponent(new URL(req.url, 'http://x').pathname);
    let file = files[path];
    if (!file) {
      file = normalize(join(site, path === '/' ? 'index.html' : path));
      if (!file.startsWith(resolve(site)) || !existsSync(file) || !statSync(file).isFile()) {
        res.writeHead(404).end('not found');
        return;
      }
    }
    const body = readFileSync(file);
    res.writeHead(200, {'Content-Type': kTypes[extname(file)] ?? 'application/octet-stream',
                        'Content-Length': body.length, 'Cache-Control': 'no-store'});
    res.end(body);
  });
  return new Promise((ok) => server.listen(0, '127.0.0.1', () => ok(server)));
}

async function openPage(browser, url, log, waitForPack = true) {
  const page = await browser.newPage();
  page.on('console', (m) => log.push(`[console.${m.type()}] ${m.text()}`));
  page.on('pageerror', (e) => log.push(`[pageerror] ${e.message}`));
  await page.setViewport({width: 1180, height: 560, deviceScaleFactor: 1});
  await page.goto(url, {waitUntil: 'load'});
  if (waitForPack) {
    await page.waitForFunction(
        () => ['ready', 'error'].includes(document.body.dataset.state), {timeout: 60000});
  }
  return page;
}

// Mean and spread of |a − b| over the mask's pixels, less a one-pixel border when `erode`.
function compareMesh(page, ref, mask, w, h, erode = true) {
  let n = 0, sum = 0, within = 0, max = 0;
  const b = erode ? 1 : 0;
  for (let y = b; y < h - b; ++y) {
    for (let x = b; x < w - b; ++x) {
      const i = y * w + x;
      if (!mask[i]) continue;
      if (erode && !(mask[i - 1] && mask[i + 1] && mask[i - w] && mask[i + w])) continue;
      let worst = 0;
      for (let c = 0; c < 3; ++c) {
        const d = Math.abs(page[3 * i + c] - ref[3 * i + c]);
        sum += d;
        worst = Math.max(worst, d);
      }
      max = Math.max(max, worst);
      if (worst <= kPixelTolerance) ++within;
      ++n;
    }
  }
  return {pixels: n, mean: n ? sum / (3 * n * 255) : NaN, within: n ? within / n : 0, max};
}

// A drag across the view: the left button rotates the lighting, the right one orbits the camera
// (by 2π × `span` of the canvas width).
async function drag(page, steps, stepMs, button = 'left', span = 0.4) {
  const box = await (await page.$('#gl')).boundingBox();
  const y = box.y + box.height / 2;
  const x0 = box.x + box.width * 0.3;
  await page.mouse.move(x0, y);
  await page.mouse.down({button});
  for (let i = 1; i <= steps; ++i) {
    await page.mouse.move(x0 + (box.width * span * i) / steps, y);
    await new Promise((r) => setTimeout(r, stepMs));
  }
  await page.mouse.up({button});
}

// Idle: no frame for half a second (and converged).
async function settle(page) {
  await page.waitForFunction(() => {
    const s = window.prtStats;
    return s.frames.length && s.converged && performance.now() - s.lastFrameAt > 500;
  }, {timeout: 60000, polling: 100});
}

// max |a − b| / max |b| over two radiance arrays.
function relativeChange(a, b) {
  let d = 0, m = 0;
  for (let i = 0; i < a.length; ++i) {
    d = Math.max(d, Math.abs(a[i] - b[i]));
    m = Math.max(m, Math.abs(b[i]));
  }
  return m > 0 ? d / m : d;
}

// The page's canvas against a prt-view PNG on the mesh's pixels (a): logs and checks.
async function compareWithPrtView(page, shot, reference, what, check) {
  const got = decodePng(readFileSync(shot));
  const ref = decodePng(readFileSync(reference));
  check(got.width === ref.width && got.height === ref.height,
        `${what}: page ${got.width}×${got.height} = prt-view ${ref.width}×${ref.height}`);
  const mask = Buffer.from(await page.evaluate(() => window.prtPage.meshMask()), 'base64');
  const r = compareMesh(got.rgb, ref.rgb, mask, got.width, got.height);
  console.log(`${what}: mesh pixels ${r.pixels}: mean |page − prt-view| ` +
              `${(100 * r.mean).toFixed(3)} % of full scale, ${(100 * r.within).toFixed(2)} % ` +
              `within ${kPixelTolerance}/255, max ${r.max}/255`);
  check(r.pixels > 0.05 * got.width * got.height, `${what}: the mesh covers > 5 % of the image`);
  check(r.mean <= kMeanTolerance, `${what}: mean difference ≤ ${100 * kMeanTolerance} %`);
  check(r.within >= kPixelFraction,
        `${what}: ≥ ${100 * kPixelFraction} % of mesh pixels within ${kPixelTolerance}/255`);
}

// An orbit step (a right-button drag across the canvas): the stats after it, its orbit frames
// and how much the radiance changed (relativeChange).
async function orbitStep(page, before) {
  const r0 = await page.evaluate(() => window.prtPage.radiance());
  const n0 = before.frames.length;
  await drag(page, 8, 30, 'right', 0.08);
  await settle(page);
  const after = await page.evaluate(() => window.prtStats);
  const steps = after.frames.slice(n0 - after.frames.length).filter((f) => f.orbit);
  const r1 = await page.evaluate(() => window.prtPage.radiance());
  return {after, steps, change: relativeChange(r1, r0)};
}

// The page's view after an orbit step against prt-view's of `pack` towards the page's new eye
// (files `<name>-orbit.png` and `prt-view-<name>-orbit.png` in the output folder).
async function compareOrbitWithPrtView(a, page, after, pack, name, label, viewArgs, check) {
  const shot = join(a.outDir, `${name}-orbit.png`);
  await (await page.$('#gl')).screenshot({path: shot});
  const ref = join(a.outDir, `prt-view-${name}-orbit.png`);
  const spec = [...after.eye, ...after.target].map((x) => x.toPrecision(9)).join(',');
  execFileSync(a.prtView, [resolve(pack), '--env', resolve(a.env), '--exposure', a.exposure,
                           ...viewArgs, '--camera', spec, '--out', ref, '--quiet']);
  await compareWithPrtView(page, shot, ref, `${label}, orbited`, check);
}

async function main() {
  const a = parseArgs(process.argv);
  mkdirSync(a.outDir, {recursive: true});
  const files = {'/data/pack.prtpack': resolve(a.pack), '/data/env.hdr': resolve(a.env)};
  if (a.glossyPack) files['/data/glossy.prtpack'] = resolve(a.glossyPack);
  if (a.termsPack) files['/data/terms.prtpack'] = resolve(a.termsPack);
  if (a.corrupt) files['/data/corrupt.prtpack'] = resolve(a.corrupt);
  if (a.badEnv) files['/data/truncated.hdr'] = resolve(a.badEnv);
  const server = await serve(resolve(a.site), files);
  const base = `http://127.0.0.1:${server.address().port}`;
  const browser = await puppeteer.launch({
    executablePath: a.chromium,
    headless: true,
    args: ['--headless=new', '--no-sandbox', '--use-gl=angle', '--use-angle=swiftshader',
           '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist', '--window-size=1200,900'],
  });
  const log = [];
  const failures = [];
  const check = (ok, what) => {
    console.log(`${ok ? 'ok  ' : 'FAIL'} ${what}`);
    if (!ok) failures.push(what);
  };
  try {
    const url = `${base}/index.html?pack=/data/pack.prtpack&env=/data/env.hdr` +
                `&exposure=${a.exposure}${a.budget ? `&budget=${a.budget}` : ''}`;
    const page = await openPage(browser, url, log);
    const s0 = await page.evaluate(() => window.prtStats);
    check(s0.state === 'ready', `the page opens the pack (state ${s0.state}${s0.error ? `: ${s0.error}` : ''})`);
    if (s0.state !== 'ready') throw new Error('the page did not open the pack');
    const shot = join(a.outDir, 'page.png');
    await (await page.$(s0.isImage ? '#image' : '#gl')).screenshot({path: shot});

    if (a.measure && s0.isGlossy) {  // a glossy pack: its orbit and rotation steps
      const bench = await page.evaluate(() => window.prtPage.glossyBenchmark({frames: 10}));
      await drag(page, 20, 16, 'right', 0.1);
      await settle(page);
      const s = await page.evaluate(() => window.prtStats);
      const orbit = s.frames.filter((f) => f.orbit && f.glossy);
      const med = (xs) => [...xs].sort((p, q) => p - q)[Math.floor(xs.length / 2)];
      console.log(JSON.stringify({
        pack: a.pack, samples: s.samples, n: s.cubemapSize, ...bench,
        orbitDragFrames: orbit.length, orbitDragFps: s.orbitFps,
        orbitDragFrameMedianMs: med(orbit.map((f) => f.totalMs)),
        orbitDragRelightMedianMs: med(orbit.map((f) => f.relightMs)),
        exactRelightMs: s0.exactRelightMs, openMs: s0.openMs,
        loadToFirstFrameMs: s0.loadToFirstFrameMs, memoryBytes: s0.memoryBytes,
        wasmHeapBytes: s0.wasmHeapBytes,
      }, null, 1));
      return;
    }
    if (a.measure) {
      const bench = await page.evaluate(() => window.prtPage.benchmark({frames: 30,
                                                                        mapWidths: [1024, 512, 256, 128]}));
      // The page's loop rotating by itself: as a drag, and drawing alone (no relight).
      const spin = await page.evaluate(() => window.prtPage.spin({ms: 3000}));
      await page.waitForFunction(() => window.prtStats.converged, {timeout: 60000});
      const spinDraw = await page.evaluate(() => window.prtPage.spin({ms: 3000, relight: false}));
      await page.waitForFunction(() => window.prtStats.converged, {timeout: 60000});
      const raf = await page.evaluate(() => new Promise((ok) => {
        let n = 0;
        const t0 = performance.now();
        const f = () => (++n, performance.now() - t0 < 2000 ? requestAnimationFrame(f)
                                                             : ok(n / ((performance.now() - t0) / 1000)));
        requestAnimationFrame(f);
      }));
      await drag(page, 120, 16);
      await page.waitForFunction(() => window.prtStats.dragFps !== null, {timeout: 30000});
      await page.waitForFunction(() => window.prtStats.converged, {timeout: 60000});
      const s = await page.evaluate(() => window.prtStats);
      if (a.screenshot) await page.screenshot({path: a.screenshot});
      const dragFrames = s.frames.filter((f) => f.rotateMs > 0);
      const med = (xs) => [...xs].sort((p, q) => p - q)[Math.floor(xs.length / 2)];
      console.log(JSON.stringify({
        pack: a.pack, samples: s.samples, n: s.cubemapSize, budget: s.budget, ...bench,
        loadToFirstFrameMs: s0.loadToFirstFrameMs, openMs: s0.openMs, load: s0.load,
        bytesDownloaded: s0.bytesDownloaded, dragFps: s.dragFps, dragFrames: s.dragFrames,
        dragFrameMedianMs: med(dragFrames.map((f) => f.totalMs)),
        dragRotateMedianMs: med(dragFrames.map((f) => f.rotateMs)),
        dragRelightMedianMs: med(dragFrames.map((f) => f.relightMs)),
        dragDrawMedianMs: med(dragFrames.map((f) => f.drawMs)),
        spin, spinDrawOnly: spinDraw, rafOnlyFps: raf,
        memoryBytes: s0.memoryBytes, wasmHeapBytes: s0.wasmHeapBytes,
      }, null, 1));
      return;
    }

    // (a) the image against prt-view's.
    if (a.reference) {
      const got = decodePng(readFileSync(shot));
      const ref = decodePng(readFileSync(a.reference));
      check(got.width === ref.width && got.height === ref.height,
            `page ${got.width}×${got.height} = prt-view ${ref.width}×${ref.height}`);
      const mask = Buffer.from(await page.evaluate(() => window.prtPage.meshMask()), 'base64');
      const r = compareMesh(got.rgb, ref.rgb, mask, got.width, got.height);
      console.log(`mesh pixels ${r.pixels}: mean |page − prt-view| ${(100 * r.mean).toFixed(3)} % ` +
                  `of full scale, ${(100 * r.within).toFixed(2)} % within ${kPixelTolerance}/255, ` +
                  `max ${r.max}/255`);
      check(r.pixels > 0.05 * got.width * got.height, 'the mesh covers > 5 % of the image');
      check(r.mean <= kMeanTolerance, `mean difference ≤ ${100 * kMeanTolerance} %`);
      check(r.within >= kPixelFraction,
            `≥ ${100 * kPixelFraction} % of mesh pixels within ${kPixelTolerance}/255`);
    }

    // (c) frame times after a drag that rotates the environment.
    await drag(page, 30, 20);
    await page.waitForFunction(() => window.prtStats.dragFps !== null, {timeout: 30000});
    // Converged: no frame for a while once PBI has reached the exact lighting.
    await page.waitForFunction(() => {
      const f = window.prtStats.frames;
      return f.length && window.prtStats.converged &&
             performance.now() - window.prtStats.lastFrameAt > 500;
    }, {timeout: 60000, polling: 100});
    const s = await page.evaluate(() => window.prtStats);
    const text = await page.$eval('#stats', (e) => e.textContent);
    const rotated = s.frames.filter((f) => f.rotateMs > 0);
    const pbi = s.frames.filter((f) => f.terms > 0);
    console.log(`frames ${s.frames.length}: ${rotated.length} rotated (preview ${rotated.filter((f) => f.preview).length}), ` +
                `drag ${s.dragFps.toFixed(1)} fps, last frame ${s.lastFrameMs.toFixed(2)} ms, ` +
                `exact ${s.exactRelightMs.toFixed(2)} ms`);
    check(rotated.length > 0 && rotated.every((f) => f.preview),
          'dragging rotated the environment in preview frames');
    check(pbi.length > rotated.length, 'PBI frames went on after the drag');
    check(s.frames.every((f) => Number.isFinite(f.totalMs) && f.totalMs >= 0),
          'every frame time is a finite number');
    check(s.dragFps > 0 && Number.isFinite(s.exactRelightMs), 'fps and exact time in prtStats');
    check(/frame time\s+[\d.]+ ms/.test(text) && /term budget\s+\d+/.test(text),
          'frame time and term budget in the #stats text');
    check(s.converged && !s.preview, 'converged to the full map after the drag');

    // (e) an orbit step on the diffuse pack: drawn again from the new eye, nothing relit.
    const before = await page.evaluate(() => window.prtPage.radiance());
    const framesBefore = s.frames.length;
    await drag(page, 10, 20, 'right', 0.1);
    await settle(page);
    const so = await page.evaluate(() => window.prtStats);
    const orbited = so.frames.slice(framesBefore - so.frames.length).filter((f) => f.orbit);
    const after = await page.evaluate(() => window.prtPage.radiance());
    console.log(`diffuse orbit: ${orbited.length} frames to ${so.orbitDeg.toFixed(1)}°, ` +
                `median ${orbited.length ? orbited.map((f) => f.totalMs).sort((p, q) => p - q)[orbited.length >> 1].toFixed(2) : '–'} ms`);
    check(orbited.length > 0 && Math.abs(so.orbitDeg) > 1, 'a right-button drag orbits the camera');
    check(orbited.every((f) => f.relightMs === 0 && f.terms === 0),
          'a diffuse pack\'s orbit frames only draw');
    check(relativeChange(after, before) === 0, 'a diffuse pack\'s radiance does not follow the eye');
    await page.close();

    // (d) an image pack, opened through the file inputs (the map first, then the pack).
    if (a.imagePack) {
      const p = await openPage(browser, `${base}/index.html?exposure=${a.exposure}`, log, false);
      await (await p.$('#env-file')).uploadFile(resolve(a.env));
      await p.waitForFunction(() => window.prtStats.env !== null, {timeout: 30000});
      await (await p.$('#pack-file')).uploadFile(resolve(a.imagePack));
      await p.waitForFunction(() => ['ready', 'error'].includes(window.prtStats.state) &&
                                    window.prtStats.pack !== null, {timeout: 60000});
      const st = await p.evaluate(() => ({state: window.prtStats.state, error: window.prtStats.error,
                                          isImage: window.prtStats.isImage,
                                          image: !document.getElementById('image').hidden,
                                          gl: !document.getElementById('gl').hidden}));
      check(st.state === 'ready' && st.isImage && st.image && !st.gl,
            `an image pack from the file inputs is drawn as an image (${st.state}${st.error ? `: ${st.error}` : ''})`);
      if (st.state === 'ready' && a.imageReference) {
        const img = await p.evaluate(() => window.prtPage.imagePixels());
        const ref = decodePng(readFileSync(a.imageReference));
        const rgb = Buffer.from(img.rgb, 'base64');
        check(img.width === ref.width && img.height === ref.height,
              `image ${img.width}×${img.height} = prt-view ${ref.width}×${ref.height}`);
        const all = new Uint8Array(img.width * img.height).fill(1);
        const r = compareMesh(rgb, ref.rgb, all, img.width, img.height, false);
        console.log(`image pixels ${r.pixels}: mean |page − prt-view| ${(100 * r.mean).toFixed(3)} %, ` +
                    `${(100 * r.within).toFixed(2)} % within ${kPixelTolerance}/255, max ${r.max}/255`);
        check(r.mean <= kMeanTolerance && r.within >= kPixelFraction,
              'the image pack matches prt-view within the tolerance');
      }
      await p.close();
    }

    // (g) a glossy vertex pack (BRDF terms, docs/glossy-transport.md): prt-view's image from its
    // camera, then an orbit step combines the terms again for the new eye (prt_runtime_reshade,
    // no relight) and matches prt-view towards that eye.
    if (a.termsPack) {
      const t = await openPage(browser, `${base}/index.html?pack=/data/terms.prtpack` +
                                            `&env=/data/env.hdr&exposure=${a.exposure}`, log);
      const ts = await t.evaluate(() => window.prtStats);
      check(ts.state === 'ready' && !ts.isGlossy,
            `the page opens the glossy vertex pack (${ts.state}${ts.error ? `: ${ts.error}` : ''})`);
      if (ts.state === 'ready') {
        const tshot = join(a.outDir, 'terms.png');
        await (await t.$('#gl')).screenshot({path: tshot});
        if (a.termsReference)
          await compareWithPrtView(t, tshot, a.termsReference, 'glossy terms, the pack\'s camera',
                                   check);
        const {after: to, steps, change} = await orbitStep(t, ts);
        console.log(`glossy terms orbit: ${steps.length} frames to ${to.orbitDeg.toFixed(1)}°, ` +
                    `radiance changed by ${(100 * change).toFixed(2)} % of its max`);
        check(steps.length > 0 && steps.every((f) => f.relightMs >= 0 && Number.isFinite(f.totalMs)),
              'an orbit step recombines the glossy vertex pack\'s terms');
        check(change > 1e-3, 'the glossy vertex radiance follows the eye');
        if (a.prtView && a.termsReference)
          await compareOrbitWithPrtView(a, t, to, a.termsPack, 'terms', 'glossy terms', ['--exact'],
                                        check);
      }
      await t.close();
    }

    // (f) a glossy pack: prt-view's image from its camera, then an orbit step relights it.
    if (a.glossyPack) {
      const g = await openPage(browser, `${base}/index.html?pack=/data/glossy.prtpack` +
                                            `&env=/data/env.hdr&exposure=${a.exposure}`, log);
      const gs = await g.evaluate(() => window.prtStats);
      check(gs.state === 'ready' && gs.isGlossy,
            `the page opens the glossy pack (${gs.state}${gs.error ? `: ${gs.error}` : ''})`);
      if (gs.state === 'ready') {
        const gshot = join(a.outDir, 'glossy.png');
        await (await g.$('#gl')).screenshot({path: gshot});
        if (a.glossyReference) {
          await compareWithPrtView(g, gshot, a.glossyReference, 'glossy, the pack\'s camera',
                                   check);
        }
        const {after: go, steps: orbit, change} = await orbitStep(g, gs);
        const steps = orbit.filter((f) => f.glossy);
        const med = (xs) => [...xs].sort((p, q) => p - q)[xs.length >> 1];
        console.log(`glossy orbit: ${steps.length} frames to ${go.orbitDeg.toFixed(1)}°, frame ` +
                    `median ${steps.length ? med(steps.map((f) => f.totalMs)).toFixed(2) : '–'} ms ` +
                    `(relight ${steps.length ? med(steps.map((f) => f.relightMs)).toFixed(2) : '–'} ms), ` +
                    `radiance changed by ${(100 * change).toFixed(2)} % of its max`);
        check(steps.length > 0 && steps.every((f) => f.relightMs > 0 && Number.isFinite(f.totalMs)),
              'an orbit step relights the glossy pack');
        check(change > 1e-3, 'the glossy radiance follows the eye');
        const text = await g.$eval('#stats', (e) => e.textContent);
        check(/glossy frame\s+[\d.]+ ms/.test(text), 'the glossy frame time in the #stats text');
        if (a.prtView && a.glossyReference)
          await compareOrbitWithPrtView(a, g, go, a.glossyPack, 'glossy', 'glossy', [], check);
        const bench = await g.evaluate(() => window.prtPage.glossyBenchmark({frames: 10}));
        console.log(`glossy steps in the page: ${JSON.stringify(bench)}`);
      }
      await g.close();
    }

    // (b) a corrupt pack: the runtime's message on the page.
    if (a.corrupt) {
      const bad = await openPage(browser, `${base}/index.html?pack=/data/corrupt.prtpack` +
                                              '&env=/data/env.hdr', log);
      const e = await bad.evaluate(() => ({state: window.prtStats.state,
                                           error: window.prtStats.error,
                                           shown: !document.getElementById('error').hidden,
                                           text: document.getElementById('error').textContent}));
      console.log(`corrupt pack: ${e.text}`);
      check(e.state === 'error' && e.shown, 'a corrupt pack shows an error');
      check(/^Cannot open .*corrupt\.prtpack: .{10,}/.test(e.text) && e.text === e.error,
            'the error names the pack and carries the runtime\'s message');
      await bad.close();
    }
    if (a.badEnv) {
      const bad = await openPage(browser, `${base}/index.html?pack=/data/pack.prtpack` +
                                              '&env=/data/truncated.hdr', log);
      const e = await bad.evaluate(() => ({state: window.prtStats.state,
                                           shown: !document.getElementById('error').hidden,
                                           text: document.getElementById('error').textContent}));
      console.log(`truncated map: ${e.text}`);
      check(e.state === 'error' && e.shown && /truncated\.hdr: truncated in scanline \d+/.test(e.text),
            'a truncated .hdr shows the reader\'s error');
      await bad.close();
    }
  } finally {
    await browser.close();
    server.close();
    writeFileSync(join(a.outDir, 'console.log'), log.join('\n') + '\n');
    if (failures.length) {
      console.log(log.join('\n'));
      console.log(`web_page: ${failures.length} check(s) failed`);
      process.exitCode = 1;
    }
  }
}

main().catch((e) => {
  console.error(`web_page: ${e.stack ?? e}`);
  process.exitCode = 1;
});
