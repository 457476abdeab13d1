//! The Black Pill's servo side: whichever back-end the rig names, chosen at
//! run time (one firmware image for every rig), through the core's output
//! abstraction.
//!
//! | rig `output` | peripheral | pins |
//! |---|---|---|
//! | `maestro` | USART2, TX by DMA (DMA1 stream 6, channel 4) | PA2 TX (AF7) |
//! | `dynamixel`, `feetech` | USART2 half-duplex, TX by DMA | PA2 data (AF7, open drain, pull-up) |
//! | `pca9685` | I2C1 at 400 kHz ([`super::i2c`]) | PB6 SCL, PB7 SDA (AF4) |
//! | `pwm` | TIM2, TIM3, TIM4 ([`super::timers`]) | see the timer module |
//!
//! **When a frame goes out** ([`Servos::ready`]): a UART back-end sends the
//! newest targets as soon as the last frame has left the DMA (so never more
//! than the line carries, and the loop never waits for the line); the
//! PCA9685 at most once per PWM period of the chip (its outputs change only
//! at a period's start; the burst takes 1.5 ms of polled I2C); timer PWM
//! every frame (a register write; the new width starts with the next
//! period).
//!
//! **Power-up**: nothing is driven until the first frame after `Arm` (or
//! the first step of a calibration `Jog`, which drives the rig's outputs
//! while disarmed): the UART stays idle, the PCA9685 is set up with every
//! output full off, the timers run with compare 0 (pins low). A rig the
//! board cannot drive never arms (`Unsupported`), is never jogged, and none
//! of this is touched.

use core::convert::Infallible;

use embedded_hal::delay::DelayNs;
use marionette_core::output::pca9685::Pca9685;
use marionette_core::output::pwm::{Pwm, TimerSetup};
use marionette_core::output::serial::{Serial, UartServos};
use marionette_core::output::support::{self, uart_divisor};
use marionette_core::output::{OutputError, Refusal, ServoOutput, Support};
use marionette_core::rig::{Output, ServoDesc};
use stm32f4::stm32f411 as pac;

use super::clock::{PCLK1_HZ, SYSCLK_HZ};
use super::i2c::{I2c1, I2cError};
use super::timers::{self, Timers};

/// Bytes of the DMA transmit buffer: the largest frame (24 Maestro Set
/// Targets, 96 bytes; a Sync Write to 24 bus servos, under 160) fits.
pub const TX_BUFFER: usize = 256;

/// Polls of the DMA before a write gives up (about 50 ms at 100 MHz, under
/// the 100 ms watchdog: only the second packet of a frame that switches bus
/// torque ever waits, one packet's time).
const TX_SPINS: u32 = 1_000_000;

/// The servo peripherals not yet given to a back-end.
pub struct Parts {
    /// The servo UART.
    pub usart2: pac::USART2,
    /// Its transmit DMA.
    pub dma1: pac::DMA1,
    /// The PCA9685's bus.
    pub i2c1: pac::I2C1,
    /// The servo timers.
    pub timers: (pac::TIM2, pac::TIM3, pac::TIM4),
    /// Pins.
    pub gpioa: pac::GPIOA,
    /// Pins.
    pub gpiob: pac::GPIOB,
    /// The DMA buffer (a `'static` singleton: the DMA reads it while the
    /// program runs on).
    pub buffer: &'static mut [u8; TX_BUFFER],
}

/// Enables the clocks of every servo peripheral (the ones a rig does not
/// use stay idle).
pub fn enable_clocks(rcc: &pac::RCC) {
    rcc.ahb1enr()
        .modify(|_, w| w.gpioaen().enabled().gpioben().enabled().dma1en().enabled());
    rcc.apb1enr().modify(|_, w| {
        w.usart2en().enabled().i2c1en().enabled();
        w.tim2en().enabled().tim3en().enabled().tim4en().enabled()
    });
    // Two bus cycles before the registers answer.
    let _ = rcc.apb1enr().read();
}

/// The back-end in use.
enum Active {
    /// None yet (or a refused rig).
    None(Option<Parts>),
    /// A UART back-end.
    Uart(UartServos<DmaTx>),
    /// A PCA9685, and its period, µs.
    Pca9685(Pca9685<I2c1>, u32),
    /// Timer PWM at this frame rate.
    Pwm(Timers, u32),
}

/// The servo outputs of the Black Pill.
pub struct Servos {
    active: Active,
    /// Port A once the back-end is set up (its pins configured; PA0 is
    /// the show button, read through it).
    pins: Option<pac::GPIOA>,
    /// When the PCA9685 was last written, µs.
    last_us: Option<u32>,
    /// The board clock at the last [`Servos::ready`], µs.
    now_us: u32,
}

