//! Mocap clips → retargeted, normalized examples.
//!
//! Each clip is imported ([`crate::import`]), every frame is put through the
//! core's forward kinematics on the imported skeleton and retargeted to the
//! rig ([`super::retarget`]). Then:
//!
//! - **Grid tables**: every `every`-th frame of the chosen ranges is one
//!   example. With `frame = "heading"` each example is expressed in its own
//!   heading frame: origin on the floor (y = 0) below the root, turned about
//!   Y so that the root's forward axis points along +Z. Parameters measured
//!   from a segment (the hand) are its position in that frame, so "hand at
//!   (x, y, z)" means "x to the figure's left, y above the floor, z in front".
//!   `frame = "root"` is the same with the origin at the root joint itself
//!   (y above the root), for parameter maps in the root's frame.
//!   `frame = "stand"` measures the parameters in the root's own frame
//!   (origin at the root joint, axes turning with the root in yaw, pitch and
//!   roll), then places the pose at the rig's rest root placement
//!   ([`Rig::rest_root`]), for a figure whose root is held by a stand.
//!   A parameter's segment position may be that of a point fixed in the
//!   segment (`point`, e.g. a palm centre in the forearm's frame).
//! - **Motion tables**: each clip is cut at `cut = [first, ..., last]` into
//!   phases, expressed in the heading frame of its first frame, and each
//!   phase is time-resampled with [`marionette_core::clip::resample`] to the
//!   common frame count (W&H Fig. 6). A looping clip (one phase, `last` one
//!   period after `first`) is first made "in place": the frame's +Z is the
//!   direction of travel from `first` to `last`, and the root's net
//!   displacement on all three axes (a climb on a slope too) is removed
//!   linearly in time from every position and stored as the cycle's root
//!   travel (the table's `travel` array); then
//!   [`marionette_core::clip::seam_blend`] spreads the remaining mismatch
//!   over the ends. Each phase's duration is its frame span times the frame
//!   time. Parameters: a segment's position at the first phase boundary
//!   (`cut[1]`, the reach pose) or at `first` for a loop; `speed` = the
//!   root's net horizontal travel divided by the clip's duration.

use glam::{DQuat, DVec3, Quat, Vec3};
use marionette_core::clip::{self, Span};
use marionette_core::grid::SliceSamples;
use marionette_core::pose::{self, Pose};

use super::Seg;
use super::error::{BuildError, InputError};
use super::resample::{Record, Value};
use super::retarget::{CAP, Rig};
use super::spec::{AxisSpec, ClipSpec, FrameKind, Measure, MocapSpec, MotionSpec, Spec};
use crate::import::{self, EndSites, ImportError, Motion};

/// One imported, retargeted clip in the mocap's world frame.
#[derive(Debug, Clone)]
pub struct Clip {
    /// Name (file stem).
    pub name: String,
    /// Seconds per frame.
    pub frame_time: f64,
    /// Rig poses per frame.
    pub poses: Vec<Vec<Seg>>,
}

/// The rig and the clips.
#[derive(Debug, Clone)]
pub struct Mocap {
    /// The rig.
    pub rig: Rig,
    /// The clips, in spec order.
    pub clips: Vec<Clip>,
    /// Clips whose frame rate looks wrong (see `rate_warnings`).
    pub warnings: Vec<String>,
}

