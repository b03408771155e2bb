// The viewer page: reads the run's manifest (/api/run), streams and draws its Gaussians
// (splats.js, sorted by sort-worker.js) or its mesh, draws the cameras as frusta, and lists the
// metrics, held-out renders and videos. Orbit / fly controls; clicking a camera looks through
// it with its own intrinsics. `window.fewviewView` exposes hooks for tests and scripts
// (renderCamera(i) draws exactly camera i at its resolution and returns a PNG data URL).
import { SplatData, SplatRenderer, streamPly, floatOffsets, compile } from "/splats.js";

const $ = (id) => document.getElementById(id);
const GROUP_COLORS = {
  train: [1.0, 0.6, 0.1], test: [0.3, 0.6, 1.0], initial: [0.95, 0.25, 0.25], refined: [0.2, 0.9, 0.35],
  estimated: [1.0, 0.6, 0.1],
};

function showError(message) {
  const el = $("error");
  el.textContent = `error: ${String(message).split("\n")[0]}`;
  el.hidden = false;
  $("status").textContent = "failed";
}
window.addEventListener("error", (e) => showError(e.message));
window.addEventListener("unhandledrejection", (e) => showError(e.reason && e.reason.message ? e.reason.message : e.reason));

// --- small 3×3 / 3-vector helpers (row-major arrays) ---------------------------------------
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const norm = (a) => Math.hypot(a[0], a[1], a[2]);
const normalize = (a) => scale(a, 1 / (norm(a) || 1));
const row = (R, i) => [R[3 * i], R[3 * i + 1], R[3 * i + 2]];
const mulVec = (R, v) => [dot(row(R, 0), v), dot(row(R, 1), v), dot(row(R, 2), v)];
const mulTVec = (R, v) => [
  R[0] * v[0] + R[3] * v[1] + R[6] * v[2], R[1] * v[0] + R[4] * v[1] + R[7] * v[2], R[2] * v[0] + R[5] * v[1] + R[8] * v[2]];
function rotation(axis, angle) {
  const [x, y, z] = normalize(axis);
  const c = Math.cos(angle), s = Math.sin(angle), k = 1 - c;
  return [c + x * x * k, x * y * k - z * s, x * z * k + y * s, y * x * k + z * s, c + y * y * k, y * z * k - x * s,
    z * x * k - y * s, z * y * k + x * s, c + z * z * k];
}
// R Qᵀ: the camera turned by the world rotation Q.
function turn(R, Q) {
  const out = new Array(9);
  for (let i = 0; i < 3; i++) for (let j = 0; j < 3; j++) {
    out[3 * i + j] = R[3 * i] * Q[3 * j] + R[3 * i + 1] * Q[3 * j + 1] + R[3 * i + 2] * Q[3 * j + 2];
  }
  return out;
}
function solve3(A, b) {
  const det = A[0] * (A[4] * A[8] - A[5] * A[7]) - A[1] * (A[3] * A[8] - A[5] * A[6]) + A[2] * (A[3] * A[7] - A[4] * A[6]);
  if (!(Math.abs(det) > 1e-9)) return null;
  const inv = [A[4] * A[8] - A[5] * A[7], A[2] * A[7] - A[1] * A[8], A[1] * A[5] - A[2] * A[4],
    A[5] * A[6] - A[3] * A[8], A[0] * A[8] - A[2] * A[6], A[2] * A[3] - A[0] * A[5],
    A[3] * A[7] - A[4] * A[6], A[1] * A[6] - A[0] * A[7], A[0] * A[4] - A[1] * A[3]];
  return mulVec(inv, b).map((v) => v / det);
}
const cameraCenter = (cam) => scale(mulTVec(cam.rotation, cam.translation), -1);

// --- state ------------------------------------------------------------------------------------
const canvas = $("canvas");
let gl = null;
const S = {
  manifest: null, splats: null, data: null, worker: null, mesh: null, lines: null,
  R: [1, 0, 0, 0, 1, 0, 0, 0, 1], c: [0, 0, -3],
  intr: { fx: 700, fy: 700, cx: 400, cy: 300, w: 800, h: 600 },
  target: [0, 0, 0], up: [0, -1, 0], sceneScale: 1,
  mode: "orbit", fixed: null, overlays: true, exactSort: false, selected: -1,
  version: 0, dataVersion: 0, sort: null, sorted: { version: -1, data: -1, exact: false },
  loadedAll: false, lastSortAt: 0, keys: new Set(), waiters: [], placed: false,
  // Pictures: `serial` counts the changes that call for a new one (view, order, size, overlays,
  // mesh); `shown` is the serial of the picture on the canvas, `full` the serial of the last
  // full-quality one; `pass` a full-quality picture being drawn over several frames.
  serial: 0, shown: -1, shownVersion: -1, full: -1, pass: null, lastChangeAt: 0,
  // One frame in flight: its fence, when it was submitted, and what it was.
  fence: null, submitted: null,
  // The resolution factor of quick frames, adapted to their measured time.
  quickScale: 0.25, quickBudget: Infinity,
};
// Timings (ms since the page started, as performance.now()) for tests and for the status line:
// `timeline` marks the first of each stage; totals of parsing, uploading and sorting; the
// frames drawn (scale, Gaussians, milliseconds).
const stats = {
  firstPicture: null, fullPicture: null, loadedAt: null, gaussians: 0, lastFrameMs: 0,
  timeline: {}, parseMs: 0, uploadMs: 0, sortMs: 0, sorts: 0, frames: [],
};
function mark(name) { if (!(name in stats.timeline)) stats.timeline[name] = performance.now(); }
let resolveReady;
const ready = new Promise((r) => { resolveReady = r; });

