//! Which source views render a target camera. "PoseGaussian: Pose-Driven Novel View Synthesis
//! for Robust 3D Human Reconstruction" builds on GPS-Gaussian, which renders a novel view from
//! the two source views that flank it; the paper does not say how they are found. Here they are
//! the `count` input cameras nearest the target, by one of two measures ([`Nearness`]).

use fewview_scene::Camera;

use crate::error::{HumanError, Result};

/// How near a source camera is to a target camera.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Nearness {
    /// The angle between the optical axes (the default): on a ring of cameras looking at the
    /// person it is the angle between the cameras seen from the person, and it needs no centre
    /// of the scene. Ties go to the nearer centre.
    ViewDirection,
    /// The distance between camera centres. Ties go to the smaller angle.
    CentreDistance,
}

/// The `count` cameras of `inputs` (indices into `cameras`) nearest `target`, nearest first;
/// remaining ties go to the lower index. A target that is itself among `inputs` comes first.
pub fn nearest_sources(
    target: &Camera,
    cameras: &[Camera],
    inputs: &[usize],
    count: usize,
    nearness: Nearness,
) -> Result<Vec<usize>> {
    if count == 0 || count > inputs.len() {
        let m = format!("{count} source views of {} input cameras", inputs.len());
        return Err(HumanError::argument("source views", m));
    }
    if let Some(&c) = inputs.iter().find(|&&c| c >= cameras.len()) {
        let m = format!("input camera {c} of {} cameras", cameras.len());
        return Err(HumanError::argument("source views", m));
    }
    let key = |c: usize| {
        let angle = target.forward().angle(&cameras[c].forward());
        let distance = (target.center() - cameras[c].center()).norm();
        match nearness {
            Nearness::ViewDirection => (angle, distance),
            Nearness::CentreDistance => (distance, angle),
        }
    };
    let mut ranked: Vec<(f64, f64, usize)> = inputs
        .iter()
        .map(|&c| {
            let (a, b) = key(c);
            (a, b, c)
        })
        .collect();
    ranked.sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
    Ok(ranked.into_iter().take(count).map(|(_, _, c)| c).collect())
}
