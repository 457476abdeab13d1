//! `marionette icount`: instruction counts on the emulated Cortex-M4F.

use super::CmdError;
use crate::icount;

/// Arguments of `marionette icount`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Print the rows as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Builds and runs the bench firmware under `-icount` and prints its rows.
pub fn run(args: &Args) -> Result<(), CmdError> {
    let rows = icount::measure()?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
    } else {
        println!(
            "Instruction counts on QEMU mps2-an386 (Cortex-M4F), -icount shift=7; \
             instructions, not cycles.\n"
        );
        print!("{}", icount::table(&rows));
    }
    Ok(())
}
