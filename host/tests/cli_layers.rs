//! Layers named in a rig file (#18): `[[layer]]` tables pick the tables
//! given with repeated `--tables`, their sources and masks, and the board
//! performs them. Errors name the file, the line and the field, whether the
//! rig file alone shows them or only the tables do.

use marionette_core::layer::{Root, Source};
use marionette_core::region::Region;
use marionette_host::{perform, rigfile};
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
        .current_dir(repo())
        .args(args)
        .output()
        .unwrap()
}

/// The walk on the legs, speed ramping, over a 3-parameter rest grid on
/// the right arm and half the torso.
const LAYERS: &str = r#"
[[layer]]
name = "walk"
table = 1
root = "drop"
fade_s = 0.1
params = [{ ramp = [0.9, 1.8, 1.5] }]
mask = { l_thigh = 1, l_shin = 1, l_foot = 1, r_thigh = 1.0, r_shin = 1, r_foot = 1 }

[[layer]]
name = "arm"
table = 0
weight = { param = 0 }
params = [{ param = 0 }, { param = 1 }, { param = 2 }]
mask = { r_upper_arm = 1, r_forearm = 1, torso = 0.5 }
"#;

/// humanoid16's rig text with `extra` appended, written to `dir/name`.
fn rig_with(dir: &Path, name: &str, extra: &str) -> (PathBuf, String) {
    let mut text = std::fs::read_to_string(repo().join("rigs/humanoid16.toml")).unwrap();
    text.push_str(extra);
    let path = dir.join(name);
    std::fs::write(&path, &text).unwrap();
    (path, text)
}

/// The 1-based line of the first line of `text` that starts with `start`
/// at or after line `from`.
fn line_of(text: &str, start: &str, from: usize) -> usize {
    text.lines()
        .enumerate()
        .skip(from.saturating_sub(1))
        .find(|(_, l)| l.trim_start().starts_with(start))
        .map(|(i, _)| i + 1)
        .unwrap()
}

