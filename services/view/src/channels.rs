//! The view's Foxglove channels: one [`foxglove::Context`] holding every channel the live
//! view serves, with their topic names and schemas. The WebSocket server is a sink of this
//! context; a channel encodes only while some client subscribes to it
//! ([`ViewChannels::wanted`]).

use std::sync::Arc;

use foxglove::messages::{
    CameraCalibration, CompressedImage, FrameTransforms, Grid, Log, PointCloud,
};
use foxglove::{Channel, Context, PartialMetadata, RawChannel, Schema};
use hvs_probe::schemas::FoxgloveJson;
use serde_json::Value;

/// Topic of the left image (JPEG; the recordings hold it as `foxglove.RawImage` under the
/// same name, so one Foxglove layout serves both).
pub const LEFT_IMAGE: &str = "/frames/320x240/left";
/// Topic of the left camera's calibration.
pub const CALIBRATION: &str = "/camera/calibration";
/// Topic of the coloured disparity map with its legend (JPEG).
pub const DISPARITY_IMAGE: &str = "/disparity/colour";
/// Topic of the fused edge map over the left image (JPEG).
pub const FUSED_IMAGE: &str = "/fused/colour";
/// Topic of the point cloud from the 320x240 disparity map.
pub const POINTS: &str = "/disparity/points";
/// Topic of the frame transforms (world -> robot -> camera).
pub const TRANSFORMS: &str = "/tf";
/// Topic of the navigator's map.
pub const MAP: &str = "/map";
/// Topic of the ranges (JSON, the recordings' schema).
pub const RANGES: &str = "/ranges";
/// Topic of the decisions (JSON).
pub const DECISIONS: &str = "/decisions";
/// Topic of the actuator output (JSON).
pub const ACTUATOR: &str = "/actuator/sent";
/// Topic of the dead-reckoned pose (JSON).
pub const POSE: &str = "/decision/pose";
/// Topic of the simulator's true pose (JSON).
pub const SIM_TRUTH: &str = "/sim/truth";
/// Topic of the stage table (JSON).
pub const STAGES: &str = "/hvs/stages";
/// Topic of the colour scale and wall thresholds (JSON).
pub const LEGEND: &str = "/hvs/legend";
/// Topic of log lines.
pub const LOG: &str = "/log";

/// A JSON channel with its JSON schema.
#[derive(Debug, Clone)]
pub struct JsonChannel(Arc<RawChannel>);

impl JsonChannel {
    fn new(
        ctx: &Arc<Context>,
        topic: &str,
        name: &str,
        schema: &Value,
    ) -> Result<Self, foxglove::FoxgloveError> {
        let schema = Schema::new(name, "jsonschema", schema.to_string().into_bytes());
        let raw = ctx
            .channel_builder(topic)
            .message_encoding("json")
            .schema(schema)
            .build_raw()?;
        Ok(Self(raw))
    }

    /// Whether some client subscribes.
    pub fn wanted(&self) -> bool {
        self.0.has_sinks()
    }

    /// Sends a JSON value logged at `wall_ns`.
    pub fn log(&self, value: &Value, wall_ns: u64) {
        self.0.log_with_meta(
            value.to_string().as_bytes(),
            PartialMetadata {
                log_time: Some(wall_ns),
            },
        );
    }
}

/// Every channel of the view.
#[derive(Debug)]
pub struct ViewChannels {
    /// The context the server serves.
    pub context: Arc<Context>,
    /// Left image.
    pub left: Channel<CompressedImage>,
    /// Calibration.
    pub calibration: Channel<CameraCalibration>,
    /// Coloured disparity.
    pub disparity: Channel<CompressedImage>,
    /// Fused edge map.
    pub fused: Channel<CompressedImage>,
    /// Point cloud.
    pub points: Channel<PointCloud>,
    /// Transforms.
    pub transforms: Channel<FrameTransforms>,
    /// Map.
    pub map: Channel<Grid>,
    /// Log lines.
    pub log: Channel<Log>,
    /// Ranges.
    pub ranges: JsonChannel,
    /// Decisions.
    pub decisions: JsonChannel,
    /// Actuator output.
    pub actuator: JsonChannel,
    /// Dead-reckoned pose.
    pub pose: JsonChannel,
    /// Simulator truth.
    pub sim_truth: JsonChannel,
    /// Stage table.
    pub stages: JsonChannel,
    /// Legend and thresholds.
    pub legend: JsonChannel,
}

fn json_channel<T: FoxgloveJson>(
    ctx: &Arc<Context>,
    topic: &str,
) -> Result<JsonChannel, foxglove::FoxgloveError> {
    JsonChannel::new(ctx, topic, T::SCHEMA_NAME, &T::json_schema())
}

impl ViewChannels {
    /// Creates the context and every channel.
    pub fn new() -> Result<Self, foxglove::FoxgloveError> {
        use hvs_shared::messages::{ActuatorReport, Decision, RangeReport, RobotPose};
        let ctx = Context::new();
        Ok(Self {
            left: ctx.channel_builder(LEFT_IMAGE).build(),
            calibration: ctx.channel_builder(CALIBRATION).build(),
            disparity: ctx.channel_builder(DISPARITY_IMAGE).build(),
            fused: ctx.channel_builder(FUSED_IMAGE).build(),
            points: ctx.channel_builder(POINTS).build(),
            transforms: ctx.channel_builder(TRANSFORMS).build(),
            map: ctx.channel_builder(MAP).build(),
            log: ctx.channel_builder(LOG).build(),
            ranges: json_channel::<RangeReport>(&ctx, RANGES)?,
            decisions: json_channel::<Decision>(&ctx, DECISIONS)?,
            actuator: json_channel::<ActuatorReport>(&ctx, ACTUATOR)?,
            pose: json_channel::<RobotPose>(&ctx, POSE)?,
            sim_truth: JsonChannel::new(
                &ctx,
                SIM_TRUTH,
                "hvs.SimTruth",
                &crate::health::sim_truth_schema(),
            )?,
            stages: JsonChannel::new(
                &ctx,
                STAGES,
                "hvs.StageTable",
                &crate::health::stage_table_schema(),
            )?,
            legend: JsonChannel::new(&ctx, LEGEND, "hvs.Legend", &crate::health::legend_schema())?,
            context: ctx,
        })
    }
}
