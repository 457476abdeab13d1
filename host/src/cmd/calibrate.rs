//! `marionette calibrate`: find a servo's limits by moving it from the
//! keyboard, and write them into the rig file.
//!
//! The tool talks to a board the way `stream` does: a real one on a serial
//! port (`--port`), or, without one, the emulated board booted here with the
//! rig (and no table) in its flash region. It moves one servo channel with
//! the wire protocol's `Jog` command (protocol version 3): the board moves
//! the channel through the slew limiter a performance uses, so a jog never
//! leaves the channel's calibrated range (the rig's `pulse_us`, or a bus
//! servo's `limits`) and never moves faster than the servo's `max_speed` and
//! `max_accel`. Start from the servo's full travel in the rig file (its
//! datasheet's range) and narrow it to where the figure's mechanism allows.
//! The screen shows the pulse (a bus servo's position) commanded and, on the
//! emulated board, the one its servo link actually carries (decoded from
//! UART1). While it waits, the tool repeats the jog every 250 ms:
//! a board that hears nothing for a second ends the jog and eases the
//! servo back to rest (a host that crashed must not leave it held).
//!
//! | key | does |
//! |---|---|
//! | ← → (or `h` `l`) | one small step down / up (10 µs; a bus servo 5 positions) |
//! | ↓ ↑ (or `j` `k`) | ten steps down / up |
//! | `n` | the current value is the **min** (the low end of the range) |
//! | `x` | the current value is the **max** (the high end) |
//! | `c` | the current value is the **centre** |
//! | `w` | write min, centre and max into the rig file |
//! | `q` (or Ctrl-C) | ease the servo back to rest and quit |
//!
//! Writing keeps the rig file's comments and layout (`toml_edit`): in the
//! `[[servo]]` entry of the channel, a pulse servo gets `pulse_us = [min,
//! max]` (in the order the file had them, less its `trim_us`) and `rest_us =
//! centre`; a bus servo `limits = [min, max]` and `center = centre`
//! (whichever were set). The edited file is checked with the rig-file reader
//! before it is written; a result it refuses is not written (the message
//! says why). The board keeps the rig it booted with: flash the new one (or
//! run the tool again) to see the new limits in force.

use super::CmdError;
use crate::perform::{self, ServoFormat};
use crate::qemu::{self, Config, Emulator};
use crate::rigfile::{self, RigFile};
use console::{Key, Term};
use marionette_core::rig::ServoDesc;
use marionette_core::servo::quarter_us;
use marionette_core::wire::{
    Command, CommandKind, Hello, Message, PROTOCOL_VERSION, Status, StatusReason,
};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use toml_edit::{DocumentMut, Item, Value};

/// Arguments of `marionette calibrate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The rig file (docs/rig.md; read, and written with the limits found),
    /// or a rig name: `rigs/<name>.toml` here (a built-in rig is refused,
    /// having no file to write to).
    #[arg(long, default_value = "rigs/humanoid16.toml")]
    pub rig: PathBuf,
    /// The servo channel to calibrate.
    #[arg(long)]
    pub channel: u8,
    /// A real board's tracker serial port (without it: the emulated board).
    #[arg(long)]
    pub port: Option<String>,
    /// Baud rate of the tracker link.
    #[arg(long, default_value_t = 921_600)]
    pub baud: u32,
}

/// How often a held jog is repeated while `calibrate` waits (for a key, or
/// for the servo to arrive): well within the board's jog watchdog
/// ([`marionette_core::perform::JOG_TIMEOUT_US`], a second), which ends a
/// jog whose host has gone quiet.
const KEEP_ALIVE: Duration = Duration::from_millis(250);

/// A board to jog.
trait Link {
    /// Sends a wire frame.
    fn send(&mut self, bytes: &[u8]) -> Result<(), CmdError>;
    /// What the board sent on its tracker link since the last call.
    fn replies(&mut self) -> Vec<u8>;
    /// What it sent on its servo link since the last call (`None`: not
    /// visible from here).
    fn servo(&mut self) -> Option<Vec<u8>>;
}

/// The emulated board, with the rig in its region.
struct Emulated {
    emulator: Emulator,
    _region: tempfile::NamedTempFile,
}

