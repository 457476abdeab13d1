//! The independent watchdog (IWDG), clocked by the ~32 kHz internal LSI.
//!
//! Once started it cannot be stopped; only a reset does. The LSI is not
//! trimmed (datasheet: 17..47 kHz), so the nominal [`TIMEOUT_MS`] is really
//! somewhere between about 68 ms and 190 ms.

use stm32f4::stm32f411 as pac;

/// Nominal timeout, ms.
pub const TIMEOUT_MS: u32 = 100;
/// Nominal LSI frequency, Hz.
const LSI_HZ: u32 = 32_000;
/// The prescaler `start` selects (`divide_by4`).
const PRESCALER: u32 = 4;
/// Reload value: the counter runs from RELOAD down to 0, i.e. RELOAD + 1 ticks.
const RELOAD: u16 = (TIMEOUT_MS * LSI_HZ / PRESCALER / 1000 - 1) as u16;
const _: () = assert!(TIMEOUT_MS * LSI_HZ / PRESCALER / 1000 - 1 <= 0xFFF);

/// Polls of the register-update flags before giving up. An update takes up
/// to a few LSI periods (hundreds of microseconds at 100 MHz).
const SPINS: u32 = 2_000_000;

/// The running watchdog.
pub struct Watchdog {
    iwdg: pac::IWDG,
    configured: bool,
}

impl Watchdog {
    /// Starts the watchdog with a [`TIMEOUT_MS`] timeout.
    ///
    /// Starting also switches the LSI on; the prescaler and reload registers
    /// are written after the unlock key and take effect once the PVU/RVU
    /// flags clear. If they never do, the watchdog still runs, with its reset
    /// period (about 512 ms); [`Watchdog::is_configured`] then says `false`.
    #[must_use]
    pub fn start(iwdg: pac::IWDG) -> Self {
        iwdg.kr().write(|w| w.key().start());
        iwdg.kr().write(|w| w.key().unlock());
        iwdg.pr().write(|w| w.pr().divide_by4());
        iwdg.rlr().write(|w| w.rl().set(RELOAD));
        let configured = (0..SPINS).any(|_| {
            let sr = iwdg.sr().read();
            sr.pvu().bit_is_clear() && sr.rvu().bit_is_clear()
        });
        let mut watchdog = Self { iwdg, configured };
        // Reload now, so the new period counts from here; this also relocks
        // the prescaler and reload registers.
        watchdog.feed();
        watchdog
    }

    /// Whether the [`TIMEOUT_MS`] period took effect.
    #[must_use]
    pub const fn is_configured(&self) -> bool {
        self.configured
    }

    /// Restarts the countdown.
    #[inline]
    pub fn feed(&mut self) {
        self.iwdg.kr().write(|w| w.key().feed());
    }
}
