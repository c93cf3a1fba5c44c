//! The serial link to the servo controller, through `serialport`: the same code opens the
//! robot's `/dev/ttyUSB0` and the simulator's pseudo-terminal.
//!
//! The link is a state machine that never blocks the stage ([`PscLink::poll`] reads only
//! the bytes already received and returns at once):
//!
//! ```text
//!   absent --device opens--> probing --valid version reply--> up --write fails or node removed--> lost
//!     ^                        |  (re-asks `!SCVER?` every 500 ms,                                  |
//!     |                        |   names silence, echo or garbage)                                  |
//!     +------device missing / open fails-------------------------------------------------------------+
//! ```
//!
//! A robot's laptop usually boots before the motor battery is switched on, so a silent,
//! absent or unplugged controller is a state the stage reports and waits in, not an error
//! that ends it. Nothing but version queries goes out before a valid reply.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serialport::{DataBits, FlowControl, Parity, SerialPort, StopBits, TTYPort};

use crate::psc::VERSION_QUERY;

/// How long one version query waits for its reply before it is asked again.
pub const QUERY_WINDOW: Duration = Duration::from_millis(500);
/// Extra wait when the window ends inside a reply (its first bytes look like a version).
const QUERY_GRACE: Duration = Duration::from_millis(60);
/// Reopen delays while the device is missing or cannot be opened: short enough that a
/// controller plugged in is picked up within a second.
const REOPEN_MIN: Duration = Duration::from_millis(100);
const REOPEN_MAX: Duration = Duration::from_millis(800);
/// While up, the device node is checked this often (a USB adapter pulled out).
const NODE_CHECK: Duration = Duration::from_millis(250);

/// Why the link is not up, or why it failed. Every message names the device.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LinkError {
    /// The device does not exist.
    #[error("serial device {device} does not exist (adapter unplugged, or wrong actuator.device?)")]
    Missing {
        /// The device.
        device: PathBuf,
    },
    /// The device exists but cannot be opened (permissions, in use by another process).
    #[error("cannot open serial device {device}: {detail}")]
    Open {
        /// The device.
        device: PathBuf,
        /// The OS's reason.
        detail: String,
    },
    /// Nothing came back to the version query.
    #[error(
        "no servo controller answers on {device}: no reply to !SCVER? within {timeout_ms} ms \
         (check the controller's power, the wiring and baud rate {baud})"
    )]
    Silent {
        /// The device.
        device: PathBuf,
        /// Wait time.
        timeout_ms: u64,
        /// Baud rate tried.
        baud: u32,
    },
    /// Only the query itself came back: a loopback or single-wire line with no controller.
    #[error(
        "only an echo on {device}: the line returns !SCVER? but no servo controller answers \
         behind it (loopback adapter, or the controller is off)"
    )]
    Echo {
        /// The device.
        device: PathBuf,
    },
    /// Bytes came back that are not a PSC version.
    #[error(
        "{device} answers {hex}, not a PSC firmware version such as \"1.4\" (wrong baud rate \
         {baud}, or not a Parallax Servo Controller?)"
    )]
    Garbage {
        /// The device.
        device: PathBuf,
        /// The bytes received, in hex.
        hex: String,
        /// Baud rate tried.
        baud: u32,
    },
    /// Reading or writing failed (the device vanished, for example a USB adapter unplugged).
    #[error("serial link {device} lost: {detail}")]
    Io {
        /// The device.
        device: PathBuf,
        /// The OS's reason.
        detail: String,
    },
}

/// What the bytes received after a version query say.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum VersionReply {
    /// A firmware version (three ASCII bytes, digit '.' digit).
    Version(String),
    /// Nothing conclusive yet: nothing, echoes, or the start of a version.
    Incomplete,
    /// Bytes that can be neither an echo of the query nor a version.
    Garbage,
}

