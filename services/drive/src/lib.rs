//! The closed-loop simulator (`hvs sim drive`, and the navigation tests call it directly): the
//! robot's algorithms in a closed loop with the simulated world, in one process and faster
//! than real time.
//!
//! Every step renders the 320x240 stereo pair the robot sees, runs the configured stereo
//! matcher, the fusion path (edges, fused map, window ranges), the decision navigator, and the
//! actuator's commander, whose PSC bytes go to the simulator's PSC emulator with their wire
//! timing; the simulated robot then moves for one step. The same library code runs in the
//! stage processes; only the iceoryx2 hops and the 640x480 worker are left out (the fast path
//! alone drives), so that minutes of driving take seconds and are repeatable. Used by the
//! closed-loop tests and to measure coverage with and without the visit memory.

use std::collections::{BTreeMap, HashSet};
use std::path::PathBuf;

use hvs_actuator::commander::{Commander, DecisionInput};
use hvs_decision::Navigator;
use hvs_fusion::FusionPath;
use hvs_runtime::config::HvsConfig;
use hvs_shared::messages::{IntersectionType, MotionCommand, RangeSource};
use hvs_sim::{GridMap, MapError, Pose, SimConfig, SimRenderError, SimWorld, lock_psc};
use hvs_stereo::{ImageView, StereoError, matcher_for};

