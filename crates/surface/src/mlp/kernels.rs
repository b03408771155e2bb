//! Host forward and backward of a small fully connected network, fused over layers.
//!
//! Rows are processed in fixed blocks; the backward recomputes each block's activations
//! instead of storing them (the layers are narrow, so recomputing costs one forward pass and
//! saves `N × width` floats per layer). Parameter gradients are summed per fixed block of rows
//! and then over blocks in order, so results do not depend on the thread count.

use num_traits::Float;
use rayon::prelude::*;

use super::spec::{Activation, MlpSpec};

/// Rows per parallel work item.
const ROWS: usize = 256;

#[inline(always)]
fn act<T: Float>(a: Activation, z: T) -> T {
    match a {
        Activation::None => z,
        Activation::Relu => z.max(T::zero()),
        Activation::Softplus(beta) => {
            let b = T::from(beta).unwrap();
            let x = b * z;
            if x > T::from(20.0).unwrap() {
                z
            } else {
                x.exp().ln_1p() / b
            }
        }
        Activation::Sigmoid => T::one() / (T::one() + (-z).exp()),
    }
}

/// `d act / d z` written in terms of the output `y = act(z)`.
#[inline(always)]
fn dact<T: Float>(a: Activation, y: T) -> T {
    match a {
        Activation::None => T::one(),
        Activation::Relu => {
            if y > T::zero() {
                T::one()
            } else {
                T::zero()
            }
        }
        // softplus'(z) = σ(βz) = 1 − exp(−β·softplus(z)).
        Activation::Softplus(beta) => T::one() - (-(T::from(beta).unwrap()) * y).exp(),
        Activation::Sigmoid => y * (T::one() - y),
    }
}

#[inline(always)]
/// Forward of one row; `acts` receives every layer's output (input first), `acts[k]` of width
/// `dims[k]`.
fn row_forward<T: Float>(spec: &MlpSpec, params: &[T], input: &[T], acts: &mut [Vec<T>]) {
    acts[0].copy_from_slice(input);
    let n_layers = spec.dims.len() - 1;
    let mut off = 0;
    for k in 0..n_layers {
        let (din, dout) = (spec.dims[k], spec.dims[k + 1]);
        let w = &params[off..off + din * dout];
        let b = &params[off + din * dout..off + din * dout + dout];
        off += din * dout + dout;
        let (lo, hi) = acts.split_at_mut(k + 1);
        let x = &lo[k];
        let y = &mut hi[0];
        y.copy_from_slice(b);
        for (&xi, wr) in x.iter().zip(w.chunks_exact(dout)) {
            if xi == T::zero() {
                continue;
            }
            for (yj, &wj) in y.iter_mut().zip(wr) {
                *yj = *yj + xi * wj;
            }
        }
        let a = if k + 1 == n_layers {
            spec.output
        } else {
            spec.hidden
        };
        for v in y.iter_mut() {
            *v = act(a, *v);
        }
    }
}

fn buffers<T: Float>(spec: &MlpSpec) -> Vec<Vec<T>> {
    spec.dims.iter().map(|&d| vec![T::zero(); d]).collect()
}

/// `input [N, dims[0]]` → `[N, dims.last()]`.
pub fn forward<T: Float + Send + Sync>(spec: &MlpSpec, params: &[T], input: &[T]) -> Vec<T> {
    let (din, dout) = (spec.dims[0], *spec.dims.last().unwrap());
    let n = input.len() / din;
    let mut out = vec![T::zero(); n * dout];
    out.par_chunks_mut(ROWS * dout)
        .zip(input.par_chunks(ROWS * din))
        .for_each(|(o, x)| forward_block_best(spec, params, x, o));
    out
}

