//! The unrolled tree of the W&H hand grid (three linear axes).
//!
//! The window is 2×2×2 and the rotation tree
//! `z(y(x(q0, q1), x(q2, q3)), y(x(q4, q5), x(q6, q7)))`. Its slerps skip
//! the normalization step of the fast slerp
//! ([`crate::math::SlerpWeight::blend_lanes`]: a blend of unit inputs is
//! already unit to within 4e-6) and only the root is normalized, by the same
//! Newton step ([`crate::math::renormalize_lanes`]); the result stays within
//! the grid's stated bound (see [`crate::grid`]) and unit to within 1e-6
//! (`tests/synth.rs`). When a level's coefficient is exactly 0 or 1 that
//! level passes its input through, so grid points return their samples bit
//! for bit.
//!
//! On targets with SIMD (the host) segments go in blocks of eight, level by
//! level on four segments at a time ([`crate::math::F4`] lanes); on the
//! Cortex-M each segment runs on its own. Both perform the same operations
//! per segment in the same order, so they give the same bits (tested).

use glam::{Quat, Vec3};

use super::lanes::{Soa, blend_pairs, fetch_block};
use super::query::AxisQuery;
use super::{GridError, MAX_WINDOW, Samples};
use crate::math::{self, F4, Lane, LaneWeight, SlerpWeight};

/// The W&H hand grid, three linear axes: a 2×2×2 window and the tree
/// `z(y(x(q0, q1), x(q2, q3)), y(x(q4, q5), x(q6, q7)))` of unnormalized
/// blends, normalized once if any level blends.
pub(super) struct Trilinear {
    index: [u32; 8],
    weight: [f32; 8],
    slerp: [SlerpWeight; 3],
    blends: bool,
}

impl Trilinear {
    pub(super) fn new(x: &AxisQuery, y: &AxisQuery, z: &AxisQuery) -> Self {
        let ([x0, x1, ..], [y0, y1, ..], [z0, z1, ..]) = (x.offset, y.offset, z.offset);
        let ([u0, u1, ..], [v0, v1, ..], [w0, w1, ..]) = (x.weight, y.weight, z.weight);
        // The same sums and products, in the same order, as `Window::of`.
        let at = |a: u32, b: u32, c: u32| a.wrapping_add(b).wrapping_add(c);
        // Written out, not `[..].map(..)` (an out-of-line loop at opt-level "s").
        let slerp = [
            SlerpWeight::new(x.t),
            SlerpWeight::new(y.t),
            SlerpWeight::new(z.t),
        ];
        Self {
            index: [
                at(x0, y0, z0),
                at(x1, y0, z0),
                at(x0, y1, z0),
                at(x1, y1, z0),
                at(x0, y0, z1),
                at(x1, y0, z1),
                at(x0, y1, z1),
                at(x1, y1, z1),
            ],
            weight: [
                u0 * v0 * w0,
                u1 * v0 * w0,
                u0 * v1 * w0,
                u1 * v1 * w0,
                u0 * v0 * w1,
                u1 * v0 * w1,
                u0 * v1 * w1,
                u1 * v1 * w1,
            ],
            blends: slerp.iter().any(SlerpWeight::is_blend),
            slerp,
        }
    }

    /// Every segment: in blocks level by level with [`F4`] lanes if
    /// `wide`, else one at a time.
    #[inline(always)]
    pub(super) fn pose<S: Samples>(
        &self,
        samples: &S,
        (positions, rotations): (&mut [Vec3], &mut [Quat]),
        wide: bool,
    ) -> Result<(), GridError> {
        if wide {
            self.pose_wide(samples, positions, rotations)
        } else {
            self.pose_each(samples, positions, rotations)
        }
    }

