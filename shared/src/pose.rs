//! Poses: the hybrid position + quaternion representation of Wiley & Hahn
//! (1997), the joint-local form, and the conversions between them.
//!
//! # Representation
//!
//! A [`Pose`] stores, for every segment of the figure, its **absolute** (world)
//! joint origin and its **absolute** orientation as a unit quaternion. This is
//! the "hybrid position and orientation representation corresponding to data
//! from magnetic trackers" of Wiley & Hahn (Figure 1): each segment is placed
//! independently, the way a tracker reports it, rather than as a chain of
//! joint angles.
//!
//! A [`LocalPose`] is the classic joint-local form: one root translation and,
//! per segment, the rotation relative to its parent. Together with a
//! [`Hierarchy`] (parents and rest offsets) it determines a [`Pose`] through
//! [`forward`] kinematics; [`to_local`] goes back (W&H: "a simple conversion
//! between this hybrid representation and joint Euler angle forms"). Joint
//! angles for individual degrees of freedom are the `body` module's business;
//! it builds on [`LocalPose`].
//!
//! # Why interpolate the hybrid form
//!
//! Synthesis blends several example poses (lerp for positions, slerp for
//! orientations). Blending joint-local angles composes errors down the chain:
//! a small difference in the shoulder angle swings the whole arm, so the hand
//! of a blend of two reaches is not between the two hands, and Euler angles
//! add their own trouble (gimbal lock, wrap-around at ±π, order dependence,
//! non-uniform speed). Blending *absolute* positions and orientations keeps
//! every segment between its examples in world space: the hand of the blend
//! lies on the segment between the example hands, which is exactly what
//! interpolation synthesis for hand placement needs, and quaternion slerp has
//! no singularities. W&H report this "allows a greater degree of
//! interpolation" with dissimilar examples.
//!
//! The price is that blended absolute positions no longer keep the rig's limb
//! lengths exactly (the interpolated elbow–wrist distance of two poses is
//! shorter than either). [`enforce_lengths`] restores them: each child origin
//! is moved along the line from its (already corrected) parent origin to its
//! own interpolated origin, to the rig length `|offset|`, and the correction is
//! propagated to all descendants (W&H: "the lower arm can be adjusted along the
//! line between the elbow and shoulder point to the correct distance"). The
//! orientations are kept. Alternatively, [`to_local`] followed by [`forward`]
//! rebuilds all positions from the orientations and the rig offsets.
//!
//! # Conventions
//!
//! - Segments are indexed `0..len`; segment 0 is the only root
//!   (`parents[0] == NO_PARENT`), and every other segment's parent has a
//!   smaller index (`parents[i] < i`, topological order), so one forward pass
//!   visits parents before children.
//! - `offsets[i]` is the joint origin of segment `i` in its parent's frame
//!   (the rest translation from the parent's origin). The root's offset is
//!   ignored by [`forward`]; the root is placed by
//!   [`LocalPose::root_position`].
//! - World origin of `i`: `p[i] = p[parent] + R[parent] · offsets[i]`; world
//!   orientation `R[i] = R[parent] · L[i]` (quaternion product, the local
//!   rotation applied in the parent's frame).
//! - Units are metres, right-handed, Y up. Quaternions are unit length; `q`
//!   and `−q` are the same rotation.
//! - Capacity is the const parameter `N` (default [`MAX_SEGMENTS`]); the
//!   number of segments in use is `count ≤ N`. Functions that receive a pose
//!   whose `count` exceeds `N` return [`PoseError::Capacity`].

use glam::{Quat, Vec3};

use crate::math;

/// Default segment capacity of a pose (and the most a `u8` parent index with
/// [`NO_PARENT`] reserved comfortably addresses).
pub const MAX_SEGMENTS: usize = 64;

/// Parent index of the root segment.
pub const NO_PARENT: u8 = u8::MAX;

/// Why a pose operation was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PoseError {
    /// More segments than the pose type holds (`count > N`).
    Capacity,
    /// The hierarchy's `parents` and `offsets` differ in length, or differ from
    /// the pose's segment count.
    LengthMismatch,
    /// Segment 0 is not a root, or a segment's parent is not an earlier segment.
    ParentOrder {
        /// The offending segment.
        segment: u8,
    },
    /// A segment index at or past the segment count.
    Index,
}

/// Absolute (world) hybrid pose: one position and one unit quaternion per
/// segment (see the module doc). Fields are public for in-place use; keep
/// `count ≤ N`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose<const N: usize = MAX_SEGMENTS> {
    /// Segments in use.
    pub count: usize,
    /// World joint origin of each segment (metres).
    pub positions: [Vec3; N],
    /// World orientation of each segment.
    pub rotations: [Quat; N],
}

