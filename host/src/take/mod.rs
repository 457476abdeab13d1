//! Takes: one performance kept whole, to be looked at, replayed, edited and
//! built into a show (issue #17).
//!
//! A [`Take`] holds the table region the board performed from (rig and
//! tables, exactly as flashed) and a time-ordered list of [`Event`]s: every
//! wire message the host sent (tracker frames, parameters, commands), every
//! reply the board sent (status, acks, telemetry), and every set of servo
//! targets the board put on its servo link, each with its board-clock time.
//! A take from a board on a serial port ([`Take::of_port`]: `stream`,
//! `live --port`) holds what the host saw instead: the region it knows (the
//! rig, and the tables if given), the messages as written at the host's
//! times, the replies, and the servo targets the board reported in its
//! telemetry ([`EventKind::Reported`]; its servo link is not seen).
//! The format is specified in `docs/take.md` (versions 1 and [`VERSION`]
//! 2); [`Take::to_bytes`] writes it and [`Take::parse`] reads it back,
//! refusing a damaged file with the field and offset at fault.
//!
//! Times: a sent message carries the time it was (or is to be) sent; an
//! output carries the board clock of the step that produced it (the
//! tracker frame's time, or the tick's clock for easing); a reply carries
//! the time of the message it answers (its sequence number), or of the
//! last message sent before it.

pub mod edit;
pub mod export;
pub mod filter;

use crate::perform::{self, PerformError, Run, Sent};
use marionette_core::crc::crc32;
use marionette_core::region::Region;
use marionette_core::wire::Message;
use serde::Serialize;
use std::path::Path;

/// The take file's magic.
pub const MAGIC: [u8; 4] = *b"MTAK";
/// The newest take format version this host reads and writes: version 2
/// adds event kind 5 ([`EventKind::Reported`]). A take without such events
/// is written as version 1, byte for byte as before.
pub const VERSION: u16 = 2;
/// Bytes of the fixed header (magic .. region length).
pub const HEADER_LEN: usize = 16;
/// Bytes of one event's head (kind, time, length).
pub const EVENT_HEAD_LEN: usize = 7;

/// What an event is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EventKind {
    /// Kind 1: bytes the host sent on the tracker link (one wire frame,
    /// possibly after a `0x00` delimiter).
    Sent,
    /// Kind 2: one wire frame the board sent back.
    Reply,
    /// Kind 3: servo targets driven by a tracker frame.
    FrameOutput,
    /// Kind 4: servo targets of an easing step (rest, fail-safe, jog).
    RestOutput,
    /// Kind 5 (version 2): servo targets the board reported in a
    /// `Telemetry` (a take from a port, whose servo link is not seen), at
    /// the time of the tracker frame it reports.
    Reported,
}

impl EventKind {
    /// The kind's code in the file.
    #[must_use]
    pub const fn code(self) -> u8 {
        match self {
            Self::Sent => 1,
            Self::Reply => 2,
            Self::FrameOutput => 3,
            Self::RestOutput => 4,
            Self::Reported => 5,
        }
    }

    /// The kind of `code` in a take of format `version`.
    fn from_code(code: u8, version: u16) -> Option<Self> {
        match code {
            1 => Some(Self::Sent),
            2 => Some(Self::Reply),
            3 => Some(Self::FrameOutput),
            4 => Some(Self::RestOutput),
            5 if version >= 2 => Some(Self::Reported),
            _ => None,
        }
    }

    /// Whether the event is a set of servo targets (the board's, or
    /// reported).
    #[must_use]
    pub const fn is_output(self) -> bool {
        matches!(self, Self::FrameOutput | Self::RestOutput | Self::Reported)
    }

    /// Whether the event is a set of targets the board put on its servo
    /// link.
    #[must_use]
    pub const fn is_board_output(self) -> bool {
        matches!(self, Self::FrameOutput | Self::RestOutput)
    }
}

/// One timed event of a take.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Event {
    /// Board-clock time, µs.
    pub time_us: u32,
    /// What it is.
    pub kind: EventKind,
    /// Its bytes: wire bytes for `Sent` and `Reply`, the targets (`u16`
    /// little-endian by channel, quarter-µs or bus position × 4) for outputs.
    pub data: Vec<u8>,
}

