//! `fewview bench`: speed and memory figures, each beside a reference measured in the same run.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args as ClapArgs;
use fewview_scene::load::{LoadOptions, load_dataset};
use fewview_scene::synthetic::{DemoOptions, demo_dataset};
use serde::Serialize;

use fewview_splat::pipeline::MAX_INIT_POINTS;

use super::number_args::{count_in, positive_count};
use super::output_paths::check_folder;

/// Measure speed and memory, beside references measured in the same run.
///
/// Measures the rasterizer (forward and backward splat–pixel pairs per CPU-second at 100k
/// Gaussians and 504×378, beside a plain single-threaded blend loop), training iterations per
/// second (the demo scene, and LLFF fern 3-view when the data is available), surface training
/// iterations per second on DTU scan65 3-view (hash grid, beside the NeuS MLP; with the poses
/// refined and with them held, as the CPU schedule holds them), the SSIM loss,
/// the occlusion-aware Poisson blend at 1024², Semi-Global Matching on fern's rectified pair
/// (1, 10) cropped to 504×378 with 64 disparities (beside the same on one thread; the whole
/// stereo pair at its own size too), PoseGaussian inference per frame for both presets (by
/// stage, beside a matrix product's multiply-add rate), and peak memory. Prints a table and writes JSON.
///
/// Throughput is reported per CPU-second (CPU time summed over threads), which does not change
/// much when other programs load the machine; wall-clock seconds are reported too. The
/// rasterizer's per-core figures run on one thread (like the plain loop they are compared
/// with); its all-threads figures are printed beside them.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// Where to write the JSON report.
    #[arg(long, default_value = "runs/bench.json", value_name = "FILE")]
    pub json: PathBuf,
    /// LLFF fern folder for the training-step figure (default: `$FEWVIEW_DATA/llff/fern`).
    #[arg(long, value_name = "DIR")]
    pub fern: Option<PathBuf>,
    /// Gaussians in the rasterizer benchmark (1 to 10,000,000, the `--init-points` limit).
    #[arg(long, default_value_t = 100_000, value_parser = gaussian_count)]
    pub gaussians: usize,
    /// Training steps timed per dataset (at least 1).
    #[arg(long, default_value_t = 20, value_parser = positive_count)]
    pub train_steps: usize,
    /// DTU scan65 folder for the surface training-step figure (default:
    /// `$FEWVIEW_DATA/dtu/scan65`; views 22, 25, 28 at 400×300).
    #[arg(long, value_name = "DIR")]
    pub dtu: Option<PathBuf>,
    /// Surface training steps timed (the NeuS-MLP reference runs one).
    #[arg(long, default_value_t = 10)]
    pub surface_steps: usize,
    /// Frames timed for PoseGaussian inference with the CPU preset (the paper preset times one).
    #[arg(long, default_value_t = 3, value_parser = positive_count)]
    pub human_frames: usize,
    /// Repetitions of each rasterizer measurement (median reported; at least 1).
    #[arg(long, default_value_t = 5, value_parser = positive_count)]
    pub runs: usize,
    /// Where the rasterizer and training steps run: `cpu`, or `gpu` (builds with `--features
    /// gpu`; the rasterizer's CPU figures are then measured on the same scene as the yardstick).
    #[arg(long, value_enum, default_value_t)]
    pub device: fewview_splat::ComputeDevice,
    /// Image size of the rasterizer benchmark, `WIDTHxHEIGHT`.
    #[arg(long, default_value = "504x378", value_parser = parse_size, value_name = "WxH")]
    pub raster_size: (usize, usize),
    /// Also write the rasterizer benchmark's scene as `DIR/scene.ply` and `DIR/cameras.json`
    /// (for timing other rasterizers on the same Gaussians).
    #[arg(long, value_name = "DIR")]
    pub write_scene: Option<PathBuf>,
    /// Measure only these sections, e.g. `--only human,ssim` (default: all).
    #[arg(long, value_enum, value_delimiter = ',', value_name = "SECTION")]
    pub only: Vec<Section>,
}

