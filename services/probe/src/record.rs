//! `hvs probe record`: topics of a running pipeline into an MCAP file (the `mcap` crate).
//!
//! Every channel is JSON-encoded with a JSON schema, which Foxglove and Lichtblick open
//! without plugins: each stereo pair becomes two `foxglove.RawImage` messages (`mono8`,
//! base64 data, as the schema's `contentEncoding` says) on `/<topic>/left` and
//! `/<topic>/right`, each carrying the pair's hvs frame header under `hvs_header`; ranges,
//! decisions and actuator output are their `hvs probe echo --json` objects. Log times are
//! wall-clock (CLOCK_REALTIME) ns; the payloads keep their CLOCK_MONOTONIC stamps.
//!
//! Nothing is dropped silently: samples a subscriber lost (a gap in the payload's sequence
//! numbers: the recorder fell behind) are counted per topic, written to the file's
//! `hvs.recording` metadata record and printed at the end. A full disk (or any write error)
//! ends the recording with a readable file: the data section is cut back to the last chunk
//! that was written whole (the writer flushes a chunk every second) and closed with the
//! metadata, a DataEnd and a Footer record, written by hand because the `mcap` writer cannot
//! go on after a failed write. A small reserve file made at the start and deleted then leaves
//! room for them.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use hvs_runtime::clock::{WallClock, monotonic_ns};
use hvs_runtime::config::CameraConfig;
use hvs_runtime::error_chain;
use hvs_runtime::ipc::{ReceiveError, TopicSubscriber};
use hvs_shared::messages::{
    ActuatorReport, Decision, FrameHeader, RangeReport, RobotPose, StereoFrame320x240,
    StereoFrame640x480, StereoPayload,
};
use hvs_shared::topics::{Topic, TopicByPath};
use serde_json::{Value, json};

use crate::attach::{AttachError, Payload, Probe, resolve_topic};
use crate::schemas::{
    CAMERA_CALIBRATION_SCHEMA, CAMERA_FRAME, FRAME_TRANSFORMS_SCHEMA, FoxgloveJson, Pinhole,
    calibration_json, pose_transforms, transforms_json,
};

/// Topics recorded when none are named.
pub const DEFAULT_TOPICS: [&str; 6] = [
    "frames/320x240",
    "frames/640x480",
    "ranges",
    "decisions",
    "actuator/sent",
    "decision/pose",
];

/// Name of the metadata record with the counts.
pub const METADATA_NAME: &str = "hvs.recording";

/// Bytes kept free for closing the file after a full disk.
const RESERVE_BYTES: usize = 256 * 1024;

/// JSON schema of `foxglove.RawImage` (the fields hvs fills).
const RAW_IMAGE_SCHEMA: &str = r#"{"title":"foxglove.RawImage","type":"object","properties":{"timestamp":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}},"frame_id":{"type":"string"},"width":{"type":"integer","minimum":0},"height":{"type":"integer","minimum":0},"encoding":{"type":"string"},"step":{"type":"integer","minimum":0},"data":{"type":"string","contentEncoding":"base64"}}}"#;

/// Options of `hvs probe record`.
#[derive(Debug, Clone)]
pub struct RecordOptions {
    /// Output file.
    pub out: PathBuf,
    /// Topic paths (empty: [`DEFAULT_TOPICS`]).
    pub topics: Vec<String>,
    /// Stop after this long (`None`: until interrupted).
    pub duration: Option<Duration>,
    /// Create the topics if the pipeline has not yet (`hvs run --record` starts the recorder
    /// before the stages, so the recording holds the first frame and every actuator output).
    pub create_topics: bool,
    /// Created once every topic is subscribed (`hvs run --record` waits for it).
    pub ready_file: Option<PathBuf>,
    /// The camera, for the calibration and camera transform written beside the images
    /// (`None`: neither is recorded).
    pub camera: Option<CameraConfig>,
}

/// What a recording holds, per topic.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct TopicCounts {
    /// Samples written.
    pub written: u64,
    /// Samples lost before the recorder read them (sequence gaps).
    pub dropped: u64,
    /// Samples read but lost with the last, unfinished chunk when a write error (a full
    /// disk) cut the recording short.
    pub lost_at_end: u64,
}

