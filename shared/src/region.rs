//! The table region: everything a board performs from, as flashed.
//!
//! A board keeps one region of flash (or of the emulator's memory) for its
//! rig and motion tables. This module is the **one owner of its layout**: the
//! firmware reads it with [`Region::parse_into`], the host writes it with
//! [`write()`] (`marionette sim`, `emulate`, `icount`, `demo` and `flash` all
//! go through here) and checks it with the same parse before flashing.
//!
//! # Region format version 1 (a small directory)
//!
//! All integers little-endian; offsets from the first byte of the region.
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `"MREG"` (`4D 52 45 47`) |
//! | 4 | 2 | format version, `u16` ([`VERSION`] = 1) |
//! | 6 | 2 | entry count `n`, `u16` (1 ..= [`MAX_ENTRIES`]) |
//! | 8 | 12 · `n` | the directory: per entry `kind: u16`, `reserved: u16` (0), `offset: u32`, `len: u32` |
//! | 8 + 12 · `n` | 4 | CRC-32/ISO-HDLC ([`crate::crc`]) of bytes `0 .. 8 + 12 · n` |
//! | `offset`ᵢ | `len`ᵢ | entry `i`'s blob |
//!
//! Rules the reader checks: every `offset` is a multiple of 4, at or after
//! the end of the directory's CRC, and at or after the end of the previous
//! entry (entries are in address order and never overlap); every entry lies
//! inside the region; `reserved` is 0. Each blob carries its own magic,
//! version and CRC, so the directory's CRC covers only the directory. The
//! writer ([`write()`]) puts the blobs in the order given, each at the next
//! 4-aligned offset after the previous one, with zero padding between them
//! and after the last one up to a multiple of 4.
//!
//! Entry kinds ([`EntryKind`]): 1 the rig blob ([`crate::rig`]; exactly one),
//! 2 a table blob ([`crate::table`]; the first one is table 0), 3 a layer
//! list ([`crate::layer`]; at most one, see [Layers](self#layers)), 4 a
//! show ([`crate::show`]; the first one is played; added within version 1,
//! as the rule below allows: a reader that predates it skips it). A reader
//! skips entries of kinds it does not know, so later formats can add entries
//! (more tables, a show) that an older firmware ignores; a change that an
//! older reader would misread bumps [`VERSION`], and a reader refuses a
//! region of a version it does not know ([`StatusReason::BadVersion`]).
//!
//! ## Example
//!
//! Two entries, a 5-byte blob of kind 1 and a 3-byte blob of kind 2
//! (the bytes are not real blobs: the layout does not look inside):
//!
//! ```text
//! 4D 52 45 47  01 00  02 00                    magic, version 1, 2 entries
//! 01 00 00 00  24 00 00 00  05 00 00 00        kind 1 at 0x24, 5 bytes
//! 02 00 00 00  2C 00 00 00  03 00 00 00        kind 2 at 0x2C, 3 bytes
//! c0 c1 c2 c3                                  CRC-32 of the 32 bytes above
//! b0 b1 b2 b3 b4  00 00 00                     blob 1, padding to 0x2C
//! t0 t1 t2  00                                 blob 2, padding to 4
//! ```
//!
//! ## The older layout
//!
//! Before the directory, a region was the rig blob, zero padding to the
//! next 4-byte boundary, then the table blob. A region that starts with the
//! rig blob's magic (`"MRIG"`) is still read that way.
//!
//! # Layers
//!
//! A region with a layer list (kind 3) is performed by its layers instead
//! of table 0: layer `i` names the `n`-th table entry (`n` from 0, in
//! directory order; several layers may share one), and the board synthesizes
//! every layer each frame and blends them ([`crate::layer`]). The reader
//! checks the list (magic, version, CRC, fields, the rig's segment count)
//! and then every layer's table: present and valid (the table reasons
//! below), built for the rig (`RigMismatch`), and a static grid or a clip
//! table of the clip layout with as many parameter axes as the layer has
//! sources (`Unsupported`). The first failing layer refuses the whole region
//! at arming with its reason, and [`Region::refused_layer`] names it. An
//! older reader skips the list and performs table 0.
//!
//! # Why a board cannot arm
//!
//! [`Region::reason`] is the [`StatusReason`] the board reports: `NoRig` for
//! a missing or invalid rig, `RigTooLarge` for a rig over the capacity,
//! `NoTable` for no table (or an erased table slot), the table's own reasons
//! (`BadMagic`, `BadVersion`, `BadCrc`, `BadBounds`, `RigMismatch`,
//! `Unsupported`), and for a damaged directory `BadVersion` (unknown region
//! version), `BadCrc` (its CRC) or `BadBounds` (an entry out of place).
//! [`directory`] gives the precise [`RegionError`] for a host message.

