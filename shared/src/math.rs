//! The core's own `f32` math, used identically on the host and on the firmware.
//!
//! # Why the core has its own math
//!
//! Host and firmware must produce bit-identical numbers. The `f32` inherent
//! transcendental methods (`x.sin()`, `x.sqrt()`) do not exist in `core`, and on
//! the host they resolve to the platform `libm`, whose results differ between
//! platforms. glam's `Quat::slerp`, `Vec3::length` and friends call `libm` (and
//! are slow on the Cortex-M4F: README's `slerp.glam` row). Everything here is
//! built from IEEE-754 `+ - * /`, integer bit manipulation and comparisons only,
//! evaluated in a fixed order (Rust never contracts `a * b + c` into an FMA), so
//! every function returns the same bits on every target. The exact rounding
//! check in [`sqrt`] is integer arithmetic on the significands.
//!
//! Quaternion dot products are written out component by component
//! ([`quat_dot`]) rather than through `Quat::dot`: with SIMD enabled, glam sums
//! the four products in a different order on x86 than the scalar code does on
//! the M4F, which changes the last bit.
//!
//! # Implementations and measured accuracy
//!
//! Errors are measured against `f64` references (std `f64` methods, in the unit
//! tests below) over a dense sweep of the whole domain plus edge cases; each test
//! asserts the bound quoted here. "ulp" is relative to the `f32` result.
//!
//! | function | implementation | domain | measured max error |
//! |---|---|---|---|
//! | [`abs`] | clear the sign bit | all | exact |
//! | [`rsqrt`] | bit-trick seed (`0x5f37_5a86`) + 3 Newton steps, subnormals pre-scaled by 2^24 | `x > 0` | 1.9e-7 relative (≤ 2 ulp) |
//! | [`sqrt`] | `x · rsqrt(x)` then an exact integer midpoint test picks the correctly rounded neighbour | `x ≥ 0` | correctly rounded (≤ 0.5 ulp), identical to the M4F `VSQRT` |
//! | [`sin`], [`cos`], [`sin_cos`] | Cody–Waite reduction by π/2 with a 3-part constant (8 + 8 + 24 bits; skipped below π/4, where it changes nothing), minimax odd/even polynomials on [−π/4, π/4] (degree 7 / 8, coefficients fitted for this crate) | accurate for `|x| ≤ 1e5` | 8.7e-8 absolute (≈ 1.5 ulp, worst near `r = ±π/4`) |
//! | [`asin`], [`acos`] | minimax `x + x³P(x²)` (degree 13) on `|x| ≤ ½`; `asin x = π/2 − 2·asin √((1−x)/2)` above | `[−1, 1]` (clamped) | asin 1.6e-7, acos 3.1e-7 absolute (≈ 1.3 ulp) |
//! | [`atan`], [`atan2`] | octant reduction, `atan t = π/4 + atan((t−1)/(t+1))` above tan(π/8), minimax degree 13 | all | atan 1.7e-7, atan2 2.9e-7 absolute (≈ 1.2 ulp of π) |
//! | [`slerp`], [`SlerpWeight`] | fitted polynomial slerp weights (below) + one Newton normalization step | unit inputs, `t ∈ [0, 1]` | 6.7e-6 rad rotation angle (fit: 6.5e-6), `|r| − 1` within 1.5e-7 |
//! | [`nlerp`] | normalized linear blend, shortest arc | unit inputs | exact direction of the blend; up to 0.14 rad from slerp |
//! | [`from_axis_angle`], [`rotation_arc`], [`quat_angle`] | built on the above | | see tests |
//!
//! ## Why not micromath
//!
//! micromath 2.1 (`F32Ext`) was measured in the tests here as well
//! (`micromath_is_too_coarse`): its `sqrt` is off by up to 6.1 % (a bit trick
//! without Newton steps), its `sin` by 1.1e-3 and `atan2` by 2.8e-3 rad.
//! 1e-3 rad at a 1 m limb is a 1 mm error at the hand before any interpolation,
//! and a 3 % normalization error compounds through every quaternion product.
//! None of its functions is accurate enough for the pose pipeline, so the core
//! uses none of them; all functions above are this crate's own.
//!
//! # The fast slerp
//!
//! Exact slerp is `r = w0·a + w1·b` with `w1 = W(t, x) = sin(tθ)/sin θ`,
//! `w0 = W(1 − t, x)`, `x = cos θ = |a·b|` (after flipping `b` to the shortest
//! arc, so `x ∈ [0, 1]`). `W` is odd in `t` and analytic in `x` on `[0, 1]`
//! (it is `t` at `x = 1`), so we approximate it directly as
//!
//! ```text
//! W(t, x) ≈ t · F(t², x),   F = Σ_{j ≤ 5, k ≤ 3} c_jk · x^j · t^(2k)
//! ```
//!
//! (24 coefficients, degree 5 in `x`, degree 3 in `t²`). The coefficients were
//! fitted for this crate by weighted least squares over 80×80 Chebyshev nodes
//! of `t, x ∈ [0, 1]`, iteratively reweighted (Lawson) towards the minimax of
//! the weight error; the fit's `f64` error is 7.0e-6 in the weights and
//! 6.5e-6 rad in the rotation angle of the result (degree 4 in `x` gives
//! 3.2e-5 rad, degree 4 with the nlerp-parameter correction form 1.1e-5 rad
//! but needs a full `rsqrt`). Because the weights approximate the *exact*
//! slerp weights, the blend is already unit to within 4e-6, so a single
//! Newton step from 1 (`r · (1.5 − ½|r|²)`) normalizes it to rounding error:
//! no `rsqrt` seed, no `sin`/`acos`.
//!
//! `t` is usually shared by many slerps (one grid query drives every
//! segment), so [`SlerpWeight::new`] folds `t` into two sets of six
//! coefficients in `x` once; each slerp then costs a 4-term dot product, two
//! independent degree-5 polynomials (Estrin's scheme, sharing `x²`, `x⁴`), a 4-component blend, a squared
//! norm and the Newton step: about 55 floating-point operations, no branch
//! besides the endpoint check. At `t = 0` and `t = 1` the inputs are returned
//! bit for bit (`a` and `b` respectively, without sign flip).
//!
//! `t` outside `[0, 1]` is clamped; extrapolation along the great circle is done
//! exactly with [`reflect`] (`slerp(a, b, 2)`) followed by a slerp inside
//! `[0, 1]`.

// Coefficients are written as fitted (in f64) and rounded to f32 by the compiler;
// `!(x < y)` is used on purpose where NaN must take the exceptional branch.
#![allow(clippy::excessive_precision, clippy::neg_cmp_op_on_partial_ord)]

use glam::{Quat, Vec3};

/// π as the nearest `f32`.
pub const PI: f32 = core::f32::consts::PI;
/// π/2 as the nearest `f32`.
pub const FRAC_PI_2: f32 = core::f32::consts::FRAC_PI_2;
/// π/4 as the nearest `f32`.
pub const FRAC_PI_4: f32 = core::f32::consts::FRAC_PI_4;

