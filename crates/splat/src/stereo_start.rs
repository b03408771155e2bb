//! The stereo start of "Splat-based Gradient-domain Fusion for Seamless View Transition"
//! (the fusion paper §2): initial Gaussians from the confidence-based hierarchical point cloud of the
//! training views' stereo pairs instead of random points.
//!
//! The training views are ordered along their baseline and paired with their neighbours
//! ([`fewview_geom::stereo::pairs`]); each pair's depth comes from a [`DepthSource`]
//! (Semi-Global Matching on the rectified pair, refined to sub-pixel, in place of the paper's
//! UniMatch; or the user's own depth maps); the hierarchical cloud accepts the consistent
//! points first and the doubtful ones only behind them, is contracted with Eq. (2), and a random
//! 10 % of it (the paper's ratio) becomes the Gaussians.

use std::path::{Path, PathBuf};

use fewview_geom::contract::sample_indices;
use fewview_geom::stereo::hierarchy::{
    HierarchicalCloud, HierarchyOptions, Region, hierarchical_cloud,
};
use fewview_geom::stereo::pairs::{OverlapRule, StereoView, stereo_pairs, with_depth_bounds};
use fewview_geom::stereo::refine::RefineOptions;
use fewview_geom::stereo::sgm::{Paths, SgmParams};
use fewview_geom::stereo::source::{
    DepthMapSource, DepthSource, DisparityRange, PairMethod, Photometry, SgmSource, pair_method,
};
use fewview_scene::{Dataset, PointCloud, SceneError};
use serde::{Deserialize, Serialize};

use crate::sky_shell::{SHELL_BLOCK_PX, Shell, sky_shell};
use crate::stereo_pair_check::{PairCheck, PairCheckError, PairCheckReport, check_pairs};

/// Where the pairs' depth comes from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DepthFrom {
    /// Semi-Global Matching on each rectified pair, both ways.
    Sgm,
    /// `<dir>/<view name>.npy` (float z-depth) or `.png` (16-bit, millimetres) per training view.
    Maps(PathBuf),
}

/// How the stereo start is built.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StereoInit {
    pub depth: DepthFrom,
    /// Fraction of the hierarchical cloud that becomes Gaussians (the fusion paper: 0.1; its
    /// alternative (a): 0.01).
    pub fraction: f64,
    /// The most Gaussians the start gives (0: no cap): a larger cloud is sampled more sparsely.
    /// The fusion paper's 10 % was set on a few views; on a long capture (29 photos of a street
    /// give 5.3 million points) it would make training many times slower for little gain.
    #[serde(default = "default_max_points")]
    pub max_points: usize,
    /// Add a shell of Gaussians for the sky and far background ([`crate::sky_shell`]): off by
    /// default (not in the fusion paper); `fewview` turns it on for a folder of photos.
    #[serde(default)]
    pub sky_shell: bool,
    pub sgm: SgmParams,
    pub range: DisparityRange,
    /// Sub-pixel refinement of the disparities (`None`: SGM's parabola only).
    pub refine: Option<RefineOptions>,
    /// How a pair's photos are brought to one brightness before matching.
    #[serde(default)]
    pub photometry: Photometry,
    pub overlap: OverlapRule,
    /// The check by feature matching of the pairs that overlap (off by default).
    #[serde(default)]
    pub pair_check: PairCheck,
    pub hierarchy: HierarchyOptions,
}

/// The default cap on the stereo start's Gaussians ([`StereoInit::max_points`]).
pub const DEFAULT_MAX_POINTS: usize = 250_000;

fn default_max_points() -> usize {
    DEFAULT_MAX_POINTS
}

impl StereoInit {
    /// The fraction of a cloud of `points` points that becomes Gaussians: [`Self::fraction`],
    /// lowered so that at most [`Self::max_points`] are drawn.
    pub fn fraction_of(&self, points: usize) -> f64 {
        if self.max_points == 0 || points == 0 {
            return self.fraction;
        }
        self.fraction.min(self.max_points as f64 / points as f64)
    }
}

