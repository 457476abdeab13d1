//! Host benchmarks for the POSIT solver on the CMU 31-joint skeleton, body
//! root fixed, 4 goals (both hands, both feet):
//!
//! - **cold, synthesized start**: the goals are the touch points of a random
//!   pose, moved up to 3 cm; the start is that pose with every DOF moved up to
//!   ±0.1 rad (what interpolation synthesis hands the solver);
//! - **cold, rest start**: the same goals from the rest pose (T-pose);
//! - **warm**: from the previous frame's solution, every goal moved ≤ 2 cm
//!   (`warm/…` with a fresh working state, `warm-state/TreeDls` with the
//!   [`SolverState`] that the previous frame's solve left, as a live loop
//!   keeps it).
//!
//! Before the criterion runs, a README-ready table compares the paper's greedy
//! chain solver with CCD, chain DLS and the whole-tree DLS on the same problems:
//! residuals, weighted error, iterations (balancing iterations for the first
//! three, LM iterations for the tree DLS) and host time.
//!
//! The peer baseline (`peer`): the `k` crate's Jacobian IK, which a user
//! might pick instead, on the same skeleton, starts and goals, with its
//! residuals measured by the core's forward kinematics and its time in the
//! same table and criterion group.
//! Instruction counts on the Cortex-M4F come from the firmware bench.

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{Criterion, criterion_group, criterion_main};
use glam::Vec3;
use marionette_core::body::{Angles, Body, cmu};
use marionette_core::goal::{Goal, GoalSet, Target};
use marionette_core::pose::{LocalPose, Pose};
use marionette_core::solve::{Method, RootMode, Solver, SolverState, solve, solve_with};

const N: usize = 32;
const PROBLEMS: usize = 32;
type A = Angles<N>;

/// Deterministic pseudo-random numbers in [-1, 1).
struct Lcg(u64);
impl Lcg {
    fn unit(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 40) as f32 / (1u64 << 23) as f32 - 1.0
    }
    fn vec(&mut self) -> Vec3 {
        Vec3::new(self.unit(), self.unit(), self.unit())
    }
}

struct Problem {
    synth: A,
    rest: A,
    goals: GoalSet<4>,
    moved: GoalSet<4>,
}

fn touch(body: &Body<'_>, a: &A, seg: u8) -> Vec3 {
    let mut local = LocalPose::<N>::default();
    let mut pose = Pose::<N>::default();
    a.forward(body, &mut local, &mut pose).expect("forward");
    Goal::reach(seg, Vec3::ZERO, 1.0)
        .world_point(body, &pose)
        .expect("touch point")
}

fn problems() -> Vec<Problem> {
    let body = &cmu::BODY;
    let mut rng = Lcg(0x5EED);
    let root = Vec3::new(0.0, 0.95, 0.0);
    (0..PROBLEMS)
        .map(|_| {
            let mut truth = A::rest(body).expect("rest");
            truth.root_position = root;
            let mut synth = truth;
            for (i, s) in body.segments.iter().enumerate().skip(1) {
                for (k, d) in s.joint.dofs().iter().enumerate() {
                    let mid = 0.5 * (d.min + d.max);
                    truth.values[i][k] = mid + 0.25 * (d.max - d.min) * rng.unit();
                    synth.values[i][k] = d.clamp(truth.values[i][k] + 0.1 * rng.unit());
                }
            }
            let mut goals = GoalSet::<4>::new();
            for seg in [
                cmu::index::LEFT_HAND,
                cmu::index::RIGHT_HAND,
                cmu::index::LEFT_FOOT,
                cmu::index::RIGHT_FOOT,
            ] {
                let at = touch(body, &truth, seg) + rng.vec() * (0.03 / 3f32.sqrt());
                goals.push(Goal::reach(seg, at, 1.0)).expect("capacity");
            }
            let mut moved = goals;
            for g in moved.as_mut_slice() {
                if let Target::Position(p) = &mut g.target {
                    *p += rng.vec() * (0.02 / 3f32.sqrt());
                }
            }
            let mut rest = A::rest(body).expect("rest");
            rest.root_position = root;
            Problem {
                synth,
                rest,
                goals,
                moved,
            }
        })
        .collect()
}

