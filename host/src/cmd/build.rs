//! `marionette build SPEC -o tables.bin`: build a table blob from mocap or a
//! JSON example set (see [`crate::build`]), print what was measured, and
//! optionally measure held-out error (`--holdout CLIP|all`).
//!
//! With a rig file, it says what the live loop's deadline leaves the
//! solver with this table at the rig's frame period (a `deadline` line;
//! `deadline` in `--json`: `period_us`, `synthesis_instructions`,
//! `sensors`, `solver_left`, `solver_floor`, `keeps_period`; see
//! [`crate::period`]), and warns when the rig's frames would run over it.
//!
//! A looping clip table reports each clip's seam (a `seam` line; `seams` in
//! `--json`: `clip`, `given` and `chosen` cut `[first, last]`, `search`,
//! `window`, `jump_given_m`, `jump_chosen_m`, `step_m`; see
//! [`crate::build::mocap::Seam`]).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use serde_json::json;

use super::CmdError;
use crate::board::Board;
use crate::build::{self, Built, Dataset, Progress, examples, measure, spec};
use crate::capacity;

/// Arguments of `marionette build`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The build spec (`.toml`; docs/spec.md), or a JSON example set (`.json`; docs/example-set.md).
    pub spec: PathBuf,
    /// Where to write the table blob.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Leave this clip out (name or file stem, or `all` for each in turn),
    /// build from the rest and report the error of synthesizing at its
    /// parameters.
    #[arg(long)]
    pub holdout: Option<String>,
    /// Also write the examples (after retargeting and normalization) as a
    /// JSON example set.
    #[arg(long)]
    pub examples_out: Option<PathBuf>,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
    /// Never draw a progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// The board the table is for: its table region must hold it (without
    /// this, any board's).
    #[arg(long, value_parser = ["emulated", "blackpill"])]
    pub board: Option<String>,
}

/// Every file a spec reads: none of them may be overwritten.
fn spec_inputs(spec: &spec::Spec, spec_path: &Path) -> Vec<(String, PathBuf)> {
    let mut out = vec![("the build spec".to_owned(), spec_path.to_path_buf())];
    match &spec.input {
        spec::Input::Examples(p) => out.push(("the example set".into(), p.clone())),
        spec::Input::Mocap(m) => {
            if let Some(s) = &m.skeleton {
                out.push(("the skeleton".into(), s.clone()));
            }
            for c in &m.clips {
                out.push((format!("clip {}", c.name), c.file.clone()));
            }
        }
    }
    if let Some(r) = &spec.rig.file {
        out.push(("the rig file".into(), r.clone()));
    }
    out
}

/// Writes `bytes` to `path` unless it is one of `inputs`.
fn save(path: &Path, bytes: &[u8], inputs: &[(String, PathBuf)]) -> Result<(), CmdError> {
    let inputs: Vec<(&str, &Path)> = inputs
        .iter()
        .map(|(w, p)| (w.as_str(), p.as_path()))
        .collect();
    Ok(crate::save::save(path, bytes, &inputs)?)
}

/// The table's size against each board (or the one asked for); an error if
/// none (or not that one) can hold it.
fn board_fit(
    bytes: usize,
    rig_blob: u64,
    board: Option<&Board>,
) -> Result<Vec<(Board, bool, u64)>, CmdError> {
    let fits = capacity::fits(bytes as u64, rig_blob);
    let ok = fits
        .iter()
        .any(|(b, fit, _)| *fit && board.is_none_or(|want| want.key == b.key));
    if ok {
        return Ok(fits);
    }
    let regions: Vec<String> = fits
        .iter()
        .map(|(b, _, _)| format!("{} {} B", b.key, b.table_region))
        .collect();
    Err(format!(
        "the table is {bytes} B, more than {} ({}); nothing was written",
        board.map_or("every board's table region".into(), |b| format!(
            "{}'s table region",
            b.key
        )),
        regions.join(", ")
    )
    .into())
}

