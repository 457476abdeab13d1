//! Fits the whole-tree solver's cost model (`marionette_core::solve::cost`,
//! its `COST` array) to instruction counts on the emulated Cortex-M4F.
//!
//! Run with `cargo run --release -p marionette-tests --example fit_cost`
//! (needs `qemu-system-arm` and the `thumbv7em-none-eabihf` target, as the
//! tests do).
//!
//! It runs the `cost` firmware binary (`firmware/src/bin/cost.rs`) twice on
//! QEMU under `-icount`, with the bench's table region: as built into
//! `marionette-host` (the instructions of each solve: its ticks over
//! `icount::TICKS_PER_INSTRUCTION`), and built with the `cost-terms` feature
//! in its own folder `target/cost-terms` (a nested `cargo build --release
//! --bin cost` in `firmware/`), which also prints the units of each term.
//! Counting the units costs instructions, hence the two runs; they solve the
//! same problems alike, which is checked (ids, iterations, convergence, and
//! each solve's `work` equal to the current `COST` times its units). A line
//! per solve:
//!
//! ```text
//! cost <id> <ticks> <work> <iterations> <converged> [<units of each term...>]
//! ```
//!
//! Then it solves the linear program "the smallest total relative excess
//! `Σᵢ (c·uᵢ)/mᵢ` with every solve bounded, `c·uᵢ ≥ mᵢ`, `c ≥ 0`" (module
//! `fit`, by the simplex method of module `simplex`), rounds each
//! coefficient up to an integer, checks that every solve is still bounded
//! (raising a coefficient where one is not, and saying so), and prints the
//! new `COST` array as Rust source beside the ratios counted/measured
//! (least, median, greatest) of the current and the new coefficients. A
//! term no solve has a unit of keeps its current coefficient. Nothing is
//! written: paste the array into `shared/src/solve/cost.rs`.
//!
//! The number of terms is `marionette_core::solve::cost::TERMS`; the
//! firmware prints as many units per solve, from the same source tree.
//!
//! The modules' unit tests (hand-worked programs) run with `cargo test -p
//! marionette-tests --example fit_cost`, and with the rest of the package's
//! tests.

#[path = "fit_cost/fit.rs"]
mod fit;
#[path = "fit_cost/simplex.rs"]
mod simplex;

use fit::{Bump, Solve};
use marionette_core::solve::cost::{COST, TERMS};
use marionette_host::{icount, qemu};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// The firmware's target triple (`firmware/.cargo/config.toml`).
const TARGET: &str = "thumbv7em-none-eabihf";

/// Environment of the outer cargo that must not reach the firmware's build
/// (flags, target and wrappers for the host build; as in `host/build.rs`).
const OUTER_ENV: [&str; 11] = [
    "RUSTFLAGS",
    "CARGO_ENCODED_RUSTFLAGS",
    "CARGO_BUILD_RUSTFLAGS",
    "CARGO_BUILD_TARGET",
    "CARGO_TARGET_DIR",
    "CARGO_BUILD_TARGET_DIR",
    "RUSTC",
    "RUSTC_WRAPPER",
    "RUSTC_WORKSPACE_WRAPPER",
    "CLIPPY_ARGS",
    "RUSTDOC",
];

/// Leading fields of a `cost` line before the units: id, ticks, work,
/// iterations, converged.
const FIELDS: [&str; 5] = ["id", "ticks", "work", "iterations", "converged"];

