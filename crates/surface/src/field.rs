//! The signed distance field `s(P)` with its geometry features, the colour network, and the
//! NeuS sharpness parameter — everything whose parameters the model optimiser updates.
//!
//! Two geometry encoders sit behind [`SdfNetwork`]:
//! - [`HashGridSdf`] (default): multi-resolution hash grid + one small MLP (Instant-NSR,
//!   Neuralangelo), progressive levels through the BARF window. This is the CPU-practical path.
//! - [`NeusMlpSdf`]: NeuS's 8×256 MLP with a skip connection at layer 4, positional encoding
//!   with BARF's coarse-to-fine window, Softplus(β = 100) and the geometric initialisation —
//!   the architecture the surface paper uses (§B.1). Weight normalisation is left out (it only
//!   reparameterises the optimisation).
//!
//! Normals `n(P) = ∂s/∂P` (Eq. 3) come from finite differences of the network
//! ([`sdf_and_gradient`], Neuralangelo's numerical gradients): Burn has no second-order
//! gradients, and the Eikonal loss needs the gradient of `‖n‖`.

use std::sync::Arc;

use burn::tensor::{Device, Tensor, TensorData};
use serde::{Deserialize, Serialize};

use crate::hashgrid::op::{HashEncoding, hash_encode};
use crate::hashgrid::{GridLayout, HashGridConfig, init_table, level_window};
use crate::mlp::op::mlp;
use crate::mlp::{Activation, MlpSpec, init_default, init_geometric};

/// Which geometry encoder.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum EncoderKind {
    /// A multi-resolution hash grid and a small MLP (Instant-NSR, Neuralangelo).
    HashGrid,
    /// The paper's 8×256 MLP with positional encoding (NeuS).
    NeusMlp,
}

/// Finite-difference stencil for the SDF gradient.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum FdScheme {
    /// Four taps at the vertices of a regular tetrahedron, `∇s ≈ Σ vₖ s(P + ε vₖ) / (4ε)`
    /// (second-order accurate, 4 extra evaluations; as in Instant-NSR).
    Tetrahedron,
    /// Six taps `(s(P + εeₐ) − s(P − εeₐ)) / 2ε` (Neuralangelo).
    Central,
}

/// Everything about the networks.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FieldConfig {
    pub encoder: EncoderKind,
    pub hash: HashGridConfig,
    /// Hidden widths of the SDF head on top of the hash grid.
    pub sdf_hidden: Vec<usize>,
    /// Geometry feature width passed to the colour network (hash grid; NeuS uses 256).
    pub feature_dim: usize,
    /// Hidden widths of the colour network (hash grid; NeuS uses 4 × 256).
    pub color_hidden: Vec<usize>,
    /// Frequencies of NeuS's positional encoding (`multires`, 6).
    pub neus_frequencies: usize,
    /// Radius of the initial sphere of the geometric initialisation (NeuS: 0.5).
    pub init_radius: f32,
    /// Initial value of NeuS's variance parameter (`inv_s = exp(10 · variance)`, 0.3).
    pub init_variance: f32,
    pub fd_scheme: FdScheme,
    /// Hash levels active from the start of the coarse-to-fine window.
    pub always_on_levels: usize,
    /// Hidden activation of the SDF head on the hash grid. ReLU by default: the grid makes the
    /// field only piecewise smooth anyway and normals come from finite differences, while
    /// NeuS's Softplus(β = 100) costs two transcendental functions per unit on a CPU (the NeuS
    /// MLP keeps Softplus(100)).
    pub sdf_activation: crate::mlp::Activation,
}

impl Default for FieldConfig {
    fn default() -> Self {
        Self {
            encoder: EncoderKind::HashGrid,
            hash: HashGridConfig::default(),
            sdf_hidden: vec![64],
            feature_dim: 15,
            color_hidden: vec![64, 64],
            neus_frequencies: 6,
            init_radius: 0.5,
            init_variance: 0.3,
            fd_scheme: FdScheme::Tetrahedron,
            always_on_levels: 4,
            sdf_activation: Activation::Relu,
        }
    }
}

