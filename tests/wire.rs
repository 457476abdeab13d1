//! Wire protocol: exact bytes against the spec, COBS against the published
//! vectors, the receive path's rejections, and a noise proptest.
//!
//! The expected frames are written out by hand from the spec in
//! `marionette_core::wire` (postcard layout, CRC-32/ISO-HDLC little-endian,
//! COBS); the CRC values were computed with zlib (`zlib.crc32`), not with the
//! code under test.

use marionette_core::wire::{
    self, Ack, Command, CommandKind, ErrorCounters, FRAME_CAPACITY, FrameReader, Hello, Incoming,
    List, MAX_FRAME, MAX_PAYLOAD, MAX_SENSORS, Message, PROTOCOL_VERSION, Params, Receiver, Sensor,
    Session, ShowState, Status, StatusReason, Telemetry, TrackerFrame, WireError, cobs,
};
use marionette_core::wire::{FrameTiming, State, Trip};
use proptest::prelude::*;

// ---------------------------------------------------------------- helpers

fn encode(msg: &Message) -> Vec<u8> {
    let mut out = [0u8; MAX_FRAME];
    wire::encode(msg, &mut out).expect("encode").to_vec()
}

/// Runs `bytes` through a fresh FrameReader + decode_frame.
fn decode_stream(bytes: &[u8]) -> (Vec<Result<Message, WireError>>, ErrorCounters) {
    let mut reader = FrameReader::<FRAME_CAPACITY>::new();
    let mut errors = ErrorCounters::new();
    let mut out = Vec::new();
    let mut input = bytes;
    while let Some(frame) = reader.push_slice(&mut input, &mut errors) {
        out.push(wire::decode_frame(frame));
    }
    (out, errors)
}

fn feed<const N: usize>(rx: &mut Receiver<N>, bytes: &[u8]) -> Vec<Incoming> {
    let mut out = Vec::new();
    let mut input = bytes;
    while let Some(m) = rx.push_slice(&mut input) {
        out.push(m);
    }
    out
}

fn sensor(id: u8, position: [f32; 3], rotation: [f32; 4]) -> Sensor {
    Sensor {
        id,
        position,
        rotation,
    }
}

const IDENTITY: [f32; 4] = [1.0, 0.0, 0.0, 0.0];

fn tracker(seq: u32, sensors: &[Sensor]) -> Message {
    Message::TrackerFrame(TrackerFrame {
        seq,
        time_us: seq.wrapping_mul(1000),
        sensors: List::from_slice(sensors).unwrap(),
    })
}

fn command(seq: u32, kind: CommandKind) -> Message {
    Message::Command(Command { seq, kind })
}

/// Checks encode(msg) == frame, and that frame decodes back to msg.
fn check_exact(msg: Message, frame: &[u8]) {
    assert_eq!(encode(&msg), frame, "encoding of {msg:?}");
    let (got, errors) = decode_stream(frame);
    assert_eq!(got, vec![Ok(msg)]);
    assert_eq!(errors, ErrorCounters::new());
}

// ------------------------------------------------------------ exact bytes

#[test]
fn hello_exact() {
    // payload: 00 (tag Hello) 01 (varint 1); crc 0x36DE2269 → 69 22 DE 36.
    // COBS of 00 01 69 22 DE 36: block [] + zero → 01; block of 5 → 06 ...
    check_exact(
        Message::Hello(Hello {
            protocol_version: 1,
        }),
        &[0x01, 0x06, 0x01, 0x69, 0x22, 0xDE, 0x36, 0x00],
    );
}

#[test]
fn tracker_frame_one_sensor_exact() {
    // payload:
    //   01            tag TrackerFrame
    //   01            seq 1
    //   E8 07         time_us 1000 (0x3E8: 0x68|0x80, 0x07)
    //   01            1 sensor
    //   00            id 0
    //   00 00 00 00   x  0.0
    //   00 00 C0 3F   y  1.5   (0x3FC00000)
    //   00 00 80 BE   z -0.25  (0xBE800000)
    //   00 00 80 3F   w  1.0   (0x3F800000)
    //   00 00 00 00 ×3  x y z 0.0
    // crc 0xDB0F8228 → 28 82 0F DB
    let frame = [
        0x06, 0x01, 0x01, 0xE8, 0x07, 0x01, // [01 01 E8 07 01] + id 00
        0x01, 0x01, 0x01, 0x01, // x: 00 00 00 00
        0x01, 0x01, 0x03, 0xC0, 0x3F, // y: 00 00 C0 3F, + z's first 00
        0x01, 0x03, 0x80, 0xBE, // z: 00 80 BE, + w's first 00
        0x01, 0x03, 0x80, 0x3F, // w: 00 80 3F, + x's first 00
        0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01, // 11 more zeros
        0x05, 0x28, 0x82, 0x0F, 0xDB, // CRC, last block
        0x00,
    ];
    check_exact(
        Message::TrackerFrame(TrackerFrame {
            seq: 1,
            time_us: 1000,
            sensors: List::from_slice(&[sensor(0, [0.0, 1.5, -0.25], IDENTITY)]).unwrap(),
        }),
        &frame,
    );
}

