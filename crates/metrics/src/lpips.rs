//! LPIPS (Zhang et al. 2018, "The Unreasonable Effectiveness of Deep Features as a Perceptual
//! Metric", Eq. 1) in Burn, computed exactly as the reference `lpips` package (v0.1) and the
//! shift-tolerant ST-LPIPS package (`stlpips-pytorch`, Ghildyal & Liu 2022):
//!
//! ```text
//! x ∈ [0,1] → 2x − 1 → (· − shift) / scale                        (scaling layer)
//! f_l = backbone activations at the tapped ReLUs
//! f̂_l = f_l / (‖f_l‖₂ over channels + 1e-10)                     (channel-unit normalisation)
//! d = Σ_l mean_{h,w} Σ_c w_{l,c} (f̂⁰_{l,c,h,w} − f̂¹_{l,c,h,w})²   (linear heads, spatial mean, sum)
//! ```
//!
//! Backbones: AlexNet, VGG16 and SqueezeNet 1.1 (torchvision layouts, the `lpips` package's
//! taps) and the shift-tolerant AlexNet/VGG16 of ST-LPIPS (stride-1 convolutions followed by
//! reflect-padded [1 2 1]² blur-pool downsampling). Weights are read from standard PyTorch
//! `.pth` files (torchvision `features.N.*`, `lpips`-style `net.sliceK.N.*`, and
//! `linK.model.{0,1}.weight` heads), with no Python at run time. The ST-LPIPS AlexNet weights
//! (BSD-2-Clause, see `weights/`) are embedded in the binary as the offline default.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use burn::store::pytorch::PytorchReader;
use burn::tensor::module::{conv2d, max_pool2d};
use burn::tensor::ops::{ConvOptions, MaxPoolOptions, PadMode};
use burn::tensor::{Device, Tensor, TensorData, activation::relu};
use fewview_scene::Image;

use crate::error::{MetricsError, Result, check_same_shape};
use crate::temporal::PerceptualDistance;

/// The ST-LPIPS AlexNet weights (`alex_shift_tolerant.pth` from `stlpips-pytorch` 0.0.2).
const ST_ALEX_WEIGHTS: &[u8] = include_bytes!("../weights/stlpips_alex_shift_tolerant.pth");

/// Which backbone (and so which weight layout) an [`Lpips`] uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum LpipsNet {
    /// `lpips` v0.1 with torchvision AlexNet.
    Alex,
    /// `lpips` v0.1 with torchvision VGG16.
    Vgg,
    /// `lpips` v0.1 with torchvision SqueezeNet 1.1.
    Squeeze,
    /// ST-LPIPS shift-tolerant AlexNet (`stlpips-pytorch`, variant `shift_tolerant`).
    StAlex,
    /// ST-LPIPS shift-tolerant VGG16.
    StVgg,
}

