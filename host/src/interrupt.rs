//! Ctrl-C for the commands that run until told to stop (`live`, and
//! `stream` and `replay --port` on a long recording): one handler for all
//! of them.
//!
//! [`stop_on_ctrl_c`] installs it (SIGINT, and SIGTERM and SIGHUP too). The
//! first signal sets the stop flag it returns and says on stderr that the
//! command is stopping: the session then ends as it does at `--seconds` or
//! at the end of its recording (the board disarmed, the summary printed,
//! the end check run, the take saved). Before the board has armed (while
//! the command still says `Hello`), it ends the command with an error
//! instead, and the board is never armed. A second signal quits at once with
//! exit code 130, for a session that hangs on its way out.
//!
//! A terminal's Ctrl-C goes to every process of its foreground process
//! group, so an emulated board (QEMU) started by such a command would die
//! with the first Ctrl-C, before it is disarmed and checked. Once the
//! handler is installed, [`spawn`] starts children in their own process
//! group instead, and the quit at once ends them (SIGKILL) before exiting:
//! nothing is left running. Without the handler (every other command) a
//! child shares the command's group and dies with it as before.

use crate::cmd::CmdError;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use std::os::unix::process::CommandExt;
use std::process::{Child, Command, ExitStatus};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard, PoisonError};

/// Set by the first signal.
static STOP: AtomicBool = AtomicBool::new(false);
/// Signals received.
static SIGNALS: AtomicUsize = AtomicUsize::new(0);
/// Whether the handler is installed.
static INSTALLED: AtomicBool = AtomicBool::new(false);
/// The children to end on the quit at once (process ids).
static CHILDREN: Mutex<Vec<u32>> = Mutex::new(Vec::new());

/// The exit code of the quit at once (128 + SIGINT, as a shell reports a
/// process ended by Ctrl-C).
pub const QUIT_NOW: i32 = 130;

/// Installs the handler for `command` (the name it says it is stopping
/// under, e.g. `live`) and returns the flag the first Ctrl-C sets. Once per
/// process: a second call is refused.
pub fn stop_on_ctrl_c(command: &'static str) -> Result<&'static AtomicBool, CmdError> {
    ctrlc::set_handler(move || on_signal(command))
        .map_err(|e| format!("{command}: cannot handle Ctrl-C: {e}"))?;
    INSTALLED.store(true, Ordering::SeqCst);
    Ok(&STOP)
}

/// What a signal does (on ctrlc's thread, not in the signal handler: it
/// may print, lock and exit).
fn on_signal(command: &str) {
    if SIGNALS.fetch_add(1, Ordering::SeqCst) == 0 {
        STOP.store(true, Ordering::SeqCst);
        eprintln!("{command}: stopping (Ctrl-C again to quit now)");
        return;
    }
    eprintln!("{command}: quitting now (exit code {QUIT_NOW})");
    for &id in children().iter() {
        if let Ok(pid) = i32::try_from(id) {
            let _ = kill(Pid::from_raw(pid), Signal::SIGKILL);
        }
    }
    std::process::exit(QUIT_NOW);
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

/// The children to end, locked (a poisoned lock is still used: the list
/// stays valid).
fn children() -> MutexGuard<'static, Vec<u32>> {
    CHILDREN.lock().unwrap_or_else(PoisonError::into_inner)
}
