//! A [`PoseModel`] written as the tools of the field read it: a COLMAP text model
//! (`sparse/0/cameras.txt`, `images.txt`, `points3D.txt`), nerfstudio's `transforms.json`
//! (with the points as `sparse_pc.ply`, named by its `ply_file_path` as nerfstudio's own
//! `ns-process-data` writes them, and each frame's `depth_bounds`),
//! `cameras.json` (the camera list `fewview pose-error` reads), `poses_report.json` and
//! `cameras.png` (the cameras and points seen from above), with the
//! registered photos placed in `images/` beside them so that the folder loads as a dataset.
//! Every file is written atomically.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use fewview_scene::atomic::write_bytes;
use fewview_scene::axes::opengl_to_opencv;
use fewview_scene::colmap::text::image_line;
use fewview_scene::ply::{PlyEncoding, PlyGeometry};
use fewview_scene::{Image, Intrinsics};
use nalgebra::Vector3;
use serde_json::{Value, json};

use crate::error::{Result, SfmError};
use crate::poses::PoseModel;

/// The model's files under `out` (which is created); returns their paths.
pub fn write_model(model: &PoseModel, out: &Path) -> Result<Vec<PathBuf>> {
    let sparse = out.join("sparse").join("0");
    std::fs::create_dir_all(&sparse).map_err(|e| SfmError::io(&sparse, e))?;
    let (camera_of, cameras) = distinct_cameras(model);
    let json = |path: PathBuf, doc: Value| match serde_json::to_string_pretty(&doc) {
        Ok(text) => Ok((path, text)),
        Err(e) => Err(SfmError::input(&path, format!("cannot write JSON: {e}"))),
    };
    let files = [
        (
            sparse.join("cameras.txt"),
            cameras_txt(&cameras, model.report.bundle.radial_k1),
        ),
        (sparse.join("images.txt"), images_txt(model, &camera_of)),
        (sparse.join("points3D.txt"), points_txt(model)),
        json(out.join("transforms.json"), transforms_json(model))?,
    ];
    for (path, text) in &files {
        write_bytes(path, text.as_bytes())?;
    }
    let cloud = (!model.points.is_empty()).then(|| out.join(POINTS_PLY));
    if let Some(path) = &cloud {
        write_points_ply(model, path)?;
    }
    let picture = out.join("cameras.png");
    top_view(model, 800).save_png(&picture)?;
    let (cameras_json, text) = json(out.join("cameras.json"), named_cameras(model))?;
    write_bytes(&cameras_json, text.as_bytes())?;
    // Last: its presence says the folder is complete ([`crate::folder::has_model`]).
    let (report, text) = json(out.join("poses_report.json"), report_json(model))?;
    write_bytes(&report, text.as_bytes())?;
    let mut written: Vec<PathBuf> = files.into_iter().map(|(p, _)| p).collect();
    written.extend(cloud);
    written.extend([cameras_json, picture, report]);
    Ok(written)
}

/// The file name of the model's points beside `transforms.json` (nerfstudio's own name).
pub const POINTS_PLY: &str = "sparse_pc.ply";

/// The model's points with their colours as a binary PLY point cloud.
fn write_points_ply(model: &PoseModel, path: &Path) -> Result<()> {
    let geometry = PlyGeometry {
        vertices: model
            .points
            .iter()
            .map(|p| p.xyz.map(|v| v as f32))
            .collect(),
        faces: Vec::new(),
        colors: Some(
            model
                .points
                .iter()
                .map(|p| p.rgb.map(|c| c as f32 / 255.0))
                .collect(),
        ),
        normals: None,
    };
    Ok(fewview_scene::ply::write(
        path,
        &geometry,
        PlyEncoding::BinaryLittleEndian,
    )?)
}

