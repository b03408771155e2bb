//! The surface start on the demo scene, from a surface run folder made of the scene's exact
//! geometry: the checks that refuse another run, the refined poses, and training with the
//! mesh's depth.

use std::path::Path;

use fewview_geom::Mesh;
use fewview_geom::depth::depth_to_mesh;
use fewview_scene::synthetic::{DemoOptions, DemoShading, demo_dataset, demo_depth};
use fewview_scene::{Camera, Dataset, Se3};
use fewview_splat::eval::render_model;
use fewview_splat::pipeline::adopt_init_poses;
use fewview_splat::pipeline::{InitStrategy, RunConfig, initial_model, train_run};
use fewview_splat::raster::{RenderCamera, RenderSettings};
use fewview_splat::read_ply;
use fewview_splat::surface_start::{SurfacePoses, mesh_depth};
use fewview_splat::train::TrainConfig;
use nalgebra::Vector3;

fn demo() -> Dataset {
    demo_dataset(&DemoOptions {
        width: 64,
        height: 48,
        views: 8,
        train: vec![1, 4, 7],
        supersample: 2,
        shading: DemoShading::Lambertian,
        ..DemoOptions::default()
    })
}

/// The training views' exact depth as one mesh.
fn exact_mesh(ds: &Dataset) -> Mesh {
    let mut mesh = Mesh::new(Vec::new(), Vec::new());
    for v in ds.train_views() {
        let part = depth_to_mesh(&demo_depth(&v.camera), &v.camera, None, 0.0).unwrap();
        let offset = mesh.vertices.len() as u32;
        mesh.vertices.extend(part.vertices);
        mesh.faces
            .extend(part.faces.iter().map(|f| f.map(|i| i + offset)));
    }
    mesh
}

/// Writes what a surface run leaves: `metrics.json` naming `name` and `views`, the mesh and
/// the aligned refined cameras.
fn write_surface_run(
    dir: &Path,
    name: &str,
    views: &[usize],
    mesh: &Mesh,
    cameras: &[Camera],
    initial_deg: f64,
) {
    std::fs::create_dir_all(dir).unwrap();
    let metrics = serde_json::json!({
        "dataset": name,
        "train_views": views,
        "initial_pose_error": { "rotation_deg": initial_deg },
    });
    std::fs::write(dir.join("metrics.json"), metrics.to_string()).unwrap();
    fewview_geom::io::write_mesh(&dir.join("mesh_input_frame.ply"), mesh).unwrap();
    fewview_geom::io::cameras::write_cameras(&dir.join("poses_refined_aligned.json"), cameras)
        .unwrap();
}

fn training_cameras(ds: &Dataset) -> Vec<Camera> {
    ds.train_views().map(|v| v.camera.clone()).collect()
}

fn surface_config(dir: &Path, iterations: usize, depth_weight: f32) -> RunConfig {
    let mut train = TrainConfig::sparse_view(iterations);
    train.seed = 3;
    let mut cfg = RunConfig::new(train);
    cfg.init = InitStrategy::Surface(dir.to_path_buf());
    cfg.surface_depth_weight = depth_weight;
    cfg
}

#[test]
fn a_surface_run_of_other_data_or_views_is_refused() {
    let ds = demo();
    let mesh = exact_mesh(&ds);
    let tmp = tempfile::tempdir().unwrap();
    let cams = training_cameras(&ds);
    let refuse = |dir: &Path, want: &str| {
        let e = initial_model(&ds, &surface_config(dir, 10, 0.2))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(want) && e.contains(&dir.display().to_string()),
            "{e}"
        );
        assert_eq!(e.lines().count(), 1, "{e}");
    };
    let other_scene = tmp.path().join("other-scene");
    write_surface_run(&other_scene, "scan65", &ds.train, &mesh, &cams, 0.0);
    refuse(&other_scene, "a surface run of `scan65`");
    let other_views = tmp.path().join("other-views");
    write_surface_run(&other_views, &ds.name, &[0, 1, 2], &mesh, &cams, 0.0);
    refuse(&other_views, "reconstructed views [0, 1, 2]");
    let no_mesh = tmp.path().join("no-mesh");
    write_surface_run(&no_mesh, &ds.name, &ds.train, &mesh, &cams, 0.0);
    std::fs::remove_file(no_mesh.join("mesh_input_frame.ply")).unwrap();
    refuse(&no_mesh, "mesh_input_frame.ply");
    refuse(&tmp.path().join("nothing"), "not a finished surface run");
}

