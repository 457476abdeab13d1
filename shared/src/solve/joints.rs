//! The joints the whole-tree solver moves: their groups (one per segment, or
//! the root translation), the forward kinematics of just the segments the
//! goals hang from, and the Jacobian columns.
//!
//! A column of `J` is `ω × (x − p)` for a DOF with world axis `ω` and pivot
//! `p`, for every goal whose segment it moves; `ω` for orientation rows; minus
//! the same terms for a goal given in the frame of a segment the DOF also
//! moves. Columns are stored scaled by each goal's `√(w / w_max)`, three per
//! (group, goal) link.
//!
//! Everything is sized by the body's capacity `N` (a group per moving
//! segment; the root, which never turns, leaves room for the translation),
//! about 280 bytes per segment of capacity, and built in place in the
//! caller's [`super::SolverState`]: the groups once per layout (body, root
//! mode, goal segments), the columns once per iteration. Forward kinematics
//! keeps each joint's rotation with the angles it was computed at and
//! computes it again only when they change (bit for bit the same numbers).

use super::slots::{Kind, Slot, Slots};
use super::{RootMode, SolveError, Solver, Work};
use crate::body::{Axis, Body, Segment};
use crate::goal::Frame;
use crate::math;
use glam::{Mat3, Quat, Vec3};

/// Marker for the translation group.
const TRANSLATION: u8 = u8::MAX;
/// Marker for a path segment whose joint does not move.
const FIXED: u8 = u8::MAX;

/// The DOFs of one segment's joint (or the root translation), with the goals
/// they move and what the solver needs of the joint, copied once.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Group {
    pub seg: u8,
    parent: u8,
    pub count: u8,
    axes: [Axis; 3],
    /// First link and number of links.
    start: u8,
    len: u8,
    /// Bit `j`: moves slot `j`'s point.
    pub dep_a: u16,
    /// Bit `j`: moves slot `j`'s frame segment.
    pub dep_b: u16,
    /// The joint origin in the parent's frame.
    offset: Vec3,
    pub min: Vec3,
    pub max: Vec3,
    /// Sine and cosine of the first DOF's angle (for the middle axis).
    turn: (f32, f32),
    /// Takes part in the current linearisation ([`Joints::settle`]).
    pub live: bool,
    /// Its values changed since the last forward kinematics.
    moved: bool,
    /// The goals it moves (the bits of `dep_a | dep_b`).
    moves: u8,
}

/// A joint's rotation relative to its parent, kept with the angles it was
/// computed at (compared bit for bit), so that forward kinematics computes it
/// again only when the angles change.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Local {
    /// `rotation` is that of the angles `at` if this is the joints' current
    /// generation (0: never).
    generation: u32,
    at: [f32; 3],
    rotation: Quat,
}

/// The current generation and the local rotations.
type Cache<'c, const N: usize> = (u32, &'c mut [Local; N]);

impl Local {
    /// Nothing kept (all zero bits: a new state is cleared, not copied).
    const NONE: Local = Local {
        generation: 0,
        at: [0.0; 3],
        rotation: Quat::from_xyzw(0.0, 0.0, 0.0, 0.0),
    };

    /// Whether the rotation was computed in this generation at exactly
    /// these values.
    #[inline]
    fn holds(&self, generation: u32, values: &[f32; 3]) -> bool {
        let [a, b, c] = self.at;
        let [x, y, z] = *values;
        self.generation == generation
            && a.to_bits() == x.to_bits()
            && b.to_bits() == y.to_bits()
            && c.to_bits() == z.to_bits()
    }

    /// `rotation`, kept for the angles `at` in this generation.
    #[inline]
    fn new(generation: u32, at: [f32; 3], rotation: Quat) -> Self {
        Local {
            generation,
            at,
            rotation,
        }
    }
}

/// Per group and DOF, at the current linearisation: the curvature `|c|²`,
/// the gradient `c·r̃` and the tension; the steps that would reach the lower
/// and upper limits; `1 / D` (0 for a DOF that does not take part) and the
/// step. And the group's lever: the sum of its goals' `w / w_max`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Dofs {
    // The sums are set to zero per linearisation: kept apart by the limit
    // steps, they are cleared by plain stores, not a call to `memclr`.
    pub curvature: Vec3,
    pub lo: Vec3,
    pub grad: Vec3,
    pub hi: Vec3,
    pub tension: Vec3,
    pub inv_d: Vec3,
    pub delta: Vec3,
    /// The values before the step.
    back: Vec3,
    pub lever: f32,
    /// The warm active set: `+1` (`-1`) where the last step carried the DOF
    /// through its upper (lower) limit and the goals still push it there;
    /// the next step starts with it at that limit (see [`super::system`]).
    pub pin: Vec3,
    /// Whether any of `pin` is set (one test per group on the hot paths).
    pub pinned: bool,
    /// The `1 / D` of each DOF that this step holds at its pin (0 for the
    /// others), for the test that lets it go.
    pub held_inv: Vec3,
}

