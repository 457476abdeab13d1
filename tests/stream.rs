//! `marionette stream` as a person would use it: the `perform` firmware on
//! QEMU with its tracker UART on a pseudo-terminal (`-chardev pty`) and its
//! servo UART to a file, the bundled kind of 1 kHz recording streamed at
//! its full rate. The emulated UART takes far fewer bytes a second than the
//! recording needs (DESIGN §6: about 20 kB/s), so the real-time sender must
//! drop frames (newest wins) and must not stall. The servo bytes the board
//! wrote equal the native core run on the frames actually sent.

use marionette_core::wire::Message;
use marionette_host::cmd::stream::{self, Args};
use marionette_host::perform::{self, Framing};
use marionette_host::{import, qemu};
use marionette_tests::puppet::{humanoid16, recording, rest_table, rig_blob};
use std::io::Write;
use std::path::PathBuf;
use std::time::{Duration, Instant};

#[test]
fn stream_at_1_khz_over_a_pty_drops_frames_never_stalls_and_matches_sim() {
    let dir = tempfile::tempdir().unwrap();
    let rig = humanoid16();
    // A 60 s fail-safe: a loaded machine must not trip it (the trips the
    // board reports are followed anyway; see tests/perform.rs).
    let region = perform::region(&rig_blob(&rig, Some(60_000)), Some(&rest_table(&rig)));
    let region_file = dir.path().join("region.bin");
    std::fs::write(&region_file, &region).unwrap();
    let servo_file = dir.path().join("uart1.bin");
    // 1,500 frames at 1 kHz: 1.5 s of a hand circling.
    let rec = dir.path().join("take.csv");
    let mut text = Vec::new();
    marionette_host::cmd::record::write_csv_exact(&mut text, &recording(1500)).unwrap();
    std::fs::File::create(&rec)
        .unwrap()
        .write_all(&text)
        .unwrap();

    let elf = qemu::firmware_elf("perform").unwrap();
    let mut board = qemu::PtyBoard::start(&elf, &region_file, &servo_file).unwrap();
    let args = Args {
        port: board.pty().display().to_string(),
        // The emulated UART's rate, about 20 kB/s: the sender never
        // writes faster, so nothing piles up in the pty.
        baud: 200_000,
        recording: rec.clone(),
        rig: marionette_tests::puppet::repo().join("rigs/humanoid16.toml"),
        fast: false,
        frame: Framing::Compact,
        out: dir.path().to_path_buf(),
        json: false,
        take: None,
        tables: Vec::new(),
        view: Default::default(),
    };
    let t0 = Instant::now();
    let (summary, replies) = stream::stream(&args, &std::sync::atomic::AtomicBool::new(false))
        .expect("stream completes");
    let took = t0.elapsed();
    assert_eq!(
        board.wait(Duration::from_secs(30)).unwrap(),
        Some(0),
        "the board ends on Disarm"
    );
    println!(
        "stream: {} of {} frames sent, {} dropped, {:.0} B/s of {:.0}, {:.2} s ({took:?} in all)",
        summary.sender.sent,
        summary.frames,
        summary.sender.dropped,
        summary.link_bytes_per_s,
        summary.link_capacity_bytes_per_s,
        summary.seconds
    );
    let c = &summary.sender;
    assert!(summary.disarm_acked);
    assert_eq!(c.offered, 1500);
    assert_eq!(c.sent + c.dropped, c.offered);
    assert!(
        c.dropped > 100,
        "at 1 kHz the emulated UART cannot take every frame"
    );
    assert!(c.sent > 100);
    // Real time: 1.5 s of recording takes about 1.5 s, not the backlog.
    assert!(summary.seconds < 3.0, "{} s", summary.seconds);
    assert!(summary.link_bytes_per_s <= summary.link_capacity_bytes_per_s * 1.05);
    assert!(summary.timing.is_some() && summary.telemetry > 0);

    // The servo bytes equal the native core on the frames actually sent.
    let sent = import::csv::read_tracker_csv(&PathBuf::from(&summary.sent_csv)).unwrap();
    let frames = perform::frames(&sent).unwrap();
    assert_eq!(frames.len() as u64, c.sent);
    let session = perform::session(&frames).unwrap();
    let outputs = perform::decode_maestro(&std::fs::read(&servo_file).unwrap(), 16);
    let followed = perform::follow(&region, &session, &outputs, &replies).unwrap();
    assert_eq!(followed.run.frame_targets.len(), frames.len());
    assert!(followed.compared >= frames.len());
    assert_eq!(followed.mismatches, 0, "trips {:?}", followed.trips);
    // The native run's own replies and the board's agree on the errors: none.
    let errors = replies.iter().rev().find_map(|m| match m {
        Message::Telemetry(t) => Some(t.errors),
        _ => None,
    });
    assert_eq!(errors.map(|e| e.total()), Some(0), "{errors:?}");
}
