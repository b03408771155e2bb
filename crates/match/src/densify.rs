//! Dense correspondences grown from sparse matches (a deviation from the surface paper, off by default:
//! `--densify`).
//!
//! **Why.** The surface paper takes PDC-Net's dense matches: thousands per pair. SIFT finds a few dozen
//! per pair on views 45° apart (the analytic ring: 5–50) and a few hundred on DTU's narrow
//! triplet, and the pose errors the matches fix shrink with their number (crate README's noise
//! analysis). The issue names dense flow with forward–backward checks as the classical
//! alternative; this is that, seeded by the sparse matches so that it needs no coarse-to-fine
//! search over the large displacements of wide baselines.
//!
//! **How.** Points of view `a` on a regular grid (`spacing_px`, inside `a`'s mask when masks
//! are used) are matched by region growing: a point next to accepted matches (within
//! `reach_px` of one) gets the affine map fitted to its nearest accepted matches as its start
//! (`refine::local_affine`); affine Lucas–Kanade with gain and bias ([`super::refine`]) moves it to
//! where the windows agree. It is accepted when the windows correlate (`min_ncc`), it stayed
//! near the prediction (`max_shift_px`), and the backward fit from `b` returns to the grid point
//! within `max_forward_backward_px`. Accepted points seed the next round, so matches spread
//! from the sparse seeds over the textured surface both views see. A pair with too few seeds
//! of its own (views 90° apart on a ring, DTU's outer pair 22–28) is seeded by composing two
//! pairs' dense matches through a third view ([`compose_through`]). Nothing here uses poses.
//!
//! **Measured** (crate README): on the analytic ring and DTU's wide triplet the warm-up can
//! then run on chained triangles (13.3° → 0.47°; 12° → 0.16–0.19°). On the narrow triplet it
//! does not lower the error (0.134° against 0.106° from the sparse matches): there the dense
//! matches' errors are correlated and do not average away.

use fewview_scene::Image;
use nalgebra::Vector2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::refine::{AffineRefineOptions, Plane, Window, end_a, end_b, local_affine, refine_one};
use crate::correspondence::{Match, mask_admits};

/// Options of [`densify_matches`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DensifyOptions {
    /// Spacing of the grid of candidate points in view `a` (pixels of the matching images).
    pub spacing_px: usize,
    /// A candidate is tried once an accepted match lies within this distance of it.
    pub reach_px: f64,
    /// Most rounds of growth.
    pub rounds: usize,
    /// Least normalised cross-correlation of the fitted windows.
    pub min_ncc: f64,
    /// Most distance between the refined `b` and the affine prediction (pixels).
    pub max_shift_px: f64,
    /// Most distance between the grid point and where the backward fit returns (pixels).
    pub max_forward_backward_px: f64,
    /// Accepted matches the affine start of a candidate is fitted to.
    pub neighbours: usize,
    /// Pairs with fewer direct seeds are seeded by composition through a third view.
    pub min_seeds: usize,
    /// Also seed by composition the pairs of views missing from the `pairs` given to
    /// [`densify_matches`] (those the matcher was not asked to match, beyond the pipeline's
    /// `max_pair_angle_deg`). The angle filter keeps look-alike SIFT matches between views that
    /// share no surface out; a composed match instead rests on two grown pairs and is then
    /// checked by its own windows, so it needs no such guard. It gives views two steps apart
    /// on a ring their matches, and DTU's wide outer pair when σ = 0.15 noise has pushed it
    /// past the angle (seed 1: 89.7°). Off by default; the surface method's CPU schedule
    /// turns it on for the dense matches it grows when the warm-up needs them.
    #[serde(default)]
    pub compose_unmatched_pairs: bool,
    /// Confidence given to composed matches.
    pub composed_confidence: f32,
}

impl Default for DensifyOptions {
    fn default() -> Self {
        Self {
            spacing_px: 8,
            reach_px: 24.0,
            rounds: 12,
            min_ncc: 0.9,
            max_shift_px: 3.0,
            max_forward_backward_px: 0.3,
            neighbours: 10,
            min_seeds: 20,
            compose_unmatched_pairs: false,
            composed_confidence: 0.5,
        }
    }
}

