//! The table region: the rig blob and the table blob as flashed, read in
//! place and validated together.
//!
//! A board keeps one region of flash (or emulated memory) for what it
//! performs: the rig blob ([`crate::rig`]), zero padding to the next 4-byte
//! boundary, then the table blob ([`crate::table`]). [`Region::parse`]
//! validates both and says why the board cannot arm if it cannot
//! ([`StatusReason`]).

use crate::pose::MAX_SEGMENTS;
use crate::rig::MAX_PARAMS;
use crate::rig::{Rig, RigError};
use crate::table::{Kind, Table, TableError};
use crate::wire::StatusReason;

/// The validated contents of the table region: the rig blob, then the table
/// blob at the next 4-byte boundary. The rig has capacity `N` (see
/// [Capacity](crate::frame#capacity)).
#[derive(Clone, Debug)]
pub struct Region<'a, const N: usize = MAX_SEGMENTS> {
    /// The rig, if its blob is valid (and fits the capacity).
    pub rig: Option<Rig<'a, N>>,
    /// The table, if its blob is valid and matches the rig.
    pub table: Option<Table<'a>>,
    /// Why the board cannot arm ([`StatusReason::Ok`] if it can).
    pub reason: StatusReason,
}

impl<'a> Region<'a> {
    /// Validates a table region (magic, version, CRC and bounds of both
    /// blobs, and that the table was built for this rig), at the rig
    /// format's capacity; [`Region::parse_sized`] reads it into a smaller
    /// rig.
    #[must_use]
    pub fn parse(bytes: &'a [u8]) -> Self {
        Self::parse_sized(bytes)
    }
}

impl<'a, const N: usize> Region<'a, N> {
    /// [`Region::parse`] with a rig of capacity `N`: a valid rig with more
    /// segments is refused with [`StatusReason::RigTooLarge`].
    #[must_use]
    pub fn parse_sized(bytes: &'a [u8]) -> Self {
        let mut region = Self::EMPTY;
        region.parse_into(bytes);
        region
    }

    /// No rig and no table ([`StatusReason::NoRig`]): where
    /// [`Region::parse_into`] starts.
    pub const EMPTY: Self = Self {
        rig: None,
        table: None,
        reason: StatusReason::NoRig,
    };

    /// [`Region::parse_sized`] in place, for a caller that keeps the region
    /// where it is: the rig is kilobytes, and every move is a copy on the
    /// stack. Never inlined: the decoding's temporaries stay in this call's
    /// stack frame.
    #[inline(never)]
    pub fn parse_into(&mut self, bytes: &'a [u8]) {
        self.table = None;
        self.reason = StatusReason::NoRig;
        let rest = match Rig::parse_into(bytes, &mut self.rig) {
            Ok(rest) => rest,
            Err(RigError::Capacity { .. }) => {
                self.reason = StatusReason::RigTooLarge;
                return;
            }
            Err(_) => return,
        };
        let Some(rig) = &self.rig else {
            return;
        };
        let pad = (4 - (bytes.len() - rest.len()) % 4) % 4;
        let table_bytes = rest.get(pad..).unwrap_or(&[]);
        (self.table, self.reason) = if table_bytes.len() < 4 {
            (None, StatusReason::NoTable)
        } else {
            match Table::parse(table_bytes) {
                Ok(t) => match check_table(rig, &t) {
                    StatusReason::Ok => (Some(t), StatusReason::Ok),
                    why => (None, why),
                },
                Err(TableError::BadMagic) if erased(table_bytes) => (None, StatusReason::NoTable),
                Err(e) => (None, table_reason(e)),
            }
        };
    }
}

/// Whether a valid table can drive this rig.
fn check_table<const N: usize>(rig: &Rig<'_, N>, table: &Table<'_>) -> StatusReason {
    if table.rig_hash() != rig.rig_hash() || table.segment_count() != rig.body().len() {
        StatusReason::RigMismatch
    } else if table.kind() != Kind::Grid || table.axes().len() > MAX_PARAMS {
        StatusReason::Unsupported
    } else {
        StatusReason::Ok
    }
}

/// Whether the table slot starts like erased flash (`FF`) or an empty
/// emulator region (`00`): no table was written, as opposed to a damaged one.
fn erased(bytes: &[u8]) -> bool {
    let head = bytes.get(..4).unwrap_or(&[]);
    head.iter().all(|&b| b == 0x00) || head.iter().all(|&b| b == 0xFF)
}

/// The status reason for a table that failed to parse.
fn table_reason(e: TableError) -> StatusReason {
    match e {
        TableError::BadMagic => StatusReason::BadMagic,
        TableError::BadVersion { .. } => StatusReason::BadVersion,
        TableError::BadCrc => StatusReason::BadCrc,
        _ => StatusReason::BadBounds,
    }
}
