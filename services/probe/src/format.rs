//! Readable text and JSON of every payload type (pure logic, no IPC): what `hvs probe echo`
//! prints. Images are summarised by their headers, never dumped.

use hvs_shared::messages::{
    ActuatorReport, ControlCommand, ControlRequest, Decision, DisparityHeader, DisparityMap320x240,
    DisparityMap640x480, FrameHeader, FrameSource, IntersectionType, LogLevel, LogLine,
    MotionCommand, NavMap, RangeReport, RangeSource, RangeWindow, RobotPose, RowAlignState,
    SendReason, SimTruth, StageHealth, StageHeartbeat, StageState, StereoAlgorithm,
    StereoFrame320x240, StereoFrame640x480, SupervisorStatus, decode_name,
};
use serde_json::{Value, json};

/// A payload that `hvs probe echo` can print.
pub trait Describe {
    /// One human-readable line (several for tables such as the supervisor status).
    fn describe_text(&self) -> String;
    /// The same content as a JSON object (one line per sample with `--json`).
    fn describe_json(&self) -> Value;
    /// Publication time (CLOCK_MONOTONIC ns) when the payload carries one. Rates are measured
    /// on it rather than on arrival at the probe, so the probe's own scheduling (several
    /// samples taken in one wake-up) does not skew the periods.
    fn stamp_ns(&self) -> Option<u64> {
        None
    }
}

/// A payload's time stamp, `None` when unset (0).
fn stamp(ns: u64) -> Option<u64> {
    (ns != 0).then_some(ns)
}

fn ms(ns: u64) -> f64 {
    ns as f64 / 1e6
}

/// Milliseconds from `from_ns` to `to_ns` (0 when either is unset or they are out of order).
fn span_ms(from_ns: u64, to_ns: u64) -> f64 {
    if from_ns == 0 || to_ns < from_ns {
        0.0
    } else {
        ms(to_ns - from_ns)
    }
}

fn source_label(code: u32) -> &'static str {
    FrameSource::from_code(code).map_or("?", FrameSource::label)
}

fn frame_text(h: &FrameHeader) -> String {
    format!(
        "frame {} {}x{} source {} skew {:+.2} ms capture->publish {:.2} ms",
        h.frame_id,
        h.width,
        h.height,
        source_label(h.source),
        h.skew_ns as f64 / 1e6,
        span_ms(h.capture_ns, h.published_ns)
    )
}

fn frame_json(h: &FrameHeader) -> Value {
    json!({
        "frame_id": h.frame_id,
        "width": h.width,
        "height": h.height,
        "source": source_label(h.source),
        "capture_ns": h.capture_ns,
        "left_capture_ns": h.left_capture_ns,
        "right_capture_ns": h.right_capture_ns,
        "published_ns": h.published_ns,
        "skew_ns": h.skew_ns,
        "capture_to_publish_ms": span_ms(h.capture_ns, h.published_ns),
    })
}

fn algorithm_label(code: u32) -> &'static str {
    StereoAlgorithm::from_code(code).map_or("?", StereoAlgorithm::label)
}

fn disparity_text(h: &DisparityHeader) -> String {
    let pixels = (h.width as f64 * h.height as f64).max(1.0);
    format!(
        "disparity {} {}x{} {} d {}..{} px valid {:.1}% compute {:.2} ms capture->publish {:.2} ms rows {:+.2} px {}",
        h.frame_id,
        h.width,
        h.height,
        algorithm_label(h.algorithm),
        h.min_disp,
        h.max_disp,
        100.0 * h.valid_px as f64 / pixels,
        ms(h.compute_ns),
        span_ms(h.capture_ns, h.published_ns),
        h.row_shift_mpx as f64 / 1000.0,
        RowAlignState::from_code(h.row_align).map_or("?", RowAlignState::label)
    )
}