use core::fmt;

use crate::clip::Clips;
use crate::crc::{Crc32, crc32};
use crate::layer::{Layer, Layers, MAX_LAYERS};
use crate::pose::MAX_SEGMENTS;
use crate::rig::{self, MAX_PARAMS, Rig, RigError};
use crate::show::{self, Show, ShowError};
use crate::table::{Kind, Table, TableError};
use crate::wire::StatusReason;

/// The region's magic.
pub const MAGIC: [u8; 4] = *b"MREG";
/// The region format version this core reads and writes.
pub const VERSION: u16 = 1;
/// Most entries in a directory.
pub const MAX_ENTRIES: usize = 16;
/// Bytes before the directory: magic, version, entry count.
pub const PREFIX_LEN: usize = 8;
/// Bytes of one directory entry.
pub const ENTRY_LEN: usize = 12;
/// Bytes of the directory's CRC.
pub const CRC_LEN: usize = 4;

/// The capacity (segments) the shipped firmware parses its region at
/// (`marionette-firmware`'s `app::SEGMENTS`): the host checks a region with
/// it before flashing, so that it sees exactly what the board will.
pub const FIRMWARE_SEGMENTS: usize = 24;

/// What an entry holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct EntryKind(pub u16);

impl EntryKind {
    /// The rig blob ([`crate::rig`]).
    pub const RIG: Self = Self(1);
    /// A table blob ([`crate::table`]).
    pub const TABLE: Self = Self(2);
    /// A layer list ([`crate::layer`]; at most one).
    pub const LAYERS: Self = Self(3);
    /// A show ([`crate::show`]; the first one is played).
    pub const SHOW: Self = Self(4);
    /// A whole region nested as one entry, which the live loop ignores: the
    /// instruction-count bench carries its layered variant so.
    pub const NESTED: Self = Self(0x100);
}

/// One blob of a region.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Entry<'a> {
    /// What the blob is.
    pub kind: EntryKind,
    /// The blob's bytes (exactly `len` of the directory).
    pub bytes: &'a [u8],
}

impl<'a> Entry<'a> {
    /// The rig blob `bytes`.
    #[must_use]
    pub const fn rig(bytes: &'a [u8]) -> Self {
        Self {
            kind: EntryKind::RIG,
            bytes,
        }
    }

    /// The table blob `bytes`.
    #[must_use]
    pub const fn table(bytes: &'a [u8]) -> Self {
        Self {
            kind: EntryKind::TABLE,
            bytes,
        }
    }

    /// The show blob `bytes`.
    #[must_use]
    pub const fn show(bytes: &'a [u8]) -> Self {
        Self {
            kind: EntryKind::SHOW,
            bytes,
        }
    }

    /// The layer list blob `bytes`.
    #[must_use]
    pub const fn layers(bytes: &'a [u8]) -> Self {
        Self {
            kind: EntryKind::LAYERS,
            bytes,
        }
    }
}

/// Why a region's directory was refused, or a region could not be written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RegionError {
    /// The bytes end inside the prefix or the directory.
    Truncated,
    /// Neither a region (`"MREG"`) nor an older region (`"MRIG"`).
    Magic,
    /// A region format version this core does not read.
    Version(u16),
    /// The directory's CRC does not match.
    Crc,
    /// No entry, or more than [`MAX_ENTRIES`].
    EntryCount(usize),
    /// Entry `index` is misaligned, overlaps the directory or the entry
    /// before it, reaches past the region, or has a non-zero reserved field.
    Entry {
        /// Its position in the directory.
        index: usize,
    },
    /// No rig entry.
    NoRig,
    /// More than one rig entry.
    DuplicateRig,
    /// The output buffer is too small (writer).
    BufferTooSmall,
    /// An offset or length does not fit 32 bits (writer).
    TooLarge,
}

