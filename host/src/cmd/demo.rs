//! `marionette demo`: the whole pipeline in one command, on real data.
//!
//! 1. **Build** the reach table for the humanoid16 puppet from HDM05 mocap
//!    (`data/builds/reach_humanoid16.toml`: right-palm position grid, five
//!    reaching clips retargeted onto `rigs/humanoid16.toml`) and check that
//!    the rig and table arm the board (`Region::parse`: rig hash, segment
//!    count and kind match).
//! 2. **Perform** a held-out take (`data/recordings/reach_hdm05_007.csv`, an
//!    HDM05 grab the table was not built from, as three 1 kHz trackers:
//!    right palm, left palm, pelvis) on the emulated board: boot the
//!    `perform` firmware on QEMU with rig + table in its table region, stream
//!    the session over the tracker link, decode the Maestro servo commands
//!    (as `marionette emulate`), and compare every output frame with the
//!    core run natively on the same bytes. Any difference is an error (exit
//!    status 1).
//! 3. **Draw**: the servo curves the board sent, and the figure (the native
//!    core's solved pose, with its goals) at a few times, in four views.
//!
//! `--layers` performs two layers instead of the reach table alone
//! ([`layered_region`]): the walk clip table (`--walk-spec`, default
//! `data/builds/walk_humanoid16.toml`) plays on the legs, the left arm and
//! the torso, its speed ramping from the table's slowest walk to its run over
//! the take, while the reach grid drives the right arm (and half of the torso
//! and head) from the tracked hand, and the solver puts the hand on it. The
//! rest is the same: the emulated board against the native core, bit for bit.
//!
//! Written to `--out` (default `out/`): `SPEC_STEM.bin`, e.g. `reach_humanoid16.bin` (the table
//! blob), `region.bin` (rig + table, as flashed), `servo_emulated.csv`
//! (`time_us,ch0..ch15`, µs), `servo_emulated.png`, and `frame_<k>.png`.

use super::CmdError;
use super::emulate::{BOARD, Compared};
use super::sim::{self, Inputs};
use crate::board;
use crate::build::{self, Built, Progress, spec};
use crate::import::csv::read_tracker_csv;
use crate::perform::{self, Pacing, Run};
use crate::refusal;
use crate::render::{self, Figure, Mark, PlotOptions, Series};
use crate::rigfile;
use glam::{DQuat, DVec3};
use marionette_core::frame::{Cause, Region};
use marionette_core::goal::{Attach, Frame, GoalSet, Target};
use marionette_core::pose::{MAX_SEGMENTS, Pose};
use marionette_core::rig::{MAX_PARAMS, Rig};
use marionette_core::wire::{ErrorCounters, MAX_GOALS, Message, StatusReason, TrackerFrame};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `marionette demo`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The table's build spec (docs/spec.md). The defaults of `--spec`,
    /// `--rig` and `--recording` (and the mocap the spec reads) are built
    /// into marionette: a path that does not exist here is looked up there.
    #[arg(long, default_value = "data/builds/reach_humanoid16.toml")]
    pub spec: PathBuf,
    /// The rig file (TOML; docs/rig.md), or a rig name: `rigs/<name>.toml`
    /// here, else a rig built in (humanoid16, cmu31).
    #[arg(long, default_value = "rigs/humanoid16.toml")]
    pub rig: PathBuf,
    /// The tracker recording (CSV; docs/recording.md).
    #[arg(long, default_value = "data/recordings/reach_hdm05_007.csv")]
    pub recording: PathBuf,
    /// Where to write the table, servo curves and pictures.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// How many frames of the figure to draw (evenly spaced in time).
    #[arg(long, default_value_t = 4)]
    pub frames: usize,
    /// Also save the session as a take (docs/take.md): the input sent,
    /// the board's outputs and replies, with times.
    #[arg(long)]
    pub take: Option<PathBuf>,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
    /// The live view (`--view`, `--listen`).
    #[command(flatten)]
    pub view: super::view::ViewArgs,
    /// Perform two layers ([`layered_region`]): the walk table of
    /// `--walk-spec` on the legs (its speed ramping from the table's slowest
    /// to its fastest over the take) while the right arm follows the tracked
    /// hand with the reach table of `--spec` (plus the solve).
    #[arg(long)]
    pub layers: bool,
    /// The walk (clip) table's build spec, for `--layers`.
    #[arg(long, default_value = "data/builds/walk_humanoid16.toml")]
    pub walk_spec: PathBuf,
}

