//! A rig file written from a mocap skeleton (`marionette rig --from-skeleton
//! FILE.bvh|FILE.asf -o rig.toml`): a starting point a solver and a build
//! spec can use at once, with comments marking what to edit.
//!
//! # What is written
//!
//! - one `[[segment]]` per joint (BVH `ROOT`/`JOINT`, ASF root and bones), in
//!   the file's depth-first order, the root first; End Sites and ASF bone
//!   tips are not segments but give their parent's `touch` point. A
//!   segment's `origin` is its joint's rest offset in metres, its `touch`
//!   its first child's origin (the origin for a leaf without an End Site);
//! - `dofs` from the skeleton's rotation channels:
//!   - BVH: one DOF per rotation channel of a non-root joint, in the listed
//!     order; this is exactly the BVH rotation (`R = R_c1 · R_c2 · R_c3`, the
//!     rig's `q = R_a(t0) · R_b(t1) · …`), so every frame of the file is a
//!     pose of the rig. Limits are the generous ±180°;
//!   - ASF: a bone's `dof rx ry rz` turns about the axes of its `axis`
//!     frame `C`, as `C · Rz · Ry · Rx · C⁻¹`; the rig lists them last first
//!     (`rz`, `ry`, `rx`), each about the rig axis nearest to `C`'s (signed,
//!     distinct). With `axis 0 0 0` that is exact; a tilted axis frame (the
//!     HDM05/CMU femurs' 20°) is rounded to the nearest axis and the DOF's
//!     comment says by how much. Limits are the file's `limits` (negated for
//!     an axis that points the other way), ±180° where it gives none;
//! - the root's rotation and translation channels are not DOFs: a rig's root
//!   is placed by `root_position`/`root_rotation` (`solve --root float`
//!   moves it). `root_position` puts the lowest joint at rest on the floor
//!   (y = 0);
//! - no servos, `[output] kind = "pwm"` (a skeleton drives nothing yet), no
//!   goals (`solve` reads its goals from a goals file) and a `[retarget]`
//!   map from each segment to its mocap joint, so a build spec with `[rig]
//!   file = "rig.toml"` builds tables from the same mocap for this rig;
//! - `frame_period_us` from the BVH frame time (the AMC's 120 Hz for an ASF).
//!
//! Joints may be selected and renamed as in a build spec's `[rig]` (the
//! [`NameMap`]: `strip_prefix`, `rename`, `drop`, `keep`); a dropped joint's
//! rest offset is added to its kept children's origins, and its DOFs are
//! lost. A rig holds at most [`MAX_SEGMENTS`] segments with names of at most
//! [`NAME_LEN`] bytes: a skeleton over either limit is refused with the
//! joint's file and line and the option that fixes it.
//!
//! The text written is parsed back by [`crate::rigfile::parse`] before it is
//! returned, so a written rig always loads.

use std::fmt::Write as _;
use std::path::Path;

use glam::{DQuat, DVec3};
use marionette_core::rig::{MAX_SEGMENTS, NAME_LEN, RIG_NAME_LEN};

use crate::build::spec::NameMap;
use crate::import::{Axis, ImportError, Joint, amc, bvh};

/// Frame period written for an ASF skeleton (AMC files are 120 Hz).
const ASF_FRAME_PERIOD_US: u32 = 8333;

/// The generous limit written where the skeleton gives none, degrees.
const OPEN_LIMIT_DEG: f64 = 180.0;

/// A rotation-axis tilt (degrees) below which an ASF axis counts as exact.
const TILT_NOTE_DEG: f64 = 0.5;

