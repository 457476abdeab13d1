//! The firmware on the emulated board (QEMU `mps2-an386`), driven through the
//! host harness: links, the table region and the determinism of instruction
//! counts. The live loop against the native core is in `perform.rs`.

use marionette_host::icount;
use marionette_host::qemu::{self, Config, TABLE_REGION_LEN};
use std::io::Write;

fn echo_elf() -> std::path::PathBuf {
    qemu::firmware_elf("echo").expect("the embedded firmware is written out")
}

#[test]
fn echo_round_trips_on_both_uarts() {
    let message = b"marionette \x00\x01\xfe\xff";
    let mut input = message.to_vec();
    input.push(0x04); // EOT ends the session
    let out = qemu::run(&Config::new(echo_elf()), &input).expect("echo runs");
    assert_eq!(out.status, Some(0), "console: {}", out.console);
    assert_eq!(out.tracker, message, "UART0 echoes the tracker bytes");
    let complement: Vec<u8> = message.iter().map(|b| !b).collect();
    assert_eq!(out.servo, complement, "UART1 carries the complement");
}

#[test]
fn a_table_blob_is_visible_in_place() {
    let mut blob = tempfile::NamedTempFile::new().unwrap();
    blob.write_all(&[0x4d, 0x41, 0x52, 0x49, 0x01, 0x02, 0x03, 0xfe, 0x99])
        .unwrap();
    let config = Config {
        tables: Some(blob.path().to_path_buf()),
        ..Config::new(echo_elf())
    };
    let out = qemu::run(&config, &[0x04]).expect("echo runs");
    assert_eq!(out.status, Some(0));
    let expected = format!("tables 4d415249010203fe len {TABLE_REGION_LEN}");
    let got = out
        .console
        .lines()
        .find(|l| l.starts_with("tables"))
        .unwrap_or("");
    assert_eq!(got, expected, "console: {}", out.console);
}

#[test]
fn without_a_blob_the_table_region_reads_empty() {
    let out = qemu::run(&Config::new(echo_elf()), &[0x04]).expect("echo runs");
    assert!(
        out.console.contains("tables 0000000000000000 len"),
        "console: {}",
        out.console
    );
}

#[test]
fn instruction_counts_are_identical_across_runs() {
    let first = icount::measure().expect("bench runs");
    let second = icount::measure().expect("bench runs");
    assert!(first.iter().any(|r| r.name == "slerp.core"));
    assert!(first.iter().any(|r| r.name == "slerp.glam"));
    let ticks = |rows: &[icount::Row]| {
        rows.iter()
            .map(|r| (r.name.clone(), r.ticks))
            .collect::<Vec<_>>()
    };
    assert_eq!(ticks(&first), ticks(&second));
}
