//! Weighted damped least squares over the whole reach tree
//! ([`Method::TreeDls`](super::Method::TreeDls)).
//!
//! Minimises `E(θ) = Σ wᵢ·|rᵢ(θ)|²` over the joint angles of the reach tree's
//! chains (and the root translation in [`RootMode::Float`]) with
//! Levenberg–Marquardt steps in the small "goal space" form. Each active goal
//! owns a 3-row block (a plane goal uses its first row), rows are scaled by
//! `√(wᵢ / w_max)`, and each step is
//!
//! ```text
//! Δ = D⁻¹·J̃ᵀ·y,   (J̃·D⁻¹·J̃ᵀ + I)·y = r̃,
//! ```
//!
//! which equals `(J̃ᵀJ̃ + D)⁻¹·J̃ᵀ·r̃` (push-through identity) but needs only a
//! block Cholesky factorisation of `k × k` blocks of 3×3 for `k` goals, far
//! smaller than the number of joints. A column of `J` is `ω × (x − p)` for a
//! DOF with world axis `ω` and pivot `p`, for every goal whose segment it moves;
//! `ω` for orientation rows; minus the same terms for a goal given in the frame
//! of a segment the DOF also moves.
//!
//! `D_i = λ²·(J̃ᵀJ̃)ᵢᵢ + s_i`: Marquardt's scaling, so radians and metres are
//! damped alike, plus `s_i ≥ 0`, the diagonal of the second-order term that
//! Gauss–Newton leaves out: for a goal pulling its point `x` with residual `r`,
//! `r · (x − p)⊥ω`, the tension that makes a stretched limb stiff against
//! turning. Without it, unreachable goals (the paper's 40/10 example) converge
//! very slowly.
//!
//! Joint limits: a DOF on a limit that the gradient pushes outwards is held; a
//! DOF that the step would carry through a limit moves only to the limit and is
//! held, its motion is taken out of the residual and the others are solved
//! again (a few rounds). One-sided plane goals that are satisfied wait on
//! standby and join the step only if it would carry their point through the
//! plane.
//!
//! A step that does not lower `E` is undone and the damping raised ×4; one that
//! does lowers it ÷3. The solve stops when every goal is within `tolerance`,
//! when `E` stops decreasing, or at the iteration cap.
//!
//! Per iteration: one forward kinematics (only the moving segments' joint
//! rotations are rebuilt), the world axes of the moving joints, every column
//! twice (once for the matrix, once for the step; each a cross product per
//! goal), and one block Cholesky factorisation (again per round of clamping).

use super::ccd::world_axes;
use super::dls::{MAX_STEP, at_limit_outward};
use super::reach::bit;
use super::{ReachTree, RootMode, SolveError, Solver, Work};
use crate::goal::{Frame, PlaneSide, Residual, Target};
use crate::math;
use crate::pose::MAX_SEGMENTS;
use glam::{Mat3, Vec3};

/// The most active goals [`Method::TreeDls`](super::Method::TreeDls) takes.
pub const MAX_GOALS: usize = 10;
/// Joint groups: every segment's joint, plus the root translation.
const MAX_GROUPS: usize = MAX_SEGMENTS + 1;
/// Marker for the translation group.
const TRANSLATION: u8 = u8::MAX;
/// The smallest damping factor: keeps the matrix's condition within what
/// `f32` Cholesky resolves (about 1e4 against the identity).
const MIN_DAMPING: f32 = 1e-2;
/// Beyond this damping a step is pointless: the error is at a minimum.
const MAX_DAMPING: f32 = 100.0;
/// A relative decrease of the error below this is "no further improvement".
const STALL: f32 = 1e-6;
/// Rounds of clamping variables that a step would push through a limit.
const CLAMP_PASSES: usize = 3;

/// Lower block triangle of `J̃·D⁻¹·J̃ᵀ + I`: `a[t][s]` for `t ≥ s`.
type Blocks = [[Mat3; MAX_GOALS]; MAX_GOALS];
/// One 3-vector per goal.
type Rhs = [Vec3; MAX_GOALS];
/// Per group, per DOF.
type PerDof = [[f32; 3]; MAX_GROUPS];

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Point,
    Plane,
    Orientation,
}

/// One active goal: its scale and its geometry at the current pose.
#[derive(Clone, Copy, Debug)]
struct Slot {
    /// Index in the goal set.
    goal: usize,
    kind: Kind,
    /// A one-sided plane goal.
    one_sided: bool,
    /// √(w / w_max).
    sw_full: f32,
    /// The scale in use: `sw_full`, or 0 for a satisfied one-sided plane.
    sw: f32,
    /// Attached point.
    x: Vec3,
    /// Target point (points) or frame origin (planes).
    g: Vec3,
    /// Plane normal.
    n: Vec3,
    /// Distance above the plane of a satisfied one-sided plane goal.
    gap: f32,
}

const EMPTY_SLOT: Slot = Slot {
    goal: 0,
    kind: Kind::Point,
    one_sided: false,
    sw_full: 0.0,
    sw: 0.0,
    x: Vec3::ZERO,
    g: Vec3::ZERO,
    n: Vec3::ZERO,
    gap: 0.0,
};

