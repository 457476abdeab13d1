//! The `f32` tracker frame (tag 1) read in place: the receiver's path for
//! full-precision frames, with no [`Message`](super::Message) built.
//!
//! Decoding a [`TrackerFrame`] through postcard fills a half-kilobyte
//! `Message` (its sensor list at capacity), reads every float through
//! serde, and moves the result before it is validated into the receiver's
//! frame. [`TrackerView`] checks the payload's layout once and then reads
//! each sensor's 29 bytes straight into the validated frame, so a frame
//! costs in proportion to its sensors, as a compact frame does.
//!
//! ## Layout (after the tag byte, [`TRACKER_TAG`])
//!
//! ```text
//! seq      varint u32     1..=5 bytes
//! time_us  varint u32     1..=5 bytes
//! n        varint usize   sensors, 0..=16
//! sensors  n × 29 bytes   id: u8, position: 3 × f32, rotation: 4 × f32 ([w, x, y, z])
//! ```
//!
//! Floats are IEEE-754 little-endian. The payload must end with the last
//! sensor. The contract is postcard's: a payload is accepted exactly when
//! [`super::decode_payload`] accepts it, over-long varints included (at most
//! 5 bytes for a `u32`, as many as a `usize` of the target takes for `n`, and
//! no bits beyond the type's in the last byte), and gives the same
//! [`TrackerFrame`] (`tests` below check both against postcard).

use super::WireError;
use super::message::{MAX_SENSORS, Sensor};

/// The wire tag of [`TrackerFrame`](super::TrackerFrame).
pub const TRACKER_TAG: u8 = 1;

/// Bytes of one sensor on the wire: the id and seven `f32`s.
pub const SENSOR_WIRE_BYTES: usize = 29;

/// A tracker frame's payload after the tag, its layout checked (see the
/// module doc).
#[derive(Clone, Copy, Debug)]
pub struct TrackerView<'a> {
    seq: u32,
    time_us: u32,
    sensors: &'a [u8],
}

impl<'a> TrackerView<'a> {
    /// Checks the layout.
    ///
    /// # Errors
    /// [`WireError::Decode`] wherever postcard decoding the
    /// [`TrackerFrame`](super::TrackerFrame) would fail: a bad or truncated
    /// varint, more than [`MAX_SENSORS`] sensors, a truncated sensor or
    /// bytes left over.
    pub fn new(body: &'a [u8]) -> Result<Self, WireError> {
        let (seq, rest) = varint(body, u32::BITS)?;
        let (time_us, rest) = varint(rest, u32::BITS)?;
        let (n, sensors) = varint(rest, usize::BITS)?;
        let n = usize::try_from(n).map_err(|_| WireError::Decode)?;
        if n > MAX_SENSORS || Some(sensors.len()) != n.checked_mul(SENSOR_WIRE_BYTES) {
            return Err(WireError::Decode);
        }
        let seq = u32::try_from(seq).map_err(|_| WireError::Decode)?;
        let time_us = u32::try_from(time_us).map_err(|_| WireError::Decode)?;
        Ok(Self {
            seq,
            time_us,
            sensors,
        })
    }

    /// The sequence number.
    #[must_use]
    pub fn seq(&self) -> u32 {
        self.seq
    }

    /// The sample time, µs.
    #[must_use]
    pub fn time_us(&self) -> u32 {
        self.time_us
    }

    /// The sensors, as decoded (not yet validated).
    pub fn sensors(&self) -> impl Iterator<Item = Sensor> + 'a {
        self.sensors
            .chunks_exact(SENSOR_WIRE_BYTES)
            .map(sensor_from_bytes)
    }
}

/// One sensor from its 29 wire bytes (`chunks_exact` gives exactly 29).
#[inline]
fn sensor_from_bytes(bytes: &[u8]) -> Sensor {
    let (&id, floats) = bytes.split_first().unwrap_or((&0, &[]));
    let f = |i: usize| {
        let word = floats
            .get(4 * i..4 * i + 4)
            .and_then(|w| <[u8; 4]>::try_from(w).ok())
            .unwrap_or_default();
        f32::from_le_bytes(word)
    };
    Sensor {
        id,
        position: [f(0), f(1), f(2)],
        rotation: [f(3), f(4), f(5), f(6)],
    }
}