impl fmt::Display for RegionError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Truncated => f.write_str("region truncated inside its directory"),
            Self::Magic => f.write_str("not a region (bad magic)"),
            Self::Version(v) => write!(f, "region format version {v} (expected {VERSION})"),
            Self::Crc => f.write_str("region directory CRC mismatch"),
            Self::EntryCount(n) => {
                write!(f, "region has {n} entries (1 ..= {MAX_ENTRIES} allowed)")
            }
            Self::Entry { index } => write!(
                f,
                "region entry {index} is misaligned, overlaps another or lies outside the region"
            ),
            Self::NoRig => f.write_str("region has no rig entry"),
            Self::DuplicateRig => f.write_str("region has more than one rig entry"),
            Self::BufferTooSmall => f.write_str("region buffer too small"),
            Self::TooLarge => f.write_str("region larger than 4 GiB"),
        }
    }
}

impl RegionError {
    /// The status reason a board reports for this directory problem.
    #[must_use]
    pub const fn reason(self) -> StatusReason {
        match self {
            Self::Version(_) => StatusReason::BadVersion,
            Self::Crc => StatusReason::BadCrc,
            Self::Magic | Self::NoRig => StatusReason::NoRig,
            _ => StatusReason::BadBounds,
        }
    }
}

/// Rounds up to a multiple of 4.
const fn align4(n: usize) -> usize {
    n.saturating_add(3) & !3
}

/// The bytes before the first blob: prefix, `n` entries and the CRC.
const fn directory_len(n: usize) -> usize {
    PREFIX_LEN + ENTRY_LEN * n + CRC_LEN
}

/// A little-endian `u16` at `at`.
fn u16_at(bytes: &[u8], at: usize) -> Option<u16> {
    let b = bytes.get(at..at.checked_add(2)?)?;
    Some(u16::from_le_bytes(b.try_into().ok()?))
}

/// A little-endian `u32` at `at`.
fn u32_at(bytes: &[u8], at: usize) -> Option<u32> {
    let b = bytes.get(at..at.checked_add(4)?)?;
    Some(u32::from_le_bytes(b.try_into().ok()?))
}

/// A checked directory (see [`directory`]): its entries, in address order.
#[derive(Clone, Copy, Debug)]
pub struct Directory<'a> {
    bytes: &'a [u8],
    count: usize,
}

impl<'a> Directory<'a> {
    /// The number of entries.
    #[must_use]
    pub fn len(&self) -> usize {
        self.count
    }

    /// Whether there is no entry (never, for a checked directory).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Entry `i` (`None` past the end).
    #[must_use]
    pub fn get(&self, i: usize) -> Option<Entry<'a>> {
        if i >= self.count {
            return None;
        }
        let at = PREFIX_LEN + ENTRY_LEN * i;
        let kind = EntryKind(u16_at(self.bytes, at)?);
        let offset = usize::try_from(u32_at(self.bytes, at + 4)?).ok()?;
        let len = usize::try_from(u32_at(self.bytes, at + 8)?).ok()?;
        let bytes = self.bytes.get(offset..offset.checked_add(len)?)?;
        Some(Entry { kind, bytes })
    }

    /// The entries in address order.
    pub fn iter(&self) -> impl Iterator<Item = Entry<'a>> + '_ {
        (0..self.count).filter_map(|i| self.get(i))
    }

    /// The `n`-th entry of `kind`.
    #[must_use]
    pub fn find(&self, kind: EntryKind, n: usize) -> Option<Entry<'a>> {
        self.iter().filter(|e| e.kind == kind).nth(n)
    }
}

