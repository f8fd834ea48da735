// panel-volume.js: the panel's volume section: the volume menu (names, the id only where
// it differs), the volume's size and voxel, and what the file says about its orientation.
import { formatNumber } from './ui.js';

export function mountVolume(ctx) {
  const { $ } = ctx;
  $('volume').addEventListener('change', (e) => ctx.selectVolume(e.target.value, false));
}

export function listVolumes(ctx, list) {
  ctx.$('volume').replaceChildren(...list.map((v) => {
    const o = new Option(v.name && v.name !== v.id ? `${v.name} (${v.id})` : v.id, v.id);
    o.title = `${v.modality ? `${v.modality} · ` : ''}${v.dims?.join('×') ?? ''}`;
    return o;
  }));
}

// The size line and the orientation note of the current volume.
export function showVolume(ctx) {
  const { $ } = ctx, info = ctx.info();
  $('volume').value = info.id;
  $('volume-info').textContent = `${info.modality ? `${info.modality} · ` : ''}${info.dims.join('×')} ${info.value_type} · ` +
    `voxel ${info.spacing.map((s) => formatNumber(s, 3)).join('×')} mm`;
  const note = $('orientation-note');
  note.hidden = info.orientation !== 'none';
  note.textContent = 'The file does not say how the patient lies: its axes are taken as i to the left, ' +
    'j posterior, k superior (LPS, as in DICOM), so the head may show upside down or from behind. ' +
    'Set where they point under View (axes), or give the catalog entry an "orientation".';
}
