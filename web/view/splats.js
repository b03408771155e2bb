// Gaussian splats in WebGL2: the PLY stream parser, the packing into textures and the
// renderer. The projection, colour and compositing follow fewview_splat::raster (see
// crates/splat/src/raster/mod.rs and reference.rs) so that a training camera's picture here
// matches `fewview render` of it:
//   - camera x = R p + t (OpenCV axes), culled when z < near plane;
//   - Σ = R(q) S² R(q)ᵀ, Σ' = J W Σ Wᵀ Jᵀ + 0.3 I with J the EWA Jacobian at the centre
//     whose x/z, y/z are clamped to 1.3× the half field of view;
//   - colour max(0, 0.5 + Σ_k Y_k(d) sh_k), d the unit direction from the camera centre, with
//     the Inria SH basis constants and sign convention, up to the PLY's SH degree;
//   - α = min(0.99, σ(ô) exp(−½ dᵀ Σ'⁻¹ d)), skipped below 1/255; each splat's quad covers the
//     ellipse where α ≥ 1/255 can hold (half-widths sqrt(2 ln(255 o) Σ'_xx) + 1 px), the
//     same bound the CPU rasterizer bins with;
//   - front-to-back compositing sorted by camera z, into a float target (C += T α c,
//     A += T α with T = 1 − A), then C + (1 − A)·background.
// One difference is left: the CPU rasterizer stops a pixel before its transmittance would fall
// below 1e-4 (that splat is not blended), the page blends every splat. The stop depends on the
// running product of (1 − α) at that pixel, which a fragment cannot read (WebGL2 has no
// framebuffer fetch) and the blend stage, linear in the destination, cannot test. Per-pixel
// stop indices would need about log2(N) full passes (a binary search with the depth test). The
// difference is at most the transmittance left at the stop, under 1e-4 / (1 − 0.99) = 0.01,
// and only on pixels that become opaque.
"use strict";

const SH_C0 = 0.28209479177387814;

// Texels per Gaussian in the main RGBA32F texture: (x, y, z, opacity), (Σ00, Σ01, Σ02, Σ11),
// (Σ12, Σ22, dc_r, dc_g), (dc_b, 0, 0, 0), with dc = SH_C0 · f_dc.
const MAIN_TEXELS = 4;
const TEX_WIDTH = 4096;

// Texels per Gaussian of the SH texture (RGBA32UI, two halves per uint, coefficient-major)
// for SH degree 1, 2, 3: 9, 24, 45 halves.
const SH_TEXELS = [0, 2, 3, 6];

function shRestCount(degree) {
  return 3 * ((degree + 1) * (degree + 1) - 1);
}

// --- float → half (round to nearest even), for packing SH coefficients -------------------
const f32 = new Float32Array(1);
const u32 = new Uint32Array(f32.buffer);
function toHalf(v) {
  f32[0] = v;
  const x = u32[0];
  const sign = (x >>> 16) & 0x8000;
  let exp = ((x >>> 23) & 0xff) - 127 + 15;
  let mant = x & 0x7fffff;
  if (((x >>> 23) & 0xff) === 0xff) return sign | 0x7c00 | (mant ? 0x200 : 0);
  if (exp >= 31) return sign | 0x7c00;
  if (exp <= 0) {
    if (exp < -10) return sign;
    mant |= 0x800000;
    const shift = 14 - exp;
    let h = mant >>> shift;
    const rem = mant & ((1 << shift) - 1);
    const half = 1 << (shift - 1);
    if (rem > half || (rem === half && (h & 1))) h += 1;
    return sign | h;
  }
  let h = (exp << 10) | (mant >>> 13);
  const rem = mant & 0x1fff;
  if (rem > 0x1000 || (rem === 0x1000 && (h & 1))) h += 1;
  return sign | h;
}

