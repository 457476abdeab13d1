//! The compact tracker frame (`wire::compact`): exact bytes worked out by
//! hand from its spec (CRCs from zlib), the quantization error against the
//! `f32` frame over a million random sensors, and the receiver's handling
//! (sequence and time extension, rejections).

use marionette_core::wire::compact::{
    self, CompactFrame, POSITION_STEP_M, ROTATION_ERROR_RAD, SENSOR_BYTES,
};
use marionette_core::wire::{
    self, Command, CommandKind, Incoming, List, MAX_FRAME, Message, Receiver, Sensor, TrackerFrame,
    WireError,
};
use marionette_tests::synth_ref::{Rng, angle_between};

fn encode(msg: &Message) -> Vec<u8> {
    let mut out = [0u8; MAX_FRAME];
    wire::encode(msg, &mut out).expect("encode").to_vec()
}

fn sensor(id: u8, position: [f32; 3], rotation: [f32; 4]) -> Sensor {
    Sensor {
        id,
        position,
        rotation,
    }
}

fn frame(seq: u32, time_us: u32, sensors: &[Sensor]) -> TrackerFrame {
    TrackerFrame {
        seq,
        time_us,
        sensors: List::from_slice(sensors).unwrap(),
    }
}

fn compact(f: &TrackerFrame) -> Message {
    Message::CompactFrame(CompactFrame::pack(f).expect("packs"))
}

fn feed(rx: &mut Receiver, bytes: &[u8]) -> Vec<Incoming> {
    let mut out = Vec::new();
    let mut input = bytes;
    while let Some(m) = rx.push_slice(&mut input) {
        out.push(m);
    }
    out
}

/// The spec's worked example: seq 1, time 1000 µs, sensor 0 at
/// [0, 1.5, −0.25] m, identity. Payload written out from the layout;
/// CRC 0xB26A81BF from zlib; COBS by hand.
#[test]
fn worked_example_exact() {
    let f = frame(
        1,
        1000,
        &[sensor(0, [0.0, 1.5, -0.25], [1.0, 0.0, 0.0, 0.0])],
    );
    let mut payload = [0u8; 64];
    let p = wire::encode_payload(&compact(&f), &mut payload).unwrap();
    assert_eq!(
        p,
        &[
            0x07, 0x01, 0x00, 0xE8, 0x03, 0x00, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
            0x00, 0x30, 0x00, 0xF8
        ]
    );
    assert_eq!(
        encode(&compact(&f)),
        [
            0x03, 0x07, 0x01, 0x03, 0xE8, 0x03, 0x02, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01,
            0x01, 0x02, 0x30, 0x06, 0xF8, 0xBF, 0x81, 0x6A, 0xB2, 0x00
        ]
    );
    let mut rx: Receiver = Receiver::new();
    assert_eq!(feed(&mut rx, &encode(&compact(&f))), [Incoming::Tracker]);
    let got = rx.frame();
    assert_eq!((got.seq(), got.time_us()), (1, 1000));
    let s = got.sensors()[0];
    assert_eq!(s.position().to_array(), [0.0, 1.5, -0.25]);
    assert_eq!(s.rotation(), glam::Quat::IDENTITY);
}

/// Rotations by hand: 90° about Y (`w` and `y` tie: `w`, the first, is
/// dropped; `y` = 1023 steps) and `[0.6, −0.8, 0, 0]` (`x` is largest and
/// negative: the sign flips, `w` goes as round(−0.6 · 1023·√2) = −868).
#[test]
fn smallest_three_by_hand() {
    let h = core::f32::consts::FRAC_1_SQRT_2;
    let bytes = compact::pack_sensor(&sensor(2, [0.0; 3], [h, 0.0, h, 0.0])).unwrap();
    // Word 2 | 1023 << 17 = 0x07FE0002.
    assert_eq!(&bytes[..5], &[0x02, 0x00, 0xFE, 0x07, 0x00]);
    let back = compact::unpack_sensor(&bytes).unwrap().rotation();
    assert!(angle_between(q(back), [0.0, h as f64, 0.0, h as f64]) < 1e-6);
    let bytes = compact::pack_sensor(&sensor(0, [0.0; 3], [0.6, -0.8, 0.0, 0.0])).unwrap();
    // i = 1; a = −868 → 0x49C (11 bits); word 0x10 | 0x49C << 6 = 0x12710.
    assert_eq!(&bytes[..5], &[0x10, 0x27, 0x01, 0x00, 0x00]);
    let back = compact::unpack_sensor(&bytes).unwrap().rotation();
    // −q: the same rotation.
    assert!((back.x - 0.8).abs() < 1e-3 && (back.w + 0.6).abs() < 1e-3);
}

