//! One step of the live loop: a validated tracker frame in, servo targets out.
//!
//! [`Pipeline`] is the per-frame work of a puppet (map, synthesize, solve,
//! servo), shared by the firmware and the host's `marionette sim` through
//! [`Performer`], which owns the protocol (hello,
//! arm, disarm, status, fail-safe) and calls the pipeline once per accepted
//! frame. Given the same frames and the same clock readings, host and board
//! produce bit-identical servo targets.
//!
//! ## One tracker frame
//!
//! ```text
//! ValidTrackerFrame ─▶ map   rig sensor map → parameters + weighted goals
//!                    ▶ synth grid query on the table blob, read in place
//!                    ▶ solve synthesized pose + last frame's correction
//!                    ▶ servo joint angle → calibrated pulse → slew limit
//! ```
//!
//! - **map**: [`Rig::map_sensors`] after boresight correction; `Params`
//!   messages (dials) override parameters `0..k`, and `SetGoalWeight`
//!   overrides goal weights.
//! - **synth**: the table's grid is queried at the parameters (clamped or
//!   projected into the valid cells, as the grid module documents) and the
//!   pose of every segment is interpolated from the flash-resident samples.
//! - **solve**: the synthesized pose is projected onto the joints' degrees of
//!   freedom; on the joints the active goals hang from, the previous frame's
//!   correction (solved minus synthesized) is added back, so the solver
//!   starts where it left those goals a frame ago, moved by how the
//!   synthesis moved; then the goals are solved ([`Solver::DEFAULT`]). The
//!   solver keeps its [`SolverState`] from frame to frame (the reach tree
//!   and joint layout are rebuilt only when the active goals change) and
//!   never leaves a joint limit. It works within a budget per frame
//!   ([`crate::deadline`]): what it cannot finish in one frame, the
//!   correction carries into the next. A frame whose budget does not cover
//!   a solve's fixed part does not solve: it drives the start (synthesized
//!   plus correction) and keeps the correction; the world pose
//!   ([`Pipeline::pose`]) and the residuals are then the last solve's.
//! - **servo**: each servo follows one joint angle through its calibration
//!   and a [`Slew`] limiter, so no pulse leaves its calibrated range or moves
//!   faster than the servo's speed and acceleration limits.
//!
//! ## Layers
//!
//! A region with a layer list ([`crate::layer`]) replaces the synth stage
//! by the layers: each frame every layer takes its parameters from its
//! sources (rig parameters after the dials, constants, ramps over the time
//! performed), moves its effective weight towards its weight source by at
//! most `dt / fade_s` (the cross-fade), synthesizes its table (a grid query,
//! or a clip table at its playhead, advanced by `dt` over the cycle duration
//! interpolated at the parameters), and is blended over the rest pose in
//! list order, per segment by its mask, in joint-local space. Solve and
//! servo follow as for one table. The layers start over (phase 0, time 0,
//! weights at their sources without a fade) whenever the loop disarms or
//! the fail-safe trips, like the solver's correction.
//!
//! ## Time
//!
//! One output step is made per performed tracker frame. The slew limits of a
//! step are those of `dt = min(Δt_tracker, frame period)`, where `Δt_tracker`
//! is the difference of the frames' own timestamps: a tracker faster than the
//! rig's frame rate cannot make a servo faster than its limit, and a slow one
//! only makes it slower. Wrapping timestamps are handled; a timestamp that
//! goes backwards counts as `dt = 0` (the smallest step the limiter allows).
//! [`Pipeline::ease_to_rest`] makes one step towards every servo's rest
//! pulse at the frame period, within the same limits.
//!
//! ## Idle
//!
//! Once every servo is at rest after a disarm or a fail-safe trip, a rig
//! whose idle policy is `Off` ([`crate::rig::Idle`]) releases the outputs
//! with one more update whose targets are all 0 ("no pulse"; a bus servo's
//! torque off); `Hold` keeps the rest targets. Outputs are never released
//! before the first armed frame, and the next armed frame drives them again
//! from rest ([`Pipeline::rest_step`]).
//!
//! ## Calibration jog
//!
//! While disarmed, [`Pipeline::jog`] holds one servo at a target of the
//! caller's instead of its rest pulse (`marionette calibrate` finds a
//! servo's limits so; the wire's `Jog` command). The jogged channel moves
//! through its own [`Slew`] limiter, the one the performance uses, stepping
//! with [`Pipeline::rest_step`] at the frame period: it never leaves the
//! channel's calibrated range (a target beyond it stops at its end) and
//! never moves faster than the servo's speed and acceleration limits.
//! Ending a jog ([`Pipeline::end_jog`], or a target of 0) eases the channel
//! back to rest, after which it is the loop's again. A jog counts as
//! driving the outputs: afterwards the idle policy `Off` releases them.
//!
//! ## Capacity
//!
//! [`Region`], [`Pipeline`] and the [`SolverState`] the caller lends the
//! pipeline hold the rig, poses, joint angles and the solver's working
//! state for at most `N` segments, a const parameter (default
//! [`MAX_SEGMENTS`], the rig format's limit). A firmware picks the smallest
//! that fits its rigs (the firmware's 24 holds the shipped puppet
//! `humanoid16`, 13 segments, with room): RAM and per-frame copies scale
//! with it. It parses its region in place (a rig is kilobytes, and every
//! move of one is a copy on the stack) and runs the loop on it:
//!
//! ```text
//! let mut region = Region::<24>::EMPTY;
//! region.parse_into(flash_bytes);
//! let mut solver = SolverState::<24>::new(); // most of the loop's memory
//! let mut performer = Performer::new(&region, &mut solver); // Performer<'_, '_, 24>
//! ```
//!
//! A rig with more segments than `N` is refused as
//! [`RigTooLarge`](crate::wire::StatusReason::RigTooLarge), like a missing rig: nothing is driven.

