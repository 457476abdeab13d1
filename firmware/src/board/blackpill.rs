//! The real board: STM32F411CEU6 "Black Pill" (Cortex-M4F at 100 MHz, 25 MHz
//! crystal, 512 KB flash, 128 KB RAM), probe-rs chip `STM32F411CEUx`.
//!
//! | link | peripheral | pins (AF7) | rate |
//! |---|---|---|---|
//! | tracker | USART1 (APB2, 100 MHz) | PA9 TX, PA10 RX | 921 600 bit/s (−0.45 %) |
//!
//! The servo outputs are whichever back-end the rig names, chosen at run
//! time ([`servo`]): a Pololu Maestro or bus servos on USART2 (PA2), a
//! PCA9685 on I2C1 ([`i2c`]: PB6, PB7), or timer PWM on TIM2..TIM4
//! ([`timers`], 12 channels).
//!
//! Everything is programmed through the PAC with compile-time constants
//! ([`clock`], [`uart`], [`watchdog`]): the HAL's clock and serial set-up keep
//! panicking branches that `panic-never` rejects in release builds. Logging is
//! defmt over RTT through this crate's own panic-free logger ([`rtt`]).
//!
//! The independent watchdog resets the chip if the loop stops feeding it for
//! about 100 ms (it is frozen while a debugger halts the core); a Pololu
//! Maestro holds its last targets meanwhile (unless its own serial timeout is
//! set). Time comes from the DWT cycle counter.

pub mod clock;
pub mod i2c;
pub mod rtt;
pub mod servo;
pub mod timers;
pub mod uart;
pub mod watchdog;

use super::{Board, Outcome};
use cortex_m::peripheral::DWT;
use marionette_core::output::support::UartRate;
use marionette_core::output::support::{uart_divisor, uart_error_permille};
use marionette_core::output::{Refusal, Support};
use marionette_core::rig::{Output, ServoDesc};
use stm32f4::stm32f411 as pac;
use uart::Uart;
use watchdog::Watchdog;

pub use clock::SYSCLK_HZ;
pub use watchdog::TIMEOUT_MS as WATCHDOG_MS;

/// Tracker link rate, bit/s.
pub const TRACKER_BAUD: u32 = 921_600;

const TRACKER_BRR: u16 = uart_divisor(clock::PCLK2_HZ, TRACKER_BAUD);
// Both ends of a UART link tolerate a few percent in total; keep ours under 1 %.
const _: () = assert!(uart_error_permille(clock::PCLK2_HZ, TRACKER_BAUD, TRACKER_BRR) < 10);
// 16× oversampling needs USARTDIV >= 1.
const _: () = assert!(TRACKER_BRR >= 16);
// The core's description of this board: USART2 on PCLK1.
const _: () = assert!(matches!(
    Support::BLACKPILL.uart,
    UartRate::Clock(clock::PCLK1_HZ)
));

/// DWT cycles per microsecond.
const CYCLES_PER_US: u32 = SYSCLK_HZ / 1_000_000;
const _: () = assert!(SYSCLK_HZ.is_multiple_of(1_000_000));

/// Why the board could not start.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum InitError {
    /// The peripherals were already taken.
    Taken,
    /// The 25 MHz crystal did not start.
    Crystal,
    /// Flash did not accept the wait states for 100 MHz.
    FlashLatency,
    /// The PLL did not lock.
    Pll,
    /// The regulator did not reach scale 1.
    Regulator,
    /// SYSCLK did not switch to the PLL.
    Switch,
}

/// What caused the last reset, from the RCC reset flags (most specific first).
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum ResetCause {
    /// The independent watchdog fired: the loop stalled.
    Watchdog,
    /// The window watchdog fired.
    WindowWatchdog,
    /// Software reset (a debugger's reset usually shows up here).
    Software,
    /// Low-power management reset.
    LowPower,
    /// Power-on (or power-down) reset.
    PowerOn,
    /// Brown-out: the supply dipped.
    BrownOut,
    /// The NRST pin.
    Pin,
    /// No flag was set.
    Unknown,
}