impl Link for Emulated {
    fn send(&mut self, bytes: &[u8]) -> Result<(), CmdError> {
        Ok(self.emulator.send(bytes)?)
    }
    fn replies(&mut self) -> Vec<u8> {
        self.emulator.take_replies()
    }
    fn servo(&mut self) -> Option<Vec<u8>> {
        Some(self.emulator.take_servo())
    }
}

/// A real board on a serial port.
struct Port {
    port: Box<dyn serialport::SerialPort>,
    received: Arc<Mutex<Vec<u8>>>,
}

impl Link for Port {
    fn send(&mut self, bytes: &[u8]) -> Result<(), CmdError> {
        std::io::Write::write_all(&mut self.port, bytes).map_err(|e| e.to_string().into())
    }
    fn replies(&mut self) -> Vec<u8> {
        self.received
            .lock()
            .map(|mut v| std::mem::take(&mut *v))
            .unwrap_or_default()
    }
    fn servo(&mut self) -> Option<Vec<u8>> {
        None
    }
}

/// Opens the serial port and starts a reader thread.
fn open_port(name: &str, baud: u32) -> Result<Port, CmdError> {
    let port = serialport::new(name, baud)
        .timeout(Duration::from_millis(50))
        .open()
        .map_err(|e| format!("{name}: {e}"))?;
    let mut reader = port.try_clone().map_err(|e| format!("{name}: {e}"))?;
    let received = Arc::new(Mutex::new(Vec::new()));
    let sink = Arc::clone(&received);
    std::thread::spawn(move || {
        let mut buf = [0u8; 256];
        loop {
            match reader.read(&mut buf) {
                Ok(n) if n > 0 => {
                    if let (Ok(mut v), Some(chunk)) = (sink.lock(), buf.get(..n)) {
                        v.extend_from_slice(chunk);
                    }
                }
                // Time-outs (nothing to read) and a vanished port alike.
                Ok(_) | Err(_) => std::thread::sleep(Duration::from_millis(5)),
            }
        }
    });
    Ok(Port { port, received })
}

/// Boots the emulated board with the rig alone in its region.
fn boot_emulated(region: &[u8]) -> Result<Emulated, CmdError> {
    let mut file = tempfile::NamedTempFile::new()?;
    std::io::Write::write_all(&mut file, region)?;
    let config = Config {
        tables: Some(file.path().to_path_buf()),
        timeout: Duration::from_secs(6 * 3600),
        ..Config::new(qemu::firmware_elf("perform")?)
    };
    Ok(Emulated {
        emulator: Emulator::start(&config)?,
        _region: file,
    })
}

/// What a calibration has found: µs (pulse servos) or positions (bus
/// servos); `None` where not set.
#[derive(Clone, Copy, Debug, Default)]
pub struct Found {
    /// The pulse (position) at the rig's first `angle`.
    pub min: Option<f32>,
    /// The rest pulse (a bus servo's position at joint angle 0).
    pub centre: Option<f32>,
    /// The pulse (position) at the rig's second `angle`.
    pub max: Option<f32>,
}

/// The calibration session.
struct Session<'l> {
    link: &'l mut dyn Link,
    channel: u8,
    /// A bus servo (positions), not a pulse servo (µs).
    bus: bool,
    /// The channel's calibrated range, µs or positions: the board's limit.
    range: (f32, f32),
    /// The commanded value, µs or positions.
    value: f32,
    /// The last value seen on the servo link.
    seen: Option<f32>,
    format: Option<ServoFormat>,
    /// Everything the servo link carried (decoded as a whole: its frames
    /// may be cut anywhere).
    servo_bytes: Vec<u8>,
    /// Reply bytes after the last frame delimiter.
    reply_bytes: Vec<u8>,
    seq: u32,
    /// When the last command went out, if a jog is held (not ended).
    holding: Option<Instant>,
    found: Found,
    message: String,
}

