//! Loop-by-loop twins of the network's blocks, for tests: plain `Vec<f32>` arithmetic that
//! reads the modules' weights and computes the same functions without any Burn operation.

use burn::module::Param;
use burn::nn::conv::Conv2d;
use burn::nn::{BatchNorm, Linear};
use burn::tensor::Tensor;

use super::residual::ResidualUnit;
use super::se::SqueezeExcitation;

/// An NCHW array on the host.
#[derive(Clone, Debug)]
pub struct Host {
    pub data: Vec<f32>,
    pub shape: [usize; 4],
}

impl Host {
    pub fn from_tensor(t: Tensor<4>) -> Self {
        let shape = t.dims();
        Self {
            data: t.into_data().try_to_vec::<f32>().unwrap(),
            shape,
        }
    }

    fn zeros(shape: [usize; 4]) -> Self {
        Self {
            data: vec![0.0; shape.iter().product()],
            shape,
        }
    }

    fn at(&self, n: usize, c: usize, y: usize, x: usize) -> f32 {
        let [_, cs, h, w] = self.shape;
        self.data[((n * cs + c) * h + y) * w + x]
    }

    fn at_mut(&mut self, n: usize, c: usize, y: usize, x: usize) -> &mut f32 {
        let [_, cs, h, w] = self.shape;
        &mut self.data[((n * cs + c) * h + y) * w + x]
    }

    fn map(mut self, f: impl Fn(f32) -> f32) -> Self {
        self.data.iter_mut().for_each(|v| *v = f(*v));
        self
    }

    fn add(mut self, other: &Host) -> Self {
        assert_eq!(self.shape, other.shape);
        self.data
            .iter_mut()
            .zip(&other.data)
            .for_each(|(a, b)| *a += b);
        self
    }
}

pub fn values<const D: usize>(p: &Param<Tensor<D>>) -> Vec<f32> {
    p.val().into_data().try_to_vec::<f32>().unwrap()
}

/// Zero-padded (by `k / 2`) strided cross-correlation plus bias, as the module is configured.
pub fn conv(x: &Host, conv: &Conv2d) -> Host {
    let w = values(&conv.weight);
    let [co, ci, k, _] = conv.weight.dims();
    let bias = conv.bias.as_ref().map(values).unwrap_or(vec![0.0; co]);
    let s = conv.stride[0];
    let [n, cin, h, wd] = x.shape;
    assert_eq!(cin, ci);
    let (ho, wo) = ((h - 1) / s + 1, (wd - 1) / s + 1);
    let mut out = Host::zeros([n, co, ho, wo]);
    for (b, o, oy, ox) in iter4([n, co, ho, wo]) {
        let at = |i: usize, ky: usize, kx: usize| {
            let iy = (oy * s + ky).checked_sub(k / 2).filter(|&y| y < h);
            let ix = (ox * s + kx).checked_sub(k / 2).filter(|&x_| x_ < wd);
            match (iy, ix) {
                (Some(iy), Some(ix)) => w[((o * ci + i) * k + ky) * k + kx] * x.at(b, i, iy, ix),
                _ => 0.0,
            }
        };
        *out.at_mut(b, o, oy, ox) = bias[o]
            + iter4([1, ci, k, k])
                .map(|(_, i, ky, kx)| at(i, ky, kx))
                .sum::<f32>();
    }
    out
}

/// Inference-mode batch norm with the running statistics.
pub fn batch_norm(x: &Host, bn: &BatchNorm) -> Host {
    let (g, b) = (values(&bn.gamma), values(&bn.beta));
    let mean: Vec<f32> = bn
        .running_mean
        .value()
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
    let var: Vec<f32> = bn
        .running_var
        .value()
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
    let mut out = x.clone();
    let [n, c, h, w] = x.shape;
    for (b_, c_, y, x_) in iter4([n, c, h, w]) {
        let v = x.at(b_, c_, y, x_);
        *out.at_mut(b_, c_, y, x_) =
            (v - mean[c_]) / (var[c_] + bn.epsilon as f32).sqrt() * g[c_] + b[c_];
    }
    out
}

fn iter4(s: [usize; 4]) -> impl Iterator<Item = (usize, usize, usize, usize)> {
    (0..s[0]).flat_map(move |a| {
        (0..s[1])
            .flat_map(move |b| (0..s[2]).flat_map(move |c| (0..s[3]).map(move |d| (a, b, c, d))))
    })
}

/// `out_j = Σ_i in_i W[i][j] + b_j` with Burn's `[d_input, d_output]` weight layout.
fn linear(input: &[f32], l: &Linear) -> Vec<f32> {
    let w = values(&l.weight);
    let [di, dout] = l.weight.dims();
    let bias = l.bias.as_ref().map(values).unwrap_or(vec![0.0; dout]);
    (0..dout)
        .map(|j| bias[j] + (0..di).map(|i| input[i] * w[i * dout + j]).sum::<f32>())
        .collect()
}

pub fn squeeze_excitation(x: &Host, se: &SqueezeExcitation) -> Host {
    let [n, c, h, w] = x.shape;
    let mut out = x.clone();
    for b in 0..n {
        let means: Vec<f32> = (0..c)
            .map(|ch| {
                iter4([1, 1, h, w])
                    .map(|(_, _, y, x_)| x.at(b, ch, y, x_))
                    .sum::<f32>()
                    / (h * w) as f32
            })
            .collect();
        let hidden: Vec<f32> = linear(&means, &se.reduce)
            .into_iter()
            .map(|v| v.max(0.0))
            .collect();
        let gate: Vec<f32> = linear(&hidden, &se.expand)
            .into_iter()
            .map(|v| 1.0 / (1.0 + (-v).exp()))
            .collect();
        for (_, ch, y, x_) in iter4([1, c, h, w]) {
            *out.at_mut(b, ch, y, x_) *= gate[ch];
        }
    }
    out
}

pub fn residual_unit(x: &Host, u: &ResidualUnit) -> Host {
    let mut y = conv(x, &u.conv1);
    if let Some(bn) = &u.norm1 {
        y = batch_norm(&y, bn).map(|v| v.max(0.0));
    }
    if let Some(c2) = &u.conv2 {
        y = conv(&y, c2);
    }
    if let Some(bn) = &u.norm2 {
        y = batch_norm(&y, bn);
    }
    let skip = match &u.shortcut {
        Some(p) => {
            let s = conv(x, &p.conv);
            p.norm.as_ref().map(|bn| batch_norm(&s, bn)).unwrap_or(s)
        }
        None => x.clone(),
    };
    squeeze_excitation(&y, &u.se).add(&skip).map(|v| v.max(0.0))
}
