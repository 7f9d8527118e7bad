// loosefit view: plays the panels of window.LOOSEFIT_MANIFEST side by side (three.js), with the per-vertex
// error heat map, its legend and the per-frame metric plot (uPlot). The data format is described in
// loosefit/viz/viewer.py. Classic script (no modules) so that an exported page also opens from disk.
(function () {
  'use strict';
  const M = window.LOOSEFIT_MANIFEST;
  const $ = (id) => document.getElementById(id);
  const PALETTE = ['#4fc3f7', '#ffb74d', '#81c784', '#e57373', '#ba68c8', '#fff176', '#a1887f', '#90a4ae'];
  const CURSOR_COLOR = '#ff3b30';

  // The public handle used by the tests and the benchmark (window.loosefitViewer).
  const viewer = { ready: false, frame: 0, numFrames: M.numFrames, plotCursorFrame: null, timing: {} };
  window.loosefitViewer = viewer;

  function loadScript(src) {
    return new Promise((resolve, reject) => {
      const s = document.createElement('script');
      s.src = src;
      s.onload = resolve;
      s.onerror = () => reject(new Error('cannot load ' + src));
      document.head.appendChild(s);
    });
  }

  // Base64 to bytes: the browser's own decoder where it has one, else atob.
  function base64Bytes(text) {
    if (typeof Uint8Array.fromBase64 === 'function') return Uint8Array.fromBase64(text);
    const bin = atob(text);
    const out = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) out[i] = bin.charCodeAt(i);
    return out;
  }

  // The binary data: fetched from the server, or assembled from the export's base64 chunk scripts.
  async function loadData() {
    if (M.data.binary) {
      const r = await fetch(M.data.binary);
      if (!r.ok) throw new Error('cannot load ' + M.data.binary + ': HTTP ' + r.status);
      return r.arrayBuffer();
    }
    const names = [];
    for (let i = 0; i < M.data.chunks; i++) names.push('data/chunk-' + String(i).padStart(3, '0') + '.js');
    await Promise.all(names.map(loadScript));
    viewer.timing.chunkScriptsMs = performance.now();
    const bytes = new Uint8Array(M.byteLength);
    let offset = 0;
    for (let i = 0; i < M.data.chunks; i++) {
      const part = base64Bytes(window.LOOSEFIT_CHUNKS[i]);
      window.LOOSEFIT_CHUNKS[i] = null;
      bytes.set(part, offset);
      offset += part.length;
    }
    if (offset !== M.byteLength) throw new Error('data chunks hold ' + offset + ' bytes, expected ' + M.byteLength);
    return bytes.buffer;
  }

  function view(buffer, index) {
    const b = M.buffers[index];
    const Type = b.dtype === 'uint32' ? Uint32Array : Float32Array;
    return new Type(buffer, b.offset, b.bytes / 4);
  }

  // Heat map colour of an error value: entry floor((e - lo) / (hi - lo) * N), clipped (matplotlib's rule).
  const LUT = M.colormap;
  const NLUT = LUT.length / 3;
  function lutIndex(e) {
    const [lo, hi] = M.errorRange;
    return Math.min(NLUT - 1, Math.max(0, Math.floor((e - lo) / (hi - lo) * NLUT)));
  }

  let renderer, camera, controls, panels, plot;
  let heatOn = true;

  function buildPanels(buffer) {
    return M.panels.map((p) => {
      const scene = new THREE.Scene();
      scene.background = new THREE.Color(0x303238);
      scene.add(new THREE.HemisphereLight(0xffffff, 0x404040, 0.75));
      const sun = new THREE.DirectionalLight(0xffffff, 0.55);
      sun.position.set(1.5, -3, 4);
      scene.add(sun);
      const tracks = p.tracks.map((t) => {
        const verts = view(buffer, t.verts);
        const faces = view(buffer, t.faces);
        const errors = t.errors === null ? null : view(buffer, t.errors);
        const geometry = new THREE.BufferGeometry();
        geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(t.numVerts * 3), 3));
        geometry.setIndex(new THREE.BufferAttribute(faces, 1));
        if (errors) geometry.setAttribute('color', new THREE.BufferAttribute(new Float32Array(t.numVerts * 3), 3));
        const solid = new THREE.Color(t.color[0], t.color[1], t.color[2]);
        const material = new THREE.MeshLambertMaterial({ color: solid, side: THREE.DoubleSide });
        const mesh = new THREE.Mesh(geometry, material);
        mesh.frustumCulled = false;
        scene.add(mesh);
        return { info: t, verts, errors, geometry, material, solid, mesh, shownFrame: -1 };
      });
      return { info: p, scene, tracks };
    });
  }

  function frameOf(track, k) { return Math.min(k, track.info.numFrames - 1); }

  function updateTrack(track, k) {
    const f = frameOf(track, k);
    const n = track.info.numVerts * 3;
    const pos = track.geometry.attributes.position;
    pos.array.set(track.verts.subarray(f * n, (f + 1) * n));
    pos.needsUpdate = true;
    track.geometry.computeVertexNormals();
    // an input longer than the reference has no error past the reference's end: its plain colour there
    const heat = heatOn && track.errors !== null && k < track.info.errorFrames;
    if (heat) {
      const col = track.geometry.attributes.color;
      const V = track.info.numVerts;
      const e = track.errors.subarray(k * V, (k + 1) * V);
      for (let i = 0; i < V; i++) {
        const j = 3 * lutIndex(e[i]);
        col.array[3 * i] = LUT[j] / 255;
        col.array[3 * i + 1] = LUT[j + 1] / 255;
        col.array[3 * i + 2] = LUT[j + 2] / 255;
      }
      col.needsUpdate = true;
    }
    if (track.material.vertexColors !== heat) {
      track.material.vertexColors = heat;
      track.material.color.copy(heat ? new THREE.Color(1, 1, 1) : track.solid);
      track.material.needsUpdate = true;
    }
    track.shownFrame = f;
  }

  function fitCamera() {
    const box = new THREE.Box3();
    const v = new THREE.Vector3();
    for (const p of panels) for (const t of p.tracks) {
      const a = t.verts;
      const step = Math.max(1, Math.floor(a.length / 3 / 200000)) * 3;
      for (let i = 0; i < a.length; i += step) box.expandByPoint(v.set(a[i], a[i + 1], a[i + 2]));
    }
    const center = box.getCenter(new THREE.Vector3());
    const radius = Math.max(1e-3, box.getSize(new THREE.Vector3()).length() / 2);
    camera = new THREE.PerspectiveCamera(30, 1, radius / 100, radius * 100);
    camera.up.set(0, 0, 1);
    const dir = new THREE.Vector3(0.45, -1.0, 0.3).normalize();
    // Far enough for the box's height to fit the vertical field of view of a panel and its horizontal
    // diagonal the horizontal one, measured from the box's near side.
    const canvas = renderer.domElement;
    const aspect = canvas.clientWidth / panels.length / Math.max(1, canvas.clientHeight);
    const size = box.getSize(new THREE.Vector3());
    const halfV = (30 / 2) * Math.PI / 180;
    const halfH = Math.atan(Math.tan(halfV) * aspect);
    const halfWidth = Math.hypot(size.x, size.y) / 2;
    const dist = 1.08 * (Math.max(size.z / 2 / Math.tan(halfV), halfWidth / Math.tan(halfH)) + halfWidth);
    camera.position.copy(center).addScaledVector(dir, dist);
    controls = new THREE.OrbitControls(camera, renderer.domElement);
    controls.target.copy(center);
    controls.update();
    controls.addEventListener('change', render);
  }

  function render() {
    const canvas = renderer.domElement;
    const w = canvas.clientWidth, h = canvas.clientHeight;
    const size = renderer.getSize(new THREE.Vector2());
    if (size.x !== w || size.y !== h) renderer.setSize(w, h, false);
    const n = panels.length;
    panels.forEach((p, i) => {
      const x0 = Math.round(i * w / n), x1 = Math.round((i + 1) * w / n);
      renderer.setViewport(x0, 0, x1 - x0, h);
      renderer.setScissor(x0, 0, x1 - x0, h);
      camera.aspect = (x1 - x0) / Math.max(1, h);
      camera.updateProjectionMatrix();
      renderer.render(p.scene, camera);
    });
    viewer.renderedFrame = viewer.frame;
  }

  function setFrame(k) {
    k = Math.max(0, Math.min(M.numFrames - 1, Math.round(k)));
    viewer.frame = k;
    for (const p of panels) for (const t of p.tracks) updateTrack(t, k);
    $('scrub').value = String(k);
    $('frame-label').textContent = 'frame ' + k + ' / ' + (M.numFrames - 1);
    if (plot) plot.redraw(false, false);
    render();
  }

  // Play: advance by fps x speed frames per second of wall time, looping.
  let playing = false, speed = 1, last = null, acc = 0;
  function tick(now) {
    if (!playing) return;
    if (last !== null) {
      acc += (now - last) / 1000 * M.fps * speed;
      const steps = Math.floor(acc);
      if (steps > 0) { acc -= steps; setFrame((viewer.frame + steps) % M.numFrames); }
    }
    last = now;
    requestAnimationFrame(tick);
  }
  function play() { if (!playing) { playing = true; last = null; acc = 0; $('play').textContent = 'pause'; requestAnimationFrame(tick); } }
  function pause() { playing = false; $('play').textContent = 'play'; }

  function drawLegend() {
    const hasErrors = M.panels.some((p) => p.tracks.some((t) => t.errors !== null));
    if (!hasErrors) { $('legend').style.display = 'none'; return; }
    const ctx = $('legend-bar').getContext('2d');
    for (let j = 0; j < NLUT; j++) {
      ctx.fillStyle = 'rgb(' + LUT[3 * j] + ',' + LUT[3 * j + 1] + ',' + LUT[3 * j + 2] + ')';
      ctx.fillRect(j * 256 / NLUT, 0, 256 / NLUT, 14);
    }
    const [lo, hi] = M.errorRange;
    const fmt = (x) => (Math.abs(x) >= 100 ? x.toFixed(0) : x.toPrecision(3));
    $('legend-low').textContent = fmt(lo);
    $('legend-mid').textContent = fmt((lo + hi) / 2);
    $('legend-high').textContent = (M.errorMax > hi ? '\u2265 ' : '') + fmt(hi);
    $('legend-ref').textContent = M.panels[0].title;
  }

  function buildPlot() {
    const T = M.numFrames;
    const x = Array.from({ length: T }, (_, i) => i);
    const series = [{ label: 'frame' }];
    const data = [x];
    const scales = new Set();
    M.panels.forEach((p, i) => {
      for (const [key, scale, label, dash] of [['rmse_mm', 'mm', 'RMSE mm', undefined], ['collision_pct', '%', 'collision %', [6, 4]]]) {
        const values = p.metrics[key];
        if (!values) continue;
        scales.add(scale);
        series.push({ label: p.title + ' ' + label, scale, stroke: PALETTE[i % PALETTE.length], width: 1.5, dash,
          spanGaps: true,
          value: (u, v) => (v === null || v === undefined ? '-' : v.toFixed(2)) });
        data.push(x.map((k) => (k < values.length ? values[k] : null)));
      }
    });
    if (series.length === 1) { $('plot').style.display = 'none'; return null; }
    const axes = [{ stroke: '#ccc', grid: { stroke: '#333' }, label: 'frame' }];
    if (scales.has('mm')) axes.push({ scale: 'mm', stroke: '#ccc', grid: { stroke: '#333' }, label: 'RMSE (mm)' });
    if (scales.has('%')) axes.push({ scale: '%', side: 1, stroke: '#ccc', grid: { show: false }, label: 'collision (%)' });
    const opts = {
      width: 360, height: 260, series, axes,
      // Metric axes start at zero, so that a nearly constant curve looks constant.
      scales: {
        x: { time: false },
        mm: { range: (u, lo, hi) => [0, hi > 0 ? hi * 1.1 : 1] },
        '%': { range: (u, lo, hi) => [0, hi > 0 ? Math.min(100, hi * 1.1) : 1] },
      },
      cursor: { drag: { x: false, y: false } },
      hooks: {
        draw: [(u) => {
          const cx = Math.round(u.valToPos(viewer.frame, 'x', true));
          const ctx = u.ctx;
          ctx.save();
          ctx.setLineDash([]);
          ctx.strokeStyle = CURSOR_COLOR;
          ctx.lineWidth = 2 * (window.devicePixelRatio || 1);
          ctx.beginPath();
          ctx.moveTo(cx, u.bbox.top);
          ctx.lineTo(cx, u.bbox.top + u.bbox.height);
          ctx.stroke();
          ctx.restore();
          viewer.plotCursorFrame = viewer.frame;
          viewer.plotCursorX = cx;
        }],
      },
    };
    const u = new uPlot(opts, data, $('plot'));
    u.over.addEventListener('click', () => {
      if (u.cursor.left >= 0) setFrame(u.posToVal(u.cursor.left, 'x'));
    });
    return u;
  }

  function wireControls() {
    const scrub = $('scrub');
    scrub.max = String(M.numFrames - 1);
    scrub.addEventListener('input', () => { pause(); setFrame(Number(scrub.value)); });
    $('play').addEventListener('click', () => (playing ? pause() : play()));
    $('speed').addEventListener('change', (e) => { speed = Number(e.target.value); });
    $('heat').addEventListener('change', (e) => { heatOn = e.target.checked; setFrame(viewer.frame); });
    window.addEventListener('resize', render);
    window.addEventListener('keydown', (e) => {
      if (e.target.tagName === 'INPUT' || e.target.tagName === 'SELECT') return;
      if (e.code === 'Space') { e.preventDefault(); playing ? pause() : play(); }
      if (e.code === 'ArrowRight') { pause(); setFrame(viewer.frame + 1); }
      if (e.code === 'ArrowLeft') { pause(); setFrame(viewer.frame - 1); }
    });
  }

  function titles() {
    const box = $('titles');
    for (const p of M.panels) {
      const d = document.createElement('div');
      d.textContent = p.title;
      d.title = p.source;
      box.appendChild(d);
    }
  }

  async function main() {
    const t0 = performance.now();
    const buffer = await loadData();
    viewer.timing.dataMs = performance.now() - t0;
    viewer.timing.startMs = t0;
    const mark = (name) => { viewer.timing[name] = performance.now(); };
    renderer = new THREE.WebGLRenderer({ canvas: $('gl'), antialias: true, preserveDrawingBuffer: true });
    renderer.setPixelRatio(window.devicePixelRatio || 1);
    renderer.setScissorTest(true);
    mark('rendererMs');
    panels = buildPanels(buffer);
    fitCamera();
    titles();
    drawLegend();
    wireControls();
    plot = buildPlot();
    mark('builtMs');
    setFrame(0);
    viewer.timing.readyMs = performance.now();
    viewer.ready = true;
    $('status').textContent = M.panels.length + ' panel(s), ' + M.numFrames + ' frames @ ' + M.fps + ' fps';
  }

  // Test and scripting API.
  Object.assign(viewer, {
    setFrame, play, pause,
    setSpeed: (s) => { speed = s; $('speed').value = String(s); },
    isPlaying: () => playing,
    setHeat: (on) => { $('heat').checked = on; heatOn = on; setFrame(viewer.frame); },
    // Current vertex positions (flat [x0, y0, z0, x1, ...]) of a track, read back from the scene.
    positions: (panel, track) => Array.from(panels[panel].tracks[track].geometry.attributes.position.array),
    // Current vertex colour [r, g, b] in [0, 1] of a track's vertex (null without a heat map).
    vertexColor: (panel, track, i) => {
      const t = panels[panel].tracks[track];
      if (!t.material.vertexColors) return null;
      const a = t.geometry.attributes.color.array;
      return [a[3 * i], a[3 * i + 1], a[3 * i + 2]];
    },
    // The error (mm) shown at a vertex in the current frame.
    errorAt: (panel, track, i) => {
      const t = panels[panel].tracks[track];
      const k = viewer.frame;
      return t.errors === null || k >= t.info.errorFrames ? null : t.errors[k * t.info.numVerts + i];
    },
    // The legend bar's colour [r, g, b] (0-255) at an error value, read from its pixels.
    legendColorAt: (e) => {
      const [lo, hi] = M.errorRange;
      const x = Math.min(255, Math.max(0, Math.floor((e - lo) / (hi - lo) * 256)));
      const d = $('legend-bar').getContext('2d').getImageData(x, 7, 1, 1).data;
      return [d[0], d[1], d[2]];
    },
    legendLabels: () => [$('legend-low').textContent, $('legend-mid').textContent, $('legend-high').textContent],
    plotData: () => (plot ? plot.data.map((s) => Array.from(s)) : null),
    plotSeries: () => (plot ? plot.series.map((s) => s.label) : null),
  });

  main().catch((err) => {
    $('status').textContent = 'error: ' + err.message;
    console.error('loosefit view:', err);
  });
})();
