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

#[test]
fn an_edited_take_replays_bit_for_bit_and_its_smoothing_is_the_filters() {
    use marionette_host::take::edit::Input;
    use marionette_host::take::filter::smooth;
    let take = emulated_take(400);
    let mut input = Input::of(&take);
    let raw = input.clone();
    input.trim(0.05, 0.3).unwrap();
    input.smooth_sensor(0, 5.0).unwrap();
    let edited = input.take(&take.region).unwrap();
    assert_eq!(edited.source, "edit");
    // 0.05 ..= 0.3 s of a 1 kHz recording: 251 frames.
    assert_eq!(edited.info().sent.tracker_frames, 251);
    // Sensor 0's x is the filter's output on the trimmed raw x.
    let kept: Vec<_> = raw.frames[50..=300].to_vec();
    let xs: Vec<(f64, f64)> = kept
        .iter()
        .map(|f| {
            let s = f.sensors.iter().find(|s| s.id == 0).unwrap();
            (
                f64::from(f.time_us - 50_000) / 1e6,
                f64::from(s.position[0]),
            )
        })
        .collect();
    let expected = smooth(5.0, &xs);
    let back = Input::of(&edited);
    for (k, (f, e)) in back.frames.iter().zip(&expected).enumerate() {
        let x = f64::from(f.sensors.iter().find(|s| s.id == 0).unwrap().position[0]);
        // The compact frame quantizes positions to 1/8192 m.
        assert!((x - e).abs() < 2e-4, "frame {k}: {x} vs {e}");
    }
    let summary = replay::emulated(&edited, Pacing::AsFastAsPossible, 1.0).unwrap();
    assert_eq!(summary.mismatches, Some(0), "{summary:?}");
}

#[test]
fn the_bvh_export_parses_back_to_the_solved_figure() {
    use marionette_host::import::bvh;
    use marionette_host::take::export;
    let take = emulated_take(120);
    let text = export::bvh(&take).unwrap();
    let mut file = tempfile::NamedTempFile::new().unwrap();
    std::io::Write::write_all(&mut file, text.as_bytes()).unwrap();
    let motion = bvh::read_motion(file.path(), 0.01).unwrap();
    let rig = humanoid16();
    let names = rig.segment_names();
    let joints: Vec<_> = motion.joints.iter().filter(|j| !j.end_site).collect();
    assert_eq!(joints.len(), names.len());
    assert_eq!(motion.frames.len(), take.frame_outputs());
    assert_eq!(motion.frames.len(), 120);
    assert!((motion.frame_time - 0.001).abs() < 1e-9);
    // Forward kinematics of the file (written here, as the importer's doc
    // states it) against the core's solved pose.
    let poses = export::solved_poses(&take).unwrap();
    for k in [0, 60, 119] {
        let frame = &motion.frames[k];
        let mut pos = vec![glam::DVec3::ZERO; motion.joints.len()];
        let mut rot = vec![glam::DQuat::IDENTITY; motion.joints.len()];
        for (j, joint) in motion.joints.iter().enumerate() {
            (pos[j], rot[j]) = match joint.parent {
                None => (frame.root_position, frame.rotations[j]),
                Some(p) => (pos[p] + rot[p] * joint.offset, rot[p] * frame.rotations[j]),
            };
        }
        for (seg, name) in names.iter().enumerate() {
            let j = motion.joint_index(name).unwrap();
            let core = poses[k].0[seg].as_dvec3();
            assert!(
                (pos[j] - core).length() < 1e-4,
                "frame {k} {name}: {:?} vs {core:?}",
                pos[j]
            );
        }
    }
}

