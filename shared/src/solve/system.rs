//! One Levenberg–Marquardt step of the whole-tree solver, in goal space:
//!
//! ```text
//! Δ = D⁻¹·J̃ᵀ·y,   (J̃·D⁻¹·J̃ᵀ + I)·y = r̃,
//! ```
//!
//! which equals `(J̃ᵀJ̃ + D)⁻¹·J̃ᵀ·r̃` (push-through identity) but needs only a
//! block Cholesky factorisation of `k × k` blocks of 3×3 for `k` goals, far
//! smaller than the number of joints.
//!
//! `D_i = λ²·((J̃ᵀJ̃)ᵢᵢ + μ²) + s_i`: Marquardt's scaling, so radians and
//! metres are damped alike, with a floor `μ` (a lever of [`LEVER`]): a DOF
//! whose axis passes close to the goals it moves would otherwise be almost
//! free, and a large turn of it spoils the linear model. `s_i ≥ 0` is the
//! diagonal of the second-order term that Gauss–Newton leaves out, for the
//! goals that the last step did not bring much closer (see
//! [`super::joints`]); without it, unreachable goals converge very slowly.
//!
//! Joint limits: a DOF on a limit that the gradient pushes outwards is held; a
//! DOF that the step would carry through a limit moves only to the limit and
//! is held, its motion is taken out of the residual and the others are solved
//! again (a few rounds). A satisfied one-sided plane waits on standby and joins
//! the step only if the step would carry its point through the plane.

use super::Work;
use super::joints::{Dofs, Joints, Link, entry, geometry, links_of};
use super::slots::{MAX_GOALS, Rhs, Slots};
use crate::math;
use glam::{Mat3, Vec3};

/// Rounds of clamping variables that a step would push through a limit.
pub(super) const CLAMP_PASSES: usize = 3;
/// The damping floor's lever, m: below it a DOF is damped as if its goals
/// were this far from its axis.
const LEVER: f32 = 0.1;

/// Blocks of the packed lower block triangle.
const BLOCKS: usize = MAX_GOALS * (MAX_GOALS + 1) / 2;

/// The lower block triangle of `J̃·D⁻¹·J̃ᵀ + I`, packed by rows: block
/// `(t, s)`, `s ≤ t`, at `t·(t+1)/2 + s`; and its factor.
pub(super) struct System {
    a: [Mat3; BLOCKS],
    /// The factor of `a` ([`factor`]).
    l: [Mat3; BLOCKS],
    /// The solution `y` of a clamping round.
    y: Rhs,
    /// Bit `s` of entry `t`: block `(t, s)` of the factor may be nonzero
    /// (the goals share a moving joint, or fill-in).
    coupled: Coupling,
    /// The awake slots and the unmet slots (which decide the live groups)
    /// `coupled` was found for, with the current joint layout (`None`: not
    /// yet).
    coupled_for: Option<(u16, u16)>,
    /// Bit `j`: slot `j` takes part.
    awake: u16,
    /// The work of the last [`System::step`]: its rounds, its
    /// factorisation passes, and whether it found the coupling again.
    pub work: (usize, usize, bool),
    /// The most work of a factorisation for this layout: its off-diagonal
    /// blocks and its block products when every goal is awake and every
    /// group live ([`System::forget`]).
    pub most: (usize, usize),
}

/// Per block row, the blocks that may be nonzero.
type Coupling = [u16; MAX_GOALS];

/// The index of block `(t, s)`, `s ≤ t`.
#[inline]
fn at(t: usize, s: usize) -> usize {
    t * (t + 1) / 2 + s
}

impl System {
    /// An empty system.
    pub const EMPTY: Self = System {
        a: [Mat3::ZERO; BLOCKS],
        l: [Mat3::ZERO; BLOCKS],
        y: [Vec3::ZERO; MAX_GOALS],
        coupled: [0; MAX_GOALS],
        coupled_for: None,
        awake: 0,
        work: (0, 0, false),
        most: (0, 0),
    };

