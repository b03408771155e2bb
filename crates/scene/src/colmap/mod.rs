//! COLMAP sparse models (text or binary): `cameras`, `images`, `points3D`, with the photos in
//! `images/`.
//!
//! COLMAP already uses this crate's convention: `cam_from_world` (quaternion `qw qx qy qz` +
//! translation) maps world to OpenCV camera axes, and the centre of the top-left pixel is at
//! `(0.5, 0.5)`. Pinhole models (`SIMPLE_PINHOLE`, `PINHOLE`) load as they are; the distortion
//! models `SIMPLE_RADIAL`, `RADIAL`, `OPENCV` and `FULL_OPENCV` load only when every distortion
//! coefficient is zero (undistort first, e.g. with `colmap image_undistorter`); fisheye and other
//! models are errors. COLMAP 3.12+ also writes `rigs` and `frames` files; they are not needed.

pub mod binary;
mod model;
pub mod text;

pub use model::{
    CAMERA_MODELS, ColmapCamera, ColmapImage, ColmapModel, ColmapPoint, PoseFields,
    model_param_count,
};

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::camera::Camera;
use crate::dataset::{Dataset, View};
use crate::error::{Result, SceneError};
use crate::load_options::LoadOptions;
use crate::load_report::LoadReport;
use crate::split;
use crate::view_files;

/// The folder holding a COLMAP model: `sparse/0/`, `sparse/` or `root` itself, the first with a
/// `cameras.bin` or `cameras.txt`.
pub fn find_model_dir(root: &Path) -> Option<PathBuf> {
    [
        root.join("sparse").join("0"),
        root.join("sparse"),
        root.to_owned(),
    ]
    .into_iter()
    .find(|d| d.join("cameras.bin").is_file() || d.join("cameras.txt").is_file())
}

/// Reads the model in `dir`: binary when `cameras.bin` exists, else text. A missing file of the
/// three is an error naming it.
pub fn read_model(dir: &Path) -> Result<ColmapModel> {
    let (ext, is_binary) = if dir.join("cameras.bin").is_file() {
        ("bin", true)
    } else {
        ("txt", false)
    };
    let path = |name: &str| dir.join(format!("{name}.{ext}"));
    for name in ["cameras", "images", "points3D"] {
        let p = path(name);
        if !p.is_file() {
            let e = std::io::Error::new(
                std::io::ErrorKind::NotFound,
                "missing file of the COLMAP model",
            );
            return Err(SceneError::io(p, e));
        }
    }
    let model = if is_binary {
        ColmapModel {
            cameras: binary::read_cameras(&path("cameras"))?,
            images: binary::read_images(&path("images"))?,
            points: binary::read_points(&path("points3D"))?,
        }
    } else {
        ColmapModel {
            cameras: text::read_cameras(&path("cameras"))?,
            images: text::read_images(&path("images"))?,
            points: text::read_points(&path("points3D"))?,
        }
    };
    if let Some(img) = model
        .images
        .iter()
        .find(|i| !model.cameras.contains_key(&i.camera_id))
    {
        return Err(SceneError::invalid(
            path("images"),
            format!(
                "image {} ({}) refers to camera {}, which cameras.{ext} lacks",
                img.id, img.name, img.camera_id
            ),
        ));
    }
    // Ids and names must each name one image: the views are looked up by name and the refined
    // poses are written back by id.
    let mut ids = std::collections::BTreeSet::new();
    let mut names = std::collections::BTreeSet::new();
    for img in &model.images {
        if !ids.insert(img.id) {
            return Err(SceneError::invalid(
                path("images"),
                format!("image id {} appears twice", img.id),
            ));
        }
        if !names.insert(img.name.as_str()) {
            return Err(SceneError::invalid(
                path("images"),
                format!("image name {} appears twice", img.name),
            ));
        }
    }
    Ok(model)
}

/// The points of the model in `dir` alone (`points3D.bin`, else `points3D.txt`), `None` when
/// neither exists.
pub fn read_points_in(dir: &Path) -> Result<Option<Vec<ColmapPoint>>> {
    let (bin, txt) = (dir.join("points3D.bin"), dir.join("points3D.txt"));
    if bin.is_file() {
        binary::read_points(&bin).map(Some)
    } else if txt.is_file() {
        text::read_points(&txt).map(Some)
    } else {
        Ok(None)
    }
}

