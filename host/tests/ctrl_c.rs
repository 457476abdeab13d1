//! Ctrl-C ends `marionette live` cleanly: the real binary on the emulated
//! board, driven by a VMC sender, is sent SIGINT the way a terminal sends
//! it (to its whole process group, so the emulated board started by it
//! gets it too unless `live` keeps it out). It must end as at `--seconds`:
//! exit 0, the summary printed with the end check, the take saved and
//! loadable, the recording written. A second Ctrl-C quits at once (exit
//! code 130) and leaves no emulated board running. `stream` to a board on
//! a serial port ends early the same way on Ctrl-C, and a Ctrl-C before the
//! board answers ends it without arming the board. `replay --port` ends
//! early the same way, the board disarmed. A signal to any other command
//! (here `emulate`), sent to it alone, ends its emulated board too.

#[path = "support/recording.rs"]
mod recording;
#[path = "support/vmc.rs"]
mod vmc;

use marionette_host::{perform, rigfile};
use recording::repeated_recording;
use std::io::{BufRead, BufReader, Read};
use std::os::fd::AsRawFd;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};
use vmc::vmc_hand;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// humanoid16's table whose every sample is the rest pose (the solver
/// moves the figure to the goals), for the emulated board.
fn rest_tables(dir: &Path) -> PathBuf {
    let rig = rigfile::load(&repo().join("rigs/humanoid16.toml")).unwrap();
    let axes = [
        ("hand_x", -1.0, 2.0, 2),
        ("hand_y", -1.0, 2.0, 2),
        ("hand_z", -1.0, 2.0, 2),
    ];
    let path = dir.join("rest.bin");
    std::fs::write(&path, perform::rest_grid(&rig, &axes).unwrap()).unwrap();
    path
}

/// A real board's flash for the emulated board on a pty: humanoid16 and
/// [`rest_tables`].
fn board_region(dir: &Path) -> PathBuf {
    let rig = rigfile::load(&repo().join("rigs/humanoid16.toml")).unwrap();
    let table = std::fs::read(rest_tables(dir)).unwrap();
    let mut blob = vec![0u8; marionette_core::rig::MAX_BLOB_LEN];
    let n = rig.desc().to_blob(&mut blob).unwrap();
    let region = dir.join("region.bin");
    std::fs::write(&region, perform::region(&blob[..n], Some(&table))).unwrap();
    region
}

/// `marionette live` on the emulated board (or `stream`), in a process
/// group of its own (as a terminal's foreground job); its stdout lines come
/// on the receiver, its stderr is read whole at the end.
struct Live {
    child: Child,
    lines: Receiver<String>,
    out: PathBuf,
    take: PathBuf,
}

impl Live {
    fn start(dir: &Path, extra: &[&str]) -> Self {
        let tables = rest_tables(dir);
        let out = dir.join("out");
        let take = dir.join("live.take");
        let args = ["--tables", s(&tables), "--take", s(&take), "--out", s(&out)];
        let child = Self::spawn(&[&["live"], &args[..], &["--listen", "127.0.0.1:0"], extra]);
        Self::with(child, out, take)
    }

    /// `marionette ARGS` (concatenated), its own process group's leader.
    fn spawn(args: &[&[&str]]) -> Child {
        Command::new(env!("CARGO_BIN_EXE_marionette"))
            .args(args.concat())
            .process_group(0)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("marionette runs")
    }

