//! iceoryx2 wiring shared by every process: one way to create a node, open a topic, publish in
//! place and receive with drop counting.
//!
//! Each [`TopicPublisher`] owns an iceoryx2 publisher plus a notifier on the event service of
//! the same name; each [`TopicSubscriber`] owns a subscriber plus a listener that a WaitSet
//! blocks on. Every operation has its own error enum, and every error names the service.

use core::cell::Cell;
use core::fmt::Debug;
use core::time::Duration;
use std::sync::LazyLock;

use bytemuck::Pod;
use iceoryx2::node::{NodeState, NodeWaitFailure};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use iceoryx2::sample_mut::SampleMut;

use hvs_shared::messages::Sequenced;
use hvs_shared::topics::Topic;

/// The iceoryx2 service flavour used everywhere: inter-process, shared memory.
pub type IpcService = ipc::Service;

/// A received sample, valid while held (it pins one slot of the publisher's memory).
pub type ReceivedSample<T> = Sample<IpcService, T, ()>;

/// A loaned sample being written in place before [`TopicPublisher::send`].
pub type LoanedSample<T> = SampleMut<IpcService, T, ()>;

/// The iceoryx2 configuration used by hvs: iceoryx2's defaults, built in code so no config file
/// is searched for. Every hvs process uses the same one.
pub fn iceoryx_config() -> &'static Config {
    static CONFIG: LazyLock<Config> = LazyLock::new(Config::default);
    &CONFIG
}

/// An iceoryx2 error, kept whole as the source of hvs's own (each iceoryx2 operation has its
/// own error enum; callers match hvs's variants, and the chain still shows iceoryx2's).
pub type IoxError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Why a node could not be created.
#[derive(Debug, thiserror::Error)]
pub enum NodeOpenError {
    /// The node name is not a valid iceoryx2 node name.
    #[error("invalid iceoryx2 node name {name:?}: {source}")]
    InvalidName {
        /// The name.
        name: String,
        /// iceoryx2's error.
        #[source]
        source: IoxError,
    },
    /// iceoryx2 refused to create the node.
    #[error("cannot create iceoryx2 node {name:?}: {source}")]
    Create {
        /// The name.
        name: String,
        /// iceoryx2's error.
        #[source]
        source: IoxError,
    },
}

/// Why a topic could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum TopicOpenError {
    /// The service name is invalid.
    #[error("invalid service name {service:?}: {source}")]
    InvalidName {
        /// The service.
        service: String,
        /// iceoryx2's error.
        #[source]
        source: IoxError,
    },
    /// The service does not exist (only when opening without creating).
    #[error("service {service:?} does not exist (is the pipeline of this instance running?)")]
    NotFound {
        /// The service.
        service: String,
    },
    /// The service exists with incompatible settings or could not be created.
    #[error("cannot open service {service:?}: {source}")]
    Service {
        /// The service.
        service: String,
        /// iceoryx2's error.
        #[source]
        source: IoxError,
    },
    /// The publisher, subscriber, notifier or listener port could not be created.
    #[error("cannot create {port} on service {service:?}: {source}")]
    Port {
        /// The service.
        service: String,
        /// Which port.
        port: &'static str,
        /// iceoryx2's error.
        #[source]
        source: IoxError,
    },
}

/// Why a sample could not be published.
#[derive(Debug, thiserror::Error)]
pub enum PublishError {
    /// No shared-memory sample could be loaned.
    #[error("cannot loan a sample on {service:?}: {source}")]
    Loan {
        /// The service.
        service: String,
        /// iceoryx2's error.
        #[source]
        source: IoxError,
    },
    /// The sample could not be delivered.
    #[error("cannot send on {service:?}: {source}")]
    Send {
        /// The service.
        service: String,
        /// iceoryx2's error.
        #[source]
        source: IoxError,
    },
}

