//! The table blob writer: the one writer of the format that
//! [`marionette_core::table`] documents and reads.
//!
//! [`write()`] takes an in-memory [`TableSpec`] (axes, segment names, `f32`
//! samples as `[sample][segment]` position + rotation, the cell-validity
//! mask, the rig hash and, for clip tables, the durations), checks it,
//! quantizes every sample with the core's [`quant`] functions (the ones the
//! firmware decodes with), lays out the arrays, appends the CRC, and finally
//! parses the result with the core reader before returning it, so a blob that
//! leaves this module is one the firmware accepts.

use glam::{Quat, Vec3};
use marionette_core::crc::crc32;
use marionette_core::table::{
    self, Axis, CRC_LEN, Header, Interp, Kind, MAX_AXES, MAX_HEADER_LEN, MAX_SEGMENTS, NAME_LEN,
    PREFIX_LEN, SAMPLE_LEN, Span, Table, TableError, Wrap, align4, quant,
};

/// One axis of a table to write.
#[derive(Clone, Debug, PartialEq)]
pub struct AxisSpec {
    /// Name (at most 24 bytes of UTF-8, no NUL).
    pub name: String,
    /// Coordinate of the first sample.
    pub min: f32,
    /// Spacing of the samples (> 0).
    pub step: f32,
    /// Number of samples (≥ 2).
    pub count: u16,
    /// Bounded or cyclic (`period = count · step`).
    pub wrap: Wrap,
    /// Linear or Catmull-Rom.
    pub interp: Interp,
}

/// An in-memory table to write.
#[derive(Clone, Debug, PartialEq)]
pub struct TableSpec {
    /// Hash of the rig the table is built for.
    pub rig_hash: u64,
    /// Static grid or clip set. For clips the last axis is the phase axis:
    /// `min = 0`, spanning `[0, phases]` (bounded: `(count − 1) · step`,
    /// cyclic: `period`).
    pub kind: Kind,
    /// The axes, axis 0 fastest in the sample order (1 ..= 6).
    pub axes: Vec<AxisSpec>,
    /// One name per segment (at most 24 bytes of UTF-8 each, no NUL).
    pub segment_names: Vec<String>,
    /// `[grid sample][segment]` position (metres) and rotation (unit
    /// quaternion); grid samples row-major, axis 0 fastest.
    pub samples: Vec<Vec<(Vec3, Quat)>>,
    /// One flag per parameter cell (row-major over the parameter axes' cell
    /// counts, axis 0 fastest): `true` = backed by data.
    pub valid: Vec<bool>,
    /// Clips only: seconds per phase per parameter sample, phase fastest.
    /// Empty for a grid.
    pub durations: Vec<f32>,
    /// Looping clips only: each parameter sample's root displacement over
    /// one cycle (x, y, z metres in the clip frame). Empty otherwise.
    pub travel: Vec<[f32; 3]>,
}

