//! `hvs status`, `hvs restart STAGE`, `hvs stop`: talk to a running supervisor through its
//! status and control topics.

use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use hvs_runtime::config::STAGE_NAMES;
use hvs_runtime::ipc::{IpcNode, TopicOpenError, TopicPublisher, TopicSubscriber};
use hvs_shared::messages::{
    ControlCommand, ControlRequest, MotionCommand, NAME_LEN, StageHealth, StageState,
    SupervisorStatus, decode_name, encode_name,
};
use hvs_shared::topics;
use serde::Serialize;

/// How long a client waits for the supervisor's status.
const STATUS_WAIT: Duration = Duration::from_secs(3);

fn client_node(instance: &str, role: &str) -> anyhow::Result<IpcNode> {
    Ok(IpcNode::create(
        instance,
        &format!("hvs-{role}-{}", std::process::id()),
    )?)
}

fn status_subscriber(node: &IpcNode) -> anyhow::Result<TopicSubscriber<SupervisorStatus>> {
    match node.existing_subscriber(&topics::SUPERVISOR_STATUS, 1) {
        Ok(s) => Ok(s),
        Err(TopicOpenError::NotFound { .. }) => bail!(
            "no hvs supervisor is running for instance {:?} (start one with `hvs run`)",
            node.instance()
        ),
        Err(e) => Err(e.into()),
    }
}

