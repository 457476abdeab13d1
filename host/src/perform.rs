//! A performance, driven from the host: one session of wire messages, run
//! natively through the core's [`Performer`] (`marionette sim`) or on the
//! emulated board (`marionette emulate`), and the comparison of the two.
//!
//! A session is the byte stream a tracker bridge sends: `Hello`, `Arm`, one
//! `TrackerFrame` per recorded time step, and finally `Disarm`. The table
//! region holds the rig blob and the table blob behind a small directory
//! ([`region()`], the core's [`marionette_core::region`]), exactly as the
//! firmware reads it.
//!
//! The native run uses each frame's timestamp as the board clock and calls
//! [`Performer::tick`] at the rig's frame period in the gaps, as the firmware
//! does with its own clock. The emulated board streams as fast as its UART
//! takes the bytes, so its clock reaches the fail-safe time-out while frames
//! are flowing only if the host stalls for longer than that: the board then
//! rightly eases towards rest until the next frame, and reports the trip in
//! its telemetry (the message that ended it, and how many fail-safe ticks it
//! lasted). [`follow`] replays the session natively with the trips the board
//! reported; every servo target must then be bit-identical between the two.

use crate::blob::{self, AxisSpec, BlobError, TableSpec};
use crate::import::csv::TrackerSample;
use crate::qemu::{self, Config, QemuError};
use crate::rigfile::RigFile;
use marionette_core::frame::NoCycles;
use marionette_core::output::bus::{self, Protocol};
use marionette_core::output::{dynamixel, feetech};
use marionette_core::perform::{Cause, Performer, Update};
use marionette_core::region::{self, Region};
use marionette_core::rig::{FeetechSeries, Output as RigOutput};
use marionette_core::servo::maestro;
use marionette_core::solve::SolverState;
use marionette_core::table::{Interp, Kind, Wrap};
use marionette_core::wire::{
    self, Command, CommandKind, CompactFrame, Hello, List, MAX_FRAME, MAX_SENSORS, Message,
    PROTOCOL_VERSION, Sensor, TrackerFrame, Trip, WireError,
};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// Errors of a host-driven performance.
#[derive(Debug, thiserror::Error)]
pub enum PerformError {
    /// The table region holds no valid rig.
    #[error("the table region holds no valid rig blob")]
    NoRig,
    /// A recording has more sensors in one time step than a frame carries.
    #[error(
        "recording: {count} sensors at time {time_us} µs; a tracker frame carries at most {MAX_SENSORS}"
    )]
    TooManySensors {
        /// The time step.
        time_us: u64,
        /// Sensors found.
        count: usize,
    },
    /// A recording's sensor id is beyond what a tracker frame carries.
    #[error(
        "recording: sensor {sensor} at time {time_us} µs; tracker frames carry sensor ids 0..{MAX_SENSORS}"
    )]
    SensorId {
        /// The time step.
        time_us: u64,
        /// The sensor id.
        sensor: u8,
    },
    /// A table could not be built.
    #[error("building a table: {0}")]
    Table(String),
    /// A message could not be encoded.
    #[error("encoding a wire message: {0:?}")]
    Wire(WireError),
    /// The emulator failed.
    #[error(transparent)]
    Qemu(#[from] QemuError),
    /// A file could not be written or read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// What went wrong.
        source: std::io::Error,
    },
}

/// The table region image (the core's [`region::write`]): a directory, the
/// rig blob and the table blob (if any), exactly as the board reads it.
/// Empty (a region without a rig) only if the blobs do not fit the format's
/// 32-bit offsets.
#[must_use]
pub fn region(rig_blob: &[u8], table_blob: Option<&[u8]>) -> Vec<u8> {
    let mut entries = vec![region::Entry::rig(rig_blob)];
    entries.extend(table_blob.map(region::Entry::table));
    let mut out = vec![0u8; region::len(&entries).unwrap_or(0)];
    match region::write(&entries, &mut out) {
        Ok(n) => out.truncate(n),
        Err(_) => out.clear(),
    }
    out
}

/// A static grid over `axes` (each `(name, min, step, count)`, linear and
/// bounded) whose every sample is the rig's rest pose: a table that arms the
/// board and leaves all the visible work to the solver. Used by the
/// instruction-count bench and the end-to-end tests.
pub fn rest_grid(rig: &RigFile, axes: &[(&str, f32, f32, u16)]) -> Result<Vec<u8>, PerformError> {
    let rig_blob = crate::rigfile::to_blob(rig).map_err(|e| PerformError::Table(e.to_string()))?;
    let region = Region::parse(&rig_blob);
    let core_rig = region.rig.ok_or(PerformError::NoRig)?;
    let rest = core_rig.rest_pose();
    let pose: Vec<_> = rest
        .positions
        .iter()
        .zip(&rest.rotations)
        .take(rig.segment_names().len())
        .map(|(p, q)| (*p, *q))
        .collect();
    let axes: Vec<AxisSpec> = axes
        .iter()
        .map(|&(name, min, step, count)| AxisSpec {
            name: name.into(),
            min,
            step,
            count,
            wrap: Wrap::Bounded,
            interp: Interp::Linear,
        })
        .collect();
    let samples: usize = axes.iter().map(|a| usize::from(a.count)).product();
    let cells: usize = axes
        .iter()
        .map(|a| usize::from(a.count).saturating_sub(1))
        .product();
    let spec = TableSpec {
        rig_hash: rig.rig_hash(),
        kind: Kind::Grid,
        axes,
        segment_names: rig.segment_names().to_vec(),
        samples: vec![pose; samples],
        valid: vec![true; cells],
        durations: vec![],
        travel: vec![],
    };
    blob::write(&spec).map_err(|e: BlobError| PerformError::Table(e.to_string()))
}

