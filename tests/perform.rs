//! The live loop end to end: the firmware on the emulated board against the
//! core run natively (`marionette sim`) on the same session, the fail-safe,
//! and line noise. The rig is the shipped `rigs/humanoid16.toml`; the table is
//! a small grid whose every sample is the rig's rest pose
//! (`perform::rest_grid`), so the solver does the visible work; the recording
//! is a synthetic right hand circling in front of the performer at 1 kHz.

use marionette_host::perform::{self, Pacing, Sent};
use marionette_tests::puppet::{self, humanoid16, limits, recording, rest_table, rig_blob};
use std::time::Duration;

struct Setup {
    region: Vec<u8>,
    region_file: tempfile::NamedTempFile,
    frames: usize,
    session: Vec<Sent>,
}

/// The bit-for-bit comparisons use a 60 s fail-safe time-out: the emulated
/// board's clock follows the wall clock, so on a loaded machine a stall of
/// the host longer than the rig's 100 ms would (rightly) trip the fail-safe
/// in the middle of a stream and make the board's output differ from a
/// native run that saw no gap. The fail-safe test keeps 100 ms.
fn setup(frames: u32, noise: bool) -> Setup {
    setup_with(frames, noise, Some(60_000))
}

fn setup_with(frames: u32, noise: bool, failsafe_timeout_ms: Option<u32>) -> Setup {
    let rig = humanoid16();
    let region = perform::region(
        &rig_blob(&rig, failsafe_timeout_ms),
        Some(&rest_table(&rig)),
    );
    let mut region_file = tempfile::NamedTempFile::new().unwrap();
    std::io::Write::write_all(&mut region_file, &region).unwrap();
    let frames_v = perform::frames(&recording(frames)).unwrap();
    let mut session = perform::session(&frames_v).unwrap();
    if noise {
        // Random bytes between messages (a small LCG: the inputs, not a
        // result), each run closed by a 0x00: a session sends no delimiter
        // before each frame (each ends in one), so noise not closed by one
        // would take the next frame with it (see tests/protocol.rs).
        let mut seed = 12345u32;
        for sent in session.iter_mut().skip(2) {
            let mut junk = Vec::new();
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            for _ in 0..(seed >> 27) {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                junk.push((seed >> 24) as u8);
            }
            junk.push(0);
            junk.extend_from_slice(&sent.bytes);
            sent.bytes = junk;
        }
    }
    Setup {
        region,
        region_file,
        frames: frames_v.len(),
        session,
    }
}

#[test]
fn the_emulated_board_drives_servos_exactly_as_the_native_core() {
    let s = setup(400, false);
    let native = perform::simulate(&s.region, &s.session).unwrap();
    assert_eq!(
        native.frame_targets.len(),
        s.frames,
        "every frame drives the servos"
    );
    let channels = native.frame_targets[0].len();
    assert_eq!(channels, 16);
    // The solver moved the arm: the targets are not all at rest.
    assert_ne!(native.frame_targets.first(), native.frame_targets.last());
    let (board, _) = perform::emulate(
        s.region_file.path(),
        &s.session,
        channels,
        s.frames,
        Pacing::AsFastAsPossible,
        Duration::ZERO,
    )
    .unwrap();
    assert_eq!(board.frame_targets.len(), s.frames);
    for (i, (a, b)) in native
        .frame_targets
        .iter()
        .zip(&board.frame_targets)
        .enumerate()
    {
        assert_eq!(a, b, "frame {i}: firmware and native core differ");
    }
}

#[test]
fn when_the_tracker_stops_the_servos_ease_to_rest_within_their_limits() {
    let s = setup_with(300, false, None);
    let native = perform::simulate(&s.region, &s.session).unwrap();
    let channels = native.frame_targets[0].len();
    // Stop streaming for 1.5 s (the fail-safe time-out is 0.1 s), then disarm.
    let (board, _) = perform::emulate(
        s.region_file.path(),
        &s.session,
        channels,
        s.frames,
        Pacing::AsFastAsPossible,
        Duration::from_millis(1500),
    )
    .unwrap();
    assert!(
        !board.rest_targets.is_empty(),
        "the fail-safe moved the servos"
    );
    let last = board.rest_targets.last().unwrap();
    let limits = limits(&humanoid16());
    for (ch, l) in limits.iter().enumerate() {
        assert_eq!(last[ch], l.rest, "channel {ch} ends at rest");
    }
    let rest: Vec<u16> = limits.iter().map(|l| l.rest).collect();
    let all: Vec<Vec<u16>> = std::iter::once(rest)
        .chain(board.frame_targets.iter().cloned())
        .chain(board.rest_targets.iter().cloned())
        .collect();
    let bad = puppet::violations(&all, &limits);
    assert!(bad.is_empty(), "limits violated: {bad:#?}");
}

