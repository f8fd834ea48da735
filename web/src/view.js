// view.js: the 3D view: three.js scene, mesh decoding (Draco in a worker with DRACOLoader,
// glb-meshopt with GLTFLoader + MeshoptDecoder), one mesh per surface with its own colour
// and opacity, a clipping plane, orbit controls, a light that follows the camera, framing,
// and a scale bar in millimetres.
//
// Meshes arrive in LPS millimetres (x to the patient's left, y posterior, z superior).
// The mesh group is turned so that superior is up and anterior faces the viewer:
// display (x, y, z) = (L, S, A) = (x, z, -y), a rotation of -90 degrees about x.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { DRACOLoader } from 'three/addons/loaders/DRACOLoader.js';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { MeshoptDecoder } from 'three/addons/libs/meshopt_decoder.module.js';

const AXES = { x: 0, y: 1, z: 2 };

export class View {
  constructor(container) {
    this.container = container;
    this.renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio, 2));
    this.renderer.localClippingEnabled = true;
    container.prepend(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(35, 1, 0.1, 1e6);
    this.scene.add(this.camera);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x404048, 1.2));
    const headlight = new THREE.DirectionalLight(0xffffff, 2.2);
    headlight.position.set(0.3, 0.5, 1); // from just above and right of the eye
    this.camera.add(headlight);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.addEventListener('change', () => this.render());
    this.group = new THREE.Group();
    this.group.rotation.x = -Math.PI / 2;
    this.turn = new THREE.Group(); // the optional half turn about the viewing axis
    this.turn.add(this.group);
    this.scene.add(this.turn);
    this.plane = new THREE.Plane(new THREE.Vector3(1, 0, 0), 0);
    this.clipping = [];
    this.surfaces = [];
    this.draco = new DRACOLoader().setDecoderPath('./three/addons/libs/draco/');
    this.draco.preload();
    this.gltf = new GLTFLoader().setMeshoptDecoder(MeshoptDecoder);
    this.onScale = () => {};
    new ResizeObserver(() => this.resize()).observe(container);
    this.resize();
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

  // The i-th surface's mesh and material, made on first use.
  surface(i) {
    while (this.surfaces.length <= i) {
      const material = new THREE.MeshStandardMaterial({ color: 0xe8dccb, roughness: 0.55, metalness: 0,
        side: THREE.DoubleSide, clippingPlanes: this.clipping });
      this.surfaces.push({ material, mesh: null });
    }
    return this.surfaces[i];
  }

  // Shows a decoded mesh as surface i in place of its previous one; frames it when asked.
  show(i, { geometry, matrix }, frame) {
    if (!geometry.getAttribute('normal') && geometry.getAttribute('position')?.count) geometry.computeVertexNormals();
    const s = this.surface(i);
    if (s.mesh) {
      this.group.remove(s.mesh);
      s.mesh.geometry.dispose();
    }
    s.mesh = new THREE.Mesh(geometry, s.material);
    s.mesh.matrixAutoUpdate = false;
    s.mesh.matrix.copy(matrix);
    s.mesh.renderOrder = s.material.transparent ? 1 : 0; // translucent after opaque
    this.group.add(s.mesh);
    if (frame && geometry.getAttribute('position')?.count) this.frame();
    this.render();
  }

  // Removes surface i's mesh (a surface switched off).
  hide(i) {
    const s = this.surfaces[i];
    if (s?.mesh) {
      this.group.remove(s.mesh);
      s.mesh.geometry.dispose();
      s.mesh = null;
    }
    this.render();
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
    this.render();
  }

  clear() {
    this.surfaces.forEach((_, i) => this.hide(i));
  }

  // The clipping plane: off, or across `axis` ('x', 'y' or 'z' of the volume's LPS mm) at
  // `at`, keeping the side below it (or above when `flip`).
  clip(on, axis, at, flip) {
    this.clipping.length = 0;
    if (on) {
      const normal = new THREE.Vector3();
      normal.setComponent(AXES[axis] ?? 0, flip ? 1 : -1);
      this.turn.updateMatrixWorld(true);
      const local = new THREE.Plane(normal, flip ? -at : at);
      this.plane.copy(local).applyMatrix4(this.group.matrixWorld);
      this.clipping.push(this.plane);
    }
    for (const s of this.surfaces) s.material.needsUpdate = true;
    this.render();
  }

  frame() {
    this.turn.updateMatrixWorld(true); // the half turn must count before measuring
    const box = new THREE.Box3().setFromObject(this.group);
    const sphere = box.getBoundingSphere(new THREE.Sphere());
    const distance = sphere.radius / Math.sin(THREE.MathUtils.degToRad(this.camera.fov / 2)) * 1.1;
    this.controls.target.copy(sphere.center);
    this.camera.position.copy(sphere.center).add(new THREE.Vector3(0, 0, distance));
    this.camera.near = distance / 100;
    this.camera.far = distance * 10;
    this.camera.updateProjectionMatrix();
    this.controls.update();
  }

  set wireframe(on) {
    for (const s of this.surfaces) s.material.wireframe = on;
    this.render();
  }

  // Files without orientation (plain spacings) may store the head upside down: a half turn
  // about the viewing axis (a rotation, never a mirror) puts it right, face still forward.
  set flipped(on) {
    this.turn.rotation.z = on ? Math.PI : 0;
    if (this.surfaces.some((s) => s.mesh)) this.frame();
    this.render();
  }

  set background(color) { this.renderer.setClearColor(color); this.render(); }

  resize() {
    const { clientWidth: w, clientHeight: h } = this.container;
    if (!w || !h) return;
    this.renderer.setSize(w, h);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.render();
  }

  // Millimetres per pixel at the orbit target: what the scale bar needs.
  mmPerPixel() {
    const distance = this.camera.position.distanceTo(this.controls.target);
    const visible = 2 * distance * Math.tan(THREE.MathUtils.degToRad(this.camera.fov / 2));
    return visible / this.container.clientHeight;
  }

  render() {
    this.renderer.render(this.scene, this.camera);
    this.onScale(this.mmPerPixel());
  }
}
