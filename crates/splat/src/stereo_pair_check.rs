//! The stereo start's check of its pairs by feature matching.
//!
//! The pairs of [`fewview_geom::stereo::pairs::stereo_pairs`] are chosen by geometry: the views'
//! frustums overlap and their axes are close enough. Geometry cannot see what the photos show:
//! two views of a glossy or textureless surface, or of one seen at a grazing angle, overlap on
//! paper and still give block matching nothing to hold on to. With a matcher chosen, each pair
//! also needs enough correspondences that agree with its cameras: matches (SIFT, XFeat, XFeat*
//! or LighterGlue, as `surface` and `poses` use them) within a few pixels of the epipolar line
//! the known poses draw. A pair with fewer is left out of the cloud; all pairs failing is an
//! error naming them. Off by default: the fusion paper takes every overlapping pair.

use fewview_geom::stereo::pairs::StereoView;
use fewview_match::correspondence::{MatchInput, epipolar_distance, fundamental_from_cameras};
use fewview_match::learned::{MatcherKind, matcher_for};
use fewview_match::sift::SiftOptions;
use serde::{Deserialize, Serialize};

/// A pair check that cannot run (settings out of range, unreadable weights) or that no pair
/// passes, in one line.
#[derive(Debug, thiserror::Error)]
#[error("stereo pair check: {0}")]
pub struct PairCheckError(String);

/// The pairs a check keeps, and its report when a matcher ran.
#[derive(Debug)]
pub struct CheckedPairs {
    pub pairs: Vec<(usize, usize)>,
    pub report: Option<PairCheckReport>,
}

/// How the stereo start checks a geometrically overlapping pair before matching it densely.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PairCheck {
    /// The matcher whose correspondences must tie the pair (`None`: geometry alone).
    pub matcher: Option<MatcherKind>,
    /// Fewest correspondences consistent with the cameras a kept pair has.
    pub min_matches: usize,
    /// Largest distance (pixels, the mean of both images') from a correspondence to the
    /// epipolar line of the cameras for it to count.
    pub max_epipolar_px: f64,
}

impl Default for PairCheck {
    fn default() -> Self {
        Self {
            matcher: None,
            min_matches: 30,
            max_epipolar_px: 2.0,
        }
    }
}

/// What the matcher found for one pair.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PairMatches {
    pub views: (String, String),
    /// Correspondences the matcher returned (after its own RANSAC filter).
    pub matches: usize,
    /// Those within [`PairCheck::max_epipolar_px`] of the cameras' epipolar lines.
    pub consistent: usize,
    pub kept: bool,
}

/// The check's record for `stereo.json`: the matcher that ran (its `--stereo-pair-check` name;
/// why, when it is not the one asked for) and each pair's counts.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PairCheckReport {
    pub matcher: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fallback: Option<String>,
    pub pairs: Vec<PairMatches>,
}

/// The pairs that pass `check` and the check's report (`None` when no matcher is chosen, and
/// every pair is kept). Settings out of range, and every pair failing, are errors.
pub fn check_pairs(
    views: &[StereoView],
    pairs: &[(usize, usize)],
    check: &PairCheck,
) -> Result<CheckedPairs, PairCheckError> {
    let Some(kind) = check.matcher else {
        return Ok(CheckedPairs {
            pairs: pairs.to_vec(),
            report: None,
        });
    };
    if !(check.max_epipolar_px.is_finite() && check.max_epipolar_px > 0.0) {
        return Err(PairCheckError(format!(
            "epipolar distance {} px is not positive",
            check.max_epipolar_px
        )));
    }
    let inputs: Vec<MatchInput> = views
        .iter()
        .map(|v| MatchInput {
            image: v.image,
            mask: v.mask,
        })
        .collect();
    let (matcher, fallback) = matcher_for(kind, &SiftOptions::default(), &inputs)
        .map_err(|e| PairCheckError(e.to_string()))?;
    let ran = match fallback {
        Some(_) => MatcherKind::Classical,
        None => kind,
    };
    let mut kept = Vec::new();
    let mut report = Vec::new();
    for &(a, b) in pairs {
        let f = fundamental_from_cameras(views[a].camera, views[b].camera);
        let found = matcher.match_pair(&inputs[a], &inputs[b]);
        let consistent = found
            .iter()
            .filter(|m| epipolar_distance(&f, m.a, m.b) <= check.max_epipolar_px)
            .count();
        let keep = consistent >= check.min_matches;
        if keep {
            kept.push((a, b));
        }
        report.push(PairMatches {
            views: (views[a].name.to_string(), views[b].name.to_string()),
            matches: found.len(),
            consistent,
            kept: keep,
        });
    }
    if kept.is_empty() && !pairs.is_empty() {
        let counts: Vec<String> = report
            .iter()
            .map(|p| format!("{}–{}: {}", p.views.0, p.views.1, p.consistent))
            .collect();
        return Err(PairCheckError(format!(
            "no pair has {} matches consistent with its cameras ({}; matcher {})",
            check.min_matches,
            counts.join(", "),
            ran.name()
        )));
    }
    let report = PairCheckReport {
        matcher: ran.name().to_string(),
        fallback,
        pairs: report,
    };
    Ok(CheckedPairs {
        pairs: kept,
        report: Some(report),
    })
}

