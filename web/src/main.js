// main.js: the viewer's state and its life. The URL holds the view (volume, tolerance,
// detail, normals, codec; per surface its level, colour and opacity; the clipping plane), so a link
// restores it.
//
// Each surface has at most one mesh request in flight. While its level slider moves, it
// shows previews (a coarse tolerance, no normals): when a preview arrives, the next one is
// asked for the slider's latest level, the levels passed over in between are never asked.
// On release the preview in flight is aborted and the full mesh fetched; a generation
// counter per surface drops any answer that a newer request has superseded, so a stale mesh
// never replaces the final one.
import { ApiError, CODEC_FORMATS, getJson, getMeasures, getMesh, meshUrl } from './api.js';
import { drawHistogram, formatNumber, showError, showMeasures, showScale, showStats } from './ui.js';
import { View } from './view.js';

const $ = (id) => document.getElementById(id);
const view = new View($('view'));
view.onScale = showScale;

// The codec the viewer asks for unless the URL says otherwise (docs/performance.md has the
// browser benchmark that chose it).
const DEFAULT_CODEC = 'meshopt';
const DEFAULT_COLORS = ['#e8dccb', '#6fa8dc'];

const state = {
  volume: null, tolerance: 0, distance: 0, normals: 'tricubic', codec: DEFAULT_CODEC, cap: true,
  surfaces: [
    { level: null, color: DEFAULT_COLORS[0], opacity: 1, on: true },
    { level: null, color: DEFAULT_COLORS[1], opacity: 1, on: false },
  ],
  clip: { on: false, axis: 'x', at: 0.5, flip: false },
};
// Per surface: the generation (bumped by every full request), the controllers of its
// requests, the preview pump's state.
const live = state.surfaces.map(() => ({ generation: 0, controller: null, inFlight: false, want: null,
  previewTolerance: null }));
// What the page has drawn, for the browser tests and the benchmark: one record per mesh
// shown; the benchmark also asks for one surface's full mesh and times it to the screen.
const shown = [];
window.isoViewer = { state, shown, refresh: (i, coarse) => refresh(i, coarse) };
let info = null;        // the current volume's document
let bounds = null;      // the volume's LPS box in mm: [[x0, y0, z0], [x1, y1, z1]]
let framedVolume = null;

// ---- sliders: level linear over the value range; tolerance log, position 0 is exactly 0
const range = () => (info ? info.value_range[1] - info.value_range[0] : 1) || 1;
const toleranceFromSlider = (s) => (s <= 0 ? 0 : range() * 10 ** ((s - 100) / 25));
const sliderFromTolerance = (t) => (t <= 0 ? 0 : Math.max(1, Math.min(100, 100 + 25 * Math.log10(t / range()))));
// Detail: distance= in mm, log over voxels of the smallest spacing (position 60 is one
// voxel); position 0 is 0, the surface itself (no distance asked).
const voxel = () => (info ? Math.min(...info.spacing) : 1);
const distanceFromSlider = (s) => (s <= 0 ? 0 : Number((voxel() * 10 ** ((s - 60) / 30)).toPrecision(2)));
const sliderFromDistance = (d) => (d <= 0 ? 0 : Math.max(1, Math.min(100, Math.round(60 + 30 * Math.log10(d / voxel())))));
const distanceText = (d) => (d <= 0 ? 'exact' : `${formatNumber(d, 3)} mm = ${formatNumber(d / voxel(), 2)} voxel`) +
  ` (voxel ${formatNumber(voxel(), 3)} mm)`;
