//! The compact tracker frame (tag 7): the same information as a
//! [`TrackerFrame`], quantized, in 7 + 11·n bytes of payload.
//!
//! # Layout
//!
//! ```text
//! payload = 07                 tag 7
//!           seq16   2 bytes    low 16 bits of the host sequence number, LE
//!           time24  3 bytes    low 24 bits of time_us, LE
//!           n       1 byte     sensors (a postcard varint: 0..=16 is one byte)
//!           n × sensor, 11 bytes each
//!
//! sensor  = bytes 0..5: a 40-bit little-endian word
//!             bits  0..4    id (0..=15)
//!             bits  4..6    i: which of w, x, y, z (0..=3) was dropped
//!             bits  6..17   a ┐ the other three components in w, x, y, z
//!             bits 17..28   b │ order, each an 11-bit two's-complement
//!             bits 28..39   c ┘ integer k: component = k / (1023·√2)
//!             bit  39       0 (reserved)
//!           bytes 5..11: x, y, z, each i16 LE in steps of 2⁻¹³ m
//! ```
//!
//! A 3-sensor frame is 40 bytes of payload, 46 framed (CRC, COBS and the
//! delimiter add 6 for any payload under 254 bytes): 46 % of a 921,600-baud
//! link at 1 kHz (8N1).
//!
//! # Values
//!
//! - **Position**: `x = kx · 2⁻¹³` m (≈ 0.122 mm), `kx` in `−32768..=32767`,
//!   so the range is `[−4, 4 − 2⁻¹³]` m per axis. The encoder rounds to the
//!   nearest step (ties up): quantization error ≤ 2⁻¹⁴ m ≈ 0.061 mm per
//!   axis. A position outside the range cannot be sent compact (send the
//!   `f32` frame, tag 1, which every board also accepts).
//! - **Rotation** ("smallest three"): the unit quaternion `q = [w, x, y, z]`
//!   (or `−q`, the same rotation) is sent without its component of largest
//!   magnitude, `i`, made non-negative; the other three, each in
//!   `[−1/√2, 1/√2]`, as `k = round(v · 1023·√2)` (ties of the largest go
//!   to the first of w, x, y, z). The receiver rebuilds
//!   `q_i = √(1 − a² − b² − c²)` (unit to within 1e-6; identity comes back
//!   exact). The angle between the sent
//!   and the received rotation is at most 0.14° ([`ROTATION_ERROR_RAD`]):
//!   each sent component is off by at most half a step, `e = 1/(2·1023·√2)`,
//!   so the three by `√3·e`; the rebuilt one (at least ½) by at most `√3`
//!   times that; the quaternions are at most `2·√3·e` apart, and the angle
//!   is twice that. `tests/compact.rs` checks it on a million random
//!   rotations (worst 0.119°).
//! - **seq16 and time24** are extended by the receiver from the last
//!   accepted values: `seq = last + (seq16 − last mod 2¹⁶)` read as a signed
//!   16-bit step (so a compact frame is at most 32,767 ahead of or 32,768
//!   behind the last accepted number, then checked as any sequence number);
//!   `time_us = last_time + (time24 − last_time mod 2²⁴)` (taken as at most
//!   16.777215 s after the last accepted tracker frame; the board only uses
//!   time differences, capped at the frame period). The first of each after
//!   boot or a `Hello` is taken as is. `f32` frames set both in full.
//!
//! # Rejections
//!
//! As for any message: a payload that is not exactly `7 + 11·n` bytes with
//! `n ≤ 16` is a `decode` error; a sensor id repeated, a reserved bit set,
//! or `a² + b² + c² > 1` is a `range` error. Every decodable frame is
//! otherwise valid: positions are within ±4 m and rotations unit.
//!
//! # Worked example
//!
//! `seq 1, time_us 1000, sensor 0 at [0, 1.5, −0.25] m, identity`:
//! identity drops `w` (`i = 0`) and sends `a = b = c = 0`: word `0`, bytes
//! `00 00 00 00 00`; positions `0, 12288, −2048` steps: `00 00 00 30 00 F8`.
//!
//! ```text
//! payload  07 01 00 E8 03 00 01 00 00 00 00 00 00 00 00 30 00 F8
//! ```

use serde::{Deserialize, Serialize};

use super::{List, MAX_SENSORS, Sensor, SensorSample, TrackerFrame, WireError};
use crate::math;
use glam::{Quat, Vec3};

