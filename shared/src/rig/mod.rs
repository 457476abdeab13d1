//! The runtime view of a rig: the skeleton, the servo channels, the output
//! back-end and the tracker mapping of one physical figure, read from a
//! flash-resident **rig blob** next to the motion tables.
//!
//! The host reads the rig file (TOML, `marionette-host`'s `rigfile`) into a
//! [`RigDesc`] and writes it with [`RigDesc::to_blob`]; the firmware reads it
//! with [`Rig::parse`], which checks the blob, decodes the description
//! (borrowing the names from the blob: nothing is copied but fixed-size
//! numbers), validates every field ([`RigDesc::validate`]) and builds the
//! arrays a [`Body`] borrows. Then, per frame:
//!
//! - [`Rig::map_sensors`] turns tracker sensors into synthesis parameters and
//!   weighted goals (see [`sensor`]);
//! - [`Rig::body`] is the body tree the solver works on;
//! - [`Rig::servos`] say which joint DOF drives which channel, with its
//!   [`crate::servo::Calibration`] and slew limits.
//!
//! # Blob layout (format version 2)
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `"MRIG"` (`4D 52 49 47`) |
//! | 4 | 2 | format version, `u16` LE ([`VERSION`] = 2) |
//! | 6 | 4 | description length `L`, `u32` LE (≤ [`MAX_DESC_LEN`]) |
//! | 10 | `L` | [`RigDesc`], postcard 1.x (exactly `L` bytes) |
//! | 10 + `L` | 4 | CRC-32/ISO-HDLC ([`crate::crc`]) of bytes `0 .. 10 + L`, `u32` LE |
//! | 14 + `L` | 0–3 | zero padding to a multiple of 4 |
//!
//! Whatever follows the padding (another blob, erased flash) is returned
//! untouched by [`Rig::parse`], so a rig blob and table blobs can sit back to
//! back at 4-aligned offsets.
//!
//! Postcard writes struct fields in declaration order without tags: `u8` and
//! `bool` as one byte, `u16`/`u32` as LEB128 varints, `f32` as 4 bytes LE, a
//! string as varint length then UTF-8 bytes, `[f32; N]` as `N` floats, an
//! `Option` as byte 0 / byte 1 then the value, an enum as its varint variant
//! index then its fields, and a list as varint length then the items. The
//! description is, in order: `name` (string), `frame_period_us`,
//! `failsafe_timeout_ms`, `root_position` (3 × f32), `root_rotation`
//! (`[w, x, y, z]`), `output` ([`Output`]), `idle` ([`Idle`]), `segments`
//! ([`SegmentDesc`]: name, parent `u8`, origin, touch, DOF list of
//! ([`AxisName`], min, max)), `servos` ([`ServoDesc`], its bus `id` last),
//! `params` ([`ParamMap`]) and `goals` ([`GoalMap`]); the types' docs give
//! each variant's index.
//!
//! Version 2 added the serial bus servo outputs (variants 3 and 4 of
//! [`Output`]), `idle` and the servos' `id`. A version 1 blob is refused
//! ([`RigError::Version`]): write it again from its rig file.
//!
//! # Rig hash
//!
//! A table is built for one skeleton. [`RigDesc::rig_hash`] (the `rig_hash`
//! of the table blob header) is the **64-bit FNV-1a** (offset basis
//! `0xcbf29ce484222325`, prime `0x100000001b3`) of the postcard encoding of
//! the `segments` list alone: renaming, moving or re-limiting a segment changes
//! it; re-calibrating a servo, changing the output or the sensor mapping does
//! not (none of them changes what a table holds).
//!
//! # Conventions
//!
//! SI units (m, rad, s; pulses in µs), right-handed, Y up, quaternions
//! `[w, x, y, z]`, as everywhere in Marionette. A segment's frame is at its
//! joint origin; at rest (all angles zero) every frame is parallel to the
//! root's (see [`crate::body`]).
//!
//! # Capacity
//!
//! A [`Rig`] holds its segment arrays and rest pose for at most `N` segments
//! (a const parameter, default [`MAX_SEGMENTS`], the format's limit). A board
//! with little RAM instantiates a smaller one, e.g. `Rig<'_, 24>` (the
//! firmware's: the shipped puppet fits): [`Rig::parse_sized`] and
//! [`Rig::from_desc_sized`] refuse a rig with more segments with
//! [`RigError::Capacity`].

