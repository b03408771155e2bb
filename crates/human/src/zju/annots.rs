//! ZJU-MoCap's `annots.npy`: a pickled dict
//! `{'cams': {'K': [3×3], 'R': [3×3], 'T': [3×1 mm], 'D': [5×1]}, 'ims': [{'ims': [path per
//! camera]}, ...]}` (one list entry per camera and per frame; releases store the lists as Python
//! lists or as stacked NumPy arrays, and both are accepted).

use std::path::Path;

use super::numpy::{Value, read_object_npy};
use crate::error::{HumanError, Result};

/// One camera's calibration as stored (OpenCV convention, translation in millimetres).
#[derive(Clone, Debug, PartialEq)]
pub struct CameraParams {
    /// Row-major 3×3.
    pub k: [f64; 9],
    /// Row-major 3×3.
    pub r: [f64; 9],
    /// Millimetres.
    pub t_mm: [f64; 3],
    /// OpenCV distortion coefficients (4 or 5).
    pub d: Vec<f64>,
}

/// The content of `annots.npy`.
#[derive(Clone, Debug, PartialEq)]
pub struct Annots {
    pub cameras: Vec<CameraParams>,
    /// `images[frame][camera]`: image path relative to the capture folder.
    pub images: Vec<Vec<String>>,
}

/// Reads and checks `annots.npy`.
pub fn read_annots(path: &Path) -> Result<Annots> {
    let root = read_object_npy(path)?;
    let bad = |m: String| HumanError::format(path, m);
    let cams = root
        .get("cams")
        .ok_or_else(|| bad("no 'cams' entry".into()))?;
    let k = per_camera(cams, "K", &[9], path)?;
    let r = per_camera(cams, "R", &[9], path)?;
    let t = per_camera(cams, "T", &[3], path)?;
    let d = per_camera(cams, "D", &[5, 4], path)?;
    let n = k.len();
    if [r.len(), t.len(), d.len()].iter().any(|&m| m != n) || n == 0 {
        let counts = [n, r.len(), t.len(), d.len()];
        return Err(bad(format!(
            "cams K, R, T, D hold {counts:?} cameras (need equal, non-zero)"
        )));
    }
    let cameras = (0..n)
        .map(|c| CameraParams {
            k: fixed(&k[c]),
            r: fixed(&r[c]),
            t_mm: fixed(&t[c]),
            d: d[c].clone(),
        })
        .collect();
    let images = read_images(&root, n, path)?;
    Ok(Annots { cameras, images })
}

fn fixed<const N: usize>(v: &[f64]) -> [f64; N] {
    let mut out = [0.0; N];
    out.copy_from_slice(&v[..N]);
    out
}

/// `cams[key]`: one entry per camera, each with one of the allowed numbers of values.
fn per_camera(cams: &Value, key: &str, sizes: &[usize], path: &Path) -> Result<Vec<Vec<f64>>> {
    let bad = |m: String| HumanError::format(path, format!("cams['{key}']: {m}"));
    let entry = cams.get(key).ok_or_else(|| bad("missing".into()))?;
    let items: Vec<Vec<f64>> = match entry {
        Value::Array(a) if a.shape.len() >= 2 => {
            let values = entry.numbers().ok_or_else(|| bad("not numeric".into()))?;
            let per = values.len() / a.shape[0].max(1);
            values.chunks(per.max(1)).map(<[f64]>::to_vec).collect()
        }
        _ => {
            let list = entry
                .items()
                .ok_or_else(|| bad(format!("{} is not a list", entry.kind())))?;
            list.iter()
                .map(|v| {
                    v.numbers()
                        .ok_or_else(|| bad(format!("an entry is {}", v.kind())))
                })
                .collect::<Result<_>>()?
        }
    };
    for (c, v) in items.iter().enumerate() {
        if !sizes.contains(&v.len()) || v.iter().any(|x| !x.is_finite()) {
            return Err(bad(format!(
                "camera {c} has {} values {v:?} (need {sizes:?}, finite)",
                v.len()
            )));
        }
    }
    Ok(items)
}

/// `ims[frame]['ims']`: the image path of every camera in every frame.
fn read_images(root: &Value, cameras: usize, path: &Path) -> Result<Vec<Vec<String>>> {
    let bad = |m: String| HumanError::format(path, m);
    let frames = root
        .get("ims")
        .and_then(Value::items)
        .ok_or_else(|| bad("no 'ims' list".into()))?;
    if frames.is_empty() {
        return Err(bad("'ims' holds no frames".into()));
    }
    let mut out = Vec::with_capacity(frames.len());
    for (f, frame) in frames.iter().enumerate() {
        let list = frame.get("ims").and_then(Value::items);
        let paths: Option<Vec<String>> =
            list.and_then(|l| l.iter().map(|v| v.as_str().map(str::to_owned)).collect());
        let paths = paths.ok_or_else(|| bad(format!("ims[{f}]['ims'] is not a list of paths")))?;
        if paths.len() != cameras {
            let msg = format!(
                "ims[{f}] lists {} images but cams has {cameras} cameras",
                paths.len()
            );
            return Err(bad(msg));
        }
        out.push(paths);
    }
    Ok(out)
}
