//! Temporal-coherence metrics of a rendered sequence against its ground truth.
//!
//! * **Per-frame** PSNR, SSIM and (optionally) LPIPS.
//! * **Δ (frame-to-frame change of a metric)**, the Δ columns of the PoseGaussian paper's tables: for a
//!   per-frame metric `m_t`, `d_t = |m_t − m_{t−1}|` for `t = 1..T−1`, reported as the mean and
//!   the (population, `1/(T−1)`) standard deviation of `d_t`. A method whose quality flickers
//!   from frame to frame has a large Δ even when its mean quality is good. The PoseGaussian paper does not
//!   spell the formula out; this is the definition used here, stated so results can be compared.
//!   Two consecutive infinite PSNRs (exact frames) count as no change.
//! * **tLP** (TecoGAN, Chu et al. 2020, Eq. 9 of their paper): `100 · |LPIPS(gt_{t−1}, gt_t) −
//!   LPIPS(out_{t−1}, out_t)|`, averaged over `t`; it compares how much the output changes
//!   perceptually between frames with how much the ground truth does.
//! * **Warping error** (Lai et al. 2018, "Learning Blind Video Temporal Consistency", Eq. 8):
//!   `E = 1/(T−1) Σ_t Σ_i M_t(i) ‖out_t(i) − warp(out_{t−1})(i)‖² / Σ_i M_t(i)`, where the warp
//!   uses a backward flow supplied by the caller (our renderers know it exactly from depth and
//!   cameras) with bilinear sampling, and `M_t` is the caller's validity (non-occlusion) mask
//!   times "the flow lands inside frame t−1". The squared norm is over channels.

use fewview_scene::Image;

use crate::error::{MetricsError, Result, check_same_shape};
use crate::psnr::psnr;
use crate::ssim::{SsimOptions, ssim_with};

/// A perceptual distance between two images (LPIPS in practice); tLP and per-frame LPIPS are
/// computed with whatever implementation the caller passes.
pub trait PerceptualDistance {
    /// Name reported with the results (e.g. `lpips-alex-v0.1`).
    fn name(&self) -> String;
    fn distance(&self, a: &Image, b: &Image) -> Result<f64>;

    /// Per-frame distances `D(out_t, gt_t)` and tLP values (see [`tlp_per_transition`]) of
    /// equal-length sequences. The default calls [`Self::distance`]; an implementation may
    /// share work between the calls (LPIPS computes each frame's features once).
    fn sequence_distances(
        &self,
        output: &[Image],
        ground_truth: &[Image],
    ) -> Result<(Vec<f64>, Vec<f64>)> {
        let per_frame = output
            .iter()
            .zip(ground_truth)
            .map(|(o, g)| self.distance(o, g))
            .collect::<Result<_>>()?;
        Ok((per_frame, tlp_per_transition(output, ground_truth, self)?))
    }
}

/// Backward optical flow of frame `t`: pixel `(x, y)` of frame `t` shows the point that was at
/// `(x + dx, y + dy)` in frame `t − 1` (pixel-centre coordinates, in pixels).
#[derive(Clone, Debug, PartialEq)]
pub struct Flow {
    pub width: usize,
    pub height: usize,
    /// `(dx, dy)` per pixel, row-major.
    pub data: Vec<[f32; 2]>,
    /// Optional validity mask (1 = the point is visible in both frames), row-major.
    pub valid: Option<Vec<bool>>,
    /// The file the flow was read from ([`read_flo`] sets it), named in the errors of
    /// [`warping_errors`].
    pub source: Option<std::path::PathBuf>,
}

/// Mean and population standard deviation of a series.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct MeanStd {
    pub mean: f64,
    pub std: f64,
}

impl MeanStd {
    pub fn of(values: &[f64]) -> Self {
        if values.is_empty() {
            return Self {
                mean: f64::NAN,
                std: f64::NAN,
            };
        }
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
        Self {
            mean,
            std: var.sqrt(),
        }
    }
}

/// Per-frame values of one metric, their mean, and the Δ statistics.
#[derive(Clone, Debug, serde::Serialize)]
pub struct MetricSeries {
    pub name: String,
    pub per_frame: Vec<f64>,
    pub mean: f64,
    /// Mean and standard deviation of `|m_t − m_{t−1}|`.
    pub delta: MeanStd,
}

