//! Servo outputs against independent references.
//!
//! - PWM duty cycles and PCA9685 counts against `f64` evaluations of the
//!   datasheet formulas, over every quarter-µs target.
//! - PCA9685 prescales against a brute-force search for the closest period.
//! - The bytes each back-end puts on its bus, decoded here from the PCA9685
//!   register map and the Maestro manual (Set Target through the lead's
//!   `servo::maestro::decode_set_target`, Set Multiple Targets by hand), and
//!   the bus servos' packets from the Dynamixel Protocol 2.0 and Feetech
//!   manuals.
//! - Decimation against the UART's capacity: a decimated Maestro never queues
//!   more bytes than the line can carry.

use std::convert::Infallible;

use embedded_hal::delay::DelayNs;
use embedded_hal::i2c::{ErrorType, I2c, Operation};
use embedded_hal::pwm::SetDutyCycle;
use marionette_core::output::maestro::{self, Command};
use marionette_core::output::pca9685::{self, OSCILLATOR_HZ};
use marionette_core::output::pwm::{self, Pwm};
use marionette_core::output::{
    Decimated, FRAME_HZ_MAX, FRAME_HZ_MIN, Maestro, OutputError, Pca9685, ServoOutput,
    frames_per_write,
};
use marionette_core::servo::maestro::decode_set_target;

// ---------------------------------------------------------------- fakes

/// A PWM channel that records every duty it is given.
struct Channel {
    max: u16,
    duties: Vec<u16>,
}

impl embedded_hal::pwm::ErrorType for Channel {
    type Error = Infallible;
}

impl SetDutyCycle for Channel {
    fn max_duty_cycle(&self) -> u16 {
        self.max
    }
    fn set_duty_cycle(&mut self, duty: u16) -> Result<(), Infallible> {
        assert!(duty <= self.max, "duty {duty} above max {}", self.max);
        self.duties.push(duty);
        Ok(())
    }
}

/// An I2C bus that records every write as (address, bytes).
#[derive(Default)]
struct Bus {
    writes: Vec<(u8, Vec<u8>)>,
}

impl ErrorType for Bus {
    type Error = Infallible;
}

impl I2c for Bus {
    fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Infallible> {
        for op in operations {
            match op {
                Operation::Write(bytes) => self.writes.push((address, bytes.to_vec())),
                Operation::Read(_) => panic!("the output never reads"),
            }
        }
        Ok(())
    }
}

struct NoDelay;

impl DelayNs for NoDelay {
    fn delay_ns(&mut self, _ns: u32) {}
}

/// A UART that takes at most `chunk` bytes per call.
struct Uart {
    sent: Vec<u8>,
    chunk: usize,
}

impl embedded_io::ErrorType for Uart {
    type Error = Infallible;
}

impl embedded_io::Write for Uart {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        let n = buf.len().min(self.chunk);
        self.sent.extend_from_slice(&buf[..n]);
        Ok(n)
    }
    fn flush(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}

/// A deterministic generator for test inputs.
fn lcg(state: &mut u32) -> u32 {
    *state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
    *state >> 8
}

// ---------------------------------------------------------------- PWM

/// duty = pulse_us / period_us · max, rounded half up, at most max.
fn duty_ref(q: u16, hz: u32, max: u16) -> u16 {
    let pulse_us = f64::from(q) / 4.0;
    let period_us = 1e6 / f64::from(hz);
    // The exact quotient is a multiple of 1/4e6 away from any .5 unless it is
    // one: evaluate it as one division of an exact integer product.
    let exact = f64::from(q) * f64::from(hz) * f64::from(max) / 4e6;
    assert!((exact - pulse_us / period_us * f64::from(max)).abs() < 1e-6);
    ((exact + 0.5).floor()).min(f64::from(max)) as u16
}

#[test]
fn pwm_duty_matches_the_f64_formula_for_every_target() {
    for (hz, max) in [
        (50, 20_000),
        (50, u16::MAX),
        (60, 4095),
        (200, 1000),
        (333, 1000),
        (333, u16::MAX),
        (100, 1),
    ] {
        for q in 0..=u16::MAX {
            assert_eq!(
                pwm::duty(q, hz, max),
                duty_ref(q, hz, max),
                "{q} q at {hz} Hz of {max}"
            );
        }
    }
}

#[test]
fn pwm_frames_reach_each_channel_and_leave_the_rest() {
    let ch = |max| Channel {
        max,
        duties: Vec::new(),
    };
    let mut out = Pwm::new([ch(20_000), ch(u16::MAX), ch(1000)], 50).unwrap();
    out.write(&[6000, 4000, 8000]).unwrap();
    out.write(&[4400]).unwrap();
    let [a, b, c] = out.release();
    // 1500 µs of 20 000 -> 1500; 1000 µs of 65535 -> 3276.75 -> 3277;
    // 2000 µs of 1000 -> 100; then 1100 µs of 20 000 -> 1100.
    assert_eq!(a.duties, [1500, 1100]);
    assert_eq!(b.duties, [3277]);
    assert_eq!(c.duties, [100]);
}

