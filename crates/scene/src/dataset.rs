//! A loaded dataset: views (camera + image + optional mask), the train/test split, and what the
//! format offers for initialisation (sparse points, depth bounds).

use nalgebra::{Matrix4, Vector3};
use serde::{Deserialize, Serialize};

use crate::camera::Camera;
use crate::image::Image;

/// One photograph with its camera.
#[derive(Clone, Debug)]
pub struct View {
    /// File stem or frame name, for reports.
    pub name: String,
    pub camera: Camera,
    /// RGB, backgrounds of RGBA inputs already composited.
    pub image: Image,
    /// Foreground mask (1 channel, 0 or 1) when the dataset has one.
    pub mask: Option<Image>,
    /// The mask is the photo's own alpha channel, so `image = rgb·mask + (1 − mask)·background`
    /// (with the dataset's `background`) and the image can be re-composited over any other
    /// colour. False for masks read from separate files (DTU), which outline an object in
    /// front of a real background.
    pub mask_is_alpha: bool,
    /// Pixels that hold photo data (1) or lie in the blank border an undistortion left (0),
    /// 1 channel; `None` when every pixel is valid. Losses and metrics ignore invalid pixels.
    pub valid: Option<Image>,
    /// Near/far depth bounds of this view when the format gives them (LLFF).
    pub depth_bounds: Option<(f64, f64)>,
    /// Which entry of the camera file this view was read from, so that refined poses can be
    /// written back in the input's own format ([`crate::pose_export`]): the LLFF row, the DTU
    /// `world_mat_i` index, the frame's position in its transforms file (for NeRF-synthetic, in
    /// `transforms_train.json` for training views and `transforms_test.json` for test views),
    /// the COLMAP `IMAGE_ID`. In-process scenes number their views from 0.
    pub source_index: usize,
}

/// A coloured point cloud (e.g. COLMAP `points3D`), used to initialise Gaussians.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PointCloud {
    pub positions: Vec<[f32; 3]>,
    /// RGB in `[0, 1]`, one per position.
    pub colors: Vec<[f32; 3]>,
    /// Per view name, the indices of the points that view observed (the points' structure-from-
    /// motion tracks), where the source records them (`fewview poses`' `observed_points`);
    /// empty otherwise. A point can lie inside a view's image and still be hidden from it.
    #[serde(default)]
    pub observed_by: std::collections::BTreeMap<String, Vec<u32>>,
}

impl PointCloud {
    pub fn len(&self) -> usize {
        self.positions.len()
    }
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// The points view `name` observed, when the cloud records it.
    pub fn observed_in(&self, name: &str) -> Option<impl Iterator<Item = &[f32; 3]>> {
        let ids = self.observed_by.get(name)?;
        Some(ids.iter().filter_map(|&i| self.positions.get(i as usize)))
    }
}

/// Views with a train/test split.
#[derive(Clone, Debug)]
pub struct Dataset {
    /// Scene name (folder name), for reports.
    pub name: String,
    pub views: Vec<View>,
    /// Indices into `views` used for training.
    pub train: Vec<usize>,
    /// Indices into `views` held out for evaluation.
    pub test: Vec<usize>,
    /// Sparse points from the capture's structure-from-motion, when available.
    pub points: Option<PointCloud>,
    /// Background colour the RGBA images were composited over (black for opaque photos).
    pub background: [f32; 3],
    /// Maps this dataset's world coordinates back to the source's own world frame when the
    /// loader normalised them (DTU: IDR's `scale_mat`, normalised unit-sphere coordinates to
    /// millimetres; LLFF: the inverse of NeRF's bounds rescaling and recentring). `None` when the
    /// poses are as stored.
    pub to_source_world: Option<Matrix4<f64>>,
}

impl Dataset {
    pub fn train_views(&self) -> impl Iterator<Item = &View> {
        self.train.iter().map(|&i| &self.views[i])
    }

    pub fn test_views(&self) -> impl Iterator<Item = &View> {
        self.test.iter().map(|&i| &self.views[i])
    }

    /// Centre and radius of the training cameras (the "scene extent" of 3DGS: 1.1 × the largest
    /// distance from the mean camera centre). Learning rates of positions scale with it.
    pub fn camera_extent(&self) -> (Vector3<f64>, f64) {
        camera_extent(self.train_views().map(|v| &v.camera))
    }

    /// Makes every view's separate foreground mask (DTU's) its photo's alpha: the photo becomes
    /// `rgb·mask + (1 − mask)·background`, so training and scores see the object alone, as
    /// IDR/NeuS-style methods train on DTU with masks. Returns how many views changed; views
    /// without a mask, or whose mask already is their alpha, keep their photos.
    pub fn composite_masks_as_alpha(&mut self) -> usize {
        let background = self.background;
        let mut changed = 0;
        for view in &mut self.views {
            let Some(mask) = view.mask.as_ref().filter(|_| !view.mask_is_alpha) else {
                continue;
            };
            let c = view.image.channels;
            for (pixel, &a) in view.image.data.chunks_mut(c).zip(&mask.data) {
                for (v, b) in pixel.iter_mut().zip(background) {
                    *v = *v * a + (1.0 - a) * b;
                }
            }
            view.mask_is_alpha = true;
            changed += 1;
        }
        changed
    }
}

/// Centre and radius of a set of cameras, as 3DGS's `getNerfppNorm`: the radius is 1.1 × the
/// largest distance of a camera centre from their mean (never below a small positive value).
pub fn camera_extent<'a>(cameras: impl Iterator<Item = &'a Camera>) -> (Vector3<f64>, f64) {
    let centers: Vec<Vector3<f64>> = cameras.map(super::camera::Camera::center).collect();
    if centers.is_empty() {
        return (Vector3::zeros(), 1.0);
    }
    let mean = centers.iter().sum::<Vector3<f64>>() / centers.len() as f64;
    let max = centers
        .iter()
        .map(|c| (c - mean).norm())
        .fold(0.0f64, f64::max);
    (mean, (max * 1.1).max(1e-6))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{Intrinsics, Se3};

    fn view(mask: Option<Image>, mask_is_alpha: bool) -> View {
        View {
            name: "v".into(),
            camera: Camera::new(Intrinsics::centered(10.0, 2, 1), Se3::identity()),
            image: Image::from_vec(2, 1, 3, vec![0.2, 0.4, 0.6, 0.8, 0.6, 0.4]),
            mask,
            mask_is_alpha,
            valid: None,
            depth_bounds: None,
            source_index: 0,
        }
    }

    #[test]
    fn separate_masks_become_alpha_over_the_background() {
        let half = Image::from_vec(2, 1, 1, vec![1.0, 0.5]);
        let mut ds = Dataset {
            name: "d".into(),
            views: vec![
                view(Some(half.clone()), false),
                view(None, false),
                view(Some(half), true),
            ],
            train: vec![0, 1, 2],
            test: Vec::new(),
            points: None,
            background: [0.0, 1.0, 0.0],
            to_source_world: None,
        };
        assert_eq!(ds.composite_masks_as_alpha(), 1);
        // The first pixel is inside the mask; the second half-covered over green.
        assert_eq!(ds.views[0].image.data, vec![0.2, 0.4, 0.6, 0.4, 0.8, 0.2]);
        assert!(ds.views[0].mask_is_alpha);
        // No mask, or a mask that already is the alpha: the photo stays.
        assert_eq!(ds.views[1].image.data, ds.views[2].image.data);
        assert_eq!(ds.composite_masks_as_alpha(), 0);
    }
}