#[cfg(test)]
mod tests {
    use fewview_scene::{Camera, Image, Intrinsics, Se3};
    use nalgebra::{Rotation3, Vector3};
    use rand::{RngExt, SeedableRng};

    use super::*;

    const W: usize = 200;
    const H: usize = 150;
    /// The disparity of the textured plane between the two views, in pixels.
    const SHIFT: usize = 8;

    /// Grey noise blurred by two box filters of radius 2, `W + SHIFT` pixels wide.
    fn texture(seed: u64) -> Vec<f32> {
        let w = W + SHIFT;
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let mut t: Vec<f32> = (0..w * H).map(|_| rng.random::<f32>()).collect();
        for _ in 0..2 {
            let mut out = vec![0.0; w * H];
            for y in 0..H {
                for x in 0..w {
                    let (mut sum, mut n) = (0.0, 0.0);
                    for yy in y.saturating_sub(2)..(y + 3).min(H) {
                        for xx in x.saturating_sub(2)..(x + 3).min(w) {
                            sum += t[yy * w + xx];
                            n += 1.0;
                        }
                    }
                    out[y * w + x] = sum / n;
                }
            }
            t = out;
        }
        t
    }

    /// The texture's window starting at column `offset`, as an RGB image.
    fn window(t: &[f32], offset: usize) -> Image {
        let data = (0..H)
            .flat_map(|y| (0..W).map(move |x| (y, x)))
            .flat_map(|(y, x)| [t[y * (W + SHIFT) + x + offset]; 3])
            .collect();
        Image::from_vec(W, H, 3, data)
    }

    /// Two views of a fronto-parallel textured plane, the second moved along x so that the
    /// plane's disparity is `SHIFT` pixels: its photo is the first one's shifted by `SHIFT`.
    /// `tilt_deg` turns the second camera about its x axis in the cameras only (not the photo):
    /// wrong poses.
    fn rig(tilt_deg: f64) -> ([Camera; 2], [Image; 2]) {
        let focal = 180.0;
        let intrinsics = Intrinsics::centered(focal, W as u32, H as u32);
        let depth = 2.0;
        let baseline = SHIFT as f64 * depth / focal;
        let tilt = Rotation3::from_axis_angle(&Vector3::x_axis(), tilt_deg.to_radians());
        let a = Camera::new(intrinsics, Se3::identity());
        let b = Camera::new(
            intrinsics,
            Se3::new(*tilt.matrix(), Vector3::new(-baseline, 0.0, 0.0)),
        );
        let t = texture(7);
        ([a, b], [window(&t, 0), window(&t, SHIFT)])
    }

    /// The rig's two views, named `a` and `b`.
    fn views<'a>(cameras: &'a [Camera; 2], images: &'a [Image; 2]) -> Vec<StereoView<'a>> {
        ["a", "b"]
            .iter()
            .zip(cameras.iter().zip(images))
            .map(|(name, (camera, image))| StereoView {
                name,
                camera,
                image,
                depth_bounds: Some((1.0, 4.0)),
                mask: None,
                sparse_points: &[],
            })
            .collect()
    }

    fn check(tilt_deg: f64, min_matches: usize) -> Result<CheckedPairs, PairCheckError> {
        let (cameras, images) = rig(tilt_deg);
        let views = views(&cameras, &images);
        let settings = PairCheck {
            matcher: Some(MatcherKind::Classical),
            min_matches,
            ..PairCheck::default()
        };
        check_pairs(&views, &[(0, 1)], &settings)
    }

    /// With the true cameras nearly every SIFT match of the shifted texture lies on its
    /// epipolar line; with the second camera tilted by 3° (epipolar lines about 9 px off)
    /// almost none does, and the only pair failing is an error naming it.
    #[test]
    fn matches_must_agree_with_the_cameras() {
        let checked = check(0.0, 20).unwrap();
        let report = checked.report.unwrap();
        assert_eq!(report.matcher, "classical");
        let pair = &report.pairs[0];
        assert_eq!(checked.pairs, vec![(0, 1)]);
        assert!(pair.matches >= 20, "{pair:?}");
        assert!(
            pair.consistent as f64 >= 0.9 * pair.matches as f64,
            "{pair:?}"
        );

        let err = check(3.0, 20).unwrap_err().to_string();
        assert!(err.contains("a–b"), "{err}");
        let checked = check(3.0, 0).unwrap();
        let pair = &checked.report.unwrap().pairs[0];
        assert_eq!(checked.pairs, vec![(0, 1)]);
        assert!(pair.consistent * 10 <= pair.matches, "{pair:?}");
    }

    /// Without a matcher every pair passes untouched and no report is made; a non-positive
    /// epipolar distance is refused.
    #[test]
    fn geometry_alone_keeps_every_pair_and_bad_settings_are_refused() {
        let (cameras, images) = rig(0.0);
        let views = views(&cameras, &images);
        let pairs = [(0, 1), (1, 0)];
        let checked = check_pairs(&views, &pairs, &PairCheck::default()).unwrap();
        assert_eq!(checked.pairs, pairs);
        assert!(checked.report.is_none());
        let bad = PairCheck {
            matcher: Some(MatcherKind::Classical),
            max_epipolar_px: 0.0,
            ..PairCheck::default()
        };
        assert!(check_pairs(&views, &pairs, &bad).is_err());
    }
}
