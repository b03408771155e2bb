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
pub mod sift;
pub mod weights;
pub mod xfeat;

pub use correspondence::{
    Match, MatchInput, MatchPrecision, Matcher, covisible_pairs, epipolar_distance,
    epipolar_precision, fundamental_from_cameras, match_all_pairs, match_pairs,
};
pub(crate) use correspondence::{luminance, mask_admits, ransac_filter, unordered_pairs};
pub use error::{MatchError, Result};
pub use lighterglue::{GlueMatch, GlueOptions, LighterGlue};
pub use xfeat::{DenseFeatures, DetectOptions, Features, XFeat};

/// A tensor's values on the host, row-major, through the project's read-back
/// ([`fewview_optim::host::f32_values`]). The networks' tensors are `f32` on the CPU, so a
/// failure is a bug, and it panics naming the tensor.
pub(crate) fn host<const D: usize>(t: burn::tensor::Tensor<D>) -> Vec<f32> {
    fewview_optim::host::f32_values(t, "a matcher tensor").unwrap_or_else(|e| panic!("{e}"))
}
