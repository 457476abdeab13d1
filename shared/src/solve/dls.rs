//! Damped least squares: a chain solver for the balancing methods, and the
//! whole-tree weighted solver [`Method::TreeDls`](super::Method::TreeDls).
//!
//! ## Whole tree
//!
//! Minimises `E(θ) = Σ wᵢ·|rᵢ(θ)|²` over the reach tree's joint angles (and the
//! root translation in [`RootMode::Float`]) with Levenberg–Marquardt steps in the
//! `J·Jᵀ` form: rows are scaled by `√(wᵢ / w_max)`, and each step solves
//!
//! ```text
//! (J̃·J̃ᵀ + λ²·I)·y = r̃,   Δθ = J̃ᵀ·y
//! ```
//!
//! by Cholesky on an `m × m` system, `m` = 3 per point or orientation goal and 1
//! per plane goal (at most [`MAX_ROWS`]): for a handful of goals this is far
//! smaller than the number of joints. A column of `J` is `ω × (x − p)` for a
//! rotational DOF with world axis `ω` and pivot `p`, for every goal whose segment
//! it moves; `ω` for orientation rows; minus the same terms for goals given in
//! the frame of a segment the DOF also moves.
//!
//! Joint limits: the step is clamped into the limits (a projected step), and a
//! DOF that sits on a limit while the gradient pushes it outwards is left out of
//! the next linearisation (an active set), so the other joints take over.
//!
//! A step that does not lower `E` is undone and the damping raised ×4; a step
//! that does lowers it ÷3. The solve stops when every goal is within
//! `tolerance`, when `E` stops decreasing, or at the iteration cap.

use super::ccd::world_axes;
use super::{Chain, ReachTree, RootMode, SolveError, Solver, Work};
use crate::goal::{Frame, Goal, PlaneSide, Residual, Target};
use crate::math;
use crate::pose::MAX_SEGMENTS;
use glam::Vec3;

/// The most least-squares rows (3 per point or orientation goal, 1 per plane
/// goal) that [`Method::TreeDls`](super::Method::TreeDls) solves at once.
pub const MAX_ROWS: usize = 30;
/// The most variables: every DOF of [`MAX_SEGMENTS`] segments plus translation.
const MAX_VARS: usize = 3 * MAX_SEGMENTS + 3;
/// The largest rotation (rad) or translation (m) of one step.
const MAX_STEP: f32 = 0.5;
/// Marker for a translation variable.
const TRANSLATION: u8 = u8::MAX;

/// Damped least squares on one chain: moves the touch point of `end` towards
/// `target` in `solver.chain_iterations` steps.
pub(super) fn solve_chain<const N: usize>(
    solver: &Solver,
    work: &mut Work<'_, '_, N>,
    chain: &Chain<N>,
    end: usize,
    target: Vec3,
) -> Result<(), SolveError> {
    let lambda2 = solver.damping * solver.damping;
    let tol2 = solver.tolerance * solver.tolerance;
    for _ in 0..solver.chain_iterations.max(1) {
        let e = work.touch(end);
        let r = target - e;
        if r.length_squared() <= tol2 {
            break;
        }
        // Columns c = ω × (e − p) of the free DOFs, their inverse damping
        // 1/D = 1/(λ²·|c|² + tension), and A = Σ c·cᵀ/D + I.
        let mut cols = [[(Vec3::ZERO, 0.0f32); 3]; N];
        let mut a = [[0.0f32; 3]; 3];
        for (seg, col) in chain.segments().zip(cols.iter_mut()) {
            let (Some(parent), Some(s), Some(v)) = (work.body.parent(seg), work.body.segment(seg), work.angles.get(seg)) else {
                continue;
            };
            let rp = work.pose.rotations.get(parent).copied().unwrap_or_default();
            let p = work.pose.positions.get(seg).copied().unwrap_or_default();
            let axes = world_axes(&s.joint, v, rp);
            for (((c, &w), dof), &x) in col.iter_mut().zip(&axes).zip(s.joint.dofs()).zip(v) {
                let arm = e - p;
                let j = w.cross(arm);
                if !at_limit_outward(dof.min, dof.max, x, j.dot(r)) {
                    let tension = r.dot(arm - w * w.dot(arm)).max(0.0);
                    let inv_d = 1.0 / (lambda2 * (j.length_squared() + 1e-6) + tension);
                    *c = (j, inv_d);
                    add_outer(&mut a, j, inv_d);
                }
            }
        }
        for (k, row) in a.iter_mut().enumerate() {
            if let Some(d) = row.get_mut(k) {
                *d += 1.0;
            }
        }
        let mut y = [r.x, r.y, r.z];
        if !cholesky_solve(&mut a, 3, &mut y) {
            break;
        }
        let y = Vec3::new(y[0], y[1], y[2]);
        let biggest = cols.iter().take(chain.len()).flatten().fold(0.0f32, |m, (c, d)| m.max(math::abs(c.dot(y) * d)));
        let scale = if biggest > MAX_STEP { MAX_STEP / biggest } else { 1.0 };
        for (seg, col) in chain.segments().zip(&cols) {
            let (Some(s), Some(v)) = (work.body.segment(seg), work.angles.get_mut(seg)) else {
                continue;
            };
            for ((x, dof), (c, d)) in v.iter_mut().zip(s.joint.dofs()).zip(col) {
                *x = dof.clamp(*x + c.dot(y) * d * scale);
            }
        }
        work.forward()?;
    }
    Ok(())
}

