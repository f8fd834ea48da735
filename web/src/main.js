// main.js: the viewer's life: the state (url.js holds it in the link), the volume opened,
// the panel's sections (panel-*.js, each with its own module), the requests (loader.js),
// the view (view.js, camera.js, marker.js), the status line (status.js), the keys
// (keys.js), and a segmentation's segments over the volume (panel-segments.js). Sections
// talk to each other only through the context made here.
import { ApiError, getJson } from './api.js';
import { Loader } from './loader.js';
import { mountKeys } from './keys.js';
import { mountClip, applyClip, syncClip } from './panel-clip.js';
import { mountExport, syncExport } from './panel-export.js';
import { mountQuality, syncQuality, updateDetail } from './panel-quality.js';
import { mountSegments, openSegments, reloadSegments, sameGrid, syncSegments } from './panel-segments.js';
import { drawLevels, mountSurfaces, syncSurfaces } from './panel-surfaces.js';
import { applyLook, mountView, syncView } from './panel-view.js';
import { listVolumes, mountVolume, showVolume } from './panel-volume.js';
import { showStatus, showSurfaceStats } from './status.js';
import { showError, showMeasures, showScale } from './ui.js';
import { defaultState, readUrl, writeUrl } from './url.js';
import { View } from './view.js';

const $ = (id) => document.getElementById(id);
const state = defaultState();
const view = new View($('view'));
view.onScale = showScale;
let info = null; // the current volume's document

const ctx = {
  $, state, view,
  info: () => info,
  volumes: [], // the collection's list (GET /v1/volumes)
  // Whether the volume's own surfaces are drawn: always, but under a segmentation only when
  // "CT surface" is ticked (else the segments alone).
  shows: () => !state.seg.id || state.seg.ct,
  // The volume's LPS box as its file places it: [[x0, y0, z0], [x1, y1, z1]].
  box() {
    const m = info.index_to_world;
    const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (let c = 0; c < 8; c++) {
      const ijk = [0, 1, 2].map((a) => ((c >> a) & 1) * (info.dims[a] - 1));
      for (let r = 0; r < 3; r++) {
        const x = m[4 * r] * ijk[0] + m[4 * r + 1] * ijk[1] + m[4 * r + 2] * ijk[2] + m[4 * r + 3];
        lo[r] = Math.min(lo[r], x);
        hi[r] = Math.max(hi[r], x);
      }
    }
    return [lo, hi];
  },
  suggested: () => (info?.suggested_levels?.length ? info.suggested_levels : info ? [(info.value_range[0] + info.value_range[1]) / 2] : []),
  writeUrl() { writeUrl(state); },
  sync() {
    syncSurfaces(ctx);
    syncView(ctx);
    syncClip(ctx);
    syncQuality(ctx);
    syncExport(ctx);
    syncSegments(ctx);
  },
  refresh(i, preview = true) {
    showError('');
    showMeasures($('measures'), []);
    ctx.writeUrl();
    ctx.sync();
    return ctx.loader.refresh(i, preview);
  },
  refreshAll() { return Promise.all(state.surfaces.map((_, i) => ctx.refresh(i))); },
  // The normals or the codec changed: the segments' meshes too.
  reloadSegments() { reloadSegments(ctx); },
  pickLevel(i, level) {
    state.surfaces[i].level = level;
    ctx.refresh(i);
    if (i === 0) updateDetail(ctx);
  },
  nextLevel(step) {
    const levels = ctx.suggested();
    if (!levels.length) return;
    const at = levels.findIndex((l) => l === state.surfaces[0].level);
    ctx.pickLevel(0, levels[(at + step + levels.length) % levels.length]);
  },
  preset(name) {
    view.camera.view(name, view.drawnBox() ?? view.bounds);
    ctx.cameraMoved();
  },
  resetView() { ctx.preset('anterior'); },
  cameraMoved() {
    state.camera = view.camera.toText();
    ctx.writeUrl();
  },
  // A 422's offer taken: the tolerance or detail that fits, for every surface.
  applyFit(o) {
    if (o.distance !== undefined) state.distance = o.distance;
    else state.tolerance = o.tolerance;
    ctx.refreshAll();
    updateDetail(ctx);
  },
  error(e) {
    if (e.name === 'AbortError') return;
    showError(e instanceof ApiError ? e.message : `Something failed: ${e.message}`);
  },
};

