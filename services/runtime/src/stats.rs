//! Small statistics helpers for status lines, heartbeats and reports.

/// Collects latency samples over a period and reports percentiles.
#[derive(Debug, Default, Clone)]
pub struct LatencyWindow {
    samples_ns: Vec<u64>,
}

/// Percentiles of a set of latency samples.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct LatencySummary {
    /// Number of samples.
    pub count: u64,
    /// Median, ns.
    pub p50_ns: u64,
    /// 99th percentile, ns.
    pub p99_ns: u64,
    /// Largest, ns.
    pub max_ns: u64,
}

impl LatencyWindow {
    /// Adds one sample.
    pub fn record(&mut self, latency_ns: u64) {
        self.samples_ns.push(latency_ns);
    }

    /// Number of samples collected.
    pub fn len(&self) -> usize {
        self.samples_ns.len()
    }

    /// True when no sample was collected.
    pub fn is_empty(&self) -> bool {
        self.samples_ns.is_empty()
    }

    /// Percentiles of the collected samples (without clearing them).
    pub fn summary(&self) -> LatencySummary {
        summarize(&self.samples_ns)
    }

    /// Percentiles of the collected samples, then clears them for the next period.
    pub fn take_summary(&mut self) -> LatencySummary {
        let s = summarize(&self.samples_ns);
        self.samples_ns.clear();
        s
    }
}

/// Nearest-rank percentiles of `samples_ns`.
pub fn summarize(samples_ns: &[u64]) -> LatencySummary {
    if samples_ns.is_empty() {
        return LatencySummary::default();
    }
    let mut sorted = samples_ns.to_vec();
    sorted.sort_unstable();
    LatencySummary {
        count: sorted.len() as u64,
        p50_ns: percentile_sorted(&sorted, 50.0),
        p99_ns: percentile_sorted(&sorted, 99.0),
        max_ns: sorted[sorted.len() - 1],
    }
}

/// Nearest-rank percentile `p` (0..=100) of an ascending, non-empty slice.
pub fn percentile_sorted(sorted: &[u64], p: f64) -> u64 {
    let rank = ((p / 100.0) * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_use_nearest_rank() {
        let v: Vec<u64> = (1..=100).collect();
        let s = summarize(&v);
        assert_eq!((s.p50_ns, s.p99_ns, s.max_ns, s.count), (50, 99, 100, 100));
        let s = summarize(&[7]);
        assert_eq!((s.p50_ns, s.p99_ns, s.max_ns), (7, 7, 7));
        assert_eq!(summarize(&[]), LatencySummary::default());
    }

    #[test]
    fn take_summary_clears() {
        let mut w = LatencyWindow::default();
        w.record(3);
        w.record(1);
        assert_eq!(w.take_summary().max_ns, 3);
        assert!(w.is_empty());
    }
}
