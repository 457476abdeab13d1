//! `marionette inspect BLOB [--rig RIG] [--json]`: a table blob's header and
//! sizes, and with `--rig` whether the rig and the table arm a board together
//! (exit status 3 if no board would arm, with the reason; the JSON's
//! `arming` object, see [`arming`]).
//!
//! JSON keys (a contract): `bytes`, `version`, `kind` (`"grid"` |
//! `"clips"`), `phases` (clips) or null, `rig_hash` (hex string), `axes`
//! (`name`, `min`, `max`, `step`, `count`, `cyclic`, `cubic`; `max` is the
//! last sample, or `min` + period on a cyclic axis), `segments` (names),
//! `sample_bytes` (bytes per segment sample, 12), `pose_bytes` (per grid
//! sample), `grid_samples`, `param_samples`, `cells`, `valid_cells`,
//! `sections` (bytes: `header` = prefix, postcard header and padding before
//! the arrays; `samples`, `valid`, `durations`, `crc`),
//! `position_scale` (m per LSB), `position_bound_m`, `rotation_bound_rad`,
//! `durations` (`min`, `max` seconds, or null for a grid).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use marionette_core::region::{self, Region};
use marionette_core::table::{Kind, SAMPLE_LEN, Table, Wrap};
use marionette_core::wire::StatusReason;
use serde_json::json;

use super::CmdError;
use crate::board::BOARDS;
use crate::{capacity, refusal};

/// Arguments of `marionette inspect`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The table blob.
    pub blob: PathBuf,
    /// Also say whether this rig file and the table arm a board together,
    /// and why not (the core's own check, then each board's capacity).
    #[arg(long)]
    pub rig: Option<PathBuf>,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// Whether a rig and a table arm the boards together, as JSON: `rig`
/// (file), `rig_hash`, `table_rig_hash`, `arms` (the core's check, as the
/// firmware runs it), `reason`, `explanation`, `detail`, `advice`,
/// `boards` (`board`, `arms`, `reason`, `detail`, `region_bytes`),
/// `deadline` (what the rig's period leaves the solver with this table,
/// [`crate::period::Period`]; null when the core would not arm); and the
/// refusal when the core would not arm, or no board would.
pub fn arming(
    rig_path: &Path,
    table: &[u8],
) -> Result<(serde_json::Value, Option<refusal::Stop>), CmdError> {
    let rig = crate::rigfile::load(&crate::rigfile::resolve(rig_path))?;
    let rig_blob = crate::rigfile::to_blob(&rig)?;
    let region = crate::perform::region(&rig_blob, Some(table));
    let reason = Region::parse(&region).reason;
    let (what, advice) = refusal::explain(reason);
    let boards: Vec<_> = BOARDS
        .iter()
        .map(|b| {
            let stop = refusal::precheck(b.key, &region, b);
            let used = capacity::region_bytes(rig_blob.len() as u64, table.len() as u64);
            let too_big = used > b.table_region as u64;
            let (arms, why, detail) = match (&stop, too_big) {
                (None, false) => (true, "Ok".to_owned(), None),
                (None, true) => (
                    false,
                    "TooLarge".to_owned(),
                    Some(format!(
                        "{used} B exceed its {} B table region",
                        b.table_region
                    )),
                ),
                (Some(s), _) => match &s.problem {
                    refusal::Problem::Refused { reason, detail } => {
                        (false, format!("{reason:?}"), detail.clone())
                    }
                    refusal::Problem::Fault { what } => (false, "Fault".into(), Some(what.clone())),
                },
            };
            json!({ "board": b.key, "arms": arms, "reason": why, "detail": detail,
                    "region_bytes": [used, b.table_region] })
        })
        .collect();
    let table_hash = Table::parse(table)
        .map(|t| format!("{:#018x}", t.rig_hash()))
        .ok();
    // The core's refusal first; else, if no board arms, the emulated one's.
    let stop = if reason == StatusReason::Ok {
        let none_arms = boards.iter().all(|b| b["arms"] != true);
        none_arms
            .then(|| refusal::precheck(BOARDS[0].name, &region, &BOARDS[0]))
            .flatten()
    } else {
        Some(refusal::Stop::refused("a board", reason, &region, None))
    }
    .map(refusal::Stop::foreseen);
    let doc = json!({
        "rig": rig.file,
        "rig_hash": format!("{:#018x}", rig.rig_hash()),
        "table_rig_hash": table_hash,
        "arms": reason == StatusReason::Ok,
        "reason": format!("{reason:?}"),
        "explanation": what,
        "detail": refusal::detail(reason, &region, None),
        "advice": if reason == StatusReason::Ok { "" } else { advice },
        "boards": boards,
        "deadline": crate::period::Period::of(&region),
    });
    Ok((doc, stop))
}