#[test]
fn noise_between_frames_is_rejected_and_counted_and_every_frame_still_drives() {
    let clean = setup(300, false);
    let noisy = setup(300, true);
    let reference = perform::simulate(&clean.region, &clean.session).unwrap();
    let native = perform::simulate(&noisy.region, &noisy.session).unwrap();
    assert_eq!(
        native.frame_targets, reference.frame_targets,
        "noise changed the outputs"
    );
    let channels = native.frame_targets[0].len();
    let (board, _) = perform::emulate(
        noisy.region_file.path(),
        &noisy.session,
        channels,
        noisy.frames,
        Pacing::AsFastAsPossible,
        Duration::ZERO,
    )
    .unwrap();
    assert_eq!(board.frame_targets, reference.frame_targets);
    // The board's telemetry counts the rejected junk.
    let rejected = board
        .replies
        .iter()
        .filter_map(|m| match m {
            marionette_core::wire::Message::Telemetry(t) => Some(t.errors.total()),
            _ => None,
        })
        .max()
        .unwrap_or(0);
    assert!(rejected > 0, "no rejects counted in telemetry");
    let native_rejects = native.replies.iter().filter_map(|m| match m {
        marionette_core::wire::Message::Telemetry(t) => Some(t.errors.total()),
        _ => None,
    });
    assert_eq!(
        native_rejects.max(),
        Some(rejected),
        "board and native count the same rejects"
    );
}

#[test]
fn without_tables_the_board_refuses_to_arm_and_says_why() {
    let rig = humanoid16();
    let region = perform::region(&marionette_host::rigfile::to_blob(&rig).unwrap(), None);
    let frames = perform::frames(&recording(50)).unwrap();
    let session = perform::session(&frames).unwrap();
    let run = perform::simulate(&region, &session).unwrap();
    assert!(
        run.frame_targets.is_empty(),
        "a disarmed board drives nothing"
    );
    let status = run.replies.iter().find_map(|m| match m {
        marionette_core::wire::Message::Status(s) => Some(*s),
        _ => None,
    });
    let status = status.expect("Hello is answered with a Status");
    assert!(!status.armed);
    assert_eq!(status.reason, marionette_core::wire::StatusReason::NoTable);
}

/// The loop carries the solver's correction from frame to frame (its warm
/// start): with the tracker held still, the solved figure settles and stays
/// put instead of drifting (a correction added twice, or never replaced,
/// would walk it away frame after frame).
#[test]
fn a_still_tracker_gives_a_still_figure() {
    let rig = humanoid16();
    let region = perform::region(&rig_blob(&rig, Some(60_000)), Some(&rest_table(&rig)));
    let samples: Vec<_> = (0..200u32)
        .flat_map(|i| {
            let mut s = puppet::step(0, glam::DVec3::ZERO);
            for x in &mut s {
                x.time_us += u64::from(i) * 1000;
            }
            s
        })
        .collect();
    let frames = perform::frames(&samples).unwrap();
    let session = perform::session(&frames).unwrap();
    let mut poses = Vec::new();
    perform::simulate_with(&region, &session, &mut |p, u| {
        if matches!(u.outputs, Some(marionette_core::frame::Cause::Frame(_))) {
            poses.push(*p.pose().unwrap());
        }
    })
    .unwrap();
    assert_eq!(poses.len(), 200);
    let drift = |a: &marionette_core::pose::Pose<64>, b: &marionette_core::pose::Pose<64>| {
        a.positions()
            .iter()
            .zip(b.positions())
            .map(|(p, q)| (*p - *q).length())
            .fold(0.0f32, f32::max)
    };
    // Settled after a few frames, then still (well under a servo's step).
    for w in poses[20..].windows(2) {
        assert!(drift(&w[0], &w[1]) < 1e-4, "the figure drifts");
    }
    assert!(drift(&poses[20], &poses[199]) < 1e-4, "the figure drifts");
}

/// A region is read at a capacity (the firmware's is 24 segments): a rig
/// with more segments is refused with its own reason, and nothing drives.
#[test]
fn a_rig_over_the_capacity_is_refused_as_too_large() {
    use marionette_core::frame::{Performer, Region};
    use marionette_core::solve::SolverState;
    use marionette_core::wire::StatusReason;
    let rig = humanoid16();
    let region = perform::region(&rig_blob(&rig, None), Some(&rest_table(&rig)));
    let small = Region::<8>::parse_sized(&region);
    assert_eq!(small.reason, StatusReason::RigTooLarge);
    assert!(small.rig.is_none() && small.table.is_none());
    let mut solver = SolverState::new();
    let refused = Performer::new(&small, &mut solver);
    assert!(refused.pipeline().is_none() && refused.targets().is_empty());
    assert_eq!(refused.reason(), StatusReason::RigTooLarge);
    let mut fits = Region::<16>::EMPTY;
    fits.parse_into(&region);
    assert_eq!(fits.reason, StatusReason::Ok);
    let mut solver = SolverState::new();
    let performer = Performer::new(&fits, &mut solver);
    assert_eq!(
        performer
            .pose()
            .expect("humanoid16 (13 segments) fits 16")
            .len(),
        13,
        "humanoid16: 13 segments, 16 DOFs"
    );
}

