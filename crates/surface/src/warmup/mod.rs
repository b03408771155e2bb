//! Epipolar pose warm-up: a deviation from the surface paper, off in the paper schedule (`--pose-warmup on|off`).
//!
//! Why: the paper's joint optimisation relies on PDC-Net's thousands of dense matches per pair
//! to pull noisy poses back while the field is fitted. With the far fewer matches a classical
//! matcher finds between wide views, the colour loss fits the field to the wrong poses faster
//! than the matches correct them. The
//! matches alone, though, already fix the relative rotations and translation directions of
//! every pair through the epipolar constraint, independently of any geometry. This step
//! minimises their robust Sampson distances over the poses before the joint optimisation starts,
//! which then begins from poses the matches agree with.
//!
//! Model: each world-to-camera pose is updated on the left, `P_i ← exp(ξ_i) P_i`, with
//! `ξ_i ∈ se(3)` (rotation first, [`se3_exp`](crate::pose::se3_exp)); the residual of match `k` between views `a` and
//! `b` is the signed Sampson distance `x_bᵀ F x_a / √((F x_a)₁² + (F x_a)₂² + (Fᵀ x_b)₁² + (Fᵀ x_b)₂²)`
//! (pixels) with `F` from the current poses and the known intrinsics, weighted by the match's
//! confidence and a Cauchy weight `1 / (1 + (d/s)²)` (iteratively reweighted). The scale `s`
//! starts wide (the noisy poses put true matches tens of pixels off their epipolar lines) and
//! halves down to `cauchy_px`, so inliers steer first and
//! outliers lose their say as the poses settle. Levenberg–Marquardt with a plain
//! `λI` damping, so the directions the epipolar constraints cannot see (a global similarity of
//! all cameras) are left where they are. Jacobians by central differences (18 unknowns for
//! three views; a few hundred residuals).

mod graph;
mod options;
mod solve;

use fewview_scene::{Intrinsics, Se3};

pub use self::graph::matches_tie_the_views;
use self::graph::tying_matches;
pub use self::options::{Connectivity, WarmupOptions, WarmupReport};
use self::solve::{
    anneal, cauchy, covariance_scaled, distances, halving_scales, in_front_fraction, median_abs,
    median_variance,
};
use crate::matching::Match;
use crate::pose::into_frame_of;
use fewview_sfm::global_start::global_start;

