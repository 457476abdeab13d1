//! The paper's `solve_simple_chain`: a greedy algorithm on the triangle
//! inequality. "Consecutive links are aligned until there is sufficient length
//! to solve the reach as a triangle or the chain is fully straightened."
//!
//! Walking the chain from its proximal joint, with `a` the current link (this
//! joint to the next, or to the end point), `b` the length of the rest of the
//! chain if straightened, and `c` the distance from this joint to the target:
//!
//! - `c ≥ a + b`: the target is out of reach of a bent chain, so the link is
//!   aligned with the target direction (straightening);
//! - `|a − b| < c < a + b`: the reach is solved as a triangle with sides
//!   `a, b, c`: the link is turned, in its current bending plane, to the angle
//!   `acos((a² + c² − b²)/(2ac))` from the target direction, after which the
//!   rest of the chain straightens towards the target;
//! - `c ≤ b − a`: the rest of the chain is long enough to fold back, and the
//!   link is left as it is (`c ≤ a − b`: it is aligned, as close as it gets).
//!
//! Joint limits (the paper has none) are applied the only way a greedy pass
//! can: each joint's new rotation is projected onto its DOFs and clamped, and
//! the joints further down re-measure from where the limited joint left them.
//! This is where the paper warns the greedy approach "may stop at local minima".

use super::{Chain, SolveError, Work};
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
        for k in 0..chain.len() {
            step(work, chain, k, end, target)?;
        }
    }
    Ok(())
}

/// The chain's points: joint origins from index `k` on, then the end point.
fn point<const N: usize>(work: &Work<'_, '_, N>, chain: &Chain<N>, k: usize, end: usize) -> Vec3 {
    match chain.segments().nth(k) {
        Some(s) => work.pose.positions.get(s).copied().unwrap_or(Vec3::ZERO),
        None => work.touch(end),
    }
}

/// One greedy step at the chain's `k`-th joint.
fn step<const N: usize>(
    work: &mut Work<'_, '_, N>,
    chain: &Chain<N>,
    k: usize,
    end: usize,
    target: Vec3,
) -> Result<(), SolveError> {
    let Some(seg) = chain.segments().nth(k) else {
        return Ok(());
    };
    let p = point(work, chain, k, end);
    let next = point(work, chain, k + 1, end);
    let a = crate::goal::norm(next - p);
    let to_target = target - p;
    let c = crate::goal::norm(to_target);
    if a < 1e-6 || c < 1e-9 {
        return Ok(());
    }
    let b: f32 = (k + 1..chain.len())
        .map(|j| crate::goal::norm(point(work, chain, j + 1, end) - point(work, chain, j, end)))
        .sum();
    let d = to_target / c;
    let u = (next - p) / a;
    let w = if c >= a + b || c <= a - b {
        d
    } else if c > b - a {
        let cos_phi = ((a * a + c * c - b * b) / (2.0 * a * c)).clamp(-1.0, 1.0);
        let sin_phi = math::sqrt((1.0 - cos_phi * cos_phi).max(0.0));
        d * cos_phi + bend_direction(u, d, work, chain, k, end) * sin_phi
    } else {
        return Ok(());
    };
    turn(work, seg, math::rotation_arc(u, w))
}

/// The unit direction, perpendicular to `d`, of the current bending plane.
fn bend_direction<const N: usize>(
    u: Vec3,
    d: Vec3,
    work: &Work<'_, '_, N>,
    chain: &Chain<N>,
    k: usize,
    end: usize,
) -> Vec3 {
    let perp = u - d * u.dot(d);
    if perp.length_squared() > 1e-8 {
        return math::normalize_vec3(perp);
    }
    // The link points at the target: bend the way the rest of the chain bends.
    let rest = point(work, chain, chain.len(), end) - point(work, chain, k + 1, end);
    let perp = rest - d * rest.dot(d);
    if perp.length_squared() > 1e-8 {
        return math::normalize_vec3(perp);
    }
    let other = if math::abs(d.x) < 0.6 {
        Vec3::X
    } else {
        Vec3::Y
    };
    math::normalize_vec3(d.cross(other))
}

/// Applies the world rotation `delta` to segment `seg` (about its joint),
/// projected onto the joint's DOFs and clamped; recomputes the pose.
fn turn<const N: usize>(
    work: &mut Work<'_, '_, N>,
    seg: usize,
    delta: Quat,
) -> Result<(), SolveError> {
    let (Some(parent), Some(s)) = (work.body.parent(seg), work.body.segment(seg)) else {
        return Ok(());
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
    let values = s.joint.project(rp.conjugate() * (delta * rs));
    if let Some(v) = work.angles.get_mut(seg) {
        *v = values;
    }
    work.forward()
}