impl MetricSeries {
    /// The series of `per_frame` with its mean over the values that are not `NaN` (frames or
    /// transitions not scored) and its Δ over the neighbouring pairs that both are.
    pub fn over_scored(name: impl Into<String>, per_frame: Vec<f64>) -> Self {
        let scored: Vec<f64> = per_frame.iter().copied().filter(|v| !v.is_nan()).collect();
        let deltas: Vec<f64> = frame_deltas(&per_frame)
            .into_iter()
            .filter(|v| !v.is_nan())
            .collect();
        Self {
            name: name.into(),
            mean: scored.iter().sum::<f64>() / scored.len().max(1) as f64,
            delta: MeanStd::of(&deltas),
            per_frame,
        }
    }

    pub fn new(name: impl Into<String>, per_frame: Vec<f64>) -> Self {
        let mean = per_frame.iter().sum::<f64>() / per_frame.len().max(1) as f64;
        let delta = MeanStd::of(&frame_deltas(&per_frame));
        Self {
            name: name.into(),
            per_frame,
            mean,
            delta,
        }
    }
}

/// `|m_t − m_{t−1}|` for `t = 1..T−1` (equal infinities count as 0).
pub fn frame_deltas(values: &[f64]) -> Vec<f64> {
    values
        .windows(2)
        .map(|w| {
            if w[0] == w[1] {
                0.0
            } else {
                (w[1] - w[0]).abs()
            }
        })
        .collect()
}

/// Everything `eval-video` reports.
#[derive(Clone, Debug, serde::Serialize)]
pub struct TemporalReport {
    pub frames: usize,
    pub psnr: MetricSeries,
    pub ssim: MetricSeries,
    pub lpips: Option<MetricSeries>,
    /// The perceptual distance used for LPIPS and tLP (variant named).
    pub perceptual: Option<String>,
    /// Per-transition tLP values (`t = 1..T−1`) and their mean.
    pub tlp: Option<MetricSeries>,
    /// Per-transition warping errors and their mean.
    pub warping_error: Option<MetricSeries>,
}

/// Evaluates `output` against `ground_truth` (same frame count and sizes). `perceptual`
/// enables per-frame LPIPS and tLP; `flows` (one per transition, `T − 1`) enables the warping
/// error.
pub fn evaluate_sequence(
    output: &[Image],
    ground_truth: &[Image],
    ssim_opts: &SsimOptions,
    perceptual: Option<&dyn PerceptualDistance>,
    flows: Option<&[Flow]>,
) -> Result<TemporalReport> {
    check_sequences(output, ground_truth)?;
    let per_frame = |f: &dyn Fn(&Image, &Image) -> Result<f64>| -> Result<Vec<f64>> {
        output
            .iter()
            .zip(ground_truth)
            .enumerate()
            .map(|(t, (o, g))| {
                f(o, g).map_err(|e| MetricsError::invalid(format!("frame {t}: {e}")))
            })
            .collect()
    };
    let psnr_series = MetricSeries::new("psnr", per_frame(&|o, g| psnr(o, g))?);
    let ssim_series = MetricSeries::new("ssim", per_frame(&|o, g| ssim_with(o, g, ssim_opts))?);
    let (lpips, tlp) = match perceptual {
        Some(p) => {
            let (values, tlp) = p.sequence_distances(output, ground_truth)?;
            (
                Some(MetricSeries::new("lpips", values)),
                Some(MetricSeries::new("tlp", tlp)),
            )
        }
        None => (None, None),
    };
    let warping_error = match flows {
        Some(f) => Some(MetricSeries::new(
            "warping_error",
            warping_errors(output, f)?,
        )),
        None => None,
    };
    Ok(TemporalReport {
        frames: output.len(),
        psnr: psnr_series,
        ssim: ssim_series,
        lpips,
        perceptual: perceptual.map(PerceptualDistance::name),
        tlp,
        warping_error,
    })
}

