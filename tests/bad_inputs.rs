//! Host robustness (issue #7, item 5): malformed JSON example sets
//! (`marionette build set.json`), build specs (`marionette build spec.toml`)
//! and goals files (`marionette solve --goals`) give errors that name the
//! file, the line and the field, and never panic.
//!
//! Each table case breaks one thing in a valid base file and states, by hand,
//! the line and field the error must name. The sweeps cut every base file at
//! every character and drop junk characters (multi-byte ones included) at
//! every position: no parser may panic, and every error must still carry the
//! file, a line and a field.
//!
//! Mocap files have their table in `tests/import.rs`, rig files in
//! `tests/rig.rs`; the rig TOML, BVH and AMC parsers are also fuzzed
//! (`tests/fuzz/`, replayed by `tests/fuzz_replay.rs`).

use marionette_core::solve::Solver;
use marionette_host::build::error::{InputError, Source};
use marionette_host::build::{self, examples, spec};
use marionette_host::cmd::solve;
use marionette_host::rigfile::{self, RigFile};
use marionette_tests::fuzz_targets::HUMANOID16_TOML;
use std::path::PathBuf;
use std::sync::OnceLock;

/// A base with `from` replaced by `to` (first occurrence, which must exist).
fn edit(base: &str, from: &str, to: &str) -> String {
    assert!(base.contains(from), "edit {from:?} does not apply");
    base.replacen(from, to, 1)
}

/// A case: what is broken, the replacement, and the line, field and part of
/// the problem the error must give.
struct Case {
    what: &'static str,
    from: &'static str,
    to: &'static str,
    line: usize,
    field: &'static str,
    needle: &'static str,
}

const fn case(
    what: &'static str,
    from: &'static str,
    to: &'static str,
    line: usize,
    field: &'static str,
    needle: &'static str,
) -> Case {
    Case {
        what,
        from,
        to,
        line,
        field,
        needle,
    }
}

/// Runs a table against a parser, collecting every mismatch.
fn check_table(base: &str, file: &str, cases: &[Case], parse: fn(&str) -> Result<(), InputError>) {
    parse(base).unwrap_or_else(|e| panic!("the base {file} must parse: {e}"));
    let mut failures = Vec::new();
    for c in cases {
        let text = edit(base, c.from, c.to);
        match parse(&text) {
            Ok(()) => failures.push(format!("{}: accepted", c.what)),
            Err(e) => {
                let msg = e.to_string();
                let prefix = format!("{file}:{}: {}: ", c.line, c.field);
                let ok = e.file == file
                    && e.line == c.line
                    && e.field == c.field
                    && msg.starts_with(&prefix)
                    && msg.contains(c.needle);
                if !ok {
                    failures.push(format!(
                        "{}: want {prefix:?} and {:?}, got {msg:?}",
                        c.what, c.needle
                    ));
                }
            }
        }
    }
    assert!(failures.is_empty(), "\n{}", failures.join("\n"));
}

/// Every prefix of `base` (at character boundaries), and `base` with each
/// junk character inserted at and substituted for each character.
fn mutations(base: &str) -> Vec<String> {
    const JUNK: [&str; 12] = [
        "\0", "{", "}", "[", "]", "\"", ",", ":", "-", "é", "€", "\n",
    ];
    let mut out = Vec::new();
    let bounds: Vec<usize> = base
        .char_indices()
        .map(|(i, _)| i)
        .chain([base.len()])
        .collect();
    for w in bounds.windows(2) {
        let (at, next) = (w[0], w[1]);
        out.push(base[..at].to_owned());
        for j in JUNK {
            out.push(format!("{}{j}{}", &base[..at], &base[at..]));
            out.push(format!("{}{j}{}", &base[..at], &base[next..]));
        }
    }
    out
}

/// No panic on any mutation; every error names the file, a line ≥ 1 and a
/// field.
fn sweep(base: &str, file: &str, parse: fn(&str) -> Result<(), InputError>) {
    let mut errors = 0;
    for text in mutations(base) {
        let result = std::panic::catch_unwind(|| parse(&text));
        match result {
            Err(_) => panic!("{file}: the parser panicked on {text:?}"),
            Ok(Ok(())) => {}
            Ok(Err(e)) => {
                errors += 1;
                assert!(
                    e.file == file && e.line >= 1 && !e.field.is_empty(),
                    "{file}: unlocated error {e} for {text:?}"
                );
                assert!(e.to_string().starts_with(&format!("{file}:{}: ", e.line)));
            }
        }
    }
    assert!(errors > 0, "{file}: the sweep must produce errors");
}

