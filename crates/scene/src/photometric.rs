//! Per-photo exposure, white balance and vignetting, as a phone's automatic exposure gives them:
//! photos of one scene whose colours disagree. The fusion paper ("Splat-based Gradient-domain
//! Fusion for Seamless View Transition") studies transitions on such captures (Tanks and Temples,
//! DL3DV); [`PhotoJitter`] makes them reproducibly from photos that agree (the demo scene, or a
//! dataset's training photos).
//!
//! A photo's disturbance is a gain per pixel and channel in linear light ([`PhotoGain`]):
//!
//! * exposure `2^u`, `u ~ U(−EV, EV)`;
//! * white balance: one factor `1 + F·v_c`, `v_c ~ U(−1, 1)`, per channel;
//! * vignetting of strength `S`: a radial falloff `1 − a·r²` (`a ~ S·U(0.5, 1)`, `r` the distance
//!   from the image centre, 1 at the corners) times a gradient across the frame
//!   `1 + b·(d · p)` (`b ~ S·U(0, 0.5)`, `d` a random unit direction, `p ∈ [−1, 1]²` the position in
//!   the frame), so the gain varies over the photo and differs between photos.
//!
//! Images are sRGB-encoded: the gain applies to the decoded linear values, which are encoded
//! again and clipped to `[0, 1]`, as a camera's exposure acts on the light before its tone curve.
//!
//! The draws of photo `i` depend only on the seed and `i` (SplitMix64, so that they do not change
//! with a random-number crate's version), so a photo's gain is the same whichever views train.
//! Between two photos the gain is interpolated log-linearly ([`PhotoGain::log2_between`]): the
//! smooth colour transition a camera moving from one photo to the other would see.

use serde::{Deserialize, Serialize};

use crate::dataset::Dataset;
use crate::image::Image;

/// The largest exposure jitter accepted, in EV: beyond it most of a photo clips.
pub const MAX_EXPOSURE_EV: f64 = 3.0;
/// The largest white-balance jitter: a channel's factor stays within `1 ± 0.5`.
pub const MAX_WHITE_BALANCE: f64 = 0.5;
/// The largest vignetting strength: the gain stays positive everywhere below 1.
pub const MAX_VIGNETTING: f64 = 0.9;

/// How much the photos' exposure, white balance and vignetting may differ (all 0: not at all).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PhotoJitter {
    /// Exposure range `EV`: each photo gets `2^u`, `u ~ U(−EV, EV)`.
    pub exposure_ev: f64,
    /// White balance range `F`: each channel gets `1 + F·v`, `v ~ U(−1, 1)`.
    pub white_balance: f64,
    /// Vignetting strength `S` (see the module docs).
    pub vignetting: f64,
    /// Seed of the draws.
    pub seed: u64,
}

impl PhotoJitter {
    /// Whether every photo keeps its colours.
    pub fn is_none(&self) -> bool {
        self.exposure_ev == 0.0 && self.white_balance == 0.0 && self.vignetting == 0.0
    }

    /// Checks the ranges; the message names the setting and its limit.
    pub fn validate(&self) -> Result<(), String> {
        let check = |name: &str, value: f64, max: f64| {
            if value.is_finite() && (0.0..=max).contains(&value) {
                Ok(())
            } else {
                Err(format!("{name} {value} is not in [0, {max}]"))
            }
        };
        check("exposure jitter (EV)", self.exposure_ev, MAX_EXPOSURE_EV)?;
        check(
            "white-balance jitter",
            self.white_balance,
            MAX_WHITE_BALANCE,
        )?;
        check("vignetting", self.vignetting, MAX_VIGNETTING)
    }

    /// The gain of photo `index` (its position in the dataset's view list).
    pub fn gain(&self, index: usize) -> PhotoGain {
        let mut draw = SplitMix64::new(self.seed, index as u64);
        let exposure_ev = self.exposure_ev * draw.symmetric();
        let white_balance = [0; 3].map(|_| 1.0 + self.white_balance * draw.symmetric());
        let radial = self.vignetting * (0.5 + 0.5 * draw.unit());
        let slope = self.vignetting * 0.5 * draw.unit();
        let angle = std::f64::consts::TAU * draw.unit();
        PhotoGain {
            exposure_ev,
            white_balance,
            radial,
            gradient: [slope * angle.cos(), slope * angle.sin()],
        }
    }
}

/// One photo's gain over its frame (see the module docs); [`PhotoGain::default`] is 1.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PhotoGain {
    pub exposure_ev: f64,
    /// Per-channel factor.
    pub white_balance: [f64; 3],
    /// Radial falloff `a` of `1 − a·r²`.
    pub radial: f64,
    /// `b·d` of the gradient `1 + b·(d · p)`.
    pub gradient: [f64; 2],
}

