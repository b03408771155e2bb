//! The Temporal Pose Stabilizer (TPS) of "PoseGaussian: Pose-Driven Novel View Synthesis for
//! Robust 3D Human Reconstruction": each source camera's per-pixel Gaussian parameter maps of
//! frame `t` are smoothed with that camera's already stabilised maps of frame `t − 1`, warped by
//! the skeleton's motion, less where the body moves fast.
//!
//! The paper says only that TPS "adjusts view blending based on inter-frame pose dynamics" (and
//! that it takes ~18 ms a frame). The rest is our design, host-side and without learned weights.
//! For every foreground pixel `p` of frame `t`, with z-depth `d_t(p)`:
//!
//! 1. `X` is `p`'s centre (pixel `(i, j)` has its centre at `(i + ½, j + ½)`) lifted to depth
//!    `d_t(p)` through the source camera.
//! 2. `j*` is the joint of frame `t` nearest `X`; `Δ = J_t[j*] − J_{t−1}[j*]` is its motion and
//!    `v = |Δ|` its speed (metres per frame).
//! 3. `X' = X − Δ` is where that surface point was at `t − 1`. It projects to pixel coordinates
//!    `(u', v')` and depth `z'`; `p'` is the pixel containing `(u', v')` (a nearest-pixel lookup,
//!    no interpolation). The previous values are used only when `p'` is inside the image and in
//!    the previous mask, and `|d_{t−1}(p') − z'| ≤` [`TpsConfig::depth_tolerance`]; otherwise `p`
//!    keeps its values.
//! 4. The weight is `w = max_weight · exp(−v / speed_scale)` ([`TpsConfig`]).
//! 5. Depth: `d_t(p) ← (1 − w) d_t(p) + w (d_{t−1}(p') + (RΔ)_z)`, the previous surface point
//!    `back-project(p', d_{t−1}(p'))` moved by `Δ`, whose camera z is exactly
//!    `d_{t−1}(p') + (RΔ)_z` (camera z is affine in the world point). Every other channel:
//!    `m_t(p) ← (1 − w) m_t(p) + w m_{t−1}(p')`. The unit-quaternion channels
//!    ([`SourceMaps::quaternion`]) take the previous quaternion's sign that agrees with the
//!    current one (`q` and `−q` are one rotation) and are renormalised after the blend.
//!
//! Since `t − 1` was itself stabilised, the maps are an exponential moving average along the
//! motion, restarted wherever the warp finds nothing consistent (disocclusions, fast limbs).
//! [`Stabilizer`] keeps the state over a sequence, one entry per source camera.
//!
//! Defaults: `max_weight` 0.5 (a still body averages the new frame and the history equally),
//! `speed_scale` 0.02 m/frame (a joint moving 2 cm a frame gets `e⁻¹` of that) and
//! `depth_tolerance` 0.05 m (a few centimetres of depth noise pass, a limb crossing in front of
//! the torso does not).

use std::collections::HashMap;
use std::ops::Range;

use fewview_scene::Camera;
use nalgebra::Vector3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{HumanError, Result};

/// The TPS weights; see the module docs for where each enters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct TpsConfig {
    /// Weight of the previous frame where the body is still, in `[0, 1]`.
    pub max_weight: f32,
    /// Joint speed (metres per frame) at which the weight falls to `max_weight / e`; positive.
    pub speed_scale: f32,
    /// Largest difference (metres) between the previous depth at the warped pixel and the warped
    /// point's depth for the previous values to count; non-negative.
    pub depth_tolerance: f32,
}

impl Default for TpsConfig {
    fn default() -> Self {
        Self {
            max_weight: 0.5,
            speed_scale: 0.02,
            depth_tolerance: 0.05,
        }
    }
}

impl TpsConfig {
    /// `max_weight · exp(−speed / speed_scale)`.
    pub fn weight(&self, speed: f64) -> f32 {
        (self.max_weight as f64 * (-speed / self.speed_scale as f64).exp()) as f32
    }

