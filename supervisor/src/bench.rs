//! `hvs bench ipc`: one-hop latency of a stereo pair between two real processes, through
//! iceoryx2 shared memory (zero copy) and, as a same-run baseline, through a Unix socket that
//! copies the same bytes.
//!
//! The sender stamps `CLOCK_MONOTONIC` into the frame header just before handing the frame
//! over; the receiver (a child `hvs bench ipc-receiver` process) stamps the time it holds the
//! frame and prints the percentiles. Both transports wake the receiver by blocking (event
//! listener / socket read), as the pipeline does.

use std::io::{BufRead, BufReader, Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use hvs_runtime::clock::monotonic_ns;
use hvs_runtime::ipc::IpcNode;
use hvs_runtime::stats::{LatencySummary, summarize};
use hvs_shared::messages::{FrameHeader, Sequenced, StereoFrame320x240, StereoFrame640x480};
use hvs_shared::topics::{self, Topic};
use serde::{Deserialize, Serialize};

use crate::bench_view::{ViewLoad, Watcher};

/// Frame sizes the benchmark knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
pub enum FrameSize {
    /// 320x240 pair (153 672 bytes).
    #[value(name = "320x240")]
    Lo,
    /// 640x480 pair (614 472 bytes).
    #[value(name = "640x480")]
    Hi,
}

impl FrameSize {
    fn bytes(self) -> usize {
        match self {
            Self::Lo => size_of::<StereoFrame320x240>(),
            Self::Hi => size_of::<StereoFrame640x480>(),
        }
    }

    fn label(self) -> &'static str {
        match self {
            Self::Lo => "320x240",
            Self::Hi => "640x480",
        }
    }
}

/// Transports compared.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
pub enum Transport {
    /// iceoryx2 publish/subscribe, zero copy.
    Iceoryx2,
    /// A Unix stream socket carrying a copy of the bytes.
    UnixSocket,
}

/// What the receiver prints (one JSON line).
#[derive(Debug, Serialize, Deserialize)]
pub struct ReceiverResult {
    /// Samples received.
    pub received: u64,
    /// Latency percentiles, ns.
    pub p50_ns: u64,
    /// 99th percentile, ns.
    pub p99_ns: u64,
    /// Largest, ns.
    pub max_ns: u64,
}

/// Parent side: runs every size and transport and prints a table.
pub fn run_ipc(count: u32, rate_hz: f64) -> anyhow::Result<()> {
    if count < 10 {
        bail!("--count {count} is too small for percentiles (use at least 10)");
    }
    if !(rate_hz > 0.0 && rate_hz <= 10_000.0) {
        bail!("--rate {rate_hz} must be in (0, 10000] Hz");
    }
    println!(
        "one-hop latency, sender process -> receiver process, {count} frames at {rate_hz} Hz, blocking receiver"
    );
    println!(
        "{:<9} {:<12} {:>12} {:>10} {:>10} {:>10}",
        "size", "transport", "bytes", "p50 us", "p99 us", "max us"
    );
    let mut rows = Vec::new();
    for size in [FrameSize::Lo, FrameSize::Hi] {
        for transport in [Transport::Iceoryx2, Transport::UnixSocket] {
            let r = run_pair(size, transport, count, rate_hz)?;
            println!(
                "{:<9} {:<12} {:>12} {:>10.1} {:>10.1} {:>10.1}",
                size.label(),
                match transport {
                    Transport::Iceoryx2 => "iceoryx2",
                    Transport::UnixSocket => "unix-socket",
                },
                size.bytes(),
                r.p50_ns as f64 / 1e3,
                r.p99_ns as f64 / 1e3,
                r.max_ns as f64 / 1e3
            );
            rows.push((size, transport, r));
        }
    }
    let p50 = |s, t| {
        rows.iter()
            .find(|r| r.0 == s && r.1 == t)
            .map_or(0.0, |r| r.2.p50_ns as f64)
    };
    println!(
        "iceoryx2 640x480 / 320x240 p50: {:.2}x for {:.1}x the bytes (zero copy: cost does not grow with size)",
        p50(FrameSize::Hi, Transport::Iceoryx2) / p50(FrameSize::Lo, Transport::Iceoryx2).max(1.0),
        FrameSize::Hi.bytes() as f64 / FrameSize::Lo.bytes() as f64
    );
    for size in [FrameSize::Lo, FrameSize::Hi] {
        println!(
            "{}: unix-socket / iceoryx2 p50 = {:.1}x",
            size.label(),
            p50(size, Transport::UnixSocket) / p50(size, Transport::Iceoryx2).max(1.0)
        );
    }
    Ok(())
}

