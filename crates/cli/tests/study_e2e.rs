//! The user study end to end: `fewview study serve` on loopback, a participant in headless
//! Chromium (answers half, reloads, finishes), 24 concurrent simulated participants through the
//! API, then the server is killed (SIGKILL) and `fewview study analyze` must find every answer
//! and count the wins right. A second test builds a study from `fewview fusion` runs and walks a
//! participant through its videos. Needs `scripts/setup.sh` (the test command runs it).

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Where playwright-core lives; fails when the headless browser is not installed.
fn browser() -> PathBuf {
    let node_modules = repo().join(".cache/browser/node_modules");
    assert!(
        node_modules.join("playwright-core").exists() && Path::new("/usr/bin/chromium").exists(),
        "headless browser missing: run scripts/setup.sh (scripts/test.sh does)"
    );
    node_modules
}

fn write_study(dir: &Path) -> PathBuf {
    let methods = ["FreeNeRF", "MVPGS", "Ours"];
    let scenes = ["truck", "train"];
    let mut videos = String::new();
    for (s, scene) in scenes.iter().enumerate() {
        videos += &format!("[videos.{scene}]\n");
        for (m, method) in methods.iter().enumerate() {
            let img = fewview_scene::Image::filled(32, 24, &[0.2 * m as f32, 0.5, 0.3 * s as f32]);
            let name = format!("{scene}_{method}.png");
            img.save_png(&dir.join(&name)).unwrap();
            videos += &format!("{method} = \"{name}\"\n");
        }
    }
    let config = format!(
        "title = \"e2e study\"\nseed = 5\ndatabase = \"answers.sqlite\"\nmethods = [\"FreeNeRF\", \"MVPGS\", \"Ours\"]\nscenes = [\"truck\", \"train\"]\n{videos}"
    );
    let path = dir.join("study.toml");
    std::fs::write(&path, config).unwrap();
    path
}

#[test]
fn browser_session_reload_concurrency_and_analysis() {
    let node_modules = browser();
    let dir = tempfile::tempdir().unwrap();
    let config = write_study(dir.path());
    let exe = env!("CARGO_BIN_EXE_fewview");
    let (mut server, url) = serve(&config);
    assert!(url.starts_with("http://127.0.0.1:"), "{url}");

    let result = dir.path().join("e2e.json");
    let status = Command::new("node")
        .arg(repo().join("web/tests/study_e2e.cjs"))
        .env("NODE_PATH", &node_modules)
        .env("STUDY_URL", &url)
        .env("STUDY_RESULT", &result)
        .env("SIMULATED", "24")
        .status()
        .unwrap();
    // A crash: no graceful shutdown. Everything acknowledged must already be on disk.
    server.kill().unwrap();
    server.wait().unwrap();
    assert!(status.success(), "node end-to-end script failed");

    // What the participants chose, resolved to methods through the stored plans.
    let result: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&result).unwrap()).unwrap();
    let db = rusqlite::Connection::open(dir.path().join("answers.sqlite")).unwrap();
    let mut expected: BTreeMap<(String, String, String), u64> = BTreeMap::new(); // (question, winner, loser)
    let mut answers = 0;
    let sessions = result["sessions"].as_array().unwrap();
    assert_eq!(sessions.len(), 25);
    for s in sessions {
        let participant = s["participant"].as_str().unwrap();
        let choices = s["choices"].as_array().unwrap();
        assert_eq!(choices.len() as u64, s["total"].as_u64().unwrap());
        assert_eq!(choices.len(), 6, "2 scenes × 3 method pairs");
        for c in choices {
            let index = c["index"].as_i64().unwrap();
            let (left, right): (String, String) = db
                .query_row("SELECT left_method, right_method FROM trials WHERE participant = ?1 AND idx = ?2", rusqlite::params![participant, index], |r| Ok((r.get(0)?, r.get(1)?)))
                .unwrap();
            for (q, side) in c["answers"].as_object().unwrap() {
                let (w, l) = if side == "left" {
                    (&left, &right)
                } else {
                    (&right, &left)
                };
                *expected
                    .entry((q.clone(), w.clone(), l.clone()))
                    .or_default() += 1;
                answers += 1;
            }
        }
    }
    let stored: i64 = db
        .query_row("SELECT COUNT(*) FROM responses", [], |r| r.get(0))
        .unwrap();
    assert_eq!(
        stored, answers,
        "every acknowledged answer is stored, none twice"
    );

    // The analysis of the stored answers counts exactly those wins.
    let out = dir.path().join("analysis");
    let status = Command::new(exe)
        .args(["study", "analyze", "--config"])
        .arg(&config)
        .arg("--out")
        .arg(&out)
        .args(["--tune", "300", "--draws", "300"])
        .stdout(Stdio::null())
        .status()
        .unwrap();
    assert!(status.success());
    let pairs = std::fs::read_to_string(out.join("pairs.csv")).unwrap();
    let mut rows = 0;
    for line in pairs.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let (q, m, o, wins, n) = (
            f[0],
            f[1],
            f[2],
            f[3].parse::<u64>().unwrap(),
            f[4].parse::<u64>().unwrap(),
        );
        let key = |w: &str, l: &str| {
            expected
                .get(&(q.to_string(), w.to_string(), l.to_string()))
                .copied()
                .unwrap_or(0)
        };
        assert_eq!(wins, key(m, o), "{line}");
        assert_eq!(n, key(m, o) + key(o, m), "{line}");
        // 25 participants × 2 scenes compare each pair.
        assert_eq!(n, 50, "{line}");
        rows += 1;
    }
    assert_eq!(rows, 2 * 3 * 2, "2 questions × 3 pairs × both directions");
    assert!(out.join("ranking_Q1.png").exists() && out.join("report.md").exists());
}

