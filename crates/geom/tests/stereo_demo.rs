//! The stereo start on the demo scene, whose ray tracer gives the exact depth of every pixel:
//! how close the hierarchical cloud's points lie to the true surface, per confidence tier.

// Tests report what they measured.
#![allow(clippy::print_stdout, clippy::print_stderr)]

use fewview_geom::stereo::hierarchy::{HierarchyOptions, Region, hierarchical_cloud};
use fewview_geom::stereo::pairs::{OverlapRule, StereoView, stereo_pairs};
use fewview_geom::stereo::sgm::SgmParams;
use fewview_geom::stereo::source::{DisparityRange, Photometry, SgmSource};
use fewview_scene::photometric::PhotoJitter;
use fewview_scene::synthetic::{DemoGloss, DemoOptions, demo_dataset, demo_depth};
use nalgebra::Vector3;

/// Per tier: points, and the fraction within 1 % of the true depth, and the median error, on
/// the default demo scene at `width`.
fn tier_accuracy(width: usize) -> Vec<(Region, usize, f64, f64)> {
    let opts = DemoOptions {
        width,
        height: width * 3 / 4,
        ..DemoOptions::default()
    };
    tier_accuracy_of(&opts, Photometry::default())
}

/// [`tier_accuracy`] of any demo scene, its pairs matched with `photometry`.
fn tier_accuracy_of(opts: &DemoOptions, photometry: Photometry) -> Vec<(Region, usize, f64, f64)> {
    let ds = demo_dataset(opts);
    let views: Vec<StereoView> = ds.train_views().map(StereoView::of).collect();
    let pairs = stereo_pairs(&views, &OverlapRule::default()).unwrap();
    let source = SgmSource {
        views: &views,
        params: SgmParams {
            paths: fewview_geom::stereo::sgm::Paths::Eight,
            ..Default::default()
        },
        range: DisparityRange::FromDepthBounds,
        refine: Some(Default::default()),
        photometry,
    };
    let options = HierarchyOptions {
        contraction: None,
        ..Default::default()
    };
    let cloud = hierarchical_cloud(&views, &pairs, &source, &options, &mut |_, _| {}).unwrap();
    let truth: Vec<Vec<f32>> = views.iter().map(|v| demo_depth(v.camera)).collect();
    let mut errors: [Vec<f64>; 3] = Default::default();
    for (k, &(v, p)) in cloud.sources.iter().enumerate() {
        let cam = views[v as usize].camera;
        let x = cloud.points.positions[k].map(|c| c as f64);
        let z = cam.world_to_camera.transform_point(&Vector3::from(x)).z;
        let t = truth[v as usize][p as usize] as f64;
        let rel = if t > 0.0 { (z - t) / t } else { f64::INFINITY };
        errors[cloud.regions[k] as usize].push(rel);
    }
    Region::ALL
        .iter()
        .zip(errors.iter_mut())
        .map(|(&r, e)| {
            e.sort_by(f64::total_cmp);
            eprintln!(
                "{r:?} signed quantiles: {:?}",
                [0.05, 0.25, 0.5, 0.75, 0.95]
                    .map(|q| e.get((q * e.len() as f64) as usize).copied().unwrap_or(0.0))
            );
            e.iter_mut().for_each(|x| *x = x.abs());
            e.sort_by(f64::total_cmp);
            let within = e.iter().filter(|&&x| x < 0.01).count() as f64 / e.len().max(1) as f64;
            let median = e.get(e.len() / 2).copied().unwrap_or(f64::NAN);
            (r, e.len(), within, median)
        })
        .collect()
}

#[test]
fn consistent_points_lie_within_one_percent_of_the_true_depth() {
    for width in [200, 400] {
        let tiers = tier_accuracy(width);
        for &(r, n, within, median) in &tiers {
            eprintln!(
                "demo {width}px {r:?}: {n} points, {:.1} % within 1 % of the true depth, median error {:.3} %",
                100.0 * within,
                100.0 * median
            );
        }
        let (_, n, within, _) = tiers[0];
        assert!(n > 5000, "{n} consistent points");
        assert!(within >= 0.95, "{within}");
    }
}

/// The demo scene with its highlight at full strength (0.4, 40) photographed with per-photo
/// exposure, white balance and vignetting.
fn jittered(exposure_ev: f64, vignetting: f64) -> DemoOptions {
    DemoOptions {
        width: 200,
        height: 150,
        gloss: DemoGloss {
            sphere: (0.4, 40.0),
            ..DemoGloss::default()
        },
        jitter: PhotoJitter {
            exposure_ev,
            white_balance: 0.05,
            vignetting,
            seed: 0,
        },
        ..DemoOptions::default()
    }
}

/// Consistent points and the fraction within 1 % of the true depth.
fn consistent(opts: &DemoOptions, photometry: Photometry) -> (usize, f64) {
    let (_, n, within, median) = tier_accuracy_of(opts, photometry)[0];
    eprintln!(
        "{:.1} EV, vignetting {:.1}, {photometry:?}: {n} consistent points, {:.1} % within 1 %, median {:.3} %",
        opts.jitter.exposure_ev,
        opts.jitter.vignetting,
        100.0 * within,
        100.0 * median
    );
    (n, within)
}

