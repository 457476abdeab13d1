//! Static interpolation synthesis on a regular grid (Wiley & Hahn 1997).
//!
//! # Grid
//!
//! A grid has 1 to [`MAX_AXES`] parameter axes (for example hand position
//! x, y, z, or the cylindrical coordinates of a pedalling foot). Axis `a` has
//! `count` samples at `min + i·step`, `i = 0..count`. A [`AxisKind::Bounded`]
//! axis has `count − 1` cells and ends at `min + (count − 1)·step`; a
//! [`AxisKind::Cyclic`] axis wraps with `period = count·step` (sample `count`
//! is sample 0 again) and has `count` cells.
//!
//! # Samples and their layout
//!
//! Every grid point holds a [`Pose`]-like sample (a position and a rotation per
//! segment), read through the [`Samples`] trait so that tables can be decoded
//! in place from a flash blob. Sample indices are **row-major with axis 0
//! fastest**: the sample at grid coordinates `(i0, i1, …)` has index
//! `i0 + count0·(i1 + count1·(i2 + …))`. [`SliceSamples`] stores them as
//! `[sample][segment]` slices: element `sample·segments + segment`.
//!
//! Cells are numbered the same way over the per-axis cell counts; the
//! optional validity mask holds one bit per cell (bit `c % 8` of byte `c / 8`,
//! 1 = valid).
//!
//! # Query: coefficients once, then every segment
//!
//! [`Grid::query`] finds the cell by one multiplication by the precomputed
//! `1/step` per axis (no search) and records, per axis, the window samples,
//! their position weights and the in-cell coordinate: a small [`Query`],
//! cheap to return by value. [`Query::pose`] then computes, once per call,
//! everything that does not depend on the segment (the sample indices of the
//! window, the tensor-product position weights and the per-axis slerp
//! coefficients with the fast-slerp polynomial folded, see [`SlerpWeight`])
//! and applies it to every segment; [`Query::segment`] does one segment.
//!
//! # The interpolation tree
//!
//! With `p` linear axes the window has `2^p` samples and the result is the
//! W&H binary tree of `2^p − 1` interpolations: all pairs along axis 0 first
//! (coefficient `u = (t − l)/(h − l)`), then the results along axis 1, and so
//! on. Rotations use the core's fast slerp ([`math::slerp`], within 6.7e-6 rad
//! of exact slerp) along the shortest arc. Positions are linear in the
//! samples, so the same tree is evaluated as one weighted sum with the
//! products of the per-axis weights (identical in exact arithmetic, fewer
//! operations); at grid points the weights are exactly 0 and 1, so samples
//! come back bit for bit.
//!
//! The W&H hand grid, three linear axes, has its own unrolled tree: its
//! slerps skip the normalization step of the fast slerp
//! ([`SlerpWeight::blend_lanes`]; a blend is unit to within 4e-6 already)
//! and only the root is normalized, by the same Newton step
//! ([`math::renormalize_lanes`]). That saves a fifth of the tree's
//! operations; against the exact `f64` tree the rotation error stays within
//! 1.1e-5 rad (`tests/synth.rs` measures it, inside cells and on their faces;
//! 5.6e-6 rad with every slerp normalized). Other grids normalize every
//! slerp.
//!
//! A [`Interp::CatmullRom`] axis uses the 4 samples `k−1, k, k+1, k+2` around
//! cell `k` (so the window is 4 wide along that axis) and interpolates
//! between the middle two:
//! - positions: uniform Catmull-Rom weights
//!   `w(−1) = (−s³ + 2s² − s)/2`, `w(0) = (3s³ − 5s² + 2)/2`,
//!   `w(1) = (−3s³ + 4s² + s)/2`, `w(2) = (s³ − s²)/2`. The tangent at a
//!   sample is the central difference, which is exact for quadratics, so
//!   uniform Catmull-Rom reproduces polynomials of degree ≤ 2 exactly in
//!   interior cells (not cubics: the central difference of `x³` is `3x² + 1`);
//! - rotations: the Barry–Goldman pyramid (the Neville-like form of
//!   Catmull-Rom) with every `lerp` replaced by a slerp: level 1
//!   `A1 = slerp(P−1, P0, s+1)`, `A2 = slerp(P0, P1, s)`,
//!   `A3 = slerp(P1, P2, s−1)`; level 2 `B1 = slerp(A1, A2, (s+1)/2)`,
//!   `B2 = slerp(A2, A3, s/2)`; result `slerp(B1, B2, s)`. The extrapolating
//!   slerps are computed exactly as `slerp(P0, reflect(P−1, P0), s)` and
//!   `slerp(P1, reflect(P2, P1), 1−s)` (see [`math::reflect`]), so every fast
//!   slerp runs with its parameter in `[0, 1]`. This is a proper spherical
//!   curve (it stays on the unit sphere, is `C¹`, interpolates the samples and
//!   is sign-independent); on a great circle it reduces to Catmull-Rom of the
//!   angle, so uniform rotation about a fixed axis is reproduced exactly. It
//!   was chosen over squad because it needs no quaternion log/exp per segment
//!   (6 slerps and 2 reflections), and over Shoemake's Bézier construction
//!   because it needs fewer slerps.
//!
//! At the ends of a bounded Catmull-Rom axis (and next to an invalid cell) the
//! missing outer sample is replaced by a linear phantom, `P−1 = 2P0 − P1`
//! (`reflect(P1, P0)` for rotations); then `A1 = A2` exactly, so the end
//! cells reproduce linear data (and uniform rotations) but not quadratics.
//! On cyclic axes the window wraps. Linear and Catmull-Rom axes can be mixed;
//! each axis is reduced in order, axis 0 first.
//!
//! # Parameters out of range, invalid cells, NaN
//!
//! - NaN or infinite parameters are rejected with [`GridError::NonFinite`].
//! - Bounded axes clamp to `[min, max]` ([`Adjust::Clamped`]). Cyclic axes
//!   wrap (never clamped).
//! - Parameters within `4ε·(1 + |u| + |min|/step)` cells of a grid point
//!   (`u` in cell units, `ε = 2^-23`) snap to it, so grid points computed in
//!   `f32` as `min + i·step` return their sample exactly. The tolerance is a
//!   few times the rounding error of the parameter itself, so snapping never
//!   moves a query by more than its own `f32` precision (a few ulp).
//! - A point on the boundary of a valid cell is accepted as is.
//! - If the cell found is marked invalid, the query is projected to the
//!   nearest point of the nearest valid cell, distance measured in cell units
//!   (each axis divided by its step; wrapped on cyclic axes), ties to the
//!   lowest cell index ([`Adjust::Projected`]). This is a scan over all cells
//!   (`O(cells · axes)`), paid only while a query is outside the valid region.
//!   No valid cell at all gives [`GridError::NoValidCell`].
//! - [`Query::adjust`] reports what happened; [`Query::params`] gives the
//!   parameters actually used.

use glam::{Quat, Vec3};

use crate::math::{self, F4, Lane, LaneWeight, SlerpWeight};
use crate::pose::Pose;

/// Most axes a grid may have.
pub const MAX_AXES: usize = 6;
/// Most samples in one interpolation window (a linear axis contributes a
/// factor 2, a Catmull-Rom axis 4): up to six linear axes, one Catmull-Rom
/// axis with four linear ones, two with two, or three Catmull-Rom axes. (Kept
/// small: the query and the rotation scratch are sized by it.)
pub const MAX_WINDOW: usize = 64;

/// How an axis continues past its ends.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AxisKind {
    /// `count` samples from `min` to `min + (count − 1)·step`; outside, clamp.
    Bounded,
    /// Periodic with `period = count·step` (checked to 1e-5 relative).
    Cyclic {
        /// The period in parameter units.
        period: f32,
    },
}

/// Interpolation along an axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interp {
    /// Lerp / slerp between the two samples around the parameter.
    Linear,
    /// Catmull-Rom over four samples (see the module doc).
    CatmullRom,
}

/// One grid axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Axis {
    /// Parameter value of sample 0.
    pub min: f32,
    /// Spacing between samples (> 0).
    pub step: f32,
    /// Number of samples (≥ 2).
    pub count: u32,
    /// Bounded or cyclic.
    pub kind: AxisKind,
    /// Linear or Catmull-Rom.
    pub interp: Interp,
}

impl Axis {
    /// A bounded linear axis.
    #[must_use]
    pub const fn linear(min: f32, step: f32, count: u32) -> Self {
        Self {
            min,
            step,
            count,
            kind: AxisKind::Bounded,
            interp: Interp::Linear,
        }
    }

    /// Number of cells (`count − 1` bounded, `count` cyclic).
    #[must_use]
    pub fn cells(&self) -> u32 {
        match self.kind {
            AxisKind::Bounded => self.count.saturating_sub(1),
            AxisKind::Cyclic { .. } => self.count,
        }
    }