/// Why a table could not be written.
#[derive(Debug, thiserror::Error)]
pub enum BlobError {
    /// No axis, or more than six.
    #[error("a table needs 1 to {MAX_AXES} axes, got {0}")]
    AxisCount(usize),
    /// An axis violates the grid's rules.
    #[error("axis {index} ({name:?}): {reason}")]
    Axis {
        /// Index of the axis.
        index: usize,
        /// Its name.
        name: String,
        /// What is wrong.
        reason: &'static str,
    },
    /// A name is longer than 24 bytes or holds a NUL byte.
    #[error("name {0:?} is longer than {NAME_LEN} bytes or contains NUL")]
    Name(String),
    /// No segment, or more than 256.
    #[error("a table needs 1 to {MAX_SEGMENTS} segments, got {0}")]
    SegmentCount(usize),
    /// The number of grid samples differs from the product of the axis counts.
    #[error("expected {expected} grid samples, got {found}")]
    SampleCount {
        /// Product of the axis counts.
        expected: usize,
        /// Samples given.
        found: usize,
    },
    /// A grid sample has the wrong number of segments.
    #[error("grid sample {sample} has {found} segments, expected {expected}")]
    SampleSegments {
        /// The grid sample.
        sample: usize,
        /// Segments expected.
        expected: usize,
        /// Segments found.
        found: usize,
    },
    /// A position or rotation is not finite, or a rotation is zero.
    #[error("grid sample {sample}, segment {segment}: non-finite position or degenerate rotation")]
    BadSample {
        /// The grid sample.
        sample: usize,
        /// The segment.
        segment: usize,
    },
    /// A coordinate exceeds the quantizable range.
    #[error(
        "largest coordinate {max_abs} m exceeds the table range of {} m",
        quant::MAX_POSITION
    )]
    PositionRange {
        /// The largest absolute coordinate.
        max_abs: f32,
    },
    /// The validity mask has the wrong length.
    #[error("expected {expected} validity flags (one per parameter cell), got {found}")]
    ValidCount {
        /// Number of parameter cells.
        expected: usize,
        /// Flags given.
        found: usize,
    },
    /// The travel has the wrong length (one per parameter sample of a
    /// looping clip table, none otherwise), or a value is not finite.
    #[error("travel: expected {expected} finite x, y, z triples, got {found}")]
    Travel {
        /// Triples expected.
        expected: usize,
        /// Triples given.
        found: usize,
    },
    /// The durations have the wrong length, or one is not finite and positive.
    #[error("durations: expected {expected} finite positive values, got {found} values")]
    Durations {
        /// Durations expected.
        expected: usize,
        /// Durations given.
        found: usize,
    },
    /// The blob would exceed the format's 32-bit lengths.
    #[error("the table is too large for the blob format")]
    TooLarge,
    /// The core rejected the header or the finished blob (a writer bug).
    #[error("table format: {0}")]
    Format(#[from] TableError),
}

/// Builds the blob of `spec`.
pub fn write(spec: &TableSpec) -> Result<Vec<u8>, BlobError> {
    let axes = header_axes(spec)?;
    let segment_names = names(&spec.segment_names)?;
    let shape = check_shape(spec)?;
    let scale = position_scale(&spec.samples)?;
    let samples = encode_samples(&spec.samples, scale);
    let valid = mask(&spec.valid, shape.param_cells)?;
    let durations = durations(spec, shape.param_samples)?;
    let travel = travel(spec, shape.param_samples)?;
    let mut header = Header {
        total_len: 0,
        rig_hash: spec.rig_hash,
        kind: spec.kind,
        axis_count: u8::try_from(spec.axes.len())
            .map_err(|_| BlobError::AxisCount(spec.axes.len()))?,
        axes,
        segment_count: u16::try_from(spec.segment_names.len())
            .map_err(|_| BlobError::SegmentCount(spec.segment_names.len()))?,
        segment_names: &segment_names,
        position_scale: scale,
        position_bound: quant::position_bound(scale),
        rotation_bound: quant::ROTATION_BOUND,
        samples: Span::default(),
        valid: Span::default(),
        durations: Span::default(),
        travel: Span::default(),
    };
    let arrays = [
        samples.as_slice(),
        valid.as_slice(),
        durations.as_slice(),
        travel.as_slice(),
    ];
    let encoded = lay_out(&mut header, arrays)?;
    let blob = assemble(&header, &encoded, arrays)?;
    Table::parse(&blob)?;
    Ok(blob)
}

/// Counts of the spec's shape.
struct Shape {
    param_samples: usize,
    param_cells: usize,
}

/// The header's fixed axis array, checked by the core's own rule.
fn header_axes(spec: &TableSpec) -> Result<[Axis; MAX_AXES], BlobError> {
    let n = spec.axes.len();
    if n == 0 || n > MAX_AXES {
        return Err(BlobError::AxisCount(n));
    }
    let mut out = [Axis::UNUSED; MAX_AXES];
    for (index, (slot, a)) in out.iter_mut().zip(&spec.axes).enumerate() {
        let axis = Axis {
            name: name(&a.name)?,
            min: a.min,
            step: a.step,
            count: a.count,
            wrap: a.wrap,
            interp: a.interp,
        };
        if marionette_core::grid::Axis::try_from(&axis).is_err() {
            let reason = "needs count ≥ 2, finite min, finite step > 0 and period = count · step";
            return Err(BlobError::Axis {
                index,
                name: a.name.clone(),
                reason,
            });
        }
        *slot = axis;
    }
    if let (Kind::Clips { phases }, Some(phase)) = (spec.kind, spec.axes.last()) {
        check_phase_axis(phase, phases, n - 1)?;
    }
    Ok(out)
}

