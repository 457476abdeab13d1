//! `marionette emulate`: a performance on the emulated board.
//!
//! Boots the `perform` firmware on QEMU with the rig and tables in its table
//! region, streams a tracker recording over UART0, decodes the Pololu Maestro
//! commands that come back on UART1, and checks the targets of every tracker
//! frame against the core run natively on the same session
//! (`marionette sim`): they must be bit-identical.

use super::CmdError;
use super::sim::{self, Inputs};
use crate::perform::{self, Pacing};
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `marionette emulate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The rig file.
    #[arg(long, default_value = "rigs/humanoid16.toml")]
    pub rig: PathBuf,
    /// The table blob (`marionette build`); without it the board does not arm.
    #[arg(long)]
    pub tables: Option<PathBuf>,
    /// The tracker recording (CSV).
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
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
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
    /// The servo CSV written.
    pub servo_csv: String,
    /// Wall-clock seconds, including boot.
    pub seconds: f64,
}

/// Runs the session on the emulated board and natively, and compares them.
pub fn compare(
    inputs: &Inputs,
    out: &std::path::Path,
    pacing: Pacing,
) -> Result<(perform::Run, Summary, Vec<u8>), CmdError> {
    let start = Instant::now();
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let region_file = out.join("region.bin");
    std::fs::write(&region_file, &inputs.region)
        .map_err(|e| format!("{}: {e}", region_file.display()))?;
    let native = perform::simulate(&inputs.region, &inputs.session)?;
    let channels = native.frame_targets.first().map_or(1, Vec::len);
    let expected = native.frame_targets.len();
    let (board, raw) = perform::emulate(
        &region_file,
        &inputs.session,
        channels,
        expected,
        pacing,
        std::time::Duration::ZERO,
    )?;
    // Every output the board sent, in order (the split above is by count).
    let sent: Vec<Vec<u16>> = board
        .frame_targets
        .iter()
        .chain(&board.rest_targets)
        .cloned()
        .collect();
    let followed = perform::follow(&inputs.region, &inputs.session, &sent, &board.replies)?;
    let csv = out.join("servo_emulated.csv");
    sim::write_servo_csv(&csv, inputs, &board)?;
    let summary = Summary {
        frames: inputs.frames,
        frame_outputs: board.frame_targets.len(),
        mismatches: followed.mismatches,
        failsafe_trips: followed.trips.len(),
        rest_steps: sent.len().saturating_sub(followed.compared),
        replies: board.replies.len(),
        ranges_us: sim::ranges(&board),
        servo_csv: csv.display().to_string(),
        seconds: start.elapsed().as_secs_f64(),
    };
    Ok((board, summary, raw))
}

/// Runs the performance and prints its summary.
pub fn run(args: &Args) -> Result<(), CmdError> {
    let inputs = sim::load_with(
        &args.rig,
        args.tables.as_deref(),
        &args.recording,
        args.frame,
    )?;
    let pacing = if args.realtime {
        Pacing::RealTime
    } else {
        Pacing::AsFastAsPossible
    };
    let (_, summary, raw) = compare(&inputs, &args.out, pacing)?;
    if let Some(path) = &args.raw_servo {
        std::fs::write(path, raw).map_err(|e| format!("{}: {e}", path.display()))?;
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!(
            "emulated board: {} tracker frames in, {} servo frames out, {} differ from the native core, \
             {} fail-safe trips followed, {} steps to rest, {} replies; servo curves in {} ({:.1} s)",
            summary.frames,
            summary.frame_outputs,
            summary.mismatches,
            summary.failsafe_trips,
            summary.rest_steps,
            summary.replies,
            summary.servo_csv,
            summary.seconds
        );
    }
    if summary.mismatches > 0 {
        return Err("the emulated board's servo output differs from the native core".into());
    }
    Ok(())
}
