// marker.js: the orientation marker in the view's lower left corner: the patient's axes as
// three coloured lines (left-right red, posterior-anterior green, inferior-superior blue,
// as in 3D Slicer) with their letters at both ends, turned with the main camera. It is
// drawn on a small 2D canvas of its own over the view (no WebGL program to compile before
// the first surface). For a volume whose file has no orientation the letters are grey:
// they name assumed directions.
import * as THREE from 'three';

const SIZE = 110; // CSS pixels
const AXES = [['L', 'R', '#d9534f'], ['P', 'A', '#5cb85c'], ['S', 'I', '#4a90e2']];

export class Marker {
  constructor(container) {
    this.canvas = document.createElement('canvas');
    this.canvas.className = 'marker';
    const ratio = Math.min(window.devicePixelRatio, 2);
    this.canvas.width = this.canvas.height = SIZE * ratio;
    Object.assign(this.canvas.style, { position: 'absolute', left: '8px', bottom: '8px', width: `${SIZE}px`,
      height: `${SIZE}px`, pointerEvents: 'none' });
    container.append(this.canvas);
    this.known = true;
    this.inverse = new THREE.Matrix4();
  }

  setAxesKnown(known) { this.known = known; }

  // Where each letter lands (pixels of the marker, from its top left) and its depth toward
  // the viewer (smaller: nearer), seen from the main camera's direction.
  letters(main) {
    this.inverse.copy(main.matrixWorld).invert().setPosition(0, 0, 0); // the camera's rotation only
    const out = {};
    AXES.forEach(([plus, minus], a) => {
      for (const [text, sign] of [[plus, 1], [minus, -1]]) {
        const p = new THREE.Vector3().setComponent(a, sign).applyMatrix4(this.inverse);
        out[text] = { x: SIZE / 2 + p.x * SIZE * 0.36, y: SIZE / 2 - p.y * SIZE * 0.36, depth: -p.z, axis: a };
      }
    });
    return out;
  }

  render(main) {
    const ctx = this.canvas.getContext('2d');
    const ratio = this.canvas.width / SIZE;
    ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
    ctx.clearRect(0, 0, SIZE, SIZE);
    const letters = Object.entries(this.letters(main)).sort((a, b) => b[1].depth - a[1].depth); // far first
    ctx.lineWidth = 2;
    ctx.font = 'bold 15px system-ui, sans-serif';
    ctx.textAlign = 'center';
    ctx.textBaseline = 'middle';
    for (const [text, p] of letters) {
      const color = AXES[p.axis][2];
      ctx.strokeStyle = color;
      ctx.beginPath();
      ctx.moveTo(SIZE / 2, SIZE / 2);
      ctx.lineTo(SIZE / 2 + (p.x - SIZE / 2) * 0.78, SIZE / 2 + (p.y - SIZE / 2) * 0.78);
      ctx.stroke();
      ctx.fillStyle = this.known ? color : '#888888';
      ctx.fillText(text, p.x, p.y);
    }
  }
}
