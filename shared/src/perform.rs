//! The board's side of a performance: the protocol state machine around the
//! per-frame [`Pipeline`].
//!
//! [`Performer`] is everything a board does with the tracker link, shared by
//! the firmware (which only moves bytes between it and its peripherals) and
//! the host's `marionette sim` (which feeds it a recording). It answers the
//! handshake and the commands, keeps the fail-safe, times each frame, and
//! hands every accepted tracker frame to the [`Pipeline`] (map, synthesize,
//! solve, servo) when there is a rig to drive. Without a valid rig it still
//! speaks the protocol: it answers `Hello` and `RequestStatus` with the
//! reason, refuses `Arm`, and never produces servo targets.
//!
//! ## States
//!
//! ```text
//!              Arm (reason Ok)          no valid frame for the time-out (tick)
//!   Disarmed ──────────────────▶ Armed ─────────────────────────────────▶ FailSafe
//!      ▲  ◀──── Disarm, or a Hello ──┘ ◀── an accepted tracker frame ────────┘
//!      └────────────── Disarm, or a Hello ◀───────────────────────────────────┘
//!   Unready: no rig, no usable table, or a back-end the board lacks (Arm refused)
//! ```
//!
//! - **Disarmed**: tracker frames are taken (their sensors and times kept)
//!   and the servos ease to rest, one step per frame or tick.
//! - **Armed**: every accepted tracker frame is performed.
//! - **FailSafe**: armed, but [`Performer::tick`] found no accepted tracker
//!   frame for the rig's fail-safe time-out (counted from the last frame or
//!   from `Arm`): each tick drops the solver's correction and eases the
//!   servos one step to rest. The next accepted tracker frame ends the trip
//!   and is performed; the trip is reported (see below).
//! - **Jogging** (disarmed, calibration): a `Jog` command holds one servo
//!   at a target of the host's (see below); `Arm` is refused until the jog
//!   has ended.
//! - A `Hello` with another protocol version disarms and reports
//!   `ProtocolMismatch` until a matching `Hello`, which clears it (the
//!   reason is the session's, never latched).
//!
//! ## Calibration jog
//!
//! `Jog { channel, target }` (quarter-µs, or a bus servo's position × 4) is
//! accepted (`Ack` ok) only while disarmed, with a rig the board can drive
//! (its state `Disarmed`, or `Unready` for want of a table: a servo is
//! calibrated before its tables are built), for a channel of the rig's
//! servos, and while no other channel is jogging. The channel then moves
//! one slew step per [`Performer::tick`] (and per tracker frame taken) towards
//! the target through the same limiter as a performance
//! ([`Pipeline::jog`]): **never outside the channel's calibrated range**
//! (the rig's pulse range or bus-servo limits, after trim and reversal: a
//! target beyond it stops at its end) and **never faster than the servo's
//! speed and acceleration limits**. Every other servo eases to, or stays
//! at, rest. Further `Jog`s to the same channel move its target; `Jog`
//! with target 0, `Disarm` or any `Hello` end the jog: the channel eases
//! back to rest and is the loop's again. So does a second without any
//! message from the host ([`JOG_TIMEOUT_US`]): a host that vanished
//! mid-jog must not leave a servo held, perhaps stalled against its end
//! stop, so a host holding a jog repeats it (or sends any message) more
//! often than that. `Arm` is refused while a jog is under way, including
//! its easing back.
//!
//! ## Shows
//!
//! A region may hold a show ([`crate::show`]) built for its rig. The board
//! plays it while disarmed: from boot if the show says so, or from a
//! trigger ([`Performer::play_show`]: the board's button). Each
//! [`Performer::tick`] plays one frame: every servo the show drives steps
//! towards the frame's target through its slew limiter (within its
//! calibrated range and speed and acceleration limits), and the outputs go
//! out every frame ([`Cause::Show`]). At its end the show starts again
//! (loop) or the servos ease to rest. `Arm` (the host takes over),
//! `Disarm`, the command `Show { play: false }` or a board that cannot
//! drive its rig stop it (`Show { play: true }` starts it from its first
//! frame); tracker frames
//! taken while it plays move nothing; `Jog` is refused while it plays.
//!
//! A region whose show fails its checks (truncated, a flipped bit, built
//! for another rig: [`crate::show::ShowError`]) plays nothing: the servos
//! stay at rest. `Status` says why ([`ShowState`]) and counts the refusals:
//! one at boot, one for each trigger refused because of it.
//!
//! ## Replies
//!
//! - `Hello` → `Status` (with `request_seq: None`).
//! - `RequestStatus` → `Status` with `request_seq: Some(seq)`, and no `Ack`.
//! - every other command → `Ack { seq, ok }`.
//! - `Telemetry` after every [`TELEMETRY_EVERY`]th performed frame, and
//!   after the frame that ends a fail-safe trip; its `seq` is that frame's.
//!
//! ## What the board reports about itself
//!
//! `Status` and `Telemetry` carry the [`State`] and the number of fail-safe
//! trips since boot. `Telemetry` also carries the last trip: the sequence
//! number of the message that ended it and the number of fail-safe ticks it
//! lasted ([`Performer::tick`] calls that found the link silent; each drops
//! the solver's correction and eases one step). A native replay that runs
//! that many ticks just before that message reproduces the board's output
//! bit for bit. It also carries [`FrameTiming`]: each performed frame's
//! count from the [`Cycles`] the board passes (the frame's `TOTAL` stage),
//! as mean, worst and overruns since the last `Arm`.

