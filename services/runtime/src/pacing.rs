//! Rate limits (the view's channels, the bridge's topics): at most `hz` messages a second, measured on the sample's own
//! time stamps so that a burst of queued samples does not all pass.

/// Lets a message through at most every `1 / hz` seconds.
#[derive(Debug, Clone, Copy)]
pub struct RateLimit {
    period_ns: u64,
    last_ns: Option<u64>,
}

impl RateLimit {
    /// A limit of `hz` messages a second (`hz` > 0).
    pub fn new(hz: f64) -> Self {
        Self {
            period_ns: (1e9 / hz.max(1e-3)) as u64,
            last_ns: None,
        }
    }

    /// Whether a message stamped `now_ns` may go; if so it counts as sent. A message up to
    /// 10 % early passes, so that a 15 Hz camera is not halved by a 15 Hz limit.
    pub fn admit(&mut self, now_ns: u64) -> bool {
        let due = match self.last_ns {
            None => true,
            Some(last) => now_ns.saturating_sub(last) >= self.period_ns - self.period_ns / 10,
        };
        if due {
            self.last_ns = Some(now_ns);
        }
        due
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passes_the_rate_and_not_more() {
        let mut r = RateLimit::new(15.0);
        // A 30 Hz stream through a 15 Hz limit: every other frame.
        let passed = (0..30u64).filter(|i| r.admit(i * 33_333_333)).count();
        assert_eq!(passed, 15);
        // A 15 Hz stream with jitter passes whole.
        let mut r = RateLimit::new(15.0);
        let passed = (0..30u64)
            .filter(|i| r.admit(i * 66_666_666 + (i % 2) * 3_000_000))
            .count();
        assert_eq!(passed, 30);
    }
}
