// loosefit view --live: plays the server's motions on the body (linear blend skinning here) and computes the
// garment in this page, one frame at a time, with the run's ONNX step model in onnxruntime-web (WebGPU where the
// browser has an adapter, else WebAssembly). The data format is described in loosefit/viz/live.py.
//
// Switching motion blends the joint rotations over BLEND_FRAMES frames (quaternion slerp, shortest arc), and the new
// motion continues from the body's current root position and heading; the garment's recurrent state is carried
// across the switch, so the garment never restarts.
import * as ort from './vendor/ort.webgpu.min.mjs';

const $ = (id) => document.getElementById(id);
const BLEND_FRAMES = 10;
const BODY_COLOR = 0xc8b4a0, GARMENT_COLOR = 0x4f8fd8;

// The public handle used by the tests and the benchmark.
const live = { ready: false, frame: 0, renders: 0, backend: null, error: null, blendFrames: BLEND_FRAMES, record: false,
  log: [], stats: { stepsPerSecond: 0, drawsPerSecond: 0, inferMs: 0, skinMs: 0, drawMs: 0 } };
window.loosefitLive = live;

// ---- quaternions [x, y, z, w] ------------------------------------------------------------------------------

function aaToQuat(x, y, z, out, o) {
  const a = Math.hypot(x, y, z);
  if (a < 1e-12) { out[o] = 0.5 * x; out[o + 1] = 0.5 * y; out[o + 2] = 0.5 * z; out[o + 3] = 1; return; }
  const s = Math.sin(a / 2) / a;
  out[o] = x * s; out[o + 1] = y * s; out[o + 2] = z * s; out[o + 3] = Math.cos(a / 2);
}

// Axis-angle of a unit quaternion, angle in [0, pi] (the w >= 0 representative).
function quatToAa(q, o, out, k) {
  let x = q[o], y = q[o + 1], z = q[o + 2], w = q[o + 3];
  if (w < 0) { x = -x; y = -y; z = -z; w = -w; }
  const s = Math.hypot(x, y, z);
  const scale = s < 1e-12 ? 2 : 2 * Math.atan2(s, w) / s;
  out[k] = x * scale; out[k + 1] = y * scale; out[k + 2] = z * scale;
}

function quatMul(a, ao, b, bo, out, o) {
  const ax = a[ao], ay = a[ao + 1], az = a[ao + 2], aw = a[ao + 3];
  const bx = b[bo], by = b[bo + 1], bz = b[bo + 2], bw = b[bo + 3];
  out[o] = aw * bx + ax * bw + ay * bz - az * by;
  out[o + 1] = aw * by - ax * bz + ay * bw + az * bx;
  out[o + 2] = aw * bz + ax * by - ay * bx + az * bw;
  out[o + 3] = aw * bw - ax * bx - ay * by - az * bz;
}

// Shortest-arc slerp of a and b at t, written to out.
function slerp(a, ao, b, bo, t, out, o) {
  let bx = b[bo], by = b[bo + 1], bz = b[bo + 2], bw = b[bo + 3];
  let d = a[ao] * bx + a[ao + 1] * by + a[ao + 2] * bz + a[ao + 3] * bw;
  if (d < 0) { d = -d; bx = -bx; by = -by; bz = -bz; bw = -bw; }
  let wa, wb;
  if (d > 0.9995) { wa = 1 - t; wb = t; } else {
    const th = Math.acos(d), s = Math.sin(th);
    wa = Math.sin((1 - t) * th) / s; wb = Math.sin(t * th) / s;
  }
  const x = wa * a[ao] + wb * bx, y = wa * a[ao + 1] + wb * by, z = wa * a[ao + 2] + wb * bz, w = wa * a[ao + 3] + wb * bw;
  const n = Math.hypot(x, y, z, w);
  out[o] = x / n; out[o + 1] = y / n; out[o + 2] = z / n; out[o + 3] = w / n;
}

// Row-major 3x3 rotation of a unit quaternion.
function quatToMat(q, o, m) {
  const x = q[o], y = q[o + 1], z = q[o + 2], w = q[o + 3];
  m[0] = 1 - 2 * (y * y + z * z); m[1] = 2 * (x * y - z * w); m[2] = 2 * (x * z + y * w);
  m[3] = 2 * (x * y + z * w); m[4] = 1 - 2 * (x * x + z * z); m[5] = 2 * (y * z - x * w);
  m[6] = 2 * (x * z - y * w); m[7] = 2 * (y * z + x * w); m[8] = 1 - 2 * (x * x + y * y);
}

