//! The articulated body: a tree of rigid segments joined by limited revolute joints.
//!
//! This is the body tree of Badler, Manoochehri & Walters (1987), Figure 12, with
//! the extensions their paper lists as future work (joint limits, touch points
//! anywhere in a segment):
//!
//! - every [`Segment`] has a parent (`NO_PARENT` for the root, otherwise a lower
//!   index), the origin of its joint as a fixed point in the parent's frame, a
//!   [`Joint`] of 0–3 rotational degrees of freedom in a stated order, each with
//!   `[min, max]` limits, and a touch point in its own frame (where goals attach;
//!   by default the distal joint);
//! - the root (segment 0) is free: its world position and orientation are part
//!   of the joint state, not of the body;
//! - a body is a set of borrowed slices, so shipped bodies are `static` data (in
//!   flash on the firmware), and a host can build one from a rig file.
//!
//! Frames: a segment's frame sits at its joint origin. With all angles zero every
//! frame is parallel to the root's ("rest pose"); a joint's rotation relative to
//! its parent is the product of its axis rotations in the stated order,
//! `q = R_a(θ₀)·R_b(θ₁)·R_c(θ₂)` (intrinsic, as BVH `CHANNELS` read left to right).
//!
//! [`Angles`] is the joint state the solver works on; [`Angles::to_local`] and
//! [`pose::forward`] give world transforms (the project's one forward kinematics),
//! and [`Angles::from_local`] projects an arbitrary local pose (e.g. a synthesized
//! one) onto the joints' degrees of freedom for a warm start.

use crate::math;
use crate::pose::{self, Hierarchy, LocalPose, MAX_SEGMENTS, NO_PARENT, Pose, PoseError};
use core::f32::consts::{PI, TAU};
use glam::{Mat3, Quat, Vec3};

pub mod cmu;
pub mod tempus;

/// A rotation axis of a joint, in the segment's rest frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Axis {
    /// +X.
    X,
    /// +Y.
    Y,
    /// +Z.
    Z,
}

impl Axis {
    /// The unit vector of the axis.
    #[inline]
    #[must_use]
    pub const fn unit(self) -> Vec3 {
        match self {
            Axis::X => Vec3::X,
            Axis::Y => Vec3::Y,
            Axis::Z => Vec3::Z,
        }
    }

    /// The rotation by `angle` radians about this axis.
    #[inline]
    #[must_use]
    pub fn rotation(self, angle: f32) -> Quat {
        let (s, c) = math::sin_cos(0.5 * angle);
        self.rotation_half(s, c)
    }

    /// [`Axis::rotation`] from the sine and cosine of half the angle.
    #[inline]
    #[must_use]
    pub const fn rotation_half(self, s: f32, c: f32) -> Quat {
        match self {
            Axis::X => Quat::from_xyzw(s, 0.0, 0.0, c),
            Axis::Y => Quat::from_xyzw(0.0, s, 0.0, c),
            Axis::Z => Quat::from_xyzw(0.0, 0.0, s, c),
        }
    }

    /// `q · R(angle)`, the product with a rotation about this axis, in 8
    /// multiplications instead of a general quaternion product's 16.
    #[inline(always)]
    #[must_use]
    pub fn rotate_after(self, q: Quat, angle: f32) -> Quat {
        let (s, c) = math::sin_cos(0.5 * angle);
        self.rotate_after_half(q, s, c)
    }

    /// [`Axis::rotate_after`] from the sine and cosine of half the angle.
    #[inline(always)]
    #[must_use]
    pub fn rotate_after_half(self, q: Quat, s: f32, c: f32) -> Quat {
        let (x, y, z, w) = (q.x, q.y, q.z, q.w);
        match self {
            Axis::X => Quat::from_xyzw(x * c + w * s, y * c + z * s, z * c - y * s, w * c - x * s),
            Axis::Y => Quat::from_xyzw(x * c - z * s, y * c + w * s, z * c + x * s, w * c - y * s),
            Axis::Z => Quat::from_xyzw(x * c + y * s, y * c - x * s, z * c + w * s, w * c - z * s),
        }
    }

