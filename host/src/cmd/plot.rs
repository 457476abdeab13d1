//! `marionette plot`: curves over time from a CSV file.
//!
//! The first column is time (`time_us`, `time_ms` or `time_s`), the others
//! numeric series, e.g. the servo targets `marionette sim`/`emulate` write
//! (`time_us,ch0,ch1,...`, pulses in µs). A tracker recording (a `sensor`
//! column) is split by sensor: one line per sensor and coordinate
//! (`sensor 0: x`). See [`crate::render::Series`].

use super::CmdError;
use crate::render::{self, PlotOptions, Series};
use std::path::PathBuf;

/// Arguments of `marionette plot`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The CSV file.
    pub csv: PathBuf,
    /// Output picture, `.png` or `.svg`.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Only these columns, in this order (comma-separated header names).
    #[arg(long, value_delimiter = ',')]
    pub columns: Vec<String>,
    /// Caption (default: the CSV file name).
    #[arg(long)]
    pub title: Option<String>,
    /// The vertical axis' label.
    #[arg(long, default_value = "value")]
    pub y_label: String,
    /// Width in pixels.
    #[arg(long, default_value_t = 1200)]
    pub width: u32,
    /// Height in pixels.
    #[arg(long, default_value_t = 700)]
    pub height: u32,
}

/// Reads the CSV, draws it and says where.
pub fn run(args: &Args) -> Result<(), CmdError> {
    crate::save::check(&args.output, &[("the CSV", args.csv.as_path())])?;
    let text =
        std::fs::read_to_string(&args.csv).map_err(|e| format!("{}: {e}", args.csv.display()))?;
    let mut series =
        Series::parse_csv(&text).map_err(|e| format!("{}: {e}", args.csv.display()))?;
    // A tracker recording: one line per sensor and coordinate, not the
    // sensor id drawn as a curve.
    if let Some(wide) = series.split_by("sensor") {
        series = wide;
    }
    if !args.columns.is_empty() {
        series
            .select(&args.columns)
            .map_err(|e| format!("{}: {e}", args.csv.display()))?;
    }
    let opt = PlotOptions {
        width: args.width,
        height: args.height,
        title: args
            .title
            .clone()
            .unwrap_or_else(|| match args.csv.file_name() {
                Some(name) => name.to_string_lossy().into_owned(),
                None => args.csv.display().to_string(),
            }),
        y_label: args.y_label.clone(),
    };
    render::plot(&series, &args.output, &opt)?;
    println!(
        "{}: {} series, {} samples",
        args.output.display(),
        series.columns.len(),
        series.time.len()
    );
    Ok(())
}