/// Segments each layer of `demo --layers` owns, with their mask weight
/// (255 = 1). Walk: the legs and the left arm's swing, the torso; the
/// pelvis stays at rest (the puppet is on a stand, and the walk's travel is
/// dropped). Reach: the right arm, and half of the torso and the head over
/// the walk's.
pub const DEMO_MASKS: [(&str, &[(&str, u8)]); 2] = [
    (
        "walk",
        &[
            ("torso", 255),
            ("head", 255),
            ("l_upper_arm", 255),
            ("l_forearm", 255),
            ("l_thigh", 255),
            ("l_shin", 255),
            ("l_foot", 255),
            ("r_thigh", 255),
            ("r_shin", 255),
            ("r_foot", 255),
        ],
    ),
    (
        "reach",
        &[
            ("torso", 128),
            ("head", 128),
            ("r_upper_arm", 255),
            ("r_forearm", 255),
        ],
    ),
];

/// The goals `demo --layers` switches off (by segment): the left hand's and
/// the feet's, so that the legs and the left arm walk (in the air, on the
/// stand) instead of being held on the left tracker and the floor; the
/// right hand stays on its tracker.
pub const DEMO_GOALS_OFF: [&str; 3] = ["l_forearm", "l_foot", "r_foot"];

/// Sets the weight of the rig's goals on `segments` to 0 at the start of
/// `session` (`Hello`, `Arm` numbered 0, the frames from 1, …):
/// `SetGoalWeight` commands sent with the `Hello` (in the same write, so
/// that the session still opens with `Hello` and `Arm`), numbered just below
/// the `Arm`'s 0 (the sequence wraps from `u32::MAX` to 0).
fn goals_off(
    rig: &marionette_core::rig::RigDesc<'_>,
    segments: &[&str],
    session: &mut [perform::Sent],
) -> Result<(), CmdError> {
    use marionette_core::wire::{Command, CommandKind};
    let names = rig.segments.as_slice();
    let goals: Vec<u8> = rig
        .goals
        .as_slice()
        .iter()
        .enumerate()
        .filter(|(_, g)| {
            names
                .get(usize::from(g.segment))
                .is_some_and(|s| segments.contains(&s.name))
        })
        .map(|(i, _)| u8::try_from(i).unwrap_or(u8::MAX))
        .collect();
    let n = u32::try_from(goals.len()).unwrap_or(0);
    let Some(hello) = session.first_mut() else {
        return Err("demo --layers: the session is empty".into());
    };
    for (k, goal) in (0u32..).zip(goals) {
        let cmd = Message::Command(Command {
            seq: 0u32.wrapping_sub(n - k),
            kind: CommandKind::SetGoalWeight { goal, weight: 0.0 },
        });
        hello.bytes.extend(perform::frame_bytes(&cmd)?);
    }
    Ok(())
}

/// A layer mask over `segments` from `(name, weight)` pairs (others 0).
fn mask(segments: &[String], owned: &[(&str, u8)]) -> Result<Vec<u8>, CmdError> {
    let mut m = vec![0u8; segments.len()];
    for (name, w) in owned {
        let i = segments
            .iter()
            .position(|s| s == name)
            .ok_or_else(|| format!("demo --layers: the rig has no segment `{name}`"))?;
        m[i] = *w;
    }
    Ok(m)
}

