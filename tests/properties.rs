//! Property tests of the core (issue #7, item 3), for any input including
//! NaN, infinities, huge values and denormals:
//!
//! - grid synthesis returns a finite pose with unit rotations, or a typed
//!   error ([`GridError::NonFinite`] for a NaN or infinite parameter,
//!   [`GridError::NoValidCell`] for an all-invalid mask);
//! - the solver (every method, both root modes, on the shipped humanoid16 and
//!   cmu31 rigs) never leaves a joint limit and never produces a NaN angle or
//!   position, whatever the goals;
//! - every servo output stays within its calibrated pulse range, every step
//!   within its speed limit, and every change of step within its
//!   acceleration limit (except where the range forces a sharper stop);
//! - the live loop's fail-safe always reaches rest (`Performer::tick` after
//!   arbitrary frames, commands and dials), with the same output checks on
//!   every step.
//!
//! The expectations are the documented contracts, not outputs of the code:
//! unit length, limits and ranges are checked directly.

use glam::{Quat, Vec3};
use marionette_core::body::{Angles, Body};
use marionette_core::frame::{Performer, Region};
use marionette_core::goal::{Attach, Frame, Goal, GoalSet, PlaneSide, Target};
use marionette_core::grid::{Axis, Grid, GridError, Interp, SliceSamples, Wrap};
use marionette_core::pose::{MAX_SEGMENTS, Pose};
use marionette_core::rig::Rig;
use marionette_core::servo::{Calibration, Slew, StepLimits, quarter_us};
use marionette_core::solve::{self, Method, RootMode, Solver, SolverState};
use marionette_core::wire::{
    Command, CommandKind, List, MAX_SENSORS, Message, Params, Sensor, TrackerFrame,
};
use marionette_host::perform;
use marionette_host::rigfile;
use marionette_tests::fuzz_targets::{self, Run};
use proptest::prelude::*;
use std::sync::OnceLock;

// ------------------------------------------------------------- strategies

/// Any `f32`, weighted towards the awkward ones: ordinary values, then every
/// class (NaN, ±∞, subnormals, zeros) and the extremes.
fn wild() -> impl Strategy<Value = f32> {
    prop_oneof![
        6 => -3.0f32..3.0,
        2 => prop::num::f32::ANY,
        2 => prop::sample::select(vec![
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
            f32::MIN,
            1e30,
            -1e30,
            f32::MIN_POSITIVE,
            f32::MIN_POSITIVE / 8.0,
            -1e-42,
            0.0,
            -0.0,
        ]),
    ]
}

fn wild3() -> impl Strategy<Value = Vec3> {
    prop::array::uniform3(wild()).prop_map(Vec3::from_array)
}

/// A unit quaternion (table samples are always unit).
fn unit_quat() -> impl Strategy<Value = Quat> {
    prop::array::uniform4(-1.0f32..1.0).prop_map(|[x, y, z, w]| {
        let q = Quat::from_xyzw(x, y, z, w);
        let n = q.dot(q).sqrt();
        if n < 1e-3 {
            Quat::IDENTITY
        } else {
            q * (1.0 / n)
        }
    })
}

fn grid_axis() -> impl Strategy<Value = Axis> {
    (
        -10.0f32..10.0,
        0.01f32..5.0,
        2u32..5,
        any::<bool>(),
        any::<bool>(),
    )
        .prop_map(|(min, step, count, cyclic, cubic)| Axis {
            min,
            step,
            count,
            wrap: if cyclic {
                Wrap::Cyclic {
                    period: step * count as f32,
                }
            } else {
                Wrap::Bounded
            },
            interp: if cubic {
                Interp::CatmullRom
            } else {
                Interp::Linear
            },
        })
}

fn unit(q: Quat, tol: f32) -> bool {
    q.is_finite() && (q.dot(q) - 1.0).abs() <= tol
}

// -------------------------------------------------------------------- rigs

