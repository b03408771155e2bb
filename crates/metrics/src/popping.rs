//! Local popping: how much a small part of a video changes at once between two frames, after
//! the camera's motion is taken out.
//!
//! A transition between photos whose colours disagree can fail in two ways. A global ramp (the
//! whole frame brightening a little each frame) is what a natural transition looks like; a seam
//! or a patch whose colour switches from one frame to the next is what a viewer reacts to. The
//! warping error (Lai et al. 2018) averages over the frame and cannot tell the two apart. Local
//! popping looks at the tail instead:
//!
//! * both frames low-passed with a Gaussian of [`POPPING_SIGMA`] pixels, and the pixels within
//!   2σ of a motion boundary (an occlusion edge, where the low-pass mixes surfaces that move
//!   differently) left out;
//! * per transition `t`, the difference map `|frame_t − warp(frame_{t−1})|` over the pixels both
//!   frames show (the exact backward flow and its occlusion mask, bilinear sampling), each
//!   pixel's value the largest of its channels' absolute differences;
//! * its 99th percentile over those pixels: what the worst 1 % of the frame does;
//! * **local popping** = the 99th percentile of that over the transitions: the worst moments of
//!   the clip, ignoring a single outlier frame.
//!
//! The low-pass is the one step beyond the literal per-pixel difference. Bilinear resampling of
//! a sharp edge, and texture finer than the pixels (which aliases differently in every frame),
//! leave differences of a tenth of the contrast where nothing changed: by the per-pixel measure
//! a ray-traced truth seen along its exact flow pops more than a blurry render, and a checkered
//! floor more than a patch that switches colour. A Gaussian of two pixels makes the frames
//! smooth enough for bilinear sampling to follow them (the demo's Lambertian truth along its
//! exact flow: 33 levels of 255 per pixel, 9 after a one-pixel Gaussian, 5 after two), while a
//! patch that switches colour keeps its switch. [`local_popping_with`] with σ = 0 gives the per-pixel form. Percentiles are
//! nearest-rank (`⌈q·n⌉`-th smallest).

use fewview_scene::Image;

use crate::error::{MetricsError, Result};
use crate::temporal::{Flow, for_each_warped_pixel};
use fewview_geom::blend::gaussian_blur;

/// The percentile of local popping, over pixels and over transitions.
pub const POPPING_PERCENTILE: f64 = 0.99;

/// Standard deviation (pixels) of the Gaussian the frames are low-passed with.
pub const POPPING_SIGMA: f32 = 2.0;

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
    let mut map = vec![f32::NAN; current.num_pixels()];
    for_each_warped_pixel(previous, current, flow, |i, now, before| {
        map[i] = now
            .iter()
            .zip(before)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max);
    })?;
    Ok(map)
}

/// Largest flow difference (pixels) between neighbours that still counts as one motion.
pub const MOTION_BOUNDARY: f32 = 0.25;

/// Pixels within `reach` pixels (a square) of a motion boundary: a pixel whose flow differs
/// from a 4-neighbour's by more than [`MOTION_BOUNDARY`], or whose neighbour's flow is not
/// trusted. A low-pass mixes the two sides of such a boundary, which move differently, so no
/// single flow warps the mixture.
pub fn near_motion_boundaries(flow: &Flow, reach: usize) -> Vec<bool> {
    let (w, h) = (flow.width, flow.height);
    let trusted = |i: usize| flow.valid.as_ref().is_none_or(|v| v[i]);
    let mut edge = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let differs = |j: usize| {
                !trusted(i) || !trusted(j) || {
                    let (a, b) = (flow.data[i], flow.data[j]);
                    (a[0] - b[0]).hypot(a[1] - b[1]) > MOTION_BOUNDARY
                }
            };
            for j in [(x + 1 < w).then_some(i + 1), (y + 1 < h).then_some(i + w)]
                .into_iter()
                .flatten()
            {
                if differs(j) {
                    edge[i] = true;
                    edge[j] = true;
                }
            }
        }
    }
    dilate(&edge, w, h, reach)
}

/// `mask` grown by `reach` pixels in a square (separable maximum).
fn dilate(mask: &[bool], w: usize, h: usize, reach: usize) -> Vec<bool> {
    let mut rows = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            let (lo, hi) = (x.saturating_sub(reach), (x + reach).min(w - 1));
            rows[y * w + x] = (lo..=hi).any(|k| mask[y * w + k]);
        }
    }
    let mut out = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            let (lo, hi) = (y.saturating_sub(reach), (y + reach).min(h - 1));
            out[y * w + x] = (lo..=hi).any(|k| rows[k * w + x]);
        }
    }
    out
}

