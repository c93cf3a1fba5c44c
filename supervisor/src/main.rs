//! `hvs`: run the robot pipeline and the tools around it.

mod bench;
mod bench_stages;
mod bench_view;
mod control;
mod doctor;
mod drive;
mod policy;
mod probe_cli;
mod process;
mod procstat;
mod report;
mod run;
mod soak;
mod stereo_cli;

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use clap::{Parser, Subcommand};
use hvs_runtime::config::HvsConfig;

/// hvs: a hybrid stereo-vision system that drives a small robot down hallways.
#[derive(Debug, Parser)]
#[command(version, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the whole pipeline (default: the simulated robot of config/sim.toml).
    ///
    /// Every stage runs as its own process; a stage that dies or hangs is restarted by its
    /// policy without touching the others. Ctrl-C stops the actuator first (neutral pulses),
    /// then the rest.
    Run {
        /// Pipeline configuration (default: config/sim.toml).
        #[arg(long, value_name = "FILE")]
        config: Option<PathBuf>,
        /// Instance name (overrides the config's `instance`).
        #[arg(long, value_name = "NAME")]
        instance: Option<String>,
        /// Stop after this many seconds.
        #[arg(long, value_name = "SECONDS")]
        duration: Option<f64>,
        /// Write a JSON report (per-stage counters, latencies) here when stopping.
        #[arg(long, value_name = "FILE")]
        report: Option<PathBuf>,
        /// Play an MCAP recording through the pipeline instead of the config's frame source
        /// (no simulator, no actuator: the recorded actuator output is re-published); stops at
        /// the end of the recording. In lockstep (the default) the decisions repeat the
        /// recorded ones frame for frame.
        #[arg(long, value_name = "FILE.mcap")]
        replay: Option<PathBuf>,
        /// Record the run to an MCAP file from before its first frame (what `hvs probe
        /// record` records: both pairs, ranges, decisions, actuator output).
        #[arg(long, value_name = "FILE.mcap")]
        record: Option<PathBuf>,
        /// Start the zenoh bridge listening here, e.g. tcp/127.0.0.1:7447 (added to
        /// `[bridge] listen`; repeatable). Loopback keeps it on this machine; the robot's
        /// address lets another computer connect (docs/distributed.md).
        #[arg(long, value_name = "ENDPOINT")]
        bridge_listen: Vec<String>,
        /// Start the zenoh bridge connecting to this peer or router, e.g.
        /// tcp/192.168.1.20:7447 (added to `[bridge] connect`; repeatable; retried while
        /// it is down).
        #[arg(long, value_name = "ENDPOINT")]
        bridge_connect: Vec<String>,
    },
    /// Check a config without starting anything: the schema, every section's ranges, the
    /// stage graph (a frame source, every enabled stage's inputs published), the stereo
    /// matchers' parameters and the simulator's map. Exit 0 when it is good, 1 otherwise,
    /// with the file, key and line at fault.
    Check {
        /// Pipeline configuration (default: config/sim.toml).
        #[arg(long, value_name = "FILE")]
        config: Option<PathBuf>,
    },
    /// Check what a robot needs before `hvs run`: the config, the cameras (stable names,
    /// formats, both streaming together), the serial device and the servo controller,
    /// /dev/shm space, leftovers of a dead run. One line per check with what to do about
    /// it; exit 0 when nothing fails, 1 otherwise.
    Doctor {
        /// Pipeline configuration (default: config/sim.toml; the robot's is
        /// config/minoru.toml).
        #[arg(long, value_name = "FILE")]
        config: Option<PathBuf>,
    },
    /// Show the stages of a running pipeline: pid, state, restarts, rate, latency.
    Status {
        #[command(flatten)]
        target: Target,
        /// Print JSON instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Replace one stage of a running pipeline in place; the others keep running.
    Restart {
        /// Stage to restart (sim, capture, stereo-lo, stereo-hi, fusion, decision, actuator).
        stage: String,
        #[command(flatten)]
        target: Target,
        /// Give up waiting for the new process after this many seconds.
        #[arg(long, default_value_t = 15.0, value_name = "SECONDS")]
        timeout: f64,
    },
    /// Compute one disparity map: `--left L.png --right R.png --out D.png` (16-bit PNG,
    /// disparity x 256, 0 = invalid: the KITTI convention).
    Stereo {
        /// Algorithm: bm-sad, bm-ssd, bm-ncc, bm-census, ogale, sgm (default: the config's).
        #[arg(long)]
        algo: Option<String>,
        /// Left image (PNG; colour is converted to grey).
        #[arg(long, value_name = "FILE")]
        left: PathBuf,
        /// Right image.
        #[arg(long, value_name = "FILE")]
        right: PathBuf,
        /// Output disparity PNG.
        #[arg(long, value_name = "FILE")]
        out: PathBuf,
        /// Smallest disparity searched, px.
        #[arg(long)]
        min_disp: Option<u32>,
        /// Largest disparity searched, px.
        #[arg(long)]
        max_disp: Option<u32>,
        #[command(flatten)]
        base: stereo_cli::StereoBase,
    },
    /// Score stereo algorithms on every scene of a dataset folder (bad-1, bad-2, density,
    /// ms per frame), optionally also with webcam defects.
    Eval {
        /// Algorithm, comma-separated list, `all`, or `none` (with --export only).
        #[arg(long, default_value = "sgm")]
        algo: String,
        /// Dataset folder (one sub-folder per scene, like ../shared/datasets).
        #[arg(long, value_name = "DIR")]
        dataset: PathBuf,
        /// Also score with webcam defects on the right image (gain 0.8, offset +10, noise
        /// sigma 4, 1 px vertical shift).
        #[arg(long)]
        degrade: bool,
        /// Print JSON.
        #[arg(long)]
        json: bool,
        /// Matching runs per scene for the timing (median reported).
        #[arg(long, default_value_t = 3)]
        repeat: usize,
        /// Write each scene's grey (and degraded) inputs here, for external matchers.
        #[arg(long, value_name = "DIR")]
        export: Option<PathBuf>,
        /// Score `<scene>-<clean|degraded>.png` disparity maps from this folder instead of
        /// running a matcher (label the rows with --algo).
        #[arg(long, value_name = "DIR")]
        predictions: Option<PathBuf>,
        /// Save our disparity maps here.
        #[arg(long, value_name = "DIR")]
        save: Option<PathBuf>,
        /// Also score with the right image shifted down by N rows (negative: up), for each N
        /// of a comma-separated list (e.g. `--vshift=-4,-2,2,4`); with --degrade the shift
        /// replaces the defects' own 1 px. The row alignment (stereo.*.row_align) is what
        /// should undo it.
        #[arg(
            long,
            value_name = "N[,N...]",
            value_delimiter = ',',
            allow_negative_numbers = true
        )]
        vshift: Vec<i32>,
        #[command(flatten)]
        base: stereo_cli::StereoBase,
    },
    /// Simulator tools.
    Sim {
        #[command(subcommand)]
        what: SimCommand,
    },
    /// Benchmarks that print numbers (release builds only give meaningful figures).
    Bench {
        #[command(subcommand)]
        what: BenchCommand,
    },
    /// Look inside a running pipeline, read-only: topics, rates, samples, images, a live
    /// table of the stages. Probes attach and detach at any time and never slow the pipeline.
    Probe {
        #[command(subcommand)]
        what: probe_cli::ProbeCommand,
    },
    /// Stop a running pipeline in order (actuator first).
    Stop {
        #[command(flatten)]
        target: Target,
        /// Give up waiting after this many seconds.
        #[arg(long, default_value_t = 30.0, value_name = "SECONDS")]
        timeout: f64,
    },
}

