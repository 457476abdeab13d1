//! Small decoders of the servo links, written here from the manuals (not
//! from the code under test), and the behaviour every back-end documents,
//! as a slow obvious reference:
//!
//! - **Pololu Maestro** user's guide, compact protocol: Set Target is
//!   `0x84, channel, target & 0x7F, target >> 7 & 0x7F` (quarter-µs).
//! - **ROBOTIS Dynamixel Protocol 2.0** (e-Manual): `FF FF FD 00`, ID, length
//!   (LE, instruction to CRC), instruction, parameters, CRC-16 (polynomial
//!   0x8005, initial 0, unreflected) of everything before it; `FF FF FD` in
//!   the instruction or parameters is followed by a stuffed `FD`. Sync Write
//!   (0x83): address (LE16), data length L (LE16), then ID + L bytes per servo.
//! - **Feetech SCS/STS** protocol: `FF FF`, ID, length (parameters + 2),
//!   instruction, parameters, `~(ID + length + instruction + parameters)`.
//!   Sync Write (0x83): address, L, then ID + L bytes per servo; 2-byte values
//!   little-endian on STS, big-endian on SCS.

/// One decoded Sync Write: the register address and, per servo, its ID and
/// value (1-byte registers as is; positions as integers).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SyncWrite {
    /// The register address.
    pub address: u16,
    /// (ID, value) per servo, in packet order.
    pub items: Vec<(u8, u32)>,
}

/// The Protocol 2.0 CRC-16, bit by bit from its polynomial.
#[must_use]
pub fn dynamixel_crc(bytes: &[u8]) -> u16 {
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

/// Every Dynamixel Protocol 2.0 Sync Write in `bytes`.
///
/// # Panics
/// On anything that is not a well-formed broadcast Sync Write (a test
/// failure: the board must send nothing else).
#[must_use]
pub fn decode_dynamixel(mut bytes: &[u8]) -> Vec<SyncWrite> {
    let mut out = Vec::new();
    while !bytes.is_empty() {
        assert_eq!(&bytes[..4], &[0xFF, 0xFF, 0xFD, 0x00], "header");
        assert_eq!(bytes[4], 0xFE, "broadcast ID");
        let len = usize::from(u16::from_le_bytes([bytes[5], bytes[6]]));
        let end = 7 + len;
        let crc = u16::from_le_bytes([bytes[end - 2], bytes[end - 1]]);
        assert_eq!(dynamixel_crc(&bytes[..end - 2]), crc, "CRC");
        // Undo the stuffing: FF FF FD FD -> FF FF FD.
        let mut body = Vec::new();
        for &b in &bytes[7..end - 2] {
            if b == 0xFD && body.ends_with(&[0xFF, 0xFF, 0xFD]) {
                continue;
            }
            body.push(b);
        }
        assert_eq!(body[0], 0x83, "Sync Write");
        let address = u16::from_le_bytes([body[1], body[2]]);
        let l = usize::from(u16::from_le_bytes([body[3], body[4]]));
        let items = body[5..]
            .chunks(l + 1)
            .map(|c| {
                assert_eq!(c.len(), l + 1, "whole items");
                let mut v = [0u8; 4];
                v[..l].copy_from_slice(&c[1..]);
                (c[0], u32::from_le_bytes(v))
            })
            .collect();
        out.push(SyncWrite { address, items });
        bytes = &bytes[end..];
    }
    out
}

/// Every Feetech Sync Write in `bytes`; `big_endian` for the SCS series.
///
/// # Panics
/// On anything that is not a well-formed broadcast Sync Write.
#[must_use]
pub fn decode_feetech(mut bytes: &[u8], big_endian: bool) -> Vec<SyncWrite> {
    let mut out = Vec::new();
    while !bytes.is_empty() {
        assert_eq!(&bytes[..3], &[0xFF, 0xFF, 0xFE], "header, broadcast ID");
        let len = usize::from(bytes[3]);
        let end = 4 + len;
        let sum: u32 = bytes[2..end - 1].iter().map(|&b| u32::from(b)).sum();
        assert_eq!(!(sum as u8), bytes[end - 1], "checksum");
        assert_eq!(bytes[4], 0x83, "Sync Write");
        let address = u16::from(bytes[5]);
        let l = usize::from(bytes[6]);
        assert_eq!(len, (l + 1) * ((len - 4) / (l + 1)) + 4, "length rule");
        let items = bytes[7..end - 1]
            .chunks(l + 1)
            .map(|c| {
                let v = match l {
                    1 => u32::from(c[1]),
                    2 if big_endian => u32::from(c[1]) << 8 | u32::from(c[2]),
                    2 => u32::from(c[2]) << 8 | u32::from(c[1]),
                    _ => panic!("data length {l}"),
                };
                (c[0], v)
            })
            .collect();
        out.push(SyncWrite { address, items });
        bytes = &bytes[end..];
    }
    out
}

/// Every Maestro Set Target in `bytes`: (channel, target in quarter-µs).
///
/// # Panics
/// On anything else.
#[must_use]
pub fn decode_maestro(bytes: &[u8]) -> Vec<(u8, u16)> {
    assert_eq!(bytes.len() % 4, 0, "whole commands");
    bytes
        .chunks(4)
        .map(|c| {
            assert_eq!(c[0], 0x84, "Set Target");
            assert!(c[1] < 0x80 && c[2] < 0x80 && c[3] < 0x80, "7-bit data");
            (c[1], u16::from(c[2]) | u16::from(c[3]) << 7)
        })
        .collect()
}

/// What a bus back-end must send for a sequence of output frames (targets
/// in quarter units by channel; `ids[channel]` the bus ID), as the
/// back-end documents it: per frame, Torque Enable = 1 to the servos that
/// get a position and are not on yet, Torque Enable = 0 to the servos whose
/// target is 0 and that are on, then Goal Position, `round(target / 4)`, to
/// every servo with a target.
#[must_use]
pub fn expected_bus_writes(
    frames: &[Vec<u16>],
    ids: &[Option<u8>],
    torque_at: u16,
    goal_at: u16,
) -> Vec<SyncWrite> {
    let mut on = vec![false; ids.len()];
    let mut out = Vec::new();
    for frame in frames {
        let servos = || {
            ids.iter()
                .enumerate()
                .filter_map(|(ch, id)| id.map(|id| (ch, id, frame.get(ch).copied().unwrap_or(0))))
        };
        let switch_on: Vec<(u8, u32)> = servos()
            .filter(|&(ch, _, q)| q != 0 && !on[ch])
            .map(|(_, id, _)| (id, 1))
            .collect();
        let switch_off: Vec<(u8, u32)> = servos()
            .filter(|&(ch, _, q)| q == 0 && on[ch])
            .map(|(_, id, _)| (id, 0))
            .collect();
        let goals: Vec<(u8, u32)> = servos()
            .filter(|&(_, _, q)| q != 0)
            .map(|(_, id, q)| (id, (f64::from(q) / 4.0).round() as u32))
            .collect();
        for (ch, _, q) in servos() {
            on[ch] = q != 0;
        }
        for (items, address) in [
            (switch_on, torque_at),
            (switch_off, torque_at),
            (goals, goal_at),
        ] {
            if !items.is_empty() {
                out.push(SyncWrite { address, items });
            }
        }
    }
    out
}
