//! `fewview blend`: blend two images with two validity masks (the fusion paper §4, Fig. 2 and 9).

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args as ClapArgs, ValueEnum};
use fewview_geom::blend::{
    PoissonOptions, Solver, Weights, gaussian_feather_blend, laplacian_pyramid_blend,
    occlusion_aware_poisson_with, poisson_blend,
};
use fewview_geom::io::read_npy;

use super::geom_common::{load_image, load_mask, write_json};
use super::number_args::positive;
use super::output_paths::{check_file, check_optional_file};

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum Method {
    /// Occlusion-aware Poisson blending (Eq. 3 of the fusion paper's supplement): pixels valid in
    /// one mask keep that
    /// image, the overlap follows the weighted gradients of both.
    OcclusionAware,
    /// Standard Poisson blending (Pérez et al. 2003): G's gradients inside MASK_G, F elsewhere.
    Poisson,
    /// Laplacian-pyramid blending (Burt & Adelson 1983).
    Pyramid,
    /// Gaussian feathering of the two masks.
    Feather,
}

/// Blend two images F and G with their validity masks.
///
/// Images are PNG/JPEG (alpha dropped) of equal size; masks are images whose first channel is
/// valid above 0.5. Pixels valid in neither mask come out black.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// First image (f*).
    #[arg(long)]
    pub f: PathBuf,
    /// Second image (g*).
    #[arg(long)]
    pub g: PathBuf,
    /// Where F is valid (Ω_f*).
    #[arg(long)]
    pub mask_f: PathBuf,
    /// Where G is valid (Ω_g*).
    ///
    /// For `--method poisson`, the region G is pasted into.
    #[arg(long)]
    pub mask_g: PathBuf,
    /// Output PNG (the name must end in `.png`).
    #[arg(long, short)]
    pub out: PathBuf,
    #[arg(long, value_enum, default_value = "occlusion-aware")]
    pub method: Method,
    /// Weight of F in the overlap.
    ///
    /// Weight of F's gradients (or colour) in the overlap; G gets 1 − weight.
    #[arg(long, default_value_t = 0.5)]
    pub weight: f32,
    /// Per-pixel weights of F (float32 .npy).
    ///
    /// Per-pixel weights of F instead of --weight: a float32 .npy of shape H×W in [0, 1].
    #[arg(long)]
    pub weights_npy: Option<PathBuf>,
    /// Linear solver of the Poisson methods.
    #[arg(long, value_enum, default_value = "mg-cg")]
    pub solver: Solver,
    /// Relative residual at which the iterative solver stops.
    #[arg(long, default_value_t = 1e-7, value_parser = positive)]
    pub tolerance: f64,
    /// Pérez's mixed gradients (Poisson).
    ///
    /// Pérez's mixed gradients (the larger of the two images' differences), `--method poisson`.
    #[arg(long)]
    pub mixed: bool,
    /// Pyramid levels, `--method pyramid`.
    #[arg(long, default_value_t = 5)]
    pub levels: usize,
    /// Gaussian σ in pixels, `--method feather`.
    #[arg(long, default_value_t = 8.0)]
    pub sigma: f32,
    /// Also write the solver figures as JSON.
    ///
    /// Also write the solver figures (unknowns, iterations, residual) as JSON.
    #[arg(long)]
    pub stats: Option<PathBuf>,
}

pub fn run(args: Args) -> Result<()> {
    // The result is always encoded as PNG: PNG bytes in a `.jpg` file mislead every reader, and
    // checking first spares the solve.
    if !args
        .out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"))
    {
        anyhow::bail!(
            "{}: the blended image is written as PNG; name the output *.png",
            args.out.display()
        );
    }
    check_file(&args.out, "--out")?;
    check_optional_file(args.stats.as_deref(), "--stats")?;
    let f = load_image(&args.f)?;
    let g = load_image(&args.g)?;
    let (mf, wf, hf) = load_mask(&args.mask_f)?;
    let (mg, wg, hg) = load_mask(&args.mask_g)?;
    for (what, (w, h)) in [(&args.mask_f, (wf, hf)), (&args.mask_g, (wg, hg))] {
        if (w, h) != (f.width, f.height) {
            anyhow::bail!(
                "{}: mask is {w}×{h} but {} is {}×{}",
                what.display(),
                args.f.display(),
                f.width,
                f.height
            );
        }
    }
    let per_pixel = match &args.weights_npy {
        Some(p) => {
            let a = read_npy(p)?;
            if a.shape != [f.height, f.width] {
                anyhow::bail!(
                    "{}: weights have shape {:?}, expected [{}, {}]",
                    p.display(),
                    a.shape,
                    f.height,
                    f.width
                );
            }
            Some(a.data)
        }
        None => None,
    };
    let weights = match &per_pixel {
        Some(w) => Weights::PerPixel(w),
        None => Weights::Constant(args.weight),
    };
    let options = PoissonOptions {
        solver: args.solver,
        tolerance: args.tolerance,
    };
    let context = || format!("blending {} and {}", args.f.display(), args.g.display());
    let (out, stats) = match args.method {
        Method::OcclusionAware => {
            let (img, s) = occlusion_aware_poisson_with(&f, &g, &mf, &mg, weights, &options)
                .with_context(context)?;
            (img, Some(s))
        }
        Method::Poisson => {
            let (img, s) =
                poisson_blend(&f, &g, &mg, args.mixed, &options).with_context(context)?;
            (img, Some(s))
        }
        Method::Pyramid => (
            laplacian_pyramid_blend(&f, &g, &mf, &mg, args.levels, weights)
                .with_context(context)?,
            None,
        ),
        Method::Feather => (
            gaussian_feather_blend(&f, &g, &mf, &mg, args.sigma, weights).with_context(context)?,
            None,
        ),
    };
    out.save_png(&args.out)
        .with_context(|| format!("writing {}", args.out.display()))?;
    let report = match stats {
        Some(s) => serde_json::json!({
            "method": format!("{:?}", args.method),
            "unknowns": s.solve.unknowns,
            "iterations": s.solve.iterations,
            "relative_residual": s.solve.relative_residual,
            "pinned_regions": s.pinned,
        }),
        None => serde_json::json!({ "method": format!("{:?}", args.method) }),
    };
    if let Some(p) = &args.stats {
        write_json(p, &report)?;
    }
    println!("{}", serde_json::to_string(&report)?);
    Ok(())
}
