//! Cameras as JSON, for the command line.
//!
//! A camera file holds one camera or a list of them. Each camera is either the serde form of
//! [`fewview_scene::Camera`] (`{"intrinsics": {...}, "world_to_camera": {"rotation": [9 numbers,
//! column-major], "translation": [3]}}`) or the friendlier
//!
//! ```json
//! {"intrinsics": {"fx": 500, "fy": 500, "cx": 320, "cy": 240, "width": 640, "height": 480},
//!  "world_to_camera": [[1,0,0,0],[0,1,0,0],[0,0,1,2],[0,0,0,1]]}
//! ```
//!
//! with a row-major 4×4 world-to-camera matrix (OpenCV axes). Pose files (for pose error) may
//! also be a plain list of row-major 4×4 world-to-camera matrices.

use std::path::Path;

use fewview_scene::{Camera, Intrinsics, Se3};
use nalgebra::Matrix4;
use serde_json::Value;

use crate::error::{GeomError, Result};

fn matrix_from_rows(v: &Value) -> Option<Matrix4<f64>> {
    let rows = v.as_array()?;
    if rows.len() != 4 && rows.len() != 3 {
        return None;
    }
    let mut m = Matrix4::identity();
    for (r, row) in rows.iter().enumerate() {
        let row = row.as_array()?;
        if row.len() != 4 {
            return None;
        }
        for (c, x) in row.iter().enumerate() {
            m[(r, c)] = x.as_f64()?;
        }
    }
    Some(m)
}

/// A camera of either form, with its world-to-camera matrix as written (the serde form has no
/// last row, so its matrix has `[0, 0, 0, 1]`).
fn camera_from_value(v: &Value) -> std::result::Result<(Camera, Matrix4<f64>), String> {
    if let Ok(c) = serde_json::from_value::<Camera>(v.clone()) {
        let m = c.world_to_camera.to_matrix4();
        return Ok((c, m));
    }
    let intr: Intrinsics = serde_json::from_value(
        v.get("intrinsics")
            .cloned()
            .ok_or("camera has no 'intrinsics'")?,
    )
    .map_err(|e| format!("bad intrinsics: {e}"))?;
    let m = v
        .get("world_to_camera")
        .and_then(matrix_from_rows)
        .ok_or("'world_to_camera' must be a row-major 4×4 (or 3×4) matrix")?;
    Ok((Camera::new(intr, Se3::from_matrix4(&m)), m))
}

/// The largest magnitude a camera value (focal length, principal point, translation) may have:
/// the scene loaders' bound, beyond which single-precision rendering overflows.
pub const MAX_CAMERA_MAGNITUDE: f64 = fewview_scene::load::MAX_CAMERA_MAGNITUDE;

/// How far `RᵀR` may be from the identity (Frobenius norm) for `R` to count as a rotation, and
/// how far the last row of a pose matrix may be from `[0, 0, 0, 1]`.
const POSE_TOLERANCE: f64 = 1e-3;

/// Why a world-to-camera matrix is not a rigid pose, if it is not: a value that is not finite, a
/// translation beyond [`MAX_CAMERA_MAGNITUDE`], a rotation block that is not orthonormal or is a
/// reflection (det −1), or a last row other than `[0, 0, 0, 1]`.
pub fn pose_problem(m: &Matrix4<f64>) -> Option<String> {
    if let Some(v) = m.iter().find(|v| !v.is_finite()) {
        return Some(format!("holds a non-finite value ({v})"));
    }
    let t = m.fixed_view::<3, 1>(0, 3);
    if let Some(v) = t.iter().find(|v| v.abs() > MAX_CAMERA_MAGNITUDE) {
        return Some(format!(
            "translation {v:.3e} is beyond the {MAX_CAMERA_MAGNITUDE:.0e} a camera value may have"
        ));
    }
    let last = m.fixed_view::<1, 4>(3, 0);
    let identity_row = nalgebra::RowVector4::new(0.0, 0.0, 0.0, 1.0);
    if (last - identity_row).abs().max() > POSE_TOLERANCE {
        return Some(format!(
            "last row is [{}, {}, {}, {}], not [0, 0, 0, 1]",
            last[0], last[1], last[2], last[3]
        ));
    }
    let r = m.fixed_view::<3, 3>(0, 0).into_owned();
    let err = (r.transpose() * r - nalgebra::Matrix3::identity()).norm();
    if err > POSE_TOLERANCE {
        return Some(format!(
            "rotation is not orthonormal (|RᵀR − I| = {err:.2e})"
        ));
    }
    let det = r.determinant();
    if det <= 0.0 {
        return Some(format!(
            "rotation is a reflection (det {det:.3}), not a proper rotation (det +1)"
        ));
    }
    None
}

