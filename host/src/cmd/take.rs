//! `marionette take`: look at, edit and export takes (docs/take.md).
//!
//! - `take info TAKE`: a summary (`--json`).
//! - `take edit TAKE -o OUT`: trim, time-scale, smooth, cross-fade (see
//!   [`crate::take::edit`]); the edited take's outputs are the native
//!   core's on the edited input.
//! - `take export TAKE`: the servo curves as CSV, the solved figure as BVH.

use super::CmdError;
use crate::take::Take;
use crate::take::edit::Input;
use crate::take::export;
use std::path::PathBuf;

/// Arguments of `marionette take`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// What to do.
    #[command(subcommand)]
    pub action: Action,
}

/// The `take` subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum Action {
    /// Summarize a take.
    Info(InfoArgs),
    /// Edit a take's input (applied in this order: trim, time-scale,
    /// smooth, cross-fade); its outputs become the native core's on it.
    Edit(EditArgs),
    /// Export the servo curves (CSV) and the solved figure (BVH).
    Export(ExportArgs),
}

/// Arguments of `marionette take edit`.
#[derive(clap::Args, Debug)]
pub struct EditArgs {
    /// The take to edit.
    pub take: PathBuf,
    /// The edited take.
    #[arg(short, long)]
    pub out: PathBuf,
    /// Keep only FROM,TO (seconds from the first tracker frame).
    #[arg(long, value_delimiter = ',', value_name = "FROM,TO")]
    pub trim: Option<Vec<f64>>,
    /// Multiply every time by this (2: half speed).
    #[arg(long)]
    pub time_scale: Option<f64>,
    /// Smooth this sensor (position and orientation).
    #[arg(long)]
    pub smooth_sensor: Vec<u8>,
    /// Smooth this parameter (index in the `Params` messages).
    #[arg(long)]
    pub smooth_param: Vec<usize>,
    /// The smoothing filter's natural frequency, Hz (critically damped,
    /// second order; docs/take.md).
    #[arg(long, default_value_t = 4.0)]
    pub hz: f64,
    /// Cross-fade into this take.
    #[arg(long)]
    pub crossfade: Option<PathBuf>,
    /// Where the cross-fade starts, seconds from the first frame.
    #[arg(long, default_value_t = 0.0)]
    pub at: f64,
    /// The cross-fade's length, seconds.
    #[arg(long, default_value_t = 0.5)]
    pub window: f64,
}

/// Arguments of `marionette take export`.
#[derive(clap::Args, Debug)]
pub struct ExportArgs {
    /// The take.
    pub take: PathBuf,
    /// Write the servo curves here (`time_us,ch0,…`, µs).
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Write the solved figure here (BVH, centimetres).
    #[arg(long)]
    pub bvh: Option<PathBuf>,
}

/// Arguments of `marionette take info`.
#[derive(clap::Args, Debug)]
pub struct InfoArgs {
    /// The take.
    pub take: PathBuf,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Runs a `take` subcommand.
pub fn run(args: &Args) -> Result<(), CmdError> {
    match &args.action {
        Action::Info(a) => info(a),
        Action::Edit(a) => edit(a),
        Action::Export(a) => export(a),
    }
}

fn edit(args: &EditArgs) -> Result<(), CmdError> {
    let take = Take::load(&args.take)?;
    let mut input = Input::of(&take);
    if let Some(t) = &args.trim {
        let [from, to] = t.as_slice() else {
            return Err("--trim FROM,TO: two numbers, seconds".into());
        };
        input.trim(*from, *to)?;
    }
    if let Some(k) = args.time_scale {
        input.scale(k)?;
    }
    for &id in &args.smooth_sensor {
        input.smooth_sensor(id, args.hz)?;
    }
    for &p in &args.smooth_param {
        input.smooth_param(p, args.hz)?;
    }
    if let Some(other) = &args.crossfade {
        let other_take = Take::load(other)?;
        if other_take.region != take.region {
            return Err(format!(
                "--crossfade {}: its rig and tables differ from {}'s",
                other.display(),
                args.take.display()
            )
            .into());
        }
        input.crossfade(&Input::of(&other_take), args.at, args.window)?;
    }
    let edited = input.take(&take.region)?;
    crate::save::check(&args.out, &[("the take", args.take.as_path())])?;
    edited.save(&args.out)?;
    let info = edited.info();
    println!(
        "edited take {}: {} tracker frames over {:.3} s, {} outputs",
        args.out.display(),
        info.sent.tracker_frames,
        info.seconds,
        info.frame_outputs + info.rest_outputs
    );
    Ok(())
}

fn export(args: &ExportArgs) -> Result<(), CmdError> {
    let take = Take::load(&args.take)?;
    let inputs = [("the take", args.take.as_path())];
    if let Some(path) = &args.csv {
        crate::save::save(path, export::curves_csv(&take).as_bytes(), &inputs)?;
        println!("servo curves: {}", path.display());
    }
    if let Some(path) = &args.bvh {
        crate::save::save(path, export::bvh(&take)?.as_bytes(), &inputs)?;
        println!("solved figure: {}", path.display());
    }
    if args.csv.is_none() && args.bvh.is_none() {
        return Err("take export: say what, --csv FILE and/or --bvh FILE".into());
    }
    Ok(())
}

fn info(args: &InfoArgs) -> Result<(), CmdError> {
    let take = Take::load(&args.take)?;
    let info = take.info();
    if args.json {
        println!("{}", serde_json::to_string_pretty(&info)?);
        return Ok(());
    }
    println!(
        "take {} (format {}, from {}): {:.3} s, rig {}, {} channels at {} µs\n\
         sent: {} hello, {} tracker frames, {} params, {} commands\n\
         board: {} outputs driven by frames, {} easing, {} reported by telemetry{}, {} replies \
         ({} telemetry)\n\
         region: {} bytes{}",
        args.take.display(),
        info.format_version,
        info.source,
        info.seconds,
        info.rig_hash.as_deref().unwrap_or("(none)"),
        info.channels,
        info.period_us,
        info.sent.hellos,
        info.sent.tracker_frames,
        info.sent.params,
        info.sent.commands,
        info.frame_outputs,
        info.rest_outputs,
        info.reported_outputs,
        if info.servo_link_seen {
            ""
        } else {
            " (a board on a port: its servo link not seen)"
        },
        info.replies,
        info.telemetry,
        info.region_bytes,
        if info.has_table {
            ", with a table"
        } else {
            ", no table"
        },
    );
    Ok(())
}