fn run_pair(
    size: FrameSize,
    transport: Transport,
    count: u32,
    rate_hz: f64,
) -> anyhow::Result<ReceiverResult> {
    let instance = format!("bench{}", std::process::id());
    let exe = std::env::current_exe().context("cannot locate the hvs executable")?;
    let socket_path = std::env::temp_dir().join(format!("hvs-bench-{}.sock", std::process::id()));
    let _ = std::fs::remove_file(&socket_path);
    let listener = match transport {
        Transport::UnixSocket => Some(
            UnixListener::bind(&socket_path)
                .with_context(|| format!("cannot bind {}", socket_path.display()))?,
        ),
        Transport::Iceoryx2 => None,
    };
    let mut child = Command::new(exe)
        .args([
            "bench",
            "ipc-receiver",
            "--instance",
            &instance,
            "--count",
            &count.to_string(),
        ])
        .arg("--size")
        .arg(size.label())
        .arg("--transport")
        .arg(match transport {
            Transport::Iceoryx2 => "iceoryx2",
            Transport::UnixSocket => "unix-socket",
        })
        .arg("--socket")
        .arg(&socket_path)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .context("cannot start the receiver process")?;
    let stdout = child.stdout.take().context("receiver stdout")?;
    let mut lines = BufReader::new(stdout).lines();
    let period = Duration::from_secs_f64(1.0 / rate_hz);
    let send_result = match transport {
        Transport::Iceoryx2 => {
            let node = IpcNode::create(&instance, "bench-sender")?;
            // Wait for the receiver's "ready" so no frame is sent before it subscribed.
            wait_ready(&mut lines)?;
            match size {
                FrameSize::Lo => {
                    send_iceoryx(&node, &topics::FRAMES_LO, count, period, |f| &mut f.header)
                }
                FrameSize::Hi => {
                    send_iceoryx(&node, &topics::FRAMES_HI, count, period, |f| &mut f.header)
                }
            }
        }
        Transport::UnixSocket => {
            let Some(listener) = listener else {
                bail!("no listener");
            };
            let (mut stream, _) = listener.accept().context("receiver did not connect")?;
            wait_ready(&mut lines)?;
            send_socket(&mut stream, size.bytes(), count, period)
        }
    };
    let line = lines.next().context("receiver printed no result")??;
    let status = child.wait()?;
    let _ = std::fs::remove_file(&socket_path);
    send_result?;
    if !status.success() {
        bail!("receiver failed: {status}");
    }
    let result: ReceiverResult =
        serde_json::from_str(&line).with_context(|| format!("bad receiver output {line:?}"))?;
    if result.received < count as u64 * 9 / 10 {
        bail!("receiver got only {} of {count} frames", result.received);
    }
    Ok(result)
}

fn wait_ready(
    lines: &mut std::io::Lines<BufReader<std::process::ChildStdout>>,
) -> anyhow::Result<()> {
    match lines.next() {
        Some(Ok(l)) if l == "ready" => Ok(()),
        other => bail!("receiver did not get ready: {other:?}"),
    }
}

fn send_iceoryx<T>(
    node: &IpcNode,
    topic: &Topic<T>,
    count: u32,
    period: Duration,
    header: fn(&mut T) -> &mut FrameHeader,
) -> anyhow::Result<()>
where
    T: core::fmt::Debug + iceoryx2::prelude::ZeroCopySend + bytemuck::Pod + 'static,
{
    let mut publisher = node.publisher(topic)?;
    let mut next = Instant::now();
    for i in 1..=count as u64 {
        let mut sample = publisher.loan()?;
        let h = header(sample.payload_mut());
        h.frame_id = i;
        h.published_ns = monotonic_ns();
        publisher.send(sample)?;
        next += period;
        if let Some(wait) = next.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
    }
    // Give the receiver time to take the last frames before the service goes away.
    std::thread::sleep(Duration::from_millis(200));
    Ok(())
}

fn send_socket(
    stream: &mut UnixStream,
    bytes: usize,
    count: u32,
    period: Duration,
) -> anyhow::Result<()> {
    let mut frame = vec![0u8; bytes];
    let mut next = Instant::now();
    for i in 1..=count as u64 {
        frame[..8].copy_from_slice(&i.to_le_bytes());
        frame[8..16].copy_from_slice(&monotonic_ns().to_le_bytes());
        stream.write_all(&frame).context("socket write")?;
        next += period;
        if let Some(wait) = next.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
    }
    Ok(())
}

