//! Calibrated two-view stereo for the start of "Splat-based Gradient-domain Fusion for Seamless
//! View Transition" (the fusion paper §2), in the order the work happens:
//!
//! 1. [`pairs`]: which training views are matched (consecutive views along the baseline);
//! 2. [`rectify`]: both views of a pair turned to a common image plane, rows aligned, and the
//!    [`range`] of disparities to search (from the sparse points both views see);
//! 3. [`sgm`]: Semi-Global Matching of the rectified pair, as OpenCV's `StereoSGBM` does it (the
//!    paper uses UniMatch, a learned model whose weights cannot be fetched here), over a
//!    [`search_window`] that may start at any disparity;
//! 4. [`refine`]: each disparity refined to sub-pixel on a slanted window, and marked verified
//!    when the window fits;
//! 5. [`source`]: the [`source::DepthSource`] seam: SGM on a rectified pair, mapped back to depth
//!    in the original cameras, or, for pairs rectification cannot serve (a camera walking
//!    forward), a [`sweep`] of depth planes in each view; or the user's own depth maps;
//! 6. [`hierarchy`]: the confidence-based hierarchical point cloud (R^c, R^o, R^s) and its
//!    contraction, from which a 10 % sample becomes the initial Gaussians.

pub mod hierarchy;
pub mod pairs;
pub mod range;
pub mod rectify;
pub mod refine;
pub mod search_window;
pub mod sgm;
pub mod source;
pub mod sweep;
pub mod sweep_refine;
pub mod view_depth;