/// The active goals.
struct Slots {
    s: [Slot; MAX_GOALS],
    count: usize,
    /// Bit `j`: slot `j` takes part in the step.
    awake: u16,
}

impl Slots {
    fn new<const N: usize>(work: &Work<'_, '_, N>, wmax: f32) -> Result<Self, SolveError> {
        let mut slots = Slots {
            s: [EMPTY_SLOT; MAX_GOALS],
            count: 0,
            awake: 0,
        };
        for (i, g) in work.goals.iter().enumerate().filter(|(_, g)| g.is_active()) {
            let (kind, one_sided) = match g.target {
                Target::Position(_) => (Kind::Point, false),
                Target::Plane { side, .. } => (Kind::Plane, side == PlaneSide::Above),
                Target::Orientation(_) => (Kind::Orientation, false),
            };
            let rel = g.weight / wmax;
            let sw = rel * math::rsqrt(rel);
            let free = slots
                .s
                .get_mut(slots.count)
                .ok_or(SolveError::TooManyGoals)?;
            *free = Slot {
                goal: i,
                kind,
                one_sided,
                sw_full: sw,
                sw,
                ..EMPTY_SLOT
            };
            slots.count += 1;
        }
        Ok(slots)
    }

    fn iter(&self) -> impl Iterator<Item = &Slot> {
        self.s.iter().take(self.count)
    }

    /// Refreshes geometry and scaled residuals `r` at the current pose; returns
    /// (the scaled error `Σ |r̃|²`, the largest squared unscaled residual).
    fn evaluate<const N: usize>(
        &mut self,
        work: &Work<'_, '_, N>,
        r: &mut Rhs,
    ) -> Result<(f32, f32), SolveError> {
        let (mut error, mut worst) = (0.0f32, 0.0f32);
        self.awake = 0;
        for (j, (slot, rj)) in self
            .s
            .iter_mut()
            .zip(r.iter_mut())
            .take(self.count)
            .enumerate()
        {
            let bad = SolveError::BadGoal(u8::try_from(slot.goal).unwrap_or(u8::MAX));
            let g = work.goals.get(slot.goal).ok_or(bad)?;
            let values = match g.evaluate(work.body, work.pose).ok_or(bad)? {
                Residual::Position(d) => {
                    slot.x = g.world_point(work.body, work.pose).ok_or(bad)?;
                    slot.g = slot.x + d;
                    slot.sw = slot.sw_full;
                    d
                }
                Residual::Plane { normal, correction } => {
                    slot.x = g.world_point(work.body, work.pose).ok_or(bad)?;
                    slot.n = normal;
                    slot.g = match g.frame {
                        Frame::World => Vec3::ZERO,
                        Frame::Segment(f) => work
                            .pose
                            .positions
                            .get(usize::from(f))
                            .copied()
                            .unwrap_or(Vec3::ZERO),
                    };
                    let asleep = slot.one_sided && correction == 0.0;
                    slot.sw = if asleep { 0.0 } else { slot.sw_full };
                    if asleep && let Target::Plane { offset, .. } = g.target {
                        slot.gap = normal.dot(slot.x) - offset - normal.dot(slot.g);
                    }
                    Vec3::new(correction, 0.0, 0.0)
                }
                Residual::Orientation(w) => {
                    slot.sw = slot.sw_full;
                    w
                }
            };
            if slot.sw != 0.0 {
                self.awake |= 1 << j;
            }
            worst = larger(worst, values.length_squared());
            *rj = values * slot.sw;
            error += rj.length_squared();
        }
        Ok((error, worst))
    }

    /// The scaled error at the current pose, without touching the slots.
    fn error<const N: usize>(&self, work: &Work<'_, '_, N>) -> Result<f32, SolveError> {
        let mut error = 0.0f32;
        for slot in self.iter() {
            let bad = SolveError::BadGoal(u8::try_from(slot.goal).unwrap_or(u8::MAX));
            let g = work.goals.get(slot.goal).ok_or(bad)?;
            let d2 = match g.evaluate(work.body, work.pose).ok_or(bad)? {
                Residual::Position(d) | Residual::Orientation(d) => d.length_squared(),
                Residual::Plane { correction, .. } => correction * correction,
            };
            error += d2 * slot.sw_full * slot.sw_full;
        }
        Ok(error)
    }
}

/// The DOFs of one segment's joint (or the root translation, `seg ==
/// TRANSLATION`), with the goals they move.
#[derive(Clone, Copy, Debug, Default)]
struct Group {
    seg: u8,
    count: u8,
    min: [f32; 3],
    max: [f32; 3],
    /// Bit `j`: moves slot `j`'s point.
    dep_a: u16,
    /// Bit `j`: moves slot `j`'s frame segment.
    dep_b: u16,
}

impl Group {
    #[inline]
    fn translation(&self) -> bool {
        self.seg == TRANSLATION
    }
}

