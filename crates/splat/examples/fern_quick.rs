use burn::tensor::Device;
use fewview_scene::load::{LoadOptions, load_dataset};
use fewview_splat::init::{FrustumView, from_points, random_in_frustums};
use fewview_splat::raster::{RenderCamera, RenderSettings};
use fewview_splat::train::{TrainConfig, TrainView, Trainer};
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let iters: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(1000);
    let npts: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(20000);
    let data = std::env::var("FEWVIEW_DATA").unwrap();
    let ds = load_dataset(
        &std::path::Path::new(&data).join("llff/fern"),
        &LoadOptions::default(),
    )
    .unwrap();
    let device = Device::flex().autodiff();
    let fv: Vec<FrustumView> = ds
        .train_views()
        .map(|v| FrustumView {
            camera: &v.camera,
            image: &v.image,
            near: v.depth_bounds.unwrap().0,
            far: v.depth_bounds.unwrap().1,
        })
        .collect();
    let cloud = random_in_frustums(&fv, npts, 0);
    let model = from_points(&cloud, 3);
    let views: Vec<TrainView> = ds
        .train_views()
        .map(|v| TrainView::new(&v.name, RenderCamera::from(&v.camera), &v.image, &device))
        .collect();
    let (_, extent) = ds.camera_extent();
    let cfg = TrainConfig::sparse_view(iters);
    let mut t = Trainer::new(cfg.clone(), model, views, extent as f32, device).unwrap();
    let start = Instant::now();
    t.run(
        |p| {
            if p.iteration % 100 == 0 || p.densified.is_some() && p.iteration % 500 == 0 {
                eprintln!(
                    "it {} loss {:.4} n {} {:?} t={:.1}s",
                    p.iteration,
                    p.loss,
                    p.gaussians,
                    p.densified,
                    start.elapsed().as_secs_f64()
                );
            }
        },
        |_, _| Ok(()),
    )
    .unwrap();
    let test: Vec<_> = ds.test_views().collect();
    let settings = RenderSettings {
        background: cfg.background,
        sh_degree: cfg.sh_degree,
        near_plane: cfg.near_plane,
    };
    let (rep, renders) = fewview_splat::eval::evaluate(&t.state.model, &test, &settings).unwrap();
    println!(
        "iters {iters} time {:.1}s  gaussians {}  test psnr {:.3} ssim {:.4}  per view {:?}",
        start.elapsed().as_secs_f64(),
        t.state.model.len(),
        rep.mean_psnr,
        rep.mean_ssim,
        rep.views.iter().map(|v| v.psnr).collect::<Vec<_>>()
    );
    for (i, r) in renders.iter().enumerate() {
        r.rgb
            .save_png(std::path::Path::new(&format!("/tmp/fern_test{i}.png")))
            .unwrap();
    }
}
