//! The JSON messages and JSON schemas hvs shows to Foxglove and Lichtblick: the live view
//! (`hvs-view`) and the MCAP recordings (`hvs probe record`) both use these, so that a
//! recording and a live session look the same.
//!
//! Every field is named in its channel's schema with its type; codes are numbers with their
//! labels beside them (`command` and `command_label`), so that a plot panel can draw them.
//! Camera calibration and frame transforms follow the `foxglove.CameraCalibration` and
//! `foxglove.FrameTransforms` schemas (the JSON form of Foxglove's own types).

use hvs_runtime::config::CameraConfig;
use hvs_shared::messages::{
    ActuatorReport, Decision, IntersectionType, MotionCommand, NavPolicy, RangeReport, RangeSource,
    RobotPose, SendReason,
};
use serde_json::{Map, Value, json};

/// Frame of the dead-reckoned world (where the robot started).
pub const WORLD_FRAME: &str = "world";
/// Frame of the robot's turning centre: x ahead, y left, z up.
pub const ROBOT_FRAME: &str = "robot";
/// Optical frame of the left camera: z along the optical axis, x right, y down.
pub const CAMERA_FRAME: &str = "camera";

/// A field's type in a schema.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A JSON integer.
    Integer,
    /// A JSON number.
    Number,
    /// A string.
    Text,
    /// An array of numbers.
    Numbers,
}

/// The JSON schema of an object: `fields` (name, type, description) and `nested` (name,
/// schema), all required.
pub fn schema_of(title: &str, fields: &[(&str, Kind, &str)], nested: &[(&str, Value)]) -> Value {
    let mut props = Map::new();
    for (name, kind, description) in fields {
        let t = match kind {
            Kind::Integer => json!({"type": "integer", "description": description}),
            Kind::Number => json!({"type": "number", "description": description}),
            Kind::Text => json!({"type": "string", "description": description}),
            Kind::Numbers => {
                json!({"type": "array", "items": {"type": "number"}, "description": description})
            }
        };
        props.insert((*name).to_string(), t);
    }
    for (name, v) in nested {
        props.insert((*name).to_string(), v.clone());
    }
    let required: Vec<&str> = fields
        .iter()
        .map(|f| f.0)
        .chain(nested.iter().map(|n| n.0))
        .collect();
    json!({"title": title, "type": "object", "properties": props, "required": required})
}

/// A hvs message shown in Foxglove: its schema name, JSON schema and JSON form.
pub trait FoxgloveJson {
    /// Schema name (`hvs.RangeReport`).
    const SCHEMA_NAME: &'static str;
    /// The JSON schema.
    fn json_schema() -> Value;
    /// The message as JSON, following the schema.
    fn to_foxglove_json(&self) -> Value;
    /// The time the message is logged at, CLOCK_MONOTONIC ns.
    fn log_monotonic_ns(&self) -> u64;
}

fn window_schema() -> Value {
    schema_of(
        "hvs.RangeWindow",
        &[
            (
                "range_m",
                Kind::Number,
                "range of the window, m (0 = no data)",
            ),
            ("near_m", Kind::Number, "nearest valid point, m"),
            ("mean_m", Kind::Number, "mean range, m"),
            (
                "valid_px",
                Kind::Integer,
                "edge pixels with a valid disparity",
            ),
            (
                "confidence",
                Kind::Number,
                "share of the window's edge pixels that are valid",
            ),
            ("source", Kind::Integer, "RangeSource code"),
            ("source_label", Kind::Text, "RangeSource label"),
        ],
        &[],
    )
}

impl FoxgloveJson for RangeReport {
    const SCHEMA_NAME: &'static str = "hvs.RangeReport";

