//! Servo mapping: joint angle to pulse width, and the servo-bus encodings.
//!
//! A hobby servo is driven by a pulse of 500–2500 µs repeated at 50–333 Hz. Each
//! servo channel has a [`Calibration`]: the joint-angle range it can reach, the
//! pulse widths at the ends of that range, a trim and a direction. The mapping is
//! linear and always clamped, so no input (NaN included) can produce a pulse
//! outside `[pulse_min_us, pulse_max_us]`.
//!
//! ## Motion limits
//!
//! A [`Slew`] limiter sits between the target a frame asks for and the pulse
//! that is sent. It works in whole quarter-microseconds, the unit on the wire,
//! so its guarantees are exact rather than approximately true in floating point:
//!
//! 1. the pulse never leaves the calibrated range;
//! 2. no step changes the pulse by more than the speed limit allows for one
//!    frame period;
//! 3. the step changes by at most the acceleration limit per frame, except where
//!    keeping rule 1 or 2 requires a sharper stop;
//! 4. it brakes in time: it never commands a speed from which it could not stop
//!    at the target within the acceleration limit.
//!
//! Rules 1 and 2 hold for every input, NaN and infinities included.
//!
//! ## Pololu Maestro
//!
//! The Maestro's compact serial protocol sets a channel's target with four
//! bytes: `0x84, channel, target & 0x7F, (target >> 7) & 0x7F`, where the target
//! is in quarter-microseconds (1500 µs is 6000). See [`maestro`].

use crate::math;

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
        let mut u = if span > 0.0 {
            (angle - self.angle_min) / span
        } else {
            0.5
        };
        if u.is_nan() {
            u = 0.5;
        }
        let u = u.clamp(0.0, 1.0);
        let u = if self.reversed { 1.0 - u } else { u };
        let pulse = self.pulse_min_us + u * (self.pulse_max_us - self.pulse_min_us) + self.trim_us;
        // Not `f32::clamp`: it asserts its bounds (a panic path).
        math::clamp(pulse, self.pulse_low(), self.pulse_high())
    }

    /// The joint angle a pulse width stands for: the inverse of
    /// [`Calibration::pulse_us`] inside the calibrated range (a pulse
    /// outside it maps to the nearer end). A degenerate pulse range, or a
    /// NaN pulse, gives the middle of the angle range. Used to show the
    /// figure as its servos place it (the board reports servo targets).
    #[must_use]
    pub fn angle_of(&self, pulse_us: f32) -> f32 {
        let span = self.pulse_max_us - self.pulse_min_us;
        let mut u = if span == 0.0 {
            0.5
        } else {
            (pulse_us - self.trim_us - self.pulse_min_us) / span
        };
        if u.is_nan() {
            u = 0.5;
        }
        let u = math::clamp(u, 0.0, 1.0);
        let u = if self.reversed { 1.0 - u } else { u };
        self.angle_min + u * (self.angle_max - self.angle_min)
    }

    /// The lowest pulse this channel may ever receive, µs.
    #[must_use]
    pub fn pulse_low(&self) -> f32 {
        math::min(self.pulse_min_us, self.pulse_max_us)
    }

    /// The highest pulse this channel may ever receive, µs.
    #[must_use]
    pub fn pulse_high(&self) -> f32 {
        math::max(self.pulse_min_us, self.pulse_max_us)
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

/// Speed and acceleration limits of one channel, in output units per frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StepLimits {
    /// Largest change of the pulse in one frame, quarter-µs (≥ 1).
    pub max_step: u16,
    /// Largest change of the step between frames, quarter-µs per frame (≥ 1).
    pub max_accel: u16,
}

impl StepLimits {
    /// Limits for a servo whose joint turns at most `max_speed` rad/s with at
    /// most `max_accel` rad/s², driven every `period_s` seconds through `cal`.
    /// Each limit is rounded down, but never below one quarter-µs per frame.
    #[must_use]
    pub fn from_joint(cal: &Calibration, max_speed: f32, max_accel: f32, period_s: f32) -> Self {
        let span_angle = cal.angle_max - cal.angle_min;
        let span_pulse = cal.pulse_high() - cal.pulse_low();
        let q_per_rad = if span_angle > 0.0 {
            span_pulse * 4.0 / span_angle
        } else {
            0.0
        };
        let to_units = |x: f32| {
            let u = x * q_per_rad;
            if u.is_nan() || u < 1.0 {
                1
            } else if u >= f32::from(u16::MAX) {
                u16::MAX
            } else {
                u as u16
            }
        };
        Self {
            max_step: to_units(max_speed * period_s),
            max_accel: to_units(max_accel * period_s * period_s),
        }
    }
}

