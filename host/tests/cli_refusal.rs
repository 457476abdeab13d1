//! Every refusal explained (#20): `emulate`, `sim` and `demo` with inputs
//! the board cannot perform. Each must end at once (no hang), print the
//! board's `Status` reason with what to do, exit 3 (never armed), and carry
//! the reason in `--json`. The reasons are the firmware's own: the emulated
//! board is booted on QEMU and its `Status` read back.

use marionette_host::perform;
use marionette_host::rigfile;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Runs `marionette` and waits at most `limit`: a run still going then is
/// killed and fails the test as a hang (the harness's own deadlines are
/// longer; nothing here should come close).
fn run_within(args: &[&str], limit: Duration) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_marionette"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > limit {
            let _ = child.kill();
            panic!("{args:?} hung for {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

const LIMIT: Duration = Duration::from_secs(90);

/// The first 60 time steps of the bundled recording (three sensors).
fn short_recording(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(repo().join("data/recordings/reach_hdm05_007.csv")).unwrap();
    let rows: Vec<&str> = text.lines().take(1 + 3 * 60).collect();
    let path = dir.join("short.csv");
    std::fs::write(&path, rows.join("\n") + "\n").unwrap();
    path
}

fn build(spec: &str, out: &Path) {
    let o = run_within(
        &["build", s(&repo().join(spec)), "-o", s(out), "--quiet"],
        LIMIT,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// Asserts exit code 3 and the reason on stderr and in the JSON summary.
fn refused(args: &[&str], reason: &str, detail: &str) {
    let o = run_within(args, LIMIT);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(3), "{args:?}: {err}");
    assert!(
        err.contains(&format!("refused to arm: {reason}:")) && err.contains("what to do:"),
        "{args:?}: {err}"
    );
    assert!(err.contains(detail), "{args:?}: {err}");
    let mut json = args.to_vec();
    json.push("--json");
    let o = run_within(&json, LIMIT);
    assert_eq!(o.status.code(), Some(3));
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(doc["board"]["armed"], false, "{doc}");
    assert_eq!(doc["board"]["reason"], reason, "{doc}");
    assert_eq!(doc["board"]["exit_code"], 3, "{doc}");
    assert!(doc["board"]["advice"].as_str().unwrap().len() > 10);
}

#[test]
fn the_emulated_board_says_why_it_never_arms() {
    let dir = tempfile::tempdir().unwrap();
    let rec = short_recording(dir.path());
    let rig = repo().join("rigs/humanoid16.toml");
    let table = dir.path().join("reach.bin");
    build("data/builds/reach_humanoid16.toml", &table);
    let blob = std::fs::read(&table).unwrap();
    let out = dir.path().join("out");
    let emulate = |tables: &Path, rig: &Path| {
        vec![
            "emulate".to_owned(),
            "--rig".into(),
            s(rig).into(),
            "--tables".into(),
            s(tables).into(),
            "--recording".into(),
            s(&rec).into(),
            "--out".into(),
            s(&out).into(),
        ]
    };
    let check = |args: Vec<String>, reason: &str, detail: &str| {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        refused(&args, reason, detail);
        assert!(
            !out.join("servo_emulated.csv").exists(),
            "no curves written"
        );
    };

    // No table at all.
    let args = [
        "emulate",
        "--rig",
        s(&rig),
        "--recording",
        s(&rec),
        "--out",
        s(&out),
    ];
    refused(&args, "NoTable", "--tables");

    // A flipped bit: the CRC; cut short: its bounds (the region's directory
    // holds the blob's true length, which its header's sizes overrun).
    let mut bad = blob.clone();
    bad[blob.len() / 2] ^= 0x10;
    let bad_crc = dir.path().join("badcrc.bin");
    std::fs::write(&bad_crc, &bad).unwrap();
    check(emulate(&bad_crc, &rig), "BadCrc", "inspect");
    let cut = dir.path().join("cut.bin");
    std::fs::write(&cut, &blob[..blob.len() / 2]).unwrap();
    check(emulate(&cut, &rig), "BadBounds", "inspect");

    // The region image (rig + table) given as the table.
    let rig_file = rigfile::load(&rig).unwrap();
    let region = perform::region(&rigfile::to_blob(&rig_file).unwrap(), Some(&blob));
    let region_bin = dir.path().join("region.bin");
    std::fs::write(&region_bin, region).unwrap();
    check(emulate(&region_bin, &rig), "BadMagic", "region.bin");

    // The clips table the walk spec builds.
    let walk = dir.path().join("walk.bin");
    build("data/builds/walk_humanoid16.toml", &walk);
    check(emulate(&walk, &rig), "Unsupported", "clip (motion) table");

    // A table built for another rig: the same puppet with a longer shin.
    let text = std::fs::read_to_string(&rig).unwrap();
    let other = dir.path().join("other.toml");
    let longer = text.replacen(
        "origin = [0.0, -0.18, 0.0]",
        "origin = [0.0, -0.19, 0.0]",
        1,
    );
    assert_ne!(longer, text);
    std::fs::write(&other, longer).unwrap();
    check(emulate(&table, &other), "RigMismatch", "hash");

    // A PCA9685 rig: the emulated board drives a Maestro only, and says so
    // at once instead of waiting for servo bytes that never come.
    let pca = dir.path().join("pca.toml");
    let pca_text = text.replace(
        "kind = \"maestro\"                # Pololu Maestro, compact protocol over UART\nbaud = 115200",
        "kind = \"pca9685\"\ni2c_addr = 0x40\nfreq_hz = 50",
    );
    assert_ne!(pca_text, text);
    std::fs::write(&pca, pca_text).unwrap();
    check(emulate(&table, &pca), "Unsupported", "pca9685");
    let pwm = dir.path().join("pwm.toml");
    let pwm_text = text.replace(
        "kind = \"maestro\"                # Pololu Maestro, compact protocol over UART\nbaud = 115200",
        "kind = \"pwm\"\nfreq_hz = 50",
    );
    std::fs::write(&pwm, pwm_text).unwrap();
    check(emulate(&table, &pwm), "Unsupported", "pwm");

    // The demo checks first, with the same words.
    let demo = [
        "demo",
        "--rig",
        s(&pca),
        "--recording",
        s(&rec),
        "--out",
        s(&out),
    ];
    refused(&demo, "Unsupported", "pca9685");
}

#[test]
fn sim_says_why_the_loop_never_arms() {
    let dir = tempfile::tempdir().unwrap();
    let rec = short_recording(dir.path());
    let out = dir.path().join("out");
    let rig = repo().join("rigs/humanoid16.toml");
    let args = [
        "sim",
        "--rig",
        s(&rig),
        "--recording",
        s(&rec),
        "--out",
        s(&out),
    ];
    refused(&args, "NoTable", "marionette build");
    assert!(!out.join("servo_sim.csv").exists());
}

#[test]
fn a_recording_beyond_the_wire_clock_is_refused_before_streaming() {
    let dir = tempfile::tempdir().unwrap();
    let rec = short_recording(dir.path());
    let text = std::fs::read_to_string(&rec).unwrap();
    let last = text.lines().last().unwrap();
    let (_, rest) = last.split_once(',').unwrap();
    let jump = dir.path().join("jump.csv");
    std::fs::write(&jump, format!("{text}{},{rest}\n", u64::MAX)).unwrap();
    let o = run_within(
        &[
            "emulate",
            "--realtime",
            "--rig",
            s(&repo().join("rigs/humanoid16.toml")),
            "--recording",
            s(&jump),
            "--out",
            s(&dir.path().join("out")),
        ],
        LIMIT,
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("jump.csv:182: time_us") && err.contains("71 min"),
        "{err}"
    );
}

/// A table region holding the humanoid16 rig and no table.
fn rig_without_table() -> Vec<u8> {
    let rig = rigfile::load(&repo().join("rigs/humanoid16.toml")).unwrap();
    let mut blob = vec![0u8; marionette_core::rig::MAX_BLOB_LEN];
    let n = rig.desc().to_blob(&mut blob).unwrap();
    perform::region(&blob[..n], None)
}

/// `stream` to a board (the emulated one on a pty, as a real board's
/// serial port) whose flash holds a rig but no table: the board answers
/// `Hello` with `NoTable`, and `stream` says so, with what to do, exits 3
/// and carries the reason in `--json`, as `emulate` does.
#[test]
fn stream_says_why_the_board_never_arms() {
    let dir = tempfile::tempdir().unwrap();
    let rec = short_recording(dir.path());
    let rig_path = repo().join("rigs/humanoid16.toml");
    let region_file = dir.path().join("region.bin");
    std::fs::write(&region_file, rig_without_table()).unwrap();
    let elf = marionette_host::qemu::firmware_elf("perform").unwrap();
    let board =
        marionette_host::qemu::PtyBoard::start(&elf, &region_file, &dir.path().join("uart1.bin"))
            .unwrap();
    let out = dir.path().join("out");
    refused(
        &[
            "stream",
            "--port",
            s(board.pty()),
            "--recording",
            s(&rec),
            "--rig",
            s(&rig_path),
            "--out",
            s(&out),
        ],
        "NoTable",
        "the board on /dev/",
    );
    assert!(!out.join("sent.csv").exists(), "nothing was streamed");
}

/// `replay` of a take whose region holds a rig but no table: the emulated
/// board refuses to arm (`NoTable`), and `replay` says so, exits 3 and
/// carries the reason in `--json`, as `emulate` does.
#[test]
fn replay_says_why_the_board_never_arms() {
    use marionette_host::take::{Event, EventKind, Take};
    let dir = tempfile::tempdir().unwrap();
    let rec = short_recording(dir.path());
    let frames =
        perform::frames(&marionette_host::import::csv::read_tracker_csv(&rec).unwrap()).unwrap();
    let take = Take {
        channels: 16,
        period_us: 1000,
        region: rig_without_table(),
        source: "no table".into(),
        events: perform::session(&frames)
            .unwrap()
            .into_iter()
            .map(|s| Event {
                time_us: s.time_us,
                kind: EventKind::Sent,
                data: s.bytes,
            })
            .collect(),
    };
    let path = dir.path().join("no_table.take");
    take.save(&path).unwrap();
    refused(
        &["replay", s(&path), "--emulated", "--fast"],
        "NoTable",
        "table region",
    );
}