impl ResetCause {
    /// Reads the reset flags, then clears them for the next reset.
    fn take(rcc: &pac::RCC) -> Self {
        let csr = rcc.csr().read();
        let cause = if csr.wdgrstf().is_reset() {
            Self::Watchdog
        } else if csr.wwdgrstf().is_reset() {
            Self::WindowWatchdog
        } else if csr.sftrstf().is_reset() {
            Self::Software
        } else if csr.lpwrrstf().is_reset() {
            Self::LowPower
        } else if csr.porrstf().is_reset() {
            Self::PowerOn
        } else if csr.borrstf().is_reset() {
            Self::BrownOut
        } else if csr.padrstf().is_reset() {
            Self::Pin
        } else {
            Self::Unknown
        };
        rcc.csr().modify(|_, w| w.rmvf().clear());
        cause
    }
}

/// Microseconds from the DWT cycle counter, which wraps every 43 s at
/// 100 MHz. Each update folds the cycles since the previous one into a
/// microsecond count and a sub-microsecond remainder, so the count stays
/// exact as long as updates come at least once per wrap (the watchdog feed
/// does one).
struct Micros {
    last: u32,
    us: u32,
    rem: u32,
}

impl Micros {
    fn start() -> Self {
        Self {
            last: DWT::cycle_count(),
            us: 0,
            rem: 0,
        }
    }

    fn update(&mut self) -> u32 {
        let now = DWT::cycle_count();
        let delta = now.wrapping_sub(self.last);
        self.last = now;
        // rem < CYCLES_PER_US before and after, so the sum cannot overflow.
        let rem = self.rem + delta % CYCLES_PER_US;
        self.us = self
            .us
            .wrapping_add(delta / CYCLES_PER_US + rem / CYCLES_PER_US);
        self.rem = rem % CYCLES_PER_US;
        self.us
    }
}

/// Routes PA2/PA3 (USART2) and PA9/PA10 (USART1) to alternate function 7,
/// with pull-ups on the receive pins so an unplugged link idles high.
fn route_pins(gpioa: &pac::GPIOA) {
    gpioa.afrl().modify(|_, w| w.afrl2().af7().afrl3().af7());
    gpioa.afrh().modify(|_, w| w.afrh9().af7().afrh10().af7());
    // PA0, the KEY button to ground (an input at reset): pulled up.
    gpioa
        .pupdr()
        .modify(|_, w| w.pupdr0().pull_up().pupdr3().pull_up().pupdr10().pull_up());
    gpioa
        .ospeedr()
        .modify(|_, w| w.ospeedr2().medium_speed().ospeedr9().medium_speed());
    gpioa.moder().modify(|_, w| {
        w.moder2().alternate().moder3().alternate();
        w.moder9().alternate().moder10().alternate()
    });
}

/// The Black Pill board.
pub struct BlackPill {
    tracker: Uart<pac::USART1>,
    servo: servo::Servos,
    watchdog: Watchdog,
    micros: Micros,
    reset_cause: ResetCause,
    /// Since when the show button has been held (µs), and whether this
    /// press was reported.
    key: Option<(u32, bool)>,
}

/// How long the show button must be held to count, µs.
const KEY_DEBOUNCE_US: u32 = 20_000;

