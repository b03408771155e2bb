//! Adam on the network's weights, one target view per step, with checkpoints a run resumes
//! from bit for bit.

use std::collections::HashMap;
use std::path::Path;

use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::tensor::{Bytes, Device};
use fewview_geom::Mesh;
use fewview_scene::sealed;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};

use super::forward::{DepthBracket, ForwardSettings, predict, prediction_gaussians};
use super::loss::{LossParts, LossWeights, training_loss};
use super::prepare::{
    DepthSettings, Framing, InputViews, PreparedFrame, frame_hull, hull_config, prepare_frame,
};
use crate::depth::{DepthInput, StereoSettings};
use crate::error::{HumanError, Result};
use crate::gaussians::{GaussianOptions, render_gaussians};
use crate::net::{NetConfig, PoseGaussianNet, PoseMapConfig, Variant, checkpoint};

/// The two network presets (NetConfig::paper and NetConfig::cpu).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum Preset {
    /// 512×512 inputs, widths 32/64/96/128: for a GPU.
    Paper,
    /// 128×256 crops, widths 16/32/48/64: thousands of steps in two hours on two cores.
    Cpu,
}

impl Preset {
    pub fn net(self, variant: Variant, pose_channels: usize) -> NetConfig {
        let mut c = match self {
            Preset::Paper => NetConfig::paper(variant),
            Preset::Cpu => NetConfig::cpu(variant),
        };
        c.pose_channels = pose_channels;
        c
    }
}

/// Everything that shapes a training run. Stored in its checkpoints: a resume must match.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig {
    pub preset: Preset,
    pub variant: Variant,
    pub iterations: usize,
    /// Adam's step size (GPS-Gaussian's 2·10⁻⁴).
    pub learning_rate: f64,
    pub seed: u64,
    /// Source views per target (the PoseGaussian paper: the 2 nearest).
    pub source_views: usize,
    pub loss: LossWeights,
    /// The depth the network reads (runs stored before the choice existed read the hull's).
    #[serde(default = "DepthInput::before_choice")]
    pub depth: DepthInput,
    /// How stereo depth is searched, when it is the input.
    #[serde(default)]
    pub stereo: StereoSettings,
    /// Where the depth head's output lands around the input depth ([`DepthInput::bracket`]).
    pub bracket: DepthBracket,
    /// `false` trains the per-frame baseline (no pose information).
    pub use_pose: bool,
    /// Edge of the visual hull's voxels (metres).
    pub hull_voxel: f64,
    /// Margin around the person's box in the crops (fraction of its size).
    pub crop_margin: f64,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            preset: Preset::Cpu,
            variant: Variant::Normalized,
            iterations: 2000,
            learning_rate: 2e-4,
            seed: 0,
            source_views: 2,
            loss: LossWeights::default(),
            depth: DepthInput::default(),
            stereo: StereoSettings::default(),
            bracket: DepthInput::default().bracket(),
            use_pose: true,
            hull_voxel: 0.01,
            crop_margin: 0.1,
        }
    }
}

impl TrainConfig {
    /// The input depth's settings.
    pub fn depth_settings(&self) -> DepthSettings {
        DepthSettings {
            input: self.depth,
            stereo: self.stereo.clone(),
        }
    }
}

/// What one step did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepStats {
    pub iteration: usize,
    pub frame: usize,
    pub target: usize,
    pub sources: Vec<usize>,
    pub loss: LossParts,
    /// Wall time of the step, seconds (preparing a frame seen for the first time included).
    pub seconds: f64,
}

/// The state a checkpoint stores besides the weights and Adam's moments.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct State {
    config: TrainConfig,
    framing: Framing,
    parents: Vec<i64>,
    iteration: usize,
}

const STATE_MAGIC: &[u8] = b"FVHTRN1\0";

/// A training run over `inputs` (the training view of a split).
pub struct Trainer<'a> {
    inputs: &'a dyn InputViews,
    frames: Vec<usize>,
    config: TrainConfig,
    net: PoseGaussianNet,
    optimizer: ModuleOptimizer,
    framing: Framing,
    parents: Vec<i64>,
    hulls: HashMap<usize, Mesh>,
    prepared: HashMap<usize, PreparedFrame>,
    iteration: usize,
    device: Device,
}