/// One goal moved by a group, with the group's scaled column per DOF.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Link {
    pub slot: u8,
    /// Column `k`: DOF `k`'s derivative of the slot's three rows (zero for a
    /// DOF the group does not have).
    pub cols: Mat3,
}

const NO_GROUP: Group = Group {
    seg: 0,
    parent: 0,
    count: 0,
    axes: [Axis::X; 3],
    start: 0,
    len: 0,
    dep_a: 0,
    dep_b: 0,
    offset: Vec3::ZERO,
    min: Vec3::ZERO,
    max: Vec3::ZERO,
    turn: (0.0, 0.0),
    live: false,
    moved: false,
    moves: 0,
};
const NO_DOFS: Dofs = Dofs {
    curvature: Vec3::ZERO,
    grad: Vec3::ZERO,
    tension: Vec3::ZERO,
    lo: Vec3::ZERO,
    hi: Vec3::ZERO,
    inv_d: Vec3::ZERO,
    delta: Vec3::ZERO,
    back: Vec3::ZERO,
    lever: 0.0,
    pin: Vec3::ZERO,
    pinned: false,
    held_inv: Vec3::ZERO,
};
const NO_LINK: Link = Link {
    slot: 0,
    cols: Mat3::ZERO,
};

impl Group {
    #[inline]
    pub fn translation(&self) -> bool {
        self.seg == TRANSLATION
    }

    /// The current values of the group's DOFs (zeros for the translation).
    #[inline]
    pub fn values<const N: usize>(&self, work: &Work<'_, '_, N>) -> [f32; 3] {
        if self.translation() {
            return [0.0; 3];
        }
        work.angles
            .get(usize::from(self.seg))
            .copied()
            .unwrap_or([0.0; 3])
    }
}

/// The sizes the work of a layout depends on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Sizes {
    /// Steps of the goals' climbs.
    pub climbs: usize,
    /// DOFs of the groups.
    pub dofs: usize,
    /// DOFs of the segments off the path.
    pub rest_dofs: usize,
}

/// The sizes the work of an iteration depends on: the live groups, their
/// DOFs, their links, the DOFs of their links and `Σ links²`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Live {
    pub groups: usize,
    pub dofs: usize,
    pub links: usize,
    pub link_dofs: usize,
    pub pairs: usize,
}

/// The moving joints, their state and their columns.
pub(super) struct Joints<const N: usize> {
    pub groups: [Group; N],
    pub dofs: [Dofs; N],
    pub links: [[Link; 2]; N],
    pub count: usize,
    /// The segments the forward kinematics visits, in order (those that
    /// carry a goal or a goal's frame, and their ancestors), each with its
    /// group or [`FIXED`], and its parent ([`FIXED`] for the root).
    order: [(u8, u8, u8); N],
    /// Segments in `order`.
    nodes: usize,
    /// Bit `s`: segment `s` is in `order`.
    path: u64,
    /// The root position before the step.
    back_root: Vec3,
    /// Bit `j`: slot `j` is not met; sets the live groups
    /// ([`Joints::settle`]).
    unmet: u16,
    /// Bit `j`: slot `j` is moved by a live group.
    pub reach: u16,
    /// The root position changed since the last forward kinematics.
    root_moved: bool,
    /// The work sizes of the layout: the steps of the goals' climbs in
    /// [`Joints::init`], the DOFs of the groups and of the segments off the
    /// path.
    pub sizes: Sizes,
    /// The work sizes of the live groups ([`Joints::settle`]).
    pub live: Live,
    /// The pose in the work is that of the angles, except for the groups
    /// marked `moved` and the root if `root_moved` (false: the next forward
    /// kinematics places the whole path).
    placed: bool,
    /// Per segment, the rotation of its joint (and for a moving one, `turn`
    /// in its group) at the angles it was last computed at.
    local: [Local; N],
    /// The generation of the entries of `local` that hold: a new layout
    /// starts a new one.
    generation: u32,
}

impl<const N: usize> Joints<N> {
    /// No group.
    pub const EMPTY: Self = Joints {
        groups: [NO_GROUP; N],
        dofs: [NO_DOFS; N],
        links: [[NO_LINK; 2]; N],
        count: 0,
        order: [(0, 0, 0); N],
        nodes: 0,
        path: 0,
        back_root: Vec3::ZERO,
        unmet: 0,
        reach: 0,
        root_moved: false,
        sizes: Sizes {
            climbs: 0,
            dofs: 0,
            rest_dofs: 0,
        },
        live: Live {
            groups: 0,
            dofs: 0,
            links: 0,
            link_dofs: 0,
            pairs: 0,
        },
        placed: false,
        local: [Local::NONE; N],
        generation: 0,
    };