mod desc;
pub mod sensor;

pub use desc::{
    AxisName, Cylinder, DofDesc, FeetechSeries, GoalMap, GoalSource, Idle, MAX_GOALS, MAX_PARAMS,
    MAX_SEGMENTS, MAX_SENSORS, MAX_SERVOS, Measure, NAME_LEN, Output, ParamMap, RIG_NAME_LEN,
    RefFrame, RigDesc, SegmentDesc, SensorGoal, ServoDesc,
};
pub use sensor::MapReport;

use crate::body::{Angles, Body, BodyError, Joint, Segment};
use crate::crc::crc32;
use crate::pose::{LocalPose, NO_PARENT, Pose};
use crate::wire::List;
use glam::{Quat, Vec3};

/// The blob magic.
pub const MAGIC: [u8; 4] = *b"MRIG";
/// The blob format version this core reads and writes.
pub const VERSION: u16 = 2;
/// Bytes before the description: magic, version, length.
pub const PREFIX_LEN: usize = 10;
/// Bytes of the CRC after the description.
pub const CRC_LEN: usize = 4;
/// Longest description accepted. A full rig (64 segments with 24-byte names
/// and 3 DOFs each, 24 servos, 6 parameters, 8 goals) encodes to under
/// 7.2 KiB.
pub const MAX_DESC_LEN: usize = 8192;
/// Longest blob, padding included.
pub const MAX_BLOB_LEN: usize = PREFIX_LEN + MAX_DESC_LEN + CRC_LEN;

/// Which entry of a rig a validation error is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Place {
    /// The rig's own fields.
    Rig,
    /// The output back-end.
    Output,
    /// Segment `i`.
    Segment(u8),
    /// DOF `dof` of segment `segment`.
    Dof {
        /// The segment.
        segment: u8,
        /// The DOF's position in the joint.
        dof: u8,
    },
    /// Servo entry `i` (list position, not channel).
    Servo(u8),
    /// Parameter entry `i` (list position).
    Param(u8),
    /// Goal entry `i` (list position).
    Goal(u8),
}

/// What is wrong with a field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Problem {
    /// NaN or infinite.
    NonFinite,
    /// Outside its allowed range (see the field's doc).
    OutOfRange,
    /// A `[min, max]` pair with `min > max` (or `min == max` where a span is
    /// needed).
    Unordered,
    /// Repeats an earlier entry's value (names, channels, parameters, axes).
    Duplicate,
    /// The parent is not an earlier segment (or the root has a parent).
    NotTopological,
    /// Names a segment, DOF or sensor that does not exist (or itself).
    BadReference,
    /// Empty where something is required.
    Empty,
    /// A quaternion or axis that is not of unit length.
    NotUnit,
    /// The root has degrees of freedom (it is free; its placement is the
    /// rig's `root_position` / `root_rotation`).
    RootDof,
    /// More entries than the format holds.
    Capacity,
}

/// A validation failure: the entry, the field (named as in the rig file) and
/// what is wrong.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Invalid {
    /// The entry.
    pub place: Place,
    /// The field, as the rig file's key.
    pub field: &'static str,
    /// What is wrong.
    pub problem: Problem,
}

/// Why a rig blob or description was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RigError {
    /// The bytes end before the prefix, the description or the CRC.
    Truncated,
    /// The first four bytes are not [`MAGIC`].
    Magic,
    /// A format version this core does not read.
    Version(u16),
    /// The description length exceeds [`MAX_DESC_LEN`].
    TooLong,
    /// The CRC does not match.
    Crc,
    /// The description is not valid postcard for [`RigDesc`] (or does not
    /// fill exactly its stated length).
    Decode,
    /// The output buffer is too small for the blob.
    BufferTooSmall,
    /// A field breaks a rule of the format.
    Invalid(Invalid),
    /// The body module refused the skeleton (cannot happen after validation;
    /// kept so that no error is swallowed).
    Body(BodyError),
    /// The rig is valid but has more segments than the [`Rig`]'s capacity
    /// `N` (the build's limit, below the format's [`MAX_SEGMENTS`]).
    Capacity {
        /// The rig's segments.
        segments: u8,
        /// The capacity.
        capacity: u8,
    },
}

