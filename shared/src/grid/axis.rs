//! Grid axes: where the samples lie along each parameter, how the axis
//! continues past its ends, how it interpolates, and how a parameter value
//! is located in a cell.
//!
//! [`Wrap`] and [`Interp`] are the one vocabulary of the grid and the table
//! header (the blob stores them as they are, see [`crate::table`]).

use serde::{Deserialize, Serialize};

use crate::math;

/// How an axis continues past its ends.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Wrap {
    /// `count` samples from `min` to `min + (count − 1)·step`; outside, clamp.
    Bounded,
    /// Periodic with `period = count·step` (checked to 1e-5 relative); the
    /// sample after the last is the first.
    Cyclic {
        /// The period in parameter units.
        period: f32,
    },
}

/// Interpolation along an axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Interp {
    /// Lerp / slerp between the two samples around the parameter.
    Linear,
    /// Catmull-Rom over four samples (see the module doc).
    CatmullRom,
}

/// A stored axis that is not usable (see [`Axis::is_valid`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct InvalidAxis;

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
    pub wrap: Wrap,
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
            wrap: Wrap::Bounded,
            interp: Interp::Linear,
        }
    }

    /// Number of cells (`count − 1` bounded, `count` cyclic).
    #[must_use]
    pub fn cells(&self) -> u32 {
        match self.wrap {
            Wrap::Bounded => self.count.saturating_sub(1),
            Wrap::Cyclic { .. } => self.count,
        }
    }

    /// Samples along the axis in an interpolation window (2 linear, 4
    /// Catmull-Rom).
    pub(super) fn window(&self) -> usize {
        match self.interp {
            Interp::Linear => 2,
            Interp::CatmullRom => 4,
        }
    }
}

/// Where a query landed along one axis.
#[derive(Clone, Copy, Debug)]
pub(super) struct Located {
    /// Cell index along the axis.
    pub(super) cell: u32,
    /// Position inside the cell, `[0, 1]`.
    pub(super) t: f32,
}

impl Axis {
    /// Whether the axis is usable: `count ≥ 2`, finite `min`, finite
    /// `step > 0`, and for a cyclic axis `period = count · step` to 1e-5
    /// relative.
    #[must_use]
    pub fn is_valid(&self) -> bool {
        let ok =
            self.count >= 2 && self.min.is_finite() && self.step.is_finite() && self.step > 0.0;
        let period_ok = match self.wrap {
            Wrap::Bounded => true,
            Wrap::Cyclic { period } => {
                let expect = self.count as f32 * self.step;
                math::abs(period - expect) <= 1e-5 * expect
            }
        };
        ok && period_ok
    }
}

/// Parameter in cell units along the axis (wrapped or clamped), and whether
/// it was clamped.
pub(super) fn to_cell_units(axis: &Axis, inv_step: f32, p: f32) -> (f32, bool) {
    let u = (p - axis.min) * inv_step;
    let n = axis.count as f32;
    // Rounding of p = min + i·step and of the line above is below
    // ε·(|min|/step + 2|u|) cells; snap within four times that.
    let tol = 4.0 * f32::EPSILON * (1.0 + math::abs(u) + math::abs(axis.min) * inv_step);
    match axis.wrap {
        Wrap::Bounded => {
            // max/min, not clamp: clamp asserts lo <= hi, a panic path.
            let c = snap(u.max(0.0).min(n - 1.0), tol);
            (c, math::abs(c - u) > tol)
        }
        Wrap::Cyclic { .. } => {
            let w = u - n * math::floor(u / n);
            // Not `w >= n || w < 0`: a huge parameter makes `u` infinite and
            // `w` NaN, which must wrap to 0 too (a NaN weight is a NaN pose).
            let w = snap(if (0.0..n).contains(&w) { w } else { 0.0 }, tol);
            (if w >= n { 0.0 } else { w }, false)
        }
    }
}

/// Snaps `u` to the nearest integer when within `tol`.
pub(super) fn snap(u: f32, tol: f32) -> f32 {
    let r = math::floor(u + 0.5);
    if math::abs(u - r) <= tol { r } else { u }
}

/// Cell and in-cell coordinate for `u` (cell units, already in range).
pub(super) fn locate(axis: &Axis, u: f32) -> Located {
    let cells = axis.cells();
    let k = math::floor(u);
    // Saturating float→int; the last sample of a bounded axis is t = 1 of the last cell.
    let mut cell = k as u32;
    let mut t = u - k;
    if cell >= cells {
        match axis.wrap {
            Wrap::Bounded => {
                cell = cells.saturating_sub(1);
                t = u - cell as f32;
            }
            Wrap::Cyclic { .. } => {
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
pub(super) fn nearest_in_cell(axis: &Axis, u: f32, k: u32) -> (f32, f32) {
    let lo = k as f32;
    let one = |v: f32| {
        let c = v.max(lo).min(lo + 1.0);
        (math::abs(v - c), c - lo)
    };
    match axis.wrap {
        Wrap::Bounded => one(u),
        Wrap::Cyclic { .. } => {
            let n = axis.count as f32;
            let (a, b, c) = (one(u), one(u - n), one(u + n));
            let best = if b.0 < a.0 { b } else { a };
            if c.0 < best.0 { c } else { best }
        }
    }
}

/// The parameter value a located query stands for.
pub(super) fn axis_param(axis: &Axis, l: &Located) -> f32 {
    let v = axis.min + (l.cell as f32 + l.t) * axis.step;
    match axis.wrap {
        Wrap::Cyclic { period } if v >= axis.min + period => v - period,
        _ => v,
    }
}