fn q(r: glam::Quat) -> [f64; 4] {
    [r.x as f64, r.y as f64, r.z as f64, r.w as f64]
}

/// Positions: steps of 2⁻¹³ m, range [−4, 4 − 2⁻¹³]; outside it, or not
/// finite, the compact frame refuses (the `f32` frame carries it).
#[test]
fn position_steps_and_range() {
    let pos = |x: f32| compact::pack_sensor(&sensor(0, [x, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]));
    assert_eq!(&pos(-4.0).unwrap()[5..7], &[0x00, 0x80]);
    assert_eq!(&pos(4.0 - 1.0 / 8192.0).unwrap()[5..7], &[0xFF, 0x7F]);
    // 1 step and a half rounds up to 2; 0.1 mm (0.82 steps) to 1.
    assert_eq!(&pos(1.5 / 8192.0).unwrap()[5..7], &[0x02, 0x00]);
    assert_eq!(&pos(0.0001).unwrap()[5..7], &[0x01, 0x00]);
    for bad in [4.0, -4.0001, f32::NAN, f32::INFINITY] {
        assert_eq!(pos(bad), Err(WireError::Range), "{bad}");
    }
    assert_eq!(POSITION_STEP_M, 1.0 / 8192.0);
}

/// The quantization error against the `f32` frame, over a million random
/// sensors (positions uniform in ±3.99 m, rotations uniform): position
/// within half a step per axis, rotation within `ROTATION_ERROR_RAD`
/// (0.14°). Packing an unpacked sensor gives the same bytes, except at
/// near-ties of the two largest components (then the other one is dropped,
/// within the same bound): fewer than 1 in 1,000 here.
#[test]
fn quantization_error_against_the_f32_frame() {
    let mut rng = Rng::new(14);
    let (mut worst_p, mut worst_q) = (0.0f64, 0.0f64);
    let mut repacked_differently = 0;
    for _ in 0..1_000_000 {
        let p = [0; 3].map(|_| rng.range(-3.99, 3.99) as f32);
        let [x, y, z, w] = rng.quat();
        let s = sensor(5, p, [w as f32, x as f32, y as f32, z as f32]);
        let exact = s.validate().unwrap();
        let bytes = compact::pack_sensor(&s).unwrap();
        let got = compact::unpack_sensor(&bytes).unwrap();
        for (a, b) in got
            .position()
            .to_array()
            .iter()
            .zip(exact.position().to_array())
        {
            worst_p = worst_p.max((f64::from(*a) - f64::from(b)).abs());
        }
        worst_q = worst_q.max(angle_between(q(got.rotation()), q(exact.rotation())));
        let again = sensor(
            got.id(),
            got.position().to_array(),
            [
                got.rotation().w,
                got.rotation().x,
                got.rotation().y,
                got.rotation().z,
            ],
        );
        let bytes2 = compact::pack_sensor(&again).unwrap();
        if bytes2 != bytes {
            repacked_differently += 1;
            assert_eq!(bytes2[5..], bytes[5..], "positions repack exactly");
            let got2 = compact::unpack_sensor(&bytes2).unwrap();
            let drift = angle_between(q(got2.rotation()), q(got.rotation()));
            assert!(drift <= f64::from(ROTATION_ERROR_RAD), "{s:?}");
        }
    }
    assert!(repacked_differently < 1000, "{repacked_differently}");
    eprintln!(
        "worst position error {:.4} mm, rotation {:.4}°; {repacked_differently} repacked differently",
        worst_p * 1e3,
        worst_q.to_degrees()
    );
    assert!(worst_p <= 1.0 / 16384.0 + 1e-7, "{worst_p}");
    assert!(worst_q <= f64::from(ROTATION_ERROR_RAD), "{worst_q}");
}

