//! Quantization of one segment sample: position as 3 × `i16` with a per-table
//! scale, rotation as "smallest three" in 48 bits. 12 bytes per sample.
//!
//! The writer (host) and the reader (firmware) share this one implementation.
//! See the [module docs](super) for the byte layout and the error bound.

use core::f32::consts::FRAC_1_SQRT_2;

use glam::{Quat, Vec3};

use crate::math;

/// Bytes of one quantized segment sample: 3 × `i16` position + 6-byte rotation.
pub const SAMPLE_LEN: usize = 12;

/// Bytes of one quantized rotation.
pub const ROTATION_LEN: usize = 6;

/// Largest position code magnitude (`i16::MIN` is never written).
pub const POSITION_CODE_MAX: i16 = 32_767;

/// Largest `max |coordinate|` a table may hold, in metres. With it the position
/// scale is at most `32 / 32767` m ≈ 0.977 mm per LSB, so the position error
/// bound ([`position_bound`]) stays below 0.5 mm.
pub const MAX_POSITION: f32 = 32.0;

/// Smallest range used to choose a scale (a table whose positions are all
/// zero still gets a finite, non-zero scale), in metres.
pub const MIN_POSITION_RANGE: f32 = 1.0e-3;

/// Position error bound as a multiple of the scale: `0.5` from rounding to the
/// nearest code, plus `0.006` for the `f32` rounding of `p / scale`, of the
/// `+ 0.5` rounding step and of `code · scale` (each ≤ 32767 · 2⁻²⁴ ≈ 0.002).
pub const POSITION_BOUND_PER_SCALE: f32 = 0.51;

/// Stated rotation error bound of [`quantize_rotation`] then
/// [`dequantize_rotation`]: the rotation angle between the input and the
/// decoded quaternion, in radians (1.75e-4 rad ≈ 0.01°).
///
/// Derivation: the three stored components `s` lie in `[−1/√2, 1/√2]` and are
/// coded with step `Δ = (1/√2) / 16383 ≈ 4.316e-5`, so each is off by at most
/// `Δ/2`: `|e| ≤ √3·Δ/2`. The rebuilt largest component `L = √(1 − |s|²)`
/// moves by `−(s·e)/L`, at most `3·Δ/2` because every `|sᵢ| ≤ L`. That change
/// is orthogonal to the quaternion to first order, so the quaternion turns by
/// at most `√(3 + 9)·Δ/2 = √3·Δ` and the rotation by twice that,
/// `2√3·Δ = 1.495e-4` rad (0.00857°), reached when `s = (L, L, L)` (all four
/// components ½) with every rounding error at its maximum and the same sign.
/// `tests/table.rs` measures exactly that maximum against an `f64` reference;
/// the stated bound leaves 17 % for `f32` rounding.
pub const ROTATION_BOUND: f32 = 1.75e-4;

/// Code of the component value 0 (the middle of the 15-bit range).
const ROT_MID: i32 = 16_383;
/// Largest code written (the value `+1/√2`); code 32767 is never written.
const ROT_CODE_MAX: i32 = 32_766;
/// Codes per unit of component value: `16383 / (1/√2)`.
const ROT_ENC: f32 = ROT_MID as f32 / FRAC_1_SQRT_2;
/// Component value per code: `(1/√2) / 16383`.
const ROT_DEC: f32 = FRAC_1_SQRT_2 / ROT_MID as f32;
/// Mask of one 15-bit component field.
const ROT_FIELD: u32 = 0x7FFF;

/// The position scale (metres per LSB) for a table whose largest absolute
/// coordinate is `max_abs`: the smallest `f32` scale with
/// `max_abs / scale ≤ 32767`, so no position is clamped. `None` when
/// `max_abs` exceeds [`MAX_POSITION`] or is not a number.
#[must_use]
pub fn position_scale(max_abs: f32) -> Option<f32> {
    if max_abs.is_nan() || max_abs > MAX_POSITION {
        return None;
    }
    let range = if max_abs > MIN_POSITION_RANGE {
        max_abs
    } else {
        MIN_POSITION_RANGE
    };
    let code_max = f32::from(POSITION_CODE_MAX);
    let scale = range / code_max;
    Some(if range / scale > code_max {
        scale.next_up()
    } else {
        scale
    })
}