    /// Finds the groups that move for these goals, in segment order (the
    /// translation first), in place of any it held: the joints of the
    /// segments that the goals and their frames hang from (the reach tree's
    /// simple chains), strictly below the anchor: the body root
    /// ([`RootMode::Fixed`]) or the goals' lowest common ancestor, the reach
    /// tree's root ([`RootMode::Float`]). Found by climbing from each goal's
    /// segment and frame segment, without building the tree.
    pub fn init(&mut self, solver: &Solver, work: &Work<'_, '_, N>, slots: &Slots) {
        (self.count, self.nodes, self.path) = (0, 0, 0);
        self.generation = self.generation.wrapping_add(1);
        if self.generation == 0 {
            // Wrapped: forget every entry for certain.
            (self.local, self.generation) = ([Local::NONE; N], 1);
        }
        let body = work.body;
        // Per segment, the slots whose point and whose frame it moves; and
        // the slots with a point and with a frame.
        let mut moves = [(0u16, 0u16); N];
        let (mut dep_a, mut dep_b) = (0u16, 0u16);
        self.sizes = Sizes {
            climbs: 0,
            dofs: 0,
            rest_dofs: 0,
        };
        for (j, slot) in slots.iter().enumerate() {
            let Some(g) = work.goals.get(usize::from(slot.goal)) else {
                continue;
            };
            self.sizes.climbs += climb(body, usize::from(g.segment), (1 << j, 0), &mut moves);
            dep_a |= 1 << j;
            if let Frame::Segment(f) = g.frame {
                self.sizes.climbs += climb(body, usize::from(f), (0, 1 << j), &mut moves);
                dep_b |= 1 << j;
            }
        }
        if solver.root == RootMode::Float {
            self.sizes.dofs += 3;
            self.push(Group {
                seg: TRANSLATION,
                count: 3,
                dep_a,
                dep_b,
                moves: (dep_a | dep_b).count_ones() as u8,
                min: Vec3::NEG_INFINITY,
                max: Vec3::INFINITY,
                ..NO_GROUP
            });
        }
        // The path (the segments that move a slot) in segment order; a
        // moving joint's group as it comes. The anchor and its ancestors move
        // every slot's point and frame.
        let mut at = 1u64;
        for (s, (seg, &deps)) in body.segments.iter().zip(&moves).enumerate() {
            let on_path = deps != (0, 0);
            let above = match solver.root {
                RootMode::Float => deps == (dep_a, dep_b),
                RootMode::Fixed => s == 0,
            };
            if !on_path {
                self.sizes.rest_dofs += seg.joint.count();
            }
            if on_path {
                let group = if !above && seg.joint.count() > 0 {
                    self.sizes.dofs += seg.joint.count();
                    self.push(joint_group(s, seg, deps))
                } else {
                    FIXED
                };
                if let Some(o) = self.order.get_mut(self.nodes) {
                    let parent = if s == 0 { FIXED } else { seg.parent };
                    *o = (u8::try_from(s).unwrap_or(0), group, parent);
                    self.nodes += 1;
                }
                self.path |= at;
            }
            at <<= 1;
        }
    }

    /// Appends a group; returns its index ([`FIXED`] if there is no room).
    fn push(&mut self, g: Group) -> u8 {
        let Some(slot) = self.groups.get_mut(self.count) else {
            return FIXED;
        };
        *slot = g;
        // A new layout: no DOF is pinned.
        if let Some(d) = self.dofs.get_mut(self.count) {
            (d.pin, d.pinned) = (Vec3::ZERO, false);
        }
        self.count += 1;
        u8::try_from(self.count - 1).unwrap_or(FIXED)
    }

    /// The segments the forward kinematics visits (the path).
    pub fn path_len(&self) -> usize {
        self.nodes
    }

    /// The groups in use.
    pub fn groups(&self) -> &[Group] {
        self.groups.get(..self.count).unwrap_or(&[])
    }

    /// Applies the step (each DOF's `delta`), scaled to at most `max_step`
    /// (rad or m), clamped into the limits. With `keep`, first keeps the
    /// values of the moving DOFs and the root position, to go back to with
    /// [`Joints::back`].
    pub fn apply(&mut self, work: &mut Work<'_, '_, N>, max_step: f32, keep: bool) {
        let n = self.count;
        let dofs = self.dofs.get(..n).unwrap_or(&[]).iter();
        let biggest = dofs.fold(0.0f32, |m, d| math::max(d.delta.abs().max_element(), m));
        let scale = if biggest > max_step {
            max_step / biggest
        } else {
            1.0
        };
        if keep {
            self.back_root = work.angles.root_position;
        }
        let groups = self.groups.get_mut(..n).unwrap_or(&mut []);
        let dofs = self.dofs.get_mut(..n).unwrap_or(&mut []);
        for (g, d) in groups.iter_mut().zip(dofs) {
            if !g.live {
                continue;
            }
            g.moved = true;
            if g.translation() {
                self.root_moved = true;
                work.angles.root_position += d.delta * scale;
                continue;
            }
            if let Some(values) = work.angles.get_mut(usize::from(g.seg)) {
                if keep {
                    d.back = Vec3::from_array(*values);
                }
                // By count, without an iterator (opt-level "s").
                let (step, [x, y, z]) = (d.delta * scale, *values);
                let (lo, hi) = (g.min, g.max);
                let count = g.count;
                if count > 0 {
                    values[0] = math::clamp(x + step.x, lo.x, hi.x);
                }
                if count > 1 {
                    values[1] = math::clamp(y + step.y, lo.y, hi.y);
                }
                if count > 2 {
                    values[2] = math::clamp(z + step.z, lo.z, hi.z);
                }
            }
        }
    }