/// Refines world-to-camera `poses` (one per view, `intrinsics` alike) so that `matches`
/// (view indices into them) satisfy their epipolar constraints. Returns the poses unchanged,
/// with the reason in the report, when the input is inconsistent or the matches too few.
pub fn epipolar_warmup(
    poses: &[Se3],
    intrinsics: &[Intrinsics],
    matches: &[Match],
    options: &WarmupOptions,
) -> (Vec<Se3>, WarmupReport) {
    let n = poses.len();
    let mut report = WarmupReport::unstarted();
    let views_ok = matches
        .iter()
        .all(|m| m.view_a < n && m.view_b < n && m.view_a != m.view_b);
    if n != intrinsics.len()
        || !views_ok
        || options.cauchy_px.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
    {
        report.skipped =
            Some("bad input (pose/intrinsics counts, match views or Cauchy scale)".into());
        return (poses.to_vec(), report);
    }
    let matches = match tying_matches(matches, n, options) {
        Ok(m) => m,
        Err(why) => {
            report.skipped = Some(why);
            return (poses.to_vec(), report);
        }
    };
    let matches = &matches[..];
    let d0 = distances(poses, intrinsics, matches);
    report.in_front = in_front_fraction(poses, intrinsics, matches);
    report.initial_median_px = median_abs(&d0);
    report.final_median_px = report.initial_median_px;
    let robust_cost = |d: &[f64]| -> f64 {
        d.iter()
            .zip(matches)
            .map(|(x, m)| m.confidence.max(0.0) as f64 * cauchy(*x, options.cauchy_px).0)
            .sum()
    };
    report.initial_cost = robust_cost(&d0);
    // Annealing runs from the initial poses, from a wide and from a narrow starting scale, and
    // from the global start at a narrow one. The epipolar constraint cannot tell a relative
    // translation `t` from `−t`, and a wide start can carry a camera over to that mirrored
    // solution (same cost, points behind the cameras); a narrow start can stop in a worse
    // minimum, and on DTU scan37 both runs from the initial poses did (12.8° off, 0.28 px
    // median against the true poses' 0.03 px), which the global start does not inherit. Each
    // run's result also stands with its translations negated (the whole set mirrored,
    // [`mirrored`]; exactly the same cost), since both runs can end mirrored: on the narrow DTU
    // triplet with quadratic-warp matches both did, every match behind the cameras and the
    // translation error ×100 99. The candidate whose triangulated matches lie in front of both
    // cameras wins; between two that do, the lower final cost.
    let wide = (2.0 * report.initial_median_px)
        .max(options.start_px)
        .max(options.cauchy_px);
    let narrow = (2.0 * report.initial_median_px).max(options.cauchy_px);
    let mut starts: Vec<(&str, Vec<Se3>, f64)> = vec![("initial, wide", poses.to_vec(), wide)];
    if narrow != wide {
        starts.push(("initial, narrow", poses.to_vec(), narrow));
    }
    if options.global_start {
        match global_start(poses, intrinsics, matches, options.min_matches_per_pair, 0) {
            Ok(g) => {
                let d = distances(&g.poses, intrinsics, matches);
                let start = (2.0 * median_abs(&d)).max(options.cauchy_px);
                report.global_start = g.pairs;
                starts.push(("global", g.poses, start));
            }
            Err(why) => report.global_start_failed = Some(why),
        }
    }
    let mut best: Option<Candidate> = None;
    for (label, start_poses, start) in &starts {
        let scales = halving_scales(*start, options.cauchy_px);
        let sampson = |p: &[Se3]| distances(p, intrinsics, matches);
        let (annealed, d, iterations) = anneal(start_poses, matches, &scales, options, &sampson);
        report.iterations += iterations;
        // The mirrored set's distances are these with their signs flipped: the same cost and
        // the same median.
        let cost = robust_cost(&d);
        for candidate in [mirrored(&annealed), annealed] {
            let front = in_front_fraction(&candidate, intrinsics, matches);
            let better = match &best {
                None => true,
                Some(b) => {
                    let (ok, best_ok) = (front >= 0.75, b.in_front >= 0.75);
                    (ok && !best_ok)
                        || (ok == best_ok && (cost < b.cost || (!ok && front > b.in_front)))
                }
            };
            if better {
                best = Some(Candidate {
                    in_front: front,
                    cost,
                    poses: candidate,
                    distances: d.clone(),
                    scales: scales.clone(),
                    label,
                });
            }
        }
    }
    let Some(best) = best else {
        return (poses.to_vec(), report);
    };
    // Never hand on poses the matches agree with less than the initial ones.
    if best.cost.partial_cmp(&report.initial_cost) != Some(std::cmp::Ordering::Less) {
        report.skipped = Some(format!(
            "the warm-up would end with a higher epipolar cost ({:.4e}) than it started ({:.4e})",
            best.cost, report.initial_cost
        ));
        return (poses.to_vec(), report);
    }
    report.scales_px = best.scales;
    report.in_front = best.in_front;
    report.chosen_start = best.label.to_string();
    report.final_cost = best.cost;
    report.final_median_px = median_abs(&best.distances);
    let mut refined = best.poses;
    // The polish starts from the chosen run's optimum, inside its basin: weighing the
    // distances during the annealing itself let one wide-triplet seed settle 12° off.
    if let Some(reference) = median_variance(matches).filter(|_| options.covariance_polish) {
        let scaled = |p: &[Se3]| covariance_scaled(p, intrinsics, matches, reference);
        let (polished, _, iterations) =
            anneal(&refined, matches, &[options.cauchy_px], options, &scaled);
        report.iterations += iterations;
        report.covariance_weighted = matches.iter().filter(|m| m.b_covariance.is_some()).count();
        report.final_median_px = median_abs(&distances(&polished, intrinsics, matches));
        refined = polished;
    }
    (into_frame_of(&refined, poses), report)
}