    /// An error unless every field is in its range (NaN is in none).
    pub fn check(&self) -> Result<()> {
        if !(0.0..=1.0).contains(&self.max_weight) {
            return Err(arg(format!(
                "max_weight {} is not in [0, 1]",
                self.max_weight
            )));
        }
        if !(self.speed_scale > 0.0 && self.speed_scale.is_finite()) {
            return Err(arg(format!(
                "speed_scale {} is not positive",
                self.speed_scale
            )));
        }
        if !(self.depth_tolerance >= 0.0) {
            let m = format!("depth_tolerance {} is negative", self.depth_tolerance);
            return Err(arg(m));
        }
        Ok(())
    }
}

/// One source view's per-pixel maps for one frame. Rasters are row-major: pixel `(x, y)` is
/// index `y * width + x`.
#[derive(Clone, Debug, PartialEq)]
pub struct SourceMaps {
    pub width: usize,
    pub height: usize,
    /// Foreground pixels; only these are stabilised or used as history.
    pub mask: Vec<bool>,
    /// Camera z-depth (metres) of each pixel's surface point.
    pub depth: Vec<f32>,
    /// Number of channels in `values`.
    pub channels: usize,
    /// Channel-major: channel `c` of pixel `p` is `values[c * width * height + p]`.
    pub values: Vec<f32>,
    /// The four channels holding a unit quaternion (e.g. the rotation head's, in the source
    /// camera's frame), if any.
    pub quaternion: Option<Range<usize>>,
}

impl SourceMaps {
    /// `width · height`.
    pub fn pixels(&self) -> usize {
        self.width * self.height
    }

    /// Number of foreground pixels.
    pub fn foreground(&self) -> usize {
        self.mask.iter().filter(|&&m| m).count()
    }

    /// Channel `c` as one raster.
    pub fn channel(&self, c: usize) -> &[f32] {
        let n = self.pixels();
        &self.values[c * n..(c + 1) * n]
    }

    /// An error unless the vectors' lengths match the size and the quaternion range is four
    /// channels inside `channels`; `what` names the maps in the message.
    pub fn check(&self, what: &str) -> Result<()> {
        let n = self.width.checked_mul(self.height);
        let values = n.and_then(|n| n.checked_mul(self.channels));
        let (Some(n), Some(values)) = (n, values) else {
            return Err(arg(format!("{what}: size overflows")));
        };
        let lengths = [
            ("mask", self.mask.len(), n),
            ("depth", self.depth.len(), n),
            ("values", self.values.len(), values),
        ];
        for (name, len, expected) in lengths {
            if len != expected {
                return Err(arg(format!(
                    "{what}: {name} has {len} entries, expected {expected}"
                )));
            }
        }
        match &self.quaternion {
            Some(q) if q.len() != 4 || q.end > self.channels => Err(arg(format!(
                "{what}: quaternion channels {q:?} are not 4 of the {} channels",
                self.channels
            ))),
            _ => Ok(()),
        }
    }
}

/// What one call of [`stabilize`] did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TpsStats {
    /// Foreground pixels of the current maps.
    pub pixels: usize,
    /// Those that found consistent previous values and were blended.
    pub blended: usize,
    /// Mean weight `w` of the blended pixels (0 when none was).
    pub mean_weight: f32,
}

/// The current maps blended with the previous (stabilised) maps of the same source camera,
/// warped by the joints' motion from `joints_previous` to `joints_current` (world coordinates,
/// the same joints in the same order). `camera` is the source camera at the maps' resolution.
pub fn stabilize(
    previous: &SourceMaps,
    current: &SourceMaps,
    camera: &Camera,
    joints_previous: &[[f64; 3]],
    joints_current: &[[f64; 3]],
    config: &TpsConfig,
) -> Result<(SourceMaps, TpsStats)> {
    config.check()?;
    check_frame(current, camera, joints_current, "current")?;
    check_frame(previous, camera, joints_previous, "previous")?;
    check_layouts(previous, current)?;
    if joints_previous.len() != joints_current.len() {
        return Err(arg(format!(
            "{} previous joints but {} current ones",
            joints_previous.len(),
            joints_current.len()
        )));
    }
    let motion = Motion::new(camera, joints_previous, joints_current, config);
    let matches: Vec<Option<Match>> = (0..current.pixels())
        .into_par_iter()
        .map(|p| motion.find(previous, current, p))
        .collect();
    let out = blend(previous, current, &matches);
    Ok((out, stats(current, &matches)))
}