/// Waits for a status newer than `after_seq`.
fn next_status(
    sub: &TopicSubscriber<SupervisorStatus>,
    after_seq: u64,
    timeout: Duration,
) -> anyhow::Result<Option<SupervisorStatus>> {
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(s) = sub.receive_latest()? {
            let s = *s.payload();
            if s.seq > after_seq {
                return Ok(Some(s));
            }
        }
        if Instant::now() >= deadline {
            return Ok(None);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// One stage in `hvs status --json`.
#[derive(Debug, Serialize)]
pub struct StageLine {
    /// Stage name.
    pub stage: String,
    /// Process id (0 when not running).
    pub pid: u32,
    /// State.
    pub state: String,
    /// Restarts.
    pub restarts: u32,
    /// Output rate, Hz.
    pub rate_hz: f32,
    /// Median latency, ms.
    pub latency_p50_ms: f64,
    /// 99th percentile latency, ms.
    pub latency_p99_ms: f64,
    /// Samples in.
    pub frames_in: u64,
    /// Samples out.
    pub frames_out: u64,
    /// Samples lost.
    pub drops: u64,
    /// Time since the last heartbeat, ms.
    pub heartbeat_age_ms: u32,
    /// Last exit status.
    pub last_exit: i32,
    /// Health the stage reports ("running", "degraded", ...; empty before its first beat).
    pub health: String,
    /// The stage's own note: the device in use, or what it waits for.
    pub note: String,
}

/// `hvs status --json`.
#[derive(Debug, Serialize)]
pub struct StatusJson {
    /// Instance.
    pub instance: String,
    /// Supervisor pid.
    pub supervisor_pid: u32,
    /// Seconds since the supervisor started.
    pub uptime_s: f64,
    /// Last command decided.
    pub last_command: String,
    /// Capture-to-decision median, ms.
    pub decision_latency_p50_ms: f64,
    /// Capture-to-decision 99th percentile, ms.
    pub decision_latency_p99_ms: f64,
    /// Stages.
    pub stages: Vec<StageLine>,
}

fn to_json(instance: &str, s: &SupervisorStatus) -> StatusJson {
    let stages = s
        .stages
        .iter()
        .take(s.stage_count as usize)
        .map(|e| StageLine {
            stage: decode_name(&e.stage).to_string(),
            pid: e.pid,
            state: StageState::from_code(e.state)
                .map_or("?", |s| s.label())
                .to_string(),
            restarts: e.restarts,
            rate_hz: e.rate_hz,
            latency_p50_ms: e.latency_p50_ns as f64 / 1e6,
            latency_p99_ms: e.latency_p99_ns as f64 / 1e6,
            frames_in: e.frames_in,
            frames_out: e.frames_out,
            drops: e.drops,
            heartbeat_age_ms: e.heartbeat_age_ms,
            last_exit: e.last_exit,
            health: StageHealth::from_code(e.health)
                .map_or("", |h| h.label())
                .to_string(),
            note: decode_name(&e.note).to_string(),
        })
        .collect();
    StatusJson {
        instance: instance.to_string(),
        supervisor_pid: s.supervisor_pid,
        uptime_s: s.time_ns.saturating_sub(s.started_ns) as f64 / 1e9,
        last_command: MotionCommand::from_code(s.last_command).label().to_string(),
        decision_latency_p50_ms: s.decision_latency_p50_ns as f64 / 1e6,
        decision_latency_p99_ms: s.decision_latency_p99_ns as f64 / 1e6,
        stages,
    }
}

/// Fetches the current status of an instance.
pub fn fetch_status(instance: &str) -> anyhow::Result<StatusJson> {
    let node = client_node(instance, "status")?;
    let sub = status_subscriber(&node)?;
    let status = next_status(&sub, 0, STATUS_WAIT)?.with_context(|| {
        format!("the supervisor of instance {instance:?} sent no status within {STATUS_WAIT:?}")
    })?;
    Ok(to_json(instance, &status))
}

/// `hvs status`.
pub fn status(instance: &str, json: bool) -> anyhow::Result<()> {
    let s = fetch_status(instance)?;
    if json {
        println!("{}", serde_json::to_string_pretty(&s)?);
        return Ok(());
    }
    println!(
        "instance {}  supervisor pid {}  up {:.0} s  last command {}  capture->decision p50 {:.1} ms p99 {:.1} ms",
        s.instance,
        s.supervisor_pid,
        s.uptime_s,
        s.last_command,
        s.decision_latency_p50_ms,
        s.decision_latency_p99_ms
    );
    println!(
        "{:<10} {:>7} {:<9} {:>8} {:>8} {:>17} {:>9} {:>9} {:>7} {:>8}  NOTE",
        "STAGE",
        "PID",
        "STATE",
        "RESTARTS",
        "RATE Hz",
        "LATENCY p50/p99",
        "IN",
        "OUT",
        "DROPS",
        "HB AGE"
    );
    for st in &s.stages {
        let hb = if st.heartbeat_age_ms == u32::MAX {
            "-".to_string()
        } else {
            format!("{} ms", st.heartbeat_age_ms)
        };
        println!(
            "{:<10} {:>7} {:<9} {:>8} {:>8.1} {:>7.2}/{:<6.2} ms {:>9} {:>9} {:>7} {:>8}  {}",
            st.stage,
            st.pid,
            st.state,
            st.restarts,
            st.rate_hz,
            st.latency_p50_ms,
            st.latency_p99_ms,
            st.frames_in,
            st.frames_out,
            st.drops,
            hb,
            st.note
        );
    }
    Ok(())
}

/// Publishes a control request. The returned publisher must stay alive until the supervisor
/// has acted: iceoryx2 withdraws the samples of a dropped publisher that were not yet taken.
fn send_request(
    node: &IpcNode,
    command: ControlCommand,
    stage: &str,
) -> anyhow::Result<TopicPublisher<ControlRequest>> {
    let mut publisher = node.publisher(&topics::SUPERVISOR_CONTROL)?;
    let request = ControlRequest {
        seq: 1,
        sender_pid: std::process::id(),
        command: command as u32,
        stage: encode_name::<NAME_LEN>(stage),
    };
    publisher.publish_copy(&request)?;
    Ok(publisher)
}

/// `hvs restart STAGE`: replaces one stage in place and waits until its new process runs.
pub fn restart(instance: &str, stage: &str, timeout: Duration) -> anyhow::Result<()> {
    if !STAGE_NAMES.contains(&stage) {
        bail!(
            "unknown stage {stage:?}; stages: {}",
            STAGE_NAMES.join(", ")
        );
    }
    let node = client_node(instance, "restart")?;
    let sub = status_subscriber(&node)?;
    let before = next_status(&sub, 0, STATUS_WAIT)?
        .with_context(|| format!("the supervisor of instance {instance:?} sent no status"))?;
    let find = |s: &SupervisorStatus| {
        s.stages
            .iter()
            .take(s.stage_count as usize)
            .find(|e| decode_name(&e.stage) == stage)
            .copied()
    };
    let old =
        find(&before).with_context(|| format!("stage {stage} is not part of this pipeline"))?;
    if old.state == StageState::Disabled as u32 {
        bail!("stage {stage} is disabled in the config of instance {instance:?}");
    }
    let _request = send_request(&node, ControlCommand::Restart, stage)?;
    let deadline = Instant::now() + timeout;
    let mut seq = before.seq;
    while Instant::now() < deadline {
        let Some(s) = next_status(&sub, seq, deadline - Instant::now())? else {
            break;
        };
        seq = s.seq;
        if let Some(e) = find(&s)
            && e.pid != 0
            && e.pid != old.pid
            && e.state == StageState::Running as u32
        {
            println!("restarted {stage}: pid {} -> {}", old.pid, e.pid);
            return Ok(());
        }
    }
    bail!(
        "{stage} was asked to restart but is not running again after {timeout:?}; see `hvs status`"
    )
}

/// True while `pid` exists and has not exited: a zombie (exited, not yet reaped by its
/// parent) counts as exited.
fn process_running(pid: nix::unistd::Pid) -> bool {
    // Signal 0 probes whether the process exists.
    if nix::sys::signal::kill(pid, None).is_err() {
        return false;
    }
    // /proc/<pid>/stat: "pid (comm) STATE ..."; comm may contain spaces, so split after ')'.
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .ok()
        .and_then(|s| {
            s.rsplit_once(')')
                .map(|(_, rest)| rest.trim_start().starts_with('Z'))
        })
        .is_none_or(|zombie| !zombie)
}

/// `hvs stop`: orderly stop of an instance; waits until the supervisor is gone.
pub fn stop(instance: &str, timeout: Duration) -> anyhow::Result<()> {
    let node = client_node(instance, "stop")?;
    let sub = status_subscriber(&node)?;
    let status = next_status(&sub, 0, STATUS_WAIT)?
        .with_context(|| format!("the supervisor of instance {instance:?} sent no status"))?;
    let _request = send_request(&node, ControlCommand::Stop, "")?;
    drop(sub);
    let deadline = Instant::now() + timeout;
    let pid = nix::unistd::Pid::from_raw(status.supervisor_pid as i32);
    while Instant::now() < deadline {
        if !process_running(pid) {
            println!(
                "stopped instance {instance} (supervisor pid {})",
                status.supervisor_pid
            );
            return Ok(());
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    bail!(
        "the supervisor of instance {instance:?} (pid {}) is still running after {timeout:?}",
        status.supervisor_pid
    )
}
