// The settings form: amc-core's StabilizerParams (the fields this page
// offers), the lens and the output format. Each number field is checked in
// the page against the range amc-core's `validate()` enforces, so a bad value
// gets a message naming the field before any work starts; an empty field
// means the default.
import { $, showError, setPageState } from './state.js';

/**
 * The number fields: input id, label, the parameter's name in amc-core, its
 * default, range (inclusive, except the minimum when `openMin`), whole numbers
 * only, unit. Ranges: amc-core's option table (amc-core/src/options.rs) and the
 * params' validate(): n_avg, deghost, margin, max_crop, rate_a, rate_b, lookahead, readout_ms, and fov (0 < DEG <= 179).
 * `words`: words accepted instead of a number; `unset`: an empty field is not
 * sent (readout_ms: the lens file's readout applies, else 0).
 */
export const FIELDS = [
  { id: 'n_avg', label: 'Averaging window', def: 6, min: 1, max: 64, int: true, unit: 'frames' },
  { id: 'deghost', label: 'Deghost', def: 0, min: 0, max: 64, unit: 'levels of 255' },
  { id: 'margin', label: 'Margin', def: 0.125, min: 0, max: 0.45, unit: 'share of each side' },
  { id: 'max_crop', label: 'Max crop', def: 0.15, min: 0, max: 0.5, unit: 'share of the width' },
  { id: 'rate_a', label: 'Smoothing a', def: 2, min: 0, max: 1000, unit: 'per second' },
  { id: 'rate_b', label: 'Smoothing b', def: 20, min: 0, max: 10000, unit: 'per second per radian' },
  { id: 'lookahead', label: 'Lookahead', def: 0, min: 0, max: 600, int: true, unit: 'frames' },
  { id: 'fov', label: 'Field of view', def: 70, min: 0, max: 179, openMin: true, unit: 'degrees' },
  { id: 'readout_ms', label: 'Readout', def: 0, min: 0, max: 100, unit: 'milliseconds', words: ['auto'], unset: true },
];


const range = (f) => (f.openMin ? `${f.min} < value <= ${f.max}` : `${f.min}..=${f.max}`) + ` ${f.unit}`;

/** Reads one field: its value, or an error message naming it and its range. */
function readField(f) {
  const el = $(f.id);
  const text = el.value.trim();
  const name = `${f.label} (${f.id})`;
  const words = f.words ? ` or ${f.words.join(', ')}` : '';
  const empty = f.unset ? `the lens file's, else ${f.def}` : `the default, ${f.def}`;
  const allowed = `allowed: ${range(f)}${words}${f.int ? ', whole numbers' : ''}; empty means ${empty}`;
  if (el.validity && el.validity.badInput) return { error: `${name}: not a number (${allowed}).` };
  if (text === '') return { value: f.unset ? null : f.def };
  if (f.words && f.words.includes(text.toLowerCase())) return { value: text.toLowerCase() };
  const v = Number(text);
  const inRange = Number.isFinite(v) && (f.openMin ? v > f.min && v <= f.max : v >= f.min && v <= f.max);
  if (!inRange) return { error: `${name}: ${text} is out of range (${allowed}).` };
  if (f.int && !Number.isInteger(v)) return { error: `${name}: ${text} is not a whole number (${allowed}).` };
  return { value: v };
}

/**
 * The form's settings: `{ params, fov, readout, format, lensFile, errors }`;
 * `errors` lists `{ id, message }` for every bad field (then `params` must
 * not be used). `readout` is the readout field: milliseconds (also in
 * `params.shutter`), `'auto'` (the worker estimates it first) or `null`
 * (empty: the lens file's readout, else 0).
 */