/// Why receiving failed.
#[derive(Debug, thiserror::Error)]
#[error("cannot receive on {service:?}: {source}")]
pub struct ReceiveError {
    /// The service.
    pub service: String,
    /// iceoryx2's error.
    #[source]
    pub source: IoxError,
}

/// `service` as an iceoryx2 service name.
fn service_name(service: &str) -> Result<ServiceName, TopicOpenError> {
    ServiceName::new(service).map_err(|e| TopicOpenError::InvalidName {
        service: service.to_string(),
        source: e.into(),
    })
}

/// A WaitSet operation that failed (every stage waits on one).
#[derive(Debug, thiserror::Error)]
pub enum WaitSetError {
    /// The WaitSet could not be created.
    #[error("cannot create a WaitSet")]
    Create(#[source] IoxError),
    /// A topic's event listener could not be attached.
    #[error("cannot wait on {service}")]
    Attach {
        /// The service.
        service: String,
        /// iceoryx2's error.
        #[source]
        source: IoxError,
    },
    /// An interval could not be attached.
    #[error("cannot attach a {period_ms} ms interval to the WaitSet")]
    Interval {
        /// The period.
        period_ms: u128,
        /// iceoryx2's error.
        #[source]
        source: IoxError,
    },
    /// Waiting failed.
    #[error("the WaitSet failed")]
    Wait(#[source] IoxError),
}

/// Wakes `waitset` every `period` (the guard must live as long as the wait).
pub fn attach_interval(
    waitset: &WaitSet<IpcService>,
    period: Duration,
) -> Result<iceoryx2::waitset::WaitSetGuard<'_, 'static, IpcService>, WaitSetError> {
    waitset
        .attach_interval(period)
        .map_err(|e| WaitSetError::Interval {
            period_ms: period.as_millis(),
            source: e.into(),
        })
}

/// The ports on a topic's service ([`IpcNode::topic_ports`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TopicPorts {
    /// Publishers connected now.
    pub publishers: usize,
    /// Subscribers connected now.
    pub subscribers: usize,
    /// The most subscribers the service admits.
    pub max_subscribers: usize,
}

/// An iceoryx2 node of one hvs process, bound to an instance.
pub struct IpcNode {
    node: Node<IpcService>,
    instance: String,
}

impl IpcNode {
    /// Creates the node `name` for `instance`, first removing resources that crashed processes
    /// left behind (iceoryx2 issues 1584/601), so a restarted stage can reopen its services.
    pub fn create(instance: &str, name: &str) -> Result<Self, NodeOpenError> {
        let node_name = NodeName::new(name).map_err(|e| NodeOpenError::InvalidName {
            name: name.to_string(),
            source: e.into(),
        })?;
        let removed = cleanup_dead_nodes();
        if removed > 0 {
            tracing::info!(removed, "removed resources of dead iceoryx2 nodes");
        }
        let node = NodeBuilder::new()
            .name(&node_name)
            .config(iceoryx_config())
            .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
            .create::<IpcService>()
            .map_err(|e| NodeOpenError::Create {
                name: name.to_string(),
                source: e.into(),
            })?;
        Ok(Self {
            node,
            instance: instance.to_string(),
        })
    }

    /// The instance this node works in.
    pub fn instance(&self) -> &str {
        &self.instance
    }

    /// The underlying iceoryx2 node.
    pub fn node(&self) -> &Node<IpcService> {
        &self.node
    }

    /// True once SIGINT or SIGTERM was received (checked without sleeping).
    pub fn termination_requested(&self) -> bool {
        matches!(
            self.node.wait(Duration::ZERO),
            Err(NodeWaitFailure::TerminationRequest)
        )
    }

    /// Sleeps up to `period`; returns false once SIGINT or SIGTERM was received.
    pub fn sleep(&self, period: Duration) -> bool {
        !matches!(
            self.node.wait(period),
            Err(NodeWaitFailure::TerminationRequest)
        )
    }

