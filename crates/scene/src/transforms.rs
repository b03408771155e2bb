//! `transforms*.json` datasets: NeRF-synthetic ("Blender": `transforms_train.json` +
//! `transforms_test.json`) and nerfstudio / instant-ngp (one `transforms.json`).
//!
//! Each frame has a 4×4 **camera-to-world** `transform_matrix` in OpenGL camera axes (x right,
//! y up, looking along −z), converted here to OpenCV by negating the y and z axes. `file_path`
//! is relative to the JSON file; one without an extension gets `.png` (NeRF-synthetic).
//!
//! Intrinsics, per frame or for the whole file (a frame's value wins): `fl_x`, `fl_y`, `cx`,
//! `cy`, `w`, `h` in pixels, or NeRF's `camera_angle_x` (focal `0.5·W / tan(0.5·angle_x)`,
//! `fy = fx`, principal point at the image centre). The image centre is `(W/2, H/2)` in this
//! crate's half-integer pixel convention, as in 3DGS and nerfstudio; NeRF's original ray
//! generator put pixel centres at integers, half a pixel off from this.
//!
//! **Distortion**: `camera_model` `OPENCV` (or none, as instant-ngp writes) with `k1 k2 k3 k4
//! p1 p2`, or `OPENCV_FISHEYE` with `k1 … k4`, per file or per frame
//! ([`crate::distortion::camera_from_transforms`]); photos are undistorted into a pinhole on
//! load ([`LoadOptions::undistort`]). Other models (`EQUIRECTANGULAR`) are errors.
//!
//! nerfstudio: frames whose image file is missing are skipped (as instant-ngp and nerfstudio
//! do) and counted in the load report; an error only when none remains.
//!
//! RGBA images are composited over the background (white by default, the NeRF protocol
//! `rgb·a + (1 − a)`) and their alpha kept as the view's (soft) mask. A frame's `mask_path`, when
//! present, gives a binary mask instead.

use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Matrix4};
use rayon::prelude::*;
use serde::Deserialize;

use crate::axes::opengl_to_opencv;
use crate::camera::{Camera, Intrinsics, Se3};
use crate::dataset::{Dataset, View};
use crate::distortion::cache::CacheOutcome;
use crate::distortion::{LensCamera, camera_from_transforms};
use crate::error::{Result, SceneError};
use crate::image::Image;
use crate::load_options::LoadOptions;
use crate::load_report::LoadReport;
use crate::split;
use crate::view_files;

/// Intrinsics and distortion fields, at file or frame level.
#[derive(Clone, Debug, Default, Deserialize)]
struct CameraFields {
    camera_angle_x: Option<f64>,
    fl_x: Option<f64>,
    fl_y: Option<f64>,
    cx: Option<f64>,
    cy: Option<f64>,
    w: Option<f64>,
    h: Option<f64>,
    k1: Option<f64>,
    k2: Option<f64>,
    k3: Option<f64>,
    k4: Option<f64>,
    p1: Option<f64>,
    p2: Option<f64>,
    camera_model: Option<String>,
}

impl CameraFields {
    /// Frame-level fields over file-level ones.
    fn or(&self, file: &CameraFields) -> CameraFields {
        CameraFields {
            camera_angle_x: self.camera_angle_x.or(file.camera_angle_x),
            fl_x: self.fl_x.or(file.fl_x),
            fl_y: self.fl_y.or(file.fl_y),
            cx: self.cx.or(file.cx),
            cy: self.cy.or(file.cy),
            w: self.w.or(file.w),
            h: self.h.or(file.h),
            k1: self.k1.or(file.k1),
            k2: self.k2.or(file.k2),
            k3: self.k3.or(file.k3),
            k4: self.k4.or(file.k4),
            p1: self.p1.or(file.p1),
            p2: self.p2.or(file.p2),
            camera_model: self.camera_model.clone().or(file.camera_model.clone()),
        }
    }

    /// The camera with its lens for an image of `width × height` (see the module docs).
    fn lens(&self, width: usize, height: usize) -> std::result::Result<LensCamera, String> {
        let intrinsics = self.intrinsics(width, height)?;
        camera_from_transforms(
            intrinsics,
            self.camera_model.as_deref(),
            [self.k1, self.k2, self.k3, self.k4],
            [self.p1, self.p2],
        )
    }

    /// Whether the camera model and distortion fields can be read, before any image is.
    fn check_model(&self) -> std::result::Result<(), String> {
        camera_from_transforms(
            Intrinsics::centered(1.0, 1, 1),
            self.camera_model.as_deref(),
            [self.k1, self.k2, self.k3, self.k4],
            [self.p1, self.p2],
        )
        .map(|_| ())
    }