/// Whether a DOF at `x` sits on a limit that the descent direction `g` (the
/// derivative of the error decrease) pushes it through.
#[inline]
fn at_limit_outward(min: f32, max: f32, x: f32, g: f32) -> bool {
    (x >= max - 1e-6 && g > 0.0) || (x <= min + 1e-6 && g < 0.0)
}

/// `a += s·j·jᵀ` for a 3×3 block.
fn add_outer(a: &mut [[f32; 3]; 3], j: Vec3, s: f32) {
    let v = [j.x, j.y, j.z];
    for (row, &vi) in a.iter_mut().zip(&v) {
        for (x, &vj) in row.iter_mut().zip(&v) {
            *x += vi * s * vj;
        }
    }
}

/// Solves `A·x = b` for symmetric positive definite `A` (dimension `m ≤ M`,
/// lower triangle read, overwritten by the Cholesky factor); `b` becomes `x`.
/// Returns false if `A` is not numerically positive definite.
pub(super) fn cholesky_solve<const M: usize>(
    a: &mut [[f32; M]; M],
    m: usize,
    b: &mut [f32; M],
) -> bool {
    let m = m.min(M);
    // A = L·Lᵀ; the diagonal keeps 1/Lᵢᵢ.
    for i in 0..m {
        let (done, rest) = a.split_at_mut(i);
        let Some(row_i) = rest.first_mut() else {
            return false;
        };
        for (j, row_j) in done.iter().enumerate() {
            let dot: f32 = row_i
                .iter()
                .zip(row_j.iter())
                .take(j)
                .map(|(x, y)| x * y)
                .sum();
            let inv = row_j.get(j).copied().unwrap_or(0.0);
            if let Some(x) = row_i.get_mut(j) {
                *x = (*x - dot) * inv;
            }
        }
        let sq: f32 = row_i.iter().take(i).map(|x| x * x).sum();
        let d = row_i.get(i).copied().unwrap_or(0.0) - sq;
        if d <= 1e-20 || d.is_nan() {
            return false;
        }
        if let Some(x) = row_i.get_mut(i) {
            *x = math::rsqrt(d);
        }
    }
    // L·z = b.
    for (i, row) in a.iter().enumerate().take(m) {
        let s: f32 = row.iter().zip(b.iter()).take(i).map(|(l, z)| l * z).sum();
        if let (Some(x), Some(&inv)) = (b.get_mut(i), row.get(i)) {
            *x = (*x - s) * inv;
        }
    }
    // Lᵀ·x = z.
    for i in (0..m).rev() {
        let s: f32 = a
            .iter()
            .zip(b.iter())
            .take(m)
            .skip(i + 1)
            .map(|(row, &x)| row.get(i).copied().unwrap_or(0.0) * x)
            .sum();
        if let (Some(x), Some(&inv)) = (b.get_mut(i), a.get(i).and_then(|r| r.get(i))) {
            *x = (*x - s) * inv;
        }
    }
    true
}

