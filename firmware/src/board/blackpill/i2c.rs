//! I2C1 as an embedded-hal 1.0 master, polled: the bus of the PCA9685.
//!
//! Register-level (RM0383 §18, the STM32F4 "v1" I2C), like the USARTs, so
//! that no HAL code and none of its panicking branches sit in the path. Fast
//! mode, 400 kHz nominal: with PCLK1 = 50 MHz, `FREQ` = 50, duty
//! `T_low/T_high` = 2, `CCR` = 50 MHz / (3 · 400 kHz) = 41.7 → 42 (396.8 kHz),
//! `TRISE` = 300 ns · 50 MHz + 1 = 16 (the fast-mode rise time).
//!
//! Pins: PB6 SCL, PB7 SDA, alternate function 4, open drain, with the
//! internal pull-ups (the PCA9685 boards carry their own 10 kΩ ones).
//!
//! Every wait is bounded ([`SPINS`]): a bus held low, a missing device or a
//! stuck flag gives an error, never a hang (the watchdog would reset the
//! board, and the servos would lose their pulses meanwhile).
//!
//! Reads are done byte by byte with ACK cleared before the last byte's ADDR
//! or BTF clear; the PCA9685 back-end only writes.

use embedded_hal::i2c::{ErrorKind, NoAcknowledgeSource, Operation};
use stm32f4::stm32f411 as pac;

/// Polls of a status flag before giving up: at 100 MHz well over the 25 µs a
/// byte takes at 400 kHz, short of the watchdog.
pub const SPINS: u32 = 20_000;
/// CR2.FREQ: the peripheral clock in MHz.
const FREQ_MHZ: u8 = 50;
/// CCR in fast mode, duty 2.
const CCR: u16 = 42;
/// TRISE for 300 ns.
const TRISE: u8 = 16;

/// What went wrong on the bus.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum I2cError {
    /// No device acknowledged its address.
    AddressNack,
    /// The device did not acknowledge a data byte.
    DataNack,
    /// Another master won the bus.
    Arbitration,
    /// A misplaced START or STOP.
    Bus,
    /// A flag did not come within [`SPINS`] polls.
    Timeout,
}

impl embedded_hal::i2c::Error for I2cError {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::AddressNack => ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address),
            Self::DataNack => ErrorKind::NoAcknowledge(NoAcknowledgeSource::Data),
            Self::Arbitration => ErrorKind::ArbitrationLoss,
            Self::Bus => ErrorKind::Bus,
            Self::Timeout => ErrorKind::Other,
        }
    }
}

/// I2C1, master, fast mode.
pub struct I2c1 {
    i2c: pac::I2C1,
}

impl I2c1 {
    /// Routes PB6/PB7 and sets the peripheral up. The caller has enabled
    /// the GPIOB and I2C1 clocks.
    pub fn new(i2c: pac::I2C1, gpiob: &pac::GPIOB) -> Self {
        gpiob.afrl().modify(|_, w| w.afrl6().af4().afrl7().af4());
        gpiob
            .otyper()
            .modify(|_, w| w.ot6().open_drain().ot7().open_drain());
        gpiob
            .pupdr()
            .modify(|_, w| w.pupdr6().pull_up().pupdr7().pull_up());
        gpiob
            .ospeedr()
            .modify(|_, w| w.ospeedr6().medium_speed().ospeedr7().medium_speed());
        gpiob
            .moder()
            .modify(|_, w| w.moder6().alternate().moder7().alternate());
        // A reset clears a bus state left by an interrupted transfer.
        i2c.cr1().write(|w| w.swrst().set_bit());
        i2c.cr1().write(|w| w.swrst().clear_bit());
        // SAFETY: FREQ (6 bits) and CCR (12 bits) take raw values; both are
        // the constants above, within their fields (50 ≤ 63, 42 ≤ 4095).
        i2c.cr2().write(|w| unsafe { w.freq().bits(FREQ_MHZ) });
        i2c.ccr()
            .write(|w| unsafe { w.f_s().set_bit().duty().set_bit().ccr().bits(CCR) });
        i2c.trise().write(|w| w.trise().set(TRISE));
        i2c.cr1().write(|w| w.pe().set_bit());
        Self { i2c }
    }

