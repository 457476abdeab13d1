//! # marionette-firmware
//!
//! The firmware only moves bytes: tracker bytes from a UART into the core, and
//! servo commands from the core out to the servo bus. All per-frame logic lives in
//! `marionette-core`, which the host runs natively on the same inputs.
//!
//! The app ([`app`]) is generic over a small [`board::Board`] abstraction, so the
//! same loop runs on:
//!
//! - the emulated board, QEMU `mps2-an386` (feature `qemu`, the default):
//!   CMSDK UART0 is the tracker link, UART1 the servo bus, and semihosting gives
//!   exit codes and console output;
//! - the STM32F411 "Black Pill" (feature `blackpill`), flashed and run with
//!   `probe-rs run`, logging over defmt/RTT.
//!
//! ## No panic path
//!
//! Release builds link `panic-never`: if any panicking branch survives
//! optimisation, the link fails. Debug builds on the emulated board exit QEMU with
//! status [`board::EXIT_PANIC`] instead.
#![no_std]

pub mod app;
pub mod board;
pub mod region;

#[cfg(feature = "qemu")]
pub mod console;
#[cfg(feature = "qemu")]
pub mod icount;
#[cfg(feature = "qemu")]
pub mod stack;

// Release: any reachable panic is a link error.
#[cfg(not(debug_assertions))]
use panic_never as _;

// Debug on the emulated board: report the panic and exit QEMU with a failure status.
#[cfg(all(debug_assertions, feature = "qemu"))]
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    semihosting::eprintln!("firmware panic: {}", info);
    semihosting::process::exit(board::EXIT_PANIC)
}

// Debug on the Black Pill: panic-probe prints over defmt and halts.
#[cfg(all(debug_assertions, feature = "blackpill"))]
use panic_probe as _;
