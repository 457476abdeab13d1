//! NXP PCA9685: 16 channels of 12-bit PWM over I2C, through the `pwm-pca9685`
//! driver.
//!
//! ## Registers (NXP PCA9685 datasheet, section 7.3)
//!
//! | register | address | used for |
//! |---|---|---|
//! | MODE1 | `0x00` | bit 7 RESTART, bit 5 AI (auto-increment), bit 4 SLEEP, bit 0 ALLCALL; `0x11` at power-up |
//! | LEDn_ON_L, _ON_H, _OFF_L, _OFF_H | `0x06 + 4n` .. `0x09 + 4n` | 12-bit on and off counts; bit 4 of _OFF_H is "full off" |
//! | PRE_SCALE | `0xFE` | the PWM frequency; writable only while SLEEP is set |
//!
//! The PWM period is 4096 ticks of the oscillator divided by `prescale + 1`,
//! so `prescale = round(osc / (4096 · f)) − 1` (datasheet equation 1; with the
//! 25 MHz internal oscillator, 200 Hz gives 30). The chip accepts 3..=255.
//!
//! ## What goes on the bus
//!
//! [`Pca9685::init`] (with the driver's cached MODE1 at its power-up value):
//!
//! 1. MODE1 ← `0x11` (SLEEP | ALLCALL): stops the oscillator, even when the chip
//!    kept running through a reset of the microcontroller;
//! 2. PRE_SCALE ← the prescale;
//! 3. MODE1 ← `0x31` (AI | SLEEP | ALLCALL): auto-increment on;
//! 4. ALL_LED_OFF_L, _H (`0xFC`, `0xFD`) ← `00 10`: every output full off, so
//!    that nothing moves before the first frame (the chip's own reset state,
//!    made sure of when it kept old values through a reset of the board);
//! 5. MODE1 ← `0x21` (AI | ALLCALL): wakes the oscillator;
//! 6. waits 500 µs, the datasheet's oscillator start-up time, before any PWM
//!    register is written.
//!
//! Every [`ServoOutput::write`] then sends **one auto-increment burst** of 65
//! bytes: the register address `0x06` (LED0_ON_L) and, for each of the 16
//! channels `n`, `on_l on_h off_l off_h` = `00 00 (off & 0xFF) (off >> 8)`
//! (on at count 0, off at `off`), or `00 00 00 10` (bit 4 of LEDn_OFF_H:
//! full off) for a target of 0 and for the channels past the end of the
//! frame. Writing the PWM registers also clears a pending RESTART, so no
//! explicit restart is needed after waking.

//! ## Counts
//!
//! One tick lasts `(prescale + 1) / osc` seconds, so a target of `q`
//! quarter-µs is `round(q · osc / (4·10⁶ · (prescale + 1)))` ticks, saturated to
//! 4095. This is `pulse_us · 4096 · f / 10⁶` with the frequency the prescale
//! actually gives, not the one asked for: at 200 Hz the chip runs at
//! 25 MHz / (4096 · 31) = 196.9 Hz, and 1500 µs is 1210 ticks, where the
//! nominal 200 Hz would give 1229 (24 µs too long).
//!
//! The internal oscillator is only nominally 25 MHz. If a scope shows another
//! frequency, give the measured one to [`Pca9685::with_oscillator`].
//!
//! ## Bus time
//!
//! A frame is one transaction of 66 bytes (address included) of 9 clocks
//! each, 594 clocks: 1.49 ms at 400 kHz. The chip starts a new pulse once per
//! period (20 ms at 50 Hz, 2.5 ms at 400 Hz), so a board writes at most once
//! a period ([`super::Decimated`], or its own clock).

use embedded_hal::delay::DelayNs;
use embedded_hal::i2c::I2c;
use pwm_pca9685::{Channel, ChannelOnOffControl, Error as DriverError, Pca9685 as Driver};

use super::{ConfigError, OutputError, ServoOutput};

/// The internal oscillator's nominal frequency, Hz.
pub const OSCILLATOR_HZ: u32 = 25_000_000;
/// Output channels on one chip.
pub const CHANNELS: usize = 16;
/// The largest on/off count (12 bits).
pub const COUNT_MAX: u16 = 4095;
/// The oscillator start-up time after SLEEP is cleared, µs.
pub const WAKE_US: u32 = 500;
/// The lowest servo frame rate, Hz.
pub const FRAME_HZ_MIN: u32 = 50;
/// The highest servo frame rate, Hz (a 2.5 ms period).
pub const FRAME_HZ_MAX: u32 = 400;