/// Sizes: 7 + 11·n bytes of payload; a 3-sensor frame is 46 bytes framed,
/// whatever its sequence number and time.
#[test]
fn a_three_sensor_frame_is_46_bytes_framed() {
    let s = sensor(0, [0.3, 1.2, -0.4], [0.5, 0.5, 0.5, 0.5]);
    for (seq, time) in [(1, 0), (u32::MAX, u32::MAX), (70_000, 20_000_000)] {
        let f = frame(
            seq,
            time,
            &[s, sensor(1, [0.1; 3], [1.0, 0.0, 0.0, 0.0]), {
                let mut t = s;
                t.id = 9;
                t
            }],
        );
        let mut payload = [0u8; 64];
        assert_eq!(
            wire::encode_payload(&compact(&f), &mut payload)
                .unwrap()
                .len(),
            40
        );
        assert!(encode(&compact(&f)).len() <= 46);
    }
    assert_eq!(SENSOR_BYTES, 11);
}

/// The receiver extends `seq16` and `time24` from the last accepted values
/// (hand-worked wraps), and checks the result like any sequence number.
#[test]
fn sequence_and_time_are_extended() {
    assert_eq!(compact::extend_seq(None, 7), 7);
    assert_eq!(compact::extend_seq(Some(0x0001_FFFE), 0x0001), 0x0002_0001);
    assert_eq!(compact::extend_seq(Some(0x0002_0001), 0xFFFE), 0x0001_FFFE);
    assert_eq!(compact::extend_seq(Some(5), 5 + 32_767), 32_772);
    assert_eq!(compact::extend_seq(Some(40_000), 7_232), 7_232);
    assert_eq!(compact::extend_time(None, 99), 99);
    assert_eq!(compact::extend_time(Some(0x00FF_FFF0), 0x10), 0x0100_0010);
    assert_eq!(compact::extend_time(Some(u32::MAX - 5), 4), 4);

    let s = [sensor(0, [0.0; 3], [1.0, 0.0, 0.0, 0.0])];
    let mut rx: Receiver = Receiver::new();
    let mut stream = Vec::new();
    // seq 65,534 .. 65,538 at 8.388608 s apart (time wraps 24 bits twice).
    for k in 0..5u32 {
        stream.extend(encode(&compact(&frame(65_534 + k, k * 8_388_608, &s))));
    }
    // A duplicate (stale) and a gap (lost).
    stream.extend(encode(&compact(&frame(65_538, 0, &s))));
    stream.extend(encode(&compact(&frame(65_541, 0, &s))));
    let mut seen = Vec::new();
    let mut input = stream.as_slice();
    while rx.push_slice(&mut input).is_some() {
        seen.push((rx.frame().seq(), rx.frame().time_us()));
    }
    assert_eq!(
        seen,
        [
            (65_534, 0),
            (65_535, 8_388_608),
            (65_536, 16_777_216),
            (65_537, 25_165_824),
            (65_538, 33_554_432),
            // Sent with time 0: taken as 0 µs after the last (24-bit step).
            (65_541, 33_554_432),
        ]
    );
    assert_eq!((rx.errors().stale, rx.errors().lost), (1, 2));
    // A command in between keeps the shared counter.
    let cmd = Message::Command(Command {
        seq: 65_542,
        kind: CommandKind::RequestStatus,
    });
    assert_eq!(feed(&mut rx, &encode(&cmd)).len(), 1);
    assert_eq!(
        feed(&mut rx, &encode(&compact(&frame(65_543, 0, &s)))),
        [Incoming::Tracker]
    );
    assert_eq!(rx.errors().lost, 2);
}