#[test]
fn command_exact() {
    // Arm: 03 (Command) 05 (seq) 00 (Arm); crc 0x8070930E.
    check_exact(
        command(5, CommandKind::Arm),
        &[0x03, 0x03, 0x05, 0x05, 0x0E, 0x93, 0x70, 0x80, 0x00],
    );
    // SetGoalWeight: 03 07 04 (variant 4) 02 (goal) 00 00 00 3F (0.5);
    // crc 0x793DDA4F.
    check_exact(
        command(
            7,
            CommandKind::SetGoalWeight {
                goal: 2,
                weight: 0.5,
            },
        ),
        &[
            0x05, 0x03, 0x07, 0x04, 0x02, 0x01, 0x01, 0x06, 0x3F, 0x4F, 0xDA, 0x3D, 0x79, 0x00,
        ],
    );
}

#[test]
fn jog_exact() {
    // The spec's example (wire module doc, "Calibration: Jog"):
    // 03 (Command) 05 (seq) 07 (Jog) 01 (channel) F0 2E (varint 6000:
    // 6000 = 46·128 + 112, 112|0x80 = F0, 46 = 2E); crc 0xABC9E281
    // (zlib.crc32), no zero in payload + CRC: one block of 10.
    check_exact(
        command(
            5,
            CommandKind::Jog {
                channel: 1,
                target: 6000,
            },
        ),
        &[
            0x0B, 0x03, 0x05, 0x07, 0x01, 0xF0, 0x2E, 0x81, 0xE2, 0xC9, 0xAB, 0x00,
        ],
    );
}

#[test]
fn params_exact() {
    // 02 (Params) 02 (seq) 02 (2 values) 00 00 00 3F (0.5) 00 00 80 BF (-1.0);
    // crc 0x5AC4E997.
    check_exact(
        Message::Params(Params {
            seq: 2,
            values: List::from_slice(&[0.5, -1.0]).unwrap(),
        }),
        &[
            0x04, 0x02, 0x02, 0x02, 0x01, 0x01, 0x02, 0x3F, 0x01, 0x07, 0x80, 0xBF, 0x97, 0xE9,
            0xC4, 0x5A, 0x00,
        ],
    );
}

#[test]
fn ack_exact() {
    // 06 (Ack) AC 02 (seq 300) 01 (true); crc 0x917C76D0.
    check_exact(
        Message::Ack(Ack { seq: 300, ok: true }),
        &[0x09, 0x06, 0xAC, 0x02, 0x01, 0xD0, 0x76, 0x7C, 0x91, 0x00],
    );
}

#[test]
fn status_exact() {
    // 04 (Status) 02 (version) 01 (armed) 00 (table_ok false) 04 (BadCrc)
    // errors: 01 02 00 00 00 AC 02 00 00 (cobs 1, crc 2, lost 300)
    // 80 01 (frames_ok 128); version 2's appended fields: 01 05
    // (request_seq Some(5)), 02 (state Armed), 03 (trips); version 5's:
    // 09 (show RigMismatch) 02 (show_refusals); crc 0x3A661FA9 (zlib's).
    check_exact(
        Message::Status(Status {
            protocol_version: 2,
            armed: true,
            table_ok: false,
            reason: StatusReason::BadCrc,
            errors: ErrorCounters {
                cobs: 1,
                crc: 2,
                lost: 300,
                ..ErrorCounters::new()
            },
            frames_ok: 128,
            request_seq: Some(5),
            state: State::Armed,
            trips: 3,
            show: ShowState::RigMismatch,
            show_refusals: 2,
        }),
        &[
            0x04, 0x04, 0x02, 0x01, 0x04, 0x04, 0x01, 0x02, 0x01, 0x01, 0x03, 0xAC, 0x02, 0x01,
            0x0D, 0x80, 0x01, 0x01, 0x05, 0x02, 0x03, 0x09, 0x02, 0xA9, 0x1F, 0x66, 0x3A, 0x00,
        ],
    );
}

/// Every `StatusReason` encodes as the tag the spec gives it (the
/// payload's fifth byte, after the message tag, version, armed, table_ok).
#[test]
fn status_reason_tags_exact() {
    let tags = [
        (StatusReason::Ok, 0),
        (StatusReason::NoTable, 1),
        (StatusReason::BadMagic, 2),
        (StatusReason::BadVersion, 3),
        (StatusReason::BadCrc, 4),
        (StatusReason::BadBounds, 5),
        (StatusReason::ProtocolMismatch, 6),
        (StatusReason::NoRig, 7),
        (StatusReason::RigMismatch, 8),
        (StatusReason::Unsupported, 9),
        (StatusReason::RigTooLarge, 10),
    ];
    for (reason, tag) in tags {
        let msg = Message::Status(Status {
            protocol_version: 1,
            armed: false,
            table_ok: false,
            reason,
            errors: ErrorCounters::new(),
            frames_ok: 0,
            request_seq: None,
            state: State::Unready,
            trips: 0,
            show: ShowState::None,
            show_refusals: 0,
        });
        let frame = encode(&msg);
        let mut payload = [0u8; MAX_FRAME];
        let n = cobs::decode(&frame[..frame.len() - 1], &mut payload).unwrap();
        assert_eq!(&payload[..5], &[0x04, 0x01, 0x00, 0x00, tag], "{reason:?}");
        assert!(n > 5);
        check_exact(msg, &frame);
    }
}