use crate::body::{Angles, Body};
use crate::clip::Clips;
use crate::deadline::{self, Budget, Received, Synthesis};
use crate::goal::GoalSet;
use crate::grid::{Adjust, Grid, Query};
use crate::layer::{self, Layers, MAX_LAYERS, Playhead, Root};
pub use crate::perform::{Cause, Performer, Update};
use crate::pose::{self, LocalPose, MAX_SEGMENTS, Pose};
pub use crate::region::Region;
use crate::rig::{Idle, MAX_PARAMS, Rig};
use crate::servo::{Slew, quarter_us};
use crate::show::{Cursor as ShowCursor, Show};
use crate::solve::{self, SolveError, Solver, SolverState};
use crate::table::{Kind, Table};
use crate::wire::{List, MAX_GOALS, MAX_SENSORS, MAX_SERVOS, STAGES, Sensor, ValidTrackerFrame};
use glam::Quat;

/// The live loop's solver. A constant, so that a firmware links only the
/// method it runs ([`Solver::DEFAULT`]'s whole-tree DLS), not the balancing
/// solvers the host compares it with.
const SOLVER: Solver = Solver::DEFAULT;

/// Stage indices in [`Telemetry::stage_counts`](crate::wire::Telemetry::stage_counts).
pub mod stage {
    /// Receiving and decoding the frame.
    pub const DECODE: usize = 0;
    /// Sensor map.
    pub const MAP: usize = 1;
    /// Synthesis from the tables.
    pub const SYNTH: usize = 2;
    /// Goal solving.
    pub const SOLVE: usize = 3;
    /// Servo mapping and slew limits.
    pub const SERVO: usize = 4;
    /// The whole frame.
    pub const TOTAL: usize = 5;
}

/// Reads a free-running cycle (or instruction) counter for the stage
/// counts and frame timing; the host passes one that reads zero.
pub trait Cycles {
    /// The counter now; differences are taken with wrapping arithmetic.
    fn now(&mut self) -> u32;

    /// Counts per second (0: no counter, [`NoCycles`]). The frame period
    /// in counts is the budget a frame overruns.
    fn hz(&self) -> u32 {
        0
    }
}

/// A [`Cycles`] that always reads zero.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoCycles;

impl Cycles for NoCycles {
    #[inline]
    fn now(&mut self) -> u32 {
        0
    }
}

/// The solver's correction of the last frame: solved minus synthesized
/// angles, root shift and turn.
///
/// Live, the solver starts from this frame's synthesized pose **plus the
/// last frame's correction** on the joints the active goals hang from (their
/// paths to the root, and the root itself); every other joint starts, and
/// stays, as synthesized. So the start keeps the table's style and is already
/// where the solver left the goals a frame ago, moved only by how the
/// synthesis moved: a warm start from the previous frame's solution that
/// never drifts away from the synthesis on joints no goal pulls. The
/// correction is dropped when a solve fails and when the loop disarms or
/// times out.
///
/// One buffer serves both ends of a solve, so no copy of the joint state is
/// made: [`Correction::start`] adds the correction to the synthesized angles
/// and keeps the synthesized ones in its place; [`Correction::finish`] turns
/// them into the new correction, `solved − synthesized`.
#[derive(Clone, Copy, Debug)]
struct Correction<const N: usize> {
    /// Between frames: the correction per joint (while `held`); during a
    /// solve: the synthesized angles.
    values: [[f32; 3]; N],
    /// The root's shift, or during a solve its synthesized position.
    root_shift: glam::Vec3,
    /// The root's turn, or during a solve its synthesized orientation.
    root_turn: Quat,
    /// Whether a correction is held (false: none yet, or dropped).
    held: bool,
}

impl<const N: usize> Correction<N> {
    /// No correction.
    const NONE: Self = Self {
        values: [[0.0; 3]; N],
        root_shift: glam::Vec3::ZERO,
        root_turn: Quat::IDENTITY,
        held: false,
    };

    /// Drops the correction.
    fn clear(&mut self) {
        self.held = false;
    }