/// Simulator tools.
#[derive(Debug, Subcommand)]
enum SimCommand {
    /// Render one stereo pair of a map: left.png, right.png (8-bit grey) and gt_disp.png
    /// (16-bit, disparity x 256, 0 = unknown).
    Render {
        /// Map file (see config/maps).
        #[arg(long, value_name = "FILE")]
        map: PathBuf,
        /// Robot pose `x_m,y_m,heading_deg` (default: the map's start pose).
        #[arg(long, value_name = "X,Y,DEG", allow_hyphen_values = true)]
        pose: Option<String>,
        /// Output folder (created if missing).
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        /// Image size.
        #[arg(long, default_value = "640x480", value_parser = ["640x480", "320x240"])]
        size: String,
        /// Right-image gain (webcam defect).
        #[arg(long, default_value_t = 1.0)]
        gain: f32,
        /// Right-image offset, grey levels.
        #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
        offset: f32,
        /// Gaussian noise sigma on both images, grey levels.
        #[arg(long, default_value_t = 0.0)]
        noise: f32,
        /// Vertical misalignment of the right image, px.
        #[arg(long, default_value_t = 0, allow_hyphen_values = true)]
        vertical_shift: i32,
    },
    /// Drive the robot's algorithms (stereo, fusion, decision, actuator) in a closed loop with
    /// the simulator, in one process and faster than real time; prints collisions, distinct
    /// cells covered, the intersections seen and the commands sent.
    Drive {
        /// Map file (default: the config's sim.map).
        #[arg(long, value_name = "FILE")]
        map: Option<PathBuf>,
        /// Start pose `x_m,y_m,heading_deg` (default: the map's start pose).
        #[arg(long, value_name = "X,Y,DEG", allow_hyphen_values = true)]
        pose: Option<String>,
        /// Simulated seconds.
        #[arg(long, default_value_t = 60.0)]
        duration: f64,
        /// Decisions per simulated second.
        #[arg(long, default_value_t = hvs_drive::DEFAULT_RATE_HZ)]
        rate_hz: f64,
        /// Visit memory on or off (default: the config's decision.visit_memory).
        #[arg(long, value_parser = ["on", "off"])]
        memory: Option<String>,
        /// Local occupancy map on or off (default: the config's decision.local_map).
        #[arg(long, value_parser = ["on", "off"])]
        local_map: Option<String>,
        /// Wall contrast 0..1, overriding the map's @wall_contrast: 1 the full wall texture,
        /// 0 plain painted walls (only the camera's noise on them).
        #[arg(long, value_name = "C")]
        wall_contrast: Option<f64>,
        /// Wheel slip and speed errors of the realistic preset (2 % wheel scale errors, 3 %
        /// speed variation, 5 % of each turn in place lost), overriding [sim.motion]: dead
        /// reckoning then drifts.
        #[arg(long)]
        motion_noise: bool,
        /// Seed of the images' and the motion's noise (default: the config's sim.seed).
        #[arg(long, value_name = "N")]
        seed: Option<u64>,
        /// Drive a maze generated in memory from this seed (as `hvs sim maze --seed N`)
        /// instead of a map file.
        #[arg(long, value_name = "N", conflicts_with = "map")]
        maze_seed: Option<u64>,
        /// Config file (default: config/sim.toml).
        #[arg(long, value_name = "FILE")]
        config: Option<PathBuf>,
        /// Print JSON (with coverage_pct, explored_s, coverage_curve and cells_per_m).
        #[arg(long)]
        json: bool,
    },
    /// Generate a random maze map: square rooms and corridor slots 2.45 m across on 0.175 m
    /// cells, joined by doorways 0.7 to 1.05 m wide, with loops, at least one dead-end
    /// corridor, free-standing pillars in some rooms, walls 0.35 m thick all round, and a
    /// start marker in a room with room to turn. Every floor cell is reachable from the
    /// start. The same seed always gives the same maze. The default 4x4 slots make
    /// 11.55 m x 11.55 m, the size of config/maps/maze.txt; `hvs sim drive --map FILE` drives it
    /// (or `hvs sim drive --maze-seed N` without writing a file).
    #[command(verbatim_doc_comment)]
    Maze {
        /// Seed.
        #[arg(long, value_name = "N")]
        seed: u64,
        /// Output map file (default: standard output).
        #[arg(long, value_name = "FILE")]
        out: Option<PathBuf>,
        /// Slots across x down, 2 to 16 each (each 2.45 m plus a 0.35 m wall).
        #[arg(long, value_name = "WxH", default_value = "4x4")]
        rooms: String,
    },
}