/// The outcome of a recording.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RecordSummary {
    /// Output file.
    pub out: PathBuf,
    /// Counts per topic path.
    pub topics: BTreeMap<String, TopicCounts>,
    /// Bytes in the file.
    pub bytes: u64,
    /// Seconds recorded.
    pub duration_s: f64,
    /// Why it ended early (a write error such as a full disk), if it did.
    pub cut_short: Option<String>,
}

impl RecordSummary {
    /// Samples lost over all topics.
    pub fn dropped(&self) -> u64 {
        self.topics.values().map(|c| c.dropped).sum()
    }
}

/// Why `hvs probe record` failed.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// Attaching failed.
    #[error(transparent)]
    Attach(#[from] AttachError),
    /// The topic holds what a recording does not take (disparity maps, heartbeats...).
    #[error("topic {topic:?} cannot be recorded; recordable topics: {known}")]
    NotRecordable {
        /// The topic path.
        topic: String,
        /// Recordable paths.
        known: String,
    },
    /// The output file could not be created or started.
    #[error("cannot create the recording {}: {detail}", path.display())]
    Create {
        /// The file.
        path: PathBuf,
        /// The reason.
        detail: String,
    },
    /// Receiving failed.
    #[error("recording topic {topic}")]
    Receive {
        /// The topic path.
        topic: String,
        /// The receive error.
        #[source]
        source: ReceiveError,
    },
    /// Closing the file failed after a write error; the file may be unreadable.
    #[error("cannot close the recording {} after a write error ({cause}): {detail}", path.display())]
    Close {
        /// The file.
        path: PathBuf,
        /// The write error that ended the recording.
        cause: String,
        /// Why closing failed.
        detail: String,
    },
}

/// The file under the MCAP writer: counts the bytes written so the recording can be cut
/// back to the last whole chunk.
struct CountingFile {
    file: File,
    /// Position in the file, shared with the recorder (the writer owns the file).
    pos: Arc<AtomicU64>,
}

impl Write for CountingFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.file.write(buf)?;
        self.pos.fetch_add(n as u64, Ordering::Relaxed);
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.file.flush()
    }
}

impl Seek for CountingFile {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        let pos = self.file.seek(to)?;
        self.pos.store(pos, Ordering::Relaxed);
        Ok(pos)
    }
}

/// A payload type a recording takes.
pub trait Recordable: Payload {
    /// Stereo frames: recorded as two images.
    const STEREO: bool = false;
    /// The pair's header and images, for stereo frames.
    fn stereo(&self) -> Option<(&FrameHeader, &[u8], &[u8])> {
        None
    }
    /// Schema name and JSON schema of the message channel (not for stereo frames).
    fn schema() -> (&'static str, Value) {
        ("hvs.Message", json!({"type": "object"}))
    }
    /// The message as recorded (not for stereo frames).
    fn record_json(&self) -> Value {
        self.describe_json()
    }
    /// Frame transforms recorded on `/tf` beside the message, stamped `stamp_ns` (poses
    /// only).
    fn transforms(&self, _camera: &CameraConfig, _stamp_ns: u64) -> Option<Value> {
        None
    }
}

/// The live view's JSON and schema (`crate::schemas`), so that both look the same; the
/// braces hold any further methods of the type.
macro_rules! recordable_as_foxglove_json {
    ($t:ty { $($more:item)* }) => {
        impl Recordable for $t {
            fn schema() -> (&'static str, Value) {
                (<$t as FoxgloveJson>::SCHEMA_NAME, <$t as FoxgloveJson>::json_schema())
            }
            fn record_json(&self) -> Value {
                self.to_foxglove_json()
            }
            $($more)*
        }
    };
}

impl Recordable for StereoFrame320x240 {
    const STEREO: bool = true;
    fn stereo(&self) -> Option<(&FrameHeader, &[u8], &[u8])> {
        Some(self.parts())
    }
}

impl Recordable for StereoFrame640x480 {
    const STEREO: bool = true;
    fn stereo(&self) -> Option<(&FrameHeader, &[u8], &[u8])> {
        Some(self.parts())
    }
}

