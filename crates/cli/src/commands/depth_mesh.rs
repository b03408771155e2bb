//! `fewview depth-mesh`: mesh a depth map (the fusion paper §1, Eq. 1).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args as ClapArgs;
use fewview_geom::depth::{DepthOptions, EdgeTest, TAU_DEPTH, depth_to_mesh_with};
use fewview_geom::io::{cameras::read_cameras, read_depth, write_mesh};
use fewview_scene::Camera;

use super::geom_common::load_image;
use super::number_args::non_negative_f32;
use super::output_paths::check_file;

/// Depth-edge filter options shared by depth-mesh and depth-points.
#[derive(Clone, Debug, ClapArgs)]
pub struct DepthInput {
    /// τ_depth of Eq. (1) (0: no filter).
    ///
    /// τ_depth of Eq. (1); pixels whose edge measure reaches it are dropped. 0 disables the
    /// filter.
    #[arg(long, default_value_t = TAU_DEPTH, value_parser = non_negative_f32)]
    pub tau: f32,
    #[arg(long, value_enum, default_value = "area")]
    pub edge_test: EdgeTest,
    /// Scale of 16-bit PNG depth values.
    ///
    /// E.g. 0.001 for millimetres → metres.
    #[arg(long, default_value_t = 1.0)]
    pub png_scale: f32,
}

pub fn load_camera(path: &std::path::Path, view: usize) -> Result<Camera> {
    let cams = read_cameras(path)?;
    let n = cams.len();
    cams.into_iter()
        .nth(view)
        .with_context(|| format!("{}: camera {view} asked for, file has {n}", path.display()))
}

/// Reads one depth map with camera `view` of a camera file and optional colours.
pub fn load_depth_view(
    depth: &std::path::Path,
    input: &DepthInput,
    camera: &std::path::Path,
    view: usize,
    image: Option<&std::path::Path>,
) -> Result<(Vec<f32>, Camera, Option<fewview_scene::Image>)> {
    let d = read_depth(depth, input.png_scale)?;
    let cam = load_camera(camera, view)?;
    if (d.width, d.height) != (cam.width() as usize, cam.height() as usize) {
        bail!(
            "{}: depth is {}×{} but camera {} of {} is {}×{}",
            depth.display(),
            d.width,
            d.height,
            view,
            camera.display(),
            cam.width(),
            cam.height()
        );
    }
    let img = image.map(load_image).transpose()?;
    Ok((d.depth, cam, img))
}

/// Mesh a depth map (the fusion paper's supplement §1).
///
/// Back-projects every pixel centre, connects right/down neighbours into triangles and drops
/// depth-edge pixels with the test of Eq. (1).
///
/// Depth: .npy float32 H×W (z-depth along the optical axis) or 16-bit PNG (× --png-scale);
/// 0 means no depth, NaN is an error.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// Depth map (.npy or .png).
    #[arg(long)]
    pub depth: PathBuf,
    /// Camera JSON (OpenCV axes).
    ///
    /// Camera JSON (intrinsics + row-major world_to_camera 4×4, OpenCV axes); a file with a
    /// list of cameras needs --view.
    #[arg(long)]
    pub camera: PathBuf,
    /// Which camera of the file.
    #[arg(long, default_value_t = 0)]
    pub view: usize,
    /// Colour image for vertex colours (same size as the depth map).
    #[arg(long)]
    pub image: Option<PathBuf>,
    #[command(flatten)]
    pub input: DepthInput,
    /// Output mesh (.ply, .obj or .off).
    #[arg(long, short)]
    pub out: PathBuf,
}

pub fn run(args: Args) -> Result<()> {
    check_file(&args.out, "--out")?;
    let (depth, cam, img) = load_depth_view(
        &args.depth,
        &args.input,
        &args.camera,
        args.view,
        args.image.as_deref(),
    )?;
    let opts = DepthOptions {
        tau: args.input.tau,
        test: args.input.edge_test,
    };
    let mesh = depth_to_mesh_with(&depth, &cam, img.as_ref(), &opts)
        .with_context(|| format!("meshing {}", args.depth.display()))?;
    write_mesh(&args.out, &mesh)?;
    println!(
        "{}",
        serde_json::json!({"vertices": mesh.vertices.len(), "faces": mesh.faces.len(),
            // Not the `PathBuf`: serde refuses a path that is not UTF-8.
            "out": args.out.display().to_string()})
    );
    Ok(())
}
