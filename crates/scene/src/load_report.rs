//! What a load did besides producing the dataset: frames it skipped, photos it undistorted and
//! how the undistortion cache served them, and warnings for the user. The library never
//! prints; the CLI prints [`LoadReport::warnings`].

use crate::distortion::cache::CacheOutcome;

/// The side effects and warnings of one [`crate::load_dataset_with_report`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LoadReport {
    /// Frames of a `transforms.json` skipped because their image file is missing.
    pub missing_frames: usize,
    /// Views whose photos were undistorted into a pinhole (afresh or from the cache).
    pub undistorted: usize,
    /// Of those, how many were read from the undistortion cache.
    pub cache_hits: usize,
    /// Of those, how many were undistorted and written to the cache.
    pub cache_writes: usize,
    /// One line each, for the user.
    pub warnings: Vec<String>,
}

impl LoadReport {
    /// Counts what the cache did for one photo (a cache that cannot be written is warned about
    /// once per load).
    pub(crate) fn record(&mut self, outcome: &CacheOutcome) {
        match outcome {
            CacheOutcome::Pinhole => return,
            CacheOutcome::Hit => self.cache_hits += 1,
            CacheOutcome::Written => self.cache_writes += 1,
            CacheOutcome::Unwritable(why) => {
                if !self
                    .warnings
                    .iter()
                    .any(|w| w.starts_with("cannot write the undistortion cache"))
                {
                    self.warnings.push(format!(
                        "cannot write the undistortion cache ({why}); photos are undistorted again on every load"
                    ));
                }
            }
        }
        self.undistorted += 1;
    }
}
