//! Locating a query (cell by division, clamping, wrapping, snapping,
//! projection out of invalid cells) and the [`Query`] it produces: per axis
//! the window samples, their position weights and the in-cell coordinate.
//! [`Query::pose`] hands the window to the unrolled trilinear tree
//! (`trilinear.rs`) or the general tree (`general.rs`).

use glam::{Quat, Vec3};

use super::axis::{Interp, Located, Wrap, axis_param, locate, nearest_in_cell, to_cell_units};
use super::cost;
use super::general::{AxisWeights, Cubic, Plan, cubic_position_weights};
use super::lanes::WIDE;
use super::trilinear::Trilinear;
use super::{Adjust, Axis, Grid, GridError, MAX_AXES, MAX_WINDOW, Samples};
use crate::math::{self, SlerpWeight};
use crate::pose::Pose;

/// Cells per axis whose distances [`Grid::project`] works out once per
/// projection.
const PROJECT_CACHE: usize = cost::CACHED as usize;

/// How one axis of a located query interpolates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Shape {
    /// Two samples: lerp / slerp.
    Linear,
    /// Four samples: Catmull-Rom, with `P−1` / `P2` replaced by linear
    /// phantoms where the flags say so.
    Cubic { lo_phantom: bool, hi_phantom: bool },
}

/// One axis of a located query.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct AxisQuery {
    /// The window samples along the axis, in window order, as sample-index
    /// offsets (index along the axis times the axis' sample stride).
    pub(super) offset: [u32; 4],
    /// Position weights of those samples.
    pub(super) weight: [f32; 4],
    /// Position inside the cell, `[0, 1]`.
    pub(super) t: f32,
    pub(super) shape: Shape,
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
    pub(super) fn width(&self) -> usize {
        match self.shape {
            Shape::Linear => 2,
            Shape::Cubic { .. } => 4,
        }
    }

    /// The rotation coefficients (polynomials folded, see [`SlerpWeight`]).
    pub(super) fn rotation_weights(&self) -> AxisWeights {
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
    /// The work of its projection ([`cost::project`]), 0 without one.
    projected: u32,
}

/// The window of a query: the indices of its samples (axis 0 fastest) and
/// their position weights (the tensor product of the axis weights).
#[derive(Clone, Copy, Debug)]
pub struct Window {
    index: [u32; MAX_WINDOW],
    weight: [f32; MAX_WINDOW],
    pub(super) len: usize,
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

impl<'a> Grid<'a> {
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
        let mut projected = 0;
        if !self.cell_valid(self.cell_index(&loc) as usize) {
            let (moved, d2, scanned) = self.project(&u)?;
            loc = moved;
            projected = cost::project(self, scanned);
            // On the boundary of a valid cell: not a projection.
            if d2 > 0.0 {
                adjust = Adjust::Projected;
            }
        }
        self.build_query(&loc, adjust, q);
        q.projected = projected;
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