function changed() { S.version++; S.serial++; S.lastChangeAt = performance.now(); }
function redraw() { S.serial++; }

function currentView() {
  const w = canvas.width, h = canvas.height;
  const k = S.intr, s = h / k.h;
  const R = S.R;
  return {
    R: new Float32Array(R), t: new Float32Array(scale(mulVec(R, S.c), -1)), center: new Float32Array(S.c),
    fx: k.fx * s, fy: k.fy * s, cx: w / 2 + (k.cx - k.w / 2) * s, cy: k.cy * s, width: w, height: h,
    near: S.manifest ? S.manifest.near_plane : 0.2,
    background: new Float32Array(S.manifest && !["surface", "poses"].includes(S.manifest.kind) ? S.manifest.background : [0.12, 0.12, 0.14]),
  };
}

function resize() {
  const dpr = window.devicePixelRatio || 1;
  const w = S.fixed ? S.fixed.w : Math.max(1, Math.round(canvas.clientWidth * dpr));
  const h = S.fixed ? S.fixed.h : Math.max(1, Math.round(canvas.clientHeight * dpr));
  if (canvas.width !== w || canvas.height !== h) {
    canvas.width = w;
    canvas.height = h;
    redraw();
  }
}

function lookThrough(cam) {
  S.R = cam.rotation.slice();
  S.c = cameraCenter(cam);
  S.intr = { fx: cam.fx, fy: cam.fy, cx: cam.cx, cy: cam.cy, w: cam.width, h: cam.height };
  const forward = row(S.R, 2);
  const d = Math.max(norm(sub(S.target, S.c)), 1e-3);
  S.target = add(S.c, scale(forward, d));
  changed();
}

function jumpTo(i) {
  S.selected = i;
  S.exactSort = false;
  lookThrough(S.manifest.cameras[i]);
  buildFrusta();
  for (const li of document.querySelectorAll("#cameras li")) li.classList.toggle("selected", Number(li.dataset.index) === i);
}

// --- controls -----------------------------------------------------------------------------------
function orbit(dx, dy) {
  const yaw = rotation(S.up, -dx * 0.005);
  const right = row(turn(S.R, yaw), 0);
  const Q = mulMat(rotation(right, dy * 0.005), yaw);
  const pivot = S.mode === "orbit" ? S.target : S.c;
  S.c = add(pivot, mulVec(Q, sub(S.c, pivot)));
  S.R = turn(S.R, Q);
  if (S.mode === "fly") S.target = add(S.c, scale(row(S.R, 2), norm(sub(S.target, S.c))));
  changed();
}
function mulMat(A, B) {
  const out = new Array(9);
  for (let i = 0; i < 3; i++) for (let j = 0; j < 3; j++) {
    out[3 * i + j] = A[3 * i] * B[j] + A[3 * i + 1] * B[3 + j] + A[3 * i + 2] * B[6 + j];
  }
  return out;
}
function pan(dx, dy) {
  const d = norm(sub(S.target, S.c));
  const k = d / (S.intr.fy * canvas.height / S.intr.h) * (window.devicePixelRatio || 1);
  const move = add(scale(row(S.R, 0), -dx * k), scale(row(S.R, 1), -dy * k));
  S.c = add(S.c, move);
  S.target = add(S.target, move);
  changed();
}
function zoom(amount) {
  const f = Math.exp(amount * 0.001);
  S.c = add(S.target, scale(sub(S.c, S.target), f));
  changed();
}
function fly(dt) {
  const step = S.sceneScale * 0.6 * dt;
  let m = [0, 0, 0];
  const k = S.keys;
  if (k.has("w")) m = add(m, row(S.R, 2));
  if (k.has("s")) m = sub(m, row(S.R, 2));
  if (k.has("d")) m = add(m, row(S.R, 0));
  if (k.has("a")) m = sub(m, row(S.R, 0));
  if (k.has("e")) m = add(m, S.up);
  if (k.has("q")) m = sub(m, S.up);
  if (norm(m) > 0) {
    m = scale(normalize(m), step);
    S.c = add(S.c, m);
    S.target = add(S.target, m);
    S.exactSort = false;
    changed();
  }
}

