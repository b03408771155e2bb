//! Everything the network and the loss read for one frame, computed once: per input camera the
//! cropped image, mask, pose joints, visual-hull depth and the depth the network reads
//! ([`crate::depth`]: stereo, the hull's or the dataset's), and the dataset's depth, which the
//! loss reads.

use fewview_geom::Mesh;
use fewview_scene::{Camera, Image};
use rayon::prelude::*;

use super::crop::{Crop, common_scale};
use crate::depth::{DepthInput, StereoInput, StereoSettings, pair_depth, stereo_partners};
use crate::error::{HumanError, Result};
use crate::gaussians::{Nearness, nearest_sources};
use crate::hull::{Bounds, Hull, HullConfig, render_depth};
use crate::maps::{DepthMap, Mask};
use crate::source::MultiView;
use crate::split::{Split, TrainingView};

/// Read access to the input cameras, as training (its frames only) or inference (any frame)
/// is allowed it. Held-out cameras are never read through it.
pub trait InputViews: Sync {
    fn camera(&self, camera: usize) -> Result<&Camera>;
    fn input_cameras(&self) -> &[usize];
    fn image(&self, camera: usize, frame: usize) -> Result<Image>;
    fn mask(&self, camera: usize, frame: usize) -> Result<Mask>;
    /// The dataset's depth (the loss's depth term): `None` when the capture has no depth
    /// maps, an error when one of its files cannot be read.
    fn depth(&self, camera: usize, frame: usize) -> Result<Option<DepthMap>>;
    fn joints2d(&self, camera: usize, frame: usize) -> Result<Vec<[f64; 2]>>;
}

impl InputViews for TrainingView<'_> {
    fn camera(&self, camera: usize) -> Result<&Camera> {
        TrainingView::camera(self, camera)
    }
    fn input_cameras(&self) -> &[usize] {
        &self.split().input_cameras
    }
    fn image(&self, camera: usize, frame: usize) -> Result<Image> {
        TrainingView::image(self, camera, frame)
    }
    fn mask(&self, camera: usize, frame: usize) -> Result<Mask> {
        TrainingView::mask(self, camera, frame)
    }
    fn depth(&self, camera: usize, frame: usize) -> Result<Option<DepthMap>> {
        if !self.has_depth() {
            return Ok(None);
        }
        TrainingView::depth(self, camera, frame).map(Some)
    }
    fn joints2d(&self, camera: usize, frame: usize) -> Result<Vec<[f64; 2]>> {
        TrainingView::joints2d(self, camera, frame)
    }
}

/// The input cameras at every frame: what inference may read.
pub struct InferenceInputs<'a> {
    pub source: &'a dyn MultiView,
    pub split: &'a Split,
    /// Read the capture's depth maps too (the oracle input depth, or a report's truth);
    /// otherwise [`InputViews::depth`] is `None` and no depth file is read.
    pub depth_maps: bool,
}

impl InferenceInputs<'_> {
    fn check(&self, camera: usize) -> Result<()> {
        if self.split.input_cameras.contains(&camera) {
            return Ok(());
        }
        let m = format!("camera {camera} is not an input camera");
        Err(HumanError::argument("inference inputs", m))
    }
}

impl InputViews for InferenceInputs<'_> {
    fn camera(&self, camera: usize) -> Result<&Camera> {
        self.check(camera)?;
        Ok(&self.source.cameras()[camera])
    }
    fn input_cameras(&self) -> &[usize] {
        &self.split.input_cameras
    }
    fn image(&self, camera: usize, frame: usize) -> Result<Image> {
        self.check(camera)?;
        self.source.image(camera, frame)
    }
    fn mask(&self, camera: usize, frame: usize) -> Result<Mask> {
        self.check(camera)?;
        self.source.mask(camera, frame)
    }
    /// The capture's depth of an input camera, when asked for and the capture has depth maps.
    fn depth(&self, camera: usize, frame: usize) -> Result<Option<DepthMap>> {
        self.check(camera)?;
        if !self.depth_maps || !self.source.has_depth() {
            return Ok(None);
        }
        self.source.depth(camera, frame).map(Some)
    }
    fn joints2d(&self, camera: usize, frame: usize) -> Result<Vec<[f64; 2]>> {
        self.check(camera)?;
        self.source.joints2d(camera, frame)
    }
}

