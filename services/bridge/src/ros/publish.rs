//! The ROS 2 side of the bridge: the left image at both sizes with their camera infos, the
//! 320x240 disparity and the commanded motion, on rmw_zenoh's keys, with the liveliness
//! tokens that make `ros2 topic list` and `ros2 node list` show them.

use std::cell::RefCell;

use zenoh::Wait;
use zenoh::liveliness::LivelinessToken;
use zenoh::qos::CongestionControl;

use hvs_runtime::clock::WallClock;
use hvs_runtime::config::HvsConfig;
use hvs_runtime::ipc::{IpcNode, TopicSubscriber};
use hvs_runtime::pacing::RateLimit;
use hvs_runtime::stage::StageError;
use hvs_shared::messages::{BridgeTopicStats, StereoPayload};
use hvs_shared::topics;

use super::graph::{self, RosType};
use super::messages::{self, Intrinsics, Stamp};
use crate::ports::{Counters, Direction};

/// The coordinate frame of the images (the left camera's optical frame, as in the view).
pub const CAMERA_FRAME: &str = "camera";

/// The ROS 2 topics, relative to the namespace, and their types.
pub const ROS_TOPICS: [(&str, RosType); 6] = [
    ("left/image_raw", RosType::Image),
    ("left/camera_info", RosType::CameraInfo),
    ("left_640x480/image_raw", RosType::Image),
    ("left_640x480/camera_info", RosType::CameraInfo),
    ("disparity", RosType::DisparityImage),
    ("commanded_twist", RosType::Twist),
];

/// One ROS 2 publisher.
struct RosPublisher {
    name: String,
    publisher: zenoh::pubsub::Publisher<'static>,
    gid: [u8; 16],
    seq: i64,
    counters: Counters,
    _token: LivelinessToken,
}

impl RosPublisher {
    fn put(&mut self, payload: Vec<u8>, wall_ns: u64) -> Result<(), StageError> {
        self.seq += 1;
        let len = payload.len();
        let attachment = graph::attachment(self.seq, wall_ns as i64, &self.gid);
        self.publisher
            .put(payload)
            .attachment(attachment.to_vec())
            .wait()
            .map_err(|e| StageError::from(format!("zenoh put {}: {e}", self.name)))?;
        self.counters.count(len, len);
        Ok(())
    }
}

/// What publishing changes (behind a RefCell: the stage's WaitSet keeps the subscribers'
/// listeners borrowed).
struct RosState {
    pubs: Vec<RosPublisher>,
    lo_rate: RateLimit,
    hi_rate: RateLimit,
    disparity_rate: RateLimit,
}

/// The ROS 2 publications of the bridge.
pub struct RosOut {
    frames_lo: TopicSubscriber<hvs_shared::messages::StereoFrame320x240>,
    frames_hi: TopicSubscriber<hvs_shared::messages::StereoFrame640x480>,
    disparity: TopicSubscriber<hvs_shared::messages::DisparityMap320x240>,
    decisions: TopicSubscriber<hvs_shared::messages::Decision>,
    state: RefCell<RosState>,
    clock: WallClock,
    lo: Intrinsics,
    hi: Intrinsics,
    baseline_m: f64,
    forward_speed_mps: f64,
    track_m: f64,
    _node_token: LivelinessToken,
}

fn intrinsics(config: &HvsConfig, width: u32, height: u32) -> Intrinsics {
    Intrinsics {
        width,
        height,
        focal_px: config.camera.focal_px(width as usize),
        cx: f64::from(width) * 0.5,
        cy: f64::from(height) * 0.5,
    }
}

