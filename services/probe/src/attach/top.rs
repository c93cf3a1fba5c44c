//! `hvs probe top`: the live table of every stage, from the supervisor's status, the stages'
//! heartbeats and the decisions (topics that do not exist yet are retried every frame).

use std::io::Write;
use std::time::{Duration, Instant};

use hvs_runtime::clock::monotonic_ns;
use hvs_runtime::config::STAGE_NAMES;
use hvs_runtime::ipc::{ReceiveError, TopicSubscriber};
use hvs_shared::messages::{Decision, StageHeartbeat, SupervisorStatus};
use hvs_shared::topics;

use super::{AttachError, Probe};
use crate::format::Describe;
use crate::rate::RateEstimator;
use crate::top::{CLEAR_SCREEN, TopView, render_top};

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
