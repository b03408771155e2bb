//! `fewview human`: pose-guided feed-forward Gaussians of moving people (the PoseGaussian paper).

mod depth;
mod eval;
mod render;
mod shared;
mod train;

use clap::{Args as ClapArgs, Subcommand};

pub use depth::DepthArgs;
pub use eval::EvalArgs;
pub use render::RenderArgs;
pub use train::TrainArgs;

/// Pose-guided Gaussians of moving people from synchronized multi-view video (PoseGaussian:
/// Pose-Driven Novel View Synthesis for Robust 3D Human Reconstruction).
///
/// `train` fits the network on the input cameras of the training frames (the split of
/// PoseGaussian's protocol: on `seq_a`, cameras 2, 5, 8, 11 and frames 40–59 are never read);
/// `render` draws any camera of the rig, or a path circling it, from the input cameras of each
/// frame; `eval` scores the held-out cameras against the baselines; `depth` compares the input
/// depths (hull, per-frame stereo, the capture's) and how much each flickers.
#[derive(Debug, ClapArgs)]
pub struct Args {
    #[command(subcommand)]
    pub command: HumanCommand,
}

#[derive(Debug, Subcommand)]
pub enum HumanCommand {
    Train(TrainArgs),
    Render(RenderArgs),
    Eval(EvalArgs),
    Depth(DepthArgs),
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        HumanCommand::Train(a) => train::train(a),
        HumanCommand::Render(a) => render::render(a),
        HumanCommand::Eval(a) => eval::eval(a),
        HumanCommand::Depth(a) => depth::depth(a),
    }
}
