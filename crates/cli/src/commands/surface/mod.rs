//! `fewview surface`: neural implicit surface + pose refinement from a few views with noisy
//! poses (the surface paper). The flags are the library's [`Overrides`](fewview_surface::Overrides); this module parses them,
//! shows progress and prints the report.

mod args;
mod flags;
mod report;

use std::path::PathBuf;

use anyhow::Context;
use fewview_surface::LoadedInputs;
use fewview_surface::pipeline::checkpoint_path;

pub use self::args::Args;
use self::report::{print_event, print_report};
use super::output_paths::check_folder;
use super::progress;

pub fn run(args: Args) -> anyhow::Result<()> {
    if !args.table.is_empty() {
        let rows = args
            .table
            .iter()
            .map(|r| fewview_surface::table1::read_row(r))
            .collect::<Result<Vec<_>, _>>()?;
        print!("{}", fewview_surface::table1::markdown(&rows));
        return Ok(());
    }
    let scene = args.scene()?;
    let config = args.config()?;
    let inputs = LoadedInputs::load(&scene, &config)?;
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("runs").join(format!("surface-{}", inputs.name)));
    check_folder(&out, "--out")?;
    let ds = &inputs.dataset;
    eprintln!(
        "surface on {} ({} train views, {}x{}, {} iterations) → {}",
        ds.name,
        ds.train.len(),
        ds.views[ds.train[0]].image.width,
        ds.views[ds.train[0]].image.height,
        config.train.iterations,
        out.display()
    );
    let bar = progress::iterations(config.train.iterations as u64, "surface");
    let checkpoint = checkpoint_path(&out);
    if args.resume && !checkpoint.exists() {
        eprintln!(
            "note: --resume: no {} yet, starting from the first iteration",
            checkpoint.display()
        );
    }
    let report = fewview_surface::run(inputs.run_inputs(), &config, &out, args.resume, &mut |e| {
        print_event(&bar, e);
    })
    .with_context(|| format!("surface run in {}", out.display()))?;
    bar.finish_and_clear();
    print_report(&report, &out);
    Ok(())
}

#[cfg(test)]
mod tests;
