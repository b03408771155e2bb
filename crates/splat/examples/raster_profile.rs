use fewview_splat::cputime::process_cpu_seconds as now;
use fewview_splat::raster::blend::{TileGeometry, TileState, forward_tile};
use fewview_splat::raster::project::{CameraF, project_one};
use fewview_splat::raster::tiles::bin;
use rayon::prelude::*;
fn main() {
    let s = fewview_splat::bench::SyntheticScene::new(100_000, 504, 378, 1);
    let g = s.refs();
    let cam = CameraF::<f32>::new(&s.camera, 0.2);
    for _ in 0..3 {
        let t0 = now();
        let p: Vec<_> = (0..g.len())
            .into_par_iter()
            .map(|i| project_one(&g, i, &cam, 3))
            .collect();
        let t1 = now();
        let splats: Vec<_> = p.into_iter().flatten().map(|p| p.splat).collect();
        let bins = bin(&splats, s.camera.tiles_x(), s.camera.tiles_y());
        let t2 = now();
        let pairs: u64 = (0..bins.num_tiles())
            .into_par_iter()
            .map(|t| {
                let (tx, ty) = (t % bins.tiles_x, t / bins.tiles_x);
                let geo = TileGeometry {
                    x0: tx * 16,
                    y0: ty * 16,
                    width: 16.min(504 - tx * 16),
                    height: 16.min(378 - ty * 16),
                };
                let mut st = TileState::default();
                unsafe { fwd(&geo, bins.tile_entries(t), &splats, &mut st) }
            })
            .sum();
        let t3 = now();
        println!(
            "cpu: project {:.3} bin {:.3} ({} entries, {} visible) blend {:.3} pairs {} -> {:.0} M/s",
            t1 - t0,
            t2 - t1,
            bins.entries.len(),
            splats.len(),
            t3 - t2,
            pairs,
            pairs as f64 / (t3 - t2) / 1e6
        );
    }
}

#[target_feature(enable = "avx2")]
fn fwd(
    geo: &TileGeometry,
    list: &[u32],
    splats: &[fewview_splat::raster::project::Splat<f32>],
    st: &mut TileState<f32>,
) -> u64 {
    forward_tile(geo, list, splats, st)
}
