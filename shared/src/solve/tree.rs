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

use super::cost::{Meter, Tally, Term};
use super::joints::{Joints, ancestors};
use super::slots::{Kind, Rhs, Slots};
use super::system::System;
use super::{SolveError, Solver, Work};
use crate::body::Body;
use crate::goal::{Frame, Goal, Target};
use crate::math;

pub use super::slots::MAX_GOALS;

/// The smallest damping factor: keeps the matrix's condition within what
/// `f32` Cholesky resolves (about 1e4 against the identity).
const MIN_DAMPING: f32 = 1e-2;
/// Beyond this damping a step is pointless: the error is at a minimum.
const MAX_DAMPING: f32 = 100.0;
/// The largest turn (rad) or translation (m) of one step.
const MAX_STEP: f32 = 1.0;
/// Factorisation passes per round of a step (`system::CLAMP_PASSES`).
const CLAMP_PASSES: usize = super::system::CLAMP_PASSES;

/// The state of a whole-tree solve, built in place and kept between solves
/// (inside a [`super::SolverState`]).
pub(super) struct Lm<const N: usize> {
    joints: Joints<N>,
    slots: Slots,
    system: System,
    /// Scratch of [`System::step`]: the scaled residuals.
    rhs: Rhs,
    /// The prices of an iteration's parts for the live groups.
    prices: Prices,
}

/// The work of the parts of an iteration, by the cost model, for the live
/// groups of a linearisation.
#[derive(Clone, Copy, Debug)]
struct Prices {
    /// Every iteration.
    base: Tally,
    /// A new linearisation.
    linearise: Tally,
    /// A trial step: applying it, forward kinematics and the goals.
    trial: Tally,
    /// Going back from a rejected trial.
    reject: Tally,
    /// A round of a step (assembling the system).
    round: Tally,
    /// A factorisation pass (with the clamping at the limits).
    pass: Tally,
    /// Finding the goals' coupling again.
    couple: Tally,
    /// A one-sided plane may wake (a step may take two rounds).
    planes: bool,
}

impl Prices {
    /// Nothing priced yet.
    const NONE: Prices = Prices {
        base: Tally::NONE,
        linearise: Tally::NONE,
        trial: Tally::NONE,
        reject: Tally::NONE,
        round: Tally::NONE,
        pass: Tally::NONE,
        couple: Tally::NONE,
        planes: false,
    };
}