/// The region of `demo --layers`: the rig, table 0 the reach grid
/// (`reach_blob`, parameters the rig's 0-2, the tracked right hand), table 1
/// the walk clips (`walk_blob`), and the layer list: layer 0 the walk
/// (speed ramping from the table's slowest to its fastest over
/// `ramp_seconds`, root travel dropped, 0.25 s cross-fade), layer 1 the
/// reach over it ([`DEMO_MASKS`]). The same layers as a rig file's
/// `[[layer]]` tables, laid out by [`rigfile::region`].
pub fn layered_region(
    rig: &rigfile::RigFile,
    reach_blob: &[u8],
    walk_blob: &[u8],
    ramp_seconds: f32,
) -> Result<Vec<u8>, CmdError> {
    use marionette_core::layer::{Root, Source};
    let walk = marionette_core::table::Table::parse(walk_blob)
        .map_err(|e| format!("the walk table: {e}"))?;
    let [speed] = walk.param_axes() else {
        return Err("demo --layers: the walk table must have one parameter axis (speed)".into());
    };
    let fastest = speed.min + speed.step * f32::from(speed.count.saturating_sub(1));
    let segments = rig.segment_names();
    let layer = |(name, owned): (&str, &[(&str, u8)]), table, params| {
        Ok::<_, CmdError>(rigfile::LayerSpec {
            name: name.into(),
            line: 0,
            table,
            root: Root::Drop,
            fade_s: 0.25,
            weight: Source::Const(1.0),
            rate: Source::Const(1.0),
            params,
            mask: mask(segments, owned)?,
        })
    };
    let ramp = Source::Ramp {
        from: speed.min,
        to: fastest,
        seconds: ramp_seconds,
    };
    let hand = (0..3).map(Source::Param).collect();
    let mut layered = rig.clone();
    layered.layers = vec![
        layer(DEMO_MASKS[0], 1, vec![ramp])?,
        layer(DEMO_MASKS[1], 0, hand)?,
    ];
    let given = [
        ("the reach table", reach_blob),
        ("the walk table", walk_blob),
    ]
    .map(|(name, blob)| rigfile::Given {
        name: name.into(),
        blob,
    });
    Ok(rigfile::region(&layered, &given)?)
}

/// A path as given if it exists, else the file of that repository path
/// built into marionette (the demo's spec, the mocap it reads, its recording
/// and the bundled rigs; see [`crate::bundle`]), so the defaults work from
/// any folder.
#[must_use]
pub fn repo_path(p: &Path) -> PathBuf {
    if p.exists() || p.is_absolute() {
        return p.to_path_buf();
    }
    match crate::bundle::file(p) {
        Some(Ok(there)) => there,
        _ => p.to_path_buf(),
    }
}

/// Builds the table of a spec (no progress bar), checking first that the
/// emulated board's table region can hold it.
pub fn build_table(spec_path: &Path) -> Result<Built, CmdError> {
    build_table_with(spec_path, &Progress::new(false))
}

/// As [`build_table`], reporting its stages on `progress`.
pub fn build_table_with(spec_path: &Path, progress: &Progress) -> Result<Built, CmdError> {
    let spec = spec::read(spec_path)?;
    crate::capacity::check_spec(&spec, Some(&board::EMULATED))?;
    let data = build::load(&spec, progress)?;
    crate::capacity::check_dataset(&spec, &data, Some(&board::EMULATED))?;
    let built = build::build(&spec, &data, None, progress)?;
    progress.finish();
    Ok(built)
}

/// The region image and session of a rig file, a table blob and a recording.
pub fn inputs(rig: &Path, table: &[u8], recording: &Path) -> Result<Inputs, CmdError> {
    let rig_path = rigfile::resolve(rig);
    let rig = rigfile::load(&rig_path)?;
    let rig_blob = rigfile::to_blob(&rig)?;
    let samples = read_tracker_csv(recording)?;
    let frames = perform::frames(&samples)?;
    Ok(Inputs {
        region: perform::region(&rig_blob, Some(table)),
        session: perform::session(&frames)?,
        frames: frames.len(),
        times: frames.iter().map(|f| f.time_us).collect(),
        period_us: rig.desc().frame_period_us,
        sources: vec![
            ("the rig", rig_path),
            ("the recording", recording.to_path_buf()),
        ],
    })
}

/// A native run with the solved poses of chosen frames.
#[derive(Debug)]
pub struct Native {
    /// Whether the board can arm with this region, and why not.
    pub reason: StatusReason,
    /// The servo targets.
    pub run: Run,
    /// `(sequence number, solved world pose)` of the sampled frames.
    pub poses: Vec<(u32, Pose<MAX_SEGMENTS>)>,
    /// Frames whose parameters were clamped or projected into the table.
    pub adjusted: u32,
    /// Frames dropped because synthesis or solving failed.
    pub failed: u32,
}

