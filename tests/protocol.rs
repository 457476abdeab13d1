//! The wire spec's contracts that are not bytes: what each counter means,
//! how sequence numbers interact with rejections, when the board replies
//! and with what, and the board's state machine ([`Performer`]) run
//! natively on the shipped `humanoid16` rig. Each test is one sentence of
//! the spec in `marionette_core::wire` and `marionette_core::perform`; the
//! expected values are worked out here from the spec, not read back from
//! the code under test.

use marionette_core::crc::crc32;
use marionette_core::frame::{NoCycles, Region};
use marionette_core::perform::{Performer, TELEMETRY_EVERY};
use marionette_core::solve::SolverState;
use marionette_core::wire::{
    self, Command, CommandKind, ErrorCounters, FRAME_CAPACITY, FrameReader, Hello, Incoming, List,
    MAX_FRAME, Message, PROTOCOL_VERSION, Params, Receiver, STALE_WINDOW, Sensor, State,
    StatusReason, TrackerFrame, WireError, cobs,
};
use marionette_host::perform;
use marionette_tests::puppet::{humanoid16, rest_table, rig_blob};

fn encode(msg: &Message) -> Vec<u8> {
    let mut out = [0u8; MAX_FRAME];
    wire::encode(msg, &mut out).expect("encode").to_vec()
}

fn hello(version: u16) -> Vec<u8> {
    encode(&Message::Hello(Hello {
        protocol_version: version,
    }))
}

fn command(seq: u32, kind: CommandKind) -> Vec<u8> {
    encode(&Message::Command(Command { seq, kind }))
}

/// A 3-sensor frame where humanoid16's performer holds the trackers.
fn frame(seq: u32) -> Vec<u8> {
    let at = |id, position| Sensor {
        id,
        position,
        rotation: [1.0, 0.0, 0.0, 0.0],
    };
    encode(&Message::TrackerFrame(TrackerFrame {
        seq,
        time_us: seq * 1000,
        sensors: List::from_slice(&[
            at(0, [-0.3, 1.25, 0.3]),
            at(1, [0.3, 0.8, 0.1]),
            at(2, [0.0, 1.0, 0.0]),
        ])
        .unwrap(),
    }))
}

fn feed(rx: &mut Receiver, bytes: &[u8]) -> Vec<Incoming> {
    let mut out = Vec::new();
    let mut input = bytes;
    while let Some(m) = rx.push_slice(&mut input) {
        out.push(m);
    }
    out
}

/// The region of the tests: humanoid16 with a rest-pose grid.
fn region() -> Vec<u8> {
    let rig = humanoid16();
    perform::region(&rig_blob(&rig, None), Some(&rest_table(&rig)))
}

/// Feeds `bytes` to `p` at board time `now`; returns the replies.
fn send(p: &mut Performer<'_, '_>, bytes: &[u8], now: u32) -> Vec<Message> {
    let mut input = bytes;
    let mut replies = Vec::new();
    while !input.is_empty() {
        if let Some(r) = p.receive(&mut input, now, &mut NoCycles).reply {
            replies.push(r);
        }
    }
    replies
}

// -------------------------------------------------------------- the bug

