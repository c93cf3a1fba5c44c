//! The reply classifier and the state machine against a real pseudo-terminal.

use std::os::fd::OwnedFd;

use super::*;

const ECHO: &[u8] = VERSION_QUERY;

#[test]
fn a_version_is_three_ascii_bytes_and_echoes_are_skipped() {
    assert_eq!(classify_reply(b"1.4"), VersionReply::Version("1.4".into()));
    assert_eq!(
        classify_reply(&[ECHO, b"1.4"].concat()),
        VersionReply::Version("1.4".into())
    );
    // Two queries echoed, the reply to the first behind the second echo.
    assert_eq!(
        classify_reply(&[ECHO, ECHO, b"2.0"].concat()),
        VersionReply::Version("2.0".into())
    );
    // A glitch byte of a controller powering up, then its answer.
    assert_eq!(
        classify_reply(b"\x001.4"),
        VersionReply::Version("1.4".into())
    );
    // Two queries answered.
    assert_eq!(
        classify_reply(b"1.41.4"),
        VersionReply::Version("1.4".into())
    );
}

#[test]
fn echoes_and_partial_replies_are_not_yet_a_verdict() {
    assert_eq!(classify_reply(b""), VersionReply::Incomplete);
    assert_eq!(classify_reply(ECHO), VersionReply::Incomplete);
    assert_eq!(classify_reply(&ECHO[..3]), VersionReply::Incomplete);
    assert_eq!(classify_reply(b"1"), VersionReply::Incomplete);
    assert_eq!(
        classify_reply(&[ECHO, b"1."].concat()),
        VersionReply::Incomplete
    );
}

#[test]
fn garbage_is_named_as_such() {
    // A digit-dot-digit inside other text is not a version: a GPS sentence, a "3.3V".
    for bytes in [
        &b"abc"[..],
        b"\xff\xfe\xfd",
        b"1-4",
        b"?\r\n",
        b"14.",
        b"abc1.4",
        b"1.4V",
        b"$GPGGA,123519,4807.038,N",
        b"3.3V\r\n",
    ] {
        assert_eq!(classify_reply(bytes), VersionReply::Garbage, "{bytes:?}");
    }
    let dev = Path::new("/dev/ttyX");
    assert!(matches!(
        window_verdict(b"", dev, 2400),
        LinkError::Silent { .. }
    ));
    assert!(matches!(
        window_verdict(ECHO, dev, 2400),
        LinkError::Echo { .. }
    ));
    assert!(matches!(
        window_verdict(&[ECHO, ECHO].concat(), dev, 2400),
        LinkError::Echo { .. }
    ));
    let e = window_verdict(b"\xffZ", dev, 2400);
    assert_eq!(
        e.to_string(),
        "/dev/ttyX answers ff 5a, not a PSC firmware version such as \"1.4\" (wrong baud rate \
         2400, or not a Parallax Servo Controller?)"
    );
}

/// A pseudo-terminal: the master end is the test's controller.
struct Pty {
    master: OwnedFd,
    _slave: OwnedFd,
    path: PathBuf,
}

fn pty() -> Pty {
    let p = nix::pty::openpty(None, None).expect("openpty");
    let mut t = nix::sys::termios::tcgetattr(&p.slave).expect("tcgetattr");
    nix::sys::termios::cfmakeraw(&mut t);
    nix::sys::termios::tcsetattr(&p.slave, nix::sys::termios::SetArg::TCSANOW, &t)
        .expect("raw mode");
    let path = nix::unistd::ttyname(&p.slave).expect("pty name");
    Pty {
        master: p.master,
        _slave: p.slave,
        path,
    }
}

impl Pty {
    fn read(&self) -> Vec<u8> {
        let mut out = Vec::new();
        let mut buf = [0u8; 256];
        loop {
            let mut fds = [nix::poll::PollFd::new(
                std::os::fd::AsFd::as_fd(&self.master),
                nix::poll::PollFlags::POLLIN,
            )];
            if nix::poll::poll(&mut fds, nix::poll::PollTimeout::ZERO).unwrap_or(0) == 0 {
                return out;
            }
            match nix::unistd::read(&self.master, &mut buf) {
                Ok(0) | Err(_) => return out,
                Ok(n) => out.extend_from_slice(&buf[..n]),
            }
        }
    }

    fn write(&self, bytes: &[u8]) {
        nix::unistd::write(&self.master, bytes).expect("write to the pty master");
    }
}

fn link(path: &Path) -> PscLink {
    PscLink::new(
        LinkSettings {
            device: path.to_path_buf(),
            baud: 2400,
            check: true,
            exclusive: false,
        },
        Instant::now(),
    )
}

