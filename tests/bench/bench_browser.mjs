// bench_browser.mjs: the web client in headless Chromium against a real isoserve:
// - views: opening each volume of the default collection, CThead and the bunny as a new
//   user does (a fresh page, a level not asked before), with and without Detail: the time
//   to the first surface drawn (the preview) and to the full surface, and their triangles;
// - orbit: frames per second while the mouse orbits the bunny's 2 M-triangle surface, and
//   how long after the last mouse move its frame is on screen;
// - loads: for each volume, codec and link, the time from asking for a full mesh
//   (uncached: a new level each time) to it being drawn, and its bytes on the wire;
// - drag: mesh updates per second while the level slider is dragged across CThead's range
//   and the bunny's (2 M triangles exact; target >= 10 updates per second on loopback).
// Links are Chrome DevTools Protocol network emulation (Network.emulateNetworkConditions):
// loopback as is, 100 Mbit/s and 20 Mbit/s with 2 ms and 10 ms of latency. Software GL on
// 2 cores makes draw times pessimistic; server and transfer times are not. Prints tables,
// writes bench/results/browser.json (with its date, commit and load, provenance()).
//
// Volumes: the default collection (Debian's mricron templates and the phantoms); CThead,
// ch2 (ch2bet) and ch2better NRRDs and the bunny from ../shared/volumes
// (ISO_SHARED_VOLUMES), skipped with a SKIP line without them. ISO_BENCH_WEB_BEFORE=DIR
// runs the views beside an older client's files (DIR: a built web root), alternating, for
// ratios measured side by side. ISO_BENCH_REPEAT sets the
// loads per cell (default 3; the median is reported); ISO_BENCH_ONLY=views|orbit|loads|drag
// (comma-separated) runs those phases alone.
import { execSync, spawn } from 'node:child_process';
import { existsSync, mkdirSync, mkdtempSync, rmSync, writeFileSync } from 'node:fs';
import { createRequire } from 'node:module';
import { cpus, loadavg, tmpdir } from 'node:os';
import { join, resolve } from 'node:path';

// What the JSON starts with (as tests/bench/provenance.py writes it for the Python benches).
function provenance() {
  let commit = 'unknown';
  try {
    commit = execSync('git rev-parse --short=12 HEAD', { encoding: 'utf8' }).trim();
    if (execSync('git status --porcelain --untracked-files=no', { encoding: 'utf8' }).trim()) commit += '-dirty';
  } catch { /* not a git checkout */ }
  return { date: new Date().toISOString().replace(/\.\d+Z$/, 'Z'), commit, load_average: loadavg(), cores: cpus().length };
}

const require = createRequire(resolve('web/node_modules') + '/');
const { chromium } = require('playwright-core');
const shared = process.env.ISO_SHARED_VOLUMES ?? '../shared/volumes';
const REPEAT = Number(process.env.ISO_BENCH_REPEAT ?? 3);
const CODECS = ['draco', 'meshopt'];
const LINKS = [
  { name: 'loopback', conditions: null },
  { name: '100 Mbit/s', conditions: { offline: false, latency: 2, downloadThroughput: 100e6 / 8, uploadThroughput: 100e6 / 8 } },
  { name: '20 Mbit/s', conditions: { offline: false, latency: 10, downloadThroughput: 20e6 / 8, uploadThroughput: 20e6 / 8 } },
];

const phases = new Set((process.env.ISO_BENCH_ONLY ?? 'views,orbit,loads,drag').split(','));
const MRICRON = '/usr/share/mricron/templates/';

