use fewview_splat::raster::blend::{TileGeometry, TileState, forward_tile};
use fewview_splat::raster::project::Splat;

#[inline(never)]
fn kernel(geo: &TileGeometry, list: &[u32], splats: &[Splat<f32>], st: &mut TileState<f32>) -> u64 {
    forward_tile(geo, list, splats, st)
}
#[target_feature(enable = "avx2")]
#[inline(never)]
fn kernel_avx2(
    geo: &TileGeometry,
    list: &[u32],
    splats: &[Splat<f32>],
    st: &mut TileState<f32>,
) -> u64 {
    forward_tile(geo, list, splats, st)
}

fn main() {
    let n = 2000;
    let splats: Vec<Splat<f32>> = (0..n)
        .map(|i| Splat {
            mean: [8.0 + (i % 7) as f32, 8.0 + (i % 5) as f32],
            conic: [0.02, 0.001, 0.03],
            opacity: 0.02,
            color: [0.5, 0.2, 0.1],
            depth: i as f32,
            rows: [0, 16],
            cols: [0, 16],
        })
        .collect();
    let list: Vec<u32> = (0..n as u32).collect();
    let geo = TileGeometry {
        x0: 0,
        y0: 0,
        width: 16,
        height: 16,
    };
    for round in 0..3 {
        let mut st = TileState::default();
        let c = fewview_splat::cputime::process_cpu_seconds();
        let mut pairs = 0;
        for _ in 0..50 {
            st = TileState::default();
            pairs += kernel(&geo, &list, &splats, &mut st);
        }
        let dt = fewview_splat::cputime::process_cpu_seconds() - c;
        let mut st2 = TileState::default();
        let c2 = fewview_splat::cputime::process_cpu_seconds();
        let mut pairs2 = 0;
        for _ in 0..50 {
            st2 = TileState::default();
            pairs2 += unsafe { kernel_avx2(&geo, &list, &splats, &mut st2) };
        }
        let dt2 = fewview_splat::cputime::process_cpu_seconds() - c2;
        println!(
            "round {round}: sse {:.1} Mpairs/s  avx2 {:.1} Mpairs/s  T={} {}",
            pairs as f64 / dt / 1e6,
            pairs2 as f64 / dt2 / 1e6,
            st.transmittance[3][3],
            st2.transmittance[3][3]
        );
    }
}