/// The set of cameras with every translation negated: the camera centres reflected through
/// the origin, the rotations kept. Each relative translation flips sign, so every epipolar
/// constraint (and Sampson distance) stays the same and every triangulated point moves to
/// the other side of its cameras.
fn mirrored(poses: &[Se3]) -> Vec<Se3> {
    poses
        .iter()
        .map(|p| Se3::new(p.rotation, -p.translation))
        .collect()
}

/// One annealing run's result, as [`epipolar_warmup`] compares them.
struct Candidate<'a> {
    /// Which start it came from.
    label: &'a str,
    in_front: f64,
    /// Robust cost at the final scale.
    cost: f64,
    poses: Vec<Se3>,
    distances: Vec<f64>,
    scales: Vec<f64>,
}

#[cfg(test)]
mod tests {
    use fewview_scene::axes_meeting_point;

    use super::graph::*;
    use super::solve::*;
    use super::*;
    use crate::pose::perturb_poses;
    use fewview_geom::similarity::rotation_angle_deg;
    use fewview_metrics::pose_error::{PoseErrorOptions, pose_error_pairwise};
    use fewview_scene::Camera;
    use nalgebra::Vector3;
    use rand::{RngExt, SeedableRng};

    /// `n` points uniform in the cube `[−1, 1]³`.
    fn cube_points(rng: &mut rand::rngs::StdRng, n: usize) -> Vec<Vector3<f64>> {
        (0..n)
            .map(|_| Vector3::from_fn(|_, _| 2.0 * rng.random::<f64>() - 1.0))
            .collect()
    }

    /// Three cameras around a cloud of points filling most of their images (as a DTU object
    /// does), the matches its projections.
    fn scene(outliers: f64, noise_px: f64) -> (Vec<Se3>, Vec<Intrinsics>, Vec<Match>) {
        let k = Intrinsics::centered(500.0, 400, 300);
        let cams: Vec<Camera> = [
            Vector3::new(3.0, 0.0, 0.5),
            Vector3::new(2.6, 1.5, 0.6),
            Vector3::new(2.0, 2.4, 0.4),
        ]
        .iter()
        .map(|c| Camera::look_at(k, *c, Vector3::zeros(), Vector3::z()))
        .collect();
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let points = cube_points(&mut rng, 120);
        let mut matches = Vec::new();
        for a in 0..3 {
            for b in a + 1..3 {
                for p in &points {
                    let (ua, va, _) = cams[a].project(p).unwrap();
                    let (mut ub, mut vb, _) = cams[b].project(p).unwrap();
                    ub += noise_px * (rng.random::<f64>() - 0.5) * 2.0;
                    vb += noise_px * (rng.random::<f64>() - 0.5) * 2.0;
                    if rng.random::<f64>() < outliers {
                        ub = rng.random::<f64>() * 400.0;
                        vb = rng.random::<f64>() * 300.0;
                    }
                    matches.push(Match {
                        view_a: a,
                        view_b: b,
                        a: [ua as f32, va as f32],
                        b: [ub as f32, vb as f32],
                        confidence: 1.0,
                        b_covariance: None,
                    });
                }
            }
        }
        let truth = cams.iter().map(|c| c.world_to_camera).collect();
        (truth, vec![k; 3], matches)
    }

    /// Largest error (degrees) of the pairwise relative rotations, which no global frame
    /// changes (and which has no ε floor), and Alg. 2's translation error × 100.
    fn errors(est: &[Se3], truth: &[Se3]) -> (f64, f64) {
        let mut worst: f64 = 0.0;
        for a in 0..est.len() {
            for b in a + 1..est.len() {
                let e = est[a].rotation * est[b].rotation.transpose();
                let t = truth[a].rotation * truth[b].rotation.transpose();
                worst = worst.max(crate::pose::rotation_angle_deg(&e, &t));
            }
        }
        let e = pose_error_pairwise(est, truth, &PoseErrorOptions::default()).unwrap();
        (worst, e.translation * 100.0)
    }

