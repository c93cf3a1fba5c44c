//! The view's own JSON channels: the stage table (from the supervisor's status), the
//! simulator's true pose, the colour scale and wall thresholds; and the log lines: the
//! stages' own (the `log` topic) and those made from changes in the stage table (a stage
//! restarted, stopped, degraded).

use foxglove::messages::Log;
use foxglove::messages::log::Level;
use hvs_probe::schemas::{Kind, schema_of};
use hvs_shared::messages::{
    LogLevel, LogLine, SimTruth, StageHealth, StageState, SupervisorStatus, decode_name,
};
use serde_json::{Value, json};

/// Schema of [`sim_truth_json`].
pub fn sim_truth_schema() -> Value {
    schema_of(
        "hvs.SimTruth",
        &[
            ("sim_time_s", Kind::Number, "simulated time, s"),
            ("x_m", Kind::Number, "true position in the map, m"),
            ("y_m", Kind::Number, "true position in the map, m"),
            ("heading_deg", Kind::Number, "true heading, degrees"),
            ("odometer_m", Kind::Number, "distance driven, m"),
            ("collisions", Kind::Integer, "collisions so far"),
            ("in_collision", Kind::Integer, "1 while touching a wall"),
            (
                "left_pw",
                Kind::Integer,
                "left pulse the simulated controller drives, 2 us units",
            ),
            ("right_pw", Kind::Integer, "right pulse, 2 us units"),
        ],
        &[],
    )
}

/// The simulator's truth as JSON.
pub fn sim_truth_json(t: &SimTruth) -> Value {
    json!({
        "sim_time_s": t.sim_time_s,
        "x_m": t.x_m,
        "y_m": t.y_m,
        "heading_deg": t.heading_rad.to_degrees(),
        "odometer_m": t.odometer_m,
        "collisions": t.collisions,
        "in_collision": t.in_collision,
        "left_pw": t.left_pw,
        "right_pw": t.right_pw,
    })
}

/// Schema of [`stage_table_json`].
pub fn stage_table_schema() -> Value {
    let stage = schema_of(
        "hvs.StageRow",
        &[
            ("stage", Kind::Text, "stage name"),
            ("state", Kind::Integer, "StageState code"),
            ("state_label", Kind::Text, "StageState label"),
            (
                "health",
                Kind::Integer,
                "StageHealth code (0 = no heartbeat yet)",
            ),
            ("health_label", Kind::Text, "StageHealth label"),
            ("pid", Kind::Integer, "process id"),
            ("restarts", Kind::Integer, "restarts so far"),
            ("rate_hz", Kind::Number, "output rate, Hz"),
            ("latency_p50_ms", Kind::Number, "median latency, ms"),
            (
                "latency_p99_ms",
                Kind::Number,
                "99th percentile latency, ms",
            ),
            ("drops", Kind::Integer, "samples dropped"),
            (
                "heartbeat_age_ms",
                Kind::Integer,
                "age of the last heartbeat, ms",
            ),
            ("note", Kind::Text, "the stage's status note"),
        ],
        &[],
    );
    schema_of(
        "hvs.StageTable",
        &[
            (
                "decision_latency_p50_ms",
                Kind::Number,
                "capture to decision, median, ms",
            ),
            (
                "decision_latency_p99_ms",
                Kind::Number,
                "capture to decision, 99th percentile, ms",
            ),
        ],
        &[("stages", json!({"type": "array", "items": stage}))],
    )
}

fn state_label(code: u32) -> &'static str {
    StageState::from_code(code).map_or("?", StageState::label)
}

fn health_label(code: u32) -> &'static str {
    StageHealth::from_code(code).map_or("-", StageHealth::label)
}

/// The supervisor's stage table as JSON.
pub fn stage_table_json(s: &SupervisorStatus) -> Value {
    let n = (s.stage_count as usize).min(s.stages.len());
    let stages: Vec<Value> = s.stages[..n]
        .iter()
        .map(|e| {
            json!({
                "stage": decode_name(&e.stage),
                "state": e.state,
                "state_label": state_label(e.state),
                "health": e.health,
                "health_label": health_label(e.health),
                "pid": e.pid,
                "restarts": e.restarts,
                "rate_hz": e.rate_hz,
                "latency_p50_ms": e.latency_p50_ns as f64 / 1e6,
                "latency_p99_ms": e.latency_p99_ns as f64 / 1e6,
                "drops": e.drops,
                "heartbeat_age_ms": e.heartbeat_age_ms,
                "note": decode_name(&e.note),
            })
        })
        .collect();
    json!({
        "decision_latency_p50_ms": s.decision_latency_p50_ns as f64 / 1e6,
        "decision_latency_p99_ms": s.decision_latency_p99_ns as f64 / 1e6,
        "stages": stages,
    })
}

/// The colour scale of the disparity images and the wall thresholds, for a legend.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Legend {
    /// Depth at the red end of the colour map, m.
    pub near_m: f64,
    /// Depth at the blue end, m.
    pub far_m: f64,
    /// Side wall threshold (320x240), m.
    pub side_wall_m: f64,
    /// Front wall threshold (320x240), m.
    pub front_wall_m: f64,
}

