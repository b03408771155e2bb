//! `fewview bench`: speed and memory figures, each beside a reference measured in the same run.

mod args;
mod report;
mod sections;
mod table;

use anyhow::Context;
use fewview_scene::synthetic::{DemoOptions, demo_dataset};

pub use self::args::Args;
use self::args::Section;
use self::report::{Machine, Report, peak_memory_mib};
use self::sections::{
    fern_train_bench, human_training_bench, match_bench, stereo_bench, surface_train_bench,
    write_scene,
};
use self::table::print_table;
use super::output_paths::check_folder;

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
        raster_kernels: format!("{:?}", fewview_splat::raster::kernels::KernelBuild::best()),
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
            Some(fewview_geom::bench::blend_1024().context("the Poisson blend benchmark")?)
        }
        false => None,
    };
    let stereo = match args.wants(Section::Stereo) {
        true => stereo_bench(args.fern.clone(), args.runs)?,
        false => None,
    };
    let mut human_inference = Vec::new();
    if args.wants(Section::Human) && on_cpu {
        for (preset, frames) in [
            (fewview_human::train::Preset::Cpu, args.human_frames),
            (fewview_human::train::Preset::Paper, 1),
        ] {
            eprintln!("PoseGaussian inference: {preset:?} preset ...");
            human_inference.push(fewview_human::bench::inference_bench(preset, frames)?);
        }
    }
    let human_training = match args.wants(Section::Human) {
        true => human_training_bench(device, args.human_frames)?,
        false => Vec::new(),
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
