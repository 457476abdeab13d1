//! Damped least squares on one simple chain (the chain solver of
//! [`Method::Dls`](super::Method::Dls)), and the small dense Cholesky solver
//! shared with the whole-tree solver.
//!
//! A chain step solves `(Σ c·cᵀ/D + I)·y = r` for the 3-vector displacement `r`
//! of the end point, with columns `c = ω × (e − p)` of the free DOFs and
//! per-DOF damping `D = λ²·|c|² + tension`, and moves each DOF by `c·y / D`.
//! DOFs on a limit that the step would push further out are left out.

use super::ccd::world_axes;
use super::{Chain, SolveError, Solver, Work};
use crate::math;
use glam::Vec3;

/// The largest rotation (rad) or translation (m) of one step.
pub(super) const MAX_STEP: f32 = 0.5;

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
            let (Some(parent), Some(s), Some(v)) = (
                work.body.parent(seg),
                work.body.segment(seg),
                work.angles.get(seg),
            ) else {
                continue;
            };
            let rp = work.pose.rotations.get(parent).copied().unwrap_or_default();
            let rs = work.pose.rotations.get(seg).copied().unwrap_or_default();
            let p = work.pose.positions.get(seg).copied().unwrap_or_default();
            let axes = world_axes(&s.joint, v, rp, rs);
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
        let biggest = cols
            .iter()
            .take(chain.len())
            .flatten()
            .fold(0.0f32, |m, (c, d)| m.max(math::abs(c.dot(y) * d)));
        let scale = if biggest > MAX_STEP {
            MAX_STEP / biggest
        } else {
            1.0
        };
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
pub(super) fn at_limit_outward(min: f32, max: f32, x: f32, g: f32) -> bool {
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
/// lower triangle read, overwritten by the Cholesky factor with `1/Lᵢᵢ` on the
/// diagonal); `b` becomes `x`. Returns false if `A` is not numerically
/// positive definite.
pub(super) fn cholesky_solve<const M: usize>(
    a: &mut [[f32; M]; M],
    m: usize,
    b: &mut [f32; M],
) -> bool {
    let m = m.min(M);
    // A = L·Lᵀ, row by row.
    for i in 0..m {
        let Some((done, rest)) = a.split_at_mut_checked(i) else {
            return false;
        };
        let Some((left, diag)) = rest.first_mut().and_then(|row| row.split_at_mut_checked(i))
        else {
            return false;
        };
        for (j, row_j) in done.iter().enumerate() {
            let Some((lk, tail)) = left.split_at_mut_checked(j) else {
                return false;
            };
            let dot: f32 = lk.iter().zip(row_j).map(|(x, y)| x * y).sum();
            if let (Some(x), Some(&inv)) = (tail.first_mut(), row_j.get(j)) {
                *x = (*x - dot) * inv;
            }
        }
        let sq: f32 = left.iter().map(|x| x * x).sum();
        let Some(d) = diag.first_mut() else {
            return false;
        };
        let v = *d - sq;
        if v <= 1e-20 || v.is_nan() {
            return false;
        }
        *d = math::rsqrt(v);
    }
    // L·z = b.
    for (i, row) in a.iter().enumerate().take(m) {
        let Some((head, tail)) = b.split_at_mut_checked(i) else {
            return false;
        };
        let s: f32 = row.iter().zip(head.iter()).map(|(l, z)| l * z).sum();
        if let (Some(x), Some(&inv)) = (tail.first_mut(), row.get(i)) {
            *x = (*x - s) * inv;
        }
    }
    // Lᵀ·x = z, column-oriented so that L is read by rows.
    for (i, row) in a.iter().enumerate().take(m).rev() {
        let Some((head, tail)) = b.split_at_mut_checked(i) else {
            return false;
        };
        let (Some(x), Some(&inv)) = (tail.first_mut(), row.get(i)) else {
            return false;
        };
        *x *= inv;
        let xi = *x;
        for (bk, l) in head.iter_mut().zip(row.iter()) {
            *bk -= l * xi;
        }
    }
    true
}
