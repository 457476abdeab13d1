//! BVH (Biovision Hierarchy) import.
//!
//! Accepts any hierarchy and any channel list per joint: 0 to 6 channels
//! named `Xposition Yposition Zposition Xrotation Yrotation Zrotation`, in any
//! order, each at most once; `End Site` blocks; CRLF or LF line endings.
//! Tested on the CMU 31-joint cgspeed files (root 6 channels, others
//! `Zrotation Yrotation Xrotation`) and the ~100-joint iClone rig.
//!
//! # Semantics
//!
//! * **Rotation.** A joint's rotation channels, read in the order listed
//!   (`c1 c2 c3`), give `R = R_c1(a1) · R_c2(a2) · R_c3(a3)` acting on column
//!   vectors: intrinsic rotations in the listed order (equivalently,
//!   extrinsic in reverse order). Angles are degrees. `R` is the joint's
//!   rotation relative to its parent's frame.
//! * **Position.** Offsets and position channels are multiplied by the
//!   caller's `scale` (see the table in [`crate::import`]). A joint's local
//!   translation is `OFFSET + (Xposition, Yposition, Zposition)` — the
//!   channels are *added* to the offset. This matters for the iClone files,
//!   whose root `OFFSET` is 105.2 cm with `Yposition` near 0: adding gives a
//!   standing hip height, replacing would put the hips on the floor. (bvhio,
//!   used as a reference in the tests, replaces; CMU roots have zero offsets,
//!   so both agree there.)
//! * **Frames.** After `MOTION`, `Frames: n` and `Frame Time: t` (seconds,
//!   finite and > 0), exactly `n` non-blank lines of exactly as many numbers
//!   as there are channels. Blank lines are skipped. Anything after the last
//!   frame other than blank lines is an error.
//!
//! [`FrameReader`] streams frames one at a time after reading the
//! hierarchy; [`parse`] and [`read`] collect them all into a [`Bvh`].

use std::io::BufRead;
use std::path::Path;

use glam::{DQuat, DVec3};

use super::{
    Axis, Frame, ImportError, Joint, Lines, MAX_JOINTS, Motion, check_scale, finite, number_error,
};

/// One BVH channel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Channel {
    /// Translation along X (scaled to metres).
    Xposition,
    /// Translation along Y (scaled to metres).
    Yposition,
    /// Translation along Z (scaled to metres).
    Zposition,
    /// Rotation about X, degrees.
    Xrotation,
    /// Rotation about Y, degrees.
    Yrotation,
    /// Rotation about Z, degrees.
    Zrotation,
}

impl Channel {
    fn from_token(token: &str) -> Option<Self> {
        Some(match token {
            "Xposition" => Self::Xposition,
            "Yposition" => Self::Yposition,
            "Zposition" => Self::Zposition,
            "Xrotation" => Self::Xrotation,
            "Yrotation" => Self::Yrotation,
            "Zrotation" => Self::Zrotation,
            _ => return None,
        })
    }

    /// The rotation axis, for rotation channels.
    #[must_use]
    pub fn rotation_axis(self) -> Option<Axis> {
        match self {
            Self::Xrotation => Some(Axis::X),
            Self::Yrotation => Some(Axis::Y),
            Self::Zrotation => Some(Axis::Z),
            _ => None,
        }
    }

    /// The translation component index (0 = x), for position channels.
    #[must_use]
    pub fn position_index(self) -> Option<usize> {
        match self {
            Self::Xposition => Some(0),
            Self::Yposition => Some(1),
            Self::Zposition => Some(2),
            _ => None,
        }
    }
}

/// One joint (or End Site) of a BVH hierarchy.
#[derive(Clone, Debug, PartialEq)]
pub struct BvhJoint {
    /// Name; End Sites are named `<parent name>.end`.
    pub name: String,
    /// Parent index (`None` for the root). Parents precede children.
    pub parent: Option<usize>,
    /// `OFFSET` × scale, metres.
    pub offset: DVec3,
    /// Channels in file order (empty for End Sites).
    pub channels: Vec<Channel>,
    /// Index of this joint's first channel within a frame's values.
    pub first_channel: usize,
    /// Whether this is an `End Site`.
    pub end_site: bool,
}

