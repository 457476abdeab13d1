//! Goals: where points of the body should be, weighted.
//!
//! A goal of Badler et al. (1987) is a location plus a weight; weight 0 means
//! inactive. When goals conflict the weights decide: at equilibrium the weighted
//! displacements balance, so two unreachable goals weighted 40 and 10 end with
//! the second four times farther from its goal than the first.
//!
//! Beyond the paper's point goals (its "Extensions" list):
//! - the attached point can be any point in the segment's frame
//!   ([`Attach::Point`]), not only the touch point;
//! - [`Target::Plane`]: only the distance to a plane counts (a foot on the
//!   floor), either exactly on it or merely not below it;
//! - [`Target::Orientation`]: the segment's orientation, with its own weight
//!   (per rad², against per m² for positions);
//! - the target can be given in another segment's frame ([`Frame::Segment`]),
//!   e.g. a hand on the other wrist; it then moves with that segment.
//!
//! The solver minimises `Σ weight · residual²` (see [`Goal::evaluate`]).

use crate::body::Body;
use crate::math;
use crate::pose::Pose;
use glam::{Quat, Vec3};

/// The frame a goal's target is expressed in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Frame {
    /// World coordinates.
    World,
    /// The frame of this segment (its joint origin and world orientation).
    Segment(u8),
}

/// Which point of the segment the goal pulls.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Attach {
    /// The segment's touch point.
    Touch,
    /// A point in the segment's frame, metres.
    Point(Vec3),
}

/// Which side of a plane satisfies a plane goal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlaneSide {
    /// The point must lie on the plane.
    Contact,
    /// The point must not lie below the plane (the normal points "up").
    Above,
}

/// What a goal asks of its segment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Target {
    /// The attached point at this location.
    Position(Vec3),
    /// The attached point on the plane `normal · x = offset` (`normal` unit).
    Plane {
        /// Unit normal.
        normal: Vec3,
        /// Signed distance of the plane from the frame origin along `normal`.
        offset: f32,
        /// Equality or one-sided.
        side: PlaneSide,
    },
    /// The segment's orientation equal to this rotation.
    Orientation(Quat),
}

/// One weighted goal on one segment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Goal {
    /// The segment the goal pulls.
    pub segment: u8,
    /// The point of the segment (ignored by orientation goals).
    pub attach: Attach,
    /// The target.
    pub target: Target,
    /// The frame of the target.
    pub frame: Frame,
    /// Importance; 0 (or negative, or NaN) means inactive.
    pub weight: f32,
}

/// A goal's current error, in world coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Residual {
    /// Displacement from the attached point to the target, m.
    Position(Vec3),
    /// Distance along the world plane normal that the point must still move
    /// (0 for a satisfied one-sided plane), with that normal.
    Plane {
        /// World unit normal.
        normal: Vec3,
        /// Signed correction along `normal`, m.
        correction: f32,
    },
    /// The rotation vector (axis × angle, world) that takes the segment to its
    /// target orientation, rad.
    Orientation(Vec3),
}

impl Residual {
    /// The size of the error: metres for points and planes, radians for
    /// orientations.
    #[must_use]
    pub fn magnitude(&self) -> f32 {
        match *self {
            Residual::Position(d) | Residual::Orientation(d) => norm(d),
            Residual::Plane { correction, .. } => math::abs(correction),
        }
    }

    /// The displacement the attached point should make (zero for orientations).
    #[must_use]
    pub fn displacement(&self) -> Vec3 {
        match *self {
            Residual::Position(d) => d,
            Residual::Plane { normal, correction } => normal * correction,
            Residual::Orientation(_) => Vec3::ZERO,
        }
    }
}

impl Goal {
    /// An inactive goal (weight 0).
    pub const INACTIVE: Goal = Goal {
        segment: 0,
        attach: Attach::Touch,
        target: Target::Position(Vec3::ZERO),
        frame: Frame::World,
        weight: 0.0,
    };

    /// The paper's goal: this segment's touch point at a world location.
    #[must_use]
    pub const fn reach(segment: u8, location: Vec3, weight: f32) -> Self {
        Goal {
            segment,
            attach: Attach::Touch,
            target: Target::Position(location),
            frame: Frame::World,
            weight,
        }
    }

