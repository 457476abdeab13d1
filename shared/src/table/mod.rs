//! The flash-resident table blob: format, quantization and the in-place reader.
//!
//! A *table* is a regular grid of poses in parameter space (Wiley & Hahn's
//! static synthesis), or a set of clips on such a grid (motion synthesis). The
//! host builds it (`marionette-host`'s `blob` module is the one writer), the
//! firmware maps the blob from flash and reads it **in place** with
//! [`Table::parse`]: the header is decoded once (borrowing the names from the
//! blob), the sample arrays are never copied, and each
//! [`Table::sample`] decodes one 12-byte segment sample on demand.
//!
//! # Blob layout
//!
//! All integers outside the header are little-endian. Offsets are from the
//! first byte of the blob.
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `"MRNT"` (`4D 52 4E 54`) |
//! | 4 | 2 | format version, `u16` LE ([`VERSION`] = 2; version 1 is read too) |
//! | 6 | 4 | header length `H`, `u32` LE (≤ [`MAX_HEADER_LEN`]) |
//! | 10 | `H` | header, postcard ([`Header`], below) |
//! | 10 + `H` | 0–3 | zero padding to a multiple of 4: the *data start* `D` |
//! | `samples.offset` | `samples.len` | sample array (below) |
//! | `valid.offset` | `valid.len` | validity bitmask (below) |
//! | `durations.offset` | `durations.len` | clip durations, `f32` LE (below) |
//! | `travel.offset` | `travel.len` | looping clips' root travel per cycle, `f32` LE (below) |
//! | `total_len − 4` | 4 | CRC-32/ISO-HDLC ([`crate::crc`]) of bytes `0 .. total_len − 4`, `u32` LE |
//!
//! The writer places the four arrays in this order right after `D`, each at a
//! 4-aligned offset, zero-padded between them. The reader only requires every
//! array to be 4-aligned and to lie within `D .. total_len − 4`. Bytes after
//! `total_len` (erased flash `0xFF`, zeros of an emulator's memory region) are
//! ignored.
//!
//! # Header (postcard 1.x wire format)
//!
//! Postcard writes struct fields in order with no tags; `u8` as one raw byte;
//! `u16`/`u32`/`u64` as unsigned LEB128 varints; `f32` as 4 bytes LE; an enum
//! as a varint variant index followed by its fields; a fixed array `[T; N]` as
//! `N` elements back to back; a byte slice as a varint length then the bytes.
//!
//! | # | field | encoding | meaning |
//! |---|---|---|---|
//! | 1 | `total_len` | varint `u32` | bytes from the magic to the end of the CRC |
//! | 2 | `rig_hash` | varint `u64` | hash of the rig the table was built for |
//! | 3 | `kind` | varint 0 = `Grid`; varint 1 = `Clips` then `phases: u8` | see [`Kind`] |
//! | 4 | `axis_count` | `u8` | 1 ..= [`MAX_AXES`] used axes |
//! | 5 | `axes` | 6 × [`Axis`] | used axes first, then [`Axis::UNUSED`] |
//! | 6 | `segment_count` | varint `u16` | 1 ..= [`MAX_SEGMENTS`] |
//! | 7 | `segment_names` | varint length, bytes | `segment_count` × [`NAME_LEN`] bytes, UTF-8, zero-padded |
//! | 8 | `position_scale` | `f32` | metres per position LSB (finite, > 0) |
//! | 9 | `position_bound` | `f32` | stated position error bound, metres |
//! | 10 | `rotation_bound` | `f32` | stated rotation error bound, radians |
//! | 11 | `samples` | [`Span`]: varint `u32` offset, varint `u32` length | the sample array |
//! | 12 | `valid` | [`Span`] | the validity bitmask |
//! | 13 | `durations` | [`Span`] | the durations (length 0 for a grid) |
//! | 14 | `travel` | [`Span`] | the root travel (length 0 but for looping clips); version 2 |
//!
//! A version 1 header ends after field 13; it is read with an empty
//! `travel` (a version 1 loop has no stored travel: zero).
//!
//! Each [`Axis`] is: `name` 24 bytes (UTF-8, zero-padded), `min: f32`,
//! `step: f32`, `count`: varint `u16`, `wrap`: varint 0 = `Bounded` or varint 1
//! = `Cyclic` then `period: f32`, `interp`: varint 0 = `Linear`, 1 =
//! `CatmullRom`.
//!
//! # Arrays
//!
//! - **Samples.** Grid samples in row-major order, axis 0 fastest (sample
//!   index `i = i₀ + n₀·(i₁ + n₁·(i₂ + …))`), and within each grid sample the
//!   `segment_count` segments in order, 12 bytes each: `samples.len` must be
//!   `∏ countₖ · segment_count · 12`. One segment sample is
//!
//!   | bytes | field |
//!   |---|---|
//!   | 0–1, 2–3, 4–5 | position x, y, z: `i16` LE codes, metres = `code · position_scale` |
//!   | 6–11 | rotation, "smallest three" in a 48-bit LE word |
//!
//!   Rotation word bits 0–1: index (in `[w, x, y, z]` order) of the dropped
//!   component, the one of largest magnitude, made positive by negating the
//!   whole quaternion; ties go to the lowest index. Bits 2–16, 17–31, 32–46:
//!   the other three components in `[w, x, y, z]` order, each 15 bits coding
//!   `v = (code − 16383) · (1/√2) / 16383` (codes 0 ..= 32766 cover
//!   `[−1/√2, 1/√2]`). Bit 47: zero (ignored by the reader). The dropped
//!   component is rebuilt as `√max(0, 1 − a² − b² − c²)` and the result
//!   renormalized. See [`quant`] for the code.
//! - **Validity bitmask.** One bit per *parameter cell*, in the layout
//!   [`crate::grid`] takes: cells are numbered row-major over the per-axis
//!   cell counts (`count − 1` on a bounded axis, `count` on a cyclic one),
//!   axis 0 fastest, over all axes for a grid and all but the last (phase)
//!   axis for clips; bit `c` is bit `c mod 8` (LSB first) of byte `c / 8`;
//!   1 = the cell is backed by data, 0 = it lies outside the data and
//!   synthesis projects queries out of it. `valid.len` must be
//!   `⌈parameter cells / 8⌉`; the writer zeroes the unused high bits.
//! - **Durations** (clips only). `f32` LE seconds, one per phase per parameter
//!   sample, phase fastest: `durations.len` must be
//!   `parameter samples · phases · 4`; 0 for a grid.
//!
//! - **Travel** (looping clip tables only, version 2). `f32` LE metres, three
//!   per parameter sample (x, y, z in the clip frame: y up, z the direction
//!   of travel), parameter sample order: `travel.len` must be
//!   `parameter samples · 12` for a clip table whose phase axis is cyclic, 0
//!   otherwise. The builder removes each loop's net root displacement from
//!   its poses (so the loop closes in place) and stores it here;
//!   [`crate::clip::Motion::travel`] interpolates it like the durations.
//!
//! # Error bound
//!
//! Against the unquantized (normalized) input, each decoded sample is within
//! `position_bound = 0.51 · position_scale` per coordinate and within
//! [`quant::ROTATION_BOUND`] = 1.75e-4 rad (0.01°) of rotation angle; the
//! analytic worst case of the rotation code is 1.495e-4 rad (0.00857°, see
//! [`quant::ROTATION_BOUND`]). The writer chooses the smallest scale that does
//! not clip the largest coordinate and refuses coordinates beyond
//! [`quant::MAX_POSITION`] = 32 m, so the position bound is below 0.5 mm
//! (0.498 mm at the full 32 m range, 0.031 mm for a 2 m figure). Both bounds
//! are stored in the header; `tests/table.rs` checks them against an `f64`
//! reference over random and edge-case rotations and at the 32 m range.
//!
//! # Size
//!
//! One blob holds one table. 31 segments × 5 × 5 × 5 samples = 46,500 bytes
//! of samples; with its header (31 names), mask and CRC the blob is 47,512
//! bytes, so five such tables fit the Black Pill's 256 KB table region (v1
//! defines no directory of several blobs; the reader ignores what follows
//! `total_len`, so blobs could be placed back to back at 4-aligned offsets).
//!
//! [`Table::sample`] decodes one segment sample on each call (no cache);
//! the grid reads a segment's whole window before interpolating
//! ([`Samples::DECODES`]). Instruction counts are in README's measured
//! section (`synth.table16.core`, `marionette icount`).

