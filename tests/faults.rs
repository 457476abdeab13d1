//! Fault injection on the emulated board (issue #7): the `perform` firmware
//! on QEMU `mps2-an386`, the shipped `humanoid16` rig with its 100 ms
//! fail-safe, and a script of tracker traffic with one kind of fault each.
//!
//! What every link scenario checks, from numbers the test computes itself
//! while building the script (never from the loop under test):
//!
//! - **no reset, no hang**: the firmware prints `boot` once and exits with
//!   status 0 after the closing `Disarm`, within the harness time-out;
//! - **every intact message accepted**: the board's `Status.frames_ok` (asked
//!   for at the end) equals the intact messages sent;
//! - **every damaged frame rejected and counted**: the board's rejection
//!   counters (`cobs + crc + decode + oversize + range`) equal the damaged
//!   frames sent (noise counts one per non-empty run of bytes between
//!   `0x00` delimiters, which is how the framing defines a frame), and the
//!   `lost` counter equals the tracker frames whose sequence number never
//!   arrived intact;
//! - **no output beyond its limits**: every Maestro target on the servo bus
//!   lies within its channel's pulse range from the rig file, and no step
//!   (from the power-up rest pulses on) is faster than the joint's top speed
//!   over one frame period.
//!
//! The table scenarios corrupt the table region instead and check that the
//! board refuses to arm, says why in its `Status`, and never writes a single
//! byte to the servo bus.
//!
//! Each test prints one row of the README's fault table; run them with
//! `cargo test -p marionette-tests --test faults -- --nocapture --test-threads=1`.

use glam::DVec3;
use marionette_core::wire::{
    self, Command, CommandKind, FRAME_CAPACITY, Hello, Message, PROTOCOL_VERSION, Sensor,
    StatusReason,
};
use marionette_host::perform;
use marionette_host::qemu::{self, Config, Emulator};
use marionette_tests::puppet::{self, Limits, humanoid16, rest_table, rig_blob};
use marionette_tests::synth_ref::Rng;
use std::io::Write;
use std::time::Duration;

/// One step of a script.
enum Part {
    /// Bytes for the tracker link.
    Send(Vec<u8>),
    /// After a `RequestStatus`: wait for the board's `statuses`-th `Status`
    /// (it handles messages in order, so every frame before has been
    /// driven), then send nothing for `pause`. The servo output during the
    /// pause is kept apart, to check that the fail-safe eases to rest.
    Pause { statuses: usize, pause: Duration },
}

/// A script of traffic and what the test expects of it.
#[derive(Default)]
struct Script {
    parts: Vec<Part>,
    /// Next host sequence number.
    seq: u32,
    /// Next tracker time step.
    step: u32,
    /// Hand offset for the next frames.
    offset: DVec3,
    /// Messages sent intact (the board must accept each).
    intact: u32,
    /// Tracker frames sent intact.
    intact_frames: u32,
    /// Damaged frames sent (the board must reject and count each).
    damaged: u32,
    /// Tracker frames whose sequence number never arrives intact.
    lost: u32,
    /// Faults injected (the README's "inputs tried").
    faults: u32,
    /// Intact messages up to and including the closing `RequestStatus`.
    accepted_at_status: u32,
    /// `Status` replies asked for so far (the `Hello`'s included).
    statuses: usize,
}

impl Script {
    /// `Hello` and `Arm`.
    fn start() -> Self {
        let mut s = Self::default();
        s.message(&Message::Hello(Hello {
            protocol_version: PROTOCOL_VERSION,
        }));
        s.statuses = 1;
        s.command(CommandKind::Arm);
        s
    }

    fn message(&mut self, msg: &Message) {
        self.parts
            .push(Part::Send(perform::encode(msg).expect("encodes")));
        self.intact += 1;
    }

    fn command(&mut self, kind: CommandKind) {
        let seq = self.next_seq();
        self.message(&Message::Command(Command { seq, kind }));
    }

    fn next_seq(&mut self) -> u32 {
        self.seq += 1;
        self.seq - 1
    }

