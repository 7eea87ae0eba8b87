// The bench page's script (bench.html; a file of its own, as the server's
// Content-Security-Policy allows no inline script):
// ?frames=/frames/x.rgba&w=320&h=180&n=600&fov=70[&fmt=RGBA|I420][&vf=/frames/x.yuv (I420 frames: also time the VideoFrame path)]
const q = new URLSearchParams(location.search);
if (q.get('frames')) {
  document.body.dataset.state = 'processing';
  const w = new Worker('bench-worker.js', { type: 'module' });
  w.onmessage = (e) => {
    window.benchResult = e.data;
    document.getElementById('out').textContent = JSON.stringify(e.data, null, 1);
    document.body.dataset.state = e.data.error ? 'error' : 'done';
  };
  w.postMessage(Object.fromEntries(q));
}
