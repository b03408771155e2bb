use std::time::Instant;
use fewview_splat::raster::project::{CameraF, project_one};
use fewview_splat::raster::tiles::bin;
use fewview_splat::raster::blend::{TileGeometry, TileState, forward_tile};
use rayon::prelude::*;
fn main() {
    let s = fewview_splat::bench::SyntheticScene::new(100_000, 504, 378, 1);
    let g = s.refs();
    let cam = CameraF::<f32>::new(&s.camera, 0.2);
    for _ in 0..3 {
    let t0 = Instant::now();
    let p: Vec<_> = (0..g.len()).into_par_iter().map(|i| project_one(&g, i, &cam, 3)).collect();
    let t1 = Instant::now();
    let splats: Vec<_> = p.into_iter().flatten().map(|p| p.splat).collect();
    let bins = bin(&splats, s.camera.tiles_x(), s.camera.tiles_y());
    let t2 = Instant::now();
    let pairs: u64 = (0..bins.num_tiles()).into_par_iter().map(|t| {
        let (tx, ty) = (t % bins.tiles_x, t / bins.tiles_x);
        let geo = TileGeometry { x0: tx*16, y0: ty*16, width: 16.min(504 - tx*16), height: 16.min(378-ty*16) };
        let mut st = TileState::default();
        forward_tile(&geo, bins.tile_entries(t), &splats, &mut st)
    }).sum();
    let t3 = Instant::now();
    println!("project {:?} bin {:?} ({} entries, {} visible) blend {:?} pairs {}", t1-t0, t2-t1, bins.entries.len(), splats.len(), t3-t2, pairs);
    }
}
