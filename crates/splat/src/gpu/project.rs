//! Per-Gaussian projection on the device: the forward pass of [`crate::raster::project`] and its
//! exact backward, one unit per Gaussian, written after the CPU code line by line (same
//! operation order, so the two agree to rounding).
//!
//! Camera constants travel in one `f32` buffer laid out as [`CameraBuffer`] describes.
// Device code: CubeCL's expanded struct types are not `Copy` (a struct passed twice is cloned)
// and its macro cannot infer the type of a unary minus on some expressions (written as `* -1`).
#![allow(clippy::clone_on_copy, clippy::neg_multiply)]

use cubecl::prelude::*;

use super::sh::{Vec3, basis, basis_grad};
use crate::raster::project::CameraF;
use crate::raster::{ALPHA_MIN, DILATION, RenderCamera, TILE};

/// Floats per splat in the `splats` buffer: mean x, y; conic a, b, c; opacity; r, g, b; depth.
pub const SPLAT_FLOATS: usize = 10;
/// Floats per splat gradient (the same layout as [`crate::raster::project::SplatGrad`]):
/// mean x, y; conic a, b, c; opacity; r, g, b; depth.
pub const GRAD_FLOATS: usize = 10;

/// Index of each camera constant in the camera buffer.
pub struct CameraBuffer;

impl CameraBuffer {
    pub const FX: usize = 0;
    pub const FY: usize = 1;
    pub const CX: usize = 2;
    pub const CY: usize = 3;
    /// World-to-camera rotation, 9 values row-major.
    pub const ROT: usize = 4;
    pub const TRANS: usize = 13;
    pub const CENTER: usize = 16;
    /// `−lim_x[0], lim_x[1], −lim_y[0], lim_y[1]`: the FoV clamp interval of `x/z` and `y/z`.
    pub const LIMITS: usize = 19;
    pub const NEAR: usize = 23;
    pub const LEN: usize = 24;

    /// The constants of `camera` in `f32`, rounded from `f64` exactly as the CPU rasterizer's
    /// [`CameraF`] does.
    pub fn values(camera: &RenderCamera, near: f64) -> Vec<f32> {
        let c = CameraF::<f32>::new(camera, near);
        let mut v = vec![c.fx, c.fy, c.cx, c.cy];
        v.extend(c.rotation.iter().flatten());
        v.extend(c.translation);
        v.extend(c.center);
        v.extend([-c.lim_x[0], c.lim_x[1], -c.lim_y[0], c.lim_y[1], c.near]);
        debug_assert_eq!(v.len(), Self::LEN);
        v
    }
}

/// The forward projection of one Gaussian up to (not including) the culling decisions, the
/// values the backward pass reuses (the CPU code's `Forward`).
#[derive(CubeType, Clone, Copy)]
#[expand(derive(Clone))]
pub struct Fwd {
    /// Camera-space centre.
    pub t0: f32,
    pub t1: f32,
    pub t2: f32,
    /// Clamped `x/z`, `y/z`, and whether each clamp was active.
    pub rx: f32,
    pub ry: f32,
    pub clamped_x: bool,
    pub clamped_y: bool,
    /// Unit quaternion and the norm it was divided by.
    pub qw: f32,
    pub qx: f32,
    pub qy: f32,
    pub qz: f32,
    pub q_norm: f32,
    /// `R(q)`, row-major.
    pub r00: f32,
    pub r01: f32,
    pub r02: f32,
    pub r10: f32,
    pub r11: f32,
    pub r12: f32,
    pub r20: f32,
    pub r21: f32,
    pub r22: f32,
    pub s0: f32,
    pub s1: f32,
    pub s2: f32,
    /// 3D covariance, upper triangle.
    pub sg00: f32,
    pub sg01: f32,
    pub sg02: f32,
    pub sg11: f32,
    pub sg12: f32,
    pub sg22: f32,
    /// `T = J W`, 2×3.
    pub m00: f32,
    pub m01: f32,
    pub m02: f32,
    pub m10: f32,
    pub m11: f32,
    pub m12: f32,
    /// Dilated 2D covariance `(a, b, c)` and its determinant.
    pub cov_a: f32,
    pub cov_b: f32,
    pub cov_c: f32,
    pub det: f32,
    /// Unit view direction and the distance it was divided by.
    pub dir: Vec3,
    pub dir_norm: f32,
    /// Colour before `max(0, ·)`.
    pub red: f32,
    pub green: f32,
    pub blue: f32,
    pub opacity: f32,
    /// False when the centre is behind the near plane or the quaternion is zero.
    pub ok: bool,
}