    /// The next tracker frame (not yet sent).
    fn frame(&mut self) -> Message {
        let samples = puppet::step(self.step, self.offset);
        self.step += 1;
        let mut frame = perform::frames(&samples).expect("one frame")[0];
        frame.seq = self.next_seq();
        Message::TrackerFrame(frame)
    }

    /// `n` intact tracker frames.
    fn frames(&mut self, n: u32) {
        for _ in 0..n {
            let f = self.frame();
            self.message(&f);
            self.intact_frames += 1;
        }
    }

    /// A tracker frame damaged by `damage` (which must keep it non-empty
    /// and free of `0x00`); its sequence number is lost.
    fn damaged_frame(&mut self, damage: impl FnOnce(&mut Vec<u8>)) {
        let f = self.frame();
        let bytes = perform::encode(&f).expect("encodes");
        // [0x00, COBS body, 0x00]: damage the body only.
        let mut body = bytes[1..bytes.len() - 1].to_vec();
        damage(&mut body);
        assert!(
            !body.is_empty() && !body.contains(&0),
            "a fault stays one frame"
        );
        self.raw(&body, 1);
        self.lost += 1;
    }

    /// Bytes between two delimiters, expected to count `rejections`.
    fn raw(&mut self, body: &[u8], rejections: u32) {
        let mut bytes = vec![0];
        bytes.extend_from_slice(body);
        bytes.push(0);
        self.parts.push(Part::Send(bytes));
        self.damaged += rejections;
        self.faults += 1;
    }

    /// A well-formed, in-sequence tracker frame whose values are out of range.
    fn invalid_frame(&mut self, spoil: impl FnOnce(&mut [Sensor])) {
        let Message::TrackerFrame(mut f) = self.frame() else {
            unreachable!()
        };
        let mut sensors = f.sensors.as_slice().to_vec();
        spoil(&mut sensors);
        f.sensors = wire::List::from_slice(&sensors).expect("fits");
        self.parts.push(Part::Send(
            perform::encode(&Message::TrackerFrame(f)).expect("encodes"),
        ));
        self.damaged += 1;
        self.faults += 1;
    }

    /// No traffic for `pause` once the board has answered every frame.
    fn pause(&mut self, pause: Duration) {
        self.command(CommandKind::RequestStatus);
        self.statuses += 1;
        self.parts.push(Part::Pause {
            statuses: self.statuses,
            pause,
        });
    }

    /// `RequestStatus` then `Disarm`.
    fn finish(mut self) -> Self {
        self.command(CommandKind::RequestStatus);
        self.accepted_at_status = self.intact;
        self.command(CommandKind::Disarm);
        self
    }
}

/// Noise: runs of bytes between `0x00`s each count as one rejected frame.
fn noise_runs(noise: &[u8]) -> u32 {
    noise.split(|b| *b == 0).filter(|r| !r.is_empty()).count() as u32
}

/// `Status` messages among the board's replies.
fn count_statuses(bytes: &[u8]) -> usize {
    perform::decode_replies(bytes)
        .iter()
        .filter(|m| matches!(m, Message::Status(_)))
        .count()
}

/// What the board did with a script.
struct Outcome {
    status: Option<i32>,
    boots: usize,
    frames_ok: u32,
    rejected: u32,
    lost: u32,
    /// Every output frame on the servo bus, in order.
    outputs: Vec<Vec<u16>>,
    /// The output frames made during each pause (ranges of `outputs`).
    paused: Vec<std::ops::Range<usize>>,
    console: String,
}

fn region_file(region: &[u8]) -> tempfile::NamedTempFile {
    let mut f = tempfile::NamedTempFile::new().unwrap();
    f.write_all(region).unwrap();
    f
}

fn board(region: &[u8]) -> (Emulator, tempfile::NamedTempFile) {
    let file = region_file(region);
    let config = Config {
        tables: Some(file.path().to_path_buf()),
        timeout: Duration::from_secs(180),
        ..Config::new(qemu::firmware_elf("perform").expect("the embedded firmware is written out"))
    };
    (Emulator::start(&config).expect("QEMU starts"), file)
}