/// A geometry network: points `[N, 3]` → `[N, 1 + F]` (SDF first, then features).
pub trait SdfNetwork: Send + Sync {
    /// Feature width `F`.
    fn feature_dim(&self) -> usize;
    /// Names and sizes of the parameter vectors.
    fn param_shapes(&self) -> Vec<(&'static str, usize)>;
    /// Initial parameters (geometric initialisation), from a seed.
    fn init_params(&self, seed: u64) -> Vec<Vec<f32>>;
    /// Sets the coarse-to-fine progress `alpha ∈ [0, 1]` (0: coarsest, 1: everything on).
    fn set_progress(&mut self, alpha: f64);
    /// The finite-difference step suited to the current progress.
    fn fd_step(&self) -> f32;
    /// Evaluates the network with parameter tensors in the order of [`Self::param_shapes`].
    fn forward(&self, params: &[Tensor<1>], points: Tensor<2>) -> Tensor<2>;
}

/// Hash grid + MLP.
pub struct HashGridSdf {
    layout: Arc<GridLayout>,
    encoding: HashEncoding,
    spec: Arc<MlpSpec>,
    init_radius: f32,
    always_on: usize,
    fd_min: f32,
    fd_step: f32,
}

impl HashGridSdf {
    pub fn new(cfg: &FieldConfig) -> Result<Self, String> {
        let layout = Arc::new(cfg.hash.layout()?);
        let mut dims = vec![3 + layout.output_dim()];
        dims.extend(&cfg.sdf_hidden);
        dims.push(1 + cfg.feature_dim);
        let spec = Arc::new(MlpSpec {
            dims,
            hidden: cfg.sdf_activation,
            output: Activation::None,
        });
        spec.validate()?;
        let always_on = cfg.always_on_levels.min(layout.levels.len());
        let finest = layout.levels.last().map(|l| l.resolution).unwrap_or(1);
        let fd_min = 2.0 * cfg.hash.bound / finest as f32;
        let mut s = Self {
            encoding: HashEncoding {
                layout: layout.clone(),
                window: vec![1.0; layout.levels.len()],
            },
            layout,
            spec,
            init_radius: cfg.init_radius,
            always_on,
            fd_min,
            fd_step: fd_min,
        };
        s.set_progress(1.0);
        Ok(s)
    }

    pub fn layout(&self) -> &GridLayout {
        &self.layout
    }
}

impl SdfNetwork for HashGridSdf {
    fn feature_dim(&self) -> usize {
        self.spec.output_dim() - 1
    }

    fn param_shapes(&self) -> Vec<(&'static str, usize)> {
        vec![
            ("hash_table", self.layout.num_params()),
            ("sdf_mlp", self.spec.num_params()),
        ]
    }

    fn init_params(&self, seed: u64) -> Vec<Vec<f32>> {
        vec![
            init_table(&self.layout, seed),
            init_geometric(&self.spec, 3, self.init_radius, seed.wrapping_add(1)),
        ]
    }

    /// Levels open one after another over `alpha ∈ [0, 1]` (BARF window); the
    /// finite-difference step follows the finest active level's cell size (Neuralangelo).
    fn set_progress(&mut self, alpha: f64) {
        let n = self.layout.levels.len();
        let ramp = (n - self.always_on) as f64;
        self.encoding.window = level_window(n, alpha.clamp(0.0, 1.0) * ramp, self.always_on);
        let finest_on = self
            .encoding
            .window
            .iter()
            .rposition(|w| *w > 0.5)
            .unwrap_or(0);
        let cell = 2.0 * self.layout.bound / self.layout.levels[finest_on].resolution as f32;
        self.fd_step = cell.max(self.fd_min);
    }

    fn fd_step(&self) -> f32 {
        self.fd_step
    }

    fn forward(&self, params: &[Tensor<1>], points: Tensor<2>) -> Tensor<2> {
        let enc = hash_encode(points.clone(), params[0].clone(), &self.encoding);
        mlp(
            Tensor::cat(vec![points, enc], 1),
            params[1].clone(),
            &self.spec,
        )
    }
}

/// NeuS's 8×256 SDF MLP (skip connection at layer 4), in two fused halves.
pub struct NeusMlpSdf {
    frequencies: usize,
    window: Vec<f32>,
    first: Arc<MlpSpec>,
    second: Arc<MlpSpec>,
    init_radius: f32,
}

impl NeusMlpSdf {
    pub fn new(cfg: &FieldConfig) -> Self {
        let d_in = 3 + 6 * cfg.neus_frequencies;
        let first = Arc::new(MlpSpec {
            dims: vec![d_in, 256, 256, 256, 256 - d_in],
            hidden: Activation::Softplus(100.0),
            output: Activation::Softplus(100.0),
        });
        let second = Arc::new(MlpSpec {
            dims: vec![256, 256, 256, 256, 257],
            hidden: Activation::Softplus(100.0),
            output: Activation::None,
        });
        Self {
            frequencies: cfg.neus_frequencies,
            window: vec![1.0; cfg.neus_frequencies],
            first,
            second,
            init_radius: cfg.init_radius,
        }
    }

