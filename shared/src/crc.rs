//! CRC-32/ISO-HDLC: the zlib / Ethernet / PNG checksum.
//!
//! Parameters (Rocksoft model): width 32, polynomial 0x04C11DB7 (processed
//! reflected as 0xEDB88320), init 0xFFFFFFFF, input and output reflected,
//! xorout 0xFFFFFFFF. Check value: `crc32(b"123456789") == 0xCBF4_3926`.
//!
//! The 256-entry table is built by a `const fn` at compile time. Lookups index
//! it with `(crc ^ byte) & 0xFF`, which is at most 255 and the table has 256
//! entries, so the bounds check is provably dead and there is no panic path.
//!
//! Used by the wire protocol ([`crate::wire`]) and the table blob format.

/// The reflected CRC-32/ISO-HDLC polynomial.
pub const POLY_REFLECTED: u32 = 0xEDB8_8320;

/// The initial register value (and the final XOR).
const INIT: u32 = 0xFFFF_FFFF;

/// The byte-wise lookup table, generated at compile time.
static TABLE: [u32; 256] = make_table();

/// Builds the byte-wise table for the reflected polynomial.
const fn make_table() -> [u32; 256] {
    let mut table = [0u32; 256];
    let mut n: usize = 0;
    while n < 256 {
        // `n < 256` so the cast is exact.
        let mut c = n as u32;
        let mut k = 0;
        while k < 8 {
            c = if c & 1 != 0 {
                POLY_REFLECTED ^ (c >> 1)
            } else {
                c >> 1
            };
            k += 1;
        }
        // Const evaluation: an out-of-bounds index would be a compile error,
        // not a run-time panic. `n < 256` here anyway.
        #[allow(clippy::indexing_slicing)]
        {
            table[n] = c;
        }
        n += 1;
    }
    table
}

/// Advances the (non-inverted) CRC register over one byte.
#[inline(always)]
fn byte(reg: u32, b: u8) -> u32 {
    // `& 0xFF` bounds the index to 0..=255 and TABLE has 256 entries.
    let idx = ((reg ^ u32::from(b)) & 0xFF) as usize;
    let t = match TABLE.get(idx) {
        Some(t) => *t,
        None => 0,
    };
    t ^ (reg >> 8)
}

/// Advances the (non-inverted) CRC register over `bytes`: four bytes per
/// turn of the loop (the same table steps, a quarter of the loop's own
/// work), then the rest one by one. Not inlined: one copy of the unrolled
/// loop serves every caller.
#[inline(never)]
fn step(mut reg: u32, bytes: &[u8]) -> u32 {
    let words = bytes.chunks_exact(4);
    let tail = words.remainder();
    for w in words {
        if let &[a, b, c, d] = w {
            reg = byte(byte(byte(byte(reg, a), b), c), d);
        }
    }
    for &b in tail {
        reg = byte(reg, b);
    }
    reg
}

/// CRC-32/ISO-HDLC of `bytes` in one call.
#[inline]
#[must_use]
pub fn crc32(bytes: &[u8]) -> u32 {
    step(INIT, bytes) ^ INIT
}

/// Incremental CRC-32/ISO-HDLC: feed chunks with [`Crc32::update`], read the
/// checksum with [`Crc32::finish`]. The result equals [`crc32`] of the
/// concatenated chunks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Crc32 {
    reg: u32,
}

impl Default for Crc32 {
    fn default() -> Self {
        Self::new()
    }
}

impl Crc32 {
    /// A hasher that has seen no bytes.
    #[inline]
    #[must_use]
    pub const fn new() -> Self {
        Self { reg: INIT }
    }

    /// Feeds `bytes` into the checksum. Byte by byte, inlined: an encoder
    /// feeds a few bytes at a time, too few for [`crc32`]'s unrolled loop
    /// to pay for its call.
    #[inline]
    pub fn update(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.reg = byte(self.reg, b);
        }
    }

    /// The checksum of all bytes fed so far. Does not consume the hasher:
    /// more bytes may be fed afterwards.
    #[inline]
    #[must_use]
    pub const fn finish(&self) -> u32 {
        self.reg ^ INIT
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Slow bit-by-bit reference, written from the Rocksoft parameters
    /// (non-reflected polynomial 0x04C11DB7, reflecting input and output by hand).
    fn reference(bytes: &[u8]) -> u32 {
        let mut reg: u32 = 0xFFFF_FFFF;
        for &b in bytes {
            let b = b.reverse_bits();
            for i in (0..8).rev() {
                let bit = (b >> i) & 1;
                let top = (reg >> 31) & 1;
                reg <<= 1;
                if (top ^ u32::from(bit)) != 0 {
                    reg ^= 0x04C1_1DB7;
                }
            }
        }
        reg.reverse_bits() ^ 0xFFFF_FFFF
    }

    #[test]
    fn check_value() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(reference(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn empty_is_zero() {
        assert_eq!(crc32(&[]), 0);
        assert_eq!(Crc32::new().finish(), 0);
    }

    #[test]
    fn known_vectors() {
        // zlib.crc32 values, well known.
        assert_eq!(crc32(b"a"), 0xE8B7_BE43);
        assert_eq!(
            crc32(b"The quick brown fox jumps over the lazy dog"),
            0x414F_A339
        );
        assert_eq!(crc32(&[0u8]), 0xD202_EF8D);
    }

    #[test]
    fn table_entries() {
        // Independent spot checks of the table (zlib's crc_table).
        assert_eq!(TABLE[0], 0);
        assert_eq!(TABLE[1], 0x7707_3096);
        assert_eq!(TABLE[128], 0xEDB8_8320);
        assert_eq!(TABLE[255], 0x2D02_EF8D);
    }

    #[test]
    fn incremental_equals_one_shot() {
        let data: [u8; 300] = core::array::from_fn(|i| (i * 31 + 7) as u8);
        for split in [0, 1, 2, 17, 150, 299, 300] {
            let (a, b) = data.split_at(split);
            let mut h = Crc32::new();
            h.update(a);
            h.update(b);
            assert_eq!(h.finish(), crc32(&data), "split {split}");
        }
        let mut h = Crc32::default();
        for b in data {
            h.update(&[b]);
        }
        assert_eq!(h.finish(), crc32(&data));
    }

    #[test]
    fn matches_bitwise_reference() {
        // Deterministic pseudo-random inputs of many lengths.
        let mut x: u32 = 0x1234_5678;
        let mut buf = [0u8; 97];
        for len in 0..buf.len() {
            for b in buf.iter_mut().take(len) {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                *b = x as u8;
            }
            assert_eq!(crc32(&buf[..len]), reference(&buf[..len]), "len {len}");
        }
    }
}