/// Near and far z-depth of the points each photo observes, as LLFF's `imgs2poses` bounds its
/// COLMAP models from percentiles of the observed points' depths. LLFF takes the 0.1st and
/// 99.9th percentile of a dense capture's many points; with the few hundred points of a few
/// photos those are single points, so the 1st and 99th are taken, of the points triangulated
/// from rays at least [`MIN_BOUND_ANGLE_DEG`] apart (COLMAP's own filter of uncertain points;
/// a point near the epipole of a camera walking forward can land at any depth). `None` for a
/// photo that observes fewer than [`MIN_BOUND_POINTS`] points in front of it.
pub fn depth_bounds(model: &PoseModel) -> Vec<Option<(f64, f64)>> {
    let centres: Vec<Vector3<f64>> = model.photos.iter().map(|p| p.camera.center()).collect();
    // Per photo: the depths of all its points, and of the well triangulated ones.
    let mut depths: Vec<[Vec<f64>; 2]> = vec![Default::default(); model.photos.len()];
    for point in &model.points {
        let x = Vector3::from(point.xyz);
        let certain =
            triangulation_angle_deg(&x, &point.observations, &centres) >= MIN_BOUND_ANGLE_DEG;
        for &(photo, _) in &point.observations {
            let z = model.photos[photo]
                .camera
                .world_to_camera
                .transform_point(&x)
                .z;
            if z.is_finite() && z > 0.0 {
                depths[photo][0].push(z);
                if certain {
                    depths[photo][1].push(z);
                }
            }
        }
    }
    depths
        .into_iter()
        .map(|[all, certain]| {
            let mut z = if certain.len() >= MIN_BOUND_POINTS {
                certain
            } else {
                all
            };
            if z.len() < MIN_BOUND_POINTS {
                return None;
            }
            z.sort_by(f64::total_cmp);
            let (near, far) = (percentile(&z, 0.01), percentile(&z, 0.99));
            (near < far).then_some((near, far))
        })
        .collect()
}

/// The fewest observed points from which a photo's depth bounds are taken.
pub const MIN_BOUND_POINTS: usize = 8;

/// The smallest angle (degrees) between two rays of a point whose depth bounds a photo
/// (COLMAP's `filter_min_tri_angle`).
pub const MIN_BOUND_ANGLE_DEG: f64 = 1.5;

/// The largest angle (degrees) between the rays from the observing photos' centres to `x`.
fn triangulation_angle_deg(
    x: &Vector3<f64>,
    observations: &[(usize, [f64; 2])],
    centres: &[Vector3<f64>],
) -> f64 {
    let rays: Vec<Vector3<f64>> = observations
        .iter()
        .filter_map(|&(photo, _)| (x - centres[photo]).try_normalize(1e-12))
        .collect();
    let mut widest = 0.0f64;
    for (i, a) in rays.iter().enumerate() {
        for b in &rays[i + 1..] {
            widest = widest.max(a.dot(b).clamp(-1.0, 1.0).acos().to_degrees());
        }
    }
    widest
}

/// The `q`-quantile of sorted values, linearly interpolated (NumPy's default).
fn percentile(sorted: &[f64], q: f64) -> f64 {
    let at = q * (sorted.len() - 1) as f64;
    let (i, t) = (at.floor() as usize, at.fract());
    match sorted.get(i + 1) {
        Some(next) => sorted[i] + t * (next - sorted[i]),
        None => sorted[i],
    }
}

/// The registered cameras as `fewview pose-error` reads them, each with its photo's file name
/// (by which `pose-error` finds the same view in a dataset folder).
fn named_cameras(model: &PoseModel) -> Value {
    let named = model.photos.iter().map(|p| {
        let mut camera = fewview_geom::io::cameras::camera_to_json(&p.camera);
        camera["name"] = Value::from(p.name.clone());
        camera
    });
    Value::Array(named.collect())
}

/// Places the registered photos of `model`, read from `images_dir`, in `out/images/` (a hard
/// link where the file system allows, else a copy), as the written model names them.
pub fn place_images(model: &PoseModel, images_dir: &Path, out: &Path) -> Result<()> {
    let images = out.join("images");
    std::fs::create_dir_all(&images).map_err(|e| SfmError::io(&images, e))?;
    for photo in &model.photos {
        let (from, to) = (images_dir.join(&photo.name), images.join(&photo.name));
        if to.exists() {
            continue;
        }
        if std::fs::hard_link(&from, &to).is_err() {
            std::fs::copy(&from, &to).map_err(|e| SfmError::io(&from, e))?;
        }
    }
    Ok(())
}

/// One COLMAP camera per distinct set of intrinsics (photos of one camera share it); the
/// camera id (1-based) of each photo.
fn distinct_cameras(model: &PoseModel) -> (Vec<usize>, Vec<Intrinsics>) {
    let mut cameras: Vec<Intrinsics> = Vec::new();
    let ids = model
        .photos
        .iter()
        .map(|p| {
            let k = p.camera.intrinsics;
            match cameras.iter().position(|c| *c == k) {
                Some(i) => i + 1,
                None => {
                    cameras.push(k);
                    cameras.len()
                }
            }
        })
        .collect();
    (ids, cameras)
}

