// url.js: the view as a link. Everything that decides the picture is in the query string,
// so that reloading a link draws the same pixels: the volume, per surface its level,
// colour and opacity, the tolerance, detail, normals and codec, the clipping plane, the
// camera (eye and target in LPS mm), the assumed axes of a volume without orientation,
// wireframe and background, "close at the border" for measures and downloads, and a
// segmentation's view: which one, which segments are shown (all when left out; ranges such
// as 1-40,42), their opacities and whether the CT's surface is drawn under them. Values at
// their defaults are left out, so short links stay short.

export const DEFAULT_CODEC = 'meshopt';
export const DEFAULT_COLORS = ['#e8dccb', '#6fa8dc'];
export const AXES_CODES = ['LPS', 'LPI', 'LAS', 'LAI', 'RPS', 'RPI', 'RAS', 'RAI'];

export function defaultState() {
  return {
    volume: null, tolerance: 0, distance: 0, normals: 'tricubic', codec: DEFAULT_CODEC, cap: true,
    surfaces: [
      { level: null, color: DEFAULT_COLORS[0], opacity: 1, on: true },
      { level: null, color: DEFAULT_COLORS[1], opacity: 1, on: false },
    ],
    clip: { on: false, axis: 'x', at: 0.5, flip: false },
    camera: null,       // "ex,ey,ez,tx,ty,tz" or null: frame the first surface drawn
    axes: 'LPS',        // where an unoriented volume's i, j, k are taken to point
    wireframe: false,
    light: false,
    // A segmentation over the volume (its id: the volume itself, or one on its grid), the
    // segments shown (null: all), opacities other than 1 by segment number, and whether
    // the volume's own surfaces (the CT's) are drawn too, else the segments alone (null:
    // as the volume opened decides, see main.js).
    seg: { id: null, visible: null, opacity: {}, ct: null },
  };
}

// "1-3,7" <-> [1, 2, 3, 7]: segment numbers, ascending runs as ranges.
export function numbersText(numbers) {
  const sorted = [...numbers].sort((a, b) => a - b), runs = [];
  for (const n of sorted) {
    const run = runs.at(-1);
    if (run && n === run[1] + 1) run[1] = n;
    else runs.push([n, n]);
  }
  return runs.map(([a, b]) => (a === b ? `${a}` : `${a}-${b}`)).join(',');
}

function parseNumbers(text) {
  const out = new Set();
  for (const part of text.split(',')) {
    const m = /^(\d{1,5})(?:-(\d{1,5}))?$/.exec(part);
    if (!m) return null;
    const [a, b] = [Number(m[1]), Number(m[2] ?? m[1])];
    if (b < a || b - a > 65535) return null;
    for (let n = a; n <= b; n++) out.add(n);
  }
  return out;
}

const finite = (v) => v !== null && v !== '' && Number.isFinite(Number(v));

// Reads a link's query into state (unknown or malformed values keep the defaults).
export function readUrl(q, state) {
  state.surfaces.forEach((s, i) => {
    const n = i ? String(i + 1) : '';
    if (finite(q.get(`level${n}`))) { s.level = Number(q.get(`level${n}`)); s.on = true; }
    if (/^[0-9a-f]{6}$/i.test(q.get(`color${n}`) ?? '')) s.color = `#${q.get(`color${n}`).toLowerCase()}`;
    if (finite(q.get(`opacity${n}`))) s.opacity = Math.min(1, Math.max(0.05, Number(q.get(`opacity${n}`))));
  });
  if (finite(q.get('tolerance')) && Number(q.get('tolerance')) >= 0) state.tolerance = Number(q.get('tolerance'));
  if (finite(q.get('distance')) && Number(q.get('distance')) >= 0) state.distance = Number(q.get('distance'));
  if (['none', 'trilinear', 'triquadratic', 'tricubic'].includes(q.get('normals'))) state.normals = q.get('normals');
  if (['draco', 'meshopt'].includes(q.get('codec'))) state.codec = q.get('codec');
  if (q.get('cap') === 'false') state.cap = false;
  const clip = /^([xyz]):([0-9.]+)(:flip)?$/.exec(q.get('clip') ?? '');
  if (clip && Number(clip[2]) <= 1) state.clip = { on: true, axis: clip[1], at: Number(clip[2]), flip: !!clip[3] };
  if (q.get('camera')) state.camera = q.get('camera');
  if (AXES_CODES.includes((q.get('axes') ?? '').toUpperCase())) state.axes = q.get('axes').toUpperCase();
  if (q.get('wireframe') === 'true') state.wireframe = true;
  if (q.get('background') === 'light') state.light = true;
  if (/^[A-Za-z0-9._-]{1,64}$/.test(q.get('segmentation') ?? '')) state.seg.id = q.get('segmentation');
  const shown = q.get('segments');
  if (shown === 'none') state.seg.visible = new Set();
  else if (shown) state.seg.visible = parseNumbers(shown);
  for (const part of (q.get('segopacity') ?? '').split(',')) {
    const m = /^(\d{1,5}):([0-9.]+)$/.exec(part);
    if (m && finite(m[2])) state.seg.opacity[m[1]] = Math.min(1, Math.max(0.05, Number(m[2])));
  }
  if (['true', 'false'].includes(q.get('ct'))) state.seg.ct = q.get('ct') === 'true';
}

// The link of state (the query string, with its "?").
export function urlOf(state) {
  const q = new URLSearchParams({ volume: state.volume ?? '', level: String(state.surfaces[0].level) });
  if (state.tolerance !== 0) q.set('tolerance', String(state.tolerance));
  if (state.distance > 0) q.set('distance', String(state.distance));
  if (state.normals !== 'tricubic') q.set('normals', state.normals);
  if (state.codec !== DEFAULT_CODEC) q.set('codec', state.codec);
  state.surfaces.forEach((s, i) => {
    const n = i ? String(i + 1) : '';
    if (i && !s.on) return;
    if (i) q.set(`level${n}`, String(s.level));
    if (s.color !== DEFAULT_COLORS[i]) q.set(`color${n}`, s.color.slice(1));
    if (s.opacity !== 1) q.set(`opacity${n}`, String(s.opacity));
  });
  if (state.clip.on) q.set('clip', `${state.clip.axis}:${state.clip.at}${state.clip.flip ? ':flip' : ''}`);
  if (!state.cap) q.set('cap', 'false');
  if (state.axes !== 'LPS') q.set('axes', state.axes);
  if (state.wireframe) q.set('wireframe', 'true');
  if (state.light) q.set('background', 'light');
  if (state.seg.id) {
    q.set('segmentation', state.seg.id);
    if (state.seg.visible) q.set('segments', state.seg.visible.size ? numbersText(state.seg.visible) : 'none');
    const opacities = Object.entries(state.seg.opacity).filter(([, o]) => o !== 1);
    if (opacities.length) q.set('segopacity', opacities.map(([n, o]) => `${n}:${o}`).join(','));
    q.set('ct', String(!!state.seg.ct));
  }
  if (state.camera) q.set('camera', state.camera);
  return `?${q}`.replace(/%2C/g, ',').replace(/%3A/g, ':');
}

export function writeUrl(state) {
  const url = urlOf(state);
  if (url !== location.search) history.replaceState(null, '', url);
}
