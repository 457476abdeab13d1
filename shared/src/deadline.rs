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
//!          − what the frame brought: RESERVE_PER_SENSOR × sensors (compact), or
//!            RESERVE_F32_FRAME + RESERVE_PER_F32_SENSOR × sensors (f32 frames)
//!          (− ADJUSTED_PER_SEGMENT × segments when the synthesis had to adjust
//!           the parameters, which it knows before the solve),
//!          a plain frame's at least MIN_SOLVE_BUDGET
//! ```
//!
//! A frame's sensors and framing ([`Received`]) are known once it is
//! decoded, so a tracker setup that sends more sensors than the rig reads,
//! or `f32` frames rather than compact ones, gets a solver budget that
//! much smaller, frame by frame, instead of a reserve measured on one
//! recording's frames.
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
//! The floor is for a rig whose period is too short for that: below it the
//! solver cannot take one whole-tree step on a rig like `humanoid16` (its
//! fixed part and one iteration, by the cost model), and a loop that never
//! moves towards its goals is no puppet. Such a rig's plain frames get the
//! floor and may run over their period by up to the difference, bounded by
//! the reserve and the floor; the board counts them in `Telemetry`'s
//! overruns. Its adjusted frames, the hard ones, never get it: they keep
//! what the period leaves, so no frame runs over by more than a plain one.
//! README's "Real time" gives the figures.
//!
//! Every input is the rig's or a constant, so the board, the emulated board
//! and the host's native replay take the same decisions and their outputs
//! stay bit-identical.
//!
//! The reserve is the rest of the frame (receiving and decoding the frame,
//! the sensor map, the synthesis, the servo map): its worst, measured on
//! the emulated board by `tests/realtime.rs` over the bundled recording
//! sent compact and as `f32` frames, the same with a sensor the rig does
//! not read, and four other HDM05 clips recorded at 1 kHz. That test also
//! checks that the reserve bounds every frame's rest, that it is within
//! 5 % of the worst, that the solver keeps its budget on every frame, and
//! that the goals still converge. When a stage gets faster, lower the
//! reserve to its new worst (the same test prints it): the solver gets
//! the difference.

use crate::wire::{MAX_SENSORS, ValidTrackerFrame};

/// The core clock of the board the budget is set for, Hz: the STM32F411
/// Black Pill at 100 MHz (its firmware checks that its clock is this one).
/// The emulated board and the host's native replay use the same budget, so
/// their output stays bit-identical to the board's.
pub const CLOCK_HZ: u32 = 100_000_000;

/// Cycles per instruction the budget assumes, in hundredths: the realistic
/// model of the project's cycle estimator (`../shared/tools/cycles`:
/// Cortex-M4 timings, 3 flash wait states and the ART accelerator) gives
/// 1.37 to 1.73 per stage of the live loop and 1.65 to 1.68 for a whole
/// frame (the mean, the worst and the cold one; README, "Real time"): the
/// largest, rounded up. It does not model interrupts or bus contention: a
/// board's DWT counts (`Telemetry`'s timing) settle it.
pub const CPI_PERCENT: u32 = 168;

/// Instructions of the stages around the solver that grow neither with
/// the rig's segments nor with the frame's sensors: receiving and decoding
/// a frame besides its sensors, the sensor map, the servo map, the loop's
/// own work and the solver's besides its counted work.
pub const RESERVE_BASE: u32 = 8_870;

/// Instructions of the synthesis per segment of the rig when it uses the
/// parameters as given (with [`RESERVE_BASE`], at least the worst rest of
/// a frame `tests/realtime.rs` measures for `humanoid16`'s 13 segments, and
/// within 5 % of it: the test checks both).
pub const RESERVE_PER_SEGMENT: u32 = 1_692;

/// More instructions of the synthesis per segment when it had to clamp or
/// project the parameters into the table (the same rule for the worst rest
/// of such a frame).
pub const ADJUSTED_PER_SEGMENT: u32 = 620;

/// The floor of a plain frame's budget, for a rig whose period is too
/// short: when a plain frame's period less its reserve is below this, its
/// solver gets this much instead (and such a frame may run over its
/// period). It is the fixed
/// part and one iteration with one factorisation pass of the whole-tree
/// solver on `humanoid16`'s four goals, by the cost model
/// (`tests/realtime.rs` checks that just below it no frame of the bundled
/// recording iterates, and that from it up the goals follow).
pub const MIN_SOLVE_BUDGET: u32 = 26_520;

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

/// The solver's work per frame, in the units of
/// [`Report::work`](crate::solve::Report::work), by what the frame needs
/// before the solve: whether its synthesis used the parameters as given
/// ("plain") or had to adjust them, and what it brought ([`Received`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Budget {
    /// A plain frame's (for a rig's budget: before its [`Received`]).
    plain: u32,
    /// An adjusted frame's (likewise).
    adjusted: u32,
    /// A rig's budget: what the frame received comes off it, and a plain
    /// frame gets at least [`MIN_SOLVE_BUDGET`]. Otherwise fixed.
    rig: bool,
}

impl Budget {
    /// The same budget for every frame (`u32::MAX`: no limit).
    #[must_use]
    pub const fn uniform(work: u32) -> Self {
        Self::fixed(work, work)
    }