/// CPU-side storage of the Gaussians as they arrive, packed for the textures.
export class SplatData {
  constructor(count, shDegree) {
    this.count = count;
    this.loaded = 0;
    this.shDegree = shDegree;
    this.perRow = TEX_WIDTH / MAIN_TEXELS;
    this.rows = Math.ceil(count / this.perRow);
    this.main = new Float32Array(this.rows * TEX_WIDTH * 4);
    this.positions = new Float32Array(count * 3);
    this.shTexels = SH_TEXELS[shDegree];
    if (this.shTexels > 0) {
      this.shPerRow = Math.floor(TEX_WIDTH / this.shTexels);
      this.shWidth = this.shPerRow * this.shTexels;
      this.shRows = Math.ceil(count / this.shPerRow);
      this.sh = new Uint32Array(this.shRows * this.shWidth * 4);
    }
  }

  /// Packs `n` rows of a PLY (`floats`, a Float32Array over whole rows of `stride` bytes,
  /// little-endian, 4-aligned) starting at Gaussian `start`.
  addRows(start, n, floats, strideFloats, o) {
    const main = this.main;
    const pos = this.positions;
    const rest = shRestCount(this.shDegree);
    const perChannel = rest / 3;
    const halves = new Uint16Array(this.shTexels * 8);
    for (let r = 0; r < n; r++) {
      const b = r * strideFloats;
      const i = start + r;
      const x = floats[b + o.x], y = floats[b + o.y], z = floats[b + o.z];
      pos[3 * i] = x; pos[3 * i + 1] = y; pos[3 * i + 2] = z;
      // Σ = M Mᵀ with M = R(q/|q|) diag(exp ŝ).
      let qw = floats[b + o.rot_0], qx = floats[b + o.rot_1], qy = floats[b + o.rot_2], qz = floats[b + o.rot_3];
      const qn = Math.hypot(qw, qx, qy, qz);
      let opacity = 1 / (1 + Math.exp(-floats[b + o.opacity]));
      if (!(qn > 1e-12) || !Number.isFinite(opacity)) { opacity = 0; qw = 1; qx = qy = qz = 0; } else {
        qw /= qn; qx /= qn; qy /= qn; qz /= qn;
      }
      const sx = Math.exp(floats[b + o.scale_0]), sy = Math.exp(floats[b + o.scale_1]), sz = Math.exp(floats[b + o.scale_2]);
      const r00 = 1 - 2 * (qy * qy + qz * qz), r01 = 2 * (qx * qy - qw * qz), r02 = 2 * (qx * qz + qw * qy);
      const r10 = 2 * (qx * qy + qw * qz), r11 = 1 - 2 * (qx * qx + qz * qz), r12 = 2 * (qy * qz - qw * qx);
      const r20 = 2 * (qx * qz - qw * qy), r21 = 2 * (qy * qz + qw * qx), r22 = 1 - 2 * (qx * qx + qy * qy);
      const m00 = r00 * sx, m01 = r01 * sy, m02 = r02 * sz;
      const m10 = r10 * sx, m11 = r11 * sy, m12 = r12 * sz;
      const m20 = r20 * sx, m21 = r21 * sy, m22 = r22 * sz;
      const t = i * MAIN_TEXELS * 4;
      main[t] = x; main[t + 1] = y; main[t + 2] = z; main[t + 3] = opacity;
      main[t + 4] = m00 * m00 + m01 * m01 + m02 * m02;
      main[t + 5] = m00 * m10 + m01 * m11 + m02 * m12;
      main[t + 6] = m00 * m20 + m01 * m21 + m02 * m22;
      main[t + 7] = m10 * m10 + m11 * m11 + m12 * m12;
      main[t + 8] = m10 * m20 + m11 * m21 + m12 * m22;
      main[t + 9] = m20 * m20 + m21 * m21 + m22 * m22;
      main[t + 10] = SH_C0 * floats[b + o.f_dc_0];
      main[t + 11] = SH_C0 * floats[b + o.f_dc_1];
      main[t + 12] = SH_C0 * floats[b + o.f_dc_2];
      if (this.shTexels > 0) {
        // f_rest is channel-major in the file; the texture holds coefficient-major halves.
        halves.fill(0);
        for (let k = 0; k < perChannel; k++) {
          for (let c = 0; c < 3; c++) {
            halves[3 * k + c] = toHalf(floats[b + o.rest[c * perChannel + k]]);
          }
        }
        const words = new Uint32Array(halves.buffer);
        const row = Math.floor(i / this.shPerRow);
        const col = (i % this.shPerRow) * this.shTexels;
        this.sh.set(words, (row * this.shWidth + col) * 4);
      }
    }
    this.loaded = Math.max(this.loaded, start + n);
  }
}