/// Runs the build.
pub fn run(args: &Args) -> Result<(), CmdError> {
    if args.output.is_none() && args.holdout.is_none() && args.examples_out.is_none() {
        return Err("nothing to do: give -o FILE, --holdout CLIP or --examples-out FILE".into());
    }
    let start = Instant::now();
    let board = args.board.as_deref().and_then(Board::by_key);
    let spec = read_spec(&args.spec)?;
    let inputs = spec_inputs(&spec, &args.spec);
    for out in [&args.output, &args.examples_out].into_iter().flatten() {
        let inputs: Vec<(&str, &Path)> = inputs
            .iter()
            .map(|(w, p)| (w.as_str(), p.as_path()))
            .collect();
        crate::save::check(out, &inputs)?;
    }
    if args.output.is_some() {
        capacity::check_spec(&spec, board.as_ref())?;
    }
    let progress = Progress::new(!args.quiet);
    let data = build::load(&spec, &progress)?;
    if args.output.is_some() {
        capacity::check_dataset(&spec, &data, board.as_ref())?;
    }
    for w in &data.warnings {
        eprintln!("warning: {w}");
    }
    if let Some(path) = &args.examples_out {
        write_examples(&data, path, &inputs)?;
    }
    let mut report = serde_json::Map::new();
    if let Some(out) = &args.output {
        let built = build::build(&spec, &data, None, &progress)?;
        let fits = board_fit(
            built.blob.len(),
            capacity::rig_blob_bytes(&spec),
            board.as_ref(),
        )?;
        save(out, &built.blob, &inputs)?;
        progress.finish();
        let total = start.elapsed().as_secs_f64();
        let period = deadline(&spec, &built.blob);
        if args.json {
            let mut doc = build_json(&built, &data, out, total);
            doc["boards"] = fits_json(&fits);
            if let Some(p) = &period {
                doc["deadline"] = serde_json::to_value(p)?;
            }
            report.insert("build".into(), doc);
        } else {
            print!("{}", build_text(&args.spec, out, &built, &data, total));
            print!("{}", fits_text(&fits));
            if let Some(p) = &period {
                println!("  {}", p.text());
            }
        }
        if let Some(p) = period.filter(|p| !p.keeps_period) {
            eprintln!(
                "warning: with this table the rig's frames leave the solver {} instructions, less than the {} it needs: on the board they run over the rig's {} µs period (a coarser or linear table, or a longer frame_period_us)",
                p.solver_left, p.solver_floor, p.period_us
            );
        }
    }
    if let Some(which) = &args.holdout {
        let groups = holdout_groups(&data, which)?;
        let rows = groups
            .iter()
            .enumerate()
            .map(|(k, &g)| {
                let name = &data.groups[g];
                progress.set_prefix(&format!("hold-out {}/{} ({name}): ", k + 1, groups.len()));
                measure::holdout(&spec, &data, g, &progress)
            })
            .collect::<Result<Vec<_>, _>>()?;
        progress.finish();
        if args.json {
            report.insert("holdout".into(), serde_json::to_value(&rows)?);
            report.insert("holdout_pooled".into(), pooled_json(&rows));
        } else {
            print!("{}", holdout_text(&rows));
        }
    }
    if args.json {
        if !data.warnings.is_empty() {
            report.insert("warnings".into(), json!(data.warnings));
        }
        println!("{}", serde_json::to_string_pretty(&report)?);
    }
    Ok(())
}

/// What the deadline leaves the spec's rig with the table `blob`
/// ([`crate::period`]); `None` without a rig file.
fn deadline(spec: &spec::Spec, blob: &[u8]) -> Option<crate::period::Period> {
    let rig = crate::rigfile::load(spec.rig.file.as_ref()?).ok()?;
    let rig_blob = crate::rigfile::to_blob(&rig).ok()?;
    crate::period::Period::of(&crate::perform::region(&rig_blob, Some(blob)))
}

