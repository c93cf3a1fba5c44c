//! Parallax Servo Controller (PSC) emulator: wire-protocol parser with resynchronisation,
//! 2400-baud wire timing, ramped pulse outputs on 16 channels, version/position replies, and a
//! check of the host's serial settings.
//!
//! # Protocol
//! - position: `'!' 'S' 'C' C R PW_low PW_high 0x0D` (C 0..=15, R 0..=63, PW 250..=1250 in
//!   2 us units);
//! - `!SCVER?\r` is answered with the three ASCII bytes `1.4`;
//! - `!SCRSP` C `\r` is answered with C, PW high byte, PW low byte of the current position.
//!
//! # Timing
//! At 2400 baud 8N1 a byte takes 10 bits = 1/240 s on the wire. Byte k takes effect at
//! `max(arrival_k, effect_{k-1}) + 1/240 s`, so a host that writes faster than the wire builds a
//! backlog ([`PscParser::backlog_s`]). A command takes effect when its last byte does. Replies are
//! due when their 3 bytes have crossed the return wire (3/240 s after the query took effect).
//!
//! # Ramps
//! R = 0 jumps immediately; R = 1..=63 slews the output linearly, a full 250 -> 1250 excursion
//! taking 0.75 s (R = 1) up to 60 s (R = 63), linear in R in between. A channel that was never
//! commanded outputs no pulse ([`PscEmulator::pulse_at`] returns `None`), and its first command
//! takes effect immediately whatever its ramp (there is no previous position to ramp from).

use std::collections::VecDeque;
use std::fmt;

/// Baud rate of the PSC link.
pub const PSC_BAUD: u32 = 2400;
/// Wire time of one byte at 2400 baud 8N1 (10 bits), seconds.
pub const BYTE_TIME_S: f64 = 10.0 / PSC_BAUD as f64;
/// Number of PSC channels.
pub const CHANNELS: usize = 16;
/// Smallest valid pulse width, 2 us units (0.5 ms).
pub const PW_MIN: u16 = 250;
/// Largest valid pulse width, 2 us units (2.5 ms).
pub const PW_MAX: u16 = 1250;
/// Largest ramp value.
pub const RAMP_MAX: u8 = 63;
/// The firmware version the emulator reports.
pub const FIRMWARE_VERSION: [u8; 3] = *b"1.4";
/// Length of every PSC frame in bytes.
pub const FRAME_LEN: usize = 8;

/// Time for a full 250 -> 1250 excursion at ramp `ramp` (1..=63), seconds.
pub fn ramp_full_excursion_s(ramp: u8) -> f64 {
    let r = f64::from(ramp.clamp(1, RAMP_MAX));
    0.75 + (r - 1.0) * (60.0 - 0.75) / 62.0
}

/// A valid command decoded from the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PscCommand {
    /// Move `channel` to `pulse` (2 us units) with `ramp`.
    SetPosition {
        /// Channel 0..=15.
        channel: u8,
        /// Ramp 0..=63.
        ramp: u8,
        /// Pulse width 250..=1250 in 2 us units.
        pulse: u16,
    },
    /// `!SCVER?\r`.
    QueryVersion,
    /// `!SCRSP` C `\r`.
    QueryPosition {
        /// Channel 0..=15.
        channel: u8,
    },
}

/// A command with the time its last byte took effect.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PscEvent {
    /// When the command takes effect, seconds (same clock as the arrival times).
    pub time_s: f64,
    /// The command.
    pub command: PscCommand,
}

/// Why a frame that started with `!SC` was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Malformed {
    /// The 8th byte was not 0x0D.
    BadTerminator {
        /// The byte found.
        byte: u8,
    },
    /// Channel above 15.
    ChannelOutOfRange {
        /// The channel byte.
        channel: u8,
    },
    /// Pulse width outside 250..=1250.
    PulseOutOfRange {
        /// The pulse width.
        pulse: u16,
    },
    /// Ramp above 63.
    RampOutOfRange {
        /// The ramp byte.
        ramp: u8,
    },
    /// `!SCV...`/`!SCR...` that is not `!SCVER?\r` / `!SCRSP` C `\r`.
    BadQuery,
}

