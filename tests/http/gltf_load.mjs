// gltf_load.mjs: loads a glb with three.js's own GLTFLoader in node and prints
// "<triangles> <vertices> <has normals>", then the world bounding box's min and max (the node
// transforms applied: KHR_mesh_quantization's dequantization). EXT_meshopt_compression is
// decoded by three's own MeshoptDecoder (WebAssembly, no worker). DRACOLoader decodes in Web Workers, which node
// lacks, so the KHR_draco_mesh_compression extension is handed a decoder with the same
// decodeDracoFile contract built on npm's draco3d: everything else (the container, the
// JSON, accessors, the extension's attribute mapping) is GLTFLoader's own code.
// With CORNERS, also writes every triangle corner's world position there, in triangle order
// (float32 x, y, z each): a decoded mesh compared corner by corner, whatever its numbering.
// usage: node gltf_load.mjs FILE.glb WEB_DIR [CORNERS]   (WEB_DIR/node_modules holds three and draco3d)
import { readFileSync, writeFileSync } from 'node:fs';
import { createRequire } from 'node:module';
import { pathToFileURL } from 'node:url';

const modules = process.argv[3] + '/node_modules/';
const THREE = await import(pathToFileURL(modules + 'three/build/three.module.js'));
const { GLTFLoader } = await import(pathToFileURL(modules + 'three/examples/jsm/loaders/GLTFLoader.js'));
const { MeshoptDecoder } = await import(pathToFileURL(modules + 'three/examples/jsm/libs/meshopt_decoder.module.js'));
const require = createRequire(modules);
const draco3d = require('draco3d');
const module = await draco3d.createDecoderModule({});

const dracoInNode = {
  preload() { return this; },
  decodeDracoFile(buffer, callback, attributeIDs, attributeTypes) {
    const decoder = new module.Decoder();
    const mesh = new module.Mesh();
    const bytes = new Int8Array(buffer);
    const status = decoder.DecodeArrayToMesh(bytes, bytes.length, mesh);
    if (!status.ok()) throw new Error('draco: ' + status.error_msg());
    const geometry = new THREE.BufferGeometry();
    for (const [name, id] of Object.entries(attributeIDs)) {
      const attribute = decoder.GetAttributeByUniqueId(mesh, id);
      const values = new module.DracoFloat32Array();
      decoder.GetAttributeFloatForAllPoints(mesh, attribute, values);
      const n = mesh.num_points() * attribute.num_components();
      const array = new Float32Array(n);
      for (let i = 0; i < n; i++) array[i] = values.GetValue(i);
      module.destroy(values);
      geometry.setAttribute(name, new THREE.BufferAttribute(array, attribute.num_components()));
    }
    const faces = mesh.num_faces();
    const index = new Uint32Array(faces * 3);
    const face = new module.DracoInt32Array();
    for (let f = 0; f < faces; f++) {
      decoder.GetFaceFromMesh(mesh, f, face);
      for (let k = 0; k < 3; k++) index[3 * f + k] = face.GetValue(k);
    }
    module.destroy(face);
    geometry.setIndex(new THREE.BufferAttribute(index, 1));
    module.destroy(mesh);
    module.destroy(decoder);
    callback(geometry);
  },
};

const data = readFileSync(process.argv[2]);
const loader = new GLTFLoader().setDRACOLoader(dracoInNode).setMeshoptDecoder(MeshoptDecoder);
const buffer = data.buffer.slice(data.byteOffset, data.byteOffset + data.byteLength);
loader.parse(buffer, '', (gltf) => {
  let triangles = 0, vertices = 0, normals = true;
  gltf.scene.traverse((o) => {
    if (!o.isMesh) return;
    triangles += o.geometry.index.count / 3;
    vertices += o.geometry.attributes.position.count;
    normals = normals && !!o.geometry.attributes.normal;
  });
  const box = new THREE.Box3().setFromObject(gltf.scene);
  if (process.argv[4]) {
    const corners = [], p = new THREE.Vector3();
    gltf.scene.traverse((o) => {
      if (!o.isMesh) return;
      const index = o.geometry.index, position = o.geometry.attributes.position;
      for (let i = 0; i < index.count; i++) {
        p.fromBufferAttribute(position, index.getX(i)).applyMatrix4(o.matrixWorld);
        corners.push(p.x, p.y, p.z);
      }
    });
    writeFileSync(process.argv[4], new Float32Array(corners));
  }
  console.log(`${triangles} ${vertices} ${normals} ${box.min.toArray().join(' ')} ${box.max.toArray().join(' ')}`);
}, (error) => { console.error(String(error)); process.exit(1); });
