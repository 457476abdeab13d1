//! Editing a take's input: trim, time-scale, smooth, cross-fade.
//!
//! An edit works on what the host sent: the tracker frames (decoded from
//! either framing, with their times) and the `Params` messages. The edited
//! input becomes a new session (`Hello`, `Arm`, the frames and parameters
//! in time order with fresh sequence numbers, `Disarm`), and the edited
//! take's outputs and replies are the native core's on it, from the same
//! table region (its source is `edit`): `replay --emulated` on the board
//! reproduces them bit for bit like any take.
//!
//! Times below are seconds from the take's first tracker frame.

use super::Take;
use super::filter::CriticallyDamped;
use crate::perform::{self, Framing, PerformError, Sent};
use glam::{Quat, Vec3};
use marionette_core::wire::{
    Command, CommandKind, Hello, List, MAX_PARAMS, Message, PROTOCOL_VERSION, Params, Sensor,
    TrackerFrame, compact,
};

/// A take's input, decoded.
#[derive(Clone, Debug, PartialEq)]
pub struct Input {
    /// Tracker frames, in time order.
    pub frames: Vec<TrackerFrame>,
    /// `Params` values with their times.
    pub params: Vec<(u32, Vec<f32>)>,
    /// Whether the frames went compact.
    pub framing: Framing,
}

/// Why an edit failed.
#[derive(Debug, thiserror::Error)]
pub enum EditError {
    /// The take holds no tracker frame.
    #[error("the take has no tracker frames")]
    NoFrames,
    /// A bad edit argument.
    #[error("{0}")]
    Argument(String),
    /// Rebuilding the session failed.
    #[error(transparent)]
    Perform(#[from] PerformError),
}

/// A tracker frame from a compact one, at `time_us` (the event's full time).
fn unpack(c: &marionette_core::wire::CompactFrame, seq: u32, time_us: u32) -> TrackerFrame {
    let mut sensors = List::new();
    for packed in &c.sensors {
        if let Ok(s) = compact::unpack_sensor(packed) {
            let q = s.rotation();
            let _ = sensors.push(Sensor {
                id: s.id(),
                position: s.position().to_array(),
                rotation: [q.w, q.x, q.y, q.z],
            });
        }
    }
    TrackerFrame {
        seq,
        time_us,
        sensors,
    }
}

impl Input {
    /// The input of a take.
    #[must_use]
    pub fn of(take: &Take) -> Self {
        let mut out = Self {
            frames: Vec::new(),
            params: Vec::new(),
            framing: Framing::F32,
        };
        for sent in take.session() {
            for m in perform::decode_replies(&sent.bytes) {
                match m {
                    Message::TrackerFrame(f) => out.frames.push(f),
                    Message::CompactFrame(c) => {
                        out.framing = Framing::Compact;
                        out.frames.push(unpack(&c, 0, sent.time_us));
                    }
                    Message::Params(p) => out
                        .params
                        .push((sent.time_us, p.values.as_slice().to_vec())),
                    _ => {}
                }
            }
        }
        out
    }

    fn first(&self) -> Result<u32, EditError> {
        self.frames
            .first()
            .map(|f| f.time_us)
            .ok_or(EditError::NoFrames)
    }

    /// Keeps what lies within `[from, to]` s; the first frame kept takes
    /// the take's first time.
    pub fn trim(&mut self, from: f64, to: f64) -> Result<(), EditError> {
        if !(from >= 0.0 && to > from) {
            return Err(EditError::Argument(format!(
                "--trim {from},{to}: need 0 <= from < to"
            )));
        }
        let first = self.first()?;
        let rel = |t: u32| f64::from(t.wrapping_sub(first)) / 1e6;
        let keep = |t: u32| (from..=to).contains(&rel(t));
        let shift = (from * 1e6).round() as u32;
        let moved = |t: u32| t.wrapping_sub(shift);
        self.frames.retain(|f| keep(f.time_us));
        self.params.retain(|p| keep(p.0));
        for f in &mut self.frames {
            f.time_us = moved(f.time_us);
        }
        for p in &mut self.params {
            p.0 = moved(p.0);
        }
        if self.frames.is_empty() {
            return Err(EditError::NoFrames);
        }
        Ok(())
    }

    /// Multiplies every time (from the first frame) by `factor`: 2 plays
    /// twice as slowly.
    pub fn scale(&mut self, factor: f64) -> Result<(), EditError> {
        if !(factor.is_finite() && factor > 0.0) {
            return Err(EditError::Argument(format!(
                "--time-scale {factor}: must be a positive number"
            )));
        }
        let first = self.first()?;
        let at =
            |t: u32| first.wrapping_add((f64::from(t.wrapping_sub(first)) * factor).round() as u32);
        for f in &mut self.frames {
            f.time_us = at(f.time_us);
        }
        for p in &mut self.params {
            p.0 = at(p.0);
        }
        // Two frames that landed on one microsecond: keep the later.
        self.frames.dedup_by(|b, a| {
            a.time_us == b.time_us && {
                *a = *b;
                true
            }
        });
        Ok(())
    }