impl Event {
    /// The servo targets of an output event (empty for the others).
    #[must_use]
    pub fn targets(&self) -> Vec<u16> {
        if !self.kind.is_output() {
            return Vec::new();
        }
        self.data
            .chunks_exact(2)
            .map(|c| u16::from_le_bytes([c[0], c[1]]))
            .collect()
    }

    /// The messages of a `Sent` or `Reply` event (empty for outputs).
    #[must_use]
    pub fn messages(&self) -> Vec<Message> {
        if self.kind.is_output() {
            return Vec::new();
        }
        perform::decode_replies(&self.data)
    }

    /// An output event of `targets`.
    #[must_use]
    pub fn output(time_us: u32, frame: bool, targets: &[u16]) -> Self {
        Self::targets_of(
            if frame {
                EventKind::FrameOutput
            } else {
                EventKind::RestOutput
            },
            time_us,
            targets,
        )
    }

    /// An event of `kind` holding `targets`.
    #[must_use]
    pub fn targets_of(kind: EventKind, time_us: u32, targets: &[u16]) -> Self {
        Self {
            time_us,
            kind,
            data: targets.iter().flat_map(|t| t.to_le_bytes()).collect(),
        }
    }
}

/// One recorded performance (see the module doc).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Take {
    /// Servo channels per output.
    pub channels: u16,
    /// The rig's frame period, µs.
    pub period_us: u32,
    /// The table region the board performed from.
    pub region: Vec<u8>,
    /// What made the take (`emulate`, `demo`, `sim`, `edit`, …).
    pub source: String,
    /// The events, in time order (ties in the order they happened).
    pub events: Vec<Event>,
}

/// Why a take file was refused.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum TakeError {
    /// The file ends before a field.
    #[error("truncated: the file ends inside {field} at byte {offset}")]
    Truncated {
        /// The field.
        field: &'static str,
        /// Where it starts.
        offset: usize,
    },
    /// Not a take.
    #[error("not a take: the magic at byte 0 is not \"MTAK\"")]
    Magic,
    /// A version this host does not read.
    #[error("take format version {0} at byte 4; this marionette reads versions 1 to {VERSION}")]
    Version(u16),
    /// The CRC does not match.
    #[error("CRC mismatch (stored {stored:#010x}, computed {computed:#010x}): the file is damaged")]
    Crc {
        /// The CRC in the file.
        stored: u32,
        /// The CRC of its bytes.
        computed: u32,
    },
    /// An event of unknown kind.
    #[error("event {index} at byte {offset}: unknown kind {kind}")]
    Kind {
        /// The event's index.
        index: usize,
        /// Where it starts.
        offset: usize,
        /// The kind code.
        kind: u8,
    },
    /// An output event whose length is not the channel count's.
    #[error("event {index} at byte {offset}: an output of {len} bytes; {channels} channels take {}", 2 * usize::from(*channels))]
    OutputLen {
        /// The event's index.
        index: usize,
        /// Where it starts.
        offset: usize,
        /// Its length.
        len: usize,
        /// The take's channels.
        channels: u16,
    },
    /// Bytes after the last event.
    #[error("{0} bytes after the last event")]
    Trailing(usize),
    /// The source name is not UTF-8.
    #[error("the source name is not UTF-8")]
    Source,
    /// A field does not fit the format.
    #[error("{0} does not fit the take format")]
    TooLarge(&'static str),
    /// The region holds no valid rig.
    #[error("the take's table region holds no valid rig")]
    NoRig,
}

/// Reads little-endian integers from a byte slice, naming what is missing.
struct Cursor<'b> {
    bytes: &'b [u8],
    at: usize,
}

