//! The reach tree of Badler et al. (1987), Figures 14–16.
//!
//! A node is a body segment that either carries an active goal or is a branch
//! between two or more subtrees that carry goals. Subtrees without goals are
//! pruned and simple chains are contracted, so every node hangs from its reach
//! parent by a simple chain of body joints: the joints of the segments strictly
//! below the parent down to and including the node. Solving that chain moves the
//! node (and everything below it) without disturbing goals outside its subtree.

use super::SolveError;
use crate::body::Body;
use crate::goal::{Frame, Goal};
use crate::pose::{MAX_SEGMENTS, NO_PARENT};

/// A reach tree: nodes in ascending segment order, so a node's reach parent
/// always comes before it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ReachTree<const N: usize = MAX_SEGMENTS> {
    len: usize,
    segment: [u8; N],
    parent: [u8; N],
    node_of: [u8; N],
    /// Bit `s`: segment `s` is a node or an ancestor of one.
    on_path: u64,
    /// Per segment: bit mask of its ancestors and itself.
    ancestry: [u64; N],
}

impl<const N: usize> ReachTree<N> {
    /// Builds the reach tree of the active goals. A goal given in another
    /// segment's frame makes both segments nodes: it pulls them towards each
    /// other. An empty goal set gives an empty tree.
    pub fn build(body: &Body<'_>, goals: &[Goal]) -> Result<Self, SolveError> {
        let mut tree = Self::EMPTY;
        tree.fill(body, goals)?;
        Ok(tree)
    }

    /// An empty tree (all zero bits: a new state is cleared, not copied;
    /// nothing past `len` is read).
    pub(crate) const EMPTY: Self = ReachTree {
        len: 0,
        segment: [0; N],
        parent: [0; N],
        node_of: [0; N],
        on_path: 0,
        ancestry: [0; N],
    };

    /// [`ReachTree::build`] into an empty tree, in place.
    pub(crate) fn fill(&mut self, body: &Body<'_>, goals: &[Goal]) -> Result<(), SolveError> {
        let n = body.len();
        if n > N {
            return Err(SolveError::Capacity);
        }
        self.node_of = [NO_PARENT; N];
        let mut has_goal = [false; N];
        for (i, g) in goals.iter().enumerate().filter(|(_, g)| g.is_active()) {
            let bad = SolveError::BadGoal(u8::try_from(i).unwrap_or(u8::MAX));
            let frame = match g.frame {
                Frame::World => None,
                Frame::Segment(f) => Some(usize::from(f)),
            };
            for s in core::iter::once(usize::from(g.segment)).chain(frame) {
                *has_goal.get_mut(s).filter(|_| s < n).ok_or(bad)? = true;
            }
        }
        // Bottom-up: does a segment's subtree hold a goal, and how many of its
        // children's subtrees do?
        let mut holds = has_goal;
        let mut goal_children = [0u8; N];
        for i in (1..n).rev() {
            let (Some(p), Some(&h)) = (body.parent(i), holds.get(i)) else {
                continue;
            };
            if h {
                if let Some(c) = goal_children.get_mut(p) {
                    *c = c.saturating_add(1);
                }
                if let Some(hp) = holds.get_mut(p) {
                    *hp = true;
                }
            }
        }
        let tree = self;
        for s in 0..n {
            let up = body
                .parent(s)
                .and_then(|p| tree.ancestry.get(p).copied())
                .unwrap_or(0);
            if let Some(a) = tree.ancestry.get_mut(s) {
                *a = up | bit(s);
            }
            if holds.get(s).copied().unwrap_or(false) {
                tree.on_path |= bit(s);
            }
        }
        for s in 0..n {
            let is_node = has_goal.get(s).copied().unwrap_or(false)
                || goal_children.get(s).copied().unwrap_or(0) >= 2;
            if is_node {
                tree.push(body, s);
            }
        }
        Ok(())
    }

