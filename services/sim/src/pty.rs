//! The serial side of the PSC emulator: a pseudo-terminal whose slave end a client opens exactly
//! like `/dev/ttyUSB0` (through a symlink), with a reader thread feeding the emulator.
//!
//! Design: one background thread polls the pty master (`poll(2)` with a timeout of at most
//! 20 ms, shorter when a reply falls due sooner). Bytes read are stamped with [`SimClock`] time
//! and fed to the shared [`PscEmulator`]; replies are written back when due. Before feeding bytes
//! the thread reads the line settings of the slave (`TCGETS2`) and records them in the emulator,
//! which ignores bytes while they are not 2400 8N1. The pty keeps its own slave descriptor open
//! for its whole life, so the master never reads EIO when a client closes the port, and a client
//! may reopen it at any time. Dropping the [`PscPty`] stops the thread and removes the symlink
//! (if it still points at this pty's slave).

use std::os::fd::{AsFd, AsRawFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use nix::errno::Errno;
use nix::fcntl::{FcntlArg, OFlag, fcntl};
use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
use nix::sys::termios::{
    BaudRate, ControlFlags, SetArg, cfmakeraw, cfsetspeed, tcgetattr, tcsetattr,
};

use crate::psc::SerialSettings;
use crate::world::{SharedPsc, lock_psc};

/// Monotonic simulation clock: seconds since its creation. Copies share the origin.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SimClock {
    origin: Instant,
}

impl Default for SimClock {
    fn default() -> Self {
        Self::new()
    }
}

impl SimClock {
    /// A clock starting now.
    pub fn new() -> Self {
        SimClock {
            origin: Instant::now(),
        }
    }

    /// A clock whose zero is `origin`.
    pub fn with_origin(origin: Instant) -> Self {
        SimClock { origin }
    }

    /// Seconds since the origin.
    pub fn now_s(&self) -> f64 {
        self.origin.elapsed().as_secs_f64()
    }

    /// The origin instant.
    pub fn origin(&self) -> Instant {
        self.origin
    }
}