    fn window(&self) -> usize {
        match self.interp {
            Interp::Linear => 2,
            Interp::CatmullRom => 4,
        }
    }
}

/// Why a grid or a query was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GridError {
    /// No axis, or more than [`MAX_AXES`].
    AxisCount,
    /// An axis has fewer than 2 samples, a non-finite `min`, a non-positive or
    /// non-finite `step`, or a period that is not `count·step`.
    BadAxis {
        /// The offending axis.
        axis: u8,
    },
    /// The interpolation window would exceed [`MAX_WINDOW`] samples.
    WindowTooLarge,
    /// The number of samples or cells does not fit in `u32`.
    TooManySamples,
    /// The validity mask is shorter than one bit per cell.
    MaskLength,
    /// The number of parameters differs from the number of axes.
    ParamCount,
    /// A parameter is NaN or infinite.
    NonFinite {
        /// The offending axis.
        axis: u8,
    },
    /// Every cell is marked invalid.
    NoValidCell,
    /// The sample source lacks a sample the grid needs.
    MissingSample,
    /// The sample source has more segments than the output pose holds.
    Capacity,
}

/// What a query did to its parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Adjust {
    /// Used as given (cyclic wrapping and grid-point snapping included).
    None,
    /// At least one bounded axis was clamped to its range.
    Clamped,
    /// The cell was invalid; moved to the nearest valid cell.
    Projected,
}

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

/// A regular grid in parameter space with an optional cell-validity mask.
#[derive(Clone, Copy, Debug)]
pub struct Grid<'a> {
    axes: [Axis; MAX_AXES],
    axis_count: usize,
    inv_step: [f32; MAX_AXES],
    sample_stride: [u32; MAX_AXES],
    cell_stride: [u32; MAX_AXES],
    samples: u32,
    cells: u32,
    window: usize,
    valid: Option<&'a [u8]>,
}

/// Per-axis coefficients of a query.
#[derive(Clone, Copy, Debug, PartialEq)]
enum AxisWeights {
    /// Slerp weight `t` between the two window samples.
    Linear(SlerpWeight),
    /// Catmull-Rom pyramid (see the module doc).
    Cubic(Cubic),
}

/// Spherical Catmull-Rom coefficients for one parameter `s`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Cubic {
    s: SlerpWeight,
    one_minus_s: SlerpWeight,
    half_s_plus: SlerpWeight,
    half_s: SlerpWeight,
    /// `P−1` is the linear phantom (`A1 = A2`).
    lo_phantom: bool,
    /// `P2` is the linear phantom (`A3 = A2`).
    hi_phantom: bool,
}

impl Cubic {
    fn new(s: f32, lo_phantom: bool, hi_phantom: bool) -> Self {
        Self {
            s: SlerpWeight::new(s),
            one_minus_s: SlerpWeight::new(1.0 - s),
            half_s_plus: SlerpWeight::new(0.5 * (s + 1.0)),
            half_s: SlerpWeight::new(0.5 * s),
            lo_phantom,
            hi_phantom,
        }
    }

    /// Spherical Catmull-Rom of four rotations (exact endpoints), on
    /// `[x, y, z, w]` components of any lane type (same bits per lane).
    #[inline]
    fn rotation<T: Lane>(&self, p: [[T; 4]; 4]) -> [T; 4] {
        let [p0, p1, p2, p3] = p;
        let s = self.s.t();
        if s <= 0.0 {
            return p1;
        }
        if s >= 1.0 {
            return p2;
        }
        let a2 = self.s.apply_lanes(p1, p2);
        let a1 = if self.lo_phantom {
            a2
        } else {
            self.s.apply_lanes(p1, math::reflect_lanes(p0, p1))
        };
        let a3 = if self.hi_phantom {
            a2
        } else {
            self.one_minus_s
                .apply_lanes(p2, math::reflect_lanes(p3, p2))
        };
        let b1 = self.half_s_plus.apply_lanes(a1, a2);
        let b2 = self.half_s.apply_lanes(a2, a3);
        self.s.apply_lanes(b1, b2)
    }
}

/// Catmull-Rom position weights for `P−1, P0, P1, P2` at `s`, phantoms
/// folded in.
fn cubic_position_weights(s: f32, lo_phantom: bool, hi_phantom: bool) -> [f32; 4] {
    let (s2, s3) = (s * s, s * s * s);
    let mut w = [
        0.5 * (-s3 + 2.0 * s2 - s),
        0.5 * (3.0 * s3 - 5.0 * s2 + 2.0),
        0.5 * (-3.0 * s3 + 4.0 * s2 + s),
        0.5 * (s3 - s2),
    ];
    if lo_phantom {
        // P−1 = 2·P0 − P1
        w = [0.0, w[1] + 2.0 * w[0], w[2] - w[0], w[3]];
    }
    if hi_phantom {
        // P2 = 2·P1 − P0
        w = [w[0], w[1] - w[3], w[2] + 2.0 * w[3], 0.0];
    }
    w
}

/// How one axis of a located query interpolates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Shape {
    /// Two samples: lerp / slerp.
    Linear,
    /// Four samples: Catmull-Rom, with `P−1` / `P2` replaced by linear
    /// phantoms where the flags say so.
    Cubic { lo_phantom: bool, hi_phantom: bool },
}

/// One axis of a located query.
#[derive(Clone, Copy, Debug, PartialEq)]
struct AxisQuery {
    /// The window samples along the axis, in window order, as sample-index
    /// offsets (index along the axis times the axis' sample stride).
    offset: [u32; 4],
    /// Position weights of those samples.
    weight: [f32; 4],
    /// Position inside the cell, `[0, 1]`.
    t: f32,
    shape: Shape,
}

impl AxisQuery {
    /// The filler of unused axis slots.
    const UNUSED: Self = Self {
        offset: [0; 4],
        weight: [1.0, 0.0, 0.0, 0.0],
        t: 0.0,
        shape: Shape::Linear,
    };

    /// Samples along the axis in the window (2 linear, 4 Catmull-Rom).
    fn width(&self) -> usize {
        match self.shape {
            Shape::Linear => 2,
            Shape::Cubic { .. } => 4,
        }
    }

    /// The rotation coefficients (polynomials folded, see [`SlerpWeight`]).
    fn rotation_weights(&self) -> AxisWeights {
        match self.shape {
            Shape::Linear => AxisWeights::Linear(SlerpWeight::new(self.t)),
            Shape::Cubic {
                lo_phantom,
                hi_phantom,
            } => AxisWeights::Cubic(Cubic::new(self.t, lo_phantom, hi_phantom)),
        }
    }
}

/// A located query: per axis, the window samples, their position weights
/// and the in-cell coordinate (see the module doc). It is small (cheap to
/// return and copy); [`Query::pose`] derives the coefficients it applies to
/// every segment once per call.
#[derive(Clone, Copy, Debug)]
pub struct Query {
    axes: [AxisQuery; MAX_AXES],
    axis_count: usize,
    params: [f32; MAX_AXES],
    adjust: Adjust,
}

/// The window of a query: the indices of its samples (axis 0 fastest) and
/// their position weights (the tensor product of the axis weights).
#[derive(Clone, Copy, Debug)]
pub struct Window {
    index: [u32; MAX_WINDOW],
    weight: [f32; MAX_WINDOW],
    len: usize,
}

impl Window {
    /// The tensor expansion of `axes` (axis 0 fastest).
    fn of(axes: &[AxisQuery]) -> Self {
        let mut w = Window {
            index: [0; MAX_WINDOW],
            weight: [0.0; MAX_WINDOW],
            len: 1,
        };
        if let Some(first) = w.weight.first_mut() {
            *first = 1.0;
        }
        for axis in axes {
            w.expand(axis);
        }
        w
    }

    /// Expands the window by one axis: every existing entry is repeated for
    /// each of the axis' samples (the new axis varies slowest).
    fn expand(&mut self, axis: &AxisQuery) {
        let old = self.len;
        let width = axis.width();
        self.len = old.saturating_mul(width).min(MAX_WINDOW);
        // Fill from the back so the old entries are read before being overwritten.
        let along = axis.offset.iter().zip(&axis.weight).take(width);
        for (digit, (&offset, &aw)) in along.enumerate().rev() {
            for base in (0..old).rev() {
                let j = digit * old + base;
                let (bi, bw) = (
                    self.index.get(base).copied().unwrap_or(0),
                    self.weight.get(base).copied().unwrap_or(0.0),
                );
                if let (Some(wi), Some(ww)) = (self.index.get_mut(j), self.weight.get_mut(j)) {
                    *wi = bi.wrapping_add(offset);
                    *ww = bw * aw;
                }
            }
        }
    }

