// screenshots.mjs: the README's pictures: the shared CT head at skin and bone levels, as
// the web client shows them. Not part of make test (it needs ../shared/volumes).
// usage: node tests/browser/screenshots.mjs   (from the repository root, after make)
import { spawn } from 'node:child_process';
import { mkdtempSync, rmSync, writeFileSync } from 'node:fs';
import { createRequire } from 'node:module';
import { tmpdir } from 'node:os';
import { join, resolve } from 'node:path';

const require = createRequire(resolve('web/node_modules') + '/');
const { chromium } = require('playwright-core');
const shared = process.env.ISO_SHARED_VOLUMES ?? '../shared/volumes';
const tmp = mkdtempSync(join(tmpdir(), 'isoserve-shots-'));
writeFileSync(join(tmp, 'catalog.json'), JSON.stringify({ volumes: [{ id: 'cthead', name: 'CT head (Stanford)',
  modality: 'CT', path: resolve(shared, 'CThead_256x256x113_u16be.nhdr'), levels: [700.5, 1500.5] }] }));
const server = spawn(resolve('build/isoserve'), ['serve', '--catalog', join(tmp, 'catalog.json'), '--listen', '127.0.0.1:0'],
  { stdio: ['ignore', 'ignore', 'pipe'] });
const port = await new Promise((ok) => {
  let log = '';
  server.stderr.on('data', (d) => { log += d; const m = /127\.0\.0\.1:(\d+)\//.exec(log); if (m) ok(Number(m[1])); });
});
for (let i = 0; i < 200 && (await fetch(`http://127.0.0.1:${port}/healthz`).catch(() => ({}))).status !== 200; i++)
  await new Promise((r) => setTimeout(r, 100));
const profile = mkdtempSync(join(tmpdir(), 'isoserve-chromium-'));
const context = await chromium.launchPersistentContext(profile, {
  executablePath: '/usr/bin/chromium', headless: true, viewport: { width: 1200, height: 760 },
  args: ['--headless', '--no-sandbox', '--disable-gpu', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
    '--disable-background-networking', '--disable-component-update', '--disable-sync', '--no-first-run'],
});
const page = context.pages()[0] ?? await context.newPage();
for (const [name, level] of [['skin', 700.5], ['bone', 1500.5]]) {
  await page.goto(`http://127.0.0.1:${port}/?volume=cthead&level=${level}&tolerance=0&normals=tricubic`);
  const final = await page.waitForResponse((r) => r.url().includes(`level=${level}&tolerance=0&`), { timeout: 120000 });
  const t = final.headers()['x-iso-triangles'];
  await page.waitForFunction((n) => document.getElementById('stat-triangles')?.textContent.replace(/,/g, '') === n, t, { timeout: 120000 });
  await page.check('#flip'); // CThead's header has no orientation; its slices run foot to crown
  await page.waitForTimeout(300);
  await page.screenshot({ path: `docs/screenshot-${name}.png` });
  console.log(`docs/screenshot-${name}.png: level ${level}, ${t} triangles`);
}
await context.close();
server.kill('SIGTERM');
rmSync(profile, { recursive: true, force: true });
rmSync(tmp, { recursive: true, force: true });
