//! Console lines over semihosting, without `core::fmt`.
//!
//! `core::fmt` and semihosting's `write_fmt` keep panicking branches that
//! survive optimisation, which `panic-never` rejects. Report lines are short
//! and made of words and integers, so a fixed line buffer does the job.

use semihosting::io::Write;

/// Capacity of one console line, bytes. Longer lines are truncated.
pub const LINE_CAPACITY: usize = 160;

/// A console line being built.
pub struct Line {
    buf: [u8; LINE_CAPACITY],
    len: usize,
}

impl Default for Line {
    fn default() -> Self {
        Self::new()
    }
}

impl Line {
    /// An empty line.
    #[must_use]
    pub const fn new() -> Self {
        Self {
            buf: [0; LINE_CAPACITY],
            len: 0,
        }
    }

    /// Appends bytes, truncating at capacity.
    pub fn bytes(&mut self, bytes: &[u8]) -> &mut Self {
        if let Some(rest) = self.buf.get_mut(self.len..) {
            let n = rest.len().min(bytes.len());
            if let (Some(dst), Some(src)) = (rest.get_mut(..n), bytes.get(..n)) {
                dst.copy_from_slice(src);
                self.len += n;
            }
        }
        self
    }

    /// Appends a word.
    pub fn str(&mut self, s: &str) -> &mut Self {
        self.bytes(s.as_bytes())
    }

    /// Appends an unsigned integer in decimal.
    pub fn u32(&mut self, mut value: u32) -> &mut Self {
        let mut digits = [0u8; 10];
        let mut start = digits.len();
        for slot in digits.iter_mut().rev() {
            *slot = b'0' + (value % 10) as u8;
            start -= 1;
            value /= 10;
            if value == 0 {
                break;
            }
        }
        self.bytes(digits.get(start..).unwrap_or_default())
    }

    /// Appends a byte as two lowercase hex digits.
    pub fn hex(&mut self, byte: u8) -> &mut Self {
        const HEX: &[u8; 16] = b"0123456789abcdef";
        self.bytes(&[HEX[usize::from(byte >> 4)], HEX[usize::from(byte & 0xF)]])
    }

    /// Writes the line and a newline to the host's stdout; errors are dropped
    /// (there is nowhere to report them).
    pub fn print(&mut self) {
        self.bytes(b"\n");
        let Ok(mut out) = semihosting::io::stdout() else {
            return;
        };
        let mut pending = self.buf.get(..self.len).unwrap_or_default();
        while !pending.is_empty() {
            match out.write(pending) {
                Ok(n) if n > 0 => pending = pending.get(n..).unwrap_or_default(),
                _ => return,
            }
        }
        self.len = 0;
    }
}
