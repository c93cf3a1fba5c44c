//! The real ioctl path on files that are not cameras, and every capture fallback on a fake
//! Minoru ([`fake`]).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use hvs_runtime::config::{PowerLine, V4l2Controls, V4l2PixelFormat};

use super::controls::id;
use super::fake::{FakeBus, FakeCamera, MINORU_BUS_BYTES_PER_S};
use super::*;

fn mode() -> CameraMode {
    CameraMode {
        width: 640,
        height: 480,
        format: V4l2PixelFormat::Yuyv,
        fps: 30.0,
        buffers: 4,
    }
}

#[test]
fn missing_device_is_named() {
    let err = Camera::open(Path::new("/dev/video-hvs-missing"), &mode())
        .err()
        .expect("no such device");
    assert!(matches!(err, OpenError::Missing { .. }), "{err:?}");
    assert!(!err.is_permanent());
    assert_eq!(
        err.to_string(),
        "camera /dev/video-hvs-missing does not exist (not plugged in, or wrong device path?)"
    );
}

#[test]
fn stereo_open_names_the_missing_side() {
    let spec = StereoSpec {
        left_device: PathBuf::from("/dev/video-hvs-missing-left"),
        right_device: PathBuf::from("/dev/video-hvs-missing-right"),
        mode: mode(),
        max_skew_ns: 10_000_000,
        stall_timeout: Duration::from_secs(2),
        controls: V4l2Controls::default(),
    };
    let err = StereoCamera::open(&spec).err().expect("no such devices");
    assert!(
        err.to_string().contains("/dev/video-hvs-missing-left"),
        "{err}"
    );
}

#[test]
fn a_file_that_is_not_a_camera_fails_querycap() {
    // /dev/null opens fine; VIDIOC_QUERYCAP then fails (ENOTTY): the real ioctl path runs.
    let err = Camera::open(Path::new("/dev/null"), &mode())
        .err()
        .expect("not a camera");
    assert!(matches!(err, OpenError::NotV4l2 { .. }), "{err:?}");
    assert!(err.is_permanent());
    let msg = err.to_string();
    assert!(msg.starts_with("/dev/null is not a V4L2 device"), "{msg}");
}

#[test]
fn fourcc_codes_match_the_kernel() {
    assert_eq!(fourcc_of(V4l2PixelFormat::Yuyv), 0x5659_5559);
    assert_eq!(fourcc_of(V4l2PixelFormat::Mjpeg), 0x4750_4a4d);
    assert_eq!(fourcc_name(0x4750_4a4d), "MJPG");
    assert_eq!(mode().to_string(), "640x480 YUYV at 30 fps");
}

#[test]
fn ioctl_numbers_match_the_kernel() {
    // Values from linux/videodev2.h on x86_64 / aarch64.
    #[cfg(target_pointer_width = "64")]
    {
        assert_eq!(
            nix::request_code_read!(b'V', 0, size_of::<sys::Capability>()),
            0x8068_5600
        );
        assert_eq!(
            nix::request_code_readwrite!(b'V', 5, size_of::<sys::Format>()),
            0xc0d0_5605
        );
        assert_eq!(
            nix::request_code_readwrite!(b'V', 17, size_of::<sys::Buffer>()),
            0xc058_5611
        );
        assert_eq!(
            nix::request_code_readwrite!(b'V', 22, size_of::<sys::StreamParm>()),
            0xc0cc_5616
        );
        // The enumeration and control calls of the negotiation and the control lock.
        for (nr, size, code) in [
            (2, size_of::<sys::FmtDesc>(), 0xc040_5602),
            (27, size_of::<sys::Control>(), 0xc008_561b),
            (28, size_of::<sys::Control>(), 0xc008_561c),
            (36, size_of::<sys::QueryCtrl>(), 0xc044_5624),
            (74, size_of::<sys::FrmSizeEnum>(), 0xc02c_564a),
            (75, size_of::<sys::FrmIvalEnum>(), 0xc034_564b),
        ] {
            assert_eq!(
                nix::request_code_readwrite!(b'V', nr, size),
                code,
                "ioctl {nr}"
            );
        }
    }
}

