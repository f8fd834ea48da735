// screenshots.mjs: the README's pictures: the shared CT head at the skin level, then skin
// (translucent) over bone with a clipping plane, as the web client shows them. Not part of
// make test (it needs ../shared/volumes).
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
// CThead's header has no orientation; its first slice is the crown: LPI.
writeFileSync(join(tmp, 'catalog.json'), JSON.stringify({ volumes: [{ id: 'cthead', name: 'CT head (Stanford)',
  modality: 'CT', path: resolve(shared, 'CThead_256x256x113_u16be.nhdr'), levels: [700.5, 1500.5], orientation: 'LPI' }] }));
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
const views = [
  ['skin', 'level=700.5'],
  ['skin-over-bone', 'level=700.5&color=e8b89a&opacity=0.3&level2=1500.5&color2=f2efe6&clip=x:0.55'],
];
for (const [name, query] of views) {
  await page.goto(`http://127.0.0.1:${port}/?volume=cthead&${query}`);
  const surfaces = query.includes('level2') ? 2 : 1;
  await page.waitForFunction((n) => [...Array(n).keys()].every((i) => window.isoViewer?.shown.some((m) => m.surface === i && m.kind === 'final')),
    surfaces, { timeout: 180000 });
  if (surfaces === 2) await page.keyboard.press('l'); // the patient's left: the cut faces the viewer
  await page.evaluate(() => window.isoViewer.view.drawn());
  await page.click('#measure');
  await page.waitForFunction((n) => (document.getElementById('measures').textContent.match(/mm²/g) || []).length === n, surfaces, { timeout: 180000 });
  await page.screenshot({ path: `docs/screenshot-${name}.png` });
  console.log(`docs/screenshot-${name}.png: ${query}`);
}
await context.close();
server.kill('SIGTERM');
rmSync(profile, { recursive: true, force: true });
rmSync(tmp, { recursive: true, force: true });
