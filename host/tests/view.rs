//! The live view in a real browser (#17): `marionette demo --view` on the
//! emulated board, `stream --view` and `live --view` on the emulated board
//! as a real one (its tracker link on a pseudo-terminal), and headless
//! Chromium (Debian package `chromium`, which
//! `.ci/setup tests` installs when missing) taking screenshots of the page at two
//! instants while the board performs. The page must have rendered (the
//! figure's views are not blank) and the figure must have moved between
//! the two (pixels of the views differ).
#![cfg(feature = "view")]

#[path = "support/recording.rs"]
mod recording;
#[path = "support/vmc.rs"]
mod vmc;

use marionette_host::{perform, rigfile};
use recording::repeated_recording;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Mutex;
use std::sync::mpsc::Sender;
use std::time::{Duration, Instant};
use vmc::vmc_hand;

/// The browser, as Debian installs it.
fn chromium() -> PathBuf {
    ["/usr/bin/chromium", "/usr/bin/chromium-browser"]
        .iter()
        .map(PathBuf::from)
        .find(|p| p.exists())
        .expect("headless Chromium is needed: run .ci/setup tests (Debian package `chromium`)")
}

/// A screenshot of `url` after the page has had `settle` to draw.
fn screenshot(url: &str, path: &Path, settle: Duration) -> Vec<u8> {
    // Its output is kept (a pipe): with stderr on /dev/null this
    // Chromium has been seen to write a page without its script's drawing.
    let out = Command::new(chromium())
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            // Containers often have a small /dev/shm.
            "--disable-dev-shm-usage",
            "--hide-scrollbars",
            "--window-size=1280,900",
        ])
        .arg(format!("--timeout={}", settle.as_millis()))
        .arg(format!("--screenshot={}", path.display()))
        .arg(url)
        .output()
        .expect("chromium runs");
    assert!(
        out.status.success(),
        "chromium: {}: {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    std::fs::read(path).expect("chromium wrote the screenshot")
}

/// RGB pixels of a PNG, with its width.
fn pixels(png_bytes: &[u8]) -> (Vec<[u8; 3]>, usize) {
    let mut reader = png::Decoder::new(png_bytes).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    let step = info.color_type.samples();
    let px = buf[..info.buffer_size()]
        .chunks(step)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    (px, info.width as usize)
}

/// The four views' area (left two thirds, below the header) of a 1280×900
/// page.
fn in_views(i: usize, width: usize) -> bool {
    let (x, y) = (i % width, i / width);
    (16..840).contains(&x) && (60..740).contains(&y)
}

/// `marionette ARGS` (a session with its view on a free port); returns it
/// and the page's URL, which it prints on stderr. Its stdout lines are
/// sent to `stdout` if given.
fn start_view(args: &[&str], stdout: Option<Sender<String>>) -> (Child, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_marionette"))
        .args(args)
        .stdout(if stdout.is_some() {
            Stdio::piped()
        } else {
            Stdio::null()
        })
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let name = args[0].to_owned();
    if let (Some(tx), Some(out)) = (stdout, child.stdout.take()) {
        let name = name.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                println!("{name}: {line}");
                let _ = tx.send(line);
            }
        });
    }
    let stderr = child.stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            eprintln!("{name}: {line}");
            if let Some(at) = line.find("http://") {
                let _ = tx.send(line[at..].trim().to_owned());
            }
        }
    });
    let url = rx
        .recv_timeout(Duration::from_secs(120))
        .expect("the session prints the view's address");
    (child, url)
}

/// Kills the session if the test fails before it ends.
struct KillOnDrop(Option<Child>);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        if let Some(mut c) = self.0.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// Waits until the view's event stream carries a figure (the board has
/// started performing; before that the demo checks its inputs natively).
fn wait_for_figure(url: &str, limit: Duration) {
    use std::io::{Read, Write};
    let addr = url.trim_start_matches("http://").trim_end_matches('/');
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(limit)).unwrap();
    s.write_all(b"GET /events HTTP/1.1\r\nHost: view\r\n\r\n")
        .unwrap();
    let start = Instant::now();
    let mut got = Vec::new();
    let mut buf = [0u8; 4096];
    while start.elapsed() < limit {
        let n = s.read(&mut buf).unwrap_or(0);
        assert!(n > 0, "the event stream ended before a figure came");
        got.extend_from_slice(&buf[..n]);
        if String::from_utf8_lossy(&got).contains("\"bones\":[[") {
            return;
        }
    }
    panic!("no figure on the event stream within {limit:?}");
}