function setMode(mode) {
  S.mode = mode;
  $("mode").textContent = mode === "orbit" ? "mode: orbit (F: fly)" : "mode: fly (F: orbit)";
}

function pick(x, y) {
  const v = currentView();
  let best = -1, bestD = 20 * (window.devicePixelRatio || 1);
  S.manifest.cameras.forEach((cam, i) => {
    for (const p of [cameraCenter(cam), add(cameraCenter(cam), scale(row(cam.rotation, 2), S.frustumDepth))]) {
      const t = add(mulVec(S.R, p), Array.from(v.t));
      if (t[2] <= 1e-6) continue;
      const u = v.fx * t[0] / t[2] + v.cx, w = v.fy * t[1] / t[2] + v.cy;
      const d = Math.hypot(u - x, w - y);
      if (d < bestD) { bestD = d; best = i; }
    }
  });
  if (best >= 0) jumpTo(best);
}

function installControls() {
  let down = null;
  canvas.addEventListener("contextmenu", (e) => e.preventDefault());
  canvas.addEventListener("pointerdown", (e) => {
    down = { x: e.clientX, y: e.clientY, moved: 0, pan: e.button === 2 || e.shiftKey };
    canvas.setPointerCapture(e.pointerId);
  });
  canvas.addEventListener("pointermove", (e) => {
    if (!down) return;
    const dx = e.clientX - down.x, dy = e.clientY - down.y;
    down.x = e.clientX; down.y = e.clientY;
    down.moved += Math.abs(dx) + Math.abs(dy);
    S.exactSort = false;
    if (down.pan) pan(dx, dy); else orbit(dx, dy);
  });
  canvas.addEventListener("pointerup", (e) => {
    if (down && down.moved < 4 && S.manifest) {
      const r = canvas.getBoundingClientRect();
      pick((e.clientX - r.left) * canvas.width / r.width, (e.clientY - r.top) * canvas.height / r.height);
    }
    down = null;
  });
  canvas.addEventListener("wheel", (e) => { e.preventDefault(); S.exactSort = false; zoom(e.deltaY); }, { passive: false });
  window.addEventListener("keydown", (e) => {
    if (e.target && e.target.tagName === "INPUT") return;
    const k = e.key.toLowerCase();
    if (k === "f") setMode(S.mode === "orbit" ? "fly" : "orbit");
    else if ("wasdqe".includes(k) && k.length === 1) S.keys.add(k);
  });
  window.addEventListener("keyup", (e) => S.keys.delete(e.key.toLowerCase()));
  window.addEventListener("resize", redraw);
  $("mode").addEventListener("click", () => setMode(S.mode === "orbit" ? "fly" : "orbit"));
  $("reset").addEventListener("click", () => { S.fixed = null; S.overlays = true; initialView(); });
}

// --- frusta and mesh (lines and triangles, same pinhole projection) ----------------------------
const GEOM_VS = `#version 300 es
precision highp float;
uniform mat3 u_R; uniform vec3 u_t; uniform vec4 u_intr; uniform vec2 u_size; uniform vec2 u_clip;
uniform vec3 u_center;
in vec3 a_pos; in vec3 a_color; in vec3 a_normal;
out vec3 v_color;
uniform int u_shade;
void main() {
  vec3 t = u_R * a_pos + u_t;
  float n = u_clip.x, f = u_clip.y;
  gl_Position = vec4((u_intr.x * t.x + u_intr.z * t.z) / u_size.x * 2.0 - t.z,
    t.z - (u_intr.y * t.y + u_intr.w * t.z) / u_size.y * 2.0, (t.z * (f + n) - 2.0 * f * n) / (f - n), t.z);
  float k = 1.0;
  if (u_shade == 1) k = 0.25 + 0.75 * abs(dot(normalize(a_normal), normalize(u_center - a_pos)));
  v_color = a_color * k;
  gl_PointSize = 3.0;
}`;
const GEOM_FS = `#version 300 es
precision highp float;
in vec3 v_color; out vec4 out_color;
void main() { out_color = vec4(v_color, 1.0); }`;
let geomProg = null, geomU = null;

function geomBuffers(arrays) {
  const vao = gl.createVertexArray();
  gl.bindVertexArray(vao);
  for (const [name, data] of Object.entries(arrays)) {
    const loc = gl.getAttribLocation(geomProg, name);
    if (loc < 0) continue;
    const b = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, b);
    gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
    gl.enableVertexAttribArray(loc);
    gl.vertexAttribPointer(loc, 3, gl.FLOAT, false, 0, 0);
  }
  return vao;
}

