//! A polled USART driver (8N1, 16× oversampling) implementing embedded-io 0.7.
//!
//! Register-level, so that no HAL code (and none of its panicking branches)
//! sits between the app and the data register. The baud-rate divisor is a
//! compile-time constant, from the core's
//! [`uart_divisor`](marionette_core::output::support::uart_divisor): with 16×
//! oversampling BRR holds 16 × USARTDIV as mantissa:fraction (RM0383
//! §19.3.4), which is `pclk / baud` rounded, the core's formula.

use core::ops::Deref;
use stm32f4::stm32f411::usart1::RegisterBlock;

/// A receive error reported by the USART status register.
///
/// The byte in the data register when the error was seen is discarded.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum UartError {
    /// A byte arrived before the previous one was read: bytes were lost.
    Overrun,
    /// A stop bit was missing (wrong baud rate, break, or line noise).
    Framing,
    /// Noise was detected on a received bit.
    Noise,
    /// Parity error (only with parity enabled, which this driver never does).
    Parity,
}

impl core::fmt::Display for UartError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            UartError::Overrun => "UART overrun",
            UartError::Framing => "UART framing error",
            UartError::Noise => "UART noise",
            UartError::Parity => "UART parity error",
        })
    }
}

impl core::error::Error for UartError {}

impl embedded_io::Error for UartError {
    fn kind(&self) -> embedded_io::ErrorKind {
        match self {
            UartError::Overrun => embedded_io::ErrorKind::Other,
            UartError::Framing | UartError::Noise | UartError::Parity => {
                embedded_io::ErrorKind::InvalidData
            }
        }
    }
}

/// One USART, owned. `P` is the PAC singleton (`USART1`, `USART2`, ...).
pub struct Uart<P> {
    port: P,
}

impl<P: Deref<Target = RegisterBlock>> Uart<P> {
    /// Configures the port for 8N1 at the rate given by `brr` (see
    /// [`uart_divisor`](marionette_core::output::support::uart_divisor)) and enables the transmitter and the receiver.
    ///
    /// The caller has enabled the port's clock and routed its pins.
    pub fn new(port: P, brr: u16) -> Self {
        port.cr1().reset();
        port.cr2().reset();
        port.cr3().reset();
        port.brr().write(|w| {
            w.div_mantissa().set(brr >> 4);
            w.div_fraction().set((brr & 0xF) as u8)
        });
        port.cr1()
            .write(|w| w.ue().enabled().te().enabled().re().enabled());
        Self { port }
    }

    /// One snapshot of the receive side of the status register: `Err` if an
    /// error is flagged, `Ok(true)` if a byte is waiting.
    ///
    /// Reading SR is the first half of clearing an error; reading DR is the
    /// second.
    fn rx_status(&self) -> Result<bool, UartError> {
        let sr = self.port.sr().read();
        if sr.ore().is_overrun() {
            Err(UartError::Overrun)
        } else if sr.fe().is_error() {
            Err(UartError::Framing)
        } else if sr.nf().is_noise() {
            Err(UartError::Noise)
        } else if sr.pe().is_error() {
            Err(UartError::Parity)
        } else {
            Ok(sr.rxne().is_data_ready())
        }
    }

    fn data(&self) -> u8 {
        // 8N1: the data byte is the low 8 bits of DR.
        self.port.dr().read().dr().bits() as u8
    }

    /// Takes one byte if one is waiting: `Ok(None)` if not, `Err` (and the
    /// error cleared, its byte dropped) if the port flagged one.
    fn try_read_byte(&mut self) -> Result<Option<u8>, UartError> {
        match self.rx_status() {
            Ok(ready) => Ok(ready.then(|| self.data())),
            Err(error) => {
                // SR was just read; reading DR completes the clear sequence.
                let _ = self.data();
                Err(error)
            }
        }
    }
}

impl<P> embedded_io::ErrorType for Uart<P> {
    type Error = UartError;
}

impl<P: Deref<Target = RegisterBlock>> embedded_io::Read for Uart<P> {
    /// Blocks until a byte (or an error) arrives, then returns every byte
    /// already waiting, up to `buf.len()`.
    ///
    /// An error found after some bytes were read is left pending, those bytes
    /// are returned, and the next call reports the error.
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, UartError> {
        let mut n = 0;
        for slot in buf.iter_mut() {
            // After the first byte, stop at an empty port or a pending error.
            if n > 0 && self.rx_status() != Ok(true) {
                break;
            }
            *slot = loop {
                if let Some(byte) = self.try_read_byte()? {
                    break byte;
                }
            };
            n += 1;
        }
        Ok(n)
    }
}

impl<P: Deref<Target = RegisterBlock>> embedded_io::ReadReady for Uart<P> {
    /// True when `read` would return at once: a byte or an error is waiting.
    fn read_ready(&mut self) -> Result<bool, UartError> {
        Ok(self.rx_status() != Ok(false))
    }
}

impl<P: Deref<Target = RegisterBlock>> embedded_io::Write for Uart<P> {
    /// Blocks until every byte is in the transmitter.
    fn write(&mut self, buf: &[u8]) -> Result<usize, UartError> {
        for &byte in buf {
            while !self.port.sr().read().txe().is_tx_empty() {}
            self.port.dr().write(|w| w.dr().set(u16::from(byte)));
        }
        Ok(buf.len())
    }

    /// Blocks until the last byte has left the shift register.
    fn flush(&mut self) -> Result<(), UartError> {
        while !self.port.sr().read().tc().is_tx_complete() {}
        Ok(())
    }
}
