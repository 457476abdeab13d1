#![cfg(feature = "flash")]
//! `marionette flash`'s library side: the Black Pill layout, the plan's
//! refusals, and staging/committing on probe-rs' fake probe.
//!
//! ELF files are written here by hand from the ELF32 specification (header,
//! program headers, section headers), independent of the `object` reader the
//! code under test uses.

use glam::{Quat, Vec3};
use marionette_core::table::{Interp, Kind, Wrap};
use marionette_core::wire::StatusReason;
use marionette_host::blob::{self, AxisSpec, TableSpec};
use marionette_host::flash::{
    self, BLACKPILL, Chunk, Content, DEFAULT_CHIP, FlashError, Options, Plan, Region,
};
use marionette_host::{icount, perform, rigfile};
use probe_rs::Permissions;
use probe_rs::probe::fake_probe::FakeProbe;

const KIB: u64 = 1024;

/// A section of a hand-built ELF: name, load address, bytes (`None`: a
/// NOBITS section of that many bytes, e.g. `.bss`).
struct Sec {
    name: &'static str,
    addr: u32,
    bytes: Option<Vec<u8>>,
    size: u32,
}

fn progbits(name: &'static str, addr: u32, len: usize) -> Sec {
    Sec {
        name,
        addr,
        bytes: Some((0..len).map(|i| (i % 251) as u8).collect()),
        size: len as u32,
    }
}

fn nobits(name: &'static str, addr: u32, size: u32) -> Sec {
    Sec {
        name,
        addr,
        bytes: None,
        size,
    }
}

/// An ELF32 little-endian ARM executable with one PT_LOAD segment per section
/// (p_paddr = p_vaddr = the section's address).
fn elf32(sections: &[Sec]) -> Vec<u8> {
    const EHSIZE: u32 = 52;
    const PHENTSIZE: u32 = 32;
    const SHENTSIZE: u32 = 40;
    let phnum = sections.len() as u32;
    let mut data_at = EHSIZE + phnum * PHENTSIZE;
    let mut offsets = Vec::new();
    for s in sections {
        offsets.push(data_at);
        data_at += s.bytes.as_ref().map_or(0, |b| b.len() as u32);
    }
    // .shstrtab: "\0" then each name, then ".shstrtab".
    let mut shstr = vec![0u8];
    let mut name_at = Vec::new();
    for s in sections {
        name_at.push(shstr.len() as u32);
        shstr.extend_from_slice(s.name.as_bytes());
        shstr.push(0);
    }
    let shstrtab_name = shstr.len() as u32;
    shstr.extend_from_slice(b".shstrtab\0");
    let shstr_at = data_at;
    let shoff = (shstr_at + shstr.len() as u32 + 3) & !3;
    let shnum = sections.len() as u32 + 2;

    let mut out = Vec::new();
    let u16le = |o: &mut Vec<u8>, v: u32| o.extend_from_slice(&(v as u16).to_le_bytes());
    let u32le = |o: &mut Vec<u8>, v: u32| o.extend_from_slice(&v.to_le_bytes());
    out.extend_from_slice(&[0x7F, b'E', b'L', b'F', 1, 1, 1, 0]);
    out.extend_from_slice(&[0; 8]);
    u16le(&mut out, 2); // ET_EXEC
    u16le(&mut out, 40); // EM_ARM
    u32le(&mut out, 1); // EV_CURRENT
    u32le(&mut out, sections.first().map_or(0, |s| s.addr) | 1); // entry (Thumb)
    u32le(&mut out, EHSIZE); // phoff
    u32le(&mut out, shoff);
    u32le(&mut out, 0x0500_0400); // EABI5, hard float
    u16le(&mut out, EHSIZE);
    u16le(&mut out, PHENTSIZE);
    u16le(&mut out, phnum);
    u16le(&mut out, SHENTSIZE);
    u16le(&mut out, shnum);
    u16le(&mut out, shnum - 1); // shstrndx: the last section
    assert_eq!(out.len(), EHSIZE as usize);
    for (s, &off) in sections.iter().zip(&offsets) {
        let filesz = s.bytes.as_ref().map_or(0, |b| b.len() as u32);
        u32le(&mut out, 1); // PT_LOAD
        u32le(&mut out, off);
        u32le(&mut out, s.addr); // vaddr
        u32le(&mut out, s.addr); // paddr
        u32le(&mut out, filesz);
        u32le(&mut out, s.size); // memsz
        u32le(&mut out, 5); // R+X
        u32le(&mut out, 4);
    }
    for s in sections {
        if let Some(b) = &s.bytes {
            out.extend_from_slice(b);
        }
    }
    out.extend_from_slice(&shstr);
    out.resize(shoff as usize, 0);
    out.extend_from_slice(&[0; 40]); // null section
    for ((s, &off), &name) in sections.iter().zip(&offsets).zip(&name_at) {
        u32le(&mut out, name);
        u32le(&mut out, if s.bytes.is_some() { 1 } else { 8 }); // PROGBITS / NOBITS
        u32le(&mut out, 6); // ALLOC | EXECINSTR
        u32le(&mut out, s.addr);
        u32le(&mut out, off);
        u32le(&mut out, s.size);
        u32le(&mut out, 0);
        u32le(&mut out, 0);
        u32le(&mut out, 4);
        u32le(&mut out, 0);
    }
    u32le(&mut out, shstrtab_name);
    u32le(&mut out, 3); // SHT_STRTAB
    u32le(&mut out, 0);
    u32le(&mut out, 0);
    u32le(&mut out, shstr_at);
    u32le(&mut out, shstr.len() as u32);
    out.extend_from_slice(&[0; 16]);
    out
}