/// The joint groups that move, in segment order, with their dependencies.
fn groups<const N: usize>(
    solver: &Solver,
    tree: &ReachTree<N>,
    work: &Work<'_, '_, N>,
    slots: &Slots,
    out: &mut [Group; MAX_GROUPS],
) -> usize {
    // Per slot: the ancestry of its goal's segment and of its frame segment.
    let mut masks = [(0u64, 0u64); MAX_GOALS];
    for (m, slot) in masks.iter_mut().zip(slots.iter()) {
        if let Some(g) = work.goals.get(slot.goal) {
            let frame = match g.frame {
                Frame::World => 0,
                Frame::Segment(f) => tree.ancestry(usize::from(f)),
            };
            *m = (tree.ancestry(usize::from(g.segment)), frame);
        }
    }
    let deps = |b: u64| {
        masks
            .iter()
            .take(slots.count)
            .enumerate()
            .fold((0u16, 0u16), |(a, f), (j, m)| {
                (
                    if m.0 & b != 0 { a | 1 << j } else { a },
                    if m.1 & b != 0 { f | 1 << j } else { f },
                )
            })
    };
    let mut n = 0;
    let mut push = |g: Group| {
        if let Some(slot) = out.get_mut(n) {
            *slot = g;
            n += 1;
        }
    };
    let anchor = match solver.root {
        RootMode::Float => {
            let (all, framed) = deps(u64::MAX);
            push(Group {
                seg: TRANSLATION,
                count: 3,
                dep_a: all,
                dep_b: framed,
                ..Group::default()
            });
            None
        }
        RootMode::Fixed => Some(0),
    };
    for (s, seg) in work.body.segments.iter().enumerate().skip(1) {
        if !tree.moves(s, anchor) || seg.joint.count() == 0 {
            continue;
        }
        let (dep_a, dep_b) = deps(bit(s));
        let mut g = Group {
            seg: u8::try_from(s).unwrap_or(0),
            dep_a,
            dep_b,
            ..Group::default()
        };
        for ((d, min), max) in seg
            .joint
            .dofs()
            .iter()
            .zip(g.min.iter_mut())
            .zip(g.max.iter_mut())
        {
            (*min, *max) = (d.min, d.max);
            g.count += 1;
        }
        push(g);
    }
    n
}

/// Bit mask of the segments whose joints the groups move.
fn moving_segments(groups: &[Group]) -> u64 {
    groups
        .iter()
        .filter(|g| !g.translation())
        .fold(0, |m, g| m | bit(usize::from(g.seg)))
}

/// Pivot and world axes of every group at the current pose.
fn geometry<const N: usize>(
    work: &Work<'_, '_, N>,
    groups: &[Group],
    out: &mut [(Vec3, [Vec3; 3]); MAX_GROUPS],
) {
    for (g, o) in groups.iter().zip(out.iter_mut()) {
        if g.translation() {
            *o = (Vec3::ZERO, [Vec3::X, Vec3::Y, Vec3::Z]);
            continue;
        }
        let s = usize::from(g.seg);
        let (Some(parent), Some(segment), Some(values)) = (
            work.body.parent(s),
            work.body.segment(s),
            work.angles.get(s),
        ) else {
            continue;
        };
        let rp = work.pose.rotations.get(parent).copied().unwrap_or_default();
        let rs = work.pose.rotations.get(s).copied().unwrap_or_default();
        let p = work.pose.positions.get(s).copied().unwrap_or_default();
        *o = (p, world_axes(&segment.joint, values, rp, rs));
    }
}

/// The unscaled derivative of a slot's rows with respect to one DOF with world
/// axis `w` and pivot `p`, given which of the point (`da`) and the frame (`db`)
/// it moves; for a translation `w` is its direction.
#[inline]
fn derivative(slot: &Slot, da: bool, db: bool, translation: bool, w: Vec3, p: Vec3) -> Vec3 {
    let (x, g, n) = (slot.x, slot.g, slot.n);
    match (slot.kind, translation) {
        (Kind::Point, true) => {
            if db {
                Vec3::ZERO
            } else {
                w
            }
        }
        (Kind::Point, false) => {
            let a = if da { w.cross(x - p) } else { Vec3::ZERO };
            let b = if db { w.cross(g - p) } else { Vec3::ZERO };
            a - b
        }
        (Kind::Plane, true) => Vec3::new(if db { 0.0 } else { n.dot(w) }, 0.0, 0.0),
        (Kind::Plane, false) => {
            let mut j = if da { n.dot(w.cross(x - p)) } else { 0.0 };
            if db {
                j += w.cross(n).dot(x - g) - n.dot(w.cross(g - p));
            }
            Vec3::new(j, 0.0, 0.0)
        }
        (Kind::Orientation, true) => Vec3::ZERO,
        (Kind::Orientation, false) => {
            (if da { w } else { Vec3::ZERO }) - (if db { w } else { Vec3::ZERO })
        }
    }
}