const levelFromSlider = (s) => Number((info.value_range[0] + (s / 1000) * range()).toPrecision(6));
const sliderFromLevel = (l) => Math.round(((l - info.value_range[0]) / range()) * 1000);
// Previews: from the volume's own suggestion when it has one, else half the value range,
// never finer than the tolerance asked for; coarsened while a surface's previews come back
// with more than PREVIEW_TRIANGLES (each answer steers the next surface's tolerance by at
// most 1.5x, up to four times the value range). The server, the wire, the decoder and
// the draw all pay per triangle, and a preview only has to follow the slider.
const PREVIEW_TRIANGLES = 16000;
const previewFloor = () => Math.max(state.tolerance, info?.preview_tolerance ?? range() / 2);
const previewTolerance = (i) => Math.max(previewFloor(), live[i].previewTolerance ?? 0);
function steerPreview(i, tolerance, triangles) {
  if (!(triangles > 0)) return;
  const f = Math.min(1.5, Math.max(1 / 1.5, Math.sqrt(triangles / PREVIEW_TRIANGLES)));
  live[i].previewTolerance = Math.min(4 * range(), Math.max(previewFloor(), tolerance * f));
}
const format = () => CODEC_FORMATS[state.codec] ?? 'draco';

function volumeBounds(doc) {
  const m = doc.index_to_world;
  const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  for (let c = 0; c < 8; c++) {
    const ijk = [0, 1, 2].map((a) => ((c >> a) & 1) * (doc.dims[a] - 1));
    for (let r = 0; r < 3; r++) {
      const x = m[4 * r] * ijk[0] + m[4 * r + 1] * ijk[1] + m[4 * r + 2] * ijk[2] + m[4 * r + 3];
      lo[r] = Math.min(lo[r], x);
      hi[r] = Math.max(hi[r], x);
    }
  }
  return [lo, hi];
}

function writeUrl() {
  const q = new URLSearchParams({ volume: state.volume, level: String(state.surfaces[0].level),
    tolerance: String(state.tolerance), normals: state.normals, codec: state.codec });
  if (state.distance > 0) q.set('distance', String(state.distance));
  state.surfaces.forEach((s, i) => {
    const n = i ? String(i + 1) : '';
    if (i && !s.on) return;
    if (i) q.set(`level${n}`, String(s.level));
    if (s.color !== DEFAULT_COLORS[i]) q.set(`color${n}`, s.color.slice(1));
    if (s.opacity !== 1) q.set(`opacity${n}`, String(s.opacity));
  });
  if (state.clip.on) q.set('clip', `${state.clip.axis}:${state.clip.at}${state.clip.flip ? ':flip' : ''}`);
  if (!state.cap) q.set('cap', 'false');
  history.replaceState(null, '', `?${q}`);
}

function readUrl(q) {
  const finite = (v) => v !== null && v !== '' && Number.isFinite(Number(v));
  state.surfaces.forEach((s, i) => {
    const n = i ? String(i + 1) : '';
    if (finite(q.get(`level${n}`))) { s.level = Number(q.get(`level${n}`)); s.on = true; }
    if (/^[0-9a-f]{6}$/i.test(q.get(`color${n}`) ?? '')) s.color = `#${q.get(`color${n}`).toLowerCase()}`;
    if (finite(q.get(`opacity${n}`))) s.opacity = Math.min(1, Math.max(0.05, Number(q.get(`opacity${n}`))));
  });
  if (finite(q.get('tolerance')) && Number(q.get('tolerance')) >= 0) state.tolerance = Number(q.get('tolerance'));
  if (finite(q.get('distance')) && Number(q.get('distance')) >= 0) state.distance = Number(q.get('distance'));
  if (q.has('normals')) state.normals = q.get('normals');
  if (q.get('codec') in CODEC_FORMATS) state.codec = q.get('codec');
  if (q.get('cap') === 'false') state.cap = false;
  const clip = /^([xyz]):([0-9.]+)(:flip)?$/.exec(q.get('clip') ?? '');
  if (clip && Number(clip[2]) <= 1) state.clip = { on: true, axis: clip[1], at: Number(clip[2]), flip: !!clip[3] };
}