fn disparity_json(h: &DisparityHeader) -> Value {
    json!({
        "frame_id": h.frame_id,
        "width": h.width,
        "height": h.height,
        "algorithm": algorithm_label(h.algorithm),
        "min_disp": h.min_disp,
        "max_disp": h.max_disp,
        "valid_px": h.valid_px,
        "row_shift_px": h.row_shift_mpx as f64 / 1000.0,
        "row_align": RowAlignState::from_code(h.row_align).map_or("?", RowAlignState::label),
        "compute_ms": ms(h.compute_ns),
        "capture_ns": h.capture_ns,
        "published_ns": h.published_ns,
        "capture_to_publish_ms": span_ms(h.capture_ns, h.published_ns),
    })
}

/// `Describe` for the image payloads: they are summarised by their header (the two sizes of a
/// frame pair share one text, the two sizes of a disparity map another).
macro_rules! describe_by_header {
    ($($payload:ty => $text:ident, $json:ident;)*) => {$(
        impl Describe for $payload {
            fn stamp_ns(&self) -> Option<u64> {
                stamp(self.header.published_ns)
            }

            fn describe_text(&self) -> String {
                $text(&self.header)
            }
            fn describe_json(&self) -> Value {
                $json(&self.header)
            }
        }
    )*};
}

describe_by_header! {
    StereoFrame320x240 => frame_text, frame_json;
    StereoFrame640x480 => frame_text, frame_json;
    DisparityMap320x240 => disparity_text, disparity_json;
    DisparityMap640x480 => disparity_text, disparity_json;
}

fn range_source_label(code: u32) -> &'static str {
    RangeSource::from_code(code).label()
}

/// The windows of a report that are in use.
pub(crate) fn used_windows(r: &RangeReport) -> &[RangeWindow] {
    &r.windows[..(r.window_count as usize).min(r.windows.len())]
}

impl Describe for RangeReport {
    fn stamp_ns(&self) -> Option<u64> {
        stamp(self.published_ns)
    }

    fn describe_text(&self) -> String {
        let windows: Vec<String> = used_windows(self)
            .iter()
            .map(|w| {
                format!(
                    "{:.2}m({},near {:.2},{}px)",
                    w.range_m,
                    range_source_label(w.source),
                    w.near_m,
                    w.valid_px
                )
            })
            .collect();
        format!(
            "ranges {} [{}] edges {} valid {} hi {} scan {}/{} bins capture->publish {:.2} ms",
            self.frame_id,
            windows.join(" "),
            self.edge_px,
            self.valid_edge_px,
            if self.hi_frame_id == 0 {
                "-".to_string()
            } else {
                format!("{} ({:.0} ms old)", self.hi_frame_id, ms(self.hi_age_ns))
            },
            self.scan.valid_bins(),
            self.scan.range_m.len(),
            span_ms(self.capture_ns, self.published_ns)
        )
    }

    fn describe_json(&self) -> Value {
        let windows: Vec<Value> = used_windows(self)
            .iter()
            .map(|w| {
                json!({
                    "range_m": w.range_m,
                    "near_m": w.near_m,
                    "mean_m": w.mean_m,
                    "valid_px": w.valid_px,
                    "confidence": w.confidence,
                    "source": range_source_label(w.source),
                })
            })
            .collect();
        json!({
            "frame_id": self.frame_id,
            "capture_ns": self.capture_ns,
            "published_ns": self.published_ns,
            "capture_to_publish_ms": span_ms(self.capture_ns, self.published_ns),
            "hi_frame_id": self.hi_frame_id,
            "hi_age_ms": ms(self.hi_age_ns),
            "edge_px": self.edge_px,
            "valid_edge_px": self.valid_edge_px,
            "windows": windows,
            "scan_range_m": self.scan.range_m.to_vec(),
        })
    }
}

impl Describe for Decision {
    fn stamp_ns(&self) -> Option<u64> {
        stamp(self.published_ns)
    }

    fn describe_text(&self) -> String {
        format!(
            "decision {} {} {} walls L {:.2} F {:.2} R {:.2} turn {:.0} deg ramp {} capture->decision {:.2} ms",
            self.frame_id,
            MotionCommand::from_code(self.command).label(),
            IntersectionType::from_code(self.intersection).label(),
            self.wall_left,
            self.wall_front,
            self.wall_right,
            self.turn_angle_deg,
            self.ramp,
            span_ms(self.capture_ns, self.published_ns)
        )
    }

