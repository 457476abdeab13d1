//! The serial wire protocol between the host and the board.
//!
//! # Specification (protocol version 5)
//!
//! This is the whole contract: a host can be written from it alone. The
//! board's behaviour (states, replies, fail-safe) is in
//! [`crate::perform`].
//!
//! ## Frames
//!
//! Every message travels in one frame:
//!
//! ```text
//! frame = COBS( payload ++ crc32_le(payload) ) ++ 0x00
//! payload = postcard(Message)
//! ```
//!
//! - **payload**: the [`Message`] serialized by postcard 1.x (layout below).
//! - **CRC**: CRC-32/ISO-HDLC ([`crate::crc`]: zlib/Ethernet, reflected
//!   polynomial `0xEDB88320`, init and xorout `0xFFFFFFFF`) of the payload
//!   bytes only, appended as 4 bytes **little-endian**.
//! - **COBS** (Cheshire & Baker; [`cobs`]) of payload + CRC, so that the frame
//!   contains no `0x00`, followed by one `0x00` delimiter. When payload + CRC
//!   ends with a full block (254 non-zero bytes after its last zero), the
//!   encoder writes **no** empty block after it (no trailing `01` before the
//!   delimiter); a receiver accepts the frame with or without that `01`.
//! - A receiver treats every `0x00` as the end of a frame. A sender may send
//!   extra `0x00` bytes at any time (e.g. one before the first frame) to
//!   resynchronise; empty frames are ignored. Bytes received before the first
//!   delimiter form a frame like any other and will normally fail the CRC.
//! - Limits: payload ≤ [`MAX_PAYLOAD`] = 476 bytes, decoded frame (payload +
//!   CRC) ≤ [`FRAME_CAPACITY`] = 480 bytes, encoded frame including the
//!   delimiter ≤ [`MAX_FRAME`] = 483 bytes.
//!
//! ## Rejections and their counters
//!
//! A frame or message is rejected, and counted by kind in
//! [`ErrorCounters`] (each a saturating `u32`), at the first check it fails:
//!
//! 1. `oversize`: the **decoded** frame (payload + CRC) would exceed
//!    [`FRAME_CAPACITY`] (480 bytes), however many bytes it took encoded (a
//!    483-byte encoded frame of 481 decoded bytes is oversize; one of 480 is
//!    not). Counted once; the rest of it, up to the next `0x00`, is dropped.
//! 2. `cobs`: the frame ended (`0x00`) inside a COBS block.
//! 3. `crc`: the decoded frame is shorter than 4 bytes, or its CRC differs.
//! 4. `decode`: postcard cannot decode the payload (unknown tag or variant,
//!    bad varint or bool, truncated field, list over capacity), bytes remain
//!    after the message, or a board-to-host message reached the board.
//! 5. `version`: a `Hello` with a version the board does not speak, and
//!    every other message after it until an accepted `Hello`.
//! 6. `stale`: a sequence number already accepted or up to
//!    [`STALE_WINDOW`] behind (see below).
//! 7. `range`: validation failed (see Validation).
//!
//! A frame **cut short** is counted by where the cut fell: inside a COBS
//! block → `cobs`; on a block boundary → `crc` (the bytes before the cut are
//! a well-formed packet whose CRC fails). A cut frame with no delimiter after
//! it runs into the next frame: both are lost as **one** rejection, and
//! their sequence numbers show up in `lost` at the next accepted message.
//!
//! //! ## postcard encoding of the field types
//!
//! | type | bytes |
//! |---|---|
//! | `u8` | 1 byte, as is |
//! | `u16`, `u32` | unsigned LEB128 varint: 7 bits per byte, least significant group first, high bit set on every byte but the last (`0`→`00`, `127`→`7F`, `128`→`80 01`, `300`→`AC 02`, `1000`→`E8 07`, `u32::MAX`→`FF FF FF FF 0F`); at most 3 bytes for `u16`, 5 for `u32` |
//! | `bool` | `00` false, `01` true; any other byte is a decode error |
//! | `f32` | 4 bytes, IEEE-754 bits little-endian (`1.0`→`00 00 80 3F`) |
//! | `[T; n]` | `n` elements, no length prefix |
//! | [`List<T, N>`](List) | `varint(len)` then `len` elements; `len > N` is a decode error |
//! | struct | fields in declaration order, no tags, no padding |
//! | enum | `varint(variant index)` then the variant's fields |
//!
//! Encoders emit the shortest varint. Decoders (postcard) also accept
//! over-long varints that fit the type; the CRC protects against corruption.
//!
//! ## Messages: the tags are the contract
//!
//! | tag | message | direction | fields, in order |
//! |---|---|---|---|
//! | 0 | [`Hello`] | host → board | `protocol_version: u16` |
//! | 1 | [`TrackerFrame`] | host → board | `seq: u32, time_us: u32, sensors: List<Sensor, 16>` |
//! | 2 | [`Params`] | host → board | `seq: u32, values: List<f32, 6>` |
//! | 3 | [`Command`] | host → board | `seq: u32, kind: CommandKind` |
//! | 4 | [`Status`] | board → host | `protocol_version: u16, armed: bool, table_ok: bool, reason: StatusReason, errors: ErrorCounters, frames_ok: u32`; v2 appends `request_seq: Option<u32>, state: State, trips: u32`; v5 appends `show: ShowState, show_refusals: u32` |
//! | 5 | [`Telemetry`] | board → host | `seq: u32, servo_targets: List<u16, 24>, goal_residuals: List<f32, 8>, stage_counts: [u32; 6], errors: ErrorCounters`; v2 appends `state: State, trips: u32, last_trip: Trip, timing: FrameTiming` |
//! | 6 | [`Ack`] | board → host | `seq: u32, ok: bool` |
//! | 7 | [`CompactFrame`] (v2) | host → board | `seq16: [u8; 2], time24: [u8; 3], sensors: List<[u8; 11], 16>`: a tracker frame quantized, specified in [`compact`] |
//!
//! - [`Sensor`]: `id: u8, position: [f32; 3]` (metres), `rotation: [f32; 4]`
//!   (`[w, x, y, z]`) — 29 bytes.
//! - [`CommandKind`]: 0 `Arm`, 1 `Disarm`, 2 `SelectTable(u8)`,
//!   3 `SelectClip(u8)`, 4 `SetGoalWeight { goal: u8, weight: f32 }`,
//!   5 `Boresight { sensor: u8 }`, 6 `RequestStatus`,
//!   7 `Jog { channel: u8, target: u16 }` (v3; calibration, below),
//!   8 `Show { play: bool }` (v4; start or stop the flashed show).
//! - [`StatusReason`]: 0 `Ok`, 1 `NoTable`, 2 `BadMagic`, 3 `BadVersion`
//!   (table format), 4 `BadCrc`, 5 `BadBounds`, 6 `ProtocolMismatch`, 7 `NoRig`,
//!   8 `RigMismatch`, 9 `Unsupported`, 10 `RigTooLarge` (a valid rig with
//!   more segments than the firmware holds).
//! - [`ErrorCounters`]: eight `u32` varints: `cobs, crc, decode, oversize,
//!   version, lost, stale, range`.
//! - `Option<u32>`: `00` for `None`, `01` then the varint for `Some`.
//! - [`State`]: 0 `Unready` (cannot arm: see `reason`), 1 `Disarmed`,
//!   2 `Armed`, 3 `FailSafe` (armed, tracker silent past the time-out).
//! - [`ShowState`] (v5): 0 `None` (no show in the region), 1 `Ready`,
//!   2 `Playing`; the region's show refused (the board plays nothing):
//!   3 `Truncated`, 4 `BadMagic`, 5 `BadVersion` (show format), 6 `BadCrc`,
//!   7 `BadHeader`, 8 `BadKeys`, 9 `RigMismatch` (built for another rig).
//! - [`Trip`]: `seq: u32, ticks: u32`; [`FrameTiming`]: `frames, mean,
//!   worst, overruns, budget`, five `u32`.
//! - `stage_counts`: decode, map, synth, solve, servo, total, in the
//!   board's counter units (see [`FrameTiming`]).
//! - `servo_targets` are in quarter-microseconds (Maestro units).
//!
//! Largest payloads: `TrackerFrame` with 16 sensors and 5-byte varints
//! 1 + 5 + 5 + 1 + 16 × 29 = 476 bytes; `Telemetry` 223; `Status` 70;
//! `CompactFrame` 7 + 16 × 11 = 183.
//!
//! ### Calibration: `Jog`
//!
//! `Command { seq, kind: Jog { channel, target } }` moves one servo while
//! the board is disarmed (`marionette calibrate`). `target` is in the
//! servo's target units × 4, like `servo_targets`: quarter-µs for a pulse
//! servo, position × 4 for a bus servo; `0` ends the jog. **The rule:** a
//! jog can never leave the servo's hard limits. The board moves the channel
//! through the same slew limiter as a performance, so its target never
//! leaves the channel's calibrated range (the rig's `pulse_us` or bus
//! `limits`, after trim and reversal; a target beyond it stops at the end)
//! and never changes faster than the servo's `max_speed` and `max_accel`
//! allow. The board answers `Ack { ok: true }` when it takes the jog, and
//! `ok: false` while armed, when it cannot drive the rig (no rig,
//! `Unsupported`), for a channel the rig has no servo on, or while another
//! channel is jogging. `Jog` target 0, `Disarm` or a `Hello` end the jog
//! (the servo eases back to rest); `Arm` is refused until it is back. So
//! does a second in which the board accepts no message at all
//! ([`crate::perform::JOG_TIMEOUT_US`], 1,000,000 µs of the board's clock):
//! a host that vanished mid-jog does not leave a servo held, perhaps
//! stalled against its end stop. A host that holds a jog while its user
//! looks repeats the `Jog` (same target) or sends any other message more
//! often than that (`marionette calibrate`: every 250 ms).
//! Behaviour in detail: [`crate::perform`].
//!
//! `Jog { channel: 1, target: 6000 }` (1500 µs) with `seq` 5: payload
//! `03 05 07 01 F0 2E` (tag 3, seq 5, kind 7, channel 1, varint 6000),
//! CRC `0xABC9E281`, frame `0B 03 05 07 01 F0 2E 81 E2 C9 AB 00`.
//!
//! ### What the fields mean
//!
//! - `Status.frames_ok`: every message the board accepted since boot, of
//!   every kind (`Hello`s it speaks, tracker frames, `Params`, commands),
//!   including the `RequestStatus` a `Status` answers.
//! - `Status.table_ok`: the region's rig and table can perform (the reason
//!   would be `Ok` but for a protocol mismatch).
//! - `Status.reason` is `ProtocolMismatch` only while the last `Hello` was
//!   refused; an accepted `Hello` clears it.
//! - `Status.show` (v5): the flashed show; a refused one (tags 3 and up)
//!   is never played, and `Status.show_refusals` counts the refusals since
//!   boot: 1 at boot, plus 1 for every trigger refused because of it (a
//!   `Show { play: true }`, answered `Ack { ok: false }`, or the button).
//! - `Telemetry.seq`: the sequence number of the tracker frame whose
//!   outputs it reports. Telemetry goes out after every 10th **performed**
//!   frame (armed; frames taken while disarmed do not count) and after the
//!   frame that ends a fail-safe trip, not after every frame.
//! - Replies: a `Hello` gets a `Status` (`request_seq: None`); a
//!   `RequestStatus` gets a `Status` whose `request_seq` is its `seq`, and
//!   **no** `Ack`; every other command gets an `Ack` echoing its `seq`.
//!   Replies come in the order of the messages they answer.
//!
//! ## Sequence numbers
//!
//! The host keeps **one** `u32` counter for `TrackerFrame`, `Params` and
//! `Command`, incremented by one per message sent (wrapping), starting
//! anywhere (normally 0) after a `Hello`. The board checks it with
//! [`SeqTracker`], against the last number it accepted:
//!
//! - ahead by `d` (`1 ≤ d < 2³¹`): accepted; `d − 1` are counted as `lost`;
//! - equal, or behind by at most [`STALE_WINDOW`] = 256: rejected as `stale`;
//! - behind by more than 256: taken as the sender restarting its counter:
//!   accepted, nothing counted as lost, tracking continues from it;
//! - the first number after boot or an accepted `Hello` is always accepted.
//!
//! A message rejected **before** its sequence number is read (`oversize`,
//! `cobs`, `crc`, `decode`, `version`) does not advance the tracker, so its
//! number shows up in `lost` at the next accepted message. One rejected by
//! **validation** (`range`) does advance it: it is counted once, as
//! `range`, never also as `lost`. A `stale` one does neither.
//!
//! ## Validation (board side)
//!
//! Decoding yields raw values; `validate()` turns host messages into
//! [`ValidTrackerFrame`], [`ValidParams`], [`ValidCommand`] or counts a
//! `range` rejection:
//! - sensor ids `< 16` and unique; `|position| ≤ 100 m` (NaN/inf rejected);
//!   quaternion with `| |q|² − 1 | ≤ 0.1` is renormalised, otherwise rejected;
//! - params finite with `|v| ≤ 1e6`;
//! - `SetGoalWeight`: goal `< 8`, `0 ≤ weight ≤ 1e6`; `Boresight`: sensor `< 16`;
//!   `Jog`: channel `< 24`, target `≤ 0x3FFF` (16383, the Maestro's 14 bits).
//!
//! ## Versioning
//!
//! [`PROTOCOL_VERSION`] is 5. The host opens a session with `Hello`; the board
//! answers with a `Status` carrying its own version. A board accepts a host
//! version from [`MIN_PROTOCOL_VERSION`] (1) to its own; on any other it
//! counts a `version` error, disarms, reports `reason = ProtocolMismatch`,
//! and rejects every other message (counted as `version`) until a `Hello` it
//! accepts, which clears the mismatch. Before any `Hello` the board accepts
//! messages. Any change to an existing message's layout, or to a tag, bumps
//! the version; new messages and new enum variants are appended at the end
//! (a new variant also bumps the version, since an old decoder rejects it).
//! Decoding is strict: trailing bytes after the message are a decode error.
//!
//! Version 2 only **appended**: fields to the board's `Status` and
//! `Telemetry`, and message tag 7 (the compact tracker frame, which hosts
//! send by default; tag 1 stays valid). Every version-1 host message is
//! valid version 2, so a
//! board keeps accepting version-1 hosts. A version-1 host that decodes
//! strictly rejects the longer replies; one that reads a reply's prefix
//! (and ignores what follows) gets the version-1 fields unchanged. In every
//! version `Status.protocol_version` is the payload's second field: bytes
//! `04` then its varint.
//!
//! Version 3 only **appended** the command kind 7 (`Jog`). Every version-1
//! and version-2 message keeps its bytes, and the board's replies are
//! unchanged, so a board keeps accepting version-1 and version-2 hosts (which
//! never send `Jog`). A version-2 board refuses a version-3 `Hello`
//! (`ProtocolMismatch`) instead of counting each `Jog` as a `decode` error,
//! so a host learns that its board cannot be jogged before it tries.
//!
//! Version 4 only **appended** the command kind 8 (`Show { play }`: start
//! or stop the show flashed beside the rig and tables), on the same terms:
//! a board keeps accepting version-1 to version-3 hosts, and a version-3
//! board refuses a version-4 `Hello`.
//!
//! Version 5 only **appended** two fields to the board's `Status`
//! (`show: ShowState, show_refusals: u32`: the flashed show, and why and
//! how often the board refused it). Every host message keeps its bytes, so
//! a board keeps accepting version-1 to version-4 hosts; their `Status`
//! replies are longer, read as for version 2 above.
//!
//! ## Worked example
//!
//! `Hello { protocol_version: 2 }`:
//!
//! ```text
//! payload           00 02                  tag 0, varint 2
//! crc32(payload)    0xAFD773D3  -> LE      D3 73 D7 AF
//! payload ++ crc    00 02 D3 73 D7 AF
//! COBS              01 | 06 02 D3 73 D7 AF  (block "" + zero, block of 5)
//! frame             01 06 02 D3 73 D7 AF 00
//! ```
//!
//! `Ack { seq: 300, ok: true }`: payload `06 AC 02 01`, CRC `0x917C76D0`,
//! frame `09 06 AC 02 01 D0 76 7C 91 00`.
//!
//! `Command { seq: 5, kind: Arm }`: payload `03 05 00`, CRC `0x8070930E`,
//! frame `03 03 05 05 0E 93 70 80 00`.
//!
//! `TrackerFrame { seq: 1, time_us: 1000, sensors: [Sensor { id: 0,
//! position: [0.0, 1.5, -0.25], rotation: [1, 0, 0, 0] }] }`:
//!
//! ```text
//! payload  01 01 E8 07 01 00  00 00 00 00  00 00 C0 3F  00 00 80 BE
//!          00 00 80 3F  00 00 00 00  00 00 00 00  00 00 00 00
//! crc      0xDB0F8228 -> 28 82 0F DB
//! frame    06 01 01 E8 07 01 01 01 01 01 01 01 03 C0 3F 01 03 80 BE 01
//!          03 80 3F 01 01 01 01 01 01 01 01 01 01 01 05 28 82 0F DB 00
//! ```
//!
//! # Use
//!
//! - Sender: [`encode`] a [`Message`] into a buffer of [`MAX_FRAME`] bytes and
//!   write the returned slice.
//! - Board receiver: [`Receiver`] (bytes in, validated [`Incoming`] out, all
//!   counters kept; tracker frames, compact or `f32`, read and validated in
//!   place: [`CompactView`](compact::CompactView), [`TrackerView`]), or the pieces:
//!   [`FrameReader`] → [`decode_frame`] → [`SeqTracker`] → `validate()`.
//!
//! Nothing here allocates or panics.