/// Keeps the last stabilised maps per source camera over a sequence of frames.
#[derive(Clone, Debug)]
pub struct Stabilizer {
    config: TpsConfig,
    state: HashMap<usize, (usize, SourceMaps, Vec<[f64; 3]>)>,
}

impl Stabilizer {
    pub fn new(config: TpsConfig) -> Self {
        Self {
            config,
            state: HashMap::new(),
        }
    }

    pub fn config(&self) -> &TpsConfig {
        &self.config
    }

    /// Forgets every camera's history (e.g. at a cut to another sequence).
    pub fn reset(&mut self) {
        self.state.clear();
    }

    /// Stabilises `maps` of source camera `camera_index` at `frame` against that camera's
    /// stored maps when they are of `frame − 1`; otherwise passes `maps` through unchanged
    /// (nothing blended). Either way the result becomes the camera's history. On an error the
    /// history is left as it was.
    pub fn apply(
        &mut self,
        camera_index: usize,
        frame: usize,
        camera: &Camera,
        maps: SourceMaps,
        joints: &[[f64; 3]],
    ) -> Result<(SourceMaps, TpsStats)> {
        let (out, stats) = match self.state.get(&camera_index) {
            Some((f, prev, prev_joints)) if f.checked_add(1) == Some(frame) => {
                stabilize(prev, &maps, camera, prev_joints, joints, &self.config)?
            }
            _ => pass_through(maps, camera, joints, &self.config)?,
        };
        let stored = (frame, out.clone(), joints.to_vec());
        self.state.insert(camera_index, stored);
        Ok((out, stats))
    }
}

/// `maps` unchanged, after the checks [`stabilize`] would make.
fn pass_through(
    maps: SourceMaps,
    camera: &Camera,
    joints: &[[f64; 3]],
    config: &TpsConfig,
) -> Result<(SourceMaps, TpsStats)> {
    config.check()?;
    check_frame(&maps, camera, joints, "current")?;
    let stats = TpsStats {
        pixels: maps.foreground(),
        blended: 0,
        mean_weight: 0.0,
    };
    Ok((maps, stats))
}

fn arg(message: String) -> HumanError {
    HumanError::argument("temporal pose stabilizer", message)
}

/// An error unless `maps` is consistent, of the camera's size, and `joints` are finite and some.
fn check_frame(maps: &SourceMaps, camera: &Camera, joints: &[[f64; 3]], what: &str) -> Result<()> {
    maps.check(&format!("{what} maps"))?;
    let (w, h) = (camera.width() as usize, camera.height() as usize);
    if (maps.width, maps.height) != (w, h) {
        return Err(arg(format!(
            "{what} maps are {}×{} but the camera is {w}×{h} (use Camera::resized)",
            maps.width, maps.height
        )));
    }
    if joints.is_empty() {
        return Err(arg(format!("{what} joints: none given")));
    }
    if let Some(i) = joints.iter().position(|j| j.iter().any(|c| !c.is_finite())) {
        return Err(arg(format!(
            "{what} joint {i} is not finite: {:?}",
            joints[i]
        )));
    }
    Ok(())
}

/// An error unless both frames' maps have the same size and channels.
fn check_layouts(previous: &SourceMaps, current: &SourceMaps) -> Result<()> {
    let layout = |m: &SourceMaps| (m.width, m.height, m.channels, m.quaternion.clone());
    if layout(previous) != layout(current) {
        return Err(arg(format!(
            "previous maps (width, height, channels, quaternion) {:?} differ from current {:?}",
            layout(previous),
            layout(current)
        )));
    }
    Ok(())
}

/// Where a current pixel's previous values are and how much of them it takes.
#[derive(Clone, Copy, Debug)]
struct Match {
    /// Index of `p'` in the previous maps.
    previous: usize,
    weight: f32,
    /// The previous depth carried along by the motion.
    depth: f64,
}

/// The skeleton's motion between the two frames, as seen by one camera.
struct Motion<'a> {
    camera: &'a Camera,
    config: &'a TpsConfig,
    joints: Vec<Vector3<f64>>,
    deltas: Vec<Vector3<f64>>,
}

