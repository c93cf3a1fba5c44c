//! Rate estimation from sample times and sequence numbers (pure logic, no IPC). The times
//! are the payloads' publication stamps where they carry one, else arrival at the probe.
//!
//! The first sample a probe receives is usually the topic's history sample (published before
//! the probe attached), so its arrival time says nothing about the rate: it only sets the
//! sequence origin. Timing starts at the second sample; the rate is the number of periods
//! over their summed length.

/// Rate statistics of one window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RateStats {
    /// Samples received in the window.
    pub samples: u64,
    /// Sequence numbers skipped in the window: samples the probe missed (overwritten in its
    /// queue) or ids the publisher never sent (the 640x480 path skips frames by design).
    pub gaps: u64,
    /// Arrival rate, Hz (`None` with fewer than two timed arrivals).
    pub rate_hz: Option<f64>,
    /// Mean time between arrivals, ms.
    pub mean_period_ms: Option<f64>,
    /// Shortest time between arrivals, ms.
    pub min_period_ms: Option<f64>,
    /// Longest time between arrivals, ms.
    pub max_period_ms: Option<f64>,
}

/// Accumulates arrivals; [`RateEstimator::take_window`] ends a window and starts the next one
/// (periods stay continuous across windows).
#[derive(Debug, Clone, Default)]
pub struct RateEstimator {
    last_sequence: Option<u64>,
    last_arrival_ns: Option<u64>,
    samples: u64,
    gaps: u64,
    periods: u64,
    sum_period_ns: u64,
    min_period_ns: u64,
    max_period_ns: u64,
    total_samples: u64,
    total_gaps: u64,
    total_periods: u64,
    total_sum_period_ns: u64,
}

impl RateEstimator {
    /// An estimator with nothing seen yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Records a sample with payload sequence number `sequence` that arrived at `arrival_ns`
    /// (any monotonic clock, ns).
    pub fn observe(&mut self, sequence: u64, arrival_ns: u64) {
        self.samples += 1;
        self.total_samples += 1;
        if let Some(last) = self.last_sequence
            && sequence > last
        {
            // A gap: the publisher replaced samples the probe had not taken yet. A lower or
            // equal sequence is a restarted publisher (a new origin): nothing to count.
            let gap = sequence - last - 1;
            self.gaps += gap;
            self.total_gaps += gap;
        }
        match (self.last_sequence, self.last_arrival_ns) {
            // First sample: maybe history, sets the sequence origin only.
            (None, _) => {}
            (Some(_), None) => self.last_arrival_ns = Some(arrival_ns),
            (Some(_), Some(prev)) => {
                let period = arrival_ns.saturating_sub(prev);
                if self.periods == 0 {
                    self.min_period_ns = period;
                    self.max_period_ns = period;
                } else {
                    self.min_period_ns = self.min_period_ns.min(period);
                    self.max_period_ns = self.max_period_ns.max(period);
                }
                self.periods += 1;
                self.sum_period_ns += period;
                self.total_periods += 1;
                self.total_sum_period_ns += period;
                self.last_arrival_ns = Some(arrival_ns);
            }
        }
        self.last_sequence = Some(sequence);
    }

    /// Statistics of the current window, without ending it.
    pub fn window(&self) -> RateStats {
        let ms = |ns: u64| ns as f64 / 1e6;
        let timed = self.periods > 0 && self.sum_period_ns > 0;
        RateStats {
            samples: self.samples,
            gaps: self.gaps,
            rate_hz: timed.then(|| self.periods as f64 * 1e9 / self.sum_period_ns as f64),
            mean_period_ms: timed.then(|| ms(self.sum_period_ns) / self.periods as f64),
            min_period_ms: (self.periods > 0).then(|| ms(self.min_period_ns)),
            max_period_ms: (self.periods > 0).then(|| ms(self.max_period_ns)),
        }
    }

    /// Ends the current window: returns its statistics and starts an empty one.
    pub fn take_window(&mut self) -> RateStats {
        let stats = self.window();
        self.samples = 0;
        self.gaps = 0;
        self.periods = 0;
        self.sum_period_ns = 0;
        self.min_period_ns = 0;
        self.max_period_ns = 0;
        stats
    }

    /// Statistics since the estimator was created (min and max period are not kept).
    pub fn total(&self) -> RateStats {
        let timed = self.total_periods > 0 && self.total_sum_period_ns > 0;
        RateStats {
            samples: self.total_samples,
            gaps: self.total_gaps,
            rate_hz: timed
                .then(|| self.total_periods as f64 * 1e9 / self.total_sum_period_ns as f64),
            mean_period_ms: timed
                .then(|| self.total_sum_period_ns as f64 / 1e6 / self.total_periods as f64),
            min_period_ms: None,
            max_period_ms: None,
        }
    }
}

