//! Deterministic instruction counts on the emulated board.
//!
//! QEMU does not model cycle timing, and DWT CYCCNT reads 0. Run instead with
//! `-icount shift=7,align=off`: every instruction then advances virtual time by
//! 2^7 ns, and SysTick, clocked by the 25 MHz core clock, ticks 3.2 times per
//! instruction. A region's instruction count is its SysTick delta / 3.2, less
//! the delta of an empty region measured the same way.
//!
//! SysTick is 24 bits wide, so one region may span at most about 5.2 million
//! instructions. These are instruction counts, not Cortex-M4 cycles.

use cortex_m::peripheral::SYST;
use cortex_m::peripheral::syst::SystClkSource;

/// SysTick reload value: the full 24-bit range.
const RELOAD: u32 = 0x00FF_FFFF;

/// Times regions of code in SysTick ticks.
pub struct Counter {
    syst: SYST,
    overhead: u32,
}

impl Counter {
    /// Starts SysTick free-running from the core clock (RVR = 0xFFFFFF,
    /// CSR = 0b101) and measures the cost of an empty region.
    #[must_use]
    pub fn new(mut syst: SYST) -> Self {
        syst.set_reload(RELOAD);
        syst.clear_current();
        syst.set_clock_source(SystClkSource::Core);
        syst.disable_interrupt();
        syst.enable_counter();
        let mut counter = Self { syst, overhead: 0 };
        counter.overhead = counter.raw_ticks(|| ());
        counter
    }

    #[inline(always)]
    fn raw_ticks<R>(&mut self, f: impl FnOnce() -> R) -> u32 {
        self.syst.clear_current();
        let start = SYST::get_current();
        let r = f();
        let end = SYST::get_current();
        core::hint::black_box(r);
        start.wrapping_sub(end) & RELOAD
    }

    /// SysTick ticks spent in `f`, less the empty-region overhead.
    #[inline(always)]
    pub fn ticks<R>(&mut self, f: impl FnOnce() -> R) -> u32 {
        self.raw_ticks(f).saturating_sub(self.overhead)
    }

    /// The overhead subtracted from every measurement, in ticks.
    #[must_use]
    pub fn overhead(&self) -> u32 {
        self.overhead
    }
}

/// Converts SysTick ticks under `-icount shift=7` to instructions (ticks / 3.2),
/// rounded to nearest.
#[must_use]
pub const fn instructions(ticks: u32) -> u32 {
    ((ticks as u64 * 5 + 8) / 16) as u32
}