recordable_as_foxglove_json!(RangeReport {});
recordable_as_foxglove_json!(Decision {});
recordable_as_foxglove_json!(ActuatorReport {});
recordable_as_foxglove_json!(RobotPose {
    fn transforms(&self, camera: &CameraConfig, stamp_ns: u64) -> Option<Value> {
        Some(transforms_json(&pose_transforms(self, camera), stamp_ns))
    }
});

/// One recorded topic: its subscriber and channel ids.
trait Source {
    fn path(&self) -> &str;
    /// Writes what arrived; returns how many samples.
    fn drain(&mut self, sink: &mut Sink) -> Result<u64, Drained>;
    fn dropped(&self) -> u64;
}

enum Drained {
    Receive(ReceiveError),
    Write(String),
}

struct TopicSource<T: Recordable> {
    path: String,
    sub: TopicSubscriber<T>,
    channels: Vec<u16>,
    /// `/tf` and the camera, for poses.
    transforms: Option<(u16, CameraConfig)>,
}

impl<T: Recordable> Source for TopicSource<T> {
    fn path(&self) -> &str {
        &self.path
    }

    fn drain(&mut self, sink: &mut Sink) -> Result<u64, Drained> {
        let mut n = 0;
        while let Some(sample) = self.sub.receive().map_err(Drained::Receive)? {
            let p = sample.payload();
            match p.stereo() {
                Some((header, left, right)) => {
                    let log_ns = sink.wall_ns(header.capture_ns);
                    let hvs = p.describe_json();
                    for (channel, side, pixels) in [
                        (self.channels[0], "left", left),
                        (self.channels[1], "right", right),
                    ] {
                        let msg = raw_image(header, side, pixels, log_ns, &hvs);
                        sink.write(channel, log_ns, &msg)?;
                    }
                }
                None => {
                    let log_ns = sink.wall_ns(p.stamp_ns().unwrap_or_else(monotonic_ns));
                    let msg = p.record_json().to_string();
                    sink.write(self.channels[0], log_ns, msg.as_bytes())?;
                    if let Some((channel, camera)) = &self.transforms
                        && let Some(tf) = p.transforms(camera, log_ns)
                    {
                        sink.write(*channel, log_ns, tf.to_string().as_bytes())?;
                    }
                }
            }
            n += 1;
        }
        Ok(n)
    }

    fn dropped(&self) -> u64 {
        self.sub.dropped()
    }
}

/// A `foxglove.RawImage` JSON message of one image of a pair.
fn raw_image(header: &FrameHeader, side: &str, pixels: &[u8], log_ns: u64, hvs: &Value) -> Vec<u8> {
    use base64::Engine;
    json!({
        "timestamp": {"sec": log_ns / 1_000_000_000, "nsec": log_ns % 1_000_000_000},
        "frame_id": if side == "left" { CAMERA_FRAME.to_string() } else { format!("{CAMERA_FRAME}_{side}") },
        "width": header.width,
        "height": header.height,
        "encoding": "mono8",
        "step": header.width,
        "data": base64::engine::general_purpose::STANDARD.encode(pixels),
        "hvs_header": hvs,
    })
    .to_string()
    .into_bytes()
}

/// The MCAP writer and the bookkeeping for a clean end.
struct Sink {
    writer: mcap::Writer<CountingFile>,
    /// The last sequence number per channel (each channel counts its own messages).
    sequences: BTreeMap<u16, u32>,
    /// Log times are wall-clock.
    wall: WallClock,
}

impl Sink {
    fn wall_ns(&self, monotonic_ns: u64) -> u64 {
        self.wall.wall_ns(monotonic_ns)
    }

    fn write(&mut self, channel: u16, log_ns: u64, data: &[u8]) -> Result<(), Drained> {
        let sequence = self.sequences.entry(channel).or_insert(0);
        *sequence = sequence.wrapping_add(1);
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: *sequence,
            log_time: log_ns,
            publish_time: log_ns,
        };
        self.writer
            .write_to_known_channel(&header, data)
            .map_err(|e| Drained::Write(error_chain(&e)))
    }
}

/// Topic of the frame transforms (world -> robot -> camera) beside `decision/pose`.
pub const TRANSFORMS_TOPIC: &str = "/tf";
/// Topic of the left camera's calibration at 320x240 (`/camera/calibration/640x480` at
/// 640x480).
pub const CALIBRATION_TOPIC: &str = "/camera/calibration";

