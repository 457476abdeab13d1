//! The sensor map: tracker sensors → synthesis parameters and weighted goals.
//!
//! Each frame, [`Rig::map_sensors`] reads the sensors of one tracker frame
//! (ids, world positions, `[w, x, y, z]` rotations) and
//!
//! - for every [`ParamMap`] writes
//!   `params[param] = offset + scale · measure(sensor in frame)`, where the
//!   sensor pose is first expressed in the entry's reference frame
//!   ([`RefFrame`]: world, a segment's rest frame, or another sensor's current
//!   frame): `p' = R⁻¹·(p − o)`, `q' = R⁻¹·q`; and the measure is a coordinate
//!   of `p'`, a cylindrical coordinate of `p'` about an axis through a point,
//!   or the twist angle of `q'` about an axis;
//! - for every [`GoalMap`], in order, pushes its goal (and, with an
//!   orientation weight, a second, orientation goal) into the goal set. A
//!   sensor goal's target is `offset + scale · p'` (and `q' · rotation_offset`
//!   for the orientation), expressed in the entry's puppet frame; plane and
//!   point goals are fixed.
//!
//! The mapping is total: any float (NaN, infinities, zero quaternions) is
//! accepted and nothing panics. A parameter whose sensor (or reference
//! sensor) is missing from the frame, or whose value comes out non-finite,
//! keeps its previous value; such a goal is still pushed, with weight 0
//! (inactive), so goal indices stay fixed from frame to frame. Both are
//! reported in the [`MapReport`].

use super::desc::Cylinder;
use super::{GoalMap, GoalSource, Measure, ParamMap, RefFrame, Rig, SensorGoal, quat_wxyz};
use crate::goal::{Attach, Frame, Goal, GoalSet, PlaneSide, Target};
use crate::math;
use crate::wire::Sensor;
use glam::{Quat, Vec3};

/// What [`Rig::map_sensors`] could not do. Bit `i` of each mask refers to
/// entry `i` of the rig's parameter or goal list.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MapReport {
    /// Parameters left unchanged: their sensor or reference sensor is missing.
    pub params_missing: u32,
    /// Parameters left unchanged: non-finite input or result.
    pub params_non_finite: u32,
    /// Parameters whose index is beyond the output slice.
    pub params_unwritten: u32,
    /// Goals made inactive: their sensor or reference sensor is missing.
    pub goals_missing: u32,
    /// Goals made inactive: non-finite input or result.
    pub goals_non_finite: u32,
    /// Goal entries that did not fit the goal set.
    pub goals_dropped: u32,
}

impl MapReport {
    /// Whether every entry was mapped.
    #[must_use]
    pub fn is_clean(&self) -> bool {
        *self == MapReport::default()
    }
}

/// Why one entry was skipped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Skip {
    Missing,
    NonFinite,
}

/// Sets bit `i` of a mask (bits past 31 are dropped).
#[inline]
fn set(mask: &mut u32, i: usize) {
    if let Some(bit) = u32::try_from(i).ok().and_then(|i| 1u32.checked_shl(i)) {
        *mask |= bit;
    }
}

/// A finite rigid placement (origin, unit rotation).
type Placement = (Vec3, Quat);

/// A sensor's placement in world, checked finite and normalized.
fn sensor_placement(sensors: &[Sensor], id: u8) -> Result<Placement, Skip> {
    let s = sensors.iter().find(|s| s.id == id).ok_or(Skip::Missing)?;
    let p = Vec3::from_array(s.position);
    let q = quat_wxyz(s.rotation);
    let n2 = math::quat_dot(q, q);
    if !p.is_finite() || !q.is_finite() || !(1e-12..=1e12).contains(&n2) {
        return Err(Skip::NonFinite);
    }
    Ok((p, math::normalize_quat(q)))
}

/// `v` if finite.
#[inline]
fn finite(v: f32) -> Result<f32, Skip> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(Skip::NonFinite)
    }
}

/// Cylindrical coordinate of `d` about `axis` (see [`Cylinder::Angle`] for
/// the angle's zero and sense).
fn cylindrical(d: Vec3, axis: super::AxisName, component: Cylinder) -> f32 {
    let (h, u, v) = match axis {
        super::AxisName::X => (d.x, d.y, d.z),
        super::AxisName::Y => (d.y, d.z, d.x),
        super::AxisName::Z => (d.z, d.x, d.y),
    };
    match component {
        Cylinder::Radius => math::sqrt(u * u + v * v),
        Cylinder::Angle => math::atan2(v, u),
        Cylinder::Height => h,
    }
}

/// `v` normalized (left as is when its squared length is exactly 1).
#[inline]
fn unit_vec3(v: Vec3) -> Vec3 {
    if v.dot(v) == 1.0 {
        v
    } else {
        math::normalize_vec3(v)
    }
}

/// Twist angle of `q` about `axis`, radians in `[−π, π]`.
fn twist(q: Quat, axis: super::AxisName) -> f32 {
    let q = if q.w < 0.0 { -q } else { q };
    2.0 * math::atan2(axis.to_body().component(q.xyz()), q.w)
}

