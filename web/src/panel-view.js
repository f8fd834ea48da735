// panel-view.js: the panel's view section: preset views (anterior, posterior, left, right,
// superior, inferior) and reset, wireframe and background, and for a volume whose file has
// no orientation the axes' assumed directions.
import { AXES_CODES } from './url.js';

const AXES_TEXT = { L: 'left', R: 'right', P: 'posterior', A: 'anterior', S: 'superior', I: 'inferior' };

export function mountView(ctx) {
  const { $, state, view } = ctx;
  for (const b of document.querySelectorAll('[data-preset]')) b.addEventListener('click', () => ctx.preset(b.dataset.preset));
  $('reset-view').addEventListener('click', () => ctx.resetView());
  $('wireframe').addEventListener('change', (e) => { state.wireframe = e.target.checked; applyLook(ctx); ctx.writeUrl(); });
  $('light').addEventListener('change', (e) => { state.light = e.target.checked; applyLook(ctx); ctx.writeUrl(); });
  $('axes').replaceChildren(...AXES_CODES.map((code) => new Option(
    `${code}: i ${AXES_TEXT[code[0]]}, j ${AXES_TEXT[code[1]]}, k ${AXES_TEXT[code[2]]}${code === 'LPS' ? ' (assumed)' : ''}`, code)));
  $('axes').addEventListener('change', (e) => {
    state.axes = e.target.value;
    view.setVolume(ctx.box(), state.axes, false);
    ctx.resetView();
  });
}

// Wireframe and background as the state says.
export function applyLook(ctx) {
  const { state, view } = ctx;
  view.wireframe = state.wireframe;
  document.body.className = state.light ? 'light' : 'dark';
  view.background = state.light ? 0xf4f5f7 : 0x111418;
}

export function syncView(ctx) {
  const { $, state } = ctx, info = ctx.info();
  $('wireframe').checked = state.wireframe;
  $('light').checked = state.light;
  $('axes-controls').hidden = !info || info.orientation !== 'none';
  $('axes').value = state.axes;
}
