//! One module per `marionette` subcommand. Each has an `Args` (clap) and a
//! `run(&Args) -> Result<(), CmdError>`.

pub mod build;
pub mod calibrate;
pub mod demo;
pub mod emulate;
pub mod flash;
pub mod icount;
pub mod inspect;
pub mod live;
pub mod plot;
pub mod record;
pub mod render;
pub mod replay;
pub mod rig;
pub mod show;
pub mod sim;
pub mod solve;
pub mod stream;
pub mod synth;
pub mod take;
pub mod view;

/// An error from any subcommand, printed by `main` as `marionette: <error>`.
pub type CmdError = Box<dyn std::error::Error + Send + Sync>;