/// One goal's rows at the current pose.
#[derive(Clone, Copy, Debug)]
struct Block {
    /// First row.
    row: usize,
    /// The goal's segment.
    seg: usize,
    /// The frame segment, if the target is relative.
    frame: Option<usize>,
    /// What the rows measure.
    kind: Kind,
    /// √(w / w_max); 0 while on standby.
    sw: f32,
    /// A satisfied one-sided plane goal: (its distance above the plane, its
    /// √(w / w_max)). It joins the step only if the step would cross the plane.
    standby: Option<(f32, f32)>,
}

#[derive(Clone, Copy, Debug)]
enum Kind {
    /// 3 rows: attached point `x`, world target `g`.
    Point { x: Vec3, g: Vec3 },
    /// 1 row: attached point `x`, world normal `n`, frame origin `o`.
    Plane { x: Vec3, n: Vec3, o: Vec3 },
    /// 3 rows.
    Orientation,
}

impl Block {
    fn rows(&self) -> usize {
        match self.kind {
            Kind::Plane { .. } => 1,
            _ => 3,
        }
    }
}

/// The least-squares problem at the current pose: blocks, scaled residuals.
struct Rows {
    blocks: [Option<Block>; MAX_ROWS],
    count: usize,
    m: usize,
    r: [f32; MAX_ROWS],
    /// Largest unscaled residual (m or rad).
    worst: f32,
    /// Σ (scaled residual)².
    error: f32,
}

impl Rows {
    fn build<const N: usize>(work: &Work<'_, '_, N>, wmax: f32) -> Result<Self, SolveError> {
        let mut rows = Rows {
            blocks: [None; MAX_ROWS],
            count: 0,
            m: 0,
            r: [0.0; MAX_ROWS],
            worst: 0.0,
            error: 0.0,
        };
        for (g, i) in work.goals.iter().zip(0u8..).filter(|(g, _)| g.is_active()) {
            let res = g
                .evaluate(work.body, work.pose)
                .ok_or(SolveError::BadGoal(i))?;
            rows.worst = rows.worst.max(res.magnitude());
            let sw = math::sqrt(g.weight / wmax);
            let Some((kind, values, gap)) = block_of(work, g, &res) else {
                continue;
            };
            let block = Block {
                row: rows.m,
                seg: usize::from(g.segment),
                frame: frame_of(g),
                kind,
                sw: if gap.is_some() { 0.0 } else { sw },
                standby: gap.map(|d| (d, sw)),
            };
            let n = block.rows();
            if rows.m + n > MAX_ROWS {
                return Err(SolveError::TooManyRows);
            }
            for (dst, v) in rows.r.iter_mut().skip(rows.m).zip(values.iter().take(n)) {
                *dst = v * block.sw;
                rows.error += *dst * *dst;
            }
            if let Some(slot) = rows.blocks.get_mut(rows.count) {
                *slot = Some(block);
            }
            rows.count += 1;
            rows.m += n;
        }
        Ok(rows)
    }

    fn iter(&self) -> impl Iterator<Item = &Block> {
        self.blocks.iter().take(self.count).flatten()
    }
}

fn frame_of(g: &Goal) -> Option<usize> {
    match g.frame {
        Frame::World => None,
        Frame::Segment(s) => Some(usize::from(s)),
    }
}

