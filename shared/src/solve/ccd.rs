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
            let (Some(parent), Some(s)) = (work.body.parent(seg), work.body.segment(seg)) else {
                continue;
            };
            let rp = work
                .pose
                .rotations
                .get(parent)
                .copied()
                .unwrap_or(Quat::IDENTITY);
            let rs = work
                .pose
                .rotations
                .get(seg)
                .copied()
                .unwrap_or(Quat::IDENTITY);
            let p = work.pose.positions.get(seg).copied().unwrap_or(Vec3::ZERO);
            let Some(values) = work.angles.get_mut(seg) else {
                continue;
            };
            let axes = world_axes(&s.joint, values, rp, rs);
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

/// World axes of a joint's DOFs, given the parent's and the segment's world
/// rotations: the axis of DOF `k` is `R_parent · R_0 ⋯ R_{k−1} · axis_k`. The
/// first is `R_parent · axis_0`, the last `R_segment · axis_last` (a rotation
/// leaves its own axis fixed), so only a middle DOF needs a rotation built
/// (one `sin_cos`).
pub(super) fn world_axes(
    joint: &Joint,
    values: &[f32; 3],
    parent: Quat,
    segment: Quat,
) -> [Vec3; 3] {
    match joint.dofs() {
        [a] => [segment * a.axis.unit(), Vec3::ZERO, Vec3::ZERO],
        [a, b] => [parent * a.axis.unit(), segment * b.axis.unit(), Vec3::ZERO],
        [a, b, c] => [
            parent * a.axis.unit(),
            parent * (a.axis.rotation(values[0]) * b.axis.unit()),
            segment * c.axis.unit(),
        ],
        _ => [Vec3::ZERO; 3],
    }
}

/// The rotation by `angle` about the unit axis `w`.
#[inline]
pub(super) fn axis_rotation(w: Vec3, angle: f32) -> Quat {
    let (s, c) = math::sin_cos(0.5 * angle);
    Quat::from_xyzw(w.x * s, w.y * s, w.z * s, c)
}
