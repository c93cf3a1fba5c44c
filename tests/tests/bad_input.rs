//! Bad input, generated: every loader that reads something from outside (the config, the
//! simulator's maps, the PSC bytes on the simulated serial line, OpenCV calibration files,
//! PNG images, MCAP recordings) is fed mutated and random input with `proptest`. None may
//! panic; every error must name the file it comes from. `every_bad_input_has_a_clear_message`
//! prints the table of docs/bad-input.md.

use std::path::{Path, PathBuf};
use std::time::Duration;

use hvs_capture::calib::{StereoCalibration, StereoRectifier};
use hvs_capture::replay::ReplayIndex;
use hvs_runtime::config::HvsConfig;
use hvs_sim::GridMap;
use hvs_sim::psc::PscParser;
use hvs_tests::repo_root;
use proptest::prelude::*;
use proptest::test_runner::Config;

fn cases(n: u32) -> Config {
    Config {
        cases: n,
        // Failures are printed with their minimal input; nothing is written into the tree.
        failure_persistence: None,
        ..Config::default()
    }
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Values that tend to break parsers and range checks.
fn nasty_value() -> impl Strategy<Value = String> {
    prop_oneof![
        Just(String::new()),
        Just("\"\"".to_string()),
        Just("-1".to_string()),
        Just("0".to_string()),
        Just("nan".to_string()),
        Just("inf".to_string()),
        Just("-inf".to_string()),
        Just("1e308".to_string()),
        Just("18446744073709551616".to_string()),
        Just("[]".to_string()),
        Just("{}".to_string()),
        Just("true".to_string()),
        Just("\"\u{0}\"".to_string()),
        any::<i64>().prop_map(|v| v.to_string()),
        any::<f64>().prop_map(|v| format!("{v:?}")),
        "[ -~]{0,12}",
    ]
}

/// Text edits: replace the value of line `i`, drop line `i`, or insert a random line there.
#[derive(Debug, Clone)]
enum LineEdit {
    Value(usize, String),
    Drop(usize),
    Insert(usize, String),
}

fn line_edits() -> impl Strategy<Value = Vec<LineEdit>> {
    prop::collection::vec(
        prop_oneof![
            (any::<usize>(), nasty_value()).prop_map(|(i, v)| LineEdit::Value(i, v)),
            any::<usize>().prop_map(LineEdit::Drop),
            (any::<usize>(), "[ -~]{0,30}").prop_map(|(i, l)| LineEdit::Insert(i, l)),
        ],
        1..4,
    )
}

fn apply_edits(text: &str, edits: &[LineEdit], separator: char) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    for edit in edits {
        if lines.is_empty() {
            break;
        }
        match edit {
            LineEdit::Value(i, v) => {
                let n = lines.len();
                let line = &mut lines[i % n];
                if let Some(at) = line.find(separator) {
                    *line = format!("{}{separator} {v}", &line[..at]);
                }
            }
            LineEdit::Drop(i) => {
                let i = i % lines.len();
                lines.remove(i);
            }
            LineEdit::Insert(i, l) => {
                let i = i % lines.len();
                lines.insert(i, l.clone());
            }
        }
    }
    lines.join("\n")
}

/// Byte edits: truncate, overwrite or insert.
fn mutate_bytes(bytes: &[u8], edits: &[(usize, u8, u8)]) -> Vec<u8> {
    let mut out = bytes.to_vec();
    for &(at, byte, kind) in edits {
        if out.is_empty() {
            break;
        }
        let i = at % out.len();
        match kind % 3 {
            0 => out.truncate(i),
            1 => out[i] = byte,
            _ => out.insert(i, byte),
        }
    }
    out
}

fn byte_edits() -> impl Strategy<Value = Vec<(usize, u8, u8)>> {
    prop::collection::vec((any::<usize>(), any::<u8>(), any::<u8>()), 1..6)
}

const CONFIG_PATH: &str = "/fuzz/hvs.toml";