function syncControls() {
  state.surfaces.forEach((s, i) => {
    if (s.level !== null) {
      $(`level${i ? '-2' : ''}`).value = sliderFromLevel(s.level);
      $(`level${i ? '-2' : ''}-value`).textContent = formatNumber(s.level);
    }
    $(`color-${i + 1}`).value = s.color;
    $(`opacity-${i + 1}`).value = Math.round(s.opacity * 100);
  });
  $('surface-2').checked = state.surfaces[1].on;
  $('surface-2-controls').hidden = !state.surfaces[1].on;
  $('tolerance').value = sliderFromTolerance(state.tolerance);
  $('tolerance-value').textContent = state.tolerance === 0 ? '0 (exact)' : formatNumber(state.tolerance, 3);
  $('distance').value = sliderFromDistance(state.distance);
  $('distance-value').textContent = distanceText(state.distance);
  $('normals').value = state.normals;
  $('codec').value = state.codec;
  $('clip').checked = state.clip.on;
  $('clip-axis').value = state.clip.axis;
  $('clip-at').value = Math.round(state.clip.at * 1000);
  $('clip-flip').checked = state.clip.flip;
  $('cap').checked = state.cap;
  const params = { level: state.surfaces[0].level, tolerance: state.tolerance, normals: state.normals,
    distance: state.distance };
  $('download-glb').href = meshUrl(state.volume, { ...params, format: 'glb' });
  $('download-glb').download = `${state.volume}-${params.level}.glb`;
  $('download-ply').href = meshUrl(state.volume, { ...params, format: 'ply' });
  $('download-ply').download = `${state.volume}-${params.level}.ply`;
}

function applyClip() {
  const c = state.clip;
  const at = bounds ? bounds[0]['xyz'.indexOf(c.axis)] + c.at * (bounds[1]['xyz'.indexOf(c.axis)] - bounds[0]['xyz'.indexOf(c.axis)]) : 0;
  view.clip(c.on && !!bounds, c.axis, at, c.flip);
}

// Fetches, decodes and shows one mesh of surface i; false when a newer request of that
// surface superseded it on the way.
async function fetchAndShow(i, params, mine, signal, kind) {
  const started = performance.now();
  const mesh = await getMesh(state.volume, { ...params, format: format() }, signal);
  return display(i, mesh, params, mine, kind, started);
}

// Decodes and shows a fetched mesh unless a newer request of surface i superseded it.
async function display(i, mesh, params, mine, kind, started) {
  if (mine !== live[i].generation) return false;
  const start = performance.now();
  const decoded = await view.decode(mesh.bytes, state.codec);
  const decodeMs = performance.now() - start;
  if (mine !== live[i].generation) {
    decoded.geometry.dispose();
    return false;
  }
  const frame = i === 0 && framedVolume !== state.volume;
  const drawing = performance.now();
  view.show(i, decoded, frame);
  if (frame && mesh.triangles > 0) framedVolume = state.volume;
  // The split the browser benchmark reports: the answer's arrival after the request
  // (server and transfer; the server's own steps from its headers), decoding, drawing.
  shown.push({ surface: i, level: params.level, tolerance: params.tolerance, distance: params.distance ?? 0, kind,
    triangles: mesh.triangles, bytes: mesh.size, decodeMs, ms: performance.now() - started, at: performance.now(),
    fetchMs: (mesh.arrived ?? start) - started, serverMs: (mesh.extractMs ?? 0) + (mesh.normalsMs ?? 0) + (mesh.encodeMs ?? 0),
    drawMs: performance.now() - drawing });
  if (i === 0) showStats($('stats'), mesh, decodeMs, state.codec);
  if (i === 0) $('status').textContent = mesh.triangles === 0 ? 'no surface at this level' : '';
  return true;
}

function reportError(error) {
  if (error.name === 'AbortError') return;
  showError(error instanceof ApiError ? error.message : `Could not show the mesh: ${error.message}`);
  $('status').textContent = '';
}

