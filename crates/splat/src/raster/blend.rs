//! Per-tile front-to-back alpha blending (3DGS Eq. 3) and its exact backward.
//!
//! For pixel centre `x` and the tile's splats in depth order, with `d = x − μ`,
//! `power = −½ dᵀ Σ'⁻¹ d` and `α = min(0.99, o·e^power)`: splats with `power > 0` or
//! `α < 1/255` are skipped; blending stops before the transmittance `T` would fall below 1e-4
//! (that splat is not blended); `C = Σ cᵢ αᵢ Tᵢ + T·bg`, `D = Σ zᵢ αᵢ Tᵢ`, `A = 1 − T`.
//!
//! The loops run splat-outer, pixel-inner over whole 16-pixel tile rows so they vectorise; a
//! splat only visits the tile rows its `α ≥ 1/255` ellipse can reach.

use super::project::{Splat, SplatGrad};
use super::{ALPHA_MAX, ALPHA_MIN, T_MIN, TILE};
use crate::real::Real;

pub const TILE_PIXELS: usize = TILE * TILE;

/// Per-pixel blending state of one tile, tile-major (row by row).
#[derive(Clone, Debug)]
pub struct TileState<F> {
    pub color: [[F; TILE_PIXELS]; 3],
    pub depth: [F; TILE_PIXELS],
    /// Transmittance after the last blended splat.
    pub transmittance: [F; TILE_PIXELS],
    /// Number of list entries processed before the pixel stopped (the backward pass visits
    /// entries `0..last`).
    pub last: [u32; TILE_PIXELS],
}

impl<F: Real> Default for TileState<F> {
    fn default() -> Self {
        Self {
            color: [[F::zero(); TILE_PIXELS]; 3],
            depth: [F::zero(); TILE_PIXELS],
            transmittance: [F::one(); TILE_PIXELS],
            last: [0; TILE_PIXELS],
        }
    }
}

/// Where a tile sits in the image and how much of it is inside.
#[derive(Clone, Copy, Debug)]
pub struct TileGeometry {
    pub x0: usize,
    pub y0: usize,
    /// Pixels of the tile inside the image (the last tile row/column may be partial).
    pub width: usize,
    pub height: usize,
}

/// Row range of the tile a splat can reach.
#[inline(always)]
fn tile_rows<F>(s: &Splat<F>, geo: &TileGeometry) -> (usize, usize) {
    let r0 = (s.rows[0] as usize).max(geo.y0) - geo.y0;
    let r1 = (s.rows[1] as usize)
        .min(geo.y0 + geo.height)
        .saturating_sub(geo.y0);
    (r0, r1.max(r0))
}

/// `(power, e^power, α)` of one splat at one pixel offset.
#[inline(always)]
fn splat_alpha<F: Real>(s: &Splat<F>, dx: F, dy: F) -> (F, F, F) {
    let half = F::c(0.5);
    let power = -half * (s.conic[0] * dx * dx + s.conic[2] * dy * dy) - s.conic[1] * dx * dy;
    let g = power.exp_blend();
    let alpha = (s.opacity * g).min(F::c(ALPHA_MAX));
    (power, g, alpha)
}

/// Blends `list` (indices into `splats`, front to back) into `state`. Returns the number of
/// splat–pixel pairs evaluated.
#[inline(always)]
pub fn forward_tile<F: Real>(
    geo: &TileGeometry,
    list: &[u32],
    splats: &[Splat<F>],
    state: &mut TileState<F>,
) -> u64 {
    let mut alive = [false; TILE_PIXELS];
    let mut n_alive = 0usize;
    for r in 0..geo.height {
        for c in 0..geo.width {
            alive[r * TILE + c] = true;
            n_alive += 1;
        }
    }
    let (amin, tmin) = (F::c(ALPHA_MIN), F::c(T_MIN));
    let half = F::c(0.5);
    let mut pairs = 0u64;
    for (j, &si) in list.iter().enumerate() {
        let s = &splats[si as usize];
        let (r0, r1) = tile_rows(s, geo);
        let rank = j as u32 + 1;
        let mut stopped = 0usize;
        for r in r0..r1 {
            let dy = F::c((geo.y0 + r) as f64) + half - s.mean[1];
            let base = r * TILE;
            let row = base..base + TILE;
            let t = &mut state.transmittance[row.clone()];
            let [c0, c1, c2] = &mut state.color;
            let cr = &mut c0[row.clone()];
            let cg = &mut c1[row.clone()];
            let cb = &mut c2[row.clone()];
            let dd = &mut state.depth[row.clone()];
            let last = &mut state.last[row.clone()];
            let al = &mut alive[row];
            for c in 0..TILE {
                let dx = F::c((geo.x0 + c) as f64) + half - s.mean[0];
                let (power, _, alpha) = splat_alpha(s, dx, dy);
                let valid = al[c] && power <= F::zero() && alpha >= amin;
                let test_t = t[c] * (F::one() - alpha);
                let stop = valid && test_t < tmin;
                let contrib = valid && !stop;
                let w = if contrib { alpha * t[c] } else { F::zero() };
                cr[c] = cr[c] + w * s.color[0];
                cg[c] = cg[c] + w * s.color[1];
                cb[c] = cb[c] + w * s.color[2];
                dd[c] = dd[c] + w * s.depth;
                t[c] = if contrib { test_t } else { t[c] };
                last[c] = if contrib { rank } else { last[c] };
                al[c] = al[c] && !stop;
                stopped += stop as usize;
            }
        }
        pairs += ((r1 - r0) * TILE) as u64;
        n_alive -= stopped;
        if n_alive == 0 {
            break;
        }
    }
    pairs
}

