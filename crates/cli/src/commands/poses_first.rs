//! `train --data DIR` and `fusion --data DIR` on a folder that holds only photos: the poses
//! are estimated first (as `fewview poses`) into the run's `poses/` folder, which then is the
//! dataset; a finished one is reused. Photos larger than about 1,000 px on their longer side
//! are trained at a downscale that brings them there, unless `--downscale` says otherwise.

use std::path::{Path, PathBuf};

use fewview_scene::memory::StagePeaks;
use fewview_sfm::folder::{
    WORKING_LONG_SIDE, has_model, holds_only_photos, longest_photo_side, working_downscale,
};
use fewview_sfm::photos::DEFAULT_FOV_DEG;
use fewview_sfm::{FolderOptions, poses_for_folder};

/// The folder to load as the dataset, and the downscale its photos are trained at by default.
pub struct DatasetFolder {
    pub dir: PathBuf,
    /// For a folder of photos: the factor that brings them to the working size.
    pub working_downscale: Option<u32>,
    /// The peak memory of the poses step, when it ran now.
    pub memory: StagePeaks,
}

/// The folder to load as the dataset: `data` itself, or `run/poses` when `data` holds only
/// photos (estimated now, or by an earlier invocation of the same run).
pub fn dataset_folder(data: &Path, run: &Path) -> anyhow::Result<DatasetFolder> {
    if !holds_only_photos(data) {
        return Ok(DatasetFolder {
            dir: data.to_path_buf(),
            working_downscale: None,
            memory: StagePeaks::default(),
        });
    }
    super::poses::warn_other_files(data)?;
    let working_downscale = Some(working_downscale(longest_photo_side(data)?));
    let dir = run.join("poses");
    if has_model(&dir) {
        eprintln!(
            "{} holds only photos: using the poses estimated earlier in {}",
            data.display(),
            dir.display()
        );
        return Ok(DatasetFolder {
            dir,
            working_downscale,
            memory: StagePeaks::default(),
        });
    }
    eprintln!(
        "{} holds only photos: estimating their poses first into {} (as `fewview poses`)",
        data.display(),
        dir.display()
    );
    let mut memory = StagePeaks::default();
    let model = memory.measure("poses", || {
        super::poses::with_progress(|on| {
            poses_for_folder(data, &dir, &FolderOptions::default(), on)
        })
    })?;
    super::poses::print_model(&model, DEFAULT_FOV_DEG);
    Ok(DatasetFolder {
        dir,
        working_downscale,
        memory,
    })
}

/// The downscale to load with: the one given, else the photos' working size (said in a line),
/// else 1.
pub fn chosen_downscale(given: Option<u32>, folder: &DatasetFolder, data: &Path) -> u32 {
    match (given, folder.working_downscale) {
        (Some(k), _) => k,
        (None, Some(k)) if k > 1 => {
            eprintln!(
                "working size: the photos of {} are trained at 1/{k} of their size (about \
                 {WORKING_LONG_SIDE} px on the longer side); --downscale 1 trains at full size",
                data.display()
            );
            k
        }
        _ => 1,
    }
}

/// Writes the run's stage peaks (`before` the run's own, then `after`) into `run/metrics.json`
/// under `memory` and prints them in one line.
pub fn record_memory(
    run: &Path,
    before: &StagePeaks,
    summary: &StagePeaks,
    after: &StagePeaks,
) -> anyhow::Result<()> {
    let all = StagePeaks(
        before
            .0
            .iter()
            .chain(&summary.0)
            .chain(&after.0)
            .cloned()
            .collect(),
    );
    fewview_fusion::leave_one_out::add_to_json(&run.join("metrics.json"), "memory", &all)?;
    let stages: Vec<String> = all
        .0
        .iter()
        .map(|(name, mib)| format!("{name} {:.2} GB", mib / 1024.0))
        .collect();
    println!("peak memory      {}", stages.join(", "));
    Ok(())
}
