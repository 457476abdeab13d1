//! `marionette solve`, through its library entry point
//! (`marionette_host::cmd::solve::solve_text`), which `run` wraps; the
//! binary itself (argument parsing, exit status, stdout/stderr) is tested in
//! `host/tests/cli_solve.rs`, because `CARGO_BIN_EXE_marionette` only exists
//! in the host crate's own tests.
//!
//! References are independent of the solver: a reachable target comes from a
//! forward kinematics of humanoid16's right arm written here in `f64` from
//! the rig file's numbers and the documented joint conventions; the JSON
//! contract's keys are spelled out here; error messages must name the file and
//! the field.

use marionette_core::solve::Solver;
use marionette_host::cmd::solve::{SolveOutput, solve_text, summary};
use marionette_host::rigfile::{self, RigFile};
use serde_json::Value;
use std::collections::BTreeSet;
use std::path::Path;

fn rig() -> RigFile {
    rigfile::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../rigs/humanoid16.toml")).unwrap()
}

type Q = [f64; 4];
type V = [f64; 3];

fn axis_angle(axis: V, angle: f64) -> Q {
    let (s, c) = (angle / 2.0).sin_cos();
    [c, axis[0] * s, axis[1] * s, axis[2] * s]
}

fn qmul(a: Q, b: Q) -> Q {
    let [aw, ax, ay, az] = a;
    let [bw, bx, by, bz] = b;
    [
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ]
}

fn rotate(q: Q, v: V) -> V {
    // v' = q v q*, expanded.
    let p = qmul(
        qmul(q, [0.0, v[0], v[1], v[2]]),
        [q[0], -q[1], -q[2], -q[3]],
    );
    [p[1], p[2], p[3]]
}

fn add(a: V, b: V) -> V {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// humanoid16's right palm for shoulder pitch/roll and elbow angles (rad):
/// pelvis at (0, 0.44, 0); torso +0.05 Y; shoulder (−0.12, 0.22, 0); the
/// upper arm turns R_x(pitch)·R_z(roll); elbow 0.16 below; forearm R_x(elbow);
/// palm 0.15 below the elbow.
fn right_palm(pitch: f64, roll: f64, elbow: f64) -> V {
    let shoulder = [-0.12, 0.44 + 0.05 + 0.22, 0.0];
    let upper = qmul(
        axis_angle([1.0, 0.0, 0.0], pitch),
        axis_angle([0.0, 0.0, 1.0], roll),
    );
    let elbow_p = add(shoulder, rotate(upper, [0.0, -0.16, 0.0]));
    let fore = qmul(upper, axis_angle([1.0, 0.0, 0.0], elbow));
    add(elbow_p, rotate(fore, [0.0, -0.15, 0.0]))
}

fn keys(v: &Value) -> BTreeSet<&str> {
    v.as_object().unwrap().keys().map(String::as_str).collect()
}

fn set<'a>(k: &[&'a str]) -> BTreeSet<&'a str> {
    k.iter().copied().collect()
}

