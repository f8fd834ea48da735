// panel-segments.js: the panel's segments section, for a segmentation (a label map, a
// .seg.nrrd or a DICOM SEG) opened, or one on the grid of the volume opened (the CT its
// SEG references): every segment with its colour swatch, a visibility box, an opacity
// slider and its volume in mL (GET .../segments), "all" and "none", and "CT surface": the
// volume's own surfaces under the segments, or the segments alone. The list scrolls, so a
// hundred segments fit the panel. What is shown is in the link (url.js).
//
// Meshes: when the view opens with at least half of the segments shown, one request for
// them all (GET .../segments/mesh: one glb, a node per segment): one round trip, and the
// server extracts the segments across its threads; the hidden ones come along, so ticking
// one later only shows a mesh already decoded. Otherwise, for every segment ticked later
// that is not loaded yet, and when the scene is over the server's triangle limit, each
// segment's own mesh (GET .../segments/{n}/mesh), a few in flight at a time: a toggle never downloads again a segment already here (hiding keeps
// the mesh; nothing is dropped until the volume, the normals or the codec change).
import { getJson, getMeshAt, segmentMeshUrl } from './api.js';
import { formatNumber } from './ui.js';

const IN_FLIGHT = 4; // one-segment requests at once (the browser's six connections, less the surfaces')

// The two volumes lie on one grid: the same dims and index-to-world (within 1e-3 mm).
export function sameGrid(a, b) {
  if (!a?.dims || !b?.dims || !a.index_to_world || !b.index_to_world) return false;
  return a.dims.every((d, k) => d === b.dims[k]) &&
    a.index_to_world.every((x, k) => Math.abs(x - b.index_to_world[k]) <= 1e-3 * (1 + Math.abs(x)));
}

export function mountSegments(ctx) {
  const { $, state } = ctx;
  ctx.segs = { id: null, list: [], loaded: new Set(), inFlight: new Set(), generation: 0, controller: null,
    failure: null, requests: [], pending() { return this.inFlight.size > 0; } };
  $('seg-all').addEventListener('click', () => setVisible(ctx, null));
  $('seg-none').addEventListener('click', () => setVisible(ctx, new Set()));
  $('seg-ct').addEventListener('change', (e) => {
    state.seg.ct = e.target.checked;
    ctx.refreshAll();
  });
}

// Shown: segment number n.
export const shown = (state, n) => !state.seg.visible || state.seg.visible.has(n);
const opacityOf = (state, n) => state.seg.opacity[n] ?? 1;

// Opens the segmentation `id` over the volume opened (null: none). The state's choices
// (from a link) are kept; the list, then the meshes, are fetched.
export async function openSegments(ctx, id) {
  const { $, state, view } = ctx, segs = ctx.segs;
  segs.generation++;
  segs.controller?.abort();
  segs.controller = new AbortController();
  Object.assign(segs, { id, list: [], loaded: new Set(), inFlight: new Set(), failure: null });
  view.clearSegments();
  state.seg.id = id;
  $('sec-segments').hidden = !id;
  $('segment-list').replaceChildren();
  if (!id) return;
  const mine = segs.generation;
  syncSegments(ctx);
  let doc;
  try {
    doc = await getJson(`v1/volumes/${encodeURIComponent(id)}/segments`, segs.controller.signal);
  } catch (error) {
    if (mine !== segs.generation || error.name === 'AbortError') return;
    segs.failure = `the segments could not be listed: ${error.message}`;
    syncSegments(ctx);
    return;
  }
  if (mine !== segs.generation) return;
  segs.list = doc.segments;
  segs.source = doc.source;
  $('segment-list').replaceChildren(...segs.list.map((s) => row(ctx, s)));
  normalise(state, segs);
  ctx.writeUrl();
  syncSegments(ctx);
  await ensure(ctx);
}