/// The slew limiter of one channel: see the module docs for its guarantees.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Slew {
    low: u16,
    high: u16,
    limits: StepLimits,
    /// The braking distance from the top speed under `limits`, worked out
    /// when they are set (every frame compares with it). At most 65,536 ×
    /// 65,535, so it fits 32 bits (saturated all the same: a larger value
    /// only sends [`Slew::update`] to the exact search).
    top_stop: u32,
    position: u16,
    step: i32,
}

impl Slew {
    /// A limiter for pulses in `[low, high]` quarter-µs, starting at rest at
    /// `start` (clamped into the range).
    #[must_use]
    pub fn new(low: u16, high: u16, limits: StepLimits, start: u16) -> Self {
        let (low, high) = (low.min(high), low.max(high));
        let mut slew = Self {
            low,
            high,
            limits,
            top_stop: 0,
            position: start.max(low).min(high),
            step: 0,
        };
        slew.set_limits(limits);
        slew
    }

    /// A limiter for a calibrated channel, starting at `start_us`.
    #[must_use]
    pub fn for_channel(cal: &Calibration, limits: StepLimits, start_us: f32) -> Self {
        Self::new(
            quarter_us(cal.pulse_low()),
            quarter_us(cal.pulse_high()),
            limits,
            quarter_us(start_us),
        )
    }

    /// Replaces the speed and acceleration limits (for example when the
    /// frame period changes); the position and the last step are kept.
    pub fn set_limits(&mut self, limits: StepLimits) {
        self.limits = StepLimits {
            max_step: limits.max_step.max(1),
            max_accel: limits.max_accel.max(1),
        };
        let top = braking_distance(
            u32::from(self.limits.max_step),
            u32::from(self.limits.max_accel),
        );
        self.top_stop = u32::try_from(top).unwrap_or(u32::MAX);
    }

    /// The limits in force.
    #[must_use]
    pub fn limits(&self) -> StepLimits {
        self.limits
    }

    /// The pulse last sent, quarter-µs.
    #[must_use]
    pub fn position(&self) -> u16 {
        self.position
    }

    /// The change applied by the last [`Slew::update`], quarter-µs.
    #[must_use]
    pub fn last_step(&self) -> i32 {
        self.step
    }

    /// Follows a planned trajectory (a show, [`crate::show`]) one frame:
    /// the step towards `target` is clamped to the speed limit, and the
    /// pulse stays within `[low, high]`. Unlike [`Slew::update`] it neither
    /// brakes ahead of the target nor shapes the acceleration (the show's
    /// curves were made by [`Slew::update`] and keep its limits): a
    /// trajectory within the speed limit passes unchanged.
    pub fn track(&mut self, target: u16) -> u16 {
        let target = i32::from(target.max(self.low).min(self.high));
        let here = i32::from(self.position);
        let vmax = i32::from(self.limits.max_step);
        let step = (target - here).max(-vmax).min(vmax);
        let next = (here + step)
            .max(i32::from(self.low))
            .min(i32::from(self.high));
        self.step = next - here;
        self.position = next as u16;
        self.position
    }

    /// Moves one frame towards `target` (quarter-µs) and returns the new pulse.
    pub fn update(&mut self, target: u16) -> u16 {
        // max/min rather than clamp throughout: clamp asserts lo ≤ hi, a
        // panic path the optimizer cannot always remove.
        let target = i32::from(target.max(self.low).min(self.high));
        let here = i32::from(self.position);
        let vmax = i32::from(self.limits.max_step);
        let amax = i32::from(self.limits.max_accel);
        let dist = target - here;
        // The fastest speed from which we can still stop within `dist`:
        // v² ≤ 2·a·d, in whole units per frame.
        let brake = capped_stopping_speed(dist.unsigned_abs(), amax, vmax, self.top_stop);
        let wanted = dist.signum() * dist.abs().min(brake).min(vmax);
        let step = wanted
            .max(self.step - amax)
            .min(self.step + amax)
            .max(-vmax)
            .min(vmax);
        let next = (here + step)
            .max(i32::from(self.low))
            .min(i32::from(self.high));
        self.step = next - here;
        self.position = next as u16;
        self.position
    }
}