fn solver(method: Method) -> Solver {
    Solver::DEFAULT
        .with_method(method)
        .with_root(RootMode::Fixed)
}

const METHODS: [(Method, &str); 4] = [
    (Method::Greedy, "Greedy (paper)"),
    (Method::Ccd, "CCD"),
    (Method::Dls, "Chain DLS"),
    (Method::TreeDls, "Tree DLS (default)"),
];

#[derive(Clone, Copy, PartialEq, Eq)]
enum Scenario {
    Synth,
    Rest,
    Warm,
}

/// The start and goals of every problem in a scenario (warm: from `method`'s
/// solution of the synthesized-start problem, to the moved goals).
fn cases(method: Method, scenario: Scenario, problems: &[Problem]) -> Vec<(A, GoalSet<4>)> {
    problems
        .iter()
        .map(|p| match scenario {
            Scenario::Synth => (p.synth, p.goals),
            Scenario::Rest => (p.rest, p.goals),
            Scenario::Warm => (once(method, &p.synth, &p.goals).0, p.moved),
        })
        .collect()
}

/// One solve.
fn once(method: Method, start: &A, goals: &GoalSet<4>) -> (A, marionette_core::solve::Report<4>) {
    let mut a = *start;
    let mut pose = Pose::<N>::default();
    let r = solve(&solver(method), &cmu::BODY, goals, &mut a, &mut pose).expect("solve");
    (a, r)
}

/// The README table: one row per method and scenario.
fn table(problems: &[Problem]) {
    println!(
        "\n| method | start | mean residual (mm) | max residual (mm) | all goals ≤ 0.1 mm | mean Σw·r² (mm²) | iterations | host µs/solve |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for (scenario, label) in [
        (Scenario::Synth, "cold, synthesized"),
        (Scenario::Rest, "cold, rest"),
        (Scenario::Warm, "warm (≤ 2 cm)"),
    ] {
        let all: Vec<Vec<(A, GoalSet<4>)>> = METHODS
            .iter()
            .map(|&(m, _)| cases(m, scenario, problems))
            .collect();
        let reports: Vec<Vec<marionette_core::solve::Report<4>>> = METHODS
            .iter()
            .zip(&all)
            .map(|(&(m, _), cs)| cs.iter().map(|(a, g)| once(m, a, g).1).collect())
            .collect();
        for ((&(method, name), cs), rs) in METHODS.iter().zip(&all).zip(&reports) {
            let (mut sum, mut max, mut met, mut its, mut error) = (0.0f32, 0.0f32, 0, 0u32, 0.0f32);
            for r in rs {
                for &d in &r.residuals {
                    sum += d;
                    max = max.max(d);
                }
                met += usize::from(r.residuals.iter().all(|&d| d <= 1e-4));
                its += r.iterations;
                error += r.error;
            }
            let reps = 5;
            let t0 = Instant::now();
            for _ in 0..reps {
                for (a, g) in cs {
                    black_box(once(method, black_box(a), black_box(g)));
                }
            }
            let micros = t0.elapsed().as_secs_f64() * 1e6 / (reps * cs.len()) as f64;
            let n = problems.len() as f32;
            println!(
                "| {name} | {label} | {:.3} | {:.2} | {}/{} | {:.3} | {:.1} | {:.0} |",
                sum / (4.0 * n) * 1e3,
                max * 1e3,
                met,
                problems.len(),
                error / n * 1e6,
                its as f32 / n,
                micros
            );
        }
    }
    println!();
}