/// Starts `fewview study serve` on a free loopback port; returns the server and its base URL.
fn serve(config: &Path) -> (std::process::Child, String) {
    let mut server = Command::new(env!("CARGO_BIN_EXE_fewview"))
        .args(["study", "serve", "--config"])
        .arg(config)
        .args(["--addr", "127.0.0.1:0"])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(server.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let url = line
        .split_whitespace()
        .nth(1)
        .expect("server prints its URL")
        .trim_end_matches('/')
        .to_string();
    (server, url)
}

#[test]
fn a_study_of_fusion_runs_shows_their_transition_videos_to_a_participant() {
    let node_modules = browser();
    let dir = tempfile::tempdir().unwrap();
    let exe = env!("CARGO_BIN_EXE_fewview");
    let mut runs = Vec::new();
    // The demo's jittered photos of a strong highlight: plain, the per-photo appearance model,
    // and gradient-domain fusion, as the fusion issue's study compares them.
    for (method, variant, appearance) in [
        ("plain", "plain", "none"),
        ("affine", "plain", "affine"),
        ("gf", "gf", "none"),
    ] {
        let out = dir.path().join(method);
        let status = Command::new(exe)
            .args(["fusion", "--demo", "--width", "64", "--iterations", "40"])
            .args(["--exposure-jitter", "0.5", "--white-balance-jitter", "0.05"])
            .args(["--specular", "0.4,40", "--appearance", appearance])
            .args([
                "--checkpoint-every",
                "0",
                "--no-lpips",
                "--variant",
                variant,
                "--out",
            ])
            .arg(&out)
            .stdout(Stdio::null())
            .status()
            .unwrap();
        assert!(status.success(), "fusion: {method}");
        runs.push(out);
    }
    let study = dir.path().join("study");
    let status = Command::new(exe)
        .args(["fusion", "--study"])
        .args(&runs)
        .arg("--out")
        .arg(&study)
        .stdout(Stdio::null())
        .status()
        .unwrap();
    assert!(status.success(), "fusion --study");
    let (mut server, url) = serve(&study.join("study.toml"));
    let result = dir.path().join("e2e.json");
    let status = Command::new("node")
        .arg(repo().join("web/tests/study_e2e.cjs"))
        .env("NODE_PATH", &node_modules)
        .env("STUDY_URL", &url)
        .env("STUDY_RESULT", &result)
        .env("SIMULATED", "2")
        .env("MEDIA", "video")
        .env("MIN_TOTAL", "3")
        .status()
        .unwrap();
    server.kill().unwrap();
    server.wait().unwrap();
    assert!(status.success(), "node end-to-end script failed");
    // One scene, three methods: three comparisons of two questions for each of the browser
    // participant and the two simulated ones, all stored.
    let db = rusqlite::Connection::open(study.join("responses.sqlite")).unwrap();
    let stored: i64 = db
        .query_row("SELECT COUNT(*) FROM responses", [], |r| r.get(0))
        .unwrap();
    assert_eq!(stored, 3 * 3 * 2);
}