// ------------------------------------------------------------ example sets

const SET: &str = r#"{
  "segments": [
    "hips",
    "hand"
  ],
  "axes": [
    {"name": "x", "min": -0.5, "max": 0.5, "count": 3},
    {"name": "y", "min": 0.0, "max": 1.0, "count": 2, "cubic": false}
  ],
  "examples": [
    {"params": [0.1, 0.2], "pose": [[0, 1, 0, 1, 0, 0, 0], [0.1, 1.2, 0.4, 1, 0, 0, 0]]},
    {"params": [-0.3, 0.9],
     "pose": [[0, 1, 0, 1, 0, 0, 0],
              [0.2, 1.1, 0.3, 0, 1, 0, 0]]}
  ]
}
"#;

fn parse_set(text: &str) -> Result<(), InputError> {
    let src = Source {
        file: "set.json".into(),
        text: text.into(),
    };
    examples::parse(&src).map(drop)
}

#[test]
fn bad_example_sets_name_file_line_and_field() {
    let cases = [
        case(
            "duplicate segment",
            "\"hand\"",
            "\"hips\"",
            4,
            "segments[1]",
            "duplicate",
        ),
        case(
            "segment name too long",
            "\"hand\"",
            "\"a_segment_name_over_24_bytes\"",
            4,
            "segments[1]",
            "24 bytes",
        ),
        case(
            "segment name not a string",
            "\"hand\"",
            "7",
            4,
            "segments[1]",
            "invalid type",
        ),
        case(
            "no segments",
            "\"segments\": [\n    \"hips\",\n    \"hand\"\n  ]",
            "\"segments\": []",
            2,
            "segments",
            "1 to 256",
        ),
        case(
            "axis count 1",
            "\"count\": 3",
            "\"count\": 1",
            7,
            "axes[0]",
            "count must be at least 2",
        ),
        case(
            "axis min above max",
            "\"min\": 0.0, \"max\": 1.0",
            "\"min\": 1.0, \"max\": 0.0",
            8,
            "axes[1]",
            "min < max",
        ),
        case(
            "axis flag not a bool",
            "\"cubic\": false",
            "\"cubic\": \"no\"",
            8,
            "axes[1]",
            "invalid type",
        ),
        case(
            "unknown axis key",
            "\"max\": 0.5,",
            "\"max\": 0.5, \"step\": 1,",
            7,
            "axes[0]",
            "unknown field `step`",
        ),
        case(
            "axis count out of range",
            "\"count\": 3",
            "\"count\": 70000",
            7,
            "axes[0]",
            "70000",
        ),
        case(
            "one parameter for two axes",
            "[0.1, 0.2]",
            "[0.1]",
            11,
            "examples[0].params",
            "expected 2 parameters",
        ),
        case(
            "parameter overflows",
            "[-0.3, 0.9]",
            "[-0.3, 1e999]",
            12,
            "examples[1]",
            "out of range",
        ),
        case(
            "unknown example key",
            "\"pose\": [[0, 1, 0, 1, 0, 0, 0], [0.1",
            "\"poses\": [[0, 1, 0, 1, 0, 0, 0], [0.1",
            11,
            "examples[0]",
            "unknown field `poses`",
        ),
        case(
            "one segment pose missing",
            "[[0, 1, 0, 1, 0, 0, 0],\n              [0.2, 1.1, 0.3, 0, 1, 0, 0]]",
            "[[0, 1, 0, 1, 0, 0, 0]]",
            12,
            "examples[1].pose",
            "expected 2 segments",
        ),
        case(
            "non-unit rotation",
            "[0.2, 1.1, 0.3, 0, 1, 0, 0]",
            "[0.2, 1.1, 0.3, 0, 2, 0, 0]",
            14,
            "examples[1].pose[1]",
            "unit quaternion",
        ),
        case(
            "six numbers for a segment",
            "[0.2, 1.1, 0.3, 0, 1, 0, 0]",
            "[0.2, 1.1, 0.3, 0, 1, 0]",
            14,
            "examples[1].pose[1]",
            "invalid length 6",
        ),
        case(
            "segment value not a number",
            "[0.2, 1.1, 0.3, 0, 1, 0, 0]",
            "[0.2, 1.1, \"z\", 0, 1, 0, 0]",
            14,
            "examples[1].pose[1]",
            "invalid type",
        ),
        case(
            "no examples",
            "\"examples\": [\n    {\"params\": [0.1, 0.2], \"pose\": [[0, 1, 0, 1, 0, 0, 0], [0.1, 1.2, 0.4, 1, 0, 0, 0]]},\n    {\"params\": [-0.3, 0.9],\n     \"pose\": [[0, 1, 0, 1, 0, 0, 0],\n              [0.2, 1.1, 0.3, 0, 1, 0, 0]]}\n  ]",
            "\"examples\": []",
            10,
            "examples",
            "at least one example",
        ),
        case(
            "JSON syntax",
            "\"axes\": [",
            "\"axes\": [,",
            6,
            "example set",
            "expected value",
        ),
        case(
            "unknown top-level key",
            "\"segments\": [",
            "\"segment\": 1, \"segments\": [",
            2,
            "example set",
            "unknown field `segment`",
        ),
        case(
            "top level not an object",
            SET,
            "[1, 2]\n",
            1,
            "example set",
            "invalid type",
        ),
    ];
    check_table(SET, "set.json", &cases, parse_set);
}