impl Servos {
    /// Nothing driven yet.
    #[must_use]
    pub fn new(parts: Parts) -> Self {
        Self {
            active: Active::None(Some(parts)),
            pins: None,
            last_us: None,
            now_us: 0,
        }
    }

    /// Sets up the back-end of `output` for `servos` (checked against
    /// [`Support::BLACKPILL`] by the app); once per boot.
    pub fn open(&mut self, output: &Output, servos: &[ServoDesc]) -> Result<(), Refusal> {
        let refuse = Refusal::Backend {
            kind: support::kind_name(output),
            board: Support::BLACKPILL.board,
        };
        let Active::None(parts) = &mut self.active else {
            return Err(refuse);
        };
        let Parts {
            usart2,
            dma1,
            i2c1,
            timers,
            gpioa,
            gpiob,
            buffer,
        } = parts.take().ok_or(refuse)?;
        self.active = match (*output, Serial::for_output(output, servos)) {
            (_, Some(serial)) => {
                let brr = uart_divisor(PCLK1_HZ, Serial::baud(output).unwrap_or(0));
                let half_duplex = output.is_bus();
                let uart = DmaTx::new((usart2, dma1, buffer), &gpioa, brr, half_duplex);
                Active::Uart(UartServos { uart, serial })
            }
            (Output::Pca9685 { i2c_addr, freq_hz }, None) => {
                let bus = I2c1::new(i2c1, &gpiob);
                let mut chip =
                    Pca9685::new(bus, i2c_addr, u32::from(freq_hz)).map_err(|_| refuse)?;
                chip.init(&mut Delay).map_err(|_| refuse)?;
                Active::Pca9685(chip, 1_000_000 / u32::from(freq_hz.max(1)))
            }
            (Output::Pwm { freq_hz }, None) => {
                let setup = TimerSetup::new(timers::TIMER_CLOCK_HZ, u32::from(freq_hz))
                    .map_err(|_| refuse)?;
                Active::Pwm(
                    Timers::new(timers, setup, &gpioa, &gpiob),
                    u32::from(freq_hz),
                )
            }
            _ => return Err(refuse),
        };
        self.pins = Some(gpioa);
        Ok(())
    }

    /// Whether PA0 (the KEY button, to ground, pulled up) is held down.
    #[must_use]
    pub fn key_down(&self) -> bool {
        let port = match (&self.active, &self.pins) {
            (Active::None(Some(parts)), _) => &parts.gpioa,
            (_, Some(pins)) => pins,
            _ => return false,
        };
        port.idr().read().idr0().bit_is_clear()
    }

    /// Whether a frame may go out now (see the module doc); `now_us` is the
    /// board clock.
    pub fn ready(&mut self, now_us: u32) -> bool {
        self.now_us = now_us;
        match &self.active {
            Active::Uart(out) => !out.uart.busy(),
            Active::Pca9685(_, period_us) => self
                .last_us
                .is_none_or(|t| now_us.wrapping_sub(t) >= *period_us),
            Active::Pwm(..) | Active::None(_) => true,
        }
    }

    /// Writes a frame; `now_us` is the board clock.
    fn write_at(&mut self, targets: &[u16], now_us: u32) -> Result<(), ServoError> {
        match &mut self.active {
            Active::Uart(out) => out.write(targets).map_err(|_| ServoError::Uart),
            Active::Pca9685(chip, _) => {
                self.last_us = Some(now_us);
                chip.write(targets).map_err(|e| match e {
                    OutputError::Bus(e) => ServoError::I2c(e),
                    _ => ServoError::Frame,
                })
            }
            Active::Pwm(t, hz) => {
                let channels = t.channels();
                let mut pwm = Pwm::new(channels, *hz).map_err(|_| ServoError::Frame)?;
                pwm.write(targets).map_err(|_| ServoError::Frame)
            }
            Active::None(_) => Ok(()),
        }
    }

    /// Waits for the UART's last frame to leave (before the board parks).
    pub fn flush(&mut self) {
        if let Active::Uart(out) = &mut self.active {
            let _ = embedded_io::Write::flush(&mut out.uart);
        }
    }
}

impl ServoOutput for Servos {
    type Error = ServoError;

    /// Writes a frame (call [`Servos::ready`] first: it also reads the
    /// clock the PCA9685's rate is kept by).
    fn write(&mut self, targets: &[u16]) -> Result<(), ServoError> {
        self.write_at(targets, self.now_us)
    }
}

/// Why a frame did not reach the servos.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum ServoError {
    /// The UART did not take the frame.
    Uart,
    /// The I2C bus failed.
    I2c(I2cError),
    /// The frame does not fit the back-end.
    Frame,
}