#[test]
fn a_flashed_show_plays_at_boot_with_no_host_within_its_bound() {
    use marionette_host::qemu::{self, Config, Emulator};
    use marionette_host::show;
    let take = emulated_take(600);
    let bound = 4; // quarter-µs: 1 µs
    let (blob, report) = show::build(std::slice::from_ref(&take), bound, false, true).unwrap();
    assert!(report.worst_quarter_us <= u32::from(bound));
    assert!(report.show_bytes < report.raw_bytes / 4, "{report:?}");
    let (curves, _) = show::frames(std::slice::from_ref(&take)).unwrap();
    let region = show::with_show(&take.region, &blob).unwrap();
    let mut file = tempfile::NamedTempFile::new().unwrap();
    std::io::Write::write_all(&mut file, &region).unwrap();
    let config = Config {
        tables: Some(file.path().to_path_buf()),
        ..Config::new(qemu::firmware_elf("perform").unwrap())
    };
    // No tracker input at all: the board plays the show from boot.
    let mut board = Emulator::start(&config).unwrap();
    let frames = curves.len();
    board.wait_servo_bytes(frames * 16 * 4).unwrap();
    let bytes = board.take_servo();
    drop(board);
    let sent = perform::decode_maestro(&bytes, 16);
    assert!(sent.len() >= frames, "{} of {frames} frames", sent.len());
    let mut worst = 0;
    for (k, (got, want)) in sent.iter().zip(&curves).enumerate() {
        for ch in 0..16 {
            let d = got[ch].abs_diff(want[ch]);
            worst = worst.max(d);
            assert!(
                d <= bound,
                "frame {k} channel {ch}: {} vs {}",
                got[ch],
                want[ch]
            );
        }
    }
    eprintln!("show: {frames} frames, worst {worst} quarter-µs (bound {bound})");
}

#[test]
fn the_core_plays_a_show_once_or_looping_and_arm_stops_it() {
    use marionette_core::frame::{Cause, NoCycles, Performer, Region};
    use marionette_core::solve::SolverState;
    use marionette_core::wire::{Command, CommandKind, MAX_FRAME, Message, encode};
    use marionette_host::show;
    let take = emulated_take(80);
    let (curves, _) = show::frames(std::slice::from_ref(&take)).unwrap();
    let n = curves.len() as u32;
    for looping in [false, true] {
        let (blob, _) = show::build(std::slice::from_ref(&take), 0, looping, true).unwrap();
        let bytes = show::with_show(&take.region, &blob).unwrap();
        let region = Region::parse(&bytes);
        assert!(region.show.is_some(), "{:?}", region.show_error);
        let mut solver = SolverState::new();
        let mut p = Performer::new(&region, &mut solver);
        assert_eq!(p.playing(), Some(0), "plays at boot");
        // Bound 0: every frame is the take's target exactly.
        for k in 0..n {
            let u = p.tick(1000 * (k + 1));
            assert_eq!(u.outputs, Some(Cause::Show(k)));
            assert_eq!(p.targets(), &curves[k as usize][..], "frame {k}");
        }
        if looping {
            assert_eq!(p.playing(), Some(0));
            assert_eq!(p.tick(1000 * (n + 1)).outputs, Some(Cause::Show(0)));
            // The host arms: the show stops.
            let mut buf = [0u8; MAX_FRAME];
            let arm = Message::Command(Command {
                seq: 0,
                kind: CommandKind::Arm,
            });
            let mut input: &[u8] = encode(&arm, &mut buf).unwrap();
            while !input.is_empty() {
                p.receive(&mut input, 1000 * (n + 2), &mut NoCycles);
            }
            assert_eq!(p.playing(), None);
            assert!(p.armed());
        } else {
            assert_eq!(p.playing(), None, "played once");
            assert_ne!(p.tick(1000 * (n + 1)).outputs, Some(Cause::Show(0)));
        }
    }
    // A show built for another rig is refused by the region.
    let (blob, _) = show::build(std::slice::from_ref(&take), 0, false, true).unwrap();
    let mut other = blob.clone();
    other[8] ^= 1; // the rig hash
    let crc = marionette_core::crc::crc32(&other[..other.len() - 4]);
    let len = other.len();
    other[len - 4..].copy_from_slice(&crc.to_le_bytes());
    let bytes = show::with_show(&take.region, &other).unwrap();
    let region = Region::parse(&bytes);
    assert!(region.show.is_none());
    assert_eq!(
        region.show_error,
        Some(marionette_core::show::ShowError::RigMismatch)
    );
}