impl RigError {
    /// [`RigError::Capacity`] for `segments` against a capacity.
    fn over_capacity(segments: impl TryInto<u8>, capacity: usize) -> Self {
        RigError::Capacity {
            segments: segments.try_into().unwrap_or(u8::MAX),
            capacity: u8::try_from(capacity).unwrap_or(u8::MAX),
        }
    }
}

impl From<BodyError> for RigError {
    fn from(e: BodyError) -> Self {
        RigError::Body(e)
    }
}

/// A postcard output that hashes instead of storing (64-bit FNV-1a).
struct Fnv64(u64);

impl postcard::ser_flavors::Flavor for Fnv64 {
    type Output = u64;

    fn try_push(&mut self, data: u8) -> postcard::Result<()> {
        self.0 = (self.0 ^ u64::from(data)).wrapping_mul(0x0000_0100_0000_01b3);
        Ok(())
    }

    fn finalize(self) -> postcard::Result<u64> {
        Ok(self.0)
    }
}

/// 64-bit FNV-1a of a value's postcard encoding.
fn fnv64_of<T: serde::Serialize>(value: &T) -> u64 {
    const BASIS: u64 = 0xcbf2_9ce4_8422_2325;
    postcard::serialize_with_flavor(value, Fnv64(BASIS)).unwrap_or(BASIS)
}

/// Rounds up to a multiple of 4.
const fn align4(n: usize) -> usize {
    n.saturating_add(3) & !3
}

/// Checks the blob envelope; returns the description bytes and what follows
/// the blob (after its padding).
fn envelope(bytes: &[u8]) -> Result<(&[u8], &[u8]), RigError> {
    let (prefix, _) = bytes
        .split_first_chunk::<PREFIX_LEN>()
        .ok_or(RigError::Truncated)?;
    let [m0, m1, m2, m3, v0, v1, l0, l1, l2, l3] = *prefix;
    if [m0, m1, m2, m3] != MAGIC {
        return Err(RigError::Magic);
    }
    let version = u16::from_le_bytes([v0, v1]);
    if version != VERSION {
        return Err(RigError::Version(version));
    }
    let len = usize::try_from(u32::from_le_bytes([l0, l1, l2, l3])).unwrap_or(usize::MAX);
    if len > MAX_DESC_LEN {
        return Err(RigError::TooLong);
    }
    let end = PREFIX_LEN + len;
    let covered = bytes.get(..end).ok_or(RigError::Truncated)?;
    let stored = bytes
        .get(end..end + CRC_LEN)
        .and_then(|c| <[u8; CRC_LEN]>::try_from(c).ok())
        .ok_or(RigError::Truncated)?;
    if crc32(covered) != u32::from_le_bytes(stored) {
        return Err(RigError::Crc);
    }
    let desc = covered.get(PREFIX_LEN..).ok_or(RigError::Truncated)?;
    let rest = bytes.get(align4(end + CRC_LEN)..).unwrap_or(&[]);
    Ok((desc, rest))
}

impl<'a> RigDesc<'a> {
    /// Decodes a blob's description without validating it (for inspection);
    /// returns it and the bytes after the blob.
    pub fn from_blob(bytes: &'a [u8]) -> Result<(Self, &'a [u8]), RigError> {
        Self::from_blob_sized(bytes)
    }
}

/// The head of a description, up to the length of its segment list: the
/// fields of [`RigDesc`] before `segments`, in order (postcard writes a list
/// length as the same varint as a `u32`).
type DescHead<'a> = (&'a str, u32, u32, [f32; 3], [f32; 4], Output, Idle, u32);