impl<'a> Trainer<'a> {
    /// A fresh run: the visual hulls of every training frame, the framing they imply, a
    /// network initialised from the seed.
    pub fn new(
        inputs: &'a dyn InputViews,
        frames: std::ops::Range<usize>,
        parents: &[i64],
        config: TrainConfig,
        device: Device,
    ) -> Result<Self> {
        check_depth_input(inputs, frames.start, config.depth)?;
        config.bracket.check()?;
        config.stereo.check()?;
        let hulls = carve_all(inputs, frames.clone(), config.hull_voxel)?;
        let net_config = net_config(&config, parents);
        let size = [net_config.input[1], net_config.input[0]];
        let cameras = inputs
            .input_cameras()
            .iter()
            .map(|&c| inputs.camera(c).cloned())
            .collect::<Result<Vec<_>>>()?;
        let meshes: Vec<Mesh> = hulls.values().cloned().collect();
        let framing = Framing::of_hulls(&meshes, &cameras, size, config.crop_margin)?;
        // The parameters are drawn on the CPU whatever the device, so that a seed gives the same
        // network everywhere (each backend has its own generator), then moved. Seeds the
        // generator and holds it until they are drawn: Burn draws parameters lazily, on first
        // use; reading them now ties them to the seed rather than to whatever else uses the
        // generator first.
        let net = {
            let _generator = crate::net::seed::seeded(config.seed);
            let cpu = Device::flex().autodiff();
            let draw_on = if device == cpu { &device } else { &cpu };
            draw_on.seed(config.seed);
            let net = PoseGaussianNet::new(&net_config, draw_on)?;
            let net = net.clone().load_record(net.into_record());
            if device == cpu {
                net
            } else {
                net.fork(&device)
            }
        };
        Ok(Self {
            inputs,
            frames: frames.collect(),
            optimizer: AdamConfig::new().init(),
            config,
            net,
            framing,
            parents: parents.to_vec(),
            hulls,
            prepared: HashMap::new(),
            iteration: 0,
            device,
        })
    }

    /// Continues the run checkpointed in `dir`; an error if `config` differs from the stored one
    /// in anything but the iteration count.
    pub fn resume(
        inputs: &'a dyn InputViews,
        frames: std::ops::Range<usize>,
        dir: &Path,
        config: TrainConfig,
        device: Device,
    ) -> Result<Self> {
        let state = read_state(dir)?;
        let same = TrainConfig {
            iterations: state.config.iterations,
            ..config.clone()
        };
        if same != state.config {
            return Err(HumanError::invalid(
                dir.join("state.bin"),
                "a checkpoint of a run with other settings",
            ));
        }
        let net = checkpoint::load(
            &dir.join("network.fvh"),
            &net_config(&config, &state.parents),
            &device,
        )?;
        let bytes = std::fs::read(dir.join("optimizer.bin"))
            .map_err(|e| HumanError::io(dir.join("optimizer.bin"), e))?;
        let optimizer = AdamConfig::new()
            .init()
            .from_bytes(Bytes::from_bytes_vec(bytes))
            .map_err(|e| {
                HumanError::format(
                    dir.join("optimizer.bin"),
                    format!("unreadable optimizer state: {e}"),
                )
            })?;
        Ok(Self {
            inputs,
            frames: frames.collect(),
            config,
            net,
            optimizer,
            framing: state.framing,
            parents: state.parents,
            hulls: HashMap::new(),
            prepared: HashMap::new(),
            iteration: state.iteration,
            device,
        })
    }

    pub fn iteration(&self) -> usize {
        self.iteration
    }
    pub fn config(&self) -> &TrainConfig {
        &self.config
    }
    pub fn framing(&self) -> &Framing {
        &self.framing
    }
    pub fn network(&self) -> &PoseGaussianNet {
        &self.net
    }
    pub fn parents(&self) -> &[i64] {
        &self.parents
    }