    /// Turns the synthesized `angles` into the solver's start: adds the
    /// correction, if one is held, on the joints the active goals hang
    /// from (the solver clamps them into the joint limits; a frame that
    /// does not solve clamps them itself). Keeps the synthesized angles for
    /// [`Correction::finish`].
    fn start(&mut self, body: &Body<'_>, goals: &GoalSet<MAX_GOALS>, angles: &mut Angles<N>) {
        let mut pulled = [false; N];
        if self.held {
            for g in goals.as_slice().iter().filter(|g| g.weight > 0.0) {
                let mut s = usize::from(g.segment);
                while let Some(mark) = pulled.get_mut(s) {
                    if *mark {
                        break;
                    }
                    *mark = true;
                    match body.parents.get(s) {
                        Some(&p) if p != pose::NO_PARENT => s = usize::from(p),
                        _ => break,
                    }
                }
            }
        }
        let any = pulled.contains(&true);
        let n = angles.count.min(N);
        let (Some(values), Some(kept)) = (angles.values.get_mut(..n), self.values.get_mut(..n))
        else {
            return;
        };
        for ((v, c), &p) in values.iter_mut().zip(kept).zip(&pulled) {
            let synth = *v;
            if p {
                let ([v0, v1, v2], [c0, c1, c2]) = (synth, *c);
                *v = [v0 + c0, v1 + c1, v2 + c2];
            }
            *c = synth;
        }
        let (position, rotation) = (angles.root_position, angles.root_rotation);
        if any {
            angles.root_position += self.root_shift;
            angles.root_rotation = crate::math::normalize_quat(self.root_turn * rotation);
        }
        self.root_shift = position;
        self.root_turn = rotation;
    }

    /// After a successful solve from [`Correction::start`]: holds
    /// `solved − synthesized` as the next frame's correction.
    fn finish(&mut self, solved: &Angles<N>) {
        let n = solved.count.min(N);
        let (Some(values), Some(synth)) = (solved.values.get(..n), self.values.get_mut(..n)) else {
            self.held = false;
            return;
        };
        for (c, a) in synth.iter_mut().zip(values) {
            let ([a0, a1, a2], [b0, b1, b2]) = (*a, *c);
            *c = [a0 - b0, a1 - b1, a2 - b2];
        }
        self.root_shift = solved.root_position - self.root_shift;
        self.root_turn = solved.root_rotation * self.root_turn.conjugate();
        self.held = true;
    }
}

/// A calibration jog of one channel (see [Calibration jog](self#calibration-jog)).
#[derive(Clone, Copy, Debug)]
struct Jog {
    channel: u8,
    /// Quarter units; the rest target once the jog is ending.
    target: u16,
    /// Ending: easing back to rest.
    ending: bool,
}

/// One layer's state between frames.
#[derive(Clone, Copy, Debug)]
struct LayerState {
    /// A clip layer's place in its motion.
    playhead: Playhead,
    /// The effective weight, after the cross-fade.
    weight: f32,
    /// Whether a frame has set the weight since the loop started.
    started: bool,
}

impl LayerState {
    const START: Self = Self {
        playhead: Playhead::START,
        weight: 0.0,
        started: false,
    };

    /// Moves the effective weight towards `target` (clamped to `[0, 1]`;
    /// NaN is 0) by at most `dt / fade_s`; the first frame after a start
    /// takes the target at once.
    fn fade_to(&mut self, target: f32, fade_s: f32, dt: f32) {
        let target = if target.is_nan() {
            0.0
        } else {
            crate::math::clamp(target, 0.0, 1.0)
        };
        self.weight = if !self.started || fade_s <= 0.0 {
            target
        } else {
            let step = dt / fade_s;
            crate::math::clamp(target, self.weight - step, self.weight + step)
        };
        self.started = true;
    }
}

/// One layer's pose at `params` into `out`: a grid query (into `query`), or
/// for a clip table the pose at the playhead after advancing it by `dt` (the
/// frame's step times the layer's rate). Returns what
/// the parameter query did, `None` if synthesis failed.
fn layer_pose<const N: usize>(
    table: &Table<'_>,
    params: &[f32],
    state: &mut LayerState,
    dt: f32,
    (query, out): (&mut Query, &mut Pose<N>),
) -> Option<(Adjust, u32)> {
    let grid = table.grid().ok()?;
    match table.kind() {
        Kind::Grid => {
            grid.query_into(params, query).ok()?;
            query.pose(table, out).ok()?;
            Some((query.adjust(), query.work(out.count)))
        }
        Kind::Clips { phases } => {
            let clips = Clips::new(grid, table.param_grid().ok()?, usize::from(phases)).ok()?;
            let motion = clips.motion(table, params).ok()?;
            let phase = state.playhead.advance(&motion, dt);
            clips
                .pose_into(&motion, table, phase, (&mut *query, &mut *out))
                .ok()?;
            let work = motion.work().saturating_add(query.work(out.count));
            Some((motion.adjust(), work))
        }
    }
}

/// What one frame's solve did ([`Pipeline::last_solve`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SolveStats {
    /// Its iterations.
    pub iterations: u32,
    /// Its work by the solver's cost model ([`solve::Report::work`]).
    pub work: u32,
    /// The budget it had ([`deadline`]).
    pub budget: u32,
    /// Whether it stopped on its own (goals met), not on the budget or
    /// the iteration cap.
    pub converged: bool,
}

