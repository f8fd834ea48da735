// helpers.mjs: what the browser tests share: a daemon on loopback, headless Chromium,
// pixel statistics of the view's canvas, a depth probe of the view, and anatomical
// landmarks of real scans read straight from their files (so that "face toward the viewer,
// forehead up" is judged against the anatomy, not against the viewer's own frame).
import { spawn } from 'node:child_process';
import { readFileSync } from 'node:fs';
import { createRequire } from 'node:module';
import { resolve } from 'node:path';
import { gunzipSync } from 'node:zlib';

const require = createRequire(resolve('web/node_modules') + '/');
export const { chromium } = require('playwright-core');

export const CHROMIUM_ARGS = ['--headless', '--no-sandbox', '--disable-gpu', '--use-angle=swiftshader',
  '--enable-unsafe-swiftshader', '--disable-background-networking', '--disable-component-update', '--disable-sync',
  '--disable-quic', '--no-first-run'];

// isoserve serve on 127.0.0.1:0; resolves with the process, its port on .port, when it
// says where it listens.
export function startServer(catalog, extra = []) {
  return new Promise((resolvePort, reject) => {
    const proc = spawn(resolve(process.env.ISOSERVE_BIN || 'build/isoserve'), ['serve', '--catalog', catalog,
      '--listen', '127.0.0.1:0', ...extra], { stdio: ['ignore', 'ignore', 'pipe'] });
    let log = '';
    proc.stderr.on('data', (d) => {
      log += d;
      const m = /listening on http:\/\/127\.0\.0\.1:(\d+)\//.exec(log);
      if (m && !proc.port) { proc.port = Number(m[1]); resolvePort(proc); }
    });
    proc.log = () => log;
    proc.on('exit', (code) => { if (!proc.port) reject(new Error(`server exited ${code}: ${log}`)); });
  });
}

export async function waitReady(port) {
  for (let i = 0; i < 1200; i++) {
    try { if ((await fetch(`http://127.0.0.1:${port}/healthz`)).status === 200) return; } catch { /* not yet */ }
    await new Promise((r) => setTimeout(r, 50));
  }
  throw new Error('server not ready');
}

export async function stopServer(proc) {
  if (proc.exitCode !== null) return;
  proc.kill('SIGTERM');
  await new Promise((r) => proc.on('exit', r));
}

// Waits until every surface that is on (and drawn: not under segments alone) has the full
// mesh of the state's level, tolerance and detail drawn, every segment shown is loaded and
// nothing is pending, then until that frame is on the canvas.
export async function settled(page, timeout = 120000) {
  await page.waitForFunction(() => {
    const v = window.isoViewer;
    if (!v?.ctx?.loader) return false;
    const { state, loader } = v.ctx;
    // The volume opened; a segmentation's segments: listed, every one shown here, nothing
    // on its way (the surfaces may be off: a page that has not opened it yet is not settled).
    const segs = v.ctx.segs;
    if (!v.ctx.info() || (state.seg.id && segs?.id !== state.seg.id)) return false;
    if (segs?.id && (!segs.list.length || segs.pending() ||
      segs.list.some((x) => (!state.seg.visible || state.seg.visible.has(x.number)) && !segs.loaded.has(x.number)))) return false;
    return state.surfaces.every((s, i) => {
      const d = loader.live[i].drawn;
      return !s.on || !v.ctx.shows() || (d?.kind === 'final' && d.level === s.level && d.tolerance === state.tolerance &&
        d.distance === state.distance && !loader.live[i].phase);
    });
  }, null, { timeout });
  await page.evaluate(() => window.isoViewer.view.drawn());
}

// Drawn shares of the canvas's left and right halves, and the shares of pixels whose
// colour leans red and blue (two surfaces drawn in those colours).
export async function pixelStats(page) {
  return page.evaluate(() => {
    const canvas = document.querySelector('#view canvas:not(.marker)');
    const copy = document.createElement('canvas');
    copy.width = canvas.width; copy.height = canvas.height;
    const ctx = copy.getContext('2d');
    ctx.drawImage(canvas, 0, 0);
    const { data } = ctx.getImageData(0, 0, copy.width, copy.height);
    const [r0, g0, b0] = [data[4 * (copy.width - 1)], data[4 * (copy.width - 1) + 1], data[4 * (copy.width - 1) + 2]];
    let left = 0, right = 0, red = 0, blue = 0;
    for (let i = 0; i < data.length; i += 4) {
      const [r, g, b] = [data[i], data[i + 1], data[i + 2]];
      if (Math.abs(r - r0) + Math.abs(g - g0) + Math.abs(b - b0) <= 30) continue;
      if ((i / 4) % copy.width < copy.width / 2) left++; else right++;
      if (r > b + 50 && r > g + 30) red++;
      if (b > r + 50 && b > g + 20) blue++;
    }
    const half = copy.width * copy.height / 2;
    return { left: left / half, right: right / half, red: red / (2 * half), blue: blue / (2 * half) };
  });
}

