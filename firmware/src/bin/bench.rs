//! # bench: instruction counts on the emulated Cortex-M4F
//!
//! Times named regions with SysTick under `-icount shift=7,align=off` (see
//! `marionette_firmware::icount`) and prints one line per row over semihosting:
//!
//! ```text
//! row <name> <baseline|-> <calls> <ticks>
//! ```
//!
//! `marionette icount` builds this binary, runs it on QEMU and prints the rows
//! as a table of instructions per call with the ratio against each row's
//! baseline, measured in the same run. Run it with
//! `cargo run --release -p marionette-host -- icount` from the repository root.
#![no_std]
#![no_main]

use core::hint::black_box;
use cortex_m_rt::entry;
use glam::Quat;
use marionette_core::math;
use marionette_firmware::board::qemu::exit;
use marionette_firmware::console::Line;
use marionette_firmware::icount::Counter;

/// Number of quaternion pairs each slerp row is measured over.
const PAIRS: usize = 64;

/// A small deterministic generator for bench inputs (not part of any result).
struct Lcg(u32);

impl Lcg {
    fn unit(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (self.0 >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0
    }

    fn quat(&mut self) -> Quat {
        let q = Quat::from_xyzw(self.unit(), self.unit(), self.unit(), self.unit());
        math::normalize_quat(q)
    }
}

fn report(name: &str, baseline: &str, calls: usize, ticks: u32) {
    Line::new()
        .str("row ")
        .str(name)
        .str(" ")
        .str(baseline)
        .str(" ")
        .u32(calls as u32)
        .str(" ")
        .u32(ticks)
        .print();
}

fn slerp_rows(counter: &mut Counter) {
    let mut rng = Lcg(0x1234_5678);
    let mut a = [Quat::IDENTITY; PAIRS];
    let mut b = [Quat::IDENTITY; PAIRS];
    let mut t = [0.0f32; PAIRS];
    for ((a, b), t) in a.iter_mut().zip(b.iter_mut()).zip(t.iter_mut()) {
        *a = rng.quat();
        *b = rng.quat();
        *t = rng.unit() * 0.5 + 0.5;
    }
    let (a, b, t) = (black_box(a), black_box(b), black_box(t));
    let glam_ticks = counter.ticks(|| {
        let mut acc = Quat::IDENTITY;
        for ((a, b), t) in a.iter().zip(b.iter()).zip(t.iter()) {
            acc = black_box(a.slerp(*b, *t));
        }
        acc
    });
    report("slerp.glam", "-", PAIRS, glam_ticks);
    let core_ticks = counter.ticks(|| {
        let mut acc = Quat::IDENTITY;
        for ((a, b), t) in a.iter().zip(b.iter()).zip(t.iter()) {
            acc = black_box(math::slerp(*a, *b, *t));
        }
        acc
    });
    report("slerp.core", "slerp.glam", PAIRS, core_ticks);
}

#[entry]
fn main() -> ! {
    let Some(peripherals) = cortex_m::Peripherals::take() else {
        exit(3)
    };
    let mut counter = Counter::new(peripherals.SYST);
    Line::new().str("overhead ").u32(counter.overhead()).print();
    slerp_rows(&mut counter);
    Line::new().str("end").print();
    exit(0)
}