// Heading of a root orientation: the yaw (about +Z) of where the rest pose's front (-Y) points.
function heading(q, o) {
  const m = new Float64Array(9);
  quatToMat(q, o, m);
  return Math.atan2(-m[4], -m[1]);  // R (0, -1, 0) = -(m1, m4, m7): the yaw of its horizontal part
}

// ---- data -------------------------------------------------------------------------------------------------

let M, buffer, J, motions, body, session, state, garmentFaces;

function view(index) {
  const b = M.buffers[index];
  const Type = b.dtype === 'uint32' ? Uint32Array : Float32Array;
  return new Type(buffer, b.offset, b.bytes / 4);
}

async function fetchOk(url, kind) {
  const r = await fetch(url);
  if (!r.ok) throw new Error('cannot load ' + url + ': HTTP ' + r.status);
  return kind === 'json' ? r.json() : r.arrayBuffer();
}

function topologicalOrder(parents) {
  const depth = parents.map((_, j) => { let d = 0; for (let p = parents[j]; p >= 0; p = parents[p]) d++; return d; });
  return parents.map((_, j) => j).sort((a, b) => depth[a] - depth[b] || a - b);
}

// ---- poses: per-joint quaternions (J x 4), the axis-angle fed to the model (J x 3), the root position ------

function newPose() { return { q: new Float64Array(J * 4), aa: new Float32Array(J * 3), root: new Float64Array(3) }; }

// A motion track: motion m at frame f, its root turned by yaw about +Z and moved so that its first frame's root
// (origin, horizontal) lies at `at`. The first motion plays untouched (yaw 0, at = origin).
function motionTrack(m, yaw, at) {
  const tr = motions[m].translation;
  const origin = [tr[0], tr[1]];
  const turn = new Float64Array(4);
  aaToQuat(0, 0, yaw, turn, 0);
  return { kind: 'motion', m, f: 0, yaw, turn, origin, at: at || origin, untouched: !at && yaw === 0 };
}

function sampleTrack(track, out) {
  if (track.kind === 'pose') { out.q.set(track.pose.q); out.aa.set(track.pose.aa); out.root.set(track.pose.root); return; }
  const mo = motions[track.m];
  const f = Math.min(track.f, mo.numFrames - 1);
  const rot = mo.rotations.subarray(f * J * 3, (f + 1) * J * 3);
  out.aa.set(rot);  // the motion's own values: the page feeds exactly the file's rotations when nothing blends
  for (let j = 0; j < J; j++) aaToQuat(rot[3 * j], rot[3 * j + 1], rot[3 * j + 2], out.q, 4 * j);
  const t = mo.translation;
  const px = t[3 * f], py = t[3 * f + 1], pz = t[3 * f + 2];
  if (track.untouched) { out.root[0] = px; out.root[1] = py; out.root[2] = pz; return; }
  const c = Math.cos(track.yaw), s = Math.sin(track.yaw);
  const dx = px - track.origin[0], dy = py - track.origin[1];
  out.root[0] = track.at[0] + c * dx - s * dy;
  out.root[1] = track.at[1] + s * dx + c * dy;
  out.root[2] = pz;
  const q0 = out.q.slice(0, 4);
  quatMul(track.turn, 0, q0, 0, out.q, 0);
  quatToAa(out.q, 0, out.aa, 0);
}

let current = null, blend = null, lastPose = null;
const lastStep = [0, 0];  // the root's last horizontal step shown, metres
let scratchOld, scratchNew;

// The pose shown at the current frame: the current track, or during a switch the slerp from the track left
// towards it with weight smoothstep(i / BLEND_FRAMES).
function currentPose(out) {
  if (!blend) { sampleTrack(current, out); return; }
  sampleTrack(blend.from, scratchOld);
  sampleTrack(current, scratchNew);
  const x = blend.i / BLEND_FRAMES, w = x * x * (3 - 2 * x);
  for (let j = 0; j < J; j++) {
    slerp(scratchOld.q, 4 * j, scratchNew.q, 4 * j, w, out.q, 4 * j);
    quatToAa(out.q, 4 * j, out.aa, 3 * j);
  }
  // The root moves on by the blend of the two tracks' steps (no stall, no overshoot), its height blends; the new
  // motion's anchor follows, so that it continues from the blended root once the blend is over.
  const a = trackStep(blend.from), b = trackStep(current);
  for (let k = 0; k < 2; k++) out.root[k] = lastPose.root[k] + (1 - w) * a[k] + w * b[k];
  out.root[2] = (1 - w) * scratchOld.root[2] + w * scratchNew.root[2];
  current.at = [current.at[0] + out.root[0] - scratchNew.root[0], current.at[1] + out.root[1] - scratchNew.root[1]];
}