// A settled change of surface i: a coarse mesh first (when `coarse` and it is coarser),
// then the one asked for. Aborts whatever the surface had in flight.
async function refresh(i, coarse = true) {
  const s = state.surfaces[i], l = live[i];
  const mine = ++l.generation;
  l.controller?.abort();
  l.want = null;
  l.controller = new AbortController();
  const { signal } = l.controller;
  writeUrl();
  syncControls();
  showError('');
  showMeasures($('measures'), []);
  if (!s.on) {
    view.hide(i);
    return;
  }
  view.style(i, s.color, s.opacity);
  if (i === 0) $('status').textContent = 'extracting…';
  const params = { level: s.level, tolerance: state.tolerance, normals: state.normals };
  const rough = Math.max(state.tolerance, range() / 50);
  try {
    if (coarse && rough > state.tolerance) await fetchAndShow(i, { ...params, tolerance: rough }, mine, signal, 'coarse');
    // The final mesh at the detail asked for (distance=), from the server's chain.
    if (mine === l.generation) await fetchAndShow(i, { ...params, distance: state.distance }, mine, signal, 'final');
  } catch (error) {
    if (mine === l.generation) reportError(error);
  }
}

const refreshAll = () => state.surfaces.forEach((_, i) => refresh(i));

// While the slider moves: ask for a preview at the latest level once the previous answer
// is in, and decode and draw that answer while the next one is on its way (still one
// request in flight). A full request (refresh) bumps the generation and aborts the preview
// in flight.
async function drag(i, level) {
  const l = live[i];
  l.want = level;
  $(`level${i ? '-2' : ''}-value`).textContent = formatNumber(level);
  if (l.inFlight) return;
  l.inFlight = true;
  const mine = l.generation;
  let showing = Promise.resolve();
  while (l.want !== null && mine === l.generation) {
    const params = { level: l.want, tolerance: previewTolerance(i), normals: 'none' };
    l.want = null;
    l.controller?.abort();
    l.controller = new AbortController();
    const started = performance.now();
    let mesh;
    try {
      mesh = await getMesh(state.volume, { ...params, format: format() }, l.controller.signal);
    } catch (error) {
      if (mine === l.generation) reportError(error);
      break;
    }
    steerPreview(i, params.tolerance, mesh.triangles);
    await showing; // previews are drawn in the order they were asked
    showing = display(i, mesh, params, mine, 'preview', started).catch(reportError);
    if (l.want === null) await showing; // nothing newer yet: draw, then look again
  }
  await showing;
  l.inFlight = false;
}

function release(i, level) {
  state.surfaces[i].level = level;
  live[i].inFlight = false;
  refresh(i, false);
}

async function measure() {
  const out = $('measures');
  const rows = [];
  showMeasures(out, [{ name: 'measuring…' }]);
  try {
    for (const [i, s] of state.surfaces.entries()) {
      if (!s.on) continue;
      // The measures do not depend on normals or format: the cheapest request that has them.
      const m = await getMeasures(state.volume, { level: s.level, tolerance: state.tolerance, normals: 'none',
        format: 'ply', cap: state.cap });
      rows.push({ name: `surface ${i + 1} at ${formatNumber(s.level)}`, ...m, cap: state.cap });
    }
    showMeasures(out, rows);
  } catch (error) {
    showMeasures(out, []);
    reportError(error);
  }
}

async function selectVolume(id, fromUrl) {
  try {
    info = await getJson(`v1/volumes/${encodeURIComponent(id)}`);
  } catch (error) {
    info = null;
    view.clear();
    showError(error instanceof ApiError ? error.message : `Could not load volume ${id}: ${error.message}`);
    return;
  }
  state.volume = id;
  for (const l of live) l.previewTolerance = null;
  bounds = volumeBounds(info);
  $('volume').value = id;
  const levels = info.suggested_levels.length ? info.suggested_levels : [(info.value_range[0] + info.value_range[1]) / 2];
  state.surfaces.forEach((s, i) => {
    if (!fromUrl || s.level === null) s.level = levels[Math.min(i, levels.length - 1)];
  });
  $('volume-info').textContent = `${info.name} · ${info.dims.join('×')} ${info.value_type} · ` +
    `${info.spacing.map((s) => formatNumber(s, 3)).join('×')} mm`;
  drawHistogram($('histogram'), info.histogram, info.suggested_levels, (level) => { state.surfaces[0].level = level; refresh(0); });
  applyClip();
  await Promise.all(state.surfaces.map((_, i) => refresh(i)));
}