    /// Smooths sensor `id`'s position and orientation (the orientation's
    /// components, kept on one hemisphere, then renormalized) with the
    /// critically damped filter at `hz` ([`super::filter`]).
    pub fn smooth_sensor(&mut self, id: u8, hz: f64) -> Result<(), EditError> {
        check_hz(hz)?;
        let mut filters = [CriticallyDamped::new(hz); 7];
        let mut last: Option<Quat> = None;
        let mut found = false;
        for f in &mut self.frames {
            let t = f64::from(f.time_us) / 1e6;
            let mut sensors = f.sensors.as_slice().to_vec();
            for s in sensors.iter_mut().filter(|s| s.id == id) {
                found = true;
                let [w, x, y, z] = s.rotation;
                let mut q = Quat::from_xyzw(x, y, z, w);
                if last.is_some_and(|l| l.dot(q) < 0.0) {
                    q = -q;
                }
                last = Some(q);
                let v = [
                    s.position[0],
                    s.position[1],
                    s.position[2],
                    q.w,
                    q.x,
                    q.y,
                    q.z,
                ];
                let o: Vec<f32> = filters
                    .iter_mut()
                    .zip(v)
                    .map(|(flt, u)| flt.step(t, f64::from(u)) as f32)
                    .collect();
                s.position = [o[0], o[1], o[2]];
                let q = Quat::from_xyzw(o[4], o[5], o[6], o[3]).normalize();
                s.rotation = [q.w, q.x, q.y, q.z];
            }
            f.sensors = List::from_slice(&sensors).unwrap_or_default();
        }
        if found {
            Ok(())
        } else {
            Err(EditError::Argument(format!(
                "--smooth-sensor {id}: no such sensor in the take"
            )))
        }
    }

    /// Smooths parameter `index` of the `Params` messages.
    pub fn smooth_param(&mut self, index: usize, hz: f64) -> Result<(), EditError> {
        check_hz(hz)?;
        let mut filter = CriticallyDamped::new(hz);
        let mut found = false;
        for (t, values) in &mut self.params {
            if let Some(v) = values.get_mut(index) {
                found = true;
                *v = filter.step(f64::from(*t) / 1e6, f64::from(*v)) as f32;
            }
        }
        if found {
            Ok(())
        } else {
            Err(EditError::Argument(format!(
                "--smooth-param {index}: the take sends no such parameter"
            )))
        }
    }

    /// Cross-fades into `other` at `at` s over `window` s: this input
    /// until `at`; then `other`'s frames, its first at `at`; within the
    /// window each sensor both have is blended from this one's (its last
    /// frame at or before that time) to `other`'s, the weight rising
    /// linearly from 0 to 1 (positions interpolated, orientations
    /// normalized-linear on one hemisphere). Parameters switch at `at`.
    pub fn crossfade(&mut self, other: &Self, at: f64, window: f64) -> Result<(), EditError> {
        if !(at >= 0.0 && window >= 0.0 && window.is_finite()) {
            return Err(EditError::Argument(format!(
                "--crossfade at {at} over {window}: need at >= 0, window >= 0"
            )));
        }
        let first = self.first()?;
        let other_first = other.first()?;
        let start = first.wrapping_add((at * 1e6).round() as u32);
        let moved = |t: u32| start.wrapping_add(t.wrapping_sub(other_first));
        let rel = |t: u32| f64::from(t.wrapping_sub(first)) / 1e6;
        let mine: Vec<TrackerFrame> = self.frames.clone();
        let before = |t: u32| {
            mine.iter()
                .take_while(|f| rel(f.time_us) <= rel(t))
                .last()
                .copied()
        };
        self.frames.retain(|f| rel(f.time_us) < at);
        self.params.retain(|p| rel(p.0) < at);
        for f in &other.frames {
            let mut g = *f;
            g.time_us = moved(f.time_us);
            let w = if window > 0.0 {
                ((rel(g.time_us) - at) / window).clamp(0.0, 1.0) as f32
            } else {
                1.0
            };
            if w < 1.0
                && let Some(a) = before(g.time_us)
            {
                let blended: Vec<Sensor> = g
                    .sensors
                    .iter()
                    .map(|s| {
                        a.sensors
                            .iter()
                            .find(|x| x.id == s.id)
                            .map_or(*s, |sa| blend(sa, s, w))
                    })
                    .collect();
                g.sensors = List::from_slice(&blended).unwrap_or_default();
            }
            self.frames.push(g);
        }
        self.params
            .extend(other.params.iter().map(|(t, v)| (moved(*t), v.clone())));
        Ok(())
    }