    /// Polls `flag` until set; errors flagged meanwhile are reported.
    fn wait(
        &self,
        flag: impl Fn(&pac::i2c1::sr1::R) -> bool,
        nack: I2cError,
    ) -> Result<(), I2cError> {
        for _ in 0..SPINS {
            let sr1 = self.i2c.sr1().read();
            if sr1.af().bit_is_set() {
                self.i2c.sr1().modify(|_, w| w.af().clear_bit());
                return Err(nack);
            }
            if sr1.arlo().bit_is_set() {
                self.i2c.sr1().modify(|_, w| w.arlo().clear_bit());
                return Err(I2cError::Arbitration);
            }
            if sr1.berr().bit_is_set() {
                self.i2c.sr1().modify(|_, w| w.berr().clear_bit());
                return Err(I2cError::Bus);
            }
            if flag(&sr1) {
                return Ok(());
            }
        }
        Err(I2cError::Timeout)
    }

    /// START (or repeated START) and the address byte; ADDR is left set.
    fn start(&mut self, address: u8, read: bool) -> Result<(), I2cError> {
        self.i2c.cr1().modify(|_, w| w.start().set_bit());
        self.wait(|s| s.sb().bit_is_set(), I2cError::Bus)?;
        let byte = (address << 1) | u8::from(read);
        self.i2c.dr().write(|w| w.dr().set(byte));
        self.wait(|s| s.addr().bit_is_set(), I2cError::AddressNack)
    }

    /// Clears ADDR (reading SR1 then SR2).
    fn clear_addr(&self) {
        let _ = self.i2c.sr1().read();
        let _ = self.i2c.sr2().read();
    }

    fn write_bytes(&mut self, bytes: &[u8]) -> Result<(), I2cError> {
        self.clear_addr();
        for &b in bytes {
            self.wait(|s| s.tx_e().bit_is_set(), I2cError::DataNack)?;
            self.i2c.dr().write(|w| w.dr().set(b));
        }
        self.wait(|s| s.btf().bit_is_set(), I2cError::DataNack)
    }

    fn read_bytes(&mut self, buf: &mut [u8], last: bool) -> Result<(), I2cError> {
        let n = buf.len();
        self.i2c.cr1().modify(|_, w| w.ack().bit(n > 1));
        self.clear_addr();
        for (i, slot) in buf.iter_mut().enumerate() {
            if i + 1 == n {
                self.i2c.cr1().modify(|_, w| w.ack().clear_bit());
                if last {
                    self.i2c.cr1().modify(|_, w| w.stop().set_bit());
                }
            }
            self.wait(|s| s.rx_ne().bit_is_set(), I2cError::DataNack)?;
            *slot = self.i2c.dr().read().dr().bits();
        }
        Ok(())
    }

    /// STOP, and waits for the bus to be released.
    fn stop(&mut self) -> Result<(), I2cError> {
        self.i2c.cr1().modify(|_, w| w.stop().set_bit());
        for _ in 0..SPINS {
            if self.i2c.sr2().read().msl().bit_is_clear() {
                return Ok(());
            }
        }
        Err(I2cError::Timeout)
    }
}

impl embedded_hal::i2c::ErrorType for I2c1 {
    type Error = I2cError;
}

impl embedded_hal::i2c::I2c for I2c1 {
    /// The operations in one transaction: a START (repeated between
    /// operations of different directions), then a STOP. On an error a STOP
    /// is still sent, so the bus is free for the next frame.
    fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Self::Error> {
        let count = operations.len();
        let mut result = Ok(());
        let mut reading = None;
        for (i, op) in operations.iter_mut().enumerate() {
            let last = i + 1 == count;
            result = match op {
                Operation::Write(bytes) => {
                    let started = if reading == Some(false) {
                        Ok(())
                    } else {
                        self.start(address, false)
                    };
                    reading = Some(false);
                    started.and_then(|()| self.write_bytes(bytes))
                }
                Operation::Read(buf) => {
                    let started = if reading == Some(true) {
                        Ok(())
                    } else {
                        self.start(address, true)
                    };
                    reading = Some(true);
                    started.and_then(|()| self.read_bytes(buf, last))
                }
            };
            if result.is_err() {
                break;
            }
        }
        // A read that ended the transaction has sent its STOP already.
        if reading != Some(true) || result.is_err() {
            let stopped = self.stop();
            result = result.and(stopped);
        }
        result
    }
}
