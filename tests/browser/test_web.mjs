// test_web.mjs: the web client in headless Debian Chromium (playwright-core) against a real
// isoserve on 127.0.0.1. Prints PASS/FAIL/SKIP lines; exit status 1 on failure.
// usage: node tests/browser/test_web.mjs   (from the repository root, after make)
//
// Volumes: Debian's ch2bet brain and ch2 head (NIfTI with an sform) when installed, else an
// analytic torus; the shared CThead (no orientation in its header) when ../shared is there;
// a .seg.nrrd of three segments, a CT on its grid and a label map of 100 segments, made here.
// ISO_WEB_STEPS=segments,link runs only the steps named (while working on them).
import { existsSync, mkdtempSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join, resolve } from 'node:path';
import { meshoptIndexHeaders } from '../support/glb.mjs';
import { CHROMIUM_ARGS, canvasPixels, chromium, colourPixels, faceForwardForeheadUp, headLandmarks, pixelDifference, pixelStats,
  readCThead, readNiftiU8, settled, startServer, stopServer, waitReady } from './helpers.mjs';

// tests/run.sh's asan pass runs the page against build/san/isoserve and says web-san.
const label = `web${process.env.ISO_SAN_SUFFIX || ''}`;
let failures = 0;
const report = (name, ok, why = '') => {
  if (!ok) failures++;
  console.log(ok ? `PASS ${label}.${name}` : `FAIL ${label}.${name}: ${why}`);
};
const skip = (name, why) => console.log(`SKIP ${label}.${name}: ${why}`);

const tmp = mkdtempSync(join(tmpdir(), 'isoserve-web-'));
const MRICRON = '/usr/share/mricron/templates/';
const nifti = existsSync(`${MRICRON}ch2bet.nii.gz`);
const volume = nifti
  ? { id: 'brain', path: `${MRICRON}ch2bet.nii.gz`, levels: [30, 90], level: 60 }
  : { id: 'brain', path: 'field:torus:96', levels: [0, 8], level: 0 };
const shared = resolve(process.env.ISO_SHARED_VOLUMES ?? '../shared/volumes');
const cthead = join(shared, 'CThead_256x256x113_u16be.nhdr');
console.log(`web test volume: ${volume.path}`);
const entries = [{ id: volume.id, path: volume.path, name: 'Test volume', modality: 'MR', levels: volume.levels }];
if (nifti) entries.push({ id: 'head', path: `${MRICRON}ch2.nii.gz`, name: 'Colin head', modality: 'MR', levels: [37.7] });
if (existsSync(cthead)) {
  entries.push({ id: 'cthead', path: cthead, modality: 'CT', levels: [700.5] });
  entries.push({ id: 'cthead-lpi', path: cthead, modality: 'CT', levels: [700.5], orientation: 'LPI' });
}
const segmentation = writeSegmentation(tmp);
entries.push({ id: 'seg3', path: join(tmp, 'seg3.seg.nrrd'), labels: true }, { id: 'ct3', path: join(tmp, 'ct3.nrrd'), modality: 'CT', levels: [50] },
  { id: 'labels100', path: join(tmp, 'labels100.nrrd'), labels: true });
writeFileSync(join(tmp, 'catalog.json'), JSON.stringify({ volumes: entries }));

const wait = (ms) => new Promise((r) => setTimeout(r, ms));

// A 48x48x40 grid of 1 x 1 x 1.25 mm (LPS, i to the left, j posterior, k superior):
// seg3.seg.nrrd with three segments of known names, colours and voxels (1 "liver", red, a
// box in front; 2 "kidney", green, a ball on the patient's left; 3 "spleen", blue, a larger
// box behind the liver), ct3.nrrd on the same grid (a box of 100 around them), and
// labels100.nrrd: 100 small cubes numbered 1..100, no names.
function writeSegmentation(dir) {
  const dims = [48, 48, 40], spacing = [1, 1, 1.25], n = dims[0] * dims[1] * dims[2];
  const at = (i, j, k) => (k * dims[1] + j) * dims[0] + i;
  const inBox = (p, lo, hi) => p.every((x, a) => x >= lo[a] && x < hi[a]);
  const seg = { boxes: { 1: [[8, 6, 12], [20, 16, 28]], 3: [[4, 24, 8], [26, 34, 32]] }, ball: { 2: [[36, 24, 20], 7] } };
  const labels = new Uint8Array(n), ct = new Uint8Array(n), many = new Uint8Array(n), voxels = [0, 0, 0, 0];
  for (let k = 0; k < dims[2]; k++) for (let j = 0; j < dims[1]; j++) for (let i = 0; i < dims[0]; i++) {
    const p = [i, j, k];
    let l = 0;
    if (inBox(p, ...seg.boxes[1])) l = 1;
    else if (inBox(p, ...seg.boxes[3])) l = 3;
    else if (Math.hypot(i - 36, j - 24, k - 20) <= 7) l = 2;
    labels[at(i, j, k)] = l;
    voxels[l]++;
    ct[at(i, j, k)] = inBox(p, [2, 2, 2], [46, 46, 38]) ? 100 : 0;
  }
  for (let c = 0; c < 100; c++) { // 100 cubes of 2^3 on a 5 x 5 x 4 lattice
    const [i0, j0, k0] = [4 + 9 * (c % 5), 4 + 9 * (Math.floor(c / 5) % 5), 4 + 9 * Math.floor(c / 25)];
    for (let k = k0; k < k0 + 2; k++) for (let j = j0; j < j0 + 2; j++) for (let i = i0; i < i0 + 2; i++) many[at(i, j, k)] = c + 1;
  }
  const header = (extra) => Buffer.from(`NRRD0004\ntype: uint8\ndimension: 3\nsizes: ${dims.join(' ')}\nspace: left-posterior-superior\n` +
    `space directions: (${spacing[0]},0,0) (0,${spacing[1]},0) (0,0,${spacing[2]})\nspace origin: (0,0,0)\nencoding: raw\n${extra}\n`);
  const names = { 1: ['liver', '0.9 0.1 0.1'], 2: ['kidney', '0.1 0.8 0.15'], 3: ['spleen', '0.15 0.3 0.95'] };
  const keys = Object.entries(names).map(([l, [name, color]], s) => `Segment${s}_ID:=Segment_${l}\nSegment${s}_Name:=${name}\n` +
    `Segment${s}_Color:=${color}\nSegment${s}_LabelValue:=${l}\nSegment${s}_Layer:=0\n`).join('');
  writeFileSync(join(dir, 'seg3.seg.nrrd'), Buffer.concat([header(keys), labels]));
  writeFileSync(join(dir, 'ct3.nrrd'), Buffer.concat([header(''), ct]));
  writeFileSync(join(dir, 'labels100.nrrd'), Buffer.concat([header(''), many]));
  const voxelMm3 = spacing[0] * spacing[1] * spacing[2];
  const centre = (l) => (seg.boxes[l] ? seg.boxes[l][0].map((lo, a) => (lo + seg.boxes[l][1][a] - 1) / 2) : seg.ball[l][0]);
  return { names, voxels, ml: voxels.map((v) => (v * voxelMm3) / 1000), centre };
}
const meshOf = (responses) => responses.filter((r) => r.url().includes('/mesh?'));