/// Imports and retargets every clip of the spec.
pub fn load(spec: &Spec, m: &MocapSpec, tick: &dyn Fn(&str)) -> Result<Mocap, BuildError> {
    let mut rig: Option<Rig> = None;
    let mut first_names: Vec<String> = Vec::new();
    let mut clips = Vec::with_capacity(m.clips.len());
    for (i, c) in m.clips.iter().enumerate() {
        tick(&c.name);
        let at_clip = |e: ImportError| clip_error(spec, c, i, &e);
        let motion = import_clip(spec, m, c, i)?;
        let sk = motion
            .core_skeleton(if m.end_sites {
                EndSites::Keep
            } else {
                EndSites::Drop
            })
            .map_err(at_clip)?;
        if rig.is_none() {
            rig = Some(match &spec.rig.file {
                Some(path) => {
                    let file = crate::rigfile::load(path).map_err(|e| {
                        spec.source
                            .error_line(spec.rig.line, "rig.file", e.to_string())
                    })?;
                    Rig::from_rigfile(file, &sk, &spec.source, &spec.rig)?
                }
                None => Rig::from_skeleton(&sk, &spec.rig, &spec.source, c.line)?,
            });
            first_names.clone_from(&sk.names);
        } else if sk.names != first_names {
            let problem =
                "the skeleton differs from the first clip's (every clip needs the same joints)";
            return Err(spec
                .source
                .error_line(c.line, &format!("clip[{i}].file"), problem)
                .into());
        }
        let Some(rig) = rig.as_ref() else { continue };
        let frame_time = c.fps.or(m.fps).map_or(motion.frame_time, |f| 1.0 / f);
        let poses = retarget_all(&motion, &sk, rig).map_err(|e| match e {
            BuildError::Import(e) => at_clip(e),
            BuildError::Pose { file, problem } => spec
                .source
                .error_line(
                    c.line,
                    &format!("clip[{i}].file"),
                    format!("{file}: {problem}"),
                )
                .into(),
            other => other,
        })?;
        clips.push(Clip {
            name: c.name.clone(),
            frame_time,
            poses,
        });
    }
    let rig = rig.ok_or_else(|| BuildError::Data("no clip".to_owned()))?;
    let speed_axis = spec.axes.iter().any(|a| a.measure == Measure::Speed);
    let warnings = rate_warnings(spec, m, &clips, speed_axis);
    Ok(Mocap {
        rig,
        clips,
        warnings,
    })
}

/// A clip moving slower than this (m/s) is not compared: standing clips
/// (reaches) have no speed to judge a rate by.
const MOVING: f64 = 0.2;

/// Faster than any human gait (m/s): the rate must be wrong.
const TOO_FAST: f64 = 10.0;

/// A clip whose speed is this many times off the other clips' median is
/// suspect (a 120 fps header on 60 fps data doubles it).
const SPEED_RATIO: f64 = 1.5;

/// The root's net horizontal travel over the clip divided by its duration,
/// m/s (the rig's units).
#[must_use]
pub fn root_speed(clip: &Clip) -> f64 {
    let (Some(first), Some(last)) = (clip.poses.first(), clip.poses.last()) else {
        return 0.0;
    };
    let d = last[0].0 - first[0].0;
    let seconds = (clip.poses.len().saturating_sub(1)) as f64 * clip.frame_time;
    if seconds > 0.0 {
        d.x.hypot(d.z) / seconds
    } else {
        0.0
    }
}

/// Warnings for clips whose root speed is implausible for their frame rate:
/// faster than [`TOO_FAST`], or, when no axis measures speed (so the clips
/// are one kind of motion at a similar pace, like walks on different
/// slopes), [`SPEED_RATIO`] times faster or slower than the median of the
/// other moving clips. Each names the clip, its rate and the fix.
fn rate_warnings(spec: &Spec, m: &MocapSpec, clips: &[Clip], speed_axis: bool) -> Vec<String> {
    let speeds: Vec<f64> = clips.iter().map(root_speed).collect();
    let mut out = Vec::new();
    for (i, (clip, &v)) in clips.iter().zip(&speeds).enumerate() {
        let fps = 1.0 / clip.frame_time;
        let mut others: Vec<f64> = speeds
            .iter()
            .enumerate()
            .filter(|&(j, &s)| j != i && s >= MOVING)
            .map(|(_, &s)| s)
            .collect();
        others.sort_by(f64::total_cmp);
        let median = others.get(others.len() / 2).copied();
        let why = if v > TOO_FAST {
            Some(format!("faster than any gait ({TOO_FAST} m/s)"))
        } else if let (false, true, Some(m)) = (speed_axis, v >= MOVING, median) {
            let ratio = v / m;
            (!(1.0 / SPEED_RATIO..=SPEED_RATIO).contains(&ratio))
                .then(|| format!("{ratio:.2}x the other clips' median {m:.2} m/s"))
        } else {
            None
        };
        if let Some(why) = why {
            let line = m.clips.get(i).map_or(0, |c| c.line);
            let problem = format!(
                "{}: root speed {v:.2} m/s at {fps:.0} fps is {why}; if the file's frame rate is wrong, set `fps` on the clip",
                clip.name
            );
            let field = format!("clip[{i}].fps");
            out.push(spec.source.error_line(line, &field, problem).to_string());
        }
    }
    out
}