    fn describe_json(&self) -> Value {
        json!({
            "frame_id": self.frame_id,
            "command": MotionCommand::from_code(self.command).label(),
            "intersection": IntersectionType::from_code(self.intersection).label(),
            "wall_left": self.wall_left,
            "wall_front": self.wall_front,
            "wall_right": self.wall_right,
            "turn_angle_deg": self.turn_angle_deg,
            "ramp": self.ramp,
            "policy": self.policy,
            "capture_ns": self.capture_ns,
            "published_ns": self.published_ns,
            "capture_to_decision_ms": span_ms(self.capture_ns, self.published_ns),
        })
    }
}

fn reason_label(code: u32) -> &'static str {
    SendReason::from_code(code).map_or("?", SendReason::label)
}

/// Bytes as printable text: ASCII graphic characters as themselves, others as `\xNN`.
pub fn escape_bytes(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|&b| {
            if b.is_ascii_graphic() {
                (b as char).to_string()
            } else {
                format!("\\x{b:02x}")
            }
        })
        .collect()
}

/// Bytes as space-separated hex.
pub fn hex_bytes(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect::<Vec<_>>()
        .join(" ")
}

fn sent_bytes(r: &ActuatorReport) -> &[u8] {
    &r.bytes[..(r.byte_count as usize).min(r.bytes.len())]
}

impl Describe for ActuatorReport {
    fn stamp_ns(&self) -> Option<u64> {
        stamp(self.sent_ns)
    }

    fn describe_text(&self) -> String {
        format!(
            "actuator {} {} {} pw L {} R {} (2 us) decision {} bytes \"{}\"",
            self.seq,
            reason_label(self.reason),
            MotionCommand::from_code(self.command).label(),
            self.left_pw,
            self.right_pw,
            self.decision_frame_id,
            escape_bytes(sent_bytes(self))
        )
    }

    fn describe_json(&self) -> Value {
        json!({
            "seq": self.seq,
            "reason": reason_label(self.reason),
            "command": MotionCommand::from_code(self.command).label(),
            "left_pw": self.left_pw,
            "right_pw": self.right_pw,
            "ramp": self.ramp,
            "decision_frame_id": self.decision_frame_id,
            "decision_capture_ns": self.decision_capture_ns,
            "decision_published_ns": self.decision_published_ns,
            "sent_ns": self.sent_ns,
            "capture_to_sent_ms": span_ms(self.decision_capture_ns, self.sent_ns),
            "bytes_hex": hex_bytes(sent_bytes(self)),
            "bytes_text": escape_bytes(sent_bytes(self)),
        })
    }
}

impl Describe for LogLine {
    fn stamp_ns(&self) -> Option<u64> {
        stamp(self.time_ns)
    }

    fn describe_text(&self) -> String {
        format!(
            "{:>10} | {}",
            decode_name(&self.stage),
            decode_name(&self.text)
        )
    }

    fn describe_json(&self) -> Value {
        json!({
            "seq": self.seq,
            "time_ns": self.time_ns,
            "level": LogLevel::from_code(self.level).map_or("-", LogLevel::label),
            "stage": decode_name(&self.stage),
            "text": decode_name(&self.text),
        })
    }
}

impl Describe for RobotPose {
    fn stamp_ns(&self) -> Option<u64> {
        stamp(self.published_ns)
    }

    fn describe_text(&self) -> String {
        format!(
            "pose frame {} x {:.3} y {:.3} m heading {:.1} deg driven {:.2} m",
            self.frame_id,
            self.x_m,
            self.y_m,
            self.heading_rad.to_degrees(),
            self.distance_m
        )
    }