impl Default for StereoInit {
    fn default() -> Self {
        Self {
            depth: DepthFrom::Sgm,
            fraction: 0.1,
            max_points: DEFAULT_MAX_POINTS,
            sky_shell: false,
            sgm: SgmParams {
                // Eight paths: five leave a directional bias on steep surfaces (about twice the
                // median disparity error on the demo scene's floor).
                paths: Paths::Eight,
                ..SgmParams::default()
            },
            range: DisparityRange::FromSparsePoints,
            refine: Some(RefineOptions::default()),
            photometry: Photometry::default(),
            overlap: OverlapRule::default(),
            pair_check: PairCheck::default(),
            hierarchy: HierarchyOptions::default(),
        }
    }
}

/// The stereo start of a dataset: the whole cloud, and the sample that becomes Gaussians.
pub struct StereoStart {
    /// Names of the views of each stereo pair.
    pub pairs: Vec<(String, String)>,
    /// What the depth came from ("sgm", "depth maps").
    pub source: String,
    pub cloud: HierarchicalCloud,
    /// The sampled points (positions and pixel colours) and their regions.
    pub sample: PointCloud,
    pub sample_regions: Vec<Region>,
    /// Per sampled point, the width (scene units) of the patch of its view it stands for: the
    /// pixel's footprint at its depth times the sample's spacing in pixels (`1/√fraction`).
    pub sample_footprints: Vec<f32>,
    /// The fraction of the cloud sampled: [`StereoInit::fraction`], or less under
    /// [`StereoInit::max_points`].
    pub fraction: f64,
    /// The sky shell's Gaussians, when [`StereoInit::sky_shell`] asks for them.
    pub shell: Option<Shell>,
    /// The pairs' matches when [`StereoInit::pair_check`] names a matcher.
    pub pair_check: Option<PairCheckReport>,
    /// How each training view's depth agrees with the dataset's sparse points.
    pub agreement: Vec<PointAgreement>,
    /// Pairs whose depth could not be had: their views' names and the reason.
    pub skipped: Vec<(String, String, String)>,
    /// Pairs matched by plane sweep rather than on rectified rows: their views' names and why
    /// rectification could not serve them.
    pub swept: Vec<(String, String, String)>,
}