/// Why no rig could be written from a skeleton.
#[derive(Debug, thiserror::Error)]
pub enum SkeletonError {
    /// The skeleton file is malformed (file, line and field).
    #[error("{0}")]
    Import(#[from] ImportError),
    /// The skeleton does not fit a rig as asked (file, line, field).
    #[error("{file}:{line}: {field}: {problem}")]
    At {
        /// The skeleton file.
        file: String,
        /// 1-based line of the joint concerned (0: the file as a whole).
        line: usize,
        /// The joint or option concerned.
        field: String,
        /// What is wrong and what to do.
        problem: String,
    },
}

/// How to read the skeleton and name the rig.
#[derive(Debug, Clone, Default)]
pub struct Options {
    /// BVH: metres per file unit (default: the CMU unit, as in a build
    /// spec). ASF files state their unit.
    pub scale: Option<f64>,
    /// The rig's name (default: the file's stem).
    pub name: Option<String>,
    /// Joint selection and naming.
    pub names: NameMap,
}

/// One DOF to write.
#[derive(Debug, Clone, PartialEq)]
pub struct DofOut {
    /// The rig axis.
    pub axis: Axis,
    /// Limits, radians.
    pub limits: (f64, f64),
    /// Where the DOF came from (the comment written after it).
    pub note: String,
}

/// One segment to write.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentOut {
    /// Segment name.
    pub name: String,
    /// The mocap joint it follows.
    pub joint: String,
    /// Parent segment index (`None`: the root).
    pub parent: Option<usize>,
    /// Joint origin in the parent's frame, metres.
    pub origin: DVec3,
    /// Touch point in the segment's frame, metres.
    pub touch: DVec3,
    /// Its DOFs, in rig order.
    pub dofs: Vec<DofOut>,
    /// A remark on the segment (root placement, ignored channels).
    pub note: Option<String>,
}

/// A rig made from a skeleton, ready to be written as TOML.
#[derive(Debug, Clone)]
pub struct SkeletonRig {
    /// The skeleton file.
    pub source: String,
    /// `"BVH"` or `"ASF"`.
    pub format: &'static str,
    /// Rig name.
    pub name: String,
    /// Control period, µs.
    pub frame_period_us: u32,
    /// Where the period came from.
    pub period_note: String,
    /// Metres per file unit applied.
    pub scale: f64,
    /// Root height at rest (its lowest joint on the floor), metres.
    pub root_height: f64,
    /// Segments, root first.
    pub segments: Vec<SegmentOut>,
}

/// A joint of the source skeleton with what the rig needs of it.
struct SourceJoint {
    joint: Joint,
    dofs: Vec<DofOut>,
    note: Option<String>,
}

/// Reads `path` (`.bvh` or `.asf`, by extension) into a [`SkeletonRig`].
///
/// # Errors
/// [`SkeletonError::Import`] for a malformed file (file, line, field);
/// [`SkeletonError::At`] for an unknown extension, more than
/// [`MAX_SEGMENTS`] kept joints, a segment name over [`NAME_LEN`] bytes or
/// named twice, or a bad option.
pub fn read(path: &Path, options: &Options) -> Result<SkeletonRig, SkeletonError> {
    let file = path.display().to_string();
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let (format, joints, period, scale) = match ext.as_deref() {
        Some("bvh") => bvh_joints(path, options)?,
        Some("asf") => asf_joints(path)?,
        _ => {
            return Err(SkeletonError::At {
                file,
                line: 0,
                field: "--from-skeleton".into(),
                problem: "expected a .bvh or .asf skeleton file".into(),
            });
        }
    };
    let text = std::fs::read(path)
        .map(|b| b.iter().map(|&c| char::from(c)).collect::<String>())
        .unwrap_or_default();
    let name = options.name.clone().unwrap_or_else(|| {
        let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("rig");
        truncate(stem, RIG_NAME_LEN)
    });
    if name.len() > RIG_NAME_LEN {
        return Err(SkeletonError::At {
            file,
            line: 0,
            field: "--name".into(),
            problem: format!("{name:?} is longer than {RIG_NAME_LEN} bytes"),
        });
    }
    let segments = select(&joints, &options.names, &file, &text)?;
    let root_height = rest_height(&joints);
    let (frame_period_us, period_note) = period;
    Ok(SkeletonRig {
        source: file,
        format,
        name,
        frame_period_us,
        period_note,
        scale,
        root_height,
        segments,
    })
}

