// The settings form, built from amc-core's option table (amc-core/src/options.rs,
// through amc-wasm's `options()`): every option of `amc stabilize` with its
// flag, its help (range and default) as the tooltip, its limits and its
// default, so the page and the command line cannot disagree. The page leads
// with a few plain choices (mode, smoothing strength, horizon, output) and
// keeps every other option under "Advanced", named as in the CLI. The values
// are read into the stabilizer's parameters by the core's own setters
// (amc-wasm's `resolveOptions`), as `--name value` and `?name=value` are.
import { $, showError, setPageState } from './state.js';

/** The page's names of the options (the CLI's flag follows); an option missing here is named by its flag. */
export const LABELS = {
  mode: 'Mode', roll: 'Horizon', fov: 'Field of view', readout_ms: 'Readout time',
  n_avg: 'Averaging window', deghost: 'Deghost', antialias: 'Anti-aliasing', interpolation: 'Interpolation',
  n_track: 'Template reset period', margin: 'Margin', zoom: 'Zoom', max_crop: 'Max crop',
  track_width: 'Tracking width', lookahead: 'Lookahead', rate_a: 'Smoothing gain a', rate_b: 'Smoothing gain b',
  roll_rate_a: 'Roll gain a', roll_rate_b: 'Roll gain b', output_width: 'Output width', output_height: 'Output height',
};

/** How some words read in a menu (the value sent is the word). */
const WORD_TEXT = {
  mode: { lock: 'lock (tripod)' },
  roll: { smooth: 'smooth (with pan and tilt)', lock: 'lock (level horizon)', follow: 'follow the camera' },
  zoom: { none: 'none (fixed margin)', static: 'static (two passes)' },
  interpolation: { bicubic: 'bicubic (sharper)' },
};

/** The options the page leads with; every other option is under Advanced. */
export const BASIC = ['mode', 'roll'];

/**
 * Smoothing strength: the view filter's gain is `rate_a + rate_b * |lag|`, so
 * multiplying both by one factor makes the view follow the camera that much
 * faster (a factor under 1: smoother). Each level sets `rate_a` and `rate_b`
 * to the core's defaults (`--rate-a 2 --rate-b 20`) times its factor;
 * `normal` is exactly the defaults. Rates set by hand under Advanced show as
 * `custom`.
 */
export const SMOOTHING = [
  { value: 'light', text: 'light (follows the camera closely)', factor: 2 },
  { value: 'normal', text: 'normal (the CLI\'s default)', factor: 1 },
  { value: 'strong', text: 'strong', factor: 0.5 },
  { value: 'very-strong', text: 'very strong', factor: 0.25 },
];

const spec = (table, name) => table.find((o) => o.name === name);

/** `rate_a` and `rate_b` of a smoothing level, from the table's defaults. */
export function smoothingRates(table, level) {
  const f = SMOOTHING.find((l) => l.value === level).factor;
  return { rate_a: f * spec(table, 'rate_a').default, rate_b: f * spec(table, 'rate_b').default };
}

/** The smoothing level of these rates (numbers; `null`: the default), or `'custom'`. */
export function smoothingLevel(table, rateA, rateB) {
  const a = rateA ?? spec(table, 'rate_a').default, b = rateB ?? spec(table, 'rate_b').default;
  const l = SMOOTHING.find((x) => { const r = smoothingRates(table, x.value); return r.rate_a === a && r.rate_b === b; });
  return l ? l.value : 'custom';
}

/** The field's label: the page's name and the CLI's flag, e.g. "Averaging window (--n-avg)". */
export const labelOf = (o) => `${LABELS[o.name] || o.flag} (--${o.flag})`;

/** The field's tooltip: the CLI's help line, e.g. "--n-avg N: frames averaged ..., 1..=64 (default 6)". */
export const titleOf = (o) => `--${o.flag} ${o.value_name}: ${o.help}`;

/** What the default is, in words: the value, or what the help says it is ("the input width", ...). */
export function defaultText(o) {
  if (o.default !== null) return String(o.default);
  const m = o.help.match(/\(default: (.*)\)\s*$/) || o.help.match(/\(default: ([^)]*)\)/);
  return m ? m[1] : 'unset';
}

/** The values an option allows, as its help writes them ("1..=64", "0 < DEG <= 179 or auto"). */
export function allowedText(o) {
  const a = o.allowed;
  if (a.kind === 'words') return a.words.length > 1 ? `${a.words.slice(0, -1).join(', ')} or ${a.words.at(-1)}` : a.words[0];
  const unit = o.value_name.split('|')[0];
  const range = a.above_min ? `${a.min} < ${unit} <= ${a.max}` : `${a.min}..=${a.max}`;
  return range + (a.kind === 'integer' ? ', whole numbers' : '') + (a.words && a.words.length ? ` or ${a.words.join(', ')}` : '');
}

