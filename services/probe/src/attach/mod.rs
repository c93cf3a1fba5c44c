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
//!
//! One file per command: [`list()`] (every topic with its ports and rate), [`hz()`],
//! [`echo()`], [`snapshot()`] (one sample as a PNG) and [`top()`] (the live table of the
//! stages).

use std::time::Duration;

use hvs_runtime::ipc::{IpcNode, NodeOpenError, TopicOpenError, TopicSubscriber};
use hvs_shared::messages::{Sequenced, SupervisorStatus};
use hvs_shared::topics::{self, Topic, TopicByPath, known_topic_paths, topic_by_path};
use iceoryx2::prelude::*;

use crate::format::Describe;

/// A payload a probe can attach to: every hvs message type.
pub trait Payload: core::fmt::Debug + ZeroCopySend + Sequenced + Describe + 'static {}

impl<T: core::fmt::Debug + ZeroCopySend + Sequenced + Describe + 'static> Payload for T {}

/// Calls the generic function `$f(topic, stage, args...)` with the typed topic of a
/// [`TopicByPath`] (`stage` is `Some` for heartbeats). The calling module needs
/// `TopicByPath` in scope.
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
            TopicByPath::RobotPose(t) => $f(t, None, $($arg),*),
            TopicByPath::NavMap(t) => $f(t, None, $($arg),*),
            TopicByPath::LogLine(t) => $f(t, None, $($arg),*),
            TopicByPath::StageHeartbeat(t, stage) => $f(t, Some(stage), $($arg),*),
            TopicByPath::SupervisorStatus(t) => $f(t, None, $($arg),*),
            TopicByPath::ControlRequest(t) => $f(t, None, $($arg),*),
        }
    };
}

// After `dispatch!`: its textual scope covers the command modules.
mod echo;
mod hz;
mod list;
mod snapshot;
#[cfg(test)]
mod tests;
mod top;

pub use echo::{EchoError, EchoOptions, echo, echo_line};
pub use hz::{HzError, HzOptions, hz};
pub use list::{ListError, TopicRow, list, list_json, render_list};
pub use snapshot::{SnapshotError, SnapshotInfo, SnapshotOptions, snapshot};
pub use top::{TopError, TopOptions, top};

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