fn sim_config() -> String {
    read(&repo_root().join("config/sim.toml"))
}

proptest! {
    #![proptest_config(cases(1000))]

    #[test]
    fn the_config_loader_never_panics_and_names_the_file(edits in line_edits()) {
        let text = apply_edits(&sim_config(), &edits, '=');
        if let Err(e) = HvsConfig::parse(&text, Path::new(CONFIG_PATH)) {
            prop_assert!(e.to_string().contains(CONFIG_PATH), "{e}");
        }
    }

    #[test]
    fn the_config_loader_takes_any_text(text in "\\PC{0,200}") {
        if let Err(e) = HvsConfig::parse(&text, Path::new(CONFIG_PATH)) {
            prop_assert!(e.to_string().contains(CONFIG_PATH), "{e}");
        }
    }

    #[test]
    fn the_map_loader_never_panics_and_names_the_map(
        edits in line_edits(),
        cells in prop::collection::vec((any::<usize>(), prop::sample::select(vec!['#', '.', '>', '<', '^', 'v', 'x', ' ', '@', '\n'])), 0..20),
    ) {
        let base = read(&repo_root().join("config/maps/x.txt"));
        let mut chars: Vec<char> = apply_edits(&base, &edits, ' ').chars().collect();
        for (at, c) in cells {
            if !chars.is_empty() {
                let i = at % chars.len();
                chars[i] = c;
            }
        }
        let text: String = chars.into_iter().collect();
        match GridMap::parse(&text, "fuzz.txt") {
            Ok(map) => {
                // A map that loads is usable: its start pose is inside it.
                let start = map.start_pose();
                prop_assert!(start.x_m >= 0.0 && start.x_m <= map.width_m());
                prop_assert!(start.y_m >= 0.0 && start.y_m <= map.height_m());
            }
            Err(e) => prop_assert!(e.to_string().contains("fuzz.txt"), "{e}"),
        }
    }

    #[test]
    fn the_psc_parser_survives_any_bytes_and_resynchronises(
        garbage in prop::collection::vec(any::<u8>(), 0..300),
    ) {
        let mut parser = PscParser::new();
        let mut t = 0.0;
        for &b in &garbage {
            parser.push(b, t);
            t += 1e-4;
        }
        // Counters stay consistent with what was fed.
        prop_assert!(parser.frames_ok() * 8 <= garbage.len() as u64);
        // After any garbage a valid position command gets through (at most one frame is
        // lost while the parser finds the frame boundary again).
        let frame = [b'!', b'S', b'C', 3, 7, 0x20, 0x03, 0x0D];
        let mut parsed = 0;
        for _ in 0..2 {
            for &b in &frame {
                if parser.push(b, t).is_some() {
                    parsed += 1;
                }
                t += 1e-4;
            }
        }
        prop_assert!(parsed >= 1, "no command after {:?}", garbage);
    }

    #[test]
    fn the_calibration_loader_never_panics_and_names_the_file(edits in line_edits()) {
        let fixtures = repo_root().join("services/capture/tests/fixtures");
        let path = Path::new("/fuzz/stereo.yml");
        for name in ["identity.yml", "shifted.yml"] {
            let text = apply_edits(&read(&fixtures.join(name)), &edits, ':');
            match StereoCalibration::parse(&text, path) {
                // What loads must also give a remap (or a clear error) at any size.
                Ok(calib) => {
                    for (w, h) in [(64, 48), (320, 240)] {
                        if let Err(e) = StereoRectifier::new(&calib, w, h) {
                            prop_assert!(e.to_string().contains("stereo.yml"), "{e}");
                        }
                    }
                }
                Err(e) => prop_assert!(e.to_string().contains("stereo.yml"), "{e}"),
            }
        }
    }
}

/// A valid 32x24 grey PNG.
fn small_png() -> Vec<u8> {
    let img = image::GrayImage::from_fn(32, 24, |x, y| image::Luma([(x * 7 + y * 3) as u8]));
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .expect("encode PNG");
    out.into_inner()
}

