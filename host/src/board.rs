//! The boards Marionette's firmware runs on, as the host needs to know them:
//! how big each one's table region is, how many segments its firmware
//! holds, and which servo back-ends it drives.
//!
//! These are facts of the firmware (`firmware/boards/*/memory.x`,
//! `firmware/src/app.rs`'s `SEGMENTS`, each board's `Board::supports`),
//! restated here so that `marionette build`, `rig check` and `inspect` can
//! say before anything is flashed whether a rig and a table fit a board.
//! The tests check them against the firmware itself: the emulated board is
//! booted with rigs of each back-end and of 24 and 25 segments, and must
//! arm or refuse exactly as [`Board::verdict`] predicts.

use marionette_core::rig::Output;

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
    /// Servo back-ends (`[output] kind`) it drives.
    outputs: &'static [&'static str],
    /// The only Maestro baud rate it drives, if it has one.
    maestro_baud: Option<u32>,
}

/// The emulated board (QEMU `mps2-an386`): table region at `0x0010_0000`.
pub const EMULATED: Board = Board {
    key: "emulated",
    name: "the emulated board (QEMU mps2-an386)",
    table_region: crate::qemu::TABLE_REGION_LEN,
    segments: 24,
    outputs: &["maestro"],
    maestro_baud: None,
};

/// The STM32F411 Black Pill: table region in flash sectors 6–7.
pub const BLACKPILL: Board = Board {
    key: "blackpill",
    name: "the Black Pill (STM32F411)",
    table_region: crate::flash::BLACKPILL.tables.size as usize,
    segments: 24,
    outputs: &["maestro"],
    maestro_baud: Some(115_200),
};

/// Every board, emulated first.
pub const BOARDS: [Board; 2] = [EMULATED, BLACKPILL];

/// The `[output] kind` word of a back-end.
#[must_use]
pub fn output_kind(output: &Output) -> &'static str {
    match output {
        Output::Pwm { .. } => "pwm",
        Output::Pca9685 { .. } => "pca9685",
        Output::Maestro { .. } => "maestro",
        #[allow(unreachable_patterns)]
        _ => "other",
    }
}

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

    /// Whether the board's firmware drives this servo back-end.
    #[must_use]
    pub fn drives(&self, output: &Output) -> bool {
        let kind = output_kind(output);
        let baud_ok = match (output, self.maestro_baud) {
            (Output::Maestro { baud }, Some(only)) => *baud == only,
            _ => true,
        };
        self.outputs.contains(&kind) && baud_ok
    }

    /// What the board's firmware drives, in words.
    #[must_use]
    pub fn drives_text(&self) -> String {
        self.outputs
            .iter()
            .map(|k| match (*k, self.maestro_baud) {
                ("maestro", Some(b)) => format!("maestro at {b} baud"),
                ("maestro", None) => "maestro at any baud".to_owned(),
                (k, _) => k.to_owned(),
            })
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// Whether a rig of `segments` segments driving `output`, whose rig blob
    /// is `rig_blob` bytes, with a table of `table` bytes (if any), can arm
    /// this board.
    #[must_use]
    pub fn verdict(
        &self,
        segments: usize,
        output: &Output,
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
        if !self.drives(output) {
            problems.push(format!(
                "[output] {} is not a back-end it drives ({})",
                describe_output(output),
                self.drives_text()
            ));
        }
        let used = rig_blob.next_multiple_of(4) + table.unwrap_or(0);
        if used > self.table_region {
            problems.push(format!(
                "rig blob {rig_blob} B + table {} B = {used} B exceeds its {} B table region",
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
        #[allow(unreachable_patterns)]
        other => format!("{other:?}"),
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
        let pca = Output::Pca9685 {
            i2c_addr: 0x40,
            freq_hz: 50,
        };
        let v = BLACKPILL.verdict(25, &pca, 5000, Some(300 * 1024));
        assert!(!v.fits);
        assert_eq!(v.problems.len(), 3, "{:?}", v.problems);
        let ok = EMULATED.verdict(13, &Output::default(), 5001, Some(1000));
        assert!(ok.fits, "{:?}", ok.problems);
        assert_eq!(ok.region_bytes, [5004 + 1000, 1 << 20]);
        let slow = Output::Maestro { baud: 9600 };
        assert!(EMULATED.drives(&slow) && !BLACKPILL.drives(&slow));
    }
}