    fn json_schema() -> Value {
        schema_of(
            Self::SCHEMA_NAME,
            &[
                ("frame_id", Kind::Integer, "fast-path frame id"),
                (
                    "capture_ns",
                    Kind::Integer,
                    "capture time, CLOCK_MONOTONIC ns",
                ),
                (
                    "published_ns",
                    Kind::Integer,
                    "publication time, CLOCK_MONOTONIC ns",
                ),
                (
                    "capture_to_ranges_ms",
                    Kind::Number,
                    "capture to publication, ms",
                ),
                (
                    "hi_frame_id",
                    Kind::Integer,
                    "640x480 frame fused in (0 = none)",
                ),
                ("hi_age_ms", Kind::Number, "age of that 640x480 result, ms"),
                ("window_count", Kind::Integer, "windows in use"),
                ("edge_px", Kind::Integer, "Canny edge pixels"),
                (
                    "valid_edge_px",
                    Kind::Integer,
                    "edge pixels with a valid disparity",
                ),
                (
                    "scan_range_m",
                    Kind::Numbers,
                    "obstacle scan, 64 column bins left to right, m (0 = no data, -1 = scattered)",
                ),
                (
                    "scan_tan_half_fov",
                    Kind::Number,
                    "tangent of half the scan's field of view",
                ),
            ],
            &[(
                "windows",
                json!({"type": "array", "items": window_schema(), "description": "range windows left to right"}),
            )],
        )
    }

    fn to_foxglove_json(&self) -> Value {
        let windows: Vec<Value> = crate::format::used_windows(self)
            .iter()
            .map(|w| {
                json!({
                    "range_m": w.range_m,
                    "near_m": w.near_m,
                    "mean_m": w.mean_m,
                    "valid_px": w.valid_px,
                    "confidence": w.confidence,
                    "source": w.source,
                    "source_label": RangeSource::from_code(w.source).label(),
                })
            })
            .collect();
        json!({
            "frame_id": self.frame_id,
            "capture_ns": self.capture_ns,
            "published_ns": self.published_ns,
            "capture_to_ranges_ms": span_ms(self.capture_ns, self.published_ns),
            "hi_frame_id": self.hi_frame_id,
            "hi_age_ms": self.hi_age_ns as f64 / 1e6,
            "window_count": self.window_count,
            "edge_px": self.edge_px,
            "valid_edge_px": self.valid_edge_px,
            "scan_range_m": self.scan.range_m.to_vec(),
            "scan_tan_half_fov": self.scan.tan_half_fov,
            "windows": windows,
        })
    }

    fn log_monotonic_ns(&self) -> u64 {
        self.published_ns
    }
}

impl FoxgloveJson for Decision {
    const SCHEMA_NAME: &'static str = "hvs.Decision";

    fn json_schema() -> Value {
        schema_of(
            Self::SCHEMA_NAME,
            &[
                (
                    "frame_id",
                    Kind::Integer,
                    "frame the decision was made from",
                ),
                (
                    "capture_ns",
                    Kind::Integer,
                    "capture time, CLOCK_MONOTONIC ns",
                ),
                (
                    "published_ns",
                    Kind::Integer,
                    "publication time, CLOCK_MONOTONIC ns",
                ),
                (
                    "capture_to_decision_ms",
                    Kind::Number,
                    "capture to decision, ms",
                ),
                ("command", Kind::Integer, "MotionCommand code"),
                ("command_label", Kind::Text, "MotionCommand label"),
                ("intersection", Kind::Integer, "IntersectionType code"),
                ("intersection_label", Kind::Text, "IntersectionType label"),
                (
                    "wall_left",
                    Kind::Number,
                    "membership of wall on the left, 0..1",
                ),
                (
                    "wall_front",
                    Kind::Number,
                    "membership of wall in front, 0..1",
                ),
                (
                    "wall_right",
                    Kind::Number,
                    "membership of wall on the right, 0..1",
                ),
                (
                    "turn_angle_deg",
                    Kind::Number,
                    "turn angle of a turn command, degrees",
                ),
                ("ramp", Kind::Integer, "PSC ramp, 0..63"),
                ("policy", Kind::Integer, "NavPolicy code"),
                ("policy_label", Kind::Text, "NavPolicy label"),
            ],
            &[],
        )
    }

