//! Why a board did not perform, in words, with what to do about it.
//!
//! Every command that runs a session (`sim`, `emulate`, `demo`, and the
//! streaming commands) ends it the same way: [`Outcome::of`] reads the
//! board's replies (its `Status` and the `Ack` of the `Arm` command) and
//! says whether it armed; if not, the command prints the board's
//! [`StatusReason`] with an explanation and advice ([`explain`]), puts the
//! same in its `--json` summary ([`BoardReport`]), and fails with a
//! [`Stop`], which `main` turns into one of the exit codes below.
//!
//! # Exit codes (a public contract)
//!
//! | code | meaning |
//! |---:|---|
//! | 0 | success |
//! | 1 | any other error: bad input (file, line, field named), I/O, or the emulated board and the native core disagree |
//! | 2 | bad command line (clap's usage error) |
//! | [`EXIT_REFUSED`] = 3 | the board never armed: it refused with the `Status` reason printed |
//! | [`EXIT_FAULT`] = 4 | the board stopped on a fault: it did not answer, exited with an error, reset or ran past its deadline |
//! | [`crate::interrupt::QUIT_NOW`] = 130 | quit at once on a signal (Ctrl-C, SIGTERM, SIGHUP), the emulated board ended too; for `live`, `stream`, `replay --port` and `calibrate` the second signal (the first ends the session cleanly, exit code as above) |

use crate::board::{self, Board};
use marionette_core::region::{self, EntryKind, Region};
use marionette_core::rig::Rig;
use marionette_core::table::{Kind, Table};
use marionette_core::wire::{Message, ShowState, StatusReason};
use serde::Serialize;

/// Exit code: the board never armed (see the module doc).
pub const EXIT_REFUSED: u8 = 3;
/// Exit code: the board stopped on a fault (see the module doc).
pub const EXIT_FAULT: u8 = 4;

/// What a `Status` reason means, and what to do about it.
#[must_use]
pub fn explain(reason: StatusReason) -> (&'static str, &'static str) {
    match reason {
        StatusReason::Ok => ("ready", "nothing"),
        StatusReason::NoTable => (
            "there is no motion table in its table region",
            "build one with `marionette build SPEC -o tables.bin` and pass it with `--tables tables.bin`",
        ),
        StatusReason::BadMagic => (
            "the table blob does not start with the table format's magic: the file is not a table \
             blob (a region.bin, a rig or another file?)",
            "pass the file `marionette build -o` wrote; `marionette inspect FILE` says what a file is",
        ),
        StatusReason::BadVersion => (
            "the table blob was written in a format version this firmware does not read",
            "rebuild the table with this version of `marionette build`",
        ),
        StatusReason::BadCrc => (
            "the table blob is damaged: its CRC does not match (altered or cut short)",
            "rebuild it with `marionette build`, or copy it again; `marionette inspect FILE` checks it",
        ),
        StatusReason::BadBounds => (
            "the table blob's sizes or offsets point outside it (cut short?)",
            "rebuild it with `marionette build`, or copy it again; `marionette inspect FILE` checks it",
        ),
        StatusReason::ProtocolMismatch => (
            "the board speaks another wire-protocol version than this host",
            "flash the firmware of this release (`marionette flash`)",
        ),
        StatusReason::NoRig => (
            "there is no valid rig blob in its table region",
            "check the rig with `marionette rig check RIG`, and flash it with the table",
        ),
        StatusReason::RigMismatch => (
            "the table was built for another rig (rig hash or segment count differ)",
            "rebuild the table for this rig (the spec's `[rig] file`), or perform with the rig it was \
             built for; `marionette inspect TABLE --rig RIG` compares them",
        ),
        StatusReason::Unsupported => (
            "it cannot perform this combination: a clip (motion) table where the live loop needs a \
             static grid, or a servo back-end (`[output]`) this board does not drive",
            "build a grid table (`kind = \"grid\"`), and use an `[output]` the board drives \
             (`marionette rig check RIG` lists them per board)",
        ),
        StatusReason::RigTooLarge => (
            "the rig has more segments than its firmware holds",
            "use a rig of at most 24 segments (`marionette rig check RIG` says per board)",
        ),
    }
}

/// The board's flashed show as its `Status` reports it (protocol version
/// 5): the state, and the refusals it counted since boot.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct ShowReport {
    /// `None`, `Ready`, `Playing`, or why the board refused it
    /// (`Truncated`, `BadMagic`, `BadVersion`, `BadCrc`, `BadHeader`,
    /// `BadKeys`, `RigMismatch`).
    pub state: ShowState,
    /// Whether the board refused its show (it then plays nothing).
    pub refused: bool,
    /// Refusals the board counted: once at boot, once for each trigger
    /// refused because of it.
    pub refusals: u32,
}

