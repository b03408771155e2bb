//! Bundle adjustment of camera poses on the matches' tracks, as structure from motion ends its
//! start. The surface method runs it after its warm-up (a deviation from the surface paper,
//! which refines the poses through the field alone; `--bundle-adjustment off` switches it off).
//!
//! **Why.** The surface method's epipolar warm-up fits each pair's matches on their own:
//! a pair's Sampson cost cannot say that the point a match of views 0–1 sees is the point a
//! match of views 0–2 sees at the same pixel of view 0. On a narrow field of view with a shallow
//! object that freedom is a long, flat valley (rotation traded against baseline direction), and
//! small biases of the matches pick a point in it. Joined into tracks, a grid point matched from
//! one view into two others is one 3D point seen three times, and the reprojection errors of
//! all its observations tie the three cameras together (the trifocal constraint the pairs lack).
//!
//! **Model.** Tracks join matches that share a view and a pixel (the dense matcher grows its
//! matches from one grid per view, so a grid point matched into two views joins them); a track
//! that lands on two pixels of one view is dropped. Each track is a 3D point, started by linear
//! triangulation from the current poses; each observation contributes its reprojection error
//! (pixels). Cameras take left se(3) steps (`P ← exp(ξ) P`, rotation first), the first view is
//! held, and the common scale, which no image sees, is restored at the end. Levenberg–Marquardt
//! with Marquardt's damping on analytic Jacobians, points eliminated by the Schur complement
//! (the `schur` module), Cauchy weights (iteratively reweighted) at `cauchy_sigmas` robust
//! standard deviations of the starting residuals. Unlike the surface method's patch adjustment, the
//! scale is not recomputed as the fit tightens: on DTU's triplets a shrinking scale kept
//! moving the optimum (docs/experiments.md, 2026-11-26).

use std::collections::HashMap;

use fewview_scene::distortion::Distortion;
use fewview_scene::{Intrinsics, Se3};
use nalgebra::{DMatrix, Matrix2, Matrix2x3, Matrix3, Vector2, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::schur::{BlockSystem, CameraSystem, LmStep, damped_step, keep_scale, robust_sigma};
use fewview_match::Match;

/// Options of [`bundle_adjust`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BundleOptions {
    /// Scale of the Cauchy weights, in robust standard deviations of the starting residuals.
    pub cauchy_sigmas: f64,
    /// Levenberg–Marquardt iterations.
    pub max_iterations: usize,
    /// Stop when an accepted step lowers the robust cost by less than this fraction.
    pub tolerance: f64,
    /// Fewest tracks worth adjusting the poses on.
    pub min_tracks: usize,
    /// Also adjust one focal length shared by all views: every `fx` and `fy` times a common
    /// factor (photos of one camera; the surface method's calibrated views keep theirs).
    #[serde(default)]
    pub refine_focal: bool,
    /// With [`Self::refine_focal`]: the standard deviation, in log scale, of a Gaussian prior
    /// holding the shared focal factor near its start (`None`: free). OpenSfM's bundle holds
    /// EXIF focal lengths so (its `exif_focal_sd`, 0.01), weighed against reprojection errors
    /// of [`REPROJECTION_SD`] of the image's long side. Photos of a camera walking forward
    /// need it: moving along the axis and zooming look alike, and a free focal drifts.
    #[serde(default)]
    pub focal_prior_sd: Option<f64>,
    /// Also adjust one radial distortion coefficient shared by all views, COLMAP's
    /// `SIMPLE_RADIAL` model: normalised coordinates `x` are seen at `x (1 + k1 |x|²)`
    /// (photos of one camera whose lens bends straight lines; started at 0).
    #[serde(default)]
    pub refine_radial: bool,
    /// Also adjust one shift of the principal point shared by all views (photos of one camera
    /// whose principal point is not the image centre; COLMAP's
    /// `refine_principal_point`, off by default there too: with few views or a narrow field of
    /// view it trades off against the rotations).
    #[serde(default)]
    pub refine_principal_point: bool,
}

impl Default for BundleOptions {
    fn default() -> Self {
        Self {
            cauchy_sigmas: 2.0,
            max_iterations: 1000,
            tolerance: 1e-9,
            min_tracks: 30,
            refine_focal: false,
            focal_prior_sd: None,
            refine_radial: false,
            refine_principal_point: false,
        }
    }
}

/// The standard deviation of a reprojection error as a fraction of the image's long side, the
/// unit a prior on the lens is weighed in (OpenSfM's `reprojection_error_sd`).
pub const REPROJECTION_SD: f64 = 0.004;

/// What [`bundle_adjust`] did.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BundleReport {
    /// Why the poses were left as they were, when they were.
    pub skipped: Option<String>,
    pub tracks: usize,
    /// Tracks seen in three views or more (the ones that tie more than a pair).
    pub multi_view_tracks: usize,
    pub observations: usize,
    pub iterations: usize,
    /// Robust cost of the first and the last iteration, each under its own iteration's weights.
    pub initial_cost: f64,
    pub final_cost: f64,
    /// Median reprojection error (pixels) before and after.
    pub median_px_before: f64,
    pub median_px_after: f64,
    /// With [`BundleOptions::refine_focal`]: the factor the focal lengths were multiplied by.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub focal_scale: Option<f64>,
    /// With [`BundleOptions::refine_radial`]: the radial coefficient `k1`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radial_k1: Option<f64>,
    /// With [`BundleOptions::refine_principal_point`]: the shift (pixels) added to every
    /// principal point.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub principal_shift_px: Option<[f64; 2]>,
}

/// A point seen in several views: (view, pixel) pairs, one per view.
#[derive(Clone, Debug, PartialEq)]
pub struct Track {
    pub observations: Vec<(usize, Vector2<f64>)>,
}

