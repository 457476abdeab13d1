//! The `render`, `plot` and `flash` subcommands through the `marionette`
//! binary: exit status, messages, and what the pictures contain.

use marionette_host::render::font_available;
use std::path::Path;
use std::process::{Command, Output};

fn marionette(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_marionette"))
        .args(args)
        .output()
        .expect("marionette runs")
}

fn ok(args: &[&str]) -> String {
    let out = marionette(args);
    assert!(
        out.status.success(),
        "{args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

fn fails(args: &[&str]) -> String {
    let out = marionette(args);
    assert!(!out.status.success(), "{args:?} succeeded");
    String::from_utf8(out.stderr).unwrap()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Width and height from a PNG's IHDR chunk.
fn png_size(path: &Path) -> (u32, u32) {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "PNG signature");
    assert_eq!(&bytes[12..16], b"IHDR");
    let be = |i: usize| u32::from_be_bytes(bytes[i..i + 4].try_into().unwrap());
    (be(16), be(20))
}

/// Every `<polyline>` of an SVG: stroke colour and points.
fn polylines(svg: &str) -> Vec<(String, Vec<(f64, f64)>)> {
    svg.split("<polyline")
        .skip(1)
        .map(|el| {
            let attr = |name: &str| {
                let at = el.find(&format!(" {name}=\"")).unwrap() + name.len() + 3;
                el[at..at + el[at..].find('"').unwrap()].to_string()
            };
            let points = attr("points")
                .split_whitespace()
                .map(|p| {
                    let (x, y) = p.split_once(',').unwrap();
                    (x.parse().unwrap(), y.parse().unwrap())
                })
                .collect();
            (attr("stroke"), points)
        })
        .collect()
}

const BLUE: &str = "#1F64C8"; // left
const RED: &str = "#D22D2D"; // right
const GREY: &str = "#3C3C3C"; // midline

#[test]
fn render_png_has_the_asked_size() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("rest.png");
    let said = ok(&["render", "--body", "tempus", "-o", s(&out)]);
    assert!(said.contains("22 bones"), "{said}");
    assert_eq!(png_size(&out), (1200, 1200));
    let cmu = dir.path().join("cmu.PNG");
    ok(&[
        "render",
        "--body",
        "cmu",
        "--width",
        "640",
        "--height",
        "480",
        "-o",
        s(&cmu),
    ]);
    assert_eq!(png_size(&cmu), (640, 480));
}

#[test]
fn render_svg_front_view_faces_the_viewer_with_y_up() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("rest.svg");
    ok(&["render", "--body", "tempus", "-o", s(&out)]);
    let svg = std::fs::read_to_string(&out).unwrap();
    assert!(svg.starts_with("<svg width=\"1200\" height=\"1200\""));
    // The front panel is the top-left quarter.
    let front: Vec<(String, Vec<(f64, f64)>)> = polylines(&svg)
        .into_iter()
        .filter(|(_, pts)| pts.iter().all(|&(x, y)| x < 600.0 && y < 620.0))
        .collect();
    let points = |colour: &str| -> Vec<(f64, f64)> {
        front
            .iter()
            .filter(|(c, _)| c == colour)
            .flat_map(|(_, p)| p.clone())
            .collect()
    };
    let mean_x = |p: &[(f64, f64)]| p.iter().map(|q| q.0).sum::<f64>() / p.len() as f64;
    let (left, right, mid) = (points(BLUE), points(RED), points(GREY));
    // Left and right arms and legs are all drawn: 4 bones + 1 leaf bone per
    // limb pair side (clavicle, upper arm, lower arm, hand; thigh, shin, foot).
    assert!(
        left.len() >= 2 * 8 && right.len() >= 2 * 8,
        "{left:?} {right:?}"
    );
    // Seen from the front, the figure's left (+X) is on the viewer's right.
    assert!(mean_x(&right) + 40.0 < mean_x(&left));
    // Y up: the head (top of the midline) is above the feet (bottom of the legs).
    let top_mid = mid.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
    let low_leg = left.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
    assert!(top_mid + 300.0 < low_leg, "{top_mid} {low_leg}");
    // One scale both ways: the arms hang at x = ±0.18 m (0.36 m apart) and
    // the longest vertical bone is the thigh, 0.42 m (body/tempus.rs).
    let verticals = |colour: &str| -> Vec<(f64, f64)> {
        front
            .iter()
            .filter(|(c, p)| c == colour && p.len() == 2 && p[0].0 == p[1].0)
            .map(|(_, p)| (p[0].0, (p[0].1 - p[1].1).abs()))
            .collect()
    };
    let (lv, rv) = (verticals(BLUE), verticals(RED));
    let arms_apart = lv.iter().map(|v| v.0).fold(f64::MIN, f64::max)
        - rv.iter().map(|v| v.0).fold(f64::MAX, f64::min);
    let thigh = lv.iter().map(|v| v.1).fold(0.0, f64::max);
    let ratio = arms_apart / thigh;
    assert!((ratio - 0.36 / 0.42).abs() < 0.02, "aspect {ratio}");
    if font_available() {
        for label in ["front (XY)", "side (ZY)", "top (XZ)", "perspective"] {
            assert!(svg.contains(label), "no panel label {label}");
        }
    }
}