// The canvas's pixels as a data URL (equal strings: equal pictures).
export const canvasPixels = (page) => page.evaluate(() => document.querySelector('#view canvas:not(.marker)').toDataURL());

// Counts the pixels that differ between the canvas now and a picture taken before.
export async function pixelDifference(page, before) {
  return page.evaluate(async (url) => {
    const canvas = document.querySelector('#view canvas:not(.marker)');
    const img = new Image();
    img.src = url;
    await img.decode();
    const read = (source) => {
      const c = document.createElement('canvas');
      c.width = canvas.width; c.height = canvas.height;
      const x = c.getContext('2d');
      x.drawImage(source, 0, 0);
      return x.getImageData(0, 0, c.width, c.height).data;
    };
    const a = read(img), b = read(canvas);
    let differ = 0;
    for (let i = 0; i < a.length; i += 4) if (a[i] !== b[i] || a[i + 1] !== b[i + 1] || a[i + 2] !== b[i + 2]) differ++;
    return { differ, share: differ / (a.length / 4) };
  }, before);
}

// The view as the camera sees it, by depth: renders the surfaces with a material that
// writes each pixel's distance along the viewing axis (mm) into a float target, and
// returns the nearest drawn pixel, the topmost drawn row, and where index-space points
// project (through the volume's index_to_world, the viewer's axes correction and the
// camera): pixel x, y from the top left and their distance along the viewing axis.
export async function depthProbe(page, points) {
  return page.evaluate(async (points) => {
    const THREE = await import('./three/three.module.js');
    const v = window.isoViewer.view, info = window.isoViewer.ctx.info();
    const r = v.renderer, cam = v.camera.camera;
    const size = r.getDrawingBufferSize(new THREE.Vector2());
    const [w, h] = [size.x, size.y];
    const target = new THREE.WebGLRenderTarget(w, h, { type: THREE.FloatType });
    const material = new THREE.ShaderMaterial({
      side: THREE.DoubleSide,
      vertexShader: 'varying float vDepth; void main() { vec4 p = modelViewMatrix * vec4(position, 1.0); vDepth = -p.z; gl_Position = projectionMatrix * p; }',
      fragmentShader: 'varying float vDepth; void main() { gl_FragColor = vec4(vDepth, 0.0, 0.0, 1.0); }',
    });
    v.scene.overrideMaterial = material;
    r.setRenderTarget(target);
    r.setClearColor(0x000000, 0);
    r.clear();
    r.render(v.scene, cam);
    const buf = new Float32Array(w * h * 4);
    r.readRenderTargetPixels(target, 0, 0, w, h, buf);
    r.setRenderTarget(null);
    v.scene.overrideMaterial = null;
    v.background = window.isoViewer.state.light ? 0xf4f5f7 : 0x111418;
    target.dispose();
    material.dispose();
    let nearest = { depth: Infinity, x: -1, y: -1 }, top = -1, drawn = 0;
    for (let y = h - 1; y >= 0; y--) { // rows from the top of the picture
      for (let x = 0; x < w; x++) {
        const k = 4 * (y * w + x);
        if (buf[k + 3] === 0) continue;
        drawn++;
        if (top < 0) top = h - 1 - y;
        if (buf[k] < nearest.depth) nearest = { depth: buf[k], x, y: h - 1 - y };
      }
    }
    const m = info.index_to_world;
    const projected = points.map(([i, j, k]) => {
      const world = new THREE.Vector3(...[0, 1, 2].map((row) => m[4 * row] * i + m[4 * row + 1] * j + m[4 * row + 2] * k + m[4 * row + 3]));
      world.applyMatrix4(v.group.matrixWorld);
      const depth = -world.clone().applyMatrix4(cam.matrixWorldInverse).z;
      const ndc = world.clone().project(cam);
      return { x: (ndc.x + 1) / 2 * w, y: (1 - ndc.y) / 2 * h, depth };
    });
    return { nearest, top, drawn, width: w, height: h, projected, mmPerPixel: v.camera.mmPerPixel(h) };
  }, points);
}

// Anatomy: the face toward the viewer (the nearest drawn pixel is the face's most
// anterior point: there on screen, and at its depth) and the forehead up (the crown
// projects above it, at the top of what is drawn). `anterior` and `crown` are index-space
// points found in the scan itself. Returns [ok, why].
export async function faceForwardForeheadUp(page, { anterior, crown }) {
  const p = await depthProbe(page, [anterior, crown]);
  const [front, top] = p.projected;
  const near = Math.hypot(p.nearest.x - front.x, p.nearest.y - front.y);
  const why = JSON.stringify({ nearest: p.nearest, anterior: front, crown: top, topRow: p.top, mmPerPixel: p.mmPerPixel });
  const pixelsPerMm = 1 / p.mmPerPixel;
  const ok = p.drawn > 0.02 * p.width * p.height &&
    near <= 20 * pixelsPerMm && Math.abs(p.nearest.depth - front.depth) <= 8 && // the face is what is nearest
    top.y < front.y - 40 * pixelsPerMm && Math.abs(top.y - p.top) <= 12 * pixelsPerMm; // the crown on top
  return [ok, why];
}

