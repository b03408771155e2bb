#![doc = include_str!("../README.md")]
//! Geometry toolbox (the fusion paper §1–2, §4; the surface paper Alg. 3).
//!
//! - [`depth`]: depth maps to meshes and point clouds with the depth-edge test of Eq. (1),
//!   [`contract`]: the contraction of Eq. (2) and point subsampling (the fusion paper §1–2).
//! - [`stereo`]: calibrated rectification, Semi-Global Matching (OpenCV's `StereoSGBM`,
//!   bit for bit), sub-pixel refinement and the confidence-based hierarchical point cloud of
//!   the fusion paper §2, the start of its Gaussians; [`colormap`]: false colour for depth and disparity.
//! - [`blend`]: occlusion-aware Poisson blending (Eq. 3), standard Poisson, Laplacian-pyramid and
//!   Gaussian-feather blending (the fusion paper §4, Fig. 2/9).
//! - [`raster`]: triangle rasterisation with a z-buffer and perspective-correct attributes, to
//!   reproject depth meshes into virtual views (the fusion paper §1, §4).
//! - [`mcubes`]: marching cubes on dense grids and chunked closures; [`cleanup`]: largest
//!   component and mask culling.
//! - [`epipolar`]: the five-point relative pose with RANSAC, rotation averaging and camera
//!   centres from baseline directions: a global start for noisy poses (the surface paper).
//! - [`registration`]: similarity pre-alignment, FPFH + RANSAC, ICP (the surface paper Alg. 3).
//! - [`chamfer`]: the DTU Chamfer protocol and Chamfer-L1 / F-score / normal consistency.
//! - [`io`]: PLY, OBJ, OFF, `.npy`, depth PNGs and camera JSON.

// Numeric code here indexes several parallel arrays with one loop variable, and tests for
// positivity with `!(x > 0.0)` on purpose so that NaN is rejected too.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

pub mod bench;
pub mod blend;
pub mod chamfer;
pub mod cleanup;
pub mod colormap;
pub mod contract;
pub mod depth;
pub mod epipolar;
pub mod error;
pub mod io;
pub mod knn;
pub mod mcubes;
pub mod mesh;
pub mod raster;
pub mod registration;
pub mod sampling;
pub mod similarity;
pub mod stereo;
pub mod topology;

pub use error::{GeomError, Result};
pub use mesh::{Mesh, Points};
pub use similarity::Similarity;
