//! The `marionette` command-line tool. Each subcommand lives in its own module
//! under `marionette_host::cmd`; this file only parses and dispatches.
use clap::{Parser, Subcommand};
use marionette_host::cmd;
use std::process::ExitCode;

/// Marionette: drive a puppet rig from motion tables and live trackers.
#[derive(Parser)]
#[command(
    name = "marionette",
    version,
    about,
    after_help = "Exit codes: 0 success; 1 error (bad input, I/O, board and native core disagree); \
                  2 bad command line; 3 the board never armed (its Status reason is printed); \
                  4 the board stopped on a fault; 130 quit on a signal (Ctrl-C, SIGTERM, SIGHUP; for `live`, `stream`, `replay --port` and `calibrate` the second one: the first stops them cleanly).\n\
                  File formats (goals, build spec, example set, rig, recording): docs/README.md."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// The demo: build the reach table, perform a real recording on the emulated board, draw it.
    Demo(cmd::demo::Args),
    /// Perform on the emulated board: boot the firmware on QEMU and stream to it.
    Emulate(cmd::emulate::Args),
    /// Instruction counts of the core on the emulated Cortex-M4F.
    Icount(cmd::icount::Args),
    /// Run the live loop natively on a tracker recording and write the servo curves.
    Sim(cmd::sim::Args),
    /// Stream a tracker recording to a real board over a serial port.
    Stream(cmd::stream::Args),
    /// Draw a pose and its goals in four views (front, side, top, perspective).
    Render(cmd::render::Args),
    /// Draw curves over time from a CSV file (time column first).
    Plot(cmd::plot::Args),
    /// Flash the firmware ELF and/or the table blob with probe-rs.
    Flash(cmd::flash::Args),
    /// Build a table blob from mocap or a JSON example set.
    Build(cmd::build::Args),
    /// Show a table blob's header, sizes and error bound.
    Inspect(cmd::inspect::Args),
    /// Synthesize a pose from a table blob at given parameters.
    Synth(cmd::synth::Args),
    /// Position a rig to meet weighted goals (JSON in, pose and distances out).
    Solve(cmd::solve::Args),
    /// Make a tracker recording (CSV) from a mocap clip: virtual trackers on its joints.
    Record(cmd::record::Args),
    /// Find a servo's limits from the keyboard on a board (or the emulated one) and write them into the rig file.
    Calibrate(cmd::calibrate::Args),
    /// Check a rig file (summary, hash, which boards can drive it, likely slips), or write one from a mocap skeleton (`--from-skeleton`).
    Rig(cmd::rig::Args),
    /// Perform from a live source (VMC / OSC over UDP) on the emulated or a real board.
    Live(cmd::live::Args),
    /// Takes: summarize (`info`), edit (`edit`), export curves and BVH (`export`).
    Take(cmd::take::Args),
    /// Send a take's input again to the emulated board or a serial port.
    Replay(cmd::replay::Args),
    /// Shows played from flash with no host: `build` one from takes.
    Show(cmd::show::Args),
    /// The demo watched live in the browser (`demo --view`; read-only, localhost by default).
    View(cmd::demo::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // Before any emulated board starts: a signal must end it too.
    if let Err(e) = marionette_host::interrupt::install() {
        eprintln!("marionette: {e}");
    }
    let result = match cli.command {
        Command::Demo(args) => cmd::demo::run(&args),
        Command::Emulate(args) => cmd::emulate::run(&args),
        Command::Icount(args) => cmd::icount::run(&args),
        Command::Sim(args) => cmd::sim::run(&args),
        Command::Stream(args) => cmd::stream::run(&args),
        Command::Render(args) => cmd::render::run(&args),
        Command::Plot(args) => cmd::plot::run(&args),
        Command::Flash(args) => cmd::flash::run(&args),
        Command::Build(args) => cmd::build::run(&args),
        Command::Inspect(args) => cmd::inspect::run(&args),
        Command::Synth(args) => cmd::synth::run(&args),
        Command::Solve(args) => cmd::solve::run(&args),
        Command::Record(args) => cmd::record::run(&args),
        Command::Calibrate(args) => cmd::calibrate::run(&args),
        Command::Rig(args) => cmd::rig::run(&args),
        Command::Live(args) => cmd::live::run(&args),
        Command::Take(args) => cmd::take::run(&args),
        Command::Replay(args) => cmd::replay::run(&args),
        Command::Show(args) => cmd::show::run(&args),
        Command::View(mut args) => {
            args.view.view = true;
            cmd::demo::run(&args)
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("marionette: {e}");
            match e.downcast_ref::<marionette_host::refusal::Stop>() {
                Some(stop) => ExitCode::from(stop.exit_code()),
                None => ExitCode::FAILURE,
            }
        }
    }
}