    /// Opens (creating if needed) `topic` and a publisher on it.
    pub fn publisher<T>(&self, topic: &Topic<T>) -> Result<TopicPublisher<T>, TopicOpenError>
    where
        T: Debug + ZeroCopySend + Pod + 'static,
    {
        self.publisher_named(topic, topic.service_name(&self.instance))
    }

    /// Like [`IpcNode::publisher`] for a per-stage topic such as a heartbeat.
    pub fn stage_publisher<T>(
        &self,
        topic: &Topic<T>,
        stage: &str,
    ) -> Result<TopicPublisher<T>, TopicOpenError>
    where
        T: Debug + ZeroCopySend + Pod + 'static,
    {
        self.publisher_named(topic, topic.stage_service_name(&self.instance, stage))
    }

    fn publisher_named<T>(
        &self,
        topic: &Topic<T>,
        service: String,
    ) -> Result<TopicPublisher<T>, TopicOpenError>
    where
        T: Debug + ZeroCopySend + Pod + 'static,
    {
        let factory = self.pubsub_service(topic, &service, true)?;
        // A publisher of a crashed process may still hold the only slot until its node is
        // cleaned up; retry briefly so a restarted stage does not fail on that race.
        let mut attempts = 0;
        let publisher = loop {
            match factory.publisher_builder().create() {
                Ok(p) => break p,
                Err(e) if attempts < 20 => {
                    attempts += 1;
                    tracing::debug!(%service, ?e, "publisher slot busy, cleaning up and retrying");
                    cleanup_dead_nodes();
                    std::thread::sleep(Duration::from_millis(50));
                }
                Err(e) => {
                    return Err(TopicOpenError::Port {
                        service,
                        port: "publisher",
                        source: e.into(),
                    });
                }
            }
        };
        let events = self.event_service(&service, true)?;
        let notifier = events
            .notifier_builder()
            .create()
            .map_err(|e| TopicOpenError::Port {
                service: service.clone(),
                port: "notifier",
                source: e.into(),
            })?;
        Ok(TopicPublisher {
            publisher,
            notifier,
            service,
            sent: 0,
        })
    }

    /// Opens (creating if needed) `topic` and a subscriber with a queue of `buffer` samples.
    pub fn subscriber<T>(
        &self,
        topic: &Topic<T>,
        buffer: usize,
    ) -> Result<TopicSubscriber<T>, TopicOpenError>
    where
        T: Debug + ZeroCopySend + Sequenced + 'static,
    {
        self.subscriber_named(topic, topic.service_name(&self.instance), buffer, true)
    }

    /// Like [`IpcNode::subscriber`] for a per-stage topic such as a heartbeat.
    pub fn stage_subscriber<T>(
        &self,
        topic: &Topic<T>,
        stage: &str,
        buffer: usize,
    ) -> Result<TopicSubscriber<T>, TopicOpenError>
    where
        T: Debug + ZeroCopySend + Sequenced + 'static,
    {
        self.subscriber_named(
            topic,
            topic.stage_service_name(&self.instance, stage),
            buffer,
            true,
        )
    }

    /// Who is on the topic `path` (below `hvs/<instance>/`, e.g. `heartbeat/fusion`), read
    /// from the service's shared state; `None` when the service does not exist. Opening a
    /// port factory creates no port, so this disturbs nobody.
    pub fn topic_ports<T>(&self, path: &str) -> Result<Option<TopicPorts>, TopicOpenError>
    where
        T: Debug + ZeroCopySend + 'static,
    {
        let service = hvs_shared::topics::service_name(&self.instance, path);
        let name = service_name(&service)?;
        match self
            .node
            .service_builder(&name)
            .publish_subscribe::<T>()
            .open()
        {
            Ok(factory) => {
                let dynamic = factory.dynamic_config();
                Ok(Some(TopicPorts {
                    publishers: dynamic.number_of_publishers(),
                    subscribers: dynamic.number_of_subscribers(),
                    max_subscribers: factory.static_config().max_subscribers(),
                }))
            }
            Err(iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError::DoesNotExist) => Ok(None),
            Err(e) => Err(TopicOpenError::Service {
                service,
                source: e.into(),
            }),
        }
    }