/// After a `Hello` with another version the board reports
/// `ProtocolMismatch`, disarms and rejects everything; a matching `Hello`
/// clears it entirely: reason `Ok`, `table_ok`, and `Arm` is obeyed (it
/// stayed latched until a reboot before).
#[test]
fn a_matching_hello_recovers_from_a_protocol_mismatch() {
    let bytes = region();
    let region = Region::parse(&bytes);
    let mut solver = SolverState::new();
    let mut p = Performer::new(&region, &mut solver);
    assert_eq!(send(&mut p, &command(0, CommandKind::Arm), 0).len(), 1);
    assert!(p.armed());
    let reply = send(&mut p, &hello(99), 0);
    let [Message::Status(st)] = reply.as_slice() else {
        panic!("{reply:?}")
    };
    assert_eq!(
        (st.reason, st.armed, st.table_ok, st.state),
        (StatusReason::ProtocolMismatch, false, true, State::Disarmed)
    );
    // Rejected while mismatched: no Ack, counted as `version`.
    assert!(send(&mut p, &command(1, CommandKind::Arm), 0).is_empty());
    assert!(!p.armed());
    assert_eq!(p.errors().version, 2, "the Hello and the Arm");
    let reply = send(&mut p, &hello(PROTOCOL_VERSION), 0);
    let [Message::Status(st)] = reply.as_slice() else {
        panic!("{reply:?}")
    };
    assert_eq!(
        (st.reason, st.table_ok, st.state),
        (StatusReason::Ok, true, State::Disarmed)
    );
    let reply = send(&mut p, &command(0, CommandKind::Arm), 0);
    assert!(
        matches!(reply.as_slice(), [Message::Ack(a)] if a.ok && a.seq == 0),
        "{reply:?}"
    );
    assert!(p.armed());
    assert_eq!(p.state(), State::Armed);
}

/// A version-1 host's `Hello` is accepted: version 2 only appended fields
/// and a message, so every version-1 host message is valid version 2; and
/// version 3 only appended a command kind, so version-2 hosts are accepted
/// too; version 4 likewise (the `Show` command), so version-3 hosts are;
/// version 5 only appended fields to the board's `Status`, so version-4
/// hosts are.
#[test]
fn a_version_1_hello_is_accepted() {
    let mut rx: Receiver = Receiver::new();
    for v in [1, 2, 3, 4, 5] {
        let got = feed(&mut rx, &hello(v));
        assert!(
            matches!(got[..], [Incoming::Hello { host_version, accepted: true }] if host_version == v),
            "{v}: {got:?}"
        );
    }
    assert!(matches!(
        feed(&mut rx, &hello(6))[..],
        [Incoming::Hello {
            accepted: false,
            ..
        }]
    ));
    assert!(matches!(
        feed(&mut rx, &hello(0))[..],
        [Incoming::Hello {
            accepted: false,
            ..
        }]
    ));
}

// ------------------------------------------------------------- counters

/// "Oversize" is about the decoded frame (payload + CRC): more than
/// `FRAME_CAPACITY` = 480 bytes is oversize however it was encoded; 480 is
/// not (it fails the CRC here instead).
#[test]
fn oversize_means_more_than_480_decoded_bytes() {
    for (decoded, oversize, crc) in [(480usize, 0, 1), (481, 1, 0)] {
        let body: Vec<u8> = (0..decoded).map(|i| (i % 250 + 1) as u8).collect();
        let mut coded = vec![0u8; cobs::max_encoded_len(decoded)];
        let n = cobs::encode(&body, &mut coded).unwrap();
        coded.truncate(n);
        coded.push(0);
        // 480 and 481 non-zero bytes: two COBS blocks, 482 and 483 bytes
        // with the delimiter.
        assert_eq!(coded.len(), decoded + 3);
        let mut rx: Receiver = Receiver::new();
        assert!(feed(&mut rx, &coded).is_empty());
        assert_eq!(
            (rx.errors().oversize, rx.errors().crc, rx.errors().total()),
            (oversize, crc, 1),
            "{decoded} decoded bytes"
        );
    }
    assert_eq!(FRAME_CAPACITY, 480);
}

