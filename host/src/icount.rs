//! Instruction counts from the emulated Cortex-M4F.
//!
//! The firmware's `bench` binary times named regions with SysTick under
//! `-icount shift=7,align=off` and prints `row <name> <baseline|-> <calls>
//! <ticks>` lines over semihosting (see `firmware/src/icount.rs`). This module
//! runs it and turns the rows into instructions per call, with each row's ratio
//! against its baseline row from the same run.

use crate::qemu::{self, Config, QemuError};
use crate::{perform, rigfile};
use marionette_core::deadline::Budget;
use marionette_core::frame::Region;
use marionette_core::perform::Performer;
use marionette_core::region;
use marionette_core::solve::SolverState;
use serde::Serialize;
use std::time::Duration;

/// SysTick ticks per instruction under `-icount shift=7` on the 25 MHz board.
pub const TICKS_PER_INSTRUCTION: f64 = 3.2;

/// One measured region.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Row {
    /// The region's name.
    pub name: String,
    /// The row it is compared against, if any.
    pub baseline: Option<String>,
    /// Calls measured in the region.
    pub calls: u32,
    /// SysTick ticks for the whole region, overhead removed.
    pub ticks: u32,
    /// Instructions per call (ticks / 3.2 / calls).
    pub instructions: f64,
    /// Baseline instructions per call divided by this row's (higher is faster).
    pub speedup: Option<f64>,
}