// The views phase's volumes: the default collection (as the server names it, when
// installed) and the shared CThead and bunny, each at its first suggested level.
function viewVolumes() {
  const at = (f) => resolve(shared, f);
  const list = [
    { id: 'ch2bet', path: `${MRICRON}ch2bet.nii.gz`, levels: [30, 90] },
    { id: 'ch2', path: `${MRICRON}ch2.nii.gz` },
    { id: 'ch2better', path: `${MRICRON}ch2better.nii.gz`, levels: [30, 95] },
    { id: 'marschner-lobb', path: 'field:ml:128', levels: [0.5] },
    { id: 'torus', path: 'field:torus:128', levels: [0, 8] },
    { id: 'sphere', path: 'field:sphere:96', levels: [0, 20] },
  ].filter((v) => v.path.startsWith('field:') || existsSync(v.path));
  if (existsSync(at('CThead_256x256x113_u16be.nhdr'))) {
    list.push({ id: 'cthead-view', path: at('CThead_256x256x113_u16be.nhdr'), levels: [700.5, 1500.5], orientation: 'LPI' });
    list.push({ id: 'bunny', path: at('bunny_512x512x361_i16le.nhdr') });
  } else {
    console.log(`SKIP bench_browser views of CThead and the bunny: ${shared} is absent`);
  }
  return list;
}

function volumes() {
  const at = (f) => resolve(shared, f);
  if (existsSync(at('CThead_256x256x113_u16be.nhdr')))
    return [
      { id: 'cthead', label: 'CThead skin', path: at('CThead_256x256x113_u16be.nhdr'), level: 700.5, levels: [700.5, 1500.5] },
      { id: 'ch2', label: 'ch2 brain', path: at('ch2bet_181x217x181_u8.nhdr'), level: 30.5, levels: [30.5, 90.5] },
      { id: 'ch2better', label: 'ch2better brain', path: at('ch2better_301x370x316_u8.nhdr'), level: 30.5, levels: [30.5, 95.5] },
      { id: 'bunny', label: 'bunny', path: at('bunny_512x512x361_i16le.nhdr'), level: 1700.5, levels: [1700.5], dragOnly: true },
    ].filter((v) => existsSync(v.path));
  console.log(`SKIP bench_browser shared volumes: ${shared} is absent; Debian's ch2bet alone`);
  return [{ id: 'ch2', label: 'ch2 brain', path: '/usr/share/mricron/templates/ch2bet.nii.gz', level: 30.5, levels: [30.5, 90.5] }];
}

function startServer(catalog, extra = []) {
  return new Promise((ok, fail) => {
    const proc = spawn(resolve(process.env.ISOSERVE_BIN || 'build/isoserve'), ['serve', '--catalog', catalog,
      '--listen', '127.0.0.1:0', '--cache-mb', '2048', ...extra], { stdio: ['ignore', 'ignore', 'pipe'] });
    let log = '';
    proc.stderr.on('data', (d) => {
      log += d;
      const m = /listening on http:\/\/127\.0\.0\.1:(\d+)\//.exec(log);
      if (m && !proc.port) { proc.port = Number(m[1]); ok(proc); }
    });
    proc.on('exit', (code) => { if (!proc.port) fail(new Error(`server exited ${code}: ${log}`)); });
  });
}

const median = (xs) => { const s = [...xs].sort((a, b) => a - b); return s[Math.floor((s.length - 1) / 2)]; };

// One full mesh of surface 0 at `level`, timed from the request to the frame after it is
// drawn; the wire bytes from the resource timing entry (the encoded body: gzip when sent).
async function timedLoad(page, level, codec) {
  return page.evaluate(async ({ level, codec }) => {
    const v = window.isoViewer;
    v.state.codec = codec;
    v.state.surfaces[0].level = level;
    performance.clearResourceTimings();
    const start = performance.now();
    await v.refresh(0, false);
    await new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r)));
    const ms = performance.now() - start;
    const last = v.shown.at(-1);
    const e = performance.getEntriesByType('resource').filter((x) => x.name.includes('/mesh?')).at(-1);
    // The split: until the first byte (the server's work, uncached), the transfer, and
    // decoding and drawing after the last byte.
    return { ms, level: last.level, kind: last.kind, triangles: last.triangles, bytes: e?.encodedBodySize ?? null,
      decoded: last.bytes, decodeMs: last.decodeMs, firstByteMs: e.responseStart - start, transferMs: e.responseEnd - e.responseStart,
      afterMs: start + ms - e.responseEnd };
  }, { level, codec });
}