/// The larger of `a` and `b` by one comparison: `a` if `a > b`, else `b`
/// (so a NaN `a` gives `b`). No library call, unlike `f32::max` on the
/// Cortex-M4F, which has no `vmaxnm`.
#[inline(always)]
#[must_use]
pub fn max(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// The smaller of `a` and `b` by one comparison: `a` if `a < b`, else `b`
/// (see [`max`]).
#[inline(always)]
#[must_use]
pub fn min(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// `x` clamped into `[lo, hi]` by comparisons (NaN becomes `lo`; no
/// assertion that `lo ≤ hi`, unlike `f32::clamp`, which is a panic path).
#[inline]
#[must_use]
pub fn clamp(x: f32, lo: f32, hi: f32) -> f32 {
    if x >= hi {
        hi
    } else if x >= lo {
        x
    } else {
        lo
    }
}

/// Absolute value: clears the sign bit (exact, also for NaN and −0).
#[inline]
#[must_use]
pub fn abs(x: f32) -> f32 {
    f32::from_bits(x.to_bits() & 0x7fff_ffff)
}

/// `|x|` with the sign of `s` (exact bit operation).
#[inline]
#[must_use]
pub fn copysign(x: f32, s: f32) -> f32 {
    f32::from_bits((x.to_bits() & 0x7fff_ffff) | (s.to_bits() & 0x8000_0000))
}

/// Largest integer value not greater than `x` (exact; NaN and infinities pass through).
#[inline]
#[must_use]
pub fn floor(x: f32) -> f32 {
    // Every f32 with |x| >= 2^23 is already an integer.
    if !(abs(x) < 8_388_608.0) {
        return x;
    }
    let t = (x as i32) as f32;
    if t > x { t - 1.0 } else { t }
}

/// Reciprocal square root for normal positive `x` (no special cases; other
/// input gives an unspecified value, never a panic). Max relative error
/// 1.9e-7, as [`rsqrt`].
#[inline]
#[must_use]
pub(crate) fn rsqrt_normal(x: f32) -> f32 {
    let half = 0.5 * x;
    let mut y = f32::from_bits(0x5f37_5a86_u32.wrapping_sub(x.to_bits() >> 1));
    y = y * (1.5 - half * y * y);
    y = y * (1.5 - half * y * y);
    y * (1.5 - half * y * y)
}

/// `1 / sqrt(x)`. `rsqrt(0) = +inf`, `rsqrt(+inf) = 0`, negative or NaN input
/// gives NaN. Max relative error 1.9e-7 over all positive `f32`.
#[inline]
#[must_use]
pub fn rsqrt(x: f32) -> f32 {
    // Comparisons rather than `Range::contains` (a call at opt-level "s").
    #[allow(clippy::manual_range_contains)]
    if x >= f32::MIN_POSITIVE && x < f32::INFINITY {
        rsqrt_normal(x)
    } else {
        rsqrt_special(x)
    }
}

#[cold]
fn rsqrt_special(x: f32) -> f32 {
    if x > 0.0 && x < f32::MIN_POSITIVE {
        // Subnormal: scale by 2^24 (exact), correct by 2^12.
        rsqrt_normal(x * 16_777_216.0) * 4096.0
    } else if x == 0.0 {
        f32::INFINITY
    } else if x == f32::INFINITY {
        0.0
    } else {
        f32::NAN
    }
}

/// Correctly rounded square root (bit-identical to IEEE `sqrtf` / the M4F
/// `VSQRT`). `sqrt(−0) = −0`, negative or NaN input gives NaN.
#[must_use]
pub fn sqrt(x: f32) -> f32 {
    if !(x > 0.0) || x == f32::INFINITY {
        return if x == 0.0 || x == f32::INFINITY {
            x
        } else {
            f32::NAN
        };
    }
    if x < f32::MIN_POSITIVE {
        // 2^24 · x is normal; sqrt scales by 2^12, and 2^-12 · result stays normal.
        let s = x * 16_777_216.0;
        return round_sqrt(s, s * rsqrt_normal(s)) * (1.0 / 4096.0);
    }
    round_sqrt(x, x * rsqrt_normal(x))
}

/// Picks the correctly rounded square root of normal positive `x` near the
/// normal positive estimate `y` (within 2 ulp). The midpoints between
/// neighbouring `f32`s have 25 significant bits, so their squares are exact
/// 50-bit integers times a power of two ([`midpoint_square_cmp`]), and no
/// midpoint squares exactly to an `f32` (that would need an odd 25-bit
/// integer whose square has at most 24 bits), so there are no ties.
fn round_sqrt(x: f32, y: f32) -> f32 {
    let mut y = y;
    for _ in 0..3 {
        if midpoint_square_cmp(y, x).is_lt() {
            y = y.next_up();
            continue;
        }
        let down = y.next_down();
        if midpoint_square_cmp(down, x).is_gt() {
            y = down;
            continue;
        }
        break;
    }
    y
}

/// A normal positive `x` as `(m, e)` with `x = m · 2^e`, `m` its 24-bit
/// significand.
#[inline]
fn significand(x: f32) -> (u64, i32) {
    let bits = x.to_bits();
    let m = u64::from((bits & 0x007F_FFFF) | 0x0080_0000);
    let e = ((bits >> 23) & 0xFF) as i32 - 150;
    (m, e)
}

/// `mid² − x` compared with zero, exactly, where `mid` is the midpoint
/// between `a` and the next `f32` up (`a`, `x` normal and positive).
///
/// With `a = m·2^e`, the next `f32` up is `(m + 1)·2^e` (also across a
/// binade: `2^24·2^e = 2^23·2^(e+1)`), so `mid = (2m + 1)·2^(e−1)` and
/// `mid² = (2m + 1)²·2^(2e−2)`, an integer below 2^50 times a power of two,
/// compared with `x = mx·2^ex` (`mx < 2^24`) by shifting `mx`.
#[inline]
fn midpoint_square_cmp(a: f32, x: f32) -> core::cmp::Ordering {
    let (m, e) = significand(a);
    let (mx, ex) = significand(x);
    let odd = 2 * m + 1;
    let square = odd * odd;
    // mid² − x has the sign of square · 2^d − mx.
    let d = 2 * (e - 1) - ex;
    if d >= 0 {
        // square ≥ (2^24 + 1)² > 2^48 > mx.
        core::cmp::Ordering::Greater
    } else if d <= -28 {
        // mx · 2^28 ≥ 2^51 > square.
        core::cmp::Ordering::Less
    } else {
        square.cmp(&(mx << d.unsigned_abs()))
    }
}

// Cody–Waite split of π/2: P1 and P2 have 8 significant bits, so k·P1 and k·P2
// are exact for |k| < 2^16; P3 carries the next 24 bits.
const PIO2_1: f32 = 1.570_312_5;
const PIO2_2: f32 = 4.844_665_527_343_75e-4;
const PIO2_3: f32 = -6.397_578_431_460_715e-7;
const FRAC_2_PI: f32 = core::f32::consts::FRAC_2_PI;
// Low parts: PI + PI_LO is π to ~2^-48 (and likewise for π/2, π/4).
const PI_LO: f32 = -8.742_278e-8;
const FRAC_PI_2_LO: f32 = -4.371_139e-8;
const FRAC_PI_4_LO: f32 = -2.185_569_5e-8;

// sin r = r + r^3 (S1 + r^2 (S2 + r^2 S3)), |r| <= pi/4, fitted (rel err 1.4e-8).
const S1: f32 = -0.166_666_646_751_618_02;
const S2: f32 = 0.008_332_749_470_409_209;
const S3: f32 = -0.000_195_880_702_375_312_72;
// cos r = 1 + r^2 (C1 + r^2 (C2 + r^2 (C3 + r^2 C4))), |r| <= pi/4 (abs err 1.9e-10).
const C1: f32 = -0.499_999_999_693_093_6;
const C2: f32 = 0.041_666_650_680_999_03;
const C3: f32 = -0.001_388_759_056_807_339_7;
const C4: f32 = 2.446_393_330_502_231e-5;

/// The largest `f32` that [`reduce_pio2`] leaves in quadrant 0 (two below
/// [`FRAC_PI_4`]: `x·2/π + ½` rounds up to 1 from the next one on).
const SIN_COS_DIRECT: f32 = 0.785_398_07;

/// Reduces `x` to `r ∈ [−π/4, π/4]` and the quadrant `k mod 4`.
#[inline]
fn reduce_pio2(x: f32) -> (f32, i32) {
    let k = (x * FRAC_2_PI + copysign(0.5, x)) as i32;
    let kf = k as f32;
    let r = ((x - kf * PIO2_1) - kf * PIO2_2) - kf * PIO2_3;
    (r, k & 3)
}

#[inline]
fn sin_poly(r: f32) -> f32 {
    let r2 = r * r;
    r + r * r2 * (S1 + r2 * (S2 + r2 * S3))
}

#[inline]
fn cos_poly(r: f32) -> f32 {
    let r2 = r * r;
    1.0 + r2 * (C1 + r2 * (C2 + r2 * (C3 + r2 * C4)))
}

/// Sine and cosine of `x` (radians) together. Accurate (8.7e-8 absolute) for
/// `|x| ≤ 1e5`; beyond that the range reduction loses accuracy (still finite,
/// never panics). NaN or infinite input gives NaN.
///
/// Up to `SIN_COS_DIRECT` (π/4) in magnitude (a joint's half angle, mostly) the
/// reduction is skipped: it would give `r = x` and quadrant 0 there, so the
/// result is the same bit for bit (`sin_cos_fast_path_is_the_reduced_path`).
#[inline]
#[must_use]
pub fn sin_cos(x: f32) -> (f32, f32) {
    if abs(x) <= SIN_COS_DIRECT {
        return (sin_poly(x), cos_poly(x));
    }
    if !(abs(x) < f32::INFINITY) {
        return (f32::NAN, f32::NAN);
    }
    sin_cos_reduced(x)
}

/// [`sin_cos`] of a finite `x` by the range reduction to `[−π/4, π/4]` and
/// the quadrant.
#[inline]
fn sin_cos_reduced(x: f32) -> (f32, f32) {
    let (r, q) = reduce_pio2(x);
    let s = sin_poly(r);
    let c = cos_poly(r);
    match q {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

/// Sine of `x` (radians); see [`sin_cos`].
#[inline]
#[must_use]
pub fn sin(x: f32) -> f32 {
    sin_cos(x).0
}

/// Cosine of `x` (radians); see [`sin_cos`].
#[inline]
#[must_use]
pub fn cos(x: f32) -> f32 {
    sin_cos(x).1
}

// asin r = r + r^3 P(r^2) on |r| <= 1/2 (rel err 1.5e-8 in f64).
const AS: [f32; 5] = [
    0.166_666_731_100_121_42,
    0.074_987_630_112_489_13,
    0.045_020_014_823_580_78,
    0.026_434_430_254_441_057,
    0.038_326_409_582_553_185,
];

#[inline]
fn asin_poly(r: f32) -> f32 {
    let r2 = r * r;
    let [a0, a1, a2, a3, a4] = AS;
    r + r * r2 * (a0 + r2 * (a1 + r2 * (a2 + r2 * (a3 + r2 * a4))))
}

/// Arcsine in `[−π/2, π/2]`. Input is clamped to `[−1, 1]`; NaN gives NaN.
#[must_use]
pub fn asin(x: f32) -> f32 {
    let a = abs(x);
    if !(a <= 1.0) {
        return if x.is_nan() {
            f32::NAN
        } else {
            copysign(FRAC_PI_2, x)
        };
    }
    if a <= 0.5 {
        return asin_poly(x);
    }
    // asin a = π/2 − 2 asin(sqrt((1 − a)/2)); 1 − a is exact for a ≥ 1/2.
    let r = sqrt((1.0 - a) * 0.5);
    copysign((FRAC_PI_2 - 2.0 * asin_poly(r)) + FRAC_PI_2_LO, x)
}

/// Arccosine in `[0, π]`. Input is clamped to `[−1, 1]`; NaN gives NaN.
#[must_use]
pub fn acos(x: f32) -> f32 {
    let a = abs(x);
    if !(a <= 1.0) {
        return if x.is_nan() {
            f32::NAN
        } else if x > 0.0 {
            0.0
        } else {
            PI
        };
    }
    if a <= 0.5 {
        return (FRAC_PI_2 - asin_poly(x)) + FRAC_PI_2_LO;
    }
    let r = 2.0 * asin_poly(sqrt((1.0 - a) * 0.5));
    if x > 0.0 { r } else { (PI - r) + PI_LO }
}

// atan r = r + r^3 P(r^2) on |r| <= tan(pi/8) (rel err 2.7e-9 in f64).
const AT: [f32; 5] = [
    -0.333_333_318_696_369_2,
    0.199_995_599_465_154_72,
    -0.142_645_165_744_981_68,
    0.107_489_324_296_562_95,
    -0.064_670_284_285_164_41,
];
const TAN_PI_8: f32 = 0.414_213_57;

#[inline]
fn atan_poly(r: f32) -> f32 {
    let r2 = r * r;
    let [a0, a1, a2, a3, a4] = AT;
    r + r * r2 * (a0 + r2 * (a1 + r2 * (a2 + r2 * (a3 + r2 * a4))))
}

/// `atan t` for `t ∈ [0, 1]`.
#[inline]
fn atan_unit(t: f32) -> f32 {
    if t > TAN_PI_8 {
        (FRAC_PI_4 + atan_poly((t - 1.0) / (t + 1.0))) + FRAC_PI_4_LO
    } else {
        atan_poly(t)
    }
}

/// Arctangent in `(−π/2, π/2)`.
#[must_use]
pub fn atan(x: f32) -> f32 {
    let a = abs(x);
    if a <= 1.0 {
        copysign(atan_unit(a), x)
    } else if a.is_nan() {
        f32::NAN
    } else {
        copysign((FRAC_PI_2 - atan_unit(1.0 / a)) + FRAC_PI_2_LO, x)
    }
}

/// Four-quadrant arctangent of `y / x` in `[−π, π]` (IEEE conventions for
/// signed zeros and infinities; NaN in gives NaN).
#[must_use]
pub fn atan2(y: f32, x: f32) -> f32 {
    if x.is_nan() || y.is_nan() {
        return f32::NAN;
    }
    let (ax, ay) = (abs(x), abs(y));
    let a = if ay <= ax {
        if ax == 0.0 {
            0.0
        } else if ax == f32::INFINITY && ay == f32::INFINITY {
            FRAC_PI_4
        } else {
            atan_unit(ay / ax)
        }
    } else if ax == f32::INFINITY {
        FRAC_PI_4
    } else {
        (FRAC_PI_2 - atan_unit(ax / ay)) + FRAC_PI_2_LO
    };
    let a = if x.is_sign_negative() {
        (PI - a) + PI_LO
    } else {
        a
    };
    copysign(a, y)
}

/// Four-component quaternion dot product in a fixed summation order.
#[inline]
#[must_use]
pub fn quat_dot(a: Quat, b: Quat) -> f32 {
    a.x * b.x + a.y * b.y + a.z * b.z + a.w * b.w
}

/// Euclidean length `|v|` (correctly rounded square root of the dot product).
#[inline]
#[must_use]
pub fn length(v: Vec3) -> f32 {
    sqrt(v.dot(v))
}

/// Unit vector along `v`; the zero vector for zero or non-finite `v`. Very
/// small and very large vectors are rescaled first, so they normalize too.
#[inline]
#[must_use]
pub fn normalize_vec3(v: Vec3) -> Vec3 {
    let n2 = v.dot(v);
    if (f32::MIN_POSITIVE..f32::INFINITY).contains(&n2) {
        v * rsqrt_normal(n2)
    } else {
        normalize_vec3_rescaled(v)
    }
}

#[cold]
fn normalize_vec3_rescaled(v: Vec3) -> Vec3 {
    let m = abs(v.x).max(abs(v.y)).max(abs(v.z));
    if !(m > 0.0 && m < f32::INFINITY) {
        return Vec3::ZERO;
    }
    let w = v * (1.0 / m);
    let n2 = w.dot(w);
    if (f32::MIN_POSITIVE..f32::INFINITY).contains(&n2) {
        w * rsqrt_normal(n2)
    } else {
        Vec3::ZERO
    }
}

/// Unit quaternion along `q`; identity for zero, tiny or non-finite `q`.
#[inline]
#[must_use]
pub fn normalize_quat(q: Quat) -> Quat {
    let n2 = quat_dot(q, q);
    if (1e-30..f32::INFINITY).contains(&n2) {
        q * rsqrt_normal(n2)
    } else {
        Quat::IDENTITY
    }
}

/// Linear interpolation `a·(1 − t) + b·t`: returns `a` exactly at `t = 0` and
/// `b` exactly at `t = 1`; extrapolates outside `[0, 1]`.
#[inline]
#[must_use]
pub fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a * (1.0 - t) + b * t
}

/// [`lerp`] for vectors (exact at `t = 0` and `t = 1`).
#[inline]
#[must_use]
pub fn lerp_vec3(a: Vec3, b: Vec3, t: f32) -> Vec3 {
    a * (1.0 - t) + b * t
}

/// Normalized linear interpolation along the shortest arc. Exact endpoints
/// (`a` at `t = 0`, `b` at `t = 1`); inputs should be unit quaternions.
#[inline]
#[must_use]
pub fn nlerp(a: Quat, b: Quat, t: f32) -> Quat {
    if t <= 0.0 {
        return a;
    }
    if t >= 1.0 {
        return b;
    }
    let w1 = copysign(t, quat_dot(a, b));
    blend_normalize(a, b, 1.0 - t, w1)
}

/// `normalize(w0·a + w1·b)` written out in scalar form.
#[inline]
fn blend_normalize(a: Quat, b: Quat, w0: f32, w1: f32) -> Quat {
    let x = a.x * w0 + b.x * w1;
    let y = a.y * w0 + b.y * w1;
    let z = a.z * w0 + b.z * w1;
    let w = a.w * w0 + b.w * w1;
    let n2 = x * x + y * y + z * z + w * w;
    if (1e-30..f32::INFINITY).contains(&n2) {
        let s = rsqrt_normal(n2);
        Quat::from_xyzw(x * s, y * s, z * s, w * s)
    } else {
        Quat::IDENTITY
    }
}

/// The fitted slerp weight polynomial `F(t², x)`, indexed `[t² power][x power]`.
const SLERP_F: [[f32; 6]; 4] = [
    [
        1.570_772_553_152_843_8,
        -0.998_242_567_962_981_4,
        0.762_036_593_167_976_1,
        -0.547_137_133_395_922_8,
        0.281_904_062_067_990_24,
        -0.069_354_902_563_716_82,
    ],
    [
        -0.645_900_545_472_422_9,
        1.230_849_774_464_800_8,
        -1.072_221_768_126_623,
        0.805_083_396_228_422_3,
        -0.422_742_689_032_799_55,
        0.104_965_142_072_287_63,
    ],
    [
        0.079_539_106_324_037_75,
        -0.251_753_300_052_417_5,
        0.346_366_781_965_046,
        -0.296_950_480_903_935_7,
        0.165_027_079_615_362_42,
        -0.042_244_756_629_707_97,
    ],
    [
        -0.004_417_768_790_401_553,
        0.019_155_837_959_713_734,
        -0.036_318_978_416_751_33,
        0.039_600_703_127_111_77,
        -0.025_011_999_830_332_75,
        0.006_996_669_409_464_504,
    ],
];

/// Coefficients in powers of `x` of `W(s, x) = s·F(s², x)` for one `s`.
fn weight_poly(s: f32) -> [f32; 6] {
    let s2 = s * s;
    let [f0, f1, f2, f3] = SLERP_F;
    // Coefficient by coefficient (no iterator calls at opt-level "s").
    let c = |i: usize| -> f32 {
        let at = |f: [f32; 6]| f.get(i).copied().unwrap_or(0.0);
        s * (at(f0) + s2 * (at(f1) + s2 * (at(f2) + s2 * at(f3))))
    };
    [c(0), c(1), c(2), c(3), c(4), c(5)]
}

/// Evaluates a degree-5 polynomial in `x` given `x²`, `x⁴` (Estrin's scheme:
/// the same operation count as Horner with a third of its latency).
#[inline(always)]
fn poly5<T: Lane>(c: &[T; 6], x: T, x2: T, x4: T) -> T {
    let [c0, c1, c2, c3, c4, c5] = *c;
    ((c0 + c1 * x) + x2 * (c2 + c3 * x)) + x4 * (c4 + c5 * x)
}

/// A number type the slerp kernel runs on: `f32`, or [`F4`] (four
/// independent `f32` lanes). Every lane performs exactly the `f32` operation
/// sequence, so both give the same bits.
pub trait Lane:
    Copy + core::ops::Add<Output = Self> + core::ops::Sub<Output = Self> + core::ops::Mul<Output = Self>
{
    /// All lanes `v`.
    fn splat(v: f32) -> Self;
    /// Lane-wise [`abs`].
    #[must_use]
    fn abs(self) -> Self;
    /// Lane-wise [`copysign`]`(self, s)`.
    #[must_use]
    fn copysign(self, s: Self) -> Self;
}

impl Lane for f32 {
    #[inline]
    fn splat(v: f32) -> Self {
        v
    }
    #[inline]
    fn abs(self) -> Self {
        abs(self)
    }
    #[inline]
    fn copysign(self, s: Self) -> Self {
        copysign(self, s)
    }
}

/// Four `f32` lanes with lane-wise IEEE operations (the compiler maps them to
/// SIMD where the target has it). Used to run four segments' slerps at once.
/// Aligned like a SIMD register, so an `F4` in memory can be an operand.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(16))]
pub struct F4(pub [f32; 4]);

macro_rules! f4_op {
    ($tr:ident, $f:ident, $op:tt) => {
        impl core::ops::$tr for F4 {
            type Output = F4;
            #[inline]
            fn $f(self, o: F4) -> F4 {
                let ([a0, a1, a2, a3], [b0, b1, b2, b3]) = (self.0, o.0);
                F4([a0 $op b0, a1 $op b1, a2 $op b2, a3 $op b3])
            }
        }
    };
}
f4_op!(Add, add, +);
f4_op!(Sub, sub, -);
f4_op!(Mul, mul, *);

impl Lane for F4 {
    #[inline]
    fn splat(v: f32) -> Self {
        F4([v; 4])
    }
    #[inline]
    fn abs(self) -> Self {
        let [a0, a1, a2, a3] = self.0;
        F4([abs(a0), abs(a1), abs(a2), abs(a3)])
    }
    #[inline]
    fn copysign(self, s: Self) -> Self {
        let ([a0, a1, a2, a3], [s0, s1, s2, s3]) = (self.0, s.0);
        F4([
            copysign(a0, s0),
            copysign(a1, s1),
            copysign(a2, s2),
            copysign(a3, s3),
        ])
    }
}

/// Where a [`SlerpWeight`] sits: the endpoints return an input unchanged.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum SlerpMode {
    Start,
    Mid,
    End,
}

/// A slerp parameter `t` with its weight polynomials precomputed, for
/// applying the same `t` to many quaternion pairs (one grid query applies
/// the same coefficients to every segment). See the module doc.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SlerpWeight {
    t: f32,
    /// `W(1 − t, x)` in powers of `x`.
    w0: [f32; 6],
    /// `W(t, x)` in powers of `x`.
    w1: [f32; 6],
    mode: SlerpMode,
}

impl SlerpWeight {
    /// The weight `t = 0` (returns the first input).
    pub const START: SlerpWeight = SlerpWeight {
        t: 0.0,
        w0: [0.0; 6],
        w1: [0.0; 6],
        mode: SlerpMode::Start,
    };

    /// Precomputes the weight for `t` (clamped to `[0, 1]`).
    #[must_use]
    pub fn new(t: f32) -> Self {
        let mode = if t <= 0.0 {
            SlerpMode::Start
        } else if t >= 1.0 {
            SlerpMode::End
        } else {
            SlerpMode::Mid
        };
        let t = t.clamp(0.0, 1.0);
        if mode != SlerpMode::Mid {
            // The endpoints return an input; no polynomial needed.
            return Self {
                t,
                w0: [0.0; 6],
                w1: [0.0; 6],
                mode,
            };
        }
        Self {
            t,
            w0: weight_poly(1.0 - t),
            w1: weight_poly(t),
            mode,
        }
    }

    /// The (clamped) parameter.
    #[inline]
    #[must_use]
    pub fn t(&self) -> f32 {
        self.t
    }

    /// Slerp from `a` to `b` (unit quaternions, shortest arc) at this weight.
    #[inline(always)]
    #[must_use]
    pub fn apply(&self, a: Quat, b: Quat) -> Quat {
        match self.mode {
            SlerpMode::Start => a,
            SlerpMode::End => b,
            SlerpMode::Mid => self.mid(a, b),
        }
    }

    #[inline(always)]
    fn mid(&self, a: Quat, b: Quat) -> Quat {
        let [x, y, z, w] = self.kernel([a.x, a.y, a.z, a.w], [b.x, b.y, b.z, b.w]);
        Quat::from_xyzw(x, y, z, w)
    }

    /// Slerp on `[x, y, z, w]` components of any [`Lane`] type, e.g. four
    /// quaternion pairs at once as [`F4`] lanes (bit-identical to [`apply`]
    /// per lane, endpoints included).
    ///
    /// [`apply`]: SlerpWeight::apply
    #[inline(always)]
    #[must_use]
    pub fn apply_lanes<T: Lane>(&self, a: [T; 4], b: [T; 4]) -> [T; 4] {
        match self.mode {
            SlerpMode::Start => a,
            SlerpMode::End => b,
            SlerpMode::Mid => self.kernel(a, b),
        }
    }

    /// The slerp without its final normalization: `w0·a + w1·b` with the
    /// fitted weights, whose length is within 4e-6 of 1 for unit inputs (and
    /// within about the sum of the inputs' length errors more otherwise).
    /// For interpolation trees that feed it into further blends and
    /// normalize only the result ([`renormalize_lanes`]); the endpoints
    /// return an input unchanged, as [`SlerpWeight::apply`] does.
    #[inline(always)]
    #[must_use]
    pub fn blend_lanes<T: Lane>(&self, a: [T; 4], b: [T; 4]) -> [T; 4] {
        match self.mode {
            SlerpMode::Start => a,
            SlerpMode::End => b,
            SlerpMode::Mid => self.blend(a, b),
        }
    }

    /// Whether this weight blends (`0 < t < 1`) rather than returning an input.
    #[inline]
    #[must_use]
    pub fn is_blend(&self) -> bool {
        self.mode == SlerpMode::Mid
    }

    #[inline(always)]
    fn kernel<T: Lane>(&self, a: [T; 4], b: [T; 4]) -> [T; 4] {
        renormalize_lanes(self.blend(a, b))
    }

    /// The weight with its polynomial coefficients as lane values (for
    /// [`F4`], each broadcast to four lanes once rather than in every
    /// blend).
    #[inline]
    #[must_use]
    pub fn lanes<T: Lane>(&self) -> LaneWeight<T> {
        LaneWeight {
            w0: self.w0.map(T::splat),
            w1: self.w1.map(T::splat),
            mode: self.mode,
        }
    }

    /// [`SlerpWeight::blend_lanes`] for a weight known to blend
    /// ([`SlerpWeight::is_blend`]); an endpoint weight gives zeros.
    #[inline(always)]
    #[must_use]
    pub(crate) fn blend<T: Lane>(&self, a: [T; 4], b: [T; 4]) -> [T; 4] {
        blend(&self.w0.map(T::splat), &self.w1.map(T::splat), a, b)
    }
}

/// A [`SlerpWeight`] whose polynomial coefficients are lane values
/// ([`SlerpWeight::lanes`]): the same operations, so the same bits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LaneWeight<T> {
    w0: [T; 6],
    w1: [T; 6],
    mode: SlerpMode,
}

