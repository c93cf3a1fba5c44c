//! Every topic of an hvs pipeline: the whole data flow in one file.
//!
//! ```text
//!            pty (PSC bytes, 2400 baud)
//!   +-------------------------------------------------------------------------------+
//!   v                                                                               |
//!  sim --sim/camera/640x480--> capture --frames/320x240--> stereo-lo --disparity/320x240--+
//!   |                             |  \                                                 |  |
//!   |                             |   +--frames/640x480--> stereo-hi --disparity/640x480-+|
//!   |                             |                                                     ||
//!   |                             +--frames/320x240 + frames/640x480 (left images)--> fusion
//!   |                                                                                   |
//!   |                                                    ranges <-----------------------+
//!   |                                                      |
//!   |                                                      v
//!   |                                                  decision --decisions--> actuator --+
//!   |                                                                             |      |
//!   +--sim/truth--> supervisor, probes, tests          actuator/sent <------------+      |
//!                                          decision --decision/pose, decision/map--> view, probes
//!   view: reads frames, disparity, ranges, decisions, actuator/sent, sim/truth, status;
//!         serves them to Foxglove clients and a web page (WebSocket, loopback by default)
//!                                                                                        |
//!   bridge: allow-listed topics <--zenoh (tcp, explicit endpoints)--> another machine's bridge,
//!           ROS 2 (rmw_zenoh keys, CDR); what it takes in is published here as if local
//!                                                                                        |
//!   every stage --heartbeat/<stage>--> supervisor --supervisor/status--> hvs status, probe
//!   hvs restart / hvs stop --supervisor/control--> supervisor                            |
//!   serial port (real /dev/ttyUSB0, or the simulator's pty) <----------------------------+
//! ```
//!
//! | service (under `hvs/<instance>/`) | payload | publisher | subscribers |
//! |---|---|---|---|
//! | `sim/camera/640x480` | [`StereoFrame640x480`] | sim | capture |
//! | `sim/truth` | [`SimTruth`] | sim | supervisor, probe, tests |
//! | `sim/gt_disparity/640x480` | [`DisparityMap640x480`] | sim | probe, tests (scoring) |
//! | `frames/320x240` | [`StereoFrame320x240`] | capture | stereo-lo, fusion, probe |
//! | `frames/640x480` | [`StereoFrame640x480`] | capture | stereo-hi, fusion, probe |
//! | `disparity/320x240` | [`DisparityMap320x240`] | stereo-lo | fusion, probe |
//! | `disparity/640x480` | [`DisparityMap640x480`] | stereo-hi | fusion, probe |
//! | `ranges` | [`RangeReport`] | fusion | decision, probe |
//! | `decisions` | [`Decision`] | decision | actuator, supervisor, probe |
//! | `actuator/sent` | [`ActuatorReport`] | actuator (capture in a replay) | decision (dead reckoning), supervisor, view, probe |
//! | `decision/pose` | [`RobotPose`] | decision | view, probe |
//! | `decision/map` | [`NavMap`] | decision (a few per second) | view, probe |
//! | `bridge/stats` | [`BridgeStats`] | bridge (once a second) | probe, tests, `hvs bench bridge` |
//! | `log` | [`LogLine`] | supervisor (each stage's standard error, line by line) | view, probe |
//! | `heartbeat/<stage>` | [`StageHeartbeat`] | each stage | supervisor, probe |
//! | `supervisor/status` | [`SupervisorStatus`] | supervisor | `hvs status`, probe |
//! | `supervisor/control` | [`ControlRequest`] | `hvs restart`, `hvs stop` | supervisor |
//!
//! Every publish/subscribe service has an event service of the same name: the publisher
//! notifies it after each send and subscribers block on it (a WaitSet), so nothing polls.
//! Slow readers never block a publisher: every topic uses iceoryx2's safe overflow (the oldest
//! sample in a full subscriber buffer is replaced), and subscribers count the lost samples from
//! gaps in the payload's sequence number ([`Sequenced`](crate::messages::Sequenced)).
//! History 1 means a subscriber that joins late (a probe, a restarted stage) gets the newest
//! sample at once.

use core::marker::PhantomData;

use crate::messages::{
    ActuatorReport, BridgeStats, ControlRequest, Decision, DisparityMap320x240,
    DisparityMap640x480, LogLine, NavMap, RangeReport, RobotPose, SimTruth, StageHeartbeat,
    StereoFrame320x240, StereoFrame640x480, SupervisorStatus,
};

