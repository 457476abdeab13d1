//! Multi-goal weighted positioning of an articulated body (POSIT, and beyond).
//!
//! Badler, Manoochehri & Walters (1987) position a body so that weighted goals
//! are met as well as possible, like springs of stiffness `weight` pulling touch
//! points towards goals. This module implements their method and better ones on
//! the same problem, selected by [`Solver::method`]:
//!
//! - [`Method::Greedy`]: the paper, kept faithful. The [`ReachTree`] (Fig. 15)
//!   is balanced recursively (Fig. 17): after balancing its children, a node's
//!   subtree-weighted displacement `stwd = Σ w·(goal − touch point)` gives a
//!   temporary goal `touch + stwd / Σw` for the node, which `solve_simple_chain`
//!   reaches by moving the simple chain from the node's reach parent; the root
//!   node is simply translated. A node stops on zero displacement, when the
//!   displacement no longer shrinks, or at the iteration cap. The chain solver is
//!   the paper's greedy triangle-inequality one, with joint limits added.
//! - [`Method::Ccd`], [`Method::Dls`]: the same balancing with a better chain
//!   solver (cyclic coordinate descent per DOF, or damped least squares).
//! - [`Method::TreeDls`]: damped least squares (Levenberg–Marquardt) on all the
//!   reach tree's joints at once, minimising `Σ w·residual²` directly, with an
//!   active set for the joint limits. This is the default: it reaches the
//!   weighted optimum that the spring model describes, handles orientation,
//!   plane and relative goals exactly, and is the cheapest per frame.
//!
//! Every method starts from the given [`Angles`] (warm start: the synthesized
//! pose projected with [`Angles::from_local`], or the previous frame), keeps
//! every angle within its limits, never changes the root's orientation, and is
//! deterministic (only [`crate::math`] transcendentals, fixed iteration order).
//!
//! ## What moves
//!
//! Only the joints of the reach tree's simple chains (goal-less side branches
//! ride along rigidly). The root of the reach tree is handled by
//! [`Solver::root`]:
//! - [`RootMode::Float`] (the paper): the reach-tree root is placed by
//!   translating the whole body, and the linkage from the body root to it is
//!   not changed. Put a goal on the body root to make it part of the solution.
//! - [`RootMode::Fixed`] (a puppet on a stand): the body root never moves; the
//!   chain from the body root to the reach-tree root is solved instead.
//!
//! ## Cost and quality
//!
//! One whole-tree iteration computes a forward kinematics of the segments
//! the goals hang from, a Jacobian column per moving DOF and goal, the 3×3
//! blocks of the goal-space system and their factorisation, and the step
//! with its joint limits; its work grows with the moving DOFs, the goals
//! and the goal rows each joint moves. A kept [`SolverState`] skips
//! clearing the working state and laying out the joints while the goals
//! stay on the same segments, and a start at the last solution skips the
//! sines and cosines of the first forward kinematics. What the methods
//! cost and reach on the CMU skeleton (host time, Cortex-M4F instruction
//! counts, goals met) is measured in README's "Measured" section, with the
//! commands (`tests/benches/solve.rs`, `marionette icount`).
//!
//! Tree DLS is a local method: on 100 random CMU goal sets (`tests/solve.rs`)
//! it ends at a local optimum every time, and with [`Solver::restarts`] = 3
//! within 2% of the best of many reference runs every time; without restarts,
//! one set settles in a worse basin held by joint limits.
//!
//! ## Use from the firmware
//!
//! ```text
//! let mut state = SolverState::<24>::new();               // once, kept with the figure
//! // every frame:
//! let mut angles = Angles::<24>::from_local(&body, &synthesized_local)?; // or last frame's
//! let report = solve_with(&Solver::DEFAULT, &body, &goals, &mut angles, &mut pose, &mut state)?;
//! // angles: joint angles within limits for the servo map; pose: world pose.
//! ```
//!
//! The live loop ([`crate::frame::Performer`]) does this with the state its
//! caller lends it. [`solve`] is the same with a fresh state, only the part
//! its method keeps (tree DLS: for `N` = 64, about 22.7 kB built on the stack
//! per call).