/// Benchmarks.
#[derive(Debug, Subcommand)]
enum BenchCommand {
    /// One-hop latency of 320x240 and 640x480 pairs between two processes: iceoryx2 zero copy
    /// against a Unix-socket copy of the same bytes.
    Ipc {
        /// Frames per size and transport.
        #[arg(long, default_value_t = 2000)]
        count: u32,
        /// Send rate, Hz.
        #[arg(long, default_value_t = 500.0)]
        rate: f64,
    },
    /// Run the simulated pipeline for a while and print capture-to-decision and
    /// capture-to-command latency, per-stage rates and drops.
    Pipeline {
        /// Pipeline configuration (default: config/sim.toml).
        #[arg(long, value_name = "FILE")]
        config: Option<PathBuf>,
        /// How long to run, seconds (each run, with --view compare).
        #[arg(long, default_value_t = 20.0)]
        duration: f64,
        /// Who watches the live view meanwhile: nobody, the web page's channels, a Foxglove
        /// client on every channel, or all three in turn with a cost table.
        #[arg(long, value_enum, default_value = "none")]
        view: bench_view::ViewLoad,
    },
    /// Soak: the simulated pipeline for a long time with a probe attaching and detaching
    /// every few seconds; prints per-stage memory and descriptors at the start and the end,
    /// shared-memory files during and after, restarts and watchdog neutrals.
    Soak {
        /// Pipeline configuration (default: config/sim.toml).
        #[arg(long, value_name = "FILE")]
        config: Option<PathBuf>,
        /// How long to watch after the warm-up, seconds.
        #[arg(long, default_value_t = 1800.0)]
        duration: f64,
        /// A probe attaches this often, seconds.
        #[arg(long, default_value_t = 3.0)]
        probe_every: f64,
        /// Readings start after this long, seconds.
        #[arg(long, default_value_t = 15.0)]
        warm_up: f64,
    },
    /// Time per frame of the fusion stage (edges, fused map, windows) and the decision stage
    /// at 320x240 and 640x480 on a rendered simulator pair.
    Stages {
        /// Configuration (default: config/sim.toml).
        #[arg(long, value_name = "FILE")]
        config: Option<PathBuf>,
        /// Timed frames per step.
        #[arg(long, default_value_t = 200)]
        frames: usize,
    },
    /// Time stereo matchers on the built-in simulated hallway pair: median ms per frame and
    /// million disparity evaluations per second, one thread.
    Stereo {
        /// Algorithm, comma-separated list, or `all`.
        #[arg(long, default_value = "sgm")]
        algo: String,
        /// 320x240 (disparities 9..55), 640x480 (18..110) or both.
        #[arg(long, default_value = "both")]
        size: String,
        /// Timed frames per algorithm and size.
        #[arg(long, default_value_t = 50)]
        frames: usize,
        /// Also write the benchmark pairs as PNG here (for the OpenCV comparison).
        #[arg(long, value_name = "DIR")]
        export: Option<PathBuf>,
        /// Print JSON.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        base: stereo_cli::StereoBase,
    },
    /// The receiving side of `hvs bench ipc` (started by it).
    #[command(hide = true)]
    IpcReceiver {
        #[arg(long)]
        instance: String,
        #[arg(long, value_enum)]
        size: bench::FrameSize,
        #[arg(long, value_enum)]
        transport: bench::Transport,
        #[arg(long)]
        count: u32,
        #[arg(long)]
        socket: PathBuf,
    },
}