/// `cameras.txt`: `PINHOLE` cameras, or with a radial coefficient `SIMPLE_RADIAL` (one focal
/// length) or `OPENCV` (two, the other coefficients 0).
fn cameras_txt(cameras: &[Intrinsics], k1: Option<f64>) -> String {
    let mut s = String::from("# CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]\n");
    for (i, k) in cameras.iter().enumerate() {
        let params = match k1 {
            None => format!(
                "PINHOLE {} {} {:.17} {:.17} {:.17} {:.17}",
                k.width, k.height, k.fx, k.fy, k.cx, k.cy
            ),
            Some(k1) if k.fx == k.fy => format!(
                "SIMPLE_RADIAL {} {} {:.17} {:.17} {:.17} {:.17}",
                k.width, k.height, k.fx, k.cx, k.cy, k1
            ),
            Some(k1) => format!(
                "OPENCV {} {} {:.17} {:.17} {:.17} {:.17} {:.17} 0 0 0",
                k.width, k.height, k.fx, k.fy, k.cx, k.cy, k1
            ),
        };
        let _ = writeln!(s, "{} {params}", i + 1);
    }
    s
}

/// `images.txt`: each photo's world-to-camera pose, then its observed points.
fn images_txt(model: &PoseModel, camera_of: &[usize]) -> String {
    let mut observed: Vec<Vec<(f64, f64, usize)>> = vec![Vec::new(); model.photos.len()];
    for (id, point) in model.points.iter().enumerate() {
        for &(photo, [x, y]) in &point.observations {
            observed[photo].push((x, y, id + 1));
        }
    }
    let mut s = String::from(
        "# IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME\n# POINTS2D[] as (X, Y, POINT3D_ID)\n",
    );
    for (i, photo) in model.photos.iter().enumerate() {
        let pose = &photo.camera.world_to_camera;
        let _ = writeln!(s, "{}", image_line(i + 1, pose, camera_of[i], &photo.name));
        let line: Vec<String> = observed[i]
            .iter()
            .map(|(x, y, id)| format!("{x:.3} {y:.3} {id}"))
            .collect();
        let _ = writeln!(s, "{}", line.join(" "));
    }
    s
}

/// `points3D.txt`: each point with its colour, error and track (image id, index of the
/// observation in that image's line of `images.txt`).
fn points_txt(model: &PoseModel) -> String {
    let mut next_index = vec![0usize; model.photos.len()];
    let mut s = String::from("# POINT3D_ID X Y Z R G B ERROR TRACK[] as (IMAGE_ID, POINT2D_IDX)\n");
    for (id, p) in model.points.iter().enumerate() {
        let track: Vec<String> = p
            .observations
            .iter()
            .map(|&(photo, _)| {
                let index = next_index[photo];
                next_index[photo] += 1;
                format!("{} {index}", photo + 1)
            })
            .collect();
        let _ = writeln!(
            s,
            "{} {:.17} {:.17} {:.17} {} {} {} {:.6} {}",
            id + 1,
            p.xyz[0],
            p.xyz[1],
            p.xyz[2],
            p.rgb[0],
            p.rgb[1],
            p.rgb[2],
            p.error_px,
            track.join(" ")
        );
    }
    s
}

/// nerfstudio's `transforms.json`: per-frame intrinsics (`OPENCV`, with the radial coefficient
/// when one was adjusted) and OpenGL camera-to-world matrices, with the images expected under
/// `images/`.
fn transforms_json(model: &PoseModel) -> Value {
    let bounds = depth_bounds(model);
    let observed = observed_points(model);
    let frames: Vec<_> = model
        .photos
        .iter()
        .zip(&bounds)
        .zip(&observed)
        .map(|((p, bounds), observed)| {
            let k = p.camera.intrinsics;
            let gl = opengl_to_opencv(&p.camera.camera_to_world()).to_matrix4();
            let rows: Vec<Vec<f64>> = (0..4)
                .map(|r| (0..4).map(|c| gl[(r, c)]).collect())
                .collect();
            json!({
                "file_path": format!("images/{}", p.name),
                "fl_x": k.fx, "fl_y": k.fy, "cx": k.cx, "cy": k.cy, "w": k.width, "h": k.height,
                "k1": model.report.bundle.radial_k1.unwrap_or(0.0), "k2": 0.0, "p1": 0.0, "p2": 0.0,
                "transform_matrix": rows,
                "depth_bounds": bounds.map(|(near, far)| [near, far]),
                "observed_points": observed,
            })
        })
        .collect();
    let mut doc = json!({ "camera_model": "OPENCV", "frames": frames });
    if !model.points.is_empty() {
        doc["ply_file_path"] = Value::from(POINTS_PLY);
    }
    doc
}