/// A region the Black Pill arms with: `humanoid16` (a Maestro at 115 200
/// baud) and a 5×5×5 rest-pose grid built for it.
fn arming_region() -> Vec<u8> {
    icount::bench_region().expect("the bench region builds")
}

/// The humanoid16 rig blob.
fn humanoid16_blob() -> Vec<u8> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../rigs/humanoid16.toml");
    rigfile::to_blob(&rigfile::load(std::path::Path::new(path)).unwrap()).unwrap()
}

/// A small valid table blob (one axis, one segment), built for no rig.
fn tiny_blob() -> Vec<u8> {
    blob::write(&TableSpec {
        rig_hash: 0x1234,
        kind: Kind::Grid,
        axes: vec![AxisSpec {
            name: "x".into(),
            min: 0.0,
            step: 0.5,
            count: 2,
            wrap: Wrap::Bounded,
            interp: Interp::Linear,
        }],
        segment_names: vec!["root".into()],
        samples: vec![
            vec![(Vec3::ZERO, Quat::IDENTITY)],
            vec![(Vec3::new(1.0, -0.25, 0.0), Quat::IDENTITY)],
        ],
        valid: vec![true],
        durations: vec![],
        travel: vec![],
    })
    .expect("tiny spec is valid")
}

/// `ORIGIN` and `LENGTH` of a `memory.x` region, parsed from the text.
fn memory_x_region(text: &str, name: &str) -> (u64, u64) {
    let line = text
        .lines()
        .find(|l| l.trim_start().starts_with(name) && l.contains("ORIGIN"))
        .unwrap_or_else(|| panic!("no {name} in memory.x"));
    let field = |key: &str| {
        let rest = &line[line.find(key).unwrap() + key.len()..];
        let value = rest
            .trim_start_matches([' ', '='])
            .split([',', ' '])
            .next()
            .unwrap();
        if let Some(hex) = value.strip_prefix("0x") {
            u64::from_str_radix(hex, 16).unwrap()
        } else if let Some(k) = value.strip_suffix('K') {
            k.parse::<u64>().unwrap() * KIB
        } else {
            value.parse().unwrap()
        }
    };
    (field("ORIGIN"), field("LENGTH"))
}

#[test]
fn layout_matches_the_boards_linker_script() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../firmware/boards/blackpill/memory.x"
    );
    let text = std::fs::read_to_string(path).unwrap();
    let (flash, flash_len) = memory_x_region(&text, "FLASH");
    let (tables, tables_len) = memory_x_region(&text, "TABLES");
    assert_eq!((flash, flash_len), (0x0800_0000, 256 * KIB));
    assert_eq!((tables, tables_len), (0x0804_0000, 256 * KIB));
    assert_eq!(
        (BLACKPILL.firmware.start, BLACKPILL.firmware.size),
        (flash, flash_len)
    );
    assert_eq!(
        (BLACKPILL.tables.start, BLACKPILL.tables.size),
        (tables, tables_len)
    );
}

#[test]
fn region_bounds_are_half_open() {
    let r = Region {
        name: "r",
        start: 100,
        size: 10,
    };
    assert!(r.contains(100, 10) && r.contains(109, 1) && r.contains(105, 0));
    assert!(!r.contains(99, 2) && !r.contains(109, 2) && !r.contains(u64::MAX, 2));
    assert!(r.overlaps(109, 1) && r.overlaps(90, 11) && r.overlaps(90, 50));
    assert!(!r.overlaps(110, 5) && !r.overlaps(90, 10) && !r.overlaps(105, 0));
}

