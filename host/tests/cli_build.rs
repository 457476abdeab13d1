//! CLI contract tests of `marionette build`, `inspect` and `synth`: exact
//! JSON keys, a tiny JSON example set built end to end and synthesized back
//! (checked against the input numbers and the documented quantization
//! bound, not against the code under test), a tiny mocap motion table, and
//! located errors for bad inputs.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::{Value, json};

fn marionette(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_marionette"))
        .args(args)
        .output()
        .expect("run marionette")
}

fn ok(args: &[&str]) -> String {
    let out = marionette(args);
    assert!(
        out.status.success(),
        "marionette {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("utf-8 stdout")
}

fn fails(args: &[&str]) -> String {
    let out = marionette(args);
    assert!(!out.status.success(), "marionette {args:?} should fail");
    String::from_utf8(out.stderr).expect("utf-8 stderr")
}

fn keys(v: &Value) -> BTreeSet<&str> {
    v.as_object()
        .expect("object")
        .keys()
        .map(String::as_str)
        .collect()
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// The pose of the tiny set at grid point (x, y): two segments whose
/// positions and rotations differ at every grid point.
fn tiny_pose(x: f64, y: f64) -> Vec<[f64; 7]> {
    let half = 0.3 * x + 0.2 * y;
    let (sin, cos) = half.sin_cos();
    vec![
        [x, 1.0 + y, 0.5 * x * y, cos, 0.0, sin, 0.0],
        [x + 0.25, 1.5 - y, -0.2, cos, sin, 0.0, 0.0],
    ]
}

const XS: [f64; 3] = [-0.5, 0.0, 0.5];
const YS: [f64; 2] = [0.0, 0.4];

/// A 3 × 2 grid with one example on every grid point, plus two off-grid.
fn tiny_set() -> Value {
    let mut examples = Vec::new();
    for &y in &YS {
        for &x in &XS {
            examples.push(json!({"params": [x, y], "pose": tiny_pose(x, y)}));
        }
    }
    examples.push(json!({"params": [0.2, 0.1], "pose": tiny_pose(0.2, 0.1)}));
    examples.push(json!({"params": [-0.3, 0.3], "pose": tiny_pose(-0.3, 0.3)}));
    json!({
        "segments": ["hips", "hand"],
        "axes": [
            {"name": "x", "min": -0.5, "max": 0.5, "count": 3, "cyclic": false, "cubic": false},
            {"name": "y", "min": 0.0, "max": 0.4, "count": 2}
        ],
        "examples": examples
    })
}

fn build_tiny(dir: &Path) -> PathBuf {
    let set = dir.join("tiny.json");
    std::fs::write(&set, serde_json::to_string_pretty(&tiny_set()).unwrap()).unwrap();
    let blob = dir.join("tiny.bin");
    ok(&["build", s(&set), "-o", s(&blob), "--quiet"]);
    blob
}

/// Rotation angle between two `[w, x, y, z]` quaternions (robust to their
/// `f32` norms: `2·atan2(|v|, |w|)` of the relative rotation).
fn angle(a: &[f64], b: &[f64]) -> f64 {
    let (aw, av) = (a[0], [-a[1], -a[2], -a[3]]);
    let (bw, bv) = (b[0], [b[1], b[2], b[3]]);
    let w = aw * bw - (av[0] * bv[0] + av[1] * bv[1] + av[2] * bv[2]);
    let v = [
        aw * bv[0] + bw * av[0] + av[1] * bv[2] - av[2] * bv[1],
        aw * bv[1] + bw * av[1] + av[2] * bv[0] - av[0] * bv[2],
        aw * bv[2] + bw * av[2] + av[0] * bv[1] - av[1] * bv[0],
    ];
    2.0 * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        .sqrt()
        .atan2(w.abs())
}

#[test]
fn tiny_example_set_builds_and_synthesizes_its_examples_back() {
    let dir = tempfile::tempdir().unwrap();
    let blob = build_tiny(dir.path());
    // The documented bounds: positions within 0.51 LSB of the smallest
    // scale that holds the largest coordinate (|y| = 1.5 here), rotations
    // within 1.75e-4 rad. Computed here from the input, not read back.
    let scale = 1.5 / 32767.0;
    let position_bound = 0.51 * scale + 1e-7;
    let rotation_bound = 1.75e-4 + 2e-6;
    for &y in &YS {
        for &x in &XS {
            let at = format!("{x},{y}");
            let out: Value =
                serde_json::from_str(&ok(&["synth", s(&blob), "--at", &at, "--json"])).unwrap();
            assert_eq!(out["duration"], Value::Null);
            let segs = out["segments"].as_array().unwrap();
            assert_eq!(segs.len(), 2);
            for (seg, (name, want)) in segs
                .iter()
                .zip(["hips", "hand"].iter().zip(tiny_pose(x, y)))
            {
                assert_eq!(seg["name"], *name);
                let p: Vec<f64> = serde_json::from_value(seg["position"].clone()).unwrap();
                let q: Vec<f64> = serde_json::from_value(seg["rotation"].clone()).unwrap();
                for k in 0..3 {
                    assert!(
                        (p[k] - want[k]).abs() <= position_bound,
                        "{name} at {at}: {p:?} vs {want:?}"
                    );
                }
                assert!(
                    angle(&q, &want[3..]) <= rotation_bound,
                    "{name} at {at}: {q:?} vs {want:?}"
                );
            }
        }
    }
}

#[test]
fn examples_export_round_trips_the_contract() {
    let dir = tempfile::tempdir().unwrap();
    let set = dir.path().join("tiny.json");
    std::fs::write(&set, tiny_set().to_string()).unwrap();
    let out = dir.path().join("out.json");
    ok(&["build", s(&set), "--examples-out", s(&out), "--quiet"]);
    let back: Value = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let orig = tiny_set();
    assert_eq!(
        keys(&back),
        BTreeSet::from(["segments", "axes", "examples"])
    );
    assert_eq!(back["segments"], orig["segments"]);
    assert_eq!(back["examples"].as_array().unwrap().len(), 8);
    for (b, o) in back["examples"]
        .as_array()
        .unwrap()
        .iter()
        .zip(orig["examples"].as_array().unwrap())
    {
        assert_eq!(keys(b), BTreeSet::from(["params", "pose"]));
        assert_eq!(b["params"], o["params"]);
        let (bp, op) = (b["pose"].as_array().unwrap(), o["pose"].as_array().unwrap());
        for (x, y) in bp
            .iter()
            .flat_map(|v| v.as_array().unwrap())
            .zip(op.iter().flat_map(|v| v.as_array().unwrap()))
        {
            assert!((x.as_f64().unwrap() - y.as_f64().unwrap()).abs() < 1e-12);
        }
    }
}

#[test]
fn holdout_reports_each_held_out_group() {
    let dir = tempfile::tempdir().unwrap();
    let set = dir.path().join("tiny.json");
    std::fs::write(&set, tiny_set().to_string()).unwrap();
    // Example 6 (params 0.2, 0.1) held out: the other seven build the table.
    let out: Value = serde_json::from_str(&ok(&[
        "build",
        s(&set),
        "--holdout",
        "examples[6]",
        "--json",
        "--quiet",
    ]))
    .unwrap();
    let rows = out["holdout"].as_array().unwrap();
    assert_eq!(rows.len(), 1);
    assert_eq!(rows[0]["clip"], "examples[6]");
    assert_eq!(rows[0]["examples"], 1);
    let e = rows[0]["mean_joint"].as_f64().unwrap();
    assert!(e.is_finite() && e >= 0.0, "{e}");
    let e = fails(&["build", s(&set), "--holdout", "nothing"]);
    assert!(e.contains("no clip matches"), "{e}");
}

#[test]
fn synth_json_has_exactly_the_contract_keys() {
    let dir = tempfile::tempdir().unwrap();
    let blob = build_tiny(dir.path());
    let out: Value =
        serde_json::from_str(&ok(&["synth", s(&blob), "--at", "0.1,0.2", "--json"])).unwrap();
    assert_eq!(
        keys(&out),
        BTreeSet::from(["segments", "duration", "clamped", "projected"])
    );
    assert_eq!(out["clamped"], false);
    // Outside the axes: clamped, and the output says so.
    let far: Value =
        serde_json::from_str(&ok(&["synth", s(&blob), "--at", "9,0.2", "--json"])).unwrap();
    assert_eq!(far["clamped"], true);
    for seg in out["segments"].as_array().unwrap() {
        assert_eq!(keys(seg), BTreeSet::from(["name", "position", "rotation"]));
        assert_eq!(seg["position"].as_array().unwrap().len(), 3);
        assert_eq!(seg["rotation"].as_array().unwrap().len(), 4);
    }
    // Negative parameters parse; a wrong count is an error naming the axes.
    ok(&["synth", s(&blob), "--at", "-0.4,0.1", "--json"]);
    let e = fails(&["synth", s(&blob), "--at", "0.1"]);
    assert!(e.contains("2 parameter axes (x, y)"), "{e}");
    let e = fails(&["synth", s(&blob), "--at", "0.1,0.2", "--phase", "0.5"]);
    assert!(e.contains("--phase"), "{e}");
}

#[test]
fn inspect_json_has_exactly_the_contract_keys() {
    let dir = tempfile::tempdir().unwrap();
    let blob = build_tiny(dir.path());
    let out: Value = serde_json::from_str(&ok(&["inspect", s(&blob), "--json"])).unwrap();
    let expected = BTreeSet::from([
        "bytes",
        "version",
        "kind",
        "phases",
        "rig_hash",
        "axes",
        "segments",
        "sample_bytes",
        "pose_bytes",
        "grid_samples",
        "param_samples",
        "cells",
        "valid_cells",
        "sections",
        "position_scale",
        "position_bound_m",
        "rotation_bound_rad",
        "durations",
    ]);
    assert_eq!(keys(&out), expected);
    let axis_keys = BTreeSet::from(["name", "min", "max", "step", "count", "cyclic", "cubic"]);
    for a in out["axes"].as_array().unwrap() {
        assert_eq!(keys(a), axis_keys);
    }
    assert_eq!(
        keys(&out["sections"]),
        BTreeSet::from(["header", "samples", "valid", "durations", "crc"])
    );
    // Sizes, checked against the file and the format's arithmetic.
    let len = std::fs::metadata(&blob).unwrap().len();
    assert_eq!(out["bytes"], json!(len));
    assert_eq!(out["kind"], "grid");
    assert_eq!(out["phases"], Value::Null);
    assert_eq!(out["sample_bytes"], 12);
    assert_eq!(out["pose_bytes"], 24);
    assert_eq!(out["grid_samples"], 6);
    assert_eq!(out["sections"]["samples"], 6 * 2 * 12);
    assert_eq!(out["cells"], 2);
    assert_eq!(out["valid_cells"], 2);
    assert_eq!(out["segments"], json!(["hips", "hand"]));
    let bound = out["position_bound_m"].as_f64().unwrap();
    assert!(bound > 0.0 && bound <= 0.0005, "{bound}");
    // The text form names the same facts.
    let text = ok(&["inspect", s(&blob)]);
    assert!(text.contains("valid cells: 2 of 2"), "{text}");
}

#[test]
fn bad_example_sets_name_file_line_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let set = dir.path().join("bad.json");
    let text = serde_json::to_string_pretty(&tiny_set()).unwrap().replacen(
        "\"params\": [\n        0.2,",
        "\"params\": [\n        \"a\",",
        1,
    );
    assert!(text.contains("\"a\""), "the replacement must apply");
    std::fs::write(&set, &text).unwrap();
    let line = text.lines().position(|l| l.contains("\"a\"")).unwrap() + 1;
    let e = fails(&["build", s(&set), "-o", s(&dir.path().join("x.bin"))]);
    let want = format!("{}:{line}: examples[6]:", set.display());
    assert!(e.contains(&want), "expected {want:?} in {e}");
    // Wrong pose length: the example's line, and the field.
    let mut v = tiny_set();
    v["examples"][2]["pose"].as_array_mut().unwrap().pop();
    let text = serde_json::to_string_pretty(&v).unwrap();
    std::fs::write(&set, &text).unwrap();
    let e = fails(&["build", s(&set), "-o", s(&dir.path().join("x.bin"))]);
    assert!(e.contains("examples[2].pose: expected 2 segments"), "{e}");
    assert!(e.contains(&format!("{}:", set.display())), "{e}");
}

#[test]
fn bad_specs_name_file_line_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let spec = dir.path().join("spec.toml");
    let write = |t: &str| std::fs::write(&spec, t).unwrap();
    let out = s(&dir.path().join("x.bin")).to_owned();
    write("kind = \"grid\"\nexamples = \"set.json\"\n[resample]\nmethod = \"kriging\"\n");
    let e = fails(&["build", s(&spec), "-o", &out]);
    assert!(
        e.contains(&format!("{}:4: resample.method:", spec.display())),
        "{e}"
    );
    write("kind = \"grid\"\n[mocap]\nevery = 0\n[[clip]]\nfile = \"a.bvh\"\n");
    let e = fails(&["build", s(&spec), "-o", &out]);
    assert!(
        e.contains(&format!("{}:3: mocap.every:", spec.display())),
        "{e}"
    );
    write(
        "kind = \"grid\"\n[mocap]\n[[clip]]\nfile = \"a.bvh\"\n[[axis]]\nname = \"x\"\nsegment = \"hand\"\ncomponent = \"q\"\ncount = 3\n",
    );
    let e = fails(&["build", s(&spec), "-o", &out]);
    assert!(
        e.contains(&format!("{}:8: axis[0].component:", spec.display())),
        "{e}"
    );
    // A missing example set names the file it could not read.
    write("examples = \"missing.json\"\n");
    let e = fails(&["build", s(&spec), "-o", &out]);
    assert!(e.contains("missing.json:0: file: cannot read"), "{e}");
}

