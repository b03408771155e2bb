#![allow(clippy::print_stdout, clippy::print_stderr)]
use fewview_splat::raster::render::forward;
use fewview_splat::raster::{RenderCamera, RenderSettings};

#[test]
fn scratch() {
    let ply = std::env::var("PLY").unwrap();
    let data = std::env::var("DATA").unwrap();
    let model = fewview_splat::ply::read_ply(std::path::Path::new(&ply)).unwrap();
    let ds = fewview_scene::load_dataset(std::path::Path::new(&data), &Default::default()).unwrap();
    let v = &ds.views[1];
    let cam = RenderCamera::from(&v.camera);
    let settings = RenderSettings {
        background: [0.0; 3],
        sh_degree: model.sh_degree(),
        near_plane: 0.01,
    };
    let t = std::time::Instant::now();
    let (out, ctx) = forward(&model.refs(), &cam, &settings);
    let n = model.len();
    let visible = ctx.ids.len();
    let entries = ctx.bins.entries.len();
    eprintln!(
        "n {n} visible {visible} tile entries {entries} ({:.1}/splat) pairs {} ({:.0}/pixel) {:.3}s",
        entries as f64 / visible as f64,
        out.pairs,
        out.pairs as f64 / (cam.width * cam.height) as f64,
        t.elapsed().as_secs_f64()
    );
    let mut r: Vec<f64> = out
        .radii
        .iter()
        .map(|&x| x as f64)
        .filter(|&x| x > 0.0)
        .collect();
    r.sort_by(f64::total_cmp);
    eprintln!(
        "radii q10/50/90/99 {:?}",
        [0.1, 0.5, 0.9, 0.99].map(|q| r[(q * r.len() as f64) as usize])
    );
    // share of tile entries from radius bins
    let total: f64 = r.iter().map(|x| x * x).sum();
    let big: f64 = r.iter().filter(|&&x| x > 20.0).map(|x| x * x).sum();
    eprintln!(
        "area share of radius>20: {:.2}, count {}",
        big / total,
        r.iter().filter(|&&x| x > 20.0).count()
    );
}