/// Loads a COLMAP scene: the model (see [`find_model_dir`]), photos from `images/` by name.
/// Views are sorted by image name (as 3DGS does); the split is a capture's
/// ([`split::capture_split`]: at most [`split::FEW_PHOTOS`] photos all train; more are split
/// LLFF-style, every `holdout_every`-th view a test view and `n_train` spread evenly over the
/// rest, default all). The model's points become [`Dataset::points`].
pub fn load(root: &Path, opts: &LoadOptions, report: &mut LoadReport) -> Result<Dataset> {
    let dir = find_model_dir(root).ok_or_else(|| {
        SceneError::format(
            root,
            "no COLMAP model (cameras.bin or cameras.txt in sparse/0/, sparse/ or the folder)",
        )
    })?;
    let model = read_model(&dir)?;
    let mut images = model.images.clone();
    if images.is_empty() {
        return Err(SceneError::format(
            &dir,
            "the model has no registered images",
        ));
    }
    images.sort_by(|a, b| a.name.cmp(&b.name));
    let background = opts.background.unwrap_or([0.0; 3]);
    let image_dir = root.join("images");
    let k = opts.downscale;
    let cameras_file = ["cameras.bin", "cameras.txt"]
        .map(|n| dir.join(n))
        .into_iter()
        .find(|p| p.is_file())
        .unwrap_or_else(|| dir.clone());
    let loaded = view_files::first_error_in_order(images.par_iter().map(|img| {
        let cam = &model.cameras[&img.camera_id];
        let lens = cam
            .lens()
            .map_err(|m| SceneError::invalid(&cameras_file, format!("camera {}: {m}", cam.id)))?;
        let pose = img
            .world_to_camera()
            .map_err(|m| SceneError::invalid(&dir, m))?;
        let what = format!("image {} ({})", img.id, img.name);
        view_files::check_camera(&Camera::new(lens.intrinsics, pose), &dir, &what)?;
        let file = image_dir.join(&img.name);
        let p = view_files::load_lens_photo(
            &file,
            &lens,
            opts,
            root,
            background,
            (&cameras_file, &what),
        )?;
        let camera = Camera::new(p.intrinsics, pose);
        view_files::check_size(&p.photo.rgb, &camera, &file, "image")?;
        let mask = match p.photo.alpha {
            Some(a) => Some(view_files::downscale_mask(&a, k, false, &file)?),
            None => None,
        };
        let valid = match p.valid {
            Some(v) => Some(view_files::downscale_mask(&v, k, true, &file)?),
            None => None,
        };
        let view = View {
            name: view_files::stem(Path::new(&img.name)),
            camera: view_files::downscale_camera(&camera, k),
            image: view_files::downscale_image(&p.photo.rgb, k, &file)?,
            mask_is_alpha: mask.is_some(),
            mask,
            valid,
            depth_bounds: None,
            source_index: img.id as usize,
        };
        Ok((view, p.outcome))
    }))?;
    let mut views = Vec::with_capacity(loaded.len());
    for (view, outcome) in loaded {
        report.record(&outcome);
        views.push(view);
    }
    let n_views = views.len();
    let (train, test) = split::capture_split(
        n_views,
        (opts.train_views.as_deref(), opts.test_views.as_deref()),
        opts.n_train,
        opts.holdout_every,
        root,
    )?;
    Ok(Dataset {
        name: view_files::scene_name(root),
        views,
        train,
        test,
        points: Some(model.point_cloud()),
        background,
        to_source_world: None,
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::image::Image;
    use nalgebra::Vector3;
    use serde_json::Value;

    fn fixtures() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/colmap")
    }

    fn reference() -> Value {
        let text = std::fs::read_to_string(fixtures().join("reference.json")).unwrap();
        serde_json::from_str(&text).unwrap()
    }

    /// A scene folder with the fixture model under `sparse/0` and blank photos of the right sizes.
    pub(crate) fn scene(sub: &str) -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        let model = dir.path().join("sparse/0");
        std::fs::create_dir_all(&model).unwrap();
        for entry in std::fs::read_dir(fixtures().join(sub)).unwrap() {
            let p = entry.unwrap().path();
            std::fs::copy(&p, model.join(p.file_name().unwrap())).unwrap();
        }
        std::fs::create_dir_all(dir.path().join("images")).unwrap();
        for (name, img) in reference()["images"].as_object().unwrap() {
            let (w, h) = (
                img["width"].as_u64().unwrap(),
                img["height"].as_u64().unwrap(),
            );
            Image::filled(w as usize, h as usize, &[0.5, 0.25, 0.0])
                .save_png(&dir.path().join("images").join(name))
                .unwrap();
        }
        dir
    }

    fn f(v: &Value) -> f64 {
        v.as_f64().unwrap()
    }

    /// Both encodings reproduce pycolmap's cameras, poses, projections and points.
    #[test]
    fn text_and_binary_match_pycolmap() {
        let reference = reference();
        let mut models = Vec::new();
        for sub in ["text", "binary"] {
            let model = read_model(&fixtures().join(sub)).unwrap();
            models.push(model.clone());
            let dir = scene(sub);
            let d = crate::load::load_dataset(dir.path(), &LoadOptions::default()).unwrap();
            let names: Vec<&str> = d.views.iter().map(|v| v.name.as_str()).collect();
            assert_eq!(names, ["a", "b", "c", "d"], "{sub}");
            // Four photos: all train, none held out (a capture of few photos).
            assert_eq!(
                (d.test.clone(), d.train.clone()),
                (vec![], vec![0, 1, 2, 3])
            );
            let points = d.points.as_ref().unwrap();
            let ref_points = reference["points"].as_array().unwrap();
            assert_eq!(points.len(), ref_points.len());
            for (v, img) in d.views.iter().zip(["a.png", "b.png", "c.png", "d.png"]) {
                let r = &reference["images"][img];
                let kr = &r["K"];
                let k = &v.camera.intrinsics;
                assert_eq!(
                    (k.fx, k.fy, k.cx, k.cy),
                    (f(&kr[0][0]), f(&kr[1][1]), f(&kr[0][2]), f(&kr[1][2])),
                    "{sub} {img}"
                );
                let m = v.camera.world_to_camera.to_matrix4();
                for row in 0..3 {
                    for col in 0..4 {
                        assert!((m[(row, col)] - f(&r["cam_from_world"][row][col])).abs() < 1e-12);
                    }
                }
                let c = v.camera.center();
                for a in 0..3 {
                    assert!((c[a] - f(&r["center"][a])).abs() < 1e-12);
                }
                for (rp, proj) in ref_points.iter().zip(r["projections"].as_array().unwrap()) {
                    let x = Vector3::new(f(&rp["xyz"][0]), f(&rp["xyz"][1]), f(&rp["xyz"][2]));
                    let (u, w, _) = v.camera.project(&x).unwrap();
                    assert!(
                        (u - f(&proj[0])).abs() < 1e-9 && (w - f(&proj[1])).abs() < 1e-9,
                        "{sub} {img}"
                    );
                }
            }
            for (p, rp) in points.positions.iter().zip(ref_points) {
                for a in 0..3 {
                    assert_eq!(p[a], f(&rp["xyz"][a]) as f32);
                }
            }
            for (c, rp) in points.colors.iter().zip(ref_points) {
                for a in 0..3 {
                    assert_eq!(c[a], rp["rgb"][a].as_u64().unwrap() as f32 / 255.0);
                }
            }
        }
        // Text (17 significant digits) and binary agree exactly.
        assert_eq!(models[0], models[1]);
    }

    /// Two images with one id, or with one name, are refused: the views are found by name and
    /// the refined poses written back by id.
    #[test]
    fn duplicate_image_ids_and_names_are_refused() {
        let dir = scene("text");
        let images = dir.path().join("sparse/0/images.txt");
        let original = std::fs::read_to_string(&images).unwrap();
        for (from, to, expected) in [
            ("\n4 0.5469", "\n2 0.5469", "image id 2 appears twice"),
            ("1 b.png", "1 c.png", "image name c.png appears twice"),
        ] {
            assert!(original.contains(from));
            std::fs::write(&images, original.replace(from, to)).unwrap();
            let e = crate::load::load_dataset(dir.path(), &LoadOptions::default())
                .unwrap_err()
                .to_string();
            assert!(e.contains("images.txt") && e.contains(expected), "{e}");
        }
    }

    #[test]
    fn distortion_and_bad_files_are_one_line_errors() {
        let dir = scene("text");
        let cams = dir.path().join("sparse/0/cameras.txt");
        let original = std::fs::read_to_string(&cams).unwrap();
        // Distortion loads (undistorted into a pinhole); models outside the supported ones and
        // unknown ones are refused.
        std::fs::write(&cams, original.replace("16.25 11.75 0", "16.25 11.75 0.01")).unwrap();
        let d = crate::load::load_dataset(dir.path(), &LoadOptions::default()).unwrap();
        assert_eq!(d.views.len(), 4);
        for (from, expected) in [
            (
                "3 SIMPLE_RADIAL 32 24 28 16.25 11.75 0",
                "FOV is not supported",
            ),
            (
                "3 SIMPLE_RADIAL 32 24 28 16.25 11.75 0",
                "unknown camera model",
            ),
        ] {
            let to = if expected.starts_with("FOV") {
                "3 FOV 32 24 28 28 16 12 0.1"
            } else {
                "3 KANNALA_BRANDT 32 24 28 28 16 12"
            };
            std::fs::write(&cams, original.replace(from, to)).unwrap();
            let e = crate::load::load_dataset(dir.path(), &LoadOptions::default())
                .unwrap_err()
                .to_string();
            assert!(e.contains("cameras.txt") && e.contains(expected), "{e}");
        }
        std::fs::write(
            &cams,
            original.replace("PINHOLE 40 30 35 33", "PINHOLE 40 30 nan 33"),
        )
        .unwrap();
        let e = crate::load::load_dataset(dir.path(), &LoadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("cameras.txt") && e.contains("PINHOLE parameter NaN is not finite"),
            "{e}"
        );
        std::fs::write(
            &cams,
            original.replace("PINHOLE 40 30 35 33 19.5", "PINHOLE 40 30 35 33"),
        )
        .unwrap();
        let e = crate::load::load_dataset(dir.path(), &LoadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("cameras.txt")
                && e.contains("line 5")
                && e.contains("PINHOLE needs 4 parameters"),
            "{e}"
        );
        std::fs::write(&cams, &original).unwrap();
        // Photo of the wrong size.
        Image::filled(10, 10, &[0.0; 3])
            .save_png(&dir.path().join("images/b.png"))
            .unwrap();
        let e = crate::load::load_dataset(dir.path(), &LoadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("b.png") && e.contains("image is 10×10 but its camera is 32×24"),
            "{e}"
        );
        std::fs::remove_file(dir.path().join("images/b.png")).unwrap();
        let e = crate::load::load_dataset(dir.path(), &LoadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("b.png"), "{e}");
        std::fs::remove_file(dir.path().join("sparse/0/points3D.txt")).unwrap();
        let e = crate::load::load_dataset(dir.path(), &LoadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("points3D.txt") && e.contains("missing file"),
            "{e}"
        );

        // Binary: truncation anywhere is an error naming the file, never a panic.
        let dir = scene("binary");
        for name in ["cameras.bin", "images.bin", "points3D.bin"] {
            let p = dir.path().join("sparse/0").join(name);
            let bytes = std::fs::read(&p).unwrap();
            for cut in [0, 7, 8, 20, bytes.len() / 2, bytes.len() - 1] {
                std::fs::write(&p, &bytes[..cut]).unwrap();
                let e = crate::load::load_dataset(dir.path(), &LoadOptions::default())
                    .unwrap_err()
                    .to_string();
                assert!(
                    e.contains(name) && e.contains("truncated"),
                    "{name} cut {cut}: {e}"
                );
            }
            std::fs::write(&p, &bytes).unwrap();
        }
        // Trailing garbage is corruption too.
        let p = dir.path().join("sparse/0/cameras.bin");
        let mut bytes = std::fs::read(&p).unwrap();
        bytes.extend_from_slice(&[1, 2, 3]);
        std::fs::write(&p, &bytes).unwrap();
        let e = crate::load::load_dataset(dir.path(), &LoadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("cameras.bin") && e.contains("3 bytes left over"),
            "{e}"
        );
    }
}