/// A frame cut short lands in `cobs` if the cut falls inside a COBS block
/// and in `crc` if it falls on a block boundary (the bytes before it are a
/// well-formed packet whose CRC fails). Without its delimiter, a cut frame
/// runs into the next one: both are lost as one rejection, and the sequence
/// gap counts both in `lost`.
#[test]
fn a_truncated_frame_counts_as_cobs_or_crc_and_can_take_the_next_one_with_it() {
    let f1 = frame(1);
    // f1's COBS blocks: the code bytes say where each block ends.
    let mut boundaries = Vec::new();
    let mut i = 0;
    while i < f1.len() - 1 {
        boundaries.push(i);
        i += usize::from(f1[i]);
    }
    let cut_inside = boundaries[2] + 2;
    let cut_at_boundary = boundaries[3];
    assert!(!boundaries.contains(&cut_inside));
    for (cut, cobs_errors, crc_errors) in [(cut_inside, 1, 0), (cut_at_boundary, 0, 1)] {
        let mut rx: Receiver = Receiver::new();
        let mut stream = f1[..cut].to_vec();
        stream.push(0);
        stream.extend(frame(2));
        let got = feed(&mut rx, &stream);
        assert_eq!(got, [Incoming::Tracker]);
        assert_eq!(rx.frame().seq(), 2);
        let e = rx.errors();
        assert_eq!((e.cobs, e.crc, e.lost), (cobs_errors, crc_errors, 0));
    }
    // No delimiter after the cut: f1's head and f2 make one bad frame.
    let mut rx: Receiver = Receiver::new();
    let mut stream = frame(1)[..cut_inside].to_vec();
    stream.extend(frame(2));
    stream.extend(frame(3));
    let got = feed(&mut rx, &stream);
    assert_eq!(got, [Incoming::Tracker]);
    assert_eq!(rx.frame().seq(), 3);
    let e = rx.errors();
    assert_eq!(e.cobs + e.crc, 1, "one rejection for two frames: {e:?}");
    assert_eq!(e.lost, 0, "nothing accepted before frame 3: no gap yet");
    // The same after an accepted frame 0: the gap 0 → 3 counts 2 lost.
    let mut rx: Receiver = Receiver::new();
    let mut stream = frame(0);
    stream.extend(&frame(1)[..cut_inside]);
    stream.extend(frame(2));
    stream.extend(frame(3));
    assert_eq!(feed(&mut rx, &stream).len(), 2);
    assert_eq!(rx.errors().lost, 2);
}

/// Rejections and sequence numbers: a message rejected before its sequence
/// number is read (`cobs`, `crc`, `decode`, `oversize`) does not advance
/// the sequence, so it shows up in `lost` at the next accepted one; one
/// rejected by validation (`range`) does advance it (not lost later); a
/// `stale` one neither advances it nor counts as lost.
#[test]
fn rejections_and_sequence_numbers() {
    let mut rx: Receiver = Receiver::new();
    let mut stream = frame(1);
    // seq 2: CRC damaged.
    let mut bad = frame(2);
    bad[5] ^= 0x40;
    stream.extend(bad);
    // seq 3: a range rejection (a NaN position).
    stream.extend(encode(&Message::TrackerFrame(TrackerFrame {
        seq: 3,
        time_us: 3000,
        sensors: List::from_slice(&[Sensor {
            id: 0,
            position: [f32::NAN, 0.0, 0.0],
            rotation: [1.0, 0.0, 0.0, 0.0],
        }])
        .unwrap(),
    })));
    // seq 3 again: stale (duplicate of an advanced number).
    stream.extend(frame(3));
    stream.extend(frame(4));
    let mut seqs = Vec::new();
    let mut input = stream.as_slice();
    while let Some(m) = rx.push_slice(&mut input) {
        assert_eq!(m, Incoming::Tracker);
        seqs.push(rx.frame().seq());
    }
    assert_eq!(seqs, [1, 4]);
    let e = *rx.errors();
    assert_eq!(
        (e.crc + e.cobs, e.range, e.stale, e.lost),
        (1, 1, 1, 1),
        "{e:?}"
    );
}

/// `STALE_WINDOW` is 256: a number up to 256 behind the last accepted one
/// is stale; further back is taken as the sender restarting its counter
/// (accepted, nothing lost, tracking restarts from it).
#[test]
fn stale_window_is_256_and_further_back_is_a_restart() {
    assert_eq!(STALE_WINDOW, 256);
    let mut rx: Receiver = Receiver::new();
    let got = feed(&mut rx, &frame(1000));
    assert_eq!(got.len(), 1);
    assert!(feed(&mut rx, &frame(1000 - 256)).is_empty());
    assert_eq!(rx.errors().stale, 1);
    let got = feed(&mut rx, &frame(1000 - 257));
    assert_eq!(got, [Incoming::Tracker]);
    assert_eq!(rx.frame().seq(), 743);
    let got = feed(&mut rx, &frame(745));
    assert_eq!(got.len(), 1);
    assert_eq!((rx.errors().stale, rx.errors().lost), (1, 1));
}