pub mod cobs;
pub mod compact;
mod error;
mod list;
mod message;
mod reader;
mod receiver;
mod seq;
mod tracker;
mod validate;

pub use compact::CompactFrame;
pub use error::{ErrorCounters, WireError};
pub use list::List;
pub use message::{
    Ack, Command, CommandKind, Direction, FrameTiming, Hello, MAX_GOALS, MAX_PARAMS, MAX_SENSORS,
    MAX_SERVOS, Message, Params, STAGES, Sensor, ShowState, State, Status, StatusReason, Telemetry,
    TrackerFrame, Trip,
};
pub use reader::FrameReader;
pub use receiver::{Incoming, Receiver, Session};
pub use seq::{STALE_WINDOW, SeqTracker};
pub use tracker::{SENSOR_WIRE_BYTES, TRACKER_TAG, TrackerView};
pub use validate::{
    JOG_TARGET_MAX, PARAM_LIMIT, POSITION_LIMIT_M, QUAT_NORM2_TOLERANCE, SensorSample,
    ValidCommand, ValidParams, ValidTrackerFrame, WEIGHT_LIMIT,
};

use crate::crc::{Crc32, crc32};
use postcard::ser_flavors::Flavor;

/// The protocol version this crate speaks.
pub const PROTOCOL_VERSION: u16 = 5;
/// The oldest host version a board accepts: every version-1 host message is
/// a valid version-2 message (see [Versioning](self#versioning)).
pub const MIN_PROTOCOL_VERSION: u16 = 1;
/// Bytes of CRC after the payload.
pub const CRC_LEN: usize = 4;
/// Largest postcard payload of any [`Message`] (a full `TrackerFrame`).
pub const MAX_PAYLOAD: usize = 1 + 5 + 5 + 1 + MAX_SENSORS * SENSOR_WIRE_BYTES;
/// Largest decoded frame (payload + CRC): the [`FrameReader`] buffer size.
pub const FRAME_CAPACITY: usize = MAX_PAYLOAD + CRC_LEN;
/// Largest encoded frame, including the `0x00` delimiter.
pub const MAX_FRAME: usize = cobs::max_encoded_len(FRAME_CAPACITY) + 1;

