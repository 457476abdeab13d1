//! Weighted damped least squares over the whole reach tree
//! ([`Method::TreeDls`](super::Method::TreeDls)).
//!
//! Minimises `E(θ) = Σ wᵢ·|rᵢ(θ)|²` over the joint angles of the reach tree's
//! chains (and the root translation in [`RootMode::Float`](super::RootMode))
//! with Levenberg–Marquardt steps in the small goal-space form of
//! [`super::system`], on the Jacobian of [`super::joints`].
//!
//! A step that does not lower `E` is undone and the damping raised ×4; one that
//! does lowers it ÷3. Gauss–Newton underestimates steps where goals compress a
//! limb: when a step removed less than 3/4 of the error, it is tried once more
//! and kept if that helps ([`Solver::extrapolate`]).
//!
//! The solve stops when every goal is within `tolerance`; when an accepted step
//! moved no goal's residual by more than `tolerance`, or lowered `E` by less
//! than `Σ w·tolerance²` (what is left would not move a servo; the error is
//! then within about `Σ w·tolerance²` of the minimum the steps head for);
//! when the damping needed to lower `E` exceeds [`MAX_DAMPING`] (a minimum);
//! or at the iteration cap. A start that already meets every goal costs no
//! iteration.
//!
//! Per iteration: one forward kinematics of the segments the goals hang from,
//! the columns (a cross product per DOF and goal it moves), and one block
//! Cholesky factorisation of the goal rows per round of clamping.
//!
//! Goals already met hold still: each linearisation moves only the joints
//! that move a goal not yet within `tolerance`, and keeps the rows of every
//! goal those joints move, so that a shared joint does not pull a met goal
//! away. A met goal's own chain would gain at most `w·tolerance²`; on the
//! CMU skeleton reaching with hands and feet, the last iteration of a typical
//! solve moves only the arms and the spine. Forward kinematics then places
//! only the segments whose angles, or an ancestor's, changed.
//!
//! The problem is not convex: joint limits and folding limbs leave other
//! minima. With [`Solver::restarts`], when the goals are not all met, the
//! solve is repeated from the rest pose and from poses spread over the moving
//! joints' ranges, and the lowest error wins.

use super::joints::Joints;
use super::slots::{Rhs, Slots};
use super::system::System;
use super::{SolveError, Solver, Work};
use crate::math;

pub use super::slots::MAX_GOALS;

/// The smallest damping factor: keeps the matrix's condition within what
/// `f32` Cholesky resolves (about 1e4 against the identity).
const MIN_DAMPING: f32 = 1e-2;
/// Beyond this damping a step is pointless: the error is at a minimum.
const MAX_DAMPING: f32 = 100.0;
/// The largest turn (rad) or translation (m) of one step.
const MAX_STEP: f32 = 1.0;

/// The state of a whole-tree solve, built in place and kept between solves
/// (inside a [`super::SolverState`]).
pub(super) struct Lm<const N: usize> {
    joints: Joints<N>,
    slots: Slots,
    system: System,
    /// Scratch of [`System::step`]: the scaled residuals.
    rhs: Rhs,
}

impl<const N: usize> Lm<N> {
    /// Nothing built yet.
    pub const EMPTY: Self = Lm {
        joints: Joints::EMPTY,
        slots: Slots::EMPTY,
        system: System::EMPTY,
        rhs: [glam::Vec3::ZERO; MAX_GOALS],
    };

    /// The active goals as [`solve`] left them: at its final pose, if it
    /// returned with an active goal.
    pub fn slots(&self) -> &Slots {
        &self.slots
    }
}

/// Weighted DLS over the whole reach tree; returns (iterations, converged).
/// Leaves the full world pose of the result in `work`. With `laid_out`, the
/// joints in `lm` are already those of these goals (the same active goals on
/// the same segments, the same body and root mode) and are not built again.
pub(super) fn solve<const N: usize>(
    solver: &Solver,
    lm: &mut Lm<N>,
    laid_out: bool,
    work: &mut Work<'_, '_, N>,
) -> Result<(u32, bool), SolveError> {
    let wmax = work
        .goals
        .iter()
        .filter(|g| g.is_active())
        .fold(0.0f32, |m, g| math::max(g.weight, m));
    if wmax <= 0.0 {
        work.forward()?;
        return Ok((0, true));
    }
    lm.slots.init(work.goals, wmax)?;
    if !laid_out {
        lm.joints.init(solver, work, &lm.slots);
        lm.system.forget();
    }
    let (mut iterations, mut converged) = lm.run(solver, work)?;
    let tol2 = solver.tolerance * solver.tolerance;
    if solver.restarts > 0 && lm.slots.worst > tol2 {
        let (it, conv) = lm.restart(solver, work)?;
        iterations += it;
        converged &= conv;
    }
    lm.joints.forward_rest(work);
    Ok((iterations, converged))
}