fn import_clip(spec: &Spec, m: &MocapSpec, c: &ClipSpec, i: usize) -> Result<Motion, BuildError> {
    let ext = c
        .file
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    let field = format!("clip[{i}].file");
    match ext.as_deref() {
        Some("amc") => {
            let Some(asf) = &m.skeleton else {
                let problem = "an AMC clip needs `skeleton = \"file.asf\"` in [mocap]";
                return Err(spec.source.error_line(c.line, &field, problem).into());
            };
            let frame_time = c
                .fps
                .or(m.fps)
                .map_or(import::amc::HDM05_FRAME_TIME, |f| 1.0 / f);
            let skeleton = import::amc::read_asf(asf, None).map_err(|e| {
                spec.source
                    .error_line(m.skeleton_line, "mocap.skeleton", e.to_string())
            })?;
            let file = c.file.display().to_string();
            let amc = import::open(&c.file)
                .and_then(|r| import::amc::parse_amc(r, &file, &skeleton))
                .map_err(|e| clip_error(spec, c, i, &e))?;
            skeleton
                .to_motion(&amc, frame_time)
                .map_err(|e| clip_error(spec, c, i, &e))
        }
        Some("bvh") => {
            import::bvh::read_motion(&c.file, m.scale).map_err(|e| clip_error(spec, c, i, &e))
        }
        _ => {
            let problem = format!("{}: expected a .bvh or .amc file", c.file.display());
            Err(spec.source.error_line(c.line, &field, problem).into())
        }
    }
}

/// A mocap file's error, located at the spec's `[[clip]] file` that names
/// it (the mocap file's own line is in the message).
fn clip_error(spec: &Spec, c: &ClipSpec, i: usize, e: &ImportError) -> BuildError {
    spec.source
        .error_line(c.line, &format!("clip[{i}].file"), e.to_string())
        .into()
}

fn pose_error(file: &str, e: impl std::fmt::Debug) -> BuildError {
    BuildError::Pose {
        file: file.to_owned(),
        problem: format!("{e:?}"),
    }
}

/// Every frame, forward kinematics on the mocap skeleton, then retargeted.
fn retarget_all(
    motion: &Motion,
    sk: &import::CoreSkeleton,
    rig: &Rig,
) -> Result<Vec<Vec<Seg>>, BuildError> {
    let h = sk.hierarchy();
    let mut world = Pose::<CAP>::default();
    let mut out = Pose::<CAP>::default();
    (0..motion.frames.len())
        .map(|f| {
            let local = motion.local_pose::<CAP>(sk, f)?;
            pose::forward(&h, &local, &mut world).map_err(|e| pose_error(&motion.source, e))?;
            rig.retarget(&world, &mut out)
                .map_err(|e| pose_error(&motion.source, e))?;
            Ok(to_f64(&out))
        })
        .collect()
}

fn to_f64(p: &Pose<CAP>) -> Vec<Seg> {
    p.positions()
        .iter()
        .zip(p.rotations())
        .map(|(p, q)| (p.as_dvec3(), q.as_dquat().normalize()))
        .collect()
}

/// A rigid frame change `x ↦ rot · (x − origin)`.
#[derive(Debug, Clone, Copy)]
pub struct Frame {
    origin: DVec3,
    rot: DQuat,
}

impl Frame {
    /// The identity.
    pub const WORLD: Frame = Frame {
        origin: DVec3::ZERO,
        rot: DQuat::IDENTITY,
    };

    /// The heading frame of a root placement (see the module doc), or of an
    /// explicit horizontal `direction` taken as +Z.
    #[must_use]
    pub fn heading(root: &Seg, forward: DVec3, direction: Option<DVec3>) -> Frame {
        let f = direction.unwrap_or(root.1 * forward);
        let yaw = f.x.atan2(f.z);
        Frame {
            origin: DVec3::new(root.0.x, 0.0, root.0.z),
            rot: DQuat::from_rotation_y(-yaw),
        }
    }

    /// The root's own frame: origin at the root joint, axes turning with the
    /// root (`x ↦ conj(q_root) · (x − p_root)`).
    #[must_use]
    pub fn root(root: &Seg) -> Frame {
        Frame {
            origin: root.0,
            rot: root.1.conjugate(),
        }
    }

