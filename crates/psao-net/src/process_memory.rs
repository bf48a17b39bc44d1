//! This process's memory as the operating system and the C allocator see it: resident size
//! (whole, file-backed part, peak), the allocator's bytes in use and held free, and giving
//! free pages back ([`release_free_memory`]). Linux with glibc; elsewhere the readers return
//! `None` and releasing does nothing.

/// Resident memory of this process, from `/proc/self/status`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Resident {
    /// Resident bytes now (`VmRSS`).
    pub bytes: u64,
    /// Peak resident bytes so far (`VmHWM`).
    pub peak: u64,
    /// Resident bytes backed by files or shared memory (`RssFile` + `RssShmem`): the
    /// executable and libraries mapped in.
    pub file: u64,
}

/// Reads [`Resident`] (`None` where `/proc/self/status` or its fields are missing).
pub fn resident() -> Option<Resident> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let kib = |key: &str| -> Option<u64> {
        let line = status.lines().find(|l| l.starts_with(key))?;
        let value = line[key.len()..].trim().trim_end_matches("kB").trim();
        value.parse::<u64>().ok().map(|k| k * 1024)
    };
    Some(Resident {
        bytes: kib("VmRSS:")?,
        peak: kib("VmHWM:")?,
        file: kib("RssFile:")? + kib("RssShmem:").unwrap_or(0),
    })
}

/// The C allocator's (glibc malloc's) own account, over all its arenas.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MallocStats {
    /// Bytes in allocated blocks (arenas and separately mapped large blocks).
    pub in_use: u64,
    /// Bytes of free blocks the allocator holds in its arenas (resident or not).
    pub free: u64,
}

/// Reads [`MallocStats`] (`None` without glibc).
pub fn malloc_stats() -> Option<MallocStats> {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: mallinfo2 only reads the allocator's counters.
        let m = unsafe { libc::mallinfo2() };
        Some(MallocStats {
            in_use: (m.uordblks + m.hblkhd) as u64,
            free: m.fordblks as u64,
        })
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        None
    }
}

/// Give the free pages the C allocator holds back to the operating system (glibc
/// `malloc_trim(0)`, which also releases whole free pages inside its arenas). A server calls
/// it once start-up's temporary buffers (generated candidates, stored start points, tracer
/// build scratch) are freed: they would otherwise stay resident as allocator slack.
pub fn release_free_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim only returns free memory; no allocation is touched.
    unsafe {
        libc::malloc_trim(0);
    }
}

/// Size from which [`map_large_blocks_apart`] has every block mapped on its own.
pub const MMAP_THRESHOLD: usize = 256 * 1024;

/// Have the C allocator map every block of at least [`MMAP_THRESHOLD`] bytes on its own, so
/// its pages go back to the system as soon as it is freed (glibc `mallopt(M_MMAP_THRESHOLD)`).
/// By default glibc raises that threshold, up to 32 MiB, each time a mapped block is freed;
/// start-up's large temporary buffers (candidates, burial rays, stored start points) then
/// come from the heap and leave holes between the blocks the server keeps, pages that stay
/// resident (docs/BENCHMARKS.md, "The whole resident size"). A server calls it first thing,
/// before start-up allocates. Returns whether the allocator took the setting (false without
/// glibc).
pub fn map_large_blocks_apart() -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only changes an allocator parameter; the value is a positive size
    // that fits in a C int.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD as libc::c_int) == 1
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    false
}

/// Gives free pages back whenever the resident size has grown by more than a sixteenth since
/// the last time: a server's frames allocate short-lived buffers (rays, hits, updates), which
/// land in the holes start-up left in the heap and keep those pages resident after they are
/// freed (docs/BENCHMARKS.md, "The server process"). Reading the resident size costs about
/// as much as opening a small file; trimming walks the heap's free blocks, and happens only
/// as often as the resident size grows by a sixteenth.
#[derive(Clone, Copy, Debug, Default)]
pub struct SlackTrimmer {
    /// Resident bytes after the last release (0: none yet).
    after_release: u64,
}

