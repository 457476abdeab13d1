//! On-chip servo PWM: TIM2, TIM3 and TIM4, four channels each, 12 servos.
//!
//! | servo channel | timer channel | pin (alternate function) |
//! |---|---|---|
//! | 0, 1, 2, 3 | TIM2 CH1, CH2, CH3, CH4 | PA5, PA1, PA2, PA3 (AF1) |
//! | 4, 5, 6, 7 | TIM3 CH1, CH2, CH3, CH4 | PA6, PA7, PB0, PB1 (AF2) |
//! | 8, 9, 10, 11 | TIM4 CH1, CH2, CH3, CH4 | PB6, PB7, PB8, PB9 (AF2) |
//!
//! (PA0, TIM2 CH1's other pin, is the board's KEY button, hence PA5. PA2,
//! PA3 and PB6, PB7 are the servo UART's and the I2C bus' pins too: one
//! back-end runs at a time, chosen by the rig, and routes its own pins.)
//!
//! The three timers run on the 100 MHz APB1 timer clock (PCLK1 × 2) with the
//! prescaler and period of the core's [`TimerSetup`] for the rig's frame
//! rate (better than 1 µs per tick over 50–333 Hz), in PWM mode 1 with
//! preloaded compare registers, so a new pulse width starts with the next
//! period and never cuts one short. Every compare register is 0 (no pulse)
//! until the first frame: the pins stay low until the rig is armed.

use embedded_hal::pwm::{ErrorType, SetDutyCycle};
use marionette_core::output::pwm::TimerSetup;
use stm32f4::stm32f411 as pac;

/// The timer clock, Hz (APB1 at 50 MHz, timers doubled).
pub const TIMER_CLOCK_HZ: u32 = 100_000_000;
/// Servo channels of the three timers.
pub const CHANNELS: usize = 12;

/// The three servo timers.
pub struct Timers {
    tim2: pac::TIM2,
    tim3: pac::TIM3,
    tim4: pac::TIM4,
    period: u16,
}

/// Which timer a servo channel is on.
#[derive(Clone, Copy)]
enum Which {
    Tim2,
    Tim3,
    Tim4,
}

impl Timers {
    /// Starts the timers for `setup`, every output low, and routes the
    /// pins. The caller has enabled the timers' and GPIOs' clocks.
    pub fn new(
        (tim2, tim3, tim4): (pac::TIM2, pac::TIM3, pac::TIM4),
        setup: TimerSetup,
        gpioa: &pac::GPIOA,
        gpiob: &pac::GPIOB,
    ) -> Self {
        let psc = u16::try_from(setup.divider.saturating_sub(1)).unwrap_or(u16::MAX);
        let arr = setup.period.saturating_sub(1);
        tim2.cr1().reset();
        tim2.psc().write(|w| w.psc().set(psc));
        tim2.arr().write(|w| w.arr().set(u32::from(arr)));
        tim2.ccmr1_output().write(|w| {
            w.oc1m().pwm_mode1().oc1pe().enabled();
            w.oc2m().pwm_mode1().oc2pe().enabled()
        });
        tim2.ccmr2_output().write(|w| {
            w.oc3m().pwm_mode1().oc3pe().enabled();
            w.oc4m().pwm_mode1().oc4pe().enabled()
        });
        tim2.ccer().write(|w| {
            w.cc1e().set_bit().cc2e().set_bit();
            w.cc3e().set_bit().cc4e().set_bit()
        });
        tim2.cr1().write(|w| w.arpe().enabled());
        tim2.egr().write(|w| w.ug().set_bit());
        tim2.cr1().modify(|_, w| w.cen().enabled());
        for t in [&*tim3, &*tim4] {
            start16(t, psc, arr);
        }
        route(gpioa, gpiob);
        Self {
            tim2,
            tim3,
            tim4,
            period: setup.period,
        }
    }

    /// The twelve channels, for the core's [`marionette_core::output::Pwm`].
    pub fn channels(&mut self) -> [TimerChannel<'_>; CHANNELS] {
        let timers = &*self;
        core::array::from_fn(|i| TimerChannel {
            timers,
            which: match i / 4 {
                0 => Which::Tim2,
                1 => Which::Tim3,
                _ => Which::Tim4,
            },
            channel: (i % 4) as u8,
        })
    }
}