/// Groups tracker samples into frames, one per distinct timestamp, in time
/// order (sequence numbers from 1).
pub fn frames(samples: &[TrackerSample]) -> Result<Vec<TrackerFrame>, PerformError> {
    let mut sorted: Vec<&TrackerSample> = samples.iter().collect();
    sorted.sort_by_key(|s| (s.time_us, s.sensor));
    let mut out: Vec<TrackerFrame> = Vec::new();
    for group in sorted.chunk_by(|a, b| a.time_us == b.time_us) {
        let time_us = group.first().map_or(0, |s| s.time_us);
        let mut sensors = List::new();
        for s in group {
            if usize::from(s.sensor) >= MAX_SENSORS {
                return Err(PerformError::SensorId {
                    time_us,
                    sensor: s.sensor,
                });
            }
            let q = s.orientation;
            let sensor = Sensor {
                id: s.sensor,
                position: s.position.as_vec3().to_array(),
                rotation: [q.w as f32, q.x as f32, q.y as f32, q.z as f32],
            };
            sensors
                .push(sensor)
                .map_err(|_| PerformError::TooManySensors {
                    time_us,
                    count: group.len(),
                })?;
        }
        let seq = u32::try_from(out.len() + 1).unwrap_or(u32::MAX);
        out.push(TrackerFrame {
            seq,
            time_us: time_us as u32,
            sensors,
        });
    }
    Ok(out)
}

/// One message of a session, with the board-clock time at which it is sent.
#[derive(Clone, Debug)]
pub struct Sent {
    /// Board-clock time, µs (the frame's own timestamp for tracker frames).
    pub time_us: u32,
    /// The encoded wire frame.
    pub bytes: Vec<u8>,
}

/// Encodes a message as one wire frame, preceded by a `0x00` delimiter so
/// that the board resynchronises even after line noise that did not end in
/// one (an empty frame is ignored by the receiver).
pub fn encode(msg: &Message) -> Result<Vec<u8>, PerformError> {
    let mut out = vec![0];
    out.extend(frame_bytes(msg)?);
    Ok(out)
}

/// Encodes a message as one wire frame (COBS, CRC, delimiter), nothing more.
pub fn frame_bytes(msg: &Message) -> Result<Vec<u8>, PerformError> {
    let mut buf = [0u8; MAX_FRAME];
    let frame = wire::encode(msg, &mut buf).map_err(PerformError::Wire)?;
    Ok(frame.to_vec())
}

/// How tracker frames travel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
pub enum Framing {
    /// The compact frame (tag 7): quantized, 7 + 11 bytes per sensor of
    /// payload. A frame with a position outside its ±4 m goes as `f32`.
    #[default]
    Compact,
    /// The `f32` frame (tag 1), 29 bytes per sensor.
    F32,
}

/// The message carrying `frame` as `framing` says (`f32` where the compact
/// frame cannot carry it: a position outside ±4 m).
#[must_use]
pub fn tracker_message(frame: &TrackerFrame, framing: Framing) -> Message {
    match framing {
        Framing::Compact => match CompactFrame::pack(frame) {
            Ok(c) => Message::CompactFrame(c),
            Err(_) => Message::TrackerFrame(*frame),
        },
        Framing::F32 => Message::TrackerFrame(*frame),
    }
}

/// The session for a recording: `Hello`, `Arm`, the frames, `Disarm`, the
/// tracker frames compact ([`session_with`] chooses). The host's sequence
/// numbers are shared by frames and commands.
pub fn session(frames: &[TrackerFrame]) -> Result<Vec<Sent>, PerformError> {
    session_with(frames, Framing::Compact)
}

