//! Time stamps: `CLOCK_MONOTONIC` nanoseconds, the clock every hvs message uses.

use nix::time::{ClockId, clock_gettime};

/// Current `CLOCK_MONOTONIC` time in nanoseconds (the kernel clock V4L2 stamps buffers with).
pub fn monotonic_ns() -> u64 {
    match clock_gettime(ClockId::CLOCK_MONOTONIC) {
        Ok(ts) => (ts.tv_sec() as u64)
            .saturating_mul(1_000_000_000)
            .saturating_add(ts.tv_nsec() as u64),
        // CLOCK_MONOTONIC cannot fail on Linux; 0 makes any age computed from it huge, which
        // every consumer treats as "stale".
        Err(_) => 0,
    }
}

/// Nanoseconds elapsed since `earlier_ns` (0 if the clock reads earlier).
pub fn elapsed_ns(earlier_ns: u64) -> u64 {
    monotonic_ns().saturating_sub(earlier_ns)
}

/// Nanoseconds to milliseconds, for display.
pub fn ns_to_ms(ns: u64) -> f64 {
    ns as f64 / 1e6
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monotonic_clock_advances() {
        let a = monotonic_ns();
        std::thread::sleep(std::time::Duration::from_millis(2));
        let b = monotonic_ns();
        assert!(b > a + 1_000_000, "{a} -> {b}");
        assert!(elapsed_ns(b + 1_000_000_000) == 0);
    }
}