// The normals or the codec changed: every mesh again, the same way as on opening.
export function reloadSegments(ctx) {
  const segs = ctx.segs;
  if (!segs.id || !segs.list.length) return;
  segs.generation++;
  segs.controller?.abort();
  segs.controller = new AbortController();
  segs.loaded = new Set();
  segs.inFlight = new Set();
  ctx.view.clearSegments();
  ensure(ctx);
}

// "All shown" is kept as null, so the link leaves it out.
function normalise(state, segs) {
  const v = state.seg.visible;
  if (v && segs.list.length && segs.list.every((s) => v.has(s.number))) state.seg.visible = null;
}

function row(ctx, s) {
  const { state, view } = ctx, n = s.number;
  const div = document.createElement('div');
  div.className = 'segment';
  div.dataset.segment = String(n);
  const label = document.createElement('label');
  label.className = 'inline seg-name';
  label.title = [s.name, s.category, s.type].filter(Boolean).join(' · ');
  const box = document.createElement('input');
  box.type = 'checkbox';
  box.id = `seg-${n}-on`;
  const swatch = document.createElement('span');
  swatch.className = 'seg-swatch';
  swatch.style.background = s.color_hex;
  swatch.title = s.color_hex;
  const name = document.createElement('span');
  name.textContent = s.name;
  label.append(box, swatch, name);
  const opacity = document.createElement('input');
  opacity.type = 'range';
  opacity.min = '5';
  opacity.max = '100';
  opacity.step = '1';
  opacity.id = `seg-${n}-opacity`;
  opacity.setAttribute('aria-label', `${s.name} opacity (%)`);
  const value = document.createElement('output');
  value.id = `seg-${n}-opacity-value`;
  value.htmlFor = opacity.id;
  const ml = document.createElement('span');
  ml.className = 'seg-ml';
  ml.id = `seg-${n}-ml`;
  ml.textContent = `${formatNumber(s.volume_ml, 4)} mL`;
  ml.title = `${s.voxels.toLocaleString('en-US')} voxels`;
  box.addEventListener('change', () => {
    const visible = state.seg.visible ?? new Set(ctx.segs.list.map((x) => x.number));
    if (box.checked) visible.add(n); else visible.delete(n);
    setVisible(ctx, visible);
  });
  opacity.addEventListener('input', () => {
    state.seg.opacity[n] = Number(opacity.value) / 100;
    if (state.seg.opacity[n] === 1) delete state.seg.opacity[n];
    value.textContent = `${opacity.value}%`;
    view.styleSegment(n, s.color_hex, opacityOf(state, n), shown(state, n));
    ctx.writeUrl();
  });
  div.append(label, opacity, value, ml);
  return div;
}

// Shows the segments of `visible` (null: all): the meshes here at once, the missing fetched.
function setVisible(ctx, visible) {
  const { state, view } = ctx, segs = ctx.segs;
  state.seg.visible = visible;
  normalise(state, segs);
  for (const s of segs.list) view.styleSegment(s.number, s.color_hex, opacityOf(state, s.number), shown(state, s.number));
  ctx.writeUrl();
  syncSegments(ctx);
  ensure(ctx);
}