function buildFrusta() {
  const cams = S.manifest.cameras;
  if (cams.length === 0) { S.lines = null; return; }
  const pos = [], col = [];
  cams.forEach((cam, i) => {
    const C = cameraCenter(cam), d = S.frustumDepth;
    const corners = [[0, 0], [cam.width, 0], [cam.width, cam.height], [0, cam.height]].map(([u, v]) =>
      add(C, mulTVec(cam.rotation, [(u - cam.cx) / cam.fx * d, (v - cam.cy) / cam.fy * d, d])));
    const color = i === S.selected ? [1, 1, 1] : GROUP_COLORS[cam.group] || [1, 1, 0];
    for (let k = 0; k < 4; k++) {
      pos.push(...C, ...corners[k], ...corners[k], ...corners[(k + 1) % 4]);
      for (let m = 0; m < 4; m++) col.push(...color);
    }
  });
  S.lines = { vao: geomBuffers({ a_pos: new Float32Array(pos), a_color: new Float32Array(col) }), count: pos.length / 3 };
  redraw();
}

async function loadMesh() {
  const r = await fetch("/api/mesh");
  if (!r.ok) throw new Error(`cannot fetch the mesh (${r.status})`);
  const buf = await r.arrayBuffer();
  const head = new Uint32Array(buf, 0, 3);
  const [nv, nf, hasColors] = head;
  const pos = new Float32Array(buf, 12, 3 * nv);
  let off = 12 + 12 * nv;
  const colors = hasColors ? new Float32Array(buf, off, 3 * nv) : new Float32Array(3 * nv).fill(0.8);
  if (hasColors) off += 12 * nv;
  const faces = new Uint32Array(buf, off, 3 * nf);
  const normals = new Float32Array(3 * nv);
  for (let f = 0; f < nf; f++) {
    const [a, b, c] = [faces[3 * f], faces[3 * f + 1], faces[3 * f + 2]];
    const pa = [pos[3 * a], pos[3 * a + 1], pos[3 * a + 2]];
    const e1 = sub([pos[3 * b], pos[3 * b + 1], pos[3 * b + 2]], pa), e2 = sub([pos[3 * c], pos[3 * c + 1], pos[3 * c + 2]], pa);
    const n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
    for (const v of [a, b, c]) for (let k = 0; k < 3; k++) normals[3 * v + k] += n[k];
  }
  const vao = geomBuffers({ a_pos: pos, a_color: colors, a_normal: normals });
  const ib = gl.createBuffer();
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, ib);
  gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, faces, gl.STATIC_DRAW);
  gl.bindVertexArray(null);
  // A mesh without faces is a point cloud (the points of a `fewview poses` model).
  S.mesh = nf === 0 ? { vao, count: nv, points: true } : { vao, count: 3 * nf };
  if (S.manifest.cameras.length === 0 && nv > 0) {
    let m = [0, 0, 0];
    for (let i = 0; i < nv; i++) m = add(m, [pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]]);
    placeAround(scale(m, 1 / nv), pos, nv);
  }
  $("status").textContent = nf === 0 ? `${nv} points` : `mesh: ${nv} vertices, ${nf} triangles`;
  S.loadedAll = true;
  stats.loadedAt = performance.now();
  redraw();
}

function drawGeometry(v, item, mode, shade) {
  gl.useProgram(geomProg);
  gl.uniformMatrix3fv(geomU.u_R, true, v.R);
  gl.uniform3fv(geomU.u_t, v.t);
  gl.uniform3fv(geomU.u_center, v.center);
  gl.uniform4f(geomU.u_intr, v.fx, v.fy, v.cx, v.cy);
  gl.uniform2f(geomU.u_size, v.width, v.height);
  gl.uniform2f(geomU.u_clip, S.sceneScale * 1e-3, S.sceneScale * 1e3);
  gl.uniform1i(geomU.u_shade, shade ? 1 : 0);
  gl.bindVertexArray(item.vao);
  if (mode === gl.TRIANGLES) gl.drawElements(gl.TRIANGLES, item.count, gl.UNSIGNED_INT, 0);
  else gl.drawArrays(mode, 0, item.count);
  gl.bindVertexArray(null);
}