/// Per photo, the indices (in `sparse_pc.ply`'s order) of the points it observed: their tracks,
/// so that a reader can tell a point a photo saw from one that merely projects into its image
/// from behind a wall.
fn observed_points(model: &PoseModel) -> Vec<Vec<u32>> {
    let mut observed = vec![Vec::new(); model.photos.len()];
    for (i, point) in model.points.iter().enumerate() {
        for &(photo, _) in &point.observations {
            observed[photo].push(i as u32);
        }
    }
    for ids in &mut observed {
        ids.dedup();
    }
    observed
}

fn report_json(model: &PoseModel) -> Value {
    let photos: Vec<_> = model
        .photos
        .iter()
        .map(|p| json!({ "name": p.name, "focal_from": p.focal_from, "focal_px": p.camera.intrinsics.fx }))
        .collect();
    json!({
        "registered": photos,
        "unregistered": model.unregistered,
        "report": model.report,
        "gauge": "first registered photo at the origin with the identity rotation; median track depth 1",
    })
}

/// The model seen from above: the points in their colours and each camera as a red dot with
/// its viewing direction, projected onto the plane of the cameras' mean right and forward axes
/// (the ground plane of photos taken upright), `size` pixels wide.
pub fn top_view(model: &PoseModel, size: usize) -> Image {
    let (right, forward) = mean_axes(model);
    let plane = |x: &Vector3<f64>| (x.dot(&right), x.dot(&forward));
    let centres: Vec<Vector3<f64>> = model.photos.iter().map(|p| p.camera.center()).collect();
    let mut points: Vec<(f64, f64)> = model
        .points
        .iter()
        .map(|p| plane(&Vector3::from(p.xyz)))
        .filter(|(u, v)| u.is_finite() && v.is_finite())
        .collect();
    if points.is_empty() {
        points.push((0.0, 0.0));
    }
    let quantile = |values: &mut Vec<f64>, q: f64| {
        values.sort_by(f64::total_cmp);
        values[((values.len() as f64 - 1.0) * q).round() as usize]
    };
    // The 1st to 99th percentiles of the points, and every camera, fill the picture.
    let (mut us, mut vs): (Vec<f64>, Vec<f64>) = points.into_iter().unzip();
    let (mut u0, mut u1) = (quantile(&mut us, 0.01), quantile(&mut us, 0.99));
    let (mut v0, mut v1) = (quantile(&mut vs, 0.01), quantile(&mut vs, 0.99));
    for (u, v) in centres.iter().map(plane) {
        (u0, u1, v0, v1) = (u0.min(u), u1.max(u), v0.min(v), v1.max(v));
    }
    let span = (u1 - u0).max(v1 - v0).max(1e-9) * 1.15;
    let (cu, cv) = (0.5 * (u0 + u1), 0.5 * (v0 + v1));
    let mut image = Image::filled(size, size, &[1.0, 1.0, 1.0]);
    let to_pixel = |(u, v): (f64, f64)| {
        let x = ((u - cu) / span + 0.5) * size as f64;
        let y = (0.5 - (v - cv) / span) * size as f64;
        (x, y)
    };
    let mut dot = |(x, y): (f64, f64), radius: isize, colour: [f32; 3]| {
        for dy in -radius..=radius {
            for dx in -radius..=radius {
                let (px, py) = (x as isize + dx, y as isize + dy);
                if px >= 0 && py >= 0 && (px as usize) < size && (py as usize) < size {
                    for (c, value) in colour.iter().enumerate() {
                        image.set(px as usize, py as usize, c, *value);
                    }
                }
            }
        }
    };
    for p in &model.points {
        let colour = p.rgb.map(|c| c as f32 / 255.0);
        dot(to_pixel(plane(&Vector3::from(p.xyz))), 0, colour);
    }
    for (photo, centre) in model.photos.iter().zip(&centres) {
        let axis: Vector3<f64> = photo.camera.world_to_camera.rotation.row(2).transpose();
        for k in 1..=20 {
            let along = centre + axis * (0.02 * span * k as f64 / 20.0 * 5.0);
            dot(to_pixel(plane(&along)), 0, [0.8, 0.1, 0.1]);
        }
        dot(to_pixel(plane(centre)), 3, [0.8, 0.1, 0.1]);
    }
    image
}

