// api.js: the isoserve HTTP API as the client uses it: documents, meshes (with the facts
// their X-Iso headers carry) and errors turned into sentences (problem+json's detail).

export class ApiError extends Error {}

async function failure(response) {
  let detail = `${response.status} ${response.statusText}`;
  try {
    const problem = await response.json();
    if (problem.detail) detail = problem.detail;
  } catch { /* not a problem body: the status line says it */ }
  return new ApiError(detail);
}

export async function getJson(url, signal) {
  const response = await fetch(url, { signal });
  if (!response.ok) throw await failure(response);
  return response.json();
}

// The viewer's codecs and the API formats that carry them.
export const CODEC_FORMATS = { draco: 'draco', meshopt: 'glb-meshopt' };

export function meshUrl(volume, { level, tolerance, normals, format = 'draco', measures = false, cap = false, distance = 0 }) {
  const q = new URLSearchParams({ level: String(level), tolerance: String(tolerance), normals, format });
  if (distance > 0) q.set('distance', String(distance));
  if (cap) q.set('cap', 'true');
  if (measures) q.set('measures', 'true');
  return `v1/volumes/${encodeURIComponent(volume)}/mesh?${q}`;
}

const number = (h, name) => (h.get(name) === null ? null : Number(h.get(name)));

// Fetches a mesh (params.format: draco or glb-meshopt); returns its bytes and what the
// headers say about it.
export async function getMesh(volume, params, signal) {
  const response = await fetch(meshUrl(volume, params), { signal });
  if (!response.ok) throw await failure(response);
  const bytes = await response.arrayBuffer();
  return { bytes, size: bytes.byteLength, arrived: performance.now(), ...facts(response.headers) };
}

// The measures of a surface (measures=true), from the headers alone: a HEAD request.
export async function getMeasures(volume, params, signal) {
  const response = await fetch(meshUrl(volume, { ...params, measures: true }), { method: 'HEAD', signal });
  if (!response.ok) throw new ApiError(`${response.status} ${response.statusText}: the server could not measure`);
  return facts(response.headers);
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
    areaMm2: number(h, 'X-Iso-Area-Mm2'),
    volumeMm3: number(h, 'X-Iso-Volume-Mm3'),
    closed: h.get('X-Iso-Closed'),
    cache: h.get('X-Iso-Cache'),
  };
}