fn check(c: &Camera, m: &Matrix4<f64>, i: usize) -> std::result::Result<(), String> {
    let k = &c.intrinsics;
    if !k.is_finite() {
        return Err(format!("camera {i} has non-finite or non-positive values"));
    }
    if let Some((what, v)) = k
        .named_values()
        .into_iter()
        .find(|(_, v)| v.abs() > MAX_CAMERA_MAGNITUDE)
    {
        return Err(format!(
            "camera {i}: {what} {v:.3e} is beyond the {MAX_CAMERA_MAGNITUDE:.0e} a camera value may have"
        ));
    }
    if k.width == 0 || k.height == 0 {
        return Err(format!(
            "camera {i}: image size {}×{} is empty",
            k.width, k.height
        ));
    }
    match pose_problem(m) {
        Some(p) => Err(format!("camera {i}: world_to_camera {p}")),
        None => Ok(()),
    }
}

/// Reads one camera or a list of cameras.
pub fn read_cameras(path: &Path) -> Result<Vec<Camera>> {
    Ok(read_named_cameras(path)?
        .into_iter()
        .map(|(camera, _)| camera)
        .collect())
}

/// [`read_cameras`], each camera with its `name` when the file gives one (`fewview poses`
/// names each camera by its photo).
pub fn read_named_cameras(path: &Path) -> Result<Vec<(Camera, Option<String>)>> {
    let text = std::fs::read_to_string(path).map_err(|e| GeomError::io(path, e))?;
    let v: Value = serde_json::from_str(&text)
        .map_err(|e| GeomError::format(path, format!("not JSON: {e}")))?;
    let items: Vec<&Value> = match &v {
        Value::Array(a) => a.iter().collect(),
        other => vec![other],
    };
    let cams = items
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let (cam, m) = camera_from_value(c).map_err(|m| format!("camera {i}: {m}"))?;
            check(&cam, &m, i)?;
            let name = c.get("name").and_then(Value::as_str).map(str::to_string);
            Ok((cam, name))
        })
        .collect::<std::result::Result<Vec<_>, String>>()
        .map_err(|m| GeomError::format(path, m))?;
    if cams.is_empty() {
        return Err(GeomError::format(path, "no cameras in file"));
    }
    Ok(cams)
}

/// Reads world-to-camera poses: cameras (either form above) or plain 4×4 matrices.
pub fn read_poses(path: &Path) -> Result<Vec<Se3>> {
    let text = std::fs::read_to_string(path).map_err(|e| GeomError::io(path, e))?;
    let v: Value = serde_json::from_str(&text)
        .map_err(|e| GeomError::format(path, format!("not JSON: {e}")))?;
    if let Some(list) = v.as_array()
        && !list.is_empty()
        && list.iter().all(|m| matrix_from_rows(m).is_some())
    {
        return list
            .iter()
            .enumerate()
            .map(|(i, m)| {
                let m = matrix_from_rows(m).unwrap_or_else(Matrix4::identity);
                match pose_problem(&m) {
                    Some(p) => Err(GeomError::format(path, format!("pose {i}: {p}"))),
                    None => Ok(Se3::from_matrix4(&m)),
                }
            })
            .collect();
    }
    Ok(read_cameras(path)?
        .into_iter()
        .map(|c| c.world_to_camera)
        .collect())
}

/// The friendly JSON form of a camera (row-major 4×4).
pub fn camera_to_json(c: &Camera) -> Value {
    let m = c.world_to_camera.to_matrix4();
    let rows: Vec<Vec<f64>> = (0..4)
        .map(|r| (0..4).map(|k| m[(r, k)]).collect())
        .collect();
    serde_json::json!({ "intrinsics": c.intrinsics, "world_to_camera": rows })
}

