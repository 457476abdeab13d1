//! Pololu Maestro servo controllers on a UART ([`embedded_io::Write`]).
//!
//! ## Commands (Pololu Maestro user's guide, compact protocol)
//!
//! - **Set Target** (every Maestro): `0x84, channel, target & 0x7F,
//!   (target >> 7) & 0x7F`, target in quarter-µs ([`crate::servo::maestro`]).
//! - **Set Multiple Targets** (Mini Maestro 12, 18 and 24 only): `0x9F, count,
//!   first channel`, then each target as `target & 0x7F, (target >> 7) & 0x7F`,
//!   for `count` consecutive channels.
//!
//! A target of 0 tells the Maestro to stop sending pulses on that channel.
//! Targets above the 14-bit maximum (0x3FFF) are clamped to it rather than
//! masked, so an out-of-range value can never wrap to 0 and drop a servo.
//!
//! ## Bandwidth
//!
//! A UART byte is 10 bits (8N1). At 115 200 baud, Set Target for 16 channels is
//! 64 bytes = 640 bits = 5.56 ms; Set Multiple Targets is 3 + 32 = 35 bytes =
//! 3.04 ms. Either is several periods of a 1 kHz loop, so the loop must
//! decimate the Maestro output: wrap it in [`super::Decimated`] with
//! `frames_per_write(loop_hz, frame_time_us(frame_bytes(n, command), baud))`
//! (6 and 4 at 1 kHz for the two cases above). The Maestro itself only pulses
//! its servos every 20 ms by default.
//!
//! A frame is handed to the UART in one `write` loop and not flushed: with a
//! blocking UART driver the loop still waits for the bytes to leave, so give the
//! Maestro a buffered (interrupt or DMA) writer.

use core::num::NonZeroU64;

use embedded_io::Write;

use super::{OutputError, ServoOutput};
use crate::servo::maestro::{TARGET_MAX, set_target};

/// The compact-protocol command byte for Set Multiple Targets.
pub const SET_MULTIPLE_TARGETS: u8 = 0x9F;
/// The most channels on one Maestro (the Mini Maestro 24).
pub const MAX_CHANNELS: usize = 24;
/// Bits on the wire per UART byte (start, 8 data, stop).
pub const BITS_PER_BYTE: u32 = 10;

/// How a frame is sent.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Command {
    /// One Set Target (4 bytes) per channel; every Maestro.
    SetTarget,
    /// One Set Multiple Targets (3 + 2 per channel bytes); Mini Maestro only.
    SetMultipleTargets,
}

/// Bytes in a frame of `channels` targets sent with `command`.
#[inline]
#[must_use]
pub const fn frame_bytes(channels: usize, command: Command) -> usize {
    match command {
        Command::SetTarget => 4 * channels,
        Command::SetMultipleTargets if channels == 0 => 0,
        Command::SetMultipleTargets => 3 + 2 * channels,
    }
}

/// The time `bytes` take on a UART at `baud`, µs, rounded up
/// (`u32::MAX` for baud 0).
#[inline]
#[must_use]
pub fn frame_time_us(bytes: usize, baud: u32) -> u32 {
    let Some(baud) = NonZeroU64::new(u64::from(baud)) else {
        return u32::MAX;
    };
    let bits = u64::try_from(bytes)
        .unwrap_or(u64::MAX)
        .saturating_mul(u64::from(BITS_PER_BYTE));
    let us = bits
        .saturating_mul(1_000_000)
        .saturating_add(baud.get() - 1)
        / baud;
    u32::try_from(us).unwrap_or(u32::MAX)
}

/// The Set Multiple Targets header for `count` channels from `first`.
#[inline]
#[must_use]
pub const fn set_multiple_header(count: u8, first: u8) -> [u8; 3] {
    [SET_MULTIPLE_TARGETS, count & 0x7F, first & 0x7F]
}

/// A target as the two 7-bit bytes of the protocol, clamped to 0x3FFF.
#[inline]
#[must_use]
pub const fn target_bytes(target: u16) -> [u8; 2] {
    let t = if target > TARGET_MAX {
        TARGET_MAX
    } else {
        target
    };
    [(t & 0x7F) as u8, ((t >> 7) & 0x7F) as u8]
}

/// Servos on a Maestro: `targets[i]` drives channel `i` (up to 24).
#[derive(Debug)]
pub struct Maestro<W> {
    uart: W,
    command: Command,
}

impl<W: Write> Maestro<W> {
    /// A Maestro on `uart` (already set to the Maestro's baud rate), sent
    /// frames with `command`.
    #[must_use]
    pub fn new(uart: W, command: Command) -> Self {
        Self { uart, command }
    }

    /// The command frames are sent with.
    #[must_use]
    pub fn command(&self) -> Command {
        self.command
    }

    /// Gives back the UART.
    #[must_use]
    pub fn release(self) -> W {
        self.uart
    }
}

impl<W: Write> ServoOutput for Maestro<W> {
    type Error = OutputError<W::Error>;

    /// Encodes the frame into a stack buffer and writes it in one loop.
    fn write(&mut self, targets: &[u16]) -> Result<(), Self::Error> {
        if targets.len() > MAX_CHANNELS {
            return Err(OutputError::TooManyTargets {
                given: targets.len(),
                channels: MAX_CHANNELS,
            });
        }
        let mut buf = [0u8; 4 * MAX_CHANNELS];
        let len = match self.command {
            Command::SetTarget => encode_set_targets(targets, &mut buf),
            Command::SetMultipleTargets => encode_set_multiple(targets, &mut buf),
        };
        write_all(&mut self.uart, buf.get(..len).unwrap_or(&[]))
    }
}