mod balance;
mod ccd;
pub mod cost;
mod dls;
mod greedy;
mod joints;
mod reach;
mod slots;
mod system;
mod tree;

pub use reach::ReachTree;
pub use tree::MAX_GOALS;

use crate::body::{Angles, Body, BodyError};
use crate::goal::{Attach, Frame, Goal, GoalSet, Residual, Target};
use crate::math;
use crate::pose::{LocalPose, MAX_SEGMENTS, Pose};
use glam::Vec3;

/// Which algorithm positions the body.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// Reach-tree balancing (Fig. 17) with the paper's greedy triangle chain solver.
    Greedy,
    /// Reach-tree balancing with cyclic coordinate descent per DOF as chain solver.
    Ccd,
    /// Reach-tree balancing with damped least squares as chain solver.
    Dls,
    /// Weighted damped least squares over the whole reach tree.
    TreeDls,
}

/// What may move the reach tree's root.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RootMode {
    /// The paper: translate the whole body to place the reach-tree root.
    Float,
    /// The body root stays put; its chain to the reach-tree root is solved.
    Fixed,
}

/// Solver configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Solver {
    /// The algorithm.
    pub method: Method,
    /// What moves the reach-tree root.
    pub root: RootMode,
    /// Iteration cap: per reach-tree node for the balancing methods, in total
    /// for [`Method::TreeDls`].
    pub max_iterations: u16,
    /// Passes (greedy, CCD) or iterations (DLS) per simple-chain solve.
    pub chain_iterations: u16,
    /// A goal within this distance (m; rad for orientations) counts as met, and
    /// a weighted displacement below it counts as zero. [`Method::TreeDls`]
    /// also stops when a step moves no goal by more than this, or lowers
    /// `Σ w·r²` by less than `Σ w · tolerance²`.
    pub tolerance: f32,
    /// Initial Levenberg–Marquardt damping: a factor of each variable's
    /// curvature (for the chain DLS, a fixed factor).
    pub damping: f32,
    /// [`Method::TreeDls`]: after a step that removed less than 3/4 of the
    /// error, try the same step again (one or two more forward kinematics;
    /// sometimes fewer iterations when goals compress a limb).
    pub extrapolate: bool,
    /// [`Method::TreeDls`]: when the goals are not all met, solve again from
    /// this many other starts (the rest pose, then poses spread over the
    /// joints' ranges) and keep the lowest error. The problem is not convex,
    /// so this finds better minima far from the start; a live loop wants the
    /// minimum near its synthesized start instead, and 0.
    pub restarts: u8,
    /// [`Method::TreeDls`]: the most work a solve may do, in the units of
    /// [`Report::work`]; it starts no iteration (or restart) that might take
    /// it past this, and what is left is for the next solve. A budget below
    /// the solve's fixed part is refused ([`SolveError::Budget`]), so a
    /// solve's work never exceeds it. `u32::MAX`: no limit.
    pub budget: u32,
}

impl Solver {
    /// The paper's algorithm, for comparisons.
    pub const PAPER: Solver = Solver {
        method: Method::Greedy,
        root: RootMode::Float,
        max_iterations: 20,
        chain_iterations: 1,
        tolerance: 1e-5,
        damping: 0.1,
        extrapolate: true,
        restarts: 0,
        budget: u32::MAX,
    };

    /// The default: whole-tree damped least squares, root fixed, goals met to
    /// 0.1 mm (a hobby servo's resolution is about 0.1°, half a millimetre at
    /// the end of a 30 cm limb).
    pub const DEFAULT: Solver = Solver {
        method: Method::TreeDls,
        root: RootMode::Fixed,
        max_iterations: 20,
        chain_iterations: 6,
        tolerance: 1e-4,
        damping: 0.1,
        extrapolate: false,
        restarts: 0,
        budget: u32::MAX,
    };

    /// The same configuration with another method.
    #[must_use]
    pub const fn with_method(mut self, method: Method) -> Self {
        self.method = method;
        self
    }

    /// The same configuration with another root mode.
    #[must_use]
    pub const fn with_root(mut self, root: RootMode) -> Self {
        self.root = root;
        self
    }