    /// The component of `v` along this axis.
    #[inline]
    #[must_use]
    pub const fn component(self, v: Vec3) -> f32 {
        match self {
            Axis::X => v.x,
            Axis::Y => v.y,
            Axis::Z => v.z,
        }
    }

    /// The axis that is neither `self` nor `other` (`self` if they are equal).
    #[inline]
    #[must_use]
    pub const fn third(self, other: Axis) -> Axis {
        match (self, other) {
            (Axis::X, Axis::Y) | (Axis::Y, Axis::X) => Axis::Z,
            (Axis::X, Axis::Z) | (Axis::Z, Axis::X) => Axis::Y,
            (Axis::Y, Axis::Z) | (Axis::Z, Axis::Y) => Axis::X,
            _ => self,
        }
    }
}

/// One rotational degree of freedom: an axis and its limits (radians, `min <= max`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dof {
    /// The rotation axis.
    pub axis: Axis,
    /// Lower limit, radians.
    pub min: f32,
    /// Upper limit, radians.
    pub max: f32,
}

impl Dof {
    /// A degree of freedom with limits in radians.
    #[must_use]
    pub const fn new(axis: Axis, min: f32, max: f32) -> Self {
        Dof { axis, min, max }
    }

    /// A degree of freedom with limits in degrees (for readable body tables).
    #[must_use]
    pub const fn degrees(axis: Axis, min: f32, max: f32) -> Self {
        const K: f32 = core::f32::consts::PI / 180.0;
        Dof {
            axis,
            min: min * K,
            max: max * K,
        }
    }

    /// `value` clamped to the limits (NaN becomes `min`).
    #[inline]
    #[must_use]
    pub fn clamp(&self, value: f32) -> f32 {
        math::clamp(value, self.min, self.max)
    }

    /// How far `value` lies outside the limits (0 inside).
    #[inline]
    #[must_use]
    pub fn excess(&self, value: f32) -> f32 {
        if value > self.max {
            value - self.max
        } else if value < self.min {
            self.min - value
        } else {
            0.0
        }
    }
}

const UNUSED_DOF: Dof = Dof::new(Axis::X, 0.0, 0.0);

/// A revolute joint: 0 to 3 degrees of freedom applied in order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Joint {
    dofs: [Dof; 3],
    count: u8,
}

impl Joint {
    /// A rigid joint (no degree of freedom).
    pub const FIXED: Joint = Joint {
        dofs: [UNUSED_DOF; 3],
        count: 0,
    };

    /// A hinge.
    #[must_use]
    pub const fn one(a: Dof) -> Self {
        Joint {
            dofs: [a, UNUSED_DOF, UNUSED_DOF],
            count: 1,
        }
    }

    /// Two degrees of freedom, `a` then `b` (axes must differ).
    #[must_use]
    pub const fn two(a: Dof, b: Dof) -> Self {
        Joint {
            dofs: [a, b, UNUSED_DOF],
            count: 2,
        }
    }

    /// Three degrees of freedom, `a`, `b`, then `c` (a permutation of X, Y, Z).
    #[must_use]
    pub const fn three(a: Dof, b: Dof, c: Dof) -> Self {
        Joint {
            dofs: [a, b, c],
            count: 3,
        }
    }

    /// The degrees of freedom in order.
    #[inline]
    #[must_use]
    pub fn dofs(&self) -> &[Dof] {
        self.dofs.get(..usize::from(self.count)).unwrap_or(&[])
    }

    /// All three DOF entries: the degrees of freedom in order, then the
    /// unused entries, each about X with limits 0 (as every constructor
    /// leaves them).
    #[inline]
    #[must_use]
    pub(crate) const fn entries(&self) -> &[Dof; 3] {
        &self.dofs
    }

    /// The number of degrees of freedom.
    #[inline]
    #[must_use]
    pub const fn count(&self) -> usize {
        self.count as usize
    }

    /// Whether the axes are valid: distinct, and limits ordered and within ±2π.
    #[must_use]
    pub fn is_valid(&self) -> bool {
        let d = self.dofs();
        let ordered = d
            .iter()
            .all(|f| f.min <= f.max && f.min >= -TAU && f.max <= TAU);
        let distinct = match d {
            [a, b] => a.axis != b.axis,
            [a, b, c] => a.axis != b.axis && b.axis != c.axis && a.axis != c.axis,
            _ => true,
        };
        self.count <= 3 && ordered && distinct
    }

