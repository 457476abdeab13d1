//! `marionette flash`: the firmware ELF and/or the table blob onto the board
//! with probe-rs (see [`crate::flash`] for the plan and its checks).
//!
//! `--dry-run` uses no probe: it prints the plan and checks it against the
//! board layout and the chip's built-in memory map.

use super::CmdError;
use crate::flash::{self, BLACKPILL, DEFAULT_CHIP, FlashError, Options};
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use probe_rs::flashing::{ProgressEvent, ProgressOperation};
use std::path::{Path, PathBuf};

/// Arguments of `marionette flash`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Firmware ELF (goes to the firmware region, 0x0800_0000).
    #[arg(long)]
    pub elf: Option<PathBuf>,
    /// Table blob from `marionette build` (goes to the table region,
    /// 0x0804_0000, 256 KiB).
    #[arg(long)]
    pub tables: Option<PathBuf>,
    /// probe-rs chip name.
    #[arg(long, default_value = DEFAULT_CHIP)]
    pub chip: String,
    /// Print and check the plan; use no probe, write nothing.
    #[arg(long)]
    pub dry_run: bool,
    /// Read the flash back after writing and compare.
    #[arg(long)]
    pub verify: bool,
    /// Flash a blob even if it does not parse as a table.
    #[arg(long)]
    pub no_check: bool,
    /// Leave the core halted after flashing firmware (default: reset and run).
    #[arg(long)]
    pub no_reset: bool,
}

fn read(path: &Path) -> Result<Vec<u8>, CmdError> {
    std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()).into())
}

/// Plans, checks, and (unless `--dry-run`) writes.
pub fn run(args: &Args) -> Result<(), CmdError> {
    let elf = args.elf.as_deref().map(read).transpose()?;
    let tables = args.tables.as_deref().map(read).transpose()?;
    let plan = flash::plan(
        &BLACKPILL,
        elf.as_deref(),
        tables.as_deref(),
        !args.no_check,
    )
    .map_err(|e| match e {
        FlashError::BadTables(_) => format!("{e} (--no-check flashes it anyway)").into(),
        e => CmdError::from(e),
    })?;
    println!("{plan}");
    flash::check_chip(&plan, &args.chip)?;
    if args.dry_run {
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
    flash::program(&mut session, &plan, options, |e| bars.event(e))?;
    bars.finish();
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

/// Progress bars for probe-rs' flashing events, one per operation.
struct Bars {
    multi: MultiProgress,
    bars: [Option<ProgressBar>; 4],
}

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
