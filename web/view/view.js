// The viewer page: reads the run's manifest (/api/run), streams and draws its Gaussians
// (splats.js, sorted by sort-worker.js) or its mesh, draws the cameras as frusta, and lists the
// metrics, held-out renders and videos. Orbit / fly controls; clicking a camera looks through
// it with its own intrinsics. `window.fewviewView` exposes hooks for tests and scripts
// (renderCamera(i) draws exactly camera i at its resolution and returns a PNG data URL).
import { SplatData, SplatRenderer, streamPly, floatOffsets, compile } from "/splats.js";

const $ = (id) => document.getElementById(id);
const GROUP_COLORS = {
  train: [1.0, 0.6, 0.1], test: [0.3, 0.6, 1.0], initial: [0.95, 0.25, 0.25], refined: [0.2, 0.9, 0.35],
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
const gl = canvas.getContext("webgl2", { antialias: false, preserveDrawingBuffer: true, alpha: false, premultipliedAlpha: false });
const S = {
  manifest: null, splats: null, data: null, worker: null, mesh: null, lines: null,
  R: [1, 0, 0, 0, 1, 0, 0, 0, 1], c: [0, 0, -3],
  intr: { fx: 700, fy: 700, cx: 400, cy: 300, w: 800, h: 600 },
  target: [0, 0, 0], up: [0, -1, 0], sceneScale: 1,
  mode: "orbit", fixed: null, overlays: true, exactSort: false, selected: -1,
  version: 0, dataVersion: 0, sort: null, sorted: { version: -1, data: -1, exact: false },
  dirty: true, loadedAll: false, lastSortAt: 0, fence: null, drawStart: 0, keys: new Set(), waiters: [], placed: false,
};
const stats = { firstPicture: null, fullPicture: null, loadedAt: null, gaussians: 0, lastFrameMs: 0 };
let resolveReady;
const ready = new Promise((r) => { resolveReady = r; });

function changed() { S.version++; S.dirty = true; }

function currentView() {
  const w = canvas.width, h = canvas.height;
  const k = S.intr, s = h / k.h;
  const R = S.R;
  return {
    R: new Float32Array(R), t: new Float32Array(scale(mulVec(R, S.c), -1)), center: new Float32Array(S.c),
    fx: k.fx * s, fy: k.fy * s, cx: w / 2 + (k.cx - k.w / 2) * s, cy: k.cy * s, width: w, height: h,
    near: S.manifest ? S.manifest.near_plane : 0.2,
    background: new Float32Array(S.manifest && S.manifest.kind !== "surface" ? S.manifest.background : [0.12, 0.12, 0.14]),
  };
}

function resize() {
  const dpr = window.devicePixelRatio || 1;
  const w = S.fixed ? S.fixed.w : Math.max(1, Math.round(canvas.clientWidth * dpr));
  const h = S.fixed ? S.fixed.h : Math.max(1, Math.round(canvas.clientHeight * dpr));
  if (canvas.width !== w || canvas.height !== h) {
    canvas.width = w;
    canvas.height = h;
    S.dirty = true;
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
  window.addEventListener("resize", () => { S.dirty = true; });
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
  S.dirty = true;
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
  S.mesh = { vao, count: 3 * nf };
  if (S.manifest.cameras.length === 0 && nv > 0) {
    let m = [0, 0, 0];
    for (let i = 0; i < nv; i++) m = add(m, [pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]]);
    placeAround(scale(m, 1 / nv), pos, nv);
  }
  $("status").textContent = `mesh: ${nv} vertices, ${nf} triangles`;
  S.loadedAll = true;
  stats.loadedAt = performance.now();
  S.dirty = true;
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
function draw() {
  resize();
  const v = currentView();
  if (S.splats) {
    S.splats.draw(v);
  } else {
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.viewport(0, 0, v.width, v.height);
    gl.clearColor(v.background[0], v.background[1], v.background[2], 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
  }
  if (S.mesh) {
    gl.enable(gl.DEPTH_TEST);
    gl.clear(gl.DEPTH_BUFFER_BIT);
    drawGeometry(v, S.mesh, gl.TRIANGLES, true);
    gl.disable(gl.DEPTH_TEST);
  }
  if (S.overlays && S.lines) drawGeometry(v, S.lines, gl.LINES, false);
  const drewSomething = (S.splats && S.splats.instances > 0) || S.mesh;
  S.drewSomething = !!drewSomething;
}

function requestSort() {
  const v = currentView();
  S.sort = { version: S.version, data: S.dataVersion, exact: S.exactSort };
  S.worker.postMessage({ type: "sort", version: S.version, R: Array.from(S.R), t: Array.from(v.t), near: v.near, exact: S.exactSort });
}

function isSettled() {
  if (!S.loadedAll || S.dirty) return false;
  if (!S.splats) return true;
  return !S.sort && S.sorted.version === S.version && S.sorted.data === S.dataVersion && S.sorted.exact === S.exactSort;
}

const LOADING_SORT_MS = 500;
let last = performance.now();
function frame(now) {
  requestAnimationFrame(frame);
  const dt = Math.min(0.1, (now - last) / 1000);
  last = now;
  if (S.keys.size) fly(dt);
  // While the model streams in, new Gaussians join the picture with the next sort, at most
  // every LOADING_SORT_MS (each sort is followed by a redraw of everything loaded so far).
  const viewChanged = S.sorted.version !== S.version || S.sorted.exact !== S.exactSort;
  const dataChanged = S.sorted.data !== S.dataVersion;
  const loadingWait = !S.loadedAll && S.sorted.data >= 0 &&
    now - S.lastSortAt < Math.max(LOADING_SORT_MS, 2 * stats.lastFrameMs);
  if (S.splats && !S.sort && (viewChanged || (dataChanged && !loadingWait))) {
    S.lastSortAt = now;
    requestSort();
  }
  if (canvas.clientWidth && !S.fixed) {
    const dpr = window.devicePixelRatio || 1;
    if (canvas.width !== Math.round(canvas.clientWidth * dpr) || canvas.height !== Math.round(canvas.clientHeight * dpr)) S.dirty = true;
  }
  // One frame in flight: a software GPU (SwiftShader) can take seconds for a million splats,
  // and queued frames would hold up the texture uploads of the stream and the controls.
  if (S.fence) {
    if (gl.getSyncParameter(S.fence, gl.SYNC_STATUS) !== gl.SIGNALED) return;
    gl.deleteSync(S.fence);
    S.fence = null;
    stats.lastFrameMs = now - S.drawStart;
    // The first frame with something in it, once the GPU has finished it.
    if (S.drewSomething && stats.firstPicture === null) stats.firstPicture = performance.now();
  }
  if (S.dirty) {
    S.dirty = false;
    S.drawStart = now;
    draw();
    S.fence = gl.fenceSync(gl.SYNC_GPU_COMMANDS_COMPLETE, 0);
    gl.flush();
    return;
  }
  if (isSettled()) {
    if (stats.fullPicture === null) { stats.fullPicture = performance.now(); resolveReady(); }
    const w = S.waiters;
    S.waiters = [];
    w.forEach((f) => f());
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
  $("kind").textContent = { splat: "Gaussian splats", surface: "surface (mesh and poses)", ply: "Gaussian PLY" }[m.kind];
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

async function loadSplats(model) {
  S.data = new SplatData(model.count, model.sh_degree);
  S.splats = new SplatRenderer(gl, S.data);
  S.worker = new Worker("/sort-worker.js");
  S.worker.postMessage({ type: "init", count: model.count });
  S.worker.onmessage = (e) => {
    const msg = e.data;
    S.splats.setOrder(msg.order, msg.visible);
    S.sorted = S.sort;
    S.sort = null;
    S.dirty = true;
  };
  const offsets = floatOffsets(model);
  const progress = $("progress");
  await streamPly(model.url, model, (start, n, floats, strideFloats) => {
    S.data.addRows(start, n, floats, strideFloats, offsets);
    S.splats.upload(start, start + n);
    const p = S.data.positions.slice(3 * start, 3 * (start + n));
    S.worker.postMessage({ type: "positions", start, data: p }, [p.buffer]);
    S.dataVersion++;
    if (!S.placed) initialView();
    $("status").textContent = `${(start + n).toLocaleString()} of ${model.count.toLocaleString()} Gaussians`;
  }, (bytes) => { progress.value = bytes / model.file_bytes; });
  stats.loadedAt = performance.now();
  stats.gaussians = model.count;
  S.loadedAll = true;
  progress.value = 1;
  $("status").textContent = `${model.count.toLocaleString()} Gaussians, SH degree ${model.sh_degree}`;
}

async function main() {
  if (!gl) throw new Error("this browser has no WebGL2, which the viewer needs");
  geomProg = compile(gl, GEOM_VS, GEOM_FS);
  geomU = {};
  for (const n of ["u_R", "u_t", "u_intr", "u_size", "u_clip", "u_center", "u_shade"]) geomU[n] = gl.getUniformLocation(geomProg, n);
  const r = await fetch("/api/run");
  if (!r.ok) throw new Error(`cannot read the run (${r.status})`);
  const m = await r.json();
  S.manifest = m;
  fillPanels(m);
  installControls();
  setMode("orbit");
  if (m.cameras.length) initialView();
  requestAnimationFrame(frame);
  if (m.model) await loadSplats(m.model);
  else if (m.has_mesh) await loadMesh();
  else S.loadedAll = true;
}

window.fewviewView = {
  stats,
  ready,
  get cameras() { return S.manifest ? S.manifest.cameras : []; },
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