// ---- The fake Minoru: negotiation, fallbacks, controls, pairing. ----

const LEFT: &str = "/dev/fake-video0";
const RIGHT: &str = "/dev/fake-video2";

fn minoru_bus(budget: f64, skew_ns: i64) -> FakeBus {
    let mut right = FakeCamera::minoru();
    right.stamp_offset_ns = skew_ns;
    FakeBus::new(
        budget,
        vec![
            (PathBuf::from(LEFT), FakeCamera::minoru()),
            (PathBuf::from(RIGHT), right),
        ],
    )
}

fn spec(fps: f64) -> StereoSpec {
    StereoSpec {
        left_device: PathBuf::from(LEFT),
        right_device: PathBuf::from(RIGHT),
        mode: CameraMode { fps, ..mode() },
        max_skew_ns: 17_000_000,
        stall_timeout: Duration::from_secs(5),
        controls: V4l2Controls::default(),
    }
}

/// Reads `n` pairs (bounded by a generous deadline, not by their rate).
fn read_pairs(cam: &mut StereoCamera, n: usize) -> Vec<CapturedPair> {
    let deadline = Instant::now() + Duration::from_secs(30);
    let (w, h) = (cam.negotiated().mode.width, cam.negotiated().mode.height);
    let mut left = vec![0u8; (w * h) as usize];
    let mut right = vec![0u8; (w * h) as usize];
    let mut out = Vec::new();
    while out.len() < n {
        assert!(
            Instant::now() < deadline,
            "only {} pairs in 30 s",
            out.len()
        );
        if let Some(p) = cam.next_pair(Duration::from_millis(50)).expect("pair") {
            cam.read_pair(&p, &mut left, &mut right).expect("convert");
            // The grey image is the fake's ramp: Y of pixel 1 is frame + 1.
            assert_eq!(left[1], (p.pair.left.token.sequence as u8).wrapping_add(1));
            out.push(p);
        }
    }
    out
}

#[test]
fn a_bus_with_room_for_both_streams_gets_the_preferred_mode() {
    let bus = minoru_bus(1e9, 0);
    let cam = StereoCamera::open_with(&spec(30.0), &bus).expect("open");
    assert_eq!(cam.negotiated().mode.to_string(), "640x480 YUYV at 30 fps");
    assert!(!cam.negotiated().fell_back());
    assert_eq!(
        cam.negotiated().summary(),
        "640x480 YUYV at 30 fps on both cameras"
    );
    assert!(
        cam.negotiated()
            .offers
            .0
            .starts_with("YUYV 640x480@30/15/5")
    );
}

#[test]
fn enospc_at_30_fps_falls_back_to_15_fps_with_the_reason() {
    // The Minoru's hub: two 640x480 YUYV streams fit at 15 fps, not at 30.
    let bus = minoru_bus(MINORU_BUS_BYTES_PER_S, 0);
    let mut cam = StereoCamera::open_with(&spec(30.0), &bus).expect("open");
    let n = cam.negotiated().clone();
    assert_eq!(n.mode.to_string(), "640x480 YUYV at 15 fps");
    assert_eq!(n.skipped.len(), 1);
    assert_eq!(
        n.summary(),
        "640x480 YUYV at 15 fps on both cameras, after 1 failed (640x480 YUYV at 30 fps: \
         VIDIOC_STREAMON on /dev/fake-video2 failed with ENOSPC (no USB bandwidth left))"
    );
    // The rate was set on each device, 30 then 15.
    for dev in [LEFT, RIGHT] {
        assert_eq!(bus.log(Path::new(dev)).rates_set, [30.0, 15.0], "{dev}");
    }
    assert_eq!(
        bus.log(Path::new(RIGHT)).stream_ons,
        [
            ("640x480@30".to_string(), true),
            ("640x480@15".to_string(), false)
        ]
    );
    read_pairs(&mut cam, 3);
}