impl SolveStats {
    /// No solve yet.
    const NONE: Self = Self {
        iterations: 0,
        work: 0,
        budget: 0,
        converged: true,
    };
}

/// The per-frame pipeline of one rig, for at most `N` segments (see the
/// module doc): map, synthesize, solve, servo.
pub struct Pipeline<'r, 'a, const N: usize = MAX_SEGMENTS> {
    rig: &'r Rig<'a, N>,
    table: Option<&'r Table<'a>>,
    grid: Option<Grid<'a>>,
    /// The region's layers and their tables, if it has a layer list.
    layered: Option<(&'r Layers<'a>, &'r [Option<Table<'a>>; MAX_LAYERS])>,
    /// Each layer's playhead and effective weight.
    layer_state: [LayerState; MAX_LAYERS],
    /// Seconds performed since the loop last started ([`Source::Ramp`]).
    layer_time: f32,
    /// The rig's rest pose, joint-local: what the layers blend over.
    rest_local: LocalPose<N>,
    /// One layer's synthesized pose, joint-local.
    layer_local: LocalPose<N>,
    resting: bool,
    /// Whether an armed frame has driven the outputs since boot.
    driven: bool,
    /// Whether the outputs were released at rest (the rig's `Idle::Off`).
    released: bool,
    /// A calibration jog under way.
    jog: Option<Jog>,
    last_tracker_us: Option<u32>,
    params: [f32; MAX_PARAMS],
    dials: List<f32, MAX_PARAMS>,
    weights: [Option<f32>; MAX_GOALS],
    boresight: [Quat; MAX_SENSORS],
    last_sensors: List<Sensor, MAX_SENSORS>,
    goals: GoalSet<MAX_GOALS>,
    angles: Angles<N>,
    warm: Correction<N>,
    synth: Pose<N>,
    /// The grid query of the last frame's synthesis (kept: see
    /// [`Grid::query_into`]).
    query: Query,
    pose: Pose<N>,
    local: LocalPose<N>,
    /// What the solver built for the last frame's goals (reach tree, joint
    /// layout, rotations), reused while the active goals stay the same.
    solver: &'r mut SolverState<N>,
    /// The solver's work per frame ([`deadline`]).
    budget: Budget,
    /// What the last frame's synthesis did (its share of the reserve).
    synthesized: Synthesis,
    /// The work of a synthesis inside the table's valid cells
    /// ([`Grid::plain_work`]), worked out once.
    plain_work: u32,
    /// Frames whose budget said they may run over their period.
    short_frames: u32,
    /// What the last frame brought (its share of the reserve).
    received: Received,
    /// The last frame's solve.
    last_solve: SolveStats,
    slews: [Option<Slew>; MAX_SERVOS],
    /// The step length the slews' limits are set for, seconds.
    step_dt: Option<f32>,
    targets: [u16; MAX_SERVOS],
    channels: usize,
    /// The last solve's report, written in place.
    report: solve::Report<MAX_GOALS>,
    adjusted: u32,
    failed_frames: u32,
}

impl<'r, 'a, const N: usize> Pipeline<'r, 'a, N> {
    /// The pipeline of `region`'s rig (servos assumed at rest), solving with
    /// `solver`'s storage; `None` when the region holds no valid rig.
    ///
    /// The solver's state is most of a pipeline's memory (about 12 kB at 24
    /// segments), so the caller provides it, like a socket buffer in smoltcp:
    /// where it lives is the caller's choice, and the pipeline, returned by
    /// value, stays small enough to move. Never inlined, like
    /// [`Region::parse_into`].
    #[must_use]
    #[inline(never)]
    pub fn new(region: &'r Region<'a, N>, solver: &'r mut SolverState<N>) -> Option<Self> {
        let rig = region.rig.as_ref()?;
        solver.reset();
        let period = rig.frame_period_s();
        let mut slews = [None; MAX_SERVOS];
        let mut targets = [0u16; MAX_SERVOS];
        let mut channels = 0;
        for servo in rig.servos() {
            let ch = usize::from(servo.channel);
            if let (Some(slot), Some(t)) = (slews.get_mut(ch), targets.get_mut(ch)) {
                let slew = Slew::for_channel(
                    &servo.calibration(),
                    servo.step_limits(period),
                    servo.rest_us,
                );
                *t = slew.position();
                *slot = Some(slew);
                channels = channels.max(ch + 1);
            }
        }
        let angles = rig.rest_angles().ok()?;
        let mut rest_local = LocalPose::default();
        pose::to_local(&rig.body().hierarchy(), rig.rest_pose(), &mut rest_local).ok()?;
        let grid = region.table.as_ref().and_then(|t| t.grid().ok());
        let plain_work = match (&grid, region.table.as_ref()) {
            (Some(g), Some(t)) => g.plain_work(t.segment_count()),
            _ => 0,
        };
        Some(Self {
            rig,
            table: region.table.as_ref(),
            grid,
            layered: region.layers.as_ref().map(|l| (l, &region.layer_tables)),
            layer_state: [LayerState::START; MAX_LAYERS],
            layer_time: 0.0,
            rest_local,
            layer_local: LocalPose::default(),
            resting: true,
            driven: false,
            released: false,
            jog: None,
            last_tracker_us: None,
            params: [0.0; MAX_PARAMS],
            dials: List::new(),
            weights: [None; MAX_GOALS],
            boresight: [Quat::IDENTITY; MAX_SENSORS],
            last_sensors: List::new(),
            goals: GoalSet::new(),
            angles,
            warm: Correction::NONE,
            synth: Pose::default(),
            query: Query::default(),
            pose: *rig.rest_pose(),
            local: LocalPose::default(),
            solver,
            budget: Budget::for_rig(rig.frame_period_us(), deadline::CLOCK_HZ, rig.body().len()),
            synthesized: Synthesis {
                work: 0,
                adjusted: false,
            },
            plain_work,
            short_frames: 0,
            received: Received {
                sensors: 0,
                compact: true,
            },
            last_solve: SolveStats::NONE,
            slews,
            step_dt: None,
            targets,
            channels,
            report: solve::Report::EMPTY,
            adjusted: 0,
            failed_frames: 0,
        })
    }

