//! The reach tables' size / accuracy / build-time trade-off: the evidence
//! behind the "Held-out accuracy" figures of the synthesis issue.
//!
//! Run with `cargo run --release -p marionette-tests --example reach_tradeoff`
//! (a few minutes: `reach.toml` cross-validates nine methods per build;
//! `-- reach_humanoid16` for one spec).
//!
//! For each bundled reach spec (`data/builds/reach.toml`, 31 segments, and
//! `reach_humanoid16.toml`, the demo puppet's 13), it builds the spec as
//! shipped and with other grid resolutions, each with and without the
//! build's probe placement (`[resample] place_probe`), and prints per
//! variant: the blob size, the valid cells, the build time, and the
//! leave-one-clip-out figures of `marionette build SPEC --holdout all`
//! pooled over every held-out example: the table's hand median and
//! per-joint mean before solving, beside the nearest training example's
//! (the baseline, measured in the same run).

use std::path::Path;
use std::time::Instant;

use marionette_host::build::{self, Progress, error::Source, measure, spec};

/// Grid resolutions tried (hand x, y, z samples); the first is the shipped one.
const GRIDS: [[u16; 3]; 3] = [[4, 9, 6], [3, 5, 4], [5, 12, 8]];

/// The spec text with other axis counts and probe placement on or off.
fn variant(text: &str, counts: [u16; 3], place: bool) -> String {
    let mut out = String::new();
    let mut axis = 0;
    for line in text.lines() {
        if line.trim_start().starts_with("count = ") {
            out.push_str(&format!("count = {}\n", counts[axis.min(2)]));
            axis += 1;
        } else {
            out.push_str(line);
            out.push('\n');
            if line.trim() == "[resample]" {
                out.push_str(&format!("place_probe = {place}\n"));
            }
        }
    }
    out
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

fn run(dir: &Path, name: &str) -> Result<(), Box<dyn std::error::Error>> {
    let text = std::fs::read_to_string(dir.join(name))?;
    println!("\n{name}");
    println!(
        "| grid | placement | blob | valid cells | build | hand median | per joint | nearest: hand | nearest: per joint | per joint vs nearest |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    let progress = Progress::new(false);
    for counts in GRIDS {
        for place in [true, false] {
            let source = Source {
                file: name.to_owned(),
                text: variant(&text, counts, place),
            };
            let spec = spec::parse(source, dir.to_path_buf())?;
            let data = build::load(&spec, &progress)?;
            let t0 = Instant::now();
            let built = build::build(&spec, &data, None, &progress)?;
            let seconds = t0.elapsed().as_secs_f64() + data.load_seconds;
            let rows = (0..data.groups.len())
                .map(|g| measure::holdout(&spec, &data, g, &progress))
                .collect::<Result<Vec<_>, _>>()?;
            let pool = |f: &dyn Fn(&measure::Holdout) -> &Vec<f64>| -> Vec<f64> {
                rows.iter().flat_map(|r| f(r).iter().copied()).collect()
            };
            let (mut hand, joint) = (pool(&|r| &r.probe_errors), pool(&|r| &r.joint_errors));
            let (mut near_hand, near_joint) = (
                pool(&|r| &r.nearest.probe_errors),
                pool(&|r| &r.nearest.joint_errors),
            );
            let r = &built.report;
            println!(
                "| {}×{}×{} | {} | {} B | {}/{} | {:.2} s | {:.1} mm | {:.1} mm | {:.1} mm | {:.1} mm | {:+.1} % |",
                counts[0],
                counts[1],
                counts[2],
                if place { "on" } else { "off" },
                r.bytes,
                r.valid_cells,
                r.cells,
                seconds,
                1e3 * median(&mut hand),
                1e3 * mean(&joint),
                1e3 * median(&mut near_hand),
                1e3 * mean(&near_joint),
                100.0 * (mean(&joint) / mean(&near_joint) - 1.0),
            );
        }
    }
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/builds");
    let only = std::env::args().nth(1);
    for name in ["reach_humanoid16.toml", "reach.toml"] {
        if only.as_deref().is_none_or(|o| name.starts_with(o)) {
            run(&dir, name)?;
        }
    }
    Ok(())
}
