//! Flashing the board: the firmware ELF into the code region and the table
//! region (rig + tables, the core's [`marionette_core::region`] layout) into
//! its own flash, with probe-rs.
//!
//! The Black Pill's flash is split by `firmware/boards/blackpill/memory.x`:
//! sectors 0–5 (`0x0800_0000`, 256 KiB) hold the firmware and sectors 6–7
//! (`0x0804_0000`, 256 KiB) hold the table region, so a rig and its tables
//! can be re-flashed without touching the code ([`BLACKPILL`]).
//!
//! Flashing is two steps:
//!
//! 1. [`plan`] (no hardware): reads the ELF's loadable segments (what probe-rs
//!    would program: `PT_LOAD` segments with file data, at their physical
//!    address), checks that each lies inside the firmware region and none
//!    touches the table region, checks that the region fits, and (unless
//!    told not to) reads it **as the board will** ([`check_region`]): the
//!    256 KiB of the table flash, erased (`FF`) past what is written, parsed
//!    by the core's [`region::Region`] at the firmware's capacity, and the rig's
//!    servo output checked against the board's [`Support`]. Anything the
//!    board would not arm with is refused with the board's reason.
//!    [`check_chip`] then stages the plan in a probe-rs flash loader for the
//!    chip's built-in memory map, which catches addresses the chip has no
//!    flash for, still without a probe.
//! 2. [`program`]: stages the same chunks on an attached session and commits
//!    them (erase, program, optional verify), reporting progress through a
//!    callback, then reads the table region back and checks it again as the
//!    board reads it ([`ReadBack`]). With `dry_run` probe-rs prepares
//!    everything (flash algorithm, sector layout) and writes nothing; the
//!    read-back is then the bytes staged in probe-rs' flash loader, laid
//!    over erased flash.

use marionette_core::output::{Refusal, Support, support};
use marionette_core::region::{self, EntryKind, FIRMWARE_SEGMENTS, Layout as RegionLayout};
use marionette_core::rig::{Rig, RigError};
use marionette_core::table::{self, Table};
use marionette_core::wire::StatusReason;
use object::read::elf::{ElfFile, FileHeader, ProgramHeader};
use object::{Object, ObjectSection};
use std::fmt;

#[cfg(feature = "flash")]
mod probe;
#[cfg(feature = "flash")]
pub use probe::{attach, check_chip, dry_read_back, program, stage};

/// The probe-rs name of the Black Pill's chip.
pub const DEFAULT_CHIP: &str = "STM32F411CEUx";

/// A range of flash with a purpose.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Region {
    /// What the region holds (`firmware`, `tables`).
    pub name: &'static str,
    /// First address.
    pub start: u64,
    /// Length in bytes.
    pub size: u64,
}

impl Region {
    /// One past the last address.
    #[must_use]
    pub const fn end(&self) -> u64 {
        self.start + self.size
    }

    /// Whether `[start, start + len)` lies inside the region.
    #[must_use]
    pub fn contains(&self, start: u64, len: u64) -> bool {
        start >= self.start && start.checked_add(len).is_some_and(|e| e <= self.end())
    }

    /// Whether `[start, start + len)` shares a byte with the region.
    #[must_use]
    pub fn overlaps(&self, start: u64, len: u64) -> bool {
        len > 0 && start < self.end() && start.saturating_add(len) > self.start
    }
}

impl fmt::Display for Region {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} {:#010x}..{:#010x} ({} KiB)",
            self.name,
            self.start,
            self.end(),
            self.size / 1024
        )
    }
}

/// Where the firmware and the tables go.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    /// The code region.
    pub firmware: Region,
    /// The table region (rig + tables).
    pub tables: Region,
    /// The servo back-ends the board drives.
    pub support: Support,
}

/// The STM32F411CEU6 "Black Pill" (`firmware/boards/blackpill/memory.x`).
pub const BLACKPILL: Layout = Layout {
    firmware: Region {
        name: "firmware",
        start: 0x0800_0000,
        size: 256 * 1024,
    },
    tables: Region {
        name: "tables",
        start: 0x0804_0000,
        size: 256 * 1024,
    },
    support: Support::BLACKPILL,
};

/// What a chunk of a plan is.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Content {
    /// A loadable segment of the firmware ELF, with the sections it holds.
    Firmware {
        /// Segment index in the ELF's program headers.
        segment: usize,
        /// Names of the sections inside it.
        sections: Vec<String>,
    },
    /// The table region (rig + tables).
    Tables,
}

/// Bytes to write at an address.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Chunk {
    /// What the bytes are.
    pub content: Content,
    /// Where they go.
    pub address: u64,
    /// The bytes.
    pub data: Vec<u8>,
}

impl Chunk {
    /// Length in bytes.
    #[must_use]
    pub fn len(&self) -> u64 {
        self.data.len() as u64
    }