const YIELD_MS = 12, ROWS_PER_CALL = 4096;
const yieldChannel = new MessageChannel();
const yieldWaiters = [];
yieldChannel.port1.onmessage = () => { const f = yieldWaiters.shift(); if (f) f(); };
/// Resolves in a new task (a message to itself: no timer clamping).
function yieldTask() {
  return new Promise((resolve) => { yieldWaiters.push(resolve); yieldChannel.port2.postMessage(0); });
}

/// Streams a Gaussian PLY whose layout the server checked (`layout`: header_bytes, stride,
/// offsets, count) from `request` (a fetch() promise, started as early as the caller can). Calls `onRows(start, n, floats, strideFloats)` for each batch of whole rows
/// and `onProgress(bytes)`; rejects with a one-line message when the stream breaks or ends
/// early.
export async function streamPly(request, layout, onRows, onProgress) {
  const response = await request;
  if (!response.ok || !response.body) {
    throw new Error(`cannot fetch the model (${response.status} ${response.statusText})`);
  }
  const reader = response.body.getReader();
  const stride = layout.stride;
  const strideFloats = Math.ceil(stride / 4);
  const names = Object.keys(layout.offsets);
  // The floats of the `n` whole rows in `b` (n·stride bytes): a view of the chunk when the rows
  // are 4-aligned, else a copy (each drawn float through a DataView for an odd stride).
  const floatsOf = (b, n) => {
    if (stride % 4 === 0) {
      return b.byteOffset % 4 === 0 ? new Float32Array(b.buffer, b.byteOffset, n * strideFloats)
        : new Float32Array(b.slice().buffer);
    }
    const view = new DataView(b.buffer, b.byteOffset, n * stride);
    const floats = new Float32Array(n * strideFloats);
    for (let r = 0; r < n; r++) {
      for (const name of names) {
        const off = layout.offsets[name];
        floats[r * strideFloats + Math.floor(off / 4)] = view.getFloat32(r * stride + off, true);
      }
    }
    return floats;
  };
  const concat = (a, b) => {
    const c = new Uint8Array(a.length + b.length);
    c.set(a);
    c.set(b, a.length);
    return c;
  };
  let skip = layout.header_bytes;
  let pending = new Uint8Array(0);
  let rows = 0;
  let bytes = 0;
  let lastYield = performance.now();
  while (rows < layout.count) {
    let chunk;
    try {
      chunk = await reader.read();
    } catch (e) {
      throw new Error(`the model stream broke after ${rows} of ${layout.count} Gaussians (${e.message || e})`);
    }
    if (chunk.done) break;
    let data = chunk.value;
    bytes += data.length;
    onProgress(bytes);
    if (skip > 0) {
      const s = Math.min(skip, data.length);
      data = data.subarray(s);
      skip -= s;
    }
    // A row split between chunks.
    if (pending.length > 0) {
      const need = stride - pending.length;
      if (data.length < need) {
        pending = concat(pending, data);
        continue;
      }
      onRows(rows, 1, floatsOf(concat(pending, data.subarray(0, need)), 1), strideFloats);
      rows++;
      data = data.subarray(need);
    }
    // The chunk's whole rows go to onRows in slices (no copy of a large chunk before the first
    // rows are drawn), and the page gets a turn (sort results, frames, input) every few
    // milliseconds: chunks already buffered resolve without leaving the task.
    const n = Math.min(Math.floor(data.length / stride), layout.count - rows);
    for (let r = 0; r < n; r += ROWS_PER_CALL) {
      const m = Math.min(ROWS_PER_CALL, n - r);
      onRows(rows, m, floatsOf(data.subarray(r * stride, (r + m) * stride), m), strideFloats);
      rows += m;
      if (performance.now() - lastYield > YIELD_MS) {
        await yieldTask();
        lastYield = performance.now();
      }
    }
    pending = data.slice(n * stride);
  }
  if (rows < layout.count) {
    throw new Error(`the model stream ended after ${rows} of ${layout.count} Gaussians`);
  }
}

