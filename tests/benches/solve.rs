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
    group.finish();
}

criterion_group!(solve_benches, benches);
criterion_main!(solve_benches);