    /// The joint's rotation relative to its parent for these angles
    /// (unused entries are ignored): `R_a(θ₀)·R_b(θ₁)·R_c(θ₂)`.
    #[must_use]
    pub fn rotation(&self, values: &[f32; 3]) -> Quat {
        // By count, not an iterator fold: the same products in the same
        // order, without iterator calls at opt-level "s" (forward
        // kinematics calls this for every joint).
        let [a, b, c] = &self.dofs;
        let [x, y, z] = *values;
        match self.count {
            1 => a.axis.rotation(x),
            2 => b.axis.rotate_after(a.axis.rotation(x), y),
            3 => c
                .axis
                .rotate_after(b.axis.rotate_after(a.axis.rotation(x), y), z),
            _ => Quat::IDENTITY,
        }
    }

    /// `values` clamped to the limits; unused entries set to 0.
    #[inline]
    #[must_use]
    pub fn clamp(&self, values: &[f32; 3]) -> [f32; 3] {
        // By count, as in `rotation` (no iterator calls at opt-level "s").
        let [a, b, c] = &self.dofs;
        let [x, y, z] = *values;
        match self.count {
            1 => [a.clamp(x), 0.0, 0.0],
            2 => [a.clamp(x), b.clamp(y), 0.0],
            3 => [a.clamp(x), b.clamp(y), c.clamp(z)],
            _ => [0.0; 3],
        }
    }

    /// How far `values` lie outside the limits (largest excess, radians).
    #[must_use]
    pub fn excess(&self, values: &[f32; 3]) -> f32 {
        self.dofs().iter().zip(values).fold(
            0.0,
            |m, (d, &v)| if d.excess(v) > m { d.excess(v) } else { m },
        )
    }

    /// Projects an arbitrary relative rotation onto this joint's degrees of freedom
    /// and clamps to the limits.
    ///
    /// - 1 DOF: the twist of `q` about the axis (the closest rotation about it);
    /// - 2 DOFs `a, b`: the Euler decomposition `a, b, c` (c the third axis) with
    ///   `c` dropped;
    /// - 3 DOFs: the exact Euler decomposition in the joint's order.
    ///
    /// Of the two Euler solutions the one that needs the least clamping is kept,
    /// so a rotation inside the limits is reproduced exactly.
    #[must_use]
    pub fn project(&self, q: Quat) -> [f32; 3] {
        match self.dofs {
            [a, ..] if self.count == 1 => {
                let q = if q.w < 0.0 { -q } else { q };
                self.clamp(&[2.0 * math::atan2(a.axis.component(q.xyz()), q.w), 0.0, 0.0])
            }
            [a, b, _] if self.count == 2 => {
                // The third angle is dropped: not computed.
                self.best_euler(euler_in(q, [a.axis, b.axis, a.axis.third(b.axis)], false))
            }
            [a, b, c] if self.count == 3 => self.best_euler(euler(q, a.axis, b.axis, c.axis)),
            _ => [0.0; 3],
        }
    }

    /// Of the two Euler solutions, the clamped one that moves least from the exact one.
    fn best_euler(&self, (first, second): ([f32; 3], [f32; 3])) -> [f32; 3] {
        // The summed excess, by count (no iterator calls at opt-level "s");
        // the same comparison as a `sum()` from −0.
        let [a, b, c] = &self.dofs;
        let cost = |&[x, y, z]: &[f32; 3]| -> f32 {
            match self.count {
                1 => a.excess(x),
                2 => a.excess(x) + b.excess(y),
                3 => a.excess(x) + b.excess(y) + c.excess(z),
                _ => 0.0,
            }
        };
        if cost(&second) < cost(&first) {
            self.clamp(&second)
        } else {
            self.clamp(&first)
        }
    }
}