// 1. One preview, then the surface: two mesh requests, the first at the preview tolerance
// without normals and at most 12% of the surface's triangles, the second the mesh asked
// for; the stats show the header's count; the link and downloads say what is shown.
async function firstView(page, base, responses) {
  const info = await (await fetch(`${base}v1/volumes/${volume.id}`)).json();
  responses.length = 0;
  await page.goto(`${base}?volume=${volume.id}&level=${volume.level}&tolerance=1&normals=tricubic&codec=draco`);
  await settled(page);
  const meshes = meshOf(responses);
  const [preview, full] = meshes.map((r) => ({ url: new URL(r.url()), triangles: Number(r.headers()['x-iso-triangles']) }));
  const shown = await page.evaluate(() => window.isoViewer.shown.map((m) => m.kind));
  console.log(`  info: first view: ${meshes.length} mesh requests; preview ${preview?.triangles} triangles at tolerance ` +
    `${preview?.url.searchParams.get('tolerance')}, surface ${full?.triangles} (${(100 * preview?.triangles / full?.triangles).toFixed(1)}%)`);
  report('one_preview_then_the_surface', meshes.length === 2 && shown.join() === 'preview,final' &&
    Number(preview.url.searchParams.get('tolerance')) === info.value_range[1] - info.value_range[0] &&
    preview.url.searchParams.get('normals') === 'none' &&
    full.url.searchParams.get('tolerance') === '1' && preview.triangles <= 0.12 * full.triangles,
    JSON.stringify({ shown, meshes: meshes.map((r) => r.url()) }));
  firstView.triangles = full.triangles;
  const stat = (await page.textContent('#stat-triangles')).replace(/,/g, '');
  report('stats_match_header', stat === String(full.triangles), `${stat} vs ${full.triangles}`);
  const speed = meshes[1].headers()['x-iso-draco-speed'];
  report('stats_show_draco_speed', /^(8|10)$/.test(speed ?? '') && (await page.textContent('#stat-speed')) === speed, speed);
  const url = page.url();
  report('url_keeps_state', url.includes(`volume=${volume.id}`) && url.includes(`level=${volume.level}`) && /camera=[-\d.,]+/.test(url), url);
  const links = await page.$$eval('#downloads a', (as) => as.map((a) => ({ href: a.getAttribute('href'), name: a.download })));
  const want = [['format=glb&', '.glb'], ['format=glb-plain', '_plain.glb'], ['format=ply', '.ply'], ['format=stl', '.stl']];
  report('downloads_every_format_exact_level_closed', links.length === 4 && want.every(([f, ext], k) => links[k].href.includes(f) &&
    links[k].href.includes('cap=true') && links[k].name === `${volume.id}_level${volume.level}_tol1_closed${ext}`),
    JSON.stringify(links));
  // A download is what the server serves at that URL: an STL of the closed surface.
  const stl = await fetch(base + links[3].href);
  report('download_stl_closed', stl.status === 200 && stl.headers.get('content-type') === 'model/stl', String(stl.status));
  const labels = await page.evaluate(() => [...document.querySelectorAll('#panel input, #panel select')].filter((el) => {
    if (el.closest('label') || el.getAttribute('aria-label')) return false;
    return !(el.id && document.querySelector(`label[for="${el.id}"]`));
  }).map((el) => el.id));
  report('every_control_labelled', labels.length === 0, labels.join(', '));
  const option = await page.textContent('#volume option');
  report('volume_menu_names', option === `Test volume (${volume.id})`, option);
}

// 2. Progress and cancel: while the server works on the surface the status says so (and
// for how long); Esc cancels it, the preview stays and the panel says it is a preview.
async function progressAndCancel(page, base) {
  await page.goto(`${base}?volume=${volume.id}&level=${volume.level}&tolerance=0.5`);
  await page.route((u) => u.href.includes('/mesh?') && u.href.includes('tolerance=0.5&'), async (route) => {
    await wait(1500);
    await route.continue().catch(() => {});
  });
  await page.waitForFunction(() => /server extracting the surface/.test(document.getElementById('status').textContent), null, { timeout: 60000 });
  const during = await page.textContent('#status');
  await page.keyboard.press('Escape');
  await page.waitForFunction(() => !window.isoViewer.ctx.loader.pending(), null, { timeout: 10000 });
  await wait(1700);
  const after = await page.evaluate(() => ({ drawn: window.isoViewer.ctx.loader.live[0].drawn?.kind, status: document.getElementById('status').textContent,
    badge: document.getElementById('level-drawn').textContent }));
  await page.unrouteAll({ behavior: "ignoreErrors" });
  report('progress_shows_wait_and_cancels', /\(\d+\.\d s\)/.test(during) && /Cancel/.test(during) && after.drawn === 'preview' &&
    /preview/.test(after.status) && after.badge === '(preview)', JSON.stringify({ during, after }));
}