impl<T: Lane> LaneWeight<T> {
    /// [`SlerpWeight::blend_lanes`] with this weight.
    #[inline(always)]
    #[must_use]
    pub fn blend_lanes(&self, a: [T; 4], b: [T; 4]) -> [T; 4] {
        match self.mode {
            SlerpMode::Start => a,
            SlerpMode::End => b,
            SlerpMode::Mid => blend(&self.w0, &self.w1, a, b),
        }
    }
}

/// The fast slerp's unnormalized blend `w0·a + w1·b` (see the module doc).
#[inline(always)]
fn blend<T: Lane>(c0: &[T; 6], c1: &[T; 6], a: [T; 4], b: [T; 4]) -> [T; 4] {
    let [ax, ay, az, aw] = a;
    let [bx, by, bz, bw] = b;
    // Pairwise sums: shorter dependency chains (the order is fixed, so the
    // bits are still the same on every target).
    let d = (ax * bx + ay * by) + (az * bz + aw * bw);
    let x = d.abs();
    let x2 = x * x;
    let x4 = x2 * x2;
    let w0 = poly5(c0, x, x2, x4);
    let w1 = poly5(c1, x, x2, x4).copysign(d);
    [
        ax * w0 + bx * w1,
        ay * w0 + by * w1,
        az * w0 + bz * w1,
        aw * w0 + bw * w1,
    ]
}

