//! Subcommands: one module each, exposing `Args` (clap) and `run`.

mod blend;
mod chamfer;
mod depth_mesh;
mod depth_points;
mod geom_common;
mod mcubes;
mod pose_error;
mod register;

use clap::Subcommand;

#[derive(Debug, Subcommand)]
// Each subcommand's help (short and long) comes from the doc comment of its `Args`.
pub enum Command {
    Blend(blend::Args),
    DepthMesh(depth_mesh::Args),
    DepthPoints(depth_points::Args),
    Mcubes(mcubes::Args),
    Register(register::Args),
    Chamfer(chamfer::Args),
    PoseError(pose_error::Args),
}

pub fn run(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Blend(a) => blend::run(a),
        Command::DepthMesh(a) => depth_mesh::run(a),
        Command::DepthPoints(a) => depth_points::run(a),
        Command::Mcubes(a) => mcubes::run(a),
        Command::Register(a) => register::run(a),
        Command::Chamfer(a) => chamfer::run(a),
        Command::PoseError(a) => pose_error::run(a),
    }
}