/// How one DOF of a group moves one goal's rows: the column entry is
/// `sw · f(ω)` for the DOF's world axis `ω`.
#[derive(Clone, Copy, Debug)]
enum Lever {
    /// `ω × arm` (a point, moved by a rotation; for a goal in another
    /// segment's frame the arm is the difference of both arms).
    Point(Vec3),
    /// `k·ω` (a point moved by the translation, `k` = 1; an orientation,
    /// `k` = ±1).
    Axis(f32),
    /// `(ω·q, 0, 0)` with `q = (x − p) × n` (a world plane's point, moved by a
    /// rotation).
    Plane(Vec3),
    /// `(n·ω, 0, 0)` (a world plane's point, moved by the translation).
    PlaneAxis(Vec3),
    /// Anything else (a plane in another segment's frame): the general
    /// derivative.
    General { da: bool, db: bool },
    /// No effect.
    Zero,
}

/// The goals one DOF of a group moves, with its lever on each.
#[derive(Clone, Copy, Debug)]
struct Link {
    slot: u8,
    lever: Lever,
}

const NO_LINK: Link = Link {
    slot: 0,
    lever: Lever::Zero,
};
/// The most (group, goal) links one step handles.
pub(super) const MAX_LINKS: usize = 160;

/// Every group's links at one linearisation: group `i` owns
/// `links[span[i].0 .. span[i].0 + span[i].1]`, ascending by slot.
struct Links {
    span: [(u8, u8); MAX_GROUPS],
    links: [Link; MAX_LINKS],
    /// Per link, the scaled column entry of each of its group's DOFs (filled
    /// while the matrix is built, reused by the step and the clamping).
    cols: [[Vec3; 3]; MAX_LINKS],
}

impl Links {
    const EMPTY: Links = Links {
        span: [(0, 0); MAX_GROUPS],
        links: [NO_LINK; MAX_LINKS],
        cols: [[Vec3::ZERO; 3]; MAX_LINKS],
    };

    /// The links of every group at the current pivots and slots.
    fn build(
        &mut self,
        groups: &[Group],
        geometry: &[(Vec3, [Vec3; 3]); MAX_GROUPS],
        slots: &Slots,
    ) -> Result<(), SolveError> {
        let mut used = 0usize;
        for ((g, (p, _)), span) in groups.iter().zip(geometry.iter()).zip(self.span.iter_mut()) {
            let start = used;
            let mut bits = g.dep_a | g.dep_b;
            while bits != 0 {
                let j = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let Some(slot) = slots.s.get(j) else { continue };
                let (da, db) = (g.dep_a >> j & 1 != 0, g.dep_b >> j & 1 != 0);
                let lever = lever(slot, da, db, g.translation(), *p);
                let free = self.links.get_mut(used).ok_or(SolveError::TooManyGoals)?;
                *free = Link {
                    slot: u8::try_from(j).unwrap_or(0),
                    lever,
                };
                used += 1;
            }
            *span = (
                u8::try_from(start).unwrap_or(0),
                u8::try_from(used - start).unwrap_or(0),
            );
        }
        Ok(())
    }

    /// The links of a group and their column entries.
    fn of(&self, group: usize) -> (&[Link], &[[Vec3; 3]]) {
        let (start, len) = self.span.get(group).copied().unwrap_or((0, 0));
        let range = usize::from(start)..usize::from(start) + usize::from(len);
        (
            self.links.get(range.clone()).unwrap_or(&[]),
            self.cols.get(range).unwrap_or(&[]),
        )
    }

    /// The links of a group and their column entries, the entries writable.
    fn of_mut(&mut self, group: usize) -> (&[Link], &mut [[Vec3; 3]]) {
        let (start, len) = self.span.get(group).copied().unwrap_or((0, 0));
        let range = usize::from(start)..usize::from(start) + usize::from(len);
        (
            self.links.get(range.clone()).unwrap_or(&[]),
            self.cols.get_mut(range).unwrap_or(&mut []),
        )
    }
}

/// The lever of a group (pivot `p`) on a slot.
fn lever(slot: &Slot, da: bool, db: bool, translation: bool, p: Vec3) -> Lever {
    match (slot.kind, translation) {
        (Kind::Point, true) => Lever::Axis(if db { 0.0 } else { 1.0 }),
        (Kind::Point, false) => {
            let a = if da { slot.x - p } else { Vec3::ZERO };
            let b = if db { slot.g - p } else { Vec3::ZERO };
            Lever::Point(a - b)
        }
        (Kind::Orientation, true) => Lever::Zero,
        (Kind::Orientation, false) => {
            Lever::Axis(if da { 1.0 } else { 0.0 } - if db { 1.0 } else { 0.0 })
        }
        (Kind::Plane, true) if !db => Lever::PlaneAxis(slot.n),
        (Kind::Plane, false) if !db => Lever::Plane((slot.x - p).cross(slot.n)),
        (Kind::Plane, _) => Lever::General { da, db },
    }
}

