//! The UART back-ends behind one type: whichever the rig's output names.
//!
//! A board owns its servo UART; [`Serial::for_output`] picks, from the
//! rig, how frames go out on it: Pololu Maestro Set Target commands
//! ([`super::maestro`]), or Sync Writes to Dynamixel or Feetech bus servos
//! ([`super::bus`]). [`UartServos`] puts the UART and that choice together
//! as a [`ServoOutput`], which is what a board hands the app.

use embedded_io::Write;

use super::bus::{BusServos, Protocol};
use super::maestro::{Command, Maestro};
use super::{OutputError, ServoOutput};
use crate::rig::{Output, ServoDesc};

/// How frames go out on a servo UART.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Serial {
    /// Nothing selected: a write sends nothing.
    None,
    /// A Pololu Maestro.
    Maestro(Command),
    /// Serial bus servos.
    Bus(BusServos),
}

impl Serial {
    /// The UART back-end of a rig's output (`None` for the outputs that are
    /// not on a UART: PWM, PCA9685).
    #[must_use]
    pub fn for_output(output: &Output, servos: &[ServoDesc]) -> Option<Self> {
        match *output {
            // Set Target works on every Maestro (Set Multiple Targets only
            // on the Mini Maestros).
            Output::Maestro { .. } => Some(Serial::Maestro(Command::SetTarget)),
            Output::Dynamixel { .. } => {
                Some(Serial::Bus(BusServos::new(Protocol::Dynamixel, servos)))
            }
            Output::Feetech { series, .. } => Some(Serial::Bus(BusServos::new(
                Protocol::Feetech(series),
                servos,
            ))),
            Output::Pwm { .. } | Output::Pca9685 { .. } => None,
        }
    }

    /// The UART rate of a rig's output (`None` if it is not on a UART).
    #[must_use]
    pub const fn baud(output: &Output) -> Option<u32> {
        match *output {
            Output::Maestro { baud }
            | Output::Dynamixel { baud }
            | Output::Feetech { baud, .. } => Some(baud),
            Output::Pwm { .. } | Output::Pca9685 { .. } => None,
        }
    }

    /// Sends one frame of targets on `uart`.
    pub fn write<W: Write>(
        &mut self,
        uart: &mut W,
        targets: &[u16],
    ) -> Result<(), OutputError<W::Error>> {
        match self {
            Serial::None => Ok(()),
            Serial::Maestro(command) => Maestro::new(uart, *command).write(targets),
            Serial::Bus(bus) => bus.write(uart, targets),
        }
    }
}

/// A servo UART and the back-end chosen for it.
#[derive(Debug)]
pub struct UartServos<W> {
    /// The UART, already at the rig's rate.
    pub uart: W,
    /// How frames go out.
    pub serial: Serial,
}

impl<W: Write> ServoOutput for UartServos<W> {
    type Error = OutputError<W::Error>;