#[test]
fn enospc_at_every_640x480_rate_falls_back_to_320x240_for_both() {
    // A busier bus (a third device on it): 640x480 does not fit for both even at 15 fps
    // (18.4 MB/s), 320x240 at 30 (4.6 MB/s each) does.
    let bus = minoru_bus(10e6, 0);
    let mut cam = StereoCamera::open_with(&spec(30.0), &bus).expect("open");
    let n = cam.negotiated().clone();
    assert_eq!(n.mode.to_string(), "320x240 YUYV at 30 fps");
    let tried: Vec<String> = n.skipped.iter().map(|(m, _)| m.to_string()).collect();
    assert_eq!(tried, ["640x480 YUYV at 30 fps", "640x480 YUYV at 15 fps"]);
    let pairs = read_pairs(&mut cam, 2);
    assert!(pairs[1].pair.left.stamp_ns > pairs[0].pair.left.stamp_ns);
}

#[test]
fn a_bus_with_no_room_at_all_is_an_error_that_lists_every_mode_tried() {
    let bus = minoru_bus(1e6, 0);
    let err = StereoCamera::open_with(&spec(30.0), &bus)
        .err()
        .expect("nothing fits");
    assert!(matches!(err, OpenError::NoBandwidth { .. }), "{err:?}");
    assert!(!err.is_permanent(), "another device may free the bus");
    let msg = err.to_string();
    assert!(
        msg.contains("320x240 YUYV at 5 fps: VIDIOC_STREAMON"),
        "{msg}"
    );
    assert!(msg.contains("try pixel_format = \"mjpeg\""), "{msg}");
}

#[test]
fn a_format_neither_camera_offers_is_a_permanent_error_naming_the_offers() {
    let mut yuyv_only = FakeCamera::minoru();
    yuyv_only.formats.truncate(1);
    let bus = FakeBus::new(
        1e9,
        vec![
            (PathBuf::from(LEFT), yuyv_only.clone()),
            (PathBuf::from(RIGHT), yuyv_only),
        ],
    );
    let mut s = spec(30.0);
    s.mode.format = V4l2PixelFormat::Mjpeg;
    let err = StereoCamera::open_with(&s, &bus).err().expect("no MJPEG");
    assert!(err.is_permanent());
    assert!(
        err.to_string().starts_with(
            "the two cameras offer no common mode for 640x480 MJPG at up to 30 fps; left offers \
             YUYV 640x480@30/15/5 320x240@30/15/5"
        ),
        "{err}"
    );
}

#[test]
fn a_metadata_node_is_refused_with_the_hint() {
    let mut meta = FakeCamera::minoru();
    meta.metadata_only = true;
    let bus = FakeBus::new(
        1e9,
        vec![
            (PathBuf::from(LEFT), FakeCamera::minoru()),
            (PathBuf::from(RIGHT), meta),
        ],
    );
    let err = StereoCamera::open_with(&spec(30.0), &bus)
        .err()
        .expect("metadata node");
    assert!(matches!(err, OpenError::NotCapture { .. }), "{err:?}");
    assert!(
        err.to_string()
            .contains("use the camera's other /dev/videoN")
    );
}

#[test]
fn eagain_from_dqbuf_is_waited_through() {
    let mut left = FakeCamera::minoru();
    left.eagain_every = 2;
    let mut right = FakeCamera::minoru();
    right.eagain_every = 3;
    let bus = FakeBus::new(
        1e9,
        vec![(PathBuf::from(LEFT), left), (PathBuf::from(RIGHT), right)],
    );
    let mut cam = StereoCamera::open_with(&spec(30.0), &bus).expect("open");
    read_pairs(&mut cam, 4);
    assert!(bus.log(Path::new(LEFT)).eagains > 0);
    assert!(bus.log(Path::new(RIGHT)).eagains > 0);
}

#[test]
fn pairs_carry_the_kernel_timestamps_and_their_skew() {
    // The right camera runs 6 ms behind the left (unsynchronised sensors).
    let bus = minoru_bus(1e9, 6_000_000);
    let mut cam = StereoCamera::open_with(&spec(30.0), &bus).expect("open");
    for p in read_pairs(&mut cam, 4) {
        let skew = p.pair.right.stamp_ns as i64 - p.pair.left.stamp_ns as i64;
        assert_eq!(skew, 6_000_000, "{p:?}");
    }
    // 25 ms apart: beyond max_skew (17 ms), the nearest partner is the next frame, 8.3 ms
    // off: pairs still form, never with a gap above the bound.
    let bus = minoru_bus(1e9, 25_000_000);
    let mut cam = StereoCamera::open_with(&spec(30.0), &bus).expect("open");
    for p in read_pairs(&mut cam, 3) {
        let skew = (p.pair.right.stamp_ns as i64 - p.pair.left.stamp_ns as i64).abs();
        assert!(skew <= 17_000_000, "skew {skew} ns above the bound");
    }
}