/// Classifies what came back after `!SCVER?\r`. Echoes of the query (a single-wire serial
/// line returns what it is sent) are skipped wherever they stand; a version is three ASCII
/// bytes of the form `1.4`.
pub fn classify_reply(rx: &[u8]) -> VersionReply {
    let rest = strip_echoes(rx);
    // A controller powering up may put glitch bytes (line held low or high) first; nothing
    // else may stand before or after the version: a digit-dot-digit inside other text (a
    // GPS sentence, "3.3V") is not a PSC.
    let start = rest.iter().take_while(|&&b| b == 0x00 || b == 0xff).count();
    let body = &rest[start..];
    let is_version = |w: &[u8]| w[0].is_ascii_digit() && w[1] == b'.' && w[2].is_ascii_digit();
    let valid_start = match body {
        [] => true,
        [a] => a.is_ascii_digit(),
        [a, b] => a.is_ascii_digit() && *b == b'.',
        _ => false,
    };
    if valid_start {
        return VersionReply::Incomplete;
    }
    // Whole versions only (repeated queries may each have been answered).
    if body.len().is_multiple_of(3) && body.chunks_exact(3).all(is_version) {
        return VersionReply::Version(String::from_utf8_lossy(&body[..3]).into_owned());
    }
    VersionReply::Garbage
}

/// `rx` without every whole echo of the query, and without a trailing partial echo.
fn strip_echoes(rx: &[u8]) -> Vec<u8> {
    let q = VERSION_QUERY.as_slice();
    let mut out = Vec::with_capacity(rx.len());
    let mut i = 0;
    while i < rx.len() {
        let tail = &rx[i..];
        if tail.starts_with(q) {
            i += q.len();
        } else if tail.len() < q.len() && q.starts_with(tail) && tail[0] == b'!' {
            // The start of an echo still arriving.
            break;
        } else {
            out.push(rx[i]);
            i += 1;
        }
    }
    out
}

/// True if `rx` holds at least one whole echo of the query and nothing else.
fn only_echoes(rx: &[u8]) -> bool {
    !rx.is_empty() && rx.len() >= VERSION_QUERY.len() && strip_echoes(rx).is_empty()
}

/// The verdict on one query window that ended without a version.
fn window_verdict(rx: &[u8], device: &Path, baud: u32) -> LinkError {
    if rx.is_empty() {
        LinkError::Silent {
            device: device.to_path_buf(),
            timeout_ms: QUERY_WINDOW.as_millis() as u64,
            baud,
        }
    } else if only_echoes(rx) {
        LinkError::Echo {
            device: device.to_path_buf(),
        }
    } else {
        let shown: Vec<String> = strip_echoes(rx)
            .iter()
            .take(12)
            .map(|b| format!("{b:02x}"))
            .collect();
        LinkError::Garbage {
            device: device.to_path_buf(),
            hex: if shown.is_empty() {
                "part of an echo".into()
            } else {
                shown.join(" ")
            },
            baud,
        }
    }
}

/// Where the link stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkState {
    /// No open device (missing, or it cannot be opened yet).
    Absent,
    /// Open; waiting for a valid version reply.
    Probing,
    /// A controller answered: commands may go out.
    Up,
    /// Was up and failed; reopened shortly.
    Lost,
}

impl LinkState {
    /// Lower-case label.
    pub fn label(self) -> &'static str {
        match self {
            Self::Absent => "absent",
            Self::Probing => "probing",
            Self::Up => "up",
            Self::Lost => "lost",
        }
    }
}

/// Something the stage should log or act on, returned by [`PscLink::poll`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LinkEvent {
    /// A controller answered (`firmware` is empty when the check is off): start with neutral.
    Up {
        /// The firmware version it reported.
        firmware: String,
    },
    /// The reason the link is not up changed (or was seen for the first time).
    Waiting(LinkError),
    /// The link was up and failed.
    Lost(LinkError),
}

/// How the link is opened.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LinkSettings {
    /// The device path.
    pub device: PathBuf,
    /// Baud rate.
    pub baud: u32,
    /// Require a valid `!SCVER?` reply before the link is up.
    pub check: bool,
    /// Take the device for this process alone (TIOCEXCL).
    pub exclusive: bool,
}

