// panel-surfaces.js: the panel's surfaces: surface 1's level on the volume's histogram
// (click it, drag the slider, or pick a suggested level), surface 2's level, each one's
// colour and opacity. Beside a level, what the view shows when it is not that level yet
// (a preview, or the last surface drawn while the new one loads or failed), so the panel
// and the view never disagree.
import { drawHistogram, formatNumber } from './ui.js';

const ids = (i) => ({ level: i ? 'level-2' : 'level', value: i ? 'level-2-value' : 'level-value',
  drawn: i ? 'level-2-drawn' : 'level-drawn', color: `color-${i + 1}`, opacity: `opacity-${i + 1}` });

// Level slider positions: linear over the value range, 1000 steps.
const range = (info) => (info.value_range[1] - info.value_range[0]) || 1;
export const levelFromSlider = (info, s) => Number((info.value_range[0] + (s / 1000) * range(info)).toPrecision(6));
const sliderFromLevel = (info, l) => Math.round(((l - info.value_range[0]) / range(info)) * 1000);

export function mountSurfaces(ctx) {
  const { $, state, view, loader } = ctx;
  state.surfaces.forEach((s, i) => {
    const id = ids(i);
    $(id.level).addEventListener('input', (e) => {
      const level = levelFromSlider(ctx.info(), +e.target.value);
      $(id.value).textContent = formatNumber(level, 6);
      loader.drag(i, level);
    });
    $(id.level).addEventListener('change', (e) => {
      s.level = levelFromSlider(ctx.info(), +e.target.value);
      ctx.refresh(i, false); // the drag's last preview is the preview
    });
    $(id.color).addEventListener('input', (e) => { s.color = e.target.value; view.style(i, s.color, s.opacity); ctx.writeUrl(); });
    $(id.opacity).addEventListener('input', (e) => {
      s.opacity = Number(e.target.value) / 100;
      view.style(i, s.color, s.opacity);
      $(`${id.opacity}-value`).textContent = `${e.target.value}%`;
      ctx.writeUrl();
    });
  });
  $('surface-2').addEventListener('change', (e) => {
    const s = state.surfaces[1];
    s.on = e.target.checked;
    if (s.on && s.level === null) s.level = ctx.suggested()[1] ?? state.surfaces[0].level;
    ctx.refresh(1);
  });
}

// The histogram and suggested levels of a new volume.
export function drawLevels(ctx) {
  const info = ctx.info();
  drawHistogram(ctx.$('histogram'), info.histogram, info.suggested_levels, (level) => ctx.pickLevel(0, level));
}

export function syncSurfaces(ctx) {
  const { $, state, loader } = ctx, info = ctx.info();
  state.surfaces.forEach((s, i) => {
    const id = ids(i);
    if (s.level !== null && info) {
      $(id.level).value = sliderFromLevel(info, s.level);
      $(id.value).textContent = formatNumber(s.level, 6);
    }
    $(id.color).value = s.color;
    $(id.opacity).value = Math.round(s.opacity * 100);
    $(`${id.opacity}-value`).textContent = `${Math.round(s.opacity * 100)}%`;
    const drawn = loader.live[i].drawn;
    $(id.drawn).textContent = !s.on || !drawn ? '' : drawn.level !== s.level ? `(showing ${formatNumber(drawn.level)})`
      : drawn.kind !== 'final' ? '(preview)' : '';
  });
  $('surface-2').checked = state.surfaces[1].on;
  $('surface-2-controls').hidden = !state.surfaces[1].on;
}