/// Joins matches that share a view and a pixel (exactly) into tracks; a track that lands on two
/// different pixels of one view is dropped.
pub fn tracks_from_matches(matches: &[Match]) -> Vec<Track> {
    let mut ids: HashMap<(usize, u32, u32), usize> = HashMap::new();
    let mut nodes: Vec<(usize, [f32; 2])> = Vec::new();
    let mut node = |view: usize, p: [f32; 2]| {
        *ids.entry((view, p[0].to_bits(), p[1].to_bits()))
            .or_insert_with(|| {
                nodes.push((view, p));
                nodes.len() - 1
            })
    };
    let edges: Vec<(usize, usize)> = matches
        .iter()
        .map(|m| (node(m.view_a, m.a), node(m.view_b, m.b)))
        .collect();
    let mut parent: Vec<usize> = (0..nodes.len()).collect();
    fn root(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    for (a, b) in edges {
        let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
        parent[ra.max(rb)] = ra.min(rb);
    }
    let mut groups: Vec<Vec<usize>> = vec![Vec::new(); nodes.len()];
    for n in 0..nodes.len() {
        let r = root(&mut parent, n);
        groups[r].push(n);
    }
    groups
        .into_iter()
        .filter(|g| g.len() >= 2)
        .filter_map(|g| {
            let mut observations: Vec<(usize, Vector2<f64>)> = g
                .iter()
                .map(|&n| {
                    let (v, p) = nodes[n];
                    (v, Vector2::new(p[0] as f64, p[1] as f64))
                })
                .collect();
            observations.sort_by_key(|o| o.0);
            let unique = observations.windows(2).all(|w| w[0].0 != w[1].0);
            unique.then_some(Track { observations })
        })
        .collect()
}

/// The cameras' intrinsic matrices, their inverses and the lens they share (`None`: pinhole).
struct Cameras {
    k: Vec<Matrix3<f64>>,
    k_inv: Vec<Matrix3<f64>>,
    lens: Option<Distortion>,
}

impl Cameras {
    /// `None` unless every focal length is positive (the only way a pinhole `K` is singular).
    fn new(intrinsics: &[Intrinsics]) -> Option<Self> {
        Self::with_radial(intrinsics, 0.0)
    }

    /// The cameras of `intrinsics` seen through a `SIMPLE_RADIAL` lens of coefficient `k1`.
    fn with_radial(intrinsics: &[Intrinsics], k1: f64) -> Option<Self> {
        if !intrinsics.iter().all(|i| i.fx > 0.0 && i.fy > 0.0) {
            return None;
        }
        let k: Vec<Matrix3<f64>> = intrinsics.iter().map(Intrinsics::matrix).collect();
        let k_inv = intrinsics
            .iter()
            .map(|i| {
                let (fx, fy) = (i.fx, i.fy);
                Matrix3::new(
                    1.0 / fx,
                    0.0,
                    -i.cx / fx,
                    0.0,
                    1.0 / fy,
                    -i.cy / fy,
                    0.0,
                    0.0,
                    1.0,
                )
            })
            .collect();
        // COLMAP's SIMPLE_RADIAL is OpenCV's radial–tangential model with k1 alone.
        let lens = (k1 != 0.0).then(|| Distortion::opencv(&[k1]));
        Some(Self { k, k_inv, lens })
    }

    /// The normalised coordinates of pixel `p` of view `v`: `K⁻¹ p` with the lens undone
    /// ([`Distortion::undistort`]); `None` where the lens does not invert.
    fn normalised(&self, v: usize, p: &Vector2<f64>) -> Option<Vector2<f64>> {
        let d = self.k_inv[v] * Vector3::new(p.x, p.y, 1.0);
        match &self.lens {
            None => Some(Vector2::new(d.x, d.y)),
            Some(lens) => lens.undistort(d.x, d.y).map(|(x, y)| Vector2::new(x, y)),
        }
    }

    /// The pixel of world point `x` in view `v`, and the 2 × 3 Jacobian of that pixel with
    /// respect to the point in the camera's frame; `None` behind the camera.
    fn project(
        &self,
        v: usize,
        pose: &Se3,
        x: &Vector3<f64>,
    ) -> Option<(Vector2<f64>, Matrix2x3<f64>, Vector3<f64>)> {
        let c = pose.rotation * x + pose.translation;
        if c.z <= 1e-12 {
            return None;
        }
        let k = &self.k[v];
        let (fx, fy) = (k[(0, 0)], k[(1, 1)]);
        let (x, y) = (c.x / c.z, c.y / c.z);
        let ((xd, yd), j) = match &self.lens {
            None => ((x, y), [1.0, 0.0, 0.0, 1.0]),
            Some(lens) => lens.distort_with_jacobian(x, y),
        };
        let pixel = Vector2::new(fx * xd + k[(0, 2)], fy * yd + k[(1, 2)]);
        // d(pixel)/d(x, y) through the lens, times d(x, y)/d(camera point).
        let through_lens = Matrix2::new(fx * j[0], fx * j[1], fy * j[2], fy * j[3]);
        let perspective = Matrix2x3::new(1.0 / c.z, 0.0, -x / c.z, 0.0, 1.0 / c.z, -y / c.z);
        Some((pixel, through_lens * perspective, c))
    }
}

/// Linear (DLT) triangulation of a track from normalised image coordinates; `None` when the
/// point does not lie in front of every camera.
fn triangulate(cameras: &Cameras, poses: &[Se3], track: &Track) -> Option<Vector3<f64>> {
    let mut a = DMatrix::<f64>::zeros(2 * track.observations.len(), 4);
    for (i, (v, p)) in track.observations.iter().enumerate() {
        let x = cameras.normalised(*v, p)?;
        let (r, t) = (&poses[*v].rotation, &poses[*v].translation);
        for (row, coordinate) in [(2 * i, 0), (2 * i + 1, 1)] {
            for j in 0..3 {
                a[(row, j)] = x[coordinate] * r[(2, j)] - r[(coordinate, j)];
            }
            a[(row, 3)] = x[coordinate] * t.z - t[coordinate];
        }
    }
    let svd = a.svd(false, true);
    let v_t = svd.v_t?;
    let (smallest, _) = svd
        .singular_values
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    let h = v_t.row(smallest).transpose();
    if h[3].abs() < 1e-15 {
        return None;
    }
    let x = Vector3::new(h[0], h[1], h[2]) / h[3];
    let in_front = track
        .observations
        .iter()
        .all(|(v, _)| (poses[*v].rotation * x + poses[*v].translation).z > 0.0);
    in_front.then_some(x)
}

/// The reprojection residuals (2 per observation) of a track at point `x`; `None` when the
/// point is behind one of its cameras.
fn reprojection_errors(
    cameras: &Cameras,
    poses: &[Se3],
    track: &Track,
    x: &Vector3<f64>,
) -> Option<Vec<f64>> {
    let mut out = Vec::with_capacity(2 * track.observations.len());
    for (v, p) in &track.observations {
        let (pixel, _, _) = cameras.project(*v, &poses[*v], x)?;
        out.extend([pixel.x - p.x, pixel.y - p.y]);
    }
    Some(out)
}

/// Per-observation Cauchy weights (on the residual's length) at `scale` pixels.
fn cauchy_weights(r: &[f64], scale: f64) -> Vec<f64> {
    r.chunks(2)
        .map(|d| 1.0 / (1.0 + (d[0] * d[0] + d[1] * d[1]) / (scale * scale)))
        .collect()
}

fn weighted_cost(r: &[f64], w: &[f64]) -> f64 {
    r.chunks(2)
        .zip(w)
        .map(|(d, w)| w * (d[0] * d[0] + d[1] * d[1]))
        .sum()
}

/// The intrinsics with every focal length times `scale` (what [`BundleReport::focal_scale`]
/// asks of the intrinsics a bundle adjustment started from).
pub fn scaled_focal(intrinsics: &[Intrinsics], scale: f64) -> Vec<Intrinsics> {
    intrinsics
        .iter()
        .map(|k| Intrinsics {
            fx: k.fx * scale,
            fy: k.fy * scale,
            ..*k
        })
        .collect()
}

/// The intrinsics a bundle adjustment started from, with the focal factor and principal point
/// shift its report found applied.
pub fn adjusted_intrinsics(intrinsics: &[Intrinsics], report: &BundleReport) -> Vec<Intrinsics> {
    let scale = report.focal_scale.unwrap_or(1.0);
    shifted_and_scaled(intrinsics, scale, report.principal_shift_px)
}

/// `intrinsics` with every focal length times `scale` and every principal point moved by
/// `shift` (pixels).
fn shifted_and_scaled(
    intrinsics: &[Intrinsics],
    scale: f64,
    shift: Option<[f64; 2]>,
) -> Vec<Intrinsics> {
    let [dx, dy] = shift.unwrap_or([0.0; 2]);
    scaled_focal(intrinsics, scale)
        .into_iter()
        .map(|k| Intrinsics {
            cx: k.cx + dx,
            cy: k.cy + dy,
            ..k
        })
        .collect()
}

/// The shared lens parameters being adjusted: the logarithm of the focal factor, `k1` and the
/// principal point's shift (`None`: held).
#[derive(Clone, Copy, Debug, Default)]
struct Lens {
    log_focal: Option<f64>,
    k1: Option<f64>,
    principal: Option<[f64; 2]>,
}

impl Lens {
    /// The columns of the adjusted lens parameters after `pose_parameters` pose columns.
    fn columns(&self, pose_parameters: usize) -> LensColumns {
        let mut next = pose_parameters;
        let mut take = |held: bool, width: usize| {
            (!held).then(|| {
                next += width;
                next - width
            })
        };
        LensColumns {
            focal: take(self.log_focal.is_none(), 1),
            radial: take(self.k1.is_none(), 1),
            principal: take(self.principal.is_none(), 2),
        }
    }

    /// The lens moved by the lens entries of a camera step.
    fn stepped(&self, columns: &LensColumns, step: &[f64]) -> Self {
        let entry = |column: Option<usize>, offset: usize| column.map_or(0.0, |c| step[c + offset]);
        Self {
            log_focal: self.log_focal.map(|f| f + entry(columns.focal, 0)),
            k1: self.k1.map(|k| k + entry(columns.radial, 0)),
            principal: self.principal.map(|[x, y]| {
                [
                    x + entry(columns.principal, 0),
                    y + entry(columns.principal, 1),
                ]
            }),
        }
    }

    /// The prior's residual on the focal factor, in pixels (0 without a prior).
    fn prior_residual(&self, prior: Option<FocalPrior>) -> f64 {
        match (self.log_focal, prior) {
            (Some(f), Some(p)) => p.pixels_per_log * f,
            _ => 0.0,
        }
    }

    /// What this lens adds to a report: the adjusted parameters.
    fn report_into(&self, report: &mut BundleReport) {
        report.focal_scale = self.log_focal.map(f64::exp);
        report.radial_k1 = self.k1;
        report.principal_shift_px = self.principal;
    }

    /// The cameras of the intrinsics `base` seen through this lens.
    fn cameras(&self, base: &[Intrinsics]) -> Option<Cameras> {
        let scale = self.log_focal.unwrap_or(0.0).exp();
        let intrinsics = shifted_and_scaled(base, scale, self.principal);
        Cameras::with_radial(&intrinsics, self.k1.unwrap_or(0.0))
    }
}

/// A Gaussian prior on the logarithm of the shared focal factor, as a residual in pixels:
/// `pixels_per_log · log f` (the reprojection errors' standard deviation over the prior's).
#[derive(Clone, Copy, Debug)]
struct FocalPrior {
    pixels_per_log: f64,
}

impl FocalPrior {
    fn new(options: &BundleOptions, intrinsics: &[Intrinsics]) -> Option<Self> {
        let sd = options.focal_prior_sd.filter(|_| options.refine_focal)?;
        let long_side = intrinsics
            .iter()
            .map(|k| f64::from(k.width.max(k.height)))
            .fold(0.0, f64::max);
        (sd > 0.0).then(|| Self {
            pixels_per_log: REPROJECTION_SD * long_side / sd,
        })
    }
}

/// Where the adjusted lens parameters sit among the camera columns (the principal point's
/// shift takes two: x, then y).
#[derive(Clone, Copy, Debug)]
struct LensColumns {
    focal: Option<usize>,
    radial: Option<usize>,
    principal: Option<usize>,
}

impl LensColumns {
    fn count(&self) -> usize {
        usize::from(self.focal.is_some())
            + usize::from(self.radial.is_some())
            + 2 * usize::from(self.principal.is_some())
    }
}

/// The weighted normal equations of one track with analytic Jacobians. Camera parameters:
/// 6 per free view (`6 (view − 1) + k`, twist rotation first), then the adjusted lens
/// parameters, which every observation depends on: the logarithm of the shared focal factor
/// (`∂pixel/∂log f = pixel − principal point`) and the radial coefficient
/// (`∂pixel/∂k1 = (fx x r², fy y r²)` at normalised `(x, y)`, `r² = x² + y²`) and the
/// principal point's shift (`∂pixel/∂(cx, cy)` = identity).
fn track_system(
    cameras: &Cameras,
    poses: &[Se3],
    track: &Track,
    x: &Vector3<f64>,
    (r, w): (&[f64], &[f64]),
    lens: LensColumns,
) -> BlockSystem {
    let mut v = Matrix3::zeros();
    let mut g = Vector3::zeros();
    let mut columns = Vec::new();
    let mut wrows = Vec::new();
    let mut gc = Vec::new();
    // Per observation: its (column, Jacobian column) pairs.
    let mut observed: Vec<Vec<(usize, Vector2<f64>)>> = Vec::new();
    for (i, (view, _)) in track.observations.iter().enumerate() {
        let pose = &poses[*view];
        let Some((pixel, jp, c)) = cameras.project(*view, pose, x) else {
            continue;
        };
        let res = Vector2::new(r[2 * i], r[2 * i + 1]);
        let j_point = jp * pose.rotation;
        v += w[i] * j_point.transpose() * j_point;
        g += w[i] * j_point.transpose() * res;
        let mut jac: Vec<(usize, Vector2<f64>)> = Vec::new();
        if *view > 0 {
            // d(camera point)/d(twist): −[c]× for the rotation, identity for the translation.
            let skew = Matrix3::new(0.0, -c.z, c.y, c.z, 0.0, -c.x, -c.y, c.x, 0.0);
            let j_rot = jp * (-skew);
            for k in 0..6 {
                let column = if k < 3 {
                    j_rot.column(k).into()
                } else {
                    jp.column(k - 3).into()
                };
                jac.push((6 * (view - 1) + k, column));
            }
        }
        let k = &cameras.k[*view];
        if let Some(f) = lens.focal {
            jac.push((f, Vector2::new(pixel.x - k[(0, 2)], pixel.y - k[(1, 2)])));
        }
        if let Some(column) = lens.radial {
            let (nx, ny) = (c.x / c.z, c.y / c.z);
            let r2 = nx * nx + ny * ny;
            jac.push((
                column,
                Vector2::new(k[(0, 0)] * nx * r2, k[(1, 1)] * ny * r2),
            ));
        }
        if let Some(column) = lens.principal {
            jac.push((column, Vector2::new(1.0, 0.0)));
            jac.push((column + 1, Vector2::new(0.0, 1.0)));
        }
        for (column, j) in &jac {
            columns.push(*column);
            wrows.push(w[i] * j_point.transpose() * j);
            gc.push(w[i] * j.dot(&res));
        }
        observed.push(jac.into_iter().map(|(c, j)| (c, j * w[i].sqrt())).collect());
    }
    // `J_cᵀ J_c` is block diagonal over the observations (each residual sees its own columns).
    let n = columns.len();
    let mut u = vec![0.0; n * n];
    let mut offset = 0;
    for jac in &observed {
        for (a, (_, ja)) in jac.iter().enumerate() {
            for (b, (_, jb)) in jac.iter().enumerate() {
                u[(offset + a) * n + offset + b] = ja.dot(jb);
            }
        }
        offset += jac.len();
    }
    BlockSystem {
        v,
        g,
        columns,
        w: wrows,
        u,
        gc,
    }
}

/// One iteration: residuals and Cauchy weights (at `scale` pixels) at the current estimate
/// (the intrinsics `base` seen through `lens`), the tracks' systems, then damped steps until
/// one lowers the weighted cost (the damping rising ten-fold each time it does not) or the
/// damping exceeds 10⁶.
fn iterate(
    (base, prior): (&[Intrinsics], Option<FocalPrior>),
    lens: Lens,
    (tracks, points): (&[Track], &[Vector3<f64>]),
    poses: &[Se3],
    scale: f64,
    lambda: &mut f64,
) -> LmStep<Vector3<f64>> {
    let Some(cameras) = lens.cameras(base) else {
        return LmStep {
            cost_before: f64::INFINITY,
            cost_after: f64::INFINITY,
            accepted: None,
            camera_step: None,
        };
    };
    let residuals: Vec<Vec<f64>> = tracks
        .par_iter()
        .zip(points)
        // Accepted steps keep every point in front of its cameras (a step that puts one behind
        // costs infinity and is refused), so no track lacks its residuals here.
        .map(|(t, x)| {
            reprojection_errors(&cameras, poses, t, x)
                .unwrap_or_else(|| vec![0.0; 2 * t.observations.len()])
        })
        .collect();
    let weights: Vec<Vec<f64>> = residuals.iter().map(|r| cauchy_weights(r, scale)).collect();
    let cost_before: f64 = residuals
        .iter()
        .zip(&weights)
        .map(|(r, w)| weighted_cost(r, w))
        .sum::<f64>()
        + lens.prior_residual(prior).powi(2);
    let pose_parameters = 6 * (poses.len() - 1);
    let columns = lens.columns(pose_parameters);
    let systems: Vec<BlockSystem> = tracks
        .par_iter()
        .zip(points)
        .zip(residuals.par_iter().zip(&weights))
        .map(|((t, x), (r, w))| track_system(&cameras, poses, t, x, (r, w), columns))
        .collect();
    let free = pose_parameters + columns.count();
    let mut system = CameraSystem::new(free, &systems);
    if let (Some(p), Some(column)) = (prior, columns.focal) {
        system.add_prior(column, p.pixels_per_log, lens.prior_residual(prior));
    }
    damped_step(
        &system,
        &systems,
        (poses, points),
        cost_before,
        (lambda, 1e-9),
        |x, step| x + step,
        |new_poses, new_points, step| {
            let stepped = lens.stepped(&columns, step.as_slice());
            let Some(cameras) = stepped.cameras(base) else {
                return f64::INFINITY;
            };
            // Summed in order after the parallel part, so that a run repeats bit for bit.
            let costs: Vec<f64> = tracks
                .par_iter()
                .zip(new_points)
                .zip(&weights)
                .map(|((t, x), w)| {
                    reprojection_errors(&cameras, new_poses, t, x)
                        .map_or(f64::INFINITY, |r| weighted_cost(&r, w))
                })
                .collect();
            costs.iter().sum::<f64>() + stepped.prior_residual(prior).powi(2)
        },
    )
}

/// Median reprojection error (pixels) of all observations.
fn median_error(
    cameras: &Cameras,
    poses: &[Se3],
    tracks: &[Track],
    points: &[Vector3<f64>],
) -> f64 {
    let mut lengths: Vec<f64> = tracks
        .iter()
        .zip(points)
        .filter_map(|(t, x)| reprojection_errors(cameras, poses, t, x))
        .flat_map(|r| r.chunks(2).map(|d| d[0].hypot(d[1])).collect::<Vec<_>>())
        .collect();
    if lengths.is_empty() {
        return f64::NAN;
    }
    let middle = lengths.len() / 2;
    *lengths.select_nth_unstable_by(middle, f64::total_cmp).1
}

/// Adjusts `poses` (view 0 held, the common scale kept) and the tracks of `matches` to
/// minimise the robust reprojection error (module docs). Returns the poses unchanged, with the
/// reason in the report, when fewer than `min_tracks` tracks triangulate.
pub fn bundle_adjust(
    intrinsics: &[Intrinsics],
    poses: &[Se3],
    matches: &[Match],
    options: &BundleOptions,
) -> (Vec<Se3>, BundleReport) {
    bundle_adjust_with(intrinsics, poses, matches, options, |_| {})
}

/// [`bundle_adjust`], telling `on_iteration(k)` after its `k`-th Levenberg–Marquardt
/// iteration (at most [`BundleOptions::max_iterations`]).
pub fn bundle_adjust_with(
    intrinsics: &[Intrinsics],
    poses: &[Se3],
    matches: &[Match],
    options: &BundleOptions,
    on_iteration: impl Fn(usize),
) -> (Vec<Se3>, BundleReport) {
    let Some(cameras) = Cameras::new(intrinsics) else {
        let report = BundleReport {
            skipped: Some("intrinsics with a focal length that is not positive".into()),
            ..Default::default()
        };
        return (poses.to_vec(), report);
    };
    let (tracks, mut points): (Vec<Track>, Vec<Vector3<f64>>) = tracks_from_matches(matches)
        .into_iter()
        .filter_map(|t| triangulate(&cameras, poses, &t).map(|x| (t, x)))
        .unzip();
    let mut report = BundleReport {
        tracks: tracks.len(),
        multi_view_tracks: tracks.iter().filter(|t| t.observations.len() >= 3).count(),
        observations: tracks.iter().map(|t| t.observations.len()).sum(),
        ..Default::default()
    };
    if tracks.len() < options.min_tracks || poses.len() < 2 {
        report.skipped = Some(format!(
            "{} tracks triangulate from {} matches (fewer than {})",
            tracks.len(),
            matches.len(),
            options.min_tracks
        ));
        return (poses.to_vec(), report);
    }
    report.median_px_before = median_error(&cameras, poses, &tracks, &points);
    let mut current = poses.to_vec();
    let mut lens = Lens {
        log_focal: options.refine_focal.then_some(0.0),
        k1: options.refine_radial.then_some(0.0),
        principal: options.refine_principal_point.then_some([0.0; 2]),
    };
    let prior = FocalPrior::new(options, intrinsics);
    let mut lambda = 1e-3;
    // The Cauchy scale is set once, from the residuals at the start: recomputed every
    // iteration it would shrink with the fit and keep re-deciding which tracks count.
    let start_residuals = tracks
        .iter()
        .zip(&points)
        .filter_map(|(t, x)| reprojection_errors(&cameras, poses, t, x))
        .flatten();
    let scale = (options.cauchy_sigmas * robust_sigma(start_residuals)).max(1e-9);
    let columns = lens.columns(6 * (poses.len() - 1));
    for iteration in 0..options.max_iterations {
        let step = iterate(
            (intrinsics, prior),
            lens,
            (&tracks, &points),
            &current,
            scale,
            &mut lambda,
        );
        report.iterations = iteration + 1;
        on_iteration(iteration + 1);
        if iteration == 0 {
            report.initial_cost = step.cost_before;
        }
        report.final_cost = step.cost_after;
        let (Some((poses_after, points_after)), Some(camera_step)) =
            (step.accepted, step.camera_step)
        else {
            break;
        };
        current = poses_after;
        points = points_after;
        lens = lens.stepped(&columns, camera_step.as_slice());
        let decrease =
            (step.cost_before - step.cost_after) / step.cost_before.max(f64::MIN_POSITIVE);
        if decrease < options.tolerance {
            break;
        }
    }
    lens.report_into(&mut report);
    if let Some(cameras) = lens.cameras(intrinsics) {
        report.median_px_after = median_error(&cameras, &current, &tracks, &points);
    }
    (keep_scale(poses, &current), report)
}

/// A track's triangulated point and the reprojection error of each of its observations.
#[derive(Clone, Debug, PartialEq)]
pub struct TriangulatedTrack {
    pub track: Track,
    pub point: Vector3<f64>,
    /// Pixels, one per observation, in the track's order.
    pub errors_px: Vec<f64>,
}

/// The tracks of `matches` triangulated from `poses` (linear triangulation) through cameras of
/// `intrinsics` and the radial coefficient `k1` (0: pinhole), with their reprojection errors;
/// tracks that do not triangulate in front of their cameras are left out.
pub fn triangulated_tracks(
    intrinsics: &[Intrinsics],
    k1: f64,
    poses: &[Se3],
    matches: &[Match],
) -> Vec<TriangulatedTrack> {
    let Some(cameras) = Cameras::with_radial(intrinsics, k1) else {
        return Vec::new();
    };
    tracks_from_matches(matches)
        .into_iter()
        .filter_map(|track| {
            let point = triangulate(&cameras, poses, &track)?;
            let r = reprojection_errors(&cameras, poses, &track, &point)?;
            let errors_px = r.chunks(2).map(|d| d[0].hypot(d[1])).collect();
            Some(TriangulatedTrack {
                track,
                point,
                errors_px,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::se3::se3_exp;
    use fewview_geom::similarity::rotation_angle_deg as angle_deg;

    fn rotation_angle_deg(a: &Matrix3<f64>, b: &Matrix3<f64>) -> f64 {
        angle_deg(&(a * b.transpose()))
    }
    use nalgebra::{Rotation3, Unit};

    /// Three cameras 2.5 units from a cloud of points near the origin, looking at it, 20° apart
    /// (DTU's wide triplet in miniature).
    fn rig() -> (Vec<Intrinsics>, Vec<Se3>, Vec<Vector3<f64>>) {
        let intrinsics = vec![
            Intrinsics {
                fx: 500.0,
                fy: 510.0,
                cx: 200.0,
                cy: 150.0,
                width: 400,
                height: 300
            };
            3
        ];
        let poses = (0..3)
            .map(|i| {
                let angle = (i as f64 - 1.0) * 20f64.to_radians();
                looking_at_origin(Vector3::new(2.5 * angle.sin(), -0.3, -2.5 * angle.cos()))
            })
            .collect();
        let points = (0..150)
            .map(|i| {
                let f = i as f64;
                Vector3::new(
                    (f * 0.37).sin() * 0.5,
                    (f * 0.61).cos() * 0.4,
                    (f * 0.23).sin() * 0.3,
                )
            })
            .collect();
        (intrinsics, poses, points)
    }

    /// A camera at `centre` looking at the origin, image rows along the world's y.
    fn looking_at_origin(centre: Vector3<f64>) -> Se3 {
        let forward = (-centre).normalize();
        let right = Vector3::y().cross(&forward).normalize();
        let down = forward.cross(&right);
        let r = Matrix3::from_rows(&[right.transpose(), down.transpose(), forward.transpose()]);
        Se3::new(r, -(r * centre))
    }

    /// Matches of every pair of views at the points' exact projections.
    fn exact_matches(
        intrinsics: &[Intrinsics],
        poses: &[Se3],
        points: &[Vector3<f64>],
    ) -> Vec<Match> {
        exact_matches_through(&Cameras::new(intrinsics).unwrap(), poses, points)
    }

    /// [`exact_matches`] of the given cameras (with their lens).
    fn exact_matches_through(
        cameras: &Cameras,
        poses: &[Se3],
        points: &[Vector3<f64>],
    ) -> Vec<Match> {
        let pixel = |v: usize, x: &Vector3<f64>| {
            let (p, _, _) = cameras.project(v, &poses[v], x).unwrap();
            [p.x as f32, p.y as f32]
        };
        let mut matches = Vec::new();
        let n = poses.len();
        let pairs: Vec<(usize, usize)> = (0..n)
            .flat_map(|a| (a + 1..n).map(move |b| (a, b)))
            .collect();
        for x in points {
            for &(a, b) in &pairs {
                matches.push(Match {
                    view_a: a,
                    view_b: b,
                    a: pixel(a, x),
                    b: pixel(b, x),
                    confidence: 1.0,
                    b_covariance: None,
                });
            }
        }
        matches
    }

    #[test]
    fn tracks_join_shared_pixels_and_drop_conflicts() {
        let m = |view_a, a: [f32; 2], view_b, b: [f32; 2]| Match {
            view_a,
            view_b,
            a,
            b,
            confidence: 1.0,
            b_covariance: None,
        };
        let matches = vec![
            m(0, [1.0, 2.0], 1, [3.0, 4.0]),
            m(0, [1.0, 2.0], 2, [5.0, 6.0]),
            m(1, [3.0, 4.0], 2, [5.0, 6.0]),
            // A pair on its own.
            m(0, [7.0, 7.0], 1, [8.0, 8.0]),
            // Two pixels of view 2 for one point of view 0: dropped.
            m(0, [9.0, 9.0], 2, [1.0, 1.0]),
            m(0, [9.0, 9.0], 1, [2.0, 2.0]),
            m(1, [2.0, 2.0], 2, [3.0, 3.0]),
        ];
        let tracks = tracks_from_matches(&matches);
        assert_eq!(tracks.len(), 2);
        let lengths: Vec<usize> = tracks.iter().map(|t| t.observations.len()).collect();
        assert!(lengths.contains(&3) && lengths.contains(&2));
        let triple = tracks.iter().find(|t| t.observations.len() == 3).unwrap();
        assert_eq!(triple.observations[2], (2, Vector2::new(5.0, 6.0)));
    }

    /// The analytic Jacobians against central differences of the weighted cost: `Jᵀ W r` is
    /// half the cost's gradient, for the point and for each free camera's twist.
    #[test]
    fn the_normal_equations_match_finite_differences_of_the_cost() {
        for k1 in [0.0, -0.15] {
            normal_equations_match_finite_differences(k1);
        }
    }

    /// [`the_normal_equations_match_finite_differences_of_the_cost`] through a lens `k1`.
    fn normal_equations_match_finite_differences(k1: f64) {
        let (intrinsics, poses, points) = rig();
        let cameras = Cameras::with_radial(&intrinsics, k1).unwrap();
        let track = Track {
            observations: (0..3)
                .map(|v| {
                    let (p, _, _) = cameras.project(v, &poses[v], &points[5]).unwrap();
                    (v, p + Vector2::new(0.7 * v as f64 - 0.4, 0.3))
                })
                .collect(),
        };
        let x = points[5] + Vector3::new(0.01, -0.02, 0.015);
        let r = reprojection_errors(&cameras, &poses, &track, &x).unwrap();
        let w = vec![0.9, 0.5, 0.25];
        let pinhole = LensColumns {
            focal: None,
            radial: None,
            principal: None,
        };
        let system = track_system(&cameras, &poses, &track, &x, (&r, &w), pinhole);
        let cost = |poses: &[Se3], x: &Vector3<f64>| {
            weighted_cost(
                &reprojection_errors(&cameras, poses, &track, x).unwrap(),
                &w,
            )
        };
        let h = 1e-6;
        for k in 0..3 {
            let mut e = Vector3::zeros();
            e[k] = h;
            let numeric = (cost(&poses, &(x + e)) - cost(&poses, &(x - e))) / (4.0 * h);
            assert!(
                (numeric - system.g[k]).abs() < 1e-5 * (1.0 + numeric.abs()),
                "point {k}"
            );
        }
        for (i, &column) in system.columns.iter().enumerate() {
            let (view, k) = (column / 6 + 1, column % 6);
            let moved = |sign: f64| {
                let mut xi = [0.0; 6];
                xi[k] = sign * h;
                let mut p = poses.clone();
                p[view] = se3_exp(&xi).compose(&poses[view]);
                p
            };
            let numeric = (cost(&moved(1.0), &x) - cost(&moved(-1.0), &x)) / (4.0 * h);
            assert!(
                (numeric - system.gc[i]).abs() < 1e-5 * (1.0 + numeric.abs()),
                "camera {view} twist {k}: {numeric} vs {}",
                system.gc[i]
            );
        }
    }

    #[test]
    fn exact_matches_bring_perturbed_poses_back_to_the_truth() {
        let (intrinsics, truth, points) = rig();
        let matches = exact_matches(&intrinsics, &truth, &points);
        let mut start = truth.clone();
        for (v, axis) in [
            (1, Vector3::new(0.3, 1.0, -0.2)),
            (2, Vector3::new(-1.0, 0.2, 0.5)),
        ] {
            let turn = Rotation3::from_axis_angle(&Unit::new_normalize(axis), 0.5f64.to_radians());
            start[v] = Se3::new(
                turn.into_inner() * truth[v].rotation,
                truth[v].translation * 1.01,
            );
        }
        let (adjusted, report) =
            bundle_adjust(&intrinsics, &start, &matches, &BundleOptions::default());
        assert_eq!(report.skipped, None);
        assert_eq!((report.tracks, report.multi_view_tracks), (150, 150));
        assert!(report.median_px_after < 1e-3, "{report:?}");
        for v in 0..3 {
            let error = rotation_angle_deg(&adjusted[v].rotation, &truth[v].rotation);
            assert!(error < 1e-4, "view {v}: {error}°");
            let (c, t) = (
                adjusted[v].inverse().translation,
                truth[v].inverse().translation,
            );
            // Centres agree up to the common scale, which keep_scale fixes to the start's.
            let (c0, t0) = (
                adjusted[0].inverse().translation,
                truth[0].inverse().translation,
            );
            if v > 0 {
                let cos = (c - c0).normalize().dot(&(t - t0).normalize());
                assert!(
                    cos > 1.0 - 1e-9,
                    "view {v}: baseline direction off by {cos}"
                );
            }
        }
    }

    /// The lens columns' gradients against central differences of the cost in the logarithm
    /// of the shared focal factor and in `k1` (summed over the observations that carry them),
    /// through a bent lens.
    #[test]
    fn the_lens_columns_match_finite_differences_of_the_cost() {
        let (intrinsics, poses, points) = rig();
        let k1 = -0.1;
        let cameras = Cameras::with_radial(&intrinsics, k1).unwrap();
        let track = Track {
            observations: (0..3)
                .map(|v| {
                    let (p, _, _) = cameras.project(v, &poses[v], &points[7]).unwrap();
                    (v, p + Vector2::new(0.5 - 0.3 * v as f64, -0.6))
                })
                .collect(),
        };
        let x = points[7] + Vector3::new(-0.01, 0.02, 0.01);
        let r = reprojection_errors(&cameras, &poses, &track, &x).unwrap();
        let w = vec![0.8, 0.6, 0.3];
        let (focal, radial, principal) = (12, 13, 14);
        let columns = LensColumns {
            focal: Some(focal),
            radial: Some(radial),
            principal: Some(principal),
        };
        let system = track_system(&cameras, &poses, &track, &x, (&r, &w), columns);
        let analytic = |column: usize| -> f64 {
            system
                .columns
                .iter()
                .zip(&system.gc)
                .filter(|(c, _)| **c == column)
                .map(|(_, g)| g)
                .sum()
        };
        let cost = |log_focal: f64, k1: f64, shift: [f64; 2]| {
            let lens = Lens {
                log_focal: Some(log_focal),
                k1: Some(k1),
                principal: Some(shift),
            };
            let cameras = lens.cameras(&intrinsics).unwrap();
            weighted_cost(
                &reprojection_errors(&cameras, &poses, &track, &x).unwrap(),
                &w,
            )
        };
        let h = 1e-6;
        for (column, numeric) in [
            (
                focal,
                (cost(h, k1, [0.0; 2]) - cost(-h, k1, [0.0; 2])) / (4.0 * h),
            ),
            (
                radial,
                (cost(0.0, k1 + h, [0.0; 2]) - cost(0.0, k1 - h, [0.0; 2])) / (4.0 * h),
            ),
            (
                principal,
                (cost(0.0, k1, [h, 0.0]) - cost(0.0, k1, [-h, 0.0])) / (4.0 * h),
            ),
            (
                principal + 1,
                (cost(0.0, k1, [0.0, h]) - cost(0.0, k1, [0.0, -h])) / (4.0 * h),
            ),
        ] {
            let analytic = analytic(column);
            assert!(
                (numeric - analytic).abs() < 1e-5 * (1.0 + numeric.abs()),
                "column {column}: {numeric} vs {analytic}"
            );
        }
    }

    /// Undistorting a distorted pixel gives back the normalised coordinates it came from.
    #[test]
    fn normalised_coordinates_undo_the_lens() {
        let (intrinsics, poses, points) = rig();
        for k1 in [-0.2, 0.0, 0.15] {
            let cameras = Cameras::with_radial(&intrinsics, k1).unwrap();
            for x in &points[..20] {
                let (pixel, _, c) = cameras.project(1, &poses[1], x).unwrap();
                let back = cameras.normalised(1, &pixel).unwrap();
                let truth = Vector2::new(c.x / c.z, c.y / c.z);
                assert!((back - truth).norm() < 1e-12, "k1 {k1}: {back} vs {truth}");
            }
        }
    }

    /// Exact matches, poses turned and the focal lengths 3 % too long: the shared focal comes
    /// back to the truth with the poses.
    #[test]
    fn a_shared_focal_three_percent_off_is_recovered() {
        let (intrinsics, truth, points) = rig();
        let matches = exact_matches(&intrinsics, &truth, &points);
        let mut start = truth.clone();
        let turn = Rotation3::from_axis_angle(
            &Unit::new_normalize(Vector3::new(0.2, 1.0, 0.1)),
            0.3f64.to_radians(),
        );
        start[2] = Se3::new(turn.into_inner() * truth[2].rotation, truth[2].translation);
        let long = scaled_focal(&intrinsics, 1.03);
        let options = BundleOptions {
            refine_focal: true,
            ..BundleOptions::default()
        };
        let (adjusted, report) = bundle_adjust(&long, &start, &matches, &options);
        let factor = report.focal_scale.unwrap();
        assert!((factor * 1.03 - 1.0).abs() < 1e-4, "focal factor {factor}");
        assert!(report.median_px_after < 1e-3, "{report:?}");
        for v in 1..3 {
            let error = rotation_angle_deg(&adjusted[v].rotation, &truth[v].rotation);
            assert!(error < 1e-3, "view {v}: {error}°");
        }
    }

    /// The same focal 3 % off under a prior: a tight one holds it where it started, a loose
    /// one lets the matches bring it back.
    #[test]
    fn a_focal_prior_holds_the_focal_by_its_width() {
        let (intrinsics, truth, points) = rig();
        let matches = exact_matches(&intrinsics, &truth, &points);
        let long = scaled_focal(&intrinsics, 1.03);
        let factor = |sd: f64| {
            let options = BundleOptions {
                refine_focal: true,
                focal_prior_sd: Some(sd),
                ..BundleOptions::default()
            };
            bundle_adjust(&long, &truth, &matches, &options)
                .1
                .focal_scale
                .unwrap()
        };
        let held = factor(1e-6);
        assert!((held - 1.0).abs() < 1e-4, "tight prior: factor {held}");
        let loose = factor(10.0);
        assert!(
            (loose * 1.03 - 1.0).abs() < 1e-3,
            "loose prior: factor {loose}"
        );
    }

    /// Matches seen through a lens (`k1` = −0.12) and adjusted from a pinhole start with the
    /// focal lengths 2 % too long: the coefficient, the focal and the poses come back.
    #[test]
    fn a_shared_radial_coefficient_is_recovered() {
        let (intrinsics, truth, points) = rig();
        let k1 = -0.12;
        let cameras = Cameras::with_radial(&intrinsics, k1).unwrap();
        let matches: Vec<Match> = exact_matches_through(&cameras, &truth, &points);
        let long = scaled_focal(&intrinsics, 1.02);
        let options = BundleOptions {
            refine_focal: true,
            refine_radial: true,
            ..BundleOptions::default()
        };
        let (adjusted, report) = bundle_adjust(&long, &truth, &matches, &options);
        let got = report.radial_k1.unwrap();
        assert!((got - k1).abs() < 1e-3 * k1.abs(), "k1 {got} vs {k1}");
        let factor = report.focal_scale.unwrap();
        assert!((factor * 1.02 - 1.0).abs() < 1e-4, "focal factor {factor}");
        assert!(report.median_px_after < 1e-3, "{report:?}");
        for v in 1..3 {
            let error = rotation_angle_deg(&adjusted[v].rotation, &truth[v].rotation);
            assert!(error < 1e-3, "view {v}: {error}°");
        }
        // Without the coefficient the same matches leave a pixel-sized residual.
        let pinhole = BundleOptions {
            refine_radial: false,
            ..options
        };
        let (_, held) = bundle_adjust(&long, &truth, &matches, &pinhole);
        assert!(
            held.median_px_after > 100.0 * report.median_px_after.max(1e-6),
            "{held:?}"
        );
    }

    /// Matches of cameras whose principal point sits 6 px right and 4 px below the centre the
    /// adjustment assumes: the shift comes back with the poses; held, it turns the cameras. The
    /// rig's arc gains a camera above and one below, as a capture moves the camera both ways;
    /// on one horizontal arc the vertical shift trades off against the pitch.
    #[test]
    fn a_shared_principal_point_shift_is_recovered() {
        let (mut intrinsics, mut truth, points) = rig();
        truth.push(looking_at_origin(Vector3::new(0.3, -1.4, -2.2)));
        truth.push(looking_at_origin(Vector3::new(-0.3, 0.9, -2.4)));
        intrinsics.resize(truth.len(), intrinsics[0]);
        let shifted: Vec<Intrinsics> = intrinsics
            .iter()
            .map(|k| Intrinsics {
                cx: k.cx + 6.0,
                cy: k.cy + 4.0,
                ..*k
            })
            .collect();
        let matches = exact_matches(&shifted, &truth, &points);
        let options = BundleOptions {
            refine_focal: true,
            refine_principal_point: true,
            ..BundleOptions::default()
        };
        let (adjusted, report) = bundle_adjust(&intrinsics, &truth, &matches, &options);
        let [dx, dy] = report.principal_shift_px.unwrap();
        assert!(
            (dx - 6.0).abs() < 1e-3 && (dy - 4.0).abs() < 1e-3,
            "{dx}, {dy}"
        );
        assert!(report.median_px_after < 1e-3, "{report:?}");
        for v in 1..truth.len() {
            let error = rotation_angle_deg(&adjusted[v].rotation, &truth[v].rotation);
            assert!(error < 1e-3, "view {v}: {error}°");
        }
        let k = &adjusted_intrinsics(&intrinsics, &report)[1];
        assert!((k.cx - shifted[1].cx).abs() < 1e-3, "{k:?}");
        let held = BundleOptions {
            refine_principal_point: false,
            ..options
        };
        // Held, the shift is mostly absorbed by turning the cameras: a small residual and
        // rotations off by a tenth of a degree.
        let (turned, without) = bundle_adjust(&intrinsics, &truth, &matches, &held);
        assert!(without.median_px_after > 1e-3, "{without:?}");
        let worst = (1..truth.len())
            .map(|v| rotation_angle_deg(&turned[v].rotation, &truth[v].rotation))
            .fold(0.0, f64::max);
        assert!(worst > 0.1, "{worst}°");
    }

    #[test]
    fn too_few_tracks_leave_the_poses_and_say_why() {
        let (intrinsics, truth, points) = rig();
        let matches = exact_matches(&intrinsics, &truth, &points[..5]);
        let (adjusted, report) =
            bundle_adjust(&intrinsics, &truth, &matches, &BundleOptions::default());
        assert_eq!(adjusted, truth);
        assert!(report.skipped.unwrap().contains("5 tracks"));
    }
}
