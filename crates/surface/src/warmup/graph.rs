//! Which matches can fix the poses: the pairs of views with enough of them, and whether those
//! pairs tie every camera to the others ([`matches_tie_the_views`]).

use nalgebra::DMatrix;

use super::options::{Connectivity, WarmupOptions};
use crate::matching::Match;

/// The matches of the pairs of views that have at least `min_per_pair` of them, or why they
/// cannot fix the poses. Pairs below the threshold are dropped rather than vetoing the
/// warm-up: on a ring of views, opposite views share no matches while neighbours share
/// hundreds. The epipolar constraint fixes the direction of each pair's baseline, not its
/// length, so what remains must tie every baseline length to the others: the usable pairs must
/// make the camera centres parallel rigid ([`parallel_rigid`]; e.g. triangles, which have known
/// length ratios, chained through shared edges). A plain cycle of four or more views would
/// leave lengths free. With [`Connectivity::Connected`] it is enough that they connect all
/// views.
pub(super) fn usable_matches(
    matches: &[Match],
    n: usize,
    min_per_pair: usize,
    connectivity: Connectivity,
) -> Result<Vec<Match>, String> {
    let key = |a: usize, b: usize| a.min(b) * n + a.max(b);
    let mut per_pair = vec![0usize; n * n];
    for m in matches {
        per_pair[key(m.view_a, m.view_b)] += 1;
    }
    let usable = |a: usize, b: usize| per_pair[key(a, b)] >= min_per_pair.max(1);
    let fewest = (0..n)
        .flat_map(|a| (a + 1..n).map(move |b| (a, b)))
        .map(|(a, b)| per_pair[key(a, b)])
        .min()
        .unwrap_or(0);
    let (held, what) = match connectivity {
        _ if n == 2 => (usable(0, 1), "join the two views"),
        Connectivity::Rigid => (
            parallel_rigid(n, &usable),
            "fix all baseline lengths (triangles chained over all views, or the like)",
        ),
        Connectivity::Connected => (connects_all(n, &usable), "connect all views"),
    };
    if !held {
        return Err(format!(
            "too few matches: {fewest} for the weakest pair of views; the pairs with {min_per_pair} or more do not {what}"
        ));
    }
    Ok(matches
        .iter()
        .filter(|m| usable(m.view_a, m.view_b))
        .copied()
        .collect())
}

/// The matches the warm-up uses ([`usable_matches`]), or why there are too few of them to tie
/// the `n` views together (also when they are fewer than the unknowns, six per view).
pub(super) fn tying_matches(
    matches: &[Match],
    n: usize,
    options: &WarmupOptions,
) -> Result<Vec<Match>, String> {
    let unknowns = 6 * n;
    let usable = usable_matches(
        matches,
        n,
        options.min_matches_per_pair,
        options.connectivity,
    )?;
    if usable.len() < unknowns {
        return Err(format!(
            "too few matches: {} for {unknowns} unknowns",
            usable.len()
        ));
    }
    Ok(usable)
}

/// `Ok` when [`super::epipolar_warmup`] would find enough `matches` between `n` views to run under
/// `options`, else why not: a run can then decide to look for more matches first.
pub fn matches_tie_the_views(
    n: usize,
    matches: &[Match],
    options: &WarmupOptions,
) -> Result<(), String> {
    tying_matches(matches, n, options).map(|_| ())
}

/// Whether the graph of `edge`s reaches every one of the `n` views from view 0.
pub(super) fn connects_all(n: usize, edge: &dyn Fn(usize, usize) -> bool) -> bool {
    let mut reached = vec![false; n];
    let mut stack = vec![0];
    reached[0] = true;
    while let Some(a) = stack.pop() {
        for b in 0..n {
            if !reached[b] && edge(a.min(b), a.max(b)) && a != b {
                reached[b] = true;
                stack.push(b);
            }
        }
    }
    reached.iter().all(|&r| r)
}

/// Whether the directions of the baselines `edge(a, b)` (`a < b`) fix the `n` camera centres up
/// to a common translation and scale (parallel rigidity), even when the cameras lie in one plane
/// (a ring). Each edge asks `c_a − c_b` to be parallel to a known direction. In the plane that
/// is one linear constraint on the centres, and the graph is rigid when the constraints leave
/// only the three-dimensional family of translations and scalings: rank `2n − 3` at generic
/// directions (those of random planar centres, fixed seed; rigidity is a property of the graph
/// for almost every placement). The planar test is the strict one: out of a plane a cycle of
/// four views would already be rigid, but on a ring its directions are coplanar and its lengths
/// free. Triangles chained through shared edges are rigid; two rigid groups that share one
/// view are not (their relative scale is free) unless further baselines tie them, which is how
/// rings of views at several elevations connect.
pub(super) fn parallel_rigid(n: usize, edge: &dyn Fn(usize, usize) -> bool) -> bool {
    if n < 2 {
        return true;
    }
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut uniform = || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let centres: Vec<(f64, f64)> = (0..n).map(|_| (uniform(), uniform())).collect();
    let pairs: Vec<(usize, usize)> = (0..n)
        .flat_map(|a| (a + 1..n).map(move |b| (a, b)))
        .filter(|&(a, b)| edge(a, b))
        .collect();
    let free = 2 * n - 3;
    if pairs.len() < free {
        return false;
    }
    let mut m = DMatrix::<f64>::zeros(pairs.len(), 2 * n);
    for (row, &(a, b)) in pairs.iter().enumerate() {
        let (dx, dy) = (centres[a].0 - centres[b].0, centres[a].1 - centres[b].1);
        let len = dx.hypot(dy);
        // The unit normal of the baseline: its component of c_a − c_b must vanish.
        let (nx, ny) = (-dy / len, dx / len);
        m[(row, 2 * a)] = nx;
        m[(row, 2 * a + 1)] = ny;
        m[(row, 2 * b)] = -nx;
        m[(row, 2 * b + 1)] = -ny;
    }
    let singular = m.singular_values();
    let largest = singular.max();
    singular.iter().filter(|&&s| s > 1e-9 * largest).count() == free
}
