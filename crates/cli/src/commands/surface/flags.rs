//! The `surface` command's flags that are not plain values: their parsers, the switches and
//! names they take, and their translation into the library's settings.

use clap::ValueEnum;
use fewview_surface::adam::ExpSchedule;
use fewview_surface::matching::refine::WarpModel;

use crate::commands::number_args::{non_negative, non_negative_f32, number_pair};

/// The largest `--pose-noise`. σ is the standard deviation of every se(3) component: radians
/// for the rotation and units of the normalised scene (radius 1) for the translation. At σ = π
/// the rotations are already close to uniformly random and the cameras land several scene
/// radii away, so a larger σ describes no pose refinement problem (1e300 used to reach the
/// pose sampler and fail after the run folder was written).
const MAX_POSE_NOISE: f64 = std::f64::consts::PI;

/// `--pose-noise`: a finite σ in [0, [`MAX_POSE_NOISE`]].
pub(super) fn pose_noise(s: &str) -> Result<f64, String> {
    match non_negative(s)? {
        v if v <= MAX_POSE_NOISE => Ok(v),
        _ => Err(format!("{s}: expected σ ≤ π (radians of rotation noise)")),
    }
}

/// The largest `--mesh-resolution`. Marching cubes evaluates the field at n³ grid points and
/// the mesh grows as n²: at 2048 that is 8.6·10⁹ field evaluations (hours on a CPU) and tens of
/// millions of triangles (gigabytes), 4× the 512 NeuS meshes at; 100000 ran for ever.
pub(super) const MAX_MESH_RESOLUTION: i64 = 2048;

/// `on` or `off` for a stage whose default comes from `--schedule`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Toggle {
    On,
    Off,
}

/// A loss term `--no-loss` switches off ([`LossSwitches`](fewview_surface::LossSwitches); `gc`: geometric consistency).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum LossTerm {
    Matching,
    Ncc,
    Gc,
    Uncertainty,
    Psdf,
    Eikonal,
}

/// The λ that `--lambda NAME=VALUE` sets ([`LossWeights`](fewview_surface::LossWeights)).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum WeightName {
    Mc,
    U,
    Gc,
    Geo,
    Psdf,
}

/// `NAME=VALUE` of `--lambda`.
pub(super) fn loss_weight(s: &str) -> std::result::Result<(WeightName, f32), String> {
    use clap::ValueEnum;
    let (name, value) = s
        .split_once('=')
        .ok_or_else(|| format!("{s}: expected NAME=VALUE, e.g. u=0.02"))?;
    let name = WeightName::from_str(name.trim(), true)
        .map_err(|_| format!("{s}: unknown weight {name:?} (mc, u, gc, geo, psdf)"))?;
    Ok((name, non_negative_f32(value.trim())?))
}

/// `--match-refine`: the warp model of the sub-pixel refinement (the library's [`WarpModel`], by
/// its own names), or `none`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MatchRefine(pub Option<WarpModel>);

/// Parses `--match-refine`: `none`, or a [`WarpModel`] name.
pub(super) fn match_refine(s: &str) -> Result<MatchRefine, String> {
    if s == "none" {
        return Ok(MatchRefine(None));
    }
    WarpModel::from_str(s, false)
        .map(|w| MatchRefine(Some(w)))
        .map_err(|_| {
            let names: Vec<String> = WarpModel::value_variants()
                .iter()
                .filter_map(|w| w.to_possible_value().map(|v| v.get_name().to_string()))
                .collect();
            format!("expected {} or none", names.join(", "))
        })
}

/// `--c2f`: 0 ≤ α₁ ≤ α₂ ≤ 1.
pub(super) fn c2f_window(s: &str) -> Result<(f64, f64), String> {
    let (a1, a2) = number_pair(s, "0.4,0.7")?;
    if !((0.0..=1.0).contains(&a1) && (0.0..=1.0).contains(&a2) && a1 <= a2) {
        return Err("expected 0 ≤ α₁ ≤ α₂ ≤ 1".into());
    }
    Ok((a1, a2))
}

/// `--pose-lr`: two positive rates.
pub(super) fn pose_rates(s: &str) -> Result<ExpSchedule, String> {
    let (start, end) = number_pair(s, "1e-3,1e-4")?;
    if !([start, end].iter().all(|r| r.is_finite() && *r > 0.0)) {
        return Err("expected two positive rates like 1e-3,1e-4".into());
    }
    Ok(ExpSchedule {
        start: start as f32,
        end: end as f32,
    })
}

/// `Some(true)` for `--x`, `Some(false)` for `--no-x`, `None` for neither (the schedule's).
pub(super) fn switch(toggle: Option<Toggle>) -> Option<bool> {
    toggle.map(|t| t == Toggle::On)
}