/// An unsigned LEB128 varint of a `bits`-bit type, as postcard reads it:
/// at most `⌈bits / 7⌉` bytes, and the last of that many carries no bits
/// beyond the type's. Returns the value and the bytes after it.
fn varint(bytes: &[u8], bits: u32) -> Result<(u64, &[u8]), WireError> {
    let max = bits.div_ceil(7);
    let last_bits = bits - 7 * (max - 1);
    let mut value = 0u64;
    let mut rest = bytes;
    for i in 0..max {
        let (&b, tail) = rest.split_first().ok_or(WireError::Decode)?;
        rest = tail;
        value |= u64::from(b & 0x7F) << (7 * i);
        if b & 0x80 == 0 {
            if i == max - 1 && u32::from(b) >> last_bits != 0 {
                return Err(WireError::Decode);
            }
            return Ok((value, rest));
        }
    }
    Err(WireError::Decode)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::message::{Message, TrackerFrame};
    use crate::wire::{List, decode_payload, encode_payload};

    /// The view's frame, or its error, as a `TrackerFrame`.
    fn via_view(payload: &[u8]) -> Result<TrackerFrame, WireError> {
        let (&tag, body) = payload.split_first().ok_or(WireError::Decode)?;
        assert_eq!(tag, TRACKER_TAG);
        let view = TrackerView::new(body)?;
        let mut sensors = List::new();
        for s in view.sensors() {
            sensors.push(s).map_err(|_| WireError::Decode)?;
        }
        Ok(TrackerFrame {
            seq: view.seq(),
            time_us: view.time_us(),
            sensors,
        })
    }

    /// postcard's frame, or its error (the reference).
    fn via_postcard(payload: &[u8]) -> Result<TrackerFrame, WireError> {
        match decode_payload(payload)? {
            Message::TrackerFrame(f) => Ok(f),
            _ => Err(WireError::Decode),
        }
    }

    /// Both decoders agree, bit for bit on the floats.
    fn agree(payload: &[u8]) {
        let (a, b) = (via_view(payload), via_postcard(payload));
        match (&a, &b) {
            (Ok(x), Ok(y)) => {
                assert_eq!((x.seq, x.time_us), (y.seq, y.time_us), "{payload:02X?}");
                assert_eq!(x.sensors.len(), y.sensors.len(), "{payload:02X?}");
                for (s, t) in x.sensors.iter().zip(&y.sensors) {
                    assert_eq!(s.id, t.id);
                    let bits = |v: &[f32], w: &[f32]| {
                        v.iter().zip(w).all(|(a, b)| a.to_bits() == b.to_bits())
                    };
                    assert!(bits(&s.position, &t.position), "{payload:02X?}");
                    assert!(bits(&s.rotation, &t.rotation), "{payload:02X?}");
                }
            }
            _ => assert_eq!(a.is_ok(), b.is_ok(), "{payload:02X?}: {a:?} vs {b:?}"),
        }
    }

    /// A payload under construction (the core has no `Vec`).
    struct Buf {
        bytes: [u8; 600],
        len: usize,
    }

    impl Buf {
        fn new() -> Self {
            Self {
                bytes: [0; 600],
                len: 0,
            }
        }
        fn push(&mut self, b: u8) {
            self.bytes[self.len] = b;
            self.len += 1;
        }
        fn extend_from_slice(&mut self, bytes: &[u8]) {
            bytes.iter().for_each(|&b| self.push(b));
        }
        fn as_slice(&self) -> &[u8] {
            &self.bytes[..self.len]
        }
    }

    fn frame(seq: u32, time_us: u32, n: u8) -> TrackerFrame {
        let mut sensors = List::new();
        for i in 0..n {
            let x = f32::from(i);
            sensors
                .push(Sensor {
                    id: i,
                    position: [x * 0.25, -1.5, f32::NAN],
                    rotation: [1.0, 0.0, -0.0, f32::INFINITY],
                })
                .unwrap();
        }
        TrackerFrame {
            seq,
            time_us,
            sensors,
        }
    }

    #[test]
    fn reads_a_frame_with_exact_bytes() {
        // seq 300 = AC 02, time 1 = 01, n = 1, id 7, then 1.0 and zeros.
        let mut payload = Buf::new();
        payload.extend_from_slice(&[0x01, 0xAC, 0x02, 0x01, 0x01, 0x07]);
        payload.extend_from_slice(&1.0f32.to_le_bytes());
        payload.extend_from_slice(&[0; 24]);
        let f = via_view(payload.as_slice()).unwrap();
        assert_eq!((f.seq, f.time_us, f.sensors.len()), (300, 1, 1));
        assert_eq!(f.sensors.as_slice()[0].id, 7);
        assert_eq!(f.sensors.as_slice()[0].position, [1.0, 0.0, 0.0]);
        assert_eq!(f.sensors.as_slice()[0].rotation, [0.0; 4]);
        agree(payload.as_slice());
    }

    #[test]
    fn agrees_with_postcard_on_encoded_frames() {
        let mut buf = [0u8; 512];
        for (seq, time) in [(0, 0), (127, 128), (u32::MAX, 16_383), (1 << 28, 1 << 21)] {
            for n in [0, 1, 3, 16] {
                let msg = Message::TrackerFrame(frame(seq, time, n));
                let payload = encode_payload(&msg, &mut buf).unwrap();
                agree(payload);
                let f = via_view(payload).unwrap();
                assert_eq!(
                    (f.seq, f.time_us, f.sensors.len()),
                    (seq, time, usize::from(n))
                );
            }
        }
    }

    #[test]
    fn agrees_with_postcard_on_every_cut_and_extension() {
        let mut buf = [0u8; 512];
        let msg = Message::TrackerFrame(frame(1000, 70_000, 2));
        let payload = encode_payload(&msg, &mut buf).unwrap();
        for cut in 1..payload.len() {
            agree(&payload[..cut]);
        }
        let mut longer = Buf::new();
        longer.extend_from_slice(payload);
        longer.push(0);
        agree(longer.as_slice());
    }

    #[test]
    fn agrees_with_postcard_on_odd_varints() {
        // Over-long (padded) varints, bits beyond the type, too many bytes,
        // and a sensor count over capacity, in each of the three varints.
        let forms: [&[u8]; 9] = [
            &[0x80, 0x00],
            &[0x81, 0x80, 0x80, 0x80, 0x00],
            &[0xFF, 0xFF, 0xFF, 0xFF, 0x0F],
            &[0xFF, 0xFF, 0xFF, 0xFF, 0x1F],
            &[0x80, 0x80, 0x80, 0x80, 0x80, 0x00],
            &[0x81, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x00],
            &[0x81, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x02],
            &[0x11],
            &[0x80],
        ];
        for (slot, form, sensors) in (0..3).flat_map(|slot| {
            forms
                .iter()
                .flat_map(move |form| (0..2).map(move |n| (slot, form, n)))
        }) {
            let mut payload = Buf::new();
            payload.push(TRACKER_TAG);
            for k in 0..3 {
                if k == slot {
                    payload.extend_from_slice(form);
                } else {
                    payload.push(u8::from(k == 2));
                }
            }
            for _ in 0..sensors {
                payload.extend_from_slice(&[0x05; 29]);
            }
            agree(payload.as_slice());
        }
    }

    #[test]
    fn agrees_with_postcard_on_random_bytes() {
        let mut h = 0x2545_F491u32;
        let mut next = move || {
            h ^= h << 13;
            h ^= h >> 17;
            h ^= h << 5;
            h
        };
        for _ in 0..20_000 {
            let len = (next() % 80) as usize;
            let mut payload = Buf::new();
            payload.push(TRACKER_TAG);
            for _ in 0..len {
                // Mostly small bytes, so that some varints end early.
                let b = next();
                payload.push(if b % 3 == 0 {
                    (b >> 8) as u8
                } else {
                    (b >> 8) as u8 & 0x03
                });
            }
            agree(payload.as_slice());
        }
    }
}