fn benches(c: &mut Criterion) {
    let problems = problems();
    table(&problems);
    peer::table(&problems);
    let mut group = c.benchmark_group("solve");
    group
        .sample_size(20)
        .measurement_time(Duration::from_secs(2))
        .warm_up_time(Duration::from_millis(500));
    for &(method, _) in &METHODS {
        for (scenario, label) in [
            (Scenario::Synth, "cold-synth"),
            (Scenario::Rest, "cold-rest"),
            (Scenario::Warm, "warm"),
        ] {
            let cs = cases(method, scenario, &problems);
            group.bench_function(format!("{label}/{method:?}"), |b| {
                let mut i = 0;
                b.iter(|| {
                    i = (i + 1) % cs.len();
                    let (a, g) = &cs[i];
                    black_box(once(method, a, g))
                });
            });
        }
    }
    // The live loop's warm frame: each problem keeps the state its previous
    // frame's solve left (`solve_with`), reused by every timed solve of it.
    let warm: Vec<(A, GoalSet<4>)> = cases(Method::TreeDls, Scenario::Warm, &problems);
    let mut states: Vec<SolverState<N>> = problems
        .iter()
        .map(|p| {
            let (mut a, mut pose, mut state) = (p.synth, Pose::<N>::default(), SolverState::new());
            let s = solver(Method::TreeDls);
            solve_with(&s, &cmu::BODY, &p.goals, &mut a, &mut pose, &mut state).expect("solve");
            state
        })
        .collect();
    group.bench_function("warm-state/TreeDls", |b| {
        let mut i = 0;
        let mut pose = Pose::<N>::default();
        b.iter(|| {
            i = (i + 1) % warm.len();
            let (mut a, g) = warm[i];
            let s = solver(Method::TreeDls);
            black_box(solve_with(
                &s,
                &cmu::BODY,
                &g,
                &mut a,
                &mut pose,
                &mut states[i],
            ))
        });
    });
    for (scenario, label) in [
        (Scenario::Synth, "cold-synth"),
        (Scenario::Rest, "cold-rest"),
        (Scenario::Warm, "warm"),
    ] {
        let limbs = peer::cases(scenario, &problems);
        group.bench_function(format!("{label}/k-jacobian"), |b| {
            let mut i = 0;
            b.iter(|| {
                i = (i + 1) % limbs.len();
                black_box(limbs[i].solve())
            });
        });
    }
    group.finish();
}

/// The `k` crate (0.32, `f64`, nalgebra) as a peer baseline.
///
/// `k` solves one serial chain per call, with the end transform of the whole
/// chain from its root, so each goal's limb is its own `k` tree: a fixed base
/// node at the world placement of the limb's parent segment in the start
/// pose (the torso branch for an arm, the hips for a leg), one rotational
/// node per degree of freedom (the core's `R_a·R_b·R_c` order, limits as
/// `k` ranges, the segment offset on the first), and a fixed node at the
/// touch point. The torso is not solved (the tree DLS moves it too): the four
/// limbs are independent chains and are solved one after the other,
/// position only (`Constraints` without rotation), to 0.1 mm as our solver,
/// `k`'s default step multiplier 0.5, at most 100 steps. On a failure `k`
/// restores the chain's start angles (its contract), so such a limb's residual
/// is its start's.
mod peer {
    use std::time::Instant;

    use glam::{Quat, Vec3};
    use k::nalgebra::{self as na, Isometry3, Translation3, UnitQuaternion, Vector3};
    use k::{Constraints, InverseKinematicsSolver, JacobianIkSolver, JointType, NodeBuilder};
    use k::{SerialChain, joint::Range};
    use marionette_core::body::{Axis, Body, cmu};
    use marionette_core::goal::{GoalSet, Target};
    use marionette_core::pose::{LocalPose, Pose};

    use super::{A, N, Problem, Scenario, black_box};

    /// Stop within 0.1 mm, as the tree DLS (`Solver::DEFAULT`).
    const TOLERANCE: f64 = 1e-4;
    /// `k`'s default step multiplier.
    const MULTIPLIER: f64 = 0.5;
    /// Most steps per limb.
    const MAX_TRY: usize = 100;