/// A two-joint BVH: the root walks along +Z at `speed` m/s (CMU units are
/// not used: scale 1) while the child swings about X with a 1 s period.
fn walk_bvh(speed: f64, frames: usize) -> String {
    let dt = 0.05;
    let mut s = String::from(
        "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\n  JOINT Leg\n  {\n    OFFSET 0 -0.5 0\n    CHANNELS 3 Zrotation Yrotation Xrotation\n    End Site\n    {\n      OFFSET 0 -0.5 0\n    }\n  }\n}\nMOTION\n",
    );
    s += &format!("Frames: {frames}\nFrame Time: {dt}\n");
    for f in 0..frames {
        let t = f as f64 * dt;
        let swing = 30.0 * (std::f64::consts::TAU * t).sin();
        s += &format!("0 1 {} 0 0 0 0 0 {swing}\n", speed * t);
    }
    s
}

#[test]
fn tiny_motion_table_from_mocap() {
    let dir = tempfile::tempdir().unwrap();
    // 1 s cycles: frames 0..=20 at 20 fps.
    std::fs::write(dir.path().join("slow.bvh"), walk_bvh(1.0, 30)).unwrap();
    std::fs::write(dir.path().join("fast.bvh"), walk_bvh(2.0, 30)).unwrap();
    let spec = dir.path().join("walk.toml");
    std::fs::write(
        &spec,
        "kind = \"clips\"\n[mocap]\nscale = 1.0\n[[clip]]\nfile = \"slow.bvh\"\ncut = [0, 20]\n[[clip]]\nfile = \"fast.bvh\"\ncut = [0, 20]\n[[axis]]\nname = \"speed\"\nmeasure = \"speed\"\nmin = 1.0\nmax = 2.0\ncount = 2\n[motion]\nframes = 10\nlooping = true\nseam_window = 2\n",
    )
    .unwrap();
    let blob = dir.path().join("walk.bin");
    ok(&["build", s(&spec), "-o", s(&blob), "--quiet"]);
    let info: Value = serde_json::from_str(&ok(&["inspect", s(&blob), "--json"])).unwrap();
    assert_eq!(info["kind"], "clips");
    assert_eq!(info["phases"], 1);
    assert_eq!(info["axes"][1]["name"], "phase");
    assert_eq!(info["axes"][1]["cyclic"], true);
    // Both clips last 20 frames × 0.05 s = 1 s.
    assert!(
        (info["durations"]["min"].as_f64().unwrap() - 1.0).abs() < 1e-6,
        "{info}"
    );
    // Phase 0.2 is stored frame 2 of 10, t = 0.2 s: the leg has swung
    // 30°·sin(2π·0.2) about X (travel removed, so the root stays at x = z =
    // 0, 1 m up).
    let out: Value = serde_json::from_str(&ok(&[
        "synth",
        s(&blob),
        "--at",
        "1.5",
        "--phase",
        "0.2",
        "--json",
    ]))
    .unwrap();
    assert_eq!(
        keys(&out),
        BTreeSet::from(["segments", "duration", "clamped", "projected", "travel"])
    );
    assert!(
        (out["duration"].as_f64().unwrap() - 1.0).abs() < 1e-5,
        "{out}"
    );
    // The loop's root travel per cycle: 1.5 m/s for 1 s along +Z (the
    // heading frame's direction of travel), nothing up or sideways.
    let travel: Vec<f64> = out["travel"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert!(
        travel[0].abs() < 1e-4 && travel[1].abs() < 1e-4 && (travel[2] - 1.5).abs() < 1e-3,
        "{travel:?}"
    );
    let leg: Vec<f64> = serde_json::from_value(out["segments"][1]["rotation"].clone()).unwrap();
    let half = (30.0 * (0.4 * std::f64::consts::PI).sin() / 2.0).to_radians();
    let want = [half.cos(), half.sin(), 0.0, 0.0];
    assert!(angle(&leg, &want) < 1e-3, "{leg:?}");
    let hips: Vec<f64> = serde_json::from_value(out["segments"][0]["position"].clone()).unwrap();
    assert!(
        (hips[1] - 1.0).abs() < 1e-3 && hips[0].abs() < 1e-3,
        "{hips:?}"
    );
}

/// The shipped reach spec (humanoid16), its paths made absolute, with
/// `edit` applied, written into `dir`.
fn reach_spec(dir: &Path, edit: impl Fn(&str) -> String) -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .canonicalize()
        .unwrap();
    let text = std::fs::read_to_string(root.join("data/builds/reach_humanoid16.toml")).unwrap();
    let text = edit(&text)
        .replace("\"../../", &format!("\"{}/", root.display()))
        .replace("\"../", &format!("\"{}/data/", root.display()));
    let path = dir.join("reach.toml");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn build_says_whether_the_rig_keeps_its_period_with_the_table() {
    let dir = tempfile::tempdir().unwrap();
    let blob = dir.path().join("t.bin");
    let deadline = |spec: &Path| {
        let args = ["build", s(spec), "-o", s(&blob), "--quiet", "--json"];
        let out = marionette(&args);
        assert!(out.status.success(), "{args:?}");
        let doc: Value = serde_json::from_slice(&out.stdout).unwrap();
        let stderr = String::from_utf8(out.stderr).unwrap();
        (doc["build"]["deadline"].clone(), stderr)
    };
    // The shipped table keeps the 1 kHz period: the solver is left at
    // least its floor, and nothing is said on stderr.
    let (d, stderr) = deadline(&reach_spec(dir.path(), str::to_owned));
    let contract = [
        "period_us",
        "synthesis_instructions",
        "sensors",
        "solver_left",
        "solver_floor",
        "keeps_period",
    ];
    assert_eq!(keys(&d), contract.into_iter().collect());
    assert_eq!(d["period_us"], 1000);
    assert_eq!(d["sensors"], 3);
    assert_eq!(d["keeps_period"], true);
    assert!(d["solver_left"].as_u64() >= d["solver_floor"].as_u64());
    assert!(!stderr.contains("warning: with this table"), "{stderr}");
    // One Catmull-Rom axis: a window of 16 samples for each of 13
    // segments, which leaves the solver nothing at 1 kHz.
    let cubic = |t: &str| t.replacen("count = 4\n", "count = 4\ncubic = true\n", 1);
    let (d, stderr) = deadline(&reach_spec(dir.path(), cubic));
    assert_eq!(d["keeps_period"], false);
    assert!(d["solver_left"].as_u64() < d["solver_floor"].as_u64());
    assert!(stderr.contains("warning: with this table"), "{stderr}");
    assert!(stderr.contains("1000 µs period"), "{stderr}");
}