/// Runs the session natively, keeping the poses of the frames `sample`
/// (sequence numbers, from 1).
pub fn native(inputs: &Inputs, sample: &[u32]) -> Result<Native, CmdError> {
    let reason = Region::parse(&inputs.region).reason;
    let mut poses = Vec::new();
    let (mut adjusted, mut failed) = (0, 0);
    let run = perform::simulate_with(&inputs.region, &inputs.session, &mut |p, u| {
        if let (Some(Cause::Frame(seq)), Some(pose)) = (u.outputs, p.pose())
            && sample.contains(&seq)
        {
            poses.push((seq, *pose));
        }
        adjusted = p.adjusted_frames();
        failed = p.failed_frames();
    })?;
    Ok(Native {
        reason,
        run,
        poses,
        adjusted,
        failed,
    })
}

/// Evenly spaced frame sequence numbers (1-based) out of `frames`.
#[must_use]
pub fn sample_frames(frames: usize, count: usize) -> Vec<u32> {
    let last = frames.saturating_sub(1);
    let count = count.min(frames);
    (0..count)
        .map(|k| {
            let i = (k * last + (count - 1).max(1) / 2) / (count - 1).max(1);
            u32::try_from(i + 1).unwrap_or(u32::MAX)
        })
        .collect()
}

/// One servo's range over the performance.
#[derive(Debug, Serialize)]
pub struct ServoRange {
    /// Output channel.
    pub channel: u8,
    /// The joint and DOF axis it turns (`r_forearm.x`).
    pub joint: String,
    /// Lowest and highest target sent, µs.
    pub sent_us: [f64; 2],
    /// The pulses of the joint's limits (the most the solver may ask), µs.
    pub limits_us: [f64; 2],
}

/// What `demo --layers` performed.
#[derive(Debug, Serialize)]
pub struct LayersSummary {
    /// The walk table's build spec.
    pub walk_spec: String,
    /// Walk table blob bytes (written as `SPEC_STEM.bin` beside the reach table).
    pub walk_table_bytes: usize,
    /// The walk speed ramp: from, to (the table's speed axis), over seconds.
    pub speed_ramp: [f64; 3],
    /// Each layer in blend order: name, table entry, and the segments it
    /// owns with their mask weight (0..1).
    pub layers: Vec<LayerInfo>,
}

/// One layer of `demo --layers`.
#[derive(Debug, Serialize)]
pub struct LayerInfo {
    /// `walk` or `reach`.
    pub name: String,
    /// Index among the region's table entries.
    pub table: u8,
    /// `(segment, weight)` for the segments with a non-zero mask.
    pub mask: Vec<(String, f64)>,
}

/// Turns the demo's `inputs` (of [`inputs`]) into those of `demo --layers`:
/// the region becomes [`layered_region`] with the walk speed ramping over
/// the take, and the session switches the goals of [`DEMO_GOALS_OFF`] off.
/// Returns the ramp's length, seconds.
pub fn make_layered(
    inputs: &mut Inputs,
    rig_path: &Path,
    reach_blob: &[u8],
    walk_blob: &[u8],
) -> Result<f32, CmdError> {
    let rig = rigfile::load(&rigfile::resolve(rig_path))?;
    let span_us = match (inputs.times.first(), inputs.times.last()) {
        (Some(a), Some(b)) => b.wrapping_sub(*a),
        _ => 0,
    };
    let seconds = (span_us as f32 * 1e-6).max(0.1);
    inputs.region = layered_region(&rig, reach_blob, walk_blob, seconds)?;
    goals_off(&rig.desc(), &DEMO_GOALS_OFF, &mut inputs.session)?;
    Ok(seconds)
}

/// Builds the walk table and replaces the region of `inputs` by the
/// layered one ([`layered_region`]), the speed ramping over the take.
fn use_layers(
    args: &Args,
    rig_path: &Path,
    reach_blob: &[u8],
    inputs: &mut Inputs,
) -> Result<LayersSummary, CmdError> {
    let walk_spec = repo_path(&args.walk_spec);
    let walk = build_table(&walk_spec)?;
    let stem = walk_spec
        .file_stem()
        .map_or_else(|| "walk".to_string(), |s| s.to_string_lossy().into_owned());
    crate::save::save(
        &args.out.join(format!("{stem}.bin")),
        &walk.blob,
        &[("the spec", walk_spec.as_path())],
    )?;
    let seconds = make_layered(inputs, rig_path, reach_blob, &walk.blob)?;
    let table = marionette_core::table::Table::parse(&walk.blob)
        .map_err(|e| format!("the walk table: {e}"))?;
    let speed = table
        .param_axes()
        .first()
        .copied()
        .ok_or("the walk table has no speed axis")?;
    let fastest = speed.min + speed.step * f32::from(speed.count.saturating_sub(1));
    let layers = DEMO_MASKS
        .iter()
        .zip([1u8, 0])
        .map(|((name, owned), table)| LayerInfo {
            name: (*name).to_string(),
            table,
            mask: owned
                .iter()
                .map(|(s, w)| ((*s).to_string(), f64::from(*w) / 255.0))
                .collect(),
        })
        .collect();
    Ok(LayersSummary {
        walk_spec: walk_spec.display().to_string(),
        walk_table_bytes: walk.blob.len(),
        speed_ramp: [f64::from(speed.min), f64::from(fastest), f64::from(seconds)],
        layers,
    })
}