    fn to_foxglove_json(&self) -> Value {
        json!({
            "frame_id": self.frame_id,
            "capture_ns": self.capture_ns,
            "published_ns": self.published_ns,
            "capture_to_decision_ms": span_ms(self.capture_ns, self.published_ns),
            "command": self.command,
            "command_label": MotionCommand::from_code(self.command).label(),
            "intersection": self.intersection,
            "intersection_label": IntersectionType::from_code(self.intersection).label(),
            "wall_left": self.wall_left,
            "wall_front": self.wall_front,
            "wall_right": self.wall_right,
            "turn_angle_deg": self.turn_angle_deg,
            "ramp": self.ramp,
            "policy": self.policy,
            "policy_label": NavPolicy::from_code(self.policy).map_or("?", NavPolicy::label),
        })
    }

    fn log_monotonic_ns(&self) -> u64 {
        self.published_ns
    }
}

impl FoxgloveJson for ActuatorReport {
    const SCHEMA_NAME: &'static str = "hvs.ActuatorReport";

    fn json_schema() -> Value {
        schema_of(
            Self::SCHEMA_NAME,
            &[
                (
                    "seq",
                    Kind::Integer,
                    "report counter of the actuator process",
                ),
                ("reason", Kind::Integer, "SendReason code"),
                ("reason_label", Kind::Text, "SendReason label"),
                ("command", Kind::Integer, "MotionCommand code"),
                ("command_label", Kind::Text, "MotionCommand label"),
                ("left_pw", Kind::Integer, "left servo pulse, 2 us units"),
                ("right_pw", Kind::Integer, "right servo pulse, 2 us units"),
                ("ramp", Kind::Integer, "PSC ramp, 0..63"),
                (
                    "decision_frame_id",
                    Kind::Integer,
                    "frame of the decision acted on (0 = none)",
                ),
                (
                    "decision_capture_ns",
                    Kind::Integer,
                    "capture time of that frame, CLOCK_MONOTONIC ns",
                ),
                (
                    "decision_published_ns",
                    Kind::Integer,
                    "publication time of the decision, CLOCK_MONOTONIC ns",
                ),
                (
                    "sent_ns",
                    Kind::Integer,
                    "time the last byte was written, CLOCK_MONOTONIC ns",
                ),
                (
                    "capture_to_sent_ms",
                    Kind::Number,
                    "capture to serial write, ms",
                ),
                (
                    "bytes_hex",
                    Kind::Text,
                    "bytes written to the servo controller, hex",
                ),
            ],
            &[],
        )
    }

    fn to_foxglove_json(&self) -> Value {
        let bytes = &self.bytes[..(self.byte_count as usize).min(self.bytes.len())];
        json!({
            "seq": self.seq,
            "reason": self.reason,
            "reason_label": SendReason::from_code(self.reason).map_or("?", SendReason::label),
            "command": self.command,
            "command_label": MotionCommand::from_code(self.command).label(),
            "left_pw": self.left_pw,
            "right_pw": self.right_pw,
            "ramp": self.ramp,
            "decision_frame_id": self.decision_frame_id,
            "decision_capture_ns": self.decision_capture_ns,
            "decision_published_ns": self.decision_published_ns,
            "sent_ns": self.sent_ns,
            "capture_to_sent_ms": span_ms(self.decision_capture_ns, self.sent_ns),
            "bytes_hex": crate::format::hex_bytes(bytes),
        })
    }

    fn log_monotonic_ns(&self) -> u64 {
        self.sent_ns
    }
}

impl FoxgloveJson for RobotPose {
    const SCHEMA_NAME: &'static str = "hvs.RobotPose";

    fn json_schema() -> Value {
        schema_of(
            Self::SCHEMA_NAME,
            &[
                ("frame_id", Kind::Integer, "frame of the decision"),
                (
                    "capture_ns",
                    Kind::Integer,
                    "capture time, CLOCK_MONOTONIC ns",
                ),
                ("x_m", Kind::Number, "ahead of the start pose, m"),
                ("y_m", Kind::Number, "left of the start pose, m"),
                (
                    "heading_deg",
                    Kind::Number,
                    "heading from the start heading, counter-clockwise, degrees",
                ),
                ("distance_m", Kind::Number, "distance driven, m"),
            ],
            &[],
        )
    }

