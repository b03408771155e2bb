//! Scores of novel views against the held-out cameras, the way the PoseGaussian paper reports them: PSNR,
//! SSIM and LPIPS per frame, and the temporal Δ-metrics (mean and standard deviation of
//! `|m_t − m_{t−1}|` over consecutive frames of one camera, fewview-metrics' `MetricSeries`),
//! each averaged over the held-out cameras.

use fewview_metrics::ssim::SsimOptions;
use fewview_metrics::temporal::{
    MeanStd, PerceptualDistance, TemporalReport, error_changes, evaluate_sequence,
};
use fewview_scene::Image;
use serde::{Deserialize, Serialize};

use crate::error::{HumanError, Result};
use crate::source::MultiView;
use crate::train::prepare::Framing;

/// One method's scores on one set of targets.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Scores {
    pub method: String,
    pub cameras: usize,
    pub frames: usize,
    pub psnr: f64,
    pub ssim: f64,
    pub lpips: Option<f64>,
    /// Δ-metrics: per camera the mean and standard deviation over its consecutive frames,
    /// then averaged over the cameras.
    pub delta_psnr: (f64, f64),
    pub delta_ssim: (f64, f64),
    pub delta_lpips: Option<(f64, f64)>,
    /// The flicker of the error: per camera the mean over consecutive frames of the mean
    /// absolute change of `render − truth` (colour values in [0, 1]; fewview-metrics'
    /// `error_changes`), averaged over the cameras. Zero for a render that tracks the truth
    /// or keeps a steady error, where the Δ-metrics also move with the person's motion and
    /// with how good a render is at all.
    #[serde(default)]
    pub error_flicker: f64,
}

fn averaged(stats: impl Iterator<Item = MeanStd>) -> (f64, f64) {
    let v: Vec<MeanStd> = stats.collect();
    let n = v.len().max(1) as f64;
    (
        v.iter().map(|s| s.mean).sum::<f64>() / n,
        v.iter().map(|s| s.std).sum::<f64>() / n,
    )
}

/// Scores `renders[c][t]` against `truths[c][t]` (camera `c`, consecutive frames `t`).
pub fn score(
    method: &str,
    renders: &[Vec<Image>],
    truths: &[Vec<Image>],
    perceptual: Option<&dyn PerceptualDistance>,
) -> Result<Scores> {
    if renders.len() != truths.len() || renders.is_empty() {
        let m = format!(
            "{} rendered cameras against {} true ones",
            renders.len(),
            truths.len()
        );
        return Err(HumanError::argument("evaluation", m));
    }
    let reports = renders
        .iter()
        .zip(truths)
        .map(|(r, t)| evaluate_sequence(r, t, &SsimOptions::default(), perceptual, None))
        .collect::<std::result::Result<Vec<TemporalReport>, _>>()
        .map_err(|e| HumanError::argument("evaluation", e.to_string()))?;
    let n = reports.len() as f64;
    let flicker = renders
        .iter()
        .zip(truths)
        .map(|(r, t)| error_changes(r, t).map(|c| MeanStd::of(&c).mean))
        .sum::<std::result::Result<f64, _>>()
        .map_err(|e| HumanError::argument("evaluation", e.to_string()))?;
    let mean = |f: &dyn Fn(&TemporalReport) -> f64| reports.iter().map(f).sum::<f64>() / n;
    let has_lpips = reports.iter().all(|r| r.lpips.is_some());
    Ok(Scores {
        method: method.to_string(),
        cameras: reports.len(),
        frames: reports[0].frames,
        psnr: mean(&|r| r.psnr.mean),
        ssim: mean(&|r| r.ssim.mean),
        lpips: has_lpips.then(|| mean(&|r| r.lpips.as_ref().map_or(f64::NAN, |l| l.mean))),
        delta_psnr: averaged(reports.iter().map(|r| r.psnr.delta)),
        delta_ssim: averaged(reports.iter().map(|r| r.ssim.delta)),
        delta_lpips: has_lpips.then(|| {
            averaged(
                reports
                    .iter()
                    .filter_map(|r| r.lpips.as_ref().map(|l| l.delta)),
            )
        }),
        error_flicker: flicker / n,
    })
}

/// The held-out camera `camera`'s images of `frames`, cropped as the run crops it. Evaluation
/// only: training never calls this.
pub fn truth_frames(
    source: &dyn MultiView,
    framing: &Framing,
    camera: usize,
    frames: std::ops::Range<usize>,
) -> Result<Vec<Image>> {
    let full = source
        .cameras()
        .get(camera)
        .ok_or_else(|| HumanError::argument("evaluation", format!("no camera {camera}")))?;
    let crop = framing.crop(full);
    frames
        .map(|f| Ok(crop.image(&source.image(camera, f)?)))
        .collect()
}

