// The page's wiring: file intake (pick, drop, or Enter on the drop zone),
// cancel, the server fallback button, the settings form (built from the
// core's option table, which amc-wasm gives), the synced players and the
// tabs. Each part lives in its own module; the shared state is state.js's
// one object.
import init, { options, resolveOptions } from './pkg/amc_wasm.js';
import { $, state, showError } from './state.js';
import { runLocal } from './local-run.js';
import { runOnServer } from './server-run.js';
import { initPlayer } from './player.js';
import { buildForm } from './settings.js';
import { readableList, EXTENSIONS } from './formats.js';
import { connectLive, disconnectLive } from './live.js';
import { initAuth } from './auth.js';

// --- Input: pick or drop ---------------------------------------------------
// The containers the page reads, named once (formats.js); anything else is offered to the server.
$('drop-formats').textContent = readableList();
$('file').accept = ['video/*', ...EXTENSIONS].join(',');
$('file').onchange = () => runLocal($('file').files[0]);
$('again').onclick = () => runLocal(state.file);
const drop = $('drop');
for (const ev of ['dragenter', 'dragover']) drop.addEventListener(ev, (e) => { e.preventDefault(); drop.classList.add('over'); });
for (const ev of ['dragleave', 'drop']) drop.addEventListener(ev, () => drop.classList.remove('over'));
drop.addEventListener('drop', (e) => { e.preventDefault(); runLocal(e.dataTransfer.files[0]); });
drop.addEventListener('keydown', (e) => { if (e.target === drop && (e.key === 'Enter' || e.key === ' ')) { e.preventDefault(); $('file').click(); } });
document.addEventListener('dragover', (e) => e.preventDefault());
// A drop elsewhere on the page also counts; the drop zone handles its own.
document.addEventListener('drop', (e) => { e.preventDefault(); if (!drop.contains(e.target)) runLocal(e.dataTransfer.files[0]); });

$('cancel').onclick = () => { if (state.cancel) state.cancel(); state.cancel = null; };
$('server-btn').onclick = () => runOnServer(state.file);

// The settings form: every option of the CLI, from the core's table. It is never
// submitted (Enter in a field would reload the page); wired here, not by an
// inline handler, which the server's Content-Security-Policy forbids.
$('settings').addEventListener('submit', (e) => e.preventDefault());
initAuth();
init().then(() => buildForm(options(), resolveOptions))
  .catch((e) => showError(`The page could not load its WebAssembly module (amc-wasm): ${e && e.message ? e.message : e}`));
initPlayer();

// --- Tabs: the clip, the live feed ------------------------------------------
for (const b of document.querySelectorAll('.tab')) {
  b.onclick = () => {
    for (const o of document.querySelectorAll('.tab')) o.classList.toggle('active', o === b);
    $('panel-clip').hidden = b.dataset.tab !== 'clip';
    $('panel-live').hidden = b.dataset.tab !== 'live';
    if (b.dataset.tab === 'live') connectLive(); else disconnectLive();
  };
}
if (location.hash === '#live') $('tab-live').click();