/// `image` with each channel blurred by a Gaussian of `sigma` pixels (mirror border; `sigma`
/// 0 leaves it as it is).
pub fn low_pass(image: &Image, sigma: f32) -> Image {
    if sigma <= 0.0 {
        return image.clone();
    }
    let (w, h, c) = (image.width, image.height, image.channels);
    let mut out = image.clone();
    for k in 0..c {
        let plane: Vec<f32> = image.data.iter().skip(k).step_by(c).copied().collect();
        let blurred = gaussian_blur(&plane, w, h, sigma);
        for (p, v) in blurred.into_iter().enumerate() {
            out.data[p * c + k] = v;
        }
    }
    out
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

/// Local popping of `frames` under `flows` (one backward flow per transition), frames
/// low-passed with [`POPPING_SIGMA`], and the difference map of every transition (for pictures
/// of where it pops).
pub fn local_popping(frames: &[Image], flows: &[Flow]) -> Result<(Popping, Vec<Vec<f32>>)> {
    local_popping_with(frames, flows, POPPING_SIGMA)
}

/// [`local_popping`] with another low-pass (σ in pixels; 0: the frames as they are).
pub fn local_popping_with(
    frames: &[Image],
    flows: &[Flow],
    sigma: f32,
) -> Result<(Popping, Vec<Vec<f32>>)> {
    if frames.len() < 2 || flows.len() + 1 != frames.len() {
        return Err(MetricsError::ShapeMismatch(format!(
            "{} flows for {} frames (need at least 2 frames and one flow per transition)",
            flows.len(),
            frames.len()
        )));
    }
    let frames: Vec<Image> = frames.iter().map(|f| low_pass(f, sigma)).collect();
    let reach = (2.0 * sigma).ceil() as usize;
    let maps = (1..frames.len())
        .map(|t| {
            let mut map = difference_map(&frames[t - 1], &frames[t], &flows[t - 1])
                .map_err(|e| MetricsError::invalid(format!("transition {t}: {e}")))?;
            if reach > 0 {
                let near = near_motion_boundaries(&flows[t - 1], reach);
                for (v, n) in map.iter_mut().zip(near) {
                    if n {
                        *v = f32::NAN;
                    }
                }
            }
            Ok(map)
        })
        .collect::<Result<Vec<_>>>()?;
    Ok((popping_of_maps(&maps, None)?, maps))
}

/// Local popping from the difference maps of [`local_popping_with`] (one per transition,
/// `NaN` where a pixel is not scored), over the pixels `keep` marks (all without it; one mask
/// per map). The region of a clip a method can be asked about, e.g. where two training photos
/// overlap, is the caller's choice.
pub fn popping_of_maps(maps: &[Vec<f32>], keep: Option<&[Vec<bool>]>) -> Result<Popping> {
    if let Some(k) = keep
        && (k.len() != maps.len() || k.iter().zip(maps).any(|(k, m)| k.len() != m.len()))
    {
        return Err(MetricsError::ShapeMismatch(
            "one mask per difference map, of its size".into(),
        ));
    }
    let per_transition: Vec<f64> = maps
        .iter()
        .enumerate()
        .map(|(t, m)| {
            let kept = m
                .iter()
                .enumerate()
                .filter(|&(p, _)| keep.is_none_or(|k| k[t][p]))
                .map(|(_, &v)| v as f64);
            percentile(kept, POPPING_PERCENTILE).unwrap_or(f64::NAN)
        })
        .collect();
    summarised(
        per_transition,
        "no transition has a co-visible pixel: popping is undefined",
    )
}

/// [`Popping`] of per-transition values: their 99th percentile and the mean of the finite ones;
/// `undefined` is the error when no value is finite.
fn summarised(per_transition: Vec<f64>, undefined: &str) -> Result<Popping> {
    let p99 = percentile(per_transition.iter().copied(), POPPING_PERCENTILE)
        .ok_or_else(|| MetricsError::invalid(undefined))?;
    let finite: Vec<f64> = per_transition
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    let mean = finite.iter().sum::<f64>() / finite.len() as f64;
    Ok(Popping {
        per_transition,
        p99,
        mean,
    })
}

/// Popping in excess of a reference's along the same flows: per transition, how far the clip's
/// popping exceeds the reference's (`max(0, clip − reference)`; `NaN` where either is), then
/// its 99th percentile and mean as in [`Popping`]. With a ray-traced truth as the reference, what
/// the truth itself does along the path (a moving highlight, a gain ramp between photos of
/// different exposure) is not counted against the clip. Both must have the same transitions.
pub fn popping_excess(clip: &Popping, reference: &Popping) -> Result<Popping> {
    if clip.per_transition.len() != reference.per_transition.len() {
        return Err(MetricsError::ShapeMismatch(format!(
            "{} transitions against the reference's {}",
            clip.per_transition.len(),
            reference.per_transition.len()
        )));
    }
    let per_transition: Vec<f64> = clip
        .per_transition
        .iter()
        .zip(&reference.per_transition)
        .map(|(c, r)| {
            if c.is_finite() && r.is_finite() {
                (c - r).max(0.0)
            } else {
                f64::NAN
            }
        })
        .collect();
    summarised(
        per_transition,
        "no transition is scored in both: popping excess is undefined",
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A still camera over five frames: the truth brightens by 10 levels at transition 2, the
    /// clip by 25 there and by 4 at transition 3, where the truth holds. The excess is 15 and 4
    /// levels at those transitions and 0 elsewhere, whatever the low-pass (the frames are flat).
    #[test]
    fn the_excess_over_the_truth_is_what_the_clip_adds() {
        let (w, h) = (12, 10);
        let clip_levels = [100.0, 100.0, 125.0, 129.0, 129.0];
        let truth_levels = [100.0, 100.0, 110.0, 110.0, 110.0];
        let frames = |levels: &[f32]| -> Vec<Image> {
            levels
                .iter()
                .map(|&l| Image::filled(w, h, &[l / 255.0; 3]))
                .collect()
        };
        let flows = vec![still(w, h); 4];
        let clip = local_popping(&frames(&clip_levels), &flows).unwrap().0;
        let truth = local_popping(&frames(&truth_levels), &flows).unwrap().0;
        let excess = popping_excess(&clip, &truth).unwrap();
        let levels: Vec<f64> = excess.per_transition.iter().map(|v| v * 255.0).collect();
        for (got, want) in levels.iter().zip([0.0, 15.0, 4.0, 0.0]) {
            assert!((got - want).abs() < 1e-3, "{levels:?}");
        }
        assert!((excess.p99 * 255.0 - 15.0).abs() < 1e-3);
        assert!((excess.mean * 255.0 - 19.0 / 4.0).abs() < 1e-3);
        let short = Popping {
            per_transition: vec![0.0; 3],
            p99: 0.0,
            mean: 0.0,
        };
        assert!(popping_excess(&clip, &short).is_err());
    }

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
        let (p, maps) = local_popping_with(&ramp, &flows, 0.0).unwrap();
        assert!((p.p99 - 0.01).abs() < 1e-5, "{p:?}");
        assert_eq!(maps.len(), 4);
        // A 4×4 patch (4 % of the frame) switches its green channel by 0.3 at one transition:
        // above the 99th percentile of its pixels, so it shows.
        let mut pop: Vec<Image> = (0..5).map(|_| frame(0.3, 0.3)).collect();
        for f in &mut pop[3..] {
            *f = frame(0.3, 0.6);
        }
        let (p, maps) = local_popping_with(&pop, &flows, 0.0).unwrap();
        assert!((p.per_transition[2] - 0.3).abs() < 1e-5, "{p:?}");
        assert_eq!(p.per_transition[0], 0.0);
        assert!((p.p99 - 0.3).abs() < 1e-5);
        assert!((maps[2][0] - 0.3).abs() < 1e-6 && maps[2][10 * w + 10] == 0.0);
        // The warping error of the switch is small: it averages over the frame.
        let we = crate::temporal::warping_error(&pop[2], &pop[3], &flows[2]).unwrap();
        assert!(we < 0.004, "{we}");
    }

    #[test]
    fn a_mask_scores_only_the_pixels_it_keeps() {
        // Two transitions of 10 pixels: values 0.0..0.9, and a single hot pixel in the second.
        let first: Vec<f32> = (0..10).map(|i| i as f32 / 10.0).collect();
        let mut second = vec![0.05f32; 10];
        second[9] = 1.0;
        second[0] = f32::NAN;
        let maps = vec![first, second];
        let all = popping_of_maps(&maps, None).unwrap();
        assert_eq!(all.per_transition, vec![0.9f32 as f64, 1.0]);
        // Keeping the first five pixels of each: 0.4 and 0.05 (the NaN stays out).
        let keep: Vec<Vec<bool>> = (0..2).map(|_| (0..10).map(|p| p < 5).collect()).collect();
        let kept = popping_of_maps(&maps, Some(&keep)).unwrap();
        assert_eq!(kept.per_transition, vec![0.4f32 as f64, 0.05f32 as f64]);
        assert_eq!(kept.p99, 0.4f32 as f64);
        assert!(((kept.mean - (0.4 + 0.05) / 2.0) as f32).abs() < 1e-6);
        // A transition with nothing kept is NaN and left out of the percentile.
        let none: Vec<Vec<bool>> = vec![vec![false; 10], vec![true; 10]];
        let p = popping_of_maps(&maps, Some(&none)).unwrap();
        assert!(p.per_transition[0].is_nan() && p.p99 == 1.0);
        assert!(popping_of_maps(&maps, Some(&none[..1])).is_err());
    }

    /// A sharp edge moving by a fraction of a pixel: the scene does not change, bilinear
    /// resampling of the edge does; a patch that switches colour does change.
    #[test]
    fn the_low_pass_quiets_a_moving_edge_but_not_a_switching_patch() {
        let (w, h) = (40, 30);
        // Columns box-filtered from a step at x = e (pixel i covers [i, i + 1)).
        let edge = |e: f32| {
            let mut img = Image::new(w, h, 3);
            for y in 0..h {
                for x in 0..w {
                    let cover = (x as f32 + 1.0 - e).clamp(0.0, 1.0);
                    img.set(x, y, 0, 0.2 + 0.6 * cover);
                }
            }
            img
        };
        // Frame 1 is frame 0 moved 0.5 px right: its pixel x shows frame 0's x − 0.5.
        let frames = [edge(20.25), edge(20.75)];
        let mut flow = still(w, h);
        flow.data.iter_mut().for_each(|d| *d = [-0.5, 0.0]);
        let raw = local_popping_with(&frames, std::slice::from_ref(&flow), 0.0)
            .unwrap()
            .0;
        let smooth = local_popping(&frames, std::slice::from_ref(&flow))
            .unwrap()
            .0;
        assert!(raw.p99 > 0.05, "{raw:?}");
        assert!(smooth.p99 < 0.3 * raw.p99, "{smooth:?} vs {raw:?}");
        // A 10×10 patch switching by 0.2 keeps most of its switch after the low-pass.
        let base = Image::filled(w, h, &[0.5, 0.5, 0.5]);
        let mut patch = base.clone();
        for y in 10..20 {
            for x in 10..20 {
                patch.set(x, y, 0, 0.7);
            }
        }
        let still_flow = [still(w, h)];
        let p = local_popping(&[base, patch], &still_flow).unwrap().0;
        assert!(p.p99 > 0.18, "{p:?}");
    }

    #[test]
    fn motion_boundaries_and_untrusted_pixels_are_left_out_with_their_surroundings() {
        let (w, h) = (12, 5);
        // The left half is still, the right half moves one pixel: a boundary between x 5 and 6.
        let mut flow = still(w, h);
        for y in 0..h {
            for x in 6..w {
                flow.data[y * w + x] = [1.0, 0.0];
            }
        }
        let near = near_motion_boundaries(&flow, 2);
        for y in 0..h {
            for x in 0..w {
                // Columns 5 and 6 border each other; two pixels around them.
                assert_eq!(near[y * w + x], (3..=8).contains(&x), "({x}, {y})");
            }
        }
        // An untrusted pixel is a boundary too; a small flow difference is not.
        let mut gentle = still(w, h);
        gentle
            .data
            .iter_mut()
            .enumerate()
            .for_each(|(i, d)| *d = [0.02 * (i % w) as f32, 0.0]);
        gentle.valid = Some((0..w * h).map(|i| i != 2 * w + 10).collect());
        let near = near_motion_boundaries(&gentle, 1);
        // The untrusted pixel and its four neighbours, grown by one pixel.
        let expect = |x: usize, y: usize| {
            [(10, 2), (9, 2), (11, 2), (10, 1), (10, 3)]
                .iter()
                .any(|&(ex, ey): &(usize, usize)| ex.abs_diff(x) <= 1 && ey.abs_diff(y) <= 1)
        };
        for y in 0..h {
            for x in 0..w {
                assert_eq!(near[y * w + x], expect(x, y), "({x}, {y})");
            }
        }
    }

    #[test]
    fn the_low_pass_is_a_per_channel_gaussian() {
        let mut img = Image::new(9, 9, 3);
        img.set(4, 4, 1, 1.0);
        let blurred = low_pass(&img, 1.0);
        // The impulse response: a normalised Gaussian in green, nothing in the other channels.
        let g = |d: f32| (-d * d / 2.0).exp();
        let norm: f32 = (-3..=3).map(|d| g(d as f32)).sum::<f32>();
        let expect = g(1.0) * g(0.0) / (norm * norm);
        assert!((blurred.get(5, 4, 1) - expect).abs() < 1e-6);
        assert_eq!(blurred.get(5, 4, 0), 0.0);
        assert_eq!(low_pass(&img, 0.0), img);
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