/// Reads camera constant `k`.
#[cube]
fn cam_at(cam: &[f32], #[comptime] k: usize) -> f32 {
    cam[k]
}

/// The world-to-camera rotation `W`, row-major.
#[derive(CubeType, Clone, Copy)]
#[expand(derive(Clone))]
struct Rotation {
    w00: f32,
    w01: f32,
    w02: f32,
    w10: f32,
    w11: f32,
    w12: f32,
    w20: f32,
    w21: f32,
    w22: f32,
}

/// Reads `W` from the camera buffer (the forward and backward projections both use it).
#[cube]
fn rotation(cam: &[f32]) -> Rotation {
    Rotation {
        w00: cam_at(cam, CameraBuffer::ROT),
        w01: cam_at(cam, CameraBuffer::ROT + 1),
        w02: cam_at(cam, CameraBuffer::ROT + 2),
        w10: cam_at(cam, CameraBuffer::ROT + 3),
        w11: cam_at(cam, CameraBuffer::ROT + 4),
        w12: cam_at(cam, CameraBuffer::ROT + 5),
        w20: cam_at(cam, CameraBuffer::ROT + 6),
        w21: cam_at(cam, CameraBuffer::ROT + 7),
        w22: cam_at(cam, CameraBuffer::ROT + 8),
    }
}

/// `Σ_k Y_k(d) sh_k` for one colour channel, plus 0.5 (the Inria convention).
#[cube]
fn sh_channel(sh: &[f32], base: usize, k_used: u32, dir: Vec3, ch: usize) -> f32 {
    let mut v = 0.5f32;
    for k in 0..k_used {
        v += basis(k, dir.clone()) * sh[base + 3 * k as usize + ch];
    }
    v
}

