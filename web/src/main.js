// main.js: the viewer's state and its life: the URL holds the view
// (?volume=&level=&tolerance=&normals=), every change fetches a coarse mesh first and then
// the one asked for, and a superseded request is aborted so that a stale mesh never
// replaces a newer one.
import { ApiError, getJson, getMesh, meshUrl } from './api.js';
import { drawHistogram, formatNumber, showError, showScale, showStats } from './ui.js';
import { View } from './view.js';

const $ = (id) => document.getElementById(id);
const view = new View($('view'));
view.onScale = showScale;

const state = { volume: null, level: null, tolerance: 0, normals: 'tricubic' };
let info = null;        // the current volume's document
let generation = 0;     // bumps on every change; answers of older generations are dropped
let controller = null;  // aborts the requests of the previous generation
let framedVolume = null;

// ---- tolerance slider: log scale over the value range, position 0 is exactly 0
const range = () => (info ? info.value_range[1] - info.value_range[0] : 1) || 1;
const toleranceFromSlider = (s) => (s <= 0 ? 0 : range() * 10 ** ((s - 100) / 25));
const sliderFromTolerance = (t) => (t <= 0 ? 0 : Math.max(1, Math.min(100, 100 + 25 * Math.log10(t / range()))));
const levelFromSlider = (s) => info.value_range[0] + (s / 1000) * range();
const sliderFromLevel = (l) => Math.round(((l - info.value_range[0]) / range()) * 1000);

function writeUrl() {
  const q = new URLSearchParams({ volume: state.volume, level: String(state.level),
    tolerance: String(state.tolerance), normals: state.normals });
  history.replaceState(null, '', `?${q}`);
}

function syncControls() {
  $('level').value = sliderFromLevel(state.level);
  $('level-value').textContent = formatNumber(state.level);
  $('tolerance').value = sliderFromTolerance(state.tolerance);
  $('tolerance-value').textContent = state.tolerance === 0 ? '0 (exact)' : formatNumber(state.tolerance, 3);
  $('normals').value = state.normals;
  const params = { level: state.level, tolerance: state.tolerance, normals: state.normals };
  $('download-glb').href = meshUrl(state.volume, { ...params, format: 'glb' });
  $('download-glb').download = `${state.volume}-${state.level}.glb`;
  $('download-ply').href = meshUrl(state.volume, { ...params, format: 'ply' });
  $('download-ply').download = `${state.volume}-${state.level}.ply`;
}

// Fetches and shows one mesh of this generation; false when it was superseded.
async function fetchAndShow(params, mine, signal) {
  const mesh = await getMesh(state.volume, params, signal);
  if (mine !== generation) return false;
  const start = performance.now();
  const geometry = await view.decode(mesh.bytes);
  const decodeMs = performance.now() - start;
  if (mine !== generation) {
    geometry.dispose();
    return false;
  }
  const frame = framedVolume !== state.volume;
  view.show(geometry, frame);
  if (frame && mesh.triangles > 0) framedVolume = state.volume;
  showStats($('stats'), mesh, decodeMs);
  $('status').textContent = mesh.triangles === 0 ? 'no surface at this level' : '';
  return true;
}

// A change: coarse first (a fiftieth of the value range as tolerance), then the real one.
async function refresh() {
  const mine = ++generation;
  controller?.abort();
  controller = new AbortController();
  const { signal } = controller;
  writeUrl();
  syncControls();
  showError('');
  $('status').textContent = 'extracting…';
  const params = { level: state.level, tolerance: state.tolerance, normals: state.normals };
  const coarse = Math.max(state.tolerance, range() / 50);
  try {
    if (coarse > state.tolerance) await fetchAndShow({ ...params, tolerance: coarse }, mine, signal);
    if (mine === generation) await fetchAndShow(params, mine, signal);
  } catch (error) {
    if (error.name === 'AbortError' || mine !== generation) return;
    showError(error instanceof ApiError ? error.message : `Could not show the mesh: ${error.message}`);
    $('status').textContent = '';
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
  $('volume').value = id;
  const levels = info.suggested_levels.length ? info.suggested_levels : [(info.value_range[0] + info.value_range[1]) / 2];
  if (!fromUrl || state.level === null) state.level = levels[0];
  $('volume-info').textContent = `${info.name} · ${info.dims.join('×')} ${info.value_type} · ` +
    `${info.spacing.map((s) => formatNumber(s, 3)).join('×')} mm`;
  drawHistogram($('histogram'), info.histogram, info.suggested_levels, (level) => { state.level = level; refresh(); });
  await refresh();
}

function wire() {
  $('volume').addEventListener('change', (e) => { state.level = null; selectVolume(e.target.value, false); });
  $('level').addEventListener('input', (e) => { $('level-value').textContent = formatNumber(levelFromSlider(+e.target.value)); });
  $('level').addEventListener('change', (e) => { state.level = Number(levelFromSlider(+e.target.value).toPrecision(6)); refresh(); });
  $('tolerance').addEventListener('input', (e) => { $('tolerance-value').textContent = formatNumber(toleranceFromSlider(+e.target.value), 3); });
  $('tolerance').addEventListener('change', (e) => { state.tolerance = Number(toleranceFromSlider(+e.target.value).toPrecision(3)); refresh(); });
  $('normals').addEventListener('change', (e) => { state.normals = e.target.value; refresh(); });
  $('wireframe').addEventListener('change', (e) => { view.wireframe = e.target.checked; });
  $('flip').addEventListener('change', (e) => { view.flipped = e.target.checked; });
  $('light').addEventListener('change', (e) => {
    document.body.className = e.target.checked ? 'light' : 'dark';
    view.background = e.target.checked ? 0xf4f5f7 : 0x111418;
  });
}

async function start() {
  wire();
  view.background = 0x111418;
  const q = new URLSearchParams(location.search);
  if (q.has('level') && Number.isFinite(Number(q.get('level')))) state.level = Number(q.get('level'));
  if (q.has('tolerance') && Number(q.get('tolerance')) >= 0) state.tolerance = Number(q.get('tolerance'));
  if (q.has('normals')) state.normals = q.get('normals');
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