// A NIfTI-1 (gzip) volume's dims and samples (uint8 only: the mricron templates).
export function readNiftiU8(path) {
  const b = gunzipSync(readFileSync(path));
  const dims = [0, 1, 2].map((a) => b.readInt16LE(42 + 2 * a));
  if (b.readInt16LE(70) !== 2) throw new Error(`${path}: not uint8`);
  const offset = Math.round(b.readFloatLE(108));
  return { dims, data: b.subarray(offset, offset + dims[0] * dims[1] * dims[2]), at: (i, j, k) => (k * dims[1] + j) * dims[0] + i };
}

// The shared CThead (uint16 big endian, 256x256x113) from its gzip raw file.
export function readCThead(path) {
  const b = gunzipSync(readFileSync(path));
  const dims = [256, 256, 113];
  return { dims, data: { length: dims[0] * dims[1] * dims[2] }, value: (n) => b.readUInt16BE(2 * n),
    at: (i, j, k) => (k * dims[1] + j) * dims[0] + i };
}

// The landmarks of a head scan above `level`: its most anterior voxel (the extreme of
// index axis `front.axis` in direction `front.sign`) and the crown (the centre of the
// voxels in the slices nearest the extreme of `up.axis` in direction `up.sign`). Which
// index direction is anterior and which superior is the scan's anatomy, found by looking at
// it (see the callers), not the viewer's frame.
export function headLandmarks(vol, level, front, up, value = (n) => vol.data[n]) {
  const [nx, ny, nz] = vol.dims;
  let best = null, crownEdge = null;
  const inside = [];
  for (let k = 0; k < nz; k++)
    for (let j = 0; j < ny; j++)
      for (let i = 0; i < nx; i++) {
        if (!(value(vol.at(i, j, k)) > level)) continue;
        const p = [i, j, k];
        const f = front.sign * p[front.axis], u = up.sign * p[up.axis];
        if (!best || f > best.f) best = { f, p };
        if (crownEdge === null || u > crownEdge) crownEdge = u;
        inside.push(p);
      }
  const top = inside.filter((p) => up.sign * p[up.axis] >= crownEdge - 3);
  const crown = [0, 1, 2].map((a) => top.reduce((s, p) => s + p[a], 0) / top.length);
  return { anterior: best.p, crown };
}

// The canvas's pixels by colour (red, green and blue segments, the beige default surface):
// per class the count and the centroid (canvas pixels from the top left); the colour at
// each of `points` (index-space points of the volume, projected as depthProbe does) with
// where it projects; and the canvas's mm per pixel.
export async function colourPixels(page, points = []) {
  return page.evaluate(async (points) => {
    const THREE = await import('./three/three.module.js');
    const v = window.isoViewer.view, info = window.isoViewer.ctx.info();
    const canvas = document.querySelector('#view canvas:not(.marker)');
    const copy = document.createElement('canvas');
    copy.width = canvas.width; copy.height = canvas.height;
    const c2d = copy.getContext('2d');
    c2d.drawImage(canvas, 0, 0);
    const { data } = c2d.getImageData(0, 0, copy.width, copy.height);
    const classes = {
      red: (r, g, b) => r > g + 60 && r > b + 60,
      green: (r, g, b) => g > r + 50 && g > b + 40,
      blue: (r, g, b) => b > r + 60 && b > g + 30,
      beige: (r, g, b) => r > 110 && g > 100 && b > 80 && r >= b && r - b < 70 && Math.abs(r - g) < 40,
    };
    const out = Object.fromEntries(Object.keys(classes).map((k) => [k, { count: 0, x: 0, y: 0 }]));
    for (let p = 0; p < data.length; p += 4) {
      const [r, g, b] = [data[p], data[p + 1], data[p + 2]];
      for (const [name, is] of Object.entries(classes)) {
        if (!is(r, g, b)) continue;
        const o = out[name];
        o.count++; o.x += (p / 4) % copy.width; o.y += Math.floor(p / 4 / copy.width);
      }
    }
    for (const o of Object.values(out)) if (o.count) { o.x /= o.count; o.y /= o.count; }
    const m = info.index_to_world, cam = v.camera.camera;
    const at = points.map(([i, j, k]) => {
      const world = new THREE.Vector3(...[0, 1, 2].map((row) => m[4 * row] * i + m[4 * row + 1] * j + m[4 * row + 2] * k + m[4 * row + 3]));
      world.applyMatrix4(v.group.matrixWorld);
      const ndc = world.project(cam);
      const x = Math.round((ndc.x + 1) / 2 * copy.width), y = Math.round((1 - ndc.y) / 2 * copy.height);
      const q = 4 * (y * copy.width + x);
      return { x, y, rgb: [data[q], data[q + 1], data[q + 2]] };
    });
    return { ...out, at, pixels: copy.width * copy.height, mmPerPixel: v.camera.mmPerPixel(copy.height) };
  }, points);
}