    /// Sample indices of the window (axis 0 fastest).
    #[must_use]
    pub fn indices(&self) -> &[u32] {
        self.index.get(..self.len).unwrap_or(&[])
    }

    /// Position weight of each window sample.
    #[must_use]
    pub fn weights(&self) -> &[f32] {
        self.weight.get(..self.len).unwrap_or(&[])
    }
}

/// Where a query landed along one axis.
#[derive(Clone, Copy, Debug)]
struct Located {
    /// Cell index along the axis.
    cell: u32,
    /// Position inside the cell, `[0, 1]`.
    t: f32,
}

impl<'a> Grid<'a> {
    /// Builds and validates a grid. `valid`, if given, needs one bit per cell.
    pub fn new(axes: &[Axis], valid: Option<&'a [u8]>) -> Result<Self, GridError> {
        if axes.is_empty() || axes.len() > MAX_AXES {
            return Err(GridError::AxisCount);
        }
        let mut g = Grid {
            axes: [Axis::linear(0.0, 1.0, 2); MAX_AXES],
            axis_count: axes.len(),
            inv_step: [1.0; MAX_AXES],
            sample_stride: [0; MAX_AXES],
            cell_stride: [0; MAX_AXES],
            samples: 1,
            cells: 1,
            window: 1,
            valid,
        };
        let fields = g
            .axes
            .iter_mut()
            .zip(&mut g.inv_step)
            .zip(&mut g.sample_stride)
            .zip(&mut g.cell_stride);
        for (i, ((((slot, inv), ss), cs), axis)) in fields.zip(axes).enumerate() {
            check_axis(axis).map_err(|()| GridError::BadAxis { axis: i as u8 })?;
            *slot = *axis;
            *inv = 1.0 / axis.step;
            *ss = g.samples;
            *cs = g.cells;
            g.samples = g
                .samples
                .checked_mul(axis.count)
                .ok_or(GridError::TooManySamples)?;
            g.cells = g
                .cells
                .checked_mul(axis.cells())
                .ok_or(GridError::TooManySamples)?;
            g.window = g.window.saturating_mul(axis.window());
        }
        if g.window > MAX_WINDOW {
            return Err(GridError::WindowTooLarge);
        }
        if let Some(mask) = valid
            && (mask.len() as u64) * 8 < u64::from(g.cells)
        {
            return Err(GridError::MaskLength);
        }
        Ok(g)
    }

    /// The axes.
    #[must_use]
    pub fn axes(&self) -> &[Axis] {
        self.axes.get(..self.axis_count).unwrap_or(&[])
    }

    /// Number of grid samples (product of the axis counts).
    #[must_use]
    pub fn sample_count(&self) -> usize {
        self.samples as usize
    }

    /// Number of cells (product of the axis cell counts).
    #[must_use]
    pub fn cell_count(&self) -> usize {
        self.cells as usize
    }

    /// Whether cell `index` is valid (always true without a mask).
    #[must_use]
    pub fn cell_valid(&self, index: usize) -> bool {
        match self.valid {
            None => index < self.cell_count(),
            Some(mask) => {
                index < self.cell_count()
                    && mask
                        .get(index / 8)
                        .is_some_and(|b| b >> (index % 8) & 1 == 1)
            }
        }
    }

    /// Locates `params` (one per axis) and computes the interpolation
    /// coefficients (see the module doc for the clamping/projection policy).
    ///
    /// # Example
    ///
    /// A grid over one axis, `a` from 0 to 2 in steps of 1 (three samples,
    /// two cells): `a = 0.5` lies halfway through the first cell.
    ///
    /// ```
    /// use marionette_core::grid::{Adjust, Axis, Grid};
    ///
    /// let grid = Grid::new(&[Axis::linear(0.0, 1.0, 3)], None).unwrap();
    /// let q = grid.query(&[0.5]).unwrap();
    /// // The samples it blends, and their weights.
    /// assert_eq!(q.window().indices(), &[0, 1]);
    /// assert_eq!(q.window().weights(), &[0.5, 0.5]);
    /// assert_eq!(q.adjust(), Adjust::None);
    /// // Outside the axis the parameter is clamped, and the query says so.
    /// let q = grid.query(&[7.0]).unwrap();
    /// assert_eq!(q.adjust(), Adjust::Clamped);
    /// assert_eq!(q.params(), &[2.0]);
    /// ```
    pub fn query(&self, params: &[f32]) -> Result<Query, GridError> {
        let mut q = Query::default();
        self.query_into(params, &mut q)?;
        Ok(q)
    }

    /// [`Grid::query`] into an existing [`Query`] (no copy of the large
    /// query struct; reuse one across frames on the firmware).
    pub fn query_into(&self, params: &[f32], q: &mut Query) -> Result<(), GridError> {
        if params.len() != self.axis_count {
            return Err(GridError::ParamCount);
        }
        let mut u = [0.0f32; MAX_AXES];
        let mut adjust = Adjust::None;
        for (i, ((ui, &p), axis)) in u.iter_mut().zip(params).zip(self.axes()).enumerate() {
            if !p.is_finite() {
                return Err(GridError::NonFinite { axis: i as u8 });
            }
            let (v, clamped) = to_cell_units(axis, self.inv_step.get(i).copied().unwrap_or(1.0), p);
            if clamped {
                adjust = Adjust::Clamped;
            }
            *ui = v;
        }
        let mut loc = [Located { cell: 0, t: 0.0 }; MAX_AXES];
        for ((l, &ui), axis) in loc.iter_mut().zip(&u).zip(self.axes()) {
            *l = locate(axis, ui);
        }
        if !self.cell_valid(self.cell_index(&loc) as usize) {
            let (moved, d2) = self.project(&u)?;
            loc = moved;
            // On the boundary of a valid cell: not a projection.
            if d2 > 0.0 {
                adjust = Adjust::Projected;
            }
        }
        self.build_query(&loc, adjust, q);
        Ok(())
    }

    /// Convenience: [`Grid::query`] then [`Query::pose`]; returns the adjustment.
    ///
    /// # Example
    ///
    /// Synthesizing a pose from a table in memory: one segment sampled at
    /// `a = 0` (at the origin) and `a = 1` (2 m along X, turned 90° about
    /// Y); `a = 0.25` blends them a quarter of the way.
    ///
    /// ```
    /// use glam::{Quat, Vec3};
    /// use marionette_core::grid::{Axis, Grid, SliceSamples};
    /// use marionette_core::pose::Pose;
    ///
    /// let positions = [Vec3::ZERO, Vec3::new(2.0, 0.0, 0.0)];
    /// let rotations = [Quat::IDENTITY, Quat::from_rotation_y(core::f32::consts::FRAC_PI_2)];
    /// let samples = SliceSamples::new(1, &positions, &rotations).unwrap();
    /// let grid = Grid::new(&[Axis::linear(0.0, 1.0, 2)], None).unwrap();
    ///
    /// let mut pose = Pose::<4>::new(1).unwrap();
    /// grid.synthesize(&samples, &[0.25], &mut pose).unwrap();
    /// assert!(pose.positions[0].abs_diff_eq(Vec3::new(0.5, 0.0, 0.0), 1e-6));
    /// // A quarter of the turn: 22.5° about Y.
    /// let (axis, angle) = pose.rotations[0].to_axis_angle();
    /// assert!(axis.abs_diff_eq(Vec3::Y, 1e-4) && (angle - 22.5f32.to_radians()).abs() < 1e-4);
    /// ```
    pub fn synthesize<S: Samples, const N: usize>(
        &self,
        samples: &S,
        params: &[f32],
        out: &mut Pose<N>,
    ) -> Result<Adjust, GridError> {
        let mut q = Query::default();
        self.query_into(params, &mut q)?;
        q.pose(samples, out)?;
        Ok(q.adjust())
    }

    fn cell_index(&self, loc: &[Located; MAX_AXES]) -> u32 {
        loc.iter()
            .zip(&self.cell_stride)
            .take(self.axis_count)
            .fold(0u32, |acc, (l, &s)| {
                acc.wrapping_add(l.cell.wrapping_mul(s))
            })
    }

