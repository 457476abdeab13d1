//! # echo: the emulated board's link test
//!
//! Echoes every byte from UART0 (tracker link) back on UART0, and its bitwise
//! complement on UART1 (servo bus). The byte 0x04 (EOT) ends the run with exit
//! status 0. Then it prints the first 8 bytes of the table region over
//! semihosting, so a test can check that a blob loaded with `-device loader`
//! is visible in place.
//!
//! Run (from `firmware/`): `cargo run --release --bin echo` (the QEMU runner has
//! no serial link; the host harness in `marionette-host::qemu` drives it).
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use embedded_io::{Read, Write};
use marionette_firmware::board::{Board, Outcome, qemu::Qemu};
use marionette_firmware::console::Line;

/// Ends the echo session.
const EOT: u8 = 0x04;

#[entry]
fn main() -> ! {
    let mut board = Qemu::init();
    let mut byte = [0u8; 1];
    loop {
        let (tracker, servo) = board.links();
        if !matches!(tracker.read(&mut byte), Ok(1)) {
            continue;
        }
        let [b] = byte;
        if b == EOT {
            break;
        }
        let _ = tracker.write_all(&[b]);
        let _ = servo.uart.write_all(&[!b]);
    }
    let tables = board.tables();
    let mut line = Line::new();
    line.str("tables ");
    for &b in tables.iter().take(8) {
        line.hex(b);
    }
    line.str(" len ").u32(tables.len() as u32).print();
    board.finish(Outcome::Done)
}
