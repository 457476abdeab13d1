//! The table region with real blobs: the shipped `humanoid16` rig and a rest
//! grid, laid out by the core's writer, placed where the format says, read
//! back by the board's parse; regions of the older layout still arm; an
//! entry of a kind this reader does not know is skipped.

use marionette_core::region::{self, Entry, EntryKind, FIRMWARE_SEGMENTS, Layout, Region, layout};
use marionette_core::wire::StatusReason;
use marionette_host::perform;
use marionette_tests::puppet::{humanoid16, rest_table, rig_blob};

fn blobs() -> (Vec<u8>, Vec<u8>) {
    let rig = humanoid16();
    (rig_blob(&rig, None), rest_table(&rig))
}

#[test]
fn the_writer_places_each_blob_where_the_directory_says() {
    let (rig, table) = blobs();
    let bytes = perform::region(&rig, Some(&table));
    // Prefix, two 12-byte entries, CRC: the rig at 36, the table at the next
    // multiple of 4 after it; the whole region padded to a multiple of 4.
    assert_eq!(&bytes[..8], b"MREG\x01\x00\x02\x00");
    let field = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
    assert_eq!(
        (field(8) & 0xFFFF, field(12), field(16)),
        (1, 36, rig.len())
    );
    let table_at = (36 + rig.len()).div_ceil(4) * 4;
    assert_eq!(
        (field(20) & 0xFFFF, field(24), field(28)),
        (2, table_at, table.len())
    );
    assert_eq!(&bytes[36..36 + rig.len()], &rig[..]);
    assert_eq!(&bytes[table_at..table_at + table.len()], &table[..]);
    assert_eq!(bytes.len(), (table_at + table.len()).div_ceil(4) * 4);
    let board = Region::<FIRMWARE_SEGMENTS>::parse_sized(&bytes);
    assert_eq!(board.reason, StatusReason::Ok);
    assert_eq!(layout(&bytes), Layout::Directory(2));
    assert_eq!(board.rig.as_ref().unwrap().name(), "humanoid16");
    let dir = region::directory(&bytes).unwrap();
    assert_eq!(dir.find(EntryKind::TABLE, 0).unwrap().bytes, &table[..]);
}

#[test]
fn a_region_of_the_older_layout_still_arms() {
    let (rig, table) = blobs();
    // Rig blob, zero padding to 4, table blob: the layout before the
    // directory (the rig blob's length is already a multiple of 4).
    let mut old = rig.clone();
    old.resize(rig.len().next_multiple_of(4), 0);
    old.extend_from_slice(&table);
    let legacy = Region::<FIRMWARE_SEGMENTS>::parse_sized(&old);
    let new = perform::region(&rig, Some(&table));
    let current = Region::<FIRMWARE_SEGMENTS>::parse_sized(&new);
    assert_eq!(
        (legacy.reason, layout(&old)),
        (StatusReason::Ok, Layout::Legacy)
    );
    assert_eq!(
        legacy.rig.as_ref().unwrap().rig_hash(),
        current.rig.as_ref().unwrap().rig_hash()
    );
    assert_eq!(
        legacy.table.as_ref().unwrap().rig_hash(),
        current.table.as_ref().unwrap().rig_hash()
    );
    assert!(region::directory(&old).is_err());
    // The older layout with erased flash after the rig: no table.
    let mut erased = rig.clone();
    erased.extend_from_slice(&[0xFF; 64]);
    assert_eq!(Region::parse(&erased).reason, StatusReason::NoTable);
}

#[test]
fn unknown_entry_kinds_are_skipped_and_a_damaged_table_says_why() {
    let (rig, table) = blobs();
    let show = [0x5A; 10];
    let entries = [
        Entry {
            kind: EntryKind(77),
            bytes: &show,
        },
        Entry::rig(&rig),
        Entry::table(&table),
        Entry {
            kind: EntryKind(78),
            bytes: &show,
        },
    ];
    let mut bytes = vec![0u8; region::len(&entries).unwrap()];
    region::write(&entries, &mut bytes).unwrap();
    let board = Region::<FIRMWARE_SEGMENTS>::parse_sized(&bytes);
    assert_eq!(
        (board.reason, layout(&bytes)),
        (StatusReason::Ok, Layout::Directory(4))
    );
    assert_eq!(
        region::directory(&bytes)
            .unwrap()
            .find(EntryKind(78), 0)
            .unwrap()
            .bytes,
        &show
    );
    // The second table is not table 0; a damaged table 0 is refused.
    let mut bad = table.clone();
    let mid = bad.len() / 2;
    bad[mid] ^= 4;
    let entries = [Entry::rig(&rig), Entry::table(&bad), Entry::table(&table)];
    let mut bytes = vec![0u8; region::len(&entries).unwrap()];
    region::write(&entries, &mut bytes).unwrap();
    assert_eq!(Region::parse(&bytes).reason, StatusReason::BadCrc);
}
