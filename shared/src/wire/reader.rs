//! [`FrameReader`]: splits a UART byte stream into decoded COBS frames.

use super::cobs::{Decoder, Step};
use super::{ErrorCounters, WireError};

/// Streaming frame splitter with an `N`-byte buffer for the decoded frame
/// (payload + CRC). Feed it received bytes; it yields each complete frame.
///
/// - `0x00` ends a frame. Bytes before the first `0x00` are a frame like any
///   other (usually rejected by the CRC); to resynchronise, a sender may
///   send `0x00` at any time. Empty frames (`00 00`) are ignored silently.
/// - A frame ending inside a COBS block counts as `cobs`.
/// - A frame whose decoded length exceeds `N` counts once as `oversize`;
///   the rest of it, up to the next `0x00`, is discarded.
///
/// CRC and payload checks are the caller's ([`super::decode_frame`]).
#[derive(Clone, Debug)]
pub struct FrameReader<const N: usize> {
    buf: [u8; N],
    len: usize,
    cobs: Decoder,
    /// Bytes were received since the last delimiter.
    started: bool,
    /// The current frame overflowed: drop bytes until the next delimiter.
    discarding: bool,
}

impl<const N: usize> Default for FrameReader<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> FrameReader<N> {
    /// An empty reader.
    #[must_use]
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            len: 0,
            cobs: Decoder::new(),
            started: false,
            discarding: false,
        }
    }

    /// Drops any partial frame.
    pub fn reset(&mut self) {
        self.len = 0;
        self.cobs = Decoder::new();
        self.started = false;
        self.discarding = false;
    }

    /// Feeds one byte; returns the decoded frame when `byte` completes one.
    /// Rejections are counted in `errors`.
    pub fn push(&mut self, byte: u8, errors: &mut ErrorCounters) -> Option<&[u8]> {
        let n = self.step(byte, errors)?;
        self.buf.get(..n)
    }

    /// Feeds bytes from `input` until a frame completes, advancing `input`
    /// past the consumed bytes. Call again with the same `input` for the next
    /// frame; returns `None` once `input` is exhausted.
    pub fn push_slice(&mut self, input: &mut &[u8], errors: &mut ErrorCounters) -> Option<&[u8]> {
        while let Some((&b, rest)) = input.split_first() {
            *input = rest;
            if let Some(n) = self.step(b, errors) {
                return self.buf.get(..n);
            }
        }
        None
    }

    /// One byte; `Some(len)` when a frame of `len` bytes is complete in `buf`.
    fn step(&mut self, byte: u8, errors: &mut ErrorCounters) -> Option<usize> {
        if self.discarding {
            if byte == 0 {
                self.reset();
            }
            return None;
        }
        let step = self.cobs.push(byte);
        match step {
            Step::Code => {
                self.started = true;
                None
            }
            Step::Byte(b) => {
                self.started = true;
                self.store(b, errors);
                None
            }
            Step::End(result) => self.end(result, errors),
        }
    }

    fn store(&mut self, b: u8, errors: &mut ErrorCounters) {
        if let Some(slot) = self.buf.get_mut(self.len) {
            *slot = b;
            self.len = self.len.saturating_add(1);
        } else {
            errors.record(WireError::Oversize);
            self.discarding = true;
        }
    }

    fn end(&mut self, result: Result<(), WireError>, errors: &mut ErrorCounters) -> Option<usize> {
        let (n, started) = (self.len, self.started);
        self.reset();
        match result {
            Ok(()) if started => Some(n),
            Ok(()) => None,
            Err(e) => {
                errors.record(e);
                None
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splits_frames_and_resyncs() {
        let mut r = FrameReader::<8>::new();
        let mut e = ErrorCounters::new();
        // Garbage ending inside a block, then two frames and an empty one.
        let mut input: &[u8] = &[
            0x07, 0xAA, 0x00, 0x03, 0x11, 0x22, 0x02, 0x33, 0x00, 0x00, 0x01, 0x00,
        ];
        assert_eq!(
            r.push_slice(&mut input, &mut e),
            Some(&[0x11, 0x22, 0x00, 0x33][..])
        );
        assert_eq!(e.cobs, 1);
        assert_eq!(r.push_slice(&mut input, &mut e), Some(&[][..]));
        assert_eq!(r.push_slice(&mut input, &mut e), None);
        assert!(input.is_empty());
        assert_eq!(e.total(), 1);
    }

    #[test]
    fn oversize_counted_once_then_recovers() {
        let mut r = FrameReader::<3>::new();
        let mut e = ErrorCounters::new();
        for b in [0x06, 1, 2, 3, 4, 5] {
            assert_eq!(r.push(b, &mut e), None);
        }
        assert_eq!(r.push(0, &mut e), None);
        assert_eq!(e.oversize, 1);
        for b in [0x04, 1, 2, 3] {
            assert_eq!(r.push(b, &mut e), None);
        }
        assert_eq!(r.push(0, &mut e), Some(&[1, 2, 3][..]));
        assert_eq!(e.total(), 1);
    }
}