    /// Nearest point of the nearest valid cell to `u` (cell units): the
    /// first valid cell, in index order, at the least squared distance.
    ///
    /// The distance to a cell is a sum over the axes, so each axis's
    /// squared distance to each of its cells is worked out once (for its
    /// first [`PROJECT_CACHE`] cells; beyond, when needed). The search is
    /// branch and bound: every axis is walked from the query's own cell
    /// outwards, nearest cell first ([`Outward`]), axis 0 as rows inside
    /// an odometer of the others, and a branch stops as soon as its axes
    /// alone are farther than the best valid cell so far (every later cell
    /// of that axis is farther still). Its bounds are sums in the same
    /// order as a cell's distance (`0 + d₀² + d₁² + …`) with the inner
    /// terms left out, which round no higher than the distance of any
    /// cell under them, and it prunes only what is strictly farther, so it
    /// finds the same cell as a scan of every cell in index order (tested
    /// against one), in the few rows around the query instead of all of
    /// them. A projection runs on every frame whose parameters leave the
    /// table's data. Also returns what it scanned (for its work,
    /// [`cost::project`]). Not inlined: it runs only off the table's
    /// data, and kept apart it costs the query nothing on other frames.
    #[inline(never)]
    fn project(
        &self,
        u: &[f32; MAX_AXES],
    ) -> Result<([Located; MAX_AXES], f32, cost::Scan), GridError> {
        let axes = self.axes();
        let along = |a: usize, k: u32| match (axes.get(a), u.get(a)) {
            (Some(axis), Some(&ui)) => {
                let (d, _) = nearest_in_cell(axis, ui, k);
                d * d
            }
            _ => 0.0,
        };
        let mut cache = [[0.0f32; PROJECT_CACHE]; MAX_AXES];
        for ((a, row), axis) in cache.iter_mut().enumerate().zip(axes) {
            for (k, d) in row.iter_mut().enumerate().take(axis.cells() as usize) {
                *d = along(a, k as u32);
            }
        }
        let at = |a: usize, k: u32| match cache.get(a).and_then(|row| row.get(k as usize)) {
            Some(&d) => d,
            None => along(a, k),
        };
        let used = self.axis_count.min(MAX_AXES);
        let outward = |a: usize| match (axes.get(a), u.get(a)) {
            (Some(axis), Some(&ui)) => Outward::new(axis, ui),
            _ => Outward::EMPTY,
        };
        // The odometer of axes 1..: each axis's walk, its cell and that
        // cell's squared distance.
        let mut walk = [Outward::EMPTY; MAX_AXES];
        let mut digit = [0u32; MAX_AXES];
        let mut sq = [0.0f32; MAX_AXES];
        for a in 1..used {
            let (w, k, s) = (walk.get_mut(a), digit.get_mut(a), sq.get_mut(a));
            if let (Some(w), Some(k), Some(s)) = (w, k, s) {
                *w = outward(a);
                *k = w.next(|c| at(a, c)).unwrap_or(0);
                *s = at(a, *k);
            }
        }
        let mut best: Option<(f32, u32)> = None;
        let farther = |best: Option<(f32, u32)>, d: f32| best.is_some_and(|(bd, _)| d > bd);
        let mut scan = cost::Scan {
            rows: 0,
            cells: 0,
            valid: 0,
        };
        loop {
            scan.rows = scan.rows.saturating_add(1);
            let outer = sq.get(1..used).unwrap_or(&[]);
            // The row's other axes alone (the bound of every cell in it).
            let floor = outer.iter().fold(0.0f32, |acc, s| acc + s);
            if !farther(best, floor) {
                let base = self.cell_index_of(&digit);
                let mut row = outward(0);
                while let Some(k) = row.next(|c| at(0, c)) {
                    // The same sum, in the same order, as the distance's
                    // definition: 0 + d₀² + d₁² + …
                    let d2 = outer.iter().fold(0.0f32 + at(0, k), |acc, s| acc + s);
                    if farther(best, d2) {
                        break;
                    }
                    scan.cells = scan.cells.saturating_add(1);
                    let c = base.wrapping_add(k);
                    if !self.cell_valid(c as usize) {
                        continue;
                    }
                    scan.valid = scan.valid.saturating_add(1);
                    if best.is_none_or(|(bd, bc)| d2 < bd || (d2 == bd && c < bc)) {
                        best = Some((d2, c));
                    }
                }
            }
            if !self.next_row(&mut (&mut walk, &mut digit, &mut sq), best, &at, &outward) {
                break;
            }
        }
        let (d2, c) = best.ok_or(GridError::NoValidCell)?;
        let mut loc = [Located { cell: 0, t: 0.0 }; MAX_AXES];
        let mut rest = c;
        for ((l, axis), &ui) in loc.iter_mut().zip(axes).zip(u) {
            let n = axis.cells();
            let k = rest.checked_rem(n).unwrap_or(0);
            rest = rest.checked_div(n).unwrap_or(0);
            let (_, t) = nearest_in_cell(axis, ui, k);
            *l = Located { cell: k, t };
        }
        Ok((loc, d2, scan))
    }

    /// The index of the cell at `digit` along each axis (axis 0's digit
    /// ignored: the first cell of its row).
    fn cell_index_of(&self, digit: &[u32; MAX_AXES]) -> u32 {
        digit
            .iter()
            .zip(&self.cell_stride)
            .take(self.axis_count)
            .skip(1)
            .fold(0u32, |acc, (&k, &s)| acc.wrapping_add(k.wrapping_mul(s)))
    }

