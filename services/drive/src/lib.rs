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
//!
//! The report counts, besides collisions and distance, how much of the map the camera saw
//! ([`coverage`]: the reachable floor cells whose centre was within 2 m, in the field of view
//! and in sight) and when. The options can make the drive harder than the config: plain
//! walls (`wall_contrast`), wheel slip (`motion_noise`, which makes dead reckoning drift),
//! another seed, or a freshly generated maze (`maze`, [`hvs_sim::maze`]).

pub mod coverage;

mod diagnose;

use std::collections::{BTreeMap, HashSet};
use std::path::PathBuf;

use hvs_actuator::commander::{Commander, DecisionInput};
use hvs_decision::Navigator;
use hvs_fusion::FusionPath;
use hvs_runtime::config::HvsConfig;
use hvs_runtime::stats::{LatencySummary, LatencyWindow};
use hvs_shared::messages::{IntersectionType, MotionCommand, RangeSource};
use hvs_sim::{
    GridMap, MapError, MazeError, MazeOptions, Pose, SimConfig, SimMotionNoise, SimRenderError,
    SimWorld, generate_maze, lock_psc,
};
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
    /// The maze could not be generated.
    #[error("maze")]
    Maze(#[from] MazeError),
}

/// What `hvs sim drive` runs.
#[derive(Debug, Clone)]
pub struct DriveOptions {
    /// Map file (`None`: the config's `sim.map`, unless `maze` is given).
    pub map: Option<PathBuf>,
    /// Drive a maze generated in memory instead of a map file (not with `map`).
    pub maze: Option<MazeOptions>,
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
    /// Wall contrast, 0..=1 (`None`: the map's `@wall_contrast`, 1 without one): 0 gives
    /// plain painted walls, with only the camera's noise on them.
    pub wall_contrast: Option<f64>,
    /// Wheel slip and speed errors (`None`: the config's `[sim.motion]`);
    /// [`SimMotionNoise::realistic`] is `hvs sim drive --motion-noise`.
    pub motion_noise: Option<SimMotionNoise>,
    /// Seed of the images' and the motion's noise (`None`: the config's `sim.seed`).
    pub seed: Option<u64>,
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
            wall_contrast: None,
            motion_noise: None,
            seed: None,
            maze: None,
        }
    }
}

/// Simulated seconds between two points of [`DriveReport::coverage_curve`].
pub const COVERAGE_SAMPLE_S: f64 = 30.0;

