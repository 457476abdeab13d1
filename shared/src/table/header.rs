//! The blob header: the postcard-encoded description of a table, and its
//! fixed-size parts (axes, spans).

use serde::{Deserialize, Serialize};

use crate::grid::{self, InvalidAxis};
pub use crate::grid::{Interp, Wrap};

/// Bytes of a fixed-size name (axis or segment): UTF-8, padded with zero bytes.
pub const NAME_LEN: usize = 24;

/// Most axes a table may have (parameter axes plus, for clip tables, the phase
/// axis).
pub const MAX_AXES: usize = 6;

/// Most segments a table may have.
pub const MAX_SEGMENTS: usize = 256;

/// One regular grid axis as stored in the header.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Axis {
    /// Name, UTF-8 padded with zero bytes (see [`name_str`]).
    pub name: [u8; NAME_LEN],
    /// Coordinate of the first sample.
    pub min: f32,
    /// Spacing of the samples (> 0).
    pub step: f32,
    /// Number of samples along the axis (≥ 2).
    pub count: u16,
    /// Bounded or cyclic.
    pub wrap: Wrap,
    /// Linear or Catmull-Rom.
    pub interp: Interp,
}

impl Axis {
    /// The filler of unused axis slots in [`Header::axes`].
    pub const UNUSED: Self = Self {
        name: [0; NAME_LEN],
        min: 0.0,
        step: 0.0,
        count: 0,
        wrap: Wrap::Bounded,
        interp: Interp::Linear,
    };

    /// The axis name without its zero padding (`None` if not UTF-8).
    #[must_use]
    pub fn name(&self) -> Option<&str> {
        name_str(&self.name)
    }
}

impl TryFrom<&Axis> for grid::Axis {
    type Error = InvalidAxis;

    /// The axis as the synthesis grid takes it, checked by the grid's rule
    /// ([`grid::Axis::is_valid`]).
    fn try_from(a: &Axis) -> Result<Self, InvalidAxis> {
        let axis = grid::Axis {
            min: a.min,
            step: a.step,
            count: u32::from(a.count),
            wrap: a.wrap,
            interp: a.interp,
        };
        if axis.is_valid() {
            Ok(axis)
        } else {
            Err(InvalidAxis)
        }
    }
}

/// The table's kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Kind {
    /// Static synthesis: one pose per grid sample.
    Grid,
    /// Motion synthesis: one clip per parameter sample. The last axis is the
    /// normalized clip phase: `phases` phases (a reach motion has two: rest to
    /// target, target to rest) spanning `[0, phases]`, every clip resampled to
    /// that axis's `count` frames (cyclic for looping clips). Each phase of
    /// each clip has its own duration in the durations array.
    Clips {
        /// Number of phases (≥ 1), each with its own duration.
        phases: u8,
    },
}

/// A byte range of the blob: `offset` from the first byte of the blob.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Span {
    /// Offset of the first byte, from the start of the blob (4-aligned).
    pub offset: u32,
    /// Length in bytes.
    pub len: u32,
}

/// The postcard-encoded header.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Header<'a> {
    /// Length of the whole blob, from the magic to the end of the CRC.
    pub total_len: u32,
    /// Hash of the rig the table was built for.
    pub rig_hash: u64,
    /// Static grid or clip set.
    pub kind: Kind,
    /// Number of used entries at the front of `axes` (1..=6).
    pub axis_count: u8,
    /// The axes, axis 0 fastest in the sample order; unused slots are
    /// [`Axis::UNUSED`].
    pub axes: [Axis; MAX_AXES],
    /// Number of segments per pose (1..=256).
    pub segment_count: u16,
    /// `segment_count` names of [`NAME_LEN`] bytes each.
    pub segment_names: &'a [u8],
    /// Metres per position LSB.
    pub position_scale: f32,
    /// Stated position error bound, metres (per coordinate).
    pub position_bound: f32,
    /// Stated rotation error bound, radians (rotation angle).
    pub rotation_bound: f32,
    /// The sample array: 12 bytes per (sample, segment), segment fastest.
    pub samples: Span,
    /// The validity bitmask: one bit per parameter cell, LSB first.
    pub valid: Span,
    /// Clip durations (`f32` LE, seconds), phase fastest; empty for grids.
    pub durations: Span,
    /// Looping clip tables: each parameter sample's root displacement over
    /// one cycle (`3 × f32` LE, metres, the clip frame's x, y, z); empty
    /// otherwise. Version 2 and later (a version 1 header ends before it).
    pub travel: Span,
}

/// The version 1 header: [`Header`] without `travel` (read, never written).
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
pub(super) struct HeaderV1<'a> {
    total_len: u32,
    rig_hash: u64,
    kind: Kind,
    axis_count: u8,
    axes: [Axis; MAX_AXES],
    segment_count: u16,
    segment_names: &'a [u8],
    position_scale: f32,
    position_bound: f32,
    rotation_bound: f32,
    samples: Span,
    valid: Span,
    durations: Span,
}

impl<'a> From<HeaderV1<'a>> for Header<'a> {
    fn from(h: HeaderV1<'a>) -> Self {
        Header {
            total_len: h.total_len,
            rig_hash: h.rig_hash,
            kind: h.kind,
            axis_count: h.axis_count,
            axes: h.axes,
            segment_count: h.segment_count,
            segment_names: h.segment_names,
            position_scale: h.position_scale,
            position_bound: h.position_bound,
            rotation_bound: h.rotation_bound,
            samples: h.samples,
            valid: h.valid,
            durations: h.durations,
            travel: Span::default(),
        }
    }
}

/// A fixed-size name without its zero padding (`None` if not UTF-8).
#[must_use]
pub fn name_str(bytes: &[u8]) -> Option<&str> {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    core::str::from_utf8(bytes.get(..end)?).ok()
}
