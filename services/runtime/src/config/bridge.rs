//! `[bridge]`: the zenoh bridge stage (hvs topics between machines) and its ROS 2 side.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use hvs_shared::topics;

use super::Invalid;

/// The hvs topics that may cross the bridge: the allow-list. Anything else stays on the
/// machine (heartbeats, the supervisor's status and control, the simulator's ground truth).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Deserialize, Serialize)]
pub enum BridgeTopic {
    /// `frames/320x240` (153 672 B a pair).
    #[serde(rename = "frames/320x240")]
    FramesLo,
    /// `frames/640x480` (614 472 B a pair): what a remote 640x480 worker matches.
    #[serde(rename = "frames/640x480")]
    FramesHi,
    /// `disparity/320x240`.
    #[serde(rename = "disparity/320x240")]
    DisparityLo,
    /// `disparity/640x480`: what a remote 640x480 worker sends back.
    #[serde(rename = "disparity/640x480")]
    DisparityHi,
    /// `ranges`.
    #[serde(rename = "ranges")]
    Ranges,
    /// `decisions`: motion commands. Accepted from the network only with
    /// `accept_commands = true`.
    #[serde(rename = "decisions")]
    Decisions,
    /// `actuator/sent`.
    #[serde(rename = "actuator/sent")]
    ActuatorSent,
    /// `decision/pose`.
    #[serde(rename = "decision/pose")]
    Pose,
}

impl BridgeTopic {
    /// Every topic of the allow-list.
    pub const ALL: [BridgeTopic; 8] = [
        BridgeTopic::FramesLo,
        BridgeTopic::FramesHi,
        BridgeTopic::DisparityLo,
        BridgeTopic::DisparityHi,
        BridgeTopic::Ranges,
        BridgeTopic::Decisions,
        BridgeTopic::ActuatorSent,
        BridgeTopic::Pose,
    ];

    /// The topic's path below `hvs/<instance>/` (and below `key_prefix` on zenoh).
    pub const fn path(self) -> &'static str {
        match self {
            BridgeTopic::FramesLo => topics::FRAMES_LO.path,
            BridgeTopic::FramesHi => topics::FRAMES_HI.path,
            BridgeTopic::DisparityLo => topics::DISPARITY_LO.path,
            BridgeTopic::DisparityHi => topics::DISPARITY_HI.path,
            BridgeTopic::Ranges => topics::RANGES.path,
            BridgeTopic::Decisions => topics::DECISIONS.path,
            BridgeTopic::ActuatorSent => topics::ACTUATOR_SENT.path,
            BridgeTopic::Pose => topics::DECISION_POSE.path,
        }
    }

    /// Whether the payload is an image or a map (compressed when `compression` says so).
    pub const fn is_bulk(self) -> bool {
        matches!(
            self,
            BridgeTopic::FramesLo
                | BridgeTopic::FramesHi
                | BridgeTopic::DisparityLo
                | BridgeTopic::DisparityHi
        )
    }

    /// Whether receiving it from the network would command the robot.
    pub const fn is_command(self) -> bool {
        matches!(self, BridgeTopic::Decisions)
    }
}

impl core::fmt::Display for BridgeTopic {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.path())
    }
}

/// How the bridge's zenoh session joins the others.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum BridgeMode {
    /// Talks directly to the peers it listens for or connects to.
    Peer,
    /// Goes through the zenoh router(s) in `connect` (what a ROS 2 machine runs: `rmw_zenohd`).
    Client,
}

/// Compression of images and maps on the wire (small messages are never compressed).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum BridgeCompression {
    /// Raw payloads.
    None,
    /// LZ4 block compression of each payload (lossless: the matcher sees the same pixels).
    Lz4,
}

/// ROS 2 publications in rmw_zenoh's wire format (no ROS installation needed here).
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct BridgeRosConfig {
    /// Publish the ROS 2 topics.
    pub enabled: bool,
    /// `ROS_DOMAIN_ID` of the ROS 2 graph, 0..=232.
    pub domain_id: u32,
    /// Namespace of the topics and the node (`/hvs`: topics `/hvs/left/image_raw`, ...).
    pub namespace: String,
    /// The node name other ROS 2 tools list.
    pub node: String,
    /// Most images (each size), disparity images and camera infos per second.
    pub image_hz: f64,
}

impl Default for BridgeRosConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            domain_id: 0,
            namespace: "/hvs".into(),
            node: "hvs_bridge".into(),
            image_hz: 15.0,
        }
    }
}

