//! End-to-end tests of the live view: a real pipeline, the view stage's real Foxglove
//! WebSocket server and web page on loopback, real protocol clients (well-behaved, rude and
//! many), and a real headless Chromium opening the page.

use std::io::Write;
use std::net::TcpStream;
use std::time::{Duration, Instant};

use hvs_probe::schemas::conforms;
use hvs_runtime::ipc::IpcNode;
use hvs_shared::messages::SendReason;
use hvs_shared::topics;
use hvs_tests::{Pipeline, pid_of, signal_pid, stage, view_ports};
use hvs_view::client::{FoxgloveClient, compressed_image_data};
use nix::sys::signal::Signal;
use serde_json::Value;

const START: Duration = Duration::from_secs(60);
const WAIT: Duration = Duration::from_secs(30);

/// Every channel the view advertises, with its schema name.
const CHANNELS: [(&str, &str); 15] = [
    ("/frames/320x240/left", "foxglove.CompressedImage"),
    ("/camera/calibration", "foxglove.CameraCalibration"),
    ("/disparity/colour", "foxglove.CompressedImage"),
    ("/fused/colour", "foxglove.CompressedImage"),
    ("/disparity/points", "foxglove.PointCloud"),
    ("/tf", "foxglove.FrameTransforms"),
    ("/map", "foxglove.Grid"),
    ("/log", "foxglove.Log"),
    ("/ranges", "hvs.RangeReport"),
    ("/decisions", "hvs.Decision"),
    ("/actuator/sent", "hvs.ActuatorReport"),
    ("/decision/pose", "hvs.RobotPose"),
    ("/sim/truth", "hvs.SimTruth"),
    ("/hvs/stages", "hvs.StageTable"),
    ("/hvs/legend", "hvs.Legend"),
];

/// The decision stage's output rate, averaged over `n` status readings a second apart.
fn decision_rate(p: &Pipeline, n: usize) -> f64 {
    let mut sum = 0.0;
    for _ in 0..n {
        std::thread::sleep(Duration::from_secs(1));
        let s = p.status().expect("status");
        sum += stage(&s, "decision")["rate_hz"].as_f64().unwrap_or(0.0);
    }
    sum / n as f64
}

fn jpeg_size(payload: &[u8]) -> (u32, u32) {
    let data = compressed_image_data(payload).expect("a CompressedImage with data");
    let img = image::load_from_memory(data).expect("JPEG decodes");
    (img.width(), img.height())
}