    /// The change that places a pose given in a root's own frame at a root
    /// placement: `x ↦ rotation · x + position`.
    #[must_use]
    pub fn placing(position: DVec3, rotation: DQuat) -> Frame {
        Frame {
            origin: -(rotation.conjugate() * position),
            rot: rotation,
        }
    }

    /// The same frame with its origin raised to the root joint.
    #[must_use]
    pub fn at_root(self, root: &Seg) -> Frame {
        Frame {
            origin: root.0,
            ..self
        }
    }

    /// A point in this frame.
    #[must_use]
    pub fn point(&self, p: DVec3) -> DVec3 {
        self.rot * (p - self.origin)
    }

    /// A pose in this frame.
    #[must_use]
    pub fn apply(&self, pose: &[Seg]) -> Vec<Seg> {
        pose.iter()
            .map(|&(p, q)| (self.rot * (p - self.origin), (self.rot * q).normalize()))
            .collect()
    }
}

/// Checks the position measures against the rig; returns the segment per axis.
pub fn measure_segments(spec: &Spec, rig: &Rig) -> Result<Vec<Option<usize>>, InputError> {
    spec.axes
        .iter()
        .enumerate()
        .map(|(i, a)| match &a.measure {
            Measure::Position { segment, .. } => rig.index_of(segment).map(Some).ok_or_else(|| {
                let problem = format!(
                    "no segment {segment:?} in the rig (segments: {})",
                    rig.names.join(", ")
                );
                spec.source
                    .error_line(a.line, &format!("axis[{i}].segment"), problem)
            }),
            _ => Ok(None),
        })
        .collect()
}

/// A parameter measured on a normalized pose.
fn position_param(axis: &AxisSpec, seg: Option<usize>, pose: &[Seg]) -> Option<f64> {
    match (&axis.measure, seg) {
        (
            Measure::Position {
                component, point, ..
            },
            Some(s),
        ) => pose
            .get(s)
            .map(|p| (p.0 + p.1 * DVec3::from_array(*point)).to_array()[*component]),
        _ => None,
    }
}

/// Grid examples: the chosen frames of every clip, normalized.
pub fn grid_records(spec: &Spec, m: &MocapSpec, mocap: &Mocap) -> Result<Vec<Record>, BuildError> {
    let segs = measure_segments(spec, &mocap.rig)?;
    let forward = DVec3::from_array(m.forward);
    let (rest_position, rest_rotation) = mocap.rig.rest_root();
    let stand = Frame::placing(rest_position, rest_rotation);
    let mut out = Vec::new();
    for (g, (c, clip)) in m.clips.iter().zip(&mocap.clips).enumerate() {
        let n = clip.poses.len();
        let ranges = c
            .frames
            .clone()
            .unwrap_or_else(|| vec![[0, n.saturating_sub(1)]]);
        for [a, b] in ranges {
            if b >= n {
                let problem = format!(
                    "frame {b} is past the last frame {} of {}",
                    n.saturating_sub(1),
                    clip.name
                );
                return Err(spec
                    .source
                    .error_line(c.line, &format!("clip[{g}].frames"), problem)
                    .into());
            }
            for f in (a..=b).step_by(c.every.unwrap_or(m.every)) {
                let world = &clip.poses[f];
                let frame = match spec.frame {
                    FrameKind::Heading => Frame::heading(&world[0], forward, None),
                    FrameKind::Root => Frame::heading(&world[0], forward, None).at_root(&world[0]),
                    FrameKind::Stand => Frame::root(&world[0]),
                    FrameKind::World => Frame::WORLD,
                };
                let mut pose = frame.apply(world);
                let params = grid_params(spec, c, &segs, &pose);
                if spec.frame == FrameKind::Stand {
                    pose = stand.apply(&pose);
                }
                out.push(Record {
                    params,
                    value: Value {
                        poses: pose,
                        scalars: Vec::new(),
                    },
                    group: g,
                });
            }
        }
    }
    Ok(out)
}

fn grid_params(spec: &Spec, c: &ClipSpec, segs: &[Option<usize>], pose: &[Seg]) -> Vec<f64> {
    spec.axes
        .iter()
        .zip(segs)
        .enumerate()
        .map(|(k, (a, &s))| {
            position_param(a, s, pose)
                .or_else(|| c.params.as_ref().and_then(|p| p.get(k).copied()))
                .unwrap_or(0.0)
        })
        .collect()
}