#[test]
fn render_draws_a_pose_and_its_goals() {
    let dir = tempfile::tempdir().unwrap();
    // The tempus rest pose, every segment at its rest position, but the
    // whole figure moved 2 m along +X.
    let body = marionette_core::body::tempus::BODY;
    let world = marionette_host::cmd::render::rest_pose(&body).unwrap();
    let segments: Vec<serde_json::Value> = body
        .segments
        .iter()
        .zip(&world)
        .map(|(seg, (p, q))| {
            serde_json::json!({
                "name": seg.name,
                "position": [p.x + 2.0, p.y, p.z],
                "rotation": [q.w, q.x, q.y, q.z],
            })
        })
        .collect();
    let pose = dir.path().join("pose.json");
    std::fs::write(
        &pose,
        serde_json::json!({ "segments": segments }).to_string(),
    )
    .unwrap();
    let goals = dir.path().join("goals.json");
    std::fs::write(
        &goals,
        r#"{"goals": [{"segment": "left_hand", "target": [2.4, 1.2, 0.3], "weight": 10},
            {"segment": "right_foot", "target": [1.9, 0, 0.2], "weight": 100}]}"#,
    )
    .unwrap();
    let out = dir.path().join("posed.svg");
    let said = ok(&[
        "render",
        "--pose",
        s(&pose),
        "--goals",
        s(&goals),
        "--title",
        "two goals",
        "-o",
        s(&out),
    ]);
    assert!(said.contains("2 goals"), "{said}");
    let svg = std::fs::read_to_string(&out).unwrap();
    if font_available() {
        assert!(svg.contains("left_hand ×10"));
        assert!(svg.contains("right_foot ×100"));
        assert!(svg.contains("two goals"));
    }
    // Goal lines are dashed (many short polylines) in the goal colour.
    let dashes = polylines(&svg)
        .iter()
        .filter(|(c, _)| c == "#008C46")
        .count();
    assert!(dashes > 8, "{dashes} goal dashes");
}

#[test]
fn render_takes_the_skeleton_from_a_rig_file() {
    let dir = tempfile::tempdir().unwrap();
    let rig = concat!(env!("CARGO_MANIFEST_DIR"), "/../rigs/humanoid16.toml");
    let out = dir.path().join("rig.svg");
    let said = ok(&["render", "--rig", rig, "-o", s(&out)]);
    // At least a bone from every parent to its child.
    let segments = std::fs::read_to_string(rig)
        .unwrap()
        .lines()
        .filter(|l| l.trim() == "[[segment]]")
        .count();
    let bones: usize = said
        .split_whitespace()
        .zip(said.split_whitespace().skip(1))
        .find(|(_, w)| w.starts_with("bones"))
        .and_then(|(n, _)| n.parse().ok())
        .unwrap();
    assert!(segments > 10 && bones >= segments - 1, "{said}");
    let svg = std::fs::read_to_string(&out).unwrap();
    let lines = polylines(&svg);
    assert!(lines.iter().any(|(c, _)| c == BLUE) && lines.iter().any(|(c, _)| c == RED));
    if font_available() {
        assert!(svg.contains("humanoid16 rest pose"));
    }
    let err = fails(&["render", "--rig", "no/such/rig.toml", "-o", s(&out)]);
    assert!(err.contains("no/such/rig.toml"), "{err}");
    let err = fails(&["render", "--rig", rig, "--body", "cmu", "-o", s(&out)]);
    assert!(err.contains("cannot be used with"), "{err}");
}