/// One Newton step for `1/|r|` from 1: `r · (3 − |r|²)/2`. Normalizes a
/// quaternion whose length is within about 1e-3 of 1 to rounding error
/// (a length error `e` leaves about `1.5·e²`); the last step of
/// [`SlerpWeight::apply`], and the normalization of a tree of
/// [`SlerpWeight::blend_lanes`].
#[inline(always)]
#[must_use]
pub fn renormalize_lanes<T: Lane>(r: [T; 4]) -> [T; 4] {
    let [rx, ry, rz, rw] = r;
    let s = T::splat(1.5) - T::splat(0.5) * ((rx * rx + ry * ry) + (rz * rz + rw * rw));
    [rx * s, ry * s, rz * s, rw * s]
}

/// Fast spherical linear interpolation from `a` to `b` along the shortest arc
/// (see the module doc: within 6.7e-6 rad of exact slerp for unit inputs).
/// `t` is clamped to `[0, 1]`; returns `a` exactly at `t ≤ 0` and `b` exactly
/// at `t ≥ 1`. For many pairs with the same `t`, use [`SlerpWeight`].
#[inline]
#[must_use]
pub fn slerp(a: Quat, b: Quat, t: f32) -> Quat {
    SlerpWeight::new(t).apply(a, b)
}

