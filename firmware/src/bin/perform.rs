//! # perform: the puppet on the emulated board
//!
//! The live loop on QEMU `mps2-an386`: tracker input on UART0, servo commands
//! (Pololu Maestro protocol) on UART1, exit status over semihosting.
//!
//! Run it through the host, which builds it, boots QEMU and streams input:
//! `cargo run --release -p marionette-host -- emulate` (from the repository root).
//!
//! It prints one console line, `boot`, when it starts (a reset of the board
//! would print a second one: the fault-injection tests count them), and
//! `stack <bytes>` when the session ends: the deepest the stack has been,
//! measured by painting (`marionette icount` reports it).
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use marionette_firmware::app;
use marionette_firmware::board::{Board, qemu::Qemu};
use marionette_firmware::console::Line;
use marionette_firmware::stack;

#[entry]
fn main() -> ! {
    stack::paint();
    Line::new().str("boot").print();
    let mut board = Qemu::init();
    let outcome = app::run(&mut board);
    Line::new()
        .str("stack ")
        .u32(stack::high_water() as u32)
        .print();
    board.finish(outcome)
}
