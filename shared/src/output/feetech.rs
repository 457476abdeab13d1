//! Feetech SCS/STS instruction packets: Sync Write, with the protocol's
//! checksum.
//!
//! ## Instruction packet (Feetech, "SCS/STS communication protocol")
//!
//! | bytes | field |
//! |---|---|
//! | `FF FF` | header |
//! | 1 | ID (`FE`: broadcast, no answer) |
//! | 1 | length: parameters + 2 |
//! | 1 | instruction |
//! | n | parameters |
//! | 1 | checksum: `~(ID + length + instruction + parameters) & 0xFF` |
//!
//! **Sync Write** (instruction `0x83`, broadcast ID): parameters are the
//! start address (1 byte), the data length `L` (1 byte), then per servo its
//! ID and `L` data bytes; the length is `(L + 1) · N + 4`. Two-byte values
//! are little-endian on the STS/SMS series (magnetic encoders) and
//! big-endian on the SCS series (potentiometers). The manual's example 7,
//! position `0x0800`, time 0 and speed `0x03E8` from address `0x2A` for IDs
//! 1 to 4 (STS, low byte first), is
//! `FF FF FE 20 83 2A 06 01 00 08 00 00 E8 03 02 00 08 00 00 E8 03 03 00 08
//! 00 00 E8 03 04 00 08 00 00 E8 03 58` (checked byte for byte in the tests).
//!
//! ## The memory table (used by [`super::bus`])
//!
//! Torque Enable is address 40 (1 byte), Goal Position address 42 (2
//! bytes). Marionette writes the position alone: the servo's own goal
//! time and speed registers (44, 46) stay as they are (0: as fast as it
//! can), the core's slew limiter doing the limiting.

use crate::rig::FeetechSeries;

/// The Sync Write instruction.
pub const SYNC_WRITE: u8 = 0x83;
/// The broadcast ID.
pub const BROADCAST: u8 = 0xFE;
/// Memory table: Torque Enable (1 byte).
pub const TORQUE_ENABLE: u8 = 40;
/// Memory table: Goal Position (2 bytes).
pub const GOAL_POSITION: u8 = 42;
/// Bytes of Goal Position.
pub const GOAL_POSITION_LEN: usize = 2;

/// A 2-byte register value in the series' byte order.
#[inline]
#[must_use]
pub const fn word(series: FeetechSeries, value: u16) -> [u8; 2] {
    match series {
        FeetechSeries::Sts => value.to_le_bytes(),
        FeetechSeries::Scs => value.to_be_bytes(),
    }
}

/// Writes a broadcast Sync Write of `data_len` bytes at `address` into
/// `out`: for each `(id, data)` of `items`, the first `data_len` bytes of
/// `data`. Returns the packet's length, or `None` if `out` is too small,
/// the length passes 255 or `data_len` exceeds an item's data.
pub fn sync_write<'i>(
    address: u8,
    data_len: usize,
    items: impl IntoIterator<Item = (u8, &'i [u8])>,
    out: &mut [u8],
) -> Option<usize> {
    let len8 = u8::try_from(data_len).ok()?;
    let mut n = 0usize;
    let mut put = |b: u8| -> Option<()> {
        *out.get_mut(n)? = b;
        n += 1;
        Some(())
    };
    for b in [0xFF, 0xFF, BROADCAST, 0, SYNC_WRITE, address, len8] {
        put(b)?;
    }
    for (id, data) in items {
        put(id)?;
        for &b in data.get(..data_len)? {
            put(b)?;
        }
    }
    // Parameters (from the address) plus instruction and checksum.
    let length = u8::try_from(n.checked_sub(5)? + 2).ok()?;
    *out.get_mut(3)? = length;
    let sum = out.get(2..n)?.iter().fold(0u8, |s, &b| s.wrapping_add(b));
    *out.get_mut(n)? = !sum;
    Some(n + 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sync_write_is_the_manuals_example_7() {
        // Feetech SCS/STS protocol manual, example 7: IDs 1-4, from 0x2A,
        // position 0x0800, time 0, speed 0x03E8, low byte first.
        let data: [u8; 6] = [0x00, 0x08, 0x00, 0x00, 0xE8, 0x03];
        let mut out = [0u8; 64];
        let items = (1u8..=4).map(|id| (id, &data[..]));
        let n = sync_write(0x2A, 6, items, &mut out).unwrap();
        assert_eq!(
            &out[..n],
            &[
                0xFF, 0xFF, 0xFE, 0x20, 0x83, 0x2A, 0x06, 0x01, 0x00, 0x08, 0x00, 0x00, 0xE8, 0x03,
                0x02, 0x00, 0x08, 0x00, 0x00, 0xE8, 0x03, 0x03, 0x00, 0x08, 0x00, 0x00, 0xE8, 0x03,
                0x04, 0x00, 0x08, 0x00, 0x00, 0xE8, 0x03, 0x58
            ]
        );
        // The length is (L + 1) · N + 4.
        assert_eq!(out[3], (6 + 1) * 4 + 4);
    }

    #[test]
    fn byte_order_and_limits() {
        assert_eq!(word(FeetechSeries::Sts, 0x0800), [0x00, 0x08]);
        assert_eq!(word(FeetechSeries::Scs, 0x0800), [0x08, 0x00]);
        // One servo, position 0x01F4 big-endian: length (2 + 1) · 1 + 4 = 7,
        // checksum by hand ~(FE + 07 + 83 + 2A + 02 + 07 + 01 + F4) =
        // ~0x2B0 -> ~0xB0 = 0x4F.
        let mut out = [0u8; 16];
        let items: [(u8, &[u8]); 1] = [(7, &[0x01, 0xF4])];
        let n = sync_write(GOAL_POSITION, 2, items, &mut out).unwrap();
        assert_eq!(
            &out[..n],
            &[
                0xFF, 0xFF, 0xFE, 0x07, 0x83, 0x2A, 0x02, 0x07, 0x01, 0xF4, 0x4F
            ]
        );
        assert_eq!(sync_write(GOAL_POSITION, 2, items, &mut [0u8; 10]), None);
        // 84 servos of 2 bytes: length 256 does not fit a byte.
        let many = (0..84u8).map(|id| (id, &[0u8, 0][..]));
        assert_eq!(sync_write(GOAL_POSITION, 2, many, &mut [0u8; 300]), None);
    }
}
