//! The evaluation protocol of "PoseGaussian: Pose-Driven Novel View Synthesis for Robust 3D
//! Human Reconstruction" (supplement, "standardization"): 8 input cameras "uniformly sampled
//! across the rig"; the other cameras are held out. On the synthetic capture's 12-camera ring
//! that makes cameras 2, 5, 8 and 11 the held-out ones ([`Split::seq_a`]).
//!
//! - **Novel views**: the held-out cameras, on every frame.
//! - **Novel poses**: training uses frames 0–39 (walking) only; frames 40–59 (guard and punch,
//!   unseen poses) are the test frames, again seen from the held-out cameras.
//!
//! Training reads only input cameras on training frames. [`TrainingView`] makes that a checked
//! property: it opens nothing else (an error names the refused pair), and the capture's
//! [`crate::readlog::ReadLog`] lets a test confirm that no other file was read.

use std::ops::Range;
use std::path::Path;

use fewview_scene::{Camera, Image};

use crate::error::{HumanError, Result};
use crate::maps::{DepthMap, Mask};
use crate::source::MultiView;

/// Input cameras in the PoseGaussian paper's protocol ("8 input cameras uniformly sampled across the rig").
pub const PAPER_INPUT_CAMERAS: usize = 8;

/// The file in a run folder that holds its split.
pub const SPLIT_FILE: &str = "split.json";

/// Input and held-out cameras, training and test frames.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Split {
    /// Cameras whose images the method sees (training and inference inputs).
    pub input_cameras: Vec<usize>,
    /// Cameras only used as evaluation targets.
    pub held_out_cameras: Vec<usize>,
    /// Frames used for training.
    pub train_frames: Range<usize>,
    /// Frames with poses unseen in training.
    pub test_frames: Range<usize>,
}

impl Split {
    /// The protocol on the synthetic capture's `seq_a` (12 cameras, 60 frames).
    pub fn seq_a() -> Self {
        Self {
            input_cameras: vec![0, 1, 3, 4, 6, 7, 9, 10],
            held_out_cameras: vec![2, 5, 8, 11],
            train_frames: 0..40,
            test_frames: 40..60,
        }
    }

    /// `inputs` cameras of `cameras` spread uniformly over the rig (camera `⌊i·cameras/inputs⌋`
    /// for `i < inputs`; 12 cameras and 8 inputs give [`Split::seq_a`]'s), the rest held out; frames `0..train_frames` for training and the
    /// others for testing.
    pub fn uniform(
        cameras: usize,
        inputs: usize,
        frames: usize,
        train_frames: usize,
    ) -> Result<Self> {
        if inputs == 0 || inputs >= cameras {
            let msg = format!(
                "{inputs} input cameras of {cameras} (need 1 to {})",
                cameras.saturating_sub(1)
            );
            return Err(HumanError::argument("split", msg));
        }
        if train_frames == 0 || train_frames >= frames {
            let msg = format!(
                "{train_frames} training frames of {frames} (need 1 to {})",
                frames.saturating_sub(1)
            );
            return Err(HumanError::argument("split", msg));
        }
        let input_cameras: Vec<usize> = (0..inputs).map(|i| i * cameras / inputs).collect();
        let held_out_cameras = (0..cameras)
            .filter(|c| !input_cameras.contains(c))
            .collect();
        Ok(Self {
            input_cameras,
            held_out_cameras,
            train_frames: 0..train_frames,
            test_frames: train_frames..frames,
        })
    }

    /// The protocol on any capture: `inputs` cameras spread over the rig ([`Split::uniform`]),
    /// training on the first `train_frames` frames (default two thirds of them, which on `seq_a`
    /// is frames 0–39) and testing on the rest.
    pub fn for_capture(
        source: &dyn MultiView,
        inputs: usize,
        train_frames: Option<usize>,
    ) -> Result<Self> {
        let frames = source.frame_count();
        let train = train_frames.unwrap_or(frames * 2 / 3);
        let split = Self::uniform(source.cameras().len(), inputs, frames, train)?;
        split.check_fits(source)?;
        Ok(split)
    }

    /// Writes the split as `split.json` into a run folder, so that evaluation uses the cameras
    /// and frames training used.
    pub fn save(&self, run: &Path) -> Result<()> {
        let path = run.join(SPLIT_FILE);
        let text = serde_json::to_string_pretty(self).expect("a split serializes");
        std::fs::write(&path, text + "\n")
            .map_err(|e| HumanError::format(&path, format!("cannot write ({e})")))
    }

    /// The split a run was trained with (`split.json`), or `None` when the run has none.
    pub fn load(run: &Path) -> Result<Option<Self>> {
        let path = run.join(SPLIT_FILE);
        if !path.is_file() {
            return Ok(None);
        }
        let text = std::fs::read_to_string(&path)
            .map_err(|e| HumanError::format(&path, format!("cannot read ({e})")))?;
        serde_json::from_str(&text)
            .map(Some)
            .map_err(|e| HumanError::format(&path, format!("not a split ({e})")))
    }