/// The stated position error bound (metres) of a table with this scale.
#[inline]
#[must_use]
pub fn position_bound(scale: f32) -> f32 {
    scale * POSITION_BOUND_PER_SCALE
}

/// Quantizes one coordinate: `round(v / scale)` (half away from zero), clamped
/// to `±32767`. NaN gives 0.
#[inline]
#[must_use]
fn quantize_coordinate(v: f32, scale: f32) -> i16 {
    let t = v / scale;
    let r = if t >= 0.0 {
        (t + 0.5) as i32
    } else {
        (t - 0.5) as i32
    };
    let max = i32::from(POSITION_CODE_MAX);
    // Clamped to ±32767, so the narrowing is exact.
    r.clamp(-max, max) as i16
}

/// Quantizes a position to 3 × `i16` codes with `scale` metres per LSB.
#[inline]
#[must_use]
pub fn quantize_position(p: Vec3, scale: f32) -> [i16; 3] {
    [
        quantize_coordinate(p.x, scale),
        quantize_coordinate(p.y, scale),
        quantize_coordinate(p.z, scale),
    ]
}

/// Decodes 3 × `i16` position codes: `code · scale` per axis.
#[inline]
#[must_use]
pub fn dequantize_position(codes: [i16; 3], scale: f32) -> Vec3 {
    let [x, y, z] = codes;
    Vec3::new(
        f32::from(x) * scale,
        f32::from(y) * scale,
        f32::from(z) * scale,
    )
}

/// Index (in `[w, x, y, z]` order) and value of the component of largest
/// magnitude; ties go to the lowest index.
#[inline]
fn largest(c: [f32; 4]) -> (usize, f32) {
    let mut best = (0, c[0]);
    for (i, v) in c.into_iter().enumerate().skip(1) {
        if math::abs(v) > math::abs(best.1) {
            best = (i, v);
        }
    }
    best
}

/// Code of one small component `v ∈ [−1/√2, 1/√2]`: `round(v·ENC) + 16383`,
/// clamped to `[0, 32766]`.
#[inline]
fn encode_component(v: f32) -> u32 {
    // `t ≥ 0` over the valid range, so truncation is `floor`; below, `as`
    // saturates and the clamp catches it. NaN gives 0.
    let t = v * ROT_ENC + (ROT_MID as f32 + 0.5);
    // Clamped to [0, 32766], so the widening is exact.
    (t as i32).clamp(0, ROT_CODE_MAX) as u32
}

/// Value of one 15-bit component code (the low 15 bits of `field`).
#[inline(always)]
fn decode_component(field: u32) -> f32 {
    // The field is masked to 15 bits, so it fits an i32 exactly.
    ((field & ROT_FIELD) as i32 - ROT_MID) as f32 * ROT_DEC
}

/// Quantizes a rotation to "smallest three" in 6 bytes.
///
/// `q` is normalized first (identity for a zero or non-finite `q`). The
/// component of largest magnitude (in `[w, x, y, z]` order, lowest index on
/// ties) is made positive by negating the whole quaternion (same rotation) and
/// dropped; its index goes in bits 0–1, the other three components (in
/// `[w, x, y, z]` order) in bits 2–16, 17–31 and 32–46 of a little-endian
/// 48-bit word, coded as `round(v · 16383·√2) + 16383`. Bit 47 is zero.
#[must_use]
pub fn quantize_rotation(q: Quat) -> [u8; ROTATION_LEN] {
    let q = math::normalize_quat(q);
    let c = [q.w, q.x, q.y, q.z];
    let (index, big) = largest(c);
    let sign = if big < 0.0 { -1.0 } else { 1.0 };
    let mut word = index as u64;
    let mut shift = 2;
    for (i, v) in c.into_iter().enumerate() {
        if i != index {
            word |= u64::from(encode_component(v * sign)) << shift;
            shift += 15;
        }
    }
    let [b0, b1, b2, b3, b4, b5, _, _] = word.to_le_bytes();
    [b0, b1, b2, b3, b4, b5]
}

