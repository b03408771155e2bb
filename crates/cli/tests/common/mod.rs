//! Helpers shared by the CLI's integration tests. Each test file compiles this module on its
//! own and uses only some of the helpers.
#![allow(dead_code)]

use std::path::Path;
use std::process::{Command, Output};

/// Runs the `fewview` binary built for these tests.
pub fn fewview(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fewview"))
        .args(args)
        .output()
        .expect("run fewview")
}

/// Runs `fewview` and asserts it succeeded (stderr in the message otherwise).
pub fn fewview_ok(args: &[&str]) -> Output {
    let out = fewview(args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// A path as a command-line argument (the tests' temporary paths are UTF-8).
pub fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// Asserts a failed run with one line on stderr that contains every needle, says no cause twice
/// in a row (`…: gone: gone`), and no panic.
pub fn assert_clean_error(out: &Output, needles: &[&str]) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success(),
        "expected failure, got success; stderr: {err}"
    );
    assert!(!err.contains("panicked"), "panic: {err}");
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    let error_lines: Vec<&&str> = lines.iter().filter(|l| l.starts_with("error")).collect();
    assert_eq!(error_lines.len(), 1, "want one error line, got: {err}");
    let parts: Vec<&str> = error_lines[0].split(": ").collect();
    assert!(
        parts.windows(2).all(|w| w[0] != w[1]),
        "a cause is repeated: {}",
        error_lines[0]
    );
    for n in needles {
        assert!(
            error_lines[0].contains(n),
            "`{n}` not in: {}",
            error_lines[0]
        );
    }
}