/// A Markdown table of `rows`.
pub fn table(rows: &[Scores]) -> String {
    let mut s = String::from(
        "| method | PSNR | SSIM | LPIPS | μ(ΔPSNR) | σ(ΔPSNR) | μ(ΔSSIM) | σ(ΔSSIM) | μ(ΔLPIPS) | σ(ΔLPIPS) | error flicker |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let opt = |v: Option<f64>, d: usize| v.map_or("–".to_string(), |v| format!("{v:.d$}"));
    for r in rows {
        s += &format!(
            "| {} | {:.2} | {:.4} | {} | {:.3} | {:.3} | {:.4} | {:.4} | {} | {} | {:.4} |\n",
            r.method,
            r.psnr,
            r.ssim,
            opt(r.lpips, 4),
            r.delta_psnr.0,
            r.delta_psnr.1,
            r.delta_ssim.0,
            r.delta_ssim.1,
            opt(r.delta_lpips.map(|d| d.0), 4),
            opt(r.delta_lpips.map(|d| d.1), 4),
            r.error_flicker,
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grey(v: f32) -> Image {
        Image {
            width: 16,
            height: 16,
            channels: 3,
            data: vec![v; 16 * 16 * 3],
        }
    }

    /// Two cameras, three frames: errors of constant images give known PSNRs and Δs.
    #[test]
    fn scores_average_cameras_after_the_deltas() {
        let truth = vec![vec![grey(0.5); 3], vec![grey(0.5); 3]];
        // Camera 0: errors 0.1, 0.01, 0.1 → PSNR 20, 40, 20 dB; Δ 20, 20 → μ 20, σ 0.
        // Camera 1: errors 0.1 everywhere → 20 dB; Δ 0.
        let renders = vec![
            vec![grey(0.6), grey(0.51), grey(0.6)],
            vec![grey(0.6), grey(0.6), grey(0.6)],
        ];
        let s = score("m", &renders, &truth, None).unwrap();
        assert!(
            (s.psnr - (80.0 / 3.0 + 20.0) / 2.0).abs() < 1e-4,
            "{}",
            s.psnr
        );
        assert!(
            (s.delta_psnr.0 - 10.0).abs() < 1e-4 && s.delta_psnr.1.abs() < 1e-4,
            "{:?}",
            s.delta_psnr
        );
        // The error changes by 0.09 between each of camera 0's frames and not on camera 1.
        assert!(
            (s.error_flicker - 0.045).abs() < 1e-6,
            "{}",
            s.error_flicker
        );
        assert_eq!((s.cameras, s.frames), (2, 3));
        assert!(s.lpips.is_none());
        assert!(table(&[s]).contains("| m | 23.33 |"));
    }
}

/// What [`evaluate`] renders and scores.
#[derive(Clone, Debug)]
pub struct EvalOptions {
    /// Consecutive frames to render (the novel-view table uses all, the novel-pose table those
    /// among the split's test frames).
    pub frames: std::ops::Range<usize>,
    /// Target cameras (the split's held-out cameras).
    pub cameras: Vec<usize>,
    /// Leave each target camera out of its own sources. With the input cameras as targets on
    /// training frames this is the validation protocol: an input camera predicted from its
    /// neighbours, as training does, so settings (the stabilizer's strength) can be chosen
    /// without reading a held-out camera or a test frame.
    pub leave_target_out: bool,
    /// The stabilizer's settings; `None` scores only the plain renders.
    pub tps: Option<crate::tps::TpsConfig>,
    /// Consecutive frames (inside `frames`) on which to train and score the 3DGS-per-frame
    /// baseline, with its options; a third table compares every method on them.
    pub splat: Option<(
        std::ops::Range<usize>,
        crate::baseline::SplatBaselineOptions,
    )>,
}

/// A scored run: its name in the tables and what it was trained as.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunInfo {
    pub name: String,
    /// The depth its network reads.
    pub depth: crate::depth::DepthInput,
    /// How its stereo depth was matched (read with `--depth stereo`).
    #[serde(default)]
    pub stereo: crate::depth::StereoSettings,
    /// Where its depth head could move the input depth.
    #[serde(default)]
    pub bracket: crate::depth::DepthBracket,
    /// Whether its pose encoder saw the pose (`false`: the per-frame baseline).
    pub use_pose: bool,
    /// Training steps behind its weights.
    pub iterations: usize,
}

impl RunInfo {
    pub fn of(name: &str, model: &crate::infer::Model) -> Self {
        Self {
            name: name.to_string(),
            depth: model.config.depth,
            stereo: model.config.stereo.clone(),
            bracket: model.config.bracket,
            use_pose: model.config.use_pose,
            iterations: model.iterations,
        }
    }
}

/// Both tables, and the mean time per frame of the run under test.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct EvalReport {
    /// The run under test (`ours`, with and without TPS) and each baseline run.
    #[serde(default)]
    pub runs: Vec<RunInfo>,
    pub cameras: Vec<usize>,
    pub frames: std::ops::Range<usize>,
    pub novel_view: Vec<Scores>,
    pub novel_pose: Vec<Scores>,
    /// Every method, the 3DGS-per-frame baseline included, on its frames.
    pub splat_frames: Vec<Scores>,
    pub times: crate::infer::FrameTimes,
}

/// Per method, per camera, per frame.
pub type Renders = Vec<(String, Vec<Vec<Image>>)>;

/// Renders `options.cameras` on `options.frames` with `model` (plain and, with TPS, stabilised)
/// and with every `(name, model)` of `baselines` (plain), and scores all of them against the
/// held-out images. `progress` hears of each finished frame.
pub fn evaluate(
    model: &crate::infer::Model,
    baselines: &[(String, &crate::infer::Model)],
    source: &dyn MultiView,
    split: &crate::split::Split,
    options: &EvalOptions,
    perceptual: Option<&dyn PerceptualDistance>,
    progress: &mut dyn FnMut(usize),
) -> Result<(EvalReport, Renders, Vec<Vec<Image>>)> {
    let full: Vec<fewview_scene::Camera> = options
        .cameras
        .iter()
        .map(|&c| source.cameras()[c].clone())
        .collect();
    let mut ours = crate::infer::SequenceRenderer::new(model, source, split, options.tps.clone());
    let mut others: Vec<_> = baselines
        .iter()
        .map(|(_, m)| crate::infer::SequenceRenderer::new(m, source, split, None))
        .collect();
    let k = options.cameras.len();
    let mut renders: Renders = vec![("ours, no TPS".to_string(), vec![Vec::new(); k])];
    if options.tps.is_some() {
        renders.insert(0, ("ours".to_string(), vec![Vec::new(); k]));
    }
    renders.extend(
        baselines
            .iter()
            .map(|(n, _)| (n.clone(), vec![Vec::new(); k])),
    );
    let leave_out: Vec<Option<usize>> = options
        .cameras
        .iter()
        .map(|&c| options.leave_target_out.then_some(c))
        .collect();
    let mut times = Vec::new();
    for frame in options.frames.clone() {
        let r = ours.render_frame_leaving_out(frame, &full, &leave_out)?;
        times.push(r.times);
        let mut per_method = Vec::new();
        if let Some(s) = r.stabilized {
            per_method.push(s);
        }
        per_method.push(r.plain);
        for other in &mut others {
            per_method.push(
                other
                    .render_frame_leaving_out(frame, &full, &leave_out)?
                    .plain,
            );
        }
        for ((_, cams), images) in renders.iter_mut().zip(per_method) {
            for (c, image) in images.into_iter().enumerate() {
                cams[c].push(image);
            }
        }
        progress(frame);
    }
    let truths = options
        .cameras
        .iter()
        .map(|&c| truth_frames(source, &model.framing, c, options.frames.clone()))
        .collect::<Result<Vec<_>>>()?;
    let splat = match &options.splat {
        Some((range, opts)) => {
            let inputs = crate::train::InferenceInputs {
                source,
                split,
                depth_maps: false,
            };
            let mut per_camera = vec![Vec::new(); k];
            for frame in range.clone() {
                let images =
                    crate::baseline::splat_per_frame(&inputs, frame, &model.framing, &full, opts)?;
                for (c, image) in images.into_iter().enumerate() {
                    per_camera[c].push(image);
                }
                progress(frame);
            }
            Some((range.clone(), per_camera))
        }
        None => None,
    };
    let table_of = |range: std::ops::Range<usize>| -> Result<Vec<Scores>> {
        let offset = options.frames.start;
        let (a, b) = (
            range.start.max(offset) - offset,
            range.end.min(options.frames.end).saturating_sub(offset),
        );
        if b < a + 2 {
            return Ok(Vec::new());
        }
        let cut = |v: &Vec<Vec<Image>>| v.iter().map(|c| c[a..b].to_vec()).collect::<Vec<_>>();
        renders
            .iter()
            .map(|(n, r)| score(n, &cut(r), &cut(&truths), perceptual))
            .collect()
    };
    let mut runs = vec![RunInfo::of("ours", model)];
    runs.extend(baselines.iter().map(|(n, m)| RunInfo::of(n, m)));
    let report = EvalReport {
        runs,
        cameras: options.cameras.clone(),
        frames: options.frames.clone(),
        novel_view: table_of(options.frames.clone())?,
        novel_pose: table_of(split.test_frames.clone())?,
        splat_frames: match &splat {
            Some((range, images)) => {
                let mut rows = table_of(range.clone())?;
                let offset = options.frames.start;
                let (a, b) = (range.start - offset, range.end - offset);
                let cut = truths.iter().map(|c| c[a..b].to_vec()).collect::<Vec<_>>();
                rows.push(score("3DGS per frame", images, &cut, perceptual)?);
                rows
            }
            None => Vec::new(),
        },
        times: crate::infer::FrameTimes::mean(&times),
    };
    Ok((report, renders, truths))
}

/// Frames side by side, left to right (all of one size).
pub fn side_by_side(columns: &[&Image]) -> Image {
    let (w, h) = (columns[0].width, columns[0].height);
    let n = columns.len();
    let mut data = vec![0.0f32; n * w * h * 3];
    for (i, im) in columns.iter().enumerate() {
        for y in 0..h {
            let dst = (y * n * w + i * w) * 3;
            data[dst..dst + 3 * w].copy_from_slice(&im.data[y * w * 3..(y + 1) * w * 3]);
        }
    }
    Image {
        width: n * w,
        height: h,
        channels: 3,
        data,
    }
}
