//! View stage process: subscribes to the pipeline's topics and serves them to Foxglove
//! clients and the web page. The receive loop only copies what a subscribed channel needs and
//! hands images to the encoder thread; JSON messages (small) are sent from here.

use std::net::SocketAddr;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicU16, Ordering};
use std::time::{Duration, Instant};

use foxglove::messages::{Log, log::Level};
use hvs_probe::schemas::{FoxgloveJson, pose_transforms};
use hvs_runtime::clock::{WallClock, monotonic_ns};
use hvs_runtime::ipc::TopicSubscriber;
use hvs_runtime::stage::{LoopControl, StageError, StageRuntime, run_stage};
use hvs_shared::messages::{Sequenced, StageHealth};
use hvs_shared::topics::{self, Stage};
use hvs_view::channels::{JsonChannel, ViewChannels};
use hvs_view::encode::{calibration, frame_transforms, nav_grid, stamp};
use hvs_view::health::{
    Legend, StageChanges, legend_json, sim_truth_json, stage_log, stage_table_json,
};
use hvs_view::note;
use hvs_view::pacing::RateLimit;
use hvs_view::page::PageServer;
use hvs_view::worker::{DisparityJob, Encoder, EncoderSettings, ImageJob};

/// Frames whose left image is kept for pairing with a later disparity map.
const LEFT_KEPT: usize = 4;
/// How often a failed server start is retried.
const RETRY_PERIOD: Duration = Duration::from_secs(2);

fn main() -> ExitCode {
    run_stage(Stage::View, run)
}

/// The servers, started (and retried) while the stage runs.
struct Servers {
    ws: Option<foxglove::WebSocketServerHandle>,
    ws_error: Option<String>,
    page: Option<PageServer>,
    page_error: Option<String>,
    ws_port: Arc<AtomicU16>,
    last_try: Option<Instant>,
}

impl Servers {
    fn ensure(&mut self, channels: &ViewChannels, ws_addr: SocketAddr, http_addr: SocketAddr) {
        if self.ws.is_some() && self.page.is_some() {
            return;
        }
        if self.last_try.is_some_and(|t| t.elapsed() < RETRY_PERIOD) {
            return;
        }
        self.last_try = Some(Instant::now());
        if self.ws.is_none() {
            match foxglove::WebSocketServer::new()
                .name("hvs")
                .context(&channels.context)
                .bind(ws_addr.ip().to_string(), ws_addr.port())
                .start_blocking()
            {
                Ok(h) => {
                    self.ws_port.store(h.port(), Ordering::Relaxed);
                    tracing::info!(
                        "Foxglove WebSocket server on ws://{}:{} (Foxglove or Lichtblick: Open connection)",
                        ws_addr.ip(),
                        h.port()
                    );
                    self.ws = Some(h);
                    self.ws_error = None;
                }
                Err(e) => {
                    if self.ws_error.is_none() {
                        tracing::warn!("cannot serve ws://{ws_addr}: {e}; retrying every 2 s");
                    }
                    self.ws_error = Some(format!("ws {ws_addr}: {e}"));
                }
            }
        }
        if self.page.is_none() {
            match PageServer::start(http_addr, Arc::clone(&self.ws_port)) {
                Ok(p) => {
                    tracing::info!("web page on http://{}", p.addr());
                    self.page = Some(p);
                    self.page_error = None;
                }
                Err(e) => {
                    if self.page_error.is_none() {
                        tracing::warn!("{e}; retrying every 2 s");
                    }
                    self.page_error = Some(e.to_string());
                }
            }
        }
    }

    fn note(&self) -> String {
        let ws = note::ws_part(match &self.ws {
            Some(h) => Ok((h.port(), h.client_count())),
            None => Err(self.ws_error.as_deref().unwrap_or("ws starting")),
        });
        let http = note::http_part(match &self.page {
            Some(p) => Ok(p.addr().port()),
            None => Err(self.page_error.as_deref().unwrap_or("http starting")),
        });
        format!("{ws} {http}")
    }

    fn healthy(&self) -> bool {
        self.ws.is_some() && self.page.is_some()
    }
}

/// Sends every queued sample of a small topic as JSON while a client subscribes.
fn forward_json<T>(
    sub: &TopicSubscriber<T>,
    channel: &JsonChannel,
    wall: &dyn Fn(u64) -> u64,
    rt: &mut StageRuntime,
) -> Result<(), StageError>
where
    T: FoxgloveJson + core::fmt::Debug + iceoryx2::prelude::ZeroCopySend + Sequenced + 'static,
{
    while let Some(s) = sub.receive()? {
        rt.count_in(1);
        if channel.wanted() {
            let t0 = monotonic_ns();
            let p = s.payload();
            channel.log(&p.to_foxglove_json(), wall(p.log_monotonic_ns()));
            rt.count_out(monotonic_ns() - t0);
        }
    }
    Ok(())
}

