//! `marionette take`: look at, edit and export takes (docs/take.md).
//!
//! - `take info TAKE`: a summary (`--json`).
//! - `take edit TAKE -o OUT`: trim, time-scale, smooth, cross-fade (see
//!   [`crate::take::edit`]); the edited take's outputs are the native
//!   core's on the edited input.
//! - `take export TAKE`: the servo curves as CSV, the solved figure as BVH.

use super::CmdError;
use crate::take::Take;
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
    }
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
         board: {} outputs driven by frames, {} easing, {} replies ({} telemetry)\n\
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