/// Float offsets of the drawn properties (the server's byte offsets / 4, rounded down; a stride
/// that is not a multiple of 4 is read through streamPly's DataView path, which puts each float
/// there).
export function floatOffsets(layout) {
  const o = {};
  for (const [name, off] of Object.entries(layout.offsets)) o[name] = Math.floor(off / 4);
  o.rest = [];
  for (let i = 0; i < shRestCount(layout.sh_degree); i++) o.rest.push(o[`f_rest_${i}`]);
  return o;
}

const SPLAT_VS = `#version 300 es
precision highp float;
precision highp int;
precision highp usampler2D;
uniform highp sampler2D u_main;
uniform usampler2D u_sh;
uniform mat3 u_R;
uniform vec3 u_t;
uniform vec3 u_center;
uniform vec4 u_intr;
uniform vec2 u_size;
uniform vec4 u_lim;
uniform float u_near;
uniform int u_shDegree;
uniform int u_shTexels;
uniform int u_shPerRow;
// The depth order: entry k is the Gaussian drawn k-th. Quad q draws entry u_from + q·u_step.
uniform usampler2D u_order;
uniform int u_from;
uniform int u_step;
out vec3 v_color;
out vec3 v_conic;
out vec2 v_offset;
out float v_opacity;

const float SH_C1 = 0.4886025119029199;
const float C2[5] = float[5](1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396);
const float C3[7] = float[7](-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154, -0.4570457994644658, 1.445305721320277, -0.5900435899266435);

vec4 mainTexel(int i, int k) {
  int idx = i * ${MAIN_TEXELS} + k;
  return texelFetch(u_main, ivec2(idx % ${TEX_WIDTH}, idx / ${TEX_WIDTH}), 0);
}

// The SH rest coefficients of Gaussian i, unpacked once per vertex: halves 3(k−1)+c hold
// coefficient k (1-based) of channel c.
float rest[48];
void loadRest(int i) {
  ivec2 at = ivec2((i % u_shPerRow) * u_shTexels, i / u_shPerRow);
  for (int t = 0; t < 6; t++) {
    if (t >= u_shTexels) break;
    uvec4 v = texelFetch(u_sh, at + ivec2(t, 0), 0);
    vec2 a = unpackHalf2x16(v.x), b = unpackHalf2x16(v.y), c = unpackHalf2x16(v.z), d = unpackHalf2x16(v.w);
    rest[8 * t] = a.x; rest[8 * t + 1] = a.y; rest[8 * t + 2] = b.x; rest[8 * t + 3] = b.y;
    rest[8 * t + 4] = c.x; rest[8 * t + 5] = c.y; rest[8 * t + 6] = d.x; rest[8 * t + 7] = d.y;
  }
}
vec3 shCoeff(int k) {
  int h = 3 * (k - 1);
  return vec3(rest[h], rest[h + 1], rest[h + 2]);
}

void cull() {
  gl_Position = vec4(0.0, 0.0, 2.0, 1.0);
}

void main() {
  // Quad q has vertices 4q..4q+3 (the index buffer), corner v = (±1, ±1).
  int k = u_from + (gl_VertexID >> 2) * u_step, v = gl_VertexID & 3;
  vec2 corner = vec2(float(v & 1) * 2.0 - 1.0, float(v >> 1) * 2.0 - 1.0);
  int i = int(texelFetch(u_order, ivec2(k % ${TEX_WIDTH}, k / ${TEX_WIDTH}), 0).x);
  vec4 t0 = mainTexel(i, 0);
  vec4 t1 = mainTexel(i, 1);
  vec4 t2 = mainTexel(i, 2);
  vec4 t3 = mainTexel(i, 3);
  vec3 p = t0.xyz;
  vec3 t = u_R * p + u_t;
  if (!(t.z >= u_near)) { cull(); return; }
  float fx = u_intr.x, fy = u_intr.y, cx = u_intr.z, cy = u_intr.w;
  mat3 sigma = mat3(t1.x, t1.y, t1.z, t1.y, t1.w, t2.x, t1.z, t2.x, t2.y);
  float invz = 1.0 / t.z;
  float rx = clamp(t.x * invz, -u_lim.x, u_lim.y);
  float ry = clamp(t.y * invz, -u_lim.z, u_lim.w);
  vec3 j0 = vec3(fx * invz, 0.0, -fx * rx * invz);
  vec3 j1 = vec3(0.0, fy * invz, -fy * ry * invz);
  // Rows of T = J W: (Jrow W) = Wᵀ Jrowᵀ, i.e. the row vector times the matrix.
  vec3 T0 = j0 * u_R;
  vec3 T1 = j1 * u_R;
  vec3 s0 = sigma * T0;
  vec3 s1 = sigma * T1;
  float a = dot(T0, s0) + 0.3;
  float b = dot(T0, s1);
  float c = dot(T1, s1) + 0.3;
  float det = a * c - b * b;
  float opacity = t0.w;
  if (!(det > 0.0) || !(opacity > 0.0)) { cull(); return; }
  float qmax = 2.0 * log(255.0 * opacity);
  if (!(qmax > 0.0)) { cull(); return; }
  vec2 mean = vec2(fx * t.x * invz + cx, fy * t.y * invz + cy);
  vec2 half_ = vec2(sqrt(qmax * a), sqrt(qmax * c)) + 1.0;
  vec2 offset = corner * half_;
  vec2 pixel = mean + offset;
  gl_Position = vec4(pixel.x / u_size.x * 2.0 - 1.0, 1.0 - pixel.y / u_size.y * 2.0, 0.0, 1.0);
  v_offset = offset;
  v_conic = vec3(c, -b, a) / det;
  v_opacity = opacity;

  vec3 color = vec3(0.5) + vec3(t2.z, t2.w, t3.x);
  if (u_shDegree > 0) {
    loadRest(i);
    vec3 d = normalize(p - u_center);
    float x = d.x, y = d.y, z = d.z;
    color += -SH_C1 * y * shCoeff(1) + SH_C1 * z * shCoeff(2) - SH_C1 * x * shCoeff(3);
    if (u_shDegree > 1) {
      float xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
      color += C2[0] * xy * shCoeff(4) + C2[1] * yz * shCoeff(5)
        + C2[2] * (2.0 * zz - xx - yy) * shCoeff(6) + C2[3] * xz * shCoeff(7)
        + C2[4] * (xx - yy) * shCoeff(8);
      if (u_shDegree > 2) {
        color += C3[0] * y * (3.0 * xx - yy) * shCoeff(9) + C3[1] * xy * z * shCoeff(10)
          + C3[2] * y * (4.0 * zz - xx - yy) * shCoeff(11)
          + C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy) * shCoeff(12)
          + C3[4] * x * (4.0 * zz - xx - yy) * shCoeff(13) + C3[5] * z * (xx - yy) * shCoeff(14)
          + C3[6] * x * (xx - 3.0 * yy) * shCoeff(15);
      }
    }
  }
  v_color = max(color, vec3(0.0));
}
`;