/// The cameras' mean right (x) and forward (z) axes, made orthonormal.
fn mean_axes(model: &PoseModel) -> (Vector3<f64>, Vector3<f64>) {
    let sum = |row: usize| -> Vector3<f64> {
        model
            .photos
            .iter()
            .map(|p| p.camera.world_to_camera.rotation.row(row).transpose())
            .sum()
    };
    let right = sum(0).try_normalize(1e-12).unwrap_or_else(Vector3::x);
    let forward = sum(2) - right * sum(2).dot(&right);
    let forward = forward.try_normalize(1e-12).unwrap_or_else(Vector3::z);
    (right, forward)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::photos::FocalSource;
    use crate::poses::{ModelPoint, PoseReport, RegisteredPhoto};
    use fewview_scene::Camera;

    /// Three cameras on an arc looking at a ring of points: the picture shows the points in
    /// their colour and the cameras in red, inside the frame.
    #[test]
    fn the_top_view_draws_points_and_cameras() {
        let k = Intrinsics::centered(300.0, 400, 300);
        let photos = (0..3)
            .map(|i| {
                let a = (i as f64 - 1.0) * 0.4;
                let eye = Vector3::new(3.0 * a.sin(), 0.2, -3.0 * a.cos());
                RegisteredPhoto {
                    name: format!("{i}.png"),
                    camera: Camera::look_at(k, eye, Vector3::zeros(), -Vector3::y()),
                    focal_from: FocalSource::AssumedFov,
                }
            })
            .collect();
        let points = (0..200)
            .map(|i| {
                let t = i as f64 * 0.0314;
                ModelPoint {
                    xyz: [t.cos(), 0.0, t.sin()],
                    rgb: [0, 0, 255],
                    observations: Vec::new(),
                    error_px: 0.0,
                }
            })
            .collect();
        let model = PoseModel {
            photos,
            unregistered: Vec::new(),
            points,
            report: PoseReport::default(),
        };
        let picture = top_view(&model, 200);
        if let Ok(path) = std::env::var("FEWVIEW_TOP_VIEW_PNG") {
            picture.save_png(std::path::Path::new(&path)).unwrap();
        }
        let count = |want: [f32; 3]| {
            (0..200 * 200)
                .filter(|i| picture.pixel(i % 200, i / 200) == want)
                .count()
        };
        assert!(count([0.0, 0.0, 1.0]) > 100, "points drawn");
        assert!(count([0.8, 0.1, 0.1]) > 3 * 40, "cameras drawn");
    }

    /// Three photos of a cloud of points 2–6 units away, and one far point barely triangulated:
    /// the written folder loads as a dataset whose points are the model's and whose views carry
    /// the percentile bounds of the well triangulated points they observe.
    #[test]
    fn the_written_model_reads_back_with_its_points_and_bounds() {
        let k = Intrinsics::centered(100.0, 80, 60);
        let photos: Vec<RegisteredPhoto> = (0..3)
            .map(|i| RegisteredPhoto {
                name: format!("{i}.png"),
                camera: Camera::look_at(
                    k,
                    Vector3::new(0.3 * i as f64, 0.0, 0.0),
                    Vector3::new(0.3 * i as f64, 0.0, 1.0),
                    -Vector3::y(),
                ),
                focal_from: FocalSource::AssumedFov,
            })
            .collect();
        let points: Vec<ModelPoint> = (0..50)
            .map(|i| {
                let z = 2.0 + 4.0 * i as f64 / 49.0;
                let x = 0.3 + 0.2 * ((i * 7 % 11) as f64 / 11.0 - 0.5);
                // The last photo observes only the far half.
                let observers = if z > 4.0 { 0..3 } else { 0..2 };
                ModelPoint {
                    xyz: [x, 0.1, z],
                    rgb: [i as u8 * 5, 100, 200],
                    observations: observers.map(|p| (p, [40.0, 30.0])).collect(),
                    error_px: 0.5,
                }
            })
            .collect();
        let mut points = points;
        // Seen by photos 0 and 1 under 0.02°: its depth is left out of the bounds.
        points.push(ModelPoint {
            xyz: [0.15, 0.0, 1000.0],
            rgb: [0, 0, 0],
            observations: vec![(0, [40.0, 30.0]), (1, [40.0, 30.0])],
            error_px: 0.5,
        });
        let model = PoseModel {
            photos,
            unregistered: Vec::new(),
            points,
            report: PoseReport::default(),
        };
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("images")).unwrap();
        for p in &model.photos {
            Image::filled(80, 60, &[0.5, 0.5, 0.5])
                .save_png(&dir.path().join("images").join(&p.name))
                .unwrap();
        }
        write_model(&model, dir.path()).unwrap();
        let ds = fewview_scene::load_dataset(dir.path(), &Default::default()).unwrap();
        let cloud = ds.points.as_ref().expect("the points come back");
        assert_eq!(cloud.len(), 51);
        for (got, want) in cloud.positions.iter().zip(&model.points) {
            assert_eq!(*got, want.xyz.map(|v| v as f32));
        }
        assert_eq!(
            cloud.colors[3],
            [15.0 / 255.0, 100.0 / 255.0, 200.0 / 255.0]
        );
        // NumPy: np.percentile(z, [1, 99]) of the observed depths (camera z = world z; every
        // point is seen under 2.9° or more).
        let z: Vec<f64> = (0..50).map(|i| 2.0 + 4.0 * i as f64 / 49.0).collect();
        let far_half: Vec<f64> = z.iter().copied().filter(|&z| z > 4.0).collect();
        let expect = |z: &[f64]| {
            let at = 0.01 * (z.len() - 1) as f64;
            let near = z[0] + at * (z[1] - z[0]);
            let far = z[z.len() - 1] - at * (z[z.len() - 1] - z[z.len() - 2]);
            (near, far)
        };
        // Each photo's track memberships come back under its name: the last saw the far half.
        let far_ids: Vec<u32> = (0..50).filter(|&i| z[i as usize] > 4.0).collect();
        let all_ids: Vec<u32> = (0..51).collect();
        assert_eq!(cloud.observed_by["0"], all_ids);
        assert_eq!(cloud.observed_by["1"], all_ids);
        assert_eq!(cloud.observed_by["2"], far_ids);
        let want = [expect(&z), expect(&z), expect(&far_half)];
        for (view, want) in ds.views.iter().zip(want) {
            let (near, far) = view.depth_bounds.expect("bounds come back");
            assert!(
                (near - want.0).abs() < 1e-9 && (far - want.1).abs() < 1e-9,
                "{}: {near} {far} vs {want:?}",
                view.name
            );
        }
    }

    /// A model with a radial coefficient says `SIMPLE_RADIAL` (one focal length) or `OPENCV`
    /// (two), and the scene crate's COLMAP reader finds the same camera and `k1` in it.
    #[test]
    fn a_radial_coefficient_reads_back_through_the_colmap_reader() {
        use fewview_scene::colmap::text::read_cameras;
        use fewview_scene::distortion::Distortion;
        use fewview_scene::distortion::models::camera_from_colmap;
        let square = Intrinsics::centered(300.0, 400, 300);
        let wide = Intrinsics {
            fx: 310.0,
            ..square
        };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cameras.txt");
        std::fs::write(&path, cameras_txt(&[square, wide], Some(-0.07))).unwrap();
        let cameras = read_cameras(&path).unwrap();
        let models: Vec<&str> = cameras.values().map(|c| c.model.as_str()).collect();
        assert_eq!(models, ["SIMPLE_RADIAL", "OPENCV"]);
        for (c, k) in cameras.values().zip([square, wide]) {
            let lens = camera_from_colmap(&c.model, &c.params, 400, 300).unwrap();
            assert_eq!(lens.intrinsics, k);
            match lens.distortion {
                Some(Distortion::RadialTangential {
                    radial,
                    rational,
                    tangential,
                }) => {
                    assert_eq!(radial, [-0.07, 0.0, 0.0, 0.0]);
                    assert_eq!((rational, tangential), ([0.0; 3], [0.0; 2]));
                }
                other => panic!("{}: {other:?}", c.model),
            }
        }
        let pinhole = cameras_txt(&[square], None);
        assert!(
            pinhole
                .lines()
                .nth(1)
                .unwrap()
                .starts_with("1 PINHOLE 400 300")
        );
    }
}
