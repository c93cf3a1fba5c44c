//! `hvs probe echo TOPIC`: every sample of one topic as a text or JSON line.

use std::io::Write;
use std::time::Duration;

use hvs_runtime::ipc::ReceiveError;
use hvs_shared::topics::{Topic, TopicByPath};

use super::{AttachError, Payload, Probe, resolve_topic};
use crate::format::Describe;

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