    /// Goes back to the values [`Joints::apply`] kept.
    pub fn back(&mut self, work: &mut Work<'_, '_, N>) {
        work.angles.root_position = self.back_root;
        for (d, g) in self.dofs.iter().zip(&mut self.groups).take(self.count) {
            if !g.live {
                continue;
            }
            g.moved = true;
            // The root moved only if the (live) translation did.
            self.root_moved |= g.translation();
            if let Some(x) = work.angles.get_mut(usize::from(g.seg)) {
                *x = d.back.to_array();
            }
        }
    }

    /// The values of the moving DOFs and the root position.
    pub fn save(&self, work: &Work<'_, '_, N>) -> Saved<N> {
        let mut out = Saved {
            root: work.angles.root_position,
            values: [[0.0; 3]; N],
        };
        for (o, g) in out.values.iter_mut().zip(self.groups()) {
            *o = g.values(work);
        }
        out
    }

    /// Puts back what [`Joints::save`] took.
    pub fn restore(&mut self, work: &mut Work<'_, '_, N>, saved: &Saved<N>) {
        self.placed = false;
        work.angles.root_position = saved.root;
        for (v, g) in saved.values.iter().zip(self.groups()) {
            if let Some(x) = work.angles.get_mut(usize::from(g.seg)) {
                *x = *v;
            }
        }
    }
}

/// Segment `s` and its ancestors, up to the root.
pub(super) fn ancestors<'a>(body: &'a Body<'_>, s: usize) -> impl Iterator<Item = usize> + 'a {
    // Parents come before children (checked): the climb ends.
    core::iter::successors(Some(s), |&s| body.parent(s).filter(|&p| p < s))
}

/// Adds the slot bits `(point, frame)` to the entries of `moves` of segment
/// `s` and of its ancestors; returns the segments visited.
fn climb<const N: usize>(
    body: &Body<'_>,
    s: usize,
    (point, frame): (u16, u16),
    moves: &mut [(u16, u16); N],
) -> usize {
    let mut steps = 0;
    for s in ancestors(body, s) {
        if let Some(d) = moves.get_mut(s) {
            (d.0, d.1) = (d.0 | point, d.1 | frame);
        }
        steps += 1;
    }
    steps
}

/// The group of segment `s`'s joint (unused DOFs: about X, limits 0).
#[inline]
fn joint_group(s: usize, seg: &Segment<'_>, (dep_a, dep_b): (u16, u16)) -> Group {
    let [a, b, c] = seg.joint.entries();
    Group {
        seg: u8::try_from(s).unwrap_or(0),
        parent: seg.parent,
        count: u8::try_from(seg.joint.count()).unwrap_or(0),
        axes: [a.axis, b.axis, c.axis],
        start: 0,
        len: 0,
        dep_a,
        dep_b,
        offset: seg.origin,
        min: Vec3::new(a.min, b.min, c.min),
        max: Vec3::new(a.max, b.max, c.max),
        turn: (0.0, 0.0),
        live: false,
        moved: false,
        moves: (dep_a | dep_b).count_ones() as u8,
    }
}

/// The links of group `g` in the link store.
#[inline(always)]
pub(super) fn links_of<'l>(links: &'l [[Link; 2]], g: &Group) -> &'l [Link] {
    let start = usize::from(g.start);
    links
        .as_flattened()
        .get(start..start + usize::from(g.len))
        .unwrap_or(&[])
}

/// The moving joints' values and the root position, to go back to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Saved<const N: usize> {
    root: Vec3,
    values: [[f32; 3]; N],
}

impl<const N: usize> Joints<N> {
    /// Marks every segment as changed: the next [`Joints::forward`] places
    /// the whole path (the pose in `work` is not yet that of the angles).
    pub fn unplaced(&mut self) {
        self.placed = false;
    }

