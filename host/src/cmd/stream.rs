//! `marionette stream --port DEV`: a performance on a real board.
//!
//! Streams a tracker recording to a board over a serial port (the same
//! session as `marionette emulate` and `sim`: `Hello`, `Arm`, the frames,
//! `Disarm`), in real time by default, and records what the board answers:
//! its `Status`, the `Ack`s and the `Telemetry` (servo targets, goal
//! residuals, per-stage cycle counts, error counters). The servo bus itself
//! is on the board; the telemetry's servo targets are written as CSV.

use super::CmdError;
use crate::perform::{self, Pacing};
use crate::{import, rigfile};
use marionette_core::wire::Message;
use serde::Serialize;
use std::io::{Read, Write};
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Arguments of `marionette stream`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The board's tracker serial port, e.g. /dev/ttyUSB0.
    #[arg(long)]
    pub port: String,
    /// Baud rate of the tracker link (the Black Pill's USART1 runs at 921 600).
    #[arg(long, default_value_t = 921_600)]
    pub baud: u32,
    /// The tracker recording (CSV; docs/recording.md).
    #[arg(long)]
    pub recording: PathBuf,
    /// The rig file (for its frame period; the rig itself is in the board's flash).
    #[arg(long, default_value = "rigs/humanoid16.toml")]
    pub rig: PathBuf,
    /// Send as fast as the port takes it instead of in real time.
    #[arg(long)]
    pub fast: bool,
    /// Where to write `telemetry.csv`.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

/// What the board answered.
#[derive(Debug, Default, Serialize)]
pub struct Summary {
    /// Tracker frames sent.
    pub frames: usize,
    /// Status messages received.
    pub statuses: usize,
    /// Acks received, and how many said no.
    pub acks: usize,
    /// Acks that refused their command.
    pub refused: usize,
    /// Telemetry messages received.
    pub telemetry: usize,
    /// The board's last error counters' total.
    pub errors: u32,
    /// The telemetry CSV written.
    pub telemetry_csv: String,
}

/// Tallies the board's replies and writes the telemetry's servo targets.
pub fn summarize(
    replies: &[Message],
    frames: usize,
    csv: &std::path::Path,
) -> Result<Summary, CmdError> {
    let mut s = Summary {
        frames,
        telemetry_csv: csv.display().to_string(),
        ..Summary::default()
    };
    let mut text = String::from("seq,targets_us\n");
    for m in replies {
        match m {
            Message::Status(st) => {
                s.statuses += 1;
                s.errors = st.errors.total();
            }
            Message::Ack(a) => {
                s.acks += 1;
                s.refused += usize::from(!a.ok);
            }
            Message::Telemetry(t) => {
                s.telemetry += 1;
                s.errors = t.errors.total();
                let us: Vec<String> = t
                    .servo_targets
                    .iter()
                    .map(|q| (f64::from(*q) / 4.0).to_string())
                    .collect();
                text.push_str(&format!("{},{}\n", t.seq, us.join(" ")));
            }
            _ => {}
        }
    }
    crate::save::save(csv, text.as_bytes(), &[])?;
    Ok(s)
}

/// Streams the recording to the board and reports what it answered.
pub fn run(args: &Args) -> Result<(), CmdError> {
    let _rig = rigfile::load(&rigfile::resolve(&args.rig))?;
    let samples = import::csv::read_tracker_csv(&args.recording)?;
    let frames = perform::frames(&samples)?;
    let session = perform::session(&frames)?;
    let mut port = serialport::new(&args.port, args.baud)
        .timeout(Duration::from_millis(50))
        .open()
        .map_err(|e| format!("{}: {e}", args.port))?;
    let mut reader = port
        .try_clone()
        .map_err(|e| format!("{}: {e}", args.port))?;
    let received = Arc::new(Mutex::new(Vec::new()));
    let sink = Arc::clone(&received);
    let done = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let stop = Arc::clone(&done);
    let listener = std::thread::spawn(move || {
        let mut buf = [0u8; 1024];
        while !stop.load(std::sync::atomic::Ordering::Relaxed) {
            match reader.read(&mut buf) {
                Ok(n) if n > 0 => {
                    if let (Ok(mut v), Some(chunk)) = (sink.lock(), buf.get(..n)) {
                        v.extend_from_slice(chunk);
                    }
                }
                _ => {}
            }
        }
    });
    let pacing = if args.fast {
        Pacing::AsFastAsPossible
    } else {
        Pacing::RealTime
    };
    let sent = perform::pace(&session, pacing, |bytes| port.write_all(bytes));
    std::thread::sleep(Duration::from_millis(300));
    done.store(true, std::sync::atomic::Ordering::Relaxed);
    let _ = listener.join();
    sent.map_err(|e| format!("{}: {e}", args.port))?;
    let bytes = received.lock().map(|v| v.clone()).unwrap_or_default();
    let summary = summarize(
        &perform::decode_replies(&bytes),
        frames.len(),
        &args.out.join("telemetry.csv"),
    )?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!(
            "stream: {} frames sent; board answered {} status, {} acks ({} refused), {} telemetry; \
             {} errors counted; telemetry in {}",
            summary.frames,
            summary.statuses,
            summary.acks,
            summary.refused,
            summary.telemetry,
            summary.errors,
            summary.telemetry_csv
        );
    }
    Ok(())
}
