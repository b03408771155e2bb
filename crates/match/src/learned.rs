//! The learned matchers of `fewview-match` behind [`Matcher`]: XFeat with mutual nearest
//! neighbours, XFeat* (semi-dense, refined) and XFeat + LighterGlue. Keypoints outside the
//! object mask are dropped before matching (XFeat*: matches with an end outside it), and the
//! matches pass the same RANSAC fundamental-matrix filter as SIFT's.
//!
//! XFeat places the keypoint of pixel `i` at `i` (pixel centres at integers); matches here put
//! pixel centres at half-integers, so both ends move by half a pixel.

use crate::error::MatchError;
use crate::lighterglue::{GlueOptions, LighterGlue};
use crate::xfeat::{DetectOptions, Features, XFeat};
use serde::{Deserialize, Serialize};

use super::sift::{SiftMatcher, SiftOptions};
use crate::correspondence::{Match, MatchInput, Matcher, mask_admits, ransac_filter};

/// Which matcher finds the correspondences.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum MatcherKind {
    /// SIFT, Lowe's ratio test, mutual nearest neighbours.
    #[default]
    Classical,
    /// XFeat keypoints matched by mutual nearest neighbours.
    Xfeat,
    /// XFeat*: semi-dense XFeat cells at two scales, refined to sub-pixel positions.
    XfeatStar,
    /// XFeat keypoints matched by LighterGlue.
    Lighterglue,
}

impl MatcherKind {
    /// The name written in reports.
    pub fn name(self) -> &'static str {
        match self {
            Self::Classical => "classical",
            Self::Xfeat => "xfeat",
            Self::XfeatStar => "xfeat-star",
            Self::Lighterglue => "lighterglue",
        }
    }
}

/// A loaded learned matcher.
pub struct LearnedMatcher {
    kind: MatcherKind,
    xfeat: XFeat,
    glue: Option<LighterGlue>,
    /// RANSAC settings (threshold, iterations, seed) shared with the classical matcher.
    ransac: SiftOptions,
}

impl LearnedMatcher {
    /// Loads the weights `kind` needs from the weight folder (`scripts/setup.sh`).
    pub fn load(kind: MatcherKind, ransac: SiftOptions) -> Result<Self, MatchError> {
        let glue = match kind {
            MatcherKind::Lighterglue => Some(LighterGlue::load_default()?),
            _ => None,
        };
        Ok(Self {
            kind,
            xfeat: XFeat::load_default()?,
            glue,
            ransac,
        })
    }

    fn features(&self, input: &MatchInput) -> Result<Features, MatchError> {
        let mut f = self.xfeat.detect(input.image, DetectOptions::default())?;
        f.retain(|[x, y]| mask_admits(input.mask, centre(x, y), 0.5));
        Ok(f)
    }

    fn raw_matches(&self, a: &MatchInput, b: &MatchInput) -> Result<Vec<Match>, MatchError> {
        let pair = |pa: [f32; 2], pb: [f32; 2], confidence: f32| Match {
            view_a: 0,
            view_b: 1,
            a: [pa[0] + 0.5, pa[1] + 0.5],
            b: [pb[0] + 0.5, pb[1] + 0.5],
            confidence,
            b_covariance: None,
        };
        Ok(match (self.kind, &self.glue) {
            (MatcherKind::XfeatStar, _) => {
                let top_k = DetectOptions::default().top_k;
                let matches = self.xfeat.match_star(a.image, b.image, top_k)?;
                matches
                    .into_iter()
                    .filter(|m| {
                        mask_admits(a.mask, centre(m[0], m[1]), 0.5)
                            && mask_admits(b.mask, centre(m[2], m[3]), 0.5)
                    })
                    .map(|m| pair([m[0], m[1]], [m[2], m[3]], 1.0))
                    .collect()
            }
            (MatcherKind::Lighterglue, Some(glue)) => {
                let (fa, fb) = (self.features(a)?, self.features(b)?);
                glue.match_features(&fa, &fb, GlueOptions::default())?
                    .into_iter()
                    .map(|m| pair(fa.keypoints[m.a], fb.keypoints[m.b], m.score))
                    .collect()
            }
            _ => {
                let (fa, fb) = (self.features(a)?, self.features(b)?);
                self.xfeat
                    .match_mutual(&fa, &fb, None)
                    .into_iter()
                    .map(|(i, j)| {
                        let cos: f32 = fa
                            .descriptor(i)
                            .iter()
                            .zip(fb.descriptor(j))
                            .map(|(x, y)| x * y)
                            .sum();
                        pair(fa.keypoints[i], fb.keypoints[j], cos.clamp(0.0, 1.0))
                    })
                    .collect()
            }
        })
    }
}