/// The forward projection of Gaussian `i` (see [`Fwd`]).
#[cube]
#[allow(clippy::too_many_arguments)]
pub fn forward_one(
    means: &[f32],
    log_scales: &[f32],
    quats: &[f32],
    opacity_logits: &[f32],
    sh: &[f32],
    cam: &[f32],
    i: usize,
    sh_coeffs: u32,
    k_used: u32,
) -> Fwd {
    let (px, py, pz) = (means[3 * i], means[3 * i + 1], means[3 * i + 2]);
    let rot = rotation(cam);
    let t0 = rot.w00 * px + rot.w01 * py + rot.w02 * pz + cam_at(cam, CameraBuffer::TRANS);
    let t1 = rot.w10 * px + rot.w11 * py + rot.w12 * pz + cam_at(cam, CameraBuffer::TRANS + 1);
    let t2 = rot.w20 * px + rot.w21 * py + rot.w22 * pz + cam_at(cam, CameraBuffer::TRANS + 2);
    let (q0, q1, q2, q3) = (
        quats[4 * i],
        quats[4 * i + 1],
        quats[4 * i + 2],
        quats[4 * i + 3],
    );
    let q_norm = (q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3).sqrt();
    // False for NaN, as the CPU code's negated comparisons.
    let ok = t2 >= cam_at(cam, CameraBuffer::NEAR) && q_norm > 1e-12f32;
    let (w, x, y, z) = (q0 / q_norm, q1 / q_norm, q2 / q_norm, q3 / q_norm);
    let r00 = 1.0 - 2.0 * (y * y + z * z);
    let r01 = 2.0 * (x * y - w * z);
    let r02 = 2.0 * (x * z + w * y);
    let r10 = 2.0 * (x * y + w * z);
    let r11 = 1.0 - 2.0 * (x * x + z * z);
    let r12 = 2.0 * (y * z - w * x);
    let r20 = 2.0 * (x * z - w * y);
    let r21 = 2.0 * (y * z + w * x);
    let r22 = 1.0 - 2.0 * (x * x + y * y);
    let s0 = log_scales[3 * i].exp();
    let s1 = log_scales[3 * i + 1].exp();
    let s2 = log_scales[3 * i + 2].exp();
    let (v0, v1, v2) = (s0 * s0, s1 * s1, s2 * s2);
    let sg00 = r00 * v0 * r00 + r01 * v1 * r01 + r02 * v2 * r02;
    let sg01 = r00 * v0 * r10 + r01 * v1 * r11 + r02 * v2 * r12;
    let sg02 = r00 * v0 * r20 + r01 * v1 * r21 + r02 * v2 * r22;
    let sg11 = r10 * v0 * r10 + r11 * v1 * r11 + r12 * v2 * r12;
    let sg12 = r10 * v0 * r20 + r11 * v1 * r21 + r12 * v2 * r22;
    let sg22 = r20 * v0 * r20 + r21 * v1 * r21 + r22 * v2 * r22;
    let inv_z = 1.0 / t2;
    let (raw_x, raw_y) = (t0 * inv_z, t1 * inv_z);
    let (lo_x, hi_x) = (
        cam_at(cam, CameraBuffer::LIMITS),
        cam_at(cam, CameraBuffer::LIMITS + 1),
    );
    let (lo_y, hi_y) = (
        cam_at(cam, CameraBuffer::LIMITS + 2),
        cam_at(cam, CameraBuffer::LIMITS + 3),
    );
    let rx = raw_x.max(lo_x).min(hi_x);
    let ry = raw_y.max(lo_y).min(hi_y);
    let clamped_x = raw_x < lo_x || raw_x > hi_x;
    let clamped_y = raw_y < lo_y || raw_y > hi_y;
    let (fx, fy) = (cam_at(cam, CameraBuffer::FX), cam_at(cam, CameraBuffer::FY));
    let j00 = fx * inv_z;
    let j02 = -fx * rx * inv_z;
    let j11 = fy * inv_z;
    let j12 = -fy * ry * inv_z;
    // T = J W (J01 = J10 = 0; the CPU code adds their zero products, which changes nothing).
    let m00 = j00 * rot.w00 + 0.0 * rot.w10 + j02 * rot.w20;
    let m01 = j00 * rot.w01 + 0.0 * rot.w11 + j02 * rot.w21;
    let m02 = j00 * rot.w02 + 0.0 * rot.w12 + j02 * rot.w22;
    let m10 = 0.0 * rot.w00 + j11 * rot.w10 + j12 * rot.w20;
    let m11 = 0.0 * rot.w01 + j11 * rot.w11 + j12 * rot.w21;
    let m12 = 0.0 * rot.w02 + j11 * rot.w12 + j12 * rot.w22;
    // Σ' = T Σ Tᵀ + 0.3 I
    let ts00 = m00 * sg00 + m01 * sg01 + m02 * sg02;
    let ts01 = m00 * sg01 + m01 * sg11 + m02 * sg12;
    let ts02 = m00 * sg02 + m01 * sg12 + m02 * sg22;
    let ts10 = m10 * sg00 + m11 * sg01 + m12 * sg02;
    let ts11 = m10 * sg01 + m11 * sg11 + m12 * sg12;
    let ts12 = m10 * sg02 + m11 * sg12 + m12 * sg22;
    let dilation = DILATION as f32;
    let cov_a = ts00 * m00 + ts01 * m01 + ts02 * m02 + dilation;
    let cov_b = ts00 * m10 + ts01 * m11 + ts02 * m12;
    let cov_c = ts10 * m10 + ts11 * m11 + ts12 * m12 + dilation;
    let det = cov_a * cov_c - cov_b * cov_b;
    let dx = px - cam_at(cam, CameraBuffer::CENTER);
    let dy = py - cam_at(cam, CameraBuffer::CENTER + 1);
    let dz = pz - cam_at(cam, CameraBuffer::CENTER + 2);
    let dir_norm = (dx * dx + dy * dy + dz * dz).sqrt().max(1e-20f32);
    let dir = Vec3 {
        x: dx / dir_norm,
        y: dy / dir_norm,
        z: dz / dir_norm,
    };
    let base = i * sh_coeffs as usize * 3;
    let red = sh_channel(sh, base, k_used, dir.clone(), 0);
    let green = sh_channel(sh, base, k_used, dir.clone(), 1);
    let blue = sh_channel(sh, base, k_used, dir.clone(), 2);
    let opacity = 1.0 / (1.0 + (-opacity_logits[i]).exp());
    Fwd {
        t0,
        t1,
        t2,
        rx,
        ry,
        clamped_x,
        clamped_y,
        qw: w,
        qx: x,
        qy: y,
        qz: z,
        q_norm,
        r00,
        r01,
        r02,
        r10,
        r11,
        r12,
        r20,
        r21,
        r22,
        s0,
        s1,
        s2,
        sg00,
        sg01,
        sg02,
        sg11,
        sg12,
        sg22,
        m00,
        m01,
        m02,
        m10,
        m11,
        m12,
        cov_a,
        cov_b,
        cov_c,
        det,
        dir,
        dir_norm,
        red,
        green,
        blue,
        opacity,
        ok,
    }
}