    /// Forward kinematics of the path segments: the world placement (into
    /// the work's pose, exactly as [`crate::pose::forward`] computes it) of
    /// every path segment whose angles, or an ancestor's, changed since the
    /// last call. The other segments are left as they are.
    pub fn forward(&mut self, work: &mut Work<'_, '_, N>) {
        // Per segment: placed again in this pass (its children follow).
        let mut placed_again = [false; N];
        for &(s, group, parent) in self.order.iter().take(self.nodes) {
            let s = usize::from(s);
            let group = match group {
                FIXED => None,
                g => self.groups.get_mut(usize::from(g)),
            };
            let own = match &group {
                Some(g) => g.moved,
                None => s == 0 && self.root_moved,
            };
            let after_parent = placed_again.get(usize::from(parent)) == Some(&true);
            if self.placed && !own && !after_parent {
                continue;
            }
            if let Some(p) = placed_again.get_mut(s) {
                *p = true;
            }
            let placed = match group {
                Some(g) => {
                    g.moved = false;
                    place_moving(work, g, (self.generation, &mut self.local))
                }
                None => place_fixed(work, s, (self.generation, &mut self.local)),
            };
            if let (Some((p, r)), Some(op), Some(or)) = (
                placed,
                work.pose.positions.get_mut(s),
                work.pose.rotations.get_mut(s),
            ) {
                *op = p;
                *or = r;
            }
        }
        (self.placed, self.root_moved) = (true, false);
    }

    /// The world placement of the segments off the path.
    pub fn forward_rest(&mut self, work: &mut Work<'_, '_, N>) {
        work.pose.count = work.body.len();
        let mut rest = !self.path & (u64::MAX >> (64 - work.body.len().clamp(1, 64)));
        while rest != 0 {
            let s = rest.trailing_zeros() as usize;
            rest &= rest - 1;
            if let (Some(placement), true) = (
                place_fixed(work, s, (self.generation, &mut self.local)),
                s > 0,
            ) && let (Some(op), Some(or)) = (
                work.pose.positions.get_mut(s),
                work.pose.rotations.get_mut(s),
            ) {
                (*op, *or) = placement;
            }
        }
    }
}

/// The world placement of segment `s` (the root: its own) from its parent's
/// and its joint's rotation at the current angles (kept in `cache`).
#[inline(always)]
fn place_fixed<const N: usize>(
    work: &Work<'_, '_, N>,
    s: usize,
    (generation, cache): Cache<'_, N>,
) -> Option<(Vec3, Quat)> {
    let Some(parent) = work.body.parent(s) else {
        return Some((work.angles.root_position, work.angles.root_rotation));
    };
    let values = work.angles.get(s)?;
    let kept = cache.get_mut(s)?;
    if !kept.holds(generation, values) {
        let rotation = work.body.segment(s)?.joint.rotation(values);
        *kept = Local::new(generation, *values, rotation);
    }
    let local = kept.rotation;
    let pp = *work.pose.positions.get(parent)?;
    let rp = *work.pose.rotations.get(parent)?;
    Some((pp + rp * *work.body.offsets.get(s)?, rp * local))
}

/// The world placement of a moving group's segment, rebuilding its local
/// rotation (if its angles changed) and keeping the sine and cosine of its
/// first angle.
#[inline]
fn place_moving<const N: usize>(
    work: &mut Work<'_, '_, N>,
    g: &mut Group,
    (generation, cache): Cache<'_, N>,
) -> Option<(Vec3, Quat)> {
    let s = usize::from(g.seg);
    let parent = usize::from(g.parent);
    let pp = *work.pose.positions.get(parent)?;
    let rp = *work.pose.rotations.get(parent)?;
    let values = work.angles.get(s)?;
    let kept = cache.get_mut(s)?;
    if !kept.holds(generation, values) {
        let (rotation, (sin, cos)) = local_rotation(&g.axes, g.count, values);
        g.turn = (2.0 * sin * cos, cos * cos - sin * sin);
        *kept = Local::new(generation, *values, rotation);
    }
    Some((pp + rp * g.offset, rp * kept.rotation))
}

/// The rotation of a joint with these axes (bit-identical to
/// [`Joint::rotation`]) and the sine and cosine of half the first angle.
#[inline]
fn local_rotation(axes: &[Axis; 3], count: u8, values: &[f32; 3]) -> (Quat, (f32, f32)) {
    // By count, like `Joint::rotation`: no iterator at opt-level "s".
    let [a, b, c] = *axes;
    let [x, y, z] = *values;
    if count == 0 {
        return (Quat::IDENTITY, (0.0, 1.0));
    }
    let (s, co) = math::sin_cos(0.5 * x);
    let q = a.rotation_half(s, co);
    let q = match count {
        1 => q,
        2 => b.rotate_after(q, y),
        _ => c.rotate_after(b.rotate_after(q, y), z),
    };
    (q, (s, co))
}

/// Column `axis` of the rotation matrix of `q`: the world direction of that
/// local axis.
#[inline(always)]
fn column(q: Quat, axis: Axis) -> Vec3 {
    let (x, y, z, w) = (q.x, q.y, q.z, q.w);
    match axis {
        Axis::X => Vec3::new(
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y + w * z),
            2.0 * (x * z - w * y),
        ),
        Axis::Y => Vec3::new(
            2.0 * (x * y - w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z + w * x),
        ),
        Axis::Z => Vec3::new(
            2.0 * (x * z + w * y),
            2.0 * (y * z - w * x),
            1.0 - 2.0 * (x * x + y * y),
        ),
    }
}

