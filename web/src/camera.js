// camera.js: the camera of the 3D view as a radiologist expects it: superior up, orbiting
// about the patient's long axis (OrbitControls with z up), preset views as in 3D Slicer
// (anterior, posterior, left, right, superior, inferior), reset to the anterior view framed
// on what is drawn, and the camera as text for the link (eye and target in LPS mm).
//
// Presets look at the target from the named side: "anterior" is the camera in front of the
// patient (at -y), looking toward posterior. Superior and inferior views look along the
// long axis with anterior at the top of the screen, as Slicer's do.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

// The side each preset's camera sits on, and a nudge off the long axis for the two that
// look along it (OrbitControls' up is z: a tiny offset chooses which way is up on screen).
const PRESETS = {
  anterior: [0, -1, 0], posterior: [0, 1, 0], left: [1, 0, 0], right: [-1, 0, 0],
  superior: [0, 1e-4, 1], inferior: [0, -1e-4, -1],
};
const FOV = 35;
const round = (x, step) => Math.round(x / step) * step;

export class Camera {
  constructor(element, changed) {
    this.camera = new THREE.PerspectiveCamera(FOV, 1, 0.1, 1e6);
    this.camera.up.set(0, 0, 1); // before the controls read it
    const headlight = new THREE.DirectionalLight(0xffffff, 2.2);
    headlight.position.set(0.3, 0.5, 1); // from just above and right of the eye
    this.camera.add(headlight);
    this.controls = new OrbitControls(this.camera, element);
    this.controls.addEventListener('change', () => { this.limits(); changed(); });
    this.controls.addEventListener('end', () => this.onEnd());
    this.bounds = null;
    this.onEnd = () => {};
  }

  setBounds(box) {
    this.bounds = box;
    this.limits();
  }

  setAspect(aspect) {
    this.camera.aspect = aspect;
    this.camera.updateProjectionMatrix();
  }

  // Near and far from the eye's distance and the volume's size alone, so that a camera
  // read from a link draws exactly what it drew before the link was made.
  limits() {
    const radius = this.bounds ? this.bounds.getBoundingSphere(new THREE.Sphere()).radius : 100;
    const distance = this.camera.position.distanceTo(this.controls.target);
    this.camera.near = Math.max(distance - 3 * radius, distance / 200, 0.01);
    this.camera.far = distance + 3 * radius;
    this.camera.updateProjectionMatrix();
  }

  // Looks at `box` (THREE.Box3) from a preset's side, at the distance that fits its
  // bounding sphere in the view.
  view(preset, box) {
    const side = new THREE.Vector3(...PRESETS[preset]).normalize();
    const sphere = (box ?? this.bounds ?? new THREE.Box3(new THREE.Vector3(-50, -50, -50), new THREE.Vector3(50, 50, 50)))
      .getBoundingSphere(new THREE.Sphere());
    const fit = Math.min(this.camera.fov, this.camera.fov * this.camera.aspect);
    const distance = sphere.radius / Math.sin(THREE.MathUtils.degToRad(fit / 2)) * 1.05;
    this.set(sphere.center.clone().addScaledVector(side, distance), sphere.center);
  }

  // Keeps the distance and target, changes the side (a preset key pressed while zoomed).
  turn(preset) {
    const distance = this.camera.position.distanceTo(this.controls.target);
    const side = new THREE.Vector3(...PRESETS[preset]).normalize();
    this.set(this.controls.target.clone().addScaledVector(side, distance), this.controls.target.clone());
  }

  // Eye and target, rounded as the link holds them (0.01 mm), so that what is drawn is
  // what the link restores, pixel for pixel.
  set(eye, target) {
    this.camera.position.set(round(eye.x, 0.01), round(eye.y, 0.01), round(eye.z, 0.01));
    this.controls.target.set(round(target.x, 0.01), round(target.y, 0.01), round(target.z, 0.01));
    this.controls.update();
    this.limits();
  }

  // The camera as the link's text: "ex,ey,ez,tx,ty,tz" (LPS mm of the corrected frame).
  toText() {
    const p = this.camera.position, t = this.controls.target;
    return [p.x, p.y, p.z, t.x, t.y, t.z].map((x) => String(Number(x.toFixed(2)))).join(',');
  }

  // Sets the camera from a link's text; false when the text is not six finite numbers or
  // the eye sits on the target.
  fromText(text) {
    const v = String(text ?? '').split(',').map(Number);
    if (v.length !== 6 || !v.every(Number.isFinite)) return false;
    const eye = new THREE.Vector3(v[0], v[1], v[2]), target = new THREE.Vector3(v[3], v[4], v[5]);
    if (eye.distanceTo(target) < 1e-3) return false;
    this.set(eye, target);
    return true;
  }

  // Quantizes the camera after the user moved it (rounding moves it by at most 5 µm).
  settle() {
    this.set(this.camera.position.clone(), this.controls.target.clone());
  }

  // Millimetres per pixel at the orbit target: what the scale bar needs.
  mmPerPixel(height) {
    const distance = this.camera.position.distanceTo(this.controls.target);
    return (2 * distance * Math.tan(THREE.MathUtils.degToRad(this.camera.fov / 2))) / height;
  }
}

export const PRESET_NAMES = Object.keys(PRESETS);