// Horizontal root step into a track's current frame (metres), turned as the track is: a motion past its end (a
// loop) keeps its last step, and a frozen pose the step shown when it was frozen.
function trackStep(track) {
  if (track.kind === 'pose') return track.velocity;
  const tr = motions[track.m].translation, T = motions[track.m].numFrames;
  const f1 = Math.max(1, Math.min(track.f, T - 1)), f0 = f1 - 1;
  const dx = tr[3 * f1] - tr[3 * f0], dy = tr[3 * f1 + 1] - tr[3 * f0 + 1];
  const c = Math.cos(track.yaw), s = Math.sin(track.yaw);
  return [c * dx - s * dy, s * dx + c * dy];
}

// Switch to motion m (index or name) from the pose shown last; its root continues from there.
function switchTo(m) {
  if (typeof m === 'string') m = motions.findIndex((x) => x.name === m);
  if (!(m >= 0 && m < motions.length)) throw new Error('no such motion: ' + m);
  $('motions').value = String(m);
  if (!lastPose) { current = motionTrack(m, 0, null); blend = null; return; }
  const first = newPose();
  sampleTrack(motionTrack(m, 0, null), first);
  const yaw = heading(lastPose.q, 0) - heading(first.q, 0);
  // mid-switch: from what is shown, moving on as it moved
  const from = blend ? { kind: 'pose', pose: clonePose(lastPose), velocity: lastStep.slice() } : current;
  current = motionTrack(m, yaw, [lastPose.root[0], lastPose.root[1]]);
  blend = { from, i: 1 };  // the first frame after a switch already moves towards the new motion
}

function clonePose(p) { return { q: p.q.slice(), aa: p.aa.slice(), root: p.root.slice() }; }

// ---- body skinning (loosefit.geometry.lbs: world-aligned joint frames at rest) ----------------------------

function skinBody(pose) {
  const { parents, order, restJ, restV, idx, wts, K, out, A } = body;
  const R = body.R, P = body.P, m = new Float64Array(9);
  for (const j of order) {
    quatToMat(pose.q, 4 * j, m);
    const p = parents[j], r = 9 * j;
    if (p < 0) {
      for (let k = 0; k < 9; k++) R[r + k] = m[k];
      P[3 * j] = pose.root[0]; P[3 * j + 1] = pose.root[1]; P[3 * j + 2] = pose.root[2];
    } else {
      const rp = 9 * p;
      for (let a = 0; a < 3; a++) for (let b = 0; b < 3; b++)
        R[r + 3 * a + b] = R[rp + 3 * a] * m[b] + R[rp + 3 * a + 1] * m[3 + b] + R[rp + 3 * a + 2] * m[6 + b];
      const ox = restJ[3 * j] - restJ[3 * p], oy = restJ[3 * j + 1] - restJ[3 * p + 1], oz = restJ[3 * j + 2] - restJ[3 * p + 2];
      for (let a = 0; a < 3; a++) P[3 * j + a] = P[3 * p + a] + R[rp + 3 * a] * ox + R[rp + 3 * a + 1] * oy + R[rp + 3 * a + 2] * oz;
    }
    // skinning transform [R | p - R rest_j], 12 numbers
    for (let a = 0; a < 3; a++) {
      A[12 * j + 4 * a] = R[r + 3 * a]; A[12 * j + 4 * a + 1] = R[r + 3 * a + 1]; A[12 * j + 4 * a + 2] = R[r + 3 * a + 2];
      A[12 * j + 4 * a + 3] = P[3 * j + a] - (R[r + 3 * a] * restJ[3 * j] + R[r + 3 * a + 1] * restJ[3 * j + 1] + R[r + 3 * a + 2] * restJ[3 * j + 2]);
    }
  }
  const V = body.numVerts;
  for (let v = 0; v < V; v++) {
    const x = restV[3 * v], y = restV[3 * v + 1], z = restV[3 * v + 2];
    let ox = 0, oy = 0, oz = 0;
    for (let k = 0; k < K; k++) {
      const w = wts[K * v + k];
      if (w === 0) continue;
      const a = 12 * idx[K * v + k];
      ox += w * (A[a] * x + A[a + 1] * y + A[a + 2] * z + A[a + 3]);
      oy += w * (A[a + 4] * x + A[a + 5] * y + A[a + 6] * z + A[a + 7]);
      oz += w * (A[a + 8] * x + A[a + 9] * y + A[a + 10] * z + A[a + 11]);
    }
    out[3 * v] = ox; out[3 * v + 1] = oy; out[3 * v + 2] = oz;
  }
}

