//! Shared support for Marionette's end-to-end tests: slow, obviously correct
//! `f64` reference implementations live here, never in the code under test.

/// Slow `f64` references for pose synthesis (grid, clip, pose tests).
/// Quaternions are `[x, y, z, w]` arrays, vectors `[x, y, z]`.
pub mod synth_ref {
    /// A quaternion in `f64`, `[x, y, z, w]`.
    pub type Q = [f64; 4];
    /// A vector in `f64`.
    pub type V = [f64; 3];

    /// Four-component dot product.
    pub fn dot(a: Q, b: Q) -> f64 {
        a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]
    }

    /// Unit quaternion along `a`.
    pub fn normalize(a: Q) -> Q {
        let n = dot(a, a).sqrt();
        a.map(|v| v / n)
    }

    /// Textbook slerp along the shortest arc:
    /// `sin((1−t)θ)/sin θ · a + sin(tθ)/sin θ · b`, any real `t`.
    pub fn slerp(a: Q, b: Q, t: f64) -> Q {
        let a = normalize(a);
        let mut b = normalize(b);
        if dot(a, b) < 0.0 {
            b = b.map(|v| -v);
        }
        let th = dot(a, b).clamp(-1.0, 1.0).acos();
        if th < 1e-12 {
            return a;
        }
        let s = th.sin();
        let (w0, w1) = (((1.0 - t) * th).sin() / s, (t * th).sin() / s);
        [0, 1, 2, 3].map(|i| w0 * a[i] + w1 * b[i])
    }

    /// Rotation angle between two rotations, `2·acos(|a·b|)` (sign-free).
    pub fn angle_between(a: Q, b: Q) -> f64 {
        2.0 * dot(normalize(a), normalize(b)).abs().min(1.0).acos()
    }

    /// Hamilton product `a·b`.
    pub fn mul(a: Q, b: Q) -> Q {
        let [ax, ay, az, aw] = a;
        let [bx, by, bz, bw] = b;
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    }

    /// Conjugate (inverse of a unit quaternion).
    pub fn conj(a: Q) -> Q {
        [-a[0], -a[1], -a[2], a[3]]
    }

    /// Rotates `v` by unit `q` as `q·(v,0)·q*`.
    pub fn rotate(q: Q, v: V) -> V {
        let r = mul(mul(q, [v[0], v[1], v[2], 0.0]), conj(q));
        [r[0], r[1], r[2]]
    }

    /// Rotation by `angle` about unit `axis`.
    pub fn axis_angle(axis: V, angle: f64) -> Q {
        let n = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
        let (s, c) = (0.5 * angle).sin_cos();
        [axis[0] / n * s, axis[1] / n * s, axis[2] / n * s, c]
    }

    /// `a + (b − a)·t` per component.
    pub fn lerp3(a: V, b: V, t: f64) -> V {
        [0, 1, 2].map(|i| a[i] + (b[i] - a[i]) * t)
    }

    /// Uniform Catmull-Rom between `p1` and `p2` (Hermite form with central
    /// difference tangents `(p2 − p0)/2`, `(p3 − p1)/2`).
    pub fn catmull_rom(p0: f64, p1: f64, p2: f64, p3: f64, s: f64) -> f64 {
        let (m1, m2) = (0.5 * (p2 - p0), 0.5 * (p3 - p1));
        let (s2, s3) = (s * s, s * s * s);
        (2.0 * s3 - 3.0 * s2 + 1.0) * p1
            + (s3 - 2.0 * s2 + s) * m1
            + (-2.0 * s3 + 3.0 * s2) * p2
            + (s3 - s2) * m2
    }

    /// Spherical Catmull-Rom: the Barry–Goldman pyramid with exact slerp
    /// (extrapolating slerps with `t` outside `[0, 1]` directly).
    pub fn spherical_catmull_rom(p: [Q; 4], s: f64) -> Q {
        let a1 = slerp(p[0], p[1], s + 1.0);
        let a2 = slerp(p[1], p[2], s);
        let a3 = slerp(p[2], p[3], s - 1.0);
        let b1 = slerp(a1, a2, (s + 1.0) / 2.0);
        let b2 = slerp(a2, a3, s / 2.0);
        slerp(b1, b2, s)
    }

    /// Wiley & Hahn's nested interpolation tree over the `2^p` corners of
    /// one cell (axis 0 fastest in `corners`), written out level by level:
    /// lerp positions and slerp rotations (exact, shortest arc) along axis
    /// 0 with `t[0]`, then the results along axis 1, and so on.
    pub fn nested_tree(corners: &[(V, Q)], t: &[f64]) -> (V, Q) {
        let mut level: Vec<(V, Q)> = corners.to_vec();
        for &u in t {
            level = level
                .chunks(2)
                .map(|pair| match pair {
                    [(pa, qa), (pb, qb)] => (lerp3(*pa, *pb, u), slerp(*qa, *qb, u)),
                    [one] => *one,
                    _ => unreachable!("chunks of 2"),
                })
                .collect();
        }
        level[0]
    }

    /// Deterministic xorshift64* generator for test inputs (shared by the
    /// tests that need random inputs).
    pub struct Rng(u64);

    impl Rng {
        /// Seeded generator.
        pub fn new(seed: u64) -> Self {
            Self(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1)
        }
        /// Next raw value.
        pub fn next_u64(&mut self) -> u64 {
            let mut x = self.0;
            x ^= x >> 12;
            x ^= x << 25;
            x ^= x >> 27;
            self.0 = x;
            x.wrapping_mul(0x2545_f491_4f6c_dd1d)
        }
        /// Uniform in `0..n` (`0` when `n` is 0).
        pub fn below(&mut self, n: usize) -> usize {
            (self.next_u64() % n.max(1) as u64) as usize
        }
        /// A uniformly distributed byte.
        pub fn byte(&mut self) -> u8 {
            (self.next_u64() >> 56) as u8
        }
        /// Uniform in `[0, 1)`.
        pub fn unit(&mut self) -> f64 {
            self.range(0.0, 1.0)
        }
        /// Uniform in `[lo, hi)`.
        pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
            lo + (hi - lo) * ((self.next_u64() >> 11) as f64 / (1u64 << 53) as f64)
        }
        /// Uniformly distributed unit quaternion.
        pub fn quat(&mut self) -> Q {
            loop {
                let q = [0; 4].map(|_| self.range(-1.0, 1.0));
                let n = dot(q, q);
                if n > 0.01 && n <= 1.0 {
                    return normalize(q);
                }
            }
        }
    }
}

/// Fuzz target bodies (shared by `tests/fuzz/` and `tests/fuzz_replay.rs`).
pub mod fuzz_targets;
pub mod puppet;
pub mod servo_bus;
