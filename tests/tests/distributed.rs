//! End-to-end tests of the zenoh bridge: two hvs instances as two machines on one box (each
//! its own iceoryx2 instance), bridged over zenoh on loopback with explicit endpoints and no
//! multicast scouting; the 640x480 worker on the second instance; faults on the link; and
//! hostile messages sent by a real zenoh session.

use std::time::{Duration, Instant};

use hvs_runtime::ipc::{IpcNode, TopicSubscriber};
use hvs_shared::messages::{BridgeStats, BridgeTopicStats, RangeReport, decode_name};
use hvs_shared::topics;
use hvs_tests::{Pipeline, free_loopback_port, repo_root, stage};
use nix::sys::signal::Signal;
use serde_json::Value;
use zenoh::Wait;

const START: Duration = Duration::from_secs(90);
const WAIT: Duration = Duration::from_secs(40);

/// The robot's part: everything but stereo-hi, a bridge that listens on `port`, sends the
/// 640x480 pairs and takes the disparity maps back.
fn robot_extra(port: u16) -> String {
    format!(
        r#"
[stages.stereo-hi]
enabled = false

[bridge]
listen = ["tcp/127.0.0.1:{port}"]
publish = ["frames/640x480", "ranges", "decisions"]
subscribe = ["disparity/640x480"]
rate_hz = {{ "frames/640x480" = 15.0 }}
"#
    )
}

/// config/worker.toml, connecting to `port`.
fn worker_config(port: u16) -> String {
    let text = std::fs::read_to_string(repo_root().join("config/worker.toml"))
        .expect("config/worker.toml");
    assert!(text.contains("tcp/127.0.0.1:7447"));
    text.replace("tcp/127.0.0.1:7447", &format!("tcp/127.0.0.1:{port}"))
}

/// Reads a pipeline's topics from the test process.
struct Watch {
    ranges: TopicSubscriber<RangeReport>,
    stats: TopicSubscriber<BridgeStats>,
    _node: IpcNode,
}

impl Watch {
    fn open(instance: &str) -> Self {
        let node = IpcNode::create(instance, "test-watch").expect("node");
        Self {
            ranges: node.subscriber(&topics::RANGES, 64).expect("ranges"),
            stats: node.subscriber(&topics::BRIDGE_STATS, 4).expect("stats"),
            _node: node,
        }
    }