impl LpipsNet {
    /// Name used in reports and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Self::Alex => "lpips-alex-v0.1",
            Self::Vgg => "lpips-vgg-v0.1",
            Self::Squeeze => "lpips-squeeze-v0.1",
            Self::StAlex => "stlpips-alex-shift_tolerant",
            Self::StVgg => "stlpips-vgg-shift_tolerant",
        }
    }

    /// Parses `alex`, `vgg`, `squeeze`, `st-alex`, `st-vgg` (or the full [`Self::name`]).
    pub fn parse(s: &str) -> Result<Self> {
        let all = [
            Self::Alex,
            Self::Vgg,
            Self::Squeeze,
            Self::StAlex,
            Self::StVgg,
        ];
        let short = ["alex", "vgg", "squeeze", "st-alex", "st-vgg"];
        all.iter()
            .zip(short)
            .find(|(n, sh)| s == *sh || s == n.name())
            .map(|(n, _)| *n)
            .ok_or_else(|| {
                MetricsError::invalid(format!(
                    "unknown LPIPS network {s:?} (one of {})",
                    short.join(", ")
                ))
            })
    }

    fn ops(self) -> Vec<Op> {
        use Op::*;
        let conv = |i: usize, stride: usize, pad: usize| Conv {
            key: format!("features.{i}"),
            stride,
            pad,
        };
        let c3 = |i: usize| conv(i, 1, 1);
        let pool = |k: usize, s: usize| MaxPool {
            kernel: k,
            stride: s,
            ceil: false,
        };
        match self {
            Self::Alex => vec![
                conv(0, 4, 2),
                Relu,
                Tap,
                pool(3, 2),
                conv(3, 1, 2),
                Relu,
                Tap,
                pool(3, 2),
                c3(6),
                Relu,
                Tap,
                c3(8),
                Relu,
                Tap,
                c3(10),
                Relu,
                Tap,
            ],
            Self::StAlex => vec![
                conv(0, 1, 2),
                Blur,
                Relu,
                Tap,
                pool(3, 1),
                Blur,
                conv(5, 1, 2),
                Relu,
                Tap,
                pool(3, 1),
                Blur,
                c3(9),
                Relu,
                Tap,
                c3(11),
                Relu,
                Tap,
                c3(13),
                Relu,
                Tap,
            ],
            Self::Vgg => vec![
                c3(0),
                Relu,
                c3(2),
                Relu,
                Tap,
                pool(2, 2),
                c3(5),
                Relu,
                c3(7),
                Relu,
                Tap,
                pool(2, 2),
                c3(10),
                Relu,
                c3(12),
                Relu,
                c3(14),
                Relu,
                Tap,
                pool(2, 2),
                c3(17),
                Relu,
                c3(19),
                Relu,
                c3(21),
                Relu,
                Tap,
                pool(2, 2),
                c3(24),
                Relu,
                c3(26),
                Relu,
                c3(28),
                Relu,
                Tap,
            ],
            Self::StVgg => vec![
                c3(0),
                Relu,
                c3(2),
                Relu,
                Tap,
                pool(2, 1),
                Blur,
                c3(6),
                Relu,
                c3(8),
                Relu,
                Tap,
                pool(2, 1),
                Blur,
                c3(12),
                Relu,
                c3(14),
                Relu,
                c3(16),
                Relu,
                Tap,
                pool(2, 1),
                Blur,
                c3(20),
                Relu,
                c3(22),
                Relu,
                c3(24),
                Relu,
                Tap,
                pool(2, 1),
                Blur,
                c3(28),
                Relu,
                c3(30),
                Relu,
                c3(32),
                Relu,
                Tap,
            ],
            Self::Squeeze => {
                let ceil = MaxPool {
                    kernel: 3,
                    stride: 2,
                    ceil: true,
                };
                let fire = |i: usize| Fire {
                    key: format!("features.{i}"),
                };
                vec![
                    conv(0, 2, 0),
                    Relu,
                    Tap,
                    ceil.clone(),
                    fire(3),
                    fire(4),
                    Tap,
                    ceil.clone(),
                    fire(6),
                    fire(7),
                    Tap,
                    ceil,
                    fire(9),
                    Tap,
                    fire(10),
                    Tap,
                    fire(11),
                    Tap,
                    fire(12),
                    Tap,
                ]
            }
        }
    }
}

/// One step of a backbone.
#[derive(Clone, Debug)]
enum Op {
    Conv {
        key: String,
        stride: usize,
        pad: usize,
    },
    Relu,
    MaxPool {
        kernel: usize,
        stride: usize,
        ceil: bool,
    },
    /// ST-LPIPS `Downsample(filt_size=3, stride=2, pad_more=True)`: reflection padding of 2 on
    /// every side, then the depthwise [1 2 1]ᵀ[1 2 1]/16 filter with stride 2.
    Blur,
    /// SqueezeNet fire module: squeeze 1×1 + ReLU, then [expand 1×1 + ReLU, expand 3×3 + ReLU].
    Fire {
        key: String,
    },
    /// The current activation is one of the compared feature maps.
    Tap,
}

