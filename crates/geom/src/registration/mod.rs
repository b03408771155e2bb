//! Point-cloud registration of paper 001 Alg. 3 (Appendix B.4): pre-align the reconstruction
//! with the similarity found by the camera-pose evaluation, then Open3D's standard pipeline —
//! voxel down-sampling, normals, FPFH features, RANSAC global registration on feature matches,
//! and ICP refinement on the full clouds.
//!
//! Parameters follow Open3D's semantics and its global-registration tutorial's choices, all in
//! units of the voxel size `v`: normals from ≤ 30 neighbours within `2v`, FPFH from ≤ 100
//! within `5v`, RANSAC inliers within `1.5v`, ICP correspondences within `thr_icp` (the
//! paper's input; `0.4v` in the tutorial; a coarse-to-fine list runs multi-scale ICP). Alg. 3 writes the pre-alignment as
//! `V ← s(R V + t)`; [`Similarity`] applies `x ↦ s R x + t'` (so `t' = s t`).

pub mod denoise;
pub mod features;
pub mod icp;
pub mod ransac;
pub mod voxel;

use serde::Serialize;

pub use features::{compute_fpfh, estimate_normals, pair_features};
pub use icp::{Evaluation, IcpCriteria, IcpMethod, IcpResult, evaluate_registration, icp};
pub use ransac::{RansacOptions, RansacResult, ransac_feature_matching};
pub use voxel::voxel_down_sample;

use crate::error::{GeomError, Result};
use crate::mesh::Points;
use crate::similarity::Similarity;

/// Options of [`register`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RegistrationOptions {
    /// Voxel size `v` of the down-sampling for features and RANSAC.
    pub voxel_size: f64,
    pub normal_radius: f64,
    pub normal_max_nn: usize,
    pub feature_radius: f64,
    pub feature_max_nn: usize,
    /// RANSAC (its distances default to `1.5v`).
    pub ransac: RansacOptions,
    /// `thr_icp`: ICP correspondence distances, run in turn (coarse to fine, each stage
    /// starting from the previous one; one value is plain ICP).
    pub icp_thresholds: Vec<f64>,
    pub icp_method: IcpMethod,
    pub icp_criteria: IcpCriteria,
    /// Deviation from Alg. 3, off by default: before ICP, project both full clouds onto
    /// their local planes (≤ `max_nn` neighbours within `radius`) and run point-to-plane ICP
    /// against those planes (see [`denoise`]). For scans with noise comparable to `thr_icp`.
    pub icp_denoise: Option<DenoiseOptions>,
}

/// Neighbourhood of the local-plane projection of [`RegistrationOptions::icp_denoise`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct DenoiseOptions {
    pub radius: f64,
    pub max_nn: usize,
}

impl DenoiseOptions {
    /// Neighbour cap: enough points for a stable plane at noise of about `radius / 4`.
    pub const DEFAULT_MAX_NN: usize = 100;

    /// Radius `2v`, the normal-estimation radius of the pipeline.
    pub fn for_voxel(v: f64) -> Self {
        Self {
            radius: 2.0 * v,
            max_nn: Self::DEFAULT_MAX_NN,
        }
    }
}

impl RegistrationOptions {
    /// The tutorial's parameters for voxel size `v` (point-to-point ICP, as in paper 001).
    pub fn for_voxel(v: f64) -> Self {
        Self {
            voxel_size: v,
            normal_radius: 2.0 * v,
            normal_max_nn: 30,
            feature_radius: 5.0 * v,
            feature_max_nn: 100,
            ransac: RansacOptions {
                max_correspondence_distance: 1.5 * v,
                distance_threshold: 1.5 * v,
                ..Default::default()
            },
            icp_thresholds: vec![0.4 * v],
            icp_method: IcpMethod::PointToPoint {
                with_scaling: false,
            },
            icp_criteria: IcpCriteria::default(),
            icp_denoise: None,
        }
    }
}

/// Result of [`register`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RegistrationResult {
    /// Source → target: `refined ∘ global ∘ prealignment`.
    pub transformation: Similarity,
    pub prealignment: Similarity,
    pub global: RansacResult,
    pub refined: IcpResult,
    /// Points after down-sampling (source, target).
    pub downsampled: (usize, usize),
}

fn check(points: &Points, what: &str) -> Result<()> {
    if points.is_empty() {
        return Err(GeomError::invalid(what, "has no points"));
    }
    points.validate(what)
}

/// Paper 001 Alg. 3: registers `source` onto `target`, starting from `prealignment` (the
/// camera-evaluation similarity; identity when `None`).
pub fn register(
    source: &Points,
    target: &Points,
    prealignment: Option<&Similarity>,
    options: &RegistrationOptions,
) -> Result<RegistrationResult> {
    check(source, "source")?;
    check(target, "target")?;
    let pre = prealignment.copied().unwrap_or_default();
    let scaled = Points::from_positions(pre.apply_points(&source.positions));
    let v = options.voxel_size;
    let down_s = voxel_down_sample(&scaled, v)?;
    let down_t = voxel_down_sample(&Points::from_positions(target.positions.clone()), v)?;
    let ns = estimate_normals(&down_s, options.normal_radius, options.normal_max_nn);
    let nt = estimate_normals(&down_t, options.normal_radius, options.normal_max_nn);
    let fs = compute_fpfh(
        &down_s.positions,
        &ns,
        options.feature_radius,
        options.feature_max_nn,
    );
    let ft = compute_fpfh(
        &down_t.positions,
        &nt,
        options.feature_radius,
        options.feature_max_nn,
    );
    let global = ransac_feature_matching(
        &down_s.positions,
        &down_t.positions,
        &fs,
        &ft,
        &options.ransac,
    )?;
    let (icp_source, icp_target, icp_method, target_normals) = match options.icp_denoise {
        Some(d) => {
            let s = denoise::project_to_local_planes(&scaled.positions, d.radius, d.max_nn);
            let t = denoise::project_to_local_planes(&target.positions, d.radius, d.max_nn);
            (
                s.positions,
                t.positions,
                IcpMethod::PointToPlane,
                Some(t.normals),
            )
        }
        None => {
            let normals = match options.icp_method {
                IcpMethod::PointToPlane => Some(estimate_normals(
                    target,
                    options.normal_radius,
                    options.normal_max_nn,
                )),
                IcpMethod::PointToPoint { .. } => None,
            };
            (
                scaled.positions.clone(),
                target.positions.clone(),
                options.icp_method,
                normals,
            )
        }
    };
    if options.icp_thresholds.is_empty() {
        return Err(GeomError::invalid(
            "ICP thresholds",
            "at least one is needed",
        ));
    }
    let mut current = global.transformation;
    let mut refined = None;
    for &thr in &options.icp_thresholds {
        let r = icp(
            &icp_source,
            &icp_target,
            target_normals.as_deref(),
            thr,
            &current,
            icp_method,
            &options.icp_criteria,
        )?;
        current = r.transformation;
        refined = Some(r);
    }
    let refined = refined.ok_or_else(|| GeomError::invalid("ICP thresholds", "none given"))?;
    Ok(RegistrationResult {
        transformation: refined.transformation.compose(&pre),
        prealignment: pre,
        global,
        refined,
        downsampled: (down_s.len(), down_t.len()),
    })
}