/// The serial link to the PSC as a non-blocking state machine.
pub struct PscLink {
    settings: LinkSettings,
    state: LinkState,
    port: Option<TTYPort>,
    /// When the link last stopped being up (or the stage started).
    down_since: Instant,
    next_open: Instant,
    reopen_delay: Duration,
    query_sent: Option<Instant>,
    rx: Vec<u8>,
    firmware: String,
    problem: Option<LinkError>,
    next_node_check: Instant,
}

impl PscLink {
    /// A link that opens `settings.device` at the first [`poll`](Self::poll).
    pub fn new(settings: LinkSettings, now: Instant) -> Self {
        Self {
            settings,
            state: LinkState::Absent,
            port: None,
            down_since: now,
            next_open: now,
            reopen_delay: REOPEN_MIN,
            query_sent: None,
            rx: Vec::new(),
            firmware: String::new(),
            problem: None,
            next_node_check: now,
        }
    }

    /// The state.
    pub fn state(&self) -> LinkState {
        self.state
    }

    /// The device path.
    pub fn device(&self) -> &Path {
        &self.settings.device
    }

    /// Firmware version of the controller (empty until it answered, or without a check).
    pub fn firmware(&self) -> &str {
        &self.firmware
    }

    /// A one-line status for the stage's heartbeat note, e.g. "no servo controller answers
    /// on /dev/ttyUSB0 (waiting 12 s)".
    pub fn note(&self, now: Instant) -> String {
        let device = self.settings.device.display();
        if self.state == LinkState::Up {
            return if self.firmware.is_empty() {
                format!("{device} up")
            } else {
                format!("{device} PSC {}", self.firmware)
            };
        }
        let waited = now.saturating_duration_since(self.down_since).as_secs();
        let what = match &self.problem {
            None | Some(LinkError::Silent { .. }) => {
                format!("no servo controller answers on {device}")
            }
            Some(LinkError::Missing { .. }) => format!("no serial device {device}"),
            Some(LinkError::Open { .. }) => format!("cannot open {device}"),
            Some(LinkError::Echo { .. }) => format!("only an echo on {device}, no controller"),
            Some(LinkError::Garbage { .. }) => format!("{device} answers garbage, not a PSC"),
            Some(LinkError::Io { .. }) => format!("servo controller lost on {device}"),
        };
        format!("{what} (waiting {waited} s)")
    }

    /// Advances the machine at `now`: opens the device when due, reads what arrived, judges
    /// the reply, re-asks. Never blocks.
    pub fn poll(&mut self, now: Instant) -> Option<LinkEvent> {
        match self.state {
            LinkState::Absent | LinkState::Lost => self.try_open(now),
            LinkState::Probing => self.probe(now),
            LinkState::Up => {
                if let Some(lost) = self.check_node(now) {
                    return Some(lost);
                }
                // An echoing line returns every command: keep the input buffer empty.
                if let Err(e) = self.read_available() {
                    return self.lose(now, e);
                }
                self.rx.clear();
                None
            }
        }
    }

    fn try_open(&mut self, now: Instant) -> Option<LinkEvent> {
        if now < self.next_open {
            return None;
        }
        match open_port(&self.settings) {
            Ok(port) => {
                self.port = Some(port);
                self.next_node_check = now + NODE_CHECK;
                if !self.settings.check {
                    return Some(self.come_up(now, String::new()));
                }
                self.state = LinkState::Probing;
                self.rx.clear();
                if let Some(port) = self.port.as_mut() {
                    let _ = port.clear(serialport::ClearBuffer::Input);
                }
                self.send_query(now)
            }
            Err(e) => {
                self.next_open = now + self.reopen_delay;
                self.reopen_delay = (self.reopen_delay * 2).min(REOPEN_MAX);
                self.wait_for(e)
            }
        }
    }

    fn send_query(&mut self, now: Instant) -> Option<LinkEvent> {
        self.query_sent = Some(now);
        if let Err(e) = self.write(VERSION_QUERY) {
            return self.lose(now, e);
        }
        None
    }

