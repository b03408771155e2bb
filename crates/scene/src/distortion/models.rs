//! Camera models as files name them: COLMAP's `cameras.{txt,bin}` models and the
//! `camera_model` + `k1 k2 k3 k4 p1 p2` fields of nerfstudio / instant-ngp `transforms.json`,
//! turned into a [`LensCamera`].

use super::lens::{Distortion, LensCamera};
use crate::camera::Intrinsics;

/// The COLMAP models this crate reads, with what their parameters are.
pub const COLMAP_SUPPORTED: &str =
    "SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV, OPENCV_FISHEYE";

/// The camera of a COLMAP model (parameters in COLMAP's order, e.g. `OPENCV`: `fx fy cx cy k1
/// k2 p1 p2`; `FULL_OPENCV`: `… k1 k2 p1 p2 k3 k4 k5 k6`, OpenCV's rational model), for an
/// image of `width × height`. COLMAP's pixel convention is this crate's (the top-left pixel's
/// centre at `(0.5, 0.5)`), so the values are used as they are. The caller has checked the
/// parameter count.
pub fn camera_from_colmap(
    model: &str,
    params: &[f64],
    width: u32,
    height: u32,
) -> std::result::Result<LensCamera, String> {
    let p = |i: usize| params.get(i).copied().unwrap_or(0.0);
    let k = |fx: f64, fy: f64, cx: f64, cy: f64| Intrinsics {
        fx,
        fy,
        cx,
        cy,
        width,
        height,
    };
    let radial = |k1: f64, k2: f64| Distortion::RadialTangential {
        radial: [k1, k2, 0.0, 0.0],
        rational: [0.0; 3],
        tangential: [0.0; 2],
    };
    let (intrinsics, distortion) = match model {
        "SIMPLE_PINHOLE" => (k(p(0), p(0), p(1), p(2)), None),
        "PINHOLE" => (k(p(0), p(1), p(2), p(3)), None),
        "SIMPLE_RADIAL" => (k(p(0), p(0), p(1), p(2)), Some(radial(p(3), 0.0))),
        "RADIAL" => (k(p(0), p(0), p(1), p(2)), Some(radial(p(3), p(4)))),
        "OPENCV" => (
            k(p(0), p(1), p(2), p(3)),
            Some(Distortion::opencv(&params[4..])),
        ),
        "FULL_OPENCV" => (
            k(p(0), p(1), p(2), p(3)),
            Some(Distortion::opencv(&params[4..])),
        ),
        "OPENCV_FISHEYE" => (
            k(p(0), p(1), p(2), p(3)),
            Some(Distortion::Fisheye {
                k: [p(4), p(5), p(6), p(7)],
            }),
        ),
        m if super::super::colmap::model_param_count(m).is_some() => {
            return Err(format!(
                "camera model {m} is not supported (supported: {COLMAP_SUPPORTED})"
            ));
        }
        m => return Err(format!("unknown camera model {m}")),
    };
    if let Some(v) = params.iter().find(|v| !v.is_finite()) {
        return Err(format!("{model} parameter {v} is not finite"));
    }
    Ok(LensCamera::new(intrinsics, distortion))
}

/// The distortion of a `transforms.json` camera: `camera_model` `OPENCV` (or none, as
/// instant-ngp writes, or a pinhole name) reads `k1 k2 k3 k4` as the radial polynomial on
/// `r² … r⁸` and `p1 p2` as tangential terms (nerfstudio's convention); `OPENCV_FISHEYE` reads
/// `k1 … k4` as the fisheye's. Other models are errors.
pub fn camera_from_transforms(
    intrinsics: Intrinsics,
    camera_model: Option<&str>,
    k: [Option<f64>; 4],
    p: [Option<f64>; 2],
) -> std::result::Result<LensCamera, String> {
    let k = k.map(|v| v.unwrap_or(0.0));
    let p = p.map(|v| v.unwrap_or(0.0));
    let model = camera_model.map(str::to_ascii_uppercase);
    let distortion = match model.as_deref() {
        None | Some("OPENCV" | "PINHOLE" | "SIMPLE_PINHOLE") => Distortion::RadialTangential {
            radial: k,
            rational: [0.0; 3],
            tangential: p,
        },
        Some("OPENCV_FISHEYE") => {
            if p.iter().any(|&v| v != 0.0) {
                return Err(
                    "camera_model OPENCV_FISHEYE has no tangential terms, but p1/p2 are set"
                        .to_owned(),
                );
            }
            Distortion::Fisheye { k }
        }
        Some(m) => {
            return Err(format!(
                "camera_model {m} is not supported (supported: OPENCV, OPENCV_FISHEYE, PINHOLE)"
            ));
        }
    };
    if let Some(v) = k.iter().chain(&p).find(|v| !v.is_finite()) {
        return Err(format!("distortion coefficient {v} is not finite"));
    }
    Ok(LensCamera::new(intrinsics, Some(distortion)))
}
