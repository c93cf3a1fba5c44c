//! The IPC glue: attaching to an instance as ordinary iceoryx2 subscribers and running each
//! probe command (`list`, `hz`, `echo`, `snapshot`, `top`).
//!
//! A probe only ever opens existing services and creates subscribers (and their listeners)
//! with the topics' own settings from [`hvs_shared::topics`]; it never opens a publisher on a
//! pipeline topic and never creates a service. Every topic reserves subscriber slots for
//! probes and uses safe overflow, so a probe that reads slowly only loses samples itself (the
//! publisher replaces the oldest one in the probe's queue) and a probe that is killed leaves a
//! queue nobody reads, which the publisher keeps overwriting until the next process that
//! creates an iceoryx2 node removes the dead node's resources.

use std::collections::VecDeque;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use hvs_fusion::{DepthModel, FusionPath};
use hvs_runtime::clock::monotonic_ns;
use hvs_runtime::config::{HvsConfig, STAGE_NAMES};
use hvs_runtime::ipc::{
    IpcNode, NodeOpenError, ReceiveError, ReceivedSample, TopicOpenError, TopicSubscriber,
};
use hvs_shared::messages::{
    Decision, DisparityHeader, DisparityMap320x240, DisparityMap640x480, RangeSource, Sequenced,
    StageHeartbeat, StereoFrame320x240, StereoFrame640x480, SupervisorStatus,
};
use hvs_shared::topics::{self, Topic, TopicByPath, known_topic_paths, topic_by_path};
use iceoryx2::prelude::*;

use crate::format::Describe;
use crate::rate::{RateEstimator, RateStats, rate_json, rate_line};
use crate::render::{ColourScale, disparity_image, fused_image, stereo_pair_image};
use crate::top::{CLEAR_SCREEN, TopView, render_top};

/// A payload a probe can attach to: every hvs message type.
pub trait Payload: core::fmt::Debug + ZeroCopySend + Sequenced + Describe + 'static {}

impl<T: core::fmt::Debug + ZeroCopySend + Sequenced + Describe + 'static> Payload for T {}

/// Calls the generic function `$f(topic, stage, args...)` with the typed topic of a
/// [`TopicByPath`] (`stage` is `Some` for heartbeats).
macro_rules! dispatch {
    ($by:expr, $f:ident ( $($arg:expr),* $(,)? )) => {
        match $by {
            TopicByPath::StereoFrame640x480(t) => $f(t, None, $($arg),*),
            TopicByPath::StereoFrame320x240(t) => $f(t, None, $($arg),*),
            TopicByPath::DisparityMap640x480(t) => $f(t, None, $($arg),*),
            TopicByPath::DisparityMap320x240(t) => $f(t, None, $($arg),*),
            TopicByPath::SimTruth(t) => $f(t, None, $($arg),*),
            TopicByPath::RangeReport(t) => $f(t, None, $($arg),*),
            TopicByPath::Decision(t) => $f(t, None, $($arg),*),
            TopicByPath::ActuatorReport(t) => $f(t, None, $($arg),*),
            TopicByPath::StageHeartbeat(t, stage) => $f(t, Some(stage), $($arg),*),
            TopicByPath::SupervisorStatus(t) => $f(t, None, $($arg),*),
            TopicByPath::ControlRequest(t) => $f(t, None, $($arg),*),
        }
    };
}

/// Why a probe could not attach to an instance or one of its topics.
#[derive(Debug, thiserror::Error)]
pub enum AttachError {
    /// The topic path is not one of the pipeline's topics.
    #[error("unknown topic {topic:?}; known topics: {known}")]
    UnknownTopic {
        /// The path given.
        topic: String,
        /// Every known path, comma-separated.
        known: String,
    },
    /// Nothing of the instance exists: no supervisor is running for it.
    #[error(
        "no hvs pipeline is running for instance {instance:?} (start one with `hvs run --instance {instance}`)"
    )]
    NotRunning {
        /// The instance.
        instance: String,
    },
    /// The pipeline runs but this topic was never created.
    #[error(
        "topic {topic} of instance {instance:?} does not exist (its stage has not started yet or is disabled)"
    )]
    NoSuchTopic {
        /// The instance.
        instance: String,
        /// The topic path.
        topic: String,
    },
    /// The probe's own iceoryx2 node could not be created.
    #[error("cannot attach a probe to instance {instance:?}")]
    Node {
        /// The instance.
        instance: String,
        /// The node error.
        #[source]
        source: NodeOpenError,
    },
    /// The subscriber could not be created.
    #[error("cannot subscribe to topic {topic} of instance {instance:?}")]
    Subscribe {
        /// The instance.
        instance: String,
        /// The topic path.
        topic: String,
        /// The iceoryx2 error.
        #[source]
        source: TopicOpenError,
    },
    /// The service exists but its details could not be read.
    #[error("cannot inspect topic {topic} of instance {instance:?}: {detail}")]
    Inspect {
        /// The instance.
        instance: String,
        /// The topic path.
        topic: String,
        /// iceoryx2's reason.
        detail: String,
    },
}

