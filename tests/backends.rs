//! Every servo back-end, end to end.
//!
//! - **On the emulated board**, each UART back-end (Pololu Maestro,
//!   Dynamixel Protocol 2.0, Feetech STS and SCS) drives UART1 for the
//!   shipped `humanoid16` puppet (its servo numbers taken as positions for
//!   the bus servos, IDs = channel + 1). The bytes are decoded here with the
//!   decoders written from the manuals (`marionette_tests::servo_bus`) and
//!   must be exactly what the core run natively (`sim`) asks for, frame for
//!   frame: Set Targets for the Maestro; for the bus servos, the torque
//!   switches and the Goal Positions the back-end documents.
//! - **Natively**, the same session's outputs go through every back-end's
//!   real encoder (the Maestro, bus servo and PCA9685 bytes, the PWM duty
//!   cycles), are decoded back to pulses or positions here, and must keep
//!   the slew and limit guarantees: no value outside the servo's calibrated
//!   range, no step faster than its joint allows (within the back-end's
//!   resolution).

use std::convert::Infallible;

use embedded_hal::i2c::{ErrorType, I2c, Operation};
use embedded_hal::pwm::SetDutyCycle;
use marionette_core::frame::Performer;
use marionette_core::output::pca9685::{self, Pca9685};
use marionette_core::output::pwm::Pwm;
use marionette_core::output::serial::{Serial, UartServos};
use marionette_core::output::{ServoOutput, Support};
use marionette_core::rig::{FeetechSeries, Idle, Output, RigDesc};
use marionette_host::perform::{self, Pacing, Sent};
use marionette_tests::puppet::{Limits, humanoid16, limits, recording, rest_table};
use marionette_tests::servo_bus::{
    SyncWrite, decode_dynamixel, decode_feetech, decode_maestro, expected_bus_writes,
};
use std::time::Duration;

/// The humanoid16 puppet on `output`, with its fail-safe at 60 s (see
/// `perform.rs`) and the idle policy `idle`; bus IDs are channel + 1.
fn variant(output: Output, idle: Idle) -> Vec<u8> {
    let rig = humanoid16();
    let mut desc: RigDesc<'_> = rig.desc();
    desc.output = output;
    desc.idle = idle;
    desc.failsafe_timeout_ms = 60_000;
    let servos: Vec<_> = desc
        .servos
        .iter()
        .map(|s| marionette_core::rig::ServoDesc {
            id: s.channel + 1,
            ..*s
        })
        .collect();
    desc.servos = marionette_core::wire::List::from_slice(&servos).unwrap();
    let mut buf = vec![0u8; marionette_core::rig::MAX_BLOB_LEN];
    let n = desc.to_blob(&mut buf).expect("the variant is a valid rig");
    perform::region(&buf[..n], Some(&rest_table(&rig)))
}

fn session(frames: u32) -> (Vec<Sent>, usize) {
    let f = perform::frames(&recording(frames)).unwrap();
    (perform::session(&f).unwrap(), f.len())
}

/// Every output the core sends natively, in order, as raw targets.
fn native_outputs(region: &[u8], session: &[Sent]) -> Vec<Vec<u16>> {
    let mut out = Vec::new();
    perform::simulate_with(region, session, &mut |p: &Performer<'_, '_>, u| {
        if u.outputs.is_some() {
            out.push(p.targets().to_vec());
        }
    })
    .unwrap();
    out
}

/// Runs the session on the emulated board; the raw bytes of UART1.
fn emulated_bytes(region: &[u8], session: &[Sent], frames: usize) -> Vec<u8> {
    let mut file = tempfile::NamedTempFile::new().unwrap();
    std::io::Write::write_all(&mut file, region).unwrap();
    let (_, bytes) = perform::emulate(
        file.path(),
        session,
        16,
        frames,
        Pacing::AsFastAsPossible,
        Duration::ZERO,
    )
    .unwrap();
    bytes
}

fn ids() -> Vec<Option<u8>> {
    (1..=16).map(Some).collect()
}

#[test]
fn the_maestro_on_uart1_is_the_native_core_frame_for_frame() {
    let region = variant(Output::Maestro { baud: 115_200 }, Idle::Hold);
    let (session, frames) = session(300);
    let native = native_outputs(&region, &session);
    let sent = decode_maestro(&emulated_bytes(&region, &session, frames));
    let want: Vec<(u8, u16)> = native
        .iter()
        .flat_map(|f| f.iter().enumerate().map(|(ch, &t)| (ch as u8, t)))
        .collect();
    assert!(native.len() > frames, "frames and the easing after them");
    assert_eq!(
        sent.len(),
        want.len(),
        "one Set Target per channel per output"
    );
    for (i, (a, b)) in sent.iter().zip(&want).enumerate() {
        assert_eq!(a, b, "command {i} (output {})", i / 16);
    }
}