/// Schema of [`legend_json`].
pub fn legend_schema() -> Value {
    schema_of(
        "hvs.Legend",
        &[
            (
                "near_m",
                Kind::Number,
                "depth at the red end of the colour map, m",
            ),
            (
                "far_m",
                Kind::Number,
                "depth at the blue end of the colour map, m",
            ),
            (
                "side_wall_m",
                Kind::Number,
                "a side window nearer than this is a wall, m",
            ),
            (
                "front_wall_m",
                Kind::Number,
                "a front window nearer than this is a wall, m",
            ),
        ],
        &[],
    )
}

/// The legend as JSON.
pub fn legend_json(l: &Legend) -> Value {
    json!({
        "near_m": l.near_m,
        "far_m": l.far_m,
        "side_wall_m": l.side_wall_m,
        "front_wall_m": l.front_wall_m,
    })
}

/// A stage's log line (the `log` topic) as a `foxglove.Log` named after the stage.
pub fn stage_log(l: &LogLine, wall_ns: u64) -> Log {
    let level = match LogLevel::from_code(l.level) {
        Some(LogLevel::Trace | LogLevel::Debug) => Level::Debug,
        Some(LogLevel::Info) => Level::Info,
        Some(LogLevel::Warn) => Level::Warning,
        Some(LogLevel::Error) => Level::Error,
        None => Level::Unknown,
    };
    Log {
        timestamp: Some(crate::encode::stamp(wall_ns)),
        level: level as i32,
        message: decode_name(&l.text).to_string(),
        name: decode_name(&l.stage).to_string(),
        ..Default::default()
    }
}

/// A line about a change in the stage table: a level and a text.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChangeLine {
    /// Warning rather than information.
    pub warning: bool,
    /// The text.
    pub text: String,
}

/// What changed between two stage tables, as log lines: a stage that restarted, changed
/// state, or changed health.
#[derive(Debug, Default)]
pub struct StageChanges {
    last: Vec<(String, u32, u32, u32)>,
}

impl StageChanges {
    /// The lines for a new table (none for the first one).
    pub fn lines(&mut self, s: &SupervisorStatus) -> Vec<ChangeLine> {
        let n = (s.stage_count as usize).min(s.stages.len());
        let now: Vec<(String, u32, u32, u32)> = s.stages[..n]
            .iter()
            .map(|e| {
                (
                    decode_name(&e.stage).to_string(),
                    e.state,
                    e.health,
                    e.restarts,
                )
            })
            .collect();
        let mut out = Vec::new();
        if !self.last.is_empty() {
            for (name, state, health, restarts) in &now {
                let Some((_, s0, h0, r0)) = self.last.iter().find(|l| &l.0 == name) else {
                    continue;
                };
                if restarts > r0 {
                    out.push(ChangeLine {
                        warning: true,
                        text: format!("{name} restarted ({restarts} restarts)"),
                    });
                }
                if state != s0 {
                    out.push(ChangeLine {
                        warning: StageState::from_code(*state) != Some(StageState::Running),
                        text: format!("{name}: {} -> {}", state_label(*s0), state_label(*state)),
                    });
                }
                if health != h0 && *health != 0 {
                    out.push(ChangeLine {
                        warning: StageHealth::from_code(*health) == Some(StageHealth::Degraded),
                        text: format!("{name} {}", health_label(*health)),
                    });
                }
            }
        }
        self.last = now;
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bytemuck::Zeroable;
    use hvs_probe::schemas::conforms;
    use hvs_shared::messages::{StageStatusEntry, encode_name};

    fn status(restarts: u32, state: StageState) -> SupervisorStatus {
        let mut s = SupervisorStatus::zeroed();
        s.stage_count = 1;
        s.stages[0] = StageStatusEntry {
            stage: encode_name("fusion"),
            state: state as u32,
            restarts,
            health: StageHealth::Running as u32,
            ..StageStatusEntry::zeroed()
        };
        s
    }

    #[test]
    fn json_follows_the_schemas() {
        let s = status(2, StageState::Running);
        conforms(&stage_table_json(&s), &stage_table_schema()).expect("stage table");
        conforms(&sim_truth_json(&SimTruth::zeroed()), &sim_truth_schema()).expect("truth");
        let l = Legend {
            near_m: 0.35,
            far_m: 9.6,
            side_wall_m: 0.5,
            front_wall_m: 0.9,
        };
        conforms(&legend_json(&l), &legend_schema()).expect("legend");
        assert_eq!(stage_table_json(&s)["stages"][0]["stage"], "fusion");
    }

    #[test]
    fn a_restart_becomes_a_warning_line() {
        let mut c = StageChanges::default();
        assert!(c.lines(&status(0, StageState::Running)).is_empty());
        assert!(c.lines(&status(0, StageState::Running)).is_empty());
        let lines = c.lines(&status(1, StageState::Running));
        assert_eq!(lines.len(), 1, "{lines:?}");
        assert!(lines[0].warning && lines[0].text.contains("fusion restarted"));
    }
}