/// A clip table's last axis must be the phase axis `[0, phases]`.
fn check_phase_axis(a: &AxisSpec, phases: u8, index: usize) -> Result<(), BlobError> {
    let span = match a.wrap {
        Wrap::Bounded => f32::from(a.count - 1) * a.step,
        Wrap::Cyclic { period } => period,
    };
    let target = f32::from(phases);
    let fail = |reason| {
        Err(BlobError::Axis {
            index,
            name: a.name.clone(),
            reason,
        })
    };
    if phases == 0 {
        return fail("a clip table needs at least one phase");
    }
    if a.min != 0.0 || (span - target).abs() > 1e-5 * target {
        return fail("the phase axis must start at 0 and span [0, phases]");
    }
    Ok(())
}

/// A fixed-size, zero-padded name.
fn name(s: &str) -> Result<[u8; NAME_LEN], BlobError> {
    let bytes = s.as_bytes();
    if bytes.len() > NAME_LEN || bytes.contains(&0) {
        return Err(BlobError::Name(s.to_owned()));
    }
    let mut out = [0; NAME_LEN];
    out[..bytes.len()].copy_from_slice(bytes);
    Ok(out)
}

/// The concatenated fixed-size segment names.
fn names(segments: &[String]) -> Result<Vec<u8>, BlobError> {
    if segments.is_empty() || segments.len() > MAX_SEGMENTS {
        return Err(BlobError::SegmentCount(segments.len()));
    }
    let mut out = Vec::with_capacity(segments.len() * NAME_LEN);
    for s in segments {
        out.extend_from_slice(&name(s)?);
    }
    Ok(out)
}

/// Checks the sample array against the axes and returns the shape.
fn check_shape(spec: &TableSpec) -> Result<Shape, BlobError> {
    let counts = spec.axes.iter().map(|a| usize::from(a.count));
    let expected = counts
        .clone()
        .try_fold(1_usize, usize::checked_mul)
        .ok_or(BlobError::TooLarge)?;
    if spec.samples.len() != expected {
        return Err(BlobError::SampleCount {
            expected,
            found: spec.samples.len(),
        });
    }
    let segments = spec.segment_names.len();
    for (sample, poses) in spec.samples.iter().enumerate() {
        if poses.len() != segments {
            return Err(BlobError::SampleSegments {
                sample,
                expected: segments,
                found: poses.len(),
            });
        }
        for (segment, (p, q)) in poses.iter().enumerate() {
            let q_ok = q.is_finite() && q.length_squared() > 1e-12;
            if !p.is_finite() || !q_ok {
                return Err(BlobError::BadSample { sample, segment });
            }
        }
    }
    let params = match spec.kind {
        Kind::Grid => &spec.axes[..],
        Kind::Clips { .. } => &spec.axes[..spec.axes.len() - 1],
    };
    let param_samples = params.iter().map(|a| usize::from(a.count)).product();
    let param_cells = params
        .iter()
        .map(|a| match a.wrap {
            Wrap::Bounded => usize::from(a.count) - 1,
            Wrap::Cyclic { .. } => usize::from(a.count),
        })
        .product();
    Ok(Shape {
        param_samples,
        param_cells,
    })
}

/// The per-table position scale, from the largest absolute coordinate.
fn position_scale(samples: &[Vec<(Vec3, Quat)>]) -> Result<f32, BlobError> {
    let max_abs = samples
        .iter()
        .flatten()
        .map(|(p, _)| p.abs().max_element())
        .fold(0.0_f32, f32::max);
    quant::position_scale(max_abs).ok_or(BlobError::PositionRange { max_abs })
}

/// The quantized sample array.
fn encode_samples(samples: &[Vec<(Vec3, Quat)>], scale: f32) -> Vec<u8> {
    let mut out =
        Vec::with_capacity(samples.len() * samples.first().map_or(0, Vec::len) * SAMPLE_LEN);
    for (p, q) in samples.iter().flatten() {
        out.extend_from_slice(&quant::encode_sample(*p, *q, scale));
    }
    out
}