type Parsed = (&'static str, Vec<SourceJoint>, (u32, String), f64);

fn bvh_joints(path: &Path, options: &Options) -> Result<Parsed, SkeletonError> {
    let scale = options.scale.unwrap_or(crate::import::CMU_UNIT_METRES);
    let reader = bvh::FrameReader::new(
        crate::import::open(path)?,
        &path.display().to_string(),
        scale,
    )?;
    let header = reader.header();
    let joints = header.joints.iter().map(|j| {
        let rotations: Vec<Axis> = j
            .channels
            .iter()
            .filter_map(|c| c.rotation_axis())
            .collect();
        let names: Vec<String> = j.channels.iter().map(|c| format!("{c:?}")).collect();
        let (dofs, note) = if j.parent.is_none() {
            let note = format!(
                "root: its channels ({}) place the figure; a rig's root has no DOFs \
                 (root_position/root_rotation; `solve --root float` moves it)",
                names.join(" ")
            );
            (Vec::new(), Some(note))
        } else {
            let dofs = rotations
                .iter()
                .map(|&axis| DofOut {
                    axis,
                    limits: open_limits(),
                    note: format!(
                        "{}rotation; EDIT: the joint's real range",
                        axis_word(axis).to_uppercase()
                    ),
                })
                .collect();
            let moves = j.channels.iter().any(|c| c.position_index().is_some());
            let note = moves
                .then(|| "its position channels are not kept: a rig's joints only turn".to_owned());
            (dofs, note)
        };
        SourceJoint {
            joint: Joint {
                name: j.name.clone(),
                parent: j.parent,
                offset: j.offset,
                end_site: j.end_site,
            },
            dofs,
            note,
        }
    });
    let secs = header.frame_time;
    let us = (secs * 1e6).round().clamp(100.0, 100_000.0) as u32;
    let period = (
        us,
        format!("the file's Frame Time {secs} s ({:.0} Hz)", 1.0 / secs),
    );
    Ok(("BVH", joints.collect(), period, scale))
}

fn asf_joints(path: &Path) -> Result<Parsed, SkeletonError> {
    let asf = amc::read_asf(path, None)?;
    let (joints, joint_of_bone) = asf.motion_joints();
    let mut out: Vec<SourceJoint> = joints
        .into_iter()
        .map(|joint| SourceJoint {
            joint,
            dofs: Vec::new(),
            note: None,
        })
        .collect();
    if let Some(root) = out.first_mut() {
        root.note = Some(
            "root: its AMC values place the figure; a rig's root has no DOFs \
             (root_position/root_rotation; `solve --root float` moves it)"
                .into(),
        );
    }
    for (bone, &j) in asf.bones.iter().zip(&joint_of_bone) {
        if let Some(slot) = out.get_mut(j) {
            slot.dofs = asf_dofs(bone);
        }
    }
    let period = (
        ASF_FRAME_PERIOD_US,
        "the AMC files' 120 Hz (an ASF does not say)".to_owned(),
    );
    Ok(("ASF", out, period, asf.scale))
}

/// A bone's DOFs about the rig axes nearest its axis frame's (see the
/// module docs), last `dof` first.
fn asf_dofs(bone: &amc::Bone) -> Vec<DofOut> {
    let c = bone.axis_frame();
    let (perm, signs) = nearest_axes(c);
    let open = (f64::NEG_INFINITY, f64::INFINITY);
    let limits = bone.limits.iter().copied().chain(std::iter::repeat(open));
    let pairs: Vec<(amc::Dof, (f64, f64))> = bone.dofs.iter().copied().zip(limits).collect();
    pairs
        .into_iter()
        .rev()
        .filter_map(|(dof, (lo, hi))| {
            let own = dof.rotation_axis()?;
            let k = axis_index(own);
            let (axis, sign) = (perm[k], signs[k]);
            let v = c * unit(own);
            let tilt = v.angle_between(unit(axis) * sign).to_degrees();
            let (lo, hi) = if sign < 0.0 { (-hi, -lo) } else { (lo, hi) };
            let max = OPEN_LIMIT_DEG.to_radians();
            let given = lo.is_finite() && hi.is_finite();
            let limits = (lo.clamp(-max, max), hi.clamp(-max, max));
            let mut note = format!("{dof:?}");
            if sign < 0.0 {
                note.push_str(" (its axis points along -");
                note.push_str(axis_word(axis));
                note.push_str(": angles negated)");
            }
            if tilt > TILT_NOTE_DEG {
                let _ = write!(
                    note,
                    "; its axis is {tilt:.1}° from this one (the bone's tilted `axis`): \
                     EDIT if that matters"
                );
            }
            note.push_str(if given {
                "; limits from the file"
            } else {
                "; EDIT: the joint's real range"
            });
            Some(DofOut { axis, limits, note })
        })
        .collect()
}

/// For each of `c`'s axes (x, y, z), the distinct rig axis nearest it and
/// its sign: the axis permutation with the largest summed |cosine|.
fn nearest_axes(c: DQuat) -> ([Axis; 3], [f64; 3]) {
    const PERMS: [[Axis; 3]; 6] = [
        [Axis::X, Axis::Y, Axis::Z],
        [Axis::X, Axis::Z, Axis::Y],
        [Axis::Y, Axis::X, Axis::Z],
        [Axis::Y, Axis::Z, Axis::X],
        [Axis::Z, Axis::X, Axis::Y],
        [Axis::Z, Axis::Y, Axis::X],
    ];
    let cols = [Axis::X, Axis::Y, Axis::Z].map(|a| c * unit(a));
    let score =
        |p: &[Axis; 3]| -> f64 { cols.iter().zip(p).map(|(v, &a)| v.dot(unit(a)).abs()).sum() };
    let best = PERMS
        .iter()
        .copied()
        .max_by(|a, b| score(a).total_cmp(&score(b)))
        .unwrap_or(PERMS[0]);
    let signs = [0, 1, 2].map(|k| {
        if cols[k].dot(unit(best[k])) < 0.0 {
            -1.0
        } else {
            1.0
        }
    });
    (best, signs)
}

fn unit(a: Axis) -> DVec3 {
    match a {
        Axis::X => DVec3::X,
        Axis::Y => DVec3::Y,
        Axis::Z => DVec3::Z,
    }
}

fn axis_index(a: Axis) -> usize {
    match a {
        Axis::X => 0,
        Axis::Y => 1,
        Axis::Z => 2,
    }
}

fn axis_word(a: Axis) -> &'static str {
    match a {
        Axis::X => "x",
        Axis::Y => "y",
        Axis::Z => "z",
    }
}