    /// The image size the fields state, when they state both `w` and `h`.
    fn stated_size(&self) -> Option<(usize, usize)> {
        let (w, h) = (self.w?, self.h?);
        (w >= 1.0 && h >= 1.0 && w.fract() == 0.0 && h.fract() == 0.0)
            .then_some((w as usize, h as usize))
    }

    /// Pinhole intrinsics for an image of `width × height`.
    fn intrinsics(&self, width: usize, height: usize) -> std::result::Result<Intrinsics, String> {
        let (w, h) = (width as f64, height as f64);
        for (name, stated, actual) in [("w", self.w, w), ("h", self.h, h)] {
            if let Some(stated) = stated
                && stated != actual
            {
                return Err(format!(
                    "image is {width}×{height} but the file says {name}={stated}"
                ));
            }
        }
        let k = if let Some(fx) = self.fl_x {
            Intrinsics {
                fx,
                fy: self.fl_y.unwrap_or(fx),
                cx: self.cx.unwrap_or(w / 2.0),
                cy: self.cy.unwrap_or(h / 2.0),
                width: width as u32,
                height: height as u32,
            }
        } else if let Some(angle) = self.camera_angle_x {
            if !(angle > 0.0 && angle < std::f64::consts::PI) {
                return Err(format!("camera_angle_x = {angle} is not in (0, π)"));
            }
            Intrinsics::centered(0.5 * w / (0.5 * angle).tan(), width as u32, height as u32)
        } else {
            return Err("no intrinsics: needs camera_angle_x or fl_x".to_owned());
        };
        Ok(k)
    }
}

#[derive(Clone, Debug, Deserialize)]
struct FrameJson {
    file_path: String,
    transform_matrix: [[f64; 4]; 4],
    mask_path: Option<String>,
    /// Near and far z-depth of the scene in this frame (a fewview extension that nerfstudio
    /// ignores; `fewview poses` writes it from the points each photo sees).
    depth_bounds: Option<[f64; 2]>,
    /// Indices of the `ply_file_path` points this photo observed (a fewview extension that
    /// nerfstudio ignores; `fewview poses` writes each photo's track memberships).
    observed_points: Option<Vec<u32>>,
    #[serde(flatten)]
    camera: CameraFields,
}

#[derive(Clone, Debug, Deserialize)]
struct TransformsJson {
    #[serde(flatten)]
    camera: CameraFields,
    frames: Vec<FrameJson>,
    /// A PLY point cloud of the scene, relative to the file (nerfstudio's `ns-process-data`
    /// writes its COLMAP points as `sparse_pc.ply` and names it here).
    ply_file_path: Option<String>,
}

/// One frame of a transforms file, resolved against the file's folder.
#[derive(Clone, Debug)]
pub struct Frame {
    /// The image file.
    pub image: PathBuf,
    /// A separate mask image (`mask_path`), if any.
    pub mask: Option<PathBuf>,
    /// Camera-to-world in OpenCV axes.
    pub camera_to_world: Se3,
    /// The frame's `depth_bounds`, when given.
    pub depth_bounds: Option<(f64, f64)>,
    /// The frame's `observed_points`, when given: indices into the file's point cloud.
    pub observed_points: Option<Vec<u32>>,
    camera: CameraFields,
    /// The JSON file, for errors.
    source: PathBuf,
    index: usize,
}

/// A transforms file as read: its frames, and the point cloud it names.
#[derive(Clone, Debug)]
pub struct TransformsFile {
    /// In file order, poses converted to OpenCV axes.
    pub frames: Vec<Frame>,
    /// `ply_file_path`, resolved against the file's folder.
    pub ply_file: Option<PathBuf>,
}

/// Reads a transforms JSON file: frames in file order, poses converted to OpenCV axes.
pub fn read_transforms(path: &Path) -> Result<Vec<Frame>> {
    read_transforms_file(path).map(|f| f.frames)
}

/// Reads a transforms JSON file with the point cloud it names.
pub fn read_transforms_file(path: &Path) -> Result<TransformsFile> {
    let text = std::fs::read_to_string(path).map_err(|e| SceneError::io(path, e))?;
    parse_transforms(&text, path)
}