fn read_spec(path: &std::path::Path) -> Result<spec::Spec, CmdError> {
    let is_json = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"));
    if !is_json {
        return Ok(spec::read(path)?);
    }
    // A bare example set: a grid spec with every default.
    let source = build::error::Source {
        file: format!("{} (implied spec)", path.display()),
        text: String::new(),
    };
    let name = path
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    let text = format!("examples = {}\n", toml_string(&name));
    let dir = path
        .parent()
        .map(std::path::Path::to_path_buf)
        .unwrap_or_default();
    Ok(spec::parse(build::error::Source { text, ..source }, dir)?)
}

fn toml_string(s: &str) -> String {
    serde_json::to_string(s).unwrap_or_default()
}

fn holdout_groups(data: &Dataset, which: &str) -> Result<Vec<usize>, CmdError> {
    if which == "all" {
        return Ok((0..data.groups.len()).collect());
    }
    let hits: Vec<usize> = (0..data.groups.len())
        .filter(|&g| data.groups[g].contains(which))
        .collect();
    match hits.as_slice() {
        [one] => Ok(vec![*one]),
        [] => Err(format!(
            "--holdout {which}: no clip matches (clips: {})",
            data.groups.join(", ")
        )
        .into()),
        _ => {
            let names: Vec<&str> = hits.iter().map(|&g| data.groups[g].as_str()).collect();
            Err(format!(
                "--holdout {which}: several clips match ({})",
                names.join(", ")
            )
            .into())
        }
    }
}

/// The table's fit per board, as text.
fn fits_text(fits: &[(Board, bool, u64)]) -> String {
    let mut s = String::from("  boards (table region: rig blob + table must fit):");
    for (b, fit, used) in fits {
        let _ = write!(
            s,
            " {} {} ({used} of {} B);",
            b.key,
            if *fit { "fits" } else { "does NOT fit" },
            b.table_region
        );
    }
    s.pop();
    s.push('\n');
    s
}

/// The table's fit per board, as JSON.
fn fits_json(fits: &[(Board, bool, u64)]) -> serde_json::Value {
    fits.iter()
        .map(|(b, fit, used)| {
            json!({ "board": b.key, "fits": fit, "table_bytes": used, "region_bytes": b.table_region })
        })
        .collect()
}

fn write_examples(
    data: &Dataset,
    path: &std::path::Path,
    inputs: &[(String, PathBuf)],
) -> Result<(), CmdError> {
    if data.layout != build::Layout::Grid {
        return Err("--examples-out: only grid builds have single-pose examples".into());
    }
    let set = examples::ExampleSet {
        segments: data.segments.clone(),
        axes: data.axes.clone(),
        examples: data
            .records
            .iter()
            .map(|r| examples::Example {
                params: r.params.clone(),
                pose: r.value.poses.clone(),
            })
            .collect(),
    };
    let text = serde_json::to_string(&examples::to_json(&set))?;
    save(path, text.as_bytes(), inputs)
}

fn mm(m: f64) -> String {
    format!("{:.1} mm", m * 1000.0)
}

