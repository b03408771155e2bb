//! The contraction of the fusion paper Eq. (2), the choice of its reference camera and bounds, and
//! random subsampling of the point cloud for Gaussian initialisation (the fusion paper §2, §4(a)).
//!
//! **Eq. (2), literally.** `Contract(X) = X − T` when `d = ‖X − T‖ ≤ B_near`, else
//! `(X − T)·(B_far − B_near)/d`. The far branch has norm `B_far − B_near` whatever `d` is, so
//! with `B_far = 2 B_near` every far point lands on the sphere of radius `B_near` around `T`
//! (continuous at `d = B_near`). That is [`ContractionKind::Paper`], the default. The paper says
//! it is "inspired by Mip-NeRF 360"; Mip-NeRF 360's own map scaled to these bounds,
//! `(B_far − B_near²/d)·(X − T)/d` (far points spread over the shell `[B_near, B_far)`), is
//! [`ContractionKind::MipNerf360`].
//!
//! Eq. (2) returns the offset from `T`; [`Contraction::apply`] adds `T` back so the points stay
//! in the cameras' world frame ([`Contraction::offset`] is the bare Eq. (2)).
//!
//! **Choosing `T`, `B_near`, `B_far`.** The paper: "B_near is determined as the largest depth
//! value within the top 10 % of depths across all training views, and B_far is set to twice this
//! value. The camera containing B_near is identified as T." Read literally, the largest value
//! within the top 10 % is simply the maximum depth. We read it as the depth at the border of the
//! top 10 %: pool the valid (Eq. 1-filtered) depths of all views, sort them, and take the value
//! at quantile 0.9 (nearest rank, `⌈0.9·n⌉`-th smallest); `T` is the centre of the view that
//! holds that pixel. `quantile = 1.0` gives the literal maximum.

use fewview_scene::Camera;
use nalgebra::Vector3;
use rand::SeedableRng;
use rand::rngs::StdRng;

use crate::depth::{DepthOptions, valid_pixels};
use crate::error::{GeomError, Result};
use crate::mesh::{Points, f3, v3};

/// Which far-field map (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum ContractionKind {
    /// Eq. (2) as printed: far points onto the sphere of radius `B_far − B_near`.
    #[default]
    Paper,
    /// Mip-NeRF 360's contraction scaled to `[B_near, B_far)`.
    #[cfg_attr(feature = "cli", value(name = "mipnerf360"))]
    MipNerf360,
}

/// A contraction around a reference point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Contraction {
    /// `T`: the reference camera centre.
    pub center: Vector3<f64>,
    pub b_near: f64,
    pub b_far: f64,
    pub kind: ContractionKind,
    /// Index of the view `T` belongs to (when chosen by [`contraction_reference`]).
    pub view: Option<usize>,
}

impl Contraction {
    /// Eq. (2): the contracted offset from `T`.
    pub fn offset(&self, x: &Vector3<f64>) -> Vector3<f64> {
        let o = x - self.center;
        let d = o.norm();
        if d <= self.b_near {
            return o;
        }
        match self.kind {
            ContractionKind::Paper => o * ((self.b_far - self.b_near) / d),
            ContractionKind::MipNerf360 => o * ((self.b_far - self.b_near * self.b_near / d) / d),
        }
    }

    /// `T + Contract(X)`: the contracted point in world coordinates.
    pub fn apply(&self, x: &Vector3<f64>) -> Vector3<f64> {
        self.center + self.offset(x)
    }
}

/// Contracts points (world frame in and out) around `t_ref` with Eq. (2).
pub fn contract(
    points: &[[f32; 3]],
    t_ref: &Vector3<f64>,
    b_near: f64,
    b_far: f64,
    kind: ContractionKind,
) -> Vec<[f32; 3]> {
    let c = Contraction {
        center: *t_ref,
        b_near,
        b_far,
        kind,
        view: None,
    };
    points.iter().map(|p| f3(&c.apply(&v3(p)))).collect()
}