fn rig_blobs() -> &'static [Vec<u8>; 2] {
    static BLOBS: OnceLock<[Vec<u8>; 2]> = OnceLock::new();
    BLOBS.get_or_init(|| {
        [
            (fuzz_targets::HUMANOID16_TOML, "humanoid16.toml"),
            (fuzz_targets::CMU31_TOML, "cmu31.toml"),
        ]
        .map(|(text, file)| {
            rigfile::to_blob(&rigfile::parse(text, file).expect("shipped rig"))
                .expect("shipped rig blob")
        })
    })
}

fn rig(i: usize) -> Rig<'static> {
    Rig::parse(&rig_blobs()[i]).expect("shipped rig blob").0
}

// -------------------------------------------------------------------- grid

proptest! {
    #![proptest_config(ProptestConfig { failure_persistence: None, ..ProptestConfig::with_cases(1024) })]

    /// Grid synthesis over random grids (linear, Catmull-Rom, bounded,
    /// cyclic; with or without a validity mask) of unit-rotation samples, at
    /// arbitrary parameters.
    #[test]
    fn grid_synthesis_is_finite_and_normalized_or_a_typed_error(
        axes in prop::collection::vec(grid_axis(), 1..=3),
        segments in 1usize..4,
        seed in prop::collection::vec((prop::array::uniform3(-32.0f32..32.0), unit_quat()), 256),
        mask in prop::option::of(prop::collection::vec(any::<u8>(), 8)),
        params in prop::collection::vec(wild(), 3),
    ) {
        let grid = Grid::new(&axes, mask.as_deref()).expect("valid axes");
        let n = grid.sample_count() * segments;
        let positions: Vec<Vec3> = (0..n).map(|i| Vec3::from_array(seed[i % 256].0)).collect();
        let rotations: Vec<Quat> = (0..n).map(|i| seed[(i * 7 + 3) % 256].1).collect();
        let samples = SliceSamples::new(segments, &positions, &rotations).expect("sized");
        let params = &params[..axes.len()];
        let mut pose = Pose::<8>::default();
        let first_bad = params.iter().position(|p| !p.is_finite());
        let any_valid = (0..grid.cell_count()).any(|c| grid.cell_valid(c));
        match grid.synthesize(&samples, params, &mut pose) {
            Ok(_) => {
                prop_assert!(first_bad.is_none(), "accepted {params:?}");
                prop_assert_eq!(pose.len(), segments);
                for (p, q) in pose.positions().iter().zip(pose.rotations()) {
                    prop_assert!(p.is_finite(), "position {p}");
                    prop_assert!(unit(*q, 1e-4), "rotation {q} |q|² = {}", q.dot(*q));
                }
            }
            Err(GridError::NonFinite { axis }) => {
                prop_assert_eq!(Some(usize::from(axis)), first_bad);
            }
            Err(GridError::NoValidCell) => {
                prop_assert!(first_bad.is_none() && !any_valid);
            }
            Err(e) => prop_assert!(false, "unexpected {e:?} for {params:?}"),
        }
    }
}

// ------------------------------------------------------------------ solver

