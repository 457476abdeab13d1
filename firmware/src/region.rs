//! The flash-resident table region.
//!
//! Each board's `memory.x` reserves a `TABLES` region and exports its bounds as
//! `_tables_start` / `_tables_end`. The host writes a table region there (rig
//! and tables behind a small directory, `marionette_core::region`; QEMU:
//! `-device loader,file=region.bin,addr=…`; Black Pill: `marionette flash`),
//! and the core reads it in place from the byte slice returned by [`tables`]:
//! the samples are never copied into RAM.

unsafe extern "C" {
    static _tables_start: u8;
    static _tables_end: u8;
}

/// The whole table region as a read-only byte slice.
///
/// Unwritten flash reads as `0xFF` on the real board and `0x00` on QEMU; the
/// table reader rejects both by their magic.
#[must_use]
pub fn tables() -> &'static [u8] {
    let start = (&raw const _tables_start).addr();
    let end = (&raw const _tables_end).addr();
    let len = end.saturating_sub(start);
    let ptr = core::ptr::with_exposed_provenance::<u8>(start);
    // SAFETY: the linker script reserves [start, end) as a readable memory region
    // that no Rust object occupies and nothing writes at run time, so it is valid
    // for shared reads of `len` bytes for the whole program.
    unsafe { core::slice::from_raw_parts(ptr, len) }
}