use crate::frame::{Cycles, Pipeline, Region, stage};
use crate::pose::{MAX_SEGMENTS, Pose};
use crate::show::{Cursor as ShowCursor, Show, ShowError};
use crate::solve::SolverState;
use crate::wire::{
    Ack, CommandKind, ErrorCounters, FrameTiming, Incoming, List, Message, PROTOCOL_VERSION,
    Receiver, STAGES, ShowState, State, Status, StatusReason, Telemetry, Trip, ValidCommand,
};

/// A telemetry message goes out after every this many performed frames.
pub const TELEMETRY_EVERY: u32 = 10;

/// A calibration jog ends (its channel eases back to rest) once the board
/// has accepted no message for this long, µs (see
/// [Calibration jog](self#calibration-jog)).
pub const JOG_TIMEOUT_US: u32 = 1_000_000;

/// The frame period and fail-safe time-out of a board without a rig, µs.
const IDLE_PERIOD_US: u32 = 1000;

/// Why servo targets changed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cause {
    /// An accepted tracker frame (its sequence number).
    Frame(u32),
    /// Disarmed or timed out: easing to rest, or a calibration jog
    /// moving its channel.
    Rest,
    /// A frame of the flashed show (its index; see [Shows](self#shows)).
    Show(u32),
}

/// What one call of [`Performer::receive`] or [`Performer::tick`] produced.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Update {
    /// New servo targets are ready in [`Performer::targets`].
    pub outputs: Option<Cause>,
    /// A message to send back to the host.
    pub reply: Option<Message>,
}

impl Update {
    /// Nothing happened.
    pub const NONE: Self = Self {
        outputs: None,
        reply: None,
    };

    const fn reply(msg: Message) -> Self {
        Self {
            outputs: None,
            reply: Some(msg),
        }
    }
}

/// Frame times since the last `Arm`, in the units of the board's [`Cycles`].
#[derive(Clone, Copy, Debug, Default)]
struct Timing {
    frames: u32,
    sum: u64,
    worst: u32,
    overruns: u32,
}

impl Timing {
    fn add(&mut self, cycles: u32, budget: u32) {
        self.frames = self.frames.saturating_add(1);
        self.sum = self.sum.saturating_add(u64::from(cycles));
        self.worst = self.worst.max(cycles);
        if budget > 0 && cycles > budget {
            self.overruns = self.overruns.saturating_add(1);
        }
    }

    fn report(&self, budget: u32) -> FrameTiming {
        let mean = self.sum.checked_div(u64::from(self.frames)).unwrap_or(0);
        FrameTiming {
            frames: self.frames,
            mean: u32::try_from(mean).unwrap_or(u32::MAX),
            worst: self.worst,
            overruns: self.overruns,
            budget,
        }
    }
}