/// [`session`] with the tracker frames framed as `framing` says. The first
/// message starts with a `0x00` (the board resynchronises on it); the
/// others are bare frames, each ending in its delimiter.
pub fn session_with(frames: &[TrackerFrame], framing: Framing) -> Result<Vec<Sent>, PerformError> {
    let first = frames.first().map_or(0, |f| f.time_us);
    let last = frames.last().map_or(0, |f| f.time_us);
    let n = u32::try_from(frames.len()).unwrap_or(u32::MAX);
    let mut out = vec![
        Sent {
            time_us: first,
            bytes: encode(&Message::Hello(Hello {
                protocol_version: PROTOCOL_VERSION,
            }))?,
        },
        Sent {
            time_us: first,
            bytes: frame_bytes(&Message::Command(Command {
                seq: 0,
                kind: CommandKind::Arm,
            }))?,
        },
    ];
    for f in frames {
        out.push(Sent {
            time_us: f.time_us,
            bytes: frame_bytes(&tracker_message(f, framing))?,
        });
    }
    let disarm = Command {
        seq: n.wrapping_add(1),
        kind: CommandKind::Disarm,
    };
    out.push(Sent {
        time_us: last,
        bytes: frame_bytes(&Message::Command(disarm))?,
    });
    Ok(out)
}

/// How a session is sent.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pacing {
    /// Every message as soon as the link takes it.
    AsFastAsPossible,
    /// Each message at its recorded time after the first.
    RealTime,
}

/// Sends a session through `send`, paced as asked.
pub fn pace<E>(
    session: &[Sent],
    pacing: Pacing,
    send: impl FnMut(&[u8]) -> Result<(), E>,
) -> Result<(), E> {
    pace_until(session, pacing, &AtomicBool::new(false), send).map(|_| ())
}

/// [`pace`] until `stop` is set (looked at before each message and every
/// [`STOP_POLL`] while waiting for one): returns how many messages went,
/// all of them unless it stopped.
pub fn pace_until<E>(
    session: &[Sent],
    pacing: Pacing,
    stop: &AtomicBool,
    mut send: impl FnMut(&[u8]) -> Result<(), E>,
) -> Result<usize, E> {
    let start = std::time::Instant::now();
    let first = session.first().map_or(0, |s| s.time_us);
    for (went, sent) in session.iter().enumerate() {
        if pacing == Pacing::RealTime {
            let due = Duration::from_micros(u64::from(sent.time_us.wrapping_sub(first)));
            while let Some(wait) = due.checked_sub(start.elapsed()) {
                if stop.load(Ordering::Relaxed) {
                    break;
                }
                std::thread::sleep(wait.min(STOP_POLL));
            }
        }
        if stop.load(Ordering::Relaxed) {
            return Ok(went);
        }
        send(&sent.bytes)?;
    }
    Ok(session.len())
}

/// How often [`pace_until`] looks at its stop flag while it waits.
pub const STOP_POLL: Duration = Duration::from_millis(20);

/// Everything a performance produced.
#[derive(Clone, Debug, Default)]
pub struct Run {
    /// Servo targets (quarter-µs by channel; for bus servos, whole
    /// positions × 4: [`ServoFormat::wire`]) of each accepted tracker frame.
    pub frame_targets: Vec<Vec<u16>>,
    /// Servo targets of each easing step after the frames (fail-safe or
    /// disarm), in order.
    pub rest_targets: Vec<Vec<u16>>,
    /// Replies the board sent (decoded).
    pub replies: Vec<Message>,
    /// The deepest stack the emulated board reached, bytes (measured by
    /// painting; `None` for a native run).
    pub board_stack: Option<u32>,
    /// How the emulated board stopped on a fault (a non-zero exit status,
    /// a reset), if it did; `None` for a clean end or a native run.
    pub fault: Option<String>,
    /// Tracker frames whose reserve left the solver less than it needs at
    /// the rig's period ([`marionette_core::frame::Pipeline::short_frames`]):
    /// on the board they may run over it (see [`crate::period`]). Counted
    /// by a native run (0 for an emulated one).
    pub short_frames: u32,
}

/// Runs a session natively through the core.
pub fn simulate(region_bytes: &[u8], session: &[Sent]) -> Result<Run, PerformError> {
    simulate_with(region_bytes, session, &mut |_, _| {})
}

/// [`simulate`], calling `observe` after every step that produced outputs
/// or a reply, with the performer (e.g. to sample its pose) and the update.
pub fn simulate_with(
    region_bytes: &[u8],
    session: &[Sent],
    observe: &mut dyn FnMut(&Performer<'_, '_>, &Update),
) -> Result<Run, PerformError> {
    replay(region_bytes, session, None, observe).map(|(run, _)| run)
}

/// Every servo output of a native run in the order a board sends them
/// (frame-driven and easing interleaved, as on its servo link).
pub fn simulate_outputs(
    region_bytes: &[u8],
    session: &[Sent],
) -> Result<Vec<Vec<u16>>, PerformError> {
    let (_, outputs) = replay(region_bytes, session, None, &mut |_, _| {})?;
    Ok(outputs.into_iter().map(|o| o.2).collect())
}

/// Every servo output of a native run in the order a board sends them, each
/// with the board-clock time of the step that produced it (the message's
/// time for a received message, the tick's clock for a tick) and whether a
/// tracker frame drove it: `(time_us, frame, targets)`.
pub fn simulate_timed(
    region_bytes: &[u8],
    session: &[Sent],
) -> Result<Vec<(u32, bool, Vec<u16>)>, PerformError> {
    let (_, outputs) = replay(region_bytes, session, None, &mut |_, _| {})?;
    Ok(outputs.into_iter().map(|o| (o.3, o.1, o.2)).collect())
}