/// The row kind and unscaled residual values of an active goal, and for a
/// satisfied one-sided plane goal its distance above the plane (standby).
fn block_of<const N: usize>(work: &Work<'_, '_, N>, g: &Goal, res: &Residual) -> Option<(Kind, [f32; 3], Option<f32>)> {
    let x = g.world_point(work.body, work.pose)?;
    let origin = frame_of(g).and_then(|f| work.pose.positions.get(f).copied()).unwrap_or(Vec3::ZERO);
    match *res {
        Residual::Position(d) => Some((Kind::Point { x, g: x + d }, [d.x, d.y, d.z], None)),
        Residual::Plane { normal, correction } => {
            let gap = match g.target {
                Target::Plane { offset, side: PlaneSide::Above, .. } if correction == 0.0 => {
                    Some(normal.dot(x) - offset - normal.dot(origin))
                }
                _ => None,
            };
            Some((Kind::Plane { x, n: normal, o: origin }, [correction, 0.0, 0.0], gap))
        }
        Residual::Orientation(w) => Some((Kind::Orientation, [w.x, w.y, w.z], None)),
    }
}

/// A variable: a DOF (`seg`, index) or a translation component.
#[derive(Clone, Copy, Debug, Default)]
struct Var {
    seg: u8,
    dof: u8,
}

/// Whether a variable moves a block's point (`a`) and its frame (`b`).
fn dependence(b: &Block, anc: &[u64], var: Var) -> (bool, bool) {
    if var.seg == TRANSLATION {
        return (true, b.frame.is_some());
    }
    let bit = 1u64.checked_shl(u32::from(var.seg)).unwrap_or(0);
    let dep = |s: usize| anc.get(s).is_some_and(|m| m & bit != 0);
    (dep(b.seg), b.frame.is_some_and(dep))
}

/// The unscaled derivative of a block's rows with respect to one variable with
/// world axis `w` and pivot `p` (for a translation, `w` is its direction).
fn block_column(b: &Block, (da, db): (bool, bool), var: Var, w: Vec3, p: Vec3) -> [f32; 3] {
    match (b.kind, var.seg == TRANSLATION) {
        (Kind::Point { .. }, true) => [w.x, w.y, w.z].map(|c| if db { 0.0 } else { c }),
        (Kind::Point { x, g }, false) => {
            let j = if da { w.cross(x - p) } else { Vec3::ZERO } - if db { w.cross(g - p) } else { Vec3::ZERO };
            [j.x, j.y, j.z]
        }
        (Kind::Plane { n, .. }, true) => [if db { 0.0 } else { n.dot(w) }, 0.0, 0.0],
        (Kind::Plane { x, n, o }, false) => {
            let mut j = if da { n.dot(w.cross(x - p)) } else { 0.0 };
            if db {
                j += w.cross(n).dot(x - o) - n.dot(w.cross(o - p));
            }
            [j, 0.0, 0.0]
        }
        (Kind::Orientation, true) => [0.0; 3],
        (Kind::Orientation, false) => {
            let j = if da { w } else { Vec3::ZERO } - if db { w } else { Vec3::ZERO };
            [j.x, j.y, j.z]
        }
    }
}

/// Writes the (scaled) column of one variable into `col`, only the rows it
/// touches, listed in `nz`; returns how many rows that is.
fn column(rows: &Rows, anc: &[u64], var: Var, w: Vec3, p: Vec3, col: &mut [f32; MAX_ROWS], nz: &mut [u8; MAX_ROWS]) -> usize {
    let mut k = 0;
    for b in rows.iter().filter(|b| b.sw != 0.0) {
        let dep = dependence(b, anc, var);
        if dep == (false, false) {
            continue;
        }
        let vals = block_column(b, dep, var, w, p);
        for (i, &v) in vals.iter().enumerate().take(b.rows()) {
            let row = b.row + i;
            if let (Some(c), Some(z)) = (col.get_mut(row), nz.get_mut(k)) {
                *c = v * b.sw;
                *z = u8::try_from(row).unwrap_or(0);
                k += 1;
            }
        }
    }
    k
}