#[test]
fn broken_example_sets_never_panic_and_every_error_is_located() {
    sweep(SET, "set.json", parse_set);
}

// ------------------------------------------------------------- build specs

const SPEC: &str = r#"kind = "grid"
frame = "heading"

[mocap]
skeleton = "a.asf"
every = 2

[[clip]]
file = "c1.amc"
frames = [[0, 100]]

[[axis]]
name = "hand_x"
segment = "rhand"
component = "x"
count = 4

[rig]
scale = 1.0

[resample]
method = "idw"
valid_radius = 0.9
"#;

fn parse_spec(text: &str) -> Result<(), InputError> {
    let src = Source {
        file: "spec.toml".into(),
        text: text.into(),
    };
    spec::parse(src, PathBuf::from("/nonexistent")).map(drop)
}

#[test]
fn bad_build_specs_name_file_line_and_field() {
    let cases = [
        case(
            "unknown frame",
            "frame = \"heading\"",
            "frame = \"sideways\"",
            2,
            "frame",
            "sideways",
        ),
        case(
            "both examples and mocap",
            "frame = \"heading\"",
            "examples = \"set.json\"",
            2,
            "examples",
            "not both",
        ),
        case(
            "wrong type",
            "skeleton = \"a.asf\"",
            "skeleton = 5",
            5,
            "mocap.skeleton",
            "invalid type",
        ),
        case(
            "TOML syntax",
            "every = 2",
            "every = = 2",
            6,
            "mocap.every",
            "",
        ),
        case(
            "duplicate key",
            "every = 2",
            "every = 2\nevery = 3",
            7,
            "mocap.every",
            "duplicate",
        ),
        case(
            "negative scale",
            "every = 2",
            "every = 2\nscale = -1.0",
            7,
            "mocap.scale",
            "> 0",
        ),
        case(
            "mocap without clips",
            "[[clip]]\nfile = \"c1.amc\"\nframes = [[0, 100]]\n",
            "",
            4,
            "clip",
            "at least one [[clip]]",
        ),
        case(
            "empty frame range",
            "frames = [[0, 100]]",
            "frames = [[100, 0]]",
            10,
            "clip[0].frames",
            "empty",
        ),
        case(
            "cut in a grid",
            "frames = [[0, 100]]",
            "cut = [0, 50, 100]",
            10,
            "clip[0].cut",
            "motion tables",
        ),
        case(
            "frames in a motion table",
            "kind = \"grid\"",
            "kind = \"clips\"",
            10,
            "clip[0].frames",
            "`cut`",
        ),
        case(
            "empty axis name",
            "name = \"hand_x\"",
            "name = \"\"",
            13,
            "axis[0].name",
            "1 to 24 bytes",
        ),
        case(
            "count out of range",
            "count = 4",
            "count = 70000",
            16,
            "axis[0].count",
            "",
        ),
        case(
            "zero rig scale",
            "scale = 1.0",
            "scale = 0.0",
            19,
            "rig.scale",
            "> 0",
        ),
        case(
            "missing rig file",
            "scale = 1.0",
            "file = \"no_such_rig.toml\"",
            19,
            "rig.file",
            "no rig file",
        ),
        case(
            "motion settings in a grid",
            "[rig]\nscale = 1.0",
            "[motion]\nframes = 8",
            18,
            "motion",
            "motion tables",
        ),
        case(
            "negative valid radius",
            "valid_radius = 0.9",
            "valid_radius = -1.0",
            23,
            "resample.valid_radius",
            "> 0",
        ),
        case("empty table header", "[resample]", "[]", 21, "spec", ""),
        case(
            "unknown table",
            "[resample]",
            "[resampling]",
            21,
            "resampling",
            "unknown field",
        ),
    ];
    check_table(SPEC, "spec.toml", &cases, parse_spec);
}