// ---- the garment: one call of the step model per frame ---------------------------------------------------

async function createSession(bytes) {
  const wanted = new URLSearchParams(location.search).get('backend');
  const tries = [];
  if (wanted !== 'wasm' && navigator.gpu) {
    try { if (await navigator.gpu.requestAdapter()) tries.push('webgpu'); } catch (e) { /* no adapter */ }
  }
  tries.push('wasm');
  let lastError;
  for (const ep of tries) {
    try {
      const s = await ort.InferenceSession.create(bytes, { executionProviders: [ep], graphOptimizationLevel: 'all' });
      live.backend = ep;
      return s;
    } catch (e) { lastError = e; console.warn('loosefit live: ' + ep + ' unavailable:', e); }
  }
  throw lastError;
}

async function garmentStep(pose) {
  const feeds = {
    // a copy: the pose stays the one shown, whatever the runtime does with its input buffers
    joint_rotations: new ort.Tensor('float32', pose.aa.slice(), [J, 3]),
    root_position: new ort.Tensor('float32', Float32Array.from(pose.root), [3]),
    state: new ort.Tensor('float32', state, [state.length]),
  };
  const out = await session.run(feeds);
  state = out.next_state.data.slice();
  return out.vertices.data;
}

// ---- drawing ----------------------------------------------------------------------------------------------

let renderer, scene, camera, controls, bodyMesh, garmentMesh;

function makeMesh(numVerts, faces, color) {
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(new Float32Array(numVerts * 3), 3));
  g.setIndex(new THREE.BufferAttribute(faces, 1));
  const mesh = new THREE.Mesh(g, new THREE.MeshLambertMaterial({ color, side: THREE.DoubleSide }));
  mesh.frustumCulled = false;
  scene.add(mesh);
  return mesh;
}

function setPositions(mesh, values) {
  let pos = mesh.geometry.attributes.position;
  if (pos.array.length !== values.length) {  // the garment's vertex count is the model's output size
    mesh.geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(values.length), 3));
    pos = mesh.geometry.attributes.position;
  }
  pos.array.set(values);
  pos.needsUpdate = true;
  updateNormals(mesh.geometry);
}

// Area-weighted vertex normals (what THREE's computeVertexNormals gives) over the typed arrays directly: 3-4x
// faster than its per-vertex vector objects, which cost a few milliseconds a drawn frame for the body's 27k faces.
function updateNormals(geometry) {
  const pos = geometry.attributes.position.array, index = geometry.index.array;
  let attr = geometry.attributes.normal;
  if (!attr || attr.array.length !== pos.length) {
    attr = new THREE.BufferAttribute(new Float32Array(pos.length), 3);
    geometry.setAttribute('normal', attr);
  }
  const n = attr.array;
  n.fill(0);
  for (let f = 0; f < index.length; f += 3) {
    const a = 3 * index[f], b = 3 * index[f + 1], c = 3 * index[f + 2];
    const ux = pos[b] - pos[a], uy = pos[b + 1] - pos[a + 1], uz = pos[b + 2] - pos[a + 2];
    const vx = pos[c] - pos[a], vy = pos[c + 1] - pos[a + 1], vz = pos[c + 2] - pos[a + 2];
    const x = uy * vz - uz * vy, y = uz * vx - ux * vz, z = ux * vy - uy * vx;
    n[a] += x; n[a + 1] += y; n[a + 2] += z;
    n[b] += x; n[b + 1] += y; n[b + 2] += z;
    n[c] += x; n[c + 1] += y; n[c + 2] += z;
  }
  for (let i = 0; i < n.length; i += 3) {
    const l = Math.sqrt(n[i] * n[i] + n[i + 1] * n[i + 1] + n[i + 2] * n[i + 2]);
    if (l > 0) { n[i] /= l; n[i + 1] /= l; n[i + 2] /= l; }
  }
  attr.needsUpdate = true;
}