/// A probe attached to one instance: an iceoryx2 node that only subscribes.
pub struct Probe {
    pub(crate) node: IpcNode,
}

impl Probe {
    /// Creates the probe's node (`hvs-probe-<pid>`) for `instance`. Attaching alone does not
    /// check that a pipeline runs; the commands do.
    pub fn attach(instance: &str) -> Result<Self, AttachError> {
        let node = IpcNode::create(instance, &format!("hvs-probe-{}", std::process::id()))
            .map_err(|source| AttachError::Node {
                instance: instance.to_string(),
                source,
            })?;
        Ok(Self { node })
    }

    /// The instance attached to.
    pub fn instance(&self) -> &str {
        self.node.instance()
    }

    /// True once SIGINT or SIGTERM was received.
    pub fn termination_requested(&self) -> bool {
        self.node.termination_requested()
    }

    /// Publisher count, subscriber count and subscriber limit of a topic; `None` when the
    /// service does not exist.
    fn counts<T: Payload>(&self, path: &str) -> Result<Option<(usize, usize, usize)>, AttachError> {
        let ports = self
            .node
            .topic_ports::<T>(path)
            .map_err(|e| AttachError::Inspect {
                instance: self.instance().to_string(),
                topic: path.to_string(),
                detail: hvs_runtime::error_chain(&e),
            })?;
        Ok(ports.map(|p| (p.publishers, p.subscribers, p.max_subscribers)))
    }

    /// True while the instance's supervisor runs (its status topic exists).
    pub fn pipeline_running(&self) -> bool {
        matches!(
            self.counts::<SupervisorStatus>(topics::SUPERVISOR_STATUS.path),
            Ok(Some(_))
        )
    }

    /// The error for a topic that does not exist: the whole instance, or only this topic.
    fn missing(&self, path: &str) -> AttachError {
        if self.pipeline_running() {
            AttachError::NoSuchTopic {
                instance: self.instance().to_string(),
                topic: path.to_string(),
            }
        } else {
            AttachError::NotRunning {
                instance: self.instance().to_string(),
            }
        }
    }

    /// Subscribes to an existing topic with its own settings and a queue of `buffer`.
    pub(crate) fn subscribe<T: Payload>(
        &self,
        topic: &Topic<T>,
        stage: Option<&str>,
        path: &str,
        buffer: usize,
    ) -> Result<TopicSubscriber<T>, AttachError> {
        let result = match stage {
            Some(stage) => self.node.existing_stage_subscriber(topic, stage, buffer),
            None => self.node.existing_subscriber(topic, buffer),
        };
        result.map_err(|e| match e {
            TopicOpenError::NotFound { .. } => self.missing(path),
            source => AttachError::Subscribe {
                instance: self.instance().to_string(),
                topic: path.to_string(),
                source,
            },
        })
    }

    /// Blocks up to `timeout` on the subscriber's listener (woken by the publisher's notify).
    /// Returns false when the wait was interrupted by a termination request.
    fn wait<T: Payload>(
        &self,
        sub: &TopicSubscriber<T>,
        timeout: Duration,
    ) -> Result<bool, String> {
        match sub.listener().timed_wait(|_| {}, timeout) {
            Ok(_) => Ok(!self.termination_requested()),
            Err(e) => {
                if self.termination_requested() {
                    Ok(false)
                } else {
                    Err(format!("{e:?}"))
                }
            }
        }
    }
}

/// Looks a topic path up, or names every known one.
pub fn resolve_topic(path: &str) -> Result<TopicByPath, AttachError> {
    topic_by_path(path).ok_or_else(|| AttachError::UnknownTopic {
        topic: path.to_string(),
        known: known_topic_paths().join(", "),
    })
}

