//! The emulated board, driven from the host.
//!
//! [`Emulator`] boots a firmware ELF on QEMU `mps2-an386` with:
//!
//! - UART0 (tracker link) and UART1 (servo bus) on Unix sockets that this
//!   process connects to, so bytes can be streamed in and collected out;
//! - optionally a table blob loaded at the table region with
//!   `-device loader`, where the firmware reads it in place;
//! - optionally `-icount shift=7,align=off` for deterministic instruction counts;
//! - semihosting on, so the firmware's console lines arrive on QEMU's stdout
//!   and its exit status becomes QEMU's.
//!
//! Nothing here can hang: every wait has a deadline, and dropping an
//! [`Emulator`] kills QEMU. Under a command that handles Ctrl-C itself
//! (`live`), QEMU runs in a process group of its own, so the terminal's
//! Ctrl-C reaches only the command, which disarms and checks the board
//! before it ends it ([`crate::interrupt`]).

use crate::interrupt;
use std::io::{Read, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

/// The QEMU binary for Arm system emulation.
pub const QEMU: &str = "qemu-system-arm";
/// The Debian package that provides [`QEMU`].
pub const QEMU_PACKAGE: &str = "qemu-system-arm";
/// Where the firmware expects the table blob (see `firmware/boards/qemu-an386/memory.x`).
pub const TABLE_REGION_ADDR: u32 = 0x0010_0000;
/// Size of the emulated board's table region, bytes.
pub const TABLE_REGION_LEN: usize = 1 << 20;
/// The firmware's target triple.
pub const TARGET: &str = "thumbv7em-none-eabihf";

/// What can go wrong while building or running the emulated board.
#[derive(Debug, thiserror::Error)]
pub enum QemuError {
    /// QEMU is not installed.
    #[error(
        "`{QEMU}` was not found on PATH: install the Debian package `{QEMU_PACKAGE}` \
         (apt-get install -y --no-install-recommends {QEMU_PACKAGE})"
    )]
    Missing,
    /// The embedded firmware could not be written out for QEMU.
    #[error("the firmware `{bin}` built into marionette could not be written out: {why}")]
    Firmware {
        /// The firmware binary.
        bin: String,
        /// The I/O error.
        why: String,
    },
    /// A table blob does not fit the table region.
    #[error("table blob {path}: {len} bytes does not fit the {TABLE_REGION_LEN}-byte table region")]
    TablesTooLarge {
        /// The blob file.
        path: PathBuf,
        /// Its size.
        len: usize,
    },
    /// QEMU did not open its serial sockets in time.
    #[error("QEMU did not open serial socket {0} in time")]
    Connect(PathBuf),
    /// The firmware ran past its deadline.
    #[error("the emulated board did not finish within {0:?}; QEMU was killed")]
    Timeout(Duration),
    /// An I/O error talking to QEMU.
    #[error("emulator I/O: {0}")]
    Io(#[from] std::io::Error),
}

/// Fails with [`QemuError::Missing`] unless `qemu-system-arm` is on PATH.
pub fn check_qemu() -> Result<PathBuf, QemuError> {
    find_qemu(&std::env::var_os("PATH").unwrap_or_default())
}

/// Looks for `qemu-system-arm` in a `PATH`-style list of folders.
pub fn find_qemu(path: &std::ffi::OsStr) -> Result<PathBuf, QemuError> {
    std::env::split_paths(path)
        .map(|dir| dir.join(QEMU))
        .find(|candidate| candidate.is_file())
        .ok_or(QemuError::Missing)
}

/// The path of the emulated board's firmware binary `bin` (`perform`,
/// `bench` or `echo`): the ELF built into this program with it (release,
/// panic-never, from the same sources; see [`crate::bundle`]), written to the
/// bundle folder on first use. Needs neither cargo nor the source tree.
pub fn firmware_elf(bin: &str) -> Result<PathBuf, QemuError> {
    crate::bundle::firmware(bin).map_err(|e| QemuError::Firmware {
        bin: bin.to_string(),
        why: e.to_string(),
    })
}

/// How to boot the emulated board.
#[derive(Clone, Debug)]
pub struct Config {
    /// The firmware ELF.
    pub elf: PathBuf,
    /// A table blob to load at [`TABLE_REGION_ADDR`].
    pub tables: Option<PathBuf>,
    /// Run with `-icount shift=7,align=off` (deterministic instruction counts).
    pub icount: bool,
    /// Connect UART0 and UART1 to sockets (otherwise they go nowhere).
    pub serial: bool,
    /// The longest the run may take, wall clock.
    pub timeout: Duration,
}

