//! `marionette flash`: the firmware ELF and/or the table region (rig +
//! tables) onto the board with probe-rs (see [`crate::flash`] for the plan
//! and its checks).
//!
//! The table region is either a region image (`region.bin` of `marionette
//! demo` or `emulate`), or made here from `--rig RIG.toml` and a table blob
//! of `marionette build` with the core's region writer. Before anything is
//! written it is read as the board will read it, and refused with the
//! board's reason if the board would not arm with it (`--no-check` flashes
//! it anyway). After writing, the region is read back and checked again.
//!
//! `--dry-run` uses no probe: it prints the plan, checks it against the
//! board layout and the chip's built-in memory map, and shows what the board
//! would read (the bytes probe-rs stages, over erased flash).

use super::CmdError;
#[cfg(feature = "flash")]
use crate::flash::Options;
use crate::flash::{self, BLACKPILL, DEFAULT_CHIP, FlashError};
use crate::rigfile;
#[cfg(feature = "flash")]
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use marionette_core::{region, table};
#[cfg(feature = "flash")]
use probe_rs::flashing::{ProgressEvent, ProgressOperation};
use std::path::{Path, PathBuf};

/// Arguments of `marionette flash`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Firmware ELF (goes to the firmware region, 0x0800_0000).
    #[arg(long)]
    pub elf: Option<PathBuf>,
    /// The table region (0x0804_0000, 256 KiB): a region image (rig +
    /// tables, `region.bin` of `demo` or `emulate`), or with `--rig` a table
    /// blob from `marionette build` (repeat it for a rig with `[[layer]]`
    /// tables: table 0, 1, … in order).
    #[arg(long)]
    pub tables: Vec<PathBuf>,
    /// Rig file: the region is made of this rig and the `--tables` blobs.
    #[arg(long)]
    pub rig: Option<PathBuf>,
    /// probe-rs chip name.
    #[arg(long, default_value = DEFAULT_CHIP)]
    pub chip: String,
    /// Print and check the plan; use no probe, write nothing.
    #[arg(long)]
    pub dry_run: bool,
    /// Read the flash back after writing and compare.
    #[arg(long)]
    pub verify: bool,
    /// Flash the region even if the board would not arm with it.
    #[arg(long)]
    pub no_check: bool,
    /// Leave the core halted after flashing firmware (default: reset and run).
    #[arg(long)]
    pub no_reset: bool,
}

fn read(path: &Path) -> Result<Vec<u8>, CmdError> {
    std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()).into())
}

/// The table region image to flash: the file as given, or (with `--rig`)
/// the rig and the table blobs laid out by the core.
fn region_image(args: &Args) -> Result<Option<Vec<u8>>, CmdError> {
    let blobs = args
        .tables
        .iter()
        .map(|p| read(p))
        .collect::<Result<Vec<_>, _>>()?;
    let Some(rig_path) = &args.rig else {
        return match &blobs[..] {
            [] => Ok(None),
            [one] => Ok(Some(one.clone())),
            _ => Err(
                "without --rig, --tables takes one region image (give --rig to lay \
                      out several table blobs)"
                    .into(),
            ),
        };
    };
    let rig = rigfile::load(rig_path).map_err(|e| e.to_string())?;
    let mut given = Vec::new();
    for (p, t) in args.tables.iter().zip(&blobs) {
        if t.get(..4) != Some(&table::MAGIC[..]) {
            return Err(format!(
                "{}: with --rig, --tables takes a table blob of `marionette build` (this is {})",
                p.display(),
                if region::directory(t).is_ok() {
                    "already a region"
                } else {
                    "not a table blob"
                }
            )
            .into());
        }
        given.push(rigfile::Given {
            name: p.display().to_string(),
            blob: t,
        });
    }
    Ok(Some(rigfile::region(&rig, &given)?))
}

/// Plans, checks, and (unless `--dry-run`) writes.
pub fn run(args: &Args) -> Result<(), CmdError> {
    let elf = args.elf.as_deref().map(read).transpose()?;
    let tables = region_image(args)?;
    let plan = flash::plan(
        &BLACKPILL,
        elf.as_deref(),
        tables.as_deref(),
        !args.no_check,
    )
    .map_err(|e| match e {
        FlashError::WouldNotArm { .. } => format!("{e} (--no-check flashes it anyway)").into(),
        e => CmdError::from(e),
    })?;
    println!("{plan}");
    if let (Some(t), false) = (&tables, args.no_check) {
        println!("board view: {}", flash::check_region(&BLACKPILL, t)?);
    }
    write(args, &plan)
}