    /// The rig it drives.
    #[must_use]
    pub fn rig(&self) -> &'r Rig<'a, N> {
        self.rig
    }

    /// The solver's work per frame, in the units of
    /// [`Report::work`](solve::Report::work): the rig's frame period on the
    /// board, less the rest of the frame ([`Budget::for_rig`]); each frame
    /// gets [`Budget::get`] of it for what it brought.
    #[must_use]
    pub fn solve_budget(&self) -> Budget {
        self.budget
    }

    /// Sets the solver's work per frame (for example to study the loop at
    /// another budget; the board keeps the one [`Pipeline::new`] sets).
    pub fn set_solve_budget(&mut self, budget: Budget) {
        self.budget = budget;
    }

    /// What the last frame's synthesis did: its counted work (all its
    /// layers') and whether it adjusted the parameters.
    #[must_use]
    pub fn last_synthesis(&self) -> Synthesis {
        self.synthesized
    }

    /// The frames so far whose reserve left the solver less than it needs
    /// ([`Budget::may_overrun`]): on the board they may run over their
    /// period. None on a rig and table that keep it
    /// ([`Pipeline::keeps_period`]), unless the frames bring more sensors
    /// or a projection takes more than the period.
    #[must_use]
    pub fn short_frames(&self) -> u32 {
        self.short_frames
    }

    /// The work of a synthesis from the region's table inside its valid
    /// cells ([`Grid::plain_work`]; 0 without a table). A layered rig's
    /// frames count every layer's ([`Pipeline::last_synthesis`]), which
    /// this does not.
    #[must_use]
    pub fn plain_synthesis_work(&self) -> u32 {
        self.plain_work
    }

    /// Whether the rig's plain frames keep its period with this table when
    /// each brings `received` ([`Budget::keeps_period`]).
    #[must_use]
    pub fn keeps_period(&self, received: Received) -> bool {
        let plain = Synthesis {
            work: self.plain_work,
            adjusted: false,
        };
        self.budget.keeps_period(plain, received)
    }

    /// The last frame's solve: its iterations, its work and its budget.
    #[must_use]
    pub fn last_solve(&self) -> SolveStats {
        self.last_solve
    }

    /// Whether the table is a grid this pipeline can synthesize from.
    #[must_use]
    pub fn has_grid(&self) -> bool {
        self.grid.is_some()
    }

    /// Whether the pipeline performs layers (the region's layer list).
    #[must_use]
    pub fn has_layers(&self) -> bool {
        self.layered.is_some()
    }

    /// Layer `i`'s effective weight (after its cross-fade) and phase (0
    /// for a static grid) as of the last frame.
    #[must_use]
    pub fn layer(&self, i: usize) -> Option<(f32, f32)> {
        let (layers, _) = self.layered?;
        layers.as_slice().get(i)?;
        let s = self.layer_state.get(i)?;
        Some((s.weight, s.playhead.phase()))
    }

    /// The servo targets by channel, quarter-µs (0: channel unused).
    #[must_use]
    pub fn targets(&self) -> &[u16] {
        self.targets.get(..self.channels).unwrap_or(&[])
    }

    /// The joint angles of the last performed frame (solved), before the
    /// servos' calibration and slew limits.
    #[must_use]
    pub fn angles(&self) -> &Angles<N> {
        &self.angles
    }

    /// The world pose of the last solve (or rest): a frame whose budget did
    /// not cover a solve keeps it (see [the solve stage](self)).
    #[must_use]
    pub fn pose(&self) -> &Pose<N> {
        &self.pose
    }

    /// The remaining distance to each active goal after the last solve, m.
    #[must_use]
    pub fn residuals(&self) -> &[f32] {
        self.report
            .residuals
            .get(..self.goals.as_slice().len())
            .unwrap_or(&[])
    }

    /// Frames whose parameters had to be clamped or projected into the table.
    #[must_use]
    pub fn adjusted_frames(&self) -> u32 {
        self.adjusted
    }

    /// Frames dropped because synthesis or solving failed (targets held).
    #[must_use]
    pub fn failed_frames(&self) -> u32 {
        self.failed_frames
    }