/// `frames_ok` counts every accepted message of every kind, and the
/// `Status` answering a `RequestStatus` already counts that request.
#[test]
fn frames_ok_counts_every_accepted_message() {
    let bytes = region();
    let region = Region::parse(&bytes);
    let mut solver = SolverState::new();
    let mut p = Performer::new(&region, &mut solver);
    let mut stream = hello(PROTOCOL_VERSION);
    stream.extend(command(0, CommandKind::Arm));
    for seq in 1..=5 {
        stream.extend(frame(seq));
    }
    stream.extend(encode(&Message::Params(Params {
        seq: 6,
        values: List::from_slice(&[0.1]).unwrap(),
    })));
    let mut damaged = frame(7);
    damaged[3] ^= 1;
    stream.extend(damaged);
    stream.extend(command(8, CommandKind::RequestStatus));
    let replies = send(&mut p, &stream, 0);
    let Some(Message::Status(st)) = replies.last() else {
        panic!("{replies:?}")
    };
    // Hello, Arm, 5 frames, Params, RequestStatus.
    assert_eq!(st.frames_ok, 9);
    assert_eq!(st.errors.lost, 1, "the damaged frame 7");
}

/// `RequestStatus` is answered by a `Status` (no `Ack`) whose
/// `request_seq` is the command's sequence number; a `Hello`'s has none.
#[test]
fn request_status_gets_a_status_with_its_seq_and_no_ack() {
    let bytes = region();
    let region = Region::parse(&bytes);
    let mut solver = SolverState::new();
    let mut p = Performer::new(&region, &mut solver);
    let replies = send(&mut p, &hello(PROTOCOL_VERSION), 0);
    assert!(matches!(replies[..], [Message::Status(st)] if st.request_seq.is_none()));
    let replies = send(&mut p, &command(41, CommandKind::RequestStatus), 0);
    assert!(
        matches!(replies[..], [Message::Status(st)] if st.request_seq == Some(41)),
        "{replies:?}"
    );
    let replies = send(&mut p, &command(42, CommandKind::Disarm), 0);
    assert!(matches!(replies[..], [Message::Ack(a)] if a.seq == 42 && a.ok));
}

/// `Telemetry` goes out after every 10th performed frame (frames taken
/// while disarmed do not count), and its `seq` is that frame's.
#[test]
fn telemetry_after_every_10th_performed_frame_with_its_seq() {
    assert_eq!(TELEMETRY_EVERY, 10);
    let bytes = region();
    let region = Region::parse(&bytes);
    let mut solver = SolverState::new();
    let mut p = Performer::new(&region, &mut solver);
    let mut seqs = Vec::new();
    // 5 frames disarmed, then Arm and 25 frames.
    let mut seq = 0;
    for _ in 0..5 {
        seq += 1;
        assert!(send(&mut p, &frame(seq), seq * 1000).is_empty());
    }
    seq += 1;
    send(&mut p, &command(seq, CommandKind::Arm), seq * 1000);
    for _ in 0..25 {
        seq += 1;
        for r in send(&mut p, &frame(seq), seq * 1000) {
            let Message::Telemetry(t) = r else {
                panic!("{r:?}")
            };
            assert_eq!(t.state, State::Armed);
            seqs.push(t.seq);
        }
    }
    // Performed frames are seq 7..=31: the 10th is 16, the 20th 26.
    assert_eq!(seqs, [16, 26]);
}

