//! `cargo run --release -p fewview-metrics --example ssim_bench`: prints the SSIM speed figures.
fn main() {
    let b = fewview_metrics::bench::ssim_bench(504, 378, 30);
    println!("{b:#?}");
}