/// Pixels of the views drawn in the figure's colours (bones: dark grey,
/// blue, red; goals: green), within a small tolerance for anti-aliasing.
fn figure_pixels(px: &[[u8; 3]], width: usize) -> usize {
    const INK: [[u8; 3]; 4] = [
        [0x33, 0x33, 0x33],
        [0x1f, 0x77, 0xb4],
        [0xd6, 0x27, 0x28],
        [0x2c, 0xa0, 0x2c],
    ];
    let near = |p: &[u8; 3], q: &[u8; 3]| p.iter().zip(q).all(|(a, b)| a.abs_diff(*b) <= 24);
    px.iter()
        .enumerate()
        .filter(|&(i, p)| in_views(i, width) && INK.iter().any(|q| near(p, q)))
        .count()
}

/// Screenshots until one shows the figure (a loaded machine can be slow
/// to start the browser and open the event stream); at most `tries`.
fn shot_with_figure(url: &str, path: &Path, tries: usize) -> (Vec<[u8; 3]>, usize, usize) {
    let mut last = (Vec::new(), 0, 0);
    for _ in 0..tries {
        let (px, width) = pixels(&screenshot(url, path, Duration::from_secs(5)));
        let drawn = figure_pixels(&px, width);
        last = (px, width, drawn);
        if drawn > 1500 {
            break;
        }
    }
    last
}

/// Two screenshots of the page 1 s apart (into `MARIONETTE_VIEW_SHOTS`
/// if set, named `{name}_a.png`, `{name}_b.png`): the page must have
/// drawn the figure in both, and the figure must have moved.
fn check_page(url: &str, dir: &Path, name: &str) {
    let shots =
        std::env::var_os("MARIONETTE_VIEW_SHOTS").map_or_else(|| dir.to_path_buf(), PathBuf::from);
    let start = Instant::now();
    let (a, width, drawn_a) = shot_with_figure(url, &shots.join(format!("{name}_a.png")), 3);
    std::thread::sleep(Duration::from_secs(1));
    let (b, _, drawn_b) = shot_with_figure(url, &shots.join(format!("{name}_b.png")), 3);
    let took = start.elapsed();
    let moved = a
        .iter()
        .zip(&b)
        .enumerate()
        .filter(|&(i, (p, q))| in_views(i, width) && p != q)
        .count();
    println!(
        "{name}: {drawn_a} and {drawn_b} figure pixels drawn; {moved} changed between \
         screenshots {took:?} apart"
    );
    // A stick figure in four views is thousands of pixels in its colours
    // (an empty page has none); a moving arm changes hundreds.
    assert!(
        drawn_a > 1500 && drawn_b > 1500,
        "{name}: the page did not draw a figure"
    );
    assert!(moved > 200, "{name}: the figure did not move: {moved}");
}

/// One browser test at a time: each runs a board and Chromium.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

#[test]
fn the_live_view_shows_the_demo_moving_in_a_real_browser() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let recording = repeated_recording(dir.path(), 2).0;
    let out = dir.path().join("out");
    let (demo, url) = start_view(
        &[
            "demo",
            "--view",
            "--listen",
            "127.0.0.1:0",
            "--view-linger",
            "2",
            "--recording",
            s(&recording),
            "--out",
            s(&out),
        ],
        None,
    );
    let mut demo = KillOnDrop(Some(demo));
    wait_for_figure(&url, Duration::from_secs(180));
    check_page(&url, dir.path(), "demo");
    let status = demo.0.take().unwrap().wait().unwrap();
    assert!(status.success(), "the demo ends cleanly: {status}");
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// A region for the emulated board as a real board's flash: humanoid16
/// (with a 60 s fail-safe time-out: a loaded machine's stall must not trip
/// it) and a table whose every sample is the rest pose (the solver moves
/// the figure to the goals).
fn board_region(dir: &Path) -> (PathBuf, PathBuf) {
    let rig = rigfile::load(&repo().join("rigs/humanoid16.toml")).unwrap();
    let axes = [
        ("hand_x", -1.0, 2.0, 2),
        ("hand_y", -1.0, 2.0, 2),
        ("hand_z", -1.0, 2.0, 2),
    ];
    let table = perform::rest_grid(&rig, &axes).unwrap();
    let mut desc = rig.desc();
    desc.failsafe_timeout_ms = 60_000;
    let mut blob = vec![0u8; marionette_core::rig::MAX_BLOB_LEN];
    let n = desc.to_blob(&mut blob).unwrap();
    let region = dir.join("region.bin");
    std::fs::write(&region, perform::region(&blob[..n], Some(&table))).unwrap();
    let tables = dir.join("rest.bin");
    std::fs::write(&tables, table).unwrap();
    (region, tables)
}

