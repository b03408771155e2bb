//! Loaders against the real datasets of the data README (`FEWVIEW_DATA`), checked against its
//! published numbers and against references computed by NumPy / OpenCV / Pillow
//! (`tools/make_dataset_references.py` → `tests/fixtures/references.json`).
//!
//! Run: `FEWVIEW_DATA=/work/shared/data cargo test --release -p fewview-scene -- --include-ignored`

// Tests report what they measured.
#![allow(clippy::print_stdout, clippy::print_stderr)]

use std::path::PathBuf;

use fewview_scene::{Dataset, DatasetFormat, LoadOptions, detect_format, load_dataset};
use nalgebra::{Matrix3, Matrix4, Vector3, Vector4};
use serde_json::Value;

fn data_dir() -> PathBuf {
    let dir = std::env::var_os("FEWVIEW_DATA")
        .expect("FEWVIEW_DATA is not set: point it at the shared data folder (e.g. /work/shared/data) to run the dataset tests");
    PathBuf::from(dir)
}

fn references() -> Value {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/references.json");
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap()
}

fn matrix3(v: &Value) -> Matrix3<f64> {
    Matrix3::from_fn(|r, c| f(&v[r][c]))
}

/// Deterministic pseudo-random numbers in [0, 1) (64-bit LCG, Knuth's MMIX constants).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// OpenCV camera-to-world → OpenGL axes (negate y and z columns).
fn to_opengl(c2w: &Matrix4<f64>) -> Matrix4<f64> {
    c2w * Matrix4::from_diagonal(&Vector4::new(1.0, -1.0, -1.0, 1.0))
}