/// Checks a region's prefix, directory and CRC and the placement of every
/// entry (see the module doc); does not look inside the blobs.
pub fn directory(bytes: &[u8]) -> Result<Directory<'_>, RegionError> {
    if bytes.get(..4) != Some(&MAGIC[..]) {
        return Err(RegionError::Magic);
    }
    let version = u16_at(bytes, 4).ok_or(RegionError::Truncated)?;
    if version != VERSION {
        return Err(RegionError::Version(version));
    }
    let count = usize::from(u16_at(bytes, 6).ok_or(RegionError::Truncated)?);
    if count == 0 || count > MAX_ENTRIES {
        return Err(RegionError::EntryCount(count));
    }
    let end = PREFIX_LEN + ENTRY_LEN * count;
    let covered = bytes.get(..end).ok_or(RegionError::Truncated)?;
    let stored = u32_at(bytes, end).ok_or(RegionError::Truncated)?;
    if crc32(covered) != stored {
        return Err(RegionError::Crc);
    }
    let mut next = directory_len(count);
    for index in 0..count {
        let at = PREFIX_LEN + ENTRY_LEN * index;
        let field = |k| u32_at(covered, at + k).map(|v| usize::try_from(v).unwrap_or(usize::MAX));
        let (reserved, offset, len) = (u16_at(covered, at + 2), field(4), field(8));
        let fits = match (reserved, offset, len) {
            (Some(0), Some(o), Some(l)) if o % 4 == 0 && o >= next => o.checked_add(l),
            _ => None,
        };
        match fits.filter(|&e| e <= bytes.len()) {
            Some(e) => next = e,
            None => return Err(RegionError::Entry { index }),
        }
    }
    Ok(Directory { bytes, count })
}