/// `slerp(a, b, 2)`: `a` reflected through `b` on the great circle,
/// `2(a·b)b − a`. Independent of the sign of `b`; no normalization needed for
/// unit inputs (rounding error only).
#[inline]
#[must_use]
pub fn reflect(a: Quat, b: Quat) -> Quat {
    let [x, y, z, w] = reflect_lanes([a.x, a.y, a.z, a.w], [b.x, b.y, b.z, b.w]);
    Quat::from_xyzw(x, y, z, w)
}

/// [`reflect`] on `[x, y, z, w]` components of any [`Lane`] type (same bits
/// per lane).
#[inline]
#[must_use]
pub fn reflect_lanes<T: Lane>(a: [T; 4], b: [T; 4]) -> [T; 4] {
    let [ax, ay, az, aw] = a;
    let [bx, by, bz, bw] = b;
    let s = T::splat(2.0) * (ax * bx + ay * by + az * bz + aw * bw);
    [s * bx - ax, s * by - ay, s * bz - az, s * bw - aw]
}

/// Rotation by `angle` radians about `axis` (normalized here; a zero axis
/// gives the identity).
#[inline]
#[must_use]
pub fn from_axis_angle(axis: Vec3, angle: f32) -> Quat {
    let n = normalize_vec3(axis);
    let (s, c) = sin_cos(0.5 * angle);
    let v = n * s;
    Quat::from_xyzw(v.x, v.y, v.z, c)
}

/// Rotation angle of `q` in `[0, π]` (for any non-zero `q`, sign-independent):
/// `2·atan2(|v|, |w|)`, accurate near 0 and near π.
#[inline]
#[must_use]
pub fn quat_angle(q: Quat) -> f32 {
    let v = Vec3::new(q.x, q.y, q.z);
    2.0 * atan2(length(v), abs(q.w))
}

