//! # bench: instruction counts on the emulated Cortex-M4F
//!
//! Times named regions with SysTick under `-icount shift=7,align=off` (see
//! `marionette_firmware::icount`) and prints one line per row over semihosting:
//!
//! ```text
//! row <name> <baseline|-> <calls> <ticks>
//! ```
//!
//! `marionette icount` builds this binary, runs it on QEMU and prints the rows
//! as a table of instructions per call with the ratio against each row's
//! baseline, measured in the same run. Run it with
//! `cargo run --release -p marionette-host -- icount` from the repository root.
#![no_std]
#![no_main]

use core::hint::black_box;
use cortex_m_rt::entry;
use glam::Quat;
use glam::Vec3;
use marionette_core::body::{Angles, cmu};
use marionette_core::frame::{Cycles, Region, stage};
use marionette_core::goal::{Goal, GoalSet, Target};
use marionette_core::grid::{Axis, Grid, Query, SliceSamples};
use marionette_core::math;
use marionette_core::output::ServoOutput;
use marionette_core::output::serial::{Serial, UartServos};
use marionette_core::pose::{LocalPose, Pose};
use marionette_core::region::{EntryKind, directory};
use marionette_core::rig::{FeetechSeries, Output, ServoDesc};
use marionette_core::solve::{self, Method, Solver, SolverState};
use marionette_core::wire::{
    self, Command, CommandKind, CompactFrame, List, MAX_FRAME, Message, Sensor, TrackerFrame,
};
use marionette_firmware::app::{self, BoardPerformer};
use marionette_firmware::board::qemu::{CmsdkUart, UART1_BASE, exit};
use marionette_firmware::console::Line;
use marionette_firmware::icount::Counter;
use marionette_firmware::{region, stack};

/// Number of quaternion pairs each slerp row is measured over.
const PAIRS: usize = 64;

/// A small deterministic generator for bench inputs (not part of any result).
struct Lcg(u32);