/// Polls with the clock `t` advanced by `step` until `done` holds for the link (the pty
/// moves bytes in real time: up to 5 s of it on a busy machine); returns the events.
fn run_until(
    link: &mut PscLink,
    t: &mut Instant,
    step: Duration,
    done: impl Fn(&PscLink) -> bool,
) -> Vec<LinkEvent> {
    let deadline = Instant::now() + Duration::from_secs(5);
    let mut events = Vec::new();
    while !done(link) {
        assert!(
            Instant::now() < deadline,
            "condition not reached: {events:?}"
        );
        *t += step;
        std::thread::sleep(Duration::from_millis(1));
        events.extend(link.poll(*t));
    }
    events
}

/// Polls the link with the clock `t`, advanced by `step` each time, `n` times; returns the
/// events.
fn run(link: &mut PscLink, t: &mut Instant, step: Duration, n: usize) -> Vec<LinkEvent> {
    let mut events = Vec::new();
    for _ in 0..n {
        *t += step;
        // The pty needs a moment to move bytes between its ends.
        std::thread::sleep(Duration::from_millis(1));
        events.extend(link.poll(*t));
    }
    events
}

#[test]
fn a_silent_controller_is_a_state_and_its_first_answer_brings_the_link_up() {
    let pty = pty();
    let mut link = link(&pty.path);
    let mut t = Instant::now();
    // 1.2 s of silence (simulated clock): three queries, one "silent" event, still probing.
    let events = run(&mut link, &mut t, Duration::from_millis(20), 60);
    assert!(
        matches!(
            events.as_slice(),
            [LinkEvent::Waiting(LinkError::Silent { .. })]
        ),
        "{events:?}"
    );
    assert_eq!(link.state(), LinkState::Probing);
    let sent = pty.read();
    assert_eq!(
        sent,
        [ECHO, ECHO, ECHO].concat(),
        "only version queries went out"
    );
    assert!(
        link.note(t).starts_with(&format!(
            "no servo controller answers on {} (waiting 1 s)",
            pty.path.display()
        )),
        "{}",
        link.note(t)
    );
    assert!(
        link.send(b"!SC", t).is_err(),
        "nothing is written while probing"
    );
    pty.write(b"1.4");
    let events = run_until(&mut link, &mut t, Duration::from_millis(1), PscLink::is_up);
    assert_eq!(
        events,
        vec![LinkEvent::Up {
            firmware: "1.4".into()
        }]
    );
    assert!(link.is_up());
    assert_eq!(link.note(t), format!("{} PSC 1.4", pty.path.display()));
    link.send(b"!SC\x01\x00\xf8\x02\r", t)
        .expect("write while up");
    assert_eq!(pty.read(), b"!SC\x01\x00\xf8\x02\r");
}

#[test]
fn an_echoing_line_is_never_taken_for_a_controller() {
    let pty = pty();
    let mut link = link(&pty.path);
    let mut t = Instant::now();
    let mut events = Vec::new();
    for _ in 0..80 {
        events.extend(run(&mut link, &mut t, Duration::from_millis(20), 1));
        let got = pty.read();
        pty.write(&got);
    }
    assert_eq!(link.state(), LinkState::Probing, "{events:?}");
    assert!(
        events
            .iter()
            .any(|e| matches!(e, LinkEvent::Waiting(LinkError::Echo { .. }))),
        "{events:?}"
    );
    assert!(
        link.note(t).starts_with("only an echo on"),
        "{}",
        link.note(t)
    );
}

#[test]
fn a_missing_device_is_waited_for_and_a_vanished_one_is_lost() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("ttyPSC");
    let mut link = link(&path);
    let mut t = Instant::now();
    let events = run(&mut link, &mut t, Duration::from_millis(50), 10);
    assert!(
        matches!(
            events.as_slice(),
            [LinkEvent::Waiting(LinkError::Missing { .. })]
        ),
        "{events:?}"
    );
    assert_eq!(link.state(), LinkState::Absent);
    let pty = pty();
    std::os::unix::fs::symlink(&pty.path, &path).expect("symlink");
    // Reopen delays are capped below a second.
    run(&mut link, &mut t, Duration::from_millis(50), 20);
    assert_eq!(link.state(), LinkState::Probing);
    pty.read();
    pty.write(b"1.4");
    let events = run(&mut link, &mut t, Duration::from_millis(5), 5);
    assert!(
        matches!(events.as_slice(), [LinkEvent::Up { .. }]),
        "{events:?}"
    );
    // The node is removed (the adapter pulled out): lost within the node check period.
    std::fs::remove_file(&path).expect("remove the node");
    let events = run(&mut link, &mut t, Duration::from_millis(50), 10);
    assert!(
        matches!(
            events.first(),
            Some(LinkEvent::Lost(LinkError::Missing { .. }))
        ),
        "{events:?}"
    );
    assert_ne!(link.state(), LinkState::Up);
}

#[test]
fn the_blocking_check_names_a_silent_controller() {
    let pty = pty();
    let err =
        check_controller(&pty.path, 2400, Duration::from_millis(600)).expect_err("nobody answers");
    assert!(matches!(err, LinkError::Silent { .. }), "{err:?}");
    assert!(err.to_string().contains(&pty.path.display().to_string()));
}