#[inline(always)]
fn forward_block<T: Float>(spec: &MlpSpec, params: &[T], x: &[T], o: &mut [T]) {
    let (din, dout) = (spec.dims[0], *spec.dims.last().unwrap());
    let mut acts = buffers::<T>(spec);
    for (r, xr) in x.chunks_exact(din).enumerate() {
        row_forward(spec, params, xr, &mut acts);
        o[r * dout..(r + 1) * dout].copy_from_slice(acts.last().unwrap());
    }
}

/// Whether the CPU runs the AVX2 + FMA builds of the kernels (same results: no fused
/// multiply-adds are introduced, only wider vectors).
#[cfg(target_arch = "x86_64")]
pub(crate) fn has_avx2() -> bool {
    fewview_scene::cpu::avx2_fma()
}

fn forward_block_best<T: Float>(spec: &MlpSpec, params: &[T], x: &[T], o: &mut [T]) {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx2,fma")]
        fn avx2<T: Float>(spec: &MlpSpec, params: &[T], x: &[T], o: &mut [T]) {
            forward_block(spec, params, x, o);
        }
        if has_avx2() {
            // SAFETY: the CPU supports AVX2 and FMA (checked just above).
            return unsafe { avx2(spec, params, x, o) };
        }
    }
    forward_block(spec, params, x, o);
}

/// Gradients `(d input [N, dims[0]], d params [P])` given `grad_out [N, dims.last()]`.
/// `want_input` = false skips the input gradient (returns an empty vector).
pub fn backward<T: Float + Send + Sync>(
    spec: &MlpSpec,
    params: &[T],
    input: &[T],
    grad_out: &[T],
    want_input: bool,
) -> (Vec<T>, Vec<T>) {
    let (din, dout) = (spec.dims[0], *spec.dims.last().unwrap());
    let n = input.len() / din;
    let n_layers = spec.dims.len() - 1;
    let mut offsets = Vec::with_capacity(n_layers);
    let mut off = 0;
    for k in 0..n_layers {
        offsets.push(off);
        off += spec.dims[k] * spec.dims[k + 1] + spec.dims[k + 1];
    }
    // Transposed weights, so the input gradient `W g` vectorises over the inputs.
    let transposed: Vec<Vec<T>> = (0..n_layers)
        .map(|k| {
            let (kin, kout) = (spec.dims[k], spec.dims[k + 1]);
            let w = &params[offsets[k]..offsets[k] + kin * kout];
            let mut t = vec![T::zero(); kin * kout];
            for i in 0..kin {
                for j in 0..kout {
                    t[j * kin + i] = w[i * kout + j];
                }
            }
            t
        })
        .collect();
    let mut grad_in = vec![T::zero(); if want_input { n * din } else { 0 }];
    let blocks = n.div_ceil(ROWS);
    let block_grads: Vec<(usize, Vec<T>, Vec<T>)> = (0..blocks)
        .into_par_iter()
        .map(|blk| {
            let rows = blk * ROWS..((blk + 1) * ROWS).min(n);
            let mut gp = vec![T::zero(); params.len()];
            let mut gin = vec![T::zero(); if want_input { rows.len() * din } else { 0 }];
            let ctx = BackwardCtx {
                spec,
                params,
                offsets: &offsets,
                transposed: &transposed,
                want_input,
            };
            backward_block_best(
                &ctx,
                &input[rows.start * din..rows.end * din],
                &grad_out[rows.start * dout..rows.end * dout],
                &mut gp,
                &mut gin,
            );
            (blk, gp, gin)
        })
        .collect();
    let mut grad_params = vec![T::zero(); params.len()];
    for (blk, gp, gin) in block_grads {
        for (a, b) in grad_params.iter_mut().zip(&gp) {
            *a = *a + *b;
        }
        if want_input {
            let start = blk * ROWS * din;
            grad_in[start..start + gin.len()].copy_from_slice(&gin);
        }
    }
    (grad_in, grad_params)
}