/// Prefix of every hvs service name.
pub const SERVICE_ROOT: &str = "hvs";

/// A publish/subscribe topic: its service name below `hvs/<instance>/` and the settings every
/// process opens it with (iceoryx2 requires openers to agree with the creator).
#[derive(Debug)]
pub struct Topic<T> {
    /// Service path below `hvs/<instance>/`.
    pub path: &'static str,
    /// Maximum number of publishers.
    pub max_publishers: usize,
    /// Maximum number of subscribers (each attached probe takes one).
    pub max_subscribers: usize,
    /// Samples a late subscriber receives on connecting.
    pub history: usize,
    /// Largest subscriber queue.
    pub max_buffer: usize,
    /// Samples one subscriber may hold at once.
    pub max_borrowed: usize,
    _payload: PhantomData<fn() -> T>,
}

impl<T> Topic<T> {
    const fn new(path: &'static str) -> Self {
        Self {
            path,
            max_publishers: 1,
            max_subscribers: 8,
            history: 1,
            max_buffer: 4,
            max_borrowed: 4,
            _payload: PhantomData,
        }
    }

    const fn frames(path: &'static str) -> Self {
        // Image topics: fusion keeps a few recent frames borrowed to pair them with disparity
        // maps that arrive later; every additional slot costs one frame of shared memory.
        Self {
            max_subscribers: 6,
            max_buffer: 2,
            max_borrowed: 5,
            ..Self::new(path)
        }
    }

    const fn with_buffer(self, max_buffer: usize) -> Self {
        Self { max_buffer, ..self }
    }

    const fn with_publishers(self, max_publishers: usize) -> Self {
        Self {
            max_publishers,
            ..self
        }
    }

    /// Full iceoryx2 service name of this topic in `instance`.
    pub fn service_name(&self, instance: &str) -> String {
        service_name(instance, self.path)
    }

    /// Full service name of a per-stage topic (such as [`HEARTBEAT`]) for `stage`.
    pub fn stage_service_name(&self, instance: &str, stage: &str) -> String {
        format!("{SERVICE_ROOT}/{instance}/{}/{stage}", self.path)
    }
}

/// The full service name of the topic `path` (below `hvs/<instance>/`) of an instance.
pub fn service_name(instance: &str, path: &str) -> String {
    format!("{SERVICE_ROOT}/{instance}/{path}")
}

/// Raw camera pairs rendered by the simulator (the simulated Minoru).
pub const SIM_CAMERA: Topic<StereoFrame640x480> = Topic::frames("sim/camera/640x480");
/// Exact disparity of the simulated left image (same frame ids as `sim/camera/640x480`).
pub const SIM_GT_DISPARITY: Topic<DisparityMap640x480> = Topic::frames("sim/gt_disparity/640x480");
/// Simulator ground truth: pose, collisions, pulses.
pub const SIM_TRUTH: Topic<SimTruth> = Topic::new("sim/truth");
/// Fast-path pairs, 320x240.
pub const FRAMES_LO: Topic<StereoFrame320x240> = Topic::frames("frames/320x240");
/// Long-range pairs, 640x480.
pub const FRAMES_HI: Topic<StereoFrame640x480> = Topic::frames("frames/640x480");
/// Disparity maps of the fast path.
pub const DISPARITY_LO: Topic<DisparityMap320x240> = Topic::frames("disparity/320x240");
/// Disparity maps of the long-range path.
pub const DISPARITY_HI: Topic<DisparityMap640x480> = Topic::frames("disparity/640x480");
/// Ranges per window, one report per fast-path frame.
pub const RANGES: Topic<RangeReport> = Topic::new("ranges");
/// Navigation decisions, one per range report.
pub const DECISIONS: Topic<Decision> = Topic::new("decisions");
/// The navigator's dead-reckoned pose, one per decision.
pub const DECISION_POSE: Topic<RobotPose> = Topic::new("decision/pose");
/// The navigator's map around the robot, a few times a second.
pub const NAV_MAP: Topic<NavMap> = Topic::new("decision/map");
/// What the actuator wrote to the serial port.
pub const ACTUATOR_SENT: Topic<ActuatorReport> = Topic::new("actuator/sent");
/// The bridge's traffic per topic, once a second.
pub const BRIDGE_STATS: Topic<BridgeStats> = Topic::new("bridge/stats");
/// Per-stage heartbeats: use [`Topic::stage_service_name`] with the stage name.
pub const HEARTBEAT: Topic<StageHeartbeat> = Topic::new("heartbeat");
/// The stages' log lines, as the supervisor forwards them (bursts: a deeper queue).
pub const LOG: Topic<LogLine> = Topic::new("log").with_buffer(32);
/// The supervisor's status table.
pub const SUPERVISOR_STATUS: Topic<SupervisorStatus> = Topic::new("supervisor/status");
/// Requests to the supervisor (several `hvs restart` may run at once).
pub const SUPERVISOR_CONTROL: Topic<ControlRequest> =
    Topic::new("supervisor/control").with_publishers(4);

