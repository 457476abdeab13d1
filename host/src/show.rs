//! Building a show from takes (`marionette show build`): the servo
//! targets per rig frame, compressed per channel as keyframes joined by
//! straight lines within a stated error bound (the format and the decoder
//! are the core's [`marionette_core::show`]).
//!
//! 1. **Frames.** Each take's outputs (frame-driven and easing) are
//!    sampled at the rig's frame period from its first output to its last,
//!    each frame taking the newest output at or before its time (what the
//!    servo link holds). Takes follow one another. A take from a port holds
//!    only the targets its telemetry reported, every tenth frame
//!    ([`Take::curves`]): its frames are on the straight lines between them,
//!    and, when the show has such a take, every frame is then passed
//!    through its channel's slew limiter from rest (what a board can
//!    follow; the bound is against those).
//! 2. **Keys.** Per channel the rig drives, greedily: from a key at frame
//!    `s`, the next key is the furthest frame `e` (at most [`MAX_SPAN`]
//!    frames on) such that every frame between decodes, through the core's
//!    [`interpolate`], within the bound of its target; keys sit on the
//!    samples themselves, so a key decodes exactly.
//! 3. **Check.** The blob is parsed and every frame of every channel
//!    decoded with the core's player ([`Cursor`]); the worst error is
//!    reported and must be within the bound.

use crate::take::Take;
use marionette_core::crc::crc32;
use marionette_core::region::{self, Entry, EntryKind, Region};
use marionette_core::rig::Rig;
use marionette_core::servo::Slew;
use marionette_core::show::{self, Cursor, KEY_LEN, Show, interpolate};
use serde::Serialize;

/// The longest stretch between two keys, frames (bounds the encoder's work).
pub const MAX_SPAN: usize = 2048;

/// Why a show could not be built.
#[derive(Debug, thiserror::Error)]
pub enum ShowBuildError {
    /// No take, or a take without outputs.
    #[error("{0}")]
    Empty(String),
    /// Takes of different rigs.
    #[error("take {index} was performed with another rig or tables than take 0")]
    Region {
        /// The take's index.
        index: usize,
    },
    /// The take's region has no rig.
    #[error("take 0's table region holds no valid rig")]
    NoRig,
    /// Too large for the format.
    #[error("the show does not fit the format: {0}")]
    TooLarge(&'static str),
    /// The built show does not decode within its bound (a bug).
    #[error("the built show decodes {worst} quarter units from a target, over its bound {bound}")]
    Bound {
        /// The worst error.
        worst: u32,
        /// The bound.
        bound: u16,
    },
    /// The built blob was refused by the core's parser (a bug).
    #[error("the built show was refused: {0:?}")]
    Refused(show::ShowError),
}

/// What `show build` made.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// Frames in the show.
    pub frames: u32,
    /// Frame period, µs.
    pub period_us: u32,
    /// Seconds of show.
    pub seconds: f64,
    /// Channels in the blob, and of those the ones driven.
    pub channels: [u16; 2],
    /// Keys in all.
    pub keys: usize,
    /// The stated bound, quarter units.
    pub bound_quarter_us: u16,
    /// The worst decoded error found, quarter units.
    pub worst_quarter_us: u32,
    /// Raw size: every target of every frame as `u16`, bytes.
    pub raw_bytes: usize,
    /// The blob's size, bytes.
    pub show_bytes: usize,
    /// Loop, and play at boot.
    pub looping: bool,
    /// Whether it plays at boot.
    pub at_boot: bool,
}