/// A source clip's normalized frames with their phases (`k + fraction`
/// within phase `k`), for measuring what time resampling loses.
pub type Originals = Vec<(f64, Vec<Seg>)>;

/// Motion-table examples, each clip's normalized source frames, and for a
/// loop each clip's seam.
pub type ClipRecords = (Vec<Record>, Vec<Originals>, Vec<Seam>);

/// Motion-table examples: one time-resampled clip each, each clip's
/// normalized source frames, and for a loop each clip's seam.
pub fn clip_records(spec: &Spec, m: &MocapSpec, mocap: &Mocap) -> Result<ClipRecords, BuildError> {
    let segs = measure_segments(spec, &mocap.rig)?;
    let forward = DVec3::from_array(m.forward);
    let segments = mocap.rig.names.len();
    let mut out = Vec::new();
    let mut originals = Vec::new();
    let mut seams = Vec::new();
    for (g, (c, clip)) in m.clips.iter().zip(&mocap.clips).enumerate() {
        let last = *c.cut.last().unwrap_or(&0);
        if last >= clip.poses.len() {
            let problem = format!(
                "frame {last} is past the last frame {} of {}",
                clip.poses.len().saturating_sub(1),
                clip.name
            );
            return Err(spec
                .source
                .error_line(c.line, &format!("clip[{g}].cut"), problem)
                .into());
        }
        let mut cut = c.cut.clone();
        if spec.motion.looping
            && let [a, b] = cut[..]
        {
            let seam = best_cut(&clip.poses, [a, b], spec.motion.seam_search);
            seams.push(Seam {
                clip: clip.name.clone(),
                window: spec.motion.seam_window,
                ..seam
            });
            cut = seam.chosen.to_vec();
        }
        let last = *cut.last().unwrap_or(&0);
        let first = cut[0];
        let Normalized {
            frames,
            horizontal,
            travel,
        } = normalized_clip(spec, &spec.motion, clip, first, last, forward);
        let poses = time_resample(&spec.motion, &frames, &cut, clip.frame_time, segments)
            .map_err(|e| pose_error(&clip.name, e))?;
        let durations: Vec<f64> = cut
            .windows(2)
            .map(|w| (w[1] - w[0]) as f64 * clip.frame_time)
            .collect();
        let total: f64 = durations.iter().sum();
        let at = if cut.len() > 2 { cut[1] - first } else { 0 };
        let params = spec
            .axes
            .iter()
            .zip(&segs)
            .enumerate()
            .map(|(k, (a, &s))| match a.measure {
                Measure::Speed => horizontal / total,
                _ => position_param(a, s, &frames[at])
                    .or_else(|| c.params.as_ref().and_then(|p| p.get(k).copied()))
                    .unwrap_or(0.0),
            })
            .collect();
        out.push(Record {
            params,
            value: Value {
                poses,
                // A loop's root travel rides with the durations (blended
                // with the same weights); `table_spec` splits them.
                scalars: if spec.motion.looping {
                    durations.into_iter().chain(travel.to_array()).collect()
                } else {
                    durations
                },
            },
            group: g,
        });
        originals.push(phases_of(&cut, frames));
    }
    Ok((out, originals, seams))
}

/// Frames compared on each side of a candidate seam frame, so that the
/// motion (velocities) matches as well as the pose.
pub const SEAM_CONTEXT: usize = 2;

/// A loop's seam: the cut given, the cut chosen, and how well each closes.
#[derive(Debug, Clone, PartialEq)]
pub struct Seam {
    /// The clip.
    pub clip: String,
    /// The cut in the spec, `[first, last]`.
    pub given: [usize; 2],
    /// The cut used (the given one without `seam_search`).
    pub chosen: [usize; 2],
    /// The frames searched on each side of each given end.
    pub search: usize,
    /// The seam-blend window, table frames.
    pub window: usize,
    /// Mean per-joint position jump at the seam with the given cut: how
    /// far the last frame's pose is from the first's, relative to the root
    /// (the root's net travel is carried by the loop), metres.
    pub jump_given: f64,
    /// The same with the chosen cut, metres.
    pub jump_chosen: f64,
    /// The mean per-joint step between consecutive source frames within the
    /// chosen cut, metres.
    pub step: f64,
}

/// Segment `j`'s position relative to the root, in world axes.
fn relative(pose: &[Seg], j: usize) -> DVec3 {
    pose[j].0 - pose[0].0
}