    /// Whether every servo is at its rest pulse and still.
    #[must_use]
    pub fn resting(&self) -> bool {
        self.resting
    }

    /// Whether the outputs have nothing left to do until the next armed
    /// frame: at rest, and released if the rig's idle policy is `Off` (and
    /// they were ever driven).
    #[must_use]
    pub fn settled(&self) -> bool {
        self.resting && !self.release_due()
    }

    /// Whether the outputs are at rest but still to be released.
    fn release_due(&self) -> bool {
        self.rig.idle() == Idle::Off && self.driven && !self.released
    }

    /// One step towards rest, disarmed or timed out: ease to rest, then
    /// (idle policy `Off`) release every output once (see
    /// [Idle](self#idle)). True if the targets changed.
    pub fn rest_step(&mut self) -> bool {
        if !self.resting {
            self.ease_to_rest()
        } else if self.release_due() {
            self.released = true;
            self.targets.fill(0);
            true
        } else {
            false
        }
    }

    /// Starts or moves a calibration jog of servo `channel` towards
    /// `target` (quarter units), or ends it with `target` 0 (see
    /// [Calibration jog](self#calibration-jog)). False if the rig has no
    /// servo on `channel` or another channel is jogging. Only while
    /// disarmed: the caller refuses it otherwise.
    pub fn jog(&mut self, channel: u8, target: u16) -> bool {
        let Some(servo) = self.rig.servos().iter().find(|s| s.channel == channel) else {
            return false;
        };
        let rest = quarter_us(servo.rest_us);
        match &mut self.jog {
            Some(j) if j.channel != channel => false,
            Some(j) => {
                (j.target, j.ending) = if target == 0 {
                    (rest, true)
                } else {
                    (target, false)
                };
                true
            }
            None if target == 0 => true,
            None => {
                self.jog = Some(Jog {
                    channel,
                    target,
                    ending: false,
                });
                self.resting = false;
                self.released = false;
                self.driven = true;
                true
            }
        }
    }

    /// Ends a calibration jog, if one is under way: the channel eases back
    /// to rest.
    pub fn end_jog(&mut self) {
        let rig = self.rig;
        if let Some(j) = &mut self.jog
            && let Some(servo) = rig.servos().iter().find(|s| s.channel == j.channel)
        {
            j.target = quarter_us(servo.rest_us);
            j.ending = true;
        }
    }

    /// Whether a calibration jog is under way (including one easing back
    /// to rest).
    #[must_use]
    pub fn jogging(&self) -> bool {
        self.jog.is_some()
    }

    /// Sets the dials (a `Params` message): they override parameters
    /// `0..values.len()` from the next frame on.
    pub fn set_dials(&mut self, values: &[f32]) {
        self.dials = List::from_slice(values).unwrap_or_default();
    }

    /// Overrides goal `goal`'s weight; false if there is no such goal slot.
    pub fn set_goal_weight(&mut self, goal: u8, weight: f32) -> bool {
        match self.weights.get_mut(usize::from(goal)) {
            Some(w) => {
                *w = Some(weight);
                true
            }
            None => false,
        }
    }

    /// Takes sensor `id`'s last orientation as its zero; false if the last
    /// frame had no such sensor.
    pub fn boresight(&mut self, id: u8) -> bool {
        let Some(s) = self.last_sensors.iter().find(|s| s.id == id) else {
            return false;
        };
        let [w, x, y, z] = s.rotation;
        match self.boresight.get_mut(usize::from(id)) {
            Some(b) => {
                *b = Quat::from_xyzw(x, y, z, w).conjugate();
                true
            }
            None => false,
        }
    }

    /// Takes a frame's sensors (boresight-corrected) and time; returns the
    /// step length `dt` for it, seconds (see [Time](self#time)).
    pub fn take(&mut self, frame: &ValidTrackerFrame) -> f32 {
        let dt = self.frame_dt(frame.time_us());
        self.remember(frame);
        self.received = Received::of(frame);
        dt
    }

    /// Drops the solver's correction (the warm start): the fail-safe
    /// tripped or the loop disarmed, so the next solve starts from the
    /// synthesized pose.
    pub fn drop_correction(&mut self) {
        self.warm.clear();
        self.restart_layers();
    }

    /// Starts the layers over (see [Layers](self#layers)): phase 0, the
    /// ramps' time 0, weights at their sources' values without a fade.
    fn restart_layers(&mut self) {
        self.layer_state = [LayerState::START; MAX_LAYERS];
        self.layer_time = 0.0;
    }