    /// The settings every forward pass of this run uses.
    pub fn settings(&self) -> ForwardSettings<'_> {
        forward_settings(&self.config, &self.framing, &self.parents)
    }

    /// The frame and target camera of `iteration`, drawn from the seed.
    fn sample(&self, iteration: usize) -> (usize, usize) {
        let mix = self.config.seed ^ (iteration as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        let mut rng = StdRng::seed_from_u64(mix);
        let frame = self.frames[rng.random_range(0..self.frames.len())];
        let inputs = self.inputs.input_cameras();
        (frame, inputs[rng.random_range(0..inputs.len())])
    }

    /// Prepares `frame` the first time a step draws it.
    fn ensure_prepared(&mut self, frame: usize) -> Result<()> {
        if !self.prepared.contains_key(&frame) {
            if !self.hulls.contains_key(&frame) {
                let mesh = frame_hull(self.inputs, frame, &hull_config(self.config.hull_voxel))?;
                self.hulls.insert(frame, mesh);
            }
            let depth = self.config.depth_settings();
            let mesh = &self.hulls[&frame];
            let prepared = prepare_frame(self.inputs, frame, mesh, &self.framing, &depth)?;
            self.prepared.insert(frame, prepared);
        }
        Ok(())
    }

    /// One Adam step.
    pub fn step(&mut self) -> Result<StepStats> {
        let started = std::time::Instant::now();
        let iteration = self.iteration + 1;
        let (frame, target) = self.sample(iteration);
        let k = self.config.source_views;
        self.ensure_prepared(frame)?;
        let prepared = &self.prepared[&frame];
        let target_camera = &prepared
            .view(target)
            .ok_or_else(|| {
                HumanError::argument("training", format!("camera {target} is not prepared"))
            })?
            .camera;
        let sources = prepared.nearest(target_camera, k, Some(target))?;
        let views: Vec<_> = sources.iter().filter_map(|&c| prepared.view(c)).collect();
        let target_view = prepared.view(target).ok_or_else(|| {
            HumanError::argument("training", format!("camera {target} is not prepared"))
        })?;
        let settings = self.settings();
        let prediction = predict(&self.net, &views, &settings, &self.device)?;
        let gaussians = prediction_gaussians(&views, &prediction.maps, &settings)?;
        let rendered = render_gaussians(&gaussians, &target_view.camera);
        let (loss, parts) = training_loss(
            &prediction.heads,
            &prediction.maps,
            &views,
            &gaussians,
            &rendered,
            target_view,
            &self.config.loss,
        )?;
        if !parts.total.is_finite() {
            return Err(HumanError::argument(
                "training",
                format!(
                    "the loss is {} at iteration {iteration} (frame {frame}, camera {target})",
                    parts.total
                ),
            ));
        }
        let grads = GradientsParams::from_grads(loss.backward(), &self.net);
        let net = self.net.clone();
        self.net = self.optimizer.step(self.config.learning_rate, net, grads);
        self.iteration = iteration;
        let seconds = started.elapsed().as_secs_f64();
        Ok(StepStats {
            iteration,
            frame,
            target,
            sources,
            loss: parts,
            seconds,
        })
    }

    /// Writes the weights, Adam's state and the run's state to `dir` (the state last, so that
    /// an interrupted write leaves the previous checkpoint readable... as a whole set).
    pub fn save(&self, dir: &Path) -> Result<()> {
        std::fs::create_dir_all(dir).map_err(|e| HumanError::io(dir, e))?;
        checkpoint::save(&self.net, &dir.join("network.fvh"))?;
        let bytes = self.optimizer.into_bytes().map_err(|e| {
            HumanError::format(dir.join("optimizer.bin"), format!("cannot encode: {e}"))
        })?;
        write_atomic(&dir.join("optimizer.bin"), &bytes)?;
        let state = State {
            config: self.config.clone(),
            framing: self.framing.clone(),
            parents: self.parents.clone(),
            iteration: self.iteration,
        };
        let json = serde_json::to_vec(&state).expect("the state serialises");
        Ok(sealed::write(&dir.join("state.bin"), STATE_MAGIC, &json)?)
    }

    /// The network without its autodiff graph, for inference.
    pub fn inference_network(&self) -> PoseGaussianNet {
        self.net.clone().valid()
    }
}

fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, bytes).map_err(|e| HumanError::io(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| HumanError::io(path, e))
}

fn read_state(dir: &Path) -> Result<State> {
    let path = dir.join("state.bin");
    let bytes = sealed::read(&path, STATE_MAGIC, &[], "a human training checkpoint")?;
    serde_json::from_slice(&bytes)
        .map_err(|e| HumanError::format(&path, format!("unreadable state: {e}")))
}

/// The run's framing, configuration and joint tree stored in checkpoint `dir`.
pub fn stored_run(dir: &Path) -> Result<(TrainConfig, Framing, Vec<i64>, usize)> {
    let s = read_state(dir)?;
    Ok((s.config, s.framing, s.parents, s.iteration))
}

/// The network configuration a training configuration implies.
pub fn net_config(config: &TrainConfig, parents: &[i64]) -> NetConfig {
    let channels = crate::net::pose_map_channels(parents, PoseMapConfig::default().style);
    config.preset.net(config.variant, channels)
}

/// The forward settings of a run.
pub fn forward_settings<'s>(
    config: &TrainConfig,
    framing: &'s Framing,
    parents: &'s [i64],
) -> ForwardSettings<'s> {
    ForwardSettings {
        framing,
        bracket: config.bracket,
        parents,
        pose_map: PoseMapConfig {
            sigma_px: 2.0 * framing.scale.max(0.5),
            ..PoseMapConfig::default()
        },
        use_pose: config.use_pose,
        gaussians: GaussianOptions {
            source_views: config.source_views,
            ..GaussianOptions::default()
        },
    }
}

/// An error, before anything is trained, when the input depth asks for what the capture lacks.
fn check_depth_input(inputs: &dyn InputViews, frame: usize, depth: DepthInput) -> Result<()> {
    let Some(&camera) = inputs.input_cameras().first() else {
        return Ok(());
    };
    if depth == DepthInput::Dataset && inputs.depth(camera, frame)?.is_none() {
        return Err(DepthInput::dataset_depth_missing());
    }
    Ok(())
}

fn carve_all(
    inputs: &dyn InputViews,
    frames: std::ops::Range<usize>,
    voxel: f64,
) -> Result<HashMap<usize, Mesh>> {
    frames
        .map(|f| Ok((f, frame_hull(inputs, f, &hull_config(voxel))?)))
        .collect()
}

/// The device training runs on: the CPU backend with autodiff.
pub fn default_device() -> Device {
    Device::flex().autodiff()
}
