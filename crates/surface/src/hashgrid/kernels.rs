//! Host forward and backward of the hash encoding (layout and conventions in the parent module).
//!
//! Generic over `f32`/`f64` so that the tests compare the hand-written backward with finite
//! differences in double precision. The table gradient is parallel over levels (each level owns
//! a disjoint slice of the table, so there are no write conflicts and the sums are in a fixed
//! order: results do not depend on the thread count); the position gradient is parallel over
//! points.

use num_traits::Float;
use rayon::prelude::*;

use super::layout::{GridLayout, LevelLayout};

const PRIME_Y: u32 = 2_654_435_761;
const PRIME_Z: u32 = 805_459_861;
/// Points per parallel work item.
const CHUNK: usize = 512;

/// The 8 vertices of a point's cell at one level and their trilinear weights.
struct Cell<T> {
    index: [usize; 8],
    weight: [T; 8],
    /// `∂ weight / ∂ position` along each axis, in world units (zero along clamped axes).
    dweight: [[T; 3]; 8],
}

#[inline(always)]
fn vertex_index(lay: &LevelLayout, x: u32, y: u32, z: u32) -> usize {
    if lay.dense {
        let n = lay.resolution as usize + 1;
        x as usize + n * (y as usize + n * z as usize)
    } else {
        let h = x ^ y.wrapping_mul(PRIME_Y) ^ z.wrapping_mul(PRIME_Z);
        (h as usize) & (lay.entries - 1)
    }
}

#[inline(always)]
fn cell<T: Float>(p: [T; 3], lay: &LevelLayout, bound: T, with_grad: bool) -> Cell<T> {
    let one = T::one();
    let two = one + one;
    let n = T::from(lay.resolution).unwrap();
    let scale = n / (two * bound);
    let mut base = [0u32; 3];
    let mut frac = [T::zero(); 3];
    let mut dpos = [T::zero(); 3];
    for a in 0..3 {
        let u = (p[a] + bound) / (two * bound);
        let inside = u >= T::zero() && u <= one;
        let u = u.max(T::zero()).min(one);
        let pos = u * n;
        let i = pos.floor().min(n - one).max(T::zero());
        base[a] = i.to_u32().unwrap_or(0);
        frac[a] = pos - i;
        dpos[a] = if inside { scale } else { T::zero() };
    }
    let mut out = Cell {
        index: [0; 8],
        weight: [T::zero(); 8],
        dweight: [[T::zero(); 3]; 8],
    };
    for c in 0..8 {
        let bits = [c & 1, (c >> 1) & 1, (c >> 2) & 1];
        let f: [T; 3] = std::array::from_fn(|a| if bits[a] == 1 { frac[a] } else { one - frac[a] });
        out.index[c] = vertex_index(
            lay,
            base[0] + bits[0] as u32,
            base[1] + bits[1] as u32,
            base[2] + bits[2] as u32,
        );
        out.weight[c] = f[0] * f[1] * f[2];
        if with_grad {
            let s: [T; 3] = std::array::from_fn(|a| if bits[a] == 1 { one } else { -one });
            out.dweight[c] = [
                s[0] * f[1] * f[2] * dpos[0],
                f[0] * s[1] * f[2] * dpos[1],
                f[0] * f[1] * s[2] * dpos[2],
            ];
        }
    }
    out
}

#[inline(always)]
fn forward_chunk<T: Float>(
    layout: &GridLayout,
    table: &[T],
    window: &[T],
    bound: T,
    pos: &[T],
    o: &mut [T],
) {
    let nf = layout.features;
    let dim = layout.levels.len() * nf;
    for (k, p) in pos.chunks_exact(3).enumerate() {
        let p = [p[0], p[1], p[2]];
        let row = &mut o[k * dim..(k + 1) * dim];
        for (l, lay) in layout.levels.iter().enumerate() {
            let m = window[l];
            if m == T::zero() {
                continue;
            }
            let c = cell(p, lay, bound, false);
            for f in 0..nf {
                let mut acc = T::zero();
                for v in 0..8 {
                    acc = acc + c.weight[v] * table[(lay.offset + c.index[v]) * nf + f];
                }
                row[l * nf + f] = m * acc;
            }
        }
    }
}