/// A pixel span `[lo, hi)` along one axis, empty when `lo ≥ hi`.
#[derive(CubeType, Clone, Copy)]
#[expand(derive(Clone))]
struct Span {
    lo: f32,
    hi: f32,
}

/// Pixel span along one axis where `α ≥ 1/255` is possible (pixel `k`'s centre is `k + 0.5`).
#[cube]
fn pixel_span(center: f32, half_extent: f32, size: u32) -> Span {
    Span {
        lo: (center - half_extent - 0.5).ceil().max(0.0),
        hi: ((center + half_extent - 0.5).floor() + 1.0).min(size as f32),
    }
}

/// Projects every Gaussian: splat (see [`SPLAT_FLOATS`]), tile rectangle
/// `[tx0, tx1) × [ty0, ty1)` (empty when culled), screen radius (0 when culled) and depth key.
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn project_forward(
    means: &[f32],
    log_scales: &[f32],
    quats: &[f32],
    opacity_logits: &[f32],
    sh: &[f32],
    cam: &[f32],
    splats: &mut [f32],
    rects: &mut [u32],
    radii: &mut [f32],
    depth_keys: &mut [u32],
    n: u32,
    sh_coeffs: u32,
    k_used: u32,
    width: u32,
    height: u32,
) {
    let i = ABSOLUTE_POS;
    if i >= n as usize {
        terminate!();
    }
    let f = forward_one(
        means,
        log_scales,
        quats,
        opacity_logits,
        sh,
        cam,
        i,
        sh_coeffs,
        k_used,
    );
    let inv_det = 1.0 / f.det;
    let inv_z = 1.0 / f.t2;
    let mean_x = cam_at(cam, CameraBuffer::FX) * f.t0 * inv_z + cam_at(cam, CameraBuffer::CX);
    let mean_y = cam_at(cam, CameraBuffer::FY) * f.t1 * inv_z + cam_at(cam, CameraBuffer::CY);
    let mid = 0.5 * (f.cov_a + f.cov_c);
    let lambda = mid + (mid * mid - f.det).max(0.1).sqrt();
    let radius = (3.0 * lambda.sqrt()).ceil();
    // α = o·exp(−q/2) ≥ 1/255 ⇔ q ≤ 2 ln(255 o); one pixel of margin absorbs rounding.
    let q_max = 2.0 * (f.opacity / (ALPHA_MIN as f32)).ln();
    let hx = (q_max * f.cov_a).sqrt() + 1.0;
    let hy = (q_max * f.cov_c).sqrt() + 1.0;
    let cols = pixel_span(mean_x, hx, width);
    let rows = pixel_span(mean_y, hy, height);
    let visible = f.ok
        && f.det > 0.0
        && f.opacity >= 0.0
        && f.opacity <= 1.0
        && q_max > 0.0
        && cols.lo < cols.hi
        && rows.lo < rows.hi;
    let o = i * SPLAT_FLOATS;
    splats[o] = mean_x;
    splats[o + 1] = mean_y;
    splats[o + 2] = f.cov_c * inv_det;
    splats[o + 3] = -f.cov_b * inv_det;
    splats[o + 4] = f.cov_a * inv_det;
    splats[o + 5] = f.opacity;
    splats[o + 6] = f.red.max(0.0);
    splats[o + 7] = f.green.max(0.0);
    splats[o + 8] = f.blue.max(0.0);
    splats[o + 9] = f.t2;
    let tile = TILE as u32;
    let mut tx0 = 0u32;
    let mut tx1 = 0u32;
    let mut ty0 = 0u32;
    let mut ty1 = 0u32;
    let mut r = 0.0f32;
    if visible {
        tx0 = cols.lo as u32 / tile;
        tx1 = (cols.hi as u32 - 1) / tile + 1;
        ty0 = rows.lo as u32 / tile;
        ty1 = (rows.hi as u32 - 1) / tile + 1;
        r = radius;
    }
    rects[4 * i] = tx0;
    rects[4 * i + 1] = tx1;
    rects[4 * i + 2] = ty0;
    rects[4 * i + 3] = ty1;
    radii[i] = r;
    depth_keys[i] = u32::reinterpret(f.t2.max(0.0));
}

