//! Wire errors and the per-kind rejection counters.

use serde::{Deserialize, Serialize};

/// Why a frame or message was rejected, or why encoding failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WireError {
    /// Malformed COBS: the frame ended inside a block.
    Cobs,
    /// The frame is shorter than its CRC, or the CRC does not match.
    Crc,
    /// postcard could not decode the payload: unknown tag, bad varint, bad
    /// bool, truncated field, list longer than its capacity, or trailing bytes.
    Decode,
    /// The decoded frame does not fit the receiver's buffer.
    Oversize,
    /// `Hello` carried another protocol version, or a message arrived after
    /// such a `Hello`.
    Version,
    /// The sequence number is a duplicate or older than the last accepted one.
    Stale,
    /// A value is NaN, infinite or out of its documented range, sensor ids
    /// are repeated or too large, or a quaternion is far from unit length.
    Range,
    /// A board-to-host message arrived at the board (or the other way round).
    Direction,
    /// Encoding: the output buffer is too small, or a list is over capacity.
    BufferFull,
}

/// Rejection counters by kind. Every counter saturates at `u32::MAX`.
///
/// Field order is part of the wire contract (it is sent in `Status` and
/// `Telemetry`): `cobs, crc, decode, oversize, version, lost, stale, range`,
/// each a postcard varint `u32`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ErrorCounters {
    /// Frames with malformed COBS.
    pub cobs: u32,
    /// Frames failing the CRC (or too short to carry one).
    pub crc: u32,
    /// Frames whose payload postcard could not decode, plus messages that
    /// travelled in the wrong direction.
    pub decode: u32,
    /// Frames longer than the receiver's buffer.
    pub oversize: u32,
    /// Protocol version mismatches.
    pub version: u32,
    /// Frames lost, from gaps in the sequence numbers.
    pub lost: u32,
    /// Duplicate or out-of-order frames rejected.
    pub stale: u32,
    /// Messages rejected by validation (NaN, infinity, out of range).
    pub range: u32,
}

impl ErrorCounters {
    /// All counters zero.
    #[must_use]
    pub const fn new() -> Self {
        Self {
            cobs: 0,
            crc: 0,
            decode: 0,
            oversize: 0,
            version: 0,
            lost: 0,
            stale: 0,
            range: 0,
        }
    }

    /// Counts one rejection of kind `e`. Encoder-side errors
    /// ([`WireError::BufferFull`]) are not link errors and are not counted.
    pub fn record(&mut self, e: WireError) {
        let counter = match e {
            WireError::Cobs => &mut self.cobs,
            WireError::Crc => &mut self.crc,
            WireError::Decode | WireError::Direction => &mut self.decode,
            WireError::Oversize => &mut self.oversize,
            WireError::Version => &mut self.version,
            WireError::Stale => &mut self.stale,
            WireError::Range => &mut self.range,
            WireError::BufferFull => return,
        };
        *counter = counter.saturating_add(1);
    }

    /// Adds `n` lost frames (a sequence gap).
    pub fn add_lost(&mut self, n: u32) {
        self.lost = self.lost.saturating_add(n);
    }

    /// Sum of all counters (saturating): zero means a clean link.
    #[must_use]
    pub fn total(&self) -> u32 {
        [
            self.cobs,
            self.crc,
            self.decode,
            self.oversize,
            self.version,
            self.lost,
            self.stale,
            self.range,
        ]
        .iter()
        .fold(0u32, |acc, &c| acc.saturating_add(c))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn record_counts_by_kind_and_saturates() {
        let mut c = ErrorCounters::new();
        c.record(WireError::Crc);
        c.record(WireError::Crc);
        c.record(WireError::Direction);
        c.record(WireError::BufferFull);
        assert_eq!(c.crc, 2);
        assert_eq!(c.decode, 1);
        assert_eq!(c.total(), 3);
        c.lost = u32::MAX - 1;
        c.add_lost(5);
        assert_eq!(c.lost, u32::MAX);
        assert_eq!(c.total(), u32::MAX);
    }
}
