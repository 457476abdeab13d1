//! The app: the live loop, generic over the [`Board`].
//!
//! At this stage the loop runs the core's dial mode ([`marionette_core::frame`]):
//! the tracker link carries little-endian `u16` dial values, each of which
//! becomes one Pololu Maestro Set Target command on the servo bus. The value
//! `DIAL_END` ends the session.

use crate::board::{Board, Outcome};
use embedded_io::{Read, Write};
use marionette_core::frame::{DIAL_END, dial_step};
use marionette_core::servo::Calibration;

/// Runs the loop until the host ends the session or a link fails.
pub fn run<B: Board>(board: &mut B) -> Outcome {
    let cal = Calibration::HOBBY_180;
    loop {
        board.feed_watchdog();
        let (tracker, servo) = board.links();
        let mut raw = [0u8; 2];
        if tracker.read_exact(&mut raw).is_err() {
            return Outcome::LinkError;
        }
        let dial = u16::from_le_bytes(raw);
        if dial == DIAL_END {
            return Outcome::Done;
        }
        if servo.write_all(&dial_step(dial, &cal)).is_err() {
            return Outcome::LinkError;
        }
    }
}