    /// One goal's limb as a `k` chain.
    pub(super) struct Limb {
        /// The limb's segments, top down.
        segments: Vec<usize>,
        arm: SerialChain<f64>,
        target: Isometry3<f64>,
        /// The start values of the chain's joints (one per DOF, in order).
        start: Vec<f64>,
    }

    /// A problem: the start angles and the four limbs.
    pub(super) struct Case {
        start: A,
        goals: GoalSet<4>,
        limbs: Vec<Limb>,
    }

    fn v64(v: Vec3) -> Vector3<f64> {
        Vector3::new(f64::from(v.x), f64::from(v.y), f64::from(v.z))
    }

    fn iso(p: Vec3, q: Quat) -> Isometry3<f64> {
        let q = na::Quaternion::new(
            f64::from(q.w),
            f64::from(q.x),
            f64::from(q.y),
            f64::from(q.z),
        );
        Isometry3::from_parts(
            Translation3::from(v64(p)),
            UnitQuaternion::from_quaternion(q),
        )
    }

    fn world(body: &Body<'_>, a: &A) -> Pose<N> {
        let (mut local, mut pose) = (LocalPose::<N>::default(), Pose::<N>::default());
        a.forward(body, &mut local, &mut pose).expect("forward");
        pose
    }

    /// The segments from `seg` up to, not including, the first branch (a
    /// segment with more than one child) or the root; top down.
    fn limb_segments(body: &Body<'_>, seg: usize) -> Vec<usize> {
        let children = |p: usize| {
            body.parents
                .iter()
                .filter(|&&q| usize::from(q) == p)
                .count()
        };
        let mut out = vec![seg];
        while let Some(parent) = body.parent(*out.last().expect("non-empty")) {
            if parent == 0 || children(parent) > 1 {
                break;
            }
            out.push(parent);
        }
        out.reverse();
        out
    }

    fn limb(body: &Body<'_>, start: &A, pose: &Pose<N>, seg: usize, goal: Vec3) -> Limb {
        let segments = limb_segments(body, seg);
        let top = body.parent(segments[0]).expect("a limb has a parent");
        let base = NodeBuilder::new()
            .name("base")
            .origin(iso(pose.positions[top], pose.rotations[top]))
            .into_node();
        // `k` links a node to its parent weakly: the base must outlive the
        // building of the chain (which then holds every node).
        let mut parent = base.clone();
        let mut values = Vec::new();
        for &s in &segments {
            let segment = &body.segments[s];
            let dofs = segment.joint.dofs();
            let origin = Translation3::from(v64(segment.origin));
            if dofs.is_empty() {
                let node = NodeBuilder::new()
                    .name(segment.name)
                    .translation(origin)
                    .into_node();
                node.set_parent(&parent);
                parent = node;
            }
            for (d, dof) in dofs.iter().enumerate() {
                let axis = match dof.axis {
                    Axis::X => Vector3::x_axis(),
                    Axis::Y => Vector3::y_axis(),
                    Axis::Z => Vector3::z_axis(),
                };
                let node = NodeBuilder::new()
                    .name(&format!("{}.{d}", segment.name))
                    .translation(if d == 0 {
                        origin
                    } else {
                        Translation3::identity()
                    })
                    .joint_type(JointType::Rotational { axis })
                    .limits(Some(Range::new(f64::from(dof.min), f64::from(dof.max))))
                    .into_node();
                node.set_parent(&parent);
                parent = node;
                values.push(f64::from(start.values[s][d]));
            }
        }
        let touch = NodeBuilder::new()
            .name("touch")
            .translation(Translation3::from(v64(body.segments[seg].touch)))
            .into_node();
        touch.set_parent(&parent);
        Limb {
            segments,
            arm: SerialChain::from_end(&touch),
            target: iso(goal, Quat::IDENTITY),
            start: values,
        }
    }

    impl Case {
        fn new(start: A, goals: GoalSet<4>) -> Self {
            let body = &cmu::BODY;
            let pose = world(body, &start);
            let limbs = goals
                .as_slice()
                .iter()
                .map(|g| {
                    let Target::Position(at) = g.target else {
                        panic!("point goals only")
                    };
                    limb(body, &start, &pose, usize::from(g.segment), at)
                })
                .collect();
            Case {
                start,
                goals,
                limbs,
            }
        }

