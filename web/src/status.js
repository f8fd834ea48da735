// status.js: what the view shows and what it waits for, over the view's top left: per
// surface, the level drawn (preview or full, its triangles), and the request pending
// (the server extracting, or simplifying; the download with its bytes; decoding) with its
// time so far and a Cancel button (Esc); a server that did not answer, with the retry's
// countdown and Retry now; a mesh over the server's limit, with the tolerance or detail
// that fits as one click. Also the stats table of surface 1's last mesh.
import { formatNumber, megabytes, showStats } from './ui.js';

const seconds = (ms) => `${(ms / 1000).toFixed(1)} s`;

function button(label, id, run) {
  const b = document.createElement('button');
  b.type = 'button';
  b.textContent = label;
  b.id = id;
  b.addEventListener('click', run);
  return b;
}

function phaseText(p) {
  const what = p.kind === 'final' ? 'surface' : 'preview';
  const since = seconds(performance.now() - p.since);
  if (p.step === 'downloading') {
    const got = megabytes(p.received ?? 0);
    return `downloading the ${what} at ${formatNumber(p.level, 6)}: ${p.total ? `${got} of ${megabytes(p.total)}` : got} (${since})`;
  }
  if (p.step === 'decoding') return `decoding the ${what} at ${formatNumber(p.level, 6)}`;
  return `server ${p.step} the ${what} at ${formatNumber(p.level, 6)}… (${since})`;
}

// Redraws the status lines from the loader's state.
export function showStatus(ctx) {
  const { state, loader } = ctx, box = ctx.$('status');
  const lines = [];
  state.surfaces.forEach((s, i) => {
    if (!s.on || !state.volume || !ctx.shows()) return;
    const l = loader.live[i];
    const name = state.surfaces[1].on ? `Surface ${i + 1}: ` : '';
    const d = l.drawn;
    const line = document.createElement('div');
    line.id = `status-${i + 1}`;
    let text = !d ? `${name}nothing drawn yet` : d.triangles === 0 ? `${name}no surface at ${formatNumber(d.level, 6)}`
      : `${name}${formatNumber(d.level, 6)}, ${d.kind === 'final' ? 'full' : 'preview'}, ${formatNumber(d.triangles, 7)} triangles`;
    if (l.phase) text += ` · ${phaseText(l.phase)}`;
    line.textContent = text;
    if (l.failure) {
      const f = document.createElement('div');
      f.className = 'failure';
      if (l.retry) {
        f.textContent = `${formatNumber(s.level, 6)} not loaded: ${l.failure.message}; trying again in ` +
          `${Math.max(0, Math.ceil((l.retry.at - performance.now()) / 1000))} s (attempt ${l.retry.attempt + 1})`;
        f.append(button('Retry now', `retry-${i + 1}`, l.retry.now));
      } else {
        f.textContent = `${formatNumber(s.level, 6)} not shown: ${l.failure.message}`;
      }
      if (l.offer) f.append(offer(ctx, i, l.offer));
      line.append(f);
    }
    lines.push(line);
  });
  if (loader.pending()) {
    const cancel = button('Cancel', 'cancel', () => loader.cancel());
    cancel.title = 'stop loading (Esc); what is drawn stays';
    lines[0]?.append(cancel);
  }
  box.replaceChildren(...lines);
}

// A 422's one click: the tolerance or detail whose mesh fits the server's limit.
function offer(ctx, i, o) {
  const span = document.createElement('div');
  if (o.finding) { span.textContent = `finding the finest mesh within ${formatNumber(o.limit, 9)} triangles…`; return span; }
  if (o.failed) { span.textContent = `no mesh within ${formatNumber(o.limit, 9)} triangles was found (${o.failed})`; return span; }
  const label = o.distance !== undefined
    ? `Show it with Detail ${formatNumber(o.distance, 3)} mm (${formatNumber(o.triangles, 9)} triangles)`
    : `Show it at tolerance ${formatNumber(o.tolerance, 4)} (${formatNumber(o.triangles, 9)} triangles)`;
  span.append(button(label, `fit-${i + 1}`, () => ctx.applyFit(o)));
  return span;
}

export function showSurfaceStats(ctx, i, mesh, decodeMs) {
  if (i === 0) showStats(ctx.$('stats'), mesh, decodeMs, ctx.state.codec);
}