#[test]
fn a_show_waits_for_its_command_on_the_link() {
    use marionette_core::wire::{Command, CommandKind, Hello, Message, PROTOCOL_VERSION};
    use marionette_host::qemu::{self, Config, Emulator};
    use marionette_host::show;
    let take = emulated_take(300);
    let bound = 4;
    let (blob, _) = show::build(std::slice::from_ref(&take), bound, false, false).unwrap();
    let (curves, _) = show::frames(std::slice::from_ref(&take)).unwrap();
    let region = show::with_show(&take.region, &blob).unwrap();
    let mut file = tempfile::NamedTempFile::new().unwrap();
    std::io::Write::write_all(&mut file, &region).unwrap();
    let config = Config {
        tables: Some(file.path().to_path_buf()),
        ..Config::new(qemu::firmware_elf("perform").unwrap())
    };
    let mut board = Emulator::start(&config).unwrap();
    let hello = Message::Hello(Hello {
        protocol_version: PROTOCOL_VERSION,
    });
    board.send(&perform::encode(&hello).unwrap()).unwrap();
    board
        .wait_replies(|b| !perform::decode_replies(b).is_empty())
        .unwrap();
    // Nothing moves before the command.
    assert!(board.take_servo().is_empty());
    let play = Message::Command(Command {
        seq: 1,
        kind: CommandKind::Show { play: true },
    });
    board.send(&perform::encode(&play).unwrap()).unwrap();
    board.wait_servo_bytes(curves.len() * 16 * 4).unwrap();
    let bytes = board.take_servo();
    let replies = perform::decode_replies(&board.replies_so_far());
    drop(board);
    assert!(
        replies
            .iter()
            .any(|m| matches!(m, Message::Ack(a) if a.seq == 1 && a.ok)),
        "{replies:?}"
    );
    let sent = perform::decode_maestro(&bytes, 16);
    assert!(sent.len() >= curves.len());
    for (k, (got, want)) in sent.iter().zip(&curves).enumerate() {
        for ch in 0..16 {
            assert!(
                got[ch].abs_diff(want[ch]) <= bound,
                "frame {k} channel {ch}"
            );
        }
    }
}

