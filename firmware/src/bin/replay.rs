//! # replay: every frame of a session, counted
//!
//! Replays a whole tracker session through the live loop (the core's
//! `Performer`, at the `perform` firmware's capacity) on the emulated
//! Cortex-M4F under `-icount shift=7,align=off`, and prints the SysTick
//! ticks (3.2 per instruction, see `marionette_firmware::icount`) of every
//! tracker frame, by stage:
//!
//! ```text
//! frame <seq> <decode> <map> <synth> <solve> <servo> <total> <receive>
//! ```
//!
//! `receive` is the whole call that handled the frame's bytes, as the
//! `frame.humanoid16.receive` row of `bench` measures it.
//!
//! The table region holds the rig and table blobs as usual, and at
//! [`SESSION_OFFSET`] the session: `RPLY`, the solver's budget per frame
//! (two little-endian `u32`s, plain and adjusted, see
//! `marionette_core::deadline::Budget`; both `u32::MAX`: the live loop's
//! own), the message
//! count (`u32`), then per message its board time (`u32`, µs), its length
//! (`u16`) and its wire frame. `marionette_host::icount::replay` writes it and runs
//! this binary (`tests/realtime.rs`).
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use marionette_core::deadline::Budget;
use marionette_core::frame::{Cycles, Region, stage};
use marionette_core::perform::Cause;
use marionette_core::solve::SolverState;
use marionette_firmware::app::{self, BoardPerformer};
use marionette_firmware::board::qemu::exit;
use marionette_firmware::console::Line;
use marionette_firmware::icount::Counter;
use marionette_firmware::region;

/// Where the session starts in the table region.
pub const SESSION_OFFSET: usize = 0x8_0000;

/// SysTick as an up-counter for the core's stage counts.
struct SysTickCycles;

impl Cycles for SysTickCycles {
    fn now(&mut self) -> u32 {
        0x00FF_FFFF - cortex_m::peripheral::SYST::get_current()
    }
}

/// The messages of a session: `(time µs, wire frame)`.
struct Messages<'a> {
    rest: &'a [u8],
    left: u32,
}

impl<'a> Messages<'a> {
    /// The solver's budget and the messages.
    fn new(bytes: &'a [u8]) -> Option<(Budget, Self)> {
        let (magic, rest) = bytes.split_at_checked(4)?;
        let (plain, rest) = rest.split_at_checked(4)?;
        let (adjusted, rest) = rest.split_at_checked(4)?;
        let (count, rest) = rest.split_at_checked(4)?;
        let messages = Messages {
            rest,
            left: u32::from_le_bytes(count.try_into().ok()?),
        };
        let budget = Budget::fixed(
            u32::from_le_bytes(plain.try_into().ok()?),
            u32::from_le_bytes(adjusted.try_into().ok()?),
        );
        (magic == b"RPLY").then_some((budget, messages))
    }
}

impl<'a> Iterator for Messages<'a> {
    type Item = (u32, &'a [u8]);

    fn next(&mut self) -> Option<Self::Item> {
        self.left = self.left.checked_sub(1)?;
        let (time, rest) = self.rest.split_at_checked(4)?;
        let (len, rest) = rest.split_at_checked(2)?;
        let len = u16::from_le_bytes(len.try_into().ok()?);
        let (frame, rest) = rest.split_at_checked(usize::from(len))?;
        self.rest = rest;
        Some((u32::from_le_bytes(time.try_into().ok()?), frame))
    }
}

/// Feeds one message; prints a line if it was a tracker frame that drove
/// the servos.
fn feed(performer: &mut BoardPerformer<'_, '_>, counter: &mut Counter, now_us: u32, bytes: &[u8]) {
    let mut input = bytes;
    while !input.is_empty() {
        let mut update = None;
        let ticks = counter.ticks(|| {
            update = Some(performer.receive(&mut input, now_us, &mut SysTickCycles));
        });
        let Some(Cause::Frame(seq)) = update.and_then(|u| u.outputs) else {
            continue;
        };
        let s = performer.stages();
        let mut line = Line::new();
        line.str("frame ").u32(seq);
        for i in [
            stage::DECODE,
            stage::MAP,
            stage::SYNTH,
            stage::SOLVE,
            stage::SERVO,
            stage::TOTAL,
        ] {
            line.str(" ").u32(s.get(i).copied().unwrap_or(0));
        }
        line.str(" ").u32(ticks).print();
    }
}

#[entry]
fn main() -> ! {
    let Some(peripherals) = cortex_m::Peripherals::take() else {
        exit(3)
    };
    let mut counter = Counter::new(peripherals.SYST);
    let bytes = region::tables();
    let (Some(head), Some(session)) = (bytes.get(..SESSION_OFFSET), bytes.get(SESSION_OFFSET..))
    else {
        exit(4)
    };
    let Some((budget, messages)) = Messages::new(session) else {
        Line::new().str("replay: no session").print();
        exit(5)
    };
    let region = Region::<{ app::SEGMENTS }>::parse_sized(head);
    let mut solver = SolverState::new();
    let mut performer = BoardPerformer::new(&region, &mut solver);
    let Some(pipeline) = performer.pipeline_mut() else {
        Line::new().str("replay: no rig").print();
        exit(6)
    };
    if budget != Budget::uniform(u32::MAX) {
        pipeline.set_solve_budget(budget);
    }
    for (time, frame) in messages {
        feed(&mut performer, &mut counter, time, frame);
    }
    Line::new().str("end").print();
    exit(0)
}