/// Runs a bus back-end on the emulated board and compares its packets with
/// what the native outputs call for.
fn bus_matches_native(output: Output, idle: Idle, decode: fn(&[u8]) -> Vec<SyncWrite>) {
    let (torque_at, goal_at) = match output {
        Output::Dynamixel { .. } => (64, 116),
        _ => (40, 42),
    };
    let region = variant(output, idle);
    let (session, frames) = session(300);
    let native = native_outputs(&region, &session);
    let want = expected_bus_writes(&native, &ids(), torque_at, goal_at);
    let sent = decode(&emulated_bytes(&region, &session, frames));
    // The first frame switches all 16 servos on; with idle "off" the last
    // write switches them all off.
    assert_eq!(sent[0].address, torque_at);
    assert_eq!(sent[0].items.len(), 16);
    let last = sent.last().unwrap();
    match idle {
        Idle::Off => assert_eq!((last.address, last.items.len()), (torque_at, 16)),
        Idle::Hold => assert_eq!(last.address, goal_at),
    }
    assert_eq!(sent.len(), want.len(), "{output:?}: packets");
    for (i, (a, b)) in sent.iter().zip(&want).enumerate() {
        assert_eq!(a, b, "{output:?}: packet {i}");
    }
}

#[test]
fn dynamixel_on_uart1_is_the_native_core_frame_for_frame() {
    bus_matches_native(
        Output::Dynamixel { baud: 1_000_000 },
        Idle::Off,
        decode_dynamixel,
    );
}

#[test]
fn feetech_sts_on_uart1_is_the_native_core_frame_for_frame() {
    let sts = Output::Feetech {
        baud: 1_000_000,
        series: FeetechSeries::Sts,
    };
    bus_matches_native(sts, Idle::Hold, |b| decode_feetech(b, false));
}

#[test]
fn feetech_scs_on_uart1_is_the_native_core_frame_for_frame() {
    let scs = Output::Feetech {
        baud: 500_000,
        series: FeetechSeries::Scs,
    };
    bus_matches_native(scs, Idle::Off, |b| decode_feetech(b, true));
}

// ------------------------------------------------------------------ natively

/// A UART that keeps what it is given.
struct Uart(Vec<u8>);

impl embedded_io::ErrorType for Uart {
    type Error = Infallible;
}

impl embedded_io::Write for Uart {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        self.0.extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}

/// An I2C bus that keeps every write.
#[derive(Default)]
struct Bus(Vec<Vec<u8>>);

impl ErrorType for Bus {
    type Error = Infallible;
}