fn open_limits() -> (f64, f64) {
    let m = OPEN_LIMIT_DEG.to_radians();
    (-m, m)
}

/// The kept joints as segments (End Sites only give touch points).
fn select(
    joints: &[SourceJoint],
    names: &NameMap,
    file: &str,
    text: &str,
) -> Result<Vec<SegmentOut>, SkeletonError> {
    let mut segment_of: Vec<Option<usize>> = vec![None; joints.len()];
    let mut out: Vec<SegmentOut> = Vec::new();
    for (i, sj) in joints.iter().enumerate() {
        let j = &sj.joint;
        if j.end_site || (i > 0 && !names.keeps(&j.name)) {
            continue;
        }
        let line = joint_line(text, &j.name);
        let at = |field: String, problem: String| SkeletonError::At {
            file: file.to_owned(),
            line,
            field,
            problem,
        };
        if out.len() >= MAX_SEGMENTS {
            return Err(at(
                format!("joint {:?}", j.name),
                format!(
                    "the {}th segment: a rig holds at most {MAX_SEGMENTS} (leave joints out \
                     with --drop PATTERN or --keep PATTERN, e.g. --drop '*Finger*')",
                    out.len() + 1
                ),
            ));
        }
        let name = names.segment_name(&j.name);
        if name.is_empty() || name.len() > NAME_LEN {
            return Err(at(
                format!("joint {:?}", j.name),
                format!(
                    "segment name {name:?} is empty or longer than {NAME_LEN} bytes (shorten it \
                     with --strip-prefix PREFIX or --rename {}=NEW)",
                    names.stripped(&j.name)
                ),
            ));
        }
        if out.iter().any(|s| s.name == name) {
            return Err(at(
                format!("joint {:?}", j.name),
                format!("segment name {name:?} is used twice (--rename one of them)"),
            ));
        }
        // Up to the nearest kept ancestor, adding the dropped joints' rest
        // offsets on the way (rest rotations are zero).
        let (mut origin, mut up) = (j.offset, j.parent);
        let parent = loop {
            match up {
                None => break None,
                Some(p) => match segment_of.get(p).copied().flatten() {
                    Some(s) => break Some(s),
                    None => {
                        origin += joints.get(p).map_or(DVec3::ZERO, |q| q.joint.offset);
                        up = joints.get(p).and_then(|q| q.joint.parent);
                    }
                },
            }
        };
        let touch = joints
            .iter()
            .find(|c| c.joint.parent == Some(i))
            .map_or(DVec3::ZERO, |c| c.joint.offset);
        segment_of[i] = Some(out.len());
        out.push(SegmentOut {
            name,
            joint: j.name.clone(),
            parent,
            origin: if parent.is_none() {
                DVec3::ZERO
            } else {
                origin
            },
            touch,
            dofs: if parent.is_none() {
                Vec::new()
            } else {
                sj.dofs.clone()
            },
            note: sj.note.clone(),
        });
    }
    Ok(out)
}