    /// The touch point on (or, with [`PlaneSide::Above`], not below) the world
    /// plane `normal · x = offset`; `normal` is normalised here.
    #[must_use]
    pub fn plane(segment: u8, normal: Vec3, offset: f32, side: PlaneSide, weight: f32) -> Self {
        let normal = math::normalize_vec3(normal);
        Goal {
            segment,
            attach: Attach::Touch,
            target: Target::Plane {
                normal,
                offset,
                side,
            },
            frame: Frame::World,
            weight,
        }
    }

    /// The segment's world orientation equal to `rotation`.
    #[must_use]
    pub const fn orient(segment: u8, rotation: Quat, weight: f32) -> Self {
        Goal {
            segment,
            attach: Attach::Touch,
            target: Target::Orientation(rotation),
            frame: Frame::World,
            weight,
        }
    }

    /// The same goal on another point of the segment (segment frame, m).
    #[must_use]
    pub const fn at(mut self, point: Vec3) -> Self {
        self.attach = Attach::Point(point);
        self
    }

    /// The same goal with its target expressed in another segment's frame.
    #[must_use]
    pub const fn in_frame(mut self, segment: u8) -> Self {
        self.frame = Frame::Segment(segment);
        self
    }

    /// Whether the goal takes part (positive, finite weight).
    #[inline]
    #[must_use]
    pub fn is_active(&self) -> bool {
        // The bits of the positive finite floats are 1 ..= those of MAX: one
        // unsigned comparison (the compiler turns `> 0 && is_finite` into
        // some 30 instructions of class tests on the M4F).
        self.weight.to_bits().wrapping_sub(1) < f32::MAX.to_bits()
    }

    /// Whether the goal constrains a point (position or plane), as opposed to an
    /// orientation.
    #[inline]
    #[must_use]
    pub fn is_positional(&self) -> bool {
        !matches!(self.target, Target::Orientation(_))
    }

    /// The attached point in the segment's frame.
    #[must_use]
    pub fn local_point(&self, body: &Body<'_>) -> Option<Vec3> {
        match self.attach {
            Attach::Point(p) => Some(p),
            Attach::Touch => body.segment(usize::from(self.segment)).map(|s| s.touch),
        }
    }

    /// The attached point in world coordinates.
    #[must_use]
    pub fn world_point<const N: usize>(&self, body: &Body<'_>, pose: &Pose<N>) -> Option<Vec3> {
        let i = usize::from(self.segment);
        let p = self.local_point(body)?;
        Some(*pose.positions.get(i)? + *pose.rotations.get(i)? * p)
    }

    /// The frame segment's world placement (`None` for the world frame).
    fn frame_placement<const N: usize>(&self, pose: &Pose<N>) -> Option<Option<(Vec3, Quat)>> {
        match self.frame {
            Frame::World => Some(None),
            Frame::Segment(s) => {
                let i = usize::from(s);
                Some(Some((*pose.positions.get(i)?, *pose.rotations.get(i)?)))
            }
        }
    }

    /// The goal's current error for a world pose; `None` if a segment index is
    /// out of range.
    #[must_use]
    pub fn evaluate<const N: usize>(&self, body: &Body<'_>, pose: &Pose<N>) -> Option<Residual> {
        let frame = self.frame_placement(pose)?;
        let to_world = |p: Vec3| match frame {
            None => p,
            Some((o, r)) => o + r * p,
        };
        let rotate = |v: Vec3| match frame {
            None => v,
            Some((_, r)) => r * v,
        };
        match self.target {
            Target::Position(g) => Some(Residual::Position(
                to_world(g) - self.world_point(body, pose)?,
            )),
            Target::Plane {
                normal,
                offset,
                side,
            } => {
                let n = rotate(normal);
                let origin = frame.map_or(Vec3::ZERO, |(o, _)| o);
                let s = n.dot(self.world_point(body, pose)?) - offset - n.dot(origin);
                let correction = match side {
                    PlaneSide::Contact => -s,
                    PlaneSide::Above if s < 0.0 => -s,
                    PlaneSide::Above => 0.0,
                };
                Some(Residual::Plane {
                    normal: n,
                    correction,
                })
            }
            Target::Orientation(q) => {
                let target = frame.map_or(q, |(_, r)| r * q);
                let current = *pose.rotations.get(usize::from(self.segment))?;
                Some(Residual::Orientation(rotation_vector(
                    target * current.conjugate(),
                )))
            }
        }
    }
}

