//! [`Receiver`]: the board's whole receive path, bytes in, validated
//! messages out.

use super::compact::{self, COMPACT_TAG, CompactView, SENSOR_BYTES};
use super::tracker::{TRACKER_TAG, TrackerView};
use super::validate::{ValidCommand, ValidParams, ValidTrackerFrame};
use super::{
    CRC_LEN, ErrorCounters, FRAME_CAPACITY, FrameReader, MIN_PROTOCOL_VERSION, Message,
    PROTOCOL_VERSION, Sensor, SeqTracker, WireError, decode_payload,
};
use crate::crc::crc32;

/// A validated host-to-board message.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Incoming {
    /// A `Hello`. Answer with a `Status` carrying [`PROTOCOL_VERSION`] either
    /// way; if `accepted` is false the host's version is outside
    /// [`MIN_PROTOCOL_VERSION`]`..=`[`PROTOCOL_VERSION`], the mismatch was
    /// counted, and every other message is rejected until a matching `Hello`.
    Hello {
        /// The host's protocol version.
        host_version: u16,
        /// The host's version is one this board speaks.
        accepted: bool,
    },
    /// A tracker frame (`f32` or compact), validated into
    /// [`Receiver::frame`]: read it there before feeding more bytes.
    Tracker,
    /// Parameter values.
    Params(ValidParams),
    /// A command (answer with an `Ack` echoing its `seq`).
    Command(ValidCommand),
}

/// Handshake state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Session {
    /// No `Hello` yet: messages are accepted (lenient start, so a bare
    /// stream works).
    Open,
    /// The last `Hello` carried a version this board speaks.
    Accepted,
    /// The last `Hello` carried another version: messages are rejected.
    Rejected {
        /// The host's version.
        host_version: u16,
    },
}

/// Board-side receive path: [`FrameReader`] → CRC → postcard (tracker
/// frames, compact or `f32`, read in place: [`CompactView`],
/// [`TrackerView`]) → direction and version checks →
/// [`SeqTracker`] (one counter shared by all host messages that carry `seq`)
/// → validation. Every rejection is counted in [`Receiver::errors`].
///
/// A tracker frame is validated in place into [`Receiver::frame`] (half a
/// kilobyte, never copied or cleared whole per frame).
#[derive(Clone, Debug)]
pub struct Receiver<const N: usize = FRAME_CAPACITY> {
    reader: FrameReader<N>,
    link: Link,
}

/// Everything but the frame buffer, so that a frame in the buffer can be
/// read in place while the rest is updated.
#[derive(Clone, Debug)]
struct Link {
    seq: SeqTracker,
    errors: ErrorCounters,
    frames_ok: u32,
    session: Session,
    /// The last accepted tracker frame's time, µs (extends compact times).
    last_time: Option<u32>,
    frame: ValidTrackerFrame,
}

impl<const N: usize> Default for Receiver<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Receiver<N> {
    /// A receiver with clean counters and an open session.
    #[must_use]
    pub fn new() -> Self {
        Self {
            reader: FrameReader::new(),
            link: Link {
                seq: SeqTracker::new(),
                errors: ErrorCounters::new(),
                frames_ok: 0,
                session: Session::Open,
                last_time: None,
                frame: ValidTrackerFrame::empty(),
            },
        }
    }

    /// Rejections so far.
    #[must_use]
    pub const fn errors(&self) -> &ErrorCounters {
        &self.link.errors
    }

    /// Messages accepted so far, of every kind (including accepted
    /// `Hello`s).
    #[must_use]
    pub const fn frames_ok(&self) -> u32 {
        self.link.frames_ok
    }

    /// The handshake state.
    #[must_use]
    pub const fn session(&self) -> Session {
        self.link.session
    }

    /// The tracker frame of the last [`Incoming::Tracker`] (unspecified
    /// after a rejected one).
    #[must_use]
    pub const fn frame(&self) -> &ValidTrackerFrame {
        &self.link.frame
    }

    /// Feeds one received byte.
    pub fn push(&mut self, byte: u8) -> Option<Incoming> {
        let frame = self.reader.push(byte, &mut self.link.errors)?;
        self.link.accept(frame)
    }

    /// Feeds bytes from `input` until a message is accepted, advancing
    /// `input`. Call again with the same `input` until it returns `None`.
    pub fn push_slice(&mut self, input: &mut &[u8]) -> Option<Incoming> {
        while !input.is_empty() {
            let Some(frame) = self.reader.push_slice(input, &mut self.link.errors) else {
                break;
            };
            if let Some(incoming) = self.link.accept(frame) {
                return Some(incoming);
            }
        }
        None
    }
}