#[test]
fn broken_build_specs_never_panic_and_every_error_is_located() {
    sweep(SPEC, "spec.toml", parse_spec);
}

// ------------------------------------------------------------- goals files

fn rig() -> &'static RigFile {
    static RIG: OnceLock<RigFile> = OnceLock::new();
    RIG.get_or_init(|| rigfile::parse(HUMANOID16_TOML, "humanoid16.toml").expect("shipped rig"))
}

const GOALS: &str = r#"{
  "start": {"segments": [
    {"name": "r_upper_arm", "position": [-0.12, 0.7, 0.0], "rotation": [1, 0, 0, 0]}
  ]},
  "goals": [
    {"segment": "r_forearm", "target": [-0.1, 0.6, 0.2], "weight": 10},
    {"segment": "l_forearm", "target": [0.2, 0.5, 0.1], "weight": 5, "point": [0, -0.1, 0]}
  ]
}
"#;

fn solve_goals(text: &str) -> Result<(), String> {
    solve::solve_text(rig(), text, "goals.json", &Solver::DEFAULT)
        .map(drop)
        .map_err(|e| e.to_string())
}

/// The goals file's errors name the file, the line and the field (and, for
/// JSON syntax, the column); cases the CLI test (`tests/cli_solve.rs`)
/// does not cover.
#[test]
fn bad_goals_files_name_the_file_and_the_field() {
    solve_goals(GOALS).expect("the base goals file solves");
    let cases: [(&str, &str, &str, &[&str]); 9] = [
        (
            "syntax error on line 6",
            "\"weight\": 10}",
            "\"weight\": 10,}",
            &["goals.json:6:"],
        ),
        (
            "unterminated string",
            "\"l_forearm\"",
            "\"l_forearm",
            &["goals.json:7:"],
        ),
        (
            "goals not an array",
            "\"goals\": [",
            "\"goals\": 3, \"x\": [",
            &["goals.json:5: x: unknown field"],
        ),
        (
            "goal not an object",
            "{\"segment\": \"r_forearm\", \"target\": [-0.1, 0.6, 0.2], \"weight\": 10}",
            "[1, 2]",
            &["goals.json:6: goals[0]: expected an object"],
        ),
        (
            "target with a string",
            "[0.2, 0.5, 0.1]",
            "[0.2, \"up\", 0.1]",
            &["goals.json:7: goals[1].target[1]", "expected a number"],
        ),
        (
            "point with four numbers",
            "[0, -0.1, 0]",
            "[0, -0.1, 0, 1]",
            &["goals.json:7: goals[1].point", "3 numbers"],
        ),
        (
            "weight overflows f32",
            "\"weight\": 5",
            "\"weight\": 1e300",
            &["goals.json:7: goals[1].weight", "finite"],
        ),
        (
            "start position not an array",
            "\"position\": [-0.12, 0.7, 0.0]",
            "\"position\": -0.12",
            &["goals.json:3: start.segments[0].position", "3 numbers"],
        ),
        (
            "unknown start key",
            "\"rotation\": [1, 0, 0, 0]",
            "\"rotation\": [1, 0, 0, 0], \"scale\": 2",
            &["goals.json:3: start.segments[0].scale: unknown field"],
        ),
    ];
    let mut failures = Vec::new();
    for (what, from, to, want) in cases {
        match solve_goals(&edit(GOALS, from, to)) {
            Ok(()) => failures.push(format!("{what}: accepted")),
            Err(msg) if want.iter().all(|w| msg.contains(w)) => {}
            Err(msg) => failures.push(format!("{what}: want {want:?}, got {msg:?}")),
        }
    }
    assert!(failures.is_empty(), "\n{}", failures.join("\n"));
}

#[test]
fn broken_goals_files_never_panic_and_every_error_names_the_file() {
    let mut errors = 0;
    for text in mutations(GOALS) {
        match std::panic::catch_unwind(|| solve_goals(&text)) {
            Err(_) => panic!("solve panicked on {text:?}"),
            Ok(Ok(())) => {}
            Ok(Err(msg)) => {
                errors += 1;
                assert!(msg.starts_with("goals.json"), "{msg} for {text:?}");
            }
        }
    }
    assert!(errors > 0);
}