    #[test]
    fn exact_matches_recover_the_poses() {
        let (truth, k, matches) = scene(0.0, 0.0);
        let noisy = perturb_poses(&truth, 0.05, 3);
        let (r0, _) = errors(&noisy, &truth);
        let (refined, report) = epipolar_warmup(&noisy, &k, &matches, &WarmupOptions::default());
        let (r1, t1) = errors(&refined, &truth);
        assert!(r0 > 1.0, "initial rotation error {r0}°");
        assert!(
            r1 < 1e-3 && t1 < 1e-3,
            "{r0}° → {r1}°, t×100 {t1}; {report:?}"
        );
        assert!(report.final_median_px < 1e-3, "{report:?}");
    }

    /// From poses 40–70° off (σ = 1) every start ends on the truth, the global start's pairs
    /// are reported, and the cost fell. (On this synthetic cloud the local annealing alone
    /// also gets there; on DTU scan37's wide triplet it did not: crate README.)
    #[test]
    fn poses_far_off_are_recovered_with_the_global_start_reported() {
        let (truth, k, matches) = scene(0.1, 0.2);
        let noisy = perturb_poses(&truth, 1.0, 5);
        let (r0, _) = errors(&noisy, &truth);
        let (refined, report) = epipolar_warmup(&noisy, &k, &matches, &WarmupOptions::default());
        let (r1, _) = errors(&refined, &truth);
        assert!(r0 > 30.0, "initial rotation error {r0}°");
        assert!(r1 < 0.1, "{r0}° → {r1}°; {report:?}");
        assert_eq!(report.global_start.len(), 3, "{report:?}");
        assert!(report.global_start.iter().all(|p| p.median_px < 0.2));
        assert!(report.final_cost < report.initial_cost);
    }

    /// Poses the matches already fit exactly cannot be improved: the warm-up hands them back
    /// unchanged and says why, rather than any result of equal or higher cost.
    #[test]
    fn the_warm_up_never_ends_with_a_higher_cost_than_it_started() {
        let (truth, k, matches) = scene(0.0, 0.0);
        let (refined, report) = epipolar_warmup(&truth, &k, &matches, &WarmupOptions::default());
        let why = report.skipped.as_deref().unwrap_or_default();
        if why.is_empty() {
            assert!(report.final_cost < report.initial_cost, "{report:?}");
        } else {
            assert!(why.contains("higher epipolar cost"), "{why}");
            assert_eq!(refined, truth);
        }
        // And from noisy poses the cost always falls.
        let noisy = perturb_poses(&truth, 0.15, 9);
        let (_, report) = epipolar_warmup(&noisy, &k, &matches, &WarmupOptions::default());
        assert!(report.skipped.is_none() && report.final_cost < report.initial_cost);
    }

    /// Largest distance between the camera centres of two pose sets.
    fn centre_shift(a: &[Se3], b: &[Se3]) -> f64 {
        a.iter()
            .zip(b)
            .map(|(p, q)| (p.inverse().translation - q.inverse().translation).norm())
            .fold(0.0, f64::max)
    }

    #[test]
    fn the_refined_cameras_stay_where_the_initial_ones_were() {
        // Noise that moves the whole set (a global similarity the epipolar constraints cannot
        // see) plus per-view noise: the result keeps the initial set's placement, so the
        // cameras still look at what they looked at.
        let (truth, k, matches) = scene(0.0, 0.0);
        let noisy = perturb_poses(&truth, 0.05, 3);
        let (refined, _) = epipolar_warmup(&noisy, &k, &matches, &WarmupOptions::default());
        let initial_shift = centre_shift(&noisy, &truth);
        assert!(
            centre_shift(&refined, &noisy) <= 2.0 * initial_shift,
            "{} vs {initial_shift}",
            centre_shift(&refined, &noisy)
        );
        // The set looks where the initial one looked.
        let (p0, p1) = (axes_meeting_point(&noisy), axes_meeting_point(&refined));
        assert!((p0 - p1).norm() < 0.05, "{p0} vs {p1}");
    }