impl fmt::Display for Malformed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Malformed::BadTerminator { byte } => write!(f, "bad terminator 0x{byte:02x}"),
            Malformed::ChannelOutOfRange { channel } => write!(f, "channel {channel} > 15"),
            Malformed::PulseOutOfRange { pulse } => {
                write!(f, "pulse width {pulse} outside {PW_MIN}..={PW_MAX}")
            }
            Malformed::RampOutOfRange { ramp } => write!(f, "ramp {ramp} > {RAMP_MAX}"),
            Malformed::BadQuery => write!(f, "unknown query"),
        }
    }
}

enum Check {
    Partial,
    Complete(PscCommand),
    /// Reject: `Some` counts a malformed frame; `resync` re-scans the bytes after the first.
    Reject(Option<Malformed>, bool),
}

/// Byte-stream parser of the PSC protocol with wire timing.
#[derive(Debug, Clone, Default)]
pub struct PscParser {
    buf: [u8; FRAME_LEN],
    len: usize,
    wire_end_s: f64,
    last_arrival_s: f64,
    frames_ok: u64,
    malformed: u64,
    garbage_bytes: u64,
    last_malformed: Option<Malformed>,
}

impl PscParser {
    /// A parser with an idle wire.
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds one byte that arrived (was written by the host) at `arrival_s`; returns the command
    /// it completes, stamped with the time it takes effect.
    pub fn push(&mut self, byte: u8, arrival_s: f64) -> Option<PscEvent> {
        let effect = arrival_s.max(self.wire_end_s) + BYTE_TIME_S;
        self.wire_end_s = effect;
        self.last_arrival_s = arrival_s;
        self.feed(byte).map(|command| PscEvent {
            time_s: effect,
            command,
        })
    }

    fn feed(&mut self, byte: u8) -> Option<PscCommand> {
        self.buf[self.len] = byte;
        self.len += 1;
        match self.check() {
            Check::Partial => None,
            Check::Complete(cmd) => {
                self.len = 0;
                self.frames_ok += 1;
                Some(cmd)
            }
            Check::Reject(malformed, resync) => {
                match malformed {
                    Some(m) => {
                        self.malformed += 1;
                        self.last_malformed = Some(m);
                    }
                    None => self.garbage_bytes += 1,
                }
                let rest = self.buf;
                let n = self.len;
                self.len = 0;
                if resync {
                    // Re-scan the bytes after the rejected start; fewer than 8 bytes can never
                    // complete a frame, so this produces no command.
                    for &b in &rest[1..n] {
                        let _ = self.feed(b);
                    }
                }
                None
            }
        }
    }

    fn check(&self) -> Check {
        let b = &self.buf[..self.len];
        let n = b.len();
        if b[0] != b'!' {
            return Check::Reject(None, false);
        }
        if (n >= 2 && b[1] != b'S') || (n >= 3 && b[2] != b'C') {
            return Check::Reject(None, true);
        }
        if n < 4 {
            return Check::Partial;
        }
        match b[3] {
            b'V' => {
                let want = b"!SCVER?\r";
                if b[..n] != want[..n] {
                    return Check::Reject(Some(Malformed::BadQuery), true);
                }
                if n == FRAME_LEN {
                    Check::Complete(PscCommand::QueryVersion)
                } else {
                    Check::Partial
                }
            }
            b'R' => {
                if (n >= 5 && b[4] != b'S') || (n >= 6 && b[5] != b'P') {
                    return Check::Reject(Some(Malformed::BadQuery), true);
                }
                if n < FRAME_LEN {
                    return Check::Partial;
                }
                if b[7] != b'\r' {
                    return Check::Reject(Some(Malformed::BadTerminator { byte: b[7] }), true);
                }
                if usize::from(b[6]) >= CHANNELS {
                    return Check::Reject(
                        Some(Malformed::ChannelOutOfRange { channel: b[6] }),
                        false,
                    );
                }
                Check::Complete(PscCommand::QueryPosition { channel: b[6] })
            }
            _ => {
                if n < FRAME_LEN {
                    return Check::Partial;
                }
                if b[7] != b'\r' {
                    return Check::Reject(Some(Malformed::BadTerminator { byte: b[7] }), true);
                }
                let (channel, ramp) = (b[3], b[4]);
                let pulse = u16::from_le_bytes([b[5], b[6]]);
                let bad = if usize::from(channel) >= CHANNELS {
                    Some(Malformed::ChannelOutOfRange { channel })
                } else if !(PW_MIN..=PW_MAX).contains(&pulse) {
                    Some(Malformed::PulseOutOfRange { pulse })
                } else if ramp > RAMP_MAX {
                    Some(Malformed::RampOutOfRange { ramp })
                } else {
                    None
                };
                match bad {
                    Some(m) => Check::Reject(Some(m), false),
                    None => Check::Complete(PscCommand::SetPosition {
                        channel,
                        ramp,
                        pulse,
                    }),
                }
            }
        }
    }

