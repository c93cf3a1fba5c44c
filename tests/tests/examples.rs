//! The examples a client of its own starts from, run against the simulator: each must read
//! what the pipeline publishes. (`shared/examples/read_decisions.rs`: plain iceoryx2 and the
//! contract's types; `shared/examples/read_decisions.py`: the iceoryx2 Python bindings and a
//! ctypes structure written from docs/ipc.md.)

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

/// A Python 3 that imports iceoryx2 0.10 (PyPI's, installed once under
/// `target/py-iceoryx2`; [`hvs_tests::python_with`]).
fn python_with_iceoryx2() -> (String, std::path::PathBuf) {
    hvs_tests::python_with("py-iceoryx2", "import iceoryx2", &["iceoryx2==0.10.0"])
}

/// Checks the reader's lines: five frames, a real command label, the default policy (2,
/// fuzzy), frame ids increasing.
fn check_reader_output(text: &str) {
    let ids: Vec<u64> = text
        .lines()
        .map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            assert_eq!(f[0], "frame", "{l}");
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
}

/// Runs a reader against a running pipeline and against an instance that does not exist.
fn check_reader(mut reader: impl FnMut(&str) -> std::process::Output, tag: &str) {
    let p = Pipeline::start(tag, &[], "");
    p.wait_all_running(START);
    let out = reader(&p.instance);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    check_reader_output(&text);
    // A pipeline that is not there is named.
    let out = reader("no-such-instance");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("hvs/no-such-instance/decisions"), "{err}");
    println!("{text}");
}

#[test]
fn the_rust_reader_reads_decisions_from_a_running_pipeline() {
    let exe = example("read_decisions");
    check_reader(
        |instance| {
            Command::new(&exe)
                .args(["--instance", instance, "--count", "5"])
                .output()
                .expect("run the example")
        },
        "example-rust",
    );
}

#[test]
fn the_python_reader_reads_decisions_from_a_running_pipeline() {
    let (python, site) = python_with_iceoryx2();
    let script = repo_root().join("shared/examples/read_decisions.py");
    check_reader(
        |instance| {
            Command::new(&python)
                .arg(&script)
                .args(["--instance", instance, "--count", "5"])
                .env("PYTHONPATH", &site)
                .output()
                .expect("run the Python example")
        },
        "example-py",
    );
}
