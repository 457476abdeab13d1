//! Ctrl-C (and SIGTERM, SIGHUP) for every `marionette` command: one
//! handler for the whole process, so that an emulated board (QEMU) never
//! outlives the command that started it.
//!
//! `main` calls [`install`] first. From then on children start in a process
//! group of their own ([`spawn`]), out of the terminal's Ctrl-C, and a
//! signal ends them (SIGKILL) before the command quits with exit code
//! [`QUIT_NOW`]. Without that, a signal that reaches the command alone
//! (`kill PID`, a supervisor's SIGTERM, a terminal library that re-raises
//! Ctrl-C to its own process) ended the command and left QEMU running the
//! firmware's loop on a whole core, its sockets' other end gone.
//!
//! The commands that run until told to stop (`live`; `stream` and `replay
//! --port` on a long recording; `calibrate`) ask for a clean stop instead
//! with [`stop_on_ctrl_c`]: the first signal sets the stop flag it returns
//! and says on stderr that the command is stopping: the session then ends
//! as it does at `--seconds` or at the end of its recording (the board
//! disarmed, the summary printed, the end check run, the take saved).
//! Before the board has armed (while the command still says `Hello`), it
//! ends the command with an error instead, and the board is never armed.
//! A second signal quits at once, as above, for a session that hangs on its
//! way out.
//!
//! A process that calls neither [`install`] nor [`stop_on_ctrl_c`] (tests
//! calling the commands' functions) installs nothing: its children share
//! its process group, and a signal to the group ends them with it.
//!
//! SIGKILL (or a crash) ends the command before any handler runs. For
//! that, children start through util-linux's `setpriv --pdeathsig KILL`
//! where this machine has it ([`command`]): the kernel then kills the
//! board when the thread that started it ends (start and end a board on
//! one thread, as every command does). QEMU 7.2 has no exit-with-parent
//! of its own, and setting the signal in the child ourselves would take
//! `unsafe` (`pre_exec`). Without `setpriv` (not a Linux with util-linux
//! 2.33 or later) a SIGKILL to the command alone still leaves its board
//! running.

use crate::cmd::CmdError;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use std::ffi::OsStr;
use std::os::unix::process::CommandExt;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard, OnceLock, PoisonError};

/// Set by the first signal.
static STOP: AtomicBool = AtomicBool::new(false);
/// Signals received.
static SIGNALS: AtomicUsize = AtomicUsize::new(0);
/// Whether the handler is installed.
static INSTALLED: AtomicBool = AtomicBool::new(false);
/// The command that stops cleanly on the first signal, if one asked.
static GRACEFUL: Mutex<Option<&'static str>> = Mutex::new(None);
/// The children to end on the quit at once (process ids).
static CHILDREN: Mutex<Vec<u32>> = Mutex::new(Vec::new());

/// The exit code of the quit at once (128 + SIGINT, as a shell reports a
/// process ended by Ctrl-C).
pub const QUIT_NOW: i32 = 130;

/// Installs the process's handler (once; later calls do nothing): a
/// signal ends the children and quits, unless a command asked for a clean
/// stop ([`stop_on_ctrl_c`]).
pub fn install() -> Result<(), CmdError> {
    if INSTALLED.swap(true, Ordering::SeqCst) {
        return Ok(());
    }
    ctrlc::set_handler(on_signal).map_err(|e| {
        INSTALLED.store(false, Ordering::SeqCst);
        format!("cannot handle Ctrl-C: {e}")
    })?;
    Ok(())
}

/// Asks for a clean stop for `command` (the name it says it is stopping
/// under, e.g. `live`), installing the handler if `main` has not; returns
/// the flag the first signal sets.
pub fn stop_on_ctrl_c(command: &'static str) -> Result<&'static AtomicBool, CmdError> {
    install().map_err(|e| format!("{command}: {e}"))?;
    *lock(&GRACEFUL) = Some(command);
    Ok(&STOP)
}

/// What a signal does (on ctrlc's thread, not in the signal handler: it
/// may print, lock and exit).
fn on_signal() {
    let graceful = *lock(&GRACEFUL);
    let first = SIGNALS.fetch_add(1, Ordering::SeqCst) == 0;
    if let (Some(command), true) = (graceful, first) {
        STOP.store(true, Ordering::SeqCst);
        eprintln!("{command}: stopping (Ctrl-C again to quit now)");
        return;
    }
    let name = graceful.unwrap_or("marionette");
    eprintln!("{name}: quitting now (exit code {QUIT_NOW})");
    for &id in children().iter() {
        if let Ok(pid) = i32::try_from(id) {
            let _ = kill(Pid::from_raw(pid), Signal::SIGKILL);
        }
    }
    std::process::exit(QUIT_NOW);
}

/// A command that runs `program` and is killed when the calling thread
/// ends, even by SIGKILL: `setpriv --pdeathsig KILL -- program` where
/// `setpriv` knows that option, else `program` itself. `setpriv` replaces
/// itself with `program` (the same process id).
pub fn command(program: &OsStr) -> Command {
    if has_pdeathsig() {
        let mut cmd = Command::new("setpriv");
        cmd.args(["--pdeathsig", "KILL", "--"]).arg(program);
        cmd
    } else {
        Command::new(program)
    }
}

/// Whether `setpriv` is on the `PATH` and has `--pdeathsig` (asked once).
fn has_pdeathsig() -> bool {
    static HAS: OnceLock<bool> = OnceLock::new();
    *HAS.get_or_init(|| {
        Command::new("setpriv")
            .arg("--help")
            .stdin(Stdio::null())
            .stderr(Stdio::null())
            .output()
            .is_ok_and(|out| {
                out.status.success() && String::from_utf8_lossy(&out.stdout).contains("--pdeathsig")
            })
    })
}

/// Spawns `cmd`: with the handler installed, in a process group of its
/// own (out of the terminal's Ctrl-C) and ended by the quit at once. Wait
/// for it with [`try_wait`] and [`end`], which forget it as they reap it
/// (the quit at once never signals a process id reused since).
pub fn spawn(cmd: &mut Command) -> std::io::Result<Child> {
    let installed = INSTALLED.load(Ordering::SeqCst);
    if installed {
        cmd.process_group(0);
    }
    let mut list = children();
    let child = cmd.spawn()?;
    if installed {
        list.push(child.id());
    }
    Ok(child)
}

/// [`Child::try_wait`], forgetting the child once it is reaped.
pub fn try_wait(child: &mut Child) -> std::io::Result<Option<ExitStatus>> {
    let mut list = children();
    let status = child.try_wait()?;
    if status.is_some() {
        list.retain(|&id| id != child.id());
    }
    Ok(status)
}

/// Kills the child and reaps it (errors ignored: it may have exited).
pub fn end(child: &mut Child) {
    let mut list = children();
    let _ = child.kill();
    let _ = child.wait();
    list.retain(|&id| id != child.id());
}

/// The children to end, locked.
fn children() -> MutexGuard<'static, Vec<u32>> {
    lock(&CHILDREN)
}

/// `mutex` locked (a poisoned lock is still used: its value stays valid).
fn lock<T>(mutex: &'static Mutex<T>) -> MutexGuard<'static, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}