/// A part of the benchmark that `--only` can pick.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Section {
    /// The rasterizer's forward and backward passes.
    Raster,
    /// Training steps on the demo scene and LLFF fern.
    Train,
    /// Demo training steps with the gradient-domain fusion term.
    Fusion,
    /// Demo training steps with a per-photo affine colour transform.
    Appearance,
    /// Surface training steps on DTU scan65.
    Surface,
    /// The SSIM loss.
    Ssim,
    /// The Poisson blend.
    Blend,
    /// Semi-Global Matching.
    Stereo,
    /// PoseGaussian inference per frame, both presets.
    Human,
    /// The learned matchers (XFeat, XFeat*, LighterGlue) on a 400×300 fern pair.
    Match,
}

impl Args {
    fn wants(&self, section: Section) -> bool {
        self.only.is_empty() || self.only.contains(&section)
    }
}

/// `--raster-size`: `WIDTHxHEIGHT`, each 1 to 16384.
fn parse_size(s: &str) -> Result<(usize, usize), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("`{s}`: expected WIDTHxHEIGHT, e.g. 1024x1024"))?;
    Ok((count_in(w, 1, 16384)?, count_in(h, 1, 16384)?))
}

/// `--gaussians`: at least one, and no more than training may start from
/// ([`MAX_INIT_POINTS`], about 1 KB each): 10¹² aborted on allocation.
fn gaussian_count(s: &str) -> Result<usize, String> {
    count_in(s, 1, MAX_INIT_POINTS)
}

/// The figures measured; a section left out by `--only` (or lacking its data) is absent.
#[derive(Serialize)]
struct Report {
    machine: Machine,
    #[serde(skip_serializing_if = "Option::is_none")]
    raster: Option<fewview_splat::bench::RasterBench>,
    #[cfg(feature = "gpu")]
    #[serde(skip_serializing_if = "Option::is_none")]
    raster_gpu: Option<fewview_splat::bench_gpu::GpuRasterBench>,
    #[serde(skip_serializing_if = "Option::is_none")]
    train_demo: Option<fewview_splat::bench::TrainStepBench>,
    /// Demo training steps with the gradient-domain fusion term on every step.
    #[serde(skip_serializing_if = "Option::is_none")]
    fusion_demo: Option<fewview_fusion::bench::FusionStepBench>,
    /// Demo training steps with a per-photo affine colour transform.
    #[serde(skip_serializing_if = "Option::is_none")]
    appearance_demo: Option<fewview_splat::bench::AppearanceStepBench>,
    #[serde(skip_serializing_if = "Option::is_none")]
    train_fern: Option<fewview_splat::bench::TrainStepBench>,
    #[serde(skip_serializing_if = "Option::is_none")]
    train_surface: Option<fewview_surface::bench::SurfaceStepBench>,
    #[serde(skip_serializing_if = "Option::is_none")]
    ssim: Option<fewview_metrics::bench::SsimBench>,
    #[serde(skip_serializing_if = "Option::is_none")]
    blend: Option<fewview_geom::bench::BlendBench>,
    #[serde(skip_serializing_if = "Option::is_none")]
    stereo: Option<fewview_geom::bench::StereoBench>,
    /// PoseGaussian inference per frame, both presets (synthetic frame, random weights).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    human_inference: Vec<fewview_human::bench::InferenceBench>,
    /// PoseGaussian training steps (the network's forward and backward), CPU preset.
    #[serde(skip_serializing_if = "Option::is_none")]
    human_training: Option<fewview_human::bench::TrainingBench>,
    /// The learned matchers on one 400×300 pair (fern images 0 and 4, central crops).
    #[serde(skip_serializing_if = "Option::is_none")]
    matching: Option<fewview_match::bench::MatchBench>,
    peak_memory_mib: Option<f64>,
}

#[derive(Serialize)]
struct Machine {
    threads: usize,
    avx2_fma: bool,
}

/// Peak resident memory of this process (VmHWM), in MiB.
fn peak_memory_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

