// test_web.mjs: the web client in headless Debian Chromium (playwright-core) against a real
// isoserve on 127.0.0.1. Prints PASS/FAIL lines; exit status 1 on failure.
// usage: node tests/browser/test_web.mjs   (from the repository root, after make)
import { spawn } from 'node:child_process';
import { mkdtempSync, rmSync, writeFileSync, existsSync } from 'node:fs';
import { createRequire } from 'node:module';
import { tmpdir } from 'node:os';
import { join, resolve } from 'node:path';

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

// Share of pixels that differ from the background colour of the top-left corner.
async function drawnShare(page) {
  return page.evaluate(() => {
    const canvas = document.querySelector('#view canvas');
    const copy = document.createElement('canvas');
    copy.width = canvas.width; copy.height = canvas.height;
    const ctx = copy.getContext('2d');
    ctx.drawImage(canvas, 0, 0);
    const { data } = ctx.getImageData(0, 0, copy.width, copy.height);
    const [r, g, b] = [data[0], data[1], data[2]];
    let differ = 0;
    for (let i = 0; i < data.length; i += 4)
      if (Math.abs(data[i] - r) + Math.abs(data[i + 1] - g) + Math.abs(data[i + 2] - b) > 30) differ++;
    return differ / (data.length / 4);
  });
}

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
    await page.goto(`${base}?volume=${volume.id}&${wanted}&normals=tricubic`);
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