/// The largest speed (units per frame) from which braking by `accel` per
/// frame, starting with this frame's step, covers at most `dist`.
fn stopping_speed(dist: u32, accel: i32) -> i32 {
    let a = accel.max(1) as u32;
    let mut v = 0u32;
    // The braking distance is about v²/2a: seed with √(2ad), then correct
    // against the exact integer sum (a step or two either way). The answer
    // is that integer search's, whatever the seed, so the seed need not be
    // the correctly rounded root: x·(1/√x) with the fast reciprocal root.
    let x = 2.0 * dist as f32 * a as f32;
    if x >= 1.0 {
        let seed = x * math::rsqrt(x);
        if seed.is_finite() && seed > 0.0 {
            v = seed as u32;
        }
    }
    while v > 0 && braking_distance(v, a) > u64::from(dist) {
        v -= 1;
    }
    while braking_distance(v + 1, a) <= u64::from(dist) {
        v += 1;
    }
    v.min(i32::MAX as u32) as i32
}

/// `stopping_speed(dist, accel).min(vmax)` (`vmax ≥ 0`), given `top_stop`,
/// the braking distance from `vmax` (`braking_distance(vmax, accel)`).
/// When even the top speed stops in time the brake does not bind, and the
/// exact stopping speed (at least `vmax` then: the braking distance grows
/// with the speed) is not needed.
fn capped_stopping_speed(dist: u32, accel: i32, vmax: i32, top_stop: u32) -> i32 {
    if top_stop <= dist {
        vmax
    } else {
        stopping_speed(dist, accel).min(vmax)
    }
}