#[test]
fn telemetry_exact() {
    // 05 (Telemetry) 00 (seq) 01 F0 2E (1 servo: 6000 = 0x1770 → 0xF0, 0x2E)
    // 01 00 00 80 3E (1 residual: 0.25) 01 02 03 04 05 0F (stages)
    // 00 × 8 (errors); version 2's appended fields: 03 (FailSafe) 02 (trips)
    // 07 1E (last trip: seq 7, 30 ticks) 0A DC 0B D0 0F 01 88 0E (timing:
    // 10 frames, mean 1500, worst 2000, 1 overrun, budget 1800);
    // crc 0xF1F625C1.
    check_exact(
        Message::Telemetry(Telemetry {
            seq: 0,
            servo_targets: List::from_slice(&[6000]).unwrap(),
            goal_residuals: List::from_slice(&[0.25]).unwrap(),
            stage_counts: [1, 2, 3, 4, 5, 15],
            errors: ErrorCounters::new(),
            state: State::FailSafe,
            trips: 2,
            last_trip: Trip { seq: 7, ticks: 30 },
            timing: FrameTiming {
                frames: 10,
                mean: 1500,
                worst: 2000,
                overruns: 1,
                budget: 1800,
            },
        }),
        &[
            0x02, 0x05, 0x05, 0x01, 0xF0, 0x2E, 0x01, 0x01, 0x09, 0x80, 0x3E, 0x01, 0x02, 0x03,
            0x04, 0x05, 0x0F, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x11, 0x03, 0x02, 0x07,
            0x1E, 0x0A, 0xDC, 0x0B, 0xD0, 0x0F, 0x01, 0x88, 0x0E, 0xC1, 0x25, 0xF6, 0xF1, 0x00,
        ],
    );
}

/// The `State` tags are the contract: the payload's fourth byte from the
/// end of a `Status` with `trips: 0`, no `request_seq` and no show.
#[test]
fn state_tags_exact() {
    let states = [
        (State::Unready, 0),
        (State::Disarmed, 1),
        (State::Armed, 2),
        (State::FailSafe, 3),
    ];
    for (state, tag) in states {
        let msg = Message::Status(Status {
            protocol_version: 2,
            armed: false,
            table_ok: true,
            reason: StatusReason::Ok,
            errors: ErrorCounters::new(),
            frames_ok: 0,
            request_seq: None,
            state,
            trips: 0,
            show: ShowState::None,
            show_refusals: 0,
        });
        let mut out = [0u8; MAX_PAYLOAD];
        let p = wire::encode_payload(&msg, &mut out).unwrap();
        assert_eq!(
            p,
            &[4, 2, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, tag, 0, 0, 0],
            "{state:?}"
        );
    }
}

/// The `ShowState` tags (version 5) are the contract: the payload's last
/// byte but one of a `Status` with `show_refusals: 0`.
#[test]
fn show_state_tags_exact() {
    let shows = [
        (ShowState::None, 0),
        (ShowState::Ready, 1),
        (ShowState::Playing, 2),
        (ShowState::Truncated, 3),
        (ShowState::BadMagic, 4),
        (ShowState::BadVersion, 5),
        (ShowState::BadCrc, 6),
        (ShowState::BadHeader, 7),
        (ShowState::BadKeys, 8),
        (ShowState::RigMismatch, 9),
    ];
    for (show, tag) in shows {
        let msg = Message::Status(Status {
            protocol_version: 5,
            armed: false,
            table_ok: true,
            reason: StatusReason::Ok,
            errors: ErrorCounters::new(),
            frames_ok: 0,
            request_seq: None,
            state: State::Disarmed,
            trips: 0,
            show,
            show_refusals: 0,
        });
        let mut out = [0u8; MAX_PAYLOAD];
        let p = wire::encode_payload(&msg, &mut out).unwrap();
        assert_eq!(
            p,
            &[4, 5, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0, tag, 0],
            "{show:?}"
        );
        assert_eq!(show.is_refused(), tag >= 3, "{show:?}");
    }
}

#[test]
fn message_tags_are_the_contract() {
    let bare = |m: &Message| {
        let mut out = [0u8; MAX_PAYLOAD];
        wire::encode_payload(m, &mut out).unwrap()[0]
    };
    let msgs = [
        Message::Hello(Hello {
            protocol_version: 9,
        }),
        tracker(0, &[]),
        Message::Params(Params {
            seq: 0,
            values: List::new(),
        }),
        command(0, CommandKind::RequestStatus),
        Message::Status(Status {
            protocol_version: 1,
            armed: false,
            table_ok: false,
            reason: StatusReason::NoTable,
            errors: ErrorCounters::new(),
            frames_ok: 0,
            request_seq: None,
            state: State::Unready,
            trips: 0,
            show: ShowState::None,
            show_refusals: 0,
        }),
        Message::Telemetry(Telemetry {
            seq: 0,
            servo_targets: List::new(),
            goal_residuals: List::new(),
            stage_counts: [0; 6],
            errors: ErrorCounters::new(),
            state: State::Unready,
            trips: 0,
            last_trip: Trip::default(),
            timing: FrameTiming::default(),
        }),
        Message::Ack(Ack { seq: 0, ok: false }),
    ];
    for (tag, m) in msgs.iter().enumerate() {
        assert_eq!(usize::from(bare(m)), tag);
        assert_eq!(usize::from(m.tag()), tag);
    }
    // Command kinds: payload is 03 00 <kind tag> ...
    let kinds = [
        CommandKind::Arm,
        CommandKind::Disarm,
        CommandKind::SelectTable(1),
        CommandKind::SelectClip(1),
        CommandKind::SetGoalWeight {
            goal: 0,
            weight: 1.0,
        },
        CommandKind::Boresight { sensor: 0 },
        CommandKind::RequestStatus,
        CommandKind::Jog {
            channel: 0,
            target: 0,
        },
    ];
    for (tag, k) in kinds.into_iter().enumerate() {
        let mut out = [0u8; MAX_PAYLOAD];
        let p = wire::encode_payload(&command(0, k), &mut out).unwrap();
        assert_eq!(usize::from(p[2]), tag, "{k:?}");
    }
    // SelectTable(3): 03 00 02 03.
    let mut out = [0u8; MAX_PAYLOAD];
    let p = wire::encode_payload(&command(0, CommandKind::SelectTable(3)), &mut out).unwrap();
    assert_eq!(p, &[0x03, 0x00, 0x02, 0x03]);
}