mod header;
pub mod quant;

pub use header::{
    Axis, Header, Interp, Kind, MAX_AXES, MAX_SEGMENTS, NAME_LEN, Span, Wrap, name_str,
};
pub use quant::SAMPLE_LEN;

use core::fmt;

use glam::{Quat, Vec3};

use crate::crc::crc32;
use crate::grid::{self, Grid, GridError, Samples};

/// The four magic bytes at the start of every blob.
pub const MAGIC: [u8; 4] = *b"MRNT";

/// The format version the writer writes (the reader also reads version 1,
/// which has no travel array).
pub const VERSION: u16 = 2;

/// Bytes before the header: magic, version, header length.
pub const PREFIX_LEN: usize = 10;

/// Largest accepted header length (256 segment names plus the fixed fields fit
/// with room to spare).
pub const MAX_HEADER_LEN: usize = 8192;

/// Bytes of the trailing CRC.
pub const CRC_LEN: usize = 4;

/// Why a blob was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TableError {
    /// The slice ends before the prefix, the header or `total_len`.
    Truncated,
    /// The first four bytes are not `"MRNT"`.
    BadMagic,
    /// The format version is neither 1 nor [`VERSION`].
    BadVersion {
        /// The version found in the blob.
        found: u16,
    },
    /// The header is not valid postcard for [`Header`], has trailing bytes, or
    /// holds values out of their domain (axis/segment counts, names, scale).
    BadHeader,
    /// An axis has a zero count, a non-finite or non-positive step, or an
    /// inconsistent period.
    BadAxis {
        /// Index of the offending axis.
        index: u8,
    },
    /// A length or offset points outside the blob, is misaligned, or
    /// overflows.
    BadBounds,
    /// An array's length does not match the header's shape.
    BadSize,
    /// The CRC does not match.
    BadCrc,
    /// The header does not fit the output buffer (writer side).
    BufferFull,
}

