//! `marionette sim`: the live loop run natively on a recording.
//!
//! Reads a rig file, a table blob and a tracker recording
//! (`time_us,sensor,x,y,z,qw,qx,qy,qz`), encodes the session as a host
//! would send it (compact tracker frames unless `--frame f32`), runs the
//! bytes through the core's `Performer` exactly as the firmware would, and
//! writes the servo targets per frame as CSV (`time_us,ch0,…` in µs).

use super::CmdError;
use crate::perform::{self, Framing, Run};
use crate::refusal::{self, BoardReport, Stop};
use crate::{board, import, rigfile};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Arguments of `marionette sim`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The rig file (TOML; docs/rig.md), or a rig name: `rigs/<name>.toml`
    /// here, else a rig built in (humanoid16, cmu31).
    #[arg(long, default_value = "rigs/humanoid16.toml")]
    pub rig: PathBuf,
    /// The table blob (`marionette build`); without it the rig does not arm.
    /// Repeat it for a rig with `[[layer]]` tables: table 0, 1, … in order.
    #[arg(long)]
    pub tables: Vec<PathBuf>,
    /// The tracker recording (CSV; docs/recording.md).
    #[arg(long)]
    pub recording: PathBuf,
    /// The folder to write `servo_sim.csv` into (created if missing).
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// How tracker frames travel: the compact frame (quantized) or `f32`.
    #[arg(long, value_enum, default_value_t = Framing::Compact)]
    pub frame: Framing,
    /// Also save the session as a take (docs/take.md): the input sent,
    /// the board's outputs and replies, with times.
    #[arg(long)]
    pub take: Option<PathBuf>,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

/// A summary of a run.
#[derive(Debug, Serialize)]
pub struct Summary {
    /// Tracker frames in the recording.
    pub frames: usize,
    /// Output frames driven by tracker frames.
    pub frame_outputs: usize,
    /// Easing steps to rest after the session.
    pub rest_steps: usize,
    /// Servo channels.
    pub channels: usize,
    /// Lowest and highest target per channel, µs.
    pub ranges_us: Vec<[f64; 2]>,
    /// The servo CSV written (`null` when the loop did not arm).
    pub servo_csv: Option<String>,
    /// Whether the loop armed, and if not why (see [`crate::refusal`]).
    pub board: BoardReport,
    /// Boards that would refuse this rig, with why (the native loop does
    /// not model a board's back-ends or capacity).
    pub boards_refusing: Vec<String>,
    /// Tracker frames that may run over the rig's period on the board
    /// ([`perform::Run::short_frames`]).
    pub short_frames: u32,
}