impl Config {
    /// A run of `elf` with both UARTs connected, no tables, 60 s time-out.
    #[must_use]
    pub fn new(elf: impl Into<PathBuf>) -> Self {
        Self {
            elf: elf.into(),
            tables: None,
            icount: false,
            serial: true,
            timeout: Duration::from_secs(60),
        }
    }
}

/// Bytes collected from one side of a link by a background thread.
#[derive(Clone, Default)]
struct Collected(Arc<Mutex<Vec<u8>>>);

impl Collected {
    fn spawn(mut source: impl Read + Send + 'static) -> (Self, JoinHandle<()>) {
        let sink = Self::default();
        let out = sink.clone();
        let handle = thread::spawn(move || {
            let mut buf = [0u8; 4096];
            while let Ok(n) = source.read(&mut buf) {
                if n == 0 {
                    break;
                }
                if let (Ok(mut v), Some(chunk)) = (out.0.lock(), buf.get(..n)) {
                    v.extend_from_slice(chunk);
                }
            }
        });
        (sink, handle)
    }

    fn len(&self) -> usize {
        self.0.lock().map(|v| v.len()).unwrap_or(0)
    }

    fn check(&self, done: &dyn Fn(&[u8]) -> bool) -> bool {
        self.0.lock().map(|v| done(&v)).unwrap_or(false)
    }

    fn take(&self) -> Vec<u8> {
        self.0
            .lock()
            .map(|mut v| std::mem::take(&mut *v))
            .unwrap_or_default()
    }
}

/// A look at what a running board has sent so far, for watching a session
/// while it runs (the live view); reading never takes anything away.
#[derive(Clone)]
pub struct Taps {
    servo: Collected,
    tracker: Collected,
}

impl Taps {
    /// Bytes sent on the servo bus so far.
    #[must_use]
    pub fn servo_len(&self) -> usize {
        self.servo.len()
    }

    /// A copy of servo-bus bytes `range` (empty if not all there yet).
    #[must_use]
    pub fn servo_bytes(&self, range: std::ops::Range<usize>) -> Vec<u8> {
        self.servo
            .0
            .lock()
            .ok()
            .and_then(|v| v.get(range).map(<[u8]>::to_vec))
            .unwrap_or_default()
    }

    /// A copy of the replies on the tracker link so far.
    #[must_use]
    pub fn replies(&self) -> Vec<u8> {
        self.tracker.0.lock().map(|v| v.clone()).unwrap_or_default()
    }
}

/// What a finished run produced.
#[derive(Clone, Debug)]
pub struct Output {
    /// The firmware's exit status (semihosting), or `None` if QEMU was killed
    /// by a signal.
    pub status: Option<i32>,
    /// Everything the firmware printed over semihosting.
    pub console: String,
    /// What QEMU itself printed on stderr, less its "waiting for connection"
    /// notices.
    pub diagnostics: String,
    /// Bytes the firmware sent on UART0 (the tracker link).
    pub tracker: Vec<u8>,
    /// Bytes the firmware sent on UART1 (the servo bus).
    pub servo: Vec<u8>,
}

/// A running emulated board. Dropping it kills QEMU.
pub struct Emulator {
    child: Child,
    tracker: Option<UnixStream>,
    tracker_out: Collected,
    servo_out: Collected,
    console: Collected,
    diagnostics: Collected,
    readers: Vec<JoinHandle<()>>,
    deadline: Instant,
    timeout: Duration,
}