#[test]
fn render_reads_the_pose_from_standard_input() {
    use std::io::Write;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("stdin.png");
    let body = marionette_core::body::tempus::BODY;
    let world = marionette_host::cmd::render::rest_pose(&body).unwrap();
    let segments: Vec<serde_json::Value> = body
        .segments
        .iter()
        .zip(&world)
        .map(|(seg, (p, q))| {
            serde_json::json!({"name": seg.name, "position": p.to_array(),
                               "rotation": [q.w, q.x, q.y, q.z]})
        })
        .collect();
    let mut child = Command::new(env!("CARGO_BIN_EXE_marionette"))
        .args(["render", "--pose", "-", "-o", s(&out)])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let json = serde_json::json!({ "segments": segments, "duration": null });
    child
        .stdin
        .take()
        .unwrap()
        .write_all(json.to_string().as_bytes())
        .unwrap();
    let done = child.wait_with_output().unwrap();
    assert!(done.status.success());
    assert_eq!(png_size(&out), (1200, 1200));
}

#[test]
fn render_refuses_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let err = fails(&["render", "-o", s(&dir.path().join("x.jpg"))]);
    assert!(err.contains("unknown picture format"), "{err}");
    let pose = dir.path().join("pose.json");
    std::fs::write(
        &pose,
        r#"{"segments":[{"name":"lower_torso","position":[0,1,0],"rotation":[1,0,0,0]}]}"#,
    )
    .unwrap();
    let err = fails(&[
        "render",
        "--pose",
        s(&pose),
        "-o",
        s(&dir.path().join("p.png")),
    ]);
    assert!(err.contains("is missing"), "{err}");
    let err = fails(&[
        "render",
        "--body",
        "cmu",
        "--pose",
        s(&pose),
        "-o",
        s(&dir.path().join("p.png")),
    ]);
    assert!(
        err.contains("lower_torso") && err.contains("--body"),
        "{err}"
    );
    let err = fails(&[
        "render",
        "--width",
        "50",
        "-o",
        s(&dir.path().join("p.png")),
    ]);
    assert!(err.contains("out of range"), "{err}");
}

#[test]
fn render_without_a_font_still_draws() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("plain.png");
    let run = Command::new(env!("CARGO_BIN_EXE_marionette"))
        .args(["render", "-o", s(&out)])
        .env("MARIONETTE_FONT", dir.path().join("no-such-font.ttf"))
        .output()
        .unwrap();
    assert!(run.status.success());
    let err = String::from_utf8(run.stderr).unwrap();
    assert!(err.contains("without text"), "{err}");
    assert_eq!(png_size(&out), (1200, 1200));
}