#[test]
fn blob_larger_than_the_region_is_refused() {
    let blob = vec![0u8; (256 * KIB + 1) as usize];
    let err = flash::plan(&BLACKPILL, None, Some(&blob), false).unwrap_err();
    match &err {
        FlashError::TablesTooLarge { size, region } => {
            assert_eq!(*size, 256 * KIB + 1);
            assert_eq!(*region, BLACKPILL.tables);
        }
        other => panic!("wrong error: {other:?}"),
    }
    let msg = err.to_string();
    assert!(msg.contains("262145 bytes"), "{msg}");
    assert!(msg.contains("holds 262144 bytes"), "{msg}");
    assert!(msg.contains("1 bytes too many"), "{msg}");
    // The size check comes before the content check.
    assert!(matches!(
        flash::plan(&BLACKPILL, None, Some(&blob), true),
        Err(FlashError::TablesTooLarge { .. })
    ));
}

#[test]
fn blob_filling_the_region_exactly_is_planned_at_its_start() {
    let blob = vec![0xA5u8; (256 * KIB) as usize];
    let plan = flash::plan(&BLACKPILL, None, Some(&blob), false).unwrap();
    assert_eq!(plan.chunks.len(), 1);
    let c = &plan.chunks[0];
    assert_eq!(c.content, Content::Tables);
    assert_eq!((c.address, c.len()), (0x0804_0000, 256 * KIB));
    assert_eq!(plan.bytes(), 256 * KIB);
    assert!(!plan.has_firmware());
}

/// The board's reason for a region, through the plan's check.
fn refused(region: &[u8]) -> (StatusReason, String) {
    match flash::plan(&BLACKPILL, None, Some(region), true) {
        Err(FlashError::WouldNotArm { reason, why }) => (reason, why),
        other => panic!("not refused as the board would: {other:?}"),
    }
}

#[test]
fn regions_the_board_would_not_arm_with_are_refused_with_its_reason() {
    let region = arming_region();
    let armed = flash::check_region(&BLACKPILL, &region).unwrap();
    assert_eq!(armed.rig, "humanoid16");
    assert_eq!((armed.segments, armed.servos), (13, 16));
    assert_eq!(
        (armed.output, armed.grid.clone()),
        ("maestro", vec![5, 5, 5])
    );
    assert!(armed.to_string().contains("the board arms"), "{armed}");
    assert!(flash::plan(&BLACKPILL, None, Some(&region), true).is_ok());

    // Junk: no rig. Flashed anyway with the check off.
    let junk = b"definitely not a region".to_vec();
    assert_eq!(refused(&junk).0, StatusReason::NoRig);
    assert!(flash::plan(&BLACKPILL, None, Some(&junk), false).is_ok());
    // A bare table blob: the old mistake, named.
    let err = flash::plan(&BLACKPILL, None, Some(&tiny_blob()), true).unwrap_err();
    assert!(matches!(err, FlashError::BareTable), "{err:?}");
    assert!(err.to_string().contains("--rig"), "{err}");
    // A flipped bit in the table blob: its CRC, with the table's words.
    let mut bad = region.clone();
    let last = bad.len() - 1;
    bad[last] ^= 1;
    let (reason, why) = refused(&bad);
    assert_eq!(reason, StatusReason::BadCrc);
    assert!(why.contains("table 0") && why.contains("CRC"), "{why}");
    // The directory's own CRC.
    let mut bad = region.clone();
    bad[9] ^= 1;
    let (reason, why) = refused(&bad);
    assert_eq!(reason, StatusReason::BadCrc);
    assert!(why.contains("directory"), "{why}");
    // A rig and no table.
    let rig_only = perform::region(&humanoid16_blob(), None);
    assert_eq!(refused(&rig_only).0, StatusReason::NoTable);
    // A table built for another rig.
    let other = perform::region(&humanoid16_blob(), Some(&tiny_blob()));
    assert_eq!(refused(&other).0, StatusReason::RigMismatch);
    // A rate the Black Pill's servo UART cannot make.
    let rig = rigfile::load(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../rigs/humanoid16.toml"
    )))
    .unwrap();
    let mut desc = rig.desc();
    desc.output = marionette_core::rig::Output::Dynamixel { baud: 3_000_000 };
    let mut buf = vec![0u8; marionette_core::rig::MAX_BLOB_LEN];
    let n = desc.to_blob(&mut buf).unwrap();
    let table = perform::rest_grid(&rig, &[("x", 0.0, 1.0, 2)]).unwrap();
    let (reason, why) = refused(&perform::region(&buf[..n], Some(&table)));
    assert_eq!(reason, StatusReason::Unsupported);
    assert!(why.contains("3000000 baud"), "{why}");
}