/// One output of a native run, in order: the index of the session message
/// it came from (or before which its tick ran; the session's length for the
/// easing after it), whether a tracker frame drove it, the targets, and the
/// board-clock time of the step.
type Output = (usize, bool, Vec<u16>, u32);

/// [`simulate_with`], or with the board's fail-safe trips instead of the
/// replay's own: `trips` holds `(message index, ticks)`, and each of those
/// ticks runs just before that message with the board clock at the
/// fail-safe time-out or later (as a board whose host stalled sees it);
/// while armed the replay's clock then ticks nothing of its own. Also
/// returns every output in order.
fn replay(
    region_bytes: &[u8],
    session: &[Sent],
    trips: Option<&[(usize, u32)]>,
    observe: &mut dyn FnMut(&Performer<'_, '_>, &Update),
) -> Result<(Run, Vec<Output>), PerformError> {
    let region = Region::parse(region_bytes);
    let timeout_us = region.rig.as_ref().map_or(0, |r| r.failsafe_timeout_ms());
    let timeout_us = timeout_us.saturating_mul(1000);
    let mut solver = SolverState::new();
    let mut performer = Performer::new(&region, &mut solver);
    let format = ServoFormat::of_region(region_bytes, performer.targets().len());
    let wire = |targets: &[u16]| match &format {
        Some(f) => f.wire(targets),
        None => targets.to_vec(),
    };
    let period = performer.frame_period_us().max(1);
    let (mut run, mut outputs) = (Run::default(), Vec::new());
    let mut clock = session.first().map_or(0, |s| s.time_us);
    for (i, sent) in session.iter().enumerate() {
        let mut step = |p: &Performer<'_, '_>, u: Update, now: u32| {
            record(&mut run, &mut outputs, (i, now, &wire), p, u, observe);
        };
        // Board-clock ticks in the gap before this message.
        while sent.time_us.wrapping_sub(clock) >= period
            && sent.time_us.wrapping_sub(clock) < u32::MAX / 2
        {
            clock = clock.wrapping_add(period);
            if trips.is_none() || !performer.armed() {
                let update = performer.tick(clock);
                step(&performer, update, clock);
            }
        }
        let forced = trips
            .unwrap_or(&[])
            .iter()
            .filter(|t| t.0 == i)
            .map(|t| t.1)
            .sum::<u32>();
        for k in 0..forced {
            let late = sent
                .time_us
                .wrapping_add(timeout_us.wrapping_add(k.wrapping_mul(period)));
            let update = performer.tick(late);
            step(&performer, update, late);
        }
        let mut input = sent.bytes.as_slice();
        while !input.is_empty() {
            let update = performer.receive(&mut input, sent.time_us, &mut NoCycles);
            step(&performer, update, sent.time_us);
        }
    }
    // After the session: tick until every servo is at rest (bounded).
    for _ in 0..100_000 {
        if performer.settled() {
            break;
        }
        clock = clock.wrapping_add(period);
        let update = performer.tick(clock);
        record(
            &mut run,
            &mut outputs,
            (session.len(), clock, &wire),
            &performer,
            update,
            observe,
        );
    }
    run.short_frames = performer.pipeline().map_or(0, |p| p.short_frames());
    Ok((run, outputs))
}

/// The view of targets as the servo link carries them.
type Wire<'w> = dyn Fn(&[u16]) -> Vec<u16> + 'w;

