//! `cargo run --release -p fewview-metrics --example ssim_bench`: prints the SSIM speed figures.

// An example program prints its results.
#![allow(clippy::print_stdout, clippy::print_stderr)]
fn main() {
    let b = fewview_metrics::bench::ssim_bench(504, 378, 30);
    println!("{b:#?}");
}
