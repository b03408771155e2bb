//! IDR / NeuS DTU scenes: `cameras_sphere.npz` + `image/*.png` + `mask/*.png`.
//!
//! The camera file holds, for each view `i`, `world_mat_i` (the 4×4 projection `K[R|t]` from
//! world millimetres to pixels) and `scale_mat_i` (the map from the unit sphere around the object
//! to world coordinates). As IDR and NeuS do (`load_K_Rt_from_P`), each view's camera is the
//! decomposition of `P = (world_mat_i · scale_mat_i)[:3, :4]`, so poses live in the normalised
//! frame where the object is inside the unit sphere, and `Dataset::to_source_world` keeps
//! `scale_mat` to map back to millimetres.
//!
//! The decomposition ([`decompose_projection`]) is an RQ decomposition with a positive diagonal
//! of `K`, as OpenCV's `decomposeProjectionMatrix`. `K`'s tiny skew (DTU: ~3·10⁻⁴ px, moving
//! projections by < 10⁻⁴ px) is dropped because the pinhole model has none; a skew that would
//! move a pixel by more than 0.01 px is an error instead.

use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Matrix3x4, Matrix4, Vector3};
use rayon::prelude::*;

use crate::camera::{Camera, Intrinsics, Se3};
use crate::dataset::{Dataset, View};
use crate::error::{Result, SceneError};
use crate::load_options::LoadOptions;
use crate::numpy::{self, Array};
use crate::split;
use crate::view_files;

/// Largest skew effect tolerated, in pixels at the image border (see the module docs).
const MAX_SKEW_PIXELS: f64 = 0.01;

/// A projection matrix split into intrinsics and pose: `P ∝ K [R | t]`.
#[derive(Clone, Debug, PartialEq)]
pub struct DecomposedProjection {
    /// Upper triangular, positive diagonal, `K[2][2] = 1` (may carry a skew `K[0][1]`).
    pub k: Matrix3<f64>,
    /// World-to-camera `[R | t]`, `det R = +1`.
    pub world_to_camera: Se3,
}

/// RQ decomposition `M = K R` of a non-singular 3×3 matrix: `K` upper triangular with a positive
/// diagonal, `R` orthogonal. Through Householder QR of the row-reversed transpose: with `J` the
/// exchange matrix, `(J M)ᵀ = Q U` gives `M = (J Uᵀ J)(J Qᵀ)`.
pub fn rq3(m: &Matrix3<f64>) -> (Matrix3<f64>, Matrix3<f64>) {
    let j = Matrix3::new(0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0);
    let qr = (j * m).transpose().qr();
    let (q, u) = (qr.q(), qr.r());
    let mut k = j * u.transpose() * j;
    let mut r = j * q.transpose();
    // K·D·D·R with D = diag(sign K_ii) makes the diagonal positive.
    for i in 0..3 {
        if k[(i, i)] < 0.0 {
            k.column_mut(i).neg_mut();
            r.row_mut(i).neg_mut();
        }
    }
    (k, r)
}

/// Splits a 3×4 projection into `K` and a world-to-camera pose, as OpenCV's
/// `decomposeProjectionMatrix` followed by IDR's `load_K_Rt_from_P` (`K /= K[2][2]`). `P` is
/// only defined up to scale; a negative overall sign is removed so that `det R = +1` and points
/// in front of the camera have positive depth.
pub fn decompose_projection(
    p: &Matrix3x4<f64>,
) -> std::result::Result<DecomposedProjection, String> {
    if !p.iter().all(|v| v.is_finite()) {
        return Err("projection matrix contains NaN or Inf".to_owned());
    }
    let mut m: Matrix3<f64> = p.fixed_view::<3, 3>(0, 0).into_owned();
    let mut p4: Vector3<f64> = p.column(3).into_owned();
    let det = m.determinant();
    if det.abs() <= 1e-12 * m.norm().powi(3) {
        return Err("projection matrix is singular (its left 3×3 block has no inverse)".to_owned());
    }
    if det < 0.0 {
        m = -m;
        p4 = -p4;
    }
    let (k, r) = rq3(&m);
    let s = k[(2, 2)];
    let k = k / s;
    // P = s·K·[R | t]  ⇒  t = K⁻¹ p₄ / s.
    let t = k
        .try_inverse()
        .ok_or_else(|| "intrinsic matrix is singular".to_owned())?
        * p4
        / s;
    Ok(DecomposedProjection {
        k,
        world_to_camera: Se3::new(r, t),
    })
}

