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
pub enum Command {
    /// Blend two images with validity masks (occlusion-aware Poisson, Poisson, pyramid, feather).
    Blend(blend::Args),
    /// Mesh a depth map (paper 000 §1).
    DepthMesh(depth_mesh::Args),
    /// Point cloud from depth maps, with contraction and subsampling (paper 000 §2).
    DepthPoints(depth_points::Args),
    /// Marching cubes of a scalar grid (.npy), with cleanup.
    Mcubes(mcubes::Args),
    /// Register point clouds: pre-alignment, FPFH + RANSAC, ICP (paper 001 Alg. 3).
    Register(register::Args),
    /// Chamfer distance: DTU protocol or synthetic-mesh metrics.
    Chamfer(chamfer::Args),
    /// Camera pose error (paper 001 Alg. 1–2).
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
