//! The `bench` sections that read a dataset or write a scene: each loads what it measures and
//! says in one line when it is skipped.

use std::path::PathBuf;

use anyhow::Context;
use fewview_scene::load::{LoadOptions, load_dataset};

use super::args::Args;

/// Writes the rasterizer benchmark's scene as a 3DGS PLY and its camera as JSON.
pub(super) fn write_scene(
    dir: &std::path::Path,
    n: usize,
    width: usize,
    height: usize,
) -> anyhow::Result<()> {
    let scene = fewview_splat::bench::SyntheticScene::new(n, width, height, 1);
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let model = scene.to_model();
    fewview_splat::write_ply(&dir.join("scene.ply"), &model)?;
    let c = &scene.camera;
    let r = &c.rotation;
    let t = &c.translation;
    // The friendly camera form of `cameras.json` (what `fewview render --cameras` reads).
    let camera = serde_json::json!([{
        "intrinsics": {"fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy,
                       "width": c.width, "height": c.height},
        "world_to_camera": [
            [r[0][0], r[0][1], r[0][2], t[0]],
            [r[1][0], r[1][1], r[1][2], t[1]],
            [r[2][0], r[2][1], r[2][2], t[2]],
            [0.0, 0.0, 0.0, 1.0],
        ],
    }]);
    fewview_scene::atomic::write_bytes(
        &dir.join("cameras.json"),
        &serde_json::to_vec_pretty(&camera)?,
    )?;
    eprintln!("scene written to {}", dir.display());
    Ok(())
}

/// Training steps on LLFF fern, when its folder is given or under `FEWVIEW_DATA`.
pub(super) fn fern_train_bench(
    args: &Args,
) -> anyhow::Result<Option<fewview_splat::bench::TrainStepBench>> {
    let fern_dir = args
        .fern
        .clone()
        .or_else(|| std::env::var_os("FEWVIEW_DATA").map(|d| PathBuf::from(d).join("llff/fern")));
    match fern_dir {
        Some(dir) if dir.exists() => {
            eprintln!("training steps: {} ...", dir.display());
            let ds = load_dataset(&dir, &LoadOptions::default())
                .with_context(|| format!("cannot load {}", dir.display()))?;
            Ok(Some(fewview_splat::bench::train_step_bench(
                &ds,
                args.train_steps,
                args.device,
            )?))
        }
        _ => {
            eprintln!("training steps: fern skipped (pass --fern or set FEWVIEW_DATA)");
            Ok(None)
        }
    }
}

/// Surface training steps on DTU scan65 (views 22, 25, 28 at 400×300), when available.
pub(super) fn surface_train_bench(
    args: &Args,
) -> anyhow::Result<Option<fewview_surface::bench::SurfaceStepBench>> {
    let dtu_dir = args
        .dtu
        .clone()
        .or_else(|| std::env::var_os("FEWVIEW_DATA").map(|d| PathBuf::from(d).join("dtu/scan65")));
    match dtu_dir {
        Some(dir) if dir.exists() => {
            eprintln!("surface training steps: {} ...", dir.display());
            let opts = LoadOptions {
                downscale: 2,
                train_views: Some(vec![22, 25, 28]),
                ..LoadOptions::default()
            };
            let ds = load_dataset(&dir, &opts)
                .with_context(|| format!("cannot load {}", dir.display()))?;
            Ok(Some(fewview_surface::bench::train_step_bench(
                &ds,
                args.surface_steps.max(1),
                1,
            )?))
        }
        _ => {
            eprintln!("surface training steps: skipped (pass --dtu or set FEWVIEW_DATA)");
            Ok(None)
        }
    }
}

/// Semi-Global Matching on fern's rectified pair (1, 10), cropped to 504×378, 64 disparities.
pub(super) fn stereo_bench(
    fern: Option<PathBuf>,
    runs: usize,
) -> anyhow::Result<Option<fewview_geom::bench::StereoBench>> {
    let dir = fern
        .or_else(|| std::env::var_os("FEWVIEW_DATA").map(|d| PathBuf::from(d).join("llff/fern")));
    let Some(dir) = dir.filter(|d| d.exists()) else {
        eprintln!("stereo: skipped (pass --fern or set FEWVIEW_DATA)");
        return Ok(None);
    };
    eprintln!("stereo: fern views 1 and 10 ...");
    let ds = load_dataset(&dir, &LoadOptions::default())
        .with_context(|| format!("cannot load {}", dir.display()))?;
    let view = |i: usize| fewview_geom::stereo::pairs::StereoView::of(&ds.views[i]);
    let bench = fewview_geom::bench::stereo_bench(&view(1), &view(10), (504, 378, 64), runs)?;
    Ok(Some(bench))
}

/// XFeat, XFeat* and LighterGlue on fern images 0 and 4 (central 400×300 crops of `images_8`,
/// the pair of the parity fixtures).
pub(super) fn match_bench(
    fern: Option<PathBuf>,
    runs: usize,
) -> anyhow::Result<Option<fewview_match::bench::MatchBench>> {
    let dir = fern
        .or_else(|| std::env::var_os("FEWVIEW_DATA").map(|d| PathBuf::from(d).join("llff/fern")));
    let Some(dir) = dir.filter(|d| d.exists()) else {
        eprintln!("matching: skipped (pass --fern or set FEWVIEW_DATA)");
        return Ok(None);
    };
    let (xfeat, glue) = match (
        fewview_match::XFeat::load_default(),
        fewview_match::LighterGlue::load_default(),
    ) {
        (Ok(x), Ok(g)) => (x, g),
        (Err(e), _) | (_, Err(e)) => {
            eprintln!("matching: skipped ({e})");
            return Ok(None);
        }
    };
    eprintln!("matching: fern images 0 and 4 at 400x300 ...");
    let crop = |i: usize| -> anyhow::Result<fewview_scene::Image> {
        let path = dir.join(format!("images_8/image{i:03}.png"));
        let img = fewview_scene::Image::load(&path)?;
        Ok(img.crop(
            img.width.saturating_sub(400) / 2,
            img.height.saturating_sub(300) / 2,
            400,
            300,
        ))
    };
    let bench = fewview_match::bench::match_bench(&xfeat, &glue, &crop(0)?, &crop(4)?, runs)?;
    Ok(Some(bench))
}

/// The PoseGaussian network's training steps on `device`: the CPU preset, and on a GPU the
/// paper's preset as well.
pub(super) fn human_training_bench(
    device: fewview_splat::ComputeDevice,
    steps: usize,
) -> anyhow::Result<Vec<fewview_human::bench::TrainingBench>> {
    use fewview_human::train::Preset;
    let presets: &[Preset] = match device {
        fewview_splat::ComputeDevice::Cpu => &[Preset::Cpu],
        fewview_splat::ComputeDevice::Gpu => &[Preset::Cpu, Preset::Paper],
    };
    let opened = device.open()?;
    presets
        .iter()
        .map(|&preset| {
            eprintln!(
                "PoseGaussian training steps: {preset:?} preset on the {} ...",
                device.name()
            );
            Ok(fewview_human::bench::training_bench(
                preset, steps, &opened,
            )?)
        })
        .collect()
}