    /// Valid frames decoded so far.
    pub fn frames_ok(&self) -> u64 {
        self.frames_ok
    }

    /// Frames that started with `!SC` and were rejected.
    pub fn malformed_frames(&self) -> u64 {
        self.malformed
    }

    /// Bytes discarded outside any `!SC` frame while resynchronising.
    pub fn garbage_bytes(&self) -> u64 {
        self.garbage_bytes
    }

    /// Why the last malformed frame was rejected.
    pub fn last_malformed(&self) -> Option<Malformed> {
        self.last_malformed
    }

    /// Backlog at the last byte's arrival: how long after it was written it takes effect, minus
    /// its own wire time (0 when the host never outruns the wire), seconds.
    pub fn backlog_s(&self) -> f64 {
        (self.wire_end_s - self.last_arrival_s - BYTE_TIME_S).max(0.0)
    }

    /// Wire time still queued at `time_s` (0 when the wire is idle), seconds.
    pub fn backlog_at(&self, time_s: f64) -> f64 {
        (self.wire_end_s - time_s).max(0.0)
    }

    /// When the last byte received so far takes effect, seconds.
    pub fn wire_end_s(&self) -> f64 {
        self.wire_end_s
    }
}

/// Output state of one channel.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Output {
    from: f64,
    to: u16,
    start_s: f64,
    /// Slew rate in units per second (infinite for an immediate move).
    rate: f64,
}

impl Output {
    fn at(&self, time_s: f64) -> f64 {
        let target = f64::from(self.to);
        if !self.rate.is_finite() || time_s >= self.start_s + (target - self.from).abs() / self.rate
        {
            return target;
        }
        let dt = (time_s - self.start_s).max(0.0);
        self.from + (target - self.from).signum() * self.rate * dt
    }
}

fn apply(out: Option<Output>, time_s: f64, ramp: u8, pulse: u16) -> Output {
    match out {
        Some(prev) if ramp > 0 => Output {
            from: prev.at(time_s),
            to: pulse,
            start_s: time_s,
            rate: f64::from(PW_MAX - PW_MIN) / ramp_full_excursion_s(ramp),
        },
        _ => Output {
            from: f64::from(pulse),
            to: pulse,
            start_s: time_s,
            rate: f64::INFINITY,
        },
    }
}

/// Serial parity.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Parity {
    /// No parity bit.
    None,
    /// Odd parity.
    Odd,
    /// Even parity.
    Even,
}

/// Line settings of a serial port.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SerialSettings {
    /// Baud rate.
    pub baud: u32,
    /// Data bits (5..=8).
    pub data_bits: u8,
    /// Parity.
    pub parity: Parity,
    /// Stop bits (1 or 2).
    pub stop_bits: u8,
}

impl fmt::Display for SerialSettings {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let p = match self.parity {
            Parity::None => 'N',
            Parity::Odd => 'O',
            Parity::Even => 'E',
        };
        write!(f, "{} {}{}{}", self.baud, self.data_bits, p, self.stop_bits)
    }
}

/// The host's serial settings differ from the PSC's 2400 8N1.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("serial settings {found} do not match the PSC's {expected}: {}", .problems.join(", "))]
pub struct SerialMismatch {
    /// What the host set.
    pub found: SerialSettings,
    /// What the PSC needs.
    pub expected: SerialSettings,
    /// One entry per mismatching setting, e.g. "baud 9600 (expected 2400)".
    pub problems: Vec<String>,
}