    /// The same configuration with another iteration cap.
    #[must_use]
    pub const fn with_iterations(mut self, max_iterations: u16) -> Self {
        self.max_iterations = max_iterations;
        self
    }

    /// The same configuration with another number of restarts.
    #[must_use]
    pub const fn with_restarts(mut self, restarts: u8) -> Self {
        self.restarts = restarts;
        self
    }

    /// The same configuration with another work budget.
    #[must_use]
    pub const fn with_budget(mut self, budget: u32) -> Self {
        self.budget = budget;
        self
    }
}

impl Default for Solver {
    fn default() -> Self {
        Solver::DEFAULT
    }
}

/// Why a solve was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SolveError {
    /// The body is malformed or does not match the joint state.
    Body(BodyError),
    /// The body has more segments than the state's capacity.
    Capacity,
    /// Goal `i` names a segment that does not exist, has a NaN weight, or is
    /// active with a weight above [`WEIGHT_LIMIT`] or a target or attached
    /// point beyond [`GOAL_LIMIT`] (NaN and infinities included).
    BadGoal(u8),
    /// [`Method::TreeDls`]: more active goals than [`MAX_GOALS`].
    TooManyGoals,
    /// [`Method::TreeDls`]: the [`Solver::budget`] does not cover the
    /// solve's fixed part (the checks, the joint layout if it is new, the
    /// first forward kinematics and the final pose, by the cost model):
    /// nothing was done, the angles and the pose are as given.
    Budget,
}

impl From<BodyError> for SolveError {
    fn from(e: BodyError) -> Self {
        SolveError::Body(e)
    }
}

/// The outcome of a solve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Report<const G: usize> {
    /// Balancing iterations (chain solves or root moves) or DLS iterations.
    pub iterations: u32,
    /// Stopped on zero displacement or no further improvement, not on a cap.
    pub converged: bool,
    /// Each goal's residual in goal-set order: metres for point and plane
    /// goals, radians for orientation goals (inactive goals too).
    pub residuals: [f32; G],
    /// The weighted error `Σ weight · residual²` over the active goals.
    pub error: f32,
    /// [`Method::TreeDls`]: the work the solve did, by the solver's cost
    /// model ([`cost`]: a bound on its instructions on the firmware's
    /// Cortex-M4F); 0 for the other methods.
    pub work: u32,
    /// The units of [`Report::work`] per [`cost::Term`] (to fit the model).
    #[cfg(feature = "cost-terms")]
    pub terms: [u32; cost::TERMS],
}

impl<const G: usize> Report<G> {
    /// No solve yet: no iteration, nothing left (every residual 0).
    pub const EMPTY: Self = Report {
        iterations: 0,
        converged: true,
        residuals: [0.0; G],
        error: 0.0,
        work: 0,
        #[cfg(feature = "cost-terms")]
        terms: [0; cost::TERMS],
    };
}

/// Largest accepted magnitude of any coordinate of an active goal's target
/// (position, plane normal and offset, orientation quaternion) and attached
/// point, metres: far beyond any rig, and small enough that no squared
/// distance overflows `f32`. A goal outside it (NaN and infinities included)
/// is refused with [`SolveError::BadGoal`].
pub const GOAL_LIMIT: f32 = 1.0e6;

/// Largest accepted weight of an active goal (as on the wire); a heavier
/// one is refused with [`SolveError::BadGoal`].
pub const WEIGHT_LIMIT: f32 = 1.0e6;

/// Whether every coordinate of `v` is within ±[`GOAL_LIMIT`] (false for NaN).
fn bounded(v: &[f32]) -> bool {
    v.iter().all(|x| math::abs(*x) <= GOAL_LIMIT)
}

/// Whether a goal's weight is within [`WEIGHT_LIMIT`] and its target and
/// attached point within [`GOAL_LIMIT`].
fn bounded_goal(g: &Goal) -> bool {
    let target = match g.target {
        Target::Position(p) => bounded(&p.to_array()),
        Target::Plane { normal, offset, .. } => bounded(&normal.to_array()) && bounded(&[offset]),
        Target::Orientation(q) => bounded(&q.to_array()),
    };
    let point = match g.attach {
        Attach::Point(p) => bounded(&p.to_array()),
        Attach::Touch => true,
    };
    target && point && g.weight <= WEIGHT_LIMIT
}

