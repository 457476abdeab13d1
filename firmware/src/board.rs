//! The board abstraction the app runs on.
//!
//! A board owns the two serial links and knows where its table region is. The
//! app never touches a register: everything board-specific sits behind
//! [`Board`], implemented by [`qemu::Qemu`] (emulated `mps2-an386`) and
//! `blackpill::BlackPill` (STM32F411).

use marionette_core::output::{Refusal, ServoOutput, Support};
use marionette_core::rig::{Output, ServoDesc};

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
    /// The servo outputs, driving whichever back-end
    /// [`Board::open_servos`] set up (the core's output abstraction).
    type Servos: ServoOutput;

    /// The tracker link and the servo outputs at once.
    fn links(&mut self) -> (&mut Self::Tracker, &mut Self::Servos);

    /// Sets up the servo back-end a rig names (`output`, for its `servos`),
    /// which [`Board::SUPPORT`] has accepted; writes nothing to the servos
    /// (they stay as they were at power-up until the first frame after
    /// arming). `Err` if the board cannot set it up after all.
    fn open_servos(&mut self, output: &Output, servos: &[ServoDesc]) -> Result<(), Refusal>;

    /// Whether the servo outputs can take a frame now. A board whose servo
    /// link needs time per frame (a UART, an I2C bus) says no until the last
    /// one has gone; the app keeps the newest targets meanwhile and sends
    /// them when it may (the slew limiter still runs every frame).
    fn servos_ready(&mut self) -> bool {
        true
    }

    /// The flash-resident table region.
    fn tables(&self) -> &'static [u8];

    /// Microseconds since boot, wrapping at `u32::MAX`.
    fn now_us(&mut self) -> u32;

    /// The servo back-ends this board drives (`[output]` in the rig file):
    /// a rig asking for another is refused (the board does not arm, and its
    /// `Status` says `Unsupported`). The host checks a region against the
    /// same description before flashing it.
    const SUPPORT: Support;

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

    /// Whether the board's show button was pressed (true once per press,
    /// debounced; always false on a board without one): the app then
    /// starts the flashed show ([`marionette_core::perform::Performer::play_show`]).
    fn show_button(&mut self) -> bool {
        false
    }

    /// Whether a `Disarm` command ends the run once the servos are at rest
    /// (the emulated board, so tests end cleanly); a real board keeps going.
    const ENDS_ON_DISARM: bool = false;

    /// Ends the run: on the emulated board QEMU exits with the outcome's
    /// status; a real board parks with its outputs held.
    fn finish(&mut self, outcome: Outcome) -> !;
}