/// Formats an optional number with `decimals`, or `-` when absent.
pub fn opt(value: Option<f64>, decimals: usize) -> String {
    value.map_or_else(|| "-".to_string(), |v| format!("{v:.decimals$}"))
}

/// One line of `hvs probe hz`: rate, mean/min/max period, samples and losses.
pub fn rate_line(topic: &str, s: &RateStats) -> String {
    format!(
        "{topic}: {} Hz  period mean {} ms min {} max {}  samples {} gaps {}",
        opt(s.rate_hz, 2),
        opt(s.mean_period_ms, 2),
        opt(s.min_period_ms, 2),
        opt(s.max_period_ms, 2),
        s.samples,
        s.gaps
    )
}

/// The same as [`rate_line`] as a JSON object (absent values are `null`).
pub fn rate_json(topic: &str, s: &RateStats) -> serde_json::Value {
    serde_json::json!({
        "topic": topic,
        "rate_hz": s.rate_hz,
        "mean_period_ms": s.mean_period_ms,
        "min_period_ms": s.min_period_ms,
        "max_period_ms": s.max_period_ms,
        "samples": s.samples,
        "gaps": s.gaps,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn steady_arrivals_give_their_rate_and_the_history_sample_is_not_timed() {
        let mut r = RateEstimator::new();
        // A history sample at t = 0, then live ones every 50 ms from t = 7 ms.
        r.observe(10, 0);
        for i in 0..11u64 {
            r.observe(11 + i, 7 * MS + i * 50 * MS);
        }
        let s = r.window();
        assert_eq!(s.samples, 12);
        assert_eq!(s.gaps, 0);
        assert!((s.rate_hz.unwrap() - 20.0).abs() < 1e-9, "{s:?}");
        assert_eq!(s.mean_period_ms, Some(50.0));
        assert_eq!(s.min_period_ms, Some(50.0));
        assert_eq!(s.max_period_ms, Some(50.0));
    }

    #[test]
    fn sequence_gaps_count_and_restarts_do_not() {
        let mut r = RateEstimator::new();
        r.observe(1, 0);
        r.observe(2, 10 * MS);
        r.observe(6, 20 * MS); // 3, 4, 5 gaps
        r.observe(1, 30 * MS); // publisher restarted
        r.observe(2, 45 * MS);
        let s = r.window();
        assert_eq!(s.gaps, 3);
        assert_eq!(s.min_period_ms, Some(10.0));
        assert_eq!(s.max_period_ms, Some(15.0));
    }

    #[test]
    fn windows_restart_counts_but_keep_periods_continuous() {
        let mut r = RateEstimator::new();
        for i in 0..5u64 {
            r.observe(i, i * 100 * MS);
        }
        let first = r.take_window();
        assert_eq!(first.samples, 5);
        assert_eq!(first.rate_hz.map(|h| h.round()), Some(10.0));
        r.observe(5, 500 * MS);
        let second = r.take_window();
        assert_eq!(second.samples, 1);
        assert_eq!(
            second.mean_period_ms,
            Some(100.0),
            "period spans the windows"
        );
        let empty = r.window();
        assert_eq!(empty.samples, 0);
        assert_eq!(empty.rate_hz, None);
        assert_eq!(r.total().samples, 6);
        assert_eq!(r.total().rate_hz.map(|h| h.round()), Some(10.0));
    }

    #[test]
    fn too_few_samples_have_no_rate() {
        let mut r = RateEstimator::new();
        assert_eq!(r.window().rate_hz, None);
        r.observe(1, 0);
        r.observe(2, 5 * MS);
        assert_eq!(
            r.window().rate_hz,
            None,
            "history + one live sample: no period yet"
        );
        assert_eq!(opt(r.window().rate_hz, 1), "-");
        assert_eq!(opt(Some(2.345), 2), "2.35");
    }

    #[test]
    fn lines_show_every_figure() {
        let mut r = RateEstimator::new();
        for i in 0..4u64 {
            r.observe(i, i * 40 * MS);
        }
        let s = r.window();
        assert_eq!(
            rate_line("decisions", &s),
            "decisions: 25.00 Hz  period mean 40.00 ms min 40.00 max 40.00  samples 4 gaps 0"
        );
        let j = rate_json("decisions", &s);
        assert_eq!(j["samples"], 4);
        assert!((j["rate_hz"].as_f64().unwrap() - 25.0).abs() < 1e-9);
        assert!(rate_json("x", &RateEstimator::new().window())["rate_hz"].is_null());
    }
}