    /// Subscribes to an existing topic without creating it: for clients such as `hvs status`
    /// and probes, which must not create services of a pipeline that is not running.
    pub fn existing_subscriber<T>(
        &self,
        topic: &Topic<T>,
        buffer: usize,
    ) -> Result<TopicSubscriber<T>, TopicOpenError>
    where
        T: Debug + ZeroCopySend + Sequenced + 'static,
    {
        self.subscriber_named(topic, topic.service_name(&self.instance), buffer, false)
    }

    /// Like [`IpcNode::existing_subscriber`] for a per-stage topic.
    pub fn existing_stage_subscriber<T>(
        &self,
        topic: &Topic<T>,
        stage: &str,
        buffer: usize,
    ) -> Result<TopicSubscriber<T>, TopicOpenError>
    where
        T: Debug + ZeroCopySend + Sequenced + 'static,
    {
        self.subscriber_named(
            topic,
            topic.stage_service_name(&self.instance, stage),
            buffer,
            false,
        )
    }

    fn subscriber_named<T>(
        &self,
        topic: &Topic<T>,
        service: String,
        buffer: usize,
        create: bool,
    ) -> Result<TopicSubscriber<T>, TopicOpenError>
    where
        T: Debug + ZeroCopySend + Sequenced + 'static,
    {
        let factory = self.pubsub_service(topic, &service, create)?;
        let subscriber = factory
            .subscriber_builder()
            .buffer_size(buffer.clamp(1, topic.max_buffer))
            .create()
            .map_err(|e| TopicOpenError::Port {
                service: service.clone(),
                port: "subscriber",
                source: e.into(),
            })?;
        let events = self.event_service(&service, create)?;
        let listener = events
            .listener_builder()
            .create()
            .map_err(|e| TopicOpenError::Port {
                service: service.clone(),
                port: "listener",
                source: e.into(),
            })?;
        Ok(TopicSubscriber {
            subscriber,
            listener,
            service,
            last_sequence: Cell::new(None),
            received: Cell::new(0),
            dropped: Cell::new(0),
        })
    }

    fn pubsub_service<T>(
        &self,
        topic: &Topic<T>,
        service: &str,
        create: bool,
    ) -> Result<
        iceoryx2::service::port_factory::publish_subscribe::PortFactory<IpcService, T, ()>,
        TopicOpenError,
    >
    where
        T: Debug + ZeroCopySend + 'static,
    {
        let name = service_name(service)?;
        let builder = self
            .node
            .service_builder(&name)
            .publish_subscribe::<T>()
            .max_publishers(topic.max_publishers)
            .max_subscribers(topic.max_subscribers)
            .history_size(topic.history)
            .subscriber_max_buffer_size(topic.max_buffer)
            .subscriber_max_borrowed_samples(topic.max_borrowed)
            .enable_safe_overflow(true);
        if create {
            builder
                .open_or_create()
                .map_err(|e| TopicOpenError::Service {
                    service: service.to_string(),
                    source: e.into(),
                })
        } else {
            builder.open().map_err(|e| match e {
                iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError::DoesNotExist => {
                    TopicOpenError::NotFound {
                        service: service.to_string(),
                    }
                }
                e => TopicOpenError::Service {
                    service: service.to_string(),
                    source: e.into(),
                },
            })
        }
    }

