//! Serial bus servos as a servo output: ROBOTIS Dynamixel (Protocol 2.0)
//! and Feetech SCS/STS on a half-duplex UART.
//!
//! The rig gives each servo channel a bus ID ([`ServoDesc::id`]); the
//! targets are positions in quarter units (the slew limiter's unit, as
//! quarter-µs are for the pulse back-ends), rounded to whole positions on
//! the wire. One [`ServoOutput::write`] sends, in this order and only when
//! needed:
//!
//! 1. a Sync Write of Torque Enable = 1 to the servos that get a position
//!    and are not known to have torque on (all of them on the first frame:
//!    a Dynamixel X starts with torque off, and ignores goals until on);
//! 2. a Sync Write of Torque Enable = 0 to the servos whose target is 0
//!    (the "no pulse" of every back-end: the rig's `idle = "off"`) and
//!    whose torque is on;
//! 3. one Sync Write of Goal Position to every servo with a target.
//!
//! Nothing is read back: the instruction packets are broadcast, so no
//! servo answers and the bus needs no turn-around.
//!
//! ## Bandwidth
//!
//! A Goal Position Sync Write to `n` servos is `14 + 5n` bytes on a
//! Dynamixel bus (at most a few more with byte stuffing) and `8 + 3n` on a
//! Feetech bus. At 10 bits per byte (8N1), 16 servos take 94 bytes,
//! 940 µs at 1 Mbaud (Dynamixel) and 56 bytes, 560 µs at 1 Mbaud
//! (Feetech); at the Dynamixel's factory 57 600 baud, 16.3 ms.
//! [`frame_bytes`] gives the count for a rig.

use embedded_io::Write;

use super::maestro::write_all;
use super::{OutputError, dynamixel, feetech};
use crate::rig::{FeetechSeries, MAX_SERVOS, ServoDesc};

/// The packet format of a bus.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Protocol {
    /// ROBOTIS Dynamixel Protocol 2.0 (X series control table).
    Dynamixel,
    /// Feetech SCS/STS, with its byte order.
    Feetech(FeetechSeries),
}

impl Protocol {
    /// Bytes of one Goal Position Sync Write to `n` servos (without
    /// Dynamixel byte stuffing, which valid positions never need).
    #[must_use]
    pub const fn frame_bytes(self, n: usize) -> usize {
        match self {
            // Header 4, ID, length 2, instruction, address 2, length 2, CRC 2.
            Protocol::Dynamixel => 14 + (1 + dynamixel::GOAL_POSITION_LEN) * n,
            // Header 2, ID, length, instruction, address, length, checksum.
            Protocol::Feetech(_) => 8 + (1 + feetech::GOAL_POSITION_LEN) * n,
        }
    }

    /// Writes a Sync Write of `data_len` bytes at `address` to `items`.
    fn sync_write<'i>(
        self,
        address: u8,
        data_len: usize,
        items: impl IntoIterator<Item = (u8, &'i [u8])>,
        out: &mut [u8],
    ) -> Option<usize> {
        match self {
            Protocol::Dynamixel => dynamixel::sync_write(u16::from(address), data_len, items, out),
            Protocol::Feetech(_) => feetech::sync_write(address, data_len, items, out),
        }
    }

    /// (Torque Enable, Goal Position) addresses and the position's bytes.
    const fn registers(self) -> (u8, u8, usize) {
        match self {
            Protocol::Dynamixel => (
                dynamixel::TORQUE_ENABLE as u8,
                dynamixel::GOAL_POSITION as u8,
                dynamixel::GOAL_POSITION_LEN,
            ),
            Protocol::Feetech(_) => (
                feetech::TORQUE_ENABLE,
                feetech::GOAL_POSITION,
                feetech::GOAL_POSITION_LEN,
            ),
        }
    }

    /// A position as the Goal Position register's bytes.
    fn position_bytes(self, position: u16) -> [u8; 4] {
        match self {
            Protocol::Dynamixel => u32::from(position).to_le_bytes(),
            Protocol::Feetech(series) => {
                let [a, b] = feetech::word(series, position);
                [a, b, 0, 0]
            }
        }
    }
}

/// Bytes of one Goal Position frame for the servos of a rig.
#[must_use]
pub fn frame_bytes(protocol: Protocol, servos: &[ServoDesc]) -> usize {
    protocol.frame_bytes(servos.len())
}

