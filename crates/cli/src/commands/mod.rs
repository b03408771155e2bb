//! Subcommands: one module each, exposing `Args` (clap) and `run`.

mod bench;
mod benchmark;
mod blend;
mod chamfer;
mod dataset_args;
mod demo;
mod depth_mesh;
mod depth_points;
mod eval;
pub mod eval_video;
mod fusion;
mod fusion_outputs;
mod fusion_study;
mod geom_common;
mod geometry_args;
mod human;
mod leave_one_out;
mod matching;
mod mcubes;
mod number_args;
mod output_paths;
#[cfg(test)]
mod parse_for_tests;
mod photo_args;
mod pose_error;
mod poses;
mod poses_first;
mod progress;
mod register;
mod render;
mod stereo;
pub mod study;
mod surface;
mod surface_first;
mod train;
mod train_args;
mod view;

use clap::Subcommand;

#[derive(Debug, Subcommand)]
// Each subcommand's help (short and long) comes from the doc comment of its `Args`.
pub enum Command {
    Demo(demo::Args),
    Train(train::Args),
    Fusion(Box<fusion::Args>),
    Render(render::Args),
    Eval(eval::Args),
    Bench(bench::Args),
    Benchmark(benchmark::Args),
    Stereo(stereo::Args),
    Blend(blend::Args),
    DepthMesh(depth_mesh::Args),
    DepthPoints(depth_points::Args),
    Mcubes(mcubes::Args),
    Register(register::Args),
    Chamfer(chamfer::Args),
    PoseError(pose_error::Args),
    Match(matching::Args),
    Poses(poses::Args),
    // Boxed: the surface command has many flags, and clippy bounds the size difference of variants.
    Surface(Box<surface::Args>),
    /// Temporal-coherence metrics of a rendered frame sequence against ground truth.
    EvalVideo(eval_video::Args),
    /// Pairwise 2AFC user study: serve the page, analyse the answers.
    Study(study::Args),
    /// Pose-guided Gaussians of moving people (PoseGaussian).
    Human(human::Args),
    View(view::Args),
}

pub fn run(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Demo(a) => demo::run(a),
        Command::Train(a) => train::run(a),
        Command::Fusion(a) => fusion::run(*a),
        Command::Render(a) => render::run(a),
        Command::Eval(a) => eval::run(a),
        Command::Bench(a) => bench::run(a),
        Command::Benchmark(a) => benchmark::run(a),
        Command::Stereo(a) => stereo::run(a),
        Command::Blend(a) => blend::run(a),
        Command::DepthMesh(a) => depth_mesh::run(a),
        Command::DepthPoints(a) => depth_points::run(a),
        Command::Mcubes(a) => mcubes::run(a),
        Command::Register(a) => register::run(a),
        Command::Chamfer(a) => chamfer::run(a),
        Command::PoseError(a) => pose_error::run(a),
        Command::Match(a) => matching::run(a),
        Command::Poses(a) => poses::run(a),
        Command::Surface(a) => surface::run(*a),
        Command::EvalVideo(args) => eval_video::run(args),
        Command::Study(args) => study::run(args),
        Command::Human(args) => human::run(args),
        Command::View(args) => view::run(args),
    }
}
