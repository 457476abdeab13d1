//! On-chip PWM: one [`SetDutyCycle`] channel per servo.
//!
//! The HAL owns the timer and sets its period; this back-end only needs to
//! know the frame rate the timer was set to, so that it can turn a pulse width
//! into a duty cycle:
//!
//! ```text
//! duty = pulse_us / period_us · max_duty = target_q · frame_hz · max_duty / 4 000 000
//! ```
//!
//! computed exactly in `u64`, rounded half up and saturated to `max_duty`.
//! For example 1500 µs at 50 Hz with `max_duty` 20 000 is duty 1500.
//!
//! ## Channels of different types
//!
//! Many HALs give each timer channel its own type. An array needs one type:
//! wrap the HAL's channels in an enum of your own, or use
//! `&mut dyn SetDutyCycle<Error = E>`. With `dyn`, the firmware's panic-never
//! link fails unless each channel type overrides `set_duty_cycle_fraction`:
//! the vtable holds every trait method, and the default one divides by a
//! runtime `denom` (checked on a thumbv7em build with panic-never). A
//! `checked_div` override is enough.

use embedded_hal::pwm::SetDutyCycle;

use super::{ConfigError, OutputError, ServoOutput, check_frame_rate};

/// The duty cycle for a pulse of `target_q` quarter-µs repeated at `frame_hz`,
/// out of `max_duty`: rounded half up, saturated to `max_duty`.
#[inline]
#[must_use]
pub fn duty(target_q: u16, frame_hz: u32, max_duty: u16) -> u16 {
    // Quarter-µs per second: 4 · 10⁶. With frame_hz ≤ 333 the product stays
    // below 2⁴¹; the saturation only guards the free function's full range.
    let num = u64::from(target_q)
        .saturating_mul(u64::from(frame_hz))
        .saturating_mul(u64::from(max_duty));
    let d = num.saturating_add(2_000_000) / 4_000_000;
    u16::try_from(d).unwrap_or(u16::MAX).min(max_duty)
}

/// Servos on `N` on-chip PWM channels: `targets[i]` drives `channels[i]`.
#[derive(Debug)]
pub struct Pwm<P, const N: usize> {
    channels: [P; N],
    frame_hz: u32,
}

impl<P: SetDutyCycle, const N: usize> Pwm<P, N> {
    /// Servos on `channels`, whose timer the HAL has set to `frame_hz`
    /// (50–333 Hz, else [`ConfigError::FrameRate`]). Sends nothing.
    pub fn new(channels: [P; N], frame_hz: u32) -> Result<Self, ConfigError> {
        Ok(Self {
            channels,
            frame_hz: check_frame_rate(frame_hz)?,
        })
    }

    /// The frame rate the duty cycles are computed for, Hz.
    #[must_use]
    pub fn frame_hz(&self) -> u32 {
        self.frame_hz
    }

    /// Gives back the channels.
    #[must_use]
    pub fn release(self) -> [P; N] {
        self.channels
    }
}

impl<P: SetDutyCycle, const N: usize> ServoOutput for Pwm<P, N> {
    type Error = OutputError<P::Error>;

    /// Sets each channel's duty cycle; stops at the first error.
    fn write(&mut self, targets: &[u16]) -> Result<(), Self::Error> {
        if targets.len() > N {
            return Err(OutputError::TooManyTargets {
                given: targets.len(),
                channels: N,
            });
        }
        for (channel, &target) in self.channels.iter_mut().zip(targets) {
            let d = duty(target, self.frame_hz, channel.max_duty_cycle());
            channel.set_duty_cycle(d).map_err(OutputError::Bus)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal_mock::eh1::pwm::{Mock, Transaction};

    #[test]
    fn duty_examples_worked_by_hand() {
        // 1500 µs of a 20 000 µs period, out of 20 000.
        assert_eq!(duty(6000, 50, 20_000), 1500);
        // 1000/20000 · 65535 = 3276.75 -> 3277.
        assert_eq!(duty(4000, 50, u16::MAX), 3277);
        // 2500 µs · 333 Hz = 0.8325 of 1000 = 832.5 exactly: half rounds up.
        assert_eq!(duty(10_000, 333, 1000), 833);
        // 3300 µs at 333 Hz is longer than the period: saturates.
        assert_eq!(duty(13_200, 333, 1000), 1000);
        // No pulse, or a channel without resolution.
        assert_eq!(duty(0, 50, 20_000), 0);
        assert_eq!(duty(6000, 50, 0), 0);
        // The worst case neither overflows nor leaves the range.
        assert_eq!(duty(u16::MAX, 333, u16::MAX), u16::MAX);
    }

    #[test]
    fn writes_one_duty_per_channel_against_the_mock() {
        let a = Mock::new(&[
            Transaction::max_duty_cycle(20_000),
            Transaction::set_duty_cycle(1500),
        ]);
        let b = Mock::new(&[
            Transaction::max_duty_cycle(20_000),
            Transaction::set_duty_cycle(1000),
        ]);
        let mut out = Pwm::new([a, b], 50).unwrap();
        out.write(&[6000, 4000]).unwrap();
        for mut ch in out.release() {
            ch.done();
        }
    }

    #[test]
    fn bad_frame_rates_and_too_many_targets_are_errors() {
        assert_eq!(
            Pwm::<Mock, 0>::new([], 49).err(),
            Some(ConfigError::FrameRate(49))
        );
        assert_eq!(
            Pwm::<Mock, 0>::new([], 334).err(),
            Some(ConfigError::FrameRate(334))
        );
        let mut out = Pwm::new([Mock::new(&[])], 50).unwrap();
        assert_eq!(
            out.write(&[6000, 6000]),
            Err(OutputError::TooManyTargets {
                given: 2,
                channels: 1
            })
        );
        for mut ch in out.release() {
            ch.done();
        }
    }
}
