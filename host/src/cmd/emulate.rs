//! `marionette emulate`: a performance on the emulated board.
//!
//! Boots the `perform` firmware on QEMU with the rig and tables in its table
//! region, streams a tracker recording over UART0, decodes the Pololu Maestro
//! commands that come back on UART1, and checks the targets of every tracker
//! frame against the core run natively on the same session
//! (`marionette sim`): they must be bit-identical.
//!
//! A board that refuses to arm, or stops on a fault, is reported with its
//! `Status` reason and what to do, and the command exits 3 or 4 (see
//! [`crate::refusal`]); `--json` carries the same in its `board` object.

use super::CmdError;
use super::sim::{self, Inputs};
use crate::perform::{self, Pacing, PerformError};
use crate::qemu::QemuError;
use crate::refusal::{self, BoardReport, Stop};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `marionette emulate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The rig file (TOML; docs/rig.md), or a rig name: `rigs/<name>.toml`
    /// here, else a rig built in (humanoid16, cmu31).
    #[arg(long, default_value = "rigs/humanoid16.toml")]
    pub rig: PathBuf,
    /// The table blob (`marionette build`); without it the board does not arm.
    /// Repeat it for a rig with `[[layer]]` tables: table 0, 1, … in order.
    #[arg(long)]
    pub tables: Vec<PathBuf>,
    /// The tracker recording (CSV; docs/recording.md).
    #[arg(long)]
    pub recording: PathBuf,
    /// Where to write `servo_emulated.csv` and `region.bin`.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Send each frame at its recorded time instead of as fast as possible.
    #[arg(long)]
    pub realtime: bool,
    /// How tracker frames travel: the compact frame (quantized) or `f32`.
    #[arg(long, value_enum, default_value_t = perform::Framing::Compact)]
    pub frame: perform::Framing,
    /// Also save the raw servo-bus bytes here.
    #[arg(long)]
    pub raw_servo: Option<PathBuf>,
    /// Also save the session as a take (docs/take.md): the input sent,
    /// the board's outputs and replies, with times.
    #[arg(long)]
    pub take: Option<PathBuf>,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
    /// The live view (`--view`, `--listen`).
    #[command(flatten)]
    pub view: super::view::ViewArgs,
}

/// The summary of a run.
#[derive(Debug, Serialize)]
pub struct Summary {
    /// Tracker frames streamed.
    pub frames: usize,
    /// Output frames the board sent for them.
    pub frame_outputs: usize,
    /// Output frames that differ from the native core's (missing ones count),
    /// with the native replay following the board's fail-safe trips.
    pub mismatches: usize,
    /// Times the board's fail-safe tripped in the middle of the stream (a
    /// host stall longer than the rig's time-out) and eased towards rest,
    /// as the board reported them; the native replay followed each (see
    /// [`perform::follow`]).
    pub failsafe_trips: usize,
    /// Easing steps to rest after the session.
    pub rest_steps: usize,
    /// Replies (status, acks, telemetry) decoded from the board.
    pub replies: usize,
    /// Per-channel [min, max] target, µs.
    pub ranges_us: Vec<[f64; 2]>,
    /// The servo CSV written (`null` when the board did not perform).
    pub servo_csv: Option<String>,
    /// Wall-clock seconds, including boot.
    pub seconds: f64,
    /// Whether the board armed, and if not why (see [`crate::refusal`]).
    pub board: BoardReport,
    /// Tracker frames that may run over the rig's period on the board, by
    /// the native replay ([`perform::Run::short_frames`]).
    pub short_frames: u32,
}

/// What [`compare`] found.
pub struct Compared {
    /// The board's run.
    pub run: perform::Run,
    /// The summary.
    pub summary: Summary,
    /// The raw servo-bus bytes.
    pub raw: Vec<u8>,
    /// Why the board did not perform, if it did not.
    pub stop: Option<Stop>,
}

/// The board's name in messages.
pub const BOARD: &str = "the emulated board";

/// A harness error that is really the board's fault (it ran past its
/// deadline), as a [`Stop`].
fn as_stop(e: PerformError) -> CmdError {
    match e {
        PerformError::Qemu(QemuError::Timeout(d)) => Box::new(Stop::fault(
            BOARD,
            format!("it did not finish within {d:?}; QEMU was killed"),
        )),
        other => Box::new(other),
    }
}

/// Runs the session on the emulated board and natively, and compares them.
/// Writes `region.bin` and, if the board performed, `servo_emulated.csv`
/// into `out`.
pub fn compare(inputs: &Inputs, out: &Path, pacing: Pacing) -> Result<Compared, CmdError> {
    compare_watched(inputs, out, pacing, &|_| ())
}

/// [`compare`], showing `watch` the board's links while it performs.
pub fn compare_watched(
    inputs: &Inputs,
    out: &Path,
    pacing: Pacing,
    watch: &dyn Fn(&crate::qemu::Taps),
) -> Result<Compared, CmdError> {
    let start = Instant::now();
    let sources = inputs.source_list();
    let region_file = sim::out_file(out, "region.bin")?;
    crate::save::check(&region_file, &sources)?;
    // The board boots from a staged copy, kept as `region.bin` only if it
    // performed: a failed run leaves nothing behind.
    let staged = crate::save::temp_beside(&region_file)?;
    std::fs::write(staged.path(), &inputs.region)
        .map_err(|e| format!("{}: {e}", staged.path().display()))?;
    let native = perform::simulate(&inputs.region, &inputs.session)?;
    let channels = native.frame_targets.first().map_or(1, Vec::len);
    let expected = native.frame_targets.len();
    let (board, raw) = perform::emulate_watched(
        staged.path(),
        &inputs.session,
        channels,
        expected,
        pacing,
        std::time::Duration::ZERO,
        watch,
    )
    .map_err(as_stop)?;
    let stop = match &board.fault {
        Some(what) => Some(Stop::fault(BOARD, what.clone())),
        None => refusal::check(
            BOARD,
            &board.replies,
            &inputs.region,
            Some(&crate::board::EMULATED),
        ),
    };
    // Every output the board sent, in order (the split above is by count).
    let sent: Vec<Vec<u16>> = board
        .frame_targets
        .iter()
        .chain(&board.rest_targets)
        .cloned()
        .collect();
    let (followed, csv) = if stop.is_none() {
        let followed = perform::follow(&inputs.region, &inputs.session, &sent, &board.replies)?;
        let csv = out.join("servo_emulated.csv");
        sim::write_servo_csv(&csv, inputs, &board)?;
        crate::save::commit(staged, &region_file)?;
        (Some(followed), Some(csv.display().to_string()))
    } else {
        (None, None)
    };
    let summary = Summary {
        frames: inputs.frames,
        frame_outputs: board.frame_targets.len(),
        mismatches: followed.as_ref().map_or(0, |f| f.mismatches),
        failsafe_trips: followed.as_ref().map_or(0, |f| f.trips.len()),
        rest_steps: sent
            .len()
            .saturating_sub(followed.as_ref().map_or(0, |f| f.compared)),
        replies: board.replies.len(),
        ranges_us: sim::ranges(&board),
        servo_csv: csv,
        seconds: start.elapsed().as_secs_f64(),
        board: stop.as_ref().map_or_else(BoardReport::armed, Stop::report),
        short_frames: native.short_frames,
    };
    Ok(Compared {
        run: board,
        summary,
        raw,
        stop,
    })
}

/// Saves a run of `inputs` as a take at `path`.
pub fn save_take(
    path: &Path,
    source: &str,
    inputs: &Inputs,
    run: &perform::Run,
) -> Result<(), CmdError> {
    let take = crate::take::Take::of_run(source, &inputs.region, &inputs.session, run)?;
    crate::save::check(path, &inputs.source_list())?;
    take.save(path)?;
    Ok(())
}

/// Runs the performance and prints its summary.
pub fn run(args: &Args) -> Result<(), CmdError> {
    let inputs = sim::load_with(&args.rig, &args.tables, &args.recording, args.frame)?;
    let pacing = if args.realtime {
        Pacing::RealTime
    } else {
        Pacing::AsFastAsPossible
    };
    for path in args.raw_servo.iter().chain(&args.take) {
        crate::save::check(path, &inputs.source_list())?;
    }
    let Compared {
        summary,
        raw,
        stop,
        run,
    } = {
        let name = args.recording.file_name().map_or_else(
            || args.recording.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        );
        let frames = if args.view.view {
            perform::frames(&crate::import::csv::read_tracker_csv(&args.recording)?)?
        } else {
            Vec::new()
        };
        super::view::watched(&args.view, &inputs.region, &name, &frames, |watch| {
            compare_watched(&inputs, &args.out, pacing, watch)
        })?
    };
    if let (Some(path), None) = (&args.raw_servo, &stop) {
        crate::save::save(path, &raw, &inputs.source_list())?;
    }
    if let (Some(path), None) = (&args.take, &stop) {
        save_take(path, "emulate", &inputs, &run)?;
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else if stop.is_none() {
        println!(
            "emulated board: {} tracker frames in, {} servo frames out, {} differ from the native core, \
             {} fail-safe trips followed, {} steps to rest, {} replies; servo curves in {} ({:.1} s)",
            summary.frames,
            summary.frame_outputs,
            summary.mismatches,
            summary.failsafe_trips,
            summary.rest_steps,
            summary.replies,
            summary.servo_csv.as_deref().unwrap_or("-"),
            summary.seconds
        );
        let short = crate::period::note(summary.short_frames, summary.frames, &inputs.region);
        if let Some(note) = short {
            eprintln!("{note}");
        }
    }
    if let Some(stop) = stop {
        return Err(Box::new(stop));
    }
    if summary.mismatches > 0 {
        return Err("the emulated board's servo output differs from the native core".into());
    }
    Ok(())
}
