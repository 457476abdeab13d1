//! Servo mapping: joint angle to pulse width, and the servo-bus encodings.
//!
//! A hobby servo is driven by a pulse of 500–2500 µs repeated at 50–333 Hz. Each
//! servo channel has a [`Calibration`]: the joint-angle range it can reach, the
//! pulse widths at the ends of that range, a trim and a direction. The mapping is
//! linear and always clamped, so no input (NaN included) can produce a pulse
//! outside `[pulse_min_us, pulse_max_us]`.
//!
//! ## Pololu Maestro
//!
//! The Maestro's compact serial protocol sets a channel's target with four
//! bytes: `0x84, channel, target & 0x7F, (target >> 7) & 0x7F`, where the target
//! is in quarter-microseconds (1500 µs is 6000). See [`maestro`].

/// The calibration of one servo channel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Calibration {
    /// Joint angle at the low end of the range, radians.
    pub angle_min: f32,
    /// Joint angle at the high end of the range, radians.
    pub angle_max: f32,
    /// Pulse width at `angle_min` (before reversal and trim), µs.
    pub pulse_min_us: f32,
    /// Pulse width at `angle_max` (before reversal and trim), µs.
    pub pulse_max_us: f32,
    /// Added to every pulse, µs; the result is still clamped to the pulse range.
    pub trim_us: f32,
    /// Swaps the ends of the pulse range (a servo mounted the other way round).
    pub reversed: bool,
}

impl Calibration {
    /// A typical 180° hobby servo: ±90° over 1000–2000 µs.
    pub const HOBBY_180: Calibration = Calibration {
        angle_min: -core::f32::consts::FRAC_PI_2,
        angle_max: core::f32::consts::FRAC_PI_2,
        pulse_min_us: 1000.0,
        pulse_max_us: 2000.0,
        trim_us: 0.0,
        reversed: false,
    };

    /// The pulse width for a joint angle, clamped to the calibrated range.
    /// A NaN angle maps to the middle of the range.
    #[must_use]
    pub fn pulse_us(&self, angle: f32) -> f32 {
        let span = self.angle_max - self.angle_min;
        let mut u = if span > 0.0 { (angle - self.angle_min) / span } else { 0.5 };
        if u.is_nan() {
            u = 0.5;
        }
        let u = u.clamp(0.0, 1.0);
        let u = if self.reversed { 1.0 - u } else { u };
        let pulse = self.pulse_min_us + u * (self.pulse_max_us - self.pulse_min_us) + self.trim_us;
        pulse.clamp(self.pulse_low(), self.pulse_high())
    }

    /// The lowest pulse this channel may ever receive, µs.
    #[must_use]
    pub fn pulse_low(&self) -> f32 {
        self.pulse_min_us.min(self.pulse_max_us)
    }

    /// The highest pulse this channel may ever receive, µs.
    #[must_use]
    pub fn pulse_high(&self) -> f32 {
        self.pulse_min_us.max(self.pulse_max_us)
    }
}

/// Converts a pulse width in µs to the Maestro's quarter-microseconds, rounding
/// to nearest and saturating to the 14-bit range the protocol carries.
#[inline]
#[must_use]
pub fn quarter_us(pulse_us: f32) -> u16 {
    let q = pulse_us * 4.0 + 0.5;
    if q.is_nan() || q <= 0.0 {
        0
    } else if q >= f32::from(maestro::TARGET_MAX) {
        maestro::TARGET_MAX
    } else {
        q as u16
    }
}

/// The Pololu Maestro compact serial protocol.
pub mod maestro {
    /// The compact-protocol command byte for Set Target.
    pub const SET_TARGET: u8 = 0x84;
    /// The largest target the protocol can carry (14 bits), quarter-µs.
    pub const TARGET_MAX: u16 = 0x3FFF;

    /// Encodes Set Target for `channel` (0–127) to `target` quarter-µs.
    /// Both are masked to the bits the protocol carries.
    #[inline]
    #[must_use]
    pub const fn set_target(channel: u8, target: u16) -> [u8; 4] {
        [
            SET_TARGET,
            channel & 0x7F,
            (target & 0x7F) as u8,
            ((target >> 7) & 0x7F) as u8,
        ]
    }

    /// Decodes a Set Target command into `(channel, target)`, or `None` if the
    /// bytes are not one.
    #[must_use]
    pub const fn decode_set_target(bytes: [u8; 4]) -> Option<(u8, u16)> {
        let [cmd, channel, lo, hi] = bytes;
        if cmd != SET_TARGET || channel > 0x7F || lo > 0x7F || hi > 0x7F {
            return None;
        }
        Some((channel, (lo as u16) | ((hi as u16) << 7)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn maestro_bytes_match_the_pololu_manual_example() {
        // Pololu's user's guide: channel 2 to 1500 µs (6000 quarter-µs) is
        // 0x84, 0x02, 0x70, 0x2E.
        assert_eq!(maestro::set_target(2, 6000), [0x84, 0x02, 0x70, 0x2E]);
        assert_eq!(maestro::decode_set_target([0x84, 0x02, 0x70, 0x2E]), Some((2, 6000)));
        assert_eq!(maestro::decode_set_target([0x85, 0x02, 0x70, 0x2E]), None);
    }

    #[test]
    fn pulses_stay_inside_the_calibrated_range() {
        let mut cal = Calibration::HOBBY_180;
        cal.trim_us = 40.0;
        for angle in [-10.0, -1.0, 0.0, 1.0, 10.0, f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let p = cal.pulse_us(angle);
            assert!((1000.0..=2000.0).contains(&p), "{angle} -> {p}");
        }
        assert_eq!(cal.pulse_us(0.0), 1540.0);
        cal.reversed = true;
        cal.trim_us = 0.0;
        assert_eq!(cal.pulse_us(cal.angle_min), 2000.0);
    }

    #[test]
    fn quarter_us_rounds_and_saturates() {
        assert_eq!(quarter_us(1500.0), 6000);
        assert_eq!(quarter_us(1500.1), 6000);
        assert_eq!(quarter_us(1500.2), 6001);
        assert_eq!(quarter_us(-3.0), 0);
        assert_eq!(quarter_us(f32::NAN), 0);
        assert_eq!(quarter_us(1.0e9), 0x3FFF);
    }
}