/// The message tag of a compact frame (its postcard variant index).
pub const COMPACT_TAG: u8 = 7;
/// Bytes per sensor.
pub const SENSOR_BYTES: usize = 11;
/// The position step, metres (2⁻¹³).
pub const POSITION_STEP_M: f32 = 1.0 / 8192.0;
/// Positions are sent within `[−POSITION_RANGE_M, POSITION_RANGE_M)` per
/// axis.
pub const POSITION_RANGE_M: f32 = 4.0;
/// The largest angle between a rotation and its compact form, radians
/// (0.14°): twice the quaternion distance `2·√3·(half a step)`, see the
/// module doc.
pub const ROTATION_ERROR_RAD: f32 = 0.14 * core::f32::consts::PI / 180.0;
/// The largest `|k|` of a rotation component.
const ROTATION_MAX: i32 = 1023;
/// `k = round(v · ROTATION_SCALE)`: 1023·√2.
const ROTATION_SCALE: f32 = 1023.0 * core::f32::consts::SQRT_2;
/// `v = k · ROTATION_STEP`.
const ROTATION_STEP: f32 = 1.0 / ROTATION_SCALE;

/// The raw compact frame, exactly as it travels (see the module doc).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CompactFrame {
    /// Low 16 bits of the sequence number, little-endian.
    pub seq16: [u8; 2],
    /// Low 24 bits of the sample time in µs, little-endian.
    pub time24: [u8; 3],
    /// The sensors, packed.
    pub sensors: List<[u8; SENSOR_BYTES], MAX_SENSORS>,
}

impl CompactFrame {
    /// The compact form of `frame`.
    ///
    /// # Errors
    /// [`WireError::Range`] for a position outside ±4 m or not finite, a
    /// rotation that is zero or not finite, or a sensor id `≥ 16`.
    pub fn pack(frame: &TrackerFrame) -> Result<Self, WireError> {
        let mut sensors = List::new();
        for s in &frame.sensors {
            sensors.push(pack_sensor(s)?)?;
        }
        let [s0, s1, ..] = frame.seq.to_le_bytes();
        let [t0, t1, t2, _] = frame.time_us.to_le_bytes();
        Ok(Self {
            seq16: [s0, s1],
            time24: [t0, t1, t2],
            sensors,
        })
    }

    /// The low 16 bits of the sequence number.
    #[must_use]
    pub fn seq16(&self) -> u16 {
        u16::from_le_bytes(self.seq16)
    }

    /// The low 24 bits of the sample time, µs.
    #[must_use]
    pub fn time24(&self) -> u32 {
        let [a, b, c] = self.time24;
        u32::from_le_bytes([a, b, c, 0])
    }
}

/// The full sequence number a compact `seq16` stands for, after `last`.
#[must_use]
pub fn extend_seq(last: Option<u32>, seq16: u16) -> u32 {
    match last {
        // The low 16 bits of the difference, read as a signed step.
        Some(last) => {
            let step = i32::from(seq16.wrapping_sub(last as u16) as i16);
            last.wrapping_add_signed(step)
        }
        None => u32::from(seq16),
    }
}

/// The full time a compact `time24` stands for, after `last`.
#[must_use]
pub fn extend_time(last: Option<u32>, time24: u32) -> u32 {
    match last {
        Some(last) => last.wrapping_add(time24.wrapping_sub(last) & 0x00FF_FFFF),
        None => time24,
    }
}

/// Packs one sensor (see the module doc).
///
/// # Errors
/// As [`CompactFrame::pack`].
pub fn pack_sensor(s: &Sensor) -> Result<[u8; SENSOR_BYTES], WireError> {
    if usize::from(s.id) >= MAX_SENSORS {
        return Err(WireError::Range);
    }
    let [w, x, y, z] = s.rotation;
    let q2 = w * w + x * x + y * y + z * z;
    if !(q2 > 0.0 && q2 < f32::INFINITY) {
        return Err(WireError::Range);
    }
    let q = math::normalize_quat(Quat::from_xyzw(x, y, z, w));
    let word = u64::from(s.id) | pack_rotation([q.w, q.x, q.y, q.z]);
    let mut out = [0u8; SENSOR_BYTES];
    let (head, tail) = out.split_at_mut(5);
    head.copy_from_slice(word.to_le_bytes().get(..5).unwrap_or(&[0; 5]));
    for (chunk, &v) in tail.chunks_exact_mut(2).zip(&s.position) {
        chunk.copy_from_slice(&quantize_position(v)?.to_le_bytes());
    }
    Ok(out)
}

/// A position in steps of 2⁻¹³ m.
fn quantize_position(v: f32) -> Result<i16, WireError> {
    let k = math::floor(v * 8192.0 + 0.5);
    // False for NaN.
    if (-32768.0..=32767.0).contains(&k) {
        Ok(k as i16)
    } else {
        Err(WireError::Range)
    }
}

/// The rotation bits (4..39) of a unit quaternion `[w, x, y, z]`: the
/// component of largest magnitude (the first on ties) dropped.
fn pack_rotation(q: [f32; 4]) -> u64 {
    rotation_bits(q, largest(q))
}