// One level's slice of the table gradient: the kernel's inner loop, inlined; a struct of its
// nine borrowed inputs would only rename them.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn backward_table_level<T: Float>(
    lay: &LevelLayout,
    l: usize,
    nf: usize,
    dim: usize,
    m: T,
    bound: T,
    positions: &[T],
    grad_out: &[T],
    g: &mut [T],
) {
    for (k, p) in positions.chunks_exact(3).enumerate() {
        let go = &grad_out[k * dim + l * nf..k * dim + (l + 1) * nf];
        if go.iter().all(|v| *v == T::zero()) {
            continue;
        }
        let c = cell([p[0], p[1], p[2]], lay, bound, false);
        for v in 0..8 {
            let w = m * c.weight[v];
            let base = c.index[v] * nf;
            for f in 0..nf {
                g[base + f] = g[base + f] + w * go[f];
            }
        }
    }
}

#[inline(always)]
fn backward_positions_chunk<T: Float>(
    layout: &GridLayout,
    table: &[T],
    window: &[T],
    bound: T,
    pos: &[T],
    go: &[T],
    gp: &mut [T],
) {
    let nf = layout.features;
    let dim = layout.levels.len() * nf;
    for (k, p) in pos.chunks_exact(3).enumerate() {
        let mut acc = [T::zero(); 3];
        for (l, lay) in layout.levels.iter().enumerate() {
            let m = window[l];
            if m == T::zero() {
                continue;
            }
            let g = &go[k * dim + l * nf..k * dim + (l + 1) * nf];
            let c = cell([p[0], p[1], p[2]], lay, bound, true);
            for v in 0..8 {
                let mut dot = T::zero();
                let base = (lay.offset + c.index[v]) * nf;
                for f in 0..nf {
                    dot = dot + table[base + f] * g[f];
                }
                let dot = dot * m;
                for a in 0..3 {
                    acc[a] = acc[a] + c.dweight[v][a] * dot;
                }
            }
        }
        gp[k * 3..k * 3 + 3].copy_from_slice(&acc);
    }
}