    /// Turns the odometer of [`Grid::project`] to its next row: the first
    /// axis after axis 0 whose walk has a next cell not strictly farther
    /// than `best` (with its own cell and the axes above it) takes it, and
    /// the axes below it walk again from their nearest cell. False when
    /// every axis is done.
    #[inline(always)]
    fn next_row(
        &self,
        (walk, digit, sq): &mut Odometer<'_>,
        best: Option<(f32, u32)>,
        at: &impl Fn(usize, u32) -> f32,
        outward: &impl Fn(usize) -> Outward,
    ) -> bool {
        let used = self.axis_count.min(MAX_AXES);
        for a in 1..used {
            let Some(w) = walk.get_mut(a) else {
                return false;
            };
            if let Some(k) = w.next(|c| at(a, c)) {
                let s = at(a, k);
                let above = sq.get(a + 1..used).unwrap_or(&[]);
                let bound = above.iter().fold(0.0f32 + s, |acc, x| acc + x);
                if best.is_some_and(|(bd, _)| bound > bd) {
                    // Every later cell of this axis is farther still: on
                    // to the next axis.
                    continue;
                }
                if let (Some(dk), Some(ds)) = (digit.get_mut(a), sq.get_mut(a)) {
                    *dk = k;
                    *ds = s;
                }
                for b in 1..a {
                    if let (Some(wb), Some(dk), Some(ds)) =
                        (walk.get_mut(b), digit.get_mut(b), sq.get_mut(b))
                    {
                        *wb = outward(b);
                        *dk = wb.next(|c| at(b, c)).unwrap_or(0);
                        *ds = at(b, *dk);
                    }
                }
                return true;
            }
        }
        false
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
        let cyclic = matches!(axis.wrap, Wrap::Cyclic { .. });
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

/// The odometer of [`Grid::project`]: per axis its walk, its cell and
/// that cell's squared distance.
type Odometer<'o> = (
    &'o mut [Outward; MAX_AXES],
    &'o mut [u32; MAX_AXES],
    &'o mut [f32; MAX_AXES],
);

/// The cells of one axis nearest first: the query's own cell, then the
/// nearer of the next cells below and above it (wrapping on a cyclic
/// axis), so their distances never decrease (a cell's distance grows with
/// its step from the query's cell, on a cyclic axis up to halfway round,
/// where the two sides meet).
#[derive(Clone, Copy, Debug)]
struct Outward {
    /// The last cell taken below (or the start).
    down: u32,
    /// The last cell taken above (or the start).
    up: u32,
    /// Cells not yet taken.
    left: u32,
    /// The axis's cells.
    cells: u32,
    cyclic: bool,
    started: bool,
}

impl Outward {
    /// A walk of no cells.
    const EMPTY: Self = Outward {
        down: 0,
        up: 0,
        left: 0,
        cells: 0,
        cyclic: false,
        started: false,
    };

    /// The walk of `axis` from the cell nearest `u` (cell units; on a
    /// cyclic axis any turn of it).
    fn new(axis: &Axis, u: f32) -> Self {
        let cyclic = matches!(axis.wrap, Wrap::Cyclic { .. });
        let n = axis.cells() as f32;
        let on_axis = if cyclic {
            u - math::floor(u / n) * n
        } else {
            u
        };
        let start = locate(axis, on_axis).cell;
        Outward {
            down: start,
            up: start,
            left: axis.cells(),
            cells: axis.cells(),
            cyclic,
            started: false,
        }
    }

    /// The next cell, given each cell's distance.
    fn next(&mut self, dist: impl Fn(u32) -> f32) -> Option<u32> {
        self.left = self.left.checked_sub(1)?;
        if !self.started {
            self.started = true;
            return Some(self.down);
        }
        let below = match (self.down, self.cyclic) {
            (0, false) => None,
            (0, true) => Some(self.cells.saturating_sub(1)),
            (d, _) => Some(d - 1),
        };
        let above = match self.up.checked_add(1) {
            Some(n) if n < self.cells => Some(n),
            _ if self.cyclic => Some(0),
            _ => None,
        };
        match (below, above) {
            (Some(b), Some(a)) if dist(a) < dist(b) => {
                self.up = a;
                Some(a)
            }
            (Some(b), _) => {
                self.down = b;
                Some(b)
            }
            (None, Some(a)) => {
                self.up = a;
                Some(a)
            }
            (None, None) => None,
        }
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
            projected: 0,
        }
    }
}

impl Query {
    /// The work of this query and of posing `segments` segments from it,
    /// in instructions of the firmware's Cortex-M4F build by the
    /// synthesis's cost model ([`cost`](super::cost)): locating it, the
    /// projection it took if any, and its window read and blended for
    /// every segment.
    #[must_use]
    pub fn work(&self, segments: usize) -> u32 {
        let mut widths = [0usize; MAX_AXES];
        for (w, a) in widths.iter_mut().zip(self.used_axes()) {
            *w = a.width();
        }
        let widths = widths.get(..self.axis_count).unwrap_or(&[]);
        let pose = cost::pose(widths, segments);
        cost::locate(self.axis_count)
            .saturating_add(self.projected)
            .saturating_add(pose)
    }

