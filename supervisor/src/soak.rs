//! `hvs bench soak`: the whole simulated pipeline for a long time (30 minutes by default) with
//! a probe attaching and detaching every few seconds, watching for what a long run on the
//! robot must not show: memory or file-descriptor growth in a stage, shared-memory files left
//! behind, restarts, and a watchdog neutral (the actuator stopping the wheels because no fresh
//! decision came).
//!
//! Everything runs as real processes: `hvs run` in its own instance, the probes as
//! `hvs probe ...` children, and a long-lived `hvs probe echo actuator/sent --json` counting the
//! watchdog neutrals after the warm-up.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use hvs_runtime::config::run_dir;

use crate::control;
use crate::procstat::{self, mib};

/// Options of `hvs bench soak`.
#[derive(Debug, Clone)]
pub struct SoakOptions {
    /// Pipeline configuration.
    pub config: PathBuf,
    /// How long the pipeline runs.
    pub duration: Duration,
    /// A probe attaches this often.
    pub probe_every: Duration,
    /// Readings start after this long (start-up allocations are not growth).
    pub warm_up: Duration,
}

/// One stage's readings.
#[derive(Debug, Clone, Default)]
struct StageWatch {
    name: String,
    pid: u32,
    rss_start: u64,
    rss_end: u64,
    rss_max: u64,
    fds_start: usize,
    fds_end: usize,
}

fn hvs_command(exe: &Path) -> Command {
    let mut cmd = Command::new(exe);
    cmd.stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    cmd
}

/// Shared-memory and iceoryx2 files of this machine.
fn iceoryx_files() -> std::collections::BTreeSet<String> {
    hvs_runtime::ipc::iceoryx_files().into_iter().collect()
}

fn fd_count(pid: u32) -> usize {
    std::fs::read_dir(format!("/proc/{pid}/fd")).map_or(0, |d| d.count())
}

/// Runs a short-lived probe to completion (killed after `limit`); true if it exited 0.
fn run_probe(exe: &Path, args: &[&str], limit: Duration) -> bool {
    let Ok(mut child) = hvs_command(exe).args(args).spawn() else {
        return false;
    };
    let deadline = Instant::now() + limit;
    loop {
        match child.try_wait() {
            Ok(Some(status)) => return status.success(),
            Ok(None) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(20)),
            _ => {
                let _ = child.kill();
                let _ = child.wait();
                return false;
            }
        }
    }
}

/// Counts the actuator's outputs and its watchdog neutrals from a long-lived echo probe.
fn watch_actuator(
    exe: &Path,
    instance: &str,
) -> anyhow::Result<(Child, Arc<AtomicU64>, Arc<AtomicU64>)> {
    let mut child = hvs_command(exe)
        .args([
            "probe",
            "echo",
            "actuator/sent",
            "--json",
            "--instance",
            instance,
        ])
        .stdout(Stdio::piped())
        .spawn()
        .context("cannot start the actuator probe")?;
    let out = child.stdout.take().context("no probe output")?;
    let (sent, watchdog) = (Arc::new(AtomicU64::new(0)), Arc::new(AtomicU64::new(0)));
    let (s, w) = (Arc::clone(&sent), Arc::clone(&watchdog));
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            s.fetch_add(1, Ordering::Relaxed);
            if line.contains("\"watchdog-neutral\"") {
                w.fetch_add(1, Ordering::Relaxed);
            }
        }
    });
    Ok((child, sent, watchdog))
}

