//! What any stereo method gives for a pair of views: a depth map of each view in its original
//! camera, with the depths the matcher could verify.

/// A z-depth map of one view in its original camera (row-major, that view's image size, 0 where
/// unknown) and which of its depths were verified (the matcher could check them against the
/// image texture; only verified depths can be pairwise consistent).
#[derive(Clone, Debug, PartialEq)]
pub struct ViewDepth {
    pub depth: Vec<f32>,
    pub verified: Vec<bool>,
}

impl ViewDepth {
    /// A depth map whose every depth counts as verified (a user's or a learned model's).
    pub fn trusted(depth: Vec<f32>) -> Self {
        let verified = depth.iter().map(|&d| d > 0.0).collect();
        Self { depth, verified }
    }
}

/// The depth maps of the two views of a pair.
#[derive(Clone, Debug, PartialEq)]
pub struct PairDepths {
    pub first: ViewDepth,
    pub second: ViewDepth,
}