// --- drawing and sorting ----------------------------------------------------------------------------
// A picture is quick or full. Quick (while the model streams in, while the camera moves, while
// the order lags the camera): the Gaussians at a reduced resolution (quickScale, halved when a
// quick frame is slow, doubled when it is fast), in whatever order the last sort gave; when
// the camera moved and the lowest resolution is still slow (a large model on a software GPU),
// only every step-th Gaussian of the order, at most quickBudget of them. Full
// (the model loaded, the camera still for STILL_MS and sorted for it): the exact picture at the
// canvas resolution, drawn in batches over several frames so that a slow software GPU stays
// responsive; any change abandons it for a quick frame.
const STILL_MS = 150;
const QUICK_SLOW_MS = 120, QUICK_FAST_MS = 30, QUICK_MIN_SCALE = 0.25;
// A sparser quick frame aims at QUICK_BUDGET_MS and draws at least QUICK_MIN_BUDGET Gaussians.
const QUICK_BUDGET_MS = 250, QUICK_MIN_BUDGET = 16384;
const BATCH_MS = 400, FIRST_BATCH = 65536;

function sortIsCurrent() {
  if (!S.splats) return true;
  return !S.sort && S.sorted.version === S.version && S.sorted.data === S.dataVersion && S.sorted.exact === S.exactSort;
}