#[test]
fn an_unplugged_camera_is_a_disconnect_and_is_reopened_once_back() {
    let bus = minoru_bus(1e9, 0);
    let mut cam = StereoCamera::open_with(&spec(30.0), &bus).expect("open");
    read_pairs(&mut cam, 1);
    bus.unplug(Path::new(RIGHT));
    let deadline = Instant::now() + Duration::from_secs(30);
    let err = loop {
        assert!(Instant::now() < deadline, "no error after the unplug");
        match cam.next_pair(Duration::from_millis(50)) {
            Ok(Some(p)) => {
                if let Err(e) = cam.release_pair(&p) {
                    break e;
                }
            }
            Ok(None) => {}
            Err(e) => break e,
        }
    };
    assert!(matches!(err, CaptureError::Disconnected { .. }), "{err:?}");
    assert!(err.needs_reconnect());
    assert!(
        err.to_string()
            .starts_with("camera /dev/fake-video2 disconnected: VIDIOC_"),
        "{err}"
    );
    drop(cam);
    let err = StereoCamera::open_with(&spec(30.0), &bus)
        .err()
        .expect("still unplugged");
    assert!(
        matches!(err, OpenError::Missing { .. }) && !err.is_permanent(),
        "{err:?}"
    );
    bus.replug(Path::new(RIGHT));
    let mut cam = StereoCamera::open_with(&spec(30.0), &bus).expect("reopen");
    read_pairs(&mut cam, 1);
}

#[test]
fn controls_are_locked_alike_on_both_cameras() {
    let bus = minoru_bus(1e9, 0);
    let mut s = spec(15.0);
    s.controls = V4l2Controls {
        exposure_100us: Some(200),
        gain: Some(300),
        white_balance_k: Some(4000),
        power_line: Some(PowerLine::Hz50),
    };
    let cam = StereoCamera::open_with(&s, &bus).expect("open");
    let (l, r) = &cam.negotiated().controls;
    assert_eq!(l, r, "both cameras alike");
    assert_eq!(
        l.applied,
        [
            ("exposure_100us", 200),
            ("gain", 255),
            ("white_balance_k", 4000),
            ("power_line", 1)
        ]
    );
    assert_eq!(
        l.problems,
        [(
            "gain",
            "300 clamped to 255 (the camera takes 0..=255)".to_string()
        )]
    );
    for dev in [LEFT, RIGHT] {
        let set = bus.log(Path::new(dev)).controls_set;
        assert_eq!(
            set,
            [
                (id::EXPOSURE_AUTO, id::EXPOSURE_MANUAL),
                (id::EXPOSURE_ABSOLUTE, 200),
                (id::GAIN, 255),
                (id::AUTO_WHITE_BALANCE, 0),
                (id::WHITE_BALANCE_TEMPERATURE, 4000),
                (id::POWER_LINE_FREQUENCY, 1)
            ],
            "{dev}"
        );
    }
}

#[test]
fn a_camera_without_a_control_is_reported_not_fatal() {
    let mut bare = FakeCamera::minoru();
    bare.controls.clear();
    let bus = FakeBus::new(
        1e9,
        vec![
            (PathBuf::from(LEFT), FakeCamera::minoru()),
            (PathBuf::from(RIGHT), bare),
        ],
    );
    let mut s = spec(15.0);
    s.controls.exposure_100us = Some(100);
    let cam = StereoCamera::open_with(&s, &bus).expect("open");
    let (l, r) = &cam.negotiated().controls;
    assert_eq!(l.applied, [("exposure_100us", 100)]);
    assert_eq!(
        r.problems,
        [(
            "exposure_100us",
            "the camera has no such control".to_string()
        )]
    );
}