/// Errors of [`PscPty::create`].
#[derive(Debug, thiserror::Error)]
pub enum PtyError {
    /// `openpty` failed.
    #[error("cannot open a pseudo-terminal: {0}")]
    OpenPty(#[source] nix::Error),
    /// The slave's name could not be found.
    #[error("cannot get the name of the pty slave: {0}")]
    SlaveName(#[source] nix::Error),
    /// Setting up the terminal modes failed.
    #[error("cannot set raw 2400 8N1 mode on {path}: {source}")]
    Termios {
        /// The slave device.
        path: PathBuf,
        /// Cause.
        source: nix::Error,
    },
    /// The link path exists and is not a symlink (it is never overwritten).
    #[error("{path} exists and is not a symlink; refusing to replace it")]
    LinkPathTaken {
        /// The link path.
        path: PathBuf,
    },
    /// Creating the symlink failed.
    #[error("cannot create symlink {link} -> {target}: {source}")]
    Link {
        /// The link path.
        link: PathBuf,
        /// The slave device.
        target: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// The reader thread could not be started.
    #[error("cannot start the pty reader thread: {0}")]
    Thread(#[source] std::io::Error),
}

/// Statistics of the serial side.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PtyStats {
    /// Bytes read from the client.
    pub bytes_received: u64,
    /// Reply bytes written to the client.
    pub reply_bytes_sent: u64,
    /// Reply bytes dropped because the client did not read (pty buffer full).
    pub reply_bytes_dropped: u64,
    /// Line settings seen at the last read.
    pub serial_settings: Option<SerialSettings>,
    /// The last settings mismatch message, while the settings are wrong.
    pub serial_mismatch: Option<String>,
    /// Read/poll errors other than "try again".
    pub io_errors: u64,
}

/// A pseudo-terminal that serves the PSC emulator (see the module docs).
#[derive(Debug)]
pub struct PscPty {
    link_path: PathBuf,
    slave_path: PathBuf,
    _slave: Arc<OwnedFd>,
    stop: Arc<AtomicBool>,
    stats: Arc<Mutex<PtyStats>>,
    thread: Option<JoinHandle<()>>,
}

/// Longest poll wait of the reader thread.
const POLL_MAX_MS: u16 = 20;

impl PscPty {
    /// Opens a pty pair, sets the slave to raw 2400 8N1, points `link_path` at the slave
    /// (replacing an existing symlink there), and starts the reader thread feeding `psc` with
    /// bytes stamped by `clock`.
    pub fn create(
        link_path: impl AsRef<Path>,
        psc: SharedPsc,
        clock: SimClock,
    ) -> Result<PscPty, PtyError> {
        let link_path = link_path.as_ref().to_path_buf();
        let pty = nix::pty::openpty(None, None).map_err(PtyError::OpenPty)?;
        let slave_path = nix::unistd::ttyname(pty.slave.as_fd()).map_err(PtyError::SlaveName)?;
        let termios_err = |source| PtyError::Termios {
            path: slave_path.clone(),
            source,
        };
        let mut t = tcgetattr(pty.slave.as_fd()).map_err(termios_err)?;
        cfmakeraw(&mut t);
        t.control_flags &= !(ControlFlags::CSIZE
            | ControlFlags::PARENB
            | ControlFlags::PARODD
            | ControlFlags::CSTOPB);
        t.control_flags |= ControlFlags::CS8 | ControlFlags::CREAD | ControlFlags::CLOCAL;
        cfsetspeed(&mut t, BaudRate::B2400).map_err(termios_err)?;
        tcsetattr(pty.slave.as_fd(), SetArg::TCSANOW, &t).map_err(termios_err)?;
        let flags = fcntl(pty.master.as_fd(), FcntlArg::F_GETFL).map_err(termios_err)?;
        fcntl(
            pty.master.as_fd(),
            FcntlArg::F_SETFL(OFlag::from_bits_truncate(flags) | OFlag::O_NONBLOCK),
        )
        .map_err(termios_err)?;
        replace_symlink(&link_path, &slave_path)?;
        let slave = Arc::new(pty.slave);
        let stop = Arc::new(AtomicBool::new(false));
        let stats = Arc::new(Mutex::new(PtyStats::default()));
        let worker = Worker {
            master: pty.master,
            slave: Arc::clone(&slave),
            psc,
            clock,
            stop: Arc::clone(&stop),
            stats: Arc::clone(&stats),
        };
        let thread = std::thread::Builder::new()
            .name("psc-pty".into())
            .spawn(move || worker.run());
        let thread = match thread {
            Ok(t) => t,
            Err(e) => {
                let _ = std::fs::remove_file(&link_path);
                return Err(PtyError::Thread(e));
            }
        };
        tracing::info!(link = %link_path.display(), slave = %slave_path.display(), "PSC pty ready");
        Ok(PscPty {
            link_path,
            slave_path,
            _slave: slave,
            stop,
            stats,
            thread: Some(thread),
        })
    }

    /// The symlink clients open.
    pub fn link_path(&self) -> &Path {
        &self.link_path
    }

    /// The pty slave device (e.g. `/dev/pts/7`).
    pub fn slave_path(&self) -> &Path {
        &self.slave_path
    }

    /// A snapshot of the statistics.
    pub fn stats(&self) -> PtyStats {
        self.stats
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }
}

impl Drop for PscPty {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        if std::fs::read_link(&self.link_path).is_ok_and(|target| target == self.slave_path) {
            let _ = std::fs::remove_file(&self.link_path);
        }
    }
}

/// Creates `link` -> `target` atomically, replacing an existing symlink but never a file.
fn replace_symlink(link: &Path, target: &Path) -> Result<(), PtyError> {
    let link_err = |source| PtyError::Link {
        link: link.to_path_buf(),
        target: target.to_path_buf(),
        source,
    };
    if let Ok(meta) = std::fs::symlink_metadata(link)
        && !meta.file_type().is_symlink()
    {
        return Err(PtyError::LinkPathTaken {
            path: link.to_path_buf(),
        });
    }
    let mut tmp_name = link.as_os_str().to_owned();
    tmp_name.push(format!(".tmp-{}", std::process::id()));
    let tmp = PathBuf::from(tmp_name);
    let _ = std::fs::remove_file(&tmp);
    std::os::unix::fs::symlink(target, &tmp).map_err(link_err)?;
    std::fs::rename(&tmp, link).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        link_err(e)
    })
}