/// Gradient of `R(q)` with respect to the unit quaternion, given `dL/dR` (row-major `g`), as the
/// CPU code's `quat_to_matrix_backward`.
#[derive(CubeType, Clone, Copy)]
#[expand(derive(Clone))]
struct Quat {
    w: f32,
    x: f32,
    y: f32,
    z: f32,
}

#[cube]
#[allow(clippy::too_many_arguments)]
fn quat_backward(
    f: Fwd,
    g00: f32,
    g01: f32,
    g02: f32,
    g10: f32,
    g11: f32,
    g12: f32,
    g20: f32,
    g21: f32,
    g22: f32,
) -> Quat {
    let w: f32 = f.qw;
    let x: f32 = f.qx;
    let y: f32 = f.qy;
    let z: f32 = f.qz;
    // The CPU code's sums, with the negative terms grouped (no unary minus in device code).
    let gw: f32 = 2.0 * ((y * g02 + z * g10 + x * g21) - (z * g01 + x * g12 + y * g20));
    let gx: f32 = 2.0
        * ((y * g01 + z * g02 + y * g10 + z * g20 + w * g21)
            - (2.0 * x * g11 + w * g12 + 2.0 * x * g22));
    let gy: f32 = 2.0
        * ((x * g01 + w * g02 + x * g10 + z * g12 + z * g21)
            - (2.0 * y * g00 + w * g20 + 2.0 * y * g22));
    let gz: f32 = 2.0
        * ((x * g02 + w * g10 + y * g12 + x * g20 + y * g21)
            - (2.0 * z * g00 + w * g01 + 2.0 * z * g11));
    Quat {
        w: gw,
        x: gx,
        y: gy,
        z: gz,
    }
}

