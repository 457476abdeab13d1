//! The synthesis's work, counted by the synthesis itself.
//!
//! The live loop's deadline ([`crate::deadline`]) gives the solver what the
//! frame period leaves after everything else a frame does, and the
//! synthesis is the part of that whose length depends on the table: a
//! query's window (2 samples along a linear axis, 4 along a Catmull-Rom
//! one, so 8 to 256 samples for one to four axes) is read and blended for
//! every segment, and a query outside the table's valid cells scans the
//! cells for the nearest one. So a [`Query`](super::Query) counts its own
//! work ([`Query::work`](super::Query::work)) as the solver does
//! ([`crate::solve::cost`]): in instructions of the firmware's Cortex-M4F
//! build, as a pure function of the grid's shape, the window and the steps
//! the projection took, so the board, the emulated board and the host's
//! native replay count the same.
//!
//! ```text
//! work = QUERY_BASE + QUERY_PER_AXIS × axes
//!      + projection, if it took one: PROJECT_BASE
//!        + PROJECT_PER_DISTANCE × the per-axis distances it caches
//!        + PROJECT_PER_ROW × rows it came to
//!        + PROJECT_PER_CELL × cells it looked at
//!        + PROJECT_PER_VALID × valid cells among them
//!        (+ PROJECT_PER_DISTANCE per row or scanned cell whose distance
//!         is beyond its cache, on an axis of more than 16 cells)
//!      + pose, three linear axes (the unrolled tree):
//!          TRILINEAR_BASE + TRILINEAR_PER_SEGMENT × segments
//!        any other grid (the general tree):
//!          GENERAL_BASE + (GENERAL_PER_QUAD × quads
//!                          + GENERAL_PER_PAIR × pairs) × segments
//! ```
//!
//! The general tree reduces the window axis by axis, axis 0 first: along a
//! linear axis each pair of samples to one (a slerp), along a Catmull-Rom
//! axis each four to one (the cubic's three slerps and their tangents), so
//! for widths `w₀, w₁, …` axis `a` takes `w_{a+1} × w_{a+2} × …`
//! reductions of its kind. The samples read are folded into these (a
//! window of `w` samples takes `w − 1` samples' worth of reductions: three
//! per quad, one per pair).
//!
//! The coefficients are upper bounds of the instructions measured on the
//! emulated board, fitted with the deadline's reserve
//! ([`crate::deadline`]): `tests/realtime.rs` replays sessions on tables of
//! each kind (the shipped trilinear grid, a finer one whose projections
//! scan many cells, a two-axis one on the general tree, one with a
//! Catmull-Rom axis, and two layers) and checks that on every frame the
//! count and the reserve bound everything but the solver. The split
//! between the trilinear tree's coefficients and the reserve's
//! per-segment part is a fit, not a profile: only their sum is checked
//! (a profile puts more of a frame in the tree, decoding the table's
//! samples included, than `TRILINEAR_PER_SEGMENT` says, and less in the
//! rest); the general tree's are fitted against the same reserve, so a
//! table's count is right relative to the shipped one's.

use super::Grid;

/// Locating a query besides its axes, and building it.
pub const QUERY_BASE: u32 = 600;
/// Locating and building one axis of a query (with a Catmull-Rom axis's
/// neighbour checks).
pub const QUERY_PER_AXIS: u32 = 260;
/// A projection's fixed part (with what a frame that took one costs
/// besides, in the query and the stages after it).
pub const PROJECT_BASE: u32 = 4_850;
/// One distance from the query to a cell along one axis.
pub const PROJECT_PER_DISTANCE: u32 = 15;
/// One row of cells along axis 0 the projection came to: turning the
/// odometer of the other axes, bounding the row, starting its walk.
pub const PROJECT_PER_ROW: u32 = 290;
/// One cell of a row the projection looked at: the next of its walk, its
/// distance and its mask bit.
pub const PROJECT_PER_CELL: u32 = 40;
/// One valid cell among them: the comparison with the best so far.
pub const PROJECT_PER_VALID: u32 = 400;
/// The unrolled trilinear tree's fixed part (its coefficients).
pub const TRILINEAR_BASE: u32 = 1_900;
/// The unrolled trilinear tree per segment (eight samples read, decoded
/// and blended).
pub const TRILINEAR_PER_SEGMENT: u32 = 490;
/// The general tree's fixed part (the window and its coefficients).
pub const GENERAL_BASE: u32 = 600;
/// One Catmull-Rom reduction of the general tree, per segment: four
/// samples read and decoded, blended to one.
pub const GENERAL_PER_QUAD: u32 = 960;
/// One linear reduction of the general tree, per segment: two samples
/// read and decoded, blended to one.
pub const GENERAL_PER_PAIR: u32 = 100;