impl BvhJoint {
    /// This joint's rotation relative to its parent for the channel values
    /// `values` of a whole frame (see the module docs for the convention).
    /// Missing values count as 0.
    #[must_use]
    pub fn rotation(&self, values: &[f64]) -> DQuat {
        self.channel_values(values)
            .fold(DQuat::IDENTITY, |q, (channel, value)| {
                match channel.rotation_axis() {
                    Some(axis) => q * axis.rotation(value.to_radians()),
                    None => q,
                }
            })
    }

    /// The translation added to [`BvhJoint::offset`] by this joint's position
    /// channels in `values` (already in metres).
    #[must_use]
    pub fn translation(&self, values: &[f64]) -> DVec3 {
        let mut t = DVec3::ZERO;
        for (channel, value) in self.channel_values(values) {
            match channel.position_index() {
                Some(0) => t.x = value,
                Some(1) => t.y = value,
                Some(2) => t.z = value,
                _ => {}
            }
        }
        t
    }

    fn channel_values<'a>(
        &'a self,
        values: &'a [f64],
    ) -> impl Iterator<Item = (Channel, f64)> + 'a {
        let mine = values.get(self.first_channel..).unwrap_or(&[]);
        self.channels.iter().copied().zip(mine.iter().copied())
    }
}

/// The `HIERARCHY` and `MOTION` header of a BVH file.
#[derive(Clone, Debug, PartialEq)]
pub struct BvhHeader {
    /// File name (for errors).
    pub source: String,
    /// Joints and End Sites in file (depth-first) order.
    pub joints: Vec<BvhJoint>,
    /// Total channels per frame.
    pub channel_count: usize,
    /// `Frames:` from the file.
    pub frame_count: usize,
    /// `Frame Time:` in seconds.
    pub frame_time: f64,
    /// Length scale applied to offsets and position channels.
    pub scale: f64,
}

/// A whole BVH file: header and all frames' channel values.
#[derive(Clone, Debug, PartialEq)]
pub struct Bvh {
    /// The header.
    pub header: BvhHeader,
    /// Channel values, frame after frame (`frame_count × channel_count`);
    /// positions in metres, rotations in degrees, in channel order.
    pub values: Vec<f64>,
}

impl Bvh {
    /// Number of frames.
    #[must_use]
    pub fn frame_count(&self) -> usize {
        self.header.frame_count
    }

    /// Channel values of frame `index`.
    #[must_use]
    pub fn frame(&self, index: usize) -> Option<&[f64]> {
        let n = self.header.channel_count;
        let start = index.checked_mul(n)?;
        self.values.get(start..start.checked_add(n)?)
    }

    /// Converts to the common [`Motion`].
    ///
    /// # Errors
    /// [`ImportError::Convert`] if a non-root joint's position channels are
    /// non-zero in some frame: the common form (like the core's
    /// `LocalPose`) only translates the root.
    pub fn to_motion(&self) -> Result<Motion, ImportError> {
        let joints = self.header.joints.iter().map(|j| Joint {
            name: j.name.clone(),
            parent: j.parent,
            offset: j.offset,
            end_site: j.end_site,
        });
        let mut motion = Motion {
            source: self.header.source.clone(),
            joints: joints.collect(),
            frame_time: self.header.frame_time,
            frames: Vec::with_capacity(self.header.frame_count),
        };
        for index in 0..self.header.frame_count {
            let values = self.frame(index).unwrap_or(&[]);
            motion.frames.push(self.header.motion_frame(values, index)?);
        }
        Ok(motion)
    }
}

impl BvhHeader {
    /// One frame's channel values as a [`Frame`] of the common [`Motion`];
    /// `index` only labels errors.
    ///
    /// # Errors
    /// [`ImportError::Convert`] if a non-root joint is translated.
    pub fn motion_frame(&self, values: &[f64], index: usize) -> Result<Frame, ImportError> {
        let mut frame = Frame {
            root_position: DVec3::ZERO,
            rotations: Vec::with_capacity(self.joints.len()),
        };
        for joint in &self.joints {
            let t = joint.translation(values);
            if joint.parent.is_none() {
                frame.root_position = joint.offset + t;
            } else if t != DVec3::ZERO {
                return Err(ImportError::Convert {
                    file: self.source.clone(),
                    frame: index,
                    problem: format!(
                        "joint {:?} has non-zero position channels; only the root may translate",
                        joint.name
                    ),
                });
            }
            frame.rotations.push(joint.rotation(values));
        }
        Ok(frame)
    }
}