/// Mesh and frusta over the canvas (after the splats, or over the background).
function drawOverlays(v) {
  if (!S.splats) {
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.viewport(0, 0, v.width, v.height);
    gl.clearColor(v.background[0], v.background[1], v.background[2], 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
  }
  if (S.mesh) {
    gl.enable(gl.DEPTH_TEST);
    gl.clear(gl.DEPTH_BUFFER_BIT);
    if (S.mesh.points) drawGeometry(v, S.mesh, gl.POINTS, false);
    else drawGeometry(v, S.mesh, gl.TRIANGLES, true);
    gl.disable(gl.DEPTH_TEST);
  }
  if (S.overlays && S.lines) drawGeometry(v, S.lines, gl.LINES, false);
}

function upload() {
  const t = performance.now();
  const n = S.splats.upload();
  if (n) { stats.uploadMs += performance.now() - t; mark("firstUpload"); }
}

/// Submits the next frame's work; returns what it was, or null when there is nothing to do.
function submitFrame(now) {
  resize();
  const still = S.loadedAll && sortIsCurrent() && now - S.lastChangeAt >= STILL_MS;
  if (S.pass && S.pass.serial !== S.serial) S.pass = null;
  const v = currentView();
  if (!S.splats) {
    if (S.shown === S.serial) return null;
    drawOverlays(v);
    return { kind: "full", serial: S.serial, version: S.version, instances: 0, drew: !!S.mesh, scale: 1, last: true };
  }
  const n = S.splats.instances;
  // Nothing to show before the first Gaussians are sorted (the first picture is theirs).
  if (n === 0 && !S.loadedAll) return null;
  // A quick frame when the picture is out of date, unless a full one can start now and either
  // costs no more or shows the same camera as the picture on the canvas (new data only).
  if (!S.pass && S.shown !== S.serial && !(still && (S.quickScale === 1 || S.shownVersion === S.version))) {
    // A quick frame: everything sorted so far, at the reduced resolution (a subset of it when
    // the camera moved).
    upload();
    const moving = S.shownVersion !== S.version && S.shownVersion >= 0;
    const step = moving ? Math.max(1, Math.ceil(n / S.quickBudget)) : 1;
    S.splats.begin(v, S.quickScale);
    S.splats.drawRange(0, n, step);
    S.splats.composite();
    drawOverlays(v);
    return {
      kind: "quick", serial: S.serial, version: S.version, instances: Math.ceil(n / step), drew: n > 0,
      scale: S.quickScale, step, last: true,
    };
  }
  if (!S.pass && still && S.full !== S.serial) {
    upload();
    S.splats.begin(v, 1);
    S.pass = { serial: S.serial, version: S.version, from: 0, whole: S.quickScale === 1 };
  }
  if (!S.pass) return null;
  const p = S.pass, from = p.from, to = p.whole ? n : Math.min(n, from + (S.batch || FIRST_BATCH));
  S.splats.drawRange(from, to);
  p.from = to;
  const last = to >= n;
  if (last) {
    S.splats.composite();
    drawOverlays(v);
    S.pass = null;
  }
  return { kind: "full", serial: p.serial, version: p.version, instances: to - from, drew: n > 0, scale: 1, last };
}

/// A frame has finished on the GPU: record it, adapt the quick scale and the batch size.
function frameDone(f, ms) {
  stats.lastFrameMs = ms;
  if (stats.frames.length < 500) {
    stats.frames.push({ at: Math.round(f.at), kind: f.kind, scale: f.scale, n: f.instances, step: f.step || 1, ms: Math.round(ms) });
  }
  if (f.kind === "quick") {
    if (ms > QUICK_SLOW_MS && S.quickScale > QUICK_MIN_SCALE) S.quickScale /= 2;
    else if (ms > QUICK_SLOW_MS) S.quickBudget = Math.max(QUICK_MIN_BUDGET, Math.round(f.instances * QUICK_BUDGET_MS / ms));
    else if (ms < QUICK_FAST_MS && S.quickScale < 1) S.quickScale *= 2;
    else if (ms < QUICK_FAST_MS) S.quickBudget *= 2;
  } else if (f.instances > 0 && !f.last) {
    S.batch = Math.max(4096, Math.round(f.instances * BATCH_MS / Math.max(ms, 1)));
  }
  if (f.last) {
    S.shown = f.serial;
    S.shownVersion = f.version;
    if (f.kind === "full") S.full = f.serial;
    if (f.drew && stats.firstPicture === null) {
      stats.firstPicture = performance.now();
      stats.firstPictureScale = f.scale;
      stats.firstPictureGaussians = f.instances;
    }
  }
}

/// Asks the worker for the depth order of the current camera.
function requestSort() {
  const v = currentView();
  S.lastSortAt = performance.now();
  S.sort = { version: S.version, data: S.dataVersion, exact: S.exactSort };
  S.worker.postMessage({ type: "sort", version: S.version, R: Array.from(S.R), t: Array.from(v.t), near: v.near, exact: S.exactSort });
}

/// The first picture's order, sorted here rather than in the worker (no round trip): the first
/// FIRST_PICTURE_MAX Gaussians of the file in front of the near plane, by camera z. It counts
/// as out of date, so the worker sorts everything loaded right after.
function firstOrder() {
  const t0 = performance.now();
  const n = Math.min(S.data.loaded, FIRST_PICTURE_MAX), p = S.data.positions, v = currentView(), R = S.R;
  const z = new Float32Array(n), idx = [];
  for (let i = 0; i < n; i++) {
    z[i] = R[6] * p[3 * i] + R[7] * p[3 * i + 1] + R[8] * p[3 * i + 2] + v.t[2];
    if (z[i] >= v.near) idx.push(i);
  }
  idx.sort((a, b) => z[a] - z[b] || a - b);
  S.splats.setOrder(Uint32Array.from(idx), idx.length);
  S.sorted = { version: S.version, data: -2, exact: false };
  stats.sortMs += performance.now() - t0;
  mark("firstOrder");
  redraw();
  tick(performance.now());
}

function isSettled() {
  return S.loadedAll && sortIsCurrent() && S.full === S.serial && !S.fence && !S.pass;
}

const LOADING_SORT_MS = 500;
// The first picture draws at most this many Gaussians (the first of the file), so that it
// comes quickly whatever the size of the first chunk of the stream.
const FIRST_PICTURE_MAX = 16384;
let last = performance.now();
function frame(now) {
  requestAnimationFrame(frame);
  tick(now);
}

function tick(now) {
  const dt = Math.min(0.1, (now - last) / 1000);
  last = now;
  if (S.keys.size) fly(dt);
  // While the model streams in, new Gaussians join the picture with the next sort, at most
  // every LOADING_SORT_MS (each sort is followed by a quick frame of everything loaded so far).
  const viewChanged = S.sorted.version !== S.version || S.sorted.exact !== S.exactSort;
  const dataChanged = S.sorted.data !== S.dataVersion;
  const loadingWait = !S.loadedAll && S.sorted.data >= 0 &&
    now - S.lastSortAt < Math.max(LOADING_SORT_MS, 2 * stats.lastFrameMs);
  if (S.splats && S.data.loaded > 0 && !S.sort && (viewChanged || (dataChanged && !loadingWait))) requestSort();
  if (canvas.clientWidth && !S.fixed) {
    const dpr = window.devicePixelRatio || 1;
    if (canvas.width !== Math.round(canvas.clientWidth * dpr) || canvas.height !== Math.round(canvas.clientHeight * dpr)) redraw();
  }
  // One frame in flight: a software GPU (SwiftShader) can take seconds for a million splats,
  // and queued frames would hold up the stream's uploads and the controls.
  if (S.fence) {
    if (gl.getSyncParameter(S.fence, gl.SYNC_STATUS) !== gl.SIGNALED) return;
    gl.deleteSync(S.fence);
    S.fence = null;
    frameDone(S.submitted, performance.now() - S.submitted.at);
  }
  const f = submitFrame(now);
  if (f) {
    f.at = performance.now();
    if (f.drew) mark("firstDraw");
    S.submitted = f;
    S.fence = gl.fenceSync(gl.SYNC_GPU_COMMANDS_COMPLETE, 0);
    gl.flush();
    return;
  }
  if (isSettled()) {
    if (stats.fullPicture === null) { stats.fullPicture = performance.now(); resolveReady(); }
    const w = S.waiters;
    S.waiters = [];
    w.forEach((fn) => fn());
  }
}

function settled() {
  return new Promise((resolve) => S.waiters.push(resolve));
}

// --- initial view -----------------------------------------------------------------------------------
function placeAround(center, pos, n) {
  let spread = 0;
  const step = Math.max(1, Math.floor(n / 10000));
  let m = 0;
  for (let i = 0; i < n; i += step) { spread += norm(sub([pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]], center)) ** 2; m++; }
  spread = Math.sqrt(spread / Math.max(m, 1)) || 1;
  S.target = center;
  S.sceneScale = spread;
  S.R = [1, 0, 0, 0, 1, 0, 0, 0, 1];
  S.c = sub(center, [0, 0, 2.5 * spread]);
  S.frustumDepth = 0.1 * spread;
  S.placed = true;
  changed();
}