ctx.loader = new Loader({
  state, view, info: () => info, shows: ctx.shows,
  onShown(i, record, mesh) {
    // The first surface drawn of a volume opened without a camera in its link frames the
    // view (anterior, superior up) and puts the camera in the link.
    if (!state.camera && record.triangles > 0) ctx.resetView();
    showSurfaceStats(ctx, i, mesh, record.decodeMs);
    syncSurfaces(ctx);
    showStatus(ctx);
  },
  onChange(progressOnly) {
    if (!progressOnly) syncSurfaces(ctx);
    showStatus(ctx);
  },
});
// What the page has drawn, for the browser tests and the benchmark.
window.isoViewer = { state, shown: ctx.loader.shown, view, ctx, refresh: (i, preview) => ctx.refresh(i, preview) };

// A second passes in the status while something is pending or a retry counts down.
setInterval(() => { if (ctx.loader.live.some((l) => l.phase || l.retry)) showStatus(ctx); }, 250);

// The segmentation to show over the volume `doc`: the volume itself, or, for an image, one
// on its grid (the link's, else the collection's first).
function segmentationOf(doc, fromLink) {
  if (doc.segments) return doc.id;
  const on = ctx.volumes.filter((v) => v.segments && sameGrid(v, doc));
  return on.find((v) => fromLink && v.id === state.seg.id)?.id ?? on[0]?.id ?? null;
}

async function selectVolume(id, fromLink) {
  let doc, seg;
  try {
    doc = await getJson(`v1/volumes/${encodeURIComponent(id)}`);
    seg = segmentationOf(doc, fromLink);
    // A segmentation opened shows over the CT on its grid (the series its SEG references,
    // the image its label map was made from) when the collection has one: that volume is
    // opened, with the segmentation over it.
    const ct = doc.segments ? ctx.volumes.find((v) => !v.segments && sameGrid(v, doc)) : null;
    if (ct) doc = await getJson(`v1/volumes/${encodeURIComponent(ct.id)}`);
  } catch (error) {
    info = null;
    view.clear();
    showError(error instanceof ApiError ? error.message : `Could not load volume ${id}: ${error.message}`);
    return;
  }
  info = doc;
  if (!fromLink) {
    state.surfaces.forEach((s) => { s.level = null; });
    state.camera = null;
    state.axes = 'LPS';
    state.seg = { id: null, visible: null, opacity: {}, ct: null };
  }
  state.volume = doc.id;
  state.seg.id = seg; // before the surfaces' requests: they are drawn with "CT surface" only
  // An image opened shows its own surface under its segmentation; a segmentation opened
  // shows its segments alone (its CT's surface one tick away).
  if (state.seg.ct === null) state.seg.ct = doc.id === id && !doc.segments;
  ctx.loader.reset();
  view.clear();
  if (info.orientation !== 'none') state.axes = 'LPS';
  view.setVolume(ctx.box(), state.axes, info.orientation !== 'none');
  if (!state.camera || !view.camera.fromText(state.camera)) {
    state.camera = null;
    view.camera.view('anterior', view.bounds); // until the first surface frames it
  }
  const levels = ctx.suggested();
  state.surfaces.forEach((s, i) => { if (s.level === null && (i === 0 || s.on)) s.level = levels[Math.min(i, levels.length - 1)]; });
  showVolume(ctx);
  drawLevels(ctx);
  applyClip(ctx);
  ctx.sync();
  // Detail's positions need the chain's figures: waited for only when the link asks for a
  // Detail (capped by them), else fetched beside the first meshes.
  const detail = updateDetail(ctx, true);
  if (state.distance > 0) await detail;
  await Promise.all([ctx.refreshAll(), openSegments(ctx, seg)]);
}
ctx.selectVolume = selectVolume;

async function start() {
  for (const mount of [mountVolume, mountSurfaces, mountSegments, mountView, mountClip, mountQuality, mountExport, mountKeys]) mount(ctx);
  view.camera.onEnd = () => { view.camera.settle(); ctx.cameraMoved(); };
  const q = new URLSearchParams(location.search);
  readUrl(q, state);
  applyLook(ctx);
  let list;
  for (let attempt = 1; ; attempt++) {
    try {
      list = (await getJson('v1/volumes')).volumes;
      showError('');
      break;
    } catch (error) {
      // The server gone or still preloading: ask again, 1, 2, 4 ... 30 s apart.
      const wait = Math.min(30, 2 ** (attempt - 1));
      showError(`${error.message}: asking again in ${wait} s`);
      await new Promise((r) => setTimeout(r, wait * 1000));
    }
  }
  ctx.volumes = list;
  listVolumes(ctx, list);
  const wanted = q.get('volume') ?? list[0]?.id;
  if (wanted) await selectVolume(wanted, q.has('volume'));
}

start();