impl Op {
    /// Keys (`features.N[.sub]`) of the convolutions this step needs.
    fn conv_keys(&self) -> Vec<String> {
        match self {
            Op::Conv { key, .. } => vec![key.clone()],
            Op::Fire { key } => ["expand1x1", "expand3x3", "squeeze"]
                .iter()
                .map(|s| format!("{key}.{s}"))
                .collect(),
            _ => vec![],
        }
    }
}

/// How weight files are matched to the backbone.
#[derive(Clone, Copy, Debug, Default)]
pub struct LoadOptions {
    /// Match convolutions by their order in the file rather than by layer index (shapes are
    /// still checked). Used to put one network's trained convolutions into another layout with
    /// the same convolution shapes, e.g. the ST-LPIPS AlexNet convolutions into the plain
    /// `lpips` AlexNet to test that code path when torchvision's ImageNet weights are absent.
    pub match_convs_by_order: bool,
}

struct RawTensor {
    shape: Vec<usize>,
    data: Vec<f32>,
}

/// The channel-normalised feature maps of one image (one `[1, C, h, w]` tensor per tap).
#[derive(Clone)]
pub struct LpipsFeatures {
    width: usize,
    height: usize,
    maps: Vec<Tensor<4>>,
}

/// A loaded LPIPS network on a Burn device.
pub struct Lpips {
    net: LpipsNet,
    device: Device,
    ops: Vec<Op>,
    convs: BTreeMap<String, (Tensor<4>, Option<Tensor<1>>)>,
    lins: Vec<Tensor<4>>,
    blur: Vec<(usize, Tensor<4>)>,
    source: String,
}

impl std::fmt::Debug for Lpips {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Lpips")
            .field("net", &self.net)
            .field("source", &self.source)
            .finish()
    }
}

const SHIFT: [f32; 3] = [-0.030, -0.088, -0.188];
const SCALE: [f32; 3] = [0.458, 0.448, 0.450];

impl Lpips {
    /// The offline default: ST-LPIPS shift-tolerant AlexNet with the weights shipped in the
    /// binary, on the CPU (`flex`) backend.
    pub fn default_st_alex() -> Result<Self> {
        // The reader needs a file (tensor data lives outside the pickle): a temporary copy.
        let mut tmp =
            tempfile::NamedTempFile::new().map_err(|e| MetricsError::io("<temporary file>", e))?;
        std::io::Write::write_all(&mut tmp, ST_ALEX_WEIGHTS)
            .map_err(|e| MetricsError::io(tmp.path(), e))?;
        let tensors = read_pth(tmp.path())?;
        Self::from_tensors(
            LpipsNet::StAlex,
            tensors,
            LoadOptions::default(),
            Device::flex(),
            "embedded ST-LPIPS AlexNet (stlpips-pytorch 0.0.2)".into(),
        )
    }

    /// Loads `net` from one or more `.pth` files (e.g. a torchvision backbone and the `lpips`
    /// linear heads, or one full ST-LPIPS file), on the CPU (`flex`) backend.
    pub fn load(net: LpipsNet, files: &[PathBuf], options: LoadOptions) -> Result<Self> {
        Self::load_on(net, files, options, Device::flex())
    }

    /// [`Self::load`] on a given Burn device.
    pub fn load_on(
        net: LpipsNet,
        files: &[PathBuf],
        options: LoadOptions,
        device: Device,
    ) -> Result<Self> {
        if files.is_empty() {
            return Err(MetricsError::invalid("no LPIPS weight file given"));
        }
        let mut all = BTreeMap::new();
        for file in files {
            if !file.is_file() {
                return Err(MetricsError::io(
                    file,
                    std::io::Error::new(std::io::ErrorKind::NotFound, "no such file"),
                ));
            }
            all.extend(read_pth(file)?);
        }
        let source = files
            .iter()
            .map(|f| f.display().to_string())
            .collect::<Vec<_>>()
            .join(" + ");
        Self::from_tensors(net, all, options, device, source)
    }

