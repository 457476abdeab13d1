//! Mocap import: BVH, Acclaim ASF/AMC and tracker CSV recordings.
//!
//! Every importer reads its file as **bytes**, decodes each line as Latin-1
//! (so the `0xFC` byte in HDM05's AMC headers is harmless; all keywords and
//! numbers are ASCII anyway) and reports errors as [`ImportError`], which
//! always names the file, the 1-based line and the field that was expected.
//! Bad input never panics.
//!
//! Mocap (BVH, ASF/AMC) converts to one common representation, [`Motion`]:
//! a joint tree in metres plus, per frame, the root position and each joint's
//! rotation relative to its parent, in `f64`. [`Motion::core_skeleton`] and
//! [`Motion::local_pose`] turn it into the core's
//! [`Hierarchy`] and
//! [`LocalPose`] (`f32`), so that world
//! positions and orientations are always computed by the one forward
//! kinematics of the project, [`marionette_core::pose::forward`].
//!
//! # Units
//!
//! Everything leaving this module is SI: metres, radians, seconds, with Y up.
//! Lengths in a file are multiplied by a scale chosen by the caller:
//!
//! | source | file unit | scale to metres |
//! |---|---|---|
//! | CMU 31-joint BVH (cgspeed conversion) | CMU unit | [`CMU_UNIT_METRES`] = 0.0254 / 0.45 = 0.056444… |
//! | iClone / Character Creator BVH (`cmu_subject07_walk_speeds_ccrig`) | centimetre | [`CENTIMETRE`] = 0.01 |
//! | ASF/AMC (HDM05, CMU) | `length L` in `:units` | 0.0254 / L (see [`amc`]) |
//!
//! DESIGN §4 rounds the CMU factor to 0.056444; the exact value differs from
//! it by 8·10⁻⁶ relative (16 µm over 2 m).
//!
//! # Text conventions shared by all formats
//!
//! * Lines end in `\n` or `\r\n`; a lone `\r` counts as whitespace, not as a
//!   line break. Lines longer than [`MAX_LINE_BYTES`] are rejected.
//! * Numbers use Rust's `f64` syntax (`1`, `-2.5`, `7.6e-016`); `nan` and
//!   `inf` parse but are rejected as [`ImportError::NotFinite`].

pub mod amc;
pub mod bvh;
pub mod csv;

use std::io::{BufRead, Read};

use glam::{DQuat, DVec3, Vec3};
use marionette_core::pose::{Hierarchy, LocalPose, NO_PARENT};

/// Metres per CMU unit: CMU and HDM05 files are in inches × (1/0.45), so one
/// unit is 0.0254 / 0.45 m = 0.056444… m (DESIGN §4).
pub const CMU_UNIT_METRES: f64 = 0.0254 / 0.45;

/// Metres per centimetre: the scale for the iClone/Character Creator BVH files.
pub const CENTIMETRE: f64 = 0.01;

/// Longest accepted line, in bytes. A 300-channel BVH frame is about 3 kB.
pub const MAX_LINE_BYTES: usize = 1 << 20;

/// Most joints accepted in one skeleton (BVH joints and End Sites, ASF bones
/// and their end points). The core's [`Hierarchy`] stores parents as `u8`, so
/// [`Motion::core_skeleton`] further limits a skeleton to
/// [`MAX_CORE_SEGMENTS`].
pub const MAX_JOINTS: usize = 1024;

/// Most segments in a core [`Hierarchy`]: parents are `u8` and
/// [`NO_PARENT`] (255) is reserved, so indices run 0..=254.
pub const MAX_CORE_SEGMENTS: usize = NO_PARENT as usize;

