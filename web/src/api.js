// api.js: the isoserve HTTP API as the client uses it: documents, meshes and a
// segmentation's meshes (with the facts their X-Iso headers carry, read while the body
// streams in so that progress can show its bytes), the simplification chain's figures,
// and errors turned into sentences (problem+json's detail) that say whether trying again
// may help.

// A failure the server explained (status, problem type, detail), or one it could not
// (status 0: the server did not answer). `retry`: seconds after which trying again may
// succeed (the server gone, 503's Retry-After), or null.
export class ApiError extends Error {
  constructor(message, { status = 0, type = '', problem = null, retry = null } = {}) {
    super(message);
    this.status = status;
    this.type = type;
    this.problem = problem;
    this.retry = retry;
  }
}

async function failure(response) {
  let detail = `${response.status} ${response.statusText}`, problem = null;
  try {
    problem = await response.json();
    if (problem.detail) detail = problem.detail;
  } catch { /* not a problem body: the status line says it */ }
  const after = Number(response.headers.get('Retry-After'));
  return new ApiError(detail, { status: response.status, type: problem?.type ?? '', problem,
    retry: response.status === 503 ? (Number.isFinite(after) && after > 0 ? after : 1) : null });
}

// fetch, with "the server did not answer" as an ApiError that may be retried.
async function request(url, options) {
  try {
    return await fetch(url, options);
  } catch (error) {
    if (error.name === 'AbortError') throw error;
    throw new ApiError('the server did not answer (is it running?)', { retry: 1 });
  }
}

export async function getJson(url, signal) {
  const response = await request(url, { signal });
  if (!response.ok) throw await failure(response);
  return response.json();
}

// The viewer's codecs and the API formats that carry them.
export const CODEC_FORMATS = { draco: 'draco', meshopt: 'glb-meshopt' };

export function meshUrl(volume, { level, tolerance, normals, format = 'draco', measures = false, cap = false, distance = 0, budget = 0 }) {
  const q = new URLSearchParams({ level: String(level), tolerance: String(tolerance), normals, format });
  if (distance > 0) q.set('distance', String(distance));
  if (budget > 0) q.set('budget', String(budget));
  if (cap) q.set('cap', 'true');
  if (measures) q.set('measures', 'true');
  return `v1/volumes/${encodeURIComponent(volume)}/mesh?${q}`;
}

const number = (h, name) => (h.get(name) === null ? null : Number(h.get(name)));

// Reads a body chunk by chunk, telling `progress(received, total)` (total: the
// Content-Length of an uncompressed body, else null) as bytes arrive.
async function readBody(response, progress) {
  const total = response.headers.get('Content-Encoding') ? null : number(response.headers, 'Content-Length');
  if (!response.body || !progress) return response.arrayBuffer();
  const reader = response.body.getReader();
  const chunks = [];
  let received = 0;
  progress(0, total);
  for (;;) {
    const { done, value } = await reader.read();
    if (done) break;
    chunks.push(value);
    received += value.byteLength;
    progress(received, total);
  }
  const bytes = new Uint8Array(received);
  let at = 0;
  for (const c of chunks) { bytes.set(c, at); at += c.byteLength; }
  return bytes.buffer;
}

// Fetches a mesh (params.format: draco or glb-meshopt); returns its bytes and what the
// headers say about it. `on.headers()` when the server has answered (its work is done),
// `on.progress(received, total)` while the body arrives.
export async function getMesh(volume, params, signal, on = {}) {
  return getMeshAt(meshUrl(volume, params), signal, on);
}

// A segmentation's meshes: segment number n's, or every segment's in one scene glb (n null).
export function segmentMeshUrl(volume, n, { normals, format, cap = true }) {
  const q = new URLSearchParams({ normals, format });
  if (cap) q.set('cap', 'true');
  const route = n === null ? 'segments/mesh' : `segments/${n}/mesh`;
  return `v1/volumes/${encodeURIComponent(volume)}/${route}?${q}`;
}

// getMesh for a mesh route's URL.
export async function getMeshAt(url, signal, on = {}) {
  const response = await request(url, { signal });
  if (!response.ok) throw await failure(response);
  on.headers?.();
  const bytes = await readBody(response, on.progress);
  const entry = performance.getEntriesByName(new URL(url, location.href).href).at(-1);
  // A body the browser's own cache gave transfers nothing: say so, not the server's word.
  const browserCached = entry ? entry.transferSize === 0 && entry.decodedBodySize > 0 : false;
  return { bytes, size: bytes.byteLength, arrived: performance.now(), browserCached, ...facts(response.headers) };
}

// The measures of a surface (measures=true), from the headers alone: a HEAD request.
export async function getMeasures(volume, params, signal) {
  const response = await request(meshUrl(volume, { ...params, measures: true }), { method: 'HEAD', signal });
  if (!response.ok) throw new ApiError(`${response.status} ${response.statusText}: the server could not measure`,
    { status: response.status });
  return facts(response.headers);
}

// The facts of the mesh a budget gives (HEAD with budget=): which tolerance or chain level
// fits, for a 422's offer.
export async function getBudgetFacts(volume, params, budget, signal) {
  const response = await request(meshUrl(volume, { ...params, budget }), { method: 'HEAD', signal });
  if (!response.ok) throw new ApiError(`${response.status} ${response.statusText}`, { status: response.status });
  return facts(response.headers);
}

// The simplification chain of (level, tolerance, cap): {state, exact_triangles, levels:
// [{triangles, distance_p99_mm, distance_max_mm}, ...]}, or null when this server has no
// such route (a 404 that is not a problem about the volume: asked once, then never again).
let chainRoute = true;
export async function getChain(volume, { level, tolerance, cap }, signal) {
  if (!chainRoute) return null;
  const q = new URLSearchParams({ level: String(level), tolerance: String(tolerance) });
  if (cap) q.set('cap', 'true');
  const response = await request(`v1/volumes/${encodeURIComponent(volume)}/chain?${q}`, { signal });
  if (response.status === 404 || response.status === 405) {
    const detail = (await response.json().catch(() => ({}))).detail ?? '';
    if (!/^no volume/.test(detail)) chainRoute = false;
    return null;
  }
  if (response.status === 400) return null;
  if (!response.ok) throw await failure(response);
  const doc = await response.json();
  return doc && Array.isArray(doc.levels) && typeof doc.state === 'string' ? doc : null;
}

function facts(h) {
  return {
    triangles: number(h, 'X-Iso-Triangles'),
    vertices: number(h, 'X-Iso-Vertices'),
    cellsVisited: number(h, 'X-Iso-Cells-Visited'),
    extractMs: number(h, 'X-Iso-Extract-Ms'),
    normalsMs: number(h, 'X-Iso-Normals-Ms'),
    measureMs: number(h, 'X-Iso-Measure-Ms'),
    encodeMs: number(h, 'X-Iso-Encode-Ms'),
    dracoSpeed: number(h, 'X-Iso-Draco-Speed'),
    errorBound: number(h, 'X-Iso-Error-Bound'),
    tolerance: number(h, 'X-Iso-Tolerance'),
    distanceMm: number(h, 'X-Iso-Distance-Mm'),
    chainLevel: number(h, 'X-Iso-Chain-Level'),
    exactTriangles: number(h, 'X-Iso-Exact-Triangles'),
    budgetSource: h.get('X-Iso-Budget-Source'),
    areaMm2: number(h, 'X-Iso-Area-Mm2'),
    volumeMm3: number(h, 'X-Iso-Volume-Mm3'),
    closed: h.get('X-Iso-Closed'),
    cache: h.get('X-Iso-Cache'),
  };
}