impl fmt::Display for TableError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Truncated => f.write_str("table blob truncated"),
            Self::BadMagic => f.write_str("not a table blob (bad magic)"),
            Self::BadVersion { found } => {
                write!(f, "table format version {found} (expected 1 or {VERSION})")
            }
            Self::BadHeader => f.write_str("malformed table header"),
            Self::BadAxis { index } => write!(f, "table axis {index} is malformed"),
            Self::BadBounds => f.write_str("table array out of bounds or misaligned"),
            Self::BadSize => f.write_str("table array size does not match its shape"),
            Self::BadCrc => f.write_str("table CRC mismatch"),
            Self::BufferFull => f.write_str("table header does not fit the buffer"),
        }
    }
}

impl core::error::Error for TableError {}

/// Rounds `n` up to a multiple of 4 (`None` on overflow).
#[inline]
#[must_use]
pub fn align4(n: usize) -> Option<usize> {
    Some(n.checked_add(3)? & !3)
}

/// The fixed 10-byte prefix for a header of `header_len` bytes.
#[must_use]
pub fn prefix(header_len: u32) -> [u8; PREFIX_LEN] {
    let [m0, m1, m2, m3] = MAGIC;
    let [v0, v1] = VERSION.to_le_bytes();
    let [h0, h1, h2, h3] = header_len.to_le_bytes();
    [m0, m1, m2, m3, v0, v1, h0, h1, h2, h3]
}

/// Encodes `header` with postcard into `out`; returns the number of bytes
/// written. The writer's half of the header format.
pub fn encode_header(header: &Header<'_>, out: &mut [u8]) -> Result<usize, TableError> {
    postcard::to_slice(header, out)
        .map(|used| used.len())
        .map_err(|_| TableError::BufferFull)
}

/// Counts derived from a header's axes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Shape {
    /// Product of all axis counts.
    grid_samples: usize,
    /// Product of the parameter axes' counts.
    param_samples: usize,
    /// Product of the parameter axes' cell counts.
    param_cells: usize,
}