// Drags surface 0's slider across the value range between the volume's two levels for
// `ms`; returns the previews drawn per second and the drag's last mesh.
async function dragRate(page, codec, ms) {
  return page.evaluate(async ({ codec, ms }) => {
    const v = window.isoViewer;
    v.state.codec = codec;
    const el = document.getElementById('level');
    const n = v.shown.length, start = performance.now();
    const [from, to] = [100, 700];
    while (performance.now() - start < ms) {
      const k = (performance.now() - start) / ms;
      el.value = String(Math.round(from + (to - from) * k));
      el.dispatchEvent(new Event('input'));
      await new Promise((r) => setTimeout(r, 16));
    }
    const previews = v.shown.slice(n).filter((m) => m.kind === 'drag');
    el.dispatchEvent(new Event('change'));
    const spent = (performance.now() - start) / 1000;
    const gaps = previews.slice(1).map((m, k) => m.at - previews[k].at);
    return { perSecond: previews.length / spent, previews: previews.length,
      triangles: median(previews.map((m) => m.triangles)), bytes: median(previews.map((m) => m.bytes)),
      gapMs: median(gaps), fetchMs: median(previews.map((m) => m.fetchMs)), serverMs: median(previews.map((m) => m.serverMs)),
      decodeMs: median(previews.map((m) => m.decodeMs)), drawMs: median(previews.map((m) => m.drawMs)) };
    function median(xs) { const s = [...xs].sort((a, b) => a - b); return s[Math.floor((s.length - 1) / 2)] ?? 0; }
  }, { codec, ms });
}

// Opens `vol` at `level` in a fresh page state (nothing seen before) and times, from the
// navigation, the first surface drawn and the full one.
async function timedView(page, base, vol, level, distance) {
  await page.goto(`${base}style.css`); // the origin's storage, without starting the viewer
  await page.evaluate(() => localStorage.clear());
  const q = `?volume=${vol.id}&level=${level}${distance ? `&distance=${distance}` : ''}`;
  const start = Date.now();
  await page.goto(`${base}${q}`);
  // Any client version: the first full mesh of surface 0 in its record of what it drew.
  await page.waitForFunction(() => window.isoViewer?.shown.some((m) => m.kind === 'final' && m.surface === 0), null, { timeout: 600000 });
  await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
  const wall = Date.now() - start;
  return page.evaluate(({ wall }) => {
    const nav = performance.getEntriesByType('navigation')[0];
    const shown = window.isoViewer.shown;
    const first = shown[0], full = shown.find((m) => m.kind === 'final');
    // performance.now() counts from the navigation's start: the times are the user's, to
    // the frame that shows the mesh drawn (drawnAt; an older client drew in show()).
    return { firstMs: first.drawnAt ?? first.at, fullMs: full.drawnAt ?? full.at, wallMs: wall, firstKind: first.kind, firstTriangles: first.triangles,
      fullTriangles: full.triangles, meshes: shown.length, fullBytes: full.bytes, navMs: nav?.duration ?? null };
  }, { wall });
}

// Orbits the camera with the mouse for `ms` (a move every 8 ms, faster than frames):
// frames drawn per second, the time from the last move to the frame showing it, and after
// the release the time to the full frame.
async function orbitRate(page, ms) {
  const box = await page.locator('#view canvas:not(.marker)').boundingBox();
  const cx = box.x + box.width / 2, cy = box.y + box.height / 2;
  await page.mouse.move(cx, cy);
  await page.mouse.down();
  const frames0 = await page.evaluate(() => window.isoViewer.view.frames);
  const start = Date.now();
  let moves = 0;
  while (Date.now() - start < ms) {
    const t = (Date.now() - start) / ms;
    await page.mouse.move(cx + 200 * Math.sin(2 * Math.PI * t), cy + 40 * Math.cos(2 * Math.PI * t));
    moves++;
    await new Promise((r) => setTimeout(r, 8));
  }
  const spent = (Date.now() - start) / 1000;
  const frames = await page.evaluate(() => window.isoViewer.view.frames);
  const lagStart = Date.now();
  await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
  const lagMs = Date.now() - lagStart;
  await page.mouse.up();
  const fullStart = Date.now();
  await page.evaluate(() => window.isoViewer.view.drawn());
  return { fps: (frames - frames0) / spent, frames: frames - frames0, moves, seconds: spent, lastMoveToFrameMs: lagMs,
    releaseToFullFrameMs: Date.now() - fullStart };
}

