//! What defines a run besides the data: the training configuration, the start and the extra
//! terms' weights ([`RunConfig`]).

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::device::ComputeDevice;
use crate::stereo_start::StereoInit;
use crate::train::TrainConfig;

/// How to place the initial Gaussians.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum InitStrategy {
    /// The dataset's sparse points if it has them; else the stereo start when at least two
    /// training views overlap (see [`fewview_geom::stereo::pairs::stereo_pairs`]); else random
    /// points in the training frustums if the views have depth bounds, else random points in a
    /// box around the point the cameras look at.
    Auto,
    /// The dataset's sparse points (COLMAP `points3D`).
    DatasetPoints,
    /// Random points in the training frustums between each view's depth bounds.
    RandomFrustum,
    /// Random points in a cube of half-size `half_size` (default: 0.35 × the median camera
    /// distance) around the point the cameras look at.
    RandomBox { half_size: Option<f64> },
    /// Gaussians read from an Inria-layout PLY.
    Ply(PathBuf),
    /// The stereo start of the fusion paper §2: a sample of the hierarchical point cloud of the
    /// training views' stereo pairs ([`crate::stereo_start`]), built as [`RunConfig::stereo`]
    /// says.
    Stereo,
    /// Gaussians on the mesh of the surface run in this folder ([`crate::surface_start`]).
    Surface(PathBuf),
}

/// Everything that defines a run besides the data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunConfig {
    pub train: TrainConfig,
    pub init: InitStrategy,
    /// Number of random initial points (random strategies).
    pub init_points: usize,
    /// How the stereo start is built, when the run uses it.
    pub stereo: StereoInit,
    /// Where training runs. Not part of a checkpoint's identity: a run may resume on another
    /// device.
    #[serde(default)]
    pub device: ComputeDevice,
    /// Weight of the surface mesh's depth in the training views
    /// ([`crate::surface_start::SurfaceDepthTerm`]) when the run starts from a surface run;
    /// 0: none.
    #[serde(default = "default_surface_depth_weight")]
    pub surface_depth_weight: f32,
    /// Weight of the stereo start's depth in the training views
    /// ([`crate::stereo_depth::StereoDepthTerm`]) when the run starts from stereo; 0: none.
    #[serde(default)]
    pub stereo_depth_weight: f32,
    /// Weight of the stereo start's depth reprojected into pseudo views
    /// ([`crate::pseudo_depth::PseudoDepthTerm`]) when the run starts from stereo; 0: none.
    #[serde(default)]
    pub pseudo_depth_weight: f32,
    /// Weight of the floater loss ([`crate::floaters::FloaterTerm`]) when the run starts from
    /// stereo; 0: none.
    #[serde(default)]
    pub floater_weight: f32,
    /// CoR-GS's co-regularised pair of fields ([`crate::train::pair`]); `None`: one field.
    #[serde(default)]
    pub co_reg: Option<crate::train::pair::CoRegConfig>,
}

fn default_surface_depth_weight() -> f32 {
    crate::surface_start::SURFACE_DEPTH_WEIGHT
}

/// The most random initial points a run accepts. Each Gaussian costs about 1 KB while training
/// (parameters, gradients and Adam moments at SH degree 3), so this is ~10 GB; sparse-view scenes
/// use 10⁴–10⁵. A larger count is refused up front instead of aborting on allocation.
pub const MAX_INIT_POINTS: usize = 10_000_000;

impl RunConfig {
    pub fn new(train: TrainConfig) -> Self {
        Self {
            train,
            init: InitStrategy::Auto,
            init_points: 20_000,
            stereo: StereoInit::default(),
            device: ComputeDevice::Cpu,
            surface_depth_weight: default_surface_depth_weight(),
            stereo_depth_weight: 0.0,
            pseudo_depth_weight: 0.0,
            floater_weight: 0.0,
            co_reg: None,
        }
    }
}