    /// The network, for reports.
    pub fn net(&self) -> LpipsNet {
        self.net
    }

    /// Where the weights came from.
    pub fn source(&self) -> &str {
        &self.source
    }

    fn from_tensors(
        net: LpipsNet,
        raw: BTreeMap<String, RawTensor>,
        options: LoadOptions,
        device: Device,
        source: String,
    ) -> Result<Self> {
        let ops = net.ops();
        let err = |m: String| MetricsError::format(PathBuf::from(&source), m);
        // Convolution keys the network needs, in layer order, and those the files have.
        let mut wanted: Vec<String> = ops.iter().flat_map(Op::conv_keys).collect();
        wanted.sort_by_key(|k| layer_sort_key(k));
        let mut present: Vec<String> = raw
            .keys()
            .filter_map(|k| k.strip_suffix(".weight"))
            .filter(|k| k.starts_with("features."))
            .map(str::to_string)
            .collect();
        present.sort_by_key(|k| layer_sort_key(k));
        let mapping: Vec<(String, String)> = if options.match_convs_by_order {
            if present.len() != wanted.len() {
                return Err(err(format!(
                    "{} has {} convolutions, the file(s) {}",
                    net.name(),
                    wanted.len(),
                    present.len()
                )));
            }
            wanted
                .iter()
                .cloned()
                .zip(present.iter().cloned())
                .collect()
        } else {
            wanted.iter().map(|k| (k.clone(), k.clone())).collect()
        };
        let mut convs = BTreeMap::new();
        for (want, have) in mapping {
            let w = raw
                .get(&format!("{have}.weight"))
                .ok_or_else(|| err(format!("missing weight {have}.weight for {}", net.name())))?;
            if w.shape.len() != 4 {
                return Err(err(format!(
                    "{have}.weight has shape {:?}, expected 4 dimensions",
                    w.shape
                )));
            }
            let bias = match raw.get(&format!("{have}.bias")) {
                Some(b) if b.shape == [w.shape[0]] => Some(Tensor::<1>::from_data(
                    TensorData::new(b.data.clone(), [w.shape[0]]),
                    &device,
                )),
                Some(b) => {
                    return Err(err(format!(
                        "{have}.bias has shape {:?}, expected [{}]",
                        b.shape, w.shape[0]
                    )));
                }
                None => None,
            };
            let shape: [usize; 4] = [w.shape[0], w.shape[1], w.shape[2], w.shape[3]];
            convs.insert(
                want,
                (
                    Tensor::<4>::from_data(TensorData::new(w.data.clone(), shape), &device),
                    bias,
                ),
            );
        }
        let taps = ops.iter().filter(|o| matches!(o, Op::Tap)).count();
        let mut lins = Vec::with_capacity(taps);
        for l in 0..taps {
            let w = [
                format!("lin{l}.model.1.weight"),
                format!("lin{l}.model.0.weight"),
            ]
            .iter()
            .find_map(|k| raw.get(k))
            .ok_or_else(|| {
                err(format!(
                    "missing linear head lin{l}.model.1.weight (the lpips v0.1 weights file)"
                ))
            })?;
            let c = w.data.len();
            if w.shape.first() != Some(&1) {
                return Err(err(format!(
                    "lin{l} has shape {:?}, expected [1, C, 1, 1]",
                    w.shape
                )));
            }
            lins.push(Tensor::<4>::from_data(
                TensorData::new(w.data.clone(), [1, c, 1, 1]),
                &device,
            ));
        }
        let mut model = Self {
            net,
            device,
            ops,
            convs,
            lins,
            blur: Vec::new(),
            source,
        };
        model.check_channels()?;
        Ok(model)
    }