    /// Whether the chunk is empty (plans never hold empty chunks).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }
}

/// What will be written where, checked against a [`Layout`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Plan {
    /// The layout checked against.
    pub layout: Layout,
    /// The chunks, firmware segments first.
    pub chunks: Vec<Chunk>,
}

impl Plan {
    /// Total bytes to write.
    #[must_use]
    pub fn bytes(&self) -> u64 {
        self.chunks.iter().map(Chunk::len).sum()
    }

    /// Whether the plan holds firmware.
    #[must_use]
    pub fn has_firmware(&self) -> bool {
        self.chunks
            .iter()
            .any(|c| matches!(c.content, Content::Firmware { .. }))
    }
}

impl fmt::Display for Plan {
    /// One line per region, then one per chunk with its share of the region.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "regions:")?;
        for r in [self.layout.firmware, self.layout.tables] {
            writeln!(f, "  {r}")?;
        }
        writeln!(f, "writes:")?;
        for c in &self.chunks {
            let (what, region) = match &c.content {
                Content::Firmware { segment, sections } => (
                    format!("ELF segment {segment} [{}]", sections.join(" ")),
                    self.layout.firmware,
                ),
                Content::Tables => (
                    "table region (rig + tables)".to_string(),
                    self.layout.tables,
                ),
            };
            writeln!(
                f,
                "  {:#010x}..{:#010x} {:>7} bytes  {what} ({:.1} % of {})",
                c.address,
                c.address + c.len(),
                c.len(),
                100.0 * c.len() as f64 / region.size as f64,
                region.name
            )?;
        }
        write!(f, "total: {} bytes", self.bytes())
    }
}

/// Why flashing was refused or failed.
#[derive(Debug, thiserror::Error)]
pub enum FlashError {
    /// Neither firmware nor tables were given.
    #[error("nothing to flash: give a firmware ELF, a table blob, or both")]
    Nothing,
    /// The region is empty.
    #[error("the table region image is empty")]
    EmptyTables,
    /// The region does not fit the table flash.
    #[error(
        "the table region image is {size} bytes but the table region ({region}) holds {} bytes: \
         {} bytes too many",
        region.size,
        size - region.size
    )]
    TablesTooLarge {
        /// Blob size.
        size: u64,
        /// The table region.
        region: Region,
    },
    /// A bare table blob where a region (rig + tables) belongs.
    #[error(
        "this is a bare table blob: the board reads a region of rig + tables, and with a \
         table alone it would report NoRig; give the rig file too (--rig RIG.toml) or \
         flash a region (out/region.bin of `marionette demo` or `emulate`)"
    )]
    BareTable,
    /// The board would not arm with this region.
    #[error("the board would not arm with this region: {reason:?} ({why})")]
    WouldNotArm {
        /// The status reason the board would report.
        reason: StatusReason,
        /// What is wrong, in detail.
        why: String,
    },
    /// The region read back from the board is not the one written.
    #[error("read back from the table region: {0}")]
    ReadBack(Box<FlashError>),
    /// The ELF could not be read.
    #[error("firmware ELF: {0}")]
    Elf(String),
    /// The ELF has nothing to program.
    #[error("firmware ELF has no loadable segment with data")]
    NoLoadableSegments,
    /// An ELF segment would overwrite the tables.
    #[error(
        "firmware ELF segment {segment} at {start:#010x}..{end:#010x} overlaps the table \
         region ({region}); the firmware must end below {:#010x}",
        region.start
    )]
    ElfOverlapsTables {
        /// Segment index.
        segment: usize,
        /// First address.
        start: u64,
        /// One past the last address.
        end: u64,
        /// The table region.
        region: Region,
    },
    /// An ELF segment lies outside the firmware region.
    #[error(
        "firmware ELF segment {segment} at {start:#010x}..{end:#010x} is outside the \
         firmware region ({region}); is this an ELF for this board?"
    )]
    ElfOutsideFirmware {
        /// Segment index.
        segment: usize,
        /// First address.
        start: u64,
        /// One past the last address.
        end: u64,
        /// The firmware region.
        region: Region,
    },
    /// The chip is unknown or its memory map rejects the plan.
    #[error("chip {chip}: {reason}")]
    Chip {
        /// The chip name.
        chip: String,
        /// What went wrong.
        reason: String,
    },
    /// No probe, or attaching failed.
    #[error("probe: {0}")]
    Probe(String),
    /// Erasing, programming or verifying failed.
    #[error("flashing failed: {0}")]
    Flash(String),
}

/// A loadable segment of an ELF file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Segment {
    /// Index in the program headers.
    pub index: usize,
    /// Physical (load) address.
    pub address: u64,
    /// The file bytes.
    pub data: Vec<u8>,
    /// Names of the sections inside.
    pub sections: Vec<String>,
}

