//! Per-stage wall times of the device rasterizer, for `fewview bench --device gpu`: while
//! recording is on, each stage waits for the device before the clock reads, so every stage is
//! charged its own kernels. Off by default (waiting serialises the host and the device, which
//! costs time of its own).

use std::sync::Mutex;
use std::time::Instant;

use cubecl::prelude::*;

/// Seconds per stage name, in the order the stages first ran.
type Stages = Vec<(&'static str, Vec<f64>)>;

/// The stages recorded so far; `None` while recording is off.
static RECORDED: Mutex<Option<Stages>> = Mutex::new(None);

fn recorded() -> std::sync::MutexGuard<'static, Option<Stages>> {
    RECORDED
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Starts recording (clearing earlier records).
pub fn start() {
    *recorded() = Some(Vec::new());
}

/// Stops recording and returns each stage's times.
pub fn finish() -> Stages {
    recorded().take().unwrap_or_default()
}

/// The clock of one render or backward pass.
pub(crate) struct StageClock<'a> {
    client: &'a Client,
    /// When the previous stage ended, while recording.
    since: Option<Instant>,
}

impl<'a> StageClock<'a> {
    /// Starts the clock after the device has finished earlier work.
    pub fn start(client: &'a Client) -> Self {
        let since = recorded().is_some().then(|| {
            wait(client);
            Instant::now()
        });
        Self { client, since }
    }

    /// Charges the time since the previous stage to `stage`.
    pub fn stage(&mut self, stage: &'static str) {
        let Some(since) = self.since else {
            return;
        };
        wait(self.client);
        let seconds = since.elapsed().as_secs_f64();
        if let Some(stages) = recorded().as_mut() {
            match stages.iter_mut().find(|(name, _)| *name == stage) {
                Some((_, times)) => times.push(seconds),
                None => stages.push((stage, vec![seconds])),
            }
        }
        self.since = Some(Instant::now());
    }
}

fn wait(client: &Client) {
    // A failed wait shows up as the stage's error at the next read-back; timing goes on.
    let _ = cubecl::future::block_on(client.sync());
}
