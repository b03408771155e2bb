//! `fewview view`: look at a run in the browser.

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::PathBuf;

use anyhow::Context;
use clap::Args as ClapArgs;
use fewview_scene::DatasetFormat;
use fewview_scene::load::LoadOptions;
use fewview_view::{OpenOptions, Run, RunKind, server};

/// Look at a run in the browser: an interactive 3D viewer served on loopback.
///
/// Serves a page (nothing is fetched from the internet) with the run drawn in 3D: the trained
/// Gaussians of a `train`, `demo` or `fusion` run, streamed to the page and drawn with the same
/// projection, colours and compositing as `fewview render`; the mesh of a `surface` run with
/// its initial and refined cameras; or the estimated cameras and points of a `poses` folder.
/// The cameras are drawn as frusta (training and estimated orange, held-out blue; surface:
/// initial red, refined green); click one, or its name in the list, to look
/// through it. Beside the view: `metrics.json`, the held-out renders next to their ground truth
/// and the run's videos.
///
/// Controls: drag to orbit (right button or Shift to pan), wheel to zoom; F switches to fly
/// (W/A/S/D/Q/E move, drag looks around). Stop the server with Ctrl-C.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// Run directory: the `--out` of `train`, `demo`, `fusion`, `surface` or `poses`.
    #[arg(
        value_name = "RUN_DIR",
        required_unless_present = "ply",
        conflicts_with = "ply"
    )]
    pub run: Option<PathBuf>,
    /// A Gaussian PLY to look at without its run.
    ///
    /// A Gaussian PLY (Inria 3DGS layout, binary little-endian) to look at without its run.
    #[arg(long, value_name = "FILE")]
    pub ply: Option<PathBuf>,
    /// The dataset the run was trained on.
    ///
    /// Its cameras are drawn when the run has no `cameras.json` (runs from before it was written),
    /// the views `config.json` names.
    #[arg(long, value_name = "DIR", conflicts_with = "ply")]
    pub data: Option<PathBuf>,
    /// With --data: force its format.
    ///
    /// With --data: force the dataset format (llff, blender, nerfstudio, dtu, colmap).
    #[arg(long, value_name = "NAME", requires = "data")]
    pub format: Option<DatasetFormat>,
    /// With --data: load it downscaled.
    ///
    /// With --data: load the dataset downscaled by this factor (faster; the cameras are resized
    /// to the run's image size either way).
    #[arg(long, default_value_t = 1, value_name = "K", requires = "data")]
    pub downscale: u32,
    /// Port to listen on; 0 picks a free one (the URL is printed).
    #[arg(long, default_value_t = 0)]
    pub port: u16,
    /// Address to listen on (default: loopback).
    ///
    /// Address to listen on: loopback by default. 0.0.0.0 lets other machines in.
    #[arg(long, default_value_t = IpAddr::V4(Ipv4Addr::LOCALHOST))]
    pub host: IpAddr,
    /// Open the page in the browser.
    ///
    /// Open the page in the default browser (`xdg-open`, or `open` on macOS).
    #[arg(long)]
    pub open: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let run = match (&args.run, &args.ply) {
        (_, Some(ply)) => Run::from_ply(ply).context("cannot view the PLY")?,
        (Some(dir), None) => {
            let opts = OpenOptions {
                data: args.data.clone(),
                load: LoadOptions {
                    format: args.format,
                    downscale: args.downscale,
                    ..LoadOptions::default()
                },
            };
            Run::open_with(dir, &opts).context("cannot view the run")?
        }
        (None, None) => anyhow::bail!("give RUN_DIR or --ply FILE"),
    };
    let m = &run.manifest;
    let what = match (m.kind, &m.model) {
        (RunKind::Surface, _) => "surface run (mesh)".to_string(),
        (_, Some(model)) => format!("{} Gaussians", model.layout.count),
        (_, None) => String::new(),
    };
    let cameras = m.cameras.len();
    if cameras == 0
        && m.kind == RunKind::Splat
        && let Some(note) = m.notes.iter().find(|n| n.starts_with("no cameras.json"))
    {
        eprintln!("note: {note}");
    }
    let open = args.open;
    server::serve(run, SocketAddr::new(args.host, args.port), |bound| {
        let url = format!("http://{bound}/");
        println!("view: {url}  ({what}, {cameras} cameras; Ctrl-C to stop)");
        if open {
            let opener = if cfg!(target_os = "macos") {
                "open"
            } else {
                "xdg-open"
            };
            if let Err(e) = std::process::Command::new(opener).arg(&url).spawn() {
                eprintln!("cannot open a browser ({opener}: {e}); open {url} yourself");
            }
        }
    })?;
    Ok(())
}