impl SerialSettings {
    /// The PSC's settings: 2400 baud, 8 data bits, no parity, 1 stop bit.
    pub const PSC: SerialSettings = SerialSettings {
        baud: PSC_BAUD,
        data_bits: 8,
        parity: Parity::None,
        stop_bits: 1,
    };

    /// Decodes data bits, parity and stop bits from a termios `c_cflag`, with the baud rate
    /// given separately (see [`SerialSettings::from_termios2`] on Linux).
    pub fn from_cflag(cflag: libc::tcflag_t, baud: u32) -> Self {
        let data_bits = match cflag & libc::CSIZE {
            libc::CS5 => 5,
            libc::CS6 => 6,
            libc::CS7 => 7,
            _ => 8,
        };
        let parity = if cflag & libc::PARENB == 0 {
            Parity::None
        } else if cflag & libc::PARODD != 0 {
            Parity::Odd
        } else {
            Parity::Even
        };
        let stop_bits = if cflag & libc::CSTOPB != 0 { 2 } else { 1 };
        SerialSettings {
            baud,
            data_bits,
            parity,
            stop_bits,
        }
    }

    /// Decodes a Linux `termios2` (as read with `TCGETS2`; clients such as the `serialport`
    /// crate set arbitrary rates with `BOTHER`, which plain `tcgetattr` cannot report).
    #[cfg(target_os = "linux")]
    pub fn from_termios2(t: &libc::termios2) -> Self {
        let baud = if t.c_cflag & libc::CBAUD == libc::BOTHER {
            t.c_ospeed
        } else {
            baud_from_code(t.c_cflag & libc::CBAUD).unwrap_or(t.c_ospeed)
        };
        Self::from_cflag(t.c_cflag, baud)
    }

    /// Checks these settings against the PSC's 2400 8N1.
    pub fn check_psc(&self) -> Result<(), SerialMismatch> {
        let e = SerialSettings::PSC;
        let mut problems = Vec::new();
        if self.baud != e.baud {
            problems.push(format!("baud {} (expected {})", self.baud, e.baud));
        }
        if self.data_bits != e.data_bits {
            problems.push(format!("{} data bits (expected 8)", self.data_bits));
        }
        if self.parity != e.parity {
            problems.push(format!("parity {:?} (expected none)", self.parity).to_lowercase());
        }
        if self.stop_bits != e.stop_bits {
            problems.push(format!("{} stop bits (expected 1)", self.stop_bits));
        }
        if problems.is_empty() {
            Ok(())
        } else {
            Err(SerialMismatch {
                found: *self,
                expected: e,
                problems,
            })
        }
    }
}

/// Baud rate of a termios `Bxxx` code.
#[cfg(target_os = "linux")]
fn baud_from_code(code: libc::tcflag_t) -> Option<u32> {
    let table: [(libc::tcflag_t, u32); 18] = [
        (libc::B50, 50),
        (libc::B75, 75),
        (libc::B110, 110),
        (libc::B134, 134),
        (libc::B150, 150),
        (libc::B200, 200),
        (libc::B300, 300),
        (libc::B600, 600),
        (libc::B1200, 1200),
        (libc::B1800, 1800),
        (libc::B2400, 2400),
        (libc::B4800, 4800),
        (libc::B9600, 9600),
        (libc::B19200, 19200),
        (libc::B38400, 38400),
        (libc::B57600, 57600),
        (libc::B115200, 115_200),
        (libc::B230400, 230_400),
    ];
    table.iter().find(|(c, _)| *c == code).map(|(_, b)| *b)
}

/// Counters of the emulator.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PscCounters {
    /// Valid frames decoded.
    pub frames_ok: u64,
    /// Frames that started with `!SC` and were rejected.
    pub malformed_frames: u64,
    /// Bytes discarded outside frames.
    pub garbage_bytes: u64,
    /// Bytes ignored because the host's serial settings were wrong.
    pub ignored_bytes: u64,
    /// Backlog of the last byte received (see [`PscParser::backlog_s`]), seconds.
    pub backlog_s: f64,
}