/// Calls an `#[inline(always)]` kernel through a copy compiled for AVX2 + FMA when the CPU
/// has them (wider vectors and a hardware `floor`; no fused multiply-adds, so the results are
/// the same as the baseline build's).
macro_rules! dispatch {
    ($f:ident($($arg:expr),*)) => {{
        #[cfg(target_arch = "x86_64")]
        {
            if crate::mlp::kernels::has_avx2() {
                // SAFETY: the CPU supports AVX2 and FMA (checked just above).
                unsafe { avx2::$f($($arg),*) }
            } else {
                $f($($arg),*)
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            $f($($arg),*)
        }
    }};
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::*;

    #[target_feature(enable = "avx2,fma")]
    pub(super) fn forward_chunk<T: Float>(
        layout: &GridLayout,
        table: &[T],
        window: &[T],
        bound: T,
        pos: &[T],
        o: &mut [T],
    ) {
        super::forward_chunk(layout, table, window, bound, pos, o);
    }

    #[target_feature(enable = "avx2,fma")]
    #[allow(clippy::too_many_arguments)]
    pub(super) fn backward_table_level<T: Float>(
        lay: &LevelLayout,
        l: usize,
        nf: usize,
        dim: usize,
        m: T,
        bound: T,
        positions: &[T],
        grad_out: &[T],
        g: &mut [T],
    ) {
        super::backward_table_level(lay, l, nf, dim, m, bound, positions, grad_out, g);
    }

    #[target_feature(enable = "avx2,fma")]
    pub(super) fn backward_positions_chunk<T: Float>(
        layout: &GridLayout,
        table: &[T],
        window: &[T],
        bound: T,
        pos: &[T],
        go: &[T],
        gp: &mut [T],
    ) {
        super::backward_positions_chunk(layout, table, window, bound, pos, go, gp);
    }
}

/// Encodes `positions` (`[N, 3]` flat): returns `[N, L·F]` features, level `l`'s scaled by
/// `window[l]`.
pub fn forward<T: Float + Send + Sync>(
    layout: &GridLayout,
    table: &[T],
    window: &[T],
    positions: &[T],
) -> Vec<T> {
    let nl = layout.levels.len();
    let nf = layout.features;
    let dim = nl * nf;
    let n = positions.len() / 3;
    let bound = T::from(layout.bound).unwrap();
    let mut out = vec![T::zero(); n * dim];
    out.par_chunks_mut(CHUNK * dim)
        .zip(positions.par_chunks(CHUNK * 3))
        .for_each(|(o, pos)| dispatch!(forward_chunk(layout, table, window, bound, pos, o)));
    out
}

/// Gradient of the table given `grad_out` (`[N, L·F]`), parallel over levels.
pub fn backward_table<T: Float + Send + Sync>(
    layout: &GridLayout,
    window: &[T],
    positions: &[T],
    grad_out: &[T],
) -> Vec<T> {
    let nf = layout.features;
    let dim = layout.levels.len() * nf;
    let bound = T::from(layout.bound).unwrap();
    let mut grad = vec![T::zero(); layout.num_params()];
    // Split the gradient into the levels' disjoint slices.
    let mut slices: Vec<(usize, &LevelLayout, &mut [T])> = Vec::with_capacity(layout.levels.len());
    let mut rest: &mut [T] = &mut grad;
    for (l, lay) in layout.levels.iter().enumerate() {
        let (head, tail) = rest.split_at_mut(lay.entries * nf);
        slices.push((l, lay, head));
        rest = tail;
    }
    slices.into_par_iter().for_each(|(l, lay, g)| {
        let m = window[l];
        if m != T::zero() {
            dispatch!(backward_table_level(
                lay, l, nf, dim, m, bound, positions, grad_out, g
            ));
        }
    });
    grad
}

/// Gradient of the positions (`[N, 3]`) given `grad_out`, parallel over points.
pub fn backward_positions<T: Float + Send + Sync>(
    layout: &GridLayout,
    table: &[T],
    window: &[T],
    positions: &[T],
    grad_out: &[T],
) -> Vec<T> {
    let nf = layout.features;
    let dim = layout.levels.len() * nf;
    let bound = T::from(layout.bound).unwrap();
    let mut grad = vec![T::zero(); positions.len()];
    grad.par_chunks_mut(CHUNK * 3)
        .zip(positions.par_chunks(CHUNK * 3))
        .zip(grad_out.par_chunks(CHUNK * dim))
        .for_each(|((gp, pos), go)| {
            dispatch!(backward_positions_chunk(
                layout, table, window, bound, pos, go, gp
            ));
        });
    grad
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hashgrid::{HashGridConfig, init_table};
    use rand::rngs::StdRng;
    use rand::{RngExt, SeedableRng};

    fn small() -> GridLayout {
        HashGridConfig {
            levels: 5,
            features_per_level: 2,
            log2_table_size: 9,
            base_resolution: 3,
            finest_resolution: 40,
            bound: 1.0,
        }
        .layout()
        .unwrap()
    }

    fn random_points(n: usize, seed: u64, r: f64) -> Vec<f64> {
        let mut rng = StdRng::seed_from_u64(seed);
        (0..n * 3).map(|_| rng.random_range(-r..r)).collect()
    }

    /// Naive reference: the interpolation written from the definition, one vertex at a time.
    fn naive(lay: &GridLayout, table: &[f64], window: &[f64], p: [f64; 3]) -> Vec<f64> {
        let mut out = Vec::new();
        for (l, lv) in lay.levels.iter().enumerate() {
            let n = lv.resolution as f64;
            let pos: Vec<f64> = p
                .iter()
                .map(|x| ((x + 1.0) / 2.0).clamp(0.0, 1.0) * n)
                .collect();
            let i0: Vec<u32> = pos.iter().map(|v| v.floor().min(n - 1.0) as u32).collect();
            for f in 0..lay.features {
                let mut acc = 0.0;
                for dz in 0..2u32 {
                    for dy in 0..2u32 {
                        for dx in 0..2u32 {
                            let d = [dx, dy, dz];
                            let mut w = 1.0;
                            for a in 0..3 {
                                let t = pos[a] - i0[a] as f64;
                                w *= if d[a] == 1 { t } else { 1.0 - t };
                            }
                            let idx = vertex_index(lv, i0[0] + dx, i0[1] + dy, i0[2] + dz);
                            acc += w * table[(lv.offset + idx) * lay.features + f];
                        }
                    }
                }
                out.push(window[l] * acc);
            }
        }
        out
    }

    #[test]
    fn forward_matches_naive_interpolation() {
        let lay = small();
        let table: Vec<f64> = init_table(&lay, 3)
            .iter()
            .map(|v| *v as f64 * 1e4)
            .collect();
        let window = vec![1.0, 1.0, 0.7, 0.2, 0.0];
        let pts = random_points(200, 5, 1.2);
        let out = forward(&lay, &table, &window, &pts);
        let dim = lay.output_dim();
        for (k, p) in pts.chunks_exact(3).enumerate() {
            let want = naive(&lay, &table, &window, [p[0], p[1], p[2]]);
            for (a, b) in out[k * dim..(k + 1) * dim].iter().zip(&want) {
                assert!((a - b).abs() < 1e-12, "{a} vs {b}");
            }
        }
    }

    #[test]
    fn the_interpolation_reproduces_vertex_values() {
        // A dense level whose table holds x + 2y − z at each vertex interpolates that linear
        // function exactly anywhere.
        let lay = HashGridConfig {
            levels: 1,
            features_per_level: 1,
            log2_table_size: 12,
            base_resolution: 7,
            finest_resolution: 7,
            bound: 1.0,
        }
        .layout()
        .unwrap();
        let n = 8usize;
        let mut table = vec![0.0f64; lay.num_params()];
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    let w = |i: usize| i as f64 / 7.0 * 2.0 - 1.0;
                    table[x + n * (y + n * z)] = w(x) + 2.0 * w(y) - w(z);
                }
            }
        }
        let pts = random_points(50, 9, 1.0);
        let out = forward(&lay, &table, &[1.0], &pts);
        for (k, p) in pts.chunks_exact(3).enumerate() {
            let want = p[0] + 2.0 * p[1] - p[2];
            assert!((out[k] - want).abs() < 1e-12);
        }
    }

    #[test]
    fn gradients_match_finite_differences() {
        let lay = small();
        let table: Vec<f64> = init_table(&lay, 7)
            .iter()
            .map(|v| *v as f64 * 1e4)
            .collect();
        let window = vec![1.0, 0.9, 0.6, 0.3, 0.05];
        let pts = random_points(40, 11, 0.95);
        let dim = lay.output_dim();
        let mut rng = StdRng::seed_from_u64(13);
        let gout: Vec<f64> = (0..40 * dim).map(|_| rng.random_range(-1.0..1.0)).collect();
        let loss = |t: &[f64], p: &[f64]| -> f64 {
            forward(&lay, t, &window, p)
                .iter()
                .zip(&gout)
                .map(|(a, b)| a * b)
                .sum()
        };
        // Table: the encoding is linear in the table, so central differences are exact.
        let gt = backward_table(&lay, &window, &pts, &gout);
        let mut checked = 0;
        for i in (0..table.len()).step_by(7) {
            let h = 1e-3;
            let mut tp = table.clone();
            tp[i] += h;
            let mut tm = table.clone();
            tm[i] -= h;
            let fd = (loss(&tp, &pts) - loss(&tm, &pts)) / (2.0 * h);
            assert!((fd - gt[i]).abs() < 1e-9, "table {i}: {fd} vs {}", gt[i]);
            checked += (gt[i] != 0.0) as usize;
        }
        assert!(
            checked > 20,
            "only {checked} non-zero table gradients checked"
        );
        // Positions: trilinear is linear along each axis inside a cell; a tiny step stays inside.
        let gp = backward_positions(&lay, &table, &window, &pts, &gout);
        for i in 0..pts.len() {
            let h = 1e-7;
            let mut pp = pts.clone();
            pp[i] += h;
            let mut pm = pts.clone();
            pm[i] -= h;
            let fd = (loss(&table, &pp) - loss(&table, &pm)) / (2.0 * h);
            let tol = 1e-5 * (1.0 + gp[i].abs());
            assert!((fd - gp[i]).abs() < tol, "position {i}: {fd} vs {}", gp[i]);
        }
    }

    #[test]
    fn clamped_axes_have_no_position_gradient() {
        let lay = small();
        let table: Vec<f64> = init_table(&lay, 1).iter().map(|v| *v as f64).collect();
        let pts = vec![1.5, 0.2, -0.3];
        let gout = vec![1.0; lay.output_dim()];
        let g = backward_positions(&lay, &table, &[1.0; 5], &pts, &gout);
        assert_eq!(g[0], 0.0);
        assert!(g[1] != 0.0 && g[2] != 0.0);
    }

    #[test]
    fn results_do_not_depend_on_the_thread_count() {
        let lay = small();
        let table = init_table(&lay, 2);
        let pts: Vec<f32> = random_points(3000, 4, 1.0)
            .iter()
            .map(|v| *v as f32)
            .collect();
        let gout: Vec<f32> = (0..3000 * lay.output_dim())
            .map(|i| ((i * 31 % 17) as f32 - 8.0) * 0.1)
            .collect();
        let window = [1.0f32; 5];
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                (
                    backward_table(&lay, &window, &pts, &gout),
                    backward_positions(&lay, &table, &window, &pts, &gout),
                )
            })
        };
        assert_eq!(run(1), run(3));
    }
}