/// `|v|` by [`math::rsqrt`] (a few ulp; the exactly rounded [`math::length`]
/// needs `f64` arithmetic, which is soft-float on the Cortex-M4F).
#[inline]
#[must_use]
pub fn norm(v: Vec3) -> f32 {
    let s = v.length_squared();
    if s > 0.0 { s * math::rsqrt(s) } else { 0.0 }
}

/// The rotation vector (axis × angle, angle in [0, π]) of a unit quaternion.
#[must_use]
pub fn rotation_vector(q: Quat) -> Vec3 {
    let q = if q.w < 0.0 { -q } else { q };
    let v = q.xyz();
    let s = norm(v);
    if s < 1e-6 {
        // sin(θ/2) ≈ θ/2: the vector part is half the rotation vector.
        return v * 2.0;
    }
    v * (2.0 * math::atan2(s, q.w) / s)
}

/// Why a goal could not be added.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GoalError {
    /// The set is full.
    Full,
}

/// A fixed-capacity set of goals.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GoalSet<const G: usize> {
    goals: [Goal; G],
    len: usize,
}

impl<const G: usize> Default for GoalSet<G> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const G: usize> GoalSet<G> {
    /// An empty set.
    #[must_use]
    pub const fn new() -> Self {
        GoalSet {
            goals: [Goal::INACTIVE; G],
            len: 0,
        }
    }

    /// Adds a goal; returns its index.
    pub fn push(&mut self, goal: Goal) -> Result<usize, GoalError> {
        let slot = self.goals.get_mut(self.len).ok_or(GoalError::Full)?;
        *slot = goal;
        self.len += 1;
        Ok(self.len - 1)
    }

    /// Removes every goal.
    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// The goals.
    #[must_use]
    pub fn as_slice(&self) -> &[Goal] {
        self.goals.get(..self.len).unwrap_or(&[])
    }

    /// The goals, mutably (to move targets or change weights between frames).
    pub fn as_mut_slice(&mut self) -> &mut [Goal] {
        self.goals.get_mut(..self.len).unwrap_or(&mut [])
    }

    /// The goal at `index`.
    #[must_use]
    pub fn get(&self, index: usize) -> Option<&Goal> {
        self.as_slice().get(index)
    }

    /// The goal at `index`, mutably.
    pub fn get_mut(&mut self, index: usize) -> Option<&mut Goal> {
        self.as_mut_slice().get_mut(index)
    }

    /// Number of goals (active or not).
    #[must_use]
    pub const fn len(&self) -> usize {
        self.len
    }