/// The PSC emulator: parser, 16 ramped outputs, and replies.
#[derive(Debug, Clone, Default)]
pub struct PscEmulator {
    parser: PscParser,
    /// Outputs as of `committed_s` (None = never commanded).
    outputs: [Option<Output>; CHANNELS],
    /// Position commands that take effect later than the last commit, in time order.
    pending: VecDeque<(f64, u8, u8, u16)>,
    /// Replies (due time, bytes) in time order.
    replies: VecDeque<(f64, Vec<u8>)>,
    serial_mismatch: Option<SerialMismatch>,
    ignored_bytes: u64,
}

impl PscEmulator {
    /// A powered-up PSC: no channel has been commanded.
    pub fn new() -> Self {
        Self::default()
    }

    /// Records the host's serial settings; while they mismatch 2400 8N1 the emulator ignores
    /// incoming bytes (real hardware would only see garbage). Returns the mismatch, if any.
    pub fn set_serial_settings(&mut self, settings: &SerialSettings) -> Result<(), SerialMismatch> {
        let r = settings.check_psc();
        self.serial_mismatch = r.clone().err();
        r
    }

    /// The current serial-settings mismatch, if any.
    pub fn serial_mismatch(&self) -> Option<&SerialMismatch> {
        self.serial_mismatch.as_ref()
    }

    /// Feeds bytes that the host wrote at `arrival_s`; returns the decoded events.
    pub fn receive(&mut self, bytes: &[u8], arrival_s: f64) -> Vec<PscEvent> {
        if self.serial_mismatch.is_some() {
            self.ignored_bytes += bytes.len() as u64;
            return Vec::new();
        }
        let mut events = Vec::new();
        for &b in bytes {
            if let Some(ev) = self.parser.push(b, arrival_s) {
                self.handle(ev);
                events.push(ev);
            }
        }
        events
    }

    fn handle(&mut self, ev: PscEvent) {
        let due = ev.time_s + 3.0 * BYTE_TIME_S;
        match ev.command {
            PscCommand::SetPosition {
                channel,
                ramp,
                pulse,
            } => self.pending.push_back((ev.time_s, channel, ramp, pulse)),
            PscCommand::QueryVersion => self.replies.push_back((due, FIRMWARE_VERSION.to_vec())),
            PscCommand::QueryPosition { channel } => {
                let pw = self
                    .pulse_at(channel, ev.time_s)
                    .map_or(0u16, |p| p.round().clamp(0.0, f64::from(u16::MAX)) as u16);
                let [hi, lo] = pw.to_be_bytes();
                self.replies.push_back((due, vec![channel, hi, lo]));
            }
        }
    }

    fn output_at(&self, channel: u8, time_s: f64) -> Option<Output> {
        let ch = usize::from(channel);
        let mut out = *self.outputs.get(ch)?;
        for &(t, c, ramp, pulse) in &self.pending {
            if t > time_s {
                break;
            }
            if c == channel {
                out = Some(apply(out, t, ramp, pulse));
            }
        }
        out
    }

    /// Output pulse width of `channel` at `time_s` in 2 us units (fractional while ramping), or
    /// `None` if the channel has never been commanded (or does not exist).
    pub fn pulse_at(&self, channel: u8, time_s: f64) -> Option<f64> {
        self.output_at(channel, time_s).map(|o| o.at(time_s))
    }

    /// Applies the commands that took effect up to `time_s` (keeps [`PscEmulator::pulse_at`]
    /// cheap); later queries should not ask for earlier times.
    pub fn commit_until(&mut self, time_s: f64) {
        while let Some(&(t, c, ramp, pulse)) = self.pending.front() {
            if t > time_s {
                break;
            }
            let slot = &mut self.outputs[usize::from(c)];
            *slot = Some(apply(*slot, t, ramp, pulse));
            self.pending.pop_front();
        }
    }