    #[test]
    fn outliers_and_pixel_noise_are_tolerated() {
        let (truth, k, matches) = scene(0.2, 0.5);
        let noisy = perturb_poses(&truth, 0.05, 4);
        let (r0, t0) = errors(&noisy, &truth);
        let (refined, report) = epipolar_warmup(&noisy, &k, &matches, &WarmupOptions::default());
        let (r1, t1) = errors(&refined, &truth);
        assert!(
            r1 < 0.1 * r0 && t1 < 0.2 * t0,
            "{r0}° → {r1}°, t×100 {t0} → {t1}; {report:?}"
        );
        assert!(report.in_front > 0.75, "{report:?}");
    }

    /// Dense matches of which every other one sits on an edge: its second end slid N(0, 1.5²)
    /// px along a random direction (and N(0, 0.05²) across it), while the others are textured
    /// points off by N(0, 0.05²) in both directions; each carries its covariance. The plain
    /// Sampson distances mix the two; the covariance polish weighs each match by its spread
    /// across its epipolar line and should land far closer to the truth.
    #[test]
    fn the_covariance_polish_discounts_matches_that_slid_along_an_edge() {
        use rand_distr::{Distribution, Normal};
        let (truth, k, mut matches) = scene(0.0, 0.0);
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        let unit = Normal::new(0.0, 1.0).unwrap();
        for (i, m) in matches.iter_mut().enumerate() {
            let angle = rng.random::<f64>() * std::f64::consts::PI;
            let (u, v) = ((angle.cos(), angle.sin()), (-angle.sin(), angle.cos()));
            let sigma_along = if i % 2 == 0 { 0.05 } else { 1.5 };
            let (s, t) = (
                sigma_along * unit.sample(&mut rng),
                0.05 * unit.sample(&mut rng),
            );
            m.b[0] += (s * u.0 + t * v.0) as f32;
            m.b[1] += (s * u.1 + t * v.1) as f32;
            let (va, vc) = (sigma_along * sigma_along, 0.05f64 * 0.05);
            m.b_covariance = Some(
                [
                    va * u.0 * u.0 + vc * v.0 * v.0,
                    va * u.0 * u.1 + vc * v.0 * v.1,
                    va * u.1 * u.1 + vc * v.1 * v.1,
                ]
                .map(|c| c as f32),
            );
        }
        let noisy = perturb_poses(&truth, 0.05, 4);
        let run = |covariance_polish: bool| {
            let options = WarmupOptions {
                covariance_polish,
                ..Default::default()
            };
            let (refined, report) = epipolar_warmup(&noisy, &k, &matches, &options);
            (errors(&refined, &truth), report)
        };
        let ((r_plain, t_plain), plain) = run(false);
        let ((r_polished, t_polished), polished) = run(true);
        eprintln!("plain {r_plain}°, t×100 {t_plain}; polished {r_polished}°, t×100 {t_polished}");
        assert_eq!(plain.covariance_weighted, 0);
        assert_eq!(polished.covariance_weighted, matches.len());
        assert!(
            r_polished < 0.5 * r_plain && t_polished < 0.5 * t_plain,
            "plain {r_plain}°, t×100 {t_plain}; polished {r_polished}°, t×100 {t_polished}"
        );
    }

    #[test]
    fn the_mirrored_solution_has_the_same_distances_but_points_behind() {
        // Negating every translation reflects the camera centres through the origin: the
        // relative translations flip sign, the epipolar constraints do not change, and the
        // triangulated points land behind the cameras (the signed distances flip sign with F).
        let (truth, k, matches) = scene(0.0, 0.0);
        let mirrored = mirrored(&truth);
        let (a, b) = (
            distances(&truth, &k, &matches),
            distances(&mirrored, &k, &matches),
        );
        assert!(
            a.iter()
                .zip(&b)
                .all(|(x, y)| (x.abs() - y.abs()).abs() < 1e-6)
        );
        assert_eq!(in_front_fraction(&truth, &k, &matches), 1.0);
        assert_eq!(in_front_fraction(&mirrored, &k, &matches), 0.0);
    }