/// The humanoid16 region with its 100 ms fail-safe and a rest table.
fn puppet_region() -> Vec<u8> {
    let rig = humanoid16();
    perform::region(&rig_blob(&rig, None), Some(&rest_table(&rig)))
}

fn run(script: &Script, channels: usize) -> Outcome {
    let (mut emulator, _file) = board(&puppet_region());
    let frame_bytes = channels * 4;
    let mut servo = Vec::new();
    let mut paused = Vec::new();
    for part in &script.parts {
        match part {
            Part::Send(bytes) => emulator.send(bytes).expect("the board takes the bytes"),
            Part::Pause { statuses, pause } => {
                emulator
                    .wait_replies(|bytes| count_statuses(bytes) >= *statuses)
                    .expect("the board answers");
                servo.extend(emulator.take_servo());
                let start = servo.len() / frame_bytes;
                std::thread::sleep(*pause);
                servo.extend(emulator.take_servo());
                paused.push(start..servo.len() / frame_bytes);
            }
        }
    }
    let out = emulator.finish().expect("the board exits");
    servo.extend(out.servo);
    let status = perform::decode_replies(&out.tracker)
        .into_iter()
        .rev()
        .find_map(|m| match m {
            Message::Status(s) => Some(s),
            _ => None,
        })
        .expect("RequestStatus is answered");
    let e = status.errors;
    Outcome {
        status: out.status,
        boots: out.console.lines().filter(|l| *l == "boot").count(),
        frames_ok: status.frames_ok,
        rejected: e.cobs + e.crc + e.decode + e.oversize + e.range,
        lost: e.lost,
        outputs: perform::decode_maestro(&servo, channels),
        paused,
        console: out.console,
    }
}

/// Runs `script`, checks everything the module doc lists, and prints the
/// README row.
fn check(kind: &str, script: &Script) -> Outcome {
    let limits = puppet::limits(&humanoid16());
    let out = run(script, limits.len());
    let rest: Vec<u16> = limits.iter().map(|l| l.rest).collect();
    let stream: Vec<Vec<u16>> = std::iter::once(rest).chain(out.outputs.clone()).collect();
    let bad = puppet::violations(&stream, &limits);
    println!(
        "| {kind} | {} | {} | {} | {} | {} | {} |",
        script.faults,
        out.frames_ok,
        out.rejected,
        out.lost,
        out.boots.saturating_sub(1),
        bad.len()
    );
    assert_eq!(out.status, Some(0), "exit status; console: {}", out.console);
    assert_eq!(out.boots, 1, "the board reset; console: {}", out.console);
    assert_eq!(
        out.frames_ok, script.accepted_at_status,
        "intact messages accepted"
    );
    assert_eq!(out.rejected, script.damaged, "damaged frames counted");
    assert_eq!(out.lost, script.lost, "lost sequence numbers counted");
    assert!(
        bad.is_empty(),
        "limits violated: {:#?}",
        &bad[..bad.len().min(20)]
    );
    // Every intact tracker frame drove the servos (plus easing steps).
    assert!(out.outputs.len() >= script.intact_frames as usize);
    out
}

/// During a pause each channel heads for its rest pulse: a servo that was
/// moving away from rest may first have to brake (its acceleration limit),
/// so its distance to rest may grow at first, but once it shrinks it never
/// grows again, and it ends no farther than it started.
fn eases_to_rest(outputs: &[Vec<u16>], limits: &[Limits]) -> Result<(), String> {
    for (ch, l) in limits.iter().enumerate() {
        let d: Vec<i32> = outputs
            .iter()
            .map(|o| (i32::from(o[ch]) - i32::from(l.rest)).abs())
            .collect();
        let turn = d.windows(2).position(|w| w[1] < w[0]).unwrap_or(d.len());
        if let Some(i) = d.windows(2).skip(turn).position(|w| w[1] > w[0]) {
            return Err(format!(
                "channel {ch}: moves away from rest again at step {}: {d:?}",
                turn + i + 1
            ));
        }
        if d.last() > d.first() {
            return Err(format!("channel {ch}: ends farther from rest: {d:?}"));
        }
    }
    Ok(())
}