// 3. The server gone: the request is tried again with a countdown; the panel says which
// level is drawn meanwhile; once the server answers, Retry now draws the level asked for.
async function retries(page, base) {
  await page.goto(`${base}?volume=${volume.id}&level=${volume.level}&tolerance=1`);
  await settled(page);
  await page.route((u) => u.href.includes('/mesh?'), (route) => route.abort('connectionrefused'));
  await page.evaluate(() => {
    const el = document.getElementById('level');
    el.value = String(Number(el.value) + 60);
    el.dispatchEvent(new Event('change'));
  });
  await page.waitForSelector('#retry-1', { timeout: 20000 });
  const status = await page.textContent('#status');
  const badge = await page.textContent('#level-drawn');
  await page.unrouteAll({ behavior: "ignoreErrors" });
  await page.click('#retry-1');
  await settled(page);
  const final = await page.evaluate(() => ({ drawn: window.isoViewer.ctx.loader.live[0].drawn.level, want: window.isoViewer.state.surfaces[0].level,
    badge: document.getElementById('level-drawn').textContent }));
  report('server_gone_retries_with_backoff', /not loaded: the server did not answer.*trying again in \d+ s \(attempt \d+\)/.test(status) && /showing 60/.test(badge) &&
    final.drawn === final.want && final.badge === '', JSON.stringify({ status, badge, final }));
}

// 4. Dragging: previews while the slider moves, never more than one mesh request in
// flight, and after release the full mesh of the final level (also a while later).
async function dragTests(page, base) {
  await page.goto(`${base}?volume=${volume.id}&level=${volume.level}&tolerance=0`);
  await settled(page);
  await page.evaluate(() => {
    window.meshFetches = { now: 0, most: 0, total: 0 };
    const plain = window.fetch;
    window.fetch = (url, options) => {
      if (!String(url).includes('/mesh?')) return plain(url, options);
      const f = window.meshFetches;
      f.now++; f.total++; f.most = Math.max(f.most, f.now);
      let done = false;
      const settle = () => { if (!done) { done = true; f.now--; } };
      options?.signal?.addEventListener('abort', settle);
      return plain(url, options).then((response) => {
        const reader = response.body.getReader.bind(response.body);
        response.body.getReader = () => {
          const r = reader();
          const read = r.read.bind(r);
          r.read = () => read().then((x) => { if (x.done) settle(); return x; }, (e) => { settle(); throw e; });
          return r;
        };
        return response;
      }, (error) => { settle(); throw error; });
    };
  });
  const before = await page.evaluate(() => window.isoViewer.shown.length);
  await page.evaluate(async () => {
    const el = document.getElementById('level');
    for (let k = 0; k <= 40; k++) {
      el.value = String(Math.round(150 + 450 * k / 40));
      el.dispatchEvent(new Event('input'));
      await new Promise((r) => setTimeout(r, 40));
    }
    el.dispatchEvent(new Event('change'));
  });
  await settled(page);
  await wait(500);
  const r = await page.evaluate((n) => ({ shown: window.isoViewer.shown.slice(n), fetches: window.meshFetches,
    state: window.isoViewer.state.surfaces[0].level, slider: Number(document.getElementById('level-value').textContent.replace(/,/g, '')),
    url: location.search }), before);
  const drags = r.shown.filter((m) => m.kind === 'drag'), last = r.shown.at(-1);
  console.log(`  info: drag: ${drags.length} previews in 1.6 s, ${r.fetches.total} mesh requests, at most ${r.fetches.most} in flight`);
  report('drag_shows_previews', drags.length >= 2, `${drags.length} previews`);
  report('drag_one_request_in_flight', r.fetches.most === 1, `at most ${r.fetches.most} in flight`);
  report('drag_final_mesh_is_final_level', last?.kind === 'final' && last.level === r.state &&
    Math.abs(last.level - r.slider) <= 1e-6 * Math.abs(r.slider) + 1e-9 && r.url.includes(`level=${r.state}&`), JSON.stringify({ last, r: { ...r, shown: 0 } }));
}