/// `hvs bench soak`.
pub fn run(opts: &SoakOptions) -> anyhow::Result<()> {
    let exe = std::env::current_exe().context("cannot locate the hvs executable")?;
    let instance = format!("soak{}", std::process::id());
    let dir = run_dir(&instance);
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let report_path = dir.with_extension("report.json");
    let files_before = iceoryx_files();
    let total = opts.duration + opts.warm_up;
    println!(
        "soak: instance {instance}, {:.0} s of pipeline ({:.0} s warm-up), a probe every {:.1} s",
        total.as_secs_f64(),
        opts.warm_up.as_secs_f64(),
        opts.probe_every.as_secs_f64()
    );
    let mut run = hvs_command(&exe)
        .arg("run")
        .arg("--config")
        .arg(&opts.config)
        .args(["--instance", &instance, "--duration"])
        .arg(format!("{}", total.as_secs_f64()))
        .arg("--report")
        .arg(&report_path)
        .spawn()
        .context("cannot start hvs run")?;
    std::thread::sleep(opts.warm_up);
    let status = match control::fetch_status(&instance) {
        Ok(s) => s,
        Err(e) => {
            let _ = run.kill();
            bail!("the pipeline did not come up within the warm-up: {e}");
        }
    };
    // The long-lived probe and one probe of each kind first: the baseline includes the
    // connections made once (growth is what keeps coming with every probe).
    let (mut echo, sent, watchdog) = watch_actuator(&exe, &instance)?;
    let probe_kinds: [&[&str]; 3] = [
        &["probe", "echo", "decisions", "--count", "5", "--json"],
        &["probe", "hz", "ranges", "--duration", "1"],
        &["probe", "list"],
    ];
    for kind in probe_kinds {
        let mut args = kind.to_vec();
        args.extend(["--instance", &instance]);
        run_probe(&exe, &args, Duration::from_secs(10));
    }
    std::thread::sleep(Duration::from_secs(1));
    let mut stages: Vec<StageWatch> = status
        .stages
        .iter()
        .filter(|s| s.pid != 0)
        .map(|s| {
            let rss = procstat::sample(s.pid).map_or(0, |p| p.rss_bytes);
            StageWatch {
                name: s.stage.clone(),
                pid: s.pid,
                rss_start: rss,
                rss_end: rss,
                rss_max: rss,
                fds_start: fd_count(s.pid),
                fds_end: fd_count(s.pid),
            }
        })
        .collect();
    let files_start = iceoryx_files();
    let started = Instant::now();
    let (mut probes, mut probe_failures) = (0u64, 0u64);
    let mut files_end = files_start.clone();
    let mut next_report = Instant::now() + Duration::from_secs(60);
    loop {
        if let Ok(Some(_)) = run.try_wait() {
            break;
        }
        if started.elapsed() + Duration::from_secs(2) < opts.duration {
            // Readings first, a pause after the last probe left: its ports are gone by then
            // (a publisher drops a departed subscriber's connection on its next send).
            for s in &mut stages {
                if let Some(p) = procstat::sample(s.pid) {
                    s.rss_end = p.rss_bytes;
                    s.rss_max = s.rss_max.max(p.rss_bytes);
                    s.fds_end = fd_count(s.pid);
                }
            }
            files_end = iceoryx_files();
            let mut args: Vec<&str> = probe_kinds[probes as usize % probe_kinds.len()].to_vec();
            args.extend(["--instance", &instance]);
            probes += 1;
            if !run_probe(&exe, &args, Duration::from_secs(10)) {
                probe_failures += 1;
            }
        }
        if Instant::now() >= next_report {
            next_report += Duration::from_secs(60);
            println!(
                "soak t={:.0}s: {probes} probes ({probe_failures} failed), stage memory {:.1} MiB, {} iceoryx2 files, {} actuator outputs, {} watchdog neutral",
                started.elapsed().as_secs_f64(),
                mib(stages.iter().map(|s| s.rss_end).sum()),
                files_end.len(),
                sent.load(Ordering::Relaxed),
                watchdog.load(Ordering::Relaxed)
            );
        }
        std::thread::sleep(opts.probe_every);
    }
    let run_status = run.wait().context("hvs run")?;
    // SIGTERM: the probe removes its node's files as it leaves (SIGKILL would leave them to
    // the next process's clean-up).
    crate::process::terminate(&mut echo, Duration::from_secs(5));
    std::thread::sleep(Duration::from_millis(500));
    let files_after = iceoryx_files();
    let report: serde_json::Value = std::fs::read(&report_path)
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok())
        .with_context(|| format!("hvs run left no report at {}", report_path.display()))?;
    let _ = std::fs::remove_file(&report_path);

    println!();
    println!(
        "soak over {:.0} s after a {:.0} s warm-up (hvs run exit: {run_status})",
        started.elapsed().as_secs_f64(),
        opts.warm_up.as_secs_f64()
    );
    println!(
        "{:<10} {:>12} {:>10} {:>10} {:>9} {:>9}",
        "stage", "rss start", "rss end", "rss max", "fds start", "fds end"
    );
    for s in &stages {
        println!(
            "{:<10} {:>10.1} M {:>8.1} M {:>8.1} M {:>9} {:>9}",
            s.name,
            mib(s.rss_start),
            mib(s.rss_end),
            mib(s.rss_max),
            s.fds_start,
            s.fds_end
        );
    }
    let growth = stages
        .iter()
        .map(|s| s.rss_end as i64 - s.rss_start as i64)
        .max()
        .unwrap_or(0);
    let restarts: u64 = report["stages"].as_array().map_or(0, |a| {
        a.iter().map(|s| s["restarts"].as_u64().unwrap_or(0)).sum()
    });
    let verdict = |ok: bool| if ok { "met" } else { "NOT met" };
    println!(
        "probes attached and detached: {probes} ({probe_failures} failed), plus one echo probe throughout"
    );
    println!(
        "decisions {}, actuator outputs seen {}, restarts {restarts}",
        report["decisions"],
        sent.load(Ordering::Relaxed)
    );
    println!("targets");
    println!(
        "  no memory growth (largest stage growth < 4 MiB):  {:+.2} MiB  {}",
        growth.signum() as f64 * mib(growth.unsigned_abs()),
        verdict(growth < 4 << 20)
    );
    let fd_growth: Vec<String> = stages
        .iter()
        .filter(|s| s.fds_end > s.fds_start)
        .map(|s| format!("{} {} -> {}", s.name, s.fds_start, s.fds_end))
        .collect();
    println!(
        "  no fd growth:                                     {}  {}",
        if fd_growth.is_empty() {
            "none".to_string()
        } else {
            fd_growth.join(", ")
        },
        verdict(fd_growth.is_empty())
    );
    println!(
        "  no file growth while running:                     {} -> {} iceoryx2 files  {}",
        files_start.len(),
        files_end.len(),
        verdict(files_end.len() <= files_start.len())
    );
    for f in files_end.difference(&files_start).take(5) {
        println!("    new while running: {f}");
    }
    println!(
        "  nothing left after the run:                       {} before, {} after  {}",
        files_before.len(),
        files_after.len(),
        verdict(files_after.len() <= files_before.len())
    );
    for f in files_after.difference(&files_before).take(5) {
        println!("    left behind: {f}");
    }
    println!(
        "  no missed watchdog (neutral for a late decision): {}  {}",
        watchdog.load(Ordering::Relaxed),
        verdict(watchdog.load(Ordering::Relaxed) == 0)
    );
    println!(
        "  no restarts, no failed probe:                     {restarts} restarts, {probe_failures} failed probes  {}",
        verdict(restarts == 0 && probe_failures == 0)
    );
    Ok(())
}