/// `stream --port PTY --view` to the emulated board on a pseudo-terminal
/// (a real board's serial port: the figure comes from the servo targets
/// in its telemetry): the page draws the figure and it moves.
#[test]
fn stream_view_shows_a_board_on_a_serial_port_moving() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let (region, _) = board_region(dir.path());
    let elf = marionette_host::qemu::firmware_elf("perform").unwrap();
    let mut board =
        marionette_host::qemu::PtyBoard::start(&elf, &region, &dir.path().join("uart1.bin"))
            .unwrap();
    // 26 s: long enough for two screenshots however slowly Chromium starts.
    let recording = repeated_recording(dir.path(), 12).0;
    let out = dir.path().join("out");
    let (stream, url) = start_view(
        &[
            "stream",
            "--port",
            s(board.pty()),
            "--baud",
            "200000",
            "--recording",
            s(&recording),
            "--out",
            s(&out),
            "--view",
            "--listen",
            "127.0.0.1:0",
            "--view-linger",
            "1",
        ],
        None,
    );
    let mut stream = KillOnDrop(Some(stream));
    wait_for_figure(&url, Duration::from_secs(60));
    check_page(&url, dir.path(), "stream");
    let status = stream.0.take().unwrap().wait().unwrap();
    assert!(status.success(), "the stream ends cleanly: {status}");
    assert_eq!(board.wait(Duration::from_secs(30)).unwrap(), Some(0));
}

/// `live --port PTY --view --take T` (its view on `--view-listen`;
/// `--listen` is the UDP source's) to the emulated board on a
/// pseudo-terminal, as a board on a serial port, driven by a VMC sender
/// moving the right hand in a circle: the page draws the figure and it
/// moves, and the take holds what the board's telemetry reported.
#[test]
fn live_view_shows_a_vmc_performance_moving() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let (region, tables) = board_region(dir.path());
    let elf = marionette_host::qemu::firmware_elf("perform").unwrap();
    let mut board =
        marionette_host::qemu::PtyBoard::start(&elf, &region, &dir.path().join("uart1.bin"))
            .unwrap();
    let out = dir.path().join("out");
    let take_path = dir.path().join("live.take");
    let (tx, lines) = std::sync::mpsc::channel();
    let (live, url) = start_view(
        &[
            "live",
            "--port",
            s(board.pty()),
            "--baud",
            "200000",
            "--take",
            s(&take_path),
            "--tables",
            s(&tables),
            "--listen",
            "127.0.0.1:0",
            "--seconds",
            "40",
            "--out",
            s(&out),
            "--view",
            "--view-listen",
            "127.0.0.1:0",
            "--view-linger",
            "1",
        ],
        Some(tx),
    );
    let mut live = KillOnDrop(Some(live));
    let to: std::net::SocketAddr = loop {
        let line = lines
            .recv_timeout(Duration::from_secs(120))
            .expect("live says where it listens");
        if let Some(at) = line.find("udp://") {
            let addr = line[at + 6..].split_whitespace().next().unwrap();
            break addr.parse().unwrap();
        }
    };
    assert_ne!(to.port(), 0);
    assert!(
        !url.contains(&format!(":{}", to.port())),
        "one address each"
    );
    let sending = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(true));
    let keep = std::sync::Arc::clone(&sending);
    let vmc = std::thread::spawn(move || {
        let socket = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let start = Instant::now();
        while keep.load(std::sync::atomic::Ordering::Relaxed) {
            let _ = socket.send_to(&vmc_hand(start.elapsed().as_secs_f64() / 2.0), to);
            std::thread::sleep(Duration::from_millis(16));
        }
    });
    wait_for_figure(&url, Duration::from_secs(60));
    check_page(&url, dir.path(), "live");
    let status = live.0.take().unwrap().wait().unwrap();
    sending.store(false, std::sync::atomic::Ordering::Relaxed);
    vmc.join().unwrap();
    assert!(status.success(), "live ends cleanly: {status}");
    assert_eq!(board.wait(Duration::from_secs(30)).unwrap(), Some(0));
    // The take from the port: the frames sent, the telemetry's targets.
    let take = marionette_host::take::Take::load(&take_path).unwrap();
    let info = take.info();
    assert_eq!((take.source.as_str(), info.format_version), ("live", 2));
    assert!(!info.servo_link_seen && info.frame_outputs == 0);
    assert!(info.sent.tracker_frames > 100, "{info:?}");
    assert_eq!(info.reported_outputs, info.telemetry);
    assert!(info.reported_outputs > 10, "{info:?}");
}