/// Reads a BVH file from disk (see [`parse`]).
///
/// # Errors
/// As [`parse`], plus [`ImportError::Io`] if the file cannot be opened.
pub fn read(path: &Path, scale: f64) -> Result<Bvh, ImportError> {
    parse(super::open(path)?, &path.display().to_string(), scale)
}

/// Reads a BVH file from disk straight into the common [`Motion`].
///
/// # Errors
/// As [`read`] and [`Bvh::to_motion`].
pub fn read_motion(path: &Path, scale: f64) -> Result<Motion, ImportError> {
    read(path, scale)?.to_motion()
}

/// Parses a whole BVH file; `file` names it in errors; `scale` converts its
/// length unit to metres.
///
/// # Errors
/// Any [`ImportError`] describing the first problem found, with its line.
pub fn parse<R: BufRead>(reader: R, file: &str, scale: f64) -> Result<Bvh, ImportError> {
    let mut frames = FrameReader::new(reader, file, scale)?;
    let header = frames.header().clone();
    let mut values = Vec::with_capacity(
        header
            .frame_count
            .saturating_mul(header.channel_count)
            .min(1 << 24),
    );
    while frames.next_frame(&mut values)? {}
    Ok(Bvh { header, values })
}

/// Streams a BVH file: the header is parsed by [`FrameReader::new`], then
/// [`FrameReader::next_frame`] reads one frame at a time.
pub struct FrameReader<R> {
    lines: Lines<R>,
    header: BvhHeader,
    read: usize,
    /// Per channel: `scale` for position channels, 1 for rotations.
    factors: Vec<f64>,
}

impl<R: BufRead> FrameReader<R> {
    /// Reads the header (`HIERARCHY` to `Frame Time:`).
    ///
    /// # Errors
    /// Any [`ImportError`] in the header.
    pub fn new(reader: R, file: &str, scale: f64) -> Result<Self, ImportError> {
        check_scale(file, scale)?;
        let mut tokens = Tokens {
            lines: Lines::new(reader, file),
            words: Vec::new(),
            next: 0,
        };
        let header = parse_header(&mut tokens, scale)?;
        let channels = header.joints.iter().flat_map(|j| &j.channels);
        let factors = channels
            .map(|c| {
                if c.position_index().is_some() {
                    scale
                } else {
                    1.0
                }
            })
            .collect();
        Ok(Self {
            lines: tokens.lines,
            header,
            read: 0,
            factors,
        })
    }

    /// The header.
    #[must_use]
    pub fn header(&self) -> &BvhHeader {
        &self.header
    }

    /// Appends the next frame's channel values to `out`; returns `false`
    /// (appending nothing) after the last frame, having checked that only
    /// blank lines follow it.
    ///
    /// # Errors
    /// Missing frames, wrong value counts, non-numbers, NaN/infinity, or
    /// content after the last frame.
    pub fn next_frame(&mut self, out: &mut Vec<f64>) -> Result<bool, ImportError> {
        if self.read >= self.header.frame_count {
            return self.expect_end().map(|()| false);
        }
        let expected = self.header.channel_count;
        let frame_no = self.read.saturating_add(1);
        loop {
            if !self.lines.advance()? {
                return Err(self
                    .lines
                    .eof(&format!("frame {frame_no} of {}", self.header.frame_count)));
            }
            let line = self.lines.text();
            if line.trim().is_empty() {
                continue;
            }
            let start = out.len();
            let mut found = 0usize;
            let mut factors = self.factors.iter();
            for token in line.split_ascii_whitespace() {
                found = found.saturating_add(1);
                let Some(factor) = factors.next() else {
                    continue;
                };
                let Some(value) = finite(token) else {
                    out.truncate(start);
                    let field = format!("frame {frame_no} value {found}");
                    return Err(number_error(
                        self.lines.file(),
                        self.lines.number(),
                        token,
                        &field,
                    ));
                };
                out.push(value * factor);
            }
            if found != expected {
                out.truncate(start);
                return Err(self.lines.syntax(
                    &format!("frame {frame_no}"),
                    &format!("{expected} values (one per channel)"),
                    Some(&format!("{found} values")),
                ));
            }
            self.read = frame_no;
            return Ok(true);
        }
    }

    fn expect_end(&mut self) -> Result<(), ImportError> {
        while self.lines.advance()? {
            if let Some(token) = self.lines.text().split_ascii_whitespace().next() {
                let token = token.to_owned();
                let field = format!("after frame {}", self.header.frame_count);
                return Err(self.lines.syntax(
                    &field,
                    "end of file (Frames: count reached)",
                    Some(&token),
                ));
            }
        }
        Ok(())
    }
}