/// An error unless `output` and `ground_truth` hold the same number (≥ 2) of frames, frame by
/// frame of one shape.
fn check_sequences(output: &[Image], ground_truth: &[Image]) -> Result<()> {
    if output.len() != ground_truth.len() {
        return Err(MetricsError::ShapeMismatch(format!(
            "{} output frames vs {} ground-truth frames",
            output.len(),
            ground_truth.len()
        )));
    }
    if output.len() < 2 {
        return Err(MetricsError::invalid(
            "temporal metrics need at least two frames",
        ));
    }
    for (t, (o, g)) in output.iter().zip(ground_truth).enumerate() {
        check_same_shape(o, g)
            .map_err(|e| MetricsError::ShapeMismatch(format!("frame {t}: {e}")))?;
    }
    Ok(())
}

/// The flicker of the error for each transition `t = 1..T−1`: the mean over pixels and
/// channels of `|(out_t − gt_t) − (out_{t−1} − gt_{t−1})|`. Zero for an output that tracks the
/// ground truth or keeps a steady error; unlike the Δ of a metric, neither the scene's own
/// motion nor the output's overall quality moves it.
pub fn error_changes(output: &[Image], ground_truth: &[Image]) -> Result<Vec<f64>> {
    check_sequences(output, ground_truth)?;
    let error = |t: usize| {
        output[t]
            .data
            .iter()
            .zip(&ground_truth[t].data)
            .map(|(o, g)| o - g)
    };
    Ok((1..output.len())
        .map(|t| {
            let sum: f64 = error(t)
                .zip(error(t - 1))
                .map(|(now, before)| f64::from((now - before).abs()))
                .sum();
            sum / output[t].data.len().max(1) as f64
        })
        .collect())
}

/// TecoGAN's tLP for each transition `t = 1..T−1`:
/// `100 · |D(gt_{t−1}, gt_t) − D(out_{t−1}, out_t)|`.
pub fn tlp_per_transition<D: PerceptualDistance + ?Sized>(
    output: &[Image],
    ground_truth: &[Image],
    d: &D,
) -> Result<Vec<f64>> {
    (1..output.len())
        .map(|t| {
            let g = d.distance(&ground_truth[t - 1], &ground_truth[t])?;
            let o = d.distance(&output[t - 1], &output[t])?;
            Ok(100.0 * (g - o).abs())
        })
        .collect()
}

/// `measure(previous, current, flow)` of every transition `t = 1..T−1` of `frames` under its
/// flow; an error unless there is one flow per transition, and a failed measure names its
/// transition (and the flow's file when it has one).
fn per_transition<T>(
    frames: &[Image],
    flows: &[Flow],
    measure: impl Fn(&Image, &Image, &Flow) -> Result<T>,
) -> Result<Vec<T>> {
    if flows.len() + 1 != frames.len() {
        return Err(MetricsError::ShapeMismatch(format!(
            "{} flows for {} frames (need one per transition, {})",
            flows.len(),
            frames.len(),
            frames.len().saturating_sub(1)
        )));
    }
    (1..frames.len())
        .map(|t| {
            let flow = &flows[t - 1];
            measure(&frames[t - 1], &frames[t], flow).map_err(|e| match &flow.source {
                Some(path) => MetricsError::format(path, format!("transition {t}: {e}")),
                None => MetricsError::invalid(format!("transition {t}: {e}")),
            })
        })
        .collect()
}

/// Lai et al.'s warping error of each transition `t = 1..T−1` (see the module doc).
pub fn warping_errors(frames: &[Image], flows: &[Flow]) -> Result<Vec<f64>> {
    per_transition(frames, flows, warping_error)
}

/// [`warping_errors`] along a rendered path, whose flows may leave the frame entirely (a
/// model that shows nothing there, or a jump between far views): such a transition is `NaN`,
/// not scored, instead of an error.
pub fn warping_errors_where_defined(frames: &[Image], flows: &[Flow]) -> Result<Vec<f64>> {
    let errors = per_transition(frames, flows, mean_warped_error)?;
    Ok(errors.into_iter().map(|e| e.unwrap_or(f64::NAN)).collect())
}

/// Warping error between `previous` warped by `flow` and `current`; an error when no pixel
/// of the flow is trusted and lands inside `previous`.
pub fn warping_error(previous: &Image, current: &Image, flow: &Flow) -> Result<f64> {
    mean_warped_error(previous, current, flow)?.ok_or_else(|| {
        MetricsError::invalid(
            "no valid pixel: the flow leaves the frame everywhere or the mask is empty",
        )
    })
}

