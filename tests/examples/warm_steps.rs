//! How many linearisations a solve needs: the evidence behind the warm-start
//! figure of the solver issue.
//!
//! Run with `cargo run --release -p marionette-tests --example warm_steps`.
//!
//! The problems are those of the firmware's `solve.cmu4.*` instruction-count
//! rows (`firmware/src/bin/bench.rs`): the CMU skeleton, root fixed, the
//! hands and feet reaching for the touch points of a random pose, from that
//! pose perturbed by up to ±0.1 rad per joint (cold); then the goals moved
//! by up to 1.15 cm per axis (≤ 2 cm) from the cold solution (warm). Problem
//! 0 is the benchmark's own; 1–19 use other seeds.
//!
//! For each, it counts the steps until every goal is within 0.1 mm:
//! - the shipped solver ([`Solver::DEFAULT`], tree DLS);
//! - idealised `f64` steps on the same variables, none of them the core's
//!   code: an exact (central-difference) Jacobian each step, the joint limits
//!   as an active set, and the shipped Marquardt damping `λ²·(|c|² + μ²)` at
//!   two values of `λ²`;
//! - the same with a second-order model: each step also solves
//!   `J·s = r − ½·∂²x[s, s]` (three fixed-point passes, the second
//!   derivative along `s` by central differences), the exact quadratic model.
//!
//! The `f64` steps are never rejected and keep their damping; the shipped
//! solver divides its damping by 3 after each accepted step, which is why it
//! needs fewer steps than the `λ² = 1e-2` rows. The `λ² = 1e-4` rows are
//! nearly undamped: what the model itself allows.

#[path = "../solve/reference.rs"]
#[allow(dead_code)]
mod reference;

use glam::Vec3;
use marionette_core::body::{Angles, cmu};
use marionette_core::goal::{Goal, GoalSet, Target};
use marionette_core::pose::{LocalPose, Pose};
use marionette_core::solve::{self, Solver, SolverState};
use reference::{RefBody, RefState, V, Var, fk, sub, variables, world};

/// The benchmark's generator (`firmware/src/bin/bench.rs`).
struct Lcg(u32);