/// Why an import failed. Every variant names the file; those raised while
/// reading text also name the 1-based line and the field.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// The file could not be opened or read.
    #[error("{file}:{line}: cannot read: {source}")]
    Io {
        /// File name as given by the caller.
        file: String,
        /// Line being read (1-based; 0 when opening).
        line: usize,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// A token or line did not have the expected form.
    #[error("{file}:{line}: {field}: expected {expected}, found {found}")]
    Syntax {
        /// File name.
        file: String,
        /// 1-based line.
        line: usize,
        /// What was being read (`CHANNELS`, `OFFSET z`, `bone name`, ...).
        field: String,
        /// What the format requires there.
        expected: String,
        /// What the file has (quoted token, or `end of line`).
        found: String,
    },
    /// A value that must be a number is not one.
    #[error("{file}:{line}: {field}: expected a number, found {found:?}")]
    NotNumber {
        /// File name.
        file: String,
        /// 1-based line.
        line: usize,
        /// What was being read.
        field: String,
        /// The offending token.
        found: String,
    },
    /// A number is NaN or infinite.
    #[error("{file}:{line}: {field}: expected a finite number, found {found:?}")]
    NotFinite {
        /// File name.
        file: String,
        /// 1-based line.
        line: usize,
        /// What was being read.
        field: String,
        /// The offending token.
        found: String,
    },
    /// The file ended where more was required.
    #[error("{file}:{line}: unexpected end of file: expected {expected}")]
    UnexpectedEof {
        /// File name.
        file: String,
        /// Number of the last line read (the end is just after it).
        line: usize,
        /// What was still required.
        expected: String,
    },
    /// A count exceeds a documented limit.
    #[error("{file}:{line}: {field}: more than {limit} allowed")]
    TooMany {
        /// File name.
        file: String,
        /// 1-based line.
        line: usize,
        /// What there are too many of.
        field: String,
        /// The limit.
        limit: usize,
    },
    /// Well-formed but inconsistent or unsupported content (duplicate or
    /// unknown names, time going backwards, translation dofs on bones, ...).
    #[error("{file}:{line}: {field}: {problem}")]
    Invalid {
        /// File name.
        file: String,
        /// 1-based line; 0 for a bad caller argument (scale, frame time).
        line: usize,
        /// What was being read.
        field: String,
        /// What is wrong with it.
        problem: String,
    },
    /// The parsed motion cannot be expressed in the core's types (too many
    /// segments for `N`, a translated non-root joint, ...).
    #[error("{file}: frame {frame}: {problem}")]
    Convert {
        /// File name.
        file: String,
        /// 0-based frame index (0 for skeleton-level problems).
        frame: usize,
        /// What is wrong.
        problem: String,
    },
}

impl ImportError {
    /// The file the error is about.
    #[must_use]
    pub fn file(&self) -> &str {
        match self {
            Self::Io { file, .. }
            | Self::Syntax { file, .. }
            | Self::NotNumber { file, .. }
            | Self::NotFinite { file, .. }
            | Self::UnexpectedEof { file, .. }
            | Self::TooMany { file, .. }
            | Self::Invalid { file, .. }
            | Self::Convert { file, .. } => file,
        }
    }

    /// The 1-based line the error is about, if it comes from reading text
    /// (0 for a bad caller argument such as a scale or frame time).
    #[must_use]
    pub fn line(&self) -> Option<usize> {
        match self {
            Self::Io { line, .. }
            | Self::Syntax { line, .. }
            | Self::NotNumber { line, .. }
            | Self::NotFinite { line, .. }
            | Self::UnexpectedEof { line, .. }
            | Self::TooMany { line, .. }
            | Self::Invalid { line, .. } => Some(*line),
            Self::Convert { .. } => None,
        }
    }
}

/// Opens `path` for one of the `read_*` functions, naming it in errors.
pub(crate) fn open(
    path: &std::path::Path,
) -> Result<std::io::BufReader<std::fs::File>, ImportError> {
    std::fs::File::open(path)
        .map(std::io::BufReader::new)
        .map_err(|source| ImportError::Io {
            file: path.display().to_string(),
            line: 0,
            source,
        })
}

/// A line-by-line reader over bytes that decodes Latin-1 and counts lines.
pub(crate) struct Lines<R> {
    reader: R,
    file: String,
    number: usize,
    bytes: Vec<u8>,
    text: String,
}

impl<R: BufRead> Lines<R> {
    /// Wraps `reader`; `file` names it in errors.
    pub(crate) fn new(reader: R, file: &str) -> Self {
        Self {
            reader,
            file: file.to_owned(),
            number: 0,
            bytes: Vec::new(),
            text: String::new(),
        }
    }

