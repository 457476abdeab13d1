//! `marionette replay TAKE`: sends a take's input again, to the emulated
//! board (`--emulated`, booted from the take's own table region) or to a
//! board on a serial port (`--port DEV`), at the take's times (`--speed`
//! scales them) or as fast as the link takes it (`--fast`).
//!
//! It compares what it can, and says what (`compares`): on the emulated
//! board, every servo output with the take's if the take holds them (a
//! take from the emulated board: they must be bit-identical); everywhere,
//! the servo targets of each `Telemetry` with the take's of the same
//! tracker frame (sequence number), which a take from a port holds too
//! (a board on a port shows no servo output). Any difference fails the
//! command.
//!
//! To a port, Ctrl-C ends the replay early ([`crate::interrupt`]): the
//! board is told to disarm, and the telemetry of the frames sent is
//! compared as at the end; a second Ctrl-C quits at once.

use super::CmdError;
use super::stream::{Replies, answer_to_hello, await_disarm};
use crate::perform::{self, Pacing, Sent};
use crate::refusal::{self, ShowReport, Stop};
use crate::take::Take;
use marionette_core::wire::compact;
use marionette_core::wire::{Command, CommandKind, Message};
use serde::Serialize;
use std::collections::HashSet;
use std::io::Write as _;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

/// Arguments of `marionette replay`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The take (docs/take.md).
    pub take: PathBuf,
    /// Replay on the emulated board, booted from the take's table region.
    #[arg(long, conflicts_with = "port")]
    pub emulated: bool,
    /// Replay to a board on this serial port (its flash must hold the
    /// take's rig and tables).
    #[arg(long)]
    pub port: Option<String>,
    /// Baud rate of the port's tracker link.
    #[arg(long, default_value_t = 921_600)]
    pub baud: u32,
    /// Time scale: 2 sends twice as fast as the take was recorded.
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Send every message as soon as the link takes it.
    #[arg(long)]
    pub fast: bool,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

/// What a replay did.
#[derive(Debug, Serialize)]
pub struct Summary {
    /// Where it went: `emulated` or the port.
    pub board: String,
    /// Messages sent.
    pub sent: usize,
    /// Servo outputs in the take.
    pub take_outputs: usize,
    /// Servo outputs the board sent (`null` on a port: not seen).
    pub board_outputs: Option<usize>,
    /// Outputs that differ from the take's, missing or extra ones counted
    /// (`null` on a port, or for a take from a port: not compared).
    pub mismatches: Option<usize>,
    /// What was compared: `servo outputs and telemetry`, `telemetry`
    /// (servo targets of each `Telemetry`, by frame), or `nothing` (the
    /// take holds no telemetry to compare with).
    pub compares: String,
    /// Telemetry messages of the take compared with the board's.
    pub telemetry_compared: usize,
    /// Of those, the ones whose servo targets differ or that the board did
    /// not send.
    pub telemetry_mismatches: usize,
    /// Replies (messages) the board sent.
    pub replies: usize,
    /// Fail-safe trips the board reported in this replay, and in the take
    /// (a host that stalls past the rig's time-out trips the board, rightly:
    /// its outputs then differ from a take that did not trip).
    pub failsafe_trips: [usize; 2],
    /// Wall-clock seconds.
    pub seconds: f64,
    /// The board's flashed show, from its last `Status`.
    pub show: Option<ShowReport>,
    /// Whether a Ctrl-C ended it before the take's end (on a port: the
    /// board was then disarmed by the replay).
    pub stopped: bool,
}

/// The take's session with its times scaled by `1 / speed` (from the first).
#[must_use]
pub fn scaled(session: &[Sent], speed: f64) -> Vec<Sent> {
    let first = session.first().map_or(0, |s| s.time_us);
    session
        .iter()
        .map(|s| Sent {
            time_us: first
                .wrapping_add((f64::from(s.time_us.wrapping_sub(first)) / speed).round() as u32),
            bytes: s.bytes.clone(),
        })
        .collect()
}

/// How many outputs differ between `a` and `b` (a missing one counts).
#[must_use]
pub fn mismatches(a: &[Vec<u16>], b: &[Vec<u16>]) -> usize {
    let differ = a.iter().zip(b).filter(|(x, y)| x != y).count();
    differ + a.len().abs_diff(b.len())
}

/// Compares the servo targets of each `Telemetry` of `take` with the
/// board's of the same frame (sequence number): `(compared, mismatches)`,
/// a telemetry the board did not send counted as a mismatch.
#[must_use]
pub fn telemetry_mismatches(take: &[Message], board: &[Message]) -> (usize, usize) {
    let targets = |replies: &[Message]| -> Vec<(u32, Vec<u16>)> {
        replies
            .iter()
            .filter_map(|m| match m {
                Message::Telemetry(t) => Some((t.seq, t.servo_targets.as_slice().to_vec())),
                _ => None,
            })
            .collect()
    };
    let ours = targets(board);
    let theirs = targets(take);
    let differ = theirs
        .iter()
        .filter(|(seq, want)| !ours.iter().any(|(s, got)| s == seq && got == want))
        .count();
    (theirs.len(), differ)
}