impl<'a, const N: usize> RigDesc<'a, N> {
    /// [`RigDesc::from_blob`] into a segment list of capacity `N`: a
    /// description that does not decode at this capacity but whose segment
    /// count is above `N` (and within the format's [`MAX_SEGMENTS`]) is
    /// refused with [`RigError::Capacity`] (the envelope's CRC has already
    /// been checked, so that is what it holds). Never inlined: the decoder's
    /// temporaries stay in this call's stack frame.
    #[inline(never)]
    pub(crate) fn from_blob_sized(bytes: &'a [u8]) -> Result<(Self, &'a [u8]), RigError> {
        let (desc, rest) = envelope(bytes)?;
        match postcard::take_from_bytes::<Self>(desc) {
            Ok((d, [])) => Ok((d, rest)),
            Ok(_) => Err(RigError::Decode),
            Err(_) => match postcard::take_from_bytes::<DescHead<'a>>(desc) {
                Ok(((.., segments), _))
                    if usize::try_from(segments).is_ok_and(|s| N < s && s <= MAX_SEGMENTS) =>
                {
                    Err(RigError::over_capacity(segments, N))
                }
                _ => Err(RigError::Decode),
            },
        }
    }

    /// Validates the description and writes it as a blob into `out`; returns
    /// the blob's length (padding included, a multiple of 4).
    pub fn to_blob(&self, out: &mut [u8]) -> Result<usize, RigError> {
        self.validate()?;
        let body = out.get_mut(PREFIX_LEN..).ok_or(RigError::BufferTooSmall)?;
        let len = postcard::to_slice(self, body)
            .map_err(|_| RigError::BufferTooSmall)?
            .len();
        if len > MAX_DESC_LEN {
            return Err(RigError::TooLong);
        }
        let end = PREFIX_LEN + len;
        let total = align4(end + CRC_LEN);
        let blob = out.get_mut(..total).ok_or(RigError::BufferTooSmall)?;
        let (prefix, tail) = blob
            .split_at_mut_checked(PREFIX_LEN)
            .ok_or(RigError::BufferTooSmall)?;
        prefix.copy_from_slice(&Self::prefix(len));
        let crc = {
            let mut c = crate::crc::Crc32::new();
            c.update(prefix);
            c.update(tail.get(..len).ok_or(RigError::BufferTooSmall)?);
            c.finish()
        };
        let after = tail.get_mut(len..).ok_or(RigError::BufferTooSmall)?;
        for (i, b) in after.iter_mut().enumerate() {
            *b = crc.to_le_bytes().get(i).copied().unwrap_or(0);
        }
        Ok(total)
    }

    fn prefix(len: usize) -> [u8; PREFIX_LEN] {
        let [m0, m1, m2, m3] = MAGIC;
        let [v0, v1] = VERSION.to_le_bytes();
        let [l0, l1, l2, l3] = u32::try_from(len).unwrap_or(u32::MAX).to_le_bytes();
        [m0, m1, m2, m3, v0, v1, l0, l1, l2, l3]
    }

    /// The skeleton hash: 64-bit FNV-1a of the postcard encoding of
    /// `segments` (see the module doc).
    #[must_use]
    pub fn rig_hash(&self) -> u64 {
        fnv64_of(&self.segments)
    }
}

/// A filler for unused segment slots.
const EMPTY_SEGMENT: Segment<'static> = Segment {
    name: "",
    parent: NO_PARENT,
    origin: Vec3::ZERO,
    joint: Joint::FIXED,
    touch: Vec3::ZERO,
};

/// A rig ready for the live loop: the arrays a [`Body`] borrows, the rest
/// pose, the servo channels and the sensor mapping, for at most `N` segments
/// (see [Capacity](self#capacity)). Names borrow from the blob (`'a`).
#[derive(Clone, Debug)]
pub struct Rig<'a, const N: usize = MAX_SEGMENTS> {
    name: &'a str,
    frame_period_us: u32,
    failsafe_timeout_ms: u32,
    output: Output,
    idle: Idle,
    root_position: Vec3,
    root_rotation: Quat,
    count: usize,
    segments: [Segment<'a>; N],
    parents: [u8; N],
    offsets: [Vec3; N],
    rest: Pose<N>,
    servos: List<ServoDesc, MAX_SERVOS>,
    params: List<ParamMap, MAX_PARAMS>,
    goals: List<GoalMap, MAX_GOALS>,
    hash: u64,
}

