//! A defmt global logger over SEGGER RTT that never panics and never blocks.
//!
//! The debug probe (`probe-rs run`) finds the RTT control block by its symbol
//! `_SEGGER_RTT` (or by scanning RAM for its ID), then polls up-channel 0 over
//! the debug port and decodes the defmt frames it finds there.
//!
//! - **Whole frames or nothing.** A frame's bytes are staged in the ring past
//!   the published write offset, and the offset moves only when the frame is
//!   complete. A frame that does not fit in the free space is dropped whole,
//!   so the host never sees a torn frame and the loop never waits for it.
//! - **Contention drops.** defmt's `acquire`/`release` may nest: an
//!   interrupt, a fault handler, or a `Format` impl that logs while a frame is
//!   open. The inner frame is counted and dropped; the outer one continues.
//!   (`defmt-rtt` panics here instead, which `panic-never` rejects.)
//! - The state is only touched inside short critical sections, one per
//!   logger call; interrupts stay enabled between the calls of a frame.
//!
//! Control-block layout (SEGGER RTT, as read by the host):
//! `{ id: [u8; 16], max_up: u32, max_down: u32, up[max_up], down[max_down] }`,
//! each channel `{ name: *const u8, buffer: *mut u8, size: u32, write: u32,
//! read: u32, flags: u32 }`. The target owns `write`, the host owns `read`.

use core::cell::RefCell;
use core::sync::atomic::{AtomicU8, AtomicU32, Ordering};
use cortex_m::interrupt::{self, Mutex};

/// Size of the up-channel ring, bytes. A power of two; one byte always stays
/// free to tell a full ring from an empty one.
pub const BUFFER_SIZE: usize = 1024;
const MASK: usize = BUFFER_SIZE - 1;
const _: () = assert!(BUFFER_SIZE.is_power_of_two());

/// SEGGER's "skip" mode: the target drops what does not fit. The host may
/// rewrite `flags` (probe-rs asks for blocking mode); this logger ignores it.
const MODE_NO_BLOCK_SKIP: u32 = 0;

#[repr(C)]
struct UpChannel {
    name: *const u8,
    buffer: *const AtomicU8,
    size: u32,
    write: AtomicU32,
    read: AtomicU32,
    flags: AtomicU32,
}

#[repr(C)]
struct ControlBlock {
    id: [u8; 16],
    max_up_channels: u32,
    max_down_channels: u32,
    up: UpChannel,
}

// SAFETY: the target never dereferences `name` or `buffer` through the
// control block (they are addresses for the host), and every field that the
// target or the host changes after start-up is an atomic.
unsafe impl Sync for ControlBlock {}

/// The up-channel ring. Atomic bytes (a plain `strb` on the M4) so that the
/// ring needs no `unsafe`, although the host reads it behind our back.
static BUFFER: [AtomicU8; BUFFER_SIZE] = [const { AtomicU8::new(0) }; BUFFER_SIZE];

// SAFETY: the symbol must be unique in the program: no other RTT
// implementation (defmt-rtt, rtt-target) is linked into the firmware.
#[unsafe(no_mangle)]
static _SEGGER_RTT: ControlBlock = ControlBlock {
    id: *b"SEGGER RTT\0\0\0\0\0\0",
    max_up_channels: 1,
    max_down_channels: 0,
    up: UpChannel {
        name: c"defmt".as_ptr().cast(),
        buffer: (&raw const BUFFER).cast(),
        size: BUFFER_SIZE as u32,
        write: AtomicU32::new(0),
        read: AtomicU32::new(0),
        flags: AtomicU32::new(MODE_NO_BLOCK_SKIP),
    },
};

/// Frames dropped since boot (ring full, or contention), wrapping.
static DROPPED: AtomicU32 = AtomicU32::new(0);

/// Frames dropped since boot because the ring was full or the logger was busy
/// (wraps at `u32::MAX`).
#[must_use]
pub fn dropped_frames() -> u32 {
    DROPPED.load(Ordering::Relaxed)
}