    /// The work of the projection the query took, 0 if it took none: its
    /// [`Query::work`] less its grid's [`Grid::plain_work`].
    #[must_use]
    pub fn projection_work(&self) -> u32 {
        self.projected
    }

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
    /// ([`crate::math::renormalize_lanes`]); other grids reduce the window axis by
    /// axis with normalized slerps. On targets with SIMD (the host) segments
    /// are processed in blocks: the window read sample by sample (a run of
    /// segments at once from [`Samples::row`]), positions weighed 12 floats
    /// at a time, the slerps of four segments running as [`crate::math::F4`] lanes
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The projection as first written, a division per axis per cell: the
    /// slow obvious reference of [`Grid::project`]'s odometer.
    fn project_slow(g: &Grid<'_>, u: &[f32; MAX_AXES]) -> Option<(u32, [u32; MAX_AXES], f32)> {
        let mut best: Option<(f32, u32)> = None;
        for c in 0..g.cells {
            if !g.cell_valid(c as usize) {
                continue;
            }
            let mut d2 = 0.0f32;
            let mut rest = c;
            for (axis, &ui) in g.axes().iter().zip(u) {
                let n = axis.cells();
                let (d, _) = nearest_in_cell(axis, ui, rest % n);
                rest /= n;
                d2 += d * d;
            }
            if best.is_none_or(|(bd, _)| d2 < bd) {
                best = Some((d2, c));
            }
        }
        let (d2, c) = best?;
        let mut cells = [0u32; MAX_AXES];
        let mut rest = c;
        for (k, axis) in cells.iter_mut().zip(g.axes()) {
            *k = rest % axis.cells();
            rest /= axis.cells();
        }
        Some((c, cells, d2))
    }

    #[test]
    fn the_projection_finds_the_cell_a_scan_of_every_cell_finds() {
        let mut h = 0x1234_5678u32;
        let mut next = move || {
            h = h.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            h >> 8
        };
        let mut projected = 0;
        for case in 0..4000 {
            let axis_count = 1 + (next() % 4) as usize;
            let mut axes = [Axis::linear(0.0, 1.0, 2); 4];
            for a in axes.iter_mut().take(axis_count) {
                // Now and then an axis longer than the distance cache.
                a.count = if axis_count <= 2 && next() % 3 == 0 {
                    2 + next() % 39
                } else {
                    2 + next() % 5
                };
                if next() % 4 == 0 {
                    a.wrap = Wrap::Cyclic {
                        period: a.count as f32,
                    };
                }
            }
            // Sparse masks (about one cell in five valid, or in fifty),
            // some empty.
            let sparse = if next() % 2 == 0 { 5 } else { 50 };
            let mask: [u8; 256] = core::array::from_fn(|_| {
                (0..8).fold(0u8, |m, b| m | (u8::from(next() % sparse == 0) << b))
            });
            let g = Grid::new(&axes[..axis_count], Some(&mask)).unwrap();
            let mut u = [0.0f32; MAX_AXES];
            for (ui, axis) in u.iter_mut().zip(g.axes()) {
                // Anywhere from a cell before the axis to one after it,
                // now and then on a sample (ties between cells).
                *ui = (next() % 10_000) as f32 / 10_000.0 * (axis.count as f32 + 2.0) - 1.0;
                if next() % 4 == 0 {
                    *ui = math::floor(*ui);
                }
            }
            let fast = g.project(&u).ok().map(|(l, d, _)| (l, d));
            // A query's count is its grid's plain work and its
            // projection's, which is none without a mask.
            let mut params = [0.0f32; MAX_AXES];
            for ((p, &ui), axis) in params.iter_mut().zip(&u).zip(g.axes()) {
                *p = axis.min + ui * axis.step;
            }
            let params = &params[..axis_count];
            if let Ok(q) = g.query(params) {
                assert_eq!(q.work(13), g.plain_work(13) + q.projection_work());
            }
            let open = Grid::new(&axes[..axis_count], None).unwrap();
            let q = open.query(params).unwrap();
            assert_eq!(q.projection_work(), 0);
            assert_eq!(q.work(13), open.plain_work(13));
            let slow = project_slow(&g, &u);
            match (fast, slow) {
                (None, None) => {}
                (Some((loc, d2)), Some((c, cells, slow_d2))) => {
                    projected += 1;
                    assert_eq!(d2.to_bits(), slow_d2.to_bits(), "case {case}: cell {c}");
                    for (l, k) in loc.iter().zip(cells).take(axis_count) {
                        assert_eq!(l.cell, k, "case {case}");
                    }
                }
                (f, s) => panic!("case {case}: {f:?} against {s:?}"),
            }
        }
        assert!(projected > 2500, "{projected}");
    }
}
