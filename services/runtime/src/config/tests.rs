//! The configuration's tests: defaults, each section's rules, the data-flow check.

use super::*;

fn parse(text: &str) -> Result<HvsConfig, ConfigError> {
    // The sim's map from the repository, so that a file in a folder that does not exist
    // is still a whole, runnable config.
    let map = concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/maps/maze.txt");
    let text = format!("{text}\n[sim]\nmap = \"{map}\"\n");
    HvsConfig::parse(&text, Path::new("/nonexistent/test.toml"))
}

#[test]
fn empty_file_gives_defaults() {
    let c = parse("").expect("defaults are valid");
    assert_eq!(c.instance, "default");
    assert_eq!(c.stereo.lo.min_disp, 9);
    assert_eq!(c.stereo.hi.max_disp, 110);
    assert!((c.decision.lo.side_m - 0.71628).abs() < 1e-6);
    assert_eq!(c.stage_specs().len(), STAGE_NAMES.len());
}

#[test]
fn unknown_key_is_named_with_its_line() {
    let err = parse("[stereo.lo]\nmin_disp = 9\nmax_dsip = 55\n").unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("max_dsip"), "{msg}");
    assert!(msg.contains("line 3"), "{msg}");
    assert!(msg.contains("/nonexistent/test.toml"), "{msg}");
}

#[test]
fn wrong_type_is_named() {
    let err = parse("[camera]\nfps = \"fast\"\n").unwrap_err().to_string();
    assert!(err.contains("fps"), "{err}");
    assert!(err.contains("line 2"), "{err}");
}

#[test]
fn key_line_finds_keys_under_headers_and_dotted() {
    let text = "instance = \"x\"\n[stereo.lo]\nmin_disp = 2 # near\nsgm.p2 = 64\n\n[ stereo.lo.sgm ]\np1 = 16\n[fusion]\nwindows=3\n";
    assert_eq!(key_line(text, "instance"), Some(1));
    assert_eq!(key_line(text, "stereo.lo.min_disp"), Some(3));
    assert_eq!(key_line(text, "stereo.lo.sgm.p2"), Some(4));
    assert_eq!(key_line(text, "stereo.lo.sgm.p1"), Some(7));
    assert_eq!(key_line(text, "fusion.windows"), Some(9));
    assert_eq!(key_line(text, "stereo.hi.min_disp"), None);
    assert_eq!(key_line(text, "min_disp"), None);
}

#[test]
fn unknown_stage_is_rejected() {
    let err = parse("[stages.stero-lo]\nrestart = \"never\"\n")
        .unwrap_err()
        .to_string();
    assert!(err.contains("stages.stero-lo"), "{err}");
    assert!(err.contains("stereo-lo"), "{err}");
}

#[test]
fn missing_map_file_is_named() {
    let err = HvsConfig::parse(
        "[sim]\nmap = \"maps/nope.txt\"\n",
        Path::new("/nonexistent/dir/sim.toml"),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("sim.map"), "{err}");
    assert!(err.contains("/nonexistent/dir/maps/nope.txt"), "{err}");
}

#[test]
fn bad_instance_name_is_rejected() {
    let err = parse("instance = \"a/b\"").unwrap_err().to_string();
    assert!(err.contains("instance"), "{err}");
}

#[test]
fn pulses_outside_psc_range_are_rejected() {
    let err = parse("[actuator.pulses.forward]\nleft = 100\nright = 800\n")
        .unwrap_err()
        .to_string();
    assert!(err.contains("actuator.pulses.forward.left"), "{err}");
}

#[test]
fn capture_defaults_to_sim_and_parses_v4l2() {
    let c = parse("").unwrap();
    assert_eq!(c.capture.source, CaptureSource::Sim);
    let c = parse(
        "[capture]\nsource = \"v4l2\"\nwidth = 320\nheight = 240\n\
         [capture.v4l2]\nleft_device = \"/dev/video4\"\nright_device = \"/dev/video6\"\n\
         pixel_format = \"mjpeg\"\nmax_skew_ms = 10\n\
         [actuator]\ndevice = \"/dev/ttyUSB0\"\n[stages.stereo-hi]\nenabled = false\n",
    )
    .unwrap();
    assert_eq!(c.capture.source, CaptureSource::V4l2);
    assert_eq!(c.capture.v4l2.pixel_format, V4l2PixelFormat::Mjpeg);
    assert_eq!(c.capture.v4l2.left_device, PathBuf::from("/dev/video4"));
    assert!((c.capture.v4l2.max_skew_ms - 10.0).abs() < 1e-9);
    assert!(!c.stage_enabled(hvs_shared::topics::Stage::Sim));
}

#[test]
fn minoru_example_config_is_valid() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/minoru.toml");
    let c = HvsConfig::load(&path).expect("config/minoru.toml must stay valid");
    assert_eq!(c.capture.source, CaptureSource::V4l2);
    assert!(!c.stage_enabled(hvs_shared::topics::Stage::Sim));
}

