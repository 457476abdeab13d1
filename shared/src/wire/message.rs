//! The raw wire messages, exactly as postcard (de)serializes them.
//!
//! Variant order is the wire contract: postcard encodes an enum variant as
//! its index. Append new variants at the end; never reorder. See the module
//! documentation of [`crate::wire`] for the byte layout.

use serde::{Deserialize, Serialize};

use super::{CompactFrame, ErrorCounters, List};

/// Maximum sensors in one [`TrackerFrame`].
pub const MAX_SENSORS: usize = 16;
/// Maximum values in one [`Params`] message.
pub const MAX_PARAMS: usize = 6;
/// Maximum servo targets in one [`Telemetry`] message.
pub const MAX_SERVOS: usize = 24;
/// Maximum goal residuals in one [`Telemetry`] message (and goal indices).
pub const MAX_GOALS: usize = 8;
/// Pipeline stages reported in [`Telemetry::stage_counts`]:
/// decode, map, synth, solve, servo, total.
pub const STAGES: usize = 6;

/// Every message, host to board (tags 0-3 and 7) and board to host (tags
/// 4-6).
///
/// Variants differ a lot in size (a full `TrackerFrame` is ~470 bytes); with
/// no heap they are stored inline on purpose.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Message {
    /// Tag 0, host → board: version handshake.
    Hello(Hello),
    /// Tag 1, host → board: one tracker sample.
    TrackerFrame(TrackerFrame),
    /// Tag 2, host → board: dial and slider values.
    Params(Params),
    /// Tag 3, host → board: a command, answered by [`Ack`].
    Command(Command),
    /// Tag 4, board → host: state and counters (answers `Hello` and
    /// `RequestStatus`).
    Status(Status),
    /// Tag 5, board → host: per-frame outputs and timings.
    Telemetry(Telemetry),
    /// Tag 6, board → host: a command's result.
    Ack(Ack),
    /// Tag 7 (version 2), host → board: one tracker sample, quantized
    /// (see [`super::compact`]).
    CompactFrame(CompactFrame),
}

/// Which way a message travels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Direction {
    /// From the host to the board.
    HostToBoard,
    /// From the board to the host.
    BoardToHost,
}

impl Message {
    /// The postcard tag (variant index) of this message.
    #[must_use]
    pub const fn tag(&self) -> u8 {
        match self {
            Self::Hello(_) => 0,
            Self::TrackerFrame(_) => 1,
            Self::Params(_) => 2,
            Self::Command(_) => 3,
            Self::Status(_) => 4,
            Self::Telemetry(_) => 5,
            Self::Ack(_) => 6,
            Self::CompactFrame(_) => 7,
        }
    }

    /// Which way this message travels.
    #[must_use]
    pub const fn direction(&self) -> Direction {
        match self {
            Self::Hello(_)
            | Self::TrackerFrame(_)
            | Self::Params(_)
            | Self::Command(_)
            | Self::CompactFrame(_) => Direction::HostToBoard,
            Self::Status(_) | Self::Telemetry(_) | Self::Ack(_) => Direction::BoardToHost,
        }
    }
}

/// Version handshake: the host's protocol version.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Hello {
    /// The sender's [`super::PROTOCOL_VERSION`].
    pub protocol_version: u16,
}

/// One tracker sensor's pose.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Sensor {
    /// Sensor id, `< MAX_SENSORS`, unique within a frame.
    pub id: u8,
    /// Position in metres, world frame (Y up).
    pub position: [f32; 3],
    /// Orientation quaternion `[w, x, y, z]`, unit length.
    pub rotation: [f32; 4],
}

/// One tracker sample: up to [`MAX_SENSORS`] sensors.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrackerFrame {
    /// Host sequence number (shared by all host messages that carry one).
    pub seq: u32,
    /// Sample time in microseconds (wraps).
    pub time_us: u32,
    /// The sensors.
    pub sensors: List<Sensor, MAX_SENSORS>,
}

/// Dial and slider values.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Params {
    /// Host sequence number.
    pub seq: u32,
    /// Up to [`MAX_PARAMS`] values.
    pub values: List<f32, MAX_PARAMS>,
}

/// A command from the host.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Command {
    /// Host sequence number; echoed by [`Ack`].
    pub seq: u32,
    /// What to do.
    pub kind: CommandKind,
}

