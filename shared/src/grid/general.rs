//! The general interpolation tree: any mix of linear and Catmull-Rom axes,
//! reduced axis by axis with normalized slerps (and the spherical
//! Catmull-Rom pyramid, see the module doc of [`crate::grid`]).

use glam::{Quat, Vec3};

use super::lanes::{Soa, fetch_block, reduce_cubic, reduce_linear};
use super::query::Window;
use super::{GridError, MAX_AXES, MAX_WINDOW, Samples};
use crate::math::{self, Lane, SlerpWeight};

/// Per-axis coefficients of a query.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum AxisWeights {
    /// Slerp weight `t` between the two window samples.
    Linear(SlerpWeight),
    /// Catmull-Rom pyramid (see the module doc).
    Cubic(Cubic),
}

/// Spherical Catmull-Rom coefficients for one parameter `s`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Cubic {
    s: SlerpWeight,
    one_minus_s: SlerpWeight,
    half_s_plus: SlerpWeight,
    half_s: SlerpWeight,
    /// `P−1` is the linear phantom (`A1 = A2`).
    lo_phantom: bool,
    /// `P2` is the linear phantom (`A3 = A2`).
    hi_phantom: bool,
}

impl Cubic {
    pub(super) fn new(s: f32, lo_phantom: bool, hi_phantom: bool) -> Self {
        Self {
            s: SlerpWeight::new(s),
            one_minus_s: SlerpWeight::new(1.0 - s),
            half_s_plus: SlerpWeight::new(0.5 * (s + 1.0)),
            half_s: SlerpWeight::new(0.5 * s),
            lo_phantom,
            hi_phantom,
        }
    }

    /// Spherical Catmull-Rom of four rotations (exact endpoints), on
    /// `[x, y, z, w]` components of any lane type (same bits per lane).
    #[inline]
    pub(super) fn rotation<T: Lane>(&self, p: [[T; 4]; 4]) -> [T; 4] {
        let [p0, p1, p2, p3] = p;
        let s = self.s.t();
        if s <= 0.0 {
            return p1;
        }
        if s >= 1.0 {
            return p2;
        }
        let a2 = self.s.apply_lanes(p1, p2);
        let a1 = if self.lo_phantom {
            a2
        } else {
            self.s.apply_lanes(p1, math::reflect_lanes(p0, p1))
        };
        let a3 = if self.hi_phantom {
            a2
        } else {
            self.one_minus_s
                .apply_lanes(p2, math::reflect_lanes(p3, p2))
        };
        let b1 = self.half_s_plus.apply_lanes(a1, a2);
        let b2 = self.half_s.apply_lanes(a2, a3);
        self.s.apply_lanes(b1, b2)
    }
}

/// Catmull-Rom position weights for `P−1, P0, P1, P2` at `s`, phantoms
/// folded in.
pub(super) fn cubic_position_weights(s: f32, lo_phantom: bool, hi_phantom: bool) -> [f32; 4] {
    let (s2, s3) = (s * s, s * s * s);
    let mut w = [
        0.5 * (-s3 + 2.0 * s2 - s),
        0.5 * (3.0 * s3 - 5.0 * s2 + 2.0),
        0.5 * (-3.0 * s3 + 4.0 * s2 + s),
        0.5 * (s3 - s2),
    ];
    if lo_phantom {
        // P−1 = 2·P0 − P1
        w = [0.0, w[1] + 2.0 * w[0], w[2] - w[0], w[3]];
    }
    if hi_phantom {
        // P2 = 2·P1 − P0
        w = [w[0], w[1] - w[3], w[2] + 2.0 * w[3], 0.0];
    }
    w
}

/// The general tree of a query: its window and every axis' rotation
/// coefficients, reduced axis by axis with normalized slerps.
pub(super) struct Plan {
    pub(super) window: Window,
    pub(super) axes: [AxisWeights; MAX_AXES],
    pub(super) axis_count: usize,
}

impl Plan {
    fn window(&self) -> &[u32] {
        self.window.indices()
    }

    fn weights(&self) -> &[f32] {
        self.window.weights()
    }

    fn axes(&self) -> &[AxisWeights] {
        self.axes.get(..self.axis_count).unwrap_or(&[])
    }