    fn probe(&mut self, now: Instant) -> Option<LinkEvent> {
        if let Some(lost) = self.check_node(now) {
            return Some(lost);
        }
        if let Err(e) = self.read_available() {
            return self.lose(now, e);
        }
        let waited = now.saturating_duration_since(self.query_sent.unwrap_or(now));
        match classify_reply(&self.rx) {
            VersionReply::Version(v) => return Some(self.come_up(now, v)),
            VersionReply::Incomplete => {
                // A window that ends inside a reply is stretched so the reply is not cut.
                let mid_reply = !strip_echoes(&self.rx).is_empty();
                let grace = if mid_reply {
                    QUERY_GRACE
                } else {
                    Duration::ZERO
                };
                if waited < QUERY_WINDOW + grace {
                    return None;
                }
            }
            // Wait the window out: the garbage is shown whole, and a version behind it counts.
            VersionReply::Garbage if waited < QUERY_WINDOW => return None,
            VersionReply::Garbage => {}
        }
        // The window ended without a version: say why, ask again.
        let verdict = window_verdict(&self.rx, &self.settings.device, self.settings.baud);
        self.rx.clear();
        let event = self.wait_for(verdict);
        if let Some(lost) = self.send_query(now) {
            return Some(lost);
        }
        event
    }

    /// Every [`NODE_CHECK`] while open: a removed device node (an adapter pulled out)
    /// takes the link down even before a read or write fails.
    fn check_node(&mut self, now: Instant) -> Option<LinkEvent> {
        if now < self.next_node_check {
            return None;
        }
        self.next_node_check = now + NODE_CHECK;
        if self.settings.device.exists() {
            return None;
        }
        let missing = LinkError::Missing {
            device: self.settings.device.clone(),
        };
        // Always an event: the link changed state.
        let event = self.lose(now, missing.clone());
        Some(event.unwrap_or(LinkEvent::Waiting(missing)))
    }

    fn come_up(&mut self, now: Instant, firmware: String) -> LinkEvent {
        self.state = LinkState::Up;
        self.reopen_delay = REOPEN_MIN;
        self.firmware = firmware.clone();
        self.problem = None;
        self.rx.clear();
        self.next_node_check = now + NODE_CHECK;
        LinkEvent::Up { firmware }
    }

    /// Records why the link is not up; an event only when the reason changed.
    fn wait_for(&mut self, e: LinkError) -> Option<LinkEvent> {
        let changed = self.problem.as_ref() != Some(&e);
        self.problem = Some(e.clone());
        changed.then_some(LinkEvent::Waiting(e))
    }

    /// Closes the port after a failure. From up: `Lost`, reopened soon. From probing: the
    /// reopen delay keeps doubling and only a new reason is reported, so a device that opens
    /// but fails every read does not flood the log.
    fn lose(&mut self, now: Instant, e: LinkError) -> Option<LinkEvent> {
        let was_up = self.state == LinkState::Up;
        self.port = None;
        self.rx.clear();
        self.query_sent = None;
        if was_up {
            self.state = LinkState::Lost;
            self.down_since = now;
            self.next_open = now + REOPEN_MIN;
            self.reopen_delay = REOPEN_MIN;
            self.problem = Some(e.clone());
            return Some(LinkEvent::Lost(e));
        }
        self.state = LinkState::Absent;
        self.next_open = now + self.reopen_delay;
        self.reopen_delay = (self.reopen_delay * 2).min(REOPEN_MAX);
        self.wait_for(e)
    }

