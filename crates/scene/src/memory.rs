//! Resident memory of this process, for runs that say what each stage needed: the peak since
//! the last reset (Linux's `VmHWM`, reset by writing 5 to `/proc/self/clear_refs`) and what the
//! machine has available (`MemAvailable`). Elsewhere every function answers `None`.

/// Resets the peak to the current resident size; false where the system cannot.
pub fn reset_peak() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// The most memory this process has held resident since the last [`reset_peak`] (or its start).
pub fn peak_bytes() -> Option<u64> {
    kib_field(
        &std::fs::read_to_string("/proc/self/status").ok()?,
        "VmHWM:",
    )
}

/// Memory the machine can give without swapping.
pub fn available_bytes() -> Option<u64> {
    kib_field(
        &std::fs::read_to_string("/proc/meminfo").ok()?,
        "MemAvailable:",
    )
}

/// The `… kB` value of the line starting with `name`, in bytes.
fn kib_field(text: &str, name: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(name))?;
    let kib: u64 = line[name.len()..]
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some(kib * 1024)
}

/// The peak resident memory of each stage of a run, in MiB, in the order measured.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StagePeaks(pub Vec<(String, f64)>);

impl StagePeaks {
    /// Runs `f` as stage `name`, recording the peak it reached (when the system tells).
    pub fn measure<T>(&mut self, name: &str, f: impl FnOnce() -> T) -> T {
        reset_peak();
        let out = f();
        if let Some(peak) = peak_bytes() {
            self.0
                .push((name.to_string(), peak as f64 / (1024.0 * 1024.0)));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kib_fields_are_read_in_bytes() {
        let status = "Name:\tfewview\nVmHWM:\t  123456 kB\nVmRSS:\t 1000 kB\n";
        assert_eq!(kib_field(status, "VmHWM:"), Some(123_456 * 1024));
        assert_eq!(kib_field(status, "VmSwap:"), None);
    }

    /// A stage that holds 64 MiB peaks at 64 MiB or more (other tests of this process may add).
    #[test]
    fn a_stage_that_holds_more_peaks_higher() {
        if peak_bytes().is_none() || !reset_peak() {
            return; // not Linux: nothing to measure
        }
        let mut peaks = StagePeaks::default();
        peaks.measure("small", || std::hint::black_box(vec![1u8; 1 << 20]).len());
        peaks.measure("large", || std::hint::black_box(vec![1u8; 64 << 20]).len());
        assert_eq!(peaks.0.len(), 2);
        assert!(peaks.0[1].1 >= 64.0, "{:?}", peaks.0);
    }
}