/// Positions the body: moves `angles` (the warm start) to meet `goals` as well as
/// possible by their weights, and leaves the world pose of the result in `pose`.
///
/// Builds afresh the part of a working state that its method keeps (tree DLS:
/// for `N` = 64, about 22.7 kB cleared); a loop that solves every frame keeps
/// a [`SolverState`] and calls [`solve_with`] instead, with the same result.
///
/// # Example
///
/// Pull the left palm of the built-in Tempus body 5 cm up and 5 cm forward
/// of where it hangs at rest, and check the solved pose puts it there.
///
/// ```
/// use glam::Vec3;
/// use marionette_core::body::{Angles, tempus::{self, index}};
/// use marionette_core::goal::{Goal, GoalSet};
/// use marionette_core::pose::{LocalPose, Pose};
/// use marionette_core::solve::{Solver, solve};
///
/// let body = tempus::BODY;
/// let mut angles = Angles::<24>::rest(&body).unwrap();
/// let (mut local, mut pose) = (LocalPose::<24>::default(), Pose::<24>::default());
/// angles.forward(&body, &mut local, &mut pose).unwrap();
///
/// let hand = index::LEFT_HAND;
/// let at_rest = Goal::reach(hand, Vec3::ZERO, 1.0).world_point(&body, &pose).unwrap();
/// let target = at_rest + Vec3::new(0.0, 0.05, 0.05);
/// let mut goals = GoalSet::<4>::new();
/// goals.push(Goal::reach(hand, target, 1.0)).unwrap();
///
/// let root = pose.positions[0];
/// let report = solve(&Solver::DEFAULT, &body, &goals, &mut angles, &mut pose).unwrap();
/// assert!(report.residuals[0] <= Solver::DEFAULT.tolerance);
/// let palm = goals.as_slice()[0].world_point(&body, &pose).unwrap();
/// assert!(palm.distance(target) <= Solver::DEFAULT.tolerance);
/// // The root stays where it was (`RootMode::Fixed`).
/// assert_eq!(pose.positions[0], root);
/// ```
pub fn solve<const N: usize, const G: usize>(
    solver: &Solver,
    body: &Body<'_>,
    goals: &GoalSet<G>,
    angles: &mut Angles<N>,
    pose: &mut Pose<N>,
) -> Result<Report<G>, SolveError> {
    // Only the part of a state that the method keeps, cleared.
    let (mut lm, mut tree);
    let kept = if solver.method == Method::TreeDls {
        lm = tree::Lm::EMPTY;
        Kept::Lm(&mut lm)
    } else {
        tree = ReachTree::EMPTY;
        Kept::Tree(&mut tree)
    };
    let mut report = Report::EMPTY;
    solve_in(
        solver,
        body,
        goals,
        angles,
        pose,
        (kept, &mut None),
        &mut report,
    )?;
    Ok(report)
}

/// [`solve`] with a working state that the caller keeps between solves.
///
/// The state is built in place on the first call and kept: the layout of the
/// moving joints (tree DLS) or the reach tree (the balancing methods) is
/// reused as long as the same body (by address), method, root mode and
/// active goals on the same segments and frames come back; goal targets,
/// weights and kinds may change freely. The result is bit-identical to
/// [`solve`]'s. After changing a body's contents in place (same address),
/// call [`SolverState::reset`].
pub fn solve_with<const N: usize, const G: usize>(
    solver: &Solver,
    body: &Body<'_>,
    goals: &GoalSet<G>,
    angles: &mut Angles<N>,
    pose: &mut Pose<N>,
    state: &mut SolverState<N>,
) -> Result<Report<G>, SolveError> {
    let mut report = Report::EMPTY;
    solve_into(solver, body, goals, angles, pose, state, &mut report)?;
    Ok(report)
}