/// What the demo measured.
#[derive(Debug, Serialize)]
pub struct Summary {
    /// `--layers`: the layers performed (absent without it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub layers: Option<LayersSummary>,
    /// The build spec.
    pub spec: String,
    /// Examples the table was built from, and from how many clips.
    pub examples: usize,
    /// Clips.
    pub clips: usize,
    /// The resampling method cross-validation chose.
    pub method: String,
    /// Valid grid cells of all.
    pub valid_cells: [usize; 2],
    /// Table blob bytes.
    pub table_bytes: usize,
    /// Seconds to build the table.
    pub build_seconds: f64,
    /// `Region::parse` on rig + table: why the board can (not) arm.
    pub arm: String,
    /// Tracker frames streamed.
    pub frames_in: usize,
    /// Servo frames the board sent for them.
    pub frames_out: usize,
    /// Output frames differing from the native core (missing ones count).
    pub mismatches: usize,
    /// Times the board's fail-safe tripped mid-stream (host stalls longer
    /// than the rig's time-out), followed by the native replay.
    pub failsafe_trips: usize,
    /// Easing steps to rest after the last frame (the board's).
    pub rest_steps: usize,
    /// Easing steps to rest natively.
    pub rest_steps_native: usize,
    /// Replies decoded from the board.
    pub replies: usize,
    /// The board's receive errors (last telemetry), summed over counters.
    pub errors: u32,
    /// Frames whose parameters the table had to clamp or project (native).
    pub adjusted_frames: u32,
    /// Frames dropped because synthesis or solving failed (native).
    pub failed_frames: u32,
    /// Tracker frames that may run over the rig's period on the board,
    /// by the native replay ([`crate::perform::Run::short_frames`]).
    pub short_frames: u32,
    /// Median right-hand goal residual over the board's telemetry, mm.
    pub hand_residual_mm: f64,
    /// Per servo.
    pub servos: Vec<ServoRange>,
    /// Files written.
    pub files: Vec<String>,
    /// Wall-clock seconds of the whole demo.
    pub seconds: f64,
    /// Wall-clock seconds on the emulated board (boot included).
    pub board_seconds: f64,
}

/// The sum of a board's receive-error counters.
pub fn error_total(e: &ErrorCounters) -> u32 {
    [
        e.cobs, e.crc, e.decode, e.oversize, e.version, e.lost, e.stale, e.range,
    ]
    .iter()
    .fold(0u32, |a, b| a.saturating_add(*b))
}

/// The last telemetry's error total and the median of goal 0's residuals.
fn telemetry(replies: &[Message]) -> (u32, f64) {
    let mut errors = 0;
    let mut hand: Vec<f64> = Vec::new();
    for r in replies {
        if let Message::Telemetry(t) = r {
            errors = error_total(&t.errors);
            if let Some(x) = t.goal_residuals.iter().next() {
                hand.push(f64::from(*x));
            }
        }
    }
    hand.sort_by(f64::total_cmp);
    let median = hand.get(hand.len() / 2).copied().unwrap_or(f64::NAN);
    (errors, median * 1000.0)
}

