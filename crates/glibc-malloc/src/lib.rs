//! glibc's allocator told to keep the memory a process frees, for the next allocations.
//!
//! By default glibc serves a large allocation (from 128 KiB, rising with what is freed) with
//! its own `mmap` and gives it back to the system with `munmap` when it is freed, and trims the
//! heap's top once 128 KiB of it is free. A program that allocates and frees buffers of a few
//! megabytes at a high rate (a tensor library, a new buffer per operation) then spends most of
//! its time in the kernel, mapping pages and faulting them in again. [`keep_freed`] raises both
//! thresholds, so that freed blocks stay in the process and are reused.
//!
//! Process-wide: for commands that run such work and end, not for a daemon whose resident
//! memory should follow what it uses. On another C library it does nothing.

/// Keeps freed blocks below `mmap_bytes` in the heap (served from it, not mapped one by one)
/// and up to `trim_bytes` of free memory at the heap's top before giving it back. Returns
/// whether the allocator took both settings (`false` on a C library other than glibc, or for
/// a value it refuses or that does not fit its `int`).
pub fn keep_freed(mmap_bytes: usize, trim_bytes: usize) -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        let set = |param: libc::c_int, bytes: usize| {
            let Ok(value) = libc::c_int::try_from(bytes) else {
                return false;
            };
            // SAFETY: `mallopt` only changes the allocator's tunables (glibc takes its own
            // lock for it) and checks the value itself (1: taken, 0: refused); no memory is
            // touched.
            unsafe { libc::mallopt(param, value) == 1 }
        };
        set(libc::M_MMAP_THRESHOLD, mmap_bytes) & set(libc::M_TRIM_THRESHOLD, trim_bytes)
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        let _ = (mmap_bytes, trim_bytes);
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn glibc_takes_the_thresholds_and_a_value_beyond_its_int_is_refused() {
        assert!(keep_freed(32 << 20, 256 << 20));
        assert!(!keep_freed(32 << 20, usize::MAX));
        // And the memory it keeps is used as before.
        let blocks: Vec<Vec<u8>> = (0..8).map(|k| vec![k; 4 << 20]).collect();
        assert!(
            blocks
                .iter()
                .enumerate()
                .all(|(k, b)| b.iter().all(|&v| usize::from(v) == k))
        );
    }
}