/// Element `(row, col)` of a rotation matrix, rows and columns named by axis.
#[inline]
fn element(m: &Mat3, row: Axis, col: Axis) -> f32 {
    let column = match col {
        Axis::X => m.x_axis,
        Axis::Y => m.y_axis,
        Axis::Z => m.z_axis,
    };
    row.component(column)
}

/// Wraps an angle into `(-π, π]`.
#[inline]
#[must_use]
pub fn wrap_angle(a: f32) -> f32 {
    if a > PI {
        a - TAU
    } else if a <= -PI {
        a + TAU
    } else {
        a
    }
}

/// Both Tait–Bryan decompositions `q = R_i(α)·R_j(β)·R_k(γ)` (i, j, k distinct):
/// the one with `|β| <= π/2` first, then `(α+π, π−β, γ+π)`, all wrapped to (−π, π].
#[must_use]
pub fn euler(q: Quat, i: Axis, j: Axis, k: Axis) -> ([f32; 3], [f32; 3]) {
    euler_in(q, [i, j, k], true)
}

/// [`euler`]; without `gamma`, the third angle is left 0 in the first
/// solution and π in the second (for a 2-DOF joint, which drops it).
#[inline(always)]
fn euler_in(q: Quat, [i, j, k]: [Axis; 3], gamma: bool) -> ([f32; 3], [f32; 3]) {
    let m = Mat3::from_quat(q);
    let even = matches!(
        (i, j),
        (Axis::X, Axis::Y) | (Axis::Y, Axis::Z) | (Axis::Z, Axis::X)
    );
    let s = if even { 1.0 } else { -1.0 };
    let sb = (s * element(&m, i, k)).clamp(-1.0, 1.0);
    let beta = math::asin(sb);
    let (alpha, gamma) = if math::abs(sb) > 0.999_999 {
        // Gimbal lock: only α ± γ is defined; put it all in α.
        (math::atan2(s * element(&m, k, j), element(&m, j, j)), 0.0)
    } else {
        (
            math::atan2(-s * element(&m, j, k), element(&m, k, k)),
            if gamma {
                math::atan2(-s * element(&m, i, j), element(&m, i, i))
            } else {
                0.0
            },
        )
    };
    let first = [alpha, beta, gamma];
    let second = [
        wrap_angle(alpha + PI),
        wrap_angle(PI - beta),
        wrap_angle(gamma + PI),
    ];
    (first, second)
}

/// One segment of a body.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment<'a> {
    /// Name (e.g. the BVH joint name).
    pub name: &'a str,
    /// Index of the parent segment, `NO_PARENT` for the root; always lower than
    /// the segment's own index.
    pub parent: u8,
    /// The joint origin, a fixed point in the parent's frame, metres (for the
    /// root: its offset from the root position, normally zero).
    pub origin: Vec3,
    /// The joint's degrees of freedom (ignored for the root, which is free).
    pub joint: Joint,
    /// The touch point in the segment's own frame, metres.
    pub touch: Vec3,
}

/// Why a body or a joint state is unusable.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BodyError {
    /// The body has no segment.
    Empty,
    /// More segments than the state's capacity (or than [`MAX_SEGMENTS`]).
    TooManySegments,
    /// The segment, parent and offset slices differ in length or content.
    Inconsistent,
    /// Segment `0` is the root and must have no parent; every other segment's
    /// parent must have a lower index. Holds the offending segment.
    BadParent(u8),
    /// A joint has repeated axes, more than 3 DOFs, or unordered limits.
    BadJoint(u8),
    /// The joint state was made for a different number of segments.
    CountMismatch,
    /// Forward kinematics failed.
    Pose(PoseError),
}

impl From<PoseError> for BodyError {
    fn from(e: PoseError) -> Self {
        BodyError::Pose(e)
    }
}

/// A body tree: borrowed segment table plus the parallel parent and offset arrays
/// that [`pose::forward`] reads. Build shipped bodies with [`parents_of`] and
/// [`offsets_of`] in `const` items; check any body with [`Body::validate`].
#[derive(Clone, Copy, Debug)]
pub struct Body<'a> {
    /// The segments, root first, parents before children.
    pub segments: &'a [Segment<'a>],
    /// `segments[i].parent` for each segment.
    pub parents: &'a [u8],
    /// `segments[i].origin` for each segment.
    pub offsets: &'a [Vec3],
}

