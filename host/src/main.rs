//! The `marionette` command-line tool.
use clap::Parser;

/// Marionette: drive a puppet rig from motion tables and live trackers.
#[derive(Parser)]
#[command(name = "marionette", version, about)]
struct Cli {}

fn main() {
    let _cli = Cli::parse();
}