// -------------------------------------------------------------- limits

fn full_tracker() -> Message {
    let sensors: Vec<Sensor> = (0..MAX_SENSORS as u8)
        .map(|id| sensor(id, [1.0, 2.0, 3.0], [0.5, 0.5, 0.5, 0.5]))
        .collect();
    Message::TrackerFrame(TrackerFrame {
        seq: u32::MAX,
        time_us: u32::MAX,
        sensors: List::from_slice(&sensors).unwrap(),
    })
}

#[test]
fn largest_message_sizes() {
    let mut out = [0u8; 1024];
    let p = wire::encode_payload(&full_tracker(), &mut out).unwrap();
    assert_eq!(p.len(), 476);
    assert_eq!(MAX_PAYLOAD, 476);
    assert_eq!(FRAME_CAPACITY, 480);
    assert_eq!(MAX_FRAME, 483);
    let frame = encode(&full_tracker());
    assert!(frame.len() <= MAX_FRAME);
    let (got, _) = decode_stream(&frame);
    assert_eq!(got, vec![Ok(full_tracker())]);

    let telemetry = Message::Telemetry(Telemetry {
        seq: u32::MAX,
        servo_targets: List::from_slice(&[u16::MAX; 24]).unwrap(),
        goal_residuals: List::from_slice(&[1.0; 8]).unwrap(),
        stage_counts: [u32::MAX; 6],
        errors: ErrorCounters {
            cobs: u32::MAX,
            crc: u32::MAX,
            decode: u32::MAX,
            oversize: u32::MAX,
            version: u32::MAX,
            lost: u32::MAX,
            stale: u32::MAX,
            range: u32::MAX,
        },
        state: State::FailSafe,
        trips: u32::MAX,
        last_trip: Trip {
            seq: u32::MAX,
            ticks: u32::MAX,
        },
        timing: FrameTiming {
            frames: u32::MAX,
            mean: u32::MAX,
            worst: u32::MAX,
            overruns: u32::MAX,
            budget: u32::MAX,
        },
    });
    let p = wire::encode_payload(&telemetry, &mut out).unwrap();
    // 182 bytes in version 1, + 1 + 5 + 2 × 5 + 5 × 5 appended in version 2.
    assert_eq!(p.len(), 223);
    // A buffer one byte short of the frame fails cleanly.
    let frame = encode(&telemetry);
    let mut short = vec![0u8; frame.len() - 1];
    assert_eq!(
        wire::encode(&telemetry, &mut short),
        Err(WireError::BufferFull)
    );
}

#[test]
fn list_over_capacity_is_a_decode_error() {
    // Params with 7 values (capacity 6): 02 00 07 then 7 × f32.
    let mut payload = vec![0x02, 0x00, 0x07];
    for _ in 0..7 {
        payload.extend_from_slice(&1.0f32.to_le_bytes());
    }
    assert_eq!(wire::decode_payload(&payload), Err(WireError::Decode));
    // The same framed with a correct CRC: counted as a decode error.
    let mut body = payload.clone();
    body.extend_from_slice(&marionette_core::crc::crc32(&payload).to_le_bytes());
    let mut coded = vec![0u8; cobs::max_encoded_len(body.len())];
    let n = cobs::encode(&body, &mut coded).unwrap();
    coded.truncate(n);
    coded.push(0);
    let mut rx = Receiver::<FRAME_CAPACITY>::new();
    assert!(feed(&mut rx, &coded).is_empty());
    assert_eq!(rx.errors().decode, 1);
    // An unknown message tag (7) and an unknown command kind (7).
    assert_eq!(wire::decode_payload(&[0x07]), Err(WireError::Decode));
    assert_eq!(
        wire::decode_payload(&[0x03, 0x00, 0x07]),
        Err(WireError::Decode)
    );
    // A bool that is neither 0 nor 1.
    assert_eq!(
        wire::decode_payload(&[0x06, 0x00, 0x02]),
        Err(WireError::Decode)
    );
}

// ------------------------------------------------------------------ COBS

