//! What a board can drive: the one rule both the firmware (which refuses to
//! arm a rig it cannot drive) and the host (which refuses to flash one)
//! apply.
//!
//! A [`Support`] lists a board's servo back-ends; [`Support::check`] takes
//! a rig's output and servo channels and says whether the board can drive
//! them, or why not ([`Refusal`]; the board's status reason is
//! [`crate::wire::StatusReason::Unsupported`]).
//!
//! ## UART rates
//!
//! A USART with 16× oversampling divides its clock by
//! `BRR = round(clock / baud)` (RM0383 §19.3.4: BRR holds 16 × USARTDIV as
//! mantissa and fraction). A rate is accepted if the rate that divisor gives
//! is within 1 % of the one asked for ([`MAX_BAUD_ERROR_PERMILLE`]): both
//! ends of a link together tolerate a few percent.

use core::fmt;

use crate::rig::{Output, ServoDesc};

/// The largest UART rate error accepted, thousandths.
pub const MAX_BAUD_ERROR_PERMILLE: u32 = 10;

/// The BRR value for `baud` on a USART clocked at `clock_hz` with 16×
/// oversampling: `clock / baud` rounded to nearest (0 for baud 0 or a
/// divisor over 16 bits).
#[must_use]
pub const fn uart_divisor(clock_hz: u32, baud: u32) -> u16 {
    match (clock_hz.saturating_add(baud / 2)).checked_div(baud) {
        Some(d) if d <= 0xFFFF => d as u16,
        _ => 0,
    }
}

/// How far the rate given by `divisor` is from `baud`, thousandths (rounded
/// down); `u32::MAX` for a zero divisor or baud.
#[must_use]
pub const fn uart_error_permille(clock_hz: u32, baud: u32, divisor: u16) -> u32 {
    let Some(actual) = clock_hz.checked_div(divisor as u32) else {
        return u32::MAX;
    };
    let diff = actual.abs_diff(baud) as u64 * 1000;
    match diff.checked_div(baud as u64) {
        Some(e) if e <= u32::MAX as u64 => e as u32,
        _ => u32::MAX,
    }
}

/// How a board's servo UART sets its rate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UartRate {
    /// No servo UART.
    None,
    /// Any rate (an emulated UART moves bytes, not bits).
    Any,
    /// A USART with 16× oversampling on this clock, Hz: a rate must divide
    /// to within [`MAX_BAUD_ERROR_PERMILLE`] and leave BRR ≥ 16.
    Clock(u32),
}

/// The servo back-ends of one board.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Support {
    /// The board, for messages.
    pub board: &'static str,
    /// The servo UART (Pololu Maestro and, where the board has them, the
    /// serial bus servos).
    pub uart: UartRate,
    /// Whether the UART back-ends include the half-duplex bus servos
    /// (Dynamixel, Feetech).
    pub bus_servos: bool,
    /// Whether a PCA9685 can be driven (over I2C).
    pub pca9685: bool,
    /// On-chip PWM channels (0: none).
    pub pwm_channels: u8,
}

/// Why a board cannot drive a rig's servos.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal {
    /// The board has no such back-end.
    Backend {
        /// The back-end (the rig file's `kind`).
        kind: &'static str,
        /// The board.
        board: &'static str,
    },
    /// The UART cannot make this rate closely enough.
    Baud {
        /// The rate asked for.
        baud: u32,
        /// The rate's error on this board, thousandths.
        error_permille: u32,
    },
    /// A servo channel the back-end does not have on this board.
    Channel {
        /// The channel.
        channel: u8,
        /// The channels the board drives.
        channels: u8,
    },
}

impl fmt::Display for Refusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Backend { kind, board } => {
                write!(f, "the {board} cannot drive a `{kind}` servo output")
            }
            Self::Baud {
                baud,
                error_permille,
            } => write!(
                f,
                "the servo UART cannot run at {baud} baud (rate error {}.{} % > 1 %)",
                error_permille / 10,
                error_permille % 10
            ),
            Self::Channel { channel, channels } => write!(
                f,
                "servo channel {channel}: this board drives channels 0..{channels} of this output"
            ),
        }
    }
}

/// The rig file's `kind` of an output.
#[must_use]
pub const fn kind_name(output: &Output) -> &'static str {
    match output {
        Output::Pwm { .. } => "pwm",
        Output::Pca9685 { .. } => "pca9685",
        Output::Maestro { .. } => "maestro",
        Output::Dynamixel { .. } => "dynamixel",
        Output::Feetech { .. } => "feetech",
    }
}

