//! The work of a whole-tree solve, counted, so that a live loop can give
//! the solver a deadline that host and firmware keep alike.
//!
//! A live loop must finish every frame within its period. Wall time would
//! make the firmware's result depend on the board's speed, and the host's
//! `sim` could no longer reproduce it bit for bit. So the solver counts its
//! own work instead: every step of [`Method::TreeDls`](super::Method::TreeDls)
//! adds what it costs by this model, and [`Solver::budget`](super::Solver)
//! caps the total. The same counts give the same decisions everywhere.
//!
//! ## The model
//!
//! The unit is one instruction of the firmware's Cortex-M4F build (release
//! profile, `opt-level = "s"`). A step costs a sum of [`Term`]s, each a
//! fixed number of instructions ([`COST`]) times a size the solver knows
//! before it takes the step: the segments, goals and path segments, the
//! moving DOFs, the goal rows each joint moves (links), and per step its
//! rounds and factorisation passes. Where the size depends on what the step
//! will find (a joint limit that clamps, a rejected trial, which rotations
//! the forward kinematics must compute again), the model counts the most the
//! step can do. So a solve's count bounds its instructions (by how much is
//! measured in README's "Real time").
//!
//! Before each iteration the solver plans the most it can afford: a step
//! with every round and clamping pass, or fewer passes (the step is then
//! taken with the limits clamped so far, and `apply` keeps every angle
//! inside its limits), or none, which ends the solve. The trial's forward
//! kinematics, and going back if the trial is rejected, are always
//! reserved. The fixed part of a solve (the checks, the joint layout if it
//! is new, the first forward kinematics, the final pose and the report) is
//! counted first: a budget below it (by the model, a bound when the layout
//! is new) is refused before any work
//! ([`SolveError::Budget`](super::SolveError::Budget)), so the count never
//! exceeds the budget.
//!
//! The coefficients were fitted (a linear program: the smallest total
//! relative excess with every solve bounded) to the instruction counts of
//! the `cost` firmware binary's solves on the emulated Cortex-M4F, with the
//! units counted by the same binary built with the `cost-terms` feature of
//! this crate. `tests/realtime.rs` runs that binary and checks that the
//! count bounds every solve; a change of the solver's code that breaks it
//! needs a new fit: `cargo run --release -p marionette-tests --example
//! fit_cost` measures, fits and prints the new [`COST`]
//! (`tests/examples/fit_cost.rs`); with `-- --write` it writes it here and
//! refits until it bounds the solves it leads to, and `-- --margin P` fits
//! every solve with `P` % to spare (default 5: the live loop's problems are
//! not the binary's).

/// The terms of the model: what each coefficient of [`COST`] is paid per.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Term {
    /// One per solve.
    Solve,
    /// Per segment of the body, per solve.
    Segment,
    /// Per goal of the set (active or not), per solve.
    Goal,
    /// Per active goal, per solve.
    Slot,
    /// Per layout build.
    Layout,
    /// Per segment, per layout build.
    LayoutSegment,
    /// Per step of the goals' climbs to the root, per layout build.
    Climb,
    /// Per path segment, per forward kinematics.
    Place,
    /// Per DOF whose rotation a forward kinematics may compute again.
    Turn,
    /// Per evaluation of a point goal in the world frame.
    EvalPoint,
    /// Per evaluation of any other goal.
    EvalOther,
    /// Per segment off the path (the final pose), per solve.
    Rest,
    /// Per DOF off the path, per solve.
    RestDof,
    /// One per iteration.
    Iteration,
    /// Per active goal, per iteration.
    IterationSlot,
    /// Per moving joint group, per iteration.
    Group,
    /// Per live DOF, per linearisation.
    LiveDof,
    /// Per DOF of a live group's goal row (link), per linearisation.
    LinkDof,
    /// Per pair of links of a live group, per round of a step.
    Pair,
    /// Per block of the goal-space system, per round of a step.
    Block,
    /// Per factorisation pass.
    Pass,
    /// Per active goal, per pass.
    PassSlot,
    /// Per off-diagonal block of the factor (the most for the layout), per
    /// pass.
    PassBlock,
    /// Per block product of the factorisation (the most for the layout),
    /// per pass.
    PassProduct,
    /// Per live DOF and link DOF, per pass.
    PassLink,
    /// Per link DOF and block, when the coupling of the goals is found
    /// again.
    Couple,
    /// Per moving group, per rejected step.
    Reject,
    /// Per moving group, per step applied.
    Apply,
}

