//! The demo's inputs end to end, natively (`marionette demo` runs the same
//! on the emulated board): the bundled tracker recording
//! (`data/recordings/reach_hdm05_007.csv`, an HDM05 grab held out of the
//! table), the shipped `rigs/humanoid16.toml` and the table built from the
//! bundled spec (`data/builds/reach_humanoid16.toml`) arm the board, and
//! every tracker frame drives all 16 servos, each within the pulses of its
//! joint's limits, computed here in `f64` from the rig file's own numbers
//! (the servo calibration's linear map), not by the code under test. And
//! the bundled recording is exactly what its `SOURCE.txt` command makes.

use marionette_core::frame::{NoCycles, Performer, Region};
use marionette_core::solve::SolverState;
use marionette_core::table::Kind;
use marionette_core::wire::StatusReason;
use marionette_host::cmd::demo;
use marionette_host::import::csv::read_tracker_csv;
use marionette_host::perform;
use marionette_host::rigfile;
use std::path::PathBuf;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Per channel: the pulses (µs) of the joint's two limits, lowest first.
fn limit_pulses(rig: &rigfile::RigFile) -> Vec<(u8, f64, f64)> {
    let desc = rig.desc();
    let segments = desc.segments.as_slice();
    desc.servos
        .as_slice()
        .iter()
        .map(|s| {
            let dof = segments[usize::from(s.segment)].dofs.as_slice()[usize::from(s.dof)];
            let pulse = |angle: f32| {
                let (a0, a1) = (f64::from(s.angle_min), f64::from(s.angle_max));
                let (p0, p1) = (f64::from(s.pulse_min_us), f64::from(s.pulse_max_us));
                let u = ((f64::from(angle) - a0) / (a1 - a0)).clamp(0.0, 1.0);
                let u = if s.reversed { 1.0 - u } else { u };
                (p0 + u * (p1 - p0) + f64::from(s.trim_us)).clamp(p0.min(p1), p0.max(p1))
            };
            let (a, b) = (pulse(dof.min), pulse(dof.max));
            (s.channel, a.min(b), a.max(b))
        })
        .collect()
}

#[test]
fn the_bundled_take_arms_the_board_and_drives_all_16_servos_within_their_limits() {
    let built = demo::build_table(&repo().join("data/builds/reach_humanoid16.toml")).unwrap();
    let rig_path = repo().join("rigs/humanoid16.toml");
    let recording = repo().join("data/recordings/reach_hdm05_007.csv");
    let inputs = demo::inputs(&rig_path, &built.blob, &recording).unwrap();

    // Rig + table arm: the table is a grid for this rig's skeleton.
    let rig = rigfile::load(&rig_path).unwrap();
    let region = Region::parse(&inputs.region);
    assert_eq!(region.reason, StatusReason::Ok);
    let table = region.table.as_ref().unwrap();
    assert_eq!(table.kind(), Kind::Grid);
    assert_eq!(table.rig_hash(), rig.rig_hash());
    assert_eq!(table.segment_count(), rig.segment_names().len());
    assert_eq!(table.axes().len(), 3, "the rig's params 0-2");

    // Every one of the 2134 frames (2.133 s at 1 kHz) drives the servos;
    // none is dropped.
    assert_eq!(inputs.frames, 2134);
    let peak = highest_hand_frame(&recording);
    let native = demo::native(&inputs, &[peak]).unwrap();
    assert_eq!(native.reason, StatusReason::Ok);
    assert_eq!(native.run.frame_targets.len(), inputs.frames);
    assert_eq!(native.failed, 0);

    // All 16 channels, every output within its joint's limit pulses (a
    // quarter-µs of rounding allowed), during the take and the easing to
    // rest after it.
    let limits = limit_pulses(&rig);
    assert_eq!(limits.len(), 16);
    let all = native
        .run
        .frame_targets
        .iter()
        .chain(&native.run.rest_targets);
    for targets in all {
        assert_eq!(targets.len(), 16);
        for &(ch, lo, hi) in &limits {
            let us = f64::from(targets[usize::from(ch)]) / 4.0;
            assert!(
                (lo - 0.25..=hi + 0.25).contains(&us),
                "channel {ch}: {us} µs outside [{lo}, {hi}]"
            );
        }
    }
    // The reach moves the right arm: shoulder pitch (channel 5) over more
    // than 90° (1000 µs of its 2000 µs per 180°), the elbow (7) too.
    let span = |ch: usize| {
        let v: Vec<u16> = native.run.frame_targets.iter().map(|t| t[ch]).collect();
        f64::from(v.iter().max().unwrap() - v.iter().min().unwrap()) / 4.0
    };
    assert!(
        span(5) > 1000.0,
        "right shoulder pitch moved {} µs",
        span(5)
    );
    assert!(span(7) > 300.0, "right elbow moved {} µs", span(7));
    // After the take every servo is back at its rest pulse.
    let last = native.run.rest_targets.last().unwrap();
    for s in rig.desc().servos.as_slice() {
        let rest = f64::from(last[usize::from(s.channel)]) / 4.0;
        assert!((rest - f64::from(s.rest_us)).abs() <= 0.25, "{s:?}: {rest}");
    }

    // At the top of the grab the puppet's right palm (the forearm's touch
    // point) is above its shoulder (0.44 + 0.05 + 0.22 m) and in front.
    let (_, pose) = native.poses.first().unwrap();
    let i = rig
        .segment_names()
        .iter()
        .position(|s| s == "r_forearm")
        .unwrap();
    let touch = glam::Vec3::from_array(rig.desc().segments.as_slice()[i].touch);
    let palm = pose.positions()[i] + pose.rotations()[i] * touch;
    assert!(palm.y > 0.71 && palm.z > 0.1, "palm at {palm}");
}