/// Wikipedia "COBS" examples 7-11 (Cheshire & Baker encoding), built from
/// their descriptions, delimiter omitted.
#[test]
fn cobs_long_vectors() {
    let range = |a: u32, b: u32| -> Vec<u8> { (a..=b).map(|x| x as u8).collect() };
    let cat = |parts: &[&[u8]]| -> Vec<u8> { parts.concat() };
    let cases: Vec<(Vec<u8>, Vec<u8>)> = vec![
        // 7: 01..FE (254 bytes) → FF 01..FE
        (range(1, 0xFE), cat(&[&[0xFF], &range(1, 0xFE)])),
        // 8: 00 01..FE (255 bytes) → 01 FF 01..FE
        (
            cat(&[&[0], &range(1, 0xFE)]),
            cat(&[&[0x01, 0xFF], &range(1, 0xFE)]),
        ),
        // 9: 01..FF (255 bytes) → FF 01..FE 02 FF
        (
            range(1, 0xFF),
            cat(&[&[0xFF], &range(1, 0xFE), &[0x02, 0xFF]]),
        ),
        // 10: 02..FF 00 (255 bytes) → FF 02..FF 01 01
        (
            cat(&[&range(2, 0xFF), &[0]]),
            cat(&[&[0xFF], &range(2, 0xFF), &[0x01, 0x01]]),
        ),
        // 11: 03..FF 00 01 (255 bytes) → FE 03..FF 02 01
        (
            cat(&[&range(3, 0xFF), &[0, 1]]),
            cat(&[&[0xFE], &range(3, 0xFF), &[0x02, 0x01]]),
        ),
    ];
    for (i, (raw, coded)) in cases.iter().enumerate() {
        let mut out = [0u8; 300];
        let n = cobs::encode(raw, &mut out).unwrap();
        assert_eq!(&out[..n], &coded[..], "encode case {}", i + 7);
        assert!(n <= cobs::max_encoded_len(raw.len()));
        let mut back = [0u8; 300];
        let m = cobs::decode(coded, &mut back).unwrap();
        assert_eq!(&back[..m], &raw[..], "decode case {}", i + 7);
    }
    // 508 non-zero bytes: two full blocks, nothing after.
    let raw = vec![0x55u8; 508];
    let mut out = [0u8; 600];
    let n = cobs::encode(&raw, &mut out).unwrap();
    assert_eq!(n, 510);
    assert_eq!((out[0], out[255]), (0xFF, 0xFF));
    assert!(out[..n].iter().all(|&b| b != 0));
}

#[test]
fn cobs_encoded_output_never_contains_zero() {
    let mut x: u32 = 99;
    let mut longest_run = 0;
    for len in 0..700u32 {
        let raw: Vec<u8> = (0..len)
            .map(|_| {
                x = x.wrapping_mul(1_103_515_245).wrapping_add(12345);
                // Short inputs are zero-rich; long ones have runs past 254.
                if (x >> 16).is_multiple_of(len % 300 + 2) {
                    0
                } else {
                    (x >> 24) as u8 | 1
                }
            })
            .collect();
        let mut out = vec![0u8; cobs::max_encoded_len(len as usize)];
        let n = cobs::encode(&raw, &mut out).unwrap();
        assert!(out[..n].iter().all(|&b| b != 0));
        longest_run = longest_run.max(raw.split(|&b| b == 0).map(<[u8]>::len).max().unwrap_or(0));
        let mut back = vec![0u8; (len as usize).max(1)];
        let m = cobs::decode(&out[..n], &mut back).unwrap();
        assert_eq!(&back[..m], &raw[..]);
    }
    assert!(longest_run > 2 * 254, "inputs exercise full blocks");
}

// ------------------------------------------------------------ receive path

#[test]
fn resync_after_garbage() {
    let hello = encode(&Message::Hello(Hello {
        protocol_version: PROTOCOL_VERSION,
    }));
    let arm = encode(&command(1, CommandKind::Arm));
    // Garbage with no zero merges with the next frame, which is lost; a
    // leading 0x00 from the sender restores sync.
    let mut stream = vec![0x13, 0x37, 0xFF];
    stream.extend_from_slice(&hello);
    stream.extend_from_slice(&[0xAA, 0xBB, 0xCC, 0x00]); // garbage ended by 0
    stream.extend_from_slice(&arm);
    stream.extend_from_slice(&[0x42, 0x00, 0x00]); // garbage, then an idle 0
    stream.extend_from_slice(&hello);
    let (got, errors) = decode_stream(&stream);
    let oks: Vec<_> = got.iter().filter_map(|r| r.as_ref().ok()).collect();
    assert_eq!(oks.len(), 2);
    assert_eq!(*oks[0], command(1, CommandKind::Arm));
    assert_eq!(oks[1].tag(), 0);
    // Rejections: the merged first frame, AA BB CC, 42 (all bad COBS).
    assert_eq!(errors.cobs, 3);
    assert_eq!(
        errors.total() + got.iter().filter(|r| r.is_err()).count() as u32,
        3
    );
}

#[test]
fn oversize_rejected_and_counted() {
    let big = encode(&full_tracker());
    let ack = encode(&command(9, CommandKind::Disarm));
    let mut rx = Receiver::<64>::new();
    let mut stream = big.clone();
    stream.extend_from_slice(&ack);
    stream.extend_from_slice(&big);
    let got = feed(&mut rx, &stream);
    assert_eq!(rx.errors().oversize, 2);
    assert_eq!(rx.errors().total(), 2);
    assert_eq!(got.len(), 1);
    assert!(matches!(got[0], Incoming::Command(c) if c.seq() == 9));
}

