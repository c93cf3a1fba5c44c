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

/// `CLOCK_REALTIME` now, ns since the Unix epoch (0 before 1970).
pub fn wall_now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

/// Converts `CLOCK_MONOTONIC` stamps to wall-clock (`CLOCK_REALTIME`, Unix epoch) ns, with
/// the offset between the two clocks read once: what recordings and the live view show
/// (Foxglove displays dates), while the payloads keep their monotonic stamps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WallClock {
    /// `CLOCK_REALTIME` minus `CLOCK_MONOTONIC`, ns.
    offset_ns: i128,
}

impl WallClock {
    /// Reads the offset now.
    pub fn now() -> Self {
        Self {
            offset_ns: i128::from(wall_now_ns()) - i128::from(monotonic_ns()),
        }
    }

    /// The wall-clock time of a monotonic stamp, ns since the Unix epoch.
    pub fn wall_ns(&self, monotonic_ns: u64) -> u64 {
        (i128::from(monotonic_ns) + self.offset_ns).max(0) as u64
    }
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

    #[test]
    fn wall_clock_is_unix_time() {
        let w = WallClock::now();
        let unix_ns = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64);
        assert!(w.wall_ns(monotonic_ns()).abs_diff(unix_ns) < 1_000_000_000);
        assert_eq!(w.wall_ns(10) + 5, w.wall_ns(15));
    }
}
