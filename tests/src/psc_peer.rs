//! A scripted servo controller on a real pseudo-terminal, for the actuator's link tests: it
//! answers `!SCVER?` late, never, with an echo or with garbage, logs every position command
//! it receives with its arrival time, and can vanish (pty closed, device node removed) and
//! come back under the same path.

use std::os::fd::{AsFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};

/// How the controller answers a version query.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PeerBehaviour {
    /// Never answers (switched off).
    Silent,
    /// Answers `1.4` this long after each query.
    Answer(Duration),
    /// Sends back every byte it receives (a loopback adapter), nothing else.
    Echo,
    /// Answers each query with bytes that are not a version.
    Garbage,
}

/// A position command the peer received.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PositionCommand {
    /// When its last byte arrived.
    pub at: Instant,
    /// Channel.
    pub channel: u8,
    /// Ramp.
    pub ramp: u8,
    /// Pulse width, 2 us units.
    pub pulse: u16,
}

/// What the peer saw and did.
#[derive(Debug, Default, Clone)]
pub struct PeerLog {
    /// Arrival time of every version query.
    pub queries: Vec<Instant>,
    /// When each version reply was written.
    pub replies: Vec<Instant>,
    /// Every position command.
    pub commands: Vec<PositionCommand>,
    /// Bytes that were neither (counted).
    pub other_bytes: usize,
}

struct Shared {
    behaviour: Mutex<PeerBehaviour>,
    log: Mutex<PeerLog>,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// The running peer: a pty whose slave is reachable at [`link`](Self::link).
pub struct PscPeer {
    link: PathBuf,
    shared: Arc<Shared>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl PscPeer {
    /// Creates the pty, links `link` to its slave and starts answering with `behaviour`.
    pub fn start(link: &Path, behaviour: PeerBehaviour) -> Self {
        let shared = Arc::new(Shared {
            behaviour: Mutex::new(behaviour),
            log: Mutex::new(PeerLog::default()),
        });
        let mut peer = Self {
            link: link.to_path_buf(),
            shared,
            stop: Arc::new(AtomicBool::new(false)),
            thread: None,
        };
        peer.appear();
        peer
    }

    /// The path the actuator opens.
    pub fn link(&self) -> &Path {
        &self.link
    }

    /// Changes how version queries are answered from now on.
    pub fn set_behaviour(&self, behaviour: PeerBehaviour) {
        *lock(&self.shared.behaviour) = behaviour;
    }

    /// A copy of the log.
    pub fn log(&self) -> PeerLog {
        lock(&self.shared.log).clone()
    }

    /// Closes the pty and removes the device node (an adapter pulled out).
    pub fn vanish(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        let _ = std::fs::remove_file(&self.link);
    }

    /// A new pty under the same path (the adapter plugged back in).
    pub fn appear(&mut self) {
        let pty = nix::pty::openpty(None, None).expect("openpty");
        let mut t = tcgetattr(&pty.slave).expect("tcgetattr");
        cfmakeraw(&mut t);
        tcsetattr(&pty.slave, SetArg::TCSANOW, &t).expect("raw mode");
        let slave = nix::unistd::ttyname(&pty.slave).expect("pty name");
        let _ = std::fs::remove_file(&self.link);
        std::os::unix::fs::symlink(&slave, &self.link).expect("link the pty");
        self.stop = Arc::new(AtomicBool::new(false));
        let stop = Arc::clone(&self.stop);
        let shared = Arc::clone(&self.shared);
        self.thread = Some(std::thread::spawn(move || {
            serve(pty.master, pty.slave, &shared, &stop)
        }));
    }
}

impl Drop for PscPeer {
    fn drop(&mut self) {
        self.vanish();
    }
}

/// The peer's loop: read, parse, answer when due. Holds the slave open so the master never
/// reads EIO while the actuator reopens.
fn serve(master: OwnedFd, _slave: OwnedFd, shared: &Shared, stop: &AtomicBool) {
    let mut rx: Vec<u8> = Vec::new();
    let mut due: Vec<(Instant, &'static [u8])> = Vec::new();
    let mut buf = [0u8; 256];
    while !stop.load(Ordering::Relaxed) {
        let mut fds = [PollFd::new(master.as_fd(), PollFlags::POLLIN)];
        let ready = poll(&mut fds, PollTimeout::from(2u16)).unwrap_or(0);
        let now = Instant::now();
        if ready > 0 {
            match nix::unistd::read(&master, &mut buf) {
                Ok(n) if n > 0 => {
                    let behaviour = *lock(&shared.behaviour);
                    if behaviour == PeerBehaviour::Echo {
                        let _ = nix::unistd::write(&master, &buf[..n]);
                    }
                    rx.extend_from_slice(&buf[..n]);
                    parse(&mut rx, now, behaviour, shared, &mut due);
                }
                _ => std::thread::sleep(Duration::from_millis(2)),
            }
        }
        due.retain(|(at, bytes)| {
            if *at > now {
                return true;
            }
            if nix::unistd::write(&master, bytes).is_ok() && bytes == b"1.4" {
                lock(&shared.log).replies.push(Instant::now());
            }
            false
        });
    }
}

fn parse(
    rx: &mut Vec<u8>,
    now: Instant,
    behaviour: PeerBehaviour,
    shared: &Shared,
    due: &mut Vec<(Instant, &'static [u8])>,
) {
    let mut log = lock(&shared.log);
    loop {
        let Some(start) = rx.windows(3).position(|w| w == b"!SC") else {
            // Keep a possible start of a frame.
            let keep = rx.len().min(2);
            log.other_bytes += rx.len() - keep;
            rx.drain(..rx.len() - keep);
            return;
        };
        log.other_bytes += start;
        rx.drain(..start);
        if rx.len() < 8 {
            return;
        }
        let frame: Vec<u8> = rx.drain(..8).collect();
        if &frame == b"!SCVER?\r" {
            log.queries.push(now);
            match behaviour {
                PeerBehaviour::Answer(delay) => due.push((now + delay, b"1.4")),
                PeerBehaviour::Garbage => due.push((now, b"\xfeZ?\x00\x13")),
                PeerBehaviour::Silent | PeerBehaviour::Echo => {}
            }
        } else {
            log.commands.push(PositionCommand {
                at: now,
                channel: frame[3],
                ramp: frame[4],
                pulse: u16::from_le_bytes([frame[5], frame[6]]),
            });
        }
    }
}