/**
 * Checks one option's text against the table: `{ value }` (the text to give
 * the core, `null` for an empty field: the default) or `{ error }` naming
 * the field, what it allows and what empty means.
 */
export function checkValue(o, raw) {
  const text = String(raw ?? '').trim();
  if (text === '') return { value: null };
  const a = o.allowed;
  const name = labelOf(o);
  const allowed = `allowed: ${allowedText(o)}; empty: the default, ${defaultText(o)}`;
  const word = text.toLowerCase();
  if ((a.words || []).includes(word)) return { value: word };
  if (a.kind === 'words') return { error: `${name}: ${text} is not one of ${allowedText(o)}.` };
  const v = Number(text);
  const inRange = Number.isFinite(v) && (a.above_min ? v > a.min : v >= a.min) && v <= a.max;
  if (!inRange) return { error: `${name}: ${text} is out of range (${allowed}).` };
  if (a.kind === 'integer' && !Number.isInteger(v)) return { error: `${name}: ${text} is not a whole number (${allowed}).` };
  return { value: text };
}

/** Whether a checked value is the option's default (empty, or equal to it). */
export function isDefault(o, value) {
  if (value == null) return true;
  if (o.default === null) return false;
  return typeof o.default === 'number' ? Number(value) === o.default : value === String(o.default).toLowerCase();
}

// --- The form -----------------------------------------------------------------

/** The option table and the core's reader, once the module is loaded (main.js). */
let TABLE = null, RESOLVE = null;
let markReady;
/** Resolves once the form is built (a clip dropped before waits for it). */
export const formReady = new Promise((r) => { markReady = r; });

function control(o) {
  const a = o.allowed;
  let el;
  if (a.kind === 'words') {
    el = document.createElement('select');
    for (const w of a.words) {
      const opt = document.createElement('option');
      opt.value = w;
      opt.textContent = (WORD_TEXT[o.name] || {})[w] || w;
      el.append(opt);
    }
    el.value = o.default;
  } else {
    el = document.createElement('input');
    if (a.words && a.words.length) {
      // A number or a word (auto): text, checked by checkValue.
      el.type = 'text';
      el.inputMode = 'decimal';
    } else {
      el.type = 'number';
      el.min = String(a.min);
      el.max = String(a.max);
      el.step = a.kind === 'integer' ? '1' : 'any';
    }
    el.value = o.default === null ? '' : String(o.default);
    el.placeholder = o.default === null ? 'default' : String(o.default);
  }
  el.id = o.name;
  el.name = o.name;
  return el;
}

function labelled(forId, text, title, el) {
  const label = document.createElement('label');
  label.htmlFor = forId;
  label.title = title;
  label.append(text, el);
  return label;
}

/**
 * Builds the form from the option table (`options()`) and keeps `resolve`
 * (`resolveOptions`) to read it: the basic options before the Output menu,
 * the smoothing strength after the mode, every other option under Advanced.
 */
export function buildForm(table, resolve) {
  TABLE = table;
  RESOLVE = resolve;
  const basic = $('basic'), before = basic.querySelector('[for=format]'), adv = $('advanced-fields');
  for (const o of table) {
    const el = control(o);
    el.title = titleOf(o);
    const label = labelled(o.name, labelOf(o), titleOf(o), el);
    if (BASIC.includes(o.name)) basic.insertBefore(label, before);
    else adv.append(label);
    // The lens file beside the field of view it overrides, and the gyro (the camera's own motion).
    if (o.name === 'fov') adv.append($('lens').closest('label'), $('gyro').closest('label'));
    if (o.name === 'mode') basic.insertBefore(smoothingControl(table), before);
  }
  for (const o of table) {
    for (const ev of ['input', 'change']) $(o.name).addEventListener(ev, onEdit);
  }
  for (const id of ['rate_a', 'rate_b']) $(id).addEventListener('input', syncSmoothing);
  $('settings').dataset.ready = 'true';
  markReady();
}

function smoothingControl(table) {
  const sel = document.createElement('select');
  sel.id = 'smoothing';
  sel.name = 'smoothing';
  for (const l of [...SMOOTHING, { value: 'custom', text: 'custom (the gains under Advanced)' }]) {
    const opt = document.createElement('option');
    opt.value = l.value;
    opt.textContent = l.text;
    sel.append(opt);
  }
  sel.value = 'normal';
  const a = spec(table, 'rate_a').default, b = spec(table, 'rate_b').default;
  const title = `How smooth the view is: sets --rate-a and --rate-b (under Advanced) to the CLI's defaults, ${a} and ${b}, ` +
    `times ${SMOOTHING.map((l) => `${l.factor} (${l.value.replace('-', ' ')})`).join(', ')}; the view filter's gain is ` +
    'rate_a + rate_b × the view\'s lag, so smaller gains follow the camera more slowly and the view is smoother. ' +
    'custom: the gains set by hand under Advanced';
  sel.title = title;
  sel.addEventListener('change', () => {
    if (sel.value === 'custom') return;
    const r = smoothingRates(table, sel.value);
    $('rate_a').value = String(r.rate_a);
    $('rate_b').value = String(r.rate_b);
    onEdit();
  });
  return labelled('smoothing', 'Smoothing', title, sel);
}