function buildScene() {
  renderer = new THREE.WebGLRenderer({ canvas: $('gl'), antialias: false, preserveDrawingBuffer: false });
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  scene = new THREE.Scene();
  scene.background = new THREE.Color(0x303238);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x404040, 0.75));
  const sun = new THREE.DirectionalLight(0xffffff, 0.55);
  sun.position.set(1.5, -3, 4);
  scene.add(sun);
  const grid = new THREE.GridHelper(20, 40, 0x555555, 0x444444);
  grid.rotation.x = Math.PI / 2;  // the floor z = 0
  scene.add(grid);
  bodyMesh = makeMesh(body.numVerts, view(M.body.faces), BODY_COLOR);
  garmentMesh = makeMesh(garmentFaces.maxIndex + 1, garmentFaces.array, GARMENT_COLOR);
  camera = new THREE.PerspectiveCamera(30, 1, 0.05, 100);
  camera.up.set(0, 0, 1);
  controls = new THREE.OrbitControls(camera, renderer.domElement);
  controls.addEventListener('change', draw);
}

// The camera keeps its offset from the body's root, so a walk stays in view.
let followed = null;
function follow(root) {
  const target = new THREE.Vector3(root[0], root[1], 0.85);
  if (followed === null) {
    camera.position.copy(target).add(new THREE.Vector3(1.9, -4.3, 0.35));
    controls.target.copy(target);
  } else {
    const d = target.clone().sub(followed);
    camera.position.add(d);
    controls.target.add(d);
  }
  followed = target;
  controls.update();
}

let stale = false, shownFrame = 0;
let drawing = false;
function draw() {
  // follow() moves the camera, whose change event calls draw() again: that inner call would render the frame a
  // second time (twice the rasterising), so it returns and this one renders once with the camera moved
  if (drawing) return;
  drawing = true;
  try { render(); } finally { drawing = false; }
}

function render() {
  const t0 = performance.now();
  if (stale && lastPose) {
    stale = false;
    skinBody(lastPose);
    setPositions(bodyMesh, body.out);
    garmentMesh.geometry.attributes.position.needsUpdate = true;
    updateNormals(garmentMesh.geometry);
    follow(lastPose.root);
    live.stats.skinMs = 0.9 * live.stats.skinMs + 0.1 * (performance.now() - t0);
    $('frame-label').textContent = 'frame ' + shownFrame + ' \u00b7 ' + motions[current.m].name + (blend ? ' (blending)' : '');
  }
  const ratio = (window.devicePixelRatio || 1) * (playing ? renderScale : 1);  // paused: every pixel
  if (renderer.getPixelRatio() !== ratio) renderer.setPixelRatio(ratio);
  const canvas = renderer.domElement;
  const w = canvas.clientWidth, h = canvas.clientHeight;
  const size = renderer.getSize(new THREE.Vector2());
  if (size.x !== w || size.y !== h) renderer.setSize(w, h, false);
  camera.aspect = w / Math.max(1, h);
  camera.updateProjectionMatrix();
  renderer.render(scene, camera);
  live.stats.drawMs = 0.9 * live.stats.drawMs + 0.1 * (performance.now() - t0);
  live.renders++;
}

// ---- one frame --------------------------------------------------------------------------------------------

const counts = { steps: 0, renders: 0, since: performance.now() };  // renders: live.renders when the window began
let shown = null;

