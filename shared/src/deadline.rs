//! The live loop's deadline: how much work one frame may take.
//!
//! A frame that overruns its period delays the next one, and the servos see
//! jitter. So the live loop ([`crate::frame::Pipeline`]) gives the solver,
//! its only stage of variable length, a budget, and the solver stops before
//! an iteration that might exceed it; what it leaves is carried into the
//! next frame by the loop's correction (see [`crate::frame`]), so the goals
//! are still met over a few frames. The cold first frame after `Arm` is
//! spread the same way.
//!
//! ## The rule
//!
//! The budget is work, not time: wall time would make the board's result
//! depend on its speed, and the host's `sim` could not reproduce it bit for
//! bit. The solver counts its work in instructions of the firmware's
//! Cortex-M4F build by its own cost model ([`crate::solve::cost`]), a pure
//! function of the problem's sizes and of the steps it took, and this
//! module turns the rig's frame period and the board's clock into that
//! unit:
//!
//! ```text
//! frame  = frame_period_us × CLOCK_HZ / 10⁶ cycles × 100 / CPI_PERCENT instructions
//! solver = frame − RESERVE_BASE − RESERVE_PER_SEGMENT × segments
//!          − what the frame synthesized: its counted work (Synthesis),
//!            and RESERVE_ADJUSTED when it had to adjust the parameters
//!          − what the frame brought: RESERVE_PER_SENSOR × sensors (compact), or
//!            RESERVE_F32_FRAME + RESERVE_PER_F32_SENSOR × sensors (f32 frames),
//!          a plain frame's at least MIN_SOLVE_BUDGET
//! ```
//!
//! Both shares are the frame's own, known before the solve. The synthesis
//! counts its work itself ([`crate::grid::cost`]): the table's window read
//! and blended for every segment (8 samples on the shipped trilinear grid,
//! up to 256 on a grid of Catmull-Rom axes) and the cells a projection
//! scanned, so a finer or smoother table gets a smaller solver budget
//! frame by frame, as a frame's sensors and framing ([`Received`]) do,
//! instead of the reserve of the table it was measured on.
//!
//! Within the budget it is a ceiling: the solver starts no iteration whose
//! counted cost does not fit what is left of it, and a solve whose budget
//! does not even cover its fixed part (the checks, the first forward
//! kinematics, the final pose) does not run at all
//! ([`SolveError::Budget`](crate::solve::SolveError::Budget)): the frame
//! drives its warm start, the synthesized pose plus the correction carried
//! from the last solve, and the correction waits for the next frame (see
//! [`crate::frame`]). So a frame takes at most the reserve and the budget.
//!
//! So a rig whose period leaves a plain frame one whole-tree iteration
//! keeps its period on every frame: one hard frame (the synthesis had to
//! clamp or project the parameters, and left the solver less) solves less
//! or not at all, and the next frames catch up. One pass of the step
//! usually suffices because the solver keeps its warm active set from frame
//! to frame (the joints held at their limits: [`crate::solve`]'s system).
//!
//! The floor is for a rig and table whose period is too short for that
//! ([`Budget::keeps_period`] says which): below it the solver cannot take
//! one whole-tree step on a rig like `humanoid16` (its fixed part and one
//! iteration, by the cost model), and a loop that never moves towards its
//! goals is no puppet. Such plain frames get the floor and may run over
//! their period by up to the difference; the board counts them in
//! `Telemetry`'s overruns, and the pipeline counts the frames it knew
//! could ([`Pipeline::short_frames`](crate::frame::Pipeline::short_frames)).
//! An adjusted frame, a hard one, never gets the floor: it keeps what the
//! period leaves, so it runs over only when its synthesis alone does not
//! fit the period (a projection over many cells, a window of many
//! samples). README's "Real time" gives the figures.
//!
//! Every input is the rig's or a constant, so the board, the emulated board
//! and the host's native replay take the same decisions and their outputs
//! stay bit-identical.
//!
//! The reserve is the rest of the frame (receiving and decoding the frame,
//! the sensor map, the synthesis, the servo map): its constants are the
//! worst measured on the emulated board by `tests/realtime.rs` over the
//! bundled recording sent compact and as `f32` frames, the same with a
//! sensor the rig does not read, four other HDM05 clips recorded at
//! 1 kHz, the recording on three other tables (finer, two axes, a
//! Catmull-Rom axis), and the layered demo. That test also checks that the
//! reserve bounds every frame's rest, that it is within 5 % of some
//! frame's rest, plain and
//! adjusted, that the solver keeps its budget on every frame, that only
//! the frames this module says may run over do, and that the goals still
//! converge. When a stage gets faster, lower the reserve to its new worst
//! (the same test prints it): the solver gets the difference.