    /// A fixed budget for plain and adjusted frames, whatever they
    /// received.
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
    /// frame received comes off it and before the floor.
    #[must_use]
    pub const fn plain(&self) -> u32 {
        self.plain
    }

    /// An adjusted frame's budget as given (likewise).
    #[must_use]
    pub const fn adjusted(&self) -> u32 {
        self.adjusted
    }

    /// The budget of a frame whose synthesis adjusted the parameters or
    /// not, and that brought `received`.
    #[must_use]
    pub const fn get(&self, adjusted: bool, received: Received) -> u32 {
        let given = if adjusted { self.adjusted } else { self.plain };
        if !self.rig {
            return given;
        }
        let left = given.saturating_sub(received.work());
        if adjusted || left >= MIN_SOLVE_BUDGET {
            left
        } else {
            MIN_SOLVE_BUDGET
        }
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

/// The reserve without what the frame received.
const fn rest_reserve(segments: usize, adjusted: bool) -> u32 {
    let per = if adjusted {
        RESERVE_PER_SEGMENT + ADJUSTED_PER_SEGMENT
    } else {
        RESERVE_PER_SEGMENT
    };
    RESERVE_BASE.saturating_add((segments as u32).saturating_mul(per))
}

/// The instructions the rest of a frame takes for a rig of `segments`
/// segments, when the synthesis `adjusted` the parameters or not, for a
/// frame that brought `received`.
#[must_use]
pub const fn reserve(segments: usize, adjusted: bool, received: Received) -> u32 {
    rest_reserve(segments, adjusted).saturating_add(received.work())
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
    adjusted: bool,
    received: Received,
) -> u32 {
    Budget::for_rig(period_us, clock_hz, segments).get(adjusted, received)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bundled recording's frames: three sensors, compact.
    const THREE: Received = Received {
        sensors: 3,
        compact: true,
    };

    #[test]
    fn one_millisecond_at_100_mhz_is_59523_instructions() {
        // 100,000 cycles / 1.68 = 59,523.8.
        assert_eq!(frame_instructions(1000, 100_000_000), 59_523);
        assert_eq!(frame_instructions(2000, 100_000_000), 119_047);
        assert_eq!(frame_instructions(u32::MAX, u32::MAX), u32::MAX);
    }

    #[test]
    fn the_reserve_counts_segments_and_what_the_frame_brought() {
        let three = 3 * RESERVE_PER_SENSOR;
        assert_eq!(
            reserve(13, false, THREE),
            RESERVE_BASE + 13 * RESERVE_PER_SEGMENT + three
        );
        assert_eq!(
            reserve(13, true, THREE),
            RESERVE_BASE + 13 * (RESERVE_PER_SEGMENT + ADJUSTED_PER_SEGMENT) + three
        );
        let f32s = Received {
            sensors: 4,
            compact: false,
        };
        assert_eq!(
            reserve(13, false, f32s),
            reserve(13, false, THREE) - three + RESERVE_F32_FRAME + 4 * RESERVE_PER_F32_SENSOR
        );
        // No frame carries more than `MAX_SENSORS`.
        let many = |sensors| Received {
            sensors,
            compact: true,
        };
        assert_eq!(many(usize::MAX).work(), many(MAX_SENSORS).work());
    }

    #[test]
    fn the_budget_is_the_period_less_the_reserve_with_a_floor_for_plain_frames() {
        // humanoid16 at 1 kHz with the recording's frames: a plain frame is
        // left at least the floor, so both budgets are the period less the
        // reserve.
        let b = Budget::for_rig(1000, CLOCK_HZ, 13);
        assert_eq!(b.get(false, THREE), 59_523 - reserve(13, false, THREE));
        assert_eq!(b.get(true, THREE), 59_523 - reserve(13, true, THREE));
        assert!(b.get(false, THREE) >= MIN_SOLVE_BUDGET);
        assert!(b.get(true, THREE) < MIN_SOLVE_BUDGET);
        // One more sensor leaves a plain frame the floor, and an adjusted
        // one what is left.
        let four = Received {
            sensors: 4,
            compact: true,
        };
        assert_eq!(b.get(false, four), MIN_SOLVE_BUDGET);
        assert_eq!(b.get(true, four), 59_523 - reserve(13, true, four));
        // A period that leaves a plain frame less: the floor on a plain
        // frame, what is left (here nothing) on an adjusted one.
        let short = Budget::for_rig(900, CLOCK_HZ, 13);
        assert_eq!(short.get(false, THREE), MIN_SOLVE_BUDGET);
        assert_eq!(short.get(true, THREE), 53_571 - reserve(13, true, THREE));
        assert_eq!(
            solve_budget(100, CLOCK_HZ, 13, false, THREE),
            MIN_SOLVE_BUDGET
        );
        assert_eq!(solve_budget(100, CLOCK_HZ, 13, true, THREE), 0);
        // At 500 Hz: the period less the reserve.
        let b = Budget::for_rig(2000, CLOCK_HZ, 13);
        assert_eq!(b.get(false, THREE), 119_047 - reserve(13, false, THREE));
        assert_eq!(b.get(true, THREE), 119_047 - reserve(13, true, THREE));
        // A fixed budget is what it says, whatever the frame brought.
        assert_eq!(Budget::uniform(7).get(true, four), 7);
        assert_eq!(Budget::fixed(5, 6).get(false, four), 5);
    }
}