    /// Whether the set is empty.
    #[must_use]
    pub const fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The capacity `G`.
    #[must_use]
    pub const fn capacity(&self) -> usize {
        G
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::{Angles, tempus};
    use crate::pose::LocalPose;

    fn rest_pose() -> Pose<32> {
        let a = Angles::<32>::rest(&tempus::BODY).unwrap();
        let mut local = LocalPose::<32>::default();
        let mut pose = Pose::<32>::default();
        a.forward(&tempus::BODY, &mut local, &mut pose).unwrap();
        pose
    }

    #[test]
    fn goal_set_capacity() {
        let mut s = GoalSet::<2>::new();
        assert_eq!(s.push(Goal::reach(1, Vec3::ZERO, 1.0)), Ok(0));
        assert_eq!(s.push(Goal::reach(2, Vec3::ZERO, 1.0)), Ok(1));
        assert_eq!(
            s.push(Goal::reach(3, Vec3::ZERO, 1.0)),
            Err(GoalError::Full)
        );
        assert_eq!(s.len(), 2);
        s.get_mut(1).unwrap().weight = 0.0;
        assert!(!s.get(1).unwrap().is_active());
        s.clear();
        assert!(s.is_empty());
    }

    #[test]
    fn active_means_positive_and_finite() {
        let weights = [
            0.0,
            -0.0,
            -1.0,
            f32::MIN_POSITIVE,
            1e-45,
            1.0,
            f32::MAX,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            -f32::NAN,
        ];
        for w in weights {
            let g = Goal::reach(1, Vec3::ZERO, w);
            assert_eq!(g.is_active(), w > 0.0 && w.is_finite(), "{w}");
        }
    }

    #[test]
    fn position_residual_at_rest() {
        let pose = rest_pose();
        // Rest: the left palm centre is at x = 0.02 + 0.16, y = 0.10 + 0.38 - 0.30 - 0.26 - 0.08.
        let palm = Vec3::new(0.18, -0.16, 0.0);
        let g = Goal::reach(
            tempus::index::LEFT_HAND,
            palm + Vec3::new(0.0, 0.0, 0.3),
            1.0,
        );
        let r = g.evaluate(&tempus::BODY, &pose).unwrap();
        assert!(
            (r.displacement() - Vec3::new(0.0, 0.0, 0.3)).length() < 1e-5,
            "{r:?}"
        );
        assert!((r.magnitude() - 0.3).abs() < 1e-5);
    }

    #[test]
    fn plane_residuals() {
        let pose = rest_pose();
        // At rest (root at the origin) the left foot's touch point is at
        // y = -0.05 - 0.42 - 0.40 - 0.08 = -0.95.
        let floor = |y, side| Goal::plane(tempus::index::LEFT_FOOT, Vec3::Y, y, side, 1.0);
        let c = floor(-1.0, PlaneSide::Contact)
            .evaluate(&tempus::BODY, &pose)
            .unwrap();
        assert!(
            (c.displacement() - Vec3::new(0.0, -0.05, 0.0)).length() < 1e-5,
            "{c:?}"
        );
        let a = floor(-1.0, PlaneSide::Above)
            .evaluate(&tempus::BODY, &pose)
            .unwrap();
        assert_eq!(a.magnitude(), 0.0);
        let b = floor(-0.7, PlaneSide::Above)
            .evaluate(&tempus::BODY, &pose)
            .unwrap();
        assert!(
            (b.displacement() - Vec3::new(0.0, 0.25, 0.0)).length() < 1e-5,
            "{b:?}"
        );
        // A tilted plane: normal (1, 1, 0)/√2 through the origin.
        let t = Goal::plane(
            tempus::index::LEFT_FOOT,
            Vec3::new(1.0, 1.0, 0.0),
            0.0,
            PlaneSide::Contact,
            1.0,
        );
        let r = t.evaluate(&tempus::BODY, &pose).unwrap();
        let foot = Vec3::new(0.09, -0.95, 0.14);
        assert!((r.magnitude() - (foot.x + foot.y).abs() / 2f32.sqrt()).abs() < 1e-5);
    }

    #[test]
    fn frame_relative_position() {
        let pose = rest_pose();
        // A target at the origin of the left hand's frame, for the right hand:
        // the displacement is left wrist - right palm.
        let g = Goal::reach(tempus::index::RIGHT_HAND, Vec3::ZERO, 1.0)
            .in_frame(tempus::index::LEFT_HAND);
        let r = g.evaluate(&tempus::BODY, &pose).unwrap().displacement();
        assert!((r - Vec3::new(0.36, 0.08, 0.0)).length() < 1e-5, "{r}");
    }

    #[test]
    fn orientation_residual_is_the_rotation_vector() {
        let pose = rest_pose();
        let q = math::from_axis_angle(Vec3::Y, 0.5);
        let r = Goal::orient(tempus::index::HEAD, q, 1.0)
            .evaluate(&tempus::BODY, &pose)
            .unwrap();
        match r {
            Residual::Orientation(w) => {
                assert!((w - Vec3::new(0.0, 0.5, 0.0)).length() < 1e-4, "{w}")
            }
            _ => panic!("wrong residual kind"),
        }
        assert_eq!(r.displacement(), Vec3::ZERO);
    }

    #[test]
    fn bad_indices_give_none() {
        let pose = rest_pose();
        assert!(
            Goal::reach(40, Vec3::ZERO, 1.0)
                .evaluate(&tempus::BODY, &pose)
                .is_none()
        );
        assert!(
            Goal::reach(1, Vec3::ZERO, 1.0)
                .in_frame(200)
                .evaluate(&tempus::BODY, &pose)
                .is_none()
        );
    }
}