impl Lcg {
    fn unit(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (self.0 >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0
    }
}

const SEGMENTS: usize = 31;
const PROBLEMS: u32 = 20;
const TOLERANCE: f64 = 1e-4;
const CAP: usize = 12;
/// The damping floor's lever squared (`solve::system::LEVER`²).
const MU2: f64 = 0.01;

/// One problem: the moving variables, the goal segments and targets, the
/// start, and the shipped solver's iterations.
struct Problem {
    body: RefBody,
    vars: Vec<Var>,
    segments: Vec<usize>,
    targets: Vec<V>,
    start: RefState,
    shipped: u32,
}

/// Problem `k`, cold or warm, built and solved as the benchmark does.
fn problem(k: u32, warm: bool) -> Problem {
    let body = cmu::BODY;
    let mut rng = Lcg(0x501E_5EED + k * 7919);
    let mut target = Angles::<SEGMENTS>::rest(&body).expect("rest pose");
    for v in target.values.iter_mut().flatten() {
        *v = rng.unit() * 0.3;
    }
    target.clamp_to_limits(&body);
    let (mut local, mut pose) = (LocalPose::<SEGMENTS>::default(), Pose::default());
    target
        .forward(&body, &mut local, &mut pose)
        .expect("forward");
    let mut goals = GoalSet::<4>::new();
    let mut segments = vec![];
    for name in ["LeftHand", "RightHand", "LeftFoot", "RightFoot"] {
        let seg = body.find(name).expect("CMU segment");
        let touch = Goal::reach(seg, Vec3::ZERO, 1.0).world_point(&body, &pose);
        goals
            .push(Goal::reach(seg, touch.expect("touch point"), 1.0))
            .expect("room");
        segments.push(usize::from(seg));
    }
    let mut start = target;
    for v in start.values.iter_mut().flatten() {
        *v += rng.unit() * 0.1;
    }
    start.clamp_to_limits(&body);
    let (mut angles, mut state) = (start, SolverState::new());
    let solver = Solver::DEFAULT;
    let cold = solve::solve_with(&solver, &body, &goals, &mut angles, &mut pose, &mut state);
    let mut shipped = cold.expect("cold solve").iterations;
    if warm {
        start = angles;
        for g in goals.as_mut_slice() {
            if let Target::Position(p) = &mut g.target {
                *p += Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 0.0115;
            }
        }
        let report = solve::solve_with(&solver, &body, &goals, &mut angles, &mut pose, &mut state);
        shipped = report.expect("warm solve").iterations;
    }
    let body = RefBody::of(&body);
    let targets = goals.as_slice().iter().map(|g| match g.target {
        Target::Position(p) => [p.x, p.y, p.z].map(f64::from),
        _ => unreachable!("position goals"),
    });
    Problem {
        vars: variables(&body, 0, &segments, false),
        targets: targets.collect(),
        body,
        segments,
        start: RefState::of(&start),
        shipped,
    }
}

/// The state moved by `t·dx`.
fn moved(p: &Problem, s: &RefState, dx: &[f64], t: f64) -> RefState {
    let mut out = s.clone();
    for (v, x) in p.vars.iter().zip(dx) {
        v.set(&mut out, v.get(s) + t * x);
    }
    out
}

/// The goals' residuals `target − touch point`, three rows per goal.
fn residuals(p: &Problem, s: &RefState) -> Vec<f64> {
    let pose = fk(&p.body, s);
    let rows = p.segments.iter().zip(&p.targets);
    rows.flat_map(|(&g, &t)| sub(t, world(&pose, g, p.body.touch[g])))
        .collect()
}

/// The largest goal distance.
fn worst(r: &[f64]) -> f64 {
    let d = r
        .chunks(3)
        .map(|c| c.iter().map(|x| x * x).sum::<f64>().sqrt());
    d.fold(0.0, f64::max)
}

/// The touch points' Jacobian, one column (12 rows) per variable.
fn jacobian(p: &Problem, s: &RefState) -> Vec<Vec<f64>> {
    let h = 1e-6;
    let columns = p.vars.iter().enumerate().map(|(i, _)| {
        let mut e = vec![0.0; p.vars.len()];
        e[i] = 1.0;
        let (plus, minus) = (
            residuals(p, &moved(p, s, &e, h)),
            residuals(p, &moved(p, s, &e, -h)),
        );
        plus.iter()
            .zip(&minus)
            .map(|(a, b)| (b - a) / (2.0 * h))
            .collect()
    });
    columns.collect()
}

/// The second derivative of the touch points along `dx`.
fn curvature(p: &Problem, s: &RefState, dx: &[f64]) -> Vec<f64> {
    let h = 1e-3;
    let at = |t: f64| residuals(p, &moved(p, s, dx, t));
    let (plus, here, minus) = (at(h), at(0.0), at(-h));
    let rows = plus.iter().zip(&here).zip(&minus);
    rows.map(|((a, b), c)| -(a - 2.0 * b + c) / (h * h))
        .collect()
}

/// Solves the dense system `a·x = b` (partial pivoting).
fn solve_dense(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Vec<f64> {
    let n = b.len();
    for i in 0..n {
        let pivot = (i..n)
            .max_by(|&x, &y| a[x][i].abs().total_cmp(&a[y][i].abs()))
            .unwrap_or(i);
        a.swap(i, pivot);
        b.swap(i, pivot);
        let (top, below) = a.split_at_mut(i + 1);
        let row = &top[i];
        for (k, other) in below.iter_mut().enumerate() {
            let f = other[i] / row[i];
            other[i..]
                .iter_mut()
                .zip(&row[i..])
                .for_each(|(x, y)| *x -= f * y);
            b[i + 1 + k] -= f * b[i];
        }
    }
    let mut x = vec![0.0; n];
    for i in (0..n).rev() {
        let s: f64 = (i + 1..n).map(|j| a[i][j] * x[j]).sum();
        x[i] = (b[i] - s) / a[i][i];
    }
    x
}

/// The damped step `D⁻¹·Jᵀ·(J·D⁻¹·Jᵀ + I)⁻¹·r` with the variables in
/// `held` fixed at the given motion.
fn damped(j: &[Vec<f64>], r: &[f64], d: &[f64], held: &[Option<f64>]) -> Vec<f64> {
    let m = r.len();
    let mut rhs = r.to_vec();
    let mut a = vec![vec![0.0; m]; m];
    for ((c, di), h) in j.iter().zip(d).zip(held) {
        if let Some(x) = h {
            rhs.iter_mut().zip(c).for_each(|(r, c)| *r -= c * x);
            continue;
        }
        for (x, row) in a.iter_mut().enumerate() {
            for (y, v) in row.iter_mut().enumerate() {
                *v += c[x] * c[y] / di;
            }
        }
    }
    a.iter_mut().enumerate().for_each(|(x, row)| row[x] += 1.0);
    let y = solve_dense(a, rhs);
    let free = j
        .iter()
        .zip(d)
        .map(|(c, di)| c.iter().zip(&y).map(|(a, b)| a * b).sum::<f64>() / di);
    free.zip(held).map(|(x, h)| h.unwrap_or(x)).collect()
}

/// The damped step with the limits as an active set: a variable the step
/// would carry through a limit is held at it and the rest solved again.
fn step(p: &Problem, s: &RefState, j: &[Vec<f64>], r: &[f64], d: &[f64]) -> Vec<f64> {
    let mut held = vec![None; p.vars.len()];
    let mut dx = damped(j, r, d, &held);
    for _ in 0..6 {
        let mut again = false;
        for (i, v) in p.vars.iter().enumerate() {
            if let (Var::Dof { min, max, .. }, None) = (*v, held[i]) {
                let x = v.get(s);
                let limit = (x + dx[i]).clamp(min, max);
                if limit != x + dx[i] {
                    (held[i], again) = (Some(limit - x), true);
                }
            }
        }
        if !again {
            break;
        }
        dx = damped(j, r, d, &held);
    }
    dx
}

/// Steps of a model until every goal is within [`TOLERANCE`] (at most
/// [`CAP`]); returns the count and the worst distance after each step.
fn run(p: &Problem, lambda2: f64, passes: usize) -> (usize, Vec<f64>) {
    let mut s = p.start.clone();
    let mut r = residuals(p, &s);
    let mut trace = vec![];
    for count in 0..CAP {
        if worst(&r) <= TOLERANCE {
            return (count, trace);
        }
        let j = jacobian(p, &s);
        let d: Vec<f64> = j
            .iter()
            .map(|c| lambda2 * (c.iter().map(|x| x * x).sum::<f64>() + MU2))
            .collect();
        let mut dx = step(p, &s, &j, &r, &d);
        for _ in 0..passes {
            let c = curvature(p, &s, &dx);
            let model: Vec<f64> = r.iter().zip(&c).map(|(r, c)| r - 0.5 * c).collect();
            dx = step(p, &s, &j, &model, &d);
        }
        s = moved(p, &s, &dx, 1.0);
        r = residuals(p, &s);
        trace.push(worst(&r));
    }
    (CAP, trace)
}

fn main() {
    for warm in [false, true] {
        let problems: Vec<Problem> = (0..PROBLEMS).map(|k| problem(k, warm)).collect();
        let start: Vec<f64> = problems
            .iter()
            .map(|p| worst(&residuals(p, &p.start)))
            .collect();
        println!(
            "{} problems, worst goal at the start {:.1}..{:.1} mm (benchmark: {:.1} mm)",
            if warm { "warm" } else { "cold" },
            1e3 * start.iter().copied().fold(f64::INFINITY, f64::min),
            1e3 * start.iter().copied().fold(0.0, f64::max),
            1e3 * start[0],
        );
        let shipped: Vec<usize> = problems.iter().map(|p| p.shipped as usize).collect();
        println!("  {:34} {}", "shipped tree DLS", histogram(&shipped));
        for (name, lambda2, passes) in [
            ("f64 linear model, λ² = 1e-2", 1e-2, 0),
            ("f64 linear model, λ² = 1e-4", 1e-4, 0),
            ("f64 quadratic model, λ² = 1e-2", 1e-2, 3),
            ("f64 quadratic model, λ² = 1e-4", 1e-4, 3),
        ] {
            let runs: Vec<(usize, Vec<f64>)> =
                problems.iter().map(|p| run(p, lambda2, passes)).collect();
            let counts: Vec<usize> = runs.iter().map(|r| r.0).collect();
            let bench = runs[0].1.iter().take(3).map(|w| format!("{:.3}", 1e3 * w));
            println!(
                "  {name:34} {}; benchmark after each step: {} mm",
                histogram(&counts),
                bench.collect::<Vec<_>>().join(", ")
            );
        }
    }
}

/// "steps: problems" for 1, 2, 3 and more steps.
fn histogram(counts: &[usize]) -> String {
    let n = |f: &dyn Fn(usize) -> bool| counts.iter().filter(|&&c| f(c)).count();
    format!(
        "1 step: {:2}, 2: {:2}, 3: {:2}, more: {:2}",
        n(&|c| c <= 1),
        n(&|c| c == 2),
        n(&|c| c == 3),
        n(&|c| c > 3)
    )
}
