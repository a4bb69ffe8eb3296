//! What the process uses: its CPU time and resident memory (for the run report, `/metrics`,
//! the recording summary and the benchmark), and a thread's CPU time.

use crate::runtime::capture::clock::read_ns;

/// CPU time the whole process has used, in seconds.
pub fn process_cpu_s() -> f64 {
    read_ns(rustix::time::ClockId::ProcessCPUTime) as f64 * 1e-9
}

/// The process's resident memory in bytes (`VmRSS` of `/proc/self/status`), when known.
pub fn process_resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find_map(|l| l.strip_prefix("VmRSS:"))?;
    let kb: u64 = line.trim().trim_end_matches("kB").trim().parse().ok()?;
    Some(kb * 1024)
}

/// CPU time the calling thread has used, in seconds.
pub fn thread_cpu_s() -> f64 {
    read_ns(rustix::time::ClockId::ThreadCPUTime) as f64 * 1e-9
}