/// Why a drive could not run.
#[derive(Debug, thiserror::Error)]
pub enum DriveError {
    /// An option is out of range.
    #[error("{option} {message}")]
    Option {
        /// The option (`--rate-hz`).
        option: &'static str,
        /// What is wrong with it.
        message: String,
    },
    /// The map could not be loaded.
    #[error("map {path}")]
    Map {
        /// The map file.
        path: PathBuf,
        /// Why (boxed: a map error carries the offending line).
        #[source]
        source: Box<MapError>,
    },
    /// The `[stereo.lo]` matcher could not be built or failed.
    #[error("stereo.lo")]
    Matcher(#[from] StereoError),
    /// The simulator could not render a frame.
    #[error("rendering")]
    Render(#[from] SimRenderError),
}

/// What `hvs sim drive` runs.
#[derive(Debug, Clone)]
pub struct DriveOptions {
    /// Map file (`None`: the config's `sim.map`).
    pub map: Option<PathBuf>,
    /// Start pose (default: the map's).
    pub pose: Option<Pose>,
    /// Simulated seconds.
    pub duration_s: f64,
    /// Decision rate, Hz.
    pub rate_hz: f64,
    /// Override of the visit memory setting.
    pub visit_memory: Option<bool>,
    /// Local occupancy map on or off (`None`: the config's `decision.local_map`).
    pub local_map: Option<bool>,
}

/// Decisions per simulated second by default (the camera's rate).
pub const DEFAULT_RATE_HZ: f64 = 15.0;

impl Default for DriveOptions {
    /// The config's map from its start pose, 20 simulated seconds at [`DEFAULT_RATE_HZ`],
    /// the config's navigator settings.
    fn default() -> Self {
        Self {
            map: None,
            pose: None,
            duration_s: 20.0,
            rate_hz: DEFAULT_RATE_HZ,
            visit_memory: None,
            local_map: None,
        }
    }
}

/// The outcome of a drive.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct DriveReport {
    /// Map name.
    pub map: String,
    /// Simulated seconds driven.
    pub duration_s: f64,
    /// Decisions made.
    pub decisions: u64,
    /// Whether the visit memory was on.
    pub visit_memory: bool,
    /// Whether the local occupancy map was on.
    pub local_map: bool,
    /// Collisions with walls (sim ground truth).
    pub collisions: u64,
    /// Distinct map cells the robot's centre entered (sim ground truth).
    pub distinct_cells: usize,
    /// Distance driven, metres (sim odometer).
    pub distance_m: f64,
    /// Start pose `(x_m, y_m, heading_deg)`.
    pub start: (f64, f64, f64),
    /// Final pose `(x_m, y_m, heading_deg)`.
    pub end: (f64, f64, f64),
    /// Final position in the start frame: metres ahead, metres to the left.
    pub end_ahead_m: f64,
    /// See `end_ahead_m`.
    pub end_left_m: f64,
    /// Decisions per intersection type (labels).
    pub intersections: BTreeMap<String, u64>,
    /// Intersection type of each decision before the first turn (labels, in order).
    pub before_first_turn: Vec<String>,
    /// The intersection type and command of the first turn decision, if any.
    pub first_turn: Option<(String, String)>,
    /// Commands sent per motion (labels).
    pub commands: BTreeMap<String, u64>,
    /// Wall-clock seconds the drive took.
    pub wall_s: f64,
}

/// Runs a drive.
pub fn drive(config: &HvsConfig, opts: &DriveOptions) -> Result<DriveReport, DriveError> {
    if !(opts.rate_hz > 0.0 && opts.rate_hz <= 60.0) {
        return Err(DriveError::Option {
            option: "--rate-hz",
            message: format!("{} must be in (0, 60]", opts.rate_hz),
        });
    }
    if !(opts.duration_s > 0.0 && opts.duration_s <= 7200.0) {
        return Err(DriveError::Option {
            option: "--duration",
            message: format!("{} must be in (0, 7200] seconds", opts.duration_s),
        });
    }
    let map_path = opts
        .map
        .clone()
        .unwrap_or_else(|| config.resolve_path(&config.sim.map));
    let map = GridMap::load(&map_path).map_err(|source| DriveError::Map {
        path: map_path.clone(),
        source: Box::new(source),
    })?;
    let (w, h) = (320usize, 240usize);
    let start = opts.pose.unwrap_or_else(|| map.start_pose());
    let map_name = map.name().to_string();
    let cell_m = map.cell_m();
    let mut world = SimWorld::new(map, SimConfig::from_hvs(config, w, h));
    world.set_pose(start);
    let mut matcher = matcher_for(&config.stereo.lo)?;
    let mut fusion = FusionPath::new(config, w, h, RangeSource::Lo);
    let mut decision_cfg = config.decision.clone();
    if let Some(m) = opts.visit_memory {
        decision_cfg.visit_memory = m;
    }
    if let Some(m) = opts.local_map {
        decision_cfg.local_map = m;
    }
    let mut nav = Navigator::new(&decision_cfg, &config.robot, &config.actuator.pulses)
        .with_camera_forward_m(config.camera.forward_m);
    let mut commander = Commander::new(&config.actuator);
    let psc = world.psc();

    let (mut left, mut right) = (vec![0u8; w * h], vec![0u8; w * h]);
    let mut disparity = vec![0u16; w * h];
    let mut cells = HashSet::new();
    let mut intersections: BTreeMap<String, u64> = BTreeMap::new();
    let mut commands: BTreeMap<String, u64> = BTreeMap::new();
    let mut before_first_turn = Vec::new();
    let mut turned = false;
    let mut first_turn = None;
    let dt = 1.0 / opts.rate_hz;
    let steps = (opts.duration_s * opts.rate_hz).round() as u64;
    let started = std::time::Instant::now();
    let ns = |t: f64| (t * 1e9) as u64;
    // Per-decision trace on stderr, for tuning.
    let trace = std::env::var_os("HVS_DRIVE_TRACE").is_some();
    for step in 0..steps {
        let t = step as f64 * dt;
        world.render(t, &mut left, &mut right, None)?;
        let lv = ImageView::new(&left, w, h)?;
        let rv = ImageView::new(&right, w, h)?;
        matcher.compute(lv, rv, &mut disparity)?;
        let (windows, _, _) = fusion.ranges(&left, &disparity, matcher.confidence());
        // The decision is made (and published) after the frame's processing time.
        let now = ns(t) + 1;
        let nd = nav.decide(&windows, config.fusion.windows as usize, fusion.scan(), now);
        if trace {
            let p = world.pose();
            eprintln!(
                "t {t:6.2} coll {} pose ({:5.2},{:5.2},{:6.1}) ranges {} mem {:.2}/{:.2}/{:.2} {} {} dr ({:5.2},{:5.2},{:6.1}) {}",
                world.collisions(),
                p.x_m,
                p.y_m,
                p.heading_deg(),
                windows[..config.fusion.windows as usize]
                    .iter()
                    .map(|w| format!("{:.2}m/{:.2}n/{}px", w.range_m, w.near_m, w.valid_px))
                    .collect::<Vec<_>>()
                    .join(" "),
                nd.memberships.left,
                nd.memberships.front,
                nd.memberships.right,
                nd.intersection.label(),
                nd.command.label(),
                nd.pose.x_m,
                nd.pose.y_m,
                nd.pose.heading_rad.to_degrees(),
                nav.describe()
            );
        }
        if let Some(_at) = std::env::var("HVS_DRIVE_MAP_AT")
            .ok()
            .and_then(|v| v.parse::<f64>().ok())
            .filter(|&at| (t - at).abs() < 0.5 * dt)
        {
            eprintln!(
                "local map at t {t:.2} (dead-reckoned pose {:.2},{:.2}):\n{}",
                nd.pose.x_m,
                nd.pose.y_m,
                nav.local_map().ascii(nd.pose.x_m, nd.pose.y_m, 2.0, now)
            );
        }
        *intersections
            .entry(nd.intersection.label().to_string())
            .or_default() += 1;
        if !turned && matches!(nd.command, MotionCommand::Left | MotionCommand::Right) {
            turned = true;
            first_turn = Some((
                nd.intersection.label().to_string(),
                nd.command.label().to_string(),
            ));
        }
        if !turned && nd.intersection != IntersectionType::Unknown {
            before_first_turn.push(nd.intersection.label().to_string());
        }
        commander.on_decision(DecisionInput {
            frame_id: step,
            capture_ns: ns(t),
            published_ns: now,
            command: nd.command,
            ramp: nd.ramp.min(63) as u8,
        });
        // The actuator polls the wire until the next frame.
        let mut poll_t = t;
        while poll_t < t + dt {
            if let Some(out) = commander.poll(ns(poll_t)) {
                lock_psc(&psc).receive(&out.bytes, poll_t);
                commander.mark_sent(ns(poll_t), &out);
                nav.on_sent(ns(poll_t), out.left_pw, out.right_pw, out.ramp);
                *commands.entry(out.command.label().to_string()).or_default() += 1;
            }
            poll_t += 0.005;
        }
        world.advance_to(t + dt);
        let p = world.pose();
        cells.insert((
            (p.x_m / cell_m).floor() as i64,
            (p.y_m / cell_m).floor() as i64,
        ));
    }
    let end = world.pose();
    let delta = end.position() - start.position();
    let truth = world.ground_truth();
    Ok(DriveReport {
        map: map_name,
        duration_s: steps as f64 * dt,
        decisions: steps,
        visit_memory: decision_cfg.visit_memory,
        local_map: decision_cfg.local_map,
        collisions: truth.collisions,
        distinct_cells: cells.len(),
        distance_m: truth.odometer_m,
        start: (start.x_m, start.y_m, start.heading_deg()),
        end: (end.x_m, end.y_m, end.heading_deg()),
        end_ahead_m: delta.dot(start.forward()),
        end_left_m: delta.dot(start.left()),
        intersections,
        before_first_turn,
        first_turn,
        commands,
        wall_s: started.elapsed().as_secs_f64(),
    })
}