    fn describe_json(&self) -> Value {
        json!({
            "frame_id": self.frame_id,
            "capture_ns": self.capture_ns,
            "published_ns": self.published_ns,
            "x_m": self.x_m,
            "y_m": self.y_m,
            "heading_rad": self.heading_rad,
            "distance_m": self.distance_m,
        })
    }
}

impl Describe for NavMap {
    fn stamp_ns(&self) -> Option<u64> {
        stamp(self.published_ns)
    }

    fn describe_text(&self) -> String {
        let (free, occupied) = self.cells.iter().fold((0, 0), |(f, o), &c| match c {
            0..=49 => (f + 1, o),
            50..=100 => (f, o + 1),
            _ => (f, o),
        });
        format!(
            "map #{} {}x{} cells of {:.2} m from ({:.2}, {:.2}) m: {free} free, {occupied} occupied",
            self.seq, self.side, self.side, self.cell_m, self.origin_x_m, self.origin_y_m
        )
    }

    fn describe_json(&self) -> Value {
        let (free, occupied) = self.cells.iter().fold((0u32, 0u32), |(f, o), &c| match c {
            0..=49 => (f + 1, o),
            50..=100 => (f, o + 1),
            _ => (f, o),
        });
        json!({
            "seq": self.seq,
            "capture_ns": self.capture_ns,
            "published_ns": self.published_ns,
            "origin_x_m": self.origin_x_m,
            "origin_y_m": self.origin_y_m,
            "cell_m": self.cell_m,
            "side": self.side,
            "free_cells": free,
            "occupied_cells": occupied,
        })
    }
}

fn health_label(code: u32) -> &'static str {
    StageHealth::from_code(code).map_or("?", StageHealth::label)
}

impl Describe for StageHeartbeat {
    fn stamp_ns(&self) -> Option<u64> {
        stamp(self.time_ns)
    }

    fn describe_text(&self) -> String {
        let note = decode_name(&self.note);
        format!(
            "heartbeat {} #{} pid {} {} up {:.1} s in {} out {} drops {} errors {} latency p50 {:.2} p99 {:.2} max {:.2} ms{}",
            decode_name(&self.stage),
            self.seq,
            self.pid,
            health_label(self.health),
            span_ms(self.started_ns, self.time_ns) / 1e3,
            self.frames_in,
            self.frames_out,
            self.drops,
            self.errors,
            ms(self.latency_p50_ns),
            ms(self.latency_p99_ns),
            ms(self.latency_max_ns),
            if note.is_empty() {
                String::new()
            } else {
                format!(" note \"{note}\"")
            }
        )
    }

    fn describe_json(&self) -> Value {
        json!({
            "stage": decode_name(&self.stage),
            "seq": self.seq,
            "pid": self.pid,
            "health": health_label(self.health),
            "time_ns": self.time_ns,
            "uptime_s": span_ms(self.started_ns, self.time_ns) / 1e3,
            "frames_in": self.frames_in,
            "frames_out": self.frames_out,
            "drops": self.drops,
            "errors": self.errors,
            "latency_p50_ms": ms(self.latency_p50_ns),
            "latency_p99_ms": ms(self.latency_p99_ns),
            "latency_max_ms": ms(self.latency_max_ns),
            "note": decode_name(&self.note),
        })
    }
}

impl Describe for SimTruth {
    fn stamp_ns(&self) -> Option<u64> {
        stamp(self.time_ns)
    }

    fn describe_text(&self) -> String {
        format!(
            "truth {} t {:.2} s pose ({:.2}, {:.2}) m {:.1} deg odometer {:.2} m frame {} psc {} ({} malformed) collisions {}{} pw L {} R {}",
            self.seq,
            self.sim_time_s,
            self.x_m,
            self.y_m,
            self.heading_rad.to_degrees(),
            self.odometer_m,
            self.frame_id,
            self.psc_frames,
            self.psc_malformed,
            self.collisions,
            if self.in_collision != 0 {
                " (touching)"
            } else {
                ""
            },
            self.left_pw,
            self.right_pw
        )
    }