fn run(rt: &mut StageRuntime) -> Result<(), StageError> {
    let view = rt.config.view.clone();
    let ws_addr = view
        .bind_addr()
        .map_err(|e| StageError::from(format!("view.bind: {e}")))?;
    let http_addr = view
        .http_addr()
        .map_err(|e| StageError::from(format!("view.http_bind: {e}")))?;
    let channels = Arc::new(
        ViewChannels::new().map_err(|e| StageError::from(format!("foxglove channels: {e}")))?,
    );
    let settings = EncoderSettings::of(&rt.config);
    let camera = rt.config.camera.clone();
    let encoder = Encoder::start(Arc::clone(&channels), settings.clone())
        .map_err(|e| StageError::from(format!("cannot start the encoder thread: {e}")))?;

    let frames = rt.node.subscriber(&topics::FRAMES_LO, 2)?;
    let disparity = rt.node.subscriber(&topics::DISPARITY_LO, 2)?;
    let ranges = rt.node.subscriber(&topics::RANGES, 4)?;
    let decisions = rt.node.subscriber(&topics::DECISIONS, 4)?;
    let sent = rt.node.subscriber(&topics::ACTUATOR_SENT, 8)?;
    let poses = rt.node.subscriber(&topics::DECISION_POSE, 4)?;
    let maps = rt.node.subscriber(&topics::NAV_MAP, 1)?;
    let truth = rt.node.subscriber(&topics::SIM_TRUTH, 2)?;
    let status = rt.node.subscriber(&topics::SUPERVISOR_STATUS, 1)?;
    let log_lines = rt.node.subscriber(&topics::LOG, topics::LOG.max_buffer)?;

    // Foxglove shows wall-clock times.
    let clock = WallClock::now();
    let wall = move |mono_ns: u64| clock.wall_ns(mono_ns);
    let mut servers = Servers {
        ws: None,
        ws_error: None,
        page: None,
        page_error: None,
        ws_port: Arc::new(AtomicU16::new(0)),
        last_try: None,
    };
    servers.ensure(&channels, ws_addr, http_addr);

    let mut image_rate = RateLimit::new(view.image_hz);
    let mut disparity_rate = RateLimit::new(view.disparity_hz);
    let mut truth_rate = RateLimit::new(10.0);
    let mut left_kept: Vec<(u64, Arc<[u8]>)> = Vec::with_capacity(LEFT_KEPT);
    let mut changes = StageChanges::default();
    let mut last_second = Instant::now() - Duration::from_secs(2);
    let lo = &rt.config.decision.lo;
    let mut legend = Legend {
        near_m: 0.0,
        far_m: 0.0,
        side_wall_m: lo.side_m,
        front_wall_m: lo.front_m,
    };

    let waitset = rt.waitset()?;
    let _frames_guard = frames.attach_to(&waitset)?;
    let _ranges_guard = ranges.attach_to(&waitset)?;
    let _status_guard = status.attach_to(&waitset)?;

    rt.run_loop(&waitset, |rt, _id| {
        for sub in [frames.listener(), ranges.listener(), status.listener()] {
            let _ = sub.try_wait(|_| {});
        }
        servers.ensure(&channels, ws_addr, http_addr);

        // Left images: copied out of shared memory once, and only for a subscribed channel;
        // the image job and the frames kept for pairing share that copy.
        let pair_left = channels.fused.has_sinks() || channels.points.has_sinks();
        while let Some(f) = frames.receive()? {
            rt.count_in(1);
            let p = f.payload();
            let send = channels.left.has_sinks() && image_rate.admit(p.header.capture_ns);
            if !send && !pair_left {
                continue;
            }
            let left: Arc<[u8]> = Arc::from(&p.left[..]);
            if send {
                encoder.images.send(ImageJob {
                    left: Arc::clone(&left),
                    wall_ns: wall(p.header.capture_ns),
                });
            }
            if pair_left {
                if left_kept.len() == LEFT_KEPT {
                    left_kept.remove(0);
                }
                left_kept.push((p.header.frame_id, left));
            }
        }
        let need_disparity = channels.disparity.has_sinks()
            || channels.fused.has_sinks()
            || channels.points.has_sinks();
        while let Some(d) = disparity.receive()? {
            rt.count_in(1);
            let m = d.payload();
            // The legend follows the searched range of the newest map.
            let scale = settings.scale(m.header.min_disp, m.header.max_disp);
            legend.near_m = scale.near_m();
            legend.far_m = scale.far_m();
            if !need_disparity || !disparity_rate.admit(m.header.capture_ns) {
                continue;
            }
            let left = left_kept
                .iter()
                .find(|(id, _)| *id == m.header.frame_id)
                .map_or_else(
                    || Arc::from(vec![0; m.disparity_q8.len()]),
                    |(_, l)| Arc::clone(l),
                );
            encoder.disparities.send(DisparityJob {
                left,
                disparity_q8: m.disparity_q8.to_vec(),
                confidence: m.confidence.to_vec(),
                min_disp: m.header.min_disp,
                max_disp: m.header.max_disp,
                wall_ns: wall(m.header.capture_ns),
            });
        }

        forward_json(&ranges, &channels.ranges, &wall, rt)?;
        forward_json(&decisions, &channels.decisions, &wall, rt)?;
        forward_json(&sent, &channels.actuator, &wall, rt)?;
        while let Some(s) = poses.receive()? {
            rt.count_in(1);
            let p = s.payload();
            let t = wall(p.published_ns);
            if channels.pose.wanted() {
                channels.pose.log(&p.to_foxglove_json(), t);
                rt.count_out(0);
            }
            if channels.transforms.has_sinks() {
                let tf = frame_transforms(&pose_transforms(p, &camera), t);
                channels.transforms.log_with_time(&tf, t);
                rt.count_out(0);
            }
        }
        if let Some(m) = maps.receive_latest()? {
            rt.count_in(1);
            if channels.map.has_sinks() {
                let t0 = monotonic_ns();
                let p = m.payload();
                channels
                    .map
                    .log_with_time(&nav_grid(p, wall(p.published_ns)), wall(p.published_ns));
                rt.count_out(monotonic_ns() - t0);
            }
        }
        if let Some(t) = truth.receive_latest()? {
            rt.count_in(1);
            let p = t.payload();
            if channels.sim_truth.wanted() && truth_rate.admit(p.time_ns) {
                channels.sim_truth.log(&sim_truth_json(p), wall(p.time_ns));
                rt.count_out(0);
            }
        }
        if let Some(s) = status.receive_latest()? {
            rt.count_in(1);
            let p = s.payload();
            let t = wall(p.time_ns);
            if channels.stages.wanted() {
                channels.stages.log(&stage_table_json(p), t);
                rt.count_out(0);
            }
            // The supervisor logs these changes itself; here they only go to /log.
            for line in changes.lines(p) {
                tracing::debug!("{}", line.text);
                if channels.log.has_sinks() {
                    channels.log.log_with_time(
                        &Log {
                            timestamp: Some(stamp(t)),
                            level: if line.warning {
                                Level::Warning
                            } else {
                                Level::Info
                            } as i32,
                            message: line.text,
                            name: "supervisor".into(),
                            ..Default::default()
                        },
                        t,
                    );
                }
            }
        }

        while let Some(l) = log_lines.receive()? {
            rt.count_in(1);
            if channels.log.has_sinks() {
                let p = l.payload();
                let t = wall(p.time_ns);
                channels.log.log_with_time(&stage_log(p, t), t);
                rt.count_out(0);
            }
        }

        // Once a second: what changes rarely, and the stage's own status.
        if last_second.elapsed() >= Duration::from_secs(1) {
            last_second = Instant::now();
            let t = wall(monotonic_ns());
            if channels.calibration.has_sinks() {
                channels
                    .calibration
                    .log_with_time(&calibration(&settings.pinhole, t), t);
            }
            if channels.legend.wanted() && legend.far_m > 0.0 {
                channels.legend.log(&legend_json(&legend), t);
            }
            rt.set_note(servers.note());
            rt.set_health(if servers.healthy() && !encoder.has_ended() {
                StageHealth::Running
            } else {
                StageHealth::Degraded
            });
            if encoder.has_ended() {
                return Err(StageError::from("the encoder thread ended"));
            }
        }
        while let Ok(done) = encoder.done.try_recv() {
            for _ in 0..done.messages {
                rt.count_out(done.busy_ns / done.messages.max(1));
            }
            for _ in 0..done.errors {
                rt.count_error();
            }
        }
        Ok(LoopControl::Continue)
    })
}