/// Every servo's sent range and joint-limit pulses.
fn servo_ranges(rig: &Rig<'_>, run: &Run) -> Vec<ServoRange> {
    let sent = sim::ranges(run);
    let body = rig.body();
    rig.servos()
        .iter()
        .map(|s| {
            let seg = body.segment(usize::from(s.segment));
            let dof = seg.and_then(|g| g.joint.dofs().get(usize::from(s.dof)).copied());
            let cal = s.calibration();
            let limits = dof.map_or([f64::NAN; 2], |d| {
                let (a, b) = (
                    f64::from(cal.pulse_us(d.min)),
                    f64::from(cal.pulse_us(d.max)),
                );
                [a.min(b), a.max(b)]
            });
            let axis = dof.map_or("?", |d| match d.axis {
                marionette_core::body::Axis::X => "x",
                marionette_core::body::Axis::Y => "y",
                marionette_core::body::Axis::Z => "z",
            });
            ServoRange {
                channel: s.channel,
                joint: format!("{}.{axis}", seg.map_or("?", |g| g.name)),
                sent_us: sent
                    .get(usize::from(s.channel))
                    .copied()
                    .unwrap_or([f64::NAN; 2]),
                limits_us: limits,
            }
        })
        .collect()
}

/// The goals of one tracker frame as marks on a pose (the demo's pictures,
/// the live view).
pub fn marks(rig: &Rig<'_>, frame: &TrackerFrame, pose: &Pose<MAX_SEGMENTS>) -> Vec<Mark> {
    let mut params = [0.0f32; MAX_PARAMS];
    let mut goals = GoalSet::<MAX_GOALS>::new();
    let _ = rig.map_sensors(frame.sensors.as_slice(), &mut params, &mut goals);
    let body = rig.body();
    let world: Vec<(DVec3, DQuat)> = pose
        .positions()
        .iter()
        .zip(pose.rotations())
        .map(|(p, q)| (p.as_dvec3(), q.as_dquat()))
        .collect();
    let placed = |i: usize| world.get(i).copied();
    goals
        .as_slice()
        .iter()
        .filter(|g| g.weight > 0.0)
        .filter_map(|g| {
            let seg = usize::from(g.segment);
            let (o, r) = placed(seg)?;
            let from = match g.attach {
                Attach::Touch => render::touch_point(&body, &world, seg)?,
                Attach::Point(p) => o + r * p.as_dvec3(),
            };
            let (fo, fr) = match g.frame {
                Frame::World => (DVec3::ZERO, DQuat::IDENTITY),
                Frame::Segment(s) => placed(usize::from(s))?,
            };
            let target = match g.target {
                Target::Position(t) => fo + fr * t.as_dvec3(),
                Target::Plane { normal, offset, .. } => {
                    let n = (fr * normal.as_dvec3()).normalize();
                    let d = n.dot(from - fo) - f64::from(offset);
                    from - n * d
                }
                Target::Orientation(_) => return None,
            };
            let name = body.segment(seg).map_or("?", |s| s.name);
            Some(Mark {
                target,
                from: Some(from),
                label: format!("{name} ×{}", g.weight),
            })
        })
        .collect()
}

/// Draws the sampled poses: `frame_<k>.png`.
fn draw_frames(
    rig: &Rig<'_>,
    recording: &str,
    frames: &[TrackerFrame],
    poses: &[(u32, Pose<MAX_SEGMENTS>)],
    out: &Path,
) -> Result<Vec<PathBuf>, CmdError> {
    let body = rig.body();
    let first = frames.first().map_or(0, |f| f.time_us);
    let mut files = Vec::new();
    for (k, (seq, pose)) in poses.iter().enumerate() {
        let Some(frame) = frames.iter().find(|f| f.seq == *seq) else {
            continue;
        };
        let t = f64::from(frame.time_us.wrapping_sub(first)) * 1e-6;
        let title = format!(
            "{}, {recording}, t = {t:.2} s (frame {seq} of {}): solved pose and goals",
            rig.name(),
            frames.len()
        );
        let mut fig = Figure::from_pose(&body, pose, title)?;
        fig.goals = marks(rig, frame, pose);
        let path = out.join(format!("frame_{k}.png"));
        render::render(&fig, &path)?;
        files.push(path);
    }
    Ok(files)
}