    fn write(&mut self, targets: &[u16]) -> Result<(), Self::Error> {
        self.serial.write(&mut self.uart, targets)
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::output::{dynamixel, feetech};
    use crate::rig::FeetechSeries;
    use std::vec::Vec;

    struct Uart(Vec<u8>);

    impl embedded_io::ErrorType for Uart {
        type Error = core::convert::Infallible;
    }

    impl Write for Uart {
        fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
            self.0.extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> Result<(), Self::Error> {
            Ok(())
        }
    }

    fn servo(channel: u8, id: u8) -> ServoDesc {
        ServoDesc {
            channel,
            id,
            ..ServoDesc::default()
        }
    }

    fn output(output: Output, servos: &[ServoDesc]) -> UartServos<Uart> {
        UartServos {
            uart: Uart(Vec::new()),
            serial: Serial::for_output(&output, servos).unwrap(),
        }
    }

    #[test]
    fn feetech_frames_byte_for_byte() {
        // Channels 0 and 2 are ids 1 and 5; channel 1 has no servo.
        let servos = [servo(0, 1), servo(2, 5)];
        let sts = Output::Feetech {
            baud: 1_000_000,
            series: FeetechSeries::Sts,
        };
        let mut out = output(sts, &servos);
        // 2048.0 and 1000.25 positions in quarter units; channel 1 ignored.
        out.write(&[8192, 1234, 4001]).unwrap();
        // Torque on for ids 1 and 5: length (1 + 1) · 2 + 4 = 8, checksum
        // ~(FE + 08 + 83 + 28 + 01 + 01 + 01 + 05 + 01) = ~0x1BA -> 0x45.
        // Goal Position 2048 = 00 08, 1000 = E8 03 (STS: low byte first):
        // length 10, checksum ~(FE+0A+83+2A+02+01+00+08+05+E8+03) = ~0x2B0
        // -> 0x4F.
        assert_eq!(
            out.uart.0,
            [
                0xFF, 0xFF, 0xFE, 0x08, 0x83, 0x28, 0x01, 0x01, 0x01, 0x05, 0x01, 0x45, //
                0xFF, 0xFF, 0xFE, 0x0A, 0x83, 0x2A, 0x02, 0x01, 0x00, 0x08, 0x05, 0xE8, 0x03, 0x4F
            ]
        );
        // The next frame: positions only. Then channel 2 released (target
        // 0): torque off for id 5 alone, id 1 keeps its position.
        out.uart.0.clear();
        out.write(&[8192, 0, 4001]).unwrap();
        let mut want = [0u8; 32];
        let pos: [(u8, &[u8]); 2] = [(1, &[0x00, 0x08]), (5, &[0xE8, 0x03])];
        let n = feetech::sync_write(42, 2, pos, &mut want).unwrap();
        assert_eq!(out.uart.0, &want[..n]);
        out.uart.0.clear();
        out.write(&[8192, 0, 0]).unwrap();
        let mut off = [0u8; 32];
        let m = feetech::sync_write(40, 1, [(5u8, &[0u8][..])], &mut off).unwrap();
        let one: [(u8, &[u8]); 1] = [(1, &[0x00, 0x08])];
        let k = feetech::sync_write(42, 2, one, &mut want).unwrap();
        assert_eq!(out.uart.0, [&off[..m], &want[..k]].concat());
        // Everything released: torque off for id 1, no positions.
        out.uart.0.clear();
        out.write(&[0, 0, 0]).unwrap();
        let m = feetech::sync_write(40, 1, [(1u8, &[0u8][..])], &mut off).unwrap();
        assert_eq!(out.uart.0, &off[..m]);
        out.uart.0.clear();
        out.write(&[0, 0, 0]).unwrap();
        assert!(out.uart.0.is_empty(), "nothing changes, nothing is sent");
    }

    #[test]
    fn dynamixel_and_scs_positions_and_the_maestro() {
        let servos = [servo(0, 1), servo(1, 2)];
        let mut out = output(Output::Dynamixel { baud: 1_000_000 }, &servos);
        // 150 and 170 as quarter units: the e-Manual's example positions.
        out.write(&[600, 680]).unwrap();
        let mut torque = [0u8; 32];
        let on: [(u8, &[u8]); 2] = [(1, &[1]), (2, &[1])];
        let t = dynamixel::sync_write(64, 1, on, &mut torque).unwrap();
        let goal = [
            0xFF, 0xFF, 0xFD, 0x00, 0xFE, 0x11, 0x00, 0x83, 0x74, 0x00, 0x04, 0x00, 0x01, 0x96,
            0x00, 0x00, 0x00, 0x02, 0xAA, 0x00, 0x00, 0x00, 0x82, 0x87,
        ];
        assert_eq!(out.uart.0, [&torque[..t], &goal[..]].concat());
        // SCS: big-endian positions.
        let scs = Output::Feetech {
            baud: 500_000,
            series: FeetechSeries::Scs,
        };
        let mut out = output(scs, &servos[..1]);
        out.write(&[2000]).unwrap();
        assert_eq!(
            &out.uart.0[out.uart.0.len() - 4..out.uart.0.len() - 1],
            &[1, 0x01, 0xF4]
        );
        // The Maestro: Set Target per channel.
        let mut out = output(Output::Maestro { baud: 115_200 }, &servos);
        out.write(&[6000, 0]).unwrap();
        assert_eq!(out.uart.0, [0x84, 0, 0x70, 0x2E, 0x84, 1, 0, 0]);
        // Not a UART output.
        assert_eq!(
            Serial::for_output(&Output::Pwm { freq_hz: 50 }, &servos),
            None
        );
        assert_eq!(
            Serial::baud(&Output::Dynamixel { baud: 57_600 }),
            Some(57_600)
        );
        let mut none = UartServos {
            uart: Uart(Vec::new()),
            serial: Serial::None,
        };
        none.write(&[6000]).unwrap();
        assert!(none.uart.0.is_empty());
    }

    #[test]
    fn positions_round_and_bandwidth() {
        use crate::output::bus::{frame_bytes, position};
        assert_eq!(position(8192), 2048);
        assert_eq!(position(8193), 2048);
        assert_eq!(position(8194), 2049);
        assert_eq!(position(u16::MAX), 16383);
        let servos: Vec<ServoDesc> = (0..16).map(|c| servo(c, c + 1)).collect();
        assert_eq!(frame_bytes(Protocol::Dynamixel, &servos), 94);
        assert_eq!(
            frame_bytes(Protocol::Feetech(FeetechSeries::Sts), &servos),
            56
        );
        // 94 bytes at 1 Mbaud, 10 bits each: 940 µs.
        assert_eq!(crate::output::maestro::frame_time_us(94, 1_000_000), 940);
    }
}
