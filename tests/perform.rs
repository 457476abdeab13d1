//! The live loop end to end: the firmware on the emulated board against the
//! core run natively (`marionette sim`) on the same session, the fail-safe,
//! and line noise. The rig is the shipped `rigs/humanoid16.toml`; the table is
//! a small grid whose every sample is the rig's rest pose
//! (`perform::rest_grid`), so the solver does the visible work; the recording
//! is a synthetic right hand circling in front of the performer at 1 kHz.

use glam::DVec3;
use marionette_host::import::csv::TrackerSample;
use marionette_host::perform::{self, Pacing, Sent};
use marionette_host::rigfile;
use std::path::PathBuf;
use std::time::Duration;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

struct Setup {
    region: Vec<u8>,
    region_file: tempfile::NamedTempFile,
    frames: usize,
    session: Vec<Sent>,
}

/// A 2×2×2 grid over the hand parameters, every sample the rest pose.
fn rest_table(rig: &rigfile::RigFile) -> Vec<u8> {
    let axes = [
        ("hand_x", -1.0, 2.0, 2),
        ("hand_y", -1.0, 2.0, 2),
        ("hand_z", -1.0, 2.0, 2),
    ];
    perform::rest_grid(rig, &axes).unwrap()
}

/// The performer's right hand circles in front of the pelvis tracker.
fn recording(frames: u32) -> Vec<TrackerSample> {
    let mut out = Vec::new();
    for i in 0..frames {
        let t = f64::from(i) * 1e-3;
        let a = t * std::f64::consts::TAU; // one turn per second
        let at = |sensor, position| TrackerSample {
            time_us: 1_000_000 + u64::from(i) * 1000,
            sensor,
            position,
            orientation: glam::DQuat::IDENTITY,
        };
        out.push(at(
            0,
            DVec3::new(-0.3 + 0.1 * a.cos(), 0.25 + 0.1 * a.sin(), 0.3),
        ));
        out.push(at(1, DVec3::new(0.3, -0.2, 0.1)));
        out.push(at(2, DVec3::ZERO));
    }
    out
}

/// The shipped rig's blob, with the fail-safe time-out replaced when given.
///
/// The emulated board's clock follows the wall clock, so on a loaded machine
/// a stall of the host longer than the rig's 100 ms time-out would (rightly)
/// trip the fail-safe in the middle of a stream and make the board's output
/// differ from a native run that saw no gap. Tests that compare outputs bit
/// for bit therefore use a 60 s time-out; the fail-safe test keeps 100 ms.
fn rig_blob(rig: &rigfile::RigFile, failsafe_timeout_ms: Option<u32>) -> Vec<u8> {
    let mut desc = rig.desc();
    if let Some(t) = failsafe_timeout_ms {
        desc.failsafe_timeout_ms = t;
    }
    let mut buf = vec![0u8; marionette_core::rig::MAX_BLOB_LEN];
    let n = desc.to_blob(&mut buf).unwrap();
    buf.truncate(n);
    buf
}

fn setup(frames: u32, noise: bool) -> Setup {
    setup_with(frames, noise, Some(60_000))
}

fn setup_with(frames: u32, noise: bool, failsafe_timeout_ms: Option<u32>) -> Setup {
    let rig = rigfile::load(&repo().join("rigs/humanoid16.toml")).unwrap();
    let region = perform::region(
        &rig_blob(&rig, failsafe_timeout_ms),
        Some(&rest_table(&rig)),
    );
    let mut region_file = tempfile::NamedTempFile::new().unwrap();
    std::io::Write::write_all(&mut region_file, &region).unwrap();
    let frames_v = perform::frames(&recording(frames)).unwrap();
    let mut session = perform::session(&frames_v).unwrap();
    if noise {
        // Random bytes between messages (a small LCG: the inputs, not a result).
        let mut seed = 12345u32;
        for sent in session.iter_mut().skip(2) {
            let mut junk = Vec::new();
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            for _ in 0..(seed >> 27) {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                junk.push((seed >> 24) as u8);
            }
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

/// Per-channel speed limit in quarter-µs per frame, and rest pulse, from the
/// rig file (independent of the loop).
fn limits() -> Vec<(u16, i32, u16, u16)> {
    let rig = rigfile::load(&repo().join("rigs/humanoid16.toml")).unwrap();
    let desc = rig.desc();
    let period = desc.frame_period_us as f32 * 1e-6;
    desc.servos
        .iter()
        .map(|s| {
            let l = s.step_limits(period);
            let q = |us: f32| (us * 4.0).round() as u16;
            let (lo, hi) = (
                s.pulse_min_us.min(s.pulse_max_us),
                s.pulse_min_us.max(s.pulse_max_us),
            );
            (q(s.rest_us), i32::from(l.max_step), q(lo), q(hi))
        })
        .collect()
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
    let limits = limits();
    for (ch, &(rest, _, _, _)) in limits.iter().enumerate() {
        assert_eq!(last[ch], rest, "channel {ch} ends at rest");
    }
    let all: Vec<&Vec<u16>> = board
        .frame_targets
        .iter()
        .chain(&board.rest_targets)
        .collect();
    for w in all.windows(2) {
        for (ch, &(_, max_step, lo, hi)) in limits.iter().enumerate() {
            let (a, b) = (i32::from(w[0][ch]), i32::from(w[1][ch]));
            assert!(
                (a - b).abs() <= max_step,
                "channel {ch}: step {a} -> {b} beyond {max_step}"
            );
            assert!(
                (lo..=hi).contains(&w[1][ch]),
                "channel {ch}: {} outside [{lo}, {hi}]",
                w[1][ch]
            );
        }
    }
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
    let rig = rigfile::load(&repo().join("rigs/humanoid16.toml")).unwrap();
    let region = perform::region(&rigfile::to_blob(&rig).unwrap(), None);
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
