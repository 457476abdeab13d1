//! The blob header: the postcard-encoded description of a table, and its
//! fixed-size parts (axes, spans).

use serde::{Deserialize, Serialize};

use crate::grid;

/// Bytes of a fixed-size name (axis or segment): UTF-8, padded with zero bytes.
pub const NAME_LEN: usize = 24;

/// Most axes a table may have (parameter axes plus, for clip tables, the phase
/// axis).
pub const MAX_AXES: usize = 6;

/// Most segments a table may have.
pub const MAX_SEGMENTS: usize = 256;

/// How an axis treats coordinates beyond its samples.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Wrap {
    /// Samples cover `[min, min + (count − 1)·step]`; outside is clamped.
    Bounded,
    /// The axis repeats with this period; `count · step == period`, and the
    /// sample after the last is the first.
    Cyclic {
        /// Length of one period, in axis units.
        period: f32,
    },
}

/// How to interpolate between samples along an axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Interp {
    /// Lerp positions and slerp rotations between the two neighbours.
    Linear,
    /// Catmull-Rom over a window of four samples.
    CatmullRom,
}

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

    /// Whether the stored values describe a usable axis, by the same rule as
    /// [`crate::grid::Grid::new`]: `count ≥ 2`, finite `min`, finite
    /// `step > 0`, and for a cyclic axis `period = count · step` to 1e-5
    /// relative.
    #[must_use]
    pub fn is_valid(&self) -> bool {
        let ok =
            self.count >= 2 && self.min.is_finite() && self.step.is_finite() && self.step > 0.0;
        let period_ok = match self.wrap {
            Wrap::Bounded => true,
            Wrap::Cyclic { period } => {
                let expect = f32::from(self.count) * self.step;
                crate::math::abs(period - expect) <= 1e-5 * expect
            }
        };
        ok && period_ok
    }

    /// Number of cells: `count − 1` bounded, `count` cyclic.
    #[must_use]
    pub fn cells(&self) -> usize {
        match self.wrap {
            Wrap::Bounded => usize::from(self.count).saturating_sub(1),
            Wrap::Cyclic { .. } => usize::from(self.count),
        }
    }

    /// The axis as the synthesis grid takes it.
    #[must_use]
    pub fn to_grid(&self) -> grid::Axis {
        grid::Axis {
            min: self.min,
            step: self.step,
            count: u32::from(self.count),
            kind: match self.wrap {
                Wrap::Bounded => grid::AxisKind::Bounded,
                Wrap::Cyclic { period } => grid::AxisKind::Cyclic { period },
            },
            interp: match self.interp {
                Interp::Linear => grid::Interp::Linear,
                Interp::CatmullRom => grid::Interp::CatmullRom,
            },
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
}

/// A fixed-size name without its zero padding (`None` if not UTF-8).
#[must_use]
pub fn name_str(bytes: &[u8]) -> Option<&str> {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    core::str::from_utf8(bytes.get(..end)?).ok()
}