impl<'a> Motion<'a> {
    /// Joint counts must already be known equal.
    fn new(
        camera: &'a Camera,
        previous: &[[f64; 3]],
        current: &[[f64; 3]],
        config: &'a TpsConfig,
    ) -> Self {
        let joints: Vec<_> = current.iter().map(|j| Vector3::from(*j)).collect();
        let deltas = joints
            .iter()
            .zip(previous)
            .map(|(j, p)| j - Vector3::from(*p))
            .collect();
        Self {
            camera,
            config,
            joints,
            deltas,
        }
    }

    /// Index of the joint nearest `x`.
    fn nearest(&self, x: &Vector3<f64>) -> usize {
        let mut best = (0, f64::INFINITY);
        for (i, j) in self.joints.iter().enumerate() {
            let d = (j - x).norm_squared();
            if d < best.1 {
                best = (i, d);
            }
        }
        best.0
    }

    /// Steps 1–4 of the module docs for current pixel `p`; `None` when `p` is background, has
    /// no valid depth, or its warped pixel is outside, background or at another depth.
    fn find(&self, previous: &SourceMaps, current: &SourceMaps, p: usize) -> Option<Match> {
        let d = current.depth[p] as f64;
        let valid = current.mask[p] && d > 0.0 && d.is_finite();
        if !valid {
            return None;
        }
        let (x, y) = ((p % current.width) as f64, (p / current.width) as f64);
        let point = self.camera.unproject(x + 0.5, y + 0.5, d);
        let j = self.nearest(&point);
        let delta = self.deltas[j];
        let (u, v, z) = self.camera.project(&(point - delta))?;
        let q = pixel_at(u, v, previous.width, previous.height)?;
        let dp = previous.depth[q] as f64;
        let tolerance = self.config.depth_tolerance as f64;
        if !previous.mask[q] || !((dp - z).abs() <= tolerance) {
            return None;
        }
        let dz = (self.camera.world_to_camera.rotation * delta).z;
        Some(Match {
            previous: q,
            weight: self.config.weight(delta.norm()),
            depth: dp + dz,
        })
    }
}

/// Index of the pixel containing pixel coordinates `(u, v)`; `None` outside the image.
fn pixel_at(u: f64, v: f64, width: usize, height: usize) -> Option<usize> {
    let inside = u >= 0.0 && v >= 0.0 && u < width as f64 && v < height as f64;
    inside.then(|| v.floor() as usize * width + u.floor() as usize)
}

/// Step 5 of the module docs: `current` with every matched pixel blended.
fn blend(previous: &SourceMaps, current: &SourceMaps, matches: &[Option<Match>]) -> SourceMaps {
    let mut out = current.clone();
    let n = current.pixels();
    let quaternion = current.quaternion.clone().unwrap_or(0..0);
    for (p, m) in matches.iter().enumerate() {
        let Some(m) = m else { continue };
        let w = m.weight;
        let d = current.depth[p] as f64;
        out.depth[p] = ((1.0 - w as f64) * d + w as f64 * m.depth) as f32;
        for c in (0..current.channels).filter(|c| !quaternion.contains(c)) {
            let (a, b) = (
                current.values[c * n + p],
                previous.values[c * n + m.previous],
            );
            out.values[c * n + p] = (1.0 - w) * a + w * b;
        }
        if !quaternion.is_empty() {
            blend_quaternion(&mut out.values, previous, quaternion.start, p, m);
        }
    }
    out
}

/// The quaternion at channels `start..start + 4` of pixel `p` in `values` (which hold the
/// current maps) blended with the previous one, sign-aligned, and renormalised; left as it is
/// if the blend has no length.
fn blend_quaternion(values: &mut [f32], previous: &SourceMaps, start: usize, p: usize, m: &Match) {
    let n = previous.pixels();
    let index = |c: usize, pixel: usize| (start + c) * n + pixel;
    let a: [f64; 4] = std::array::from_fn(|c| values[index(c, p)] as f64);
    let b: [f64; 4] = std::array::from_fn(|c| previous.values[index(c, m.previous)] as f64);
    let dot: f64 = (0..4).map(|c| a[c] * b[c]).sum();
    let sign = if dot < 0.0 { -1.0 } else { 1.0 };
    let w = m.weight as f64;
    let q: [f64; 4] = std::array::from_fn(|c| (1.0 - w) * a[c] + w * sign * b[c]);
    let norm = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    if norm > 0.0 && norm.is_finite() {
        for c in 0..4 {
            values[index(c, p)] = (q[c] / norm) as f32;
        }
    }
}