/// Plots `servo_emulated.csv` into `servo_emulated.png`, each line named
/// by its channel and the joint it turns (`ranges`), titled `title`.
fn plot_servos(csv: &Path, ranges: &[ServoRange], title: String) -> Result<PathBuf, CmdError> {
    let text = std::fs::read_to_string(csv).map_err(|e| format!("{}: {e}", csv.display()))?;
    let mut series = Series::parse_csv(&text).map_err(|e| format!("{}: {e}", csv.display()))?;
    for col in &mut series.columns {
        let channel = col
            .name
            .strip_prefix("ch")
            .and_then(|n| n.parse::<u8>().ok());
        if let Some(r) = ranges.iter().find(|r| Some(r.channel) == channel) {
            col.name = format!("{} {}", col.name, r.joint);
        }
    }
    let path = csv.with_extension("png");
    let opt = PlotOptions {
        title,
        y_label: "pulse (µs)".into(),
        ..PlotOptions::default()
    };
    render::plot(&series, &path, &opt)?;
    Ok(path)
}

/// Runs the demo and prints its summary.
pub fn run(args: &Args) -> Result<(), CmdError> {
    let start = Instant::now();
    let (spec_path, rig_path) = (repo_path(&args.spec), repo_path(&args.rig));
    let recording = repo_path(&args.recording);
    let built = build_table_with(&spec_path, &Progress::new(true))?;
    let build_seconds = start.elapsed().as_secs_f64();
    // Named for the spec it was built from (`reach_humanoid16.toml` ->
    // `reach_humanoid16.bin`).
    let stem = spec_path
        .file_stem()
        .map_or_else(|| "table".to_string(), |s| s.to_string_lossy().into_owned());
    let table_file = args.out.join(format!("{stem}.bin"));
    let recording_name = recording.file_name().map_or_else(
        || recording.display().to_string(),
        |s| s.to_string_lossy().into_owned(),
    );
    crate::save::save(
        &table_file,
        &built.blob,
        &[("the spec", spec_path.as_path())],
    )?;
    let mut inputs = inputs(&rig_path, &built.blob, &recording)?;
    let layers = if args.layers {
        Some(use_layers(args, &rig_path, &built.blob, &mut inputs)?)
    } else {
        None
    };
    if let Some(stop) = refusal::precheck(BOARD, &inputs.region, &board::EMULATED) {
        if args.json {
            let doc = serde_json::json!({ "spec": spec_path.display().to_string(), "board": stop.report() });
            println!("{}", serde_json::to_string_pretty(&doc)?);
        }
        return Err(Box::new(stop));
    }
    let region = Region::parse(&inputs.region);
    let rig = region.rig.as_ref().ok_or("the rig blob is invalid")?;
    let tracker_frames = perform::frames(&read_tracker_csv(&recording)?)?;
    let sample = sample_frames(inputs.frames, args.frames);
    let native = native(&inputs, &sample)?;
    let Compared {
        run: board,
        summary: emulated,
        stop,
        ..
    } = super::view::watched(
        &args.view,
        &inputs.region,
        &format!("{}: {recording_name}", rig.name()),
        &tracker_frames,
        |watch| {
            super::emulate::compare_watched(&inputs, &args.out, Pacing::AsFastAsPossible, watch)
        },
    )?;
    if let Some(stop) = stop {
        if args.json {
            println!("{}", serde_json::to_string_pretty(&emulated)?);
        }
        return Err(Box::new(stop));
    }
    if let Some(path) = &args.take {
        super::emulate::save_take(path, "demo", &inputs, &board)?;
    }
    let servo_csv = PathBuf::from(emulated.servo_csv.clone().unwrap_or_default());
    let mut files = vec![
        table_file.display().to_string(),
        args.out.join("region.bin").display().to_string(),
        servo_csv.display().to_string(),
        plot_servos(
            &servo_csv,
            &servo_ranges(rig, &board),
            format!(
                "{}: servo targets sent by the emulated board ({recording_name})",
                rig.name()
            ),
        )?
        .display()
        .to_string(),
    ];
    let frames = draw_frames(
        rig,
        &recording_name,
        &tracker_frames,
        &native.poses,
        &args.out,
    )?;
    for f in frames {
        files.push(f.display().to_string());
    }
    let (errors, hand_residual_mm) = telemetry(&board.replies);
    let summary = Summary {
        layers,
        spec: spec_path.display().to_string(),
        examples: built.report.examples,
        clips: built.report.groups,
        method: built.report.method.to_string(),
        valid_cells: [built.report.valid_cells, built.report.cells],
        table_bytes: built.blob.len(),
        build_seconds,
        arm: format!("{:?}", region.reason),
        frames_in: inputs.frames,
        frames_out: emulated.frame_outputs,
        mismatches: emulated.mismatches,
        failsafe_trips: emulated.failsafe_trips,
        rest_steps: emulated.rest_steps,
        rest_steps_native: native.run.rest_targets.len(),
        replies: emulated.replies,
        errors,
        adjusted_frames: native.adjusted,
        failed_frames: native.failed,
        short_frames: emulated.short_frames,
        hand_residual_mm,
        servos: servo_ranges(rig, &board),
        files,
        seconds: start.elapsed().as_secs_f64(),
        board_seconds: emulated.seconds,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        print!("{}", text(&summary, inputs.period_us));
        let short = crate::period::note(summary.short_frames, summary.frames_in, &inputs.region);
        if let Some(note) = short {
            eprintln!("{note}");
        }
    }
    if summary.mismatches > 0 {
        return Err("the emulated board's servo output differs from the native core".into());
    }
    Ok(())
}