/// Records one update: `(message, now, wire)` are the session message it
/// came from, the board clock and the view of targets as the servo link
/// carries them.
fn record(
    run: &mut Run,
    outputs: &mut Vec<Output>,
    (message, now, wire): (usize, u32, &Wire<'_>),
    performer: &Performer<'_, '_>,
    update: Update,
    observe: &mut dyn FnMut(&Performer<'_, '_>, &Update),
) {
    if update.outputs.is_some() || update.reply.is_some() {
        observe(performer, &update);
    }
    let targets = wire(performer.targets());
    match update.outputs {
        Some(Cause::Frame(_)) => {
            outputs.push((message, true, targets.clone(), now));
            run.frame_targets.push(targets);
        }
        Some(Cause::Rest | Cause::Show(_)) => {
            outputs.push((message, false, targets.clone(), now));
            run.rest_targets.push(targets);
        }
        None => {}
    }
    if let Some(reply) = update.reply {
        run.replies.push(reply);
    }
}

/// A native replay of a session that follows the board's fail-safe trips.
#[derive(Debug)]
pub struct Followed {
    /// The native run, with the trips.
    pub run: Run,
    /// The trips followed: `(session message index, ticks)`, each a run of
    /// fail-safe ticks the board reported just before that message.
    pub trips: Vec<(usize, u32)>,
    /// Trips the board reported that no message of the session ended (not
    /// followed).
    pub unplaced: usize,
    /// Outputs compared: up to the last frame-driven one (the easing after
    /// the session is not compared).
    pub compared: usize,
    /// The outputs compared that differ from the board's, or that the
    /// board did not send.
    pub mismatches: usize,
    /// The board-clock time of each output of the replay, in order (see
    /// [`simulate_timed`]): the times of the board's outputs where they
    /// match.
    pub times: Vec<u32>,
}

/// The sequence number of each session message that carries one (compact
/// frames' extended as the board extends them).
pub fn session_seqs(session: &[Sent]) -> Vec<Option<u32>> {
    let mut last = None;
    session
        .iter()
        .map(|sent| {
            let seq = decode_replies(&sent.bytes)
                .iter()
                .find_map(|m| message_seq(m, last));
            if seq.is_some() {
                last = seq;
            }
            seq
        })
        .collect()
}

/// The host sequence number a message carries, if any.
fn message_seq(msg: &Message, last: Option<u32>) -> Option<u32> {
    match msg {
        Message::TrackerFrame(f) => Some(f.seq),
        Message::Params(p) => Some(p.seq),
        Message::Command(c) => Some(c.seq),
        Message::CompactFrame(c) => Some(wire::compact::extend_seq(last, c.seq16())),
        _ => None,
    }
}

/// The fail-safe trips the board reported in its telemetry, in order: each
/// `Telemetry` whose trip count went up carries the last trip that ended
/// (the board sends one right after the frame that ends a trip).
#[must_use]
pub fn reported_trips(replies: &[Message]) -> Vec<Trip> {
    let mut seen = 0;
    let mut out = Vec::new();
    for m in replies {
        if let Message::Telemetry(t) = m
            && t.trips > seen
            && t.last_trip.ticks > 0
        {
            seen = t.trips;
            if out.last() != Some(&t.last_trip) {
                out.push(t.last_trip);
            }
        }
    }
    out
}

/// Replays `session` natively against the board's servo outputs `board`
/// (all of them, in order), following the fail-safe trips the board
/// reported in `replies` (its telemetry: the message that ended each trip
/// and how many fail-safe ticks it lasted). The board's clock is real: a
/// host that stalls longer than the rig's time-out makes it ease towards
/// rest mid-stream, rightly; the replay runs the same ticks before the same
/// message and must then match bit for bit. Every output that differs is
/// a mismatch, and counted.
pub fn follow(
    region_bytes: &[u8],
    session: &[Sent],
    board: &[Vec<u16>],
    replies: &[Message],
) -> Result<Followed, PerformError> {
    let seqs = session_seqs(session);
    let mut trips = Vec::new();
    let mut unplaced = 0;
    for trip in reported_trips(replies) {
        match seqs.iter().position(|s| *s == Some(trip.seq)) {
            Some(i) => trips.push((i, trip.ticks)),
            None => unplaced += 1,
        }
    }
    let (run, outputs) = replay(region_bytes, session, Some(&trips), &mut |_, _| {})?;
    let span = outputs.iter().rposition(|o| o.1).map_or(0, |k| k + 1);
    let mismatches = (0..span)
        .filter(|&k| board.get(k) != outputs.get(k).map(|o| &o.2))
        .count();
    Ok(Followed {
        run,
        trips,
        unplaced,
        compared: span,
        mismatches,
        times: outputs.iter().map(|o| o.3).collect(),
    })
}

/// What the emulated board's servo link carries for a region's rig.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ServoFormat {
    /// Pololu Maestro Set Target commands, `channels` per output.
    Maestro {
        /// Channels per output frame.
        channels: usize,
    },
    /// Bus servo Sync Writes ([`marionette_core::output::bus`]).
    Bus {
        /// The packet format.
        protocol: Protocol,
        /// The bus id of each channel (`None`: no servo).
        ids: Vec<Option<u8>>,
    },
}

impl ServoFormat {
    /// The format of a region's rig, `channels` per output frame (`None`
    /// without a rig, or for an output that is not on a UART).
    #[must_use]
    pub fn of_region(region_bytes: &[u8], channels: usize) -> Option<Self> {
        let region = Region::parse(region_bytes);
        let rig = region.rig.as_ref()?;
        let mut ids = vec![None; channels];
        for s in rig.servos() {
            if let Some(slot) = ids.get_mut(usize::from(s.channel)) {
                *slot = Some(s.id);
            }
        }
        match rig.output() {
            RigOutput::Maestro { .. } => Some(Self::Maestro { channels }),
            RigOutput::Dynamixel { .. } => Some(Self::Bus {
                protocol: Protocol::Dynamixel,
                ids,
            }),
            RigOutput::Feetech { series, .. } => Some(Self::Bus {
                protocol: Protocol::Feetech(series),
                ids,
            }),
            RigOutput::Pwm { .. } | RigOutput::Pca9685 { .. } => None,
        }
    }