/// `stream --take` to the emulated board on a pseudo-terminal, as to a
/// board on a serial port: the take holds what the host wrote, the
/// replies, and the servo targets the board's telemetry reported (kind 5,
/// format version 2). Those must be the servo bytes the board put on its
/// servo UART for the frames they report; `take info`, `take export`,
/// `show build` and `replay --emulated` (comparing the telemetry) work on
/// it.
#[test]
fn a_take_from_a_serial_port_holds_the_telemetrys_targets_and_replays() {
    use marionette_host::cmd::stream::{self, Args};
    use marionette_host::perform::Framing;
    use marionette_host::qemu::PtyBoard;
    use marionette_host::take::export;
    use marionette_tests::puppet::repo;
    let dir = tempfile::tempdir().unwrap();
    // The shipped rig with a 60 s fail-safe (a loaded machine must not
    // trip it), as a rig file: the take's region is made from it.
    let text = std::fs::read_to_string(repo().join("rigs/humanoid16.toml")).unwrap();
    let patient = text.replacen(
        "failsafe_timeout_ms = 100 ",
        "failsafe_timeout_ms = 60000 ",
        1,
    );
    assert_ne!(patient, text);
    let rig_path = dir.path().join("rig.toml");
    std::fs::write(&rig_path, patient).unwrap();
    let rig = marionette_host::rigfile::load(&rig_path).unwrap();
    let table = rest_table(&rig);
    let tables = dir.path().join("rest.bin");
    std::fs::write(&tables, &table).unwrap();
    let region = perform::region(&rig_blob(&rig, None), Some(&table));
    let region_file = dir.path().join("region.bin");
    std::fs::write(&region_file, &region).unwrap();
    let rec = dir.path().join("rec.csv");
    let mut csv = Vec::new();
    marionette_host::cmd::record::write_csv_exact(&mut csv, &recording(300)).unwrap();
    std::fs::write(&rec, csv).unwrap();
    let servo_file = dir.path().join("uart1.bin");
    let elf = marionette_host::qemu::firmware_elf("perform").unwrap();
    let mut board = PtyBoard::start(&elf, &region_file, &servo_file).unwrap();
    let take_path = dir.path().join("port.take");
    let args = Args {
        port: board.pty().display().to_string(),
        baud: 200_000,
        recording: rec,
        rig: rig_path,
        fast: false,
        frame: Framing::Compact,
        out: dir.path().join("out"),
        json: false,
        take: Some(take_path.clone()),
        tables: vec![tables],
        view: Default::default(),
    };
    let (summary, _) = stream::stream(&args, &std::sync::atomic::AtomicBool::new(false))
        .expect("stream completes");
    assert_eq!(board.wait(Duration::from_secs(30)).unwrap(), Some(0));
    let take = Take::load(&take_path).unwrap();
    assert_eq!(take.region, region, "the rig file's rig and the tables");
    assert_eq!(take.source, "stream");
    let info = take.info();
    assert_eq!(info.format_version, 2);
    assert!(!info.servo_link_seen);
    assert_eq!((info.frame_outputs, info.rest_outputs), (0, 0));
    assert_eq!(info.sent.tracker_frames as u64, summary.sender.sent);
    assert_eq!((info.sent.hellos, info.sent.commands), (1, 2), "{info:?}");
    assert_eq!(info.reported_outputs, summary.telemetry);
    assert!(info.reported_outputs >= 2, "{info:?}");
    // Each reported set of targets is what the board put on its servo UART
    // for the frame it reports (seq k is the k-th frame sent: Arm is 0).
    let servo = perform::decode_maestro(&std::fs::read(&servo_file).unwrap(), 16);
    let telemetry: Vec<u32> = take
        .replies()
        .iter()
        .filter_map(|m| match m {
            marionette_core::wire::Message::Telemetry(t) => Some(t.seq),
            _ => None,
        })
        .collect();
    let curves = take.curves();
    assert_eq!(curves.len(), telemetry.len());
    for ((_, targets), seq) in curves.iter().zip(&telemetry) {
        assert_eq!(targets, &servo[*seq as usize - 1], "frame seq {seq}");
    }
    // Export, show build, replay.
    let csv = export::curves_csv(&take);
    assert_eq!(csv.lines().count(), 1 + info.reported_outputs);
    let (_, report) =
        marionette_host::show::build(std::slice::from_ref(&take), 4, false, true).unwrap();
    assert!(
        report.frames > 0 && report.worst_quarter_us <= 4,
        "{report:?}"
    );
    let replayed = replay::emulated(&take, Pacing::AsFastAsPossible, 1.0).unwrap();
    assert_eq!(replayed.compares, "telemetry", "{replayed:?}");
    assert_eq!(replayed.mismatches, None);
    assert_eq!(
        (replayed.telemetry_compared, replayed.telemetry_mismatches),
        (info.reported_outputs, 0),
        "{replayed:?}"
    );
}

