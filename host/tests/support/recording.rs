//! Long recordings for the host tests that watch a board perform.

use std::path::{Path, PathBuf};

/// The demo's recording (`data/recordings/reach_hdm05_007.csv`) played
/// `times` times over, one after the other (so that the board performs for
/// long enough to be watched or interrupted), written to `dir/long.csv`;
/// returns the path and the tracker frames of one copy (three sensor rows
/// each).
pub fn repeated_recording(dir: &Path, times: u64) -> (PathBuf, usize) {
    let repo = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let text = std::fs::read_to_string(repo.join("data/recordings/reach_hdm05_007.csv")).unwrap();
    let mut lines = text.lines();
    let mut out = vec![lines.next().unwrap().to_owned()];
    let rows: Vec<(u64, &str)> = lines
        .map(|l| {
            let (t, rest) = l.split_once(',').unwrap();
            (t.parse().unwrap(), rest)
        })
        .collect();
    let span = rows.last().unwrap().0 + 1000;
    for k in 0..times {
        for (t, rest) in &rows {
            out.push(format!("{},{rest}", t + k * span));
        }
    }
    let path = dir.join("long.csv");
    std::fs::write(&path, out.join("\n") + "\n").unwrap();
    (path, rows.len() / 3)
}
