// The page's wiring: file intake (pick or drop), settings, cancel, the server
// fallback button, the form's checks, the synced players and the tabs. Each part lives in its own
// module; the shared state is state.js's one object.
import { $, state } from './state.js';
import { runLocal } from './local-run.js';
import { runOnServer } from './server-run.js';
import { initPlayer } from './player.js';
import { initSettings } from './settings.js';
import { connectLive, disconnectLive } from './live.js';

// --- Input: pick or drop ---------------------------------------------------
$('file').onchange = () => runLocal($('file').files[0]);
$('again').onclick = () => runLocal(state.file);
const drop = $('drop');
for (const ev of ['dragenter', 'dragover']) drop.addEventListener(ev, (e) => { e.preventDefault(); drop.classList.add('over'); });
for (const ev of ['dragleave', 'drop']) drop.addEventListener(ev, () => drop.classList.remove('over'));
drop.addEventListener('drop', (e) => { e.preventDefault(); runLocal(e.dataTransfer.files[0]); });
document.addEventListener('dragover', (e) => e.preventDefault());
document.addEventListener('drop', (e) => { e.preventDefault(); if (e.target !== drop) runLocal(e.dataTransfer.files[0]); });

$('cancel').onclick = () => { if (state.cancel) state.cancel(); state.cancel = null; };
$('server-btn').onclick = () => runOnServer(state.file);

initSettings();
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