fn build_text(
    spec: &std::path::Path,
    out: &std::path::Path,
    b: &Built,
    data: &Dataset,
    total: f64,
) -> String {
    let r = &b.report;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "built {} -> {} ({} bytes)",
        spec.display(),
        out.display(),
        r.bytes
    );
    let _ = writeln!(
        s,
        "  examples: {} from {} group(s); {} segments; rig hash {:#018x}",
        r.examples,
        r.groups,
        data.segments.len(),
        data.rig_hash
    );
    if r.scores.is_empty() {
        let _ = writeln!(
            s,
            "  resampling: {} (too few groups to cross-validate)",
            r.method
        );
    } else {
        let _ = writeln!(
            s,
            "  resampling, cross-validated (each group held out in turn; mean per-joint position error, median hand error, mean rotation error):"
        );
        for sc in &r.scores {
            let mark = if sc.method == r.method { "*" } else { " " };
            let probe = sc.median_probe.map_or_else(|| "-".to_owned(), mm);
            let _ = writeln!(
                s,
                "   {mark} {:<30} {:>9} {:>9} {:>7.2}°",
                sc.method.to_string(),
                mm(sc.mean_position),
                probe,
                sc.mean_rotation.to_degrees()
            );
        }
    }
    let axes: Vec<String> = b
        .table
        .axes
        .iter()
        .map(|a| format!("{} {}+{}×{}", a.name, a.min, a.step, a.count))
        .collect();
    let _ = writeln!(
        s,
        "  grid: {}; {} grid samples; valid cells {}/{}; {} samples taken exactly from examples",
        axes.join(", "),
        r.grid_samples,
        r.valid_cells,
        r.cells,
        r.exact
    );
    if let Some(tried) = r.place_tried {
        let _ = writeln!(
            s,
            "  probe placed: {} of {} resampled grid poses solved so the probe sits on its grid point (the rest stay as resampled: beyond the rig's reach)",
            r.placed, tried
        );
    }
    let per_sample = marionette_core::table::SAMPLE_LEN;
    let _ = writeln!(
        s,
        "  size: {} bytes per segment sample × {} segments × {} grid samples = {} bytes of samples; blob {} bytes",
        per_sample,
        data.segments.len(),
        r.grid_samples,
        per_sample * data.segments.len() * r.grid_samples,
        r.bytes
    );
    let q = &r.quant;
    let _ = writeln!(
        s,
        "  quantization vs the unquantized table: stored samples max {:.4} mm (bound {:.4} mm), {:.5}° (bound {:.5}°); synthesized at {} points max {:.4} mm, {:.5}°",
        q.max_position * 1000.0,
        q.position_bound * 1000.0,
        q.max_rotation.to_degrees(),
        q.rotation_bound.to_degrees(),
        q.synth_points,
        q.synth_max_position * 1000.0,
        q.synth_max_rotation.to_degrees()
    );
    if let Some(c) = &r.reconstruction {
        let _ = writeln!(
            s,
            "  source clips synthesized back at their own parameters ({} source frames): per-joint mean {}, max {}, rotation mean {:.2}°",
            c.frames,
            mm(c.mean_joint),
            mm(c.max_joint),
            c.mean_rotation.to_degrees()
        );
    }
    for seam in &data.seams {
        let [a, b] = seam.given;
        let [c, d] = seam.chosen;
        let _ = writeln!(
            s,
            "  seam {}: cut {a}..{b} -> {c}..{d} (searched ±{} frames): joint jump at the seam {} -> {} (mean frame step {}); blended over {} frames at each end",
            seam.clip,
            seam.search,
            mm(seam.jump_given),
            mm(seam.jump_chosen),
            mm(seam.step),
            seam.window
        );
    }
    let [import, cv, grid, write] = r.seconds;
    let _ = writeln!(
        s,
        "  time: import {import:.2} s, cross-validation {cv:.2} s, resampling {grid:.2} s, writing + measuring {write:.2} s; total {total:.2} s"
    );
    s
}

fn build_json(b: &Built, data: &Dataset, out: &std::path::Path, total: f64) -> serde_json::Value {
    let r = &b.report;
    let scores: Vec<_> = r
        .scores
        .iter()
        .map(|s| {
            json!({
                "method": s.method.to_string(),
                "mean_position_m": s.mean_position,
                "median_probe_m": s.median_probe,
                "mean_rotation_rad": s.mean_rotation,
            })
        })
        .collect();
    json!({
        "output": out.display().to_string(),
        "bytes": r.bytes,
        "examples": r.examples,
        "groups": r.groups,
        "segments": data.segments.len(),
        "method": r.method.to_string(),
        "cross_validation": scores,
        "grid_samples": r.grid_samples,
        "cells": r.cells,
        "valid_cells": r.valid_cells,
        "exact_samples": r.exact,
        "placed_samples": r.placed,
        "sample_bytes": marionette_core::table::SAMPLE_LEN,
        "quantization": r.quant,
        "reconstruction": r.reconstruction,
        "seams": data.seams.iter().map(|m| json!({
            "clip": m.clip, "given": m.given, "chosen": m.chosen, "search": m.search,
            "window": m.window, "jump_given_m": m.jump_given, "jump_chosen_m": m.jump_chosen,
            "step_m": m.step,
        })).collect::<Vec<_>>(),
        "seconds": {
            "import": r.seconds[0], "cross_validation": r.seconds[1],
            "resampling": r.seconds[2], "writing": r.seconds[3], "total": total,
        },
    })
}