async function stepOnce(render) {
  currentPose(shown);
  const t0 = performance.now();
  const verts = await garmentStep(shown);
  live.stats.inferMs = 0.9 * live.stats.inferMs + 0.1 * (performance.now() - t0);
  const pos = garmentMesh.geometry.attributes.position;
  if (pos.array.length === verts.length) pos.array.set(verts); else setPositions(garmentMesh, verts);
  shownFrame = live.frame;
  if (live.record) live.log.push({ frame: live.frame, motion: current.m, blend: blend ? blend.i : null,
    joint_rotations: Array.from(shown.aa), root_position: Array.from(shown.root), vertices: Array.from(verts) });
  if (lastPose) { lastStep[0] = shown.root[0] - lastPose.root[0]; lastStep[1] = shown.root[1] - lastPose.root[1]; }
  lastPose = clonePose(shown);
  stale = true;  // the body is skinned and the normals computed when drawn: only the frames drawn need them
  if (render) draw();
  counts.steps++;
  // advance: the motion left keeps playing under the blend; a motion at its end starts again, continuing
  live.frame++;
  current.f++;
  if (blend) {
    if (blend.from.kind === 'motion') blend.from.f++;
    if (++blend.i > BLEND_FRAMES) blend = null;
  }
  if (current.f >= motions[current.m].numFrames) switchTo(current.m);
}

// ---- playing ----------------------------------------------------------------------------------------------
// The garment advances on its own clock (fps x speed frames per second of wall time, on timers), and the
// screen is redrawn on animation frames with the latest result: where drawing is slow (software WebGL), the
// garment still runs at the motion's rate and the screen shows fewer of its frames.

// After a stall (a slow draw, a collection) the garment catches up at most this many frames, then drops the rest.
const CATCH_UP_FRAMES = 4;
let playing = true, speed = 1, last = null, acc = 0, busy = false, timer = null;
async function advance() {
  timer = null;
  if (!playing) return;
  const now = performance.now();
  if (last !== null) acc = Math.min(acc + (now - last) / 1000 * M.fps * speed, CATCH_UP_FRAMES);  // a stall drops time
  last = now;
  busy = true;
  try {
    while (acc >= 1 && playing) { acc -= 1; await stepOnce(false); }
  } catch (e) { fail(e); return; } finally { busy = false; }
  if (playing) timer = setTimeout(advance, Math.max(0, (1 - acc) * 1000 / (M.fps * speed) - (performance.now() - now)));
}

function onAnimationFrame(now) {
  if (stale) draw();
  updateCounts(now);
  if (playing) requestAnimationFrame(onAnimationFrame);
}

// ---- resolution while playing ------------------------------------------------------------------------------
// Where WebGL is software (SwiftShader) every drawn pixel costs CPU time beside the network's: at 960x640 the page
// played the paper's VirtualBones at 13 garment frames a second, at 480x320 at 27. While the garment falls behind
// the motion's rate the page draws fewer pixels (down to MIN_RENDER_SCALE of the device's, stretched to the
// window) rather than play the motion slowly, and climbs back after KEEP_UP_SECONDS of keeping up.
const MIN_RENDER_SCALE = 0.35, KEEP_UP_SECONDS = 3;
let renderScale = 1, adaptive = true, keptUp = 0;
function adaptRenderScale(stepsPerSecond, asked) {
  if (!adaptive) return renderScale;
  if (stepsPerSecond < 0.9 * asked) {
    renderScale = Math.max(MIN_RENDER_SCALE, renderScale * 0.8);
    keptUp = 0;
  } else if (++keptUp >= KEEP_UP_SECONDS && renderScale < 1) {
    renderScale = Math.min(1, renderScale * 1.1);
    keptUp = 0;
  }
  return renderScale;
}

function updateCounts(now) {
  const dt = now - counts.since;
  if (dt < 1000) return;
  live.stats.stepsPerSecond = counts.steps * 1000 / dt;
  live.stats.drawsPerSecond = (live.renders - counts.renders) * 1000 / dt;
  counts.steps = 0; counts.renders = live.renders; counts.since = now;
  if (playing) adaptRenderScale(live.stats.stepsPerSecond, M.fps * speed);
  live.stats.renderScale = renderScale;
  $('fps').textContent = live.stats.stepsPerSecond.toFixed(1) + ' garment fps (' + live.backend + ', '
    + live.stats.inferMs.toFixed(1) + ' ms/frame) \u00b7 ' + live.stats.drawsPerSecond.toFixed(1) + ' drawn/s'
    + (renderScale < 1 ? ' at ' + Math.round(100 * renderScale) + ' %' : '');
}

function play() {
  if (playing) return;
  playing = true; last = null; acc = 0; $('play').textContent = 'pause';
  counts.steps = 0; counts.renders = live.renders; counts.since = performance.now();
  advance();
  requestAnimationFrame(onAnimationFrame);
}
function pause() {
  playing = false; $('play').textContent = 'play';
  if (timer !== null) { clearTimeout(timer); timer = null; }
}

