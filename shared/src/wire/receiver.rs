//! [`Receiver`]: the board's whole receive path, bytes in, validated
//! messages out.

use super::validate::{ValidCommand, ValidParams, ValidTrackerFrame};
use super::{
    ErrorCounters, FRAME_CAPACITY, FrameReader, MIN_PROTOCOL_VERSION, Message, PROTOCOL_VERSION,
    SeqTracker, WireError, decode_frame,
};

/// A validated host-to-board message. Stored inline (no heap), so variants
/// differ in size on purpose.
#[allow(clippy::large_enum_variant)]
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
    /// A tracker frame.
    Tracker(ValidTrackerFrame),
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

/// Board-side receive path: [`FrameReader`] → CRC → postcard →
/// direction and version checks → [`SeqTracker`] (one counter shared by all
/// host messages that carry `seq`) → validation. Every rejection is counted
/// in [`Receiver::errors`].
#[derive(Clone, Debug)]
pub struct Receiver<const N: usize = FRAME_CAPACITY> {
    reader: FrameReader<N>,
    seq: SeqTracker,
    errors: ErrorCounters,
    frames_ok: u32,
    session: Session,
}

impl<const N: usize> Default for Receiver<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Receiver<N> {
    /// A receiver with clean counters and an open session.
    #[must_use]
    pub const fn new() -> Self {
        Self {
            reader: FrameReader::new(),
            seq: SeqTracker::new(),
            errors: ErrorCounters::new(),
            frames_ok: 0,
            session: Session::Open,
        }
    }

    /// Rejections so far.
    #[must_use]
    pub const fn errors(&self) -> &ErrorCounters {
        &self.errors
    }

    /// Messages accepted so far (including accepted `Hello`s).
    #[must_use]
    pub const fn frames_ok(&self) -> u32 {
        self.frames_ok
    }

    /// The handshake state.
    #[must_use]
    pub const fn session(&self) -> Session {
        self.session
    }

    /// Feeds one received byte.
    pub fn push(&mut self, byte: u8) -> Option<Incoming> {
        let frame = self.reader.push(byte, &mut self.errors)?;
        let msg = decode_frame(frame);
        self.accept(&msg)
    }

    /// Feeds bytes from `input` until a message is accepted, advancing
    /// `input`. Call again with the same `input` until it returns `None`.
    pub fn push_slice(&mut self, input: &mut &[u8]) -> Option<Incoming> {
        while !input.is_empty() {
            let Some(frame) = self.reader.push_slice(input, &mut self.errors) else {
                break;
            };
            let msg = decode_frame(frame);
            if let Some(incoming) = self.accept(&msg) {
                return Some(incoming);
            }
        }
        None
    }

    /// The message by reference: it is hundreds of bytes, and each move
    /// a copy.
    fn accept(&mut self, msg: &Result<Message, WireError>) -> Option<Incoming> {
        let handled = match msg {
            Ok(m) => self.handle(m),
            Err(e) => Err(*e),
        };
        match handled {
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

    fn handle(&mut self, msg: &Message) -> Result<Incoming, WireError> {
        match msg {
            Message::Hello(h) => Ok(self.hello(h.protocol_version)),
            Message::Status(_) | Message::Telemetry(_) | Message::Ack(_) => {
                Err(WireError::Direction)
            }
            _ if matches!(self.session, Session::Rejected { .. }) => Err(WireError::Version),
            Message::TrackerFrame(f) => {
                self.sequence(f.seq)?;
                f.validate().map(Incoming::Tracker)
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

    fn hello(&mut self, host_version: u16) -> Incoming {
        let accepted = (MIN_PROTOCOL_VERSION..=PROTOCOL_VERSION).contains(&host_version);
        if accepted {
            self.session = Session::Accepted;
            self.seq.reset();
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