/// A show the board refuses (a flipped bit, built for another rig, cut
/// short) plays nothing, even flashed to play at boot: the servos stay at
/// rest (no servo byte), the board's `Status` (protocol version 5) names
/// the reason and counts the refusals (1 at boot, +1 for a `Show` command
/// it refuses), and `show play` on the host says why.
#[test]
fn a_damaged_show_is_refused_with_a_counted_reason_and_nothing_moves() {
    use marionette_core::frame::{Performer, Region};
    use marionette_core::solve::SolverState;
    use marionette_core::wire::{Command, CommandKind, Hello, Message, ShowState};
    use marionette_host::qemu::{self, Config, Emulator, PtyBoard};
    use marionette_host::show;
    let take = emulated_take(120);
    let (blob, _) = show::build(std::slice::from_ref(&take), 4, true, true).unwrap();
    let recrc = |mut b: Vec<u8>| {
        let n = b.len() - 4;
        let crc = marionette_core::crc::crc32(&b[..n]);
        b[n..].copy_from_slice(&crc.to_le_bytes());
        b
    };
    let mut flipped = blob.clone();
    flipped[blob.len() / 2] ^= 0x08;
    let mut other_rig = blob.clone();
    other_rig[8] ^= 1; // the rig hash
    // Cut short: within its header, or after it (its CRC then fails).
    let cases = [
        (flipped, ShowState::BadCrc),
        (recrc(other_rig), ShowState::RigMismatch),
        (blob[..20].to_vec(), ShowState::Truncated),
        (blob[..blob.len() - 10].to_vec(), ShowState::BadCrc),
    ];
    let status = |replies: &[u8]| {
        perform::decode_replies(replies)
            .into_iter()
            .rev()
            .find_map(|m| match m {
                Message::Status(s) => Some(s),
                _ => None,
            })
    };
    let encode = |m: Message| perform::encode(&m).unwrap();
    for (k, (bad, reason)) in cases.iter().enumerate() {
        let bytes = show::with_show(&take.region, bad).unwrap();
        // The core: refused, never played, reported.
        let region = Region::parse(&bytes);
        let mut solver = SolverState::new();
        let p = Performer::new(&region, &mut solver);
        assert_eq!(p.playing(), None, "{reason:?}");
        assert_eq!(
            (p.status(None).show, p.status(None).show_refusals),
            (*reason, 1)
        );
        // The emulated board.
        let mut file = tempfile::NamedTempFile::new().unwrap();
        std::io::Write::write_all(&mut file, &bytes).unwrap();
        let config = Config {
            tables: Some(file.path().to_path_buf()),
            ..Config::new(qemu::firmware_elf("perform").unwrap())
        };
        let mut board = Emulator::start(&config).unwrap();
        board
            .send(&encode(Message::Hello(Hello {
                protocol_version: marionette_core::wire::PROTOCOL_VERSION,
            })))
            .unwrap();
        board.wait_replies(|b| status(b).is_some()).unwrap();
        let st = status(&board.replies_so_far()).unwrap();
        assert_eq!((st.show, st.show_refusals), (*reason, 1), "{st:?}");
        assert!(st.table_ok, "the rig and tables still perform");
        board
            .send(&encode(Message::Command(Command {
                seq: 1,
                kind: CommandKind::Show { play: true },
            })))
            .unwrap();
        board
            .send(&encode(Message::Command(Command {
                seq: 2,
                kind: CommandKind::RequestStatus,
            })))
            .unwrap();
        board
            .wait_replies(|b| status(b).is_some_and(|s| s.request_seq == Some(2)))
            .unwrap();
        let replies = perform::decode_replies(&board.replies_so_far());
        assert!(
            replies
                .iter()
                .any(|m| matches!(m, Message::Ack(a) if a.seq == 1 && !a.ok)),
            "{replies:?}"
        );
        let st = status(&board.replies_so_far()).unwrap();
        assert_eq!((st.show, st.show_refusals), (*reason, 2), "{st:?}");
        assert!(board.take_servo().is_empty(), "{reason:?}: a servo moved");
        drop(board);
        // The host says why (once is enough: the same code for each).
        if k == 0 {
            let servo = tempfile::NamedTempFile::new().unwrap();
            let elf = qemu::firmware_elf("perform").unwrap();
            let pty = PtyBoard::start(&elf, file.path(), servo.path()).unwrap();
            let args = marionette_host::cmd::show::Args {
                action: marionette_host::cmd::show::Action::Play(
                    marionette_host::cmd::show::PlayArgs {
                        port: pty.pty().display().to_string(),
                        baud: 200_000,
                        stop: false,
                    },
                ),
            };
            let err = marionette_host::cmd::show::run(&args)
                .unwrap_err()
                .to_string();
            assert!(
                err.contains("refused its flashed show (BadCrc")
                    && err.contains("counted 2 time(s)")
                    && err.contains("show build"),
                "{err}"
            );
        }
    }
}