/// Whitespace-separated tokens over [`Lines`], remembering line numbers.
struct Tokens<R> {
    lines: Lines<R>,
    words: Vec<String>,
    next: usize,
}

impl<R: BufRead> Tokens<R> {
    /// The next token, crossing lines; `None` at the end of the file.
    fn next(&mut self) -> Result<Option<String>, ImportError> {
        loop {
            if let Some(word) = self.words.get(self.next) {
                self.next = self.next.saturating_add(1);
                return Ok(Some(word.clone()));
            }
            if !self.lines.advance()? {
                return Ok(None);
            }
            self.words = self
                .lines
                .text()
                .split_ascii_whitespace()
                .map(str::to_owned)
                .collect();
            self.next = 0;
        }
    }

    /// The next token, which must exist (`expected` describes it).
    fn require(&mut self, expected: &str) -> Result<String, ImportError> {
        self.next()?.ok_or_else(|| self.lines.eof(expected))
    }

    /// The next token, which must equal `keyword`.
    fn keyword(&mut self, keyword: &str, field: &str) -> Result<(), ImportError> {
        let token = self.require(&format!("{keyword:?}"))?;
        if token == keyword {
            Ok(())
        } else {
            Err(self
                .lines
                .syntax(field, &format!("{keyword:?}"), Some(&token)))
        }
    }

    /// The rest of the current line joined by single spaces (a joint name
    /// may contain spaces), minus a trailing `{`, which is pushed back.
    fn rest_of_line(&mut self) -> String {
        let rest = self.words.get(self.next..).unwrap_or(&[]);
        let (name, pushed_back) = match rest.split_last() {
            Some((last, init)) if last == "{" => (init.join(" "), 1),
            _ => (rest.join(" "), 0),
        };
        self.next = self.words.len().saturating_sub(pushed_back);
        name
    }

    /// The next token as a finite number for `field`.
    fn number(&mut self, field: &str) -> Result<f64, ImportError> {
        let token = self.require(&format!("{field} (a number)"))?;
        self.lines.number_f64(&token, field)
    }
}

/// Where the hierarchy parser is: inside joint `index`, whose `{` was read.
struct Open {
    index: usize,
    has_children: bool,
}

fn parse_header<R: BufRead>(t: &mut Tokens<R>, scale: f64) -> Result<BvhHeader, ImportError> {
    t.keyword("HIERARCHY", "file start")?;
    t.keyword("ROOT", "first joint")?;
    let mut joints = Vec::new();
    let mut channel_count = 0usize;
    let mut stack = vec![open_joint(t, &mut joints, None, scale, &mut channel_count)?];
    while let Some(top) = stack.last_mut() {
        let token = t.require("JOINT, End Site or \"}\"")?;
        match token.as_str() {
            "JOINT" => {
                top.has_children = true;
                let parent = Some(top.index);
                let child = open_joint(t, &mut joints, parent, scale, &mut channel_count)?;
                stack.push(child);
            }
            "End" => {
                top.has_children = true;
                let parent = top.index;
                end_site(t, &mut joints, parent, scale)?;
            }
            "}" => {
                stack.pop();
            }
            _ => {
                return Err(t
                    .lines
                    .syntax("joint body", "JOINT, End Site or \"}\"", Some(&token)));
            }
        }
    }
    t.keyword("MOTION", "after the hierarchy")?;
    let frame_count = frames_line(t)?;
    let frame_time = frame_time_line(t)?;
    if let Some(extra) = t.words.get(t.next) {
        return Err(t.lines.syntax(
            "Frame Time",
            "end of line (frames start on the next line)",
            Some(extra),
        ));
    }
    let source = t.lines.file().to_owned();
    Ok(BvhHeader {
        source,
        joints,
        channel_count,
        frame_count,
        frame_time,
        scale,
    })
}

