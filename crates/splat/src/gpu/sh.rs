//! Real spherical-harmonics basis functions (degree ≤ 3) and their gradients in device code,
//! the same constants and sign conventions as [`crate::sh`] (the Inria 3DGS code's).

use cubecl::prelude::*;

/// A 3-vector in device code.
#[derive(CubeType, Clone, Copy)]
#[expand(derive(Clone))]
pub struct Vec3 {
    pub x: f32,
    pub y: f32,
    pub z: f32,
}

const C0: f32 = 0.282_094_791_773_878_14_f64 as f32;
const C1: f32 = 0.488_602_511_902_919_9_f64 as f32;
const C2_0: f32 = 1.092_548_430_592_079_2_f64 as f32;
const C2_2: f32 = 0.315_391_565_252_520_05_f64 as f32;
const C2_4: f32 = 0.546_274_215_296_039_6_f64 as f32;
const C3_0: f32 = -0.590_043_589_926_643_5_f64 as f32;
const C3_1: f32 = 2.890_611_442_640_554_f64 as f32;
const C3_2: f32 = -0.457_045_799_464_465_8_f64 as f32;
const C3_3: f32 = 0.373_176_332_590_115_4_f64 as f32;
const C3_5: f32 = 1.445_305_721_320_277_f64 as f32;

/// `Y_k(d)` for the unit direction `d`.
#[cube]
pub fn basis(k: u32, d: Vec3) -> f32 {
    let (x, y, z) = (d.x, d.y, d.z);
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let mut v = f32::new(C0);
    if k == 1 {
        v = -C1 * y;
    } else if k == 2 {
        v = C1 * z;
    } else if k == 3 {
        v = -C1 * x;
    } else if k == 4 {
        v = C2_0 * (x * y);
    } else if k == 5 {
        v = -C2_0 * (y * z);
    } else if k == 6 {
        v = C2_2 * (2.0 * zz - xx - yy);
    } else if k == 7 {
        v = -C2_0 * (x * z);
    } else if k == 8 {
        v = C2_4 * (xx - yy);
    } else if k == 9 {
        v = C3_0 * y * (3.0 * xx - yy);
    } else if k == 10 {
        v = C3_1 * (x * y) * z;
    } else if k == 11 {
        v = C3_2 * y * (4.0 * zz - xx - yy);
    } else if k == 12 {
        v = C3_3 * z * (2.0 * zz - 3.0 * xx - 3.0 * yy);
    } else if k == 13 {
        v = C3_2 * x * (4.0 * zz - xx - yy);
    } else if k == 14 {
        v = C3_5 * z * (xx - yy);
    } else if k == 15 {
        v = C3_0 * x * (xx - 3.0 * yy);
    }
    v
}

/// `∂Y_k/∂d` (the direction treated as free; the caller projects out the radial part).
#[cube]
pub fn basis_grad(k: u32, d: Vec3) -> Vec3 {
    let (x, y, z) = (d.x, d.y, d.z);
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let mut g = Vec3 {
        x: 0.0f32,
        y: 0.0f32,
        z: 0.0f32,
    };
    if k == 1 {
        g.y = -C1;
    } else if k == 2 {
        g.z = C1;
    } else if k == 3 {
        g.x = -C1;
    } else if k == 4 {
        g.x = C2_0 * y;
        g.y = C2_0 * x;
    } else if k == 5 {
        g.y = -C2_0 * z;
        g.z = -C2_0 * y;
    } else if k == 6 {
        g.x = -2.0 * C2_2 * x;
        g.y = -2.0 * C2_2 * y;
        g.z = 4.0 * C2_2 * z;
    } else if k == 7 {
        g.x = -C2_0 * z;
        g.z = -C2_0 * x;
    } else if k == 8 {
        g.x = 2.0 * C2_4 * x;
        g.y = -2.0 * C2_4 * y;
    } else if k == 9 {
        g.x = C3_0 * 6.0 * (x * y);
        g.y = C3_0 * (3.0 * xx - 3.0 * yy);
    } else if k == 10 {
        g.x = C3_1 * (y * z);
        g.y = C3_1 * (x * z);
        g.z = C3_1 * (x * y);
    } else if k == 11 {
        g.x = -2.0 * C3_2 * (x * y);
        g.y = C3_2 * (4.0 * zz - xx - 3.0 * yy);
        g.z = 8.0 * C3_2 * (y * z);
    } else if k == 12 {
        g.x = -6.0 * C3_3 * (x * z);
        g.y = -6.0 * C3_3 * (y * z);
        g.z = C3_3 * (6.0 * zz - 3.0 * xx - 3.0 * yy);
    } else if k == 13 {
        g.x = C3_2 * (4.0 * zz - 3.0 * xx - yy);
        g.y = -2.0 * C3_2 * (x * y);
        g.z = 8.0 * C3_2 * (x * z);
    } else if k == 14 {
        g.x = 2.0 * C3_5 * (x * z);
        g.y = -2.0 * C3_5 * (y * z);
        g.z = C3_5 * (xx - yy);
    } else if k == 15 {
        g.x = C3_0 * (3.0 * xx - 3.0 * yy);
        g.y = -6.0 * C3_0 * (x * y);
    }
    g
}