/// The variables of the whole-tree problem, in segment order.
fn variables<const N: usize>(
    solver: &Solver,
    tree: &ReachTree<N>,
    work: &Work<'_, '_, N>,
    vars: &mut [Var; MAX_VARS],
) -> usize {
    let mut n = 0;
    let mut push = |v: Var| {
        if let Some(slot) = vars.get_mut(n) {
            *slot = v;
            n += 1;
        }
    };
    let anchor = match solver.root {
        RootMode::Float => {
            for dof in 0..3 {
                push(Var {
                    seg: TRANSLATION,
                    dof,
                });
            }
            None
        }
        RootMode::Fixed => Some(0),
    };
    for (s, seg) in work.body.segments.iter().enumerate().skip(1) {
        if tree.moves(work.body, s, anchor) {
            for dof in 0..seg.joint.count() {
                push(Var {
                    seg: u8::try_from(s).unwrap_or(0),
                    dof: u8::try_from(dof).unwrap_or(0),
                });
            }
        }
    }
    n
}

/// Ancestor-or-self bit masks of every segment.
fn ancestry<const N: usize>(work: &Work<'_, '_, N>) -> [u64; N] {
    let mut anc = [0u64; N];
    for i in 0..work.body.len().min(N) {
        let up = work
            .body
            .parent(i)
            .and_then(|p| anc.get(p).copied())
            .unwrap_or(0);
        if let Some(a) = anc.get_mut(i) {
            *a = up
                | 1u64
                    .checked_shl(u32::try_from(i).unwrap_or(64))
                    .unwrap_or(0);
        }
    }
    anc
}

/// World axis and pivot of every variable at the current pose.
fn axes<const N: usize>(work: &Work<'_, '_, N>, vars: &[Var], out: &mut [(Vec3, Vec3); MAX_VARS]) {
    let mut cache: (usize, [Vec3; 3]) = (usize::MAX, [Vec3::ZERO; 3]);
    for (v, o) in vars.iter().zip(out.iter_mut()) {
        if v.seg == TRANSLATION {
            *o = (
                [Vec3::X, Vec3::Y, Vec3::Z]
                    .get(usize::from(v.dof))
                    .copied()
                    .unwrap_or(Vec3::X),
                Vec3::ZERO,
            );
            continue;
        }
        let s = usize::from(v.seg);
        if cache.0 != s {
            let (Some(parent), Some(segment), Some(values)) = (
                work.body.parent(s),
                work.body.segment(s),
                work.angles.get(s),
            ) else {
                continue;
            };
            let rp = work.pose.rotations.get(parent).copied().unwrap_or_default();
            cache = (s, world_axes(&segment.joint, values, rp));
        }
        let w = cache
            .1
            .get(usize::from(v.dof))
            .copied()
            .unwrap_or(Vec3::ZERO);
        *o = (w, work.pose.positions.get(s).copied().unwrap_or_default());
    }
}