#[test]
fn capture_values_are_checked_by_key() {
    for (text, key) in [
        (
            "[capture]\nsource = \"v4l2\"\nwidth = 800\n",
            "capture.width",
        ),
        (
            "[capture]\nsource = \"v4l2\"\n[capture.v4l2]\nmax_skew_ms = 0\n",
            "capture.v4l2.max_skew_ms",
        ),
        (
            "[capture]\nsource = \"v4l2\"\n[capture.v4l2]\nleft_device = \"/dev/a\"\nright_device = \"/dev/a\"\n",
            "capture.v4l2.right_device",
        ),
        (
            "[capture]\nsource = \"v4l2\"\n[capture.v4l2]\nbuffers = 1\n",
            "capture.v4l2.buffers",
        ),
        (
            "[capture]\nsource = \"files\"\n[capture.files]\nfolder = \"/nonexistent/pairs\"\n",
            "capture.files.folder",
        ),
        (
            "[capture]\nsource = \"v4l2\"\ncalibration = \"calib/none.yml\"\n",
            "capture.calibration",
        ),
    ] {
        let err = parse(text).unwrap_err().to_string();
        assert!(err.contains(key), "{key}: {err}");
    }
    let err = parse("[capture]\nsource = \"usb\"\n")
        .unwrap_err()
        .to_string();
    assert!(err.contains("usb"), "{err}");
    let err = parse("[capture.v4l2]\nmax_skew = 3\n")
        .unwrap_err()
        .to_string();
    assert!(err.contains("max_skew"), "{err}");
}

#[test]
fn stage_overrides_apply() {
    let c = parse("[stages.fusion]\nrestart = \"on-failure\"\nmax_restarts = 2\n").unwrap();
    let fusion = c
        .stage_specs()
        .into_iter()
        .find(|s| s.name == "fusion")
        .unwrap();
    assert_eq!(fusion.restart, RestartPolicy::OnFailure);
    assert_eq!(fusion.max_restarts, 2);
    assert!(c.stage_enabled(hvs_shared::topics::Stage::Sim));
}

#[test]
fn a_config_whose_stages_wait_on_nobody_is_refused_naming_the_keys() {
    let err = |text: &str| match parse(text) {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(ConfigError::Invalid { key, message, .. }) => (key, message),
        Err(e) => panic!("{e}"),
    };
    let (key, message) = err("[stages.sim]\nenabled = false\n");
    assert_eq!(key, "stages.sim.enabled");
    assert!(message.contains("no stage produces a frame"), "{message}");
    let (key, message) = err("[stages.capture]\nenabled = false\n");
    assert_eq!(key, "stages.capture.enabled");
    assert!(
        message.starts_with("stereo-lo reads frames/320x240"),
        "{message}"
    );
    let (key, _) = err("[stages.fusion]\nenabled = false\n");
    assert_eq!(key, "stages.fusion.enabled");
    let (key, message) = err(
        "[capture]\nsource = \"v4l2\"\n[actuator]\ndevice = \"/dev/ttyUSB0\"\n\
         [capture.v4l2]\nleft_device = \"/dev/video4\"\n[capture.v4l2.controls]\n\
         exposure_100us = 0\n",
    );
    assert_eq!(key, "capture.v4l2.controls.exposure_100us", "{message}");
    let (key, message) = err("[capture]\nsource = \"v4l2\"\n");
    assert_eq!(key, "actuator.device");
    assert!(
        message.contains("[stages.sim] enabled = false"),
        "{message}"
    );
    // Off together: a pipeline without wheels or decisions is fine.
    parse("[stages.decision]\nenabled = false\n[stages.actuator]\nenabled = false\n")
        .expect("no decisions, no actuator");
}

#[test]
fn the_nav_section_parses_and_a_bad_value_is_named_with_its_table() {
    let c = parse("[decision]\npolicy = \"explore\"\n[nav.grid]\ncell_m = 0.05\n")
        .expect("a valid [nav]");
    assert_eq!(c.decision.policy, DecisionPolicy::Explore);
    assert!((c.nav.grid.cell_m - 0.05).abs() < 1e-12);
    let err = parse("[nav.frontier]\nreplan_s = 0\n")
        .unwrap_err()
        .to_string();
    assert!(err.contains("nav.frontier.replan_s"), "{err}");
    assert!(err.contains("/nonexistent/test.toml"), "{err}");
    // The calibration's table lives in a file of its own and is checked the same way.
    let c = parse(
        "[nav.calibration]
enabled = true
",
    )
    .expect("calibration on");
    assert!(c.nav.calibration.enabled);
    let err = parse(
        "[nav.calibration]
forget_factor = 1.5
",
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("nav.calibration.forget_factor"), "{err}");
}
