// test_web.mjs: the web client in headless Debian Chromium (playwright-core) against a real
// isoserve on 127.0.0.1. Prints PASS/FAIL lines; exit status 1 on failure.
// usage: node tests/browser/test_web.mjs   (from the repository root, after make)
import { spawn } from 'node:child_process';
import { mkdtempSync, rmSync, writeFileSync, existsSync } from 'node:fs';
import { createRequire } from 'node:module';
import { tmpdir } from 'node:os';
import { join, resolve } from 'node:path';

import { meshoptIndexHeaders } from '../support/glb.mjs';

const require = createRequire(resolve('web/node_modules') + '/');
const { chromium } = require('playwright-core');

// tests/run.sh's asan pass runs the page against build/san/isoserve and says web-san.
const label = `web${process.env.ISO_SAN_SUFFIX || ''}`;
let failures = 0;
const report = (name, ok, why = '') => {
  if (!ok) failures++;
  console.log(ok ? `PASS ${label}.${name}` : `FAIL ${label}.${name}: ${why}`);
};

// The volume: Debian's ch2bet brain (NIfTI) when installed, else an analytic torus.
const tmp = mkdtempSync(join(tmpdir(), 'isoserve-web-'));
const nifti = '/usr/share/mricron/templates/ch2bet.nii.gz';
const volume = existsSync(nifti)
  ? { id: 'brain', path: nifti, levels: [30, 90], level: 60 }
  : { id: 'brain', path: 'field:torus:96', levels: [0, 8], level: 0 };
console.log(`web test volume: ${volume.path}`);
writeFileSync(join(tmp, 'catalog.json'), JSON.stringify({ volumes: [
  { id: volume.id, path: volume.path, name: 'Test volume', modality: 'MR', levels: volume.levels }] }));

function startServer() {
  return new Promise((resolvePort, reject) => {
    const proc = spawn(resolve(process.env.ISOSERVE_BIN || 'build/isoserve'), ['serve', '--catalog', join(tmp, 'catalog.json'),
      '--listen', '127.0.0.1:0'], { stdio: ['ignore', 'ignore', 'pipe'] });
    let log = '';
    proc.stderr.on('data', (d) => {
      log += d;
      const m = /listening on http:\/\/127\.0\.0\.1:(\d+)\//.exec(log);
      if (m && !proc.port) { proc.port = Number(m[1]); resolvePort(proc); }
    });
    proc.on('exit', (code) => { if (!proc.port) reject(new Error(`server exited ${code}: ${log}`)); });
  });
}

async function waitReady(port) {
  for (let i = 0; i < 600; i++) {
    try { if ((await fetch(`http://127.0.0.1:${port}/healthz`)).status === 200) return; } catch { /* not yet */ }
    await new Promise((r) => setTimeout(r, 50));
  }
  throw new Error('server not ready');
}