/// The session of `s` with every message from frame 40 on 150 ms late (a
/// host stall longer than the rig's 100 ms fail-safe), on the emulated
/// board: its replies and its servo outputs.
fn stalled_from_frame_40(s: &Setup) -> (perform::Run, Vec<Vec<u16>>) {
    let mut late = s.session.clone();
    for sent in late.iter_mut().skip(2 + 40) {
        sent.time_us += 150_000;
    }
    let board = perform::simulate(&s.region, &late).unwrap();
    let stalled = perform::simulate_outputs(&s.region, &late).unwrap();
    (board, stalled)
}

/// A host stall on the way to the board: the messages from frame 40 on
/// arrive 150 ms late, so the rig's real 100 ms fail-safe eases the servos
/// towards rest before frame 40 (modelled natively: the core's own clock
/// logic). The board reports the trip in its telemetry; the replay of the
/// on-time session follows what it reported and then matches the stalled
/// outputs bit for bit; a changed target, or outputs scrambled, stay
/// mismatches, and without the board's report the stall is a mismatch.
#[test]
fn the_native_replay_follows_the_trips_the_board_reports() {
    let s = setup_with(120, false, None);
    let (board, stalled) = stalled_from_frame_40(&s);
    let on_time = perform::simulate_outputs(&s.region, &s.session).unwrap();
    let first = (0..stalled.len()).find(|&k| stalled.get(k) != on_time.get(k));
    assert_eq!(
        first,
        Some(40),
        "the stall changes the outputs from frame 40"
    );
    // The board said: one trip, ended by frame 40 (seq 41, after Arm's 0),
    // 51 fail-safe ticks (from 100 ms to 150 ms after frame 39, 1 ms apart).
    let trips = perform::reported_trips(&board.replies);
    assert_eq!(trips.len(), 1, "{trips:?}");
    assert_eq!(trips[0].seq, 41);
    assert!((49..=52).contains(&trips[0].ticks), "{trips:?}");

    let followed = perform::follow(&s.region, &s.session, &stalled, &board.replies).unwrap();
    assert_eq!(followed.mismatches, 0);
    assert_eq!(followed.unplaced, 0);
    let [(message, ticks)] = followed.trips[..] else {
        panic!("one trip expected, got {:?}", followed.trips)
    };
    assert_eq!(message, 2 + 40, "before frame 40 (after Hello and Arm)");
    assert_eq!(ticks, trips[0].ticks);
    let easing = followed.compared - s.frames;
    assert!(easing > 10, "the stall eased {easing} steps");
    assert_eq!(ticks as usize, easing, "one easing step per tick");
    assert_eq!(followed.run.frame_targets.len(), s.frames);

    let unreported = perform::follow(&s.region, &s.session, &stalled, &[]).unwrap();
    assert!(unreported.mismatches > 10, "{}", unreported.mismatches);

    let mut changed = stalled.clone();
    changed[100][3] ^= 4;
    let followed = perform::follow(&s.region, &s.session, &changed, &board.replies).unwrap();
    assert_eq!(followed.mismatches, 1, "one changed target, one mismatch");

    let mut scrambled = stalled.clone();
    scrambled[60..].reverse();
    let followed = perform::follow(&s.region, &s.session, &scrambled, &board.replies).unwrap();
    assert!(
        followed.mismatches > 50,
        "{} mismatches",
        followed.mismatches
    );
}

/// A take of a session the board's fail-safe tripped in (as `live` saves
/// one from the emulated board: the board's outputs, the first `frames` of
/// them frame-driven) holds the board's outputs in the board's order, at
/// times that never go back. The replay that follows a trip runs its
/// easing ticks after the time of the message that ended it, so sorting
/// the take's events by those times used to move that message's output
/// (and the next ones) before the easing: `tests/live.rs`'s `assert_eq!(taken,
/// outputs)` failed whenever a loaded machine stalled long enough to trip it.
#[test]
fn a_take_keeps_the_board_outputs_in_order_around_a_failsafe_trip() {
    let s = setup_with(120, false, None);
    let (board, stalled) = stalled_from_frame_40(&s);
    assert_eq!(perform::reported_trips(&board.replies).len(), 1);
    let mut frame_targets = stalled.clone();
    let rest_targets = frame_targets.split_off(s.frames.min(stalled.len()));
    let run = perform::Run {
        frame_targets,
        rest_targets,
        replies: board.replies.clone(),
        ..perform::Run::default()
    };
    let take = marionette_host::take::Take::of_run("live", &s.region, &s.session, &run).unwrap();
    let outputs = take.outputs();
    let taken: Vec<Vec<u16>> = outputs.iter().map(|o| o.2.clone()).collect();
    assert_eq!(taken.len(), stalled.len());
    let first = (0..taken.len()).find(|&k| taken[k] != stalled[k]);
    assert_eq!(first, None, "the take's outputs leave the board's order");
    assert!(outputs.windows(2).all(|w| w[0].0 <= w[1].0));
}