fn count_drop() {
    DROPPED.fetch_add(1, Ordering::Relaxed);
}

/// Where the open frame's bytes go.
struct Stage {
    /// Next ring index to write (the published offset plus the staged bytes).
    cursor: usize,
    /// Set when a byte did not fit: the frame will be dropped.
    overflow: bool,
}

impl Stage {
    fn open(&mut self) {
        self.cursor = _SEGGER_RTT.up.write.load(Ordering::Relaxed) as usize & MASK;
        self.overflow = false;
    }

    fn push(&mut self, bytes: &[u8]) {
        if self.overflow {
            return;
        }
        let read = _SEGGER_RTT.up.read.load(Ordering::Relaxed) as usize;
        // Bytes the host has not read yet, published or staged.
        let used = self.cursor.wrapping_sub(read) & MASK;
        if bytes.len() > MASK - used {
            self.overflow = true;
            return;
        }
        for &byte in bytes {
            if let Some(slot) = BUFFER.get(self.cursor & MASK) {
                slot.store(byte, Ordering::Relaxed);
            }
            self.cursor = (self.cursor + 1) & MASK;
        }
    }

    /// Publishes the staged frame, or drops it if it overflowed.
    fn close(&self) {
        if self.overflow {
            count_drop();
        } else {
            // Release: the frame's bytes are in RAM before the host can see
            // the new offset.
            _SEGGER_RTT
                .up
                .write
                .store(self.cursor as u32, Ordering::Release);
        }
    }
}

/// The logger's state between `acquire` and `release`.
struct Frame {
    /// A frame is open.
    open: bool,
    /// Acquires nested inside the open frame; their frames are dropped.
    nested: u32,
    encoder: defmt::Encoder,
    stage: Stage,
}

impl Frame {
    fn acquire(&mut self) {
        if self.open {
            self.nested = self.nested.saturating_add(1);
            count_drop();
            return;
        }
        self.open = true;
        self.stage.open();
        let stage = &mut self.stage;
        self.encoder.start_frame(|bytes| stage.push(bytes));
    }

    fn write(&mut self, bytes: &[u8]) {
        if self.open && self.nested == 0 {
            let stage = &mut self.stage;
            self.encoder.write(bytes, |b| stage.push(b));
        }
    }

    fn release(&mut self) {
        if self.nested > 0 {
            self.nested -= 1;
        } else if self.open {
            let stage = &mut self.stage;
            self.encoder.end_frame(|bytes| stage.push(bytes));
            stage.close();
            self.open = false;
        }
    }
}

static FRAME: Mutex<RefCell<Frame>> = Mutex::new(RefCell::new(Frame {
    open: false,
    nested: 0,
    encoder: defmt::Encoder::new(),
    stage: Stage {
        cursor: 0,
        overflow: false,
    },
}));

/// Runs `f` on the frame state in a critical section and says whether it ran.
/// If the state is already borrowed (a fault handler logging in the middle of
/// a logger call), the call is dropped.
fn with_frame(f: impl FnOnce(&mut Frame)) -> bool {
    interrupt::free(|cs| match FRAME.borrow(cs).try_borrow_mut() {
        Ok(mut frame) => {
            f(&mut frame);
            true
        }
        Err(_) => false,
    })
}

#[defmt::global_logger]
struct Logger;

// SAFETY: defmt requires that the logger be safe to call from any context and
// that a frame be exclusive. Every method takes the state in a critical
// section, through a `RefCell` that refuses a second borrow, and a frame opened
// while another is open is dropped whole, so frames never interleave.
unsafe impl defmt::Logger for Logger {
    fn acquire() {
        if !with_frame(Frame::acquire) {
            count_drop();
        }
    }

    /// Non-blocking: there is nothing to wait for that the loop should wait for.
    unsafe fn flush() {}

    unsafe fn release() {
        let _ = with_frame(Frame::release);
    }

    unsafe fn write(bytes: &[u8]) {
        let _ = with_frame(|frame| frame.write(bytes));
    }
}
