//! Flashing the board: the firmware ELF into the code region and the table
//! blob into its own region, with probe-rs.
//!
//! The Black Pill's flash is split by `firmware/boards/blackpill/memory.x`:
//! sectors 0–5 (`0x0800_0000`, 256 KiB) hold the firmware and sectors 6–7
//! (`0x0804_0000`, 256 KiB) hold the table blob, so tables can be re-flashed
//! without touching the code ([`BLACKPILL`]).
//!
//! Flashing is two steps:
//!
//! 1. [`plan`] (no hardware): reads the ELF's loadable segments (what probe-rs
//!    would program: `PT_LOAD` segments with file data, at their physical
//!    address), checks that each lies inside the firmware region and none
//!    touches the table region, checks that the blob fits the table region
//!    and (unless told not to) that it is a table blob the core accepts.
//!    [`check_chip`] then stages the plan in a probe-rs flash loader for the
//!    chip's built-in memory map, which catches addresses the chip has no
//!    flash for, still without a probe.
//! 2. [`program`]: stages the same chunks on an attached session and commits
//!    them (erase, program, optional verify), reporting progress through a
//!    callback. With `dry_run` probe-rs prepares everything (flash algorithm,
//!    sector layout) and writes nothing.

use marionette_core::table::{Table, TableError};
use object::read::elf::{ElfFile, FileHeader, ProgramHeader};
use object::{Object, ObjectSection};
use probe_rs::config::Registry;
use probe_rs::flashing::{DownloadOptions, FlashLoader, FlashProgress, ProgressEvent};
use probe_rs::{Permissions, Session, SessionConfig};
use std::fmt;

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
    /// The table blob's region.
    pub tables: Region,
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
    /// The table blob.
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
                Content::Tables => ("table blob".to_string(), self.layout.tables),
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
    /// The blob is empty.
    #[error("the table blob is empty")]
    EmptyTables,
    /// The blob does not fit the table region.
    #[error(
        "the table blob is {size} bytes but the table region ({region}) holds {} bytes: \
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
    /// The blob is not one the core's reader accepts.
    #[error("the table blob is not valid: {0}")]
    BadTables(TableError),
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

/// Checks a table blob: not empty, fits the region, and (if `check`) parses
/// with the core's reader (magic, version, header, bounds, CRC).
pub fn check_tables(layout: &Layout, blob: &[u8], check: bool) -> Result<(), FlashError> {
    let size = blob.len() as u64;
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
        Table::parse(blob).map_err(FlashError::BadTables)?;
    }
    Ok(())
}

/// Plans writing `elf` (the firmware ELF's bytes) and `tables` (the blob)
/// into `layout`, refusing anything that would not fit where it belongs.
/// `check_blob` also requires the blob to parse as a table.
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

/// Stages a plan's chunks in a flash loader (probe-rs checks each against
/// the chip's memory map).
pub fn stage(mut loader: FlashLoader, plan: &Plan, chip: &str) -> Result<FlashLoader, FlashError> {
    for c in &plan.chunks {
        loader
            .add_data(c.address, &c.data)
            .map_err(|e| FlashError::Chip {
                chip: chip.to_string(),
                reason: format!("{:#010x} (+{} bytes): {}", c.address, c.len(), chain(&e)),
            })?;
    }
    Ok(loader)
}

/// Checks a plan against the chip's built-in description without a probe:
/// the chip must be known and every chunk must lie in its memory.
pub fn check_chip(plan: &Plan, chip: &str) -> Result<(), FlashError> {
    let target = Registry::from_builtin_families()
        .get_target_by_name(chip)
        .map_err(|e| FlashError::Chip {
            chip: chip.to_string(),
            reason: e.to_string(),
        })?;
    stage(target.flash_loader(), plan, chip).map(|_| ())
}

/// How to [`program`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Options {
    /// Read the flash back afterwards and compare.
    pub verify: bool,
    /// Prepare everything on the probe, write nothing.
    pub dry_run: bool,
}

/// Attaches to `chip` through the first probe found.
pub fn attach(chip: &str) -> Result<Session, FlashError> {
    let config = SessionConfig {
        permissions: Permissions::default(),
        ..SessionConfig::default()
    };
    Session::auto_attach(chip, config).map_err(|e| FlashError::Probe(chain(&e)))
}

/// Writes a plan through an attached session, reporting progress events to
/// `progress`. Erases only the sectors written; bytes of a written sector
/// that the plan does not cover are not kept.
pub fn program(
    session: &mut Session,
    plan: &Plan,
    options: Options,
    progress: impl FnMut(ProgressEvent),
) -> Result<(), FlashError> {
    let chip = session.target().name.clone();
    let loader = stage(session.target().flash_loader(), plan, &chip)?;
    let mut download = DownloadOptions::default();
    download.verify = options.verify;
    download.dry_run = options.dry_run;
    download.progress = FlashProgress::new(progress);
    loader
        .commit(session, download)
        .map_err(|e| FlashError::Flash(chain(&e)))
}

/// An error and its sources, `: `-separated (probe-rs' top-level messages
/// are often generic, the cause is in the sources).
fn chain(e: &dyn std::error::Error) -> String {
    let mut out = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        let text = s.to_string();
        if !out.contains(&text) {
            out.push_str(": ");
            out.push_str(&text);
        }
        source = s.source();
    }
    out
}
