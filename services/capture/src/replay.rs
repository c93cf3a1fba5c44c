//! Reading a recording of `hvs probe record` / `hvs run --record` back: the replay source.
//!
//! The file is read twice, streaming (a minute of recording is over a gigabyte): a first pass
//! indexes everything but the pixels (which frames the recording holds, which of them the
//! recorded pipeline decided on, which 640x480 result it fused with each, what the actuator
//! sent), a second pass decodes the images of the frames to play. [`ReplayReader`] then yields
//! one timeline: every recorded actuator output before the frame captured after it.
//!
//! Which frames are played, so that a lockstep replay repeats the recorded decisions:
//! - a 320x240 pair only where the recording has a decision on it (the recorded pipeline
//!   skipped the others, and a decision stage that saw more frames would decide differently);
//! - a 640x480 pair only where the recorded fusion used its ranges, and then with the frame id
//!   in [`FrameHeader::replay_hi_frame_id`] of the 320x240 pairs that used it.
//!
//! A recording without `/decisions` (or `/ranges`) plays every pair (every 640x480 pair, and
//! the fusion picks the freshest long-range result as it does live).
//!
//! The JSON layout read here is the one `hvs probe record` writes (docs/probe.md).

use std::collections::{BTreeMap, VecDeque};
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use base64::Engine;
use hvs_shared::messages::{
    ActuatorReport, FrameHeader, FrameSource, HI_HEIGHT, HI_WIDTH, LO_HEIGHT, LO_WIDTH,
    MotionCommand, NO_HI_FRAME, SendReason,
};
use serde::Deserialize;

/// The recording's channels this reader uses.
const LO_LEFT: &str = "/frames/320x240/left";
const LO_RIGHT: &str = "/frames/320x240/right";
const HI_LEFT: &str = "/frames/640x480/left";
const HI_RIGHT: &str = "/frames/640x480/right";
const RANGES: &str = "/ranges";
const DECISIONS: &str = "/decisions";
const ACTUATOR_SENT: &str = "/actuator/sent";

/// Why a recording cannot be replayed.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The file cannot be opened.
    #[error("cannot open recording {path}: {source}")]
    Open {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// The file is not a readable MCAP file (or is cut short inside a record).
    #[error("recording {path} is not a readable MCAP file: {detail}")]
    Mcap {
        /// The file.
        path: PathBuf,
        /// What the MCAP reader said.
        detail: String,
    },
    /// A message does not have the layout `hvs probe record` writes.
    #[error("recording {path}: message {sequence} on {channel} is malformed: {detail}")]
    Message {
        /// The file.
        path: PathBuf,
        /// The channel's topic.
        channel: String,
        /// The message's sequence number.
        sequence: u32,
        /// What is wrong.
        detail: String,
    },
    /// Nothing to play.
    #[error(
        "recording {path} has no complete stereo pair on /frames/320x240 (channels: {channels}); \
         record with `hvs probe record` (default topics) or `hvs run --record`"
    )]
    NoFrames {
        /// The file.
        path: PathBuf,
        /// The channels it has.
        channels: String,
    },
}

/// The `hvs_header` and pixels of a `foxglove.RawImage` message of the recorder.
#[derive(Deserialize)]
struct RawImageJson<'a> {
    width: u32,
    height: u32,
    #[serde(borrow)]
    data: std::borrow::Cow<'a, str>,
    hvs_header: FrameHeaderJson,
}

/// The frame header as `hvs probe echo --json` prints it.
#[derive(Deserialize)]
struct FrameHeaderJson {
    frame_id: u64,
    capture_ns: u64,
    #[serde(default)]
    left_capture_ns: Option<u64>,
    #[serde(default)]
    right_capture_ns: Option<u64>,
    #[serde(default)]
    skew_ns: i64,
}

/// Only the header of an image message (the index pass skips the pixels).
#[derive(Deserialize)]
struct ImageHeaderOnly {
    hvs_header: FrameHeaderJson,
}

#[derive(Deserialize)]
struct FrameIdJson {
    frame_id: u64,
}