/// One input camera at one frame, cropped.
#[derive(Clone, Debug)]
pub struct PreparedView {
    /// Index into the dataset's cameras.
    pub camera_index: usize,
    /// The crop's camera.
    pub camera: Camera,
    pub image: Image,
    pub mask: Mask,
    /// The visual hull's z-depth (0 where the ray misses it).
    pub hull_depth: DepthMap,
    /// The depth the network reads and the depth head refines ([`DepthInput`]).
    pub input_depth: DepthMap,
    /// The fraction of the view's masked hull pixels whose input depth came from stereo (0
    /// for the other inputs).
    pub stereo_matched: f64,
    /// The dataset's depth, when it has one.
    pub depth: Option<DepthMap>,
    /// 2D joints in the crop's pixels.
    pub joints: Vec<[f64; 2]>,
}

/// The input cameras of one frame.
#[derive(Clone, Debug)]
pub struct PreparedFrame {
    pub frame: usize,
    pub views: Vec<PreparedView>,
}

impl PreparedFrame {
    /// The view of dataset camera `camera`.
    pub fn view(&self, camera: usize) -> Option<&PreparedView> {
        self.views.iter().find(|v| v.camera_index == camera)
    }

    /// The dataset cameras of the `k` views nearest `target` by view direction, leaving out
    /// dataset camera `except` (the target itself, when it is an input camera).
    pub fn nearest(&self, target: &Camera, k: usize, except: Option<usize>) -> Result<Vec<usize>> {
        let cameras: Vec<Camera> = self.views.iter().map(|v| v.camera.clone()).collect();
        let others: Vec<usize> = (0..cameras.len())
            .filter(|&i| Some(self.views[i].camera_index) != except)
            .collect();
        let picked = nearest_sources(target, &cameras, &others, k, Nearness::ViewDirection)?;
        Ok(picked
            .into_iter()
            .map(|i| self.views[i].camera_index)
            .collect())
    }
}

/// How the hulls of a run are carved: voxels of `voxel` metres, every input camera.
pub fn hull_config(voxel: f64) -> HullConfig {
    HullConfig {
        voxel,
        ..HullConfig::default()
    }
}

/// Where the person is and how the cameras are cropped around it, fixed for a run.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Framing {
    /// The union of the training frames' visual hulls (axis-aligned box, world units).
    pub bounds: [[f64; 3]; 2],
    /// Output pixels per source pixel, the same for every camera.
    pub scale: f64,
    /// Crop `[width, height]`.
    pub size: [usize; 2],
    /// Nearest and farthest depth any camera sees the box at.
    pub near: f64,
    pub far: f64,
}

impl Framing {
    pub fn box_bounds(&self) -> Bounds {
        Bounds {
            min: self.bounds[0],
            max: self.bounds[1],
        }
    }

    /// The crop of `camera`.
    pub fn crop(&self, camera: &Camera) -> Crop {
        Crop::centred(&self.box_bounds(), camera, self.scale, self.size)
    }

    /// The framing of the hulls `meshes` seen by `cameras`, at crops of `size` with a
    /// `margin` around the box.
    pub fn of_hulls(
        meshes: &[Mesh],
        cameras: &[Camera],
        size: [usize; 2],
        margin: f64,
    ) -> Result<Self> {
        let mut b = [[f64::INFINITY; 3], [f64::NEG_INFINITY; 3]];
        for v in meshes.iter().flat_map(|m| &m.vertices) {
            for a in 0..3 {
                b[0][a] = b[0][a].min(v[a] as f64);
                b[1][a] = b[1][a].max(v[a] as f64);
            }
        }
        if !(b[0][0] <= b[1][0]) {
            return Err(HumanError::argument(
                "framing",
                "the visual hulls are empty",
            ));
        }
        let bounds = Bounds {
            min: b[0],
            max: b[1],
        };
        let centre = nalgebra::Vector3::from_fn(|a, _| 0.5 * (b[0][a] + b[1][a]));
        let radius = 0.5
            * (0..3)
                .map(|a| (b[1][a] - b[0][a]).powi(2))
                .sum::<f64>()
                .sqrt();
        let distances = cameras.iter().map(|c| (c.center() - centre).norm());
        let (near, far) = distances.fold((f64::INFINITY, 0.0f64), |(n, f), d| (n.min(d), f.max(d)));
        Ok(Self {
            bounds: b,
            scale: common_scale(&bounds, cameras, size, margin),
            size,
            near: (near - radius).max(1e-3),
            far: far + radius,
        })
    }
}