/// Every held-out example of every row, pooled: the table's and the
/// nearest example's hand median and per-joint mean.
struct Pooled {
    examples: usize,
    hand: Option<f64>,
    joint: f64,
    nearest_hand: Option<f64>,
    nearest_joint: f64,
}

fn pooled(rows: &[measure::Holdout]) -> Pooled {
    let pool = |f: &dyn Fn(&measure::Holdout) -> &Vec<f64>| -> Vec<f64> {
        rows.iter().flat_map(|r| f(r).iter().copied()).collect()
    };
    let (mut tp, tj) = (pool(&|r| &r.probe_errors), pool(&|r| &r.joint_errors));
    let (mut np, nj) = (
        pool(&|r| &r.nearest.probe_errors),
        pool(&|r| &r.nearest.joint_errors),
    );
    Pooled {
        examples: tj.len(),
        hand: build::resample::median(&mut tp),
        joint: build::resample::mean(&tj),
        nearest_hand: build::resample::median(&mut np),
        nearest_joint: build::resample::mean(&nj),
    }
}

fn pooled_json(rows: &[measure::Holdout]) -> serde_json::Value {
    let p = pooled(rows);
    json!({
        "examples": p.examples,
        "median_probe_m": p.hand,
        "mean_joint_m": p.joint,
        "nearest": {"median_probe_m": p.nearest_hand, "mean_joint_m": p.nearest_joint},
    })
}

fn holdout_text(rows: &[measure::Holdout]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "hold-out (build without the clip, synthesize with the core at its examples' parameters):"
    );
    let _ = writeln!(
        s,
        "  {:<40} {:>5} {:>11} {:>11} {:>11} {:>11} {:>11} {:>11} {:>5}  method",
        "clip",
        "n",
        "hand med",
        "joint mean",
        "solved hand",
        "solved jnt",
        "near hand",
        "near jnt",
        "proj"
    );
    let opt = |v: Option<f64>| v.map_or_else(|| "-".to_owned(), mm);
    let mut all_probe = Vec::new();
    let mut all_joint = Vec::new();
    let mut all_solved = Vec::new();
    for r in rows {
        let _ = writeln!(
            s,
            "  {:<40} {:>5} {:>11} {:>11} {:>11} {:>11} {:>11} {:>11} {:>5}  {}",
            r.clip,
            r.examples,
            opt(r.median_probe),
            mm(r.mean_joint),
            opt(r.solved.map(|x| x.median_probe)),
            opt(r.solved.map(|x| x.mean_joint)),
            opt(r.nearest.median_probe),
            mm(r.nearest.mean_joint),
            r.projected,
            r.method
        );
        if let Some(d) = r.duration_error {
            let _ = writeln!(s, "    duration error {:.1} %", d * 100.0);
        }
        all_probe.extend(r.median_probe);
        all_joint.push(r.mean_joint);
        all_solved.extend(r.solved.map(|x| x.mean_joint));
    }
    if rows.len() > 1 {
        let p = pooled(rows);
        let _ = writeln!(
            s,
            "  all {} held-out examples: table hand median {}, per-joint mean {}; nearest example hand median {}, per-joint mean {} (table {:+.1} %)",
            p.examples,
            opt(p.hand),
            mm(p.joint),
            opt(p.nearest_hand),
            mm(p.nearest_joint),
            100.0 * (p.joint / p.nearest_joint - 1.0),
        );
        let mean = |v: &[f64]| (!v.is_empty()).then(|| build::resample::mean(v));
        let _ = writeln!(
            s,
            "  mean over clips: hand median {}, per-joint mean {}, per-joint after solving {}",
            opt(mean(&all_probe)),
            mm(build::resample::mean(&all_joint)),
            opt(mean(&all_solved))
        );
    }
    s
}