/// One DOF's scaled column entry on a link's slot (world axis `w`, pivot `p`),
/// and the tension term.
#[inline]
fn entry(link: &Link, slot: &Slot, translation: bool, w: Vec3, p: Vec3, r: Vec3) -> (Vec3, f32) {
    let sw = slot.sw;
    match link.lever {
        Lever::Point(arm) => {
            let tension = if translation {
                0.0
            } else {
                r.dot(arm) - w.dot(r) * w.dot(arm)
            };
            (w.cross(arm) * sw, sw * tension)
        }
        Lever::Axis(k) => (w * (sw * k), 0.0),
        Lever::Plane(q) => {
            let (n, arm) = (slot.n, slot.x - p);
            (
                Vec3::new(sw * w.dot(q), 0.0, 0.0),
                sw * r.x * (n.dot(arm) - w.dot(n) * w.dot(arm)),
            )
        }
        Lever::PlaneAxis(n) => (Vec3::new(sw * n.dot(w), 0.0, 0.0), 0.0),
        Lever::General { da, db } => (derivative(slot, da, db, translation, w, p) * sw, 0.0),
        Lever::Zero => (Vec3::ZERO, 0.0),
    }
}

/// `a += s · c·cᵀ` on the lower block triangle, over a group's links, for
/// the column of DOF `k`.
#[inline]
fn outer(a: &mut Blocks, links: &[Link], cols: &[[Vec3; 3]], k: usize, s: f32) {
    let col = |e: &[Vec3; 3]| e.get(k).copied().unwrap_or(Vec3::ZERO);
    for (i, (lt, et)) in links.iter().zip(cols).enumerate() {
        let Some(row) = a.get_mut(usize::from(lt.slot)) else {
            continue;
        };
        let u = col(et) * s;
        for (lk, ek) in links.iter().zip(cols).take(i + 1) {
            let ck = col(ek);
            if let Some(block) = row.get_mut(usize::from(lk.slot)) {
                block.x_axis += u * ck.x;
                block.y_axis += u * ck.y;
                block.z_axis += u * ck.z;
            }
        }
    }
}

/// `b` if it is larger, else `a` (no libm call, unlike `f32::max`).
#[inline]
fn larger(a: f32, b: f32) -> f32 {
    if b > a { b } else { a }
}

/// Cholesky of a symmetric positive definite 3×3 matrix: the inverse of its
/// lower factor, or `None`.
fn chol3_inverse(m: Mat3) -> Option<Mat3> {
    let (a00, a10, a20) = (m.x_axis.x, m.x_axis.y, m.x_axis.z);
    let (a11, a21, a22) = (m.y_axis.y, m.y_axis.z, m.z_axis.z);
    if a00 <= 1e-20 || a00.is_nan() {
        return None;
    }
    let i00 = math::rsqrt(a00);
    let (l10, l20) = (a10 * i00, a20 * i00);
    let d1 = a11 - l10 * l10;
    if d1 <= 1e-20 || d1.is_nan() {
        return None;
    }
    let i11 = math::rsqrt(d1);
    let l21 = (a21 - l20 * l10) * i11;
    let d2 = a22 - l20 * l20 - l21 * l21;
    if d2 <= 1e-20 || d2.is_nan() {
        return None;
    }
    let i22 = math::rsqrt(d2);
    // Inverse of L = [[l00,0,0],[l10,l11,0],[l20,l21,l22]] (lower, column-major below).
    let m10 = -l10 * i00 * i11;
    let m21 = -l21 * i11 * i22;
    let m20 = -(l20 * i00 + l21 * m10) * i22;
    Some(Mat3::from_cols(
        Vec3::new(i00, m10, m20),
        Vec3::new(0.0, i11, m21),
        Vec3::new(0.0, 0.0, i22),
    ))
}

/// Solves `A·y = b` for the block matrix `a` (lower block triangle, `n`
/// blocks), overwriting `a` with the factor (inverse diagonal blocks) and `b`
/// with `y`. False if `A` is not numerically positive definite.
fn block_cholesky_solve(a: &mut Blocks, n: usize, b: &mut Rhs) -> bool {
    let n = n.min(MAX_GOALS);
    for s in 0..n {
        let Some((done, rest)) = a.split_at_mut_checked(s) else {
            return false;
        };
        let Some(row_s) = rest.first_mut() else {
            return false;
        };
        // Off-diagonal blocks of row s: L_sk = (A_sk − Σ_{j<k} L_sj·L_kjᵀ)·L_kk⁻ᵀ.
        for (k, row_k) in done.iter().enumerate() {
            let Some((left, tail)) = row_s.split_at_mut_checked(k) else {
                return false;
            };
            let mut acc = tail.first().copied().unwrap_or(Mat3::ZERO);
            for (lsj, lkj) in left.iter().zip(row_k.iter()) {
                acc -= *lsj * lkj.transpose();
            }
            let inv_kk = row_k.get(k).copied().unwrap_or(Mat3::ZERO);
            if let Some(x) = tail.first_mut() {
                *x = acc * inv_kk.transpose();
            }
        }
        // Diagonal: L_ss·L_ssᵀ = A_ss − Σ_k L_sk·L_skᵀ; keep L_ss⁻¹.
        let Some((left, tail)) = row_s.split_at_mut_checked(s) else {
            return false;
        };
        let mut acc = tail.first().copied().unwrap_or(Mat3::ZERO);
        for l in left.iter() {
            acc -= *l * l.transpose();
        }
        let (Some(inv), Some(x)) = (chol3_inverse(acc), tail.first_mut()) else {
            return false;
        };
        *x = inv;
    }
    // L·z = b.
    for (s, row) in a.iter().enumerate().take(n) {
        let Some((head, tail)) = b.split_at_mut_checked(s) else {
            return false;
        };
        let mut v = tail.first().copied().unwrap_or(Vec3::ZERO);
        for (l, z) in row.iter().zip(head.iter()) {
            v -= *l * *z;
        }
        if let (Some(x), Some(inv)) = (tail.first_mut(), row.get(s)) {
            *x = *inv * v;
        }
    }
    // Lᵀ·y = z, by rows of L.
    for (s, row) in a.iter().enumerate().take(n).rev() {
        let Some((head, tail)) = b.split_at_mut_checked(s) else {
            return false;
        };
        let (Some(x), Some(inv)) = (tail.first_mut(), row.get(s)) else {
            return false;
        };
        *x = inv.transpose() * *x;
        let ys = *x;
        for (bk, l) in head.iter_mut().zip(row.iter()) {
            *bk -= l.transpose() * ys;
        }
    }
    true
}

