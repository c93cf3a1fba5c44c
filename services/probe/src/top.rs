//! The table of `hvs probe top` (pure logic, no IPC): one row per stage from the supervisor's
//! status, completed by each stage's own newest heartbeat, and the newest decision.

use hvs_shared::messages::{
    Decision, IntersectionType, MotionCommand, StageHealth, StageHeartbeat, StageState,
    SupervisorStatus, decode_name,
};

/// ANSI: cursor home, clear screen (what the live view prints before each frame).
pub const CLEAR_SCREEN: &str = "\x1b[H\x1b[2J";

/// Everything one frame of `hvs probe top` shows.
#[derive(Debug, Clone, Default)]
pub struct TopView {
    /// Instance name.
    pub instance: String,
    /// The supervisor's newest status (`None` until one arrived).
    pub status: Option<SupervisorStatus>,
    /// Newest heartbeat of each stage that has one.
    pub heartbeats: Vec<StageHeartbeat>,
    /// Newest decision.
    pub last_decision: Option<Decision>,
    /// Decisions per second measured by the probe.
    pub decision_rate_hz: Option<f64>,
    /// Sequence gaps of `decisions` since the probe attached (decisions it never saw).
    pub decision_gaps: u64,
}

fn ms(ns: u64) -> f64 {
    ns as f64 / 1e6
}

/// Renders one frame of the table (no ANSI escapes; lines end with `\n`).
pub fn render_top(view: &TopView) -> String {
    let mut out = String::new();
    let Some(status) = &view.status else {
        out.push_str(&format!(
            "hvs top  instance {}  waiting for the supervisor's status...\n",
            view.instance
        ));
        return out;
    };
    out.push_str(&format!(
        "hvs top  instance {}  supervisor pid {}  up {:.0} s  capture->decision p50 {:.1} ms p99 {:.1} ms{}\n",
        view.instance,
        status.supervisor_pid,
        status.time_ns.saturating_sub(status.started_ns) as f64 / 1e9,
        ms(status.decision_latency_p50_ns),
        ms(status.decision_latency_p99_ns),
        if status.stopping != 0 { "  STOPPING" } else { "" }
    ));
    match &view.last_decision {
        Some(d) => out.push_str(&format!(
            "last decision #{} {} {}  walls L {:.2} F {:.2} R {:.2}  decisions {} Hz  gaps {}\n",
            d.frame_id,
            MotionCommand::from_code(d.command).label(),
            IntersectionType::from_code(d.intersection).label(),
            d.wall_left,
            d.wall_front,
            d.wall_right,
            crate::rate::opt(view.decision_rate_hz, 1),
            view.decision_gaps
        )),
        None => out.push_str("last decision: none yet\n"),
    }
    out.push_str(&format!(
        "{:<10} {:<9} {:>7} {:>8} {:>8} {:>15} {:>8} {:>9} {:<9} {:>7}  {}\n",
        "STAGE",
        "STATE",
        "PID",
        "RESTARTS",
        "RATE Hz",
        "LAT p50/p99 ms",
        "MAX ms",
        "DROPS",
        "HEALTH",
        "HB AGE",
        "NOTE"
    ));
    let count = (status.stage_count as usize).min(status.stages.len());
    for e in &status.stages[..count] {
        let name = decode_name(&e.stage);
        let hb = view
            .heartbeats
            .iter()
            .find(|h| decode_name(&h.stage) == name && h.pid == e.pid);
        let hb_age = if e.heartbeat_age_ms == u32::MAX {
            "-".to_string()
        } else {
            format!("{} ms", e.heartbeat_age_ms)
        };
        out.push_str(&format!(
            "{:<10} {:<9} {:>7} {:>8} {:>8.1} {:>7.2}/{:<7.2} {:>8} {:>9} {:<9} {:>7}  {}\n",
            name,
            StageState::from_code(e.state).map_or("?", StageState::label),
            e.pid,
            e.restarts,
            e.rate_hz,
            ms(e.latency_p50_ns),
            ms(e.latency_p99_ns),
            hb.map_or("-".to_string(), |h| format!("{:.2}", ms(h.latency_max_ns))),
            e.drops,
            hb.map_or("-", |h| StageHealth::from_code(h.health)
                .map_or("?", StageHealth::label)),
            hb_age,
            hb.map_or("", |h| decode_name(&h.note))
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use bytemuck::Zeroable;
    use hvs_shared::messages::{NAME_LEN, StageStatusEntry, encode_name};

    fn status() -> SupervisorStatus {
        let mut s = SupervisorStatus::zeroed();
        s.supervisor_pid = 100;
        s.started_ns = 1_000_000_000;
        s.time_ns = 61_000_000_000;
        s.decision_latency_p50_ns = 12_300_000;
        s.stage_count = 2;
        s.stages[0] = StageStatusEntry {
            stage: encode_name::<NAME_LEN>("capture"),
            pid: 101,
            state: StageState::Running as u32,
            restarts: 0,
            rate_hz: 29.9,
            heartbeat_age_ms: 40,
            ..StageStatusEntry::zeroed()
        };
        s.stages[1] = StageStatusEntry {
            stage: encode_name::<NAME_LEN>("fusion"),
            pid: 102,
            state: StageState::Backoff as u32,
            restarts: 3,
            drops: 7,
            heartbeat_age_ms: u32::MAX,
            ..StageStatusEntry::zeroed()
        };
        s
    }

    #[test]
    fn rows_combine_status_heartbeats_and_the_last_decision() {
        let mut hb = StageHeartbeat::zeroed();
        hb.stage = encode_name::<NAME_LEN>("capture");
        hb.pid = 101;
        hb.health = StageHealth::Degraded as u32;
        hb.latency_max_ns = 2_500_000;
        hb.note = encode_name::<128>("sim camera");
        let view = TopView {
            instance: "t1".into(),
            status: Some(status()),
            heartbeats: vec![hb],
            last_decision: Some(Decision {
                frame_id: 77,
                command: MotionCommand::Forward as u32,
                intersection: IntersectionType::StraightHallway as u32,
                ..Decision::default()
            }),
            decision_rate_hz: Some(14.96),
            decision_gaps: 0,
        };
        let text = render_top(&view);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 5, "{text}");
        assert!(
            lines[0].contains("instance t1  supervisor pid 100  up 60 s"),
            "{text}"
        );
        assert!(lines[0].contains("p50 12.3 ms"), "{text}");
        assert!(
            lines[1].contains("#77 FWD hallway") && lines[1].contains("15.0 Hz"),
            "{text}"
        );
        assert!(lines[2].starts_with("STAGE"));
        assert!(lines[3].starts_with("capture    running"), "{text}");
        assert!(
            lines[3].contains("degraded") && lines[3].contains("2.50"),
            "{text}"
        );
        assert!(lines[3].ends_with("sim camera"), "{text}");
        assert!(lines[4].starts_with("fusion     backoff"), "{text}");
        assert!(
            lines[4].contains("  3 ") && lines[4].contains("  7 "),
            "{text}"
        );
    }

    #[test]
    fn without_status_it_says_it_waits() {
        let text = render_top(&TopView {
            instance: "x".into(),
            ..TopView::default()
        });
        assert!(text.contains("waiting for the supervisor"), "{text}");
    }
}