/// Checks a frame rate against [`FRAME_HZ_MIN`]..=[`FRAME_HZ_MAX`].
pub fn check_frame_rate(frame_hz: u32) -> Result<u32, ConfigError> {
    if (FRAME_HZ_MIN..=FRAME_HZ_MAX).contains(&frame_hz) {
        Ok(frame_hz)
    } else {
        Err(ConfigError::FrameRate(frame_hz))
    }
}

/// The prescale for `frame_hz` from an `osc_hz` oscillator:
/// `round(osc / (4096 · f)) − 1`, which must lie in 3..=255.
pub fn prescale(osc_hz: u32, frame_hz: u32) -> Result<u8, ConfigError> {
    let per_period = 4096 * u64::from(frame_hz);
    let Some(ticks) = (u64::from(osc_hz) + per_period / 2).checked_div(per_period) else {
        return Err(ConfigError::FrameRate(frame_hz));
    };
    match ticks.checked_sub(1).map(u8::try_from) {
        Some(Ok(p)) if p >= 3 => Ok(p),
        _ => Err(ConfigError::Prescale(
            u32::try_from(ticks.saturating_sub(1)).unwrap_or(u32::MAX),
        )),
    }
}

/// The off count for a pulse of `target_q` quarter-µs with this oscillator and
/// prescale: `round(q · osc / (4·10⁶ · (prescale + 1)))`, at most 4095.
#[inline]
#[must_use]
pub fn counts(target_q: u16, osc_hz: u32, prescale: u8) -> u16 {
    let num = u64::from(target_q) * u64::from(osc_hz);
    let den = 4_000_000 * (u64::from(prescale) + 1);
    let c = (num + den / 2).checked_div(den).unwrap_or(u64::MAX);
    u16::try_from(c).unwrap_or(u16::MAX).min(COUNT_MAX)
}

/// Servos on a PCA9685: `targets[i]` drives channel `i` (up to 16).
#[derive(Debug)]
pub struct Pca9685<I2C> {
    driver: Driver<I2C>,
    osc_hz: u32,
    prescale: u8,
}

impl<I2C: I2c> Pca9685<I2C> {
    /// A chip at 7-bit `address` (0x40 with no address pins strapped) driving
    /// servos at `frame_hz` (50–400 Hz) from the internal oscillator.
    /// Sends nothing: call [`Pca9685::init`] before the first write.
    pub fn new(i2c: I2C, address: u8, frame_hz: u32) -> Result<Self, ConfigError> {
        Self::with_oscillator(i2c, address, frame_hz, OSCILLATOR_HZ)
    }

    /// As [`Pca9685::new`], with the oscillator's measured frequency.
    pub fn with_oscillator(
        i2c: I2C,
        address: u8,
        frame_hz: u32,
        osc_hz: u32,
    ) -> Result<Self, ConfigError> {
        let prescale = prescale(osc_hz, check_frame_rate(frame_hz)?)?;
        let driver = Driver::new(i2c, address).map_err(|_| ConfigError::Address(address))?;
        Ok(Self {
            driver,
            osc_hz,
            prescale,
        })
    }

    /// Sets the frequency and wakes the chip: see the module docs for the
    /// exact sequence. Blocks for 500 µs on `delay`.
    pub fn init(&mut self, delay: &mut impl DelayNs) -> Result<(), OutputError<I2C::Error>> {
        self.driver.disable().map_err(driver_error)?;
        self.driver
            .set_prescale(self.prescale)
            .map_err(driver_error)?;
        self.driver
            .set_channel_full_off(Channel::All)
            .map_err(driver_error)?;
        self.driver.enable().map_err(driver_error)?;
        delay.delay_us(WAKE_US);
        Ok(())
    }

    /// The prescale written by [`Pca9685::init`].
    #[must_use]
    pub fn prescale(&self) -> u8 {
        self.prescale
    }

    /// Gives back the I2C bus.
    #[must_use]
    pub fn release(self) -> I2C {
        self.driver.destroy()
    }
}