/// What a file that is not a table blob is, when it is a rig blob or a
/// region image (a rig blob and a table, as flashed) instead.
fn what_else(bytes: &[u8]) -> Option<String> {
    match (region::layout(bytes), refusal::blobs(bytes)) {
        (region::Layout::Unknown, _) => None,
        (region::Layout::Legacy, (Some(rig), None)) => {
            Some(format!("it is a rig blob ({} B), not a table", rig.len()))
        }
        (_, (rig, table)) => Some(format!(
            "it is a region image (a rig blob of {} B and a table of {} B), as flashed; \
             inspect the table blob `marionette build -o` wrote",
            rig.map_or(0, <[u8]>::len),
            table.map_or(0, <[u8]>::len)
        )),
    }
}

/// An `f32` as the `f64` of its shortest decimal form (0.4, not
/// 0.4000000059604645), so JSON shows what the table stores.
#[must_use]
pub fn short(x: f32) -> f64 {
    x.to_string().parse().unwrap_or(f64::from(x))
}

/// Reads a blob file.
pub fn read_blob(path: &std::path::Path) -> Result<Vec<u8>, CmdError> {
    std::fs::read(path).map_err(|e| format!("{}: cannot read: {e}", path.display()).into())
}

/// Runs the inspection.
pub fn run(args: &Args) -> Result<(), CmdError> {
    let bytes = read_blob(&args.blob)?;
    let table = Table::parse(&bytes).map_err(|e| match what_else(&bytes) {
        Some(other) => format!("{}: {e}: {other}", args.blob.display()),
        None => format!("{}: {e}", args.blob.display()),
    })?;
    let mut v = describe(&table);
    let arm = match &args.rig {
        Some(rig) => Some(arming(rig, &bytes)?),
        None => None,
    };
    if args.json {
        if let Some((a, _)) = &arm {
            v["arming"] = a.clone();
        }
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        print!("{}", text(&args.blob, &v));
        if let Some((a, _)) = &arm {
            print!("{}", arming_text(a));
        }
    }
    match arm.and_then(|(_, stop)| stop) {
        Some(stop) => Err(Box::new(stop)),
        None => Ok(()),
    }
}

/// The JSON description of a table.
#[must_use]
pub fn describe(t: &Table<'_>) -> serde_json::Value {
    let h = t.header();
    let axes: Vec<_> = t
        .axes()
        .iter()
        .map(|a| {
            let (max, cyclic) = match a.wrap {
                Wrap::Bounded => (a.min + a.step * f32::from(a.count - 1), false),
                Wrap::Cyclic { period } => (a.min + period, true),
            };
            json!({
                "name": a.name().unwrap_or(""), "min": short(a.min), "max": short(max), "step": short(a.step),
                "count": a.count, "cyclic": cyclic,
                "cubic": a.interp == marionette_core::table::Interp::CatmullRom,
            })
        })
        .collect();
    let segments: Vec<&str> = (0..t.segment_count())
        .map(|i| t.segment_name(i).unwrap_or(""))
        .collect();
    let valid = (0..t.param_cells())
        .filter(|&c| t.cell_valid(c) == Some(true))
        .count();
    let (kind, phases) = match t.kind() {
        Kind::Grid => ("grid", None),
        Kind::Clips { phases } => ("clips", Some(phases)),
    };
    let durations = phases.map(|p| {
        let all: Vec<f32> = (0..t.param_samples())
            .flat_map(|i| (0..usize::from(p)).filter_map(move |k| t.duration(i, k)))
            .collect();
        json!({
            "min": short(all.iter().copied().fold(f32::INFINITY, f32::min)),
            "max": short(all.iter().copied().fold(0.0_f32, f32::max)),
        })
    });
    json!({
        "bytes": t.len(),
        "version": marionette_core::table::VERSION,
        "kind": kind,
        "phases": phases,
        "rig_hash": format!("{:#018x}", t.rig_hash()),
        "axes": axes,
        "segments": segments,
        "sample_bytes": SAMPLE_LEN,
        "pose_bytes": SAMPLE_LEN * t.segment_count(),
        "grid_samples": t.grid_samples(),
        "param_samples": t.param_samples(),
        "cells": t.param_cells(),
        "valid_cells": valid,
        "sections": {
            "header": h.samples.offset,
            "samples": h.samples.len,
            "valid": h.valid.len,
            "durations": h.durations.len,
            "crc": marionette_core::table::CRC_LEN,
        },
        "position_scale": short(h.position_scale),
        "position_bound_m": short(h.position_bound),
        "rotation_bound_rad": short(h.rotation_bound),
        "durations": durations,
    })
}

