//! OpenCV-calibrated cameras (the synthetic capture's `cameras.json`, ZJU-MoCap's `annots.npy`)
//! converted to fewview-scene's [`Camera`].
//!
//! Both formats put pixel centres at integer coordinates: the top-left pixel's centre is `(0, 0)`.
//! fewview-scene puts it at `(0.5, 0.5)` (pixel `i` covers `[i, i + 1)`), so the conversion adds
//! half a pixel to the principal point and to every 2D position ([`pixel_from_opencv`]); focal
//! lengths, rotation and translation are unchanged. The axes are already OpenCV's (x right,
//! y down, z forward, world-to-camera `x_cam = R x_world + t`).

use std::path::Path;

use fewview_scene::{Camera, Intrinsics, Se3};
use nalgebra::{Matrix3, Vector3};

use crate::error::{HumanError, Result};

/// How far `RᵀR` may be from the identity (max abs entry) before a rotation is refused; within
/// it the matrix is replaced by the nearest rotation (calibration files print ~9 digits).
const ROTATION_TOLERANCE: f64 = 1e-4;

/// Half a pixel: OpenCV's integer pixel centres to fewview-scene's half-integer ones.
pub const HALF_PIXEL: f64 = 0.5;

/// A pixel position `(u, v)` from OpenCV's convention to fewview-scene's.
pub fn pixel_from_opencv(p: [f64; 2]) -> [f64; 2] {
    [p[0] + HALF_PIXEL, p[1] + HALF_PIXEL]
}

/// The camera of an OpenCV calibration `K`, `R`, `t` (translation in metres) for a
/// `width × height` image. `what` names the camera in errors about `path`.
pub fn camera_from_opencv(
    k: &Matrix3<f64>,
    r: &Matrix3<f64>,
    t: &Vector3<f64>,
    size: (u32, u32),
    path: &Path,
    what: &str,
) -> Result<Camera> {
    let bad = |m: String| HumanError::invalid(path, format!("{what}: {m}"));
    if !(k
        .iter()
        .chain(r.iter())
        .chain(t.iter())
        .all(|v| v.is_finite()))
    {
        return Err(bad("K, R and t must be finite".into()));
    }
    let zero = [k[(0, 1)], k[(1, 0)], k[(2, 0)], k[(2, 1)]];
    if zero
        .iter()
        .any(|v| v.abs() > 1e-9 * k[(0, 0)].abs().max(1.0))
        || k[(2, 2)] != 1.0
    {
        return Err(bad(format!(
            "K = {:?} is not a pinhole matrix without skew",
            k.as_slice()
        )));
    }
    if !(k[(0, 0)] > 0.0 && k[(1, 1)] > 0.0) {
        return Err(bad("focal lengths must be positive".into()));
    }
    if size.0 == 0 || size.1 == 0 {
        return Err(bad(format!("image size {}×{}", size.0, size.1)));
    }
    let rotation = nearest_rotation(r).ok_or_else(|| bad("R is not a rotation matrix".into()))?;
    let intrinsics = Intrinsics {
        fx: k[(0, 0)],
        fy: k[(1, 1)],
        cx: k[(0, 2)] + HALF_PIXEL,
        cy: k[(1, 2)] + HALF_PIXEL,
        width: size.0,
        height: size.1,
    };
    Ok(Camera::new(intrinsics, Se3::new(rotation, *t)))
}

/// The rotation nearest to `r` (SVD), when `r` is within [`ROTATION_TOLERANCE`] of orthonormal
/// with a positive determinant (`r` itself when orthonormal to 1e-12).
fn nearest_rotation(r: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let err = (r.transpose() * r - Matrix3::identity()).amax();
    if !(err <= ROTATION_TOLERANCE) || r.determinant() <= 0.0 {
        return None;
    }
    if err <= 1e-12 {
        return Some(*r);
    }
    let svd = r.svd(true, true);
    Some(svd.u? * svd.v_t?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn principal_point_moves_half_a_pixel_and_projections_agree() {
        let k = Matrix3::new(640.0, 0.0, 255.5, 0.0, 640.0, 255.5, 0.0, 0.0, 1.0);
        let r = Matrix3::identity();
        let t = Vector3::new(0.1, -0.2, 3.0);
        let cam = camera_from_opencv(&k, &r, &t, (512, 512), Path::new("x"), "cam").unwrap();
        assert_eq!((cam.intrinsics.cx, cam.intrinsics.cy), (256.0, 256.0));
        // OpenCV's projection K (R X + t), moved by half a pixel, is fewview's projection.
        let x = Vector3::new(0.3, 0.1, 0.5);
        let p = k * (r * x + t);
        let (u, v) = (p.x / p.z, p.y / p.z);
        let (u2, v2, _) = cam.project(&x).unwrap();
        let q = pixel_from_opencv([u, v]);
        assert!((q[0] - u2).abs() < 1e-12 && (q[1] - v2).abs() < 1e-12);
    }

    #[test]
    fn skew_reflection_and_nan_are_refused() {
        let path = Path::new("cams.json");
        let t = Vector3::zeros();
        let skew = Matrix3::new(600.0, 2.0, 300.0, 0.0, 600.0, 200.0, 0.0, 0.0, 1.0);
        let e = camera_from_opencv(&skew, &Matrix3::identity(), &t, (4, 4), path, "cam_01");
        assert!(e.unwrap_err().to_string().contains("cam_01: K"));
        let k = Matrix3::new(600.0, 0.0, 300.0, 0.0, 600.0, 200.0, 0.0, 0.0, 1.0);
        let flip = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0));
        let e = camera_from_opencv(&k, &flip, &t, (4, 4), path, "cam_02").unwrap_err();
        assert!(e.to_string().contains("not a rotation"), "{e}");
        let mut nan = k;
        nan[(0, 2)] = f64::NAN;
        let e = camera_from_opencv(&nan, &Matrix3::identity(), &t, (4, 4), path, "c").unwrap_err();
        assert!(e.to_string().starts_with("cams.json: c: "), "{e}");
    }
}
