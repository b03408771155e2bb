//! The pose map, the input of PoseGaussian's pose encoder: the source view's 2D joints drawn
//! as an image ("PoseGaussian: Pose-Driven Novel View Synthesis for Robust 3D Human
//! Reconstruction"; the paper does not say how the joints are drawn).
//!
//! Chosen here, as pose-conditioned image networks commonly draw a skeleton: one Gaussian
//! heatmap per joint, `exp(−d² / 2σ²)` with `d` the distance from the pixel centre to the joint,
//! and one limb channel per bone (a joint and its parent), the same profile with `d` the
//! distance to the segment between them. The heatmaps say where each joint is; the limbs say
//! which joints are connected and cover the body between them. Channels: the heatmaps in joint
//! order, then the limbs in the order of their child joint. Pixel centres are at half-integers,
//! the crate's convention, so a joint at `(2.5, 3.5)` peaks at pixel column 2, row 3.

use burn::tensor::{Device, Tensor, TensorData};

use crate::error::{HumanError, Result};

/// Which channels the pose map has.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PoseMapStyle {
    /// One heatmap per joint.
    Heatmaps,
    /// One limb channel per bone.
    Limbs,
    /// Heatmaps, then limbs (the network presets expect this: 17 + 16 channels).
    Both,
}

/// How to draw the pose map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseMapConfig {
    pub style: PoseMapStyle,
    /// Standard deviation of the Gaussian profile, pixels (scale it with the image).
    pub sigma_px: f64,
}

impl Default for PoseMapConfig {
    fn default() -> Self {
        Self {
            style: PoseMapStyle::Both,
            sigma_px: 2.0,
        }
    }
}

/// Channels the pose map of a skeleton with these `parents` (−1 for a root) has.
pub fn pose_map_channels(parents: &[i64], style: PoseMapStyle) -> usize {
    let bones = parents.iter().filter(|&&p| p >= 0).count();
    match style {
        PoseMapStyle::Heatmaps => parents.len(),
        PoseMapStyle::Limbs => bones,
        PoseMapStyle::Both => parents.len() + bones,
    }
}

/// The pose map as a `[C, height, width]` tensor on `device`; see [`pose_map_host`].
pub fn pose_map(
    joints: &[[f64; 2]],
    parents: &[i64],
    size: [usize; 2],
    config: &PoseMapConfig,
    device: &Device,
) -> Result<Tensor<3>> {
    let data = pose_map_host(joints, parents, size, config)?;
    let c = pose_map_channels(parents, config.style);
    Ok(Tensor::from_data(
        TensorData::new(data, [c, size[0], size[1]]),
        device,
    ))
}

/// The pose map, channel-major (`C × height × width`), of `joints` (pixel `(u, v)`) whose
/// parents are `parents`; an error if the two differ in length, a parent index is out of range,
/// a joint is not finite or σ is not positive.
pub fn pose_map_host(
    joints: &[[f64; 2]],
    parents: &[i64],
    size: [usize; 2],
    config: &PoseMapConfig,
) -> Result<Vec<f32>> {
    check(joints, parents, config)?;
    let segments = channel_segments(joints, parents, config.style);
    let [h, w] = size;
    let k = -0.5 / (config.sigma_px * config.sigma_px);
    let mut out = Vec::with_capacity(segments.len() * h * w);
    for (a, b) in segments {
        for y in 0..h {
            for x in 0..w {
                let p = [x as f64 + 0.5, y as f64 + 0.5];
                out.push((k * segment_distance2(p, a, b)).exp() as f32);
            }
        }
    }
    Ok(out)
}

/// Per channel the segment it draws: a joint is the degenerate segment `(j, j)`.
fn channel_segments(
    joints: &[[f64; 2]],
    parents: &[i64],
    style: PoseMapStyle,
) -> Vec<([f64; 2], [f64; 2])> {
    let heat = joints.iter().map(|&j| (j, j));
    let limbs = joints
        .iter()
        .zip(parents)
        .filter(|(_, p)| **p >= 0)
        .map(|(&j, &p)| (j, joints[p as usize]));
    match style {
        PoseMapStyle::Heatmaps => heat.collect(),
        PoseMapStyle::Limbs => limbs.collect(),
        PoseMapStyle::Both => heat.chain(limbs).collect(),
    }
}