/// The encoder writes no empty block after a frame whose COBS ends in a
/// full (0xFF) block; a receiver accepts the frame with or without it.
#[test]
fn a_frame_ending_in_a_full_cobs_block_has_no_trailing_byte() {
    // A 9-sensor frame whose last zero byte is 255 bytes from the end of
    // payload + CRC: its COBS ends in one full block. Floats without zero
    // bytes except one placed at that index; the seq is searched for a CRC
    // without a zero byte.
    let nz = f32::from_bits(0x3E99_999A); // 0.3: no zero byte
    let with_zero = f32::from_bits(0x3F80_0001); // 01 00 80 3F
    let msg = |seq: u32| {
        let sensors: Vec<Sensor> = (1..=9)
            .map(|id| Sensor {
                id,
                position: [nz, nz, if id == 1 { with_zero } else { nz }],
                rotation: [nz; 4],
            })
            .collect();
        Message::TrackerFrame(TrackerFrame {
            seq,
            time_us: 0,
            sensors: List::from_slice(&sensors).unwrap(),
        })
    };
    let mut found = None;
    for seq in 1..127u32 {
        let mut payload = [0u8; wire::MAX_PAYLOAD];
        let p = wire::encode_payload(&msg(seq), &mut payload)
            .unwrap()
            .to_vec();
        let mut body = p.clone();
        body.extend(crc32(&p).to_le_bytes());
        let last_zero = body.iter().rposition(|&b| b == 0).unwrap();
        if body.len() - last_zero - 1 == 254 {
            found = Some((seq, body));
            break;
        }
    }
    let (seq, body) = found.expect("a seq whose CRC has no zero byte");
    // tag, seq, time 0 (the zero at index 2), 9 sensors: 1 + 1 + 1 + 1 + 261,
    // + 4 CRC = 269 bytes, the last zero at index 14.
    assert_eq!(body.len(), 269);
    let frame = encode(&msg(seq));
    // COBS: 03 01 01 (up to index 2's zero), 0C + 11 bytes (up to index
    // 14's zero), FF + 254 bytes, then the delimiter: no 01 before it.
    assert_eq!(frame.len(), 3 + 12 + 255 + 1);
    assert_eq!(&frame[..3], &[0x03, 0x01, 0x01]);
    assert_eq!((frame[3], frame[15]), (0x0C, 0xFF));
    assert_eq!(frame[frame.len() - 2], body[268]);
    let mut with_empty_block = frame[..frame.len() - 1].to_vec();
    with_empty_block.extend([0x01, 0x00]);
    for bytes in [frame, with_empty_block] {
        let mut reader = FrameReader::<FRAME_CAPACITY>::new();
        let mut errors = ErrorCounters::new();
        let mut input = bytes.as_slice();
        let got = reader
            .push_slice(&mut input, &mut errors)
            .map(<[u8]>::to_vec);
        assert_eq!(got.as_deref(), Some(body.as_slice()));
        assert_eq!(wire::decode_frame(&body), Ok(msg(seq)));
        assert_eq!(errors.total(), 0);
    }
}

/// Without a rig the board still speaks the protocol: `Hello` and
/// `RequestStatus` get its reason, `Arm` is refused, frames drive nothing.
#[test]
fn without_a_rig_the_board_answers_and_refuses() {
    let region = Region::parse(&[0xFF; 64]);
    assert_eq!(region.reason, StatusReason::NoRig);
    let mut solver = SolverState::new();
    let mut p = Performer::new(&region, &mut solver);
    let mut stream = hello(PROTOCOL_VERSION);
    stream.extend(command(0, CommandKind::Arm));
    stream.extend(frame(1));
    stream.extend(command(2, CommandKind::RequestStatus));
    let replies = send(&mut p, &stream, 0);
    assert_eq!(replies.len(), 3, "{replies:?}");
    for r in [&replies[0], &replies[2]] {
        let Message::Status(st) = r else {
            panic!("{r:?}")
        };
        assert_eq!(
            (st.reason, st.armed, st.table_ok, st.state),
            (StatusReason::NoRig, false, false, State::Unready)
        );
    }
    assert!(matches!(replies[1], Message::Ack(a) if !a.ok));
    assert!(p.targets().is_empty() && !p.armed());
    assert!(p.tick(10_000_000).outputs.is_none());
}

