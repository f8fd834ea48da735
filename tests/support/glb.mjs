// glb.mjs: reads a glTF binary's container as another decoder would, for the tests: its
// JSON chunk and BIN chunk, and the first byte of every EXT_meshopt_compression view that
// codes triangles (the index codec's header: EXT_meshopt_compression's TRIANGLES mode
// requires 0xe1, version 1).
const GLB_MAGIC = 0x46546c67, CHUNK_JSON = 0x4e4f534a, CHUNK_BIN = 0x004e4942;

// { json, bin } of a glb (bin a Uint8Array view, null when absent); throws on a bad container.
export function glbChunks(bytes) {
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  if (bytes.byteLength < 20 || view.getUint32(0, true) !== GLB_MAGIC) throw new Error('not a glb');
  let json = null, bin = null;
  for (let at = 12; at + 8 <= bytes.byteLength;) {
    const length = view.getUint32(at, true), type = view.getUint32(at + 4, true);
    const data = bytes.subarray(at + 8, at + 8 + length);
    if (type === CHUNK_JSON) json = JSON.parse(new TextDecoder().decode(data));
    if (type === CHUNK_BIN) bin = data;
    at += 8 + length;
  }
  if (!json) throw new Error('glb without a JSON chunk');
  return { json, bin };
}

// The first byte of each meshopt view of mode TRIANGLES, in view order.
export function meshoptIndexHeaders(bytes) {
  const { json, bin } = glbChunks(bytes);
  return (json.bufferViews || [])
    .map((v) => v.extensions?.EXT_meshopt_compression)
    .filter((m) => m && m.mode === 'TRIANGLES')
    .map((m) => bin[m.byteOffset || 0]);
}