/// Distance covered by the steps v, v−a, v−2a, … while they are positive.
fn braking_distance(v: u32, a: u32) -> u64 {
    // Terms v − k·a for k = 0..=n with n = ⌊v/a⌋ (the last one may be zero).
    // The division in 32 bits (one instruction on the Cortex-M4; a 64-bit
    // one is a library call), the sum in 64.
    let a = a.max(1);
    let n = u64::from(v / a);
    let (v, a) = (u64::from(v), u64::from(a));
    n * v - a * n * (n + 1) / 2 + v
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
    fn angle_of_inverts_the_pulse_by_hand_worked_cases() {
        // ±90° over 1000–2000 µs: 1750 µs is three quarters of the way, +45°.
        let c = Calibration::HOBBY_180;
        let quarter = core::f32::consts::FRAC_PI_4;
        assert!((c.angle_of(1750.0) - quarter).abs() < 1e-6);
        assert!((c.angle_of(1500.0)).abs() < 1e-6);
        // Beyond the range: the nearer end.
        assert!((c.angle_of(2600.0) - core::f32::consts::FRAC_PI_2).abs() < 1e-6);
        // Reversed with a +20 µs trim: 1270 µs is 1250 before the trim, a
        // quarter of the way, so three quarters from the far end: +45°.
        let r = Calibration {
            reversed: true,
            trim_us: 20.0,
            ..Calibration::HOBBY_180
        };
        assert!((r.angle_of(1270.0) - quarter).abs() < 1e-5);
        // Round trip where the trimmed pulse is not clamped (the trim moves
        // the ends by 20 µs, 0.063 rad).
        for k in -8..=8 {
            let a = k as f32 * 0.18;
            for cal in [c, r] {
                assert!((cal.angle_of(cal.pulse_us(a)) - a).abs() < 1e-4, "{a}");
            }
        }
        assert!(c.angle_of(f32::NAN).abs() < 1e-6);
    }

    #[test]
    fn stopping_speed_is_the_largest_speed_that_stops_in_time() {
        // The integer search's answer, whatever the seed: the largest v whose
        // braking distance fits, found by brute force.
        for accel in [1, 2, 3, 7, 40, 1000, 65_535] {
            for dist in (0..3000).chain([65_535, 1 << 20]) {
                let v = stopping_speed(dist, accel);
                let a = accel as u32;
                assert!(braking_distance(v as u32, a) <= u64::from(dist) || v == 0);
                assert!(
                    braking_distance(v as u32 + 1, a) > u64::from(dist),
                    "{dist} {accel}"
                );
            }
        }
        for accel in [1, 3, 40, 65_535] {
            for vmax in [0, 1, 2, 7, 100, 65_535] {
                for dist in (0..2000).chain([65_535, 1 << 20]) {
                    let top = braking_distance(vmax as u32, accel as u32);
                    let top_stop = u32::try_from(top).unwrap_or(u32::MAX);
                    assert_eq!(
                        capped_stopping_speed(dist, accel, vmax, top_stop),
                        stopping_speed(dist, accel).min(vmax),
                        "{dist} {accel} {vmax}"
                    );
                }
            }
        }
        // The distance of v, v - a, ... summed directly.
        for (v, a) in [(0u32, 1u32), (7, 2), (10, 3), (9, 3), (1000, 7), (5, 40)] {
            let direct: u64 = (0..=v / a).map(|k| u64::from(v - k * a)).sum();
            assert_eq!(braking_distance(v, a), direct, "{v} {a}");
        }
    }

    #[test]
    fn maestro_bytes_match_the_pololu_manual_example() {
        // Pololu's user's guide: channel 2 to 1500 µs (6000 quarter-µs) is
        // 0x84, 0x02, 0x70, 0x2E.
        assert_eq!(maestro::set_target(2, 6000), [0x84, 0x02, 0x70, 0x2E]);
        assert_eq!(
            maestro::decode_set_target([0x84, 0x02, 0x70, 0x2E]),
            Some((2, 6000))
        );
        assert_eq!(maestro::decode_set_target([0x85, 0x02, 0x70, 0x2E]), None);
    }

    #[test]
    fn pulses_stay_inside_the_calibrated_range() {
        let mut cal = Calibration::HOBBY_180;
        cal.trim_us = 40.0;
        for angle in [
            -10.0,
            -1.0,
            0.0,
            1.0,
            10.0,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ] {
            let p = cal.pulse_us(angle);
            assert!((1000.0..=2000.0).contains(&p), "{angle} -> {p}");
        }
        assert_eq!(cal.pulse_us(0.0), 1540.0);
        cal.reversed = true;
        cal.trim_us = 0.0;
        assert_eq!(cal.pulse_us(cal.angle_min), 2000.0);
    }

    /// A tiny deterministic generator for test inputs.
    fn lcg(state: &mut u32) -> u32 {
        *state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        *state >> 8
    }

    #[test]
    fn slew_never_leaves_the_range_or_exceeds_the_speed_limit() {
        let limits = StepLimits {
            max_step: 37,
            max_accel: 5,
        };
        let mut slew = Slew::new(4000, 8000, limits, 6000);
        let mut seed = 7;
        for _ in 0..20_000 {
            // Targets anywhere in u16, often far outside the range.
            let target = (lcg(&mut seed) & 0xFFFF) as u16;
            let before = slew.position();
            let after = slew.update(target);
            assert!((4000..=8000).contains(&after));
            assert!((i32::from(after) - i32::from(before)).abs() <= 37);
        }
    }

    #[test]
    fn slew_reaches_a_held_target_without_breaking_the_acceleration_limit() {
        let limits = StepLimits {
            max_step: 40,
            max_accel: 3,
        };
        for (start, target) in [
            (4000u16, 8000u16),
            (8000, 4000),
            (6000, 6001),
            (6000, 5000),
            (4000, 4500),
        ] {
            let mut slew = Slew::new(4000, 8000, limits, start);
            let mut prev_step = 0;
            let mut frames = 0;
            while slew.position() != target || slew.last_step() != 0 {
                slew.update(target);
                let step = slew.last_step();
                assert!(
                    (step - prev_step).abs() <= 3,
                    "{start}->{target}: step {prev_step} -> {step}"
                );
                // Braking in time: never passes the target.
                let p = i32::from(slew.position());
                let (lo, hi) = (i32::from(start.min(target)), i32::from(start.max(target)));
                assert!(
                    (lo..=hi).contains(&p),
                    "{start}->{target}: overshoot to {p}"
                );
                prev_step = step;
                frames += 1;
                assert!(frames < 10_000, "{start}->{target} never settles");
            }
            // Independent bound: accelerate, cruise, brake takes at most
            // distance/vmax + 2·vmax/amax + 2 frames.
            let dist = i32::from(start.abs_diff(target));
            assert!(
                frames <= dist / 40 + 2 * 40 / 3 + 2 + 1,
                "{start}->{target}: {frames} frames"
            );
        }
    }

    #[test]
    fn nan_targets_and_degenerate_limits_are_safe() {
        let cal = Calibration::HOBBY_180;
        let limits = StepLimits::from_joint(&cal, f32::NAN, -1.0, 0.001);
        assert_eq!(
            limits,
            StepLimits {
                max_step: 1,
                max_accel: 1
            }
        );
        let mut slew = Slew::for_channel(&cal, limits, f32::NAN);
        for _ in 0..100 {
            let p = slew.update(quarter_us(cal.pulse_us(f32::NAN)));
            assert!((4000..=8000).contains(&p));
        }
    }

    #[test]
    fn joint_limits_convert_to_quarter_microseconds_per_frame() {
        // 180° over 1000 µs = 4000 quarter-µs per π rad. At 6 rad/s and 1 kHz:
        // 0.006 rad per frame = 7.64 quarter-µs -> 7.
        let limits = StepLimits::from_joint(&Calibration::HOBBY_180, 6.0, 2000.0, 0.001);
        assert_eq!(limits.max_step, 7);
        // 2000 rad/s² · 1e-6 s² = 0.002 rad = 2.55 -> 2.
        assert_eq!(limits.max_accel, 2);
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