/// USART2's transmitter fed by DMA1 stream 6 (channel 4, RM0383 table 27).
pub struct DmaTx {
    usart: pac::USART2,
    dma: pac::DMA1,
    buffer: &'static mut [u8; TX_BUFFER],
}

/// The DMA stream of USART2_TX.
const STREAM: usize = 6;
/// Its request channel.
const CHANNEL: u8 = 4;

impl DmaTx {
    /// Sets USART2 to `brr`, 8N1, transmitter only, fed by DMA;
    /// `half_duplex`: the single-wire mode of the bus servos (PA2 open
    /// drain with a pull-up, released between bytes; RM0383 §19.3.10).
    /// PA2 is already routed to USART2 (AF7) at start-up.
    fn new(
        (usart, dma, buffer): (pac::USART2, pac::DMA1, &'static mut [u8; TX_BUFFER]),
        gpioa: &pac::GPIOA,
        brr: u16,
        half_duplex: bool,
    ) -> Self {
        if half_duplex {
            gpioa.otyper().modify(|_, w| w.ot2().open_drain());
            gpioa.pupdr().modify(|_, w| w.pupdr2().pull_up());
        }
        dma.st(STREAM).cr().reset();
        usart.cr1().reset();
        usart.cr2().reset();
        usart
            .cr3()
            .write(|w| w.hdsel().bit(half_duplex).dmat().enabled());
        usart.brr().write(|w| {
            w.div_mantissa().set(brr >> 4);
            w.div_fraction().set((brr & 0xF) as u8)
        });
        usart.cr1().write(|w| w.ue().enabled().te().enabled());
        Self { usart, dma, buffer }
    }

    /// Whether the last frame is still being handed to the USART (the DMA
    /// clears the stream's EN when its last byte is taken).
    #[must_use]
    pub fn busy(&self) -> bool {
        self.dma.st(STREAM).cr().read().en().bit_is_set()
    }

    /// Waits (bounded) for the stream to finish; false if it did not.
    fn wait(&self) -> bool {
        for _ in 0..TX_SPINS {
            if !self.busy() {
                return true;
            }
        }
        false
    }
}

impl embedded_io::ErrorType for DmaTx {
    type Error = Infallible;
}

impl embedded_io::Write for DmaTx {
    /// Copies up to [`TX_BUFFER`] bytes and starts the DMA; waits first
    /// (bounded) if the previous transfer is still running, and returns
    /// `Ok(0)` (taken as a link error) if it never ends.
    fn write(&mut self, bytes: &[u8]) -> Result<usize, Infallible> {
        if !self.wait() {
            return Ok(0);
        }
        let n = bytes.len().min(TX_BUFFER);
        if let (Some(dst), Some(src)) = (self.buffer.get_mut(..n), bytes.get(..n)) {
            dst.copy_from_slice(src);
        }
        let data = core::ptr::from_ref(self.usart.dr()).addr() as u32;
        let memory = self.buffer.as_ptr().addr() as u32;
        // Stream 6's flags: transfer complete, half, error, direct, FIFO.
        self.dma.hifcr().write(|w| {
            w.ctcif6().set_bit().chtif6().set_bit().cteif6().set_bit();
            w.cdmeif6().set_bit().cfeif6().set_bit()
        });
        let st = self.dma.st(STREAM);
        // SAFETY: PAR and M0AR take raw addresses. `data` is USART2's data
        // register; `memory` is a `'static` buffer that this driver alone
        // holds and writes only while the stream is disabled (checked just
        // above), so the DMA never reads a buffer being written or freed.
        st.par().write(|w| unsafe { w.pa().bits(data) });
        st.m0ar().write(|w| unsafe { w.m0a().bits(memory) });
        st.ndtr().write(|w| w.ndt().set(n as u16));
        // The buffer's bytes land before the stream starts reading them.
        cortex_m::asm::dmb();
        st.cr().write(|w| {
            w.chsel().set(CHANNEL).dir().memory_to_peripheral();
            w.minc().incremented().pinc().fixed();
            w.msize().bits8().psize().bits8().pl().medium();
            w.en().enabled()
        });
        Ok(n)
    }

    /// Waits (bounded) until the last byte has left the shift register.
    fn flush(&mut self) -> Result<(), Infallible> {
        if self.wait() {
            for _ in 0..TX_SPINS {
                if self.usart.sr().read().tc().is_tx_complete() {
                    break;
                }
            }
        }
        Ok(())
    }
}

/// Busy-waits on the core clock (the PCA9685's 500 µs oscillator start-up).
struct Delay;

impl DelayNs for Delay {
    fn delay_ns(&mut self, ns: u32) {
        let cycles = u64::from(ns) * u64::from(SYSCLK_HZ / 1_000_000) / 1000;
        cortex_m::asm::delay(u32::try_from(cycles).unwrap_or(u32::MAX));
    }
}