/** The smoothing menu follows the gains typed under Advanced. */
function syncSmoothing() {
  const num = (id) => { const r = checkValue(spec(TABLE, id), $(id).value); return r.value == null ? null : Number(r.value); };
  $('smoothing').value = smoothingLevel(TABLE, num('rate_a'), num('rate_b'));
}

/**
 * The form's settings: `{ values, params, fov, readout, format, gyro,
 * lensFile, errors }` (`gyro`: `'auto'`, the clip's own track, or `'off'`). `values` maps each option to its checked text (`null`: the
 * default); `params` (the core's StabilizerParams, without the shutter),
 * `fov` (degrees or `'auto'`) and `readout` (milliseconds, `'auto'` or
 * `null`: the lens file's, else 0) are the core's reading of them.
 * `errors` lists `{ id, message }` for every bad field (then `params` is
 * not set).
 */
export function settings() {
  const values = {}, errors = [];
  for (const o of TABLE) {
    const el = $(o.name);
    // A number field holding something that is not a number reads as empty.
    const r = el.validity && el.validity.badInput
      ? { error: `${labelOf(o)}: not a number (allowed: ${allowedText(o)}; empty: the default, ${defaultText(o)}).` }
      : checkValue(o, el.value);
    if (r.error) errors.push({ id: o.name, message: r.error });
    else values[o.name] = r.value;
  }
  const out = { values, format: $('format').value, gyro: $('gyro').value, lensFile: $('lens').files[0] || null, errors };
  if (errors.length) return out;
  try {
    Object.assign(out, RESOLVE(JSON.stringify(values)));
  } catch (e) {
    // The core refused a combination the field checks let through: name its option.
    const o = TABLE.find((x) => new RegExp(`\\b${x.name}\\b`).test(e.message)) || TABLE[0];
    errors.push({ id: o.name, message: `${labelOf(o)}: ${e.message}` });
  }
  return out;
}

/** Marks bad fields (aria-invalid) and shows their messages under the form; returns them joined. */
export function showFieldErrors(errors) {
  for (const o of TABLE || []) $(o.name).setAttribute('aria-invalid', String(errors.some((e) => e.id === o.name)));
  const box = $('form-error');
  box.textContent = errors.map((e) => e.message).join('\n');
  box.hidden = errors.length === 0;
  // A bad field under the fold: open it so the field can be seen.
  if (errors.some((e) => !BASIC.includes(e.id))) $('advanced').open = true;
  return box.textContent;
}

/**
 * Refuses to start with bad settings: marks the fields, and says so in the
 * page's error box (naming the fields; the ranges are under the form).
 */
export function refuseSettings(errors) {
  showFieldErrors(errors);
  const names = errors.map((e) => labelOf(spec(TABLE, e.id)));
  showError(`Not started: ${names.join(', ')} out of range; see the message under the settings.`);
  $('error').dataset.source = 'settings';
  $(errors[0].id).focus();
}

/** Checks the form as the user types; clears a settings refusal once all is well. */
function onEdit() {
  const { errors } = settings();
  showFieldErrors(errors);
  if (!errors.length && !$('error').hidden && $('error').dataset.source === 'settings') {
    $('error').hidden = true;
    $('status-text').textContent = 'Settings fixed: pick a clip, or press Stabilize again.';
    setPageState('idle');
  }
}

/** The lens argument of the WASM stabilizer: the lens file's text, or the field of view (degrees or `'auto'`). */
export async function lensArg(s) {
  return s.lensFile ? await s.lensFile.text() : s.fov;
}

/**
 * The query of `POST /jobs` for these settings (`s.values`, checked) and
 * the option table: the mode and the format always, every other option only
 * where it is not the default (the server's defaults are the same table's),
 * and no field of view with a lens file (the file is sent).
 */
export function serverQuery(s, table = TABLE) {
  const q = new URLSearchParams();
  for (const o of table) {
    const v = s.values[o.name];
    if (o.name === 'fov' && s.lensFile) continue;
    if (o.name === 'mode' ? v == null : isDefault(o, v)) continue;
    q.set(o.name, v);
  }
  q.set('format', s.format);
  return q;
}