impl Session<'_> {
    fn command(&mut self, kind: CommandKind) -> Result<u32, CmdError> {
        self.seq = self.seq.wrapping_add(1);
        let msg = Message::Command(Command {
            seq: self.seq,
            kind,
        });
        self.link.send(&perform::encode(&msg)?)?;
        Ok(self.seq)
    }

    /// Jogs to `value` (µs or positions), kept within the channel's range.
    fn jog(&mut self, value: f32) -> Result<(), CmdError> {
        let (lo, hi) = self.range;
        self.value = value.clamp(lo, hi);
        if self.value != value {
            self.message = format!(
                "at the rig's limit ({lo:.0}..{hi:.0}): widen it in the rig file to go further"
            );
        }
        self.hold()
    }

    /// Sends the jog to the commanded value (again), holding it.
    fn hold(&mut self) -> Result<(), CmdError> {
        self.command(CommandKind::Jog {
            channel: self.channel,
            target: quarter_us(self.value),
        })?;
        self.holding = Some(Instant::now());
        Ok(())
    }

    /// Ends the jog: the servo eases back to rest, and is no longer held.
    fn release(&mut self) -> Result<(), CmdError> {
        self.holding = None;
        self.command(CommandKind::Jog {
            channel: self.channel,
            target: 0,
        })?;
        Ok(())
    }

    /// Repeats a held jog once [`KEEP_ALIVE`] has passed since the last.
    fn keep_alive(&mut self) -> Result<(), CmdError> {
        match self.holding {
            Some(sent) if sent.elapsed() >= KEEP_ALIVE => self.hold(),
            _ => Ok(()),
        }
    }

    /// Takes what the board sent: Acks (a refused jog is shown), and the
    /// servo link's last value for the channel.
    fn poll(&mut self) {
        self.reply_bytes.extend(self.link.replies());
        let cut = self
            .reply_bytes
            .iter()
            .rposition(|&b| b == 0)
            .map_or(0, |i| i + 1);
        let complete: Vec<u8> = self.reply_bytes.drain(..cut).collect();
        for m in perform::decode_replies(&complete) {
            if let Message::Ack(a) = m
                && !a.ok
            {
                self.message = format!(
                    "the board refused command {} (see `Jog` in the wire spec)",
                    a.seq
                );
            }
        }
        let Some(new) = self.link.servo() else {
            return;
        };
        if new.is_empty() {
            return;
        }
        self.servo_bytes.extend(new);
        if let Some(format) = &self.format {
            let ch = usize::from(self.channel);
            if let Some(v) = format
                .decode(&self.servo_bytes)
                .iter()
                .rev()
                .find_map(|f| f.get(ch).copied())
            {
                self.seen = (v != 0).then_some(f32::from(v) / 4.0);
            }
        }
    }

    /// Polls and redraws until the servo link shows the commanded value (at
    /// most `wait`; a real board's link is not visible: just `wait`).
    fn settle(&mut self, term: &Term, rig: &str, wait: Duration) -> Result<(), CmdError> {
        let until = Instant::now() + wait;
        let mut shown = String::new();
        loop {
            self.keep_alive()?;
            self.poll();
            let screen = self.screen(rig);
            if screen != shown {
                term.clear_screen()?;
                term.write_line(&screen)?;
                shown = screen;
            }
            let arrived = self.format.is_some() && self.seen == Some(self.value);
            if arrived || Instant::now() >= until {
                return Ok(());
            }
            std::thread::sleep(Duration::from_millis(25));
        }
    }

    fn screen(&self, rig: &str) -> String {
        let unit = if self.bus { "" } else { " µs" };
        let show = |v: Option<f32>| v.map_or("-".to_string(), |v| format!("{v:.0}{unit}"));
        let (small, big) = if self.bus {
            ("5", "50")
        } else {
            ("10 µs", "100 µs")
        };
        let seen = if self.format.is_some() {
            show(self.seen)
        } else {
            "(not visible)".to_string()
        };
        format!(
            "marionette calibrate: rig {rig}, channel {}, range {}..{}\n\
             {}: commanded {}, on the servo link {seen}\n\
             min {}   centre {}   max {}\n\
             keys: ←/→ or h/l {small}, ↓/↑ or j/k {big}; n min, c centre, x max; w write; q quit\n\
             {}",
            self.channel,
            show(Some(self.range.0)),
            show(Some(self.range.1)),
            if self.bus { "position" } else { "pulse" },
            show(Some(self.value)),
            show(self.found.min),
            show(self.found.centre),
            show(self.found.max),
            self.message
        )
    }
}

