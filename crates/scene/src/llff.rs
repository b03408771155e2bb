//! LLFF forward-facing captures: `poses_bounds.npy` + `images_N/`.
//!
//! Each row of `poses_bounds.npy` is 17 numbers: a row-major 3×5 matrix `[R | t | hwf]` and the
//! view's near/far depth bounds. `R` is camera-to-world with columns (down, right, back), `t` the
//! camera centre, `hwf` (height, width, focal) **at full resolution**. Row `i` belongs to the
//! `i`-th image in sorted file-name order.
//!
//! By default the poses get NeRF's `load_llff_data` normalisation (as RegNeRF and SPARF use it):
//! scale the scene so the smallest near bound becomes `1/bd_factor` with `bd_factor = 0.75`, then
//! recenter on the average pose. [`LoadOptions::llff_normalize`] switches it off.

use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Matrix4, Vector3};
use rayon::prelude::*;

use crate::axes::opengl_to_opencv;
use crate::camera::{Camera, Intrinsics, Se3};
use crate::dataset::{Dataset, PointCloud, View};
use crate::error::{Result, SceneError};
use crate::load_options::LoadOptions;
use crate::numpy;
use crate::split;
use crate::view_files::{self, MAX_CAMERA_MAGNITUDE};

/// NeRF's `bd_factor`: after rescaling, the smallest near bound is `1 / BD_FACTOR`.
pub const BD_FACTOR: f64 = 0.75;

/// One row of `poses_bounds.npy`, in NeRF's OpenGL axes.
#[derive(Clone, Debug, PartialEq)]
pub struct LlffPose {
    /// Camera-to-world in OpenGL axes (columns right, up, back), as NeRF's loader makes it from
    /// LLFF's (down, right, back) by taking columns (1, −0, 2).
    pub camera_to_world_gl: Se3,
    /// Full-resolution image height, width and focal length in pixels.
    pub hwf: [f64; 3],
    /// Near and far depth bounds.
    pub bounds: (f64, f64),
}

/// Parses `poses_bounds.npy` into poses, checking shape and finiteness.
pub fn read_poses_bounds(path: &Path) -> Result<Vec<LlffPose>> {
    poses_from_array(&numpy::read_npy(path)?, path)
}

/// The poses of a `poses_bounds.npy` array already read from `path` (named in errors).
pub(crate) fn poses_from_array(a: &numpy::Array, path: &Path) -> Result<Vec<LlffPose>> {
    if a.shape.len() != 2 || a.shape[1] != 17 {
        return Err(SceneError::format(
            path,
            format!("array has shape {:?}, expected (N, 17)", a.shape),
        ));
    }
    if a.shape[0] == 0 {
        return Err(SceneError::format(path, "no poses (the array has 0 rows)"));
    }
    a.data
        .chunks_exact(17)
        .enumerate()
        .map(|(i, row)| {
            if let Some(k) = row.iter().position(|v| !v.is_finite()) {
                return Err(SceneError::invalid(
                    path,
                    format!("row {i} has a non-finite value in column {k}"),
                ));
            }
            if let Some(k) = row.iter().position(|v| v.abs() > MAX_CAMERA_MAGNITUDE) {
                return Err(SceneError::invalid(
                    path,
                    format!(
                        "row {i}, column {k} holds {:.3e}, beyond the {MAX_CAMERA_MAGNITUDE:.0e} a camera value may have",
                        row[k]
                    ),
                ));
            }
            // Row-major 3×5: element (r, c) is row[5r + c].
            let m = |r: usize, c: usize| row[5 * r + c];
            let col = |c: usize| Vector3::new(m(0, c), m(1, c), m(2, c));
            let (down, right, back) = (col(0), col(1), col(2));
            let rotation = Matrix3::from_columns(&[right, -down, back]);
            let hwf = [m(0, 4), m(1, 4), m(2, 4)];
            let bounds = (row[15], row[16]);
            if !(bounds.0 > 0.0 && bounds.1 >= bounds.0) {
                return Err(SceneError::invalid(
                    path,
                    format!("row {i}: depth bounds ({}, {}) are not 0 < near <= far", bounds.0, bounds.1),
                ));
            }
            if !(hwf[0] >= 1.0 && hwf[1] >= 1.0 && hwf[2] > 0.0) {
                return Err(SceneError::invalid(
                    path,
                    format!("row {i}: hwf ({}, {}, {}) is not a positive size and focal", hwf[0], hwf[1], hwf[2]),
                ));
            }
            let orthonormal = (rotation.transpose() * rotation - Matrix3::identity()).abs().max();
            if orthonormal > 1e-3 {
                return Err(SceneError::invalid(
                    path,
                    format!("row {i}: the 3×3 rotation is not orthonormal (|RᵀR − I| = {orthonormal:.2e})"),
                ));
            }
            Ok(LlffPose {
                camera_to_world_gl: Se3::new(rotation, col(3)),
                hwf,
                bounds,
            })
        })
        .collect()
}

