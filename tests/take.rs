//! Takes (issue #17): a session on the emulated board saved as a take,
//! read back, and replayed on the emulated board, whose outputs must be
//! bit-identical to the take's; edits and exports checked against hand-worked
//! or independent results.
//!
//! The rig is the shipped humanoid16 with a 60 s fail-safe time-out (as in
//! tests/perform.rs: a loaded machine's stall must not trip the board), the
//! table a rest grid, the recording a synthetic hand circling at 1 kHz.

use marionette_host::cmd::replay;
use marionette_host::perform::{self, Pacing};
use marionette_host::take::{EventKind, Take};
use marionette_tests::puppet::{humanoid16, recording, rest_table, rig_blob};
use std::time::Duration;

fn region() -> Vec<u8> {
    let rig = humanoid16();
    perform::region(&rig_blob(&rig, Some(60_000)), Some(&rest_table(&rig)))
}

/// A take of `frames` frames made on the emulated board.
fn emulated_take(frames: u32) -> Take {
    let region = region();
    let mut file = tempfile::NamedTempFile::new().unwrap();
    std::io::Write::write_all(&mut file, &region).unwrap();
    let tracker = perform::frames(&recording(frames)).unwrap();
    let session = perform::session(&tracker).unwrap();
    let (board, _) = perform::emulate(
        file.path(),
        &session,
        16,
        tracker.len(),
        Pacing::AsFastAsPossible,
        Duration::ZERO,
    )
    .unwrap();
    assert_eq!(board.fault, None);
    Take::of_run("emulate", &region, &session, &board).unwrap()
}

#[test]
fn an_emulated_take_reads_back_and_replays_bit_for_bit() {
    let take = emulated_take(300);
    let bytes = take.to_bytes().unwrap();
    let back = Take::parse(&bytes).unwrap();
    assert_eq!(back, take);
    // What the take holds: the session, the outputs and the replies.
    let info = back.info();
    assert_eq!(info.sent.tracker_frames, 300);
    assert_eq!(info.sent.commands, 2);
    assert_eq!(info.frame_outputs, 300);
    assert!(info.telemetry >= 30, "{info:?}");
    // Its outputs are the native core's on the same session (independent
    // of the board), each frame-driven one at its tracker frame's time.
    let native = perform::simulate_timed(&back.region, &back.session()).unwrap();
    let outputs = back.outputs();
    assert_eq!(outputs.len(), native.len());
    for (k, (o, n)) in outputs.iter().zip(&native).enumerate() {
        assert_eq!(o, n, "output {k}");
    }
    let frame_times: Vec<u32> = perform::frames(&recording(300))
        .unwrap()
        .iter()
        .map(|f| f.time_us)
        .collect();
    let output_times: Vec<u32> = outputs.iter().filter(|o| o.1).map(|o| o.0).collect();
    assert_eq!(output_times, frame_times);
    // Replayed on the emulated board: bit-identical.
    let summary = replay::emulated(&back, Pacing::AsFastAsPossible, 1.0).unwrap();
    assert_eq!(summary.failsafe_trips, [0, 0]);
    assert_eq!(summary.board_outputs, Some(outputs.len()));
    assert_eq!(summary.mismatches, Some(0), "{summary:?}");
}

#[test]
fn a_take_whose_outputs_were_changed_does_not_replay_identically() {
    let mut take = emulated_take(60);
    let k = take
        .events
        .iter()
        .position(|e| e.kind == EventKind::FrameOutput)
        .unwrap();
    take.events[k].data[0] ^= 4;
    let summary = replay::emulated(&take, Pacing::AsFastAsPossible, 1.0).unwrap();
    assert_eq!(summary.mismatches, Some(1), "{summary:?}");
}
