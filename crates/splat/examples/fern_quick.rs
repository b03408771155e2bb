//! Development probe: held-out PSNR along a fern run (env: ITERS, POINTS, UNTIL, SH, EVERY).
use burn::tensor::Device;
use fewview_scene::load::{LoadOptions, load_dataset};
use fewview_splat::pipeline::{RunConfig, initial_model};
use fewview_splat::raster::{RenderCamera, RenderSettings};
use fewview_splat::train::{TrainConfig, TrainView, Trainer};
use std::time::Instant;

fn env(k: &str, d: usize) -> usize {
    std::env::var(k)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(d)
}

fn main() {
    let iters = env("ITERS", 3000);
    let data = std::env::var("FEWVIEW_DATA").unwrap();
    let scene = std::env::var("SCENE").unwrap_or("llff/fern".into());
    let ds = load_dataset(
        &std::path::Path::new(&data).join(&scene),
        &LoadOptions::default(),
    )
    .unwrap();
    let device = Device::flex().autodiff();
    let mut tc = TrainConfig::sparse_view(iters);
    tc.densify.until_iter = env("UNTIL", tc.densify.until_iter);
    tc.sh_degree = env("SH", 3);
    tc.background = ds.background;
    let mut cfg = RunConfig::new(tc.clone());
    cfg.init_points = env("POINTS", 20000);
    let model = initial_model(&ds, &cfg).unwrap();
    let views: Vec<TrainView> = ds
        .train_views()
        .map(|v| TrainView::new(&v.name, RenderCamera::from(&v.camera), &v.image, &device))
        .collect();
    let (_, extent) = ds.camera_extent();
    let mut t = Trainer::new(tc.clone(), model, views, extent as f32, device).unwrap();
    let start = Instant::now();
    let test: Vec<_> = ds.test_views().collect();
    let every = env("EVERY", 250);
    while !t.is_done() {
        let p = t.step().unwrap();
        if p.iteration % every == 0 {
            let settings = RenderSettings {
                background: tc.background,
                sh_degree: tc.active_sh_degree(p.iteration),
                near_plane: tc.near_plane,
            };
            let (rep, _) = fewview_splat::eval::evaluate(&t.state.model, &test, &settings).unwrap();
            println!(
                "it {} loss {:.4} n {} test psnr {:.3} ssim {:.4} t={:.0}s",
                p.iteration,
                p.loss,
                p.gaussians,
                rep.mean_psnr,
                rep.mean_ssim,
                start.elapsed().as_secs_f64()
            );
        }
    }
}