async function viewsAndOrbit(context, results) {
  const vols = viewVolumes();
  const tmp = mkdtempSync(join(tmpdir(), 'isoserve-bench-views-'));
  writeFileSync(join(tmp, 'catalog.json'), JSON.stringify({ volumes: vols.map(({ id, path, levels, orientation }) =>
    ({ id, path, ...(levels ? { levels } : {}), ...(orientation ? { orientation } : {}) })) }));
  const server = await startServer(join(tmp, 'catalog.json'));
  const before = process.env.ISO_BENCH_WEB_BEFORE
    ? await startServer(join(tmp, 'catalog.json'), ['--web-root', resolve(process.env.ISO_BENCH_WEB_BEFORE)]) : null;
  const base = `http://127.0.0.1:${server.port}/`;
  const clients = [['now', base], ...(before ? [['before', `http://127.0.0.1:${before.port}/`]] : [])];
  try {
    for (const [, b] of clients)
      for (let i = 0; i < 3000 && (await fetch(`${b}healthz`).catch(() => ({}))).status !== 200; i++)
        await new Promise((r) => setTimeout(r, 100));
    const page = await context.newPage();
    let turn = 0;
    if (phases.has('views')) {
      for (const vol of vols) {
        const info = await (await fetch(`${base}v1/volumes/${vol.id}`)).json();
        const voxel = Math.min(...info.spacing);
        const level = info.suggested_levels[0] ?? (info.value_range[0] + info.value_range[1]) / 2;
        for (const [label, distance] of [['surface', 0], ['Detail 1 voxel', Number(voxel.toPrecision(3))]]) {
          // The clients alternate, each turn starting with the other; each asks a level not
          // asked before: the server extracts (and builds the chain) anew.
          const order = turn++ % 2 ? [...clients].reverse() : clients;
          for (const [client, b] of order) {
            const bump = (distance ? 2 : 1) + (client === 'before' ? 4 : 0);
            const bumped = Number((level + 1e-4 * (info.value_range[1] - info.value_range[0]) * bump).toPrecision(7));
            const r = await timedView(page, b, vol, bumped, distance);
            const row = { volume: vol.id, detail: label, client, level: bumped, ...r };
            results.views.push(row);
            console.log(`  view ${vol.id} | ${label} | ${client}: first surface ${r.firstMs.toFixed(0)} ms (${r.firstKind}, ${r.firstTriangles} triangles), ` +
              `full ${r.fullMs.toFixed(0)} ms (${r.fullTriangles} triangles; first/full ${(r.firstTriangles / r.fullTriangles).toFixed(3)}), ${r.meshes} meshes drawn`);
          }
        }
      }
    }
    const bunny = vols.find((v) => v.id === 'bunny');
    if (phases.has('orbit') && bunny) {
      await page.goto(`${base}?volume=bunny&level=1700`);
      await page.waitForFunction(() => window.isoViewer?.ctx?.loader.live[0].drawn?.kind === 'final', null, { timeout: 600000 });
      await page.evaluate(() => window.isoViewer.view.drawn());
      const triangles = await page.evaluate(() => window.isoViewer.ctx.loader.live[0].drawn.triangles);
      const o = await orbitRate(page, 8000);
      results.orbits.push({ volume: 'bunny', level: 1700, triangles, ...o });
      console.log(`  orbit bunny 1700 (${triangles} triangles): ${o.fps.toFixed(2)} frames/s (${o.frames} frames for ${o.moves} mouse moves in ` +
        `${o.seconds.toFixed(1)} s); last move to its frame ${o.lastMoveToFrameMs} ms, release to the full frame ${o.releaseToFullFrameMs} ms`);
    } else if (phases.has('orbit')) {
      console.log('SKIP bench_browser orbit: the bunny needs ../shared/volumes');
    }
    await page.close();
  } finally {
    server.kill('SIGTERM');
    before?.kill('SIGTERM');
    rmSync(tmp, { recursive: true, force: true });
  }
}

