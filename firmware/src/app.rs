//! The app: the live loop, generic over the [`Board`].
//!
//! Everything the board does with the tracker link is the core's
//! [`Performer`] (the protocol, the fail-safe, the per-frame pipeline); the
//! app only moves bytes. Each pass of the loop:
//!
//! 1. reads whatever the tracker link has ready and feeds it to the
//!    performer, sending each reply (`Status`, `Ack`, `Telemetry`) back as a
//!    wire frame and each new set of servo targets to the servo outputs the
//!    rig names (`[output]`: a Maestro, bus servos, a PCA9685, timer PWM),
//!    which the board set up through the core's output abstraction
//!    ([`Board::open_servos`]); a board that needs time per frame on its
//!    servo link ([`Board::servos_ready`]) gets the newest targets once it
//!    can take them;
//! 2. every frame period of the board clock, calls [`Performer::tick`], which
//!    eases the servos to rest after the fail-safe time-out or a disarm, and
//!    plays the flashed show while it plays;
//! 3. a press of the board's show button ([`Board::show_button`]) starts
//!    the flashed show.
//!
//! A rig whose servo back-end the board cannot drive ([`Board::SUPPORT`])
//! never arms: its `Status` reason is `Unsupported`.
//!
//! The loop holds rigs of at most [`SEGMENTS`] segments (its RAM scales with
//! it); a valid rig with more is reported as `RigTooLarge` and, like a
//! missing rig, drives nothing: the performer then answers `Hello` and
//! `RequestStatus` with the reason, refuses `Arm`, and never writes the
//! servo bus.

use crate::board::{Board, Outcome};
use embedded_io::{Read, ReadReady, Write};
use marionette_core::frame::Cycles;
use marionette_core::output::ServoOutput;
use marionette_core::perform::{Performer, Update};
use marionette_core::region::{FIRMWARE_SEGMENTS, Region};
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
/// servos, and is not driven by a board. The value lives in the core
/// ([`FIRMWARE_SEGMENTS`]) so that the host checks a region at the same
/// capacity before flashing it.
pub const SEGMENTS: usize = FIRMWARE_SEGMENTS;

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
    if let Some(rig) = &region.rig {
        let opened = B::SUPPORT
            .check(&rig.output(), rig.servos())
            .and_then(|()| board.open_servos(&rig.output(), rig.servos()));
        if opened.is_err() {
            performer.refuse(StatusReason::Unsupported);
        }
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
    // New targets not yet sent to the servos.
    let mut pending = false;
    loop {
        board.feed_watchdog();
        if board.show_button() {
            performer.play_show();
        }
        let n = match read_ready(board, &mut buf) {
            Ok(n) => n,
            Err(outcome) => return outcome,
        };
        let mut input = buf.get(..n).unwrap_or(&[]);
        while !input.is_empty() {
            let now = board.now_us();
            let update = performer.receive(&mut input, now, &mut BoardCycles(board));
            if let Err(outcome) = emit(board, performer, &update, &mut pending) {
                return outcome;
            }
        }
        let now = board.now_us();
        if now.wrapping_sub(last_tick) >= period {
            last_tick = now;
            let update = performer.tick(now);
            if let Err(outcome) = emit(board, performer, &update, &mut pending) {
                return outcome;
            }
        }
        if pending && let Err(outcome) = flush_servos(board, performer, &mut pending) {
            return outcome;
        }
        if B::ENDS_ON_DISARM && !pending && performer.disarms() > 0 && performer.settled() {
            return Outcome::Done;
        }
    }
}

/// Sends an update's reply, and its servo targets as soon as the servo
/// outputs can take them ([`Board::servos_ready`]). By reference: an
/// update is hundreds of bytes, and a move of one a copy per frame.
fn emit<B: Board>(
    board: &mut B,
    performer: &BoardPerformer<'_, '_>,
    update: &Update,
    pending: &mut bool,
) -> Result<(), Outcome> {
    if let Some(reply) = &update.reply {
        let (tracker, _) = board.links();
        send(tracker, reply)?;
    }
    if update.outputs.is_some() {
        *pending = true;
        flush_servos(board, performer, pending)?;
    }
    Ok(())
}

/// Writes the newest targets to the servo outputs if they can take them.
fn flush_servos<B: Board>(
    board: &mut B,
    performer: &BoardPerformer<'_, '_>,
    pending: &mut bool,
) -> Result<(), Outcome> {
    if board.servos_ready() {
        let (_, servos) = board.links();
        servos
            .write(performer.targets())
            .map_err(|_| Outcome::LinkError)?;
        *pending = false;
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
