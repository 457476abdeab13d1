//! What fits where: a table's size worked out from its shape before it is
//! built, against each board's table region.
//!
//! `marionette build` calls [`check_spec`] before it reads any mocap and
//! [`check_dataset`] before it resamples, so that a table no board can hold
//! (a 1000 × 1000 grid, a million frames per phase) is refused in
//! milliseconds, naming the spec's line and field, instead of after minutes
//! and gigabytes. After the build, [`fits`] states the blob's exact size
//! against every board.
//!
//! A table's samples take [`SAMPLE_LEN`] bytes per segment per grid sample;
//! the header, validity mask, durations and CRC add a little. The region
//! holds the rig blob too, at the next 4-byte boundary before the table.

use crate::board::{BOARDS, Board};
use crate::build::error::{InputError, Source};
use crate::build::spec::{Input, Kind, Spec};
use crate::build::{Dataset, Layout};
use marionette_core::table::SAMPLE_LEN;

/// Bytes of a table's samples: `grid_samples × segments × 12`.
#[must_use]
pub fn sample_bytes(grid_samples: u64, segments: u64) -> u64 {
    grid_samples
        .saturating_mul(segments)
        .saturating_mul(SAMPLE_LEN as u64)
}

/// Bytes of the region a rig blob and a table (0: none) take together, laid
/// out as [`marionette_core::region::write`] does: the directory (one entry
/// per blob, then its CRC), then each blob at the next 4-aligned offset.
#[must_use]
pub fn region_bytes(rig_blob: u64, table: u64) -> u64 {
    use marionette_core::region::{CRC_LEN, ENTRY_LEN, PREFIX_LEN};
    let entries = if table > 0 { 2 } else { 1 };
    let directory = (PREFIX_LEN + ENTRY_LEN * entries + CRC_LEN) as u64;
    directory
        .next_multiple_of(4)
        .saturating_add(rig_blob)
        .next_multiple_of(4)
        .saturating_add(table)
        .next_multiple_of(4)
}

/// How a table of `table` bytes (with a rig blob of `rig_blob` bytes) fits
/// each board: `(board, fits, region bytes used)`.
#[must_use]
pub fn fits(table: u64, rig_blob: u64) -> Vec<(Board, bool, u64)> {
    BOARDS
        .iter()
        .map(|b| {
            let used = region_bytes(rig_blob, table);
            (*b, used <= b.table_region as u64, used)
        })
        .collect()
}

/// The boards a table is checked against: the one asked for, or all.
fn targets(board: Option<&Board>) -> Vec<Board> {
    board.map_or_else(|| BOARDS.to_vec(), |b| vec![*b])
}

/// Why `bytes` of samples (at least) fit none of `boards`, in words; `None`
/// if one of them can hold them.
fn too_big(what: &str, bytes: u64, rig_blob: u64, board: Option<&Board>) -> Option<String> {
    let boards = targets(board);
    let used = region_bytes(rig_blob, bytes);
    if boards.iter().any(|b| used <= b.table_region as u64) {
        return None;
    }
    let regions: Vec<String> = boards
        .iter()
        .map(|b| format!("{} {} B", b.key, b.table_region))
        .collect();
    let which = if board.is_some() {
        "the board's table region"
    } else {
        "every board's table region"
    };
    Some(format!(
        "{what} = {bytes} B of samples{}, more than {which} ({}); use fewer samples, or fewer \
         segments",
        if rig_blob > 0 {
            format!(" (+ the rig blob, {rig_blob} B)")
        } else {
            String::new()
        },
        regions.join(", ")
    ))
}

/// The line of `key` inside the `[table]` of a TOML text (0 if absent).
fn line_of_key(text: &str, table: &str, key: &str) -> usize {
    let mut inside = false;
    for (i, line) in text.lines().enumerate() {
        let t = line.trim();
        if t.starts_with('[') {
            inside = t.trim_matches(|c| c == '[' || c == ']').trim() == table;
        } else if inside && t.split('=').next().is_some_and(|k| k.trim() == key) {
            return i + 1;
        }
    }
    0
}

/// The bytes of the spec's rig file's blob (0 without a rig file).
#[must_use]
pub fn rig_blob_bytes(spec: &Spec) -> u64 {
    rig_file_size(spec).map_or(0, |(_, b)| b)
}

/// The segments and rig-blob bytes of the spec's rig file (if it names
/// one and it loads; the build reports its errors later).
fn rig_file_size(spec: &Spec) -> Option<(u64, u64)> {
    let path = spec.rig.file.as_ref()?;
    let rig = crate::rigfile::load(path).ok()?;
    let blob = crate::rigfile::to_blob(&rig).ok()?;
    Some((rig.segment_names().len() as u64, blob.len() as u64))
}