/// The loadable segments of an ELF file that a probe programs: `PT_LOAD`
/// with file data and at least one section inside, at the physical (load)
/// address.
pub fn elf_segments(elf: &[u8]) -> Result<Vec<Segment>, FlashError> {
    let err = |e: object::read::Error| FlashError::Elf(e.to_string());
    match object::FileKind::parse(elf).map_err(err)? {
        object::FileKind::Elf32 => segments_of(
            &ElfFile::<object::elf::FileHeader32<object::Endianness>>::parse(elf).map_err(err)?,
        ),
        object::FileKind::Elf64 => segments_of(
            &ElfFile::<object::elf::FileHeader64<object::Endianness>>::parse(elf).map_err(err)?,
        ),
        other => Err(FlashError::Elf(format!("not an ELF file ({other:?})"))),
    }
}

fn segments_of<H: FileHeader<Endian = object::Endianness>>(
    file: &ElfFile<'_, H>,
) -> Result<Vec<Segment>, FlashError> {
    let endian = file.endian();
    let data = file.data();
    let mut out = Vec::new();
    for (index, ph) in file.elf_program_headers().iter().enumerate() {
        if ph.p_type(endian) != object::elf::PT_LOAD {
            continue;
        }
        let bytes = ph
            .data(endian, data)
            .map_err(|()| FlashError::Elf(format!("segment {index}: data out of the file")))?;
        if bytes.is_empty() {
            continue;
        }
        let (offset, size) = ph.file_range(endian);
        let sections: Vec<String> = file
            .sections()
            .filter(|s| {
                s.file_range()
                    .is_some_and(|(o, n)| n > 0 && o >= offset && o + n <= offset + size)
            })
            .filter_map(|s| s.name().ok().map(str::to_string))
            .collect();
        if sections.is_empty() {
            continue;
        }
        out.push(Segment {
            index,
            address: ph.p_paddr(endian).into(),
            data: bytes.to_vec(),
            sections,
        });
    }
    Ok(out)
}

/// What the board makes of a table region: it arms, with this rig and table.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Armed {
    /// How the region is laid out.
    pub layout: RegionLayout,
    /// The rig's name.
    pub rig: String,
    /// Its segments.
    pub segments: usize,
    /// Its servo channels.
    pub servos: usize,
    /// Its servo back-end, as the rig file names it.
    pub output: &'static str,
    /// Table 0's grid, samples per axis (with layers: layer 0's table's).
    pub grid: Vec<u16>,
    /// Layers the region performs (0: table 0 alone).
    pub layers: usize,
}

impl fmt::Display for Armed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let layout = match self.layout {
            RegionLayout::Directory(n) => format!("region v{} ({n} entries)", region::VERSION),
            RegionLayout::Legacy => "older region layout (rig, table)".to_string(),
            RegionLayout::Unknown => "unknown layout".to_string(),
        };
        let grid: Vec<String> = self.grid.iter().map(u16::to_string).collect();
        let tables = if self.layers == 0 {
            format!("table 0 a {} grid", grid.join("×"))
        } else {
            format!(
                "{} layers, layer 0's table a {} grid",
                self.layers,
                grid.join("×")
            )
        };
        write!(
            f,
            "{layout}: rig `{}` ({} segments, {} servos on {}), {tables}: the board arms",
            self.rig, self.segments, self.servos, self.output,
        )
    }
}

/// The table flash as the board sees it: `bytes` at its start, erased
/// flash (`FF`) after them up to the region's size.
#[must_use]
pub fn board_image(layout: &Layout, bytes: &[u8]) -> Vec<u8> {
    let size = usize::try_from(layout.tables.size).unwrap_or(usize::MAX);
    let mut image = bytes.to_vec();
    if image.len() < size {
        image.resize(size, 0xFF);
    }
    image
}

/// Reads a table region exactly as the board does (the table flash with
/// `bytes` at its start, erased after them; the core's [`region::Region`] at the
/// firmware's capacity; the board's [`Support`] for the rig's output) and
/// says whether it arms, or why not.
pub fn check_region(layout: &Layout, bytes: &[u8]) -> Result<Armed, FlashError> {
    if bytes.get(..4) == Some(&table::MAGIC[..]) {
        return Err(FlashError::BareTable);
    }
    let image = board_image(layout, bytes);
    let region = region::Region::<FIRMWARE_SEGMENTS>::parse_sized(&image);
    let layers = region.layers.map_or(0, |l| l.as_slice().len());
    let first = region.table.as_ref().or(region.layer_tables[0].as_ref());
    let (Some(rig), Some(table), StatusReason::Ok) = (&region.rig, first, region.reason) else {
        return Err(FlashError::WouldNotArm {
            reason: region.reason,
            why: match region.refused_layer {
                Some(i) => format!("layer {i}'s table is refused ({:?})", region.reason),
                None => explain(&image),
            },
        });
    };
    layout
        .support
        .check(&rig.output(), rig.servos())
        .map_err(|r: Refusal| FlashError::WouldNotArm {
            reason: StatusReason::Unsupported,
            why: r.to_string(),
        })?;
    Ok(Armed {
        layout: region::layout(&image),
        rig: rig.name().to_string(),
        segments: rig.body().len(),
        servos: rig.servos().len(),
        output: support::kind_name(&rig.output()),
        grid: table.axes().iter().map(|a| a.count).collect(),
        layers,
    })
}