/// The warping error over the pixels the flow carries into `previous`; `None` when there are
/// none.
fn mean_warped_error(previous: &Image, current: &Image, flow: &Flow) -> Result<Option<f64>> {
    let (mut sum, mut count) = (0.0f64, 0usize);
    for_each_warped_pixel(previous, current, flow, |_, now, before| {
        sum += now
            .iter()
            .zip(before)
            .map(|(a, b)| ((a - b) as f64).powi(2))
            .sum::<f64>();
        count += 1;
    })?;
    Ok((count > 0).then(|| sum / count as f64))
}

/// Calls `visit(i, current pixel, previous sampled at i + flow)` for every pixel `i` of
/// `current` whose flow is trusted and lands inside `previous` (bilinear sampling). Checks the
/// shapes and that the flow is finite first.
pub(crate) fn for_each_warped_pixel(
    previous: &Image,
    current: &Image,
    flow: &Flow,
    mut visit: impl FnMut(usize, &[f32], &[f32]),
) -> Result<()> {
    check_same_shape(previous, current)?;
    let (w, h, c) = (current.width, current.height, current.channels);
    if flow.width != w || flow.height != h || flow.data.len() != w * h {
        return Err(MetricsError::ShapeMismatch(format!(
            "flow is {}x{}, frames are {w}x{h}",
            flow.width, flow.height
        )));
    }
    if let Some(v) = &flow.valid
        && v.len() != w * h
    {
        return Err(MetricsError::ShapeMismatch(
            "flow validity mask size".into(),
        ));
    }
    let mut sample = vec![0.0f32; c];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if flow.valid.as_ref().is_some_and(|v| !v[i]) {
                continue;
            }
            let [dx, dy] = flow.data[i];
            if !(dx.is_finite() && dy.is_finite()) {
                return Err(MetricsError::invalid(format!(
                    "flow is not finite at pixel ({x}, {y})"
                )));
            }
            if bilinear(previous, x as f32 + dx, y as f32 + dy, &mut sample) {
                visit(i, current.pixel(x, y), &sample);
            }
        }
    }
    Ok(())
}

/// Bilinear sample at continuous pixel coordinates (pixel centres at integers); `false` if the
/// point is outside the frame.
pub(crate) fn bilinear(img: &Image, x: f32, y: f32, out: &mut [f32]) -> bool {
    if x < 0.0 || y < 0.0 || x > (img.width - 1) as f32 || y > (img.height - 1) as f32 {
        return false;
    }
    let (x0, y0) = (x.floor() as usize, y.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(img.width - 1), (y0 + 1).min(img.height - 1));
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    for (k, o) in out.iter_mut().enumerate() {
        let top = img.get(x0, y0, k) * (1.0 - fx) + img.get(x1, y0, k) * fx;
        let bottom = img.get(x0, y1, k) * (1.0 - fx) + img.get(x1, y1, k) * fx;
        *o = top * (1.0 - fy) + bottom * fy;
    }
    true
}

/// Reads a Middlebury `.flo` optical-flow file (little-endian: magic 202021.25, width, height,
/// then `(u, v)` per pixel). Values above 1e9 mark unknown flow and become invalid pixels.
pub fn read_flo(path: &std::path::Path) -> Result<Flow> {
    let bytes = std::fs::read(path).map_err(|e| MetricsError::io(path, e))?;
    let word = |i: usize| -> Option<[u8; 4]> {
        bytes
            .get(4 * i..4 * i + 4)
            .map(|b| [b[0], b[1], b[2], b[3]])
    };
    let bad = |m: &str| MetricsError::format(path, m.to_string());
    if word(0).map(f32::from_le_bytes) != Some(202021.25) {
        return Err(bad("not a .flo file (bad magic number)"));
    }
    let (w, h) = match (
        word(1).map(i32::from_le_bytes),
        word(2).map(i32::from_le_bytes),
    ) {
        (Some(w), Some(h)) if w > 0 && h > 0 && (w as u64) * (h as u64) < (1 << 31) => {
            (w as usize, h as usize)
        }
        _ => return Err(bad("bad .flo dimensions")),
    };
    if bytes.len() != 12 + 8 * w * h {
        return Err(bad(&format!(
            "{} bytes, expected {} for {w}x{h}",
            bytes.len(),
            12 + 8 * w * h
        )));
    }
    let mut data = Vec::with_capacity(w * h);
    let mut valid = Vec::with_capacity(w * h);
    for i in 0..w * h {
        let u = f32::from_le_bytes(word(3 + 2 * i).expect("length checked"));
        let v = f32::from_le_bytes(word(4 + 2 * i).expect("length checked"));
        let ok = u.is_finite() && v.is_finite() && u.abs() < 1e9 && v.abs() < 1e9;
        valid.push(ok);
        data.push(if ok { [u, v] } else { [0.0, 0.0] });
    }
    if !valid.contains(&true) {
        return Err(bad(
            "no valid flow vector: every value is NaN, infinite or above 1e9 (unknown flow)",
        ));
    }
    Ok(Flow {
        width: w,
        height: h,
        data,
        valid: Some(valid),
        source: Some(path.to_owned()),
    })
}