async function main() {
  const vols = volumes();
  const tmp = mkdtempSync(join(tmpdir(), 'isoserve-bench-browser-'));
  writeFileSync(join(tmp, 'catalog.json'), JSON.stringify({ volumes: vols.map((v) => ({ id: v.id, path: v.path, name: v.label, levels: v.levels })) }));
  const server = await startServer(join(tmp, 'catalog.json'));
  const base = `http://127.0.0.1:${server.port}/`;
  for (let i = 0; i < 1200 && (await fetch(`${base}healthz`).catch(() => ({}))).status !== 200; i++)
    await new Promise((r) => setTimeout(r, 100));
  const profile = mkdtempSync(join(tmpdir(), 'isoserve-chromium-'));
  const context = await chromium.launchPersistentContext(profile, {
    executablePath: '/usr/bin/chromium', headless: true, viewport: { width: 1100, height: 760 },
    args: ['--headless', '--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
      '--disable-background-networking', '--disable-component-update', '--disable-sync', '--no-first-run'],
  });
  const results = { views: [], orbits: [], loads: [], drags: [] };
  try {
    if (phases.has('views') || phases.has('orbit')) await viewsAndOrbit(context, results);
    const page = context.pages()[0] ?? await context.newPage();
    const cdp = await context.newCDPSession(page);
    await cdp.send('Network.enable');
    let bump = 0;
    for (const vol of phases.has('loads') ? vols.filter((v) => !v.dragOnly) : []) {
      await page.goto(`${base}?volume=${vol.id}&level=${vol.level}&tolerance=0&codec=draco`);
      await page.waitForFunction(() => window.isoViewer?.shown.some((m) => m.kind === 'final'), null, { timeout: 300000 });
      for (const link of LINKS) {
        await cdp.send('Network.emulateNetworkConditions', link.conditions ??
          { offline: false, latency: 0, downloadThroughput: -1, uploadThroughput: -1 });
        // The codecs alternate, each repetition starting with the other: the machine's
        // load moves, and side by side is what makes a ratio.
        const runs = Object.fromEntries(CODECS.map((c) => [c, []]));
        for (let r = 0; r < REPEAT; r++)
          for (const codec of r % 2 ? [...CODECS].reverse() : CODECS) {
            // A level not asked before: the server extracts and encodes (uncached).
            const level = vol.level + 0.001 * ++bump;
            const run = await timedLoad(page, level, codec);
            if (run.kind !== 'final' || Math.abs(run.level - level) > 1e-9) throw new Error(`${vol.id}: drew ${JSON.stringify(run)}`);
            runs[codec].push(run);
          }
        for (const codec of CODECS) {
          const rs = runs[codec];
          const row = { volume: vol.label, link: link.name, codec, ms: median(rs.map((x) => x.ms)),
            firstByteMs: median(rs.map((x) => x.firstByteMs)), transferMs: median(rs.map((x) => x.transferMs)),
            afterMs: median(rs.map((x) => x.afterMs)), decodeMs: median(rs.map((x) => x.decodeMs)), runs: rs.map((x) => Math.round(x.ms)),
            bytes: median(rs.map((x) => x.bytes)), triangles: rs[0].triangles };
          results.loads.push(row);
          console.log(`  ${row.volume} | ${row.link} | ${row.codec}: ${row.ms.toFixed(0)} ms (${row.runs.join(', ')}; ` +
            `first byte ${row.firstByteMs.toFixed(0)}, transfer ${row.transferMs.toFixed(0)}, decode+draw ${row.afterMs.toFixed(0)}, decode ${row.decodeMs.toFixed(0)}), ` +
            `${(row.bytes / 1e6).toFixed(2)} MB, ${row.triangles} triangles`);
        }
      }
    }
    // Dragging across the first volume's range (CThead) and the bunny's, loopback and 20 Mbit/s.
    for (const vol of vols.filter((v, k) => k === 0 || v.dragOnly)) {
      for (const link of !phases.has('drag') ? [] : process.env.ISO_BENCH_DRAG_LOOPBACK ? [LINKS[0]] : [LINKS[0], LINKS[2]]) {
        await cdp.send('Network.emulateNetworkConditions', link.conditions ??
          { offline: false, latency: 0, downloadThroughput: -1, uploadThroughput: -1 });
        for (const codec of CODECS) {
          await page.goto(`${base}?volume=${vol.id}&level=${vol.level}&tolerance=0&codec=${codec}`);
          await page.waitForFunction(() => window.isoViewer?.shown.some((m) => m.kind === 'final'), null, { timeout: 300000 });
          const d = await dragRate(page, codec, 4000);
          const row = { volume: vol.label, link: link.name, codec, ...d };
          results.drags.push(row);
          console.log(`  drag ${row.volume} | ${row.link} | ${codec}: ${d.perSecond.toFixed(1)} updates/s ` +
            `(${d.previews} previews, median ${d.triangles} triangles, ${(d.bytes / 1e3).toFixed(0)} kB decoded; medians: ` +
            `${d.gapMs?.toFixed(0)} ms between previews, request to answer ${d.fetchMs?.toFixed(0)} (server ${d.serverMs?.toFixed(0)}), ` +
            `decode ${d.decodeMs?.toFixed(0)}, draw ${d.drawMs?.toFixed(0)})`);
        }
      }
    }
  } finally {
    await context.close();
    server.kill('SIGTERM');
    rmSync(profile, { recursive: true, force: true });
    rmSync(tmp, { recursive: true, force: true });
  }
  printTables(results);
  mkdirSync('bench/results', { recursive: true });
  writeFileSync('bench/results/browser.json', JSON.stringify({ ...provenance(), ...results }, null, 1));
  console.log('wrote bench/results/browser.json');
}