/// The targets of each show frame (see the module doc), and the period.
pub fn frames(takes: &[Take]) -> Result<(Vec<Vec<u16>>, u32), ShowBuildError> {
    let first = takes
        .first()
        .ok_or_else(|| ShowBuildError::Empty("no take given".into()))?;
    let period = first.period_us.max(1);
    let mut out = Vec::new();
    for (index, take) in takes.iter().enumerate() {
        if take.region != first.region {
            return Err(ShowBuildError::Region { index });
        }
        let outputs = take.curves();
        let (Some(start), Some(end)) = (outputs.first(), outputs.last()) else {
            return Err(ShowBuildError::Empty(format!(
                "take {index} has no outputs"
            )));
        };
        let span = end.0.wrapping_sub(start.0);
        let reported = take.outputs().is_empty();
        let mut k = 0usize;
        let mut t = 0u32;
        while t <= span {
            while outputs
                .get(k + 1)
                .is_some_and(|o| o.0.wrapping_sub(start.0) <= t)
            {
                k += 1;
            }
            let held = outputs.get(k).map(|o| o.1.clone()).unwrap_or_default();
            out.push(match (reported, outputs.get(k), outputs.get(k + 1)) {
                (true, Some(a), Some(b)) => between(a, b, start.0.wrapping_add(t)),
                _ => held,
            });
            t = match t.checked_add(period) {
                Some(next) => next,
                None => break,
            };
        }
    }
    Ok((out, period))
}

/// The targets at time `t` on the straight line from `a` to `b` (times
/// and targets), rounded to the nearest.
fn between(a: &(u32, Vec<u16>), b: &(u32, Vec<u16>), t: u32) -> Vec<u16> {
    let span = f64::from(b.0.wrapping_sub(a.0).max(1));
    let w = f64::from(t.wrapping_sub(a.0)) / span;
    a.1.iter()
        .zip(&b.1)
        .map(|(&x, &y)| (f64::from(x) + w * (f64::from(y) - f64::from(x))).round() as u16)
        .collect()
}

/// `frames` as each channel's slew limiter (from rest) plays them: what a
/// board can follow.
fn followed(frames: &mut [Vec<u16>], limiters: &[Option<Slew>]) {
    let mut limiters = limiters.to_vec();
    for targets in frames {
        for (v, slew) in targets.iter_mut().zip(limiters.iter_mut()) {
            *v = played(slew, *v);
        }
    }
}

/// What a board makes of a decoded target: the channel's slew limiter
/// following it ([`Slew::track`], as the core's player does), or the
/// target itself.
fn played(slew: &mut Option<Slew>, target: u16) -> u16 {
    match slew {
        Some(s) => s.track(target),
        None => target,
    }
}

/// The keys of one channel's samples within `bound` (see the module doc),
/// as played through `slew` (the channel's limiter at the start of the
/// show; `None`: the decoded targets themselves).
#[must_use]
pub fn keys(samples: &[u16], bound: u16, slew: Option<Slew>) -> Vec<(u32, u16)> {
    let n = samples.len();
    let mut out = Vec::new();
    let Some(&v0) = samples.first() else {
        return out;
    };
    out.push((0u32, v0));
    let mut state = slew;
    played(&mut state, v0);
    let mut s = 0usize;
    while s + 1 < n {
        // The limiter after frames s + 1 ..= e of the segment s..e, if
        // every one of them is within the bound.
        let fits = |e: usize| {
            let (vs, ve) = (samples[s], samples[e]);
            let mut sim = state;
            (s + 1..=e)
                .all(|f| {
                    let d = interpolate(s as u32, vs, e as u32, ve, f as u32);
                    played(&mut sim, d).abs_diff(samples[f]) <= bound
                })
                .then_some(sim)
        };
        let mut e = s + 1;
        let mut next = fits(e);
        while e + 1 < n && e + 1 - s <= MAX_SPAN {
            match fits(e + 1) {
                Some(sim) => (e, next) = (e + 1, Some(sim)),
                None => break,
            }
        }
        state = next.unwrap_or_else(|| {
            // Not even the next frame is within the bound: keep it exact
            // (the check after encoding reports the error).
            let mut sim = state;
            played(&mut sim, samples[e]);
            sim
        });
        out.push((e as u32, samples[e]));
        s = e;
    }
    out
}

/// Each channel's slew limiter as a show starts on the rig (at rest,
/// still, with the limits for the frame period), as the core's player
/// has it.
#[must_use]
pub fn slews(rig: &Rig<'_>, channels: usize) -> Vec<Option<Slew>> {
    let period = rig.frame_period_s();
    let mut out = vec![None; channels];
    for servo in rig.servos() {
        if let Some(slot) = out.get_mut(usize::from(servo.channel)) {
            *slot = Some(Slew::for_channel(
                &servo.calibration(),
                servo.step_limits(period),
                servo.rest_us,
            ));
        }
    }
    out
}

