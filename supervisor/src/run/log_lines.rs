//! The `log` topic: every line a stage writes to its standard error (its `tracing` output),
//! forwarded by the supervisor's reader threads, published by the main loop as
//! [`LogLine`]s for the live view and probes. Never blocking: a line that finds the queue
//! full is dropped (the terminal still shows it).

use crossbeam_channel::{Receiver, Sender};
use hvs_runtime::clock::monotonic_ns;
use hvs_runtime::ipc::TopicPublisher;
use hvs_shared::messages::{LOG_TEXT_LEN, LogLevel, LogLine, NAME_LEN, encode_name};

/// Lines waiting for the main loop at most.
const QUEUE: usize = 1024;

/// A line read from a stage.
#[derive(Debug, Clone)]
pub struct StageLine {
    /// The stage.
    pub stage: String,
    /// The line, without its newline.
    pub text: String,
    /// When it was read, CLOCK_MONOTONIC ns.
    pub time_ns: u64,
}

/// Where the reader threads put lines.
#[derive(Debug, Clone)]
pub struct LineSender {
    tx: Sender<StageLine>,
}

impl LineSender {
    /// Queues a line; a full queue drops it.
    pub fn send(&self, stage: &str, text: &str) {
        let line = StageLine {
            stage: stage.to_string(),
            text: text.to_string(),
            time_ns: monotonic_ns(),
        };
        // Full: the main loop is behind, and the line is on the terminal anyway.
        let _ = self.tx.try_send(line);
    }
}

/// The main loop's side: publishes queued lines.
pub struct LogForwarder {
    rx: Receiver<StageLine>,
    publisher: TopicPublisher<LogLine>,
    seq: u64,
}

impl LogForwarder {
    /// A forwarder publishing on `publisher`, and the sender for the reader threads.
    pub fn new(publisher: TopicPublisher<LogLine>) -> (Self, LineSender) {
        let (tx, rx) = crossbeam_channel::bounded(QUEUE);
        (
            Self {
                rx,
                publisher,
                seq: 0,
            },
            LineSender { tx },
        )
    }

    /// Publishes every queued line.
    pub fn drain(&mut self) {
        while let Ok(line) = self.rx.try_recv() {
            self.seq += 1;
            let msg = log_line(self.seq, &line);
            if let Err(e) = self.publisher.publish_copy(&msg) {
                tracing::debug!("log line not published: {e}");
            }
        }
    }
}

/// The level a `tracing` line names in its first words (`2026-... WARN stage{...}: ...`).
pub fn level_of(text: &str) -> Option<LogLevel> {
    text.split_whitespace()
        .take(3)
        .find_map(LogLevel::from_label)
}

/// The message of a line.
pub fn log_line(seq: u64, line: &StageLine) -> LogLine {
    let stage: [u8; NAME_LEN] = encode_name(&line.stage);
    let text: [u8; LOG_TEXT_LEN] = encode_name(&line.text);
    LogLine {
        seq,
        time_ns: line.time_ns,
        level: level_of(&line.text).map_or(0, LogLevel::code),
        reserved: 0,
        stage,
        text,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hvs_shared::messages::decode_name;

    #[test]
    fn levels_come_from_the_tracing_prefix() {
        let warn = "2026-12-03T07:42:30.123456Z  WARN stage{name=\"view\"}: port in use";
        assert_eq!(level_of(warn), Some(LogLevel::Warn));
        assert_eq!(
            level_of("2026-12-03T07:42:30Z ERROR x"),
            Some(LogLevel::Error)
        );
        assert_eq!(level_of("a line with no level, INFO later on"), None);
        let long = format!("2026 INFO {}", "é".repeat(300));
        let m = log_line(
            7,
            &StageLine {
                stage: "fusion".into(),
                text: long,
                time_ns: 5,
            },
        );
        assert_eq!(m.level, LogLevel::Info.code());
        assert_eq!(decode_name(&m.stage), "fusion");
        assert!(decode_name(&m.text).len() <= LOG_TEXT_LEN && decode_name(&m.text).ends_with('é'));
    }
}