/// Backward of [`project_forward`](fn@project_forward): from each Gaussian's splat gradient
/// (`splat_grads`, [`GRAD_FLOATS`] per Gaussian, zero for culled ones) to its parameters, as the
/// CPU code's `project_one_backward`, and the `means2d` probe's gradient (pixel gradient × half
/// the image size, the reference code's NDC units).
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn project_backward(
    means: &[f32],
    log_scales: &[f32],
    quats: &[f32],
    opacity_logits: &[f32],
    sh: &[f32],
    cam: &[f32],
    rects: &[u32],
    splat_grads: &[f32],
    d_means: &mut [f32],
    d_log_scales: &mut [f32],
    d_quats: &mut [f32],
    d_opacity: &mut [f32],
    d_sh: &mut [f32],
    d_means2d: &mut [f32],
    n: u32,
    sh_coeffs: u32,
    k_used: u32,
    width: u32,
    height: u32,
) {
    let i = ABSOLUTE_POS;
    if i >= n as usize {
        terminate!();
    }
    let k3 = sh_coeffs as usize * 3;
    for k in 0..k3 {
        d_sh[i * k3 + k] = 0.0;
    }
    let visible = rects[4 * i + 1] > rects[4 * i];
    let o = i * GRAD_FLOATS;
    let dl_mx = splat_grads[o];
    let dl_my = splat_grads[o + 1];
    d_means2d[2 * i] = dl_mx * (width as f32 * 0.5);
    d_means2d[2 * i + 1] = dl_my * (height as f32 * 0.5);
    if !visible {
        d_means[3 * i] = 0.0;
        d_means[3 * i + 1] = 0.0;
        d_means[3 * i + 2] = 0.0;
        d_log_scales[3 * i] = 0.0;
        d_log_scales[3 * i + 1] = 0.0;
        d_log_scales[3 * i + 2] = 0.0;
        d_quats[4 * i] = 0.0;
        d_quats[4 * i + 1] = 0.0;
        d_quats[4 * i + 2] = 0.0;
        d_quats[4 * i + 3] = 0.0;
        d_opacity[i] = 0.0;
        terminate!();
    }
    let f = forward_one(
        means,
        log_scales,
        quats,
        opacity_logits,
        sh,
        cam,
        i,
        sh_coeffs,
        k_used,
    );
    let (dl_a, dl_b, dl_c) = (splat_grads[o + 2], splat_grads[o + 3], splat_grads[o + 4]);
    let dl_opacity = splat_grads[o + 5];
    let dl_depth = splat_grads[o + 9];
    d_opacity[i] = dl_opacity * f.opacity * (1.0 - f.opacity);

    // Colour: max(0, raw) → SH coefficients and the view direction.
    let dc_r = select(f.red < 0.0, 0.0f32, splat_grads[o + 6]);
    let dc_g = select(f.green < 0.0, 0.0f32, splat_grads[o + 7]);
    let dc_b = select(f.blue < 0.0, 0.0f32, splat_grads[o + 8]);
    let base = i * k3;
    let mut ddir_x = 0.0f32;
    let mut ddir_y = 0.0f32;
    let mut ddir_z = 0.0f32;
    for k in 0..k_used {
        let y = basis(k, f.dir.clone());
        let kk = base + 3 * k as usize;
        d_sh[kk] = y * dc_r;
        d_sh[kk + 1] = y * dc_g;
        d_sh[kk + 2] = y * dc_b;
        let s = dc_r * sh[kk] + dc_g * sh[kk + 1] + dc_b * sh[kk + 2];
        let dy = basis_grad(k, f.dir.clone());
        ddir_x += s * dy.x;
        ddir_y += s * dy.y;
        ddir_z += s * dy.z;
    }
    // d = v/|v|: dL/dv = (ddir − d (d·ddir)) / |v|.
    let dd = f.dir.x * ddir_x + f.dir.y * ddir_y + f.dir.z * ddir_z;
    let mut dm_x = (ddir_x - f.dir.x * dd) / f.dir_norm;
    let mut dm_y = (ddir_y - f.dir.y * dd) / f.dir_norm;
    let mut dm_z = (ddir_z - f.dir.z * dd) / f.dir_norm;

    // Screen centre and depth → camera-space point.
    let (fx, fy) = (cam_at(cam, CameraBuffer::FX), cam_at(cam, CameraBuffer::FY));
    let inv_z = 1.0 / f.t2;
    let mut dt0 = dl_mx * fx * inv_z;
    let mut dt1 = dl_my * fy * inv_z;
    let mut dt2 = -(dl_mx * fx * f.t0 + dl_my * fy * f.t1) * inv_z * inv_z;
    dt2 += dl_depth;

    // Conic C = A⁻¹ of A = [[a, b], [b, c]]: dL/dA = −C G C with G = [[ga, gb/2], [gb/2, gc]].
    let det = f.det;
    let c00 = f.cov_c / det;
    let c01 = -f.cov_b / det;
    let c11 = f.cov_a / det;
    let (g00, g01, g11) = (dl_a, dl_b * 0.5, dl_c);
    let cg00 = c00 * g00 + c01 * g01;
    let cg01 = c00 * g01 + c01 * g11;
    let cg10 = c01 * g00 + c11 * g01;
    let cg11 = c01 * g01 + c11 * g11;
    let da00 = -(cg00 * c00 + cg01 * c01);
    let da01 = -(cg00 * c01 + cg01 * c11);
    let da10 = -(cg10 * c00 + cg11 * c01);
    let da11 = -(cg10 * c01 + cg11 * c11);

    // Σ' = T Σ Tᵀ: dL/dΣ = Tᵀ dA T, dL/dT = 2 dA T Σ.
    let (m00, m01, m02, m10, m11, m12) = (f.m00, f.m01, f.m02, f.m10, f.m11, f.m12);
    // u = dA T (2×3)
    let u00 = da00 * m00 + da01 * m10;
    let u01 = da00 * m01 + da01 * m11;
    let u02 = da00 * m02 + da01 * m12;
    let u10 = da10 * m00 + da11 * m10;
    let u11 = da10 * m01 + da11 * m11;
    let u12 = da10 * m02 + da11 * m12;
    // dΣ = Tᵀ u (3×3)
    let ds00 = m00 * u00 + m10 * u10;
    let ds01 = m00 * u01 + m10 * u11;
    let ds02 = m00 * u02 + m10 * u12;
    let ds10 = m01 * u00 + m11 * u10;
    let ds11 = m01 * u01 + m11 * u11;
    let ds12 = m01 * u02 + m11 * u12;
    let ds20 = m02 * u00 + m12 * u10;
    let ds21 = m02 * u01 + m12 * u11;
    let ds22 = m02 * u02 + m12 * u12;
    // dT = 2 u Σ
    let (s00, s01, s02, s11, s12, s22) = (f.sg00, f.sg01, f.sg02, f.sg11, f.sg12, f.sg22);
    let dtm00 = 2.0 * (u00 * s00 + u01 * s01 + u02 * s02);
    let dtm01 = 2.0 * (u00 * s01 + u01 * s11 + u02 * s12);
    let dtm02 = 2.0 * (u00 * s02 + u01 * s12 + u02 * s22);
    let dtm10 = 2.0 * (u10 * s00 + u11 * s01 + u12 * s02);
    let dtm11 = 2.0 * (u10 * s01 + u11 * s11 + u12 * s12);
    let dtm12 = 2.0 * (u10 * s02 + u11 * s12 + u12 * s22);
    // T = J W: dL/dJ = dL/dT Wᵀ (only J00, J02, J11, J12 depend on t).
    let rot = rotation(cam);
    let dj00 = dtm00 * rot.w00 + dtm01 * rot.w01 + dtm02 * rot.w02;
    let dj02 = dtm00 * rot.w20 + dtm01 * rot.w21 + dtm02 * rot.w22;
    let dj11 = dtm10 * rot.w10 + dtm11 * rot.w11 + dtm12 * rot.w12;
    let dj12 = dtm10 * rot.w20 + dtm11 * rot.w21 + dtm12 * rot.w22;
    let iz2 = inv_z * inv_z;
    dt2 = dt2 - dj00 * fx * iz2 - dj11 * fy * iz2;
    if f.clamped_x {
        dt2 += dj02 * fx * f.rx * iz2;
    } else {
        dt0 -= dj02 * fx * iz2;
        dt2 += dj02 * 2.0 * fx * f.t0 * iz2 * inv_z;
    }
    if f.clamped_y {
        dt2 += dj12 * fy * f.ry * iz2;
    } else {
        dt1 -= dj12 * fy * iz2;
        dt2 += dj12 * 2.0 * fy * f.t1 * iz2 * inv_z;
    }
    // t = W p + t₀: dL/dp = Wᵀ dL/dt.
    dm_x += rot.w00 * dt0 + rot.w10 * dt1 + rot.w20 * dt2;
    dm_y += rot.w01 * dt0 + rot.w11 * dt1 + rot.w21 * dt2;
    dm_z += rot.w02 * dt0 + rot.w12 * dt1 + rot.w22 * dt2;
    d_means[3 * i] = dm_x;
    d_means[3 * i + 1] = dm_y;
    d_means[3 * i + 2] = dm_z;

    scale_rotation_backward(
        f,
        ds00,
        ds01,
        ds02,
        ds10,
        ds11,
        ds12,
        ds20,
        ds21,
        ds22,
        d_log_scales,
        d_quats,
        i,
    );
}

