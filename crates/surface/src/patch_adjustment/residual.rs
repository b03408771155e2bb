//! What the patches are compared through ([`Views`]) and what they are: a plane seen around a
//! pixel of its reference view ([`Patch`]) with its depth and normal ([`PatchState`]); the
//! photometric residual of a patch in a view.

use fewview_scene::{Image, Intrinsics, Se3};
use nalgebra::{Matrix3, Vector2, Vector3};
use rayon::prelude::*;

use super::options::PatchAdjustmentOptions;
use crate::matching::refine::{Plane, Window};

/// The images, cameras and window the patches are compared through.
pub(super) struct Views {
    pub(super) planes: Vec<Plane>,
    pub(super) k: Vec<Matrix3<f64>>,
    pub(super) k_inv: Vec<Matrix3<f64>>,
    pub(super) window: Window,
    /// Sum of the window's weights.
    pub(super) weight_sum: f64,
    /// Square roots of the window's weights (the residuals' factors).
    pub(super) sqrt_weights: Vec<f64>,
}

/// A plane seen around `centre` in its reference view.
pub(super) struct Patch {
    pub(super) reference: usize,
    pub(super) centre: Vector2<f64>,
    /// `K_r⁻¹ (centre, 1)`: the point at depth `z` is `z · ray` (reference camera frame).
    pub(super) ray: Vector3<f64>,
    /// The reference window's samples minus their weighted mean, and their weighted energy.
    pub(super) template: Vec<f64>,
    pub(super) template_energy: f64,
    /// The views it is compared in (never the reference).
    pub(super) views: Vec<usize>,
    /// Views of the seeding match beyond the reference (for the report).
    pub(super) paired: usize,
}

/// A patch's unknowns.
#[derive(Clone, Copy, Debug)]
pub(super) struct PatchState {
    pub(super) log_depth: f64,
    /// Unit normal in the reference camera frame, facing the camera.
    pub(super) normal: Vector3<f64>,
}

impl PatchState {
    /// The state after the step `(log depth, tilt along e₁, tilt along e₂)`.
    pub(super) fn moved(&self, step: &[f64; 3]) -> Self {
        let (e1, e2) = tangents(&self.normal);
        Self {
            log_depth: self.log_depth + step[0],
            normal: (self.normal + step[1] * e1 + step[2] * e2).normalize(),
        }
    }
}

/// Two unit vectors orthogonal to `n` and to each other.
pub(super) fn tangents(n: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let axis = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = n.cross(&axis).normalize();
    (e1, n.cross(&e1))
}

impl Views {
    pub(super) fn new(
        images: &[&Image],
        intrinsics: &[Intrinsics],
        options: &PatchAdjustmentOptions,
    ) -> Self {
        let window = Window::new(options.half_window);
        let weight_sum = window.weights.iter().sum();
        let sqrt_weights = window.weights.iter().map(|w| w.sqrt()).collect();
        let k: Vec<Matrix3<f64>> = intrinsics.iter().map(Intrinsics::matrix).collect();
        Self {
            planes: images
                .par_iter()
                .map(|im| Plane::new(im, options.blur_sigma))
                .collect(),
            k_inv: k
                .iter()
                .map(|k| k.try_inverse().unwrap_or_else(Matrix3::zeros))
                .collect(),
            k,
            window,
            weight_sum,
            sqrt_weights,
        }
    }

    /// The homography from reference pixels to view `v`'s pixels of the patch's plane.
    pub(super) fn homography(
        &self,
        patch: &Patch,
        state: &PatchState,
        poses: &[Se3],
        v: usize,
    ) -> Matrix3<f64> {
        let r = patch.reference;
        let point = state.log_depth.exp() * patch.ray;
        let distance = state.normal.dot(&point);
        let rotation = poses[v].rotation * poses[r].rotation.transpose();
        let translation = poses[v].translation - rotation * poses[r].translation;
        self.k[v] * (rotation + translation * state.normal.transpose() / distance) * self.k_inv[r]
    }

    /// View `v`'s samples of the patch's window through `h`, and whether all lie inside.
    pub(super) fn warped_window(
        &self,
        patch: &Patch,
        h: &Matrix3<f64>,
        v: usize,
        out: &mut Vec<f64>,
    ) -> bool {
        let plane = &self.planes[v];
        let mut inside = true;
        out.clear();
        for d in &self.window.offsets {
            let x = patch.centre + d;
            let y = h * Vector3::new(x.x, x.y, 1.0);
            let (px, py) = (y.x / y.z, y.y / y.z);
            inside &= y.z > 0.0 && plane.inside(px, py);
            out.push(plane.sample(&plane.value, px, py));
        }
        inside
    }

    /// Normalised cross-correlation of the patch's template with `values` (window-weighted).
    pub(super) fn ncc(&self, patch: &Patch, values: &[f64]) -> f64 {
        let centred = self.centred(values);
        let cross = self.weighted_dot(&patch.template, &centred);
        let denominator = (patch.template_energy * self.weighted_dot(&centred, &centred)).sqrt();
        if denominator > 0.0 {
            cross / denominator
        } else {
            0.0
        }
    }

    /// `Σ w a b` over the window.
    pub(super) fn weighted_dot(&self, a: &[f64], b: &[f64]) -> f64 {
        self.window
            .weights
            .iter()
            .zip(a)
            .zip(b)
            .map(|((w, a), b)| w * a * b)
            .sum()
    }

    /// `values` minus their weighted mean.
    pub(super) fn centred(&self, values: &[f64]) -> Vec<f64> {
        let mean = self
            .window
            .weights
            .iter()
            .zip(values)
            .map(|(w, v)| w * v)
            .sum::<f64>()
            / self.weight_sum;
        values.iter().map(|v| v - mean).collect()
    }

    /// Appends `√w · (values − mean − g · template)` with the best gain `g` (the bias is the
    /// mean): the residuals of one patch in one view.
    pub(super) fn push_residuals(&self, patch: &Patch, values: &[f64], out: &mut Vec<f64>) {
        let centred = self.centred(values);
        let gain = self.weighted_dot(&patch.template, &centred) / patch.template_energy;
        for ((s, t), c) in self.sqrt_weights.iter().zip(&patch.template).zip(&centred) {
            out.push(s * (c - gain * t));
        }
    }

    /// All residuals of `patch` at `state` under `poses`, view after view.
    pub(super) fn residuals(&self, patch: &Patch, state: &PatchState, poses: &[Se3]) -> Vec<f64> {
        let mut out = Vec::with_capacity(patch.views.len() * self.window.offsets.len());
        for &v in &patch.views {
            self.push_view_residuals(patch, state, poses, v, &mut out);
        }
        out
    }

    /// Appends the residuals of `patch` at `state` in view `v` alone.
    pub(super) fn push_view_residuals(
        &self,
        patch: &Patch,
        state: &PatchState,
        poses: &[Se3],
        v: usize,
        out: &mut Vec<f64>,
    ) {
        let mut values = Vec::with_capacity(self.window.offsets.len());
        let h = self.homography(patch, state, poses, v);
        self.warped_window(patch, &h, v, &mut values);
        self.push_residuals(patch, &values, out);
    }
}