#[derive(Deserialize)]
struct RangesJson {
    frame_id: u64,
    hi_frame_id: u64,
}

#[derive(Deserialize)]
struct SentJson {
    seq: u64,
    reason: CodeOrLabel,
    command: CodeOrLabel,
    left_pw: u16,
    right_pw: u16,
    decision_frame_id: u64,
    #[serde(default)]
    decision_capture_ns: u64,
    #[serde(default)]
    decision_published_ns: u64,
    sent_ns: u64,
    bytes_hex: String,
    /// Absent in recordings made before the report carried it: then read from the first
    /// PSC command (`!SC`, channel, ramp, ...).
    #[serde(default)]
    ramp: Option<u8>,
}

/// A code as recorded: a number with its label beside it (current recordings), or the label
/// alone (recordings made before the recordings carried numeric codes).
#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum CodeOrLabel {
    Code(u32),
    Label(String),
}

impl SentJson {
    fn report(&self) -> Result<ActuatorReport, String> {
        let mut bytes = [0u8; 16];
        let hex: Vec<&str> = self.bytes_hex.split_whitespace().collect();
        if hex.len() > bytes.len() {
            return Err(format!("{} bytes, at most 16", hex.len()));
        }
        for (b, h) in bytes.iter_mut().zip(&hex) {
            *b = u8::from_str_radix(h, 16).map_err(|_| format!("bytes_hex {h:?} is not hex"))?;
        }
        let command = match &self.command {
            CodeOrLabel::Code(c) => MotionCommand::try_from_code(*c),
            CodeOrLabel::Label(l) => MotionCommand::from_label(l),
        }
        .ok_or_else(|| format!("unknown command {:?}", self.command))?;
        let reason = match &self.reason {
            CodeOrLabel::Code(c) => SendReason::try_from_code(*c),
            CodeOrLabel::Label(l) => SendReason::from_label(l),
        }
        .ok_or_else(|| format!("unknown reason {:?}", self.reason))?;
        Ok(ActuatorReport {
            seq: self.seq,
            sent_ns: self.sent_ns,
            decision_frame_id: self.decision_frame_id,
            decision_capture_ns: self.decision_capture_ns,
            decision_published_ns: self.decision_published_ns,
            reason: reason as u32,
            command: command as u32,
            left_pw: self.left_pw,
            right_pw: self.right_pw,
            byte_count: hex.len() as u16,
            ramp: self.ramp.unwrap_or(bytes[4]),
            reserved: 0,
            bytes,
        })
    }
}

/// What the recording holds about one frame id.
#[derive(Debug, Default, Clone)]
struct FrameEntry {
    capture_ns: u64,
    /// Bit 0 left, bit 1 right.
    lo_parts: u8,
    hi_parts: u8,
    decided: bool,
    /// The recorded `/ranges` hi_frame_id (0: none fused), if the ranges were recorded.
    fused_hi: Option<u64>,
    /// The recorded fusion used this frame's 640x480 ranges.
    hi_used: bool,
}

/// One frame of the replay plan.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReplayStep {
    /// The recorded frame id (kept: decisions are compared by it).
    pub frame_id: u64,
    /// Recorded capture time, CLOCK_MONOTONIC ns of the recording machine.
    pub capture_ns: u64,
    /// The 320x240 pair is played.
    pub lo: bool,
    /// The 640x480 pair is played.
    pub hi: bool,
    /// [`FrameHeader::replay_hi_frame_id`] for the 320x240 pair.
    pub replay_hi_frame_id: u64,
    /// A lockstep replay waits for the pipeline's 640x480 disparity of this frame (a later
    /// frame fuses it).
    pub wait_for_hi: bool,
}