    /// Range reports received over `d`: (count, how many fused a 640x480 result).
    fn ranges_for(&self, d: Duration) -> (usize, usize) {
        let end = Instant::now() + d;
        let (mut n, mut hi) = (0, 0);
        while Instant::now() < end {
            while let Ok(Some(s)) = self.ranges.receive() {
                n += 1;
                if s.payload().hi_frame_id != 0 {
                    hi += 1;
                }
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        (n, hi)
    }

    /// Waits until range reports fuse remote 640x480 results again; returns how long it took.
    fn wait_hi_fused(&self, what: &str, timeout: Duration, logs: &dyn Fn() -> String) -> Duration {
        let t0 = Instant::now();
        while t0.elapsed() < timeout {
            let (_, hi) = self.ranges_for(Duration::from_millis(500));
            if hi > 0 {
                return t0.elapsed();
            }
        }
        panic!(
            "{what}: no 640x480 result fused within {timeout:?}\n{}",
            logs()
        );
    }

    /// The newest bridge stats (waiting up to `timeout` for one).
    fn latest_stats(&self, timeout: Duration) -> BridgeStats {
        let end = Instant::now() + timeout;
        let mut latest = None;
        while Instant::now() < end {
            while let Ok(Some(s)) = self.stats.receive() {
                latest = Some(*s.payload());
            }
            if latest.is_some() {
                break;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        latest.expect("bridge/stats published")
    }
}

fn entry<'a>(stats: &'a BridgeStats, topic: &str, direction: u32) -> &'a BridgeTopicStats {
    stats.topics[..stats.topic_count as usize]
        .iter()
        .find(|e| decode_name(&e.topic) == topic && e.direction == direction)
        .unwrap_or_else(|| panic!("no bridge stats for {topic}"))
}

fn restarts(status: &Value) -> Vec<(String, u64)> {
    hvs_tests::stages(status)
        .iter()
        .map(|s| {
            (
                s["stage"].as_str().unwrap_or("").to_string(),
                s["restarts"].as_u64().unwrap_or(0),
            )
        })
        .collect()
}

#[test]
fn the_640x480_worker_on_a_second_instance_feeds_the_robot_and_its_loss_never_stalls_it() {
    let port = free_loopback_port();
    let robot = Pipeline::start("robot", &[], &robot_extra(port));
    let worker = Pipeline::start_beside("worker", &worker_config(port));
    robot.wait_all_running(START);
    worker.wait_status("the worker's stereo-hi producing", START, |s| {
        stage(s, "stereo-hi")["frames_out"].as_u64().unwrap_or(0) > 0
    });
    let watch = Watch::open(&robot.instance);
    let took = watch.wait_hi_fused("worker up", WAIT, &|| robot.logs() + &worker.logs());
    println!("first remote 640x480 result fused after {took:?}");

    // Steady state: the hop and the bandwidth.
    let (n, hi) = watch.ranges_for(Duration::from_secs(8));
    let stats = watch.latest_stats(Duration::from_secs(3));
    let frames_out = entry(&stats, "frames/640x480", 0);
    let disp_in = entry(&stats, "disparity/640x480", 1);
    println!(
        "robot: {n} range reports in 8 s, {hi} with a remote 640x480 result; peers {}",
        stats.peers
    );
    println!(
        "frames/640x480 out: {} msgs, raw {:.1} MB, wire {:.1} MB (lz4 {:.0} %)",
        frames_out.messages,
        frames_out.raw_bytes as f64 / 1e6,
        frames_out.wire_bytes as f64 / 1e6,
        100.0 * frames_out.wire_bytes as f64 / frames_out.raw_bytes.max(1) as f64
    );
    println!(
        "disparity/640x480 in: {} msgs, raw {:.1} MB, wire {:.1} MB (lz4 {:.0} %), hop p50 {:.2} ms p99 {:.2} ms, dropped {} rejected {}",
        disp_in.messages,
        disp_in.raw_bytes as f64 / 1e6,
        disp_in.wire_bytes as f64 / 1e6,
        100.0 * disp_in.wire_bytes as f64 / disp_in.raw_bytes.max(1) as f64,
        disp_in.hop_p50_ns as f64 / 1e6,
        disp_in.hop_p99_ns as f64 / 1e6,
        disp_in.dropped,
        disp_in.rejected
    );
    assert_eq!(stats.peers, 1);
    assert!(frames_out.messages > 0 && disp_in.messages > 0);
    // Noisy camera images barely compress (a block that does not shrink goes raw); the
    // disparity maps, with their invalid areas, do.
    assert!(frames_out.wire_bytes <= frames_out.raw_bytes);
    assert!(
        disp_in.wire_bytes < disp_in.raw_bytes,
        "lz4 shrinks disparity maps"
    );
    assert!(
        hi * 2 > n,
        "most reports fuse the remote results: {hi} of {n}"
    );
    assert_eq!(disp_in.rejected, 0);

    // The worker is killed (the link dies with it): the fast path drives alone.
    let before = robot.status().expect("status");
    let mut worker = worker;
    worker.signal(Signal::SIGKILL);
    worker.wait_exit(WAIT);
    let _ = watch.ranges_for(Duration::from_millis(600)); // what was in flight ages out
    let (n_alone, hi_alone) = watch.ranges_for(Duration::from_secs(5));
    let after = robot.status().expect("status");
    let rate = stage(&after, "decision")["rate_hz"].as_f64().unwrap_or(0.0);
    println!(
        "worker killed: {n_alone} range reports in 5 s, {hi_alone} with a 640x480 result; decisions {rate:.1} Hz; robot bridge {}",
        stage(&after, "bridge")["note"]
    );
    assert_eq!(hi_alone, 0, "stale 640x480 results age out");
    assert!(
        n_alone >= 5 * 15,
        "the fast path keeps deciding: {n_alone} in 5 s"
    );
    assert_eq!(restarts(&before), restarts(&after), "nothing restarts");

    // A new worker comes up: the robot picks its results up again.
    let worker = Pipeline::start_beside("worker2", &worker_config(port));
    let took = watch.wait_hi_fused("worker back", START, &|| robot.logs() + &worker.logs());
    println!("remote 640x480 results fused again {took:?} after the worker restarted");
    let end = robot.status().expect("status");
    assert_eq!(
        restarts(&before),
        restarts(&end),
        "nothing restarted on the robot"
    );
}

#[test]
fn malformed_and_unlisted_messages_from_the_network_are_counted_and_dropped() {
    let port = free_loopback_port();
    let robot = Pipeline::start("robot-hostile", &[], &robot_extra(port));
    robot.wait_all_running(START);
    let watch = Watch::open(&robot.instance);

    let mut config = zenoh::Config::default();
    for (k, v) in [
        ("mode", "\"peer\"".to_string()),
        ("scouting/multicast/enabled", "false".into()),
        ("connect/endpoints", format!("[\"tcp/127.0.0.1:{port}\"]")),
    ] {
        config.insert_json5(k, &v).expect("zenoh config");
    }
    let session = zenoh::open(config).wait().expect("zenoh session");
    // Wait until the robot's bridge sees this peer.
    let t0 = Instant::now();
    while watch.latest_stats(Duration::from_secs(2)).peers == 0 {
        assert!(
            t0.elapsed() < WAIT,
            "the robot's bridge never saw the test's peer"
        );
    }
    let key = "hvs/disparity/640x480";
    let good_attachment = hvs_bridge::wire::Envelope {
        flags: hvs_bridge::wire::FLAG_LZ4,
        raw_len: core::mem::size_of::<hvs_shared::messages::DisparityMap640x480>() as u64,
        sent_wall_ns: 0,
        seq: 1,
    }
    .to_bytes();
    let typed =
        zenoh::bytes::Encoding::APPLICATION_OCTET_STREAM.with_schema("hvs::DisparityMap640x480");
    /// What is wrong, the payload, the attachment, the encoding.
    type HostilePut<'a> = (&'a str, Vec<u8>, Option<Vec<u8>>, zenoh::bytes::Encoding);
    let puts: Vec<HostilePut> = vec![
        ("no attachment", vec![1, 2, 3], None, typed.clone()),
        (
            "junk attachment",
            vec![1, 2, 3],
            Some(vec![0; 7]),
            typed.clone(),
        ),
        (
            "wrong type",
            vec![0; 10],
            Some(good_attachment.to_vec()),
            zenoh::bytes::Encoding::APPLICATION_OCTET_STREAM.with_schema("hvs::Decision"),
        ),
        (
            "corrupt lz4",
            vec![0xff; 4096],
            Some(good_attachment.to_vec()),
            typed.clone(),
        ),
        (
            "oversized",
            vec![0; 4 << 20],
            Some(good_attachment.to_vec()),
            typed.clone(),
        ),
    ];
    let sent = puts.len() as u64;
    // Reliable and blocking, and only once the robot's subscriber is known here: every
    // message reaches the robot, so every one must be counted there.
    let publisher = session
        .declare_publisher(key)
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .wait()
        .expect("zenoh publisher");
    let t0 = Instant::now();
    while !publisher
        .matching_status()
        .wait()
        .is_ok_and(|m| m.matching())
    {
        assert!(t0.elapsed() < WAIT, "the robot's subscriber never matched");
        std::thread::sleep(Duration::from_millis(50));
    }
    for (what, payload, attachment, encoding) in puts {
        let mut put = publisher.put(payload).encoding(encoding);
        if let Some(a) = attachment {
            put = put.attachment(a);
        }
        put.wait().unwrap_or_else(|e| panic!("put {what}: {e}"));
    }
    // A motion command: not in the robot's allow-list (and refused by default anyway).
    let decision = hvs_shared::messages::Decision {
        command: hvs_shared::codes::MotionCommand::Forward.code(),
        ..Default::default()
    };
    let (payload, att) = hvs_bridge::wire::encode(&decision, false, 0, 1);
    session
        .put("hvs/decisions", payload)
        .encoding(zenoh::bytes::Encoding::APPLICATION_OCTET_STREAM.with_schema("hvs::Decision"))
        .attachment(att.to_vec())
        .wait()
        .expect("put decision");

    let t0 = Instant::now();
    let rejected = loop {
        let stats = watch.latest_stats(Duration::from_secs(2));
        let r = entry(&stats, "disparity/640x480", 1).rejected;
        if r >= sent || t0.elapsed() > WAIT {
            break r;
        }
    };
    println!("robot bridge rejected {rejected} of {sent} malformed messages");
    assert_eq!(rejected, sent, "every malformed message is counted");
    let status = robot.status().expect("status");
    assert_eq!(stage(&status, "bridge")["restarts"].as_u64(), Some(0));
    assert_eq!(stage(&status, "bridge")["state"], "running");
    let (n, _) = watch.ranges_for(Duration::from_secs(2));
    assert!(n > 20, "the robot keeps deciding");
    drop(session);
}

/// crc32 of every left image the pipeline publishes (both sizes) while `stop` is unset.
fn collect_left_crcs(
    instance: String,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> std::thread::JoinHandle<std::collections::HashSet<u32>> {
    std::thread::spawn(move || {
        use std::sync::atomic::Ordering;
        let node = IpcNode::create(&instance, "test-crc").expect("node");
        let lo = node.subscriber(&topics::FRAMES_LO, 8).expect("frames lo");
        let hi = node.subscriber(&topics::FRAMES_HI, 8).expect("frames hi");
        let mut crcs = std::collections::HashSet::new();
        while !stop.load(Ordering::Relaxed) {
            while let Ok(Some(s)) = lo.receive() {
                crcs.insert(crc32fast::hash(&s.payload().left));
            }
            while let Ok(Some(s)) = hi.receive() {
                crcs.insert(crc32fast::hash(&s.payload().left));
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        crcs
    })
}

#[test]
fn a_ros2_client_without_ros_decodes_images_camera_info_disparity_and_motion() {
    let (python, site) = hvs_tests::python_with(
        "py-ros2",
        "import zenoh, numpy; from rosbags.typesys import Stores, get_typestore",
        &["eclipse-zenoh==1.10.2", "rosbags==0.11.9"],
    );
    let port = free_loopback_port();
    let robot = Pipeline::start(
        "ros2",
        &[],
        &format!(
            "[bridge]\nlisten = [\"tcp/127.0.0.1:{port}\"]\n[bridge.ros]\nenabled = true\ndomain_id = 7\n"
        ),
    );
    robot.wait_all_running(START);
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let crcs = collect_left_crcs(robot.instance.clone(), std::sync::Arc::clone(&stop));
    let out = std::process::Command::new(&python)
        .arg(repo_root().join("tests/python/ros2_client.py"))
        .args([
            "--connect",
            &format!("tcp/127.0.0.1:{port}"),
            "--domain",
            "7",
        ])
        .env("PYTHONPATH", &site)
        .output()
        .expect("run the ROS 2 client");
    std::thread::sleep(Duration::from_millis(200));
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let crcs = crcs.join().expect("crc thread");
    assert!(
        out.status.success(),
        "ros2_client.py failed: {}\n{}",
        String::from_utf8_lossy(&out.stderr),
        robot.logs()
    );
    let report: Value = serde_json::from_slice(&out.stdout).expect("the client prints JSON");
    assert_eq!(report["errors"], serde_json::json!([]), "{report}");

    let config = hvs_runtime::config::HvsConfig::load(&robot.config).expect("config");
    let topic = |name: &str| -> &Value {
        report["topics"]
            .get(name)
            .unwrap_or_else(|| panic!("no {name} in {report}"))
    };
    let expected = [
        ("/hvs/left/image_raw", "sensor_msgs/msg/Image"),
        ("/hvs/left/camera_info", "sensor_msgs/msg/CameraInfo"),
        ("/hvs/left_640x480/image_raw", "sensor_msgs/msg/Image"),
        (
            "/hvs/left_640x480/camera_info",
            "sensor_msgs/msg/CameraInfo",
        ),
        ("/hvs/disparity", "stereo_msgs/msg/DisparityImage"),
        ("/hvs/commanded_twist", "geometry_msgs/msg/Twist"),
    ];
    let tokens: Vec<&str> = report["tokens"]
        .as_array()
        .expect("tokens")
        .iter()
        .filter_map(Value::as_str)
        .collect();
    assert!(
        tokens.iter().any(|t| t.contains("/NN/%/%hvs/hvs_bridge")),
        "node token: {tokens:?}"
    );
    for (name, ros_type) in expected {
        let t = topic(name);
        assert_eq!(t["type"], ros_type, "{name}");
        // The key's type hash is the one rosbags computes from the type's definition.
        assert_eq!(t["hash"], report["rosbags_hashes"][ros_type], "{name}");
        assert!(
            t["key"]
                .as_str()
                .is_some_and(|k| k.starts_with(&format!("7{name}/"))),
            "{name}: {}",
            t["key"]
        );
        let mangled = name.replace('/', "%");
        assert!(
            tokens
                .iter()
                .any(|k| k.contains("/MP/") && k.contains(&mangled)),
            "no publisher token for {name}: {tokens:?}"
        );
        let samples = t["samples"].as_array().expect("samples");
        assert!(samples.len() >= 3, "{name}: {samples:?}");
        for s in samples {
            assert_eq!(s["cdr_header"], "00010000", "{name}");
            assert_eq!(s["attachment_len"], 33, "{name}");
            assert_eq!(s["attachment_gid_len"], 16, "{name}");
        }
    }
    // Images: the pixels are the pipeline's own left images, byte for byte.
    for (name, w, h) in [
        ("/hvs/left/image_raw", 320, 240),
        ("/hvs/left_640x480/image_raw", 640, 480),
    ] {
        for s in topic(name)["samples"].as_array().expect("samples") {
            assert_eq!(
                (s["width"].as_u64(), s["height"].as_u64()),
                (Some(w), Some(h))
            );
            assert_eq!(s["encoding"], "mono8");
            assert_eq!(s["step"].as_u64(), Some(w));
            assert_eq!(s["frame_id"], "camera");
            let crc = s["data_crc32"].as_u64().expect("crc") as u32;
            assert!(
                crcs.contains(&crc),
                "{name}: image {crc:#x} is not one the pipeline published"
            );
        }
    }
    for (name, w) in [
        ("/hvs/left/camera_info", 320),
        ("/hvs/left_640x480/camera_info", 640),
    ] {
        for s in topic(name)["samples"].as_array().expect("samples") {
            let focal = config.camera.focal_px(w);
            assert_eq!(s["k"][0].as_f64(), Some(focal), "{name}");
            assert_eq!(s["k"][2].as_f64(), Some(w as f64 / 2.0), "{name}");
        }
    }
    for s in topic("/hvs/disparity")["samples"]
        .as_array()
        .expect("samples")
    {
        assert_eq!(s["encoding"], "32FC1");
        assert_eq!(
            (s["width"].as_u64(), s["height"].as_u64()),
            (Some(320), Some(240))
        );
        assert_eq!(
            s["t"]
                .as_f64()
                .map(|t| (t - config.camera.baseline_m).abs() < 1e-6),
            Some(true)
        );
        assert!(s["valid_px"].as_u64().unwrap_or(0) > 1000, "{s}");
        assert!(
            s["valid_max"].as_f64().unwrap_or(1e9)
                <= s["max_disparity"].as_f64().unwrap_or(0.0) + 1.0
        );
    }
    let v = config.robot.forward_speed_mps;
    let w = 2.0 * v / config.robot.track_m;
    for s in topic("/hvs/commanded_twist")["samples"]
        .as_array()
        .expect("samples")
    {
        let (x, z) = (
            s["linear_x"].as_f64().unwrap_or(f64::NAN),
            s["angular_z"].as_f64().unwrap_or(f64::NAN),
        );
        let legal = [(0.0, 0.0), (v, 0.0), (-v, 0.0), (0.0, w), (0.0, -w)];
        assert!(
            legal
                .iter()
                .any(|(a, b)| (a - x).abs() < 1e-9 && (b - z).abs() < 1e-9),
            "twist ({x}, {z}) is none of the commands {legal:?}"
        );
    }
    println!(
        "ROS 2 client: 6 topics, {} liveliness tokens, images matched {} local left images",
        tokens.len(),
        crcs.len()
    );
}
