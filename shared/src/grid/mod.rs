//! Static interpolation synthesis on a regular grid (Wiley & Hahn 1997).
//!
//! # Grid
//!
//! A grid has 1 to [`MAX_AXES`] parameter axes (for example hand position
//! x, y, z, or the cylindrical coordinates of a pedalling foot). Axis `a` has
//! `count` samples at `min + i·step`, `i = 0..count`. A [`Wrap::Bounded`]
//! axis has `count − 1` cells and ends at `min + (count − 1)·step`; a
//! [`Wrap::Cyclic`] axis wraps with `period = count·step` (sample `count`
//! is sample 0 again) and has `count` cells.
//!
//! # Samples and their layout
//!
//! Every grid point holds a [`Pose`](crate::pose::Pose)-like sample (a position and a rotation per
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
//! coefficients with the fast-slerp polynomial folded, see [`SlerpWeight`](crate::math::SlerpWeight))
//! and applies it to every segment; [`Query::segment`] does one segment.
//!
//! # The interpolation tree
//!
//! With `p` linear axes the window has `2^p` samples and the result is the
//! W&H binary tree of `2^p − 1` interpolations: all pairs along axis 0 first
//! (coefficient `u = (t − l)/(h − l)`), then the results along axis 1, and so
//! on. Rotations use the core's fast slerp ([`crate::math::slerp`]) along the
//! shortest arc. Positions are linear in the samples, so the same tree is
//! evaluated as one weighted sum with the products of the per-axis weights
//! (identical in exact arithmetic); at grid points the weights are exactly 0
//! and 1, so samples come back bit for bit.
//!
//! **Bound** (checked by `tests/synth.rs` against a slow `f64` tree with
//! exact slerp, inside cells and on their faces, edges and corners): every
//! synthesized position within 1e-5 m and every rotation within 5e-5 rad of
//! the exact tree over the same `f32` samples, for neighbouring samples up
//! to 2.4 rad apart. Three linear axes (the W&H hand grid) take an unrolled
//! tree (`grid/trilinear.rs`); every other grid the general one
//! (`grid/general.rs`).
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
//!   `slerp(P1, reflect(P2, P1), 1−s)` (see [`crate::math::reflect`]), so every fast
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

mod axis;
pub mod cost;
mod general;
mod lanes;
mod query;
mod samples;
mod trilinear;

pub use axis::{Axis, Interp, InvalidAxis, Wrap};
pub use query::{Query, Window};
pub use samples::{Samples, SliceSamples};

/// Most axes a grid may have.
pub const MAX_AXES: usize = 6;
/// Most samples in one interpolation window (a linear axis contributes a
/// factor 2, a Catmull-Rom axis 4): up to six linear axes, one Catmull-Rom
/// axis with four linear ones, two with two, or three Catmull-Rom axes. (Kept
/// small: the query and the rotation scratch are sized by it.)
pub const MAX_WINDOW: usize = 64;

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
            if !axis.is_valid() {
                return Err(GridError::BadAxis { axis: i as u8 });
            }
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

    /// The work of a query inside the table's valid cells and of posing
    /// `segments` segments from it ([`Query::work`] without a
    /// projection): every such query's, whatever its parameters.
    #[must_use]
    pub fn plain_work(&self, segments: usize) -> u32 {
        let axes = self.axes();
        let mut widths = [0usize; MAX_AXES];
        for (w, a) in widths.iter_mut().zip(axes) {
            *w = if a.interp == Interp::Linear { 2 } else { 4 };
        }
        let widths = widths.get(..axes.len()).unwrap_or(&[]);
        cost::locate(axes.len()).saturating_add(cost::pose(widths, segments))
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
            wrap: Wrap::Cyclic { period: 1.0 },
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
            wrap: Wrap::Cyclic { period: 2.0 },
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
}
