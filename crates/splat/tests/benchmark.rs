//! The benchmark protocols' splits, sizes and masks on the shared scenes against the protocols
//! as RegNeRF defines them (`FEWVIEW_DATA`).

use std::path::PathBuf;

use fewview_scene::Image;
use fewview_scene::split::DTU_TEST_VIEWS;
use fewview_splat::benchmark::Protocol;
use fewview_splat::benchmark::masked::interior;

fn data_dir() -> PathBuf {
    PathBuf::from(
        std::env::var_os("FEWVIEW_DATA")
            .expect("FEWVIEW_DATA must name the shared data folder (e.g. ../shared/data)"),
    )
}

fn size(ds: &fewview_scene::Dataset) -> (usize, usize) {
    let image = &ds.views[ds.train[0]].image;
    (image.width, image.height)
}

#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn llff_trains_on_three_evenly_spaced_views_and_holds_out_every_eighth() {
    let ds = Protocol::Llff.load(&data_dir().join("llff/fern")).unwrap();
    assert_eq!(ds.train, vec![1, 10, 19]);
    assert_eq!(ds.test, vec![0, 8, 16]);
    assert_eq!(size(&ds), (504, 378));
}

#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn dtu_trains_on_25_22_28_and_scores_the_test_views_inside_their_masks() {
    let ds = Protocol::Dtu.load(&data_dir().join("dtu/scan65")).unwrap();
    assert_eq!(ds.train, vec![25, 22, 28]);
    assert_eq!(ds.test, DTU_TEST_VIEWS.to_vec());
    assert_eq!(size(&ds), (400, 300));
    for v in ds.test_views() {
        let mask = v.mask.as_ref().expect("a mask on every test view");
        assert_eq!((mask.width, mask.height), (400, 300));
    }
}

#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn blender_trains_on_eight_views_at_400_pixels() {
    let ds = Protocol::Blender
        .load(&data_dir().join("nerf_synthetic/lego"))
        .unwrap();
    assert_eq!(ds.train.len(), 8);
    assert_eq!(size(&ds), (400, 400));
    assert!(!ds.test.is_empty());
}

/// The interior the DTU PSNR is taken over ([`fewview_splat::benchmark::masked::interior`])
/// against the peers' rule on the same masks: Pillow's bicubic resize to 400×300 and `== 1`
/// (fixtures by `tools/make_dtu_interior_fixtures.py`). The two may differ only along the
/// object's outline.
#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn the_dtu_interior_is_the_peers_resized_mask_that_is_exactly_one() {
    let fixtures = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/dtu_interior");
    let ds = Protocol::Dtu.load(&data_dir().join("dtu/scan65")).unwrap();
    for index in [1usize, 12, 33, 45] {
        let view = &ds.views[index];
        let ours = interior(view.mask.as_ref().unwrap());
        let peers = Image::load(&fixtures.join(format!("{index:03}.png"))).unwrap();
        assert_eq!((peers.width, peers.height), (400, 300));
        let in_peers = |p: usize| peers.data[p * peers.channels] > 0.5;
        let differing = (0..400 * 300)
            .filter(|&p| (ours.data[p] > 0.5) != in_peers(p))
            .count();
        let inside = (0..400 * 300).filter(|&p| in_peers(p)).count();
        assert!(inside > 30_000, "view {index}: {inside} interior pixels");
        assert!(
            differing * 100 < inside,
            "view {index}: {differing} of {inside} interior pixels differ"
        );
    }
}
