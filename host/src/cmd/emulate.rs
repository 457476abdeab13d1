//! `marionette emulate`: a performance on the emulated board.
//!
//! Boots the `perform` firmware on QEMU, streams a dial sweep over the tracker
//! link as fast as the link takes it, decodes the Pololu Maestro commands that
//! come back on the servo bus, and checks every one against the core run
//! natively on the same input.

use super::CmdError;
use crate::qemu::{self, Config};
use marionette_core::frame::{DIAL_END, DIAL_MAX, dial_step};
use marionette_core::servo::{Calibration, maestro};
use serde::Serialize;
use std::time::Instant;

/// Arguments of `marionette emulate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Number of frames to stream.
    #[arg(long, default_value_t = 2000)]
    pub frames: u32,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

/// The summary of a run.
#[derive(Debug, Serialize)]
pub struct Summary {
    /// Frames streamed.
    pub frames: usize,
    /// Servo commands received from the board.
    pub commands: usize,
    /// Commands that differ from the native core's (missing ones count too).
    pub mismatches: usize,
    /// Lowest pulse commanded, µs.
    pub pulse_min_us: f64,
    /// Highest pulse commanded, µs.
    pub pulse_max_us: f64,
    /// The firmware's exit status.
    pub exit_status: Option<i32>,
    /// Wall-clock seconds for the run, including boot.
    pub seconds: f64,
}

/// The dial input: one slow sweep up and down, as a performer turning a knob.
#[must_use]
pub fn dial_sweep(frames: u32) -> Vec<u16> {
    (0..frames)
        .map(|i| {
            let phase = f64::from(i) / f64::from(frames.max(1)) * std::f64::consts::TAU;
            ((1.0 - phase.cos()) * 0.5 * f64::from(DIAL_MAX)).round() as u16
        })
        .collect()
}

/// Streams `dials` to the emulated board and compares its servo commands with
/// the native core's.
pub fn perform(dials: &[u16]) -> Result<Summary, CmdError> {
    let start = Instant::now();
    let elf = qemu::build_firmware("perform")?;
    let mut input: Vec<u8> = dials.iter().flat_map(|d| d.to_le_bytes()).collect();
    input.extend_from_slice(&DIAL_END.to_le_bytes());
    let out = qemu::run(&Config::new(elf), &input)?;
    let cal = Calibration::HOBBY_180;
    let commands: Vec<[u8; 4]> = out
        .servo
        .chunks_exact(4)
        .filter_map(|c| c.try_into().ok())
        .collect();
    let differing = dials
        .iter()
        .zip(&commands)
        .filter(|(d, c)| dial_step(**d, &cal) != **c)
        .count();
    let pulses: Vec<f64> = commands
        .iter()
        .filter_map(|c| maestro::decode_set_target(*c))
        .map(|(_, q)| f64::from(q) / 4.0)
        .collect();
    Ok(Summary {
        frames: dials.len(),
        commands: commands.len(),
        mismatches: differing + dials.len().abs_diff(commands.len()),
        pulse_min_us: pulses.iter().copied().fold(f64::INFINITY, f64::min),
        pulse_max_us: pulses.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        exit_status: out.status,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Runs the performance and prints its summary.
pub fn run(args: &Args) -> Result<(), CmdError> {
    let summary = perform(&dial_sweep(args.frames))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!(
            "emulated board: {} frames in, {} servo commands out ({:.0}–{:.0} µs), \
             {} differ from the native core; exit status {:?}; {:.1} s",
            summary.frames,
            summary.commands,
            summary.pulse_min_us,
            summary.pulse_max_us,
            summary.mismatches,
            summary.exit_status,
            summary.seconds
        );
    }
    if summary.mismatches > 0 || summary.exit_status != Some(0) {
        return Err("the emulated board's servo output differs from the native core".into());
    }
    Ok(())
}