    /// Nearest point of the nearest valid cell to `u` (cell units).
    fn project(&self, u: &[f32; MAX_AXES]) -> Result<([Located; MAX_AXES], f32), GridError> {
        let mut best: Option<(f32, u32)> = None;
        for c in 0..self.cells {
            if !self.cell_valid(c as usize) {
                continue;
            }
            let mut d2 = 0.0f32;
            let mut rest = c;
            for (axis, &ui) in self.axes().iter().zip(u) {
                let n = axis.cells();
                let k = rest.checked_rem(n).unwrap_or(0);
                rest = rest.checked_div(n).unwrap_or(0);
                let (d, _) = nearest_in_cell(axis, ui, k);
                d2 += d * d;
            }
            if best.is_none_or(|(bd, _)| d2 < bd) {
                best = Some((d2, c));
            }
        }
        let (d2, c) = best.ok_or(GridError::NoValidCell)?;
        let mut loc = [Located { cell: 0, t: 0.0 }; MAX_AXES];
        let mut rest = c;
        for ((l, axis), &ui) in loc.iter_mut().zip(self.axes()).zip(u) {
            let n = axis.cells();
            let k = rest.checked_rem(n).unwrap_or(0);
            rest = rest.checked_div(n).unwrap_or(0);
            let (_, t) = nearest_in_cell(axis, ui, k);
            *l = Located { cell: k, t };
        }
        Ok((loc, d2))
    }

    fn build_query(&self, loc: &[Located; MAX_AXES], adjust: Adjust, q: &mut Query) {
        q.axis_count = self.axis_count;
        q.adjust = adjust;
        for (a, (((axis, l), aq), param)) in self
            .axes()
            .iter()
            .zip(loc)
            .zip(&mut q.axes)
            .zip(&mut q.params)
            .enumerate()
        {
            *aq = self.axis_window(a, loc, axis, l);
            *param = axis_param(axis, l);
        }
    }

    /// Window samples along axis `a` (window order, as index offsets),
    /// their position weights and the interpolation shape.
    fn axis_window(
        &self,
        a: usize,
        loc: &[Located; MAX_AXES],
        axis: &Axis,
        l: &Located,
    ) -> AxisQuery {
        let n = axis.count;
        let k = l.cell;
        let cyclic = matches!(axis.kind, AxisKind::Cyclic { .. });
        let next = |i: u32| {
            if i + 1 >= n {
                if cyclic { 0 } else { i }
            } else {
                i + 1
            }
        };
        let stride = self.sample_stride.get(a).copied().unwrap_or(0);
        let (idx, weight, shape) = match axis.interp {
            Interp::Linear => (
                [k, next(k), 0, 0],
                [1.0 - l.t, l.t, 0.0, 0.0],
                Shape::Linear,
            ),
            Interp::CatmullRom => {
                let k1 = next(k);
                let (has_lo, has_hi) = (cyclic || k > 0, cyclic || k + 2 < n);
                let lo_ok = has_lo && self.neighbour_valid(a, loc, false);
                let hi_ok = has_hi && self.neighbour_valid(a, loc, true);
                let km1 = if lo_ok {
                    if k == 0 { n - 1 } else { k - 1 }
                } else {
                    k
                };
                let k2 = if hi_ok { next(k1) } else { k1 };
                (
                    [km1, k, k1, k2],
                    cubic_position_weights(l.t, !lo_ok, !hi_ok),
                    Shape::Cubic {
                        lo_phantom: !lo_ok,
                        hi_phantom: !hi_ok,
                    },
                )
            }
        };
        AxisQuery {
            offset: idx.map(|i| i.wrapping_mul(stride)),
            weight,
            t: l.t,
            shape,
        }
    }

    /// Whether the cell next to the located one along axis `a` is valid.
    fn neighbour_valid(&self, a: usize, loc: &[Located; MAX_AXES], up: bool) -> bool {
        if self.valid.is_none() {
            return true;
        }
        let mut moved = *loc;
        let (Some(l), Some(axis)) = (moved.get_mut(a), self.axes().get(a)) else {
            return false;
        };
        let n = axis.cells();
        l.cell = match (up, l.cell) {
            (true, c) if c + 1 < n => c + 1,
            (true, _) => 0,
            (false, 0) => n.saturating_sub(1),
            (false, c) => c - 1,
        };
        self.cell_valid(self.cell_index(&moved) as usize)
    }
}

fn check_axis(a: &Axis) -> Result<(), ()> {
    let ok = a.count >= 2 && a.min.is_finite() && a.step.is_finite() && a.step > 0.0;
    let period_ok = match a.kind {
        AxisKind::Bounded => true,
        AxisKind::Cyclic { period } => {
            let expect = a.count as f32 * a.step;
            math::abs(period - expect) <= 1e-5 * expect
        }
    };
    if ok && period_ok { Ok(()) } else { Err(()) }
}

/// Parameter in cell units along the axis (wrapped or clamped), and whether
/// it was clamped.
fn to_cell_units(axis: &Axis, inv_step: f32, p: f32) -> (f32, bool) {
    let u = (p - axis.min) * inv_step;
    let n = axis.count as f32;
    // Rounding of p = min + i·step and of the line above is below
    // ε·(|min|/step + 2|u|) cells; snap within four times that.
    let tol = 4.0 * f32::EPSILON * (1.0 + math::abs(u) + math::abs(axis.min) * inv_step);
    match axis.kind {
        AxisKind::Bounded => {
            // max/min, not clamp: clamp asserts lo <= hi, a panic path.
            let c = snap(u.max(0.0).min(n - 1.0), tol);
            (c, math::abs(c - u) > tol)
        }
        AxisKind::Cyclic { .. } => {
            let w = u - n * math::floor(u / n);
            // Not `w >= n || w < 0`: a huge parameter makes `u` infinite and
            // `w` NaN, which must wrap to 0 too (a NaN weight is a NaN pose).
            let w = snap(if (0.0..n).contains(&w) { w } else { 0.0 }, tol);
            (if w >= n { 0.0 } else { w }, false)
        }
    }
}

/// Snaps `u` to the nearest integer when within `tol`.
fn snap(u: f32, tol: f32) -> f32 {
    let r = math::floor(u + 0.5);
    if math::abs(u - r) <= tol { r } else { u }
}

/// Cell and in-cell coordinate for `u` (cell units, already in range).
fn locate(axis: &Axis, u: f32) -> Located {
    let cells = axis.cells();
    let k = math::floor(u);
    // Saturating float→int; the last sample of a bounded axis is t = 1 of the last cell.
    let mut cell = k as u32;
    let mut t = u - k;
    if cell >= cells {
        match axis.kind {
            AxisKind::Bounded => {
                cell = cells.saturating_sub(1);
                t = u - cell as f32;
            }
            AxisKind::Cyclic { .. } => {
                cell = 0;
                t = 0.0;
            }
        }
    }
    Located {
        cell,
        t: t.clamp(0.0, 1.0),
    }
}

/// Distance (cell units) from `u` to cell `k` along the axis, and the
/// in-cell coordinate of the nearest point.
fn nearest_in_cell(axis: &Axis, u: f32, k: u32) -> (f32, f32) {
    let lo = k as f32;
    let one = |v: f32| {
        let c = v.max(lo).min(lo + 1.0);
        (math::abs(v - c), c - lo)
    };
    match axis.kind {
        AxisKind::Bounded => one(u),
        AxisKind::Cyclic { .. } => {
            let n = axis.count as f32;
            let (a, b, c) = (one(u), one(u - n), one(u + n));
            let best = if b.0 < a.0 { b } else { a };
            if c.0 < best.0 { c } else { best }
        }
    }
}

/// The parameter value a located query stands for.
fn axis_param(axis: &Axis, l: &Located) -> f32 {
    let v = axis.min + (l.cell as f32 + l.t) * axis.step;
    match axis.kind {
        AxisKind::Cyclic { period } if v >= axis.min + period => v - period,
        _ => v,
    }
}

impl Default for Query {
    /// An empty query (window of one sample 0, no axes); fill it with
    /// [`Grid::query_into`].
    fn default() -> Self {
        Query {
            axes: [AxisQuery::UNUSED; MAX_AXES],
            axis_count: 0,
            params: [0.0; MAX_AXES],
            adjust: Adjust::None,
        }
    }
}

impl Query {
    /// What the query did to its parameters.
    #[must_use]
    pub fn adjust(&self) -> Adjust {
        self.adjust
    }

    /// The parameters actually used (after clamping, wrapping, projection).
    #[must_use]
    pub fn params(&self) -> &[f32] {
        self.params.get(..self.axis_count).unwrap_or(&[])
    }

    /// The window: sample indices (axis 0 fastest) and the position weight
    /// of each (tensor product of the axis weights).
    #[must_use]
    pub fn window(&self) -> Window {
        Window::of(self.used_axes())
    }

    fn used_axes(&self) -> &[AxisQuery] {
        self.axes.get(..self.axis_count).unwrap_or(&[])
    }