#[test]
fn empty_inputs_are_refused() {
    assert!(matches!(
        flash::plan(&BLACKPILL, None, None, true),
        Err(FlashError::Nothing)
    ));
    assert!(matches!(
        flash::plan(&BLACKPILL, None, Some(&[]), false),
        Err(FlashError::EmptyTables)
    ));
    let only_bss = elf32(&[nobits(".bss", 0x2000_0000, 64)]);
    assert!(matches!(
        flash::plan(&BLACKPILL, Some(&only_bss), None, true),
        Err(FlashError::NoLoadableSegments)
    ));
    assert!(matches!(
        flash::plan(&BLACKPILL, Some(b"\x7fELF garbage"), None, true),
        Err(FlashError::Elf(_))
    ));
}

#[test]
fn elf_segments_are_planned_at_their_load_addresses() {
    let elf = elf32(&[
        progbits(".vector_table", 0x0800_0000, 0x198),
        progbits(".text", 0x0800_0198, 1000),
        nobits(".bss", 0x2000_0000, 4096),
        progbits(".data", 0x0800_0580, 48),
    ]);
    let segs = flash::elf_segments(&elf).unwrap();
    let got: Vec<(usize, u64, usize, Vec<String>)> = segs
        .iter()
        .map(|s| (s.index, s.address, s.data.len(), s.sections.clone()))
        .collect();
    assert_eq!(
        got,
        vec![
            (0, 0x0800_0000, 0x198, vec![".vector_table".to_string()]),
            (1, 0x0800_0198, 1000, vec![".text".to_string()]),
            (3, 0x0800_0580, 48, vec![".data".to_string()]),
        ]
    );
    // The bytes written: i mod 251.
    assert_eq!(segs[1].data[249..253], [249, 250, 0, 1]);

    let blob = arming_region();
    let plan = flash::plan(&BLACKPILL, Some(&elf), Some(&blob), true).unwrap();
    assert_eq!(plan.chunks.len(), 4);
    assert!(plan.has_firmware());
    assert_eq!(plan.bytes(), (0x198 + 1000 + 48 + blob.len()) as u64);
    let last = plan.chunks.last().unwrap();
    assert_eq!(
        (last.content.clone(), last.address),
        (Content::Tables, 0x0804_0000)
    );
    assert_eq!(last.data, blob);
    let text = plan.to_string();
    assert!(text.contains("0x08040000"), "{text}");
    assert!(text.contains("ELF segment 1 [.text]"), "{text}");
}

#[test]
fn elf_reaching_the_table_region_is_refused() {
    // Ends exactly at the table region: fine.
    let fits = elf32(&[progbits(".text", 0x0803_FF00, 0x100)]);
    assert!(flash::plan(&BLACKPILL, Some(&fits), None, true).is_ok());
    // One byte more overlaps it.
    let over = elf32(&[
        progbits(".vector_table", 0x0800_0000, 0x100),
        progbits(".text", 0x0803_FF00, 0x101),
    ]);
    let err = flash::plan(&BLACKPILL, Some(&over), None, true).unwrap_err();
    match &err {
        FlashError::ElfOverlapsTables {
            segment,
            start,
            end,
            region,
        } => {
            assert_eq!((*segment, *start, *end), (1, 0x0803_FF00, 0x0804_0001));
            assert_eq!(*region, BLACKPILL.tables);
        }
        other => panic!("wrong error: {other:?}"),
    }
    assert!(
        err.to_string().contains("overlaps the table region"),
        "{err}"
    );
    // A segment inside the table region is an overlap too, not "outside".
    let inside = elf32(&[progbits(".tables", 0x0804_0000, 16)]);
    assert!(matches!(
        flash::plan(&BLACKPILL, Some(&inside), None, true),
        Err(FlashError::ElfOverlapsTables { .. })
    ));
}