/// [`solve_with`] with the report written in place: a live loop keeps one
/// (a report is returned by copy otherwise, every frame). After an error,
/// `report` is unspecified.
pub fn solve_into<const N: usize, const G: usize>(
    solver: &Solver,
    body: &Body<'_>,
    goals: &GoalSet<G>,
    angles: &mut Angles<N>,
    pose: &mut Pose<N>,
    state: &mut SolverState<N>,
    report: &mut Report<G>,
) -> Result<(), SolveError> {
    let kept = if solver.method == Method::TreeDls {
        Kept::Lm(&mut state.lm)
    } else {
        Kept::Tree(&mut state.tree)
    };
    let state = (kept, &mut state.layout);
    solve_in(solver, body, goals, angles, pose, state, report)
}

/// The part of a [`SolverState`] that the solver's method keeps.
enum Kept<'s, const N: usize> {
    /// The balancing methods' reach tree.
    Tree(&'s mut ReachTree<N>),
    /// Tree DLS's moving joints, goal rows and system.
    Lm(&'s mut tree::Lm<N>),
}

/// [`solve_into`] on the part of the state the method keeps (`kept`, built
/// for `state_layout`).
fn solve_in<const N: usize, const G: usize>(
    solver: &Solver,
    body: &Body<'_>,
    goals: &GoalSet<G>,
    angles: &mut Angles<N>,
    pose: &mut Pose<N>,
    (kept, state_layout): (Kept<'_, N>, &mut Option<Layout>),
    report: &mut Report<G>,
) -> Result<(), SolveError> {
    let mut work = Work::new(body, goals.as_slice(), angles, pose);
    let mut meter = cost::Meter::new(solver.budget);
    meter.add(cost::Term::Solve, 1);
    meter.add(cost::Term::Segment, body.len());
    meter.add(cost::Term::Goal, goals.as_slice().len());
    let layout = Layout::of(solver, body, goals.as_slice());
    let laid_out = layout.is_some() && *state_layout == layout;
    if let Kept::Lm(lm) = &kept
        && solver.budget != u32::MAX
        && lm.fixed_work(laid_out, body, goals.as_slice()) > meter.left()
    {
        // Not even the fixed part fits: nothing done, nothing kept
        // changed.
        return Err(SolveError::Budget);
    }
    work.check()?;
    // Valid again only once this solve has built what it needs.
    *state_layout = None;
    let (iterations, converged, lm) = match kept {
        // Finds the reach tree's joints from the goals, without the tree.
        Kept::Lm(lm) => {
            let (iterations, converged) = tree::solve(solver, lm, laid_out, &mut work, &mut meter)?;
            (iterations, converged, Some(lm))
        }
        Kept::Tree(tree) => {
            if !laid_out {
                *tree = ReachTree::EMPTY;
                tree.fill(body, goals.as_slice())?;
            }
            work.forward()?;
            let (iterations, converged) = if tree.is_empty() {
                (0, true)
            } else {
                balance::solve(solver, tree, &mut work)?
            };
            (iterations, converged, None)
        }
    };
    *state_layout = layout;
    (report.iterations, report.converged, report.error) = (iterations, converged, 0.0);
    report.work = if lm.is_some() {
        meter.spent().cost()
    } else {
        0
    };
    #[cfg(feature = "cost-terms")]
    {
        report.terms = meter.spent().units;
    }
    // With an active goal, tree DLS leaves every active goal's residual at
    // the final pose in its slots (in goal order): the same numbers as
    // evaluating the goal again.
    let slots = lm.map(|lm| lm.slots());
    let mut kept = slots.into_iter().flat_map(|s| s.iter()).peekable();
    for (r, i) in report.residuals.iter_mut().zip(0u8..) {
        let Some(g) = goals.as_slice().get(usize::from(i)) else {
            *r = 0.0;
            continue;
        };
        let active = g.is_active();
        *r = match kept.next_if(|s| active && s.goal == i) {
            Some(slot) => slot.magnitude(),
            None => g
                .evaluate(body, work.pose)
                .ok_or(SolveError::BadGoal(i))?
                .magnitude(),
        };
        if active {
            report.error += g.weight * *r * *r;
        }
    }
    Ok(())
}

/// The working state of [`solve_with`], kept by the caller between solves
/// (a live loop keeps one per figure): the reach tree (of the balancing
/// methods), the moving joints and their Jacobian columns, each joint's
/// rotation with the angles it was computed at, the goal rows and the
/// goal-space system. Sized by the body capacity `N`: about 286 bytes per
/// segment of capacity plus 5.2 kB (14.0 kB for `N` = 31, 23.4 kB for `N` =
/// 64).
/// Nothing in it changes a result: a solve with a kept state is
/// bit-identical to one with a new state.
pub struct SolverState<const N: usize> {
    tree: ReachTree<N>,
    lm: tree::Lm<N>,
    /// What `tree` and the joints in `lm` were built for; `None`: nothing
    /// valid.
    layout: Option<Layout>,
}

impl<const N: usize> SolverState<N> {
    /// A state with nothing built yet.
    #[must_use]
    pub const fn new() -> Self {
        SolverState {
            tree: ReachTree::EMPTY,
            lm: tree::Lm::EMPTY,
            layout: None,
        }
    }

    /// Forgets what was built, so that the next solve builds it again (after
    /// a body's contents changed in place).
    pub fn reset(&mut self) {
        self.layout = None;
    }
}

impl<const N: usize> Default for SolverState<N> {
    fn default() -> Self {
        Self::new()
    }
}

/// What the reach tree and the joint layout depend on: the body (by the
/// addresses of its tables and its length), the method and root mode, and
/// per active goal, in order, its segment and frame segment.
#[derive(Clone, Copy, Debug, Eq)]
struct Layout {
    body: [usize; 4],
    method: Method,
    root: RootMode,
    count: usize,
    /// Segment and frame segment (`u8::MAX`: the world) of each active goal.
    goals: [(u8, u8); MAX_GOALS],
}

impl PartialEq for Layout {
    /// Field by field and word by word (the derived comparison is a call of
    /// a byte-wise `memcmp` on the M4F).
    fn eq(&self, other: &Self) -> bool {
        let ([a, b, c, d], [e, f, g, h]) = (self.body, other.body);
        (a, b, c, d) == (e, f, g, h)
            && (self.method, self.root, self.count) == (other.method, other.root, other.count)
            && self.goals.iter().zip(&other.goals).all(|(x, y)| x == y)
    }
}

impl Layout {
    /// The layout of a solve; `None` (never reused) with more active goals
    /// than [`MAX_GOALS`].
    fn of(solver: &Solver, body: &Body<'_>, goals: &[Goal]) -> Option<Self> {
        let mut layout = Layout {
            body: [
                body.segments.as_ptr() as usize,
                body.parents.as_ptr() as usize,
                body.offsets.as_ptr() as usize,
                body.len(),
            ],
            method: solver.method,
            root: solver.root,
            count: 0,
            goals: [(0, 0); MAX_GOALS],
        };
        for g in goals.iter().filter(|g| g.is_active()) {
            let frame = match g.frame {
                Frame::World => u8::MAX,
                Frame::Segment(f) => f,
            };
            *layout.goals.get_mut(layout.count)? = (g.segment, frame);
            layout.count += 1;
        }
        Some(layout)
    }
}

/// The weighted error `Σ weight · residual²` of the active goals at `angles`
/// (world pose left in `pose`).
pub fn weighted_error<const N: usize>(
    body: &Body<'_>,
    goals: &[Goal],
    angles: &Angles<N>,
    pose: &mut Pose<N>,
) -> Result<f32, SolveError> {
    let mut local = LocalPose::<N>::default();
    angles.forward(body, &mut local, pose)?;
    let mut e = 0.0;
    for (g, i) in goals.iter().zip(0u8..).filter(|(g, _)| g.is_active()) {
        let r = g.evaluate(body, pose).ok_or(SolveError::BadGoal(i))?;
        e += g.weight * squared(&r);
    }
    Ok(e)
}

/// The squared size of a residual.
#[inline]
fn squared(r: &Residual) -> f32 {
    match *r {
        Residual::Position(d) | Residual::Orientation(d) => d.length_squared(),
        Residual::Plane { correction, .. } => correction * correction,
    }
}

/// The mutable state of one solve: the joint state, its world pose, scratch.
pub(crate) struct Work<'w, 'b, const N: usize> {
    pub body: &'w Body<'b>,
    pub goals: &'w [Goal],
    pub angles: &'w mut Angles<N>,
    pub pose: &'w mut Pose<N>,
    /// Scratch of [`Work::forward`], made on first use.
    local: Option<LocalPose<N>>,
}

impl<'w, 'b, const N: usize> Work<'w, 'b, N> {
    /// The state of a solve of `goals` from `angles`, not yet checked.
    fn new(
        body: &'w Body<'b>,
        goals: &'w [Goal],
        angles: &'w mut Angles<N>,
        pose: &'w mut Pose<N>,
    ) -> Self {
        Work {
            body,
            goals,
            angles,
            pose,
            local: None,
        }
    }

    /// Checks the body's structure (capacity, parents before children,
    /// matching slices; its joints are checked by `Body::validate`, once),
    /// the joint state and the goals, and clamps the angles into their
    /// limits.
    fn check(&mut self) -> Result<(), SolveError> {
        let body = self.body;
        if body.len() > N || body.len() > MAX_SEGMENTS {
            return Err(SolveError::Capacity);
        }
        if self.angles.count != body.len() {
            return Err(SolveError::Body(BodyError::CountMismatch));
        }
        for (g, i) in self.goals.iter().zip(0u8..) {
            let frame_ok = match g.frame {
                Frame::World => true,
                Frame::Segment(s) => usize::from(s) < body.len(),
            };
            if usize::from(g.segment) >= body.len()
                || !frame_ok
                || g.weight.is_nan()
                || (g.is_active() && !bounded_goal(g))
            {
                return Err(SolveError::BadGoal(i));
            }
        }
        body.hierarchy()
            .validate()
            .map_err(|e| SolveError::Body(BodyError::Pose(e)))?;
        self.angles.clamp_to_limits(body);
        Ok(())
    }

    /// Recomputes the world pose from the angles (the one forward kinematics).
    pub fn forward(&mut self) -> Result<(), SolveError> {
        let local = self.local.get_or_insert_with(LocalPose::default);
        self.angles.forward(self.body, local, self.pose)?;
        Ok(())
    }

    /// World position of a segment's touch point.
    pub fn touch(&self, segment: usize) -> Vec3 {
        let (Some(&p), Some(&r), Some(s)) = (
            self.pose.positions.get(segment),
            self.pose.rotations.get(segment),
            self.body.segment(segment),
        ) else {
            return Vec3::ZERO;
        };
        p + r * s.touch
    }
}

/// Segments from `top` (exclusive) down to `bottom` (inclusive), proximal first.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Chain<const N: usize> {
    len: usize,
    segments: [u8; N],
}

impl<const N: usize> Chain<N> {
    /// The chain from `top` (exclusive; `None` = the body root) to `bottom`;
    /// `skip_bottom` leaves the bottom joint out (it is reserved for an
    /// orientation goal). The body root's joint is never part of a chain.
    pub fn between(body: &Body<'_>, top: Option<usize>, bottom: usize, skip_bottom: bool) -> Self {
        let mut up = [0u8; N];
        let mut len = 0;
        let mut s = Some(bottom);
        while let Some(seg) = s {
            if Some(seg) == top || seg == 0 || len >= N {
                break;
            }
            if !(skip_bottom && seg == bottom)
                && let Some(slot) = up.get_mut(len)
            {
                *slot = u8::try_from(seg).unwrap_or(u8::MAX);
                len += 1;
            }
            s = body.parent(seg);
        }
        let mut segments = [0u8; N];
        for (d, &u) in segments.iter_mut().zip(up.iter().take(len).rev()) {
            *d = u;
        }
        Chain { len, segments }
    }

    /// The segments, proximal first.
    pub fn segments(&self) -> impl DoubleEndedIterator<Item = usize> + '_ {
        self.segments.iter().take(self.len).map(|&s| usize::from(s))
    }

    /// Number of segments.
    pub fn len(&self) -> usize {
        self.len
    }
}