impl<const N: usize> Lm<N> {
    /// Forward kinematics and the goals at the current angles.
    fn refresh(&mut self, work: &mut Work<'_, '_, N>) -> Result<(), SolveError> {
        self.joints.forward(work);
        self.slots.evaluate(work)
    }

    /// Levenberg–Marquardt from the current angles; returns (iterations,
    /// converged). Leaves the forward kinematics of the result in `work`.
    fn run(
        &mut self,
        solver: &Solver,
        work: &mut Work<'_, '_, N>,
    ) -> Result<(u32, bool), SolveError> {
        self.joints.unplaced();
        self.refresh(work)?;
        self.slots.keep();
        let tol2 = solver.tolerance * solver.tolerance;
        let mut lambda = math::max(MIN_DAMPING, solver.damping);
        let mut fresh = true;
        let mut iterations = 0u32;
        while iterations < u32::from(solver.max_iterations) {
            if self.slots.worst <= tol2 || self.joints.count == 0 {
                return Ok((iterations, true));
            }
            iterations += 1;
            if fresh {
                self.joints.settle(&self.slots, tol2);
                self.joints.linearise(work, &self.slots)?;
                fresh = false;
            }
            if !self.system.step(
                work,
                &mut self.joints,
                &self.slots,
                &mut self.rhs,
                lambda * lambda,
            ) {
                lambda *= 4.0;
                continue;
            }
            let error = self.slots.error;
            self.trial(solver, work)?;
            if self.slots.error < error {
                let moved = self.slots.accept();
                fresh = true;
                lambda = math::max(MIN_DAMPING, lambda / 3.0);
                let gained = error - self.slots.error;
                if moved <= tol2 || gained <= self.slots.weight * tol2 {
                    return Ok((iterations, true));
                }
            } else {
                self.joints.back(work);
                self.refresh(work)?;
                self.slots.keep();
                lambda *= 4.0;
                if lambda > MAX_DAMPING {
                    return Ok((iterations, true));
                }
            }
        }
        Ok((iterations, self.slots.worst <= tol2))
    }

    /// Applies the step (and, if it helped but little, once more) and
    /// evaluates the goals.
    fn trial(&mut self, solver: &Solver, work: &mut Work<'_, '_, N>) -> Result<(), SolveError> {
        let error = self.slots.error;
        self.joints.apply(work, MAX_STEP, true);
        self.refresh(work)?;
        if solver.extrapolate && self.slots.error < error && self.slots.error > 0.25 * error {
            let once = self.slots.error;
            self.joints.apply(work, MAX_STEP, false);
            self.refresh(work)?;
            if self.slots.error >= once {
                // Back to the single step (applied again: the same numbers).
                self.joints.back(work);
                self.joints.apply(work, MAX_STEP, false);
                self.refresh(work)?;
            }
        }
        Ok(())
    }

    /// Solves again from the rest pose and from spread poses of the moving
    /// joints; keeps the lowest error. Returns (iterations, converged).
    fn restart(
        &mut self,
        solver: &Solver,
        work: &mut Work<'_, '_, N>,
    ) -> Result<(u32, bool), SolveError> {
        let (mut best, mut best_error) = (self.joints.save(work), self.slots.error);
        let start = best;
        let (mut iterations, mut converged) = (0u32, true);
        for k in 0..solver.restarts {
            self.joints.restore(work, &start);
            spread(work, &self.joints, k);
            let (it, conv) = self.run(solver, work)?;
            iterations += it;
            if self.slots.error < best_error {
                (best, best_error, converged) = (self.joints.save(work), self.slots.error, conv);
            }
        }
        self.joints.restore(work, &best);
        self.refresh(work).map(|()| (iterations, converged))
    }
}

/// Start `k` of the restarts: the moving joints at rest (`k` = 0, zero
/// clamped into the limits) or spread over the middle half of their ranges
/// by a fixed sequence.
fn spread<const N: usize>(work: &mut Work<'_, '_, N>, joints: &Joints<N>, k: u8) {
    let mut h = 0x9E37_79B9u32.wrapping_mul(u32::from(k));
    for g in joints.groups().iter().filter(|g| !g.translation()) {
        let Some(values) = work.angles.get_mut(usize::from(g.seg)) else {
            continue;
        };
        let limits = g.min.to_array().into_iter().zip(g.max.to_array());
        for (v, (min, max)) in values.iter_mut().zip(limits).take(usize::from(g.count)) {
            h = h.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let u = (h >> 8) as f32 * (1.0 / 16_777_216.0);
            let x = if k == 0 {
                0.0
            } else {
                min + (max - min) * (0.25 + 0.5 * u)
            };
            *v = math::clamp(x, min, max);
        }
    }
}
