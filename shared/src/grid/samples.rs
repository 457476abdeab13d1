//! Where the grid reads its samples from: the [`Samples`] trait (a flash
//! table decodes on demand, see [`crate::table::Table`]) and in-memory
//! [`SliceSamples`].

use glam::{Quat, Vec3};

/// A read-only source of grid samples (see the module doc for the layout).
pub trait Samples {
    /// Segments per sample.
    fn segment_count(&self) -> usize;
    /// Number of samples available.
    fn sample_count(&self) -> usize;
    /// Position and rotation of `segment` in sample `index`.
    fn sample(&self, index: usize, segment: usize) -> Option<(Vec3, Quat)>;
    /// Every segment of sample `index`, positions and rotations, where the
    /// source holds them as slices in memory; `None` for sources that decode
    /// (the default) or out of range. A speed path: the grid then reads a
    /// run of segments without a call per sample; the values are those of
    /// [`Samples::sample`].
    fn row(&self, index: usize) -> Option<(&[Vec3], &[Quat])> {
        let _ = index;
        None
    }
    /// A speed hint: whether [`Samples::sample`] decodes (costs much more
    /// than a few loads). The grid then reads a segment's whole window
    /// before interpolating rather than each pair as it blends it; the
    /// operations, and so the results, are the same either way.
    const DECODES: bool = false;
}

/// In-memory samples: `[sample][segment]` slices (host, tests).
#[derive(Clone, Copy, Debug)]
pub struct SliceSamples<'a> {
    segments: usize,
    positions: &'a [Vec3],
    rotations: &'a [Quat],
}

impl<'a> SliceSamples<'a> {
    /// Wraps the slices; `None` if their lengths differ or are not a multiple
    /// of `segments` (or `segments` is 0).
    #[must_use]
    pub fn new(segments: usize, positions: &'a [Vec3], rotations: &'a [Quat]) -> Option<Self> {
        let ok = segments > 0
            && positions.len() == rotations.len()
            && positions.len().checked_rem(segments) == Some(0);
        ok.then_some(Self {
            segments,
            positions,
            rotations,
        })
    }
}

impl Samples for SliceSamples<'_> {
    #[inline]
    fn segment_count(&self) -> usize {
        self.segments
    }

    #[inline]
    fn sample_count(&self) -> usize {
        self.positions.len().checked_div(self.segments).unwrap_or(0)
    }

    #[inline]
    fn sample(&self, index: usize, segment: usize) -> Option<(Vec3, Quat)> {
        if segment >= self.segments {
            return None;
        }
        // A wrapped product can only land on some other sample, never out of
        // bounds (the slices are checked), so plain wrapping arithmetic is safe.
        let i = index.wrapping_mul(self.segments).wrapping_add(segment);
        match (self.positions.get(i), self.rotations.get(i)) {
            (Some(&p), Some(&q)) => Some((p, q)),
            _ => None,
        }
    }

    #[inline]
    fn row(&self, index: usize) -> Option<(&[Vec3], &[Quat])> {
        let from = index.checked_mul(self.segments)?;
        let range = from..from.checked_add(self.segments)?;
        Some((
            self.positions.get(range.clone())?,
            self.rotations.get(range)?,
        ))
    }
}