/// The live loop of one board (see the module doc), for rigs of at most `N`
/// segments.
///
/// # Examples
///
/// A one-servo rig (an arm on a post; the servo turns ±90° over 1000 to
/// 2000 µs, so its rest angle 0 is 1500 µs) flashed without a table: the
/// board says why it cannot arm, refuses `Arm`, and takes tracker frames
/// while its servo stays at its rest target (nothing new to send: it starts
/// there).
///
/// ```
/// use marionette_core::frame::{NoCycles, Region};
/// use marionette_core::perform::Performer;
/// use marionette_core::pose::NO_PARENT;
/// use marionette_core::region::{self, Entry};
/// use marionette_core::rig::{
///     AxisName, DofDesc, Idle, Output, RigDesc, SegmentDesc, ServoDesc,
/// };
/// use marionette_core::solve::SolverState;
/// use marionette_core::wire::{
///     Command, CommandKind, Hello, List, MAX_FRAME, Message, PROTOCOL_VERSION, State,
///     StatusReason, TrackerFrame, encode,
/// };
///
/// let mut desc = RigDesc::<4> {
///     name: "arm",
///     frame_period_us: 1000,
///     failsafe_timeout_ms: 100,
///     root_position: [0.0, 1.0, 0.0],
///     root_rotation: [1.0, 0.0, 0.0, 0.0],
///     output: Output::Maestro { baud: 115_200 },
///     idle: Idle::Hold,
///     segments: List::new(),
///     servos: List::new(),
///     params: List::new(),
///     goals: List::new(),
/// };
/// let post = SegmentDesc { name: "post", parent: NO_PARENT, ..SegmentDesc::default() };
/// let mut dofs = List::new();
/// dofs.push(DofDesc { axis: AxisName::X, min: -1.5, max: 1.5 }).unwrap();
/// let arm = SegmentDesc { name: "arm", parent: 0, dofs, ..SegmentDesc::default() };
/// desc.segments.push(post).unwrap();
/// desc.segments.push(arm).unwrap();
/// let half_turn = core::f32::consts::FRAC_PI_2;
/// desc.servos.push(ServoDesc {
///     channel: 0,
///     segment: 1,
///     angle_min: -half_turn,
///     angle_max: half_turn,
///     pulse_min_us: 1000.0,
///     pulse_max_us: 2000.0,
///     rest_us: 1500.0,
///     max_speed: 5.0,
///     max_accel: 40.0,
///     ..ServoDesc::default()
/// }).unwrap();
/// let mut rig_blob = [0u8; 512];
/// let n = desc.to_blob(&mut rig_blob).unwrap();
/// let mut flash = [0u8; 1024];
/// let n = region::write(&[Entry::rig(&rig_blob[..n])], &mut flash).unwrap();
///
/// let region = Region::<4>::parse_sized(&flash[..n]);
/// let mut solver = SolverState::<4>::new();
/// let mut board = Performer::new(&region, &mut solver);
/// let mut send = |board: &mut Performer<'_, '_, 4>, msg: Message, now_us: u32| {
///     let mut buf = [0u8; MAX_FRAME];
///     let mut bytes = encode(&msg, &mut buf).unwrap();
///     board.receive(&mut bytes, now_us, &mut NoCycles)
/// };
///
/// let hello = Message::Hello(Hello { protocol_version: PROTOCOL_VERSION });
/// match send(&mut board, hello, 0).reply {
///     Some(Message::Status(s)) => assert_eq!(s.reason, StatusReason::NoTable),
///     other => panic!("{other:?}"),
/// }
/// let arm = Message::Command(Command { seq: 0, kind: CommandKind::Arm });
/// match send(&mut board, arm, 10).reply {
///     Some(Message::Ack(a)) => assert!(!a.ok),
///     other => panic!("{other:?}"),
/// }
/// for seq in 1..=3 {
///     let frame = TrackerFrame { seq, time_us: seq * 1000, sensors: List::new() };
///     let update = send(&mut board, Message::TrackerFrame(frame), seq * 1000);
///     assert_eq!(update.outputs, None);
///     assert_eq!(board.targets(), &[1500 * 4]); // quarter-µs
/// }
/// assert_eq!((board.state(), board.armed()), (State::Unready, false));
/// ```
///
/// With a table built for the rig (`marionette build`; the region holds
/// both), `Arm` is acknowledged and every tracker frame is performed:
/// [`Update::outputs`] is `Some(Cause::Frame(seq))` ([`Cause`]).
pub struct Performer<'r, 'a, const N: usize = MAX_SEGMENTS> {
    pipeline: Option<Pipeline<'r, 'a, N>>,
    receiver: Receiver,
    /// Why the board cannot arm, from its region or [`Performer::refuse`]
    /// (never `ProtocolMismatch`, which is the session's).
    reason: StatusReason,
    /// [`Performer::refuse`]d: the board cannot drive this rig's outputs.
    refused: bool,
    armed: bool,
    period_us: u32,
    timeout_us: u32,
    last_frame_us: u32,
    /// When the last message was accepted (the jog's watchdog).
    last_heard_us: u32,
    /// In the fail-safe state: the ticks of the current trip so far.
    trip_ticks: Option<u32>,
    trips: u32,
    last_trip: Trip,
    stages: [u32; STAGES],
    timing: Timing,
    frames_out: u32,
    disarms: u32,
    /// The region's show, if it has a valid one for the rig.
    show: Option<Show<'a>>,
    /// The show's next frame, while it plays.
    playing: Option<u32>,
    cursor: ShowCursor,
    /// Why the region's show was refused ([`ShowState::None`] if it was
    /// not), and the refusals counted since boot.
    show_refused: ShowState,
    show_refusals: u32,
}