    /// Verifies that consecutive layers' channel counts chain, and prepares blur kernels.
    fn check_channels(&mut self) -> Result<()> {
        let mut channels = 3usize;
        let mut tap = 0;
        let err = |m: String| MetricsError::format(PathBuf::from(&self.source), m);
        for op in &self.ops {
            match op {
                Op::Conv { key, .. } => {
                    let dims = self.convs[key].0.dims();
                    if dims[1] != channels {
                        return Err(err(format!(
                            "{key} expects {} input channels, the previous layer gives {channels}",
                            dims[1]
                        )));
                    }
                    channels = dims[0];
                }
                Op::Fire { key } => {
                    let s = self.convs[&format!("{key}.squeeze")].0.dims();
                    let e1 = self.convs[&format!("{key}.expand1x1")].0.dims();
                    let e3 = self.convs[&format!("{key}.expand3x3")].0.dims();
                    if s[1] != channels || e1[1] != s[0] || e3[1] != s[0] {
                        return Err(err(format!("{key}: fire module channels do not chain")));
                    }
                    channels = e1[0] + e3[0];
                }
                Op::Blur => {
                    if !self.blur.iter().any(|(c, _)| *c == channels) {
                        let k = [1.0f32, 2.0, 1.0];
                        let mut data = Vec::with_capacity(channels * 9);
                        for _ in 0..channels {
                            for a in k {
                                for b in k {
                                    data.push(a * b / 16.0);
                                }
                            }
                        }
                        self.blur.push((
                            channels,
                            Tensor::<4>::from_data(
                                TensorData::new(data, [channels, 1, 3, 3]),
                                &self.device,
                            ),
                        ));
                    }
                }
                Op::Tap => {
                    let c = self.lins[tap].dims()[1];
                    if c != channels {
                        return Err(err(format!(
                            "lin{tap} has {c} channels, the tapped layer {channels}"
                        )));
                    }
                    tap += 1;
                }
                Op::Relu | Op::MaxPool { .. } => {}
            }
        }
        Ok(())
    }

    fn conv(&self, x: Tensor<4>, key: &str, stride: usize, pad: usize) -> Tensor<4> {
        let (w, b) = &self.convs[key];
        conv2d(
            x,
            w.clone(),
            b.clone(),
            ConvOptions::new([stride, stride], [pad, pad], [1, 1], 1),
        )
    }

    /// The tapped feature maps of a batch `[N, 3, H, W]` (already scaled).
    fn features(&self, mut x: Tensor<4>) -> Vec<Tensor<4>> {
        let mut taps = Vec::new();
        for op in &self.ops {
            x = match op {
                Op::Conv { key, stride, pad } => self.conv(x, key, *stride, *pad),
                Op::Relu => relu(x),
                Op::MaxPool {
                    kernel,
                    stride,
                    ceil,
                } => {
                    let mut o = MaxPoolOptions::new([*kernel, *kernel]);
                    o.stride = [*stride, *stride];
                    o.ceil_mode = *ceil;
                    max_pool2d(x, o)
                }
                Op::Blur => {
                    let c = x.dims()[1];
                    let k = &self
                        .blur
                        .iter()
                        .find(|(ch, _)| *ch == c)
                        .expect("prepared in check_channels")
                        .1;
                    let padded = x.pad([(0, 0), (0, 0), (2, 2), (2, 2)], PadMode::Reflect);
                    conv2d(
                        padded,
                        k.clone(),
                        None,
                        ConvOptions::new([2, 2], [0, 0], [1, 1], c),
                    )
                }
                Op::Fire { key } => {
                    let s = relu(self.conv(x, &format!("{key}.squeeze"), 1, 0));
                    let e1 = relu(self.conv(s.clone(), &format!("{key}.expand1x1"), 1, 0));
                    let e3 = relu(self.conv(s, &format!("{key}.expand3x3"), 1, 1));
                    Tensor::cat(vec![e1, e3], 1)
                }
                Op::Tap => {
                    taps.push(x.clone());
                    x
                }
            };
        }
        taps
    }