/// Shared inputs of the backward blocks.
struct BackwardCtx<'a, T> {
    spec: &'a MlpSpec,
    params: &'a [T],
    offsets: &'a [usize],
    transposed: &'a [Vec<T>],
    want_input: bool,
}

#[inline(always)]
fn backward_block<T: Float>(
    ctx: &BackwardCtx<T>,
    input: &[T],
    grad_out: &[T],
    gp: &mut [T],
    gin: &mut [T],
) {
    let BackwardCtx {
        spec,
        params,
        offsets,
        transposed,
        want_input,
    } = *ctx;
    let (din, dout) = (spec.dims[0], *spec.dims.last().unwrap());
    let n_layers = spec.dims.len() - 1;
    let rows = input.len() / din;
    let mut acts = buffers::<T>(spec);
    let mut g: Vec<Vec<T>> = buffers::<T>(spec);
    for r in 0..rows {
        row_forward(spec, params, &input[r * din..(r + 1) * din], &mut acts);
        g[n_layers].copy_from_slice(&grad_out[r * dout..(r + 1) * dout]);
        for k in (0..n_layers).rev() {
            let (kin, kout) = (spec.dims[k], spec.dims[k + 1]);
            let a = if k + 1 == n_layers {
                spec.output
            } else {
                spec.hidden
            };
            // g[k+1] ← g[k+1] ⊙ act'(pre).
            for (gj, &yj) in g[k + 1].iter_mut().zip(&acts[k + 1]) {
                *gj = *gj * dact(a, yj);
            }
            let o = offsets[k];
            let (gw, rest) = gp[o..].split_at_mut(kin * kout);
            let gb = &mut rest[..kout];
            let x = &acts[k];
            let (glo, ghi) = g.split_at_mut(k + 1);
            let gz = &ghi[0];
            for (b, &z) in gb.iter_mut().zip(gz) {
                *b = *b + z;
            }
            for (&xi, row_w) in x.iter().zip(gw.chunks_exact_mut(kout)) {
                if xi != T::zero() {
                    for (w, &z) in row_w.iter_mut().zip(gz) {
                        *w = *w + xi * z;
                    }
                }
            }
            if k > 0 || want_input {
                let wt = &transposed[k];
                let gx = &mut glo[k];
                gx.fill(T::zero());
                for (&gj, col) in gz.iter().zip(wt.chunks_exact(kin)) {
                    if gj == T::zero() {
                        continue;
                    }
                    for (x, &c) in gx.iter_mut().zip(col) {
                        *x = *x + gj * c;
                    }
                }
            }
        }
        if want_input {
            gin[r * din..(r + 1) * din].copy_from_slice(&g[0]);
        }
    }
}

