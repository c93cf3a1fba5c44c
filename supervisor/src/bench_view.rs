//! `hvs bench pipeline --view ...`: what watching the robot costs it. A client thread finds
//! the view stage's port in the supervisor's status, connects over the Foxglove WebSocket
//! protocol and reads everything it subscribed to until the run ends, while the pipeline's
//! own report measures decision rate, capture-to-decision latency and CPU per stage.
//!
//! The browser itself runs on the operator's laptop, not on the robot, so "the page open" is
//! measured as what the robot sees of it: one client subscribed to the page's channels
//! ([`hvs_view::page::PAGE_TOPICS`]).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use hvs_runtime::ipc::{IpcNode, TopicSubscriber};
use hvs_shared::messages::{SupervisorStatus, decode_name};
use hvs_shared::topics;
use hvs_view::client::FoxgloveClient;
use hvs_view::note;

/// Who watches the robot during a benchmark run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ViewLoad {
    /// No client (the view stage runs, idle).
    None,
    /// The web page open: one client on the page's channels.
    Page,
    /// One Foxglove client subscribed to every channel.
    All,
    /// The three above in turn, then a table side by side.
    Compare,
}

impl ViewLoad {
    /// The label in tables.
    pub fn label(self) -> &'static str {
        match self {
            ViewLoad::None => "no client",
            ViewLoad::Page => "page open",
            ViewLoad::All => "client on everything",
            ViewLoad::Compare => "compare",
        }
    }
}

/// A running client and what it has read.
pub struct Watcher {
    stop: Arc<AtomicBool>,
    messages: Arc<AtomicU64>,
    bytes: Arc<AtomicU64>,
    thread: Option<JoinHandle<Result<(), String>>>,
}

impl Watcher {
    /// Starts the client thread for `load` on `instance` (nothing for [`ViewLoad::None`]).
    pub fn start(instance: &str, load: ViewLoad) -> Option<Self> {
        let topics: Vec<String> = match load {
            ViewLoad::None | ViewLoad::Compare => return None,
            ViewLoad::Page => hvs_view::page::PAGE_TOPICS
                .iter()
                .map(|t| (*t).to_string())
                .collect(),
            ViewLoad::All => Vec::new(),
        };
        let stop = Arc::new(AtomicBool::new(false));
        let messages = Arc::new(AtomicU64::new(0));
        let bytes = Arc::new(AtomicU64::new(0));
        let (s, m, b) = (Arc::clone(&stop), Arc::clone(&messages), Arc::clone(&bytes));
        let instance = instance.to_string();
        let thread = std::thread::Builder::new()
            .name("bench-view-client".into())
            .spawn(move || watch(&instance, &topics, &s, &m, &b))
            .ok()?;
        Some(Self {
            stop,
            messages,
            bytes,
            thread: Some(thread),
        })
    }

    /// Stops the client: (messages, bytes) read.
    pub fn finish(mut self) -> (u64, u64) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            match t.join() {
                Ok(Err(e)) => eprintln!("hvs bench: the view client failed: {e}"),
                Err(_) => eprintln!("hvs bench: the view client panicked"),
                Ok(Ok(())) => {}
            }
        }
        (
            self.messages.load(Ordering::Relaxed),
            self.bytes.load(Ordering::Relaxed),
        )
    }
}

/// The view's WebSocket port from its note in the supervisor's newest status.
fn view_port(status: &TopicSubscriber<SupervisorStatus>) -> Result<Option<u16>, String> {
    let Some(s) = status.receive_latest().map_err(|e| e.to_string())? else {
        return Ok(None);
    };
    let st = s.payload();
    let n = (st.stage_count as usize).min(st.stages.len());
    Ok(st.stages[..n]
        .iter()
        .find(|e| decode_name(&e.stage) == "view")
        .and_then(|e| note::ws_port(decode_name(&e.note))))
}

fn watch(
    instance: &str,
    topics: &[String],
    stop: &AtomicBool,
    messages: &AtomicU64,
    bytes: &AtomicU64,
) -> Result<(), String> {
    let node = IpcNode::create(instance, "bench-view").map_err(|e| e.to_string())?;
    let status = node
        .subscriber(&topics::SUPERVISOR_STATUS, 1)
        .map_err(|e| e.to_string())?;
    let deadline = Instant::now() + Duration::from_secs(60);
    // Connect, read until the connection ends, and connect again: the pipeline stopping (or
    // the view restarting) closes it; the counts say what was watched.
    while !stop.load(Ordering::Relaxed) {
        let Some(port) = view_port(&status)? else {
            if Instant::now() > deadline && messages.load(Ordering::Relaxed) == 0 {
                return Err("the view did not serve within 60 s".into());
            }
            std::thread::sleep(Duration::from_millis(200));
            continue;
        };
        let Ok(mut client) = FoxgloveClient::connect(port) else {
            std::thread::sleep(Duration::from_millis(200));
            continue;
        };
        let all: Vec<String> = client.channels.keys().cloned().collect();
        let want: Vec<&str> = if topics.is_empty() {
            all.iter().map(String::as_str).collect()
        } else {
            topics.iter().map(String::as_str).collect()
        };
        client.subscribe(&want)?;
        while !stop.load(Ordering::Relaxed) {
            match client.poll() {
                Ok(Some(r)) => {
                    messages.fetch_add(1, Ordering::Relaxed);
                    bytes.fetch_add(r.payload.len() as u64, Ordering::Relaxed);
                }
                Ok(None) => {}
                Err(_) => break,
            }
        }
    }
    Ok(())
}