/// The [`Shape`] of a header's axes; checks every used axis.
fn shape(header: &Header<'_>) -> Result<Shape, TableError> {
    let axes = header
        .axes
        .get(..usize::from(header.axis_count))
        .ok_or(TableError::BadHeader)?;
    let param_axes = match header.kind {
        Kind::Grid => axes.len(),
        Kind::Clips { phases: 1.. } => axes.len().checked_sub(1).ok_or(TableError::BadHeader)?,
        Kind::Clips { phases: 0 } => return Err(TableError::BadHeader),
    };
    if axes.is_empty() {
        return Err(TableError::BadHeader);
    }
    let mut shape = Shape {
        grid_samples: 1,
        param_samples: 1,
        param_cells: 1,
    };
    for (i, axis) in axes.iter().enumerate() {
        // `i < MAX_AXES = 6`, so it fits a u8.
        let cells = grid::Axis::try_from(axis)
            .map_err(|_| TableError::BadAxis { index: i as u8 })?
            .cells() as usize;
        let count = usize::from(axis.count);
        shape.grid_samples = shape
            .grid_samples
            .checked_mul(count)
            .ok_or(TableError::BadBounds)?;
        if i < param_axes {
            shape.param_samples = shape.grid_samples;
            shape.param_cells = shape
                .param_cells
                .checked_mul(cells)
                .ok_or(TableError::BadBounds)?;
        }
    }
    Ok(shape)
}

/// Checks the header's segment fields and scale.
fn check_segments(header: &Header<'_>) -> Result<(), TableError> {
    let count = usize::from(header.segment_count);
    let names_ok = count.checked_mul(NAME_LEN) == Some(header.segment_names.len());
    let scale_ok = header.position_scale.is_finite() && header.position_scale > 0.0;
    if (1..=MAX_SEGMENTS).contains(&count) && names_ok && scale_ok {
        Ok(())
    } else {
        Err(TableError::BadHeader)
    }
}

/// The bytes of `span`, which must be 4-aligned, lie in `data` (the blob from
/// the data start to the CRC, starting at blob offset `start`) and be exactly
/// `expected` long.
fn array(
    data: &[u8],
    start: usize,
    span: Span,
    expected: Option<usize>,
) -> Result<&[u8], TableError> {
    let offset = usize::try_from(span.offset).map_err(|_| TableError::BadBounds)?;
    let len = usize::try_from(span.len).map_err(|_| TableError::BadBounds)?;
    let from = offset.checked_sub(start).ok_or(TableError::BadBounds)?;
    let to = from.checked_add(len).ok_or(TableError::BadBounds)?;
    let bytes = data.get(from..to).ok_or(TableError::BadBounds)?;
    if offset % 4 != 0 {
        return Err(TableError::BadBounds);
    }
    if expected != Some(len) {
        return Err(TableError::BadSize);
    }
    Ok(bytes)
}

/// Reads the prefix and decodes the header; returns it with the data start
/// and the format version.
fn read_header(bytes: &[u8]) -> Result<(Header<'_>, usize, u16), TableError> {
    let Some((&[m0, m1, m2, m3, v0, v1, h0, h1, h2, h3], rest)) =
        bytes.split_first_chunk::<PREFIX_LEN>()
    else {
        return Err(TableError::Truncated);
    };
    if [m0, m1, m2, m3] != MAGIC {
        return Err(TableError::BadMagic);
    }
    let found = u16::from_le_bytes([v0, v1]);
    if found != 1 && found != VERSION {
        return Err(TableError::BadVersion { found });
    }
    let header_len =
        usize::try_from(u32::from_le_bytes([h0, h1, h2, h3])).map_err(|_| TableError::BadBounds)?;
    if header_len > MAX_HEADER_LEN {
        return Err(TableError::BadBounds);
    }
    let raw = rest.get(..header_len).ok_or(TableError::Truncated)?;
    let header = if found == 1 {
        match postcard::take_from_bytes::<header::HeaderV1<'_>>(raw) {
            Ok((header, [])) => Header::from(header),
            _ => return Err(TableError::BadHeader),
        }
    } else {
        match postcard::take_from_bytes::<Header<'_>>(raw) {
            Ok((header, [])) => header,
            _ => return Err(TableError::BadHeader),
        }
    };
    // header_len ≤ MAX_HEADER_LEN, so neither step can overflow; checked anyway.
    let start = PREFIX_LEN
        .checked_add(header_len)
        .and_then(align4)
        .ok_or(TableError::BadBounds)?;
    Ok((header, start, found))
}