/// Errors of the stereo start, naming the views or the file.
#[derive(Debug, thiserror::Error)]
pub enum StereoStartError {
    #[error(transparent)]
    Geom(#[from] fewview_geom::GeomError),
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    PairCheck(#[from] PairCheckError),
    #[error("stereo start: {0}")]
    Other(String),
}

/// The training views of `ds` as the stereo code sees them, with the dataset's sparse points
/// (missing depth bounds taken from those points or guessed from where the cameras look, see
/// [`with_depth_bounds`]).
pub fn stereo_views(ds: &Dataset) -> Vec<StereoView<'_>> {
    let points = ds.points.as_ref().map_or(&[][..], |p| &p.positions[..]);
    let views: Vec<StereoView> = ds
        .train_views()
        .map(|v| StereoView {
            sparse_points: points,
            ..StereoView::of(v)
        })
        .collect();
    with_depth_bounds(&views)
}

/// Builds the stereo start of `ds` (its training views). `on_pair(done, total)` reports progress.
pub fn stereo_start(
    ds: &Dataset,
    init: &StereoInit,
    seed: u64,
    on_pair: &mut dyn FnMut(usize, usize),
) -> Result<StereoStart, StereoStartError> {
    if !(init.fraction > 0.0 && init.fraction <= 1.0) {
        return Err(StereoStartError::Other(format!(
            "sample fraction {} is not in (0, 1]",
            init.fraction
        )));
    }
    let views = stereo_views(ds);
    let checked = check_pairs(
        &views,
        &stereo_pairs(&views, &init.overlap)?,
        &init.pair_check,
    )?;
    let pairs = checked.pairs;
    let source: Box<dyn DepthSource + '_> = match &init.depth {
        DepthFrom::Sgm => Box::new(SgmSource {
            views: &views,
            params: init.sgm.clone(),
            range: init.range,
            refine: init.refine,
            photometry: init.photometry,
        }),
        DepthFrom::Maps(dir) => Box::new(DepthMapSource::load(dir, &views, 0.001)?),
    };
    let cloud = hierarchical_cloud(&views, &pairs, source.as_ref(), &init.hierarchy, on_pair)?;
    if cloud.points.is_empty() {
        return Err(StereoStartError::Other(format!(
            "the stereo pairs of {} gave no points (textureless images, or wrong poses?)",
            ds.name
        )));
    }
    let names = |a: usize, b: usize| (views[a].name.to_string(), views[b].name.to_string());
    let skipped = cloud
        .skipped
        .iter()
        .map(|(a, b, why)| {
            let (a, b) = names(*a, *b);
            (a, b, why.clone())
        })
        .collect();
    let swept = match init.depth {
        DepthFrom::Sgm => pairs
            .iter()
            .filter_map(
                |&(a, b)| match pair_method(views[a].camera, views[b].camera) {
                    PairMethod::PlaneSweep(why) => {
                        let (a, b) = names(a, b);
                        Some((a, b, why))
                    }
                    PairMethod::Rectified => None,
                },
            )
            .collect(),
        DepthFrom::Maps(_) => Vec::new(),
    };
    let observed: Vec<Option<Vec<[f32; 3]>>> = views
        .iter()
        .map(|v| {
            let cloud = ds.points.as_ref()?;
            Some(cloud.observed_in(v.name)?.copied().collect())
        })
        .collect();
    let agreement = point_agreement(&cloud, &views, &observed);
    let shell = if init.sky_shell {
        sky_shell(&views, &cloud, SHELL_BLOCK_PX)
    } else {
        None
    };
    let fraction = init.fraction_of(cloud.points.len());
    let chosen = sample_indices(cloud.points.len(), fraction, seed)?;
    let points = cloud.points.select(&chosen);
    let sample_regions = chosen.iter().map(|&i| cloud.regions[i]).collect();
    let sample_footprints = footprints(&cloud, &views, &chosen, fraction);
    let sample = PointCloud {
        positions: points.positions,
        colors: points.colors.unwrap_or_default(),
        ..PointCloud::default()
    };
    Ok(StereoStart {
        pairs: pairs
            .iter()
            .map(|&(a, b)| (views[a].name.to_string(), views[b].name.to_string()))
            .collect(),
        source: source.name().to_string(),
        cloud,
        sample,
        sample_regions,
        sample_footprints,
        fraction,
        shell,
        pair_check: checked.report,
        agreement,
        skipped,
        swept,
    })
}

/// How one view's stereo depth agrees with the structure-from-motion points it sees: over all
/// its depth, and over the verified depth alone (R^c, consistent between the two views of a
/// pair), the depth the fusion paper trusts.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PointAgreement {
    pub view: String,
    /// Sparse points in front of the view and inside its image.
    pub points_seen: usize,
    /// Every pixel with a point of the cloud (R^c, R^o or R^s).
    pub all: DepthAgreement,
    /// The pixels in R^c only.
    pub verified: DepthAgreement,
}

impl PointAgreement {
    /// One line for the run's summary: depth and verified depth, each with its error.
    pub fn note(&self) -> String {
        let part = |a: &DepthAgreement| match a.median_relative_error {
            Some(e) => format!(
                "{:.0} % of its pixels (median error {:.1} % at {} sparse points)",
                100.0 * a.pixels_with_depth,
                100.0 * e,
                a.points_compared
            ),
            None => format!(
                "{:.0} % of its pixels (no sparse point there)",
                100.0 * a.pixels_with_depth
            ),
        };
        format!(
            "stereo start: view {}: depth at {}, verified at {}",
            self.view,
            part(&self.all),
            part(&self.verified)
        )
    }
}

/// The share of a view's pixels with depth, and how that depth meets the sparse points.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct DepthAgreement {
    pub pixels_with_depth: f64,
    /// Sparse points whose pixel has depth, and the median of `|z_stereo − z_point| / z_point`.
    pub points_compared: usize,
    pub median_relative_error: Option<f64>,
}

impl DepthAgreement {
    fn new(pixels: usize, with_depth: usize, mut errors: Vec<f64>) -> Self {
        errors.sort_by(f64::total_cmp);
        Self {
            pixels_with_depth: with_depth as f64 / pixels.max(1) as f64,
            points_compared: errors.len(),
            median_relative_error: errors.get(errors.len() / 2).copied(),
        }
    }
}