/// The arming verdict as text.
fn arming_text(a: &serde_json::Value) -> String {
    let mut s = String::new();
    let str_of = |k: &str| a[k].as_str().unwrap_or("").to_owned();
    let _ = writeln!(
        s,
        "with rig {} (hash {}; the table's {}):",
        str_of("rig"),
        str_of("rig_hash"),
        a["table_rig_hash"].as_str().unwrap_or("?")
    );
    if a["arms"] == true {
        let _ = writeln!(s, "  rig + table: Ok (the core arms)");
        let period: Option<crate::period::Period> =
            serde_json::from_value(a["deadline"].clone()).ok();
        if let Some(p) = period {
            let _ = writeln!(s, "  {}", p.text());
        }
    } else {
        let detail = a["detail"]
            .as_str()
            .map_or_else(String::new, |d| format!(" ({d})"));
        let _ = writeln!(
            s,
            "  rig + table: {}: {}{detail}\n  what to do: {}",
            str_of("reason"),
            str_of("explanation"),
            str_of("advice")
        );
    }
    for b in a["boards"].as_array().into_iter().flatten() {
        let used = &b["region_bytes"];
        let verdict = if b["arms"] == true {
            "arms".to_owned()
        } else {
            let detail = b["detail"]
                .as_str()
                .map_or_else(String::new, |d| format!(" ({d})"));
            format!("refuses: {}{detail}", b["reason"].as_str().unwrap_or(""))
        };
        let _ = writeln!(
            s,
            "  {:<10} {verdict}; region {} of {} B",
            b["board"].as_str().unwrap_or(""),
            used[0],
            used[1]
        );
    }
    s
}

fn text(path: &std::path::Path, v: &serde_json::Value) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{}: table blob v{}, {} bytes",
        path.display(),
        v["version"],
        v["bytes"]
    );
    let kind = v["kind"].as_str().unwrap_or("");
    match v["phases"].as_u64() {
        Some(p) => {
            let _ = writeln!(
                s,
                "  kind: {kind} ({p} phase(s)); rig hash {}",
                v["rig_hash"].as_str().unwrap_or("")
            );
        }
        None => {
            let _ = writeln!(
                s,
                "  kind: {kind}; rig hash {}",
                v["rig_hash"].as_str().unwrap_or("")
            );
        }
    }
    for a in v["axes"].as_array().into_iter().flatten() {
        let _ = writeln!(
            s,
            "  axis {:<24} {} .. {} step {} × {}{}{}",
            a["name"].as_str().unwrap_or(""),
            a["min"],
            a["max"],
            a["step"],
            a["count"],
            if a["cyclic"] == true { ", cyclic" } else { "" },
            if a["cubic"] == true {
                ", Catmull-Rom"
            } else {
                ""
            }
        );
    }
    let names: Vec<&str> = v["segments"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|n| n.as_str())
        .collect();
    let _ = writeln!(s, "  segments ({}): {}", names.len(), names.join(" "));
    let _ = writeln!(
        s,
        "  samples: {} grid samples × {} bytes ({} per segment sample) = {} bytes",
        v["grid_samples"], v["pose_bytes"], v["sample_bytes"], v["sections"]["samples"]
    );
    let _ = writeln!(s, "  valid cells: {} of {}", v["valid_cells"], v["cells"]);
    let _ = writeln!(
        s,
        "  sections (bytes): prefix + header + padding {}, samples {}, validity mask {}, durations {}, CRC {}",
        v["sections"]["header"],
        v["sections"]["samples"],
        v["sections"]["valid"],
        v["sections"]["durations"],
        v["sections"]["crc"]
    );
    let _ = writeln!(
        s,
        "  error bound: position {:.4} mm (scale {:.5} mm/LSB), rotation {:.5}° ({} rad)",
        v["position_bound_m"].as_f64().unwrap_or(0.0) * 1000.0,
        v["position_scale"].as_f64().unwrap_or(0.0) * 1000.0,
        v["rotation_bound_rad"].as_f64().unwrap_or(0.0).to_degrees(),
        v["rotation_bound_rad"]
    );
    if let Some(d) = v["durations"].as_object() {
        let _ = writeln!(s, "  durations: {} .. {} s", d["min"], d["max"]);
    }
    s
}
