//! `--init surface` without a folder (`train`, `fusion`): the surface method runs first, on the
//! same dataset and views, into the run's `surface/` folder, and the Gaussians start from its
//! mesh. The surface run starts from the input's own poses (`--initial-poses loaded`) and
//! refines them; a finished one is reused and an interrupted one resumed.

use std::path::{Path, PathBuf};

use clap::Parser;

/// The dataset flags the surface run repeats.
pub struct SurfaceFirst {
    pub data: PathBuf,
    pub downscale: u32,
    pub train_views: Option<Vec<usize>>,
    pub test_views: Option<Vec<usize>>,
    pub n_train: Option<usize>,
    pub object_only: bool,
    pub seed: u64,
}

/// Whether `--init` asks for a surface run made here.
pub fn wanted(init: &str) -> bool {
    init == "surface"
}

/// The `--init` value that starts from the surface run made for the run in `out`.
fn init_for(out: &Path) -> String {
    format!("surface:{}", out.join("surface").display())
}

/// Runs (or reuses, or resumes) the surface method into `out/surface`.
fn run(first: &SurfaceFirst, out: &Path) -> anyhow::Result<()> {
    let dir = out.join("surface");
    if dir.join("mesh.ply").is_file() && dir.join("metrics.json").is_file() {
        eprintln!(
            "--init surface: reusing the finished surface run in {}",
            dir.display()
        );
        return Ok(());
    }
    let list = |v: &[usize]| v.iter().map(usize::to_string).collect::<Vec<_>>().join(",");
    let mut argv: Vec<String> = ["fewview surface", "--initial-poses", "loaded"]
        .map(String::from)
        .to_vec();
    argv.extend(["--data".into(), first.data.display().to_string()]);
    argv.extend(["--downscale".into(), first.downscale.to_string()]);
    argv.extend(["--seed".into(), first.seed.to_string()]);
    argv.extend(["--out".into(), dir.display().to_string()]);
    if let Some(v) = &first.train_views {
        argv.extend(["--train-views".into(), list(v)]);
    }
    if let Some(v) = &first.test_views {
        argv.extend(["--test-views".into(), list(v)]);
    }
    if let Some(n) = first.n_train {
        argv.extend(["--n-train".into(), n.to_string()]);
    }
    if first.object_only {
        argv.push("--object-only".into());
    }
    if fewview_surface::pipeline::checkpoint_path(&dir).is_file() {
        argv.push("--resume".into());
    }
    eprintln!(
        "--init surface: running the surface method first into {} (`{}`)",
        dir.display(),
        argv[1..].join(" ")
    );
    super::surface::run(SurfaceCommand::try_parse_from(&argv)?.args)
}

/// `fewview surface`'s flags as a command line of their own.
#[derive(Parser)]
struct SurfaceCommand {
    #[command(flatten)]
    args: super::surface::Args,
}

/// Replaces a bare `--init surface` in `init` by the `surface:DIR` of the run in `out`, so that
/// the other flags are checked before the surface method's minutes; whether it was bare.
pub fn take(init: &mut String, out: &Path) -> bool {
    let bare = wanted(init);
    if bare {
        *init = init_for(out);
    }
    bare
}

/// After [`take`]: runs the surface method when `bare`, and returns the pose choice to adopt.
pub fn run_if(
    bare: bool,
    first: impl FnOnce() -> anyhow::Result<SurfaceFirst>,
    out: &Path,
    choice: fewview_splat::surface_start::SurfacePoses,
) -> anyhow::Result<fewview_splat::surface_start::SurfacePoses> {
    if !bare {
        return Ok(choice);
    }
    run(&first()?, out)?;
    Ok(poses(choice))
}

/// `--surface-poses auto` for a surface run made here: it refined the input's own poses, so its
/// refined ones are the better guess.
fn poses(
    choice: fewview_splat::surface_start::SurfacePoses,
) -> fewview_splat::surface_start::SurfacePoses {
    use fewview_splat::surface_start::SurfacePoses;
    match choice {
        SurfacePoses::Auto => SurfacePoses::Refined,
        other => other,
    }
}