/// Counts of the current foreground and the matched pixels, and the matched pixels' mean weight.
fn stats(current: &SourceMaps, matches: &[Option<Match>]) -> TpsStats {
    let weights: Vec<f32> = matches.iter().flatten().map(|m| m.weight).collect();
    let sum: f64 = weights.iter().map(|&w| w as f64).sum();
    let mean_weight = if weights.is_empty() {
        0.0
    } else {
        (sum / weights.len() as f64) as f32
    };
    TpsStats {
        pixels: current.foreground(),
        blended: weights.len(),
        mean_weight,
    }
}

#[cfg(test)]
mod tests {
    use fewview_scene::{Intrinsics, Se3};

    use super::*;

    const SIZE: usize = 16;
    const N: usize = SIZE * SIZE;

    /// Focal 100 px looking down world +z from `(−0.1, 0.2, −0.5)`: at camera depth 2 m one pixel
    /// is 2 cm.
    fn camera() -> Camera {
        let k = Intrinsics::centered(100.0, SIZE as u32, SIZE as u32);
        let pose = Se3::new(nalgebra::Matrix3::identity(), Vector3::new(0.1, -0.2, 0.5));
        Camera::new(k, pose)
    }

    /// A fronto-parallel plane at camera depth `depth` filling the image; channel `c` of the
    /// pixel whose centre lies on the plane at world point `x` is `value(c, x)`.
    fn plane(
        depth: f64,
        channels: usize,
        value: impl Fn(usize, &Vector3<f64>) -> f32,
    ) -> SourceMaps {
        let cam = camera();
        let mut values = vec![0.0; channels * N];
        for p in 0..N {
            let (x, y) = ((p % SIZE) as f64 + 0.5, (p / SIZE) as f64 + 0.5);
            let point = cam.unproject(x, y, depth);
            for c in 0..channels {
                values[c * N + p] = value(c, &point);
            }
        }
        SourceMaps {
            width: SIZE,
            height: SIZE,
            mask: vec![true; N],
            depth: vec![depth as f32; N],
            channels,
            values,
            quaternion: None,
        }
    }

    fn constant(depth: f64, value: f32) -> SourceMaps {
        plane(depth, 1, |_, _| value)
    }

    fn skeleton() -> Vec<[f64; 3]> {
        vec![[0.0, 0.0, 1.5], [0.1, 0.05, 1.5], [-0.1, -0.08, 1.6]]
    }

    fn moved(joints: &[[f64; 3]], d: [f64; 3]) -> Vec<[f64; 3]> {
        joints
            .iter()
            .map(|j| [j[0] + d[0], j[1] + d[1], j[2] + d[2]])
            .collect()
    }

    fn pattern(x: &Vector3<f64>) -> f32 {
        ((7.0 * x.x).sin() + (5.0 * x.y).cos() + x.x * x.y) as f32
    }

    fn strong() -> TpsConfig {
        TpsConfig {
            max_weight: 1.0,
            speed_scale: 1.0,
            depth_tolerance: 0.05,
        }
    }

    #[test]
    fn still_skeleton_and_identical_maps_change_nothing() {
        let mut maps = plane(2.0, 5, |c, x| if c == 0 { pattern(x) } else { 0.5 });
        maps.quaternion = Some(1..5);
        for p in [0, 37, 200] {
            maps.mask[p] = false;
            maps.depth[p] = 0.0;
        }
        let j = skeleton();
        let (out, stats) =
            stabilize(&maps, &maps, &camera(), &j, &j, &TpsConfig::default()).expect("stabilize");
        assert_eq!(out, maps);
        assert_eq!(stats.pixels, N - 3);
        assert_eq!(stats.blended, N - 3);
        assert_eq!(stats.mean_weight, 0.5);
    }

