//! End-to-end tests of `hvs probe record`: a real pipeline, a real recorder process, real
//! MCAP files read back with the `mcap` crate, and a real full disk (a 24 MiB tmpfs).

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

use hvs_tests::{Pipeline, bin, hvs_ok};
use serde_json::Value;

const START: Duration = Duration::from_secs(60);

/// Messages per channel topic of an MCAP file, checking every image on the way.
fn read_recording(path: &Path) -> (BTreeMap<String, u64>, BTreeMap<String, String>) {
    let bytes = std::fs::read(path).expect("read the recording");
    let mut counts = BTreeMap::new();
    for message in mcap::MessageStream::new(&bytes).expect("MCAP magic and header") {
        let message = message.expect("every message reads back");
        let topic = message.channel.topic.clone();
        if topic.starts_with("/frames/") {
            let schema = message.channel.schema.as_ref().expect("image schema");
            assert_eq!(schema.name, "foxglove.RawImage");
            let v: Value = serde_json::from_slice(&message.data).expect("JSON image");
            let (w, h) = (
                v["width"].as_u64().unwrap_or(0),
                v["height"].as_u64().unwrap_or(0),
            );
            assert_eq!(v["encoding"], "mono8");
            assert_eq!(v["step"].as_u64(), Some(w));
            let data = v["data"].as_str().expect("base64 data");
            assert_eq!(
                data.len() as u64,
                (w * h).div_ceil(3) * 4,
                "{topic}: {w}x{h}"
            );
            assert!(v["hvs_header"]["frame_id"].as_u64().is_some(), "{v}");
        }
        if let Some(schema) = message.channel.schema.as_ref()
            && schema.name.starts_with("hvs.")
        {
            // The live view's schemas: every field named with its type, and the messages
            // follow them.
            let js: Value = serde_json::from_slice(&schema.data).expect("JSON schema");
            let v: Value = serde_json::from_slice(&message.data).expect("JSON message");
            hvs_probe::schemas::conforms(&v, &js).unwrap_or_else(|e| panic!("{topic}: {e}"));
        }
        // One sequence per channel: 1, 2, 3... with no gaps.
        let n = counts.get(&topic).copied().unwrap_or(0);
        assert_eq!(u64::from(message.sequence), n + 1, "{topic}: sequence");
        *counts.entry(topic).or_insert(0) += 1;
    }
    let meta = hvs_probe::record::read_metadata(&bytes).expect("hvs.recording metadata");
    (counts, meta)
}

#[test]
fn a_recording_holds_every_topic_and_its_counts() {
    let p = Pipeline::start("record", &[], "");
    p.wait_all_running(START);
    let dir = tempfile::tempdir().expect("tempdir");
    let file = dir.path().join("run.mcap");
    let out = hvs_ok(&[
        "probe",
        "record",
        "--instance",
        &p.instance,
        "--config",
        p.config.to_str().expect("utf-8 path"),
        "--out",
        file.to_str().expect("utf-8 path"),
        "--duration",
        "3",
        "--json",
    ]);
    let summary: Value = serde_json::from_slice(&out.stdout).expect("summary JSON");
    println!("{summary}");
    let (counts, meta) = read_recording(&file);
    println!("{counts:?}\n{meta:?}");
    for topic in [
        "frames/320x240",
        "frames/640x480",
        "ranges",
        "decisions",
        "actuator/sent",
        "decision/pose",
    ] {
        let written = summary["topics"][topic]["written"]
            .as_u64()
            .expect("written");
        assert!(written > 0, "{topic}: nothing recorded");
        assert_eq!(meta[&format!("written.{topic}")], written.to_string());
        assert!(meta.contains_key(&format!("dropped.{topic}")));
        if topic.starts_with("frames/") {
            assert_eq!(counts[&format!("/{topic}/left")], written);
            assert_eq!(counts[&format!("/{topic}/right")], written);
        } else {
            assert_eq!(counts[&format!("/{topic}")], written);
        }
    }
    // About 3 s of a 30 Hz pipeline, less what the recorder lost (counted, not hidden).
    let lo = summary["topics"]["frames/320x240"]["written"]
        .as_u64()
        .unwrap_or(0)
        + summary["topics"]["frames/320x240"]["dropped"]
            .as_u64()
            .unwrap_or(0);
    assert!(lo >= 30, "{summary}");
    // Calibration once a second, and the transforms of every pose.
    assert!(
        counts.get("/camera/calibration").copied().unwrap_or(0) >= 2,
        "{counts:?}"
    );
    assert!(
        counts.contains_key("/camera/calibration/640x480"),
        "{counts:?}"
    );
    assert_eq!(
        counts.get("/tf"),
        counts.get("/decision/pose"),
        "{counts:?}"
    );
    assert!(summary["cut_short"].is_null(), "{summary}");
}

#[test]
fn a_full_disk_ends_the_recording_with_a_readable_file() {
    // A private mount namespace with a 24 MiB tmpfs: the recorder fills it in about a second.
    let probe = Command::new("unshare").args(["-m", "true"]).output();
    if !probe.is_ok_and(|o| o.status.success()) {
        println!("SKIPPED: no permission for a private mount namespace (unshare -m)");
        return;
    }
    let p = Pipeline::start("record-full", &[], "");
    p.wait_all_running(START);
    let disk = tempfile::tempdir().expect("tempdir");
    let keep = tempfile::tempdir().expect("tempdir");
    let mount = disk.path().to_str().expect("utf-8 path");
    let kept = keep.path().join("run.mcap");
    let script = format!(
        "mount -t tmpfs -o size=24m tmpfs {mount} && \
         {hvs} probe record --instance {instance} --out {mount}/run.mcap --duration 20 --json \
         && cp {mount}/run.mcap {kept}",
        hvs = bin("hvs").display(),
        instance = p.instance,
        kept = kept.display(),
    );
    let out = Command::new("unshare")
        .args(["-m", "sh", "-c", &script])
        .env("RUST_LOG", "warn")
        .output()
        .expect("run unshare");
    assert!(
        out.status.success(),
        "recorder on a full disk failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary: Value = serde_json::from_slice(&out.stdout).expect("summary JSON");
    println!("{summary}");
    let cause = summary["cut_short"]
        .as_str()
        .expect("cut short by the full disk");
    assert!(cause.to_lowercase().contains("space"), "{cause}");
    assert!(
        summary["duration_s"].as_f64().unwrap_or(99.0) < 15.0,
        "{summary}"
    );
    let (counts, meta) = read_recording(&kept);
    println!("{counts:?}\n{meta:?}");
    assert!(
        meta["cut_short"].to_lowercase().contains("space"),
        "{meta:?}"
    );
    assert!(
        counts.get("/frames/320x240/left").copied().unwrap_or(0) > 0,
        "the whole chunks before the full disk are kept: {counts:?}"
    );
    // The counts say what the file holds, and what the unfinished chunk took with it.
    for (topic, channel) in [
        ("frames/320x240", "/frames/320x240/left"),
        ("decisions", "/decisions"),
    ] {
        let written = summary["topics"][topic]["written"]
            .as_u64()
            .expect("written");
        assert_eq!(
            counts.get(channel).copied().unwrap_or(0),
            written,
            "{topic}"
        );
        assert_eq!(meta[&format!("written.{topic}")], written.to_string());
        assert!(
            meta.contains_key(&format!("lost_at_end.{topic}")),
            "{meta:?}"
        );
    }
}
