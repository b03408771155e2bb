use fewview_surface::cputime::process_cpu_seconds;
use fewview_surface::sdf_scene::{SdfSceneOptions, sdf_dataset};
use fewview_surface::train::{TrainConfig, TrainView, Trainer};
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let iters: usize = args.get(1).map(|s| s.parse().unwrap()).unwrap_or(200);
    let opts = SdfSceneOptions {
        width: 320,
        height: 240,
        views: 16,
        train: vec![0, 2, 4, 6, 8, 10, 12, 14],
        supersample: 2,
        fov_deg: 30.0,
        ..Default::default()
    };
    let ds = sdf_dataset(&opts);
    let views: Vec<TrainView> = ds
        .train
        .iter()
        .map(|&i| TrainView {
            image: ds.views[i].image.clone(),
            mask: ds.views[i].mask.clone(),
            intrinsics: ds.views[i].camera.intrinsics,
        })
        .collect();
    let poses: Vec<_> = ds
        .train
        .iter()
        .map(|&i| ds.views[i].camera.world_to_camera)
        .collect();
    let mut cfg = TrainConfig::default();
    cfg.iterations = iters;
    cfg.refine_poses = false;
    cfg.c2f = (0.0, 0.5);
    let mut t = Trainer::new(cfg, views, &poses, vec![]).unwrap();
    let c0 = process_cpu_seconds();
    let w0 = std::time::Instant::now();
    for i in 0..iters {
        let s = t.step().unwrap();
        if i % 50 == 0 || i + 1 == iters {
            println!(
                "{i} psnr {:.2} mask {:.4} eik {:.4} inv_s {:.1} | cpu {:.1}s wall {:.1}s",
                s.psnr,
                s.mask,
                s.eikonal,
                s.inv_s,
                process_cpu_seconds() - c0,
                w0.elapsed().as_secs_f64()
            );
        }
    }
    if std::env::var("NOMESH").is_ok() { return; }
    let (field, params) = t.field_params();
    let mesh = fewview_surface::extract::extract_mesh(field, params, &Default::default()).unwrap();
    let gt = fewview_geom::mcubes::marching_cubes_chunked(
        |p: &[[f64; 3]]| {
            p.iter()
                .map(|q| {
                    fewview_surface::sdf_scene::sdf(&nalgebra::Vector3::new(q[0], q[1], q[2]))
                        as f32
                })
                .collect()
        },
        ([-1.0; 3], [1.0; 3]),
        [256; 3],
        32,
        0.0,
    )
    .unwrap();
    let m = fewview_geom::chamfer::surface_metrics(&mesh, &gt, 100000, &[0.01, 0.02], 0).unwrap();
    let diag = fewview_geom::mesh::bbox_diagonal(&gt.vertices);
    println!(
        "chamfer {:.5} ({:.3}% of diag {:.3}); acc {:.5} comp {:.5}",
        m.chamfer_l1,
        100.0 * m.chamfer_l1 / diag,
        diag,
        m.accuracy,
        m.completeness
    );
    fewview_geom::io::write_mesh(std::path::Path::new("/tmp/quick_mesh.ply"), &mesh).unwrap();
}