    /// Every segment, one at a time (the Cortex-M path). Not inlined: the
    /// loop gets the registers to itself, whatever the caller keeps live.
    #[inline(never)]
    fn pose_each<S: Samples>(
        &self,
        samples: &S,
        positions: &mut [Vec3],
        rotations: &mut [Quat],
    ) -> Result<(), GridError> {
        let all = positions.iter_mut().zip(rotations.iter_mut());
        let blends = self.slerp.iter().all(SlerpWeight::is_blend);
        if S::DECODES {
            // The whole window first (one copy of the decoder), then the tree.
            for (seg, (p, r)) in all.enumerate() {
                let (pos, q) = self.fetch(samples, seg)?;
                let [x, y, z, w] = if blends {
                    self.tree_blend(q)
                } else {
                    self.tree(q)
                };
                (*p, *r) = (pos, Quat::from_xyzw(x, y, z, w));
            }
            return Ok(());
        }
        let rows = self.index.map(|i| samples.row(i as usize));
        if blends && rows.iter().all(Option::is_some) {
            // In memory: the window's rows once, then one check per read.
            let rows = rows.map(|r| r.unwrap_or((&[], &[])));
            for (seg, (p, r)) in all.enumerate() {
                (*p, *r) = self.segment_blend_by(|j| {
                    let (ps, qs) = rows.get(j)?;
                    Some((*ps.get(seg)?, *qs.get(seg)?))
                })?;
            }
        } else if blends {
            for (seg, (p, r)) in all.enumerate() {
                (*p, *r) = self.segment_blend_by(|j| {
                    let &index = self.index.get(j)?;
                    samples.sample(index as usize, seg)
                })?;
            }
        } else {
            for (seg, (p, r)) in all.enumerate() {
                (*p, *r) = self.segment(samples, seg)?;
            }
        }
        Ok(())
    }

    /// [`Trilinear::tree`] when every level blends (a query inside a
    /// cell, the usual case): the same operations without the endpoint
    /// checks.
    #[inline(always)]
    fn tree_blend(&self, q: [[f32; 4]; 8]) -> [f32; 4] {
        let [q0, q1, q2, q3, q4, q5, q6, q7] = q;
        let [x, y, z] = &self.slerp;
        let ab = y.blend(x.blend(q0, q1), x.blend(q2, q3));
        let cd = y.blend(x.blend(q4, q5), x.blend(q6, q7));
        math::renormalize_lanes(z.blend(ab, cd))
    }

    /// One segment when every level blends, each pair blended as soon as
    /// it is read (window sample `j` by `read(j)`): the operations of
    /// [`Trilinear::tree_blend`], in another order.
    #[inline(always)]
    fn segment_blend_by(
        &self,
        read: impl Fn(usize) -> Option<(Vec3, Quat)>,
    ) -> Result<(Vec3, Quat), GridError> {
        let [x, y, z] = &self.slerp;
        let [w0, w1, w2, w3, w4, w5, w6, w7] = self.weight;
        let get = |j: usize| {
            let (p, q) = read(j).ok_or(GridError::MissingSample)?;
            Ok::<_, GridError>((p, [q.x, q.y, q.z, q.w]))
        };
        let ((p0, q0), (p1, q1)) = (get(0)?, get(1)?);
        let mut p = p0 * w0 + p1 * w1;
        let a = x.blend(q0, q1);
        let ((p2, q2), (p3, q3)) = (get(2)?, get(3)?);
        p = p + p2 * w2 + p3 * w3;
        let ab = y.blend(a, x.blend(q2, q3));
        let ((p4, q4), (p5, q5)) = (get(4)?, get(5)?);
        p = p + p4 * w4 + p5 * w5;
        let c = x.blend(q4, q5);
        let ((p6, q6), (p7, q7)) = (get(6)?, get(7)?);
        p = p + p6 * w6 + p7 * w7;
        let cd = y.blend(c, x.blend(q6, q7));
        let [rx, ry, rz, rw] = math::renormalize_lanes(z.blend(ab, cd));
        Ok((p, Quat::from_xyzw(rx, ry, rz, rw)))
    }