impl<const N: usize> Default for Pose<N> {
    fn default() -> Self {
        Self {
            count: 0,
            positions: [Vec3::ZERO; N],
            rotations: [Quat::IDENTITY; N],
        }
    }
}

impl<const N: usize> Pose<N> {
    /// A pose of `count` segments, all at the origin with identity rotation.
    pub fn new(count: usize) -> Result<Self, PoseError> {
        if count > N {
            return Err(PoseError::Capacity);
        }
        Ok(Self {
            count,
            ..Self::default()
        })
    }

    /// Segments in use (never more than `N`).
    #[inline]
    #[must_use]
    pub fn len(&self) -> usize {
        self.count.min(N)
    }

    /// Whether the pose has no segment.
    #[inline]
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// World origin of segment `i`.
    #[inline]
    #[must_use]
    pub fn position(&self, i: usize) -> Option<Vec3> {
        self.positions().get(i).copied()
    }

    /// World orientation of segment `i`.
    #[inline]
    #[must_use]
    pub fn rotation(&self, i: usize) -> Option<Quat> {
        self.rotations().get(i).copied()
    }

    /// Sets segment `i`.
    pub fn set(&mut self, i: usize, position: Vec3, rotation: Quat) -> Result<(), PoseError> {
        let n = self.len();
        match (
            self.positions.get_mut(..n).and_then(|p| p.get_mut(i)),
            self.rotations.get_mut(i),
        ) {
            (Some(p), Some(r)) => {
                *p = position;
                *r = rotation;
                Ok(())
            }
            _ => Err(PoseError::Index),
        }
    }

    /// The positions in use.
    #[inline]
    #[must_use]
    pub fn positions(&self) -> &[Vec3] {
        self.positions.get(..self.len()).unwrap_or(&[])
    }

    /// The rotations in use.
    #[inline]
    #[must_use]
    pub fn rotations(&self) -> &[Quat] {
        self.rotations.get(..self.len()).unwrap_or(&[])
    }

    /// The positions in use, mutable.
    #[inline]
    pub fn positions_mut(&mut self) -> &mut [Vec3] {
        let n = self.len();
        self.positions.get_mut(..n).unwrap_or(&mut [])
    }

    /// The rotations in use, mutable.
    #[inline]
    pub fn rotations_mut(&mut self) -> &mut [Quat] {
        let n = self.len();
        self.rotations.get_mut(..n).unwrap_or(&mut [])
    }
}

/// Joint-local pose: the root translation plus, per segment, the rotation
/// relative to the parent (the root's is its world rotation). Fields are
/// public for in-place use; keep `count ≤ N`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalPose<const N: usize = MAX_SEGMENTS> {
    /// Segments in use.
    pub count: usize,
    /// World position of the root's joint origin (metres).
    pub root_position: Vec3,
    /// Rotation of each segment relative to its parent.
    pub rotations: [Quat; N],
}

impl<const N: usize> Default for LocalPose<N> {
    fn default() -> Self {
        Self {
            count: 0,
            root_position: Vec3::ZERO,
            rotations: [Quat::IDENTITY; N],
        }
    }
}

impl<const N: usize> LocalPose<N> {
    /// The rest pose of `count` segments: root at the origin, identity rotations.
    pub fn new(count: usize) -> Result<Self, PoseError> {
        if count > N {
            return Err(PoseError::Capacity);
        }
        Ok(Self {
            count,
            ..Self::default()
        })
    }

    /// Segments in use (never more than `N`).
    #[inline]
    #[must_use]
    pub fn len(&self) -> usize {
        self.count.min(N)
    }

    /// Whether the pose has no segment.
    #[inline]
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Local rotation of segment `i`.
    #[inline]
    #[must_use]
    pub fn rotation(&self, i: usize) -> Option<Quat> {
        self.rotations
            .get(..self.len())
            .and_then(|r| r.get(i))
            .copied()
    }
}

/// A borrowed skeleton topology (see the module doc for the conventions).
#[derive(Clone, Copy, Debug)]
pub struct Hierarchy<'a> {
    /// Parent of each segment: [`NO_PARENT`] for segment 0, else an earlier index.
    pub parents: &'a [u8],
    /// Joint origin of each segment in its parent's frame (metres).
    pub offsets: &'a [Vec3],
}