/// Goals built with the public constructors (which normalize a plane's
/// normal, as `Target::Plane` requires) from arbitrary values.
fn goal() -> impl Strategy<Value = Goal> {
    // Mostly sensible values, so that most problems are solved rather than
    // refused; one part in nine anything at all.
    let v3 = || prop_oneof![8 => prop::array::uniform3(-2.0f32..2.0).prop_map(Vec3::from_array), 1 => wild3()];
    let kind = prop_oneof![
        3 => v3().prop_map(|t| (0u8, t, 0.0, Quat::IDENTITY)),
        1 => (v3(), wild(), any::<bool>()).prop_map(|(n, o, above)| (1 + u8::from(above), n, o, Quat::IDENTITY)),
        1 => prop_oneof![
            4 => unit_quat(),
            1 => prop::array::uniform4(wild()).prop_map(|[x, y, z, w]| Quat::from_xyzw(x, y, z, w)),
        ].prop_map(|q| (3, Vec3::ZERO, 0.0, q)),
    ];
    (
        prop_oneof![12 => 0u8..13, 1 => any::<u8>()],
        prop_oneof![3 => Just(None), 1 => v3().prop_map(Some)],
        kind,
        prop_oneof![6 => Just(None), 1 => (0u8..13).prop_map(Some), 1 => any::<u8>().prop_map(Some)],
        prop_oneof![6 => 0.1f32..100.0, 1 => wild()],
    )
        .prop_map(|(segment, point, (kind, v, offset, q), frame, weight)| {
            let mut g = match kind {
                0 => Goal::reach(segment, v, weight),
                1 => Goal::plane(segment, v, offset, PlaneSide::Contact, weight),
                2 => Goal::plane(segment, v, offset, PlaneSide::Above, weight),
                _ => Goal::orient(segment, q, weight),
            };
            if let Some(p) = point {
                g = g.at(p);
            }
            if let Some(f) = frame {
                g = g.in_frame(f);
            }
            g
        })
}

/// Every coordinate of a goal's target and attached point within
/// ±`solve::GOAL_LIMIT`, and its weight at most 1e6 (the documented domain;
/// false for NaN).
fn bounded(g: &Goal) -> bool {
    let ok = |v: &[f32]| v.iter().all(|x| x.abs() <= solve::GOAL_LIMIT);
    let target = match g.target {
        Target::Position(p) => ok(&p.to_array()),
        Target::Plane { normal, offset, .. } => ok(&normal.to_array()) && ok(&[offset]),
        Target::Orientation(q) => ok(&q.to_array()),
    };
    target && !matches!(g.attach, Attach::Point(p) if !ok(&p.to_array())) && g.weight <= 1.0e6
}

/// Angles at fraction `u` of each DOF's range.
fn within_limits(body: &Body<'_>, start: &Angles<MAX_SEGMENTS>, u: &[f32]) -> Angles<MAX_SEGMENTS> {
    let mut a = *start;
    for (i, s) in body.segments.iter().enumerate().skip(1) {
        for (k, d) in s.joint.dofs().iter().enumerate() {
            let t = u[(i * 3 + k) % u.len()];
            a.values[i][k] = d.min + t * (d.max - d.min);
        }
    }
    a
}

const METHODS: [Method; 4] = [Method::TreeDls, Method::Dls, Method::Ccd, Method::Greedy];

proptest! {
    #![proptest_config(ProptestConfig { failure_persistence: None, ..ProptestConfig::with_cases(256) })]

    /// Whatever the goals (any segment index, target, point, frame and
    /// weight, NaN and infinities included) and whatever start within the
    /// limits, every method keeps every angle within its limits and the
    /// angles and pose finite; a missing segment, a NaN weight or an active
    /// goal beyond the documented limits is a typed error.
    #[test]
    fn the_solver_keeps_joint_limits_and_never_returns_nan(
        which in 0usize..2,
        goals in prop::collection::vec(goal(), 1..6),
        start in prop::collection::vec(0.0f32..=1.0, 1..96),
        root_float in any::<bool>(),
    ) {
        let rig = rig(which);
        let body = rig.body();
        let rest = rig.rest_angles::<MAX_SEGMENTS>().expect("rest");
        let start = within_limits(&body, &rest, &start);
        let mut set = GoalSet::<8>::new();
        for g in &goals {
            set.push(*g).expect("at most 8");
        }
        // The documented refusals: a goal on a missing segment or frame, with
        // a NaN weight, or active beyond the weight or coordinate limits.
        let bad_goal = goals.iter().any(|g| {
            usize::from(g.segment) >= body.len()
                || matches!(g.frame, Frame::Segment(s) if usize::from(s) >= body.len())
                || g.weight.is_nan()
                || (g.is_active() && !bounded(g))
        });
        for method in METHODS {
            let root = if root_float { RootMode::Float } else { RootMode::Fixed };
            let solver = Solver::DEFAULT.with_method(method).with_root(root);
            let mut angles = start;
            let mut pose = Pose::<MAX_SEGMENTS>::default();
            let result = solve::solve(&solver, &body, &set, &mut angles, &mut pose);
            prop_assert_eq!(angles.limit_excess(&body), 0.0, "{:?}: a joint left its limits", method);
            for v in &angles.values[..angles.count] {
                prop_assert!(v.iter().all(|a| a.is_finite()), "{:?}: angles {:?}", method, v);
            }
            prop_assert!(angles.root_position.is_finite() && angles.root_rotation.is_finite());
            match result {
                Ok(_) => {
                    prop_assert!(!bad_goal, "{:?}: accepted a bad goal", method);
                    for (p, q) in pose.positions().iter().zip(pose.rotations()) {
                        prop_assert!(p.is_finite() && unit(*q, 1e-3), "{:?}: pose {} {}", method, p, q);
                    }
                }
                Err(e) => prop_assert!(bad_goal, "{:?}: {:?} for valid goals", method, e),
            }
        }
    }
}