#[test]
fn elf_for_another_memory_map_is_refused() {
    // The emulated board's firmware links at 0x0000_0000.
    let qemu = elf32(&[progbits(".vector_table", 0x0000_0000, 0x400)]);
    let err = flash::plan(&BLACKPILL, Some(&qemu), None, true).unwrap_err();
    assert!(
        matches!(
            err,
            FlashError::ElfOutsideFirmware {
                start: 0,
                end: 0x400,
                ..
            }
        ),
        "{err:?}"
    );
    // Code loaded into RAM is not flashed either.
    let ram = elf32(&[progbits(".ramfunc", 0x2000_0000, 16)]);
    assert!(matches!(
        flash::plan(&BLACKPILL, Some(&ram), None, true),
        Err(FlashError::ElfOutsideFirmware { .. })
    ));
}

#[test]
fn plan_is_checked_against_the_chips_memory_map() {
    let blob = arming_region();
    let plan = flash::plan(&BLACKPILL, None, Some(&blob), true).unwrap();
    flash::check_chip(&plan, DEFAULT_CHIP).unwrap();
    let err = flash::check_chip(&plan, "NOT_A_CHIP").unwrap_err();
    assert!(matches!(err, FlashError::Chip { .. }), "{err:?}");
    // Past the end of the 512 KiB flash (0x0808_0000): probe-rs refuses it.
    let beyond = Plan {
        layout: BLACKPILL,
        chunks: vec![Chunk {
            content: Content::Tables,
            address: 0x0807_FFF0,
            data: vec![0; 32],
        }],
    };
    let err = flash::check_chip(&beyond, DEFAULT_CHIP).unwrap_err();
    assert!(err.to_string().contains("0x0807fff0"), "{err}");
}

fn fake_session(chip: &str) -> probe_rs::Session {
    FakeProbe::with_mocked_core()
        .into_probe()
        .attach(chip, Permissions::default())
        .expect("fake probe attaches")
}

#[test]
fn fitting_plan_commits_as_a_dry_run_on_a_fake_probe() {
    let elf = elf32(&[
        progbits(".vector_table", 0x0800_0000, 0x198),
        progbits(".text", 0x0800_0198, 4000),
    ]);
    let region = arming_region();
    let plan = flash::plan(&BLACKPILL, Some(&elf), Some(&region), true).unwrap();
    for chip in ["STM32F411RETx", DEFAULT_CHIP] {
        let mut session = fake_session(chip);
        let mut events = 0;
        let options = Options {
            verify: false,
            dry_run: true,
        };
        let read_back = flash::program(&mut session, &plan, options, |_| events += 1)
            .unwrap_or_else(|e| panic!("{chip}: {e}"))
            .expect("the plan writes the table region");
        // A dry run reports its skipped steps and nothing else.
        assert!(events > 0, "{chip}: no progress event");
        // What the board will read: the region probe-rs staged, then erased
        // flash to the end of the 256 KiB table region; it parses as a
        // region the board arms with.
        assert!(read_back.staged);
        assert_eq!(read_back.image.len(), 256 * 1024);
        assert_eq!(&read_back.image[..region.len()], &region[..]);
        assert!(read_back.image[region.len()..].iter().all(|&b| b == 0xFF));
        let armed = read_back.verdict.as_ref().expect("the board arms");
        assert_eq!((armed.rig.as_str(), armed.servos), ("humanoid16", 16));
        let board = marionette_core::region::Region::<
            { marionette_core::region::FIRMWARE_SEGMENTS },
        >::parse_sized(&read_back.image);
        assert_eq!(board.reason, StatusReason::Ok);
        // Without a probe, the same staged bytes.
        let dry = flash::dry_read_back(&plan, chip).unwrap().unwrap();
        assert_eq!(dry.image, read_back.image);
    }
    // A plan without the table region reads nothing back.
    let firmware_only = flash::plan(&BLACKPILL, Some(&elf), None, true).unwrap();
    let mut session = fake_session(DEFAULT_CHIP);
    let options = Options {
        verify: false,
        dry_run: true,
    };
    assert!(
        flash::program(&mut session, &firmware_only, options, |_| {})
            .unwrap()
            .is_none()
    );
}

#[test]
fn chunk_beyond_flash_is_refused_on_a_fake_probe() {
    let mut session = fake_session("STM32F411RETx");
    let plan = Plan {
        layout: BLACKPILL,
        chunks: vec![Chunk {
            content: Content::Tables,
            address: 0x0804_0000,
            data: vec![0; (256 * KIB + 16) as usize],
        }],
    };
    let options = Options {
        verify: false,
        dry_run: true,
    };
    let err = flash::program(&mut session, &plan, options, |_| {}).unwrap_err();
    assert!(matches!(err, FlashError::Chip { .. }), "{err:?}");
}
