// loader.js: the requests of each surface and what they are doing, for the view and the
// status line.
//
// A settled change of a surface (a level picked, a tolerance, a volume opened) shows one
// small preview, then the surface: the preview at a tolerance of the whole value range
// (twice the volume's preview_tolerance, which alone leaves 16-30% of the triangles on
// the MRI brains; the whole range leaves 0.4-2% on every volume measured, and the shape),
// or coarser where the slider's previews have found their size; no normals. Then the mesh
// asked for. The full mesh is asked
// for as soon as the preview's body is in, and the preview is decoded and drawn while the
// server works on it (still one request in flight per surface). No preview when the mesh
// asked for is in the browser's cache already, when the tolerance asked for is as coarse,
// or when Detail asks for a chain level no larger than the preview would be (the chain's
// own figures say so when the server has them).
//
// While a level slider moves, previews follow it: when one arrives, the next is asked for
// the slider's latest level; the levels passed over are never asked. A generation counter
// per surface drops any answer a newer request superseded, so a stale mesh never replaces
// the final one. Every request reports its phase (waiting for the server: extracting, or
// extracting and simplifying; downloading, with bytes; decoding) and is aborted by the
// next change or by cancel(). A server that does not answer (or answers 503) is asked
// again after 1, 2, 4 ... 30 s; a 422 (more triangles than the server serves) asks the
// server which tolerance or detail fits and offers it.
import { ApiError, CODEC_FORMATS, getBudgetFacts, getChain, getMesh, meshUrl } from './api.js';

const PREVIEW_TRIANGLES = 16000;
const LOD_TRIANGLES = 200000; // a full mesh larger than this gets a preview to turn with
const RETRY_MAX_S = 30;

// The full meshes this browser has fetched (their URLs, the last SEEN_MAX), kept across
// reloads: asking the HTTP cache whether it holds one would log a failed request.
const SEEN_MAX = 500;
const seen = {
  urls: (() => { try { return JSON.parse(localStorage.getItem('isoserve.seen') ?? '[]'); } catch { return []; } })(),
  has(url) { return this.urls.includes(url); },
  add(url) {
    if (this.has(url)) return;
    this.urls = [...this.urls.slice(-(SEEN_MAX - 1)), url];
    try { localStorage.setItem('isoserve.seen', JSON.stringify(this.urls)); } catch { /* full or denied: no shortcut */ }
  },
};

export class Loader {
  // ctx: { state, view, info() (the volume's document), shows() (whether the surfaces are
  // drawn at all), onShown(record), onChange() }
  constructor(ctx) {
    this.ctx = ctx;
    this.live = ctx.state.surfaces.map(() => this.fresh());
    this.shown = []; // one record per mesh drawn (tests and the benchmark read them)
  }

  fresh() {
    return { generation: 0, controller: null, inFlight: false, want: null, previewTolerance: null,
      phase: null, drawn: null, failure: null, offer: null, retry: null, attempt: 0 };
  }

  // A new volume: nothing drawn, previews steered anew.
  reset() {
    this.live.forEach((l) => { this.abort(l); Object.assign(l, this.fresh(), { generation: l.generation + 1 }); });
  }

  get range() {
    const info = this.ctx.info();
    return info ? (info.value_range[1] - info.value_range[0]) || 1 : 1;
  }

  previewFloor() {
    const info = this.ctx.info();
    return Math.max(this.ctx.state.tolerance, info?.preview_tolerance ?? this.range / 2);
  }

  previewTolerance(i) {
    return Math.max(this.previewFloor(), this.live[i].previewTolerance ?? 0);
  }

  // Each preview's answer steers the next tolerance by at most 1.5x toward
  // PREVIEW_TRIANGLES, up to four times the value range.
  steer(i, tolerance, triangles) {
    if (!(triangles > 0)) return;
    const f = Math.min(1.5, Math.max(1 / 1.5, Math.sqrt(triangles / PREVIEW_TRIANGLES)));
    this.live[i].previewTolerance = Math.min(4 * this.range, Math.max(this.previewFloor(), tolerance * f));
  }

