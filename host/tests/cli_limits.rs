//! Limits before work (#20): every size limit is checked before memory is
//! taken. Each oversized input is run with its address space capped (`ulimit
//! -v`) far below what the work would have taken, and must end with a clear
//! error naming the limit (exit 1), never a panic (101) or an abort.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Runs `marionette args` with at most `mib` MiB of address space.
fn capped(mib: u64, args: &[&str]) -> Output {
    Command::new("sh")
        .arg("-c")
        .arg(format!("ulimit -v {}; exec \"$0\" \"$@\"", mib * 1024))
        .arg(env!("CARGO_BIN_EXE_marionette"))
        .args(args)
        .output()
        .unwrap()
}

/// Asserts a refusal (exit 1) whose message holds every one of `words`.
fn refused(mib: u64, args: &[&str], words: &[&str]) -> String {
    let o = capped(mib, args);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
    for w in words {
        assert!(err.contains(w), "{args:?}: missing {w:?} in {err}");
    }
    err
}

/// Pictures: 65536² used to panic inside plotters, 100000² to take 4.2 GB.
#[test]
fn picture_sizes_are_bounded_before_drawing() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("p.png");
    for (w, h) in [
        ("65536", "65536"),
        ("100000", "100000"),
        ("8192", "8193"),
        ("8192", "8192"),
    ] {
        refused(
            256,
            &["render", "--width", w, "--height", h, "-o", s(&png)],
            &["out of range", "8192"],
        );
    }
    assert!(!png.exists());
    let csv = dir.path().join("c.csv");
    std::fs::write(&csv, "time_s,a\n0,1\n1,2\n").unwrap();
    refused(
        256,
        &[
            "plot",
            s(&csv),
            "--width",
            "65536",
            "--height",
            "65536",
            "-o",
            s(&png),
        ],
        &["out of range"],
    );
    // The longest side itself draws.
    let o = capped(
        512,
        &[
            "render",
            "--width",
            "8192",
            "--height",
            "200",
            "-o",
            s(&png),
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// A bundled spec with its relative paths made absolute and `edits`
/// applied, written into `dir`.
fn spec(dir: &Path, name: &str, edits: &[(&str, &str)]) -> PathBuf {
    let builds = repo().join("data/builds");
    let mut text = std::fs::read_to_string(builds.join(name)).unwrap();
    text = text
        .replace("\"../../", &format!("\"{}/", repo().display()))
        .replace("\"../", &format!("\"{}/", repo().join("data").display()));
    for (from, to) in edits {
        assert!(text.contains(from), "{name} has no {from:?}");
        text = text.replacen(from, to, 1);
    }
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// `build`: a million frames per phase took 55 s and 10 GB; a 1000 × 1000
/// grid built a 72 MB table no board holds. Both are refused from the spec
/// alone, with the line, the field and the sizes.
#[test]
fn build_refuses_tables_no_board_holds_before_reading_mocap() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("t.bin");
    let frames = spec(
        dir.path(),
        "walk_humanoid16.toml",
        &[("frames = 64", "frames = 1000000")],
    );
    refused(
        64,
        &["build", s(&frames), "-o", s(&out)],
        &["walk_humanoid16.toml:", "motion.frames", "65535"],
    );
    let grid = spec(
        dir.path(),
        "reach_humanoid16.toml",
        &[("count = 4", "count = 1000"), ("count = 9", "count = 1000")],
    );
    refused(
        64,
        &["build", s(&grid), "-o", s(&out)],
        &[
            "reach_humanoid16.toml:",
            "count",
            "1000 × 1000 × 6 grid samples × 13 segments × 12 B = 936000000 B",
            "emulated 1048576 B, blackpill 262144 B",
        ],
    );
    // 40 × 30 × 6 × 13 × 12 = 1,123,200 B: just over the emulated board's
    // 1 MiB; 20 × 30 × 6 × 13 × 12 = 561,600 B fits it but not the Black Pill.
    let mid = spec(
        dir.path(),
        "reach_humanoid16.toml",
        &[("count = 4", "count = 20"), ("count = 9", "count = 30")],
    );
    refused(
        64,
        &["build", s(&mid), "-o", s(&out), "--board", "blackpill"],
        &["561600 B", "blackpill 262144 B"],
    );
    assert!(!out.exists());
}

/// A 100,000-segment rig took 600 MB to be refused; now the count is
/// checked before the TOML is parsed, and the file size before it is read.
#[test]
fn rig_files_of_too_many_segments_are_refused_before_parsing() {
    let dir = tempfile::tempdir().unwrap();
    let mut text = String::from(
        "name = \"big\"\nframe_period_us = 1000\nfailsafe_timeout_ms = 100\n\
         [[segment]]\nname = \"s0\"\n",
    );
    for i in 1..65 {
        text.push_str(&format!(
            "[[segment]]\nname = \"s{i}\"\nparent = \"s{}\"\norigin = [0, 0.01, 0]\n",
            i - 1
        ));
    }
    let rig = dir.path().join("big.toml");
    std::fs::write(&rig, &text).unwrap();
    let goals = dir.path().join("g.json");
    std::fs::write(&goals, "{\"goals\": []}").unwrap();
    // Lines 1-3 the rig, 4-5 the root; segment i ≥ 1 starts on line
    // 6 + 4 (i − 1): index 64, the 65th, on line 258.
    refused(
        64,
        &["solve", s(&rig), "--goals", s(&goals)],
        &["big.toml:258: segment[64]", "more than 64"],
    );
    let filler = "# padding\n".repeat(200_000);
    std::fs::write(&rig, format!("{text}{filler}")).unwrap();
    refused(
        64,
        &["solve", s(&rig), "--goals", s(&goals)],
        &["big.toml", "a rig file is at most 1048576"],
    );
}

/// `record --rate-hz 1000000` took 23 s and 547 MB; the rate and the
/// recording's size are checked before anything is computed, and a
/// repeated sensor id or an overflowing start time is refused.
#[test]
fn record_checks_rate_length_and_ids_before_computing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("take.csv");
    let data = repo().join("data/hdm05_bk");
    let clip = data.join("HDM_bk_grabHighR_005_120.amc");
    let asf = data.join("HDM_bk.asf");
    let base = ["record", s(&clip), "--skeleton", s(&asf), "-o", s(&out)];
    let with = |more: &[&'static str]| -> Vec<String> {
        base.iter()
            .map(|a| a.to_string())
            .chain(more.iter().map(|a| a.to_string()))
            .collect()
    };
    let cases: [(&[&str], &[&str]); 4] = [
        (&["--rate-hz", "1000000"], &["--rate-hz", "10000"]),
        (
            &["--sensor", "0=root", "--sensor", "0=lhand"],
            &["--sensor 0", "twice"],
        ),
        (&["--sensor", "16=root"], &["0..16"]),
        (
            &["--start-us", "18446744073709551000"],
            &["--start-us", "64 bits"],
        ),
    ];
    for (more, words) in cases {
        let args = with(more);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        refused(64, &args, words);
    }
    assert!(!out.exists(), "nothing written");
    // The clip itself is never the output.
    let args = ["record", s(&clip), "--skeleton", s(&asf), "-o", s(&asf)];
    refused(64, &args, &["is an input"]);
}