/// Adds the calibration channel of each recorded image size.
fn add_calibration(
    writer: &mut mcap::Writer<CountingFile>,
    camera: &CameraConfig,
    paths: &[String],
) -> Result<Vec<(u16, Pinhole)>, mcap::McapError> {
    let schema = writer.add_schema(
        "foxglove.CameraCalibration",
        "jsonschema",
        CAMERA_CALIBRATION_SCHEMA.as_bytes(),
    )?;
    let mut out = Vec::new();
    for (path, topic, w, h) in [
        ("frames/320x240", CALIBRATION_TOPIC.to_string(), 320, 240),
        (
            "frames/640x480",
            format!("{CALIBRATION_TOPIC}/640x480"),
            640,
            480,
        ),
    ] {
        if paths.iter().any(|p| p == path) {
            let id = writer.add_channel(schema, &topic, "json", &BTreeMap::new())?;
            out.push((id, Pinhole::of(camera, w, h)));
        }
    }
    Ok(out)
}

/// Subscribes to one topic and adds its channels.
fn open_source<T: Recordable>(
    topic: &'static Topic<T>,
    probe: &Probe,
    path: &str,
    writer: &mut mcap::Writer<CountingFile>,
    create_topics: bool,
    camera: Option<&CameraConfig>,
    create: &dyn Fn(String) -> RecordError,
) -> Result<Box<dyn Source>, RecordError> {
    let sub = if create_topics {
        probe
            .node
            .subscriber(topic, topic.max_buffer)
            .map_err(|source| AttachError::Subscribe {
                instance: probe.instance().to_string(),
                topic: path.to_string(),
                source,
            })?
    } else {
        probe.subscribe(topic, None, path, topic.max_buffer)?
    };
    let no_meta = BTreeMap::new();
    let mcap_err = |e: mcap::McapError| create(e.to_string());
    let channels = if T::STEREO {
        let schema = writer
            .add_schema(
                "foxglove.RawImage",
                "jsonschema",
                RAW_IMAGE_SCHEMA.as_bytes(),
            )
            .map_err(mcap_err)?;
        let mut ids = Vec::new();
        for side in ["left", "right"] {
            ids.push(
                writer
                    .add_channel(schema, &format!("/{path}/{side}"), "json", &no_meta)
                    .map_err(mcap_err)?,
            );
        }
        ids
    } else {
        let (name, json_schema) = T::schema();
        let schema = writer
            .add_schema(name, "jsonschema", json_schema.to_string().as_bytes())
            .map_err(mcap_err)?;
        vec![
            writer
                .add_channel(schema, &format!("/{path}"), "json", &no_meta)
                .map_err(mcap_err)?,
        ]
    };
    let transforms = match camera {
        Some(camera) if path == hvs_shared::topics::DECISION_POSE.path => {
            let schema = writer
                .add_schema(
                    "foxglove.FrameTransforms",
                    "jsonschema",
                    FRAME_TRANSFORMS_SCHEMA.as_bytes(),
                )
                .map_err(mcap_err)?;
            let id = writer
                .add_channel(schema, TRANSFORMS_TOPIC, "json", &no_meta)
                .map_err(mcap_err)?;
            Some((id, camera.clone()))
        }
        _ => None,
    };
    Ok(Box::new(TopicSource {
        path: path.to_string(),
        sub,
        channels,
        transforms,
    }))
}