#[test]
fn foxglove_clients_see_every_channel_and_rude_clients_change_nothing() {
    let p = Pipeline::start("view", &[], "");
    p.wait_all_running(START);
    let (ws_port, _) = view_ports(&p, WAIT);
    let rate_before = decision_rate(&p, 3);

    // One client: every channel advertised with its schema.
    let mut a = FoxgloveClient::connect(ws_port).expect("connect");
    assert_eq!(a.server_info["op"], "serverInfo");
    for (topic, schema) in CHANNELS {
        let ch = a
            .channels
            .get(topic)
            .unwrap_or_else(|| panic!("{topic} not advertised: {:?}", a.channels.keys()));
        assert_eq!(ch.schema_name, schema, "{topic}");
        if schema.starts_with("hvs.") {
            assert_eq!(
                (ch.encoding.as_str(), ch.schema_encoding.as_str()),
                ("json", "jsonschema")
            );
            let s: Value = serde_json::from_str(&ch.schema).expect("schema is JSON");
            let props = s["properties"].as_object().expect("properties");
            assert!(
                props.values().all(|p| p["type"].is_string()),
                "{topic}: every field has a type"
            );
        } else {
            assert_eq!(ch.encoding, "protobuf", "{topic}");
        }
    }
    // Codes are numbers, labels beside them.
    let d: Value = serde_json::from_str(&a.channels["/decisions"].schema).expect("schema");
    assert_eq!(d["properties"]["command"]["type"], "integer");
    assert_eq!(d["properties"]["command_label"]["type"], "string");

    let want = [
        "/frames/320x240/left",
        "/disparity/colour",
        "/fused/colour",
        "/disparity/points",
        "/camera/calibration",
        "/tf",
        "/map",
        "/ranges",
        "/decisions",
        "/actuator/sent",
        "/decision/pose",
        "/sim/truth",
        "/hvs/stages",
        "/hvs/legend",
    ];
    a.subscribe(&want).expect("subscribe");
    let got = a
        .collect(&want, 2, Duration::from_secs(40))
        .unwrap_or_else(|e| panic!("{e}\n{}", p.logs()));
    assert_eq!(
        jpeg_size(&got["/frames/320x240/left"][0].payload),
        (320, 240)
    );
    let legend_w = 320 + hvs_probe::render::LEGEND_WIDTH_PX;
    assert_eq!(
        jpeg_size(&got["/disparity/colour"][0].payload),
        (legend_w, 240)
    );
    assert_eq!(jpeg_size(&got["/fused/colour"][0].payload), (legend_w, 240));
    assert!(
        got["/disparity/points"][0].payload.len() > 1000,
        "a point cloud with points"
    );
    for topic in want.iter().filter(|t| a.channels[**t].encoding == "json") {
        let schema: Value = serde_json::from_str(&a.channels[*topic].schema).expect("schema");
        for m in &got[*topic] {
            let v: Value = serde_json::from_slice(&m.payload).expect("JSON message");
            conforms(&v, &schema).unwrap_or_else(|e| panic!("{topic}: {e}: {v}"));
        }
    }
    let wall_now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    let t = got["/ranges"][0].log_time_ns;
    assert!(
        t.abs_diff(wall_now) < 60_000_000_000,
        "log times are wall-clock: {t} vs {wall_now}"
    );

    // A second client gets images too.
    let mut b = FoxgloveClient::connect(ws_port).expect("second client");
    b.subscribe(&["/frames/320x240/left"]).expect("subscribe");
    b.collect(&["/frames/320x240/left"], 3, WAIT)
        .expect("second client's images");

    // Rude clients: garbage over raw TCP, garbage over the protocol, a frame cut off.
    for junk in [
        &b"\x00\x01\x02garbage\r\n\r\n"[..],
        b"GET / HTTP/1.1\r\nHost: x\r\n\r\n",
    ] {
        let mut s = TcpStream::connect(("127.0.0.1", ws_port)).expect("raw connect");
        let _ = s.write_all(junk);
    }
    let mut rude = FoxgloveClient::connect(ws_port).expect("rude client");
    rude.send_text("{not json").expect("send");
    rude.send_text(r#"{"op":"subscribe","subscriptions":[{"id":1,"channelId":999999}]}"#)
        .expect("send");
    rude.send_text(r#"{"op":"unsubscribe","subscriptionIds":[424242]}"#)
        .expect("send");
    rude.send_binary(vec![0xff; 100]).expect("send");
    drop(rude);
    let cut = FoxgloveClient::connect(ws_port).expect("client to cut off");
    cut.send_partial_frame_and_drop();

    // Twenty at once, all watching the left image.
    let mut many: Vec<FoxgloveClient> = (0..20)
        .map(|i| FoxgloveClient::connect(ws_port).unwrap_or_else(|e| panic!("client {i}: {e}")))
        .collect();
    for c in &mut many {
        c.subscribe(&["/frames/320x240/left", "/ranges"])
            .expect("subscribe");
    }
    for (i, c) in many.iter_mut().enumerate() {
        c.collect(&["/frames/320x240/left"], 1, WAIT)
            .unwrap_or_else(|e| panic!("client {i} of 20: {e}"));
    }
    let rate_during = decision_rate(&p, 3);
    eprintln!("decision rate: {rate_before:.1} Hz without clients, {rate_during:.1} Hz with 22");
    assert!(
        rate_during >= 0.8 * rate_before,
        "decision rate fell from {rate_before:.1} to {rate_during:.1} Hz with clients"
    );
    drop(many);

    // The first client is still served, a new one connects, and the view never restarted.
    a.collect(&["/frames/320x240/left"], 2, WAIT)
        .expect("first client still served");
    let mut late = FoxgloveClient::connect(ws_port).expect("client after the rude ones");
    late.subscribe(&["/frames/320x240/left"])
        .expect("subscribe");
    late.collect(&["/frames/320x240/left"], 1, WAIT)
        .expect("late client's image");
    let s = p.status().expect("status");
    assert_eq!(stage(&s, "view")["restarts"], 0, "{}", p.logs());
    assert!(stage(&s, "view")["frames_out"].as_u64().unwrap_or(0) > 0);
}

#[test]
fn the_view_killed_is_restarted_and_the_robot_never_notices() {
    let p = Pipeline::start("viewkill", &[], "");
    let before = p.wait_all_running(START);
    view_ports(&p, WAIT);
    let node = IpcNode::create(&p.instance, "e2e-observer").expect("node");
    let sent = node
        .subscriber(&topics::ACTUATOR_SENT, 16)
        .expect("actuator reports");
    let view_pid = pid_of(&before, "view");
    signal_pid(view_pid, Signal::SIGKILL);
    let killed_at = Instant::now();
    let restarted = |s: &Value| {
        let v = stage(s, "view");
        v["restarts"].as_u64().unwrap_or(0) >= 1
            && pid_of(s, "view") != view_pid
            && v["note"]
                .as_str()
                .is_some_and(|n| hvs_view::note::ws_port(n).is_some())
    };
    let mut decisions_seen = 0;
    let mut after = None;
    while after.is_none() {
        assert!(
            killed_at.elapsed() < WAIT,
            "the view did not come back within {WAIT:?}\n{}",
            p.logs()
        );
        while let Some(r) = sent.receive().expect("receive") {
            let r = r.payload();
            assert_ne!(
                SendReason::from_code(r.reason),
                Some(SendReason::WatchdogNeutral),
                "the actuator fell back to neutral while the view restarted"
            );
            decisions_seen +=
                u32::from(SendReason::from_code(r.reason) == Some(SendReason::Decision));
        }
        after = p.status().filter(|s| restarted(s));
        std::thread::sleep(Duration::from_millis(50));
    }
    let after = after.unwrap_or_default();
    assert!(decisions_seen > 0, "the robot kept driving on decisions");
    for name in [
        "sim",
        "capture",
        "stereo-lo",
        "fusion",
        "decision",
        "actuator",
    ] {
        assert_eq!(
            pid_of(&after, name),
            pid_of(&before, name),
            "{name} was disturbed"
        );
        assert_eq!(stage(&after, name)["restarts"], 0, "{name} restarted");
    }
    eprintln!("view back after {:?}", killed_at.elapsed());
    let (ws_port, _) = view_ports(&p, WAIT);
    let mut c = FoxgloveClient::connect(ws_port).expect("connect to the restarted view");
    c.subscribe(&["/frames/320x240/left"]).expect("subscribe");
    c.collect(&["/frames/320x240/left"], 1, WAIT)
        .expect("an image from the restarted view");

    // The stages' own log lines reach /log: restart the 640x480 worker (off the decision
    // path) and look for its start-up line and the supervisor's note of the restart.
    c.subscribe(&["/log"]).expect("subscribe to /log");
    hvs_tests::hvs_ok(&["restart", "stereo-hi", "--instance", &p.instance]);
    let deadline = Instant::now() + WAIT;
    let (mut from_stage, mut restart_noted) = (false, false);
    while !(from_stage && restart_noted) {
        assert!(
            Instant::now() < deadline,
            "no log lines of the restart on /log (stage's own: {from_stage}, restart: {restart_noted})"
        );
        let Ok(m) = c.next(Duration::from_secs(1)) else {
            continue;
        };
        if m.topic != "/log" {
            continue;
        }
        let text = |field| {
            hvs_view::client::bytes_field(&m.payload, field)
                .map(|b| String::from_utf8_lossy(b).into_owned())
                .unwrap_or_default()
        };
        let (message, name) = (text(3), text(4));
        from_stage |= name == "stereo-hi" && message.contains("starting");
        restart_noted |= name == "supervisor" && message.contains("stereo-hi restarted");
    }
}

/// A plain HTTP/1.1 request to loopback: (status code, body). The body is read to its
/// Content-Length (Chromium's DevTools server keeps the connection open), else to the end.
fn http(port: u16, method: &str, path: &str) -> (u16, String) {
    use std::io::{BufRead, BufReader, Read};
    let mut s = TcpStream::connect(("127.0.0.1", port)).expect("connect");
    s.set_read_timeout(Some(WAIT)).expect("timeout");
    write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nConnection: close\r\nContent-Length: 0\r\n\r\n"
    )
    .expect("request");
    let mut r = BufReader::new(s);
    let mut status = String::new();
    r.read_line(&mut status).expect("status line");
    let code = status
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    let mut length = None;
    loop {
        let mut line = String::new();
        if r.read_line(&mut line).expect("header") == 0 || line.trim().is_empty() {
            break;
        }
        if let Some((k, v)) = line.split_once(':')
            && k.trim().eq_ignore_ascii_case("content-length")
        {
            length = v.trim().parse::<usize>().ok();
        }
    }
    let mut body = Vec::new();
    match length {
        Some(n) => {
            body.resize(n, 0);
            r.read_exact(&mut body).expect("body");
        }
        None => {
            r.read_to_end(&mut body).expect("body");
        }
    }
    (code, String::from_utf8_lossy(&body).into_owned())
}

/// The browser: `HVS_CHROMIUM`, else Debian's `/usr/bin/chromium`.
fn chromium() -> Option<std::path::PathBuf> {
    std::env::var_os("HVS_CHROMIUM")
        .map(std::path::PathBuf::from)
        .or_else(|| Some(std::path::PathBuf::from("/usr/bin/chromium")))
        .filter(|p| p.is_file())
}

/// Headless Chromium driven over the Chrome DevTools protocol.
struct Browser {
    child: std::process::Child,
    _profile: tempfile::TempDir,
    ws: tungstenite::WebSocket<tungstenite::stream::MaybeTlsStream<TcpStream>>,
    next_id: u64,
}

impl Browser {
    fn launch(exe: &std::path::Path) -> Self {
        let profile = tempfile::tempdir().expect("profile dir");
        let child = std::process::Command::new(exe)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--remote-debugging-port=0",
                "--remote-allow-origins=*",
                "--window-size=1280,1000",
            ])
            .arg(format!("--user-data-dir={}", profile.path().display()))
            .arg("about:blank")
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .expect("start chromium");
        let port_file = profile.path().join("DevToolsActivePort");
        let deadline = Instant::now() + WAIT;
        let port: u16 = loop {
            if let Some(p) = std::fs::read_to_string(&port_file)
                .ok()
                .and_then(|t| t.lines().next().and_then(|l| l.trim().parse().ok()))
            {
                break p;
            }
            assert!(
                Instant::now() < deadline,
                "chromium did not open its DevTools port"
            );
            std::thread::sleep(Duration::from_millis(100));
        };
        let targets: Value =
            serde_json::from_str(&http(port, "GET", "/json/list").1).expect("targets");
        let url = targets
            .as_array()
            .into_iter()
            .flatten()
            .find(|t| t["type"] == "page")
            .and_then(|t| t["webSocketDebuggerUrl"].as_str())
            .expect("a page target")
            .to_string();
        let (ws, _) = tungstenite::connect(url.as_str()).expect("DevTools connection");
        // A browser that stops answering fails the test instead of hanging it.
        if let tungstenite::stream::MaybeTlsStream::Plain(s) = ws.get_ref() {
            s.set_read_timeout(Some(WAIT)).expect("read timeout");
        }
        Self {
            child,
            _profile: profile,
            ws,
            next_id: 1,
        }
    }

    fn call(&mut self, method: &str, params: Value) -> Value {
        let id = self.next_id;
        self.next_id += 1;
        let msg = serde_json::json!({"id": id, "method": method, "params": params});
        self.ws
            .send(tungstenite::Message::text(msg.to_string()))
            .expect("send");
        loop {
            let m = self.ws.read().expect("DevTools reply");
            if let tungstenite::Message::Text(t) = m {
                let v: Value = serde_json::from_str(t.as_str()).expect("JSON");
                if v["id"] == id {
                    assert!(v["error"].is_null(), "{method}: {v}");
                    return v["result"].clone();
                }
            }
        }
    }

    fn eval(&mut self, expression: &str) -> Value {
        let r = self.call(
            "Runtime.evaluate",
            serde_json::json!({"expression": expression, "returnByValue": true}),
        );
        r["result"]["value"].clone()
    }

    /// Waits until `document.body.dataset.frames` (left images shown) reaches `n`.
    fn wait_frames(&mut self, n: u64) -> u64 {
        let deadline = Instant::now() + Duration::from_secs(40);
        loop {
            let f = self
                .eval("Number(document.body.dataset.frames || 0)")
                .as_u64()
                .unwrap_or(0);
            if f >= n {
                return f;
            }
            assert!(
                Instant::now() < deadline,
                "the page showed {f} of {n} images"
            );
            std::thread::sleep(Duration::from_millis(200));
        }
    }

    fn screenshot(&mut self) -> image::RgbImage {
        use base64::Engine;
        let r = self.call(
            "Page.captureScreenshot",
            serde_json::json!({"format": "png"}),
        );
        let png = base64::engine::general_purpose::STANDARD
            .decode(r["data"].as_str().expect("data"))
            .expect("base64");
        image::load_from_memory(&png).expect("PNG").to_rgb8()
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Share of pixels that differ by more than 24 levels in some channel between two crops.
fn changed_share(a: &image::RgbImage, b: &image::RgbImage, rect: (u32, u32, u32, u32)) -> f64 {
    let (x0, y0, w, h) = rect;
    let mut changed = 0u64;
    for y in y0..y0 + h {
        for x in x0..x0 + w {
            let (p, q) = (a.get_pixel(x, y).0, b.get_pixel(x, y).0);
            if p.iter().zip(q).any(|(u, v)| u.abs_diff(v) > 24) {
                changed += 1;
            }
        }
    }
    changed as f64 / f64::from(w * h).max(1.0)
}

/// Standard deviation of the grey levels in a crop.
fn grey_stddev(img: &image::RgbImage, rect: (u32, u32, u32, u32)) -> f64 {
    let (x0, y0, w, h) = rect;
    let vals: Vec<f64> = (y0..y0 + h)
        .flat_map(|y| (x0..x0 + w).map(move |x| (x, y)))
        .map(|(x, y)| {
            let p = img.get_pixel(x, y).0;
            (f64::from(p[0]) + f64::from(p[1]) + f64::from(p[2])) / 3.0
        })
        .collect();
    let n = vals.len().max(1) as f64;
    let mean = vals.iter().sum::<f64>() / n;
    (vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt()
}

#[test]
fn a_real_browser_shows_the_live_page() {
    let Some(exe) = chromium() else {
        assert!(
            std::env::var_os("HVS_REQUIRE_BROWSER").is_none(),
            "HVS_REQUIRE_BROWSER is set but no chromium: apt-get install chromium"
        );
        eprintln!("SKIPPED: no /usr/bin/chromium (apt-get install chromium; .ci/run installs it)");
        return;
    };
    let p = Pipeline::start("viewpage", &[], "");
    p.wait_all_running(START);
    let (ws_port, http_port) = view_ports(&p, WAIT);

    // The page server: the page, self-contained and pointing at the WebSocket port.
    let (code, body) = http(http_port, "GET", "/");
    assert_eq!(code, 200);
    assert!(
        body.contains(&format!("const WS_PORT = {ws_port};")),
        "page names the ws port"
    );
    assert!(
        !body.contains("http://") && !body.contains("https://"),
        "nothing fetched"
    );
    assert_eq!(http(http_port, "GET", "/nope").0, 404);
    assert_eq!(http(http_port, "POST", "/").0, 405);

    let mut b = Browser::launch(&exe);
    b.call(
        "Page.navigate",
        serde_json::json!({"url": format!("http://127.0.0.1:{http_port}/")}),
    );
    let first = b.wait_frames(3);
    // Let the other panels (disparity at 5 Hz, stage table at 1 Hz) fill in.
    let deadline = Instant::now() + WAIT;
    while b
        .eval("document.querySelectorAll('#stages tbody tr').length")
        .as_u64()
        < Some(8)
        || b.eval("document.getElementById('disparity').naturalWidth")
            .as_u64()
            < Some(320)
        || b.eval("document.getElementById('fused').naturalWidth")
            .as_u64()
            < Some(320)
        || b.eval("document.getElementById('near').textContent.endsWith(' m')") != Value::Bool(true)
    {
        assert!(
            Instant::now() < deadline,
            "the page did not fill in\n{}",
            p.logs()
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    let rect = b.eval(
        "(() => { const r = document.getElementById('left').getBoundingClientRect(); \
         return [Math.round(r.x), Math.round(r.y), Math.round(r.width), Math.round(r.height)]; })()",
    );
    let rect: Vec<u32> = rect
        .as_array()
        .expect("rect")
        .iter()
        .map(|v| v.as_u64().unwrap_or(0) as u32)
        .collect();
    let rect = (rect[0], rect[1], rect[2], rect[3]);
    assert!(
        rect.2 >= 160 && rect.3 >= 120,
        "left image shown at {rect:?}"
    );
    let shot1 = b.screenshot();
    b.wait_frames(first + 10);
    let shot2 = b.screenshot();
    if let Some(dir) = std::env::var_os("HVS_VIEW_SCREENSHOTS") {
        let dir = std::path::PathBuf::from(dir);
        std::fs::create_dir_all(&dir).expect("screenshot dir");
        shot1.save(dir.join("view-page-1.png")).expect("save");
        shot2.save(dir.join("view-page-2.png")).expect("save");
    }
    let sd = grey_stddev(&shot1, rect);
    let changed = changed_share(&shot1, &shot2, rect);
    eprintln!(
        "left image on the page: grey stddev {sd:.1}, {:.1} % of pixels changed",
        changed * 100.0
    );
    assert!(
        sd > 10.0,
        "the left image on the page is blank (stddev {sd:.1})"
    );
    assert!(
        changed > 0.01,
        "the left image did not change ({:.2} %)",
        changed * 100.0
    );
    let whole = (0, 0, shot1.width(), shot1.height());
    assert!(grey_stddev(&shot1, whole) > 10.0, "the page is blank");
    let command = b.eval("document.getElementById('command').textContent");
    assert!(
        command.as_str().is_some_and(|c| c != "-"),
        "a command is shown: {command}"
    );
}
