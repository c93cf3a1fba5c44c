//! Bridge stage process: opens the zenoh session, the allow-listed ports each way and the
//! ROS 2 publications, then moves samples whenever a local topic or the zenoh side has one.
//! Incoming samples arrive on zenoh's threads and wait in bounded queues; the WaitSet cannot
//! wait on those, so while anything comes in it also wakes every 2 ms to publish them (the
//! hop's added wait, at most 2 ms, is in the measured hop latency).

use std::process::ExitCode;
use std::time::{Duration, Instant};

use zenoh::Wait;

use hvs_bridge::ports::{Direction, Port, open_port};
use hvs_bridge::ros::publish::RosOut;
use hvs_bridge::session;
use hvs_runtime::clock::monotonic_ns;
use hvs_runtime::config::BridgeMode;
use hvs_runtime::ipc::attach_interval;
use hvs_runtime::stage::{LoopControl, StageError, StageRuntime, run_stage};
use hvs_shared::messages::{BridgeStats, MAX_BRIDGE_TOPICS, StageHealth};
use hvs_shared::topics::{self, Stage};

/// How often queued incoming samples are published.
const INCOMING_PERIOD: Duration = Duration::from_millis(2);
/// How often the stats are published and the note updated.
const STATS_PERIOD: Duration = Duration::from_secs(1);

fn main() -> ExitCode {
    run_stage(Stage::Bridge, run)
}

fn run(rt: &mut StageRuntime) -> Result<(), StageError> {
    let cfg = rt.config.bridge.clone();
    tracing::info!(
        "zenoh {:?}, listen {:?}, connect {:?}, multicast scouting off; out {:?}, in {:?}",
        cfg.mode,
        cfg.listen,
        cfg.connect,
        cfg.publish.iter().map(|t| t.path()).collect::<Vec<_>>(),
        cfg.subscribe.iter().map(|t| t.path()).collect::<Vec<_>>()
    );
    let session = session::open(&cfg)?;
    let mut ports: Vec<Box<dyn Port>> = Vec::new();
    for t in &cfg.publish {
        ports.push(open_port(&rt.node, &session, &cfg, *t, Direction::Out)?);
    }
    for t in &cfg.subscribe {
        ports.push(open_port(&rt.node, &session, &cfg, *t, Direction::In)?);
    }
    let ros = if cfg.ros.enabled {
        Some(RosOut::open(&rt.node, &session, &rt.config)?)
    } else {
        None
    };
    let mut stats_pub = rt.node.publisher(&topics::BRIDGE_STATS)?;

    let waitset = rt.waitset()?;
    let mut guards = Vec::new();
    for p in &ports {
        if let Some(l) = p.listener() {
            guards.push(
                waitset.attach_notification(l).map_err(|e| {
                    StageError::from(format!("cannot wait on {}: {e:?}", p.topic()))
                })?,
            );
        }
    }
    if let Some(r) = &ros {
        for l in r.listeners() {
            guards.push(
                waitset
                    .attach_notification(l)
                    .map_err(|e| StageError::from(format!("cannot wait on a ROS input: {e:?}")))?,
            );
        }
    }
    let _tick = if cfg.subscribe.is_empty() {
        None
    } else {
        Some(attach_interval(&waitset, INCOMING_PERIOD)?)
    };

    let mut last_stats = Instant::now();
    let mut seq = 0u64;
    let mut last_counts = (0u64, 0u64);
    rt.run_loop(&waitset, |rt, _id| {
        let t0 = monotonic_ns();
        let mut moved = 0;
        for p in &ports {
            moved += p.pump()?;
        }
        if let Some(r) = &ros {
            moved += r.pump()?;
        }
        if moved > 0 {
            rt.count_in(moved as u64);
            rt.count_out(monotonic_ns() - t0);
        }
        if last_stats.elapsed() >= STATS_PERIOD {
            last_stats = Instant::now();
            let info = session.info();
            let peers = match cfg.mode {
                BridgeMode::Peer => info.peers_zid().wait().count(),
                BridgeMode::Client => info.routers_zid().wait().count(),
            };
            let mut stats = BridgeStats {
                seq: {
                    seq += 1;
                    seq
                },
                time_ns: monotonic_ns(),
                peers: peers as u32,
                ..Default::default()
            };
            let mut entries: Vec<_> = ports.iter().map(|p| p.stats()).collect();
            if let Some(r) = &ros {
                entries.extend(r.stats());
            }
            let (mut out, mut inc, mut dropped, mut rejected) = (0, 0, 0, 0);
            for (slot, e) in stats.topics.iter_mut().zip(&entries) {
                *slot = *e;
            }
            for e in &entries {
                if e.direction == Direction::Out as u32 {
                    out += e.messages;
                } else {
                    inc += e.messages;
                    dropped += e.dropped;
                    rejected += e.rejected;
                }
            }
            stats.topic_count = entries.len().min(MAX_BRIDGE_TOPICS) as u32;
            if let Err(e) = stats_pub.publish_copy(&stats) {
                rt.report_error("bridge/stats", &e);
            }
            let secs = STATS_PERIOD.as_secs_f64();
            let note = format!(
                "peers {peers} out {:.0}/s in {:.0}/s dropped {dropped} rejected {rejected}",
                (out - last_counts.0) as f64 / secs,
                (inc - last_counts.1) as f64 / secs,
            );
            last_counts = (out, inc);
            rt.set_drops(dropped);
            rt.set_health(if peers == 0 {
                StageHealth::Degraded
            } else {
                StageHealth::Running
            });
            rt.set_note(note);
        }
        Ok(LoopControl::Continue)
    })?;
    drop(guards);
    Ok(())
}
