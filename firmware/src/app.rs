//! The app: the live loop, generic over the [`Board`].
//!
//! Everything the board does with the tracker link is the core's
//! [`Performer`] (the protocol, the fail-safe, the per-frame pipeline); the
//! app only moves bytes. Each pass of the loop:
//!
//! 1. reads whatever the tracker link has ready and feeds it to the
//!    performer, sending each reply (`Status`, `Ack`, `Telemetry`) back as a
//!    wire frame and each new set of servo targets to the servo bus as
//!    Pololu Maestro Set Target commands;
//! 2. every frame period of the board clock, calls [`Performer::tick`], which
//!    eases the servos to rest after the fail-safe time-out or a disarm.
//!
//! A rig whose servo back-end the board cannot drive ([`Board::supports`])
//! never arms: its `Status` reason is `Unsupported`.
//!
//! The loop holds rigs of at most [`SEGMENTS`] segments (its RAM scales with
//! it); a valid rig with more is reported as `RigTooLarge` and, like a
//! missing rig, drives nothing: the performer then answers `Hello` and
//! `RequestStatus` with the reason, refuses `Arm`, and never writes the
//! servo bus.

use crate::board::{Board, Outcome};
use embedded_io::{Read, ReadReady, Write};
use marionette_core::frame::{Cycles, Region};
use marionette_core::output::ServoOutput;
use marionette_core::output::maestro::{Command, Maestro};
use marionette_core::perform::{Performer, Update};
use marionette_core::solve::SolverState;
use marionette_core::wire::{self, MAX_FRAME, Message, StatusReason};

/// Bytes read from the tracker link per pass.
const CHUNK: usize = 64;

/// The most segments of a rig this firmware drives: the capacity of its
/// [`Region`], [`Performer`] and solver state, which are most of its RAM
/// (about 600 bytes per segment). The shipped puppet, `humanoid16`, has 13
/// segments; 24 leaves room for a fuller figure within the 32 KB RAM budget
/// (the largest Maestro drives 24 servos). The other shipped rig, `cmu31`
/// (31 segments), is a reference skeleton for building tables, with no
/// servos, and is not driven by a board.
pub const SEGMENTS: usize = 24;

/// The live loop at the firmware's capacity.
pub type BoardPerformer<'r, 'a> = Performer<'r, 'a, SEGMENTS>;

/// The board's cycle counter, seen by the core.
struct BoardCycles<'b, B: Board>(&'b mut B);

impl<B: Board> Cycles for BoardCycles<'_, B> {
    fn now(&mut self) -> u32 {
        self.0.cycles()
    }

    fn hz(&self) -> u32 {
        self.0.cycles_hz()
    }
}

/// Runs the loop until the session ends (emulated board) or forever.
pub fn run<B: Board>(board: &mut B) -> Outcome {
    // Parsed in place: the region is kilobytes, and every move a copy.
    let mut region = Region::<SEGMENTS>::EMPTY;
    region.parse_into(board.tables());
    drive(board, &region)
}

/// Drives the region's rig (or speaks the protocol without one). Not
/// inlined into [`run`], so that the performer's stack frame is not below
/// the region parse's.
#[inline(never)]
fn drive<B: Board>(board: &mut B, region: &Region<'_, SEGMENTS>) -> Outcome {
    // The solver's state is most of the loop's memory: made here, in place,
    // and lent to the performer (which stays small enough to move).
    let mut solver = SolverState::new();
    let mut performer = Performer::new(region, &mut solver);
    if let Some(rig) = &region.rig
        && !board.supports(&rig.output())
    {
        performer.refuse(StatusReason::Unsupported);
    }
    perform(board, &mut performer)
}

/// Reads what the tracker link has ready into `buf`.
fn read_ready<B: Board>(board: &mut B, buf: &mut [u8; CHUNK]) -> Result<usize, Outcome> {
    let (tracker, _) = board.links();
    match tracker.read_ready() {
        Ok(true) => tracker.read(buf).map_err(|_| Outcome::LinkError),
        Ok(false) => Ok(0),
        Err(_) => Err(Outcome::LinkError),
    }
}

fn perform<B: Board>(board: &mut B, performer: &mut BoardPerformer<'_, '_>) -> Outcome {
    let period = performer.frame_period_us().max(1);
    let mut last_tick = board.now_us();
    let mut buf = [0u8; CHUNK];
    loop {
        board.feed_watchdog();
        let n = match read_ready(board, &mut buf) {
            Ok(n) => n,
            Err(outcome) => return outcome,
        };
        let mut input = buf.get(..n).unwrap_or(&[]);
        while !input.is_empty() {
            let now = board.now_us();
            let update = performer.receive(&mut input, now, &mut BoardCycles(board));
            if let Err(outcome) = emit(board, performer, update) {
                return outcome;
            }
        }
        let now = board.now_us();
        if now.wrapping_sub(last_tick) >= period {
            last_tick = now;
            let update = performer.tick(now);
            if let Err(outcome) = emit(board, performer, update) {
                return outcome;
            }
        }
        if B::ENDS_ON_DISARM && performer.disarms() > 0 && performer.resting() {
            return Outcome::Done;
        }
    }
}

/// Sends an update's servo targets and reply.
fn emit<B: Board>(
    board: &mut B,
    performer: &BoardPerformer<'_, '_>,
    update: Update,
) -> Result<(), Outcome> {
    let (tracker, servo) = board.links();
    if update.outputs.is_some() {
        let mut maestro = Maestro::new(&mut *servo, Command::SetTarget);
        maestro
            .write(performer.targets())
            .map_err(|_| Outcome::LinkError)?;
    }
    if let Some(reply) = update.reply {
        send(tracker, &reply)?;
    }
    Ok(())
}

/// Sends one message as a wire frame.
fn send<W: Write>(link: &mut W, msg: &Message) -> Result<(), Outcome> {
    let mut out = [0u8; MAX_FRAME];
    match wire::encode(msg, &mut out) {
        Ok(frame) => link.write_all(frame).map_err(|_| Outcome::LinkError),
        // Every board-to-host message fits MAX_FRAME; nothing to send otherwise.
        Err(_) => Ok(()),
    }
}
