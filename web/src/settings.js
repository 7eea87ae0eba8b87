// The settings form: stabilizer parameters (amc-core's StabilizerParams), lens, output format.
import { $ } from './state.js';

export function settings() {
  const num = (id) => Number($(id).value);
  return {
    params: {
      view: { mode: $('mode').value, rate_a: num('rate_a'), rate_b: num('rate_b'), lookahead: num('lookahead') },
      render: { n_avg: num('n_avg'), margin: num('margin') },
    },
    fov: num('fov'),
    format: $('format').value,
  };
}

/** The lens argument of the WASM Stabilizer: the lens file's text, or the field of view. */
export async function lensArg(s) {
  const f = $('lens').files[0];
  return f ? await f.text() : s.fov;
}
