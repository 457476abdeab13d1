//! # cost: the solver's cost model against instruction counts
//!
//! Solves a fixed, varied set of problems with the whole-tree solver on the
//! emulated Cortex-M4F under `-icount shift=7,align=off` and prints, per
//! solve, its instructions (SysTick ticks / 3.2, see
//! `marionette_firmware::icount`) beside the work the solver counted for
//! itself ([`Report::work`](marionette_core::solve::Report::work)):
//!
//! ```text
//! cost <problem> <ticks> <work> <iterations> <converged 0|1>
//! ```
//!
//! Built with the `cost-terms` feature, each line ends with the units of
//! each term of the cost model (`marionette_core::solve::cost::Term`, in
//! order), and counting them costs instructions too. The model's
//! coefficients are fitted to both runs (the instructions of this binary as
//! built, the units of the `cost-terms` build) by `cargo run --release -p
//! marionette-tests --example fit_cost` (`tests/examples/fit_cost.rs`).
//!
//! The problems: the CMU and TEMPUS skeletons and the table region's rig
//! (the bench's `humanoid16`), 1 to 10 goals of every kind (points in the
//! world and in a segment's frame, contact and one-sided planes,
//! orientations), root fixed or floating, cold (a new state) and warm (the
//! goals moved, the state kept), with iteration caps, budgets and
//! restarts. `tests/realtime.rs` runs it and checks that the counted work
//! bounds every solve's instructions.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use glam::{Quat, Vec3};
use marionette_core::body::{Angles, Body, cmu, tempus};
use marionette_core::frame::Region;
use marionette_core::goal::{Goal, GoalSet, PlaneSide};
use marionette_core::math;
use marionette_core::pose::{LocalPose, Pose};
use marionette_core::solve::{self, MAX_GOALS, RootMode, Solver, SolverState};
use marionette_firmware::board::qemu::exit;
use marionette_firmware::console::Line;
use marionette_firmware::icount::Counter;
use marionette_firmware::region;

/// The capacity of the problems' states (the CMU skeleton's 31 segments).
const N: usize = 31;
/// Problems per body.
const PROBLEMS: u32 = 120;

/// A small deterministic generator (not part of any result).
struct Lcg(u32);

