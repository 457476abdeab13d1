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
    for (w, h) in [("65536", "65536"), ("100000", "100000"), ("8192", "8193"), ("8192", "8192")] {
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
        &["plot", s(&csv), "--width", "65536", "--height", "65536", "-o", s(&png)],
        &["out of range"],
    );
    // The longest side itself draws.
    let o = capped(
        512,
        &["render", "--width", "8192", "--height", "200", "-o", s(&png)],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let _ = repo();
}
