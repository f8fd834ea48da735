// view.js: the 3D view: three.js scene in the patient's frame, mesh decoding (Draco in a
// worker with DRACOLoader, glb-meshopt with GLTFLoader + MeshoptDecoder), one mesh per
// surface and one per segment of a segmentation (a scene glb's nodes, or one segment's
// mesh), each with its own colour and opacity, a clipping plane, the camera (camera.js)
// and the orientation marker (marker.js), drawn on demand: every change asks for a frame
// and at most one frame is drawn per animation frame, so input never queues behind
// drawing.
//
// While the camera turns or the clipping plane moves, a view whose last full frame took
// more than SLOW_FRAME_MS (software GL, a large mesh) draws each surface's preview mesh
// instead, at half the resolution (as VTK's LOD actors and volume renderers' interactive
// quality do), and the full meshes again once the button is released and nothing has
// moved for SETTLE_MS: turning stays smooth (a pause with the button down does not start
// a slow full frame), and what stays on screen is the full surface.
//
// The scene's world is LPS millimetres, as the meshes arrive (x to the patient's left, y
// posterior, z superior), superior up. A volume whose file has no orientation gets its
// assumed axes corrected by `axes` (a mirror per flipped axis about the volume's centre);
// everything else (camera, clipping plane, URL) is in the corrected frame.
import * as THREE from 'three';
import { DRACOLoader } from 'three/addons/loaders/DRACOLoader.js';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { MeshoptDecoder } from 'three/addons/libs/meshopt_decoder.module.js';
import { Camera } from './camera.js';
import { Marker } from './marker.js';

const AXES = { x: 0, y: 1, z: 2 };
const DEFAULT_AXES = 'LPS';
const SLOW_FRAME_MS = 60;
const SETTLE_MS = 250;