/// A phone's automatic exposure (0.5 EV, 5 % white balance) of a strong highlight: the
/// consistent points stay on the surface as on the photos that agree (the left–right check
/// keeps the moving highlight out); with 1.5 EV and vignetting, matching each pair's gains
/// first keeps more of them.
#[test]
fn jittered_photos_of_a_strong_highlight_still_give_consistent_points() {
    let (n, within) = consistent(&jittered(0.5, 0.0), Photometry::AsIs);
    assert!(n > 4000 && within >= 0.93, "{n} points, {within}");
    let strong = jittered(1.5, 0.4);
    let (as_is, _) = consistent(&strong, Photometry::AsIs);
    let (matched, within) = consistent(&strong, Photometry::GainMatched);
    assert!(within >= 0.93, "{within}");
    assert!(
        matched as f64 > 1.1 * as_is as f64,
        "{matched} points with matched gains, {as_is} as is"
    );
}

/// A demo view and a second one 1.2 units (about 30 % of the way to the scene) further along
/// its optical axis: rectification cannot serve the pair (the baseline is the axis), so the
/// stereo source sweeps planes in each view; of the consistent points of the pair's
/// hierarchical cloud, at least 85 % lie within 2 % of the exact depth and 95 % within 5 %
/// (the misses sit on the spheres' silhouettes and highlights).
#[test]
fn plane_sweep_finds_the_depth_of_a_camera_walking_forward() {
    use fewview_geom::stereo::source::{PairMethod, pair_method};
    use fewview_scene::synthetic::demo_render;
    let opts = DemoOptions {
        width: 320,
        height: 240,
        ..DemoOptions::default()
    };
    let ds = demo_dataset(&opts);
    let back = ds.views[ds.train[1]].camera.clone();
    let step = back.forward() * 1.2;
    let front = fewview_scene::Camera::new(
        back.intrinsics,
        fewview_scene::Se3::new(
            back.world_to_camera.rotation,
            back.world_to_camera.translation - back.world_to_camera.rotation * step,
        ),
    );
    assert!((front.center() - back.center() - step).norm() < 1e-9);
    assert!(matches!(
        pair_method(&back, &front),
        PairMethod::PlaneSweep(_)
    ));
    let images = [demo_render(&back, &opts), demo_render(&front, &opts)];
    let cameras = [&back, &front];
    let truth: Vec<Vec<f32>> = cameras.iter().map(|c| demo_depth(c)).collect();
    let seen: Vec<f32> = truth
        .iter()
        .flatten()
        .copied()
        .filter(|&z| z > 0.0)
        .collect();
    let near = seen.iter().copied().fold(f32::INFINITY, f32::min) as f64;
    let far = seen.iter().copied().fold(0.0, f32::max) as f64;
    let views: Vec<StereoView> = (0..2)
        .map(|i| StereoView {
            name: ["back", "front"][i],
            camera: cameras[i],
            image: &images[i],
            depth_bounds: Some((near, far)),
            mask: None,
            sparse_points: &[],
        })
        .collect();
    let source = SgmSource {
        views: &views,
        params: SgmParams {
            paths: fewview_geom::stereo::sgm::Paths::Eight,
            ..Default::default()
        },
        range: DisparityRange::FromSparsePoints,
        refine: Some(Default::default()),
        photometry: Photometry::AsIs,
    };
    let options = HierarchyOptions {
        contraction: None,
        ..Default::default()
    };
    let cloud = hierarchical_cloud(&views, &[(0, 1)], &source, &options, &mut |_, _| {}).unwrap();
    let mut errors: [Vec<f64>; 2] = Default::default();
    for (k, &(v, p)) in cloud.sources.iter().enumerate() {
        if cloud.regions[k] != Region::Consistent {
            continue;
        }
        let cam = cameras[v as usize];
        let x = cloud.points.positions[k].map(|c| c as f64);
        let z = cam.world_to_camera.transform_point(&Vector3::from(x)).z;
        let t = truth[v as usize][p as usize] as f64;
        errors[v as usize].push(if t > 0.0 {
            ((z - t) / t).abs()
        } else {
            f64::INFINITY
        });
    }
    let all: Vec<f64> = errors.iter().flatten().copied().collect();
    let share = |bound: f64| all.iter().filter(|&&e| e < bound).count() as f64 / all.len() as f64;
    eprintln!(
        "within 2 %: {:.3}, within 5 %: {:.3}",
        share(0.02),
        share(0.05)
    );
    for (k, e) in errors.iter().enumerate() {
        let scene = truth[k].iter().filter(|&&t| t > 0.0).count();
        eprintln!(
            "{}: {} consistent points ({:.1} % of the scene's pixels), {:.1} % within 2 %",
            views[k].name,
            e.len(),
            100.0 * e.len() as f64 / scene as f64,
            100.0 * e.iter().filter(|&&e| e < 0.02).count() as f64 / e.len() as f64
        );
    }
    assert!(share(0.02) >= 0.85 && share(0.05) >= 0.95);
    assert!(all.len() > 5000, "{} consistent points", all.len());
}