    /// Interpolates every segment of the samples into `out` (`out.count` is set
    /// to the source's segment count).
    ///
    /// Three linear axes (the W&H hand grid) take an unrolled 4 + 2 + 1 tree
    /// of [`SlerpWeight::blend_lanes`] whose result is normalized once
    /// ([`math::renormalize_lanes`]); other grids reduce the window axis by
    /// axis with normalized slerps. On targets with SIMD (the host) segments
    /// are processed in blocks: the window read sample by sample (a run of
    /// segments at once from [`Samples::row`]), positions weighed 12 floats
    /// at a time, the slerps of four segments running as [`math::F4`] lanes
    /// with their coefficients broadcast once ([`SlerpWeight::lanes`]). On
    /// the Cortex-M (no SIMD) each segment runs on its own
    /// ([`Query::pose_scalar`] forces that path anywhere). All paths perform
    /// the same operations in the same order per segment, so they give the
    /// same bits (tested).
    pub fn pose<S: Samples, const N: usize>(
        &self,
        samples: &S,
        out: &mut Pose<N>,
    ) -> Result<(), GridError> {
        self.pose_on(samples, out, WIDE)
    }

    /// [`Query::pose`] through the path the Cortex-M takes (one segment at
    /// a time) on any target, for tests: the same bits as `pose`.
    pub fn pose_scalar<S: Samples, const N: usize>(
        &self,
        samples: &S,
        out: &mut Pose<N>,
    ) -> Result<(), GridError> {
        self.pose_on(samples, out, false)
    }

    /// [`Query::pose`], in blocks of [`F4`] lanes if `wide`.
    #[inline(always)]
    fn pose_on<S: Samples, const N: usize>(
        &self,
        samples: &S,
        out: &mut Pose<N>,
        wide: bool,
    ) -> Result<(), GridError> {
        let n = samples.segment_count();
        if n > N {
            return Err(GridError::Capacity);
        }
        out.count = n;
        let positions = out.positions.get_mut(..n).unwrap_or(&mut []);
        let rotations = out.rotations.get_mut(..n).unwrap_or(&mut []);
        match self.trilinear() {
            Some(tree) => tree.pose(samples, (positions, rotations), wide),
            None => self.general(samples, (positions, rotations), wide),
        }
    }

    /// Interpolates one segment (the scalar path the Cortex-M uses for
    /// every segment). Derives the coefficients on every call: for whole
    /// poses use [`Query::pose`].
    pub fn segment<S: Samples>(
        &self,
        samples: &S,
        segment: usize,
    ) -> Result<(Vec3, Quat), GridError> {
        match self.trilinear() {
            Some(tree) => tree.segment(samples, segment),
            None => {
                let mut out = (Vec3::ZERO, Quat::IDENTITY);
                let slots = (
                    core::slice::from_mut(&mut out.0),
                    core::slice::from_mut(&mut out.1),
                );
                self.plan().scalar_any(samples, segment, slots)?;
                Ok(out)
            }
        }
    }

    /// The unrolled tree of an all-linear three-axis query.
    fn trilinear(&self) -> Option<Trilinear> {
        match self.used_axes() {
            [x, y, z] if [x, y, z].iter().all(|a| a.shape == Shape::Linear) => {
                Some(Trilinear::new(x, y, z))
            }
            _ => None,
        }
    }

    /// [`Query::pose`] through the general tree. Not inlined: its scratch
    /// (a few kilobytes) then takes stack only when a grid needs it.
    #[inline(never)]
    fn general<S: Samples>(
        &self,
        samples: &S,
        (positions, rotations): (&mut [Vec3], &mut [Quat]),
        wide: bool,
    ) -> Result<(), GridError> {
        let plan = self.plan();
        if wide {
            plan.pose(samples, positions, rotations)
        } else {
            plan.scalar_any(samples, 0, (positions, rotations))
        }
    }

    /// The window and rotation coefficients of the general tree.
    fn plan(&self) -> Plan {
        let mut axes = [AxisWeights::Linear(SlerpWeight::START); MAX_AXES];
        for (w, a) in axes.iter_mut().zip(self.used_axes()) {
            *w = a.rotation_weights();
        }
        Plan {
            window: self.window(),
            axes,
            axis_count: self.axis_count,
        }
    }
}

/// The W&H hand grid, three linear axes: a 2×2×2 window and the tree
/// `z(y(x(q0, q1), x(q2, q3)), y(x(q4, q5), x(q6, q7)))` of unnormalized
/// blends, normalized once if any level blends.
struct Trilinear {
    index: [u32; 8],
    weight: [f32; 8],
    slerp: [SlerpWeight; 3],
    blends: bool,
}

impl Trilinear {
    fn new(x: &AxisQuery, y: &AxisQuery, z: &AxisQuery) -> Self {
        let ([x0, x1, ..], [y0, y1, ..], [z0, z1, ..]) = (x.offset, y.offset, z.offset);
        let ([u0, u1, ..], [v0, v1, ..], [w0, w1, ..]) = (x.weight, y.weight, z.weight);
        // The same sums and products, in the same order, as `Window::of`.
        let at = |a: u32, b: u32, c: u32| a.wrapping_add(b).wrapping_add(c);
        // Written out, not `[..].map(..)` (an out-of-line loop at opt-level "s").
        let slerp = [
            SlerpWeight::new(x.t),
            SlerpWeight::new(y.t),
            SlerpWeight::new(z.t),
        ];
        Self {
            index: [
                at(x0, y0, z0),
                at(x1, y0, z0),
                at(x0, y1, z0),
                at(x1, y1, z0),
                at(x0, y0, z1),
                at(x1, y0, z1),
                at(x0, y1, z1),
                at(x1, y1, z1),
            ],
            weight: [
                u0 * v0 * w0,
                u1 * v0 * w0,
                u0 * v1 * w0,
                u1 * v1 * w0,
                u0 * v0 * w1,
                u1 * v0 * w1,
                u0 * v1 * w1,
                u1 * v1 * w1,
            ],
            blends: slerp.iter().any(SlerpWeight::is_blend),
            slerp,
        }
    }

    /// Every segment: in blocks level by level with [`F4`] lanes if
    /// `wide`, else one at a time.
    #[inline(always)]
    fn pose<S: Samples>(
        &self,
        samples: &S,
        (positions, rotations): (&mut [Vec3], &mut [Quat]),
        wide: bool,
    ) -> Result<(), GridError> {
        if wide {
            self.pose_wide(samples, positions, rotations)
        } else {
            self.pose_each(samples, positions, rotations)
        }
    }

    /// Every segment, one at a time (the Cortex-M path). Not inlined: the
    /// loop gets the registers to itself, whatever the caller keeps live.
    #[inline(never)]
    fn pose_each<S: Samples>(
        &self,
        samples: &S,
        positions: &mut [Vec3],
        rotations: &mut [Quat],
    ) -> Result<(), GridError> {
        let all = positions.iter_mut().zip(rotations.iter_mut());
        let blends = self.slerp.iter().all(SlerpWeight::is_blend);
        if S::DECODES {
            // The whole window first (one copy of the decoder), then the tree.
            for (seg, (p, r)) in all.enumerate() {
                let (pos, q) = self.fetch(samples, seg)?;
                let [x, y, z, w] = if blends {
                    self.tree_blend(q)
                } else {
                    self.tree(q)
                };
                (*p, *r) = (pos, Quat::from_xyzw(x, y, z, w));
            }
            return Ok(());
        }
        let rows = self.index.map(|i| samples.row(i as usize));
        if blends && rows.iter().all(Option::is_some) {
            // In memory: the window's rows once, then one check per read.
            let rows = rows.map(|r| r.unwrap_or((&[], &[])));
            for (seg, (p, r)) in all.enumerate() {
                (*p, *r) = self.segment_blend_by(|j| {
                    let (ps, qs) = rows.get(j)?;
                    Some((*ps.get(seg)?, *qs.get(seg)?))
                })?;
            }
        } else if blends {
            for (seg, (p, r)) in all.enumerate() {
                (*p, *r) = self.segment_blend_by(|j| {
                    let &index = self.index.get(j)?;
                    samples.sample(index as usize, seg)
                })?;
            }
        } else {
            for (seg, (p, r)) in all.enumerate() {
                (*p, *r) = self.segment(samples, seg)?;
            }
        }
        Ok(())
    }

    /// [`Trilinear::tree`] when every level blends (a query inside a
    /// cell, the usual case): the same operations without the endpoint
    /// checks.
    #[inline(always)]
    fn tree_blend(&self, q: [[f32; 4]; 8]) -> [f32; 4] {
        let [q0, q1, q2, q3, q4, q5, q6, q7] = q;
        let [x, y, z] = &self.slerp;
        let ab = y.blend(x.blend(q0, q1), x.blend(q2, q3));
        let cd = y.blend(x.blend(q4, q5), x.blend(q6, q7));
        math::renormalize_lanes(z.blend(ab, cd))
    }