/// World axes of a group's DOFs from the parent's and the segment's world
/// rotations: the axis of DOF `k` is `R_parent · R_0 ⋯ R_{k−1} · axis_k`; the
/// first is `R_parent · axis_0`, the last `R_segment · axis_last`, a middle
/// one `R_parent · (cos θ₀·b + sin θ₀·a × b)`.
#[inline(always)]
fn world_axes(g: &Group, rp: Quat, rs: Quat) -> [Vec3; 3] {
    let [a, b, c] = g.axes;
    match g.count {
        1 => [column(rs, a), Vec3::ZERO, Vec3::ZERO],
        2 => [column(rp, a), column(rs, b), Vec3::ZERO],
        3 => {
            let (sin, cos) = g.turn;
            let cyclic = matches!(
                (a, b),
                (Axis::X, Axis::Y) | (Axis::Y, Axis::Z) | (Axis::Z, Axis::X)
            );
            let sin = if cyclic { sin } else { -sin };
            let middle = column(rp, b) * cos + column(rp, a.third(b)) * sin;
            [column(rp, a), middle, column(rs, c)]
        }
        _ => [Vec3::ZERO; 3],
    }
}

impl<const N: usize> Joints<N> {
    /// Chooses the groups the next linearisation moves: those that move a
    /// goal not yet met (residual above `√tol2`). A met goal whose joints
    /// move no unmet goal is left where it is, and so are those joints: a
    /// step would gain at most `w·tol2` from it. Also finds the slots the
    /// live groups move ([`Joints::reach`]): their rows stay in the step,
    /// so that a shared joint does not pull a met goal away.
    pub fn settle(&mut self, slots: &Slots, tol2: f32) {
        let unmet = slots.iter().enumerate().fold(0u16, |m, (j, s)| {
            if s.r.length_squared() > tol2 {
                m | 1 << j
            } else {
                m
            }
        });
        let mut reach = 0u16;
        let mut live = Live {
            groups: 0,
            dofs: 0,
            links: 0,
            link_dofs: 0,
            pairs: 0,
        };
        for g in self.groups.iter_mut().take(self.count) {
            let moves = g.dep_a | g.dep_b;
            g.live = moves & unmet != 0;
            if g.live {
                reach |= moves;
                let (links, dofs) = (usize::from(g.moves), usize::from(g.count));
                live.groups += 1;
                live.dofs += dofs;
                live.links += links;
                live.link_dofs += links * dofs;
                live.pairs += links * links;
            }
        }
        (self.unmet, self.reach, self.live) = (unmet, reach, live);
    }

    /// The groups in use, their DOFs' state and the link store, borrowed
    /// apart (the step reads the groups and links and writes the DOFs).
    #[inline(always)]
    pub fn parts(&mut self) -> (&[Group], &mut [Dofs], &[[Link; 2]]) {
        let count = self.count;
        (
            self.groups.get(..count).unwrap_or(&[]),
            self.dofs.get_mut(..count).unwrap_or(&mut []),
            &self.links,
        )
    }

    /// The goals that are not met ([`Joints::settle`]): with the layout,
    /// they decide which groups are live.
    pub fn unmet(&self) -> u16 {
        self.unmet
    }

    /// Builds every group's links and columns at the current pose; each DOF's
    /// curvature, gradient and tension (from the goals the last step did not
    /// bring much closer), and the steps to its limits.
    pub fn linearise(&mut self, work: &Work<'_, '_, N>, slots: &Slots) -> Result<(), SolveError> {
        let mut used = 0usize;
        let links = self.links.as_flattened_mut();
        let n = self.count;
        let groups = self.groups.get_mut(..n).unwrap_or(&mut []);
        let dofs = self.dofs.get_mut(..n).unwrap_or(&mut []);
        for (g, d) in groups.iter_mut().zip(dofs) {
            if !g.live {
                // Held where it is: no links, no step.
                (g.len, d.delta) = (0, Vec3::ZERO);
                continue;
            }
            let (p, axes) = geometry(work, g);
            let v = Vec3::from_array(g.values(work));
            // `inv_d`, `delta` and `back` are set by the step.
            (d.curvature, d.grad, d.tension, d.lever) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO, 0.0);
            (d.lo, d.hi) = (g.min - v, g.max - v);
            let mut tense = false;
            g.start = u8::try_from(used).map_err(|_| SolveError::TooManyGoals)?;
            let mut bits = g.dep_a | g.dep_b;
            while bits != 0 {
                let j = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let Some(slot) = slots.s.get(j) else { continue };
                let (da, db) = (g.dep_a >> j & 1 != 0, g.dep_b >> j & 1 != 0);
                let (cols, t) = columns(slot, da, db, g.translation(), &axes, p);
                let link = Link {
                    slot: u8::try_from(j).unwrap_or(0),
                    cols: cols * slot.sw,
                };
                if slot.awake {
                    d.add(&link, slot.r * slot.sw, slot.sw * slot.sw);
                    if slot.stretched {
                        d.tension += t * (slot.sw * slot.sw);
                        tense = true;
                    }
                }
                *links.get_mut(used).ok_or(SolveError::TooManyGoals)? = link;
                used += 1;
            }
            g.len = u8::try_from(used - usize::from(g.start)).unwrap_or(0);
            if tense {
                d.tension = d.tension.max(Vec3::ZERO);
            }
        }
        Ok(())
    }

    /// Recomputes every DOF's curvature and gradient for these awake slots
    /// and scaled residuals (after standby planes woke).
    pub fn sums(&mut self, slots: &Slots, awake: u16, r: &[Vec3]) {
        for (g, d) in self
            .groups
            .iter()
            .zip(self.dofs.iter_mut())
            .take(self.count)
        {
            (d.curvature, d.grad, d.lever) = (Vec3::ZERO, Vec3::ZERO, 0.0);
            for l in links_of(&self.links, g)
                .iter()
                .filter(|l| awake >> l.slot & 1 != 0)
            {
                let j = usize::from(l.slot);
                let rj = r.get(j).copied().unwrap_or(Vec3::ZERO);
                let sw = slots.s.get(j).map_or(0.0, |s| s.sw);
                d.add(l, rj, sw * sw);
            }
        }
    }
}

