//! The live view in a real browser (#17): `marionette demo --view` on the
//! emulated board, and headless Chromium (Debian package `chromium`, which
//! `.ci/setup` installs when missing) taking screenshots of the page at two
//! instants while the board performs. The page must have rendered (the
//! figure's views are not blank) and the figure must have moved between
//! the two (pixels of the views differ).
#![cfg(feature = "view")]

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The browser, as Debian installs it.
fn chromium() -> PathBuf {
    ["/usr/bin/chromium", "/usr/bin/chromium-browser"]
        .iter()
        .map(PathBuf::from)
        .find(|p| p.exists())
        .expect("headless Chromium is needed: run .ci/setup (Debian package `chromium`)")
}

/// A screenshot of `url` after the page has had `settle` to draw.
fn screenshot(url: &str, path: &Path, settle: Duration) -> Vec<u8> {
    let out = Command::new(chromium())
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--hide-scrollbars",
            "--window-size=1280,900",
        ])
        .arg(format!("--timeout={}", settle.as_millis()))
        .arg(format!("--screenshot={}", path.display()))
        .arg(url)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .expect("chromium runs");
    assert!(out.success(), "chromium: {out}");
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

/// The demo with its view on a free port; returns it and the page's URL.
fn start_demo(out: &Path) -> (Child, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_marionette"))
        .args([
            "demo",
            "--view",
            "--listen",
            "127.0.0.1:0",
            "--view-linger",
            "2",
        ])
        .arg("--out")
        .arg(out)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = child.stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if let Some(at) = line.find("http://") {
                let _ = tx.send(line[at..].trim().to_owned());
            }
        }
    });
    let url = rx
        .recv_timeout(Duration::from_secs(120))
        .expect("the demo prints the view's address");
    (child, url)
}

#[test]
fn the_live_view_shows_the_demo_moving_in_a_real_browser() {
    let dir = tempfile::tempdir().unwrap();
    let (mut demo, url) = start_demo(&dir.path().join("out"));
    let settle = Duration::from_secs(3);
    let start = Instant::now();
    let first = screenshot(&url, &dir.path().join("a.png"), settle);
    std::thread::sleep(Duration::from_secs(2));
    let second = screenshot(&url, &dir.path().join("b.png"), settle);
    let took = start.elapsed();
    let (a, width) = pixels(&first);
    let (b, _) = pixels(&second);
    let white = [255, 255, 255];
    let background = [0xf4, 0xf4, 0xf2];
    let drawn = a
        .iter()
        .enumerate()
        .filter(|&(i, p)| in_views(i, width) && *p != white && *p != background)
        .count();
    let moved = a
        .iter()
        .zip(&b)
        .enumerate()
        .filter(|&(i, (p, q))| in_views(i, width) && p != q)
        .count();
    println!("{drawn} figure pixels drawn; {moved} changed between screenshots {took:?} apart");
    // A stick figure in four views is thousands of pixels; a moving arm
    // changes hundreds.
    assert!(drawn > 2000, "the page did not render a figure: {drawn}");
    assert!(moved > 200, "the figure did not move: {moved}");
    let status = demo.wait().unwrap();
    assert!(status.success(), "the demo ends cleanly: {status}");
}