/// Dense matches for the pairs `pairs` (`(a, b)` with `a < b`; `view_a`/`view_b` index
/// `images` and `masks`), grown from `seeds` (see the module docs). Pairs with fewer than
/// `min_seeds` direct seeds are seeded instead by composing the dense matches of two pairs
/// through a third view ([`compose_through`]): views 90° apart on a ring share few SIFT matches
/// but each shares many with the view between them. The seeds themselves are not returned
/// (composed seeds are: they are matches of their pair); grid points closer than half a spacing
/// to a seed's `a` end are skipped. `window` gives the Lucas–Kanade window and blur.
/// Deterministic: the result does not depend on the number of threads.
pub fn densify_matches(
    images: &[&Image],
    masks: &[Option<&Image>],
    seeds: &[Match],
    pairs: &[(usize, usize)],
    window: &AffineRefineOptions,
    options: &DensifyOptions,
) -> Vec<Match> {
    let planes: Vec<Plane> = images
        .par_iter()
        .map(|im| Plane::new(im, window.blur_sigma))
        .collect();
    let lk = Window::new(window.half_window);
    let grow_pair = |va: usize, vb: usize, pair_seeds: &[Match]| -> Vec<Match> {
        let ctx = PairContext {
            a: &planes[va],
            b: &planes[vb],
            mask_a: masks.get(va).copied().flatten(),
            mask_b: masks.get(vb).copied().flatten(),
            window: &lk,
            refine: window,
            options,
        };
        let margin = window.half_window as f64 + 1.0;
        ctx.grow(pair_seeds, margin)
            .into_iter()
            .map(|(a, b, ncc, covariance)| Match {
                b_covariance: Some(covariance.map(|c| c as f32)),
                ..pair_match((va, vb), a, b, ncc.clamp(0.0, 1.0) as f32)
            })
            .collect()
    };
    let of_pair = |ms: &[Match], va: usize, vb: usize| -> Vec<Match> {
        ms.iter()
            .filter(|m| m.view_a == va && m.view_b == vb)
            .copied()
            .collect()
    };
    // Pass 1: every pair with enough direct seeds to fit an affine start.
    let mut dense: Vec<Match> = Vec::new();
    for &(va, vb) in pairs {
        let direct = of_pair(seeds, va, vb);
        if direct.len() >= 3 {
            dense.extend(grow_pair(va, vb, &direct));
        }
    }
    let unmatched = (0..images.len())
        .flat_map(|a| (a + 1..images.len()).map(move |b| (a, b)))
        .filter(|p| options.compose_unmatched_pairs && !pairs.contains(p));
    let weak: Vec<(usize, usize)> = pairs
        .iter()
        .copied()
        .filter(|&(va, vb)| {
            of_pair(seeds, va, vb).len() + of_pair(&dense, va, vb).len() < options.min_seeds
        })
        .chain(unmatched)
        .collect();
    // Pass 2: the others, seeded through a third view.
    let first_pass: Vec<Match> = seeds.iter().chain(&dense).copied().collect();
    for (va, vb) in weak {
        let mut composed = Vec::new();
        for via in (0..images.len()).filter(|&v| v != va && v != vb) {
            let first = oriented(&first_pass, va, via);
            let second = oriented(&first_pass, via, vb);
            if first.len() >= options.min_seeds && second.len() >= options.min_seeds {
                composed.extend(compose_through(&first, &second, options));
            }
        }
        let composed: Vec<Match> = composed
            .into_iter()
            .map(|(a, b)| pair_match((va, vb), a, b, options.composed_confidence))
            .collect();
        if composed.len() < options.min_seeds {
            continue;
        }
        let direct = of_pair(&first_pass, va, vb);
        let pair_seeds: Vec<Match> = direct.iter().chain(&composed).copied().collect();
        let grown = grow_pair(va, vb, &pair_seeds);
        dense.extend(composed);
        dense.extend(grown);
    }
    dense
}

/// A match of the pair `views` from its two ends.
fn pair_match(views: (usize, usize), a: Vector2<f64>, b: Vector2<f64>, confidence: f32) -> Match {
    Match {
        view_a: views.0,
        view_b: views.1,
        a: [a.x as f32, a.y as f32],
        b: [b.x as f32, b.y as f32],
        confidence,
        b_covariance: None,
    }
}