/// Shortest rotation taking direction `from` to direction `to` (both are
/// normalized here). With `h = f + t`, the quaternion `(|h|²/2, f × h)` equals
/// `(1 + cos θ, sin θ·n)` but is computed without cancellation, so it stays
/// accurate close to opposite directions. Within ~1e-6 rad of opposite (and
/// for a zero input) a rotation by π about an axis perpendicular to `from` is
/// returned (identity if `from` is zero).
#[must_use]
pub fn rotation_arc(from: Vec3, to: Vec3) -> Quat {
    let f = normalize_vec3(from);
    let t = normalize_vec3(to);
    if f == Vec3::ZERO || t == Vec3::ZERO {
        return Quat::IDENTITY;
    }
    let h = f + t;
    let h2 = h.dot(h);
    if h2 < 1e-12 {
        // Opposite: rotate by π about an axis perpendicular to f.
        let other = if abs(f.x) < 0.6 { Vec3::X } else { Vec3::Y };
        let n = normalize_vec3(f.cross(other));
        return Quat::from_xyzw(n.x, n.y, n.z, 0.0);
    }
    let v = f.cross(h);
    normalize_quat(Quat::from_xyzw(v.x, v.y, v.z, 0.5 * h2))
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec::Vec;

    /// Small deterministic PRNG (xorshift64*) for test inputs.
    pub(crate) struct Rng(u64);
    impl Rng {
        pub(crate) fn new(seed: u64) -> Self {
            Self(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1)
        }
        pub(crate) fn next_u64(&mut self) -> u64 {
            let mut x = self.0;
            x ^= x >> 12;
            x ^= x << 25;
            x ^= x >> 27;
            self.0 = x;
            x.wrapping_mul(0x2545_f491_4f6c_dd1d)
        }
        /// Uniform in [0, 1).
        pub(crate) fn unit(&mut self) -> f64 {
            (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
        }
        pub(crate) fn range(&mut self, lo: f64, hi: f64) -> f64 {
            lo + (hi - lo) * self.unit()
        }
        /// Uniformly distributed unit quaternion (f64 components).
        pub(crate) fn quat(&mut self) -> [f64; 4] {
            loop {
                let q = [
                    self.range(-1.0, 1.0),
                    self.range(-1.0, 1.0),
                    self.range(-1.0, 1.0),
                    self.range(-1.0, 1.0),
                ];
                let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
                if n > 0.1 && n <= 1.0 {
                    return q.map(|v| v / n);
                }
            }
        }
    }

    fn q32(q: [f64; 4]) -> Quat {
        Quat::from_xyzw(q[0] as f32, q[1] as f32, q[2] as f32, q[3] as f32)
    }
    fn q64(q: Quat) -> [f64; 4] {
        [
            f64::from(q.x),
            f64::from(q.y),
            f64::from(q.z),
            f64::from(q.w),
        ]
    }
    fn dot64(a: [f64; 4], b: [f64; 4]) -> f64 {
        a.iter().zip(b).map(|(x, y)| x * y).sum()
    }
    fn norm64(a: [f64; 4]) -> [f64; 4] {
        let n = dot64(a, a).sqrt();
        a.map(|v| v / n)
    }
    /// Exact slerp in f64 along the shortest arc (textbook formula).
    pub(crate) fn slerp64(a: [f64; 4], b: [f64; 4], t: f64) -> [f64; 4] {
        let b = if dot64(a, b) < 0.0 { b.map(|v| -v) } else { b };
        slerp64_arc(a, b, t)
    }
    /// Exact slerp in f64 along the arc from `a` to `b` as given (no flip).
    pub(crate) fn slerp64_arc(a: [f64; 4], b: [f64; 4], t: f64) -> [f64; 4] {
        let (a, b) = (norm64(a), norm64(b));
        let th = dot64(a, b).clamp(-1.0, 1.0).acos();
        if th < 1e-12 {
            return a;
        }
        let s = th.sin();
        let (w0, w1) = (((1.0 - t) * th).sin() / s, (t * th).sin() / s);
        [0, 1, 2, 3].map(|i| w0 * a[i] + w1 * b[i])
    }
    /// Rotation angle between two quaternions, 2·acos(|a·b|), in f64.
    pub(crate) fn rot_err(a: [f64; 4], b: [f64; 4]) -> f64 {
        let d = dot64(norm64(a), norm64(b)).abs().min(1.0);
        2.0 * d.acos()
    }

    /// Floats spread over the whole positive range: every `stride`-th bit pattern.
    fn positive_sweep(stride: u32) -> impl Iterator<Item = f32> {
        (1u32..0x7f80_0000)
            .step_by(stride as usize)
            .map(f32::from_bits)
    }

    #[test]
    fn max_min_clamp_compare_like_std() {
        let xs = [-3.5f32, -0.0, 0.0, 1e-30, 2.0, 7.25, f32::INFINITY];
        for &a in &xs {
            for &b in &xs {
                if a != b {
                    assert_eq!(max(a, b), a.max(b), "{a} {b}");
                    assert_eq!(min(a, b), a.min(b), "{a} {b}");
                }
                let (lo, hi) = if a <= b { (a, b) } else { (b, a) };
                for &x in &xs {
                    assert_eq!(clamp(x, lo, hi), x.clamp(lo, hi), "{x} {lo} {hi}");
                }
            }
        }
        // NaN: `max`/`min` take the other value, `clamp` the lower bound.
        assert_eq!(max(f32::NAN, 1.0), 1.0);
        assert_eq!(min(f32::NAN, 1.0), 1.0);
        assert_eq!(clamp(f32::NAN, -1.0, 1.0), -1.0);
    }

    #[test]
    fn abs_copysign_floor() {
        assert_eq!(abs(-2.5).to_bits(), 2.5f32.to_bits());
        assert_eq!(abs(-0.0).to_bits(), 0.0f32.to_bits());
        assert_eq!(copysign(3.0, -0.0), -3.0);
        for x in [
            -2.5f32,
            -2.0,
            -0.5,
            -0.0,
            0.0,
            0.3,
            1.0,
            7.9,
            -1e9,
            1e9,
            8_388_607.5,
            -8_388_607.5,
        ] {
            assert_eq!(floor(x), f64::from(x).floor() as f32, "{x}");
        }
        assert!(floor(f32::NAN).is_nan());
    }

    #[test]
    fn rsqrt_error_bound() {
        let mut max = 0.0f64;
        let subnormals = (1u32..0x0080_0000).step_by(4099).map(f32::from_bits);
        for x in positive_sweep(97)
            .chain(subnormals)
            .chain([f32::MIN_POSITIVE, f32::MAX, 1.0, 4.0])
        {
            let r = f64::from(rsqrt(x));
            let e = 1.0 / f64::from(x).sqrt();
            max = max.max((r - e).abs() / e);
        }
        std::println!("rsqrt max rel err {max:e}");
        assert!(max < 2.0e-7, "{max:e}");
        assert_eq!(rsqrt(0.0), f32::INFINITY);
        assert_eq!(rsqrt(f32::INFINITY), 0.0);
        assert!(rsqrt(-1.0).is_nan() && rsqrt(f32::NAN).is_nan());
    }

    #[test]
    fn sqrt_is_correctly_rounded() {
        // f64 sqrt rounded to f32 is the correctly rounded f32 sqrt (53 >= 2·24 + 2).
        let subnormals = (1u32..0x0080_0000).step_by(1021).map(f32::from_bits);
        let dense = (0x3f80_0000u32..0x4080_0000).step_by(7).map(f32::from_bits);
        for x in positive_sweep(61)
            .chain(subnormals)
            .chain(dense)
            .chain([f32::MIN_POSITIVE, f32::MAX])
        {
            let e = f64::from(x).sqrt() as f32;
            assert_eq!(sqrt(x).to_bits(), e.to_bits(), "sqrt({x:e})");
        }
        assert_eq!(sqrt(0.0).to_bits(), 0.0f32.to_bits());
        assert_eq!(sqrt(-0.0).to_bits(), (-0.0f32).to_bits());
        assert_eq!(sqrt(f32::INFINITY), f32::INFINITY);
        assert!(sqrt(-1.0).is_nan() && sqrt(f32::NAN).is_nan());
    }

    /// The fast path of [`sin_cos`] (`|x| ≤` [`SIN_COS_DIRECT`]) gives the
    /// reduced path's bits. The reduction gives quadrant 0 and `r = x`
    /// wherever `x·2/π + ½` rounds below 1 (`x − 0·P` is `x`, also for −0),
    /// and both roundings are monotone in `x`: the floats next to the bound
    /// are checked exhaustively, the rest densely.
    #[test]
    fn sin_cos_fast_path_is_the_reduced_path() {
        let same = |x: f32| {
            let (a, b) = (sin_cos(x), sin_cos_reduced(x));
            assert_eq!(
                (a.0.to_bits(), a.1.to_bits()),
                (b.0.to_bits(), b.1.to_bits()),
                "sin_cos({x:e})"
            );
        };
        assert_eq!(SIN_COS_DIRECT.to_bits(), FRAC_PI_4.to_bits() - 2);
        assert_eq!(reduce_pio2(SIN_COS_DIRECT), (SIN_COS_DIRECT, 0));
        assert_eq!(reduce_pio2(SIN_COS_DIRECT.next_up()).1, 1);
        let edge = FRAC_PI_4.to_bits();
        for bits in edge - (1 << 20)..edge + (1 << 20) {
            same(f32::from_bits(bits));
            same(-f32::from_bits(bits));
        }
        for bits in (0..edge).step_by(97) {
            same(f32::from_bits(bits));
            same(-f32::from_bits(bits));
        }
        for x in [0.0, -0.0, f32::MIN_POSITIVE, 1e-45, SIN_COS_DIRECT] {
            same(x);
            same(-x);
        }
    }

    #[test]
    fn sin_cos_error_bound() {
        let mut max = 0.0f64;
        let mut check = |x: f32| {
            let (s, c) = sin_cos(x);
            let xd = f64::from(x);
            max = max
                .max((f64::from(s) - xd.sin()).abs())
                .max((f64::from(c) - xd.cos()).abs());
            assert_eq!(s.to_bits(), sin(x).to_bits());
            assert_eq!(c.to_bits(), cos(x).to_bits());
        };
        for i in -2_000_000..=2_000_000 {
            check(i as f32 * (7.0 / 2_000_000.0));
        }
        for i in -200_000..=200_000 {
            check(i as f32 * 0.5);
        }
        for x in [
            0.0,
            -0.0,
            1e-30,
            FRAC_PI_4,
            FRAC_PI_2,
            PI,
            -PI,
            2.0 * PI,
            1e5,
            -1e5,
            99_999.99,
        ] {
            check(x);
        }
        std::println!("sin/cos max abs err {max:e}");
        assert!(max < 9.0e-8, "{max:e}");
        assert!(sin(f32::NAN).is_nan() && cos(f32::INFINITY).is_nan());
    }

    #[test]
    fn asin_acos_error_bound() {
        let (mut ms, mut mc) = (0.0f64, 0.0f64);
        let n = 2_000_000;
        for i in -n..=n {
            let x = i as f32 / n as f32;
            let xd = f64::from(x);
            ms = ms.max((f64::from(asin(x)) - xd.asin()).abs());
            mc = mc.max((f64::from(acos(x)) - xd.acos()).abs());
        }
        for x in [
            1.0f32,
            -1.0,
            0.5,
            -0.5,
            0.5f32.next_up(),
            1.0f32.next_down(),
            1e-20,
        ] {
            let xd = f64::from(x);
            ms = ms.max((f64::from(asin(x)) - xd.asin()).abs());
            mc = mc.max((f64::from(acos(x)) - xd.acos()).abs());
        }
        std::println!("asin max abs err {ms:e}, acos {mc:e}");
        assert!(ms < 1.7e-7 && mc < 3.2e-7, "{ms:e} {mc:e}");
        assert_eq!(acos(1.5), 0.0);
        assert_eq!(acos(-1.5), PI);
        assert_eq!(asin(2.0), FRAC_PI_2);
        assert!(asin(f32::NAN).is_nan() && acos(f32::NAN).is_nan());
    }

    #[test]
    fn atan_atan2_error_bound() {
        let mut max = 0.0f64;
        for i in -1_000_000..=1_000_000 {
            let x = i as f32 * 1e-5;
            max = max.max((f64::from(atan(x)) - f64::from(x).atan()).abs());
            let big = i as f32 * 100.0;
            max = max.max((f64::from(atan(big)) - f64::from(big).atan()).abs());
        }
        let n = 4000;
        for i in 0..n {
            let a = -3.2 + 6.4 * i as f64 / n as f64;
            for r in [1e-30f64, 1e-3, 1.0, 7.5, 1e30] {
                let (y, x) = ((r * a.sin()) as f32, (r * a.cos()) as f32);
                let e = f64::from(y).atan2(f64::from(x));
                max = max.max((f64::from(atan2(y, x)) - e).abs());
            }
        }
        std::println!("atan/atan2 max abs err {max:e}");
        assert!(max < 2.9e-7, "{max:e}");
        let inf = f32::INFINITY;
        for (y, x) in [
            (0.0f32, 0.0f32),
            (-0.0, 0.0),
            (0.0, -0.0),
            (-0.0, -0.0),
            (inf, inf),
            (-inf, inf),
            (inf, -inf),
            (1.0, inf),
            (1.0, -inf),
            (inf, 1.0),
        ] {
            let e = f64::from(y).atan2(f64::from(x)) as f32;
            assert!(
                (atan2(y, x) - e).abs() < 3e-7
                    && atan2(y, x).is_sign_negative() == e.is_sign_negative(),
                "atan2({y}, {x})"
            );
        }
        assert!(atan2(f32::NAN, 1.0).is_nan() && atan(f32::NAN).is_nan());
    }

    /// Slerp error over random pairs, nearly identical and nearly opposite pairs.
    #[test]
    fn slerp_error_bound() {
        let mut rng = Rng::new(7);
        let mut pairs: Vec<([f64; 4], [f64; 4])> = Vec::new();
        for _ in 0..20_000 {
            pairs.push((rng.quat(), rng.quat()));
        }
        for k in 0..2_000 {
            let a = rng.quat();
            // b close to a, to -a, or at 90° in 4D (opposite rotations).
            let eps = 10f64.powf(rng.range(-7.0, -1.0));
            let p = rng.quat();
            let near = norm64([0, 1, 2, 3].map(|i| a[i] + eps * p[i]));
            let perp = {
                let d = dot64(p, a);
                norm64([0, 1, 2, 3].map(|i| p[i] - d * a[i]))
            };
            let opp = norm64(
                [0, 1, 2, 3].map(|i| perp[i] + eps * a[i] * if k % 2 == 0 { 1.0 } else { -1.0 }),
            );
            pairs.push((a, near));
            pairs.push((a, near.map(|v| -v)));
            pairs.push((a, opp));
            pairs.push((a, perp));
        }
        let mut max = 0.0f64;
        let mut max_norm = 0.0f64;
        let mut worst = (Quat::IDENTITY, Quat::IDENTITY, 0.0f32);
        for (a, b) in pairs {
            let (qa, qb) = (q32(a), q32(b));
            let ts = (0..=64)
                .map(|i| i as f32 / 64.0)
                .chain((0..8).map(|_| rng.unit() as f32));
            for t in ts.collect::<Vec<_>>() {
                let r = slerp(qa, qb, t);
                let e = slerp64(q64(qa), q64(qb), f64::from(t));
                let mut err = rot_err(q64(r), e);
                if dot64(q64(qa), q64(qb)).abs() < 1e-6 {
                    // Rotations π apart: both arcs are shortest; accept either.
                    let e2 = slerp64_arc(q64(qa), q64(-qb), f64::from(t));
                    let e3 = slerp64_arc(q64(qa), q64(qb), f64::from(t));
                    err = err.min(rot_err(q64(r), e3));
                    err = err.min(rot_err(q64(r), e2));
                }
                if err > max {
                    max = err;
                    worst = (qa, qb, t);
                }
                max_norm = max_norm.max((dot64(q64(r), q64(r)).sqrt() - 1.0).abs());
            }
        }
        std::println!("worst case {worst:?}");
        std::println!("slerp max rotation error {max:e} rad, max |norm-1| {max_norm:e}");
        assert!(max < 7.0e-6, "{max:e}");
        assert!(max_norm < 2e-7, "{max_norm:e}");
    }

    #[test]
    fn slerp_endpoints_exact_and_weight_matches() {
        let mut rng = Rng::new(3);
        for _ in 0..1000 {
            let (a, b) = (q32(rng.quat()), q32(rng.quat()));
            assert_eq!(slerp(a, b, 0.0), a);
            assert_eq!(slerp(a, b, 1.0), b);
            assert_eq!(slerp(a, b, -0.5), a);
            assert_eq!(slerp(a, b, 1.5), b);
            assert_eq!(nlerp(a, b, 0.0), a);
            assert_eq!(nlerp(a, b, 1.0), b);
            let w = SlerpWeight::new(0.3);
            assert_eq!(w.apply(a, b), slerp(a, b, 0.3));
        }
    }

    #[test]
    fn nlerp_is_normalized_blend() {
        let mut rng = Rng::new(5);
        for _ in 0..1000 {
            let (a, b) = (rng.quat(), rng.quat());
            let t = rng.unit();
            let s = if dot64(a, b) < 0.0 { -1.0 } else { 1.0 };
            let e = norm64([0, 1, 2, 3].map(|i| (1.0 - t) * a[i] + s * t * b[i]));
            let r = nlerp(q32(a), q32(b), t as f32);
            assert!(rot_err(q64(r), e) < 1e-5);
        }
    }

    #[test]
    fn reflect_is_slerp_at_two() {
        let mut rng = Rng::new(11);
        for _ in 0..1000 {
            let (a, b) = (rng.quat(), rng.quat());
            let r = reflect(q32(a), q32(b));
            assert!(rot_err(q64(r), slerp64(a, b, 2.0)) < 2e-5);
            assert!(rot_err(q64(reflect(q32(a), -q32(b))), slerp64(a, b, 2.0)) < 2e-5);
        }
    }

    #[test]
    fn normalize_edge_cases() {
        assert_eq!(normalize_vec3(Vec3::ZERO), Vec3::ZERO);
        assert_eq!(normalize_vec3(Vec3::new(f32::NAN, 0.0, 0.0)), Vec3::ZERO);
        assert_eq!(
            normalize_vec3(Vec3::new(f32::INFINITY, 0.0, 0.0)),
            Vec3::ZERO
        );
        let tiny = normalize_vec3(Vec3::new(1e-30, 0.0, 1e-30));
        assert!((tiny.x - core::f32::consts::FRAC_1_SQRT_2).abs() < 1e-6);
        let huge = normalize_vec3(Vec3::new(3e30, 4e30, 0.0));
        assert!((huge.x - 0.6).abs() < 1e-6 && (huge.y - 0.8).abs() < 1e-6);
        assert_eq!(
            normalize_quat(Quat::from_xyzw(0.0, 0.0, 0.0, 0.0)),
            Quat::IDENTITY
        );
        assert_eq!(
            normalize_quat(Quat::from_xyzw(f32::NAN, 0.0, 0.0, 1.0)),
            Quat::IDENTITY
        );
        let q = normalize_quat(Quat::from_xyzw(0.0, 3.0, 0.0, 4.0));
        assert!((q.y - 0.6).abs() < 1e-7 && (q.w - 0.8).abs() < 1e-7);
        assert!((length(Vec3::new(3.0, 4.0, 12.0)) - 13.0).abs() == 0.0);
    }

    /// Rotates v by the (f64) quaternion q.
    fn rotate64(q: [f64; 4], v: [f64; 3]) -> [f64; 3] {
        let [x, y, z, w] = norm64(q);
        let u = [x, y, z];
        let cross = |a: [f64; 3], b: [f64; 3]| {
            [
                a[1] * b[2] - a[2] * b[1],
                a[2] * b[0] - a[0] * b[2],
                a[0] * b[1] - a[1] * b[0],
            ]
        };
        let t = cross(u, v).map(|c| 2.0 * c);
        let ut = cross(u, t);
        [0, 1, 2].map(|i| v[i] + w * t[i] + ut[i])
    }

    #[test]
    fn axis_angle_and_angle() {
        let mut rng = Rng::new(13);
        for _ in 0..5000 {
            let axis = [
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            ];
            let n = axis.iter().map(|v| v * v).sum::<f64>().sqrt();
            if n < 0.05 {
                continue;
            }
            let angle = rng.range(-PI as f64, PI as f64);
            let q = from_axis_angle(
                Vec3::new(axis[0] as f32, axis[1] as f32, axis[2] as f32),
                angle as f32,
            );
            let (s, c) = (0.5 * angle).sin_cos();
            let e = [axis[0] / n * s, axis[1] / n * s, axis[2] / n * s, c];
            assert!(rot_err(q64(q), e) < 2e-6);
            assert!((f64::from(quat_angle(q)) - angle.abs()).abs() < 1e-6);
        }
        assert_eq!(from_axis_angle(Vec3::ZERO, 1.0).x, 0.0);
        assert!((quat_angle(Quat::from_xyzw(1.0, 0.0, 0.0, 0.0)) - PI).abs() < 1e-6);
        assert!((quat_angle(Quat::from_xyzw(-1e-4, 0.0, 0.0, -1.0)) - 2e-4).abs() < 1e-9);
    }

    #[test]
    fn rotation_arc_maps_from_to_to() {
        let mut rng = Rng::new(17);
        let mut max = 0.0f64;
        for k in 0..20_000 {
            let f = loop {
                let v = [
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                ];
                let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
                if n > 0.1 {
                    break v.map(|x| x / n);
                }
            };
            // Random targets, plus targets within 1e-7..1e-2 rad of the opposite.
            let t = if k % 2 == 0 {
                let v = [
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                ];
                let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
                v.map(|x| x / n)
            } else {
                let eps = 10f64.powf(rng.range(-7.0, -2.0));
                let p = [
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                ];
                let v = [0, 1, 2].map(|i| -f[i] + eps * p[i]);
                let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
                v.map(|x| x / n)
            };
            let (f32v, t32v) = (
                Vec3::new(f[0] as f32, f[1] as f32, f[2] as f32),
                Vec3::new(t[0] as f32, t[1] as f32, t[2] as f32),
            );
            let q = rotation_arc(f32v, t32v);
            assert!((dot64(q64(q), q64(q)) - 1.0).abs() < 1e-6);
            let fv = [f64::from(f32v.x), f64::from(f32v.y), f64::from(f32v.z)];
            let tv = [f64::from(t32v.x), f64::from(t32v.y), f64::from(t32v.z)];
            let r = rotate64(q64(q), fv);
            let tn = tv.iter().map(|x| x * x).sum::<f64>().sqrt();
            let err = [0, 1, 2]
                .map(|i| r[i] - tv[i] / tn)
                .iter()
                .map(|x| x * x)
                .sum::<f64>()
                .sqrt();
            max = max.max(err);
        }
        std::println!("rotation_arc max |q·f − t| {max:e}");
        assert!(max < 2e-6, "{max:e}");
        let q = rotation_arc(Vec3::X, -Vec3::X);
        assert!((quat_angle(q) - PI).abs() < 1e-6);
        assert_eq!(rotation_arc(Vec3::ZERO, Vec3::X), Quat::IDENTITY);
    }

    /// Documents why micromath is not used: its errors exceed the core's bounds
    /// by orders of magnitude.
    #[test]
    fn micromath_is_too_coarse() {
        use micromath::F32Ext;
        let (mut es, mut esin, mut eat) = (0.0f64, 0.0f64, 0.0f64);
        for i in 1..200_000 {
            let x = i as f32 * 1e-3;
            let e = f64::from(x).sqrt();
            es = es.max((f64::from(F32Ext::sqrt(x)) - e).abs() / e);
            let a = (i as f32 - 100_000.0) * 6e-5;
            esin = esin.max((f64::from(F32Ext::sin(a)) - f64::from(a).sin()).abs());
            let (y, xx) = (f64::from(a).sin() as f32, f64::from(a).cos() as f32);
            eat = eat
                .max((f64::from(F32Ext::atan2(y, xx)) - f64::from(y).atan2(f64::from(xx))).abs());
        }
        std::println!("micromath: sqrt rel {es:e}, sin abs {esin:e}, atan2 abs {eat:e}");
        assert!(es > 1e-2 && esin > 1e-4 && eat > 1e-4);
    }
}