/// The stages of the pipeline, in start order. Each is one process under the supervisor;
/// [`Stage::name`] is its name in configs, service names (`heartbeat/<name>`), logs and
/// `hvs restart <name>`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Stage {
    /// The simulated world (camera, robot, servo controller on a pty).
    Sim,
    /// Frames from the cameras, the simulator, files or a recording.
    Capture,
    /// The 320x240 stereo matcher (every frame).
    StereoLo,
    /// The 640x480 stereo worker (as fast as it can).
    StereoHi,
    /// Edges, disparity and ranges.
    Fusion,
    /// The navigator.
    Decision,
    /// The servo controller link.
    Actuator,
    /// The live view: a Foxglove WebSocket server and a web page for an operator.
    View,
    /// The zenoh bridge to other machines and ROS 2 (on when an endpoint is configured).
    Bridge,
}

impl Stage {
    /// Every stage, in start order.
    pub const ALL: [Stage; 9] = [
        Stage::Sim,
        Stage::Capture,
        Stage::StereoLo,
        Stage::StereoHi,
        Stage::Fusion,
        Stage::Decision,
        Stage::Actuator,
        Stage::View,
        Stage::Bridge,
    ];

    /// The stage's name (`stereo-lo`, ...).
    pub const fn name(self) -> &'static str {
        match self {
            Stage::Sim => "sim",
            Stage::Capture => "capture",
            Stage::StereoLo => "stereo-lo",
            Stage::StereoHi => "stereo-hi",
            Stage::Fusion => "fusion",
            Stage::Decision => "decision",
            Stage::Actuator => "actuator",
            Stage::View => "view",
            Stage::Bridge => "bridge",
        }
    }

    /// The stage of a name, if it is one.
    pub fn from_name(name: &str) -> Option<Stage> {
        Stage::ALL.into_iter().find(|s| s.name() == name)
    }

    /// The binary that runs the stage by default.
    pub const fn default_program(self) -> &'static str {
        match self {
            Stage::Sim => "hvs-sim",
            Stage::Capture => "hvs-capture",
            Stage::StereoLo | Stage::StereoHi => "hvs-stereo",
            Stage::Fusion => "hvs-fusion",
            Stage::Decision => "hvs-decision",
            Stage::Actuator => "hvs-actuator",
            Stage::View => "hvs-view",
            Stage::Bridge => "hvs-bridge",
        }
    }
}

/// The names of the stages the supervisor knows, in start order ([`Stage::ALL`]'s names).
pub const STAGE_NAMES: [&str; 9] = {
    let mut names = [""; 9];
    let mut i = 0;
    while i < 9 {
        names[i] = Stage::ALL[i].name();
        i += 1;
    }
    names
};

impl core::fmt::Display for Stage {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// One input of a stage: the topic it waits on and the stage that publishes it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StageInput {
    /// The reading stage.
    pub stage: Stage,
    /// The topic path it reads.
    pub topic: &'static str,
    /// The stage that publishes it.
    pub publisher: Stage,
}