function initialView() {
  const cams = S.manifest.cameras;
  if (cams.length === 0) {
    if (S.data && S.data.loaded > 0) {
      const n = S.data.loaded, p = S.data.positions;
      let m = [0, 0, 0];
      for (let i = 0; i < n; i++) m = add(m, [p[3 * i], p[3 * i + 1], p[3 * i + 2]]);
      placeAround(scale(m, 1 / n), p, n);
    }
    return;
  }
  const main = cams.filter((c) => c.group === "train" || c.group === "refined");
  const use = main.length ? main : cams;
  // Up: the mean of the cameras' up (−y) axes; target: the point nearest every optical axis.
  S.up = normalize(use.reduce((u, c) => sub(u, row(c.rotation, 1)), [0, 0, 0]));
  const A = [0, 0, 0, 0, 0, 0, 0, 0, 0];
  let b = [0, 0, 0];
  for (const c of use) {
    const d = row(c.rotation, 2), C = cameraCenter(c);
    const P = [1 - d[0] * d[0], -d[0] * d[1], -d[0] * d[2], -d[1] * d[0], 1 - d[1] * d[1], -d[1] * d[2], -d[2] * d[0], -d[2] * d[1], 1 - d[2] * d[2]];
    for (let k = 0; k < 9; k++) A[k] += P[k];
    b = add(b, mulVec(P, C));
  }
  const centers = use.map(cameraCenter);
  const mean = scale(centers.reduce(add, [0, 0, 0]), 1 / centers.length);
  S.target = (use.length > 1 && solve3(A, b)) || add(mean, row(use[0].rotation, 2));
  const dists = centers.map((C) => norm(sub(C, S.target))).sort((a, b2) => a - b2);
  S.sceneScale = dists[Math.floor(dists.length / 2)] || 1;
  S.frustumDepth = 0.12 * S.sceneScale;
  S.placed = true;
  buildFrusta();
  jumpTo(cams.indexOf(use[0]));
}

// --- page furniture -------------------------------------------------------------------------------
function flatten(obj, prefix, out, depth) {
  for (const [k, v] of Object.entries(obj)) {
    const key = prefix ? `${prefix}.${k}` : k;
    if (v !== null && typeof v === "object" && !Array.isArray(v) && depth < 3) flatten(v, key, out, depth + 1);
    else if (typeof v === "number" || typeof v === "string" || typeof v === "boolean") out.push([key, v]);
  }
  return out;
}

function fillPanels(m) {
  $("title").textContent = m.title;
  $("kind").textContent = {
    splat: "Gaussian splats", surface: "surface (mesh and poses)", poses: "camera poses (estimated cameras and points)",
    ply: "Gaussian PLY",
  }[m.kind];
  const list = $("cameras");
  m.cameras.forEach((cam, i) => {
    const li = document.createElement("li");
    li.dataset.index = i;
    const swatch = document.createElement("span");
    swatch.className = "swatch";
    swatch.style.background = `rgb(${(GROUP_COLORS[cam.group] || [1, 1, 0]).map((x) => Math.round(255 * x)).join(",")})`;
    li.append(swatch, `${cam.name} (${cam.group})`);
    li.addEventListener("click", () => jumpTo(i));
    list.append(li);
  });
  if (!m.cameras.length) $("cameras").textContent = "none";
  const metrics = $("metrics");
  if (m.metrics) {
    const table = document.createElement("table");
    for (const [k, v] of flatten(m.metrics, "", [], 0)) {
      const tr = table.insertRow();
      tr.insertCell().textContent = k;
      tr.insertCell().textContent = typeof v === "number" && !Number.isInteger(v) ? v.toFixed(4) : String(v);
    }
    metrics.append(table);
  } else metrics.textContent = "no metrics.json";
  for (const note of m.notes) {
    const li = document.createElement("li");
    li.textContent = note;
    $("notes").append(li);
  }
  const images = $("images");
  for (const img of m.images) {
    const fig = document.createElement("figure");
    const cap = document.createElement("figcaption");
    cap.textContent = img.name;
    fig.append(cap);
    for (const [url, label] of [[img.render, "render"], [img.truth, "ground truth"]]) {
      if (!url) continue;
      const el = document.createElement("img");
      el.src = url; el.alt = `${img.name} ${label}`; el.title = label; el.loading = "lazy";
      fig.append(el);
    }
    images.append(fig);
  }
  $("images-section").hidden = m.images.length === 0;
  if (m.kind === "poses") $("images-title").textContent = "The model";
  const videos = $("videos");
  for (const v of m.videos) {
    const fig = document.createElement("figure");
    const cap = document.createElement("figcaption");
    cap.textContent = v.name;
    let el;
    if (v.name.toLowerCase().endsWith(".gif")) { el = document.createElement("img"); el.src = v.url; }
    else { el = document.createElement("video"); el.src = v.url; el.controls = true; el.loop = true; el.muted = true; el.preload = "metadata"; }
    fig.append(cap, el);
    videos.append(fig);
  }
  $("videos-section").hidden = m.videos.length === 0;
}

