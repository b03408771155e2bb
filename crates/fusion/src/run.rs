//! One fusion run: the splat training run of `fewview train` with the chosen variant's loss
//! terms added, and `fusion.json` recording the variant and what its terms did.

use std::path::Path;

use fewview_scene::Dataset;
use fewview_splat::pipeline::{RunConfig, RunSummary, train_run_with};
use fewview_splat::stereo_start::stereo_views;
use fewview_splat::train::{AppearanceModel, LossTerm, Progress};
use serde::{Deserialize, Serialize};

use crate::error::FusionError;
use crate::terms::{FusionView, KnnColorTerm, SharedStats, VirtualViewTerm};
use crate::variant::{FusionConfig, Variant};
use crate::virtual_view::{Neighbours, adjacent_pairs};

/// Fraction of the hierarchical cloud alternative (a) starts from (supplement §4: 1 %).
pub const SPARSE_INIT_FRACTION: f64 = 0.01;

/// What `fusion.json` holds.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FusionRecord {
    pub config: FusionConfig,
    /// The adjacent training-view pairs virtual views are drawn between, by name.
    pub pairs: Vec<(String, String)>,
    /// What the virtual-view term did (absent for variants without one).
    #[serde(default)]
    pub term: Option<serde_json::Value>,
}

/// The run configuration a variant trains with: alternative (a) samples 1 % of the stereo
/// start's cloud; the others keep `base`.
pub fn run_config_for(variant: Variant, base: &RunConfig) -> RunConfig {
    let mut cfg = base.clone();
    if variant == Variant::SparseInit {
        cfg.stereo.fraction = SPARSE_INIT_FRACTION;
    }
    cfg
}

/// The adjacent pairs of `ds`'s training views (indices in its training order).
pub fn training_pairs(ds: &Dataset) -> Result<Vec<Neighbours>, FusionError> {
    adjacent_pairs(&stereo_views(ds))
}

/// The variant's loss terms, and a handle on the virtual-view term's statistics.
pub fn fusion_terms(
    ds: &Dataset,
    run: &RunConfig,
    fusion: &FusionConfig,
    pairs: &[Neighbours],
) -> (Vec<Box<dyn LossTerm>>, Option<SharedStats>) {
    match fusion.variant {
        Variant::KnnColor => (vec![Box::new(KnnColorTerm::new(fusion.knn))], None),
        v if v.uses_virtual_views() => {
            let views = ds
                .train_views()
                .map(|v| FusionView {
                    camera: v.camera.clone(),
                    photo: v.image.clone(),
                })
                .collect();
            let term = VirtualViewTerm::new(fusion.clone(), views, pairs.to_vec(), &run.train);
            let stats = term.stats.clone();
            (vec![Box::new(term)], Some(stats))
        }
        _ => (Vec::new(), None),
    }
}

/// Trains `ds` with the fusion variant `fusion.variant` in `dir` (see
/// [`fewview_splat::pipeline::train_run`] for the run directory) and writes `fusion.json`.
/// Views that share nothing, and a resume under other fusion settings, are refused before
/// anything is written.
pub fn fusion_run(
    ds: &Dataset,
    base: &RunConfig,
    fusion: &FusionConfig,
    dir: &Path,
    resume: bool,
    on_progress: impl FnMut(&Progress),
) -> Result<(RunSummary, FusionRecord), FusionError> {
    fusion.validate().map_err(FusionError::Invalid)?;
    let appearance = base.train.appearance.model;
    if appearance != AppearanceModel::None && !fusion.variant.takes_appearance() {
        return Err(FusionError::Invalid(format!(
            "the appearance model `{}` does not combine with variant `{}`: its target is a blend \
             of the photos' own colours (use plain, sparse-init, knn-color, tv or gf)",
            appearance.name(),
            fusion.variant
        )));
    }
    let pairs = training_pairs(ds)?;
    let record_path = dir.join("fusion.json");
    if resume {
        check_resume(&record_path, fusion)?;
    }
    let run = run_config_for(fusion.variant, base);
    let (terms, stats) = fusion_terms(ds, &run, fusion, &pairs);
    let summary = train_run_with(ds, &run, dir, resume, terms, on_progress)?;
    let names: Vec<&str> = ds.train_views().map(|v| v.name.as_str()).collect();
    let term = stats
        .map(|s| {
            serde_json::to_value(&*s.lock().unwrap_or_else(std::sync::PoisonError::into_inner))
        })
        .transpose()
        .map_err(|e| FusionError::Invalid(e.to_string()))?;
    let record = FusionRecord {
        config: fusion.clone(),
        pairs: pairs
            .iter()
            .map(|p| (names[p.first].to_string(), names[p.second].to_string()))
            .collect(),
        term,
    };
    let json =
        serde_json::to_vec_pretty(&record).map_err(|e| FusionError::Invalid(e.to_string()))?;
    fewview_scene::atomic::write_bytes(&record_path, &json)?;
    Ok((summary, record))
}

/// A resumed run must keep its fusion settings (they are recorded in `fusion.json` when the
/// run ends; an interrupted run has only `config.json`, whose settings the trainer checks).
fn check_resume(path: &Path, fusion: &FusionConfig) -> Result<(), FusionError> {
    let Ok(bytes) = std::fs::read(path) else {
        return Ok(());
    };
    let saved: FusionRecord = serde_json::from_slice(&bytes)
        .map_err(|e| FusionError::Invalid(format!("{}: {e}", path.display())))?;
    if &saved.config != fusion {
        return Err(FusionError::Invalid(format!(
            "{}: the run was trained with other fusion settings (variant {})",
            path.display(),
            saved.config.variant
        )));
    }
    Ok(())
}