/// The index of the component of largest magnitude (the first on ties).
fn largest(q: [f32; 4]) -> usize {
    let mut best = 0;
    let mut best_mag = -1.0;
    for (i, v) in q.iter().enumerate() {
        if math::abs(*v) > best_mag {
            best = i;
            best_mag = math::abs(*v);
        }
    }
    best
}

/// The rotation bits of `q` with component `i` dropped.
fn rotation_bits(q: [f32; 4], i: usize) -> u64 {
    let sign = if q.get(i).copied().unwrap_or(0.0) < 0.0 {
        -1.0
    } else {
        1.0
    };
    let mut bits = (i as u64 & 3) << 4;
    let mut shift = 6;
    for (_, &v) in q.iter().enumerate().filter(|&(j, _)| j != i) {
        let k = math::floor(v * sign * ROTATION_SCALE + 0.5) as i32;
        let k = k.clamp(-ROTATION_MAX, ROTATION_MAX);
        bits |= (u64::from(k as u32) & 0x7FF) << shift;
        shift += 11;
    }
    bits
}

/// The unit quaternion of rotation bits (4..40 of the sensor word).
fn unpack_rotation(word: u64) -> Result<Quat, WireError> {
    if word & (1 << 39) != 0 {
        return Err(WireError::Range);
    }
    let component = |shift: u32| {
        // Sign-extend the 11-bit field.
        let k = (((word >> shift) as u32 & 0x7FF) << 21) as i32 >> 21;
        k as f32 * ROTATION_STEP
    };
    let (a, b, c) = (component(6), component(17), component(28));
    let rest = 1.0 - (a * a + b * b + c * c);
    if rest < 0.0 {
        return Err(WireError::Range);
    }
    let d = math::sqrt(rest);
    let [w, x, y, z] = match (word >> 4) & 3 {
        0 => [d, a, b, c],
        1 => [a, d, b, c],
        2 => [a, b, d, c],
        _ => [a, b, c, d],
    };
    // Unit by construction (to within rounding: |1 − |q|| < 1e-6).
    Ok(Quat::from_xyzw(x, y, z, w))
}

/// Unpacks one sensor (see the module doc).
///
/// # Errors
/// [`WireError::Range`] for a reserved bit set or `a² + b² + c² > 1`.
pub fn unpack_sensor(bytes: &[u8; SENSOR_BYTES]) -> Result<SensorSample, WireError> {
    let mut out = SensorSample::default();
    unpack_sensor_into(bytes, &mut out)?;
    Ok(out)
}

/// [`unpack_sensor`] into `out`, in place.
///
/// # Errors
/// As [`unpack_sensor`].
pub fn unpack_sensor_into(bytes: &[u8], out: &mut SensorSample) -> Result<(), WireError> {
    let &[b0, b1, b2, b3, b4, x0, x1, y0, y1, z0, z1] = bytes else {
        return Err(WireError::Decode);
    };
    let word = u64::from_le_bytes([b0, b1, b2, b3, b4, 0, 0, 0]);
    let rotation = unpack_rotation(word)?;
    let step = |lo, hi| f32::from(i16::from_le_bytes([lo, hi])) * POSITION_STEP_M;
    let position = Vec3::new(step(x0, x1), step(y0, y1), step(z0, z1));
    out.set(b0 & 0x0F, position, rotation);
    Ok(())
}

/// A compact frame's payload after the tag, read in place (the receiver's
/// path: no copy of the frame).
#[derive(Clone, Copy, Debug)]
pub struct CompactView<'a> {
    seq16: u16,
    time24: u32,
    sensors: &'a [u8],
}

impl<'a> CompactView<'a> {
    /// Checks the layout: 6 bytes of header (`seq16`, `time24`, `n`) and
    /// exactly `n ≤ 16` sensors of 11 bytes.
    ///
    /// # Errors
    /// [`WireError::Decode`] for any other length or `n > 16` (as postcard
    /// decoding the [`CompactFrame`] would).
    pub fn new(body: &'a [u8]) -> Result<Self, WireError> {
        let Some((&[s0, s1, t0, t1, t2, n], sensors)) = body.split_first_chunk::<6>() else {
            return Err(WireError::Decode);
        };
        let n = usize::from(n);
        if n > MAX_SENSORS || sensors.len() != n * SENSOR_BYTES {
            return Err(WireError::Decode);
        }
        Ok(Self {
            seq16: u16::from_le_bytes([s0, s1]),
            time24: u32::from_le_bytes([t0, t1, t2, 0]),
            sensors,
        })
    }

    /// The low 16 bits of the sequence number.
    #[must_use]
    pub fn seq16(&self) -> u16 {
        self.seq16
    }

    /// The low 24 bits of the sample time, µs.
    #[must_use]
    pub fn time24(&self) -> u32 {
        self.time24
    }

    /// The packed sensors, 11 bytes each.
    pub fn sensors(&self) -> core::slice::ChunksExact<'a, u8> {
        self.sensors.chunks_exact(SENSOR_BYTES)
    }
}
