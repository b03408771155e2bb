//! Lens distortion: the camera models of COLMAP and OpenCV, and undistortion into the crate's
//! ideal pinhole convention.
//!
//! A [`LensCamera`] is pinhole intrinsics plus an optional [`Distortion`] that acts on
//! normalised image coordinates `(x/z, y/z)` of OpenCV camera axes, exactly as OpenCV's
//! `projectPoints` / `fisheye::distortPoints` and COLMAP's camera models do:
//!
//! * [`Distortion::RadialTangential`] (Brown–Conrady, OpenCV's default and rational models,
//!   COLMAP `SIMPLE_RADIAL`, `RADIAL`, `OPENCV`, `FULL_OPENCV`, nerfstudio `OPENCV`):
//!   `r² = x² + y²`, `s = (1 + k1 r² + k2 r⁴ + k3 r⁶ + k4 r⁸) / (1 + k5 r² + k6 r⁴ + k7 r⁶)`,
//!   `x_d = x s + 2 p1 x y + p2 (r² + 2 x²)`, `y_d = y s + p1 (r² + 2 y²) + 2 p2 x y`.
//!   OpenCV's rational `k4 k5 k6` are the denominator's `k5 k6 k7` here; the numerator's `r⁸`
//!   term is nerfstudio's `k4`.
//! * [`Distortion::Fisheye`] (Kannala–Brandt, OpenCV `fisheye`, COLMAP `OPENCV_FISHEYE`):
//!   `θ = atan(r)`, `θ_d = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)`, `(x_d, y_d) = (θ_d / r) (x, y)`.
//!
//! Undistorting inverts these by Newton's method started at the distorted point, as COLMAP's
//! `IterativeUndistortion` does (COLMAP differentiates numerically; the Jacobian here is
//! analytic), and the fisheye angle by a one-dimensional Newton iteration on `θ_d(θ)`, as
//! OpenCV's `fisheye::undistortPoints`. [`LensCamera::check_invertible`] refuses a lens whose
//! mapping folds over inside the image (a non-monotonic radial term, a fisheye beyond 180°),
//! where no inverse exists.
//!
//! Images are undistorted on load ([`remap`]); the results are cached per dataset ([`cache`]).

pub mod cache;
pub mod lens;
pub mod models;
pub mod remap;

pub use lens::{Distortion, LensCamera};
pub use models::{camera_from_colmap, camera_from_transforms};
pub use remap::{Resample, UndistortFit, undistort_image, undistorted_intrinsics, valid_mask};

#[cfg(test)]
mod tests;