/// Splits off the CRC-checked blob body `[start, total_len − 4)` after
/// verifying the CRC.
fn checked_data(bytes: &[u8], total_len: u32, start: usize) -> Result<&[u8], TableError> {
    let total = usize::try_from(total_len).map_err(|_| TableError::BadBounds)?;
    let blob = bytes.get(..total).ok_or(TableError::Truncated)?;
    let crc_at = total.checked_sub(CRC_LEN).ok_or(TableError::BadBounds)?;
    let (covered, stored) = blob.split_at_checked(crc_at).ok_or(TableError::BadBounds)?;
    let stored = stored
        .first_chunk::<CRC_LEN>()
        .ok_or(TableError::BadBounds)?;
    if crc32(covered) != u32::from_le_bytes(*stored) {
        return Err(TableError::BadCrc);
    }
    covered.get(start..).ok_or(TableError::BadBounds)
}

/// A parsed table blob, borrowing the blob's bytes (flash) for its whole life.
#[derive(Clone, Copy, Debug)]
pub struct Table<'a> {
    header: Header<'a>,
    samples: &'a [u8],
    valid: &'a [u8],
    durations: &'a [u8],
    travel: &'a [u8],
    shape: Shape,
}

impl<'a> Table<'a> {
    /// Validates a blob and returns a reader over it.
    ///
    /// Checks, in order: prefix length ([`TableError::Truncated`]), magic,
    /// version, header length (≤ [`MAX_HEADER_LEN`], within the slice), the
    /// postcard header (exactly `H` bytes), `total_len` within the slice, the
    /// CRC, then the shape (axes, segments, names, scale) and every array's
    /// bounds, alignment and size. Trailing bytes after `total_len` are
    /// ignored. Never panics; all offset arithmetic is checked.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, TableError> {
        let (header, start, version) = read_header(bytes)?;
        let data = checked_data(bytes, header.total_len, start)?;
        check_segments(&header)?;
        let shape = shape(&header)?;
        let sample_bytes = shape
            .grid_samples
            .checked_mul(usize::from(header.segment_count))
            .and_then(|n| n.checked_mul(SAMPLE_LEN));
        let duration_bytes = match header.kind {
            Kind::Grid => Some(0),
            Kind::Clips { phases } => shape
                .param_samples
                .checked_mul(usize::from(phases))
                .and_then(|n| n.checked_mul(4)),
        };
        let samples = array(data, start, header.samples, sample_bytes)?;
        let valid = array(
            data,
            start,
            header.valid,
            Some(shape.param_cells.div_ceil(8)),
        )?;
        let durations = array(data, start, header.durations, duration_bytes)?;
        let looping = matches!(header.kind, Kind::Clips { .. })
            && header
                .axes
                .get(usize::from(header.axis_count).wrapping_sub(1))
                .is_some_and(|a| matches!(a.wrap, Wrap::Cyclic { .. }));
        let travel = if version == 1 {
            &[][..]
        } else {
            let expected = if looping {
                shape.param_samples.checked_mul(12)
            } else {
                Some(0)
            };
            array(data, start, header.travel, expected)?
        };
        Ok(Self {
            header,
            samples,
            valid,
            durations,
            travel,
            shape,
        })
    }

    /// The decoded header (for `marionette inspect`).
    #[inline]
    #[must_use]
    pub fn header(&self) -> &Header<'a> {
        &self.header
    }

    /// The table's kind.
    #[inline]
    #[must_use]
    pub fn kind(&self) -> Kind {
        self.header.kind
    }

    /// Hash of the rig the table was built for.
    #[inline]
    #[must_use]
    pub fn rig_hash(&self) -> u64 {
        self.header.rig_hash
    }

    /// Bytes of the blob from the magic to the end of the CRC.
    #[inline]
    #[must_use]
    pub fn len(&self) -> usize {
        self.header.total_len as usize
    }

    /// Always `false`: a parsed blob holds at least its prefix and CRC.
    #[inline]
    #[must_use]
    pub fn is_empty(&self) -> bool {
        false
    }

    /// The used axes, axis 0 fastest in the sample order (for clip tables the
    /// last one is the phase axis).
    #[must_use]
    pub fn axes(&self) -> &[Axis] {
        self.header
            .axes
            .get(..usize::from(self.header.axis_count))
            .unwrap_or(&[])
    }

    /// Number of segments per pose.
    #[inline]
    #[must_use]
    pub fn segment_count(&self) -> usize {
        usize::from(self.header.segment_count)
    }

    /// Name of segment `segment` (`None` out of range or not UTF-8).
    #[must_use]
    pub fn segment_name(&self, segment: usize) -> Option<&'a str> {
        let from = segment.checked_mul(NAME_LEN)?;
        name_str(
            self.header
                .segment_names
                .get(from..from.checked_add(NAME_LEN)?)?,
        )
    }

    /// Index of the segment named `name`.
    #[must_use]
    pub fn segment_index(&self, name: &str) -> Option<usize> {
        (0..self.segment_count()).find(|&s| self.segment_name(s) == Some(name))
    }

    /// Number of grid samples (product of all axis counts).
    #[inline]
    #[must_use]
    pub fn grid_samples(&self) -> usize {
        self.shape.grid_samples
    }

    /// Number of parameter samples (product of the parameter axes' counts: all
    /// axes for a grid, all but the phase axis for clips).
    #[inline]
    #[must_use]
    pub fn param_samples(&self) -> usize {
        self.shape.param_samples
    }

    /// Number of parameter cells (product of the parameter axes' cell counts):
    /// the length in bits of the validity mask.
    #[inline]
    #[must_use]
    pub fn param_cells(&self) -> usize {
        self.shape.param_cells
    }

    /// The parameter axes: all axes for a grid, all but the last for clips.
    #[must_use]
    pub fn param_axes(&self) -> &[Axis] {
        let axes = self.axes();
        match self.header.kind {
            Kind::Grid => axes,
            Kind::Clips { .. } => axes.split_last().map_or(&[], |(_, params)| params),
        }
    }

    /// The synthesis grid over all axes (for clips the phase axis included).
    /// A grid table carries its validity mask; a clip table's mask covers the
    /// parameter cells only, see [`Table::param_grid`].
    pub fn grid(&self) -> Result<Grid<'a>, GridError> {
        let (axes, n) = grid_axes(self.axes())?;
        let mask = match self.header.kind {
            Kind::Grid => Some(self.valid),
            Kind::Clips { .. } => None,
        };
        Grid::new(axes.get(..n).unwrap_or(&[]), mask)
    }

    /// The grid over the parameter axes with the validity mask: the grid of a
    /// grid table, the parameter grid of a clip table (whose clips are
    /// parameter samples; [`GridError::AxisCount`] for a single clip).
    pub fn param_grid(&self) -> Result<Grid<'a>, GridError> {
        let (axes, n) = grid_axes(self.param_axes())?;
        Grid::new(axes.get(..n).unwrap_or(&[]), Some(self.valid))
    }

    /// Metres per position LSB.
    #[inline]
    #[must_use]
    pub fn position_scale(&self) -> f32 {
        self.header.position_scale
    }

    /// The 12 stored bytes of one segment sample.
    #[inline(always)]
    #[must_use]
    pub fn raw_sample(&self, index: usize, segment: usize) -> Option<&'a [u8; SAMPLE_LEN]> {
        let segments = self.segment_count();
        if index >= self.shape.grid_samples || segment >= segments {
            return None;
        }
        // In range, the offset is below `samples.len()` (checked by `parse`
        // to be `grid_samples · segments · 12`), so it cannot wrap.
        let from = index
            .wrapping_mul(segments)
            .wrapping_add(segment)
            .wrapping_mul(SAMPLE_LEN);
        self.samples.get(from..)?.first_chunk::<SAMPLE_LEN>()
    }

    /// Decodes the position and rotation of `segment` at grid sample `index`
    /// (row-major, axis 0 fastest). `None` if either is out of range.
    #[inline(always)]
    #[must_use]
    pub fn sample(&self, index: usize, segment: usize) -> Option<(Vec3, Quat)> {
        Some(quant::decode_sample(
            self.raw_sample(index, segment)?,
            self.header.position_scale,
        ))
    }

    /// Whether parameter cell `index` is backed by data (`None` out of range).
    #[must_use]
    pub fn cell_valid(&self, index: usize) -> Option<bool> {
        if index >= self.shape.param_cells {
            return None;
        }
        let byte = self.valid.get(index / 8)?;
        Some(byte >> (index % 8) & 1 == 1)
    }

    /// The raw validity bitmask (see the module docs).
    #[inline]
    #[must_use]
    pub fn valid_mask(&self) -> &'a [u8] {
        self.valid
    }

    /// Duration in seconds of `phase` of the clip at parameter sample `index`
    /// (`None` for a grid or out of range).
    #[must_use]
    pub fn duration(&self, index: usize, phase: usize) -> Option<f32> {
        let Kind::Clips { phases } = self.header.kind else {
            return None;
        };
        if phase >= usize::from(phases) {
            return None;
        }
        let slot = index.checked_mul(usize::from(phases))?.checked_add(phase)?;
        let bytes = self
            .durations
            .get(slot.checked_mul(4)?..)?
            .first_chunk::<4>()?;
        Some(f32::from_le_bytes(*bytes))
    }
}