    /// `[x, w_k sin(2^k x), w_k cos(2^k x)]` (NeuS's embedder, BARF's window weights `w_k`).
    fn encode(&self, x: Tensor<2>) -> Tensor<2> {
        let mut parts = vec![x.clone()];
        for k in 0..self.frequencies {
            let f = (1u64 << k) as f32;
            let w = self.window[k];
            let xf = x.clone() * f;
            parts.push(xf.clone().sin() * w);
            parts.push(xf.cos() * w);
        }
        Tensor::cat(parts, 1)
    }
}

impl SdfNetwork for NeusMlpSdf {
    fn feature_dim(&self) -> usize {
        256
    }

    fn param_shapes(&self) -> Vec<(&'static str, usize)> {
        vec![
            ("sdf_mlp_a", self.first.num_params()),
            ("sdf_mlp_b", self.second.num_params()),
        ]
    }

    /// NeuS's geometric initialisation: hidden layers `N(0, 2/width)`, positional-encoding
    /// inputs of the first layer and of the skip layer zero, last layer `√π/√width` and bias
    /// `−radius`; the skip concatenation is divided by √2 as in NeuS.
    fn init_params(&self, seed: u64) -> Vec<Vec<f32>> {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut a = init_geometric(&self.first, 3, self.init_radius, seed);
        // `init_geometric` treats the last layer of the first half as an output layer; redo it
        // as a hidden layer.
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed.wrapping_add(7));
        let k = self.first.dims.len() - 2;
        let (din, dout) = (self.first.dims[k], self.first.dims[k + 1]);
        let off = self.first.layer_offset(k);
        let n = Normal::new(0.0f32, (2.0f32).sqrt() / (dout as f32).sqrt()).unwrap();
        for v in &mut a[off..off + din * dout] {
            *v = n.sample(&mut rng);
        }
        a[off + din * dout..off + din * dout + dout].fill(0.0);
        // Second half: its input is [h (256 − d_in), x (3), PE]; zero the PE rows of layer 0.
        let mut b = init_geometric(&self.second, 256, self.init_radius, seed.wrapping_add(3));
        let d_in = self.first.dims[0];
        let h = 256 - d_in;
        let dout0 = self.second.dims[1];
        for i in h + 3..256 {
            b[i * dout0..(i + 1) * dout0].fill(0.0);
        }
        vec![a, b]
    }

    fn set_progress(&mut self, alpha: f64) {
        self.window = level_window(
            self.frequencies,
            alpha.clamp(0.0, 1.0) * self.frequencies as f64,
            0,
        );
    }

    fn fd_step(&self) -> f32 {
        // NeuS differentiates analytically; 10⁻³ of the unit sphere is far below its detail.
        1e-3
    }

    fn forward(&self, params: &[Tensor<1>], points: Tensor<2>) -> Tensor<2> {
        let x = self.encode(points);
        let h = mlp(x.clone(), params[0].clone(), &self.first);
        let skip = Tensor::cat(vec![h, x], 1) * std::f32::consts::FRAC_1_SQRT_2;
        mlp(skip, params[1].clone(), &self.second)
    }
}