const SPLAT_FS = `#version 300 es
precision highp float;
in vec3 v_color;
in vec3 v_conic;
in vec2 v_offset;
in float v_opacity;
out vec4 out_color;
void main() {
  vec2 d = v_offset;
  float power = -0.5 * (v_conic.x * d.x * d.x + v_conic.z * d.y * d.y) - v_conic.y * d.x * d.y;
  if (power > 0.0) discard;
  float alpha = min(0.99, v_opacity * exp(power));
  if (alpha < 1.0 / 255.0) discard;
  out_color = vec4(v_color * alpha, alpha);
}
`;

const FULL_VS = `#version 300 es
void main() {
  vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
  gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
`;

const COMPOSITE_FS = `#version 300 es
precision highp float;
uniform highp sampler2D u_accum;
uniform vec3 u_background;
// Accumulation pixels per canvas pixel: 1 reads the pixel itself (the exact picture); below 1
// (a reduced-resolution frame) interpolates the four nearest accumulation pixels bilinearly.
uniform float u_scale;
out vec4 out_color;
void main() {
  vec4 a;
  if (u_scale == 1.0) {
    a = texelFetch(u_accum, ivec2(gl_FragCoord.xy), 0);
  } else {
    ivec2 size = textureSize(u_accum, 0);
    vec2 p = gl_FragCoord.xy * u_scale - 0.5;
    vec2 f = fract(p);
    ivec2 i0 = clamp(ivec2(floor(p)), ivec2(0), size - 1);
    ivec2 i1 = clamp(i0 + 1, ivec2(0), size - 1);
    a = mix(mix(texelFetch(u_accum, i0, 0), texelFetch(u_accum, ivec2(i1.x, i0.y), 0), f.x),
      mix(texelFetch(u_accum, ivec2(i0.x, i1.y), 0), texelFetch(u_accum, i1, 0), f.x), f.y);
  }
  out_color = vec4(a.rgb + (1.0 - a.a) * u_background, 1.0);
}
`;