/// A `[w, x, y, z]` array as a quaternion.
#[inline]
#[must_use]
pub(crate) fn quat_wxyz(q: [f32; 4]) -> Quat {
    let [w, x, y, z] = q;
    Quat::from_xyzw(x, y, z, w)
}

/// `q` normalized (left as is when its squared norm is exactly 1).
#[inline]
fn unit_quat(q: Quat) -> Quat {
    if crate::math::quat_dot(q, q) == 1.0 {
        q
    } else {
        crate::math::normalize_quat(q)
    }
}

impl<'a> Rig<'a> {
    /// Checks and decodes a rig blob (see the module doc); returns the rig and
    /// the bytes after the blob. Every field is validated
    /// ([`RigDesc::validate`]); nothing panics on any input. The rig has the
    /// format's capacity; [`Rig::parse_sized`] makes a smaller one.
    pub fn parse(bytes: &'a [u8]) -> Result<(Self, &'a [u8]), RigError> {
        Self::parse_sized(bytes)
    }

    /// Validates a description and builds the runtime rig (at the format's
    /// capacity; see [`Rig::from_desc_sized`]).
    pub fn from_desc(desc: &RigDesc<'a>) -> Result<Self, RigError> {
        Self::from_desc_sized(desc)
    }

    /// The joint angle a servo follows, from a joint state (`None` if the
    /// state does not cover the servo's segment).
    #[must_use]
    pub fn servo_angle<const N: usize>(servo: &ServoDesc, angles: &Angles<N>) -> Option<f32> {
        angles
            .get(usize::from(servo.segment))?
            .get(usize::from(servo.dof))
            .copied()
    }
}

impl<'a, const N: usize> Rig<'a, N> {
    /// [`Rig::parse`] into a rig of capacity `N`: a valid rig with more than
    /// `N` segments is refused with [`RigError::Capacity`].
    pub fn parse_sized(bytes: &'a [u8]) -> Result<(Self, &'a [u8]), RigError> {
        let mut slot = None;
        let rest = Self::parse_into(bytes, &mut slot)?;
        slot.map(|rig| (rig, rest)).ok_or(RigError::Truncated)
    }

    /// [`Rig::parse_sized`] into `slot` (set to the rig on success, `None`
    /// on an error), for a caller that keeps the rig in place: a rig is
    /// kilobytes, and every move is a copy on the stack. Returns the bytes
    /// after the blob. Never inlined: the decoded description stays in this
    /// call's stack frame.
    #[inline(never)]
    pub fn parse_into(bytes: &'a [u8], slot: &mut Option<Self>) -> Result<&'a [u8], RigError> {
        *slot = None;
        // Borrowed where it was returned: no copy of the description.
        let parsed = RigDesc::<N>::from_blob_sized(bytes);
        let (desc, rest) = match &parsed {
            Ok((desc, rest)) => (desc, *rest),
            Err(e) => return Err(*e),
        };
        Self::from_desc_into(desc, slot)?;
        Ok(rest)
    }

    /// [`Rig::from_desc`] into a rig of capacity `N`: a valid rig with more
    /// than `N` segments is refused with [`RigError::Capacity`].
    pub fn from_desc_sized<const M: usize>(desc: &RigDesc<'a, M>) -> Result<Self, RigError> {
        let mut slot = None;
        Self::from_desc_into(desc, &mut slot)?;
        slot.ok_or(RigError::Truncated)
    }

    /// [`Rig::from_desc_sized`] into `slot` (see [`Rig::parse_into`]).
    /// Never inlined: its temporaries stay in this call's stack frame.
    #[inline(never)]
    pub fn from_desc_into<const M: usize>(
        desc: &RigDesc<'a, M>,
        slot: &mut Option<Self>,
    ) -> Result<(), RigError> {
        *slot = None;
        desc.validate()?;
        if desc.segments.len() > N {
            return Err(RigError::over_capacity(desc.segments.len(), N));
        }
        let rig = slot.insert(Rig {
            name: desc.name,
            frame_period_us: desc.frame_period_us,
            failsafe_timeout_ms: desc.failsafe_timeout_ms,
            output: desc.output,
            idle: desc.idle,
            root_position: Vec3::from_array(desc.root_position),
            root_rotation: unit_quat(quat_wxyz(desc.root_rotation)),
            count: desc.segments.len(),
            segments: [EMPTY_SEGMENT; N],
            parents: [NO_PARENT; N],
            offsets: [Vec3::ZERO; N],
            rest: Pose::default(),
            servos: desc.servos,
            params: desc.params,
            goals: desc.goals,
            hash: desc.rig_hash(),
        });
        for (((seg, parent), offset), d) in rig
            .segments
            .iter_mut()
            .zip(rig.parents.iter_mut())
            .zip(rig.offsets.iter_mut())
            .zip(desc.segments.iter())
        {
            *seg = Segment {
                name: d.name,
                parent: d.parent,
                origin: Vec3::from_array(d.origin),
                joint: d.joint(),
                touch: Vec3::from_array(d.touch),
            };
            *parent = d.parent;
            *offset = seg.origin;
        }
        match rig.compute_rest() {
            Ok(pose) => {
                rig.rest = pose;
                Ok(())
            }
            Err(e) => {
                *slot = None;
                Err(e)
            }
        }
    }

    fn compute_rest(&self) -> Result<Pose<N>, RigError> {
        let body = self.body();
        body.validate()?;
        let angles = self.rest_angles::<N>()?;
        let mut local = LocalPose::default();
        let mut pose = Pose::default();
        angles.forward(&body, &mut local, &mut pose)?;
        Ok(pose)
    }

    /// The rig's name.
    #[must_use]
    pub fn name(&self) -> &'a str {
        self.name
    }

