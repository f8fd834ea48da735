// keys.js: keyboard shortcuts for the common actions and the help overlay (? or the ?
// button) that lists them. Keys act on the view unless a text field or menu has the focus.

export const SHORTCUTS = [
  ['A P L R S I', 'anterior, posterior, left, right, superior, inferior view'],
  ['0 or Home', 'reset the view: anterior, framed on the surfaces'],
  ['N / Shift+N', 'next / previous suggested level'],
  ['W', 'wireframe on or off'],
  ['B', 'light or dark background'],
  ['C', 'clipping plane on or off'],
  ['M', 'measure area and enclosed volume'],
  ['Esc', 'cancel loading; close this help'],
  ['?', 'this help'],
];

const PRESET_KEYS = { a: 'anterior', p: 'posterior', l: 'left', r: 'right', s: 'superior', i: 'inferior' };

export function mountKeys(ctx) {
  const help = ctx.$('help');
  const title = document.createElement('h2');
  title.textContent = 'isoserve: keys and mouse';
  const table = document.createElement('table');
  for (const [keys, what] of [...SHORTCUTS, ['left drag', 'turn about the patient\'s long axis and tilt'],
    ['right drag / Shift+drag', 'move'], ['wheel', 'zoom'], ['click on the histogram', 'set the level there']]) {
    const tr = document.createElement('tr');
    const k = document.createElement('td');
    for (const part of keys.split(' / ')) {
      const kbd = document.createElement('kbd');
      kbd.textContent = part;
      k.append(kbd, ' ');
    }
    const w = document.createElement('td');
    w.textContent = what;
    tr.append(k, w);
    table.append(tr);
  }
  const note = document.createElement('p');
  note.textContent = 'The link in the address bar keeps the whole view: camera, surfaces, clipping, colours, the segments shown.';
  help.replaceChildren(title, table, note);
  help.addEventListener('click', () => toggleHelp(ctx, false));
  ctx.$('help-button').addEventListener('click', () => toggleHelp(ctx));
  document.addEventListener('keydown', (e) => onKey(ctx, e));
}

export function toggleHelp(ctx, show) {
  const help = ctx.$('help');
  help.hidden = show === undefined ? !help.hidden : !show;
}

function onKey(ctx, e) {
  if (e.ctrlKey || e.metaKey || e.altKey) return;
  const t = e.target;
  if (t instanceof HTMLSelectElement || (t instanceof HTMLInputElement && !['range', 'checkbox', 'color'].includes(t.type))) return;
  const key = e.key.length === 1 ? e.key.toLowerCase() : e.key;
  if (e.key === '?') toggleHelp(ctx);
  else if (key === 'Escape') { toggleHelp(ctx, false); ctx.loader.cancel(); }
  else if (PRESET_KEYS[key]) ctx.preset(PRESET_KEYS[key]);
  else if (key === '0' || key === 'Home') ctx.resetView();
  else if (key === 'n') ctx.nextLevel(e.shiftKey ? -1 : 1);
  else if (key === 'w') { ctx.$('wireframe').click(); }
  else if (key === 'b') { ctx.$('light').click(); }
  else if (key === 'c') { ctx.$('clip').click(); }
  else if (key === 'm') { ctx.$('measure').click(); }
  else return;
  e.preventDefault();
}