pub fn run(args: Args) -> anyhow::Result<()> {
    // The report's folder is created at the end; a path that cannot be written is refused
    // before the minutes of measuring.
    if args.json.is_dir() {
        anyhow::bail!(
            "--json {}: is a folder, expected a file name",
            args.json.display()
        );
    }
    if let Some(parent) = args.json.parent() {
        check_folder(parent, "--json")?;
    }
    let avx2_fma = fewview_scene::cpu::avx2_fma();
    let machine = Machine {
        threads: rayon::current_num_threads(),
        avx2_fma,
    };
    let device = args.device;
    let (width, height) = args.raster_size;
    if let Some(dir) = &args.write_scene {
        write_scene(dir, args.gaussians, width, height)?;
    }
    let on_cpu = device == fewview_splat::ComputeDevice::Cpu;
    let raster = (on_cpu && args.wants(Section::Raster)).then(|| {
        eprintln!(
            "rasterizer: {} Gaussians at {width}x{height} ...",
            args.gaussians
        );
        fewview_splat::bench::raster_bench(args.gaussians, width, height, args.runs.max(1))
    });
    #[cfg(feature = "gpu")]
    let raster_gpu = match !on_cpu && args.wants(Section::Raster) {
        true => {
            eprintln!(
                "rasterizer on the GPU: {} Gaussians at {width}x{height} ...",
                args.gaussians
            );
            let scene = fewview_splat::bench::SyntheticScene::new(args.gaussians, width, height, 1);
            let gpu = device.open()?;
            Some(
                fewview_splat::bench_gpu::gpu_raster_bench(&gpu, &scene, args.runs)
                    .map_err(anyhow::Error::msg)?,
            )
        }
        false => None,
    };
    let demo = (args.wants(Section::Train)
        || args.wants(Section::Fusion)
        || args.wants(Section::Appearance))
    .then(|| demo_dataset(&DemoOptions::default()));
    let train_demo = match (&demo, args.wants(Section::Train)) {
        (Some(demo), true) => {
            eprintln!("training steps: demo scene ...");
            Some(fewview_splat::bench::train_step_bench(
                demo,
                args.train_steps,
                device,
            )?)
        }
        _ => None,
    };
    let fusion_demo = match (&demo, args.wants(Section::Fusion)) {
        (Some(demo), true) => {
            eprintln!("training steps with the fusion term: demo scene ...");
            Some(fewview_fusion::bench::fusion_step_bench(
                demo,
                args.train_steps,
            )?)
        }
        _ => None,
    };
    let appearance_demo = match (&demo, args.wants(Section::Appearance)) {
        (Some(demo), true) => {
            eprintln!("training steps with a per-photo colour transform: demo scene ...");
            Some(fewview_splat::bench::appearance_step_bench(
                demo,
                args.train_steps,
            )?)
        }
        _ => None,
    };
    let train_fern = match args.wants(Section::Train) {
        true => fern_train_bench(&args)?,
        false => None,
    };
    let train_surface = match args.wants(Section::Surface) {
        true => surface_train_bench(&args)?,
        false => None,
    };
    let ssim = args.wants(Section::Ssim).then(|| {
        eprintln!("SSIM loss ...");
        fewview_metrics::bench::ssim_bench(504, 378, 10)
    });
    let blend = match args.wants(Section::Blend) {
        true => {
            eprintln!("Poisson blend 1024x1024x3 ...");
            fewview_geom::bench::blend_1024().ok()
        }
        false => None,
    };
    let stereo = match args.wants(Section::Stereo) {
        true => stereo_bench(args.fern.clone(), args.runs)?,
        false => None,
    };
    let mut human_inference = Vec::new();
    if args.wants(Section::Human) {
        for (preset, frames) in [
            (fewview_human::train::Preset::Cpu, args.human_frames),
            (fewview_human::train::Preset::Paper, 1),
        ] {
            eprintln!("PoseGaussian inference: {preset:?} preset ...");
            human_inference.push(fewview_human::bench::inference_bench(preset, frames)?);
        }
    }
    let human_training = match args.wants(Section::Human) {
        true => {
            eprintln!("PoseGaussian training steps: Cpu preset ...");
            let preset = fewview_human::train::Preset::Cpu;
            Some(fewview_human::bench::training_bench(
                preset,
                args.human_frames,
            )?)
        }
        false => None,
    };
    let matching = match args.wants(Section::Match) {
        true => match_bench(args.fern.clone(), args.runs)?,
        false => None,
    };
    let report = Report {
        machine,
        raster,
        #[cfg(feature = "gpu")]
        raster_gpu,
        train_demo,
        fusion_demo,
        appearance_demo,
        train_fern,
        train_surface,
        ssim,
        blend,
        stereo,
        human_inference,
        human_training,
        matching,
        peak_memory_mib: peak_memory_mib(),
    };
    print_table(&report);
    if let Some(parent) = args.json.parent() {
        std::fs::create_dir_all(parent)?;
    }
    fewview_scene::atomic::write_bytes(&args.json, &serde_json::to_vec_pretty(&report)?)?;
    println!("\nJSON report: {}", args.json.display());
    Ok(())
}