/// postcard flavor that COBS-encodes and checksums on the fly, then appends
/// the CRC and the delimiter.
struct FrameFlavor<'a> {
    cobs: cobs::Encoder<'a>,
    crc: Crc32,
}

const FULL: postcard::Error = postcard::Error::SerializeBufferFull;

impl Flavor for FrameFlavor<'_> {
    type Output = usize;

    fn try_extend(&mut self, data: &[u8]) -> postcard::Result<()> {
        self.crc.update(data);
        self.cobs.push_slice(data).map_err(|_| FULL)
    }

    fn try_push(&mut self, data: u8) -> postcard::Result<()> {
        self.try_extend(&[data])
    }

    fn finalize(mut self) -> postcard::Result<usize> {
        let crc = self.crc.finish().to_le_bytes();
        self.cobs.push_slice(&crc).map_err(|_| FULL)?;
        self.cobs.finish_frame().map_err(|_| FULL)
    }
}

/// Encodes `msg` as a complete frame (COBS, CRC, delimiter) into `out` and
/// returns the bytes to send.
///
/// # Errors
/// [`WireError::BufferFull`] if `out` is too small ([`MAX_FRAME`] always
/// suffices).
///
/// # Example
///
/// A host encodes a tracker frame; the board's [`Receiver`] takes the bytes
/// (in any chunks) and hands back the validated frame.
///
/// ```
/// use marionette_core::wire::{
///     Incoming, List, MAX_FRAME, Message, Receiver, Sensor, TrackerFrame, encode,
/// };
///
/// let mut sensors = List::new();
/// sensors.push(Sensor { id: 2, position: [0.1, 1.2, 0.3], rotation: [1.0, 0.0, 0.0, 0.0] }).unwrap();
/// let frame = Message::TrackerFrame(TrackerFrame { seq: 1, time_us: 5_000, sensors });
/// let mut buf = [0u8; MAX_FRAME];
/// let bytes = encode(&frame, &mut buf).unwrap();
///
/// let mut board = Receiver::<512>::new();
/// let mut input = bytes;
/// assert_eq!(board.push_slice(&mut input), Some(Incoming::Tracker));
/// let got = board.frame();
/// assert_eq!((got.seq(), got.time_us()), (1, 5_000));
/// assert_eq!(got.sensor(2).unwrap().position().to_array(), [0.1, 1.2, 0.3]);
/// assert_eq!(board.errors().total(), 0);
/// ```
pub fn encode<'a>(msg: &Message, out: &'a mut [u8]) -> Result<&'a [u8], WireError> {
    let flavor = FrameFlavor {
        cobs: cobs::Encoder::new(&mut *out),
        crc: Crc32::new(),
    };
    let n = postcard::serialize_with_flavor(msg, flavor).map_err(|_| WireError::BufferFull)?;
    out.get(..n).ok_or(WireError::BufferFull)
}