    /// Forgets the coupling: the joint layout changed. Finds the most work
    /// of a factorisation for the new layout (`n` goals): the coupling of
    /// all goals through all groups bounds that of any goals awake through
    /// any groups live.
    pub fn forget<const N: usize>(&mut self, joints: &Joints<N>, n: usize) {
        self.coupled_for = None;
        let mut all: Coupling = [0; MAX_GOALS];
        for g in joints.groups() {
            let moves = g.dep_a | g.dep_b;
            let mut bits = moves;
            while bits != 0 {
                let t = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                if let Some(c) = all.get_mut(t) {
                    *c |= moves & ((2u16 << t) - 1);
                }
            }
        }
        fill_in(&mut all, n);
        let (mut blocks, mut products) = (0, 0);
        for (s, &cs) in all.iter().enumerate().take(n) {
            let mut below = cs & ((1u16 << s) - 1);
            blocks += below.count_ones() as usize;
            while below != 0 {
                let k = below.trailing_zeros() as usize;
                below &= below - 1;
                let ck = all.get(k).copied().unwrap_or(0);
                products += (cs & ck & ((1u16 << k) - 1)).count_ones() as usize;
            }
        }
        self.most = (blocks, products);
    }

    /// Computes the step (each group's `delta`) at damping `λ²` for the
    /// linearisation in `joints` and the residuals in `slots` (scaled into
    /// `r`, scratch kept by the caller, left less the motion of the DOFs held
    /// at a limit), in at most `plan = (rounds, passes per round)` (a woken
    /// plane takes a second round; a clamped limit another pass); false if
    /// the system is singular.
    pub fn step<const N: usize>(
        &mut self,
        work: &Work<'_, '_, N>,
        joints: &mut Joints<N>,
        slots: &Slots,
        r: &mut Rhs,
        lambda2: f32,
        (rounds, passes): (usize, usize),
    ) -> bool {
        slots.rhs(r);
        self.awake = slots.awake() & joints.reach;
        self.work = (0, 0, false);
        for round in 0..rounds.min(2) {
            self.work.0 += 1;
            if round > 0 {
                joints.sums(slots, self.awake, r);
            }
            self.assemble(joints, slots.count, lambda2);
            if !self.solve(joints, slots.count, r, passes) {
                return false;
            }
            let awake = self.awake;
            if !self.wake(work, joints, slots, r) {
                break;
            }
            // The residuals again where the clamping took out the motion of
            // held DOFs (only the awake goals'; the woken ones are new).
            for (j, (rj, slot)) in r.iter_mut().zip(slots.iter()).enumerate() {
                if awake >> j & 1 != 0 {
                    *rj = slot.r * slot.sw;
                }
            }
        }
        true
    }

    /// Solves for the step, clamping at the limits (at most `passes`, and
    /// [`CLAMP_PASSES`]; the motion of the DOFs held at a limit is taken out
    /// of `r`); false if the matrix is singular.
    fn solve<const N: usize>(
        &mut self,
        joints: &mut Joints<N>,
        n: usize,
        r: &mut Rhs,
        passes: usize,
    ) -> bool {
        let n = n.min(MAX_GOALS);
        let passes = passes.clamp(1, CLAMP_PASSES);
        for pass in 0..passes {
            self.work.1 += 1;
            if !factor(&self.a, &mut self.l, &self.coupled, n, r, &mut self.y)
                || !substitute(&self.l, &self.coupled, n, &mut self.y)
            {
                return false;
            }
            let last = pass + 1 == passes;
            if !spread(joints, &mut self.a, self.awake, &self.y, r, last) {
                break;
            }
        }
        true
    }

    /// Every DOF's damping ([`damp`]) and `J̃·D⁻¹·J̃ᵀ + I` over the DOFs
    /// that take part.
    fn assemble<const N: usize>(&mut self, joints: &mut Joints<N>, n: usize, lambda2: f32) {
        // Which goals share a joint depends only on the layout and the
        // awake goals.
        let key = (self.awake, joints.unmet());
        let known = self.coupled_for == Some(key);
        // The blocks the factorisation reads start at the identity (with a
        // known coupling, only those: the others are never read).
        for t in 0..n {
            let row = self.coupled.get(t).copied().unwrap_or(0);
            for s in 0..=t {
                if let Some(b) = self.a.get_mut(at(t, s)) {
                    if s == t {
                        *b = Mat3::IDENTITY;
                    } else if !known || row >> s & 1 != 0 {
                        *b = Mat3::ZERO;
                    }
                }
            }
        }
        if !known {
            self.coupled = [0; MAX_GOALS];
        }
        let (groups, dofs, links) = joints.parts();
        for (g, d) in groups.iter().zip(dofs) {
            if !g.live {
                continue;
            }
            damp(d, lambda2);
            let links = links_of(links, g);
            outer(&mut self.a, links, self.awake, d.inv_d);
            if !known {
                couple(&mut self.coupled, g.dep_a | g.dep_b, self.awake);
            }
        }
        if !known {
            fill_in(&mut self.coupled, n);
            self.coupled_for = Some(key);
            self.work.2 = true;
        }
    }

