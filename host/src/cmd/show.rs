//! `marionette show build TAKE… -o show.bin`: a show from takes, for a
//! board to play from flash with no host (see [`crate::show`] and
//! docs/show.md).

use super::CmdError;
use crate::take::Take;
use std::path::PathBuf;

/// Arguments of `marionette show`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// What to do.
    #[command(subcommand)]
    pub action: Action,
}

/// The `show` subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum Action {
    /// Build a show from one or more takes (played one after another).
    Build(BuildArgs),
    /// Start (or `--stop`) the show flashed on a board, over its tracker link.
    Play(PlayArgs),
}

/// Arguments of `marionette show play`.
#[derive(clap::Args, Debug)]
pub struct PlayArgs {
    /// The board's tracker serial port.
    #[arg(long)]
    pub port: String,
    /// Baud rate of the tracker link.
    #[arg(long, default_value_t = 921_600)]
    pub baud: u32,
    /// Stop the show instead.
    #[arg(long)]
    pub stop: bool,
}

/// Arguments of `marionette show build`.
#[derive(clap::Args, Debug)]
pub struct BuildArgs {
    /// The takes, in playing order (all performed with the same rig and tables).
    #[arg(required = true)]
    pub takes: Vec<PathBuf>,
    /// The show blob to write.
    #[arg(short, long)]
    pub out: PathBuf,
    /// Also write the table region with the show beside the rig and
    /// tables (what `emulate`/`flash` load).
    #[arg(long)]
    pub region: Option<PathBuf>,
    /// The error bound, µs: no decoded target is further than this from
    /// the take's (a multiple of 0.25).
    #[arg(long, default_value_t = 1.0)]
    pub bound_us: f64,
    /// Start again after the last frame.
    #[arg(long = "loop")]
    pub looping: bool,
    /// Play at boot (otherwise only on a trigger).
    #[arg(long)]
    pub at_boot: bool,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Runs a `show` subcommand.
pub fn run(args: &Args) -> Result<(), CmdError> {
    match &args.action {
        Action::Build(a) => build(a),
        Action::Play(a) => play(a),
    }
}

/// Says `Hello` until the board answers, then sends `Show { play }` and
/// waits for its `Ack`.
fn play(args: &PlayArgs) -> Result<(), CmdError> {
    use marionette_core::wire::{Command, CommandKind, Hello, Message, PROTOCOL_VERSION};
    use std::io::Write as _;
    use std::time::Duration;
    let name = &args.port;
    let mut port = serialport::new(name, args.baud)
        .timeout(Duration::from_millis(50))
        .open()
        .map_err(|e| format!("{name}: {e}"))?;
    let reader = port.try_clone().map_err(|e| format!("{name}: {e}"))?;
    let replies = super::stream::Replies::spawn(reader);
    let hello = crate::perform::encode(&Message::Hello(Hello {
        protocol_version: PROTOCOL_VERSION,
    }))?;
    let mut answered = false;
    for _ in 0..5 {
        port.write_all(&hello).map_err(|e| format!("{name}: {e}"))?;
        let got = replies.wait_for(Duration::from_secs(1), |m| match m {
            Message::Status(s) if s.request_seq.is_none() => Some(()),
            _ => None,
        });
        if got.is_some() {
            answered = true;
            break;
        }
    }
    if !answered {
        return Err(format!("{name}: no answer from the board in 5 s").into());
    }
    let command = Message::Command(Command {
        seq: 1,
        kind: CommandKind::Show { play: !args.stop },
    });
    port.write_all(&crate::perform::encode(&command)?)
        .map_err(|e| format!("{name}: {e}"))?;
    let ack = replies.wait_for(Duration::from_secs(2), |m| match m {
        Message::Ack(a) if a.seq == 1 => Some(a.ok),
        _ => None,
    });
    if ack == Some(false) {
        // Why: the board's Status after the refusal.
        let ask = Message::Command(Command {
            seq: 2,
            kind: CommandKind::RequestStatus,
        });
        port.write_all(&crate::perform::encode(&ask)?)
            .map_err(|e| format!("{name}: {e}"))?;
        let _ = replies.wait_for(Duration::from_secs(2), |m| match m {
            Message::Status(s) if s.request_seq == Some(2) => Some(()),
            _ => None,
        });
    }
    let show = crate::refusal::ShowReport::of(&replies.finish());
    if let Some(line) = show
        .as_ref()
        .and_then(crate::refusal::ShowReport::refusal_line)
    {
        return Err(format!("{name}: {line}").into());
    }
    match ack {
        Some(true) => {
            println!(
                "{name}: show {}",
                if args.stop { "stopped" } else { "playing" }
            );
            Ok(())
        }
        Some(false) => Err(format!(
            "{name}: the board refused: it is armed, or its region holds no show for its rig"
        )
        .into()),
        None => Err(format!("{name}: the board did not answer the command within 2 s").into()),
    }
}

fn build(args: &BuildArgs) -> Result<(), CmdError> {
    let quarter = args.bound_us * 4.0;
    if !(quarter.is_finite() && (0.0..=f64::from(u16::MAX)).contains(&quarter)) {
        return Err(format!("--bound-us {}: 0 to 16383.75", args.bound_us).into());
    }
    let bound = quarter.floor() as u16;
    let takes = args
        .takes
        .iter()
        .map(|p| Take::load(p))
        .collect::<Result<Vec<_>, _>>()?;
    let inputs: Vec<(&str, &std::path::Path)> =
        args.takes.iter().map(|p| ("a take", p.as_path())).collect();
    let (blob, report) = crate::show::build(&takes, bound, args.looping, args.at_boot)?;
    crate::save::save(&args.out, &blob, &inputs)?;
    if let (Some(path), Some(first)) = (&args.region, takes.first()) {
        let region = crate::show::with_show(&first.region, &blob)?;
        crate::save::save(path, &region, &inputs)?;
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "show {}: {} frames ({:.2} s at {} µs), {} of {} channels driven, {} keys; \
             {} bytes (raw {} bytes, {:.1} %); bound {} µs, worst {} µs{}{}",
            args.out.display(),
            report.frames,
            report.seconds,
            report.period_us,
            report.channels[1],
            report.channels[0],
            report.keys,
            report.show_bytes,
            report.raw_bytes,
            100.0 * report.show_bytes as f64 / report.raw_bytes.max(1) as f64,
            f64::from(report.bound_quarter_us) / 4.0,
            f64::from(report.worst_quarter_us) / 4.0,
            if report.looping { ", loops" } else { ", once" },
            if report.at_boot {
                ", plays at boot"
            } else {
                ""
            },
        );
    }
    Ok(())
}
