//! The active goals of the whole-tree solver as rows of its goal-space
//! system: each goal owns a block of three rows (a plane goal uses the
//! first), scaled by `√(w / w_max)`, and its geometry at the current pose.

use super::{SolveError, Work};
use crate::goal::{Frame, Goal, PlaneSide, Residual, Target, norm};
use crate::math;
use glam::Vec3;

/// The most active goals [`Method::TreeDls`](super::Method::TreeDls) takes.
pub const MAX_GOALS: usize = 10;
/// One 3-vector per goal.
pub(super) type Rhs = [Vec3; MAX_GOALS];

/// What a goal constrains.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Kind {
    /// A point at a point.
    Point,
    /// A point on a plane (one row).
    Plane,
    /// An orientation.
    Orientation,
}

/// One active goal: its rows, its scale and its geometry at the current pose.
#[derive(Clone, Copy, Debug)]
pub(super) struct Slot {
    /// Index in the goal set.
    pub goal: u8,
    pub kind: Kind,
    /// A one-sided plane goal.
    pub one_sided: bool,
    /// √(w / w_max).
    pub sw: f32,
    /// Takes part in the step (false for a satisfied one-sided plane).
    pub awake: bool,
    /// Attached point.
    pub x: Vec3,
    /// Target point (points) or frame origin (planes).
    pub g: Vec3,
    /// Plane normal.
    pub n: Vec3,
    /// Height above the plane of a satisfied one-sided plane goal.
    pub gap: f32,
    /// Unscaled residual (a plane's in `x`; zero while asleep).
    pub r: Vec3,
    /// `r` before the step being tried ([`Slots::keep`]).
    pub before: Vec3,
    /// The last accepted step left more than half of the residual.
    pub stretched: bool,
}

const EMPTY_SLOT: Slot = Slot {
    goal: 0,
    kind: Kind::Point,
    one_sided: false,
    sw: 0.0,
    awake: false,
    x: Vec3::ZERO,
    g: Vec3::ZERO,
    n: Vec3::ZERO,
    gap: 0.0,
    r: Vec3::ZERO,
    before: Vec3::ZERO,
    stretched: false,
};

/// The active goals.
#[derive(Clone, Copy, Debug)]
pub(super) struct Slots {
    pub s: [Slot; MAX_GOALS],
    pub count: usize,
    /// `Σ (w / w_max)·|r|²` at the current pose.
    pub error: f32,
    /// The largest unscaled `|r|²`.
    pub worst: f32,
    /// `Σ w / w_max`.
    pub weight: f32,
    /// Point goals in the world frame (the cheapest to evaluate).
    pub simple: usize,
}

impl Slots {
    /// No goal.
    pub const EMPTY: Self = Slots {
        s: [EMPTY_SLOT; MAX_GOALS],
        count: 0,
        error: 0.0,
        worst: 0.0,
        weight: 0.0,
        simple: 0,
    };

    /// Takes the active goals of the set (scaled by the heaviest weight
    /// `wmax`), not yet evaluated, in place of any it held.
    pub fn init(&mut self, goals: &[Goal], wmax: f32) -> Result<(), SolveError> {
        (self.count, self.weight, self.simple) = (0, 0.0, 0);
        for (i, g) in goals.iter().enumerate().filter(|(_, g)| g.is_active()) {
            if let (Target::Position(_), Frame::World) = (g.target, g.frame) {
                self.simple += 1;
            }
            let (kind, one_sided) = match g.target {
                Target::Position(_) => (Kind::Point, false),
                Target::Plane { side, .. } => (Kind::Plane, side == PlaneSide::Above),
                Target::Orientation(_) => (Kind::Orientation, false),
            };
            let rel = g.weight / wmax;
            let free = self.s.get_mut(self.count).ok_or(SolveError::TooManyGoals)?;
            *free = Slot {
                goal: u8::try_from(i).map_err(|_| SolveError::TooManyGoals)?,
                kind,
                one_sided,
                sw: rel * math::rsqrt(rel),
                ..EMPTY_SLOT
            };
            self.weight += rel;
            self.count += 1;
        }
        Ok(())
    }

