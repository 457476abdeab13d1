//! Servo outputs: the back-ends that put the limited servo targets on a wire.
//!
//! The servo map ([`crate::servo`]) turns each joint angle into a target in
//! quarter-microseconds and slew-limits it. An output takes one frame of those
//! targets, `targets[i]` for channel `i`, and drives the hardware:
//!
//! | back-end | hardware | module |
//! |---|---|---|
//! | [`Pwm`] | on-chip timer channels ([`embedded_hal::pwm::SetDutyCycle`]) | [`pwm`] |
//! | [`Pca9685`] | NXP PCA9685 16-channel PWM over [`embedded_hal::i2c::I2c`] | [`pca9685`] |
//! | [`Maestro`] | Pololu Maestro over a UART ([`embedded_io::Write`]) | [`maestro`] |
//! | [`bus::BusServos`] | Dynamixel (Protocol 2.0) or Feetech SCS/STS bus servos on a half-duplex UART | [`bus`], [`dynamixel`], [`feetech`] |
//!
//! [`serial::UartServos`] drives whichever UART back-end a rig names
//! ([`serial::Serial::for_output`]); [`support`] says which back-ends each
//! board has. All of them implement [`ServoOutput`]. A target of `0` means
//! "no pulse" on every back-end (the Maestro's own convention): the channel
//! goes limp (a bus servo's torque goes off).
//!
//! ## Frame rate and decimation
//!
//! Hobby servos take a pulse every 3–20 ms ([`FRAME_HZ_MIN`]–[`FRAME_HZ_MAX`]),
//! while the control loop runs at about 1 kHz. Writing a new target more often
//! than the output frame rate changes nothing, and the serial back-ends cannot
//! keep up anyway: 16 Maestro Set Target commands take 5.6 ms at 115 200 baud,
//! and 16 PCA9685 channel writes take about 2.2 ms on a 400 kHz I2C bus.
//! Wrap such an output in [`Decimated`] and pick the factor with
//! [`frames_per_write`]. The slew limiter still runs every loop frame; the
//! output samples its latest position.
//!
//! ## No panic path
//!
//! Nothing here indexes unchecked, divides by a runtime value or calls a
//! panicking library function: the bus is written with a loop of our own rather
//! than `embedded_io::Write::write_all` (which panics when a writer returns
//! `Ok(0)`), and every count saturates instead of overflowing.

pub mod bus;
pub mod dynamixel;
pub mod feetech;
pub mod maestro;
pub mod pca9685;
pub mod pwm;
pub mod serial;
pub mod support;

pub use maestro::Maestro;
pub use pca9685::Pca9685;
pub use pwm::Pwm;
pub use support::{Refusal, Support};

/// The lowest servo frame rate an output accepts, Hz (a 20 ms period).
pub const FRAME_HZ_MIN: u32 = 50;
/// The highest servo frame rate an output accepts, Hz (a 3 ms period, which
/// still fits a 2.5 ms pulse).
pub const FRAME_HZ_MAX: u32 = 333;

/// A servo output: writes one frame of targets, `targets[i]` to channel `i`.
pub trait ServoOutput {
    /// What a failed write reports.
    type Error;

    /// Sends one frame. Each target is in quarter-microseconds, already
    /// calibrated and slew-limited; `0` means no pulse. Channels past the end
    /// of `targets` keep their last value.
    fn write(&mut self, targets: &[u16]) -> Result<(), Self::Error>;
}

impl<T: ServoOutput + ?Sized> ServoOutput for &mut T {
    type Error = T::Error;

    #[inline]
    fn write(&mut self, targets: &[u16]) -> Result<(), Self::Error> {
        T::write(self, targets)
    }
}

/// An output that cannot be set up as asked. Nothing was sent.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ConfigError {
    /// The servo frame rate (Hz) is outside [`FRAME_HZ_MIN`]..=[`FRAME_HZ_MAX`].
    FrameRate(u32),
    /// Not a usable 7-bit PCA9685 address (0x00–0x07, 0x70 and above 0x7F
    /// are reserved).
    Address(u8),
    /// The PCA9685 prescale for this oscillator and frame rate would be this
    /// value, outside the 3..=255 the chip accepts.
    Prescale(u32),
}

/// A frame that could not be written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputError<E> {
    /// The peripheral or bus reported an error.
    Bus(E),
    /// More targets than the output has channels.
    TooManyTargets {
        /// Targets in the frame.
        given: usize,
        /// Channels the output drives.
        channels: usize,
    },
    /// The UART accepted no bytes (`write` returned `Ok(0)`).
    WriteZero,
    /// The driver refused a value. The outputs saturate every value first, so
    /// this means a driver bug rather than bad input.
    Rejected,
}