impl Link {
    /// One decoded frame (payload + CRC): accepted, or its rejection
    /// counted.
    fn accept(&mut self, frame: &[u8]) -> Option<Incoming> {
        match self.decode(frame) {
            Ok(incoming) => {
                if !matches!(
                    incoming,
                    Incoming::Hello {
                        accepted: false,
                        ..
                    }
                ) {
                    self.frames_ok = self.frames_ok.saturating_add(1);
                }
                Some(incoming)
            }
            Err(e) => {
                self.errors.record(e);
                None
            }
        }
    }

    fn decode(&mut self, frame: &[u8]) -> Result<Incoming, WireError> {
        let split = frame.len().checked_sub(CRC_LEN).ok_or(WireError::Crc)?;
        let (payload, crc) = frame.split_at_checked(split).ok_or(WireError::Crc)?;
        let crc: [u8; CRC_LEN] = crc.try_into().map_err(|_| WireError::Crc)?;
        if u32::from_le_bytes(crc) != crc32(payload) {
            return Err(WireError::Crc);
        }
        match payload.split_first() {
            // The hot paths: read in place, no `Message` built.
            Some((&COMPACT_TAG, body)) => {
                let view = CompactView::new(body)?;
                self.compact(view.seq16(), view.time24(), view.sensors())
            }
            Some((&TRACKER_TAG, body)) => {
                let view = TrackerView::new(body)?;
                self.tracker(view.seq(), view.time_us(), &mut view.sensors())
            }
            _ => self.handle(&decode_payload(payload)?),
        }
    }

    fn handle(&mut self, msg: &Message) -> Result<Incoming, WireError> {
        match msg {
            Message::Hello(h) => Ok(self.hello(h.protocol_version)),
            Message::Status(_) | Message::Telemetry(_) | Message::Ack(_) => {
                Err(WireError::Direction)
            }
            Message::CompactFrame(c) => self.compact(
                c.seq16(),
                c.time24(),
                c.sensors.iter().map(<[u8; SENSOR_BYTES]>::as_slice),
            ),
            _ if self.rejected() => Err(WireError::Version),
            Message::TrackerFrame(f) => {
                self.tracker(f.seq, f.time_us, &mut f.sensors.iter().copied())
            }
            Message::Params(p) => {
                self.sequence(p.seq)?;
                p.validate().map(Incoming::Params)
            }
            Message::Command(c) => {
                self.sequence(c.seq)?;
                c.validate().map(Incoming::Command)
            }
        }
    }

    fn rejected(&self) -> bool {
        matches!(self.session, Session::Rejected { .. })
    }

    /// A compact tracker frame: its sequence number and time extended from
    /// the last accepted ones, its sensors unpacked in place into
    /// [`Receiver::frame`].
    fn compact<'s>(
        &mut self,
        seq16: u16,
        time24: u32,
        sensors: impl Iterator<Item = &'s [u8]>,
    ) -> Result<Incoming, WireError> {
        if self.rejected() {
            return Err(WireError::Version);
        }
        let seq = compact::extend_seq(self.seq.last(), seq16);
        self.sequence(seq)?;
        let time_us = compact::extend_time(self.last_time, time24);
        self.frame.restart(seq, time_us, true);
        for bytes in sensors {
            self.frame
                .push_with(|slot| compact::unpack_sensor_into(bytes, slot))?;
        }
        self.last_time = Some(time_us);
        Ok(Incoming::Tracker)
    }

    /// An `f32` tracker frame: its sequence number checked, its sensors
    /// validated in place into [`Receiver::frame`]. One copy for both
    /// sources of sensors (the in-place view and a decoded `Message`).
    #[inline(never)]
    fn tracker(
        &mut self,
        seq: u32,
        time_us: u32,
        sensors: &mut dyn Iterator<Item = Sensor>,
    ) -> Result<Incoming, WireError> {
        if self.rejected() {
            return Err(WireError::Version);
        }
        self.sequence(seq)?;
        self.frame.validate_from(seq, time_us, sensors)?;
        self.last_time = Some(time_us);
        Ok(Incoming::Tracker)
    }

    fn hello(&mut self, host_version: u16) -> Incoming {
        let accepted = (MIN_PROTOCOL_VERSION..=PROTOCOL_VERSION).contains(&host_version);
        if accepted {
            self.session = Session::Accepted;
            self.seq.reset();
            self.last_time = None;
        } else {
            self.session = Session::Rejected { host_version };
            self.errors.record(WireError::Version);
        }
        Incoming::Hello {
            host_version,
            accepted,
        }
    }

    /// Sequence check before validation, so a frame rejected for its values
    /// still advances the sequence and does not later show up as lost.
    fn sequence(&mut self, seq: u32) -> Result<(), WireError> {
        let lost = self.seq.observe(seq)?;
        self.errors.add_lost(lost);
        Ok(())
    }
}