/// The emulated board reports its own fail-safe trip: the host goes quiet
/// for 0.4 s after frame 60 (the rig's time-out is 0.1 s). A `Status`
/// asked for during the silence says `FailSafe`; the `Telemetry` after the
/// next frame reports the trip ended by it; the native replay that follows
/// the board's report matches every servo output bit for bit.
#[test]
fn the_emulated_board_reports_its_failsafe_trip_and_the_replay_follows_it() {
    use marionette_core::wire::{Command, CommandKind, Message, State};
    use marionette_host::qemu;
    let s = setup_with(150, false, None);
    let channels = 16;
    let elf = qemu::firmware_elf("perform").unwrap();
    let config = qemu::Config {
        tables: Some(s.region_file.path().to_path_buf()),
        timeout: Duration::from_secs(120),
        ..qemu::Config::new(elf)
    };
    let mut board = qemu::Emulator::start(&config).unwrap();
    let (head, tail) = s.session.split_at(2 + 60);
    for sent in head {
        board.send(&sent.bytes).unwrap();
    }
    board.wait_servo_bytes(60 * channels * 4).unwrap();
    let silence = std::time::Instant::now();
    std::thread::sleep(Duration::from_millis(400));
    // Asked mid-silence: seq 1000 is far ahead; nothing else depends on it.
    let ask = Message::Command(Command {
        seq: 1000,
        kind: CommandKind::RequestStatus,
    });
    board.send(&perform::frame_bytes(&ask).unwrap()).unwrap();
    board
        .wait_replies(|b| {
            perform::decode_replies(b)
                .iter()
                .any(|m| matches!(m, Message::Status(st) if st.request_seq == Some(1000)))
        })
        .unwrap();
    // The session goes on after a Hello (the board restarts sequence
    // tracking from the next frame: no gap is counted for seq 1000).
    let hello = perform::encode(&Message::Hello(marionette_core::wire::Hello {
        protocol_version: marionette_core::wire::PROTOCOL_VERSION,
    }))
    .unwrap();
    board.send(&hello).unwrap();
    let (body, last) = tail.split_at(tail.len() - 1);
    for sent in body {
        board.send(&sent.bytes).unwrap();
    }
    // The silence as the host kept it, with 50 ms for the board's latency.
    let silent_ms = u32::try_from(silence.elapsed().as_millis() + 50).unwrap_or(u32::MAX);
    board.wait_servo_bytes(150 * channels * 4).unwrap();
    board.send(&last[0].bytes).unwrap();
    let out = board.finish().unwrap();
    let replies = perform::decode_replies(&out.tracker);
    let asked = replies.iter().find_map(|m| match m {
        Message::Status(st) if st.request_seq == Some(1000) => Some(*st),
        _ => None,
    });
    let asked = asked.expect("the RequestStatus is answered");
    assert_eq!(asked.state, State::FailSafe);
    assert!(asked.trips >= 1);
    let trips = perform::reported_trips(&replies);
    // Frames are seq 1.. (Arm is 0): the first after the silence is seq 61.
    let trip = trips
        .iter()
        .find(|t| t.seq == 61)
        .expect("the trip is reported");
    // The emulated loop ticks at most once a ms of the host's clock (it
    // reads it), and fewer times when the machine starves QEMU: at least one
    // tick, at most one per ms of the silence.
    assert!(
        (1..=silent_ms).contains(&trip.ticks),
        "{trips:?}, silence {silent_ms} ms"
    );
    // The native replay of the session as the board saw it, with the
    // board's trips: RequestStatus and Hello included.
    let mut seen: Vec<Sent> = head.to_vec();
    seen.push(Sent {
        time_us: head.last().unwrap().time_us,
        bytes: perform::frame_bytes(&ask).unwrap(),
    });
    seen.push(Sent {
        time_us: head.last().unwrap().time_us,
        bytes: hello,
    });
    seen.extend_from_slice(tail);
    let outputs = perform::decode_maestro(&out.servo, channels);
    let followed = perform::follow(&s.region, &seen, &outputs, &replies).unwrap();
    assert_eq!(followed.unplaced, 0);
    assert!(followed.compared >= 150);
    assert_eq!(followed.mismatches, 0, "trips {:?}", followed.trips);
}