    /// Appends segment `s` as a node, linking it to its nearest node ancestor.
    fn push(&mut self, body: &Body<'_>, s: usize) {
        let node = self.len;
        let parent = self.nearest_node_ancestor(body, s).unwrap_or(NO_PARENT);
        if let (Some(seg), Some(par), Some(of)) = (
            self.segment.get_mut(node),
            self.parent.get_mut(node),
            self.node_of.get_mut(s),
        ) {
            *seg = u8::try_from(s).unwrap_or(u8::MAX);
            *par = parent;
            *of = u8::try_from(node).unwrap_or(NO_PARENT);
            self.len += 1;
        }
    }

    fn nearest_node_ancestor(&self, body: &Body<'_>, s: usize) -> Option<u8> {
        let mut a = body.parent(s);
        for _ in 0..body.len() {
            let p = a?;
            match self.node_of.get(p) {
                Some(&n) if n != NO_PARENT => return Some(n),
                _ => a = body.parent(p),
            }
        }
        None
    }

    /// Number of nodes.
    #[must_use]
    pub const fn len(&self) -> usize {
        self.len
    }

    /// Whether the tree has no node (no active goal).
    #[must_use]
    pub const fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The body segment of node `node`.
    #[must_use]
    pub fn segment(&self, node: usize) -> Option<usize> {
        self.segment
            .get(node)
            .filter(|_| node < self.len)
            .map(|&s| usize::from(s))
    }

    /// The reach parent (a node index) of node `node`; `None` for the root.
    #[must_use]
    pub fn parent(&self, node: usize) -> Option<usize> {
        self.parent
            .get(node)
            .filter(|&&p| node < self.len && p != NO_PARENT)
            .map(|&p| usize::from(p))
    }

    /// The node of a body segment, if it is one.
    #[must_use]
    pub fn node_of(&self, segment: usize) -> Option<usize> {
        self.node_of
            .get(segment)
            .map(|&n| usize::from(n))
            .filter(|&n| n < self.len)
    }

    /// The root node's segment: the topmost node (the lowest common ancestor of
    /// all goal segments).
    #[must_use]
    pub fn root_segment(&self) -> Option<usize> {
        self.segment(0)
    }

    /// The children (node indices) of node `node`.
    pub fn children(&self, node: usize) -> impl Iterator<Item = usize> + '_ {
        let lim = self.len;
        self.parent
            .iter()
            .take(lim)
            .enumerate()
            .filter(move |&(_, &p)| usize::from(p) == node)
            .map(|(i, _)| i)
    }

    /// Whether the solver may move `segment`'s joint: it is an ancestor-or-self
    /// of a node (so it lies on a node's simple chain) and strictly below the
    /// anchor — the reach-tree root when `anchor` is `None` (the paper: the
    /// linkage above the reach-tree root is not changed), or `anchor` itself
    /// (e.g. the body root, whose chain to the reach-tree root is then solved).
    #[must_use]
    pub fn moves(&self, segment: usize, anchor: Option<usize>) -> bool {
        let Some(anchor) = anchor.or_else(|| self.root_segment()) else {
            return false;
        };
        let below = segment != anchor
            && self
                .ancestry
                .get(segment)
                .is_some_and(|a| a & bit(anchor) != 0);
        below && self.on_path & bit(segment) != 0
    }

    /// Bit mask of the ancestors of `segment` and itself.
    #[must_use]
    pub fn ancestry(&self, segment: usize) -> u64 {
        self.ancestry.get(segment).copied().unwrap_or(0)
    }
}

