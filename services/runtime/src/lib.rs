//! The runtime every hvs process shares, on top of the contract (`hvs-shared`):
//!
//! - [`config`]: the TOML configuration every process loads; each section validates itself.
//! - [`ipc`]: how a process opens topics, publishes in place and receives, on iceoryx2.
//! - [`stage`]: the common skeleton of a stage process (arguments, logging, heartbeat, loop).
//! - [`clock`], [`stats`]: time stamps and latency percentiles.

pub mod clock;
pub mod config;
pub mod ipc;
pub mod pacing;
pub mod stage;
pub mod stats;

/// Formats an error with its chain of causes (`outer: cause: root`), skipping a cause whose text
/// the message already contains (many errors quote their cause in their own message).
pub fn error_chain(error: &(dyn std::error::Error + 'static)) -> String {
    let mut message = error.to_string();
    let mut source = error.source();
    while let Some(cause) = source {
        let text = cause.to_string();
        if !message.contains(&text) {
            message.push_str(": ");
            message.push_str(&text);
        }
        source = cause.source();
    }
    message
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    #[error("cannot read map {path}: {source}")]
    struct Quoting {
        path: String,
        source: std::io::Error,
    }

    #[derive(Debug, thiserror::Error)]
    #[error("starting the sim")]
    struct Outer(#[source] Quoting);

    #[test]
    fn error_chain_skips_causes_already_quoted() {
        let e = Outer(Quoting {
            path: "m.txt".into(),
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "no such file"),
        });
        assert_eq!(
            error_chain(&e),
            "starting the sim: cannot read map m.txt: no such file"
        );
    }
}