// 5. Two surfaces, a clipping plane, a turned camera, wireframe off, light background:
// the link restores every pixel; the measures match the server's.
async function linkTests(page, base) {
  const [outer, inner] = volume.levels;
  // Tolerance 40 (about a third of the brain's range) halves the triangles software GL draws.
  await page.goto(`${base}?volume=${volume.id}&level=${outer}&tolerance=40&color=ff2020&opacity=0.35&level2=${inner}&color2=2040ff`);
  await settled(page);
  const both = await pixelStats(page);
  report('two_surfaces_two_colours', both.red > 0.005 && both.blue > 0.01, JSON.stringify(both));
  await page.check('#clip');
  await page.evaluate(() => window.isoViewer.view.drawn());
  const cut = await pixelStats(page);
  const [kept, gone] = cut.left > cut.right ? ['left', 'right'] : ['right', 'left'];
  report('clip_plane_cuts_one_half', cut[gone] < 0.35 * both[gone] && cut[kept] > 0.7 * both[kept], JSON.stringify({ both, cut }));
  // Turn the camera by dragging, then the light background.
  const box = await page.locator('#view canvas:not(.marker)').boundingBox();
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
  await page.mouse.down();
  await page.mouse.move(box.x + box.width / 2 + 120, box.y + box.height / 2 - 30, { steps: 3 });
  await page.mouse.up();
  await page.check('#light');
  await page.evaluate(() => window.isoViewer.view.drawn());
  const before = await canvasPixels(page);
  const link = page.url();
  report('url_holds_the_view', /level2=/.test(link) && /color=ff2020/.test(link) && /opacity=0.35/.test(link) &&
    /color2=2040ff/.test(link) && /clip=x:0.5/.test(link) && /background=light/.test(link) && /camera=[-\d.,]+/.test(link), link);
  await page.goto(link);
  await settled(page);
  const diff = await pixelDifference(page, before);
  const cache = await page.textContent('#stat-cache');
  report('link_restores_the_same_pixels', diff.differ === 0, `${diff.differ} pixels (${(100 * diff.share).toFixed(2)}%) differ`);
  report('browser_cache_said', cache === 'browser cache', cache);
  await page.click('#measure');
  await page.waitForFunction(() => (document.getElementById('measures').textContent.match(/mm²/g) || []).length === 2, null, { timeout: 90000 });
  const text = await page.textContent('#measures');
  const head = await fetch(`${base}v1/volumes/${volume.id}/mesh?level=${outer}&tolerance=40&normals=none&format=ply&cap=true&measures=true`, { method: 'HEAD' });
  const area = Number(head.headers.get('x-iso-area-mm2')), ml = Number(head.headers.get('x-iso-volume-mm3')) / 1000;
  const shownArea = Number(/area([\d,.]+) mm²/.exec(text)?.[1].replace(/,/g, ''));
  const shownMl = Number(/enclosed volume([\d,.]+) mL/.exec(text)?.[1].replace(/,/g, ''));
  report('measures_on_demand', Math.abs(shownArea - area) <= 1e-5 * area && head.headers.get('x-iso-closed') === 'true' &&
    Math.abs(shownMl - ml) <= 1e-4 * ml, `shown ${shownArea} mm², ${shownMl} mL; server ${area} mm², ${ml} mL`);
}

// 6. The fast codec draws the same mesh as Draco, from an index stream of codec version 1
// (header 0xe1, as EXT_meshopt_compression requires); Detail offers distinct levels within
// a few voxels and draws the chain's smaller mesh.
async function codecAndDetail(page, base, draco) {
  const fast = page.waitForResponse((r) => r.url().includes('format=glb-meshopt') && r.url().includes(`level=${volume.level}&tolerance=1&`), { timeout: 60000 });
  await page.goto(`${base}?volume=${volume.id}&level=${volume.level}&tolerance=1`);
  await settled(page);
  const exact = await page.evaluate(() => window.isoViewer.ctx.loader.live[0].drawn.triangles);
  const headers = meshoptIndexHeaders(new Uint8Array(await (await fast).body()));
  report('meshopt_codec_draws', (await page.textContent('#stat-codec')) === 'meshopt' && exact === draco.triangles &&
    headers.length === 1 && headers[0] === 0xe1, `${exact} triangles (Draco ${draco.triangles}), index headers ${headers}`);
  const detail = await page.evaluate(() => window.isoViewer.ctx.detail);
  const voxelMm = Math.min(...(await (await fetch(`${base}v1/volumes/${volume.id}`)).json()).spacing);
  const distances = detail.positions.map((p) => p.distance);
  const distinct = detail.positions.every((p, k) => k === 0 || !p.triangles || p.triangles < (detail.positions[k - 1].triangles ?? Infinity));
  report('detail_offers_distinct_levels_within_3_voxels', distances[0] === 0 && distances.length >= 2 &&
    distances.every((d, k) => k === 0 || (d > distances[k - 1] && d <= 3 * voxelMm * 1.0001)) && distinct, JSON.stringify(detail.positions));
  const at = Math.min(2, detail.positions.length - 1);
  await page.evaluate((at) => {
    const el = document.getElementById('distance');
    el.value = String(at);
    el.dispatchEvent(new Event('input'));
    el.dispatchEvent(new Event('change'));
  }, at);
  const detailed = await page.waitForResponse((r) => r.url().includes('/mesh?') && r.url().includes('distance='), { timeout: 120000 });
  await settled(page);
  const h = detailed.headers(), asked = Number(new URL(detailed.url()).searchParams.get('distance'));
  const label = await page.textContent('#distance-value');
  report('detail_draws_the_chain_level', Math.abs(asked - distances[at]) < 1e-9 && Number(h['x-iso-distance-mm']) <= asked &&
    Number(h['x-iso-chain-level']) >= 1 && Number(h['x-iso-triangles']) < exact && / mm = [\d.]+ voxel/.test(label) &&
    page.url().includes(`distance=${asked}`), `asked ${asked} mm, got ${h['x-iso-distance-mm']} mm, level ${h['x-iso-chain-level']}, ` +
    `${h['x-iso-triangles']} of ${exact}; "${label}"`);
  // The chain's own figures (GET .../chain, here as a server that has the route answers,
  // finest level first): positions only at levels that change the mesh (level 2 is no
  // closer than level 3, so asking its distance would give level 3) and none past 3
  // voxels; a chain level no larger than a preview is asked for without one.
  const voxel3 = 3 * voxelMm;
  const levels = [[600000, 0], [300000, 0.1], [150000, 0.25], [75000, 0.2], [37000, 0.6], [18000, 1.5], [9000, voxel3 * 1.5]]
    .map(([triangles, p99]) => ({ triangles, distance_p99_mm: p99 * voxelMm, distance_max_mm: 2 * p99 * voxelMm }));
  await page.route((u) => u.pathname.endsWith('/chain'), (route) => route.fulfill({ contentType: 'application/json',
    body: JSON.stringify({ level: volume.level, tolerance: 1, state: 'ready', exact_triangles: 600000, levels }) }));
  await page.goto(`${base}?volume=${volume.id}&level=${volume.level}&tolerance=1`);
  await settled(page);
  await page.waitForFunction(() => window.isoViewer.ctx.detail.chain?.state === 'ready', null, { timeout: 20000 });
  const mocked = await page.evaluate(() => window.isoViewer.ctx.detail.positions.map((p) => [p.k ?? 0, p.triangles ?? 0]));
  report('detail_positions_from_the_chain', JSON.stringify(mocked) === JSON.stringify([[0, 0], [1, 300000], [3, 75000], [4, 37000], [5, 18000]]),
    JSON.stringify(mocked));
  const n = await page.evaluate(() => window.isoViewer.shown.length);
  await page.evaluate(() => {
    const el = document.getElementById('distance');
    el.value = '4';
    el.dispatchEvent(new Event('input'));
    el.dispatchEvent(new Event('change'));
  });
  await settled(page);
  const after = await page.evaluate((n) => ({ kinds: window.isoViewer.shown.slice(n).map((m) => m.kind), distance: window.isoViewer.state.distance,
    label: document.getElementById('distance-value').textContent }), n);
  report('detail_small_level_without_preview', after.kinds.join() === 'final' && Math.abs(after.distance - 1.5 * voxelMm) < 1e-3 &&
    /18,000 triangles, p99/.test(after.label), JSON.stringify(after));
  await page.unrouteAll({ behavior: 'ignoreErrors' });
  // A link asking far beyond a few voxels asks for no more than the last position.
  await page.goto(`${base}?volume=${volume.id}&level=${volume.level}&tolerance=1&distance=100`);
  await settled(page);
  const capped = await page.evaluate(() => window.isoViewer.state.distance);
  report('detail_capped_from_a_link', capped <= 3 * voxelMm * 1.0001, String(capped));
}

