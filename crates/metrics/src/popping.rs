//! Local popping: how much a small part of a video changes at once between two frames, after
//! the camera's motion is taken out.
//!
//! A transition between photos whose colours disagree can fail in two ways. A global ramp (the
//! whole frame brightening a little each frame) is what a natural transition looks like; a seam
//! or a patch whose colour switches from one frame to the next is what a viewer reacts to. The
//! warping error (Lai et al. 2018) averages over the frame and cannot tell the two apart. Local
//! popping looks at the tail instead:
//!
//! * per transition `t`, the difference map `|frame_t − warp(frame_{t−1})|` over the pixels both
//!   frames show (the exact backward flow and its occlusion mask, bilinear sampling), each
//!   pixel's value the largest of its channels' absolute differences;
//! * its 99th percentile over those pixels: what the worst 1 % of the frame does;
//! * **local popping** = the 99th percentile of that over the transitions: the worst moments of
//!   the clip, ignoring a single outlier frame.
//!
//! Percentiles are nearest-rank (`⌈q·n⌉`-th smallest).

use fewview_scene::Image;

use crate::error::{MetricsError, Result, check_same_shape};
use crate::temporal::{Flow, bilinear};

/// The percentile of local popping, over pixels and over transitions.
pub const POPPING_PERCENTILE: f64 = 0.99;

/// Local popping of a clip (see the module docs).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Popping {
    /// The 99th percentile over co-visible pixels of each transition `t = 1..T−1`.
    pub per_transition: Vec<f64>,
    /// The 99th percentile of `per_transition`.
    pub p99: f64,
    /// The mean of `per_transition`.
    pub mean: f64,
}

/// Per-pixel `max_c |current − warp(previous)|` where the flow is trusted and lands inside
/// `previous`; `NaN` elsewhere.
pub fn difference_map(previous: &Image, current: &Image, flow: &Flow) -> Result<Vec<f32>> {
    check_same_shape(previous, current)?;
    let (w, h, c) = (current.width, current.height, current.channels);
    if flow.width != w || flow.height != h || flow.data.len() != w * h {
        return Err(MetricsError::ShapeMismatch(format!(
            "flow is {}x{}, frames are {w}x{h}",
            flow.width, flow.height
        )));
    }
    if flow.valid.as_ref().is_some_and(|v| v.len() != w * h) {
        return Err(MetricsError::ShapeMismatch(
            "flow validity mask size".into(),
        ));
    }
    let mut sample = vec![0.0f32; c];
    let mut map = vec![f32::NAN; w * h];
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
                map[i] = current
                    .pixel(x, y)
                    .iter()
                    .zip(&sample)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f32::max);
            }
        }
    }
    Ok(map)
}

/// The nearest-rank `q`-quantile (`0 < q ≤ 1`) of the finite values, `None` when there are none.
pub fn percentile(values: impl IntoIterator<Item = f64>, q: f64) -> Option<f64> {
    let mut v: Vec<f64> = values.into_iter().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let rank = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len());
    Some(v[rank - 1])
}