use crate::wire::{MAX_SENSORS, ValidTrackerFrame};

/// The core clock of the board the budget is set for, Hz: the STM32F411
/// Black Pill at 100 MHz (its firmware checks that its clock is this one).
/// The emulated board and the host's native replay use the same budget, so
/// their output stays bit-identical to the board's.
pub const CLOCK_HZ: u32 = 100_000_000;

/// Cycles per instruction the budget assumes, in hundredths: the realistic
/// model of the project's cycle estimator (`../shared/tools/cycles`:
/// Cortex-M4 timings, 3 flash wait states and the ART accelerator): the
/// largest figure it has given for a whole frame (the mean, the worst or
/// the cold one; README, "Real time"), rounded up. It does not model
/// interrupts or bus contention: a board's DWT counts (`Telemetry`'s
/// timing) settle it.
pub const CPI_PERCENT: u32 = 168;

/// Instructions of the stages around the solver that grow neither with
/// the rig's segments nor with the frame's sensors nor with the table:
/// receiving and decoding a frame besides its sensors, the sensor map, the
/// servo map, the loop's own work and the solver's besides its counted
/// work.
pub const RESERVE_BASE: u32 = 8_871;

/// Instructions per segment of the rig outside the solver besides the
/// synthesis's counted work ([`Synthesis`]): the synthesized pose made
/// local and turned into joint angles, and the servo map (with
/// [`RESERVE_BASE`], at least the worst rest of a frame `tests/realtime.rs`
/// measures for `humanoid16`'s 13 segments, and within 5 % of it: the test
/// checks both).
pub const RESERVE_PER_SEGMENT: u32 = 951;

/// More instructions outside the synthesis's counted work in a frame
/// whose synthesis had to clamp or project the parameters (the worst rest
/// of such a frame `tests/realtime.rs` measures, the same rule as
/// [`RESERVE_PER_SEGMENT`]).
pub const RESERVE_ADJUSTED: u32 = 60;

/// Instructions per segment of each layer of a layered rig besides its
/// synthesis's counted work: its pose made local and blended over the
/// others (`crate::layer`); at least the worst of `demo --layers`'s frames
/// (two layers), which `tests/realtime.rs` replays.
pub const LAYER_PER_SEGMENT: u32 = 1_004;

/// The floor of a plain frame's budget, for a rig whose period is too
/// short: when a plain frame's period less its reserve is below this, its
/// solver gets this much instead (and such a frame may run over its
/// period). It is the fixed
/// part and one iteration with one factorisation pass of the whole-tree
/// solver on `humanoid16`'s four goals, by the cost model
/// (`tests/realtime.rs` checks that just below it no frame of the bundled
/// recording iterates, and that from it up the goals follow).
pub const MIN_SOLVE_BUDGET: u32 = 26_509;

/// Instructions of receiving one sensor of a compact frame (tag 7): its
/// bytes through COBS and the CRC, unpacking and checking it, and taking
/// it into the loop (the boresight). At least the growth of the worst
/// receive from 3 to 4 and to 16 sensors (`tests/realtime.rs` runs the
/// recording with a fourth sensor; README's "Real time" gives the 16).
pub const RESERVE_PER_SENSOR: u32 = 710;

/// Instructions of receiving one sensor of an `f32` frame (tag 1, 29
/// bytes against a compact sensor's 11).
pub const RESERVE_PER_F32_SENSOR: u32 = 800;

/// More instructions of receiving an `f32` frame than a compact one,
/// besides its sensors (its header's varints).
pub const RESERVE_F32_FRAME: u32 = 320;