impl<'r, 'a, const N: usize> Performer<'r, 'a, N> {
    /// The loop for `region` (disarmed; servos assumed at rest), solving with
    /// `solver`'s storage. Without a valid rig it only speaks the protocol
    /// and reports the region's reason.
    #[must_use]
    pub fn new(region: &'r Region<'a, N>, solver: &'r mut SolverState<N>) -> Self {
        let pipeline = Pipeline::new(region, solver);
        let reason = match (region.reason, &pipeline) {
            (StatusReason::Ok, Some(p)) if !p.has_grid() && !p.has_layers() => {
                StatusReason::Unsupported
            }
            (StatusReason::Ok, None) => StatusReason::NoRig,
            (r, _) => r,
        };
        let (period_us, timeout_ms) = pipeline.as_ref().map_or((IDLE_PERIOD_US, 0), |p| {
            (p.rig().frame_period_us(), p.rig().failsafe_timeout_ms())
        });
        let show = region.show.filter(|_| pipeline.is_some());
        let show_refused = region.show_error.map_or(ShowState::None, refusal);
        Self {
            pipeline,
            receiver: Receiver::new(),
            reason,
            refused: false,
            armed: false,
            period_us,
            timeout_us: timeout_ms.saturating_mul(1000),
            last_frame_us: 0,
            last_heard_us: 0,
            trip_ticks: None,
            trips: 0,
            last_trip: Trip::default(),
            stages: [0; STAGES],
            timing: Timing::default(),
            frames_out: 0,
            disarms: 0,
            show,
            playing: show.filter(Show::at_boot).map(|_| 0),
            cursor: ShowCursor::default(),
            show_refused,
            show_refusals: u32::from(show_refused.is_refused()),
        }
    }

    /// The flashed show's state, as `Status` reports it.
    #[must_use]
    pub fn show_state(&self) -> ShowState {
        match (self.playing, &self.show) {
            (Some(_), _) => ShowState::Playing,
            (None, Some(_)) => ShowState::Ready,
            (None, None) => self.show_refused,
        }
    }

    /// The show frame to play next, while the flashed show plays.
    #[must_use]
    pub fn playing(&self) -> Option<u32> {
        self.playing
    }

    /// Starts the flashed show from its first frame (a trigger: a button,
    /// or the host); false if there is none, the board is armed, or it
    /// cannot drive its rig. Never inlined: a cold path kept out of the
    /// frame's.
    #[inline(never)]
    pub fn play_show(&mut self) -> bool {
        let ok = self.show.is_some() && !self.armed && !self.refused;
        if ok {
            self.playing = Some(0);
            self.cursor = ShowCursor::default();
        } else if self.show_refused.is_refused() {
            self.show_refusals = self.show_refusals.saturating_add(1);
        }
        ok
    }

    /// Stops the show, if it plays: the servos ease to rest.
    pub fn stop_show(&mut self) {
        self.playing = None;
    }

    /// One frame of the show (see [Shows](self#shows)). Never inlined (as
    /// [`Performer::play_show`]).
    #[inline(never)]
    fn show_tick(&mut self, frame: u32) -> Update {
        let (Some(show), Some(pipeline)) = (&self.show, &mut self.pipeline) else {
            self.playing = None;
            return Update::NONE;
        };
        pipeline.play_step(show, &mut self.cursor, frame);
        let next = frame.saturating_add(1);
        self.playing = if next < show.frames() {
            Some(next)
        } else if show.looping() {
            self.cursor = ShowCursor::default();
            Some(0)
        } else {
            None
        };
        Update {
            outputs: Some(Cause::Show(frame)),
            reply: None,
        }
    }