    fn event_service(
        &self,
        service: &str,
        create: bool,
    ) -> Result<iceoryx2::service::port_factory::event::PortFactory<IpcService>, TopicOpenError>
    {
        let name = service_name(service)?;
        let builder = self
            .node
            .service_builder(&name)
            .event()
            .max_notifiers(8)
            .max_listeners(16);
        let result = if create {
            builder.open_or_create().map_err(IoxError::from)
        } else {
            builder.open().map_err(IoxError::from)
        };
        result.map_err(|source| TopicOpenError::Service {
            service: format!("{service} (event)"),
            source,
        })
    }
}

/// The files iceoryx2 keeps in /dev/shm and /tmp/iceoryx2 (to check nothing leaks), except
/// its domain-wide node counter (`*.global_mgmt`), which iceoryx2 creates once without owner
/// and keeps by design.
pub fn iceoryx_files() -> Vec<String> {
    let mut files = Vec::new();
    for dir in ["/dev/shm", "/tmp/iceoryx2/services", "/tmp/iceoryx2/nodes"] {
        if let Ok(entries) = std::fs::read_dir(dir) {
            for e in entries.flatten() {
                let name = e.file_name().to_string_lossy().into_owned();
                let ours = dir != "/dev/shm" || name.starts_with("iox2_");
                if ours && !name.ends_with(".global_mgmt") {
                    files.push(format!("{dir}/{name}"));
                }
            }
        }
    }
    files.sort();
    files
}

/// Counts the iceoryx2 nodes of dead processes whose resources are still there (a run that
/// was killed); `Err` carries iceoryx2's reason when the nodes cannot be listed.
pub fn dead_nodes() -> Result<usize, String> {
    let mut dead = 0;
    Node::<IpcService>::list(iceoryx_config(), |state| {
        if let NodeState::Dead(_) = state {
            dead += 1;
        }
        CallbackProgression::Continue
    })
    .map_err(|e| format!("{e:?}"))?;
    Ok(dead)
}

/// Removes the stale resources of every dead iceoryx2 node; returns how many were removed.
pub fn cleanup_dead_nodes() -> usize {
    let mut removed = 0;
    let result = Node::<IpcService>::list(iceoryx_config(), |state| {
        if let NodeState::Dead(view) = state {
            match view.try_remove_stale_resources() {
                Ok(()) => removed += 1,
                Err(e) => tracing::debug!(?e, "could not remove a dead node's resources"),
            }
        }
        CallbackProgression::Continue
    });
    if let Err(e) = result {
        tracing::warn!(?e, "cannot list iceoryx2 nodes for cleanup");
    }
    removed
}

/// A publisher that writes samples in place and wakes the topic's subscribers.
pub struct TopicPublisher<T: Debug + ZeroCopySend + 'static> {
    publisher: Publisher<IpcService, T, ()>,
    notifier: Notifier<IpcService>,
    service: String,
    sent: u64,
}

impl<T: Debug + ZeroCopySend + Pod + 'static> TopicPublisher<T> {
    /// Loans a shared-memory sample to be written in place (it holds the previous contents of
    /// that slot: overwrite every field you publish).
    pub fn loan(&self) -> Result<LoanedSample<T>, PublishError> {
        // Connect subscribers that joined since the last send (iceoryx2 issue 1641), so a late
        // subscriber of a busy publisher receives and gets its history.
        if let Err(e) = self.publisher.update_connections() {
            tracing::debug!(service = %self.service, ?e, "update_connections failed");
        }
        let sample = self
            .publisher
            .loan_uninit()
            .map_err(|e| PublishError::Loan {
                service: self.service.clone(),
                source: e.into(),
            })?;
        // SAFETY: `T: Pod`, so every bit pattern is a valid `T`; the slot is shared memory that
        // the OS zero-filled when it was mapped and that earlier samples may have overwritten,
        // so its bytes are initialised (never padding or undef from the Rust side).
        Ok(unsafe { sample.assume_init() })
    }

    /// Delivers a written sample and notifies the subscribers' listeners.
    pub fn send(&mut self, sample: LoanedSample<T>) -> Result<usize, PublishError> {
        let receivers = sample.send().map_err(|e| PublishError::Send {
            service: self.service.clone(),
            source: e.into(),
        })?;
        self.sent += 1;
        if let Err(e) = self.notifier.notify() {
            tracing::debug!(service = %self.service, ?e, "notify failed");
        }
        Ok(receivers)
    }

    /// Copies a small value into a sample and sends it.
    pub fn publish_copy(&mut self, value: &T) -> Result<usize, PublishError> {
        let mut sample = self.loan()?;
        *sample.payload_mut() = *value;
        self.send(sample)
    }

    /// Connects subscribers that joined since the last send and delivers their history.
    pub fn update_connections(&self) {
        if let Err(e) = self.publisher.update_connections() {
            tracing::debug!(service = %self.service, ?e, "update_connections failed");
        }
    }

    /// Samples sent by this publisher.
    pub fn sent(&self) -> u64 {
        self.sent
    }

    /// The full service name.
    pub fn service(&self) -> &str {
        &self.service
    }
}