export function compile(gl, vs, fs) {
  const prog = gl.createProgram();
  for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
    const s = gl.createShader(type);
    gl.shaderSource(s, src);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) {
      throw new Error(`shader: ${gl.getShaderInfoLog(s).split("\n")[0]}`);
    }
    gl.attachShader(prog, s);
  }
  gl.linkProgram(prog);
  if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) {
    throw new Error(`shader link: ${gl.getProgramInfoLog(prog).split("\n")[0]}`);
  }
  return prog;
}

function uniforms(gl, prog, names) {
  const u = {};
  for (const n of names) u[n] = gl.getUniformLocation(prog, n);
  return u;
}

/// Draws a SplatData with the order a sort worker returned. A picture is one pass: begin()
/// clears an accumulation target (at a fraction of the canvas resolution for a quick frame),
/// drawRange() blends a consecutive range of the sorted Gaussians into it (a pass may be split
/// over several frames: front-to-back blending in the same order gives the same picture), and
/// composite() puts it on the canvas over the background.
export class SplatRenderer {
  constructor(gl, data) {
    this.gl = gl;
    this.data = data;
    if (!gl.getExtension("EXT_color_buffer_float")) {
      throw new Error("this browser cannot render to float targets (EXT_color_buffer_float)");
    }
    this.floatBlend = !!gl.getExtension("EXT_float_blend");
    this.prog = compile(gl, SPLAT_VS, SPLAT_FS);
    this.u = uniforms(gl, this.prog, ["u_main", "u_sh", "u_order", "u_R", "u_t", "u_center", "u_intr", "u_size",
      "u_lim", "u_near", "u_shDegree", "u_shTexels", "u_shPerRow", "u_from", "u_step"]);
    this.composite_ = compile(gl, FULL_VS, COMPOSITE_FS);
    this.cu = uniforms(gl, this.composite_, ["u_accum", "u_background", "u_scale"]);

    // One indexed quad per Gaussian, not an instanced quad: software WebGL (SwiftShader) sets
    // up each instance as a draw of its own, which made instanced quads several times slower.
    this.vao = gl.createVertexArray();
    gl.bindVertexArray(this.vao);
    this.indices = gl.createBuffer();
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, this.indices);
    gl.bindVertexArray(null);
    this.quads = 0;
    this.orderTex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, this.orderTex);
    gl.texStorage2D(gl.TEXTURE_2D, 1, gl.R32UI, TEX_WIDTH, Math.ceil(data.count / TEX_WIDTH));
    this.nearest();
    this.instances = 0;

    this.mainTex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, this.mainTex);
    gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA32F, TEX_WIDTH, data.rows);
    this.nearest();
    if (data.shTexels > 0) {
      this.shTex = gl.createTexture();
      gl.bindTexture(gl.TEXTURE_2D, this.shTex);
      gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA32UI, data.shWidth, data.shRows);
      this.nearest();
    }
    // Gaussians [0, uploaded) are in the textures.
    this.uploaded = 0;
    // Accumulation targets by size ("w×h" → {fbo, tex}); the canvas size and one reduced size.
    this.targets = new Map();
    this.frame = null;
    this.warmUp();
  }

  /// Makes the index buffer hold at least `n` quads (doubling, so that a model streaming in
  /// does not pay for the whole index buffer before its first picture).
  ensureQuads(n) {
    if (n <= this.quads) return;
    const gl = this.gl;
    const cap = Math.min(this.data.count, Math.max(n, 2 * this.quads, 65536));
    const quads = new Uint32Array(6 * cap);
    for (let k = 0; k < cap; k++) {
      const v = 4 * k, q = 6 * k;
      quads[q] = v; quads[q + 1] = v + 1; quads[q + 2] = v + 2;
      quads[q + 3] = v + 2; quads[q + 4] = v + 1; quads[q + 5] = v + 3;
    }
    gl.bindVertexArray(this.vao);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, quads, gl.STATIC_DRAW);
    gl.bindVertexArray(null);
    this.quads = cap;
  }

  /// Draws one invisible quad (an all-zero Gaussian has opacity 0 and is culled) into a 1×1
  /// target, so that a software GPU compiles the splat and composite programs while the model
  /// is still on its way, not during the first picture.
  warmUp() {
    const view = {
      R: new Float32Array([1, 0, 0, 0, 1, 0, 0, 0, 1]), t: new Float32Array(3), center: new Float32Array(3),
      fx: 1, fy: 1, cx: 0.5, cy: 0.5, width: 1, height: 1, near: 0.2, background: new Float32Array(3),
    };
    this.instances = 1;
    this.begin(view, 1);
    this.drawRange(0, 1);
    this.instances = 0;
    const gl = this.gl;
    this.composite();
    gl.flush();
  }

  nearest() {
    const gl = this.gl;
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
  }

  /// Uploads the Gaussians that arrived since the last upload (one call per texture, however
  /// many stream chunks they came in). Returns the number uploaded.
  upload() {
    const gl = this.gl, d = this.data;
    const start = this.uploaded, end = d.loaded;
    if (end <= start) return 0;
    const r0 = Math.floor(start / d.perRow), r1 = Math.floor((end - 1) / d.perRow);
    gl.bindTexture(gl.TEXTURE_2D, this.mainTex);
    gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, r0, TEX_WIDTH, r1 - r0 + 1, gl.RGBA, gl.FLOAT,
      d.main.subarray(r0 * TEX_WIDTH * 4, (r1 + 1) * TEX_WIDTH * 4));
    if (d.shTexels > 0) {
      const s0 = Math.floor(start / d.shPerRow), s1 = Math.floor((end - 1) / d.shPerRow);
      gl.bindTexture(gl.TEXTURE_2D, this.shTex);
      gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, s0, d.shWidth, s1 - s0 + 1, gl.RGBA_INTEGER, gl.UNSIGNED_INT,
        d.sh.subarray(s0 * d.shWidth * 4, (s1 + 1) * d.shWidth * 4));
    }
    this.uploaded = end;
    return end - start;
  }

  setOrder(order, count) {
    const gl = this.gl;
    gl.bindTexture(gl.TEXTURE_2D, this.orderTex);
    const rows = Math.floor(count / TEX_WIDTH), rest = count - rows * TEX_WIDTH;
    if (rows > 0) {
      gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, 0, TEX_WIDTH, rows, gl.RED_INTEGER, gl.UNSIGNED_INT,
        order.subarray(0, rows * TEX_WIDTH));
    }
    if (rest > 0) {
      gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, rows, rest, 1, gl.RED_INTEGER, gl.UNSIGNED_INT,
        order.subarray(rows * TEX_WIDTH, count));
    }
    this.instances = count;
  }

  target(w, h) {
    const gl = this.gl;
    const key = `${w}x${h}`;
    let t = this.targets.get(key);
    if (t) return t;
    if (this.targets.size >= 2) {
      for (const old of this.targets.values()) { gl.deleteFramebuffer(old.fbo); gl.deleteTexture(old.tex); }
      this.targets.clear();
    }
    const tex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, tex);
    gl.texStorage2D(gl.TEXTURE_2D, 1, this.floatBlend ? gl.RGBA32F : gl.RGBA16F, w, h);
    this.nearest();
    const fbo = gl.createFramebuffer();
    gl.bindFramebuffer(gl.FRAMEBUFFER, fbo);
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, tex, 0);
    if (gl.checkFramebufferStatus(gl.FRAMEBUFFER) !== gl.FRAMEBUFFER_COMPLETE) {
      throw new Error("cannot render to a float target here");
    }
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    t = { fbo, tex, w, h };
    this.targets.set(key, t);
    return t;
  }

  /// Starts a picture of `view` (R row-major 9, t, center, fx, fy, cx, cy, width, height, near,
  /// background) at `scale` (≤ 1) of its resolution: the Gaussians are projected with the
  /// intrinsics scaled by the same factor.
  begin(view, scale) {
    const gl = this.gl;
    const w = Math.max(1, Math.round(view.width * scale)), h = Math.max(1, Math.round(view.height * scale));
    const sx = w / view.width, sy = h / view.height;
    const t = this.target(w, h);
    this.frame = {
      view, target: t, w, h, scale: scale === 1 ? 1 : sx,
      fx: view.fx * sx, fy: view.fy * sy, cx: view.cx * sx, cy: view.cy * sy,
    };
    gl.bindFramebuffer(gl.FRAMEBUFFER, t.fbo);
    gl.viewport(0, 0, w, h);
    gl.clearColor(0, 0, 0, 0);
    gl.clear(gl.COLOR_BUFFER_BIT);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
  }

  /// Blends the sorted Gaussians [from, to) into the picture begun last; with `step` > 1 only
  /// every step-th of them (a sparser, cheaper picture while the camera moves).
  drawRange(from, to, step = 1) {
    const gl = this.gl, d = this.data, f = this.frame, view = f.view;
    to = Math.min(to, this.instances);
    if (to <= from) return;
    const quads = Math.ceil((to - from) / step);
    this.ensureQuads(quads);
    gl.bindFramebuffer(gl.FRAMEBUFFER, f.target.fbo);
    gl.viewport(0, 0, f.w, f.h);
    gl.useProgram(this.prog);
    gl.enable(gl.BLEND);
    gl.disable(gl.DEPTH_TEST);
    gl.blendEquation(gl.FUNC_ADD);
    gl.blendFuncSeparate(gl.ONE_MINUS_DST_ALPHA, gl.ONE, gl.ONE_MINUS_DST_ALPHA, gl.ONE);
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_2D, this.mainTex);
    gl.uniform1i(this.u.u_main, 0);
    gl.activeTexture(gl.TEXTURE1);
    gl.bindTexture(gl.TEXTURE_2D, d.shTexels > 0 ? this.shTex : null);
    gl.uniform1i(this.u.u_sh, 1);
    gl.activeTexture(gl.TEXTURE2);
    gl.bindTexture(gl.TEXTURE_2D, this.orderTex);
    gl.uniform1i(this.u.u_order, 2);
    gl.activeTexture(gl.TEXTURE0);
    gl.uniformMatrix3fv(this.u.u_R, true, view.R);
    gl.uniform3fv(this.u.u_t, view.t);
    gl.uniform3fv(this.u.u_center, view.center);
    gl.uniform4f(this.u.u_intr, f.fx, f.fy, f.cx, f.cy);
    gl.uniform2f(this.u.u_size, f.w, f.h);
    gl.uniform4f(this.u.u_lim, 1.3 * f.cx / f.fx, 1.3 * (f.w - f.cx) / f.fx,
      1.3 * f.cy / f.fy, 1.3 * (f.h - f.cy) / f.fy);
    gl.uniform1f(this.u.u_near, view.near);
    gl.uniform1i(this.u.u_shDegree, d.shDegree);
    gl.uniform1i(this.u.u_shTexels, d.shTexels || 1);
    gl.uniform1i(this.u.u_shPerRow, d.shPerRow || 1);
    gl.uniform1i(this.u.u_from, from);
    gl.uniform1i(this.u.u_step, step);
    gl.bindVertexArray(this.vao);
    gl.drawElements(gl.TRIANGLES, 6 * quads, gl.UNSIGNED_INT, 0);
    gl.bindVertexArray(null);
    gl.disable(gl.BLEND);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
  }

  /// Puts the picture begun last on the canvas (the default framebuffer), over the background.
  composite() {
    const gl = this.gl, f = this.frame, view = f.view;
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.viewport(0, 0, view.width, view.height);
    gl.useProgram(this.composite_);
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_2D, f.target.tex);
    gl.uniform1i(this.cu.u_accum, 0);
    gl.uniform3fv(this.cu.u_background, view.background);
    gl.uniform1f(this.cu.u_scale, f.scale);
    gl.drawArrays(gl.TRIANGLES, 0, 3);
  }
}