/// The 1-based line naming joint `name` (`ROOT`/`JOINT name` in a BVH,
/// `name name` in an ASF), 0 if none does.
fn joint_line(text: &str, name: &str) -> usize {
    text.lines()
        .position(|l| {
            let mut t = l.split_whitespace();
            matches!(t.next(), Some("ROOT" | "JOINT" | "name")) && t.next() == Some(name)
        })
        .map_or(0, |i| i + 1)
}

/// The drop from the root to its lowest joint at rest, metres.
fn rest_height(joints: &[SourceJoint]) -> f64 {
    let mut y = vec![0.0f64; joints.len()];
    for (i, j) in joints.iter().enumerate().skip(1) {
        let up = j
            .joint
            .parent
            .and_then(|p| y.get(p).copied())
            .unwrap_or(0.0);
        y[i] = up + j.joint.offset.y;
    }
    -y.iter().copied().fold(0.0, f64::min)
}

fn truncate(s: &str, max: usize) -> String {
    let mut end = s.len().min(max);
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    s[..end].to_owned()
}

/// A TOML string literal.
fn quoted(s: &str) -> String {
    toml::Value::String(s.to_owned()).to_string()
}

/// A number for the rig file: at most 6 decimals (µm, µrad), no `-0`.
fn num(v: f64) -> String {
    let s = format!("{v:.6}");
    let s = s.trim_end_matches('0');
    let s = s
        .strip_suffix('.')
        .map_or(s.to_owned(), |t| format!("{t}.0"));
    if s == "-0.0" { "0.0".to_owned() } else { s }
}

fn vec3(v: DVec3) -> String {
    format!("[{}, {}, {}]", num(v.x), num(v.y), num(v.z))
}

impl SkeletonRig {
    /// Total DOFs.
    #[must_use]
    pub fn dof_count(&self) -> usize {
        self.segments.iter().map(|s| s.dofs.len()).sum()
    }

    /// The rig file's text (comments mark what to edit).
    #[must_use]
    pub fn to_toml(&self) -> String {
        let mut s = String::new();
        self.write_header(&mut s);
        for (i, seg) in self.segments.iter().enumerate() {
            self.write_segment(&mut s, i, seg);
        }
        s
    }

