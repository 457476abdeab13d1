//! Rig checks (#20): `rig check` (summary, hash, per-board verdict, unit and
//! wiring slips), `inspect TABLE --rig RIG` (do they arm together, and why
//! not), and JSON example sets built for a `[rig] file` (the rig's hash).
//! The per-board verdicts are the firmware's: a 25-segment rig is booted on
//! the emulated board, which must refuse it as `rig check` said.

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
        .args(args)
        .output()
        .unwrap()
}

fn humanoid16() -> (PathBuf, String) {
    let path = repo().join("rigs/humanoid16.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    (path, text)
}

/// humanoid16 with `extra` rigid segments hanging from the pelvis.
fn with_segments(dir: &Path, extra: usize) -> PathBuf {
    let (_, mut text) = humanoid16();
    for i in 0..extra {
        text.push_str(&format!(
            "\n[[segment]]\nname = \"x{i:02}\"\nparent = \"pelvis\"\norigin = [0.0, 0.01, 0.0]\n"
        ));
    }
    let path = dir.join(format!("h{}.toml", 13 + extra));
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn rig_check_shows_the_hash_and_what_each_board_says() {
    let (path, _) = humanoid16();
    let o = marionette(&["rig", "check", s(&path)]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let hash = format!("{:#018x}", rigfile::load(&path).unwrap().rig_hash());
    assert!(out.contains(&format!("hash {hash}")), "{out}");
    assert!(
        out.contains("13 segments, 16 DOFs, 16 servos on maestro at 115200 baud"),
        "{out}"
    );
    assert!(out.contains("emulated   can drive it") && out.contains("blackpill  can drive it"));
    assert!(out.contains("0 error(s), 0 warning(s)"), "{out}");

    let o = marionette(&["rig", "check", s(&repo().join("rigs/cmu31.toml")), "--json"]);
    assert!(o.status.success());
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(doc["segments"], 31);
    // 31 segments fit neither firmware; only the Black Pill has PWM timers.
    let boards = doc["boards"].as_array().unwrap();
    let problems = |i: usize| boards[i]["problems"].to_string();
    assert_eq!(boards[0]["fits"], false);
    assert!(
        problems(0).contains("31 segments") && problems(0).contains("`pwm`"),
        "{}",
        problems(0)
    );
    assert_eq!(boards[1]["fits"], false);
    assert!(
        problems(1).contains("31 segments") && !problems(1).contains("pwm"),
        "{}",
        problems(1)
    );
    assert_eq!(
        doc["warnings"].as_array().unwrap().len(),
        1,
        "one: no servos"
    );
}

#[test]
fn rig_check_finds_unit_and_wiring_slips_with_their_lines() {
    let dir = tempfile::tempdir().unwrap();
    let (_, text) = humanoid16();
    let line_of = |t: &str, needle: &str| t[..t.find(needle).unwrap()].lines().count() + 1;
    // Degrees in the radians key of servo 0; a 19 m shin (centimetres in
    // metres); servo 3 moved from l_upper_arm.z onto l_upper_arm.x, which
    // servo 2 drives: x driven twice, z by none.
    let slip = text
        .replacen("angle_deg = [", "angle = [", 1)
        .replacen(
            "origin = [0.0, -0.19, 0.0]      # knee",
            "origin = [0.0, -19, 0.0]",
            1,
        )
        .replacen(
            "channel = 3\njoint = \"l_upper_arm\"\naxis = \"z\"",
            "channel = 3\njoint = \"l_upper_arm\"\naxis = \"x\"",
            1,
        );
    let path = dir.path().join("slip.toml");
    std::fs::write(&path, &slip).unwrap();
    let o = marionette(&["rig", "check", s(&path), "--json"]);
    assert_eq!(o.status.code(), Some(1));
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let errors = doc["errors"].as_array().unwrap();
    assert_eq!(errors.len(), 1, "{doc}");
    assert_eq!(errors[0]["field"], "servo[3]");
    assert_eq!(errors[0]["line"], line_of(&slip, "channel = 3") - 1);
    assert!(
        errors[0]["message"]
            .as_str()
            .unwrap()
            .contains("l_upper_arm.x")
    );
    let warnings: Vec<(String, u64)> = doc["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| {
            (
                w["field"].as_str().unwrap().to_owned(),
                w["line"].as_u64().unwrap(),
            )
        })
        .collect();
    let want = [
        (
            "segment[3].dofs[1]".to_owned(),
            line_of(&slip, "name = \"l_upper_arm\"") as u64 - 1,
        ),
        (
            "segment[8].origin".to_owned(),
            line_of(&slip, "name = \"l_shin\"") as u64 - 1,
        ),
        (
            "servo[0].angle".to_owned(),
            line_of(&slip, "angle = [") as u64,
        ),
    ];
    assert_eq!(warnings, want, "{doc}");
}

#[test]
fn a_rig_over_the_firmware_capacity_is_named_and_the_board_agrees() {
    let dir = tempfile::tempdir().unwrap();
    let h25 = with_segments(dir.path(), 12);
    let o = marionette(&["rig", "check", s(&h25)]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("emulated   cannot: 25 segments; its firmware holds at most 24"),
        "{out}"
    );
    // The emulated board itself: it refuses the 25-segment rig at boot.
    let rig = rigfile::load(&h25).unwrap();
    let table = perform::rest_grid(&rig, &[("a", -0.5, 0.5, 3)]).unwrap();
    let table_file = dir.path().join("rest.bin");
    std::fs::write(&table_file, table).unwrap();
    let rec = dir.path().join("rec.csv");
    std::fs::write(
        &rec,
        "time_us,sensor,x,y,z,qw,qx,qy,qz\n0,0,0,1,0,1,0,0,0\n",
    )
    .unwrap();
    let o = marionette(&[
        "emulate",
        "--rig",
        s(&h25),
        "--tables",
        s(&table_file),
        "--recording",
        s(&rec),
        "--out",
        s(&dir.path().join("out")),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(3), "{err}");
    assert!(
        err.contains("RigTooLarge") && err.contains("25 segments"),
        "{err}"
    );
    // 24 segments: both boards can drive it.
    let h24 = with_segments(dir.path(), 11);
    let o = marionette(&["rig", "check", s(&h24)]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("emulated   can drive it"), "{out}");
}

#[test]
fn inspect_says_whether_a_rig_and_a_table_arm_together() {
    let dir = tempfile::tempdir().unwrap();
    let (path, text) = humanoid16();
    let rig = rigfile::load(&path).unwrap();
    let table = dir.path().join("rest.bin");
    std::fs::write(
        &table,
        perform::rest_grid(&rig, &[("a", -0.5, 0.5, 3)]).unwrap(),
    )
    .unwrap();
    let o = marionette(&["inspect", s(&table), "--rig", s(&path), "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(doc["arming"]["arms"], true);
    assert_eq!(doc["arming"]["boards"][1]["arms"], true, "{doc}");
    // A one-axis linear grid leaves the 1 kHz rig's solver more than its
    // floor: its plain frames keep the period.
    let deadline = &doc["arming"]["deadline"];
    assert_eq!(deadline["period_us"], 1000, "{doc}");
    assert_eq!(deadline["keeps_period"], true, "{doc}");
    assert!(deadline["solver_left"].as_u64() >= deadline["solver_floor"].as_u64());
    // Another rig (a longer shin): the hashes differ, named.
    let other = dir.path().join("other.toml");
    std::fs::write(&other, text.replacen("-0.18, 0.0]", "-0.2, 0.0]", 1)).unwrap();
    let o = marionette(&["inspect", s(&table), "--rig", s(&other)]);
    let (out, err) = (
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    assert_eq!(o.status.code(), Some(3), "{err}");
    assert!(out.contains("RigMismatch") && err.contains("would refuse to arm: RigMismatch"));
    // A PCA9685 rig: the core arms, the emulated board has no I2C, the
    // Black Pill drives it.
    let pca = dir.path().join("pca.toml");
    let maestro = "kind = \"maestro\"                # Pololu Maestro, compact protocol over UART\nbaud = 115200";
    assert!(text.contains(maestro));
    std::fs::write(
        &pca,
        text.replace(maestro, "kind = \"pca9685\"\ni2c_addr = 0x40\nfreq_hz = 50"),
    )
    .unwrap();
    let o = marionette(&["inspect", s(&table), "--rig", s(&pca), "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(doc["arming"]["arms"], true);
    assert_eq!(doc["arming"]["boards"][0]["reason"], "Unsupported");
    assert_eq!(doc["arming"]["boards"][1]["arms"], true);
    // On-chip PWM with 16 channels: the Black Pill has 12; no board arms.
    let pwm = dir.path().join("pwm.toml");
    std::fs::write(&pwm, text.replace(maestro, "kind = \"pwm\"\nfreq_hz = 50")).unwrap();
    let o = marionette(&["inspect", s(&table), "--rig", s(&pwm), "--json"]);
    assert_eq!(
        o.status.code(),
        Some(3),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(doc["arming"]["boards"][0]["reason"], "Unsupported");
    let detail = doc["arming"]["boards"][1]["detail"].as_str().unwrap();
    assert!(detail.contains("channel 12"), "{detail}");
    // A region image is named as one.
    let region = dir.path().join("region.bin");
    let image = perform::region(
        &rigfile::to_blob(&rig).unwrap(),
        Some(&std::fs::read(&table).unwrap()),
    );
    std::fs::write(&region, image).unwrap();
    let o = marionette(&["inspect", s(&region)]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("region image"), "{err}");
}

#[test]
fn a_json_example_set_built_for_a_rig_file_has_the_rigs_hash() {
    let dir = tempfile::tempdir().unwrap();
    let (rig, _) = humanoid16();
    // A two-example set over humanoid16's segments, in the rig's order.
    let names = rigfile::load(&rig).unwrap().segment_names().to_vec();
    let pose = |y: f64| {
        let segs: Vec<String> = (0..names.len())
            .map(|i| format!("[0, {}, 0, 1, 0, 0, 0]", y + 0.1 * i as f64))
            .collect();
        format!("[{}]", segs.join(", "))
    };
    let set = dir.path().join("set.json");
    let quoted: Vec<String> = names.iter().map(|n| format!("{n:?}")).collect();
    std::fs::write(
        &set,
        format!(
            "{{\n\"segments\": [{}],\n\"axes\": [{{\"name\": \"a\", \"min\": 0, \"max\": 1, \"count\": 2}}],\n\
             \"examples\": [{{\"params\": [0], \"pose\": {}}}, {{\"params\": [1], \"pose\": {}}}]\n}}\n",
            quoted.join(", "),
            pose(0.4),
            pose(0.5)
        ),
    )
    .unwrap();
    let with_rig = dir.path().join("with_rig.toml");
    std::fs::write(
        &with_rig,
        format!("examples = \"set.json\"\n\n[rig]\nfile = {:?}\n", s(&rig)),
    )
    .unwrap();
    let table = dir.path().join("t.bin");
    let o = marionette(&["build", s(&with_rig), "-o", s(&table), "--quiet"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = marionette(&["inspect", s(&table), "--rig", s(&rig)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stdout));
    // Without [rig] the hash is the set's own, and the rig refuses it.
    let bare = dir.path().join("bare.toml");
    std::fs::write(&bare, "examples = \"set.json\"\n").unwrap();
    let o = marionette(&["build", s(&bare), "-o", s(&table), "--quiet"]);
    assert!(o.status.success());
    let o = marionette(&["inspect", s(&table), "--rig", s(&rig)]);
    assert_eq!(o.status.code(), Some(3));
    // A set whose segments are not the rig's is refused, naming the field.
    let text = std::fs::read_to_string(&set).unwrap();
    std::fs::write(&set, text.replacen("\"pelvis\"", "\"hips\"", 1)).unwrap();
    let o = marionette(&["build", s(&with_rig), "-o", s(&table), "--quiet"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        err.contains("set.json:") && err.contains("segments") && err.contains("hips"),
        "{err}"
    );
}

// ---------------------------------------------------------------------------
// `rig --from-skeleton` (#16 item 5). References are read here from the
// skeleton files' text: joint and channel counts, OFFSETs.

/// `rig --from-skeleton SKELETON -o OUT` plus `extra`.
fn from_skeleton(skeleton: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["rig", "--from-skeleton", s(skeleton), "-o", s(out)];
    args.extend_from_slice(extra);
    marionette(&args)
}

fn ok(o: &Output) -> String {
    assert!(
        o.status.success(),
        "stdout: {}\nstderr: {}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// `solve RIG` with one goal pulling `segment` to `target`; the goal's
/// distance after solving, m.
fn solve_distance(dir: &Path, rig: &Path, segment: &str, target: [f64; 3]) -> f64 {
    let goals = dir.join(format!("{segment}.json"));
    let doc = serde_json::json!({"goals": [{"segment": segment, "target": target, "weight": 1}]});
    std::fs::write(&goals, doc.to_string()).unwrap();
    let o = marionette(&["solve", s(rig), "--goals", s(&goals), "--json"]);
    let v: serde_json::Value = serde_json::from_str(&ok(&o)).unwrap();
    v["goals"][0]["distance"].as_f64().unwrap()
}

/// The rest position of `joint` in a BVH text: the sum of the OFFSETs from
/// the root down to it (times `scale`), found by walking the braces.
fn bvh_rest_position(text: &str, joint: &str, scale: f64) -> [f64; 3] {
    let mut stack: Vec<[f64; 3]> = Vec::new();
    let mut pending: Option<String> = None;
    let mut current: Vec<String> = Vec::new();
    for line in text.lines() {
        let t: Vec<&str> = line.split_whitespace().collect();
        match t.first().copied() {
            Some("ROOT" | "JOINT") => pending = Some(t[1].to_owned()),
            Some("End") => pending = Some("end".into()),
            Some("{") => {
                current.push(pending.take().unwrap());
                stack.push(*stack.last().unwrap_or(&[0.0; 3]));
            }
            Some("}") => {
                current.pop();
                stack.pop();
            }
            Some("OFFSET") => {
                let top = stack.last_mut().unwrap();
                for k in 0..3 {
                    top[k] += t[k + 1].parse::<f64>().unwrap() * scale;
                }
                if current.last().map(String::as_str) == Some(joint) {
                    return *top;
                }
            }
            Some("MOTION") => break,
            _ => {}
        }
    }
    panic!("no joint {joint}")
}

#[test]
fn a_rig_from_a_bvh_skeleton_loads_passes_rig_check_and_solves() {
    let dir = tempfile::tempdir().unwrap();
    let bvh = repo().join("data/cmu_02_01_walk/02_01.bvh");
    let out = dir.path().join("cmu.toml");
    let said = ok(&from_skeleton(&bvh, &out, &[]));
    assert!(said.contains("31 segments"), "{said}");
    // Counted from the file: joints (End Sites excluded) and the rotation
    // channels of every joint but the root.
    let text = std::fs::read_to_string(&bvh).unwrap();
    let hierarchy = text.split("MOTION").next().unwrap();
    let joints = hierarchy
        .lines()
        .filter(|l| l.trim_start().starts_with("ROOT") || l.trim_start().starts_with("JOINT"))
        .count();
    let rotations: usize = hierarchy
        .lines()
        .filter(|l| l.trim_start().starts_with("CHANNELS"))
        .skip(1)
        .map(|l| l.matches("rotation").count())
        .sum();
    let rig = rigfile::load(&out).unwrap_or_else(|e| panic!("{e}"));
    let desc = rig.desc();
    assert_eq!(desc.segments.len(), joints);
    let dofs: usize = desc.segments.iter().map(|s| s.dofs.len()).sum();
    assert_eq!(dofs, rotations);
    // LeftUpLeg's origin is its OFFSET in metres (CMU unit 0.0254/0.45 m).
    let unit = 0.0254 / 0.45;
    let leg = desc
        .segments
        .iter()
        .find(|s| s.name == "LeftUpLeg")
        .unwrap();
    for (got, want) in leg.origin.iter().zip([1.363060, -1.794630, 0.839290]) {
        assert!(
            (f64::from(*got) - want * unit).abs() < 2e-6,
            "{:?}",
            leg.origin
        );
    }
    // The DOFs follow the channel order Zrotation Yrotation Xrotation.
    let axes: Vec<String> = leg.dofs.iter().map(|d| format!("{:?}", d.axis)).collect();
    assert_eq!(axes, ["Z", "Y", "X"]);
    let text_out = std::fs::read_to_string(&out).unwrap();
    assert!(text_out.contains("EDIT"), "comments mark what to edit");
    let o = marionette(&["rig", "check", s(&out)]);
    let report = ok(&o);
    assert!(report.contains("0 error(s)"), "{report}");
    // Solve: the right hand 15 cm forward and 20 cm up from its rest
    // position (the rig's root_position plus the OFFSET chain, here).
    let rest = bvh_rest_position(&text, "RightHand", unit);
    let root_y = f64::from(desc.root_position[1]);
    let target = [rest[0], rest[1] + root_y + 0.2, rest[2] + 0.15];
    let d = solve_distance(dir.path(), &out, "RightHand", target);
    assert!(d < 1e-3, "RightHand {d} m from {target:?}");
    // Its [retarget] map: a spec with `[rig] file` = the written rig builds
    // a table from CMU walks of the same skeleton, for this rig (its hash).
    let spec = dir.path().join("walk.toml");
    let clip = |f: &str| s(&repo().join("data/cmu_16_walk_run").join(f)).to_owned();
    std::fs::write(
        &spec,
        format!(
            "kind = \"clips\"\n[mocap]\n[rig]\nfile = \"cmu.toml\"\n[[clip]]\nfile = \"{}\"\n\
             cut = [121, 235]\n[[clip]]\nfile = \"{}\"\ncut = [19, 103]\n[[axis]]\n\
             name = \"speed\"\nmeasure = \"speed\"\ncount = 2\n[motion]\nframes = 16\n\
             looping = true\n",
            clip("16_21.bvh"),
            clip("16_45.bvh")
        ),
    )
    .unwrap();
    let table = dir.path().join("walk.bin");
    ok(&marionette(&["build", s(&spec), "-o", s(&table)]));
    let check: serde_json::Value =
        serde_json::from_str(&ok(&marionette(&["rig", "check", s(&out), "--json"]))).unwrap();
    let inspect: serde_json::Value =
        serde_json::from_str(&ok(&marionette(&["inspect", s(&table), "--json"]))).unwrap();
    assert_eq!(inspect["rig_hash"], check["hash"]);
}

#[test]
fn a_rig_from_an_asf_skeleton_loads_passes_rig_check_and_solves() {
    let dir = tempfile::tempdir().unwrap();
    let asf = repo().join("data/hdm05_bk/HDM_bk.asf");
    let out = dir.path().join("hdm.toml");
    ok(&from_skeleton(&asf, &out, &["--name", "hdm05"]));
    let text = std::fs::read_to_string(&asf).unwrap();
    let bones = text.lines().filter(|l| l.trim() == "begin").count() - 1; // :hierarchy's begin
    let dofs_in_file: usize = text
        .lines()
        .filter_map(|l| l.trim().strip_prefix("dof "))
        .map(|d| d.split_whitespace().count())
        .sum();
    let rig = rigfile::load(&out).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(rig.name(), "hdm05");
    let desc = rig.desc();
    assert_eq!(desc.segments.len(), bones + 1, "the root and each bone");
    let dofs: usize = desc.segments.iter().map(|s| s.dofs.len()).sum();
    assert_eq!(dofs, dofs_in_file);
    // ltibia: `dof rx`, limits (-10.0 170.0), axis tilted 20° about z.
    let tibia = desc.segments.iter().find(|s| s.name == "ltibia").unwrap();
    assert_eq!(tibia.dofs.len(), 1);
    let d = tibia.dofs.as_slice()[0];
    assert_eq!(format!("{:?}", d.axis), "X");
    assert!((f64::from(d.min).to_degrees() + 10.0).abs() < 1e-3);
    assert!((f64::from(d.max).to_degrees() - 170.0).abs() < 1e-3);
    let written = std::fs::read_to_string(&out).unwrap();
    assert!(
        written.contains("20.0° from this one"),
        "the tilt is stated"
    );
    let report = ok(&marionette(&["rig", "check", s(&out)]));
    assert!(report.contains("0 error(s)"), "{report}");
    let d = solve_distance(dir.path(), &out, "rhand", [-0.3, 1.3, 0.3]);
    assert!(d < 1e-3, "rhand {d} m off");
}

#[test]
fn rig_from_skeleton_refuses_to_overwrite_its_input_or_an_existing_file() {
    let dir = tempfile::tempdir().unwrap();
    let bvh = dir.path().join("walk.bvh");
    std::fs::copy(repo().join("data/cmu_02_01_walk/02_01.bvh"), &bvh).unwrap();
    let before = std::fs::read(&bvh).unwrap();
    for extra in [&[][..], &["--force"][..]] {
        let o = from_skeleton(&bvh, &bvh, extra);
        assert!(!o.status.success());
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("refusing to write over the input"), "{err}");
        assert_eq!(
            std::fs::read(&bvh).unwrap(),
            before,
            "the input is untouched"
        );
    }
    let out = dir.path().join("rig.toml");
    std::fs::write(&out, "mine").unwrap();
    let o = from_skeleton(&bvh, &out, &[]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--force"));
    assert_eq!(std::fs::read_to_string(&out).unwrap(), "mine");
    ok(&from_skeleton(&bvh, &out, &["--force"]));
    assert!(rigfile::load(&out).is_ok());
}

#[test]
fn bad_skeleton_files_are_named_with_their_line() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("rig.toml");
    // A BVH whose third OFFSET is not a number (line 12), an ASF whose
    // lfemur length is not one (line 27 of HDM_bk.asf).
    let bvh_text = std::fs::read_to_string(repo().join("data/cmu_02_01_walk/02_01.bvh")).unwrap();
    let asf_text = std::fs::read_to_string(repo().join("data/hdm05_bk/HDM_bk.asf")).unwrap();
    let cases = [
        (
            "bad.bvh",
            bvh_text.replacen("OFFSET 1.363060", "OFFSET one", 1),
            "one",
        ),
        (
            "bad.asf",
            asf_text.replacen("length 7.88132", "length seven", 1),
            "seven",
        ),
    ];
    for (name, text, token) in cases {
        let line = 1 + text.lines().position(|l| l.contains(token)).unwrap();
        let path = dir.path().join(name);
        std::fs::write(&path, &text).unwrap();
        let o = from_skeleton(&path, &out, &[]);
        assert!(!o.status.success());
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains(&format!("{}:{line}:", path.display())),
            "{name}: {err}"
        );
        assert!(err.contains(token), "{err}");
        assert!(!out.exists(), "nothing written");
    }
    // A joint name over the 24-byte limit names its line and the option.
    let long = bvh_text.replacen("JOINT LeftUpLeg", "JOINT LeftUpLegWithAVeryLongName", 1);
    let path = dir.path().join("long.bvh");
    std::fs::write(&path, &long).unwrap();
    let line = 1 + long.lines().position(|l| l.contains("VeryLong")).unwrap();
    let o = from_skeleton(&path, &out, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains(&format!(":{line}:")), "{err}");
    assert!(
        err.contains("--rename LeftUpLegWithAVeryLongName=NEW"),
        "{err}"
    );
    ok(&from_skeleton(
        &path,
        &out,
        &["--rename", "LeftUpLegWithAVeryLongName=LeftUpLeg"],
    ));
    assert!(
        rigfile::load(&out)
            .unwrap()
            .segment_names()
            .contains(&"LeftUpLeg".to_owned())
    );
}

#[test]
fn rig_alone_says_what_to_give() {
    let o = marionette(&["rig"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--from-skeleton"));
}