/// What the index pass found.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ReplaySummary {
    /// Frame ids with a 320x240 and/or 640x480 image in the file.
    pub frames_in_file: usize,
    /// Frames to play (steps).
    pub steps: usize,
    /// 320x240 pairs to play.
    pub lo_pairs: usize,
    /// 640x480 pairs to play.
    pub hi_pairs: usize,
    /// Recorded decisions (0 when `/decisions` was not recorded).
    pub decisions: usize,
    /// Recorded actuator outputs to re-publish.
    pub actuator_sent: usize,
    /// Frames whose recorded fusion used a 640x480 frame the file does not hold: their ranges
    /// (and maybe decisions) cannot be reproduced.
    pub hi_missing: usize,
    /// Decided frames whose 320x240 pair is not (completely) in the file.
    pub lo_missing: usize,
    /// Recorded with `/decisions` (only the decided frames are played).
    pub has_decisions: bool,
    /// Recorded with `/ranges` (the recorded 640x480 fusion is repeated).
    pub has_ranges: bool,
    /// The file ends inside a record (the recorder was killed, the disk pulled): only the
    /// messages before are played. What the MCAP reader said.
    pub truncated: Option<String>,
}

/// The index of a recording: the replay plan and the actuator timeline.
#[derive(Debug, Clone)]
pub struct ReplayIndex {
    path: PathBuf,
    /// Messages readable before the file breaks off (all of them when it is whole).
    readable_messages: u64,
    steps: Vec<ReplayStep>,
    sent: Vec<ActuatorReport>,
    summary: ReplaySummary,
}

fn open_messages(path: &Path) -> Result<mcap::io::MessageReader<BufReader<File>>, ReplayError> {
    let file = File::open(path).map_err(|source| ReplayError::Open {
        path: path.to_path_buf(),
        source,
    })?;
    // A damaged length field must give an error, not a huge allocation (found by the
    // generated bad input of tests/tests/bad_input.rs).
    let options =
        mcap::sans_io::LinearReaderOptions::default().with_record_length_limit(MAX_RECORD_BYTES);
    Ok(mcap::io::MessageReader::new_with_options(
        BufReader::with_capacity(1 << 20, file),
        options,
    ))
}

/// Longest MCAP record accepted: the recorder's chunks are about 4 MiB (a 640x480 image
/// message is 0.4 MB), so 64 MiB is far above anything it writes.
const MAX_RECORD_BYTES: usize = 64 << 20;

/// Checks that `path` can be opened and starts with the MCAP magic (cheap: 8 bytes; `hvs run
/// --replay` calls it before starting any stage).
pub fn check_magic(path: &Path) -> Result<(), ReplayError> {
    let open_error = |source| ReplayError::Open {
        path: path.to_path_buf(),
        source,
    };
    let mut head = [0u8; 8];
    let n = std::io::Read::read(&mut File::open(path).map_err(open_error)?, &mut head)
        .map_err(open_error)?;
    if head[..n] != *mcap::MAGIC {
        return Err(ReplayError::Mcap {
            path: path.to_path_buf(),
            detail: "it does not start with the MCAP magic".to_string(),
        });
    }
    Ok(())
}

fn mcap_error(path: &Path, e: mcap::McapError) -> ReplayError {
    ReplayError::Mcap {
        path: path.to_path_buf(),
        detail: e.to_string(),
    }
}

/// A message that does not have the recorder's layout.
fn malformed(path: &Path, message: &mcap::Message<'_>, detail: String) -> ReplayError {
    ReplayError::Message {
        path: path.to_path_buf(),
        channel: message.channel.topic.clone(),
        sequence: message.sequence,
        detail,
    }
}

fn side_bit(topic: &str) -> u8 {
    if topic.ends_with("/left") { 1 } else { 2 }
}

