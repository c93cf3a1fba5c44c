//! One topic crossing the bridge: an [`OutPort`] reads the local topic and puts each sample
//! on zenoh; an [`InPort`] takes zenoh samples (decoded and checked on zenoh's thread),
//! queues the newest through [`crate::queue`] and publishes them into shared memory on the
//! stage's thread. Both count what they pass, drop and refuse.

use std::cell::RefCell;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::ipc::Service as IpcService;
use zenoh::Wait;
use zenoh::bytes::Encoding;
use zenoh::qos::CongestionControl;
use zenoh::sample::Locality;

use hvs_runtime::clock::wall_now_ns;
use hvs_runtime::config::BridgeTopic;
use hvs_runtime::ipc::{IpcNode, TopicPublisher, TopicSubscriber};
use hvs_runtime::pacing::RateLimit;
use hvs_runtime::stage::StageError;
use hvs_runtime::stats::LatencyWindow;
use hvs_shared::messages::{BridgeTopicStats, NAME_LEN, encode_name};
use hvs_shared::topics::{self, Topic};

use crate::check::Bridged;
use crate::queue::{NewestReceiver, newest};
use crate::wire;

/// Which way a topic crosses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// Local shared memory to zenoh.
    Out = 0,
    /// zenoh to local shared memory.
    In = 1,
}

/// A topic's counters since the bridge started.
#[derive(Debug, Default)]
pub struct Counters {
    /// Messages passed.
    pub messages: u64,
    /// Contract bytes passed.
    pub raw_bytes: u64,
    /// Bytes on the wire.
    pub wire_bytes: u64,
    /// Queue overflows (in) or rate-limited samples (out).
    pub dropped: u64,
    hops: LatencyWindow,
}

impl Counters {
    /// The stats entry, taking the hop latencies gathered since the last call.
    pub fn entry(&mut self, name: &str, direction: Direction, rejected: u64) -> BridgeTopicStats {
        let hop = self.hops.take_summary();
        BridgeTopicStats {
            topic: encode_name::<NAME_LEN>(name),
            direction: direction as u32,
            reserved: 0,
            messages: self.messages,
            raw_bytes: self.raw_bytes,
            wire_bytes: self.wire_bytes,
            dropped: self.dropped,
            rejected,
            hop_p50_ns: hop.p50_ns,
            hop_p99_ns: hop.p99_ns,
        }
    }

    /// Counts one message.
    pub fn count(&mut self, raw: usize, wire: usize) {
        self.messages += 1;
        self.raw_bytes += raw as u64;
        self.wire_bytes += wire as u64;
    }
}

/// A topic crossing the bridge, either way.
pub trait Port {
    /// The topic.
    fn topic(&self) -> BridgeTopic;
    /// Moves every waiting sample across; returns how many. (`&self`: the stage's WaitSet
    /// keeps the port's listener borrowed while it runs.)
    fn pump(&self) -> Result<usize, StageError>;
    /// The counters as a stats entry.
    fn stats(&self) -> BridgeTopicStats;
    /// The listener to wake the stage on (outgoing topics).
    fn listener(&self) -> Option<&Listener<IpcService>>;
}

/// The zenoh key of an hvs topic.
pub fn key(prefix: &str, topic: BridgeTopic) -> String {
    format!("{prefix}/{}", topic.path())
}

/// A local topic sent to zenoh.
pub struct OutPort<T: Bridged> {
    topic: BridgeTopic,
    sub: TopicSubscriber<T>,
    publisher: zenoh::pubsub::Publisher<'static>,
    compress: bool,
    state: RefCell<OutState>,
}

struct OutState {
    rate: Option<RateLimit>,
    seq: u64,
    counters: Counters,
}