/// Chooses `T`, `B_near` and `B_far = 2·B_near` from the training views' depth maps (see the
/// module docs; `quantile` 0.9 is our reading of "top 10 %").
pub fn contraction_reference(
    views: &[(&[f32], &Camera)],
    options: &DepthOptions,
    quantile: f64,
    kind: ContractionKind,
) -> Result<Contraction> {
    if !(0.0..=1.0).contains(&quantile) {
        return Err(GeomError::invalid(
            "quantile",
            format!("{quantile} is not in [0, 1]"),
        ));
    }
    let mut pooled: Vec<(f32, u32)> = Vec::new();
    for (v, (depth, cam)) in views.iter().enumerate() {
        let valid = valid_pixels(depth, cam, options)
            .map_err(|e| GeomError::invalid(format!("view {v}"), e.to_string()))?;
        pooled.extend(
            depth
                .iter()
                .zip(&valid)
                .filter(|(_, ok)| **ok)
                .map(|(&d, _)| (d, v as u32)),
        );
    }
    if pooled.is_empty() {
        return Err(GeomError::invalid(
            "depth maps",
            "no valid depth in any view",
        ));
    }
    let n = pooled.len();
    let rank = ((quantile * n as f64).ceil() as usize).clamp(1, n) - 1;
    let (_, &mut (b_near, view), _) =
        pooled.select_nth_unstable_by(rank, |a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let b_near = b_near as f64;
    Ok(Contraction {
        center: views[view as usize].1.center(),
        b_near,
        b_far: 2.0 * b_near,
        kind,
        view: Some(view as usize),
    })
}

/// A random subset of `round(fraction·n)` points, without replacement, in their original order
/// (the fusion paper: 10 % for our initialisation, 1 % for alternative (a)).
pub fn subsample(points: &Points, fraction: f64, seed: u64) -> Result<Points> {
    Ok(points.select(&sample_indices(points.len(), fraction, seed)?))
}

/// `round(fraction·n)` distinct indices below `n`, drawn with `seed`, in increasing order.
pub fn sample_indices(n: usize, fraction: f64, seed: u64) -> Result<Vec<usize>> {
    if !(0.0..=1.0).contains(&fraction) {
        return Err(GeomError::invalid(
            "fraction",
            format!("{fraction} is not in [0, 1]"),
        ));
    }
    let k = (fraction * n as f64).round() as usize;
    let mut rng = StdRng::seed_from_u64(seed);
    let mut idx = rand::seq::index::sample(&mut rng, n, k).into_vec();
    idx.sort_unstable();
    Ok(idx)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::depth::tests::test_camera;

    #[test]
    fn paper_contraction_is_identity_inside_and_a_sphere_outside() {
        let t = Vector3::new(1.0, 2.0, 3.0);
        let pts = [
            [1.5f32, 2.0, 3.0],
            [11.0, 2.0, 3.0],
            [1.0, 2.0, -97.0],
            [1.0, 4.0, 3.0],
        ];
        let out = contract(&pts, &t, 2.0, 4.0, ContractionKind::Paper);
        assert_eq!(out[0], pts[0]);
        assert_eq!(out[3], pts[3]); // d = B_near exactly: first branch
        for o in &out[1..3] {
            assert!(((v3(o) - t).norm() - 2.0).abs() < 1e-6);
        }
        assert!((v3(&out[1]) - Vector3::new(3.0, 2.0, 3.0)).norm() < 1e-6);
    }

    #[test]
    fn mipnerf_contraction_is_continuous_monotone_and_bounded() {
        let c = Contraction {
            center: Vector3::zeros(),
            b_near: 2.0,
            b_far: 4.0,
            kind: ContractionKind::MipNerf360,
            view: None,
        };
        let r = |d: f64| c.offset(&Vector3::new(d, 0.0, 0.0)).x;
        assert!((r(2.0 + 1e-9) - 2.0).abs() < 1e-6);
        assert!(r(3.0) < r(5.0) && r(5.0) < r(100.0) && r(1e9) < 4.0);
        assert!((r(4.0) - 3.0).abs() < 1e-12); // 4 − 4/4
    }

    #[test]
    fn reference_is_the_ninetieth_percentile_view() {
        let cam_a = test_camera(10, 10, 300.0);
        let mut cam_b = test_camera(10, 10, 300.0);
        cam_b.world_to_camera.translation.x += 5.0;
        // View a: depths 1..=100 in steps of 1 (row-major); view b: all 50.
        let a: Vec<f32> = (1..=100).map(|v| v as f32).collect();
        let b = vec![50.0f32; 100];
        let opts = DepthOptions {
            tau: 0.0,
            ..Default::default()
        };
        let c = contraction_reference(
            &[(&a, &cam_a), (&b, &cam_b)],
            &opts,
            0.9,
            ContractionKind::Paper,
        )
        .unwrap();
        // 200 depths; rank ⌈180⌉ = 180th smallest. Sorted: 1..49 (49), then 101 fifties, then
        // 51..100: the 180th is 49 + 101 + 30 = 180 → 80.
        assert_eq!(c.b_near, 80.0);
        assert_eq!(c.b_far, 160.0);
        assert_eq!(c.view, Some(0));
        assert!((c.center - cam_a.center()).norm() < 1e-12);
        let max = contraction_reference(
            &[(&a, &cam_a), (&b, &cam_b)],
            &opts,
            1.0,
            ContractionKind::Paper,
        )
        .unwrap();
        assert_eq!(max.b_near, 100.0);
        let none = vec![0.0f32; 100];
        assert!(
            contraction_reference(&[(&none, &cam_a)], &opts, 0.9, ContractionKind::Paper).is_err()
        );
    }

    #[test]
    fn subsample_is_seeded_and_sized() {
        let pts = Points::from_positions((0..1000).map(|i| [i as f32, 0.0, 0.0]).collect());
        let a = subsample(&pts, 0.1, 7).unwrap();
        let b = subsample(&pts, 0.1, 7).unwrap();
        let c = subsample(&pts, 0.1, 8).unwrap();
        assert_eq!(a.len(), 100);
        assert_eq!(a, b);
        assert_ne!(a, c);
        assert_eq!(subsample(&pts, 0.01, 1).unwrap().len(), 10);
        assert!(a.positions.windows(2).all(|w| w[0][0] < w[1][0]));
    }
}