#[test]
fn refined_poses_replace_the_training_cameras_when_the_run_started_elsewhere() {
    let ds = demo();
    let mesh = exact_mesh(&ds);
    let tmp = tempfile::tempdir().unwrap();
    // "Refined" cameras: each training camera moved 1 cm sideways.
    let moved: Vec<Camera> = training_cameras(&ds)
        .iter()
        .map(|c| {
            let shift = Se3::new(nalgebra::Matrix3::identity(), Vector3::new(0.01, 0.0, 0.0));
            Camera::new(c.intrinsics, shift.compose(&c.world_to_camera))
        })
        .collect();
    for (initial_deg, choice, adopted) in [
        (5.0, SurfacePoses::Auto, true),
        (0.0, SurfacePoses::Auto, false),
        (0.0, SurfacePoses::Refined, true),
        (5.0, SurfacePoses::Dataset, false),
    ] {
        let dir = tmp.path().join(format!("run-{initial_deg}-{choice:?}"));
        write_surface_run(&dir, &ds.name, &ds.train, &mesh, &moved, initial_deg);
        let mut now = ds.clone();
        let line = adopt_init_poses(&mut now, &surface_config(&dir, 10, 0.2), choice)
            .unwrap()
            .unwrap();
        let want = if adopted {
            &moved
        } else {
            &training_cameras(&ds)
        };
        for (got, want) in now.train_views().zip(want) {
            let d = (got.camera.center() - want.center()).norm();
            assert!(d < 1e-9, "{choice:?} from {initial_deg}°: {d}");
        }
        assert_eq!(line.contains("refined"), adopted, "{line}");
        // Held-out views keep their cameras.
        for (a, b) in now.test_views().zip(ds.test_views()) {
            assert_eq!(a.camera.world_to_camera, b.camera.world_to_camera);
        }
    }
}

/// Mean `|rendered depth − mesh depth| / mesh depth` of the trained model in the training views.
fn depth_error(ds: &Dataset, mesh: &Mesh, run: &Path) -> f64 {
    let model = read_ply(&run.join("point_cloud.ply")).unwrap();
    let settings = RenderSettings {
        sh_degree: model.sh_degree(),
        ..RenderSettings::default()
    };
    let (mut sum, mut n) = (0.0, 0usize);
    for v in ds.train_views() {
        let r = render_model(&model, &RenderCamera::from(&v.camera), &settings);
        let target = mesh_depth(mesh, &v.camera).unwrap();
        for (d, t) in r.depth.data.iter().zip(target) {
            if t > 0.0 {
                sum += ((d - t) / t).abs() as f64;
                n += 1;
            }
        }
    }
    sum / n as f64
}

#[test]
fn training_from_the_surface_follows_its_depth() {
    let ds = demo();
    let mesh = exact_mesh(&ds);
    let tmp = tempfile::tempdir().unwrap();
    let surface = tmp.path().join("surface");
    write_surface_run(
        &surface,
        &ds.name,
        &ds.train,
        &mesh,
        &training_cameras(&ds),
        0.0,
    );
    let mut errors = Vec::new();
    for weight in [0.0, 1.0] {
        let out = tmp.path().join(format!("splats-{weight}"));
        let summary = train_run(
            &ds,
            &surface_config(&surface, 150, weight),
            &out,
            false,
            |_| {},
        )
        .unwrap();
        assert_eq!(summary.init, "surface");
        let psnr = summary.test.mean_psnr;
        errors.push(depth_error(&ds, &mesh, &out));
        eprintln!(
            "depth weight {weight}: held-out PSNR {psnr:.2} dB, relative depth error {:.4}",
            errors.last().unwrap()
        );
        assert!(psnr > 16.0, "{psnr}");
    }
    assert!(errors[1] < 0.8 * errors[0], "{errors:?}");
}