#[test]
fn pwm_accepts_exactly_50_to_333_hz() {
    for hz in 0..2000 {
        let ok = Pwm::new(
            [Channel {
                max: 1,
                duties: Vec::new(),
            }],
            hz,
        )
        .is_ok();
        assert_eq!(ok, (FRAME_HZ_MIN..=FRAME_HZ_MAX).contains(&hz), "{hz} Hz");
    }
}

// ---------------------------------------------------------------- PCA9685

#[test]
fn prescale_gives_the_closest_period_for_every_frame_rate() {
    for osc in [OSCILLATOR_HZ, 26_000_000, 24_000_000] {
        for hz in FRAME_HZ_MIN..=FRAME_HZ_MAX {
            let p = pca9685::prescale(osc, hz).unwrap();
            // Datasheet equation 1 in f64.
            let formula = (f64::from(osc) / (4096.0 * f64::from(hz))).round() - 1.0;
            assert_eq!(f64::from(p), formula, "{osc} Hz osc, {hz} Hz");
            // No other legal prescale gives a period closer to 1/hz.
            let err =
                |p: u32| (f64::from(4096 * (p + 1)) / f64::from(osc) - 1.0 / f64::from(hz)).abs();
            let best = (3..=255)
                .min_by(|&a, &b| err(a).total_cmp(&err(b)))
                .unwrap();
            assert_eq!(u32::from(p), best, "{osc} Hz osc, {hz} Hz");
        }
    }
}

#[test]
fn counts_match_the_f64_tick_length_for_every_target() {
    for (osc, p) in [
        (OSCILLATOR_HZ, 121),
        (OSCILLATOR_HZ, 30),
        (OSCILLATOR_HZ, 17),
        (26_500_000, 3),
    ] {
        let tick_us = f64::from(p + 1) / f64::from(osc) * 1e6;
        for q in 0..=u16::MAX {
            let want = (f64::from(q) / 4.0 / tick_us).round().min(4095.0) as u16;
            assert_eq!(pca9685::counts(q, osc, p), want, "{q} q, prescale {p}");
        }
    }
}

/// Decodes one auto-increment burst from LED0_ON_L (register 0x06, then
/// LEDn_ON_L, _ON_H, _OFF_L, _OFF_H for n = 0..16, datasheet §7.3) into
/// (on, off, full_off) per channel.
fn decode_burst(bytes: &[u8]) -> Vec<(u16, u16, bool)> {
    assert_eq!(bytes[0], 0x06, "a burst starts at LED0_ON_L");
    assert_eq!(bytes.len(), 1 + 16 * 4, "all 16 channels in one burst");
    bytes[1..]
        .chunks_exact(4)
        .map(|c| {
            let on = u16::from_le_bytes([c[0], c[1]]);
            let off = u16::from_le_bytes([c[2], c[3]]);
            (on, off & 0x0FFF, off & 0x1000 != 0)
        })
        .collect()
}

#[test]
fn pca9685_frames_decode_back_to_their_pulses() {
    let mut out = Pca9685::new(Bus::default(), 0x55, 60).unwrap();
    out.init(&mut NoDelay).unwrap();
    let p = out.prescale();
    // 25e6 / (4096 · 60) = 101.7 -> 101.
    assert_eq!(p, 101);
    let tick_us = f64::from(p + 1) / 25.0;
    let mut seed = 1;
    let mut frames = Vec::new();
    for _ in 0..50 {
        let n = 1 + (lcg(&mut seed) % 16) as usize;
        let frame: Vec<u16> = (0..n)
            .map(|_| match lcg(&mut seed) % 8 {
                0 => 0,
                _ => 2000 + (lcg(&mut seed) % 10_000) as u16,
            })
            .collect();
        out.write(&frame).unwrap();
        frames.push(frame);
    }
    let writes = out.release().writes;
    assert!(writes.iter().all(|(a, _)| *a == 0x55));
    // init: sleep, prescale, auto-increment, all outputs off, wake.
    assert_eq!(writes[0].1, [0x00, 0x11]);
    assert_eq!(writes[1].1, [0xFE, 101]);
    assert_eq!(writes[2].1, [0x00, 0x31]);
    assert_eq!(writes[3].1, [0xFC, 0x00, 0x10]);
    assert_eq!(writes[4].1, [0x00, 0x21]);
    // Then exactly one burst per frame.
    assert_eq!(writes.len(), 5 + frames.len());
    for (frame, (_, burst)) in frames.iter().zip(&writes[5..]) {
        for (i, (on, off, full_off)) in decode_burst(burst).into_iter().enumerate() {
            let q = frame.get(i).copied().unwrap_or(0);
            if q == 0 {
                assert!(full_off, "target 0 (or no target) switches channel {i} off");
            } else {
                assert!(!full_off);
                assert_eq!(on, 0);
                let pulse_us = f64::from(off) * tick_us;
                assert!(
                    (pulse_us - f64::from(q) / 4.0).abs() <= tick_us / 2.0 + 1e-9,
                    "{q} q -> {off} ticks"
                );
            }
        }
    }
}