/// The tables: 0 a rest grid over the three hand parameters, 1 the walk.
fn tables(dir: &Path) -> [PathBuf; 2] {
    let rig = rigfile::load(&repo().join("rigs/humanoid16.toml")).unwrap();
    let axes = [("x", -0.4, 0.2, 5), ("y", 0.0, 0.2, 5), ("z", -0.4, 0.2, 5)];
    let rest = dir.join("rest.bin");
    std::fs::write(&rest, perform::rest_grid(&rig, &axes).unwrap()).unwrap();
    let walk = dir.join("walk.bin");
    let o = marionette(&["build", "data/builds/walk_humanoid16.toml", "-o", s(&walk)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    [rest, walk]
}

#[test]
fn the_rig_file_reads_its_layers_as_written() {
    let dir = tempfile::tempdir().unwrap();
    let (path, _) = rig_with(dir.path(), "layered.toml", LAYERS);
    let rig = rigfile::load(&path).unwrap();
    let names = rig.segment_names();
    let at = |n: &str| names.iter().position(|s| s == n).unwrap();
    let [walk, arm] = &rig.layers[..] else {
        panic!("two layers: {:?}", rig.layers)
    };
    assert_eq!((walk.name.as_str(), walk.table), ("walk", 1));
    assert_eq!((walk.root, walk.fade_s), (Root::Drop, 0.1));
    assert_eq!(walk.weight, Source::Const(1.0), "the default weight");
    assert_eq!(
        walk.params,
        [Source::Ramp {
            from: 0.9,
            to: 1.8,
            seconds: 1.5
        }]
    );
    assert_eq!(walk.mask[at("l_shin")], 255);
    assert_eq!(walk.mask[at("r_upper_arm")], 0, "unnamed segments get 0");
    assert_eq!(arm.weight, Source::Param(0));
    assert_eq!(arm.fade_s, 0.25, "the default cross-fade");
    assert_eq!(arm.mask[at("torso")], 128, "0.5 in 1/255 steps, rounded");
    assert_eq!(
        arm.params,
        [Source::Param(0), Source::Param(1), Source::Param(2)]
    );
}

#[test]
fn emulate_performs_the_layers_the_rig_names_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let (layered, _) = rig_with(dir.path(), "layered.toml", LAYERS);
    let [rest, walk] = tables(dir.path());
    let recording = repo().join("data/recordings/reach_hdm05_007.csv");
    let run = |rig: &Path, tables: &[&Path], out: &str| {
        let out = dir.path().join(out);
        let mut args = vec!["emulate", "--rig", s(rig), "--recording", s(&recording)];
        for t in tables {
            args.extend(["--tables", s(t)]);
        }
        args.extend(["--out", s(&out), "--json"]);
        let o = marionette(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        (v, std::fs::read(out.join("region.bin")).unwrap())
    };
    let (v, region) = run(&layered, &[&rest, &walk], "layered");
    assert_eq!(v["mismatches"], 0, "{v}");
    assert_eq!(v["frames"], v["frame_outputs"], "{v}");
    // The region carries both tables and the layer list the rig names.
    let r = Region::parse(&region);
    let list = r.layers.expect("a layer list");
    assert_eq!(list.as_slice().len(), 2);
    assert_eq!(list.as_slice()[0].table, 1);
    assert_eq!(list.as_slice()[1].axis_count, 3);
    // The walk layer swings the thighs; the rest grid alone holds them.
    let (plain, _) = run(&repo().join("rigs/humanoid16.toml"), &[&rest], "plain");
    let rig = rigfile::load(&layered).unwrap();
    let servos = rig.desc().servos;
    let names = rig.segment_names();
    let thigh = usize::from(
        servos
            .iter()
            .find(|sv| names[usize::from(sv.segment)] == "l_thigh")
            .unwrap()
            .channel,
    );
    let swing = |v: &serde_json::Value| {
        let r = &v["ranges_us"][thigh];
        r[1].as_f64().unwrap() - r[0].as_f64().unwrap()
    };
    assert!(swing(&v) > 200.0, "the walk swings the thigh: {v}");
    assert!(swing(&plain) < swing(&v) / 4.0, "{plain}");
}

/// Runs `sim` with `rig` and the tables, expecting an error that contains
/// `want`.
fn refused(rig: &Path, tables: &[PathBuf], want: &str) {
    let dir = tables[0].parent().unwrap();
    let mut args = vec![
        "sim".to_string(),
        "--rig".into(),
        s(rig).into(),
        "--recording".into(),
        "data/recordings/reach_hdm05_007.csv".into(),
        "--out".into(),
        s(&dir.join("out")).into(),
    ];
    for t in tables {
        args.extend(["--tables".into(), s(t).into()]);
    }
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = marionette(&args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{want}: accepted");
    assert!(err.contains(want), "wanted {want:?} in: {err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn layer_errors_name_the_file_line_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let tables = tables(dir.path());
    let cases: [(&str, &str, &str, &str); 6] = [
        (
            "mask = { l_thigh = 1, l_shin = 1, l_foot = 1",
            "mask = { l_thig = 1, l_shin = 1, l_foot = 1",
            "mask = { l_thig",
            "layer[0].mask.l_thig: unknown segment \"l_thig\"",
        ),
        (
            "mask = { r_upper_arm = 1",
            "mask = { r_upper_arm = 2",
            "mask = { r_upper_arm",
            "layer[1].mask.r_upper_arm: 2 is not a weight 0 ..= 1",
        ),
        (
            "weight = { param = 0 }",
            "weight = \"loud\"",
            "weight",
            "layer[1].weight: expected a number, { param = N } or { ramp = [from, to, seconds] }",
        ),
        (
            "params = [{ ramp = [0.9, 1.8, 1.5] }]",
            "params = [{ ramp = [0.9, 1.8, 0] }]",
            "params",
            "layer[0].params[0]: a ramp is [from, to, seconds]",
        ),
        // Found only with the tables: an index beyond those given, and a
        // parameter count that is not the table's.
        (
            "table = 1",
            "table = 2",
            "table = 2",
            "layer[0].table: table 2 of the tables given, but 2 given",
        ),
        (
            "params = [{ param = 0 }, { param = 1 }, { param = 2 }]",
            "params = [{ param = 0 }, { param = 1 }]",
            "table = 0",
            "layer[1].params: ",
        ),
    ];
    for (i, (from, to, line_start, want)) in cases.into_iter().enumerate() {
        let (path, text) = rig_with(
            dir.path(),
            &format!("bad{i}.toml"),
            &LAYERS.replacen(from, to, 1),
        );
        let first = line_of(&text, "[[layer]]", 1);
        let layer = if want.starts_with("layer[1]") {
            line_of(&text, "[[layer]]", first + 1)
        } else {
            first
        };
        let line = line_of(&text, line_start, layer);
        refused(&path, &tables, &format!("{}:{line}: {want}", s(&path)));
    }
    let four = LAYERS.repeat(2);
    let (path, text) = rig_with(dir.path(), "four.toml", &four);
    let fourth = (0..4).fold(0, |at, _| line_of(&text, "[[layer]]", at + 1));
    refused(
        &path,
        &tables,
        &format!("{}:{fourth}: layer[3]: more than 3 layers", s(&path)),
    );
    // Two tables for a rig without layers: which one would it perform?
    refused(
        &repo().join("rigs/humanoid16.toml"),
        &tables,
        "2 tables given; a rig without [[layer]] tables performs one",
    );
}

#[test]
fn flash_lays_out_the_layered_region_and_the_board_would_arm_with_it() {
    let dir = tempfile::tempdir().unwrap();
    let (layered, _) = rig_with(dir.path(), "layered.toml", LAYERS);
    let [rest, walk] = tables(dir.path());
    let o = marionette(&[
        "flash",
        "--dry-run",
        "--rig",
        s(&layered),
        "--tables",
        s(&rest),
        "--tables",
        s(&walk),
    ]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{out}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        out.contains("(4 entries)") && out.contains("2 layers"),
        "{out}"
    );
    assert!(out.contains("the board arms"), "{out}");
    // Without --rig several blobs cannot be laid out.
    let o = marionette(&[
        "flash",
        "--dry-run",
        "--tables",
        s(&rest),
        "--tables",
        s(&walk),
    ]);
    assert!(!o.status.success());
    assert!(
        String::from_utf8_lossy(&o.stderr)
            .contains("without --rig, --tables takes one region image"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}