/// Why a region does not arm, in words: the first of the directory's, the
/// rig blob's and the table blob's own errors.
fn explain(image: &[u8]) -> String {
    let (rig, table) = match region::directory(image) {
        Ok(dir) => (
            dir.find(EntryKind::RIG, 0).map(|e| e.bytes),
            dir.find(EntryKind::TABLE, 0).map(|e| e.bytes),
        ),
        Err(region::RegionError::Magic)
            if image.get(..4) == Some(&marionette_core::rig::MAGIC[..]) =>
        {
            (Some(image), None)
        }
        Err(e) => return e.to_string(),
    };
    let Some(rig) = rig else {
        return "the region has no rig entry".into();
    };
    match Rig::<FIRMWARE_SEGMENTS>::parse_sized(rig) {
        Err(RigError::Capacity { segments, capacity }) => {
            return format!("the rig has {segments} segments; the firmware holds {capacity}");
        }
        Err(e) => return format!("the rig blob is refused: {e:?}"),
        Ok(_) => {}
    }
    match table.map(Table::parse) {
        None => "the region has no table".into(),
        Some(Err(e)) => format!("table 0: {e}"),
        Some(Ok(_)) => "table 0 was built for another rig, or is not a static grid".into(),
    }
}

/// Checks a table region image: not empty, fits the table flash, and (if
/// `check`) arms the board ([`check_region`]).
pub fn check_tables(layout: &Layout, bytes: &[u8], check: bool) -> Result<(), FlashError> {
    let size = bytes.len() as u64;
    if size == 0 {
        return Err(FlashError::EmptyTables);
    }
    if size > layout.tables.size {
        return Err(FlashError::TablesTooLarge {
            size,
            region: layout.tables,
        });
    }
    if check {
        check_region(layout, bytes)?;
    }
    Ok(())
}

/// Plans writing `elf` (the firmware ELF's bytes) and `tables` (a table
/// region image: rig + tables, [`marionette_core::region`]) into `layout`,
/// refusing anything that would not fit where it belongs. `check_blob` also
/// requires the region to arm the board ([`check_region`]).
pub fn plan(
    layout: &Layout,
    elf: Option<&[u8]>,
    tables: Option<&[u8]>,
    check_blob: bool,
) -> Result<Plan, FlashError> {
    let mut chunks = Vec::new();
    if let Some(elf) = elf {
        let segments = elf_segments(elf)?;
        if segments.is_empty() {
            return Err(FlashError::NoLoadableSegments);
        }
        for Segment {
            index: segment,
            address,
            data,
            sections,
        } in segments
        {
            let (len, end) = (data.len() as u64, address + data.len() as u64);
            if layout.tables.overlaps(address, len) {
                return Err(FlashError::ElfOverlapsTables {
                    segment,
                    start: address,
                    end,
                    region: layout.tables,
                });
            }
            if !layout.firmware.contains(address, len) {
                return Err(FlashError::ElfOutsideFirmware {
                    segment,
                    start: address,
                    end,
                    region: layout.firmware,
                });
            }
            chunks.push(Chunk {
                content: Content::Firmware { segment, sections },
                address,
                data,
            });
        }
    }
    if let Some(blob) = tables {
        check_tables(layout, blob, check_blob)?;
        chunks.push(Chunk {
            content: Content::Tables,
            address: layout.tables.start,
            data: blob.to_vec(),
        });
    }
    if chunks.is_empty() {
        return Err(FlashError::Nothing);
    }
    Ok(Plan {
        layout: *layout,
        chunks,
    })
}

/// How to [`program`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Options {
    /// Read the flash back afterwards and compare.
    pub verify: bool,
    /// Prepare everything on the probe, write nothing.
    pub dry_run: bool,
}

/// The table region after [`program`]: the bytes the board will read, and
/// what it makes of them.
#[derive(Debug)]
pub struct ReadBack {
    /// The whole table flash: read from the chip after writing, or (dry run)
    /// the bytes staged in probe-rs' flash loader over erased flash.
    pub image: Vec<u8>,
    /// Whether they are the bytes probe-rs staged rather than read from
    /// the chip (a dry run).
    pub staged: bool,
    /// [`check_region`] on the image: whether the board arms.
    pub verdict: Result<Armed, FlashError>,
}
