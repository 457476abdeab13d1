//! Consistent Overhead Byte Stuffing (Cheshire & Baker, 1999), panic-free.
//!
//! COBS removes every `0x00` from a packet so that `0x00` can delimit frames.
//! The encoded packet is a sequence of blocks; each block is a code byte `c`
//! (1..=255) followed by `c − 1` non-zero data bytes. A block with `c < 0xFF`
//! stands for its data followed by one `0x00`; a block with `c = 0xFF` stands
//! for its 254 data bytes alone. The implicit zero after the last block is
//! dropped. The empty packet encodes as `[0x01]`.
//!
//! The encoder follows the convention of the Wikipedia examples: when the
//! input ends right after a full (`0xFF`) block, no empty final block is
//! written (254 non-zero bytes encode as `FF …254 bytes…`, not `FF … 01`).
//! The decoder accepts both forms.
//!
//! Both directions work byte by byte ([`Encoder`], [`Decoder`]) so the frame
//! encoder and the UART reader need no intermediate buffer; [`encode`] and
//! [`decode`] are the slice conveniences. No function here can panic: every
//! write goes through `get_mut` and reports [`WireError::BufferFull`].

use super::WireError;

/// Upper bound on the COBS encoding of `n` bytes (without the delimiter).
#[inline]
#[must_use]
pub const fn max_encoded_len(n: usize) -> usize {
    n + n / 254 + 1
}

/// Streaming COBS encoder writing into a caller buffer.
#[derive(Debug)]
pub struct Encoder<'a> {
    out: &'a mut [u8],
    /// Where the current block's code byte goes.
    code_idx: usize,
    /// Where the next data byte goes.
    pos: usize,
    /// The current block's code: 1 + data bytes so far.
    code: u8,
    /// The previous block was closed because it was full (254 bytes).
    after_full: bool,
}

impl<'a> Encoder<'a> {
    /// An encoder writing into `out`.
    #[must_use]
    pub fn new(out: &'a mut [u8]) -> Self {
        Self {
            out,
            code_idx: 0,
            pos: 1,
            code: 1,
            after_full: false,
        }
    }

    fn put(&mut self, idx: usize, b: u8) -> Result<(), WireError> {
        let slot = self.out.get_mut(idx).ok_or(WireError::BufferFull)?;
        *slot = b;
        Ok(())
    }

    fn close_block(&mut self, full: bool) -> Result<(), WireError> {
        self.put(self.code_idx, self.code)?;
        self.code_idx = self.pos;
        self.pos = self.pos.saturating_add(1);
        self.code = 1;
        self.after_full = full;
        Ok(())
    }

    /// Encodes one input byte.
    ///
    /// # Errors
    /// [`WireError::BufferFull`] if `out` is too small.
    pub fn push(&mut self, b: u8) -> Result<(), WireError> {
        if b == 0 {
            return self.close_block(false);
        }
        self.put(self.pos, b)?;
        self.pos = self.pos.saturating_add(1);
        self.code = self.code.saturating_add(1);
        if self.code == 0xFF {
            self.close_block(true)
        } else {
            Ok(())
        }
    }

    /// Encodes every byte of `bytes`.
    ///
    /// # Errors
    /// [`WireError::BufferFull`] if `out` is too small.
    pub fn push_slice(&mut self, bytes: &[u8]) -> Result<(), WireError> {
        bytes.iter().try_for_each(|&b| self.push(b))
    }

    /// Closes the last block and returns the encoded length (no delimiter).
    /// Push nothing after this except through [`Encoder::finish_frame`].
    ///
    /// # Errors
    /// [`WireError::BufferFull`] if `out` is too small.
    pub fn finish(&mut self) -> Result<usize, WireError> {
        if self.code == 1 && self.after_full {
            // The last block would be empty after a full block: omit it.
            return Ok(self.code_idx);
        }
        self.put(self.code_idx, self.code)?;
        Ok(self.pos)
    }

    /// Closes the last block, appends the `0x00` delimiter and returns the
    /// frame length including the delimiter.
    ///
    /// # Errors
    /// [`WireError::BufferFull`] if `out` is too small.
    pub fn finish_frame(&mut self) -> Result<usize, WireError> {
        let n = self.finish()?;
        self.put(n, 0)?;
        Ok(n.saturating_add(1))
    }
}

/// What one input byte meant to the [`Decoder`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step {
    /// A code byte with nothing to output.
    Code,
    /// One output byte (a data byte, or the zero a previous block stood for).
    Byte(u8),
    /// The `0x00` delimiter: the packet ended, well-formed or not.
    End(Result<(), WireError>),
}

/// Streaming COBS decoder: feed encoded bytes, get decoded bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Decoder {
    /// Data bytes still expected in the current block.
    left: u8,
    /// The previous block had `code < 0xFF`: a zero precedes the next block.
    zero_pending: bool,
}

impl Decoder {
    /// A decoder at the start of a packet.
    #[must_use]
    pub const fn new() -> Self {
        Self {
            left: 0,
            zero_pending: false,
        }
    }