impl ReplayIndex {
    /// Reads the file once (everything but the pixels) and plans the replay.
    pub fn open(path: &Path) -> Result<Self, ReplayError> {
        check_magic(path)?;
        let mut frames: BTreeMap<u64, FrameEntry> = BTreeMap::new();
        let mut sent = Vec::new();
        let mut channels: BTreeMap<String, u64> = BTreeMap::new();
        let (mut has_decisions, mut has_ranges) = (false, false);
        let mut decisions = 0usize;
        let mut readable_messages = 0u64;
        let mut truncated = None;
        for message in open_messages(path)? {
            let message = match message {
                Ok(m) => m,
                // Cut off after some messages: play those.
                Err(e) if readable_messages > 0 => {
                    truncated = Some(e.to_string());
                    break;
                }
                Err(e) => return Err(mcap_error(path, e)),
            };
            readable_messages += 1;
            let topic = message.channel.topic.as_str();
            *channels.entry(topic.to_string()).or_default() += 1;
            let bad = |detail: String| malformed(path, &message, detail);
            let data = &message.data[..];
            match topic {
                LO_LEFT | LO_RIGHT | HI_LEFT | HI_RIGHT => {
                    let h: ImageHeaderOnly =
                        serde_json::from_slice(data).map_err(|e| bad(e.to_string()))?;
                    let entry = frames.entry(h.hvs_header.frame_id).or_default();
                    entry.capture_ns = h.hvs_header.capture_ns;
                    if topic.starts_with("/frames/320x240") {
                        entry.lo_parts |= side_bit(topic);
                    } else {
                        entry.hi_parts |= side_bit(topic);
                    }
                }
                RANGES => {
                    has_ranges = true;
                    let r: RangesJson =
                        serde_json::from_slice(data).map_err(|e| bad(e.to_string()))?;
                    frames.entry(r.frame_id).or_default().fused_hi = Some(r.hi_frame_id);
                    if r.hi_frame_id != 0 {
                        frames.entry(r.hi_frame_id).or_default().hi_used = true;
                    }
                }
                DECISIONS => {
                    has_decisions = true;
                    decisions += 1;
                    let d: FrameIdJson =
                        serde_json::from_slice(data).map_err(|e| bad(e.to_string()))?;
                    frames.entry(d.frame_id).or_default().decided = true;
                }
                ACTUATOR_SENT => {
                    let s: SentJson =
                        serde_json::from_slice(data).map_err(|e| bad(e.to_string()))?;
                    sent.push(s.report().map_err(bad)?);
                }
                _ => {}
            }
        }
        sent.sort_by_key(|r| r.sent_ns);
        let mut summary = ReplaySummary {
            frames_in_file: frames
                .values()
                .filter(|e| e.lo_parts != 0 || e.hi_parts != 0)
                .count(),
            decisions,
            actuator_sent: sent.len(),
            has_decisions,
            has_ranges,
            truncated,
            ..ReplaySummary::default()
        };
        let hi_complete: Vec<u64> = frames
            .iter()
            .filter(|(_, e)| e.hi_parts == 3)
            .map(|(&id, _)| id)
            .collect();
        let mut steps = Vec::new();
        for (&frame_id, e) in &frames {
            let lo_complete = e.lo_parts == 3;
            let lo = lo_complete && (!has_decisions || e.decided);
            if has_decisions && e.decided && !lo_complete {
                summary.lo_missing += 1;
            }
            let hi = e.hi_parts == 3 && (!has_ranges || e.hi_used);
            let replay_hi_frame_id = match e.fused_hi {
                None => 0,
                Some(0) => NO_HI_FRAME,
                Some(h) if hi_complete.binary_search(&h).is_ok() && h <= frame_id => h,
                Some(_) => {
                    if lo {
                        summary.hi_missing += 1;
                    }
                    NO_HI_FRAME
                }
            };
            if lo || hi {
                steps.push(ReplayStep {
                    frame_id,
                    capture_ns: e.capture_ns,
                    lo,
                    hi,
                    replay_hi_frame_id,
                    wait_for_hi: hi && has_ranges,
                });
            }
        }
        summary.steps = steps.len();
        summary.lo_pairs = steps.iter().filter(|s| s.lo).count();
        summary.hi_pairs = steps.iter().filter(|s| s.hi).count();
        if summary.lo_pairs == 0 {
            return Err(ReplayError::NoFrames {
                path: path.to_path_buf(),
                channels: channels
                    .iter()
                    .map(|(c, n)| format!("{c} ({n})"))
                    .collect::<Vec<_>>()
                    .join(", "),
            });
        }
        Ok(Self {
            path: path.to_path_buf(),
            readable_messages,
            steps,
            sent,
            summary,
        })
    }

    /// What will be played.
    pub fn summary(&self) -> &ReplaySummary {
        &self.summary
    }