/// Weighted DLS over the whole reach tree; returns (iterations, converged).
pub(super) fn solve_tree<const N: usize>(
    solver: &Solver,
    tree: &ReachTree<N>,
    work: &mut Work<'_, '_, N>,
) -> Result<(u32, bool), SolveError> {
    let wmax = work.goals.iter().filter(|g| g.is_active()).fold(0.0f32, |m, g| m.max(g.weight));
    if wmax <= 0.0 {
        return Ok((0, true));
    }
    let mut vars = [Var::default(); MAX_VARS];
    let nvars = variables(solver, tree, work, &mut vars);
    let vars = vars.get(..nvars).unwrap_or(&[]);
    let anc = ancestry(work);
    let mut lambda = solver.damping.max(MIN_DAMPING);
    let mut rows = Rows::build(work, wmax)?;
    let mut iterations = 0u32;
    let mut lin = Linearization {
        geometry: [(Vec3::ZERO, Vec3::ZERO); MAX_VARS],
        locked: [false; MAX_VARS],
        inv_d: [0.0; MAX_VARS],
        delta: [0.0; MAX_VARS],
    };
    let mut fresh = true;
    while iterations < u32::from(solver.max_iterations) {
        if rows.worst <= solver.tolerance || rows.m == 0 || nvars == 0 {
            return Ok((iterations, true));
        }
        iterations += 1;
        if fresh {
            axes(work, vars, &mut lin.geometry);
        }
        if !step(work, &mut rows, &anc, vars, lambda * lambda, &mut lin) {
            lambda *= 4.0;
            fresh = false;
            continue;
        }
        let saved = (*work.angles, work.pose.positions, work.pose.rotations);
        apply_step(work, vars, &lin.delta);
        work.forward()?;
        let next = Rows::build(work, wmax)?;
        if next.error < rows.error {
            let stalled = rows.error - next.error <= STALL * rows.error;
            rows = next;
            // Gauss–Newton underestimates steps where goals compress a limb:
            // try the same step once more and keep it if it helps.
            if solver.extrapolate {
                let kept = (*work.angles, work.pose.positions, work.pose.rotations);
                apply_step(work, vars, &lin.delta);
                work.forward()?;
                let further = Rows::build(work, wmax)?;
                if further.error < rows.error {
                    rows = further;
                } else {
                    (*work.angles, work.pose.positions, work.pose.rotations) = kept;
                }
            }
            lambda = (lambda / 3.0).max(MIN_DAMPING);
            fresh = true;
            if stalled {
                return Ok((iterations, true));
            }
        } else {
            (*work.angles, work.pose.positions, work.pose.rotations) = saved;
            lambda *= 4.0;
            fresh = false;
            if lambda > MAX_DAMPING {
                return Ok((iterations, true));
            }
        }
    }
    Ok((iterations, rows.worst <= solver.tolerance))
}

/// The smallest damping factor: keeps `A`'s condition within what `f32`
/// Cholesky resolves (about 1e4 against the identity).
const MIN_DAMPING: f32 = 1e-2;
/// Beyond this damping a step is pointless: the error is at a minimum.
const MAX_DAMPING: f32 = 1.0;
/// A relative decrease of the error below this is "no further improvement".
const STALL: f32 = 1e-6;
/// Rounds of clamping variables that a step would push through a limit.
const CLAMP_PASSES: usize = 4;

/// The per-variable part of one linearisation.
struct Linearization {
    /// World axis and pivot of each variable.
    geometry: [(Vec3, Vec3); MAX_VARS],
    /// Variables held (on a limit) in this step.
    locked: [bool; MAX_VARS],
    /// `1 / D_i`, the inverse per-variable damping.
    inv_d: [f32; MAX_VARS],
    /// The step.
    delta: [f32; MAX_VARS],
}

/// Computes the step `lin.delta`; false if the system is singular.
///
/// A variable on a limit whose gradient pushes it outwards is held. Then, up to
/// [`CLAMP_PASSES`] times: solve for the free variables; every variable the
/// step would carry through a limit moves only to that limit and is held, its
/// motion is taken out of the residual, and the rest is solved again.
fn step<const N: usize>(
    work: &Work<'_, '_, N>,
    rows: &mut Rows,
    anc: &[u64],
    vars: &[Var],
    lambda2: f32,
    lin: &mut Linearization,
) -> bool {
    let mut col = [0.0f32; MAX_ROWS];
    let mut nz = [0u8; MAX_ROWS];
    let mut r = rows.r;
    lin.delta = [0.0; MAX_VARS];
    for pass in 0..CLAMP_PASSES {
        let mut a = [[0.0f32; MAX_ROWS]; MAX_ROWS];
        normal_matrix(work, rows, anc, vars, lambda2, lin, &mut a, pass == 0);
        let mut y = r;
        if !cholesky_solve(&mut a, rows.m, &mut y) {
            return false;
        }
        let mut clamped = false;
        for (i, (v, &(w, p))) in vars.iter().zip(&lin.geometry).enumerate() {
            let (Some(&inv_d), Some(&held)) = (lin.inv_d.get(i), lin.locked.get(i)) else { continue };
            if held {
                continue;
            }
            let k = column(rows, anc, *v, w, p, &mut col, &mut nz);
            let nz = nz.get(..k).unwrap_or(&[]);
            let d: f32 = nz.iter().map(|&j| at(&col, j) * at(&y, j)).sum::<f32>() * inv_d;
            let bound = limit_of(work, v).and_then(|(min, max, x)| {
                if x + d > max {
                    Some(max - x)
                } else if x + d < min {
                    Some(min - x)
                } else {
                    None
                }
            });
            let Some(slot) = lin.delta.get_mut(i) else { continue };
            *slot = bound.unwrap_or(d);
            if let (Some(partial), Some(l), true) = (bound, lin.locked.get_mut(i), pass + 1 < CLAMP_PASSES) {
                *l = true;
                clamped = true;
                for &j in nz {
                    if let Some(rj) = r.get_mut(usize::from(j)) {
                        *rj -= at(&col, j) * partial;
                    }
                }
            }
        }
        if pass + 1 < CLAMP_PASSES && wake(rows, anc, vars, lin, &mut r) {
            clamped = true;
        }
        if !clamped {
            break;
        }
    }
    true
}