/// Writes Set Target for each target into `buf`; returns the bytes used.
fn encode_set_targets(targets: &[u16], buf: &mut [u8; 4 * MAX_CHANNELS]) -> usize {
    let mut len = 0;
    for ((ch, &t), out) in (0u8..).zip(targets).zip(buf.chunks_exact_mut(4)) {
        out.copy_from_slice(&set_target(ch, t.min(TARGET_MAX)));
        len += 4;
    }
    len
}

/// Writes one Set Multiple Targets into `buf`; returns the bytes used.
fn encode_set_multiple(targets: &[u16], buf: &mut [u8; 4 * MAX_CHANNELS]) -> usize {
    let Ok(count) = u8::try_from(targets.len()) else {
        return 0;
    };
    if count == 0 {
        return 0;
    }
    let (head, body) = buf.split_at_mut(3);
    head.copy_from_slice(&set_multiple_header(count, 0));
    let mut len = 3;
    for (&t, out) in targets.iter().zip(body.chunks_exact_mut(2)) {
        out.copy_from_slice(&target_bytes(t));
        len += 2;
    }
    len
}

/// `write` until `bytes` are all taken; unlike `Write::write_all`, a writer
/// that takes nothing is an error, not a panic.
pub(super) fn write_all<W: Write>(
    uart: &mut W,
    mut bytes: &[u8],
) -> Result<(), OutputError<W::Error>> {
    while !bytes.is_empty() {
        match uart.write(bytes) {
            Ok(0) => return Err(OutputError::WriteZero),
            Ok(n) => bytes = bytes.get(n..).unwrap_or(&[]),
            Err(e) => return Err(OutputError::Bus(e)),
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec::Vec;

    /// A UART that takes at most `chunk` bytes per call (0: refuses all).
    struct Uart {
        sent: Vec<u8>,
        chunk: usize,
    }

    impl embedded_io::ErrorType for Uart {
        type Error = core::convert::Infallible;
    }

    impl Write for Uart {
        fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
            let n = buf.len().min(self.chunk);
            self.sent.extend_from_slice(&buf[..n]);
            Ok(n)
        }
        fn flush(&mut self) -> Result<(), Self::Error> {
            Ok(())
        }
    }

    fn uart(chunk: usize) -> Uart {
        Uart {
            sent: Vec::new(),
            chunk,
        }
    }

    #[test]
    fn set_target_frames_match_the_manual_encoding() {
        // 1500 µs = 6000 = 0x1770 -> 0x70, 0x2E (the Pololu guide's example);
        // 1000 µs = 4000 = 0xFA0 -> 0x20, 0x1F; 0 stops the pulses.
        let mut m = Maestro::new(uart(3), Command::SetTarget);
        m.write(&[6000, 4000, 0]).unwrap();
        assert_eq!(
            m.release().sent,
            [
                0x84, 0x00, 0x70, 0x2E, 0x84, 0x01, 0x20, 0x1F, 0x84, 0x02, 0x00, 0x00
            ]
        );
    }

    #[test]
    fn set_multiple_targets_frame_matches_the_manual_encoding() {
        // 2000 µs = 8000 = 0x1F40 -> 0x40, 0x3E. 0xFFFF clamps to 0x3FFF.
        let mut m = Maestro::new(uart(64), Command::SetMultipleTargets);
        m.write(&[6000, 8000, 0xFFFF]).unwrap();
        assert_eq!(
            m.release().sent,
            [0x9F, 0x03, 0x00, 0x70, 0x2E, 0x40, 0x3E, 0x7F, 0x7F]
        );
        let mut m = Maestro::new(uart(64), Command::SetMultipleTargets);
        m.write(&[]).unwrap();
        assert!(m.release().sent.is_empty());
    }

    #[test]
    fn a_full_maestro_24_frame_and_the_limits() {
        let mut m = Maestro::new(uart(7), Command::SetTarget);
        m.write(&[6000; 24]).unwrap();
        let sent = m.release().sent;
        assert_eq!(sent.len(), 96);
        assert_eq!(&sent[92..], &[0x84, 23, 0x70, 0x2E]);
        let mut m = Maestro::new(uart(7), Command::SetTarget);
        assert_eq!(
            m.write(&[6000; 25]),
            Err(OutputError::TooManyTargets {
                given: 25,
                channels: 24
            })
        );
        let mut m = Maestro::new(uart(0), Command::SetTarget);
        assert_eq!(m.write(&[6000]), Err(OutputError::WriteZero));
    }

    #[test]
    fn bandwidth_worked_by_hand() {
        assert_eq!(frame_bytes(16, Command::SetTarget), 64);
        assert_eq!(frame_bytes(16, Command::SetMultipleTargets), 35);
        assert_eq!(frame_bytes(0, Command::SetMultipleTargets), 0);
        // 640 bits at 115 200 baud = 5555.6 µs -> 5556; 350 bits = 3038.2 -> 3039.
        assert_eq!(frame_time_us(64, 115_200), 5556);
        assert_eq!(frame_time_us(35, 115_200), 3039);
        // 10 bytes at 100 000 baud is exactly 1000 µs.
        assert_eq!(frame_time_us(10, 100_000), 1000);
        assert_eq!(frame_time_us(1, 0), u32::MAX);
        assert_eq!(crate::output::frames_per_write(1000, 5556), 6);
        assert_eq!(crate::output::frames_per_write(1000, 3039), 4);
    }
}