/// What a [`Command`] asks for. Variant order is the wire contract.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum CommandKind {
    /// Tag 0: enable the servo outputs.
    Arm,
    /// Tag 1: disable the servo outputs.
    Disarm,
    /// Tag 2: use motion table `n`.
    SelectTable(u8),
    /// Tag 3: use clip `n` of the current table.
    SelectClip(u8),
    /// Tag 4: set goal `goal`'s weight (0 disables the goal).
    SetGoalWeight {
        /// Goal index, `< MAX_GOALS`.
        goal: u8,
        /// Weight, finite, `0 ≤ weight ≤ WEIGHT_LIMIT`.
        weight: f32,
    },
    /// Tag 5: take sensor `sensor`'s current pose as its reference.
    Boresight {
        /// Sensor id, `< MAX_SENSORS`.
        sensor: u8,
    },
    /// Tag 6: answer with a [`Status`].
    RequestStatus,
    /// Tag 7 (version 3): calibration. While disarmed, move servo `channel`
    /// towards `target` (quarter-µs, or a bus servo's position × 4); `target`
    /// 0 ends the jog (the channel eases back to rest). The board keeps the
    /// channel within its calibrated range and its slew limits, refuses the
    /// jog while armed or while another channel jogs, and refuses `Arm`
    /// while a jog is under way (see [`crate::perform`], Calibration jog).
    /// A jog also ends after a second without any message from the host
    /// ([`crate::perform::JOG_TIMEOUT_US`]): a host holding a servo where it
    /// is repeats this command (or sends any message) more often.
    Jog {
        /// Servo channel, `< MAX_SERVOS`.
        channel: u8,
        /// Target, quarter units (0: end the jog), `≤ 0x3FFF`.
        target: u16,
    },
    /// Tag 8 (version 4): start (`play: true`, from its first frame) or
    /// stop the show flashed in the board's region, which it plays while
    /// disarmed (see [`crate::perform`], Shows). Refused (`Ack` not ok)
    /// while armed or without a show.
    Show {
        /// Start (true) or stop (false).
        play: bool,
    },
}

/// Why the board is (not) ready. Variant order is the wire contract.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum StatusReason {
    /// Tag 0: ready.
    #[default]
    Ok,
    /// Tag 1: no motion table in flash.
    NoTable,
    /// Tag 2: the table blob's magic is wrong.
    BadMagic,
    /// Tag 3: the table blob's format version is unsupported.
    BadVersion,
    /// Tag 4: the table blob's CRC does not match.
    BadCrc,
    /// Tag 5: the table blob's sizes or offsets are out of bounds.
    BadBounds,
    /// Tag 6: the host's `Hello` carried another protocol version.
    ProtocolMismatch,
    /// Tag 7: no valid rig blob in flash (nothing to drive).
    NoRig,
    /// Tag 8: the table was built for another rig (rig hash or segment count
    /// differ).
    RigMismatch,
    /// Tag 9: the table is valid but of a kind this firmware cannot perform
    /// (for example a clip table where a static grid is needed).
    Unsupported,
    /// Tag 10: the rig blob is valid but has more segments than this
    /// firmware's capacity (nothing to drive).
    RigTooLarge,
}

/// The board's state and counters.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Status {
    /// The board's [`super::PROTOCOL_VERSION`].
    pub protocol_version: u16,
    /// Outputs enabled.
    pub armed: bool,
    /// A valid table is loaded.
    pub table_ok: bool,
    /// Why not ready, or `Ok`.
    pub reason: StatusReason,
    /// Rejections so far.
    pub errors: ErrorCounters,
    /// Messages accepted so far, of every kind (`Hello`s that matched,
    /// tracker frames, `Params`, commands).
    pub frames_ok: u32,
    /// Appended in version 2: the sequence number of the `RequestStatus`
    /// this answers, `None` when it answers a `Hello`.
    pub request_seq: Option<u32>,
    /// Appended in version 2: the board's state.
    pub state: State,
    /// Appended in version 2: fail-safe trips since boot.
    pub trips: u32,
    /// Appended in version 5: the show flashed beside the rig and tables:
    /// none, ready, playing, or refused and why.
    pub show: ShowState,
    /// Appended in version 5: times the board refused its show since boot:
    /// once at boot when the region's show fails its checks, and once for
    /// every trigger (`Show { play: true }`, the board's button) refused
    /// because of it.
    pub show_refusals: u32,
}