    /// Wakes every standby plane whose point the step would carry through the
    /// plane (its residual becomes the distance to the plane); returns whether
    /// any woke, so that the step is recomputed with it.
    fn wake<const N: usize>(
        &mut self,
        work: &Work<'_, '_, N>,
        joints: &Joints<N>,
        slots: &Slots,
        r: &mut Rhs,
    ) -> bool {
        let mut woke = false;
        for (j, (slot, rj)) in slots.iter().zip(r.iter_mut()).enumerate() {
            // Awake, or moved by no live group: nothing to wake.
            if self.awake >> j & 1 != 0 || joints.reach >> j & 1 == 0 {
                continue;
            }
            let mut ds = 0.0;
            for (g, d) in joints.groups().iter().zip(&joints.dofs) {
                if !g.live {
                    continue;
                }
                let (da, db) = (g.dep_a >> j & 1 != 0, g.dep_b >> j & 1 != 0);
                if da || db {
                    let (p, axes) = geometry(work, g);
                    for (w, d) in axes.iter().zip(d.delta.to_array()) {
                        ds += entry(slot, da, db, g.translation(), *w, p).x * d;
                    }
                }
            }
            if slot.gap + ds < 0.0 {
                self.awake |= 1 << j;
                *rj = Vec3::new(-slot.gap * slot.sw, 0.0, 0.0);
                woke = true;
            }
        }
        woke
    }
}

/// A group's `1 / D` per DOF (0 for one held at a limit that the gradient
/// pushes outwards); a zero step. A DOF a group does not have has a zero
/// column and moves nothing.
#[inline(always)]
fn damp(d: &mut Dofs, lambda2: f32) {
    let floor = LEVER * LEVER * lambda2;
    let damping = d.curvature * lambda2 + Vec3::splat(floor * d.lever) + d.tension;
    let inv = |damping: f32, grad: f32, lo: f32, hi: f32| {
        // Held: on a limit (within 1e-6) that the gradient pushes through.
        let held = (hi <= 1e-6 && grad > 0.0) || (lo >= -1e-6 && grad < 0.0);
        if held { 0.0 } else { 1.0 / (damping + 1e-12) }
    };
    let (g, lo, hi) = (d.grad, d.lo, d.hi);
    d.inv_d = Vec3::new(
        inv(damping.x, g.x, lo.x, hi.x),
        inv(damping.y, g.y, lo.y, hi.y),
        inv(damping.z, g.z, lo.z, hi.z),
    );
    d.delta = Vec3::ZERO;
}

/// The step `D⁻¹·J̃ᵀ·y` of every DOF that takes part; unless `last`, DOFs
/// that would cross a limit move to it and stop taking part, their motion
/// taken out of `target` and their columns out of `a`. Returns whether any
/// was clamped.
fn spread<const N: usize>(
    joints: &mut Joints<N>,
    a: &mut [Mat3],
    awake: u16,
    y: &Rhs,
    target: &mut Rhs,
    last: bool,
) -> bool {
    let mut clamped = false;
    let (groups, dofs, links) = joints.parts();
    for (g, d) in groups.iter().zip(dofs) {
        if !g.live {
            continue;
        }
        let links = links_of(links, g);
        let mut cy = Vec3::ZERO;
        for l in links.iter().filter(|l| awake >> l.slot & 1 != 0) {
            cy += l.cols.transpose() * y.get(usize::from(l.slot)).copied().unwrap_or(Vec3::ZERO);
        }
        let step = cy * d.inv_d;
        let free = |id: f32, step: f32, old: f32| if id == 0.0 { old } else { step };
        d.delta = Vec3::new(
            free(d.inv_d.x, step.x, d.delta.x),
            free(d.inv_d.y, step.y, d.delta.y),
            free(d.inv_d.z, step.z, d.delta.z),
        );
        if last {
            continue;
        }
        // Move to the limit, hold there, solve the rest for what is left.
        let (x, lo, hi, id) = (d.delta, d.lo, d.hi, d.inv_d);
        let inside = |x: f32, lo: f32, hi: f32| x <= hi && x >= lo;
        if inside(x.x, lo.x, hi.x) && inside(x.y, lo.y, hi.y) && inside(x.z, lo.z, hi.z) {
            // Mostly so: nothing crosses a limit.
            continue;
        }
        let over = |id: f32, x: f32, lo: f32, hi: f32| id != 0.0 && (x > hi || x < lo);
        let out = Vec3::new(
            if over(id.x, x.x, lo.x, hi.x) {
                id.x
            } else {
                0.0
            },
            if over(id.y, x.y, lo.y, hi.y) {
                id.y
            } else {
                0.0
            },
            if over(id.z, x.z, lo.z, hi.z) {
                id.z
            } else {
                0.0
            },
        );
        if out == Vec3::ZERO {
            continue;
        }
        let bound = |o: f32, x: f32, lo: f32, hi: f32| {
            if o == 0.0 {
                (x, 0.0)
            } else {
                let b = if x > hi { hi } else { lo };
                (b, b)
            }
        };
        let (bx, mx) = bound(out.x, x.x, lo.x, hi.x);
        let (by, my) = bound(out.y, x.y, lo.y, hi.y);
        let (bz, mz) = bound(out.z, x.z, lo.z, hi.z);
        (d.delta, d.inv_d) = (Vec3::new(bx, by, bz), d.inv_d - out);
        let moved = Vec3::new(mx, my, mz);
        for l in links.iter().filter(|l| awake >> l.slot & 1 != 0) {
            if let Some(t) = target.get_mut(usize::from(l.slot)) {
                *t -= l.cols * moved;
            }
        }
        outer(a, links, awake, -out);
        clamped = true;
    }
    clamped
}