/// A keypoint `(x, y)` of XFeat (integer centres) in half-integer centres, for the mask test.
fn centre(x: f32, y: f32) -> nalgebra::Vector2<f64> {
    nalgebra::Vector2::new(x as f64 + 0.5, y as f64 + 0.5)
}

impl Matcher for LearnedMatcher {
    fn match_pair(&self, a: &MatchInput, b: &MatchInput) -> Vec<Match> {
        // The images were checked when the dataset loaded (finite, at least 32 px: see
        // `matcher_for`); a failure here is a bug, not bad input.
        let matches = self
            .raw_matches(a, b)
            .expect("learned matching of checked images");
        match self.ransac.ransac_px {
            Some(px) => ransac_filter(matches, px, self.ransac.ransac_iterations, self.ransac.seed),
            None => matches,
        }
    }

    fn name(&self) -> &str {
        self.kind.name()
    }
}

/// The weight files `kind` needs.
fn weight_files(kind: MatcherKind) -> Vec<std::path::PathBuf> {
    match kind {
        MatcherKind::Classical => Vec::new(),
        MatcherKind::Xfeat | MatcherKind::XfeatStar => {
            vec![crate::weights::xfeat_weights()]
        }
        MatcherKind::Lighterglue => vec![
            crate::weights::xfeat_weights(),
            crate::weights::lighterglue_weights(),
        ],
    }
}

/// Refuses weight files that exist but cannot serve `kind` (truncated, another network's, wrong
/// shapes), naming the file, before a run writes anything. Missing files are not an error: the
/// run then falls back to the classical matcher and says so ([`matcher_for`]).
pub fn check_weights(kind: MatcherKind) -> Result<(), MatchError> {
    matcher_for(kind, &SiftOptions::default(), &[]).map(drop)
}

/// The matcher `kind` names, or the classical one with the reason in one line when its weights
/// are missing or the images are too small for it. Weight files that exist but cannot be loaded
/// are an error naming the file.
pub fn matcher_for(
    kind: MatcherKind,
    options: &SiftOptions,
    inputs: &[MatchInput],
) -> Result<(Box<dyn Matcher>, Option<String>), MatchError> {
    let classical = || {
        Box::new(SiftMatcher {
            options: options.clone(),
        }) as Box<dyn Matcher>
    };
    let fallback = |why: String| {
        let line = format!(
            "matcher {}: {why}; using the classical matcher",
            kind.name()
        );
        Ok((classical(), Some(line)))
    };
    if kind == MatcherKind::Classical {
        return Ok((classical(), None));
    }
    if let Some(i) = inputs
        .iter()
        .find(|i| i.image.width < 32 || i.image.height < 32)
    {
        return fallback(format!(
            "a {}×{} image is smaller than XFeat's 32-pixel stride",
            i.image.width, i.image.height
        ));
    }
    if inputs.iter().any(|i| !i.image.is_finite()) {
        return fallback("an image has NaN or infinite pixels".to_string());
    }
    if let Err(missing) = weight_files(kind)
        .iter()
        .try_for_each(|f| crate::weights::require(f))
    {
        return fallback(missing.to_string());
    }
    Ok((Box::new(LearnedMatcher::load(kind, options.clone())?), None))
}