fn backward_block_best<T: Float>(
    ctx: &BackwardCtx<T>,
    input: &[T],
    grad_out: &[T],
    gp: &mut [T],
    gin: &mut [T],
) {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx2,fma")]
        fn avx2<T: Float>(
            ctx: &BackwardCtx<T>,
            input: &[T],
            grad_out: &[T],
            gp: &mut [T],
            gin: &mut [T],
        ) {
            backward_block(ctx, input, grad_out, gp, gin);
        }
        if has_avx2() {
            // SAFETY: the CPU supports AVX2 and FMA (checked just above).
            return unsafe { avx2(ctx, input, grad_out, gp, gin) };
        }
    }
    backward_block(ctx, input, grad_out, gp, gin);
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{RngExt, SeedableRng};

    fn spec(hidden: Activation, output: Activation) -> MlpSpec {
        MlpSpec {
            dims: vec![5, 7, 6, 3],
            hidden,
            output,
        }
    }

    fn random(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = StdRng::seed_from_u64(seed);
        (0..n).map(|_| rng.random_range(-1.0..1.0)).collect()
    }

    /// Naive reference: explicit matrix–vector products per layer.
    fn naive(spec: &MlpSpec, params: &[f64], x: &[f64]) -> Vec<f64> {
        let mut h = x.to_vec();
        let mut off = 0;
        for k in 0..spec.dims.len() - 1 {
            let (a, b) = (spec.dims[k], spec.dims[k + 1]);
            let mut y = vec![0.0; b];
            for j in 0..b {
                y[j] = params[off + a * b + j];
                for i in 0..a {
                    y[j] += h[i] * params[off + i * b + j];
                }
                let act_k = if k + 2 == spec.dims.len() {
                    spec.output
                } else {
                    spec.hidden
                };
                y[j] = match act_k {
                    Activation::None => y[j],
                    Activation::Relu => y[j].max(0.0),
                    Activation::Softplus(beta) => {
                        (1.0 + (beta as f64 * y[j]).exp()).ln() / beta as f64
                    }
                    Activation::Sigmoid => 1.0 / (1.0 + (-y[j]).exp()),
                };
            }
            off += a * b + b;
            h = y;
        }
        h
    }

    #[test]
    fn forward_matches_naive_layers() {
        for (hid, out) in [
            (Activation::Softplus(100.0), Activation::None),
            (Activation::Relu, Activation::Sigmoid),
        ] {
            let s = spec(hid, out);
            let params = random(s.num_params(), 1);
            let x = random(300 * 5, 2);
            let y = forward(&s, &params, &x);
            for (r, xr) in x.chunks_exact(5).enumerate() {
                let want = naive(&s, &params, xr);
                for (a, b) in y[r * 3..r * 3 + 3].iter().zip(&want) {
                    assert!((a - b).abs() < 1e-10 * (1.0 + b.abs()), "{a} vs {b}");
                }
            }
        }
    }

    #[test]
    fn gradients_match_finite_differences() {
        for (hid, out) in [
            (Activation::Softplus(10.0), Activation::None),
            (Activation::Softplus(100.0), Activation::Sigmoid),
            (Activation::Relu, Activation::Sigmoid),
        ] {
            let s = spec(hid, out);
            let params = random(s.num_params(), 3);
            let n = 20;
            let x = random(n * 5, 4);
            let gout = random(n * 3, 5);
            let loss = |p: &[f64], x: &[f64]| -> f64 {
                forward(&s, p, x)
                    .iter()
                    .zip(&gout)
                    .map(|(a, b)| a * b)
                    .sum()
            };
            let (gx, gp) = backward(&s, &params, &x, &gout, true);
            let h = 1e-6;
            for i in 0..params.len() {
                let mut pp = params.clone();
                pp[i] += h;
                let mut pm = params.clone();
                pm[i] -= h;
                let fd = (loss(&pp, &x) - loss(&pm, &x)) / (2.0 * h);
                assert!(
                    (fd - gp[i]).abs() < 1e-6 * (1.0 + fd.abs()),
                    "param {i}: {fd} vs {}",
                    gp[i]
                );
            }
            for i in 0..x.len() {
                let mut xp = x.clone();
                xp[i] += h;
                let mut xm = x.clone();
                xm[i] -= h;
                let fd = (loss(&params, &xp) - loss(&params, &xm)) / (2.0 * h);
                assert!(
                    (fd - gx[i]).abs() < 1e-6 * (1.0 + fd.abs()),
                    "input {i}: {fd} vs {}",
                    gx[i]
                );
            }
        }
    }

    #[test]
    fn results_do_not_depend_on_the_thread_count() {
        let s = spec(Activation::Softplus(100.0), Activation::None);
        let params: Vec<f32> = random(s.num_params(), 6)
            .iter()
            .map(|v| *v as f32)
            .collect();
        let x: Vec<f32> = random(2000 * 5, 7).iter().map(|v| *v as f32).collect();
        let gout: Vec<f32> = random(2000 * 3, 8).iter().map(|v| *v as f32).collect();
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| backward(&s, &params, &x, &gout, true))
        };
        assert_eq!(run(1), run(4));
    }
}