/// Activates every standby plane row that the step `lin.delta` would carry
/// through its plane (its residual becomes the distance to the plane);
/// returns whether any did.
fn wake(rows: &mut Rows, anc: &[u64], vars: &[Var], lin: &Linearization, r: &mut [f32; MAX_ROWS]) -> bool {
    let mut woke = false;
    for b in rows.blocks.iter_mut().take(rows.count).flatten() {
        let Some((gap, sw)) = b.standby else { continue };
        let ds: f32 = vars
            .iter()
            .zip(&lin.geometry)
            .zip(&lin.delta)
            .filter(|(_, d)| **d != 0.0)
            .map(|((v, &(w, p)), d)| block_column(b, dependence(b, anc, *v), *v, w, p)[0] * d)
            .sum();
        if gap + ds < 0.0 {
            b.standby = None;
            b.sw = sw;
            if let (Some(x), Some(y)) = (rows.r.get_mut(b.row), r.get_mut(b.row)) {
                *x = -gap * sw;
                *y = -gap * sw;
            }
            woke = true;
        }
    }
    woke
}

#[inline]
fn at(v: &[f32; MAX_ROWS], i: u8) -> f32 {
    v.get(usize::from(i)).copied().unwrap_or(0.0)
}

/// Builds `A = J̃·D⁻¹·J̃ᵀ + I` (lower triangle) over the free variables, for
/// the step `Δ = D⁻¹·J̃ᵀ·A⁻¹·r̃`, which equals `(J̃ᵀJ̃ + D)⁻¹·J̃ᵀ·r̃`
/// (push-through identity). `D_i = λ²·(J̃ᵀJ̃)ᵢᵢ + s_i` (Marquardt's scaling,
/// so radians and metres are damped alike), where `s_i ≥ 0` is the diagonal of
/// the second-order term Gauss–Newton leaves out: for a goal pulling its point
/// `x` with residual `r` about the axis `ω` through `p`, `r · (x − p)⊥ω`, the
/// "tension" that makes a stretched limb stiff against turning. Without it,
/// unreachable goals converge very slowly. With `first`, also decides which
/// variables start held: those on a limit that the gradient pushes outwards.
#[allow(clippy::too_many_arguments)]
fn normal_matrix<const N: usize>(
    work: &Work<'_, '_, N>,
    rows: &Rows,
    anc: &[u64],
    vars: &[Var],
    lambda2: f32,
    lin: &mut Linearization,
    a: &mut [[f32; MAX_ROWS]; MAX_ROWS],
    first: bool,
) {
    let mut col = [0.0f32; MAX_ROWS];
    let mut nz = [0u8; MAX_ROWS];
    for (((v, &(w, p)), lock), inv_d) in vars.iter().zip(&lin.geometry).zip(lin.locked.iter_mut()).zip(lin.inv_d.iter_mut()) {
        if !first && *lock {
            continue;
        }
        let k = column(rows, anc, *v, w, p, &mut col, &mut nz);
        let nz = nz.get(..k).unwrap_or(&[]);
        if first {
            let g: f32 = nz.iter().map(|&i| at(&col, i) * at(&rows.r, i)).sum();
            *lock = limit_of(work, v).is_some_and(|(min, max, x)| at_limit_outward(min, max, x, g));
            if *lock {
                continue;
            }
            let curvature: f32 = nz.iter().map(|&i| at(&col, i) * at(&col, i)).sum();
            *inv_d = 1.0 / (lambda2 * (curvature + 1e-6) + stiffness(rows, anc, *v, w, p));
        }
        for (ii, &i) in nz.iter().enumerate() {
            let ci = at(&col, i) * *inv_d;
            let Some(row) = a.get_mut(usize::from(i)) else { continue };
            for &j in nz.iter().take(ii + 1) {
                if let Some(x) = row.get_mut(usize::from(j)) {
                    *x += ci * at(&col, j);
                }
            }
        }
    }
    for (k, row) in a.iter_mut().enumerate().take(rows.m) {
        if let Some(d) = row.get_mut(k) {
            *d += 1.0;
        }
    }
}