#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn fern_matches_nerf_loader_and_regnerf_split() {
    let root = data_dir().join("llff/fern");
    assert_eq!(detect_format(&root).unwrap(), DatasetFormat::Llff);
    let d = load_dataset(&root, &LoadOptions::default()).unwrap();
    assert_eq!(d.name, "fern");
    assert_eq!(d.views.len(), 20);
    assert_eq!(d.test, vec![0, 8, 16]);
    assert_eq!(d.train, vec![1, 10, 19]);
    assert_eq!(d.views[0].name, "image000");
    let r = &references()["fern"];
    for (i, v) in d.views.iter().enumerate() {
        let k = &v.camera.intrinsics;
        assert_eq!(
            (k.width, k.height, v.image.width, v.image.height),
            (504, 378, 504, 378)
        );
        assert!((k.fx - 407.57).abs() < 0.01 && k.fx == k.fy, "{k:?}");
        assert!((k.fx - f(&r["hwf"][i][2])).abs() < 1e-9);
        assert_eq!((k.cx, k.cy), (252.0, 189.0));
        // NeRF's normalised pose (OpenGL axes), computed by NumPy.
        let gl = to_opengl(&v.camera.camera_to_world().to_matrix4());
        for row in 0..3 {
            for col in 0..4 {
                let want = f(&r["c2w_opengl"][i][row][col]);
                assert!(
                    (gl[(row, col)] - want).abs() < 1e-9,
                    "view {i} ({row},{col}): {} vs {want}",
                    gl[(row, col)]
                );
            }
        }
        let (near, far) = v.depth_bounds.unwrap();
        assert!(
            (near - f(&r["bounds"][i][0])).abs() < 1e-9
                && (far - f(&r["bounds"][i][1])).abs() < 1e-9
        );
    }
    let min_near = d
        .views
        .iter()
        .map(|v| v.depth_bounds.unwrap().0)
        .fold(f64::MAX, f64::min);
    assert!((min_near - 1.0 / 0.75).abs() < 1e-12);
    // to_source_world undoes the normalisation: back to the stored camera centres.
    let raw = load_dataset(
        &root,
        &LoadOptions {
            llff_normalize: false,
            ..Default::default()
        },
    )
    .unwrap();
    let m = d.to_source_world.unwrap();
    for (a, b) in raw.views.iter().zip(&d.views) {
        let c = m.transform_point(&b.camera.center().into()).coords;
        assert!((c - a.camera.center()).norm() < 1e-9 * a.camera.center().norm().max(1.0));
    }
    for (n, want) in [
        (6, vec![1, 4, 7, 12, 15, 19]),
        (9, vec![1, 3, 5, 7, 10, 12, 14, 17, 19]),
    ] {
        let d = load_dataset(
            &root,
            &LoadOptions {
                n_train: Some(n),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(d.train, want);
    }
    let half = load_dataset(
        &root,
        &LoadOptions {
            downscale: 2,
            ..Default::default()
        },
    )
    .unwrap();
    let k = &half.views[3].camera.intrinsics;
    assert_eq!(
        (k.width, k.height, half.views[3].image.width),
        (252, 189, 252)
    );
    assert!((k.fx - d.views[3].camera.intrinsics.fx / 2.0).abs() < 1e-12);
}

#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn lego_sparse_split_compositing_and_projection() {
    let root = data_dir().join("nerf_synthetic/lego");
    assert_eq!(detect_format(&root).unwrap(), DatasetFormat::Blender);
    let d = load_dataset(&root, &LoadOptions::default()).unwrap();
    let names: Vec<&str> = d.train_views().map(|v| v.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "r_26", "r_86", "r_2", "r_55", "r_75", "r_93", "r_16", "r_73"
        ]
    );
    assert_eq!(d.test.len(), 25);
    let test_names: Vec<String> = d.test_views().map(|v| v.name.clone()).collect();
    assert_eq!(test_names[..3], ["r_0", "r_8", "r_16"]);
    assert_eq!(d.background, [1.0; 3]);
    let r = &references()["lego"];
    for v in &d.views {
        let k = &v.camera.intrinsics;
        assert_eq!((k.width, k.height, k.cx, k.cy), (400, 400, 200.0, 200.0));
        assert!((k.fx - 555.56).abs() < 0.01 && (k.fx - f(&r["focal"])).abs() < 1e-9);
    }
    // Pixels of r_26 read by Pillow, composited over white; alpha kept as the mask.
    let v = &d.views[0];
    let mask = v.mask.as_ref().unwrap();
    for p in r["pixels"].as_array().unwrap() {
        let (x, y) = (
            p["x"].as_u64().unwrap() as usize,
            p["y"].as_u64().unwrap() as usize,
        );
        for c in 0..3 {
            assert!(
                (v.image.get(x, y, c) as f64 - f(&p["white"][c])).abs() < 1e-6,
                "{p}"
            );
        }
        assert!((mask.get(x, y, 0) as f64 - f(&p["rgba"][3])).abs() < 1e-6);
    }
    // OpenGL → OpenCV: projections agree with NumPy's through the OpenGL camera.
    for (p, want) in r["points"]
        .as_array()
        .unwrap()
        .iter()
        .zip(r["projections"].as_array().unwrap())
    {
        let x = Vector3::new(f(&p[0]), f(&p[1]), f(&p[2]));
        let (u, w, z) = v.camera.project(&x).unwrap();
        assert!(
            (u - f(&want[0])).abs() < 1e-9
                && (w - f(&want[1])).abs() < 1e-9
                && (z - f(&want[2])).abs() < 1e-9
        );
    }
    // All 100 training views.
    let all = load_dataset(
        &root,
        &LoadOptions {
            n_train: Some(100),
            test_views: Some(vec![0]),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(all.train.len(), 100);
}

fn dtu_checks(d: &Dataset, cameras: &str, downscale: u32) {
    let root = data_dir().join("dtu/scan65");
    let r = &references()["dtu"][cameras];
    let npz = std::fs::File::open(root.join(cameras)).unwrap();
    let mut npz = npyz::npz::NpzArchive::new(std::io::BufReader::new(npz)).unwrap();
    // Some of these files store matrices in Fortran order (cameras_linear_init.npz, cameras.npz).
    let mut read4 = |name: String| -> Matrix4<f64> {
        let npy = npz.by_name(&name).unwrap().unwrap();
        let order = npy.order();
        let v: Vec<f64> = npy
            .into_vec::<f32>()
            .unwrap()
            .iter()
            .map(|&x| x as f64)
            .collect();
        match order {
            npyz::Order::C => Matrix4::from_row_slice(&v),
            npyz::Order::Fortran => Matrix4::from_column_slice(&v),
        }
    };
    let scale = read4("scale_mat_0".into());
    assert_eq!(d.to_source_world.unwrap(), scale);
    let s = downscale as f64;
    let mut rng = Lcg(65);
    let mut worst = 0.0f64;
    for (i, v) in d.views.iter().enumerate() {
        let k = &v.camera.intrinsics;
        assert_eq!((k.width, k.height), (800 / downscale, 600 / downscale));
        assert_eq!(
            (v.image.width, v.image.height),
            (800 / downscale as usize, 600 / downscale as usize)
        );
        // OpenCV's decomposition of the same projection.
        let kr = matrix3(&r["views"][i]["K"]);
        for (got, want) in [
            (k.fx, kr[(0, 0)]),
            (k.fy, kr[(1, 1)]),
            (k.cx, kr[(0, 2)]),
            (k.cy, kr[(1, 2)]),
        ] {
            assert!(
                (got - want / s).abs() < 1e-6 * want,
                "view {i}: {got} vs {want}"
            );
        }
        let rr = matrix3(&r["views"][i]["R"]);
        assert!(
            (v.camera.world_to_camera.rotation - rr).abs().max() < 1e-6,
            "view {i}"
        );
        let c = v.camera.center();
        for a in 0..3 {
            assert!(
                (c[a] - f(&r["views"][i]["center"][a])).abs() < 1e-5,
                "view {i}"
            );
        }
        // Outside the unit sphere, looking at the origin.
        assert!(c.norm() > 1.0, "view {i} centre {c}");
        assert!(v.camera.forward().dot(&(-c).normalize()) > 0.95, "view {i}");
        // Reprojection reproduces world_mat @ [X, 1] (pixel coordinates / downscale).
        let world = read4(format!("world_mat_{i}"));
        for _ in 0..20 {
            let x_n = Vector3::new(rng.next() - 0.5, rng.next() - 0.5, rng.next() - 0.5);
            let x_w = scale * x_n.push(1.0);
            let q = world * x_w;
            let (u, w, _) = v.camera.project(&x_n).unwrap();
            let (u_ref, w_ref) = (q.x / q.z / s, q.y / q.z / s);
            // Relative to the pixel position's magnitude (a coordinate near 0 has no scale of its own).
            let err = ((u - u_ref).powi(2) + (w - w_ref).powi(2)).sqrt()
                / (u_ref.powi(2) + w_ref.powi(2)).sqrt();
            worst = worst.max(err);
            assert!(err < 1e-6, "view {i}: ({u}, {w}) vs ({u_ref}, {w_ref})");
        }
        let m = v.mask.as_ref().unwrap();
        assert_eq!(
            (m.channels, m.width, m.height),
            (1, v.image.width, v.image.height)
        );
        assert!(m.data.iter().all(|&x| x == 0.0 || x == 1.0));
        let fg = m.data.iter().sum::<f32>() / m.data.len() as f32;
        assert!(fg > 0.01 && fg < 0.9, "view {i}: foreground fraction {fg}");
    }
    eprintln!("{cameras} downscale {downscale}: worst relative reprojection error {worst:.2e}");
}

#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn dtu_scan65_cameras_masks_and_split() {
    let root = data_dir().join("dtu/scan65");
    assert_eq!(detect_format(&root).unwrap(), DatasetFormat::DtuIdr);
    let d = load_dataset(&root, &LoadOptions::default()).unwrap();
    assert_eq!(d.views.len(), 49);
    assert_eq!(d.train, vec![25, 22, 28]);
    assert_eq!(
        d.test,
        vec![
            1, 2, 9, 10, 11, 12, 14, 15, 23, 24, 26, 27, 29, 30, 31, 32, 33, 34, 35, 41, 42, 43,
            45, 46, 47
        ]
    );
    assert_eq!(d.views[25].name, "000025");
    // The README's decomposition of world_mat_0 @ scale_mat_0.
    let k = &d.views[0].camera.intrinsics;
    for (got, want) in [
        (k.fx, 1446.17),
        (k.fy, 1441.59),
        (k.cx, 411.60),
        (k.cy, 309.54),
    ] {
        assert!((got - want).abs() < 0.01, "{got} vs {want}");
    }
    dtu_checks(&d, "cameras_sphere.npz", 1);

    let half = load_dataset(
        &root,
        &LoadOptions {
            downscale: 2,
            ..Default::default()
        },
    )
    .unwrap();
    dtu_checks(&half, "cameras_sphere.npz", 2);

    let opts = LoadOptions {
        cameras_file: Some("cameras_linear_init.npz".into()),
        train_views: Some(vec![22, 23, 24]),
        ..Default::default()
    };
    let noisy = load_dataset(&root, &opts).unwrap();
    assert_eq!(noisy.train, vec![22, 23, 24]);
    dtu_checks(&noisy, "cameras_linear_init.npz", 1);
    // Perturbed by a few degrees (README: up to about 6°), same intrinsics.
    let max_angle = d
        .views
        .iter()
        .zip(&noisy.views)
        .map(|(a, b)| {
            a.camera
                .world_to_camera
                .quaternion()
                .angle_to(&b.camera.world_to_camera.quaternion())
                .to_degrees()
        })
        .fold(0.0, f64::max);
    assert!(max_angle > 1.0 && max_angle < 8.0, "{max_angle}");
    assert!((noisy.views[0].camera.intrinsics.fx - k.fx).abs() < 0.01);
}