/// `hvs probe record`: records until the duration is over or the process is interrupted;
/// `progress` gets a status line every second.
pub fn record(
    probe: &Probe,
    opts: &RecordOptions,
    progress: &mut dyn Write,
) -> Result<RecordSummary, RecordError> {
    let paths: Vec<String> = if opts.topics.is_empty() {
        DEFAULT_TOPICS.iter().map(|s| s.to_string()).collect()
    } else {
        opts.topics.clone()
    };
    let not_recordable = |path: &str| RecordError::NotRecordable {
        topic: path.to_string(),
        known: DEFAULT_TOPICS.join(", "),
    };
    // Every topic checked before the file is created.
    let mut resolved = Vec::new();
    for path in &paths {
        let by = resolve_topic(path)?;
        if !DEFAULT_TOPICS.contains(&path.as_str()) {
            return Err(not_recordable(path));
        }
        resolved.push((path, by));
    }
    let out = opts.out.clone();
    let create = |detail: String| RecordError::Create {
        path: out.clone(),
        detail,
    };
    let reserve_path = reserve_path(&out);
    if let Err(e) = std::fs::write(&reserve_path, vec![0u8; RESERVE_BYTES]) {
        tracing::debug!("no reserve file next to the recording: {e}");
    }
    let file = File::create(&out).map_err(|e| create(e.to_string()))?;
    let options = mcap::WriteOptions::new()
        .profile("")
        .library(format!("hvs {}", env!("CARGO_PKG_VERSION")))
        .compression(Some(mcap::Compression::Zstd))
        .compression_level(1)
        .chunk_size(Some(4 * 1024 * 1024));
    let pos = Arc::new(AtomicU64::new(0));
    let mut writer = options
        .create(CountingFile {
            file,
            pos: Arc::clone(&pos),
        })
        .map_err(|e| create(e.to_string()))?;
    let camera = opts.camera.as_ref();
    let mut sources = Vec::new();
    for (path, by) in resolved {
        // Every recordable topic is opened the same way; only its payload type differs.
        macro_rules! open {
            ($t:expr) => {
                open_source(
                    $t,
                    probe,
                    path,
                    &mut writer,
                    opts.create_topics,
                    camera,
                    &create,
                )
            };
        }
        let source = match by {
            TopicByPath::StereoFrame320x240(t) => open!(t),
            TopicByPath::StereoFrame640x480(t) => open!(t),
            TopicByPath::RangeReport(t) => open!(t),
            TopicByPath::Decision(t) => open!(t),
            TopicByPath::ActuatorReport(t) => open!(t),
            TopicByPath::RobotPose(t) => open!(t),
            _ => Err(not_recordable(path)),
        };
        sources.push(source?);
    }
    let calibration = match camera {
        Some(camera) => {
            Some(add_calibration(&mut writer, camera, &paths).map_err(|e| create(e.to_string()))?)
        }
        None => None,
    };
    // The header and channels on disk first: a recording cut short keeps them.
    writer.flush().map_err(|e| create(e.to_string()))?;
    if let Some(ready) = &opts.ready_file {
        std::fs::write(ready, b"").map_err(|e| {
            create(format!(
                "cannot create the ready file {}: {e}",
                ready.display()
            ))
        })?;
    }
    let mut good_len = pos.load(Ordering::Relaxed);
    let mut sink = Sink {
        writer,
        sequences: BTreeMap::new(),
        wall: WallClock::now(),
    };
    let mut counts: BTreeMap<String, TopicCounts> = paths
        .iter()
        .map(|p| (p.clone(), TopicCounts::default()))
        .collect();
    let mut flushed = counts.clone();
    let start = Instant::now();
    let mut last_flush = Instant::now();
    let mut last_calibration: Option<Instant> = None;
    let mut cut_short: Option<String> = None;
    let mut interrupted = false;
    'record: loop {
        // One more pass after the end is asked for: what was published before it is kept.
        let ending = interrupted
            || opts.duration.is_some_and(|d| start.elapsed() >= d)
            || probe.termination_requested();
        let mut got = 0;
        for source in &mut sources {
            match source.drain(&mut sink) {
                Ok(n) => {
                    got += n;
                    if let Some(c) = counts.get_mut(source.path()) {
                        c.written += n;
                        c.dropped = source.dropped();
                    }
                }
                Err(Drained::Receive(e)) => {
                    return Err(RecordError::Receive {
                        topic: source.path().to_string(),
                        source: e,
                    });
                }
                Err(Drained::Write(e)) => {
                    cut_short = Some(e);
                    break 'record;
                }
            }
        }
        if let Some(cals) = &calibration
            && last_calibration.is_none_or(|t| t.elapsed() >= Duration::from_secs(1))
        {
            // Once a second, so that a player that seeks finds one nearby.
            last_calibration = Some(Instant::now());
            let log_ns = sink.wall_ns(monotonic_ns());
            for (channel, pinhole) in cals {
                let msg = calibration_json(pinhole, log_ns).to_string();
                if let Err(e) = sink.write(*channel, log_ns, msg.as_bytes()) {
                    cut_short = Some(match e {
                        Drained::Write(e) => e,
                        Drained::Receive(e) => error_chain(&e),
                    });
                    break 'record;
                }
            }
        }
        if last_flush.elapsed() >= Duration::from_secs(1) {
            last_flush = Instant::now();
            if let Err(e) = sink.writer.flush() {
                cut_short = Some(error_chain(&e));
                break 'record;
            }
            good_len = pos.load(Ordering::Relaxed);
            flushed = counts.clone();
            let _ = writeln!(
                progress,
                "recording {}: {:.0} s, {} messages, {:.1} MB, {} dropped",
                opts.out.display(),
                start.elapsed().as_secs_f64(),
                counts.values().map(|c| c.written).sum::<u64>(),
                good_len as f64 / 1e6,
                counts.values().map(|c| c.dropped).sum::<u64>(),
            );
        }
        if ending {
            break;
        }
        if got == 0 && !probe.node.sleep(Duration::from_millis(2)) {
            // Interrupted (the node reports a signal once): the next pass is the last.
            interrupted = true;
        }
    }
    let duration_s = start.elapsed().as_secs_f64();
    let _ = std::fs::remove_file(&reserve_path);
    let Sink { mut writer, .. } = sink;
    let finished = match &cut_short {
        None => writer
            .write_metadata(&mcap::records::Metadata {
                name: METADATA_NAME.to_string(),
                metadata: recording_metadata(probe.instance(), duration_s, &counts, None),
            })
            .and_then(|()| writer.finish().map(|_| ()))
            .map_err(|e| error_chain(&e)),
        Some(cause) => Err(cause.clone()),
    };
    let bytes = match finished {
        Ok(()) => file_len(&opts.out),
        Err(cause) => {
            keep_flushed(&mut counts, &flushed);
            let metadata = recording_metadata(probe.instance(), duration_s, &counts, Some(&cause));
            let bytes = close_cut_short(writer, &opts.out, good_len, &metadata, &cause)?;
            cut_short = Some(cause);
            bytes
        }
    };
    Ok(RecordSummary {
        out: opts.out.clone(),
        topics: counts,
        bytes,
        duration_s,
        cut_short,
    })
}

