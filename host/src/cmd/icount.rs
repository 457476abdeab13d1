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

/// Time steps of the bundled recording performed to measure the `perform`
/// firmware's stack.
const PERFORM_FRAMES: usize = 500;

/// Runs the bench firmware (built into marionette) under `-icount` and prints its rows.
pub fn run(args: &Args) -> Result<(), CmdError> {
    let console = icount::run_bench()?;
    let rows = icount::parse(&console)?;
    let perform = icount::footprint(&crate::qemu::firmware_elf("perform")?)?;
    let stack = icount::stack_bytes(&console);
    let perform_stack = icount::perform_stack(PERFORM_FRAMES)?;
    let layers_stack = icount::perform_stack_layers(PERFORM_FRAMES)?;
    if args.json {
        let doc = serde_json::json!({
            "rows": rows,
            "perform_footprint": perform,
            "perform_stack_bytes": perform_stack,
            "perform_stack_layers_bytes": layers_stack,
            "bench_stack_bytes": stack,
        });
        println!("{}", serde_json::to_string_pretty(&doc)?);
    } else {
        println!(
            "Instruction counts on QEMU mps2-an386 (Cortex-M4F), -icount shift=7; \
             instructions, not cycles.\n"
        );
        print!("{}", icount::table(&rows));
        let show = |s: Option<u32>| s.map_or("?".into(), |s| s.to_string());
        println!(
            "\nperform firmware: {} B flash (text + rodata + vectors), {} B data, {} B bss; \
             deepest stack {} B over {PERFORM_FRAMES} frames of the bundled recording \
             ({} B with two layers); deepest stack in the bench: {} B",
            perform.text,
            perform.data,
            perform.bss,
            show(perform_stack),
            show(layers_stack),
            show(stack)
        );
    }
    Ok(())
}