/// The scratch of one step.
struct Linear {
    /// Pivot and world axes per group.
    geometry: [(Vec3, [Vec3; 3]); MAX_GROUPS],
    /// Each group's links to the goals.
    links: Links,
    /// `1 / D` per DOF; 0 for a held DOF.
    inv_d: PerDof,
    /// The step per DOF.
    delta: PerDof,
    /// The matrix and its factor.
    a: Blocks,
    l: Blocks,
}

/// Computes the step `lin.delta`; false if the system is singular.
fn step<const N: usize>(
    work: &Work<'_, '_, N>,
    slots: &mut Slots,
    r: &mut Rhs,
    groups: &[Group],
    lambda2: f32,
    lin: &mut Linear,
) -> bool {
    let n = slots.count;
    for _round in 0..2 {
        for row in lin.a.iter_mut().take(n) {
            for b in row.iter_mut().take(n) {
                *b = Mat3::ZERO;
            }
        }
        // Active set, damping, A = J̃·D⁻¹·J̃ᵀ + I.
        for (gi, g) in groups.iter().enumerate() {
            let (Some(&(p, axes)), Some(inv_d), Some(delta)) = (
                lin.geometry.get(gi),
                lin.inv_d.get_mut(gi),
                lin.delta.get_mut(gi),
            ) else {
                continue;
            };
            let (links, cols) = lin.links.of_mut(gi);
            let x = value(work, g);
            for k in 0..usize::from(g.count).min(3) {
                let (Some(&w), Some(id), Some(d)) =
                    (axes.get(k), inv_d.get_mut(k), delta.get_mut(k))
                else {
                    continue;
                };
                *d = 0.0;
                let (mut curvature, mut grad, mut tension) = (0.0f32, 0.0f32, 0.0f32);
                for (link, e) in links.iter().zip(cols.iter_mut()) {
                    let j = usize::from(link.slot);
                    let (Some(slot), Some(&rj), Some(ek)) =
                        (slots.s.get(j), r.get(j), e.get_mut(k))
                    else {
                        continue;
                    };
                    let (c, t) = entry(link, slot, g.translation(), w, p, rj);
                    *ek = c;
                    curvature += c.length_squared();
                    grad += c.dot(rj);
                    tension += t;
                }
                let (min, max, v) = limits(g, &x, k);
                let held = !g.translation() && at_limit_outward(min, max, v, grad);
                *id = if held {
                    0.0
                } else {
                    1.0 / (lambda2 * (curvature + 1e-6) + larger(tension, 0.0))
                };
                if *id != 0.0 {
                    outer(&mut lin.a, links, cols, k, *id);
                }
            }
        }
        for (s, row) in lin.a.iter_mut().enumerate().take(n) {
            if let Some(d) = row.get_mut(s) {
                *d += Mat3::IDENTITY;
            }
        }
        let mut target = *r;
        for pass in 0..CLAMP_PASSES {
            for (dst, src) in lin.l.iter_mut().zip(lin.a.iter()).take(n) {
                for (d, s) in dst.iter_mut().zip(src.iter()).take(n) {
                    *d = *s;
                }
            }
            let mut y = target;
            if !block_cholesky_solve(&mut lin.l, n, &mut y) {
                return false;
            }
            let last = pass + 1 == CLAMP_PASSES;
            let mut clamped = false;
            for (gi, g) in groups.iter().enumerate() {
                let (Some(inv_d), Some(delta)) = (lin.inv_d.get_mut(gi), lin.delta.get_mut(gi))
                else {
                    continue;
                };
                let (links, cols) = lin.links.of(gi);
                let x = value(work, g);
                for k in 0..usize::from(g.count).min(3) {
                    let (Some(id), Some(d)) = (inv_d.get_mut(k), delta.get_mut(k)) else {
                        continue;
                    };
                    if *id == 0.0 {
                        continue;
                    }
                    let cy: f32 = links
                        .iter()
                        .zip(cols)
                        .map(|(link, e)| {
                            e.get(k)
                                .copied()
                                .unwrap_or(Vec3::ZERO)
                                .dot(y.get(usize::from(link.slot)).copied().unwrap_or(Vec3::ZERO))
                        })
                        .sum();
                    *d = cy * *id;
                    if g.translation() || last {
                        continue;
                    }
                    let (min, max, v) = limits(g, &x, k);
                    let bound = if v + *d > max {
                        max
                    } else if v + *d < min {
                        min
                    } else {
                        continue;
                    };
                    // Move to the limit, hold there, solve the rest for what is left.
                    *d = bound - v;
                    for (link, e) in links.iter().zip(cols) {
                        if let Some(t) = target.get_mut(usize::from(link.slot)) {
                            *t -= e.get(k).copied().unwrap_or(Vec3::ZERO) * *d;
                        }
                    }
                    outer(&mut lin.a, links, cols, k, -*id);
                    *id = 0.0;
                    clamped = true;
                }
            }
            if !clamped {
                break;
            }
        }
        if !wake(slots, r, groups, lin) {
            return true;
        }
    }
    true
}