/// [`PointAgreement`] of every view of `cloud` with the sparse points it observed (`observed`,
/// per view, where the dataset records the points' tracks), else with every sparse point in its
/// image: a point hidden behind a nearer surface would count against correct depth.
fn point_agreement(
    cloud: &HierarchicalCloud,
    views: &[StereoView],
    observed: &[Option<Vec<[f32; 3]>>],
) -> Vec<PointAgreement> {
    views
        .iter()
        .zip(observed)
        .zip(&cloud.pixel_depths)
        .zip(&cloud.pixel_regions)
        .map(|(((view, observed), depths), regions)| {
            let verified = |p: usize| regions[p] == Some(Region::Consistent);
            let points = observed.as_deref().unwrap_or(view.sparse_points);
            let pixels = points.iter().filter_map(|p| {
                let x = nalgebra::Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                view.camera.pixel_of(&x)
            });
            let (mut seen, mut all, mut sure) = (0, Vec::new(), Vec::new());
            for (p, z) in pixels {
                seen += 1;
                if depths[p] > 0.0 {
                    let error = (depths[p] as f64 - z).abs() / z;
                    all.push(error);
                    if verified(p) {
                        sure.push(error);
                    }
                }
            }
            let with_depth = depths.iter().filter(|&&d| d > 0.0).count();
            let with_verified = (0..depths.len()).filter(|&p| verified(p)).count();
            PointAgreement {
                view: view.name.to_string(),
                points_seen: seen,
                all: DepthAgreement::new(depths.len(), with_depth, all),
                verified: DepthAgreement::new(depths.len(), with_verified, sure),
            }
        })
        .collect()
}

/// The patch each chosen point of `cloud` stands for in the view it was seen in: its depth
/// there over the focal length (a pixel's footprint), times `1/√fraction` (the sample's spacing
/// in pixels).
fn footprints(
    cloud: &HierarchicalCloud,
    views: &[StereoView],
    chosen: &[usize],
    fraction: f64,
) -> Vec<f32> {
    let spacing = 1.0 / fraction.sqrt();
    chosen
        .iter()
        .map(|&i| {
            let camera = views[cloud.sources[i].0 as usize].camera;
            let x = cloud.points.positions[i].map(f64::from);
            let z = camera.world_to_camera.transform_point(&x.into()).z;
            (z.abs() / camera.intrinsics.fx * spacing) as f32
        })
        .collect()
}

/// A summary of a stereo start for `stereo.json`.
#[derive(Debug, Serialize)]
pub struct StereoSummary<'a> {
    pub source: &'a str,
    pub pairs: &'a [(String, String)],
    /// Per region (R^c, R^o, R^s): pixels classified, points accepted.
    pub candidates: [usize; 3],
    pub accepted: [usize; 3],
    pub points: usize,
    pub sampled: usize,
    /// The fraction of the points sampled (below the configured one under the cap).
    pub fraction: f64,
    /// Eq. (2): the reference view, `B_near` and `B_far`.
    pub contraction_view: Option<String>,
    pub b_near: Option<f64>,
    pub b_far: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pair_check: Option<&'a PairCheckReport>,
    /// Each view's depth against the sparse points it observed.
    pub agreement: &'a [PointAgreement],
    /// Pairs without depth, and pairs swept in their own cameras: views and reason.
    pub skipped: &'a [(String, String, String)],
    pub swept: &'a [(String, String, String)],
}

