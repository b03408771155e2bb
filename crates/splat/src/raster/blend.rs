//! Per-tile front-to-back alpha blending (3DGS Eq. 3) and its exact backward.
//!
//! For pixel centre `x` and the tile's splats in depth order, with `d = x − μ`,
//! `power = −½ dᵀ Σ'⁻¹ d` and `α = min(0.99, o·e^power)`: splats with `power > 0` or
//! `α < 1/255` are skipped; blending stops before the transmittance `T` would fall below 1e-4
//! (that splat is not blended); `C = Σ cᵢ αᵢ Tᵢ + T·bg`, `D = Σ zᵢ αᵢ Tᵢ`, `A = 1 − T`.
//!
//! The loops run splat-outer, pixel-inner over whole 16-pixel tile rows so they vectorise; a
//! splat only visits the tile rows its `α ≥ 1/255` ellipse can reach.

use super::inputs::{ALPHA_MAX, ALPHA_MIN, T_MIN, TILE};
use super::project::{Splat, SplatGrad};
use crate::real::{MulAdd, Real};

pub const TILE_PIXELS: usize = TILE * TILE;

/// A per-pixel quantity of one tile, row by row (fixed sizes, so the row loops vectorise without
/// bounds checks).
pub type TileRows<T> = [[T; TILE]; TILE];

/// Per-pixel blending state of one tile.
#[derive(Clone, Debug)]
pub struct TileState<F> {
    pub color: [TileRows<F>; 3],
    pub depth: TileRows<F>,
    /// Transmittance after the last blended splat.
    pub transmittance: TileRows<F>,
    /// Number of list entries processed before the pixel stopped (the backward pass visits
    /// entries `0..last`).
    pub last: TileRows<u32>,
}