/// Opens a session: `Hello` until the board answers with its `Status`.
fn hello(link: &mut dyn Link) -> Result<Status, CmdError> {
    let msg = Message::Hello(Hello {
        protocol_version: PROTOCOL_VERSION,
    });
    let until = Instant::now() + Duration::from_secs(30);
    let mut next_hello = Instant::now();
    let mut bytes = Vec::new();
    while Instant::now() < until {
        if Instant::now() >= next_hello {
            link.send(&perform::encode(&msg)?)?;
            next_hello = Instant::now() + Duration::from_secs(1);
        }
        std::thread::sleep(Duration::from_millis(20));
        bytes.extend(link.replies());
        if let Some(Message::Status(s)) = perform::decode_replies(&bytes)
            .into_iter()
            .find(|m| matches!(m, Message::Status(_)))
        {
            return Ok(s);
        }
    }
    Err("the board did not answer Hello with a Status".into())
}

/// Why a board that answered `status` cannot be jogged, if it cannot.
fn unusable(status: &Status) -> Option<String> {
    match status.reason {
        StatusReason::ProtocolMismatch => Some(format!(
            "the board refused protocol version {PROTOCOL_VERSION} (Jog needs it): update its firmware"
        )),
        StatusReason::Unsupported | StatusReason::NoRig | StatusReason::RigTooLarge => Some(
            format!("the board cannot drive this rig: {:?}", status.reason),
        ),
        _ => None,
    }
}

/// Runs the keyboard session.
pub fn run(args: &Args) -> Result<(), CmdError> {
    let path = rigfile::resolve(&args.rig);
    if path.starts_with(crate::bundle::folder()) {
        return Err(format!(
            "{}: a rig built into marionette has no file to write the limits to; \
             copy {} and calibrate the copy",
            args.rig.display(),
            path.display()
        )
        .into());
    }
    let rig = rigfile::load(&path)?;
    let desc = rig.desc();
    let servo = *desc
        .servos
        .iter()
        .find(|s| s.channel == args.channel)
        .ok_or_else(|| {
            format!(
                "{}: no [[servo]] on channel {}",
                path.display(),
                args.channel
            )
        })?;
    let term = Term::stdout();
    if !term.is_term() {
        return Err("calibrate is interactive: run it in a terminal".into());
    }
    // A signal (SIGTERM, SIGHUP; Ctrl-C while the screen settles) quits as
    // `q` does; the emulated board runs out of the terminal's Ctrl-C, ended
    // by this process ([`crate::interrupt`]).
    let stop = crate::interrupt::stop_on_ctrl_c("calibrate")?;
    let rig_blob = rigfile::to_blob(&rig)?;
    let region = perform::region(&rig_blob, None);
    let channels = desc
        .servos
        .iter()
        .map(|s| usize::from(s.channel) + 1)
        .max()
        .unwrap_or(0);
    let mut link: Box<dyn Link> = match &args.port {
        Some(port) => Box::new(open_port(port, args.baud)?),
        None => Box::new(boot_emulated(&region)?),
    };
    let status = hello(link.as_mut())?;
    if let Some(why) = unusable(&status) {
        return Err(why.into());
    }
    let cal = servo.calibration();
    let format = if args.port.is_some() {
        None
    } else {
        ServoFormat::of_region(&region, channels)
    };
    let mut s = Session {
        link: link.as_mut(),
        channel: args.channel,
        bus: desc.output.is_bus(),
        range: (cal.pulse_low(), cal.pulse_high()),
        value: servo.rest_us,
        seen: None,
        format,
        servo_bytes: Vec::new(),
        reply_bytes: Vec::new(),
        seq: 0,
        holding: None,
        found: Found::default(),
        message: String::new(),
    };
    let name = rig.name().to_string();
    s.jog(servo.rest_us)?;
    s.settle(&term, &name, Duration::from_secs(2))?;
    let saved = terminal_mode();
    let outcome = keys(&term, &mut s, (&path, &servo, &name), stop);
    // Back to rest; Disarm also ends the emulated board's session.
    s.message = "back to rest".into();
    s.value = servo.rest_us;
    let _ = s.release();
    let _ = s.settle(&term, &name, Duration::from_secs(3));
    let _ = s.command(CommandKind::Disarm);
    restore_terminal(saved);
    let _ = term.write_line("");
    outcome
}

