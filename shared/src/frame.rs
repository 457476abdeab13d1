//! One step of the live loop.
//!
//! At this stage the loop has one mode, the **dial**: a single parameter in
//! `0..=DIAL_MAX` (a slider on the host, or a knob) sweeps one joint between its
//! rest orientation and a key orientation by [`math::slerp`], and the joint's
//! angle drives servo channel 0 through its [`Calibration`]. It exercises the
//! whole byte-to-servo path (input, core math, servo mapping, Maestro encoding)
//! and is computed bit-identically on the host and on the firmware.

use crate::math;
use crate::servo::{Calibration, maestro, quarter_us};
use glam::Quat;

/// The largest dial value; [`DIAL_END`] is reserved to end a session.
pub const DIAL_MAX: u16 = 0xFFFE;
/// The dial value that ends a session.
pub const DIAL_END: u16 = 0xFFFF;

/// The key orientation of the dial joint: 90° about +X.
const KEY: Quat = Quat::from_xyzw(
    core::f32::consts::FRAC_1_SQRT_2,
    0.0,
    0.0,
    core::f32::consts::FRAC_1_SQRT_2,
);

/// The joint angle, radians, for a dial value (clamped to [`DIAL_MAX`]).
#[must_use]
pub fn dial_angle(dial: u16) -> f32 {
    let t = f32::from(dial.min(DIAL_MAX)) / f32::from(DIAL_MAX);
    math::quat_angle(math::slerp(Quat::IDENTITY, KEY, t))
}

/// The Maestro Set Target command for a dial value on channel 0.
#[must_use]
pub fn dial_step(dial: u16, cal: &Calibration) -> [u8; 4] {
    maestro::set_target(0, quarter_us(cal.pulse_us(dial_angle(dial))))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_dial_sweeps_a_quarter_turn() {
        assert_eq!(dial_angle(0), 0.0);
        assert!((dial_angle(DIAL_MAX) - core::f32::consts::FRAC_PI_2).abs() < 1e-4);
        // Halfway along the slerp is halfway in angle (f64 closed form: π/4).
        assert!((dial_angle(DIAL_MAX / 2) - core::f32::consts::FRAC_PI_4).abs() < 1e-3);
        // 0 rad is the middle of a ±90° servo: 1500 µs = 6000 quarter-µs.
        assert_eq!(
            dial_step(0, &Calibration::HOBBY_180),
            maestro::set_target(0, 6000)
        );
    }
}
