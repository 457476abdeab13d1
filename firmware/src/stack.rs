//! Maximum stack depth, measured by painting.
//!
//! [`paint`] fills the free RAM between the end of the statics (`__sheap`)
//! and a margin below the current stack pointer with a known word; after the
//! workload, [`high_water`] finds the lowest word that was overwritten. The
//! difference from the top of RAM (`_stack_start`) is the deepest the stack
//! has been. Only words that changed count, so the figure is a lower bound by
//! at most the last words written with the pattern value itself.

use core::ptr::{read_volatile, write_volatile};

/// The paint pattern.
const PAINT: u32 = 0xDEAD_BEEF;
/// Words left unpainted just below the current stack pointer.
const MARGIN_WORDS: usize = 16;

unsafe extern "C" {
    static __sheap: u32;
    static _stack_start: u32;
}

fn bounds() -> (usize, usize) {
    (
        (&raw const __sheap).addr(),
        (&raw const _stack_start).addr(),
    )
}

/// Paints the unused stack. Call early, from a shallow frame.
pub fn paint() {
    let (low, _) = bounds();
    let sp = cortex_m::register::msp::read() as usize;
    let high = sp.saturating_sub(MARGIN_WORDS * 4);
    let mut addr = low;
    while addr < high {
        // SAFETY: [__sheap, sp − margin) is RAM that no Rust object occupies
        // (there is no heap) and that the stack has not reached yet.
        unsafe { write_volatile(core::ptr::with_exposed_provenance_mut::<u32>(addr), PAINT) };
        addr += 4;
    }
}

/// The deepest the stack has reached since [`paint`], bytes.
#[must_use]
pub fn high_water() -> usize {
    let (low, top) = bounds();
    let mut addr = low;
    while addr < top {
        // SAFETY: as in `paint`: plain RAM between the statics and the stack top.
        let word = unsafe { read_volatile(core::ptr::with_exposed_provenance::<u32>(addr)) };
        if word != PAINT {
            break;
        }
        addr += 4;
    }
    top.saturating_sub(addr)
}