// ------------------------------------------- build errors found while loading

/// The bundled data folder.
fn data(relative: &str) -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../data")
        .join(relative)
        .display()
        .to_string()
}

/// A clips spec over two BVH files, with `extra` appended.
fn clips_spec(mocap: &str, a: &str, b: &str, extra: &str) -> String {
    format!(
        "kind = \"clips\"\n[mocap]\n{mocap}\n[[clip]]\nfile = \"{a}\"\ncut = [0, 100]\n\
         [[clip]]\nfile = \"{b}\"\ncut = [0, 100]\n[[axis]]\nname = \"speed\"\n\
         measure = \"speed\"\ncount = 2\n{extra}\n"
    )
}

/// A grid spec over HDM05 with the skeleton `asf` and the clip `amc`.
fn grid_spec(asf: &str, amc: &str) -> String {
    format!(
        "kind = \"grid\"\n[mocap]\nskeleton = \"{asf}\"\n[[clip]]\nfile = \"{amc}\"\n\
         [[axis]]\nname = \"x\"\nsegment = \"rhand\"\ncomponent = \"x\"\ncount = 3\n"
    )
}

/// `build::load` of a spec text (in `dir`); its error as text.
fn load_error(text: &str, dir: &std::path::Path) -> String {
    let src = Source {
        file: "spec.toml".into(),
        text: text.into(),
    };
    let spec = spec::parse(src, dir.to_path_buf()).unwrap_or_else(|e| panic!("parse: {e}"));
    match build::load(&spec, &build::Progress::new(false)) {
        Ok(_) => panic!("loaded:\n{text}"),
        Err(e) => e.to_string(),
    }
}

