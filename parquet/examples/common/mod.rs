//! What the examples share.

/// This thread's CPU time in seconds (Linux: the first field of schedstat, in ns): the machine
/// is shared, so wall time would measure the other builds too.
pub fn cpu_s() -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse::<f64>().ok())
        .map_or(f64::NAN, |ns| ns / 1e9)
}