/// Checks a servo frame rate against [`FRAME_HZ_MIN`]..=[`FRAME_HZ_MAX`].
#[inline]
pub fn check_frame_rate(frame_hz: u32) -> Result<u32, ConfigError> {
    if (FRAME_HZ_MIN..=FRAME_HZ_MAX).contains(&frame_hz) {
        Ok(frame_hz)
    } else {
        Err(ConfigError::FrameRate(frame_hz))
    }
}

/// The decimation factor that leaves at least `busy_us` between writes when the
/// loop runs at `loop_hz`: ⌈busy_us · loop_hz / 10⁶⌉, at least 1, saturating.
///
/// Use the output's frame time as `busy_us`: `1_000_000 / frame_hz` for PWM
/// and the PCA9685 (20 000 µs at 50 Hz gives 20 at 1 kHz), or
/// [`maestro::frame_time_us`] for the Maestro (5 556 µs for 16 channels at
/// 115 200 baud gives 6 at 1 kHz).
#[inline]
#[must_use]
pub fn frames_per_write(loop_hz: u32, busy_us: u32) -> u16 {
    let n = (u64::from(busy_us) * u64::from(loop_hz)).div_ceil(1_000_000);
    u16::try_from(n.max(1)).unwrap_or(u16::MAX)
}

/// An output written only on every n-th frame (the first frame included).
///
/// Skipped frames return `Ok(())` without touching the bus.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Decimated<O> {
    inner: O,
    every: u16,
    countdown: u16,
}

impl<O> Decimated<O> {
    /// Writes `inner` on every `every_n_frames`-th call; 0 counts as 1.
    #[must_use]
    pub fn new(inner: O, every_n_frames: u16) -> Self {
        Self {
            inner,
            every: every_n_frames.max(1),
            countdown: 0,
        }
    }

    /// The decimation factor.
    #[must_use]
    pub fn every(&self) -> u16 {
        self.every
    }

    /// Whether the next [`ServoOutput::write`] reaches the inner output.
    #[must_use]
    pub fn will_write(&self) -> bool {
        self.countdown == 0
    }

    /// The wrapped output.
    #[must_use]
    pub fn inner(&self) -> &O {
        &self.inner
    }

    /// The wrapped output, mutably (for set-up such as a PCA9685 `init`).
    pub fn inner_mut(&mut self) -> &mut O {
        &mut self.inner
    }

    /// Gives back the wrapped output.
    #[must_use]
    pub fn into_inner(self) -> O {
        self.inner
    }
}

impl<O: ServoOutput> ServoOutput for Decimated<O> {
    type Error = O::Error;

    fn write(&mut self, targets: &[u16]) -> Result<(), Self::Error> {
        if self.countdown > 0 {
            self.countdown = self.countdown.saturating_sub(1);
            return Ok(());
        }
        self.countdown = self.every.saturating_sub(1);
        self.inner.write(targets)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Records how many frames reached it.
    #[derive(Default)]
    struct Counter {
        frames: usize,
    }

    impl ServoOutput for Counter {
        type Error = ();
        fn write(&mut self, _targets: &[u16]) -> Result<(), ()> {
            self.frames += 1;
            Ok(())
        }
    }

    #[test]
    fn decimation_writes_the_first_frame_then_every_nth() {
        let mut out = Decimated::new(Counter::default(), 3);
        let mut written = [false; 7];
        for w in &mut written {
            let before = out.inner().frames;
            out.write(&[6000]).unwrap();
            *w = out.inner().frames > before;
        }
        assert_eq!(written, [true, false, false, true, false, false, true]);
        // Factors 0 and 1 both write every frame.
        for n in [0, 1] {
            let mut out = Decimated::new(Counter::default(), n);
            for _ in 0..5 {
                assert!(out.will_write());
                out.write(&[]).unwrap();
            }
            assert_eq!(out.into_inner().frames, 5);
        }
    }

    #[test]
    fn frames_per_write_rounds_up() {
        // 50 Hz frames under a 1 kHz loop: 20 000 µs -> every 20th frame.
        assert_eq!(frames_per_write(1000, 20_000), 20);
        // 5 556 µs of UART traffic at 1 kHz -> 5.556 -> 6.
        assert_eq!(frames_per_write(1000, 5_556), 6);
        // Exactly one loop period -> 1; nothing busy -> still 1.
        assert_eq!(frames_per_write(1000, 1000), 1);
        assert_eq!(frames_per_write(1000, 0), 1);
        assert_eq!(frames_per_write(u32::MAX, u32::MAX), u16::MAX);
    }

    #[test]
    fn frame_rates_outside_50_to_333_hz_are_rejected() {
        assert_eq!(check_frame_rate(49), Err(ConfigError::FrameRate(49)));
        assert_eq!(check_frame_rate(50), Ok(50));
        assert_eq!(check_frame_rate(333), Ok(333));
        assert_eq!(check_frame_rate(334), Err(ConfigError::FrameRate(334)));
        assert_eq!(check_frame_rate(0), Err(ConfigError::FrameRate(0)));
    }
}