/// Marks the blocks that a group moving the slots `moves` makes nonzero
/// among the awake ones (a live group has a link to every slot it moves).
/// Out of line: inlined into the assembly, it made the live loop's frames
/// (where the coupling is mostly known) take more instructions.
#[inline(never)]
fn couple(coupled: &mut Coupling, moves: u16, awake: u16) {
    let mask = moves & awake;
    let mut bits = mask;
    while bits != 0 {
        let t = bits.trailing_zeros() as usize;
        bits &= bits - 1;
        if let Some(c) = coupled.get_mut(t) {
            // The lower triangle: slots up to this one.
            *c |= mask & ((2u16 << t) - 1);
        }
    }
}

/// Adds the fill-in of the factorisation: `L_ts` may be nonzero if some
/// `k < s` has both `L_tk` and `L_sk` nonzero.
fn fill_in(coupled: &mut Coupling, n: usize) {
    for t in 0..n {
        for s in 0..t {
            let (Some(&ct), Some(&cs)) = (coupled.get(t), coupled.get(s)) else {
                continue;
            };
            if ct & cs & ((1u16 << s) - 1) != 0
                && let Some(c) = coupled.get_mut(t)
            {
                *c |= 1 << s;
            }
        }
    }
}

/// `a += C_t·diag(d)·C_sᵀ` on the lower block triangle, for every pair of a
/// group's links to awake slots (links ascend by slot). Of a diagonal block
/// only the lower triangle is kept: [`chol3_inverse`] reads no more.
#[inline(always)]
fn outer(a: &mut [Mat3], links: &[Link], awake: u16, d: Vec3) {
    for (i, lt) in links.iter().enumerate() {
        if awake >> lt.slot & 1 == 0 {
            continue;
        }
        let t = usize::from(lt.slot);
        let c = lt.cols;
        let (u0, u1, u2) = (c.x_axis * d.x, c.y_axis * d.y, c.z_axis * d.z);
        for ls in links.iter().take(i) {
            if awake >> ls.slot & 1 == 0 {
                continue;
            }
            let (c0, c1, c2) = (ls.cols.x_axis, ls.cols.y_axis, ls.cols.z_axis);
            if let Some(b) = a.get_mut(at(t, usize::from(ls.slot))) {
                b.x_axis += u0 * c0.x + u1 * c1.x + u2 * c2.x;
                b.y_axis += u0 * c0.y + u1 * c1.y + u2 * c2.y;
                b.z_axis += u0 * c0.z + u1 * c1.z + u2 * c2.z;
            }
        }
        if let Some(b) = a.get_mut(at(t, t)) {
            let (c0, c1, c2) = (c.x_axis, c.y_axis, c.z_axis);
            b.x_axis += u0 * c0.x + u1 * c1.x + u2 * c2.x;
            b.y_axis.y += u0.y * c0.y + u1.y * c1.y + u2.y * c2.y;
            b.y_axis.z += u0.z * c0.y + u1.z * c1.y + u2.z * c2.y;
            b.z_axis.z += u0.z * c0.z + u1.z * c1.z + u2.z * c2.z;
        }
    }
}