impl Default for PhotoGain {
    fn default() -> Self {
        Self {
            exposure_ev: 0.0,
            white_balance: [1.0; 3],
            radial: 0.0,
            gradient: [0.0; 2],
        }
    }
}

impl PhotoGain {
    /// `log₂` of the gain per channel at frame position `p ∈ [−1, 1]²` (`(−1, −1)` the top-left
    /// corner of the image, `(1, 1)` the bottom-right).
    pub fn log2_at(&self, p: [f64; 2]) -> [f64; 3] {
        let r2 = (p[0] * p[0] + p[1] * p[1]) / 2.0;
        let spatial =
            (1.0 - self.radial * r2) * (1.0 + self.gradient[0] * p[0] + self.gradient[1] * p[1]);
        let common = self.exposure_ev + spatial.log2();
        self.white_balance.map(|w| common + w.log2())
    }

    /// `log₂` of the gain `t` of the way from `a` to `b` at `p`: `(1 − t)·log₂ a + t·log₂ b`.
    pub fn log2_between(a: &PhotoGain, b: &PhotoGain, t: f64, p: [f64; 2]) -> [f64; 3] {
        let (la, lb) = (a.log2_at(p), b.log2_at(p));
        [0, 1, 2].map(|c| (1.0 - t) * la[c] + t * lb[c])
    }

    /// `image` photographed with this gain.
    pub fn apply(&self, image: &Image) -> Image {
        apply_log2_gain(image, |p| self.log2_at(p))
    }

    /// `image` with the gain `t` of the way from `a` to `b`.
    pub fn apply_between(a: &PhotoGain, b: &PhotoGain, t: f64, image: &Image) -> Image {
        apply_log2_gain(image, |p| PhotoGain::log2_between(a, b, t, p))
    }
}

/// `image` (sRGB, 3 or more channels; a fourth is kept as it is) with the linear-light gain
/// `2^log2_gain(p)` at each pixel's frame position `p`.
pub fn apply_log2_gain(image: &Image, log2_gain: impl Fn([f64; 2]) -> [f64; 3]) -> Image {
    let mut out = image.clone();
    let (w, h) = (image.width, image.height);
    let channels = image.channels.min(3);
    for y in 0..h {
        for x in 0..w {
            let p = [
                2.0 * (x as f64 + 0.5) / w as f64 - 1.0,
                2.0 * (y as f64 + 0.5) / h as f64 - 1.0,
            ];
            let g = log2_gain(p);
            for (c, &gc) in g.iter().enumerate().take(channels) {
                let v = image.get(x, y, c) as f64;
                let linear = srgb_to_linear(v) * gc.exp2();
                out.set(x, y, c, linear_to_srgb(linear).clamp(0.0, 1.0) as f32);
            }
        }
    }
    out
}

