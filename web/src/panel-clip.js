// panel-clip.js: the panel's clipping section: a plane across one of the patient's axes
// (left-right, front-back, foot-head) at a place along the volume, keeping either side.
// Moving it changes a uniform only, and the view draws at most once per animation frame
// (with the previews while the slider is held, when full frames are slow).
export function mountClip(ctx) {
  const { $, state } = ctx;
  const changed = () => {
    state.clip = { on: $('clip').checked, axis: $('clip-axis').value, at: Number($('clip-at').value) / 1000,
      flip: $('clip-flip').checked };
    applyClip(ctx);
    syncClip(ctx);
    ctx.writeUrl();
  };
  for (const id of ['clip', 'clip-axis', 'clip-flip']) $(id).addEventListener('change', changed);
  $('clip-at').addEventListener('input', changed);
  // While the slider is held the view may draw previews (view.js); the full frame follows
  // its release.
  $('clip-at').addEventListener('pointerdown', () => { ctx.view.holding = true; });
  for (const type of ['pointerup', 'pointercancel', 'change']) $('clip-at').addEventListener(type, () => { ctx.view.holding = false; ctx.view.moving(); });
}

export function applyClip(ctx) {
  const c = ctx.state.clip;
  ctx.view.clip(c.on, c.axis, c.at, c.flip);
}

export function syncClip(ctx) {
  const { $, state } = ctx, c = state.clip;
  $('clip').checked = c.on;
  $('clip-axis').value = c.axis;
  $('clip-at').value = Math.round(c.at * 1000);
  $('clip-flip').checked = c.flip;
  const box = ctx.view.bounds, a = 'xyz'.indexOf(c.axis);
  $('clip-at-value').textContent = box ? `${(box.min.getComponent(a) + c.at * (box.max.getComponent(a) - box.min.getComponent(a))).toFixed(1)} mm` : '';
}