impl<F: Real> Default for TileState<F> {
    fn default() -> Self {
        Self {
            color: [[[F::zero(); TILE]; TILE]; 3],
            depth: [[F::zero(); TILE]; TILE],
            transmittance: [[F::one(); TILE]; TILE],
            last: [[0; TILE]; TILE],
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

impl TileGeometry {
    /// Pixel-centre x coordinates of the tile's columns.
    #[inline(always)]
    fn column_centres<F: Real>(&self) -> [F; TILE] {
        std::array::from_fn(|c| F::c((self.x0 + c) as f64 + 0.5))
    }
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

/// Per-row constants of a splat's exponent: `power = dx·(h_a·dx + k1) + k0` with
/// `h_a = −a/2`, `k1 = −b·dy`, `k0 = −c·dy²/2`, i.e. `−½(a dx² + c dy²) − b dx dy`.
#[derive(Clone, Copy)]
struct RowTerms<F> {
    ha: F,
    k1: F,
    k0: F,
}

#[inline(always)]
fn row_terms<F: Real>(s: &Splat<F>, dy: F) -> RowTerms<F> {
    let half = F::c(0.5);
    RowTerms {
        ha: -half * s.conic[0],
        k1: -s.conic[1] * dy,
        k0: -half * s.conic[2] * dy * dy,
    }
}

/// `(power, e^power, α)` of one splat at horizontal offset `dx` on a row.
#[inline(always)]
fn splat_alpha<F: Real, M: MulAdd>(s: &Splat<F>, row: RowTerms<F>, dx: F) -> (F, F, F) {
    let power = M::madd(dx, M::madd(row.ha, dx, row.k1), row.k0);
    let g = power.exp_blend::<M>();
    let alpha = (s.opacity * g).min(F::c(ALPHA_MAX));
    (power, g, alpha)
}

/// Columns processed together: one AVX vector of `f32`.
pub const BLOCK: usize = 8;

/// Column blocks `[b0, b1)` of the tile a splat can reach.
#[inline(always)]
fn tile_blocks<F>(s: &Splat<F>, geo: &TileGeometry) -> (usize, usize) {
    let c0 = (s.cols[0] as usize).max(geo.x0) - geo.x0;
    let c1 = (s.cols[1] as usize)
        .min(geo.x0 + geo.width)
        .saturating_sub(geo.x0);
    if c1 <= c0 {
        return (0, 0);
    }
    (c0 / BLOCK, (c1 - 1) / BLOCK + 1)
}

/// How many list entries ahead the blending loops prefetch splats. A tile's list is a sparse,
/// scattered subset of all splats, so without it nearly every splat is a cache miss that the
/// loop waits for (measured: ~12 % of the forward kernel's time on the load of one splat).
const PREFETCH_AHEAD: usize = 8;

/// Asks the CPU to bring `value` (both cache lines it may straddle) into L1.
#[inline(always)]
fn prefetch<T>(value: &T) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let start = value as *const T as *const i8;
        // SAFETY: prefetching is a hint with no architectural effect; both addresses lie
        // within (or one line past the start of) the referenced value.
        unsafe {
            _mm_prefetch::<_MM_HINT_T0>(start);
            _mm_prefetch::<_MM_HINT_T0>(start.wrapping_add(std::mem::size_of::<T>() - 1));
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = value;
}

/// Blends `list` (indices into `splats`, front to back) into `state`. Returns the number of
/// splat–pixel pairs evaluated.
// `&` between the per-lane tests keeps them vector masks (see the loop).
#[allow(clippy::needless_bitwise_bool)]
#[inline(always)]
pub fn forward_tile<F: Real, M: MulAdd>(
    geo: &TileGeometry,
    list: &[u32],
    splats: &[Splat<F>],
    state: &mut TileState<F>,
) -> u64 {
    // 1 for pixels still blending, 0 once stopped or outside the image (a float mask keeps the
    // loop in one vector width).
    let mut alive = [[F::zero(); TILE]; TILE];
    for row in alive.iter_mut().take(geo.height) {
        for a in row.iter_mut().take(geo.width) {
            *a = F::one();
        }
    }
    let mut n_alive = geo.width * geo.height;
    // `state.last`, kept in floats while blending (see the update below).
    let mut last_rank = [[F::zero(); TILE]; TILE];
    let (amin, tmin) = (F::c(ALPHA_MIN), F::c(T_MIN));
    let zero = F::zero();
    let px = geo.column_centres::<F>();
    let mut pairs = 0u64;
    for (j, &si) in list.iter().enumerate() {
        if let Some(&ahead) = list.get(j + PREFETCH_AHEAD) {
            prefetch(&splats[ahead as usize]);
        }
        let s = &splats[si as usize];
        let (r0, r1) = tile_rows(s, geo);
        let (b0, b1) = tile_blocks(s, geo);
        let rank = F::c((j + 1) as f64);
        let mut stopped = 0u32;
        for r in r0..r1 {
            let dy = F::c((geo.y0 + r) as f64 + 0.5) - s.mean[1];
            let row = row_terms(s, dy);
            for b in b0..b1 {
                let cols = b * BLOCK..(b + 1) * BLOCK;
                let t: &mut [F; BLOCK] = (&mut state.transmittance[r][cols.clone()])
                    .try_into()
                    .unwrap();
                let [c0, c1, c2] = &mut state.color;
                let cr: &mut [F; BLOCK] = (&mut c0[r][cols.clone()]).try_into().unwrap();
                let cg: &mut [F; BLOCK] = (&mut c1[r][cols.clone()]).try_into().unwrap();
                let cb: &mut [F; BLOCK] = (&mut c2[r][cols.clone()]).try_into().unwrap();
                let dd: &mut [F; BLOCK] = (&mut state.depth[r][cols.clone()]).try_into().unwrap();
                let last: &mut [F; BLOCK] = (&mut last_rank[r][cols.clone()]).try_into().unwrap();
                let al: &mut [F; BLOCK] = (&mut alive[r][cols.clone()]).try_into().unwrap();
                let x: &[F; BLOCK] = (&px[cols]).try_into().unwrap();
                for c in 0..BLOCK {
                    let dx = x[c] - s.mean[0];
                    let (power, _, alpha) = splat_alpha::<F, M>(s, row, dx);
                    // `&`, not `&&`: with no short circuit the three tests stay vector masks
                    // instead of being turned into branches and packed booleans.
                    let valid = (al[c] > zero) & (power <= zero) & (alpha >= amin);
                    let test_t = t[c] * (F::one() - alpha);
                    let stop = valid & (test_t < tmin);
                    let contrib = valid & !stop;
                    let w = if contrib { alpha * t[c] } else { zero };
                    cr[c] = M::madd(w, s.color[0], cr[c]);
                    cg[c] = M::madd(w, s.color[1], cg[c]);
                    cb[c] = M::madd(w, s.color[2], cb[c]);
                    dd[c] = M::madd(w, s.depth, dd[c]);
                    // Both updates are written as arithmetic on every lane: as selects, LLVM
                    // turns them into masked loads and stores, which are microcoded and slow
                    // on AMD Zen (they took a fifth of the kernel's time). `t − w` is `T(1 − α)`
                    // when the splat contributes (w = αT) and `T` otherwise (w = 0).
                    // The rank is tracked in floats (exact below 2²⁴ entries) for the same
                    // reason: `last + 1·(rank − last)` is `rank`, `last + 0·(…)` is `last`.
                    t[c] = t[c] - w;
                    let on = if contrib { F::one() } else { zero };
                    last[c] = M::madd(on, rank - last[c], last[c]);
                    al[c] = if stop { zero } else { al[c] };
                    stopped += stop as u32;
                }
            }
        }
        pairs += ((r1 - r0) * (b1 - b0) * BLOCK) as u64;
        n_alive -= stopped as usize;
        if n_alive == 0 {
            break;
        }
    }
    for (dst, src) in state.last.iter_mut().zip(&last_rank) {
        for (d, s) in dst.iter_mut().zip(src) {
            *d = s.to_u32().unwrap_or(0);
        }
    }
    pairs
}

/// Upstream gradient of one tile's pixels: colour, depth, alpha.
#[derive(Clone, Debug)]
pub struct TileGrad<F> {
    pub color: [TileRows<F>; 3],
    pub depth: TileRows<F>,
    pub alpha: TileRows<F>,
}

impl<F: Real> Default for TileGrad<F> {
    fn default() -> Self {
        Self {
            color: [[[F::zero(); TILE]; TILE]; 3],
            depth: [[F::zero(); TILE]; TILE],
            alpha: [[F::zero(); TILE]; TILE],
        }
    }
}

/// Backward of [`forward_tile`]: writes `SplatGrad::LEN` values per list entry into `out`
/// (entry `j` at `out[j * LEN..]`), the gradient of the loss with respect to that splat's
/// blending inputs summed over this tile's pixels. Returns the number of splat–pixel pairs
/// evaluated.
///
/// Walks each pixel's list back to front, recovering `Tᵢ = Tᵢ₊₁ / (1 − αᵢ)` and the colour
/// behind splat `i`, `Aᵢ = αᵢ₊₁ cᵢ₊₁ + (1 − αᵢ₊₁) Aᵢ₊₁` (starting from the background), so
/// `∂C/∂αᵢ = Tᵢ (cᵢ − Aᵢ)`; depth (background 0) and alpha (colour 1, background 0) alike.
#[allow(clippy::needless_bitwise_bool)]
#[inline(always)]
pub fn backward_tile<F: Real, M: MulAdd>(
    geo: &TileGeometry,
    list: &[u32],
    splats: &[Splat<F>],
    state: &TileState<F>,
    background: [F; 3],
    grad: &TileGrad<F>,
    out: &mut [F],
) -> u64 {
    const L: usize = SplatGrad::<f32>::LEN;
    let zero = F::zero();
    let one = F::one();
    let half = F::c(0.5);
    let (amin, amax) = (F::c(ALPHA_MIN), F::c(ALPHA_MAX));
    let px = geo.column_centres::<F>();
    let mut t = state.transmittance;
    let mut acc = background.map(|b| [[b; TILE]; TILE]);
    let mut acc_d = [[zero; TILE]; TILE];
    let mut acc_a = [[zero; TILE]; TILE];
    let max_last = state.last.iter().flatten().copied().max().unwrap_or(0) as usize;
    out.iter_mut().for_each(|v| *v = zero);
    let mut pairs = 0u64;
    for j in (0..max_last.min(list.len())).rev() {
        if let Some(ahead) = j.checked_sub(PREFETCH_AHEAD) {
            prefetch(&splats[list[ahead] as usize]);
        }
        let s = &splats[list[j] as usize];
        let (r0, r1) = tile_rows(s, geo);
        let rank = j as u32;
        pairs += ((r1 - r0) * TILE) as u64;
        let mut lane = [[zero; TILE]; L];
        for r in r0..r1 {
            let dy = F::c((geo.y0 + r) as f64 + 0.5) - s.mean[1];
            let row = row_terms(s, dy);
            let last = &state.last[r];
            let (gr, gg, gb) = (&grad.color[0][r], &grad.color[1][r], &grad.color[2][r]);
            let (gd, ga) = (&grad.depth[r], &grad.alpha[r]);
            let t = &mut t[r];
            let [a0, a1, a2] = &mut acc;
            let (ar, ag, ab) = (&mut a0[r], &mut a1[r], &mut a2[r]);
            let ad = &mut acc_d[r];
            let aa = &mut acc_a[r];
            for c in 0..TILE {
                let dx = px[c] - s.mean[0];
                let (power, g, alpha) = splat_alpha::<F, M>(s, row, dx);
                let valid = (rank < last[c]) & (power <= zero) & (alpha >= amin);
                let one_minus = one - alpha;
                let t_j = t[c] / one_minus;
                let w = if valid { alpha * t_j } else { zero };
                let mut dot = gr[c] * (s.color[0] - ar[c]);
                dot = M::madd(gg[c], s.color[1] - ag[c], dot);
                dot = M::madd(gb[c], s.color[2] - ab[c], dot);
                dot = M::madd(gd[c], s.depth - ad[c], dot);
                dot = M::madd(ga[c], one - aa[c], dot);
                let dl_dalpha = t_j * dot;
                lane[6][c] = M::madd(w, gr[c], lane[6][c]);
                lane[7][c] = M::madd(w, gg[c], lane[7][c]);
                lane[8][c] = M::madd(w, gb[c], lane[8][c]);
                lane[9][c] = M::madd(w, gd[c], lane[9][c]);
                // α = o·g unless clamped at 0.99, where it no longer depends on o or the shape.
                let free = valid & (s.opacity * g < amax);
                let dl_dalpha = if free { dl_dalpha } else { zero };
                let dpow = dl_dalpha * alpha;
                lane[5][c] = M::madd(dl_dalpha, g, lane[5][c]);
                lane[0][c] = M::madd(dpow, M::madd(s.conic[0], dx, s.conic[1] * dy), lane[0][c]);
                lane[1][c] = M::madd(dpow, M::madd(s.conic[2], dy, s.conic[1] * dx), lane[1][c]);
                let hdx = half * dpow * dx;
                lane[2][c] = M::madd(-hdx, dx, lane[2][c]);
                lane[3][c] = M::madd(-dpow * dx, dy, lane[3][c]);
                lane[4][c] = M::madd(-half * dpow * dy, dy, lane[4][c]);
                let keep = if valid { one_minus } else { one };
                let add = if valid { alpha } else { zero };
                ar[c] = M::madd(add, s.color[0], keep * ar[c]);
                ag[c] = M::madd(add, s.color[1], keep * ag[c]);
                ab[c] = M::madd(add, s.color[2], keep * ab[c]);
                ad[c] = M::madd(add, s.depth, keep * ad[c]);
                aa[c] = M::madd(keep, aa[c], add);
                t[c] = if valid { t_j } else { t[c] };
            }
        }
        let dst = &mut out[j * L..(j + 1) * L];
        for (k, v) in dst.iter_mut().enumerate() {
            *v = lane[k].iter().copied().fold(zero, |a, b| a + b);
        }
    }
    pairs
}
