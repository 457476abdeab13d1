//! Cyclic coordinate descent with joint limits, one DOF at a time.
//!
//! From the distal joint to the proximal one, each DOF is turned about its own
//! world axis by the angle that best aligns the end point with the target in
//! the plane perpendicular to that axis, then clamped to its limits. Because
//! every step is a single angle, the limits are respected exactly and nothing
//! needs projecting. A pass needs one forward kinematics at its end: while the
//! pass walks towards the root, the joints it has not reached yet do not move,
//! so their world frames stay valid, and the end point is rotated along.

use super::{Chain, SolveError, Work};
use crate::body::Joint;
use crate::math;
use glam::{Quat, Vec3};

/// Moves the touch point of `end` towards `target` with the joints of `chain`.
pub(super) fn solve_chain<const N: usize>(
    work: &mut Work<'_, '_, N>,
    chain: &Chain<N>,
    end: usize,
    target: Vec3,
    passes: u16,
) -> Result<(), SolveError> {
    for _ in 0..passes.max(1) {
        let mut e = work.touch(end);
        for seg in chain.segments().rev() {
            let (Some(parent), Some(s)) = (work.body.parent(seg), work.body.segment(seg)) else { continue };
            let rp = work.pose.rotations.get(parent).copied().unwrap_or(Quat::IDENTITY);
            let p = work.pose.positions.get(seg).copied().unwrap_or(Vec3::ZERO);
            let Some(values) = work.angles.get_mut(seg) else { continue };
            let axes = world_axes(&s.joint, values, rp);
            for ((v, dof), &w) in values.iter_mut().zip(s.joint.dofs()).zip(&axes).rev() {
                let (re, rt) = (e - p, target - p);
                let ep = re - w * w.dot(re);
                let tp = rt - w * w.dot(rt);
                if ep.length_squared() < 1e-12 || tp.length_squared() < 1e-12 {
                    continue;
                }
                let delta = math::atan2(w.dot(ep.cross(tp)), ep.dot(tp));
                let new = dof.clamp(*v + delta);
                e = p + axis_rotation(w, new - *v) * re;
                *v = new;
            }
        }
        work.forward()?;
    }
    Ok(())
}

/// World axes of a joint's DOFs, given the parent's world rotation: the axis of
/// DOF `k` is `R_parent · R_0 ⋯ R_{k−1} · axis_k`.
pub(super) fn world_axes(joint: &Joint, values: &[f32; 3], parent: Quat) -> [Vec3; 3] {
    let mut out = [Vec3::ZERO; 3];
    let mut q = parent;
    let last = joint.count().saturating_sub(1);
    for (k, ((o, d), &v)) in out.iter_mut().zip(joint.dofs()).zip(values).enumerate() {
        *o = q * d.axis.unit();
        if k < last {
            q *= d.axis.rotation(v);
        }
    }
    out
}

/// The rotation by `angle` about the unit axis `w`.
#[inline]
pub(super) fn axis_rotation(w: Vec3, angle: f32) -> Quat {
    let (s, c) = math::sin_cos(0.5 * angle);
    Quat::from_xyzw(w.x * s, w.y * s, w.z * s, c)
}