    fn write_header(&self, s: &mut String) {
        let _ = write!(
            s,
            "# {name}: a rig written by `marionette rig --from-skeleton {src}` from the {fmt} \
             skeleton\n# ({n} segments, {d} DOFs). It loads, passes `marionette rig check` and \
             `marionette solve`\n# runs on it as it is; lines marked EDIT are guesses to \
             replace with the figure's facts.\n#\n\
             # - Conventions (docs/rig.md): metres, radians (`limits_deg` in degrees), Y up; a \
             joint's\n#   rotation is the product of its DOFs in the order listed. Lengths are \
             the file's\n#   times {scale} m per unit.\n\
             # - dofs: the skeleton's rotation channels{exact}. EDIT the limits ({limits})\n\
             #   to the joints' real ranges before solving for a puppet.\n\
             # - touch: where goals attach, the joint's first child (or End Site); EDIT for \
             hands and feet.\n\
             # - No [[servo]], [[param]] or [[goal]] yet: add them to drive a puppet \
             (docs/rig.md).\n\
             # - [retarget]: each segment takes its mocap joint, so a build spec with `[rig] \
             file =`\n#   this file builds tables from the same mocap for this rig.\n\n",
            name = self.name,
            src = self.source,
            fmt = self.format,
            n = self.segments.len(),
            d = self.dof_count(),
            scale = num(self.scale),
            limits = if self.format == "BVH" {
                "±180° here"
            } else {
                "the file's, ±180° where it gives none"
            },
            exact = if self.format == "BVH" {
                ", so every frame of its mocap is a pose of this rig"
            } else {
                "; a bone's tilted `axis` is rounded\n#   to the nearest rig axis (the DOF's comment \
                 says by how much)"
            },
        );
        let _ = writeln!(s, "name = {}", quoted(&self.name));
        let _ = writeln!(
            s,
            "frame_period_us = {}          # {}",
            self.frame_period_us, self.period_note
        );
        let _ = writeln!(s, "failsafe_timeout_ms = 100");
        let _ = writeln!(
            s,
            "root_position = [0.0, {}, 0.0]  # the root at rest, its lowest joint on the floor \
             (EDIT: a puppet's stand)",
            num(self.root_height)
        );
        let _ = writeln!(s, "root_rotation = [1.0, 0.0, 0.0, 0.0]");
        s.push_str(
            "\n[output]                        # EDIT: the servo back-end (a skeleton drives \
             nothing yet)\nkind = \"pwm\"\nfreq_hz = 50\n\n",
        );
        s.push_str("[retarget]                      # host only: mocap joint -> segment\n");
        if self.segments.iter().all(|g| g.name == g.joint) {
            s.push_str(
                "identity = true                 # every segment takes its own name's joint\n",
            );
        } else {
            for g in &self.segments {
                let _ = writeln!(
                    s,
                    "[[retarget.joint]]\nmocap = {}\nsegment = {}",
                    quoted(&g.joint),
                    quoted(&g.name)
                );
            }
        }
    }

    fn write_segment(&self, s: &mut String, i: usize, seg: &SegmentOut) {
        s.push_str("\n[[segment]]\n");
        let _ = writeln!(s, "name = {}", quoted(&seg.name));
        if let Some(note) = &seg.note {
            let _ = writeln!(s, "# {note}");
        }
        if let Some(p) = seg.parent.and_then(|p| self.segments.get(p)) {
            let _ = writeln!(s, "parent = {}", quoted(&p.name));
            let _ = writeln!(s, "origin = {}", vec3(seg.origin));
        }
        let _ = writeln!(s, "touch = {}", vec3(seg.touch));
        if i > 0 && !seg.dofs.is_empty() {
            s.push_str("dofs = [\n");
            for d in &seg.dofs {
                let _ = writeln!(
                    s,
                    "  {{ axis = \"{}\", limits_deg = [{}, {}] }},   # {}",
                    axis_word(d.axis),
                    num(d.limits.0.to_degrees()),
                    num(d.limits.1.to_degrees()),
                    d.note
                );
            }
            s.push_str("]\n");
        }
    }
}

/// Reads the skeleton and returns the checked rig text: the text is parsed
/// back as a rig file (named `out` in errors) before it is returned.
///
/// # Errors
/// As [`read`]; a text the rig parser refuses is reported as its error.
pub fn rig_text(
    path: &Path,
    options: &Options,
    out: &str,
) -> Result<(SkeletonRig, String), String> {
    let rig = read(path, options).map_err(|e| e.to_string())?;
    let text = rig.to_toml();
    crate::rigfile::parse(&text, out).map_err(|e| format!("the rig written: {e}"))?;
    Ok((rig, text))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_short_and_never_negative_zero() {
        assert_eq!(num(0.0), "0.0");
        assert_eq!(num(-0.000_000_1), "0.0");
        assert_eq!(num(1.5), "1.5");
        assert_eq!(num(-90.0), "-90.0");
        assert_eq!(num(0.056_444_444_4), "0.056444");
    }

    #[test]
    fn an_untilted_axis_frame_maps_each_axis_to_itself() {
        let (p, s) = nearest_axes(DQuat::IDENTITY);
        assert_eq!(p, [Axis::X, Axis::Y, Axis::Z]);
        assert_eq!(s, [1.0; 3]);
        // -90° about x: the frame's y is -z, its z is +y.
        let (p, s) = nearest_axes(DQuat::from_rotation_x(-std::f64::consts::FRAC_PI_2));
        assert_eq!(p, [Axis::X, Axis::Z, Axis::Y]);
        assert_eq!(s, [1.0, -1.0, 1.0]);
    }
}