impl ShowReport {
    /// The show as the last `Status` among `replies` reports it.
    #[must_use]
    pub fn of(replies: &[Message]) -> Option<Self> {
        replies.iter().rev().find_map(|m| match m {
            Message::Status(s) => Some(Self {
                state: s.show,
                refused: s.show.is_refused(),
                refusals: s.show_refusals,
            }),
            _ => None,
        })
    }

    /// A refused show in words with what to do (`None` if it was not
    /// refused).
    #[must_use]
    pub fn refusal_line(&self) -> Option<String> {
        let why = match self.state {
            ShowState::Truncated => "it is cut short (shorter than its header and tables say)",
            ShowState::BadMagic => "it is not a show (its magic is wrong)",
            ShowState::BadVersion => "it was written in a show format this firmware does not read",
            ShowState::BadCrc => "it is damaged: its CRC does not match",
            ShowState::BadHeader => "a header field is out of range",
            ShowState::BadKeys => "a channel's keys are out of order",
            ShowState::RigMismatch => "it was built for another rig than the one in its flash",
            ShowState::None | ShowState::Ready | ShowState::Playing => return None,
        };
        Some(format!(
            "the board refused its flashed show ({:?}: {why}; counted {} time(s)); it plays \
             nothing and its servos stay at rest: rebuild the show from takes of this rig \
             (`marionette show build TAKE -o show.bin --region region.bin`) and flash the region",
            self.state, self.refusals
        ))
    }
}

/// The specific cause behind a reason, where the host can tell it from
/// the region it loaded (`None` for a board whose region it does not
/// know).
#[must_use]
pub fn detail(reason: StatusReason, region: &[u8], board: Option<&Board>) -> Option<String> {
    let (rig, table) = parts(region);
    let rig = rig.as_deref();
    match reason {
        StatusReason::Unsupported => {
            if let Some(t) = &table
                && matches!(t.kind(), Kind::Clips { .. })
            {
                return Some(
                    "the table is a clip (motion) table; the live loop performs grid tables".into(),
                );
            }
            let (rig, board) = (rig?, board?);
            board.refuses(&rig.output(), rig.servos())
        }
        StatusReason::RigMismatch => {
            let (rig, t) = (rig?, table?);
            Some(format!(
                "the rig's hash is {:#018x} with {} segments; the table's {:#018x} with {}",
                rig.rig_hash(),
                rig.body().len(),
                t.rig_hash(),
                t.segment_count()
            ))
        }
        StatusReason::RigTooLarge => {
            let (parsed, _) = Rig::parse(blobs(region).0?).ok()?;
            let limit = board.map_or(24, |b| b.segments);
            Some(format!(
                "the rig has {} segments; the firmware holds {limit}",
                parsed.body().len()
            ))
        }
        _ => None,
    }
}

/// The rig (boxed: it is kilobytes) and the table of a region image.
fn parts(region: &[u8]) -> (Option<Box<Rig<'_>>>, Option<Table<'_>>) {
    let (rig, table) = blobs(region);
    let Some(Ok((rig, _))) = rig.map(Rig::parse) else {
        return (None, None);
    };
    let table = table.and_then(|t| Table::parse(t).ok());
    (Some(Box::new(rig)), table)
}

/// The rig blob and table 0's blob of a region, as the core lays it out
/// ([`marionette_core::region`]: the directory, or the older rig + table).
#[must_use]
pub fn blobs(region: &[u8]) -> (Option<&[u8]>, Option<&[u8]>) {
    if let Ok(dir) = region::directory(region) {
        let rig = dir.find(EntryKind::RIG, 0).map(|e| e.bytes);
        let table = dir.find(EntryKind::TABLE, 0).map(|e| e.bytes);
        return (rig, table);
    }
    let Ok((_, rest)) = Rig::parse(region) else {
        return (None, None);
    };
    let rig_len = region.len() - rest.len();
    let table = region
        .get(rig_len.next_multiple_of(4)..)
        .filter(|t| !t.is_empty());
    (region.get(..rig_len), table)
}

/// How a session went, from the board's replies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// The board acknowledged `Arm`.
    Armed,
    /// The board refused `Arm`; its last `Status` said why (`Ok` if it sent
    /// none).
    Refused(StatusReason),
    /// The board never answered the `Arm`.
    Silent,
}