    /// One segment when every level blends, each pair blended as soon as
    /// it is read (window sample `j` by `read(j)`): the operations of
    /// [`Trilinear::tree_blend`], in another order.
    #[inline(always)]
    fn segment_blend_by(
        &self,
        read: impl Fn(usize) -> Option<(Vec3, Quat)>,
    ) -> Result<(Vec3, Quat), GridError> {
        let [x, y, z] = &self.slerp;
        let [w0, w1, w2, w3, w4, w5, w6, w7] = self.weight;
        let get = |j: usize| {
            let (p, q) = read(j).ok_or(GridError::MissingSample)?;
            Ok::<_, GridError>((p, [q.x, q.y, q.z, q.w]))
        };
        let ((p0, q0), (p1, q1)) = (get(0)?, get(1)?);
        let mut p = p0 * w0 + p1 * w1;
        let a = x.blend(q0, q1);
        let ((p2, q2), (p3, q3)) = (get(2)?, get(3)?);
        p = p + p2 * w2 + p3 * w3;
        let ab = y.blend(a, x.blend(q2, q3));
        let ((p4, q4), (p5, q5)) = (get(4)?, get(5)?);
        p = p + p4 * w4 + p5 * w5;
        let c = x.blend(q4, q5);
        let ((p6, q6), (p7, q7)) = (get(6)?, get(7)?);
        p = p + p6 * w6 + p7 * w7;
        let cd = y.blend(c, x.blend(q6, q7));
        let [rx, ry, rz, rw] = math::renormalize_lanes(z.blend(ab, cd));
        Ok((p, Quat::from_xyzw(rx, ry, rz, rw)))
    }

    /// The host path: blocks of `MAX_WINDOW / 8` segments, the same
    /// operations as [`Trilinear::segment`] level by level on four segments
    /// at a time.
    #[inline(never)]
    fn pose_wide<S: Samples>(
        &self,
        samples: &S,
        positions: &mut [Vec3],
        rotations: &mut [Quat],
    ) -> Result<(), GridError> {
        const BLOCK: usize = MAX_WINDOW / 8;
        let mut buf = Soa::new();
        let weights = self.slerp.each_ref().map(SlerpWeight::lanes::<F4>);
        let blocks = positions.chunks_mut(BLOCK).zip(rotations.chunks_mut(BLOCK));
        for (k, (p, r)) in blocks.enumerate() {
            let count = p.len();
            let window = (self.index.as_slice(), self.weight.as_slice());
            fetch_block(samples, window, (k * BLOCK, BLOCK), p, &mut buf)?;
            for lane in [0, 4] {
                if lane < count {
                    self.tree_lanes::<BLOCK>(&weights, &mut buf, lane);
                }
            }
            buf.store(r);
        }
        Ok(())
    }

    /// The tree on slots `lane..lane + 4` of a scratch laid out
    /// `[window][B]`, level by level in place; the results end up in slots
    /// `lane..lane + 4`.
    #[inline(always)]
    fn tree_lanes<const B: usize>(
        &self,
        weights: &[LaneWeight<F4>; 3],
        buf: &mut Soa,
        lane: usize,
    ) {
        let [x, y, z] = weights;
        blend_pairs::<B>(buf, x, 4, lane);
        blend_pairs::<B>(buf, y, 2, lane);
        blend_pairs::<B>(buf, z, 1, lane);
        if self.blends
            && let Some(r) = buf.get4(lane)
        {
            buf.set4(lane, math::renormalize_lanes(r));
        }
    }

    /// One segment.
    #[inline]
    fn segment<S: Samples>(&self, samples: &S, segment: usize) -> Result<(Vec3, Quat), GridError> {
        let (p, q) = self.fetch(samples, segment)?;
        let [x, y, z, w] = self.tree(q);
        Ok((p, Quat::from_xyzw(x, y, z, w)))
    }

    /// The window of one segment: the weighted sum of its positions (in
    /// window order) and its rotations as `[x, y, z, w]`.
    #[inline(always)]
    fn fetch<S: Samples>(
        &self,
        samples: &S,
        segment: usize,
    ) -> Result<(Vec3, [[f32; 4]; 8]), GridError> {
        let mut q = [[0.0; 4]; 8];
        let mut p = Vec3::ZERO;
        // A counted loop rather than zipped iterators: at opt-level "s" the
        // loop is not unrolled, and the iterators cost more than the reads.
        let mut j = 0;
        while let (Some(&index), Some(&w), Some(slot)) =
            (self.index.get(j), self.weight.get(j), q.get_mut(j))
        {
            let (sp, sq) = samples
                .sample(index as usize, segment)
                .ok_or(GridError::MissingSample)?;
            p = if j == 0 { sp * w } else { p + sp * w };
            *slot = [sq.x, sq.y, sq.z, sq.w];
            j += 1;
        }
        Ok((p, q))
    }

    /// The rotation tree on any lane type.
    #[inline(always)]
    fn tree<T: Lane>(&self, q: [[T; 4]; 8]) -> [T; 4] {
        let [q0, q1, q2, q3, q4, q5, q6, q7] = q;
        let [x, y, z] = &self.slerp;
        let ab = y.blend_lanes(x.blend_lanes(q0, q1), x.blend_lanes(q2, q3));
        let cd = y.blend_lanes(x.blend_lanes(q4, q5), x.blend_lanes(q6, q7));
        let r = z.blend_lanes(ab, cd);
        if self.blends {
            math::renormalize_lanes(r)
        } else {
            r
        }
    }
}

/// The general tree of a query: its window and every axis' rotation
/// coefficients, reduced axis by axis with normalized slerps.
struct Plan {
    window: Window,
    axes: [AxisWeights; MAX_AXES],
    axis_count: usize,
}

impl Plan {
    fn window(&self) -> &[u32] {
        self.window.indices()
    }

    fn weights(&self) -> &[f32] {
        self.window.weights()
    }

    fn axes(&self) -> &[AxisWeights] {
        self.axes.get(..self.axis_count).unwrap_or(&[])
    }

    /// Every segment in blocks, with [`F4`] lanes where the block allows.
    fn pose<S: Samples>(
        &self,
        samples: &S,
        positions: &mut [Vec3],
        rotations: &mut [Quat],
    ) -> Result<(), GridError> {
        let n = positions.len();
        let block = MAX_WINDOW.checked_div(self.window.len).unwrap_or(1).max(1);
        let mut buf = Soa::new();
        let mut first = 0;
        while first < n {
            let count = block.min(n - first);
            let p = positions.get_mut(first..first + count).unwrap_or(&mut []);
            fetch_block(
                samples,
                (self.window(), self.weights()),
                (first, block),
                p,
                &mut buf,
            )?;
            self.reduce(&mut buf, block, count);
            let r = rotations.get_mut(first..first + count).unwrap_or(&mut []);
            buf.store(r);
            first += count;
        }
        Ok(())
    }

    /// Segments `first..` through the scalar path with a window-sized buffer.
    fn scalar_any<S: Samples>(
        &self,
        samples: &S,
        first: usize,
        out: (&mut [Vec3], &mut [Quat]),
    ) -> Result<(), GridError> {
        // Two buffer sizes only: every instance is a copy of the loop (and of
        // an inlined sample decoder), which costs flash.
        match self.window.len {
            0..=16 => self.scalar::<S, 16>(samples, first, out),
            _ => self.scalar::<S, MAX_WINDOW>(samples, first, out),
        }
    }

    /// Segments `first..` into `out` one at a time with a `K`-entry window
    /// buffer (`K ≥ len`), reducing in place; the same operations per segment,
    /// in the same order, as the blocked path.
    fn scalar<S: Samples, const K: usize>(
        &self,
        samples: &S,
        first: usize,
        out: (&mut [Vec3], &mut [Quat]),
    ) -> Result<(), GridError> {
        let mut buf = [Quat::IDENTITY; K];
        for (seg, (p, r)) in out.0.iter_mut().zip(out.1.iter_mut()).enumerate() {
            let window = buf.iter_mut().zip(self.window()).zip(self.weights());
            for (j, ((slot, &index), &w)) in window.enumerate() {
                let (sp, sq) = samples
                    .sample(index as usize, first + seg)
                    .ok_or(GridError::MissingSample)?;
                *p = if j == 0 { sp * w } else { *p + sp * w };
                *slot = sq;
            }
            let mut len = self.window.len;
            for axis in self.axes() {
                len = match axis {
                    AxisWeights::Linear(w) => pairs_in_place(&mut buf, len, w),
                    AxisWeights::Cubic(c) => quads_in_place(&mut buf, len, c),
                };
            }
            *r = buf.first().copied().unwrap_or(Quat::IDENTITY);
        }
        Ok(())
    }

    /// Runs the rotation tree on `count` segments laid out `[window][block]`;
    /// the results end up in slots `0..count`.
    #[inline]
    fn reduce(&self, buf: &mut Soa, block: usize, count: usize) {
        let mut len = self.window.len;
        for axis in self.axes() {
            len = match axis {
                AxisWeights::Linear(w) => reduce_linear(buf, len, block, count, w),
                AxisWeights::Cubic(c) => reduce_cubic(buf, len, block, count, c),
            };
        }
    }
}