    fn to_foxglove_json(&self) -> Value {
        json!({
            "frame_id": self.frame_id,
            "capture_ns": self.capture_ns,
            "x_m": self.x_m,
            "y_m": self.y_m,
            "heading_deg": self.heading_rad.to_degrees(),
            "distance_m": self.distance_m,
        })
    }

    fn log_monotonic_ns(&self) -> u64 {
        self.published_ns
    }
}

fn span_ms(from_ns: u64, to_ns: u64) -> f64 {
    if from_ns == 0 || to_ns < from_ns {
        0.0
    } else {
        (to_ns - from_ns) as f64 / 1e6
    }
}

/// The pinhole calibration of the left camera at `width x height` from the config
/// (rectified images: no distortion; the right camera sits `baseline_m` to the right).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pinhole {
    /// Image width, px.
    pub width: u32,
    /// Image height, px.
    pub height: u32,
    /// Focal length, px.
    pub focal_px: f64,
    /// Principal point, px.
    pub cx: f64,
    /// Principal point, px.
    pub cy: f64,
    /// Stereo baseline, m.
    pub baseline_m: f64,
}

impl Pinhole {
    /// The calibration of an image size from the camera config.
    pub fn of(camera: &CameraConfig, width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            focal_px: camera.focal_px(width as usize),
            cx: f64::from(width) * 0.5,
            cy: f64::from(height) * 0.5,
            baseline_m: camera.baseline_m,
        }
    }

    /// The 3x3 intrinsic matrix, row-major.
    pub fn k(&self) -> [f64; 9] {
        [
            self.focal_px,
            0.0,
            self.cx,
            0.0,
            self.focal_px,
            self.cy,
            0.0,
            0.0,
            1.0,
        ]
    }

    /// The 3x4 projection matrix of the left camera, row-major.
    pub fn p(&self) -> [f64; 12] {
        [
            self.focal_px,
            0.0,
            self.cx,
            0.0,
            0.0,
            self.focal_px,
            self.cy,
            0.0,
            0.0,
            0.0,
            1.0,
            0.0,
        ]
    }

    /// Depth of a disparity, metres.
    pub fn depth_m(&self, disparity_px: f64) -> f64 {
        self.focal_px * self.baseline_m / disparity_px
    }
}

/// `foxglove.CameraCalibration` as JSON (what a recording holds).
pub fn calibration_json(c: &Pinhole, stamp_ns: u64) -> Value {
    json!({
        "timestamp": timestamp(stamp_ns),
        "frame_id": CAMERA_FRAME,
        "width": c.width,
        "height": c.height,
        "distortion_model": "plumb_bob",
        "D": [0.0, 0.0, 0.0, 0.0, 0.0],
        "K": c.k(),
        "R": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        "P": c.p(),
    })
}

