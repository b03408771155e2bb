//! The classical matcher ([`fewview_surface::matching::sift`]) on two views of the surface
//! method's analytic scene, scored by the symmetric epipolar distance under the exact cameras.

use fewview_surface::matching::sift::SiftMatcher;
use fewview_surface::matching::{MatchInput, epipolar_precision, match_all_pairs};
use fewview_surface::sdf_scene::{SdfSceneOptions, sdf_dataset};

#[test]
fn matches_on_the_analytic_scene_respect_the_true_epipolar_geometry() {
    let opts = SdfSceneOptions {
        width: 320,
        height: 240,
        views: 16,
        train: vec![0, 1],
        supersample: 2,
        fov_deg: 30.0,
        ..Default::default()
    };
    let ds = sdf_dataset(&opts);
    let inputs: Vec<MatchInput> = ds.views[..2]
        .iter()
        .map(|v| MatchInput {
            image: &v.image,
            mask: v.mask.as_ref(),
        })
        .collect();
    let matches = match_all_pairs(&SiftMatcher::default(), &inputs);
    let cams: Vec<_> = ds.views[..2].iter().map(|v| v.camera.clone()).collect();
    let p = epipolar_precision(&matches, &cams);
    assert!(p.matches >= 25, "{p:?}");
    assert!(p.precision_2px > 0.9, "{p:?}");
}