/// Runs every image loader of the product on `file` (32x24 expected).
fn load_with_every_loader(file: &Path) -> Vec<Result<(), String>> {
    let mut dst = vec![0u8; 32 * 24];
    vec![
        hvs_capture::files::load_grey(file, 32, 24, &mut dst).map_err(|e| e.to_string()),
        hvs_stereo::eval::read_grey(file)
            .map(|_| ())
            .map_err(|e| e.to_string()),
        hvs_stereo::eval::read_disparity_png(file)
            .map(|_| ())
            .map_err(|e| e.to_string()),
        hvs_sim::pngio::read_gray8(file)
            .map(|_| ())
            .map_err(|e| e.to_string()),
    ]
}

proptest! {
    #![proptest_config(cases(400))]

    #[test]
    fn the_image_loaders_never_panic_and_name_the_file(edits in byte_edits()) {
        let dir = tempfile::tempdir().expect("tempdir");
        let file = dir.path().join("fuzz.png");
        std::fs::write(&file, mutate_bytes(&small_png(), &edits)).expect("write");
        for result in load_with_every_loader(&file) {
            if let Err(e) = result {
                prop_assert!(e.contains("fuzz.png"), "{e}");
            }
        }
    }
}

/// A small recording from the replay's own unit-test layout: 4 frames, both sizes.
fn small_recording(path: &Path) {
    use base64::Engine;
    let file = std::fs::File::create(path).expect("create");
    let mut w = mcap::WriteOptions::new()
        .chunk_size(Some(64 * 1024))
        .create(std::io::BufWriter::new(file))
        .expect("writer");
    let schema = w.add_schema("s", "jsonschema", b"{}").expect("schema");
    let meta = std::collections::BTreeMap::new();
    let mut seq = 0;
    let topics = [
        "/frames/320x240/left",
        "/frames/320x240/right",
        "/frames/640x480/left",
        "/frames/640x480/right",
    ];
    let channels: Vec<u16> = topics
        .iter()
        .map(|t| w.add_channel(schema, t, "json", &meta).expect("channel"))
        .collect();
    for id in 1..=4u64 {
        for (i, &channel_id) in channels.iter().enumerate() {
            let (wd, ht) = if i < 2 { (320, 240) } else { (640, 480) };
            let data = base64::engine::general_purpose::STANDARD.encode(vec![id as u8; wd * ht]);
            let body = serde_json::json!({"width": wd, "height": ht, "data": data,
                "hvs_header": {"frame_id": id, "capture_ns": id * 33_000_000}});
            seq += 1;
            let header = mcap::records::MessageHeader {
                channel_id,
                sequence: seq,
                log_time: seq as u64,
                publish_time: seq as u64,
            };
            w.write_to_known_channel(&header, body.to_string().as_bytes())
                .expect("write");
        }
    }
    w.finish().expect("finish");
}

proptest! {
    #![proptest_config(cases(200))]

    #[test]
    fn the_replay_reader_never_panics_on_a_damaged_recording(edits in byte_edits()) {
        let dir = tempfile::tempdir().expect("tempdir");
        let good = dir.path().join("good.mcap");
        small_recording(&good);
        let bytes = std::fs::read(&good).expect("read");
        let file = dir.path().join("fuzz.mcap");
        std::fs::write(&file, mutate_bytes(&bytes, &edits)).expect("write");
        match ReplayIndex::open(&file) {
            Ok(index) => {
                let mut reader = index.reader().expect("reader");
                loop {
                    match reader.next_event() {
                        Ok(Some(_)) => {}
                        Ok(None) => break,
                        Err(e) => {
                            prop_assert!(e.to_string().contains("fuzz.mcap"), "{e}");
                            break;
                        }
                    }
                }
            }
            Err(e) => prop_assert!(e.to_string().contains("fuzz.mcap"), "{e}"),
        }
    }
}

