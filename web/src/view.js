// view.js: the 3D view: three.js scene, Draco decoding in a worker (DRACOLoader), orbit
// controls, a light that follows the camera, framing, and a scale bar in millimetres.
//
// Meshes arrive in LPS millimetres (x to the patient's left, y posterior, z superior).
// The mesh group is turned so that superior is up and anterior faces the viewer:
// display (x, y, z) = (L, S, A) = (x, z, -y), a rotation of -90 degrees about x.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { DRACOLoader } from 'three/addons/loaders/DRACOLoader.js';

export class View {
  constructor(container) {
    this.container = container;
    this.renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio, 2));
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
    this.material = new THREE.MeshStandardMaterial({ color: 0xe8dccb, roughness: 0.55, metalness: 0, side: THREE.DoubleSide });
    this.draco = new DRACOLoader().setDecoderPath('./three/addons/libs/draco/');
    this.draco.preload();
    this.mesh = null;
    this.onScale = () => {};
    new ResizeObserver(() => this.resize()).observe(container);
    this.resize();
  }

  // Decodes Draco bytes into geometry (in the loader's worker); resolves with it.
  decode(bytes) {
    return new Promise((resolve, reject) => this.draco.parse(bytes, resolve, reject));
  }

  // Shows geometry in place of the current mesh; frames it when asked.
  show(geometry, frame) {
    if (!geometry.getAttribute('normal') && geometry.getAttribute('position')?.count) geometry.computeVertexNormals();
    if (this.mesh) {
      this.group.remove(this.mesh);
      this.mesh.geometry.dispose();
    }
    this.mesh = new THREE.Mesh(geometry, this.material);
    this.group.add(this.mesh);
    if (frame && geometry.getAttribute('position')?.count) this.frame();
    this.render();
  }

  clear() {
    if (this.mesh) {
      this.group.remove(this.mesh);
      this.mesh.geometry.dispose();
      this.mesh = null;
    }
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

  set wireframe(on) { this.material.wireframe = on; this.render(); }

  // Files without orientation (plain spacings) may store the head upside down: a half turn
  // about the viewing axis (a rotation, never a mirror) puts it right, face still forward.
  set flipped(on) {
    this.turn.rotation.z = on ? Math.PI : 0;
    if (this.mesh) this.frame();
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