/// A Foxglove timestamp object.
pub fn timestamp(ns: u64) -> Value {
    json!({"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000})
}

/// One rigid transform: translation (m) and rotation quaternion `(x, y, z, w)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transform {
    /// Parent frame.
    pub parent: &'static str,
    /// Child frame.
    pub child: &'static str,
    /// Translation of the child's origin in the parent, m.
    pub translation_m: [f64; 3],
    /// Rotation of the child in the parent, quaternion `(x, y, z, w)`.
    pub rotation: [f64; 4],
}

/// The transforms of a pose: world -> robot (the dead-reckoned pose, on the floor) and
/// robot -> camera (the left camera's optical frame, `forward_m` ahead and `height_m` up,
/// `baseline_m / 2` to the left of the centre line).
pub fn pose_transforms(pose: &RobotPose, camera: &CameraConfig) -> [Transform; 2] {
    let half = pose.heading_rad * 0.5;
    [
        Transform {
            parent: WORLD_FRAME,
            child: ROBOT_FRAME,
            translation_m: [pose.x_m, pose.y_m, 0.0],
            rotation: [0.0, 0.0, half.sin(), half.cos()],
        },
        Transform {
            parent: ROBOT_FRAME,
            child: CAMERA_FRAME,
            translation_m: [camera.forward_m, camera.baseline_m * 0.5, camera.height_m],
            // Optical axes in the robot frame: z ahead, x right (-y), y down (-z).
            rotation: [-0.5, 0.5, -0.5, 0.5],
        },
    ]
}

/// `foxglove.FrameTransforms` as JSON (what a recording holds).
pub fn transforms_json(transforms: &[Transform], stamp_ns: u64) -> Value {
    let list: Vec<Value> = transforms
        .iter()
        .map(|t| {
            json!({
                "timestamp": timestamp(stamp_ns),
                "parent_frame_id": t.parent,
                "child_frame_id": t.child,
                "translation": {"x": t.translation_m[0], "y": t.translation_m[1], "z": t.translation_m[2]},
                "rotation": {"x": t.rotation[0], "y": t.rotation[1], "z": t.rotation[2], "w": t.rotation[3]},
            })
        })
        .collect();
    json!({"transforms": list})
}

/// JSON schema of `foxglove.CameraCalibration` (the fields hvs fills).
pub const CAMERA_CALIBRATION_SCHEMA: &str = r#"{"title":"foxglove.CameraCalibration","type":"object","properties":{"timestamp":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}},"frame_id":{"type":"string"},"width":{"type":"integer","minimum":0},"height":{"type":"integer","minimum":0},"distortion_model":{"type":"string"},"D":{"type":"array","items":{"type":"number"}},"K":{"type":"array","items":{"type":"number"},"minItems":9,"maxItems":9},"R":{"type":"array","items":{"type":"number"},"minItems":9,"maxItems":9},"P":{"type":"array","items":{"type":"number"},"minItems":12,"maxItems":12}}}"#;

/// JSON schema of `foxglove.FrameTransforms`.
pub const FRAME_TRANSFORMS_SCHEMA: &str = r#"{"title":"foxglove.FrameTransforms","type":"object","properties":{"transforms":{"type":"array","items":{"type":"object","properties":{"timestamp":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}},"parent_frame_id":{"type":"string"},"child_frame_id":{"type":"string"},"translation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}},"rotation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}}}}}}"#;

/// Checks that `v` follows `schema` (as [`schema_of`] writes them): every key is in the
/// schema with a matching type, recursively, and every required key is there. The error
/// names the first path at fault.
pub fn conforms(v: &Value, schema: &Value) -> Result<(), String> {
    conforms_at(v, schema, "$")
}

fn conforms_at(v: &Value, schema: &Value, at: &str) -> Result<(), String> {
    match schema["type"].as_str() {
        Some("object") => {
            let obj = v
                .as_object()
                .ok_or_else(|| format!("{at} is not an object"))?;
            for (k, item) in obj {
                let s = &schema["properties"][k];
                if s.is_null() {
                    return Err(format!("{at}.{k} is not in the schema"));
                }
                conforms_at(item, s, &format!("{at}.{k}"))?;
            }
            for r in schema["required"].as_array().into_iter().flatten() {
                let r = r.as_str().unwrap_or("");
                if !obj.contains_key(r) {
                    return Err(format!("{at}.{r} is required but missing"));
                }
            }
            Ok(())
        }
        Some("array") => {
            let items = v
                .as_array()
                .ok_or_else(|| format!("{at} is not an array"))?;
            for (i, item) in items.iter().enumerate() {
                conforms_at(item, &schema["items"], &format!("{at}[{i}]"))?;
            }
            Ok(())
        }
        Some("integer") if v.is_u64() || v.is_i64() => Ok(()),
        Some("number") if v.is_number() => Ok(()),
        Some("string") if v.is_string() => Ok(()),
        other => Err(format!("{at} = {v} is not of schema type {other:?}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hvs_shared::messages::{ObstacleScan, RangeWindow};

    fn check<T: FoxgloveJson>(m: &T) {
        let schema = T::json_schema();
        assert_eq!(schema["title"], T::SCHEMA_NAME);
        if let Err(e) = conforms(&m.to_foxglove_json(), &schema) {
            panic!("{}: {e}", T::SCHEMA_NAME);
        }
    }

    #[test]
    fn messages_follow_their_schemas_with_codes_as_numbers() {
        let mut r = RangeReport {
            frame_id: 7,
            capture_ns: 1_000,
            published_ns: 3_000_000,
            window_count: 3,
            scan: ObstacleScan::default(),
            ..Default::default()
        };
        r.windows[1] = RangeWindow {
            range_m: 1.5,
            source: RangeSource::Lo as u32,
            ..Default::default()
        };
        check(&r);
        let j = r.to_foxglove_json();
        assert_eq!(j["windows"].as_array().map(Vec::len), Some(3));
        assert_eq!(j["windows"][1]["source"], RangeSource::Lo as u32);
        assert_eq!(j["scan_range_m"].as_array().map(Vec::len), Some(64));
        let d = Decision {
            command: MotionCommand::Forward as u32,
            intersection: IntersectionType::StraightHallway as u32,
            ..Default::default()
        };
        check(&d);
        let j = d.to_foxglove_json();
        assert_eq!(j["command"], MotionCommand::Forward as u32);
        assert_eq!(j["command_label"], MotionCommand::Forward.label());
        let a = ActuatorReport {
            byte_count: 2,
            bytes: [0x21, 0x53, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
            ..Default::default()
        };
        check(&a);
        assert_eq!(a.to_foxglove_json()["bytes_hex"], "21 53");
        check(&RobotPose::default());
    }

    #[test]
    fn the_camera_looks_ahead_of_the_robot() {
        let camera = CameraConfig::default();
        let pose = RobotPose {
            heading_rad: std::f64::consts::FRAC_PI_2,
            ..Default::default()
        };
        let [world, cam] = pose_transforms(&pose, &camera);
        // A quarter turn left: the quaternion's z and w are both sin(45 deg).
        assert!((world.rotation[2] - world.rotation[3]).abs() < 1e-12);
        // Rotating the optical z axis (0, 0, 1) by the camera rotation gives the robot's x.
        let [x, y, z, w] = cam.rotation;
        let v = [0.0, 0.0, 1.0];
        // v' = v + 2w(q x v) + 2 q x (q x v)
        let q = [x, y, z];
        let cross = |a: [f64; 3], b: [f64; 3]| {
            [
                a[1] * b[2] - a[2] * b[1],
                a[2] * b[0] - a[0] * b[2],
                a[0] * b[1] - a[1] * b[0],
            ]
        };
        let t = cross(q, v);
        let u = cross(q, t);
        let r = [
            v[0] + 2.0 * (w * t[0] + u[0]),
            v[1] + 2.0 * (w * t[1] + u[1]),
            v[2] + 2.0 * (w * t[2] + u[2]),
        ];
        assert!(
            (r[0] - 1.0).abs() < 1e-12 && r[1].abs() < 1e-12 && r[2].abs() < 1e-12,
            "{r:?}"
        );
        let tf = transforms_json(&[world, cam], 5);
        assert_eq!(tf["transforms"][1]["child_frame_id"], CAMERA_FRAME);
        let schema: Value = serde_json::from_str(FRAME_TRANSFORMS_SCHEMA).expect("schema");
        assert_eq!(schema["title"], "foxglove.FrameTransforms");
        let cal = calibration_json(&Pinhole::of(&camera, 320, 240), 5);
        let schema: Value = serde_json::from_str(CAMERA_CALIBRATION_SCHEMA).expect("schema");
        for key in cal.as_object().expect("object").keys() {
            assert!(schema["properties"].get(key).is_some(), "{key}");
        }
        assert_eq!(cal["K"][0], camera.focal_px_320);
    }
}