/// What a replay compared, in words (see the module doc).
fn compares(outputs: bool, telemetry: usize) -> String {
    match (outputs, telemetry > 0) {
        (true, true) => "servo outputs and telemetry",
        (true, false) => "servo outputs",
        (false, true) => "telemetry",
        (false, false) => "nothing",
    }
    .into()
}

/// The emulated board, as refusals name it.
const EMULATED_BOARD: &str = "the emulated board";

/// Why a replay's board never armed (its `Status` reason), or stopped: a
/// refusal always; a board that never answered `Arm` only if the take's
/// own board did (a take may hold no `Arm`, a show played disarmed).
fn stop_of(
    board: &str,
    replies: &[Message],
    take: &Take,
    known: Option<&crate::board::Board>,
) -> Option<Stop> {
    let stop = refusal::check(board, replies, &take.region, known)?;
    let take_armed = refusal::check(board, &take.replies(), &take.region, known).is_none();
    (take_armed || stop.exit_code() == refusal::EXIT_REFUSED).then_some(stop)
}

/// Replays on the emulated board; returns the summary.
pub fn emulated(take: &Take, pacing: Pacing, speed: f64) -> Result<Summary, CmdError> {
    let start = Instant::now();
    let staged = tempfile::NamedTempFile::new()?;
    std::fs::write(staged.path(), &take.region)
        .map_err(|e| format!("{}: {e}", staged.path().display()))?;
    let session = scaled(&take.session(), speed);
    let (board, _) = perform::emulate(
        staged.path(),
        &session,
        usize::from(take.channels),
        take.frame_outputs(),
        pacing,
        Duration::ZERO,
    )?;
    if let Some(fault) = &board.fault {
        return Err(Box::new(Stop::fault(EMULATED_BOARD, fault.clone())));
    }
    if let Some(stop) = stop_of(
        EMULATED_BOARD,
        &board.replies,
        take,
        Some(&crate::board::EMULATED),
    ) {
        return Err(Box::new(stop));
    }
    let sent: Vec<Vec<u16>> = board
        .frame_targets
        .iter()
        .chain(&board.rest_targets)
        .cloned()
        .collect();
    let expected: Vec<Vec<u16>> = take.outputs().into_iter().map(|o| o.2).collect();
    let seen = !expected.is_empty();
    let (telemetry_compared, telemetry_mismatches) =
        telemetry_mismatches(&take.replies(), &board.replies);
    Ok(Summary {
        board: "emulated".into(),
        sent: session.len(),
        take_outputs: expected.len(),
        board_outputs: Some(sent.len()),
        mismatches: seen.then(|| mismatches(&expected, &sent)),
        compares: compares(seen, telemetry_compared),
        telemetry_compared,
        telemetry_mismatches,
        replies: board.replies.len(),
        failsafe_trips: [
            perform::reported_trips(&board.replies).len(),
            perform::reported_trips(&take.replies()).len(),
        ],
        seconds: start.elapsed().as_secs_f64(),
        show: ShowReport::of(&board.replies),
        stopped: false,
    })
}