/// Reads the window of segments `first..first + positions.len()`:
/// positions as the weighted sum (in window order), rotations into slot
/// `j·block + b` of the scratch. Window-major, so each window sample's
/// segments are read consecutively.
#[inline]
fn fetch_block<S: Samples>(
    samples: &S,
    (window, weights): (&[u32], &[f32]),
    (first, block): (usize, usize),
    positions: &mut [Vec3],
    buf: &mut Soa,
) -> Result<(), GridError> {
    let count = positions.len();
    for (j, (&index, &w)) in window.iter().zip(weights).enumerate() {
        let range = j * block..j * block + count;
        let [cx, cy, cz, cw] = &mut buf.0;
        let (Some(sx), Some(sy), Some(sz), Some(sw)) = (
            cx.get_mut(range.clone()),
            cy.get_mut(range.clone()),
            cz.get_mut(range.clone()),
            cw.get_mut(range),
        ) else {
            return Err(GridError::MissingSample);
        };
        if let Some((ps, qs)) = samples.row(index as usize) {
            let run = first..first + count;
            let (Some(ps), Some(qs)) = (ps.get(run.clone()), qs.get(run)) else {
                return Err(GridError::MissingSample);
            };
            weigh(positions, ps, w, j == 0);
            transpose(qs, [sx, sy, sz, sw]);
            continue;
        }
        let rows = sx.iter_mut().zip(sy).zip(sz).zip(sw);
        for (b, ((((x, y), z), qw), p)) in rows.zip(positions.iter_mut()).enumerate() {
            let (sp, sq) = samples
                .sample(index as usize, first + b)
                .ok_or(GridError::MissingSample)?;
            *p = if j == 0 { sp * w } else { *p + sp * w };
            (*x, *y, *z, *qw) = (sq.x, sq.y, sq.z, sq.w);
        }
    }
    Ok(())
}

/// `p = s·w` (`first`) or `p + s·w` for every pair: the same per-coordinate
/// operations on four positions (12 floats) at a time where the target has
/// SIMD.
#[inline]
fn weigh(positions: &mut [Vec3], samples: &[Vec3], w: f32, first: bool) {
    let flat = |v: &[Vec3; 4]| {
        let [a, b, c, d] = *v;
        [
            F4([a.x, a.y, a.z, b.x]),
            F4([b.y, b.z, c.x, c.y]),
            F4([c.z, d.x, d.y, d.z]),
        ]
    };
    let wide = if WIDE { positions.len() / 4 * 4 } else { 0 };
    let (head, tail) = positions.split_at_mut(wide);
    let quads = head.chunks_exact_mut(4).zip(samples.chunks_exact(4));
    for (p, s) in quads {
        if let (Some(p), Some(s)) = (p.first_chunk_mut::<4>(), s.first_chunk::<4>()) {
            let [s0, s1, s2] = flat(s).map(|v| v * F4::splat(w));
            let [x0, x1, x2] = if first {
                [s0, s1, s2]
            } else {
                let [p0, p1, p2] = flat(p);
                [p0 + s0, p1 + s1, p2 + s2]
            };
            let ([a0, a1, a2, b0], [b1, b2, c0, c1], [c2, d0, d1, d2]) = (x0.0, x1.0, x2.0);
            *p = [
                Vec3::new(a0, a1, a2),
                Vec3::new(b0, b1, b2),
                Vec3::new(c0, c1, c2),
                Vec3::new(d0, d1, d2),
            ];
        }
    }
    for (p, &s) in tail.iter_mut().zip(samples.iter().skip(wide)) {
        *p = if first { s * w } else { *p + s * w };
    }
}

/// `g[i] = blend(g[2i], g[2i+1])` for `i < len` on slots `lane..lane + 4` of
/// each window group `g` (stride `B`).
#[inline(always)]
fn blend_pairs<const B: usize>(buf: &mut Soa, w: &LaneWeight<F4>, len: usize, lane: usize) {
    for i in 0..len {
        let (a, b) = (buf.get4(2 * i * B + lane), buf.get4((2 * i + 1) * B + lane));
        if let (Some(a), Some(b)) = (a, b) {
            buf.set4(i * B + lane, w.blend_lanes(a, b));
        }
    }
}

/// Rotations into per-component rows (`[x, y, z, w]`).
#[inline]
fn transpose(rotations: &[Quat], [rx, ry, rz, rw]: [&mut [f32]; 4]) {
    let rows = rx.iter_mut().zip(ry).zip(rz).zip(rw);
    for ((((x, y), z), w), q) in rows.zip(rotations) {
        (*x, *y, *z, *w) = (q.x, q.y, q.z, q.w);
    }
}

/// `buf[i] = slerp(buf[2i], buf[2i+1])` for `i < len/2`.
#[inline]
fn pairs_in_place<const K: usize>(buf: &mut [Quat; K], len: usize, w: &SlerpWeight) -> usize {
    let half = len / 2;
    for i in 0..half {
        if let (Some(&a), Some(&b)) = (buf.get(2 * i), buf.get(2 * i + 1))
            && let Some(slot) = buf.get_mut(i)
        {
            *slot = w.apply(a, b);
        }
    }
    half
}

/// `buf[i] = spherical Catmull-Rom(buf[4i..4i+4])` for `i < len/4`.
#[inline]
fn quads_in_place<const K: usize>(buf: &mut [Quat; K], len: usize, c: &Cubic) -> usize {
    let quarter = len / 4;
    for i in 0..quarter {
        let at = |k: usize| {
            let q = buf.get(4 * i + k).copied().unwrap_or(Quat::IDENTITY);
            [q.x, q.y, q.z, q.w]
        };
        let [x, y, z, w] = c.rotation([at(0), at(1), at(2), at(3)]);
        if let Some(slot) = buf.get_mut(i) {
            *slot = Quat::from_xyzw(x, y, z, w);
        }
    }
    quarter
}

/// Rotation scratch, one array per quaternion component (`[x, y, z, w]`).
struct Soa([[f32; MAX_WINDOW]; 4]);

impl Soa {
    fn new() -> Self {
        Soa([
            [0.0; MAX_WINDOW],
            [0.0; MAX_WINDOW],
            [0.0; MAX_WINDOW],
            [1.0; MAX_WINDOW],
        ])
    }

    #[inline]
    fn get(&self, i: usize) -> Quat {
        let [x, y, z, w] = &self.0;
        let at = |c: &[f32; MAX_WINDOW]| c.get(i).copied().unwrap_or(0.0);
        Quat::from_xyzw(at(x), at(y), at(z), at(w))
    }

    #[inline]
    fn set(&mut self, i: usize, q: Quat) {
        for (c, v) in self.0.iter_mut().zip([q.x, q.y, q.z, q.w]) {
            if let Some(slot) = c.get_mut(i) {
                *slot = v;
            }
        }
    }

    /// Slots `0..out.len()` as quaternions.
    #[inline]
    fn store(&self, out: &mut [Quat]) {
        let [cx, cy, cz, cw] = &self.0;
        for ((((r, &x), &y), &z), &w) in out.iter_mut().zip(cx).zip(cy).zip(cz).zip(cw) {
            *r = Quat::from_xyzw(x, y, z, w);
        }
    }

    /// Four consecutive slots starting at `i`, as lanes.
    #[inline]
    fn get4(&self, i: usize) -> Option<[F4; 4]> {
        let [x, y, z, w] = &self.0;
        let lanes = |c: &[f32; MAX_WINDOW]| {
            c.get(i..)
                .and_then(|s| s.first_chunk::<4>())
                .map(|a| F4(*a))
        };
        Some([lanes(x)?, lanes(y)?, lanes(z)?, lanes(w)?])
    }

    #[inline]
    fn set4(&mut self, i: usize, v: [F4; 4]) {
        for (c, lane) in self.0.iter_mut().zip(v) {
            if let Some(dst) = c.get_mut(i..).and_then(|s| s.first_chunk_mut::<4>()) {
                *dst = lane.0;
            }
        }
    }
}

/// Four lanes of slerp per step where the target has SIMD; on the Cortex-M
/// (no SIMD FPU) the scalar path avoids the register pressure of four lanes.
const WIDE: bool = !cfg!(target_arch = "arm");