impl<'b> Cursor<'b> {
    fn take(&mut self, n: usize, field: &'static str) -> Result<&'b [u8], TakeError> {
        let out =
            self.bytes
                .get(self.at..self.at.saturating_add(n))
                .ok_or(TakeError::Truncated {
                    field,
                    offset: self.at,
                })?;
        self.at += n;
        Ok(out)
    }

    fn u16(&mut self, field: &'static str) -> Result<u16, TakeError> {
        let b = self.take(2, field)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }

    fn u32(&mut self, field: &'static str) -> Result<u32, TakeError> {
        let b = self.take(4, field)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
}

impl Take {
    /// The format version the take is written in: 2 if it holds reported
    /// targets (kind 5), else 1.
    #[must_use]
    pub fn version(&self) -> u16 {
        if self.events.iter().any(|e| e.kind == EventKind::Reported) {
            2
        } else {
            1
        }
    }

    /// The take's bytes (docs/take.md).
    pub fn to_bytes(&self) -> Result<Vec<u8>, TakeError> {
        let mut out = Vec::new();
        out.extend_from_slice(&MAGIC);
        out.extend_from_slice(&self.version().to_le_bytes());
        out.extend_from_slice(&self.channels.to_le_bytes());
        out.extend_from_slice(&self.period_us.to_le_bytes());
        let region_len =
            u32::try_from(self.region.len()).map_err(|_| TakeError::TooLarge("the region"))?;
        out.extend_from_slice(&region_len.to_le_bytes());
        out.extend_from_slice(&self.region);
        let source_len =
            u16::try_from(self.source.len()).map_err(|_| TakeError::TooLarge("the source name"))?;
        out.extend_from_slice(&source_len.to_le_bytes());
        out.extend_from_slice(self.source.as_bytes());
        let count =
            u32::try_from(self.events.len()).map_err(|_| TakeError::TooLarge("the event count"))?;
        out.extend_from_slice(&count.to_le_bytes());
        for e in &self.events {
            let len = u16::try_from(e.data.len()).map_err(|_| TakeError::TooLarge("an event"))?;
            out.push(e.kind.code());
            out.extend_from_slice(&e.time_us.to_le_bytes());
            out.extend_from_slice(&len.to_le_bytes());
            out.extend_from_slice(&e.data);
        }
        let crc = crc32(&out);
        out.extend_from_slice(&crc.to_le_bytes());
        Ok(out)
    }

    /// Reads a take, checking magic, version, CRC and every event.
    pub fn parse(bytes: &[u8]) -> Result<Self, TakeError> {
        if bytes.len() >= 4 && bytes.get(..4) != Some(&MAGIC[..]) {
            return Err(TakeError::Magic);
        }
        let mut c = Cursor { bytes, at: 0 };
        c.take(4, "the magic")?;
        let version = c.u16("the version")?;
        if !(1..=VERSION).contains(&version) {
            return Err(TakeError::Version(version));
        }
        let body_len = bytes.len().checked_sub(4).ok_or(TakeError::Truncated {
            field: "the CRC",
            offset: bytes.len(),
        })?;
        let (body, tail) = bytes.split_at(body_len.max(6));
        let stored = tail
            .get(..4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .ok_or(TakeError::Truncated {
                field: "the CRC",
                offset: body.len(),
            })?;
        let computed = crc32(body);
        if stored != computed {
            return Err(TakeError::Crc { stored, computed });
        }
        let mut c = Cursor { bytes: body, at: 6 };
        let channels = c.u16("the channel count")?;
        let period_us = c.u32("the frame period")?;
        let region_len = c.u32("the region length")? as usize;
        let region = c.take(region_len, "the region")?.to_vec();
        let source_len = usize::from(c.u16("the source length")?);
        let source = std::str::from_utf8(c.take(source_len, "the source name")?)
            .map_err(|_| TakeError::Source)?
            .to_string();
        let count = c.u32("the event count")? as usize;
        let mut events = Vec::with_capacity(count.min(body.len() / EVENT_HEAD_LEN));
        for index in 0..count {
            let offset = c.at;
            let code = c.take(1, "an event's kind")?[0];
            let kind = EventKind::from_code(code, version).ok_or(TakeError::Kind {
                index,
                offset,
                kind: code,
            })?;
            let time_us = c.u32("an event's time")?;
            let len = usize::from(c.u16("an event's length")?);
            if kind.is_output() && len != 2 * usize::from(channels) {
                return Err(TakeError::OutputLen {
                    index,
                    offset,
                    len,
                    channels,
                });
            }
            let data = c.take(len, "an event's data")?.to_vec();
            events.push(Event {
                time_us,
                kind,
                data,
            });
        }
        if c.at != body.len() {
            return Err(TakeError::Trailing(body.len() - c.at));
        }
        Ok(Self {
            channels,
            period_us,
            region,
            source,
            events,
        })
    }

    /// Reads a take file; errors name the file.
    pub fn load(path: &Path) -> Result<Self, String> {
        let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
        Self::parse(&bytes).map_err(|e| format!("take {}: {e}", path.display()))
    }

    /// Writes the take to `path` (through a staged file: a failed write
    /// leaves nothing behind).
    pub fn save(&self, path: &Path) -> Result<(), String> {
        let bytes = self
            .to_bytes()
            .map_err(|e| format!("{}: {e}", path.display()))?;
        crate::save::save(path, &bytes, &[]).map_err(|e| e.to_string())
    }

    /// A take of one run: the session sent, the outputs of `run` (the
    /// board's, or the native core's) in order, and its replies. Output
    /// and reply times come from a native replay of the session that
    /// follows the fail-safe trips the board reported (the outputs are the
    /// board's own: only their times are the replay's, and an output past
    /// the replay's end takes the period after the one before; the times
    /// never go back, so the take keeps the board's order).
    pub fn of_run(
        source: &str,
        region: &[u8],
        session: &[Sent],
        run: &Run,
    ) -> Result<Self, PerformError> {
        let outputs: Vec<Vec<u16>> = run
            .frame_targets
            .iter()
            .chain(&run.rest_targets)
            .cloned()
            .collect();
        let followed = perform::follow(region, session, &outputs, &run.replies)?;
        let parsed = Region::parse(region);
        let rig = parsed.rig.as_ref().ok_or(PerformError::NoRig)?;
        let period_us = rig.frame_period_us();
        let channels = outputs.first().map_or_else(
            || {
                rig.servos()
                    .iter()
                    .map(|s| usize::from(s.channel) + 1)
                    .max()
                    .unwrap_or(0)
            },
            Vec::len,
        );
        let mut events = sent_events(session);
        let frames = run.frame_targets.len();
        let end = session.last().map_or(0, |s| s.time_us);
        let times = output_times(&followed.times, outputs.len(), end, period_us);
        for (k, (targets, time_us)) in outputs.iter().zip(times).enumerate() {
            events.push(Event::output(time_us, k < frames, targets));
        }
        events.extend(reply_events(session, &run.replies)?);
        // Stable: at one time, sent before outputs before replies.
        events.sort_by_key(|e| e.time_us);
        Ok(Self {
            channels: u16::try_from(channels).unwrap_or(u16::MAX),
            period_us,
            region: region.to_vec(),
            source: source.to_string(),
            events,
        })
    }

    /// A take of a session with a board on a serial port: `written`, every
    /// message the host wrote at its time (from the last `Hello` before the
    /// first other message: the handshake's unanswered ones are left out),
    /// the board's `replies`, and the servo targets each `Telemetry`
    /// reported, at the time of the tracker frame it reports (padded or cut
    /// to the rig's channels). `region` is what the host knows of the
    /// board's flash: the rig, and the tables if given.
    pub fn of_port(
        source: &str,
        region: &[u8],
        written: &[Sent],
        replies: &[Message],
    ) -> Result<Self, PerformError> {
        let parsed = Region::parse(region);
        let rig = parsed.rig.as_ref().ok_or(PerformError::NoRig)?;
        let channels = rig
            .servos()
            .iter()
            .map(|s| usize::from(s.channel) + 1)
            .max()
            .unwrap_or(0);
        let session = from_last_hello(written);
        let mut events = sent_events(session);
        let answers = reply_events(session, replies)?;
        for (m, e) in replies.iter().zip(&answers) {
            if let Message::Telemetry(t) = m {
                let mut targets = t.servo_targets.as_slice().to_vec();
                targets.resize(channels, 0);
                events.push(Event::targets_of(EventKind::Reported, e.time_us, &targets));
            }
        }
        events.extend(answers);
        // Stable: at one time, sent before reported before replies.
        events.sort_by_key(|e| e.time_us);
        Ok(Self {
            channels: u16::try_from(channels).unwrap_or(u16::MAX),
            period_us: rig.frame_period_us(),
            region: region.to_vec(),
            source: source.to_string(),
            events,
        })
    }

    /// The session the take sent (its `Sent` events, in order).
    #[must_use]
    pub fn session(&self) -> Vec<Sent> {
        self.events
            .iter()
            .filter(|e| e.kind == EventKind::Sent)
            .map(|e| Sent {
                time_us: e.time_us,
                bytes: e.data.clone(),
            })
            .collect()
    }

    /// Every output the board put on its servo link (frame-driven and
    /// easing, in order) as `(time, frame, targets)`; none in a take from a
    /// port.
    #[must_use]
    pub fn outputs(&self) -> Vec<(u32, bool, Vec<u16>)> {
        self.events
            .iter()
            .filter(|e| e.kind.is_board_output())
            .map(|e| (e.time_us, e.kind == EventKind::FrameOutput, e.targets()))
            .collect()
    }

    /// The servo curves the take holds, as `(time, targets)`: the board's
    /// outputs if it has them, else the targets its telemetry reported
    /// (a take from a port).
    #[must_use]
    pub fn curves(&self) -> Vec<(u32, Vec<u16>)> {
        let board = self.events.iter().any(|e| e.kind.is_board_output());
        self.events
            .iter()
            .filter(|e| {
                if board {
                    e.kind.is_board_output()
                } else {
                    e.kind == EventKind::Reported
                }
            })
            .map(|e| (e.time_us, e.targets()))
            .collect()
    }

    /// The frame-driven outputs' count.
    #[must_use]
    pub fn frame_outputs(&self) -> usize {
        self.count(EventKind::FrameOutput)
    }

    /// Events of one kind.
    #[must_use]
    pub fn count(&self, kind: EventKind) -> usize {
        self.events.iter().filter(|e| e.kind == kind).count()
    }

    /// The decoded replies (status, acks, telemetry), in order.
    #[must_use]
    pub fn replies(&self) -> Vec<Message> {
        self.events
            .iter()
            .filter(|e| e.kind == EventKind::Reply)
            .flat_map(Event::messages)
            .collect()
    }

    /// The take's summary (`marionette take info`).
    #[must_use]
    pub fn info(&self) -> Info {
        let first = self.events.first().map_or(0, |e| e.time_us);
        let last = self.events.last().map_or(0, |e| e.time_us);
        let mut sent = SentCounts::default();
        for m in self
            .session()
            .iter()
            .flat_map(|s| perform::decode_replies(&s.bytes))
        {
            match m {
                Message::TrackerFrame(_) | Message::CompactFrame(_) => sent.tracker_frames += 1,
                Message::Params(_) => sent.params += 1,
                Message::Command(_) => sent.commands += 1,
                Message::Hello(_) => sent.hellos += 1,
                _ => {}
            }
        }
        let replies = self.replies();
        let telemetry = replies
            .iter()
            .filter(|m| matches!(m, Message::Telemetry(_)))
            .count();
        let curves = self.curves();
        let ranges_us = (0..usize::from(self.channels))
            .map(|ch| {
                let values = curves
                    .iter()
                    .filter_map(|o| o.1.get(ch))
                    .filter(|&&v| v > 0)
                    .map(|&v| f64::from(v) / 4.0);
                let (lo, hi) = values.fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
                    (lo.min(v), hi.max(v))
                });
                if lo.is_finite() { [lo, hi] } else { [0.0, 0.0] }
            })
            .collect();
        let region = Region::parse(&self.region);
        Info {
            format_version: self.version(),
            source: self.source.clone(),
            rig_hash: region
                .rig
                .as_ref()
                .map(|r| format!("{:016x}", r.rig_hash())),
            region_bytes: self.region.len(),
            has_table: region.table.is_some(),
            period_us: self.period_us,
            channels: self.channels,
            seconds: f64::from(last.wrapping_sub(first)) / 1e6,
            events: self.events.len(),
            sent,
            replies: replies.len(),
            telemetry,
            frame_outputs: self.frame_outputs(),
            rest_outputs: self.count(EventKind::RestOutput),
            reported_outputs: self.count(EventKind::Reported),
            servo_link_seen: self.events.iter().any(|e| e.kind.is_board_output())
                || !self.events.iter().any(|e| e.kind == EventKind::Reported),
            ranges_us,
        }
    }
}

/// The replies of a run as events: each at the time of the session message
/// it answers (by sequence number; a `Status` without one answers the
/// `Hello` before it), else at the time of the last message sent.
fn reply_events(session: &[Sent], replies: &[Message]) -> Result<Vec<Event>, PerformError> {
    let seqs = perform::session_seqs(session);
    let time_of = |seq: u32| {
        seqs.iter()
            .position(|s| *s == Some(seq))
            .and_then(|i| session.get(i))
            .map(|s| s.time_us)
    };
    let first = session.first().map_or(0, |s| s.time_us);
    let end = session.last().map_or(0, |s| s.time_us);
    replies
        .iter()
        .map(|m| {
            let time_us = match m {
                Message::Ack(a) => time_of(a.seq),
                Message::Telemetry(t) => time_of(t.seq),
                Message::Status(s) => s.request_seq.map_or(Some(first), time_of),
                _ => None,
            }
            .unwrap_or(end);
            Ok(Event {
                time_us,
                kind: EventKind::Reply,
                data: perform::frame_bytes(m)?,
            })
        })
        .collect()
}

/// `written` from the last `Hello` before its first other message.
fn from_last_hello(written: &[Sent]) -> &[Sent] {
    let is_hello = |s: &Sent| {
        perform::decode_replies(&s.bytes)
            .iter()
            .any(|m| matches!(m, Message::Hello(_)))
    };
    let first_other = written
        .iter()
        .position(|s| !is_hello(s))
        .unwrap_or(written.len());
    let last_hello = written
        .get(..first_other)
        .and_then(|opening| opening.iter().rposition(is_hello))
        .unwrap_or(0);
    written.get(last_hello..).unwrap_or(written)
}

/// Messages the host sent, by kind.
#[derive(Clone, Debug, Default, Serialize, PartialEq, Eq)]
pub struct SentCounts {
    /// `Hello`s.
    pub hellos: usize,
    /// Tracker frames (either framing).
    pub tracker_frames: usize,
    /// `Params` messages.
    pub params: usize,
    /// Commands.
    pub commands: usize,
}

/// A take's summary (`marionette take info --json`).
#[derive(Clone, Debug, Serialize)]
pub struct Info {
    /// The take format version.
    pub format_version: u16,
    /// What made it.
    pub source: String,
    /// The rig's hash (hex), if the region holds a valid rig.
    pub rig_hash: Option<String>,
    /// The region's size, bytes.
    pub region_bytes: usize,
    /// Whether the region holds a valid table for the rig.
    pub has_table: bool,
    /// The rig's frame period, µs.
    pub period_us: u32,
    /// Servo channels.
    pub channels: u16,
    /// From the first event to the last, s.
    pub seconds: f64,
    /// Events in all.
    pub events: usize,
    /// Messages sent, by kind.
    pub sent: SentCounts,
    /// Replies (messages) from the board.
    pub replies: usize,
    /// Of which telemetry.
    pub telemetry: usize,
    /// Frame-driven outputs.
    pub frame_outputs: usize,
    /// Easing outputs.
    pub rest_outputs: usize,
    /// Servo targets reported by telemetry (a take from a port).
    pub reported_outputs: usize,
    /// Whether the take holds the board's servo link (false: a take from a
    /// port, whose curves are the targets its telemetry reported).
    pub servo_link_seen: bool,
    /// Per-channel [min, max] target of the curves (µs; quarter-µs ÷ 4,
    /// zeros skipped).
    pub ranges_us: Vec<[f64; 2]>,
}

/// One `Sent` event per message of `session`, at its time.
fn sent_events(session: &[Sent]) -> Vec<Event> {
    session
        .iter()
        .map(|s| Event {
            time_us: s.time_us,
            kind: EventKind::Sent,
            data: s.bytes.clone(),
        })
        .collect()
}

/// The times of `n` board outputs: the replay's (`replay`) where it has
/// them, past its end a period after the one before (from `end`, the
/// session's last message), and never going back. The replay runs a
/// fail-safe trip's easing ticks late enough for the core's clock to see
/// the time-out, after the time of the message that ended the trip, which
/// the board received after them: such an output takes the time of the
/// next one, so that sorting the take's events keeps the board's order.
fn output_times(replay: &[u32], n: usize, end: u32, period_us: u32) -> Vec<u32> {
    let mut last = end;
    let mut times: Vec<u32> = (0..n)
        .map(|k| {
            last = replay
                .get(k)
                .copied()
                .unwrap_or_else(|| last.wrapping_add(period_us));
            last
        })
        .collect();
    let mut next = u32::MAX;
    for t in times.iter_mut().rev() {
        *t = (*t).min(next);
        next = *t;
    }
    times
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn output_times_follow_the_replay_and_never_go_back() {
        // A trip's two easing outputs (5000, 6000) timed after the output
        // of the message that ended it (2000): they take its time; past
        // the replay's end, a period (1000) after the one before.
        let replay = [0, 1000, 5000, 6000, 2000, 3000];
        assert_eq!(
            output_times(&replay, 8, 3000, 1000),
            [0, 1000, 2000, 2000, 2000, 3000, 4000, 5000]
        );
        assert_eq!(output_times(&[], 2, 7000, 1000), [8000, 9000]);
    }

    fn small() -> Take {
        Take {
            channels: 2,
            period_us: 1000,
            region: vec![0xAA, 0xBB],
            source: "t".into(),
            events: vec![
                Event {
                    time_us: 5,
                    kind: EventKind::Sent,
                    data: vec![0x00, 0x01],
                },
                Event::output(6, true, &[0x1770, 0x0001]),
            ],
        }
    }

    #[test]
    fn a_small_take_has_the_documented_bytes() {
        let bytes = small().to_bytes().unwrap();
        let mut expected: Vec<u8> = vec![
            b'M', b'T', b'A', b'K', 1, 0, // magic, version 1
            2, 0, // channels
            0xE8, 0x03, 0, 0, // period 1000
            2, 0, 0, 0, 0xAA, 0xBB, // region
            1, 0, b't', // source
            2, 0, 0, 0, // events
            1, 5, 0, 0, 0, 2, 0, 0x00, 0x01, // sent at 5 µs
            3, 6, 0, 0, 0, 4, 0, 0x70, 0x17, 0x01, 0x00, // frame output at 6 µs
        ];
        let crc = crc32(&expected);
        expected.extend_from_slice(&crc.to_le_bytes());
        assert_eq!(bytes, expected);
        assert_eq!(Take::parse(&bytes).unwrap(), small());
    }

    /// The example of docs/take.md's version 2: a take from a port, its
    /// targets reported by telemetry (kind 5).
    fn from_a_port() -> Take {
        let mut take = small();
        take.source = "p".into();
        take.events[1] = Event::targets_of(EventKind::Reported, 6, &[0x1770, 0x0001]);
        take
    }

    #[test]
    fn a_take_from_a_port_has_the_documented_bytes() {
        let take = from_a_port();
        let bytes = take.to_bytes().unwrap();
        let mut expected: Vec<u8> = vec![
            b'M', b'T', b'A', b'K', 2, 0, // magic, version 2
            2, 0, // channels
            0xE8, 0x03, 0, 0, // period 1000
            2, 0, 0, 0, 0xAA, 0xBB, // region
            1, 0, b'p', // source
            2, 0, 0, 0, // events
            1, 5, 0, 0, 0, 2, 0, 0x00, 0x01, // sent at 5 µs
            5, 6, 0, 0, 0, 4, 0, 0x70, 0x17, 0x01, 0x00, // reported at 6 µs
        ];
        let crc = crc32(&expected);
        expected.extend_from_slice(&crc.to_le_bytes());
        assert_eq!(bytes, expected);
        let back = Take::parse(&bytes).unwrap();
        assert_eq!(back, take);
        assert!(back.outputs().is_empty(), "no servo link seen");
        assert_eq!(back.curves(), vec![(6, vec![0x1770, 0x0001])]);
        let info = back.info();
        assert_eq!((info.format_version, info.reported_outputs), (2, 1));
        assert!(!info.servo_link_seen);
        // Kind 5 is version 2's: in a version-1 file it is unknown.
        let mut v1 = expected.clone();
        v1[4] = 1;
        let n = v1.len() - 4;
        let crc = crc32(&v1[..n]);
        v1[n..].copy_from_slice(&crc.to_le_bytes());
        assert_eq!(
            Take::parse(&v1),
            Err(TakeError::Kind {
                index: 1,
                offset: 34,
                kind: 5
            })
        );
    }

    #[test]
    fn damaged_takes_are_refused_with_the_reason() {
        let bytes = small().to_bytes().unwrap();
        for cut in 0..bytes.len() {
            assert!(Take::parse(&bytes[..cut]).is_err(), "cut at {cut}");
        }
        for i in 0..bytes.len() {
            for bit in 0..8 {
                let mut b = bytes.clone();
                b[i] ^= 1 << bit;
                assert!(Take::parse(&b).is_err(), "byte {i} bit {bit}");
            }
        }
        let mut v3 = bytes.clone();
        v3[4] = 3;
        assert_eq!(Take::parse(&v3), Err(TakeError::Version(3)));
        assert_eq!(Take::parse(b"MREG\x01\x00"), Err(TakeError::Magic));
    }
}
