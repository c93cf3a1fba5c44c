//! `hvs probe list|hz|echo|snapshot|top|record`: read-only views of a running pipeline from a
//! separate process (the logic lives in the `hvs-probe` crate; see docs/probe.md).

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use hvs_probe::attach::{self, list_json, render_list};
use hvs_probe::record::{self, RecordOptions};
use hvs_probe::{EchoOptions, HzOptions, Probe, SnapshotOptions, TopOptions};
use hvs_runtime::config::HvsConfig;

use crate::{Target, default_config, seconds};

/// Probe commands.
#[derive(Debug, clap::Subcommand)]
pub enum ProbeCommand {
    /// Every topic of an instance with its publishers, subscribers and measured rate.
    List {
        #[command(flatten)]
        target: Target,
        /// Measure rates over this many seconds.
        #[arg(long, default_value_t = 1.0, value_name = "SECONDS")]
        window_s: f64,
        /// Print JSON instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Rate of one topic (rate, mean/min/max period, lost samples), printed once a second.
    Hz {
        /// Topic path, e.g. `decisions`, `frames/320x240`, `heartbeat/fusion`.
        topic: String,
        #[command(flatten)]
        target: Target,
        /// Stop after this many once-a-second reports.
        #[arg(long, value_name = "N")]
        count: Option<u64>,
        /// Stop after this many seconds (`--duration` means seconds in every command).
        #[arg(long = "duration", alias = "duration-s", value_name = "SECONDS")]
        duration_s: Option<f64>,
        /// Print JSON lines.
        #[arg(long)]
        json: bool,
    },
    /// Print every sample of a topic as readable text (or JSON lines).
    Echo {
        /// Topic path, e.g. `decisions`, `ranges`, `actuator/sent`, `heartbeat/capture`.
        topic: String,
        #[command(flatten)]
        target: Target,
        /// Stop after this many samples.
        #[arg(long, value_name = "N")]
        count: Option<u64>,
        /// Print JSON lines.
        #[arg(long)]
        json: bool,
        /// Read deliberately slowly: hold each sample and sleep this many ms before the next
        /// (to see that a slow probe cannot slow the pipeline).
        #[arg(long, default_value_t = 0, value_name = "MS")]
        slow_ms: u64,
    },
    /// Write one image sample as PNG: a frame pair side by side (grey), a disparity map in
    /// a colour map with a legend in metres, or with --fused the fused map over the left
    /// image.
    Snapshot {
        /// Topic path: frames/320x240, frames/640x480, sim/camera/640x480, disparity/320x240,
        /// disparity/640x480 or sim/gt_disparity/640x480.
        topic: String,
        #[command(flatten)]
        target: Target,
        /// Output PNG.
        #[arg(long, value_name = "FILE")]
        out: PathBuf,
        /// Disparity at the Canny edges of the left image, over that image.
        #[arg(long)]
        fused: bool,
        /// Give up after this many seconds without a suitable sample.
        #[arg(long, default_value_t = 5.0, value_name = "SECONDS")]
        timeout_s: f64,
    },
    /// A live view of every stage (rate, latency, drops, restarts, last decision), redrawn
    /// once a second; Ctrl-C to leave.
    Top {
        #[command(flatten)]
        target: Target,
        /// Print one frame (no escape codes) and exit.
        #[arg(long)]
        once: bool,
        /// Seconds between frames.
        #[arg(long, default_value_t = 1.0, value_name = "SECONDS")]
        refresh_s: f64,
    },
    /// Record topics into an MCAP file (Foxglove/Lichtblick open it: images as
    /// foxglove.RawImage) until Ctrl-C or --duration; lost samples are counted in the file's
    /// metadata and printed at the end; a full disk ends it with a readable file.
    Record {
        #[command(flatten)]
        target: Target,
        /// Output MCAP file.
        #[arg(long, value_name = "FILE")]
        out: PathBuf,
        /// Topics to record (default: frames/320x240 frames/640x480 ranges decisions
        /// actuator/sent).
        #[arg(long, num_args = 1.., value_name = "TOPIC")]
        topics: Vec<String>,
        /// Stop after this many seconds (`--duration` means seconds in every command).
        #[arg(long = "duration", alias = "duration-s", value_name = "SECONDS")]
        duration_s: Option<f64>,
        /// Print the summary as JSON.
        #[arg(long)]
        json: bool,
        /// Create the topics if no stage has yet (used by `hvs run --record`).
        #[arg(long, hide = true)]
        create_topics: bool,
        /// Create this file once subscribed (used by `hvs run --record`).
        #[arg(long, hide = true, value_name = "FILE")]
        ready_file: Option<PathBuf>,
    },
}

/// The config whose camera and fusion settings a snapshot uses: --config, else the default.
fn snapshot_config(target: &Target) -> anyhow::Result<HvsConfig> {
    let path = match &target.config {
        Some(p) => p.clone(),
        None => default_config()?,
    };
    Ok(HvsConfig::load(&path)?)
}

/// Runs one probe command.
pub fn run(command: ProbeCommand) -> anyhow::Result<()> {
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    match command {
        ProbeCommand::List {
            target,
            window_s,
            json,
        } => {
            let window = seconds(window_s, "--window-s")?;
            let probe = Probe::attach(&target.instance()?)?;
            let rows = attach::list(&probe, window)?;
            let text = if json {
                format!("{:#}\n", list_json(probe.instance(), window, &rows))
            } else {
                render_list(probe.instance(), window, &rows)
            };
            out.write_all(text.as_bytes())
                .and_then(|()| out.flush())
                .context("writing the topic list")?;
        }
        ProbeCommand::Hz {
            topic,
            target,
            count,
            duration_s,
            json,
        } => {
            let opts = HzOptions {
                count,
                duration: duration_s.map(|d| seconds(d, "--duration")).transpose()?,
                report_period: std::time::Duration::from_secs(1),
                json,
            };
            attach::resolve_topic(&topic)?;
            let probe = Probe::attach(&target.instance()?)?;
            attach::hz(&probe, &topic, &opts, &mut out)?;
        }
        ProbeCommand::Echo {
            topic,
            target,
            count,
            json,
            slow_ms,
        } => {
            let opts = EchoOptions {
                count,
                json,
                slow: std::time::Duration::from_millis(slow_ms),
            };
            attach::resolve_topic(&topic)?;
            let probe = Probe::attach(&target.instance()?)?;
            attach::echo(&probe, &topic, &opts, &mut out)?;
        }
        ProbeCommand::Snapshot {
            topic,
            target,
            out: file,
            fused,
            timeout_s,
        } => {
            let opts = SnapshotOptions {
                out: file,
                fused,
                timeout: seconds(timeout_s, "--timeout-s")?,
            };
            attach::resolve_topic(&topic)?;
            let config = snapshot_config(&target)?;
            let probe = Probe::attach(&target.instance()?)?;
            let info = attach::snapshot(&probe, &topic, &config, &opts)?;
            writeln!(
                out,
                "wrote {} ({}x{} px, frame {})",
                opts.out.display(),
                info.width_px,
                info.height_px,
                info.frame_id
            )
            .context("writing the result line")?;
        }
        ProbeCommand::Top {
            target,
            once,
            refresh_s,
        } => {
            let opts = TopOptions {
                once,
                refresh: seconds(refresh_s, "--refresh-s")?,
            };
            let probe = Probe::attach(&target.instance()?)?;
            attach::top(&probe, &opts, &mut out)?;
        }
        ProbeCommand::Record {
            target,
            out: file,
            topics,
            duration_s,
            json,
            create_topics,
            ready_file,
        } => {
            // The calibration and camera transform come from the config (--config, else the
            // default); without one the recording simply lacks them.
            let camera = match snapshot_config(&target) {
                Ok(c) => Some(c.camera),
                Err(e) => {
                    tracing::warn!("no camera calibration in the recording: {e:#}");
                    None
                }
            };
            let opts = RecordOptions {
                out: file,
                topics,
                duration: duration_s.map(|d| seconds(d, "--duration")).transpose()?,
                create_topics,
                ready_file,
                camera,
            };
            let probe = Probe::attach(&target.instance()?)?;
            let summary = record::record(&probe, &opts, &mut std::io::stderr())?;
            let text = if json {
                format!("{}\n", serde_json::to_string(&summary)?)
            } else {
                let mut t = format!(
                    "wrote {} ({:.1} MB, {:.1} s){}\n",
                    summary.out.display(),
                    summary.bytes as f64 / 1e6,
                    summary.duration_s,
                    summary
                        .cut_short
                        .as_ref()
                        .map(|c| format!(", cut short: {c}"))
                        .unwrap_or_default()
                );
                for (path, c) in &summary.topics {
                    t.push_str(&format!(
                        "  {path:16} {:6} written {:6} dropped\n",
                        c.written, c.dropped
                    ));
                }
                t
            };
            out.write_all(text.as_bytes())
                .and_then(|()| out.flush())
                .context("writing the summary")?;
            if summary.dropped() > 0 {
                tracing::warn!(
                    "{} samples were lost before the recorder read them (counted in the file's \
                     metadata)",
                    summary.dropped()
                );
            }
        }
    }
    Ok(())
}