/// One row of the table: what was tried, the message, and the name the message must carry.
struct Row {
    loader: &'static str,
    input: String,
    message: String,
    must_name: String,
}

impl Row {
    fn of<T, E: std::fmt::Display>(
        loader: &'static str,
        input: &str,
        result: Result<T, E>,
        must_name: impl Into<String>,
    ) -> Self {
        Self {
            loader,
            input: input.to_string(),
            message: result.map_or_else(|e| e.to_string(), |_| "(accepted)".to_string()),
            must_name: must_name.into(),
        }
    }
}

fn config_row(input: &str, text: &str) -> Row {
    let result = HvsConfig::parse(text, Path::new(CONFIG_PATH));
    Row::of("config", input, result, CONFIG_PATH)
}

fn with_line(text: &str, from: &str, to: &str) -> String {
    assert!(text.contains(from), "config/sim.toml has no {from:?}");
    text.replace(from, to)
}

fn file_rows(dir: &Path) -> Vec<Row> {
    let mut rows = Vec::new();
    let write = |name: &str, bytes: &[u8]| -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, bytes).expect("write");
        p
    };
    let png = small_png();
    let map_cases: [(&str, &str); 4] = [
        ("no start marker", "@cell_m 0.35\n#####\n#...#\n#####\n"),
        ("two start markers", "@cell_m 0.35\n#####\n#>.>#\n#####\n"),
        (
            "unknown cell character",
            "@cell_m 0.35\n#####\n#>.?#\n#####\n",
        ),
        ("cell size 0", "@cell_m 0\n#####\n#>..#\n#####\n"),
    ];
    for (what, text) in map_cases {
        let p = write("bad_map.txt", text.as_bytes());
        rows.push(Row::of("map", what, GridMap::load(&p), "bad_map.txt"));
    }
    let fixture = read(&repo_root().join("services/capture/tests/fixtures/identity.yml"));
    let calib_cases = [
        ("not YAML", "this is not a calibration".to_string()),
        ("K1 missing", fixture.replace("K1:", "Kx:")),
        (
            "K1 with 8 numbers",
            fixture.replacen(
                "data: [ 50., 0., 31.5, 0., 50., 23.5, 0., 0., 1. ]",
                "data: [ 50., 0., 31.5, 0., 50., 23.5, 0., 0. ]",
                1,
            ),
        ),
        (
            "image_width not a number",
            fixture.replace("image_width: 64", "image_width: wide"),
        ),
    ];
    for (what, text) in calib_cases {
        let p = write("stereo.yml", text.as_bytes());
        rows.push(Row::of(
            "calibration",
            what,
            StereoCalibration::load(&p),
            "stereo.yml",
        ));
    }
    let image_cases: [(&str, Vec<u8>); 3] = [
        ("PNG cut in half", png[..png.len() / 2].to_vec()),
        ("not an image", b"hello".to_vec()),
        ("empty file", Vec::new()),
    ];
    for (what, bytes) in image_cases {
        let p = write("image.png", &bytes);
        let mut dst = vec![0u8; 32 * 24];
        rows.push(Row::of(
            "image (capture files source)",
            what,
            hvs_capture::files::load_grey(&p, 32, 24, &mut dst),
            "image.png",
        ));
    }
    let p = write("image.png", &png);
    let mut dst = vec![0u8; 64 * 48];
    rows.push(Row::of(
        "image (capture files source)",
        "32x24 where 64x48 is configured",
        hvs_capture::files::load_grey(&p, 64, 48, &mut dst),
        "image.png",
    ));
    // The actuator's serial link: a missing device, a file that is not a terminal, and a
    // real pseudo-terminal nobody answers on.
    let pty = nix::pty::openpty(None, None).expect("openpty");
    let silent = nix::unistd::ttyname(&pty.slave).expect("pty name");
    let link_cases = [
        ("missing device", dir.join("ttyUSB9")),
        ("not a terminal", write("not-a-tty", b"")),
        ("pseudo-terminal with no controller", silent.clone()),
    ];
    for (what, device) in link_cases {
        rows.push(Row::of(
            "serial link (actuator)",
            what,
            hvs_actuator::link::check_controller(&device, 2400, Duration::from_millis(600)),
            device.display().to_string(),
        ));
    }
    drop(pty);
    let good = dir.join("good.mcap");
    small_recording(&good);
    let bytes = std::fs::read(&good).expect("read");
    let replay_cases: [(&str, Vec<u8>); 2] = [
        ("not MCAP", b"hello".to_vec()),
        ("cut inside the header", bytes[..60].to_vec()),
    ];
    for (what, bytes) in replay_cases {
        let p = write("run.mcap", &bytes);
        rows.push(Row::of(
            "recording (replay)",
            what,
            ReplayIndex::open(&p),
            "run.mcap",
        ));
    }
    rows
}