/// The terminal's mode, to restore at the end: the key reader may still be
/// waiting for a key (in raw mode) when a signal ends the session.
fn terminal_mode() -> Option<nix::sys::termios::Termios> {
    nix::sys::termios::tcgetattr(std::io::stdin()).ok()
}

/// Puts the terminal back in `saved` mode.
fn restore_terminal(saved: Option<nix::sys::termios::Termios>) {
    if let Some(mode) = saved {
        let now = nix::sys::termios::SetArg::TCSANOW;
        let _ = nix::sys::termios::tcsetattr(std::io::stdin(), now, &mode);
    }
}

/// Reads keys on a thread of its own, so that the session can repeat its
/// jog while no key comes. The thread ends after a key that quits.
fn key_reader() -> mpsc::Receiver<std::io::Result<Key>> {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let term = Term::stdout();
        loop {
            let key = term.read_key_raw();
            let last = key.as_ref().map_or(true, quits);
            if tx.send(key).is_err() || last {
                return;
            }
        }
    });
    rx
}

/// Whether `key` ends the session: `q`, Escape or Ctrl-C.
fn quits(key: &Key) -> bool {
    matches!(key, Key::Char('q') | Key::Escape | Key::CtrlC)
}

/// The key loop, until `q`, Escape or Ctrl-C (a key in the terminal's raw
/// mode, or a signal that set `stop`), repeating the held jog while no key
/// comes ([`KEEP_ALIVE`]).
fn keys(
    term: &Term,
    s: &mut Session<'_>,
    (path, servo, rig): (&Path, &ServoDesc, &str),
    stop: &AtomicBool,
) -> Result<(), CmdError> {
    let (small, big) = if s.bus { (5.0, 50.0) } else { (10.0, 100.0) };
    let keys = key_reader();
    while !stop.load(Ordering::Relaxed) {
        let key = match keys.recv_timeout(KEEP_ALIVE / 5) {
            Ok(key) => key?,
            Err(RecvTimeoutError::Timeout) => {
                // Repeats the held jog; shows what the servo link carries.
                s.settle(term, rig, Duration::ZERO)?;
                continue;
            }
            Err(RecvTimeoutError::Disconnected) => return Ok(()),
        };
        if quits(&key) {
            return Ok(());
        }
        s.message.clear();
        let step = match key {
            Key::ArrowLeft | Key::Char('h') => Some(-small),
            Key::ArrowRight | Key::Char('l') => Some(small),
            Key::ArrowDown | Key::Char('j') => Some(-big),
            Key::ArrowUp | Key::Char('k') => Some(big),
            Key::Char('n') => {
                s.found.min = Some(s.value);
                None
            }
            Key::Char('x') => {
                s.found.max = Some(s.value);
                None
            }
            Key::Char('c') => {
                s.found.centre = Some(s.value);
                None
            }
            Key::Char('w') => {
                s.message = match write_rig(path, servo, s.bus, s.found) {
                    Ok(()) => format!("wrote {}", path.display()),
                    Err(e) => format!("not written: {e}"),
                };
                None
            }
            _ => None,
        };
        if let Some(step) = step {
            s.jog(s.value + step)?;
        }
        s.settle(term, rig, Duration::from_secs(2))?;
    }
    Ok(())
}

/// Sets `key` of `table` to `value`, keeping the old value's comments and
/// spacing.
fn set(table: &mut toml_edit::Table, key: &str, mut value: Value) {
    if let Some(old) = table.get(key).and_then(Item::as_value) {
        *value.decor_mut() = old.decor().clone();
    }
    table.insert(key, Item::Value(value));
}

/// Writes what was found into the channel's `[[servo]]` of the rig file.
fn write_rig(path: &Path, servo: &ServoDesc, bus: bool, found: Found) -> Result<(), CmdError> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let edited = edit_rig(&text, servo.channel, bus, found)?;
    // The rig-file reader's word on the result, before it replaces the file.
    let _: RigFile = rigfile::parse(&edited, &path.display().to_string())?;
    // Replaced whole (a temporary file renamed), never half-written.
    crate::save::save(path, edited.as_bytes(), &[])?;
    Ok(())
}