impl Hierarchy<'_> {
    /// Number of segments.
    #[inline]
    #[must_use]
    pub fn len(&self) -> usize {
        self.parents.len()
    }

    /// Whether there is no segment.
    #[inline]
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.parents.is_empty()
    }

    /// Checks the structure and returns the segment count.
    pub fn validate(&self) -> Result<usize, PoseError> {
        let n = self.parents.len();
        if self.offsets.len() != n {
            return Err(PoseError::LengthMismatch);
        }
        for (i, &p) in self.parents.iter().enumerate() {
            let ok = if i == 0 {
                p == NO_PARENT
            } else {
                usize::from(p) < i
            };
            if !ok {
                return Err(PoseError::ParentOrder {
                    segment: u8::try_from(i).unwrap_or(u8::MAX),
                });
            }
        }
        Ok(n)
    }

    /// Validates and checks that `count` segments fit both the hierarchy and `N`.
    fn check<const N: usize>(&self, count: usize) -> Result<usize, PoseError> {
        if count > N {
            return Err(PoseError::Capacity);
        }
        let n = self.validate()?;
        if n != count {
            return Err(PoseError::LengthMismatch);
        }
        Ok(n)
    }
}

/// Forward kinematics: world pose of a joint-local pose. `out.count` is set to
/// the segment count. Rotations are composed without renormalization.
pub fn forward<const N: usize>(
    h: &Hierarchy,
    local: &LocalPose<N>,
    out: &mut Pose<N>,
) -> Result<(), PoseError> {
    let n = h.check::<N>(local.count)?;
    out.count = n;
    for (i, ((&parent, &offset), &lr)) in h
        .parents
        .iter()
        .zip(h.offsets)
        .zip(&local.rotations)
        .enumerate()
    {
        let (p, r) = match (
            out.positions.get(usize::from(parent)),
            out.rotations.get(usize::from(parent)),
        ) {
            (Some(&pp), Some(&pr)) if i > 0 => (pp + pr * offset, pr * lr),
            _ => (local.root_position, lr),
        };
        if let (Some(op), Some(or)) = (out.positions.get_mut(i), out.rotations.get_mut(i)) {
            *op = p;
            *or = r;
        }
    }
    Ok(())
}

/// Inverse of [`forward`] for the rotations: local rotation of each segment
/// `conj(R[parent]) · R[i]` (for unit quaternions the conjugate is the
/// inverse), root position from segment 0. The non-root positions are not
/// part of a [`LocalPose`]: they follow from the rig offsets.
pub fn to_local<const N: usize>(
    h: &Hierarchy,
    pose: &Pose<N>,
    out: &mut LocalPose<N>,
) -> Result<(), PoseError> {
    let n = h.check::<N>(pose.count)?;
    out.count = n;
    out.root_position = pose.positions.first().copied().unwrap_or(Vec3::ZERO);
    for ((lr, &parent), &r) in out.rotations.iter_mut().zip(h.parents).zip(&pose.rotations) {
        *lr = match pose.rotations.get(usize::from(parent)) {
            Some(&pr) if parent != NO_PARENT => pr.conjugate() * r,
            _ => r,
        };
    }
    Ok(())
}