/// The limits of DOF `k` of a group and its current value.
#[inline]
fn limits(g: &Group, values: &[f32; 3], k: usize) -> (f32, f32, f32) {
    (
        g.min.get(k).copied().unwrap_or(0.0),
        g.max.get(k).copied().unwrap_or(0.0),
        values.get(k).copied().unwrap_or(0.0),
    )
}

/// Wakes every standby plane whose point the step would carry through the
/// plane (its residual becomes the distance to the plane); returns whether any
/// woke, so that the step is recomputed with it.
fn wake(slots: &mut Slots, r: &mut Rhs, groups: &[Group], lin: &Linear) -> bool {
    let mut woke = false;
    for (j, (slot, rj)) in slots
        .s
        .iter_mut()
        .zip(r.iter_mut())
        .take(slots.count)
        .enumerate()
    {
        if slot.sw != 0.0 || slot.kind != Kind::Plane {
            continue;
        }
        let mut ds = 0.0;
        for (g, ((p, axes), delta)) in groups.iter().zip(lin.geometry.iter().zip(lin.delta.iter()))
        {
            let (da, db) = (g.dep_a >> j & 1 != 0, g.dep_b >> j & 1 != 0);
            if da || db {
                for (w, d) in axes.iter().zip(delta).take(usize::from(g.count)) {
                    ds += derivative(slot, da, db, g.translation(), *w, *p).x * d;
                }
            }
        }
        if slot.gap + ds < 0.0 {
            slot.sw = slot.sw_full;
            *rj = Vec3::new(-slot.gap * slot.sw, 0.0, 0.0);
            slots.awake |= 1 << j;
            woke = true;
        }
    }
    woke
}

/// The current angles of a group's joint (zeros for the translation).
#[inline]
fn value<const N: usize>(work: &Work<'_, '_, N>, g: &Group) -> [f32; 3] {
    if g.translation() {
        return [0.0; 3];
    }
    work.angles
        .get(usize::from(g.seg))
        .copied()
        .unwrap_or([0.0; 3])
}

/// Applies a step, scaled to at most [`MAX_STEP`], clamped into the limits.
fn apply<const N: usize>(work: &mut Work<'_, '_, N>, groups: &[Group], delta: &PerDof) {
    let biggest = delta
        .iter()
        .take(groups.len())
        .flatten()
        .fold(0.0f32, |m, d| larger(m, math::abs(*d)));
    let scale = if biggest > MAX_STEP {
        MAX_STEP / biggest
    } else {
        1.0
    };
    for (g, d) in groups.iter().zip(delta) {
        if g.translation() {
            work.angles.root_position += Vec3::new(d[0], d[1], d[2]) * scale;
        } else if let Some(values) = work.angles.get_mut(usize::from(g.seg)) {
            for (((x, d), min), max) in values
                .iter_mut()
                .zip(d)
                .zip(&g.min)
                .zip(&g.max)
                .take(usize::from(g.count))
            {
                let moved = *x + d * scale;
                *x = if moved >= *max {
                    *max
                } else if moved >= *min {
                    moved
                } else {
                    *min
                };
            }
        }
    }
}