impl Dofs {
    /// Adds a link's curvature, gradient (for scaled residual `r`) and lever
    /// (its slot's `w / w_max`).
    #[inline(always)]
    fn add(&mut self, l: &Link, r: Vec3, sw2: f32) {
        let c = l.cols;
        self.curvature += Vec3::new(
            c.x_axis.length_squared(),
            c.y_axis.length_squared(),
            c.z_axis.length_squared(),
        );
        self.grad += c.transpose() * r;
        self.lever += sw2;
    }
}

/// The pivot and world axes of a group at the current pose (the translation's
/// axes are its directions).
#[inline(always)]
pub(super) fn geometry<const N: usize>(work: &Work<'_, '_, N>, g: &Group) -> (Vec3, [Vec3; 3]) {
    let s = usize::from(g.seg);
    let poses = (
        work.pose.positions.get(s),
        work.pose.rotations.get(usize::from(g.parent)),
        work.pose.rotations.get(s),
    );
    match poses {
        (Some(&p), Some(&rp), Some(&rs)) if !g.translation() => (p, world_axes(g, rp, rs)),
        _ => (Vec3::ZERO, [Vec3::X, Vec3::Y, Vec3::Z]),
    }
}

/// The unscaled derivatives of a slot's rows with respect to a group's DOFs
/// (world axes `w`, pivot `p`; for the translation the axes are its
/// directions), given which of the point (`da`) and the frame (`db`) the
/// group moves; and per DOF the tension (zero unless the goal is marked
/// stretched): for a goal pulling its point `x` with residual `r`,
/// `r · (x − p)⊥ω`, the diagonal of the second-order term that makes a
/// stretched limb stiff against turning.
#[inline(always)]
fn columns(
    slot: &Slot,
    da: bool,
    db: bool,
    translation: bool,
    w: &[Vec3; 3],
    p: Vec3,
) -> (Mat3, Vec3) {
    let [w0, w1, w2] = *w;
    let (x, g, n, r) = (slot.x, slot.g, slot.n, slot.r);
    let dots = |v: Vec3| Vec3::new(w0.dot(v), w1.dot(v), w2.dot(v));
    let stretched = slot.stretched;
    match (slot.kind, translation) {
        (Kind::Point, true) => (if db { Mat3::ZERO } else { Mat3::IDENTITY }, Vec3::ZERO),
        (Kind::Point, false) => {
            let a = if da { x - p } else { Vec3::ZERO };
            let arm = if db { a - (g - p) } else { a };
            let cols = Mat3::from_cols(w0.cross(arm), w1.cross(arm), w2.cross(arm));
            if !stretched {
                return (cols, Vec3::ZERO);
            }
            (cols, Vec3::splat(r.dot(arm)) - dots(r) * dots(arm))
        }
        (Kind::Plane, true) if !db => (plane_rows(n), Vec3::ZERO),
        (Kind::Plane, false) if !db => {
            let arm = x - p;
            let rows = plane_rows(dots(arm.cross(n)));
            if !stretched {
                return (rows, Vec3::ZERO);
            }
            (rows, (Vec3::splat(n.dot(arm)) - dots(n) * dots(arm)) * r.x)
        }
        (Kind::Plane, _) => {
            let j = |w: Vec3| entry(slot, da, db, translation, w, p).x;
            (plane_rows(Vec3::new(j(w0), j(w1), j(w2))), Vec3::ZERO)
        }
        (Kind::Orientation, true) => (Mat3::ZERO, Vec3::ZERO),
        (Kind::Orientation, false) => {
            let k = if da { 1.0 } else { 0.0 } - if db { 1.0 } else { 0.0 };
            (Mat3::from_cols(w0, w1, w2) * k, Vec3::ZERO)
        }
    }
}