    /// Started from the mirrored truth, slightly perturbed, both annealing runs stay on the
    /// mirrored side (every point behind the cameras, the same distances); the warm-up must
    /// still return the set with the points in front.
    #[test]
    fn a_warm_up_that_ends_mirrored_returns_the_unmirrored_set() {
        let (truth, k, matches) = scene(0.0, 0.0);
        let start = perturb_poses(&mirrored(&truth), 0.01, 5);
        let (_, t0) = errors(&start, &truth);
        let (refined, report) = epipolar_warmup(&start, &k, &matches, &WarmupOptions::default());
        let (r1, t1) = errors(&refined, &truth);
        assert!(t0 > 50.0, "the start is mirrored: t×100 {t0}");
        assert!(report.in_front > 0.99, "{report:?}");
        assert!(r1 < 1e-3 && t1 < 1e-3, "{r1}°, t×100 {t1}; {report:?}");
    }

    /// The edge predicate of the graph whose edges are `pairs` (either order).
    fn graph(pairs: &'static [(usize, usize)]) -> impl Fn(usize, usize) -> bool {
        move |a, b| pairs.contains(&(a.min(b), a.max(b)))
    }

    #[test]
    fn baseline_lengths_must_be_tied_not_just_views_shared() {
        // Triangles 034, 134, 234 chained through edge 34, plus 012: rigid.
        let chained: &[(usize, usize)] = &[
            (0, 1),
            (1, 2),
            (0, 2),
            (0, 3),
            (0, 4),
            (1, 3),
            (1, 4),
            (2, 3),
            (2, 4),
            (3, 4),
        ];
        assert!(parallel_rigid(5, &graph(chained)));
        // A bow tie: triangles 012 and 234 meet at view 2 only, so the scale of one against
        // the other is free.
        let bow_tie: &[(usize, usize)] = &[(0, 1), (1, 2), (0, 2), (2, 3), (2, 4), (3, 4)];
        assert!(!parallel_rigid(5, &graph(bow_tie)));
        // The bow tie plus one baseline across it (0–3): triangle 0-2-3 now has all three
        // directions and ties the two scales, though no new triangle shares an edge with 012.
        let tied: &[(usize, usize)] = &[(0, 1), (1, 2), (0, 2), (2, 3), (2, 4), (3, 4), (0, 3)];
        assert!(parallel_rigid(5, &graph(tied)));
        // A ring of four views: lengths free. One diagonal makes two triangles sharing it.
        let ring: &[(usize, usize)] = &[(0, 1), (1, 2), (2, 3), (0, 3)];
        assert!(!parallel_rigid(4, &graph(ring)));
        let braced: &[(usize, usize)] = &[(0, 1), (1, 2), (2, 3), (0, 3), (0, 2)];
        assert!(parallel_rigid(4, &graph(braced)));
        // Two views are always fixed up to scale; a triangle is; a chain of three is not.
        assert!(parallel_rigid(2, &graph(&[(0, 1)])));
        assert!(parallel_rigid(3, &graph(&[(0, 1), (1, 2), (0, 2)])));
        assert!(!parallel_rigid(3, &graph(&[(0, 1), (1, 2)])));
    }

    #[test]
    fn too_few_matches_leave_the_poses_alone() {
        let (truth, k, matches) = scene(0.0, 0.0);
        let (out, report) = epipolar_warmup(&truth, &k, &matches[..10], &WarmupOptions::default());
        assert_eq!(out, truth);
        assert_eq!(report.iterations, 0);
        // 120 matches per pair, but one pair cut to 30: below the default 40.
        let thin: Vec<Match> = matches
            .iter()
            .filter(|m| !(m.view_a == 0 && m.view_b == 2))
            .chain(
                matches
                    .iter()
                    .filter(|m| m.view_a == 0 && m.view_b == 2)
                    .take(30),
            )
            .copied()
            .collect();
        let (out, report) = epipolar_warmup(&truth, &k, &thin, &WarmupOptions::default());
        assert_eq!(out, truth);
        assert!(report.skipped.unwrap().contains("30"));
    }