    /// Appends the bytes already received to `rx` (never waits).
    fn read_available(&mut self) -> Result<(), LinkError> {
        let Some(port) = self.port.as_mut() else {
            return Ok(());
        };
        let mut buf = [0u8; 64];
        loop {
            let pending = port.bytes_to_read().map_err(|e| LinkError::Io {
                device: self.settings.device.clone(),
                detail: format!("reading: {e}"),
            })?;
            if pending == 0 {
                return Ok(());
            }
            let want = (pending as usize).min(buf.len());
            match port.read(&mut buf[..want]) {
                Ok(0) => return Ok(()),
                Ok(n) => {
                    // Bound what a babbling line can make us hold.
                    if self.rx.len() < 4096 {
                        self.rx.extend_from_slice(&buf[..n]);
                    }
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::TimedOut
                            | std::io::ErrorKind::Interrupted
                            | std::io::ErrorKind::WouldBlock
                    ) =>
                {
                    return Ok(());
                }
                Err(e) => {
                    return Err(LinkError::Io {
                        device: self.settings.device.clone(),
                        detail: format!("reading: {e}"),
                    });
                }
            }
        }
    }

    /// True while commands may be written.
    pub fn is_up(&self) -> bool {
        self.state == LinkState::Up
    }

    /// Hands `bytes` to the serial driver (returns before they are on the wire). Only while
    /// up; a failure takes the link down (`Lost`) and is returned.
    pub fn send(&mut self, bytes: &[u8], now: Instant) -> Result<(), LinkError> {
        if self.state != LinkState::Up {
            return Err(self.problem.clone().unwrap_or(LinkError::Silent {
                device: self.settings.device.clone(),
                timeout_ms: QUERY_WINDOW.as_millis() as u64,
                baud: self.settings.baud,
            }));
        }
        match self.write(bytes) {
            Ok(()) => Ok(()),
            Err(e) => {
                let _ = self.lose(now, e.clone());
                Err(e)
            }
        }
    }

    fn write(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        let Some(port) = self.port.as_mut() else {
            return Err(LinkError::Io {
                device: self.settings.device.clone(),
                detail: "not open".into(),
            });
        };
        port.write_all(bytes).map_err(|e| LinkError::Io {
            device: self.settings.device.clone(),
            detail: format!("writing: {e}"),
        })
    }

    /// Blocks until everything written is on the wire (used before exiting).
    pub fn drain(&mut self) {
        if let Some(port) = self.port.as_mut() {
            let _ = port.flush();
        }
    }
}

fn open_port(s: &LinkSettings) -> Result<TTYPort, LinkError> {
    if !s.device.exists() {
        return Err(LinkError::Missing {
            device: s.device.clone(),
        });
    }
    serialport::new(s.device.to_string_lossy(), s.baud)
        .data_bits(DataBits::Eight)
        .parity(Parity::None)
        .stop_bits(StopBits::One)
        .flow_control(FlowControl::None)
        // Bounds a write to a line whose buffer is full; reads never wait (bytes_to_read).
        .timeout(Duration::from_millis(20))
        .exclusive(s.exclusive)
        .open_native()
        .map_err(|e| LinkError::Open {
            device: s.device.clone(),
            detail: e.to_string(),
        })
}

/// Opens the device and waits up to `timeout` for a valid version reply (re-asking every
/// [`QUERY_WINDOW`]): the blocking check `hvs doctor` runs. Returns the firmware version or
/// the last reason the link did not come up.
pub fn check_controller(device: &Path, baud: u32, timeout: Duration) -> Result<String, LinkError> {
    let start = Instant::now();
    let mut link = PscLink::new(
        LinkSettings {
            device: device.to_path_buf(),
            baud,
            check: true,
            exclusive: false,
        },
        start,
    );
    let mut last = None;
    loop {
        let now = Instant::now();
        match link.poll(now) {
            Some(LinkEvent::Up { firmware }) => return Ok(firmware),
            Some(LinkEvent::Waiting(e) | LinkEvent::Lost(e)) => last = Some(e),
            None => {}
        }
        if now.duration_since(start) >= timeout {
            return Err(match (link.state(), last) {
                // A window still open at the deadline: judge what it holds so far.
                (LinkState::Probing, _) if !link.rx.is_empty() => {
                    window_verdict(&link.rx, device, baud)
                }
                (_, Some(e)) => e,
                _ => window_verdict(&[], device, baud),
            });
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[cfg(test)]
mod tests;