    /// Reply bytes due by `time_s` (in order), removed from the queue.
    pub fn take_replies_due(&mut self, time_s: f64) -> Vec<u8> {
        let mut out = Vec::new();
        while let Some((t, _)) = self.replies.front() {
            if *t > time_s {
                break;
            }
            if let Some((_, bytes)) = self.replies.pop_front() {
                out.extend_from_slice(&bytes);
            }
        }
        out
    }

    /// When the next queued reply is due, if any.
    pub fn next_reply_due_s(&self) -> Option<f64> {
        self.replies.front().map(|(t, _)| *t)
    }

    /// Counters (frames, errors, backlog).
    pub fn counters(&self) -> PscCounters {
        PscCounters {
            frames_ok: self.parser.frames_ok(),
            malformed_frames: self.parser.malformed_frames(),
            garbage_bytes: self.parser.garbage_bytes(),
            ignored_bytes: self.ignored_bytes,
            backlog_s: self.parser.backlog_s(),
        }
    }

    /// The parser (for its last error and backlog queries).
    pub fn parser(&self) -> &PscParser {
        &self.parser
    }
}

/// Encodes a position command frame (for tests and tools).
pub fn encode_position(channel: u8, ramp: u8, pulse: u16) -> [u8; FRAME_LEN] {
    let [lo, hi] = pulse.to_le_bytes();
    [b'!', b'S', b'C', channel, ramp, lo, hi, b'\r']
}

#[cfg(test)]
mod tests {
    use super::*;

    fn feed_all(p: &mut PscParser, bytes: &[u8], t: f64) -> Vec<PscEvent> {
        bytes.iter().filter_map(|&b| p.push(b, t)).collect()
    }

    #[test]
    fn position_frame_is_byte_exact() {
        let mut p = PscParser::new();
        let frame = [b'!', b'S', b'C', 5, 0, 0x20, 0x03, 0x0d]; // 800 = 0x0320
        let ev = feed_all(&mut p, &frame, 0.0);
        assert_eq!(ev.len(), 1);
        assert_eq!(
            ev[0].command,
            PscCommand::SetPosition {
                channel: 5,
                ramp: 0,
                pulse: 800
            }
        );
        assert_eq!(encode_position(5, 0, 800), frame);
        // Only the 8th byte completes the frame.
        let mut p = PscParser::new();
        for (i, &b) in frame.iter().enumerate() {
            assert_eq!(p.push(b, 0.0).is_some(), i == 7, "byte {i}");
        }
    }

    #[test]
    fn resynchronises_after_garbage_and_truncated_frames() {
        let mut p = PscParser::new();
        let mut bytes = b"xx\r!!S".to_vec();
        // A truncated frame (host dropped 2 bytes) runs into the next good frame.
        bytes.extend_from_slice(&[b'!', b'S', b'C', 1, 0, 0xd0]);
        bytes.extend_from_slice(&encode_position(1, 0, 720));
        bytes.extend_from_slice(&encode_position(5, 3, 800));
        let ev = feed_all(&mut p, &bytes, 0.0);
        let cmds: Vec<_> = ev.iter().map(|e| e.command).collect();
        assert_eq!(
            cmds,
            vec![
                PscCommand::SetPosition {
                    channel: 1,
                    ramp: 0,
                    pulse: 720
                },
                PscCommand::SetPosition {
                    channel: 5,
                    ramp: 3,
                    pulse: 800
                }
            ]
        );
        assert_eq!(p.malformed_frames(), 1, "the truncated frame");
        assert!(p.garbage_bytes() >= 4);
        assert!(matches!(
            p.last_malformed(),
            Some(Malformed::BadTerminator { .. })
        ));
    }

    #[test]
    fn frame_with_bang_in_payload_parses() {
        // PW 545 = 0x0221: low byte is '!'.
        let mut p = PscParser::new();
        let ev = feed_all(&mut p, &encode_position(2, 0, 545), 0.0);
        assert_eq!(ev.len(), 1);
        assert_eq!(p.garbage_bytes() + p.malformed_frames(), 0);
    }