function startWorker(count) {
  S.worker = new Worker("/sort-worker.js");
  S.worker.postMessage({ type: "init", count });
  S.worker.onmessage = (e) => {
    const msg = e.data;
    S.splats.setOrder(msg.order, msg.visible);
    S.sorted = S.sort;
    S.sort = null;
    stats.sortMs += msg.ms;
    stats.sorts++;
    redraw();
  };
}

/// Streams the model from `request` (its fetch, started with the worker before the context).
async function loadSplats(model, request) {
  S.data = new SplatData(model.count, model.sh_degree);
  S.splats = new SplatRenderer(gl, S.data);
  mark("renderer");
  const offsets = floatOffsets(model);
  const progress = $("progress");
  await streamPly(request, model, (start, n, floats, strideFloats) => {
    mark("firstRows");
    const t = performance.now();
    S.data.addRows(start, n, floats, strideFloats, offsets);
    stats.parseMs += performance.now() - t;
    const p = S.data.positions.slice(3 * start, 3 * (start + n));
    S.worker.postMessage({ type: "positions", start, data: p }, [p.buffer]);
    S.dataVersion++;
    if (!S.placed) initialView();
    if (!S.sort && S.sorted.data === -1) firstOrder();
    $("status").textContent = `${(start + n).toLocaleString()} of ${model.count.toLocaleString()} Gaussians`;
  }, (bytes) => { progress.value = bytes / model.file_bytes; });
  stats.loadedAt = performance.now();
  stats.gaussians = model.count;
  S.loadedAll = true;
  progress.value = 1;
  $("status").textContent = `${model.count.toLocaleString()} Gaussians, SH degree ${model.sh_degree}`;
}

async function main() {
  mark("script");
  const r = await fetch("/api/run");
  if (!r.ok) throw new Error(`cannot read the run (${r.status})`);
  const m = await r.json();
  mark("manifest");
  S.manifest = m;
  // The model's stream and its sort worker start before the WebGL context, whose creation
  // (the start of a software GPU) is the slowest step before the first picture.
  const request = m.model ? fetch(m.model.url) : null;
  if (m.model) startWorker(m.model.count);
  gl = canvas.getContext("webgl2", { antialias: false, preserveDrawingBuffer: true, alpha: false, premultipliedAlpha: false });
  if (!gl) throw new Error("this browser has no WebGL2, which the viewer needs");
  geomProg = compile(gl, GEOM_VS, GEOM_FS);
  geomU = {};
  for (const n of ["u_R", "u_t", "u_intr", "u_size", "u_clip", "u_center", "u_shade"]) geomU[n] = gl.getUniformLocation(geomProg, n);
  mark("context");
  fillPanels(m);
  installControls();
  setMode("orbit");
  if (m.cameras.length) initialView();
  requestAnimationFrame(frame);
  if (m.model) await loadSplats(m.model, request);
  else if (m.has_mesh) await loadMesh();
  else S.loadedAll = true;
}

window.fewviewView = {
  stats,
  ready,
  get cameras() { return S.manifest ? S.manifest.cameras : []; },
  /// The colour drawn where nothing is (the run's background; grey behind a mesh).
  get background() { return Array.from(currentView().background); },
  settled,
  /// Draws camera `i` exactly (its intrinsics, pose and resolution, no frusta, exact depth
  /// order) and returns the picture as a PNG data URL.
  async renderCamera(i) {
    await ready;
    const cam = S.manifest.cameras[i];
    if (!cam) throw new Error(`no camera ${i}`);
    S.fixed = { w: cam.width, h: cam.height };
    S.overlays = false;
    S.exactSort = true;
    S.selected = i;
    lookThrough(cam);
    await settled();
    return canvas.toDataURL("image/png");
  },
  /// The canvas as it is now, once the picture is up to date, as a PNG data URL.
  async capture() {
    await settled();
    return canvas.toDataURL("image/png");
  },
};

main().catch((e) => showError(e.message || e));