impl<const N: usize> Lm<N> {
    /// Nothing built yet.
    pub const EMPTY: Self = Lm {
        joints: Joints::EMPTY,
        slots: Slots::EMPTY,
        system: System::EMPTY,
        rhs: [glam::Vec3::ZERO; MAX_GOALS],
        prices: Prices::NONE,
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
/// Counts its work in `meter` and starts no iteration that might take it
/// past its limit.
pub(super) fn solve<const N: usize>(
    solver: &Solver,
    lm: &mut Lm<N>,
    laid_out: bool,
    work: &mut Work<'_, '_, N>,
    meter: &mut Meter,
) -> Result<(u32, bool), SolveError> {
    let wmax = work
        .goals
        .iter()
        .filter(|g| g.is_active())
        .fold(0.0f32, |m, g| math::max(g.weight, m));
    let segments = work.body.len();
    if wmax <= 0.0 {
        meter.add_tally(&still_work(segments));
        work.forward()?;
        return Ok((0, true));
    }
    lm.slots.init(work.goals, wmax)?;
    meter.add(Term::Slot, lm.slots.count);
    if !laid_out {
        lm.joints.init(solver, work, &lm.slots);
        lm.system.forget(&lm.joints, lm.slots.count);
        meter.add_tally(&layout_work(segments, lm.joints.sizes.climbs));
    }
    // The final pose of the segments off the path, counted first: it is
    // always made.
    meter.add_tally(&lm.rest_work(segments));
    let (mut iterations, mut converged) = lm.run(solver, work, meter)?;
    let tol2 = solver.tolerance * solver.tolerance;
    if solver.restarts > 0 && lm.slots.worst > tol2 {
        let (it, conv) = lm.restart(solver, work, meter)?;
        iterations += it;
        converged &= conv;
    }
    lm.joints.forward_rest(work);
    Ok((iterations, converged))
}

/// The work of placing every segment when no goal is active.
fn still_work(segments: usize) -> Tally {
    Tally::NONE
        .with(Term::Place, segments)
        .with(Term::Turn, 3 * segments)
}

/// The work of building the joint layout: `climbs` steps of the goals'
/// climbs to the root.
fn layout_work(segments: usize, climbs: usize) -> Tally {
    Tally::NONE
        .with(Term::Layout, 1)
        .with(Term::LayoutSegment, segments)
        .with(Term::Climb, climbs)
}

/// The work of evaluating the goals: `simple` point goals in the world
/// frame of `active` ones.
fn eval_work(active: usize, simple: usize) -> Tally {
    Tally::NONE
        .with(Term::EvalPoint, simple)
        .with(Term::EvalOther, active.saturating_sub(simple))
}

impl<const N: usize> Lm<N> {
    /// The most work of a solve's fixed part besides [`Term::Solve`], the
    /// segments and the goals (which the caller counts): the goals' slots,
    /// the joint layout unless `laid_out` (the same goals on the same
    /// segments as the kept joints), the final pose of the segments off
    /// the path and the first forward kinematics. Exact for a kept layout;
    /// for a new one a bound (the goals' climbs counted, every segment
    /// both on the path and off it, with three DOFs).
    pub(super) fn fixed_work(&self, laid_out: bool, body: &Body<'_>, goals: &[Goal]) -> u32 {
        let segments = body.len();
        let (mut active, mut simple, mut climbs) = (0usize, 0usize, 0usize);
        for g in goals.iter().filter(|g| g.is_active()) {
            active += 1;
            if !laid_out {
                climbs += ancestors(body, usize::from(g.segment)).count();
            }
            match (g.target, g.frame) {
                (Target::Position(_), Frame::World) => simple += 1,
                (_, Frame::Segment(f)) if !laid_out => {
                    climbs += ancestors(body, usize::from(f)).count();
                }
                _ => {}
            }
        }
        let goals = Tally::NONE
            .with(Term::Slot, active)
            .plus(&eval_work(active, simple));
        let kept = if laid_out {
            self.rest_work(segments)
                .with(Term::Place, self.joints.path_len())
                .with(Term::Turn, self.joints.sizes.dofs)
        } else {
            layout_work(segments, climbs)
                .plus(&still_work(segments))
                .with(Term::Rest, segments)
                .with(Term::RestDof, 3 * segments)
        };
        still_work(segments).cost().max(kept.plus(&goals).cost())
    }

    /// The work of the final pose of the segments off the path.
    fn rest_work(&self, segments: usize) -> Tally {
        Tally::NONE
            .with(Term::Rest, segments.saturating_sub(self.joints.path_len()))
            .with(Term::RestDof, self.joints.sizes.rest_dofs)
    }

    /// Forward kinematics and the goals at the current angles.
    fn refresh(&mut self, work: &mut Work<'_, '_, N>) -> Result<(), SolveError> {
        self.joints.forward(work);
        self.slots.evaluate(work)
    }

    /// The work of a forward kinematics that may turn joints of `dofs`
    /// DOFs, and of evaluating the goals.
    fn refresh_work(&self, dofs: usize) -> Tally {
        Tally::NONE
            .with(Term::Place, self.joints.path_len())
            .with(Term::Turn, dofs)
            .plus(&eval_work(self.slots.count, self.slots.simple))
    }

    /// Prices the parts of an iteration with the live groups of the last
    /// [`Joints::settle`].
    fn price(&mut self) {
        let live = self.joints.live;
        let (groups, g) = (self.joints.count, self.slots.count);
        let refresh = self.refresh_work(live.dofs);
        let (blocks, products) = self.system.most;
        self.prices = Prices {
            base: Tally::NONE
                .with(Term::Iteration, 1)
                .with(Term::IterationSlot, g)
                .with(Term::Group, groups),
            linearise: Tally::NONE
                .with(Term::LiveDof, live.dofs)
                .with(Term::LinkDof, live.link_dofs),
            trial: refresh.with(Term::Apply, groups),
            reject: refresh.with(Term::Reject, groups),
            round: Tally::NONE
                .with(Term::Pair, live.pairs)
                .with(Term::Block, g * g),
            pass: Tally::NONE
                .with(Term::Pass, 1)
                .with(Term::PassSlot, g)
                .with(Term::PassBlock, blocks)
                .with(Term::PassProduct, products)
                .with(Term::PassLink, live.dofs + live.link_dofs),
            couple: Tally::NONE.with(Term::Couple, live.link_dofs + g * g),
            planes: self
                .slots
                .iter()
                .any(|s| s.kind == Kind::Plane && s.one_sided),
        };
    }

    /// The most a next iteration can do within `left`: its rounds (2 when a
    /// one-sided plane may wake) and its factorisation passes per round (up
    /// to [`CLAMP_PASSES`]), with its trials, finding the coupling and a
    /// rejection reserved; `None` if not even one pass fits.
    fn plan(&self, solver: &Solver, fresh: bool, left: u32) -> Option<(usize, usize)> {
        let p = &self.prices;
        let trials = if solver.extrapolate { 3 } else { 1 };
        let mut fixed = p.base.plus(&p.couple).plus(&p.reject);
        fixed = fixed.plus(&p.trial.times(trials));
        if fresh {
            fixed = fixed.plus(&p.linearise);
        }
        let pass = p.pass.cost().max(1);
        let most = if p.planes { 2 } else { 1 };
        (1..=most).rev().find_map(|rounds| {
            let before = fixed.plus(&p.round.times(rounds)).cost();
            let avail = left.checked_sub(before)?;
            let per = pass.saturating_mul(rounds as u32);
            let passes = (avail / per).min(CLAMP_PASSES as u32);
            (passes > 0).then_some((rounds, passes as usize))
        })
    }

    /// The work of an iteration: a linearisation if `fresh`, a step of
    /// `(rounds, passes, coupling found again)`, `trials` forward
    /// kinematics, and going back if `rejected`.
    fn iteration_work(
        &self,
        fresh: bool,
        (rounds, passes, couple): (usize, usize, bool),
        trials: usize,
        rejected: bool,
    ) -> Tally {
        let p = &self.prices;
        let mut t = p
            .base
            .plus(&p.round.times(rounds))
            .plus(&p.pass.times(passes))
            .plus(&p.trial.times(trials));
        if fresh {
            t = t.plus(&p.linearise);
        }
        if couple {
            t = t.plus(&p.couple);
        }
        if rejected {
            t = t.plus(&p.reject);
        }
        t
    }

    /// Levenberg–Marquardt from the current angles; returns (iterations,
    /// converged). Leaves the forward kinematics of the result in `work`.
    fn run(
        &mut self,
        solver: &Solver,
        work: &mut Work<'_, '_, N>,
        meter: &mut Meter,
    ) -> Result<(u32, bool), SolveError> {
        self.joints.unplaced();
        meter.add_tally(&self.refresh_work(self.joints.sizes.dofs));
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
            if fresh {
                self.joints.settle(&self.slots, tol2);
                self.price();
            }
            let Some(plan) = self.plan(solver, fresh, meter.left()) else {
                // Out of work: what is left is for the next solve.
                return Ok((iterations, false));
            };
            iterations += 1;
            let linearised = fresh;
            if fresh {
                self.joints.linearise(work, &self.slots)?;
                fresh = false;
            }
            let stepped = self.system.step(
                work,
                &mut self.joints,
                &self.slots,
                &mut self.rhs,
                lambda * lambda,
                plan,
            );
            if !stepped {
                meter.add_tally(&self.iteration_work(linearised, self.system.work, 0, false));
                lambda *= 4.0;
                continue;
            }
            let error = self.slots.error;
            let trials = self.trial(solver, work)?;
            let accepted = self.slots.error < error;
            meter.add_tally(&self.iteration_work(linearised, self.system.work, trials, !accepted));
            if accepted {
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
    /// evaluates the goals; returns the forward kinematics made.
    fn trial(&mut self, solver: &Solver, work: &mut Work<'_, '_, N>) -> Result<usize, SolveError> {
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
                return Ok(3);
            }
            return Ok(2);
        }
        Ok(1)
    }

    /// Solves again from the rest pose and from spread poses of the moving
    /// joints, while the work allows; keeps the lowest error. Returns
    /// (iterations, converged).
    fn restart(
        &mut self,
        solver: &Solver,
        work: &mut Work<'_, '_, N>,
        meter: &mut Meter,
    ) -> Result<(u32, bool), SolveError> {
        let (mut best, mut best_error) = (self.joints.save(work), self.slots.error);
        let start = best;
        let (mut iterations, mut converged) = (0u32, true);
        // Each start and the return to the best: a forward kinematics of
        // every moving joint.
        let again = self
            .refresh_work(self.joints.sizes.dofs)
            .with(Term::Apply, self.joints.count);
        for k in 0..solver.restarts {
            // This start's first forward kinematics and the way back.
            if meter.left() < again.cost().saturating_mul(2) {
                break;
            }
            meter.add_tally(&again);
            self.joints.restore(work, &start);
            spread(work, &self.joints, k);
            let (it, conv) = self.run(solver, work, meter)?;
            iterations += it;
            if self.slots.error < best_error {
                (best, best_error, converged) = (self.joints.save(work), self.slots.error, conv);
            }
        }
        meter.add_tally(&again);
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