/// Which running pipeline a client command talks to.
#[derive(Debug, clap::Args)]
struct Target {
    /// Instance name (default: the `instance` of --config, else "default").
    #[arg(long, value_name = "NAME")]
    instance: Option<String>,
    /// Config whose `instance` to use.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
}

impl Target {
    fn instance(&self) -> anyhow::Result<String> {
        if let Some(i) = &self.instance {
            return Ok(i.clone());
        }
        if let Some(path) = &self.config {
            return Ok(HvsConfig::load(path)?.instance);
        }
        Ok("default".to_string())
    }
}

/// The config file to use: `given`, else the default (`config/sim.toml` in the current
/// folder, else in the source tree).
fn resolve_config(given: Option<PathBuf>) -> anyhow::Result<PathBuf> {
    if let Some(path) = given {
        return Ok(path);
    }
    default_config()
}

/// The default config: `config/sim.toml` in the current folder, else in the source tree.
fn default_config() -> anyhow::Result<PathBuf> {
    let local = PathBuf::from("config/sim.toml");
    if local.is_file() {
        return Ok(local);
    }
    let built_in = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/sim.toml");
    if built_in.is_file() {
        return Ok(built_in);
    }
    anyhow::bail!(
        "no --config given and config/sim.toml not found in {}",
        std::env::current_dir()?.display()
    )
}