/// The SDF `[N, 1]`, features `[N, F]` and the finite-difference gradient `[N, 3]` of a network
/// at `points`, evaluating all stencil taps in one batch.
pub fn sdf_and_gradient(
    net: &dyn SdfNetwork,
    params: &[Tensor<1>],
    points: Tensor<2>,
    scheme: FdScheme,
    step: f32,
) -> (Tensor<2>, Tensor<2>, Tensor<2>) {
    let [n, _] = points.dims();
    let device = points.device();
    let offsets: Vec<[f32; 3]> = match scheme {
        FdScheme::Tetrahedron => vec![
            [1.0, -1.0, -1.0],
            [-1.0, -1.0, 1.0],
            [-1.0, 1.0, -1.0],
            [1.0, 1.0, 1.0],
        ],
        FdScheme::Central => vec![
            [1.0, 0.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
        ],
    };
    let mut taps = vec![points.clone()];
    for o in &offsets {
        let d = Tensor::<2>::from_data(
            TensorData::new(vec![o[0] * step, o[1] * step, o[2] * step], [1, 3]),
            &device,
        );
        taps.push(points.clone() + d);
    }
    let out = net.forward(params, Tensor::cat(taps, 0));
    let width = out.dims()[1];
    let center = out.clone().slice([0..n, 0..width]);
    let sdf = center.clone().slice([0..n, 0..1]);
    let features = center.slice([0..n, 1..width]);
    let tap = |k: usize| out.clone().slice([(k + 1) * n..(k + 2) * n, 0..1]);
    let grad = match scheme {
        FdScheme::Tetrahedron => {
            let mut g: Option<Tensor<2>> = None;
            for (k, o) in offsets.iter().enumerate() {
                let v = Tensor::<2>::from_data(TensorData::new(o.to_vec(), [1, 3]), &device);
                let term = tap(k) * v;
                g = Some(match g {
                    None => term,
                    Some(acc) => acc + term,
                });
            }
            g.unwrap() / (4.0 * step)
        }
        FdScheme::Central => Tensor::cat(
            (0..3)
                .map(|a| (tap(2 * a) - tap(2 * a + 1)) / (2.0 * step))
                .collect(),
            1,
        ),
    };
    (sdf, features, grad)
}

/// Real spherical harmonics up to degree 3 (16 values) of unit directions `[N, 3]`, the
/// view-direction encoding of Instant NGP / Instant-NSR.
pub fn sh_encode(dirs: Tensor<2>) -> Tensor<2> {
    let [n, _] = dirs.dims();
    let c = |i: usize| dirs.clone().slice([0..n, i..i + 1]);
    let (x, y, z) = (c(0), c(1), c(2));
    let (xx, yy, zz) = (
        x.clone() * x.clone(),
        y.clone() * y.clone(),
        z.clone() * z.clone(),
    );
    let (xy, yz, xz) = (
        x.clone() * y.clone(),
        y.clone() * z.clone(),
        x.clone() * z.clone(),
    );
    let ones = x.clone().zeros_like() + 0.282_094_8;
    Tensor::cat(
        vec![
            ones,
            y.clone() * -0.488_602_52,
            z.clone() * 0.488_602_52,
            x.clone() * -0.488_602_52,
            xy.clone() * 1.092_548_4,
            yz.clone() * -1.092_548_4,
            zz.clone() * 0.946_174_7 - 0.315_391_57,
            xz.clone() * -1.092_548_4,
            (xx.clone() - yy.clone()) * 0.546_274_2,
            y.clone() * (xx.clone() * -3.0 + yy.clone()) * 0.590_043_6,
            xy * z.clone() * 2.890_611_4,
            y.clone() * (zz.clone() * -5.0 + 1.0) * 0.457_045_8,
            z.clone() * (zz.clone() * 5.0 - 3.0) * 0.373_176_33,
            x.clone() * (zz * -5.0 + 1.0) * 0.457_045_8,
            z * (xx.clone() - yy.clone()) * 1.445_305_7,
            x * (xx * -1.0 + yy * 3.0) * 0.590_043_6,
        ],
        1,
    )
}

/// The colour network `c(P, n, d, f)`: `[P, n, SH(d), f]` → MLP (ReLU) → sigmoid RGB.
pub struct ColorNetwork {
    pub spec: Arc<MlpSpec>,
}

impl ColorNetwork {
    pub fn new(feature_dim: usize, hidden: &[usize]) -> Self {
        let mut dims = vec![3 + 3 + 16 + feature_dim];
        dims.extend(hidden);
        dims.push(3);
        Self {
            spec: Arc::new(MlpSpec {
                dims,
                hidden: Activation::Relu,
                output: Activation::Sigmoid,
            }),
        }
    }

    pub fn init_params(&self, seed: u64) -> Vec<f32> {
        init_default(&self.spec, seed)
    }

    pub fn forward(
        &self,
        params: Tensor<1>,
        points: Tensor<2>,
        normals: Tensor<2>,
        dirs: Tensor<2>,
        features: Tensor<2>,
    ) -> Tensor<2> {
        let x = Tensor::cat(vec![points, normals, sh_encode(dirs), features], 1);
        mlp(x, params, &self.spec)
    }
}

/// The geometry network, the colour network and the sharpness, with their configuration.
pub struct Field {
    pub config: FieldConfig,
    pub sdf: Box<dyn SdfNetwork>,
    pub color: ColorNetwork,
}

/// Index of each parameter vector in [`Field::param_shapes`].
pub struct ParamIndex {
    /// The SDF network's vectors.
    pub sdf: std::ops::Range<usize>,
    pub color: usize,
    pub variance: usize,
}

impl Field {
    pub fn new(config: FieldConfig) -> Result<Self, String> {
        let sdf: Box<dyn SdfNetwork> = match config.encoder {
            EncoderKind::HashGrid => Box::new(HashGridSdf::new(&config)?),
            EncoderKind::NeusMlp => Box::new(NeusMlpSdf::new(&config)),
        };
        let color = ColorNetwork::new(
            sdf.feature_dim(),
            &match config.encoder {
                EncoderKind::HashGrid => config.color_hidden.clone(),
                EncoderKind::NeusMlp => vec![256; 4],
            },
        );
        Ok(Self { config, sdf, color })
    }

    /// Names and sizes of all parameter vectors: the SDF network's, the colour network's, and
    /// the variance.
    pub fn param_shapes(&self) -> Vec<(&'static str, usize)> {
        let mut v = self.sdf.param_shapes();
        v.push(("color_mlp", self.color.spec.num_params()));
        v.push(("variance", 1));
        v
    }

    pub fn index(&self) -> ParamIndex {
        let n = self.sdf.param_shapes().len();
        ParamIndex {
            sdf: 0..n,
            color: n,
            variance: n + 1,
        }
    }

    pub fn init_params(&self, seed: u64) -> Vec<Vec<f32>> {
        let mut v = self.sdf.init_params(seed);
        v.push(self.color.init_params(seed.wrapping_add(100)));
        v.push(vec![self.config.init_variance]);
        v
    }

    /// SDF values only (no gradient), on host parameters, for sampling and mesh extraction.
    pub fn sdf_host(&self, params: &[Vec<f32>], points: &[f32]) -> crate::error::Result<Vec<f32>> {
        let device = Device::flex();
        let idx = self.index();
        let tensors: Vec<Tensor<1>> = params[idx.sdf.clone()]
            .iter()
            .map(|p| Tensor::from_data(TensorData::new(p.clone(), [p.len()]), &device))
            .collect();
        let n = points.len() / 3;
        let pts = Tensor::<2>::from_data(TensorData::new(points.to_vec(), [n, 3]), &device);
        let out = self.sdf.forward(&tensors, pts);
        Ok(fewview_optim::f32_values(
            out.slice([0..n, 0..1]),
            "SDF values",
        )?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn host_params(p: &[Vec<f32>], device: &Device) -> Vec<Tensor<1>> {
        p.iter()
            .map(|v| Tensor::from_data(TensorData::new(v.clone(), [v.len()]), device))
            .collect()
    }

    #[test]
    fn both_encoders_start_near_a_sphere_with_unit_gradient() {
        for encoder in [EncoderKind::HashGrid, EncoderKind::NeusMlp] {
            let field = Field::new(FieldConfig {
                encoder,
                ..FieldConfig::default()
            })
            .unwrap();
            let params = field.init_params(3);
            let pts: Vec<f32> = (0..64)
                .flat_map(|i| {
                    let t = i as f32 * 0.37;
                    let r = 0.35 + 0.5 * (i as f32 / 64.0);
                    [r * t.cos() * 0.8, r * t.sin() * 0.8, r * 0.6]
                })
                .collect();
            let sdf = field.sdf_host(&params, &pts).unwrap();
            for (k, s) in sdf.iter().enumerate() {
                let p = &pts[k * 3..k * 3 + 3];
                let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                // Geometric initialisation is a random-feature estimate of ‖x‖ (see the mlp
                // tests): ~18 % spread with 64 hidden units, ~9 % with NeuS's 256.
                assert!(
                    (s - (r - 0.5)).abs() < 0.35 * r,
                    "{encoder:?}: {s} vs {}",
                    r - 0.5
                );
            }
            // The finite-difference gradient of ‖x‖ − r is the radial unit vector.
            let device = Device::flex();
            let t = host_params(&params, &device);
            let n = pts.len() / 3;
            let pt = Tensor::<2>::from_data(TensorData::new(pts.clone(), [n, 3]), &device);
            let idx = field.index();
            for scheme in [FdScheme::Tetrahedron, FdScheme::Central] {
                let (_, _, g) = sdf_and_gradient(
                    field.sdf.as_ref(),
                    &t[idx.sdf.clone()],
                    pt.clone(),
                    scheme,
                    1e-2,
                );
                let g = g.into_data().try_to_vec::<f32>().unwrap();
                for k in 0..n {
                    let gk = &g[3 * k..3 * k + 3];
                    let p = &pts[3 * k..3 * k + 3];
                    let norm = (gk[0].powi(2) + gk[1].powi(2) + gk[2].powi(2)).sqrt();
                    let r = (p[0].powi(2) + p[1].powi(2) + p[2].powi(2)).sqrt();
                    let cos = (gk[0] * p[0] + gk[1] * p[1] + gk[2] * p[2]) / (norm * r);
                    assert!(
                        (0.6..1.5).contains(&norm),
                        "{encoder:?} {scheme:?}: |∇s| = {norm}"
                    );
                    assert!(
                        cos > 0.8,
                        "{encoder:?} {scheme:?}: ∇s is not radial ({cos})"
                    );
                }
            }
        }
    }

    #[test]
    fn finite_differences_are_exact_for_a_quadratic() {
        // A network that computes x² + 2y − z: hash grid disabled (zero table), SDF MLP replaced
        // through the trait by a closure-like test network.
        struct Quadratic;
        impl SdfNetwork for Quadratic {
            fn feature_dim(&self) -> usize {
                0
            }
            fn param_shapes(&self) -> Vec<(&'static str, usize)> {
                vec![]
            }
            fn init_params(&self, _: u64) -> Vec<Vec<f32>> {
                vec![]
            }
            fn set_progress(&mut self, _: f64) {}
            fn fd_step(&self) -> f32 {
                0.1
            }
            fn forward(&self, _: &[Tensor<1>], p: Tensor<2>) -> Tensor<2> {
                let [n, _] = p.dims();
                let x = p.clone().slice([0..n, 0..1]);
                let y = p.clone().slice([0..n, 1..2]);
                let z = p.slice([0..n, 2..3]);
                x.clone() * x + y * 2.0 - z
            }
        }
        let device = Device::flex();
        let pts = Tensor::<2>::from_data(TensorData::new(vec![0.3f32, -0.2, 0.5], [1, 3]), &device);
        for scheme in [FdScheme::Tetrahedron, FdScheme::Central] {
            let (s, _, g) = sdf_and_gradient(&Quadratic, &[], pts.clone(), scheme, 0.1);
            let g = g.into_data().try_to_vec::<f32>().unwrap();
            assert!(
                (s.into_data().try_to_vec::<f32>().unwrap()[0] - (0.09 + -0.4 - 0.5)).abs() < 1e-6
            );
            for (a, b) in g.iter().zip([0.6f32, 2.0, -1.0]) {
                assert!((a - b).abs() < 1e-5, "{scheme:?}: {g:?}");
            }
        }
    }

    #[test]
    fn sh_basis_is_orthonormal_on_the_sphere() {
        // Monte-Carlo-free check: a Fibonacci sphere quadrature of Y_i Y_j ≈ δ_ij / (4π) · 4π.
        let n = 4000;
        let dirs: Vec<f32> = (0..n)
            .flat_map(|i| {
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let r = (1.0 - z * z).sqrt();
                let phi = i as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
                [(r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32]
            })
            .collect();
        let device = Device::flex();
        let y = sh_encode(Tensor::<2>::from_data(
            TensorData::new(dirs, [n, 3]),
            &device,
        ))
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
        for i in 0..16 {
            for j in 0..16 {
                let s: f64 = (0..n)
                    .map(|k| y[k * 16 + i] as f64 * y[k * 16 + j] as f64)
                    .sum::<f64>()
                    * 4.0
                    * std::f64::consts::PI
                    / n as f64;
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((s - want).abs() < 0.01, "⟨Y{i}, Y{j}⟩ = {s}");
            }
        }
    }
}
