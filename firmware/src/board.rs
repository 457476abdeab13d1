//! The board abstraction the app runs on.
//!
//! A board owns the two serial links and knows where its table region is. The
//! app never touches a register: everything board-specific sits behind
//! [`Board`], implemented by [`qemu::Qemu`] (emulated `mps2-an386`) and
//! `blackpill::BlackPill` (STM32F411).

use marionette_core::rig::Output;

#[cfg(feature = "qemu")]
pub mod qemu;

#[cfg(feature = "blackpill")]
pub mod blackpill;

/// Exit status reported by a debug build that panicked (emulated board only).
pub const EXIT_PANIC: i32 = 101;

/// How a run of the app ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// The host ended the session cleanly.
    Done,
    /// A link failed.
    LinkError,
}

impl Outcome {
    /// The process exit status for this outcome (emulated board).
    #[must_use]
    pub const fn exit_status(self) -> i32 {
        match self {
            Outcome::Done => 0,
            Outcome::LinkError => 2,
        }
    }
}

/// The peripherals the app needs, and nothing more.
pub trait Board {
    /// The tracker link: frames in, telemetry out.
    type Tracker: embedded_io::Read + embedded_io::Write + embedded_io::ReadReady;
    /// The servo bus (for example a Pololu Maestro on a UART).
    type ServoBus: embedded_io::Write;

    /// Both serial links at once.
    fn links(&mut self) -> (&mut Self::Tracker, &mut Self::ServoBus);

    /// The flash-resident table region.
    fn tables(&self) -> &'static [u8];

    /// Microseconds since boot, wrapping at `u32::MAX`.
    fn now_us(&mut self) -> u32;

    /// Whether this board can drive the servo back-end a rig asks for
    /// (`[output]` in the rig file). The app drives a Pololu Maestro over
    /// [`Board::ServoBus`]; the on-chip PWM and PCA9685 back-ends of
    /// `marionette_core::output` need pins no board here wires yet, so a rig
    /// asking for them is refused: the board does not arm, and its `Status`
    /// says `Unsupported`.
    fn supports(&self, output: &Output) -> bool {
        matches!(output, Output::Maestro { .. })
    }

    /// Tells the watchdog the loop is alive (no-op where there is none).
    fn feed_watchdog(&mut self);

    /// A free-running cycle counter for the per-stage counts in telemetry
    /// (wrapping; 0 where there is none).
    fn cycles(&mut self) -> u32 {
        0
    }

    /// Counts per second of [`Board::cycles`] (0 where there is no
    /// counter): the rig's frame period in counts is the budget the live
    /// loop reports overruns against.
    fn cycles_hz(&self) -> u32 {
        0
    }

    /// Whether a `Disarm` command ends the run once the servos are at rest
    /// (the emulated board, so tests end cleanly); a real board keeps going.
    const ENDS_ON_DISARM: bool = false;

    /// Ends the run: on the emulated board QEMU exits with the outcome's
    /// status; a real board parks with its outputs held.
    fn finish(&mut self, outcome: Outcome) -> !;
}