/// The (at most) `k` correspondences of `ends` whose first end lies nearest `at`, among those
/// within squared distance `max_d2`; ties go to the earlier index, so the choice is
/// deterministic.
fn nearest_ends(
    ends: &[(Vector2<f64>, Vector2<f64>)],
    at: Vector2<f64>,
    k: usize,
    max_d2: f64,
) -> Vec<(Vector2<f64>, Vector2<f64>)> {
    let mut near: Vec<(f64, usize)> = ends
        .iter()
        .enumerate()
        .map(|(i, (a, _))| ((a - at).norm_squared(), i))
        .filter(|(d, _)| *d <= max_d2)
        .collect();
    if near.len() > k {
        near.select_nth_unstable_by(k - 1, |x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
        near.truncate(k);
    }
    near.iter().map(|&(_, i)| ends[i]).collect()
}

/// The matches between views `from` and `to` as `(point in from, point in to)`, whichever way
/// round they are stored.
fn oriented(matches: &[Match], from: usize, to: usize) -> Vec<(Vector2<f64>, Vector2<f64>)> {
    matches
        .iter()
        .filter_map(|m| {
            if m.view_a == from && m.view_b == to {
                Some((end_a(m), end_b(m)))
            } else if m.view_a == to && m.view_b == from {
                Some((end_b(m), end_a(m)))
            } else {
                None
            }
        })
        .collect()
}

/// Composes correspondences `x → y` (`first`) with `y → z` (`second`): each `y` of `first` that
/// has at least `neighbours` points of `second` within `reach_px` is carried to `z` by the
/// affine map fitted to them (`refine::local_affine`). Returns `(x, z)` pairs.
pub fn compose_through(
    first: &[(Vector2<f64>, Vector2<f64>)],
    second: &[(Vector2<f64>, Vector2<f64>)],
    options: &DensifyOptions,
) -> Vec<(Vector2<f64>, Vector2<f64>)> {
    let k = options.neighbours.max(3);
    let reach2 = options.reach_px * options.reach_px;
    first
        .par_iter()
        .filter_map(|(x, y)| {
            let ends = nearest_ends(second, *y, k, reach2);
            if ends.len() < k {
                return None;
            }
            let (z, _) = local_affine(*y, &ends)?;
            Some((*x, z))
        })
        .collect()
}

/// What one pair of views needs while growing.
struct PairContext<'a> {
    a: &'a Plane,
    b: &'a Plane,
    mask_a: Option<&'a Image>,
    mask_b: Option<&'a Image>,
    window: &'a Window,
    /// The Lucas–Kanade settings: iterations, warp model and bend limit.
    refine: &'a AffineRefineOptions,
    options: &'a DensifyOptions,
}

/// A grown match: its two ends, the NCC of its windows and the covariance of `b`.
type Grown = (Vector2<f64>, Vector2<f64>, f64, [f64; 3]);