    /// Map, synthesize, solve and drive the servos for the frame last
    /// [`Pipeline::take`]n, with steps of `dt` seconds. Writes the stage
    /// counts `MAP..=SERVO` into `stages` and returns the counter at the end.
    /// If synthesis or solving fails the targets are held and the frame is
    /// counted in [`Pipeline::failed_frames`].
    pub fn perform(&mut self, dt: f32, cycles: &mut dyn Cycles, stages: &mut [u32; STAGES]) -> u32 {
        self.resting = false;
        self.released = false;
        self.driven = true;
        let t0 = cycles.now();
        self.map();
        let t1 = cycles.now();
        let synthesized = if self.layered.is_some() {
            self.synthesize_layers(dt)
        } else {
            self.synthesize()
        };
        let t2 = cycles.now();
        let solved = synthesized && self.solve();
        let t3 = cycles.now();
        if solved {
            self.drive(dt);
        } else {
            self.failed_frames = self.failed_frames.saturating_add(1);
        }
        let t4 = cycles.now();
        stages[stage::MAP] = t1.wrapping_sub(t0);
        stages[stage::SYNTH] = t2.wrapping_sub(t1);
        stages[stage::SOLVE] = t3.wrapping_sub(t2);
        stages[stage::SERVO] = t4.wrapping_sub(t3);
        t4
    }

    /// The step length for a frame at tracker time `time_us`, seconds.
    fn frame_dt(&mut self, time_us: u32) -> f32 {
        let period_us = self.rig.frame_period_us();
        let dt_us = match self.last_tracker_us {
            Some(last) if time_us.wrapping_sub(last) < u32::MAX / 2 => {
                time_us.wrapping_sub(last).min(period_us)
            }
            Some(_) => 0,
            None => period_us,
        };
        self.last_tracker_us = Some(time_us);
        dt_us as f32 * 1e-6
    }

    /// Keeps the frame's sensors, boresight-corrected, for mapping.
    fn remember(&mut self, frame: &ValidTrackerFrame) {
        self.last_sensors.clear();
        for s in frame.sensors() {
            let b = self
                .boresight
                .get(usize::from(s.id()))
                .copied()
                .unwrap_or(Quat::IDENTITY);
            let q = s.rotation() * b;
            let _ = self.last_sensors.push(Sensor {
                id: s.id(),
                position: s.position().to_array(),
                rotation: [q.w, q.x, q.y, q.z],
            });
        }
    }

    /// Sensors → parameters and goals, then dial and weight overrides.
    fn map(&mut self) {
        let _ = self.rig.map_sensors(
            self.last_sensors.as_slice(),
            &mut self.params,
            &mut self.goals,
        );
        for (p, d) in self.params.iter_mut().zip(self.dials.iter()) {
            *p = *d;
        }
        for (g, w) in self
            .goals
            .as_mut_slice()
            .iter_mut()
            .zip(self.weights.iter())
        {
            if let Some(w) = w {
                g.weight = *w;
            }
        }
    }

    /// Grid synthesis into the warm start. False if it failed.
    fn synthesize(&mut self) -> bool {
        let (Some(grid), Some(table)) = (&self.grid, self.table) else {
            return false;
        };
        let n = grid.axes().len();
        let Some(params) = self.params.get(..n) else {
            return false;
        };
        // Kept and filled in place: a query is a few hundred bytes, and a
        // new one a clear and a copy of them every frame.
        let query = &mut self.query;
        if grid.query_into(params, query).is_err() {
            return false;
        }
        let adjusted = query.adjust() != Adjust::None;
        if adjusted {
            self.adjusted = self.adjusted.saturating_add(1);
        }
        if query.pose(table, &mut self.synth).is_err() {
            return false;
        }
        self.synthesized = Synthesis {
            work: self.plain_work.saturating_add(query.projection_work()),
            adjusted,
        };
        let body = self.rig.body();
        if pose::to_local(&body.hierarchy(), &self.synth, &mut self.local).is_err() {
            return false;
        }
        self.angles.set_from_local(&body, &self.local).is_ok()
    }

    /// Synthesizes every layer, blends them over the rest pose (see
    /// [`crate::layer`]) and sets the joint angles. False if a layer failed.
    fn synthesize_layers(&mut self, dt: f32) -> bool {
        let Some((layers, tables)) = self.layered else {
            return false;
        };
        let time = self.layer_time;
        self.layer_time += dt;
        self.local = self.rest_local;
        let mut adjusted = false;
        let mut work = 0u32;
        for ((layer, table), i) in layers.as_slice().iter().zip(tables).zip(0..) {
            let Some(table) = table else {
                return false;
            };
            let mut params = [0.0f32; MAX_PARAMS];
            for (p, s) in params.iter_mut().zip(layer.sources()) {
                *p = s.value(&self.params, time);
            }
            let params = params.get(..usize::from(layer.axis_count)).unwrap_or(&[]);
            let target = layer.weight.value(&self.params, time);
            let Some(state) = self.layer_state.get_mut(i) else {
                return false;
            };
            state.fade_to(target, layer.fade_s, dt);
            let step = dt * layer.rate_at(&self.params, time);
            let out = (&mut self.query, &mut self.synth);
            let Some((adjust, synthesis)) = layer_pose(table, params, state, step, out) else {
                return false;
            };
            adjusted |= adjust != Adjust::None;
            let blend = (self.synth.count as u32).saturating_mul(deadline::LAYER_PER_SEGMENT);
            work = work.saturating_add(synthesis).saturating_add(blend);
            let body = self.rig.body();
            if pose::to_local(&body.hierarchy(), &self.synth, &mut self.layer_local).is_err() {
                return false;
            }
            if layer.root == Root::Apply {
                self.layer_local.root_position += state.playhead.travelled();
            }
            layer::blend(&mut self.local, &self.layer_local, layer.mask, state.weight);
        }
        self.synthesized = Synthesis { work, adjusted };
        if adjusted {
            self.adjusted = self.adjusted.saturating_add(1);
        }
        let body = self.rig.body();
        self.angles.set_from_local(&body, &self.local).is_ok()
    }