/// Weighted DLS over the whole reach tree; returns (iterations, converged).
pub(super) fn solve<const N: usize>(
    solver: &Solver,
    tree: &ReachTree<N>,
    work: &mut Work<'_, '_, N>,
) -> Result<(u32, bool), SolveError> {
    let wmax = work
        .goals
        .iter()
        .filter(|g| g.is_active())
        .fold(0.0f32, |m, g| larger(m, g.weight));
    if wmax <= 0.0 {
        return Ok((0, true));
    }
    let mut slots = Slots::new(work, wmax)?;
    let mut all = [Group::default(); MAX_GROUPS];
    let count = groups(solver, tree, work, &slots, &mut all);
    let groups = all.get(..count).unwrap_or(&[]);
    let moving = moving_segments(groups);
    let mut r: Rhs = [Vec3::ZERO; MAX_GOALS];
    let (mut error, mut worst) = slots.evaluate(work, &mut r)?;
    let tol2 = solver.tolerance * solver.tolerance;
    let mut lambda = larger(solver.damping, MIN_DAMPING);
    let mut lin = Linear {
        geometry: [(Vec3::ZERO, [Vec3::ZERO; 3]); MAX_GROUPS],
        links: Links::EMPTY,
        inv_d: [[0.0; 3]; MAX_GROUPS],
        delta: [[0.0; 3]; MAX_GROUPS],
        a: [[Mat3::ZERO; MAX_GOALS]; MAX_GOALS],
        l: [[Mat3::ZERO; MAX_GOALS]; MAX_GOALS],
    };
    let mut iterations = 0u32;
    let mut fresh = true;
    while iterations < u32::from(solver.max_iterations) {
        if worst <= tol2 || count == 0 {
            return Ok((iterations, true));
        }
        iterations += 1;
        if fresh {
            geometry(work, groups, &mut lin.geometry);
            lin.links.build(groups, &lin.geometry, &slots)?;
        }
        let awake = slots.awake;
        if !step(work, &mut slots, &mut r, groups, lambda * lambda, &mut lin) {
            lambda *= 4.0;
            fresh = false;
            continue;
        }
        let saved = (*work.angles, work.pose.positions, work.pose.rotations);
        apply(work, groups, &lin.delta);
        work.forward_segments(moving)?;
        let mut trial = slots.error(work)?;
        if trial < error {
            // Gauss–Newton underestimates steps where goals compress a limb:
            // when a step removed less than 3/4 of the error, try it once more
            // and keep it if it helps.
            if solver.extrapolate && trial > 0.25 * error {
                let kept = (*work.angles, work.pose.positions, work.pose.rotations);
                apply(work, groups, &lin.delta);
                work.forward_segments(moving)?;
                let further = slots.error(work)?;
                if further < trial {
                    trial = further;
                } else {
                    (*work.angles, work.pose.positions, work.pose.rotations) = kept;
                }
            }
            let stalled = error - trial <= STALL * error;
            (error, worst) = slots.evaluate(work, &mut r)?;
            lambda = larger(lambda / 3.0, MIN_DAMPING);
            fresh = true;
            if stalled {
                return Ok((iterations, true));
            }
        } else {
            (*work.angles, work.pose.positions, work.pose.rotations) = saved;
            if slots.awake != awake {
                // Planes woke for the rejected step: back to this state's rows.
                (error, worst) = slots.evaluate(work, &mut r)?;
                lin.links.build(groups, &lin.geometry, &slots)?;
            }
            lambda *= 4.0;
            fresh = false;
            if lambda > MAX_DAMPING {
                return Ok((iterations, true));
            }
        }
    }
    Ok((iterations, worst <= tol2))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn block_cholesky_matches_a_hand_solved_system() {
        // A = [[4,2,0 | 1,0,0],[2,5,1 | 0,1,0],[0,1,3 | 0,0,1] ; sym] + the 3×3
        // identity-like lower-right block diag(2,2,2); solve A·y = b and check
        // A·y = b by multiplying back with the original blocks.
        let a00 = Mat3::from_cols(
            Vec3::new(4.0, 2.0, 0.0),
            Vec3::new(2.0, 5.0, 1.0),
            Vec3::new(0.0, 1.0, 3.0),
        );
        let a10 = Mat3::IDENTITY;
        let a11 = Mat3::from_diagonal(Vec3::splat(2.0));
        let mut a: Blocks = [[Mat3::ZERO; MAX_GOALS]; MAX_GOALS];
        a[0][0] = a00;
        a[1][0] = a10;
        a[1][1] = a11;
        let b0 = Vec3::new(1.0, -2.0, 0.5);
        let b1 = Vec3::new(0.25, 3.0, -1.0);
        let mut y: Rhs = [Vec3::ZERO; MAX_GOALS];
        y[0] = b0;
        y[1] = b1;
        assert!(block_cholesky_solve(&mut a, 2, &mut y));
        let r0 = a00 * y[0] + a10.transpose() * y[1] - b0;
        let r1 = a10 * y[0] + a11 * y[1] - b1;
        assert!(r0.length() < 1e-5 && r1.length() < 1e-5, "{r0} {r1}");
    }

    #[test]
    fn chol3_rejects_indefinite() {
        assert!(chol3_inverse(Mat3::from_diagonal(Vec3::new(1.0, -1.0, 1.0))).is_none());
        let inv = chol3_inverse(Mat3::from_diagonal(Vec3::new(4.0, 9.0, 16.0))).unwrap();
        assert!((inv.x_axis.x - 0.5).abs() < 1e-6 && (inv.z_axis.z - 0.25).abs() < 1e-6);
    }
}