    /// The session of this input (see the module doc).
    pub fn session(&self) -> Result<Vec<Sent>, EditError> {
        let mut timed: Vec<(u32, Message)> = Vec::new();
        for f in &self.frames {
            timed.push((f.time_us, Message::TrackerFrame(*f)));
        }
        for (t, v) in &self.params {
            let mut values = List::<f32, MAX_PARAMS>::new();
            for x in v.iter().take(MAX_PARAMS) {
                let _ = values.push(*x);
            }
            timed.push((*t, Message::Params(Params { seq: 0, values })));
        }
        let first = self.first()?;
        timed.sort_by_key(|(t, _)| t.wrapping_sub(first));
        let mut out = vec![
            Sent {
                time_us: first,
                bytes: perform::encode(&Message::Hello(Hello {
                    protocol_version: PROTOCOL_VERSION,
                }))?,
            },
            Sent {
                time_us: first,
                bytes: perform::frame_bytes(&Message::Command(Command {
                    seq: 0,
                    kind: CommandKind::Arm,
                }))?,
            },
        ];
        let mut seq = 0u32;
        for (t, mut m) in timed {
            seq = seq.wrapping_add(1);
            match &mut m {
                Message::TrackerFrame(f) => {
                    f.seq = seq;
                    m = perform::tracker_message(f, self.framing);
                }
                Message::Params(p) => p.seq = seq,
                _ => {}
            }
            out.push(Sent {
                time_us: t,
                bytes: perform::frame_bytes(&m)?,
            });
        }
        let last = out.last().map_or(first, |s| s.time_us);
        out.push(Sent {
            time_us: last,
            bytes: perform::frame_bytes(&Message::Command(Command {
                seq: seq.wrapping_add(1),
                kind: CommandKind::Disarm,
            }))?,
        });
        Ok(out)
    }

    /// The take of this input on `region`: the native core's outputs and
    /// replies (source `edit`).
    pub fn take(&self, region: &[u8]) -> Result<Take, EditError> {
        let session = self.session()?;
        let run = perform::simulate(region, &session)?;
        Ok(Take::of_run("edit", region, &session, &run)?)
    }
}

fn check_hz(hz: f64) -> Result<(), EditError> {
    if hz.is_finite() && hz > 0.0 {
        Ok(())
    } else {
        Err(EditError::Argument(format!(
            "smoothing at {hz} Hz: must be a positive number"
        )))
    }
}

/// `a` blended towards `b` by `w` (0: `a`, 1: `b`).
fn blend(a: &Sensor, b: &Sensor, w: f32) -> Sensor {
    let pa = Vec3::from(a.position);
    let pb = Vec3::from(b.position);
    let quat = |r: [f32; 4]| Quat::from_xyzw(r[1], r[2], r[3], r[0]);
    let qa = quat(a.rotation);
    let mut qb = quat(b.rotation);
    if qa.dot(qb) < 0.0 {
        qb = -qb;
    }
    let q = (qa * (1.0 - w) + qb * w).normalize();
    Sensor {
        id: b.id,
        position: pa.lerp(pb, w).to_array(),
        rotation: [q.w, q.x, q.y, q.z],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(t: u32, x: f32) -> TrackerFrame {
        let mut sensors = List::new();
        sensors
            .push(Sensor {
                id: 0,
                position: [x, 1.0, 0.0],
                rotation: [1.0, 0.0, 0.0, 0.0],
            })
            .unwrap();
        TrackerFrame {
            seq: 0,
            time_us: t,
            sensors,
        }
    }

    fn input(times: &[u32], x: f32) -> Input {
        Input {
            frames: times.iter().map(|&t| frame(t, x)).collect(),
            params: vec![],
            framing: Framing::F32,
        }
    }

    #[test]
    fn trim_and_scale_move_times_as_worked_by_hand() {
        let mut i = input(&[1000, 2000, 3000, 4000, 5000], 0.0);
        i.trim(0.001, 0.003).unwrap();
        let times: Vec<u32> = i.frames.iter().map(|f| f.time_us).collect();
        assert_eq!(times, [1000, 2000, 3000]);
        i.scale(2.5).unwrap();
        let times: Vec<u32> = i.frames.iter().map(|f| f.time_us).collect();
        assert_eq!(times, [1000, 3500, 6000]);
        assert!(i.trim(0.5, 0.6).is_err());
    }

    #[test]
    fn a_crossfade_blends_linearly_over_its_window() {
        // A at x = 0 from 0 to 10 ms, B at x = 1; fade at 4 ms over 4 ms.
        let mut a = input(&(0..=10).map(|k| k * 1000).collect::<Vec<_>>(), 0.0);
        let b = input(
            &(0..=10).map(|k| 100_000 + k * 1000).collect::<Vec<_>>(),
            1.0,
        );
        a.crossfade(&b, 0.004, 0.004).unwrap();
        let xs: Vec<(u32, f32)> = a
            .frames
            .iter()
            .map(|f| (f.time_us, f.sensors.as_slice()[0].position[0]))
            .collect();
        let expected: Vec<(u32, f32)> = (0..4)
            .map(|k| (k * 1000, 0.0))
            .chain((0..=10).map(|k| (4000 + k * 1000, (k as f32 / 4.0).min(1.0))))
            .collect();
        assert_eq!(xs, expected);
    }
}