impl Emulator {
    /// Boots QEMU and connects to its serial sockets. Their folder is
    /// removed once both are connected (a connected socket needs no path),
    /// so that a command killed later (`kill -9`, the quit at once on a
    /// second Ctrl-C) leaves nothing in the temporary folder.
    pub fn start(config: &Config) -> Result<Self, QemuError> {
        let qemu = check_qemu()?;
        let dir = tempfile::Builder::new()
            .prefix("marionette-qemu")
            .tempdir()?;
        let sockets = [dir.path().join("uart0.sock"), dir.path().join("uart1.sock")];
        let mut cmd = qemu_command(&qemu, config, &Uarts::Sockets(&sockets))?;
        let mut child = interrupt::spawn(&mut cmd)?;
        let mut readers = Vec::new();
        let stdout = child
            .stdout
            .take()
            .ok_or_else(|| std::io::Error::other("QEMU stdout not captured"))?;
        let (console, h) = Collected::spawn(stdout);
        readers.push(h);
        let stderr = child
            .stderr
            .take()
            .ok_or_else(|| std::io::Error::other("QEMU stderr not captured"))?;
        let (diagnostics, h) = Collected::spawn(stderr);
        readers.push(h);
        let mut emulator = Self {
            child,
            tracker: None,
            tracker_out: Collected::default(),
            servo_out: Collected::default(),
            console,
            diagnostics,
            readers,
            deadline: Instant::now() + config.timeout,
            timeout: config.timeout,
        };
        if config.serial {
            let [s0, s1] = &sockets;
            let uart0 = emulator.connect(s0)?;
            let uart1 = emulator.connect(s1)?;
            let (tracker_out, h0) = Collected::spawn(uart0.try_clone()?);
            let (servo_out, h1) = Collected::spawn(uart1);
            emulator.readers.extend([h0, h1]);
            emulator.tracker_out = tracker_out;
            emulator.servo_out = servo_out;
            emulator.tracker = Some(uart0);
        }
        dir.close()?;
        Ok(emulator)
    }

    /// Connects to one of QEMU's serial sockets, retrying until it appears.
    fn connect(&mut self, path: &Path) -> Result<UnixStream, QemuError> {
        let give_up = Instant::now() + Duration::from_secs(10);
        loop {
            if let Ok(stream) = UnixStream::connect(path) {
                return Ok(stream);
            }
            if Instant::now() > give_up || interrupt::try_wait(&mut self.child)?.is_some() {
                return Err(QemuError::Connect(path.to_path_buf()));
            }
            thread::sleep(Duration::from_millis(10));
        }
    }

    /// Sends bytes to the board's tracker link (UART0).
    pub fn send(&mut self, bytes: &[u8]) -> Result<(), QemuError> {
        let left = self.remaining()?;
        let stream = self
            .tracker
            .as_mut()
            .ok_or_else(|| std::io::Error::other("serial links are not connected"))?;
        stream.set_write_timeout(Some(left))?;
        stream.write_all(bytes)?;
        Ok(())
    }

    /// Waits until the board has sent at least `n` bytes on the servo bus, or
    /// has exited.
    pub fn wait_servo_bytes(&mut self, n: usize) -> Result<(), QemuError> {
        self.wait_servo_bytes_with(n, &|_| ())
    }

    /// As [`Emulator::wait_servo_bytes`], telling `seen` how many bytes have
    /// come so far each time it looks.
    pub fn wait_servo_bytes_with(
        &mut self,
        n: usize,
        seen: &dyn Fn(usize),
    ) -> Result<(), QemuError> {
        loop {
            let got = self.servo_out.len();
            seen(got);
            if got >= n {
                break;
            }
            self.remaining()?;
            if interrupt::try_wait(&mut self.child)?.is_some() {
                break;
            }
            thread::sleep(Duration::from_millis(1));
        }
        Ok(())
    }

    /// A [`Taps`] on this board's links.
    #[must_use]
    pub fn taps(&self) -> Taps {
        Taps {
            servo: self.servo_out.clone(),
            tracker: self.tracker_out.clone(),
        }
    }

    /// How many bytes the board has sent on the servo bus so far.
    #[must_use]
    pub fn servo_bytes(&self) -> usize {
        self.servo_out.len()
    }

    /// Waits until the bytes the board has sent on its tracker link (its
    /// replies) satisfy `done`, or it has exited.
    pub fn wait_replies(&mut self, done: impl Fn(&[u8]) -> bool) -> Result<(), QemuError> {
        while !self.tracker_out.check(&done) {
            self.remaining()?;
            if interrupt::try_wait(&mut self.child)?.is_some() {
                break;
            }
            thread::sleep(Duration::from_millis(1));
        }
        Ok(())
    }