    /// LPIPS distance between two images of the same size (RGB, or grey replicated to RGB),
    /// values in `[0, 1]`.
    pub fn distance(&self, a: &Image, b: &Image) -> Result<f64> {
        check_same_shape(a, b)?;
        let (fa, fb) = (self.features_of(a)?, self.features_of(b)?);
        self.distance_between(&fa, &fb)
    }

    /// The smallest width and height this network scores: its strided layers need that many
    /// pixels to leave a feature map at every stage.
    pub fn min_side(&self) -> usize {
        match self.net {
            LpipsNet::Alex | LpipsNet::StAlex => 32,
            LpipsNet::Squeeze => 24,
            LpipsNet::Vgg | LpipsNet::StVgg => 16,
        }
    }

    /// The channel-normalised feature maps of one image, to compare it with several others
    /// without recomputing the backbone ([`Self::distance_between`]).
    pub fn features_of(&self, img: &Image) -> Result<LpipsFeatures> {
        if !img.is_finite() {
            return Err(MetricsError::invalid(
                "image contains NaN or infinite values",
            ));
        }
        let min = self.min_side();
        if img.width < min || img.height < min {
            return Err(MetricsError::invalid(format!(
                "{} needs images of at least {min}x{min} pixels, got {}x{}",
                self.net.name(),
                img.width,
                img.height
            )));
        }
        let maps = self
            .features(self.to_input(img)?)
            .into_iter()
            .map(|f| {
                let norm = f.clone().powi_scalar(2).sum_dim(1).sqrt().add_scalar(1e-10);
                f / norm
            })
            .collect();
        Ok(LpipsFeatures {
            width: img.width,
            height: img.height,
            maps,
        })
    }

    /// LPIPS between two images' features (from [`Self::features_of`] of this network).
    pub fn distance_between(&self, a: &LpipsFeatures, b: &LpipsFeatures) -> Result<f64> {
        if (a.width, a.height) != (b.width, b.height)
            || a.maps.len() != self.lins.len()
            || b.maps.len() != self.lins.len()
        {
            return Err(MetricsError::ShapeMismatch(format!(
                "LPIPS features of {}x{} and {}x{} images",
                a.width, a.height, b.width, b.height
            )));
        }
        let mut total: Option<Tensor<1>> = None;
        for ((f0, f1), lin) in a.maps.iter().zip(&b.maps).zip(&self.lins) {
            let d = (f0.clone() - f1.clone()).powi_scalar(2);
            let layer = (d * lin.clone()).sum_dim(1).mean();
            total = Some(match total {
                Some(t) => t + layer,
                None => layer,
            });
        }
        let value: Vec<f32> = total
            .expect("every network has taps")
            .into_data()
            .try_to_vec()
            .map_err(|e| MetricsError::invalid(format!("LPIPS readback: {e:?}")))?;
        Ok(value[0] as f64)
    }

    /// `[1, 3, H, W]`: `(2x − 1 − shift) / scale`.
    fn to_input(&self, img: &Image) -> Result<Tensor<4>> {
        let (w, h) = (img.width, img.height);
        let channel = |c: usize| -> Vec<f32> {
            let src = if img.channels == 1 { 0 } else { c };
            img.data
                .chunks_exact(img.channels)
                .map(|p| (2.0 * p[src] - 1.0 - SHIFT[c]) / SCALE[c])
                .collect()
        };
        if img.channels != 3 && img.channels != 1 {
            return Err(MetricsError::invalid(format!(
                "LPIPS needs RGB or grey images, got {} channels (composite RGBA first)",
                img.channels
            )));
        }
        let mut data = Vec::with_capacity(3 * w * h);
        for c in 0..3 {
            data.extend(channel(c));
        }
        Ok(Tensor::<4>::from_data(
            TensorData::new(data, [1, 3, h, w]),
            &self.device,
        ))
    }
}