/// Coverage at which a map counts as explored ([`DriveReport::explored_s`]), percent.
pub const EXPLORED_PCT: f64 = 95.0;

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
    /// Whether the local occupancy map was filled (`DecisionConfig::fills_local_map`).
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
    /// Time the navigator took per decision on this machine (wall clock, not simulated):
    /// count, median, 99th percentile and largest, nanoseconds.
    pub decision_latency: LatencySummary,
    /// Share of the map's reachable floor cells (4-connected to the start cell) the camera
    /// saw, percent: the cell's centre within 2 m of the camera, inside its horizontal field
    /// of view and in its line of sight, at some frame (sim ground truth, [`coverage`]).
    #[serde(default)]
    pub coverage_pct: f64,
    /// Reachable floor cells of the map (what `coverage_pct` is a share of).
    #[serde(default)]
    pub reachable_cells: usize,
    /// Simulated seconds at which the coverage first reached 95 % (`None`: never).
    #[serde(default)]
    pub explored_s: Option<f64>,
    /// `(simulated seconds, coverage_pct)` every 30 simulated seconds, and at the end.
    #[serde(default)]
    pub coverage_curve: Vec<(f64, f64)>,
    /// `distinct_cells / distance_m` (0 when the robot did not move).
    #[serde(default)]
    pub cells_per_m: f64,
    /// The wall contrast driven with (0 plain paint .. 1 the full texture).
    #[serde(default)]
    pub wall_contrast: f64,
    /// Whether the robot's wheels slipped (`[sim.motion]` or `motion_noise` on).
    #[serde(default)]
    pub motion_noise: bool,
    /// Seed of the images' and the motion's noise.
    #[serde(default)]
    pub seed: u64,
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
    if let Some(c) = opts.wall_contrast
        && !(0.0..=1.0).contains(&c)
    {
        return Err(DriveError::Option {
            option: "--wall-contrast",
            message: format!("{c} must be in 0..=1"),
        });
    }
    if let Some(m) = &opts.motion_noise {
        m.validate().map_err(|e| DriveError::Option {
            option: "--motion-noise",
            message: format!("{} {}", e.key, e.message),
        })?;
    }
    let mut map = load_map(config, opts)?;
    if let Some(c) = opts.wall_contrast {
        map.set_wall_contrast(c);
    }
    let (w, h) = (320usize, 240usize);
    let start = opts.pose.unwrap_or_else(|| map.start_pose());
    let map_name = map.name().to_string();
    let cell_m = map.cell_m();
    let wall_contrast = map.wall_contrast();
    let mut sim_config = SimConfig::from_hvs(config, w, h);
    if let Some(m) = opts.motion_noise {
        sim_config.motion = m;
    }
    if let Some(seed) = opts.seed {
        sim_config.seed = seed;
    }
    let mut world = SimWorld::new(map, sim_config);
    world.set_pose(start);
    let mut seen = coverage::Coverage::for_rig(world.map(), &start, world.rig());
    let mut coverage_curve = Vec::new();
    let mut explored_s = None;
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
        .with_camera_forward_m(config.camera.forward_m)
        .with_nav(&config.nav, &config.robot, &config.actuator.pulses)
        .with_matcher_reach(config.stereo.lo.max_disp, w as u32);
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
    let mut decision_latency = LatencyWindow::default();
    let ns = |t: f64| (t * 1e9) as u64;
    // Per-decision trace on stderr, for tuning.
    let trace = std::env::var_os("HVS_DRIVE_TRACE").is_some();
    let trace_scan = trace && std::env::var_os("HVS_DRIVE_TRACE_SCAN").is_some();
    for step in 0..steps {
        let t = step as f64 * dt;
        world.render(t, &mut left, &mut right, None)?;
        // What this frame shows: the camera at the left image's pose.
        let camera = coverage::camera_pose(&world.pose_at(t), world.rig());
        seen.observe(world.map(), &camera);
        if explored_s.is_none() && seen.pct() >= EXPLORED_PCT {
            explored_s = Some(t);
        }
        let lv = ImageView::new(&left, w, h)?;
        let rv = ImageView::new(&right, w, h)?;
        matcher.compute(lv, rv, &mut disparity)?;
        let (windows, _, _) = fusion.ranges(&left, &disparity, matcher.confidence());
        // The decision is made (and published) after the frame's processing time.
        let now = ns(t) + 1;
        let decide_started = std::time::Instant::now();
        let nd = nav.decide(&windows, config.fusion.windows as usize, fusion.scan(), now);
        decision_latency.record(decide_started.elapsed().as_nanos() as u64);
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
            if trace_scan {
                // The obstacle scan's 64 depths (0 = no data), to compare with the true
                // pose's ray casts when tuning perception.
                let sc = fusion.scan();
                eprintln!(
                    "scan {t:6.2} {} {}",
                    sc.tan_half_fov,
                    diagnose::depths_text(&sc.range_m)
                );
                // The same bins' depths from the true pose of the frame (the left eye).
                let truth =
                    diagnose::true_scan_depths(world.map(), world.rig(), &world.pose_at(t), sc);
                eprintln!("truth {t:6.2} {}", diagnose::depths_text(&truth));
            }
        }
        if let Some(_at) = std::env::var("HVS_DRIVE_MAP_AT")
            .ok()
            .and_then(|v| v.parse::<f64>().ok())
            .filter(|&at| (t - at).abs() < 0.5 * dt)
        {
            if let Some(e) = nav.explorer() {
                eprintln!(
                    "explorer grid at t {t:.2} (dead-reckoned pose {:.2},{:.2}):\n{}",
                    nd.pose.x_m,
                    nd.pose.y_m,
                    e.grid().ascii(nd.pose.x_m, nd.pose.y_m, 4.0)
                );
            } else {
                eprintln!(
                    "local map at t {t:.2} (dead-reckoned pose {:.2},{:.2}):\n{}",
                    nd.pose.x_m,
                    nd.pose.y_m,
                    nav.local_map().ascii(nd.pose.x_m, nd.pose.y_m, 2.0, now)
                );
            }
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
        let collisions_before = world.collisions();
        world.advance_to(t + dt);
        let p = world.pose();
        if trace && let Some(e) = nav.explorer() {
            let each_second = step % (opts.rate_hz.round().max(1.0) as u64) == 0;
            let collided = world.collisions() > collisions_before;
            diagnose::trace(
                &diagnose::Scene {
                    map: world.map(),
                    truth: &p,
                    believed: &nd.pose,
                    grid: e.grid(),
                    robot: &config.robot,
                },
                t,
                each_second,
                collided,
            );
        }
        cells.insert((
            (p.x_m / cell_m).floor() as i64,
            (p.y_m / cell_m).floor() as i64,
        ));
        // A point of the curve at every multiple of 30 s (the frames before it counted).
        let sample_t = (coverage_curve.len() + 1) as f64 * COVERAGE_SAMPLE_S;
        if (step + 1) as f64 * dt >= sample_t - 1e-9 {
            coverage_curve.push((sample_t, seen.pct()));
        }
    }
    let duration_s = steps as f64 * dt;
    if coverage_curve
        .last()
        .is_none_or(|&(t, _)| (t - duration_s).abs() > 1e-9)
    {
        coverage_curve.push((duration_s, seen.pct()));
    }
    let end = world.pose();
    let delta = end.position() - start.position();
    let truth = world.ground_truth();
    let distance_m = truth.odometer_m;
    Ok(DriveReport {
        map: map_name,
        duration_s,
        decisions: steps,
        visit_memory: decision_cfg.visit_memory,
        local_map: decision_cfg.fills_local_map(),
        collisions: truth.collisions,
        distinct_cells: cells.len(),
        distance_m,
        start: (start.x_m, start.y_m, start.heading_deg()),
        end: (end.x_m, end.y_m, end.heading_deg()),
        end_ahead_m: delta.dot(start.forward()),
        end_left_m: delta.dot(start.left()),
        intersections,
        before_first_turn,
        first_turn,
        commands,
        wall_s: started.elapsed().as_secs_f64(),
        decision_latency: decision_latency.summary(),
        coverage_pct: seen.pct(),
        reachable_cells: seen.reachable_cells(),
        explored_s,
        coverage_curve,
        cells_per_m: if distance_m > 1e-9 {
            cells.len() as f64 / distance_m
        } else {
            0.0
        },
        wall_contrast,
        motion_noise: world.robot().motion_noise().is_some(),
        seed: sim_config.seed,
    })
}

/// The map to drive: the generated maze, the map file given, or the config's.
fn load_map(config: &HvsConfig, opts: &DriveOptions) -> Result<GridMap, DriveError> {
    if let Some(maze) = &opts.maze {
        if opts.map.is_some() {
            return Err(DriveError::Option {
                option: "--maze-seed",
                message: "and --map cannot both be given".to_string(),
            });
        }
        let m = generate_maze(maze)?;
        let name = format!("maze-{}", maze.seed);
        return GridMap::parse(&m.text, &name).map_err(|source| DriveError::Map {
            path: PathBuf::from(name),
            source: Box::new(source),
        });
    }
    let map_path = opts
        .map
        .clone()
        .unwrap_or_else(|| config.resolve_path(&config.sim.map));
    GridMap::load(&map_path).map_err(|source| DriveError::Map {
        path: map_path.clone(),
        source: Box::new(source),
    })
}

#[cfg(test)]
mod tests;