/// After `ROOT`/`JOINT`: name, `{`, `OFFSET`, `CHANNELS`.
fn open_joint<R: BufRead>(
    t: &mut Tokens<R>,
    joints: &mut Vec<BvhJoint>,
    parent: Option<usize>,
    scale: f64,
    channel_count: &mut usize,
) -> Result<Open, ImportError> {
    let name = t.rest_of_line();
    if name.is_empty() {
        return Err(t
            .lines
            .syntax("joint name", "a name after ROOT/JOINT", None));
    }
    if joints.iter().any(|j: &BvhJoint| j.name == name) {
        return Err(t
            .lines
            .invalid("joint name", format!("duplicate joint {name:?}")));
    }
    if joints.len() >= MAX_JOINTS {
        return Err(t.lines.too_many("joints", MAX_JOINTS));
    }
    t.keyword("{", &format!("joint {name}"))?;
    let offset = offset(t, &name, scale)?;
    t.keyword("CHANNELS", &format!("joint {name}"))?;
    let channels = channels(t, &name)?;
    let first_channel = *channel_count;
    *channel_count = channel_count.saturating_add(channels.len());
    joints.push(BvhJoint {
        name,
        parent,
        offset,
        channels,
        first_channel,
        end_site: false,
    });
    Ok(Open {
        index: joints.len().saturating_sub(1),
        has_children: false,
    })
}

/// After `End`: `Site`, `{`, `OFFSET x y z`, `}`.
fn end_site<R: BufRead>(
    t: &mut Tokens<R>,
    joints: &mut Vec<BvhJoint>,
    parent: usize,
    scale: f64,
) -> Result<(), ImportError> {
    let parent_name = joints
        .get(parent)
        .map(|j| j.name.clone())
        .unwrap_or_default();
    t.keyword("Site", &format!("End Site of {parent_name}"))?;
    t.keyword("{", &format!("End Site of {parent_name}"))?;
    let offset = offset(t, &format!("End Site of {parent_name}"), scale)?;
    t.keyword("}", &format!("End Site of {parent_name}"))?;
    if joints.len() >= MAX_JOINTS {
        return Err(t.lines.too_many("joints", MAX_JOINTS));
    }
    let name = format!("{parent_name}.end");
    joints.push(BvhJoint {
        name,
        parent: Some(parent),
        offset,
        channels: Vec::new(),
        first_channel: 0,
        end_site: true,
    });
    Ok(())
}

fn offset<R: BufRead>(t: &mut Tokens<R>, owner: &str, scale: f64) -> Result<DVec3, ImportError> {
    t.keyword("OFFSET", owner)?;
    let x = t.number(&format!("{owner} OFFSET x"))?;
    let y = t.number(&format!("{owner} OFFSET y"))?;
    let z = t.number(&format!("{owner} OFFSET z"))?;
    Ok(DVec3::new(x, y, z) * scale)
}

fn channels<R: BufRead>(t: &mut Tokens<R>, owner: &str) -> Result<Vec<Channel>, ImportError> {
    let field = format!("{owner} CHANNELS");
    let token = t.require("channel count")?;
    let count: usize = token.parse().map_err(|_| {
        t.lines
            .syntax(&field, "a channel count 0..=6", Some(&token))
    })?;
    if count > 6 {
        return Err(t
            .lines
            .syntax(&field, "a channel count 0..=6", Some(&token)));
    }
    let mut channels = Vec::with_capacity(count);
    for i in 0..count {
        let token = t.require(&format!("{count} channel names"))?;
        let expected = "Xposition, Yposition, Zposition, Xrotation, Yrotation or Zrotation";
        let Some(channel) = Channel::from_token(&token) else {
            return Err(t.lines.syntax(
                &format!("{field} name {}", i.saturating_add(1)),
                expected,
                Some(&token),
            ));
        };
        if channels.contains(&channel) {
            return Err(t
                .lines
                .invalid(&field, format!("channel {token} listed twice")));
        }
        channels.push(channel);
    }
    Ok(channels)
}

/// `Frames: n` (also accepts `Frames:` and `n` on separate tokens only).
fn frames_line<R: BufRead>(t: &mut Tokens<R>) -> Result<usize, ImportError> {
    t.keyword("Frames:", "MOTION")?;
    let token = t.require("frame count")?;
    token.parse().map_err(|_| {
        t.lines.syntax(
            "Frames:",
            "a frame count (non-negative integer)",
            Some(&token),
        )
    })
}