    /// Solves the goals, warm-started (see [`Correction`]). False if it
    /// failed.
    fn solve(&mut self) -> bool {
        let body: Body<'_> = self.rig.body();
        self.warm.start(&body, &self.goals, &mut self.angles);
        let (budget, short) = self.budget.decide(self.synthesized, self.received);
        if short {
            self.short_frames = self.short_frames.saturating_add(1);
        }
        match solve::solve_into(
            &SOLVER.with_budget(budget),
            &body,
            &self.goals,
            &mut self.angles,
            &mut self.pose,
            self.solver,
            &mut self.report,
        ) {
            Ok(()) => {
                let report = &self.report;
                self.last_solve = SolveStats {
                    iterations: report.iterations,
                    work: report.work,
                    budget,
                    converged: report.converged,
                };
                self.warm.finish(&self.angles);
                true
            }
            Err(SolveError::Budget) => {
                // Not even the solve's fixed part fits this frame: drive
                // the warm start and carry the correction on.
                self.angles.clamp_to_limits(&body);
                self.last_solve = SolveStats {
                    iterations: 0,
                    work: 0,
                    budget,
                    converged: false,
                };
                self.warm.finish(&self.angles);
                true
            }
            Err(_) => {
                self.warm.clear();
                false
            }
        }
    }

    /// Joint angles → pulses → slew-limited targets.
    fn drive(&mut self, dt: f32) {
        self.set_step(dt);
        for servo in self.rig.servos() {
            let ch = usize::from(servo.channel);
            let (Some(Some(slew)), Some(t)) = (self.slews.get_mut(ch), self.targets.get_mut(ch))
            else {
                continue;
            };
            let angle = Rig::servo_angle(servo, &self.angles).unwrap_or(f32::NAN);
            let target = quarter_us(servo.calibration().pulse_us(angle));
            *t = slew.update(target);
        }
    }

    /// Sets every servo's slew limits for steps of `dt` seconds, unless they
    /// already are: at a steady tracker rate `dt` is the same frame after
    /// frame, and the limits with it.
    fn set_step(&mut self, dt: f32) {
        if self.step_dt.map(f32::to_bits) == Some(dt.to_bits()) {
            return;
        }
        for servo in self.rig.servos() {
            if let Some(Some(slew)) = self.slews.get_mut(usize::from(servo.channel)) {
                slew.set_limits(servo.step_limits(dt));
            }
        }
        self.step_dt = Some(dt);
    }

    /// One frame of a show ([`crate::show`]): every servo the show drives
    /// follows its target for `frame` through its slew limiter
    /// ([`Slew::track`]: never outside its calibrated range, never faster
    /// than its speed limit); a servo the show does not drive goes back to
    /// rest the same way. Any jog ends. Never inlined: kept out of the
    /// frame's path.
    #[inline(never)]
    pub fn play_step(&mut self, show: &Show<'_>, cursor: &mut ShowCursor, frame: u32) {
        let period = self.rig.frame_period_s();
        self.set_step(period);
        self.jog = None;
        for servo in self.rig.servos() {
            let ch = usize::from(servo.channel);
            let (Some(Some(slew)), Some(t)) = (self.slews.get_mut(ch), self.targets.get_mut(ch))
            else {
                continue;
            };
            let goal = cursor
                .target(show, u16::from(servo.channel), frame)
                .unwrap_or_else(|| quarter_us(servo.rest_us));
            *t = slew.track(goal);
        }
        cursor.played(frame);
        self.resting = false;
        self.released = false;
        self.driven = true;
    }

    /// One rest-ward step of every servo at the frame period (a jogged
    /// channel steps towards its jog target instead). True if any target
    /// moved; once every servo is at rest and still (and no jog is under
    /// way), [`Pipeline::resting`] is true.
    pub fn ease_to_rest(&mut self) -> bool {
        let period = self.rig.frame_period_s();
        self.set_step(period);
        let mut moved = false;
        let mut all_rest = true;
        for servo in self.rig.servos() {
            let ch = usize::from(servo.channel);
            let (Some(Some(slew)), Some(t)) = (self.slews.get_mut(ch), self.targets.get_mut(ch))
            else {
                continue;
            };
            let goal = match self.jog {
                Some(j) if j.channel == servo.channel => j.target,
                _ => quarter_us(servo.rest_us),
            };
            let next = slew.update(goal);
            moved |= next != *t;
            all_rest &= next == goal && slew.last_step() == 0;
            *t = next;
        }
        if all_rest && self.jog.is_some_and(|j| j.ending) {
            self.jog = None;
        }
        self.resting = all_rest && self.jog.is_none();
        moved
    }
}