    /// Every segment in blocks, with [`F4`] lanes where the block allows.
    pub(super) fn pose<S: Samples>(
        &self,
        samples: &S,
        positions: &mut [Vec3],
        rotations: &mut [Quat],
    ) -> Result<(), GridError> {
        let n = positions.len();
        let block = MAX_WINDOW.checked_div(self.window.len).unwrap_or(1).max(1);
        let mut buf = Soa::new();
        let mut first = 0;
        while first < n {
            let count = block.min(n - first);
            let p = positions.get_mut(first..first + count).unwrap_or(&mut []);
            fetch_block(
                samples,
                (self.window(), self.weights()),
                (first, block),
                p,
                &mut buf,
            )?;
            self.reduce(&mut buf, block, count);
            let r = rotations.get_mut(first..first + count).unwrap_or(&mut []);
            buf.store(r);
            first += count;
        }
        Ok(())
    }

    /// Segments `first..` through the scalar path with a window-sized buffer.
    pub(super) fn scalar_any<S: Samples>(
        &self,
        samples: &S,
        first: usize,
        out: (&mut [Vec3], &mut [Quat]),
    ) -> Result<(), GridError> {
        // Two buffer sizes only: every instance is a copy of the loop (and of
        // an inlined sample decoder), which costs flash.
        match self.window.len {
            0..=16 => self.scalar::<S, 16>(samples, first, out),
            _ => self.scalar::<S, MAX_WINDOW>(samples, first, out),
        }
    }

    /// Segments `first..` into `out` one at a time with a `K`-entry window
    /// buffer (`K ≥ len`), reducing in place; the same operations per segment,
    /// in the same order, as the blocked path.
    fn scalar<S: Samples, const K: usize>(
        &self,
        samples: &S,
        first: usize,
        out: (&mut [Vec3], &mut [Quat]),
    ) -> Result<(), GridError> {
        let mut buf = [Quat::IDENTITY; K];
        for (seg, (p, r)) in out.0.iter_mut().zip(out.1.iter_mut()).enumerate() {
            let window = buf.iter_mut().zip(self.window()).zip(self.weights());
            for (j, ((slot, &index), &w)) in window.enumerate() {
                let (sp, sq) = samples
                    .sample(index as usize, first + seg)
                    .ok_or(GridError::MissingSample)?;
                *p = if j == 0 { sp * w } else { *p + sp * w };
                *slot = sq;
            }
            let mut len = self.window.len;
            for axis in self.axes() {
                len = match axis {
                    AxisWeights::Linear(w) => pairs_in_place(&mut buf, len, w),
                    AxisWeights::Cubic(c) => quads_in_place(&mut buf, len, c),
                };
            }
            *r = buf.first().copied().unwrap_or(Quat::IDENTITY);
        }
        Ok(())
    }

    /// Runs the rotation tree on `count` segments laid out `[window][block]`;
    /// the results end up in slots `0..count`.
    #[inline]
    fn reduce(&self, buf: &mut Soa, block: usize, count: usize) {
        let mut len = self.window.len;
        for axis in self.axes() {
            len = match axis {
                AxisWeights::Linear(w) => reduce_linear(buf, len, block, count, w),
                AxisWeights::Cubic(c) => reduce_cubic(buf, len, block, count, c),
            };
        }
    }
}

/// `buf[i] = slerp(buf[2i], buf[2i+1])` for `i < len/2`.
#[inline]
fn pairs_in_place<const K: usize>(buf: &mut [Quat; K], len: usize, w: &SlerpWeight) -> usize {
    let half = len / 2;
    for i in 0..half {
        if let (Some(&a), Some(&b)) = (buf.get(2 * i), buf.get(2 * i + 1))
            && let Some(slot) = buf.get_mut(i)
        {
            *slot = w.apply(a, b);
        }
    }
    half
}

/// `buf[i] = spherical Catmull-Rom(buf[4i..4i+4])` for `i < len/4`.
#[inline]
fn quads_in_place<const K: usize>(buf: &mut [Quat; K], len: usize, c: &Cubic) -> usize {
    let quarter = len / 4;
    for i in 0..quarter {
        let at = |k: usize| {
            let q = buf.get(4 * i + k).copied().unwrap_or(Quat::IDENTITY);
            [q.x, q.y, q.z, q.w]
        };
        let [x, y, z, w] = c.rotation([at(0), at(1), at(2), at(3)]);
        if let Some(slot) = buf.get_mut(i) {
            *slot = Quat::from_xyzw(x, y, z, w);
        }
    }
    quarter
}