impl BlackPill {
    /// Clocks the chip at 100 MHz from the 25 MHz crystal, opens both links
    /// and starts the watchdog (last, so that a failed start-up parks
    /// instead of resetting in a loop).
    pub fn init() -> Result<Self, InitError> {
        let mut cp = cortex_m::Peripherals::take().ok_or(InitError::Taken)?;
        let dp = pac::Peripherals::take().ok_or(InitError::Taken)?;
        let reset_cause = ResetCause::take(&dp.RCC);
        clock::setup(&dp.RCC, &dp.FLASH, &dp.PWR)?;

        cp.DCB.enable_trace();
        cp.DWT.enable_cycle_counter();

        dp.RCC.ahb1enr().modify(|_, w| w.gpioaen().enabled());
        servo::enable_clocks(&dp.RCC);
        dp.RCC.apb2enr().modify(|_, w| w.usart1en().enabled());
        // Read back: a peripheral's registers need two bus cycles after its clock is enabled.
        let _ = dp.RCC.apb2enr().read();
        route_pins(&dp.GPIOA);
        let tracker = Uart::new(dp.USART1, TRACKER_BRR);
        let buffer = cortex_m::singleton!(: [u8; servo::TX_BUFFER] = [0; servo::TX_BUFFER])
            .ok_or(InitError::Taken)?;
        let servo = servo::Servos::new(servo::Parts {
            usart2: dp.USART2,
            dma1: dp.DMA1,
            i2c1: dp.I2C1,
            timers: (dp.TIM2, dp.TIM3, dp.TIM4),
            gpioa: dp.GPIOA,
            gpiob: dp.GPIOB,
            buffer,
        });

        // Keep the watchdog from resetting the chip while a debugger halts it.
        dp.DBGMCU
            .apb1_fz()
            .modify(|_, w| w.dbg_iwdg_stop().set_bit());
        let watchdog = Watchdog::start(dp.IWDG);
        Ok(Self {
            tracker,
            servo,
            watchdog,
            micros: Micros::start(),
            reset_cause,
            key: None,
        })
    }

    /// What caused the reset before this start.
    #[must_use]
    pub const fn reset_cause(&self) -> ResetCause {
        self.reset_cause
    }

    /// Whether the watchdog runs with its nominal period (see
    /// [`Watchdog::is_configured`]).
    #[must_use]
    pub const fn watchdog_configured(&self) -> bool {
        self.watchdog.is_configured()
    }
}

impl Board for BlackPill {
    type Tracker = Uart<pac::USART1>;
    type Servos = servo::Servos;

    fn links(&mut self) -> (&mut Self::Tracker, &mut Self::Servos) {
        (&mut self.tracker, &mut self.servo)
    }

    fn open_servos(&mut self, output: &Output, servos: &[ServoDesc]) -> Result<(), Refusal> {
        self.servo.open(output, servos)
    }

    fn servos_ready(&mut self) -> bool {
        let now = self.micros.update();
        self.servo.ready(now)
    }

    /// Every back-end: UART (Maestro, Dynamixel, Feetech), PCA9685, PWM.
    const SUPPORT: Support = Support::BLACKPILL;

    fn tables(&self) -> &'static [u8] {
        crate::region::tables()
    }

    fn now_us(&mut self) -> u32 {
        self.micros.update()
    }

    fn cycles(&mut self) -> u32 {
        cortex_m::peripheral::DWT::cycle_count()
    }

    fn show_button(&mut self) -> bool {
        if !self.servo.key_down() {
            self.key = None;
            return false;
        }
        let now = self.micros.update();
        let (since, reported) = self.key.unwrap_or((now, false));
        let fire = !reported && now.wrapping_sub(since) >= KEY_DEBOUNCE_US;
        self.key = Some((since, reported || fire));
        fire
    }

    fn feed_watchdog(&mut self) {
        self.watchdog.feed();
        // The loop feeds far more often than the 43 s counter wrap.
        self.micros.update();
    }

    fn finish(&mut self, outcome: Outcome) -> ! {
        self.servo.flush();
        defmt::warn!(
            "session ended: status {}, {} log frames dropped",
            outcome.exit_status(),
            rtt::dropped_frames()
        );
        // The servos hold their last command. Keep feeding the watchdog: the
        // board is idle, not stuck. (No interrupt is enabled, so `wfi` would
        // never wake up to feed it.)
        loop {
            self.feed_watchdog();
            cortex_m::asm::delay(SYSCLK_HZ / 1000);
        }
    }
}
