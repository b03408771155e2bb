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

fn camera_from_value(v: &Value) -> std::result::Result<Camera, String> {
    if let Ok(c) = serde_json::from_value::<Camera>(v.clone()) {
        return Ok(c);
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
    Ok(Camera::new(intr, Se3::from_matrix4(&m)))
}

fn check(c: &Camera, i: usize) -> std::result::Result<(), String> {
    if !c.is_finite() {
        return Err(format!("camera {i} has non-finite or non-positive values"));
    }
    let r = &c.world_to_camera.rotation;
    let err = (r.transpose() * r - nalgebra::Matrix3::identity()).norm();
    if err > 1e-3 {
        return Err(format!(
            "camera {i}: rotation is not orthonormal (|RᵀR − I| = {err:.2e})"
        ));
    }
    Ok(())
}

/// Reads one camera or a list of cameras.
pub fn read_cameras(path: &Path) -> Result<Vec<Camera>> {
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
            let cam = camera_from_value(c).map_err(|m| format!("camera {i}: {m}"))?;
            check(&cam, i)?;
            Ok(cam)
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
        let poses: Vec<Se3> = list
            .iter()
            .map(|m| Se3::from_matrix4(&matrix_from_rows(m).unwrap_or_else(Matrix4::identity)))
            .collect();
        for (i, p) in poses.iter().enumerate() {
            if !p.is_finite() {
                return Err(GeomError::format(path, format!("pose {i} is not finite")));
            }
        }
        return Ok(poses);
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
}
