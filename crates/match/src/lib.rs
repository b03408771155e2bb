#![doc = include_str!("../README.md")]

mod attention;
pub mod bench;
pub mod correspondence;
pub mod dense;
pub mod densify;
pub mod error;
pub mod fundamental;
pub mod learned;
pub mod lighterglue;
pub mod refine;
pub mod report;
pub mod retrieval;
pub mod sift;
mod tensor;
pub mod weights;
pub mod xfeat;

pub use correspondence::{
    Match, MatchInput, MatchPrecision, Matcher, covisible_pairs, epipolar_distance,
    epipolar_precision, fundamental_from_cameras, match_all_pairs, match_pairs,
};
pub use error::{MatchError, Result};
pub use lighterglue::{GlueMatch, GlueOptions, LighterGlue};
pub use xfeat::{DenseFeatures, DetectOptions, Features, XFeat};