// Drawn shares of the canvas's left and right halves, and the count of pixels whose colour
// leans red and blue (two surfaces drawn in those colours).
async function pixelStats(page) {
  return page.evaluate(() => {
    const canvas = document.querySelector('#view canvas');
    const copy = document.createElement('canvas');
    copy.width = canvas.width; copy.height = canvas.height;
    const ctx = copy.getContext('2d');
    ctx.drawImage(canvas, 0, 0);
    const { data } = ctx.getImageData(0, 0, copy.width, copy.height);
    const [r0, g0, b0] = [data[0], data[1], data[2]];
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

// Drag the level slider for `ms` (input events every 40 ms across `from`..`to` of the
// slider), then release at `to`.
async function dragSlider(page, id, from, to, ms) {
  await page.evaluate(async ({ id, from, to, ms }) => {
    const el = document.getElementById(id);
    const steps = Math.max(2, Math.round(ms / 40));
    for (let k = 0; k <= steps; k++) {
      el.value = String(Math.round(from + (to - from) * k / steps));
      el.dispatchEvent(new Event('input'));
      await new Promise((r) => setTimeout(r, 40));
    }
    el.dispatchEvent(new Event('change'));
  }, { id, from, to, ms });
}

// 4. Dragging: previews show while the slider moves, never more than one mesh request in
// flight (counted in the page around fetch), and after release the mesh shown is the final
// level's full mesh, also a while later (no stale answer lands after it).
async function dragTests(page, base) {
  await page.goto(`${base}?volume=${volume.id}&level=${volume.level}&tolerance=0`);
  await page.waitForFunction(() => window.isoViewer?.shown.some((m) => m.kind === 'final'), null, { timeout: 60000 });
  await page.evaluate(() => {
    window.meshFetches = { now: 0, most: 0, total: 0 };
    const plain = window.fetch;
    window.fetch = (url, options) => {
      if (!String(url).includes('/mesh?')) return plain(url, options);
      const f = window.meshFetches;
      f.now++; f.total++; f.most = Math.max(f.most, f.now);
      // Settled when the body is read, the fetch fails, or its signal aborts it (at once:
      // an aborted request is no longer in flight, though its rejection comes later).
      let settled = false;
      const done = () => { if (!settled) { settled = true; f.now--; } };
      options?.signal?.addEventListener('abort', done);
      return plain(url, options).then((response) => {
        const body = response.arrayBuffer.bind(response);
        response.arrayBuffer = () => body().finally(done);
        return response;
      }, (error) => { done(); throw error; });
    };
  });
  const before = await page.evaluate(() => window.isoViewer.shown.length);
  await dragSlider(page, 'level', 150, 600, 2500);
  const finalLevel = await page.evaluate(() => Number(document.getElementById('level-value').textContent.replace(/,/g, '')));
  await page.waitForFunction(() => window.isoViewer.shown.at(-1)?.kind === 'final', null, { timeout: 60000 });
  await page.waitForTimeout(1500);
  const r = await page.evaluate((n) => ({ shown: window.isoViewer.shown.slice(n), fetches: window.meshFetches,
    state: window.isoViewer.state.surfaces[0].level, url: location.search }), before);
  const previews = r.shown.filter((m) => m.kind === 'preview');
  const last = r.shown.at(-1);
  console.log(`  info: drag: ${previews.length} previews in 2.5 s, ${r.fetches.total} mesh requests, at most ${r.fetches.most} in flight; final level ${last?.level}`);
  report('drag_shows_previews', previews.length >= 2, `${previews.length} previews`);
  report('drag_one_request_in_flight', r.fetches.most === 1, `at most ${r.fetches.most} in flight`);
  report('drag_final_mesh_is_final_level', last?.kind === 'final' && last.level === r.state &&
    Math.abs(last.level - finalLevel) <= 1e-6 * Math.abs(finalLevel) + 1e-9 && r.url.includes(`level=${r.state}&`),
    `last shown ${JSON.stringify(last)}, slider ${finalLevel}, state ${r.state}`);
}

// 5. Two surfaces (red translucent outside, blue opaque inside) both show; the clipping
// plane removes one half; the URL restores all of it; the measures match the server's.
async function twoSurfaceTests(page, base) {
  const [outer, inner] = volume.levels;
  const url = `${base}?volume=${volume.id}&level=${outer}&tolerance=1&color=ff2020&opacity=0.35&level2=${inner}&color2=2040ff`;
  await page.goto(url);
  await page.waitForFunction(() => [0, 1].every((i) => window.isoViewer?.shown.some((m) => m.surface === i && m.kind === 'final')),
    null, { timeout: 90000 });
  await page.waitForTimeout(300);
  const both = await pixelStats(page);
  console.log(`  info: two surfaces: ${(both.red * 100).toFixed(1)}% red, ${(both.blue * 100).toFixed(1)}% blue pixels`);
  report('two_surfaces_two_colours', both.red > 0.005 && both.blue > 0.01, JSON.stringify(both));
  await page.check('#clip');
  await page.waitForTimeout(300);
  const cut = await pixelStats(page);
  console.log(`  info: clip x at the middle: left ${(both.left * 100).toFixed(1)}% -> ${(cut.left * 100).toFixed(1)}%, right ${(both.right * 100).toFixed(1)}% -> ${(cut.right * 100).toFixed(1)}%`);
  const [kept, gone] = cut.left > cut.right ? ['left', 'right'] : ['right', 'left'];
  report('clip_plane_cuts_one_half', cut[gone] < 0.35 * both[gone] && cut[kept] > 0.7 * both[kept], JSON.stringify({ both, cut }));
  const link = page.url();
  report('url_holds_surfaces_and_clip', /level2=/.test(link) && /color=ff2020/.test(link) && /opacity=0.35/.test(link) &&
    /color2=2040ff/.test(link) && /clip=x%3A0.5/.test(link), link);
  await page.goto(link);
  await page.waitForFunction(() => [0, 1].every((i) => window.isoViewer?.shown.some((m) => m.surface === i && m.kind === 'final')),
    null, { timeout: 90000 });
  await page.waitForTimeout(300);
  const again = await pixelStats(page);
  const restored = await page.evaluate(() => ({ clip: document.getElementById('clip').checked, color: document.getElementById('color-2').value,
    on: document.getElementById('surface-2').checked }));
  report('link_restores_view', restored.clip && restored.on && restored.color === '#2040ff' &&
    Math.abs(again.left - cut.left) < 0.02 && Math.abs(again.right - cut.right) < 0.02 && again.blue > 0.005,
    JSON.stringify({ restored, again, cut }));
  // Measures on demand: area (mm²) and enclosed volume (mL, closed at the border) of both
  // surfaces, as the server's headers give them.
  await page.click('#measure');
  await page.waitForFunction(() => document.getElementById('measures').textContent.includes('mm²'), null, { timeout: 90000 });
  await page.waitForFunction(() => (document.getElementById('measures').textContent.match(/mm²/g) || []).length === 2, null, { timeout: 90000 });
  const text = await page.textContent('#measures');
  const head = await fetch(`${base}v1/volumes/${volume.id}/mesh?level=${outer}&tolerance=1&normals=none&format=ply&cap=true&measures=true`, { method: 'HEAD' });
  const area = Number(head.headers.get('x-iso-area-mm2')), ml = Number(head.headers.get('x-iso-volume-mm3')) / 1000;
  const shownArea = Number(/area([\d,.]+) mm²/.exec(text)?.[1].replace(/,/g, ''));
  const shownMl = Number(/enclosed volume([\d,.]+) mL/.exec(text)?.[1].replace(/,/g, ''));
  console.log(`  info: measures: ${text.replace(/\s+/g, ' ')}`);
  report('measures_on_demand', Math.abs(shownArea - area) <= 1e-5 * area && head.headers.get('x-iso-closed') === 'true' &&
    Math.abs(shownMl - ml) <= 1e-4 * ml, `shown ${shownArea} mm², ${shownMl} mL; server ${area} mm², ${ml} mL`);
}

// Share of pixels that differ from the background colour of the top-left corner.
const drawnShare = async (page) => {
  const { left, right } = await pixelStats(page);
  return (left + right) / 2;
};

const pixels = (page) => page.evaluate(() => document.querySelector('#view canvas').toDataURL());

async function main() {
  const server = await startServer();
  const base = `http://127.0.0.1:${server.port}/`;
  const profile = mkdtempSync(join(tmpdir(), 'isoserve-chromium-'));
  let context;
  try {
    await waitReady(server.port);
    context = await chromium.launchPersistentContext(profile, {
      executablePath: '/usr/bin/chromium', headless: true, viewport: { width: 1100, height: 760 },
      args: ['--headless', '--no-sandbox', '--disable-gpu', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
        '--disable-background-networking', '--disable-component-update', '--disable-sync', '--disable-quic', '--no-first-run'],
    });
    const page = context.pages()[0] ?? await context.newPage();
    const errors = [], hosts = new Set(), meshes = [];
    page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
    page.on('pageerror', (e) => errors.push(String(e)));
    // Workers start from blob: URLs and the icon is a data: URL: local. Everything else must
    // go to the server on loopback.
    page.on('request', (r) => {
      const url = new URL(r.url());
      if (url.protocol !== 'blob:' && url.protocol !== 'data:') hosts.add(`${url.protocol}//${url.hostname}`);
    });
    page.on('response', (r) => { if (r.url().includes('/mesh?')) meshes.push(r); });

    // 1. The page loads and draws the requested mesh; the stats show the header's count.
    const t0 = Date.now();
    const wanted = `level=${volume.level}&tolerance=1`;
    await page.goto(`${base}?volume=${volume.id}&${wanted}&normals=tricubic&codec=draco`);
    const final = await page.waitForResponse((r) => r.url().includes('/mesh?') && r.url().includes(`level=${volume.level}&tolerance=1&`), { timeout: 60000 });
    const triangles = final.headers()['x-iso-triangles'];
    await page.waitForFunction((t) => document.getElementById('stat-triangles')?.textContent.replace(/,/g, '') === t,
      triangles, { timeout: 60000 });
    const loadMs = Date.now() - t0;
    const share = await drawnShare(page);
    const decode = await page.textContent('#stats');
    console.log(`  info: first view in ${loadMs} ms, ${triangles} triangles, ${(share * 100).toFixed(1)}% of pixels drawn; ` +
      `${meshes.length} mesh responses (coarse first); stats: ${decode.replace(/\s+/g, ' ').slice(0, 160)}`);
    report('mesh_drawn', share > 0.02, `only ${(share * 100).toFixed(2)}% of pixels differ from the background`);
    report('stats_match_header', Number(triangles) > 0, `X-Iso-Triangles ${triangles}`);
    const speed = final.headers()['x-iso-draco-speed'];
    const shownSpeed = await page.textContent('#stat-speed');
    report('stats_show_draco_speed', /^(8|10)$/.test(speed ?? '') && shownSpeed === speed,
      `X-Iso-Draco-Speed ${speed}, shown ${shownSpeed}`);
    report('coarse_then_fine', meshes.length >= 2 && !meshes[0].url().includes('tolerance=1&'),
      meshes.map((r) => r.url()).join(' '));
    report('url_keeps_state', page.url().includes(`volume=${volume.id}`) && page.url().includes(`level=${volume.level}`), page.url());
    report('downloads', (await page.getAttribute('#download-glb', 'href')).includes('format=glb') &&
      (await page.getAttribute('#download-ply', 'href')).includes('format=ply'), 'download links');

    // 2. Moving the level slider fetches and draws a new mesh.
    const before = await pixels(page);
    const count = meshes.length;
    await page.evaluate(() => {
      const el = document.getElementById('level');
      el.value = String(Math.round(Number(el.value) * 1.4 + 20));
      el.dispatchEvent(new Event('input'));
      el.dispatchEvent(new Event('change'));
    });
    await page.waitForResponse((r) => r.url().includes('/mesh?') && r.url().includes('tolerance=1&'), { timeout: 60000 });
    const newTriangles = meshes[meshes.length - 1].headers()['x-iso-triangles'];
    await page.waitForFunction((t) => document.getElementById('stat-triangles')?.textContent.replace(/,/g, '') === t,
      newTriangles, { timeout: 60000 });
    const after = await pixels(page);
    report('level_slider_redraws', meshes.length > count && newTriangles !== triangles && after !== before,
      `responses ${count} -> ${meshes.length}, triangles ${triangles} -> ${newTriangles}`);

    // 3. The fast codec (the default): glb-meshopt through GLTFLoader + MeshoptDecoder draws
    // the same mesh as Draco (the same triangle count) at the same level, from an index
    // stream of codec version 1 (header 0xe1, as EXT_meshopt_compression requires).
    await page.goto(`${base}?volume=${volume.id}&${wanted}`);
    const fast = await page.waitForResponse((r) => r.url().includes('format=glb-meshopt') && r.url().includes(`level=${volume.level}&tolerance=1&`), { timeout: 60000 });
    await page.waitForFunction((t) => document.getElementById('stat-triangles')?.textContent.replace(/,/g, '') === t,
      triangles, { timeout: 60000 });
    const headers = meshoptIndexHeaders(new Uint8Array(await fast.body()));
    report('meshopt_codec_draws', fast.headers()['x-iso-triangles'] === triangles && (await page.textContent('#stat-codec')) === 'meshopt' &&
      await drawnShare(page) > 0.02 && headers.length === 1 && headers[0] === 0xe1,
      `meshopt ${fast.headers()['x-iso-triangles']} triangles, draco ${triangles}, index headers ${headers}`);

    // 4. The detail control: one voxel (position 60) asks the final mesh with distance= in
    // mm; the server's answer is within it, comes from its chain with fewer triangles than
    // the surface itself, and the control shows millimetres and the voxel size.
    const exactTriangles = Number(fast.headers()['x-iso-triangles']);
    await page.evaluate(() => {
      const el = document.getElementById('distance');
      el.value = '60';
      el.dispatchEvent(new Event('input'));
      el.dispatchEvent(new Event('change'));
    });
    const detailed = await page.waitForResponse((r) => r.url().includes('/mesh?') && r.url().includes('&distance='), { timeout: 120000 });
    const asked = Number(new URL(detailed.url()).searchParams.get('distance'));
    const h = detailed.headers();
    await page.waitForFunction((t) => document.getElementById('stat-triangles')?.textContent.replace(/,/g, '') === t,
      h['x-iso-triangles'], { timeout: 60000 });
    const label = await page.textContent('#distance-value');
    const voxelMm = Math.min(...(await (await fetch(`${base}v1/volumes/${volume.id}`)).json()).spacing);
    report('detail_control_distance', Math.abs(asked - voxelMm) <= 0.01 * voxelMm && Number(h['x-iso-distance-mm']) <= asked &&
      Number(h['x-iso-chain-level']) >= 1 && Number(h['x-iso-triangles']) < exactTriangles &&
      label.includes(' mm') && label.includes(`voxel ${voxelMm} mm`) && page.url().includes(`distance=${asked}`) &&
      (await page.textContent('#stat-distance')).includes('mm') && await drawnShare(page) > 0.02,
      `asked ${asked} mm (voxel ${voxelMm}), got ${h['x-iso-distance-mm']} mm at chain level ${h['x-iso-chain-level']}, ` +
      `${h['x-iso-triangles']} of ${exactTriangles} triangles; label "${label}"; ${page.url()}`);
    await page.goto(`${base}?volume=${volume.id}&${wanted}`);

    await dragTests(page, base);
    await twoSurfaceTests(page, base);

    report('no_console_errors', errors.length === 0, errors.join(' | '));

    // 3. An unknown volume: a readable error from the problem body (the browser logs the
    // 404 itself, which is expected here).
    await page.goto(`${base}?volume=nope&level=1`);
    await page.waitForSelector('#error:not([hidden])', { timeout: 30000 });
    const message = await page.textContent('#error');
    report('unknown_volume_error', /no volume "nope"/.test(message), message);

    report('only_loopback', [...hosts].every((h) => h === 'http://127.0.0.1'), [...hosts].join(', '));
  } finally {
    await context?.close();
    server.kill('SIGTERM');
    await new Promise((r) => server.on('exit', r));
    rmSync(profile, { recursive: true, force: true });
    rmSync(tmp, { recursive: true, force: true });
  }
}

main().catch((e) => { report('run', false, e.stack || String(e)); }).finally(() => process.exit(failures ? 1 : 0));
