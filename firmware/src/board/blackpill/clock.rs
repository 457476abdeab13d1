//! Clock tree: 100 MHz SYSCLK from the Black Pill's 25 MHz crystal.
//!
//! Every divider is a compile-time constant checked against the limits of the
//! STM32F411 reference manual (RM0383) by `const` assertions, so the run-time
//! code is a fixed sequence of register writes with bounded waits: there is no
//! arithmetic that could fail.
//!
//! | clock | source | Hz |
//! |---|---|---|
//! | HSE | crystal | 25 MHz |
//! | PLL input | HSE / M (M = 25) | 1 MHz |
//! | VCO | × N (N = 400) | 400 MHz |
//! | SYSCLK = HCLK | VCO / P (P = 4) | 100 MHz |
//! | PCLK1 (APB1: USART2, IWDG bus) | HCLK / 2 | 50 MHz |
//! | PCLK2 (APB2: USART1) | HCLK / 1 | 100 MHz |
//! | PLL48CK (USB, unused) | VCO / Q (Q = 8) | 50 MHz |

use super::InitError;
use stm32f4::stm32f411 as pac;

/// Crystal frequency of the Black Pill, Hz.
pub const HSE_HZ: u32 = 25_000_000;
/// PLL input divider M (RM0383: 2..=63, PLL input 1..=2 MHz).
const PLL_M: u8 = 25;
/// PLL multiplier N (RM0383: 50..=432, VCO output 100..=432 MHz).
const PLL_N: u16 = 400;
/// PLL main output divider P (one of 2, 4, 6, 8; the register writes P = 4).
const PLL_P: u32 = 4;
/// PLL divider Q for the 48 MHz domain (RM0383: 2..=15). USB is not used, so
/// any valid value does; 8 keeps it at 50 MHz.
const PLL_Q: u8 = 8;

/// PLL input, Hz.
const PLL_IN_HZ: u32 = HSE_HZ / PLL_M as u32;
/// VCO output, Hz.
const VCO_HZ: u32 = PLL_IN_HZ * PLL_N as u32;
/// System (core) clock, Hz.
pub const SYSCLK_HZ: u32 = VCO_HZ / PLL_P;
/// AHB clock, Hz (HPRE = 1).
pub const HCLK_HZ: u32 = SYSCLK_HZ;
/// APB1 clock, Hz (PPRE1 = 2): USART2.
pub const PCLK1_HZ: u32 = HCLK_HZ / 2;
/// APB2 clock, Hz (PPRE2 = 1): USART1.
pub const PCLK2_HZ: u32 = HCLK_HZ;

const _: () = assert!(HSE_HZ.is_multiple_of(PLL_M as u32));
const _: () = assert!(PLL_M >= 2 && PLL_M <= 63);
const _: () = assert!(PLL_IN_HZ >= 1_000_000 && PLL_IN_HZ <= 2_000_000);
const _: () = assert!(PLL_N >= 50 && PLL_N <= 432);
const _: () = assert!(VCO_HZ >= 100_000_000 && VCO_HZ <= 432_000_000);
const _: () = assert!(PLL_Q >= 2 && PLL_Q <= 15);
const _: () = assert!(SYSCLK_HZ == 100_000_000);
// The live loop's solver budget is set for this clock (core `deadline`).
const _: () = assert!(SYSCLK_HZ == marionette_core::deadline::CLOCK_HZ);
// RM0383: APB1 at most 50 MHz, APB2 at most 100 MHz.
const _: () = assert!(PCLK1_HZ <= 50_000_000 && PCLK2_HZ <= 100_000_000);
// RM0383 table 5 (2.7..3.6 V): 90 MHz < HCLK <= 100 MHz needs 3 wait states,
// which `setup` programs.
const _: () = assert!(HCLK_HZ > 90_000_000 && HCLK_HZ <= 100_000_000);
const FLASH_WAIT_STATES: u8 = 3;

/// Polls of a ready flag before giving up. At the 16 MHz reset clock this is
/// well over 100 ms, against a crystal start-up time of a few milliseconds.
const SPINS: u32 = 2_000_000;

/// Polls `ready` at most [`SPINS`] times.
fn wait_for(mut ready: impl FnMut() -> bool, error: InitError) -> Result<(), InitError> {
    for _ in 0..SPINS {
        if ready() {
            return Ok(());
        }
    }
    Err(error)
}

/// Switches SYSCLK from the 16 MHz internal oscillator to the PLL at 100 MHz.
///
/// Order per RM0383 §6.3: crystal on; regulator scale 1 (only writable while
/// the PLL is off); flash wait states raised *before* the clock; bus
/// prescalers; PLL on; switch.
pub fn setup(rcc: &pac::RCC, flash: &pac::FLASH, pwr: &pac::PWR) -> Result<(), InitError> {
    rcc.cr().modify(|_, w| w.hseon().on());
    wait_for(|| rcc.cr().read().hserdy().is_ready(), InitError::Crystal)?;

    rcc.apb1enr().modify(|_, w| w.pwren().enabled());
    // Read back: a peripheral's registers need two bus cycles after its clock is enabled.
    let _ = rcc.apb1enr().read();
    pwr.cr().modify(|_, w| w.vos().scale1());

    flash.acr().write(|w| {
        w.latency().set(FLASH_WAIT_STATES);
        w.prften().enabled().icen().enabled().dcen().enabled()
    });
    if flash.acr().read().latency().bits() != FLASH_WAIT_STATES {
        return Err(InitError::FlashLatency);
    }

    rcc.cfgr()
        .modify(|_, w| w.hpre().div1().ppre1().div2().ppre2().div1());
    rcc.pllcfgr().write(|w| {
        // SAFETY: PLLM, PLLN and PLLQ take raw bits; the values are the
        // constants above, checked against their RM0383 ranges at compile time.
        unsafe { w.pllm().bits(PLL_M).plln().bits(PLL_N).pllq().bits(PLL_Q) };
        w.pllp().div4().pllsrc().hse()
    });
    rcc.cr().modify(|_, w| w.pllon().on());
    wait_for(|| rcc.cr().read().pllrdy().is_ready(), InitError::Pll)?;
    wait_for(
        || pwr.csr().read().vosrdy().bit_is_set(),
        InitError::Regulator,
    )?;

    rcc.cfgr().modify(|_, w| w.sw().pll());
    wait_for(|| rcc.cfgr().read().sws().is_pll(), InitError::Switch)
}