/// NeRF's `poses_avg`: the mean centre, with the summed back (z) axis and summed up (y) axis
/// orthonormalised into a camera-to-world frame (OpenGL axes).
pub fn average_pose(poses: &[Se3]) -> Se3 {
    let n = poses.len().max(1) as f64;
    let center = poses.iter().map(|p| p.translation).sum::<Vector3<f64>>() / n;
    let z = poses
        .iter()
        .map(|p| p.rotation.column(2).into_owned())
        .sum::<Vector3<f64>>()
        .normalize();
    let up = poses
        .iter()
        .map(|p| p.rotation.column(1).into_owned())
        .sum::<Vector3<f64>>();
    let x = up.cross(&z).normalize();
    let y = z.cross(&x).normalize();
    Se3::new(Matrix3::from_columns(&[x, y, z]), center)
}

/// NeRF's LLFF normalisation of camera-to-world poses (OpenGL axes) and bounds: scale by
/// `s = 1 / (min bound · bd_factor)`, then express every pose in the frame of the average pose.
/// Returns the normalised poses, the scaled bounds and the 4×4 map from normalised coordinates
/// back to the stored ones (`x = A·x_n / s`, `A` the average pose).
pub fn normalize(
    poses: &[Se3],
    bounds: &[(f64, f64)],
    bd_factor: f64,
) -> (Vec<Se3>, Vec<(f64, f64)>, Matrix4<f64>) {
    let min_bound = bounds
        .iter()
        .flat_map(|&(n, f)| [n, f])
        .fold(f64::INFINITY, f64::min);
    let s = 1.0 / (min_bound * bd_factor);
    let scaled: Vec<Se3> = poses
        .iter()
        .map(|p| Se3::new(p.rotation, p.translation * s))
        .collect();
    let avg = average_pose(&scaled);
    let avg_inv = avg.inverse();
    let recentered = scaled.iter().map(|p| avg_inv.compose(p)).collect();
    let bounds = bounds.iter().map(|&(n, f)| (n * s, f * s)).collect();
    let mut unscale = Matrix4::identity();
    unscale
        .fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(Matrix3::identity() / s));
    (recentered, bounds, unscale * avg.to_matrix4())
}

/// The image folder for `factor` and the extra integer downscale it needs: `images_{factor}`
/// itself, or the largest stored resolution whose factor divides `factor`.
fn image_folder(root: &Path, factor: u32) -> Result<(PathBuf, u32)> {
    let folder = |g: u32| {
        if g == 1 {
            root.join("images")
        } else {
            root.join(format!("images_{g}"))
        }
    };
    for g in (1..=factor).rev().filter(|g| factor.is_multiple_of(*g)) {
        let dir = folder(g);
        if dir.is_dir() {
            return Ok((dir, g));
        }
    }
    Err(SceneError::format(
        root,
        format!(
            "no images_{factor}/ folder (nor images/ or an images_N/ with N dividing {factor} to downscale from)"
        ),
    ))
}