export class View {
  constructor(container) {
    this.container = container;
    this.renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    this.pixelRatio = Math.min(window.devicePixelRatio, 2);
    this.renderer.setPixelRatio(this.pixelRatio);
    this.renderer.localClippingEnabled = true;
    container.prepend(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x404048, 1.2));
    this.camera = new Camera(this.renderer.domElement, () => this.moving());
    this.holding = false; // a mouse button down on the view
    this.camera.controls.addEventListener('start', () => { this.holding = true; });
    this.camera.controls.addEventListener('end', () => { this.holding = false; this.moving(); });
    this.scene.add(this.camera.camera);
    this.group = new THREE.Group(); // the axes correction of an unoriented volume
    this.group.matrixAutoUpdate = false;
    this.scene.add(this.group);
    this.marker = new Marker(container);
    this.plane = new THREE.Plane(new THREE.Vector3(1, 0, 0), 0);
    this.clipping = [];
    this.surfaces = [];
    this.segments = new Map(); // segment number -> { material, mesh }: a segmentation's surfaces
    this.wire = false;
    this.bounds = null; // the volume's box in the corrected frame: THREE.Box3
    this.draco = new DRACOLoader().setDecoderPath('./three/addons/libs/draco/');
    this.draco.preload();
    this.gltf = new GLTFLoader().setMeshoptDecoder(MeshoptDecoder).setDRACOLoader(this.draco);
    this.onScale = () => {};
    this.onFrame = () => {};
    this.frames = 0; // drawn frames, for the benchmark's frames per second
    this.pending = false;
    this.fullFrameMs = 0; // the last frame with every full mesh
    this.afterFrame = []; // called once after the next frame is drawn
    this.motion = null;   // the timer that ends a motion
    new ResizeObserver(() => this.resize()).observe(container);
    this.resize();
  }

  // Asks for a frame; many asks before the next animation frame draw once. Nothing is
  // drawn before a volume is set: the page's first requests go out without waiting for
  // the first frame's shaders.
  requestRender() {
    if (this.pending || !this.bounds) return;
    this.pending = true;
    requestAnimationFrame(() => {
      this.pending = false;
      this.render();
    });
  }

  // The camera or the clipping plane moves: draw, with the previews if full frames are
  // slow, until SETTLE_MS pass without motion.
  moving() {
    clearTimeout(this.motion);
    const settle = () => {
      if (this.holding) { this.motion = setTimeout(settle, SETTLE_MS); return; }
      this.motion = null;
      this.requestRender();
    };
    this.motion = setTimeout(settle, SETTLE_MS);
    this.requestRender();
  }

  // Resolves once the frames asked for so far are drawn, full meshes included (tests read
  // pixels after it).
  async drawn() {
    while (this.motion || this.pending) await new Promise((resolve) => setTimeout(resolve, 20));
    return new Promise((resolve) => requestAnimationFrame(() => requestAnimationFrame(resolve)));
  }

  // Decodes a mesh body into { geometry, matrix } (matrix: the glb node's transform, which
  // dequantizes meshopt's integer positions; identity for Draco).
  async decode(bytes, codec) {
    if (codec !== 'meshopt') {
      const geometry = await new Promise((resolve, reject) => this.draco.parse(bytes, resolve, reject));
      return { geometry, matrix: new THREE.Matrix4() };
    }
    const gltf = await this.gltf.parseAsync(bytes, '');
    let found = null;
    gltf.scene.updateMatrixWorld(true);
    gltf.scene.traverse((o) => { if (o.isMesh && !found) found = o; });
    if (!found) return { geometry: new THREE.BufferGeometry(), matrix: new THREE.Matrix4() };
    return { geometry: found.geometry, matrix: found.matrixWorld.clone() };
  }

  // Decodes a scene glb (a segmentation's segments: one mesh node per segment, its number
  // in the node's extras.segment) into [{ number, name, geometry, matrix }].
  async decodeScene(bytes) {
    const gltf = await this.gltf.parseAsync(bytes, '');
    gltf.scene.updateMatrixWorld(true);
    const found = [];
    gltf.scene.traverse((o) => {
      if (!o.isMesh) return;
      const number = o.userData?.segment ?? o.parent?.userData?.segment;
      found.push({ number, name: o.name, geometry: o.geometry, matrix: o.matrixWorld.clone() });
      o.material?.dispose?.(); // the viewer's own materials carry colour and opacity
    });
    return found;
  }

  // The volume: its LPS box as the file places it ([[x0, y0, z0], [x1, y1, z1]]), the
  // assumed axes' correction (a code like LPI: where i, j, k point) and whether the file
  // says how its axes lie. Sets the camera's limits; the camera itself is set by the caller.
  setVolume(box, axes = DEFAULT_AXES, oriented = true) {
    const lo = new THREE.Vector3(...box[0]), hi = new THREE.Vector3(...box[1]);
    const centre = lo.clone().add(hi).multiplyScalar(0.5);
    const sign = [...DEFAULT_AXES].map((letter, a) => (axes[a] === letter ? 1 : -1));
    this.group.matrix.makeTranslation(centre.x, centre.y, centre.z)
      .multiply(new THREE.Matrix4().makeScale(...sign))
      .multiply(new THREE.Matrix4().makeTranslation(-centre.x, -centre.y, -centre.z));
    this.group.matrixWorldNeedsUpdate = true;
    this.axes = axes;
    this.bounds = new THREE.Box3(lo, hi); // a mirror about the centre keeps the box
    this.camera.setBounds(this.bounds);
    this.marker.setAxesKnown(oriented);
    this.requestRender();
  }

  // The i-th surface's mesh and material, made on first use.
  surface(i) {
    while (this.surfaces.length <= i) {
      const material = new THREE.MeshStandardMaterial({ color: 0xe8dccb, roughness: 0.55, metalness: 0,
        side: THREE.DoubleSide, clippingPlanes: this.clipping });
      this.surfaces.push({ material, mesh: null });
    }
    return this.surfaces[i];
  }

  // Shows a decoded mesh as surface i in place of its previous one. `lod`: it is a preview,
  // also kept to stand in for the full mesh while the view moves; a full mesh of another
  // level than the kept preview drops it.
  show(i, { geometry, matrix }, { lod = false, level = null } = {}) {
    if (!geometry.getAttribute('normal') && geometry.getAttribute('position')?.count) geometry.computeVertexNormals();
    const s = this.surface(i);
    if (s.mesh) this.drop(s.mesh);
    s.mesh = this.mesh(s, geometry, matrix);
    this.group.add(s.mesh);
    if (lod) this.keepLod(i, { geometry: geometry.clone(), matrix }, level);
    else if (s.lod && s.lodLevel !== level) this.keepLod(i, null, null);
    this.measure = true;
    this.requestRender();
  }

  // Keeps a preview (or none) to stand in for surface i's mesh while the view moves.
  keepLod(i, decoded, level) {
    const s = this.surface(i);
    if (s.lod) this.drop(s.lod);
    s.lod = decoded ? this.mesh(s, decoded.geometry, decoded.matrix) : null;
    s.lodLevel = level;
    if (s.lod) { s.lod.visible = false; this.group.add(s.lod); }
  }

  mesh(s, geometry, matrix) {
    const mesh = new THREE.Mesh(geometry, s.material);
    mesh.matrixAutoUpdate = false;
    mesh.matrix.copy(matrix);
    mesh.renderOrder = s.material.transparent ? 1 : 0; // translucent after opaque
    return mesh;
  }

  drop(mesh) {
    this.group.remove(mesh);
    mesh.geometry.dispose();
  }

  // Whether surface i has a preview to stand in while the view moves.
  hasLod(i) { return !!this.surfaces[i]?.lod; }

  // The box of what is drawn (corrected frame), or null when nothing is.
  drawnBox() {
    this.group.updateMatrixWorld(true);
    const box = new THREE.Box3();
    const drawn = [...this.surfaces, ...[...this.segments.values()].filter((s) => s.mesh?.visible)];
    for (const s of drawn) if (s.mesh?.geometry.getAttribute('position')?.count) box.expandByObject(s.mesh);
    return box.isEmpty() ? null : box;
  }

  // Removes surface i's mesh (a surface switched off).
  hide(i) {
    const s = this.surfaces[i];
    if (s?.mesh) this.drop(s.mesh);
    if (s?.lod) this.drop(s.lod);
    if (s) { s.mesh = null; s.lod = null; }
    this.requestRender();
  }

  // Colour ('#rrggbb') and opacity (0..1) of surface i. A translucent surface writes no
  // depth, so the opaque one behind it shows through.
  style(i, color, opacity) {
    const { material, mesh } = this.surface(i);
    material.color.set(color);
    material.opacity = opacity;
    material.transparent = opacity < 1;
    material.depthWrite = opacity >= 1;
    material.needsUpdate = true;
    if (mesh) mesh.renderOrder = material.transparent ? 1 : 0;
    if (this.surfaces[i].lod) this.surfaces[i].lod.renderOrder = material.transparent ? 1 : 0;
    this.requestRender();
  }

  clear() {
    this.surfaces.forEach((_, i) => this.hide(i));
    this.clearSegments();
  }

  // Segment n's decoded mesh, drawn in its colour and opacity (and shown or not), in place
  // of any it had.
  showSegment(n, { geometry, matrix }, color, opacity, visible) {
    if (!geometry.getAttribute('normal') && geometry.getAttribute('position')?.count) geometry.computeVertexNormals();
    let s = this.segments.get(n);
    if (!s) {
      s = { material: new THREE.MeshStandardMaterial({ roughness: 0.55, metalness: 0, side: THREE.DoubleSide,
        clippingPlanes: this.clipping, wireframe: this.wire }), mesh: null };
      this.segments.set(n, s);
    }
    if (s.mesh) this.drop(s.mesh);
    s.mesh = this.mesh(s, geometry, matrix);
    this.group.add(s.mesh);
    this.styleSegment(n, color, opacity, visible);
    this.measure = true;
  }

  // Segment n's colour, opacity and visibility: no request, no decoding, one frame.
  styleSegment(n, color, opacity, visible) {
    const s = this.segments.get(n);
    if (!s) return;
    const m = s.material;
    m.color.set(color);
    if (m.transparent !== opacity < 1) m.needsUpdate = true;
    m.opacity = opacity;
    m.transparent = opacity < 1;
    m.depthWrite = opacity >= 1;
    if (s.mesh) { s.mesh.visible = visible; s.mesh.renderOrder = m.transparent ? 1 : 0; }
    this.requestRender();
  }

  clearSegments() {
    for (const s of this.segments.values()) {
      if (s.mesh) this.drop(s.mesh);
      s.material.dispose();
    }
    this.segments.clear();
    this.requestRender();
  }

  // The clipping plane: off, or across `axis` ('x', 'y' or 'z' of the corrected LPS frame)
  // at `at` (0..1 of the volume's box), keeping the side below it (or above when `flip`).
  clip(on, axis, at, flip) {
    const a = AXES[axis] ?? 0;
    const was = this.clipping.length;
    this.clipping.length = 0;
    if (on && this.bounds) {
      const where = this.bounds.min.getComponent(a) + at * (this.bounds.max.getComponent(a) - this.bounds.min.getComponent(a));
      const normal = new THREE.Vector3().setComponent(a, flip ? 1 : -1);
      this.plane.set(normal, flip ? -where : where);
      this.clipping.push(this.plane);
    }
    // The shaders change only when the plane comes or goes; moving it is a uniform.
    if (was !== this.clipping.length) for (const s of this.materials()) s.material.needsUpdate = true;
    this.moving();
  }

  // Every surface's and segment's { material }.
  materials() { return [...this.surfaces, ...this.segments.values()]; }

  set wireframe(on) {
    this.wire = on;
    for (const s of this.materials()) s.material.wireframe = on;
    this.requestRender();
  }

  set background(color) {
    this.renderer.setClearColor(color);
    this.requestRender();
  }

  resize() {
    const { clientWidth: w, clientHeight: h } = this.container;
    if (!w || !h) return;
    this.renderer.setSize(w, h);
    this.camera.setAspect(w / h);
    this.requestRender();
  }

  render() {
    this.frames++;
    const { clientWidth: w, clientHeight: h } = this.container;
    // Previews stand in while moving when full frames are slow; never a surface without one.
    const light = this.motion !== null && this.fullFrameMs > SLOW_FRAME_MS;
    for (const s of this.surfaces) {
      if (!s.mesh) continue;
      const swap = light && !!s.lod;
      s.mesh.visible = !swap;
      if (s.lod) s.lod.visible = swap;
    }
    const ratio = light ? this.pixelRatio / 2 : this.pixelRatio;
    if (this.renderer.getPixelRatio() !== ratio) this.renderer.setPixelRatio(ratio), this.renderer.setSize(w, h);
    const start = performance.now();
    this.renderer.render(this.scene, this.camera.camera);
    // Reading one pixel waits for the GPU: the frame's real cost, measured on the first
    // full frame after a mesh changed.
    if (!light && this.measure) {
      this.measure = false;
      this.renderer.getContext().readPixels(0, 0, 1, 1, 0x1908, 0x1401, new Uint8Array(4));
      this.fullFrameMs = performance.now() - start;
    }
    this.marker.render(this.camera.camera);
    this.onScale(this.camera.mmPerPixel(h));
    this.onFrame();
    const after = this.afterFrame;
    this.afterFrame = [];
    for (const f of after) f();
  }
}