    fn with(mut child: Child, out: PathBuf, take: PathBuf) -> Self {
        let stdout = child.stdout.take().unwrap();
        let (tx, lines) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                println!("> {line}");
                let _ = tx.send(line);
            }
        });
        Self {
            child,
            lines,
            out,
            take,
        }
    }

    /// Where it listens, once the board has armed (it says so then).
    fn source(&self) -> std::net::SocketAddr {
        loop {
            let line = self
                .lines
                .recv_timeout(Duration::from_secs(120))
                .expect("live says where it listens");
            if let Some(at) = line.find("udp://") {
                let addr = line[at + 6..].split_whitespace().next().unwrap();
                return addr.parse().unwrap();
            }
        }
    }

    /// SIGINT to its whole process group, as a terminal's Ctrl-C.
    fn ctrl_c(&self) {
        let group = format!("-{}", self.child.id());
        let status = Command::new("kill")
            .args(["-INT", "--", &group])
            .status()
            .unwrap();
        assert!(status.success(), "kill -INT {group}");
    }

    /// Waits for it to exit (killing its group after `limit`); its status,
    /// the rest of its stdout and its stderr.
    fn finish(mut self, limit: Duration) -> (ExitStatus, String, String) {
        let deadline = Instant::now() + limit;
        let status = loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                break status;
            }
            if Instant::now() > deadline {
                let group = format!("-{}", self.child.id());
                let _ = Command::new("kill").args(["-KILL", "--", &group]).status();
                let _ = self.child.wait();
                panic!("it did not end within {limit:?} of Ctrl-C");
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        let mut stderr = String::new();
        self.child
            .stderr
            .take()
            .unwrap()
            .read_to_string(&mut stderr)
            .unwrap();
        eprintln!("stderr: {stderr}");
        let stdout: Vec<String> =
            std::iter::from_fn(|| self.lines.recv_timeout(Duration::from_secs(5)).ok()).collect();
        (status, stdout.join("\n"), stderr)
    }
}

/// The ids of the processes whose command line names `path` (the
/// emulated board, which reads `out/region.bin`).
fn processes_naming(path: &Path) -> Vec<String> {
    let needle = path.to_string_lossy().into_owned();
    std::fs::read_dir("/proc")
        .unwrap()
        .filter_map(|e| {
            let e = e.ok()?;
            let cmdline = std::fs::read(e.path().join("cmdline")).ok()?;
            String::from_utf8_lossy(&cmdline)
                .replace('\0', " ")
                .contains(&needle)
                .then(|| e.file_name().to_string_lossy().into_owned())
        })
        .collect()
}

#[test]
fn ctrl_c_ends_a_live_take_as_seconds_would() {
    let dir = tempfile::tempdir().unwrap();
    let live = Live::start(dir.path(), &[]);
    let to = live.source();
    let socket = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let start = Instant::now();
    for i in 0..300u32 {
        let due = Duration::from_millis(5 * u64::from(i));
        std::thread::sleep(due.saturating_sub(start.elapsed()));
        socket.send_to(&vmc_hand(f64::from(i) / 300.0), to).unwrap();
    }
    // The newest frames reach the board and the recording (100 ms flushes).
    std::thread::sleep(Duration::from_millis(300));
    live.ctrl_c();
    let (take_path, csv) = (live.take.clone(), live.out.join("live.csv"));
    let (status, stdout, stderr) = live.finish(Duration::from_secs(120));

    assert!(status.success(), "live ends cleanly on Ctrl-C: {status}");
    assert!(
        stderr.contains("live: stopping (Ctrl-C again to quit now)"),
        "{stderr}"
    );
    assert!(
        stdout.contains("live: stopped by Ctrl-C after "),
        "{stdout}"
    );
    assert!(
        stdout.contains("live: 300 packets from 1 sender(s)"),
        "{stdout}"
    );
    assert!(!stdout.contains("no Ack of Disarm"), "disarmed: {stdout}");
    // The end check ran and the board's servo output equals the core's.
    let check = stdout
        .lines()
        .find(|l| l.starts_with("emulated board: "))
        .unwrap_or_else(|| panic!("the end check's line: {stdout}"));
    let compared: usize = check["emulated board: ".len()..]
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!(compared > 0 && check.contains(": 0 differ"), "{check}");
    assert!(stdout.contains(&format!("recording: {}", csv.display())));

    // The recording and the take: the same frames, the board's outputs.
    let recorded = marionette_host::import::csv::read_tracker_csv(&csv).unwrap();
    let frames = perform::frames(&recorded).unwrap();
    assert!(frames.len() >= 10, "{} frames recorded", frames.len());
    let take = marionette_host::take::Take::load(&take_path).expect("the take loads");
    assert_eq!(take.source, "live");
    let info = take.info();
    assert_eq!(info.sent.tracker_frames, frames.len());
    assert!(info.servo_link_seen, "{info:?}");
    assert_eq!(info.frame_outputs, frames.len(), "{info:?}");
    assert!(processes_naming(&dir.path().join("out/region.bin")).is_empty());
}