impl<T: Bridged> OutPort<T> {
    /// Subscribes to the local topic and declares the zenoh publisher.
    pub fn open(
        node: &IpcNode,
        session: &zenoh::Session,
        prefix: &str,
        topic: BridgeTopic,
        local: &Topic<T>,
        compress: bool,
        rate_hz: Option<f64>,
    ) -> Result<Self, StageError> {
        let sub = node.subscriber(local, local.max_buffer.min(4))?;
        let key = key(prefix, topic);
        let publisher = session
            .declare_publisher(key.clone())
            .encoding(Encoding::APPLICATION_OCTET_STREAM.with_schema(T::TYPE_NAME))
            // A slow link drops images rather than stalling the stage.
            .congestion_control(CongestionControl::Drop)
            .allowed_destination(Locality::Remote)
            .wait()
            .map_err(|e| StageError::from(format!("zenoh publisher {key}: {e}")))?;
        Ok(Self {
            topic,
            sub,
            publisher,
            compress: compress && topic.is_bulk(),
            state: RefCell::new(OutState {
                rate: rate_hz.map(RateLimit::new),
                seq: 0,
                counters: Counters::default(),
            }),
        })
    }
}

impl<T: Bridged> Port for OutPort<T> {
    fn topic(&self) -> BridgeTopic {
        self.topic
    }

    fn pump(&self) -> Result<usize, StageError> {
        self.sub.clear_events();
        let mut state = self.state.borrow_mut();
        let mut n = 0;
        while let Some(sample) = self.sub.receive()? {
            let now = wall_now_ns();
            if let Some(rate) = &mut state.rate
                && !rate.admit(now)
            {
                state.counters.dropped += 1;
                continue;
            }
            state.seq += 1;
            let value = sample.payload();
            let (payload, attachment) = wire::encode(value, self.compress, now, state.seq);
            let wire_len = payload.len();
            self.publisher
                .put(payload)
                .attachment(attachment.to_vec())
                .wait()
                .map_err(|e| StageError::from(format!("zenoh put {}: {e}", self.topic)))?;
            state.counters.count(core::mem::size_of::<T>(), wire_len);
            n += 1;
        }
        Ok(n)
    }

    fn stats(&self) -> BridgeTopicStats {
        self.state
            .borrow_mut()
            .counters
            .entry(self.topic.path(), Direction::Out, 0)
    }

    fn listener(&self) -> Option<&Listener<IpcService>> {
        Some(self.sub.listener())
    }
}

/// A checked sample from zenoh, waiting for the stage's thread.
struct Incoming<T> {
    value: Box<T>,
    sent_wall_ns: u64,
    wire_len: usize,
}

/// A zenoh topic published into local shared memory.
pub struct InPort<T: Bridged> {
    topic: BridgeTopic,
    rx: NewestReceiver<Incoming<T>>,
    publisher: RefCell<TopicPublisher<T>>,
    rejected: Arc<AtomicU64>,
    counters: RefCell<Counters>,
    _subscriber: zenoh::pubsub::Subscriber<()>,
}

