//! The zenoh session of the bridge: built from `[bridge]`, with multicast scouting off (every
//! peer is an explicit endpoint) and connections retried in the background, so the robot
//! and a worker can start in any order and a lost link comes back by itself.

use hvs_runtime::config::{BridgeConfig, BridgeMode};

/// Why the session could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// A setting was refused by zenoh.
    #[error("zenoh config {key} = {value}: {message}")]
    Config {
        /// The zenoh config key.
        key: &'static str,
        /// The value given.
        value: String,
        /// zenoh's message.
        message: String,
    },
    /// zenoh could not open the session (a listen endpoint taken or not local, ...).
    #[error("cannot open the zenoh session (listen {listen:?}, connect {connect:?}): {message}")]
    Open {
        /// The listen endpoints.
        listen: Vec<String>,
        /// The connect endpoints.
        connect: Vec<String>,
        /// zenoh's message.
        message: String,
    },
}

fn json_list(items: &[String]) -> String {
    serde_json::to_string(items).unwrap_or_else(|_| "[]".into())
}

/// The zenoh config of the bridge.
pub fn zenoh_config(cfg: &BridgeConfig) -> Result<zenoh::Config, SessionError> {
    let mode = match cfg.mode {
        BridgeMode::Peer => "\"peer\"",
        BridgeMode::Client => "\"client\"",
    };
    let settings: [(&'static str, String); 8] = [
        ("mode", mode.into()),
        ("scouting/multicast/enabled", "false".into()),
        // Gossip tells peers about each other's listen endpoints; with explicit endpoints on
        // both sides it adds nothing, and it must not make a peer dial an address it was
        // not configured for.
        ("scouting/gossip/enabled", "false".into()),
        ("listen/endpoints", json_list(&cfg.listen)),
        ("connect/endpoints", json_list(&cfg.connect)),
        // Keep trying a peer that is down (it may start later, or come back).
        ("connect/timeout_ms", "-1".into()),
        ("connect/exit_on_failure", "false".into()),
        // hvs stamps its own samples; no need for zenoh's timestamping.
        ("timestamping/enabled", "false".into()),
    ];
    let mut config = zenoh::Config::default();
    for (key, value) in settings {
        config
            .insert_json5(key, &value)
            .map_err(|e| SessionError::Config {
                key,
                value: value.clone(),
                message: e.to_string(),
            })?;
    }
    Ok(config)
}

/// Opens the session.
pub fn open(cfg: &BridgeConfig) -> Result<zenoh::Session, SessionError> {
    use zenoh::Wait;
    let config = zenoh_config(cfg)?;
    zenoh::open(config).wait().map_err(|e| SessionError::Open {
        listen: cfg.listen.clone(),
        connect: cfg.connect.clone(),
        message: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn multicast_scouting_is_off_and_endpoints_are_explicit() {
        let cfg = BridgeConfig {
            listen: vec!["tcp/127.0.0.1:17447".into()],
            connect: vec!["tcp/127.0.0.1:17448".into()],
            ..Default::default()
        };
        let c = zenoh_config(&cfg).expect("config");
        let get = |k: &str| c.get_json(k).expect(k);
        assert_eq!(get("scouting/multicast/enabled"), "false");
        assert_eq!(get("scouting/gossip/enabled"), "false");
        assert!(get("listen/endpoints").contains("tcp/127.0.0.1:17447"));
        assert!(get("connect/endpoints").contains("tcp/127.0.0.1:17448"));
    }
}
