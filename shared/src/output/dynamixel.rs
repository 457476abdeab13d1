//! ROBOTIS Dynamixel Protocol 2.0 instruction packets: Sync Write, with the
//! protocol's byte stuffing and CRC-16.
//!
//! ## Instruction packet (ROBOTIS e-Manual, "DYNAMIXEL Protocol 2.0")
//!
//! | bytes | field |
//! |---|---|
//! | `FF FF FD` | header |
//! | `00` | reserved |
//! | 1 | packet ID (`FE`: broadcast, no status packet comes back) |
//! | 2 | length, LE: instruction + parameters (after stuffing) + CRC, in bytes |
//! | 1 | instruction |
//! | n | parameters |
//! | 2 | CRC-16, LE, of every byte before it (header included, after stuffing) |
//!
//! **Byte stuffing.** Wherever `FF FF FD` appears from the instruction on,
//! an extra `FD` follows it (`FF FF FD FD`), so that a header can only be
//! a header; the length and the CRC count the stuffed bytes.
//!
//! **CRC-16** (the e-Manual's "CRC" page): polynomial
//! x¹⁶ + x¹⁵ + x² + 1 (`0x8005`), initial value 0, no reflection, no final
//! XOR (the CRC-16/UMTS parameters: check value `crc16(b"123456789") ==
//! 0xFEE8`).
//!
//! **Sync Write** (instruction `0x83`, broadcast ID): parameters are the
//! start address (2 bytes LE), the data length `L` (2 bytes LE), then per
//! servo its ID and `L` data bytes. The e-Manual's example, Goal Position
//! (address 116, 4 bytes) 150 for ID 1 and 170 for ID 2 on XM430-W210
//! servos, is
//! `FF FF FD 00 FE 11 00 83 74 00 04 00 01 96 00 00 00 02 AA 00 00 00 82 87`
//! (checked byte for byte in the tests).
//!
//! ## The X series control table (used by [`super::bus`])
//!
//! Torque Enable is address 64 (1 byte: 0 off, 1 on; Goal Position is
//! ignored while off, and torque is off at power-up), Goal Position address
//! 116 (4 bytes, 0 ..= 4095 in position mode, 0.088° per unit).

/// The Sync Write instruction.
pub const SYNC_WRITE: u8 = 0x83;
/// The broadcast packet ID.
pub const BROADCAST: u8 = 0xFE;
/// Control table: Torque Enable (1 byte).
pub const TORQUE_ENABLE: u16 = 64;
/// Control table: Goal Position (4 bytes).
pub const GOAL_POSITION: u16 = 116;
/// Bytes of Goal Position.
pub const GOAL_POSITION_LEN: usize = 4;
/// The header and reserved byte.
pub const HEADER: [u8; 4] = [0xFF, 0xFF, 0xFD, 0x00];

/// The CRC-16 lookup table, built at compile time.
static TABLE: [u16; 256] = make_table();

/// The byte-wise table of the non-reflected polynomial `0x8005`.
const fn make_table() -> [u16; 256] {
    let mut table = [0u16; 256];
    let mut n = 0usize;
    while n < 256 {
        let mut c = (n as u16) << 8;
        let mut k = 0;
        while k < 8 {
            c = if c & 0x8000 != 0 {
                (c << 1) ^ 0x8005
            } else {
                c << 1
            };
            k += 1;
        }
        // Const evaluation: an out-of-bounds index is a compile error.
        #[allow(clippy::indexing_slicing)]
        {
            table[n] = c;
        }
        n += 1;
    }
    table
}

/// Continues a Protocol 2.0 CRC-16 over `bytes`.
#[must_use]
pub fn crc16_update(mut crc: u16, bytes: &[u8]) -> u16 {
    for &b in bytes {
        let i = usize::from((crc >> 8) as u8 ^ b);
        crc = (crc << 8) ^ TABLE.get(i).copied().unwrap_or(0);
    }
    crc
}

/// The Protocol 2.0 CRC-16 of `bytes`.
#[inline]
#[must_use]
pub fn crc16(bytes: &[u8]) -> u16 {
    crc16_update(0, bytes)
}

/// Builds a packet in a caller's buffer, stuffing as it goes.
struct Packet<'b> {
    out: &'b mut [u8],
    len: usize,
    /// Consecutive `FF`s, then whether an `FD` followed them, since the
    /// instruction: the stuffing state.
    ff: u8,
    full: bool,
}

impl<'b> Packet<'b> {
    fn new(out: &'b mut [u8]) -> Self {
        let mut p = Self {
            out,
            len: 0,
            ff: 0,
            full: false,
        };
        for b in HEADER {
            p.raw(b);
        }
        p.raw(BROADCAST);
        p.raw(0);
        p.raw(0);
        p
    }

    fn raw(&mut self, b: u8) {
        match self.out.get_mut(self.len) {
            Some(slot) => {
                *slot = b;
                self.len += 1;
            }
            None => self.full = true,
        }
    }

