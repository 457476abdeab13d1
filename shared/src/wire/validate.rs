//! Validated representations of the host-to-board messages.
//!
//! Decoding yields raw [`Message`](super::Message)s whose numbers may be NaN,
//! infinite or absurd. `validate()` turns a raw message into a typed value
//! whose invariants hold by construction (private fields, getters only), or
//! rejects it with [`WireError::Range`].

use glam::{Quat, Vec3};

use super::message::{
    Command, CommandKind, MAX_GOALS, MAX_PARAMS, MAX_SENSORS, MAX_SERVOS, Params,
};
use super::message::{Sensor, TrackerFrame};
use super::{List, WireError};
use crate::math;

/// Largest accepted sensor distance from the origin, metres.
pub const POSITION_LIMIT_M: f32 = 100.0;
/// Largest accepted `| |q|² − 1 |` for a sensor quaternion; within it the
/// quaternion is renormalised, beyond it the frame is rejected
/// (`|q|` between about 0.95 and 1.05).
pub const QUAT_NORM2_TOLERANCE: f32 = 0.1;
/// Largest `Jog` target, quarter units (the 14 bits the Maestro carries).
pub const JOG_TARGET_MAX: u16 = 0x3FFF;
/// Largest accepted `|value|` of a parameter.
pub const PARAM_LIMIT: f32 = 1.0e6;
/// Largest accepted goal weight.
pub const WEIGHT_LIMIT: f32 = 1.0e6;

/// `|x| ≤ limit`, false for NaN.
#[inline]
fn within(x: f32, limit: f32) -> bool {
    math::abs(x) <= limit
}

/// A validated sensor: finite position within [`POSITION_LIMIT_M`], unit
/// rotation, id `< MAX_SENSORS`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SensorSample {
    id: u8,
    position: Vec3,
    rotation: Quat,
}

impl SensorSample {
    /// Sets every field; the caller has established the invariants (a
    /// compact sensor is valid by construction).
    pub(crate) fn set(&mut self, id: u8, position: Vec3, rotation: Quat) {
        self.id = id;
        self.position = position;
        self.rotation = rotation;
    }

    /// Sensor id, `< MAX_SENSORS`.
    #[must_use]
    pub const fn id(&self) -> u8 {
        self.id
    }
    /// Position, metres.
    #[must_use]
    pub const fn position(&self) -> Vec3 {
        self.position
    }
    /// Orientation, unit length (renormalised with [`math::normalize_quat`]).
    #[must_use]
    pub const fn rotation(&self) -> Quat {
        self.rotation
    }
}

impl Sensor {
    /// Checks one sensor.
    ///
    /// # Errors
    /// [`WireError::Range`] for id `≥ MAX_SENSORS`, a non-finite or too-far
    /// position, or a non-finite or far-from-unit quaternion.
    pub fn validate(&self) -> Result<SensorSample, WireError> {
        let mut out = SensorSample::default();
        self.validate_into(&mut out).map(|()| out)
    }

    /// [`Sensor::validate`] into `out`, in place (no copy of the sample);
    /// on an error `out` is unchanged.
    ///
    /// # Errors
    /// As [`Sensor::validate`].
    pub fn validate_into(&self, out: &mut SensorSample) -> Result<(), WireError> {
        if usize::from(self.id) >= MAX_SENSORS {
            return Err(WireError::Range);
        }
        let [px, py, pz] = self.position;
        let p2 = px * px + py * py + pz * pz;
        // False for NaN, and for infinity (also from overflowing squares).
        if !(0.0..=POSITION_LIMIT_M * POSITION_LIMIT_M).contains(&p2) {
            return Err(WireError::Range);
        }
        let [w, x, y, z] = self.rotation;
        let q2 = w * w + x * x + y * y + z * z;
        if !within(q2 - 1.0, QUAT_NORM2_TOLERANCE) {
            return Err(WireError::Range);
        }
        out.set(
            self.id,
            Vec3::new(px, py, pz),
            math::normalize_quat(Quat::from_xyzw(x, y, z, w)),
        );
        Ok(())
    }
}

// `ValidTrackerFrame::ids` holds a bit per possible id.
const _: () = assert!(MAX_SENSORS <= u16::BITS as usize);