/// What a tracker frame brought, which its share of the reserve depends
/// on: known once the frame is decoded, before the solve.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Received {
    /// Its sensors (all of them, the rig's or not).
    pub sensors: usize,
    /// It came as a compact frame, not as `f32`s.
    pub compact: bool,
}

impl Received {
    /// What `frame` brought.
    #[must_use]
    pub fn of(frame: &ValidTrackerFrame) -> Self {
        Received {
            sensors: frame.sensors().len(),
            compact: frame.is_compact(),
        }
    }

    /// The instructions of receiving it, besides [`RESERVE_BASE`].
    #[must_use]
    pub const fn work(&self) -> u32 {
        let n = if self.sensors > MAX_SENSORS {
            MAX_SENSORS as u32
        } else {
            self.sensors as u32
        };
        if self.compact {
            n * RESERVE_PER_SENSOR
        } else {
            RESERVE_F32_FRAME + n * RESERVE_PER_F32_SENSOR
        }
    }
}

/// What a frame's synthesis did, which its share of the reserve depends
/// on: known once it has run, before the solve.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Synthesis {
    /// Its work by the synthesis's own count
    /// ([`Query::work`](crate::grid::Query::work)): the table's window
    /// for every segment and the projection, if it took one.
    pub work: u32,
    /// It had to clamp or project the parameters into the table.
    pub adjusted: bool,
}

/// The solver's work per frame, in the units of
/// [`Report::work`](crate::solve::Report::work), by what the frame needs
/// before the solve: what its synthesis did ([`Synthesis`]) and what it
/// brought ([`Received`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Budget {
    /// A plain frame's (for a rig's budget: the period less
    /// [`RESERVE_BASE`] and [`RESERVE_PER_SEGMENT`]s, before the frame's
    /// own share).
    plain: u32,
    /// An adjusted frame's (likewise).
    adjusted: u32,
    /// A rig's budget: what the frame synthesized and received comes off
    /// it, and a plain frame gets at least [`MIN_SOLVE_BUDGET`]. Otherwise
    /// fixed.
    rig: bool,
}

impl Budget {
    /// The same budget for every frame (`u32::MAX`: no limit).
    #[must_use]
    pub const fn uniform(work: u32) -> Self {
        Self::fixed(work, work)
    }

    /// A fixed budget for plain and adjusted frames, whatever they
    /// synthesized and received.
    #[must_use]
    pub const fn fixed(plain: u32, adjusted: u32) -> Self {
        Budget {
            plain,
            adjusted,
            rig: false,
        }
    }

    /// The budget of a rig of `segments` segments at a frame period of
    /// `period_us` on a board of `clock_hz` ([`solve_budget`]).
    #[must_use]
    pub const fn for_rig(period_us: u32, clock_hz: u32, segments: usize) -> Self {
        let frame = frame_instructions(period_us, clock_hz);
        Budget {
            plain: frame.saturating_sub(rest_reserve(segments, false)),
            adjusted: frame.saturating_sub(rest_reserve(segments, true)),
            rig: true,
        }
    }

    /// A plain frame's budget as given: for a rig's, before what the
    /// frame synthesized and received comes off it, and before the floor.
    #[must_use]
    pub const fn plain(&self) -> u32 {
        self.plain
    }

    /// An adjusted frame's budget as given (likewise).
    #[must_use]
    pub const fn adjusted(&self) -> u32 {
        self.adjusted
    }

    /// What the period leaves the solver of a frame that synthesized
    /// `synthesis` and brought `received`, before the floor (a fixed
    /// budget: as given).
    #[must_use]
    pub const fn left(&self, synthesis: Synthesis, received: Received) -> u32 {
        let given = if synthesis.adjusted {
            self.adjusted
        } else {
            self.plain
        };
        if !self.rig {
            return given;
        }
        given
            .saturating_sub(received.work())
            .saturating_sub(synthesis.work)
    }

    /// The budget of a frame that synthesized `synthesis` and brought
    /// `received`: what the period leaves, for a rig's plain frame at least
    /// [`MIN_SOLVE_BUDGET`].
    #[must_use]
    pub const fn get(&self, synthesis: Synthesis, received: Received) -> u32 {
        self.decide(synthesis, received).0
    }