function wireSurface(i) {
  const id = i ? 'level-2' : 'level';
  $(id).addEventListener('input', (e) => drag(i, levelFromSlider(+e.target.value)));
  $(id).addEventListener('change', (e) => release(i, levelFromSlider(+e.target.value)));
  $(`color-${i + 1}`).addEventListener('input', (e) => {
    state.surfaces[i].color = e.target.value;
    view.style(i, state.surfaces[i].color, state.surfaces[i].opacity);
    writeUrl();
  });
  $(`opacity-${i + 1}`).addEventListener('input', (e) => {
    state.surfaces[i].opacity = Number(e.target.value) / 100;
    view.style(i, state.surfaces[i].color, state.surfaces[i].opacity);
    writeUrl();
  });
}

function wire() {
  $('volume').addEventListener('change', (e) => {
    state.surfaces.forEach((s) => { s.level = null; });
    selectVolume(e.target.value, false);
  });
  wireSurface(0);
  wireSurface(1);
  $('surface-2').addEventListener('change', (e) => { state.surfaces[1].on = e.target.checked; refresh(1); });
  $('tolerance').addEventListener('input', (e) => { $('tolerance-value').textContent = formatNumber(toleranceFromSlider(+e.target.value), 3); });
  $('tolerance').addEventListener('change', (e) => { state.tolerance = Number(toleranceFromSlider(+e.target.value).toPrecision(3)); refreshAll(); });
  $('distance').addEventListener('input', (e) => { $('distance-value').textContent = distanceText(distanceFromSlider(+e.target.value)); });
  $('distance').addEventListener('change', (e) => { state.distance = distanceFromSlider(+e.target.value); refreshAll(); });
  $('normals').addEventListener('change', (e) => { state.normals = e.target.value; refreshAll(); });
  $('codec').addEventListener('change', (e) => { state.codec = e.target.value; refreshAll(); });
  const clipChanged = () => {
    state.clip = { on: $('clip').checked, axis: $('clip-axis').value, at: Number($('clip-at').value) / 1000,
      flip: $('clip-flip').checked };
    applyClip();
    writeUrl();
  };
  for (const id of ['clip', 'clip-axis', 'clip-flip']) $(id).addEventListener('change', clipChanged);
  $('clip-at').addEventListener('input', clipChanged);
  $('cap').addEventListener('change', (e) => { state.cap = e.target.checked; writeUrl(); showMeasures($('measures'), []); });
  $('measure').addEventListener('click', measure);
  $('wireframe').addEventListener('change', (e) => { view.wireframe = e.target.checked; });
  $('flip').addEventListener('change', (e) => { view.flipped = e.target.checked; applyClip(); });
  $('light').addEventListener('change', (e) => {
    document.body.className = e.target.checked ? 'light' : 'dark';
    view.background = e.target.checked ? 0xf4f5f7 : 0x111418;
  });
}

async function start() {
  wire();
  view.background = 0x111418;
  const q = new URLSearchParams(location.search);
  readUrl(q);
  let list;
  try {
    list = (await getJson('v1/volumes')).volumes;
  } catch (error) {
    showError(error instanceof ApiError ? error.message : `The server did not answer: ${error.message}`);
    return;
  }
  $('volume').replaceChildren(...list.map((v) => new Option(`${v.name} (${v.id})`, v.id)));
  const wanted = q.get('volume') ?? list[0]?.id;
  if (wanted) await selectVolume(wanted, q.has('volume'));
}

start();
