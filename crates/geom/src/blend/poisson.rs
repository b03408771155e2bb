//! Poisson image blending: occlusion-aware (the fusion paper §4, Eq. 3) and standard (Pérez et al.
//! 2003).
//!
//! Discretisation (Pérez et al. Eq. 7): for every unknown pixel `p` and each 4-neighbour `q`
//! inside the image that is unknown or has a fixed (Dirichlet) value,
//! `|N_p| f_p − Σ_{q unknown} f_q = Σ_{q fixed} f*_q + Σ_q v_pq`, with `v_pq` the guidance
//! difference along the edge `p → q`. Neighbours outside the image, or with no value (covered
//! by neither mask), are left out (a natural, zero-flux boundary). A connected region of
//! unknowns that touches no fixed pixel would only be determined up to a constant; its first
//! pixel (row-major) is then fixed to the guidance images' weighted value, which the module
//! reports in [`PoissonStats::pinned`].

use fewview_scene::Image;

use super::inputs::{Weights, check_images, check_mask};
use super::solver::{GridOperator, SolveStats, Solver, solve};
use crate::error::Result;

/// Options of the Poisson blends.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoissonOptions {
    pub solver: Solver,
    /// Relative residual `‖b − Ax‖/‖b‖` at which CG stops.
    pub tolerance: f64,
}

impl Default for PoissonOptions {
    fn default() -> Self {
        Self {
            solver: Solver::MultigridCg,
            tolerance: 1e-7,
        }
    }
}

/// Figures of a Poisson blend.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PoissonStats {
    pub solve: SolveStats,
    /// Regions without any fixed neighbour whose first pixel was fixed.
    pub pinned: usize,
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Cell {
    Unknown,
    Fixed,
    Outside,
}

/// The solution of a masked Poisson problem: per channel, every pixel (unknown pixels solved,
/// fixed pixels their value, outside 0), in f64.
pub(crate) struct PoissonSolution {
    pub planes: Vec<Vec<f64>>,
    pub stats: PoissonStats,
}

/// Builds and solves a masked Poisson problem from per-pixel roles, fixed values and guidance.
fn solve_masked<FV, GV>(
    w: usize,
    h: usize,
    channels: usize,
    mut cells: Vec<Cell>,
    fixed_value: FV,
    guidance: GV,
    options: &PoissonOptions,
) -> Result<PoissonSolution>
where
    FV: Fn(usize, usize) -> f64,
    GV: Fn(usize, usize, usize) -> f64,
{
    let neighbours = |p: usize| {
        let (i, j) = (p % w, p / w);
        [
            (i > 0).then(|| p - 1),
            (i + 1 < w).then(|| p + 1),
            (j > 0).then(|| p - w),
            (j + 1 < h).then(|| p + w),
        ]
    };
    // Pin regions of unknowns that touch no fixed pixel.
    let mut seen = vec![false; w * h];
    let mut pinned = 0;
    let mut stack = Vec::new();
    for start in 0..w * h {
        if cells[start] != Cell::Unknown || seen[start] {
            continue;
        }
        let mut touches_fixed = false;
        seen[start] = true;
        stack.push(start);
        while let Some(p) = stack.pop() {
            for q in neighbours(p).into_iter().flatten() {
                match cells[q] {
                    Cell::Fixed => touches_fixed = true,
                    Cell::Unknown if !seen[q] => {
                        seen[q] = true;
                        stack.push(q);
                    }
                    _ => {}
                }
            }
        }
        if !touches_fixed {
            cells[start] = Cell::Fixed;
            pinned += 1;
        }
    }
    let active: Vec<bool> = cells.iter().map(|c| *c == Cell::Unknown).collect();
    let mut diag = vec![0.0; w * h];
    let mut wx = vec![0.0; w * h];
    let mut wy = vec![0.0; w * h];
    let mut rhs = vec![vec![0.0; w * h]; channels];
    for p in 0..w * h {
        if !active[p] {
            continue;
        }
        for q in neighbours(p).into_iter().flatten() {
            if cells[q] == Cell::Outside {
                continue;
            }
            diag[p] += 1.0;
            for (c, b) in rhs.iter_mut().enumerate() {
                b[p] += guidance(p, q, c);
                if cells[q] == Cell::Fixed {
                    b[p] += fixed_value(q, c);
                }
            }
        }
        if p % w + 1 < w && active[p + 1] {
            wx[p] = 1.0;
        }
        if p / w + 1 < h && active[p + w] {
            wy[p] = 1.0;
        }
    }
    let op = GridOperator {
        w,
        h,
        active,
        diag,
        wx,
        wy,
    };
    let (mut planes, solve_stats) = if op.active.iter().any(|a| *a) {
        solve(&op, &rhs, options.solver, options.tolerance)?
    } else {
        (vec![vec![0.0; w * h]; channels], SolveStats::default())
    };
    for (c, plane) in planes.iter_mut().enumerate() {
        for p in 0..w * h {
            if cells[p] == Cell::Fixed {
                plane[p] = fixed_value(p, c);
            }
        }
    }
    Ok(PoissonSolution {
        planes,
        stats: PoissonStats {
            solve: solve_stats,
            pinned,
        },
    })
}