    /// The frames to play, in frame-id order.
    pub fn steps(&self) -> &[ReplayStep] {
        &self.steps
    }

    /// The earliest recorded time (first frame or actuator output), CLOCK_MONOTONIC ns of the
    /// recording machine.
    pub fn start_ns(&self) -> u64 {
        let first_frame = self.steps.first().map_or(u64::MAX, |s| s.capture_ns);
        let first_sent = self.sent.first().map_or(u64::MAX, |r| r.sent_ns);
        first_frame.min(first_sent)
    }

    /// Starts the second pass: the timeline with the images decoded.
    pub fn reader(&self) -> Result<ReplayReader<'_>, ReplayError> {
        Ok(ReplayReader {
            index: self,
            messages: open_messages(&self.path)?,
            pending: BTreeMap::new(),
            next_step: 0,
            next_sent: 0,
            messages_read: 0,
            ready: VecDeque::new(),
        })
    }
}

/// A grey stereo pair as recorded.
#[derive(Debug, Clone)]
pub struct ReplayPair {
    /// The recorded header with `source` = replay (times as recorded).
    pub header: FrameHeader,
    /// Left image, row-major.
    pub left: Vec<u8>,
    /// Right image.
    pub right: Vec<u8>,
}

/// One frame of the replay.
#[derive(Debug, Clone)]
pub struct ReplayFrame {
    /// The plan for it.
    pub step: ReplayStep,
    /// The 320x240 pair, if played.
    pub lo: Option<ReplayPair>,
    /// The 640x480 pair, if played.
    pub hi: Option<ReplayPair>,
}

/// The next thing to publish.
#[derive(Debug, Clone)]
pub enum ReplayEvent {
    /// A recorded actuator output (for the decision's dead reckoning).
    Sent(ActuatorReport),
    /// A frame.
    Frame(Box<ReplayFrame>),
}

#[derive(Default)]
struct PendingFrame {
    lo: [Option<Vec<u8>>; 2],
    hi: [Option<Vec<u8>>; 2],
    lo_header: Option<FrameHeader>,
    hi_header: Option<FrameHeader>,
}

/// The second pass: yields the timeline, decoding images as it reads the file.
pub struct ReplayReader<'a> {
    index: &'a ReplayIndex,
    messages: mcap::io::MessageReader<BufReader<File>>,
    /// Frames of the plan whose images are being collected, by step index.
    pending: BTreeMap<usize, PendingFrame>,
    next_step: usize,
    next_sent: usize,
    messages_read: u64,
    ready: VecDeque<ReplayEvent>,
}