/// Checks the size of the table a spec asks for before anything is read:
/// the product of the axis counts (and, for clips, the frames per phase)
/// times the segments (the rig file's, or at least 1) must fit a board's
/// table region (`board`, or any). Example sets are checked by
/// [`check_dataset`], once read.
pub fn check_spec(spec: &Spec, board: Option<&Board>) -> Result<(), InputError> {
    if let Input::Examples(_) = spec.input {
        return Ok(());
    }
    let (segments, rig_blob) = rig_file_size(spec).unwrap_or((1, 0));
    let mut samples: u64 = 1;
    let mut words = Vec::new();
    for a in &spec.axes {
        samples = samples.saturating_mul(u64::from(a.count));
        words.push(a.count.to_string());
    }
    let mut field = None;
    if spec.kind == Kind::Clips {
        let phases = match &spec.input {
            Input::Mocap(m) => m.clips.first().map_or(1, |c| c.cut.len().saturating_sub(1)),
            Input::Examples(_) => 1,
        };
        let frames = spec.motion.frames as u64;
        let count = if spec.motion.looping {
            frames
        } else {
            frames.saturating_mul(phases as u64).saturating_add(1)
        };
        let line = line_of_key(&spec.source.text, "motion", "frames");
        if count > u64::from(u16::MAX) {
            return Err(spec.source.error_line(
                line,
                "motion.frames",
                format!(
                    "{frames} frames per phase make a phase axis of {count} samples; a table axis \
                     holds at most {}",
                    u16::MAX
                ),
            ));
        }
        samples = samples.saturating_mul(count);
        words.push(format!("{count} phase samples"));
        field = Some((line, "motion.frames".to_owned()));
    }
    let what = format!(
        "{} grid samples × {segments} segment{} × {SAMPLE_LEN} B",
        words.join(" × "),
        if segments == 1 { " (at least)" } else { "s" }
    );
    let Some(problem) = too_big(&what, sample_bytes(samples, segments), rig_blob, board) else {
        return Ok(());
    };
    let (line, field) = field.unwrap_or_else(|| largest_axis(spec));
    Err(spec.source.error_line(line, &field, problem))
}

/// The line and field of the axis with the most samples.
fn largest_axis(spec: &Spec) -> (usize, String) {
    spec.axes
        .iter()
        .enumerate()
        .max_by_key(|(_, a)| a.count)
        .map_or((0, "axis".into()), |(i, a)| {
            (a.line, format!("axis[{i}].count"))
        })
}

/// Checks the size of the table a loaded dataset will make, before it is
/// resampled: its axes' counts (and frames per clip) times its segments.
pub fn check_dataset(spec: &Spec, data: &Dataset, board: Option<&Board>) -> Result<(), InputError> {
    let rig_blob = rig_file_size(spec).map_or(0, |(_, b)| b);
    let mut samples: u64 = 1;
    let mut words = Vec::new();
    for a in &data.axes {
        samples = samples.saturating_mul(u64::from(a.count));
        words.push(a.count.to_string());
    }
    if let Layout::Clips { .. } = data.layout {
        let frames = data.layout.frames() as u64;
        samples = samples.saturating_mul(frames);
        words.push(format!("{frames} phase samples"));
    }
    let segments = data.segments.len() as u64;
    let what = format!(
        "{} grid samples × {segments} segments × {SAMPLE_LEN} B",
        words.join(" × ")
    );
    let Some(problem) = too_big(&what, sample_bytes(samples, segments), rig_blob, board) else {
        return Ok(());
    };
    match &spec.input {
        Input::Examples(path) => {
            let text = std::fs::read_to_string(path).unwrap_or_default();
            let src = Source {
                file: path.display().to_string(),
                text,
            };
            let line = crate::locate::line(&src.text, "axes");
            Err(src.error_line(line, "axes", problem))
        }
        Input::Mocap(_) => {
            let (line, field) = largest_axis(spec);
            Err(spec.source.error_line(line, &field, problem))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_are_counted_by_hand() {
        // 6 × 6 × 6 grid samples × 13 segments × 12 bytes.
        assert_eq!(sample_bytes(216, 13), 33_696);
        // MREG prefix 8 + 2 entries of 12 + CRC 4 = 36; 5001 -> 5004; 101 -> 104.
        assert_eq!(region_bytes(5001, 101), 36 + 5004 + 104);
        assert_eq!(region_bytes(5001, 0), 24 + 5004);
        assert_eq!(sample_bytes(u64::MAX, 2), u64::MAX);
        let f = fits(300 * 1024, 4000);
        assert_eq!(f.len(), 2);
        assert!(f[0].1 && !f[1].1, "{f:?}");
    }

    #[test]
    fn keys_are_found_in_their_table() {
        let text = "kind = \"clips\"\nframes = 3\n[motion]\n# frames = 9\nlooping = true\n frames = 10\n[resample]\nframes = 4\n";
        assert_eq!(line_of_key(text, "motion", "frames"), 6);
        assert_eq!(line_of_key(text, "axis", "frames"), 0);
    }
}