    /// Marks the loop as unable to drive this rig on this board (for
    /// example a servo back-end the board lacks): it disarms, refuses every
    /// `Arm`, and reports `reason` in its [`Status`] (unless the region
    /// already gave a reason, which is reported first).
    pub fn refuse(&mut self, reason: StatusReason) {
        if self.reason == StatusReason::Ok {
            self.reason = reason;
        }
        self.refused = true;
        self.armed = false;
        self.playing = None;
        if let Some(pipeline) = &mut self.pipeline {
            pipeline.end_jog();
        }
    }

    /// The per-frame pipeline, if the region holds a rig.
    #[must_use]
    pub fn pipeline(&self) -> Option<&Pipeline<'r, 'a, N>> {
        self.pipeline.as_ref()
    }

    /// The per-frame pipeline, mutable (for example to study the loop at
    /// another solver budget, [`Pipeline::set_solve_budget`]).
    #[must_use]
    pub fn pipeline_mut(&mut self) -> Option<&mut Pipeline<'r, 'a, N>> {
        self.pipeline.as_mut()
    }

    /// The rig's frame period (1000 µs without a rig): call
    /// [`Performer::tick`] this often.
    #[must_use]
    pub fn frame_period_us(&self) -> u32 {
        self.period_us
    }

    /// The servo targets by channel, quarter-µs (empty without a rig).
    #[must_use]
    pub fn targets(&self) -> &[u16] {
        self.pipeline.as_ref().map_or(&[], Pipeline::targets)
    }

    /// Whether the servo outputs are enabled.
    #[must_use]
    pub fn armed(&self) -> bool {
        self.armed
    }

    /// Why the board cannot arm now ([`StatusReason::Ok`] if it can),
    /// `ProtocolMismatch` while the session's last `Hello` did not match.
    #[must_use]
    pub fn reason(&self) -> StatusReason {
        match self.receiver.session() {
            crate::wire::Session::Rejected { .. } => StatusReason::ProtocolMismatch,
            _ => self.reason,
        }
    }

    /// The board's state (see the module doc).
    #[must_use]
    pub fn state(&self) -> State {
        match (self.reason(), self.armed, self.trip_ticks) {
            (StatusReason::Ok, true, Some(_)) => State::FailSafe,
            (StatusReason::Ok, true, None) => State::Armed,
            (StatusReason::Ok, false, _) | (StatusReason::ProtocolMismatch, _, _) => {
                State::Disarmed
            }
            _ => State::Unready,
        }
    }

    /// The receive path's error counters.
    #[must_use]
    pub fn errors(&self) -> &ErrorCounters {
        self.receiver.errors()
    }

    /// Frames whose parameters had to be clamped or projected into the table.
    #[must_use]
    pub fn adjusted_frames(&self) -> u32 {
        self.pipeline.as_ref().map_or(0, Pipeline::adjusted_frames)
    }

    /// Frames dropped because synthesis or solving failed (targets held).
    #[must_use]
    pub fn failed_frames(&self) -> u32 {
        self.pipeline.as_ref().map_or(0, Pipeline::failed_frames)
    }

    /// The current world pose of the figure (solved, or rest), if there is
    /// a rig.
    #[must_use]
    pub fn pose(&self) -> Option<&Pose<N>> {
        self.pipeline.as_ref().map(Pipeline::pose)
    }

    /// The per-stage counts of the last performed frame (see [`stage`]), in
    /// the units of the [`Cycles`] passed to [`Performer::receive`].
    #[must_use]
    pub fn stages(&self) -> [u32; STAGES] {
        self.stages
    }

    /// Fail-safe trips since boot.
    #[must_use]
    pub fn trips(&self) -> u32 {
        self.trips
    }

    /// The last fail-safe trip that ended (zeros before the first).
    #[must_use]
    pub fn last_trip(&self) -> Trip {
        self.last_trip
    }

    /// How many `Disarm` commands the loop has obeyed.
    #[must_use]
    pub fn disarms(&self) -> u32 {
        self.disarms
    }

