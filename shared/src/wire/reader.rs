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
    ///
    /// The data bytes of a COBS block are copied as one run (up to a `0x00`,
    /// the block's end or the buffer's): the same frames, errors and state
    /// as [`FrameReader::push`] byte by byte, at a fraction of the cost.
    pub fn push_slice(&mut self, input: &mut &[u8], errors: &mut ErrorCounters) -> Option<&[u8]> {
        loop {
            // Runs of a few bytes are cheaper byte by byte.
            if self.cobs.pending_data() >= 4 && !self.discarding {
                self.take_run(input);
            }
            let (&b, rest) = input.split_first()?;
            *input = rest;
            if let Some(n) = self.step(b, errors) {
                return self.buf.get(..n);
            }
        }
    }

    /// Stores the leading data bytes of `input` that belong to the current
    /// COBS block and fit the buffer, none of them `0x00`; advances `input`.
    fn take_run(&mut self, input: &mut &[u8]) {
        let space = N.saturating_sub(self.len);
        let limit = self.cobs.pending_data().min(space).min(input.len());
        let Some(run) = input.get(..limit) else {
            return;
        };
        let k = run.iter().position(|&b| b == 0).unwrap_or(run.len());
        let (Some(src), Some(dst)) = (run.get(..k), self.buf.get_mut(self.len..)) else {
            return;
        };
        if k == 0 {
            return;
        }
        for (d, s) in dst.iter_mut().zip(src) {
            *d = *s;
        }
        self.len = self.len.saturating_add(k);
        self.cobs.skip_data(k);
        self.started = true;
        *input = input.get(k..).unwrap_or(&[]);
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
    extern crate std;

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

    /// `push_slice` (which copies runs) and `push` byte by byte give the
    /// same frames, counters and state on any stream: valid frames, zeros
    /// inside blocks, frames ending mid-block, oversize frames, noise.
    #[test]
    fn runs_equal_bytes() {
        let mut seed = 0x1234_5678u32;
        let mut next = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 24) as u8
        };
        let (mut frames, mut oversize, mut cobs) = (0, 0, 0);
        for round in 0..400 {
            // Encoded frames (some longer than the buffer) between noise.
            let mut stream = std::vec::Vec::new();
            while stream.len() < 300 {
                if next() % 2 == 0 {
                    let len = usize::from(next()) % 60;
                    let payload: std::vec::Vec<u8> = (0..len).map(|_| next() % 4).collect();
                    let mut enc = [0u8; 80];
                    let n = super::super::cobs::encode(&payload, &mut enc).unwrap();
                    stream.extend_from_slice(&enc[..n]);
                    stream.push(0);
                } else {
                    for _ in 0..next() % 20 {
                        // Mostly small codes and data, some zeros and 0xFF codes.
                        stream.push(match next() % 16 {
                            0 => 0,
                            1 => 0xFF,
                            2..=5 => next() % 8,
                            _ => next(),
                        });
                    }
                }
            }
            let mut bytewise = FrameReader::<40>::new();
            let mut e1 = ErrorCounters::new();
            let mut frames1 = std::vec::Vec::new();
            for &b in &stream {
                if let Some(f) = bytewise.push(b, &mut e1) {
                    frames1.push(f.to_vec());
                }
            }
            let mut runs = FrameReader::<40>::new();
            let mut e2 = ErrorCounters::new();
            let mut frames2 = std::vec::Vec::new();
            // Chunks of varying length, as a UART delivers them.
            let mut rest: &[u8] = &stream;
            while !rest.is_empty() {
                let cut = (usize::from(next()) % 70 + 1).min(rest.len());
                let (mut chunk, tail) = rest.split_at(cut);
                rest = tail;
                while let Some(f) = runs.push_slice(&mut chunk, &mut e2) {
                    frames2.push(f.to_vec());
                }
            }
            assert_eq!(frames1, frames2, "round {round}");
            assert_eq!(e1, e2, "round {round}");
            assert_eq!(
                (
                    bytewise.len,
                    bytewise.started,
                    bytewise.discarding,
                    bytewise.cobs
                ),
                (runs.len, runs.started, runs.discarding, runs.cobs),
                "round {round}"
            );
            frames += frames1.iter().filter(|f| !f.is_empty()).count();
            (oversize, cobs) = (oversize + e1.oversize, cobs + e1.cobs);
        }
        // The streams exercised every case.
        assert!(
            frames > 1000 && oversize > 500 && cobs > 500,
            "{frames} {oversize} {cobs}"
        );
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