impl<const N: usize> Rig<'_, N> {
    /// The placement of a reference frame (`None` = world).
    fn reference(&self, frame: RefFrame, sensors: &[Sensor]) -> Result<Option<Placement>, Skip> {
        match frame {
            RefFrame::World => Ok(None),
            RefFrame::Segment(s) => {
                let i = usize::from(s);
                match (self.rest.positions.get(i), self.rest.rotations.get(i)) {
                    (Some(&p), Some(&q)) => Ok(Some((p, q))),
                    _ => Err(Skip::Missing),
                }
            }
            RefFrame::Sensor(id) => sensor_placement(sensors, id).map(Some),
        }
    }

    /// A sensor's placement expressed in a reference frame.
    fn sensor_in(&self, sensors: &[Sensor], id: u8, frame: RefFrame) -> Result<Placement, Skip> {
        let (p, q) = sensor_placement(sensors, id)?;
        match self.reference(frame, sensors)? {
            None => Ok((p, q)),
            Some((o, r)) => {
                let inv = r.conjugate();
                Ok((inv * (p - o), inv * q))
            }
        }
    }

    /// The value of one parameter entry.
    fn param_value(&self, m: &ParamMap, sensors: &[Sensor]) -> Result<f32, Skip> {
        let (p, q) = self.sensor_in(sensors, m.sensor, m.frame)?;
        let raw = match m.measure {
            Measure::Position(a) => a.to_body().component(p),
            Measure::Cylindrical {
                axis,
                center,
                component,
            } => cylindrical(p - Vec3::from_array(center), axis, component),
            Measure::Rotation(a) => twist(q, a),
        };
        finite(m.offset + m.scale * finite(raw)?)
    }

    /// The targets of a sensor goal: position and orientation.
    fn sensor_targets(&self, s: &SensorGoal, sensors: &[Sensor]) -> Result<(Vec3, Quat), Skip> {
        let (p, q) = self.sensor_in(sensors, s.sensor, s.source)?;
        let target = Vec3::from_array(s.offset) + p * s.scale;
        let rotation = math::normalize_quat(q * quat_wxyz(s.rotation_offset));
        if target.is_finite() && rotation.is_finite() {
            Ok((target, rotation))
        } else {
            Err(Skip::NonFinite)
        }
    }

    /// Maps one tracker frame's sensors to parameters and goals (see the
    /// module doc). `params` is indexed by each entry's `param`; entries
    /// beyond its length are reported, not written. `goals` is cleared and
    /// refilled with [`Rig::goal_count`] goals in rig order.
    pub fn map_sensors<const G: usize>(
        &self,
        sensors: &[Sensor],
        params: &mut [f32],
        goals: &mut GoalSet<G>,
    ) -> MapReport {
        let mut report = MapReport::default();
        for (i, m) in self.params.iter().enumerate() {
            match self.param_value(m, sensors) {
                Ok(v) => match params.get_mut(usize::from(m.param)) {
                    Some(slot) => *slot = v,
                    None => set(&mut report.params_unwritten, i),
                },
                Err(Skip::Missing) => set(&mut report.params_missing, i),
                Err(Skip::NonFinite) => set(&mut report.params_non_finite, i),
            }
        }
        goals.clear();
        for (i, g) in self.goals.iter().enumerate() {
            let pushed = self.push_goal(i, g, sensors, goals, &mut report);
            if pushed.is_err() {
                set(&mut report.goals_dropped, i);
            }
        }
        report
    }

    /// Pushes the goal(s) of one entry.
    fn push_goal<const G: usize>(
        &self,
        i: usize,
        g: &GoalMap,
        sensors: &[Sensor],
        goals: &mut GoalSet<G>,
        report: &mut MapReport,
    ) -> Result<(), crate::goal::GoalError> {
        let base = Goal {
            segment: g.segment,
            attach: g
                .point
                .map_or(Attach::Touch, |p| Attach::Point(Vec3::from_array(p))),
            target: Target::Position(Vec3::ZERO),
            frame: g.frame.map_or(Frame::World, Frame::Segment),
            weight: g.weight,
        };
        match g.target {
            GoalSource::Point(t) => {
                goals.push(Goal {
                    target: Target::Position(Vec3::from_array(t)),
                    ..base
                })?;
            }
            GoalSource::Plane {
                normal,
                offset,
                above,
            } => {
                let side = if above {
                    PlaneSide::Above
                } else {
                    PlaneSide::Contact
                };
                goals.push(Goal {
                    target: Target::Plane {
                        normal: unit_vec3(Vec3::from_array(normal)),
                        offset,
                        side,
                    },
                    ..base
                })?;
            }
            GoalSource::Sensor(s) => {
                let (position, rotation, weight) = match self.sensor_targets(&s, sensors) {
                    Ok((p, q)) => (p, q, 1.0),
                    Err(skip) => {
                        let mask = match skip {
                            Skip::Missing => &mut report.goals_missing,
                            Skip::NonFinite => &mut report.goals_non_finite,
                        };
                        set(mask, i);
                        (Vec3::ZERO, Quat::IDENTITY, 0.0)
                    }
                };
                goals.push(Goal {
                    target: Target::Position(position),
                    weight: g.weight * weight,
                    ..base
                })?;
                if s.orientation_weight > 0.0 {
                    goals.push(Goal {
                        target: Target::Orientation(rotation),
                        weight: s.orientation_weight * weight,
                        ..base
                    })?;
                }
            }
        }
        Ok(())
    }
}
