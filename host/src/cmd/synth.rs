//! `marionette synth BLOB --at p1,p2,... [--phase X] [--json]`: synthesize a
//! pose with the core, reading the blob in place.
//!
//! JSON output (a contract, exactly these keys):
//! `{"segments":[{"name","position":[x,y,z],"rotation":[w,x,y,z]}],"duration":s|null}`
//! — positions in metres, rotations unit quaternions `[w, x, y, z]`;
//! `duration` is the interpolated motion's total duration in seconds for a
//! clip table, null for a grid. A looping clip table adds `"travel":[x,y,z]`,
//! the root's displacement per cycle in metres (the clip frame: y up, z the
//! direction of travel). `clamped` is true when the parameters were clamped
//! to the axes, or the phase to a one-shot motion's `[0, phases]`;
//! `projected` when they fell in an invalid cell and were projected onto the
//! data. When the parameters were clamped to the axes
//! or projected out of an invalid cell, a note goes to stderr.

use std::fmt::Write as _;
use std::path::PathBuf;

use marionette_core::grid::Adjust;
use marionette_core::table::Table;
use serde_json::json;

use super::CmdError;
use super::inspect::short;
use crate::build::query::{self, Synth};

/// Arguments of `marionette synth`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The table blob.
    pub blob: PathBuf,
    /// Parameter values, one per parameter axis, comma-separated.
    #[arg(
        long,
        value_delimiter = ',',
        allow_hyphen_values = true,
        required = true
    )]
    pub at: Vec<f32>,
    /// Clip tables: the phase in [0, phases] (default 0).
    #[arg(long, allow_hyphen_values = true)]
    pub phase: Option<f32>,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// Runs the synthesis.
pub fn run(args: &Args) -> Result<(), CmdError> {
    let bytes = super::inspect::read_blob(&args.blob)?;
    let table = Table::parse(&bytes).map_err(|e| format!("{}: {e}", args.blob.display()))?;
    if args.phase.is_some() && table.kind() == marionette_core::table::Kind::Grid {
        return Err("--phase is for clip tables; this is a grid table".into());
    }
    let s = query::synthesize(&table, &args.at, args.phase)?;
    if s.adjust != Adjust::None {
        let how = if s.adjust == Adjust::Clamped {
            "clamped to the axes"
        } else {
            "projected into the valid region"
        };
        eprintln!("marionette: parameters {how}: {:?}", s.params);
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&to_json(&table, &s))?);
    } else {
        print!("{}", text(&table, &s));
    }
    Ok(())
}

/// The contract's JSON.
#[must_use]
pub fn to_json(table: &Table<'_>, s: &Synth) -> serde_json::Value {
    let segments: Vec<_> = s
        .pose
        .iter()
        .enumerate()
        .map(|(i, (p, q))| {
            let position = [p.x, p.y, p.z].map(short);
            let rotation = [q.w, q.x, q.y, q.z].map(short);
            json!({
                "name": table.segment_name(i).unwrap_or(""),
                "position": position,
                "rotation": rotation,
            })
        })
        .collect();
    let mut out = json!({
        "segments": segments,
        "duration": s.duration.map(short),
        "clamped": s.adjust == Adjust::Clamped,
        "projected": s.adjust == Adjust::Projected,
    });
    if let (Some(t), Some(map)) = (s.travel, out.as_object_mut()) {
        map.insert("travel".into(), json!(t.map(short)));
    }
    out
}

fn text(table: &Table<'_>, s: &Synth) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{:<24} {:>27}   {:>35}",
        "segment", "position (m)", "rotation [w, x, y, z]"
    );
    for (i, (p, q)) in s.pose.iter().enumerate() {
        let _ = writeln!(
            out,
            "{:<24} {:>8.4} {:>8.4} {:>8.4}   {:>8.5} {:>8.5} {:>8.5} {:>8.5}",
            table.segment_name(i).unwrap_or(""),
            p.x,
            p.y,
            p.z,
            q.w,
            q.x,
            q.y,
            q.z
        );
    }
    if let Some(d) = s.duration {
        let per: Vec<String> = s.durations.iter().map(|d| format!("{d:.3}")).collect();
        let _ = writeln!(out, "duration: {d:.3} s (phases: {} s)", per.join(", "));
    }
    if let Some([x, y, z]) = s.travel {
        let _ = writeln!(out, "travel per cycle: {x:.4} {y:.4} {z:.4} m");
    }
    out
}
