//! `hvs probe hz TOPIC`: the rate of one topic, reported once per period, then the totals.

use std::io::Write;
use std::time::{Duration, Instant};

use hvs_runtime::clock::monotonic_ns;
use hvs_runtime::ipc::ReceiveError;
use hvs_shared::topics::{Topic, TopicByPath};

use super::{AttachError, Payload, Probe, resolve_topic};
use crate::rate::{RateEstimator, RateStats, rate_json, rate_line};

/// Options of `hvs probe hz`.
#[derive(Debug, Clone)]
pub struct HzOptions {
    /// Stop after this many reports.
    pub count: Option<u64>,
    /// Stop after this long.
    pub duration: Option<Duration>,
    /// Time between reports.
    pub report_period: Duration,
    /// JSON lines instead of text.
    pub json: bool,
}

/// Why `hvs probe hz` failed.
#[derive(Debug, thiserror::Error)]
pub enum HzError {
    /// Attaching failed.
    #[error(transparent)]
    Attach(#[from] AttachError),
    /// Receiving failed.
    #[error("measuring the rate of topic {topic}")]
    Receive {
        /// The topic path.
        topic: String,
        /// The receive error.
        #[source]
        source: ReceiveError,
    },
    /// Waiting on the topic's listener failed.
    #[error("measuring the rate of topic {topic}: waiting failed: {detail}")]
    Wait {
        /// The topic path.
        topic: String,
        /// iceoryx2's reason.
        detail: String,
    },
    /// Writing the output failed.
    #[error("measuring the rate of topic {topic}: cannot write the output")]
    Output {
        /// The topic path.
        topic: String,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
}

/// `hvs probe hz TOPIC`: prints the rate once per `report_period`, then a total line; returns
/// the totals.
pub fn hz(
    probe: &Probe,
    path: &str,
    opts: &HzOptions,
    out: &mut dyn Write,
) -> Result<RateStats, HzError> {
    let by = resolve_topic(path)?;
    dispatch!(by, hz_typed(probe, path, opts, out))
}

fn hz_typed<T: Payload>(
    topic: &'static Topic<T>,
    stage: Option<&'static str>,
    probe: &Probe,
    path: &str,
    opts: &HzOptions,
    out: &mut dyn Write,
) -> Result<RateStats, HzError> {
    let sub = probe.subscribe(topic, stage, path, topic.max_buffer)?;
    let output = |source| HzError::Output {
        topic: path.to_string(),
        source,
    };
    let mut rate = RateEstimator::new();
    let start = Instant::now();
    let end = opts.duration.map(|d| start + d);
    let period = opts.report_period.max(Duration::from_millis(10));
    let mut next_report = start + period;
    let mut reports = 0u64;
    loop {
        let now = Instant::now();
        if end.is_some_and(|e| now >= e) || opts.count.is_some_and(|c| reports >= c) {
            break;
        }
        if now >= next_report {
            let stats = rate.take_window();
            let line = if opts.json {
                rate_json(path, &stats).to_string()
            } else {
                rate_line(path, &stats)
            };
            writeln!(out, "{line}")
                .and_then(|()| out.flush())
                .map_err(output)?;
            reports += 1;
            next_report += period;
            continue;
        }
        let until = end.map_or(next_report, |e| e.min(next_report));
        let awake = probe
            .wait(&sub, until.saturating_duration_since(now))
            .map_err(|detail| HzError::Wait {
                topic: path.to_string(),
                detail,
            })?;
        let arrival_ns = monotonic_ns();
        while let Some(s) = sub.receive().map_err(|source| HzError::Receive {
            topic: path.to_string(),
            source,
        })? {
            rate.observe(
                s.payload().sequence(),
                s.payload().stamp_ns().unwrap_or(arrival_ns),
            );
        }
        if !awake {
            break;
        }
    }
    let total = rate.total();
    let line = if opts.json {
        let mut v = rate_json(path, &total);
        v["total"] = true.into();
        v["elapsed_s"] = start.elapsed().as_secs_f64().into();
        v.to_string()
    } else {
        format!(
            "{} (total over {:.1} s)",
            rate_line(path, &total),
            start.elapsed().as_secs_f64()
        )
    };
    writeln!(out, "{line}")
        .and_then(|()| out.flush())
        .map_err(output)?;
    Ok(total)
}