/// The tension term of a rotational variable, `Σ √w̃·r̃ · (x − p)⊥ω` over the
/// goals it moves (for a goal in another segment's frame whose frame it moves,
/// minus the same term at the target), clamped at 0.
fn stiffness(rows: &Rows, anc: &[u64], var: Var, w: Vec3, p: Vec3) -> f32 {
    if var.seg == TRANSLATION {
        return 0.0;
    }
    let perp = |v: Vec3| v - w * w.dot(v);
    let mut s = 0.0;
    for b in rows.iter().filter(|b| b.sw != 0.0) {
        let (da, db) = dependence(b, anc, var);
        let r = |i: usize| rows.r.get(b.row + i).copied().unwrap_or(0.0);
        let bend = match b.kind {
            Kind::Point { x, g } => {
                let arm = if da { perp(x - p) } else { Vec3::ZERO } - if db { perp(g - p) } else { Vec3::ZERO };
                Vec3::new(r(0), r(1), r(2)).dot(arm)
            }
            Kind::Plane { x, n, .. } if da && !db => r(0) * n.dot(perp(x - p)),
            Kind::Plane { .. } | Kind::Orientation => continue,
        };
        s += b.sw * bend;
    }
    s.max(0.0)
}

/// The limits and current value of a rotational variable (`None` for translation).
fn limit_of<const N: usize>(work: &Work<'_, '_, N>, v: &Var) -> Option<(f32, f32, f32)> {
    let s = usize::from(v.seg);
    let d = usize::from(v.dof);
    let dof = work.body.segment(s)?.joint.dofs().get(d).copied()?;
    let x = work.angles.get(s)?.get(d).copied()?;
    Some((dof.min, dof.max, x))
}

/// Applies a step, scaled to at most [`MAX_STEP`], clamped into the limits.
fn apply_step<const N: usize>(work: &mut Work<'_, '_, N>, vars: &[Var], delta: &[f32; MAX_VARS]) {
    let biggest = delta.iter().take(vars.len()).fold(0.0f32, |m, d| m.max(math::abs(*d)));
    let scale = if biggest > MAX_STEP { MAX_STEP / biggest } else { 1.0 };
    for (v, &d) in vars.iter().zip(delta) {
        let step = d * scale;
        if v.seg == TRANSLATION {
            let e = [Vec3::X, Vec3::Y, Vec3::Z].get(usize::from(v.dof)).copied().unwrap_or(Vec3::ZERO);
            work.angles.root_position += e * step;
            continue;
        }
        let s = usize::from(v.seg);
        let Some(dof) = work.body.segment(s).and_then(|seg| seg.joint.dofs().get(usize::from(v.dof)).copied()) else {
            continue;
        };
        if let Some(x) = work.angles.get_mut(s).and_then(|a| a.get_mut(usize::from(v.dof))) {
            *x = dof.clamp(*x + step);
        }
    }
}