    #[test]
    fn rigid_motion_is_aligned_by_the_warp() {
        // 4 cm right and 2 cm up at 2 m: the image moves by exactly (2, −1) pixels.
        let delta = Vector3::new(0.04, -0.02, 0.0);
        let previous = plane(2.0, 2, |c, x| pattern(x) + c as f32);
        let current = plane(2.0, 2, |c, x| pattern(&(x - delta)) + c as f32);
        let unaligned = (0..N)
            .map(|p| (previous.values[p] - current.values[p]).abs())
            .fold(0.0, f32::max);
        assert!(unaligned > 0.1, "the test needs content that moves");
        let (j0, j1) = (skeleton(), moved(&skeleton(), delta.into()));
        let (out, stats) =
            stabilize(&previous, &current, &camera(), &j0, &j1, &strong()).expect("stabilize");
        assert_eq!(stats.pixels, N);
        assert_eq!(stats.blended, (SIZE - 2) * (SIZE - 1));
        assert!((stats.mean_weight - (-delta.norm()).exp() as f32).abs() < 1e-6);
        for (a, b) in out.values.iter().zip(&current.values) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
        assert!(out.depth.iter().all(|&d| (d - 2.0).abs() < 1e-6));
    }

    #[test]
    fn depth_is_carried_along_the_motion() {
        // The plane recedes from 1.9 m to 2 m; the previous depth moved by Δ is the current one.
        let (previous, current) = (constant(1.9, 1.0), constant(2.0, 0.0));
        let (j0, j1) = (skeleton(), moved(&skeleton(), [0.0, 0.0, 0.1]));
        let (out, stats) =
            stabilize(&previous, &current, &camera(), &j0, &j1, &strong()).expect("stabilize");
        let w = (-0.1f64).exp() as f32;
        assert_eq!(stats.blended, N);
        assert!((stats.mean_weight - w).abs() < 1e-6);
        assert!(out.depth.iter().all(|&d| (d - 2.0).abs() < 1e-6));
        assert!(out.values.iter().all(|&v| (v - w).abs() < 1e-6));
    }

    #[test]
    fn fast_motion_keeps_the_current_maps() {
        // 30 cm a frame is 15 speed scales: w = 0.5 e^−15.
        let (previous, current) = (constant(1.7, 1.0), constant(2.0, 0.0));
        let (j0, j1) = (skeleton(), moved(&skeleton(), [0.0, 0.0, 0.3]));
        let config = TpsConfig::default();
        let (out, stats) =
            stabilize(&previous, &current, &camera(), &j0, &j1, &config).expect("stabilize");
        let w = 0.5 * (-15.0f64).exp();
        assert!(stats.blended > 0 && stats.blended < N);
        assert!(((stats.mean_weight as f64 - w) / w).abs() < 1e-5);
        assert!(out.values.iter().all(|&v| (0.0..1e-6).contains(&v)));
        assert!(out.depth.iter().all(|&d| (d - 2.0).abs() < 1e-6));
    }

    #[test]
    fn inconsistent_previous_pixels_leave_the_current_ones() {
        let (mut previous, mut current) = (constant(2.0, 1.0), constant(2.0, 0.0));
        let (background, outside, far, near, no_depth) = (0, 17, 40, 60, 90);
        current.mask[background] = false;
        previous.mask[outside] = false;
        previous.depth[far] = 2.06;
        previous.depth[near] = 2.04;
        current.depth[no_depth] = f32::NAN;
        let j = skeleton();
        let config = TpsConfig::default();
        let (out, stats) =
            stabilize(&previous, &current, &camera(), &j, &j, &config).expect("stabilize");
        assert_eq!(stats.pixels, N - 1);
        assert_eq!(stats.blended, N - 4);
        for p in [background, outside, far, no_depth] {
            assert_eq!(out.values[p], 0.0, "pixel {p}");
        }
        assert!(out.depth[no_depth].is_nan());
        assert_eq!(out.depth[far], 2.0);
        assert!((out.depth[near] - 2.02).abs() < 1e-6);
        let rest = (0..N).filter(|p| ![background, outside, far, no_depth].contains(p));
        assert!(rest.map(|p| out.values[p]).all(|v| v == 0.5));
    }