/// Every error `marionette build SPEC` finds past the spec's own syntax, in
/// a mocap file, a skeleton, a rig file or the table's name rules, names
/// the spec, the line of the field that brought it in and that field; a
/// mocap file's error also keeps that file's own line.
#[test]
fn build_errors_name_the_spec_line_and_field_and_the_mocap_files_line() {
    let dir = tempfile::tempdir().unwrap();
    let put = |name: &str, text: String| {
        std::fs::write(dir.path().join(name), text).unwrap();
        name.to_owned()
    };
    let walk = data("cmu_02_01_walk/02_01.bvh");
    let run = data("cmu_16_walk_run/16_21.bvh");
    let bvh_text = std::fs::read_to_string(&walk).unwrap();
    let asf_text = std::fs::read_to_string(data("hdm05_bk/HDM_bk.asf")).unwrap();
    let amc_path = data("hdm05_bk/HDM_bk_grabHighR_005_120.amc");
    // Latin-1 (HDM05's AMC headers hold a 0xFC byte).
    let amc_text: String = std::fs::read(&amc_path)
        .unwrap()
        .iter()
        .map(|&b| char::from(b))
        .collect();
    let line_of =
        |text: &str, needle: &str| 1 + text.lines().position(|l| l.contains(needle)).unwrap();
    let bad_bvh = put(
        "bad.bvh",
        bvh_text.replacen("OFFSET 1.363060", "OFFSET x", 1),
    );
    let bvh_line = line_of(&bvh_text, "OFFSET 1.363060");
    let bad_asf = put(
        "bad.asf",
        asf_text.replacen("length 7.88132", "length x", 1),
    );
    let asf_line = line_of(&asf_text, "length 7.88132");
    // The AMC's 30th line: its first number becomes `zz`.
    let amc_lines: Vec<String> = amc_text
        .lines()
        .enumerate()
        .map(|(i, l)| match (i, l.split_once(' ')) {
            (29, Some((bone, rest))) => {
                let tail = rest.split_once(' ').map_or("", |(_, t)| t);
                format!("{bone} zz {tail}")
            }
            _ => l.to_owned(),
        })
        .collect();
    let bad_amc = "bad.amc".to_owned();
    let bytes: Vec<u8> = amc_lines.join("\n").chars().map(|c| c as u8).collect();
    std::fs::write(dir.path().join(&bad_amc), bytes).unwrap();
    let bad_rig = put("rig.toml", "name = \"x\"\n".into());
    let cc = data("cmu_subject07_walk_speeds_ccrig/007_04.bvh");
    let cc2 = data("cmu_subject07_walk_speeds_ccrig/007_12.bvh");
    let pruning = "[rig]\ndrop = [\"*Twist*\", \"*Toe1\", \"*Mid*\", \"*Index*\", \"*Ring*\", \
                   \"*Pinky*\", \"*Thumb*\", \"*Facial*\", \"*Jaw*\", \"*Tongue*\", \"*Teeth*\", \
                   \"*Eye\", \"*Breast\"]";
    // (what, spec, the error's start, what it must also say)
    let cases: Vec<(&str, String, String, Vec<String>)> = vec![
        (
            "a malformed BVH clip",
            clips_spec("", &walk, &bad_bvh, ""),
            "spec.toml:8: clip[1].file: ".into(),
            vec![format!("bad.bvh:{bvh_line}:"), "LeftUpLeg OFFSET".into()],
        ),
        (
            "a missing clip",
            clips_spec("", "nothere.bvh", &run, ""),
            "spec.toml:5: clip[0].file: ".into(),
            vec!["nothere.bvh".into(), "cannot read".into()],
        ),
        (
            "a malformed ASF skeleton",
            grid_spec(&bad_asf, &amc_path),
            "spec.toml:3: mocap.skeleton: ".into(),
            vec![format!("bad.asf:{asf_line}:"), "bone length".into()],
        ),
        (
            "a malformed AMC clip",
            grid_spec(&data("hdm05_bk/HDM_bk.asf"), &bad_amc),
            "spec.toml:5: clip[0].file: ".into(),
            vec!["bad.amc:30:".into(), "\"zz\"".into()],
        ),
        (
            "a rig file that does not load",
            clips_spec("", &walk, &run, &format!("[rig]\nfile = \"{bad_rig}\"")),
            "spec.toml:15: rig.file: ".into(),
            vec!["rig.toml:1:".into(), "frame_period_us".into()],
        ),
        (
            "100 joints and no [rig] table",
            clips_spec("scale = 0.01", &cc, &cc2, ""),
            "spec.toml:5: clip[0].file: ".into(),
            vec![
                "100 segments".into(),
                "in a [rig] table".into(),
                "drop = ".into(),
            ],
        ),
        (
            "a 26-byte joint name kept",
            clips_spec("scale = 0.01", &cc, &cc2, pruning),
            "spec.toml:14: rig.strip_prefix: ".into(),
            vec![
                "\"CC_Base_L_ToeBaseShareBone\"".into(),
                "longer than 24 bytes".into(),
                "strip_prefix = \"CC_Base_\"".into(),
                "rename = { CC_Base_L_ToeBaseShareBone = ".into(),
            ],
        ),
        (
            "the 26-byte name after stripping the prefix, renamed too long",
            clips_spec(
                "scale = 0.01",
                &cc,
                &cc2,
                &format!(
                    "{pruning}\nstrip_prefix = \"CC_Base_\"\nrename = {{ L_ToeBaseShareBone = \"a_26_byte_segment_name_xx\" }}"
                ),
            ),
            "spec.toml:17: rig.rename: ".into(),
            vec!["rename = { L_ToeBaseShareBone = ".into()],
        ),
    ];
    // Found while building: axes whose range holds no example.
    let far = grid_spec(&data("hdm05_bk/HDM_bk.asf"), &amc_path)
        .replace("count = 3", "count = 3\nmin = 5.0\nmax = 6.0")
        .replace("[mocap]\n", "[mocap]\nevery = 8\n")
        + "[resample]\nvalid_radius = 0.5\n";
    let src = Source {
        file: "spec.toml".into(),
        text: far.clone(),
    };
    let spec = spec::parse(src, dir.path().to_path_buf()).unwrap();
    let progress = build::Progress::new(false);
    let loaded = build::load(&spec, &progress).unwrap();
    let e = build::build(&spec, &loaded, None, &progress)
        .unwrap_err()
        .to_string();
    let line = 1 + far
        .lines()
        .position(|l| l.starts_with("valid_radius"))
        .unwrap();
    assert!(
        e.starts_with(&format!(
            "spec.toml:{line}: resample.valid_radius: every grid cell"
        )),
        "{e}"
    );
    let mut failures = Vec::new();
    for (what, text, start, needles) in &cases {
        let e = load_error(text, dir.path());
        if !e.starts_with(start.as_str()) || needles.iter().any(|n| !e.contains(n.as_str())) {
            failures.push(format!("{what}: want {start:?} and {needles:?}, got {e:?}"));
        }
    }
    assert!(failures.is_empty(), "\n{}", failures.join("\n"));
}