/// Reads the slave's line settings with `TCGETS2` (exact baud even for `BOTHER` rates).
#[cfg(target_os = "linux")]
pub fn read_serial_settings(fd: &impl AsRawFd) -> Result<SerialSettings, Errno> {
    // SAFETY: `termios2` is plain old data, so a zeroed value is valid; TCGETS2 writes exactly
    // one `termios2` through the pointer, which points at a live local of that type.
    let mut t: libc::termios2 = unsafe { std::mem::zeroed() };
    let rc = unsafe { libc::ioctl(fd.as_raw_fd(), libc::TCGETS2, &mut t as *mut libc::termios2) };
    Errno::result(rc)?;
    Ok(SerialSettings::from_termios2(&t))
}

struct Worker {
    master: OwnedFd,
    slave: Arc<OwnedFd>,
    psc: SharedPsc,
    clock: SimClock,
    stop: Arc<AtomicBool>,
    stats: Arc<Mutex<PtyStats>>,
}

impl Worker {
    fn stats(&self) -> std::sync::MutexGuard<'_, PtyStats> {
        self.stats.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn run(self) {
        let mut buf = [0u8; 512];
        let mut pending_out: Vec<u8> = Vec::new();
        while !self.stop.load(Ordering::Relaxed) {
            let now = self.clock.now_s();
            let next_due = lock_psc(&self.psc).next_reply_due_s();
            let wait_ms = match next_due {
                Some(t) if pending_out.is_empty() => {
                    (((t - now).max(0.0) * 1e3).ceil() as u16).min(POLL_MAX_MS)
                }
                Some(_) => 1,
                None if !pending_out.is_empty() => 1,
                None => POLL_MAX_MS,
            };
            let mut fds = [PollFd::new(self.master.as_fd(), PollFlags::POLLIN)];
            match poll(&mut fds, PollTimeout::from(wait_ms)) {
                Ok(_) | Err(Errno::EINTR) => {}
                Err(e) => {
                    self.stats().io_errors += 1;
                    tracing::warn!(error = %e, "PSC pty poll failed");
                    std::thread::sleep(Duration::from_millis(u64::from(POLL_MAX_MS)));
                    continue;
                }
            }
            let readable = fds[0]
                .revents()
                .is_some_and(|r| r.intersects(PollFlags::POLLIN));
            if readable {
                self.read_input(&mut buf);
            }
            let due = lock_psc(&self.psc).take_replies_due(self.clock.now_s());
            pending_out.extend_from_slice(&due);
            if !pending_out.is_empty() {
                self.write_output(&mut pending_out);
            }
        }
    }

    fn read_input(&self, buf: &mut [u8]) {
        match nix::unistd::read(self.master.as_fd(), buf) {
            Ok(0) | Err(Errno::EAGAIN) | Err(Errno::EINTR) => {}
            Ok(n) => {
                let arrival_s = self.clock.now_s();
                let settings = read_serial_settings(&self.slave.as_raw_fd()).ok();
                let mut psc = lock_psc(&self.psc);
                let mismatch = match settings {
                    Some(s) => psc.set_serial_settings(&s).err().map(|e| e.to_string()),
                    None => None,
                };
                psc.receive(&buf[..n], arrival_s);
                drop(psc);
                let mut st = self.stats();
                st.bytes_received += n as u64;
                if mismatch.is_some() && st.serial_mismatch != mismatch {
                    tracing::warn!(problem = ?mismatch, "PSC link: host serial settings are wrong; ignoring its bytes");
                }
                st.serial_settings = settings;
                st.serial_mismatch = mismatch;
            }
            Err(e) => {
                self.stats().io_errors += 1;
                tracing::warn!(error = %e, "PSC pty read failed");
                std::thread::sleep(Duration::from_millis(u64::from(POLL_MAX_MS)));
            }
        }
    }

