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
//!          (− ADJUSTED_PER_SEGMENT × segments when the synthesis had to adjust
//!           the parameters, which it knows before the solve),
//!          a plain frame's at least MIN_SOLVE_BUDGET
//! ```
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
//! the sensor map, the synthesis, the servo map): its worst over the bundled
//! recording, measured on the emulated board by `tests/realtime.rs`, which
//! also checks that the reserve bounds it, that the solver keeps its budget
//! on every frame, and that the goals still converge. When a stage gets
//! faster, lower the reserve to its new worst (the same test prints it):
//! the solver gets the difference.

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

/// Instructions of the stages around the solver that do not grow with the
/// rig's segments: receiving and decoding a frame, the sensor map, the
/// servo map, the loop's own work and the solver's besides its counted
/// work.
pub const RESERVE_BASE: u32 = 11_000;

/// Instructions of the synthesis per segment of the rig when it uses the
/// parameters as given (with [`RESERVE_BASE`], at least the worst rest of
/// a frame `tests/realtime.rs` measures for `humanoid16`'s 13 segments, and
/// within 5 % of it: the test checks both).
pub const RESERVE_PER_SEGMENT: u32 = 1_692;

/// More instructions of the synthesis per segment when it had to clamp or
/// project the parameters into the table (the same rule for the worst rest
/// of such a frame).
pub const ADJUSTED_PER_SEGMENT: u32 = 512;

/// The floor of a plain frame's budget, for a rig whose period is too
/// short: when a plain frame's period less its reserve is below this, its
/// solver gets this much instead (and such a frame may run over its
/// period). It is the fixed
/// part and one iteration with one factorisation pass of the whole-tree
/// solver on `humanoid16`'s four goals, by the cost model
/// (`tests/realtime.rs` checks that just below it no frame of the bundled
/// recording iterates, and that from it up the goals follow).
pub const MIN_SOLVE_BUDGET: u32 = 26_520;

/// The solver's work per frame, in the units of
/// [`Report::work`](crate::solve::Report::work): one for a frame whose
/// synthesis used the parameters as given, one for a frame where it had to
/// adjust them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Budget {
    /// The synthesis used the parameters as given.
    pub plain: u32,
    /// The synthesis clamped or projected them.
    pub adjusted: u32,
}

impl Budget {
    /// The same budget for every frame (`u32::MAX`: no limit).
    #[must_use]
    pub const fn uniform(work: u32) -> Self {
        Budget {
            plain: work,
            adjusted: work,
        }
    }

    /// The budget of a rig of `segments` segments at a frame period of
    /// `period_us` on a board of `clock_hz` ([`solve_budget`]).
    #[must_use]
    pub const fn for_rig(period_us: u32, clock_hz: u32, segments: usize) -> Self {
        Budget {
            plain: solve_budget(period_us, clock_hz, segments, false),
            adjusted: solve_budget(period_us, clock_hz, segments, true),
        }
    }

    /// The budget of a frame whose synthesis adjusted the parameters or not.
    #[inline]
    #[must_use]
    pub const fn get(&self, adjusted: bool) -> u32 {
        if adjusted { self.adjusted } else { self.plain }
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

/// The instructions the rest of a frame takes for a rig of `segments`
/// segments, when the synthesis `adjusted` the parameters or not.
#[must_use]
pub const fn reserve(segments: usize, adjusted: bool) -> u32 {
    let per = if adjusted {
        RESERVE_PER_SEGMENT + ADJUSTED_PER_SEGMENT
    } else {
        RESERVE_PER_SEGMENT
    };
    RESERVE_BASE.saturating_add((segments as u32).saturating_mul(per))
}

/// The solver's budget for one frame, in the units of
/// [`Report::work`](crate::solve::Report::work): a frame's instructions less
/// the [`reserve`]; for a plain frame at least [`MIN_SOLVE_BUDGET`]. An
/// adjusted frame may be left too little to solve.
#[must_use]
pub const fn solve_budget(period_us: u32, clock_hz: u32, segments: usize, adjusted: bool) -> u32 {
    let left = frame_instructions(period_us, clock_hz).saturating_sub(reserve(segments, adjusted));
    if adjusted || left >= MIN_SOLVE_BUDGET {
        left
    } else {
        MIN_SOLVE_BUDGET
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_millisecond_at_100_mhz_is_59523_instructions() {
        // 100,000 cycles / 1.68 = 59,523.8.
        assert_eq!(frame_instructions(1000, 100_000_000), 59_523);
        assert_eq!(frame_instructions(2000, 100_000_000), 119_047);
        assert_eq!(frame_instructions(u32::MAX, u32::MAX), u32::MAX);
        assert_eq!(reserve(13, false), 11_000 + 13 * RESERVE_PER_SEGMENT);
        assert_eq!(
            reserve(13, true),
            11_000 + 13 * (RESERVE_PER_SEGMENT + ADJUSTED_PER_SEGMENT)
        );
        // humanoid16 at 1 kHz: a plain frame is left at least the floor, so
        // both budgets are the period less the reserve.
        let b = Budget::for_rig(1000, CLOCK_HZ, 13);
        assert_eq!(b.get(false), 59_523 - reserve(13, false));
        assert_eq!(b.get(true), 59_523 - reserve(13, true));
        assert!(b.get(false) >= MIN_SOLVE_BUDGET && b.get(true) < MIN_SOLVE_BUDGET);
        // A period that leaves a plain frame less: the floor on a plain
        // frame, what is left (here nothing) on an adjusted one.
        let short = Budget::for_rig(900, CLOCK_HZ, 13);
        assert_eq!(short.get(false), MIN_SOLVE_BUDGET);
        assert_eq!(short.get(true), 53_571 - reserve(13, true));
        assert_eq!(solve_budget(100, CLOCK_HZ, 13, false), MIN_SOLVE_BUDGET);
        assert_eq!(solve_budget(100, CLOCK_HZ, 13, true), 0);
        // At 500 Hz: the period less the reserve.
        let b = Budget::for_rig(2000, CLOCK_HZ, 13);
        assert_eq!(b.get(false), 119_047 - reserve(13, false));
        assert_eq!(b.get(true), 119_047 - reserve(13, true));
        assert_eq!(Budget::uniform(7).get(true), 7);
    }
}