/// A validated tracker frame: every sensor valid, ids unique.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValidTrackerFrame {
    seq: u32,
    time_us: u32,
    sensors: List<SensorSample, MAX_SENSORS>,
    /// Bit `id` set for each sensor taken (ids are below [`MAX_SENSORS`]).
    ids: u16,
    /// It came as a compact frame (tag 7), not as `f32`s.
    compact: bool,
}

impl ValidTrackerFrame {
    /// Sequence number.
    #[must_use]
    pub const fn seq(&self) -> u32 {
        self.seq
    }
    /// Sample time, microseconds.
    #[must_use]
    pub const fn time_us(&self) -> u32 {
        self.time_us
    }
    /// The sensors, in wire order.
    #[must_use]
    pub fn sensors(&self) -> &[SensorSample] {
        self.sensors.as_slice()
    }
    /// The sensor with id `id`, if present.
    #[must_use]
    pub fn sensor(&self, id: u8) -> Option<&SensorSample> {
        self.sensors().iter().find(|s| s.id == id)
    }
    /// Whether it came as a compact frame (tag 7) rather than as `f32`s
    /// (tag 1, or validated from a [`TrackerFrame`]): the two cost the
    /// receiver differently ([`crate::deadline::Received`]).
    #[must_use]
    pub const fn is_compact(&self) -> bool {
        self.compact
    }
}

impl ValidTrackerFrame {
    /// An empty frame, to be filled by [`TrackerFrame::validate_into`] or a
    /// receiver.
    #[must_use]
    pub fn empty() -> Self {
        Self {
            seq: 0,
            time_us: 0,
            sensors: List::new(),
            ids: 0,
            compact: false,
        }
    }

    /// Starts refilling the frame in place (no whole-buffer clear), from a
    /// compact frame or not.
    pub(crate) fn restart(&mut self, seq: u32, time_us: u32, compact: bool) {
        self.seq = seq;
        self.time_us = time_us;
        self.sensors.clear();
        self.ids = 0;
        self.compact = compact;
    }

    /// Refills the frame with `sensors`, each validated (the check of
    /// [`TrackerFrame::validate_into`], for any source of raw sensors). On
    /// an error the frame holds a partial frame.
    pub(crate) fn validate_from(
        &mut self,
        seq: u32,
        time_us: u32,
        sensors: impl Iterator<Item = Sensor>,
    ) -> Result<(), WireError> {
        self.restart(seq, time_us, false);
        for s in sensors {
            self.push_with(|slot| s.validate_into(slot))?;
        }
        Ok(())
    }

    /// Appends a sensor that `fill` writes in place (no copy of it), then
    /// checks that its id is new.
    ///
    /// # Errors
    /// `fill`'s error; [`WireError::Range`] for a repeated id or more than
    /// [`MAX_SENSORS`] sensors.
    pub(crate) fn push_with(
        &mut self,
        fill: impl FnOnce(&mut SensorSample) -> Result<(), WireError>,
    ) -> Result<(), WireError> {
        let slot = self.sensors.next_slot().ok_or(WireError::Range)?;
        fill(slot)?;
        // One bit per id: constant time, not a scan of the sensors so far.
        let bit = 1u16.checked_shl(u32::from(slot.id)).unwrap_or(0);
        if bit == 0 || self.ids & bit != 0 {
            return Err(WireError::Range);
        }
        self.ids |= bit;
        self.sensors.commit();
        Ok(())
    }
}

impl TrackerFrame {
    /// Checks every sensor and that no id repeats.
    ///
    /// # Errors
    /// [`WireError::Range`] on the first invalid sensor or repeated id.
    pub fn validate(&self) -> Result<ValidTrackerFrame, WireError> {
        let mut out = ValidTrackerFrame::empty();
        self.validate_into(&mut out)?;
        Ok(out)
    }

    /// [`TrackerFrame::validate`] into `out`, in place (it is half a
    /// kilobyte). On an error `out` holds a partial frame.
    ///
    /// # Errors
    /// As [`TrackerFrame::validate`].
    pub fn validate_into(&self, out: &mut ValidTrackerFrame) -> Result<(), WireError> {
        out.validate_from(self.seq, self.time_us, self.sensors.iter().copied())
    }
}

/// Validated parameters: every value finite and within [`PARAM_LIMIT`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValidParams {
    seq: u32,
    values: List<f32, MAX_PARAMS>,
}

impl ValidParams {
    /// Sequence number.
    #[must_use]
    pub const fn seq(&self) -> u32 {
        self.seq
    }
    /// The values (at most [`MAX_PARAMS`]).
    #[must_use]
    pub fn values(&self) -> &[f32] {
        self.values.as_slice()
    }
}