impl I2c for Bus {
    fn transaction(&mut self, _: u8, ops: &mut [Operation<'_>]) -> Result<(), Infallible> {
        for op in ops {
            if let Operation::Write(bytes) = op {
                self.0.push(bytes.to_vec());
            }
        }
        Ok(())
    }
}

/// A timer channel of 0.5 µs ticks at 50 Hz (40 000 per period) that keeps
/// its duty cycles.
struct Channel(Vec<u16>);

impl embedded_hal::pwm::ErrorType for Channel {
    type Error = Infallible;
}

impl SetDutyCycle for Channel {
    fn max_duty_cycle(&self) -> u16 {
        40_000
    }
    fn set_duty_cycle(&mut self, duty: u16) -> Result<(), Infallible> {
        self.0.push(duty);
        Ok(())
    }
}

/// Checks decoded frames (quarter units by channel; `None`: no pulse) against
/// the rig's limits, with `slack` quarter units for the back-end's
/// resolution. Returns the violations.
fn check(frames: &[Vec<Option<f64>>], limits: &[Limits], slack: f64) -> Vec<String> {
    let mut bad = Vec::new();
    for (i, f) in frames.iter().enumerate() {
        for (ch, (v, l)) in f.iter().zip(limits).enumerate() {
            let Some(v) = *v else { continue };
            if v < f64::from(l.low) - slack || v > f64::from(l.high) + slack {
                bad.push(format!(
                    "output {i} ch {ch}: {v} outside [{}, {}]",
                    l.low, l.high
                ));
            }
        }
    }
    for (i, w) in frames.windows(2).enumerate() {
        for (ch, ((a, b), l)) in w[0].iter().zip(&w[1]).zip(limits).enumerate() {
            if let (Some(a), Some(b)) = (a, b)
                && (a - b).abs() > f64::from(l.max_step) + slack
            {
                bad.push(format!("output {} ch {ch}: step {a} -> {b}", i + 1));
            }
        }
    }
    bad
}

/// The native outputs of the puppet on `output` (idle off), each sent
/// through the back-end's encoder and decoded back to quarter units.
fn through(output: Output) -> Vec<Vec<Option<f64>>> {
    let region = variant(output, Idle::Off);
    let (session, _) = session(400);
    let native = native_outputs(&region, &session);
    let servos = {
        let r = marionette_core::region::Region::parse(&region);
        r.rig.unwrap().servos().to_vec()
    };
    let to_frames = |values: Vec<(usize, Option<f64>)>| -> Vec<Vec<Option<f64>>> {
        values
            .chunks(16)
            .map(|c| c.iter().map(|v| v.1).collect())
            .collect()
    };
    match output {
        Output::Maestro { .. } | Output::Dynamixel { .. } | Output::Feetech { .. } => {
            let mut out = UartServos {
                uart: Uart(Vec::new()),
                serial: Serial::for_output(&output, &servos).unwrap(),
            };
            let mut frames = Vec::new();
            for f in &native {
                out.uart.0.clear();
                out.write(f).unwrap();
                frames.push(decode_uart(&output, &out.uart.0));
            }
            frames
        }
        Output::Pca9685 { freq_hz, .. } => {
            let mut out = Pca9685::new(Bus::default(), 0x40, u32::from(freq_hz)).unwrap();
            out.init(&mut NoDelay).unwrap();
            let tick_q = f64::from(out.prescale() + 1) / 25.0 * 4.0;
            for f in &native {
                out.write(f).unwrap();
            }
            let writes = out.release().0;
            let mut values = Vec::new();
            for burst in &writes[5..] {
                assert_eq!((burst[0], burst.len()), (0x06, 65), "one burst per frame");
                for (ch, c) in burst[1..].chunks(4).take(16).enumerate() {
                    let off = u16::from_le_bytes([c[2], c[3]]);
                    let v = (off & 0x1000 == 0).then(|| f64::from(off & 0x0FFF) * tick_q);
                    values.push((ch, v));
                }
            }
            to_frames(values)
        }
        Output::Pwm { .. } => {
            let mut out = Pwm::new(
                core::array::from_fn::<_, 16, _>(|_| Channel(Vec::new())),
                50,
            )
            .unwrap();
            for f in &native {
                out.write(f).unwrap();
            }
            let channels = out.release();
            (0..native.len())
                .map(|i| {
                    channels
                        .iter()
                        .map(|c| {
                            let d = c.0[i];
                            // 0.5 µs ticks: 2 quarter-µs each.
                            (d != 0).then(|| f64::from(d) * 2.0)
                        })
                        .collect()
                })
                .collect()
        }
    }
}

/// One frame of UART bytes as quarter units by channel (`None`: no pulse,
/// or no position in this frame).
fn decode_uart(output: &Output, bytes: &[u8]) -> Vec<Option<f64>> {
    let mut frame = vec![None; 16];
    let positions = match output {
        Output::Maestro { .. } => {
            for (ch, t) in decode_maestro(bytes) {
                frame[usize::from(ch)] = (t != 0).then_some(f64::from(t));
            }
            return frame;
        }
        Output::Dynamixel { .. } => decode_dynamixel(bytes),
        Output::Feetech { series, .. } => decode_feetech(bytes, *series == FeetechSeries::Scs),
        _ => unreachable!(),
    };
    let goal = positions
        .iter()
        .filter(|w| w.address == 116 || w.address == 42);
    for w in goal {
        for &(id, p) in &w.items {
            frame[usize::from(id - 1)] = Some(f64::from(p) * 4.0);
        }
    }
    frame
}

struct NoDelay;

impl embedded_hal::delay::DelayNs for NoDelay {
    fn delay_ns(&mut self, _: u32) {}
}

#[test]
fn every_back_end_keeps_the_slew_and_limit_guarantees() {
    let limits = limits(&humanoid16());
    let kinds = [
        (Output::Maestro { baud: 115_200 }, 0.0),
        // Whole positions: ±2 quarter units of rounding each way.
        (Output::Dynamixel { baud: 1_000_000 }, 4.0),
        (
            Output::Feetech {
                baud: 1_000_000,
                series: FeetechSeries::Sts,
            },
            4.0,
        ),
        // 50 Hz: a PCA9685 tick is 122 / 25 MHz = 4.88 µs = 19.5 quarter-µs.
        (
            Output::Pca9685 {
                i2c_addr: 0x40,
                freq_hz: 50,
            },
            19.6,
        ),
        // 0.5 µs timer ticks.
        (Output::Pwm { freq_hz: 50 }, 2.0),
    ];
    for (output, slack) in kinds {
        let frames = through(output);
        assert!(frames.len() > 400, "{output:?}");
        let moving = frames.windows(2).any(|w| w[0] != w[1]);
        assert!(moving, "{output:?}: the figure moved");
        let bad = check(&frames, &limits, slack);
        assert!(bad.is_empty(), "{output:?}:\n{}", bad.join("\n"));
        // The release at the end: every output off.
        assert!(
            frames.last().unwrap().iter().all(Option::is_none),
            "{output:?}: idle off releases every servo"
        );
    }
    // The boards: the emulated one drives the UART back-ends only.
    for output in [
        Output::Maestro { baud: 115_200 },
        Output::Dynamixel { baud: 57_600 },
    ] {
        assert_eq!(Support::EMULATED.check(&output, &[]), Ok(()));
    }
    assert!(
        Support::EMULATED
            .check(&Output::Pwm { freq_hz: 50 }, &[])
            .is_err()
    );
    assert_eq!(pca9685::FRAME_HZ_MAX, 400);
}