#[test]
fn random_noise_at_full_rate_is_rejected_and_counted() {
    let mut s = Script::start();
    let mut rng = Rng::new(1);
    for i in 0..1000 {
        let len = if i % 250 == 125 { 4096 } else { rng.below(49) };
        let noise: Vec<u8> = (0..len).map(|_| rng.byte()).collect();
        let runs = noise_runs(&noise);
        s.parts.push(Part::Send(noise));
        s.damaged += runs;
        s.faults += u32::from(len > 0);
        s.frames(1);
    }
    check(
        "random noise between frames (0–48 B; 4 KiB ×4)",
        &s.finish(),
    );
}

#[test]
fn truncated_frames_are_rejected_and_counted() {
    let mut s = Script::start();
    let mut rng = Rng::new(2);
    for i in 0..1000 {
        if i % 5 == 4 {
            let cut = rng.next_u64() as usize;
            s.damaged_frame(|b| b.truncate(1 + cut % (b.len() - 1)));
        } else {
            s.frames(1);
        }
    }
    s.frames(1);
    check("truncated frames", &s.finish());
}

#[test]
fn flipped_bits_are_rejected_and_counted() {
    let mut s = Script::start();
    let mut rng = Rng::new(3);
    for i in 0..1000 {
        if i % 5 == 4 {
            let flips = 1 + rng.below(3);
            let picks: Vec<u64> = (0..8).map(|_| rng.next_u64()).collect();
            s.damaged_frame(|b| flip_bits(b, flips, &picks));
        } else {
            s.frames(1);
        }
    }
    s.frames(1);
    check("flipped bits (1–3 per frame)", &s.finish());
}

/// Flips `n` distinct bits of `body`, chosen by `picks`, skipping any flip
/// that would make a byte `0x00` (that would split the frame in two).
fn flip_bits(body: &mut [u8], n: usize, picks: &[u64]) {
    let bits = body.len() * 8;
    let mut done: Vec<usize> = Vec::new();
    for &p in picks {
        if done.len() == n {
            break;
        }
        let bit = p as usize % bits;
        let (byte, mask) = (bit / 8, 1u8 << (bit % 8));
        if done.contains(&bit) || body[byte] ^ mask == 0 {
            continue;
        }
        body[byte] ^= mask;
        done.push(bit);
    }
    assert!(!done.is_empty());
}

#[test]
fn oversized_frames_are_rejected_and_counted() {
    let mut s = Script::start();
    let mut rng = Rng::new(4);
    for i in 0..600 {
        if i % 10 == 9 {
            let len = FRAME_CAPACITY + 1 + rng.below(3 * FRAME_CAPACITY);
            let junk: Vec<u8> = (0..len).map(|_| rng.byte().max(1)).collect();
            s.raw(&junk, 1);
        } else if i % 10 == 4 {
            // A well-formed COBS frame, just longer than any message.
            let payload: Vec<u8> = (0..FRAME_CAPACITY + 16).map(|_| rng.byte()).collect();
            let mut cobs = vec![0u8; payload.len() + payload.len() / 254 + 2];
            let n = wire::cobs::encode(&payload, &mut cobs).expect("encodes");
            s.raw(&cobs[..n], 1);
        }
        s.frames(1);
    }
    check("oversized frames", &s.finish());
}

#[test]
fn out_of_range_values_are_rejected_and_counted() {
    let mut s = Script::start();
    for i in 0..600u32 {
        match i % 20 {
            3 => s.invalid_frame(|v| v[0].position[0] = f32::NAN),
            7 => s.invalid_frame(|v| v[1].position[2] = f32::INFINITY),
            11 => s.invalid_frame(|v| v[2].position[1] = 1.0e9),
            13 => s.invalid_frame(|v| v[0].rotation = [0.0; 4]),
            17 => s.invalid_frame(|v| v[1].id = v[0].id),
            19 => s.invalid_frame(|v| v[2].id = 200),
            _ => s.frames(1),
        }
    }
    check("NaN, infinite, out-of-range values", &s.finish());
}