/// Number of terms.
pub const TERMS: usize = 28;

/// Instructions per unit of each term, in [`Term`] order.
pub const COST: [u32; TERMS] = [
    3945, 10, 360, 0, 0, 175, 112, 184, 30, 60, 203, 60, 11, 802, 71, 205, 54, 40, 93, 24, 100,
    483, 183, 59, 33, 0, 0, 187,
];

/// The cost of `count` units of `term`. The sizes the solver counts are
/// small (at most [`MAX_SEGMENTS`](crate::pose::MAX_SEGMENTS) segments of
/// three DOFs and [`MAX_GOALS`](super::MAX_GOALS) goals), so no product
/// comes near `u32::MAX`; the sums saturate.
#[inline(always)]
fn of(term: Term, count: usize) -> u32 {
    match COST.get(term as usize) {
        Some(&c) => c.wrapping_mul(count as u32),
        None => 0,
    }
}

/// A sum of terms: their cost, and with the `cost-terms` feature their
/// units (to fit [`COST`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Tally {
    cost: u32,
    /// Units per term, in [`Term`] order.
    #[cfg(feature = "cost-terms")]
    pub units: [u32; TERMS],
}

impl Tally {
    /// Nothing.
    pub const NONE: Tally = Tally {
        cost: 0,
        #[cfg(feature = "cost-terms")]
        units: [0; TERMS],
    };

    /// `count` units of `term` more.
    #[inline(always)]
    #[must_use]
    pub(super) fn with(mut self, term: Term, count: usize) -> Self {
        self.cost = self.cost.saturating_add(of(term, count));
        #[cfg(feature = "cost-terms")]
        if let Some(u) = self.units.get_mut(term as usize) {
            *u = u.saturating_add(count as u32);
        }
        self
    }

    /// This and `other`.
    #[inline(always)]
    #[must_use]
    pub(super) fn plus(mut self, other: &Tally) -> Self {
        self.cost = self.cost.saturating_add(other.cost);
        #[cfg(feature = "cost-terms")]
        for (a, b) in self.units.iter_mut().zip(other.units) {
            *a = a.saturating_add(b);
        }
        self
    }

    /// This `n` times.
    #[inline(always)]
    #[must_use]
    pub(super) fn times(mut self, n: usize) -> Self {
        let n32 = n as u32;
        self.cost = self.cost.saturating_mul(n32);
        #[cfg(feature = "cost-terms")]
        for u in &mut self.units {
            *u = u.saturating_mul(n32);
        }
        self
    }

    /// The instructions.
    #[inline(always)]
    #[must_use]
    pub fn cost(&self) -> u32 {
        self.cost
    }
}

/// Counts the work of one solve against a limit.
#[derive(Clone, Copy, Debug)]
pub(super) struct Meter {
    spent: Tally,
    limit: u32,
}

impl Meter {
    /// Nothing spent yet; at most `limit`.
    pub const fn new(limit: u32) -> Self {
        Meter {
            spent: Tally::NONE,
            limit,
        }
    }

    /// Adds `count` units of `term`.
    #[inline(always)]
    pub fn add(&mut self, term: Term, count: usize) {
        self.spent = self.spent.with(term, count);
    }

    /// Adds a tally.
    #[inline(always)]
    pub fn add_tally(&mut self, t: &Tally) {
        self.spent = self.spent.plus(t);
    }

    /// What is left of the limit.
    #[inline(always)]
    pub fn left(&self) -> u32 {
        self.limit.saturating_sub(self.spent.cost)
    }

    /// The work counted so far.
    pub fn spent(&self) -> &Tally {
        &self.spent
    }
}