    /// The file name used in errors.
    pub(crate) fn file(&self) -> &str {
        &self.file
    }

    /// 1-based number of the line last returned by [`Lines::next_line`].
    pub(crate) fn number(&self) -> usize {
        self.number
    }

    /// Reads the next line; `false` at the end of the file. The line, without
    /// its terminator, is then [`Lines::text`].
    pub(crate) fn advance(&mut self) -> Result<bool, ImportError> {
        self.bytes.clear();
        self.text.clear();
        let limit = u64::try_from(MAX_LINE_BYTES)
            .unwrap_or(u64::MAX)
            .saturating_add(1);
        let read = (&mut self.reader)
            .take(limit)
            .read_until(b'\n', &mut self.bytes);
        let count = read.map_err(|source| ImportError::Io {
            file: self.file.clone(),
            line: self.number.saturating_add(1),
            source,
        })?;
        if count == 0 {
            return Ok(false);
        }
        self.number = self.number.saturating_add(1);
        if self.bytes.last() == Some(&b'\n') {
            self.bytes.pop();
        } else if self.bytes.len() > MAX_LINE_BYTES {
            return Err(self.too_many("line length in bytes", MAX_LINE_BYTES));
        }
        if self.bytes.last() == Some(&b'\r') {
            self.bytes.pop();
        }
        self.text.extend(self.bytes.iter().map(|&b| char::from(b)));
        Ok(true)
    }

    /// The line last read by [`Lines::advance`] (Latin-1 decoded).
    pub(crate) fn text(&self) -> &str {
        &self.text
    }

    /// Parses `token` as a finite `f64` for `field`, on the current line.
    pub(crate) fn number_f64(&self, token: &str, field: &str) -> Result<f64, ImportError> {
        parse_f64(&self.file, self.number, token, field)
    }

    /// A [`ImportError::Syntax`] on the current line.
    pub(crate) fn syntax(&self, field: &str, expected: &str, found: Option<&str>) -> ImportError {
        ImportError::Syntax {
            file: self.file.clone(),
            line: self.number,
            field: field.to_owned(),
            expected: expected.to_owned(),
            found: found.map_or_else(|| "end of line".to_owned(), |t| format!("{t:?}")),
        }
    }

    /// An [`ImportError::Invalid`] on the current line.
    pub(crate) fn invalid(&self, field: &str, problem: impl Into<String>) -> ImportError {
        ImportError::Invalid {
            file: self.file.clone(),
            line: self.number,
            field: field.to_owned(),
            problem: problem.into(),
        }
    }

    /// An [`ImportError::TooMany`] on the current line.
    pub(crate) fn too_many(&self, field: &str, limit: usize) -> ImportError {
        ImportError::TooMany {
            file: self.file.clone(),
            line: self.number,
            field: field.to_owned(),
            limit,
        }
    }

    /// An [`ImportError::UnexpectedEof`] after the last line read.
    pub(crate) fn eof(&self, expected: &str) -> ImportError {
        ImportError::UnexpectedEof {
            file: self.file.clone(),
            line: self.number,
            expected: expected.to_owned(),
        }
    }
}

/// Parses a finite `f64`, naming `file`, `line` and `field` on failure.
pub(crate) fn parse_f64(
    file: &str,
    line: usize,
    token: &str,
    field: &str,
) -> Result<f64, ImportError> {
    finite(token).ok_or_else(|| number_error(file, line, token, field))
}

/// `token` as a finite `f64`, if it is one (the allocation-free fast path).
pub(crate) fn finite(token: &str) -> Option<f64> {
    token.parse::<f64>().ok().filter(|v| v.is_finite())
}

/// The error for a `token` that [`finite`] rejected.
pub(crate) fn number_error(file: &str, line: usize, token: &str, field: &str) -> ImportError {
    let (file, field, found) = (file.to_owned(), field.to_owned(), token.to_owned());
    if token.parse::<f64>().is_ok() {
        ImportError::NotFinite {
            file,
            line,
            field,
            found,
        }
    } else {
        ImportError::NotNumber {
            file,
            line,
            field,
            found,
        }
    }
}