impl Outcome {
    /// Reads the replies of a session whose `Arm` command had sequence
    /// number `arm_seq`.
    #[must_use]
    pub fn of(replies: &[Message], arm_seq: u32) -> Outcome {
        let reason = replies
            .iter()
            .filter_map(|m| match m {
                Message::Status(s) => Some(s.reason),
                _ => None,
            })
            .next_back();
        let ack = replies.iter().find_map(|m| match m {
            Message::Ack(a) if a.seq == arm_seq => Some(a.ok),
            _ => None,
        });
        match ack {
            Some(true) => Outcome::Armed,
            Some(false) => Outcome::Refused(reason.unwrap_or_default()),
            None => Outcome::Silent,
        }
    }
}

/// Why a board stopped a session.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Problem {
    /// It never armed.
    Refused {
        /// Its `Status` reason.
        reason: StatusReason,
        /// The specific cause, where known ([`detail`]).
        detail: Option<String>,
    },
    /// It stopped on a fault.
    Fault {
        /// What happened.
        what: String,
    },
}

/// A board that did not perform: the error a command fails with.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{}", self.text())]
pub struct Stop {
    /// The board, in words (`the emulated board`).
    pub board: String,
    /// What went wrong.
    pub problem: Problem,
    /// Foreseen from the files rather than seen on a running board.
    pub foreseen: bool,
}

/// A board's state at the end of a session, for `--json` summaries.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct BoardReport {
    /// Whether it armed and performed.
    pub armed: bool,
    /// Its `Status` reason (`Ok` when it armed; `Fault` when it stopped on
    /// a fault).
    pub reason: String,
    /// What the reason means.
    pub explanation: String,
    /// The specific cause, where known.
    pub detail: Option<String>,
    /// What to do about it.
    pub advice: String,
    /// The exit code the command ends with for this (0 when armed).
    pub exit_code: u8,
}

impl BoardReport {
    /// The report of a board that armed.
    #[must_use]
    pub fn armed() -> Self {
        Self {
            armed: true,
            reason: "Ok".into(),
            explanation: "ready".into(),
            detail: None,
            advice: String::new(),
            exit_code: 0,
        }
    }
}

impl Stop {
    /// A board that refused to arm, with the cause looked up in `region`.
    #[must_use]
    pub fn refused(
        board: impl Into<String>,
        reason: StatusReason,
        region: &[u8],
        known: Option<&Board>,
    ) -> Self {
        Self {
            board: board.into(),
            problem: Problem::Refused {
                reason,
                detail: detail(reason, region, known),
            },
            foreseen: false,
        }
    }

    /// The same stop, foreseen from the files ("would refuse").
    #[must_use]
    pub fn foreseen(self) -> Self {
        Self {
            foreseen: true,
            ..self
        }
    }

    /// A board that stopped on a fault.
    #[must_use]
    pub fn fault(board: impl Into<String>, what: impl Into<String>) -> Self {
        Self {
            board: board.into(),
            problem: Problem::Fault { what: what.into() },
            foreseen: false,
        }
    }

    /// The process exit code for this stop.
    #[must_use]
    pub fn exit_code(&self) -> u8 {
        match self.problem {
            Problem::Refused { .. } => EXIT_REFUSED,
            Problem::Fault { .. } => EXIT_FAULT,
        }
    }

    /// The report for a `--json` summary.
    #[must_use]
    pub fn report(&self) -> BoardReport {
        match &self.problem {
            Problem::Refused { reason, detail } => {
                let (what, advice) = explain(*reason);
                BoardReport {
                    armed: false,
                    reason: format!("{reason:?}"),
                    explanation: what.into(),
                    detail: detail.clone(),
                    advice: advice.into(),
                    exit_code: EXIT_REFUSED,
                }
            }
            Problem::Fault { what } => BoardReport {
                armed: false,
                reason: "Fault".into(),
                explanation: what.clone(),
                detail: None,
                advice: "run it again; if it repeats, report it with the command line".into(),
                exit_code: EXIT_FAULT,
            },
        }
    }

    /// The message printed on standard error: what, why, what to do.
    #[must_use]
    pub fn text(&self) -> String {
        match &self.problem {
            Problem::Refused { reason, detail } => {
                let (what, advice) = explain(*reason);
                let detail = detail
                    .as_ref()
                    .map_or_else(String::new, |d| format!(" ({d})"));
                let verb = if self.foreseen {
                    "would refuse"
                } else {
                    "refused"
                };
                format!(
                    "{} {verb} to arm: {reason:?}: {what}{detail}.\n  what to do: {advice}",
                    self.board
                )
            }
            Problem::Fault { what } => format!("{} stopped on a fault: {what}", self.board),
        }
    }
}

/// The stop, if any, of a session whose replies are `replies` (`Arm` sent
/// with sequence number 0, as [`crate::perform::session`] does).
#[must_use]
pub fn check(
    board: &str,
    replies: &[Message],
    region: &[u8],
    known: Option<&Board>,
) -> Option<Stop> {
    match Outcome::of(replies, 0) {
        Outcome::Armed => None,
        Outcome::Refused(reason) => Some(Stop::refused(board, reason, region, known)),
        Outcome::Silent => Some(Stop::fault(
            board,
            "it never answered the Arm command (not running, or not this firmware?)",
        )),
    }
}