/// The visual hull of `frame` carved from the input cameras' masks, as a mesh.
pub fn frame_hull(inputs: &dyn InputViews, frame: usize, config: &HullConfig) -> Result<Mesh> {
    let ids = inputs.input_cameras();
    let masks = ids
        .iter()
        .map(|&c| inputs.mask(c, frame))
        .collect::<Result<Vec<_>>>()?;
    let cameras = ids
        .iter()
        .map(|&c| inputs.camera(c).cloned())
        .collect::<Result<Vec<_>>>()?;
    Hull::carve(&cameras, &masks, config)?.mesh()
}

/// Which depth the network reads, and how stereo finds it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DepthSettings {
    pub input: DepthInput,
    pub stereo: StereoSettings,
}

/// The input views of `frame`, cropped by `framing`, with the hull `mesh`'s depth and the
/// input depth `depth` asks for.
pub fn prepare_frame(
    inputs: &dyn InputViews,
    frame: usize,
    mesh: &Mesh,
    framing: &Framing,
    depth: &DepthSettings,
) -> Result<PreparedFrame> {
    let mut views = inputs
        .input_cameras()
        .par_iter()
        .map(|&c| {
            let full = inputs.camera(c)?;
            let crop = framing.crop(full);
            let camera = crop.camera(full);
            let joints = inputs.joints2d(c, frame)?;
            let hull_depth = render_depth(mesh, &camera)?;
            Ok(PreparedView {
                camera_index: c,
                image: crop.image(&inputs.image(c, frame)?),
                mask: crop.mask(&inputs.mask(c, frame)?),
                input_depth: hull_depth.clone(),
                stereo_matched: 0.0,
                hull_depth,
                depth: inputs.depth(c, frame)?.map(|d| crop.depth(&d)),
                joints: joints.iter().map(|&p| crop.point(p)).collect(),
                camera,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    match depth.input {
        DepthInput::Hull => {}
        DepthInput::Dataset => {
            for v in &mut views {
                v.input_depth = v
                    .depth
                    .clone()
                    .ok_or_else(DepthInput::dataset_depth_missing)?;
            }
        }
        DepthInput::Stereo => add_stereo_depth(&mut views, &depth.stereo)?,
    }
    Ok(PreparedFrame { frame, views })
}

/// Replaces each view's input depth by stereo with its partner ([`stereo_partners`]), each
/// pair matched once.
fn add_stereo_depth(views: &mut [PreparedView], settings: &StereoSettings) -> Result<()> {
    let cameras: Vec<&Camera> = views.iter().map(|v| &v.camera).collect();
    let partners = stereo_partners(&cameras, settings.partner)?;
    let mut pairs: Vec<(usize, usize)> = partners
        .iter()
        .enumerate()
        .map(|(i, &j)| (i.min(j), i.max(j)))
        .collect();
    pairs.sort_unstable();
    pairs.dedup();
    let names: Vec<String> = views
        .iter()
        .map(|v| format!("camera {}", v.camera_index))
        .collect();
    let input = |i: usize| StereoInput {
        name: &names[i],
        camera: &views[i].camera,
        image: &views[i].image,
        mask: &views[i].mask,
        hull: &views[i].hull_depth,
    };
    let depths = pairs
        .par_iter()
        .map(|&(i, j)| pair_depth(&input(i), &input(j), settings))
        .collect::<Result<Vec<_>>>()?;
    for (i, &j) in partners.iter().enumerate() {
        let k = pairs
            .binary_search(&(i.min(j), i.max(j)))
            .expect("every pair matched");
        let side = usize::from(i > j);
        views[i].input_depth = depths[k].depth[side].clone();
        views[i].stereo_matched = depths[k].matched[side];
    }
    Ok(())
}