function fail(err) {
  live.error = String(err && err.message || err);
  $('status').textContent = 'error: ' + live.error;
  console.error('loosefit live:', err);
}

async function main() {
  M = await fetchOk('live/manifest.json', 'json');
  const [data, model] = await Promise.all([fetchOk(M.data), fetchOk(M.model)]);
  buffer = data;
  J = M.metadata.joint_names.length;
  motions = M.motions.map((m) => ({ name: m.name, numFrames: m.numFrames, rotations: view(m.rotations), translation: view(m.translation) }));
  const b = M.body;
  body = { numVerts: b.numVerts, K: b.influences, parents: b.parents, order: topologicalOrder(b.parents),
    restV: view(b.restVerts), restJ: view(b.restJoints), idx: view(b.skinIndex), wts: view(b.skinWeight),
    out: new Float32Array(b.numVerts * 3), A: new Float64Array(12 * J), R: new Float64Array(9 * J), P: new Float64Array(3 * J) };
  const flat = M.metadata.faces.flat(2);
  garmentFaces = { array: Uint32Array.from(flat), maxIndex: flat.reduce((a, x) => Math.max(a, x), 0) };
  state = Float32Array.from(M.metadata.initial_state);
  ort.env.wasm.wasmPaths = new URL('vendor/', location.href).href;
  session = await createSession(new Uint8Array(model));
  shown = newPose(); scratchOld = newPose(); scratchNew = newPose();
  buildScene();
  const select = $('motions');
  motions.forEach((m, i) => { const o = document.createElement('option'); o.value = String(i); o.textContent = m.name; select.appendChild(o); });
  select.addEventListener('change', () => switchTo(Number(select.value)));
  $('speed').addEventListener('change', (e) => { speed = Number(e.target.value); });
  $('play').addEventListener('click', () => (playing ? pause() : play()));
  window.addEventListener('resize', draw);
  window.addEventListener('keydown', (e) => {
    if (e.target.tagName === 'SELECT') return;
    if (e.code === 'Space') { e.preventDefault(); playing ? pause() : play(); }
  });
  switchTo(0);
  const auto = new URLSearchParams(location.search).get('play') !== '0';
  await stepOnce(true);
  $('status').textContent = M.metadata.method + ' \u00b7 ' + J + ' joints \u00b7 ' + garmentMesh.geometry.attributes.position.count
    + ' garment vertices \u00b7 ' + live.backend;
  live.ready = true;
  playing = false;
  if (auto) play(); else pause();
}

// Test and scripting API: stepping never uses the animation timer.
Object.assign(live, {
  play, pause, switchTo,
  setSpeed: (s) => { speed = s; $('speed').value = String(s); },
  speed: () => speed,
  motionNames: () => motions.map((m) => m.name),
  // Step n frames now (the timer paused), drawing each when render is true; resolves to the frame count.
  step: async (n, render = false) => {
    pause();
    while (busy) await new Promise((r) => setTimeout(r, 5));
    for (let i = 0; i < n; i++) await stepOnce(render);
    if (!render) draw();
    return live.frame;
  },
  garment: () => Array.from(garmentMesh.geometry.attributes.position.array),
  body: () => Array.from(bodyMesh.geometry.attributes.position.array),
  // the vertex normals drawn (updateNormals), of the garment or the body
  normals: (which) => Array.from((which === 'body' ? bodyMesh : garmentMesh).geometry.attributes.normal.array),
  state: () => Array.from(state),
  // The resolution while playing: adaptRenderScale(garment fps, asked fps) as the page applies it each second;
  // setRenderScale(s) fixes it (null: adaptive again); drawingBuffer(): the canvas' drawn [width, height] and the
  // [width, height] in CSS pixels it was last drawn for.
  adaptRenderScale,
  setRenderScale: (s) => { adaptive = s === null; if (s !== null) renderScale = s; },
  renderScale: () => renderScale,
  drawingBuffer: () => {
    const c = renderer.domElement, size = renderer.getSize(new THREE.Vector2());
    return [c.width, c.height, size.x, size.y];
  },
  current: () => ({ motion: motions[current.m].name, frame: current.f, blending: blend !== null }),
});
window.loosefitStep = (n) => live.step(n);

main().catch(fail);