#[test]
fn crc_corruption_counted() {
    let frame = encode(&command(4, CommandKind::SelectClip(2)));
    let mut rx = Receiver::<FRAME_CAPACITY>::new();
    // Flip a bit in every non-code position in turn (keeping it non-zero).
    let mut corrupted = 0;
    for i in 1..frame.len() - 1 {
        let mut bad = frame.clone();
        bad[i] ^= 0x40;
        if bad[i] == 0 {
            continue;
        }
        let got = feed(&mut rx, &bad);
        assert!(got.is_empty(), "byte {i}");
        corrupted += 1;
    }
    let e = *rx.errors();
    // Each corrupted frame is rejected exactly once, as COBS (a corrupted code
    // byte) or CRC; nothing gets through.
    assert_eq!(e.cobs + e.crc, corrupted);
    assert!(e.crc > 0);
    assert_eq!(rx.frames_ok(), 0);
    // The intact frame still passes.
    assert_eq!(feed(&mut rx, &frame).len(), 1);
}

#[test]
fn sequence_gaps_counted_with_wrap() {
    let mut rx = Receiver::<FRAME_CAPACITY>::new();
    let s = [sensor(1, [0.0; 3], IDENTITY)];
    let mut stream = Vec::new();
    for seq in [u32::MAX - 2, u32::MAX - 1, 1, 2, 2, 0, 6] {
        stream.extend(encode(&tracker(seq, &s)));
    }
    let mut seqs = Vec::new();
    let mut input = stream.as_slice();
    while let Some(m) = rx.push_slice(&mut input) {
        assert_eq!(m, Incoming::Tracker);
        seqs.push(rx.frame().seq());
    }
    assert_eq!(seqs, [u32::MAX - 2, u32::MAX - 1, 1, 2, 6]);
    // MAX-1 → 1 skips MAX and 0 (2 lost); 2 → 6 skips 3, 4, 5 (3 lost).
    assert_eq!(rx.errors().lost, 5);
    // The repeated 2 and the late 0 are stale.
    assert_eq!(rx.errors().stale, 2);
    // Params and commands share the counter: 7 follows 6.
    let got = feed(&mut rx, &encode(&command(7, CommandKind::Arm)));
    assert_eq!(got.len(), 1);
    assert_eq!(rx.errors().lost, 5);
    assert_eq!(rx.frames_ok(), 6);
}

#[test]
fn validation_rejects_bad_values() {
    let ok = |id| sensor(id, [0.1, 1.0, -0.2], IDENTITY);
    let bad_frames = [
        vec![sensor(0, [f32::NAN, 0.0, 0.0], IDENTITY)],
        vec![sensor(0, [0.0, f32::INFINITY, 0.0], IDENTITY)],
        vec![sensor(0, [0.0, 0.0, -100.5], IDENTITY)],
        vec![sensor(0, [80.0, 80.0, 0.0], IDENTITY)],
        vec![sensor(0, [0.0; 3], [f32::NAN, 0.0, 0.0, 0.0])],
        vec![sensor(0, [0.0; 3], [0.0, 0.0, f32::NEG_INFINITY, 0.0])],
        vec![sensor(0, [0.0; 3], [0.7, 0.0, 0.0, 0.0])], // |q| = 0.7
        vec![sensor(0, [0.0; 3], [0.0; 4])],
        vec![ok(16)],
        vec![ok(255)],
        vec![ok(3), ok(5), ok(3)],
    ];
    let bad_commands = [
        CommandKind::SetGoalWeight {
            goal: 8,
            weight: 1.0,
        },
        CommandKind::SetGoalWeight {
            goal: 0,
            weight: -1.0,
        },
        CommandKind::SetGoalWeight {
            goal: 0,
            weight: f32::NAN,
        },
        CommandKind::SetGoalWeight {
            goal: 0,
            weight: f32::INFINITY,
        },
        CommandKind::Boresight { sensor: 16 },
        CommandKind::Jog {
            channel: 24,
            target: 6000,
        },
        CommandKind::Jog {
            channel: 0,
            target: 0x4000,
        },
    ];
    let bad_params = [[f32::NAN, 0.0], [0.0, f32::INFINITY], [2.0e6, 0.0]];

    let mut rx = Receiver::<FRAME_CAPACITY>::new();
    let mut seq = 0;
    let mut stream = Vec::new();
    for f in &bad_frames {
        seq += 1;
        stream.extend(encode(&tracker(seq, f)));
    }
    for k in bad_commands {
        seq += 1;
        stream.extend(encode(&command(seq, k)));
    }
    for p in bad_params {
        seq += 1;
        stream.extend(encode(&Message::Params(Params {
            seq,
            values: List::from_slice(&p).unwrap(),
        })));
    }
    assert!(feed(&mut rx, &stream).is_empty());
    let n = (bad_frames.len() + bad_commands.len() + bad_params.len()) as u32;
    assert_eq!(rx.errors().range, n);
    assert_eq!(
        rx.errors().total(),
        n,
        "no lost frames: rejected ones advance seq"
    );

    // Good ones, including a slightly off-unit quaternion, pass.
    let good = tracker(
        seq + 1,
        &[
            ok(15),
            ok(0),
            sensor(7, [99.0, 0.0, 0.0], [0.0, 1.03, 0.0, 0.0]),
        ],
    );
    let got = feed(&mut rx, &encode(&good));
    assert_eq!(got, [Incoming::Tracker]);
    let f = rx.frame();
    assert_eq!(f.sensors().len(), 3);
    let q = f.sensor(7).unwrap().rotation();
    // [w,x,y,z] = [0, 1.03, 0, 0] renormalised to the unit x quaternion.
    assert!((q.x - 1.0).abs() < 1e-6 && q.y == 0.0 && q.z == 0.0 && q.w == 0.0);
    assert_eq!(f.sensor(0).unwrap().position().y, 1.0);
    let got = feed(
        &mut rx,
        &encode(&command(
            seq + 2,
            CommandKind::SetGoalWeight {
                goal: 7,
                weight: 0.0,
            },
        )),
    );
    assert!(matches!(got[0], Incoming::Command(c) if c.seq() == seq + 2));
}