/// The mean per-joint position jump of a loop cut at `a` and `b` (see
/// [`Seam::jump_given`]).
#[must_use]
pub fn seam_jump(poses: &[Vec<Seg>], a: usize, b: usize) -> f64 {
    let (pa, pb) = (&poses[a], &poses[b]);
    let n = pa.len().max(1);
    (1..pa.len())
        .map(|j| (relative(pb, j) - relative(pa, j)).length())
        .sum::<f64>()
        / n as f64
}

/// The mean per-joint step between consecutive frames of `a..=b`, metres.
#[must_use]
pub fn mean_step(poses: &[Vec<Seg>], a: usize, b: usize) -> f64 {
    let frames = poses.get(a..=b).unwrap_or(&[]);
    let (mut sum, mut count) = (0.0, 0usize);
    for w in frames.windows(2) {
        for (p, q) in w[0].iter().zip(&w[1]) {
            sum += (q.0 - p.0).length();
            count += 1;
        }
    }
    if count == 0 { 0.0 } else { sum / count as f64 }
}

/// How badly a loop cut at `a` and `b` closes: over the frames `a + k` and
/// `b + k` for `k` in `−SEAM_CONTEXT..=SEAM_CONTEXT` (those inside the
/// clip), the squared differences of every segment's position relative to
/// the root, plus the squared difference of the root's path from `a` and
/// from `b`; the mean over the `k` compared.
fn seam_cost(poses: &[Vec<Seg>], a: usize, b: usize) -> f64 {
    let c = SEAM_CONTEXT as isize;
    let (mut sum, mut count) = (0.0, 0usize);
    for k in -c..=c {
        let (Some(ia), Some(ib)) = (a.checked_add_signed(k), b.checked_add_signed(k)) else {
            continue;
        };
        let (Some(pa), Some(pb)) = (poses.get(ia), poses.get(ib)) else {
            continue;
        };
        let limbs: f64 = (1..pa.len())
            .map(|j| (relative(pb, j) - relative(pa, j)).length_squared())
            .sum();
        let path = (pb[0].0 - poses[b][0].0) - (pa[0].0 - poses[a][0].0);
        sum += limbs + path.length_squared();
        count += 1;
    }
    if count == 0 {
        f64::INFINITY
    } else {
        sum / count as f64
    }
}

/// The loop cut within `search` frames of `given` at each end (inside the
/// clip, at least half the given cycle long) whose seam closes best
/// (the least mean per-joint jump between its two ends); ties keep the
/// cut nearer the given one. `search = 0` keeps the given cut.
#[must_use]
pub fn best_cut(poses: &[Vec<Seg>], given: [usize; 2], search: usize) -> Seam {
    let [a, b] = given;
    let last = poses.len().saturating_sub(1);
    let min_len = (b - a).div_ceil(2).max(1);
    let mut best = (seam_cost(poses, a, b), given);
    for a2 in a.saturating_sub(search)..=(a + search).min(last) {
        for b2 in b.saturating_sub(search)..=(b + search).min(last) {
            if b2 < a2 + min_len {
                continue;
            }
            let cost = seam_cost(poses, a2, b2);
            let moved = a.abs_diff(a2) + b.abs_diff(b2);
            let best_moved = a.abs_diff(best.1[0]) + b.abs_diff(best.1[1]);
            if cost < best.0 || (cost == best.0 && moved < best_moved) {
                best = (cost, [a2, b2]);
            }
        }
    }
    let chosen = best.1;
    Seam {
        clip: String::new(),
        given,
        chosen,
        search,
        window: 0,
        jump_given: seam_jump(poses, a, b),
        jump_chosen: seam_jump(poses, chosen[0], chosen[1]),
        step: mean_step(poses, chosen[0], chosen[1]),
    }
}

/// Each frame of `first..=last` with its phase.
fn phases_of(cut: &[usize], frames: Vec<Vec<Seg>>) -> Originals {
    let first = cut[0];
    frames
        .into_iter()
        .enumerate()
        .map(|(i, pose)| {
            let f = first + i;
            let k = cut
                .windows(2)
                .position(|w| f < w[1])
                .unwrap_or(cut.len() - 2);
            let (a, b) = (cut[k], cut[k + 1]);
            (k as f64 + (f - a) as f64 / (b - a) as f64, pose)
        })
        .collect()
}

