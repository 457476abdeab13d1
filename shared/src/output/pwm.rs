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
//! ## Timer set-up
//!
//! [`TimerSetup::new`] picks a timer's prescaler and period for a frame
//! rate: the smallest clock divider whose period still fits a 16-bit
//! auto-reload register, so the tick is as fine as the timer allows. On the
//! Black Pill (timer clock 100 MHz): 50 Hz divides by 31 (a 0.31 µs tick,
//! period 64 516 ticks), 200 Hz by 8 (0.08 µs, 62 500), 333 Hz by 5 (0.05 µs,
//! 60 060): better than 1 µs over the whole 50–333 Hz range. The duty cycle
//! of a target is then [`duty`] with `max_duty` the period in ticks.
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

/// A timer's prescaler and period for a frame rate (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TimerSetup {
    /// The clock divider (the prescaler register holds `divider − 1`).
    pub divider: u32,
    /// Ticks per period (the auto-reload register holds `period − 1`);
    /// the channels' `max_duty`.
    pub period: u16,
}

impl TimerSetup {
    /// The finest tick for `frame_hz` (50–333 Hz) on a timer clocked at
    /// `clock_hz` with a 16-bit auto-reload register: `divider = ⌈clock /
    /// (f · 65 535)⌉`, `period = round(clock / (divider · f))`.
    pub fn new(clock_hz: u32, frame_hz: u32) -> Result<Self, ConfigError> {
        let f = u64::from(check_frame_rate(frame_hz)?);
        let clock = u64::from(clock_hz);
        let divider = clock.div_ceil(f * u64::from(u16::MAX)).max(1);
        let period = (clock + divider * f / 2) / (divider * f);
        match (u32::try_from(divider), u16::try_from(period)) {
            (Ok(divider), Ok(period)) if period > 0 => Ok(Self { divider, period }),
            _ => Err(ConfigError::FrameRate(frame_hz)),
        }
    }

    /// One tick, ns (rounded to nearest).
    #[must_use]
    pub fn tick_ns(&self, clock_hz: u32) -> u32 {
        let ns = (u64::from(self.divider) * 1_000_000_000 + u64::from(clock_hz) / 2)
            .checked_div(u64::from(clock_hz))
            .unwrap_or(u64::MAX);
        u32::try_from(ns).unwrap_or(u32::MAX)
    }
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
    fn black_pill_timer_setups_and_compare_values_worked_by_hand() {
        const CLOCK: u32 = 100_000_000;
        // 50 Hz: 100e6 / (50 · 65 535) = 30.5 -> 31; 100e6 / 31 / 50 =
        // 64 516.1 -> 64 516 ticks of 310 ns.
        let s50 = TimerSetup::new(CLOCK, 50).unwrap();
        assert_eq!(
            s50,
            TimerSetup {
                divider: 31,
                period: 64_516
            }
        );
        assert_eq!(s50.tick_ns(CLOCK), 310);
        // 1500 µs: 6000 · 50 · 64 516 / 4e6 = 4838.7 -> 4839 ticks (1500.09 µs).
        assert_eq!(duty(6000, 50, s50.period), 4839);
        // 1000 and 2000 µs: 3225.8 -> 3226, 6451.6 -> 6452.
        assert_eq!(duty(4000, 50, s50.period), 3226);
        assert_eq!(duty(8000, 50, s50.period), 6452);
        // 200 Hz: ⌈7.63⌉ = 8, 62 500 ticks of 80 ns; 1500 µs = 18 750.
        let s200 = TimerSetup::new(CLOCK, 200).unwrap();
        assert_eq!(
            (s200.divider, s200.period, s200.tick_ns(CLOCK)),
            (8, 62_500, 80)
        );
        assert_eq!(duty(6000, 200, s200.period), 18_750);
        // 333 Hz: ⌈4.58⌉ = 5, 60 060.06 -> 60 060 ticks of 50 ns; 1500 µs =
        // 6000 · 333 · 60 060 / 4e6 = 29 999.97 -> 30 000.
        let s333 = TimerSetup::new(CLOCK, 333).unwrap();
        assert_eq!(
            (s333.divider, s333.period, s333.tick_ns(CLOCK)),
            (5, 60_060, 50)
        );
        assert_eq!(duty(6000, 333, s333.period), 30_000);
        // Every rate of the range has a tick of 1 µs or better.
        for f in 50..=333 {
            let s = TimerSetup::new(CLOCK, f).unwrap();
            assert!(s.tick_ns(CLOCK) <= 1000, "{f} Hz");
            assert!(s.period >= 32_768, "{f} Hz: {s:?}");
        }
        assert_eq!(TimerSetup::new(CLOCK, 49), Err(ConfigError::FrameRate(49)));
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
