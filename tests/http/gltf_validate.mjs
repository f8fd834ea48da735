// gltf_validate.mjs: runs the Khronos glTF validator (npm's gltf-validator) over glb files
// and prints, per file, "<errors> <warnings> <meshopt index headers, hex, comma-separated>"
// (the headers: the first byte of each EXT_meshopt_compression TRIANGLES view; "-" if none).
// The validator does not decode the meshopt or Draco streams; it checks everything around
// them (the container, the JSON against the schema, accessors, views, the extensions' use).
// usage: node gltf_validate.mjs WEB_DIR FILE.glb...   (WEB_DIR/node_modules holds gltf-validator)
import { readFileSync } from 'node:fs';
import { createRequire } from 'node:module';
import { pathToFileURL } from 'node:url';

const here = new URL('.', import.meta.url);
const { meshoptIndexHeaders } = await import(new URL('../support/glb.mjs', here));
const require = createRequire(pathToFileURL(process.argv[2] + '/node_modules/'));
const validator = require('gltf-validator');

for (const file of process.argv.slice(3)) {
  const bytes = new Uint8Array(readFileSync(file));
  const report = await validator.validateBytes(bytes, { maxIssues: 100 });
  const headers = meshoptIndexHeaders(bytes).map((b) => '0x' + b.toString(16)).join(',') || '-';
  console.log(`${report.issues.numErrors} ${report.issues.numWarnings} ${headers}`);
  for (const m of report.issues.messages.filter((x) => x.severity <= 1))
    console.error(`${file}: ${m.severity ? 'warning' : 'error'} ${m.code} at ${m.pointer}: ${m.message}`);
}
