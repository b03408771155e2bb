//! Speed of the learned matchers on one image pair (`fewview bench --only match`).

use std::time::Instant;

use fewview_scene::Image;
use serde::Serialize;

use crate::error::Result;
use crate::lighterglue::{GlueOptions, LighterGlue};
use crate::xfeat::{DetectOptions, XFeat};

/// Median wall seconds of each stage for one pair, and the counts they produced.
#[derive(Clone, Debug, Serialize)]
pub struct MatchBench {
    pub width: usize,
    pub height: usize,
    pub runs: usize,
    pub threads: usize,
    /// XFeat detection of one image (network, heatmap, NMS, descriptors).
    pub detect_seconds: f64,
    /// The pair end to end with mutual nearest neighbours: both detections and the matching.
    pub pair_mnn_seconds: f64,
    /// The pair end to end with LighterGlue: both detections and the matcher.
    pub pair_lighterglue_seconds: f64,
    /// The pair end to end with XFeat* (both images at two scales, matching, refinement).
    pub pair_star_seconds: f64,
    pub keypoints: [usize; 2],
    pub mnn_matches: usize,
    pub lighterglue_matches: usize,
    pub star_matches: usize,
}

/// Times each mode on `(a, b)` over `runs` repetitions (after one warm-up).
pub fn match_bench(
    xfeat: &XFeat,
    glue: &LighterGlue,
    a: &Image,
    b: &Image,
    runs: usize,
) -> Result<MatchBench> {
    let options = DetectOptions::default();
    let runs = runs.max(1);
    let fa = xfeat.detect(a, options)?;
    let fb = xfeat.detect(b, options)?;
    let detect_seconds = median_seconds(runs, || xfeat.detect(a, options).map(drop))?;
    let mut mnn = 0;
    let pair_mnn_seconds = median_seconds(runs, || {
        let (fa, fb) = (xfeat.detect(a, options)?, xfeat.detect(b, options)?);
        mnn = xfeat.match_mutual(&fa, &fb, None).len();
        Ok(())
    })?;
    let mut glued = 0;
    let pair_lighterglue_seconds = median_seconds(runs, || {
        let (fa, fb) = (xfeat.detect(a, options)?, xfeat.detect(b, options)?);
        glued = glue.match_features(&fa, &fb, GlueOptions::default())?.len();
        Ok(())
    })?;
    let mut star = 0;
    let pair_star_seconds = median_seconds(runs, || {
        star = xfeat.match_star(a, b, options.top_k)?.len();
        Ok(())
    })?;
    Ok(MatchBench {
        width: a.width,
        height: a.height,
        runs,
        threads: rayon::current_num_threads(),
        detect_seconds,
        pair_mnn_seconds,
        pair_lighterglue_seconds,
        pair_star_seconds,
        keypoints: [fa.len(), fb.len()],
        mnn_matches: mnn,
        lighterglue_matches: glued,
        star_matches: star,
    })
}

/// Median wall seconds of `runs` calls of `f`, after one untimed call.
fn median_seconds(runs: usize, mut f: impl FnMut() -> Result<()>) -> Result<f64> {
    f()?;
    let mut times = Vec::with_capacity(runs);
    for _ in 0..runs {
        let start = Instant::now();
        f()?;
        times.push(start.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    Ok(times[runs / 2])
}