/// Decodes a "smallest three" rotation: the three stored components, the
/// dropped one rebuilt as `√(1 − a² − b² − c²)` (as `x · rsqrt(x)`), then
/// renormalized by one Newton step of `rsqrt` from 1 (exact for a norm of
/// 1); codes no writer produces (`a² + b² + c² ≥ 1`) take
/// [`math::normalize_quat`] instead. Bit 47 is ignored. Every bit pattern
/// decodes to a unit quaternion.
#[must_use]
pub fn dequantize_rotation(bytes: &[u8; ROTATION_LEN]) -> Quat {
    let [b0, b1, b2, b3, b4, b5] = *bytes;
    // The 48-bit word as two 32-bit halves (cheaper than u64 shifts on the M4F).
    let lo = u32::from_le_bytes([b0, b1, b2, b3]);
    let hi = u32::from(u16::from_le_bytes([b4, b5]));
    rotation_from_words(lo, hi)
}

/// [`dequantize_rotation`] of the 48-bit word `lo | hi << 32`.
#[inline(always)]
fn rotation_from_words(lo: u32, hi: u32) -> Quat {
    let a = decode_component(lo >> 2);
    let b = decode_component(lo >> 17);
    let c = decode_component(hi);
    let small = a * a + b * b + c * c;
    let rest = 1.0 - small;
    // One unsigned compare for `f32::MIN_POSITIVE ≤ rest < 1` (both
    // constants are Thumb-2 immediates).
    let fast = rest.to_bits().wrapping_sub(f32::MIN_POSITIVE.to_bits())
        < 1.0f32.to_bits() - f32::MIN_POSITIVE.to_bits();
    let (big, f) = if fast {
        // `rest · rsqrt(rest)` (≤ 2 ulp) instead of the correctly rounded
        // `math::sqrt`, whose `f64` rounding check is soft-float on the M4F;
        // the renormalization absorbs the difference.
        let big = rest * math::rsqrt_normal(rest);
        // `|q|² = |s|² + big²` is 1 to a few ulp here, so one Newton step of
        // `rsqrt` from 1, `(3 − |q|²)/2`, renormalizes to ~1e-13.
        (big, 1.5 - 0.5 * (small + big * big))
    } else if rest >= 1.0 {
        // `small` rounds away (an axis-aligned rotation, such as a rest
        // pose's identity): the dropped component is 1 and the stored ones
        // are kept as they are (`× 1` is exact), without normalization.
        (1.0, 1.0)
    } else {
        return rotation_edge(lo & 3, [a, b, c], rest);
    };
    place(lo & 3, big * f, [a * f, b * f, c * f])
}

/// The quaternion with the dropped component `big` at `index` (in
/// `[w, x, y, z]` order) and the stored ones in order around it.
#[inline(always)]
fn place(index: u32, big: f32, [a, b, c]: [f32; 3]) -> Quat {
    let [w, x, y, z] = match index {
        0 => [big, a, b, c],
        1 => [a, big, b, c],
        2 => [a, b, big, c],
        _ => [a, b, c, big],
    };
    Quat::from_xyzw(x, y, z, w)
}

/// The codes no writer produces (`rest < f32::MIN_POSITIVE`), fully
/// normalized.
#[cold]
fn rotation_edge(index: u32, s: [f32; 3], rest: f32) -> Quat {
    let big = if rest > 0.0 {
        rest * math::rsqrt(rest)
    } else {
        0.0
    };
    math::normalize_quat(place(index, big, s))
}

/// Quantizes one segment sample to its 12 bytes: position codes x, y, z as
/// `i16` LE (bytes 0–5), then the rotation (bytes 6–11).
#[must_use]
pub fn encode_sample(position: Vec3, rotation: Quat, scale: f32) -> [u8; SAMPLE_LEN] {
    let [x, y, z] = quantize_position(position, scale);
    let [x0, x1] = x.to_le_bytes();
    let [y0, y1] = y.to_le_bytes();
    let [z0, z1] = z.to_le_bytes();
    let [r0, r1, r2, r3, r4, r5] = quantize_rotation(rotation);
    [x0, x1, y0, y1, z0, z1, r0, r1, r2, r3, r4, r5]
}

