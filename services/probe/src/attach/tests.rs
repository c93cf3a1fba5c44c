//! Tests of the pure helpers of the probe commands: topic lookup, payload names, the
//! `list` table and JSON, and echo lines.

use super::*;
use crate::rate::RateStats;
use hvs_shared::messages::{Decision, StereoFrame320x240};

fn stats(samples: u64, gaps: u64, rate_hz: Option<f64>, period_ms: Option<f64>) -> RateStats {
    RateStats {
        samples,
        gaps,
        rate_hz,
        mean_period_ms: period_ms,
        min_period_ms: period_ms,
        max_period_ms: period_ms,
    }
}

fn rows() -> Vec<TopicRow> {
    vec![
        TopicRow {
            topic: "decisions".to_string(),
            payload: "Decision",
            ports: Some((1, 2, 8)),
            stats: Some(stats(30, 1, Some(30.0), Some(33.3))),
        },
        TopicRow {
            topic: "ranges".to_string(),
            payload: "RangeReport",
            ports: None,
            stats: None,
        },
    ]
}

#[test]
fn every_known_topic_path_resolves() {
    let paths = known_topic_paths();
    assert!(!paths.is_empty());
    for path in &paths {
        assert!(resolve_topic(path).is_ok(), "{path} does not resolve");
    }
    assert!(matches!(
        resolve_topic(topics::DECISIONS.path),
        Ok(TopicByPath::Decision(_))
    ));
    assert!(matches!(
        resolve_topic(topics::SUPERVISOR_STATUS.path),
        Ok(TopicByPath::SupervisorStatus(_))
    ));
}

#[test]
fn an_unknown_topic_names_every_known_one() {
    match resolve_topic("no/such/topic") {
        Err(AttachError::UnknownTopic { topic, known }) => {
            assert_eq!(topic, "no/such/topic");
            assert_eq!(known, known_topic_paths().join(", "));
        }
        other => panic!("expected UnknownTopic, got {other:?}"),
    }
    let message = resolve_topic("nope").expect_err("unknown").to_string();
    assert!(message.starts_with("unknown topic \"nope\"; known topics: "));
    assert!(message.contains(topics::DECISIONS.path));
}

#[test]
fn short_type_names_drop_the_module_path() {
    assert_eq!(short_type_name::<Decision>(), "Decision");
    assert_eq!(
        short_type_name::<StereoFrame320x240>(),
        "StereoFrame320x240"
    );
    assert_eq!(short_type_name::<SupervisorStatus>(), "SupervisorStatus");
    assert_eq!(short_type_name::<u32>(), "u32");
}

#[test]
fn list_table_shows_present_and_absent_topics() {
    let text = render_list("robot", Duration::from_millis(1500), &rows());
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 4, "{text}");
    assert_eq!(lines[0], "instance robot: 2 topics, rates over 1.5 s");
    assert!(lines[1].starts_with("TOPIC"));
    for column in ["TYPE", "PUBS", "SUBS", "RATE Hz", "PERIOD ms", "GAPS"] {
        assert!(
            lines[1].contains(column),
            "{column} missing from {:?}",
            lines[1]
        );
    }
    let present: Vec<&str> = lines[2].split_whitespace().collect();
    assert_eq!(
        present,
        ["decisions", "Decision", "1", "2/8", "30.0", "33.3", "1"]
    );
    assert!(!lines[2].contains("not created"));
    assert!(lines[3].starts_with("ranges"));
    assert!(lines[3].ends_with("(not created)"), "{:?}", lines[3]);
}

#[test]
fn list_json_carries_the_ports_and_rates_of_present_topics_only() {
    let v = list_json("robot", Duration::from_secs(2), &rows());
    assert_eq!(v["instance"], "robot");
    assert_eq!(v["window_s"], 2.0);
    let topics = v["topics"].as_array().expect("topics array");
    assert_eq!(topics.len(), 2);
    let present = &topics[0];
    assert_eq!(present["topic"], "decisions");
    assert_eq!(present["type"], "Decision");
    assert_eq!(present["exists"], true);
    assert_eq!(present["publishers"], 1);
    assert_eq!(present["subscribers"], 2);
    assert_eq!(present["max_subscribers"], 8);
    assert_eq!(present["samples"], 30);
    assert_eq!(present["gaps"], 1);
    assert_eq!(present["rate_hz"], 30.0);
    assert_eq!(present["mean_period_ms"], 33.3);
    let absent = &topics[1];
    assert_eq!(absent["topic"], "ranges");
    assert_eq!(absent["exists"], false);
    assert!(absent.get("publishers").is_none());
    assert!(absent.get("rate_hz").is_none());
}

#[test]
fn echo_lines_are_the_description_with_the_topic_in_json() {
    let d = Decision {
        frame_id: 42,
        ..Decision::default()
    };
    assert_eq!(echo_line("decisions", &d, false), d.describe_text());
    let json: serde_json::Value =
        serde_json::from_str(&echo_line("decisions", &d, true)).expect("valid JSON");
    assert_eq!(json["topic"], "decisions");
    let mut expected = d.describe_json();
    if let Some(map) = expected.as_object_mut() {
        map.insert("topic".into(), "decisions".into());
    }
    assert_eq!(json, expected);
}