/// Short payload type name (`Decision`) of `T`.
pub(crate) fn short_type_name<T>() -> &'static str {
    let full = core::any::type_name::<T>();
    full.rsplit("::").next().unwrap_or(full)
}

// ---------------------------------------------------------------------------------------------
// list

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

// ---------------------------------------------------------------------------------------------
// hz

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

// ---------------------------------------------------------------------------------------------
// echo

/// Options of `hvs probe echo`.
#[derive(Debug, Clone)]
pub struct EchoOptions {
    /// Stop after this many samples.
    pub count: Option<u64>,
    /// JSON lines instead of text.
    pub json: bool,
    /// Sleep this long after each sample while still holding it (a deliberately slow reader,
    /// to show it cannot slow the pipeline).
    pub slow: Duration,
}

/// Why `hvs probe echo` failed.
#[derive(Debug, thiserror::Error)]
pub enum EchoError {
    /// Attaching failed.
    #[error(transparent)]
    Attach(#[from] AttachError),
    /// Receiving failed.
    #[error("echoing topic {topic}")]
    Receive {
        /// The topic path.
        topic: String,
        /// The receive error.
        #[source]
        source: ReceiveError,
    },
    /// Waiting on the topic's listener failed.
    #[error("echoing topic {topic}: waiting failed: {detail}")]
    Wait {
        /// The topic path.
        topic: String,
        /// iceoryx2's reason.
        detail: String,
    },
    /// Writing the output failed.
    #[error("echoing topic {topic}: cannot write the output")]
    Output {
        /// The topic path.
        topic: String,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
}

/// `hvs probe echo TOPIC`: prints every sample as text or JSON lines; returns how many.
pub fn echo(
    probe: &Probe,
    path: &str,
    opts: &EchoOptions,
    out: &mut dyn Write,
) -> Result<u64, EchoError> {
    let by = resolve_topic(path)?;
    dispatch!(by, echo_typed(probe, path, opts, out))
}

/// One sample as an echo line.
pub fn echo_line<T: Describe>(path: &str, payload: &T, json: bool) -> String {
    if json {
        let mut v = payload.describe_json();
        if let Some(map) = v.as_object_mut() {
            map.insert("topic".into(), path.into());
        }
        v.to_string()
    } else {
        payload.describe_text()
    }
}

fn echo_typed<T: Payload>(
    topic: &'static Topic<T>,
    stage: Option<&'static str>,
    probe: &Probe,
    path: &str,
    opts: &EchoOptions,
    out: &mut dyn Write,
) -> Result<u64, EchoError> {
    let sub = probe.subscribe(topic, stage, path, topic.max_buffer)?;
    let mut printed = 0u64;
    loop {
        if opts.count.is_some_and(|c| printed >= c) {
            return Ok(printed);
        }
        let awake = probe
            .wait(&sub, Duration::from_millis(200))
            .map_err(|detail| EchoError::Wait {
                topic: path.to_string(),
                detail,
            })?;
        if !awake {
            return Ok(printed);
        }
        while let Some(sample) = sub.receive().map_err(|source| EchoError::Receive {
            topic: path.to_string(),
            source,
        })? {
            let line = echo_line(path, sample.payload(), opts.json);
            match writeln!(out, "{line}").and_then(|()| out.flush()) {
                Ok(()) => {}
                // `hvs probe echo ... | head`: the reader is gone, a normal end.
                Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => return Ok(printed),
                Err(source) => {
                    return Err(EchoError::Output {
                        topic: path.to_string(),
                        source,
                    });
                }
            }
            printed += 1;
            if !opts.slow.is_zero() && !probe.node.sleep(opts.slow) {
                return Ok(printed);
            }
            // `sample` is released only here: a slow probe holds a borrowed sample the whole
            // time it sleeps, the worst case for the publisher.
            drop(sample);
            if opts.count.is_some_and(|c| printed >= c) {
                return Ok(printed);
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// snapshot

/// Options of `hvs probe snapshot`.
#[derive(Debug, Clone)]
pub struct SnapshotOptions {
    /// PNG file to write.
    pub out: PathBuf,
    /// Render the fused map (disparity at edge pixels) over the left image.
    pub fused: bool,
    /// Give up when no suitable sample arrives within this time.
    pub timeout: Duration,
}

/// What `hvs probe snapshot` wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SnapshotInfo {
    /// Frame id of the sample shown.
    pub frame_id: u64,
    /// PNG width, px.
    pub width_px: u32,
    /// PNG height, px.
    pub height_px: u32,
}

/// Why `hvs probe snapshot` failed.
#[derive(Debug, thiserror::Error)]
pub enum SnapshotError {
    /// Attaching failed.
    #[error(transparent)]
    Attach(#[from] AttachError),
    /// The topic carries no image.
    #[error(
        "topic {topic} carries no image; snapshot takes frames/320x240, frames/640x480, sim/camera/640x480, disparity/320x240, disparity/640x480 or sim/gt_disparity/640x480"
    )]
    NotAnImage {
        /// The topic path.
        topic: String,
    },
    /// `--fused` was given with a topic that is not a disparity map.
    #[error(
        "--fused needs a disparity topic (disparity/320x240, disparity/640x480, sim/gt_disparity/640x480), not {topic}"
    )]
    FusedNeedsDisparity {
        /// The topic path.
        topic: String,
    },
    /// No suitable sample arrived in time.
    #[error("no sample of topic {topic} of instance {instance:?} arrived within {timeout_s:.1} s")]
    Timeout {
        /// The instance.
        instance: String,
        /// The topic path (both topics for `--fused`).
        topic: String,
        /// The time waited, s.
        timeout_s: f64,
    },
    /// Receiving failed.
    #[error("snapshot of topic {topic}")]
    Receive {
        /// The topic path.
        topic: String,
        /// The receive error.
        #[source]
        source: ReceiveError,
    },
    /// The PNG could not be written.
    #[error("cannot write snapshot {}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The image error.
        #[source]
        source: image::ImageError,
    },
}

/// Frame-pair payloads.
trait PairPayload: Payload {
    const SIZE: (u32, u32);
    fn frame_id(&self) -> u64;
    fn left(&self) -> &[u8];
    fn right(&self) -> &[u8];
}

macro_rules! pair_payload {
    ($t:ty) => {
        impl PairPayload for $t {
            const SIZE: (u32, u32) = (<$t>::WIDTH as u32, <$t>::HEIGHT as u32);
            fn frame_id(&self) -> u64 {
                self.header.frame_id
            }
            fn left(&self) -> &[u8] {
                &self.left
            }
            fn right(&self) -> &[u8] {
                &self.right
            }
        }
    };
}
pair_payload!(StereoFrame320x240);
pair_payload!(StereoFrame640x480);

/// Disparity-map payloads.
trait DisparityPayload: Payload {
    const SIZE: (u32, u32);
    fn header(&self) -> &DisparityHeader;
    fn disparity_q8(&self) -> &[u16];
}

macro_rules! disparity_payload {
    ($t:ty) => {
        impl DisparityPayload for $t {
            const SIZE: (u32, u32) = (<$t>::WIDTH as u32, <$t>::HEIGHT as u32);
            fn header(&self) -> &DisparityHeader {
                &self.header
            }
            fn disparity_q8(&self) -> &[u16] {
                &self.disparity_q8
            }
        }
    };
}
disparity_payload!(DisparityMap320x240);
disparity_payload!(DisparityMap640x480);

/// `hvs probe snapshot TOPIC --out F.png`: writes one sample of an image topic as a PNG.
pub fn snapshot(
    probe: &Probe,
    path: &str,
    config: &HvsConfig,
    opts: &SnapshotOptions,
) -> Result<SnapshotInfo, SnapshotError> {
    let not_image = || SnapshotError::NotAnImage {
        topic: path.to_string(),
    };
    match resolve_topic(path)? {
        TopicByPath::StereoFrame320x240(t) if !opts.fused => snapshot_pair(probe, t, path, opts),
        TopicByPath::StereoFrame640x480(t) if !opts.fused => snapshot_pair(probe, t, path, opts),
        TopicByPath::StereoFrame320x240(_) | TopicByPath::StereoFrame640x480(_) => {
            Err(SnapshotError::FusedNeedsDisparity {
                topic: path.to_string(),
            })
        }
        TopicByPath::DisparityMap320x240(t) if !opts.fused => {
            snapshot_disparity(probe, t, path, config, opts)
        }
        TopicByPath::DisparityMap640x480(t) if !opts.fused => {
            snapshot_disparity(probe, t, path, config, opts)
        }
        TopicByPath::DisparityMap320x240(t) => {
            snapshot_fused(probe, t, path, &topics::FRAMES_LO, config, opts)
        }
        TopicByPath::DisparityMap640x480(t) => {
            // The simulator's exact disparity belongs to its own camera frames.
            let frames = if path == topics::SIM_GT_DISPARITY.path {
                &topics::SIM_CAMERA
            } else {
                &topics::FRAMES_HI
            };
            snapshot_fused(probe, t, path, frames, config, opts)
        }
        _ if opts.fused => Err(SnapshotError::FusedNeedsDisparity {
            topic: path.to_string(),
        }),
        _ => Err(not_image()),
    }
}

/// Waits for the newest sample of `sub` until `deadline`.
fn newest_sample<T: Payload>(
    probe: &Probe,
    sub: &TopicSubscriber<T>,
    path: &str,
    deadline: Instant,
) -> Result<Option<ReceivedSample<T>>, SnapshotError> {
    loop {
        if let Some(s) = sub
            .receive_latest()
            .map_err(|source| SnapshotError::Receive {
                topic: path.to_string(),
                source,
            })?
        {
            return Ok(Some(s));
        }
        let now = Instant::now();
        if now >= deadline || probe.termination_requested() {
            return Ok(None);
        }
        // A failed wait is retried until the deadline (receive above reports real errors).
        let _ = probe.wait(sub, (deadline - now).min(Duration::from_millis(100)));
    }
}

fn timeout_error(probe: &Probe, topic: &str, opts: &SnapshotOptions) -> SnapshotError {
    SnapshotError::Timeout {
        instance: probe.instance().to_string(),
        topic: topic.to_string(),
        timeout_s: opts.timeout.as_secs_f64(),
    }
}

fn save_png<P, C>(img: &image::ImageBuffer<P, C>, out: &Path) -> Result<(), SnapshotError>
where
    P: image::Pixel + image::PixelWithColorType,
    [P::Subpixel]: image::EncodableLayout,
    C: core::ops::Deref<Target = [P::Subpixel]>,
{
    img.save_with_format(out, image::ImageFormat::Png)
        .map_err(|source| SnapshotError::Write {
            path: out.to_path_buf(),
            source,
        })
}

fn snapshot_pair<T: PairPayload>(
    probe: &Probe,
    topic: &'static Topic<T>,
    path: &str,
    opts: &SnapshotOptions,
) -> Result<SnapshotInfo, SnapshotError> {
    let sub = probe.subscribe(topic, None, path, 1)?;
    let sample = newest_sample(probe, &sub, path, Instant::now() + opts.timeout)?
        .ok_or_else(|| timeout_error(probe, path, opts))?;
    let p = sample.payload();
    let (w, h) = T::SIZE;
    let img = stereo_pair_image(p.left(), p.right(), w, h);
    let frame_id = p.frame_id();
    drop(sample);
    save_png(&img, &opts.out)?;
    Ok(SnapshotInfo {
        frame_id,
        width_px: img.width(),
        height_px: img.height(),
    })
}

fn colour_scale(h: &DisparityHeader, width: u32, config: &HvsConfig) -> ColourScale {
    ColourScale::new(
        h.min_disp,
        h.max_disp,
        DepthModel {
            focal_px: config.camera.focal_px(width as usize),
            baseline_m: config.camera.baseline_m,
        },
    )
}

fn snapshot_disparity<T: DisparityPayload>(
    probe: &Probe,
    topic: &'static Topic<T>,
    path: &str,
    config: &HvsConfig,
    opts: &SnapshotOptions,
) -> Result<SnapshotInfo, SnapshotError> {
    let sub = probe.subscribe(topic, None, path, 1)?;
    let sample = newest_sample(probe, &sub, path, Instant::now() + opts.timeout)?
        .ok_or_else(|| timeout_error(probe, path, opts))?;
    let p = sample.payload();
    let (w, h) = T::SIZE;
    let img = disparity_image(p.disparity_q8(), w, h, &colour_scale(p.header(), w, config));
    let frame_id = p.header().frame_id;
    drop(sample);
    save_png(&img, &opts.out)?;
    Ok(SnapshotInfo {
        frame_id,
        width_px: img.width(),
        height_px: img.height(),
    })
}

/// Left images kept at first while waiting for the disparity map of the same frame.
const KEPT_LEFT_IMAGES: usize = 8;
/// At most this many: a map older than every kept image doubles the count (on a loaded
/// machine the 640x480 maps trail the frames by more than 8 frames).
const MAX_KEPT_LEFT_IMAGES: usize = 256;

fn snapshot_fused<D: DisparityPayload, F: PairPayload>(
    probe: &Probe,
    disparity: &'static Topic<D>,
    path: &str,
    frames: &'static Topic<F>,
    config: &HvsConfig,
    opts: &SnapshotOptions,
) -> Result<SnapshotInfo, SnapshotError> {
    let receive_error = |topic: &str| {
        let topic = topic.to_string();
        move |source| SnapshotError::Receive { topic, source }
    };
    let frame_sub = probe.subscribe(frames, None, frames.path, frames.max_buffer)?;
    let disp_sub = probe.subscribe(disparity, None, path, disparity.max_buffer)?;
    let (w, h) = D::SIZE;
    let deadline = Instant::now() + opts.timeout;
    // Copies of recent left images (the frames themselves are released at once).
    let mut lefts: VecDeque<(u64, Vec<u8>)> = VecDeque::new();
    let mut kept = KEPT_LEFT_IMAGES;
    while Instant::now() < deadline {
        while let Some(f) = frame_sub.receive().map_err(receive_error(frames.path))? {
            while lefts.len() >= kept {
                lefts.pop_front();
            }
            lefts.push_back((f.payload().frame_id(), f.payload().left().to_vec()));
        }
        while let Some(d) = disp_sub.receive().map_err(receive_error(path))? {
            let d = d.payload();
            let id = d.header().frame_id;
            let Some((_, left)) = lefts.iter().find(|(fid, _)| *fid == id) else {
                if lefts.front().is_some_and(|(oldest, _)| id < *oldest) {
                    // The map trails the frames by more than the kept images: keep more.
                    kept = (kept * 2).min(MAX_KEPT_LEFT_IMAGES);
                }
                continue;
            };
            if F::SIZE != D::SIZE {
                continue;
            }
            // Fusion's own path (its edge detector and thresholds from the config), so that
            // the snapshot shows what the fusion stage computes.
            let source = if w >= 640 {
                RangeSource::Hi
            } else {
                RangeSource::Lo
            };
            let mut path = FusionPath::new(config, w as usize, h as usize, source);
            path.ranges(left, d.disparity_q8(), None);
            let fused_q8 = path.fused();
            let img = fused_image(left, fused_q8, w, h, &colour_scale(d.header(), w, config));
            save_png(&img, &opts.out)?;
            return Ok(SnapshotInfo {
                frame_id: id,
                width_px: img.width(),
                height_px: img.height(),
            });
        }
        if !probe.node.sleep(Duration::from_millis(5)) {
            break;
        }
    }
    Err(timeout_error(
        probe,
        &format!("{path} with its frame on {}", frames.path),
        opts,
    ))
}

// ---------------------------------------------------------------------------------------------
// top

/// Options of `hvs probe top`.
#[derive(Debug, Clone)]
pub struct TopOptions {
    /// Print one frame (no ANSI escapes) and exit.
    pub once: bool,
    /// Time between frames.
    pub refresh: Duration,
}

/// Why `hvs probe top` failed.
#[derive(Debug, thiserror::Error)]
pub enum TopError {
    /// Attaching failed.
    #[error(transparent)]
    Attach(#[from] AttachError),
    /// The supervisor sent no status.
    #[error("the supervisor of instance {instance:?} sent no status within {waited_s:.1} s")]
    NoStatus {
        /// The instance.
        instance: String,
        /// Time waited, s.
        waited_s: f64,
    },
    /// Receiving failed.
    #[error("top of instance {instance:?}: topic {topic}")]
    Receive {
        /// The instance.
        instance: String,
        /// The topic path.
        topic: String,
        /// The receive error.
        #[source]
        source: ReceiveError,
    },
    /// Writing the output failed.
    #[error("top of instance {instance:?}: cannot write the output")]
    Output {
        /// The instance.
        instance: String,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
}

/// The subscribers of `hvs probe top`; topics that do not exist yet are retried each frame.
struct TopInputs {
    status: TopicSubscriber<SupervisorStatus>,
    heartbeats: Vec<(&'static str, Option<TopicSubscriber<StageHeartbeat>>)>,
    decisions: Option<TopicSubscriber<Decision>>,
}

impl TopInputs {
    fn connect_missing(&mut self, probe: &Probe) {
        for (stage, sub) in &mut self.heartbeats {
            if sub.is_none() {
                let path = format!("{}/{stage}", topics::HEARTBEAT.path);
                *sub = probe
                    .subscribe(&topics::HEARTBEAT, Some(stage), &path, 1)
                    .ok();
            }
        }
        if self.decisions.is_none() {
            self.decisions = probe
                .subscribe(
                    &topics::DECISIONS,
                    None,
                    topics::DECISIONS.path,
                    topics::DECISIONS.max_buffer,
                )
                .ok();
        }
    }
}

/// `hvs probe top`: a live table of every stage, redrawn every `refresh` (or once).
pub fn top(probe: &Probe, opts: &TopOptions, out: &mut dyn Write) -> Result<(), TopError> {
    let instance = probe.instance().to_string();
    let receive_error = |topic: &str| {
        let instance = instance.clone();
        let topic = topic.to_string();
        move |source| TopError::Receive {
            instance,
            topic,
            source,
        }
    };
    let status = probe.subscribe(
        &topics::SUPERVISOR_STATUS,
        None,
        topics::SUPERVISOR_STATUS.path,
        1,
    )?;
    let mut inputs = TopInputs {
        status,
        heartbeats: STAGE_NAMES.iter().map(|s| (*s, None)).collect(),
        decisions: None,
    };
    let mut view = TopView {
        instance: instance.clone(),
        ..TopView::default()
    };
    let mut decision_rate = RateEstimator::new();
    let refresh = opts.refresh.max(Duration::from_millis(50));
    let started = Instant::now();
    // Give up in --once mode when no status came within this time.
    let status_wait = Duration::from_secs(3) + refresh;
    let mut next_frame = started + refresh;
    loop {
        inputs.connect_missing(probe);
        let frame_end = next_frame;
        // Drain every input until the frame is due (decisions are the fastest input: wait on
        // them, else sleep in short steps).
        loop {
            let now_ns = monotonic_ns();
            if let Some(s) = inputs
                .status
                .receive_latest()
                .map_err(receive_error(topics::SUPERVISOR_STATUS.path))?
            {
                view.status = Some(*s.payload());
            }
            for (stage, sub) in &inputs.heartbeats {
                if let Some(sub) = sub
                    && let Some(h) = sub.receive_latest().map_err(receive_error(&format!(
                        "{}/{stage}",
                        topics::HEARTBEAT.path
                    )))?
                {
                    let h = *h.payload();
                    view.heartbeats.retain(|old| old.stage != h.stage);
                    view.heartbeats.push(h);
                }
            }
            if let Some(sub) = &inputs.decisions {
                while let Some(d) = sub
                    .receive()
                    .map_err(receive_error(topics::DECISIONS.path))?
                {
                    decision_rate.observe(
                        d.payload().frame_id,
                        d.payload().stamp_ns().unwrap_or(now_ns),
                    );
                    view.last_decision = Some(*d.payload());
                }
            }
            let now = Instant::now();
            if now >= frame_end || probe.termination_requested() {
                break;
            }
            let step = (frame_end - now).min(Duration::from_millis(20));
            match &inputs.decisions {
                Some(sub) => {
                    let _ = probe.wait(sub, step);
                }
                None => {
                    probe.node.sleep(step);
                }
            }
        }
        if probe.termination_requested() {
            return Ok(());
        }
        let window = decision_rate.take_window();
        view.decision_rate_hz = window.rate_hz;
        view.decision_gaps = decision_rate.total().gaps;
        let write_error = |source| TopError::Output {
            instance: instance.clone(),
            source,
        };
        if opts.once {
            if view.status.is_some() {
                write!(out, "{}", render_top(&view))
                    .and_then(|()| out.flush())
                    .map_err(write_error)?;
                return Ok(());
            }
            if started.elapsed() >= status_wait {
                return Err(TopError::NoStatus {
                    instance,
                    waited_s: started.elapsed().as_secs_f64(),
                });
            }
        } else {
            match write!(out, "{CLEAR_SCREEN}{}", render_top(&view)).and_then(|()| out.flush()) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => return Ok(()),
                Err(e) => return Err(write_error(e)),
            }
        }
        next_frame += refresh;
    }
}