/// The inputs each stage cannot work without (the table above, read as a graph): the
/// pre-start check (`hvs_runtime::config::HvsConfig::validate`) refuses a
/// config in which an enabled stage waits on a topic that no enabled stage publishes.
/// Capture reads `sim/camera/640x480` only with `capture.source = "sim"`, and publishes
/// `frames/640x480` only at a 640x480 capture size; fusion also takes the 640x480 results
/// when they come, but drives without them.
pub const STAGE_INPUTS: [StageInput; 6] = [
    StageInput {
        stage: Stage::Capture,
        topic: SIM_CAMERA.path,
        publisher: Stage::Sim,
    },
    StageInput {
        stage: Stage::StereoLo,
        topic: FRAMES_LO.path,
        publisher: Stage::Capture,
    },
    StageInput {
        stage: Stage::StereoHi,
        topic: FRAMES_HI.path,
        publisher: Stage::Capture,
    },
    StageInput {
        stage: Stage::Fusion,
        topic: DISPARITY_LO.path,
        publisher: Stage::StereoLo,
    },
    StageInput {
        stage: Stage::Decision,
        topic: RANGES.path,
        publisher: Stage::Fusion,
    },
    StageInput {
        stage: Stage::Actuator,
        topic: DECISIONS.path,
        publisher: Stage::Decision,
    },
];

/// The stage that publishes each pipeline topic (the table above's publisher column, for the
/// topics one stage owns): the pre-start check refuses a bridge that would take one of them
/// from the network while the local stage publishes it too.
pub const STAGE_PUBLISHERS: [(&str, Stage); 11] = [
    (SIM_CAMERA.path, Stage::Sim),
    (SIM_TRUTH.path, Stage::Sim),
    (FRAMES_LO.path, Stage::Capture),
    (FRAMES_HI.path, Stage::Capture),
    (DISPARITY_LO.path, Stage::StereoLo),
    (DISPARITY_HI.path, Stage::StereoHi),
    (RANGES.path, Stage::Fusion),
    (DECISIONS.path, Stage::Decision),
    (ACTUATOR_SENT.path, Stage::Actuator),
    (DECISION_POSE.path, Stage::Decision),
    (NAV_MAP.path, Stage::Decision),
];

/// Every fixed topic path with its iceoryx2 payload type name, for discovery by probes.
pub const ALL_TOPIC_PATHS: [(&str, &str); 15] = [
    (SIM_CAMERA.path, "hvs::StereoFrame640x480"),
    (SIM_GT_DISPARITY.path, "hvs::DisparityMap640x480"),
    (SIM_TRUTH.path, "hvs::SimTruth"),
    (FRAMES_LO.path, "hvs::StereoFrame320x240"),
    (FRAMES_HI.path, "hvs::StereoFrame640x480"),
    (DISPARITY_LO.path, "hvs::DisparityMap320x240"),
    (DISPARITY_HI.path, "hvs::DisparityMap640x480"),
    (RANGES.path, "hvs::RangeReport"),
    (DECISIONS.path, "hvs::Decision"),
    (ACTUATOR_SENT.path, "hvs::ActuatorReport"),
    (DECISION_POSE.path, "hvs::RobotPose"),
    (NAV_MAP.path, "hvs::NavMap"),
    (LOG.path, "hvs::LogLine"),
    (SUPERVISOR_STATUS.path, "hvs::SupervisorStatus"),
    (SUPERVISOR_CONTROL.path, "hvs::ControlRequest"),
];

