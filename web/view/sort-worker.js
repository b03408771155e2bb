// Depth sort of the Gaussians for the viewer, off the main thread. Messages in:
//   {type: "init", count}                       capacity
//   {type: "positions", start, data}            xyz of Gaussians [start, start + data.length / 3)
//   {type: "sort", version, R, t, near, exact}  camera (R row-major world-to-camera, t)
// Out: {type: "order", version, order, visible, ms}: the indices of the Gaussians in front of
// the near plane, nearest first, and the milliseconds the sort took. The interactive sort is a
// 16-bit counting sort of camera z (two passes over the Gaussians, no comparisons);
// `exact` sorts by z and then by index, the order fewview_splat's rasterizer draws in.
"use strict";

let positions = new Float32Array(0);
let loaded = 0;
let depths = new Float32Array(0);
let keys = new Uint16Array(0);
let visibleIdx = new Uint32Array(0);
const counts = new Uint32Array(65536);

function sort(msg) {
  const started = performance.now();
  const R = msg.R, t = msg.t;
  const n = loaded;
  if (depths.length < n) {
    depths = new Float32Array(positions.length / 3);
    keys = new Uint16Array(positions.length / 3);
    visibleIdx = new Uint32Array(positions.length / 3);
  }
  const f = Math.fround;
  const r20 = f(R[6]), r21 = f(R[7]), r22 = f(R[8]), t2 = f(t[2]);
  let visible = 0;
  let zmin = Infinity, zmax = -Infinity;
  for (let i = 0; i < n; i++) {
    // In f32, as the rasterizer computes camera z.
    const z = Math.fround(Math.fround(Math.fround(Math.fround(r20 * positions[3 * i]) + Math.fround(r21 * positions[3 * i + 1]))
      + Math.fround(r22 * positions[3 * i + 2])) + t2);
    if (z >= msg.near) {
      depths[i] = z;
      visibleIdx[visible++] = i;
      if (z < zmin) zmin = z;
      if (z > zmax) zmax = z;
    }
  }
  const order = new Uint32Array(Math.max(visible, 1));
  if (msg.exact) {
    const idx = visibleIdx.slice(0, visible);
    idx.sort((a, b) => depths[a] - depths[b] || a - b);
    order.set(idx);
  } else if (visible > 0) {
    const scale = zmax > zmin ? 65535 / (zmax - zmin) : 0;
    counts.fill(0);
    for (let k = 0; k < visible; k++) {
      const i = visibleIdx[k];
      const key = Math.min(65535, Math.floor((depths[i] - zmin) * scale));
      keys[k] = key;
      counts[key]++;
    }
    let sum = 0;
    for (let b = 0; b < 65536; b++) {
      const c = counts[b];
      counts[b] = sum;
      sum += c;
    }
    for (let k = 0; k < visible; k++) order[counts[keys[k]]++] = visibleIdx[k];
  }
  postMessage({ type: "order", version: msg.version, order, visible, ms: performance.now() - started }, [order.buffer]);
}

onmessage = (e) => {
  const msg = e.data;
  if (msg.type === "init") {
    positions = new Float32Array(msg.count * 3);
    loaded = 0;
  } else if (msg.type === "positions") {
    positions.set(msg.data, msg.start * 3);
    loaded = Math.max(loaded, msg.start + msg.data.length / 3);
  } else if (msg.type === "sort") {
    sort(msg);
  }
};