/// Errors from running or reading the bench.
#[derive(Debug, thiserror::Error)]
pub enum IcountError {
    /// The emulator failed.
    #[error(transparent)]
    Qemu(#[from] QemuError),
    /// The bench exited with a failure status.
    #[error("the bench firmware exited with status {0:?}")]
    Status(Option<i32>),
    /// A console line did not parse.
    #[error("bench output line {line}: {why}: {text:?}")]
    Parse {
        /// 1-based line number in the bench's console output.
        line: usize,
        /// What was wrong.
        why: &'static str,
        /// The line.
        text: String,
    },
    /// The bench's table region could not be made.
    #[error("bench table region: {0}")]
    Region(String),
    /// The stack session's recording could not be read.
    #[error(transparent)]
    Import(#[from] crate::import::ImportError),
    /// The stack session failed on the emulated board.
    #[error(transparent)]
    Perform(#[from] perform::PerformError),
    /// A row names a baseline that no earlier row has.
    #[error("row {row} names baseline {baseline}, which is not an earlier row")]
    UnknownBaseline {
        /// The row.
        row: String,
        /// The missing baseline.
        baseline: String,
    },
}

/// Parses the bench's console output into rows with ratios.
pub fn parse(console: &str) -> Result<Vec<Row>, IcountError> {
    let mut rows: Vec<Row> = Vec::new();
    for (i, text) in console.lines().enumerate() {
        let mut words = text.split_whitespace();
        if words.next() != Some("row") {
            continue;
        }
        let bad = |why| IcountError::Parse {
            line: i + 1,
            why,
            text: text.to_string(),
        };
        let name = words.next().ok_or_else(|| bad("missing name"))?.to_string();
        let baseline = words.next().ok_or_else(|| bad("missing baseline"))?;
        let calls: u32 = words
            .next()
            .and_then(|w| w.parse().ok())
            .ok_or_else(|| bad("bad call count"))?;
        let ticks: u32 = words
            .next()
            .and_then(|w| w.parse().ok())
            .ok_or_else(|| bad("bad tick count"))?;
        if calls == 0 {
            return Err(bad("zero calls"));
        }
        let instructions = f64::from(ticks) / TICKS_PER_INSTRUCTION / f64::from(calls);
        let (baseline, speedup) = if baseline == "-" {
            (None, None)
        } else {
            let base = rows.iter().find(|r| r.name == baseline).ok_or_else(|| {
                IcountError::UnknownBaseline {
                    row: name.clone(),
                    baseline: baseline.to_string(),
                }
            })?;
            (
                Some(baseline.to_string()),
                Some(base.instructions / instructions),
            )
        };
        rows.push(Row {
            name,
            baseline,
            calls,
            ticks,
            instructions,
            speedup,
        });
    }
    Ok(rows)
}

/// The table region the bench's per-frame rows run on: the shipped
/// `humanoid16` rig (3 parameters, 4 goals) and a 5×5×5 grid over the hand
/// parameters whose samples are the rest pose.
pub fn bench_region() -> Result<Vec<u8>, IcountError> {
    let path = bundled("rigs/humanoid16.toml")?;
    let rig = rigfile::load(&path).map_err(|e| IcountError::Region(e.to_string()))?;
    let blob = rigfile::to_blob(&rig).map_err(|e| IcountError::Region(e.to_string()))?;
    let axes = [
        ("hand_x", -0.3, 0.15, 5),
        ("hand_y", -0.3, 0.15, 5),
        ("hand_z", -0.1, 0.15, 5),
    ];
    let table = perform::rest_grid(&rig, &axes).map_err(|e| IcountError::Region(e.to_string()))?;
    let layered = layered_bench_region(&rig, &table)?;
    // The nested region before the table, so that the table stays the
    // region's last blob.
    let entries = [
        region::Entry::rig(&blob),
        region::Entry {
            kind: region::EntryKind::NESTED,
            bytes: &layered,
        },
        region::Entry::table(&table),
    ];
    let mut out = vec![0u8; region::len(&entries).map_err(|e| IcountError::Region(e.to_string()))?];
    let n = region::write(&entries, &mut out).map_err(|e| IcountError::Region(e.to_string()))?;
    out.truncate(n);
    Ok(out)
}

/// The bench's two-layer region (nested in [`bench_region`] as
/// [`region::EntryKind::NESTED`], which the live loop ignores): the same
/// rig, the walk clip table built from the bundled
/// `data/builds/walk_humanoid16.toml` on the legs, and the rest grid `grid`
/// on the right arm, as `marionette demo --layers` lays them out
/// ([`crate::cmd::demo::layered_region`]).
pub fn layered_bench_region(rig: &rigfile::RigFile, grid: &[u8]) -> Result<Vec<u8>, IcountError> {
    let spec = bundled("data/builds/walk_humanoid16.toml")?;
    let walk =
        crate::cmd::demo::build_table(&spec).map_err(|e| IcountError::Region(e.to_string()))?;
    crate::cmd::demo::layered_region(rig, grid, &walk.blob, 2.0)
        .map_err(|e| IcountError::Region(e.to_string()))
}

/// The path of a file built into marionette (see [`crate::bundle`]).
fn bundled(rel: &str) -> Result<std::path::PathBuf, IcountError> {
    crate::bundle::file(std::path::Path::new(rel))
        .ok_or_else(|| IcountError::Region(format!("{rel} is not built into marionette")))?
        .map_err(|e| IcountError::Qemu(QemuError::Io(e)))
}

/// Runs the bench firmware (built into marionette) under `-icount` and returns its
/// console output.
pub fn run_bench() -> Result<String, IcountError> {
    let elf = qemu::firmware_elf("bench")?;
    let mut region = tempfile::NamedTempFile::new().map_err(QemuError::Io)?;
    std::io::Write::write_all(&mut region, &bench_region()?).map_err(QemuError::Io)?;
    let config = Config {
        icount: true,
        serial: false,
        tables: Some(region.path().to_path_buf()),
        timeout: Duration::from_secs(300),
        ..Config::new(elf)
    };
    let out = qemu::run(&config, &[])?;
    if out.status != Some(0) {
        return Err(IcountError::Status(out.status));
    }
    Ok(out.console)
}

/// The deepest stack of the `perform` firmware, bytes: the first `frames`
/// time steps of the bundled tracker recording performed on the bench's
/// table region (the whole live loop, fail-safe easing included).
pub fn perform_stack(frames: usize) -> Result<Option<u32>, IcountError> {
    perform_stack_on(&bench_region()?, frames)
}

/// [`perform_stack`] on the bench's two-layer region
/// ([`layered_bench_region`]).
pub fn perform_stack_layers(frames: usize) -> Result<Option<u32>, IcountError> {
    let bench = bench_region()?;
    let nested = region::directory(&bench)
        .ok()
        .and_then(|d| d.find(region::EntryKind::NESTED, 0))
        .ok_or_else(|| IcountError::Region("the bench region nests no layered region".into()))?;
    perform_stack_on(nested.bytes, frames)
}

/// [`perform_stack`] on the table region `region`.
fn perform_stack_on(region: &[u8], frames: usize) -> Result<Option<u32>, IcountError> {
    let recording = bundled("data/recordings/reach_hdm05_007.csv")?;
    let samples = crate::import::csv::read_tracker_csv(&recording)?;
    let mut all = perform::frames(&samples)?;
    all.truncate(frames);
    let session = perform::session(&all)?;
    // Channels per output frame: as many as the core's loop drives.
    let channels = Performer::new(&Region::parse(region), &mut SolverState::new())
        .targets()
        .len();
    let mut file = tempfile::NamedTempFile::new().map_err(QemuError::Io)?;
    std::io::Write::write_all(&mut file, region).map_err(QemuError::Io)?;
    let (run, _) = perform::emulate(
        file.path(),
        &session,
        channels,
        all.len(),
        perform::Pacing::AsFastAsPossible,
        Duration::ZERO,
    )?;
    Ok(run.board_stack)
}

/// Where the `replay` firmware reads the session in the table region
/// (`firmware/src/bin/replay.rs`).
pub const REPLAY_SESSION_OFFSET: usize = 0x8_0000;

/// The instructions of one tracker frame of a replayed session, by stage.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct FrameCost {
    /// The frame's sequence number.
    pub seq: u32,
    /// Receiving and decoding.
    pub decode: f64,
    /// The sensor map.
    pub map: f64,
    /// Synthesis.
    pub synth: f64,
    /// Solving.
    pub solve: f64,
    /// The servo map.
    pub servo: f64,
    /// The whole frame in the core's stage counts.
    pub total: f64,
    /// The whole call of the performer that handled the frame.
    pub receive: f64,
}

/// Runs a session through the live loop on the emulated board
/// (`firmware/src/bin/replay.rs`), with the solver's budget per frame
/// (`None`: the loop's own), and returns the instructions of every tracker
/// frame that drove the servos, in order.
pub fn replay(
    region: &[u8],
    session: &[perform::Sent],
    budget: Option<Budget>,
) -> Result<Vec<FrameCost>, IcountError> {
    if region.len() > REPLAY_SESSION_OFFSET {
        return Err(IcountError::Region(format!(
            "the region is {} bytes; the replay firmware reads at most {REPLAY_SESSION_OFFSET}",
            region.len()
        )));
    }
    let mut image = region.to_vec();
    image.resize(REPLAY_SESSION_OFFSET, 0);
    image.extend_from_slice(b"RPLY");
    // The loop's own budget: both words u32::MAX.
    let budget = budget.unwrap_or(Budget::uniform(u32::MAX));
    image.extend_from_slice(&budget.plain().to_le_bytes());
    image.extend_from_slice(&budget.adjusted().to_le_bytes());
    image.extend_from_slice(
        &u32::try_from(session.len())
            .unwrap_or(u32::MAX)
            .to_le_bytes(),
    );
    for m in session {
        let len = u16::try_from(m.bytes.len())
            .map_err(|_| IcountError::Region("a message longer than 65535 bytes".into()))?;
        image.extend_from_slice(&m.time_us.to_le_bytes());
        image.extend_from_slice(&len.to_le_bytes());
        image.extend_from_slice(&m.bytes);
    }
    if image.len() > qemu::TABLE_REGION_LEN {
        return Err(IcountError::Region(format!(
            "the session does not fit the emulated table region ({} bytes)",
            image.len()
        )));
    }
    let elf = qemu::firmware_elf("replay")?;
    let mut file = tempfile::NamedTempFile::new().map_err(QemuError::Io)?;
    std::io::Write::write_all(&mut file, &image).map_err(QemuError::Io)?;
    let config = Config {
        icount: true,
        serial: false,
        tables: Some(file.path().to_path_buf()),
        timeout: Duration::from_secs(600),
        ..Config::new(elf)
    };
    let out = qemu::run(&config, &[])?;
    if out.status != Some(0) {
        return Err(IcountError::Status(out.status));
    }
    parse_frames(&out.console)
}

/// Parses the `frame` lines of the replay firmware.
pub fn parse_frames(console: &str) -> Result<Vec<FrameCost>, IcountError> {
    let mut frames = Vec::new();
    for (i, text) in console.lines().enumerate() {
        let mut words = text.split_whitespace();
        if words.next() != Some("frame") {
            continue;
        }
        let v: Vec<u32> = words
            .map(str::parse)
            .collect::<Result<_, _>>()
            .map_err(|_| IcountError::Parse {
                line: i + 1,
                why: "not a number",
                text: text.to_string(),
            })?;
        let [seq, decode, map, synth, solve, servo, total, receive] = v[..] else {
            return Err(IcountError::Parse {
                line: i + 1,
                why: "not eight numbers",
                text: text.to_string(),
            });
        };
        let i = |t: u32| f64::from(t) / TICKS_PER_INSTRUCTION;
        frames.push(FrameCost {
            seq,
            decode: i(decode),
            map: i(map),
            synth: i(synth),
            solve: i(solve),
            servo: i(servo),
            total: i(total),
            receive: i(receive),
        });
    }
    Ok(frames)
}

/// Runs the bench firmware (built into marionette) under `-icount` and returns its rows.
pub fn measure() -> Result<Vec<Row>, IcountError> {
    parse(&run_bench()?)
}

/// The deepest stack the bench reported (`stack <bytes>` line), if any.
#[must_use]
pub fn stack_bytes(console: &str) -> Option<u32> {
    console
        .lines()
        .find_map(|l| l.strip_prefix("stack ")?.trim().parse().ok())
}

/// Flash and RAM use of a firmware ELF.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Footprint {
    /// Code and read-only data in flash (`.vector_table`, `.text`, `.rodata`), bytes.
    pub text: u64,
    /// Initialised statics (`.data`: in flash and in RAM), bytes.
    pub data: u64,
    /// Zeroed statics (`.bss`, `.uninit`), bytes.
    pub bss: u64,
}

/// Reads the section sizes of a firmware ELF.
pub fn footprint(elf: &std::path::Path) -> Result<Footprint, IcountError> {
    use object::{Object, ObjectSection};
    let bytes = std::fs::read(elf).map_err(QemuError::Io)?;
    let file = object::File::parse(&*bytes)
        .map_err(|e| IcountError::Region(format!("{}: {e}", elf.display())))?;
    let mut f = Footprint::default();
    for section in file.sections() {
        match section.name().unwrap_or("") {
            ".vector_table" | ".text" | ".rodata" => f.text += section.size(),
            ".data" => f.data += section.size(),
            ".bss" | ".uninit" => f.bss += section.size(),
            _ => {}
        }
    }
    Ok(f)
}

/// Formats rows as a Markdown table.
#[must_use]
pub fn table(rows: &[Row]) -> String {
    let mut s = String::from(
        "| region | instructions per call | calls | baseline | speed-up vs baseline |\n\
         |---|---:|---:|---|---:|\n",
    );
    for r in rows {
        let base = r.baseline.as_deref().unwrap_or("");
        let ratio = r.speedup.map(|x| format!("{x:.1}×")).unwrap_or_default();
        s.push_str(&format!(
            "| {} | {:.0} | {} | {} | {} |\n",
            r.name, r.instructions, r.calls, base, ratio
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_parse_with_ratio_against_the_baseline() {
        let text = "overhead 12\nrow a - 10 3200\nnoise\nrow b a 10 320\nend\n";
        let rows = parse(text).unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[0].instructions, 100.0);
        assert_eq!(rows[1].instructions, 10.0);
        assert_eq!(rows[1].speedup, Some(10.0));
    }

    #[test]
    fn bad_rows_name_their_line() {
        let err = parse("row a - x 1\n").unwrap_err().to_string();
        assert!(err.contains("line 1"), "{err}");
        let err = parse("row b a 1 1\n").unwrap_err().to_string();
        assert!(err.contains("baseline a"), "{err}");
    }
}
