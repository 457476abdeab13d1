//! `marionette calibrate` as a terminal program: run in tmux against the
//! emulated board, driven with `send-keys`, read with `capture-pane`. The
//! pulses expected on screen are worked from the keys pressed and the rig
//! file's numbers (humanoid16 channel 1: rest 1500 µs, `pulse_us = [1000,
//! 2000]`, small step 10 µs, large step 100 µs), and the rig file written
//! must be the original with exactly the calibrated lines changed.
//!
//! The same on Dynamixel bus servos, in positions.
//!
//! Skipped, with a message, only when tmux is not installed (`.ci/setup`
//! installs it); QEMU is required like every emulated-board test.

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

/// A private tmux server (its own socket), killed when dropped.
struct Tmux {
    socket: String,
}

impl Tmux {
    fn cmd(&self) -> Command {
        let mut c = Command::new("tmux");
        c.args(["-u", "-L", &self.socket]);
        c
    }

    fn run(&self, args: &[&str]) -> String {
        let out = self.cmd().args(args).output().expect("tmux runs");
        assert!(
            out.status.success(),
            "tmux {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    }

    fn keys(&self, keys: &[&str]) {
        let mut args = vec!["send-keys", "-t", "cal"];
        args.extend(keys);
        self.run(&args);
    }

    /// Waits until the screen shows every one of `texts` (a hang guard of
    /// 120 s, not a timing check); returns the screen.
    fn wait_for(&self, texts: &[&str]) -> String {
        let until = Instant::now() + Duration::from_secs(120);
        loop {
            let screen = self.run(&["capture-pane", "-p", "-t", "cal"]);
            if texts.iter().all(|t| screen.contains(t)) {
                return screen;
            }
            assert!(
                Instant::now() < until,
                "waiting for {texts:?}, the screen:\n{screen}"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

impl Drop for Tmux {
    fn drop(&mut self) {
        let _ = self.cmd().arg("kill-server").output();
    }
}

fn tmux_installed() -> bool {
    Command::new("tmux")
        .arg("-V")
        .output()
        .is_ok_and(|o| o.status.success())
}

/// humanoid16's channel 1 entry, as the shipped file has it.
const CHANNEL_1: &str = "channel = 1
joint = \"head\"
axis = \"x\"
angle_deg = [-45, 45]           # 90° servo
pulse_us = [1000, 2000]
max_speed = 7.0
max_accel = 60.0
";

/// Starts `marionette calibrate --channel 1` on a copy of `rig_text` in a
/// private tmux server; returns it (killed when dropped), the rig's path and
/// the temporary directory holding it. `None` (with the skip message) when
/// tmux is missing.
fn start(rig_text: &str) -> Option<(Tmux, std::path::PathBuf, tempfile::TempDir)> {
    if !tmux_installed() {
        eprintln!(
            "SKIPPED: tmux is not installed (run .ci/setup tests); calibrate's terminal test needs it"
        );
        return None;
    }
    // Built here first, so that the tool's own build is a no-op.
    marionette_host::qemu::firmware_elf("perform").expect("the embedded firmware is written out");
    let dir = tempfile::tempdir().unwrap();
    let rig = dir.path().join("puppet.toml");
    std::fs::write(&rig, rig_text).unwrap();
    static SESSIONS: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let n = SESSIONS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmux = Tmux {
        socket: format!("marionette-calibrate-{}-{n}", std::process::id()),
    };
    let line = format!(
        "'{}' calibrate --rig '{}' --channel 1; echo EXIT=$?; sleep 600",
        env!("CARGO_BIN_EXE_marionette"),
        rig.display()
    );
    tmux.run(&[
        "new-session",
        "-d",
        "-s",
        "cal",
        "-x",
        "120",
        "-y",
        "24",
        &line,
    ]);
    Some((tmux, rig, dir))
}

fn shipped_rig() -> String {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    std::fs::read_to_string(repo.join("rigs/humanoid16.toml")).unwrap()
}

#[test]
fn calibrate_in_a_terminal_jogs_the_emulated_board_and_writes_the_rig() {
    let original = shipped_rig();
    assert!(original.contains(CHANNEL_1));
    let Some((tmux, rig, _dir)) = start(&original) else {
        return;
    };
    tmux.wait_for(&["channel 1, range 1000 µs..2000 µs", "commanded 1500 µs"]);

    // 1500 + 2·100 + 10.
    tmux.keys(&["k", "k", "Right"]);
    tmux.wait_for(&["commanded 1710 µs, on the servo link 1710 µs"]);
    // Seven more large steps would be 2410: the board's range ends at 2000.
    tmux.keys(&["Up", "Up", "Up", "Up", "Up", "Up", "Up"]);
    tmux.wait_for(&[
        "commanded 2000 µs, on the servo link 2000 µs",
        "at the rig's limit",
    ]);
    tmux.keys(&["Left", "x"]);
    tmux.wait_for(&["max 1990 µs", "on the servo link 1990 µs"]);
    // 1990 − 8·100 = 1190.
    tmux.keys(&["j", "j", "j", "j", "j", "j", "j", "j", "n"]);
    tmux.wait_for(&[
        "commanded 1190 µs, on the servo link 1190 µs",
        "min 1190 µs",
    ]);
    // 1190 + 5·10 = 1240.
    tmux.keys(&["l", "l", "l", "l", "l", "c", "w"]);
    tmux.wait_for(&["centre 1240 µs", "wrote "]);
    tmux.keys(&["q"]);
    tmux.wait_for(&["back to rest", "on the servo link 1500 µs", "EXIT=0"]);

    let written = std::fs::read_to_string(&rig).unwrap();
    let expected = original.replacen(
        CHANNEL_1,
        &CHANNEL_1
            .replace("[1000, 2000]", "[1190, 1990]")
            .replace("max_accel = 60.0\n", "max_accel = 60.0\nrest_us = 1240\n"),
        1,
    );
    assert_eq!(written, expected, "only channel 1's limits change");
    let loaded = marionette_host::rigfile::load(&rig).unwrap();
    let servo = loaded
        .desc()
        .servos
        .iter()
        .find(|s| s.channel == 1)
        .copied()
        .unwrap();
    assert_eq!(
        (servo.pulse_min_us, servo.pulse_max_us, servo.rest_us),
        (1190.0, 1990.0, 1240.0)
    );
}

/// A servo held where the user jogged it stays there while they look: the
/// board ends a jog after a second without a message from the host (its
/// watchdog), so `calibrate` repeats the jog while it waits for a key.
#[test]
fn a_jogged_servo_stays_while_the_user_looks() {
    let Some((tmux, _rig, _dir)) = start(&shipped_rig()) else {
        return;
    };
    tmux.wait_for(&["commanded 1500 µs"]);
    tmux.keys(&["k", "k"]);
    tmux.wait_for(&["commanded 1700 µs, on the servo link 1700 µs"]);
    // Three times the board's watchdog without a key.
    std::thread::sleep(Duration::from_secs(3));
    tmux.keys(&["c"]);
    tmux.wait_for(&["centre 1700 µs", "on the servo link 1700 µs"]);
    tmux.keys(&["q"]);
    tmux.wait_for(&["on the servo link 1500 µs", "EXIT=0"]);
}

/// The processes whose parent is `pid` (from `/proc/*/stat`).
fn children_of(pid: u32) -> Vec<u32> {
    std::fs::read_dir("/proc")
        .unwrap()
        .filter_map(|e| {
            let id: u32 = e.ok()?.file_name().to_str()?.parse().ok()?;
            let stat = std::fs::read_to_string(format!("/proc/{id}/stat")).ok()?;
            // `pid (comm) state ppid …`: the command may hold spaces.
            let ppid = stat.rsplit_once(") ")?.1.split(' ').nth(1)?;
            (ppid.parse() == Ok(pid)).then_some(id)
        })
        .collect()
}

/// Whether process `pid` still runs (exists and is not a zombie).
fn running(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .ok()
        .and_then(|stat| Some(stat.rsplit_once(") ")?.1.starts_with('Z')))
        .is_some_and(|zombie| !zombie)
}

/// Ctrl-C quits as `q` does: the servo eases back to rest, the command
/// exits 0, nothing is written, and the emulated board it started does not
/// outlive it (the terminal's Ctrl-C used to end the command alone and
/// leave QEMU running). Channel 1 is jogged up one large step, then
/// Ctrl-C pressed: once the servo link shows the step (`settled`: at the
/// prompt, a key in the terminal's raw mode), or as soon as the screen
/// shows the command (mostly while the screen settles: a signal).
fn quits_on_ctrl_c(settled: bool) {
    let original = shipped_rig();
    let Some((tmux, rig, _dir)) = start(&original) else {
        return;
    };
    tmux.wait_for(&["channel 1, range 1000 µs..2000 µs", "commanded 1500 µs"]);
    let shell: u32 = tmux
        .run(&["display", "-p", "-t", "cal", "#{pane_pid}"])
        .trim()
        .parse()
        .unwrap();
    let tool = children_of(shell);
    assert_eq!(tool.len(), 1, "the shell runs calibrate: {tool:?}");
    let board = children_of(tool[0]);
    assert_eq!(
        board.len(),
        1,
        "calibrate runs the emulated board: {board:?}"
    );
    tmux.keys(&["k"]);
    if settled {
        tmux.wait_for(&["commanded 1600 µs, on the servo link 1600 µs"]);
    } else {
        tmux.wait_for(&["commanded 1600 µs"]);
    }
    tmux.keys(&["C-c"]);
    tmux.wait_for(&["back to rest", "on the servo link 1500 µs", "EXIT=0"]);
    assert!(!running(board[0]), "the emulated board still runs");
    assert_eq!(std::fs::read_to_string(&rig).unwrap(), original);
}

#[test]
fn ctrl_c_at_calibrates_prompt_eases_back_to_rest_and_leaves_no_board_running() {
    quits_on_ctrl_c(true);
}

#[test]
fn ctrl_c_right_behind_a_jog_eases_back_to_rest_and_leaves_no_board_running() {
    quits_on_ctrl_c(false);
}

/// The same puppet on Dynamixel bus servos: positions (4096 a turn, centre
/// 2048), channel 1's ±45° are 2048 ∓ 512; the board's Sync Writes carry the
/// positions, and the tool writes `limits` and `center`.
#[test]
fn calibrate_moves_a_bus_servo_in_positions_and_writes_limits_and_center() {
    let maestro = "kind = \"maestro\"                # Pololu Maestro, compact protocol over UART\nbaud = 115200\n";
    let original = shipped_rig();
    assert!(original.contains(maestro));
    let bus: String = original
        .replacen(maestro, "kind = \"dynamixel\"\nbaud = 1000000\n", 1)
        .lines()
        .filter(|l| !l.starts_with("pulse_us =") && !l.starts_with("trim_us ="))
        .map(|l| format!("{l}\n"))
        .collect();
    let Some((tmux, rig, _dir)) = start(&bus) else {
        return;
    };
    tmux.wait_for(&["channel 1, range 1536..2560", "position: commanded 2048"]);
    // 2048 + 2·50 + 5.
    tmux.keys(&["k", "k", "l", "x"]);
    tmux.wait_for(&["commanded 2153, on the servo link 2153", "max 2153"]);
    // 2153 − 6·50 = 1853.
    tmux.keys(&["j", "j", "j", "j", "j", "j", "n"]);
    tmux.wait_for(&["commanded 1853, on the servo link 1853", "min 1853"]);
    // 1853 + 3·50 = 2003.
    tmux.keys(&["k", "k", "k", "c", "w"]);
    tmux.wait_for(&["centre 2003", "wrote "]);
    tmux.keys(&["q"]);
    tmux.wait_for(&["on the servo link 2048", "EXIT=0"]);

    let entry = CHANNEL_1.replace("pulse_us = [1000, 2000]\n", "");
    let written = std::fs::read_to_string(&rig).unwrap();
    let expected = bus.replacen(
        &entry,
        &entry.replace(
            "max_accel = 60.0\n",
            "max_accel = 60.0\nlimits = [1853, 2153]\ncenter = 2003\n",
        ),
        1,
    );
    assert_eq!(written, expected, "only channel 1's limits change");
    let loaded = marionette_host::rigfile::load(&rig).unwrap();
    let servo = loaded
        .desc()
        .servos
        .iter()
        .find(|s| s.channel == 1)
        .copied()
        .unwrap();
    // 2003 ± 512 within the limits; at rest (angle 0) the centre.
    assert_eq!(
        (servo.pulse_min_us, servo.pulse_max_us, servo.rest_us),
        (1853.0, 2153.0, 2003.0)
    );
}