/// The 3D covariance's gradient `dΣ` (row-major) through `Σ = M Mᵀ`, `M = R(q) diag(s)`, to the
/// log-scales and the (unnormalised) quaternion of Gaussian `i`.
#[cube]
#[allow(clippy::too_many_arguments)]
fn scale_rotation_backward(
    f: Fwd,
    ds00: f32,
    ds01: f32,
    ds02: f32,
    ds10: f32,
    ds11: f32,
    ds12: f32,
    ds20: f32,
    ds21: f32,
    ds22: f32,
    d_log_scales: &mut [f32],
    d_quats: &mut [f32],
    i: usize,
) {
    // Σ = M Mᵀ, M = R S: dL/dM = 2 sym(dΣ) M; dL/ds_k = Σ_a R_ak dL/dM_ak; dL/dR = dL/dM S.
    let y01 = (ds01 + ds10) * 0.5;
    let y02 = (ds02 + ds20) * 0.5;
    let y12 = (ds12 + ds21) * 0.5;
    let (r00, r01, r02) = (f.r00, f.r01, f.r02);
    let (r10, r11, r12) = (f.r10, f.r11, f.r12);
    let (r20, r21, r22) = (f.r20, f.r21, f.r22);
    // Column k of M is s_k times column k of R.
    let mk00 = r00 * f.s0;
    let mk10 = r10 * f.s0;
    let mk20 = r20 * f.s0;
    let mk01 = r01 * f.s1;
    let mk11 = r11 * f.s1;
    let mk21 = r21 * f.s1;
    let mk02 = r02 * f.s2;
    let mk12 = r12 * f.s2;
    let mk22 = r22 * f.s2;
    let dmm00 = 2.0 * (ds00 * mk00 + y01 * mk10 + y02 * mk20);
    let dmm01 = 2.0 * (ds00 * mk01 + y01 * mk11 + y02 * mk21);
    let dmm02 = 2.0 * (ds00 * mk02 + y01 * mk12 + y02 * mk22);
    let dmm10 = 2.0 * (y01 * mk00 + ds11 * mk10 + y12 * mk20);
    let dmm11 = 2.0 * (y01 * mk01 + ds11 * mk11 + y12 * mk21);
    let dmm12 = 2.0 * (y01 * mk02 + ds11 * mk12 + y12 * mk22);
    let dmm20 = 2.0 * (y02 * mk00 + y12 * mk10 + ds22 * mk20);
    let dmm21 = 2.0 * (y02 * mk01 + y12 * mk11 + ds22 * mk21);
    let dmm22 = 2.0 * (y02 * mk02 + y12 * mk12 + ds22 * mk22);
    let dsc0 = r00 * dmm00 + r10 * dmm10 + r20 * dmm20;
    let dsc1 = r01 * dmm01 + r11 * dmm11 + r21 * dmm21;
    let dsc2 = r02 * dmm02 + r12 * dmm12 + r22 * dmm22;
    d_log_scales[3 * i] = dsc0 * f.s0;
    d_log_scales[3 * i + 1] = dsc1 * f.s1;
    d_log_scales[3 * i + 2] = dsc2 * f.s2;
    let dq = quat_backward(
        f.clone(),
        dmm00 * f.s0,
        dmm01 * f.s1,
        dmm02 * f.s2,
        dmm10 * f.s0,
        dmm11 * f.s1,
        dmm12 * f.s2,
        dmm20 * f.s0,
        dmm21 * f.s1,
        dmm22 * f.s2,
    );
    // q̂ = q/|q|: dL/dq = (dL/dq̂ − q̂ (q̂·dL/dq̂)) / |q|.
    let proj = f.qw * dq.w + f.qx * dq.x + f.qy * dq.y + f.qz * dq.z;
    d_quats[4 * i] = (dq.w - f.qw * proj) / f.q_norm;
    d_quats[4 * i + 1] = (dq.x - f.qx * proj) / f.q_norm;
    d_quats[4 * i + 2] = (dq.y - f.qy * proj) / f.q_norm;
    d_quats[4 * i + 3] = (dq.z - f.qz * proj) / f.q_norm;
}