/// Writes the rasterizer benchmark's scene as a 3DGS PLY and its camera as JSON.
fn write_scene(dir: &std::path::Path, n: usize, width: usize, height: usize) -> anyhow::Result<()> {
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
fn fern_train_bench(args: &Args) -> anyhow::Result<Option<fewview_splat::bench::TrainStepBench>> {
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
fn surface_train_bench(
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
fn stereo_bench(
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
fn match_bench(
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

fn print_table(r: &Report) {
    println!("{:<46} {:>14} {:>14}", "figure", "value", "reference");
    if let Some(m) = &r.matching {
        let pair = format!("{}x{} pair", m.width, m.height);
        let rows = [
            ("XFeat detect, one image s", m.detect_seconds, String::new()),
            (
                "XFeat + MNN, pair s",
                m.pair_mnn_seconds,
                format!("{} matches", m.mnn_matches),
            ),
            (
                "XFeat + LighterGlue, pair s",
                m.pair_lighterglue_seconds,
                format!("{} matches", m.lighterglue_matches),
            ),
            (
                "XFeat*, pair s",
                m.pair_star_seconds,
                format!("{} matches", m.star_matches),
            ),
        ];
        for (name, seconds, note) in rows {
            println!(
                "{:<46} {:>14.3} {:>14}",
                format!("{name} ({pair})"),
                seconds,
                note
            );
        }
    }
    if let Some(t) = &r.human_training {
        println!(
            "{:<46} {:>14.3} {:>14}",
            format!(
                "PoseGaussian {} training s/step ({}x{})",
                t.preset, t.size[0], t.size[1]
            ),
            t.seconds_per_step,
            format!("fwd {:.3}", t.forward_seconds)
        );
        println!(
            "{:<46} {:>14.2} {:>14.2}",
            "  training GMAC/s vs 1024³ matmul", t.network_gmacs_per_s, t.matmul_gmacs_per_s
        );
    }
    for h in &r.human_inference {
        println!(
            "{:<46} {:>14.3} {:>14}",
            format!(
                "PoseGaussian {} s/frame ({}x{}, 2 sources)",
                h.preset, h.size[0], h.size[1]
            ),
            h.seconds_per_frame,
            ""
        );
        println!(
            "{:<46} {:>14}",
            "  image / pose / depth enc, decoder, TPS, render",
            format!(
                "{:.3} / {:.3} / {:.3} / {:.3} / {:.3} / {:.3}",
                h.image_encoder,
                h.pose_encoder,
                h.depth_encoder,
                h.decoder_and_heads,
                h.tps,
                h.rendering
            )
        );
        println!(
            "{:<46} {:>14.2} {:>14.2}",
            "  network GMAC/s vs 1024³ matmul", h.network_gmacs_per_s, h.matmul_gmacs_per_s
        );
    }
    if let Some(rb) = &r.raster {
        print_raster(rb);
    }
    print_training(r);
    if let Some(s) = &r.ssim {
        println!(
            "{:<46} {:>14.2} {:>14.2}",
            "SSIM value+grad ms 504x378 (vs PSNR)", s.value_grad_ms, s.psnr_ms
        );
    }
    print_blend_and_stereo(r);
    if let Some(m) = r.peak_memory_mib {
        println!("{:<46} {:>14.0} {:>14}", "peak memory MiB", m, "");
    }
}

fn print_raster(rb: &fewview_splat::bench::RasterBench) {
    let g = |v: f64| format!("{:.3e}", v);
    println!(
        "{:<46} {:>14} {:>14}",
        format!(
            "raster fwd pairs/s/core ({}k, {}x{}, 1 thread)",
            rb.gaussians / 1000,
            rb.width,
            rb.height
        ),
        g(rb.forward_pairs_per_sec_per_core),
        g(rb.reference_pairs_per_sec)
    );
    println!(
        "{:<46} {:>14} {:>14}",
        "raster bwd pairs/s/core (1 thread)",
        g(rb.backward_pairs_per_sec_per_core),
        ""
    );
    println!(
        "{:<46} {:>14} {:>14}",
        format!("  fwd / bwd per CPU-s, {} threads", rb.threads),
        g(rb.forward_pairs_per_cpu_sec_all_threads),
        g(rb.backward_pairs_per_cpu_sec_all_threads)
    );
    println!(
        "{:<46} {:>14.1} {:>14}",
        format!("raster fwd ms (wall, {} threads)", rb.threads),
        rb.forward_seconds * 1e3,
        ""
    );
    println!(
        "{:<46} {:>14.1} {:>14}",
        format!("raster bwd ms (wall, {} threads)", rb.threads),
        rb.backward_seconds * 1e3,
        ""
    );
    println!(
        "{:<46} {:>14.2} {:>14}",
        "raster fwd speed-up vs plain loop (per core)", rb.forward_vs_reference, "1"
    );
}

fn print_training(r: &Report) {
    for t in [r.train_demo.as_ref(), r.train_fern.as_ref()]
        .into_iter()
        .flatten()
    {
        println!(
            "{:<46} {:>14.2} {:>14}",
            format!(
                "train it/s {} {}x{} ({} G)",
                t.dataset, t.width, t.height, t.gaussians
            ),
            t.iterations_per_second,
            ""
        );
        println!(
            "{:<46} {:>14.2} {:>14}",
            "  it per CPU-second", t.iterations_per_cpu_second, ""
        );
    }
    if let Some(f) = &r.fusion_demo {
        println!(
            "{:<46} {:>14.2} {:>14.2}",
            "demo it/s with fusion term (vs without)",
            f.fusion.iterations_per_second,
            f.plain.iterations_per_second
        );
        println!(
            "{:<46} {:>14.2} {:>14}",
            "  fusion term's share of a step", f.term_share, ""
        );
    }
    if let Some(a) = &r.appearance_demo {
        println!(
            "{:<46} {:>14.2} {:>14.2}",
            "demo it/CPU-s with colour transforms (vs without)",
            a.affine.iterations_per_cpu_second,
            a.plain.iterations_per_cpu_second
        );
        println!(
            "{:<46} {:>14.3} {:>14}",
            "  transforms' cost per step (fraction, CPU time)", a.overhead, ""
        );
    }
    if let Some(s) = &r.train_surface {
        println!(
            "{:<46} {:>14.3} {:>14.4}",
            format!(
                "surface it/s {} {}x{} (vs NeuS MLP)",
                s.dataset, s.width, s.height
            ),
            s.hash_grid.iterations_per_second,
            s.reference_neus_mlp.iterations_per_second
        );
        println!(
            "{:<46} {:>14.3} {:>14.4}",
            "  it per CPU-second",
            s.hash_grid.iterations_per_cpu_second,
            s.reference_neus_mlp.iterations_per_cpu_second
        );
        println!(
            "{:<46} {:>14.3} {:>14.3}",
            "  it per CPU-second, poses held (vs refined)",
            s.hash_grid_poses_held.iterations_per_cpu_second,
            s.hash_grid.iterations_per_cpu_second
        );
    }
}

fn print_blend_and_stereo(r: &Report) {
    let g = |v: f64| format!("{:.3e}", v);
    if let Some(b) = &r.blend {
        println!(
            "{:<46} {:>14.2} {:>14.2}",
            "Poisson blend 1024^2x3 s (vs direct, half size)", b.seconds, b.reference_seconds
        );
        if let Some(c) = b.cpu_seconds {
            println!("{:<46} {:>14.2} {:>14}", "  CPU seconds", c, "");
        }
    }
    if let Some(b) = &r.stereo {
        println!(
            "{:<46} {:>14} {:>14}",
            format!(
                "SGM pix·disp/CPU-s ({}x{}, {} d, vs 1 thread)",
                b.width, b.height, b.disparities
            ),
            g(b.pixel_disparities_per_cpu_second),
            g((b.width * b.height * b.disparities) as f64 / b.one_thread_seconds)
        );
        println!(
            "{:<46} {:>14.3} {:>14.3}",
            "  SGM s: 5 paths (vs 1 thread)", b.opencv_mode_seconds, b.one_thread_seconds
        );
        println!(
            "{:<46} {:>14.3} {:>14}",
            "  SGM s: 8 paths, partial border", b.default_seconds, ""
        );
        println!(
            "{:<46} {:>14.3} {:>14}",
            format!(
                "  stereo pair s ({}x{}, {} d, both ways, refined)",
                b.pair_width, b.pair_height, b.pair_disparities
            ),
            b.pair_seconds,
            ""
        );
    }
}
