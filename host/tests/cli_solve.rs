//! `marionette solve` as a process: exit status, stdout JSON, stderr message.
//! (The library-level contract and error table are in `tests/cli_solve.rs`;
//! only the host crate's own tests get `CARGO_BIN_EXE_marionette`.)

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn rig() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../rigs/humanoid16.toml")
}

fn run(goals: &str, extra: &[&str]) -> Output {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("goals.json");
    std::fs::write(&path, goals).unwrap();
    Command::new(env!("CARGO_BIN_EXE_marionette"))
        .arg("solve")
        .arg(rig())
        .arg("--goals")
        .arg(&path)
        .args(extra)
        .output()
        .unwrap()
}

#[test]
fn prints_the_contracted_json() {
    // The rest position of the left sole: already met.
    let out = run(
        r#"{"goals": [{"segment": "l_foot", "target": [0.065, 0.0, 0.03], "weight": 1}]}"#,
        &["--json"],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let keys: Vec<&str> = v.as_object().unwrap().keys().map(String::as_str).collect();
    let mut keys = keys;
    keys.sort_unstable();
    assert_eq!(
        keys,
        [
            "converged",
            "goals",
            "iterations",
            "met",
            "restarts",
            "segments",
            "tolerance",
            "unreachable"
        ]
    );
    assert_eq!(v["restarts"], 3, "offline solve restarts by default");
    assert_eq!(v["met"], 1);
    assert_eq!(v["goals"][0]["met"], true);
    let g = &v["goals"][0];
    assert_eq!(g["segment"], "l_foot");
    assert!(g["distance"].as_f64().unwrap() < 1e-4);
    assert_eq!(v["segments"].as_array().unwrap().len(), 13);
}

#[test]
fn prints_a_summary_without_json() {
    let out = run(
        r#"{"goals": [{"segment": "l_foot", "target": [0.065, 0.0, 0.03], "weight": 1}]}"#,
        &[],
    );
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.starts_with("humanoid16: 1 goal(s)"), "{text}");
    assert!(text.contains("1 of 1 goal(s) met"), "{text}");
    assert!(text.contains("l_foot"), "{text}");
}

#[test]
fn bad_input_exits_non_zero_naming_the_line_and_field() {
    let out = run(
        r#"{"goals": [{"segment": "l_hand", "target": [0, 0, 0], "weight": 1}]}"#,
        &["--json"],
    );
    assert!(!out.status.success());
    assert!(out.stdout.is_empty());
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(
        err.contains("goals.json:1: goals[0].segment: unknown segment \"l_hand\""),
        "{err}"
    );
    let out = run("{\"goals\": [\n  {\"segment\": 1,}\n]}", &[]);
    assert!(!out.status.success());
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(err.contains("goals.json:2:"), "{err}");
}

#[test]
fn restarts_can_be_set() {
    let goals = r#"{"goals": [{"segment": "l_foot", "target": [0.065, 0.0, 0.03], "weight": 1}]}"#;
    let out = run(goals, &["--json", "--restarts", "0"]);
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["restarts"], 0);
}