/// The bit of segment `s` in a 64-bit mask (0 beyond 63).
#[inline(always)]
#[must_use]
fn bit(s: usize) -> u64 {
    if s < 64 { 1 << s } else { 0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::{Joint, Segment, offsets_of, parents_of, tempus};
    use glam::Vec3;

    const fn seg(name: &'static str, parent: u8) -> Segment<'static> {
        Segment {
            name,
            parent,
            origin: Vec3::Y,
            joint: Joint::FIXED,
            touch: Vec3::Y,
        }
    }

    // Figure 15(a): A is the root; B below A branches into C and D; C branches
    // into E and F; G hangs below D.
    const FIG15: [Segment<'static>; 7] = [
        seg("A", NO_PARENT),
        seg("B", 0),
        seg("C", 1),
        seg("D", 1),
        seg("E", 2),
        seg("F", 2),
        seg("G", 3),
    ];
    const P: [u8; 7] = parents_of(&FIG15);
    const O: [Vec3; 7] = offsets_of(&FIG15);
    const BODY: Body<'static> = Body {
        segments: &FIG15,
        parents: &P,
        offsets: &O,
    };

    fn children<const N: usize>(t: &ReachTree<N>, node: usize) -> ([usize; 4], usize) {
        let mut out = [0; 4];
        let mut k = 0;
        for c in t.children(node) {
            out[k] = c;
            k += 1;
        }
        (out, k)
    }

    #[test]
    fn figure_15_reach_tree() {
        let goals = [
            Goal::reach(0, Vec3::ZERO, 1.0),
            Goal::reach(4, Vec3::ZERO, 1.0),
            Goal::reach(6, Vec3::ZERO, 1.0),
        ];
        let t = ReachTree::<8>::build(&BODY, &goals).unwrap();
        // Nodes A, B, E, G; B is the implicit branch; C (one goal subtree) is not.
        let segs: [usize; 4] = core::array::from_fn(|i| t.segment(i).unwrap());
        assert_eq!(segs, [0, 1, 4, 6]);
        assert_eq!(t.len(), 4);
        assert_eq!(t.parent(0), None);
        assert_eq!(t.parent(1), Some(0));
        assert_eq!(t.parent(2), Some(1));
        assert_eq!(t.parent(3), Some(1));
        assert_eq!(t.node_of(2), None);
        assert_eq!(children(&t, 1), ([2, 3, 0, 0], 2));
        // F's subtree moves with the chain B..E but F's own joint is not solved.
        assert!(t.moves(2, None) && t.moves(4, None) && !t.moves(5, None));
        assert!(!t.moves(0, None));
    }

    #[test]
    fn inactive_goals_are_pruned_and_bad_indices_rejected() {
        let goals = [
            Goal::reach(4, Vec3::ZERO, 0.0),
            Goal::reach(6, Vec3::ZERO, 2.0),
        ];
        let t = ReachTree::<8>::build(&BODY, &goals).unwrap();
        assert_eq!((t.len(), t.root_segment()), (1, Some(6)));
        // The root's chain to the body root (anchor 0) is movable.
        assert!(t.moves(1, Some(0)) && t.moves(3, Some(0)) && !t.moves(2, Some(0)));
        assert_eq!(
            ReachTree::<8>::build(&BODY, &[Goal::reach(9, Vec3::ZERO, 1.0)]),
            Err(SolveError::BadGoal(0))
        );
        assert!(ReachTree::<8>::build(&BODY, &[]).unwrap().is_empty());
    }

    #[test]
    fn figure_16_restrained_reach() {
        use tempus::index::*;
        let goals = [
            Goal::reach(LOWER_TORSO, Vec3::ZERO, 100.0),
            Goal::reach(LEFT_SHOULDER, Vec3::ZERO, 100.0),
            Goal::reach(RIGHT_HAND, Vec3::ZERO, 10.0),
        ];
        let t = ReachTree::<32>::build(&tempus::BODY, &goals).unwrap();
        let segs: [usize; 4] = core::array::from_fn(|i| t.segment(i).unwrap());
        // Lower torso, upper torso (the implicit branch), left shoulder, right hand.
        assert_eq!(segs, [0, 1, 4, 11]);
        assert_eq!(
            [t.parent(1), t.parent(2), t.parent(3)],
            [Some(0), Some(1), Some(1)]
        );
    }
}
