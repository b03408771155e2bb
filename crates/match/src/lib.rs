#![doc = include_str!("../README.md")]

mod attention;
pub mod bench;
pub mod error;
pub mod lighterglue;
pub mod weights;
pub mod xfeat;

pub use error::{MatchError, Result};
pub use lighterglue::{GlueMatch, GlueOptions, LighterGlue};
pub use xfeat::{DenseFeatures, DetectOptions, Features, XFeat};