impl<I2C: I2c> ServoOutput for Pca9685<I2C> {
    type Error = OutputError<I2C::Error>;

    /// One auto-increment burst for all 16 channels.
    fn write(&mut self, targets: &[u16]) -> Result<(), Self::Error> {
        if targets.len() > CHANNELS {
            return Err(OutputError::TooManyTargets {
                given: targets.len(),
                channels: CHANNELS,
            });
        }
        let mut values = [ChannelOnOffControl {
            on: 0,
            off: 0,
            full_on: false,
            full_off: true,
        }; CHANNELS];
        for (v, &target) in values.iter_mut().zip(targets) {
            if target != 0 {
                v.off = counts(target, self.osc_hz, self.prescale);
                v.full_off = false;
            }
        }
        self.driver.set_all_channels(&values).map_err(driver_error)
    }
}

/// Maps the driver's error to ours.
fn driver_error<E>(e: DriverError<E>) -> OutputError<E> {
    match e {
        DriverError::I2C(e) => OutputError::Bus(e),
        DriverError::InvalidInputData => OutputError::Rejected,
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use embedded_hal::i2c::ErrorKind;
    use embedded_hal_mock::eh1::delay::{CheckedDelay, Transaction as Delay};
    use embedded_hal_mock::eh1::i2c::{Mock, Transaction as I2cT};
    use std::vec;

    const ADDR: u8 = 0x40;

    #[test]
    fn prescale_matches_the_datasheet() {
        // Datasheet example: 200 Hz from 25 MHz -> round(30.52) - 1 = 30.
        assert_eq!(prescale(OSCILLATOR_HZ, 200), Ok(30));
        // 25e6 / (4096 · 50) = 122.07 -> 121; / (4096 · 333) = 18.33 -> 17.
        assert_eq!(prescale(OSCILLATOR_HZ, 50), Ok(121));
        assert_eq!(prescale(OSCILLATOR_HZ, 333), Ok(17));
        // 100 MHz at 50 Hz needs 487; 1 MHz at 333 Hz would be 0.
        assert_eq!(prescale(100_000_000, 50), Err(ConfigError::Prescale(487)));
        assert_eq!(prescale(1_000_000, 333), Err(ConfigError::Prescale(0)));
        assert_eq!(prescale(OSCILLATOR_HZ, 0), Err(ConfigError::FrameRate(0)));
    }

    #[test]
    fn counts_worked_by_hand() {
        // 50 Hz: prescale 121, a tick is 122 / 25 MHz = 4.88 µs = 19.52 q.
        // 1500 µs: 6000 · 25 / 488 = 307.38 -> 307.
        assert_eq!(counts(6000, OSCILLATOR_HZ, 121), 307);
        // 1000 µs: 204.92 -> 205; 2000 µs: 409.84 -> 410.
        assert_eq!(counts(4000, OSCILLATOR_HZ, 121), 205);
        assert_eq!(counts(8000, OSCILLATOR_HZ, 121), 410);
        // 61 µs: 244 · 25 / 488 = 12.5 exactly -> rounds up.
        assert_eq!(counts(244, OSCILLATOR_HZ, 121), 13);
        // 200 Hz, prescale 30: 1500 µs is 6000 · 25 / 124 = 1209.68 -> 1210.
        assert_eq!(counts(6000, OSCILLATOR_HZ, 30), 1210);
        // 333 Hz, prescale 17: 2500 µs = 250 000 / 72 = 3472.2; longer
        // pulses than the period saturate at 4095.
        assert_eq!(counts(10_000, OSCILLATOR_HZ, 17), 3472);
        assert_eq!(counts(u16::MAX, OSCILLATOR_HZ, 17), 4095);
    }

    /// The init sequence of the datasheet (module doc) at `addr`.
    fn init_writes(addr: u8, prescale: u8) -> vec::Vec<I2cT> {
        vec![
            I2cT::write(addr, vec![0x00, 0x11]),
            I2cT::write(addr, vec![0xFE, prescale]),
            I2cT::write(addr, vec![0x00, 0x31]),
            I2cT::write(addr, vec![0xFC, 0x00, 0x10]),
            I2cT::write(addr, vec![0x00, 0x21]),
        ]
    }

    /// One burst from LED0_ON_L (0x06): per channel ON_L, ON_H, OFF_L,
    /// OFF_H; `None` is full off (OFF_H bit 4).
    fn burst(addr: u8, offs: &[Option<u16>; 16]) -> I2cT {
        let mut bytes = vec![0x06];
        for off in offs {
            match off {
                Some(c) => bytes.extend_from_slice(&[0, 0, (c & 0xFF) as u8, (c >> 8) as u8]),
                None => bytes.extend_from_slice(&[0, 0, 0, 0x10]),
            }
        }
        assert_eq!(bytes.len(), 65);
        I2cT::write(addr, bytes)
    }

    #[test]
    fn init_and_frames_send_the_datasheet_bytes() {
        // Frame 1: LED0 307 = 0x133, LED1 205 = 0xCD, LED2 off (target 0),
        // LED3..15 off (past the frame). Frame 2: LED0 410 = 0x19A.
        let mut f1 = [None; 16];
        f1[0] = Some(307);
        f1[1] = Some(205);
        let mut f2 = [None; 16];
        f2[0] = Some(410);
        let mut expect = init_writes(ADDR, 121);
        expect.push(burst(ADDR, &f1));
        expect.push(burst(ADDR, &f2));
        let mut delay = CheckedDelay::new(&[Delay::delay_us(500)]);
        let mut out = Pca9685::new(Mock::new(&expect), ADDR, 50).unwrap();
        assert_eq!(out.prescale(), 121);
        out.init(&mut delay).unwrap();
        out.write(&[6000, 4000, 0]).unwrap();
        out.write(&[8000]).unwrap();
        out.release().done();
        delay.done();
    }

    #[test]
    fn sixteen_channels_reach_led15_and_seventeen_are_refused() {
        // 200 Hz at address 0x41: prescale 30 = 0x1E; 1500 µs = 1210 = 0x4BA.
        let addr = 0x41;
        let mut expect = init_writes(addr, 0x1E);
        expect.push(burst(addr, &[Some(1210); 16]));
        let mut delay = CheckedDelay::new(&[Delay::delay_us(500)]);
        let mut out = Pca9685::new(Mock::new(&expect), addr, 200).unwrap();
        out.init(&mut delay).unwrap();
        out.write(&[6000; 16]).unwrap();
        assert_eq!(
            out.write(&[6000; 17]),
            Err(OutputError::TooManyTargets {
                given: 17,
                channels: 16
            })
        );
        out.release().done();
        delay.done();
    }

    #[test]
    fn four_hundred_hertz_is_the_top() {
        // 25 MHz / (4096 · 400) = 15.26 -> prescale 14; a tick is
        // 15 / 25 MHz = 0.6 µs: 1500 µs is 2500 ticks exactly.
        assert_eq!(prescale(OSCILLATOR_HZ, 400), Ok(14));
        assert_eq!(counts(6000, OSCILLATOR_HZ, 14), 2500);
        let mut expect = init_writes(ADDR, 14);
        let mut f = [None; 16];
        f[0] = Some(2500);
        expect.push(burst(ADDR, &f));
        let mut delay = CheckedDelay::new(&[Delay::delay_us(500)]);
        let mut out = Pca9685::new(Mock::new(&expect), ADDR, 400).unwrap();
        out.init(&mut delay).unwrap();
        out.write(&[6000]).unwrap();
        out.release().done();
        delay.done();
    }

    #[test]
    fn bus_errors_and_bad_settings_surface_as_typed_errors() {
        let expect = [I2cT::write(ADDR, vec![0x00, 0x11]).with_error(ErrorKind::Other)];
        let mut out = Pca9685::new(Mock::new(&expect), ADDR, 50).unwrap();
        let mut delay = CheckedDelay::new(&[]);
        assert_eq!(
            out.init(&mut delay),
            Err(OutputError::Bus(ErrorKind::Other))
        );
        out.release().done();
        delay.done();

        for (addr, hz, err) in [
            (0x70, 50, ConfigError::Address(0x70)),
            (0x03, 50, ConfigError::Address(0x03)),
            (ADDR, 49, ConfigError::FrameRate(49)),
            (ADDR, 401, ConfigError::FrameRate(401)),
        ] {
            let mut bus = Mock::new(&[]);
            assert_eq!(Pca9685::new(bus.clone(), addr, hz).err(), Some(err));
            bus.done();
        }
    }
}