impl Table<'_> {
    /// Root displacement over one cycle of the looping clip at parameter
    /// sample `index`, metres in the clip frame (`None` for other tables, a
    /// version 1 blob, or out of range).
    #[must_use]
    pub fn travel(&self, index: usize) -> Option<Vec3> {
        let at = index.checked_mul(12)?;
        let bytes = self.travel.get(at..)?.first_chunk::<12>()?;
        let [x0, x1, x2, x3, y0, y1, y2, y3, z0, z1, z2, z3] = *bytes;
        Some(Vec3::new(
            f32::from_le_bytes([x0, x1, x2, x3]),
            f32::from_le_bytes([y0, y1, y2, y3]),
            f32::from_le_bytes([z0, z1, z2, z3]),
        ))
    }
}

/// The grid axes of `axes`, and how many there are.
fn grid_axes(axes: &[Axis]) -> Result<([grid::Axis; MAX_AXES], usize), GridError> {
    let mut out = [grid::Axis::linear(0.0, 1.0, 2); MAX_AXES];
    let mut n = 0;
    for (i, (slot, axis)) in out.iter_mut().zip(axes).enumerate() {
        *slot = grid::Axis::try_from(axis).map_err(|_| GridError::BadAxis { axis: i as u8 })?;
        n += 1;
    }
    Ok((out, n))
}