/// The sRGB decoding (IEC 61966-2-1).
pub fn srgb_to_linear(v: f64) -> f64 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// The sRGB encoding (IEC 61966-2-1).
pub fn linear_to_srgb(v: f64) -> f64 {
    if v <= 0.0031308 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Each training view's name and the gain `jitter` gives it, in training order.
pub fn training_gains(ds: &Dataset, jitter: &PhotoJitter) -> Vec<(String, PhotoGain)> {
    ds.train
        .iter()
        .map(|&i| (ds.views[i].name.clone(), jitter.gain(i)))
        .collect()
}

/// Applies `jitter` to the training photos of `ds` (held-out photos keep their colours) and
/// returns each training view's name and gain, in training order.
pub fn jitter_training_photos(ds: &mut Dataset, jitter: &PhotoJitter) -> Vec<(String, PhotoGain)> {
    if !jitter.is_none() {
        for i in ds.train.clone() {
            let view = &mut ds.views[i];
            view.image = jitter.gain(i).apply(&view.image);
        }
    }
    training_gains(ds, jitter)
}

/// SplitMix64 (Steele, Lea and Flood 2014), seeded by a seed and a stream (the photo's index).
struct SplitMix64(u64);

impl SplitMix64 {
    fn new(seed: u64, stream: u64) -> Self {
        let mut s = Self(seed ^ stream.wrapping_mul(0xD1B5_4A32_D192_ED03));
        s.next();
        s
    }

    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)` (53 bits).
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `[−1, 1)`.
    fn symmetric(&mut self) -> f64 {
        2.0 * self.unit() - 1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn jitter() -> PhotoJitter {
        PhotoJitter {
            exposure_ev: 0.5,
            white_balance: 0.05,
            vignetting: 0.3,
            seed: 7,
        }
    }

    #[test]
    fn srgb_round_trips_and_matches_the_standard_at_known_points() {
        for v in [0.0, 0.01, 0.04045, 0.2, 0.5, 0.9, 1.0] {
            // The two pieces of the standard meet to within 1e-7 at the knee.
            assert!((linear_to_srgb(srgb_to_linear(v)) - v).abs() < 1e-6, "{v}");
        }
        // 50 % grey in sRGB is 21.4 % linear light.
        assert!((srgb_to_linear(0.5) - 0.214_041_140_5).abs() < 1e-9);
    }

    #[test]
    fn gains_come_from_the_seed_and_the_photo_index_and_stay_in_range() {
        let j = jitter();
        assert_eq!(j.gain(3), j.gain(3));
        assert_ne!(j.gain(3), j.gain(4));
        assert_ne!(
            j.gain(3),
            PhotoJitter { seed: 8, ..j }.gain(3),
            "another seed draws other gains"
        );
        for i in 0..200 {
            let g = j.gain(i);
            assert!(g.exposure_ev.abs() <= 0.5);
            assert!(g.white_balance.iter().all(|w| (w - 1.0).abs() <= 0.05));
            assert!((0.15..=0.3).contains(&g.radial));
            assert!(g.gradient[0].hypot(g.gradient[1]) <= 0.15 + 1e-12);
        }
        assert_eq!(PhotoJitter::default().gain(5), PhotoGain::default());
    }

    #[test]
    fn a_uniform_gain_scales_linear_light_exactly() {
        let g = PhotoGain {
            exposure_ev: 1.0,
            white_balance: [1.0, 0.5, 1.0],
            ..PhotoGain::default()
        };
        let image = Image::filled(4, 3, &[0.2, 0.5, 0.9]);
        let out = g.apply(&image);
        let expect = |v: f64, k: f64| linear_to_srgb(srgb_to_linear(v) * k).min(1.0);
        for y in 0..3 {
            for x in 0..4 {
                assert!((out.get(x, y, 0) as f64 - expect(0.2, 2.0)).abs() < 1e-6);
                // 2 × 0.5 = 1: green keeps its value.
                assert!((out.get(x, y, 1) as f64 - 0.5).abs() < 1e-6);
                // Clipped at white.
                assert_eq!(out.get(x, y, 2), 1.0);
            }
        }
    }

    #[test]
    fn vignetting_darkens_the_corners_and_interpolation_is_log_linear() {
        let g = PhotoGain {
            radial: 0.4,
            ..PhotoGain::default()
        };
        let centre = g.log2_at([0.0, 0.0]);
        let corner = g.log2_at([1.0, 1.0]);
        assert_eq!(centre, [0.0; 3]);
        assert!((corner[0] - 0.6f64.log2()).abs() < 1e-12);
        let a = PhotoGain {
            exposure_ev: 1.0,
            ..PhotoGain::default()
        };
        let b = PhotoGain {
            exposure_ev: -1.0,
            white_balance: [2.0, 1.0, 1.0],
            ..PhotoGain::default()
        };
        let mid = PhotoGain::log2_between(&a, &b, 0.25, [0.3, -0.2]);
        assert!((mid[0] - (0.75 * 1.0 + 0.25 * (-1.0 + 1.0))).abs() < 1e-12);
        assert!((mid[1] - 0.5).abs() < 1e-12);
        assert_eq!(
            PhotoGain::log2_between(&a, &b, 0.0, [0.5, 0.5]),
            a.log2_at([0.5, 0.5])
        );
    }

    #[test]
    fn only_training_photos_are_jittered() {
        let mut ds = crate::synthetic::demo_dataset(&crate::synthetic::DemoOptions {
            width: 24,
            height: 18,
            views: 4,
            train: vec![0, 2],
            supersample: 1,
            ..Default::default()
        });
        let before = ds.clone();
        let gains = jitter_training_photos(&mut ds, &jitter());
        assert_eq!(gains.len(), 2);
        assert_eq!(gains[1], (before.views[2].name.clone(), jitter().gain(2)));
        for i in [1, 3] {
            assert_eq!(
                ds.views[i].image, before.views[i].image,
                "held-out view {i}"
            );
        }
        for i in [0, 2] {
            assert_ne!(
                ds.views[i].image, before.views[i].image,
                "training view {i}"
            );
            assert_eq!(
                ds.views[i].image,
                jitter().gain(i).apply(&before.views[i].image)
            );
        }
    }

    #[test]
    fn out_of_range_settings_are_refused_with_their_name() {
        let bad = PhotoJitter {
            exposure_ev: 3.5,
            ..PhotoJitter::default()
        };
        assert!(bad.validate().unwrap_err().contains("exposure"));
        let bad = PhotoJitter {
            exposure_ev: -0.1,
            ..PhotoJitter::default()
        };
        assert!(bad.validate().is_err());
        let bad = PhotoJitter {
            vignetting: f64::NAN,
            ..PhotoJitter::default()
        };
        assert!(bad.validate().unwrap_err().contains("vignetting"));
        assert!(jitter().validate().is_ok());
    }
}