    /// Whether training may read `(camera, frame)`.
    pub fn in_training(&self, camera: usize, frame: usize) -> bool {
        self.input_cameras.contains(&camera) && self.train_frames.contains(&frame)
    }

    /// Every `(camera, frame)` training may read.
    pub fn training_pairs(&self) -> Vec<(usize, usize)> {
        pairs(&self.input_cameras, self.train_frames.clone())
    }

    /// Novel-view targets: every held-out camera on every frame.
    pub fn novel_view_targets(&self) -> Vec<(usize, usize)> {
        pairs(&self.held_out_cameras, self.all_frames())
    }

    /// Every frame of the split, training and test.
    pub fn all_frames(&self) -> Range<usize> {
        let (t, s) = (&self.train_frames, &self.test_frames);
        t.start.min(s.start)..t.end.max(s.end)
    }

    /// Novel-pose targets: every held-out camera on the test frames.
    pub fn novel_pose_targets(&self) -> Vec<(usize, usize)> {
        pairs(&self.held_out_cameras, self.test_frames.clone())
    }

    /// An error unless the split is consistent (input cameras and training frames exist, inputs
    /// and held-out cameras are disjoint, training and test frames too) and fits `source`.
    pub fn check_fits(&self, source: &dyn MultiView) -> Result<()> {
        let bad = |m: String| HumanError::invalid(source.root(), format!("split: {m}"));
        let overlap = self
            .held_out_cameras
            .iter()
            .any(|c| self.input_cameras.contains(c));
        let (t, s) = (&self.train_frames, &self.test_frames);
        if self.input_cameras.is_empty() || t.is_empty() {
            return Err(bad("no input cameras or no training frames".into()));
        }
        if overlap || (t.start < s.end && s.start < t.end) {
            return Err(bad(format!(
                "{self:?}: held-out cameras or test frames overlap training"
            )));
        }
        let (cams, frames) = (source.cameras().len(), source.frame_count());
        let max_cam = self
            .input_cameras
            .iter()
            .chain(&self.held_out_cameras)
            .max();
        if max_cam.is_some_and(|&c| c >= cams) || self.all_frames().end > frames {
            return Err(bad(format!(
                "needs cameras up to {} and {} frames; the capture has {cams} cameras and {frames} frames",
                max_cam.copied().unwrap_or(0),
                self.all_frames().end
            )));
        }
        Ok(())
    }
}

fn pairs(cameras: &[usize], frames: Range<usize>) -> Vec<(usize, usize)> {
    frames
        .flat_map(|f| cameras.iter().map(move |&c| (c, f)))
        .collect()
}

/// A capture seen through a split's training set: it opens `(camera, frame)` only when the
/// camera is an input camera and the frame a training frame, and refuses everything else with
/// [`HumanError::OutsideTraining`] before touching a file.
pub struct TrainingView<'a> {
    source: &'a dyn MultiView,
    split: &'a Split,
}

impl<'a> TrainingView<'a> {
    pub fn new(source: &'a dyn MultiView, split: &'a Split) -> Result<Self> {
        split.check_fits(source)?;
        Ok(Self { source, split })
    }

    pub fn split(&self) -> &Split {
        self.split
    }

    /// An input camera (held-out cameras are refused: training never needs their pose).
    pub fn camera(&self, camera: usize) -> Result<&Camera> {
        if !self.split.input_cameras.contains(&camera) {
            return Err(self.refuse(format!("camera {camera}")));
        }
        Ok(&self.source.cameras()[camera])
    }

    pub fn image(&self, camera: usize, frame: usize) -> Result<Image> {
        self.check(camera, frame)?;
        self.source.image(camera, frame)
    }

    pub fn mask(&self, camera: usize, frame: usize) -> Result<Mask> {
        self.check(camera, frame)?;
        self.source.mask(camera, frame)
    }

    pub fn depth(&self, camera: usize, frame: usize) -> Result<DepthMap> {
        self.check(camera, frame)?;
        self.source.depth(camera, frame)
    }

    /// Whether the capture has depth maps at all.
    pub fn has_depth(&self) -> bool {
        self.source.has_depth()
    }

    pub fn joints2d(&self, camera: usize, frame: usize) -> Result<Vec<[f64; 2]>> {
        self.check(camera, frame)?;
        self.source.joints2d(camera, frame)
    }

    /// 3D joints of a training frame.
    pub fn joints3d(&self, frame: usize) -> Result<Vec<[f64; 3]>> {
        if !self.split.train_frames.contains(&frame) {
            return Err(self.refuse(format!("frame {frame}")));
        }
        self.source.joints3d(frame)
    }

    fn check(&self, camera: usize, frame: usize) -> Result<()> {
        if self.split.in_training(camera, frame) {
            return Ok(());
        }
        Err(self.refuse(format!("camera {camera}, frame {frame}")))
    }

    fn refuse(&self, what: String) -> HumanError {
        let s = self.split;
        HumanError::OutsideTraining {
            dataset: self.source.root().to_path_buf(),
            what,
            cameras: format!("{:?}", s.input_cameras),
            frames: format!(
                "{}..={}",
                s.train_frames.start,
                s.train_frames.end.saturating_sub(1)
            ),
        }
    }
}