    #[test]
    fn out_of_range_fields_are_counted_and_ignored() {
        let mut p = PscParser::new();
        let mut bytes = Vec::new();
        bytes.extend_from_slice(&encode_position(16, 0, 750)); // channel
        bytes.extend_from_slice(&encode_position(1, 0, 249)); // pulse low
        bytes.extend_from_slice(&encode_position(1, 0, 1251)); // pulse high
        bytes.extend_from_slice(&encode_position(1, 64, 750)); // ramp
        bytes.extend_from_slice(&encode_position(1, 0, 1250)); // valid edge
        bytes.extend_from_slice(&encode_position(15, 63, 250)); // valid edge
        let ev = feed_all(&mut p, &bytes, 0.0);
        assert_eq!(ev.len(), 2);
        assert_eq!(p.malformed_frames(), 4);
        assert_eq!(p.garbage_bytes(), 0);
        assert_eq!(p.frames_ok(), 2);
    }

    #[test]
    fn queries_are_answered() {
        let mut e = PscEmulator::new();
        e.receive(&encode_position(5, 0, 800), 0.0);
        e.receive(b"!SCVER?\r", 0.0);
        e.receive(b"!SCRSP\x05\r", 0.0);
        e.receive(b"!SCRSP\x03\r", 0.0); // never commanded: 0
        // Nothing is due before the bytes crossed the wire.
        assert!(e.take_replies_due(0.01).is_empty());
        let due = e.next_reply_due_s().unwrap();
        // VER: 16 bytes on the wire + 3 back.
        assert!((due - 19.0 * BYTE_TIME_S).abs() < 1e-12, "{due}");
        let r = e.take_replies_due(10.0);
        assert_eq!(r, vec![b'1', b'.', b'4', 5, 0x03, 0x20, 3, 0, 0]);
        assert!(e.take_replies_due(20.0).is_empty());
        let mut p = PscParser::new();
        feed_all(&mut p, b"!SCVEX?\r", 0.0);
        feed_all(&mut p, b"!SCRSX\x01\r", 0.0);
        assert_eq!(p.malformed_frames(), 2);
    }

    #[test]
    fn commands_take_effect_after_the_wire() {
        let mut e = PscEmulator::new();
        let ev = e.receive(&encode_position(1, 0, 720), 1.0);
        let t_eff = 1.0 + 8.0 * BYTE_TIME_S;
        assert!((ev[0].time_s - t_eff).abs() < 1e-12);
        assert_eq!(e.pulse_at(1, t_eff - 1e-6), None);
        assert_eq!(e.pulse_at(1, t_eff), Some(720.0));
        e.commit_until(2.0);
        assert_eq!(e.pulse_at(1, 2.0), Some(720.0));
        assert_eq!(e.pulse_at(16, 2.0), None);
    }

    #[test]
    fn ramps_slew_linearly() {
        assert!((ramp_full_excursion_s(1) - 0.75).abs() < 1e-12);
        assert!((ramp_full_excursion_s(63) - 60.0).abs() < 1e-12);
        assert!((ramp_full_excursion_s(32) - (0.75 + 31.0 * 59.25 / 62.0)).abs() < 1e-12);
        let mut e = PscEmulator::new();
        e.receive(&encode_position(0, 0, 250), 0.0);
        let t0 = 8.0 * BYTE_TIME_S;
        e.receive(&encode_position(0, 1, 1250), 1.0);
        let t1 = 1.0 + 8.0 * BYTE_TIME_S;
        let at_start = e.pulse_at(0, t1).unwrap();
        assert!((at_start - 250.0).abs() < 1e-6, "{at_start}");
        let mid = e.pulse_at(0, t1 + 0.375).unwrap();
        assert!((mid - 750.0).abs() < 1e-6, "{mid}");
        assert_eq!(e.pulse_at(0, t1 + 0.75), Some(1250.0));
        assert_eq!(e.pulse_at(0, t1 + 5.0), Some(1250.0));
        assert!(t0 < t1);
        // A new ramped command starts from wherever the output is, even mid-ramp.
        let mut e = PscEmulator::new();
        e.receive(&encode_position(2, 0, 750), 0.0);
        e.commit_until(1.0);
        e.receive(&encode_position(2, 63, 1250), 1.0); // 1000 units per 60 s
        let ts = 1.0 + 8.0 * BYTE_TIME_S;
        let p = e.pulse_at(2, ts + 6.0).unwrap();
        assert!((p - (750.0 + 100.0)).abs() < 1e-6, "{p}");
        e.receive(&encode_position(2, 63, 250), ts + 6.0 - 8.0 * BYTE_TIME_S);
        let p = e.pulse_at(2, ts + 9.0).unwrap();
        assert!((p - (850.0 - 50.0)).abs() < 1e-6, "{p}");
    }