/// Starts a 16-bit timer (TIM3, TIM4) like TIM2.
fn start16(t: &pac::tim3::RegisterBlock, psc: u16, arr: u16) {
    t.cr1().reset();
    t.psc().write(|w| w.psc().set(psc));
    t.arr().write(|w| w.arr().set(arr));
    t.ccmr1_output().write(|w| {
        w.oc1m().pwm_mode1().oc1pe().enabled();
        w.oc2m().pwm_mode1().oc2pe().enabled()
    });
    t.ccmr2_output().write(|w| {
        w.oc3m().pwm_mode1().oc3pe().enabled();
        w.oc4m().pwm_mode1().oc4pe().enabled()
    });
    t.ccer().write(|w| {
        w.cc1e().set_bit().cc2e().set_bit();
        w.cc3e().set_bit().cc4e().set_bit()
    });
    t.cr1().write(|w| w.arpe().enabled());
    t.egr().write(|w| w.ug().set_bit());
    t.cr1().modify(|_, w| w.cen().enabled());
}

/// PA1, PA2, PA3, PA5 to AF1 (TIM2); PA6, PA7, PB0, PB1 to AF2 (TIM3);
/// PB6..PB9 to AF2 (TIM4); all push-pull outputs.
fn route(gpioa: &pac::GPIOA, gpiob: &pac::GPIOB) {
    gpioa.afrl().modify(|_, w| {
        w.afrl1().af1().afrl2().af1().afrl3().af1().afrl5().af1();
        w.afrl6().af2().afrl7().af2()
    });
    gpioa.otyper().modify(|_, w| {
        w.ot1().push_pull().ot2().push_pull().ot3().push_pull();
        w.ot5().push_pull().ot6().push_pull().ot7().push_pull()
    });
    gpioa.moder().modify(|_, w| {
        w.moder1()
            .alternate()
            .moder2()
            .alternate()
            .moder3()
            .alternate();
        w.moder5()
            .alternate()
            .moder6()
            .alternate()
            .moder7()
            .alternate()
    });
    gpiob
        .afrl()
        .modify(|_, w| w.afrl0().af2().afrl1().af2().afrl6().af2().afrl7().af2());
    gpiob.afrh().modify(|_, w| w.afrh8().af2().afrh9().af2());
    gpiob.otyper().modify(|_, w| {
        w.ot0().push_pull().ot1().push_pull().ot6().push_pull();
        w.ot7().push_pull().ot8().push_pull().ot9().push_pull()
    });
    gpiob.moder().modify(|_, w| {
        w.moder0()
            .alternate()
            .moder1()
            .alternate()
            .moder6()
            .alternate();
        w.moder7()
            .alternate()
            .moder8()
            .alternate()
            .moder9()
            .alternate()
    });
}

/// One timer channel as an embedded-hal PWM output: its duty cycle is the
/// compare value, out of the period in ticks.
pub struct TimerChannel<'t> {
    timers: &'t Timers,
    which: Which,
    channel: u8,
}

impl ErrorType for TimerChannel<'_> {
    type Error = core::convert::Infallible;
}

impl SetDutyCycle for TimerChannel<'_> {
    fn max_duty_cycle(&self) -> u16 {
        self.timers.period
    }

    fn set_duty_cycle(&mut self, duty: u16) -> Result<(), Self::Error> {
        let duty = duty.min(self.timers.period);
        match self.which {
            Which::Tim2 => {
                let t = &self.timers.tim2;
                let v = u32::from(duty);
                match self.channel {
                    0 => t.ccr1().write(|w| w.ccr().set(v)),
                    1 => t.ccr2().write(|w| w.ccr().set(v)),
                    2 => t.ccr3().write(|w| w.ccr().set(v)),
                    _ => t.ccr4().write(|w| w.ccr().set(v)),
                };
            }
            Which::Tim3 => set16(&self.timers.tim3, self.channel, duty),
            Which::Tim4 => set16(&self.timers.tim4, self.channel, duty),
        }
        Ok(())
    }

    /// Without a division by a run-time value (a panic path; see
    /// `marionette_core::output::pwm`).
    fn set_duty_cycle_fraction(&mut self, num: u16, denom: u16) -> Result<(), Self::Error> {
        let duty = (u32::from(num) * u32::from(self.timers.period))
            .checked_div(u32::from(denom))
            .unwrap_or(0);
        self.set_duty_cycle(u16::try_from(duty).unwrap_or(u16::MAX))
    }
}

/// A compare register of a 16-bit timer.
fn set16(t: &pac::tim3::RegisterBlock, channel: u8, duty: u16) {
    match channel {
        0 => t.ccr1().write(|w| w.ccr().set(duty)),
        1 => t.ccr2().write(|w| w.ccr().set(duty)),
        2 => t.ccr3().write(|w| w.ccr().set(duty)),
        _ => t.ccr4().write(|w| w.ccr().set(duty)),
    };
}