impl<T: Bridged> InPort<T> {
    /// Declares the zenoh subscriber and opens the local publisher.
    pub fn open(
        node: &IpcNode,
        session: &zenoh::Session,
        prefix: &str,
        topic: BridgeTopic,
        local: &Topic<T>,
        queue: usize,
    ) -> Result<Self, StageError> {
        let publisher = node.publisher(local)?;
        let (tx, rx) = newest::<Incoming<T>>(queue);
        let rejected = Arc::new(AtomicU64::new(0));
        let rejected_cb = Arc::clone(&rejected);
        let key = key(prefix, topic);
        let subscriber = session
            .declare_subscriber(key.clone())
            .allowed_origin(Locality::Remote)
            .callback(move |sample| {
                // zenoh's thread: decode and check here, so only well-formed values queue.
                // "application/octet-stream;hvs::StereoFrame640x480": the schema names the type.
                let encoding = sample.encoding().to_string();
                let type_name = encoding.split_once(';').map(|(_, schema)| schema);
                let payload = sample.payload().to_bytes();
                let attachment = sample.attachment().map(|a| a.to_bytes());
                match wire::decode::<T>(type_name, &payload, attachment.as_deref()) {
                    Ok((value, env)) => {
                        tx.push(Incoming {
                            value,
                            sent_wall_ns: env.sent_wall_ns,
                            wire_len: payload.len(),
                        });
                    }
                    Err(e) => {
                        let n = rejected_cb.fetch_add(1, Ordering::Relaxed) + 1;
                        // The first few, then one in a hundred: a flood must not flood the log.
                        if n <= 5 || n.is_multiple_of(100) {
                            tracing::warn!(
                                "dropped a malformed message on {} ({n} so far): {e}",
                                sample.key_expr()
                            );
                        }
                    }
                }
            })
            .wait()
            .map_err(|e| StageError::from(format!("zenoh subscriber {key}: {e}")))?;
        Ok(Self {
            topic,
            rx,
            publisher: RefCell::new(publisher),
            rejected,
            counters: RefCell::new(Counters::default()),
            _subscriber: subscriber,
        })
    }
}

impl<T: Bridged> Port for InPort<T> {
    fn topic(&self) -> BridgeTopic {
        self.topic
    }

    fn pump(&self) -> Result<usize, StageError> {
        let mut publisher = self.publisher.borrow_mut();
        let mut counters = self.counters.borrow_mut();
        let mut n = 0;
        while let Some(incoming) = self.rx.try_pop() {
            let mut sample = publisher.loan()?;
            bytemuck::bytes_of_mut(sample.payload_mut())
                .copy_from_slice(bytemuck::bytes_of(&*incoming.value));
            publisher.send(sample)?;
            counters
                .hops
                .record(wall_now_ns().saturating_sub(incoming.sent_wall_ns));
            counters.count(core::mem::size_of::<T>(), incoming.wire_len);
            n += 1;
        }
        Ok(n)
    }

    fn stats(&self) -> BridgeTopicStats {
        let mut counters = self.counters.borrow_mut();
        counters.dropped = self.rx.dropped();
        let rejected = self.rejected.load(Ordering::Relaxed);
        counters.entry(self.topic.path(), Direction::In, rejected)
    }

    fn listener(&self) -> Option<&Listener<IpcService>> {
        None
    }
}

/// Opens the port of `topic` in `direction`, typed by the topic's contract type.
pub fn open_port(
    node: &IpcNode,
    session: &zenoh::Session,
    cfg: &hvs_runtime::config::BridgeConfig,
    topic: BridgeTopic,
    direction: Direction,
) -> Result<Box<dyn Port>, StageError> {
    use hvs_runtime::config::BridgeCompression;
    let prefix = cfg.key_prefix.as_str();
    let compress = cfg.compression == BridgeCompression::Lz4;
    let rate = cfg.rate_hz.get(&topic).copied();
    macro_rules! open {
        ($local:expr) => {
            match direction {
                Direction::Out => Box::new(OutPort::open(
                    node, session, prefix, topic, &$local, compress, rate,
                )?) as Box<dyn Port>,
                Direction::In => Box::new(InPort::open(
                    node, session, prefix, topic, &$local, cfg.queue,
                )?) as Box<dyn Port>,
            }
        };
    }
    Ok(match topic {
        BridgeTopic::FramesLo => open!(topics::FRAMES_LO),
        BridgeTopic::FramesHi => open!(topics::FRAMES_HI),
        BridgeTopic::DisparityLo => open!(topics::DISPARITY_LO),
        BridgeTopic::DisparityHi => open!(topics::DISPARITY_HI),
        BridgeTopic::Ranges => open!(topics::RANGES),
        BridgeTopic::Decisions => open!(topics::DECISIONS),
        BridgeTopic::ActuatorSent => open!(topics::ACTUATOR_SENT),
        BridgeTopic::Pose => open!(topics::DECISION_POSE),
    })
}
