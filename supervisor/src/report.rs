//! The JSON report `hvs run --report F` writes at the end of a run.

use hvs_runtime::stats::LatencySummary;
use serde::Serialize;

/// Latency percentiles in milliseconds.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct LatencyMs {
    /// Number of samples.
    pub count: u64,
    /// Median, ms.
    pub p50_ms: f64,
    /// 99th percentile, ms.
    pub p99_ms: f64,
    /// Largest, ms.
    pub max_ms: f64,
}

impl From<LatencySummary> for LatencyMs {
    fn from(s: LatencySummary) -> Self {
        Self {
            count: s.count,
            p50_ms: s.p50_ns as f64 / 1e6,
            p99_ms: s.p99_ns as f64 / 1e6,
            max_ms: s.max_ns as f64 / 1e6,
        }
    }
}

/// End-to-end latencies.
#[derive(Debug, Clone, Default, Serialize)]
pub struct LatencyReport {
    /// From the capture of a pair to the decision made from it (every fast-path frame).
    pub capture_to_decision: LatencyMs,
    /// From the capture of a pair to the serial write of the command decided from it (only the
    /// decisions the 2400-baud link had room for).
    pub capture_to_command: LatencyMs,
}

/// One stage's totals over the run (summed over restarts).
#[derive(Debug, Clone, Serialize)]
pub struct StageReport {
    /// Stage name.
    pub stage: String,
    /// Final state.
    pub state: String,
    /// Samples in.
    pub frames_in: u64,
    /// Samples out.
    pub frames_out: u64,
    /// Input samples lost to overflow.
    pub drops: u64,
    /// Errors.
    pub errors: u64,
    /// Restarts.
    pub restarts: u32,
    /// Last exit status (negative: killed by that signal).
    pub last_exit: i32,
    /// CPU time used (user + system, every incarnation), seconds.
    pub cpu_s: f64,
    /// `cpu_s` over the run's duration, percent of one core.
    pub cpu_pct: f64,
    /// Resident memory at the last reading, MiB.
    pub rss_mib: f64,
    /// Largest resident memory read, MiB.
    pub rss_max_mib: f64,
}

/// The simulator's ground truth at the end.
#[derive(Debug, Clone, Serialize)]
pub struct SimReport {
    /// Final x, m.
    pub x_m: f64,
    /// Final y, m.
    pub y_m: f64,
    /// Final heading, degrees.
    pub heading_deg: f64,
    /// Collision events.
    pub collisions: u32,
    /// Distance driven, m.
    pub odometer_m: f64,
    /// PSC frames the emulator received.
    pub psc_frames: u64,
    /// Malformed PSC frames.
    pub psc_malformed: u32,
}

/// The whole report.
#[derive(Debug, Clone, Serialize)]
pub struct RunReport {
    /// Instance.
    pub instance: String,
    /// Config file.
    pub config: String,
    /// Run time, s.
    pub duration_s: f64,
    /// Per stage.
    pub stages: Vec<StageReport>,
    /// Decisions seen.
    pub decisions: u64,
    /// Serial writes (both wheels each).
    pub commands_sent: u64,
    /// Neutral writes of any reason.
    pub neutral_sent: u64,
    /// Neutral writes because decisions went stale.
    pub watchdog_neutral: u64,
    /// Latencies.
    pub latency: LatencyReport,
    /// Simulator truth, when the simulator ran.
    pub sim: Option<SimReport>,
}