/// The validity bitmask, LSB first.
fn mask(valid: &[bool], cells: usize) -> Result<Vec<u8>, BlobError> {
    if valid.len() != cells {
        return Err(BlobError::ValidCount {
            expected: cells,
            found: valid.len(),
        });
    }
    let mut out = vec![0_u8; cells.div_ceil(8)];
    for (i, _) in valid.iter().enumerate().filter(|(_, v)| **v) {
        out[i / 8] |= 1 << (i % 8);
    }
    Ok(out)
}

/// The durations array (clips), checked.
fn durations(spec: &TableSpec, param_samples: usize) -> Result<Vec<u8>, BlobError> {
    let expected = match spec.kind {
        Kind::Grid => 0,
        Kind::Clips { phases } => param_samples * usize::from(phases),
    };
    let ok = spec.durations.iter().all(|d| d.is_finite() && *d > 0.0);
    if spec.durations.len() != expected || !ok {
        return Err(BlobError::Durations {
            expected,
            found: spec.durations.len(),
        });
    }
    Ok(spec
        .durations
        .iter()
        .flat_map(|d| d.to_le_bytes())
        .collect())
}

/// The travel array (looping clips), checked.
fn travel(spec: &TableSpec, param_samples: usize) -> Result<Vec<u8>, BlobError> {
    let looping = matches!(spec.kind, Kind::Clips { .. })
        && spec
            .axes
            .last()
            .is_some_and(|a| matches!(a.wrap, Wrap::Cyclic { .. }));
    let expected = if looping { param_samples } else { 0 };
    let ok = spec.travel.iter().flatten().all(|v| v.is_finite());
    if spec.travel.len() != expected || !ok {
        return Err(BlobError::Travel {
            expected,
            found: spec.travel.len(),
        });
    }
    Ok(spec
        .travel
        .iter()
        .flatten()
        .flat_map(|v| v.to_le_bytes())
        .collect())
}

/// Fills in the header's spans and total length (which change the header's
/// own varint-coded length, so iterate to the fixed point) and returns the
/// encoded header.
fn lay_out(header: &mut Header<'_>, arrays: [&[u8]; 4]) -> Result<Vec<u8>, BlobError> {
    let mut buf = vec![0_u8; MAX_HEADER_LEN];
    let mut len = table::encode_header(header, &mut buf)?;
    for _ in 0..8 {
        let mut at = align4(PREFIX_LEN + len).ok_or(BlobError::TooLarge)?;
        let mut spans = [Span::default(); 4];
        for (span, array) in spans.iter_mut().zip(arrays) {
            *span = Span {
                offset: to_u32(at)?,
                len: to_u32(array.len())?,
            };
            at = align4(at + array.len()).ok_or(BlobError::TooLarge)?;
        }
        [
            header.samples,
            header.valid,
            header.durations,
            header.travel,
        ] = spans;
        header.total_len = to_u32(at + CRC_LEN)?;
        let new_len = table::encode_header(header, &mut buf)?;
        if new_len == len {
            buf.truncate(len);
            return Ok(buf);
        }
        len = new_len;
    }
    Err(BlobError::TooLarge)
}

/// Prefix, header, padding, arrays at their offsets, CRC.
fn assemble(header: &Header<'_>, encoded: &[u8], arrays: [&[u8]; 4]) -> Result<Vec<u8>, BlobError> {
    let total = header.total_len as usize;
    let mut blob = Vec::with_capacity(total);
    blob.extend_from_slice(&table::prefix(to_u32(encoded.len())?));
    blob.extend_from_slice(encoded);
    for (span, array) in [
        header.samples,
        header.valid,
        header.durations,
        header.travel,
    ]
    .into_iter()
    .zip(arrays)
    {
        blob.resize(span.offset as usize, 0);
        blob.extend_from_slice(array);
    }
    blob.resize(total - CRC_LEN, 0);
    let crc = crc32(&blob);
    blob.extend_from_slice(&crc.to_le_bytes());
    Ok(blob)
}

/// A length as the format's `u32`.
fn to_u32(n: usize) -> Result<u32, BlobError> {
    u32::try_from(n).map_err(|_| BlobError::TooLarge)
}