/// Local popping of `frames` under `flows` (one backward flow per transition), and the
/// difference map of every transition (for pictures of where it pops).
pub fn local_popping(frames: &[Image], flows: &[Flow]) -> Result<(Popping, Vec<Vec<f32>>)> {
    if frames.len() < 2 || flows.len() + 1 != frames.len() {
        return Err(MetricsError::ShapeMismatch(format!(
            "{} flows for {} frames (need at least 2 frames and one flow per transition)",
            flows.len(),
            frames.len()
        )));
    }
    let maps = (1..frames.len())
        .map(|t| {
            difference_map(&frames[t - 1], &frames[t], &flows[t - 1])
                .map_err(|e| MetricsError::invalid(format!("transition {t}: {e}")))
        })
        .collect::<Result<Vec<_>>>()?;
    let per_transition: Vec<f64> = maps
        .iter()
        .map(|m| percentile(m.iter().map(|&v| v as f64), POPPING_PERCENTILE).unwrap_or(f64::NAN))
        .collect();
    let p99 = percentile(per_transition.iter().copied(), POPPING_PERCENTILE).ok_or_else(|| {
        MetricsError::invalid("no transition has a co-visible pixel: popping is undefined")
    })?;
    let finite: Vec<f64> = per_transition
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    let mean = finite.iter().sum::<f64>() / finite.len() as f64;
    Ok((
        Popping {
            per_transition,
            p99,
            mean,
        },
        maps,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn still(w: usize, h: usize) -> Flow {
        Flow {
            width: w,
            height: h,
            data: vec![[0.0, 0.0]; w * h],
            valid: None,
            source: None,
        }
    }

    #[test]
    fn percentiles_are_nearest_rank() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(percentile(v.iter().copied(), 0.99), Some(99.0));
        assert_eq!(percentile(v.iter().copied(), 1.0), Some(100.0));
        assert_eq!(percentile(v.iter().copied(), 0.5), Some(50.0));
        assert_eq!(percentile([3.0, f64::NAN, 1.0], 0.99), Some(3.0));
        assert_eq!(percentile([f64::NAN], 0.5), None);
    }

    #[test]
    fn a_global_ramp_pops_less_than_a_switching_patch() {
        let (w, h) = (20, 20);
        let frame = |level: f32, patch: f32| {
            let mut img = Image::filled(w, h, &[level, level, level]);
            for y in 0..4 {
                for x in 0..4 {
                    img.set(x, y, 1, patch);
                }
            }
            img
        };
        // The whole frame brightens by 0.01 per frame: popping 0.01.
        let ramp: Vec<Image> = (0..5)
            .map(|i| frame(0.3 + 0.01 * i as f32, 0.3 + 0.01 * i as f32))
            .collect();
        let flows = vec![still(w, h); 4];
        let (p, maps) = local_popping(&ramp, &flows).unwrap();
        assert!((p.p99 - 0.01).abs() < 1e-5, "{p:?}");
        assert_eq!(maps.len(), 4);
        // A 4×4 patch (4 % of the frame) switches its green channel by 0.3 at one transition:
        // above the 99th percentile of its pixels, so it shows.
        let mut pop: Vec<Image> = (0..5).map(|_| frame(0.3, 0.3)).collect();
        for f in &mut pop[3..] {
            *f = frame(0.3, 0.6);
        }
        let (p, maps) = local_popping(&pop, &flows).unwrap();
        assert!((p.per_transition[2] - 0.3).abs() < 1e-5, "{p:?}");
        assert_eq!(p.per_transition[0], 0.0);
        assert!((p.p99 - 0.3).abs() < 1e-5);
        assert!((maps[2][0] - 0.3).abs() < 1e-6 && maps[2][10 * w + 10] == 0.0);
        // The warping error of the switch is small: it averages over the frame.
        let we = crate::temporal::warping_error(&pop[2], &pop[3], &flows[2]).unwrap();
        assert!(we < 0.004, "{we}");
    }

    #[test]
    fn the_flow_is_followed_and_occluded_pixels_are_left_out() {
        let (w, h) = (12, 8);
        let mut a = Image::new(w, h, 3);
        for y in 0..h {
            for x in 0..w {
                a.set(x, y, 0, x as f32 / w as f32);
            }
        }
        // Frame b is frame a moved one pixel to the right: pixel x of b shows a's x − 1.
        let mut b = Image::new(w, h, 3);
        for y in 0..h {
            for x in 1..w {
                b.set(x, y, 0, a.get(x - 1, y, 0));
            }
        }
        let mut flow = still(w, h);
        flow.data.iter_mut().for_each(|d| *d = [-1.0, 0.0]);
        let mut valid = vec![true; w * h];
        valid[5] = false;
        flow.valid = Some(valid);
        let map = difference_map(&a, &b, &flow).unwrap();
        for y in 0..h {
            assert!(map[y * w].is_nan(), "column 0 lands outside frame a");
            for x in 1..w {
                if y * w + x != 5 {
                    assert_eq!(map[y * w + x], 0.0, "({x}, {y})");
                }
            }
        }
        assert!(map[5].is_nan());
        assert!(difference_map(&a, &Image::new(w, h + 1, 3), &flow).is_err());
    }
}