    fn describe_json(&self) -> Value {
        json!({
            "seq": self.seq,
            "sim_time_s": self.sim_time_s,
            "x_m": self.x_m,
            "y_m": self.y_m,
            "heading_deg": self.heading_rad.to_degrees(),
            "odometer_m": self.odometer_m,
            "frame_id": self.frame_id,
            "psc_frames": self.psc_frames,
            "psc_malformed": self.psc_malformed,
            "collisions": self.collisions,
            "in_collision": self.in_collision != 0,
            "left_pw": self.left_pw,
            "right_pw": self.right_pw,
        })
    }
}

fn state_label(code: u32) -> &'static str {
    StageState::from_code(code).map_or("?", StageState::label)
}

fn status_stages(s: &SupervisorStatus) -> &[hvs_shared::messages::StageStatusEntry] {
    &s.stages[..(s.stage_count as usize).min(s.stages.len())]
}

impl Describe for SupervisorStatus {
    fn stamp_ns(&self) -> Option<u64> {
        stamp(self.time_ns)
    }

    fn describe_text(&self) -> String {
        let mut text = format!(
            "status {} supervisor pid {} up {:.0} s last {} capture->decision p50 {:.1} p99 {:.1} ms{}",
            self.seq,
            self.supervisor_pid,
            span_ms(self.started_ns, self.time_ns) / 1e3,
            MotionCommand::from_code(self.last_command).label(),
            ms(self.decision_latency_p50_ns),
            ms(self.decision_latency_p99_ns),
            if self.stopping != 0 { " STOPPING" } else { "" }
        );
        for e in status_stages(self) {
            text.push_str(&format!(
                "\n  {:<10} pid {:>7} {:<8} restarts {} rate {:.1} Hz p50 {:.2} ms drops {}",
                decode_name(&e.stage),
                e.pid,
                state_label(e.state),
                e.restarts,
                e.rate_hz,
                ms(e.latency_p50_ns),
                e.drops
            ));
        }
        text
    }

    fn describe_json(&self) -> Value {
        let stages: Vec<Value> = status_stages(self)
            .iter()
            .map(|e| {
                json!({
                    "stage": decode_name(&e.stage),
                    "pid": e.pid,
                    "state": state_label(e.state),
                    "restarts": e.restarts,
                    "rate_hz": e.rate_hz,
                    "latency_p50_ms": ms(e.latency_p50_ns),
                    "latency_p99_ms": ms(e.latency_p99_ns),
                    "frames_in": e.frames_in,
                    "frames_out": e.frames_out,
                    "drops": e.drops,
                    "heartbeat_age_ms": e.heartbeat_age_ms,
                    "last_exit": e.last_exit,
                    "note": decode_name(&e.note),
                })
            })
            .collect();
        json!({
            "seq": self.seq,
            "supervisor_pid": self.supervisor_pid,
            "uptime_s": span_ms(self.started_ns, self.time_ns) / 1e3,
            "stopping": self.stopping != 0,
            "last_command": MotionCommand::from_code(self.last_command).label(),
            "decision_latency_p50_ms": ms(self.decision_latency_p50_ns),
            "decision_latency_p99_ms": ms(self.decision_latency_p99_ns),
            "stages": stages,
        })
    }
}

fn control_label(code: u32) -> &'static str {
    ControlCommand::from_code(code).map_or("?", ControlCommand::label)
}

impl Describe for ControlRequest {
    fn describe_text(&self) -> String {
        format!(
            "control {} {} {} from pid {}",
            self.seq,
            control_label(self.command),
            decode_name(&self.stage),
            self.sender_pid
        )
    }