/// The summary as text.
fn text(s: &Summary, period_us: u32) -> String {
    use std::fmt::Write as _;
    let mut o = String::new();
    let _ = writeln!(
        o,
        "table: {} -> {} examples from {} clips, {}, {}/{} cells valid, {} bytes ({:.1} s)",
        s.spec,
        s.examples,
        s.clips,
        s.method,
        s.valid_cells[0],
        s.valid_cells[1],
        s.table_bytes,
        s.build_seconds
    );
    if let Some(l) = &s.layers {
        let _ = writeln!(
            o,
            "walk table: {} -> {} bytes; speed ramps {:.2} -> {:.2} over {:.2} s",
            l.walk_spec, l.walk_table_bytes, l.speed_ramp[0], l.speed_ramp[1], l.speed_ramp[2]
        );
        for (k, layer) in l.layers.iter().enumerate() {
            let owned: Vec<String> = layer
                .mask
                .iter()
                .map(|(seg, w)| format!("{seg} {w:.2}"))
                .collect();
            let _ = writeln!(
                o,
                "layer {k}: {} (table {}) on {}",
                layer.name,
                layer.table,
                owned.join(", ")
            );
        }
        let _ = writeln!(o, "rig + layers: {} (the board arms)", s.arm);
    } else {
        let _ = writeln!(o, "rig + table: {} (the board arms)", s.arm);
    }
    let _ = writeln!(
        o,
        "emulated board: {} tracker frames in ({:.2} s at {} Hz), {} servo frames out, \
         {} differ from the native core",
        s.frames_in,
        s.frames_in as f64 * f64::from(period_us) * 1e-6,
        1_000_000 / period_us.max(1),
        s.frames_out,
        s.mismatches
    );
    if s.failsafe_trips > 0 {
        let _ = writeln!(
            o,
            "the board's fail-safe tripped {} times mid-stream (the host stalled for longer than \
             the rig's time-out); the native replay followed each",
            s.failsafe_trips
        );
    }
    let _ = writeln!(
        o,
        "after the last frame: {} steps to rest (native {}); {} replies, {} receive errors; \
         {} frames clamped/projected into the table, {} failed; right-hand goal residual \
         median {:.2} mm",
        s.rest_steps,
        s.rest_steps_native,
        s.replies,
        s.errors,
        s.adjusted_frames,
        s.failed_frames,
        s.hand_residual_mm
    );
    let _ = writeln!(
        o,
        "servos (sent range, µs; joint-limit pulses in brackets):"
    );
    for v in &s.servos {
        let _ = writeln!(
            o,
            "  ch{:<2} {:<15} {:>6.1} .. {:>6.1}  [{:>6.1} .. {:>6.1}]",
            v.channel, v.joint, v.sent_us[0], v.sent_us[1], v.limits_us[0], v.limits_us[1]
        );
    }
    let _ = writeln!(o, "wrote:");
    for f in &s.files {
        let _ = writeln!(o, "  {f}");
    }
    let _ = writeln!(
        o,
        "{:.1} s in all ({:.1} s on the emulated board)",
        s.seconds, s.board_seconds
    );
    o
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sampled_frames_are_spread_evenly() {
        assert_eq!(sample_frames(2134, 4), vec![1, 712, 1423, 2134]);
        assert_eq!(sample_frames(10, 1), vec![1]);
        assert_eq!(sample_frames(3, 5), vec![1, 2, 3]);
        assert!(sample_frames(0, 4).is_empty());
    }
}