impl SlackTrimmer {
    /// Whether `resident` bytes exceed the last release's resident size by more than a
    /// sixteenth (always, before any release).
    fn grew_past_bound(&self, resident: u64) -> bool {
        self.after_release == 0 || resident > self.after_release + self.after_release / 16
    }

    /// Release free memory if the resident size grew past the bound; true when it did.
    pub fn after_frame(&mut self) -> bool {
        let Some(now) = resident() else {
            return false;
        };
        if !self.grew_past_bound(now.bytes) {
            return false;
        }
        release_free_memory();
        self.after_release = resident().map_or(now.bytes, |r| r.bytes);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The tests measure the whole process: one at a time.
    static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

    #[test]
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    fn freed_memory_is_counted_free_and_released() {
        let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
        let r = resident().unwrap();
        assert!(r.bytes > 0 && r.peak >= r.bytes && r.file > 0 && r.file < r.bytes);
        // Many blocks below the mmap threshold, touched so their pages are resident; every
        // other one is freed, leaving holes between live blocks that only trimming returns.
        let mut blocks: Vec<Vec<u8>> = (0..2000).map(|k| vec![k as u8 | 1; 60_000]).collect();
        let held = malloc_stats().unwrap();
        let mut k = 0;
        blocks.retain(|_| {
            k += 1;
            k % 2 == 0
        });
        let freed = malloc_stats().unwrap();
        assert!(
            held.in_use >= freed.in_use + 50_000_000,
            "{held:?} {freed:?}"
        );
        assert!(freed.free >= 50_000_000, "{freed:?}");
        let before = resident().unwrap().bytes;
        release_free_memory();
        let after = resident().unwrap().bytes;
        assert!(after + 40_000_000 <= before, "{before} -> {after}");
        assert!(blocks.len() == 1000 && blocks.iter().all(|b| b[59_999] & 1 == 1));
    }

    #[test]
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    fn large_blocks_go_back_to_the_system_when_freed() {
        let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
        assert!(map_large_blocks_apart());
        // Freeing one mapped block would have raised glibc's default threshold past the
        // blocks below; with the threshold fixed each block stays a mapping of its own.
        drop(vec![1u8; 4 * MMAP_THRESHOLD]);
        let mut blocks: Vec<Vec<u8>> = (0..128)
            .map(|k| vec![k as u8 | 1; MMAP_THRESHOLD])
            .collect();
        let before = resident().unwrap().bytes;
        let mut k = 0;
        blocks.retain(|_| {
            k += 1;
            k % 2 == 0
        });
        // No trimming: the 64 freed blocks' pages (16 MiB) leave with them.
        let after = resident().unwrap().bytes;
        assert!(after + 14 * (1 << 20) <= before, "{before} -> {after}");
        assert!(blocks.len() == 64 && blocks.iter().all(|b| b[MMAP_THRESHOLD - 1] & 1 == 1));
    }

    #[test]
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    fn the_trimmer_releases_only_after_the_resident_size_grew() {
        let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
        let mut t = SlackTrimmer::default();
        assert!(t.after_frame(), "the first frame sets the bound");
        // Other tests of this process allocate as they run: the bound itself is checked on
        // sizes, not on this process's resident size.
        let bound = t.after_release + t.after_release / 16;
        assert!(!t.grew_past_bound(bound), "nothing grew past the bound");
        assert!(t.grew_past_bound(bound + 1));
        // Touched blocks below the mmap threshold, then every other one freed: the holes stay
        // resident until released.
        let grow = t.after_release / 8 + 64_000_000;
        let mut blocks: Vec<Vec<u8>> = (0..grow / 60_000)
            .map(|k| vec![k as u8 | 1; 60_000])
            .collect();
        let mut k = 0;
        blocks.retain(|_| {
            k += 1;
            k % 2 == 0
        });
        let before = resident().unwrap().bytes;
        assert!(
            t.after_frame(),
            "grew by {} of {}",
            before - t.after_release,
            t.after_release
        );
        assert!(
            t.after_release + 20_000_000 <= before,
            "{before} -> {}",
            t.after_release
        );
        assert!(blocks.iter().all(|b| b[59_999] & 1 == 1));
    }
}