    /// [`Budget::get`] and [`Budget::may_overrun`] at once (what the live
    /// loop asks every frame).
    #[must_use]
    pub const fn decide(&self, synthesis: Synthesis, received: Received) -> (u32, bool) {
        let left = self.left(synthesis, received);
        if !self.rig {
            return (left, false);
        }
        if synthesis.adjusted || left >= MIN_SOLVE_BUDGET {
            (left, left == 0)
        } else {
            (MIN_SOLVE_BUDGET, true)
        }
    }

    /// Whether a rig's plain frames that synthesized `synthesis` and
    /// brought `received` keep the period: the period leaves their solver
    /// at least [`MIN_SOLVE_BUDGET`], so they never get the floor and
    /// never run over.
    #[must_use]
    pub const fn keeps_period(&self, synthesis: Synthesis, received: Received) -> bool {
        self.left(synthesis, received) >= MIN_SOLVE_BUDGET
    }

    /// Whether a frame that synthesized `synthesis` and brought `received`
    /// may run over its period under a rig's budget: a plain one the period
    /// leaves less than the floor (it gets the floor), or one whose reserve
    /// alone takes the whole period. Never for a fixed budget (its frames
    /// take what the caller gave them).
    #[must_use]
    pub const fn may_overrun(&self, synthesis: Synthesis, received: Received) -> bool {
        self.decide(synthesis, received).1
    }
}

/// The instructions of one frame period on the board.
#[must_use]
pub const fn frame_instructions(period_us: u32, clock_hz: u32) -> u32 {
    let cycles = period_us as u64 * clock_hz as u64 / 1_000_000;
    let instructions = cycles * 100 / CPI_PERCENT as u64;
    if instructions > u32::MAX as u64 {
        u32::MAX
    } else {
        instructions as u32
    }
}

/// The reserve without the frame's own share.
const fn rest_reserve(segments: usize, adjusted: bool) -> u32 {
    let rest = RESERVE_BASE.saturating_add((segments as u32).saturating_mul(RESERVE_PER_SEGMENT));
    if adjusted {
        rest.saturating_add(RESERVE_ADJUSTED)
    } else {
        rest
    }
}

/// The instructions the rest of a frame takes for a rig of `segments`
/// segments, for a frame that synthesized `synthesis` and brought
/// `received`.
#[must_use]
pub const fn reserve(segments: usize, synthesis: Synthesis, received: Received) -> u32 {
    rest_reserve(segments, synthesis.adjusted)
        .saturating_add(received.work())
        .saturating_add(synthesis.work)
}

