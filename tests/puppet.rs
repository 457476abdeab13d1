//! The puppet used by the live-loop tests (`perform.rs`, `faults.rs`): the
//! shipped `rigs/humanoid16.toml`, a rest-pose table, a synthetic tracker
//! recording, and the servo limits read straight from the rig file, so that
//! the tests check the board's output against numbers the loop did not
//! compute.

use glam::{DQuat, DVec3};
use marionette_host::import::csv::TrackerSample;
use marionette_host::perform;
use marionette_host::rigfile::{self, RigFile};
use std::path::PathBuf;

/// The repository root.
#[must_use]
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The shipped 16-servo puppet.
///
/// # Panics
/// If the shipped rig file does not load (a test failure).
#[must_use]
pub fn humanoid16() -> RigFile {
    rigfile::load(&repo().join("rigs/humanoid16.toml")).expect("rigs/humanoid16.toml loads")
}

/// A 2×2×2 grid over the hand parameters, every sample the rest pose: a
/// table that arms the board and leaves the visible work to the solver.
///
/// # Panics
/// If the table cannot be built (a test failure).
#[must_use]
pub fn rest_table(rig: &RigFile) -> Vec<u8> {
    let axes = [
        ("hand_x", -1.0, 2.0, 2),
        ("hand_y", -1.0, 2.0, 2),
        ("hand_z", -1.0, 2.0, 2),
    ];
    perform::rest_grid(rig, &axes).expect("rest table builds")
}

/// The rig's blob, with the fail-safe time-out replaced when given.
///
/// # Panics
/// If the rig does not encode (a test failure).
#[must_use]
pub fn rig_blob(rig: &RigFile, failsafe_timeout_ms: Option<u32>) -> Vec<u8> {
    let mut desc = rig.desc();
    if let Some(t) = failsafe_timeout_ms {
        desc.failsafe_timeout_ms = t;
    }
    let mut buf = vec![0u8; marionette_core::rig::MAX_BLOB_LEN];
    let n = desc.to_blob(&mut buf).expect("rig encodes");
    buf.truncate(n);
    buf
}

/// One time step of the performer, at 1 kHz from `t = 1 s`: the right hand
/// (sensor 0) circling in front of the pelvis, once a second, shifted by
/// `offset`; sensor 1 (left hand) and sensor 2 (pelvis) still.
#[must_use]
pub fn step(i: u32, offset: DVec3) -> [TrackerSample; 3] {
    let t = f64::from(i) * 1e-3;
    let a = t * std::f64::consts::TAU;
    let at = |sensor, position| TrackerSample {
        time_us: 1_000_000 + u64::from(i) * 1000,
        sensor,
        position,
        orientation: DQuat::IDENTITY,
    };
    [
        at(
            0,
            DVec3::new(-0.3 + 0.1 * a.cos(), 0.25 + 0.1 * a.sin(), 0.3) + offset,
        ),
        at(1, DVec3::new(0.3, -0.2, 0.1)),
        at(2, DVec3::ZERO),
    ]
}

/// `frames` steps of the circling hand.
#[must_use]
pub fn recording(frames: u32) -> Vec<TrackerSample> {
    (0..frames).flat_map(|i| step(i, DVec3::ZERO)).collect()
}

/// One servo channel's limits in quarter-µs (the Maestro's units), from the
/// rig file's own numbers.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    /// Rest pulse.
    pub rest: u16,
    /// Lowest pulse.
    pub low: u16,
    /// Highest pulse.
    pub high: u16,
    /// Largest change in one frame period: the joint's top speed over one
    /// period, through the pulse-per-radian slope, rounded up.
    pub max_step: i32,
}

/// The limits of every channel (index = channel) of `rig`.
#[must_use]
pub fn limits(rig: &RigFile) -> Vec<Limits> {
    let desc = rig.desc();
    let period = f64::from(desc.frame_period_us) * 1e-6;
    let q = |us: f32| (f64::from(us) * 4.0).round() as u16;
    let mut out: Vec<(u8, Limits)> = desc
        .servos
        .iter()
        .map(|s| {
            let (lo, hi) = (
                s.pulse_min_us.min(s.pulse_max_us),
                s.pulse_min_us.max(s.pulse_max_us),
            );
            let slope = f64::from(hi - lo) * 4.0 / f64::from(s.angle_max - s.angle_min);
            let step = (f64::from(s.max_speed) * period * slope).ceil().max(1.0);
            let l = Limits {
                rest: q(s.rest_us),
                low: q(lo),
                high: q(hi),
                max_step: step as i32,
            };
            (s.channel, l)
        })
        .collect();
    out.sort_by_key(|(ch, _)| *ch);
    out.into_iter().map(|(_, l)| l).collect()
}

/// Checks a stream of output frames (quarter-µs by channel) against the
/// limits: every target within its pulse range, every step within one frame
/// period's speed limit. Returns the violations, described.
#[must_use]
pub fn violations(frames: &[Vec<u16>], limits: &[Limits]) -> Vec<String> {
    let mut out = Vec::new();
    for (i, f) in frames.iter().enumerate() {
        for (ch, (&t, l)) in f.iter().zip(limits).enumerate() {
            if !(l.low..=l.high).contains(&t) {
                out.push(format!(
                    "output {i}, channel {ch}: {t} outside [{}, {}]",
                    l.low, l.high
                ));
            }
        }
    }
    for (i, w) in frames.windows(2).enumerate() {
        for (ch, ((&a, &b), l)) in w[0].iter().zip(&w[1]).zip(limits).enumerate() {
            let step = (i32::from(a) - i32::from(b)).abs();
            if step > l.max_step {
                out.push(format!(
                    "output {}, channel {ch}: step {a} -> {b} beyond {}",
                    i + 1,
                    l.max_step
                ));
            }
        }
    }
    out
}