/// A target in quarter units as a whole position (rounded to nearest).
#[inline]
#[must_use]
pub const fn position(target_q: u16) -> u16 {
    target_q.saturating_add(2) / 4
}

/// The bytes of the largest packet: 24 servos of 5 bytes, with room for
/// Dynamixel byte stuffing (at most one byte in three).
const BUFFER: usize = 256;

/// The servos of one bus: their IDs by channel and what is known of their
/// torque. Sends through the UART it is given on each write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BusServos {
    protocol: Protocol,
    ids: [Option<u8>; MAX_SERVOS],
    torque: u32,
}

impl BusServos {
    /// The servos of a rig (channel → `id`), torque assumed off.
    #[must_use]
    pub fn new(protocol: Protocol, servos: &[ServoDesc]) -> Self {
        let mut ids = [None; MAX_SERVOS];
        for s in servos {
            if let Some(slot) = ids.get_mut(usize::from(s.channel)) {
                *slot = Some(s.id);
            }
        }
        Self {
            protocol,
            ids,
            torque: 0,
        }
    }

    /// The packet format.
    #[must_use]
    pub fn protocol(&self) -> Protocol {
        self.protocol
    }

    /// Sends one frame: torque changes, then the goal positions (see the
    /// module doc). Channels without a servo are skipped.
    pub fn write<W: Write>(
        &mut self,
        uart: &mut W,
        targets: &[u16],
    ) -> Result<(), OutputError<W::Error>> {
        if targets.len() > MAX_SERVOS {
            return Err(OutputError::TooManyTargets {
                given: targets.len(),
                channels: MAX_SERVOS,
            });
        }
        let (torque_at, goal_at, goal_len) = self.protocol.registers();
        let on = self.changed(targets, true);
        self.send(uart, torque_at, 1, on, |_| [1, 0, 0, 0])?;
        let off = self.changed(targets, false);
        self.send(uart, torque_at, 1, off, |_| [0; 4])?;
        self.torque = (self.torque | on) & !off;
        let protocol = self.protocol;
        let moving = self.with_target(targets);
        self.send(uart, goal_at, goal_len, moving, |ch| {
            let t = targets.get(ch).copied().unwrap_or(0);
            protocol.position_bytes(position(t))
        })
    }

    /// One Sync Write of `len` bytes at `address` to the servos of the
    /// channels in `mask` (nothing if it is empty), each its `data(channel)`.
    fn send<W: Write>(
        &self,
        uart: &mut W,
        address: u8,
        len: usize,
        mask: u32,
        data: impl Fn(usize) -> [u8; 4],
    ) -> Result<(), OutputError<W::Error>> {
        if mask == 0 {
            return Ok(());
        }
        let mut items = [(0u8, [0u8; 4]); MAX_SERVOS];
        let mut n = 0;
        for (ch, id) in self.ids.iter().enumerate() {
            if let (Some(id), true) = (id, mask & (1u32 << ch) != 0)
                && let Some(slot) = items.get_mut(n)
            {
                *slot = (*id, data(ch));
                n += 1;
            }
        }
        let chosen = items.get(..n).unwrap_or(&[]);
        let mut buf = [0u8; BUFFER];
        let bytes = self
            .protocol
            .sync_write(
                address,
                len,
                chosen.iter().map(|(id, d)| (*id, &d[..])),
                &mut buf,
            )
            .ok_or(OutputError::Rejected)?;
        write_all(uart, buf.get(..bytes).unwrap_or(&[]))
    }

    /// Channels (a bit each) with a servo whose torque must change: to on
    /// (`on`: a target, torque not on) or to off (target 0, torque on).
    fn changed(&self, targets: &[u16], on: bool) -> u32 {
        let mut mask = 0;
        for (ch, (&t, id)) in targets.iter().zip(&self.ids).enumerate() {
            let bit = 1u32 << ch;
            let torque = self.torque & bit != 0;
            if id.is_some() && (t != 0) == on && torque != on {
                mask |= bit;
            }
        }
        mask
    }

    /// Channels with a servo and a target.
    fn with_target(&self, targets: &[u16]) -> u32 {
        let mut mask = 0;
        for (ch, (&t, id)) in targets.iter().zip(&self.ids).enumerate() {
            if id.is_some() && t != 0 {
                mask |= 1u32 << ch;
            }
        }
        mask
    }
}