// 7. The patient the right way up: the default view is anterior with superior up, judged
// by depth pixels against landmarks found in the scans themselves; the preset keys and
// the marker follow; a volume without orientation says so, opens as LPS and is put right
// by its catalog entry or by the axes control.
async function orientationTests(page, base) {
  if (!nifti) return skip('orientation_ch2', `needs ${MRICRON}ch2.nii.gz (Debian mricron-data)`);
  const ch2 = headLandmarks(readNiftiU8(`${MRICRON}ch2.nii.gz`), 37.7, { axis: 1, sign: 1 }, { axis: 2, sign: 1 });
  await page.goto(`${base}?volume=head&level=37.7&tolerance=80`);
  await settled(page);
  const [ok, why] = await faceForwardForeheadUp(page, ch2);
  report('ch2_face_toward_viewer_forehead_up', ok, why);
  const note = await page.isHidden('#orientation-note');
  report('oriented_file_no_note', note, 'the note shows for an oriented file');
  await page.keyboard.press('p');
  await page.evaluate(() => window.isoViewer.view.drawn());
  const back = await page.evaluate(() => {
    const c = window.isoViewer.view.camera, d = c.camera.position.clone().sub(c.controls.target).normalize();
    const letters = window.isoViewer.view.marker.letters(c.camera, 800, 600);
    return { d: d.toArray(), url: location.search, front: Object.entries(letters).sort((a, b) => a[1].depth - b[1].depth)[0][0] };
  });
  report('preset_posterior_and_marker', back.d[1] > 0.999 && /camera=/.test(back.url) && back.front === 'P', JSON.stringify(back));
  await page.keyboard.press('0');
  const reset = await page.evaluate(() => {
    const c = window.isoViewer.view.camera;
    return c.camera.position.clone().sub(c.controls.target).normalize().toArray();
  });
  report('reset_is_anterior', reset[1] < -0.999, JSON.stringify(reset));
  if (!existsSync(cthead)) return skip('orientation_cthead', `${cthead} is absent`);
  const ct = readCThead(cthead.replace('.nhdr', '.raw.gz'));
  // CThead's slice 0 is the crown (its head narrows to nothing there) and its face is at
  // low j (the nose reaches j = 8; the table lies at high j).
  const marks = headLandmarks(ct, 700.5, { axis: 1, sign: -1 }, { axis: 2, sign: -1 }, ct.value);
  await page.goto(`${base}?volume=cthead-lpi&level=700.5&tolerance=400`);
  await settled(page);
  const [okLpi, whyLpi] = await faceForwardForeheadUp(page, marks);
  report('cthead_catalog_orientation_face_forward_forehead_up', okLpi, whyLpi);
  await page.goto(`${base}?volume=cthead&level=700.5&tolerance=400`);
  await settled(page);
  const [okNone] = await faceForwardForeheadUp(page, marks);
  const noteShown = await page.isVisible('#orientation-note') && await page.isVisible('#axes');
  report('cthead_without_orientation_says_so_and_opens_as_lps', !okNone && noteShown, `upright ${okNone}, note ${noteShown}`);
  await page.selectOption('#axes', 'LPI');
  await settled(page);
  const [okAxes, whyAxes] = await faceForwardForeheadUp(page, marks);
  report('cthead_axes_control_puts_it_right', okAxes && page.url().includes('axes=LPI'), whyAxes);
}

// 8. A mesh over the server's limit: the preview stays, and one click shows the finest
// mesh within the limit.
async function tooLarge(browserContext, limitBase) {
  const page = await browserContext.newPage();
  try {
    await page.goto(`${limitBase}?volume=${volume.id}&level=${volume.level}&tolerance=0`);
    await page.waitForSelector('#fit-1', { timeout: 120000 });
    const offer = await page.textContent('#fit-1');
    await page.click('#fit-1');
    await settled(page);
    const drawn = await page.evaluate(() => window.isoViewer.ctx.loader.live[0].drawn);
    report('too_large_offers_what_fits', drawn.kind === 'final' && drawn.triangles <= 20000 && drawn.triangles > 0,
      `${offer}: drew ${JSON.stringify({ ...drawn, mesh: undefined })}`);
  } finally {
    await page.close();
  }
}