// ------------------------------------------------------------------- servo

fn calibration() -> impl Strategy<Value = Calibration> {
    (
        -3.0f32..0.0,
        0.01f32..3.0,
        500.0f32..1500.0,
        50.0f32..1000.0,
        -100.0f32..100.0,
        any::<bool>(),
    )
        .prop_map(|(lo, span, p0, pspan, trim, reversed)| Calibration {
            angle_min: lo,
            angle_max: lo + span,
            pulse_min_us: p0,
            pulse_max_us: p0 + pspan,
            trim_us: trim,
            reversed,
        })
}

proptest! {
    #![proptest_config(ProptestConfig { failure_persistence: None, ..ProptestConfig::with_cases(512) })]

    /// Arbitrary joint angles through a calibration and a slew limiter:
    /// every pulse within the calibrated range, every step within the speed
    /// limit, every change of step within the acceleration limit unless the
    /// pulse sits at an end of its range.
    #[test]
    fn servo_outputs_stay_in_range_and_within_their_slew_limits(
        cal in calibration(),
        speed in prop_oneof![3 => 0.1f32..20.0, 1 => wild()],
        accel in prop_oneof![3 => 1.0f32..500.0, 1 => wild()],
        period in prop_oneof![3 => 1e-4f32..0.05, 1 => wild()],
        start in wild(),
        angles in prop::collection::vec(wild(), 1..300),
    ) {
        let limits = StepLimits::from_joint(&cal, speed, accel, period);
        prop_assert!(limits.max_step >= 1 && limits.max_accel >= 1);
        let (lo, hi) = (quarter_us(cal.pulse_low()), quarter_us(cal.pulse_high()));
        let mut slew = Slew::for_channel(&cal, limits, start);
        prop_assert!((lo..=hi).contains(&slew.position()));
        for a in angles {
            let pulse = cal.pulse_us(a);
            prop_assert!(pulse >= cal.pulse_low() && pulse <= cal.pulse_high(), "{a} -> {pulse}");
            let before = (slew.position(), slew.last_step());
            let after = slew.update(quarter_us(pulse));
            prop_assert!((lo..=hi).contains(&after), "{after} outside [{lo}, {hi}]");
            let step = i32::from(after) - i32::from(before.0);
            prop_assert_eq!(step, slew.last_step());
            prop_assert!(step.unsigned_abs() <= u32::from(limits.max_step), "step {step}");
            if after != lo && after != hi {
                prop_assert!(
                    (step - before.1).unsigned_abs() <= u32::from(limits.max_accel),
                    "step {} -> {step}, accel limit {}", before.1, limits.max_accel
                );
            }
        }
    }
}

// --------------------------------------------------------------- fail-safe

/// Sends one message to the performer, checking every update.
fn send(p: &mut Performer<'_, '_>, run: &mut Run, msg: Message) {
    run.feed(p, &perform::encode(&msg).expect("encodes"));
}