/// The flashed show, as the board sees it (appended to `Status` in
/// version 5). Variant order is the wire contract; tags 3 and up say why
/// the board refused the region's show (it then plays nothing).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum ShowState {
    /// Tag 0: the region holds no show (or the board has no rig to play
    /// one on).
    #[default]
    None,
    /// Tag 1: a valid show for the rig, not playing.
    Ready,
    /// Tag 2: playing.
    Playing,
    /// Tag 3: refused: shorter than its header and tables say.
    Truncated,
    /// Tag 4: refused: not a show (magic).
    BadMagic,
    /// Tag 5: refused: another show format version.
    BadVersion,
    /// Tag 6: refused: its CRC does not match.
    BadCrc,
    /// Tag 7: refused: a header field out of range.
    BadHeader,
    /// Tag 8: refused: a channel's keys out of order.
    BadKeys,
    /// Tag 9: refused: built for another rig.
    RigMismatch,
}

impl ShowState {
    /// Whether the board refused its show.
    #[must_use]
    pub const fn is_refused(self) -> bool {
        !matches!(self, Self::None | Self::Ready | Self::Playing)
    }
}

/// The board's state (appended to `Status` and `Telemetry` in version 2).
/// Variant order is the wire contract.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum State {
    /// Tag 0: cannot arm (no rig, no usable table, a back-end the board
    /// lacks); `Status.reason` says why.
    #[default]
    Unready,
    /// Tag 1: ready, outputs disabled; servos ease to rest.
    Disarmed,
    /// Tag 2: performing every accepted tracker frame.
    Armed,
    /// Tag 3: armed, but no valid tracker frame for the rig's fail-safe
    /// time-out: servos ease to rest until the next frame.
    FailSafe,
}

/// A fail-safe trip that ended (appended to `Telemetry` in version 2).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Trip {
    /// The sequence number of the message that ended it: the first tracker
    /// frame performed after it (or the `Disarm` that ended it).
    pub seq: u32,
    /// Fail-safe ticks it lasted: frame periods of the board clock with no
    /// valid frame after the time-out. Each dropped the solver's correction
    /// and eased every servo one step to rest (a no-op once at rest).
    pub ticks: u32,
}

/// Frame times since the last `Arm` (appended to `Telemetry` in version 2),
/// in the board's counter units: CPU cycles on hardware; on the emulated
/// board, ticks of its 25 MHz clock (QEMU's virtual clock: instructions ×
/// 3.2 under `-icount shift=7`, the host's wall clock otherwise).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct FrameTiming {
    /// Performed frames timed.
    pub frames: u32,
    /// Their mean (rounded down).
    pub mean: u32,
    /// The longest.
    pub worst: u32,
    /// Frames longer than `budget`.
    pub overruns: u32,
    /// The rig's frame period in counter units (0: the board has no
    /// counter, and nothing is an overrun).
    pub budget: u32,
}

/// Outputs and timings from the board, after every 10th performed tracker
/// frame and after the frame that ends a fail-safe trip.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Telemetry {
    /// The sequence number of the tracker frame whose outputs it reports.
    pub seq: u32,
    /// Servo targets in quarter-microseconds (Maestro units).
    pub servo_targets: List<u16, MAX_SERVOS>,
    /// Remaining distance to each goal, metres.
    pub goal_residuals: List<f32, MAX_GOALS>,
    /// Instruction counts or cycles per stage: decode, map, synth, solve,
    /// servo, total.
    pub stage_counts: [u32; STAGES],
    /// Rejections so far.
    pub errors: ErrorCounters,
    /// Appended in version 2: the board's state.
    pub state: State,
    /// Appended in version 2: fail-safe trips since boot.
    pub trips: u32,
    /// Appended in version 2: the last trip that ended (zeros before the
    /// first).
    pub last_trip: Trip,
    /// Appended in version 2: frame times since the last `Arm`.
    pub timing: FrameTiming,
}

/// A command's result.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Ack {
    /// The command's sequence number.
    pub seq: u32,
    /// Whether it was carried out.
    pub ok: bool,
}
