//! Helpers shared by the CLI's integration tests.

use std::process::Output;

/// Asserts a failed run with one line on stderr that contains every needle, and no panic.
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
    for n in needles {
        assert!(
            error_lines[0].contains(n),
            "`{n}` not in: {}",
            error_lines[0]
        );
    }
}
