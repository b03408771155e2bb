//! Training-step rate on DTU scan65 (views 22, 25, 28, 400 × 300) beside the NeuS-MLP reference:
//! `FEWVIEW_DATA=/work/shared/data cargo run --release -p fewview-surface --example scan65_bench -- 10 1`
//! (hash-grid iterations, reference iterations).

use fewview_scene::load::{LoadOptions, load_dataset};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let root = std::env::var("FEWVIEW_DATA").map_err(|_| "set FEWVIEW_DATA")?;
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .map(|s| s.parse())
        .collect::<Result<_, _>>()?;
    let ds = load_dataset(
        &std::path::Path::new(&root).join("dtu/scan65"),
        &LoadOptions {
            downscale: 2,
            train_views: Some(vec![22, 25, 28]),
            ..LoadOptions::default()
        },
    )?;
    let bench = fewview_surface::bench::train_step_bench(
        &ds,
        args.first().copied().unwrap_or(10),
        args.get(1).copied().unwrap_or(1),
    )?;
    println!("{}", serde_json::to_string_pretty(&bench)?);
    Ok(())
}