  format() { return CODEC_FORMATS[this.ctx.state.codec] ?? 'draco'; }

  abort(l) {
    l.controller?.abort();
    clearTimeout(l.retry?.timer);
    l.retry = null;
  }

  pending() { return this.live.some((l) => l.phase); }

  // Aborts whatever surface i (or every surface) has in flight; what is drawn stays.
  cancel(i) {
    for (const [k, l] of this.live.entries()) {
      if (i !== undefined && k !== i) continue;
      l.generation++;
      this.abort(l);
      l.phase = null;
      l.inFlight = false;
      l.want = null;
    }
    this.ctx.onChange();
  }

  setPhase(i, mine, phase) {
    if (mine !== this.live[i].generation) return;
    this.live[i].phase = phase ? { ...phase, since: phase.since ?? performance.now() } : null;
    this.ctx.onChange();
  }

  // A settled change of surface i: a preview first (when `preview` and worth it), then
  // the mesh asked for.
  async refresh(i, preview = true) {
    const { state, view } = this.ctx;
    const s = state.surfaces[i], l = this.live[i];
    const mine = ++l.generation;
    this.abort(l);
    l.want = null;
    l.inFlight = false;
    l.failure = null;
    l.offer = null;
    l.controller = new AbortController();
    const { signal } = l.controller;
    if (!s.on || !state.volume || !this.ctx.shows()) {
      view.hide(i);
      l.drawn = null;
      this.setPhase(i, mine, null);
      return;
    }
    view.style(i, s.color, s.opacity);
    const params = { level: s.level, tolerance: state.tolerance, normals: state.normals, distance: state.distance };
    try {
      const cached = await this.fromBrowserCache(i, params, mine, signal);
      if (cached || mine !== l.generation) return;
      let ahead = null;
      if (preview && await this.previewWorthIt(i, params, signal)) ahead = await this.preview(i, params, mine, signal);
      if (mine !== l.generation) return;
      await this.fetchAndShow(i, params, mine, signal, 'final', ahead);
      l.attempt = 0;
      this.setPhase(i, mine, null);
    } catch (error) {
      if (mine === l.generation) this.failed(i, mine, error, () => this.refresh(i, preview));
    }
  }

  // A mesh this browser fetched before (a link reloaded, a level seen again) comes from
  // its HTTP cache (mesh URLs are immutable): asked for at once, without a preview.
  async fromBrowserCache(i, params, mine, signal) {
    const url = meshUrl(this.ctx.state.volume, { ...params, format: this.format() });
    if (!seen.has(url)) return false;
    await this.fetchAndShow(i, params, mine, signal, 'final', null);
    this.setPhase(i, mine, null);
    return true;
  }

  // Whether a preview before the mesh of `params` saves the user time: not when the
  // tolerance asked for is as coarse, nor when Detail's chain level is no larger than a
  // preview (the chain's figures, when the server has them and they are built).
  async previewWorthIt(i, params, signal) {
    if (this.settleTolerance(i) <= params.tolerance) return false;
    if (!(params.distance > 0)) return true;
    const chain = await getChain(this.ctx.state.volume, params, signal).catch((e) => {
      if (e.name === 'AbortError') throw e;
      return null;
    });
    if (!chain || chain.state !== 'ready' || !chain.levels?.length) return true;
    const level = [...chain.levels].reverse().find((x) => x.distance_p99_mm <= params.distance) ?? chain.levels[0];
    const previewGuess = 0.02 * (chain.exact_triangles ?? chain.levels[0].triangles);
    return level.triangles > 2 * previewGuess;
  }

  // A settled change's preview tolerance (see the top).
  settleTolerance(i) {
    return Math.max(this.range, this.previewTolerance(i));
  }

