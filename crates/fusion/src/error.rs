//! Errors of the fusion method, each naming what failed.

use fewview_scene::SceneError;

#[derive(Debug, thiserror::Error)]
pub enum FusionError {
    #[error(transparent)]
    Geom(#[from] fewview_geom::GeomError),
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Pipeline(#[from] fewview_splat::pipeline::PipelineError),
    #[error(transparent)]
    Metrics(#[from] fewview_metrics::MetricsError),
    #[error("{0}")]
    Invalid(String),
}
