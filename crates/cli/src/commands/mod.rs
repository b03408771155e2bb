//! Subcommands: one module each, exposing `Args` (clap) and `run`.

pub mod eval_video;
pub mod study;

use clap::Subcommand;

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Temporal-coherence metrics of a rendered frame sequence against ground truth.
    EvalVideo(eval_video::Args),
    /// Pairwise 2AFC user study: serve the page, analyse the answers.
    Study(study::Args),
}

pub fn run(command: Command) -> anyhow::Result<()> {
    match command {
        Command::EvalVideo(args) => eval_video::run(args),
        Command::Study(args) => study::run(args),
    }
}