  // A preview for a large full mesh drawn without one (from the browser's cache), kept to
  // stand in while the view moves; nothing is shown or reported.
  async fetchLod(i, level, mine) {
    const l = this.live[i], p = { level, tolerance: this.settleTolerance(i), normals: 'none' };
    try {
      const mesh = await getMesh(this.ctx.state.volume, { ...p, format: this.format() }, l.controller?.signal);
      const decoded = await this.ctx.view.decode(mesh.bytes, this.ctx.state.codec);
      if (mine === l.generation) this.ctx.view.keepLod(i, decoded, level);
      else decoded.geometry.dispose();
    } catch { /* without it the view turns with the full mesh */ }
  }

  // Fetches the preview and starts decoding it; returns the drawing's promise so that the
  // full request goes out while it runs.
  async preview(i, params, mine, signal) {
    const p = { level: params.level, tolerance: this.settleTolerance(i), normals: 'none' };
    const started = performance.now();
    const mesh = await this.fetchMesh(i, p, mine, signal, 'preview');
    return this.display(i, mesh, p, mine, 'preview', started).catch(() => false);
  }

  // One request of surface i, its phases reported: the server at work, the download.
  async fetchMesh(i, params, mine, signal, kind) {
    const waiting = params.distance > 0 ? 'extracting and simplifying' : 'extracting';
    this.setPhase(i, mine, { kind, level: params.level, step: waiting });
    return getMesh(this.ctx.state.volume, { ...params, format: this.format() }, signal, {
      headers: () => this.setPhase(i, mine, { kind, level: params.level, step: 'downloading', received: 0, total: null }),
      progress: (received, total) => {
        const l = this.live[i];
        if (mine !== l.generation || !l.phase) return;
        l.phase.received = received;
        l.phase.total = total;
        this.ctx.onChange(true);
      },
    });
  }

  async fetchAndShow(i, params, mine, signal, kind, ahead) {
    const started = performance.now();
    const mesh = await this.fetchMesh(i, params, mine, signal, kind);
    await ahead; // the preview drawn first, never after
    this.setPhase(i, mine, { kind, level: params.level, step: 'decoding' });
    return this.display(i, mesh, params, mine, kind, started);
  }

  // Decodes and draws a fetched mesh unless a newer request of surface i superseded it.
  async display(i, mesh, params, mine, kind, started) {
    const l = this.live[i], { view, state } = this.ctx;
    if (mine !== l.generation) return false;
    const start = performance.now();
    const decoded = await view.decode(mesh.bytes, state.codec);
    const decodeMs = performance.now() - start;
    if (mine !== l.generation) {
      decoded.geometry.dispose();
      return false;
    }
    const drawing = performance.now();
    view.show(i, decoded, { lod: kind !== 'final', level: params.level });
    l.drawn = { level: params.level, kind, triangles: mesh.triangles, tolerance: params.tolerance,
      distance: params.distance ?? 0, mesh, decodeMs };
    // The split the browser benchmark reports: the answer's arrival after the request
    // (server and transfer; the server's own steps from its headers), decoding, drawing.
    const record = { surface: i, level: params.level, tolerance: params.tolerance, distance: params.distance ?? 0, kind,
      triangles: mesh.triangles, bytes: mesh.size, decodeMs, ms: performance.now() - started, at: performance.now(),
      fetchMs: (mesh.arrived ?? start) - started, serverMs: (mesh.extractMs ?? 0) + (mesh.normalsMs ?? 0) + (mesh.encodeMs ?? 0),
      drawMs: performance.now() - drawing, browserCached: mesh.browserCached };
    this.shown.push(record);
    view.afterFrame.push(() => { record.drawnAt = performance.now(); }); // the frame that shows it
    if (kind === 'final' && !view.hasLod(i) && mesh.triangles > LOD_TRIANGLES) this.fetchLod(i, params.level, mine);
    if (kind === 'final') seen.add(meshUrl(state.volume, { ...params, format: this.format() }));
    this.ctx.onShown(i, record, mesh);
    return true;
  }