    /// The control-loop period, µs.
    #[must_use]
    pub fn frame_period_us(&self) -> u32 {
        self.frame_period_us
    }

    /// The control-loop period, seconds.
    #[must_use]
    pub fn frame_period_s(&self) -> f32 {
        self.frame_period_us as f32 * 1e-6
    }

    /// The fail-safe timeout, ms.
    #[must_use]
    pub fn failsafe_timeout_ms(&self) -> u32 {
        self.failsafe_timeout_ms
    }

    /// The servo back-end.
    #[must_use]
    pub fn output(&self) -> Output {
        self.output
    }

    /// What the outputs do at rest after a disarm or fail-safe.
    #[must_use]
    pub fn idle(&self) -> Idle {
        self.idle
    }

    /// The skeleton hash (see the module doc); equals the `rig_hash` of the
    /// tables built for this rig.
    #[must_use]
    pub fn rig_hash(&self) -> u64 {
        self.hash
    }

    /// The body tree, borrowing the rig.
    #[must_use]
    pub fn body(&self) -> Body<'_> {
        Body {
            segments: self.segments.get(..self.count).unwrap_or(&[]),
            parents: self.parents.get(..self.count).unwrap_or(&[]),
            offsets: self.offsets.get(..self.count).unwrap_or(&[]),
        }
    }

    /// The servo channels, in rig-file order.
    #[must_use]
    pub fn servos(&self) -> &[ServoDesc] {
        self.servos.as_slice()
    }

    /// The sensor → parameter entries.
    #[must_use]
    pub fn params(&self) -> &[ParamMap] {
        self.params.as_slice()
    }

    /// The goal entries.
    #[must_use]
    pub fn goals(&self) -> &[GoalMap] {
        self.goals.as_slice()
    }

    /// The sensors the rig reads, one bit per sensor id (bit `id`): its
    /// parameter entries' and sensor goals', and the sensors they are read
    /// relative to.
    #[must_use]
    pub fn sensors_read(&self) -> u16 {
        let bit = |id: u8| 1u16.checked_shl(u32::from(id)).unwrap_or(0);
        let frame = |f: RefFrame| match f {
            RefFrame::Sensor(id) => bit(id),
            _ => 0,
        };
        let params = self.params.iter().map(|m| bit(m.sensor) | frame(m.frame));
        let goals = self.goals.iter().map(|g| match g.target {
            GoalSource::Sensor(s) => bit(s.sensor) | frame(s.source),
            _ => 0,
        });
        params.chain(goals).fold(0, |all, b| all | b)
    }

    /// The number of goals [`Rig::map_sensors`] writes (an entry with an
    /// orientation weight writes two).
    #[must_use]
    pub fn goal_count(&self) -> usize {
        self.goals.iter().map(GoalMap::goal_count).sum()
    }

    /// The root's rest placement (world position, orientation).
    #[must_use]
    pub fn root(&self) -> (Vec3, Quat) {
        (self.root_position, self.root_rotation)
    }

    /// The rest joint state: the root at its rest placement, every angle zero
    /// clamped into its limits.
    pub fn rest_angles<const M: usize>(&self) -> Result<Angles<M>, BodyError> {
        let mut a = Angles::<M>::rest(&self.body())?;
        a.root_position = self.root_position;
        a.root_rotation = self.root_rotation;
        Ok(a)
    }

    /// The world pose of [`Rig::rest_angles`].
    #[must_use]
    pub fn rest_pose(&self) -> &Pose<N> {
        &self.rest
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dof(axis: AxisName, min: f32, max: f32) -> DofDesc {
        DofDesc { axis, min, max }
    }

    fn arm() -> RigDesc<'static> {
        let mut d = RigDesc::new("arm", Output::Maestro { baud: 115_200 });
        let seg = |name, parent, origin, touch, dofs: &[DofDesc]| SegmentDesc {
            name,
            parent,
            origin,
            touch,
            dofs: List::from_slice(dofs).unwrap(),
        };
        d.segments
            .push(seg("base", NO_PARENT, [0.0; 3], [0.0; 3], &[]))
            .unwrap();
        d.segments
            .push(seg(
                "upper",
                0,
                [0.0, 0.1, 0.0],
                [0.0, 0.3, 0.0],
                &[dof(AxisName::Z, -1.5, 1.5), dof(AxisName::X, -1.0, 1.0)],
            ))
            .unwrap();
        d.segments
            .push(seg(
                "lower",
                1,
                [0.0, 0.3, 0.0],
                [0.0, 0.25, 0.0],
                &[dof(AxisName::Z, 0.0, 2.5)],
            ))
            .unwrap();
        d.servos
            .push(ServoDesc {
                channel: 3,
                segment: 2,
                dof: 0,
                angle_min: 0.0,
                angle_max: 2.5,
                pulse_min_us: 1000.0,
                pulse_max_us: 2000.0,
                trim_us: 0.0,
                reversed: false,
                rest_us: 1500.0,
                max_speed: 5.0,
                max_accel: 50.0,
                id: 0,
            })
            .unwrap();
        d
    }

    #[test]
    fn blob_round_trip_and_rest_bytes() {
        let d = arm();
        let mut buf = [0xAAu8; 600];
        let n = d.to_blob(&mut buf).unwrap();
        assert_eq!(n % 4, 0);
        assert_eq!(&buf[..4], b"MRIG");
        let (back, rest) = RigDesc::from_blob(&buf).unwrap();
        assert_eq!(back, d);
        assert_eq!(rest.len(), buf.len() - n);
        assert!(rest.iter().all(|&b| b == 0xAA));
        let (rig, _) = Rig::parse(&buf[..n]).unwrap();
        assert_eq!(rig.body().len(), 3);
        assert_eq!(rig.body().find("lower"), Some(2));
        assert_eq!(rig.body().validate(), Ok(()));
        assert_eq!(rig.servos()[0].channel, 3);
        assert_eq!(rig.rig_hash(), d.rig_hash());
        // Rest: the lower segment's origin at 0.1 + 0.3 above the root.
        let p = rig.rest_pose().positions[2];
        assert!((p - Vec3::new(0.0, 0.4, 0.0)).length() < 1e-6);
    }

    #[test]
    fn a_rig_over_the_capacity_is_refused() {
        let d = arm();
        let mut buf = [0u8; 600];
        let n = d.to_blob(&mut buf).unwrap();
        let over = RigError::Capacity {
            segments: 3,
            capacity: 2,
        };
        assert_eq!(Rig::<'_, 2>::parse_sized(&buf[..n]).err(), Some(over));
        assert_eq!(Rig::<'_, 2>::from_desc_sized(&d).err(), Some(over));
        let mut slot = None;
        assert_eq!(Rig::<'_, 2>::parse_into(&buf[..n], &mut slot), Err(over));
        assert!(slot.is_none());
        // At capacity it parses, and equals the full-capacity rig.
        let (small, rest) = Rig::<'_, 3>::parse_sized(&buf[..n]).unwrap();
        let (full, _) = Rig::parse(&buf[..n]).unwrap();
        assert!(rest.is_empty());
        assert_eq!(small.body().segments, full.body().segments);
        assert_eq!(small.rest_pose().positions(), full.rest_pose().positions());
        assert_eq!(small.rig_hash(), full.rig_hash());
        // A damaged blob is a CRC error at any capacity.
        let mut bad = buf;
        bad[PREFIX_LEN + 2] ^= 1;
        assert_eq!(
            Rig::<'_, 2>::parse_sized(&bad[..n]).err(),
            Some(RigError::Crc)
        );
    }

    #[test]
    fn every_covered_byte_is_checked() {
        let d = arm();
        let mut buf = [0u8; 600];
        let n = d.to_blob(&mut buf).unwrap();
        let len = u32::from_le_bytes(buf[6..10].try_into().unwrap()) as usize;
        let covered = PREFIX_LEN + len + CRC_LEN;
        assert!(covered <= n && n - covered < 4);
        for i in 0..covered {
            let mut b = buf;
            b[i] ^= 0x5A;
            assert!(Rig::parse(&b[..n]).is_err(), "byte {i} not covered");
        }
        for cut in 0..covered {
            assert!(Rig::parse(&buf[..cut]).is_err(), "cut at {cut}");
        }
        // Without its padding the blob still parses (the padding is optional
        // at the end of the bytes).
        assert!(Rig::parse(&buf[..covered]).is_ok());
    }

    #[test]
    fn hash_covers_the_skeleton_only() {
        let d = arm();
        let mut e = d;
        e.servos = List::new();
        e.output = Output::Pwm { freq_hz: 50 };
        assert_eq!(d.rig_hash(), e.rig_hash());
        let mut f = d;
        f.segments = List::from_slice(&d.segments.as_slice()[..2]).unwrap();
        assert_ne!(d.rig_hash(), f.rig_hash());
    }

    #[test]
    fn validation_names_the_field() {
        let bad = |f: &dyn Fn(&mut RigDesc<'static>)| {
            let mut d = arm();
            f(&mut d);
            match d.validate() {
                Err(RigError::Invalid(i)) => (i.place, i.field, i.problem),
                other => panic!("{other:?}"),
            }
        };
        assert_eq!(
            bad(&|d| d.servos = List::from_slice(&[d.servos.as_slice()[0]; 2]).unwrap()),
            (Place::Servo(1), "channel", Problem::Duplicate)
        );
        let mut s = arm().segments.as_slice()[2];
        s.parent = 2;
        assert_eq!(
            bad(&|d| d.segments =
                List::from_slice(&[d.segments.as_slice()[0], d.segments.as_slice()[1], s])
                    .unwrap()),
            (Place::Segment(2), "parent", Problem::NotTopological)
        );
        let mut s = arm().segments.as_slice()[2];
        s.dofs = List::from_slice(&[dof(AxisName::Z, 1.0, 0.0)]).unwrap();
        assert_eq!(
            bad(&|d| d.segments =
                List::from_slice(&[d.segments.as_slice()[0], d.segments.as_slice()[1], s])
                    .unwrap()),
            (
                Place::Dof { segment: 2, dof: 0 },
                "limits",
                Problem::Unordered
            )
        );
        assert_eq!(
            bad(&|d| d.root_position[1] = f32::NAN),
            (Place::Rig, "root_position", Problem::NonFinite)
        );
        assert_eq!(
            bad(&|d| d.output = Output::Pca9685 {
                i2c_addr: 0x80,
                freq_hz: 50
            }),
            (Place::Output, "i2c_addr", Problem::OutOfRange)
        );
    }
}