/// Serializes `msg` to its bare postcard payload (no CRC, no COBS).
///
/// # Errors
/// [`WireError::BufferFull`] if `out` is too small.
pub fn encode_payload<'a>(msg: &Message, out: &'a mut [u8]) -> Result<&'a [u8], WireError> {
    match postcard::to_slice(msg, out) {
        Ok(used) => Ok(used),
        Err(_) => Err(WireError::BufferFull),
    }
}

/// Decodes a bare postcard payload; every byte must be used.
///
/// # Errors
/// [`WireError::Decode`] if postcard fails or bytes remain.
pub fn decode_payload(payload: &[u8]) -> Result<Message, WireError> {
    match postcard::take_from_bytes::<Message>(payload) {
        Ok((msg, [])) => Ok(msg),
        _ => Err(WireError::Decode),
    }
}

/// Checks the CRC of a decoded frame (as yielded by [`FrameReader`]: payload
/// + 4 CRC bytes, no COBS, no delimiter) and decodes its payload.
///
/// # Errors
/// [`WireError::Crc`] if the frame is under 4 bytes or the CRC differs;
/// [`WireError::Decode`] as for [`decode_payload`].
pub fn decode_frame(frame: &[u8]) -> Result<Message, WireError> {
    let split = frame.len().checked_sub(CRC_LEN).ok_or(WireError::Crc)?;
    let (payload, crc) = frame.split_at_checked(split).ok_or(WireError::Crc)?;
    let crc: [u8; CRC_LEN] = crc.try_into().map_err(|_| WireError::Crc)?;
    if u32::from_le_bytes(crc) != crc32(payload) {
        return Err(WireError::Crc);
    }
    decode_payload(payload)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hello_frame_exact() {
        let mut out = [0u8; MAX_FRAME];
        let msg = Message::Hello(Hello {
            protocol_version: 1,
        });
        let frame = encode(&msg, &mut out).unwrap();
        assert_eq!(frame, &[0x01, 0x06, 0x01, 0x69, 0x22, 0xDE, 0x36, 0x00]);
        assert_eq!(decode_frame(&[0x00, 0x01, 0x69, 0x22, 0xDE, 0x36]), Ok(msg));
        assert_eq!(
            decode_frame(&[0x00, 0x01, 0x69, 0x22, 0xDE, 0x37]),
            Err(WireError::Crc)
        );
        assert_eq!(decode_frame(&[0x69, 0x22, 0xDE]), Err(WireError::Crc));
        // The worked example of the spec (version 2; CRC from zlib).
        let msg = Message::Hello(Hello {
            protocol_version: 2,
        });
        let frame = encode(&msg, &mut out).unwrap();
        assert_eq!(frame, &[0x01, 0x06, 0x02, 0xD3, 0x73, 0xD7, 0xAF, 0x00]);
    }

    #[test]
    fn trailing_bytes_are_a_decode_error() {
        // A valid Hello followed by one extra byte; an unknown tag; nothing.
        assert_eq!(decode_payload(&[0x00, 0x01, 0xFF]), Err(WireError::Decode));
        assert_eq!(decode_payload(&[0x07]), Err(WireError::Decode));
        assert_eq!(decode_payload(&[]), Err(WireError::Decode));
    }

    #[test]
    fn small_buffer_is_buffer_full() {
        let msg = Message::Ack(Ack { seq: 1, ok: true });
        let mut out = [0u8; 6];
        assert_eq!(encode(&msg, &mut out), Err(WireError::BufferFull));
    }
}