/// Cells per axis whose distances a projection works out once
/// (`PROJECT_CACHE` of the query's module).
pub(super) const CACHED: u32 = 16;

/// The work of posing `segments` segments from a window whose axes are
/// `widths` samples wide (2 linear, 4 Catmull-Rom; axis 0 first).
#[must_use]
pub(super) fn pose(widths: &[usize], segments: usize) -> u32 {
    let segments = segments as u32;
    if let [2, 2, 2] = widths {
        return TRILINEAR_BASE.saturating_add(segments.saturating_mul(TRILINEAR_PER_SEGMENT));
    }
    let mut per = 0u32;
    for (a, &w) in widths.iter().enumerate() {
        let later = widths.get(a + 1..).unwrap_or(&[]);
        let groups = later.iter().fold(1u32, |n, &l| n.saturating_mul(l as u32));
        let each = if w == 4 {
            GENERAL_PER_QUAD
        } else {
            GENERAL_PER_PAIR
        };
        per = per.saturating_add(groups.saturating_mul(each));
    }
    GENERAL_BASE.saturating_add(segments.saturating_mul(per))
}

/// The work of locating a query on `axes` axes (without a projection).
#[must_use]
pub(super) const fn locate(axes: usize) -> u32 {
    QUERY_BASE.saturating_add((axes as u32).saturating_mul(QUERY_PER_AXIS))
}

/// What a projection scanned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Scan {
    /// Rows of cells along axis 0 it came to (scanned or bounded out).
    pub(super) rows: u32,
    /// Cells of those rows it looked at.
    pub(super) cells: u32,
    /// Valid cells among them (each a comparison with the best).
    pub(super) valid: u32,
}

/// The work of a projection on `grid` that scanned `scan`.
#[must_use]
pub(super) fn project(grid: &Grid<'_>, scan: Scan) -> u32 {
    let axes = grid.axes();
    let wide = |a: &super::Axis| a.cells() > CACHED;
    let cached: u32 = axes.iter().map(|a| a.cells().min(CACHED)).sum();
    let per_row = if axes.iter().skip(1).any(wide) {
        PROJECT_PER_ROW + PROJECT_PER_DISTANCE
    } else {
        PROJECT_PER_ROW
    };
    let per_cell = if axes.first().is_some_and(wide) {
        PROJECT_PER_CELL + PROJECT_PER_DISTANCE
    } else {
        PROJECT_PER_CELL
    };
    PROJECT_BASE
        .saturating_add(cached.saturating_mul(PROJECT_PER_DISTANCE))
        .saturating_add(scan.rows.saturating_mul(per_row))
        .saturating_add(scan.cells.saturating_mul(per_cell))
        .saturating_add(scan.valid.saturating_mul(PROJECT_PER_VALID))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_general_tree_counts_its_reductions_axis_by_axis() {
        let (q, p) = (GENERAL_PER_QUAD, GENERAL_PER_PAIR);
        let general = |per: u32| GENERAL_BASE + 13 * per;
        // Counted by hand: axis 0 reduces the whole window, each later
        // axis what the earlier ones left.
        assert_eq!(pose(&[2, 2], 13), general(2 * p + p));
        assert_eq!(pose(&[4, 2], 13), general(2 * q + p));
        assert_eq!(pose(&[2, 4], 13), general(4 * p + q));
        assert_eq!(pose(&[4, 2, 2], 13), general(4 * q + 2 * p + p));
        assert_eq!(pose(&[4, 4, 4], 13), general(16 * q + 4 * q + q));
        assert_eq!(pose(&[2, 2, 2, 2], 13), general(8 * p + 4 * p + 2 * p + p));
        assert_eq!(pose(&[4], 13), general(q));
        // Three linear axes take the unrolled tree.
        assert_eq!(
            pose(&[2, 2, 2], 13),
            TRILINEAR_BASE + 13 * TRILINEAR_PER_SEGMENT
        );
        // Nothing wraps.
        assert_eq!(pose(&[4, 4, 4, 4], usize::MAX), u32::MAX);
    }
}