    /// At least how many bytes `frames` frame-driven outputs put on the
    /// link.
    #[must_use]
    pub fn bytes_for(&self, frames: usize) -> usize {
        match self {
            Self::Maestro { channels } => frames * channels * 4,
            Self::Bus { protocol, ids } => {
                let n = ids.iter().flatten().count();
                frames * protocol.frame_bytes(n)
            }
        }
    }

    /// The targets as they go on the link: a bus servo's position is
    /// whole, so its quarter units are rounded to a multiple of 4.
    #[must_use]
    pub fn wire(&self, targets: &[u16]) -> Vec<u16> {
        match self {
            Self::Maestro { .. } => targets.to_vec(),
            Self::Bus { .. } => targets
                .iter()
                .map(|&q| bus::position(q).saturating_mul(4))
                .collect(),
        }
    }

    /// Splits the link's bytes into output frames of targets by channel
    /// (bus positions as quarter units: `position · 4`).
    #[must_use]
    pub fn decode(&self, bytes: &[u8]) -> Vec<Vec<u16>> {
        match self {
            Self::Maestro { channels } => decode_maestro(bytes, *channels),
            Self::Bus { protocol, ids } => decode_bus(*protocol, ids, bytes),
        }
    }
}

/// Bus servo packets as output frames: each Goal Position Sync Write is a
/// frame (servos without a position: 0), and a Torque Enable = 0 to every
/// servo that no Goal Position follows is a frame of zeros (the release).
fn decode_bus(protocol: Protocol, ids: &[Option<u8>], bytes: &[u8]) -> Vec<Vec<u16>> {
    let (torque_at, goal_at) = match protocol {
        Protocol::Dynamixel => (dynamixel::TORQUE_ENABLE, dynamixel::GOAL_POSITION),
        Protocol::Feetech(_) => (
            u16::from(feetech::TORQUE_ENABLE),
            u16::from(feetech::GOAL_POSITION),
        ),
    };
    let packets = bus_packets(protocol, bytes);
    let mut frames = Vec::new();
    for (i, (address, items)) in packets.iter().enumerate() {
        let next_is_goal = packets.get(i + 1).is_some_and(|(a, _)| *a == goal_at);
        if *address == goal_at {
            let mut frame = vec![0u16; ids.len()];
            for (id, value) in items {
                if let Some(ch) = ids.iter().position(|x| *x == Some(*id)) {
                    frame[ch] = value.saturating_mul(4);
                }
            }
            frames.push(frame);
        } else if *address == torque_at
            && !next_is_goal
            && items.iter().all(|(_, v)| *v == 0)
            && items.len() == ids.iter().flatten().count()
        {
            frames.push(vec![0u16; ids.len()]);
        }
    }
    frames
}

/// The Sync Writes in a byte stream: (address, (id, value)…), values of
/// one byte or a 2/4-byte position in the bus' byte order. Stops at the
/// first byte that does not start a valid packet.
fn bus_packets(protocol: Protocol, mut bytes: &[u8]) -> Vec<(u16, Vec<(u8, u16)>)> {
    let mut out = Vec::new();
    loop {
        let parsed = match protocol {
            Protocol::Dynamixel => dynamixel_packet(bytes),
            Protocol::Feetech(series) => feetech_packet(series, bytes),
        };
        let Some((packet, rest)) = parsed else {
            return out;
        };
        out.push(packet);
        bytes = rest;
    }
}

type Packet = (u16, Vec<(u8, u16)>);

/// One Protocol 2.0 Sync Write (no stuffing: positions never need it).
fn dynamixel_packet(b: &[u8]) -> Option<(Packet, &[u8])> {
    if b.get(..5)? != [0xFF, 0xFF, 0xFD, 0x00, 0xFE] {
        return None;
    }
    let len = usize::from(u16::from_le_bytes([*b.get(5)?, *b.get(6)?]));
    let end = 7 + len;
    let packet = b.get(..end)?;
    let crc = u16::from_le_bytes([*packet.get(end - 2)?, *packet.get(end - 1)?]);
    if dynamixel::crc16(packet.get(..end - 2)?) != crc || *packet.get(7)? != dynamixel::SYNC_WRITE {
        return None;
    }
    let address = u16::from_le_bytes([*packet.get(8)?, *packet.get(9)?]);
    let data_len = usize::from(u16::from_le_bytes([*packet.get(10)?, *packet.get(11)?]));
    let items = packet
        .get(12..end - 2)?
        .chunks_exact(data_len + 1)
        .map(|c| {
            let mut v = [0u8; 4];
            for (d, s) in v.iter_mut().zip(c.get(1..).unwrap_or(&[])) {
                *d = *s;
            }
            (c[0], u32::from_le_bytes(v).min(u32::from(u16::MAX)) as u16)
        })
        .collect();
    Some(((address, items), b.get(end..)?))
}

