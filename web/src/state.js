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
  /** Counts runs: late answers of an earlier run (a server job, a worker) compare against it. */
  run: 0,
  /** Rows the clip plot draws (telemetry.js). */
  plotRows: null,
  /** Width of the input clip in pixels (the compare view's crop). */
  inputWidth: 0,
  /** Object URLs of the shown result, revoked when the next run starts. */
  urls: [],
  /** The Live tab's WebSocket and its recent telemetry messages. */
  ws: null,
  /** Whether the Live tab wants the feed (connecting, connected or waiting to reconnect). */
  liveOn: false,
  liveHist: [],
};

export function setPageState(s) {
  document.body.dataset.state = s;
  $('cancel').hidden = s !== 'processing';
}

export function showError(msg) {
  $('error').textContent = msg;
  delete $('error').dataset.source;
  $('error').hidden = false;
  $('status-text').textContent = 'Failed.';
  setPageState('error');
}

export function newUrl(blob) {
  const u = URL.createObjectURL(blob);
  state.urls.push(u);
  return u;
}

/** Clears the previous result and messages before a new run; returns the new run's number. */
export function reset() {
  state.run++;
  for (const u of state.urls) URL.revokeObjectURL(u);
  state.urls = [];
  $('error').hidden = true;
  $('unsupported').hidden = true;
  $('result').hidden = true;
  $('download-csv').hidden = true;
  state.plotRows = null;
  $('progress').value = 0;
  $('progress').removeAttribute('max');
  $('progress').max = 1;
  return state.run;
}