    /// Whether every servo is at its rest pulse and still (true without a
    /// rig).
    #[must_use]
    pub fn resting(&self) -> bool {
        self.pipeline.as_ref().is_none_or(Pipeline::resting)
    }

    /// Whether the outputs have nothing left to do until the next armed
    /// frame (see [`Pipeline::settled`]; true without a rig).
    #[must_use]
    pub fn settled(&self) -> bool {
        self.pipeline.as_ref().is_none_or(Pipeline::settled)
    }

    /// The board's status message; `request_seq` is the `RequestStatus`
    /// it answers (`None` for a `Hello`).
    #[must_use]
    pub fn status(&self, request_seq: Option<u32>) -> Status {
        Status {
            protocol_version: PROTOCOL_VERSION,
            armed: self.armed,
            table_ok: self.reason == StatusReason::Ok,
            reason: self.reason(),
            errors: *self.receiver.errors(),
            frames_ok: self.receiver.frames_ok(),
            request_seq,
            state: self.state(),
            trips: self.trips,
            show: self.show_state(),
            show_refusals: self.show_refusals,
        }
    }

    /// Feeds received bytes, advancing `input` past what was consumed, until
    /// one message has been handled; call again while `input` is not empty.
    /// `now_us` is the board clock.
    pub fn receive(&mut self, input: &mut &[u8], now_us: u32, cycles: &mut dyn Cycles) -> Update {
        let start = cycles.now();
        let Some(incoming) = self.receiver.push_slice(input) else {
            return Update::NONE;
        };
        let decoded = cycles.now();
        self.last_heard_us = now_us;
        match incoming {
            Incoming::Hello { accepted, .. } => {
                if !accepted {
                    self.disarm();
                }
                // A new session: a jog of the last one ends.
                if let Some(pipeline) = &mut self.pipeline {
                    pipeline.end_jog();
                }
                Update::reply(Message::Status(self.status(None)))
            }
            Incoming::Params(p) => {
                if let Some(pipeline) = &mut self.pipeline {
                    pipeline.set_dials(p.values());
                }
                Update::NONE
            }
            Incoming::Command(c) => Update::reply(self.command(c, now_us)),
            Incoming::Tracker => {
                self.stages[stage::DECODE] = decoded.wrapping_sub(start);
                self.frame(now_us, cycles, start)
            }
        }
    }

    /// Called by the board every frame period with its clock: runs the
    /// fail-safe (see the module doc) and eases to rest while disarmed.
    /// Returns outputs only when they moved.
    pub fn tick(&mut self, now_us: u32) -> Update {
        if let (false, Some(frame)) = (self.armed, self.playing) {
            return self.show_tick(frame);
        }
        let lost = self.armed && now_us.wrapping_sub(self.last_frame_us) >= self.timeout_us;
        if lost {
            let ticks = self.trip_ticks.map_or(1, |t| t.saturating_add(1));
            if self.trip_ticks.is_none() {
                self.trips = self.trips.saturating_add(1);
            }
            self.trip_ticks = Some(ticks);
        }
        let Some(pipeline) = &mut self.pipeline else {
            return Update::NONE;
        };
        let silent = now_us.wrapping_sub(self.last_heard_us) >= JOG_TIMEOUT_US;
        if silent && pipeline.jogging() {
            pipeline.end_jog();
        }
        if lost || !self.armed {
            pipeline.drop_correction();
            if pipeline.rest_step() {
                return Update {
                    outputs: Some(Cause::Rest),
                    reply: None,
                };
            }
        }
        Update::NONE
    }

    fn disarm(&mut self) {
        self.armed = false;
        if let Some(pipeline) = &mut self.pipeline {
            pipeline.drop_correction();
            pipeline.end_jog();
        }
    }

    /// Ends a fail-safe trip (if one is on) at the message `seq`; true if
    /// one ended.
    fn end_trip(&mut self, seq: u32) -> bool {
        match self.trip_ticks.take() {
            Some(ticks) => {
                self.last_trip = Trip { seq, ticks };
                true
            }
            None => false,
        }
    }