/// Slerps adjacent pairs in place: `g[i] = slerp(g[2i], g[2i+1])` for each
/// window group `g` (stride `block`) and each of the `count` segments.
#[inline]
fn reduce_linear(buf: &mut Soa, len: usize, block: usize, count: usize, w: &SlerpWeight) -> usize {
    let half = len / 2;
    for i in 0..half {
        let (ia, ib, io) = (2 * i * block, (2 * i + 1) * block, i * block);
        let mut b = 0;
        // Whole lanes of four; the last group may run past `count` into
        // unused slots of the block (their results are never read).
        let wide_end = if WIDE && block.is_multiple_of(4) {
            count.div_ceil(4) * 4
        } else {
            0
        };
        while b < wide_end {
            if let (Some(qa), Some(qb)) = (buf.get4(ia + b), buf.get4(ib + b)) {
                buf.set4(io + b, w.apply_lanes(qa, qb));
            }
            b += 4;
        }
        while b < count {
            let q = w.apply(buf.get(ia + b), buf.get(ib + b));
            buf.set(io + b, q);
            b += 1;
        }
    }
    half
}

/// Spherical Catmull-Rom over groups of four, in place (layout as above).
#[inline]
fn reduce_cubic(buf: &mut Soa, len: usize, block: usize, count: usize, c: &Cubic) -> usize {
    let quarter = len / 4;
    let wide_end = if WIDE && block.is_multiple_of(4) {
        count.div_ceil(4) * 4
    } else {
        0
    };
    for i in 0..quarter {
        let slot = |k: usize, b: usize| (4 * i + k) * block + b;
        let mut b = 0;
        while b < wide_end {
            if let (Some(q0), Some(q1), Some(q2), Some(q3)) = (
                buf.get4(slot(0, b)),
                buf.get4(slot(1, b)),
                buf.get4(slot(2, b)),
                buf.get4(slot(3, b)),
            ) {
                buf.set4(i * block + b, c.rotation([q0, q1, q2, q3]));
            }
            b += 4;
        }
        while b < count {
            let at = |k: usize| {
                let q = buf.get(slot(k, b));
                [q.x, q.y, q.z, q.w]
            };
            let [x, y, z, w] = c.rotation([at(0), at(1), at(2), at(3)]);
            buf.set(i * block + b, Quat::from_xyzw(x, y, z, w));
            b += 1;
        }
    }
    quarter
}

/// Limits how fast parameters may change (units per second per axis; cyclic
/// axes move the short way round). Keeps the synthesized pose from jumping
/// when a tracker glitches.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamLimiter {
    rates: [f32; MAX_AXES],
    periods: [f32; MAX_AXES],
    state: [f32; MAX_AXES],
    count: usize,
    primed: bool,
}

impl ParamLimiter {
    /// A limiter with `rates[a]` units/s on each axis; `periods[a] > 0` marks a
    /// cyclic axis (0 = not cyclic). Extra entries beyond [`MAX_AXES`] are ignored.
    #[must_use]
    pub fn new(rates: &[f32], periods: &[f32]) -> Self {
        let mut s = Self {
            rates: [0.0; MAX_AXES],
            periods: [0.0; MAX_AXES],
            state: [0.0; MAX_AXES],
            count: 0,
            primed: false,
        };
        for (d, &r) in s.rates.iter_mut().zip(rates) {
            *d = math::abs(r);
            s.count += 1;
        }
        for (d, &p) in s.periods.iter_mut().zip(periods) {
            *d = p;
        }
        s
    }

    /// Moves the state towards `target` by at most `rate·dt` per axis and
    /// returns it. The first call (or after [`ParamLimiter::reset`]) jumps to
    /// the target. Non-finite targets keep the previous value.
    pub fn update(&mut self, target: &[f32], dt: f32) -> &[f32] {
        let first = !self.primed;
        self.primed = true;
        let dt = if dt.is_finite() && dt > 0.0 { dt } else { 0.0 };
        for (((s, &t), &r), &p) in self
            .state
            .iter_mut()
            .zip(target)
            .zip(&self.rates)
            .zip(&self.periods)
        {
            if !t.is_finite() {
                continue;
            }
            if first {
                *s = t;
                continue;
            }
            let mut d = t - *s;
            if p > 0.0 {
                d -= p * math::floor(d / p + 0.5);
            }
            let m = r * dt;
            *s += d.max(-m).min(m);
            if p > 0.0 {
                *s -= p * math::floor(*s / p);
            }
        }
        self.state.get(..self.count).unwrap_or(&[])
    }

    /// Forgets the state; the next update jumps to its target.
    pub fn reset(&mut self) {
        self.primed = false;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn axis(min: f32, step: f32, count: u32) -> Axis {
        Axis::linear(min, step, count)
    }

    #[test]
    fn validation() {
        assert_eq!(Grid::new(&[], None).err(), Some(GridError::AxisCount));
        assert_eq!(
            Grid::new(&[axis(0.0, 1.0, 1)], None).err(),
            Some(GridError::BadAxis { axis: 0 })
        );
        assert_eq!(
            Grid::new(&[axis(0.0, 1.0, 2), axis(0.0, -1.0, 2)], None).err(),
            Some(GridError::BadAxis { axis: 1 })
        );
        let bad_period = Axis {
            kind: AxisKind::Cyclic { period: 1.0 },
            ..axis(0.0, 0.25, 8)
        };
        assert_eq!(
            Grid::new(&[bad_period], None).err(),
            Some(GridError::BadAxis { axis: 0 })
        );
        let cr = Axis {
            interp: Interp::CatmullRom,
            ..axis(0.0, 1.0, 4)
        };
        assert_eq!(
            Grid::new(&[cr, cr, cr, cr], None).err(),
            Some(GridError::WindowTooLarge)
        );
        assert_eq!(
            Grid::new(&[axis(0.0, 1.0, 10), axis(0.0, 1.0, 10)], Some(&[0xff; 10])).err(),
            Some(GridError::MaskLength)
        );
        let g = Grid::new(&[axis(0.0, 1.0, 3)], None).unwrap();
        assert_eq!(g.query(&[0.0, 1.0]).err(), Some(GridError::ParamCount));
        assert_eq!(
            g.query(&[f32::NAN]).err(),
            Some(GridError::NonFinite { axis: 0 })
        );
    }

    #[test]
    fn locate_and_clamp() {
        let g = Grid::new(&[axis(1.0, 0.5, 5)], None).unwrap();
        let q = g.query(&[1.75]).unwrap();
        assert_eq!(q.window().indices(), &[1, 2]);
        assert_eq!(q.window().weights(), &[0.5, 0.5]);
        assert_eq!(q.adjust(), Adjust::None);
        let q = g.query(&[3.0]).unwrap();
        assert_eq!(
            (q.window().indices(), q.window().weights()),
            (&[3u32, 4][..], &[0.0f32, 1.0][..])
        );
        let q = g.query(&[99.0]).unwrap();
        assert_eq!(q.adjust(), Adjust::Clamped);
        assert_eq!(q.params(), &[3.0]);
    }

    #[test]
    fn cyclic_wraps() {
        let a = Axis {
            kind: AxisKind::Cyclic { period: 2.0 },
            ..axis(0.0, 0.5, 4)
        };
        let g = Grid::new(&[a], None).unwrap();
        let q = g.query(&[1.75]).unwrap();
        assert_eq!(q.window().indices(), &[3, 0]);
        let q = g.query(&[-0.25]).unwrap();
        assert_eq!(q.window().indices(), &[3, 0]);
        assert_eq!(q.adjust(), Adjust::None);
        assert!((q.params()[0] - 1.75).abs() < 1e-6);
    }

    #[test]
    fn projection_to_nearest_valid_cell() {
        // 4x1 cells (5x2 samples); only cell 3 valid.
        let g = Grid::new(&[axis(0.0, 1.0, 5), axis(0.0, 1.0, 2)], Some(&[0b1000])).unwrap();
        let q = g.query(&[0.5, 0.5]).unwrap();
        assert_eq!(q.adjust(), Adjust::Projected);
        assert_eq!(q.params(), &[3.0, 0.5]);
        let g = Grid::new(&[axis(0.0, 1.0, 5), axis(0.0, 1.0, 2)], Some(&[0])).unwrap();
        assert_eq!(g.query(&[0.5, 0.5]).err(), Some(GridError::NoValidCell));
    }

    #[test]
    fn limiter() {
        let mut l = ParamLimiter::new(&[1.0, 2.0], &[0.0, 4.0]);
        assert_eq!(l.update(&[0.0, 0.5], 0.1), &[0.0, 0.5]);
        assert_eq!(l.update(&[10.0, 3.5], 0.1), &[0.1, 0.3]);
        let s = l.update(&[f32::NAN, 3.5], 0.1);
        assert!((s[0] - 0.1).abs() < 1e-6 && (s[1] - 0.1).abs() < 1e-6);
        // Wraps the short way and stays within the period.
        let s = l.update(&[0.0, 3.9], 0.1);
        assert!((s[1] - 3.9).abs() < 1e-6, "{s:?}");
        l.reset();
        assert_eq!(l.update(&[5.0, 1.0], 0.1), &[5.0, 1.0]);
    }
}