impl StereoStart {
    pub fn summary(&self, ds: &Dataset) -> StereoSummary<'_> {
        let c = self.cloud.contraction.as_ref();
        let train: Vec<&str> = ds.train_views().map(|v| v.name.as_str()).collect();
        StereoSummary {
            source: &self.source,
            pairs: &self.pairs,
            candidates: self.cloud.counts.candidates,
            accepted: self.cloud.counts.accepted,
            points: self.cloud.points.len(),
            sampled: self.sample.len(),
            fraction: self.fraction,
            contraction_view: c.and_then(|c| c.view).map(|v| train[v].to_string()),
            b_near: c.map(|c| c.b_near),
            b_far: c.map(|c| c.b_far),
            pair_check: self.pair_check.as_ref(),
            agreement: &self.agreement,
            skipped: &self.skipped,
            swept: &self.swept,
        }
    }

    /// Writes `dir/stereo_cloud.ply` (the whole cloud, pixel colours), `dir/stereo_regions.ply`
    /// (coloured by region: red R^c, green R^o, blue R^s), `dir/stereo_regions.png` (the cloud
    /// seen from the contraction view, Fig. 1) and `dir/stereo.json`.
    pub fn write(&self, ds: &Dataset, dir: &Path) -> Result<(), StereoStartError> {
        std::fs::create_dir_all(dir).map_err(|e| SceneError::io(dir, e))?;
        fewview_geom::io::write_points(&dir.join("stereo_cloud.ply"), &self.cloud.points)?;
        fewview_geom::io::write_points(
            &dir.join("stereo_regions.ply"),
            &self.cloud.region_colored(),
        )?;
        let view = self.cloud.contraction.and_then(|c| c.view).unwrap_or(0);
        let camera = &ds.train_views().nth(view).expect("a training view").camera;
        self.cloud
            .render_regions(camera, 2)
            .save_png(&dir.join("stereo_regions.png"))?;
        let json = serde_json::to_vec_pretty(&self.summary(ds))
            .map_err(|e| StereoStartError::Other(e.to_string()))?;
        fewview_scene::atomic::write_bytes(&dir.join("stereo.json"), &json)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fewview_geom::mesh::Points;
    use fewview_geom::stereo::hierarchy::RegionCounts;
    use fewview_scene::{Camera, Image, Intrinsics};
    use nalgebra::Vector3;

    /// A view facing a wall 2 units away, its depth exact and verified everywhere, and two
    /// sparse points on its optical axis: one on the wall (observed) and one 5 units away behind
    /// it (observed by another view only). With the tracks, the view's depth is exact; without,
    /// the hidden point counts as a 60 % error.
    #[test]
    fn agreement_counts_only_the_points_a_view_observed() {
        let camera = Camera::look_at(
            Intrinsics::centered(50.0, 40, 30),
            Vector3::zeros(),
            Vector3::z(),
            -Vector3::y(),
        );
        let image = Image::filled(40, 30, &[0.5, 0.5, 0.5]);
        let points = [[0.0, 0.0, 2.0], [0.0, 0.0, 5.0]];
        let view = StereoView {
            name: "wall",
            camera: &camera,
            image: &image,
            depth_bounds: None,
            mask: None,
            sparse_points: &points,
        };
        let pixels = 40 * 30;
        let cloud = HierarchicalCloud {
            points: Points::from_positions(Vec::new()),
            regions: Vec::new(),
            sources: Vec::new(),
            counts: RegionCounts::default(),
            contraction: None,
            pixel_regions: vec![vec![Some(Region::Consistent); pixels]],
            pixel_depths: vec![vec![2.0; pixels]],
            skipped: Vec::new(),
        };
        let with_tracks = point_agreement(&cloud, &[view], &[Some(vec![points[0]])]);
        let without = point_agreement(&cloud, &[view], &[None]);
        assert_eq!(with_tracks[0].points_seen, 1);
        assert_eq!(with_tracks[0].verified.median_relative_error, Some(0.0));
        assert_eq!(without[0].points_seen, 2);
        let error = without[0].verified.median_relative_error.unwrap();
        assert!((error - 0.6).abs() < 1e-6, "{error}");
    }

    /// The cap lowers the fraction only for clouds larger than `max_points / fraction`, and
    /// then gives exactly `max_points` in expectation; 0 turns it off.
    #[test]
    fn the_cap_lowers_the_fraction_of_large_clouds_only() {
        let init = StereoInit {
            fraction: 0.1,
            max_points: 1_000,
            ..StereoInit::default()
        };
        assert_eq!(init.fraction_of(5_000), 0.1);
        assert_eq!(init.fraction_of(10_000), 0.1);
        assert_eq!(init.fraction_of(40_000), 0.025);
        let uncapped = StereoInit {
            max_points: 0,
            ..init
        };
        assert_eq!(uncapped.fraction_of(40_000), 0.1);
    }
}