/// Bytes never crash the receiver, whatever their framing: the `decode`
/// counter takes an unknown tag and a board-to-host message alike.
#[test]
fn board_messages_and_unknown_tags_count_as_decode() {
    let mut rx: Receiver = Receiver::new();
    let payload = [0x09u8];
    let mut body = payload.to_vec();
    body.extend(crc32(&payload).to_le_bytes());
    let mut coded = vec![0u8; cobs::max_encoded_len(body.len())];
    let n = cobs::encode(&body, &mut coded).unwrap();
    coded.truncate(n);
    coded.push(0);
    assert!(feed(&mut rx, &coded).is_empty());
    assert_eq!(rx.errors().decode, 1);
    assert_eq!(wire::decode_payload(&[0x09]), Err(WireError::Decode));
}

// ------------------------------------------------------- calibration jog

/// Ticks `p` once per frame period (1 ms) `n` times from `*now`; returns
/// channel `ch`'s target after each tick.
fn jog_ticks(p: &mut Performer<'_, '_>, now: &mut u32, ch: usize, n: usize) -> Vec<u16> {
    (0..n)
        .map(|_| {
            *now += 1000;
            p.tick(*now);
            p.targets()[ch]
        })
        .collect()
}

/// Checks humanoid16 channel 1's hard limits on a path from `start`: the
/// rig file's `pulse_us = [1000, 2000]` is 4000..=8000 quarter-µs, and its
/// `max_speed = 7.0` rad/s over `angle_deg = [-45, 45]` at the 1 ms frame is
/// 7 · 0.001 · 4000 / (π/2) = 17.8 → 17 quarter-µs per step; `max_accel =
/// 60` gives 0.15 → 1 quarter-µs per step per step (never below 1).
fn assert_within_channel_1_limits(start: u16, path: &[u16]) {
    let mut last = (i32::from(start), 0i32);
    for (i, &t) in path.iter().enumerate() {
        assert!(
            (4000..=8000).contains(&t),
            "step {i}: {t} outside the range"
        );
        let step = i32::from(t) - last.0;
        assert!(step.abs() <= 17, "step {i}: {step} faster than the servo");
        assert!(
            (step - last.1).abs() <= 1,
            "step {i}: {step} after {}",
            last.1
        );
        last = (i32::from(t), step);
    }
}

/// `Jog` (wire spec, Calibration): taken while disarmed; the channel moves
/// within its calibrated range and slew limits (a target past the range
/// stops at its end), every other servo stays at rest; `Arm` and a second
/// channel's jog are refused until target 0 has brought it back to rest.
#[test]
fn a_jog_keeps_the_calibrated_range_and_the_slew_limits() {
    let bytes = region();
    let region = Region::parse(&bytes);
    let mut solver = SolverState::new();
    let mut p = Performer::new(&region, &mut solver);
    let rest = p.targets().to_vec();
    // head tilt: rest angle 0 = 1500 µs.
    assert_eq!(rest[1], 6000);
    let ack = |r: &[Message]| match r {
        [Message::Ack(a)] => a.ok,
        _ => panic!("{r:?}"),
    };
    send(&mut p, &hello(PROTOCOL_VERSION), 0);
    // 0x3FFF µs/4 = 4095.75 µs: far past the rig's 2000 µs.
    let jog = |seq, channel, target| command(seq, CommandKind::Jog { channel, target });
    assert!(ack(&send(&mut p, &jog(1, 1, 0x3FFF), 0)));
    assert!(!ack(&send(&mut p, &jog(2, 2, 6000), 0)), "a second channel");
    assert!(!ack(&send(&mut p, &jog(3, 20, 6000), 0)), "no servo on 20");
    assert!(!ack(&send(&mut p, &command(4, CommandKind::Arm), 0)));
    let mut now = 0;
    let out = jog_ticks(&mut p, &mut now, 1, 400);
    assert_within_channel_1_limits(6000, &out);
    assert_eq!(out[399], 8000, "stops at the end of the range");
    for (ch, (&t, &r)) in p.targets().iter().zip(&rest).enumerate() {
        assert!(ch == 1 || t == r, "channel {ch} moved");
    }
    // Moved back down below the range, then ended: back to 1500 µs.
    assert!(ack(&send(&mut p, &jog(5, 1, 100), now)));
    let down = jog_ticks(&mut p, &mut now, 1, 400);
    assert_within_channel_1_limits(8000, &down);
    assert_eq!(down[399], 4000);
    assert!(ack(&send(&mut p, &jog(6, 1, 0), now)));
    assert!(!ack(&send(&mut p, &command(7, CommandKind::Arm), now)));
    let back = jog_ticks(&mut p, &mut now, 1, 400);
    assert_within_channel_1_limits(4000, &back);
    assert_eq!(back[399], 6000);
    assert!(p.resting());
    assert!(ack(&send(&mut p, &command(8, CommandKind::Arm), now)));
    assert!(!ack(&send(&mut p, &jog(9, 1, 7000), now)), "armed");
}