/// A transforms JSON text read from `path` (named in errors, and the folder image paths are
/// relative to).
pub(crate) fn parse_transforms(text: &str, path: &Path) -> Result<TransformsFile> {
    let file: TransformsJson = serde_json::from_str(text)
        .map_err(|e| SceneError::format(path, format!("invalid transforms JSON: {e}")))?;
    let dir = path.parent().unwrap_or(Path::new("."));
    if file.frames.is_empty() {
        return Err(SceneError::format(path, "no frames"));
    }
    let ply_file = match file.ply_file_path.as_deref().map(str::trim) {
        Some("") => return Err(SceneError::invalid(path, "empty ply_file_path")),
        Some(p) => Some(dir.join(p)),
        None => None,
    };
    let frames = file
        .frames
        .into_iter()
        .enumerate()
        .map(|(i, f)| {
            // An empty path joins to the folder itself, which became `<folder>.png`.
            if f.file_path.trim().is_empty() {
                return Err(SceneError::invalid(path, format!("frame {i}: empty file_path")));
            }
            let m = Matrix4::from_fn(|r, c| f.transform_matrix[r][c]);
            if !m.iter().all(|v| v.is_finite()) {
                return Err(SceneError::invalid(
                    path,
                    format!("frame {i} ({}): transform_matrix contains NaN or Inf", f.file_path),
                ));
            }
            let gl = Se3::from_matrix4(&m);
            let err = (gl.rotation.transpose() * gl.rotation - Matrix3::identity()).abs().max();
            if err > 1e-3 {
                return Err(SceneError::invalid(
                    path,
                    format!(
                        "frame {i} ({}): transform_matrix rotation is not orthonormal (|RᵀR − I| = {err:.2e})",
                        f.file_path
                    ),
                ));
            }
            // An orthonormal matrix of determinant −1 is a mirror, which no camera pose is.
            if gl.rotation.determinant() < 0.0 {
                return Err(SceneError::invalid(
                    path,
                    format!(
                        "frame {i} ({}): transform_matrix rotation is a reflection (determinant −1)",
                        f.file_path
                    ),
                ));
            }
            let camera = f.camera.or(&file.camera);
            // The lens model is checked before any image is read.
            camera
                .check_model()
                .map_err(|m| SceneError::invalid(path, format!("frame {i} ({}): {m}", f.file_path)))?;
            let depth_bounds = match f.depth_bounds {
                Some([near, far]) if near.is_finite() && far.is_finite() && 0.0 < near && near < far => {
                    Some((near, far))
                }
                Some([near, far]) => {
                    return Err(SceneError::invalid(
                        path,
                        format!(
                            "frame {i} ({}): depth_bounds [{near}, {far}] are not 0 < near < far",
                            f.file_path
                        ),
                    ));
                }
                None => None,
            };
            let mut image = dir.join(&f.file_path);
            if image.extension().is_none() {
                image.set_extension("png");
            }
            Ok(Frame {
                image,
                mask: f.mask_path.map(|m| dir.join(m)),
                camera_to_world: opengl_to_opencv(&gl),
                depth_bounds,
                observed_points: f.observed_points,
                camera,
                source: path.to_owned(),
                index: i,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(TransformsFile { frames, ply_file })
}

/// Loads one frame as a view: image (undistorted into a pinhole unless `opts` ignores
/// distortion; RGBA composited over `background`, alpha kept as the mask), camera from the
/// frame's intrinsics at the image's size, then downscaled by `opts.downscale`.
fn load_frame(
    frame: &Frame,
    background: [f32; 3],
    opts: &LoadOptions,
    root: &Path,
) -> Result<(View, CacheOutcome)> {
    let k = opts.downscale;
    let what = format!("frame {} ({})", frame.index, frame.image.display());
    let size = match frame.camera.stated_size() {
        Some(s) => s,
        None => Image::dimensions(&frame.image)?,
    };
    let lens = frame
        .camera
        .lens(size.0, size.1)
        .map_err(|m| SceneError::invalid(&frame.source, format!("{what}: {m}")))?;
    let p = view_files::load_lens_photo(
        &frame.image,
        &lens,
        opts,
        root,
        background,
        (&frame.source, &what),
    )?;
    let (w, h) = (p.photo.rgb.width, p.photo.rgb.height);
    if p.outcome == CacheOutcome::Pinhole {
        // The file's w/h against the image as decoded.
        frame
            .camera
            .intrinsics(w, h)
            .map_err(|m| SceneError::invalid(&frame.source, format!("{what}: {m}")))?;
    }
    let camera = Camera::from_camera_to_world(p.intrinsics, frame.camera_to_world);
    view_files::check_camera(&camera, &frame.source, &format!("frame {}", frame.index))?;
    let (mask, binary) = match (&frame.mask, p.photo.alpha) {
        (Some(path), _) => {
            let m = view_files::load_binary_mask(path)?;
            let m = match lens
                .distortion
                .filter(|_| p.outcome != CacheOutcome::Pinhole)
            {
                Some(_) => {
                    view_files::check_size(
                        &m,
                        &Camera::new(lens.intrinsics, camera.world_to_camera),
                        path,
                        "mask",
                    )?;
                    // Bilinear whatever the photos' kernel: the mask is thresholded anyway.
                    view_files::binarize(&crate::distortion::undistort_image(
                        &m,
                        &lens,
                        &p.intrinsics,
                        crate::distortion::Resample::Bilinear,
                    ))
                }
                None => m,
            };
            view_files::check_size(&m, &camera, path, "mask")?;
            (Some(m), true)
        }
        (None, alpha) => (alpha, false),
    };
    let mask = match mask {
        Some(m) => Some(view_files::downscale_mask(&m, k, binary, &frame.image)?),
        None => None,
    };
    let valid = match p.valid {
        Some(v) => Some(view_files::downscale_mask(&v, k, true, &frame.image)?),
        None => None,
    };
    let mask_is_alpha = mask.is_some() && !binary;
    let view = View {
        name: view_files::stem(&frame.image),
        camera: view_files::downscale_camera(&camera, k),
        image: view_files::downscale_image(&p.photo.rgb, k, &frame.image)?,
        mask,
        mask_is_alpha,
        valid,
        depth_bounds: frame.depth_bounds,
        source_index: frame.index,
    };
    Ok((view, p.outcome))
}

fn load_frames(
    frames: &[&Frame],
    background: [f32; 3],
    opts: &LoadOptions,
    root: &Path,
    report: &mut LoadReport,
) -> Result<Vec<View>> {
    let loaded = view_files::first_error_in_order(
        frames
            .par_iter()
            .map(|f| load_frame(f, background, opts, root)),
    )?;
    Ok(loaded
        .into_iter()
        .map(|(view, outcome)| {
            report.record(&outcome);
            view
        })
        .collect())
}

/// Loads NeRF-synthetic data. Training views are the first `n_train` (default 8) entries of the
/// seed-0 permutation ([`split::BLENDER_SPARSE_PERMUTATION`], DietNeRF's protocol) among the
/// frames of `transforms_train.json`, in that order; test views are all frames of
/// `transforms_test.json`. Only these are loaded: `views` holds the training views, then the
/// test views; `train_views` / `test_views` index the frames of the respective files.
pub fn load_blender(root: &Path, opts: &LoadOptions, report: &mut LoadReport) -> Result<Dataset> {
    let train_path = root.join("transforms_train.json");
    let test_path = root.join("transforms_test.json");
    let train_frames = read_transforms(&train_path)?;
    let test_frames = read_transforms(&test_path)?;
    let train_ids = match &opts.train_views {
        Some(v) => v.clone(),
        None => split::blender_train_views(
            train_frames.len(),
            opts.n_train.unwrap_or(split::BLENDER_DEFAULT_TRAIN),
            &train_path,
        )?,
    };
    let test_ids = opts
        .test_views
        .clone()
        .unwrap_or_else(|| (0..test_frames.len()).collect());
    split::validate_split(&train_ids, train_frames.len(), "train", &train_path)?;
    split::validate_split(&test_ids, test_frames.len(), "test", &test_path)?;

    let background = opts.background.unwrap_or([1.0; 3]);
    let chosen: Vec<&Frame> = train_ids
        .iter()
        .map(|&i| &train_frames[i])
        .chain(test_ids.iter().map(|&i| &test_frames[i]))
        .collect();
    let views = load_frames(&chosen, background, opts, root, report)?;
    let n_train = train_ids.len();
    Ok(Dataset {
        name: view_files::scene_name(root),
        views,
        train: (0..n_train).collect(),
        test: (n_train..n_train + test_ids.len()).collect(),
        points: None,
        background,
        to_source_world: None,
    })
}

/// Loads a nerfstudio / instant-ngp `transforms.json`. Frames are sorted by `file_path` (as
/// nerfstudio does) and all loaded; the split is a capture's ([`split::capture_split`]: at
/// most [`split::FEW_PHOTOS`] frames all train; more are split LLFF-style, every
/// `holdout_every`-th frame a test view and `n_train` spread evenly over the rest, default all).
/// The poses are kept in the file's world frame: nerfstudio's automatic re-orientation and
/// scaling are not applied.
pub fn load_nerfstudio(
    root: &Path,
    opts: &LoadOptions,
    report: &mut LoadReport,
) -> Result<Dataset> {
    let path = root.join("transforms.json");
    let TransformsFile {
        mut frames,
        ply_file,
    } = read_transforms_file(&path)?;
    let points = ply_file.as_deref().map(read_point_cloud).transpose()?;
    frames.sort_by(|a, b| a.image.cmp(&b.image));
    let listed = frames.len();
    let first_missing = frames
        .iter()
        .find(|f| !f.image.exists())
        .map(|f| f.image.clone());
    frames.retain(|f| f.image.exists());
    if let Some(first) = first_missing {
        if frames.is_empty() {
            return Err(SceneError::invalid(
                &path,
                format!(
                    "none of the {listed} frames has its image file (first missing: {})",
                    first.display()
                ),
            ));
        }
        report.missing_frames = listed - frames.len();
        report.warnings.push(format!(
            "{}: skipped {} of {listed} frames whose image files are missing (first: {})",
            path.display(),
            report.missing_frames,
            first.display()
        ));
    }
    let background = opts.background.unwrap_or([1.0; 3]);
    let views = load_frames(
        &frames.iter().collect::<Vec<_>>(),
        background,
        opts,
        root,
        report,
    )?;
    let points = match points {
        Some(cloud) => Some(with_observations(cloud, &frames, &views, &path)?),
        None => None,
    };
    let n_views = views.len();
    let (train, test) = split::capture_split(
        n_views,
        (opts.train_views.as_deref(), opts.test_views.as_deref()),
        opts.n_train,
        opts.holdout_every,
        &path,
    )?;
    Ok(Dataset {
        name: view_files::scene_name(root),
        views,
        train,
        test,
        points,
        background,
        to_source_world: None,
    })
}

/// `cloud` with each frame's `observed_points` recorded under its view's name; an index beyond
/// the cloud is an error naming the file and the frame.
fn with_observations(
    mut cloud: crate::dataset::PointCloud,
    frames: &[Frame],
    views: &[crate::dataset::View],
    path: &Path,
) -> Result<crate::dataset::PointCloud> {
    for (frame, view) in frames.iter().zip(views) {
        let Some(ids) = &frame.observed_points else {
            continue;
        };
        if let Some(&bad) = ids.iter().find(|&&i| i as usize >= cloud.len()) {
            return Err(SceneError::invalid(
                path,
                format!(
                    "frame {} ({}): observed point {bad} is beyond the {} points of ply_file_path",
                    frame.index,
                    frame.image.display(),
                    cloud.len()
                ),
            ));
        }
        cloud.observed_by.insert(view.name.clone(), ids.clone());
    }
    Ok(cloud)
}

/// The vertices of a PLY file as a point cloud (grey where the file has no colours); a file
/// without vertices is an error naming it.
fn read_point_cloud(path: &Path) -> Result<crate::dataset::PointCloud> {
    let ply = crate::ply::read(path)?;
    if ply.vertices.is_empty() {
        return Err(SceneError::invalid(path, "the point cloud has no points"));
    }
    if let Some(i) = ply
        .vertices
        .iter()
        .position(|p| !p.iter().all(|v| v.is_finite()))
    {
        return Err(SceneError::invalid(
            path,
            format!("point {i} is not finite"),
        ));
    }
    let n = ply.vertices.len();
    Ok(crate::dataset::PointCloud {
        colors: ply.colors.unwrap_or_else(|| vec![[0.5; 3]; n]),
        positions: ply.vertices,
        ..Default::default()
    })
}

/// A camera-to-world (OpenCV axes) as the 4×4 OpenGL-axes `transform_matrix` of a frame.
#[cfg(test)]
fn gl_matrix(c2w_cv: &Se3) -> [[f64; 4]; 4] {
    let gl = opengl_to_opencv(c2w_cv).to_matrix4();
    let mut m = [[0.0; 4]; 4];
    for (r, row) in m.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = gl[(r, c)];
        }
    }
    m
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use nalgebra::Vector3;
    use serde_json::json;

    /// Writes a Blender-style scene: `n_train` + `n_test` RGBA frames of 20×16 looking at the
    /// origin from a circle.
    pub(crate) fn write_blender(
        dir: &Path,
        n_train: usize,
        n_test: usize,
        extra: serde_json::Value,
    ) {
        for (split, n) in [("train", n_train), ("test", n_test)] {
            std::fs::create_dir_all(dir.join(split)).unwrap();
            let mut frames = Vec::new();
            for i in 0..n {
                let a = i as f64 * 0.3 + if split == "test" { 0.1 } else { 0.0 };
                let eye = Vector3::new(4.0 * a.cos(), 4.0 * a.sin(), 1.0);
                let cam = Camera::look_at(
                    Intrinsics::centered(1.0, 1, 1),
                    eye,
                    Vector3::zeros(),
                    Vector3::z(),
                );
                frames.push(json!({
                    "file_path": format!("./{split}/r_{i}"),
                    "rotation": 0.0,
                    "transform_matrix": gl_matrix(&cam.camera_to_world()),
                }));
                let img = Image::filled(20, 16, &[1.0, 0.0, 0.0, 0.25]);
                img.save_png(&dir.join(split).join(format!("r_{i}.png")))
                    .unwrap();
            }
            let mut doc = json!({ "camera_angle_x": 0.6911112070083618, "frames": frames });
            if let (Some(o), Some(e)) = (doc.as_object_mut(), extra.as_object()) {
                for (k, v) in e {
                    o.insert(k.clone(), v.clone());
                }
            }
            std::fs::write(
                dir.join(format!("transforms_{split}.json")),
                serde_json::to_string_pretty(&doc).unwrap(),
            )
            .unwrap();
        }
    }

    #[test]
    fn opengl_pose_projects_known_point_to_known_pixel() {
        // An OpenGL camera at (0, 0, 5) with identity rotation looks along −z at the origin,
        // y up. A point up and to the right of the origin must land up-right of the centre:
        // x = 1, y = 1, depth 5 → u = cx + f/5, v = cy − f/5.
        let dir = tempfile::tempdir().unwrap();
        let mut identity = [[0.0; 4]; 4];
        for (i, row) in identity.iter_mut().enumerate() {
            row[i] = 1.0;
        }
        identity[2][3] = 5.0;
        let doc = json!({
            "fl_x": 50.0, "fl_y": 40.0, "cx": 10.0, "cy": 7.5, "w": 20, "h": 15,
            "k1": 0.0, "p1": 0.0,
            "frames": [{ "file_path": "images/a.png", "transform_matrix": identity }]
        });
        std::fs::create_dir_all(dir.path().join("images")).unwrap();
        Image::filled(20, 15, &[0.5, 0.5, 0.5])
            .save_png(&dir.path().join("images/a.png"))
            .unwrap();
        std::fs::write(dir.path().join("transforms.json"), doc.to_string()).unwrap();
        let opts = LoadOptions {
            train_views: Some(vec![0]),
            test_views: Some(vec![0]),
            ..Default::default()
        };
        let d = crate::load::load_dataset(dir.path(), &opts).unwrap();
        let cam = &d.views[0].camera;
        let (u, v, z) = cam.project(&Vector3::new(1.0, 1.0, 0.0)).unwrap();
        assert!((u - (10.0 + 50.0 / 5.0)).abs() < 1e-12, "{u}");
        assert!((v - (7.5 - 40.0 / 5.0)).abs() < 1e-12, "{v}");
        assert!((z - 5.0).abs() < 1e-12);
        assert!((cam.center() - Vector3::new(0.0, 0.0, 5.0)).norm() < 1e-12);
        assert!(d.views[0].mask.is_none());
    }

    #[test]
    fn blender_split_composite_and_focal() {
        let dir = tempfile::tempdir().unwrap();
        write_blender(dir.path(), 100, 3, json!({}));
        let d = crate::load::load_dataset(dir.path(), &LoadOptions::default()).unwrap();
        assert_eq!(d.views.len(), 11);
        let names: Vec<&str> = d.train_views().map(|v| v.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "r_26", "r_86", "r_2", "r_55", "r_75", "r_93", "r_16", "r_73"
            ]
        );
        assert_eq!(d.test, vec![8, 9, 10]);
        let f = 0.5 * 20.0 / (0.5f64 * 0.6911112070083618).tan();
        let k = &d.views[0].camera.intrinsics;
        assert!((k.fx - f).abs() < 1e-12 && k.fx == k.fy && k.cx == 10.0 && k.cy == 8.0);
        // rgb·a + (1 − a) with rgb = (1, 0, 0), a = 0.25 (8-bit: 64/255).
        let a = 64.0 / 255.0;
        let px = d.views[0].image.pixel(3, 4);
        assert!(
            (px[0] - 1.0).abs() < 1e-6 && (px[1] - (1.0 - a)).abs() < 1e-6,
            "{px:?}"
        );
        assert!((d.views[0].mask.as_ref().unwrap().get(3, 4, 0) - a).abs() < 1e-6);
        // Each frame's camera looks at the origin.
        for v in &d.views {
            let (u, w, _) = v.camera.project(&Vector3::zeros()).unwrap();
            assert!((u - 10.0).abs() < 1e-9 && (w - 8.0).abs() < 1e-9);
        }
        // Black background on request, explicit views, downscale.
        let opts = LoadOptions {
            background: Some([0.0; 3]),
            train_views: Some(vec![5]),
            test_views: Some(vec![2]),
            downscale: 2,
            ..Default::default()
        };
        let d = crate::load::load_dataset(dir.path(), &opts).unwrap();
        assert_eq!(d.views[0].name, "r_5");
        assert!((d.views[0].image.pixel(1, 1)[0] - a).abs() < 1e-6);
        assert_eq!((d.views[1].image.width, d.views[1].image.height), (10, 8));
        assert!((d.views[1].camera.intrinsics.fx - f / 2.0).abs() < 1e-12);
    }

    #[test]
    fn bad_transforms_are_one_line_errors() {
        let dir = tempfile::tempdir().unwrap();
        write_blender(
            dir.path(),
            100,
            2,
            json!({ "camera_model": "EQUIRECTANGULAR" }),
        );
        let e = crate::load::load_dataset(dir.path(), &LoadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("transforms_train.json")
                && e.contains("camera_model EQUIRECTANGULAR is not supported"),
            "{e}"
        );
        write_blender(dir.path(), 100, 2, json!({ "w": 30, "fl_x": 20.0 }));
        let e = crate::load::load_dataset(dir.path(), &LoadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("image is 20×16 but the file says w=30"), "{e}");
        write_blender(dir.path(), 100, 2, json!({}));
        let opts = LoadOptions {
            test_views: Some(vec![2]),
            ..Default::default()
        };
        let e = crate::load::load_dataset(dir.path(), &opts)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("transforms_test.json") && e.contains("test view 2 is out of range"),
            "{e}"
        );
        let opts = LoadOptions {
            n_train: Some(101),
            ..Default::default()
        };
        let e = crate::load::load_dataset(dir.path(), &opts)
            .unwrap_err()
            .to_string();
        assert!(e.contains("asked for 101 training views"), "{e}");
        std::fs::remove_file(dir.path().join("train/r_86.png")).unwrap();
        let e = crate::load::load_dataset(dir.path(), &LoadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("r_86.png"), "{e}");
        // NaN (Python's json writes it as a bare NaN, which is not JSON) and truncated JSON.
        let text = std::fs::read_to_string(dir.path().join("transforms_test.json")).unwrap();
        std::fs::write(
            dir.path().join("transforms_test.json"),
            text.replacen("1.0", "NaN", 1),
        )
        .unwrap();
        let e = crate::load::load_dataset(dir.path(), &LoadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("transforms_test.json") && e.contains("invalid transforms JSON"),
            "{e}"
        );
        std::fs::write(
            dir.path().join("transforms_test.json"),
            &text[..text.len() / 2],
        )
        .unwrap();
        let e = crate::load::load_dataset(dir.path(), &LoadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("invalid transforms JSON"), "{e}");
        // A non-rotation matrix.
        let doc = json!({ "camera_angle_x": 0.5, "frames": [{ "file_path": "a", "transform_matrix": [[2.0,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]] }] });
        std::fs::write(dir.path().join("transforms_test.json"), doc.to_string()).unwrap();
        let e = crate::load::load_dataset(dir.path(), &LoadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("not orthonormal"), "{e}");
        // A mirror: orthonormal, determinant −1.
        let doc = json!({ "camera_angle_x": 0.5, "frames": [{ "file_path": "a", "transform_matrix": [[-1.0,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]] }] });
        std::fs::write(dir.path().join("transforms_test.json"), doc.to_string()).unwrap();
        let e = crate::load::load_dataset(dir.path(), &LoadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("is a reflection"), "{e}");
        // An empty image path.
        let doc = json!({ "camera_angle_x": 0.5, "frames": [{ "file_path": "", "transform_matrix": [[1.0,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]] }] });
        std::fs::write(dir.path().join("transforms_test.json"), doc.to_string()).unwrap();
        let e = crate::load::load_dataset(dir.path(), &LoadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("transforms_test.json") && e.contains("frame 0: empty file_path"),
            "{e}"
        );
        // Finite but absurd: a camera 10³⁰⁰ away, and a focal length of 10³⁰⁰ (caught by the
        // loader-independent check that every loaded camera fits single precision).
        write_blender(dir.path(), 100, 2, json!({}));
        for (frame, what) in [
            (
                json!({ "file_path": "./test/r_0", "transform_matrix": [[1.0,0,0,1e300],[0,1,0,0],[0,0,1,0],[0,0,0,1]] }),
                "camera centre",
            ),
            (
                json!({ "file_path": "./test/r_0", "fl_x": 1e300, "transform_matrix": [[1.0,0,0,0],[0,1,0,0],[0,0,1,4],[0,0,0,1]] }),
                "focal length fx",
            ),
        ] {
            let doc = json!({ "camera_angle_x": 0.5, "frames": [frame] });
            std::fs::write(dir.path().join("transforms_test.json"), doc.to_string()).unwrap();
            let e = crate::load::load_dataset(dir.path(), &LoadOptions::default())
                .unwrap_err()
                .to_string();
            assert!(
                e.contains(what)
                    && e.contains("r_0")
                    && e.contains("not a finite value within 1e12"),
                "{what}: {e}"
            );
        }
    }

    /// A nerfstudio scene: ten frames written in reverse file order (`images/f_09.jpg` first),
    /// each with a mask, OpenCV camera model with zero distortion.
    pub(crate) fn write_nerfstudio(dir: &Path) {
        std::fs::create_dir_all(dir.join("images")).unwrap();
        let mut frames = Vec::new();
        for i in (0..10).rev() {
            let eye = Vector3::new(3.0, i as f64 * 0.2, 1.0);
            let cam = Camera::look_at(
                Intrinsics::centered(1.0, 1, 1),
                eye,
                Vector3::zeros(),
                Vector3::z(),
            );
            frames.push(json!({
                "file_path": format!("images/f_{i:02}.jpg"),
                "mask_path": format!("images/m_{i:02}.png"),
                "transform_matrix": gl_matrix(&cam.camera_to_world()),
                "fl_x": 12.0,
            }));
            Image::filled(8, 6, &[0.1, 0.2, 0.3])
                .save_png(&dir.join(format!("images/f_{i:02}.jpg")))
                .unwrap();
            let mut m = Image::new(8, 6, 1);
            m.set(2, 3, 0, 1.0);
            m.save_png(&dir.join(format!("images/m_{i:02}.png")))
                .unwrap();
        }
        let doc = json!({ "camera_model": "OPENCV", "k1": 0.0, "frames": frames });
        std::fs::write(dir.join("transforms.json"), doc.to_string()).unwrap();
    }

    #[test]
    fn nerfstudio_masks_sorting_and_split() {
        let dir = tempfile::tempdir().unwrap();
        write_nerfstudio(dir.path());
        let d = crate::load::load_dataset(dir.path(), &LoadOptions::default()).unwrap();
        let names: Vec<&str> = d.views.iter().map(|v| v.name.as_str()).collect();
        assert_eq!(names[..3], ["f_00", "f_01", "f_02"]);
        assert_eq!(d.test, vec![0, 8]);
        assert_eq!(d.train, vec![1, 2, 3, 4, 5, 6, 7, 9]);
        let m = d.views[4].mask.as_ref().unwrap();
        assert_eq!((m.get(2, 3, 0), m.get(3, 3, 0), m.channels), (1.0, 0.0, 1));
        assert!((d.views[4].camera.center() - Vector3::new(3.0, 0.8, 1.0)).norm() < 1e-9);
        let d = crate::load::load_dataset(
            dir.path(),
            &LoadOptions {
                n_train: Some(3),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(d.train, vec![1, 5, 9]);
    }

    /// Frames' `observed_points` come back under their views' names (frames are sorted by file,
    /// so file order and view order differ), and an index beyond the cloud is a one-line error
    /// naming the file and the frame.
    #[test]
    fn observed_points_follow_their_frames() {
        let dir = tempfile::tempdir().unwrap();
        write_nerfstudio(dir.path());
        let geometry = crate::ply::PlyGeometry {
            vertices: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            ..Default::default()
        };
        crate::ply::write(
            &dir.path().join("points.ply"),
            &geometry,
            crate::ply::PlyEncoding::Ascii,
        )
        .unwrap();
        let path = dir.path().join("transforms.json");
        let with_ids = |ids: serde_json::Value| {
            let mut doc: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
            doc["ply_file_path"] = json!("points.ply");
            // File order runs f_09 … f_00: frame 6 is f_03.
            doc["frames"][6]["observed_points"] = ids;
            std::fs::write(&path, doc.to_string()).unwrap();
        };
        with_ids(json!([0, 2]));
        let d = crate::load::load_dataset(dir.path(), &LoadOptions::default()).unwrap();
        let cloud = d.points.expect("the cloud is read");
        assert_eq!(cloud.observed_by.len(), 1);
        assert_eq!(cloud.observed_by["f_03"], vec![0, 2]);
        let seen: Vec<[f32; 3]> = cloud.observed_in("f_03").unwrap().copied().collect();
        assert_eq!(seen, vec![[0.0; 3], [0.0, 1.0, 0.0]]);
        assert!(cloud.observed_in("f_04").is_none());
        with_ids(json!([0, 7]));
        let e = crate::load::load_dataset(dir.path(), &LoadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("transforms.json") && e.contains("frame 6") && e.contains("point 7"),
            "{e}"
        );
        assert_eq!(e.lines().count(), 1, "{e}");
    }
}
