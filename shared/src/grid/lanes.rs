//! The wide paths: rotation scratch laid out one array per quaternion
//! component ([`Soa`]), so that four segments' slerps run as [`F4`] lanes on
//! targets with SIMD (the host). On the Cortex-M ([`WIDE`] false) the grid
//! takes the scalar paths; every path performs the same operations per
//! segment in the same order, so all give the same bits.

use glam::{Quat, Vec3};

use super::general::Cubic;
use super::{GridError, MAX_WINDOW, Samples};
use crate::math::{F4, Lane, LaneWeight, SlerpWeight};

/// Reads the window of segments `first..first + positions.len()`:
/// positions as the weighted sum (in window order), rotations into slot
/// `j·block + b` of the scratch. Window-major, so each window sample's
/// segments are read consecutively.
#[inline]
pub(super) fn fetch_block<S: Samples>(
    samples: &S,
    (window, weights): (&[u32], &[f32]),
    (first, block): (usize, usize),
    positions: &mut [Vec3],
    buf: &mut Soa,
) -> Result<(), GridError> {
    let count = positions.len();
    for (j, (&index, &w)) in window.iter().zip(weights).enumerate() {
        let range = j * block..j * block + count;
        let [cx, cy, cz, cw] = &mut buf.0;
        let (Some(sx), Some(sy), Some(sz), Some(sw)) = (
            cx.get_mut(range.clone()),
            cy.get_mut(range.clone()),
            cz.get_mut(range.clone()),
            cw.get_mut(range),
        ) else {
            return Err(GridError::MissingSample);
        };
        if let Some((ps, qs)) = samples.row(index as usize) {
            let run = first..first + count;
            let (Some(ps), Some(qs)) = (ps.get(run.clone()), qs.get(run)) else {
                return Err(GridError::MissingSample);
            };
            weigh(positions, ps, w, j == 0);
            transpose(qs, [sx, sy, sz, sw]);
            continue;
        }
        let rows = sx.iter_mut().zip(sy).zip(sz).zip(sw);
        for (b, ((((x, y), z), qw), p)) in rows.zip(positions.iter_mut()).enumerate() {
            let (sp, sq) = samples
                .sample(index as usize, first + b)
                .ok_or(GridError::MissingSample)?;
            *p = if j == 0 { sp * w } else { *p + sp * w };
            (*x, *y, *z, *qw) = (sq.x, sq.y, sq.z, sq.w);
        }
    }
    Ok(())
}

/// `p = s·w` (`first`) or `p + s·w` for every pair: the same per-coordinate
/// operations on four positions (12 floats) at a time where the target has
/// SIMD.
#[inline]
pub(super) fn weigh(positions: &mut [Vec3], samples: &[Vec3], w: f32, first: bool) {
    let flat = |v: &[Vec3; 4]| {
        let [a, b, c, d] = *v;
        [
            F4([a.x, a.y, a.z, b.x]),
            F4([b.y, b.z, c.x, c.y]),
            F4([c.z, d.x, d.y, d.z]),
        ]
    };
    let wide = if WIDE { positions.len() / 4 * 4 } else { 0 };
    let (head, tail) = positions.split_at_mut(wide);
    let quads = head.chunks_exact_mut(4).zip(samples.chunks_exact(4));
    for (p, s) in quads {
        if let (Some(p), Some(s)) = (p.first_chunk_mut::<4>(), s.first_chunk::<4>()) {
            let [s0, s1, s2] = flat(s).map(|v| v * F4::splat(w));
            let [x0, x1, x2] = if first {
                [s0, s1, s2]
            } else {
                let [p0, p1, p2] = flat(p);
                [p0 + s0, p1 + s1, p2 + s2]
            };
            let ([a0, a1, a2, b0], [b1, b2, c0, c1], [c2, d0, d1, d2]) = (x0.0, x1.0, x2.0);
            *p = [
                Vec3::new(a0, a1, a2),
                Vec3::new(b0, b1, b2),
                Vec3::new(c0, c1, c2),
                Vec3::new(d0, d1, d2),
            ];
        }
    }
    for (p, &s) in tail.iter_mut().zip(samples.iter().skip(wide)) {
        *p = if first { s * w } else { *p + s * w };
    }
}

/// `g[i] = blend(g[2i], g[2i+1])` for `i < len` on slots `lane..lane + 4` of
/// each window group `g` (stride `B`).
#[inline(always)]
pub(super) fn blend_pairs<const B: usize>(
    buf: &mut Soa,
    w: &LaneWeight<F4>,
    len: usize,
    lane: usize,
) {
    for i in 0..len {
        let (a, b) = (buf.get4(2 * i * B + lane), buf.get4((2 * i + 1) * B + lane));
        if let (Some(a), Some(b)) = (a, b) {
            buf.set4(i * B + lane, w.blend_lanes(a, b));
        }
    }
}

/// Rotations into per-component rows (`[x, y, z, w]`).
#[inline]
pub(super) fn transpose(rotations: &[Quat], [rx, ry, rz, rw]: [&mut [f32]; 4]) {
    let rows = rx.iter_mut().zip(ry).zip(rz).zip(rw);
    for ((((x, y), z), w), q) in rows.zip(rotations) {
        (*x, *y, *z, *w) = (q.x, q.y, q.z, q.w);
    }
}

