//! CPU time of this process, for benchmarks on shared machines.

/// CPU seconds used by this process so far (all threads), from `/proc/self/stat` (Linux;
/// `None` elsewhere).
pub fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    // Fields 14 and 15 of the full line (utime, stime) are 11 and 12 after the name.
    let ticks: f64 = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

/// CPU seconds used by all threads of this process so far, summed from the per-thread
/// scheduler statistics (`/proc/self/task/*/schedstat`, whose first field is nanoseconds on
/// the CPU): fine enough for work of a few milliseconds, where [`cpu_seconds`] counts 10 ms
/// ticks. A thread that exits between two readings takes its time out of the sum, so callers
/// measure work done by long-lived threads (the rayon pool). `None` where it is not available
/// (not Linux, or no scheduler statistics).
pub fn fine_cpu_seconds() -> Option<f64> {
    let mut ns = 0u64;
    for task in std::fs::read_dir("/proc/self/task").ok()? {
        let stat = std::fs::read_to_string(task.ok()?.path().join("schedstat")).ok()?;
        ns += stat.split_whitespace().next()?.parse::<u64>().ok()?;
    }
    Some(ns as f64 * 1e-9)
}
