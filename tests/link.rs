//! The link budget in README.md is computed from the encoder itself
//! (`marionette_host::link::budget_table`), so it cannot drift from the
//! code: the README must hold the table exactly as computed now. And the
//! compact frame meets #14's targets on it.

use marionette_host::link::{self, Link};
use marionette_host::perform::Framing;

#[test]
fn the_readme_table_is_what_the_encoder_gives() {
    let readme = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../README.md"))
        .expect("README.md");
    let table = link::budget_table();
    assert!(
        readme.contains(&table),
        "README.md's link budget is stale; the encoder gives:\n{table}"
    );
}

/// A 3-sensor compact frame is at most 48 bytes framed, and a 1 kHz stream
/// of them takes at most half of a 921,600-baud UART (10 bits a byte).
#[test]
fn three_sensors_at_1_khz_fit_half_the_uart() {
    let bytes = link::frame_bytes(3, Framing::Compact);
    assert!(bytes <= 48, "{bytes}");
    assert!(bytes * 1000 * 10 <= 921_600 / 2, "{bytes}");
    assert!(Link::UART_921600.load(bytes, 1000.0) <= 0.5);
    // The f32 frame does not fit at all.
    assert!(Link::UART_921600.max_frames_per_second(link::frame_bytes(3, Framing::F32)) < 1000);
}
