//! The examples in `docs/` are real (#20 item 5): every fenced `json`,
//! `toml` and `csv` block of every page is read by the parser of the
//! command that reads that format, and must be accepted; the small build
//! spec and its example set build a table through the binary.

use marionette_core::solve::Solver;
use marionette_host::build::error::Source;
use marionette_host::build::{examples, spec};
use marionette_host::cmd::{rig, solve};
use marionette_host::import::csv;
use marionette_host::rigfile;
use std::path::PathBuf;
use std::process::Command;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The fenced blocks of `docs/<page>` as `(language, text)`.
fn blocks(page: &str) -> Vec<(String, String)> {
    let text = std::fs::read_to_string(repo().join("docs").join(page)).unwrap();
    let mut out = Vec::new();
    let mut open: Option<(String, String)> = None;
    for line in text.lines() {
        match (&mut open, line.strip_prefix("```")) {
            (None, Some(lang)) => open = Some((lang.trim().to_owned(), String::new())),
            (Some(_), Some("")) => out.extend(open.take()),
            (Some((_, body)), _) => {
                body.push_str(line);
                body.push('\n');
            }
            (None, None) => {}
        }
    }
    assert!(open.is_none(), "{page}: unclosed block");
    out
}

/// The blocks of `page` in `lang`, asserting that every block is in one of
/// the languages the page's test reads.
fn of(page: &str, lang: &str) -> Vec<String> {
    let all = blocks(page);
    assert!(!all.is_empty(), "{page} has no example");
    for (l, _) in &all {
        assert_eq!(l, lang, "{page}: a {l:?} block no test reads");
    }
    all.into_iter().map(|(_, b)| b).collect()
}

#[test]
fn every_page_is_listed_and_every_page_has_examples() {
    let index = std::fs::read_to_string(repo().join("docs/README.md")).unwrap();
    let mut pages: Vec<String> = std::fs::read_dir(repo().join("docs"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".md") && n != "README.md")
        .collect();
    pages.sort();
    assert_eq!(
        pages,
        [
            "example-set.md",
            "goals.md",
            "recording.md",
            "rig.md",
            "show.md",
            "spec.md",
            "take.md",
            "view.md"
        ]
    );
    for p in &pages {
        assert!(
            index.contains(&format!("({p})")),
            "docs/README.md lacks {p}"
        );
        assert!(!blocks(p).is_empty(), "{p} has no example");
    }
}

#[test]
fn the_goals_example_solves_and_renders() {
    let rig = rigfile::load(&repo().join("rigs/humanoid16.toml")).unwrap();
    for doc in of("goals.md", "json") {
        let out = solve::solve_text(&rig, &doc, "docs/goals.md", &Solver::DEFAULT)
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(out.goals.len(), 2);
        let dir = tempfile::tempdir().unwrap();
        let goals = dir.path().join("goals.json");
        std::fs::write(&goals, &doc).unwrap();
        let png = dir.path().join("goals.png");
        let o = Command::new(env!("CARGO_BIN_EXE_marionette"))
            .args(["render", "--rig"])
            .arg(repo().join("rigs/humanoid16.toml"))
            .arg("--goals")
            .arg(&goals)
            .args(["--width", "320", "--height", "240", "-o"])
            .arg(&png)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(String::from_utf8_lossy(&o.stdout).contains("2 goals"));
    }
}

#[test]
fn render_and_solve_refuse_the_same_bare_list() {
    let dir = tempfile::tempdir().unwrap();
    let goals = dir.path().join("goals.json");
    std::fs::write(
        &goals,
        r#"[{"segment": "head", "target": [0, 1, 0], "weight": 1}]"#,
    )
    .unwrap();
    let run = |args: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_marionette"))
            .args(args)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(1));
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    let rig = repo().join("rigs/humanoid16.toml");
    let (rig, goals_s) = (rig.to_str().unwrap(), goals.to_str().unwrap());
    let png = dir.path().join("x.png");
    let rendered = run(&[
        "render",
        "--rig",
        rig,
        "--goals",
        goals_s,
        "-o",
        png.to_str().unwrap(),
    ]);
    let solved = run(&["solve", rig, "--goals", goals_s]);
    assert!(solved.contains("goals.json:1: (top level)"), "{solved}");
    assert_eq!(rendered, solved);
    assert!(!png.exists());
}

