// panel-quality.js: the panel's quality section: the tolerance (value units, log scale,
// 0 is the exact surface), Detail (the final mesh from the server's simplification chain:
// only its distinct levels, and none whose measured distance at the 99th percentile passes
// DETAIL_CAP_VOXELS voxels), normals and codec.
//
// Detail's positions come from GET /v1/volumes/{id}/chain (the chain's levels, finest
// first, with their triangles and p99 distances) when the server has that route and the
// chain is built; asking a level's own p99 distance gives that level. Before the chain is
// built, or from a server without the route, the positions are fixed distances of 0.5 to
// DETAIL_CAP_VOXELS voxels (the first one asked builds the chain).
import { getChain } from './api.js';
import { formatNumber } from './ui.js';

export const DETAIL_CAP_VOXELS = 3;
const FALLBACK_VOXELS = [0.5, 1, 2, 3];

const range = (info) => (info ? info.value_range[1] - info.value_range[0] : 1) || 1;
const toleranceFromSlider = (info, s) => (s <= 0 ? 0 : range(info) * 10 ** ((s - 100) / 25));
const sliderFromTolerance = (info, t) => (t <= 0 ? 0 : Math.max(1, Math.min(100, 100 + 25 * Math.log10(t / range(info)))));
export const voxel = (info) => (info ? Math.min(...info.spacing) : 1);

export function toleranceText(info, t) {
  if (t <= 0) return '0: exact';
  return `±${formatNumber(t, 3)} (${formatNumber((100 * t) / range(info), 2)}% of the value range)`;
}

export function mountQuality(ctx) {
  const { $, state } = ctx;
  ctx.detail = { positions: [{ distance: 0 }], chain: null, note: '', poll: null };
  $('tolerance').addEventListener('input', (e) => { $('tolerance-value').textContent = toleranceText(ctx.info(), toleranceFromSlider(ctx.info(), +e.target.value)); });
  $('tolerance').addEventListener('change', (e) => {
    state.tolerance = Number(toleranceFromSlider(ctx.info(), +e.target.value).toPrecision(3));
    ctx.refreshAll();
    updateDetail(ctx);
  });
  $('distance').addEventListener('input', (e) => { $('distance-value').textContent = detailText(ctx, ctx.detail.positions[+e.target.value]); });
  $('distance').addEventListener('change', (e) => {
    state.distance = ctx.detail.positions[+e.target.value]?.distance ?? 0;
    ctx.refreshAll();
    setTimeout(() => updateDetail(ctx), 1500); // a first request builds the chain
  });
  $('normals').addEventListener('change', (e) => { state.normals = e.target.value; ctx.refreshAll(); ctx.reloadSegments(); });
  $('codec').addEventListener('change', (e) => { state.codec = e.target.value; ctx.refreshAll(); ctx.reloadSegments(); });
}

function detailText(ctx, p) {
  const info = ctx.info(), v = voxel(info);
  if (!p || p.distance <= 0) return 'exact (the surface itself)';
  const d = `${formatNumber(p.distance, 3)} mm = ${formatNumber(p.distance / v, 2)} voxel`;
  return p.triangles ? `${formatNumber(p.triangles, 3)} triangles, p99 ${d}` : `within ${d}`;
}

// The positions for the chain of surface 1's level and the tolerance (or the fixed ones).
export async function updateDetail(ctx, fromLink = false) {
  const { state } = ctx, info = ctx.info();
  if (!info || state.surfaces[0].level === null) return;
  clearTimeout(ctx.detail.poll);
  const v = voxel(info), cap = DETAIL_CAP_VOXELS * v;
  let chain = null;
  try {
    chain = await getChain(state.volume, { level: state.surfaces[0].level, tolerance: state.tolerance, cap: false });
  } catch { chain = null; }
  let positions = [{ distance: 0 }], note = '';
  if (chain?.state === 'ready' && chain.levels?.length) {
    // Level k is reachable when no coarser level is as close: asking its own p99 gives it.
    const levels = chain.levels.map((l, k) => ({ ...l, k })).filter((l) => l.k > 0 && l.distance_p99_mm <= cap);
    for (const l of levels) {
      if (chain.levels.some((o, j) => j > l.k && o.distance_p99_mm <= l.distance_p99_mm)) continue;
      positions.push({ distance: Number((Math.ceil(l.distance_p99_mm * 1e4) / 1e4).toPrecision(4)), triangles: l.triangles, k: l.k });
    }
  } else {
    positions = positions.concat(FALLBACK_VOXELS.filter((x) => x <= DETAIL_CAP_VOXELS)
      .map((x) => ({ distance: Number((x * v).toPrecision(3)) })));
    if (chain?.state === 'building') {
      note = 'measuring the chain…';
      ctx.detail.poll = setTimeout(() => updateDetail(ctx), 2000);
    } else if (chain?.state === 'none') {
      note = 'the first Detail builds the chain';
    }
  }
  ctx.detail = { ...ctx.detail, positions, chain, note };
  // A distance from a link beyond the cap asks for no more than the cap (a 422's offer,
  // taken by a click, may ask for more).
  if (fromLink && state.distance > cap * 1.0001) state.distance = positions.at(-1).distance;
  syncQuality(ctx);
}

export function syncQuality(ctx) {
  const { $, state } = ctx, info = ctx.info();
  $('tolerance').value = sliderFromTolerance(info, state.tolerance);
  $('tolerance-value').textContent = toleranceText(info, state.tolerance);
  const { positions, note } = ctx.detail;
  $('distance').max = String(positions.length - 1);
  let at = positions.findIndex((p) => Math.abs(p.distance - state.distance) <= 1e-6 * Math.max(1, p.distance));
  if (at < 0) at = positions.reduce((best, p, k) => (Math.abs(p.distance - state.distance) < Math.abs(positions[best].distance - state.distance) ? k : best), 0);
  $('distance').value = String(at);
  const shown = state.distance > 0 && Math.abs(positions[at].distance - state.distance) > 1e-6 ? { distance: state.distance } : positions[at];
  const text = detailText(ctx, shown) + (note ? ` · ${note}` : '');
  $('distance-value').textContent = text;
  $('distance-value').title = text;
  $('normals').value = state.normals;
  $('codec').value = state.codec;
}