/// Restores the rig's limb lengths in an interpolated pose (W&H limb-length
/// enforcement). In topological order, each child origin is placed on the ray
/// from its parent's corrected origin along the child's *original* direction
/// from the parent (`p[i] − p[parent]` before any change), at distance
/// `|offsets[i]|`; since every child moves with its parent first, the
/// correction propagates to all descendants. If a child coincides with its
/// parent, the rig direction `R[parent] · offsets[i]` is used. The root and
/// all orientations are unchanged.
pub fn enforce_lengths<const N: usize>(h: &Hierarchy, pose: &mut Pose<N>) -> Result<(), PoseError> {
    let n = h.check::<N>(pose.count)?;
    // Original positions are needed after parents have moved.
    let original = pose.positions;
    for i in 1..n {
        let (Some(&parent), Some(&offset)) = (h.parents.get(i), h.offsets.get(i)) else {
            return Err(PoseError::LengthMismatch);
        };
        let pi = usize::from(parent);
        let (Some(&op), Some(&oc), Some(&np), Some(&pr)) = (
            original.get(pi),
            original.get(i),
            pose.positions.get(pi),
            pose.rotations.get(pi),
        ) else {
            return Err(PoseError::Index);
        };
        let mut dir = math::normalize_vec3(oc - op);
        if dir == Vec3::ZERO {
            dir = math::normalize_vec3(pr * offset);
        }
        if let Some(p) = pose.positions.get_mut(i) {
            *p = np + dir * math::length(offset);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Vec3, b: Vec3, tol: f32) -> bool {
        (a - b).abs().max_element() <= tol
    }

    /// Three segments in a chain along +X, 1 m apart; rotations about Z.
    const PARENTS: [u8; 3] = [NO_PARENT, 0, 1];
    const OFFSETS: [Vec3; 3] = [
        Vec3::new(9.0, 9.0, 9.0),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(1.0, 0.0, 0.0),
    ];

    #[test]
    fn forward_hand_worked_chain() {
        // Root at (0,0,1) turned +90° about Z; joint 1 turned another +90°.
        // Segment 1 origin: root + Rz(90)·(1,0,0) = (0,1,1).
        // Segment 2 origin: (0,1,1) + Rz(180)·(1,0,0) = (−1,1,1).
        let h = Hierarchy {
            parents: &PARENTS,
            offsets: &OFFSETS,
        };
        let rz90 = math::from_axis_angle(Vec3::Z, core::f32::consts::FRAC_PI_2);
        let mut local = LocalPose::<4>::new(3).unwrap();
        local.root_position = Vec3::new(0.0, 0.0, 1.0);
        local.rotations[0] = rz90;
        local.rotations[1] = rz90;
        let mut out = Pose::<4>::default();
        forward(&h, &local, &mut out).unwrap();
        assert_eq!(out.len(), 3);
        assert!(close(
            out.position(0).unwrap(),
            Vec3::new(0.0, 0.0, 1.0),
            0.0
        ));
        assert!(close(
            out.position(1).unwrap(),
            Vec3::new(0.0, 1.0, 1.0),
            1e-6
        ));
        assert!(close(
            out.position(2).unwrap(),
            Vec3::new(-1.0, 1.0, 1.0),
            1e-6
        ));
        // World rotation of segment 2 is 180° about Z: (0,0,±1,0).
        let r2 = out.rotation(2).unwrap();
        assert!((r2.z.abs() - 1.0).abs() < 1e-6 && r2.w.abs() < 1e-6);
    }

    #[test]
    fn validation_errors() {
        let bad_root = [0u8, 0, 1];
        let h = Hierarchy {
            parents: &bad_root,
            offsets: &OFFSETS,
        };
        assert_eq!(h.validate(), Err(PoseError::ParentOrder { segment: 0 }));
        let forward_ref = [NO_PARENT, 2, 1];
        let h = Hierarchy {
            parents: &forward_ref,
            offsets: &OFFSETS,
        };
        assert_eq!(h.validate(), Err(PoseError::ParentOrder { segment: 1 }));
        let h = Hierarchy {
            parents: &PARENTS,
            offsets: &OFFSETS[..2],
        };
        assert_eq!(h.validate(), Err(PoseError::LengthMismatch));
        let h = Hierarchy {
            parents: &PARENTS,
            offsets: &OFFSETS,
        };
        let local = LocalPose::<4>::new(2).unwrap();
        let mut out = Pose::<4>::default();
        assert_eq!(
            forward(&h, &local, &mut out),
            Err(PoseError::LengthMismatch)
        );
        let mut local2 = LocalPose::<2>::new(2).unwrap();
        local2.count = 3;
        assert_eq!(
            forward(&h, &local2, &mut Pose::<2>::default()),
            Err(PoseError::Capacity)
        );
        assert_eq!(Pose::<2>::new(3), Err(PoseError::Capacity));
    }

    #[test]
    fn accessors() {
        let mut p = Pose::<4>::new(2).unwrap();
        assert!(p.set(1, Vec3::X, Quat::IDENTITY).is_ok());
        assert_eq!(p.set(2, Vec3::X, Quat::IDENTITY), Err(PoseError::Index));
        assert_eq!(p.position(1), Some(Vec3::X));
        assert_eq!(p.position(2), None);
        assert_eq!(p.positions().len(), 2);
        p.count = 99;
        assert_eq!(p.len(), 4);
    }

    #[test]
    fn enforce_lengths_straight_chain() {
        // Chain squeezed to half length: children move out along the line.
        let h = Hierarchy {
            parents: &PARENTS,
            offsets: &OFFSETS,
        };
        let mut p = Pose::<3>::new(3).unwrap();
        p.positions = [
            Vec3::ZERO,
            Vec3::new(0.0, 0.5, 0.0),
            Vec3::new(0.0, 0.5, 0.5),
        ];
        enforce_lengths(&h, &mut p).unwrap();
        assert!(close(p.positions[1], Vec3::new(0.0, 1.0, 0.0), 1e-6));
        assert!(close(p.positions[2], Vec3::new(0.0, 1.0, 1.0), 1e-6));
        // Coincident child falls back to the rig direction R[parent]·offset.
        p.positions = [Vec3::ZERO, Vec3::ZERO, Vec3::ZERO];
        enforce_lengths(&h, &mut p).unwrap();
        assert!(close(p.positions[2], Vec3::new(2.0, 0.0, 0.0), 1e-6));
    }
}