export function settings() {
  const values = {}, errors = [];
  for (const f of FIELDS) {
    const r = readField(f);
    if (r.error) errors.push({ id: f.id, message: r.error });
    else values[f.id] = r.value;
  }
  return {
    params: {
      view: {
        mode: $('mode').value, roll: $('roll').value,
        rate_a: values.rate_a, rate_b: values.rate_b, lookahead: values.lookahead,
      },
      render: {
        n_avg: values.n_avg, margin: values.margin, deghost: values.deghost,
        interpolation: $('interpolation').value,
      },
      framing: { zoom: $('zoom').value, max_crop: values.max_crop },
      ...(typeof values.readout_ms === 'number' ? { shutter: { readout_ms: values.readout_ms } } : {}),
    },
    fov: values.fov,
    readout: values.readout_ms ?? null,
    format: $('format').value,
    lensFile: $('lens').files[0] || null,
    errors,
  };
}

/** Marks bad fields (aria-invalid) and shows their messages under the form; returns them joined. */
export function showFieldErrors(errors) {
  for (const f of FIELDS) $(f.id).setAttribute('aria-invalid', String(errors.some((e) => e.id === f.id)));
  const box = $('form-error');
  box.textContent = errors.map((e) => e.message).join('\n');
  box.hidden = errors.length === 0;
  return box.textContent;
}

/**
 * Refuses to start with bad settings: marks the fields, and says so in the
 * page's error box (naming the fields; the ranges are under the form).
 */
export function refuseSettings(errors) {
  showFieldErrors(errors);
  const names = errors.map((e) => { const f = FIELDS.find((x) => x.id === e.id); return `${f.label} (${f.id})`; });
  showError(`Not started: ${names.join(', ')} out of range; see the message under the settings.`);
  $('error').dataset.source = 'settings';
  $(errors[0].id).focus();
}

/** Checks the form as the user types; clears a settings refusal once all is well. */
export function initSettings() {
  for (const f of FIELDS) {
    $(f.id).addEventListener('input', () => {
      const { errors } = settings();
      showFieldErrors(errors);
      if (!errors.length && !$('error').hidden && $('error').dataset.source === 'settings') {
        $('error').hidden = true;
        $('status-text').textContent = 'Settings fixed: pick a clip, or press Stabilize again.';
        setPageState('idle');
      }
    });
  }
}

/** The lens argument of the WASM Stabilizer: the lens file's text, or the field of view. */
export async function lensArg(s) {
  return s.lensFile ? await s.lensFile.text() : s.fov;
}

/**
 * The query of `POST /jobs` for these settings. `rate_a`/`rate_b` are sent
 * only when they differ from the defaults, so older servers (which do not
 * know them) keep working with the default smoothing.
 */
export function serverQuery(s) {
  const def = Object.fromEntries(FIELDS.map((f) => [f.id, f.def]));
  const q = new URLSearchParams({
    mode: s.params.view.mode, n_avg: s.params.render.n_avg, margin: s.params.render.margin,
    lookahead: s.params.view.lookahead, format: s.format,
  });
  if (!s.lensFile) q.set('fov', s.fov);
  if (s.params.view.rate_a !== def.rate_a) q.set('rate_a', s.params.view.rate_a);
  if (s.params.view.rate_b !== def.rate_b) q.set('rate_b', s.params.view.rate_b);
  // Sent only when set, like the rates (older servers do not know it).
  const roll = s.params.view.roll;
  if (roll && roll !== 'smooth') q.set('roll', roll);
  // Sent only when not the defaults, like the rates (older servers do not know them).
  const { zoom, max_crop: maxCrop } = s.params.framing || {};
  if (zoom && zoom !== 'auto') q.set('zoom', zoom);
  if (maxCrop != null && maxCrop !== def.max_crop) q.set('max_crop', maxCrop);
  // Sent only when not the default (older servers do not know it).
  const deghost = s.params.render.deghost;
  if (deghost != null && deghost !== def.deghost) q.set('deghost', deghost);
  // Sent only when not the default (older servers do not know it).
  const interpolation = s.params.render.interpolation;
  if (interpolation && interpolation !== 'bilinear') q.set('interpolation', interpolation);
  // Sent only when set (empty: the lens file's readout, else 0; older servers do not know it).
  if (s.readout != null) q.set('readout_ms', s.readout);
  return q;
}