impl<'a> Body<'a> {
    /// The number of segments.
    #[inline]
    #[must_use]
    pub const fn len(&self) -> usize {
        self.segments.len()
    }

    /// Whether the body has no segment.
    #[inline]
    #[must_use]
    pub const fn is_empty(&self) -> bool {
        self.segments.is_empty()
    }

    /// The segment with this index.
    #[inline]
    #[must_use]
    pub fn segment(&self, index: usize) -> Option<&Segment<'a>> {
        self.segments.get(index)
    }

    /// The index of the segment with this name.
    #[must_use]
    pub fn find(&self, name: &str) -> Option<u8> {
        self.segments
            .iter()
            .position(|s| s.name == name)
            .and_then(|i| u8::try_from(i).ok())
    }

    /// The parent of a segment (`None` for the root or an unknown index).
    #[inline]
    #[must_use]
    pub fn parent(&self, index: usize) -> Option<usize> {
        self.parents
            .get(index)
            .filter(|&&p| p != NO_PARENT)
            .map(|&p| usize::from(p))
    }

    /// The hierarchy view that [`pose::forward`] needs.
    #[inline]
    #[must_use]
    pub fn hierarchy(&self) -> Hierarchy<'a> {
        Hierarchy {
            parents: self.parents,
            offsets: self.offsets,
        }
    }

    /// Checks the structure: non-empty, at most [`MAX_SEGMENTS`], consistent
    /// slices, root first, parents before children, valid joints.
    pub fn validate(&self) -> Result<(), BodyError> {
        let n = self.segments.len();
        if n == 0 {
            return Err(BodyError::Empty);
        }
        if n > MAX_SEGMENTS {
            return Err(BodyError::TooManySegments);
        }
        if self.parents.len() != n || self.offsets.len() != n {
            return Err(BodyError::Inconsistent);
        }
        for (i, ((s, &p), &o)) in self
            .segments
            .iter()
            .zip(self.parents)
            .zip(self.offsets)
            .enumerate()
        {
            let id = u8::try_from(i).unwrap_or(u8::MAX);
            if s.parent != p || s.origin != o {
                return Err(BodyError::Inconsistent);
            }
            let root_ok = i == 0 && p == NO_PARENT;
            if !root_ok && (i == 0 || usize::from(p) >= i) {
                return Err(BodyError::BadParent(id));
            }
            if !s.joint.is_valid() {
                return Err(BodyError::BadJoint(id));
            }
        }
        Ok(())
    }

    /// Whether segment `a` is `b` or one of its ancestors.
    #[must_use]
    pub fn is_ancestor_or_self(&self, a: usize, b: usize) -> bool {
        let mut s = b;
        for _ in 0..=self.len() {
            if s == a {
                return true;
            }
            match self.parent(s) {
                Some(p) => s = p,
                None => return false,
            }
        }
        false
    }

    /// The total number of rotational degrees of freedom (root excluded).
    #[must_use]
    pub fn dof_count(&self) -> usize {
        self.segments.iter().skip(1).map(|s| s.joint.count()).sum()
    }
}