/// The IDR/NeuS cameras of a scene: per-view normalised projections and the shared scale matrix.
#[derive(Clone, Debug)]
pub struct IdrCameras {
    /// `(world_mat_i · scale_mat_i)[:3, :4]`, in normalised coordinates.
    pub projections: Vec<Matrix3x4<f64>>,
    /// `world_mat_i` itself (world millimetres → pixels).
    pub world_mats: Vec<Matrix4<f64>>,
    /// `scale_mat` (normalised → world), the same for every view.
    pub scale_mat: Matrix4<f64>,
}

pub(crate) fn matrix4(a: &Array, name: &str, path: &Path) -> Result<Matrix4<f64>> {
    let m = match a.shape.as_slice() {
        [4, 4] => Matrix4::from_row_slice(&a.data),
        [3, 4] => {
            let mut m = Matrix4::identity();
            for r in 0..3 {
                for c in 0..4 {
                    m[(r, c)] = a.data[4 * r + c];
                }
            }
            m
        }
        s => {
            return Err(SceneError::format(
                path,
                format!("{name} has shape {s:?}, expected (4, 4)"),
            ));
        }
    };
    if !m.iter().all(|v| v.is_finite()) {
        return Err(SceneError::invalid(
            path,
            format!("{name} contains NaN or Inf"),
        ));
    }
    Ok(m)
}

/// Reads `world_mat_i` and `scale_mat_i` for `i < n_views` from an IDR camera file.
pub fn read_cameras(path: &Path, n_views: usize) -> Result<IdrCameras> {
    let arrays = numpy::read_npz(path)?;
    let get = |name: String| -> Result<Matrix4<f64>> {
        let a = arrays.get(&name).ok_or_else(|| {
            SceneError::format(path, format!("no {name} (the scene has {n_views} images)"))
        })?;
        matrix4(a, &name, path)
    };
    let mut world_mats = Vec::with_capacity(n_views);
    let mut projections = Vec::with_capacity(n_views);
    let mut scale_mat = None;
    for i in 0..n_views {
        let world = get(format!("world_mat_{i}"))?;
        let scale = get(format!("scale_mat_{i}"))?;
        let first = *scale_mat.get_or_insert(scale);
        let diff = (scale - first).abs().max();
        if diff > 1e-6 * first.abs().max() {
            return Err(SceneError::invalid(
                path,
                format!(
                    "scale_mat_{i} differs from scale_mat_0 by {diff}: the normalised frame is ambiguous"
                ),
            ));
        }
        let p = world * scale;
        projections.push(p.fixed_view::<3, 4>(0, 0).into_owned());
        world_mats.push(world);
    }
    Ok(IdrCameras {
        projections,
        world_mats,
        scale_mat: scale_mat.unwrap_or_else(Matrix4::identity),
    })
}

/// The pinhole camera of a normalised projection for an image of `width × height`.
fn camera_from_projection(
    p: &Matrix3x4<f64>,
    width: usize,
    height: usize,
) -> std::result::Result<Camera, String> {
    let d = decompose_projection(p)?;
    let k = d.k;
    let skew_pixels = k[(0, 1)].abs() * k[(1, 2)].max(height as f64 - k[(1, 2)]) / k[(1, 1)];
    if skew_pixels > MAX_SKEW_PIXELS {
        return Err(format!(
            "intrinsic skew {:.3e} moves pixels by up to {skew_pixels:.3} px: not a pinhole camera",
            k[(0, 1)]
        ));
    }
    let intrinsics = Intrinsics {
        fx: k[(0, 0)],
        fy: k[(1, 1)],
        cx: k[(0, 2)],
        cy: k[(1, 2)],
        width: width as u32,
        height: height as u32,
    };
    if !(intrinsics.cx > 0.0
        && intrinsics.cx < width as f64
        && intrinsics.cy > 0.0
        && intrinsics.cy < height as f64)
    {
        return Err(format!(
            "principal point ({:.1}, {:.1}) lies outside the {width}×{height} image: do the cameras belong to these images?",
            intrinsics.cx, intrinsics.cy
        ));
    }
    Ok(Camera::new(intrinsics, d.world_to_camera))
}

/// The camera file: `opts.cameras_file`, else `cameras_sphere.npz`, else `cameras.npz`.
pub(crate) fn cameras_path(root: &Path, opts: &LoadOptions) -> PathBuf {
    match &opts.cameras_file {
        Some(name) => root.join(name),
        None if root.join("cameras_sphere.npz").is_file() => root.join("cameras_sphere.npz"),
        None => root.join("cameras.npz"),
    }
}