impl PerceptualDistance for Lpips {
    fn name(&self) -> String {
        self.net.name().to_string()
    }
    fn distance(&self, a: &Image, b: &Image) -> Result<f64> {
        Lpips::distance(self, a, b)
    }
    /// Runs the backbone once per frame (2T evaluations instead of about 6T).
    fn sequence_distances(
        &self,
        output: &[Image],
        ground_truth: &[Image],
    ) -> Result<(Vec<f64>, Vec<f64>)> {
        let fo: Vec<LpipsFeatures> = output
            .iter()
            .map(|i| self.features_of(i))
            .collect::<Result<_>>()?;
        let fg: Vec<LpipsFeatures> = ground_truth
            .iter()
            .map(|i| self.features_of(i))
            .collect::<Result<_>>()?;
        let per_frame = fo
            .iter()
            .zip(&fg)
            .map(|(o, g)| self.distance_between(o, g))
            .collect::<Result<_>>()?;
        let tlp = (1..fo.len())
            .map(|t| {
                Ok(100.0
                    * (self.distance_between(&fg[t - 1], &fg[t])?
                        - self.distance_between(&fo[t - 1], &fo[t])?)
                    .abs())
            })
            .collect::<Result<_>>()?;
        Ok((per_frame, tlp))
    }
}

/// `features.N[.sub]` sorts by `N`, then `sub`.
fn layer_sort_key(key: &str) -> (usize, String) {
    let rest = key.strip_prefix("features.").unwrap_or(key);
    let (idx, sub) = rest.split_once('.').unwrap_or((rest, ""));
    (idx.parse().unwrap_or(usize::MAX), sub.to_string())
}

/// Reads every tensor of a `.pth` file as `f32`, with names normalised: a leading `module.` is
/// dropped and `net.sliceK.N.*` (lpips/ST-LPIPS full networks) becomes `features.N.*`
/// (torchvision), since the slices keep the torchvision layer indices.
fn read_pth(path: &Path) -> Result<BTreeMap<String, RawTensor>> {
    let pth = PytorchReader::new(path)
        .map_err(|e| MetricsError::format(path, format!("not a readable PyTorch file: {e}")))?;
    let mut out = BTreeMap::new();
    for (name, t) in pth.into_tensors() {
        let name = name.strip_prefix("module.").unwrap_or(&name).to_string();
        let name = match name.strip_prefix("net.slice") {
            Some(rest) => match rest.split_once('.') {
                Some((_, layer)) => format!("features.{layer}"),
                None => name,
            },
            None => name,
        };
        let bytes = t
            .read()
            .map_err(|e| MetricsError::format(path, format!("tensor {name}: {e}")))?;
        use burn::store::pytorch_reader::DType as D;
        let data: Vec<f32> = match t.dtype() {
            D::F32 => bytes
                .chunks_exact(4)
                .map(|b| f32::from_ne_bytes([b[0], b[1], b[2], b[3]]))
                .collect(),
            D::F64 => bytes
                .chunks_exact(8)
                .map(|b| f64::from_ne_bytes(b.try_into().expect("8 bytes")) as f32)
                .collect(),
            D::F16 => bytes
                .chunks_exact(2)
                .map(|b| half::f16::from_ne_bytes([b[0], b[1]]).to_f32())
                .collect(),
            D::BF16 => bytes
                .chunks_exact(2)
                .map(|b| half::bf16::from_ne_bytes([b[0], b[1]]).to_f32())
                .collect(),
            _ => continue, // integer buffers (e.g. num_batches_tracked) are not weights
        };
        if data.iter().any(|v| !v.is_finite()) {
            return Err(MetricsError::format(
                path,
                format!("tensor {name} contains NaN or infinite values"),
            ));
        }
        out.insert(
            name,
            RawTensor {
                shape: t.shape().to_vec(),
                data,
            },
        );
    }
    Ok(out)
}