    /// A byte of the instruction or parameters, stuffed.
    fn push(&mut self, b: u8) {
        self.raw(b);
        if self.ff >= 2 && b == 0xFD {
            self.raw(0xFD);
            self.ff = 0;
        } else if b == 0xFF {
            self.ff = self.ff.saturating_add(1);
        } else {
            self.ff = 0;
        }
    }

    /// Fills in the length, appends the CRC; the packet's bytes, or `None`
    /// if the buffer was too small.
    fn finish(self) -> Option<usize> {
        let Self { out, len, full, .. } = self;
        // Instruction onwards (from byte 7), plus the CRC.
        let length = u16::try_from(len.checked_sub(7)? + 2).ok()?;
        let [l0, l1] = length.to_le_bytes();
        *out.get_mut(5)? = l0;
        *out.get_mut(6)? = l1;
        let crc = crc16(out.get(..len)?);
        let [c0, c1] = crc.to_le_bytes();
        let tail = out.get_mut(len..len + 2)?;
        tail.copy_from_slice(&[c0, c1]);
        (!full).then_some(len + 2)
    }
}

/// Writes a broadcast Sync Write of `data_len` bytes at `address` into
/// `out`: for each `(id, data)` of `items`, the first `data_len` bytes of
/// `data`. Returns the packet's length, or `None` if `out` is too small
/// or `data_len` exceeds an item's data.
pub fn sync_write<'i>(
    address: u16,
    data_len: usize,
    items: impl IntoIterator<Item = (u8, &'i [u8])>,
    out: &mut [u8],
) -> Option<usize> {
    let mut p = Packet::new(out);
    p.push(SYNC_WRITE);
    let len16 = u16::try_from(data_len).ok()?;
    for b in address.to_le_bytes().into_iter().chain(len16.to_le_bytes()) {
        p.push(b);
    }
    for (id, data) in items {
        p.push(id);
        for &b in data.get(..data_len)? {
            p.push(b);
        }
    }
    p.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The CRC bit by bit, from the polynomial (independent of the table).
    fn crc16_bitwise(bytes: &[u8]) -> u16 {
        let mut crc = 0u16;
        for &b in bytes {
            crc ^= u16::from(b) << 8;
            for _ in 0..8 {
                crc = if crc & 0x8000 != 0 {
                    (crc << 1) ^ 0x8005
                } else {
                    crc << 1
                };
            }
        }
        crc
    }

    #[test]
    fn crc16_matches_its_definition() {
        assert_eq!(crc16(b"123456789"), 0xFEE8);
        assert_eq!(crc16_bitwise(b"123456789"), 0xFEE8);
        let mut x = 7u32;
        let bytes: [u8; 300] = core::array::from_fn(|_| {
            x = x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (x >> 24) as u8
        });
        for n in [0, 1, 2, 17, 300] {
            assert_eq!(crc16(&bytes[..n]), crc16_bitwise(&bytes[..n]), "{n}");
        }
    }

    #[test]
    fn sync_write_is_the_e_manuals_example() {
        // ROBOTIS e-Manual, Protocol 2.0, Sync Write example: ID 1 and ID 2
        // (XM430-W210), Goal Position (116, 4 bytes) 150 and 170.
        let mut out = [0u8; 64];
        let items: [(u8, &[u8]); 2] = [(1, &150u32.to_le_bytes()), (2, &170u32.to_le_bytes())];
        let n = sync_write(GOAL_POSITION, 4, items, &mut out).unwrap();
        assert_eq!(
            &out[..n],
            &[
                0xFF, 0xFF, 0xFD, 0x00, 0xFE, 0x11, 0x00, 0x83, 0x74, 0x00, 0x04, 0x00, 0x01, 0x96,
                0x00, 0x00, 0x00, 0x02, 0xAA, 0x00, 0x00, 0x00, 0x82, 0x87
            ]
        );
    }

    #[test]
    fn a_header_in_the_data_is_stuffed_and_counted() {
        // Data FF FF FD: an FD is inserted, the length says 1 + 4 + 1 + 4 +
        // 1 (stuffed) + 2 = 13, and the CRC covers the stuffed bytes.
        let mut out = [0u8; 64];
        let items: [(u8, &[u8]); 1] = [(5, &[0xFF, 0xFF, 0xFD, 0x01])];
        let n = sync_write(0x0200, 4, items, &mut out).unwrap();
        let body = [
            0xFF, 0xFF, 0xFD, 0x00, 0xFE, 0x0D, 0x00, 0x83, 0x00, 0x02, 0x04, 0x00, 0x05, 0xFF,
            0xFF, 0xFD, 0xFD, 0x01,
        ];
        assert_eq!(&out[..n - 2], &body);
        assert_eq!(&out[n - 2..n], &crc16_bitwise(&body).to_le_bytes());
        // Too small a buffer, or data shorter than the length: nothing.
        let items: [(u8, &[u8]); 1] = [(5, &[1, 2, 3, 4])];
        assert_eq!(sync_write(0, 4, items, &mut [0u8; 16]), None);
        let items: [(u8, &[u8]); 1] = [(5, &[1, 2])];
        assert_eq!(sync_write(0, 4, items, &mut out), None);
    }
}