/// Checks the plan against the chip's memory map, then (unless
/// `--dry-run`) writes it through the first probe found.
#[cfg(feature = "flash")]
fn write(args: &Args, plan: &flash::Plan) -> Result<(), CmdError> {
    flash::check_chip(plan, &args.chip)?;
    if args.dry_run {
        report(
            flash::dry_read_back(plan, &args.chip)?.as_ref(),
            args.no_check,
        )?;
        println!(
            "dry run: the plan fits the board layout and {}'s memory map; no probe used, \
             nothing written",
            args.chip
        );
        return Ok(());
    }
    let mut session = flash::attach(&args.chip)?;
    let mut bars = Bars::new();
    let options = Options {
        verify: args.verify,
        dry_run: false,
    };
    let read_back = flash::program(&mut session, plan, options, |e| bars.event(e))?;
    bars.finish();
    report(read_back.as_ref(), args.no_check)?;
    if plan.has_firmware() && !args.no_reset {
        session
            .core(0)
            .and_then(|mut core| core.reset())
            .map_err(|e| format!("reset after flashing: {e}"))?;
    }
    println!(
        "flashed {} bytes to {}{}",
        plan.bytes(),
        args.chip,
        if args.verify { ", verified" } else { "" }
    );
    Ok(())
}

/// Without probe-rs: the plan has been checked against the board layout;
/// say how to get the chip checks and the writing.
#[cfg(not(feature = "flash"))]
fn write(_args: &Args, _plan: &flash::Plan) -> Result<(), CmdError> {
    Err(
        "this marionette was built without the `flash` feature (probe-rs), so it can plan and \
         check the image (above) but not check the chip or write it; build it with the default \
         features: `cargo run --release -p marionette-host -- flash ...` or \
         `cargo install --path host`"
            .into(),
    )
}

/// Prints what the board reads back; an error if it would not arm (unless
/// `--no-check`).
#[cfg(feature = "flash")]
fn report(read_back: Option<&flash::ReadBack>, no_check: bool) -> Result<(), CmdError> {
    let Some(rb) = read_back else {
        return Ok(());
    };
    let source = if rb.staged {
        "staged bytes over erased flash"
    } else {
        "read from the chip"
    };
    match (&rb.verdict, no_check) {
        (Ok(armed), _) => println!("read back ({source}): {armed}"),
        (Err(e), true) => println!("read back ({source}): {e}"),
        (Err(e), false) => return Err(format!("read back ({source}): {e}").into()),
    }
    Ok(())
}

/// Progress bars for probe-rs' flashing events, one per operation.
#[cfg(feature = "flash")]
struct Bars {
    multi: MultiProgress,
    bars: [Option<ProgressBar>; 4],
}

#[cfg(feature = "flash")]
impl Bars {
    fn new() -> Bars {
        Bars {
            multi: MultiProgress::new(),
            bars: [None, None, None, None],
        }
    }

    fn slot(op: ProgressOperation) -> (usize, &'static str) {
        match op {
            ProgressOperation::Fill => (0, "reading"),
            ProgressOperation::Erase => (1, "erasing"),
            ProgressOperation::Program => (2, "writing"),
            ProgressOperation::Verify => (3, "verifying"),
        }
    }

    fn bar(&mut self, op: ProgressOperation) -> &ProgressBar {
        let (i, name) = Self::slot(op);
        let multi = &self.multi;
        self.bars[i].get_or_insert_with(|| {
            let bar = multi.add(ProgressBar::new(0));
            if let Ok(style) = ProgressStyle::with_template(
                "{msg:>10} [{bar:40}] {bytes:>10}/{total_bytes:<10} {bytes_per_sec}",
            ) {
                bar.set_style(style.progress_chars("=> "));
            }
            bar.set_message(name);
            bar
        })
    }

    fn event(&mut self, event: ProgressEvent) {
        match event {
            ProgressEvent::AddProgressBar { operation, total } => {
                self.bar(operation).inc_length(total.unwrap_or(0));
            }
            ProgressEvent::Progress {
                operation, size, ..
            } => self.bar(operation).inc(size),
            ProgressEvent::Finished(op) => {
                let (_, name) = Self::slot(op);
                self.bar(op).finish_with_message(format!("{name} ok"));
            }
            ProgressEvent::Failed(op) => {
                let (_, name) = Self::slot(op);
                self.bar(op).abandon_with_message(format!("{name} FAILED"));
            }
            ProgressEvent::DiagnosticMessage { message } => {
                let _ = self.multi.println(message);
            }
            ProgressEvent::Started(_) | ProgressEvent::FlashLayoutReady { .. } => {}
        }
    }

    fn finish(&self) {
        for bar in self.bars.iter().flatten() {
            if !bar.is_finished() {
                bar.finish();
            }
        }
    }
}
