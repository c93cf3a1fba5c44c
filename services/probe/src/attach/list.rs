//! `hvs probe list`: every topic of the instance with its ports and its rate, measured on all
//! topics at once by one watcher per existing topic; the table and the JSON of the rows.

use std::time::{Duration, Instant};

use hvs_runtime::clock::monotonic_ns;
use hvs_runtime::ipc::{ReceiveError, TopicSubscriber};
use hvs_shared::topics::{Topic, TopicByPath, known_topic_paths};

use super::{AttachError, Payload, Probe, resolve_topic, short_type_name};
use crate::rate::{RateEstimator, RateStats};

/// One row of `hvs probe list`.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicRow {
    /// Topic path.
    pub topic: String,
    /// Payload type name.
    pub payload: &'static str,
    /// Publisher count, subscriber count (before the probe joined) and subscriber limit;
    /// `None` when the service does not exist.
    pub ports: Option<(usize, usize, usize)>,
    /// Rate measured over the window (`None` when the service does not exist).
    pub stats: Option<RateStats>,
}

/// Why `hvs probe list` failed.
#[derive(Debug, thiserror::Error)]
pub enum ListError {
    /// Attaching failed (or no pipeline runs for the instance).
    #[error(transparent)]
    Attach(#[from] AttachError),
    /// Receiving on a topic failed.
    #[error("listing instance {instance:?}: topic {topic}")]
    Receive {
        /// The instance.
        instance: String,
        /// The topic path.
        topic: String,
        /// The receive error.
        #[source]
        source: ReceiveError,
    },
}

trait Watch {
    fn drain(&mut self, now_ns: u64) -> Result<(), ReceiveError>;
    fn stats(&self) -> RateStats;
}

struct Watched<T: Payload> {
    sub: TopicSubscriber<T>,
    rate: RateEstimator,
}

impl<T: Payload> Watch for Watched<T> {
    fn drain(&mut self, now_ns: u64) -> Result<(), ReceiveError> {
        while let Some(s) = self.sub.receive()? {
            self.rate.observe(
                s.payload().sequence(),
                s.payload().stamp_ns().unwrap_or(now_ns),
            );
        }
        Ok(())
    }

    fn stats(&self) -> RateStats {
        self.rate.window()
    }
}

type WatchedRow = (TopicRow, Option<Box<dyn Watch>>);

fn watch_topic<T: Payload>(
    topic: &'static Topic<T>,
    stage: Option<&'static str>,
    probe: &Probe,
    path: &str,
) -> Result<WatchedRow, AttachError> {
    let ports = probe.counts::<T>(path)?;
    let mut row = TopicRow {
        topic: path.to_string(),
        payload: short_type_name::<T>(),
        ports,
        stats: None,
    };
    if ports.is_none() {
        return Ok((row, None));
    }
    match probe.subscribe(topic, stage, path, topic.max_buffer) {
        Ok(sub) => {
            row.stats = Some(RateEstimator::new().window());
            Ok((
                row,
                Some(Box::new(Watched {
                    sub,
                    rate: RateEstimator::new(),
                })),
            ))
        }
        // Removed between the two calls (a stage restarting): listed as absent.
        Err(AttachError::NoSuchTopic { .. } | AttachError::NotRunning { .. }) => {
            row.ports = None;
            Ok((row, None))
        }
        Err(e) => Err(e),
    }
}

/// `hvs probe list`: every topic of the instance with its ports and the rate measured over
/// `window` (all topics at once).
pub fn list(probe: &Probe, window: Duration) -> Result<Vec<TopicRow>, ListError> {
    let mut watched: Vec<WatchedRow> = Vec::new();
    for path in known_topic_paths() {
        let by = resolve_topic(&path)?;
        watched.push(dispatch!(by, watch_topic(probe, &path))?);
    }
    if watched.iter().all(|(row, _)| row.ports.is_none()) {
        return Err(AttachError::NotRunning {
            instance: probe.instance().to_string(),
        }
        .into());
    }
    let deadline = Instant::now() + window;
    loop {
        let now_ns = monotonic_ns();
        for (row, w) in &mut watched {
            if let Some(w) = w {
                w.drain(now_ns).map_err(|source| ListError::Receive {
                    instance: probe.instance().to_string(),
                    topic: row.topic.clone(),
                    source,
                })?;
            }
        }
        // Polling every 2 ms keeps one waiting point for ~20 topics; rates use the payloads'
        // publication stamps, so the polling step does not blur the periods.
        if Instant::now() >= deadline || !probe.node.sleep(Duration::from_millis(2)) {
            break;
        }
    }
    Ok(watched
        .into_iter()
        .map(|(mut row, w)| {
            if let Some(w) = w {
                row.stats = Some(w.stats());
            }
            row
        })
        .collect())
}

/// The table of `hvs probe list`.
pub fn render_list(instance: &str, window: Duration, rows: &[TopicRow]) -> String {
    let mut out = format!(
        "instance {instance}: {} topics, rates over {:.1} s\n{:<26} {:<20} {:>4} {:>6} {:>9} {:>10} {:>5}\n",
        rows.len(),
        window.as_secs_f64(),
        "TOPIC",
        "TYPE",
        "PUBS",
        "SUBS",
        "RATE Hz",
        "PERIOD ms",
        "GAPS"
    );
    for row in rows {
        match (row.ports, row.stats) {
            (Some((pubs, subs, max)), Some(s)) => out.push_str(&format!(
                "{:<26} {:<20} {:>4} {:>6} {:>9} {:>10} {:>5}\n",
                row.topic,
                row.payload,
                pubs,
                format!("{subs}/{max}"),
                crate::rate::opt(s.rate_hz, 1),
                crate::rate::opt(s.mean_period_ms, 1),
                s.gaps
            )),
            _ => out.push_str(&format!(
                "{:<26} {:<20} {:>4} {:>6} {:>9} {:>10} {:>5}  (not created)\n",
                row.topic, row.payload, "-", "-", "-", "-", "-"
            )),
        }
    }
    out
}

/// The rows of `hvs probe list --json`.
pub fn list_json(instance: &str, window: Duration, rows: &[TopicRow]) -> serde_json::Value {
    let topics: Vec<serde_json::Value> = rows
        .iter()
        .map(|row| {
            let mut v = serde_json::json!({
                "topic": row.topic,
                "type": row.payload,
                "exists": row.ports.is_some(),
            });
            if let (Some((pubs, subs, max)), Some(s)) = (row.ports, row.stats) {
                v["publishers"] = pubs.into();
                v["subscribers"] = subs.into();
                v["max_subscribers"] = max.into();
                v["samples"] = s.samples.into();
                v["gaps"] = s.gaps.into();
                v["rate_hz"] = s.rate_hz.into();
                v["mean_period_ms"] = s.mean_period_ms.into();
            }
            v
        })
        .collect();
    serde_json::json!({
        "instance": instance,
        "window_s": window.as_secs_f64(),
        "topics": topics,
    })
}