#[test]
fn the_example_set_and_the_specs_are_read() {
    let dir = tempfile::tempdir().unwrap();
    let sets = of("example-set.md", "json");
    assert_eq!(sets.len(), 1);
    let set_path = dir.path().join("set.json");
    std::fs::write(&set_path, &sets[0]).unwrap();
    let set = examples::read(&set_path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((set.segments.len(), set.examples.len()), (2, 2));

    let specs = of("spec.md", "toml");
    assert_eq!(specs.len(), 2);
    // The example-set spec, beside its set: it builds.
    let spec_path = dir.path().join("spec.toml");
    std::fs::write(&spec_path, &specs[0]).unwrap();
    spec::read(&spec_path).unwrap_or_else(|e| panic!("{e}"));
    let table = dir.path().join("t.bin");
    let o = Command::new(env!("CARGO_BIN_EXE_marionette"))
        .arg("build")
        .arg(&spec_path)
        .arg("-o")
        .arg(&table)
        .arg("--quiet")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The mocap spec, as if in data/builds/ (its paths are relative to it).
    let source = Source {
        file: "docs/spec.md".into(),
        text: specs[1].clone(),
    };
    spec::parse(source, repo().join("data/builds")).unwrap_or_else(|e| panic!("{e}"));
}

#[test]
fn the_rig_example_loads_and_checks_clean() {
    for text in of("rig.md", "toml") {
        let file = rigfile::parse(&text, "docs/rig.md").unwrap_or_else(|e| panic!("{e}"));
        let report = rig::check(&file, &text).unwrap();
        assert!(report.errors.is_empty(), "{:?}", report.errors);
        assert!(report.warnings.is_empty(), "{:?}", report.warnings);
        assert!(report.boards.iter().all(|b| b.fits), "{:?}", report.boards);
    }
}

#[test]
fn the_recording_example_is_read() {
    for text in of("recording.md", "csv") {
        let samples = csv::parse_tracker_csv(text.as_bytes(), "docs/recording.md")
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(samples.len(), 4);
    }
}

/// The hex bytes of a layout block (`text`): each line's leading run of
/// two-digit hex tokens, up to the comment; lines of placeholders
/// (`c0 c1 …`) end it.
fn hex_bytes(block: &str) -> Vec<u8> {
    let mut out = Vec::new();
    for line in block.lines() {
        if line.starts_with("c0 c1") {
            break;
        }
        for tok in line.split_whitespace() {
            match u8::from_str_radix(tok, 16) {
                Ok(b) if tok.len() == 2 => out.push(b),
                _ => break,
            }
        }
    }
    out
}

#[test]
fn the_take_example_is_the_bytes_the_host_writes() {
    use marionette_host::take::{Event, EventKind, Take};
    let block = of("take.md", "text").remove(0);
    let take = Take {
        channels: 2,
        period_us: 1000,
        region: vec![0xAA, 0xBB],
        source: "t".into(),
        events: vec![
            Event {
                time_us: 5,
                kind: EventKind::Sent,
                data: vec![0x00, 0x01],
            },
            Event::output(6, true, &[0x1770, 0x0001]),
        ],
    };
    let bytes = take.to_bytes().unwrap();
    assert_eq!(hex_bytes(&block), bytes[..bytes.len() - 4]);
    // The same take from a port: version 2, the targets reported (kind 5).
    let block = of("take.md", "text").remove(1);
    let port = Take {
        source: "p".into(),
        events: vec![
            take.events[0].clone(),
            Event::targets_of(EventKind::Reported, 6, &[0x1770, 0x0001]),
        ],
        ..take
    };
    let bytes = port.to_bytes().unwrap();
    assert_eq!(hex_bytes(&block), bytes[..bytes.len() - 4]);
}

#[test]
fn the_show_example_is_the_bytes_the_host_writes_and_decodes() {
    use marionette_core::show::Show;
    let block = of("show.md", "text").remove(0);
    let frames = vec![vec![6000u16], vec![6002], vec![6004]];
    let blob =
        marionette_host::show::encode(&frames, &[Some(None)], 0x0102_0304_0506_0708, 1000, 4, 1)
            .unwrap();
    assert_eq!(hex_bytes(&block), blob[..blob.len() - 4]);
    let show = Show::parse(&blob).unwrap();
    assert_eq!(show.target(0, 1), Some(6002));
    assert!(show.looping() && !show.at_boot());
}
#[cfg(feature = "view")]
#[test]
fn the_view_event_example_is_a_snapshot() {
    use marionette_host::view::scene::Snapshot;
    for block in of("view.md", "json") {
        let s: Snapshot = serde_json::from_str(&block).expect("docs/view.md's example");
        assert_eq!(s.bones.len(), s.sides.len());
        // And back: the same keys (the numbers are f32 on the way).
        let again = serde_json::to_value(&s).unwrap();
        let given: serde_json::Value = serde_json::from_str(&block).unwrap();
        assert_eq!(key_paths(&again, ""), key_paths(&given, ""));
    }
}

/// Every object key of a JSON value, as paths (`link.state`).
#[cfg(feature = "view")]
fn key_paths(v: &serde_json::Value, at: &str) -> Vec<String> {
    let mut out = Vec::new();
    match v {
        serde_json::Value::Object(m) => {
            for (k, x) in m {
                let path = format!("{at}.{k}");
                out.extend(key_paths(x, &path));
                out.push(path);
            }
        }
        serde_json::Value::Array(items) => {
            for x in items {
                out.extend(key_paths(x, &format!("{at}[]")));
            }
        }
        _ => {}
    }
    out.sort();
    out.dedup();
    out
}
