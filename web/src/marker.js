// marker.js: the orientation marker in the view's lower left corner: the patient's axes as
// three coloured lines (left-right red, posterior-anterior green, inferior-superior blue,
// as in 3D Slicer) with their letters at both ends, turned with the main camera. For a
// volume whose file has no orientation the letters are grey: they name assumed directions.
import * as THREE from 'three';

const SIZE = 110; // pixels

function letter(text, color) {
  const canvas = document.createElement('canvas');
  canvas.width = canvas.height = 64;
  const ctx = canvas.getContext('2d');
  ctx.font = 'bold 44px system-ui, sans-serif';
  ctx.textAlign = 'center';
  ctx.textBaseline = 'middle';
  ctx.fillStyle = color;
  ctx.fillText(text, 32, 34);
  const sprite = new THREE.Sprite(new THREE.SpriteMaterial({ map: new THREE.CanvasTexture(canvas), depthTest: false }));
  sprite.scale.set(0.8, 0.8, 1);
  sprite.userData.text = text;
  return sprite;
}

export class Marker {
  constructor() {
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(30, 1, 0.1, 10);
    this.labels = [];
    const axes = [['L', 'R', 0xd9534f], ['P', 'A', 0x5cb85c], ['S', 'I', 0x4a90e2]];
    axes.forEach(([plus, minus, color], a) => {
      const end = new THREE.Vector3().setComponent(a, 1);
      const line = new THREE.BufferGeometry().setFromPoints([end.clone().negate(), end]);
      this.scene.add(new THREE.Line(line, new THREE.LineBasicMaterial({ color })));
      for (const [text, sign] of [[plus, 1], [minus, -1]]) {
        const label = letter(text, `#${color.toString(16).padStart(6, '0')}`);
        label.position.copy(end).multiplyScalar(1.35 * sign);
        this.labels.push(label);
        this.scene.add(label);
      }
    });
    this.scene.add(new THREE.Mesh(new THREE.BoxGeometry(0.5, 0.5, 0.5),
      new THREE.MeshBasicMaterial({ color: 0x888888, transparent: true, opacity: 0.35 })));
    this.known = true;
  }

  setAxesKnown(known) {
    this.known = known;
    for (const l of this.labels) l.material.color.set(known ? 0xffffff : 0x777777);
  }

  setBackground() { /* the marker draws over the scene's own background */ }

  // Draws the marker in the lower left corner, seen from the main camera's direction.
  render(renderer, main, width, height) {
    const size = Math.min(SIZE, width / 4, height / 4);
    this.camera.quaternion.copy(main.quaternion);
    this.camera.position.set(0, 0, 7.5).applyQuaternion(main.quaternion);
    this.camera.up.copy(main.up);
    renderer.setScissorTest(true);
    renderer.setScissor(8, 8, size, size);
    renderer.setViewport(8, 8, size, size);
    renderer.clearDepth();
    renderer.render(this.scene, this.camera);
    renderer.setScissorTest(false);
    renderer.setViewport(0, 0, width, height);
  }

  // Where each letter lands on screen now (pixels from the view's top left), for the tests.
  letters(main, width, height) {
    const size = Math.min(SIZE, width / 4, height / 4);
    this.camera.quaternion.copy(main.quaternion);
    this.camera.position.set(0, 0, 7.5).applyQuaternion(main.quaternion);
    this.camera.updateMatrixWorld();
    const out = {};
    for (const l of this.labels) {
      const p = l.position.clone().project(this.camera);
      out[l.userData.text] = { x: 8 + (p.x + 1) / 2 * size, y: height - 8 - (p.y + 1) / 2 * size, depth: p.z };
    }
    return out;
  }
}