impl Support {
    /// The emulated board (QEMU `mps2-an386`): UART1 only, at any rate.
    pub const EMULATED: Self = Self {
        board: "emulated board",
        uart: UartRate::Any,
        bus_servos: true,
        pca9685: false,
        pwm_channels: 0,
    };

    /// The STM32F411 Black Pill: USART2 on the 50 MHz APB1 clock (any rate
    /// it divides to within 1 %), half-duplex for the bus servos; a PCA9685
    /// on I2C1; 12 channels of TIM2, TIM3 and TIM4.
    pub const BLACKPILL: Self = Self {
        board: "Black Pill",
        uart: UartRate::Clock(50_000_000),
        bus_servos: true,
        pca9685: true,
        pwm_channels: 12,
    };

    /// Whether this board can drive `output` on the channels of `servos`.
    pub fn check(&self, output: &Output, servos: &[ServoDesc]) -> Result<(), Refusal> {
        let refuse = Refusal::Backend {
            kind: kind_name(output),
            board: self.board,
        };
        let channels = match *output {
            Output::Maestro { baud } => {
                self.check_baud(baud).ok_or(refuse)??;
                output.channels()
            }
            Output::Dynamixel { baud } | Output::Feetech { baud, .. } if self.bus_servos => {
                self.check_baud(baud).ok_or(refuse)??;
                output.channels()
            }
            Output::Dynamixel { .. } | Output::Feetech { .. } => return Err(refuse),
            Output::Pca9685 { .. } if self.pca9685 => output.channels(),
            Output::Pwm { .. } if self.pwm_channels > 0 => self.pwm_channels,
            Output::Pca9685 { .. } | Output::Pwm { .. } => return Err(refuse),
        };
        match servos.iter().find(|s| s.channel >= channels) {
            Some(s) => Err(Refusal::Channel {
                channel: s.channel,
                channels,
            }),
            None => Ok(()),
        }
    }

    /// `None` without a UART, else whether `baud` is usable.
    fn check_baud(&self, baud: u32) -> Option<Result<(), Refusal>> {
        match self.uart {
            UartRate::None => None,
            UartRate::Any => Some(Ok(())),
            UartRate::Clock(clock) => {
                let brr = uart_divisor(clock, baud);
                let error_permille = uart_error_permille(clock, baud, brr);
                Some(if brr >= 16 && error_permille < MAX_BAUD_ERROR_PERMILLE {
                    Ok(())
                } else {
                    Err(Refusal::Baud {
                        baud,
                        error_permille,
                    })
                })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn divisors_worked_by_hand() {
        // 50 MHz / 115 200 = 434.03 -> 434, 115 207 baud: 0.06 ‰ -> 0.
        assert_eq!(uart_divisor(50_000_000, 115_200), 434);
        assert_eq!(uart_error_permille(50_000_000, 115_200, 434), 0);
        // 1 Mbaud divides exactly (50); 3 Mbaud: 16.67 -> 17 = 2.94 Mbaud, 19 ‰.
        assert_eq!(uart_divisor(50_000_000, 1_000_000), 50);
        assert_eq!(uart_divisor(50_000_000, 3_000_000), 17);
        assert_eq!(uart_error_permille(50_000_000, 3_000_000, 17), 19);
        assert_eq!(uart_divisor(50_000_000, 0), 0);
        assert_eq!(uart_error_permille(50_000_000, 9600, 0), u32::MAX);
        // 300 baud needs 166 667 > 16 bits.
        assert_eq!(uart_divisor(50_000_000, 300), 0);
    }

    fn servo(channel: u8) -> ServoDesc {
        ServoDesc {
            channel,
            ..ServoDesc::default()
        }
    }

    #[test]
    fn boards_refuse_what_they_cannot_drive() {
        let maestro = Output::Maestro { baud: 115_200 };
        assert_eq!(Support::EMULATED.check(&maestro, &[servo(23)]), Ok(()));
        assert_eq!(Support::BLACKPILL.check(&maestro, &[servo(0)]), Ok(()));
        let clocked = Support {
            uart: UartRate::Clock(50_000_000),
            ..Support::BLACKPILL
        };
        assert_eq!(
            clocked.check(&Output::Maestro { baud: 3_000_000 }, &[]),
            Err(Refusal::Baud {
                baud: 3_000_000,
                error_permille: 19
            })
        );
        assert_eq!(
            clocked.check(&Output::Maestro { baud: 1_000_000 }, &[]),
            Ok(())
        );
        let pwm = Output::Pwm { freq_hz: 50 };
        assert_eq!(
            Support::EMULATED.check(&pwm, &[]),
            Err(Refusal::Backend {
                kind: "pwm",
                board: "emulated board"
            })
        );
    }
}