impl Lcg {
    fn unit(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (self.0 >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0
    }

    fn quat(&mut self) -> Quat {
        let q = Quat::from_xyzw(self.unit(), self.unit(), self.unit(), self.unit());
        math::normalize_quat(q)
    }
}

fn report(name: &str, baseline: &str, calls: usize, ticks: u32) {
    Line::new()
        .str("row ")
        .str(name)
        .str(" ")
        .str(baseline)
        .str(" ")
        .u32(calls as u32)
        .str(" ")
        .u32(ticks)
        .print();
}

fn slerp_rows(counter: &mut Counter) {
    let mut rng = Lcg(0x1234_5678);
    let mut a = [Quat::IDENTITY; PAIRS];
    let mut b = [Quat::IDENTITY; PAIRS];
    let mut t = [0.0f32; PAIRS];
    for ((a, b), t) in a.iter_mut().zip(b.iter_mut()).zip(t.iter_mut()) {
        *a = rng.quat();
        *b = rng.quat();
        *t = rng.unit() * 0.5 + 0.5;
    }
    let (a, b, t) = (black_box(a), black_box(b), black_box(t));
    let glam_ticks = counter.ticks(|| {
        let mut acc = Quat::IDENTITY;
        for ((a, b), t) in a.iter().zip(b.iter()).zip(t.iter()) {
            acc = black_box(a.slerp(*b, *t));
        }
        acc
    });
    report("slerp.glam", "-", PAIRS, glam_ticks);
    let core_ticks = counter.ticks(|| {
        let mut acc = Quat::IDENTITY;
        for ((a, b), t) in a.iter().zip(b.iter()).zip(t.iter()) {
            acc = black_box(math::slerp(*a, *b, *t));
        }
        acc
    });
    report("slerp.core", "slerp.glam", PAIRS, core_ticks);
}

/// Segments in the synthesis rows: the CMU skeleton.
const SEGMENTS: usize = 31;
/// Samples of a trilinear window.
const WINDOW: usize = 8;

/// The trilinear tree of the baseline: glam's `Quat::slerp` (libm `sin`) and
/// lerp, on the same window and coefficients.
fn glam_tree(p: &[Vec3; WINDOW], q: &[Quat; WINDOW], u: [f32; 3]) -> (Vec3, Quat) {
    let [ux, uy, uz] = u;
    let px = [
        p[0].lerp(p[1], ux),
        p[2].lerp(p[3], ux),
        p[4].lerp(p[5], ux),
        p[6].lerp(p[7], ux),
    ];
    let qx = [
        q[0].slerp(q[1], ux),
        q[2].slerp(q[3], ux),
        q[4].slerp(q[5], ux),
        q[6].slerp(q[7], ux),
    ];
    let py = [px[0].lerp(px[1], uy), px[2].lerp(px[3], uy)];
    let qy = [qx[0].slerp(qx[1], uy), qx[2].slerp(qx[3], uy)];
    (py[0].lerp(py[1], uz), qy[0].slerp(qy[1], uz))
}

/// A 31-segment pose on a 2×2×2 grid: the core's query + interpolation tree
/// against glam's slerp through the same tree.
fn synth_rows(counter: &mut Counter) {
    let mut rng = Lcg(0x0BAD_5EED);
    let mut positions = [Vec3::ZERO; WINDOW * SEGMENTS];
    let mut rotations = [Quat::IDENTITY; WINDOW * SEGMENTS];
    for (p, q) in positions.iter_mut().zip(rotations.iter_mut()) {
        *p = Vec3::new(rng.unit(), rng.unit(), rng.unit());
        *q = rng.quat();
    }
    let axes = [Axis::linear(0.0, 1.0, 2); 3];
    let (Ok(grid), Some(samples)) = (
        Grid::new(&axes, None),
        SliceSamples::new(SEGMENTS, &positions, &rotations),
    ) else {
        exit(4)
    };
    let params = black_box([0.3f32, 0.6, 0.8]);
    let mut query = Query::default();
    let mut pose = Pose::<SEGMENTS>::default();
    let core_ticks = counter.ticks(|| {
        let ok =
            grid.query_into(&params, &mut query).is_ok() && query.pose(&samples, &mut pose).is_ok();
        black_box(&pose);
        ok
    });
    let glam_ticks = counter.ticks(|| {
        // The baseline finds the cell by division too (step 1, origin 0).
        let u = params.map(|x| x - math::floor(x));
        for s in 0..SEGMENTS {
            let p: [Vec3; WINDOW] = core::array::from_fn(|k| {
                positions.get(k * SEGMENTS + s).copied().unwrap_or_default()
            });
            let q: [Quat; WINDOW] = core::array::from_fn(|k| {
                rotations.get(k * SEGMENTS + s).copied().unwrap_or_default()
            });
            let (pp, qq) = glam_tree(&p, &q, u);
            if let (Some(a), Some(b)) = (pose.positions.get_mut(s), pose.rotations.get_mut(s)) {
                *a = pp;
                *b = qq;
            }
        }
        black_box(&pose);
    });
    report("synth.trilinear31.glam", "-", 1, glam_ticks);
    report(
        "synth.trilinear31.core",
        "synth.trilinear31.glam",
        1,
        core_ticks,
    );
    table_row(counter);
}

/// The live loop's synthesis without its joint-angle conversion: a fresh
/// query (as the loop makes one per frame) and the pose of the table
/// region's 16 segments, decoded in place from the quantized blob, inside a
/// cell of its 5×5×5 grid.
fn table_row(counter: &mut Counter) {
    let region = Region::parse(region::tables());
    let Some((table, Ok(grid))) = region.table.as_ref().map(|t| (t, t.grid())) else {
        Line::new()
            .str("synth: no table in the table region")
            .print();
        return;
    };
    let params = black_box([0.05f32, 0.1, 0.17]);
    let mut pose = Pose::<16>::default();
    let ticks = counter.ticks(|| {
        let Ok(query) = grid.query(&params) else {
            return false;
        };
        let ok = query.pose(table, &mut pose).is_ok();
        black_box(&pose);
        ok
    });
    report("synth.table16.core", "-", 1, ticks);
}

/// The CMU skeleton reaching with both hands and feet: goals are the touch
/// points of a perturbed pose, the start ("synthesized") is that pose perturbed
/// by up to ±0.1 rad per joint; then the goals move by up to 2 cm and the solve
/// warm-starts from the previous solution.
///
/// The cold row is [`solve::solve`] (its working state built afresh). The warm
/// row is the next frame of a live loop: [`solve::solve_with`] with the
/// [`SolverState`] that the previous frame's solve left (that solve, the cold
/// one repeated with the state, is not counted; its result is bit-identical).
fn solve_rows(counter: &mut Counter) {
    let body = cmu::BODY;
    let mut rng = Lcg(0x501E_5EED);
    let Ok(mut target) = Angles::<SEGMENTS>::rest(&body) else {
        exit(5)
    };
    for v in target.values.iter_mut().flat_map(|v| v.iter_mut()) {
        *v = rng.unit() * 0.3;
    }
    target.clamp_to_limits(&body);
    let mut local = LocalPose::<SEGMENTS>::default();
    let mut pose = Pose::<SEGMENTS>::default();
    if target.forward(&body, &mut local, &mut pose).is_err() {
        exit(6)
    }
    let mut goals = GoalSet::<4>::new();
    for name in ["LeftHand", "RightHand", "LeftFoot", "RightFoot"] {
        let Some(seg) = body.find(name) else { exit(7) };
        let touch = Goal::reach(seg, Vec3::ZERO, 1.0)
            .world_point(&body, &pose)
            .unwrap_or_default();
        let _ = goals.push(Goal::reach(seg, touch, 1.0));
    }
    let mut start = target;
    for v in start.values.iter_mut().flat_map(|v| v.iter_mut()) {
        *v += rng.unit() * 0.1;
    }
    start.clamp_to_limits(&body);
    let rows = [
        (
            Method::Greedy,
            ["solve.cmu4.cold.greedy", "solve.cmu4.warm.greedy"],
            ["-", "-"],
        ),
        (
            Method::TreeDls,
            ["solve.cmu4.cold.treedls", "solve.cmu4.warm.treedls"],
            ["solve.cmu4.cold.greedy", "solve.cmu4.warm.greedy"],
        ),
    ];
    for (method, [cold_name, warm_name], [cold_base, warm_base]) in rows {
        let solver = Solver::DEFAULT.with_method(method);
        let mut angles = start;
        let cold =
            counter.ticks(|| solve::solve(&solver, &body, &goals, &mut angles, &mut pose).is_ok());
        // The previous frame, solved with the state the live loop keeps.
        let mut state = SolverState::new();
        angles = start;
        let _ = solve::solve_with(&solver, &body, &goals, &mut angles, &mut pose, &mut state);
        let mut moved = goals;
        for g in moved.as_mut_slice() {
            if let Target::Position(p) = &mut g.target {
                *p += Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 0.0115;
            }
        }
        let warm = counter.ticks(|| {
            solve::solve_with(&solver, &body, &moved, &mut angles, &mut pose, &mut state).is_ok()
        });
        report(cold_name, cold_base, 1, cold);
        report(warm_name, warm_base, 1, warm);
        if method == Method::TreeDls {
            let at1k = warm1k_row(counter, &solver, &moved, &mut angles, &mut state, &mut rng);
            for (name, predict) in [(TRACK1K, false), (TRACK1K_PREDICT, true)] {
                track_row(counter, (name, &solver, predict), &at1k, &angles);
            }
        }
    }
}

/// The next frame of the live loop at its real rate: at 1 kHz a hand moving
/// at 2 m/s moves at most 2 mm per frame. The goals move by up to 1.15 mm
/// per axis (≤ 2 mm) from the warm row's solution, solved with its state.
/// Prints `met <row> <goals met within the tolerance> <goals>` after the
/// row; returns the goals.
fn warm1k_row(
    counter: &mut Counter,
    solver: &Solver,
    previous: &GoalSet<4>,
    angles: &mut Angles<SEGMENTS>,
    state: &mut SolverState<SEGMENTS>,
    rng: &mut Lcg,
) -> GoalSet<4> {
    let body = cmu::BODY;
    let mut pose = Pose::<SEGMENTS>::default();
    let mut moved = *previous;
    for g in moved.as_mut_slice() {
        if let Target::Position(p) = &mut g.target {
            *p += Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 0.001_15;
        }
    }
    let mut result = None;
    let ticks = counter.ticks(|| {
        result = solve::solve_with(solver, &body, &moved, angles, &mut pose, state).ok();
    });
    const NAME: &str = "solve.cmu4.warm1k.treedls";
    report(NAME, "-", 1, ticks);
    let met = result.map_or(0, |r| {
        r.residuals
            .iter()
            .filter(|&&x| x <= solver.tolerance)
            .count()
    });
    Line::new()
        .str("met ")
        .str(NAME)
        .str(" ")
        .u32(met as u32)
        .str(" ")
        .u32(moved.as_slice().len() as u32)
        .print();
    moved
}

/// A tracking loop at 1 kHz fed its own solutions: each frame solves from
/// the last frame's solution.
const TRACK1K: &str = "solve.cmu4.track1k.treedls";
/// The same loop starting each frame from the last two solutions
/// extrapolated at constant velocity (`2·θₜ − θₜ₋₁`, clamped into the
/// limits), the prediction counted in the row.
const TRACK1K_PREDICT: &str = "solve.cmu4.track1k.predict";
/// Frames of the tracking rows.
const TRACK_FRAMES: u32 = 40;

/// The row `name`: [`TRACK_FRAMES`] frames of a tracking loop at 1 kHz
/// from `start` with a new state, the goals circling about `goals` at
/// 1.5 m/s (2 cm radius at 75 rad/s, phases a quarter turn apart), each
/// solved from the last frame's solution (`predict`: extrapolated); a first
/// frame, not counted, solves onto the circles. Prints `met <row> <frames
/// with every goal met> <frames>` after the row.
fn track_row(
    counter: &mut Counter,
    (name, solver, predict): (&str, &Solver, bool),
    goals: &GoalSet<4>,
    start: &Angles<SEGMENTS>,
) {
    let body = cmu::BODY;
    let mut pose = Pose::<SEGMENTS>::default();
    let mut state = SolverState::<SEGMENTS>::new();
    let (mut angles, mut last) = (*start, *start);
    let (mut ticks, mut met) = (0u32, 0u32);
    for frame in 0..=TRACK_FRAMES {
        let mut moved = *goals;
        for (k, g) in moved.as_mut_slice().iter_mut().enumerate() {
            if let Target::Position(p) = &mut g.target {
                let a = 0.075 * frame as f32 + 1.57 * k as f32;
                *p += Vec3::new(math::cos(a) - 1.0, math::sin(a), 0.0) * 0.02;
            }
        }
        let (solved, mut result) = (angles, None);
        let t = counter.ticks(|| {
            if predict && frame > 1 {
                for (v, p) in angles.values.iter_mut().zip(&last.values) {
                    for (x, y) in v.iter_mut().zip(p) {
                        *x += *x - *y;
                    }
                }
                angles.clamp_to_limits(&body);
            }
            result =
                solve::solve_with(solver, &body, &moved, &mut angles, &mut pose, &mut state).ok();
        });
        last = solved;
        if frame > 0 {
            ticks = ticks.saturating_add(t);
            let all = result.is_some_and(|r| r.residuals.iter().all(|&x| x <= solver.tolerance));
            met += u32::from(all);
        }
    }
    report(name, "-", TRACK_FRAMES as usize, ticks);
    Line::new()
        .str("met ")
        .str(name)
        .str(" ")
        .u32(met)
        .str(" ")
        .u32(TRACK_FRAMES)
        .print();
}

/// Tracker frames in the per-frame rows (the first, cold one is not counted).
const FRAMES: u32 = 40;

/// SysTick as an up-counter for the core's stage counts (the same 25 MHz
/// ticks as [`Counter`]).
struct SysTickCycles;

impl Cycles for SysTickCycles {
    fn now(&mut self) -> u32 {
        0x00FF_FFFF - cortex_m::peripheral::SYST::get_current()
    }
}

/// Feeds one encoded message to the performer.
fn feed(performer: &mut BoardPerformer<'_, '_>, msg: &Message, now_us: u32) {
    let mut buf = [0u8; MAX_FRAME];
    if let Ok(frame) = wire::encode(msg, &mut buf) {
        let mut input: &[u8] = frame;
        while !input.is_empty() {
            let _ = performer.receive(&mut input, now_us, &mut SysTickCycles);
        }
    }
}

/// A tracker frame, compact (as hosts send them by default): the right
/// hand circling, left hand and pelvis still.
fn tracker_frame(i: u32) -> Message {
    let a = i as f32 * 0.05;
    let sensor = |id, position| Sensor {
        id,
        position,
        rotation: [1.0, 0.0, 0.0, 0.0],
    };
    let mut sensors = List::new();
    let _ = sensors.push(sensor(
        0,
        [-0.3 + 0.1 * math::cos(a), 0.25 + 0.1 * math::sin(a), 0.3],
    ));
    let _ = sensors.push(sensor(1, [0.3, -0.2, 0.1]));
    let _ = sensors.push(sensor(2, [0.0, 0.0, 0.0]));
    let frame = TrackerFrame {
        seq: i + 1,
        time_us: i * 1000,
        sensors,
    };
    match CompactFrame::pack(&frame) {
        Ok(c) => Message::CompactFrame(c),
        Err(_) => Message::TrackerFrame(frame),
    }
}

/// The names of a back-end's rows: sending a frame, and the frame with it.
type Names = (&'static str, &'static str);

/// The servo outputs of the frame rows: each UART back-end on UART1, for the
/// region's servos.
fn uart_outputs(rig_servos: &[ServoDesc]) -> [(Names, UartServos<CmsdkUart>); 3] {
    let on = |output: Output| UartServos {
        uart: CmsdkUart::new(UART1_BASE),
        serial: Serial::for_output(&output, rig_servos).unwrap_or(Serial::None),
    };
    [
        (
            (
                "frame.humanoid16.emit.maestro",
                "frame.humanoid16.total.maestro",
            ),
            on(Output::Maestro { baud: 115_200 }),
        ),
        (
            (
                "frame.humanoid16.emit.dynamixel",
                "frame.humanoid16.total.dynamixel",
            ),
            on(Output::Dynamixel { baud: 1_000_000 }),
        ),
        (
            (
                "frame.humanoid16.emit.feetech",
                "frame.humanoid16.total.feetech",
            ),
            on(Output::Feetech {
                baud: 1_000_000,
                series: FeetechSeries::Sts,
            }),
        ),
    ]
}

/// The whole live loop per tracker frame on the table region's rig
/// (`humanoid16`, 3 parameters, 4 goals), by stage, at the `perform`
/// firmware's capacity: the mean of 39 frames per stage, the worst of
/// them (`frame.humanoid16.worst`, the `total` of one frame) and the first
/// frame after `Arm` (`frame.humanoid16.cold`, not among the 39); then, per
/// UART back-end, sending the frame's targets on UART1 (`emit.*`) and the
/// frame with it (`total.*`).
fn frame_rows(counter: &mut Counter) {
    frame_rows_of(counter, region::tables(), &ROWS_ONE_TABLE);
}

/// The live loop's rows of one region.
struct FrameRows {
    /// Per stage, in the order of [`stage`].
    stages: [(usize, &'static str); 6],
    receive: &'static str,
    worst: &'static str,
    cold: &'static str,
    /// Whether to time the UART back-ends too.
    emit: bool,
}

/// The rows of the table region's rig with one table.
const ROWS_ONE_TABLE: FrameRows = FrameRows {
    stages: [
        (stage::DECODE, "frame.humanoid16.decode"),
        (stage::MAP, "frame.humanoid16.map"),
        (stage::SYNTH, "frame.humanoid16.synth"),
        (stage::SOLVE, "frame.humanoid16.solve"),
        (stage::SERVO, "frame.humanoid16.servo"),
        (stage::TOTAL, "frame.humanoid16.total"),
    ],
    receive: "frame.humanoid16.receive",
    worst: "frame.humanoid16.worst",
    cold: "frame.humanoid16.cold",
    emit: true,
};

/// The rows of the same rig with two layers (the region nested in the
/// table region: a walk clip table on the legs, the grid on the arms).
const ROWS_TWO_LAYERS: FrameRows = FrameRows {
    stages: [
        (stage::DECODE, "frame.humanoid16.layers2.decode"),
        (stage::MAP, "frame.humanoid16.layers2.map"),
        (stage::SYNTH, "frame.humanoid16.layers2.synth"),
        (stage::SOLVE, "frame.humanoid16.layers2.solve"),
        (stage::SERVO, "frame.humanoid16.layers2.servo"),
        (stage::TOTAL, "frame.humanoid16.layers2.total"),
    ],
    receive: "frame.humanoid16.layers2.receive",
    worst: "frame.humanoid16.layers2.worst",
    cold: "frame.humanoid16.layers2.cold",
    emit: false,
};

/// [`frame_rows`] with two layers, if the table region nests a layered
/// region ([`EntryKind::NESTED`]).
fn layer_rows(counter: &mut Counter) {
    let nested = directory(region::tables())
        .ok()
        .and_then(|d| d.find(EntryKind::NESTED, 0));
    match nested {
        Some(e) => frame_rows_of(counter, e.bytes, &ROWS_TWO_LAYERS),
        None => Line::new().str("frame: no layered region").print(),
    }
}

/// The frame rows of the region `bytes`, named by `rows`.
fn frame_rows_of(counter: &mut Counter, bytes: &[u8], rows: &FrameRows) {
    let region = Region::<{ app::SEGMENTS }>::parse_sized(bytes);
    let mut solver = SolverState::new();
    let mut performer = BoardPerformer::new(&region, &mut solver);
    if performer.pipeline().is_none() {
        Line::new().str("frame: no rig in the table region").print();
        return;
    }
    let servos = region.rig.as_ref().map_or(&[][..], |r| r.servos());
    let mut all_outputs = uart_outputs(servos);
    let used = if rows.emit { all_outputs.len() } else { 0 };
    let outputs = all_outputs.get_mut(..used).unwrap_or(&mut []);
    feed(
        &mut performer,
        &Message::Command(Command {
            seq: 0,
            kind: CommandKind::Arm,
        }),
        0,
    );
    // The first frame after Arm (the cold solve) is not timed by `counter`
    // (SysTick is not cleared before it); its stage counts are taken modulo
    // SysTick's 24 bits.
    feed(&mut performer, &tracker_frame(0), 0);
    let cold = performer.stages().get(stage::TOTAL).copied().unwrap_or(0) & 0x00FF_FFFF;
    // The first write switches the bus servos' torque on: not a steady frame.
    for (_, out) in outputs.iter_mut() {
        let _ = out.write(performer.targets());
    }
    let mut sums = [0u32; 6];
    let mut emits = [0u32; 3];
    let mut outer = 0u32;
    let mut worst = 0u32;
    for i in 1..FRAMES {
        let msg = tracker_frame(i);
        outer = outer.saturating_add(counter.ticks(|| feed(&mut performer, &msg, i * 1000)));
        for (sum, s) in sums.iter_mut().zip(performer.stages()) {
            *sum = sum.saturating_add(s);
        }
        worst = worst.max(performer.stages().get(stage::TOTAL).copied().unwrap_or(0));
        let targets = performer.targets();
        for (sum, (_, out)) in emits.iter_mut().zip(outputs.iter_mut()) {
            *sum = sum.saturating_add(counter.ticks(|| out.write(black_box(targets)).is_ok()));
        }
    }
    let n = (FRAMES - 1) as usize;
    for (index, name) in rows.stages {
        report(name, "-", n, sums.get(index).copied().unwrap_or(0));
    }
    report(rows.receive, "-", n, outer);
    let total = sums.get(stage::TOTAL).copied().unwrap_or(0);
    for (((emit_name, total_name), _), emit) in outputs.iter().zip(emits) {
        report(emit_name, "-", n, emit);
        report(total_name, "-", n, total.saturating_add(emit));
    }
    report(rows.worst, "-", 1, worst);
    report(rows.cold, "-", 1, cold);
    Line::new()
        .str("frame armed ")
        .u32(u32::from(performer.armed()))
        .print();
}

#[entry]
fn main() -> ! {
    stack::paint();
    let Some(peripherals) = cortex_m::Peripherals::take() else {
        exit(3)
    };
    let mut counter = Counter::new(peripherals.SYST);
    Line::new().str("overhead ").u32(counter.overhead()).print();
    slerp_rows(&mut counter);
    synth_rows(&mut counter);
    solve_rows(&mut counter);
    frame_rows(&mut counter);
    layer_rows(&mut counter);
    Line::new()
        .str("stack ")
        .u32(stack::high_water() as u32)
        .print();
    Line::new().str("end").print();
    exit(0)
}
