// The page's one state object, the DOM lookup, and the page-level state
// transitions (`<body data-state>`: idle, processing, done, error) that the
// tests and tools read.
export const $ = (id) => document.getElementById(id);

export const state = {
  /** The clip last picked or dropped (Stabilize again, the server fallback). */
  file: null,
  /** The in-browser run's Web Worker, while one exists. */
  worker: null,
  /** Cancels the running work (worker or server job). */
  cancel: null,
  /** Per-frame telemetry the clip plot shows. */
  telemetry: null,
  /** Object URLs of the shown result, revoked when the next run starts. */
  urls: [],
  /** The Live tab's WebSocket and its recent telemetry messages. */
  ws: null,
  liveHist: [],
};

export function setPageState(s) {
  document.body.dataset.state = s;
  $('cancel').hidden = s !== 'processing';
}

export function showError(msg) {
  $('error').textContent = msg;
  $('error').hidden = false;
  $('status-text').textContent = 'Failed.';
  setPageState('error');
}

export function newUrl(blob) {
  const u = URL.createObjectURL(blob);
  state.urls.push(u);
  return u;
}

/** Clears the previous result and messages before a new run. */
export function reset() {
  for (const u of state.urls) URL.revokeObjectURL(u);
  state.urls = [];
  $('error').hidden = true;
  $('unsupported').hidden = true;
  $('result').hidden = true;
  $('progress').value = 0;
  $('progress').removeAttribute('max');
  $('progress').max = 1;
}