    /// Waits at most `within` (and never past the run's deadline) until the
    /// board's replies satisfy `done`; returns whether they did. Stops
    /// early if the board exits.
    pub fn wait_replies_within(
        &mut self,
        done: impl Fn(&[u8]) -> bool,
        within: Duration,
    ) -> Result<bool, QemuError> {
        let give_up = Instant::now() + within;
        loop {
            if self.tracker_out.check(&done) {
                return Ok(true);
            }
            self.remaining()?;
            if Instant::now() > give_up || interrupt::try_wait(&mut self.child)?.is_some() {
                return Ok(self.tracker_out.check(&done));
            }
            thread::sleep(Duration::from_millis(1));
        }
    }

    /// A copy of the bytes the board has sent on its tracker link so far.
    #[must_use]
    pub fn replies_so_far(&self) -> Vec<u8> {
        self.tracker_out
            .0
            .lock()
            .map(|v| v.clone())
            .unwrap_or_default()
    }

    /// Bytes received on the servo bus so far (and clears them).
    pub fn take_servo(&mut self) -> Vec<u8> {
        self.servo_out.take()
    }

    /// Bytes the board has sent on its tracker link so far (and clears
    /// them).
    pub fn take_replies(&mut self) -> Vec<u8> {
        self.tracker_out.take()
    }

    fn remaining(&mut self) -> Result<Duration, QemuError> {
        let left = self.deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            let _ = self.child.kill();
            return Err(QemuError::Timeout(self.timeout));
        }
        Ok(left)
    }

    /// Waits for the firmware to exit and returns what it produced.
    pub fn finish(mut self) -> Result<Output, QemuError> {
        let status = loop {
            if let Some(status) = interrupt::try_wait(&mut self.child)? {
                break status;
            }
            self.remaining()?;
            thread::sleep(Duration::from_millis(2));
        };
        self.tracker = None;
        for reader in self.readers.drain(..) {
            let _ = reader.join();
        }
        let diagnostics = String::from_utf8_lossy(&self.diagnostics.take())
            .lines()
            .filter(|l| !l.contains("QEMU waiting for connection"))
            .map(|l| format!("{l}\n"))
            .collect();
        Ok(Output {
            status: status.code(),
            console: String::from_utf8_lossy(&self.console.take()).into_owned(),
            diagnostics,
            tracker: self.tracker_out.take(),
            servo: self.servo_out.take(),
        })
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        interrupt::end(&mut self.child);
    }
}

/// The emulated board as a person meets it: UART0 (the tracker link) on a
/// pseudo-terminal, a serial device any program can open (`marionette
/// stream --port`), and UART1 (the servo bus) written raw to a file. QEMU
/// notices a newly opened pty only on a one-second poll, so a host says
/// `Hello` until the board answers. Dropping it kills QEMU.
pub struct PtyBoard {
    child: Child,
    pty: PathBuf,
    console: Collected,
    readers: Vec<JoinHandle<()>>,
}

impl PtyBoard {
    /// Boots `elf` with `region` in its table region, the servo bus to
    /// `servo`, and waits for QEMU to name its pty (`char device
    /// redirected to /dev/pts/N`, on its stdout).
    pub fn start(elf: &Path, region: &Path, servo: &Path) -> Result<Self, QemuError> {
        use std::io::BufRead;
        let qemu = check_qemu()?;
        let config = Config {
            tables: Some(region.to_path_buf()),
            ..Config::new(elf)
        };
        let mut cmd = qemu_command(&qemu, &config, &Uarts::Pty { servo })?;
        let mut child = interrupt::spawn(&mut cmd)?;
        let stdout = child
            .stdout
            .take()
            .ok_or_else(|| std::io::Error::other("QEMU stdout not captured"))?;
        let stderr = child
            .stderr
            .take()
            .ok_or_else(|| std::io::Error::other("QEMU stderr not captured"))?;
        let (_, h) = Collected::spawn(stderr);
        let mut lines = std::io::BufReader::new(stdout);
        let mut line = String::new();
        let pty = loop {
            line.clear();
            if lines.read_line(&mut line)? == 0 {
                interrupt::end(&mut child);
                return Err(std::io::Error::other("QEMU exited before naming its pty").into());
            }
            if let Some(rest) = line.split("redirected to ").nth(1)
                && let Some(dev) = rest.split_whitespace().next()
            {
                break PathBuf::from(dev);
            }
        };
        let (console, c) = Collected::spawn(lines);
        Ok(Self {
            child,
            pty,
            console,
            readers: vec![h, c],
        })
    }

    /// The tracker link's device, e.g. `/dev/pts/3`.
    #[must_use]
    pub fn pty(&self) -> &Path {
        &self.pty
    }