/// Checks that go beyond the config schema before anything is started: each stereo section
/// by its matchers' own rules, and the simulator's map must parse (its errors name file,
/// line and column).
pub fn preflight(config: &HvsConfig) -> anyhow::Result<()> {
    for (section, stereo, width_px) in [
        ("stereo.lo", &config.stereo.lo, 320),
        ("stereo.hi", &config.stereo.hi, 640),
    ] {
        match hvs_stereo::validate_section(stereo, width_px) {
            Ok(()) => {}
            Err(hvs_stereo::StereoError::BadParameter { key, message }) => {
                return Err(config.invalid(&format!("{section}.{key}"), message).into());
            }
            Err(hvs_stereo::StereoError::BadRange { min, max }) => {
                return Err(config
                    .invalid(
                        &format!("{section}.max_disp"),
                        format!("= {max} must be above min_disp = {min}"),
                    )
                    .into());
            }
            Err(e) => return Err(config.invalid(section, e.to_string()).into()),
        }
    }
    if config.stage_enabled(hvs_shared::topics::Stage::Sim) {
        let map = config.resolve_path(&config.sim.map);
        hvs_sim::GridMap::load(&map)
            .with_context(|| format!("config file {}: `sim.map`", config.source_path.display()))?;
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn sim_render(
    map: &Path,
    pose: Option<&str>,
    out: &Path,
    size: &str,
    gain: f32,
    offset: f32,
    noise: f32,
    vertical_shift: i32,
) -> anyhow::Result<()> {
    let pose = match pose {
        Some(p) => p
            .parse::<hvs_sim::Pose>()
            .with_context(|| format!("--pose {p:?}"))?,
        None => hvs_sim::GridMap::load(map)?.start_pose(),
    };
    let size = if size == "320x240" {
        hvs_sim::RenderSize::Qvga
    } else {
        hvs_sim::RenderSize::Vga
    };
    let defects = hvs_sim::WebcamDefects {
        gain,
        offset,
        noise_sigma: noise,
        vertical_shift_px: vertical_shift,
        right_delay_s: 0.0,
    };
    let files = hvs_sim::render_to_dir(map, &pose, out, size, &defects)?;
    println!(
        "rendered {} at ({:.2}, {:.2}) {:.1} deg: {}, {}, {}",
        map.display(),
        pose.x_m,
        pose.y_m,
        pose.heading_rad.to_degrees(),
        files.left_png.display(),
        files.right_png.display(),
        files.gt_disp_png.display()
    );
    Ok(())
}

fn seconds(s: f64, what: &str) -> anyhow::Result<Duration> {
    Duration::try_from_secs_f64(s)
        .with_context(|| format!("{what} {s} is not a valid number of seconds"))
}

fn main() -> ExitCode {
    hvs_runtime::stage::init_tracing();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Run {
            config,
            instance,
            duration,
            report,
            replay,
            record,
            bridge_listen,
            bridge_connect,
        } => (|| {
            let config_path = resolve_config(config)?;
            let duration = duration.map(|d| seconds(d, "--duration")).transpose()?;
            run::run(&run::RunOptions {
                config_path,
                instance,
                duration,
                report,
                replay,
                record,
                bridge_listen,
                bridge_connect,
                latency_warm_up: std::time::Duration::ZERO,
            })
            .map(|_| ())
        })(),
        Command::Check { config } => (|| {
            let path = resolve_config(config)?;
            let config = HvsConfig::load(&path)?;
            preflight(&config)?;
            println!("config {}: ok", path.display());
            Ok(())
        })(),
        Command::Doctor { config } => match resolve_config(config) {
            Ok(path) => {
                return if doctor::doctor(&path) {
                    ExitCode::SUCCESS
                } else {
                    ExitCode::FAILURE
                };
            }
            Err(e) => Err(e),
        },
        Command::Status { target, json } => {
            target.instance().and_then(|i| control::status(&i, json))
        }
        Command::Restart {
            stage,
            target,
            timeout,
        } => target
            .instance()
            .and_then(|i| control::restart(&i, &stage, seconds(timeout, "--timeout")?)),
        Command::Stereo {
            algo,
            left,
            right,
            out,
            min_disp,
            max_disp,
            base,
        } => stereo_cli::stereo(
            algo.as_deref(),
            &left,
            &right,
            &out,
            min_disp,
            max_disp,
            &base,
        ),
        Command::Eval {
            algo,
            dataset,
            degrade,
            json,
            repeat,
            export,
            predictions,
            save,
            vshift,
            base,
        } => stereo_cli::eval(
            &stereo_cli::EvalOptions {
                algo,
                dataset,
                degrade,
                json,
                repeat,
                export,
                predictions,
                save,
                vshift,
            },
            &base,
        ),
        Command::Sim {
            what:
                SimCommand::Render {
                    map,
                    pose,
                    out,
                    size,
                    gain,
                    offset,
                    noise,
                    vertical_shift,
                },
        } => sim_render(
            &map,
            pose.as_deref(),
            &out,
            &size,
            gain,
            offset,
            noise,
            vertical_shift,
        ),
        Command::Sim {
            what:
                SimCommand::Drive {
                    map,
                    pose,
                    duration,
                    rate_hz,
                    memory,
                    local_map,
                    wall_contrast,
                    motion_noise,
                    seed,
                    maze_seed,
                    config,
                    json,
                },
        } => (|| {
            let config = resolve_config(config)?;
            let pose = pose
                .map(|p| p.parse::<hvs_sim::Pose>())
                .transpose()
                .map_err(|e| anyhow::anyhow!("--pose: {e}"))?;
            let opts = hvs_drive::DriveOptions {
                map,
                pose,
                duration_s: duration,
                rate_hz,
                visit_memory: memory.map(|m| m == "on"),
                local_map: local_map.map(|m| m == "on"),
                wall_contrast,
                motion_noise: motion_noise.then(hvs_sim::SimMotionNoise::realistic),
                seed,
                maze: maze_seed.map(|seed| hvs_sim::MazeOptions {
                    seed,
                    ..hvs_sim::MazeOptions::default()
                }),
            };
            drive::run(&config, &opts, json)
        })(),
        Command::Sim {
            what: SimCommand::Maze { seed, out, rooms },
        } => drive::maze(seed, out.as_deref(), &rooms),
        Command::Bench { what } => match what {
            BenchCommand::Ipc { count, rate } => bench::run_ipc(count, rate),
            BenchCommand::Stereo {
                algo,
                size,
                frames,
                export,
                json,
                base,
            } => stereo_cli::bench(&algo, &size, frames, export.as_deref(), json, &base),
            BenchCommand::Stages { config, frames } => (|| {
                let config = resolve_config(config)?;
                bench_stages::run(&config, frames)
            })(),
            BenchCommand::Soak {
                config,
                duration,
                probe_every,
                warm_up,
            } => (|| {
                soak::run(&soak::SoakOptions {
                    config: resolve_config(config)?,
                    duration: seconds(duration, "--duration")?,
                    probe_every: seconds(probe_every, "--probe-every")?,
                    warm_up: seconds(warm_up, "--warm-up")?,
                })
            })(),
            BenchCommand::Pipeline {
                config,
                duration,
                view,
            } => (|| {
                let config = resolve_config(config)?;
                bench::run_pipeline(config, seconds(duration, "--duration")?, view)
            })(),
            BenchCommand::IpcReceiver {
                instance,
                size,
                transport,
                count,
                socket,
            } => bench::run_receiver(&instance, size, transport, count, socket),
        },
        Command::Probe { what } => probe_cli::run(what),
        Command::Stop { target, timeout } => target
            .instance()
            .and_then(|i| control::stop(&i, seconds(timeout, "--timeout")?)),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            let e: &(dyn std::error::Error + 'static) = e.as_ref();
            eprintln!("hvs: error: {}", hvs_runtime::error_chain(e));
            ExitCode::FAILURE
        }
    }
}
