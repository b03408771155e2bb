//! The field's sparse-view benchmarks ([`Protocol`]): every scene given trained with several
//! seeds under the protocol's split, size and masks, scored by PSNR, SSIM and ST-LPIPS, and
//! written as `benchmark.md` and `benchmark.json` beside the peers' published figures.
//!
//! ```text
//! <out>/benchmark.md, benchmark.json   the table (rewritten after every run)
//! <out>/<scene>/seed<k>/               a training run (see crate::pipeline)
//! <out>/<scene>/seed<k>/score.json     its scores; present = done
//! ```
//!
//! A half-done table resumes: scored runs are read back, a run with a checkpoint continues
//! from it, a finished run that was not scored is scored.

mod error;
pub mod masked;
pub mod protocol;
mod score;
mod table;

use std::path::{Path, PathBuf};

use fewview_metrics::lpips::Lpips;
use fewview_scene::Dataset;

use crate::pipeline::RunDir;
pub use error::BenchmarkError;
pub use protocol::{Peer, Protocol};
pub use score::SeedScore;
pub use table::{SceneRow, Table};

/// One scene of a benchmark: its name (the folder's) and its data under the protocol.
pub struct Scene {
    pub name: String,
    pub folder: PathBuf,
    pub data: Dataset,
}

/// Loads every scene under `protocol` before anything is written, so that one that cannot be
/// benchmarked stops the command with nothing half-done; two folders of one name are refused.
pub fn load_scenes(protocol: Protocol, folders: &[PathBuf]) -> Result<Vec<Scene>, BenchmarkError> {
    let mut scenes: Vec<Scene> = Vec::new();
    for folder in folders {
        let name = folder
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scene".into());
        if scenes.iter().any(|s| s.name == name) {
            return Err(BenchmarkError::Scene {
                folder: folder.clone(),
                message: format!("a second scene named `{name}`; their runs would share a folder"),
            });
        }
        let data = protocol.load(folder)?;
        scenes.push(Scene {
            name,
            folder: folder.clone(),
            data,
        });
    }
    Ok(scenes)
}

/// Where one scene's run of one seed lives.
pub fn run_dir(out: &Path, scene: &str, seed: u64) -> PathBuf {
    out.join(scene).join(format!("seed{seed}"))
}

/// Runs (or resumes) the benchmark of `scenes` with `seeds` in `out`: `train(data, seed, dir,
/// resume)` trains one run; each is then scored ([`SeedScore::of_run`]) and the table rewritten
/// and handed to `on_table`.
pub fn run(
    protocol: Protocol,
    scenes: &[Scene],
    seeds: &[u64],
    out: &Path,
    lpips: Option<&Lpips>,
    mut train: impl FnMut(&Dataset, u64, &Path, bool) -> Result<(), String>,
    mut on_table: impl FnMut(&Table),
) -> Result<Table, BenchmarkError> {
    let mut table = Table::new(protocol, seeds);
    for scene in scenes {
        let mut scores = Vec::new();
        for &seed in seeds {
            let dir = run_dir(out, &scene.name, seed);
            let score = match SeedScore::read(&dir)? {
                Some(score) => score,
                None => {
                    let run = RunDir(dir.clone());
                    if !run.finished() {
                        let resume = run.checkpoint().exists();
                        train(&scene.data, seed, &dir, resume).map_err(|message| {
                            BenchmarkError::Run {
                                run: dir.clone(),
                                message,
                            }
                        })?;
                    }
                    let score = SeedScore::of_run(&scene.data, &dir, seed, protocol, lpips)?;
                    score.write(&dir)?;
                    score
                }
            };
            scores.push(score);
            table.set(&scene.name, scores.clone());
            table.write(out)?;
            on_table(&table);
        }
    }
    Ok(table)
}