/// The `hvs.recording` metadata record's entries.
fn recording_metadata(
    instance: &str,
    duration_s: f64,
    counts: &BTreeMap<String, TopicCounts>,
    cut_short: Option<&str>,
) -> BTreeMap<String, String> {
    let mut metadata = BTreeMap::new();
    metadata.insert("instance".to_string(), instance.to_string());
    metadata.insert("duration_s".to_string(), format!("{duration_s:.3}"));
    for (path, c) in counts {
        metadata.insert(format!("written.{path}"), c.written.to_string());
        metadata.insert(format!("dropped.{path}"), c.dropped.to_string());
        metadata.insert(format!("lost_at_end.{path}"), c.lost_at_end.to_string());
    }
    if let Some(cause) = cut_short {
        metadata.insert("cut_short".to_string(), cause.to_string());
    }
    metadata
}

/// After a write error only the samples of whole chunks are in the file: the rest count as
/// lost at the end.
fn keep_flushed(
    counts: &mut BTreeMap<String, TopicCounts>,
    flushed: &BTreeMap<String, TopicCounts>,
) {
    for (path, c) in counts.iter_mut() {
        let kept = flushed.get(path).map_or(0, |f| f.written);
        c.lost_at_end = c.written.saturating_sub(kept);
        c.written = kept;
    }
}

fn file_len(path: &Path) -> u64 {
    std::fs::metadata(path).map(|m| m.len()).unwrap_or(0)
}

fn reserve_path(out: &Path) -> PathBuf {
    let mut name = out
        .file_name()
        .map(|n| n.to_os_string())
        .unwrap_or_default();
    name.push(".reserve");
    out.with_file_name(name)
}