/// The parents column of a segment table, for `const` body definitions.
#[must_use]
#[allow(clippy::indexing_slicing)] // Evaluated in const items: out of bounds is a compile error.
pub const fn parents_of<const N: usize>(segments: &[Segment<'_>; N]) -> [u8; N] {
    let mut out = [0u8; N];
    let mut i = 0;
    while i < N {
        out[i] = segments[i].parent;
        i += 1;
    }
    out
}

/// The offsets column of a segment table, for `const` body definitions.
#[must_use]
#[allow(clippy::indexing_slicing)] // Evaluated in const items: out of bounds is a compile error.
pub const fn offsets_of<const N: usize>(segments: &[Segment<'_>; N]) -> [Vec3; N] {
    let mut out = [Vec3::ZERO; N];
    let mut i = 0;
    while i < N {
        out[i] = segments[i].origin;
        i += 1;
    }
    out
}

/// A joint state: root placement plus up to three angles per segment, in the
/// order of each joint's degrees of freedom. Fixed capacity `N`, no heap.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Angles<const N: usize = MAX_SEGMENTS> {
    /// Number of segments in use (the body's length).
    pub count: usize,
    /// World position of the root.
    pub root_position: Vec3,
    /// World orientation of the root.
    pub root_rotation: Quat,
    /// Joint angles, radians, per segment (entry 0, the root's, is unused).
    pub values: [[f32; 3]; N],
}

impl<const N: usize> Angles<N> {
    /// The rest state for a body: root at the origin, every angle zero clamped
    /// into its limits.
    pub fn rest(body: &Body<'_>) -> Result<Self, BodyError> {
        body.validate()?;
        if body.len() > N {
            return Err(BodyError::TooManySegments);
        }
        let mut a = Angles {
            count: body.len(),
            root_position: Vec3::ZERO,
            root_rotation: Quat::IDENTITY,
            values: [[0.0; 3]; N],
        };
        a.clamp_to_limits(body);
        Ok(a)
    }

    /// The angles of a segment.
    #[inline]
    #[must_use]
    pub fn get(&self, segment: usize) -> Option<&[f32; 3]> {
        self.values.get(segment).filter(|_| segment < self.count)
    }

    /// The angles of a segment, mutably.
    #[inline]
    pub fn get_mut(&mut self, segment: usize) -> Option<&mut [f32; 3]> {
        if segment < self.count {
            self.values.get_mut(segment)
        } else {
            None
        }
    }

    /// Clamps every angle into its joint's limits (unused entries become 0).
    pub fn clamp_to_limits(&mut self, body: &Body<'_>) {
        // Sliced past the root rather than `skip(1)` (a call at opt-level "s").
        let (Some(values), Some(segments)) = (self.values.get_mut(1..), body.segments.get(1..))
        else {
            return;
        };
        for (v, s) in values.iter_mut().zip(segments) {
            *v = s.joint.clamp(v);
        }
    }

    /// The largest amount (radians) by which any angle exceeds its limits.
    #[must_use]
    pub fn limit_excess(&self, body: &Body<'_>) -> f32 {
        self.values
            .iter()
            .zip(body.segments)
            .skip(1)
            .fold(0.0, |m, (v, s)| {
                let e = s.joint.excess(v);
                if e > m || e.is_nan() { e } else { m }
            })
    }

    fn check(&self, body: &Body<'_>) -> Result<(), BodyError> {
        if self.count != body.len() {
            return Err(BodyError::CountMismatch);
        }
        if body.len() > N {
            return Err(BodyError::TooManySegments);
        }
        Ok(())
    }

    /// The local (parent-relative) pose of these angles.
    pub fn to_local(&self, body: &Body<'_>, out: &mut LocalPose<N>) -> Result<(), BodyError> {
        self.check(body)?;
        out.count = self.count;
        out.root_position = self.root_position;
        for (i, ((r, v), s)) in out
            .rotations
            .iter_mut()
            .zip(&self.values)
            .zip(body.segments)
            .enumerate()
        {
            *r = if i == 0 {
                self.root_rotation
            } else {
                s.joint.rotation(v)
            };
        }
        Ok(())
    }

    /// World transforms of these angles via [`pose::forward`]; `local` is scratch.
    pub fn forward(
        &self,
        body: &Body<'_>,
        local: &mut LocalPose<N>,
        out: &mut Pose<N>,
    ) -> Result<(), BodyError> {
        self.to_local(body, local)?;
        pose::forward(&body.hierarchy(), local, out)?;
        Ok(())
    }

    /// Projects a local pose (e.g. a synthesized one, converted with
    /// [`pose::to_local`]) onto the joints' degrees of freedom, within limits.
    /// The root keeps its full placement. Like [`Angles::to_local`], this
    /// trusts the body's structure (see [`Body::validate`]).
    pub fn from_local(body: &Body<'_>, local: &LocalPose<N>) -> Result<Self, BodyError> {
        let mut a = Angles {
            count: 0,
            root_position: Vec3::ZERO,
            root_rotation: Quat::IDENTITY,
            values: [[0.0; 3]; N],
        };
        a.set_from_local(body, local)?;
        Ok(a)
    }

    /// [`Angles::from_local`] in place (the live loop's per-frame
    /// conversion, without a copy of the state). On an error `self` is left
    /// unchanged.
    pub fn set_from_local(
        &mut self,
        body: &Body<'_>,
        local: &LocalPose<N>,
    ) -> Result<(), BodyError> {
        if body.is_empty() {
            return Err(BodyError::Empty);
        }
        let Some((used, unused)) = self.values.split_at_mut_checked(body.len()) else {
            return Err(BodyError::TooManySegments);
        };
        if local.count != body.len() {
            return Err(BodyError::CountMismatch);
        }
        self.count = body.len();
        self.root_position = local.root_position;
        self.root_rotation = local.rotations.first().copied().unwrap_or(Quat::IDENTITY);
        for (i, ((v, s), &q)) in used
            .iter_mut()
            .zip(body.segments)
            .zip(&local.rotations)
            .enumerate()
        {
            *v = if i == 0 { [0.0; 3] } else { s.joint.project(q) };
        }
        unused.fill([0.0; 3]);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f32, b: f32, tol: f32) -> bool {
        (a - b).abs() <= tol
    }

    fn rotation_distance(a: Quat, b: Quat) -> f32 {
        let d = a.dot(b).abs().min(1.0);
        2.0 * math::acos(d)
    }

    const ORDERS: [[Axis; 3]; 6] = [
        [Axis::X, Axis::Y, Axis::Z],
        [Axis::X, Axis::Z, Axis::Y],
        [Axis::Y, Axis::X, Axis::Z],
        [Axis::Y, Axis::Z, Axis::X],
        [Axis::Z, Axis::X, Axis::Y],
        [Axis::Z, Axis::Y, Axis::X],
    ];

    #[test]
    fn axis_rotation_matches_right_hand_rule() {
        // 90° about Z takes +X to +Y; about X takes +Y to +Z; about Y takes +Z to +X.
        let q = Axis::Z.rotation(core::f32::consts::FRAC_PI_2);
        assert!((q * Vec3::X - Vec3::Y).length_squared() < 1e-10);
        let q = Axis::X.rotation(core::f32::consts::FRAC_PI_2);
        assert!((q * Vec3::Y - Vec3::Z).length_squared() < 1e-10);
        let q = Axis::Y.rotation(core::f32::consts::FRAC_PI_2);
        assert!((q * Vec3::Z - Vec3::X).length_squared() < 1e-10);
    }

    #[test]
    fn rotate_after_is_the_quaternion_product() {
        let q = Quat::from_xyzw(0.1, -0.7, 0.3, 0.64);
        for axis in [Axis::X, Axis::Y, Axis::Z] {
            for angle in [-2.0, 0.3, 1.7] {
                let a = axis.rotate_after(q, angle);
                let b = q * axis.rotation(angle);
                assert!((a - b).length() < 1e-6, "{axis:?} {angle}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn euler_round_trips_all_orders() {
        let wide = |a| Dof::new(a, -PI, PI);
        let mid = |a| Dof::new(a, -1.5, 1.5);
        let samples = [
            [0.3, -1.2, 2.5],
            [-2.9, 1.4, -0.1],
            [1.0, 0.0, -1.0],
            [0.0, 1.5, 0.7],
            [3.0, -0.2, 3.1],
        ];
        for o in ORDERS {
            let j = Joint::three(wide(o[0]), mid(o[1]), wide(o[2]));
            for v in samples {
                let q = j.rotation(&v);
                let p = j.project(q);
                for k in 0..3 {
                    assert!(close(p[k], v[k], 2e-3), "{o:?} {v:?} -> {p:?}");
                }
            }
        }
    }

    #[test]
    fn euler_at_gimbal_lock_reproduces_rotation() {
        for o in ORDERS {
            let j = Joint::three(
                Dof::new(o[0], -3.2, 3.2),
                Dof::new(o[1], -3.2, 3.2),
                Dof::new(o[2], -3.2, 3.2),
            );
            for beta in [core::f32::consts::FRAC_PI_2, -core::f32::consts::FRAC_PI_2] {
                let q = j.rotation(&[0.4, beta, -0.3]);
                let back = j.rotation(&j.project(q));
                assert!(rotation_distance(q, back) < 5e-3, "{o:?}");
            }
        }
    }

    #[test]
    fn one_dof_projection_takes_the_twist() {
        let j = Joint::one(Dof::degrees(Axis::X, -170.0, 170.0));
        // A rotation about X composed with a small rotation about Y: the twist
        // about X is recovered.
        let q = Axis::X.rotation(1.1) * Axis::Y.rotation(0.05);
        assert!(close(j.project(q)[0], 1.1, 2e-3));
        // Exact for a pure rotation about the axis, including -q.
        assert!(close(j.project(-Axis::X.rotation(-0.7))[0], -0.7, 1e-5));
    }

    #[test]
    fn projection_clamps_to_limits() {
        let j = Joint::two(
            Dof::degrees(Axis::X, 0.0, 90.0),
            Dof::degrees(Axis::Z, -10.0, 10.0),
        );
        let p = j.project(Axis::X.rotation(-0.5) * Axis::Z.rotation(0.5));
        assert!(close(p[0], 0.0, 1e-6) && close(p[1], 10f32.to_radians(), 1e-6));
    }

    #[test]
    fn projection_prefers_the_euler_solution_inside_limits() {
        // β beyond 90° is only representable by the second solution.
        let j = Joint::three(
            Dof::new(Axis::Z, -3.2, 3.2),
            Dof::new(Axis::Y, 1.2, 3.0),
            Dof::new(Axis::X, -3.2, 3.2),
        );
        let v = [0.2, 2.0, -0.4];
        let p = j.project(j.rotation(&v));
        assert!(
            rotation_distance(j.rotation(&v), j.rotation(&p)) < 2e-3,
            "{p:?}"
        );
        assert!(close(p[1], 2.0, 2e-3));
    }

    #[test]
    fn joint_validity() {
        assert!(
            Joint::three(
                Dof::new(Axis::X, -1.0, 1.0),
                Dof::new(Axis::Y, -1.0, 1.0),
                Dof::new(Axis::Z, -1.0, 1.0)
            )
            .is_valid()
        );
        assert!(!Joint::two(Dof::new(Axis::X, -1.0, 1.0), Dof::new(Axis::X, -1.0, 1.0)).is_valid());
        assert!(!Joint::one(Dof::new(Axis::X, 1.0, -1.0)).is_valid());
    }

    #[test]
    fn shipped_bodies_validate() {
        assert_eq!(tempus::BODY.validate(), Ok(()));
        assert_eq!(cmu::BODY.validate(), Ok(()));
        assert_eq!(cmu::BODY.len(), 31);
        assert_eq!(tempus::BODY.len(), tempus::SEGMENT_COUNT);
    }

    #[test]
    fn rest_and_limits() {
        let mut a = Angles::<64>::rest(&cmu::BODY).unwrap();
        assert_eq!(a.limit_excess(&cmu::BODY), 0.0);
        *a.get_mut(3).unwrap() = [10.0, -10.0, 10.0];
        assert!(a.limit_excess(&cmu::BODY) > 1.0);
        a.clamp_to_limits(&cmu::BODY);
        assert_eq!(a.limit_excess(&cmu::BODY), 0.0);
        assert!(a.get(31).is_none());
    }

    #[test]
    fn angles_to_local_and_back() {
        let body = &tempus::BODY;
        let mut a = Angles::<32>::rest(body).unwrap();
        for (i, s) in body.segments.iter().enumerate().skip(1) {
            let v = a.get_mut(i).unwrap();
            for (k, d) in s.joint.dofs().iter().enumerate() {
                v[k] = d.min + (d.max - d.min) * (0.2 + 0.15 * k as f32);
            }
        }
        let mut local = LocalPose::<32>::default();
        a.to_local(body, &mut local).unwrap();
        let b = Angles::from_local(body, &local).unwrap();
        for (x, y) in a.values.iter().zip(&b.values) {
            for k in 0..3 {
                assert!(close(x[k], y[k], 2e-3), "{x:?} {y:?}");
            }
        }
    }
}