impl Lcg {
    /// In [-1, 1).
    fn unit(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (self.0 >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0
    }

    /// In 0..n.
    fn below(&mut self, n: u32) -> u32 {
        ((self.unit() + 1.0) * 0.5 * n as f32) as u32 % n.max(1)
    }

    fn vec(&mut self, scale: f32) -> Vec3 {
        Vec3::new(self.unit(), self.unit(), self.unit()) * scale
    }

    fn quat(&mut self) -> Quat {
        math::normalize_quat(Quat::from_xyzw(
            self.unit(),
            self.unit(),
            self.unit(),
            self.unit() + 1.5,
        ))
    }
}

/// A random pose within the limits.
fn pose_of(body: &Body<'_>, rng: &mut Lcg, spread: f32) -> Option<Angles<N>> {
    let mut a = Angles::<N>::rest(body).ok()?;
    for v in a.values.iter_mut().flat_map(|v| v.iter_mut()) {
        *v = rng.unit() * spread;
    }
    a.clamp_to_limits(body);
    Some(a)
}

/// Goal `k` of a problem: mostly points near the touch points of `pose`.
fn goal(body: &Body<'_>, pose: &Pose<N>, rng: &mut Lcg) -> Option<Goal> {
    let seg = (1 + rng.below(body.len() as u32 - 1)) as u8;
    let weight = 1.0 + 99.0 * (rng.unit() + 1.0) * 0.5;
    let touch = Goal::reach(seg, Vec3::ZERO, 1.0).world_point(body, pose)?;
    let goal = match rng.below(8) {
        0 => Goal::reach(seg, touch + rng.vec(0.05), weight).in_frame(0),
        1 => Goal::plane(seg, Vec3::Y, touch.y + 0.01, PlaneSide::Contact, weight),
        2 => Goal::plane(seg, Vec3::Y, touch.y - 0.02, PlaneSide::Above, weight),
        3 => {
            let r = *pose.rotations.get(usize::from(seg))?;
            Goal::orient(seg, math::normalize_quat(r * rng.quat()), weight)
        }
        _ => Goal::reach(seg, touch + rng.vec(0.03), weight),
    };
    Some(goal)
}

/// One problem on `body`: prints a cold and a warm solve.
fn problem(body: &Body<'_>, id: u32, counter: &mut Counter, rng: &mut Lcg) -> Option<()> {
    let target = pose_of(body, rng, 0.4)?;
    let mut local = LocalPose::<N>::default();
    let mut pose = Pose::<N>::default();
    target.forward(body, &mut local, &mut pose).ok()?;
    let mut goals = GoalSet::<MAX_GOALS>::new();
    let count = 1 + rng.below(MAX_GOALS as u32);
    for _ in 0..count {
        let g = goal(body, &pose, rng)?;
        goals.push(g).ok()?;
    }
    let mut solver = Solver::DEFAULT.with_iterations(1 + rng.below(20) as u16);
    if rng.below(3) == 0 {
        solver = solver.with_root(RootMode::Float);
    }
    if rng.below(4) == 0 {
        solver = solver.with_budget(5_000 + rng.below(60_000));
    }
    if rng.below(6) == 0 {
        solver = solver.with_restarts(1 + rng.below(3) as u8);
    }
    if rng.below(6) == 0 {
        solver.extrapolate = true;
    }
    let mut angles = target;
    for v in angles.values.iter_mut().flat_map(|v| v.iter_mut()) {
        *v += rng.unit() * 0.15;
    }
    let mut state = SolverState::<N>::new();
    measure(
        body,
        id * 2,
        &solver,
        &goals,
        &mut angles,
        &mut state,
        counter,
    );
    for g in goals.as_mut_slice() {
        if let marionette_core::goal::Target::Position(p) = &mut g.target {
            *p += rng.vec(0.004);
        }
    }
    measure(
        body,
        id * 2 + 1,
        &solver,
        &goals,
        &mut angles,
        &mut state,
        counter,
    );
    Some(())
}

/// Solves and prints one line.
fn measure(
    body: &Body<'_>,
    id: u32,
    solver: &Solver,
    goals: &GoalSet<MAX_GOALS>,
    angles: &mut Angles<N>,
    state: &mut SolverState<N>,
    counter: &mut Counter,
) {
    let mut pose = Pose::<N>::default();
    let mut result = None;
    let ticks = counter.ticks(|| {
        result = solve::solve_with(solver, body, goals, angles, &mut pose, state).ok();
    });
    let Some(report) = result else {
        Line::new().str("failed ").u32(id).print();
        return;
    };
    let mut line = Line::new();
    line.str("cost ")
        .u32(id)
        .str(" ")
        .u32(ticks)
        .str(" ")
        .u32(report.work)
        .str(" ")
        .u32(report.iterations)
        .str(" ")
        .u32(u32::from(report.converged));
    #[cfg(feature = "cost-terms")]
    for t in report.terms {
        line.str(" ").u32(t);
    }
    line.print();
}

#[entry]
fn main() -> ! {
    let Some(peripherals) = cortex_m::Peripherals::take() else {
        exit(3)
    };
    let mut counter = Counter::new(peripherals.SYST);
    let region = Region::<N>::parse_sized(region::tables());
    let rig_body = region.rig.as_ref().map(|r| r.body());
    let mut rng = Lcg(0xC057_5EED);
    let mut id = 0;
    for body in [Some(cmu::BODY), Some(tempus::BODY), rig_body]
        .into_iter()
        .flatten()
    {
        for _ in 0..PROBLEMS {
            let _ = problem(&body, id, &mut counter, &mut rng);
            id += 1;
        }
    }
    Line::new().str("end").print();
    exit(0)
}