    fn describe_json(&self) -> Value {
        json!({
            "seq": self.seq,
            "command": control_label(self.command),
            "stage": decode_name(&self.stage),
            "sender_pid": self.sender_pid,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bytemuck::Zeroable;
    use hvs_shared::messages::{NAME_LEN, StageStatusEntry, encode_name};

    #[test]
    fn decision_text_and_json_name_command_and_intersection() {
        let d = Decision {
            frame_id: 42,
            capture_ns: 1_000_000,
            published_ns: 13_500_000,
            command: MotionCommand::Left as u32,
            intersection: IntersectionType::TBottom as u32,
            wall_front: 0.9,
            turn_angle_deg: 90.0,
            ..Decision::default()
        };
        let t = d.describe_text();
        assert!(t.starts_with("decision 42 LEFT T-bottom"), "{t}");
        assert!(t.contains("capture->decision 12.50 ms"), "{t}");
        let j = d.describe_json();
        assert_eq!(j["command"], "LEFT");
        assert_eq!(j["intersection"], "T-bottom");
        assert_eq!(j["frame_id"], 42);
        assert_eq!(d.stamp_ns(), Some(13_500_000));
        assert_eq!(
            Decision::default().stamp_ns(),
            None,
            "unset stamp: use arrival"
        );
    }

    #[test]
    fn actuator_bytes_are_escaped_and_hex() {
        let mut r = ActuatorReport {
            seq: 3,
            reason: SendReason::WatchdogNeutral as u32,
            byte_count: 8,
            ..ActuatorReport::default()
        };
        r.bytes[..8].copy_from_slice(b"!SC\x00\x07\xee\x02\r");
        let t = r.describe_text();
        assert!(t.contains("watchdog-neutral"), "{t}");
        assert!(t.contains(r#""!SC\x00\x07\xee\x02\x0d""#), "{t}");
        assert_eq!(r.describe_json()["bytes_hex"], "21 53 43 00 07 ee 02 0d");
    }

    #[test]
    fn ranges_list_only_used_windows() {
        let mut r = RangeReport {
            frame_id: 9,
            window_count: 3,
            ..RangeReport::default()
        };
        r.windows[0].range_m = 1.5;
        r.windows[0].source = RangeSource::Lo as u32;
        r.windows[4].range_m = 99.0;
        let t = r.describe_text();
        assert!(t.contains("[1.50m(lo,near 0.00,0px) 0.00m(-"), "{t}");
        assert!(!t.contains("99"), "{t}");
        assert_eq!(
            r.describe_json()["windows"].as_array().map(Vec::len),
            Some(3)
        );
    }

    #[test]
    fn status_lists_its_stages_and_heartbeat_names_the_stage() {
        let mut s = SupervisorStatus::zeroed();
        s.stage_count = 1;
        s.stages[0] = StageStatusEntry {
            stage: encode_name::<NAME_LEN>("fusion"),
            state: StageState::Running as u32,
            restarts: 2,
            rate_hz: 14.5,
            ..StageStatusEntry::zeroed()
        };
        let t = s.describe_text();
        assert!(t.contains("fusion"), "{t}");
        assert!(t.contains("restarts 2 rate 14.5 Hz"), "{t}");
        assert_eq!(s.describe_json()["stages"][0]["state"], "running");
        let mut hb = StageHeartbeat::zeroed();
        hb.stage = encode_name::<NAME_LEN>("capture");
        hb.health = StageHealth::Degraded as u32;
        hb.note = encode_name::<128>("camera /dev/video2 missing");
        let t = hb.describe_text();
        assert!(t.starts_with("heartbeat capture #0"), "{t}");
        assert!(t.contains("degraded"), "{t}");
        assert!(t.ends_with("note \"camera /dev/video2 missing\""), "{t}");
    }

    #[test]
    fn frame_and_disparity_headers_are_summarised() {
        let h = FrameHeader {
            frame_id: 5,
            width: 320,
            height: 240,
            source: FrameSource::Simulator as u32,
            skew_ns: 2_500_000,
            ..FrameHeader::default()
        };
        assert!(frame_text(&h).starts_with("frame 5 320x240 source sim skew +2.50 ms"));
        let d = DisparityHeader {
            frame_id: 5,
            width: 320,
            height: 240,
            algorithm: StereoAlgorithm::Sgm as u32,
            valid_px: 76_800 / 2,
            ..DisparityHeader::default()
        };
        let t = disparity_text(&d);
        assert!(t.contains("sgm") && t.contains("valid 50.0%"), "{t}");
    }
}
