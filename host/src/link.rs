//! Link budgets: how many tracker frames a second a serial link carries.
//!
//! A frame's cost is its bytes on the wire, counted from the encoder itself
//! ([`frame_bytes`]: the worst case of each framing, every varint at its
//! longest). What a link carries:
//!
//! - **UART, 8N1**: 10 bits per byte (start, 8 data, stop), so `baud / 10`
//!   bytes a second, back to back.
//! - **USB full speed, CDC-ACM** ([`Link::UsbFs`]): the data goes in bulk
//!   transfers of 64-byte packets; a full-speed bus has a 1 ms frame, and
//!   the USB 2.0 specification (§5.8.4, table 5-9) allows at most 19 bulk
//!   transactions of 64 bytes per frame on an otherwise idle bus (1,216
//!   bytes/ms). Assumed here: the host writes each tracker frame as its own
//!   transfer (as a real-time sender must), so a frame of `B` bytes takes
//!   `⌈B/64⌉` packets whatever its size, and the host controller schedules
//!   the full 19 packets a millisecond. Real controllers often schedule
//!   fewer, other devices on the bus take their share, and the board's own
//!   loop (1 kHz) is the tighter bound in practice.

use marionette_core::wire::{self, List, MAX_FRAME, Sensor, TrackerFrame};

use crate::perform::Framing;

/// A link a board can read tracker frames from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Link {
    /// A UART with 8N1 framing at this many bit/s.
    Uart {
        /// Bits per second.
        baud: u32,
    },
    /// USB full speed, CDC-ACM (bulk, 64-byte packets).
    UsbFs,
}

/// Bulk packets of 64 bytes per 1 ms USB full-speed frame, at most.
pub const USB_FS_PACKETS_PER_MS: u32 = 19;
/// A USB full-speed bulk packet's payload, bytes.
pub const USB_FS_PACKET: usize = 64;

impl Link {
    /// The Black Pill's USART1 as the firmware sets it up.
    pub const UART_921600: Self = Self::Uart { baud: 921_600 };
    /// A UART at 2 Mbit/s.
    pub const UART_2M: Self = Self::Uart { baud: 2_000_000 };

    /// Bytes a second the link carries, at most (for USB: 19 full packets
    /// a millisecond).
    #[must_use]
    pub fn bytes_per_second(self) -> f64 {
        match self {
            Self::Uart { baud } => f64::from(baud) / 10.0,
            Self::UsbFs => f64::from(USB_FS_PACKETS_PER_MS) * USB_FS_PACKET as f64 * 1000.0,
        }
    }

    /// The most frames of `bytes` bytes a second (whole frames).
    #[must_use]
    pub fn max_frames_per_second(self, bytes: usize) -> u32 {
        let bytes = bytes.max(1);
        match self {
            Self::Uart { baud } => baud / 10 / u32::try_from(bytes).unwrap_or(u32::MAX),
            Self::UsbFs => {
                let packets = u32::try_from(bytes.div_ceil(USB_FS_PACKET)).unwrap_or(u32::MAX);
                USB_FS_PACKETS_PER_MS * 1000 / packets
            }
        }
    }

    /// The share of the link a stream of `bytes`-byte frames at `hz`
    /// takes (1.0 = all of it).
    #[must_use]
    pub fn load(self, bytes: usize, hz: f64) -> f64 {
        match self {
            Self::Uart { .. } => bytes as f64 * hz / self.bytes_per_second(),
            Self::UsbFs => {
                let packets = bytes.div_ceil(USB_FS_PACKET) as f64;
                packets * hz / (f64::from(USB_FS_PACKETS_PER_MS) * 1000.0)
            }
        }
    }

    /// A short name for tables and reports.
    #[must_use]
    pub fn name(self) -> String {
        match self {
            Self::Uart { baud } => format!("UART {baud} baud"),
            Self::UsbFs => "USB FS CDC-ACM".into(),
        }
    }
}

/// The longest encoded frame (COBS, CRC and delimiter included) of `n`
/// sensors in `framing`: sequence number and time at their longest
/// varints, every value with no zero byte (COBS's worst case).
#[must_use]
pub fn frame_bytes(n: usize, framing: Framing) -> usize {
    let sensor = |id| Sensor {
        id,
        position: [0.3, -0.3, 1.3],
        rotation: [0.5, 0.5, -0.5, 0.5],
    };
    let sensors: Vec<Sensor> = (0..16u8).map(sensor).take(n).collect();
    let frame = TrackerFrame {
        seq: u32::MAX,
        time_us: u32::MAX,
        sensors: List::from_slice(&sensors).unwrap_or_default(),
    };
    let msg = crate::perform::tracker_message(&frame, framing);
    let mut out = [0u8; MAX_FRAME];
    wire::encode(&msg, &mut out).map_or(MAX_FRAME, <[u8]>::len)
}

/// The README's link-budget table: bytes per frame and the highest frame
/// rate on each link, for 1, 3, 6 and 16 sensors in both framings, and the
/// share of a 921,600-baud UART a 1 kHz stream takes.
#[must_use]
pub fn budget_table() -> String {
    let links = [Link::UART_921600, Link::UART_2M, Link::UsbFs];
    let mut s = String::from(
        "| sensors | frame | bytes per frame | max Hz, UART 921,600 | max Hz, UART 2 Mbaud \
         | max Hz, USB FS CDC-ACM | 1 kHz on UART 921,600 |\n\
         |---:|---|---:|---:|---:|---:|---:|\n",
    );
    for n in [1, 3, 6, 16] {
        for framing in [Framing::Compact, Framing::F32] {
            let bytes = frame_bytes(n, framing);
            let rates: Vec<String> = links
                .iter()
                .map(|l| l.max_frames_per_second(bytes).to_string())
                .collect();
            let name = match framing {
                Framing::Compact => "compact (tag 7)",
                Framing::F32 => "f32 (tag 1)",
            };
            s.push_str(&format!(
                "| {n} | {name} | {bytes} | {} | {:.1} % |\n",
                rates.join(" | "),
                Link::UART_921600.load(bytes, 1000.0) * 100.0
            ));
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_worked_rates() {
        // 46 bytes at 92,160 B/s: 2003 frames; 101 bytes: 912 (DESIGN §8).
        assert_eq!(Link::UART_921600.max_frames_per_second(46), 2003);
        assert_eq!(Link::UART_921600.max_frames_per_second(101), 912);
        assert_eq!(Link::UART_2M.max_frames_per_second(100), 2000);
        // 65 bytes: 2 packets, 9,500 a second.
        assert_eq!(Link::UsbFs.max_frames_per_second(65), 9500);
        assert_eq!(Link::UsbFs.max_frames_per_second(64), 19_000);
        assert!((Link::UART_921600.load(46, 1000.0) - 46_000.0 / 92_160.0).abs() < 1e-12);
    }
}
