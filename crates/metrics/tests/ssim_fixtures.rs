//! SSIM and PSNR against scikit-image and the Inria 3DGS loss on committed fixtures
//! (made by `tools/make_ssim_fixtures.py`; see its header for the command).

use std::path::PathBuf;

use fewview_metrics::{SsimOptions, psnr, ssim, ssim_with};
use fewview_scene::Image;

fn fixtures() -> (PathBuf, serde_json::Value) {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/ssim");
    let text = std::fs::read_to_string(dir.join("expected.json")).expect("fixture JSON");
    (dir, serde_json::from_str(&text).expect("valid JSON"))
}

#[test]
fn ssim_and_psnr_match_the_reference_tools() {
    let (dir, expected) = fixtures();
    let pairs = expected["pairs"].as_array().unwrap();
    assert!(pairs.len() >= 8);
    let mut channels_seen = std::collections::BTreeSet::new();
    for pair in pairs {
        let a = Image::load(&dir.join(pair["a"].as_str().unwrap())).unwrap();
        let b = Image::load(&dir.join(pair["b"].as_str().unwrap())).unwrap();
        assert_eq!(a.width as u64, pair["width"].as_u64().unwrap());
        assert_eq!(a.channels as u64, pair["channels"].as_u64().unwrap());
        channels_seen.insert(a.channels);
        let name = pair["a"].as_str().unwrap();

        let s = ssim(&a, &b).unwrap();
        let want = pair["ssim_skimage"].as_f64().unwrap();
        assert!(
            (s - want).abs() < 1e-4,
            "{name}: skimage SSIM {want}, ours {s}"
        );
        // f32 working precision: the agreement is in fact far tighter than the 1e-4 contract.
        assert!(
            (s - want).abs() < 2e-6,
            "{name}: skimage SSIM {want}, ours {s}"
        );

        let s = ssim_with(&a, &b, &SsimOptions::training_loss()).unwrap();
        let want = pair["ssim_inria"].as_f64().unwrap();
        assert!(
            (s - want).abs() < 2e-6,
            "{name}: Inria SSIM {want}, ours {s}"
        );

        let p = psnr(&a, &b).unwrap();
        let want = pair["psnr"].as_f64().unwrap();
        assert!((p - want).abs() < 1e-4, "{name}: PSNR {want}, ours {p}");
    }
    assert!(channels_seen.contains(&1) && channels_seen.contains(&3));
}