/// One Feetech Sync Write.
fn feetech_packet(series: FeetechSeries, b: &[u8]) -> Option<(Packet, &[u8])> {
    if b.get(..3)? != [0xFF, 0xFF, 0xFE] {
        return None;
    }
    let len = usize::from(*b.get(3)?);
    let end = 4 + len;
    let packet = b.get(..end)?;
    let sum = packet
        .get(2..end - 1)?
        .iter()
        .fold(0u8, |s, &x| s.wrapping_add(x));
    if !sum != *packet.get(end - 1)? || *packet.get(4)? != feetech::SYNC_WRITE {
        return None;
    }
    let address = u16::from(*packet.get(5)?);
    let data_len = usize::from(*packet.get(6)?);
    let items = packet
        .get(7..end - 1)?
        .chunks_exact(data_len + 1)
        .map(|c| {
            let value = match (data_len, series) {
                (2, FeetechSeries::Sts) => u16::from_le_bytes([c[1], c[2]]),
                (2, FeetechSeries::Scs) => u16::from_be_bytes([c[1], c[2]]),
                _ => u16::from(c[1]),
            };
            (c[0], value)
        })
        .collect();
    Some(((address, items), b.get(end..)?))
}

/// Messages of a [`session`] up to and including its `Arm` (`Hello`, `Arm`).
pub const OPENING: usize = 2;

/// The longest the emulated board may take to answer `Hello` and `Arm`: it
/// answers at once (a few ms), so this only bounds a board that hangs.
pub const ANSWER_TIMEOUT: Duration = Duration::from_secs(10);

/// Whether the board's replies so far hold the answer to `Arm` (sequence 0).
fn arm_answered(bytes: &[u8]) -> bool {
    decode_replies(bytes)
        .iter()
        .any(|m| matches!(m, Message::Ack(a) if a.seq == 0))
}

/// Whether the replies hold an `Ack` of `Arm` that says yes.
fn arm_accepted(bytes: &[u8]) -> bool {
    decode_replies(bytes)
        .iter()
        .any(|m| matches!(m, Message::Ack(a) if a.seq == 0 && a.ok))
}

/// Runs a session on the emulated board with `region_file` in its table
/// region. `channels` is the number of servo channels per output frame (the
/// rig's highest channel + 1) and `frames` the number of frame-driven
/// outputs expected. Messages are sent as `pacing` says; the last one (the
/// `Disarm`) is sent after the board has answered every frame and a further
/// `pause` (a pause longer than the fail-safe time-out exercises it).
///
/// The board answers `Hello` and `Arm` first ([`OPENING`], within
/// [`ANSWER_TIMEOUT`]). If it refuses to arm, the frames are not sent (it
/// would drive nothing): the session ends with its `Disarm`, and the run's
/// replies say why (see [`crate::refusal`]). If it never answers, QEMU is
/// stopped and the replies are empty. A board that exits with an error or
/// resets is reported in [`Run::fault`]. The servo link is decoded by the
/// rig's output ([`ServoFormat`]).
pub fn emulate(
    region_file: &Path,
    session: &[Sent],
    channels: usize,
    frames: usize,
    pacing: Pacing,
    pause: Duration,
) -> Result<(Run, Vec<u8>), PerformError> {
    emulate_watched(
        region_file,
        session,
        channels,
        frames,
        pacing,
        pause,
        &|_| (),
    )
}

/// [`emulate`], showing `watch` the board's links ([`qemu::Taps`]) after
/// every message sent and every look while waiting for the servo bytes.
pub fn emulate_watched(
    region_file: &Path,
    session: &[Sent],
    channels: usize,
    frames: usize,
    pacing: Pacing,
    pause: Duration,
    watch: &dyn Fn(&qemu::Taps),
) -> Result<(Run, Vec<u8>), PerformError> {
    let region_bytes = std::fs::read(region_file).map_err(|source| PerformError::Io {
        path: region_file.display().to_string(),
        source,
    })?;
    let format = ServoFormat::of_region(&region_bytes, channels)
        .unwrap_or(ServoFormat::Maestro { channels });
    let elf = qemu::firmware_elf("perform")?;
    let span = session.last().map_or(0, |l| {
        let first = session.first().map_or(0, |f| f.time_us);
        l.time_us.wrapping_sub(first)
    });
    let streaming = match pacing {
        Pacing::RealTime => Duration::from_micros(u64::from(span)),
        Pacing::AsFastAsPossible => Duration::ZERO,
    };
    let config = Config {
        tables: Some(region_file.to_path_buf()),
        timeout: Duration::from_secs(120) + streaming + pause,
        ..Config::new(elf)
    };
    let mut emulator = qemu::Emulator::start(&config)?;
    let (body, last) = session.split_at(session.len().saturating_sub(1));
    let (opening, frames_part) = body.split_at(OPENING.min(body.len()));
    pace(opening, pacing, |bytes| emulator.send(bytes))?;
    let answered = emulator.wait_replies_within(arm_answered, ANSWER_TIMEOUT)?;
    if !answered {
        let replies = decode_replies(&emulator.replies_so_far());
        let run = Run {
            replies,
            fault: Some(format!(
                "it did not answer Hello and Arm within {} s",
                ANSWER_TIMEOUT.as_secs()
            )),
            ..Run::default()
        };
        return Ok((run, Vec::new()));
    }
    if arm_accepted(&emulator.replies_so_far()) {
        let progress = crate::progress::Progress::new(true);
        progress.stage("emulated board: servo frames", frames);
        let per_frame = format.bytes_for(1).max(1);
        let taps = emulator.taps();
        pace(frames_part, pacing, |bytes| {
            emulator.send(bytes)?;
            progress.set(emulator.servo_bytes() / per_frame);
            watch(&taps);
            Ok::<(), qemu::QemuError>(())
        })?;
        // Let the board finish the frames before it is told to stop.
        emulator.wait_servo_bytes_with(format.bytes_for(frames), &|got| {
            progress.set(got / per_frame);
            watch(&taps);
        })?;
        progress.finish();
        std::thread::sleep(pause);
    }
    for sent in last {
        emulator.send(&sent.bytes)?;
    }
    let out = emulator.finish()?;
    let mut targets = format.decode(&out.servo);
    let rest = targets.split_off(frames.min(targets.len()));
    let replies = decode_replies(&out.tracker);
    let fault = board_fault(&out);
    Ok((
        Run {
            frame_targets: targets,
            rest_targets: rest,
            replies,
            board_stack: crate::icount::stack_bytes(&out.console),
            fault,
            short_frames: 0,
        },
        out.servo,
    ))
}

