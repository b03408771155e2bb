//! CPU time of this process (all threads), so speed figures count the core-seconds the work
//! used, independent of other load on a shared machine.

/// Seconds of CPU time this process has used so far, summed over its threads.
pub fn process_cpu_seconds() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_PROCESS_CPUTIME_ID exists on Linux.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        return f64::NAN;
    }
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

/// Wall and CPU seconds of one call of `f`.
pub fn measure<T>(f: impl FnOnce() -> T) -> (T, f64, f64) {
    let wall = std::time::Instant::now();
    let cpu = process_cpu_seconds();
    let out = f();
    (
        out,
        wall.elapsed().as_secs_f64(),
        process_cpu_seconds() - cpu,
    )
}