impl PairContext<'_> {
    /// Region growing from `seeds`; the accepted grid matches `(a, b, ncc)`.
    fn grow(&self, seeds: &[Match], margin: f64) -> Vec<Grown> {
        let o = self.options;
        let mut known: Vec<(Vector2<f64>, Vector2<f64>)> =
            seeds.iter().map(|m| (end_a(m), end_b(m))).collect();
        let half = o.spacing_px as f64 / 2.0;
        let mut open: Vec<Vector2<f64>> = self
            .grid(margin)
            .into_iter()
            .filter(|p| known.iter().all(|(a, _)| (a - p).norm() >= half))
            .collect();
        let mut accepted = Vec::new();
        let reach2 = o.reach_px * o.reach_px;
        for _ in 0..o.rounds {
            let (ready, waiting): (Vec<Vector2<f64>>, Vec<Vector2<f64>>) = open
                .iter()
                .partition(|p| known.iter().any(|(a, _)| (a - *p).norm_squared() <= reach2));
            if ready.is_empty() {
                break;
            }
            open = waiting;
            let found: Vec<Grown> = ready
                .par_iter()
                .filter_map(|p| self.try_point(*p, &known))
                .collect();
            if found.is_empty() {
                break;
            }
            known.extend(found.iter().map(|(a, b, _, _)| (*a, *b)));
            accepted.extend(found);
        }
        accepted
    }

    /// Grid points of view `a` (pixel centres) at least `margin` inside the image and inside its
    /// mask.
    fn grid(&self, margin: f64) -> Vec<Vector2<f64>> {
        let s = self.options.spacing_px.max(1);
        let (w, h) = (self.a.width, self.a.height);
        let mut pts = Vec::new();
        for y in (s / 2..h).step_by(s) {
            for x in (s / 2..w).step_by(s) {
                let p = Vector2::new(x as f64 + 0.5, y as f64 + 0.5);
                let inside = p.x >= margin
                    && p.y >= margin
                    && p.x <= w as f64 - margin
                    && p.y <= h as f64 - margin;
                if inside && mask_admits(self.mask_a, p, 0.5) {
                    pts.push(p);
                }
            }
        }
        pts
    }

    /// Forward and backward affine Lucas–Kanade from the local affine prediction at `p`.
    fn try_point(&self, p: Vector2<f64>, known: &[(Vector2<f64>, Vector2<f64>)]) -> Option<Grown> {
        let o = self.options;
        let ends = nearest_ends(known, p, o.neighbours.max(3), f64::INFINITY);
        let (predicted, affine) = local_affine(p, &ends)?;
        let fwd = refine_one(
            self.a,
            self.b,
            p,
            predicted,
            affine,
            self.window,
            self.refine.max_iterations,
            self.refine.warp,
        )?;
        if fwd.ncc < o.min_ncc
            || (fwd.b - predicted).norm() > o.max_shift_px
            || !self.refine.bend_allowed(fwd.bend_px)
            || !mask_admits(self.mask_b, fwd.b, 0.5)
        {
            return None;
        }
        let back = refine_one(
            self.b,
            self.a,
            fwd.b,
            p,
            fwd.warp.try_inverse()?,
            self.window,
            self.refine.max_iterations,
            self.refine.warp,
        )?;
        ((back.b - p).norm() <= o.max_forward_backward_px).then_some((
            p,
            fwd.b,
            fwd.ncc,
            fwd.b_covariance,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::refine::tests::affine_pair;
    use nalgebra::Matrix2;

    fn exact_match(
        a: Vector2<f64>,
        m: &Matrix2<f64>,
        o: &Vector2<f64>,
        views: (usize, usize),
    ) -> Match {
        pair_match(views, a, m * a + o, 1.0)
    }

    /// Four seeds around the centre of a 160 × 120 image.
    fn seeds(m: &Matrix2<f64>, o: &Vector2<f64>, views: (usize, usize)) -> Vec<Match> {
        [(70.0, 50.0), (90.0, 52.0), (75.0, 68.0), (88.0, 66.0)]
            .iter()
            .map(|&(x, y)| exact_match(Vector2::new(x, y), m, o, views))
            .collect()
    }

    fn error(m: &Match, warp: &Matrix2<f64>, o: &Vector2<f64>) -> f64 {
        (end_b(m) - (warp * end_a(m) + o)).norm()
    }

    /// Dense matches between two views, grown from the four exact seeds, default options.
    fn densify_two(a: &Image, b: &Image, warp: &Matrix2<f64>, o: &Vector2<f64>) -> Vec<Match> {
        densify_matches(
            &[a, b],
            &[None, None],
            &seeds(warp, o, (0, 1)),
            &[(0, 1)],
            &AffineRefineOptions::default(),
            &DensifyOptions::default(),
        )
    }

    #[test]
    fn grows_from_four_seeds_over_the_image_along_the_true_warp() {
        let (warp, o) = (
            Matrix2::new(1.04, 0.09, -0.07, 0.95),
            Vector2::new(3.0, -2.5),
        );
        let (a, b) = affine_pair(warp, o);
        let dense = densify_two(&a, &b, &warp, &o);
        // The grid (spacing 8, 11 px margins) has 17 × 12 points; a few map outside image b.
        assert!(dense.len() >= 150, "{} matches", dense.len());
        let worst = dense
            .iter()
            .map(|m| error(m, &warp, &o))
            .fold(0.0, f64::max);
        assert!(worst < 0.05, "worst error {worst} px");
        assert!(dense.iter().all(|m| m.confidence >= 0.9));
    }

    #[test]
    fn the_checks_reject_where_the_second_view_shows_something_else() {
        let (warp, o) = (Matrix2::identity(), Vector2::new(2.0, 1.0));
        let (a, mut b) = affine_pair(warp, o);
        // Right of x = 110, view b shows an unrelated texture (another map of the same waves).
        let (_, other) = affine_pair(Matrix2::new(0.0, 1.3, -1.3, 0.0), Vector2::new(40.0, 90.0));
        for y in 0..b.height {
            for x in 110..b.width {
                b.set(x, y, 0, other.get(x, y, 0));
            }
        }
        let dense = densify_two(&a, &b, &warp, &o);
        assert!(dense.len() >= 80, "{} matches", dense.len());
        // A window (half-size 10) wholly inside the foreign part could only match by chance;
        // none is accepted, and every accepted match is right.
        assert!(
            dense.iter().all(|m| m.b[0] < 110.0 + 10.0),
            "a match in the foreign part"
        );
        // Windows wholly on the shared texture are exact; those straddling the edge pass the
        // checks with a small bias (measured 0.21 px).
        let (clean, straddling): (Vec<&Match>, Vec<&Match>) =
            dense.iter().partition(|m| m.b[0] + 10.0 < 110.0);
        let worst = |ms: &[&Match]| ms.iter().map(|m| error(m, &warp, &o)).fold(0.0, f64::max);
        assert!(worst(&clean) < 0.05, "worst error {} px", worst(&clean));
        assert!(
            worst(&straddling) < 0.5,
            "worst error {} px",
            worst(&straddling)
        );
    }

    #[test]
    fn composition_chains_two_affine_maps() {
        let (m1, o1) = (Matrix2::new(1.1, 0.2, -0.1, 0.9), Vector2::new(5.0, -3.0));
        let (m2, o2) = (Matrix2::new(0.8, -0.3, 0.25, 1.2), Vector2::new(-7.0, 11.0));
        let grid = |n: usize, step: f64| -> Vec<Vector2<f64>> {
            (0..n)
                .flat_map(|i| (0..n).map(move |j| Vector2::new(i as f64 * step, j as f64 * step)))
                .collect()
        };
        let mut first: Vec<_> = grid(6, 10.0)
            .into_iter()
            .map(|x| (x, m1 * x + o1))
            .collect();
        // A point whose middle end has no neighbours in `second`: dropped.
        first.push((Vector2::new(500.0, 500.0), Vector2::new(900.0, 900.0)));
        let second: Vec<_> = grid(12, 6.0)
            .into_iter()
            .map(|y| (y, m2 * y + o2))
            .collect();
        let opts = DensifyOptions::default();
        let composed = compose_through(&first, &second, &opts);
        assert_eq!(composed.len(), 36);
        for (x, z) in composed {
            let truth = m2 * (m1 * x + o1) + o2;
            assert!((z - truth).norm() < 1e-9, "{z} vs {truth}");
        }
    }

    #[test]
    fn pairs_without_seeds_are_seeded_through_a_third_view() {
        // Views 0 → 1 → 2 by two affine maps; seeds only on (0, 1) and (1, 2).
        let (m1, o1) = (
            Matrix2::new(1.03, 0.06, -0.05, 0.97),
            Vector2::new(2.0, -1.5),
        );
        let (m2, o2) = (
            Matrix2::new(0.98, -0.07, 0.04, 1.02),
            Vector2::new(-1.0, 2.5),
        );
        let (m02, o02) = (m2 * m1, m2 * o1 + o2);
        let (a, b) = affine_pair(m1, o1);
        // `affine_pair` draws its second image from the texture with gain 0.8 and bias 0.1;
        // image 2 is drawn the same way through the composed map.
        let (_, c) = affine_pair(m02, o02);
        let mut seed_matches = seeds(&m1, &o1, (0, 1));
        seed_matches.extend(seeds(&m2, &o2, (1, 2)));
        let of_0_2 = |pairs: &[(usize, usize)], options: &DensifyOptions| -> Vec<Match> {
            densify_matches(
                &[&a, &b, &c],
                &[None, None, None],
                &seed_matches,
                pairs,
                &AffineRefineOptions::default(),
                options,
            )
            .into_iter()
            .filter(|m| (m.view_a, m.view_b) == (0, 2))
            .collect()
        };
        let check = |through: &[Match]| {
            assert!(through.len() >= 150, "{} matches of (0, 2)", through.len());
            let worst = through
                .iter()
                .map(|m| error(m, &m02, &o02))
                .fold(0.0, f64::max);
            assert!(worst < 0.05, "worst error {worst} px");
            assert!(
                through
                    .iter()
                    .any(|m| m.confidence == DensifyOptions::default().composed_confidence)
            );
        };
        check(&of_0_2(
            &[(0, 1), (0, 2), (1, 2)],
            &DensifyOptions::default(),
        ));
        // A pair the matcher was not asked for gets matches only when asked to compose them.
        let asked = [(0, 1), (1, 2)];
        assert!(of_0_2(&asked, &DensifyOptions::default()).is_empty());
        let compose_all = DensifyOptions {
            compose_unmatched_pairs: true,
            ..Default::default()
        };
        check(&of_0_2(&asked, &compose_all));
    }
}