#[test]
fn version_handshake() {
    let mut rx = Receiver::<FRAME_CAPACITY>::new();
    assert_eq!(rx.session(), Session::Open);
    let arm = |seq| encode(&command(seq, CommandKind::Arm));
    // Before any Hello, messages are accepted.
    assert_eq!(feed(&mut rx, &arm(100)).len(), 1);

    let bad = encode(&Message::Hello(Hello {
        protocol_version: PROTOCOL_VERSION + 1,
    }));
    let got = feed(&mut rx, &bad);
    assert_eq!(
        got,
        vec![Incoming::Hello {
            host_version: PROTOCOL_VERSION + 1,
            accepted: false
        }]
    );
    assert_eq!(
        rx.session(),
        Session::Rejected {
            host_version: PROTOCOL_VERSION + 1
        }
    );
    assert!(feed(&mut rx, &arm(101)).is_empty());
    assert_eq!(rx.errors().version, 2);

    let good = encode(&Message::Hello(Hello {
        protocol_version: PROTOCOL_VERSION,
    }));
    let got = feed(&mut rx, &good);
    assert!(matches!(got[0], Incoming::Hello { accepted: true, .. }));
    assert_eq!(rx.session(), Session::Accepted);
    // A new session may restart its sequence anywhere.
    assert_eq!(feed(&mut rx, &arm(0)).len(), 1);
    assert_eq!(rx.errors().stale, 0);
    assert_eq!(rx.frames_ok(), 3);
}

#[test]
fn board_messages_at_the_board_are_rejected() {
    let mut rx = Receiver::<FRAME_CAPACITY>::new();
    let got = feed(&mut rx, &encode(&Message::Ack(Ack { seq: 1, ok: true })));
    assert!(got.is_empty());
    assert_eq!(rx.errors().decode, 1);
}

#[test]
fn byte_at_a_time_equals_slices() {
    let stream: Vec<u8> = [
        encode(&command(1, CommandKind::Arm)),
        encode(&tracker(2, &[sensor(2, [0.5; 3], IDENTITY)])),
        vec![1, 2, 3, 0],
        encode(&command(3, CommandKind::RequestStatus)),
    ]
    .concat();
    let mut a = Receiver::<FRAME_CAPACITY>::new();
    let by_byte: Vec<Incoming> = stream.iter().filter_map(|&b| a.push(b)).collect();
    let mut b = Receiver::<FRAME_CAPACITY>::new();
    assert_eq!(by_byte, feed(&mut b, &stream));
    assert_eq!(by_byte.len(), 3);
    assert_eq!(a.errors(), b.errors());
    assert_eq!(a.errors().total(), 1);
}

// ------------------------------------------------------------- proptests

fn arb_f32() -> impl Strategy<Value = f32> {
    any::<u32>().prop_map(f32::from_bits)
}

fn arb_sensor() -> impl Strategy<Value = Sensor> {
    (
        any::<u8>(),
        prop::array::uniform3(arb_f32()),
        prop::array::uniform4(arb_f32()),
    )
        .prop_map(|(id, position, rotation)| Sensor {
            id,
            position,
            rotation,
        })
}

fn arb_kind() -> impl Strategy<Value = CommandKind> {
    prop_oneof![
        Just(CommandKind::Arm),
        Just(CommandKind::Disarm),
        any::<u8>().prop_map(CommandKind::SelectTable),
        any::<u8>().prop_map(CommandKind::SelectClip),
        (any::<u8>(), arb_f32())
            .prop_map(|(goal, weight)| CommandKind::SetGoalWeight { goal, weight }),
        any::<u8>().prop_map(|sensor| CommandKind::Boresight { sensor }),
        Just(CommandKind::RequestStatus),
        (any::<u8>(), any::<u16>())
            .prop_map(|(channel, target)| CommandKind::Jog { channel, target }),
        any::<bool>().prop_map(|play| CommandKind::Show { play }),
    ]
}