/// The inputs of a performance, loaded.
pub struct Inputs {
    /// The table-region image (rig blob + table blob).
    pub region: Vec<u8>,
    /// The session to send.
    pub session: Vec<perform::Sent>,
    /// Tracker frames in it.
    pub frames: usize,
    /// Frame times, µs.
    pub times: Vec<u32>,
    /// The rig's frame period, µs.
    pub period_us: u32,
    /// The files these came from (`(what, path)`): outputs never replace them.
    pub sources: Vec<(&'static str, PathBuf)>,
}

impl Inputs {
    /// [`Inputs::sources`] as [`crate::save`] takes them.
    #[must_use]
    pub fn source_list(&self) -> Vec<(&str, &Path)> {
        self.sources
            .iter()
            .map(|(w, p)| (*w, p.as_path()))
            .collect()
    }
}

/// Loads the rig, tables and recording into a region image and a session
/// (compact frames).
pub fn load(rig: &Path, tables: &[PathBuf], recording: &Path) -> Result<Inputs, CmdError> {
    load_with(rig, tables, recording, Framing::Compact)
}

/// [`load`] with the tracker frames framed as `framing` says.
pub fn load_with(
    rig: &Path,
    tables: &[PathBuf],
    recording: &Path,
    framing: Framing,
) -> Result<Inputs, CmdError> {
    let rig_path = rigfile::resolve(rig);
    let rig = rigfile::load(&rig_path)?;
    let mut sources = vec![
        ("the rig", rig_path),
        ("the recording", recording.to_path_buf()),
    ];
    sources.extend(tables.iter().map(|t| ("the table", t.clone())));
    let samples = import::csv::read_tracker_csv(recording)?;
    let frames = perform::frames(&samples)?;
    Ok(Inputs {
        region: rigfile::region_of_files(&rig, tables)?,
        session: perform::session_with(&frames, framing)?,
        frames: frames.len(),
        times: frames.iter().map(|f| f.time_us).collect(),
        period_us: rig.desc().frame_period_us,
        sources,
    })
}

/// Writes a run's targets as `time_us,ch0,…` (µs) to `path`.
pub fn write_servo_csv(path: &Path, inputs: &Inputs, run: &Run) -> Result<(), CmdError> {
    let channels = run.frame_targets.first().map_or(0, Vec::len);
    let mut text = String::from("time_us");
    for c in 0..channels {
        text.push_str(&format!(",ch{c}"));
    }
    text.push('\n');
    let last = inputs.times.last().copied().unwrap_or(0);
    let rest_times = (1..).map(|k: u32| last.wrapping_add(k.wrapping_mul(inputs.period_us)));
    let times = inputs.times.iter().copied().chain(rest_times);
    for (t, targets) in times.zip(run.frame_targets.iter().chain(&run.rest_targets)) {
        text.push_str(&t.to_string());
        for q in targets {
            text.push_str(&format!(",{}", f64::from(*q) / 4.0));
        }
        text.push('\n');
    }
    Ok(crate::save::save(
        path,
        text.as_bytes(),
        &inputs.source_list(),
    )?)
}

/// Per-channel [min, max] of the targets, µs.
#[must_use]
pub fn ranges(run: &Run) -> Vec<[f64; 2]> {
    let channels = run.frame_targets.first().map_or(0, Vec::len);
    (0..channels)
        .map(|c| {
            let values = run
                .frame_targets
                .iter()
                .chain(&run.rest_targets)
                .filter_map(|t| t.get(c));
            values.fold([f64::INFINITY, f64::NEG_INFINITY], |[lo, hi], q| {
                let us = f64::from(*q) / 4.0;
                [lo.min(us), hi.max(us)]
            })
        })
        .collect()
}

/// The name of the native loop in messages.
pub const NATIVE: &str = "the live loop (run natively)";

/// Boards that would refuse the region's rig (segments, back-end, region
/// size), each with why: the native loop does not model a board.
#[must_use]
pub fn boards_refusing(region: &[u8]) -> Vec<String> {
    board::BOARDS
        .iter()
        .filter_map(|b| refusal::region_verdict(b, region))
        .filter(|v| !v.fits)
        .map(|v| format!("{}: {}", v.board, v.problems.join("; ")))
        .collect()
}

/// Where `--out` puts `name`: `out` must be a folder (created if missing).
pub fn out_file(out: &Path, name: &str) -> Result<PathBuf, CmdError> {
    if out.is_file() {
        return Err(format!(
            "--out {}: is a file; give the folder to write {name} into",
            out.display()
        )
        .into());
    }
    Ok(out.join(name))
}

/// Runs the session natively and writes the servo curves.
pub fn run(args: &Args) -> Result<(), CmdError> {
    let csv = out_file(&args.out, "servo_sim.csv")?;
    let inputs = load_with(&args.rig, &args.tables, &args.recording, args.frame)?;
    let run = perform::simulate(&inputs.region, &inputs.session)?;
    let stop = refusal::check(NATIVE, &run.replies, &inputs.region, None);
    if stop.is_none() {
        write_servo_csv(&csv, &inputs, &run)?;
        if let Some(path) = &args.take {
            super::emulate::save_take(path, "sim", &inputs, &run)?;
        }
    }
    let summary = Summary {
        frames: inputs.frames,
        frame_outputs: run.frame_targets.len(),
        rest_steps: run.rest_targets.len(),
        channels: run.frame_targets.first().map_or(0, Vec::len),
        ranges_us: ranges(&run),
        servo_csv: stop.is_none().then(|| csv.display().to_string()),
        board: stop.as_ref().map_or_else(BoardReport::armed, Stop::report),
        boards_refusing: boards_refusing(&inputs.region),
        short_frames: run.short_frames,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else if stop.is_none() {
        println!(
            "sim: {} frames, {} output frames, {} steps to rest, {} channels; servo curves in {}",
            summary.frames,
            summary.frame_outputs,
            summary.rest_steps,
            summary.channels,
            csv.display()
        );
        for why in &summary.boards_refusing {
            eprintln!("note: a board would refuse this rig: {why}");
        }
        let short = crate::period::note(run.short_frames, inputs.frames, &inputs.region);
        if let Some(note) = short {
            eprintln!("{note}");
        }
    }
    match stop {
        Some(stop) => Err(Box::new(stop)),
        None => Ok(()),
    }
}