// 9. Help, keys, the histogram, the panel's height.
async function panelTests(page, base) {
  await page.setViewportSize({ width: 1100, height: 800 });
  await page.goto(`${base}?volume=${volume.id}&level=${volume.level}&tolerance=1`);
  await settled(page);
  // Turning with the button held draws the preview while full frames are slow, and the
  // full mesh once released (the picture that stays is the surface).
  const canvas = await page.locator('#view canvas:not(.marker)').boundingBox();
  await page.mouse.move(canvas.x + 300, canvas.y + 300);
  await page.mouse.down();
  await page.mouse.move(canvas.x + 340, canvas.y + 310, { steps: 2 });
  await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
  const held = await page.evaluate(() => { const v = window.isoViewer.view, s = v.surfaces[0];
    return { slow: v.fullFrameMs, lod: s.lod?.visible ?? null, full: s.mesh.visible, frames: v.frames }; });
  await page.mouse.up();
  await page.evaluate(() => window.isoViewer.view.drawn());
  const released = await page.evaluate(() => { const s = window.isoViewer.view.surfaces[0]; return { lod: s.lod?.visible ?? null, full: s.mesh.visible }; });
  report('turning_draws_preview_then_full', (held.slow > 60 ? held.lod === true && !held.full : held.full) &&
    released.full && released.lod !== true, JSON.stringify({ held, released }));
  const fits = await page.evaluate(() => { const p = document.getElementById('panel'); return [p.scrollHeight, p.clientHeight]; });
  report('panel_fits_800px', fits[0] <= fits[1], `${fits[0]} px of content in ${fits[1]}`);
  await page.keyboard.press('?');
  const help = await page.isVisible('#help') && /reset the view/.test(await page.textContent('#help'));
  await page.keyboard.press('Escape');
  report('help_overlay_and_escape', help && await page.isHidden('#help'), 'help');
  const levels = await page.evaluate(() => window.isoViewer.ctx.suggested());
  await page.keyboard.press('n');
  const next = await page.evaluate(() => window.isoViewer.state.surfaces[0].level);
  report('key_n_next_suggested_level', levels.includes(next), `${next} not in ${levels}`);
  const box = await page.locator('#histogram').boundingBox();
  await page.mouse.click(box.x + box.width / 2, box.y + box.height / 3);
  await settled(page);
  const picked = await page.evaluate(() => {
    const { state, ctx } = window.isoViewer, i = ctx.info();
    return { level: state.surfaces[0].level, mid: (i.histogram.min + i.histogram.max) / 2, width: (i.histogram.max - i.histogram.min) / 100 };
  });
  report('histogram_click_sets_level', Math.abs(picked.level - picked.mid) <= picked.width, JSON.stringify(picked));
  await page.setViewportSize({ width: 1100, height: 760 });
}