/// Ends a recording after a write error: cuts the file back to `good_len` (the end of the
/// last whole chunk) and appends the metadata, DataEnd and Footer records and the magic.
fn close_cut_short(
    writer: mcap::Writer<CountingFile>,
    path: &Path,
    good_len: u64,
    metadata: &BTreeMap<String, String>,
    cause: &str,
) -> Result<u64, RecordError> {
    let close = |detail: String| RecordError::Close {
        path: path.to_path_buf(),
        cause: cause.to_string(),
        detail,
    };
    // `into_inner` hands the file back without writing a summary.
    let mut file = writer.into_inner().file;
    file.set_len(good_len).map_err(|e| close(e.to_string()))?;
    file.seek(SeekFrom::Start(good_len))
        .map_err(|e| close(e.to_string()))?;
    let tail = closing_records(metadata);
    file.write_all(&tail).map_err(|e| close(e.to_string()))?;
    file.sync_all().map_err(|e| close(e.to_string()))?;
    Ok(good_len + tail.len() as u64)
}

/// MCAP magic bytes.
const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// Metadata, DataEnd (no CRC), Footer (no summary) and the closing magic, per the MCAP spec.
fn closing_records(metadata: &BTreeMap<String, String>) -> Vec<u8> {
    fn string(out: &mut Vec<u8>, s: &str) {
        out.extend_from_slice(&(s.len() as u32).to_le_bytes());
        out.extend_from_slice(s.as_bytes());
    }
    fn record(out: &mut Vec<u8>, op: u8, body: &[u8]) {
        out.push(op);
        out.extend_from_slice(&(body.len() as u64).to_le_bytes());
        out.extend_from_slice(body);
    }
    let mut map = Vec::new();
    for (k, v) in metadata {
        string(&mut map, k);
        string(&mut map, v);
    }
    let mut body = Vec::new();
    string(&mut body, METADATA_NAME);
    body.extend_from_slice(&(map.len() as u32).to_le_bytes());
    body.extend_from_slice(&map);
    let mut out = Vec::new();
    record(&mut out, 0x0C, &body);
    record(&mut out, 0x0F, &0u32.to_le_bytes());
    record(&mut out, 0x02, &[0u8; 20]);
    out.extend_from_slice(MAGIC);
    out
}

/// Reads the `hvs.recording` metadata of a recording.
pub fn read_metadata(bytes: &[u8]) -> Result<BTreeMap<String, String>, String> {
    for record in mcap::read::LinearReader::new(bytes).map_err(|e| e.to_string())? {
        if let mcap::records::Record::Metadata(m) = record.map_err(|e| e.to_string())?
            && m.name == METADATA_NAME
        {
            return Ok(m.metadata);
        }
    }
    Err(format!("no {METADATA_NAME} metadata record"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closing_records_make_a_readable_file_after_the_header() {
        // A file cut back to its header (as after a full disk before the first chunk) and
        // closed by hand reads back with its metadata.
        let mut buf = std::io::Cursor::new(Vec::new());
        {
            let mut w = mcap::WriteOptions::new().create(&mut buf).expect("writer");
            w.flush().expect("flush");
            let _ = w.into_inner();
        }
        let mut bytes = buf.into_inner();
        let mut meta = BTreeMap::new();
        meta.insert("dropped.decisions".to_string(), "3".to_string());
        bytes.extend_from_slice(&closing_records(&meta));
        assert_eq!(read_metadata(&bytes).expect("metadata"), meta);
        assert!(
            mcap::MessageStream::new(&bytes)
                .expect("stream")
                .all(|m| m.is_ok())
        );
    }

    #[test]
    fn raw_images_follow_the_foxglove_schema() {
        let header = FrameHeader {
            frame_id: 7,
            width: 4,
            height: 2,
            ..FrameHeader::default()
        };
        let msg = raw_image(
            &header,
            "left",
            &[1, 2, 3, 4, 5, 6, 7, 8],
            1_500_000_000,
            &json!({}),
        );
        let v: Value = serde_json::from_slice(&msg).expect("json");
        assert_eq!(v["encoding"], "mono8");
        assert_eq!(v["step"], 4);
        assert_eq!(v["timestamp"]["sec"], 1);
        assert_eq!(v["timestamp"]["nsec"], 500_000_000);
        assert_eq!(v["data"], "AQIDBAUGBwg=");
        let schema: Value = serde_json::from_str(RAW_IMAGE_SCHEMA).expect("schema");
        for key in v.as_object().expect("object").keys() {
            assert!(
                key == "hvs_header" || schema["properties"].get(key).is_some(),
                "{key} not in the schema"
            );
        }
    }
}
