//! Scheduling priority of the calling thread (the correction workers run below the server
//! step). On Linux a thread has its own nice value; elsewhere this does nothing.

/// Lowers the calling thread's priority to nice value `nice` (higher is lower priority);
/// a failure (e.g. a sandbox without `setpriority`) only logs, since priority is an
/// optimisation, never a condition for serving.
pub fn lower_this_thread(nice: i32) {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: `gettid` takes no arguments and cannot fail; `setpriority` on the calling
        // thread's id reads nothing from us but plain integers.
        let result = unsafe {
            let tid = libc::syscall(libc::SYS_gettid) as libc::id_t;
            libc::setpriority(libc::PRIO_PROCESS, tid, nice)
        };
        if result != 0 {
            tracing::debug!(
                "cannot lower a thread's priority to nice {nice}: {}",
                std::io::Error::last_os_error()
            );
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = nice;
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    /// The nice value of the calling thread, from `/proc/thread-self/stat` (field 19).
    fn nice_of_this_thread() -> i32 {
        let stat = std::fs::read_to_string("/proc/thread-self/stat").unwrap();
        let after_name = &stat[stat.rfind(')').unwrap() + 2..];
        after_name.split(' ').nth(16).unwrap().parse().unwrap()
    }

    #[test]
    fn lowers_only_the_calling_thread() {
        let before = nice_of_this_thread();
        let lowered = std::thread::spawn(|| {
            lower_this_thread(10);
            nice_of_this_thread()
        })
        .join()
        .unwrap();
        if before <= 10 {
            // (An unprivileged thread already above nice 10 may not come back down to it.)
            assert_eq!(lowered, 10, "the worker's own nice value");
        }
        assert_eq!(nice_of_this_thread(), before, "other threads keep theirs");
    }
}