        /// Solves every limb from its start angles; the angles reached and
        /// how many limbs `k` reports converged.
        pub(super) fn solve(&self) -> (A, usize) {
            let solver = JacobianIkSolver::new(TOLERANCE, 1.0, MULTIPLIER, MAX_TRY);
            let constraints = Constraints {
                rotation_x: false,
                rotation_y: false,
                rotation_z: false,
                ..Constraints::default()
            };
            let mut a = self.start;
            let mut converged = 0;
            for limb in &self.limbs {
                limb.arm.set_joint_positions_clamped(&limb.start);
                let ok = solver
                    .solve_with_constraints(&limb.arm, &limb.target, &constraints)
                    .is_ok();
                converged += usize::from(ok);
                let mut values = limb.arm.joint_positions().into_iter();
                for &s in &limb.segments {
                    let n = cmu::BODY.segments[s].joint.dofs().len();
                    for v in a.values[s].iter_mut().take(n) {
                        *v = values.next().expect("one value per DOF") as f32;
                    }
                }
            }
            (a, converged)
        }

        /// Each goal's residual (m) with the core's forward kinematics.
        fn residuals(&self, a: &A) -> Vec<f32> {
            let pose = world(&cmu::BODY, a);
            self.goals
                .as_slice()
                .iter()
                .map(|g| {
                    let Target::Position(at) = g.target else {
                        unreachable!()
                    };
                    (g.world_point(&cmu::BODY, &pose).expect("point") - at).length()
                })
                .collect()
        }
    }

    /// The problems of a scenario for `k` (warm: from `k`'s own solution of
    /// the synthesized-start problem, to the moved goals).
    pub(super) fn cases(scenario: Scenario, problems: &[Problem]) -> Vec<Case> {
        problems
            .iter()
            .map(|p| match scenario {
                Scenario::Synth => Case::new(p.synth, p.goals),
                Scenario::Rest => Case::new(p.rest, p.goals),
                Scenario::Warm => Case::new(Case::new(p.synth, p.goals).solve().0, p.moved),
            })
            .collect()
    }

    /// The peer's rows for the README table (same columns where they apply).
    pub(super) fn table(problems: &[Problem]) {
        println!(
            "| method | start | mean residual (mm) | max residual (mm) | all goals ≤ 0.1 mm | limbs k reports converged | host µs/solve |"
        );
        println!("|---|---|---|---|---|---|---|");
        for (scenario, label) in [
            (Scenario::Synth, "cold, synthesized"),
            (Scenario::Rest, "cold, rest"),
            (Scenario::Warm, "warm (≤ 2 cm)"),
        ] {
            let cases = cases(scenario, problems);
            let (mut sum, mut max, mut met, mut converged) = (0.0f32, 0.0f32, 0, 0);
            for case in &cases {
                let (a, ok) = case.solve();
                let r = case.residuals(&a);
                sum += r.iter().sum::<f32>();
                max = r.iter().fold(max, |m, &d| m.max(d));
                met += usize::from(r.iter().all(|&d| d <= 1e-4));
                converged += ok;
            }
            let reps = 5;
            let t0 = Instant::now();
            for _ in 0..reps {
                for case in &cases {
                    black_box(case.solve());
                }
            }
            let micros = t0.elapsed().as_secs_f64() * 1e6 / (reps * cases.len()) as f64;
            println!(
                "| k 0.32 Jacobian (per limb) | {label} | {:.3} | {:.2} | {met}/{} | {converged}/{} | {micros:.0} |",
                sum / (4.0 * cases.len() as f32) * 1e3,
                max * 1e3,
                cases.len(),
                4 * cases.len(),
            );
        }
        println!();
    }
}

criterion_group!(solve_benches, benches);
criterion_main!(solve_benches);