/// `1 / √x` ([`math::rsqrt`], whose special cases only `+∞` reaches here) of
/// a pivot above 1e-20; `None` for a smaller one or NaN.
#[inline(always)]
fn pivot(x: f32) -> Option<f32> {
    if x > 1e-20 {
        Some(if x < f32::INFINITY {
            math::rsqrt_normal(x)
        } else {
            0.0
        })
    } else {
        None
    }
}

/// Cholesky of a symmetric positive definite 3×3 matrix: the inverse of its
/// lower factor, or `None`.
fn chol3_inverse(m: Mat3) -> Option<Mat3> {
    let (a00, a10, a20) = (m.x_axis.x, m.x_axis.y, m.x_axis.z);
    let (a11, a21, a22) = (m.y_axis.y, m.y_axis.z, m.z_axis.z);
    let i00 = pivot(a00)?;
    let (l10, l20) = (a10 * i00, a20 * i00);
    let d1 = a11 - l10 * l10;
    let i11 = pivot(d1)?;
    let l21 = (a21 - l20 * l10) * i11;
    let d2 = a22 - l20 * l20 - l21 * l21;
    let i22 = pivot(d2)?;
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

/// The block Cholesky factor `L` of the packed lower block triangle `a` (`n`
/// block rows, only the blocks marked in `coupled` nonzero) into `l`: the
/// factor's blocks where `coupled` marks them, the inverse on the diagonal;
/// and, row by row, the solution `z` of `L·z = b` into `y`. False if `A` is
/// not numerically positive definite.
fn factor(a: &[Mat3], l: &mut [Mat3], coupled: &Coupling, n: usize, b: &Rhs, y: &mut Rhs) -> bool {
    let mut rows = a;
    let mut start = 0;
    for s in 0..n {
        let (Some((row_a, rest)), Some((done, tail)), Some(&cs), Some((head, z))) = (
            rows.split_at_checked(s + 1),
            l.split_at_mut_checked(start),
            coupled.get(s),
            y.split_at_mut_checked(s),
        ) else {
            return false;
        };
        rows = rest;
        start += s + 1;
        let Some(row_s) = tail.get_mut(..=s) else {
            return false;
        };
        // Off-diagonal blocks of row s: L_sk = (A_sk − Σ_{j<k} L_sj·L_kjᵀ)·L_kk⁻ᵀ.
        let below = cs & ((1u16 << s) - 1);
        let mut bits = below;
        while bits != 0 {
            let k = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let (Some(row_k), Some((left, x)), Some(&ck), Some(&ask)) = (
                done.get(at(k, 0)..=at(k, k)),
                row_s.split_at_mut_checked(k),
                coupled.get(k),
                row_a.get(k),
            ) else {
                return false;
            };
            let mut acc = ask;
            let mut both = cs & ck & ((1u16 << k) - 1);
            while both != 0 {
                let j = both.trailing_zeros() as usize;
                both &= both - 1;
                if let (Some(lsj), Some(lkj)) = (left.get(j), row_k.get(j)) {
                    acc -= *lsj * lkj.transpose();
                }
            }
            let (Some(x), Some(inv_kk)) = (x.first_mut(), row_k.last()) else {
                return false;
            };
            *x = acc * inv_kk.transpose();
        }
        // Diagonal: L_ss·L_ssᵀ = A_ss − Σ_k L_sk·L_skᵀ; keep L_ss⁻¹. And
        // z_s = L_ss⁻¹·(b_s − Σ_k L_sk·z_k).
        let (Some((x, left)), Some(&ass), Some(&bs), Some(zs)) = (
            row_s.split_last_mut(),
            row_a.get(s),
            b.get(s),
            z.first_mut(),
        ) else {
            return false;
        };
        let (mut acc, mut v) = (ass, bs);
        let mut bits = below;
        while bits != 0 {
            let k = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            if let (Some(l), Some(zk)) = (left.get(k), head.get(k)) {
                acc -= *l * l.transpose();
                v -= *l * *zk;
            }
        }
        let Some(inv) = chol3_inverse(acc) else {
            return false;
        };
        (*x, *zs) = (inv, inv * v);
    }
    true
}

/// Solves `Lᵀ·y = z` in place for the first `n` entries, with the factor `l`
/// and the `z` of [`factor`].
fn substitute(l: &[Mat3], coupled: &Coupling, n: usize, y: &mut Rhs) -> bool {
    let Some(mut rows) = l.get(..at(n, 0)) else {
        return false;
    };
    for s in (0..n).rev() {
        let (Some((rest, row)), Some((head, tail)), Some(&cs)) = (
            rows.split_at_checked(at(s, 0)),
            y.split_at_mut_checked(s),
            coupled.get(s),
        ) else {
            return false;
        };
        rows = rest;
        let (Some(x), Some(inv)) = (tail.first_mut(), row.last()) else {
            return false;
        };
        *x = inv.transpose() * *x;
        let ys = *x;
        let mut bits = cs & ((1u16 << s) - 1);
        while bits != 0 {
            let k = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            if let (Some(bk), Some(l)) = (head.get_mut(k), row.get(k)) {
                *bk -= l.transpose() * ys;
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::{Angles, cmu};
    use crate::goal::Goal;
    use crate::pose::Pose;
    use crate::solve::Work;
    use crate::solve::joints::laid_out;

    /// The coupling [`System::assemble`] finds from each live group's goal
    /// mask is the one its links give: for every awake pair of slots `s ≤
    /// t`, marked exactly when one live group has links to both (before
    /// fill-in), checked pair by pair on the CMU skeleton with a point goal
    /// in a segment's frame, some goals met and some asleep.
    #[test]
    fn coupling_from_goal_masks_is_that_of_the_links() {
        let body = cmu::BODY;
        let mut angles = Angles::<32>::rest(&body).unwrap();
        let mut pose = Pose::<32>::default();
        let goals = [
            Goal::reach(cmu::index::LEFT_HAND, Vec3::new(0.3, 1.0, 0.2), 1.0),
            Goal::reach(cmu::index::RIGHT_HAND, Vec3::new(-0.3, 1.0, 0.2), 2.0).in_frame(1),
            Goal::reach(cmu::index::LEFT_FOOT, Vec3::new(0.1, 0.0, 0.1), 4.0),
            Goal::reach(cmu::index::RIGHT_FOOT, Vec3::new(-0.1, 0.0, 0.1), 1.0),
        ];
        let mut work = Work::new(&body, &goals, &mut angles, &mut pose);
        let (mut slots, mut joints) = laid_out(&mut work, 4.0);
        let mut checked = 0;
        for (met, awake) in [(0u16, 0b1111u16), (0b0100, 0b1011), (0b1001, 0b0110)] {
            for (j, slot) in slots.s.iter_mut().enumerate().take(4) {
                // A met goal: its residual within the tolerance.
                if met >> j & 1 != 0 {
                    slot.r = Vec3::ZERO;
                }
            }
            joints.settle(&slots, 1e-8);
            joints.linearise(&work, &slots).unwrap();
            let mut system = System::EMPTY;
            system.awake = awake;
            system.assemble(&mut joints, 4, 0.01);
            let links = &joints.links;
            let mut direct = [0u16; MAX_GOALS];
            for g in joints.groups().iter().filter(|g| g.live) {
                couple(&mut direct, g.dep_a | g.dep_b, awake);
            }
            for (t, &row) in direct.iter().enumerate().take(4) {
                for s in 0..=t {
                    let both = awake >> s & 1 != 0 && awake >> t & 1 != 0;
                    let shared = joints.groups().iter().filter(|g| g.live).any(|g| {
                        let of = links_of(links, g);
                        of.iter().any(|l| usize::from(l.slot) == s)
                            && of.iter().any(|l| usize::from(l.slot) == t)
                    });
                    assert_eq!(row >> s & 1 != 0, both && shared, "({t}, {s})");
                    if both && shared {
                        assert!(system.coupled[t] >> s & 1 != 0, "({t}, {s})");
                    }
                    checked += 1;
                }
            }
        }
        assert_eq!(checked, 30);
    }

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
        let mut a = [Mat3::ZERO; MAX_GOALS * (MAX_GOALS + 1) / 2];
        a[at(0, 0)] = a00;
        a[at(1, 0)] = a10;
        a[at(1, 1)] = a11;
        let b0 = Vec3::new(1.0, -2.0, 0.5);
        let b1 = Vec3::new(0.25, 3.0, -1.0);
        let mut b: Rhs = [Vec3::ZERO; MAX_GOALS];
        b[0] = b0;
        b[1] = b1;
        let coupled = [0b01, 0b11, 0, 0, 0, 0, 0, 0, 0, 0];
        let mut l = [Mat3::ZERO; BLOCKS];
        let mut y: Rhs = [Vec3::ZERO; MAX_GOALS];
        assert!(factor(&a, &mut l, &coupled, 2, &b, &mut y));
        assert!(substitute(&l, &coupled, 2, &mut y));
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