    /// Data bytes still expected in the current block (`0` when the next
    /// byte is a code byte or the delimiter).
    #[must_use]
    pub const fn pending_data(&self) -> usize {
        self.left as usize
    }

    /// Accounts for `n ≤` [`Decoder::pending_data`] non-zero data bytes
    /// taken as a run: the same state as [`Decoder::push`] of each of them,
    /// which would return each as [`Step::Byte`].
    pub fn skip_data(&mut self, n: usize) {
        self.left = self.left.saturating_sub(u8::try_from(n).unwrap_or(u8::MAX));
    }

    /// Feeds one encoded byte. On `0x00` the decoder resets for the next
    /// packet and reports whether the packet ended on a block boundary.
    pub fn push(&mut self, b: u8) -> Step {
        if b == 0 {
            let ok = self.left == 0;
            *self = Self::new();
            return Step::End(if ok { Ok(()) } else { Err(WireError::Cobs) });
        }
        if self.left == 0 {
            let pending = self.zero_pending;
            self.left = b.saturating_sub(1);
            self.zero_pending = b != 0xFF;
            if pending { Step::Byte(0) } else { Step::Code }
        } else {
            self.left = self.left.saturating_sub(1);
            Step::Byte(b)
        }
    }
}

/// COBS-encodes `src` into `dst` (no delimiter) and returns the length.
///
/// # Errors
/// [`WireError::BufferFull`] if `dst` is too small; [`max_encoded_len`] is
/// always enough.
pub fn encode(src: &[u8], dst: &mut [u8]) -> Result<usize, WireError> {
    let mut enc = Encoder::new(dst);
    enc.push_slice(src)?;
    enc.finish()
}

/// Decodes one COBS packet `src` (without its delimiter) into `dst` and
/// returns the decoded length.
///
/// # Errors
/// [`WireError::Cobs`] if `src` contains `0x00` or ends inside a block;
/// [`WireError::BufferFull`] if `dst` is too small (`src.len()` is enough).
pub fn decode(src: &[u8], dst: &mut [u8]) -> Result<usize, WireError> {
    let mut dec = Decoder::new();
    let mut n = 0usize;
    for &b in src {
        match dec.push(b) {
            Step::Code => {}
            Step::Byte(x) => {
                *dst.get_mut(n).ok_or(WireError::BufferFull)? = x;
                n = n.saturating_add(1);
            }
            Step::End(_) => return Err(WireError::Cobs),
        }
    }
    match dec.push(0) {
        Step::End(Ok(())) => Ok(n),
        _ => Err(WireError::Cobs),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn enc(src: &[u8]) -> ([u8; 600], usize) {
        let mut out = [0u8; 600];
        let n = encode(src, &mut out).unwrap();
        (out, n)
    }

    #[test]
    fn small_vectors() {
        // Cheshire & Baker / Wikipedia examples 1-6 (delimiter omitted).
        let cases: [(&[u8], &[u8]); 7] = [
            (&[], &[0x01]),
            (&[0x00], &[0x01, 0x01]),
            (&[0x00, 0x00], &[0x01, 0x01, 0x01]),
            (&[0x00, 0x11, 0x00], &[0x01, 0x02, 0x11, 0x01]),
            (&[0x11, 0x22, 0x00, 0x33], &[0x03, 0x11, 0x22, 0x02, 0x33]),
            (&[0x11, 0x22, 0x33, 0x44], &[0x05, 0x11, 0x22, 0x33, 0x44]),
            (&[0x11, 0x00, 0x00, 0x00], &[0x02, 0x11, 0x01, 0x01, 0x01]),
        ];
        for (raw, coded) in cases {
            let (out, n) = enc(raw);
            assert_eq!(&out[..n], coded, "encode {raw:02x?}");
            let mut back = [0u8; 16];
            let m = decode(coded, &mut back).unwrap();
            assert_eq!(&back[..m], raw, "decode {coded:02x?}");
        }
    }

    #[test]
    fn bad_packets() {
        let mut dst = [0u8; 16];
        assert_eq!(decode(&[0x03, 0x11], &mut dst), Err(WireError::Cobs));
        assert_eq!(decode(&[0x02, 0x00], &mut dst), Err(WireError::Cobs));
        assert_eq!(
            decode(&[0x05, 1, 2, 3, 4], &mut dst[..3]),
            Err(WireError::BufferFull)
        );
        assert_eq!(
            encode(&[1, 2, 3], &mut dst[..3]),
            Err(WireError::BufferFull)
        );
        assert_eq!(encode(&[], &mut []), Err(WireError::BufferFull));
    }

    #[test]
    fn trailing_empty_block_after_full_block_is_accepted() {
        let data: [u8; 254] = core::array::from_fn(|i| (i + 1) as u8);
        let mut coded = [0u8; 256];
        coded[0] = 0xFF;
        coded[1..255].copy_from_slice(&data);
        coded[255] = 0x01;
        let mut back = [0u8; 300];
        assert_eq!(decode(&coded, &mut back), Ok(254));
        assert_eq!(&back[..254], &data[..]);
        assert_eq!(decode(&coded[..255], &mut back), Ok(254));
    }
}
