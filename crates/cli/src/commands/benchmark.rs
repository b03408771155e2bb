//! `fewview benchmark`: the field's sparse-view benchmarks on the scenes given.

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args as ClapArgs;
use fewview_splat::benchmark::{self, Protocol};
use fewview_splat::pipeline::default_iterations;
use fewview_splat::sky_shell::SkyShell;

use super::output_paths::check_folder;
use super::train::train_with_progress;
use super::train_args::TrainArgs;

/// Run a sparse-view benchmark (LLFF, DTU or Blender) and write its table.
///
/// Trains every scene given with each seed under the protocol of RegNeRF, FSGS and CoR-GS
/// (LLFF: 3 views at 504×378, every 8th image held out; DTU: views 25, 22, 28 at 400×300,
/// scored inside the object masks; Blender: 8 views at 400×400), scores the held-out views by
/// PSNR, SSIM and ST-LPIPS, and writes `OUT/benchmark.md` and `OUT/benchmark.json` (per scene
/// and mean, Gaussians, training time) beside the peers' published figures. Run it again with
/// the same flags to finish a half-done table. Training flags (`--dropout`, `--iterations`, …)
/// apply to every run.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// The benchmark's protocol.
    #[arg(long, value_enum)]
    pub protocol: Protocol,
    /// Scene folders (one dataset each).
    #[arg(long, value_name = "DIR", num_args = 1.., required = true)]
    pub data: Vec<PathBuf>,
    /// Output folder: a run per scene and seed, and the table.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Seeds of each scene's runs (replaces `--seed`).
    #[arg(long, value_name = "LIST", value_delimiter = ',', default_values_t = [0u64, 1, 2])]
    pub seeds: Vec<u64>,
    /// Skip ST-LPIPS.
    #[arg(long)]
    pub no_lpips: bool,
    #[command(flatten)]
    pub train: TrainArgs,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    check_folder(&args.out, "--out")?;
    if args.seeds.is_empty() {
        bail!("--seeds: give at least one seed");
    }
    if args.train.seed != fewview_splat::TrainConfig::inria().seed {
        bail!("--seed: the benchmark runs each of --seeds");
    }
    let scenes = benchmark::load_scenes(args.protocol, &args.data)?;
    let lpips = if args.no_lpips {
        None
    } else {
        Some(fewview_metrics::lpips::Lpips::default_st_alex()?)
    };
    std::fs::create_dir_all(&args.out).with_context(|| format!("--out {}", args.out.display()))?;
    let train = |ds: &fewview_scene::Dataset, seed: u64, dir: &std::path::Path, resume: bool| {
        let mut cfg = args
            .train
            .run_config(ds.background, default_iterations(ds), false)
            .map_err(|e| format!("{e:#}"))?;
        cfg.train.seed = seed;
        if args.train.sky_shell == SkyShell::Auto {
            cfg.stereo.sky_shell = args.protocol.sky_shell();
        }
        if args.train.geometry.pseudo_depth_weight.is_none() {
            cfg.pseudo_depth_weight = args.protocol.pseudo_depth_weight();
        }
        eprintln!(
            "{} seed {seed} ({} train / {} held-out views) → {}",
            ds.name,
            ds.train.len(),
            ds.test.len(),
            dir.display()
        );
        train_with_progress(ds, &cfg, dir, resume)
            .map(|_| ())
            .map_err(|e| format!("{e:#}"))
    };
    let table = benchmark::run(
        args.protocol,
        &scenes,
        &args.seeds,
        &args.out,
        lpips.as_ref(),
        train,
        |_| {},
    )?;
    print!("{}", table.markdown());
    println!(
        "wrote {} and benchmark.json",
        args.out.join("benchmark.md").display()
    );
    Ok(())
}