/// The show blob of `frames` for the rig of hash `rig_hash`, driving the
/// channels with a limiter in `driven` (`Some`: as played through it; the
/// others get no keys).
pub fn encode(
    frames: &[Vec<u16>],
    driven: &[Option<Option<Slew>>],
    rig_hash: u64,
    period_us: u32,
    bound: u16,
    flags: u16,
) -> Result<Vec<u8>, ShowBuildError> {
    let channels = driven.len();
    let count = u32::try_from(frames.len()).map_err(|_| ShowBuildError::TooLarge("frames"))?;
    let mut out = Vec::new();
    out.extend_from_slice(&show::MAGIC);
    out.extend_from_slice(&show::VERSION.to_le_bytes());
    out.extend_from_slice(&flags.to_le_bytes());
    out.extend_from_slice(&rig_hash.to_le_bytes());
    out.extend_from_slice(&period_us.to_le_bytes());
    out.extend_from_slice(&count.to_le_bytes());
    let c = u16::try_from(channels).map_err(|_| ShowBuildError::TooLarge("channels"))?;
    out.extend_from_slice(&c.to_le_bytes());
    out.extend_from_slice(&bound.to_le_bytes());
    let per_channel: Vec<Vec<(u32, u16)>> = driven
        .iter()
        .enumerate()
        .map(|(ch, d)| match d {
            Some(slew) => {
                let samples: Vec<u16> = frames
                    .iter()
                    .map(|f| f.get(ch).copied().unwrap_or(0))
                    .collect();
                keys(&samples, bound, *slew)
            }
            None => Vec::new(),
        })
        .collect();
    for k in &per_channel {
        let n = u32::try_from(k.len()).map_err(|_| ShowBuildError::TooLarge("keys"))?;
        out.extend_from_slice(&n.to_le_bytes());
    }
    for k in per_channel.iter().flatten() {
        out.extend_from_slice(&k.0.to_le_bytes());
        out.extend_from_slice(&k.1.to_le_bytes());
    }
    let crc = crc32(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    Ok(out)
}

/// The worst error of a show against `frames`, decoding each channel it
/// drives frame by frame with the core's player, through `slews` (each
/// channel's limiter at the start; `None`: the decoded targets).
pub fn worst_error(
    blob: &[u8],
    frames: &[Vec<u16>],
    slews: &[Option<Slew>],
) -> Result<u32, ShowBuildError> {
    let show = Show::parse(blob).map_err(ShowBuildError::Refused)?;
    let mut cursor = Cursor::default();
    let mut limiters = slews.to_vec();
    limiters.resize(usize::from(show.channels()), None);
    let mut worst = 0u32;
    for (f, targets) in frames.iter().enumerate() {
        let f = f as u32;
        for (ch, slew) in (0..show.channels()).zip(limiters.iter_mut()) {
            if let Some(v) = cursor.target(&show, ch, f) {
                let want = targets.get(usize::from(ch)).copied().unwrap_or(0);
                worst = worst.max(u32::from(played(slew, v).abs_diff(want)));
            }
        }
        cursor.played(f);
    }
    Ok(worst)
}

/// The region `region_bytes` with `show` as its show entry (replacing
/// any show it had): rig, tables and show, as a board flashes them.
pub fn with_show(region_bytes: &[u8], show: &[u8]) -> Result<Vec<u8>, ShowBuildError> {
    let dir = region::directory(region_bytes).map_err(|_| ShowBuildError::NoRig)?;
    let mut entries: Vec<Entry<'_>> = dir.iter().filter(|e| e.kind != EntryKind::SHOW).collect();
    entries.push(Entry::show(show));
    let len = region::len(&entries).map_err(|_| ShowBuildError::TooLarge("the region"))?;
    let mut out = vec![0u8; len];
    let n =
        region::write(&entries, &mut out).map_err(|_| ShowBuildError::TooLarge("the region"))?;
    out.truncate(n);
    Ok(out)
}

/// Builds the show of `takes` (see the module doc); returns the blob and
/// its report.
pub fn build(
    takes: &[Take],
    bound: u16,
    looping: bool,
    at_boot: bool,
) -> Result<(Vec<u8>, Report), ShowBuildError> {
    let (mut frames, period) = frames(takes)?;
    let region_bytes = &takes.first().ok_or(ShowBuildError::NoRig)?.region;
    let region = Region::parse(region_bytes);
    let rig = region.rig.as_ref().ok_or(ShowBuildError::NoRig)?;
    let channels = frames.first().map_or(0, Vec::len);
    let limiters = slews(rig, channels);
    if takes.iter().any(|t| t.outputs().is_empty()) {
        followed(&mut frames, &limiters);
    }
    let driven: Vec<Option<Option<Slew>>> = limiters.iter().map(|s| s.map(Some)).collect();
    let flags = if looping { show::LOOP } else { 0 } | if at_boot { show::AT_BOOT } else { 0 };
    let blob = encode(&frames, &driven, rig.rig_hash(), period, bound, flags)?;
    let worst = worst_error(&blob, &frames, &limiters)?;
    if worst > u32::from(bound) {
        return Err(ShowBuildError::Bound { worst, bound });
    }
    let keys = (blob.len() - show::HEADER_LEN - 4 - 4 * channels) / KEY_LEN;
    let report = Report {
        frames: frames.len() as u32,
        period_us: period,
        seconds: frames.len() as f64 * f64::from(period) / 1e6,
        channels: [channels as u16, driven.iter().flatten().count() as u16],
        keys,
        bound_quarter_us: bound,
        worst_quarter_us: worst,
        raw_bytes: frames.len() * channels * 2,
        show_bytes: blob.len(),
        looping,
        at_boot,
    };
    Ok((blob, report))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ramp_and_a_hold_take_three_keys() {
        // 0, 10, 20, …, 100 then held at 100 for 10 frames: exact with
        // keys at 0, 10 and 20.
        let samples: Vec<u16> = (0..=10).map(|k| k * 10).chain([100; 10]).collect();
        assert_eq!(keys(&samples, 0, None), vec![(0, 0), (10, 100), (20, 100)]);
    }

    #[test]
    fn decoding_never_exceeds_the_bound() {
        // A sampled sine plus a deterministic jitter (the input, not a
        // result), at several bounds.
        let samples: Vec<u16> = (0..3000u32)
            .map(|k| {
                let s = (f64::from(k) * 0.013).sin() * 2000.0 + 6000.0;
                let jitter = f64::from((k * 7919) % 13) - 6.0;
                (s + jitter) as u16
            })
            .collect();
        let frames: Vec<Vec<u16>> = samples.iter().map(|&v| vec![v, 6000]).collect();
        let mut size = 0;
        for bound in [0u16, 2, 4, 8, 16, 40] {
            let blob = encode(&frames, &[Some(None), None], 7, 1000, bound, 0).unwrap();
            let show = Show::parse(&blob).unwrap();
            for (f, &want) in samples.iter().enumerate() {
                let got = show.target(0, f as u32).unwrap();
                assert!(
                    got.abs_diff(want) <= bound,
                    "bound {bound}, frame {f}: {got} vs {want}"
                );
            }
            assert_eq!(show.target(1, 0), None, "an undriven channel");
            assert!(worst_error(&blob, &frames, &[]).unwrap() <= u32::from(bound));
            size = blob.len();
        }
        assert!(size < samples.len() * 2 / 4, "compresses: {size} bytes");
    }

    #[test]
    fn a_damaged_show_is_refused() {
        let frames: Vec<Vec<u16>> = (0..50u16).map(|k| vec![6000 + k * 3, 5000]).collect();
        let blob = encode(&frames, &[Some(None), Some(None)], 9, 1000, 2, show::LOOP).unwrap();
        assert!(Show::parse(&blob).is_ok());
        for cut in 0..blob.len() {
            assert!(Show::parse(&blob[..cut]).is_err(), "cut at {cut}");
        }
        for i in 0..blob.len() {
            for bit in 0..8 {
                let mut b = blob.clone();
                b[i] ^= 1 << bit;
                assert!(Show::parse(&b).is_err(), "byte {i} bit {bit}");
            }
        }
        let show = Show::parse(&blob).unwrap();
        assert_eq!(
            show::check_rig(&show, 10),
            Err(show::ShowError::RigMismatch)
        );
    }
}