/// `Frame Time: t` with `t` finite and positive.
fn frame_time_line<R: BufRead>(t: &mut Tokens<R>) -> Result<f64, ImportError> {
    t.keyword("Frame", "MOTION")?;
    t.keyword("Time:", "MOTION")?;
    let time = t.number("Frame Time")?;
    if time > 0.0 {
        Ok(time)
    } else {
        Err(t
            .lines
            .invalid("Frame Time", format!("must be positive, got {time}")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TINY: &str = "HIERARCHY\nROOT a\n{\n OFFSET 1 2 3\n CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\n JOINT b\n {\n  OFFSET 0 10 0\n  CHANNELS 3 Xrotation Yrotation Zrotation\n  End Site\n  {\n   OFFSET 0 5 0\n  }\n }\n}\nMOTION\nFrames: 2\nFrame Time: 0.5\n0 0 0 0 0 0 0 0 0\n1 2 3 90 0 0 0 0 90\n";

    #[test]
    fn tiny_file_structure_and_values() {
        let bvh = parse(TINY.as_bytes(), "tiny.bvh", 0.1).unwrap();
        let h = &bvh.header;
        assert_eq!(h.joints.len(), 3);
        assert_eq!(h.channel_count, 9);
        assert_eq!(h.frame_count, 2);
        assert_eq!(h.frame_time, 0.5);
        assert_eq!(h.joints[1].parent, Some(0));
        assert_eq!(h.joints[2].name, "b.end");
        assert!(h.joints[2].end_site);
        assert!((h.joints[1].offset - DVec3::new(0.0, 1.0, 0.0)).length() < 1e-12);
        // position channels are scaled, rotations are not
        assert_eq!(
            bvh.frame(1).unwrap()[..4],
            [0.1, 0.2, 0.30000000000000004, 90.0]
        );
        let m = bvh.to_motion().unwrap();
        // root translation = (OFFSET + channels) * scale
        assert!((m.frames[1].root_position - DVec3::new(0.2, 0.4, 0.6)).length() < 1e-12);
        // Zrotation 90 deg about Z: x -> y
        let r = m.frames[1].rotations[0] * DVec3::X;
        assert!((r - DVec3::Y).length() < 1e-12);
    }

    #[test]
    fn rotation_order_is_intrinsic_in_listed_order() {
        // Channels "Zrotation Xrotation": R = Rz(90) * Rx(90). Applied to +Y:
        // Rx(90) takes +Y to +Z, Rz(90) leaves +Z. The other order would give -X... check both.
        let j = BvhJoint {
            name: "j".into(),
            parent: None,
            offset: DVec3::ZERO,
            channels: vec![Channel::Zrotation, Channel::Xrotation],
            first_channel: 0,
            end_site: false,
        };
        let v = j.rotation(&[90.0, 90.0]) * DVec3::Y;
        assert!((v - DVec3::Z).length() < 1e-12, "{v}");
        let j2 = BvhJoint {
            channels: vec![Channel::Xrotation, Channel::Zrotation],
            ..j
        };
        // Rx(90) * Rz(90): Rz takes +Y to -X, Rx leaves -X.
        let v2 = j2.rotation(&[90.0, 90.0]) * DVec3::Y;
        assert!((v2 + DVec3::X).length() < 1e-12, "{v2}");
    }

    #[test]
    fn frame_reader_streams() {
        let mut r = FrameReader::new(TINY.as_bytes(), "tiny.bvh", 1.0).unwrap();
        let mut v = Vec::new();
        assert!(r.next_frame(&mut v).unwrap());
        assert_eq!(v.len(), 9);
        assert!(r.next_frame(&mut v).unwrap());
        assert_eq!(v.len(), 18);
        assert!(!r.next_frame(&mut v).unwrap());
        assert_eq!(v.len(), 18);
    }

    #[test]
    fn joint_name_with_brace_on_same_line() {
        let text = TINY.replace("JOINT b\n {", "JOINT b {");
        let bvh = parse(text.as_bytes(), "t.bvh", 1.0).unwrap();
        assert_eq!(bvh.header.joints[1].name, "b");
    }

    #[test]
    fn non_root_translation_is_rejected_by_to_motion() {
        let text = TINY.replace(
            "CHANNELS 3 Xrotation Yrotation Zrotation",
            "CHANNELS 6 Xposition Yposition Zposition Xrotation Yrotation Zrotation",
        );
        let text = text.replace(
            "0 0 0 0 0 0 0 0 0\n1 2 3 90 0 0 0 0 90",
            "0 0 0 0 0 0 0 0 0 0 0 0\n0 0 0 0 0 0 0 1 0 0 0 0",
        );
        let bvh = parse(text.as_bytes(), "t.bvh", 1.0).unwrap();
        let err = bvh.to_motion().unwrap_err();
        assert!(
            matches!(err, ImportError::Convert { frame: 1, .. }),
            "{err}"
        );
    }
}