    #[test]
    fn fast_host_builds_backlog() {
        let mut p = PscParser::new();
        // 10 frames written at once: the last byte takes effect after 80 byte times.
        for _ in 0..10 {
            feed_all(&mut p, &encode_position(1, 0, 760), 5.0);
        }
        let expect = 79.0 * BYTE_TIME_S;
        assert!((p.backlog_s() - expect).abs() < 1e-9, "{}", p.backlog_s());
        assert!((p.backlog_at(5.0) - 80.0 * BYTE_TIME_S).abs() < 1e-9);
        assert_eq!(p.backlog_at(100.0), 0.0);
        // A host that paces its bytes at the wire rate builds none.
        let mut q = PscParser::new();
        for (i, &b) in encode_position(1, 0, 760)
            .iter()
            .cycle()
            .take(80)
            .enumerate()
        {
            q.push(b, i as f64 * BYTE_TIME_S);
        }
        assert!(q.backlog_s() < 1e-9, "{}", q.backlog_s());
        // 15 updates/s of both wheels fit on the wire (30 commands * 8 bytes = 1 s), 20 do not.
        let mut r = PscParser::new();
        for k in 0..40 {
            let t = f64::from(k) / 20.0;
            feed_all(&mut r, &encode_position(1, 0, 760), t);
            feed_all(&mut r, &encode_position(5, 0, 758), t);
        }
        assert!(r.backlog_s() > 0.5, "{}", r.backlog_s());
    }

    #[test]
    fn serial_settings_are_checked() {
        assert!(SerialSettings::PSC.check_psc().is_ok());
        let wrong = SerialSettings {
            baud: 9600,
            data_bits: 7,
            parity: Parity::Even,
            stop_bits: 2,
        };
        let e = wrong.check_psc().unwrap_err();
        assert_eq!(e.problems.len(), 4);
        let msg = e.to_string();
        assert!(
            msg.contains("9600 7E2") && msg.contains("baud 9600 (expected 2400)"),
            "{msg}"
        );
        let s = SerialSettings::from_cflag(
            libc::CS7 | libc::PARENB | libc::PARODD | libc::CSTOPB,
            2400,
        );
        assert_eq!((s.data_bits, s.parity, s.stop_bits), (7, Parity::Odd, 2));
        #[cfg(all(
            target_os = "linux",
            any(target_arch = "x86_64", target_arch = "aarch64")
        ))]
        {
            // A client that set 2400 baud through BOTHER (as the serialport crate does).
            let mut t = libc::termios2 {
                c_iflag: 0,
                c_oflag: 0,
                c_cflag: libc::BOTHER | libc::CS8 | libc::CREAD | libc::CLOCAL,
                c_lflag: 0,
                c_line: 0,
                c_cc: [0; 19],
                c_ispeed: 2400,
                c_ospeed: 2400,
            };
            assert_eq!(SerialSettings::from_termios2(&t), SerialSettings::PSC);
            t.c_cflag = libc::B9600 | libc::CS8 | libc::PARENB;
            t.c_ospeed = 0;
            let s = SerialSettings::from_termios2(&t);
            assert_eq!((s.baud, s.parity), (9600, Parity::Even));
        }
        let mut emu = PscEmulator::new();
        assert!(emu.set_serial_settings(&wrong).is_err());
        assert!(emu.receive(&encode_position(1, 0, 720), 0.0).is_empty());
        assert_eq!(emu.counters().ignored_bytes, 8);
        emu.set_serial_settings(&SerialSettings::PSC).unwrap();
        assert_eq!(emu.receive(&encode_position(1, 0, 720), 1.0).len(), 1);
    }
}
