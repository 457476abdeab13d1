//! The boards Marionette's firmware runs on, as the host needs to know them:
//! how big each one's table region is, how many segments its firmware
//! holds, and which servo back-ends it drives.
//!
//! The segment capacity is the core's [`FIRMWARE_SEGMENTS`] (the shipped
//! firmware's `app::SEGMENTS`) and the back-ends are each board's
//! [`Support`], the very rule the firmware applies when it is asked to
//! arm; only the table region sizes are restated here (from
//! `firmware/boards/*/memory.x`, checked by a test), so that
//! `marionette build`, `rig check` and `inspect` can say before anything
//! is flashed whether a rig and a table fit a board. The tests boot the
//! emulated board with rigs of 24 and 25 segments and of each back-end, and
//! it must arm or refuse exactly as [`Board::verdict`] predicts.

use marionette_core::output::Support;
use marionette_core::region::FIRMWARE_SEGMENTS;
use marionette_core::rig::{FeetechSeries, Output, ServoDesc};

/// One board.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Board {
    /// Short name, as `--board` takes it.
    pub key: &'static str,
    /// What it is, for messages.
    pub name: &'static str,
    /// Bytes of the table region (rig blob + table blob).
    pub table_region: usize,
    /// Most segments of a rig its firmware drives.
    pub segments: usize,
    /// The servo back-ends it drives (the firmware's `Board::SUPPORT`).
    pub support: Support,
}

/// The emulated board (QEMU `mps2-an386`): table region at `0x0010_0000`.
pub const EMULATED: Board = Board {
    key: "emulated",
    name: "the emulated board (QEMU mps2-an386)",
    table_region: crate::qemu::TABLE_REGION_LEN,
    segments: FIRMWARE_SEGMENTS,
    support: Support::EMULATED,
};

/// The STM32F411 Black Pill: table region in flash sectors 6–7.
pub const BLACKPILL: Board = Board {
    key: "blackpill",
    name: "the Black Pill (STM32F411)",
    table_region: crate::flash::BLACKPILL.tables.size as usize,
    segments: FIRMWARE_SEGMENTS,
    support: crate::flash::BLACKPILL.support,
};

/// Every board, emulated first.
pub const BOARDS: [Board; 2] = [EMULATED, BLACKPILL];

/// Whether a rig fits a board, and why not.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Verdict {
    /// The board's key.
    pub board: &'static str,
    /// Whether the rig (and table, if given) can arm it.
    pub fits: bool,
    /// Every reason it cannot (empty when it fits).
    pub problems: Vec<String>,
    /// Bytes of the table region used (rig blob + padding + table), and its size.
    pub region_bytes: [usize; 2],
}

impl Board {
    /// Looks a board up by its key.
    #[must_use]
    pub fn by_key(key: &str) -> Option<Board> {
        BOARDS.iter().copied().find(|b| b.key == key)
    }

    /// Why the board's firmware cannot drive these servos on this back-end
    /// ([`Support::check`], in words), or `None` if it can.
    #[must_use]
    pub fn refuses(&self, output: &Output, servos: &[ServoDesc]) -> Option<String> {
        self.support
            .check(output, servos)
            .err()
            .map(|r| format!("[output] {}: {r}", describe_output(output)))
    }

    /// Whether a rig of `segments` segments whose `servos` are driven by
    /// `output`, whose rig blob is `rig_blob` bytes, with a table of `table`
    /// bytes (if any), can arm this board.
    #[must_use]
    pub fn verdict(
        &self,
        segments: usize,
        (output, servos): (&Output, &[ServoDesc]),
        rig_blob: usize,
        table: Option<usize>,
    ) -> Verdict {
        let mut problems = Vec::new();
        if segments > self.segments {
            problems.push(format!(
                "{segments} segments; its firmware holds at most {}",
                self.segments
            ));
        }
        problems.extend(self.refuses(output, servos));
        let used = crate::capacity::region_bytes(rig_blob as u64, table.unwrap_or(0) as u64);
        let used = usize::try_from(used).unwrap_or(usize::MAX);
        if used > self.table_region {
            problems.push(format!(
                "rig blob {rig_blob} B + table {} B = a region of {used} B, over its {} B table region",
                table.unwrap_or(0),
                self.table_region
            ));
        }
        Verdict {
            board: self.key,
            fits: problems.is_empty(),
            problems,
            region_bytes: [used, self.table_region],
        }
    }
}

/// A back-end in words: `maestro at 115200 baud`.
#[must_use]
pub fn describe_output(output: &Output) -> String {
    match output {
        Output::Maestro { baud } => format!("maestro at {baud} baud"),
        Output::Pca9685 { i2c_addr, freq_hz } => {
            format!("pca9685 at I2C {i2c_addr:#04x}, {freq_hz} Hz")
        }
        Output::Pwm { freq_hz } => format!("pwm at {freq_hz} Hz"),
        Output::Dynamixel { baud } => format!("dynamixel at {baud} baud"),
        Output::Feetech { baud, series } => {
            let series = match series {
                FeetechSeries::Sts => "sts",
                FeetechSeries::Scs => "scs",
            };
            format!("feetech ({series}) at {baud} baud")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regions_are_the_memory_maps() {
        // firmware/boards/qemu-an386/memory.x: TABLES 1M; blackpill: 256K.
        assert_eq!(EMULATED.table_region, 1 << 20);
        assert_eq!(BLACKPILL.table_region, 256 * 1024);
    }

    #[test]
    fn a_verdict_lists_every_problem() {
        let pwm = Output::Pwm { freq_hz: 50 };
        let ch12 = [ServoDesc {
            channel: 12,
            ..ServoDesc::default()
        }];
        // Black Pill: 12 PWM channels (0..12), 24 segments, 256 KiB.
        let v = BLACKPILL.verdict(25, (&pwm, &ch12), 5000, Some(300 * 1024));
        assert!(!v.fits);
        assert_eq!(v.problems.len(), 3, "{:?}", v.problems);
        assert!(v.problems[1].contains("channel 12"), "{:?}", v.problems);
        let ok = EMULATED.verdict(13, (&Output::default(), &[]), 5001, Some(1000));
        assert!(ok.fits, "{:?}", ok.problems);
        assert_eq!(ok.region_bytes, [36 + 5004 + 1000, 1 << 20]);
        // 3 Mbaud: 50 MHz / 17 is 1.9 % off; the emulated UART takes any rate.
        let fast = Output::Maestro { baud: 3_000_000 };
        assert!(EMULATED.refuses(&fast, &[]).is_none());
        assert!(
            BLACKPILL
                .refuses(&fast, &[])
                .unwrap()
                .contains("3000000 baud")
        );
        assert!(EMULATED.refuses(&pwm, &[]).unwrap().contains("`pwm`"));
    }
}