/// One thing the host does.
#[derive(Clone, Debug)]
enum Act {
    /// A tracker frame `dt` µs after the previous one.
    Frame(u16, Vec<Sensor>),
    Arm,
    Disarm,
    Weight(u8, f32),
    Dials(Vec<f32>),
    /// The link is quiet for `dt` µs (the board ticks at its frame period).
    Quiet(u16),
}

fn sensor() -> impl Strategy<Value = Sensor> {
    let near = prop::array::uniform3(-0.6f32..1.5);
    (
        prop_oneof![6 => 0u8..3, 1 => any::<u8>()],
        prop_oneof![6 => near, 1 => prop::array::uniform3(wild())],
        prop_oneof![
            6 => unit_quat().prop_map(|q| [q.w, q.x, q.y, q.z]),
            1 => prop::array::uniform4(wild()),
        ],
    )
        .prop_map(|(id, position, rotation)| Sensor {
            id,
            position,
            rotation,
        })
}

fn act() -> impl Strategy<Value = Act> {
    prop_oneof![
        12 => (0u16..3000, prop::collection::vec(sensor(), 0..5)).prop_map(|(dt, s)| Act::Frame(dt, s)),
        1 => Just(Act::Arm),
        1 => Just(Act::Disarm),
        1 => (0u8..10, wild()).prop_map(|(g, w)| Act::Weight(g, w)),
        1 => prop::collection::vec(wild(), 0..7).prop_map(Act::Dials),
        1 => (0u16..u16::MAX).prop_map(Act::Quiet),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { failure_persistence: None, ..ProptestConfig::with_cases(96) })]

    /// The live loop on humanoid16 with a small table: armed, then arbitrary
    /// frames (wild floats are rejected by the wire validation; the rest drive
    /// map, synth, solve and servo), commands, dials and pauses. Every output
    /// stays in range and within one speed-limit step; once the link goes
    /// quiet every servo reaches its rest pulse and stops.
    #[test]
    fn the_fail_safe_always_reaches_rest(acts in prop::collection::vec(act(), 1..40)) {
        let region = Region::parse(fuzz_targets::humanoid16_region());
        let mut solver = SolverState::new();
        let mut p = Performer::new(&region, &mut solver);
        let rig = region.rig.as_ref().expect("rig");
        let mut run = Run::new(&p, rig);
        let mut seq = 0u32;
        let mut time_us = 0u32;
        let mut next = || { seq += 1; seq };
        send(&mut p, &mut run, Message::Command(Command { seq: next(), kind: CommandKind::Arm }));
        prop_assert!(p.armed());
        for a in acts {
            match a {
                Act::Frame(dt, sensors) => {
                    time_us = time_us.wrapping_add(u32::from(dt));
                    run.now = run.now.wrapping_add(u32::from(dt));
                    let mut list = List::<Sensor, MAX_SENSORS>::new();
                    sensors.into_iter().for_each(|s| list.push(s).expect("≤ 16"));
                    let f = TrackerFrame { seq: next(), time_us, sensors: list };
                    send(&mut p, &mut run, Message::TrackerFrame(f));
                }
                Act::Arm | Act::Disarm | Act::Weight(..) => {
                    let kind = match a {
                        Act::Arm => CommandKind::Arm,
                        Act::Disarm => CommandKind::Disarm,
                        Act::Weight(goal, weight) => CommandKind::SetGoalWeight { goal, weight },
                        _ => unreachable!(),
                    };
                    send(&mut p, &mut run, Message::Command(Command { seq: next(), kind }));
                }
                Act::Dials(v) => {
                    let values = List::from_slice(&v).expect("≤ 6");
                    send(&mut p, &mut run, Message::Params(Params { seq: next(), values }));
                }
                Act::Quiet(dt) => {
                    let period = p.frame_period_us().max(1);
                    for _ in 0..u32::from(dt) / period {
                        run.tick(&mut p, period);
                    }
                }
            }
        }
        run.finish(&mut p);
        prop_assert!(p.resting());
    }
}