/// How a finished emulated board stopped on a fault, if it did.
fn board_fault(out: &qemu::Output) -> Option<String> {
    let boots = out.console.lines().filter(|l| l.trim() == "boot").count();
    match out.status {
        Some(0) if boots <= 1 => None,
        Some(0) => Some(format!(
            "it reset during the session (booted {boots} times)"
        )),
        Some(2) => Some("its serial links failed (exit status 2)".into()),
        Some(n) => Some(format!("the firmware exited with status {n}")),
        None => Some("QEMU was killed by a signal".into()),
    }
}

/// Splits a Maestro Set Target byte stream into output frames of `channels`
/// targets each (a trailing partial frame is dropped).
#[must_use]
pub fn decode_maestro(bytes: &[u8], channels: usize) -> Vec<Vec<u16>> {
    let commands: Vec<u16> = bytes
        .chunks_exact(4)
        .filter_map(|c| <[u8; 4]>::try_from(c).ok())
        .filter_map(maestro::decode_set_target)
        .map(|(_, target)| target)
        .collect();
    commands
        .chunks_exact(channels.max(1))
        .map(<[u16]>::to_vec)
        .collect()
}

/// Decodes the board's replies from the tracker link.
#[must_use]
pub fn decode_replies(bytes: &[u8]) -> Vec<Message> {
    bytes
        .split(|b| *b == 0)
        .filter(|f| !f.is_empty())
        .filter_map(|f| {
            let mut buf = f.to_vec();
            let n = wire::cobs::decode(f, &mut buf).ok()?;
            wire::decode_frame(buf.get(..n)?).ok()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ended(status: Option<i32>, console: &str) -> qemu::Output {
        qemu::Output {
            status,
            console: console.into(),
            diagnostics: String::new(),
            tracker: Vec::new(),
            servo: Vec::new(),
        }
    }

    #[test]
    fn a_board_that_ends_badly_is_a_fault() {
        assert_eq!(board_fault(&ended(Some(0), "boot\nstack 100\n")), None);
        let reset = board_fault(&ended(Some(0), "boot\nboot\n")).unwrap();
        assert!(reset.contains("reset"), "{reset}");
        let link = board_fault(&ended(Some(2), "boot\n")).unwrap();
        assert!(link.contains("serial links"), "{link}");
        assert!(
            board_fault(&ended(None, "boot\n"))
                .unwrap()
                .contains("signal")
        );
    }

    #[test]
    fn the_arm_answer_is_read_from_the_replies() {
        let mut bytes = encode(&Message::Status(marionette_core::wire::Status {
            protocol_version: PROTOCOL_VERSION,
            armed: false,
            table_ok: false,
            reason: marionette_core::wire::StatusReason::NoTable,
            errors: marionette_core::wire::ErrorCounters::default(),
            frames_ok: 1,
            request_seq: None,
            state: marionette_core::wire::State::Unready,
            trips: 0,
            show: marionette_core::wire::ShowState::None,
            show_refusals: 0,
        }))
        .unwrap();
        assert!(!arm_answered(&bytes));
        let no = encode(&Message::Ack(wire::Ack { seq: 0, ok: false })).unwrap();
        bytes.extend_from_slice(&no);
        assert!(arm_answered(&bytes) && !arm_accepted(&bytes));
        let yes = encode(&Message::Ack(wire::Ack { seq: 0, ok: true })).unwrap();
        assert!(arm_accepted(&yes));
    }
}