/// A jog ends after a second in which the board accepted no message
/// (`perform::JOG_TIMEOUT_US`: a host that vanished must not leave the
/// servo held), not before; any message within the second, here the same
/// `Jog` again, keeps it.
#[test]
fn a_jog_ends_after_a_second_without_a_message_from_the_host() {
    let bytes = region();
    let region = Region::parse(&bytes);
    let mut solver = SolverState::new();
    let mut p = Performer::new(&region, &mut solver);
    let jog = |seq| {
        command(
            seq,
            CommandKind::Jog {
                channel: 1,
                target: 7000,
            },
        )
    };
    let acked = |r: Vec<Message>| matches!(r.as_slice(), [Message::Ack(a)] if a.ok);
    assert!(acked(send(&mut p, &jog(1), 0)));
    let mut now = 0;
    // 999 ms of silence: still held at 7000.
    let held = jog_ticks(&mut p, &mut now, 1, 999);
    assert_eq!(held[998], 7000);
    assert!(acked(send(&mut p, &jog(2), now)));
    let kept = jog_ticks(&mut p, &mut now, 1, 999);
    assert!(kept.iter().all(|&t| t == 7000), "the repeated jog keeps it");
    // The second without a message ends: back to rest within the limits.
    let back = jog_ticks(&mut p, &mut now, 1, 400);
    assert!(
        back[0] < 7000,
        "eases from the tick a second after the last message"
    );
    assert_within_channel_1_limits(7000, &back);
    assert_eq!(back[399], 6000);
    assert!(p.resting() && p.settled());
    assert_eq!(marionette_core::perform::JOG_TIMEOUT_US, 1_000_000);
}

/// A board without a table still jogs (a servo is calibrated before its
/// tables are built); one that cannot drive the rig's back-end does not;
/// `Disarm` and a `Hello` end a jog.
#[test]
fn a_jog_needs_a_drivable_rig_and_ends_with_disarm_or_hello() {
    let rig = humanoid16();
    let bytes = perform::region(&rig_blob(&rig, None), None);
    let region = Region::parse(&bytes);
    assert_eq!(region.reason, StatusReason::NoTable);
    let jog = |seq, target| command(seq, CommandKind::Jog { channel: 1, target });
    let acked = |r: Vec<Message>| matches!(r.as_slice(), [Message::Ack(a)] if a.ok);
    for end in [command(2, CommandKind::Disarm), hello(PROTOCOL_VERSION)] {
        let mut solver = SolverState::new();
        let mut p = Performer::new(&region, &mut solver);
        assert!(acked(send(&mut p, &jog(1, 7000), 0)));
        let mut now = 0;
        assert_eq!(jog_ticks(&mut p, &mut now, 1, 300)[299], 7000);
        assert!(!p.resting());
        send(&mut p, &end, now);
        let back = jog_ticks(&mut p, &mut now, 1, 300);
        assert_within_channel_1_limits(7000, &back);
        assert_eq!(back[299], 6000);
        assert!(p.resting() && p.settled());
    }
    let mut solver = SolverState::new();
    let mut p = Performer::new(&region, &mut solver);
    p.refuse(StatusReason::Unsupported);
    assert!(!acked(send(&mut p, &jog(1, 7000), 0)));
    assert!(p.tick(1000).outputs.is_none());
}
