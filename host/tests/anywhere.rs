//! Works from anywhere (#20 item 8): the built `marionette` binary, run in a
//! temporary folder outside the repository with neither cargo on `PATH` nor
//! a cached bundle (a fresh `TMPDIR`), runs the main job (`demo`: the
//! firmware, rig, spec, mocap and recording all come from inside the
//! binary) and solves a rig named `humanoid16`. A `rigs/<name>.toml` in the
//! current folder comes before the built-in rig of that name.

use std::path::Path;
use std::process::{Command, Output};

/// `marionette args` in `cwd`, with `PATH` holding only QEMU's folder (no
/// cargo) and the bundle written under `tmp`.
fn marionette(cwd: &Path, tmp: &Path, args: &[&str]) -> Output {
    let qemu = marionette_host::qemu::check_qemu().expect("qemu-system-arm is installed");
    let path = qemu.parent().expect("QEMU's folder");
    Command::new(env!("CARGO_BIN_EXE_marionette"))
        .args(args)
        .current_dir(cwd)
        .env("PATH", path)
        .env("TMPDIR", tmp)
        .env_remove("CARGO")
        .env_remove("CARGO_MANIFEST_DIR")
        .output()
        .unwrap()
}

fn text(out: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// A folder outside the repository.
fn elsewhere() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    assert!(!dir.path().starts_with(repo.canonicalize().unwrap()));
    dir
}

const GOALS: &str =
    r#"{"goals": [{"segment": "r_forearm", "target": [-0.1, 0.6, 0.2], "weight": 10}]}"#;

#[test]
fn the_main_job_runs_from_a_folder_outside_the_repository() {
    let (cwd, tmp) = (elsewhere(), elsewhere());
    let out = marionette(cwd.path(), tmp.path(), &["demo", "--json"]);
    let all = text(&out);
    assert!(out.status.success(), "{all}");
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).expect(&all);
    assert_eq!(summary["arm"], "Ok", "{all}");
    assert_eq!(summary["mismatches"], 0, "{all}");
    let frames = summary["frames_in"].as_u64().unwrap();
    assert!(frames > 2000, "{all}");
    assert_eq!(summary["frames_out"].as_u64(), Some(frames), "{all}");
    // Its outputs land in the current folder, the bundle in TMPDIR.
    for file in ["reach_humanoid16.bin", "region.bin", "servo_emulated.csv"] {
        assert!(cwd.path().join("out").join(file).is_file(), "{file}: {all}");
    }
    let bundle = std::fs::read_dir(tmp.path()).unwrap().next().unwrap();
    let bundle = bundle.unwrap().path();
    assert!(bundle.join("firmware/perform.elf").is_file());
    assert!(bundle.join("data/builds/reach_humanoid16.toml").is_file());
}

#[test]
fn rig_names_resolve_from_the_folder_then_the_built_in_rigs() {
    let (cwd, tmp) = (elsewhere(), elsewhere());
    std::fs::write(cwd.path().join("g.json"), GOALS).unwrap();
    let solve = ["solve", "humanoid16", "--goals", "g.json"];

    // No rigs/ here: the built-in humanoid16.
    let out = marionette(cwd.path(), tmp.path(), &solve);
    let all = text(&out);
    assert!(out.status.success(), "{all}");
    assert!(all.starts_with("humanoid16: "), "{all}");
    assert!(all.contains("1 of 1 goal(s) met"), "{all}");

    // A rigs/humanoid16.toml here comes first (renamed, to tell them apart).
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let rig = std::fs::read_to_string(repo.join("rigs/humanoid16.toml")).unwrap();
    let local = rig.replacen("name = \"humanoid16\"", "name = \"local16\"", 1);
    assert_ne!(local, rig);
    std::fs::create_dir(cwd.path().join("rigs")).unwrap();
    std::fs::write(cwd.path().join("rigs/humanoid16.toml"), local).unwrap();
    let out = marionette(cwd.path(), tmp.path(), &solve);
    let all = text(&out);
    assert!(out.status.success(), "{all}");
    assert!(all.starts_with("local16: "), "{all}");

    // An unknown name still names what is missing.
    let out = marionette(
        cwd.path(),
        tmp.path(),
        &["solve", "nobody", "--goals", "g.json"],
    );
    assert!(!out.status.success());
    assert!(text(&out).contains("nobody"), "{}", text(&out));
}

#[test]
fn calibrate_refuses_to_write_into_a_built_in_rig() {
    let (cwd, tmp) = (elsewhere(), elsewhere());
    let args = ["calibrate", "--rig", "humanoid16", "--channel", "0"];
    let out = marionette(cwd.path(), tmp.path(), &args);
    assert!(!out.status.success());
    assert!(
        text(&out).contains("built into marionette"),
        "{}",
        text(&out)
    );
}

#[test]
fn a_bundle_folder_name_taken_by_something_else_is_not_used() {
    let (cwd, tmp) = (elsewhere(), elsewhere());
    std::fs::write(cwd.path().join("g.json"), GOALS).unwrap();
    // This build's shared folder name, taken by a plain file.
    let name = marionette_host::bundle::folder().file_name().unwrap();
    assert!(name.to_str().unwrap().starts_with("marionette-"));
    let taken = tmp.path().join(name);
    std::fs::write(&taken, "not a folder").unwrap();
    let out = marionette(
        cwd.path(),
        tmp.path(),
        &["solve", "humanoid16", "--goals", "g.json"],
    );
    assert!(out.status.success(), "{}", text(&out));
    assert_eq!(std::fs::read_to_string(&taken).unwrap(), "not a folder");
    // A private folder beside it holds the rig instead.
    let private: Vec<_> = std::fs::read_dir(tmp.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.join("rigs/humanoid16.toml").is_file())
        .collect();
    assert_eq!(private.len(), 1, "{private:?}");
}