/// Squared distance from `p` to the segment `a`–`b`.
fn segment_distance2(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (ex, ey) = (p[0] - a[0] - t * dx, p[1] - a[1] - t * dy);
    ex * ex + ey * ey
}

fn check(joints: &[[f64; 2]], parents: &[i64], config: &PoseMapConfig) -> Result<()> {
    let bad = |m: String| Err(HumanError::argument("pose map", m));
    if joints.len() != parents.len() {
        return bad(format!(
            "{} joints but {} parents",
            joints.len(),
            parents.len()
        ));
    }
    if let Some(j) = joints.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
        return bad(format!("joint {j} is not finite ({:?})", joints[j]));
    }
    if let Some(j) = parents
        .iter()
        .position(|&p| p < -1 || p >= parents.len() as i64)
    {
        return bad(format!("joint {j}'s parent {} is out of range", parents[j]));
    }
    if !(config.sigma_px > 0.0) {
        return bad(format!("σ must be positive, not {} px", config.sigma_px));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(map: &[f32], size: [usize; 2], c: usize, y: usize, x: usize) -> f32 {
        map[(c * size[0] + y) * size[1] + x]
    }

    /// Two joints on row 4's centre line (v = 4.5), at u = 1.5 and u = 6.5, the second the
    /// child of the first. σ = 1.5 px, so exp(−d²/2σ²) = exp(−d²/4.5).
    #[test]
    fn pose_map_matches_the_analytic_profile() {
        let joints = [[1.5, 4.5], [6.5, 4.5]];
        let parents = [-1, 0];
        let size = [8, 9];
        let cfg = PoseMapConfig {
            style: PoseMapStyle::Both,
            sigma_px: 1.5,
        };
        let map = pose_map_host(&joints, &parents, size, &cfg).unwrap();
        assert_eq!(pose_map_channels(&parents, cfg.style), 3);
        assert_eq!(map.len(), 3 * 8 * 9);
        let g = |d2: f64| (-d2 / 4.5).exp() as f32;
        let cases = [
            (0, 4, 1, 1.0),          // on joint 0
            (0, 4, 3, g(4.0)),       // two pixels right of it
            (0, 2, 2, g(1.0 + 4.0)), // one right, two up
            (1, 4, 6, 1.0),          // on joint 1
            (2, 4, 4, 1.0),          // on the bone, between the joints
            (2, 2, 4, g(4.0)),       // two rows above the bone
            (2, 4, 8, g(4.0)),       // two past the end of the bone (u = 8.5)
            (2, 1, 0, g(1.0 + 9.0)), // before its start: distance to (1.5, 4.5)
        ];
        for (c, y, x, want) in cases {
            let got = at(&map, size, c, y, x);
            assert!(
                (got - want).abs() < 1e-6,
                "channel {c} ({y}, {x}): {got} vs {want}"
            );
        }
    }

    #[test]
    fn pose_map_is_a_tensor_of_the_skeleton_channels() {
        let parents = [-1, 0, 1, 2, 3, 2, 5, 6, 2, 8, 9, 0, 11, 12, 0, 14, 15];
        let joints: Vec<[f64; 2]> = (0..17).map(|j| [j as f64, 2.0 * j as f64]).collect();
        let t = pose_map(
            &joints,
            &parents,
            [40, 20],
            &PoseMapConfig::default(),
            &Device::flex(),
        );
        assert_eq!(
            t.unwrap().dims(),
            [crate::net::SKELETON_POSE_CHANNELS, 40, 20]
        );
    }

    #[test]
    fn pose_map_refuses_bad_skeletons_in_one_line() {
        let cfg = PoseMapConfig::default();
        let e =
            |j: &[[f64; 2]], p: &[i64]| pose_map_host(j, p, [4, 4], &cfg).unwrap_err().to_string();
        assert_eq!(
            e(&[[0.0, 0.0]], &[-1, 0]),
            "pose map: 1 joints but 2 parents"
        );
        assert_eq!(
            e(&[[0.0, 0.0], [1.0, 1.0]], &[-1, 2]),
            "pose map: joint 1's parent 2 is out of range"
        );
        assert!(e(&[[f64::NAN, 0.0]], &[-1]).starts_with("pose map: joint 0 is not finite"));
    }
}