impl ReplayReader<'_> {
    fn step_of(&self, frame_id: u64) -> Option<usize> {
        self.index
            .steps
            .binary_search_by_key(&frame_id, |s| s.frame_id)
            .ok()
    }

    /// Adds one image message to its pending frame.
    fn take_image(&mut self, message: &mcap::Message<'_>) -> Result<(), ReplayError> {
        let path = &self.index.path;
        let topic = message.channel.topic.as_str();
        let bad = |detail: String| malformed(path, message, detail);
        let lo = topic.starts_with("/frames/320x240");
        let image: RawImageJson =
            serde_json::from_slice(&message.data).map_err(|e| bad(e.to_string()))?;
        let Some(i) = self.step_of(image.hvs_header.frame_id) else {
            return Ok(());
        };
        let step = self.index.steps[i];
        if (lo && !step.lo) || (!lo && !step.hi) || i < self.next_step {
            return Ok(());
        }
        let (w, h) = if lo {
            (LO_WIDTH, LO_HEIGHT)
        } else {
            (HI_WIDTH, HI_HEIGHT)
        };
        if image.width as usize != w || image.height as usize != h {
            return Err(bad(format!(
                "image {}x{}, expected {w}x{h}",
                image.width, image.height
            )));
        }
        let mut pixels = vec![0u8; w * h];
        let n = base64::engine::general_purpose::STANDARD
            .decode_slice(image.data.as_bytes(), &mut pixels)
            .map_err(|e| bad(format!("image data: {e}")))?;
        if n != w * h {
            return Err(bad(format!("image data has {n} bytes, expected {}", w * h)));
        }
        let j = &image.hvs_header;
        let left_ns = j.left_capture_ns.unwrap_or(j.capture_ns);
        let header = FrameHeader {
            frame_id: j.frame_id,
            capture_ns: j.capture_ns,
            left_capture_ns: left_ns,
            right_capture_ns: j
                .right_capture_ns
                .unwrap_or((left_ns as i64 + j.skew_ns).max(0) as u64),
            skew_ns: j.skew_ns,
            published_ns: 0,
            width: w as u32,
            height: h as u32,
            source: FrameSource::Replay as u32,
            reserved: 0,
            replay_hi_frame_id: if lo { step.replay_hi_frame_id } else { 0 },
        };
        let pending = self.pending.entry(i).or_default();
        let side = usize::from(side_bit(topic) == 2);
        if lo {
            pending.lo[side] = Some(pixels);
            pending.lo_header = Some(header);
        } else {
            pending.hi[side] = Some(pixels);
            pending.hi_header = Some(header);
        }
        Ok(())
    }

    /// Moves the next steps whose images are complete (and the actuator outputs before them)
    /// to `ready`.
    fn release_complete(&mut self) {
        while let Some(&step) = self.index.steps.get(self.next_step) {
            let complete = self.pending.get(&self.next_step).is_some_and(|p| {
                (!step.lo || p.lo.iter().all(Option::is_some))
                    && (!step.hi || p.hi.iter().all(Option::is_some))
            });
            if !complete {
                return;
            }
            let Some(p) = self.pending.remove(&self.next_step) else {
                return;
            };
            self.queue_sent_until(step.capture_ns);
            let pair = |header: Option<FrameHeader>, [l, r]: [Option<Vec<u8>>; 2]| {
                Some(ReplayPair {
                    header: header?,
                    left: l?,
                    right: r?,
                })
            };
            self.ready
                .push_back(ReplayEvent::Frame(Box::new(ReplayFrame {
                    step,
                    lo: pair(p.lo_header, p.lo).filter(|_| step.lo),
                    hi: pair(p.hi_header, p.hi).filter(|_| step.hi),
                })));
            self.next_step += 1;
        }
    }

    fn queue_sent_until(&mut self, time_ns: u64) {
        while let Some(r) = self.index.sent.get(self.next_sent) {
            if r.sent_ns > time_ns {
                break;
            }
            self.ready.push_back(ReplayEvent::Sent(*r));
            self.next_sent += 1;
        }
    }

    /// The next event; `None` at the end.
    pub fn next_event(&mut self) -> Result<Option<ReplayEvent>, ReplayError> {
        loop {
            if let Some(e) = self.ready.pop_front() {
                return Ok(Some(e));
            }
            let next = if self.messages_read < self.index.readable_messages {
                self.messages.next()
            } else {
                None
            };
            match next {
                Some(message) => {
                    self.messages_read += 1;
                    let message = message.map_err(|e| mcap_error(&self.index.path, e))?;
                    if matches!(
                        message.channel.topic.as_str(),
                        LO_LEFT | LO_RIGHT | HI_LEFT | HI_RIGHT
                    ) {
                        self.take_image(&message)?;
                        self.release_complete();
                    }
                }
                None => {
                    // The file changed between the passes: whatever is incomplete is skipped.
                    if self.next_step < self.index.steps.len() {
                        self.pending.remove(&self.next_step);
                        self.next_step += 1;
                        self.release_complete();
                        continue;
                    }
                    self.queue_sent_until(u64::MAX);
                    return Ok(self.ready.pop_front());
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    /// Writes a recording in the recorder's layout: frames 1..=n at 30 Hz, 320x240 and
    /// 640x480 pairs, ranges fusing the 640x480 frame three back, decisions on the odd frames,
    /// an actuator output between frames.
    fn write_recording(path: &Path, n: u64) {
        let file = File::create(path).expect("create");
        let mut w = mcap::WriteOptions::new()
            .compression(None)
            .create(std::io::BufWriter::new(file))
            .expect("writer");
        let schema = w.add_schema("s", "jsonschema", b"{}").expect("schema");
        let meta = BTreeMap::new();
        let mut ch = BTreeMap::new();
        for t in [
            LO_LEFT,
            LO_RIGHT,
            HI_LEFT,
            HI_RIGHT,
            RANGES,
            DECISIONS,
            ACTUATOR_SENT,
        ] {
            ch.insert(t, w.add_channel(schema, t, "json", &meta).expect("ch"));
        }
        let mut seq = 0;
        let mut put = |w: &mut mcap::Writer<_>, t: &str, v: serde_json::Value| {
            seq += 1;
            let header = mcap::records::MessageHeader {
                channel_id: ch[t],
                sequence: seq,
                log_time: seq as u64,
                publish_time: seq as u64,
            };
            w.write_to_known_channel(&header, v.to_string().as_bytes())
                .expect("write");
        };
        let b64 =
            |v: u8, len: usize| base64::engine::general_purpose::STANDARD.encode(vec![v; len]);
        for id in 1..=n {
            let capture_ns = 1_000_000_000 + id * 33_000_000;
            let hdr = json!({"frame_id": id, "capture_ns": capture_ns, "skew_ns": 0});
            for (l, r, wd, ht) in [(LO_LEFT, LO_RIGHT, 320, 240), (HI_LEFT, HI_RIGHT, 640, 480)] {
                for (t, v) in [(l, id as u8), (r, id as u8 + 1)] {
                    put(
                        &mut w,
                        t,
                        json!({"width": wd, "height": ht, "data": b64(v, wd * ht), "hvs_header": hdr}),
                    );
                }
            }
            put(
                &mut w,
                RANGES,
                json!({"frame_id": id, "hi_frame_id": id.saturating_sub(3)}),
            );
            if id % 2 == 1 {
                put(&mut w, DECISIONS, json!({"frame_id": id}));
            }
            put(
                &mut w,
                ACTUATOR_SENT,
                json!({"seq": id, "reason": "decision", "command": "FWD", "left_pw": 800,
                       "right_pw": 700, "decision_frame_id": id, "sent_ns": capture_ns + 20_000_000,
                       "bytes_hex": "21 53 43 00 05 20 03 00"}),
            );
        }
        w.finish().expect("finish");
    }

    #[test]
    fn the_plan_plays_decided_frames_and_the_fused_long_range_frames() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("r.mcap");
        write_recording(&path, 12);
        let index = ReplayIndex::open(&path).expect("index");
        let s = index.summary();
        assert_eq!(s.frames_in_file, 12);
        assert_eq!(s.decisions, 6);
        assert_eq!(s.lo_pairs, 6, "{s:?}");
        // Frames 1..=9 are fused by frames 4..=12.
        assert_eq!(s.hi_pairs, 9, "{s:?}");
        assert_eq!(s.actuator_sent, 12);
        let step5 = index.steps().iter().find(|s| s.frame_id == 5).expect("5");
        assert!(step5.lo && step5.hi && step5.wait_for_hi);
        assert_eq!(step5.replay_hi_frame_id, 2);
        let step1 = index.steps()[0];
        assert_eq!(step1.replay_hi_frame_id, NO_HI_FRAME);
        assert!(
            !index
                .steps()
                .iter()
                .any(|s| s.frame_id == 12 && (s.lo || s.hi))
        );
    }

    #[test]
    fn the_timeline_puts_each_actuator_output_before_the_next_frame_captured_after_it() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("r.mcap");
        write_recording(&path, 8);
        let index = ReplayIndex::open(&path).expect("index");
        let mut reader = index.reader().expect("reader");
        let mut last_time = 0;
        let (mut frames, mut sent) = (0, 0);
        while let Some(e) = reader.next_event().expect("event") {
            match e {
                ReplayEvent::Sent(r) => {
                    assert!(r.sent_ns >= last_time);
                    assert_eq!(
                        (r.left_pw, r.right_pw, r.ramp, r.byte_count),
                        (800, 700, 5, 8)
                    );
                    last_time = r.sent_ns;
                    sent += 1;
                }
                ReplayEvent::Frame(f) => {
                    assert!(f.step.capture_ns >= last_time);
                    last_time = f.step.capture_ns;
                    let id = f.step.frame_id as u8;
                    if let Some(lo) = &f.lo {
                        assert_eq!(lo.left.len(), LO_WIDTH * LO_HEIGHT);
                        assert!(lo.left.iter().all(|&p| p == id));
                        assert!(lo.right.iter().all(|&p| p == id + 1));
                        assert_eq!(lo.header.frame_id, f.step.frame_id);
                        assert_eq!(lo.header.source, FrameSource::Replay as u32);
                        assert_eq!(lo.header.replay_hi_frame_id, f.step.replay_hi_frame_id);
                    }
                    if let Some(hi) = &f.hi {
                        assert_eq!(hi.left.len(), HI_WIDTH * HI_HEIGHT);
                        assert!(hi.right.iter().all(|&p| p == id + 1));
                    }
                    assert_eq!(f.lo.is_some(), f.step.lo);
                    assert_eq!(f.hi.is_some(), f.step.hi);
                    frames += 1;
                }
            }
        }
        assert_eq!(frames, index.summary().steps);
        assert_eq!(sent, 8);
    }

    #[test]
    fn a_recording_cut_off_mid_record_plays_up_to_the_break() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("r.mcap");
        write_recording(&path, 12);
        let whole = std::fs::read(&path).expect("read");
        let cut = dir.path().join("cut.mcap");
        // Unchunked: the cut lands inside a late message record.
        std::fs::write(&cut, &whole[..whole.len() * 3 / 4]).expect("write");
        let index = ReplayIndex::open(&cut).expect("a cut-off file still plays");
        let s = index.summary().clone();
        assert!(s.truncated.is_some(), "{s:?}");
        assert!(s.lo_pairs > 0 && s.lo_pairs < 6, "{s:?}");
        let mut reader = index.reader().expect("reader");
        let mut frames = 0;
        while let Some(e) = reader.next_event().expect("no error past the break") {
            if let ReplayEvent::Frame(_) = e {
                frames += 1;
            }
        }
        assert_eq!(frames, s.steps);
    }

    #[test]
    fn a_file_that_is_not_mcap_gets_an_error_naming_it() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("not.mcap");
        std::fs::write(&path, b"this is not an mcap file at all").expect("write");
        let e = ReplayIndex::open(&path).expect_err("not mcap");
        let text = e.to_string();
        assert!(
            text.contains("not.mcap") && text.contains("not a readable MCAP"),
            "{text}"
        );
        let e = ReplayIndex::open(&dir.path().join("missing.mcap")).expect_err("missing");
        assert!(e.to_string().contains("cannot open recording"), "{e}");
    }

    /// A recording of one message on `topic`.
    fn one_message_file(path: &Path, topic: &str, sequence: u32, data: &[u8]) {
        let file = File::create(path).expect("create");
        let mut w = mcap::WriteOptions::new()
            .create(std::io::BufWriter::new(file))
            .expect("writer");
        let schema = w.add_schema("s", "jsonschema", b"{}").expect("schema");
        let channel_id = w
            .add_channel(schema, topic, "json", &BTreeMap::new())
            .expect("ch");
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence,
            log_time: 1,
            publish_time: 1,
        };
        w.write_to_known_channel(&header, data).expect("write");
        w.finish().expect("finish");
    }

    #[test]
    fn a_recording_without_frames_says_what_it_holds() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("empty.mcap");
        one_message_file(&path, DECISIONS, 1, br#"{"frame_id": 3}"#);
        let e = ReplayIndex::open(&path).expect_err("no frames");
        assert!(e.to_string().contains("/decisions (1)"), "{e}");
    }

    #[test]
    fn a_malformed_message_is_named_by_channel_and_sequence() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("bad.mcap");
        one_message_file(&path, ACTUATOR_SENT, 7, br#"{"seq": 1}"#);
        let e = ReplayIndex::open(&path).expect_err("malformed");
        let text = e.to_string();
        assert!(
            text.contains("message 7 on /actuator/sent is malformed"),
            "{text}"
        );
    }
}
