//! `fewview human render`.

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args as ClapArgs;

use super::shared::{CaptureArgs, TpsArgs, load_model, parse_frames, run_split};
use crate::commands::progress;

/// Render a trained run from the input cameras of every frame: each `--cameras` camera (or a
/// path circling the rig with `--orbit`) as `OUT/<camera>/frame_NNNN.png` and `OUT/<camera>.mp4`.
#[derive(Debug, ClapArgs)]
pub struct RenderArgs {
    /// The run folder `human train` wrote.
    #[arg(long, value_name = "DIR")]
    pub run: PathBuf,
    #[command(flatten)]
    pub capture: CaptureArgs,
    /// Cameras of the capture to render.
    ///
    /// E.g. `2,5` (default: the run's held-out cameras).
    #[arg(
        long,
        value_name = "LIST",
        value_delimiter = ',',
        conflicts_with = "orbit"
    )]
    pub cameras: Vec<usize>,
    /// Render one camera circling the rig instead.
    ///
    /// Render one camera circling the rig once over the frames instead (`OUT/orbit.mp4`).
    #[arg(long)]
    pub orbit: bool,
    /// First and last frame (inclusive), e.g. `40..=59`; default every frame.
    #[arg(long, value_name = "A..=B")]
    pub frames: Option<String>,
    /// Switch the Temporal Pose Stabilizer off.
    #[arg(long)]
    pub no_tps: bool,
    #[command(flatten)]
    pub tps: TpsArgs,
    /// Source views per target.
    ///
    /// Default: what the run was trained with.
    #[arg(long, value_name = "N")]
    pub source_views: Option<usize>,
    /// Frames per second of the videos.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f32,
}

pub(super) fn render(args: RenderArgs) -> anyhow::Result<()> {
    use fewview_human::infer::SequenceRenderer;
    let model = load_model(&args.run, args.source_views)?;
    let (_, capture) = fewview_human::capture::open(&args.capture.data, &args.capture.sequence)?;
    let split = run_split(&args.run, &*capture)?;
    let frames = match &args.frames {
        Some(t) => parse_frames(t)?,
        None => split.all_frames(),
    };
    if frames.end > capture.frame_count() {
        bail!(
            "--frames {:?}: {} has {} frames",
            frames,
            capture.root().display(),
            capture.frame_count()
        );
    }
    let rig = capture.cameras();
    let chosen = if args.cameras.is_empty() {
        split.held_out_cameras.clone()
    } else {
        args.cameras.clone()
    };
    if let Some(c) = chosen.iter().find(|&&c| c >= rig.len()) {
        bail!(
            "--cameras: camera {c} does not exist ({} has {} cameras)",
            capture.root().display(),
            rig.len()
        );
    }
    // Per output: its name and one camera per frame.
    let outputs: Vec<(String, Vec<fewview_scene::Camera>)> = if args.orbit {
        let path = fewview_human::orbit::orbit_cameras(rig, frames.len());
        vec![("orbit".to_string(), path)]
    } else {
        chosen
            .iter()
            .map(|&c| {
                (
                    capture.camera_names()[c].clone(),
                    vec![rig[c].clone(); frames.len()],
                )
            })
            .collect()
    };
    let tps = if args.no_tps {
        None
    } else {
        Some(args.tps.config()?)
    };
    let mut renderer = SequenceRenderer::new(&model, &*capture, &split, tps);
    let out = &args.capture.out;
    for (name, _) in &outputs {
        let dir = out.join(name);
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("{}: cannot create", dir.display()))?;
    }
    let bar = progress::iterations(frames.len() as u64, "human render");
    let mut videos: Vec<Vec<fewview_scene::Image>> = vec![Vec::new(); outputs.len()];
    for (t, frame) in frames.clone().enumerate() {
        let cameras: Vec<_> = outputs.iter().map(|(_, path)| path[t].clone()).collect();
        let r = renderer.render_frame(frame, &cameras)?;
        let images = r.stabilized.unwrap_or(r.plain);
        for (k, image) in images.into_iter().enumerate() {
            let path = out
                .join(&outputs[k].0)
                .join(format!("frame_{frame:04}.png"));
            image.save_png(&path)?;
            videos[k].push(image);
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let opts = fewview_video::VideoOptions::default();
    for ((name, _), video) in outputs.iter().zip(&videos) {
        let path = out.join(format!("{name}.mp4"));
        fewview_video::write_video(&path, video, args.fps, &opts)?;
    }
    eprintln!(
        "rendered {} view(s) × {} frames of {} into {}",
        outputs.len(),
        frames.len(),
        args.run.display(),
        out.display()
    );
    Ok(())
}