fn solve(doc: &str) -> SolveOutput {
    solve_text(
        &rig(),
        doc,
        "goals.json",
        &Solver::DEFAULT.with_iterations(100),
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

fn fails(doc: &str) -> String {
    match solve_text(&rig(), doc, "goals.json", &Solver::DEFAULT) {
        Ok(_) => panic!("accepted: {doc}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn reaches_a_reachable_goal_with_the_contracted_json() {
    let (pitch, roll, elbow) = (
        -60f64.to_radians(),
        -20f64.to_radians(),
        -50f64.to_radians(),
    );
    let t = right_palm(pitch, roll, elbow);
    let doc = format!(
        r#"{{"start": "rest", "goals": [{{"segment": "r_forearm", "target": [{}, {}, {}], "weight": 10}}]}}"#,
        t[0], t[1], t[2]
    );
    let out = solve(&doc);
    assert_eq!(out.goals.len(), 1);
    assert!(out.goals[0].distance < 1e-4, "{:?}", out.goals[0]);
    for (&got, &want) in out.goals[0].touch_point.iter().zip(&t) {
        assert!((f64::from(got) - want).abs() < 1e-4);
    }
    // The JSON contract: exactly these keys.
    let v = serde_json::to_value(&out).unwrap();
    // (Extended by #20 with met, unreachable, tolerance, restarts.)
    assert_eq!(
        keys(&v),
        set(&[
            "segments",
            "goals",
            "iterations",
            "converged",
            "met",
            "unreachable",
            "tolerance",
            "restarts"
        ])
    );
    let segs = v["segments"].as_array().unwrap();
    assert_eq!(segs.len(), 13);
    for s in segs {
        assert_eq!(keys(s), set(&["name", "position", "rotation"]));
        assert_eq!(s["position"].as_array().unwrap().len(), 3);
        assert_eq!(s["rotation"].as_array().unwrap().len(), 4);
    }
    for g in v["goals"].as_array().unwrap() {
        assert_eq!(
            keys(g),
            set(&[
                "segment",
                "touch_point",
                "distance",
                "active",
                "met",
                "reach"
            ])
        );
        assert_eq!(g["met"], true);
        assert_eq!(g["segment"], "r_forearm");
    }
    assert!(v["iterations"].is_u64() && v["converged"].is_boolean());
    // The reported touch point is the palm of the reported pose: the forearm's
    // origin plus its rotation applied to the touch point (0, −0.15, 0).
    let fore = segs.iter().find(|s| s["name"] == "r_forearm").unwrap();
    let p: Vec<f64> = fore["position"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let q: Vec<f64> = fore["rotation"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let palm = add(
        [p[0], p[1], p[2]],
        rotate([q[0], q[1], q[2], q[3]], [0.0, -0.15, 0.0]),
    );
    for (&want, &got) in palm.iter().zip(&out.goals[0].touch_point) {
        assert!((want - f64::from(got)).abs() < 1e-5);
    }
    // The elbow stays a hinge within its limits: the forearm's rotation
    // relative to the upper arm is about X only, in [−130°, 0].
    let upper = segs.iter().find(|s| s["name"] == "r_upper_arm").unwrap();
    let u: Vec<f64> = upper["rotation"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let rel = qmul([u[0], -u[1], -u[2], -u[3]], [q[0], q[1], q[2], q[3]]);
    let rel = if rel[0] < 0.0 { rel.map(|x| -x) } else { rel };
    assert!(rel[2].abs() < 1e-5 && rel[3].abs() < 1e-5, "{rel:?}");
    let angle = 2.0 * rel[1].atan2(rel[0]);
    assert!(
        (-130f64.to_radians() - 1e-5..=1e-5).contains(&angle),
        "{angle}"
    );
    // The pelvis did not move (the root is fixed by default).
    let root: Vec<f64> = segs[0]["position"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert_eq!(root, [0.0, f64::from(0.44f32), 0.0]);
    assert!(summary("humanoid16", &out).contains("r_forearm"));
}

#[test]
fn a_start_pose_is_a_warm_start() {
    let t = right_palm(-1.0, -0.3, -0.8);
    let goals = format!(
        r#"[{{"segment": "r_forearm", "target": [{}, {}, {}], "weight": 10}},
            {{"segment": "l_forearm", "target": [0.2, 0.6, 0.1], "weight": 5, "point": [0, -0.1, 0]}}]"#,
        t[0], t[1], t[2]
    );
    let first = solve(&format!(r#"{{"goals": {goals}}}"#));
    // Feed the result back as the start pose: it is already the answer.
    let start = serde_json::json!({ "segments": serde_json::to_value(&first.segments).unwrap() });
    let again = solve(&format!(r#"{{"start": {start}, "goals": {goals}}}"#));
    for (a, b) in first.goals.iter().zip(&again.goals) {
        assert!((a.distance - b.distance).abs() < 1e-4, "{a:?} {b:?}");
    }
    assert!(
        again.iterations <= first.iterations,
        "{} > {}",
        again.iterations,
        first.iterations
    );
    // The left-hand goal pulls an inner point: its reported distance is the
    // distance from the reported point to the target.
    let l = &first.goals[1];
    let d: f64 = [0.2, 0.6, 0.1]
        .iter()
        .zip(l.touch_point)
        .map(|(a, b)| (a - f64::from(b)).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!((d - f64::from(l.distance)).abs() < 1e-5, "{d} {l:?}");
    // A partial start pose: only the head turned 30° about Y.
    let q = axis_angle([0.0, 1.0, 0.0], 0.5);
    let doc = format!(
        r#"{{"start": {{"segments": [{{"name": "head", "position": [0, 0, 0], "rotation": [{}, 0, {}, 0]}}]}},
            "goals": [{{"segment": "l_foot", "target": [0.065, 0.0, 0.03], "weight": 1}}]}}"#,
        q[0], q[2]
    );
    let out = solve(&doc);
    let head = out.segments.iter().find(|s| s.name == "head").unwrap();
    assert!(
        (f64::from(head.rotation[2]) - q[2]).abs() < 1e-5,
        "{head:?}"
    );
    assert!(out.goals[0].distance < 1e-4);
}

#[test]
fn bad_inputs_name_the_file_and_the_field() {
    let cases: &[(&str, &[&str])] = &[
        // JSON syntax: line and column.
        (
            "{\n  \"goals\": [\n    {\"segment\": \"r_forearm\",}\n  ]\n}",
            &["goals.json:3:"],
        ),
        (
            "{\"goals\": [{\"segment\": \"r_forearm\", \"target\": [0, 1e999, 0], \"weight\": 1}]}",
            &["goals.json:1:", "out of range"],
        ),
        ("[]", &["goals.json:1: (top level)"]),
        ("{\"goal\": []}", &["goals.json:1: goal: unknown field"]),
        ("{}", &["goals.json:1: goals: missing"]),
        (
            "{\"goals\": [{\"segment\": \"r_hand\", \"target\": [0, 1, 0], \"weight\": 1}]}",
            &["goals.json:1: goals[0].segment", "r_hand"],
        ),
        (
            "{\"goals\": [{\"segment\": \"r_forearm\", \"target\": [0, 1e39, 0], \"weight\": 1}]}",
            &["goals.json:1: goals[0].target[1]", "finite"],
        ),
        (
            "{\"goals\": [{\"segment\": \"r_forearm\", \"target\": [0, 1], \"weight\": 1}]}",
            &["goals.json:1: goals[0].target", "3 numbers"],
        ),
        (
            "{\"goals\": [{\"segment\": \"r_forearm\", \"target\": [0, 1, 0]}]}",
            &["goals.json:1: goals[0].weight: missing"],
        ),
        (
            "{\"goals\": [{\"segment\": \"r_forearm\", \"target\": [0, 1, 0], \"weight\": -2}]}",
            &["goals.json:1: goals[0].weight"],
        ),
        (
            "{\"goals\": [{\"segment\": \"r_forearm\", \"target\": [0, 1, 0], \"wieght\": 1}]}",
            &["goals.json:1: goals[0].wieght: unknown field"],
        ),
        (
            "{\"goals\": [{\"segment\": \"r_forearm\", \"target\": [0, 1, 0], \"weight\": 1, \"point\": [0, \"a\", 0]}]}",
            &["goals.json:1: goals[0].point[1]"],
        ),
        (
            "{\"start\": \"sitting\", \"goals\": []}",
            &["goals.json:1: start", "sitting"],
        ),
        (
            "{\"start\": {\"segments\": [{\"name\": \"tail\", \"position\": [0,0,0], \"rotation\": [1,0,0,0]}]}, \"goals\": []}",
            &["goals.json:1: start.segments[0].name", "tail"],
        ),
        (
            "{\"start\": {\"segments\": [{\"name\": \"head\", \"position\": [0,0,0], \"rotation\": [0,0,0,0]}]}, \"goals\": []}",
            &["goals.json:1: start.segments[0].rotation"],
        ),
        (
            "{\"start\": {\"segments\": [{\"name\": \"head\", \"position\": [0,0,0], \"rotation\": [1,0,0,0]}, {\"name\": \"head\", \"position\": [0,0,0], \"rotation\": [1,0,0,0]}]}, \"goals\": []}",
            &["goals.json:1: start.segments[1].name", "twice"],
        ),
    ];
    let mut failures = Vec::new();
    for (doc, want) in cases {
        let msg = fails(doc);
        if !want.iter().all(|w| msg.contains(w)) {
            failures.push(format!("{doc}\n  want {want:?}\n  got  {msg}"));
        }
    }
    assert!(failures.is_empty(), "\n{}", failures.join("\n"));
}

/// A small deterministic generator (xorshift), for targets.
fn uniform(state: &mut u64) -> f64 {
    *state ^= *state << 13;
    *state ^= *state >> 7;
    *state ^= *state << 17;
    (*state >> 11) as f64 / (1u64 << 53) as f64
}

#[test]
fn each_goal_says_whether_it_is_met_and_which_cannot_be() {
    // The left sole at its rest position (met), the right palm 2 m above
    // the pelvis (out of reach), the head pulled with weight 0 (inactive).
    let doc = r#"{"goals": [
        {"segment": "l_foot", "target": [0.065, 0.0, 0.03], "weight": 1},
        {"segment": "r_forearm", "target": [0, 2.44, 0], "weight": 1},
        {"segment": "head", "target": [1, 1, 1], "weight": 0}]}"#;
    let out = solve(doc);
    let met: Vec<bool> = out.goals.iter().map(|g| g.met).collect();
    assert_eq!(met, [true, false, false]);
    assert_eq!(out.met, 1);
    assert_eq!(out.unreachable, [1]);
    assert!(!out.goals[2].active && out.goals[0].active);
    // The right palm's reach from the fixed pelvis, by hand: torso 0.05,
    // shoulder |(-0.12, 0.22, 0)| = 0.250599, upper arm 0.16, palm 0.15.
    let reach = 0.05 + (0.12f64.powi(2) + 0.22f64.powi(2)).sqrt() + 0.16 + 0.15;
    let got = f64::from(out.goals[1].reach.unwrap());
    assert!((got - reach).abs() < 1e-5, "{got} {reach}");
    // No pose gets it closer than the target's distance less the reach.
    assert!(f64::from(out.goals[1].distance) >= 2.0 - reach - 1e-5);
    let text = summary("humanoid16", &out);
    assert!(text.contains("1 of 3 goal(s) met"), "{text}");
    assert!(text.contains("unreachable: goals[1] (r_forearm)"), "{text}");
    assert!(text.contains("inactive (weight 0)"), "{text}");
    // "converged" keeps its meaning: the iteration stopped, goals missed.
    assert!(out.converged, "{text}");
    assert!(text.contains("converged (the iteration stopped)"), "{text}");
}

#[test]
fn restarts_meet_reachable_goals_that_one_local_solve_misses() {
    // Reachable right-palm targets: the arm's forward kinematics (above) at
    // random angles within its limits (pitch [-135, 45]°, roll [-100, 10]°,
    // elbow [-130, 0]°).
    let mut seed = 0x2545_F491_4F6C_DD1D_u64;
    let offline = Solver::DEFAULT
        .with_iterations(100)
        .with_restarts(marionette_host::cmd::solve::DEFAULT_RESTARTS);
    let local = Solver::DEFAULT.with_iterations(100);
    let (mut met_offline, mut met_local) = (0, 0);
    let n = 60;
    for _ in 0..n {
        let mut angle = |lo: f64, hi: f64| (lo + (hi - lo) * uniform(&mut seed)).to_radians();
        let t = right_palm(angle(-135.0, 45.0), angle(-100.0, 10.0), angle(-130.0, 0.0));
        let doc = format!(
            r#"{{"goals": [{{"segment": "r_forearm", "target": [{}, {}, {}], "weight": 1}}]}}"#,
            t[0], t[1], t[2]
        );
        for (solver, count) in [(&offline, &mut met_offline), (&local, &mut met_local)] {
            let out = solve_text(&rig(), &doc, "goals.json", solver).unwrap();
            let g = &out.goals[0];
            // `met` is the distance, measured here, within the tolerance.
            let d: f64 = t
                .iter()
                .zip(g.touch_point)
                .map(|(a, b)| (a - f64::from(b)).powi(2))
                .sum::<f64>()
                .sqrt();
            assert_eq!(g.met, d <= 1e-4 + 1e-6, "{d} {g:?}");
            assert!(out.unreachable.is_empty());
            *count += usize::from(g.met);
        }
    }
    assert_eq!(met_offline, n, "restarts meet every reachable target");
    assert!(
        met_local < n,
        "one local solve misses some ({met_local} of {n})"
    );
}

#[test]
fn synth_json_output_is_a_start_pose() {
    use marionette_host::build::{self, Progress, query, spec};
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/builds/reach_humanoid16.toml");
    let spec = spec::read(&path).unwrap();
    let progress = Progress::new(false);
    let data = build::load(&spec, &progress).unwrap();
    let built = build::build(&spec, &data, None, &progress).unwrap();
    let table = marionette_core::table::Table::parse(&built.blob).unwrap();
    let s = query::synthesize(&table, &[0.05, 0.3, 0.2], None).unwrap();
    let start = marionette_host::cmd::synth::to_json(&table, &s);
    assert!(start.get("duration").is_some(), "{start}");
    // With an inactive goal the solve keeps its start: the synthesized pose
    // (projected onto the joints), not the rest pose.
    let goals = r#"[{"segment": "head", "target": [0, 1, 0], "weight": 0}]"#;
    let doc = format!(r#"{{"start": {start}, "goals": {goals}}}"#);
    let from_synth = solve(&doc);
    let from_rest = solve(&format!(r#"{{"goals": {goals}}}"#));
    let moved = from_synth
        .segments
        .iter()
        .zip(&from_rest.segments)
        .map(|(a, b)| {
            let d: f32 = a.rotation.iter().zip(b.rotation).map(|(x, y)| x * y).sum();
            2.0 * d.abs().min(1.0).acos()
        })
        .fold(0.0f32, f32::max);
    assert!(moved > 0.2, "the start was not used: {moved} rad");
    // A segment entry is still checked field by field.
    let bad = doc.replacen("\"position\"", "\"positon\"", 1);
    let e = fails(&bad);
    assert!(e.contains("start.segments[0].positon"), "{e}");
}
