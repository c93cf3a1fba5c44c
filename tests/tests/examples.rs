//! The examples a client of its own starts from, run against the simulator: each must read
//! what the pipeline publishes. (`shared/examples/read_decisions.rs`: plain iceoryx2 and the
//! contract's types.)

use std::process::Command;
use std::time::Duration;

use hvs_tests::{Pipeline, bin_dir, repo_root};

const START: Duration = Duration::from_secs(60);

/// The example's binary, built first if this run has not (`cargo test -p hvs-tests` alone
/// does not build other packages' examples).
fn example(name: &str) -> std::path::PathBuf {
    let path = bin_dir().join("examples").join(name);
    if !path.is_file() {
        let status = Command::new(env!("CARGO"))
            .args(["build", "--release", "-p", "hvs-shared", "--example", name])
            .current_dir(repo_root())
            .status()
            .expect("run cargo");
        assert!(status.success(), "cargo build --example {name} failed");
    }
    assert!(path.is_file(), "{} not built", path.display());
    path
}

#[test]
fn the_rust_reader_reads_decisions_from_a_running_pipeline() {
    let exe = example("read_decisions");
    let p = Pipeline::start("example-rust", &[], "");
    p.wait_all_running(START);
    let out = Command::new(&exe)
        .args(["--instance", &p.instance, "--count", "5"])
        .output()
        .expect("run the example");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let ids: Vec<u64> = text
        .lines()
        .map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            assert_eq!(f[0], "frame", "{l}");
            // A real command label and the default policy's code (2, fuzzy).
            assert!(
                ["STOP", "FWD", "LEFT", "RIGHT", "REV"].contains(&f[3]),
                "{l}"
            );
            assert_eq!(f.last().copied(), Some("2"), "{l}");
            f[1].parse().expect("frame id")
        })
        .collect();
    assert_eq!(ids.len(), 5, "{text}");
    assert!(ids.windows(2).all(|w| w[1] > w[0]), "{ids:?}");
    // A pipeline that is not there is named.
    let out = Command::new(&exe)
        .args(["--instance", "no-such-instance", "--count", "1"])
        .output()
        .expect("run the example");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("hvs/no-such-instance/decisions"), "{err}");
    println!("{text}");
}
