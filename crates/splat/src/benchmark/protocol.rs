//! The sparse-view protocols of RegNeRF ("RegNeRF: Regularizing Neural Radiance Fields for View
//! Synthesis from Sparse Inputs"), which FSGS and CoR-GS ("CoR-GS: Sparse-View 3D Gaussian
//! Splatting via Co-Regularization") follow: which views train and which are scored, at what
//! size, with which masks — and the peers' published figures under each.

use std::path::Path;

use fewview_scene::{Dataset, DatasetFormat, LoadOptions};
use serde::Serialize;

use super::error::BenchmarkError;

/// A benchmark protocol.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Protocol {
    /// LLFF, 3 views: every 8th image held out (0, 8, 16, …), 3 training views evenly spaced
    /// over the rest (fern: 1, 10, 19), at 504×378 (`images_8`).
    Llff,
    /// DTU, 3 views 25, 22, 28 at 400×300; scored on the 25 test views with their object masks,
    /// as the peers score them ([`super::masked`]).
    Dtu,
    /// NeRF-synthetic (Blender), 8 views 26, 86, 2, 55, 75, 93, 16, 73 at 400×400; scored on the
    /// test set over a white background.
    Blender,
}

/// A peer's published mean over a protocol's scenes.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Peer {
    pub method: &'static str,
    pub psnr: f64,
    pub ssim: f64,
    /// The original LPIPS (VGG or AlexNet as each paper says), not ST-LPIPS.
    pub lpips: f64,
    /// The table the figure comes from.
    pub source: &'static str,
}

const COR_GS_LLFF: &str = "CoR-GS, Table 1 (LLFF, 3 views)";
const COR_GS_DTU: &str = "CoR-GS, Table 3 (DTU, 3 views)";
const COR_GS_BLENDER: &str = "CoR-GS, Table 4 (Blender, 8 views)";

const fn peer(
    method: &'static str,
    psnr: f64,
    ssim: f64,
    lpips: f64,
    source: &'static str,
) -> Peer {
    Peer {
        method,
        psnr,
        ssim,
        lpips,
        source,
    }
}

const LLFF_PEERS: [Peer; 3] = [
    peer("3DGS", 19.22, 0.649, 0.229, COR_GS_LLFF),
    peer("FSGS", 20.43, 0.682, 0.248, COR_GS_LLFF),
    peer("CoR-GS", 20.45, 0.712, 0.196, COR_GS_LLFF),
];
const DTU_PEERS: [Peer; 2] = [
    peer("3DGS", 17.65, 0.816, 0.146, COR_GS_DTU),
    peer("CoR-GS", 19.21, 0.853, 0.119, COR_GS_DTU),
];
const BLENDER_PEERS: [Peer; 3] = [
    peer("3DGS", 23.20, 0.870, 0.104, COR_GS_BLENDER),
    peer("FSGS", 24.64, 0.895, 0.095, COR_GS_BLENDER),
    peer("CoR-GS", 24.43, 0.896, 0.084, COR_GS_BLENDER),
];

impl Protocol {
    pub fn name(self) -> &'static str {
        match self {
            Protocol::Llff => "llff",
            Protocol::Dtu => "dtu",
            Protocol::Blender => "blender",
        }
    }

    /// The dataset format the protocol reads.
    pub fn format(self) -> DatasetFormat {
        match self {
            Protocol::Llff => DatasetFormat::Llff,
            Protocol::Dtu => DatasetFormat::DtuIdr,
            Protocol::Blender => DatasetFormat::Blender,
        }
    }

    /// The width the protocol scores at (LLFF's comes from `images_8`).
    fn width(self) -> Option<usize> {
        match self {
            Protocol::Llff => None,
            Protocol::Dtu | Protocol::Blender => Some(400),
        }
    }

    /// Whether the scores are taken with the test views' object masks ([`super::masked`]).
    pub fn masked(self) -> bool {
        self == Protocol::Dtu
    }

    /// Whether `--sky-shell auto` gives the stereo start its shell of far Gaussians
    /// ([`crate::sky_shell`]) under this protocol: DTU's photos show a black curtain and the
    /// table's far edge beyond the object, where stereo finds no depth and a few views let
    /// floaters paint them in front of it. LLFF (forward-facing, its depth bounds given) and
    /// Blender (objects on a transparent background) have no such background.
    pub fn sky_shell(self) -> bool {
        self == Protocol::Dtu
    }

    /// The default weight of the stereo depth seen from pseudo views
    /// ([`crate::pseudo_depth`]) under this protocol: 0.1 on DTU, whose held-out views look at
    /// the object from well above and below the training row, where the depth of the Gaussians
    /// decides what lands on each pixel; off on LLFF, where it cost fern 0.36 dB, and Blender.
    pub fn pseudo_depth_weight(self) -> f32 {
        match self {
            Protocol::Dtu => 0.1,
            Protocol::Llff | Protocol::Blender => 0.0,
        }
    }

    /// The peers' published means under this protocol (each paper's own LPIPS).
    pub fn peers(self) -> &'static [Peer] {
        match self {
            Protocol::Llff => &LLFF_PEERS,
            Protocol::Dtu => &DTU_PEERS,
            Protocol::Blender => &BLENDER_PEERS,
        }
    }

    /// Loads the scene in `folder` as the protocol says: its split and size, refused in one
    /// line when it is another format, lacks the masks the protocol scores with, or cannot be
    /// brought to the protocol's size by an integer downscale.
    pub fn load(self, folder: &Path) -> Result<Dataset, BenchmarkError> {
        let refuse = |message: String| BenchmarkError::Scene {
            folder: folder.to_path_buf(),
            message,
        };
        let format = fewview_scene::detect_format(folder).map_err(|e| refuse(e.to_string()))?;
        if format != self.format() {
            return Err(refuse(format!(
                "--protocol {} reads {:?} scenes, this is {format:?}",
                self.name(),
                self.format()
            )));
        }
        let mut options = LoadOptions {
            format: Some(format),
            ..LoadOptions::default()
        };
        let load = |options: &LoadOptions| {
            fewview_scene::load_dataset(folder, options).map_err(|e| refuse(e.to_string()))
        };
        let mut ds = load(&options)?;
        if let Some(width) = self.width() {
            let stored = ds.views[ds.train[0]].image.width;
            if stored % width != 0 {
                return Err(refuse(format!(
                    "images {stored} px wide cannot be brought to the protocol's {width} by an \
                     integer downscale"
                )));
            }
            if stored != width {
                options.downscale = (stored / width) as u32;
                ds = load(&options)?;
            }
        }
        if self.masked()
            && let Some(v) = ds.test_views().find(|v| v.mask.is_none())
        {
            return Err(refuse(format!(
                "--protocol {} scores inside the object masks, and test view {} has none",
                self.name(),
                v.name
            )));
        }
        if ds.test.is_empty() {
            return Err(refuse("the split leaves no test view".into()));
        }
        Ok(ds)
    }
}