impl RosOut {
    /// Declares the node, its publishers and their liveliness tokens.
    pub fn open(
        node: &IpcNode,
        session: &zenoh::Session,
        config: &HvsConfig,
    ) -> Result<Self, StageError> {
        let ros = &config.bridge.ros;
        let zid = session.zid();
        let zid_text = zid.to_string();
        let ros_node = graph::RosNode {
            domain_id: ros.domain_id,
            zid: &zid_text,
            node_id: 0,
            namespace: &ros.namespace,
            node: &ros.node,
        };
        let node_token = session
            .liveliness()
            .declare_token(ros_node.token())
            .wait()
            .map_err(|e| StageError::from(format!("ROS 2 node token: {e}")))?;
        let mut pubs = Vec::new();
        for (i, (relative, ty)) in ROS_TOPICS.iter().enumerate() {
            let entity_id = i as u32 + 1;
            let topic = graph::full_topic(&ros.namespace, relative);
            let key = graph::data_key(ros.domain_id, &topic, *ty);
            let publisher = session
                .declare_publisher(key.clone())
                .congestion_control(CongestionControl::Drop)
                .wait()
                .map_err(|e| StageError::from(format!("zenoh publisher {key}: {e}")))?;
            let token = session
                .liveliness()
                .declare_token(ros_node.publisher_token(entity_id, &topic, *ty))
                .wait()
                .map_err(|e| StageError::from(format!("ROS 2 token for {topic}: {e}")))?;
            // A GID unique per publisher: the session id with the entity id in its last bytes.
            let mut gid = zid.to_le_bytes();
            gid[12..16].copy_from_slice(&entity_id.to_le_bytes());
            tracing::info!("ROS 2: {topic} ({}) on {key}", ty.ros_name());
            pubs.push(RosPublisher {
                name: topic,
                publisher,
                gid,
                seq: 0,
                counters: Counters::default(),
                _token: token,
            });
        }
        Ok(Self {
            frames_lo: node.subscriber(&topics::FRAMES_LO, 2)?,
            frames_hi: node.subscriber(&topics::FRAMES_HI, 2)?,
            disparity: node.subscriber(&topics::DISPARITY_LO, 2)?,
            decisions: node.subscriber(&topics::DECISIONS, 8)?,
            state: RefCell::new(RosState {
                pubs,
                lo_rate: RateLimit::new(ros.image_hz),
                hi_rate: RateLimit::new(ros.image_hz),
                disparity_rate: RateLimit::new(ros.image_hz),
            }),
            clock: WallClock::now(),
            lo: intrinsics(config, 320, 240),
            hi: intrinsics(config, 640, 480),
            baseline_m: config.camera.baseline_m,
            forward_speed_mps: config.robot.forward_speed_mps,
            track_m: config.robot.track_m,
            _node_token: node_token,
        })
    }

    /// The listeners to wake the stage on.
    pub fn listeners(
        &self,
    ) -> [&iceoryx2::port::listener::Listener<iceoryx2::prelude::ipc::Service>; 4] {
        [
            self.frames_lo.listener(),
            self.frames_hi.listener(),
            self.disparity.listener(),
            self.decisions.listener(),
        ]
    }

    /// Publishes what arrived since the last call; returns the number of ROS messages.
    pub fn pump(&self) -> Result<usize, StageError> {
        let mut guard = self.state.borrow_mut();
        let st = &mut *guard;
        let mut n = 0;
        for sub in [
            self.frames_lo.listener(),
            self.frames_hi.listener(),
            self.disparity.listener(),
            self.decisions.listener(),
        ] {
            let _ = sub.try_wait(|_| {});
        }
        if let Some(s) = self.frames_lo.receive_latest()? {
            n += self.left_image(s.payload(), &mut st.lo_rate, self.lo, &mut st.pubs[0..2])?;
        }
        if let Some(s) = self.frames_hi.receive_latest()? {
            n += self.left_image(s.payload(), &mut st.hi_rate, self.hi, &mut st.pubs[2..4])?;
        }
        if let Some(s) = self.disparity.receive_latest()? {
            let d = s.payload();
            if st.disparity_rate.admit(d.header.capture_ns) {
                let wall = self.clock.wall_ns(d.header.capture_ns);
                let stamp = Stamp {
                    wall_ns: wall,
                    frame_id: CAMERA_FRAME,
                };
                let msg = messages::disparity_image(
                    stamp,
                    d.header.width,
                    d.header.height,
                    &d.disparity_q8,
                    self.lo.focal_px as f32,
                    self.baseline_m as f32,
                    d.header.min_disp,
                    d.header.max_disp,
                );
                st.pubs[4].put(msg, wall)?;
                n += 1;
            }
        }
        while let Some(s) = self.decisions.receive()? {
            let d = s.payload();
            let (v, w) = messages::motion(d, self.forward_speed_mps, self.track_m);
            let wall = self.clock.wall_ns(d.capture_ns);
            st.pubs[5].put(messages::twist(v, w), wall)?;
            n += 1;
        }
        Ok(n)
    }

    /// Publishes a pair's left image and its camera info (`pubs`: those two publishers) when
    /// the rate allows; returns the number of messages sent.
    fn left_image(
        &self,
        frame: &impl StereoPayload,
        rate: &mut RateLimit,
        camera: Intrinsics,
        pubs: &mut [RosPublisher],
    ) -> Result<usize, StageError> {
        let (h, left, _) = frame.parts();
        if !rate.admit(h.capture_ns) {
            return Ok(0);
        }
        let wall = self.clock.wall_ns(h.capture_ns);
        let stamp = Stamp {
            wall_ns: wall,
            frame_id: CAMERA_FRAME,
        };
        let [image, info] = pubs else {
            return Err(StageError::from("a left image needs two ROS 2 publishers"));
        };
        image.put(
            messages::mono8_image(stamp, camera.width, camera.height, left),
            wall,
        )?;
        info.put(messages::camera_info(stamp, camera), wall)?;
        Ok(2)
    }

    /// The counters of every ROS 2 topic.
    pub fn stats(&self) -> Vec<BridgeTopicStats> {
        self.state
            .borrow_mut()
            .pubs
            .iter_mut()
            .map(|p| p.counters.entry(&p.name, Direction::Out, 0))
            .collect()
    }
}
