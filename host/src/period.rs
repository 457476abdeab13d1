//! Whether a rig and its table keep the rig's frame period on the board.
//!
//! The live loop's deadline ([`marionette_core::deadline`]) gives the
//! solver what the period leaves after the rest of a frame, and the
//! synthesis's share of that rest is the table's: its window read and
//! blended for every segment ([`marionette_core::grid::cost`]). A table
//! whose synthesis leaves the solver less than the least it needs
//! ([`deadline::MIN_SOLVE_BUDGET`]) gets that least anyway, and its frames
//! run over the period on the board. `marionette build` says so when it
//! writes such a table, `inspect BLOB --rig RIG` for a table and rig, and
//! `sim`, `emulate` and `demo` count the frames of a session that may run
//! over ([`crate::perform::Run::short_frames`]).

use marionette_core::deadline::{self, Received};
use marionette_core::frame::Region;
use marionette_core::perform::Performer;
use marionette_core::solve::SolverState;
use serde::{Deserialize, Serialize};

/// What the deadline leaves a rig's plain frames with its table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Period {
    /// The rig's frame period, µs.
    pub period_us: u32,
    /// The synthesis's work of a frame inside the table's valid cells,
    /// instructions (the synthesis's own count).
    pub synthesis_instructions: u32,
    /// The sensors the rig reads (a compact frame of them is assumed).
    pub sensors: u32,
    /// What the period leaves the solver of such a frame, instructions.
    pub solver_left: u32,
    /// The least the solver needs ([`deadline::MIN_SOLVE_BUDGET`]).
    pub solver_floor: u32,
    /// The solver is left at least that: the frames keep the period.
    pub keeps_period: bool,
}

impl Period {
    /// The check of `region`'s rig and table; `None` without both.
    #[must_use]
    pub fn of(region: &[u8]) -> Option<Self> {
        let region = Region::parse(region);
        let rig = region.rig.as_ref()?;
        region.table.as_ref()?;
        let received = Received {
            sensors: rig.sensors_read().count_ones() as usize,
            compact: true,
        };
        let mut solver = SolverState::new();
        let performer = Performer::new(&region, &mut solver);
        let pipeline = performer.pipeline()?;
        let synthesis = deadline::Synthesis {
            work: pipeline.plain_synthesis_work(),
            adjusted: false,
        };
        Some(Period {
            period_us: rig.frame_period_us(),
            synthesis_instructions: synthesis.work,
            sensors: received.sensors as u32,
            solver_left: pipeline.solve_budget().left(synthesis, received),
            solver_floor: deadline::MIN_SOLVE_BUDGET,
            keeps_period: pipeline.keeps_period(received),
        })
    }

    /// One line saying it: the synthesis's work and what the period leaves
    /// the solver, and whether that keeps the period.
    #[must_use]
    pub fn text(&self) -> String {
        let verdict = if self.keeps_period {
            "keeps the period".to_owned()
        } else {
            format!(
                "less than the solver's floor {}: on a {} MHz board its frames run over the period",
                self.solver_floor,
                deadline::CLOCK_HZ / 1_000_000
            )
        };
        format!(
            "deadline: synthesis {} instructions a frame; the rig's {} µs period leaves the solver {} ({} sensors, compact frames): {verdict}",
            self.synthesis_instructions, self.period_us, self.solver_left, self.sensors
        )
    }
}

/// The note `sim`, `emulate` and `demo` print when `short` of a session's
/// `frames` tracker frames may run over the period (none when `short` is 0).
#[must_use]
pub fn note(short: u32, frames: usize, region: &[u8]) -> Option<String> {
    if short == 0 {
        return None;
    }
    let why = Period::of(region).map_or_else(String::new, |p| format!(" ({})", p.text()));
    Some(format!(
        "note: {short} of {frames} tracker frames leave the solver less than it needs at the rig's period: on the board they may run over it{why}"
    ))
}