// Fetches the shown segments that are neither here nor on their way (see the top).
async function ensure(ctx) {
  const { state } = ctx, segs = ctx.segs, mine = segs.generation;
  const missing = () => segs.list.filter((s) => shown(state, s.number) && !segs.loaded.has(s.number) && !segs.inFlight.has(s.number));
  if (!missing().length) return;
  const codec = state.codec, normals = state.normals;
  const nothingYet = !segs.loaded.size && !segs.inFlight.size;
  segs.failure = null;
  try {
    if (nothingYet && missing().length >= 2 && missing().length >= segs.list.length / 2) {
      const format = codec === 'meshopt' ? 'glb-meshopt' : 'glb';
      try {
        await load(ctx, mine, segs.list, segmentMeshUrl(segs.id, null, { normals, format }), async (bytes) => {
          const nodes = await ctx.view.decodeScene(bytes);
          return new Map(nodes.map((node) => [node.number, node]));
        });
      } catch (error) {
        // All of them over the server's triangle limit (422): each one alone may fit.
        if (error.status !== 422 || mine !== segs.generation) throw error;
      }
    }
    if (missing().length && mine === segs.generation) {
      const format = codec === 'meshopt' ? 'glb-meshopt' : 'draco';
      const queue = missing();
      queue.forEach((s) => segs.inFlight.add(s.number));
      const worker = async () => {
        for (let s = queue.shift(); s && mine === segs.generation; s = queue.shift()) {
          segs.inFlight.delete(s.number); // load() takes it again
          await load(ctx, mine, [s], segmentMeshUrl(segs.id, s.number, { normals, format }),
            async (bytes) => new Map([[s.number, await ctx.view.decode(bytes, codec)]]));
        }
      };
      await Promise.all(Array.from({ length: Math.min(IN_FLIGHT, queue.length) }, worker));
    }
  } catch (error) {
    if (mine !== segs.generation || error.name === 'AbortError') return;
    segs.inFlight.clear();
    segs.failure = `segments not loaded: ${error.message}`;
    syncSegments(ctx);
    ctx.error(error);
  }
}

// One request for the segments of `which`, decoded by `decode` (bytes -> Map of number to
// { geometry, matrix }) and drawn, unless the segmentation was reopened meanwhile.
async function load(ctx, mine, which, url, decode) {
  const { state, view } = ctx, segs = ctx.segs;
  which.forEach((s) => segs.inFlight.add(s.number));
  syncSegments(ctx);
  const started = performance.now();
  try {
    const mesh = await getMeshAt(url, segs.controller.signal);
    if (mine !== segs.generation) return;
    const decoded = await decode(mesh.bytes);
    if (mine !== segs.generation) {
      for (const d of decoded.values()) d.geometry.dispose();
      return;
    }
    for (const s of which) {
      const d = decoded.get(s.number);
      if (!d) continue;
      view.showSegment(s.number, d, s.color_hex, opacityOf(state, s.number), shown(state, s.number));
      segs.loaded.add(s.number);
    }
    segs.requests.push({ url, segments: which.length, triangles: mesh.triangles, bytes: mesh.size, ms: performance.now() - started });
  } finally {
    if (mine === segs.generation) {
      which.forEach((s) => segs.inFlight.delete(s.number));
      syncSegments(ctx);
    }
  }
  // A view opened without a camera in its link is framed on the segments once they are all
  // here, when they are alone (else on the surface, as it comes: see main.js).
  if (mine === segs.generation && !state.camera && !ctx.shows() && !segs.inFlight.size && segs.loaded.size) ctx.resetView();
}

export function syncSegments(ctx) {
  const { $, state } = ctx, segs = ctx.segs;
  if (!segs?.id) return;
  const info = ctx.info();
  $('seg-ct').checked = state.seg.ct;
  // "CT surface" names the image's modality when it is not CT (an atlas over an MR).
  const modality = info?.modality && info.modality !== 'CT' ? info.modality : 'CT';
  $('seg-ct-label').textContent = info && info.id !== segs.id ? `${modality} surface (${info.name || info.id})` : 'the label map\'s surface (Level)';
  const count = segs.list.filter((s) => shown(state, s.number)).length;
  $('segments-count').textContent = segs.list.length ? `${count} of ${segs.list.length} shown` : '';
  for (const s of segs.list) {
    const box = $(`seg-${s.number}-on`);
    if (!box) continue;
    box.checked = shown(state, s.number);
    const o = Math.round(opacityOf(state, s.number) * 100);
    $(`seg-${s.number}-opacity`).value = String(o);
    $(`seg-${s.number}-opacity-value`).textContent = `${o}%`;
  }
  $('segments-status').textContent = segs.failure ? segs.failure
    : segs.inFlight.size ? `loading ${segs.inFlight.size} segment${segs.inFlight.size > 1 ? 's' : ''}…`
      : segs.id !== info?.id ? `${segs.id} · ${segs.source ?? ''}` : segs.source ?? '';
}