    fn command(&mut self, c: ValidCommand, now_us: u32) -> Message {
        let ok = match c.kind() {
            CommandKind::Arm => {
                let ready = self.reason == StatusReason::Ok
                    && self.pipeline.as_ref().is_some_and(|p| !p.jogging());
                if ready && !self.armed {
                    self.playing = None;
                    self.armed = true;
                    self.last_frame_us = now_us;
                    self.timing = Timing::default();
                }
                ready
            }
            CommandKind::Disarm => {
                self.playing = None;
                self.end_trip(c.seq());
                self.disarm();
                self.disarms = self.disarms.wrapping_add(1);
                true
            }
            CommandKind::SelectTable(n) => n == 0 && self.reason == StatusReason::Ok,
            CommandKind::SelectClip(_) => false,
            CommandKind::SetGoalWeight { goal, weight } => self
                .pipeline
                .as_mut()
                .is_some_and(|p| p.set_goal_weight(goal, weight)),
            CommandKind::Boresight { sensor } => {
                self.pipeline.as_mut().is_some_and(|p| p.boresight(sensor))
            }
            CommandKind::RequestStatus => return Message::Status(self.status(Some(c.seq()))),
            CommandKind::Jog { channel, target } => self.jog(channel, target),
            CommandKind::Show { play: true } => self.play_show(),
            CommandKind::Show { play: false } => {
                self.stop_show();
                true
            }
        };
        Message::Ack(Ack { seq: c.seq(), ok })
    }

    /// A `Jog` command (see [Calibration jog](self#calibration-jog)): false
    /// if refused.
    fn jog(&mut self, channel: u8, target: u16) -> bool {
        let drivable = !self.armed
            && self.playing.is_none()
            && !self.refused
            && self.reason() != StatusReason::ProtocolMismatch
            && self.reason != StatusReason::Unsupported;
        drivable
            && self
                .pipeline
                .as_mut()
                .is_some_and(|p| p.jog(channel, target))
    }

    /// One accepted tracker frame.
    fn frame(&mut self, now_us: u32, cycles: &mut dyn Cycles, start: u32) -> Update {
        let Some(pipeline) = &mut self.pipeline else {
            return Update::NONE;
        };
        let frame = self.receiver.frame();
        let seq = frame.seq();
        let dt = pipeline.take(frame);
        if !self.armed {
            // While the show plays, a frame moves nothing.
            let moved = self.playing.is_none() && pipeline.rest_step();
            return Update {
                outputs: moved.then_some(Cause::Rest),
                reply: None,
            };
        }
        self.last_frame_us = now_us;
        let end = pipeline.perform(dt, cycles, &mut self.stages);
        let total = end.wrapping_sub(start);
        self.stages[stage::TOTAL] = total;
        self.timing.add(total, self.budget(cycles));
        self.frames_out = self.frames_out.wrapping_add(1);
        let tripped = self.end_trip(seq);
        // The reply set in place: an update is hundreds of bytes.
        let mut update = Update {
            outputs: Some(Cause::Frame(seq)),
            reply: None,
        };
        if tripped || self.frames_out.is_multiple_of(TELEMETRY_EVERY) {
            update.reply = Some(self.telemetry(seq, cycles));
        }
        update
    }

    /// The frame period in the units of `cycles` (0 if it has no rate).
    fn budget(&self, cycles: &dyn Cycles) -> u32 {
        let c = u64::from(self.period_us) * u64::from(cycles.hz()) / 1_000_000;
        u32::try_from(c).unwrap_or(u32::MAX)
    }

    fn telemetry(&self, seq: u32, cycles: &dyn Cycles) -> Message {
        let pipeline = self.pipeline.as_ref();
        Message::Telemetry(Telemetry {
            seq,
            servo_targets: List::from_slice(self.targets()).unwrap_or_default(),
            goal_residuals: List::from_slice(pipeline.map_or(&[], Pipeline::residuals))
                .unwrap_or_default(),
            stage_counts: self.stages,
            errors: *self.receiver.errors(),
            state: self.state(),
            trips: self.trips,
            last_trip: self.last_trip,
            timing: self.timing.report(self.budget(cycles)),
        })
    }
}

/// Why the region's show was refused, as `Status` reports it.
const fn refusal(e: ShowError) -> ShowState {
    match e {
        ShowError::Truncated => ShowState::Truncated,
        ShowError::Magic => ShowState::BadMagic,
        ShowError::Version(_) => ShowState::BadVersion,
        ShowError::Crc => ShowState::BadCrc,
        ShowError::Header => ShowState::BadHeader,
        ShowError::Keys(_) => ShowState::BadKeys,
        ShowError::RigMismatch => ShowState::RigMismatch,
    }
}
