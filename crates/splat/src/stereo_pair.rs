//! One stereo pair of a dataset with everything the stereo start computes for it, for a person
//! to look at (`fewview stereo`): the rectified pair, both disparity maps, both depth maps, the
//! pair's hierarchical point cloud and where its points came from.

use std::path::Path;
use std::time::Instant;

use fewview_geom::colormap::colorize;
use fewview_geom::io::{write_npy, write_points};
use fewview_geom::stereo::hierarchy::{HierarchicalCloud, HierarchyOptions, hierarchical_cloud};
use fewview_geom::stereo::pairs::{StereoView, check_overlap, with_depth_bounds};
use fewview_geom::stereo::source::{DepthSource, PairDepths, PairStereo, match_pair};
use fewview_scene::{Dataset, SceneError};

use crate::stereo_start::{StereoInit, StereoStartError};

/// A matched pair and its (uncontracted) point cloud.
pub struct PairInspection {
    /// The two views' names, in the order given.
    pub names: [String; 2],
    pub pair: PairStereo,
    pub cloud: HierarchicalCloud,
    /// Wall seconds of rectification, matching, refinement and depth maps.
    pub match_seconds: f64,
}

/// Matches views `a` and `b` of `ds` (indices in its view order) as the stereo start would, and
/// builds their point cloud. `on_step(done, total)` reports progress. Views out of range, views
/// that do not overlap and a pair without baseline are errors naming the views.
pub fn inspect_pair(
    ds: &Dataset,
    (a, b): (usize, usize),
    init: &StereoInit,
    on_step: &mut dyn FnMut(usize, usize),
) -> Result<PairInspection, StereoStartError> {
    for v in [a, b] {
        if v >= ds.views.len() {
            return Err(StereoStartError::Other(format!(
                "view {v} is out of range ({} has {} views)",
                ds.name,
                ds.views.len()
            )));
        }
    }
    let views = with_depth_bounds(&[StereoView::of(&ds.views[a]), StereoView::of(&ds.views[b])]);
    let look_at = fewview_scene::axes_meeting_point(&[
        views[0].camera.world_to_camera,
        views[1].camera.world_to_camera,
    ]);
    check_overlap(&views[0], &views[1], &look_at, &init.overlap)?;
    let start = Instant::now();
    let pair = match_pair(
        &views[0],
        &views[1],
        &init.sgm,
        init.range,
        init.refine.as_ref(),
        init.photometry,
    )?;
    let match_seconds = start.elapsed().as_secs_f64();
    on_step(1, 2);
    // The pair as it is: no contraction, so that the cloud lies where the views saw it.
    let options = HierarchyOptions {
        contraction: None,
        ..init.hierarchy.clone()
    };
    let source = Matched(pair.depths.clone());
    let cloud = hierarchical_cloud(&views, &[(0, 1)], &source, &options, &mut |_, _| {})?;
    on_step(2, 2);
    Ok(PairInspection {
        names: [views[0].name.to_string(), views[1].name.to_string()],
        pair,
        cloud,
        match_seconds,
    })
}

/// The depth of a pair already matched.
struct Matched(PairDepths);

impl DepthSource for Matched {
    fn name(&self) -> &str {
        "sgm"
    }
    fn pair_depths(&self, _: usize, _: usize) -> fewview_geom::Result<PairDepths> {
        Ok(self.0.clone())
    }
}

impl PairInspection {
    /// Writes into `out` (created): `rectified_left.png`, `rectified_right.png`,
    /// `disparity_{left,right}.npy` (float32 pixels, 0 where none) with false-colour `.png`s,
    /// `depth_<view>.npy` (z-depth in the original camera, 0 where none) with `.png`s,
    /// `regions_<view>.png` (red R^c, green R^o, blue R^s), `cloud.ply` (pixel colours),
    /// `cloud_regions.ply` (region colours) and `stereo.json`.
    pub fn write(&self, out: &Path) -> Result<(), StereoStartError> {
        std::fs::create_dir_all(out).map_err(|e| SceneError::io(out, e))?;
        let pair = &self.pair;
        pair.left.image.save_png(&out.join("rectified_left.png"))?;
        pair.right
            .image
            .save_png(&out.join("rectified_right.png"))?;
        for (side, disp) in [
            ("left", &pair.left_disparity),
            ("right", &pair.right_disparity),
        ] {
            let values: Vec<f32> = disp
                .values
                .iter()
                .map(|v| if v.is_finite() { *v } else { 0.0 })
                .collect();
            let (w, h) = (disp.width, disp.height);
            write_npy(&out.join(format!("disparity_{side}.npy")), &[h, w], &values)?;
            colorize(&values, w, h, false).save_png(&out.join(format!("disparity_{side}.png")))?;
        }
        let originals = [&pair.depths.first, &pair.depths.second];
        for (k, (name, depth)) in self.names.iter().zip(originals).enumerate() {
            let camera = self.original_camera(k);
            let (w, h) = (camera.width() as usize, camera.height() as usize);
            write_npy(
                &out.join(format!("depth_{name}.npy")),
                &[h, w],
                &depth.depth,
            )?;
            colorize(&depth.depth, w, h, true).save_png(&out.join(format!("depth_{name}.png")))?;
            self.cloud
                .region_map(k, w, h)
                .save_png(&out.join(format!("regions_{name}.png")))?;
        }
        write_points(&out.join("cloud.ply"), &self.cloud.points)?;
        write_points(&out.join("cloud_regions.ply"), &self.cloud.region_colored())?;
        let rect = &pair.rectification;
        let json = serde_json::json!({
            "views": self.names,
            "swapped": pair.swapped,
            "focal_px": rect.intrinsics.fx,
            "baseline": rect.baseline,
            "rectified_size": [rect.intrinsics.width, rect.intrinsics.height],
            "params": pair.params,
            "valid_left": pair.left_disparity.valid_fraction(),
            "valid_right": pair.right_disparity.valid_fraction(),
            "candidates": self.cloud.counts.candidates,
            "accepted": self.cloud.counts.accepted,
            "match_seconds": self.match_seconds,
        });
        let bytes =
            serde_json::to_vec_pretty(&json).map_err(|e| StereoStartError::Other(e.to_string()))?;
        fewview_scene::atomic::write_bytes(&out.join("stereo.json"), &bytes)?;
        Ok(())
    }

    /// The original camera of the `k`-th view given (0 or 1).
    fn original_camera(&self, k: usize) -> &fewview_scene::Camera {
        use fewview_geom::stereo::rectify::Side;
        let first_is_left = !self.pair.swapped;
        let side = if (k == 0) == first_is_left {
            Side::Left
        } else {
            Side::Right
        };
        self.pair.rectification.original(side)
    }
}
