//! Outputs are safe (#20 item 7): every command writes through
//! `marionette_host::save` (a temporary file renamed when complete), makes
//! missing folders, never writes over one of its inputs, and a run that
//! fails leaves nothing behind.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn marionette(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_marionette"))
        .args(args)
        .output()
        .unwrap()
}

fn ok(args: &[&str]) {
    let o = marionette(args);
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// Exit 1 with every word of `words` on stderr.
fn refused(args: &[&str], words: &[&str]) {
    let o = marionette(args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
    for w in words {
        assert!(err.contains(w), "{args:?}: missing {w:?} in {err}");
    }
}

/// Every file under `dir`, relative, sorted (temporary files included).
fn files(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(p.strip_prefix(dir).unwrap().display().to_string());
            }
        }
    }
    out.sort();
    out
}

/// A one-segment, one-axis example set and its spec.
fn small_spec(dir: &Path) -> PathBuf {
    std::fs::write(
        dir.join("set.json"),
        r#"{"segments": ["root"], "axes": [{"name": "a", "min": 0, "max": 1, "count": 2}],
            "examples": [{"params": [0], "pose": [[0, 1, 0, 1, 0, 0, 0]]},
                         {"params": [1], "pose": [[0, 2, 0, 1, 0, 0, 0]]}]}"#,
    )
    .unwrap();
    let spec = dir.join("spec.toml");
    std::fs::write(&spec, "examples = \"set.json\"\n").unwrap();
    spec
}

#[test]
fn build_makes_folders_and_never_overwrites_its_spec() {
    let dir = tempfile::tempdir().unwrap();
    let spec = small_spec(dir.path());
    let before = std::fs::read(&spec).unwrap();
    refused(
        &["build", s(&spec), "-o", s(&spec), "--quiet"],
        &["spec.toml", "is an input"],
    );
    // The same file by another path, and the example set it reads.
    let other = dir.path().join(".").join("spec.toml");
    refused(
        &["build", s(&spec), "-o", s(&other), "--quiet"],
        &["is an input"],
    );
    let set = dir.path().join("set.json");
    refused(
        &["build", s(&spec), "-o", s(&set), "--quiet"],
        &["is an input"],
    );
    assert_eq!(std::fs::read(&spec).unwrap(), before);
    let out = dir.path().join("new/deeper/t.bin");
    ok(&["build", s(&spec), "-o", s(&out), "--quiet"]);
    assert_eq!(
        files(&dir.path().join("new")),
        ["deeper/t.bin"],
        "one file, no temporary left"
    );
}

#[test]
fn pictures_make_folders_and_never_overwrite_an_input() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("a/b/pose.png");
    ok(&["render", "-o", s(&png), "--width", "320", "--height", "240"]);
    let csv = dir.path().join("c.csv");
    std::fs::write(&csv, "time_s,a\n0,1\n1,2\n").unwrap();
    let plot = dir.path().join("c/d/plot.svg");
    ok(&["plot", s(&csv), "-o", s(&plot)]);
    assert_eq!(files(&dir.path().join("a")), ["b/pose.png"]);
    assert_eq!(files(&dir.path().join("c")), ["d/plot.svg"]);
    // The CSV as the picture: refused (a .csv is no picture format, so
    // name it .svg to reach the input check).
    let csv_svg = dir.path().join("c.svg");
    std::fs::write(&csv_svg, "time_s,a\n0,1\n1,2\n").unwrap();
    refused(&["plot", s(&csv_svg), "-o", s(&csv_svg)], &["is an input"]);
    assert_eq!(
        std::fs::read_to_string(&csv_svg).unwrap(),
        "time_s,a\n0,1\n1,2\n"
    );
    let goals = dir.path().join("goals.svg");
    std::fs::write(&goals, "[]").unwrap();
    refused(
        &["render", "--goals", s(&goals), "-o", s(&goals)],
        &["is an input"],
    );
    assert_eq!(std::fs::read_to_string(&goals).unwrap(), "[]");
}

#[test]
fn a_failed_emulation_leaves_nothing_behind() {
    let dir = tempfile::tempdir().unwrap();
    let rig = repo().join("rigs/humanoid16.toml");
    let rec = dir.path().join("rec.csv");
    std::fs::write(
        &rec,
        "time_us,sensor,x,y,z,qw,qx,qy,qz\n0,0,0,1,0,1,0,0,0\n",
    )
    .unwrap();
    let out = dir.path().join("out");
    // --raw-servo over the recording: refused before the board runs.
    refused(
        &[
            "emulate",
            "--rig",
            s(&rig),
            "--recording",
            s(&rec),
            "--out",
            s(&out),
            "--raw-servo",
            s(&rec),
        ],
        &["rec.csv", "is an input"],
    );
    assert!(!out.exists());
    // No table: the board refuses (exit 3); no region.bin, no curves.
    let raw = dir.path().join("raw.bin");
    let o = marionette(&[
        "emulate",
        "--rig",
        s(&rig),
        "--recording",
        s(&rec),
        "--out",
        s(&out),
        "--raw-servo",
        s(&raw),
    ]);
    assert_eq!(
        o.status.code(),
        Some(3),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert_eq!(files(&out), Vec::<String>::new());
    assert!(!raw.exists());
}