/// The bridge between this machine's iceoryx2 topics and zenoh.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct BridgeConfig {
    /// `peer` or `client`.
    pub mode: BridgeMode,
    /// Endpoints to listen on (`tcp/127.0.0.1:7447`; port 0 picks a free one, shown in the
    /// stage's note).
    pub listen: Vec<String>,
    /// Endpoints to connect to (`tcp/192.168.1.20:7447`); retried while they are down.
    pub connect: Vec<String>,
    /// Key prefix of hvs topics on zenoh: `<key_prefix>/<topic>`, e.g. `hvs/frames/640x480`.
    pub key_prefix: String,
    /// Local topics sent to zenoh.
    pub publish: Vec<BridgeTopic>,
    /// Topics taken from zenoh into the local shared memory.
    pub subscribe: Vec<BridgeTopic>,
    /// Compression of images and maps.
    pub compression: BridgeCompression,
    /// Samples held per topic between zenoh's threads and the stage (the oldest is dropped
    /// and counted when full), 1..=64.
    pub queue: usize,
    /// Most messages per second sent per topic (topics not listed: every sample).
    pub rate_hz: BTreeMap<BridgeTopic, f64>,
    /// Accept motion commands (`decisions`) from the network.
    pub accept_commands: bool,
    /// ROS 2 publications.
    pub ros: BridgeRosConfig,
}

impl Default for BridgeConfig {
    fn default() -> Self {
        Self {
            mode: BridgeMode::Peer,
            listen: Vec::new(),
            connect: Vec::new(),
            key_prefix: "hvs".into(),
            publish: vec![
                BridgeTopic::Ranges,
                BridgeTopic::Decisions,
                BridgeTopic::ActuatorSent,
                BridgeTopic::Pose,
            ],
            subscribe: Vec::new(),
            compression: BridgeCompression::Lz4,
            queue: 4,
            rate_hz: BTreeMap::new(),
            accept_commands: false,
            ros: BridgeRosConfig::default(),
        }
    }
}

impl BridgeConfig {
    /// Whether an endpoint is given (the bridge stage then starts by default).
    pub fn has_endpoints(&self) -> bool {
        !self.listen.is_empty() || !self.connect.is_empty()
    }

    /// Checks the section's values; the key of an error is below the section.
    pub fn validate(&self) -> Result<(), Invalid> {
        for (key, list, need_ip) in [
            ("listen", &self.listen, true),
            ("connect", &self.connect, false),
        ] {
            for (i, e) in list.iter().enumerate() {
                check_endpoint(e, need_ip)
                    .map_err(|m| Invalid::new(key, format!("[{i}] = {e:?} {m}")))?;
            }
        }
        if self.mode == BridgeMode::Client && self.connect.is_empty() && !self.listen.is_empty() {
            return Err(Invalid::new(
                "mode",
                "= \"client\" needs a router in `connect` (a client does not listen)",
            ));
        }
        if self.key_prefix.is_empty()
            || self.key_prefix.starts_with('/')
            || self.key_prefix.ends_with('/')
            || self.key_prefix.contains("//")
            || self.key_prefix.chars().any(|c| "*$?#@ ".contains(c))
        {
            return Err(Invalid::new(
                "key_prefix",
                format!(
                    "= {:?} is not a zenoh key prefix such as \"hvs\" or \"site/robot1\" (no leading or trailing '/', no wildcards)",
                    self.key_prefix
                ),
            ));
        }
        for t in &self.subscribe {
            if self.publish.contains(t) {
                return Err(Invalid::new(
                    "subscribe",
                    format!("lists {t}, which `publish` sends too: a topic crosses one way"),
                ));
            }
            if t.is_command() && !self.accept_commands {
                return Err(Invalid::new(
                    "subscribe",
                    format!(
                        "lists {t}: motion commands from the network are refused unless `accept_commands = true`"
                    ),
                ));
            }
        }
        for (key, list) in [("publish", &self.publish), ("subscribe", &self.subscribe)] {
            let mut seen = list.clone();
            seen.sort();
            seen.dedup();
            if seen.len() != list.len() {
                return Err(Invalid::new(key, "lists a topic twice"));
            }
        }
        if !(1..=64).contains(&self.queue) {
            return Err(Invalid::new(
                "queue",
                format!("= {} must be in 1..=64", self.queue),
            ));
        }
        for (t, hz) in &self.rate_hz {
            if !(*hz > 0.0 && *hz <= 1000.0) {
                return Err(Invalid::new(
                    format!("rate_hz.\"{t}\""),
                    format!("= {hz} must be in (0, 1000] Hz"),
                ));
            }
        }
        self.ros
            .validate()
            .map_err(|e| Invalid::new(format!("ros.{}", e.key), e.message))
    }
}