#[test]
fn bursts_are_all_taken() {
    let mut s = Script::start();
    for _ in 0..10 {
        s.frames(100);
        s.faults += 1;
        s.pause(Duration::from_millis(50));
    }
    check("bursts of 100 frames, 50 ms apart", &s.finish());
}

#[test]
fn a_stream_that_stops_eases_to_rest_and_restarts() {
    let mut s = Script::start();
    for _ in 0..3 {
        s.frames(300);
        s.pause(Duration::from_millis(600));
        // The tracker's own clock moves on too.
        s.step += 600;
        s.faults += 1;
    }
    s.frames(300);
    let out = check("stream stops for 0.6 s, restarts (×3)", &s.finish());
    let limits = puppet::limits(&humanoid16());
    assert_eq!(out.paused.len(), 3);
    for range in &out.paused {
        let during = &out.outputs[range.clone()];
        assert!(!during.is_empty(), "the fail-safe moved the servos");
        if let Err(e) = eases_to_rest(during, &limits) {
            panic!("fail-safe: {e}");
        }
    }
    assert!(
        out.outputs.len() > out.paused[2].end,
        "outputs after restart"
    );
}

#[test]
fn a_tracker_jump_of_one_metre_stays_within_limits() {
    let mut s = Script::start();
    s.frames(300);
    for offset in [
        DVec3::new(1.0, 0.0, 0.0),
        DVec3::new(0.0, -1.0, 0.0),
        DVec3::ZERO,
    ] {
        s.offset = offset;
        s.faults += 1;
        s.frames(200);
    }
    check("tracker jumps 1 m in one frame (×3)", &s.finish());
}

/// A session against a corrupted region: `Hello`, `Arm`, 50 frames,
/// `RequestStatus`, `Disarm`. Checks that the board refuses to arm and
/// drives nothing, and returns the reason it gives.
fn refused(region: &[u8]) -> StatusReason {
    let (mut emulator, _file) = board(region);
    let mut s = Script::start();
    s.frames(50);
    let s = s.finish();
    for part in &s.parts {
        if let Part::Send(bytes) = part {
            emulator.send(bytes).expect("the board takes the bytes");
        }
    }
    let out = emulator.finish().expect("the board exits");
    assert_eq!(out.status, Some(0), "console: {}", out.console);
    assert_eq!(out.console.lines().filter(|l| *l == "boot").count(), 1);
    assert!(out.servo.is_empty(), "a refused board drives nothing");
    let replies = perform::decode_replies(&out.tracker);
    let arm_ack = replies.iter().find_map(|m| match m {
        Message::Ack(a) if a.seq == 0 => Some(a.ok),
        _ => None,
    });
    assert_eq!(arm_ack, Some(false), "Arm is refused");
    let reasons: Vec<StatusReason> = replies
        .iter()
        .filter_map(|m| match m {
            Message::Status(st) => {
                assert!(!st.armed && !st.table_ok);
                Some(st.reason)
            }
            _ => None,
        })
        .collect();
    assert_eq!(reasons.len(), 2, "Hello and RequestStatus answered");
    assert_eq!(reasons[0], reasons[1]);
    reasons[0]
}