/// A topic picked by its path (as typed on a command line), with its payload type: tools
/// that take a topic name (`hvs probe`) dispatch on this to get a typed [`Topic`].
#[derive(Debug, Clone, Copy)]
pub enum TopicByPath {
    /// `sim/camera/640x480` or `frames/640x480`.
    StereoFrame640x480(&'static Topic<StereoFrame640x480>),
    /// `frames/320x240`.
    StereoFrame320x240(&'static Topic<StereoFrame320x240>),
    /// `sim/gt_disparity/640x480` or `disparity/640x480`.
    DisparityMap640x480(&'static Topic<DisparityMap640x480>),
    /// `disparity/320x240`.
    DisparityMap320x240(&'static Topic<DisparityMap320x240>),
    /// `sim/truth`.
    SimTruth(&'static Topic<SimTruth>),
    /// `ranges`.
    RangeReport(&'static Topic<RangeReport>),
    /// `decisions`.
    Decision(&'static Topic<Decision>),
    /// `actuator/sent`.
    ActuatorReport(&'static Topic<ActuatorReport>),
    /// `decision/pose`.
    RobotPose(&'static Topic<RobotPose>),
    /// `decision/map`.
    NavMap(&'static Topic<NavMap>),
    /// `log`.
    LogLine(&'static Topic<LogLine>),
    /// `heartbeat/<stage>`: the topic and the stage.
    StageHeartbeat(&'static Topic<StageHeartbeat>, &'static str),
    /// `supervisor/status`.
    SupervisorStatus(&'static Topic<SupervisorStatus>),
    /// `supervisor/control`.
    ControlRequest(&'static Topic<ControlRequest>),
}

/// Looks a topic up by its path below `hvs/<instance>/` (one of [`ALL_TOPIC_PATHS`], or
/// `heartbeat/<stage>` for a stage of [`STAGE_NAMES`]).
pub fn topic_by_path(path: &str) -> Option<TopicByPath> {
    use TopicByPath as T;
    Some(match path {
        p if p == SIM_CAMERA.path => T::StereoFrame640x480(&SIM_CAMERA),
        p if p == SIM_GT_DISPARITY.path => T::DisparityMap640x480(&SIM_GT_DISPARITY),
        p if p == SIM_TRUTH.path => T::SimTruth(&SIM_TRUTH),
        p if p == FRAMES_LO.path => T::StereoFrame320x240(&FRAMES_LO),
        p if p == FRAMES_HI.path => T::StereoFrame640x480(&FRAMES_HI),
        p if p == DISPARITY_LO.path => T::DisparityMap320x240(&DISPARITY_LO),
        p if p == DISPARITY_HI.path => T::DisparityMap640x480(&DISPARITY_HI),
        p if p == RANGES.path => T::RangeReport(&RANGES),
        p if p == DECISIONS.path => T::Decision(&DECISIONS),
        p if p == ACTUATOR_SENT.path => T::ActuatorReport(&ACTUATOR_SENT),
        p if p == DECISION_POSE.path => T::RobotPose(&DECISION_POSE),
        p if p == NAV_MAP.path => T::NavMap(&NAV_MAP),
        p if p == LOG.path => T::LogLine(&LOG),
        p if p == SUPERVISOR_STATUS.path => T::SupervisorStatus(&SUPERVISOR_STATUS),
        p if p == SUPERVISOR_CONTROL.path => T::ControlRequest(&SUPERVISOR_CONTROL),
        p => {
            let stage = p.strip_prefix(HEARTBEAT.path)?.strip_prefix('/')?;
            let stage = STAGE_NAMES.into_iter().find(|s| *s == stage)?;
            T::StageHeartbeat(&HEARTBEAT, stage)
        }
    })
}

/// Every topic path of a pipeline: [`ALL_TOPIC_PATHS`], then `heartbeat/<stage>` for every
/// stage, in that order (what `hvs probe list` shows and what [`topic_by_path`] accepts).
pub fn known_topic_paths() -> Vec<String> {
    ALL_TOPIC_PATHS
        .iter()
        .map(|(p, _)| (*p).to_string())
        .chain(
            STAGE_NAMES
                .iter()
                .map(|s| format!("{}/{s}", HEARTBEAT.path)),
        )
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn service_names_are_under_the_instance_prefix() {
        assert_eq!(
            FRAMES_LO.service_name("default"),
            "hvs/default/frames/320x240"
        );
        assert_eq!(
            HEARTBEAT.stage_service_name("t1", "stereo-lo"),
            "hvs/t1/heartbeat/stereo-lo"
        );
    }

    #[test]
    fn topic_paths_are_unique() {
        let mut paths: Vec<_> = ALL_TOPIC_PATHS.iter().map(|(p, _)| *p).collect();
        paths.sort_unstable();
        paths.dedup();
        assert_eq!(paths.len(), ALL_TOPIC_PATHS.len());
    }

    #[test]
    fn every_known_path_resolves_and_unknown_ones_do_not() {
        for path in known_topic_paths() {
            assert!(topic_by_path(&path).is_some(), "{path}");
        }
        assert!(matches!(
            topic_by_path("heartbeat/fusion"),
            Some(TopicByPath::StageHeartbeat(_, "fusion"))
        ));
        assert!(matches!(
            topic_by_path("frames/320x240"),
            Some(TopicByPath::StereoFrame320x240(t)) if t.path == "frames/320x240"
        ));
        for bad in [
            "",
            "heartbeat",
            "heartbeat/",
            "heartbeat/nope",
            "frames",
            "rangesx",
        ] {
            assert!(topic_by_path(bad).is_none(), "{bad:?}");
        }
    }
}
