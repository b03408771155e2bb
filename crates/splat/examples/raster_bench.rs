fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(100_000);
    let b = fewview_splat::bench::raster_bench(n, 504, 378, 5);
    println!("{b:#?}");
}