#[test]
fn pca9685_rejects_what_it_cannot_drive() {
    let mut out = Pca9685::new(Bus::default(), 0x40, 50).unwrap();
    out.init(&mut NoDelay).unwrap();
    assert_eq!(
        out.write(&[6000; 17]),
        Err(OutputError::TooManyTargets {
            given: 17,
            channels: 16
        })
    );
    // Nothing beyond init reached the bus.
    assert_eq!(out.release().writes.len(), 5);
    assert!(Pca9685::new(Bus::default(), 0x40, 49).is_err());
    assert!(Pca9685::new(Bus::default(), 0x40, 400).is_ok());
    assert!(Pca9685::new(Bus::default(), 0x40, 401).is_err());
    assert!(Pca9685::new(Bus::default(), 0x70, 50).is_err());
}

// ---------------------------------------------------------------- Maestro

/// Decodes a stream of compact-protocol commands into per-frame targets.
fn decode_maestro(bytes: &[u8], command: Command) -> Vec<(u8, u16)> {
    let mut out = Vec::new();
    match command {
        Command::SetTarget => {
            assert_eq!(bytes.len() % 4, 0);
            for c in bytes.chunks(4) {
                out.push(decode_set_target([c[0], c[1], c[2], c[3]]).expect("a Set Target"));
            }
        }
        Command::SetMultipleTargets => {
            let mut rest = bytes;
            while !rest.is_empty() {
                assert_eq!(rest[0], 0x9F);
                let (count, first) = (rest[1], rest[2]);
                for k in 0..count {
                    let (lo, hi) = (rest[3 + 2 * k as usize], rest[4 + 2 * k as usize]);
                    assert!(lo < 0x80 && hi < 0x80, "7-bit data bytes");
                    out.push((first + k, u16::from(lo) | u16::from(hi) << 7));
                }
                rest = &rest[3 + 2 * count as usize..];
            }
        }
    }
    out
}

#[test]
fn maestro_frames_decode_back_to_their_targets() {
    for command in [Command::SetTarget, Command::SetMultipleTargets] {
        for chunk in [1, 5, 1000] {
            let mut out = Maestro::new(
                Uart {
                    sent: Vec::new(),
                    chunk,
                },
                command,
            );
            let mut seed = 9;
            let mut want = Vec::new();
            for _ in 0..40 {
                let n = 1 + (lcg(&mut seed) % 24) as usize;
                let frame: Vec<u16> = (0..n).map(|_| (lcg(&mut seed) & 0xFFFF) as u16).collect();
                out.write(&frame).unwrap();
                // Channel i; targets above 14 bits clamp to 0x3FFF.
                want.extend(
                    frame
                        .iter()
                        .enumerate()
                        .map(|(i, &t)| (i as u8, t.min(0x3FFF))),
                );
            }
            let sent = out.release().sent;
            assert_eq!(
                decode_maestro(&sent, command),
                want,
                "{command:?}, chunk {chunk}"
            );
        }
    }
}

#[test]
fn decimated_maestro_never_outruns_its_uart() {
    let loop_hz = 1000u32;
    for baud in [9600u32, 38_400, 57_600, 115_200, 250_000] {
        for command in [Command::SetTarget, Command::SetMultipleTargets] {
            for n in 1..=24usize {
                let bytes = maestro::frame_bytes(n, command);
                let every = frames_per_write(loop_hz, maestro::frame_time_us(bytes, baud));
                // Writes `every` loop periods apart must fit the frame's bits:
                // every / loop_hz ≥ bytes · 10 / baud, and one fewer must not.
                let bits = 10 * bytes as u64;
                assert!(u64::from(every) * u64::from(baud) >= bits * u64::from(loop_hz));
                if every > 1 {
                    assert!(u64::from(every - 1) * u64::from(baud) < bits * u64::from(loop_hz));
                }
                // One second of the loop queues at most a second (plus the
                // frame in flight) of line time.
                let mut out = Decimated::new(
                    Maestro::new(
                        Uart {
                            sent: Vec::new(),
                            chunk: 64,
                        },
                        command,
                    ),
                    every,
                );
                for _ in 0..loop_hz {
                    out.write(&vec![6000; n]).unwrap();
                }
                let sent = out.into_inner().release().sent.len() as u64;
                assert!(
                    sent * 10 <= u64::from(baud) + bits,
                    "{baud} baud {command:?} {n} ch"
                );
            }
        }
    }
    // The example: 16 channels at 115 200 baud take 5.6 ms.
    assert_eq!(maestro::frame_time_us(64, 115_200), 5556);
    assert_eq!(frames_per_write(1000, 5556), 6);
}
