//! Flags shared by the commands that read a dataset.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use fewview_scene::distortion::Resample;
use fewview_scene::load::LoadOptions;
use fewview_scene::split::parse_view_list;
use fewview_scene::{Dataset, DatasetFormat, UndistortMode, load_dataset_with_report};

/// A list of view indices (one flag value, so clap does not treat it as repeated values).
#[derive(Debug, Clone, PartialEq)]
pub struct ViewList(pub Vec<usize>);

pub fn parse_views(s: &str) -> Result<ViewList, String> {
    parse_view_list(s).map(ViewList)
}

/// Which dataset and which views.
#[derive(Debug, Clone, Args)]
pub struct DatasetArgs {
    /// Dataset folder (LLFF, NeRF-synthetic, DTU, COLMAP, …).
    ///
    /// Dataset folder: LLFF (`poses_bounds.npy` + `images_N/`), NeRF-synthetic
    /// (`transforms_train.json`), nerfstudio (`transforms.json`), IDR/NeuS DTU
    /// (`cameras_sphere.npz` + `image/` + `mask/`) or COLMAP (`sparse/0` + `images/`).
    /// Required (an `Option` only so that `surface --synthetic` can go without it).
    #[arg(long, value_name = "DIR", required = true)]
    pub data: Option<PathBuf>,
    /// Force the format instead of detecting it.
    ///
    /// One of llff, blender, nerfstudio, dtu, colmap.
    #[arg(long, value_name = "NAME")]
    pub format: Option<DatasetFormat>,
    /// Downscale images by this integer factor on load (intrinsics follow).
    ///
    /// Downscale images by this integer factor on load (intrinsics follow). Default 1; for a
    /// folder of photos (`train`, `fusion`), the factor that brings them to about 1,000 px on
    /// their longer side.
    #[arg(long, value_name = "K")]
    pub downscale: Option<u32>,
    /// Training views of the format's sparse split.
    ///
    /// Number of training views of the format's standard sparse split (LLFF 3, NeRF-synthetic 8,
    /// DTU 3 by default).
    #[arg(long, value_name = "N")]
    pub n_train: Option<usize>,
    /// Explicit training views, e.g. `22,25,28` (indices in the dataset's view order).
    #[arg(long, value_name = "LIST", value_parser = parse_views)]
    pub train_views: Option<ViewList>,
    /// Explicit held-out views, e.g. `0,8,16`.
    #[arg(long, value_name = "LIST", value_parser = parse_views)]
    pub test_views: Option<ViewList>,
    /// DTU: camera file inside the scene folder (e.g. `cameras_linear_init.npz`).
    #[arg(long, value_name = "FILE")]
    pub cameras_file: Option<String>,
    /// Lens distortion: no-border, all-pixels or ignore.
    ///
    /// COLMAP / nerfstudio lens distortion: `no-border` undistorts each photo into a pinhole
    /// with no blank border (COLMAP image_undistorter's default), `all-pixels` keeps every photo
    /// pixel and masks the blank border out of losses and metrics, `ignore` uses the photos as
    /// if taken by a pinhole (a baseline). Undistorted photos are cached in the dataset's
    /// `.fewview-cache/undistorted/`.
    #[arg(long, default_value = "no-border", value_name = "MODE")]
    pub undistort: UndistortMode,
    /// Resampling kernel of the undistortion.
    ///
    /// How undistortion resamples the photos: `bilinear` (what COLMAP's image_undistorter and
    /// OpenCV's cv2.undistort use) or `bicubic` (Keys' kernel with a = -0.75, as OpenCV's
    /// INTER_CUBIC: sharper, slight ringing at hard edges). Each kernel has its own cache entries.
    #[arg(long, default_value = "bilinear", value_name = "KERNEL")]
    pub resample: Resample,
    /// Train and score the masked object alone (DTU).
    ///
    /// Use the dataset's separate foreground masks (DTU's `mask/`) as the photos' alpha: each
    /// photo is composited over the background and training sees the object alone, as IDR/NeuS
    /// and the surface method train on DTU; scores are then the object's.
    #[arg(long)]
    pub object_only: bool,
}

impl DatasetArgs {
    pub fn load_options(&self) -> LoadOptions {
        LoadOptions {
            format: self.format,
            downscale: self.downscale.unwrap_or(1),
            n_train: self.n_train,
            train_views: self.train_views.clone().map(|v| v.0),
            test_views: self.test_views.clone().map(|v| v.0),
            cameras_file: self.cameras_file.clone(),
            undistort: self.undistort,
            resample: self.resample,
            ..LoadOptions::default()
        }
    }

    /// The `--data` folder.
    pub fn folder(&self) -> anyhow::Result<&Path> {
        self.data
            .as_deref()
            .ok_or_else(|| anyhow::anyhow!("give --data DIR"))
    }

    pub fn load(&self) -> anyhow::Result<Dataset> {
        let folder = self.folder()?;
        let (mut ds, report) = load_dataset_with_report(folder, &self.load_options())
            .with_context(|| format!("cannot load dataset {}", folder.display()))?;
        if self.object_only {
            object_only(&mut ds, folder)?;
        }
        for w in &report.warnings {
            eprintln!("warning: {w}");
        }
        if report.undistorted > 0 {
            eprintln!(
                "undistorted {} photos ({} from the cache){}",
                report.undistorted,
                report.cache_hits,
                undistorted_cameras(&ds)
            );
        }
        Ok(ds)
    }
}

/// `--object-only`: the separate foreground masks of `ds` (read from `folder`) become its
/// photos' alpha ([`Dataset::composite_masks_as_alpha`]); an error when it has none.
pub fn object_only(ds: &mut Dataset, folder: &Path) -> anyhow::Result<()> {
    if ds.composite_masks_as_alpha() == 0 {
        anyhow::bail!(
            "--object-only: {} has no separate foreground masks to use as alpha",
            folder.display()
        );
    }
    Ok(())
}

/// The pinhole camera undistorted views share, as `fx,fy,cx,cy,w,h` (the form
/// `demo --capture-intrinsics` takes, to render a capture's exact pinhole truth), or how many
/// different ones there are.
fn undistorted_cameras(ds: &Dataset) -> String {
    let mut seen = Vec::new();
    for k in ds.views.iter().map(|v| v.camera.intrinsics) {
        if !seen.contains(&k) {
            seen.push(k);
        }
    }
    match seen.as_slice() {
        [k] => format!(
            " to the pinhole {},{},{},{},{},{}",
            k.fx, k.fy, k.cx, k.cy, k.width, k.height
        ),
        _ => format!(" to {} pinhole cameras", seen.len()),
    }
}
