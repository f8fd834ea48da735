// ui.js: the panel's pieces that draw: the histogram behind the level slider (a click on it
// picks the level there), suggested level chips, the stats table, the measures, the scale
// bar, the error line, and number formatting.

// Draws the histogram with the suggested levels marked; a click on it or on a chip calls
// onPick(level).
export function drawHistogram(canvas, histogram, levels, onPick) {
  const ctx = canvas.getContext('2d');
  const { width, height } = canvas;
  canvas.onclick = (e) => {
    const box = canvas.getBoundingClientRect();
    const t = Math.min(1, Math.max(0, (e.clientX - box.left) / box.width));
    onPick(Number((histogram.min + t * (histogram.max - histogram.min)).toPrecision(6)));
  };
  ctx.clearRect(0, 0, width, height);
  const counts = histogram.counts;
  const peak = Math.max(...counts.map((c) => Math.log1p(c)), 1);
  ctx.fillStyle = getComputedStyle(canvas).color || '#888';
  ctx.globalAlpha = 0.55;
  const w = width / counts.length;
  counts.forEach((c, i) => {
    const h = (Math.log1p(c) / peak) * (height - 4); // log counts: the air peak would flatten the rest
    ctx.fillRect(i * w, height - h, Math.max(w, 1), h);
  });
  ctx.globalAlpha = 1;
  ctx.fillStyle = '#e0a040';
  for (const level of levels) {
    const x = ((level - histogram.min) / (histogram.max - histogram.min || 1)) * width;
    ctx.fillRect(x - 1, 0, 2, height);
  }
  const chips = document.getElementById('suggested');
  chips.replaceChildren(...levels.map((level) => {
    const b = document.createElement('button');
    b.textContent = formatNumber(level);
    b.title = 'suggested level (N: the next one)';
    b.addEventListener('click', () => onPick(level));
    return b;
  }));
}

export function formatNumber(x, digits = 4) {
  if (x === null || x === undefined || Number.isNaN(x)) return '–';
  if (x !== 0 && (Math.abs(x) >= 1e6 || Math.abs(x) < 1e-3)) return x.toExponential(2);
  return Number(x.toPrecision(digits)).toLocaleString('en-US');
}

const integer = (x) => (x === null ? '–' : Math.round(x).toLocaleString('en-US'));

function fillTable(table, rows) {
  table.replaceChildren(...rows.map(([name, value, id]) => {
    const tr = document.createElement('tr');
    const a = document.createElement('td');
    const b = document.createElement('td');
    a.textContent = name;
    b.textContent = value;
    if (id) b.id = id;
    tr.append(a, b);
    return tr;
  }));
}

export function showStats(table, mesh, decodeMs, codec) {
  // A body from the browser's own cache never reached the server this time.
  const cache = mesh.browserCached ? 'browser cache' : mesh.cache ? `server ${mesh.cache}` : '–';
  fillTable(table, [
    ['triangles', integer(mesh.triangles), 'stat-triangles'],
    ['vertices', integer(mesh.vertices)],
    ['bytes over the wire', `${integer(mesh.size)} B`],
    ['server extract', `${formatNumber(mesh.extractMs, 3)} ms`],
    ['server normals', `${formatNumber(mesh.normalsMs, 3)} ms`],
    ['server encode', `${formatNumber(mesh.encodeMs, 3)} ms`],
    ['codec', codec, 'stat-codec'],
    ['Draco speed', mesh.dracoSpeed === null ? '–' : String(mesh.dracoSpeed), 'stat-speed'],
    ['decode', `${formatNumber(decodeMs, 3)} ms`],
    ['cells visited', integer(mesh.cellsVisited)],
    ['error bound', formatNumber(mesh.errorBound)],
    ['tolerance used', formatNumber(mesh.tolerance)],
    ['distance (p99)', mesh.distanceMm === null ? '–' : `${formatNumber(mesh.distanceMm, 3)} mm`, 'stat-distance'],
    ['cache', cache, 'stat-cache'],
  ]);
}

// Area in mm² and enclosed volume in mL (1 mL = 1,000 mm³) per surface; a surface that is
// not closed has no volume (cap closes it at the volume's border).
export function showMeasures(table, rows) {
  const lines = [];
  for (const r of rows) {
    lines.push([r.name, '']);
    if (r.areaMm2 === undefined) continue;
    lines.push(['area', `${formatNumber(r.areaMm2, 6)} mm²`]);
    lines.push(['enclosed volume', r.closed === 'true' && r.volumeMm3 !== null
      ? `${formatNumber(r.volumeMm3 / 1000, 5)} mL`
      : (r.cap ? '– (not closed)' : '– (open: tick “close at the border”)')]);
  }
  fillTable(table, lines);
  table.querySelectorAll('tr').forEach((tr, k) => { tr.dataset.row = String(k); });
}

// A bar of a round length (1, 2 or 5 times a power of ten mm) about 100 px long.
export function showScale(mmPerPixel) {
  if (!Number.isFinite(mmPerPixel) || mmPerPixel <= 0) return;
  const target = mmPerPixel * 100;
  const power = 10 ** Math.floor(Math.log10(target));
  const length = [1, 2, 5, 10].map((m) => m * power).find((l) => l >= target * 0.7) ?? 10 * power;
  document.getElementById('scale-bar').style.width = `${length / mmPerPixel}px`;
  document.getElementById('scale-label').textContent = `${formatNumber(length)} mm`;
}

export function showError(message, action) {
  const box = document.getElementById('error');
  box.hidden = !message;
  box.textContent = message || '';
  if (message && action) {
    const b = document.createElement('button');
    b.type = 'button';
    b.textContent = action.label;
    b.id = action.id ?? '';
    b.addEventListener('click', action.run);
    box.append(document.createElement('br'), b);
  }
}

export function megabytes(bytes) {
  return bytes >= 1e6 ? `${formatNumber(bytes / 1e6, 3)} MB` : `${formatNumber(bytes / 1e3, 3)} kB`;
}