impl Samples for Table<'_> {
    const DECODES: bool = true;

    #[inline]
    fn segment_count(&self) -> usize {
        usize::from(self.header.segment_count)
    }

    #[inline]
    fn sample_count(&self) -> usize {
        self.shape.grid_samples
    }

    #[inline(always)]
    fn sample(&self, index: usize, segment: usize) -> Option<(Vec3, Quat)> {
        Table::sample(self, index, segment)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Builds a clip table in `buf` by hand (no host writer): one parameter
    /// axis of 2 samples, a 2-frame phase axis `[0, 1]`, one segment; returns
    /// the blob length.
    fn clip_blob(buf: &mut [u8; 512]) -> usize {
        let name = |s: &[u8]| {
            let mut n = [0; NAME_LEN];
            n.iter_mut().zip(s).for_each(|(d, s)| *d = *s);
            n
        };
        let axis = |n: &[u8], count| Axis {
            name: name(n),
            min: 0.0,
            step: 1.0,
            count,
            wrap: Wrap::Bounded,
            interp: Interp::Linear,
        };
        let names = name(b"hips");
        let mut axes = [Axis::UNUSED; MAX_AXES];
        axes[0] = axis(b"speed", 2);
        axes[1] = axis(b"phase", 2);
        let mut h = Header {
            total_len: 0,
            rig_hash: 99,
            kind: Kind::Clips { phases: 1 },
            axis_count: 2,
            axes,
            segment_count: 1,
            segment_names: &names,
            position_scale: 0.001,
            position_bound: 0.00051,
            rotation_bound: quant::ROTATION_BOUND,
            samples: Span::default(),
            valid: Span::default(),
            durations: Span::default(),
            travel: Span::default(),
        };
        let mut header = [0; 400];
        let mut len = 0;
        for _ in 0..4 {
            len = encode_header(&h, &mut header).unwrap();
            let start = align4(PREFIX_LEN + len).unwrap() as u32;
            h.samples = Span {
                offset: start,
                len: 48,
            };
            h.valid = Span {
                offset: start + 48,
                len: 1,
            };
            h.durations = Span {
                offset: start + 52,
                len: 8,
            };
            h.travel = Span {
                offset: start + 60,
                len: 0,
            };
            h.total_len = start + 64;
        }
        assert_eq!(encode_header(&h, &mut header).unwrap(), len);
        buf[..PREFIX_LEN].copy_from_slice(&prefix(len as u32));
        buf[PREFIX_LEN..PREFIX_LEN + len].copy_from_slice(&header[..len]);
        let at = h.samples.offset as usize;
        for i in 0..4 {
            let p = Vec3::new(0.001 * i as f32, 0.0, 0.0);
            buf[at + 12 * i..at + 12 * i + 12].copy_from_slice(&quant::encode_sample(
                p,
                Quat::IDENTITY,
                0.001,
            ));
        }
        buf[at + 48] = 0b1;
        buf[at + 52..at + 56].copy_from_slice(&1.5_f32.to_le_bytes());
        buf[at + 56..at + 60].copy_from_slice(&0.75_f32.to_le_bytes());
        let total = h.total_len as usize;
        let crc = crc32(&buf[..total - CRC_LEN]);
        buf[total - CRC_LEN..total].copy_from_slice(&crc.to_le_bytes());
        total
    }

    #[test]
    fn prefix_and_alignment() {
        assert_eq!(
            prefix(0x0102_0304),
            [b'M', b'R', b'N', b'T', 2, 0, 4, 3, 2, 1]
        );
        assert_eq!(
            (align4(0), align4(1), align4(4), align4(7)),
            (Some(0), Some(4), Some(4), Some(8))
        );
        assert_eq!(align4(usize::MAX), None);
    }

    #[test]
    fn hand_built_clip_table() {
        let mut buf = [0xFF; 512];
        let len = clip_blob(&mut buf);
        let t = Table::parse(&buf).unwrap();
        assert_eq!(
            (t.len(), t.rig_hash(), t.kind()),
            (len, 99, Kind::Clips { phases: 1 })
        );
        assert_eq!(
            (t.grid_samples(), t.param_samples(), t.param_cells()),
            (4, 2, 1)
        );
        assert_eq!(t.segment_name(0), Some("hips"));
        assert_eq!(t.axes()[1].name(), Some("phase"));
        assert_eq!(t.param_axes().len(), 1);
        assert_eq!((t.cell_valid(0), t.cell_valid(1)), (Some(true), None));
        assert_eq!(
            (t.duration(0, 0), t.duration(1, 0), t.duration(2, 0)),
            (Some(1.5), Some(0.75), None)
        );
        assert_eq!(
            t.sample(3, 0),
            Some((Vec3::new(0.003, 0.0, 0.0), Quat::IDENTITY))
        );
        assert_eq!((t.sample(4, 0), t.sample(0, 1)), (None, None));
        // Exactly the blob, no trailing bytes, still parses; one byte less does not.
        assert!(Table::parse(&buf[..len]).is_ok());
        assert_eq!(
            Table::parse(&buf[..len - 1]).unwrap_err(),
            TableError::Truncated
        );
        // A flipped sample bit is caught by the CRC.
        buf[len - 20] ^= 0x10;
        assert_eq!(Table::parse(&buf).unwrap_err(), TableError::BadCrc);
    }
}