/// Replays to a board on a serial port: says the take's `Hello` until the
/// board answers, then sends the rest at its times, until `stop` is set
/// (a Ctrl-C: [`crate::interrupt`]). Stopped early, it disarms the board
/// itself (the take's own `Disarm` is at its end) and compares only the
/// telemetry of the tracker frames it sent; stopped before the board
/// answered, it ends with an error and the board is never armed.
pub fn on_port(
    take: &Take,
    port: (&str, u32),
    (pacing, speed): (Pacing, f64),
    stop: &AtomicBool,
) -> Result<(Summary, Vec<Message>), CmdError> {
    let (port_name, baud) = port;
    let start = Instant::now();
    let session = scaled(&take.session(), speed);
    let mut port = serialport::new(port_name, baud)
        .timeout(Duration::from_millis(50))
        .open()
        .map_err(|e| format!("{port_name}: {e}"))?;
    let reader = port.try_clone().map_err(|e| format!("{port_name}: {e}"))?;
    let replies = Replies::spawn(reader);
    let (hello, rest) = session.split_at(1.min(session.len()));
    let mut write = |bytes: &[u8]| {
        port.write_all(bytes)
            .map_err(|e| format!("{port_name}: {e}"))
    };
    let say = &mut || {
        hello
            .iter()
            .try_for_each(|s| write(&s.bytes).map_err(Into::into))
    };
    answer_to_hello(say, &replies, (port_name, Duration::from_secs(5)), stop)?;
    let went = perform::pace_until(rest, pacing, stop, &mut write)?;
    let stopped = went < rest.len();
    if stopped {
        write(&perform::encode(&Message::Command(Command {
            seq: u32::try_from(session.len()).unwrap_or(u32::MAX),
            kind: CommandKind::Disarm,
        }))?)?;
    }
    await_disarm(&replies, Duration::from_secs(20));
    let messages = replies.finish();
    if let Some(stop) = stop_of(&format!("the board on {port_name}"), &messages, take, None) {
        return Err(Box::new(stop));
    }
    let sent = rest.get(..went).unwrap_or(rest);
    let (telemetry_compared, telemetry_mismatches) =
        telemetry_mismatches(&take_telemetry_of(take, sent), &messages);
    let summary = Summary {
        board: port_name.to_string(),
        sent: hello.len() + went + usize::from(stopped),
        take_outputs: take.outputs().len(),
        board_outputs: None,
        mismatches: None,
        compares: compares(false, telemetry_compared),
        telemetry_compared,
        telemetry_mismatches,
        replies: messages.len(),
        failsafe_trips: [
            perform::reported_trips(&messages).len(),
            perform::reported_trips(&take.replies()).len(),
        ],
        seconds: start.elapsed().as_secs_f64(),
        show: ShowReport::of(&messages),
        stopped,
    };
    Ok((summary, messages))
}

/// The take's replies, its telemetry kept only for the tracker frames in
/// `sent` (a replay stopped early compares what it sent; all of them for
/// a whole replay).
fn take_telemetry_of(take: &Take, sent: &[Sent]) -> Vec<Message> {
    let mut seqs = HashSet::new();
    let mut last = None;
    for m in sent.iter().flat_map(|s| perform::decode_replies(&s.bytes)) {
        let seq = match m {
            Message::TrackerFrame(f) => f.seq,
            // Extended from the last one as the board does.
            Message::CompactFrame(c) => compact::extend_seq(last, c.seq16()),
            _ => continue,
        };
        last = Some(seq);
        seqs.insert(seq);
    }
    take.replies()
        .into_iter()
        .filter(|m| !matches!(m, Message::Telemetry(t) if !seqs.contains(&t.seq)))
        .collect()
}

/// Replays the take and prints the summary.
pub fn run(args: &Args) -> Result<(), CmdError> {
    let take = Take::load(&args.take)?;
    if !(args.speed.is_finite() && args.speed > 0.0) {
        return Err(format!("--speed {}: must be a positive number", args.speed).into());
    }
    let pacing = if args.fast {
        Pacing::AsFastAsPossible
    } else {
        Pacing::RealTime
    };
    let summary = match (&args.port, args.emulated) {
        (Some(port), false) => {
            let stop = crate::interrupt::stop_on_ctrl_c("replay")?;
            on_port(&take, (port, args.baud), (pacing, args.speed), stop).map(|r| r.0)
        }
        (None, true) => emulated(&take, pacing, args.speed),
        _ => return Err("replay: say where, --emulated or --port DEV".into()),
    }
    .inspect_err(|e| refusal::print_json_stop(&**e, args.json))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        if summary.stopped {
            println!(
                "replay: stopped by Ctrl-C after {} of the take's {} messages; the board was \
                 told to disarm",
                summary.sent.saturating_sub(1),
                take.session().len()
            );
        }
        println!(
            "replay on {}: {} messages sent, {} replies, fail-safe trips {} (take: {}); \
             {} servo outputs in the take, {} from the board, {} differ; {} telemetry \
             compared, {} differ; compared: {} ({:.1} s)",
            summary.board,
            summary.sent,
            summary.replies,
            summary.failsafe_trips[0],
            summary.failsafe_trips[1],
            summary.take_outputs,
            summary
                .board_outputs
                .map_or_else(|| "not seen".into(), |n| n.to_string()),
            summary
                .mismatches
                .map_or_else(|| "-".into(), |n| n.to_string()),
            summary.telemetry_compared,
            summary.telemetry_mismatches,
            summary.compares,
            summary.seconds
        );
        super::stream::print_show(summary.show.as_ref());
    }
    if summary.mismatches.is_some_and(|m| m > 0) {
        return Err("the board's servo output differs from the take's".into());
    }
    if summary.telemetry_mismatches > 0 {
        return Err(format!(
            "the servo targets of {} of the take's {} telemetry messages differ from the board's",
            summary.telemetry_mismatches, summary.telemetry_compared
        )
        .into());
    }
    Ok(())
}