fn servo_csv(dir: &Path) -> std::path::PathBuf {
    let mut text = String::from("time_us,ch0,ch1,ch2\n");
    for i in 0..200u32 {
        let t = f64::from(i) / 100.0;
        let gap = if (50..60).contains(&i) {
            String::new()
        } else {
            format!("{:.1}", 1500.0 + 300.0 * t.cos())
        };
        text.push_str(&format!(
            "{},{:.1},{},{}\n",
            i * 10_000,
            1500.0 + 400.0 * (std::f64::consts::TAU * t).sin(),
            gap,
            1000 + i
        ));
    }
    let path = dir.join("servo.csv");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn plot_draws_every_or_the_chosen_columns() {
    let dir = tempfile::tempdir().unwrap();
    let csv = servo_csv(dir.path());
    let png = dir.path().join("servo.png");
    let said = ok(&["plot", s(&csv), "-o", s(&png)]);
    assert!(said.contains("3 series, 200 samples"), "{said}");
    assert_eq!(png_size(&png), (1200, 700));

    let svg = dir.path().join("servo.svg");
    ok(&[
        "plot",
        s(&csv),
        "-o",
        s(&svg),
        "--columns",
        "ch2,ch1",
        "--y-label",
        "pulse (µs)",
    ]);
    let text = std::fs::read_to_string(&svg).unwrap();
    let lines = polylines(&text);
    // ch2 is the first colour, ch1 the second; ch1 has a gap: two runs.
    let runs = |c: &str| lines.iter().filter(|(k, p)| k == c && p.len() > 20).count();
    assert_eq!(runs("#F38400"), 1, "ch2 in one line");
    assert_eq!(runs("#875692"), 2, "ch1 split at its gap");
    if font_available() {
        assert!(text.contains("ch2") && text.contains("ch1") && !text.contains(">ch0<"));
        assert!(text.contains("time (s)") && text.contains("pulse (µs)"));
    }
}

#[test]
fn plot_refuses_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let csv = servo_csv(dir.path());
    let out = dir.path().join("x.png");
    let err = fails(&["plot", s(&csv), "-o", s(&out), "--columns", "ch9"]);
    assert!(
        err.contains("no column \"ch9\"") && err.contains("ch0, ch1, ch2"),
        "{err}"
    );
    let bad = dir.path().join("bad.csv");
    std::fs::write(&bad, "time_us,a\n0,1\n10,oops\n").unwrap();
    let err = fails(&["plot", s(&bad), "-o", s(&out)]);
    assert!(err.contains("line 3") && err.contains("oops"), "{err}");
    std::fs::write(&bad, "time_us\n0\n").unwrap();
    let err = fails(&["plot", s(&bad), "-o", s(&out)]);
    assert!(err.contains("nothing to plot"), "{err}");
}

#[test]
fn flash_dry_run_prints_the_plan_or_refuses() {
    let dir = tempfile::tempdir().unwrap();
    let big = dir.path().join("big.bin");
    std::fs::write(&big, vec![0u8; 256 * 1024 + 100]).unwrap();
    let err = fails(&["flash", "--tables", s(&big), "--dry-run", "--no-check"]);
    assert!(err.contains("100 bytes too many"), "{err}");

    let junk = dir.path().join("junk.bin");
    std::fs::write(&junk, b"not a table").unwrap();
    let err = fails(&["flash", "--tables", s(&junk), "--dry-run"]);
    assert!(
        err.contains("would not arm") && err.contains("NoRig") && err.contains("--no-check"),
        "{err}"
    );
    let plan = ok(&["flash", "--tables", s(&junk), "--dry-run", "--no-check"]);
    assert!(plan.contains("0x08040000..0x0804000b"), "{plan}");
    assert!(
        plan.contains("dry run") && plan.contains("STM32F411CEUx"),
        "{plan}"
    );

    let err = fails(&["flash", "--dry-run"]);
    assert!(err.contains("nothing to flash"), "{err}");
    let err = fails(&[
        "flash",
        "--tables",
        s(&junk),
        "--dry-run",
        "--no-check",
        "--chip",
        "NOPE",
    ]);
    assert!(err.contains("NOPE"), "{err}");
}

#[test]
fn flash_dry_run_makes_the_region_and_reads_it_back_as_the_board() {
    let dir = tempfile::tempdir().unwrap();
    let rig_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../rigs/humanoid16.toml");
    let rig = marionette_host::rigfile::load(&rig_path).unwrap();
    let table = marionette_host::perform::rest_grid(&rig, &[("x", 0.0, 0.5, 3)]).unwrap();
    let table_path = dir.path().join("table.bin");
    std::fs::write(&table_path, &table).unwrap();
    // A bare table blob is refused, naming the fix.
    let err = fails(&["flash", "--tables", s(&table_path), "--dry-run"]);
    assert!(
        err.contains("bare table blob") && err.contains("--rig"),
        "{err}"
    );
    // With the rig: a region, checked before and read back after.
    let out = ok(&[
        "flash",
        "--rig",
        s(&rig_path),
        "--tables",
        s(&table_path),
        "--dry-run",
    ]);
    assert!(out.contains("table region (rig + tables)"), "{out}");
    assert!(
        out.contains("board view: region v1 (2 entries): rig `humanoid16`"),
        "{out}"
    );
    assert!(
        out.contains("read back (staged bytes over erased flash): region v1")
            && out.contains("the board arms"),
        "{out}"
    );
    // The rig alone: no table, the board's reason.
    let err = fails(&["flash", "--rig", s(&rig_path), "--dry-run"]);
    assert!(err.contains("NoTable"), "{err}");
}
