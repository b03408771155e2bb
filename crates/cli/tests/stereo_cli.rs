//! `fewview stereo` and the stereo start of `train`/`demo` (`--init stereo`, `--init depth:DIR`)
//! on the demo scene: outputs, and bad input refused with one line before anything is written.

mod common;

use common::{assert_clean_error, fewview, fewview_ok, s};

#[test]
fn stereo_writes_the_pair_the_depths_and_the_cloud() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("pair");
    let run = fewview_ok(&["stereo", "--demo", "--views", "2,11", "--out", s(&out)]);
    let text = String::from_utf8_lossy(&run.stdout);
    assert!(
        text.contains("views            view_02 and view_11"),
        "{text}"
    );
    for f in [
        "rectified_left.png",
        "rectified_right.png",
        "disparity_left.npy",
        "disparity_left.png",
        "disparity_right.npy",
        "depth_view_02.npy",
        "depth_view_02.png",
        "depth_view_11.npy",
        "regions_view_02.png",
        "cloud.ply",
        "cloud_regions.ply",
        "stereo.json",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("stereo.json")).unwrap()).unwrap();
    let accepted: Vec<u64> = json["accepted"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    assert!(accepted[0] > 1000, "{accepted:?} consistent points");
    // The depth map is the first view's size (200×150), z-depth in scene units.
    let depth = fewview_geom::io::read_depth(&out.join("depth_view_02.npy"), 1.0).unwrap();
    assert_eq!((depth.width, depth.height), (200, 150));
    let valid: Vec<f32> = depth.depth.iter().copied().filter(|&d| d > 0.0).collect();
    assert!(
        valid.len() > 200 * 150 / 4,
        "{} pixels with depth",
        valid.len()
    );
    assert!(valid.iter().all(|&d| (2.0..12.0).contains(&d)));
}

#[test]
fn pairs_without_overlap_or_baseline_are_refused_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("never");
    // The ends of the demo's 50° arc: too far apart for block matching.
    let far = fewview(&["stereo", "--demo", "--views", "0,23", "--out", s(&out)]);
    assert_clean_error(&far, &["views view_00 and view_23", "do not overlap"]);
    // One view twice: no baseline.
    let same = fewview(&["stereo", "--demo", "--views", "5,5", "--out", s(&out)]);
    assert_clean_error(&same, &["view_05", "baseline"]);
    let one = fewview(&["stereo", "--demo", "--views", "5", "--out", s(&out)]);
    assert_clean_error(&one, &["exactly two views"]);
    let range = fewview(&["stereo", "--demo", "--views", "40,41", "--out", s(&out)]);
    assert_clean_error(&range, &["view 40 is out of range"]);
    assert!(!out.exists(), "a refused run wrote {}", out.display());
}

#[test]
fn depth_maps_of_the_wrong_size_are_named_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let depth = dir.path().join("depth");
    std::fs::create_dir_all(&depth).unwrap();
    // The demo at width 64 has 64×48 views; these maps are 32×24.
    for view in ["view_02", "view_11", "view_21"] {
        fewview_geom::io::write_npy(
            &depth.join(format!("{view}.npy")),
            &[24, 32],
            &[5.0; 32 * 24],
        )
        .unwrap();
    }
    let out = dir.path().join("run");
    let init = format!("depth:{}", s(&depth));
    let run = fewview(&["demo", "--width", "64", "--init", &init, "--out", s(&out)]);
    assert_clean_error(&run, &["view_02.npy", "32×24", "64×48"]);
    assert!(!out.exists(), "a refused run wrote {}", out.display());
    // A missing map is named too.
    std::fs::remove_file(depth.join("view_11.npy")).unwrap();
    std::fs::write(depth.join("view_02.npy"), b"").unwrap();
    let run = fewview(&["demo", "--width", "64", "--init", &init, "--out", s(&out)]);
    assert_clean_error(&run, &["view_02.npy"]);
    assert!(!out.exists());
}

#[test]
fn the_stereo_start_writes_its_cloud_into_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    fewview_ok(&[
        "demo",
        "--init",
        "stereo",
        "--width",
        "100",
        "--iterations",
        "30",
        "--checkpoint-every",
        "0",
        "--out",
        s(&out),
    ]);
    for f in [
        "stereo.json",
        "stereo_cloud.ply",
        "stereo_regions.ply",
        "stereo_regions.png",
    ] {
        assert!(out.join("init").join(f).exists(), "init/{f} missing");
    }
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("init/stereo.json")).unwrap()).unwrap();
    let points = json["points"].as_u64().unwrap();
    let sampled = json["sampled"].as_u64().unwrap();
    // The paper's 10 % sample.
    assert_eq!(sampled, (points as f64 * 0.1).round() as u64);
    assert_eq!(json["pairs"].as_array().unwrap().len(), 3);
}