/// What can go wrong.
#[derive(Debug, thiserror::Error)]
enum Error {
    /// Cargo could not be started or the build failed.
    #[error("building the cost firmware in {dir}: {why}")]
    Build {
        /// The firmware folder.
        dir: PathBuf,
        /// What failed.
        why: String,
    },
    /// The emulator failed.
    #[error(transparent)]
    Qemu(#[from] qemu::QemuError),
    /// The bench's region could not be made.
    #[error(transparent)]
    Icount(#[from] icount::IcountError),
    /// The firmware did not exit with 0.
    #[error("the cost firmware exited with status {status:?}; its console ended:\n{tail}")]
    Status {
        /// The exit status.
        status: Option<i32>,
        /// The console's last lines.
        tail: String,
    },
    /// A console line did not parse.
    #[error("{run} run, console line {line}, field {field}: {why}: {text:?}")]
    Parse {
        /// The run.
        run: &'static str,
        /// 1-based line of the console.
        line: usize,
        /// The field.
        field: String,
        /// What is wrong.
        why: &'static str,
        /// The line.
        text: String,
    },
    /// The two runs did not solve alike.
    #[error("the two runs disagree: {0}")]
    Runs(String),
    /// A coefficient does not fit a `u32`.
    #[error("term {term}: coefficient {value} does not fit a u32")]
    Overflow {
        /// The term.
        term: usize,
        /// The coefficient.
        value: u64,
    },
    /// The fit failed.
    #[error(transparent)]
    Fit(#[from] fit::FitError),
    /// A file could not be written.
    #[error("{0}")]
    Io(#[from] std::io::Error),
}

fn main() {
    if let Err(e) = run() {
        eprintln!("fit_cost: {e}");
        std::process::exit(1);
    }
}

fn run() -> Result<(), Error> {
    let start = Instant::now();
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let terms_elf = build(&repo)?;
    let built = start.elapsed();
    let plain = parse(&measure(&qemu::firmware_elf("cost")?)?, "cost")?;
    let terms = parse(&measure(&terms_elf)?, "cost with cost-terms")?;
    let measured = start.elapsed();
    let solves = pair(&plain, &terms)?;
    println!(
        "{} solves ({} failed), {TERMS} terms; firmware built in {:.0} s, both runs in {:.0} s",
        solves.len(),
        plain.failed,
        built.as_secs_f64(),
        (measured - built).as_secs_f64()
    );
    let mut slower: Vec<f64> = (plain.lines.iter().zip(&terms.lines))
        .map(|(p, t)| f64::from(t.head[1]) / f64::from(p.head[1]))
        .collect();
    slower.sort_by(f64::total_cmp);
    if let Some(median) = slower.get(slower.len() / 2) {
        println!("instructions with cost-terms / without, per solve: median {median:.2}");
    }
    let fitted = fit::fit(&solves, TERMS)?;
    let mut cost = fit::round_up(&fitted.exact);
    for &j in &fitted.unused {
        cost[j] = u64::from(COST[j]);
    }
    let bumps = fit::bound(&mut cost, &solves, &fitted.weight);
    report(&solves, &fitted, &cost, &bumps)?;
    println!(
        "fitted in {:.1} s",
        (start.elapsed() - measured).as_secs_f64()
    );
    Ok(())
}

/// Builds the `cost` binary with `cost-terms` into `target/cost-terms` and
/// returns its ELF.
fn build(repo: &Path) -> Result<PathBuf, Error> {
    let dir = repo.join("firmware");
    let target_dir = repo.join("target").join("cost-terms");
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut cmd = Command::new(cargo);
    cmd.current_dir(&dir)
        .args([
            "build",
            "--release",
            "--bin",
            "cost",
            "--features",
            "cost-terms",
        ])
        .arg("--target-dir")
        .arg(&target_dir);
    for var in OUTER_ENV {
        cmd.env_remove(var);
    }
    let failed = |why: String| Error::Build {
        dir: dir.clone(),
        why,
    };
    let status = cmd.status().map_err(|e| failed(e.to_string()))?;
    if !status.success() {
        return Err(failed(format!("cargo exited with {status}")));
    }
    Ok(target_dir.join(TARGET).join("release").join("cost"))
}

/// Runs `elf` on QEMU under `-icount` with the bench's region; its console.
fn measure(elf: &Path) -> Result<String, Error> {
    let mut region = tempfile::NamedTempFile::new()?;
    std::io::Write::write_all(&mut region, &icount::bench_region()?)?;
    let config = qemu::Config {
        icount: true,
        serial: false,
        tables: Some(region.path().to_path_buf()),
        timeout: Duration::from_secs(900),
        ..qemu::Config::new(elf)
    };
    let out = qemu::run(&config, &[])?;
    if out.status != Some(0) {
        let lines: Vec<&str> = out.console.lines().collect();
        let tail = lines[lines.len().saturating_sub(10)..].join("\n");
        return Err(Error::Status {
            status: out.status,
            tail: format!("{tail}\n{}", out.diagnostics),
        });
    }
    Ok(out.console)
}

/// One `cost` line.
struct Line {
    /// 1-based line of the console.
    line: usize,
    /// The leading fields ([`FIELDS`]).
    head: [u32; FIELDS.len()],
    /// The units of each term (none without `cost-terms`).
    units: Vec<u32>,
}

/// The `cost` lines of one run, and how many solves failed.
struct Run {
    /// The run's name, for errors.
    name: &'static str,
    lines: Vec<Line>,
    failed: usize,
}

/// Reads the `cost` lines of run `name` and counts its `failed` ones.
fn parse(console: &str, name: &'static str) -> Result<Run, Error> {
    let mut run = Run {
        name,
        lines: vec![],
        failed: 0,
    };
    for (i, text) in console.lines().enumerate() {
        let mut words = text.split_whitespace();
        match words.next() {
            Some("cost") => {}
            Some("failed") => {
                run.failed += 1;
                continue;
            }
            _ => continue,
        }
        let bad = |field: String, why| Error::Parse {
            run: name,
            line: i + 1,
            field,
            why,
            text: text.to_string(),
        };
        let mut values = vec![];
        for (k, w) in words.enumerate() {
            let field = FIELDS
                .get(k)
                .map_or_else(|| format!("unit {}", k - FIELDS.len()), |f| f.to_string());
            values.push(w.parse::<u32>().map_err(|_| bad(field, "not a u32"))?);
        }
        let Some((head, units)) = values.split_first_chunk() else {
            return Err(bad(FIELDS[values.len()].to_string(), "missing"));
        };
        run.lines.push(Line {
            line: i + 1,
            head: *head,
            units: units.to_vec(),
        });
    }
    Ok(run)
}

/// The solves: instructions from the plain run (counting the units costs
/// instructions too), units from the `cost-terms` run. The two must have
/// solved alike: the same ids, iterations and convergence, and the plain
/// run's work must be the current `COST` times the units.
fn pair(plain: &Run, terms: &Run) -> Result<Vec<Solve>, Error> {
    let current: Vec<u64> = COST.iter().map(|&c| u64::from(c)).collect();
    if (plain.lines.len(), plain.failed) != (terms.lines.len(), terms.failed) {
        return Err(Error::Runs(format!(
            "{} solves ({} failed) in the {} run, {} ({} failed) in the {} run",
            plain.lines.len(),
            plain.failed,
            plain.name,
            terms.lines.len(),
            terms.failed,
            terms.name
        )));
    }
    let mut solves = vec![];
    for (p, t) in plain.lines.iter().zip(&terms.lines) {
        let [id, ticks, work, iterations, converged] = p.head;
        if t.units.len() != TERMS {
            return Err(Error::Runs(format!(
                "{} run, console line {}: {} units, but the model has {TERMS} terms (is the \
                 firmware built from this tree?)",
                terms.name,
                t.line,
                t.units.len()
            )));
        }
        if [t.head[0], t.head[3], t.head[4]] != [id, iterations, converged] {
            return Err(Error::Runs(format!(
                "{} run line {} (id, iterations, converged {:?}) and {} run line {} ({:?}) \
                 differ",
                plain.name,
                p.line,
                [id, iterations, converged],
                terms.name,
                t.line,
                [t.head[0], t.head[3], t.head[4]]
            )));
        }
        let model = fit::counted_int(&current, &t.units);
        if model != u64::from(work) {
            return Err(Error::Runs(format!(
                "solve {id}: the {} run counted {work}, but COST times the {} run's units is \
                 {model}",
                plain.name, terms.name
            )));
        }
        solves.push(Solve {
            id,
            instructions: f64::from(ticks) / icount::TICKS_PER_INSTRUCTION,
            units: t.units.clone(),
        });
    }
    Ok(solves)
}

/// Prints the per-term table, the bumps, the array and the ratios.
fn report(solves: &[Solve], fitted: &fit::Fit, cost: &[u64], bumps: &[Bump]) -> Result<(), Error> {
    println!(
        "linear program: {} pivots, mean counted/measured {:.4}",
        fitted.pivots, fitted.mean_ratio
    );
    println!("term  solves using it  current  fitted (exact)  new");
    for (j, (&c, exact)) in cost.iter().zip(&fitted.exact).enumerate() {
        let using = solves.iter().filter(|s| s.units[j] > 0).count();
        println!("{j:>4}  {using:>14}  {:>7}  {exact:>14.3}  {c:>4}", COST[j]);
    }
    for &j in &fitted.unused {
        println!(
            "term {j}: no solve has a unit of it; kept at its current {}",
            COST[j]
        );
    }
    for b in bumps {
        println!(
            "rounded up, solve {} was not bounded: term {} raised by {}",
            b.id, b.term, b.by
        );
    }
    let mut new = Vec::with_capacity(cost.len());
    for (term, &value) in cost.iter().enumerate() {
        new.push(u32::try_from(value).map_err(|_| Error::Overflow { term, value })?);
    }
    println!("\n{}", source(&new));
    let current: Vec<u64> = COST.iter().map(|&c| u64::from(c)).collect();
    for (name, c) in [("current", current.as_slice()), ("new", cost)] {
        if let Some([min, median, max]) = fit::ratios(c, solves) {
            let mean = solves
                .iter()
                .map(|s| fit::counted_int(c, &s.units) as f64 / s.instructions)
                .sum::<f64>()
                / solves.len() as f64;
            println!(
                "{name:>7} COST: counted/measured over {} solves: min {min:.3}, median \
                 {median:.3}, max {max:.3}, mean {mean:.4}",
                solves.len()
            );
        }
    }
    Ok(())
}

/// The `COST` item as rustfmt lays it out (values packed into lines of
/// fewer than 100 columns).
fn source(cost: &[u32]) -> String {
    let mut out = String::from("/// Instructions per unit of each term, in [`Term`] order.\n");
    out.push_str("pub const COST: [u32; TERMS] = [\n");
    let mut line = String::from("   ");
    for c in cost {
        let item = format!(" {c},");
        if line.len() + item.len() >= 100 {
            out.push_str(&line);
            out.push('\n');
            line = String::from("   ");
        }
        line.push_str(&item);
    }
    out.push_str(&line);
    out.push_str("\n];");
    out
}

#[cfg(test)]
mod tests {
    /// The array as rustfmt laid it out in `shared/src/solve/cost.rs`: a
    /// line that would reach 100 columns is wrapped.
    #[test]
    fn the_source_is_laid_out_as_rustfmt_does() {
        let cost = [
            3945, 10, 360, 0, 0, 175, 112, 184, 30, 60, 203, 60, 11, 802, 71, 205, 54, 40, 93, 24,
            100, 483, 183, 59, 33, 0, 0, 187,
        ];
        let want = "/// Instructions per unit of each term, in [`Term`] order.
pub const COST: [u32; TERMS] = [
    3945, 10, 360, 0, 0, 175, 112, 184, 30, 60, 203, 60, 11, 802, 71, 205, 54, 40, 93, 24, 100,
    483, 183, 59, 33, 0, 0, 187,
];";
        assert_eq!(super::source(&cost), want);
    }
}