/// The solver's budget for one frame, in the units of
/// [`Report::work`](crate::solve::Report::work): a frame's instructions less
/// the [`reserve`]; for a plain frame at least [`MIN_SOLVE_BUDGET`]. An
/// adjusted frame may be left too little to solve.
#[must_use]
pub const fn solve_budget(
    period_us: u32,
    clock_hz: u32,
    segments: usize,
    synthesis: Synthesis,
    received: Received,
) -> u32 {
    Budget::for_rig(period_us, clock_hz, segments).get(synthesis, received)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bundled recording's frames: three sensors, compact.
    const THREE: Received = Received {
        sensors: 3,
        compact: true,
    };

    /// A plain synthesis of about the shipped table's work.
    const PLAIN: Synthesis = Synthesis {
        work: 9_000,
        adjusted: false,
    };

    /// An adjusted one, with a projection.
    const ADJUSTED: Synthesis = Synthesis {
        work: 15_000,
        adjusted: true,
    };

    #[test]
    fn one_millisecond_at_100_mhz_is_59523_instructions() {
        // 100,000 cycles / 1.68 = 59,523.8.
        assert_eq!(frame_instructions(1000, 100_000_000), 59_523);
        assert_eq!(frame_instructions(2000, 100_000_000), 119_047);
        assert_eq!(frame_instructions(u32::MAX, u32::MAX), u32::MAX);
    }

    #[test]
    fn the_reserve_counts_segments_the_synthesis_and_what_the_frame_brought() {
        let three = 3 * RESERVE_PER_SENSOR;
        let rest = RESERVE_BASE + 13 * RESERVE_PER_SEGMENT;
        assert_eq!(reserve(13, PLAIN, THREE), rest + 9_000 + three);
        assert_eq!(
            reserve(13, ADJUSTED, THREE),
            rest + RESERVE_ADJUSTED + 15_000 + three
        );
        let f32s = Received {
            sensors: 4,
            compact: false,
        };
        assert_eq!(
            reserve(13, PLAIN, f32s),
            rest + 9_000 + RESERVE_F32_FRAME + 4 * RESERVE_PER_F32_SENSOR
        );
        // No frame carries more than `MAX_SENSORS`.
        let many = |sensors| Received {
            sensors,
            compact: true,
        };
        assert_eq!(many(usize::MAX).work(), many(MAX_SENSORS).work());
        // Nothing wraps.
        let huge = Synthesis {
            work: u32::MAX,
            adjusted: false,
        };
        assert_eq!(reserve(13, huge, THREE), u32::MAX);
    }

    #[test]
    fn the_budget_is_the_period_less_the_reserve_with_a_floor_for_plain_frames() {
        // humanoid16 at 1 kHz: both budgets are the period less the
        // reserve, the plain one above the floor.
        let b = Budget::for_rig(1000, CLOCK_HZ, 13);
        assert_eq!(b.get(PLAIN, THREE), 59_523 - reserve(13, PLAIN, THREE));
        assert_eq!(
            b.get(ADJUSTED, THREE),
            59_523 - reserve(13, ADJUSTED, THREE)
        );
        assert!(b.get(PLAIN, THREE) >= MIN_SOLVE_BUDGET);
        assert!(b.keeps_period(PLAIN, THREE));
        // A heavier synthesis (a finer window) leaves a plain frame the
        // floor, which does not keep the period, and an adjusted one
        // what is left.
        let heavy = Synthesis {
            work: 20_000,
            adjusted: false,
        };
        assert_eq!(b.get(heavy, THREE), MIN_SOLVE_BUDGET);
        assert!(!b.keeps_period(heavy, THREE));
        assert!(b.may_overrun(heavy, THREE));
        assert!(!b.may_overrun(PLAIN, THREE));
        assert!(!b.may_overrun(ADJUSTED, THREE));
        let heavy_adjusted = Synthesis {
            adjusted: true,
            ..heavy
        };
        assert_eq!(
            b.get(heavy_adjusted, THREE),
            59_523 - reserve(13, heavy_adjusted, THREE)
        );
        // A synthesis longer than the period: the floor, or nothing.
        let cubic = Synthesis {
            work: 262_000,
            adjusted: false,
        };
        assert_eq!(b.get(cubic, THREE), MIN_SOLVE_BUDGET);
        let cubic_adjusted = Synthesis {
            adjusted: true,
            ..cubic
        };
        assert_eq!(b.get(cubic_adjusted, THREE), 0);
        assert!(b.may_overrun(cubic_adjusted, THREE));
        // An adjusted frame left less than the floor but more than nothing
        // keeps its period (it solves less).
        assert!(!b.may_overrun(heavy_adjusted, THREE));
        assert!(!Budget::uniform(0).may_overrun(cubic, THREE));
        // A shorter period: the floor on a plain frame, what is left (here
        // nothing) on an adjusted one.
        assert_eq!(
            solve_budget(100, CLOCK_HZ, 13, PLAIN, THREE),
            MIN_SOLVE_BUDGET
        );
        assert_eq!(solve_budget(100, CLOCK_HZ, 13, ADJUSTED, THREE), 0);
        // At 500 Hz: the period less the reserve.
        let b = Budget::for_rig(2000, CLOCK_HZ, 13);
        assert_eq!(b.get(heavy, THREE), 119_047 - reserve(13, heavy, THREE));
        // A fixed budget is what it says, whatever the frame did.
        assert_eq!(Budget::uniform(7).get(cubic_adjusted, THREE), 7);
        assert_eq!(Budget::fixed(5, 6).get(cubic, THREE), 5);
        assert_eq!(Budget::fixed(5, 6).get(ADJUSTED, THREE), 6);
    }
}
