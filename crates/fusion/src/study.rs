//! From finished fusion runs to a pairwise user study: each run's transition video becomes one
//! method of the study, as the fusion paper's user study (B) compares its alternatives on the same
//! camera path (supplement §5: 8-second, 20 fps clips, two questions).

use std::path::{Path, PathBuf};

use fewview_splat::pipeline::{ResolvedConfig, RunData};

use crate::error::FusionError;

/// What a study over runs shows: one scene, one video per method.
#[derive(Clone, Debug, PartialEq)]
pub struct StudyPlan {
    /// The dataset's name.
    pub scene: String,
    /// `(method, video)`: the method is the run folder's name.
    pub videos: Vec<(String, PathBuf)>,
}

fn run_data(dir: &Path) -> Result<RunData, FusionError> {
    let path = dir.join("config.json");
    let bytes = std::fs::read(&path).map_err(|e| {
        FusionError::Invalid(format!("{}: {e} (not a run directory?)", path.display()))
    })?;
    let config: ResolvedConfig = serde_json::from_slice(&bytes)
        .map_err(|e| FusionError::Invalid(format!("{}: {e}", path.display())))?;
    Ok(config.data)
}

/// Checks that `runs` (at least two) are finished runs of the same dataset, training views and
/// image size, each with its `transition.mp4` and a distinct folder name, and lists their videos.
pub fn plan_study(runs: &[PathBuf]) -> Result<StudyPlan, FusionError> {
    if runs.len() < 2 {
        return Err(FusionError::Invalid(format!(
            "a pairwise study needs at least two runs, got {}",
            runs.len()
        )));
    }
    let first = run_data(&runs[0])?;
    for dir in runs {
        if let Some(difference) = first.difference(&run_data(dir)?) {
            return Err(FusionError::Invalid(format!(
                "{} and {} are runs of different data: {difference}",
                runs[0].display(),
                dir.display()
            )));
        }
    }
    let mut videos: Vec<(String, PathBuf)> = Vec::new();
    for dir in runs {
        let video = dir.join("transition.mp4");
        if !video.is_file() {
            return Err(FusionError::Invalid(format!(
                "{}: missing (run `fewview fusion` without --no-transition)",
                video.display()
            )));
        }
        let method = dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| dir.display().to_string());
        if videos.iter().any(|(m, _)| *m == method) {
            return Err(FusionError::Invalid(format!(
                "two runs are both named `{method}`: the folder name is the method's name in the study"
            )));
        }
        videos.push((method, video));
    }
    Ok(StudyPlan {
        scene: first.dataset,
        videos,
    })
}