function printTables({ views, orbits, loads, drags }) {
  if (views.length) {
    console.log('\n| volume | detail | client | first surface ms | triangles | full surface ms | triangles | first / full |');
    console.log('|---|---|---|---:|---:|---:|---:|---:|');
    for (const r of views) console.log(`| ${r.volume} | ${r.detail} | ${r.client} | ${r.firstMs.toFixed(0)} | ${r.firstTriangles.toLocaleString('en-US')} | ` +
      `${r.fullMs.toFixed(0)} | ${r.fullTriangles.toLocaleString('en-US')} | ${(r.firstTriangles / r.fullTriangles).toFixed(3)} |`);
  }
  for (const o of orbits) console.log(`\norbit ${o.volume} (${o.triangles.toLocaleString('en-US')} triangles): ${o.fps.toFixed(2)} frames/s, ` +
    `last move to its frame ${o.lastMoveToFrameMs} ms, release to the full frame ${o.releaseToFullFrameMs} ms`);
  if (!loads.length) return printDrags(drags);
  console.log('\n| volume | triangles | link | Draco ms (first byte / transfer / decode+draw; decode) | meshopt ms (same) | meshopt / Draco | Draco MB | meshopt MB |');
  console.log('|---|---:|---|---:|---:|---:|---:|---:|');
  const split = (r) => `${r.ms.toFixed(0)} (${r.firstByteMs.toFixed(0)} / ${r.transferMs.toFixed(0)} / ${r.afterMs.toFixed(0)}; ${r.decodeMs.toFixed(0)})`;
  const key = (r) => `${r.volume}|${r.link}`;
  for (const k of [...new Set(loads.map(key))]) {
    const [d, m] = CODECS.map((c) => loads.find((r) => key(r) === k && r.codec === c));
    console.log(`| ${d.volume} | ${d.triangles.toLocaleString('en-US')} | ${d.link} | ${split(d)} | ${split(m)} | ` +
      `${(m.ms / d.ms).toFixed(2)} | ${(d.bytes / 1e6).toFixed(2)} | ${(m.bytes / 1e6).toFixed(2)} |`);
  }
  printDrags(drags);
}

function printDrags(drags) {
  if (!drags.length) return;
  console.log('\n| drag across | link | codec | updates/s | median preview triangles |');
  console.log('|---|---|---|---:|---:|');
  for (const r of drags) console.log(`| ${r.volume} | ${r.link} | ${r.codec} | ${r.perSecond.toFixed(1)} | ${r.triangles.toLocaleString('en-US')} |`);
}

main().catch((e) => { console.error(e.stack || String(e)); process.exit(1); });
