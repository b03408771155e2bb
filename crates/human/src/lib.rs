#![doc = include_str!("../README.md")]
//! People filmed by a ring of synchronized, calibrated cameras: the data layer and network of
//! "PoseGaussian: Pose-Driven Novel View Synthesis for Robust 3D Human Reconstruction"
//! (the PoseGaussian paper, whose supplement is in `papers/`).
//!
//! - [`baseline`]: the "3DGS per frame" baseline, 3DGS trained on one frame's input views.
//! - [`dataset`]: the synthetic capture (`$FEWVIEW_DATA/human`), exact depth and joints.
//! - [`zju`]: the ZJU-MoCap layout (`annots.npy`, `Camera_B*/`, `mask/`, `params/`), undistorted
//!   to pinhole images on the fly.
//! - [`capture`]: opens a capture folder of either layout.
//! - [`source`]: [`MultiView`], the interface both offer, one `(camera, frame)` at a time.
//! - [`split`]: the paper's protocol (8 input cameras, held-out views, novel poses) and
//!   [`TrainingView`], which cannot open anything outside the training set.
//! - [`hull`]: the visual hull of the input masks and its depth in each source view.
//! - [`depth`]: the depth the network reads (per-frame stereo bounded by the hull, the hull's,
//!   or the capture's) and its flicker over frames; [`depth_report`] compares them on a capture.
//! - [`gaussians`]: the heads' maps to one Gaussian per foreground pixel, the source views
//!   nearest a target, and the differentiable render into it (fewview-splat's rasterizer).
//! - [`net`]: the network (three encoders, a U-Net decoder, Gaussian-parameter heads), the pose
//!   map it reads, its multiply-add count and its checkpoints.
//! - [`eval`]: novel views and novel poses scored against the baselines; [`eval_outputs`]: the
//!   table, metrics and side-by-side video `fewview human eval` writes from them.
//! - [`orbit`]: a free-viewpoint camera path circling the rig.
//! - [`tps`]: the Temporal Pose Stabilizer, each source view's maps blended with its previous
//!   frame's, warped by the joints' motion and weighted down where they move fast.
//!
//! Cameras follow fewview-scene's convention everywhere: OpenCV axes, world-to-camera, pixel
//! centres at half-integers (both file formats put them at integers; [`opencv`] converts).

// Numeric code indexes several parallel arrays with one loop variable, and tests positivity with
// `!(x <= t)` on purpose so that NaN is rejected too.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

pub mod baseline;
pub mod bench;
pub mod capture;
pub mod dataset;
pub mod depth;
pub mod depth_report;
pub mod error;
pub mod eval;
pub mod eval_outputs;
pub mod gaussians;
pub mod hull;
pub mod infer;
pub mod maps;
pub mod net;
pub mod npy_rows;
pub mod opencv;
pub mod orbit;
pub mod readlog;
pub mod source;
pub mod split;
pub mod tps;
pub mod train;
pub mod zju;

pub use dataset::HumanDataset;
pub use error::{HumanError, Result};
pub use maps::{DepthMap, Mask};
pub use source::MultiView;
pub use split::{Split, TrainingView};
pub use zju::ZjuDataset;