/// Writes a Middlebury `.flo` file atomically (invalid pixels as 1e10).
pub fn write_flo(path: &std::path::Path, flow: &Flow) -> Result<()> {
    let mut bytes = Vec::with_capacity(12 + 8 * flow.data.len());
    bytes.extend(202021.25f32.to_le_bytes());
    bytes.extend((flow.width as i32).to_le_bytes());
    bytes.extend((flow.height as i32).to_le_bytes());
    for (i, [u, v]) in flow.data.iter().enumerate() {
        let ok = flow.valid.as_ref().is_none_or(|m| m[i]);
        bytes.extend((if ok { *u } else { 1e10 }).to_le_bytes());
        bytes.extend((if ok { *v } else { 1e10 }).to_le_bytes());
    }
    fewview_scene::atomic::write_bytes(path, &bytes)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pattern(w: usize, h: usize, phase: f32) -> Image {
        let mut img = Image::new(w, h, 3);
        for y in 0..h {
            for x in 0..w {
                for c in 0..3 {
                    img.set(
                        x,
                        y,
                        c,
                        0.5 + 0.4 * ((x as f32 * 0.4 + y as f32 * 0.25 + c as f32 + phase).sin()),
                    );
                }
            }
        }
        img
    }

    fn offset(img: &Image, delta: f32) -> Image {
        let mut out = img.clone();
        out.data
            .iter_mut()
            .for_each(|v| *v = (*v + delta).clamp(0.0, 1.0));
        out
    }

    /// Mean absolute difference: a simple perceptual-distance stand-in for the analytic tests.
    struct MeanAbs;
    impl PerceptualDistance for MeanAbs {
        fn name(&self) -> String {
            "mean-abs".into()
        }
        fn distance(&self, a: &Image, b: &Image) -> Result<f64> {
            Ok(a.data
                .iter()
                .zip(&b.data)
                .map(|(x, y)| (x - y).abs() as f64)
                .sum::<f64>()
                / a.data.len() as f64)
        }
    }

    #[test]
    fn static_sequence_has_zero_delta() {
        let gt = pattern(24, 20, 0.0);
        let out = offset(&gt, 0.05);
        let gts = vec![gt; 5];
        let outs = vec![out; 5];
        let r =
            evaluate_sequence(&outs, &gts, &SsimOptions::default(), Some(&MeanAbs), None).unwrap();
        for s in [
            &r.psnr,
            &r.ssim,
            r.lpips.as_ref().unwrap(),
            r.tlp.as_ref().unwrap(),
        ] {
            assert_eq!(
                s.delta,
                MeanStd {
                    mean: 0.0,
                    std: 0.0
                },
                "{}",
                s.name
            );
        }
        assert_eq!(r.tlp.as_ref().unwrap().mean, 0.0);
        // Exact output: infinite PSNR in every frame, still Δ = 0.
        let r = evaluate_sequence(&gts, &gts, &SsimOptions::default(), None, None).unwrap();
        assert_eq!(r.psnr.delta.mean, 0.0);
    }

    /// Frames with a constant error ε except one frame with error 2ε: PSNR jumps by
    /// 20·log10(2) dB into and out of that frame, so with T = 5 and the flicker at t = 2 the
    /// deltas are (0, a, a, 0): mean a/2, std a/2.
    #[test]
    fn one_flickering_frame_gives_the_analytic_delta() {
        let gt = pattern(24, 20, 0.0);
        let eps: f32 = 1.0 / 64.0; // exact in f32, and no clamping at this pattern's range
        let outs: Vec<Image> = (0..5)
            .map(|t| offset(&gt, if t == 2 { 2.0 * eps } else { eps }))
            .collect();
        let gts = vec![gt.clone(); 5];
        let r =
            evaluate_sequence(&outs, &gts, &SsimOptions::default(), Some(&MeanAbs), None).unwrap();
        let a = 20.0 * 2f64.log10();
        assert!(
            (r.psnr.delta.mean - a / 2.0).abs() < 1e-4,
            "{:?}",
            r.psnr.delta
        );
        assert!(
            (r.psnr.delta.std - a / 2.0).abs() < 1e-4,
            "{:?}",
            r.psnr.delta
        );
        // tLP with a static ground truth: 100·|0 − D(out_{t−1}, out_t)| = 100·ε at the two
        // transitions touching the flicker, 0 elsewhere.
        let tlp = &r.tlp.as_ref().unwrap().per_frame;
        let want = [0.0, 100.0 * eps as f64, 100.0 * eps as f64, 0.0];
        for (v, w) in tlp.iter().zip(want) {
            assert!((v - w).abs() < 1e-6, "{tlp:?}");
        }
        // SSIM deltas have the same (0, b, b, 0) structure.
        let d = frame_deltas(&r.ssim.per_frame);
        assert!(
            d[0].abs() < 1e-12 && d[3].abs() < 1e-12 && (d[1] - d[2]).abs() < 1e-9 && d[1] > 0.0,
            "{d:?}"
        );
    }

    #[test]
    fn error_changes_follow_the_error_not_the_frames() {
        // Truth brightens 0.1 a frame; the output follows it with a steady error of 0.05, then
        // jumps to an error of −0.02.
        let flat = |v: f32| Image::from_vec(4, 3, 3, vec![v; 36]);
        let truth: Vec<Image> = (0..4).map(|t| flat(0.2 + 0.1 * t as f32)).collect();
        let output = vec![flat(0.25), flat(0.35), flat(0.45), flat(0.48)];
        let changes = error_changes(&output, &truth).unwrap();
        assert_eq!(changes.len(), 3);
        for (got, want) in changes.iter().zip([0.0, 0.0, 0.07]) {
            assert!((got - want).abs() < 1e-6, "{changes:?}");
        }
        assert!(error_changes(&output[..1], &truth[..1]).is_err());
        assert!(error_changes(&output, &truth[..3]).is_err());
    }

    #[test]
    fn a_transition_whose_flow_leaves_the_frame_is_not_scored() {
        let frames = [
            pattern(30, 16, 0.0),
            pattern(30, 16, 0.0),
            pattern(30, 16, 0.1),
        ];
        let flow = |dx: f32| Flow {
            width: 30,
            height: 16,
            data: vec![[dx, 0.0]; 30 * 16],
            valid: None,
            source: None,
        };
        // Transition 1 is still and exact; transition 2's flow points 100 px off the frame.
        let flows = [flow(0.0), flow(-100.0)];
        let e = warping_errors_where_defined(&frames, &flows).unwrap();
        assert_eq!(e[0], 0.0);
        assert!(e[1].is_nan(), "{e:?}");
        let err = warping_errors(&frames, &flows).unwrap_err().to_string();
        assert!(
            err.contains("transition 2:") && err.contains("no valid pixel"),
            "{err}"
        );
        // The series' mean and Δ leave the unscored transition out.
        let series = MetricSeries::over_scored("warping_error", vec![1.0, f64::NAN, 3.0, 4.0]);
        assert_eq!(series.mean, 8.0 / 3.0);
        assert_eq!(series.delta.mean, 1.0);
        assert!(series.per_frame[1].is_nan());
    }

    #[test]
    fn warping_error_of_an_exact_flow_is_zero() {
        // Frame t is frame t−1 shifted right by 2 pixels: pixel x of frame t shows x − 2 of t−1.
        let prev = pattern(30, 16, 0.0);
        let mut cur = Image::new(30, 16, 3);
        for y in 0..16 {
            for x in 0..30 {
                for c in 0..3 {
                    cur.set(x, y, c, prev.get(x.saturating_sub(2), y, c));
                }
            }
        }
        let flow = Flow {
            width: 30,
            height: 16,
            data: vec![[-2.0, 0.0]; 30 * 16],
            valid: None,
            source: None,
        };
        // Pixels x < 2 sample outside frame t−1 and are excluded.
        assert!(warping_error(&prev, &cur, &flow).unwrap() < 1e-12);
        // A half-pixel flow interpolates: error = mean over channels' squared (half-step) differences.
        let half = Flow {
            width: 30,
            height: 16,
            data: vec![[-1.5, 0.0]; 30 * 16],
            valid: None,
            source: None,
        };
        let e = warping_error(&prev, &cur, &half).unwrap();
        let mut reference = (0.0, 0);
        for y in 0..16 {
            for x in 2..30 {
                let mut s = 0.0;
                for c in 0..3 {
                    let v = 0.5 * prev.get(x - 2, y, c) + 0.5 * prev.get(x - 1, y, c);
                    s += ((cur.get(x, y, c) - v) as f64).powi(2);
                }
                reference.0 += s;
                reference.1 += 1;
            }
        }
        assert!((e - reference.0 / reference.1 as f64).abs() < 1e-9, "{e}");
        let err = warping_errors(&[prev.clone(), cur.clone()], &[])
            .unwrap_err()
            .to_string();
        assert!(err.contains("0 flows for 2 frames"), "{err}");
    }

    #[test]
    fn flo_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f.flo");
        let flow = Flow {
            width: 3,
            height: 2,
            data: vec![
                [0.5, -1.0],
                [2.0, 0.0],
                [0.0, 0.0],
                [1.0, 1.0],
                [-3.5, 0.25],
                [0.0, 9.0],
            ],
            valid: Some(vec![true, true, false, true, true, true]),
            source: None,
        };
        write_flo(&path, &flow).unwrap();
        let back = read_flo(&path).unwrap();
        assert_eq!(back.source.as_deref(), Some(path.as_path()));
        assert_eq!(
            Flow {
                source: None,
                ..back
            },
            flow
        );
        std::fs::write(&path, b"nope").unwrap();
        assert!(read_flo(&path).unwrap_err().to_string().contains("f.flo"));
    }

    /// A flow file of the wrong size names the file (and the transition); one with no valid
    /// vector (all NaN or 1e30) is refused when read, naming the file.
    #[test]
    fn flow_errors_name_the_flow_file() {
        let dir = tempfile::tempdir().unwrap();
        let frames = [pattern(4, 3, 0.0), pattern(4, 3, 0.5), pattern(4, 3, 1.0)];
        let flow = |w: usize, h: usize, v: f32| Flow {
            width: w,
            height: h,
            data: vec![[v, 0.0]; w * h],
            valid: None,
            source: None,
        };
        let (good, small) = (dir.path().join("0.flo"), dir.path().join("1.flo"));
        write_flo(&good, &flow(4, 3, 0.0)).unwrap();
        write_flo(&small, &flow(2, 2, 0.0)).unwrap();
        let flows = [read_flo(&good).unwrap(), read_flo(&small).unwrap()];
        let e = warping_errors(&frames, &flows).unwrap_err().to_string();
        assert!(e.contains("1.flo: transition 2: "), "{e}");
        assert!(e.contains("flow is 2x2, frames are 4x3"), "{e}");
        for bad in [f32::NAN, 1e30] {
            write_flo(&small, &flow(4, 3, bad)).unwrap();
            let e = read_flo(&small).unwrap_err().to_string();
            assert!(e.contains("1.flo: no valid flow vector"), "{e}");
        }
    }

    #[test]
    fn rejects_mismatched_sequences() {
        let a = pattern(16, 16, 0.0);
        let b = pattern(16, 12, 0.0);
        assert!(
            evaluate_sequence(
                &[a.clone(), a.clone()],
                std::slice::from_ref(&a),
                &SsimOptions::default(),
                None,
                None
            )
            .is_err()
        );
        let err = evaluate_sequence(
            &[a.clone(), a.clone()],
            &[a.clone(), b],
            &SsimOptions::default(),
            None,
            None,
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("frame 1"), "{err}");
    }
}