/// Checks that a caller-provided length scale is finite and positive.
pub(crate) fn check_scale(file: &str, scale: f64) -> Result<(), ImportError> {
    if scale.is_finite() && scale > 0.0 {
        Ok(())
    } else {
        Err(ImportError::Invalid {
            file: file.to_owned(),
            line: 0,
            field: "scale".to_owned(),
            problem: format!("length scale must be finite and positive, got {scale}"),
        })
    }
}

/// A rotation axis of an Euler angle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Axis {
    /// The X axis.
    X,
    /// The Y axis.
    Y,
    /// The Z axis.
    Z,
}

impl Axis {
    /// The rotation by `radians` about this axis (right-handed), in `f64`.
    #[must_use]
    pub fn rotation(self, radians: f64) -> DQuat {
        let (s, c) = (0.5 * radians).sin_cos();
        match self {
            Self::X => DQuat::from_xyzw(s, 0.0, 0.0, c),
            Self::Y => DQuat::from_xyzw(0.0, s, 0.0, c),
            Self::Z => DQuat::from_xyzw(0.0, 0.0, s, c),
        }
    }
}

/// One joint of a [`Motion`]'s skeleton.
#[derive(Clone, Debug, PartialEq)]
pub struct Joint {
    /// Name from the file (End Sites and ASF bone tips get `<parent>.end`).
    pub name: String,
    /// Index of the parent joint; `None` only for the root (index 0).
    /// Parents always come before their children.
    pub parent: Option<usize>,
    /// Origin of this joint in its parent's frame, in metres (rest pose).
    pub offset: DVec3,
    /// Whether this is a BVH End Site or an ASF bone tip: a leaf that never
    /// rotates and only marks where the last segment ends.
    pub end_site: bool,
}

/// One frame of a [`Motion`].
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// World position of the root joint's origin, in metres.
    pub root_position: DVec3,
    /// Per joint (same order as [`Motion::joints`]): the rotation relative to
    /// the parent, applied to column vectors. The root's is its world
    /// rotation. End sites hold the identity.
    pub rotations: Vec<DQuat>,
}

/// Mocap in the project's common form: a joint tree and frames of local
/// rotations, in metres and `f64`.
///
/// Forward kinematics (done by the core, see [`Motion::local_pose`]):
/// `world_rot[j] = world_rot[parent] · rotation[j]`,
/// `world_pos[j] = world_pos[parent] + world_rot[parent] · offset[j]`, and
/// for the root `world_pos = root_position`, `world_rot = rotation[0]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Motion {
    /// The file this came from (for error messages).
    pub source: String,
    /// The skeleton; index 0 is the root; parents precede children.
    pub joints: Vec<Joint>,
    /// Seconds per frame as stated by the file (or the caller for AMC).
    pub frame_time: f64,
    /// The frames.
    pub frames: Vec<Frame>,
}

/// Whether [`Motion::core_skeleton`] keeps End Sites / bone tips as segments.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EndSites {
    /// Keep them (needed to place hand, foot and head tips).
    Keep,
    /// Drop them (the iClone rig has 41 End Sites, all at zero offset).
    Drop,
}

/// A [`Motion`]'s skeleton in the core's form: `u8` parents and `f32`
/// offsets, borrowed as a [`Hierarchy`] by [`CoreSkeleton::hierarchy`].
#[derive(Clone, Debug, PartialEq)]
pub struct CoreSkeleton {
    /// Segment names.
    pub names: Vec<String>,
    /// Parent segment per segment; [`NO_PARENT`] for the root.
    pub parents: Vec<u8>,
    /// Segment origin in the parent's frame, metres.
    pub offsets: Vec<Vec3>,
    /// For each segment, the index of the [`Motion`] joint it came from.
    pub joints: Vec<usize>,
}