    #[test]
    fn pairs_without_matches_are_dropped_when_the_rest_hold_the_views_together() {
        // A ring of six cameras around the cloud; each view is matched with its neighbours and
        // second neighbours (opposite views see different sides and share nothing).
        let k = Intrinsics::centered(500.0, 400, 300);
        let cams: Vec<Camera> = (0..6)
            .map(|i| {
                let a = i as f64 * std::f64::consts::TAU / 6.0;
                let eye = Vector3::new(3.0 * a.cos(), 3.0 * a.sin(), 0.4 + 0.2 * (i % 2) as f64);
                Camera::look_at(k, eye, Vector3::zeros(), Vector3::z())
            })
            .collect();
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        let points = cube_points(&mut rng, 80);
        let mut matches = Vec::new();
        for (a, b) in (0..6).flat_map(|a| [(a, (a + 1) % 6), (a, (a + 2) % 6)]) {
            for p in &points {
                let (ua, va, _) = cams[a].project(p).unwrap();
                let (ub, vb, _) = cams[b].project(p).unwrap();
                matches.push(Match {
                    view_a: a.min(b),
                    view_b: a.max(b),
                    a: if a < b {
                        [ua as f32, va as f32]
                    } else {
                        [ub as f32, vb as f32]
                    },
                    b: if a < b {
                        [ub as f32, vb as f32]
                    } else {
                        [ua as f32, va as f32]
                    },
                    confidence: 1.0,
                    b_covariance: None,
                });
            }
        }
        // A few stray matches between opposite views, below the threshold.
        matches.extend(matches.clone().iter().take(5).map(|m| Match {
            view_a: 0,
            view_b: 3,
            ..*m
        }));
        let truth: Vec<Se3> = cams.iter().map(|c| c.world_to_camera).collect();
        let noisy = perturb_poses(&truth, 0.05, 5);
        let (r0, t0) = errors(&noisy, &truth);
        let (refined, report) =
            epipolar_warmup(&noisy, &vec![k; 6], &matches, &WarmupOptions::default());
        let (r1, t1) = errors(&refined, &truth);
        assert!(report.skipped.is_none(), "{report:?}");
        assert!(
            r1 < 1e-3 * r0.max(1.0) && t1 < 1e-2 * t0,
            "{r0}° → {r1}°, t×100 {t0} → {t1}; {report:?}"
        );
        // Neighbours only: a cycle of six baselines whose lengths the directions do not fix.
        let open: Vec<Match> = matches
            .iter()
            .filter(|m| m.view_b - m.view_a == 1 || m.view_b - m.view_a == 5)
            .copied()
            .collect();
        let (out, report) = epipolar_warmup(&noisy, &vec![k; 6], &open, &WarmupOptions::default());
        assert_eq!(out, noisy);
        assert!(report.skipped.is_some());
        // Asked to run on any connected graph it does, and the relative rotations, which the
        // epipolar constraints fix on every edge, come out right even so.
        let connected = WarmupOptions {
            connectivity: Connectivity::Connected,
            ..Default::default()
        };
        let (out, report) = epipolar_warmup(&noisy, &vec![k; 6], &open, &connected);
        assert!(report.skipped.is_none(), "{report:?}");
        let relative = |p: &[Se3], a: usize, b: usize| p[b].rotation * p[a].rotation.transpose();
        for a in 0..6 {
            let b = (a + 1) % 6;
            let before =
                rotation_angle_deg(&(relative(&noisy, a, b) * relative(&truth, a, b).transpose()));
            let after =
                rotation_angle_deg(&(relative(&out, a, b) * relative(&truth, a, b).transpose()));
            assert!(
                after < 1e-3 * before.max(1.0),
                "views {a}, {b}: {before}° → {after}°"
            );
        }
    }

    #[test]
    fn a_chain_connects_but_is_not_rigid() {
        let chain: &[(usize, usize)] = &[(0, 1), (1, 2)];
        assert!(connects_all(3, &graph(chain)));
        assert!(!parallel_rigid(3, &graph(chain)));
        let split: &[(usize, usize)] = &[(0, 1), (2, 3)];
        assert!(!connects_all(4, &graph(split)));
    }
}