    /// Waits up to `limit` for the firmware to exit; its exit status (`None`
    /// if it is still running, or was killed by a signal).
    pub fn wait(&mut self, limit: Duration) -> Result<Option<i32>, QemuError> {
        let deadline = Instant::now() + limit;
        while Instant::now() < deadline {
            if let Some(status) = interrupt::try_wait(&mut self.child)? {
                for r in self.readers.drain(..) {
                    let _ = r.join();
                }
                return Ok(status.code());
            }
            thread::sleep(Duration::from_millis(20));
        }
        Ok(None)
    }

    /// What the firmware printed so far (semihosting).
    #[must_use]
    pub fn console(&self) -> String {
        self.console
            .0
            .lock()
            .map(|v| String::from_utf8_lossy(&v).into_owned())
            .unwrap_or_default()
    }
}

impl Drop for PtyBoard {
    fn drop(&mut self) {
        interrupt::end(&mut self.child);
    }
}

/// Where the two UARTs go.
enum Uarts<'a> {
    /// Both on Unix sockets QEMU serves (if `config.serial`).
    Sockets(&'a [PathBuf; 2]),
    /// UART0 on a pseudo-terminal, UART1 to a file.
    Pty {
        /// The servo bus's file.
        servo: &'a Path,
    },
}

/// The QEMU command line for `config`, with UARTs as `uarts` says.
fn qemu_command(qemu: &Path, config: &Config, uarts: &Uarts<'_>) -> Result<Command, QemuError> {
    let mut cmd = interrupt::command(qemu.as_os_str());
    cmd.args(["-machine", "mps2-an386", "-cpu", "cortex-m4"])
        .args(["-display", "none", "-monitor", "none"])
        .args(["-semihosting-config", "enable=on,target=native"]);
    if config.icount {
        cmd.args(["-icount", "shift=7,align=off"]);
    }
    if let Uarts::Pty { servo } = uarts {
        cmd.args(["-chardev", "pty,id=u0", "-serial", "chardev:u0"])
            .arg("-chardev")
            .arg(format!("file,id=u1,path={}", servo.display()))
            .args(["-serial", "chardev:u1"]);
    } else if let (Uarts::Sockets(sockets), true) = (uarts, config.serial) {
        for (i, sock) in sockets.iter().enumerate() {
            cmd.arg("-chardev")
                .arg(format!(
                    "socket,id=u{i},path={},server=on,wait=on",
                    sock.display()
                ))
                .arg("-serial")
                .arg(format!("chardev:u{i}"));
        }
    } else {
        cmd.args(["-serial", "null"]);
    }
    if let Some(tables) = &config.tables {
        let len = usize::try_from(std::fs::metadata(tables)?.len()).unwrap_or(usize::MAX);
        if len > TABLE_REGION_LEN {
            return Err(QemuError::TablesTooLarge {
                path: tables.clone(),
                len,
            });
        }
        cmd.arg("-device").arg(format!(
            "loader,file={},addr={TABLE_REGION_ADDR:#x}",
            tables.display()
        ));
    }
    cmd.arg("-kernel").arg(&config.elf);
    cmd.stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    Ok(cmd)
}

/// Boots `config.elf`, sends `input` on the tracker link, and waits for the
/// firmware to exit.
pub fn run(config: &Config, input: &[u8]) -> Result<Output, QemuError> {
    let mut emulator = Emulator::start(config)?;
    if !input.is_empty() {
        emulator.send(input)?;
    }
    emulator.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_qemu_names_the_debian_package() {
        let err = find_qemu(std::ffi::OsStr::new("/nonexistent"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("apt-get install"), "{err}");
        assert!(err.contains("package `qemu-system-arm`"), "{err}");
    }

    #[test]
    fn an_oversized_blob_is_refused_before_qemu_starts() {
        let mut blob = tempfile::NamedTempFile::new().unwrap();
        blob.write_all(&vec![0u8; TABLE_REGION_LEN + 1]).unwrap();
        let config = Config {
            tables: Some(blob.path().to_path_buf()),
            ..Config::new("fw.elf")
        };
        let err = qemu_command(
            Path::new(QEMU),
            &config,
            &Uarts::Sockets(&[PathBuf::new(), PathBuf::new()]),
        )
        .unwrap_err();
        assert!(matches!(err, QemuError::TablesTooLarge { .. }), "{err}");
    }
}
