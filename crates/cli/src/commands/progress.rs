//! Progress of long work, to stderr: a bar on a terminal, and plain lines (the first update,
//! then one every [`LOG_INTERVAL`], and the last) when stderr is a file or a pipe, so that a run
//! in the background or on a remote machine still says how far it is.

use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressStyle};

/// Time between two progress lines when stderr is not a terminal.
pub const LOG_INTERVAL: Duration = Duration::from_secs(10);

/// Progress of `total` steps of work named `what`.
pub struct Bar {
    bar: ProgressBar,
    /// Present when stderr is not a terminal.
    log: Option<Mutex<Log>>,
}

/// The state of the plain-line form.
struct Log {
    what: String,
    total: u64,
    position: u64,
    message: String,
    start: Instant,
    /// When the last line was written and at which position.
    last: Option<(Instant, u64)>,
}

/// A bar for `total` iterations.
pub fn iterations(total: u64, what: &str) -> Bar {
    let bar = ProgressBar::new(total);
    bar.set_style(
        ProgressStyle::with_template(
            "{prefix} {bar:30} {pos}/{len} [{elapsed_precise}<{eta_precise}] {msg}",
        )
        .expect("valid template"),
    );
    bar.set_prefix(what.to_string());
    let log = (!std::io::stderr().is_terminal()).then(|| {
        Mutex::new(Log {
            what: what.to_string(),
            total,
            position: 0,
            message: String::new(),
            start: Instant::now(),
            last: None,
        })
    });
    Bar { bar, log }
}

impl Bar {
    pub fn set_position(&self, position: u64) {
        self.bar.set_position(position);
        self.with_log(|log| {
            log.position = position;
            log.write_if_due();
        });
    }

    pub fn inc(&self, steps: u64) {
        self.bar.inc(steps);
        self.with_log(|log| {
            log.position += steps;
            log.write_if_due();
        });
    }

    /// The text after the counts (shown with the next line in the plain form).
    pub fn set_message(&self, message: impl Into<String>) {
        let message = message.into();
        self.with_log(|log| log.message.clone_from(&message));
        self.bar.set_message(message);
    }

    /// Runs `f` (which prints) with the bar out of the way.
    pub fn suspend<R>(&self, f: impl FnOnce() -> R) -> R {
        self.bar.suspend(f)
    }

    /// Removes the bar; the plain form writes its last line if it has not.
    pub fn finish_and_clear(&self) {
        self.bar.finish_and_clear();
        self.with_log(|log| {
            if log.last.map(|(_, p)| p) != Some(log.position) {
                log.write();
            }
        });
    }

    fn with_log(&self, f: impl FnOnce(&mut Log)) {
        if let Some(log) = &self.log {
            f(&mut log
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner));
        }
    }
}

impl Log {
    fn write_if_due(&mut self) {
        let due = match self.last {
            None => true,
            Some((at, _)) => at.elapsed() >= LOG_INTERVAL || self.position >= self.total,
        };
        if due {
            self.write();
        }
    }

    fn write(&mut self) {
        eprintln!("{}", self.line(self.start.elapsed()));
        self.last = Some((Instant::now(), self.position));
    }

    /// `train 1200/5000 (24%) 1m 23s, 4m 24s left: loss 0.0123`
    fn line(&self, elapsed: Duration) -> String {
        let (done, total) = (self.position, self.total.max(1));
        let mut line = format!(
            "{} {done}/{} ({}%) {}",
            self.what,
            self.total,
            100 * done / total,
            clock(elapsed)
        );
        if done > 0 && done < total {
            let left = elapsed.mul_f64((total - done) as f64 / done as f64);
            line += &format!(", {} left", clock(left));
        }
        if !self.message.is_empty() {
            line += &format!(": {}", self.message);
        }
        line
    }
}

/// `1h 02m 03s`, `2m 03s` or `3s`.
fn clock(d: Duration) -> String {
    let s = d.as_secs();
    match (s / 3600, s / 60 % 60, s % 60) {
        (0, 0, s) => format!("{s}s"),
        (0, m, s) => format!("{m}m {s:02}s"),
        (h, m, s) => format!("{h}h {m:02}m {s:02}s"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plain_progress_line_gives_counts_time_left_and_message() {
        let log = Log {
            what: "train".into(),
            total: 5000,
            position: 1250,
            message: "loss 0.0123".into(),
            start: Instant::now(),
            last: None,
        };
        assert_eq!(
            log.line(Duration::from_secs(83)),
            "train 1250/5000 (25%) 1m 23s, 4m 09s left: loss 0.0123"
        );
        let done = Log {
            position: 5000,
            message: String::new(),
            ..log
        };
        assert_eq!(
            done.line(Duration::from_secs(3725)),
            "train 5000/5000 (100%) 1h 02m 05s"
        );
    }
}