// 10. A segmentation: opening the .seg.nrrd opens the CT on its grid with the segments
// over it (alone at first); the panel lists each segment's name, colour and volume in mL
// (the voxels counted here); one request brings them all; each colour shows where its
// segment projects, goes when it is hidden (no request) and comes back; the clipping plane
// cuts the ball on the left; a translucent liver shows the spleen behind it; the CT's
// surface covers them; the link restores the same state and pixels; "none" and "all"; a
// label map of 100 segments lists them all in a list that scrolls, the panel within 800 px.
async function segmentTests(page, base, responses, browserContext) {
  const seg = segmentation;
  const segRequests = () => responses.filter((r) => /\/segments\/(\d+\/)?mesh\?/.test(r.url())).map((r) => r.url());
  const points = [1, 2, 3].map((l) => seg.centre(l));
  const near = (c, p, mm) => Math.hypot(c.x - p.x, c.y - p.y) * c.mmPerPixel <= mm;
  responses.length = 0;
  await page.goto(`${base}?volume=seg3`);
  await settled(page, 60000);
  const opened = await page.evaluate(() => ({ volume: window.isoViewer.state.volume, url: location.search,
    rows: [...document.querySelectorAll('#segment-list .segment')].map((r) => ({ name: r.querySelector('.seg-name').textContent,
      swatch: getComputedStyle(r.querySelector('.seg-swatch')).backgroundColor, ml: r.querySelector('.seg-ml').textContent,
      on: r.querySelector('input[type=checkbox]').checked })) }));
  const doc = await (await fetch(`${base}v1/volumes/seg3/segments`)).json();
  const wantRows = [1, 2, 3].map((l) => ({ name: seg.names[l][0], ml: `${Number(seg.ml[l].toPrecision(4)).toLocaleString('en-US')} mL` }));
  const rgb = (hex) => `rgb(${[1, 3, 5].map((k) => parseInt(hex.slice(k, k + 2), 16)).join(', ')})`;
  report('segments_panel_lists_names_colours_ml', opened.rows.length === 3 && opened.rows.every((r, k) => r.name === wantRows[k].name &&
    r.ml === wantRows[k].ml && r.on && r.swatch === rgb(doc.segments[k].color_hex) && doc.segments[k].voxels === seg.voxels[k + 1]),
    JSON.stringify({ rows: opened.rows, want: wantRows, voxels: seg.voxels }));
  report('segmentation_opens_over_its_ct', opened.volume === 'ct3' && /segmentation=seg3/.test(opened.url) &&
    meshOf(responses).every((r) => !/volumes\/ct3\/mesh/.test(r.url())), JSON.stringify(opened.url));
  report('segments_one_request_for_all', segRequests().length === 1 && /\/seg3\/segments\/mesh\?/.test(segRequests()[0]), segRequests().join(' '));
  const all = await colourPixels(page, points);
  report('segment_colours_where_they_project', ['red', 'green', 'blue'].every((c, k) => all[c].count > 0.002 * all.pixels &&
    near({ ...all[c], mmPerPixel: all.mmPerPixel }, all.at[k], k === 2 ? 4 : 2)) && all.beige.count === 0,
    JSON.stringify({ ...all, at: all.at }));
  // Hidden: gone, without a request; shown again: back, still without one.
  await page.uncheck('#seg-2-on');
  await page.evaluate(() => window.isoViewer.view.drawn());
  const hidden = await colourPixels(page);
  await page.check('#seg-2-on');
  await page.evaluate(() => window.isoViewer.view.drawn());
  const back = await colourPixels(page);
  report('segment_hidden_and_shown_without_requests', hidden.green.count === 0 && Math.abs(hidden.red.count - all.red.count) <= 0.02 * all.red.count &&
    back.green.count === all.green.count && segRequests().length === 1, JSON.stringify({ all: all.green.count, hidden: hidden.green.count, back: back.green.count, requests: segRequests().length }));
  await page.check('#clip');
  await page.evaluate(() => window.isoViewer.view.drawn());
  const cut = await colourPixels(page);
  report('clip_plane_cuts_segments', cut.green.count === 0 && cut.red.count >= 0.9 * all.red.count, JSON.stringify({ all, cut }));
  // The liver at 40%: the spleen behind it shows through where the liver projects.
  await page.evaluate(() => {
    const el = document.getElementById('seg-1-opacity');
    el.value = '40';
    el.dispatchEvent(new Event('input'));
  });
  await page.evaluate(() => window.isoViewer.view.drawn());
  const blend = await colourPixels(page, points);
  report('segment_opacity_blends', all.at[0].rgb[2] < 80 && blend.at[0].rgb[2] >= all.at[0].rgb[2] + 40 && blend.at[0].rgb[0] < all.at[0].rgb[0],
    JSON.stringify({ before: all.at[0].rgb, after: blend.at[0].rgb }));
  await page.uncheck('#seg-2-on');
  await page.check('#seg-ct');
  await settled(page, 60000);
  const ct = await colourPixels(page, points);
  report('ct_surface_under_segments', ct.beige.count > 0.02 * ct.pixels && ct.blue.count < 0.01 * blend.blue.count &&
    meshOf(responses).some((r) => /volumes\/ct3\/mesh/.test(r.url())), JSON.stringify({ ct, blend }));
  const link = page.url();
  const picture = await canvasPixels(page);
  report('segments_state_in_the_link', /segmentation=seg3/.test(link) && /segments=1,3(&|$)/.test(link) && /segopacity=1:0.4(&|$)/.test(link) &&
    /ct=true/.test(link) && /clip=x:0.5/.test(link), link);
  responses.length = 0;
  await page.goto(link);
  await settled(page, 60000);
  const diff = await pixelDifference(page, picture);
  const restored = await page.evaluate(() => [1, 2, 3].map((n) => [document.getElementById(`seg-${n}-on`).checked,
    document.getElementById(`seg-${n}-opacity-value`).textContent]).concat([document.getElementById('seg-ct').checked]));
  report('segments_link_restores_state_and_pixels', diff.differ === 0 && JSON.stringify(restored) ===
    JSON.stringify([[true, '40%'], [false, '100%'], [true, '100%'], true]) && segRequests().length === 1,
    `${diff.differ} pixels differ; ${JSON.stringify(restored)}; ${segRequests().join(' ')}`);
  await page.uncheck('#seg-ct');
  await page.uncheck('#clip');
  await page.click('#seg-none');
  await page.evaluate(() => window.isoViewer.view.drawn());
  const none = await colourPixels(page);
  const noneUrl = page.url();
  await page.click('#seg-all');
  await settled(page, 60000);
  const every = await colourPixels(page);
  report('segments_none_and_all', none.red.count + none.green.count + none.blue.count === 0 && /segments=none/.test(noneUrl) &&
    every.green.count > 0 && every.blue.count > 0 && !/segments=/.test(page.url()) && segRequests().length === 1,
    JSON.stringify({ none, every: [every.red.count, every.green.count, every.blue.count], noneUrl, requests: segRequests() }));
  // The CT opened: the segmentation on its grid comes with it, under the CT's own surface.
  await page.goto(`${base}?volume=ct3`);
  await settled(page, 60000);
  const image = await page.evaluate(() => ({ seg: window.isoViewer.state.seg.id, ct: document.getElementById('seg-ct').checked,
    rows: document.querySelectorAll('#segment-list .segment').length, url: location.search }));
  const imagePixels = await colourPixels(page);
  report('ct_opened_with_its_segmentation_under_its_surface', image.seg === 'seg3' && image.ct && image.rows === 3 && /ct=true/.test(image.url) &&
    imagePixels.beige.count > 0.02 * imagePixels.pixels, JSON.stringify({ image, beige: imagePixels.beige.count }));
  // One segment of three shown: its own mesh (Draco); another ticked: that one's alone.
  responses.length = 0;
  const camera = new URL(link).searchParams.get('camera'); // framed on all three
  await page.goto(`${base}?volume=ct3&segmentation=seg3&segments=2&ct=false&codec=draco&camera=${camera}`);
  await settled(page, 60000);
  const one = await colourPixels(page);
  const oneRequests = segRequests();
  await page.check('#seg-1-on');
  await settled(page, 60000);
  const two = await colourPixels(page);
  report('segments_fetched_one_by_one_never_twice', oneRequests.length === 1 && /\/segments\/2\/mesh\?.*format=draco/.test(oneRequests[0]) &&
    one.green.count > 0 && one.red.count === 0 && segRequests().length === 2 && /\/segments\/1\/mesh\?/.test(segRequests()[1]) &&
    two.red.count > 0 && two.green.count === one.green.count, JSON.stringify({ requests: segRequests(), one: [one.red.count, one.green.count], two: [two.red.count, two.green.count] }));
  // All of them over the server's triangle limit (a 422, made here: the page of its own
  // keeps the browser's log of it out of the console check): each shown segment alone.
  const limited = await browserContext.newPage();
  try {
    await limited.route((u) => u.pathname.endsWith('/segments/mesh'), (route) => route.fulfill({ status: 422,
      contentType: 'application/problem+json', body: JSON.stringify({ type: 'urn:isoserve:problem:mesh-too-large', title: 'too large',
        status: 422, detail: 'the mesh has 7,616 triangles, over this server\'s limit of 5,000' }) }));
    const asked = [];
    limited.on('request', (r) => { if (/\/segments\//.test(r.url()) && /mesh\?/.test(r.url())) asked.push(new URL(r.url()).pathname); });
    await limited.goto(`${base}?volume=seg3&camera=${camera}`);
    await settled(limited, 60000);
    const got = await limited.evaluate(() => ({ loaded: [...window.isoViewer.ctx.segs.loaded].sort(), error: document.getElementById('segments-status').textContent }));
    report('segments_over_the_limit_come_one_by_one', JSON.stringify(got.loaded) === '[1,2,3]' && asked.length === 4 &&
      asked[0].endsWith('/seg3/segments/mesh') && asked.slice(1).sort().join() === [1, 2, 3].map((n) => `/v1/volumes/seg3/segments/${n}/mesh`).join(),
      JSON.stringify({ got, asked }));
  } finally {
    await limited.close();
  }
  // A hundred segments (the scene glb with Draco): every row, a list that scrolls, a panel within 800 px.
  await page.setViewportSize({ width: 1100, height: 800 });
  responses.length = 0;
  await page.goto(`${base}?volume=labels100&codec=draco`);
  await settled(page, 60000);
  const many = await page.evaluate(() => {
    const list = document.getElementById('segment-list'), panel = document.getElementById('panel');
    return { rows: list.querySelectorAll('.segment').length, scrolls: list.scrollHeight > list.clientHeight, panel: [panel.scrollHeight, panel.clientHeight],
      last: list.querySelector('.segment:last-child .seg-name')?.textContent, ml: list.querySelector('.segment .seg-ml')?.textContent, loaded: window.isoViewer.ctx.segs.loaded.size };
  });
  report('hundred_segments_scroll_and_fit_800px', many.rows === 100 && many.scrolls && many.panel[0] <= many.panel[1] && many.loaded === 100 &&
    many.ml === '0.01 mL' && segRequests().length === 1, JSON.stringify({ many, requests: segRequests().length }));
  const labels = await page.evaluate(() => [...document.querySelectorAll('#panel input, #panel select')].filter((el) => {
    if (el.closest('label') || el.getAttribute('aria-label')) return false;
    return !(el.id && document.querySelector(`label[for="${el.id}"]`));
  }).map((el) => el.id));
  report('segment_controls_labelled', labels.length === 0, labels.join(', '));
  await page.setViewportSize({ width: 1100, height: 760 });
}

async function main() {
  const server = await startServer(join(tmp, 'catalog.json'));
  const limited = await startServer(join(tmp, 'catalog.json'), ['--max-triangles', '20000']);
  const base = `http://127.0.0.1:${server.port}/`;
  const profile = mkdtempSync(join(tmpdir(), 'isoserve-chromium-'));
  let context;
  try {
    await waitReady(server.port);
    await waitReady(limited.port);
    context = await chromium.launchPersistentContext(profile, { executablePath: '/usr/bin/chromium', headless: true,
      viewport: { width: 1100, height: 760 }, args: CHROMIUM_ARGS });
    const page = context.pages()[0] ?? await context.newPage();
    const errors = [], hosts = new Set(), responses = [];
    let chainRoute = true;
    const quiet = { refused: false };
    page.on('console', (m) => {
      // A server without the chain route answers the one probe for it with a 404; the
      // retries test refuses connections on purpose.
      if (m.type() !== 'error' || quiet.refused) return;
      if (!(/\/chain\?/.test(m.location()?.url ?? '') && !chainRoute)) errors.push(m.text());
    });
    page.on('pageerror', (e) => errors.push(String(e)));
    // Workers start from blob: URLs and the icon is a data: URL: local. Everything else must
    // go to the server on loopback.
    page.on('request', (r) => {
      const url = new URL(r.url());
      if (url.protocol !== 'blob:' && url.protocol !== 'data:') hosts.add(`${url.protocol}//${url.hostname}`);
    });
    page.on('response', (r) => {
      responses.push(r);
      if (r.url().includes('/chain?') && r.status() === 404) chainRoute = false;
    });

    const steps = [['first_view', () => firstView(page, base, responses)], ['progress', () => progressAndCancel(page, base)],
      ['retries', async () => { quiet.refused = true; try { await retries(page, base); } finally { quiet.refused = false; } }], ['drag', () => dragTests(page, base)], ['link', () => linkTests(page, base)],
      ['codec_detail', () => codecAndDetail(page, base, firstView)], ['orientation', () => orientationTests(page, base)],
      ['too_large', () => tooLarge(context, `http://127.0.0.1:${limited.port}/`)], ['panel', () => panelTests(page, base)],
      ['segments', () => segmentTests(page, base, responses, context)]];
    const only = process.env.ISO_WEB_STEPS?.split(',');
    for (const [name, run] of steps) {
      if (only && !only.includes(name)) continue;
      const t0 = Date.now();
      try { await run(); } catch (e) { report(name, false, e.stack || String(e)); }
      console.log(`  info: ${name}: ${((Date.now() - t0) / 1000).toFixed(1)} s`);
    }
    report('no_console_errors', errors.length === 0, errors.join(' | '));

    // An unknown volume: a readable error from the problem body (the browser logs the 404
    // itself, which is expected here).
    await page.goto(`${base}?volume=nope&level=1`);
    await page.waitForSelector('#error:not([hidden])', { timeout: 30000 });
    const message = await page.textContent('#error');
    report('unknown_volume_error', /no volume "nope"/.test(message), message);
    report('only_loopback', [...hosts].every((h) => h === 'http://127.0.0.1'), [...hosts].join(', '));
  } finally {
    await context?.close();
    await stopServer(server);
    await stopServer(limited);
    rmSync(profile, { recursive: true, force: true });
    rmSync(tmp, { recursive: true, force: true });
  }
}

main().catch((e) => { report('run', false, e.stack || String(e)); }).finally(() => process.exit(failures ? 1 : 0));