/// How a region's rig (and table) fits `board`: segments, back-end and
/// region size; `None` if the region holds no valid rig.
#[must_use]
pub fn region_verdict(board: &Board, region: &[u8]) -> Option<board::Verdict> {
    let (rig_blob, table) = blobs(region);
    let rig_blob = rig_blob?;
    let (rig, _) = Rig::parse(rig_blob).ok()?;
    Some(board.verdict(
        rig.body().len(),
        (&rig.output(), rig.servos()),
        rig_blob.len(),
        table.map(<[u8]>::len),
    ))
}

/// Why a region would not arm `board` (the core's own check,
/// [`Region::parse`], then the board's capacity and back-ends), before
/// anything runs; `None` if it would.
#[must_use]
pub fn precheck(name: &str, region: &[u8], board: &Board) -> Option<Stop> {
    let reason = Region::parse(region).reason;
    if reason != StatusReason::Ok {
        return Some(Stop::refused(name, reason, region, Some(board)));
    }
    let (rig, _) = parts(region);
    let rig = rig?;
    if rig.body().len() > board.segments {
        return Some(Stop::refused(
            name,
            StatusReason::RigTooLarge,
            region,
            Some(board),
        ));
    }
    if board.refuses(&rig.output(), rig.servos()).is_some() {
        return Some(Stop::refused(
            name,
            StatusReason::Unsupported,
            region,
            Some(board),
        ));
    }
    None
}

/// With `--json`, prints `{"board": …}` (the [`BoardReport`]) for an error
/// that is a board's [`Stop`], so that scripts read the reason too; the
/// error itself still ends the command with the stop's exit code.
pub fn print_json_stop(error: &(dyn std::error::Error + 'static), json: bool) {
    if let (true, Some(stop)) = (json, error.downcast_ref::<Stop>())
        && let Ok(text) =
            serde_json::to_string_pretty(&serde_json::json!({ "board": stop.report() }))
    {
        println!("{text}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use marionette_core::wire::{Ack, ErrorCounters, PROTOCOL_VERSION, Status};

    fn status(reason: StatusReason) -> Message {
        Message::Status(Status {
            protocol_version: PROTOCOL_VERSION,
            armed: false,
            table_ok: reason == StatusReason::Ok,
            reason,
            errors: ErrorCounters::default(),
            frames_ok: 1,
            request_seq: None,
            state: marionette_core::wire::State::Unready,
            trips: 0,
            show: marionette_core::wire::ShowState::None,
            show_refusals: 0,
        })
    }

    fn ack(seq: u32, ok: bool) -> Message {
        Message::Ack(Ack { seq, ok })
    }

    #[test]
    fn the_arm_ack_decides_and_the_status_says_why() {
        let refused = [status(StatusReason::NoTable), ack(0, false)];
        assert_eq!(
            Outcome::of(&refused, 0),
            Outcome::Refused(StatusReason::NoTable)
        );
        let armed = [status(StatusReason::Ok), ack(0, true), ack(9, false)];
        assert_eq!(Outcome::of(&armed, 0), Outcome::Armed);
        assert_eq!(Outcome::of(&[status(StatusReason::Ok)], 0), Outcome::Silent);
        assert_eq!(Outcome::of(&armed, 5), Outcome::Silent);
    }

    #[test]
    fn every_reason_has_words_and_advice() {
        use StatusReason::*;
        let all = [
            Ok,
            NoTable,
            BadMagic,
            BadVersion,
            BadCrc,
            BadBounds,
            ProtocolMismatch,
            NoRig,
            RigMismatch,
            Unsupported,
            RigTooLarge,
        ];
        for reason in all {
            let (what, advice) = explain(reason);
            assert!(what.len() > 4 && advice.len() > 6, "{reason:?}");
        }
    }

    #[test]
    fn stops_have_exit_codes_and_reports() {
        let s = Stop::refused("the emulated board", StatusReason::NoTable, &[], None);
        assert_eq!(s.exit_code(), EXIT_REFUSED);
        let text = s.to_string();
        assert!(
            text.contains("NoTable") && text.contains("what to do"),
            "{text}"
        );
        let r = s.report();
        assert!(!r.armed && r.reason == "NoTable" && r.exit_code == 3);
        let f = Stop::fault("the emulated board", "QEMU exited with status 2");
        assert_eq!(
            (f.exit_code(), f.report().reason.as_str()),
            (EXIT_FAULT, "Fault")
        );
    }
}