    #[test]
    fn quaternions_stay_unit_and_sign_aligned() {
        let unit = |q: [f64; 4]| {
            let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
            q.map(|x| x / n)
        };
        let (a, b) = (unit([1.0, 0.2, -0.1, 0.3]), unit([0.9, 0.3, 0.0, 0.2]));
        let mut current = plane(2.0, 4, |c, _| a[c] as f32);
        let mut previous = plane(2.0, 4, |c, _| -b[c] as f32);
        current.quaternion = Some(0..4);
        previous.quaternion = Some(0..4);
        let expected = unit(std::array::from_fn(|c| 0.5 * a[c] + 0.5 * b[c]));
        let j = skeleton();
        let config = TpsConfig::default();
        let (out, stats) =
            stabilize(&previous, &current, &camera(), &j, &j, &config).expect("stabilize");
        assert_eq!(stats.blended, N);
        for p in 0..N {
            let q: [f64; 4] = std::array::from_fn(|c| out.values[c * N + p] as f64);
            let norm = q.iter().map(|x| x * x).sum::<f64>().sqrt();
            assert!((norm - 1.0).abs() < 1e-6);
            assert!((0..4).map(|c| q[c] * a[c]).sum::<f64>() > 0.0);
            assert!((0..4).all(|c| (q[c] - expected[c]).abs() < 1e-6));
        }
    }

    #[test]
    fn stabilizer_blends_consecutive_frames_only() {
        let (cam, j) = (camera(), skeleton());
        let mut s = Stabilizer::new(TpsConfig::default());
        let first = constant(2.0, 0.25);
        let (out, stats) = s.apply(0, 0, &cam, first.clone(), &j).expect("frame 0");
        assert_eq!((out, stats.blended), (first, 0));
        // Frame 1 is missing: frame 2 passes through unchanged.
        let (out, stats) = s
            .apply(0, 2, &cam, constant(2.0, 1.0), &j)
            .expect("frame 2");
        assert_eq!((out, stats.blended), (constant(2.0, 1.0), 0));
        assert_eq!((stats.pixels, stats.mean_weight), (N, 0.0));
        // Another camera has no history yet.
        let (out, stats) = s
            .apply(1, 3, &cam, constant(2.0, 0.0), &j)
            .expect("camera 1");
        assert_eq!((out, stats.blended), (constant(2.0, 0.0), 0));
        // A failed frame leaves the history: frame 3 still blends with frame 2.
        assert!(s.apply(0, 3, &cam, constant(2.0, 0.0), &j[..2]).is_err());
        let (out, stats) = s
            .apply(0, 3, &cam, constant(2.0, 0.0), &j)
            .expect("frame 3");
        assert_eq!(stats.blended, N);
        assert!(out.values.iter().all(|&v| v == 0.5));
    }

    #[test]
    fn bad_arguments_are_errors() {
        let (cam, j) = (camera(), skeleton());
        let maps = constant(2.0, 0.0);
        let config = TpsConfig::default();
        let is_argument =
            |r: Result<(SourceMaps, TpsStats)>| matches!(r, Err(HumanError::Argument { .. }));
        assert!(is_argument(stabilize(
            &maps,
            &maps,
            &cam,
            &j,
            &j[..2],
            &config
        )));
        let small = cam.resized(8, 8);
        assert!(is_argument(stabilize(
            &maps, &maps, &small, &j, &j, &config
        )));
        let mut short = maps.clone();
        short.depth.pop();
        assert!(is_argument(stabilize(&short, &maps, &cam, &j, &j, &config)));
        let mut quaternion = plane(2.0, 4, |_, _| 0.5);
        quaternion.quaternion = Some(1..4);
        assert!(is_argument(stabilize(
            &quaternion,
            &quaternion,
            &cam,
            &j,
            &j,
            &config
        )));
        let other = plane(2.0, 4, |_, _| 0.5);
        assert!(is_argument(stabilize(&maps, &other, &cam, &j, &j, &config)));
        let bad = TpsConfig {
            max_weight: f32::NAN,
            ..config.clone()
        };
        assert!(is_argument(stabilize(&maps, &maps, &cam, &j, &j, &bad)));
        assert!(is_argument(stabilize(
            &maps,
            &maps,
            &cam,
            &[],
            &[],
            &config
        )));
    }
}