/// A session slow on its way out (its view kept up 60 s after the
/// performance, the board still running) quits at the second Ctrl-C, and
/// ends the board it started.
#[cfg(feature = "view")]
#[test]
fn a_second_ctrl_c_quits_at_once_and_leaves_no_board_running() {
    let dir = tempfile::tempdir().unwrap();
    let view = ["--view", "--view-listen", "127.0.0.1:0"];
    let live = Live::start(dir.path(), &[&view[..], &["--view-linger", "60"]].concat());
    let _ = live.source();
    let region = dir.path().join("out/region.bin");
    let board = processes_naming(&region);
    assert_eq!(board.len(), 1, "the emulated board runs: {board:?}");
    live.ctrl_c();
    std::thread::sleep(Duration::from_millis(1500));
    assert_eq!(processes_naming(&region), board, "still running");
    live.ctrl_c();
    let (status, stdout, stderr) = live.finish(Duration::from_secs(10));
    assert_eq!(status.code(), Some(130), "{stderr}");
    assert!(stderr.contains("live: stopping"), "{stderr}");
    assert!(stderr.contains("live: quitting now"), "{stderr}");
    assert!(
        !stdout.contains("stopped by Ctrl-C"),
        "no summary: {stdout}"
    );
    none_left_naming(&region);
}

/// A signal to the command alone (`kill PID`, a supervisor's SIGTERM), not
/// to its process group: `emulate` quits with exit code 130 and its
/// emulated board ends with it (it used to keep running the firmware's
/// loop on a whole core, its sockets' other end gone).
#[test]
fn a_signal_to_the_command_alone_ends_its_emulated_board_too() {
    let dir = tempfile::tempdir().unwrap();
    let (mut child, out) = emulating(dir.path());
    let pid = nix::unistd::Pid::from_raw(i32::try_from(child.id()).unwrap());
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM).unwrap();
    let status = ended(&mut child);
    let mut stderr = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    assert_eq!(status.code(), Some(130), "{stderr}");
    assert!(
        stderr.contains("marionette: quitting now (exit code 130)"),
        "{stderr}"
    );
    none_left_naming(&out);
    no_socket_folder(dir.path());
}

/// SIGKILL to the command alone: no handler runs, but the emulated board
/// was started through `setpriv --pdeathsig KILL` (util-linux, on every
/// Debian), so the kernel ends it with the command.
#[test]
fn sigkill_to_the_command_alone_ends_its_emulated_board_too() {
    let dir = tempfile::tempdir().unwrap();
    let (mut child, out) = emulating(dir.path());
    child.kill().unwrap();
    let status = ended(&mut child);
    assert_eq!(
        std::os::unix::process::ExitStatusExt::signal(&status),
        Some(9)
    );
    none_left_naming(&out);
    no_socket_folder(dir.path());
}

