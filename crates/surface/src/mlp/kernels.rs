//! Host forward and backward of a small fully connected network, fused over layers.
//!
//! Rows are processed in fixed blocks; the backward recomputes each block's activations
//! instead of storing them (the layers are narrow, so recomputing costs one forward pass and
//! saves `N × width` floats per layer). Parameter gradients are summed per fixed block of rows
//! and then over blocks in order, so results do not depend on the thread count.

use num_traits::Float;
use rayon::prelude::*;

use super::{Activation, MlpSpec};

/// Rows per parallel work item.
const ROWS: usize = 256;

#[inline]
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
#[inline]
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
        for i in 0..din {
            let xi = x[i];
            if xi == T::zero() {
                continue;
            }
            let wr = &w[i * dout..(i + 1) * dout];
            for j in 0..dout {
                y[j] = y[j] + xi * wr[j];
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
        .for_each(|(o, x)| {
            let mut acts = buffers::<T>(spec);
            for (r, xr) in x.chunks_exact(din).enumerate() {
                row_forward(spec, params, xr, &mut acts);
                o[r * dout..(r + 1) * dout].copy_from_slice(acts.last().unwrap());
            }
        });
    out
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
    let mut grad_in = vec![T::zero(); if want_input { n * din } else { 0 }];
    let blocks = n.div_ceil(ROWS);
    let block_grads: Vec<(usize, Vec<T>, Vec<T>)> = (0..blocks)
        .into_par_iter()
        .map(|blk| {
            let rows = blk * ROWS..((blk + 1) * ROWS).min(n);
            let mut gp = vec![T::zero(); params.len()];
            let mut gin = vec![T::zero(); if want_input { rows.len() * din } else { 0 }];
            let mut acts = buffers::<T>(spec);
            let mut g: Vec<Vec<T>> = buffers::<T>(spec);
            for (r, row) in rows.clone().enumerate() {
                row_forward(spec, params, &input[row * din..(row + 1) * din], &mut acts);
                g[n_layers].copy_from_slice(&grad_out[row * dout..(row + 1) * dout]);
                for k in (0..n_layers).rev() {
                    let (kin, kout) = (spec.dims[k], spec.dims[k + 1]);
                    let a = if k + 1 == n_layers {
                        spec.output
                    } else {
                        spec.hidden
                    };
                    // g[k+1] ← g[k+1] ⊙ act'(pre).
                    {
                        let y = &acts[k + 1];
                        let gk = &mut g[k + 1];
                        for j in 0..kout {
                            gk[j] = gk[j] * dact(a, y[j]);
                        }
                    }
                    let o = offsets[k];
                    let (gw, rest) = gp[o..].split_at_mut(kin * kout);
                    let gb = &mut rest[..kout];
                    let x = &acts[k];
                    let (glo, ghi) = g.split_at_mut(k + 1);
                    let gz = &ghi[0];
                    for j in 0..kout {
                        gb[j] = gb[j] + gz[j];
                    }
                    for i in 0..kin {
                        let xi = x[i];
                        if xi != T::zero() {
                            let row_w = &mut gw[i * kout..(i + 1) * kout];
                            for j in 0..kout {
                                row_w[j] = row_w[j] + xi * gz[j];
                            }
                        }
                    }
                    if k > 0 || want_input {
                        let w = &params[o..o + kin * kout];
                        let gx = &mut glo[k];
                        for i in 0..kin {
                            let wr = &w[i * kout..(i + 1) * kout];
                            let mut s = T::zero();
                            for j in 0..kout {
                                s = s + wr[j] * gz[j];
                            }
                            gx[i] = s;
                        }
                    }
                }
                if want_input {
                    gin[r * din..(r + 1) * din].copy_from_slice(&g[0]);
                }
            }
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