    /// The host path: blocks of `MAX_WINDOW / 8` segments, the same
    /// operations as [`Trilinear::segment`] level by level on four segments
    /// at a time.
    #[inline(never)]
    fn pose_wide<S: Samples>(
        &self,
        samples: &S,
        positions: &mut [Vec3],
        rotations: &mut [Quat],
    ) -> Result<(), GridError> {
        const BLOCK: usize = MAX_WINDOW / 8;
        let mut buf = Soa::new();
        let weights = self.slerp.each_ref().map(SlerpWeight::lanes::<F4>);
        let blocks = positions.chunks_mut(BLOCK).zip(rotations.chunks_mut(BLOCK));
        for (k, (p, r)) in blocks.enumerate() {
            let count = p.len();
            let window = (self.index.as_slice(), self.weight.as_slice());
            fetch_block(samples, window, (k * BLOCK, BLOCK), p, &mut buf)?;
            for lane in [0, 4] {
                if lane < count {
                    self.tree_lanes::<BLOCK>(&weights, &mut buf, lane);
                }
            }
            buf.store(r);
        }
        Ok(())
    }

    /// The tree on slots `lane..lane + 4` of a scratch laid out
    /// `[window][B]`, level by level in place; the results end up in slots
    /// `lane..lane + 4`.
    #[inline(always)]
    fn tree_lanes<const B: usize>(
        &self,
        weights: &[LaneWeight<F4>; 3],
        buf: &mut Soa,
        lane: usize,
    ) {
        let [x, y, z] = weights;
        blend_pairs::<B>(buf, x, 4, lane);
        blend_pairs::<B>(buf, y, 2, lane);
        blend_pairs::<B>(buf, z, 1, lane);
        if self.blends
            && let Some(r) = buf.get4(lane)
        {
            buf.set4(lane, math::renormalize_lanes(r));
        }
    }

    /// One segment.
    #[inline]
    pub(super) fn segment<S: Samples>(
        &self,
        samples: &S,
        segment: usize,
    ) -> Result<(Vec3, Quat), GridError> {
        let (p, q) = self.fetch(samples, segment)?;
        let [x, y, z, w] = self.tree(q);
        Ok((p, Quat::from_xyzw(x, y, z, w)))
    }

    /// The window of one segment: the weighted sum of its positions (in
    /// window order) and its rotations as `[x, y, z, w]`.
    #[inline(always)]
    fn fetch<S: Samples>(
        &self,
        samples: &S,
        segment: usize,
    ) -> Result<(Vec3, [[f32; 4]; 8]), GridError> {
        let mut q = [[0.0; 4]; 8];
        // From −0, the additive identity of every float (−0 + +0 is +0,
        // −0 + −0 is −0): the sum is `s₀·w₀ + s₁·w₁ + …` bit for bit,
        // without a special first term.
        let mut p = Vec3::splat(-0.0);
        // A counted loop rather than zipped iterators: at opt-level "s" the
        // loop is not unrolled, and the iterators cost more than the reads.
        let mut j = 0;
        while let (Some(&index), Some(&w), Some(slot)) =
            (self.index.get(j), self.weight.get(j), q.get_mut(j))
        {
            let (sp, sq) = samples
                .sample(index as usize, segment)
                .ok_or(GridError::MissingSample)?;
            p += sp * w;
            *slot = [sq.x, sq.y, sq.z, sq.w];
            j += 1;
        }
        Ok((p, q))
    }

    /// The rotation tree on any lane type.
    #[inline(always)]
    fn tree<T: Lane>(&self, q: [[T; 4]; 8]) -> [T; 4] {
        let [q0, q1, q2, q3, q4, q5, q6, q7] = q;
        let [x, y, z] = &self.slerp;
        let ab = y.blend_lanes(x.blend_lanes(q0, q1), x.blend_lanes(q2, q3));
        let cd = y.blend_lanes(x.blend_lanes(q4, q5), x.blend_lanes(q6, q7));
        let r = z.blend_lanes(ab, cd);
        if self.blends {
            math::renormalize_lanes(r)
        } else {
            r
        }
    }
}