/// `marionette emulate` of a 10 s recording into `dir/out`, with `dir/tmp`
/// as its temporary folder, once its emulated board runs (the command and
/// the board both name `out`: the board reads its flash region from there).
fn emulating(dir: &Path) -> (Child, PathBuf) {
    let (recording, _) = repeated_recording(dir, 10);
    let out = dir.join("out");
    let tables = rest_tables(dir);
    let tmp = dir.join("tmp");
    std::fs::create_dir(&tmp).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_marionette"))
        .args(["emulate", "--tables", s(&tables), "--recording"])
        .args([s(&recording), "--out", s(&out)])
        .env("TMPDIR", &tmp)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(120);
    while processes_naming(&out).len() < 2 || !socket_folders(&tmp).is_empty() {
        let folders = socket_folders(&tmp);
        assert!(
            Instant::now() < deadline && child.try_wait().unwrap().is_none(),
            "emulate ended, or ran out of time, before its board ran without a socket folder: {folders:?}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    (child, out)
}

/// Checks that the command left no folder of QEMU's serial sockets in its
/// temporary folder `dir/tmp`.
fn no_socket_folder(dir: &Path) {
    let left = socket_folders(&dir.join("tmp"));
    assert!(left.is_empty(), "left behind: {left:?}");
}

/// The folders of QEMU's serial sockets in `tmp` (`Emulator::start`
/// removes its folder once it has connected to both).
fn socket_folders(tmp: &Path) -> Vec<std::ffi::OsString> {
    std::fs::read_dir(tmp)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .filter(|n| n.to_string_lossy().starts_with("marionette-qemu"))
        .collect()
}

/// Waits (up to 30 s) for `child` to end.
fn ended(child: &mut Child) -> ExitStatus {
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return status;
        }
        assert!(Instant::now() < deadline, "the command did not end");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Waits (a hang guard of 120 s) until the board has put 4 KB on its
/// servo link (the file `servo`): a session under way.
fn moved(servo: &Path) {
    let deadline = Instant::now() + Duration::from_secs(120);
    while std::fs::metadata(servo).map_or(0, |m| m.len()) < 4096 {
        assert!(Instant::now() < deadline, "the board never moved");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Waits (up to 5 s) until no process names `path` (the emulated board
/// has ended).
fn none_left_naming(path: &Path) {
    let deadline = Instant::now() + Duration::from_secs(5);
    while !processes_naming(path).is_empty() {
        assert!(
            Instant::now() < deadline,
            "left running: {:?}",
            processes_naming(path)
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// `stream` of a 21 s recording to the emulated board on a pty (a board on
/// a serial port), Ctrl-C once the servos move: it disarms the board,
/// prints its summary, saves the take and the frames sent.
#[test]
fn ctrl_c_ends_a_stream_early_and_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let region = board_region(dir.path());
    let servo = dir.path().join("uart1.bin");
    let elf = marionette_host::qemu::firmware_elf("perform").unwrap();
    let mut board = marionette_host::qemu::PtyBoard::start(&elf, &region, &servo).unwrap();
    let (recording, per_copy) = repeated_recording(dir.path(), 10);
    let frames = per_copy * 10;
    let (out, take) = (dir.path().join("out"), dir.path().join("stream.take"));
    let child = Live::spawn(&[&[
        "stream",
        "--port",
        s(board.pty()),
        "--baud",
        "200000",
        "--recording",
        s(&recording),
        "--out",
        s(&out),
        "--take",
        s(&take),
    ]]);
    let stream = Live::with(child, out.clone(), take.clone());
    moved(&servo);
    stream.ctrl_c();
    let (status, stdout, stderr) = stream.finish(Duration::from_secs(120));
    assert!(status.success(), "stream ends cleanly on Ctrl-C: {status}");
    assert!(
        stderr.contains("stream: stopping (Ctrl-C again to quit now)"),
        "{stderr}"
    );
    let stopped = stdout
        .lines()
        .find(|l| l.starts_with("stream: stopped by Ctrl-C after "))
        .unwrap_or_else(|| panic!("{stdout}"));
    let offered: usize = stopped["stream: stopped by Ctrl-C after ".len()..]
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!(
        offered > 0 && offered < frames,
        "{stopped} ({frames} frames)"
    );
    assert!(
        stopped.ends_with(&format!(" of {frames} frames")),
        "{stopped}"
    );
    assert!(!stdout.contains("no Ack of Disarm"), "disarmed: {stdout}");
    assert_eq!(board.wait(Duration::from_secs(30)).unwrap(), Some(0));
    let sent = marionette_host::import::csv::read_tracker_csv(&out.join("sent.csv")).unwrap();
    let sent = perform::frames(&sent).unwrap();
    assert!(!sent.is_empty() && sent.len() <= offered);
    let take = marionette_host::take::Take::load(&take).expect("the take loads");
    assert_eq!(take.source, "stream");
    assert_eq!(take.info().sent.tracker_frames, sent.len());
}

/// `replay --port` of a 21 s take (made by `sim` on the same rig and
/// table) to the emulated board on a pty, Ctrl-C once the servos move: it
/// tells the board to disarm (the board then ends cleanly, having tripped
/// nothing), says where it stopped, and compares the telemetry of the
/// frames it sent: all of them match the take's.
#[test]
fn ctrl_c_ends_a_replay_to_a_port_early_and_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let region = board_region(dir.path());
    let (recording, _) = repeated_recording(dir.path(), 10);
    let take = dir.path().join("sim.take");
    let rig = repo().join("rigs/humanoid16.toml");
    let sim = Command::new(env!("CARGO_BIN_EXE_marionette"))
        .args(["sim", "--rig", s(&rig), "--tables"])
        .args([s(&rest_tables(dir.path())), "--recording", s(&recording)])
        .args(["--out", s(&dir.path().join("sim")), "--take", s(&take)])
        .output()
        .unwrap();
    assert!(sim.status.success(), "{sim:?}");
    let messages = marionette_host::take::Take::load(&take)
        .unwrap()
        .session()
        .len();
    let servo = dir.path().join("uart1.bin");
    let elf = marionette_host::qemu::firmware_elf("perform").unwrap();
    let mut board = marionette_host::qemu::PtyBoard::start(&elf, &region, &servo).unwrap();
    let port = ["--port", s(board.pty()), "--baud", "200000"];
    let child = Live::spawn(&[&["replay", s(&take)], &port[..]]);
    let replay = Live::with(child, dir.path().join("out"), take.clone());
    moved(&servo);
    replay.ctrl_c();
    let (status, stdout, stderr) = replay.finish(Duration::from_secs(120));
    assert!(
        status.success(),
        "replay ends cleanly on Ctrl-C: {status} {stderr}"
    );
    assert!(
        stderr.contains("replay: stopping (Ctrl-C again to quit now)"),
        "{stderr}"
    );
    let head = "replay: stopped by Ctrl-C after ";
    let stopped = stdout
        .lines()
        .find(|l| l.starts_with(head))
        .unwrap_or_else(|| panic!("{stdout}"));
    let sent: usize = stopped[head.len()..]
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!(sent > 2 && sent < messages, "{stopped} ({messages})");
    assert!(
        stopped.contains(&format!(" of the take's {messages} messages")),
        "{stopped}"
    );
    let summary = stdout
        .lines()
        .find(|l| l.starts_with("replay on "))
        .unwrap_or_else(|| panic!("{stdout}"));
    assert!(summary.contains("fail-safe trips 0 (take: 0)"), "{summary}");
    let compared: usize = summary
        .split("; ")
        .find_map(|part| part.strip_suffix(" telemetry compared, 0 differ"))
        .unwrap_or_else(|| panic!("telemetry compared, none differ: {summary}"))
        .parse()
        .unwrap();
    assert!(compared > 0 && compared < sent, "{summary}");
    // The board got the Disarm: it eases to rest and ends (exit 0).
    assert_eq!(board.wait(Duration::from_secs(30)).unwrap(), Some(0));
}

#[test]
fn ctrl_c_before_the_board_answers_never_arms_it() {
    // A pty with nothing behind it: `stream` says Hello once a second and
    // waits up to 5 s for an answer. Ctrl-C after its first Hello ends it
    // then, with its own error (not the no-answer fault at 5 s), and it
    // has written nothing but Hello.
    let dir = tempfile::tempdir().unwrap();
    let pty = nix::pty::openpty(None, None).unwrap();
    let slave = std::fs::read_link(format!("/proc/self/fd/{}", pty.slave.as_raw_fd())).unwrap();
    let (tx, written) = std::sync::mpsc::channel::<Vec<u8>>();
    let mut master = std::fs::File::from(pty.master);
    std::thread::spawn(move || {
        let mut buf = [0u8; 4096];
        while let Ok(n @ 1..) = master.read(&mut buf) {
            if tx.send(buf[..n].to_vec()).is_err() {
                break;
            }
        }
    });
    let (recording, _) = repeated_recording(dir.path(), 1);
    let (out, take) = (dir.path().join("out"), dir.path().join("stream.take"));
    let child = Live::spawn(&[&[
        "stream",
        "--port",
        s(&slave),
        "--recording",
        s(&recording),
        "--out",
        s(&out),
    ]]);
    let stream = Live::with(child, out, take);
    let mut bytes = Vec::new();
    while !bytes.contains(&0) || bytes.last() != Some(&0) || bytes.len() < 2 {
        let chunk = written
            .recv_timeout(Duration::from_secs(120))
            .expect("stream says Hello");
        bytes.extend(chunk);
    }
    stream.ctrl_c();
    let (status, _, stderr) = stream.finish(Duration::from_secs(60));
    assert_eq!(status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("stopped by Ctrl-C before the board armed"),
        "{stderr}"
    );
    bytes.extend(written.try_iter().flatten());
    let mut said = Vec::new();
    for frame in bytes.split(|&b| b == 0).filter(|f| !f.is_empty()) {
        let mut buf = [0u8; 512];
        let n = marionette_core::wire::cobs::decode(frame, &mut buf).unwrap();
        said.push(marionette_core::wire::decode_frame(&buf[..n]).unwrap());
    }
    assert!(!said.is_empty());
    assert!(
        said.iter()
            .all(|m| matches!(m, marionette_core::wire::Message::Hello(_))),
        "{said:?}"
    );
}