/// Rotation scratch, one array per quaternion component (`[x, y, z, w]`).
pub(super) struct Soa([[f32; MAX_WINDOW]; 4]);

impl Soa {
    pub(super) fn new() -> Self {
        Soa([
            [0.0; MAX_WINDOW],
            [0.0; MAX_WINDOW],
            [0.0; MAX_WINDOW],
            [1.0; MAX_WINDOW],
        ])
    }

    #[inline]
    pub(super) fn get(&self, i: usize) -> Quat {
        let [x, y, z, w] = &self.0;
        let at = |c: &[f32; MAX_WINDOW]| c.get(i).copied().unwrap_or(0.0);
        Quat::from_xyzw(at(x), at(y), at(z), at(w))
    }

    #[inline]
    pub(super) fn set(&mut self, i: usize, q: Quat) {
        for (c, v) in self.0.iter_mut().zip([q.x, q.y, q.z, q.w]) {
            if let Some(slot) = c.get_mut(i) {
                *slot = v;
            }
        }
    }

    /// Slots `0..out.len()` as quaternions.
    #[inline]
    pub(super) fn store(&self, out: &mut [Quat]) {
        let [cx, cy, cz, cw] = &self.0;
        for ((((r, &x), &y), &z), &w) in out.iter_mut().zip(cx).zip(cy).zip(cz).zip(cw) {
            *r = Quat::from_xyzw(x, y, z, w);
        }
    }

    /// Four consecutive slots starting at `i`, as lanes.
    #[inline]
    pub(super) fn get4(&self, i: usize) -> Option<[F4; 4]> {
        let [x, y, z, w] = &self.0;
        let lanes = |c: &[f32; MAX_WINDOW]| {
            c.get(i..)
                .and_then(|s| s.first_chunk::<4>())
                .map(|a| F4(*a))
        };
        Some([lanes(x)?, lanes(y)?, lanes(z)?, lanes(w)?])
    }

    #[inline]
    pub(super) fn set4(&mut self, i: usize, v: [F4; 4]) {
        for (c, lane) in self.0.iter_mut().zip(v) {
            if let Some(dst) = c.get_mut(i..).and_then(|s| s.first_chunk_mut::<4>()) {
                *dst = lane.0;
            }
        }
    }
}

/// Four lanes of slerp per step where the target has SIMD; on the Cortex-M
/// (no SIMD FPU) the scalar path avoids the register pressure of four lanes.
pub(super) const WIDE: bool = !cfg!(target_arch = "arm");

/// Slerps adjacent pairs in place: `g[i] = slerp(g[2i], g[2i+1])` for each
/// window group `g` (stride `block`) and each of the `count` segments.
#[inline]
pub(super) fn reduce_linear(
    buf: &mut Soa,
    len: usize,
    block: usize,
    count: usize,
    w: &SlerpWeight,
) -> usize {
    let half = len / 2;
    for i in 0..half {
        let (ia, ib, io) = (2 * i * block, (2 * i + 1) * block, i * block);
        let mut b = 0;
        // Whole lanes of four; the last group may run past `count` into
        // unused slots of the block (their results are never read).
        let wide_end = if WIDE && block.is_multiple_of(4) {
            count.div_ceil(4) * 4
        } else {
            0
        };
        while b < wide_end {
            if let (Some(qa), Some(qb)) = (buf.get4(ia + b), buf.get4(ib + b)) {
                buf.set4(io + b, w.apply_lanes(qa, qb));
            }
            b += 4;
        }
        while b < count {
            let q = w.apply(buf.get(ia + b), buf.get(ib + b));
            buf.set(io + b, q);
            b += 1;
        }
    }
    half
}

/// Spherical Catmull-Rom over groups of four, in place (layout as above).
#[inline]
pub(super) fn reduce_cubic(
    buf: &mut Soa,
    len: usize,
    block: usize,
    count: usize,
    c: &Cubic,
) -> usize {
    let quarter = len / 4;
    let wide_end = if WIDE && block.is_multiple_of(4) {
        count.div_ceil(4) * 4
    } else {
        0
    };
    for i in 0..quarter {
        let slot = |k: usize, b: usize| (4 * i + k) * block + b;
        let mut b = 0;
        while b < wide_end {
            if let (Some(q0), Some(q1), Some(q2), Some(q3)) = (
                buf.get4(slot(0, b)),
                buf.get4(slot(1, b)),
                buf.get4(slot(2, b)),
                buf.get4(slot(3, b)),
            ) {
                buf.set4(i * block + b, c.rotation([q0, q1, q2, q3]));
            }
            b += 4;
        }
        while b < count {
            let at = |k: usize| {
                let q = buf.get(slot(k, b));
                [q.x, q.y, q.z, q.w]
            };
            let [x, y, z, w] = c.rotation([at(0), at(1), at(2), at(3)]);
            buf.set(i * block + b, Quat::from_xyzw(x, y, z, w));
            b += 1;
        }
    }
    quarter
}
