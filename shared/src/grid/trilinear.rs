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
            let rows = self.index.map(|i| samples.row(i as usize));
            if self.slerp.iter().all(SlerpWeight::is_blend) && rows.iter().all(Option::is_some) {
                let rows = rows.map(|r| r.unwrap_or((&[], &[])));
                return self.pose_rows_wide(&rows, positions, rotations);
            }
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

    /// The host path from in-memory rows when every level blends (a query
    /// inside a cell, the usual case): four segments at a time as [`F4`]
    /// lanes, each window sample's four rotations read straight from its row
    /// and transposed in registers, the tree in the order of
    /// [`Trilinear::segment_blend_by`], the positions as twelve floats per
    /// window sample (in window order, as [`Trilinear::fetch`]); the last
    /// segments (fewer than four) one at a time. The same operations per
    /// segment as every other path, so the same bits.
    #[inline(never)]
    fn pose_rows_wide(
        &self,
        rows: &[(&[Vec3], &[Quat]); 8],
        positions: &mut [Vec3],
        rotations: &mut [Quat],
    ) -> Result<(), GridError> {
        let [x, y, z] = self.slerp.each_ref().map(SlerpWeight::lanes::<F4>);
        let weights = self.weight.map(F4::splat);
        let quads = positions
            .chunks_exact_mut(4)
            .zip(rotations.chunks_exact_mut(4))
            .enumerate();
        for (k, (p, r)) in quads {
            let at = k * 4;
            let read = |j: usize| {
                let (ps, qs) = rows.get(j)?;
                let ps = ps.get(at..)?.first_chunk::<4>()?;
                let qs = qs.get(at..)?.first_chunk::<4>()?;
                Some((flatten(ps), transpose4(qs)))
            };
            let get = |j: usize| read(j).ok_or(GridError::MissingSample);
            let w = |j: usize| weights.get(j).copied().unwrap_or(F4::splat(0.0));
            let weigh = |s: [F4; 3], j: usize| s.map(|v| v * w(j));
            let add = |a: [F4; 3], b: [F4; 3]| [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
            let ((p0, q0), (p1, q1)) = (get(0)?, get(1)?);
            let mut sum = add(weigh(p0, 0), weigh(p1, 1));
            let a = x.blend_lanes(q0, q1);
            let ((p2, q2), (p3, q3)) = (get(2)?, get(3)?);
            sum = add(add(sum, weigh(p2, 2)), weigh(p3, 3));
            let ab = y.blend_lanes(a, x.blend_lanes(q2, q3));
            let ((p4, q4), (p5, q5)) = (get(4)?, get(5)?);
            sum = add(add(sum, weigh(p4, 4)), weigh(p5, 5));
            let c = x.blend_lanes(q4, q5);
            let ((p6, q6), (p7, q7)) = (get(6)?, get(7)?);
            sum = add(add(sum, weigh(p6, 6)), weigh(p7, 7));
            let cd = y.blend_lanes(c, x.blend_lanes(q6, q7));
            let q = math::renormalize_lanes(z.blend_lanes(ab, cd));
            if let (Some(p), Some(r)) = (p.first_chunk_mut::<4>(), r.first_chunk_mut::<4>()) {
                *p = unflatten(sum);
                *r = untranspose4(q);
            }
        }
        let done = positions.len() / 4 * 4;
        let rest = positions.iter_mut().zip(rotations.iter_mut()).enumerate();
        for (seg, (p, r)) in rest.skip(done) {
            (*p, *r) = self.segment_blend_by(|j| {
                let (ps, qs) = rows.get(j)?;
                Some((*ps.get(seg)?, *qs.get(seg)?))
            })?;
        }
        Ok(())
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

/// Four positions as twelve floats in three lanes.
#[inline(always)]
fn flatten(v: &[Vec3; 4]) -> [F4; 3] {
    let [a, b, c, d] = *v;
    [
        F4([a.x, a.y, a.z, b.x]),
        F4([b.y, b.z, c.x, c.y]),
        F4([c.z, d.x, d.y, d.z]),
    ]
}

/// [`flatten`] undone.
#[inline(always)]
fn unflatten([x0, x1, x2]: [F4; 3]) -> [Vec3; 4] {
    let ([a0, a1, a2, b0], [b1, b2, c0, c1], [c2, d0, d1, d2]) = (x0.0, x1.0, x2.0);
    [
        Vec3::new(a0, a1, a2),
        Vec3::new(b0, b1, b2),
        Vec3::new(c0, c1, c2),
        Vec3::new(d0, d1, d2),
    ]
}

/// Four rotations as `[x, y, z, w]` lanes.
#[inline(always)]
fn transpose4(q: &[Quat; 4]) -> [F4; 4] {
    let [a, b, c, d] = *q;
    [
        F4([a.x, b.x, c.x, d.x]),
        F4([a.y, b.y, c.y, d.y]),
        F4([a.z, b.z, c.z, d.z]),
        F4([a.w, b.w, c.w, d.w]),
    ]
}

/// [`transpose4`] undone.
#[inline(always)]
fn untranspose4([x, y, z, w]: [F4; 4]) -> [Quat; 4] {
    let quat = |i: usize| {
        let at = |v: &F4| v.0.get(i).copied().unwrap_or(0.0);
        Quat::from_xyzw(at(&x), at(&y), at(&z), at(&w))
    };
    [quat(0), quat(1), quat(2), quat(3)]
}