    fn write_output(&self, out: &mut Vec<u8>) {
        match nix::unistd::write(self.master.as_fd(), out) {
            Ok(n) => {
                out.drain(..n);
                self.stats().reply_bytes_sent += n as u64;
            }
            Err(Errno::EAGAIN) | Err(Errno::EINTR) => {
                // The client is not reading; keep at most one reply's worth of bytes.
                if out.len() > 64 {
                    let drop_n = out.len() - 64;
                    out.drain(..drop_n);
                    self.stats().reply_bytes_dropped += drop_n as u64;
                }
            }
            Err(e) => {
                self.stats().io_errors += 1;
                tracing::warn!(error = %e, "PSC pty write failed");
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::psc::{PscEmulator, encode_position};
    use std::io::{Read, Write};

    fn shared() -> SharedPsc {
        Arc::new(Mutex::new(PscEmulator::new()))
    }

    fn wait_for(mut f: impl FnMut() -> bool) -> bool {
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(3) {
            if f() {
                return true;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        false
    }

    #[test]
    fn round_trip_through_serialport() {
        let dir = tempfile::tempdir().unwrap();
        let link = dir.path().join("ttyPSC");
        let psc = shared();
        let clock = SimClock::new();
        let pty = PscPty::create(&link, Arc::clone(&psc), clock).unwrap();
        assert!(std::fs::read_link(&link).unwrap().starts_with("/dev/pts"));
        let mut port = serialport::new(link.to_string_lossy(), 2400)
            .timeout(Duration::from_secs(2))
            .open_native()
            .unwrap();
        port.write_all(&encode_position(5, 0, 800)).unwrap();
        port.write_all(b"!SCVER?\r").unwrap();
        let mut reply = [0u8; 3];
        port.read_exact(&mut reply).unwrap();
        assert_eq!(&reply, b"1.4");
        assert!(wait_for(|| lock_psc(&psc).counters().frames_ok == 2));
        let now = clock.now_s();
        assert_eq!(lock_psc(&psc).pulse_at(5, now), Some(800.0));
        // Position query answers with channel, high byte, low byte.
        port.write_all(b"!SCRSP\x05\r").unwrap();
        port.read_exact(&mut reply).unwrap();
        assert_eq!(reply, [5, 0x03, 0x20]);
        let st = pty.stats();
        assert_eq!(st.serial_settings, Some(SerialSettings::PSC));
        assert_eq!(st.serial_mismatch, None);
        assert_eq!(st.bytes_received, 24);
        // The client goes away and comes back: the pty keeps serving.
        drop(port);
        let mut port = serialport::new(link.to_string_lossy(), 2400)
            .timeout(Duration::from_secs(2))
            .open_native()
            .unwrap();
        port.write_all(&encode_position(1, 0, 720)).unwrap();
        assert!(wait_for(|| lock_psc(&psc).counters().frames_ok == 4));
        drop(port);
        drop(pty);
        assert!(
            std::fs::symlink_metadata(&link).is_err(),
            "link removed on drop"
        );
    }

    #[test]
    fn wrong_baud_is_reported_and_ignored() {
        let dir = tempfile::tempdir().unwrap();
        let link = dir.path().join("ttyPSC");
        let psc = shared();
        let pty = PscPty::create(&link, Arc::clone(&psc), SimClock::new()).unwrap();
        let mut port = serialport::new(link.to_string_lossy(), 9600)
            .timeout(Duration::from_millis(300))
            .open_native()
            .unwrap();
        port.write_all(&encode_position(5, 0, 800)).unwrap();
        assert!(wait_for(|| pty.stats().bytes_received == 8));
        let st = pty.stats();
        let msg = st.serial_mismatch.unwrap_or_default();
        assert!(msg.contains("baud 9600 (expected 2400)"), "{msg}");
        let c = lock_psc(&psc).counters();
        assert_eq!((c.frames_ok, c.ignored_bytes), (0, 8));
    }

    #[test]
    fn refuses_to_replace_a_regular_file_and_replaces_a_stale_link() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("taken");
        std::fs::write(&file, b"keep").unwrap();
        let e = PscPty::create(&file, shared(), SimClock::new()).unwrap_err();
        assert!(matches!(e, PtyError::LinkPathTaken { .. }), "{e}");
        assert_eq!(std::fs::read(&file).unwrap(), b"keep");
        let link = dir.path().join("stale");
        std::os::unix::fs::symlink("/nonexistent", &link).unwrap();
        let pty = PscPty::create(&link, shared(), SimClock::new()).unwrap();
        assert_eq!(std::fs::read_link(&link).unwrap(), pty.slave_path());
    }
}