/// A clip cut to `first..=last` and put in its frame.
struct Normalized {
    /// The frames (for a loop: net root travel removed, see below).
    frames: Vec<Vec<Seg>>,
    /// The root's net horizontal travel, metres.
    horizontal: f64,
    /// For a loop: the root's net displacement from `first` to `last` in
    /// the clip frame, on all three axes (a climb too), which was removed
    /// from the frames linearly in time; zero otherwise.
    travel: DVec3,
}

/// Frames `first..=last` in the clip's frame. A looping clip is made "in
/// place" on all three axes: its net root displacement is removed linearly
/// in time (so a walk up a slope no longer climbs inside its cycle) and
/// returned, to be stored as the cycle's root displacement.
fn normalized_clip(
    spec: &Spec,
    motion: &MotionSpec,
    clip: &Clip,
    first: usize,
    last: usize,
    forward: DVec3,
) -> Normalized {
    let start = clip.poses[first][0];
    let end = clip.poses[last][0];
    let moved = end.0 - start.0;
    let d = DVec3::new(moved.x, 0.0, moved.z);
    let horizontal = d.length();
    let direction = (motion.looping && horizontal > 0.05).then_some(d);
    let frame = match spec.frame {
        FrameKind::Heading => Frame::heading(&start, forward, direction),
        // `stand` is refused for motion tables by the spec parser; as `root`.
        FrameKind::Root | FrameKind::Stand => {
            Frame::heading(&start, forward, direction).at_root(&start)
        }
        FrameKind::World => Frame::WORLD,
    };
    let span = (last - first) as f64;
    let travel = if motion.looping {
        frame.rot * moved
    } else {
        DVec3::ZERO
    };
    let frames = (first..=last)
        .map(|f| {
            let mut pose = frame.apply(&clip.poses[f]);
            let shift = travel * ((f - first) as f64 / span);
            pose.iter_mut().for_each(|s| s.0 -= shift);
            pose
        })
        .collect();
    Normalized {
        frames,
        horizontal,
        travel,
    }
}