    /// The slots in use.
    pub fn iter(&self) -> impl Iterator<Item = &Slot> {
        self.s.iter().take(self.count)
    }

    /// Refreshes every slot's geometry and residual at the current pose, and
    /// the error and the worst residual.
    pub fn evaluate<const N: usize>(&mut self, work: &Work<'_, '_, N>) -> Result<(), SolveError> {
        let (mut error, mut worst) = (0.0f32, 0.0f32);
        for slot in self.s.iter_mut().take(self.count) {
            let bad = SolveError::BadGoal(slot.goal);
            let goal = work.goals.get(usize::from(slot.goal)).ok_or(bad)?;
            slot.refresh(goal, work).ok_or(bad)?;
            let r2 = slot.r.length_squared();
            worst = math::max(r2, worst);
            error += slot.sw * slot.sw * r2;
        }
        self.error = error;
        self.worst = worst;
        Ok(())
    }

    /// Bit `j`: slot `j` is awake.
    pub fn awake(&self) -> u16 {
        self.iter()
            .enumerate()
            .fold(0, |m, (j, s)| if s.awake { m | 1 << j } else { m })
    }

    /// The scaled residuals of the awake goals (zero for the others) in the
    /// first [`Slots::count`] entries of `out` (the others are left as they
    /// are).
    pub fn rhs(&self, out: &mut Rhs) {
        for (o, slot) in out.iter_mut().zip(self.iter()) {
            *o = if slot.awake {
                slot.r * slot.sw
            } else {
                Vec3::ZERO
            };
        }
    }

    /// Keeps every goal's residual as the one before the next step.
    pub fn keep(&mut self) {
        for slot in self.s.iter_mut().take(self.count) {
            slot.before = slot.r;
        }
    }

    /// After an accepted step: marks the goals whose residual the step did
    /// not halve, keeps the residuals for the next step and returns the
    /// largest change of any goal's residual (unscaled, squared).
    pub fn accept(&mut self) -> f32 {
        let mut moved = 0.0;
        for slot in self.s.iter_mut().take(self.count) {
            let (r, before) = (slot.r, slot.before);
            slot.stretched = r.length_squared() > 0.25 * before.length_squared();
            moved = math::max((r - before).length_squared(), moved);
            slot.before = r;
        }
        moved
    }
}

impl Slot {
    /// The size of the residual: [`Residual::magnitude`] of the goal's
    /// residual at the pose of the last refresh.
    pub fn magnitude(&self) -> f32 {
        match self.kind {
            Kind::Plane => math::abs(self.r.x),
            Kind::Point | Kind::Orientation => norm(self.r),
        }
    }

    /// Geometry and residual at the current pose; `None` on a bad index.
    fn refresh<const N: usize>(&mut self, goal: &Goal, work: &Work<'_, '_, N>) -> Option<()> {
        let (body, pose) = (work.body, &*work.pose);
        if let (Target::Position(target), Frame::World) = (goal.target, goal.frame) {
            // `Goal::evaluate`'s residual, with the point computed once.
            self.x = goal.world_point(body, pose)?;
            self.r = target - self.x;
            self.g = self.x + self.r;
            self.awake = true;
            return Some(());
        }
        match goal.evaluate(body, pose)? {
            Residual::Position(d) => {
                self.x = goal.world_point(body, pose)?;
                self.g = self.x + d;
                self.awake = true;
                self.r = d;
            }
            Residual::Plane { normal, correction } => {
                self.x = goal.world_point(body, pose)?;
                self.n = normal;
                self.g = match goal.frame {
                    Frame::World => Vec3::ZERO,
                    Frame::Segment(f) => *pose.positions.get(usize::from(f))?,
                };
                self.awake = !(self.one_sided && correction == 0.0);
                if !self.awake
                    && let Target::Plane { offset, .. } = goal.target
                {
                    self.gap = normal.dot(self.x) - offset - normal.dot(self.g);
                }
                self.r = Vec3::new(correction, 0.0, 0.0);
            }
            Residual::Orientation(w) => {
                self.awake = true;
                self.r = w;
            }
        }
        Some(())
    }
}