/// Child side: receive `count` frames, print "ready" first and the result JSON last.
pub fn run_receiver(
    instance: &str,
    size: FrameSize,
    transport: Transport,
    count: u32,
    socket: PathBuf,
) -> anyhow::Result<()> {
    let mut latencies = Vec::with_capacity(count as usize);
    match transport {
        Transport::Iceoryx2 => {
            let node = IpcNode::create(instance, "bench-receiver")?;
            match size {
                FrameSize::Lo => {
                    receive_iceoryx(&node, &topics::FRAMES_LO, count, &mut latencies, |f| {
                        &f.header
                    })?
                }
                FrameSize::Hi => {
                    receive_iceoryx(&node, &topics::FRAMES_HI, count, &mut latencies, |f| {
                        &f.header
                    })?
                }
            }
        }
        Transport::UnixSocket => {
            let mut stream = UnixStream::connect(&socket)
                .with_context(|| format!("cannot connect {}", socket.display()))?;
            println!("ready");
            std::io::stdout().flush()?;
            let mut frame = vec![0u8; size.bytes()];
            for _ in 0..count {
                stream.read_exact(&mut frame).context("socket read")?;
                let now = monotonic_ns();
                let mut stamp = [0u8; 8];
                stamp.copy_from_slice(&frame[8..16]);
                latencies.push(now.saturating_sub(u64::from_le_bytes(stamp)));
            }
        }
    }
    let s: LatencySummary = summarize(&latencies);
    let result = ReceiverResult {
        received: s.count,
        p50_ns: s.p50_ns,
        p99_ns: s.p99_ns,
        max_ns: s.max_ns,
    };
    println!("{}", serde_json::to_string(&result)?);
    Ok(())
}

fn receive_iceoryx<T>(
    node: &IpcNode,
    topic: &Topic<T>,
    count: u32,
    latencies: &mut Vec<u64>,
    header: fn(&T) -> &FrameHeader,
) -> anyhow::Result<()>
where
    T: core::fmt::Debug + iceoryx2::prelude::ZeroCopySend + Sequenced + 'static,
{
    let sub = node.subscriber(topic, 2)?;
    println!("ready");
    std::io::stdout().flush()?;
    let deadline = Instant::now() + Duration::from_secs(60);
    while latencies.len() < count as usize && Instant::now() < deadline {
        // Block until notified (or 100 ms), like the pipeline's stages.
        let _ = sub
            .listener()
            .timed_wait(|_| {}, Duration::from_millis(100));
        while let Some(s) = sub.receive()? {
            let now = monotonic_ns();
            latencies.push(now.saturating_sub(header(s.payload()).published_ns));
        }
    }
    Ok(())
}

/// Latencies of the first seconds of each `--view compare` run are left out: the stages
/// starting hold most of the tail, and they start no differently with a client watching.
const WARM_UP: Duration = Duration::from_secs(5);

/// One run's line of the `--view compare` table.
struct ViewCost {
    load: ViewLoad,
    decisions_hz: f64,
    p50_ms: f64,
    p99_ms: f64,
    view_cpu_pct: f64,
    all_cpu_pct: f64,
    client_msgs_hz: f64,
    client_mb_s: f64,
}

/// `hvs bench pipeline`: the whole pipeline in its own instance for `duration`, then a table;
/// with `view` a client watches the live view meanwhile (`compare`: none, page, all in turn).
pub fn run_pipeline(config: PathBuf, duration: Duration, view: ViewLoad) -> anyhow::Result<()> {
    let loads = match view {
        ViewLoad::Compare => vec![ViewLoad::None, ViewLoad::Page, ViewLoad::All],
        one => vec![one],
    };
    let compare = loads.len() > 1;
    let mut costs = Vec::new();
    for (i, load) in loads.into_iter().enumerate() {
        let instance = format!("bench{}-{i}", std::process::id());
        let watcher = Watcher::start(&instance, load);
        let report = crate::run::run(&crate::run::RunOptions {
            config_path: config.clone(),
            instance: Some(instance),
            duration: Some(duration),
            report: None,
            replay: None,
            record: None,
            bridge_listen: Vec::new(),
            bridge_connect: Vec::new(),
            latency_warm_up: if compare { WARM_UP } else { Duration::ZERO },
        })?;
        let (msgs, bytes) = watcher.map_or((0, 0), Watcher::finish);
        print_pipeline(&report, load);
        let secs = report.duration_s.max(1e-3);
        costs.push(ViewCost {
            load,
            decisions_hz: stage_out(&report, "decision") as f64 / secs,
            p50_ms: report.latency.capture_to_decision.p50_ms,
            p99_ms: report.latency.capture_to_decision.p99_ms,
            view_cpu_pct: report
                .stages
                .iter()
                .find(|s| s.stage == "view")
                .map_or(0.0, |s| s.cpu_pct),
            all_cpu_pct: report.stages.iter().map(|s| s.cpu_pct).sum(),
            client_msgs_hz: msgs as f64 / secs,
            client_mb_s: bytes as f64 / secs / 1e6,
        });
    }
    if costs.len() > 1 {
        print_view_costs(&costs);
    }
    Ok(())
}