/// The sequence number (from 1) of the frame where the right-hand tracker is
/// highest above the pelvis tracker.
fn highest_hand_frame(recording: &std::path::Path) -> u32 {
    let samples = read_tracker_csv(recording).unwrap();
    let frames = perform::frames(&samples).unwrap();
    let height = |f: &marionette_core::wire::TrackerFrame| {
        let y = |id: u8| {
            f.sensors
                .iter()
                .find(|s| s.id == id)
                .map(|s| s.position[1])
                .unwrap()
        };
        y(0) - y(2)
    };
    frames
        .iter()
        .max_by(|a, b| height(a).total_cmp(&height(b)))
        .unwrap()
        .seq
}

#[test]
fn the_bundled_recording_is_what_marionette_record_makes() {
    // data/recordings/SOURCE.txt: `marionette record
    // data/hdm05_bk/HDM_bk_grabHighR_007_120.amc --skeleton
    // data/hdm05_bk/HDM_bk.asf --frame f32` (the f32 frame's rounding:
    // 0.1 mm, 1e-5) with the other defaults.
    use marionette_host::cmd::record;
    let hdm = repo().join("data/hdm05_bk");
    let motion = record::read_clip(
        &hdm.join("HDM_bk_grabHighR_007_120.amc"),
        Some(&hdm.join("HDM_bk.asf")),
        None,
        120.0,
    )
    .unwrap();
    let samples = record::record(&motion, &record::default_trackers(&motion), 1000.0, 0).unwrap();
    let mut made = Vec::new();
    record::write_csv(&mut made, &samples).unwrap();
    let bundled = std::fs::read(repo().join("data/recordings/reach_hdm05_007.csv")).unwrap();
    assert!(
        made == bundled,
        "the bundled recording differs from a fresh one"
    );
}
/// The firmware's capacity (`app::SEGMENTS` in firmware/src/app.rs).
const FIRMWARE_SEGMENTS: usize = 24;

/// A performer's capacity changes its memory, never its numbers: on the
/// demo's session, the firmware's capacity and the host's default give the
/// same pose and servo targets after every message (the board-vs-native
/// comparisons rest on it), and the same easing to rest.
#[test]
fn the_capacity_never_changes_the_output() {
    let root = repo();
    let built = demo::build_table(&root.join("data/builds/reach_humanoid16.toml")).unwrap();
    let inputs = demo::inputs(
        &root.join("rigs/humanoid16.toml"),
        &built.blob,
        &root.join("data/recordings/reach_hdm05_007.csv"),
    )
    .unwrap();
    let host = Region::parse(&inputs.region);
    let board = Region::<FIRMWARE_SEGMENTS>::parse_sized(&inputs.region);
    let (mut s1, mut s2) = (SolverState::new(), SolverState::new());
    let mut a = Performer::new(&host, &mut s1);
    let mut b = Performer::new(&board, &mut s2);
    let (mut time, mut armed) = (0, false);
    for (k, sent) in inputs.session.iter().enumerate() {
        let (mut ia, mut ib) = (sent.bytes.as_slice(), sent.bytes.as_slice());
        while !ia.is_empty() {
            a.receive(&mut ia, sent.time_us, &mut NoCycles);
        }
        while !ib.is_empty() {
            b.receive(&mut ib, sent.time_us, &mut NoCycles);
        }
        let (pa, pb) = (a.pose().unwrap(), b.pose().unwrap());
        assert_eq!(pa.len(), pb.len());
        for s in 0..pa.len() {
            assert_eq!(pa.positions[s], pb.positions[s], "message {k}, segment {s}");
            assert_eq!(pa.rotations[s], pb.rotations[s], "message {k}, segment {s}");
        }
        assert_eq!(a.targets(), b.targets(), "message {k}");
        time = sent.time_us;
        armed |= a.armed();
    }
    assert!(armed, "the session arms the board");
    // The link goes quiet: both ease to rest by the same steps.
    let period = a.frame_period_us().max(1);
    for step in 0..10_000 {
        if a.resting() && b.resting() {
            return;
        }
        time = time.wrapping_add(period);
        a.tick(time);
        b.tick(time);
        assert_eq!(a.targets(), b.targets(), "easing step {step}");
    }
    panic!("never came to rest");
}