/// Loads an IDR/NeuS DTU scene (see the module docs). All views are loaded; masks (from `mask/`,
/// when present) are the first channel thresholded at one half, as 1-channel 0/1 images. The
/// default split is the pixelNeRF/RegNeRF/SPARF protocol: training views 25, 22, 28 (first
/// `n_train` of [`split::DTU_TRAIN_ORDER`]), the 25 [`split::DTU_TEST_VIEWS`].
pub fn load(root: &Path, opts: &LoadOptions) -> Result<Dataset> {
    let images = view_files::list_images(&root.join("image"))?;
    let mask_dir = root.join("mask");
    let masks = if mask_dir.is_dir() {
        let m = view_files::list_images(&mask_dir)?;
        if m.len() != images.len() {
            return Err(SceneError::invalid(
                &mask_dir,
                format!("{} masks but image/ has {} images", m.len(), images.len()),
            ));
        }
        Some(m)
    } else {
        None
    };
    let cam_path = cameras_path(root, opts);
    let cameras = read_cameras(&cam_path, images.len())?;
    let background = opts.background.unwrap_or([0.0; 3]);
    let k = opts.downscale;

    let views =
        view_files::first_error_in_order(images.par_iter().enumerate().map(|(i, file)| {
            let photo = view_files::load_photo(file, background)?;
            let camera =
                camera_from_projection(&cameras.projections[i], photo.rgb.width, photo.rgb.height)
                    .map_err(|m| SceneError::invalid(&cam_path, format!("view {i}: {m}")))?;
            view_files::check_camera(&camera, &cam_path, &format!("view {i}"))?;
            let mask = match &masks {
                Some(m) => {
                    let mask = view_files::load_binary_mask(&m[i])?;
                    view_files::check_size(&mask, &camera, &m[i], "mask")?;
                    Some(view_files::downscale_mask(&mask, k, true, &m[i])?)
                }
                None => None,
            };
            Ok(View {
                name: view_files::stem(file),
                camera: view_files::downscale_camera(&camera, k),
                image: view_files::downscale_image(&photo.rgb, k, file)?,
                mask,
                depth_bounds: None,
                mask_is_alpha: false,
                valid: None,
                source_index: i,
            })
        }))?;

    let (train, test) = view_files::choose_split(
        opts,
        views.len(),
        root,
        |n| split::dtu_train_views(n.unwrap_or(split::DTU_DEFAULT_TRAIN), root),
        || split::DTU_TEST_VIEWS.to_vec(),
    )?;
    Ok(Dataset {
        name: view_files::scene_name(root),
        views,
        train,
        test,
        points: None,
        background,
        to_source_world: Some(cameras.scale_mat),
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::image::Image;
    use crate::numpy::test_util::write_npz;
    use nalgebra::{Rotation3, Vector4};

    fn random_rotation(seed: u64) -> Matrix3<f64> {
        let a = (seed as f64 * 1.37).sin();
        let b = (seed as f64 * 0.71).cos();
        Rotation3::from_euler_angles(a, b * 2.0, a * b + 0.3).into_inner()
    }

    #[test]
    fn rq_reconstructs_and_is_upper_triangular() {
        for seed in 0..20 {
            let k = Matrix3::new(
                900.0 + seed as f64,
                0.3,
                410.0,
                0.0,
                880.0,
                300.0,
                0.0,
                0.0,
                1.0,
            );
            let r = random_rotation(seed);
            let m = k * r * 3.7;
            let (k2, r2) = rq3(&m);
            assert!((k2 * r2 - m).norm() < 1e-9 * m.norm());
            assert!(k2[(1, 0)].abs() < 1e-9 && k2[(2, 0)].abs() < 1e-9 && k2[(2, 1)].abs() < 1e-9);
            assert!((0..3).all(|i| k2[(i, i)] > 0.0));
            assert!((r2 * r2.transpose() - Matrix3::identity()).norm() < 1e-12);
            assert!(((k2 / k2[(2, 2)]) - k).norm() < 1e-9 * k.norm());
        }
    }

    #[test]
    fn decomposition_recovers_k_r_t_up_to_sign_and_scale() {
        let k = Matrix3::new(1446.0, 0.0, 411.6, 0.0, 1441.6, 309.5, 0.0, 0.0, 1.0);
        let r = random_rotation(3);
        let t = Vector3::new(0.3, -0.2, 3.5);
        let mut p = Matrix3x4::zeros();
        p.fixed_view_mut::<3, 3>(0, 0).copy_from(&(k * r));
        p.set_column(3, &(k * t));
        for scale in [1.0, -2.5] {
            let d = decompose_projection(&(p * scale)).unwrap();
            assert!((d.k - k).norm() < 1e-9 * k.norm());
            assert!((d.world_to_camera.rotation - r).norm() < 1e-12);
            assert!((d.world_to_camera.translation - t).norm() < 1e-12);
        }
        assert!(decompose_projection(&Matrix3x4::zeros()).is_err());
    }

    /// A DTU-like scene: cameras on a sphere of radius 600 mm around (10, −20, 500) looking at
    /// it, a scale_mat of radius 150 mm there, 24×18 images.
    pub(crate) fn write_scene(dir: &Path, n: usize, k_scale: f64) -> (Matrix3<f64>, Matrix4<f64>) {
        let k = Matrix3::new(40.0, 0.0, 12.2, 0.0, 39.5, 8.9, 0.0, 0.0, 1.0) * k_scale;
        let k = Matrix3::from_fn(|r, c| if (r, c) == (2, 2) { 1.0 } else { k[(r, c)] });
        let centre = Vector3::new(10.0, -20.0, 500.0);
        let mut scale = Matrix4::identity() * 150.0;
        scale[(3, 3)] = 1.0;
        scale.fixed_view_mut::<3, 1>(0, 3).copy_from(&centre);
        let mut arrays = Vec::new();
        std::fs::create_dir_all(dir.join("image")).unwrap();
        std::fs::create_dir_all(dir.join("mask")).unwrap();
        for i in 0..n {
            let a = i as f64 * 0.4;
            let eye = centre + Vector3::new(600.0 * a.cos(), 100.0, 600.0 * a.sin());
            let cam = Camera::look_at(Intrinsics::centered(1.0, 1, 1), eye, centre, -Vector3::y());
            let w2c = cam.world_to_camera.to_matrix4();
            let mut kk = Matrix4::identity();
            kk.fixed_view_mut::<3, 3>(0, 0).copy_from(&k);
            let world = kk * w2c;
            arrays.push((
                format!("world_mat_{i}"),
                vec![4, 4],
                world.transpose().as_slice().to_vec(),
            ));
            arrays.push((
                format!("scale_mat_{i}"),
                vec![4, 4],
                scale.transpose().as_slice().to_vec(),
            ));
            Image::filled(24, 18, &[0.3, 0.3, 0.3])
                .save_png(&dir.join(format!("image/{i:06}.png")))
                .unwrap();
            let mut m = Image::filled(24, 18, &[0.0, 0.0, 0.0]);
            for y in 4..10 {
                for x in 6..12 {
                    for c in 0..3 {
                        m.set(x, y, c, 1.0);
                    }
                }
            }
            m.save_png(&dir.join(format!("mask/{i:03}.png"))).unwrap();
        }
        let refs: Vec<(&str, Vec<u64>, Vec<f64>)> = arrays
            .iter()
            .map(|(n, s, d)| (n.as_str(), s.clone(), d.clone()))
            .collect();
        write_npz(&dir.join("cameras_sphere.npz"), &refs);
        (k, scale)
    }

    #[test]
    fn synthetic_scene_reprojects_like_world_mat() {
        let dir = tempfile::tempdir().unwrap();
        let (k, scale) = write_scene(dir.path(), 49, 1.0);
        let d = crate::load::load_dataset(dir.path(), &LoadOptions::default()).unwrap();
        assert_eq!(d.views.len(), 49);
        assert_eq!(d.train, vec![25, 22, 28]);
        assert_eq!(d.test.len(), 25);
        assert_eq!(d.to_source_world.unwrap(), scale.map(|v| v as f32 as f64));
        let cams = read_cameras(&dir.path().join("cameras_sphere.npz"), 49).unwrap();
        for (i, v) in d.views.iter().enumerate() {
            let c = &v.camera.intrinsics;
            // float32 storage: 1e-6 relative.
            assert!(
                (c.fx - k[(0, 0)]).abs() < 1e-4 && (c.cy - k[(1, 2)]).abs() < 1e-4,
                "{c:?}"
            );
            // The normalised camera sits outside the unit sphere (radius 600/150 = 4).
            assert!(
                (v.camera.center().norm() - (600f64.powi(2) + 100f64.powi(2)).sqrt() / 150.0).abs()
                    < 1e-3
            );
            for j in 0..5 {
                let x_n = Vector3::new(0.3 * j as f64 - 0.6, 0.1 * i as f64 % 0.5, -0.2);
                let x_w = scale * Vector4::new(x_n.x, x_n.y, x_n.z, 1.0);
                let q = cams.world_mats[i] * x_w;
                let (u, w, _) = v.camera.project(&x_n).unwrap();
                assert!(
                    (u - q.x / q.z).abs() < 1e-6 * u.abs()
                        && (w - q.y / q.z).abs() < 1e-6 * w.abs()
                );
            }
            let m = v.mask.as_ref().unwrap();
            assert_eq!((m.channels, m.get(6, 4, 0), m.get(5, 4, 0)), (1, 1.0, 0.0));
        }
        // Downscale by 2: 12×9, masks stay binary.
        let d2 = crate::load::load_dataset(
            dir.path(),
            &LoadOptions {
                downscale: 2,
                ..Default::default()
            },
        )
        .unwrap();
        let v = &d2.views[0];
        assert_eq!(
            (
                v.image.width,
                v.image.height,
                v.camera.width(),
                v.camera.height()
            ),
            (12, 9, 12, 9)
        );
        assert!((v.camera.intrinsics.fx - d.views[0].camera.intrinsics.fx / 2.0).abs() < 1e-12);
        assert!(
            v.mask
                .as_ref()
                .unwrap()
                .data
                .iter()
                .all(|&x| x == 0.0 || x == 1.0)
        );
        // Narrow-baseline views by option.
        let opts = LoadOptions {
            train_views: Some(vec![22, 23, 24]),
            ..Default::default()
        };
        assert_eq!(
            crate::load::load_dataset(dir.path(), &opts).unwrap().train,
            vec![22, 23, 24]
        );
    }

    #[test]
    fn bad_dtu_inputs_are_one_line_errors() {
        let dir = tempfile::tempdir().unwrap();
        write_scene(dir.path(), 30, 1.0);
        // The standard test split needs views up to 47.
        let e = crate::load::load_dataset(dir.path(), &LoadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("test view 30 is out of range: there are 30 views"),
            "{e}"
        );
        let ok = LoadOptions {
            train_views: Some(vec![0]),
            test_views: Some(vec![1]),
            ..Default::default()
        };
        crate::load::load_dataset(dir.path(), &ok).unwrap();
        // Cameras made for images twice as large.
        write_scene(dir.path(), 30, 2.0);
        let e = crate::load::load_dataset(dir.path(), &ok)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("cameras_sphere.npz") && e.contains("principal point"),
            "{e}"
        );
        // More images than cameras.
        write_scene(dir.path(), 30, 1.0);
        Image::filled(24, 18, &[0.0; 3])
            .save_png(&dir.path().join("image/000030.png"))
            .unwrap();
        Image::filled(24, 18, &[0.0; 3])
            .save_png(&dir.path().join("mask/030.png"))
            .unwrap();
        let e = crate::load::load_dataset(dir.path(), &ok)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("no world_mat_30 (the scene has 31 images)"),
            "{e}"
        );
        std::fs::remove_file(dir.path().join("image/000030.png")).unwrap();
        let e = crate::load::load_dataset(dir.path(), &ok)
            .unwrap_err()
            .to_string();
        assert!(e.contains("31 masks but image/ has 30 images"), "{e}");
        std::fs::remove_file(dir.path().join("mask/030.png")).unwrap();
        // Mask of the wrong size.
        Image::filled(12, 9, &[0.0; 3])
            .save_png(&dir.path().join("mask/003.png"))
            .unwrap();
        let e = crate::load::load_dataset(dir.path(), &ok)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("003.png") && e.contains("mask is 12×9 but its camera is 24×18"),
            "{e}"
        );
        // Missing camera file chosen by option.
        let opts = LoadOptions {
            cameras_file: Some("cameras_linear_init.npz".into()),
            ..ok.clone()
        };
        let e = crate::load::load_dataset(dir.path(), &opts)
            .unwrap_err()
            .to_string();
        assert!(e.contains("cameras_linear_init.npz"), "{e}");
        // NaN in a matrix.
        let mut nan = vec![1.0; 16];
        nan[5] = f64::NAN;
        write_npz(
            &dir.path().join("cameras_linear_init.npz"),
            &[("world_mat_0", vec![4, 4], nan)],
        );
        let e = crate::load::load_dataset(dir.path(), &opts)
            .unwrap_err()
            .to_string();
        assert!(e.contains("world_mat_0 contains NaN or Inf"), "{e}");
    }
}