fn arb_message() -> impl Strategy<Value = Message> {
    prop_oneof![
        any::<u16>().prop_map(|protocol_version| Message::Hello(Hello { protocol_version })),
        (
            any::<u32>(),
            any::<u32>(),
            prop::collection::vec(arb_sensor(), 0..=16)
        )
            .prop_map(|(seq, time_us, s)| Message::TrackerFrame(TrackerFrame {
                seq,
                time_us,
                sensors: List::from_slice(&s).unwrap(),
            })),
        (any::<u32>(), prop::collection::vec(arb_f32(), 0..=6)).prop_map(|(seq, v)| {
            Message::Params(Params {
                seq,
                values: List::from_slice(&v).unwrap(),
            })
        }),
        (any::<u32>(), arb_kind()).prop_map(|(seq, kind)| command(seq, kind)),
        (any::<u32>(), any::<bool>(), any::<[u32; 8]>()).prop_map(|(seq, ok, e)| {
            Message::Status(Status {
                protocol_version: seq as u16,
                armed: ok,
                table_ok: !ok,
                reason: StatusReason::ProtocolMismatch,
                errors: ErrorCounters {
                    cobs: e[0],
                    crc: e[1],
                    decode: e[2],
                    oversize: e[3],
                    version: e[4],
                    lost: e[5],
                    stale: e[6],
                    range: e[7],
                },
                frames_ok: seq,
                request_seq: ok.then_some(e[0]),
                state: [
                    State::Unready,
                    State::Disarmed,
                    State::Armed,
                    State::FailSafe,
                ][(e[1] % 4) as usize],
                trips: e[2],
                show: [
                    ShowState::None,
                    ShowState::Playing,
                    ShowState::BadCrc,
                    ShowState::RigMismatch,
                ][(e[3] % 4) as usize],
                show_refusals: e[4],
            })
        }),
        (
            any::<u32>(),
            prop::collection::vec(any::<u16>(), 0..=24),
            prop::collection::vec(arb_f32(), 0..=8),
            any::<[u32; 6]>(),
            any::<[u32; 8]>()
        )
            .prop_map(
                |(seq, s, g, stage_counts, x)| Message::Telemetry(Telemetry {
                    seq,
                    servo_targets: List::from_slice(&s).unwrap(),
                    goal_residuals: List::from_slice(&g).unwrap(),
                    stage_counts,
                    errors: ErrorCounters::new(),
                    state: [
                        State::Unready,
                        State::Disarmed,
                        State::Armed,
                        State::FailSafe
                    ][(x[0] % 4) as usize],
                    trips: x[1],
                    last_trip: Trip {
                        seq: x[2],
                        ticks: x[3]
                    },
                    timing: FrameTiming {
                        frames: x[4],
                        mean: x[5],
                        worst: x[6],
                        overruns: x[7],
                        budget: seq,
                    },
                })
            ),
        (any::<u32>(), any::<bool>()).prop_map(|(seq, ok)| Message::Ack(Ack { seq, ok })),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// Any message round-trips bit for bit (NaN payloads included: compared
    /// through their re-encoding) and fits MAX_FRAME.
    #[test]
    fn round_trip(msg in arb_message()) {
        let frame = encode(&msg);
        prop_assert!(frame.len() <= MAX_FRAME);
        prop_assert_eq!(frame.iter().filter(|&&b| b == 0).count(), 1);
        let (got, errors) = decode_stream(&frame);
        prop_assert_eq!(errors, ErrorCounters::new());
        prop_assert_eq!(got.len(), 1);
        let back = got[0].expect("decodes");
        prop_assert_eq!(encode(&back), frame);
    }

    /// Random noise between valid frames: every frame (preceded by the
    /// resync 0x00 a sender may send) is decoded, in order; every non-empty
    /// run of noise between zeros is rejected and counted exactly once.
    #[test]
    fn noise_interleaved_with_frames(
        items in prop::collection::vec(
            (prop::collection::vec(any::<u8>(), 0..600), arb_message()),
            1..8,
        ),
        tail in prop::collection::vec(any::<u8>(), 0..64),
    ) {
        let mut stream = Vec::new();
        let mut noise_runs = 0u32;
        let mut sent = Vec::new();
        for (noise, msg) in &items {
            stream.extend_from_slice(noise);
            stream.push(0);
            noise_runs += noise.split(|&b| b == 0).filter(|r| !r.is_empty()).count() as u32;
            let frame = encode(msg);
            stream.extend_from_slice(&frame);
            sent.push(frame);
        }
        stream.extend_from_slice(&tail);
        // Runs in the tail count once they are ended by a zero.
        let tail_runs: Vec<&[u8]> = tail.split(|&b| b == 0).collect();
        let ended = tail_runs.len() - 1;
        noise_runs += tail_runs[..ended].iter().filter(|r| !r.is_empty()).count() as u32;

        let (got, errors) = decode_stream(&stream);
        let decoded: Vec<Vec<u8>> = got.iter().filter_map(|r| r.ok()).map(|m| encode(&m)).collect();
        prop_assert_eq!(&decoded, &sent);
        let rejected = got.iter().filter(|r| r.is_err()).count() as u32;
        prop_assert_eq!(errors.total() + rejected, noise_runs);

        // The full receive path takes the same stream without panicking and
        // byte-at-a-time agrees with slices.
        let mut a = Receiver::<FRAME_CAPACITY>::new();
        let by_byte: Vec<Incoming> = stream.iter().filter_map(|&b| a.push(b)).collect();
        let mut b = Receiver::<FRAME_CAPACITY>::new();
        prop_assert_eq!(by_byte, feed(&mut b, &stream));
        prop_assert_eq!(a.errors(), b.errors());
    }

    /// Arbitrary bytes never panic any decoder.
    #[test]
    fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..2000)) {
        let mut rx = Receiver::<FRAME_CAPACITY>::new();
        let _ = feed(&mut rx, &bytes);
        let _ = wire::decode_payload(&bytes);
        let _ = wire::decode_frame(&bytes);
        let mut dst = vec![0u8; bytes.len()];
        let _ = cobs::decode(&bytes, &mut dst);
    }
}