  // A failed request: retried with backoff when the server may answer later, an offer
  // for a 422, else the server's sentence. What is drawn stays, and the status says so.
  failed(i, mine, error, again) {
    if (error.name === 'AbortError') return;
    const l = this.live[i];
    l.phase = null;
    if (error instanceof ApiError && error.retry !== null) {
      l.attempt++;
      const wait = Math.min(RETRY_MAX_S, Math.max(error.retry, 2 ** (l.attempt - 1)));
      const at = performance.now() + wait * 1000;
      l.failure = { message: error.message, retrying: true };
      l.retry = { at, attempt: l.attempt, timer: setTimeout(() => { if (mine === l.generation) again(); }, wait * 1000),
        now: () => { if (mine === l.generation) { clearTimeout(l.retry?.timer); again(); } } };
    } else {
      l.attempt = 0;
      l.failure = { message: error instanceof ApiError ? error.message : `could not show the mesh: ${error.message}`,
        status: error.status ?? 0 };
      if (error.status === 422) this.offerFit(i, mine, error);
    }
    this.ctx.onChange();
  }

  // For a 422: the server's limit from its sentence, then the finest mesh within it (a
  // HEAD with budget=) as one click: its tolerance, or its Detail when a chain level fits.
  async offerFit(i, mine, error) {
    const m = /limit of ([\d,]+)/.exec(error.message);
    const l = this.live[i], { state } = this.ctx;
    if (!m) return;
    const limit = Number(m[1].replace(/,/g, ''));
    l.offer = { finding: true, limit };
    this.ctx.onChange();
    try {
      const f = await getBudgetFacts(state.volume, { level: state.surfaces[i].level, tolerance: state.tolerance,
        normals: 'none', format: 'ply' }, limit, l.controller?.signal);
      if (mine !== l.generation) return;
      // Rounded up: a smaller distance or tolerance could ask for a finer, larger mesh.
      const up = (x) => { const p = 10 ** (Math.floor(Math.log10(x)) - 2); return Number((Math.ceil(x / p) * p).toPrecision(3)); };
      l.offer = f.budgetSource === 'chain' && f.distanceMm !== null
        ? { limit, triangles: f.triangles, distance: up(f.distanceMm) }
        : { limit, triangles: f.triangles, tolerance: f.tolerance > 0 ? up(f.tolerance) : state.tolerance };
    } catch (e) {
      if (mine === l.generation) l.offer = { limit, failed: e.message };
    }
    this.ctx.onChange();
  }

  // While surface i's slider moves: previews of the latest level, one request in flight.
  async drag(i, level) {
    const l = this.live[i];
    if (!this.ctx.shows()) return; // the segments alone: the level waits for the release
    l.want = level;
    if (l.inFlight) return;
    l.inFlight = true;
    const mine = l.generation;
    let showing = Promise.resolve();
    while (l.want !== null && mine === l.generation) {
      const params = { level: l.want, tolerance: this.previewTolerance(i), normals: 'none' };
      l.want = null;
      l.controller?.abort();
      l.controller = new AbortController();
      const started = performance.now();
      let mesh;
      try {
        mesh = await this.fetchMesh(i, params, mine, l.controller.signal, 'drag');
      } catch (error) {
        if (mine === l.generation) this.failed(i, mine, error, () => this.refresh(i, false));
        break;
      }
      this.steer(i, params.tolerance, mesh.triangles);
      await showing; // previews are drawn in the order they were asked
      showing = this.display(i, mesh, params, mine, 'drag', started).catch(() => false);
      if (l.want === null) await showing; // nothing newer yet: draw, then look again
    }
    await showing;
    if (mine === l.generation) this.setPhase(i, mine, null);
    l.inFlight = false;
  }
}
