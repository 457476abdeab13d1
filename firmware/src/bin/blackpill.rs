//! # blackpill: the puppet on an STM32F411 "Black Pill"
//!
//! The same live loop as `perform`, on real hardware: tracker on USART1
//! (PA9/PA10), Pololu Maestro on USART2 (PA2/PA3), defmt logs over RTT (the
//! board's own panic-free logger, `board::blackpill::rtt`).
//!
//! Flash and run with a debug probe (from `firmware/`): `cargo blackpill`
//! (an alias for `cargo run --release --no-default-features --features
//! blackpill --bin blackpill` with the `probe-rs run --chip STM32F411CEUx`
//! runner). Build only: `cargo build-blackpill`.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use marionette_firmware::app;
use marionette_firmware::board::Board;
use marionette_firmware::board::blackpill::{BlackPill, SYSCLK_HZ, WATCHDOG_MS};

#[entry]
fn main() -> ! {
    let mut board = match BlackPill::init() {
        Ok(board) => board,
        Err(e) => {
            // The watchdog is not running yet: park here with the error on RTT.
            defmt::error!("board init failed: {}", e);
            loop {
                cortex_m::asm::wfi();
            }
        }
    };
    defmt::info!(
        "marionette: reset cause {}, {} Hz, watchdog {} ms, {} bytes of table region",
        board.reset_cause(),
        SYSCLK_HZ,
        WATCHDOG_MS,
        board.tables().len()
    );
    if !board.watchdog_configured() {
        defmt::warn!("watchdog period not applied: running with its reset period");
    }
    let outcome = app::run(&mut board);
    board.finish(outcome)
}
