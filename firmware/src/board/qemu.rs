//! The emulated board: QEMU `mps2-an386` (Cortex-M4F at 25 MHz).
//!
//! - UART0 (0x4000_4000) is the tracker link, UART1 (0x4000_5000) the servo bus;
//!   the i-th `-serial` option of QEMU is UART i. UART1 drives whichever UART
//!   back-end the rig names (Pololu Maestro, Dynamixel, Feetech: the core's
//!   [`UartServos`]) at any baud rate (the emulated UART moves bytes, not
//!   bits); the board has no I2C device and no timer pins, so PCA9685 and
//!   PWM rigs are refused ([`Support::EMULATED`]).
//! - CMSDK APB timer 0 (0x4000_0000) is a free-running 25 MHz down-counter
//!   used for [`Board::now_us`].
//! - Semihosting gives the exit status.

use super::{Board, Outcome};
use core::convert::Infallible;
use core::ptr::{read_volatile, write_volatile};
use marionette_core::output::serial::{Serial, UartServos};
use marionette_core::output::{Refusal, Support};
use marionette_core::rig::{Output, ServoDesc};

/// Base address of CMSDK UART0 (tracker link).
pub const UART0_BASE: usize = 0x4000_4000;
/// Base address of CMSDK UART1 (servo bus).
pub const UART1_BASE: usize = 0x4000_5000;
/// Base address of CMSDK APB timer 0.
pub const TIMER0_BASE: usize = 0x4000_0000;
/// System clock of the board, Hz.
pub const SYSCLK_HZ: u32 = 25_000_000;

const DATA: usize = 0x00;
const STATE: usize = 0x04;
const CTRL: usize = 0x08;
const BAUDDIV: usize = 0x10;
const STATE_TX_FULL: u32 = 1 << 0;
const STATE_RX_FULL: u32 = 1 << 1;

#[inline]
fn reg_read(addr: usize) -> u32 {
    // SAFETY: `addr` is one of the CMSDK peripheral registers above, which are
    // always mapped on mps2-an386 and have no read side effects beyond the
    // documented FIFO semantics.
    unsafe { read_volatile(core::ptr::with_exposed_provenance::<u32>(addr)) }
}

#[inline]
fn reg_write(addr: usize, value: u32) {
    // SAFETY: as for `reg_read`; the registers accept any 32-bit write.
    unsafe { write_volatile(core::ptr::with_exposed_provenance_mut::<u32>(addr), value) }
}

/// A CMSDK APB UART, blocking, implementing embedded-io.
pub struct CmsdkUart {
    base: usize,
}

impl CmsdkUart {
    /// Enables the UART at `base`. QEMU moves no byte until BAUDDIV ≥ 16, so
    /// BAUDDIV is written first, then TX and RX are enabled.
    #[must_use]
    pub fn new(base: usize) -> Self {
        reg_write(base + BAUDDIV, 16);
        reg_write(base + CTRL, 0b11);
        Self { base }
    }

    fn rx_full(&self) -> bool {
        reg_read(self.base + STATE) & STATE_RX_FULL != 0
    }

    fn write_byte(&mut self, byte: u8) {
        while reg_read(self.base + STATE) & STATE_TX_FULL != 0 {}
        reg_write(self.base + DATA, u32::from(byte));
    }
}

impl embedded_io::ErrorType for CmsdkUart {
    type Error = Infallible;
}

impl embedded_io::Read for CmsdkUart {
    /// Blocks until at least one byte arrives, then returns what is ready.
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        let mut n = 0;
        for slot in buf.iter_mut() {
            if n > 0 && !self.rx_full() {
                break;
            }
            while !self.rx_full() {}
            *slot = reg_read(self.base + DATA) as u8;
            n += 1;
        }
        Ok(n)
    }
}

impl embedded_io::ReadReady for CmsdkUart {
    fn read_ready(&mut self) -> Result<bool, Infallible> {
        Ok(self.rx_full())
    }
}

impl embedded_io::Write for CmsdkUart {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        for &b in buf {
            self.write_byte(b);
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> Result<(), Infallible> {
        while reg_read(self.base + STATE) & STATE_TX_FULL != 0 {}
        Ok(())
    }
}

/// A free-running microsecond clock on CMSDK timer 0.
struct Clock {
    last: u32,
    ticks: u64,
}

impl Clock {
    fn start() -> Self {
        reg_write(TIMER0_BASE + 0x08, u32::MAX); // RELOAD
        reg_write(TIMER0_BASE + 0x04, u32::MAX); // VALUE
        reg_write(TIMER0_BASE, 1); // CTRL: enable
        Self {
            last: u32::MAX,
            ticks: 0,
        }
    }

    fn now_us(&mut self) -> u32 {
        let value = reg_read(TIMER0_BASE + 0x04);
        self.ticks += u64::from(self.last.wrapping_sub(value));
        self.last = value;
        (self.ticks / u64::from(SYSCLK_HZ / 1_000_000)) as u32
    }
}

/// The emulated `mps2-an386` board.
pub struct Qemu {
    tracker: CmsdkUart,
    servo: UartServos<CmsdkUart>,
    clock: Clock,
}

impl Qemu {
    /// Brings up the UARTs and the clock.
    #[must_use]
    pub fn init() -> Self {
        Self {
            tracker: CmsdkUart::new(UART0_BASE),
            servo: UartServos {
                uart: CmsdkUart::new(UART1_BASE),
                serial: Serial::None,
            },
            clock: Clock::start(),
        }
    }
}

/// Exits QEMU with `status` (semihosting `SYS_EXIT_EXTENDED`).
pub fn exit(status: i32) -> ! {
    semihosting::process::exit(status)
}

impl Board for Qemu {
    type Tracker = CmsdkUart;
    type Servos = UartServos<CmsdkUart>;

    fn links(&mut self) -> (&mut CmsdkUart, &mut UartServos<CmsdkUart>) {
        (&mut self.tracker, &mut self.servo)
    }

    fn open_servos(&mut self, output: &Output, servos: &[ServoDesc]) -> Result<(), Refusal> {
        self.servo.serial = Serial::for_output(output, servos).ok_or(Refusal::Backend {
            kind: marionette_core::output::support::kind_name(output),
            board: Self::SUPPORT.board,
        })?;
        Ok(())
    }

    fn tables(&self) -> &'static [u8] {
        crate::region::tables()
    }

    fn now_us(&mut self) -> u32 {
        self.clock.now_us()
    }

    fn feed_watchdog(&mut self) {}

    const SUPPORT: Support = Support::EMULATED;

    /// Ticks of the 25 MHz timer 0 (under `-icount shift=7`, 3.2 per
    /// instruction).
    fn cycles(&mut self) -> u32 {
        u32::MAX - reg_read(TIMER0_BASE + 0x04)
    }

    fn cycles_hz(&self) -> u32 {
        SYSCLK_HZ
    }

    const ENDS_ON_DISARM: bool = true;

    fn finish(&mut self, outcome: Outcome) -> ! {
        let _ = embedded_io::Write::flush(&mut self.servo.uart);
        let _ = embedded_io::Write::flush(&mut self.tracker);
        exit(outcome.exit_status())
    }
}