/// The COLMAP points the poses were made from, when the capture still has them
/// (`sparse/0/points3D.{bin,txt}`). LLFF's `imgs2poses` only permutes COLMAP's camera axes, so
/// the poses share COLMAP's world frame and the points need only the normalisation
/// (`to_source⁻¹`).
fn sfm_points(root: &Path, to_source: Option<&Matrix4<f64>>) -> Result<Option<PointCloud>> {
    let Some(points) = crate::colmap::read_points_in(&root.join("sparse").join("0"))? else {
        return Ok(None);
    };
    let to_scene = to_source
        .and_then(|m| m.try_inverse())
        .unwrap_or_else(Matrix4::identity);
    let cloud = PointCloud {
        positions: points
            .iter()
            .map(|p| {
                let x = to_scene.transform_point(&Vector3::from(p.xyz).into());
                [x.x as f32, x.y as f32, x.z as f32]
            })
            .collect(),
        colors: points
            .iter()
            .map(|p| p.rgb.map(|c| c as f32 / 255.0))
            .collect(),
        ..PointCloud::default()
    };
    Ok(Some(cloud))
}

/// Loads an LLFF scene (see the module docs). Views are all rows; the split is RegNeRF's
/// ([`split::llff_split`]); `depth_bounds` are the (normalised) near/far bounds; `points` are the
/// capture's COLMAP points when `sparse/0/points3D` is still there.
pub fn load(root: &Path, opts: &LoadOptions) -> Result<Dataset> {
    let poses_path = root.join("poses_bounds.npy");
    let rows = read_poses_bounds(&poses_path)?;
    let (dir, folder_factor) = image_folder(root, opts.llff_factor)?;
    let files = view_files::list_images(&dir)?;
    if files.len() != rows.len() {
        return Err(SceneError::invalid(
            &dir,
            format!(
                "{} images but poses_bounds.npy has {} poses",
                files.len(),
                rows.len()
            ),
        ));
    }

    let gl: Vec<Se3> = rows.iter().map(|r| r.camera_to_world_gl).collect();
    let bounds: Vec<(f64, f64)> = rows.iter().map(|r| r.bounds).collect();
    let (gl, bounds, to_source) = if opts.llff_normalize {
        let (p, b, m) = normalize(&gl, &bounds, BD_FACTOR);
        (p, b, Some(m))
    } else {
        (gl, bounds, None)
    };

    let background = opts.background.unwrap_or([0.0; 3]);
    let extra = (opts.llff_factor / folder_factor).saturating_mul(opts.downscale);
    let views = view_files::first_error_in_order(
        files
            .par_iter()
            .enumerate()
            .map(|(i, file)| {
                let [h_full, w_full, f_full] = rows[i].hwf;
                let photo = view_files::load_photo(file, background)?;
                let (w, h) = (photo.rgb.width, photo.rgb.height);
                // The stored images are the full resolution divided by the folder's factor (rounded
                // either way by the resizer that made them).
                let g = folder_factor as f64;
                if (w as f64 * g - w_full).abs() >= g || (h as f64 * g - h_full).abs() >= g {
                    return Err(SceneError::invalid(
                        file,
                        format!(
                            "image is {w}×{h} but poses_bounds.npy says {w_full}×{h_full} at full resolution, i.e. {:.1}×{:.1} at factor {folder_factor}",
                            w_full / g,
                            h_full / g
                        ),
                    ));
                }
                // NeRF divides the full-resolution focal by the folder's factor; the principal point is
                // the image centre.
                let intrinsics = Intrinsics::centered(f_full / g, w as u32, h as u32);
                let camera = Camera::from_camera_to_world(intrinsics, opengl_to_opencv(&gl[i]));
                view_files::check_camera(&camera, &poses_path, &format!("row {i}"))?;
                let camera = view_files::downscale_camera(&camera, extra);
                let image = view_files::downscale_image(&photo.rgb, extra, file)?;
                let mask = match photo.alpha {
                    Some(a) => Some(view_files::downscale_mask(&a, extra, false, file)?),
                    None => None,
                };
                Ok(View {
                    name: view_files::stem(file),
                    camera,
                    image,
                    mask_is_alpha: mask.is_some(),
                    valid: None,
                    mask,
                    depth_bounds: Some(bounds[i]),
                    source_index: i,
                })
            })
    )?;

    let n_views = views.len();
    let (train, test) = view_files::choose_split(
        opts,
        n_views,
        root,
        |n| {
            let n = Some(n.unwrap_or(split::LLFF_DEFAULT_TRAIN));
            Ok(split::llff_split(n_views, opts.holdout_every, n, root)?.0)
        },
        || split::holdout_test_views(n_views, opts.holdout_every),
    )?;
    Ok(Dataset {
        name: view_files::scene_name(root),
        views,
        train,
        test,
        points: sfm_points(root, to_source.as_ref())?,
        background,
        to_source_world: to_source,
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::image::Image;
    use crate::numpy::test_util::write_npy;

    /// A camera-to-world rotation with columns (down, right, back) for a camera at `eye`
    /// looking at the origin, image-up along world +y.
    fn llff_row(eye: Vector3<f64>, hwf: [f64; 3], bounds: (f64, f64)) -> Vec<f64> {
        let forward = (-eye).normalize();
        let back = -forward;
        let right = forward.cross(&Vector3::y()).normalize();
        let up = back.cross(&right);
        let down = -up;
        let cols = [down, right, back, eye];
        let mut row = Vec::with_capacity(17);
        for r in 0..3 {
            for c in &cols {
                row.push(c[r]);
            }
            row.push(hwf[r]);
        }
        row.push(bounds.0);
        row.push(bounds.1);
        row
    }

    pub(crate) fn write_scene(
        dir: &Path,
        eyes: &[Vector3<f64>],
        folder: &str,
        size: (usize, usize),
    ) {
        let mut data = Vec::new();
        for (i, e) in eyes.iter().enumerate() {
            data.extend(llff_row(
                *e,
                [48.0, 64.0, 80.0],
                (2.0 + i as f64 * 0.1, 9.0),
            ));
        }
        write_npy(
            &dir.join("poses_bounds.npy"),
            &[eyes.len() as u64, 17],
            &data,
        );
        std::fs::create_dir_all(dir.join(folder)).unwrap();
        for i in 0..eyes.len() {
            let img = Image::filled(size.0, size.1, &[0.2, 0.4, i as f32 / 10.0]);
            img.save_png(&dir.join(folder).join(format!("image{i:03}.png")))
                .unwrap();
        }
    }

    pub(crate) fn eyes(n: usize) -> Vec<Vector3<f64>> {
        (0..n)
            .map(|i| Vector3::new(0.3 * i as f64 - 0.5, 0.1 * (i % 3) as f64, 5.0))
            .collect()
    }

    #[test]
    fn raw_poses_project_the_scene_centre_into_view() {
        let dir = tempfile::tempdir().unwrap();
        write_scene(dir.path(), &eyes(4), "images_4", (16, 12));
        let opts = LoadOptions {
            llff_factor: 4,
            llff_normalize: false,
            n_train: Some(2),
            ..Default::default()
        };
        let d = crate::load::load_dataset(dir.path(), &opts).unwrap();
        assert_eq!(d.views.len(), 4);
        assert_eq!(d.test, vec![0]);
        assert_eq!(d.train, vec![1, 3]);
        for (i, v) in d.views.iter().enumerate() {
            let k = &v.camera.intrinsics;
            assert_eq!(
                (k.fx, k.cx, k.cy, k.width, k.height),
                (20.0, 8.0, 6.0, 16, 12)
            );
            // Each synthetic camera looks at the world origin: it projects to the image centre.
            let (u, w, z) = v.camera.project(&Vector3::zeros()).unwrap();
            assert!((u - 8.0).abs() < 1e-9 && (w - 6.0).abs() < 1e-9, "{u} {w}");
            assert!((z - eyes(4)[i].norm()).abs() < 1e-9);
            // World +y (LLFF image-up) is up in the image: smaller v.
            let (_, v_up, _) = v.camera.project(&Vector3::new(0.0, 0.5, 0.0)).unwrap();
            assert!(v_up < w);
            assert_eq!(v.depth_bounds, Some((2.0 + i as f64 * 0.1, 9.0)));
        }
        assert!(d.to_source_world.is_none());
    }

    #[test]
    fn normalisation_scales_bounds_and_maps_back() {
        let dir = tempfile::tempdir().unwrap();
        write_scene(dir.path(), &eyes(5), "images_8", (8, 6));
        let raw = crate::load::load_dataset(
            dir.path(),
            &LoadOptions {
                llff_normalize: false,
                ..Default::default()
            },
        )
        .unwrap();
        let norm = crate::load::load_dataset(dir.path(), &LoadOptions::default()).unwrap();
        let m = norm.to_source_world.unwrap();
        let s = 1.0 / (2.0 * BD_FACTOR);
        for (a, b) in raw.views.iter().zip(&norm.views) {
            let (na, fa) = a.depth_bounds.unwrap();
            let (nb, fb) = b.depth_bounds.unwrap();
            assert!((nb - na * s).abs() < 1e-12 && (fb - fa * s).abs() < 1e-12);
            // The normalised camera centre maps back to the stored one.
            let c = m.transform_point(&b.camera.center().into());
            assert!((c.coords - a.camera.center()).norm() < 1e-9);
            // The same world point projects to the same pixel in both frames.
            let p_src = Vector3::new(0.2, -0.1, 0.3);
            let p_norm = m
                .try_inverse()
                .unwrap()
                .transform_point(&p_src.into())
                .coords;
            let (u0, v0, _) = a.camera.project(&p_src).unwrap();
            let (u1, v1, _) = b.camera.project(&p_norm).unwrap();
            assert!((u0 - u1).abs() < 1e-9 && (v0 - v1).abs() < 1e-9);
        }
        // COLMAP points share the stored frame: they come out normalised like the cameras.
        assert!(norm.points.is_none());
        let sparse = dir.path().join("sparse/0");
        std::fs::create_dir_all(&sparse).unwrap();
        std::fs::write(
            sparse.join("points3D.txt"),
            "# id x y z r g b error track\n1 0.2 -0.1 0.3 255 0 51 0.5 1 0\n",
        )
        .unwrap();
        let with_points = crate::load::load_dataset(dir.path(), &LoadOptions::default()).unwrap();
        let cloud = with_points.points.unwrap();
        let p = Vector3::new(0.2, -0.1, 0.3);
        let want = m.try_inverse().unwrap().transform_point(&p.into());
        let got = cloud.positions[0];
        assert!(
            (Vector3::new(got[0] as f64, got[1] as f64, got[2] as f64) - want.coords).norm() < 1e-6
        );
        assert_eq!(cloud.colors[0], [1.0, 0.0, 0.2]);
        assert!(
            (norm
                .views
                .iter()
                .map(|v| v.depth_bounds.unwrap().0)
                .fold(f64::MAX, f64::min)
                - 1.0 / BD_FACTOR)
                .abs()
                < 1e-12
        );
        // After recentring, the mean camera centre is the origin and the average pose is identity.
        let gl: Vec<Se3> = norm
            .views
            .iter()
            .map(|v| opengl_to_opencv(&v.camera.camera_to_world()))
            .collect();
        let avg = average_pose(&gl);
        assert!((avg.rotation - Matrix3::identity()).norm() < 1e-9);
        assert!(avg.translation.norm() < 1e-9);
    }

    #[test]
    fn downscales_from_a_larger_folder() {
        let dir = tempfile::tempdir().unwrap();
        write_scene(dir.path(), &eyes(3), "images_2", (32, 24));
        // Factor 8 from images_2: 4× box filter; then 2× more on request.
        let opts = LoadOptions {
            downscale: 2,
            n_train: Some(1),
            ..Default::default()
        };
        let d = crate::load::load_dataset(dir.path(), &opts).unwrap();
        let k = &d.views[0].camera.intrinsics;
        assert_eq!((k.width, k.height), (4, 3));
        assert!((k.fx - 80.0 / 16.0).abs() < 1e-12 && (k.cx - 2.0).abs() < 1e-12);
        assert_eq!((d.views[0].image.width, d.views[0].image.height), (4, 3));
    }

    #[test]
    fn bad_inputs_are_one_line_errors() {
        let dir = tempfile::tempdir().unwrap();
        write_scene(dir.path(), &eyes(3), "images_8", (8, 6));
        let opts = LoadOptions {
            n_train: Some(1),
            ..Default::default()
        };
        // Image count differs from pose count.
        std::fs::remove_file(dir.path().join("images_8/image002.png")).unwrap();
        let e = crate::load::load_dataset(dir.path(), &opts)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("images_8") && e.contains("2 images but poses_bounds.npy has 3"),
            "{e}"
        );
        // Image size disagrees with hwf.
        write_scene(dir.path(), &eyes(3), "images_8", (9, 6));
        let e = crate::load::load_dataset(dir.path(), &opts)
            .unwrap_err()
            .to_string();
        assert!(e.contains("image000.png") && e.contains("9×6"), "{e}");
        // NaN in a pose.
        write_scene(dir.path(), &eyes(3), "images_8", (8, 6));
        let mut data: Vec<f64> = eyes(3)
            .iter()
            .flat_map(|e| llff_row(*e, [48.0, 64.0, 80.0], (2.0, 9.0)))
            .collect();
        data[17 + 3] = f64::NAN;
        write_npy(&dir.path().join("poses_bounds.npy"), &[3, 17], &data);
        let e = crate::load::load_dataset(dir.path(), &opts)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("poses_bounds.npy") && e.contains("row 1 has a non-finite value"),
            "{e}"
        );
        // Finite but absurd: a camera 10³⁰⁰ away (which used to pass the loader and make a
        // run diverge after it had written its first files), and a far bound of 10³⁰⁰.
        for (index, what) in [(17 + 3, "camera centre"), (2 * 17 + 16, "far depth bound")] {
            let mut huge = data.clone();
            huge[17 + 3] = 0.0;
            huge[index] = 1e300;
            write_npy(&dir.path().join("poses_bounds.npy"), &[3, 17], &huge);
            let e = crate::load::load_dataset(dir.path(), &opts)
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("poses_bounds.npy")
                    && e.contains(&format!("row {}, column {}", index / 17, index % 17))
                    && e.contains("beyond the 1e12"),
                "{what}: {e}"
            );
        }
        // Wrong shape.
        write_npy(&dir.path().join("poses_bounds.npy"), &[3, 15], &data[..45]);
        let e = crate::load::load_dataset(dir.path(), &opts)
            .unwrap_err()
            .to_string();
        assert!(e.contains("expected (N, 17)"), "{e}");
        // Missing image folder.
        write_scene(dir.path(), &eyes(3), "images_8", (8, 6));
        std::fs::rename(dir.path().join("images_8"), dir.path().join("images_3")).unwrap();
        let e = crate::load::load_dataset(dir.path(), &opts)
            .unwrap_err()
            .to_string();
        assert!(e.contains("no images_8/ folder"), "{e}");
        // Training view out of range.
        std::fs::rename(dir.path().join("images_3"), dir.path().join("images_8")).unwrap();
        let bad = LoadOptions {
            train_views: Some(vec![1, 5]),
            ..Default::default()
        };
        let e = crate::load::load_dataset(dir.path(), &bad)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("train view 5 is out of range: there are 3 views"),
            "{e}"
        );
        let empty = LoadOptions {
            test_views: Some(vec![]),
            n_train: Some(1),
            ..Default::default()
        };
        let e = crate::load::load_dataset(dir.path(), &empty)
            .unwrap_err()
            .to_string();
        assert!(e.contains("the test split is empty"), "{e}");
        // Corrupt image.
        std::fs::write(dir.path().join("images_8/image001.png"), b"garbage").unwrap();
        let e = crate::load::load_dataset(dir.path(), &opts)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("image001.png") && e.contains("cannot decode"),
            "{e}"
        );
    }
}