/// The `--view compare` table and its targets.
fn print_view_costs(costs: &[ViewCost]) {
    println!();
    println!(
        "what watching costs (docs/view.md; latencies after a {} s warm-up)",
        WARM_UP.as_secs()
    );
    println!(
        "{:<22} {:>11} {:>9} {:>9} {:>10} {:>10} {:>10} {:>8}",
        "view load", "decisions/s", "p50 ms", "p99 ms", "view cpu%", "all cpu%", "client/s", "MB/s"
    );
    for c in costs {
        println!(
            "{:<22} {:>11.1} {:>9.2} {:>9.2} {:>10.1} {:>10.1} {:>10.1} {:>8.2}",
            c.load.label(),
            c.decisions_hz,
            c.p50_ms,
            c.p99_ms,
            c.view_cpu_pct,
            c.all_cpu_pct,
            c.client_msgs_hz,
            c.client_mb_s
        );
    }
    let verdict = |ok: bool| if ok { "met" } else { "NOT met" };
    let base = costs.iter().find(|c| c.load == ViewLoad::None);
    println!("targets");
    for c in costs.iter().filter(|c| c.load != ViewLoad::None) {
        if c.client_msgs_hz == 0.0 {
            // Nobody watched (the view's port was taken, say): nothing was measured.
            println!(
                "  {}: NOT measured: the client received nothing (is the view's port, \
                 [view] bind, free?)",
                c.load.label()
            );
            continue;
        }
        if let Some(b) = base {
            let d = c.p99_ms - b.p99_ms;
            println!(
                "  {}: capture->decision p99 within 2 ms of no client: {:+.2} ms  {}",
                c.load.label(),
                d,
                verdict(d <= 2.0)
            );
        }
        println!(
            "  {}: view stage < 25 % of one core: {:.1} %  {}",
            c.load.label(),
            c.view_cpu_pct,
            verdict(c.view_cpu_pct < 25.0)
        );
    }
}

/// The table of one run.
fn print_pipeline(report: &crate::report::RunReport, view: ViewLoad) {
    let secs = report.duration_s.max(1e-3);
    println!();
    println!(
        "pipeline over {:.1} s, live view: {}",
        report.duration_s,
        view.label()
    );
    println!(
        "{:<10} {:>9} {:>9} {:>9} {:>8} {:>8} {:>8} {:>9}",
        "stage", "in", "out", "out Hz", "drops", "restarts", "cpu %", "rss MiB"
    );
    for s in &report.stages {
        println!(
            "{:<10} {:>9} {:>9} {:>9.1} {:>8} {:>8} {:>8.1} {:>9.1}",
            s.stage,
            s.frames_in,
            s.frames_out,
            s.frames_out as f64 / secs,
            s.drops,
            s.restarts,
            s.cpu_pct,
            s.rss_max_mib
        );
    }
    let cpu: f64 = report.stages.iter().map(|s| s.cpu_pct).sum();
    println!(
        "all stages: {cpu:.0} % of one core ({} cores here)",
        cores()
    );
    let l = &report.latency;
    println!(
        "{:<22} {:>7} {:>9} {:>9} {:>9}",
        "latency", "count", "p50 ms", "p99 ms", "max ms"
    );
    for (name, v) in [
        ("capture -> decision", &l.capture_to_decision),
        ("capture -> command", &l.capture_to_command),
    ] {
        println!(
            "{:<22} {:>7} {:>9.2} {:>9.2} {:>9.2}",
            name, v.count, v.p50_ms, v.p99_ms, v.max_ms
        );
    }
    print_targets(report, secs);
}

fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

fn stage_out(report: &crate::report::RunReport, stage: &str) -> u64 {
    report
        .stages
        .iter()
        .find(|s| s.stage == stage)
        .map_or(0, |s| s.frames_out)
}

/// The pipeline targets of docs/performance.md, each with its measured value.
fn print_targets(report: &crate::report::RunReport, secs: f64) {
    let captured = stage_out(report, "capture");
    let decided = stage_out(report, "decision");
    let hi_hz = stage_out(report, "stereo-hi") as f64 / secs;
    let p99 = report.latency.capture_to_decision.p99_ms;
    let verdict = |ok: bool| if ok { "met" } else { "NOT met" };
    println!("targets");
    println!(
        "  every 320x240 frame decided:  {decided} decisions for {captured} pairs ({:.2} %)  {}",
        100.0 * decided as f64 / captured.max(1) as f64,
        verdict(captured > 0 && decided + 1 >= captured)
    );
    println!(
        "  capture->decision p99 < 33 ms: {p99:.2} ms  {}",
        verdict(p99 > 0.0 && p99 < 33.0)
    );
    println!(
        "  640x480 worker >= 10 Hz:       {hi_hz:.1} Hz  {}",
        verdict(hi_hz >= 10.0)
    );
}