/// Resamples each phase to `motion.frames` steps (W&H Fig. 6) and, for a
/// loop, blends the seam; returns `[frame][segment]` flattened.
fn time_resample(
    motion: &MotionSpec,
    frames: &[Vec<Seg>],
    cut: &[usize],
    frame_time: f64,
    segments: usize,
) -> Result<Vec<Seg>, clip::ClipError> {
    let first = cut[0];
    let mut out: Vec<Seg> = Vec::new();
    for (k, w) in cut.windows(2).enumerate() {
        let src = &frames[w[0] - first..=w[1] - first];
        let positions: Vec<Vec3> = src.iter().flatten().map(|s| s.0.as_vec3()).collect();
        let rotations: Vec<Quat> = src.iter().flatten().map(|s| s.1.as_quat()).collect();
        let samples = SliceSamples::new(segments, &positions, &rotations)
            .ok_or(clip::ClipError::OutputLength)?;
        let times: Vec<f32> = (0..src.len())
            .map(|i| (i as f64 * frame_time) as f32)
            .collect();
        let span = Span {
            start: 0.0,
            end: ((src.len() - 1) as f64 * frame_time) as f32,
        };
        let n = motion.frames + 1;
        let mut p = vec![Vec3::ZERO; n * segments];
        let mut r = vec![Quat::IDENTITY; n * segments];
        clip::resample(&samples, &times, span, false, n, &mut p, &mut r)?;
        let keep = if motion.looping {
            clip::seam_blend(&mut p, &mut r, segments, motion.seam_window)?
        } else if k + 1 == cut.len() - 1 {
            n
        } else {
            // The boundary frame starts the next phase.
            n - 1
        };
        out.extend(
            p.iter()
                .zip(&r)
                .take(keep * segments)
                .map(|(p, q)| (p.as_dvec3(), q.as_dquat().normalize())),
        );
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A root walking along +Z and a hand swinging with a period of 50
    /// frames: the best loop cut near `[10, 65]` is exactly one period long
    /// (the hand back where it was), and its jump is zero.
    #[test]
    fn best_cut_finds_the_period() {
        let period = 50.0;
        let poses: Vec<Vec<Seg>> = (0..200)
            .map(|f| {
                let t = std::f64::consts::TAU * f as f64 / period;
                let root = DVec3::new(0.0, 1.0, 0.02 * f as f64);
                let hand = root + DVec3::new(0.3 * t.sin(), -0.5, 0.2 * t.cos());
                vec![(root, DQuat::IDENTITY), (hand, DQuat::IDENTITY)]
            })
            .collect();
        let seam = best_cut(&poses, [10, 65], 10);
        assert_eq!(seam.chosen[1] - seam.chosen[0], 50, "{seam:?}");
        assert!(
            seam.jump_chosen < 1e-9 && seam.jump_given > 0.05,
            "{seam:?}"
        );
        // By hand: the hand moves 2π·√(0.3²·cos² + 0.2²·sin²)/50 per frame; the
        // root 0.02 m; their mean is near (0.02 + ~0.031) / 2.
        assert!((seam.step - 0.0255).abs() < 0.003, "{seam:?}");
        let kept = best_cut(&poses, [10, 65], 0);
        assert_eq!(kept.chosen, [10, 65]);
    }

    #[test]
    fn heading_and_root_frames() {
        // Root at (1, 0.9, 2) facing +X (turned +90° about Y); a hand 0.5 m
        // in front of it and 0.3 m to its left (+Z turned is +X, left +X
        // turned is −Z), 1.2 m up.
        let root = (
            DVec3::new(1.0, 0.9, 2.0),
            DQuat::from_rotation_y(std::f64::consts::FRAC_PI_2),
        );
        let hand = (DVec3::new(1.5, 1.2, 1.7), DQuat::IDENTITY);
        let h = Frame::heading(&root, DVec3::Z, None).apply(&[root, hand]);
        assert!(
            (h[0].0 - DVec3::new(0.0, 0.9, 0.0)).length() < 1e-12,
            "{:?}",
            h[0]
        );
        assert!(
            (h[1].0 - DVec3::new(0.3, 1.2, 0.5)).length() < 1e-12,
            "{:?}",
            h[1]
        );
        assert!(h[0].1.angle_between(DQuat::IDENTITY) < 1e-9);
        let r = Frame::heading(&root, DVec3::Z, None)
            .at_root(&root)
            .apply(&[root, hand]);
        assert!(
            (r[1].0 - DVec3::new(0.3, 0.3, 0.5)).length() < 1e-12,
            "{:?}",
            r[1]
        );
        // An explicit travel direction (+X) gives the same frame.
        let d = Frame::heading(&root, DVec3::Z, Some(DVec3::X)).apply(&[hand]);
        assert!((d[0].0 - h[1].0).length() < 1e-12);
    }

    #[test]
    fn stand_frame_follows_the_root_in_pitch_then_places_it() {
        // The root at (1, 0.9, 2) pitched forward 90° (about +X: its +Y turns
        // to +Z); a hand 0.5 m along the root's own +Y axis is at
        // (1, 0.9, 2.5) in the world, and (0, 0.5, 0) in the root's frame,
        // whatever the heading frame says.
        let root = (
            DVec3::new(1.0, 0.9, 2.0),
            DQuat::from_rotation_x(std::f64::consts::FRAC_PI_2),
        );
        let hand = (DVec3::new(1.0, 0.9, 2.5), root.1);
        let own = Frame::root(&root).apply(&[root, hand]);
        assert!(own[0].0.length() < 1e-12 && own[0].1.angle_between(DQuat::IDENTITY) < 1e-9);
        assert!(
            (own[1].0 - DVec3::new(0.0, 0.5, 0.0)).length() < 1e-12,
            "{own:?}"
        );
        // Placed on a stand at (0, 0.44, 0) turned 90° about Y: x ↦ R·x + p.
        let r = DQuat::from_rotation_y(std::f64::consts::FRAC_PI_2);
        let placed = Frame::placing(DVec3::new(0.0, 0.44, 0.0), r).apply(&own);
        assert!((placed[0].0 - DVec3::new(0.0, 0.44, 0.0)).length() < 1e-12);
        assert!(placed[0].1.angle_between(r) < 1e-9);
        assert!((placed[1].0 - DVec3::new(0.0, 0.94, 0.0)).length() < 1e-12);
        let side = Frame::placing(DVec3::ZERO, r).apply(&[(DVec3::Z, DQuat::IDENTITY)]);
        assert!((side[0].0 - DVec3::X).length() < 1e-12, "{side:?}");
    }
}