/// The bytes [`write()`] needs for `entries`.
pub fn len(entries: &[Entry<'_>]) -> Result<usize, RegionError> {
    if entries.is_empty() || entries.len() > MAX_ENTRIES {
        return Err(RegionError::EntryCount(entries.len()));
    }
    let mut end = directory_len(entries.len());
    for e in entries {
        end = align4(end)
            .checked_add(e.bytes.len())
            .ok_or(RegionError::TooLarge)?;
    }
    let total = align4(end);
    u32::try_from(total).map_err(|_| RegionError::TooLarge)?;
    Ok(total)
}

/// Writes a region of `entries` (in this order) into `out` and returns its
/// length ([`len`]). Checks the layout, not the blobs: parse the result with
/// [`Region::parse`] to see whether a board would arm with it.
pub fn write(entries: &[Entry<'_>], out: &mut [u8]) -> Result<usize, RegionError> {
    let total = len(entries)?;
    let out = out.get_mut(..total).ok_or(RegionError::BufferTooSmall)?;
    out.fill(0);
    let count = u16::try_from(entries.len()).map_err(|_| RegionError::TooLarge)?;
    let mut head = [0u8; PREFIX_LEN];
    let [m0, m1, m2, m3] = MAGIC;
    let [v0, v1] = VERSION.to_le_bytes();
    let [c0, c1] = count.to_le_bytes();
    head.copy_from_slice(&[m0, m1, m2, m3, v0, v1, c0, c1]);
    put(out, 0, &head)?;
    let mut offset = directory_len(entries.len());
    for (i, e) in entries.iter().enumerate() {
        offset = align4(offset);
        let at = PREFIX_LEN + ENTRY_LEN * i;
        let off32 = u32::try_from(offset).map_err(|_| RegionError::TooLarge)?;
        let len32 = u32::try_from(e.bytes.len()).map_err(|_| RegionError::TooLarge)?;
        put(out, at, &e.kind.0.to_le_bytes())?;
        put(out, at + 4, &off32.to_le_bytes())?;
        put(out, at + 8, &len32.to_le_bytes())?;
        put(out, offset, e.bytes)?;
        offset += e.bytes.len();
    }
    let end = PREFIX_LEN + ENTRY_LEN * entries.len();
    let crc = {
        let mut c = Crc32::new();
        c.update(out.get(..end).ok_or(RegionError::BufferTooSmall)?);
        c.finish()
    };
    put(out, end, &crc.to_le_bytes())?;
    Ok(total)
}

/// Copies `bytes` into `out` at `at`.
fn put(out: &mut [u8], at: usize, bytes: &[u8]) -> Result<(), RegionError> {
    let end = at.checked_add(bytes.len()).ok_or(RegionError::TooLarge)?;
    out.get_mut(at..end)
        .ok_or(RegionError::BufferTooSmall)?
        .copy_from_slice(bytes);
    Ok(())
}

/// How a region is laid out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// Neither layout (or a damaged directory).
    Unknown,
    /// The older layout: rig blob, padding, table blob.
    Legacy,
    /// A valid directory of format [`VERSION`], with this many entries.
    Directory(usize),
}

/// Whether `bytes` start like the older layout (the rig blob's magic).
fn is_legacy(bytes: &[u8]) -> bool {
    bytes.get(..4) == Some(&rig::MAGIC[..])
}

/// How `bytes` are laid out (what [`Region::parse`] reads them as).
#[must_use]
pub fn layout(bytes: &[u8]) -> Layout {
    match directory(bytes) {
        Ok(dir) => Layout::Directory(dir.len()),
        Err(RegionError::Magic) if is_legacy(bytes) => Layout::Legacy,
        Err(_) => Layout::Unknown,
    }
}

/// The validated contents of the table region: the rig and table 0, or the
/// rig and its layers. The rig has capacity `N` (see
/// [Capacity](crate::frame#capacity)). The other entries of a region are in
/// its [`directory`].
#[derive(Clone, Debug)]
pub struct Region<'a, const N: usize = MAX_SEGMENTS> {
    /// The rig, if its blob is valid (and fits the capacity).
    pub rig: Option<Rig<'a, N>>,
    /// Table 0, if its blob is valid and matches the rig (a region without
    /// a layer list).
    pub table: Option<Table<'a>>,
    /// The layer list (entry kind 3), if the region has one and every
    /// layer passed its checks ([Layers](self#layers)).
    pub layers: Option<Layers<'a>>,
    /// Layer `i`'s table, for each layer of [`Region::layers`].
    pub layer_tables: [Option<Table<'a>>; MAX_LAYERS],
    /// The first layer refused, when the layer list was refused because of
    /// one layer (its table missing, damaged or unfit): `reason` says why.
    pub refused_layer: Option<u8>,
    /// Why the board cannot arm ([`StatusReason::Ok`] if it can).
    pub reason: StatusReason,
    /// The first show, if it is valid and built for the rig.
    pub show: Option<Show<'a>>,
    /// Why the region's show was refused, if it has one that was.
    pub show_error: Option<ShowError>,
}

impl<'a> Region<'a> {
    /// Validates a table region (the directory, then magic, version, CRC and
    /// bounds of the rig and table blobs, and that the table was built for
    /// this rig), at the rig format's capacity; [`Region::parse_sized`]
    /// reads it into a smaller rig.
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
        layers: None,
        layer_tables: [None; MAX_LAYERS],
        refused_layer: None,
        reason: StatusReason::NoRig,
        show: None,
        show_error: None,
    };

    /// [`Region::parse_sized`] in place, for a caller that keeps the region
    /// where it is: the rig is kilobytes, and every move is a copy on the
    /// stack. Never inlined: the decoding's temporaries stay in this call's
    /// stack frame.
    #[inline(never)]
    pub fn parse_into(&mut self, bytes: &'a [u8]) {
        self.rig = None;
        self.table = None;
        self.layers = None;
        self.layer_tables = [None; MAX_LAYERS];
        self.refused_layer = None;
        self.reason = StatusReason::NoRig;
        self.show = None;
        self.show_error = None;
        match directory(bytes) {
            Ok(dir) => self.parse_entries(&dir),
            Err(RegionError::Magic) if is_legacy(bytes) => self.parse_legacy(bytes),
            Err(e) => self.reason = e.reason(),
        }
    }

    /// The rig and table 0 of a checked directory.
    fn parse_entries(&mut self, dir: &Directory<'a>) {
        let mut rigs = dir.iter().filter(|e| e.kind == EntryKind::RIG);
        let (Some(rig), None) = (rigs.next(), rigs.next()) else {
            self.reason = RegionError::NoRig.reason();
            return;
        };
        if !self.parse_rig(rig.bytes) {
            return;
        }
        if let (Some(entry), Some(rig)) = (dir.find(EntryKind::SHOW, 0), &self.rig) {
            let parsed = Show::parse(entry.bytes)
                .and_then(|s| show::check_rig(&s, rig.rig_hash()).map(|()| s));
            (self.show, self.show_error) = match parsed {
                Ok(s) => (Some(s), None),
                Err(e) => (None, Some(e)),
            };
        }
        if let Some(list) = dir.find(EntryKind::LAYERS, 0) {
            self.parse_layers(dir, list.bytes);
            return;
        }
        let table = dir.find(EntryKind::TABLE, 0).map_or(&[][..], |e| e.bytes);
        self.parse_table(table);
    }

    /// The older layout: rig blob, padding, table blob.
    fn parse_legacy(&mut self, bytes: &'a [u8]) {
        let Ok(rest) = self.rig_into(bytes) else {
            return;
        };
        let pad = (4 - (bytes.len() - rest.len()) % 4) % 4;
        self.parse_table(rest.get(pad..).unwrap_or(&[]));
    }

    /// Parses the rig blob into `self.rig`; false (and the reason set) if
    /// it is refused.
    fn parse_rig(&mut self, bytes: &'a [u8]) -> bool {
        self.rig_into(bytes).is_ok()
    }

    /// The rig into `self.rig`, returning the bytes after its blob.
    fn rig_into(&mut self, bytes: &'a [u8]) -> Result<&'a [u8], ()> {
        match Rig::parse_into(bytes, &mut self.rig) {
            Ok(rest) if self.rig.is_some() => Ok(rest),
            Err(RigError::Capacity { .. }) => {
                self.reason = StatusReason::RigTooLarge;
                Err(())
            }
            _ => Err(()),
        }
    }

    /// Table 0 from its blob bytes (empty: no table entry).
    fn parse_table(&mut self, bytes: &'a [u8]) {
        let Some(rig) = &self.rig else {
            return;
        };
        (self.table, self.reason) = if bytes.len() < 4 {
            (None, StatusReason::NoTable)
        } else {
            match Table::parse(bytes) {
                Ok(t) => match check_table(rig, &t) {
                    StatusReason::Ok => (Some(t), StatusReason::Ok),
                    why => (None, why),
                },
                Err(TableError::BadMagic) if erased(bytes) => (None, StatusReason::NoTable),
                Err(e) => (None, table_reason(e)),
            }
        };
    }
}

impl<'a, const N: usize> Region<'a, N> {
    /// The layer list and each layer's table (see [Layers](self#layers)).
    fn parse_layers(&mut self, dir: &Directory<'a>, bytes: &'a [u8]) {
        let Some(rig) = &self.rig else {
            return;
        };
        let layers = match Layers::parse(bytes) {
            Ok(l) if l.segments() == rig.body().len() => l,
            Ok(_) => {
                self.reason = StatusReason::RigMismatch;
                return;
            }
            Err(e) => {
                self.reason = e.reason();
                return;
            }
        };
        for (i, (layer, slot)) in layers
            .as_slice()
            .iter()
            .zip(self.layer_tables.iter_mut())
            .enumerate()
        {
            let bytes = dir
                .find(EntryKind::TABLE, usize::from(layer.table))
                .map_or(&[][..], |e| e.bytes);
            let why = match Table::parse(bytes) {
                Ok(t) => match check_layer_table(rig, &t, layer) {
                    StatusReason::Ok => {
                        *slot = Some(t);
                        continue;
                    }
                    why => why,
                },
                Err(_) if bytes.len() < 4 || erased(bytes) => StatusReason::NoTable,
                Err(e) => table_reason(e),
            };
            self.reason = why;
            self.refused_layer = Some(i as u8);
            self.layer_tables = [None; MAX_LAYERS];
            return;
        }
        self.layers = Some(layers);
        self.reason = StatusReason::Ok;
    }
}

/// Whether a valid table can drive one layer of this rig: built for the
/// rig, a grid or a clip table of the clip layout, with one source per
/// parameter axis.
fn check_layer_table<const N: usize>(
    rig: &Rig<'_, N>,
    table: &Table<'_>,
    layer: &Layer<'_>,
) -> StatusReason {
    if table.rig_hash() != rig.rig_hash() || table.segment_count() != rig.body().len() {
        return StatusReason::RigMismatch;
    }
    let fits = table.param_axes().len() == usize::from(layer.axis_count)
        && match table.kind() {
            Kind::Grid => table.grid().is_ok(),
            Kind::Clips { phases } => match (table.grid(), table.param_grid()) {
                (Ok(g), Ok(p)) => Clips::new(g, p, usize::from(phases)).is_ok(),
                _ => false,
            },
        };
    if fits {
        StatusReason::Ok
    } else {
        StatusReason::Unsupported
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

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec;
    use std::vec::Vec;

    /// CRC-32/ISO-HDLC bit by bit, straight from its definition (an
    /// independent check of the table-driven [`crc32`]).
    fn crc32_bitwise(bytes: &[u8]) -> u32 {
        let mut c = 0xFFFF_FFFFu32;
        for &b in bytes {
            c ^= u32::from(b);
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    (c >> 1) ^ 0xEDB8_8320
                } else {
                    c >> 1
                };
            }
        }
        !c
    }

    #[test]
    fn the_documented_example_exactly() {
        let blob1 = [0xB0, 0xB1, 0xB2, 0xB3, 0xB4];
        let blob2 = [0x70, 0x71, 0x72];
        let entries = [
            Entry {
                kind: EntryKind(1),
                bytes: &blob1,
            },
            Entry {
                kind: EntryKind(2),
                bytes: &blob2,
            },
        ];
        assert_eq!(len(&entries), Ok(0x30));
        let mut out = [0xAAu8; 0x40];
        assert_eq!(write(&entries, &mut out), Ok(0x30));
        let mut want: Vec<u8> = vec![
            0x4D, 0x52, 0x45, 0x47, 0x01, 0x00, 0x02, 0x00, // prefix
            0x01, 0x00, 0x00, 0x00, 0x24, 0x00, 0x00, 0x00, 0x05, 0x00, 0x00, 0x00, // entry 0
            0x02, 0x00, 0x00, 0x00, 0x2C, 0x00, 0x00, 0x00, 0x03, 0x00, 0x00, 0x00, // entry 1
        ];
        let crc = crc32_bitwise(&want);
        want.extend_from_slice(&crc.to_le_bytes());
        want.extend_from_slice(&[0xB0, 0xB1, 0xB2, 0xB3, 0xB4, 0, 0, 0, 0x70, 0x71, 0x72, 0]);
        assert_eq!(&out[..0x30], &want[..]);
        assert!(
            out[0x30..].iter().all(|&b| b == 0xAA),
            "writes past its length"
        );
        let dir = directory(&out).unwrap();
        assert_eq!(dir.len(), 2);
        assert_eq!(dir.get(0), Some(entries[0]));
        assert_eq!(dir.get(1), Some(entries[1]));
        assert_eq!(dir.get(2), None);
        assert_eq!(dir.find(EntryKind(2), 0), Some(entries[1]));
        assert_eq!(dir.find(EntryKind(2), 1), None);
    }

    fn two_entry_region() -> Vec<u8> {
        let (a, b) = ([1u8; 7], [2u8; 9]);
        let entries = [Entry::rig(&a), Entry::table(&b)];
        let mut out = vec![0u8; len(&entries).unwrap()];
        write(&entries, &mut out).unwrap();
        out
    }

    #[test]
    fn every_directory_byte_is_covered() {
        let region = two_entry_region();
        let dir_end = directory_len(2);
        for i in 0..dir_end {
            let mut b = region.clone();
            b[i] ^= 0x10;
            assert!(directory(&b).is_err(), "byte {i} not checked");
        }
        for cut in 0..dir_end {
            assert!(directory(&region[..cut]).is_err(), "cut at {cut}");
        }
        // The blobs themselves are the blobs' business.
        let mut b = region.clone();
        b[dir_end] ^= 0x10;
        assert!(directory(&b).is_ok());
    }

    /// Rewrites entry `i`'s offset and length and fixes the CRC.
    fn with_entry(region: &[u8], i: usize, offset: u32, len: u32) -> Vec<u8> {
        let mut b = region.to_vec();
        let at = PREFIX_LEN + ENTRY_LEN * i;
        b[at + 4..at + 8].copy_from_slice(&offset.to_le_bytes());
        b[at + 8..at + 12].copy_from_slice(&len.to_le_bytes());
        let n = usize::from(u16::from_le_bytes([b[6], b[7]]));
        let end = PREFIX_LEN + ENTRY_LEN * n;
        let crc = crc32_bitwise(&b[..end]);
        b[end..end + 4].copy_from_slice(&crc.to_le_bytes());
        b
    }

    #[test]
    fn misplaced_entries_are_refused() {
        let region = two_entry_region();
        // As written: entry 0 at 0x24 (7 bytes), entry 1 at 0x2C (9 bytes).
        assert!(directory(&region).is_ok());
        let cases = [
            (0, 0x20, 7, 0),  // inside the directory
            (0, 0x26, 7, 0),  // misaligned
            (1, 0x28, 9, 1),  // overlaps entry 0
            (1, 0x2C, 99, 1), // past the end
            (1, u32::MAX - 3, 9, 1),
        ];
        for (i, offset, len, index) in cases {
            let b = with_entry(&region, i, offset, len);
            assert_eq!(
                directory(&b).err(),
                Some(RegionError::Entry { index }),
                "{offset:#x}+{len}"
            );
        }
        // A gap is fine.
        let mut bigger = region.clone();
        bigger.extend_from_slice(&[0; 16]);
        assert!(directory(&with_entry(&bigger, 1, 0x34, 9)).is_ok());
    }

    #[test]
    fn versions_counts_and_magic() {
        let region = two_entry_region();
        let mut v2 = region.clone();
        v2[4] = 2;
        assert_eq!(directory(&v2).err(), Some(RegionError::Version(2)));
        assert_eq!(RegionError::Version(2).reason(), StatusReason::BadVersion);
        let mut none = region.clone();
        none[6] = 0;
        assert_eq!(directory(&none).err(), Some(RegionError::EntryCount(0)));
        let mut many = region.clone();
        many[6] = 17;
        assert_eq!(directory(&many).err(), Some(RegionError::EntryCount(17)));
        assert_eq!(directory(b"MRIG....").err(), Some(RegionError::Magic));
        assert_eq!(directory(&[0xFF; 64]).err(), Some(RegionError::Magic));
        assert_eq!(len(&[]), Err(RegionError::EntryCount(0)));
        let e = [Entry::rig(&[1]); 17];
        assert_eq!(len(&e), Err(RegionError::EntryCount(17)));
        let mut small = [0u8; 16];
        assert_eq!(
            write(&[Entry::rig(&[1])], &mut small),
            Err(RegionError::BufferTooSmall)
        );
    }

    #[test]
    fn a_region_without_a_valid_rig_says_why() {
        // Two entries whose "rig" is no rig blob.
        let region = two_entry_region();
        let r = Region::parse(&region);
        assert!(r.rig.is_none());
        assert_eq!(r.reason, StatusReason::NoRig);
        assert_eq!(layout(&region), Layout::Directory(2));
        // No rig entry at all; two rig entries.
        for kinds in [[EntryKind::TABLE, EntryKind(9)], [EntryKind::RIG; 2]] {
            let e = [
                Entry {
                    kind: kinds[0],
                    bytes: &[1; 4],
                },
                Entry {
                    kind: kinds[1],
                    bytes: &[2; 4],
                },
            ];
            let mut out = vec![0u8; len(&e).unwrap()];
            write(&e, &mut out).unwrap();
            assert_eq!(Region::parse(&out).reason, StatusReason::NoRig);
        }
        let mut bad = region.clone();
        bad[PREFIX_LEN] ^= 1;
        let r = Region::parse(&bad);
        assert_eq!(r.reason, StatusReason::BadCrc);
        assert_eq!(layout(&bad), Layout::Unknown);
        assert_eq!(Region::parse(&[0xFF; 64]).reason, StatusReason::NoRig);
        assert_eq!(Region::parse(&[]).reason, StatusReason::NoRig);
    }
}