/// Upstream gradient of one tile's pixels (tile-major): colour, depth, alpha.
#[derive(Clone, Debug)]
pub struct TileGrad<F> {
    pub color: [[F; TILE_PIXELS]; 3],
    pub depth: [F; TILE_PIXELS],
    pub alpha: [F; TILE_PIXELS],
}

impl<F: Real> Default for TileGrad<F> {
    fn default() -> Self {
        Self {
            color: [[F::zero(); TILE_PIXELS]; 3],
            depth: [F::zero(); TILE_PIXELS],
            alpha: [F::zero(); TILE_PIXELS],
        }
    }
}

/// Backward of [`forward_tile`]: writes `SplatGrad::LEN` values per list entry into `out`
/// (entry `j` at `out[j * LEN..]`), the gradient of the loss with respect to that splat's
/// blending inputs summed over this tile's pixels.
#[inline(always)]
pub fn backward_tile<F: Real>(
    geo: &TileGeometry,
    list: &[u32],
    splats: &[Splat<F>],
    state: &TileState<F>,
    background: [F; 3],
    grad: &TileGrad<F>,
    out: &mut [F],
) {
    const L: usize = SplatGrad::<f32>::LEN;
    let zero = F::zero();
    let one = F::one();
    let half = F::c(0.5);
    let (amin, amax) = (F::c(ALPHA_MIN), F::c(ALPHA_MAX));
    let mut t = state.transmittance;
    let mut acc = [
        [background[0]; TILE_PIXELS],
        [background[1]; TILE_PIXELS],
        [background[2]; TILE_PIXELS],
    ];
    let mut acc_d = [zero; TILE_PIXELS];
    let mut acc_a = [zero; TILE_PIXELS];
    let max_last = state.last.iter().copied().max().unwrap_or(0) as usize;
    out.iter_mut().for_each(|v| *v = zero);
    for j in (0..max_last.min(list.len())).rev() {
        let s = &splats[list[j] as usize];
        let (r0, r1) = tile_rows(s, geo);
        let rank = j as u32;
        let mut lane = [[zero; TILE]; L];
        for r in r0..r1 {
            let dy = F::c((geo.y0 + r) as f64) + half - s.mean[1];
            let base = r * TILE;
            for c in 0..TILE {
                let p = base + c;
                let dx = F::c((geo.x0 + c) as f64) + half - s.mean[0];
                let (power, g, alpha) = splat_alpha(s, dx, dy);
                let valid = rank < state.last[p] && power <= zero && alpha >= amin;
                let one_minus = one - alpha;
                let t_j = t[p] / one_minus;
                let w = alpha * t_j;
                let (gr, gg, gb) = (grad.color[0][p], grad.color[1][p], grad.color[2][p]);
                let (gd, ga) = (grad.depth[p], grad.alpha[p]);
                let dl_dalpha = t_j
                    * (gr * (s.color[0] - acc[0][p])
                        + gg * (s.color[1] - acc[1][p])
                        + gb * (s.color[2] - acc[2][p])
                        + gd * (s.depth - acc_d[p])
                        + ga * (one - acc_a[p]));
                let sel = |v: F| if valid { v } else { zero };
                lane[6][c] = lane[6][c] + sel(w * gr);
                lane[7][c] = lane[7][c] + sel(w * gg);
                lane[8][c] = lane[8][c] + sel(w * gb);
                lane[9][c] = lane[9][c] + sel(w * gd);
                // α = o·g unless clamped at 0.99, where it no longer depends on o or the shape.
                let free = valid && s.opacity * g < amax;
                let dpow = if free { dl_dalpha * alpha } else { zero };
                lane[5][c] = lane[5][c] + if free { dl_dalpha * g } else { zero };
                lane[0][c] = lane[0][c] + dpow * (s.conic[0] * dx + s.conic[1] * dy);
                lane[1][c] = lane[1][c] + dpow * (s.conic[2] * dy + s.conic[1] * dx);
                lane[2][c] = lane[2][c] - half * dpow * dx * dx;
                lane[3][c] = lane[3][c] - dpow * dx * dy;
                lane[4][c] = lane[4][c] - half * dpow * dy * dy;
                acc[0][p] = if valid {
                    alpha * s.color[0] + one_minus * acc[0][p]
                } else {
                    acc[0][p]
                };
                acc[1][p] = if valid {
                    alpha * s.color[1] + one_minus * acc[1][p]
                } else {
                    acc[1][p]
                };
                acc[2][p] = if valid {
                    alpha * s.color[2] + one_minus * acc[2][p]
                } else {
                    acc[2][p]
                };
                acc_d[p] = if valid {
                    alpha * s.depth + one_minus * acc_d[p]
                } else {
                    acc_d[p]
                };
                acc_a[p] = if valid {
                    alpha + one_minus * acc_a[p]
                } else {
                    acc_a[p]
                };
                t[p] = if valid { t_j } else { t[p] };
            }
        }
        let dst = &mut out[j * L..(j + 1) * L];
        for (k, v) in dst.iter_mut().enumerate() {
            *v = lane[k].iter().copied().fold(zero, |a, b| a + b);
        }
    }
}
