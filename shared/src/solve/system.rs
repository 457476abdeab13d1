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
//!
//! The warm active set: a DOF that the last step carried through a limit is
//! *pinned* there ([`Dofs::pin`](super::joints::Dofs)). While that limit is
//! within [`PIN_ROOM`], a next step whose plan affords fewer than
//! [`CLAMP_PASSES`] passes (a live frame's budget) starts with the DOF
//! moved to it and held, its motion taken out of the residual, as a
//! clamping round would leave it; it is let go when its own step from the
//! others' solution, `(J̃ᵀ·y)ᵢ / Dᵢ`, no longer crosses the limit (the
//! bounded step's Karush–Kuhn–Tucker condition).
//!
//! Successive steps on a moving puppet mostly meet the same limits, so one
//! factorisation pass usually finds the step that took several rounds of
//! clamping; a live frame whose budget affords one pass
//! ([`crate::deadline`]) still converges over frames. A step with all its
//! passes finds the active set by clamping, as without pins, and only
//! records them: pins held from the start of every step made some offline
//! solves converge worse (`tests/cli_solve.rs`).

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
/// How near its limit a pinned DOF must be to start the step there, rad
/// (or m): farther, the pose has moved off the limit since, and it takes
/// part as any other.
const PIN_ROOM: f32 = 0.05;

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
            let pins = passes < CLAMP_PASSES;
            self.assemble(joints, (slots.count, lambda2, pins), r);
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
    /// of `r`) for `n` goals; false if the matrix is singular.
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
    /// that take part for `n` goals at damping `λ²`; with `pins`, the pinned
    /// DOFs start at their limits, their motion taken out of `r`.
    fn assemble<const N: usize>(
        &mut self,
        joints: &mut Joints<N>,
        (n, lambda2, pins): (usize, f32, bool),
        r: &mut Rhs,
    ) {
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
            if d.pinned {
                let moved = start_pinned(d, pins);
                if moved != Vec3::ZERO {
                    take_out(links, self.awake, moved, r);
                }
            }
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

/// After [`damp`], with `pins`, moves each DOF pinned near its limit
/// ([`PIN_ROOM`]) to it and holds it there, keeping its `1 / D` for the KKT
/// test ([`repin`]); returns the motion.
#[inline(never)]
fn start_pinned(d: &mut Dofs, pins: bool) -> Vec3 {
    if !pins {
        d.held_inv = Vec3::ZERO;
        return Vec3::ZERO;
    }
    // (1 / D, 1 / D kept for the KKT test, step).
    let at = |pin: f32, inv: f32, lo: f32, hi: f32| {
        if pin > 0.0 && hi <= PIN_ROOM {
            (0.0, inv, math::max(hi, 0.0))
        } else if pin < 0.0 && lo >= -PIN_ROOM {
            (0.0, inv, math::min(lo, 0.0))
        } else {
            (inv, 0.0, 0.0)
        }
    };
    let (p, id, lo, hi) = (d.pin, d.inv_d, d.lo, d.hi);
    let (x, y, z) = (
        at(p.x, id.x, lo.x, hi.x),
        at(p.y, id.y, lo.y, hi.y),
        at(p.z, id.z, lo.z, hi.z),
    );
    d.inv_d = Vec3::new(x.0, y.0, z.0);
    d.held_inv = Vec3::new(x.1, y.1, z.1);
    d.delta = Vec3::new(x.2, y.2, z.2);
    d.delta
}

/// Takes the motion `moved` of a group's DOFs out of the awake slots'
/// residuals in `target`.
#[inline(always)]
fn take_out(links: &[Link], awake: u16, moved: Vec3, target: &mut Rhs) {
    for l in links.iter().filter(|l| awake >> l.slot & 1 != 0) {
        if let Some(t) = target.get_mut(usize::from(l.slot)) {
            *t -= l.cols * moved;
        }
    }
}

/// Each DOF's pin after a pass ([`Dofs::pin`](super::joints::Dofs)), from
/// its step and `cy = J̃ᵀ·y`. Only for a group with a pin or a step through
/// a limit: otherwise none is pinned and none becomes so.
#[inline(always)]
fn repin(d: &mut Dofs, cy: Vec3) {
    // A pinned DOF's step from the others' solution, `cy / D`: pinned while
    // it is through the limit, the bounded step's KKT condition (`cy > D·hi`
    // at an upper limit).
    let free = cy * d.held_inv;
    let (p, id, held, x, lo, hi) = (d.pin, d.inv_d, d.held_inv, d.delta, d.lo, d.hi);
    d.pin = Vec3::new(
        pin_of((p.x, id.x, held.x), (x.x, free.x), (lo.x, hi.x)),
        pin_of((p.y, id.y, held.y), (x.y, free.y), (lo.y, hi.y)),
        pin_of((p.z, id.z, held.z), (x.z, free.z), (lo.z, hi.z)),
    );
    d.pinned = d.pin != Vec3::ZERO;
}

/// A DOF's pin after a pass: one that takes part (`id ≠ 0`) is pinned where
/// its step `x` crosses a limit; one pinned and held (`held`: its `1 / D`)
/// stays so while its step from the others' solution, `free`, is through
/// that limit, and is let go otherwise; one held by the gradient ([`damp`])
/// keeps its pin.
#[inline(always)]
fn pin_of((pin, id, held): (f32, f32, f32), (x, free): (f32, f32), (lo, hi): (f32, f32)) -> f32 {
    let through = |x: f32| {
        if x > hi {
            1.0
        } else if x < lo {
            -1.0
        } else {
            0.0
        }
    };
    if id != 0.0 {
        through(x)
    } else if held == 0.0 || through(free) == pin {
        pin
    } else {
        0.0
    }
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
        let (x, lo, hi, id) = (d.delta, d.lo, d.hi, d.inv_d);
        let inside = |x: f32, lo: f32, hi: f32| x <= hi && x >= lo;
        let within = inside(x.x, lo.x, hi.x) && inside(x.y, lo.y, hi.y) && inside(x.z, lo.z, hi.z);
        if !within || d.pinned {
            repin(d, cy);
        }
        // Mostly so: nothing crosses a limit.
        if last || within {
            continue;
        }
        // Move to the limit, hold there, solve the rest for what is left.
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
        take_out(links, awake, Vec3::new(mx, my, mz), target);
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
        let goals = four_goals();
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
            system.assemble(&mut joints, (4, 0.01, false), &mut [Vec3::ZERO; MAX_GOALS]);
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

    /// Both hands and both feet of the CMU skeleton, one in another
    /// segment's frame.
    fn four_goals() -> [Goal; 4] {
        [
            Goal::reach(cmu::index::LEFT_HAND, Vec3::new(0.3, 1.0, 0.2), 1.0),
            Goal::reach(cmu::index::RIGHT_HAND, Vec3::new(-0.3, 1.0, 0.2), 2.0).in_frame(1),
            Goal::reach(cmu::index::LEFT_FOOT, Vec3::new(0.1, 0.0, 0.1), 4.0),
            Goal::reach(cmu::index::RIGHT_FOOT, Vec3::new(-0.1, 0.0, 0.1), 1.0),
        ]
    }

    /// Columns of the dense reference below (the CMU path's DOFs).
    const COLS: usize = 96;
    /// Its rows: three per slot.
    const ROWS: usize = 3 * MAX_GOALS;

    /// Solves `m·x = v` (the first `n` unknowns) by Gaussian elimination
    /// with partial pivoting, in `f64`: the slow, obvious reference.
    fn eliminate(m: &mut [[f64; COLS]; COLS], v: &mut [f64; COLS], n: usize) -> [f64; COLS] {
        for k in 0..n {
            let p = (k..n)
                .max_by(|&a, &b| m[a][k].abs().total_cmp(&m[b][k].abs()))
                .unwrap();
            m.swap(k, p);
            v.swap(k, p);
            let pivot = m[k];
            for i in k + 1..n {
                let f = m[i][k] / pivot[k];
                for (x, &y) in m[i].iter_mut().zip(&pivot).take(n).skip(k) {
                    *x -= f * y;
                }
                v[i] -= f * v[k];
            }
        }
        let mut x = [0.0; COLS];
        for k in (0..n).rev() {
            let tail: f64 = (k + 1..n).map(|j| m[k][j] * x[j]).sum();
            x[k] = (v[k] - tail) / m[k][k];
        }
        x
    }

    /// The damped least-squares step of the DOFs that take part with those
    /// held where the step left them, built densely from the links:
    /// `(J_Fᵀ·J_F + D_F)·Δ_F = J_Fᵀ·(r̃ − J_H·Δ_H)`, with `D_F = 1 / inv_d`.
    /// Returns the largest difference from the step in `joints`, relative
    /// to the largest step.
    fn dense_step<const N: usize>(joints: &mut Joints<N>, slots: &Slots, awake: u16) -> f64 {
        let mut j = [[0.0f64; COLS]; ROWS];
        let (mut held, mut d, mut got) = ([false; COLS], [0.0f64; COLS], [0.0f64; COLS]);
        let mut n = 0;
        let (groups, dofs, links) = joints.parts();
        for (g, dof) in groups.iter().zip(dofs.iter()).filter(|(g, _)| g.live) {
            for k in 0..usize::from(g.count) {
                for l in links_of(links, g)
                    .iter()
                    .filter(|l| awake >> l.slot & 1 != 0)
                {
                    let c = l.cols.col(k);
                    for (row, x) in c.to_array().into_iter().enumerate() {
                        j[3 * usize::from(l.slot) + row][n] = f64::from(x);
                    }
                }
                let id = dof.inv_d.to_array()[k];
                (held[n], got[n]) = (id == 0.0, f64::from(dof.delta.to_array()[k]));
                d[n] = if id == 0.0 { 0.0 } else { 1.0 / f64::from(id) };
                n += 1;
            }
        }
        // r̃ less the held DOFs' motion.
        let mut b = [0.0f64; ROWS];
        for (t, slot) in slots
            .iter()
            .enumerate()
            .filter(|(t, _)| awake >> t & 1 != 0)
        {
            for (row, x) in (slot.r * slot.sw).to_array().into_iter().enumerate() {
                b[3 * t + row] = f64::from(x);
            }
        }
        for (row, bi) in b.iter_mut().enumerate() {
            *bi -= (0..n)
                .filter(|&c| held[c])
                .map(|c| j[row][c] * got[c])
                .sum::<f64>();
        }
        // The normal equations of the free DOFs (held ones: x = their step).
        let (mut m, mut v) = ([[0.0f64; COLS]; COLS], [0.0f64; COLS]);
        for a in 0..n {
            if held[a] {
                (m[a][a], v[a]) = (1.0, got[a]);
                continue;
            }
            for c in (0..n).filter(|&c| !held[c]) {
                m[a][c] = (0..ROWS).map(|row| j[row][a] * j[row][c]).sum();
            }
            m[a][a] += d[a];
            v[a] = (0..ROWS).map(|row| j[row][a] * b[row]).sum();
        }
        let x = eliminate(&mut m, &mut v, n);
        let big = (0..n).map(|c| x[c].abs()).fold(0.0, f64::max);
        (0..n).map(|c| (x[c] - got[c]).abs()).fold(0.0, f64::max) / big
    }

    /// The warm active set ([`PIN_ROOM`]): with every joint 0.02 rad from
    /// both its limits, a step of three clamping passes pins the DOFs it
    /// carried through them. Fresh joints given those pins then take, in one
    /// pass, exactly the damped least-squares step of the others with the
    /// pinned DOFs at their limits (checked against a dense `f64`
    /// elimination); repeated, the pins settle on a set where no free DOF
    /// crosses a limit and every pinned one is pushed outwards (the KKT
    /// conditions of the bounded step). The extreme case: most DOFs end up
    /// pinned.
    #[test]
    fn a_pinned_step_is_the_least_squares_step_with_the_pins_held() {
        let body = cmu::BODY;
        let mut angles = Angles::<32>::rest(&body).unwrap();
        let mut pose = Pose::<32>::default();
        let goals = four_goals();
        let mut work = Work::new(&body, &goals, &mut angles, &mut pose);
        let fresh = |work: &mut Work<'_, '_, 32>| {
            let (slots, mut joints) = laid_out(work, 4.0);
            joints.settle(&slots, 1e-8);
            joints.linearise(work, &slots).unwrap();
            let (groups, dofs, _) = joints.parts();
            for (g, d) in groups.iter().zip(dofs) {
                if !g.translation() {
                    (d.lo, d.hi) = (Vec3::splat(-0.02), Vec3::splat(0.02));
                }
            }
            (slots, joints)
        };
        let pins_of =
            |joints: &Joints<32>| core::array::from_fn::<Vec3, 32, _>(|i| joints.dofs[i].pin);
        let mut r = [Vec3::ZERO; MAX_GOALS];
        let (slots, mut joints) = fresh(&mut work);
        let mut system = System::EMPTY;
        assert!(system.step(&work, &mut joints, &slots, &mut r, 0.01, (1, CLAMP_PASSES)));
        let mut pins = pins_of(&joints);
        {
            // The reference on the step with no pins (one pass: nothing held).
            let (slots, mut joints) = fresh(&mut work);
            let mut system = System::EMPTY;
            assert!(system.step(&work, &mut joints, &slots, &mut r, 0.01, (1, 1)));
            let off = dense_step(&mut joints, &slots, system.awake);
            assert!(off < 1e-5, "no pins: {off:e} of the dense step");
        }
        let pinned = |p: &[Vec3; 32]| {
            p.iter()
                .map(|v| v.abs().element_sum() as usize)
                .sum::<usize>()
        };
        assert!(
            pinned(&pins) >= 3,
            "the limits must bind: {} pinned",
            pinned(&pins)
        );
        for round in 0..12 {
            let (slots, mut joints) = fresh(&mut work);
            for (d, p) in joints.dofs.iter_mut().zip(&pins) {
                (d.pin, d.pinned) = (*p, *p != Vec3::ZERO);
            }
            let mut system = System::EMPTY;
            assert!(system.step(&work, &mut joints, &slots, &mut r, 0.01, (1, 1)));
            let off = dense_step(&mut joints, &slots, system.awake);
            // The pinned DOFs' motion, taken out of `r̃` in `f32`, cancels
            // most of it: the free steps keep less of `f32`'s precision.
            assert!(off < 1e-3, "round {round}: {off:e} of the dense step");
            let (groups, dofs, _) = joints.parts();
            for ((g, d), given) in groups.iter().zip(dofs.iter()).zip(&pins) {
                if !g.live || g.translation() {
                    continue;
                }
                for k in 0..usize::from(g.count) {
                    let (x, pin) = (d.delta.to_array()[k], given.to_array()[k]);
                    if pin != 0.0 {
                        assert_eq!(d.inv_d.to_array()[k], 0.0, "a pinned DOF is held");
                        assert_eq!(x, 0.02 * pin, "a pinned DOF starts at its limit");
                    }
                }
            }
            let next = pins_of(&joints);
            if next == pins {
                // Settled: every DOF inside its limits, the pinned ones on them.
                for d in joints.dofs.iter().take(joints.count) {
                    assert!(d.delta.abs().max_element() <= 0.02 + 1e-6, "{:?}", d.delta);
                }
                return;
            }
            pins = next;
        }
        panic!("the pins did not settle in 12 steps");
    }

    #[test]
    fn chol3_rejects_indefinite() {
        assert!(chol3_inverse(Mat3::from_diagonal(Vec3::new(1.0, -1.0, 1.0))).is_none());
        let inv = chol3_inverse(Mat3::from_diagonal(Vec3::new(4.0, 9.0, 16.0))).unwrap();
        assert!((inv.x_axis.x - 0.5).abs() < 1e-6 && (inv.z_axis.z - 0.25).abs() < 1e-6);
    }
}