#[test]
fn corrupted_tables_are_refused_at_boot_and_the_reason_reported() {
    let rig16 = humanoid16();
    let (rig, table) = (rig_blob(&rig16, None), rest_table(&rig16));
    let mut rng = Rng::new(5);
    let mut rows = Vec::new();
    // Bit flips anywhere in the table blob.
    for _ in 0..6 {
        let mut t = table.clone();
        let bit = rng.below(t.len() * 8);
        t[bit / 8] ^= 1 << (bit % 8);
        let why = refused(&perform::region(&rig, Some(&t)));
        assert!(
            matches!(
                why,
                StatusReason::BadCrc
                    | StatusReason::BadMagic
                    | StatusReason::BadVersion
                    | StatusReason::BadBounds
            ),
            "bit {bit}: {why:?}"
        );
        rows.push(format!("bit {bit} flipped: {why:?}"));
    }
    // Truncation (the rest of the region reads as zeros).
    for _ in 0..4 {
        let t = &table[..rng.below(table.len())];
        let why = refused(&perform::region(&rig, Some(t)));
        let expect = if t.len() < 4 {
            [StatusReason::NoTable, StatusReason::BadMagic]
        } else {
            [StatusReason::BadBounds, StatusReason::BadCrc]
        };
        assert!(expect.contains(&why), "{} bytes: {why:?}", t.len());
        rows.push(format!(
            "cut to {} of {} bytes: {why:?}",
            t.len(),
            table.len()
        ));
    }
    // Erased flash where the table should be: no table, not a damaged one.
    let why = refused(&perform::region(&rig, Some(&[0xFF; 64])));
    assert_eq!(why, StatusReason::NoTable);
    rows.push(format!("erased (FF) table slot: {why:?}"));
    // A flipped bit in the magic.
    let mut t = table.clone();
    t[0] ^= 0x01;
    let why = refused(&perform::region(&rig, Some(&t)));
    assert_eq!(why, StatusReason::BadMagic);
    rows.push(format!("magic bit flipped: {why:?}"));
    // A format version from the future with a correct CRC.
    let mut t = table.clone();
    let future = marionette_core::table::VERSION + 1;
    t[4..6].copy_from_slice(&future.to_le_bytes());
    let n = t.len();
    let crc = marionette_core::crc::crc32(&t[..n - 4]);
    t[n - 4..].copy_from_slice(&crc.to_le_bytes());
    let why = refused(&perform::region(&rig, Some(&t)));
    assert_eq!(why, StatusReason::BadVersion);
    rows.push(format!("format version {future}, CRC fixed: {why:?}"));
    // A corrupted rig blob: nothing to drive at all.
    let mut r = rig.clone();
    let mid = r.len() / 2;
    r[mid] ^= 0x10;
    let why = refused(&perform::region(&r, Some(&table)));
    assert_eq!(why, StatusReason::NoRig);
    rows.push(format!("rig blob bit flipped: {why:?}"));
    println!(
        "| corrupted tables (random bit flips ×6, truncations ×4, erased slot, magic, wrong version, corrupted rig) | {} | — | refused at boot: {} | — | 0 | 0 |",
        rows.len(),
        rows.len()
    );
    for r in rows {
        println!("    {r}");
    }
}

#[test]
fn a_rig_for_a_servo_back_end_the_board_lacks_is_refused() {
    let rig16 = humanoid16();
    let table = rest_table(&rig16);
    let mut desc = rig16.desc();
    desc.output = marionette_core::rig::Output::Pwm { freq_hz: 50 };
    let mut buf = vec![0u8; marionette_core::rig::MAX_BLOB_LEN];
    let n = desc.to_blob(&mut buf).unwrap();
    let why = refused(&perform::region(&buf[..n], Some(&table)));
    assert_eq!(why, StatusReason::Unsupported);
}

/// The firmware holds rigs of at most 24 segments (its RAM budget): a valid
/// rig with one more is refused at boot with its own reason, like a missing
/// rig.
#[test]
fn a_rig_over_the_firmware_capacity_is_refused() {
    let rig16 = humanoid16();
    let mut desc = rig16.desc();
    // Rigid segments hanging from the root, named n00, n01, ...: 25 in all.
    let names: Vec<String> = (0..25).map(|i| format!("n{i:02}")).collect();
    let mut extra = desc.segments.as_slice()[0];
    extra.parent = 0;
    extra.dofs = marionette_core::wire::List::new();
    for name in &names[desc.segments.len()..] {
        extra.name = name;
        desc.segments.push(extra).unwrap();
    }
    assert_eq!(desc.segments.len(), 25);
    let mut buf = vec![0u8; marionette_core::rig::MAX_BLOB_LEN];
    let n = desc.to_blob(&mut buf).unwrap();
    let why = refused(&perform::region(&buf[..n], None));
    assert_eq!(why, StatusReason::RigTooLarge);
}