#[test]
fn every_bad_input_has_a_clear_message() {
    let base = sim_config();
    let mut rows = vec![
        config_row("not TOML", "this is = = not toml"),
        config_row("unknown key", &format!("{base}\n[fusion2]\nx = 1\n")),
        config_row(
            "wrong type",
            &with_line(&base, "windows = 3", "windows = \"three\""),
        ),
        config_row(
            "out of range",
            &with_line(&base, "windows = 3", "windows = 4"),
        ),
        config_row(
            "negative rate",
            &with_line(&base, "fps = 30.0", "fps = -30.0"),
        ),
        config_row(
            "baseline 0",
            &with_line(&base, "baseline_m = 0.060", "baseline_m = 0.0"),
        ),
        config_row(
            "Canny thresholds reversed",
            &with_line(&base, "canny_low = 60", "canny_low = 200"),
        ),
        config_row(
            "instance name with a slash",
            &with_line(&base, "instance = \"default\"", "instance = \"a/b\""),
        ),
        config_row(
            "no frame source (the sim stage off, capture from the sim)",
            &with_line(
                &base,
                "[stages.sim]\nrestart = \"always\"",
                "[stages.sim]\nrestart = \"always\"\nenabled = false",
            ),
        ),
        config_row(
            "stereo-hi on with a 320x240 capture",
            &with_line(
                &base,
                "source = \"sim\"",
                "source = \"files\"\nwidth = 320\nheight = 240\nfiles.folder = \"/\"",
            ),
        ),
        config_row(
            "the actuator without a device",
            &with_line(&base, "device = \"sim\"", "device = \"\""),
        ),
        config_row(
            "a live view address without a port",
            &with_line(&base, "bind = \"127.0.0.1:8765\"", "bind = \"localhost\""),
        ),
    ];
    let dir = tempfile::tempdir().expect("tempdir");
    rows.extend(file_rows(dir.path()));
    println!("| loader | bad input | message |\n|---|---|---|");
    let mut failures = Vec::new();
    for r in &rows {
        let shown = r
            .message
            .replace(&dir.path().display().to_string(), "DIR")
            .replace('|', "\\|")
            .replace('\n', " ");
        println!("| {} | {} | {} |", r.loader, r.input, shown);
        if r.message == "(accepted)" || !r.message.contains(&r.must_name) {
            failures.push(format!("{} / {}: {}", r.loader, r.input, r.message));
        }
    }
    // The PSC parser reports rather than fails: the malformed counter and the reason.
    let mut parser = PscParser::new();
    for (i, &b) in [b'!', b'S', b'C', 3, 7, 0x20, 0x10, 0x0D]
        .iter()
        .enumerate()
    {
        parser.push(b, i as f64 * 1e-3);
    }
    println!(
        "| PSC parser (simulator) | `!SC` channel 3, ramp 7, pulse 0x1020 = 4128 | malformed frame counted: {} |",
        parser
            .last_malformed()
            .map_or("(accepted)".to_string(), |m| m.to_string())
    );
    if parser.malformed_frames() != 1 {
        failures.push("PSC: a pulse of 4128 was not counted as malformed".to_string());
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