impl BridgeRosConfig {
    /// Checks the ROS 2 values.
    pub fn validate(&self) -> Result<(), Invalid> {
        if self.domain_id > 232 {
            return Err(Invalid::new(
                "domain_id",
                format!("= {} must be in 0..=232 (ROS_DOMAIN_ID)", self.domain_id),
            ));
        }
        let ns_ok = self.namespace == "/"
            || (self.namespace.starts_with('/')
                && !self.namespace.ends_with('/')
                && self.namespace[1..].split('/').all(is_ros_token));
        if !ns_ok {
            return Err(Invalid::new(
                "namespace",
                format!(
                    "= {:?} is not a ROS 2 namespace such as \"/hvs\" (absolute, letters, digits and '_')",
                    self.namespace
                ),
            ));
        }
        if !is_ros_token(&self.node) {
            return Err(Invalid::new(
                "node",
                format!(
                    "= {:?} is not a ROS 2 node name (a letter, then letters, digits and '_')",
                    self.node
                ),
            ));
        }
        if !(self.image_hz > 0.0 && self.image_hz <= 100.0) {
            return Err(Invalid::new(
                "image_hz",
                format!("= {} must be in (0, 100] Hz", self.image_hz),
            ));
        }
        Ok(())
    }
}

/// A ROS 2 name token: a letter or '_' first, then letters, digits and '_'.
fn is_ros_token(s: &str) -> bool {
    let mut chars = s.chars();
    chars
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// Checks a zenoh endpoint `tcp/HOST:PORT` (the only transport this build has). A listen
/// endpoint needs an IP address; a connect endpoint may name a host.
fn check_endpoint(e: &str, need_ip: bool) -> Result<(), String> {
    let Some(addr) = e.strip_prefix("tcp/") else {
        return Err("is not a TCP endpoint such as \"tcp/127.0.0.1:7447\"".into());
    };
    if need_ip {
        addr.parse::<std::net::SocketAddr>()
            .map_err(|err| format!("is not tcp/IP:PORT ({err})"))?;
        return Ok(());
    }
    let Some((host, port)) = addr.rsplit_once(':') else {
        return Err("has no port (tcp/HOST:PORT)".into());
    };
    if host.is_empty() || port.parse::<u16>().is_err() {
        return Err("is not tcp/HOST:PORT".into());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_off() {
        let b = BridgeConfig::default();
        assert!(b.validate().is_ok());
        assert!(!b.has_endpoints());
        assert!(!b.ros.enabled);
        assert!(!b.accept_commands);
        assert!(!b.subscribe.contains(&BridgeTopic::Decisions));
    }

    #[test]
    fn topic_names_are_the_contract_paths() {
        #[derive(Deserialize)]
        struct One {
            t: BridgeTopic,
        }
        for t in BridgeTopic::ALL {
            let parsed: One =
                toml::from_str(&format!("t = \"{}\"", t.path())).expect("every path parses");
            assert_eq!(parsed.t, t);
        }
    }

    #[test]
    fn bad_values_name_their_key() {
        let cases: Vec<(BridgeConfig, &str)> = vec![
            (
                BridgeConfig {
                    listen: vec!["udp/127.0.0.1:7447".into()],
                    ..Default::default()
                },
                "listen",
            ),
            (
                BridgeConfig {
                    listen: vec!["tcp/localhost:7447".into()],
                    ..Default::default()
                },
                "listen",
            ),
            (
                BridgeConfig {
                    connect: vec!["tcp/robot".into()],
                    ..Default::default()
                },
                "connect",
            ),
            (
                BridgeConfig {
                    subscribe: vec![BridgeTopic::Decisions],
                    publish: vec![],
                    ..Default::default()
                },
                "subscribe",
            ),
            (
                BridgeConfig {
                    subscribe: vec![BridgeTopic::Ranges],
                    ..Default::default()
                },
                "subscribe",
            ),
            (
                BridgeConfig {
                    key_prefix: "hvs/*".into(),
                    ..Default::default()
                },
                "key_prefix",
            ),
            (
                BridgeConfig {
                    queue: 0,
                    ..Default::default()
                },
                "queue",
            ),
            (
                BridgeConfig {
                    ros: BridgeRosConfig {
                        domain_id: 300,
                        ..Default::default()
                    },
                    ..Default::default()
                },
                "ros.domain_id",
            ),
            (
                BridgeConfig {
                    ros: BridgeRosConfig {
                        namespace: "hvs".into(),
                        ..Default::default()
                    },
                    ..Default::default()
                },
                "ros.namespace",
            ),
        ];
        for (c, key) in cases {
            let e = c.validate().expect_err(key);
            assert_eq!(e.key, key, "{e:?}");
        }
        let ok = BridgeConfig {
            connect: vec!["tcp/worker.local:7447".into()],
            subscribe: vec![BridgeTopic::Decisions],
            publish: vec![],
            accept_commands: true,
            ..Default::default()
        };
        assert!(ok.validate().is_ok());
    }
}