/// A matrix whose first row is `v` (a plane's one row), the others zero.
#[inline]
fn plane_rows(v: Vec3) -> Mat3 {
    Mat3::from_cols(
        Vec3::new(v.x, 0.0, 0.0),
        Vec3::new(v.y, 0.0, 0.0),
        Vec3::new(v.z, 0.0, 0.0),
    )
}

/// The unscaled derivative of a slot's rows with respect to one DOF with world
/// axis `w` and pivot `p` (for a translation, `w` is its direction), given
/// which of the point (`da`) and the frame (`db`) it moves.
pub(super) fn entry(slot: &Slot, da: bool, db: bool, translation: bool, w: Vec3, p: Vec3) -> Vec3 {
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

/// For tests: the slots of the work's goals (heaviest weight `wmax`) and
/// the joints laid out for them by [`Solver::DEFAULT`], placed and
/// evaluated at the work's angles.
#[cfg(test)]
pub(super) fn laid_out<const N: usize>(
    work: &mut Work<'_, '_, N>,
    wmax: f32,
) -> (Slots, Joints<N>) {
    work.check().unwrap();
    let mut slots = Slots::EMPTY;
    slots.init(work.goals, wmax).unwrap();
    let mut joints = Joints::<N>::EMPTY;
    joints.init(&Solver::DEFAULT, work, &slots);
    joints.forward(work);
    slots.evaluate(work).unwrap();
    (slots, joints)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::{Angles, cmu};
    use crate::goal::Goal;
    use crate::pose::{LocalPose, Pose};

    /// The solver's joint rotation is `Joint::rotation`, bit for bit, for
    /// every joint of both shipped bodies (1 to 3 DOFs, all axis orders) at
    /// angles across their ranges, with the half-angle sine and cosine of the
    /// first DOF.
    #[test]
    fn local_rotation_is_the_joints_rotation() {
        let bits = |q: Quat| q.to_array().map(f32::to_bits);
        let mut checked = 0;
        for body in [cmu::BODY, crate::body::tempus::BODY] {
            for (s, seg) in body.segments.iter().enumerate().skip(1) {
                let g = joint_group(s, seg, (0, 0));
                for k in 0..40 {
                    let t = k as f32 / 39.0;
                    let mut values = [0.0f32; 3];
                    for (v, d) in values.iter_mut().zip(seg.joint.dofs()) {
                        *v = d.min + (d.max - d.min) * t;
                    }
                    values[0] = -values[0] * 0.7 + 0.1;
                    let (q, first) = local_rotation(&g.axes, g.count, &values);
                    assert_eq!(
                        bits(q),
                        bits(seg.joint.rotation(&values)),
                        "{} {values:?}",
                        seg.name
                    );
                    if g.count > 0 {
                        assert_eq!(first, math::sin_cos(0.5 * values[0]));
                    }
                    checked += 1;
                }
            }
        }
        assert!(checked > 1000, "{checked}");
    }

    /// Every column against a central difference of the forward kinematics.
    #[test]
    fn columns_match_finite_differences() {
        let body = cmu::BODY;
        let mut a = Angles::<32>::rest(&body).unwrap();
        for (i, v) in a.values.iter_mut().flat_map(|v| v.iter_mut()).enumerate() {
            *v = 0.3 * ((i as f32) * 0.7).sin();
        }
        a.clamp_to_limits(&body);
        let goals = [
            Goal::reach(cmu::index::LEFT_HAND, Vec3::new(0.3, 1.0, 0.2), 1.0),
            Goal::reach(cmu::index::RIGHT_FOOT, Vec3::new(-0.1, 0.0, 0.1), 4.0),
        ];
        let mut pose = Pose::<32>::default();
        let mut angles = a;
        let mut work = Work::new(&body, &goals, &mut angles, &mut pose);
        let (slots, mut joints) = laid_out(&mut work, 4.0);
        joints.settle(&slots, 0.0);
        joints.linearise(&work, &slots).unwrap();
        let point = |a: &Angles<32>, g: &Goal| {
            let (mut l, mut p) = (LocalPose::<32>::default(), Pose::<32>::default());
            a.forward(&body, &mut l, &mut p).unwrap();
            g.world_point(&body, &p).unwrap()
        };
        let mut checked = 0;
        for g in joints.groups() {
            for l in links_of(&joints.links, g) {
                let slot = slots.s[usize::from(l.slot)];
                let goal = &goals[usize::from(slot.goal)];
                for k in 0..usize::from(g.count) {
                    let h = 1e-3;
                    let (mut p, mut m) = (a, a);
                    p.values[usize::from(g.seg)][k] += h;
                    m.values[usize::from(g.seg)][k] -= h;
                    let fd = (point(&p, goal) - point(&m, goal)) / (2.0 * h) * slot.sw;
                    let col = l.cols.col(k);
                    assert!(
                        (fd - col).length() < 1e-3,
                        "seg {} dof {k}: {fd} vs {col}",
                        g.seg
                    );
                    checked += 1;
                }
            }
        }
        assert!(checked > 20, "{checked}");
    }
}
