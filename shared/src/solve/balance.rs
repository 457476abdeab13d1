//! The reach-tree balancing algorithm of Badler et al. (1987), Figure 17.
//!
//! ```text
//! balance(node):
//!     balance every child; stwd = Σ child.stwd; stweight = Σ child.stweight
//!     stwd += w·(goal − touch);  stweight += w        (the node's own goals)
//!     repeat (up to the cap):
//!         prev = |stwd|
//!         solve_simple_chain(node, parent, touch + stwd / stweight)
//!         recompute stwd, stweight as above (children re-balanced)
//!     until |stwd| >= prev
//! ```
//!
//! The reach-tree root has no chain: with [`RootMode::Float`] the whole body is
//! translated by `stwd / stweight`; with [`RootMode::Fixed`] the chain from the
//! body root is solved instead. The loop also stops as soon as the displacement
//! is zero (below `tolerance · stweight`).
//!
//! Extensions: plane goals contribute their displacement (towards the nearest
//! point of the plane); a goal in another segment's frame also pulls that
//! segment, the opposite way; a node with an orientation goal reserves its own joint
//! for it (set by projecting the target orientation onto the joint's DOFs) and
//! its chain stops one joint higher.

use super::{Chain, Method, ReachTree, RootMode, SolveError, Solver, Work, ccd, dls, greedy};
use crate::goal::{Frame, Target};
use glam::{Quat, Vec3};

/// Balances the whole reach tree; returns (iterations, converged).
pub(super) fn solve<const N: usize>(
    solver: &Solver,
    tree: &ReachTree<N>,
    work: &mut Work<'_, '_, N>,
) -> Result<(u32, bool), SolveError> {
    let mut b = Balance {
        solver,
        tree,
        iterations: 0,
        capped: false,
    };
    b.balance(work, 0, 0)?;
    Ok((b.iterations, !b.capped))
}

struct Balance<'s, 't, const N: usize> {
    solver: &'s Solver,
    tree: &'t ReachTree<N>,
    iterations: u32,
    capped: bool,
}

impl<const N: usize> Balance<'_, '_, N> {
    /// Balances the subtree of `node`; returns its (stwd, stweight).
    fn balance(
        &mut self,
        work: &mut Work<'_, '_, N>,
        node: usize,
        depth: usize,
    ) -> Result<(Vec3, f32), SolveError> {
        let Some(seg) = self.tree.segment(node).filter(|_| depth <= N) else {
            return Ok((Vec3::ZERO, 0.0));
        };
        let (mut stwd, mut stweight) = self.displacement(work, node, seg, depth)?;
        let mut count = 0u16;
        loop {
            let prev = crate::goal::norm(stwd);
            if stweight <= 0.0 || prev <= self.solver.tolerance * stweight {
                break;
            }
            if count >= self.solver.max_iterations {
                self.capped = true;
                break;
            }
            count += 1;
            let shift = stwd / stweight;
            let target = work.touch(seg) + shift;
            if !self.move_node(work, node, seg, target, shift)? {
                break;
            }
            self.iterations = self.iterations.saturating_add(1);
            (stwd, stweight) = self.displacement(work, node, seg, depth)?;
            if crate::goal::norm(stwd) >= prev {
                break;
            }
        }
        Ok((stwd, stweight))
    }

    /// Re-balances the children, applies the node's orientation goal, and sums
    /// the weighted displacements (Fig. 17's `clear_displacements`,
    /// `balance_children`, `get_approx_solution`).
    fn displacement(
        &mut self,
        work: &mut Work<'_, '_, N>,
        node: usize,
        seg: usize,
        depth: usize,
    ) -> Result<(Vec3, f32), SolveError> {
        let tree = self.tree;
        let mut stwd = Vec3::ZERO;
        let mut stweight = 0.0;
        for child in tree.children(node) {
            let (d, w) = self.balance(work, child, depth + 1)?;
            stwd += d;
            stweight += w;
        }
        orient(work, seg)?;
        for (g, i) in work
            .goals
            .iter()
            .zip(0u8..)
            .filter(|(g, _)| g.is_active() && g.is_positional())
        {
            // A goal pulls its own segment towards the target and, if the target
            // is in another segment's frame, that segment the opposite way.
            let sign = if usize::from(g.segment) == seg {
                1.0
            } else if g.frame == Frame::Segment(u8::try_from(seg).unwrap_or(u8::MAX)) {
                -1.0
            } else {
                continue;
            };
            let r = g
                .evaluate(work.body, work.pose)
                .ok_or(SolveError::BadGoal(i))?;
            stwd += r.displacement() * (sign * g.weight);
            stweight += g.weight;
        }
        Ok((stwd, stweight))
    }

    /// Moves the node's touch point towards `target` (`shift` from where it is);
    /// returns false if nothing can move it.
    fn move_node(
        &mut self,
        work: &mut Work<'_, '_, N>,
        node: usize,
        seg: usize,
        target: Vec3,
        shift: Vec3,
    ) -> Result<bool, SolveError> {
        let top = match (
            self.tree.parent(node).and_then(|p| self.tree.segment(p)),
            self.solver.root,
        ) {
            (Some(p), _) => Some(p),
            (None, RootMode::Fixed) => None,
            (None, RootMode::Float) => {
                work.angles.root_position += shift;
                work.forward()?;
                return Ok(true);
            }
        };
        let chain =
            Chain::<N>::between(work.body, top, seg, orientation_target(work, seg).is_some());
        if chain.len() == 0 {
            return Ok(false);
        }
        let n = self.solver.chain_iterations;
        match self.solver.method {
            Method::Greedy => greedy::solve_chain(work, &chain, seg, target, n)?,
            Method::Ccd => ccd::solve_chain(work, &chain, seg, target, n)?,
            Method::Dls | Method::TreeDls => {
                dls::solve_chain(self.solver, work, &chain, seg, target)?
            }
        }
        Ok(true)
    }
}

/// The world target orientation of the heaviest active orientation goal on a
/// (non-root) segment.
fn orientation_target<const N: usize>(work: &Work<'_, '_, N>, seg: usize) -> Option<Quat> {
    if seg == 0 {
        return None;
    }
    let mut best: Option<(f32, Quat)> = None;
    for g in work
        .goals
        .iter()
        .filter(|g| usize::from(g.segment) == seg && g.is_active())
    {
        if let Target::Orientation(q) = g.target {
            let world = match g.frame {
                Frame::World => q,
                Frame::Segment(f) => {
                    work.pose
                        .rotations
                        .get(usize::from(f))
                        .copied()
                        .unwrap_or(Quat::IDENTITY)
                        * q
                }
            };
            if best.is_none_or(|(w, _)| g.weight > w) {
                best = Some((g.weight, world));
            }
        }
    }
    best.map(|(_, q)| q)
}

/// Sets a segment's own joint to its orientation goal (projected onto the DOFs).
fn orient<const N: usize>(work: &mut Work<'_, '_, N>, seg: usize) -> Result<(), SolveError> {
    let Some(target) = orientation_target(work, seg) else {
        return Ok(());
    };
    let (Some(parent), Some(s)) = (work.body.parent(seg), work.body.segment(seg)) else {
        return Ok(());
    };
    let rp = work
        .pose
        .rotations
        .get(parent)
        .copied()
        .unwrap_or(Quat::IDENTITY);
    let values = s.joint.project(rp.conjugate() * target);
    if let Some(v) = work.angles.get_mut(seg) {
        *v = values;
    }
    work.forward()
}