impl CoreSkeleton {
    /// The core's view of this skeleton.
    #[must_use]
    pub fn hierarchy(&self) -> Hierarchy<'_> {
        Hierarchy {
            parents: &self.parents,
            offsets: &self.offsets,
        }
    }

    /// Number of segments.
    #[must_use]
    pub fn len(&self) -> usize {
        self.parents.len()
    }

    /// Whether there are no segments (never true for an imported motion).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.parents.is_empty()
    }

    /// Index of the segment called `name`.
    #[must_use]
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }
}

impl Motion {
    /// Index of the joint called `name`.
    #[must_use]
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// The skeleton in the core's form, keeping or dropping end sites.
    ///
    /// # Errors
    /// [`ImportError::Convert`] if the skeleton has more than
    /// [`MAX_CORE_SEGMENTS`] segments, or if a kept joint's parent is not
    /// kept (cannot happen for motions built by this module).
    pub fn core_skeleton(&self, end_sites: EndSites) -> Result<CoreSkeleton, ImportError> {
        let mut segment_of = vec![None; self.joints.len()];
        let mut out = CoreSkeleton {
            names: Vec::new(),
            parents: Vec::new(),
            offsets: Vec::new(),
            joints: Vec::new(),
        };
        for (index, joint) in self.joints.iter().enumerate() {
            if joint.end_site && end_sites == EndSites::Drop {
                continue;
            }
            let segment = out.parents.len();
            if segment >= MAX_CORE_SEGMENTS {
                return Err(
                    self.convert_error(0, format!("more than {MAX_CORE_SEGMENTS} segments"))
                );
            }
            let parent = match joint.parent {
                None => NO_PARENT,
                Some(p) => segment_of
                    .get(p)
                    .copied()
                    .flatten()
                    .and_then(|s: usize| u8::try_from(s).ok())
                    .ok_or_else(|| {
                        self.convert_error(
                            0,
                            format!("joint {:?}: parent not before it", joint.name),
                        )
                    })?,
            };
            if let Some(slot) = segment_of.get_mut(index) {
                *slot = Some(segment);
            }
            out.names.push(joint.name.clone());
            out.parents.push(parent);
            out.offsets.push(joint.offset.as_vec3());
            out.joints.push(index);
        }
        Ok(out)
    }

    /// Frame `frame` as the core's [`LocalPose`] for `skeleton` (made by
    /// [`Motion::core_skeleton`] from this motion), converted to `f32`.
    ///
    /// # Errors
    /// [`ImportError::Convert`] if `frame` is out of range, the skeleton has
    /// more than `N` segments, or it does not belong to this motion.
    pub fn local_pose<const N: usize>(
        &self,
        skeleton: &CoreSkeleton,
        frame: usize,
    ) -> Result<LocalPose<N>, ImportError> {
        let data = self.frames.get(frame).ok_or_else(|| {
            self.convert_error(
                frame,
                format!("out of range ({} frames)", self.frames.len()),
            )
        })?;
        if skeleton.len() > N {
            return Err(self.convert_error(
                frame,
                format!("{} segments do not fit LocalPose<{N}>", skeleton.len()),
            ));
        }
        let mut local = LocalPose::<N>::new(skeleton.len())
            .map_err(|e| self.convert_error(frame, format!("LocalPose<{N}>: {e:?}")))?;
        local.root_position = data.root_position.as_vec3();
        for (slot, &joint) in local.rotations.iter_mut().zip(&skeleton.joints) {
            let q = data.rotations.get(joint).ok_or_else(|| {
                self.convert_error(frame, format!("skeleton joint {joint} not in this motion"))
            })?;
            *slot = q.as_quat();
        }
        Ok(local)
    }

    /// All frames as [`LocalPose`]s (see [`Motion::local_pose`]).
    ///
    /// # Errors
    /// As [`Motion::local_pose`].
    pub fn local_poses<const N: usize>(
        &self,
        skeleton: &CoreSkeleton,
    ) -> Result<Vec<LocalPose<N>>, ImportError> {
        (0..self.frames.len())
            .map(|f| self.local_pose::<N>(skeleton, f))
            .collect()
    }

    fn convert_error(&self, frame: usize, problem: String) -> ImportError {
        ImportError::Convert {
            file: self.source.clone(),
            frame,
            problem,
        }
    }
}
