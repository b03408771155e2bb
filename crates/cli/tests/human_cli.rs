//! `fewview human`: bad inputs fail with one line naming the file, before anything is written.

mod common;

use std::path::{Path, PathBuf};

use common::{assert_clean_error, fewview, fewview_ok, s};

fn data_root() -> PathBuf {
    PathBuf::from(std::env::var("FEWVIEW_DATA").expect("set FEWVIEW_DATA to the data folder"))
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).unwrap();
        }
    }
}

/// A capture with one mask missing is refused when opened: one line naming the file, and no
/// output folder.
#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn human_train_refuses_a_capture_with_a_missing_mask() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("human");
    copy_dir(&data_root().join("human"), &data);
    std::fs::remove_file(data.join("seq_a/masks/cam_03/frame_0010.png")).unwrap();
    let out = dir.path().join("run");
    let result = fewview(&[
        "human",
        "train",
        "--data",
        s(&data),
        "--out",
        s(&out),
        "--iterations",
        "1",
    ]);
    assert_clean_error(&result, &["cam_03/frame_0010.png", "missing"]);
    assert!(!out.exists(), "an output folder was written");
}

/// A folder that holds no run is refused by `human eval` before anything is written.
#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn human_eval_refuses_a_folder_without_a_run() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("eval");
    let data = data_root().join("human");
    let result = fewview(&[
        "human",
        "eval",
        "--run",
        s(dir.path()),
        "--data",
        s(&data),
        "--out",
        s(&out),
    ]);
    assert_clean_error(&result, &["state.bin"]);
    assert!(!out.exists(), "an output folder was written");
}

/// Fails with the command's error output unless it succeeded.
fn assert_ok(done: &std::process::Output) {
    assert!(
        done.status.success(),
        "{}",
        String::from_utf8_lossy(&done.stderr)
    );
}

fn zju_fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../human/tests/fixtures/zju_small")
}

/// The ZJU-MoCap layout end to end on the committed fixture (4 cameras, 3 frames): one training
/// step on 3 input cameras and 2 frames, then the held-out camera rendered on every frame as
/// PNGs and a video; a camera that does not exist is refused before anything is written.
#[test]
fn human_train_and_render_run_on_the_zju_layout() {
    let dir = tempfile::tempdir().unwrap();
    let data = zju_fixture();
    let run = dir.path().join("run");
    train_one_step(&data, &run, "3");
    let split = std::fs::read_to_string(run.join("split.json")).unwrap();
    let split: serde_json::Value = serde_json::from_str(&split).unwrap();
    assert_eq!(split["held_out_cameras"], serde_json::json!([3]));

    let render = |out: &Path, extra: &[&str]| {
        let mut a = vec!["human", "render", "--run", s(&run), "--data", s(&data)];
        a.extend(["--out", s(out)]);
        a.extend(extra);
        fewview(&a)
    };
    let bad = dir.path().join("bad");
    assert_clean_error(
        &render(&bad, &["--cameras", "7"]),
        &["camera 7", "4 cameras"],
    );
    assert!(!bad.exists(), "an output folder was written");

    let out = dir.path().join("render");
    let done = render(&out, &[]);
    assert_ok(&done);
    for frame in 0..3 {
        let png = out.join(format!("Camera_B10/frame_{frame:04}.png"));
        let image = fewview_scene::Image::load(&png).unwrap();
        let lit = image
            .data
            .chunks(3)
            .filter(|p| p.iter().any(|&v| v > 0.1))
            .count();
        // The person covers about a tenth of the crop; a blank render would have none.
        assert!(lit > 500, "{}: {lit} lit pixels", png.display());
    }
    assert!(out.join("Camera_B10.mp4").metadata().unwrap().len() > 1000);

    // Weights of another configuration (variant 1) in the run are refused.
    let other = dir.path().join("other");
    train_one_step(&data, &other, "1");
    std::fs::copy(other.join("network.fvh"), run.join("network.fvh")).unwrap();
    let refused = dir.path().join("refused");
    assert_clean_error(
        &render(&refused, &[]),
        &["network.fvh", "weights of another network"],
    );
    assert!(!refused.exists(), "an output folder was written");
}

/// One training step of network configuration `variant` on the fixture's cameras 0–2 and
/// frames 0–1.
fn train_one_step(data: &Path, out: &Path, variant: &str) {
    train_one_step_with(data, out, &["--variant", variant]);
}