/// Writes cameras in the friendly form, atomically.
pub fn write_cameras(path: &Path, cams: &[Camera]) -> Result<()> {
    let v = Value::Array(cams.iter().map(camera_to_json).collect());
    let text = serde_json::to_string_pretty(&v).map_err(|e| GeomError::io(path, e.into()))?;
    fewview_scene::atomic::write_bytes(path, text.as_bytes())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn both_forms_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let cam = Camera::look_at(
            Intrinsics::centered(300.0, 64, 48),
            Vector3::new(1.0, 2.0, 3.0),
            Vector3::zeros(),
            Vector3::new(0.0, 0.0, 1.0),
        );
        let p = dir.path().join("c.json");
        write_cameras(&p, &[cam.clone(), cam.clone()]).unwrap();
        let back = read_cameras(&p).unwrap();
        assert_eq!(back.len(), 2);
        assert!((back[0].world_to_camera.rotation - cam.world_to_camera.rotation).norm() < 1e-12);
        let p2 = dir.path().join("s.json");
        std::fs::write(&p2, serde_json::to_string(&cam).unwrap()).unwrap();
        assert_eq!(read_cameras(&p2).unwrap()[0], cam);
        assert_eq!(read_poses(&p).unwrap().len(), 2);
        let p3 = dir.path().join("m.json");
        std::fs::write(&p3, "[[[1,0,0,0],[0,1,0,0],[0,0,1,5],[0,0,0,1]]]").unwrap();
        assert_eq!(read_poses(&p3).unwrap()[0].translation.z, 5.0);
        std::fs::write(&p3, "[[[1,0,0,0],[0,2,0,0],[0,0,1,5],[0,0,0,1]]]").unwrap();
        // A list of matrices is taken as poses; as cameras it lacks intrinsics.
        let e = read_cameras(&p3).unwrap_err().to_string();
        assert!(e.contains("m.json") && e.contains("intrinsics"), "{e}");
    }

    /// Plain matrix lists and camera-form files both refuse a pose that is not rigid (shear,
    /// reflection, bad last row, non-finite or huge translation), naming the file and the index.
    #[test]
    fn poses_that_are_not_rigid_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("poses.json");
        let ok = "[[1,0,0,0],[0,1,0,0],[0,0,1,5],[0,0,0,1]]";
        let cases = [
            (
                "[[2,0,0,0],[0,1,0,0],[0,0,1,5],[0,0,0,1]]",
                "not orthonormal",
            ),
            ("[[-1,0,0,0],[0,1,0,0],[0,0,1,5],[0,0,0,1]]", "reflection"),
            ("[[1,0,0,0],[0,1,0,0],[0,0,1,5],[5,5,5,5]]", "last row"),
            (
                "[[1,0,0,1e300],[0,1,0,0],[0,0,1,5],[0,0,0,1]]",
                "translation",
            ),
        ];
        for (bad, problem) in cases {
            std::fs::write(&p, format!("[{ok}, {bad}]")).unwrap();
            let e = read_poses(&p).unwrap_err().to_string();
            assert!(e.contains("poses.json: pose 1: "), "{e}");
            assert!(e.contains(problem), "{e}");
            let intr = r#"{"fx": 500, "fy": 500, "cx": 16, "cy": 12, "width": 32, "height": 24}"#;
            let cam = |m: &str| format!(r#"{{"intrinsics": {intr}, "world_to_camera": {m}}}"#);
            std::fs::write(&p, format!("[{}, {}]", cam(ok), cam(bad))).unwrap();
            for e in [
                read_poses(&p).unwrap_err().to_string(),
                read_cameras(&p).unwrap_err().to_string(),
            ] {
                assert!(e.contains("poses.json: camera 1: world_to_camera"), "{e}");
                assert!(e.contains(problem), "{e}");
            }
        }
        std::fs::write(&p, format!("[{ok}]")).unwrap();
        assert_eq!(read_poses(&p).unwrap().len(), 1);
    }

    /// A camera with a focal length or principal point beyond the bound, or an empty image, is
    /// refused when reading, naming the camera file.
    #[test]
    fn camera_values_are_bounded() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("cam.json");
        let m = "[[1,0,0,0],[0,1,0,0],[0,0,1,2],[0,0,0,1]]";
        let cases = [
            (
                r#""fx": 1e300, "fy": 500, "cx": 16, "cy": 12, "width": 32, "height": 24"#,
                "focal length fx",
            ),
            (
                r#""fx": 500, "fy": 500, "cx": -1e13, "cy": 12, "width": 32, "height": 24"#,
                "principal point cx",
            ),
            (
                r#""fx": 500, "fy": 500, "cx": 16, "cy": 12, "width": 0, "height": 24"#,
                "is empty",
            ),
        ];
        for (intr, problem) in cases {
            let text = format!(r#"{{"intrinsics": {{{intr}}}, "world_to_camera": {m}}}"#);
            std::fs::write(&p, text).unwrap();
            let e = read_cameras(&p).unwrap_err().to_string();
            assert!(
                e.contains("cam.json: camera 0: ") && e.contains(problem),
                "{e}"
            );
        }
    }
}