impl Params {
    /// Checks every value.
    ///
    /// # Errors
    /// [`WireError::Range`] for a NaN, infinite or too large value.
    pub fn validate(&self) -> Result<ValidParams, WireError> {
        if self.values.iter().all(|&v| within(v, PARAM_LIMIT)) {
            Ok(ValidParams {
                seq: self.seq,
                values: self.values,
            })
        } else {
            Err(WireError::Range)
        }
    }
}

/// A validated command: indices in range, weight finite and non-negative.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValidCommand {
    seq: u32,
    kind: CommandKind,
}

impl ValidCommand {
    /// Sequence number (echo it in the `Ack`).
    #[must_use]
    pub const fn seq(&self) -> u32 {
        self.seq
    }
    /// What to do; its invariants hold (see [`Command::validate`]).
    #[must_use]
    pub const fn kind(&self) -> CommandKind {
        self.kind
    }
}

impl Command {
    /// Checks `SetGoalWeight` (goal `< MAX_GOALS`, `0 ≤ weight ≤
    /// WEIGHT_LIMIT`), `Boresight` (sensor `< MAX_SENSORS`) and `Jog`
    /// (channel `< MAX_SERVOS`, target `≤ JOG_TARGET_MAX`). Table and
    /// clip numbers are checked by whoever owns the tables.
    ///
    /// # Errors
    /// [`WireError::Range`] when a check fails.
    pub fn validate(&self) -> Result<ValidCommand, WireError> {
        let ok = match self.kind {
            CommandKind::SetGoalWeight { goal, weight } => {
                usize::from(goal) < MAX_GOALS && (0.0..=WEIGHT_LIMIT).contains(&weight)
            }
            CommandKind::Boresight { sensor } => usize::from(sensor) < MAX_SENSORS,
            CommandKind::Jog { channel, target } => {
                usize::from(channel) < MAX_SERVOS && target <= JOG_TARGET_MAX
            }
            CommandKind::Arm
            | CommandKind::Disarm
            | CommandKind::SelectTable(_)
            | CommandKind::SelectClip(_)
            | CommandKind::RequestStatus
            | CommandKind::Show { .. } => true,
        };
        if ok {
            Ok(ValidCommand {
                seq: self.seq,
                kind: self.kind,
            })
        } else {
            Err(WireError::Range)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sensor(id: u8, p: [f32; 3], q: [f32; 4]) -> Sensor {
        Sensor {
            id,
            position: p,
            rotation: q,
        }
    }

    const ID: [f32; 4] = [1.0, 0.0, 0.0, 0.0];

    #[test]
    fn sensor_checks() {
        assert!(sensor(15, [99.0, 0.0, 0.0], ID).validate().is_ok());
        assert!(sensor(16, [0.0; 3], ID).validate().is_err());
        assert!(sensor(0, [0.0, 100.1, 0.0], ID).validate().is_err());
        assert!(sensor(0, [60.0, 60.0, 60.0], ID).validate().is_err());
        assert!(sensor(0, [f32::NAN, 0.0, 0.0], ID).validate().is_err());
        assert!(sensor(0, [f32::INFINITY, 0.0, 0.0], ID).validate().is_err());
        assert!(sensor(0, [1e30, 0.0, 0.0], ID).validate().is_err());
        assert!(
            sensor(0, [0.0; 3], [f32::NAN, 0.0, 0.0, 0.0])
                .validate()
                .is_err()
        );
        assert!(sensor(0, [0.0; 3], [0.0; 4]).validate().is_err());
        assert!(
            sensor(0, [0.0; 3], [2.0, 0.0, 0.0, 0.0])
                .validate()
                .is_err()
        );
    }

    #[test]
    fn near_unit_quaternion_is_renormalised() {
        // [w,x,y,z] = [1.02, 0, 0, 0] → identity; wire order w first.
        let s = sensor(3, [1.0, 2.0, 3.0], [0.0, 0.0, 1.02, 0.0])
            .validate()
            .unwrap();
        let r = s.rotation();
        assert!((r.y - 1.0).abs() < 1e-6 && r.x == 0.0 && r.z == 0.0 && r.w == 0.0);
        assert_eq!(s.position(), Vec3::new(1.0, 2.0, 3.0));
        assert_eq!(s.id(), 3);
    }
}