/// Decodes one 12-byte segment sample (see [`encode_sample`]).
#[inline(always)]
#[must_use]
pub fn decode_sample(bytes: &[u8; SAMPLE_LEN], scale: f32) -> (Vec3, Quat) {
    // The sample as three little-endian words (aligned in a blob): x | y << 16,
    // z | rotation bits 0–15 << 16, rotation bits 16–47.
    let [w0 @ .., _, _, _, _, _, _, _, _] = bytes;
    let [_, _, _, _, w1 @ .., _, _, _, _] = bytes;
    let [_, _, _, _, _, _, _, _, w2 @ ..] = bytes;
    // Written out, not `[..].map(..)`: at opt-level "s" the array map is an
    // out-of-line loop on the firmware's hottest path.
    let (w0, w1, w2) = (
        u32::from_le_bytes(*w0),
        u32::from_le_bytes(*w1),
        u32::from_le_bytes(*w2),
    );
    // `as i16` keeps the low 16 bits: the two's-complement code.
    let codes = [w0 as i16, (w0 >> 16) as i16, w1 as i16];
    (
        dequantize_position(codes, scale),
        rotation_from_words((w1 >> 16) | (w2 << 16), w2 >> 16),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hand-derived from the documented layout: the word
    /// `index | a << 2 | b << 17 | c << 32`, little-endian, 6 bytes.
    #[test]
    fn rotation_codes_hand_derived() {
        // Identity: w dropped (index 0), x, y, z = 0 → code 16383 = 0x3FFF each.
        // 0xFFFC | 0x7FFE_0000 | 0x3FFF_0000_0000 = 0x3FFF_7FFE_FFFC.
        let identity = [0xFC, 0xFF, 0xFE, 0x7F, 0xFF, 0x3F];
        assert_eq!(quantize_rotation(Quat::IDENTITY), identity);
        // −identity is the same rotation: made positive, same code.
        assert_eq!(
            quantize_rotation(Quat::from_xyzw(0.0, 0.0, 0.0, -1.0)),
            identity
        );
        // 180° about X: x dropped (index 1), w, y, z = 0.
        assert_eq!(
            quantize_rotation(Quat::from_xyzw(1.0, 0.0, 0.0, 0.0)),
            [0xFD, 0xFF, 0xFE, 0x7F, 0xFF, 0x3F]
        );
        // 180° about Z, negative: index 3, rest 0.
        assert_eq!(
            quantize_rotation(Quat::from_xyzw(0.0, 0.0, -1.0, 0.0)),
            [0xFF, 0xFF, 0xFE, 0x7F, 0xFF, 0x3F]
        );
        // 90° about Y: w = y = 1/√2, tie → w dropped; x = 0 → 16383,
        // y = 1/√2 → 32766, z = 0 → 16383:
        // 0xFFFC | 32766 << 17 = 0xFFFC_0000 | 0x3FFF_0000_0000.
        let h = FRAC_1_SQRT_2;
        assert_eq!(
            quantize_rotation(Quat::from_xyzw(0.0, h, 0.0, h)),
            [0xFC, 0xFF, 0xFC, 0xFF, 0xFF, 0x3F]
        );
        // −90° about Y: w = 1/√2, y = −1/√2 → code 0: 0xFFFC | 0 | 0x3FFF_0000_0000.
        assert_eq!(
            quantize_rotation(Quat::from_xyzw(0.0, -h, 0.0, h)),
            [0xFC, 0xFF, 0x00, 0x00, 0xFF, 0x3F]
        );
    }

    #[test]
    fn rotation_decodes_hand_derived() {
        let q = dequantize_rotation(&[0xFD, 0xFF, 0xFE, 0x7F, 0xFF, 0x3F]);
        assert_eq!((q.w, q.x, q.y, q.z), (0.0, 1.0, 0.0, 0.0));
        let q = dequantize_rotation(&[0xFC, 0xFF, 0xFE, 0x7F, 0xFF, 0x3F]);
        assert_eq!(q, Quat::IDENTITY);
        // Bit 47 is ignored.
        let q = dequantize_rotation(&[0xFC, 0xFF, 0xFE, 0x7F, 0xFF, 0xBF]);
        assert_eq!(q, Quat::IDENTITY);
    }

    #[test]
    fn position_codes_hand_derived() {
        let s = 0.001;
        assert_eq!(
            quantize_position(Vec3::new(0.0, 0.0015, -0.0015), s),
            [0, 2, -2]
        );
        assert_eq!(
            quantize_position(Vec3::new(0.0014, -0.0026, 32.767), s),
            [1, -3, 32_767]
        );
        // Beyond the range: clamped, never i16::MIN; NaN gives 0.
        assert_eq!(
            quantize_position(Vec3::new(-1e9, 1e9, f32::NAN), s),
            [-32_767, 32_767, 0]
        );
        assert_eq!(
            dequantize_position([-32_767, 2, 0], 0.5),
            Vec3::new(-16_383.5, 1.0, 0.0)
        );
    }

    #[test]
    fn scale_never_clips_the_largest_coordinate() {
        for i in 0..=10_000 {
            let max = MAX_POSITION * i as f32 / 10_000.0;
            let s = position_scale(max).unwrap();
            assert!(max / s <= 32_767.0, "{max}");
            assert!(s <= MAX_POSITION / 32_767.0 * (1.0 + 2.0 * f32::EPSILON));
            assert!(s > 0.0);
            // ±max is not clipped: it decodes within the bound (f64 check).
            for v in [max, -max] {
                let back = dequantize_position(quantize_position(Vec3::splat(v), s), s);
                let err = (f64::from(back.x) - f64::from(v)).abs();
                assert!(err <= f64::from(position_bound(s)), "{v}: {err}");
            }
        }
        assert_eq!(position_scale(MAX_POSITION * 1.0001), None);
        assert_eq!(position_scale(f32::NAN), None);
        assert_eq!(position_scale(f32::INFINITY), None);
    }

    /// Every 48-bit pattern (sampled) decodes to a unit quaternion.
    #[test]
    fn every_rotation_code_decodes_to_unit() {
        let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
        for _ in 0..200_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let [b0, b1, b2, b3, b4, b5, _, _] = x.to_le_bytes();
            let q = dequantize_rotation(&[b0, b1, b2, b3, b4, b5]);
            let n = math::quat_dot(q, q);
            assert!((n - 1.0).abs() < 1e-6, "{x:x} {q:?}");
        }
    }

    /// The decoder as it was before axis-aligned codes (`rest = 1`) took
    /// the inline path: the change must give the same bits.
    fn previous_rotation_from_words(lo: u32, hi: u32) -> Quat {
        let a = decode_component(lo >> 2);
        let b = decode_component(lo >> 17);
        let c = decode_component(hi);
        let small = a * a + b * b + c * c;
        let rest = 1.0 - small;
        if !(f32::MIN_POSITIVE..1.0).contains(&rest) {
            if rest >= 1.0 {
                return place(lo & 3, 1.0, [a, b, c]);
            }
            return rotation_edge(lo & 3, [a, b, c], rest);
        }
        let big = rest * math::rsqrt_normal(rest);
        let f = 1.5 - 0.5 * (small + big * big);
        place(lo & 3, big * f, [a * f, b * f, c * f])
    }

    #[test]
    fn decode_matches_the_previous_formula() {
        let bits = |q: Quat| [q.x, q.y, q.z, q.w].map(f32::to_bits);
        let check = |lo: u32, hi: u32| {
            let new = rotation_from_words(lo, hi & 0x7FFF);
            let old = previous_rotation_from_words(lo, hi & 0x7FFF);
            assert_eq!(bits(new), bits(old), "{hi:x}{lo:08x}");
        };
        // Every code whose stored components are all within 2 steps of 0
        // (where `rest` rounds to 1), for each dropped index.
        let near = |k: i32| (ROT_MID + k) as u32;
        for i in 0..4 {
            for (a, b, c) in
                (-2..=2).flat_map(|a| (-2..=2).flat_map(move |b| (-2..=2).map(move |c| (a, b, c))))
            {
                check(i | near(a) << 2 | near(b) << 17, near(c));
            }
        }
        // And a sample of every pattern.
        let mut x: u64 = 0x2545_F491_4F6C_DD1D;
        for _ in 0..1_000_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            check(x as u32, (x >> 32) as u32);
        }
    }

    #[test]
    fn sample_layout() {
        let bytes = encode_sample(Vec3::new(0.001, -0.002, 0.0), Quat::IDENTITY, 0.001);
        assert_eq!(
            bytes,
            [1, 0, 0xFE, 0xFF, 0, 0, 0xFC, 0xFF, 0xFE, 0x7F, 0xFF, 0x3F]
        );
        let (p, q) = decode_sample(&bytes, 0.001);
        assert_eq!((p, q), (Vec3::new(0.001, -0.002, 0.0), Quat::IDENTITY));
    }
}