/// One training step on the fixture's cameras 0–2 and frames 0–1 with `extra` flags.
fn train_one_step_with(data: &Path, out: &Path, extra: &[&str]) {
    let mut a = vec!["human", "train", "--data", s(data), "--out", s(out)];
    a.extend([
        "--input-cameras",
        "3",
        "--train-frames",
        "2",
        "--iterations",
        "1",
    ]);
    a.extend(extra);
    fewview_ok(&a);
}

/// `human eval` with a named baseline (the same method on the hull's depth) writes the table
/// with each run's depth input and steps, the report and the video; a baseline without a name
/// is refused before anything is written.
#[test]
fn human_eval_scores_named_baselines_and_says_how_each_was_trained() {
    let dir = tempfile::tempdir().unwrap();
    let data = zju_fixture();
    let (ours, hull) = (dir.path().join("ours"), dir.path().join("hull"));
    train_one_step_with(&data, &ours, &[]);
    train_one_step_with(&data, &hull, &["--depth", "hull"]);
    let eval = |out: &Path, baseline: &str| {
        let mut a = vec!["human", "eval", "--run", s(&ours), "--data", s(&data)];
        a.extend(["--out", s(out), "--no-lpips", "--baseline", baseline]);
        fewview(&a)
    };
    let bad = dir.path().join("bad");
    assert_clean_error(&eval(&bad, s(&hull)), &["--baseline", "NAME=DIR"]);
    assert!(!bad.exists(), "an output folder was written");

    let out = dir.path().join("eval");
    let done = eval(&out, &format!("hull={}", s(&hull)));
    assert_ok(&done);
    let md = std::fs::read_to_string(out.join("table.md")).unwrap();
    for row in ["| ours | stereo | yes | 1 |", "| hull | hull | yes | 1 |"] {
        assert!(md.contains(row), "`{row}` not in:\n{md}");
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(report["runs"].as_array().unwrap().len(), 2);
    let methods: Vec<&str> = report["novel_view"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["method"].as_str().unwrap())
        .collect();
    assert_eq!(methods, ["ours", "ours, no TPS", "hull"]);
    assert!(out.join("side_by_side.mp4").metadata().unwrap().len() > 1000);
}

/// `human depth` on the fixture (no depth maps: no truth row) writes its report and strip; a
/// camera that is not an input camera is refused before anything is written; and training with
/// the dataset's depth as input on a capture without depth maps is refused the same way.
#[test]
fn human_depth_reports_stereo_and_refuses_what_the_capture_cannot_give() {
    let dir = tempfile::tempdir().unwrap();
    let data = zju_fixture();
    let depth = |out: &Path, extra: &[&str]| {
        let mut a = vec!["human", "depth", "--data", s(&data), "--out", s(out)];
        a.extend(["--input-cameras", "3"]);
        a.extend(extra);
        fewview(&a)
    };
    let bad = dir.path().join("bad");
    assert_clean_error(
        &depth(&bad, &["--camera", "3"]),
        &["--camera 3", "input camera"],
    );
    assert!(!bad.exists(), "an output folder was written");

    let out = dir.path().join("depth");
    let done = depth(&out, &[]);
    assert_ok(&done);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("depth_report.json")).unwrap())
            .unwrap();
    assert!(report["truth"].is_null());
    assert!(
        report["stereo"]["flicker_m"]
            .as_f64()
            .is_some_and(f64::is_finite)
    );
    let strip = fewview_scene::Image::load(&out.join("depth_strip.png")).unwrap();
    // Three frames of one camera, image + hull + stereo each.
    assert_eq!(strip.width % 3, 0);

    let run = dir.path().join("run");
    let refused = fewview(&[
        "human",
        "train",
        "--data",
        s(&data),
        "--out",
        s(&run),
        "--input-cameras",
        "3",
        "--train-frames",
        "2",
        "--iterations",
        "1",
        "--depth",
        "dataset",
    ]);
    assert_clean_error(&refused, &["no depth maps"]);
    assert!(!run.exists(), "an output folder was written");

    let wrong = dir.path().join("wrong");
    assert_clean_error(
        &depth(&wrong, &["--stereo-search", "0.1,-0.2"]),
        &["stereo search", "0.1,-0.2", "metres"],
    );
    assert_clean_error(
        &depth(&wrong, &["--stereo-search", "0.1"]),
        &["--stereo-search", "FRONT,BEHIND"],
    );
    assert!(!wrong.exists(), "an output folder was written");
}
