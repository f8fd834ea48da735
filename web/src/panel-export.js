// panel-export.js: the panel's measure and download section: each surface's area and
// enclosed volume on demand, and its downloads as glb (Draco), glb without extensions (for
// tools that lack Draco), PLY and STL, at the level, tolerance and detail shown, closed at
// the border when that box is ticked. File names carry the exact level:
// VOLUME_level-1976.19140625_tol5_closed.stl.
import { getMeasures, meshUrl } from './api.js';
import { formatNumber, showMeasures } from './ui.js';

const FORMATS = [['glb', 'glb', 'glTF binary, Draco compressed (three.js, Blender)'],
  ['glb-plain', 'glb', 'glTF binary without extensions, for tools that lack Draco'],
  ['ply', 'ply', 'PLY, lossless (MeshLab, 3D Slicer)'], ['stl', 'stl', 'STL, for 3D printing']];

export function mountExport(ctx) {
  const { $, state } = ctx;
  $('measure').addEventListener('click', () => measure(ctx));
  $('cap').addEventListener('change', (e) => {
    state.cap = e.target.checked;
    ctx.writeUrl();
    showMeasures($('measures'), []);
    syncExport(ctx);
  });
}

// The file name of a surface's download: the volume, the exact level, what else shaped it.
export function fileName(state, s, extension, plain) {
  let name = `${state.volume}_level${s.level}`;
  if (state.tolerance > 0) name += `_tol${state.tolerance}`;
  if (state.distance > 0) name += `_detail${state.distance}mm`;
  if (state.cap) name += '_closed';
  if (plain) name += '_plain';
  return `${name}.${extension}`.replace(/[^A-Za-z0-9._+-]/g, '_');
}

export function syncExport(ctx) {
  const { $, state } = ctx;
  $('cap').checked = state.cap;
  const rows = state.surfaces.map((s, i) => {
    if (!s.on || s.level === null || !state.volume) return null;
    const row = document.createElement('div');
    const label = document.createElement('span');
    label.textContent = state.surfaces[1].on ? `surface ${i + 1}:` : 'download:';
    row.append(label);
    for (const [format, extension, title] of FORMATS) {
      const a = document.createElement('a');
      a.href = meshUrl(state.volume, { level: s.level, tolerance: state.tolerance, normals: state.normals,
        distance: state.distance, format, cap: state.cap });
      a.download = fileName(state, s, extension, format === 'glb-plain');
      a.textContent = format === 'glb-plain' ? 'glb (plain)' : format.toUpperCase() === 'GLB' ? 'glb' : format;
      a.title = title;
      a.id = `download-${format}${i ? '-2' : ''}`;
      row.append(a);
    }
    return row;
  }).filter(Boolean);
  $('downloads').replaceChildren(...rows);
}

async function measure(ctx) {
  const { $, state } = ctx;
  const out = $('measures');
  const rows = [];
  showMeasures(out, [{ name: 'measuring…' }]);
  try {
    for (const [i, s] of state.surfaces.entries()) {
      if (!s.on) continue;
      // The measures do not depend on normals or format: the cheapest request that has them.
      const m = await getMeasures(state.volume, { level: s.level, tolerance: state.tolerance, normals: 'none',
        format: 'ply', cap: state.cap, distance: state.distance });
      rows.push({ name: `surface ${i + 1} at ${formatNumber(s.level)}`, ...m, cap: state.cap });
    }
    showMeasures(out, rows);
  } catch (error) {
    showMeasures(out, []);
    ctx.error(error);
  }
}

export { measure };