/// Framed with a correct CRC, bad compact payloads are counted: a length
/// that is not 7 + 11·n or n > 16 as `decode`; a repeated id, the reserved
/// bit, or a² + b² + c² > 1 as `range`.
#[test]
fn bad_compact_frames_are_counted() {
    let good = compact::pack_sensor(&sensor(1, [0.1; 3], [1.0, 0.0, 0.0, 0.0])).unwrap();
    let framed = |body: &[u8]| {
        let mut payload = vec![0x07];
        payload.extend_from_slice(body);
        let mut all = payload.clone();
        all.extend(marionette_core::crc::crc32(&payload).to_le_bytes());
        let mut out = vec![0u8; wire::cobs::max_encoded_len(all.len())];
        let n = wire::cobs::encode(&all, &mut out).unwrap();
        out.truncate(n);
        out.push(0);
        out
    };
    let header = |seq: u8, n: u8| vec![seq, 0, 0, 0, 0, n];
    let with = |seq, n, sensors: &[[u8; 11]]| {
        let mut b = header(seq, n);
        sensors.iter().for_each(|s| b.extend_from_slice(s));
        framed(&b)
    };
    let mut reserved = good;
    reserved[4] |= 0x80;
    // a = b = c = 1023 steps: 3 · 0.5 > 1.
    let mut too_long = good;
    let word: u64 = 1 | (0x3FF << 6) | (0x3FF << 17) | (0x3FF << 28);
    too_long[..5].copy_from_slice(&word.to_le_bytes()[..5]);
    let mut rx: Receiver = Receiver::new();
    let decode_errors = [
        with(1, 2, &[good]),
        with(2, 1, &[good, good]),
        framed(&header(3, 17)),
        framed(&[4, 0, 0]),
    ];
    let range_errors = [
        with(5, 2, &[good, good]),
        with(6, 1, &[reserved]),
        with(7, 1, &[too_long]),
    ];
    for bytes in decode_errors.iter().chain(&range_errors) {
        assert!(feed(&mut rx, bytes).is_empty());
    }
    let e = rx.errors();
    assert_eq!((e.decode, e.range, e.total()), (4, 3, 7), "{e:?}");
    assert_eq!(feed(&mut rx, &with(8, 1, &[good])), [Incoming::Tracker]);
}

/// The postcard form of [`CompactFrame`] (hosts) and the receiver's
/// in-place reading agree: every random frame sent through the receiver
/// gives the sensors `unpack_sensor` gives.
#[test]
fn the_receiver_reads_what_postcard_wrote() {
    let mut rng = Rng::new(7);
    let mut rx: Receiver = Receiver::new();
    for seq in 1..2000u32 {
        let n = rng.below(17);
        let mut ids: Vec<u8> = (0..16).collect();
        let sensors: Vec<Sensor> = (0..n)
            .map(|_| {
                let id = ids.remove(rng.below(ids.len()));
                let [x, y, z, w] = rng.quat();
                let p = [0; 3].map(|_| rng.range(-3.9, 3.9) as f32);
                sensor(id, p, [w as f32, x as f32, y as f32, z as f32])
            })
            .collect();
        let f = frame(seq, seq * 997, &sensors);
        let c = CompactFrame::pack(&f).unwrap();
        let msg = Message::CompactFrame(c);
        let mut buf = [0u8; MAX_FRAME];
        let p = wire::encode_payload(&msg, &mut buf).unwrap();
        assert_eq!(p.len(), 7 + 11 * n);
        assert_eq!(wire::decode_payload(p), Ok(msg));
        assert_eq!(feed(&mut rx, &encode(&msg)), [Incoming::Tracker]);
        let got = rx.frame();
        assert_eq!((got.seq(), got.time_us()), (seq, seq * 997));
        for (g, b) in got.sensors().iter().zip(&c.sensors) {
            assert_eq!(*g, compact::unpack_sensor(b).unwrap());
        }
        assert_eq!(got.sensors().len(), n);
    }
}