/// A subscriber with the listener its process waits on, counting samples lost to overflow.
pub struct TopicSubscriber<T: Debug + ZeroCopySend + 'static> {
    subscriber: Subscriber<IpcService, T, ()>,
    listener: Listener<IpcService>,
    service: String,
    // Cells: the listener stays borrowed by a WaitSet guard while samples are received.
    last_sequence: Cell<Option<u64>>,
    received: Cell<u64>,
    dropped: Cell<u64>,
}

impl<T: Debug + ZeroCopySend + Sequenced + 'static> TopicSubscriber<T> {
    /// Wakes `waitset` when this topic's publisher notifies (the guard must live as long as
    /// the wait).
    pub fn attach_to<'w, 'a>(
        &'a self,
        waitset: &'w WaitSet<IpcService>,
    ) -> Result<iceoryx2::waitset::WaitSetGuard<'w, 'a, IpcService>, WaitSetError> {
        waitset
            .attach_notification(&self.listener)
            .map_err(|e| WaitSetError::Attach {
                service: self.service.clone(),
                source: e.into(),
            })
    }

    /// The listener to attach to a WaitSet.
    pub fn listener(&self) -> &Listener<IpcService> {
        &self.listener
    }

    /// Consumes pending wake-up events (call after the WaitSet reported this listener).
    pub fn clear_events(&self) {
        if let Err(e) = self.listener.try_wait(|_| {}) {
            tracing::debug!(service = %self.service, ?e, "listener try_wait failed");
        }
    }

    /// Takes the next queued sample, if any.
    pub fn receive(&self) -> Result<Option<ReceivedSample<T>>, ReceiveError> {
        let sample = self.subscriber.receive().map_err(|e| ReceiveError {
            service: self.service.clone(),
            source: e.into(),
        })?;
        if let Some(s) = &sample {
            self.account(s.payload().sequence());
        }
        Ok(sample)
    }

    /// Takes every queued sample and returns only the newest; the skipped ones count as drops.
    pub fn receive_latest(&self) -> Result<Option<ReceivedSample<T>>, ReceiveError> {
        let mut latest = None;
        while let Some(sample) = self.receive()? {
            if latest.replace(sample).is_some() {
                self.dropped.set(self.dropped.get() + 1);
            }
        }
        Ok(latest)
    }

    fn account(&self, sequence: u64) {
        self.received.set(self.received.get() + 1);
        match self.last_sequence.get() {
            // A gap means the publisher overwrote samples we had not taken yet.
            Some(last) if sequence > last => {
                self.dropped.set(self.dropped.get() + sequence - last - 1);
            }
            // Equal or lower: the publisher restarted (a new origin); nothing to count.
            _ => {}
        }
        self.last_sequence.set(Some(sequence));
    }

    /// Samples received.
    pub fn received(&self) -> u64 {
        self.received.get()
    }

    /// Samples the publisher sent that this subscriber never saw.
    pub fn dropped(&self) -> u64 {
        self.dropped.get()
    }

    /// The full service name.
    pub fn service(&self) -> &str {
        &self.service
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hvs_shared::messages::{Decision, StereoFrame320x240};
    use hvs_shared::topics::{DECISIONS, FRAMES_LO};

    fn unique_instance(tag: &str) -> String {
        format!("t{}-{tag}", std::process::id())
    }

    #[test]
    fn frame_written_in_place_arrives_intact() {
        let instance = unique_instance("frame");
        let node = IpcNode::create(&instance, "test-node").expect("node");
        let mut publisher = node.publisher(&FRAMES_LO).expect("publisher");
        let subscriber = node.subscriber(&FRAMES_LO, 2).expect("subscriber");
        let mut sample = publisher.loan().expect("loan");
        let frame = sample.payload_mut();
        frame.header.frame_id = 7;
        for (i, p) in frame.left.iter_mut().enumerate() {
            *p = (i % 251) as u8;
        }
        frame.right.fill(3);
        publisher.send(sample).expect("send");
        let got = subscriber.receive().expect("receive").expect("a sample");
        let frame: &StereoFrame320x240 = got.payload();
        assert_eq!(frame.header.frame_id, 7);
        assert!(
            frame
                .left
                .iter()
                .enumerate()
                .all(|(i, &p)| p == (i % 251) as u8)
        );
        assert!(frame.right.iter().all(|&p| p == 3));
    }

    #[test]
    fn overflow_drops_oldest_and_counts_the_gap() {
        let instance = unique_instance("overflow");
        let node = IpcNode::create(&instance, "test-node").expect("node");
        let mut publisher = node.publisher(&DECISIONS).expect("publisher");
        let subscriber = node.subscriber(&DECISIONS, 2).expect("subscriber");
        for id in 1..=10u64 {
            let d = Decision {
                frame_id: id,
                ..Decision::default()
            };
            // The publisher must never block even though nobody reads.
            publisher.publish_copy(&d).expect("send");
        }
        let mut ids = Vec::new();
        while let Some(s) = subscriber.receive().expect("receive") {
            ids.push(s.payload().frame_id);
        }
        assert_eq!(ids, vec![9, 10], "the two newest survive a buffer of 2");
        // The first sample seen was 9: nothing is known to be lost before it.
        assert_eq!(subscriber.dropped(), 0);
        publisher
            .publish_copy(&Decision {
                frame_id: 14,
                ..Decision::default()
            })
            .expect("send");
        let s = subscriber.receive().expect("receive").expect("sample");
        assert_eq!(s.payload().frame_id, 14);
        assert_eq!(subscriber.dropped(), 3, "11, 12 and 13 never arrived");
    }

    #[test]
    fn late_subscriber_gets_history_without_a_new_send() {
        let instance = unique_instance("late");
        let node = IpcNode::create(&instance, "test-node").expect("node");
        let mut publisher = node.publisher(&DECISIONS).expect("publisher");
        publisher
            .publish_copy(&Decision {
                frame_id: 42,
                ..Decision::default()
            })
            .expect("send");
        let late = node.subscriber(&DECISIONS, 1).expect("subscriber");
        publisher.update_connections();
        let s = late.receive().expect("receive").expect("history sample");
        assert_eq!(s.payload().frame_id, 42);
    }

    #[test]
    fn client_open_of_a_missing_topic_names_it() {
        let instance = unique_instance("missing");
        let node = IpcNode::create(&instance, "test-node").expect("node");
        let err = node
            .existing_subscriber(&DECISIONS, 1)
            .err()
            .expect("must not exist");
        let msg = err.to_string();
        assert!(msg.contains(&format!("hvs/{instance}/decisions")), "{msg}");
        assert!(matches!(err, TopicOpenError::NotFound { .. }), "{msg}");
    }
}