fn to_image(w: usize, h: usize, planes: &[Vec<f64>]) -> Image {
    let c = planes.len();
    let mut img = Image::new(w, h, c);
    for (k, plane) in planes.iter().enumerate() {
        for p in 0..w * h {
            img.data[p * c + k] = plane[p] as f32;
        }
    }
    img
}

/// Occlusion-aware Poisson blending (the fusion paper Eq. 3) in f64 planes (see
/// [`occlusion_aware_poisson_with`]).
pub(crate) fn occlusion_aware_planes(
    f: &Image,
    g: &Image,
    mask_f: &[bool],
    mask_g: &[bool],
    weights: Weights,
    options: &PoissonOptions,
) -> Result<PoissonSolution> {
    let (w, h, ch) = check_images(f, g)?;
    check_mask(mask_f, w, h, "mask of f")?;
    check_mask(mask_g, w, h, "mask of g")?;
    weights.check(w, h)?;
    let cells: Vec<Cell> = mask_f
        .iter()
        .zip(mask_g)
        .map(|(&a, &b)| match (a, b) {
            (true, true) => Cell::Unknown,
            (true, false) | (false, true) => Cell::Fixed,
            (false, false) => Cell::Outside,
        })
        .collect();
    let val = |img: &Image, p: usize, c: usize| img.data[p * ch + c] as f64;
    let fixed_value = |p: usize, c: usize| match (mask_f[p], mask_g[p]) {
        (true, false) => val(f, p, c),
        (false, true) => val(g, p, c),
        // A pinned overlap pixel: the weighted value of the two images.
        _ => {
            let wf = weights.at(p);
            wf * val(f, p, c) + (1.0 - wf) * val(g, p, c)
        }
    };
    let guidance = |p: usize, q: usize, c: usize| {
        let df = val(f, p, c) - val(f, q, c);
        let dg = val(g, p, c) - val(g, q, c);
        match (mask_f[q], mask_g[q]) {
            (true, true) => {
                let wf = 0.5 * (weights.at(p) + weights.at(q));
                wf * df + (1.0 - wf) * dg
            }
            (true, false) => df,
            (false, true) => dg,
            (false, false) => 0.0,
        }
    };
    solve_masked(w, h, ch, cells, fixed_value, guidance, options)
}

/// Occlusion-aware Poisson blending of `f` and `g` (the fusion paper §4, Eq. 3):
/// pixels valid in one mask only keep that image's value (Dirichlet condition), pixels valid
/// in both are solved for with the guidance field `w_f ∇f + (1 − w_f) ∇g`, pixels in neither
/// are 0.
///
/// Along an edge from the overlap to a pixel valid in one image only, the other image's
/// gradient is undefined, so the guidance there is that image's gradient alone. `weights`
/// gives `w_f` (per pixel, averaged over the two ends of an edge).
pub fn occlusion_aware_poisson(
    f: &Image,
    g: &Image,
    mask_f: &[bool],
    mask_g: &[bool],
    weights: Weights,
) -> Result<Image> {
    Ok(occlusion_aware_poisson_with(f, g, mask_f, mask_g, weights, &PoissonOptions::default())?.0)
}

/// [`occlusion_aware_poisson`] with options, returning the solver's figures too.
pub fn occlusion_aware_poisson_with(
    f: &Image,
    g: &Image,
    mask_f: &[bool],
    mask_g: &[bool],
    weights: Weights,
    options: &PoissonOptions,
) -> Result<(Image, PoissonStats)> {
    let s = occlusion_aware_planes(f, g, mask_f, mask_g, weights, options)?;
    Ok((to_image(f.width, f.height, &s.planes), s.stats))
}

/// Standard Poisson blending (Pérez et al. 2003, "seamless cloning"): inside `mask` the result
/// follows the gradients of `source` (or, with `mixed`, whichever of the two images' differences
/// is larger along each edge), outside it equals `target`.
pub fn poisson_blend(
    target: &Image,
    source: &Image,
    mask: &[bool],
    mixed: bool,
    options: &PoissonOptions,
) -> Result<(Image, PoissonStats)> {
    let (w, h, ch) = check_images(target, source)?;
    check_mask(mask, w, h, "mask")?;
    let cells = mask
        .iter()
        .map(|&m| if m { Cell::Unknown } else { Cell::Fixed })
        .collect();
    let val = |img: &Image, p: usize, c: usize| img.data[p * ch + c] as f64;
    let fixed_value = |p: usize, c: usize| {
        if mask[p] {
            // Pinned (the mask covers a whole region without boundary): take the source.
            val(source, p, c)
        } else {
            val(target, p, c)
        }
    };
    let guidance = |p: usize, q: usize, c: usize| {
        let ds = val(source, p, c) - val(source, q, c);
        if mixed {
            let dt = val(target, p, c) - val(target, q, c);
            if dt.abs() > ds.abs() { dt } else { ds }
        } else {
            ds
        }
    };
    let s = solve_masked(w, h, ch, cells, fixed_value, guidance, options)?;
    Ok((to_image(w, h, &s.planes), s.stats))
}

/// Errors for an empty overlap are not raised: with no pixel in both masks the result is the
/// two images pasted side by side. This helper says whether that is the case.
pub fn overlap_size(mask_f: &[bool], mask_g: &[bool]) -> usize {
    mask_f
        .iter()
        .zip(mask_g)
        .filter(|(a, b)| **a && **b)
        .count()
}