/// The rig file's text with channel `channel`'s limits set (see the module
/// doc): `found` in µs (a pulse servo) or positions (`bus`). A range with
/// only one end found keeps the file's other end.
///
/// # Errors
///
/// The text is not TOML, has no `[[servo]]` on that channel, or only one
/// end of a range was found and the file has no range to take the other
/// from.
pub fn edit_rig(text: &str, channel: u8, bus: bool, found: Found) -> Result<String, CmdError> {
    let mut doc: DocumentMut = text.parse()?;
    let servos = doc
        .get_mut("servo")
        .and_then(Item::as_array_of_tables_mut)
        .ok_or("the rig file has no [[servo]]")?;
    let table = servos
        .iter_mut()
        .find(|t| t.get("channel").and_then(Item::as_integer) == Some(i64::from(channel)))
        .ok_or_else(|| format!("no [[servo]] with channel = {channel}"))?;
    let (range_key, centre_key) = if bus {
        ("limits", "center")
    } else {
        ("pulse_us", "rest_us")
    };
    if found.min.is_some() || found.max.is_some() {
        let old = table
            .get(range_key)
            .and_then(Item::as_array)
            .and_then(|a| Some([number(a.get(0)?)?, number(a.get(1)?)?]));
        let descending = old.is_some_and(|[a, b]| a > b);
        let (old_lo, old_hi) = old.map(|[a, b]| (a.min(b), a.max(b))).unzip();
        let (Some(lo), Some(hi)) = (found.min.or(old_lo), found.max.or(old_hi)) else {
            return Err(format!(
                "channel {channel} has no {range_key} to complete: set both min and max"
            )
            .into());
        };
        let mut pair = toml_edit::Array::new();
        for v in if descending { [hi, lo] } else { [lo, hi] } {
            pair.push(round(v));
        }
        set(table, range_key, Value::Array(pair));
    }
    if let Some(c) = found.centre {
        set(table, centre_key, Value::from(round(c)));
    }
    Ok(doc.to_string())
}

/// A TOML number as `f32`.
fn number(v: &Value) -> Option<f32> {
    v.as_integer()
        .map(|i| i as f32)
        .or_else(|| v.as_float().map(|f| f as f32))
}

/// A whole number of µs or positions.
fn round(v: f32) -> i64 {
    v.round() as i64
}

#[cfg(test)]
mod tests {
    use super::{Found, edit_rig};

    const RIG: &str = "\
# a puppet
[[servo]]
channel = 0
pulse_us = [500, 2500]   # full travel
rest_us = 1500

[[servo]]  # mirrored
channel = 1
pulse_us = [2400, 600]   # descending
max_speed = 7.0
";

    #[test]
    fn edits_keep_comments_layout_and_order() {
        let found = Found {
            min: Some(810.0),
            centre: Some(1490.4),
            max: Some(2190.0),
        };
        let got = edit_rig(RIG, 1, false, found).unwrap();
        let want = "\
# a puppet
[[servo]]
channel = 0
pulse_us = [500, 2500]   # full travel
rest_us = 1500

[[servo]]  # mirrored
channel = 1
pulse_us = [2190, 810]   # descending
max_speed = 7.0
rest_us = 1490
";
        assert_eq!(got, want);
        // One end found: the file's other end stays.
        let got = edit_rig(
            RIG,
            0,
            false,
            Found {
                max: Some(2300.0),
                ..Found::default()
            },
        )
        .unwrap();
        assert!(
            got.contains("pulse_us = [500, 2300]   # full travel\n"),
            "{got}"
        );
    }

    #[test]
    fn bus_servos_get_limits_and_center() {
        let rig = "[[servo]]\nchannel = 3\nid = 4\n";
        let found = Found {
            min: Some(1000.0),
            centre: Some(2050.0),
            max: Some(3000.0),
        };
        let got = edit_rig(rig, 3, true, found).unwrap();
        assert_eq!(
            got,
            "[[servo]]\nchannel = 3\nid = 4\nlimits = [1000, 3000]\ncenter = 2050\n"
        );
        let half = Found {
            min: Some(1000.0),
            ..Found::default()
        };
        assert!(edit_rig(rig, 3, true, half).is_err(), "no max to keep");
        assert!(edit_rig(rig, 5, true, found).is_err(), "no such channel");
    }
}
