//! Fits the whole-tree solver's cost model (`marionette_core::solve::cost`,
//! its `COST` array) to instruction counts on the emulated Cortex-M4F.
//!
//! Run with `cargo run --release -p marionette-tests --example fit_cost`
//! (needs `qemu-system-arm` and the `thumbv7em-none-eabihf` target, as the
//! tests do).
//!
//! It builds the `cost` firmware binary (`firmware/src/bin/cost.rs`) twice
//! with nested `cargo build --release --bin cost` in `firmware/`: as it
//! ships, in `firmware/target` (where `host/build.rs` builds it too), and
//! with the `cost-terms` feature, which also prints the units of each term,
//! in its own folder `target/cost-terms`. It runs both on QEMU under
//! `-icount` with the bench's table region. The instructions of each solve
//! come from the first (its ticks over `icount::TICKS_PER_INSTRUCTION`),
//! since counting the units costs instructions too; the units from the
//! second. The two must solve alike, which is checked (ids, failures,
//! iterations, convergence, and each solve's `work` equal to the current
//! `COST` times its units). A line per solve:
//!
//! ```text
//! cost <id> <ticks> <work> <iterations> <converged> [<units of each term...>]
//! ```
//!
//! Then it solves the linear program "the smallest total relative excess
//! `Σᵢ (c·uᵢ)/mᵢ` with every solve bounded with a margin,
//! `c·uᵢ ≥ (1 + margin)·mᵢ`, `c ≥ 0`" (`-- --margin P`, in percent;
//! default [`MARGIN`]) (module
//! `fit`, by the simplex method of module `simplex`), rounds each
//! coefficient up to an integer, checks that every solve is still bounded
//! (raising a coefficient where one is not, and saying so), and prints the
//! new `COST` array as Rust source beside the ratios counted/measured
//! (least, median, greatest, mean) of the current and the new coefficients.
//! A term no solve has a unit of keeps its current coefficient.
//!
//! New coefficients change what a budget affords (the solver plans its
//! steps by them), so the solves under the new `COST` are not quite those
//! it was fitted to, and it may not bound all of them. With `-- --write` it
//! writes the array into `shared/src/solve/cost.rs`, builds and measures
//! again, and while the written `COST` does not bound every solve of its
//! own run, refits to all the solves measured so far and writes again (at
//! most [`ROUNDS`] rounds). Without it nothing is written.
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
use std::time::{Duration, Instant};

include!("../../host/firmware_build.rs");

/// The bound's margin by default, percent. Fitted with none, the model
/// bounded the `cost` binary's solves but under-counted a live-loop
/// frame's solve by about 4 % (README, "Real time"): the live loop's
/// problems are not the binary's.
const MARGIN: f64 = 5.0;

/// The most rounds of `--write`.
const ROUNDS: usize = 6;

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
    /// Unknown arguments.
    #[error("arguments {0:?}: the options are --write and --margin P (percent, 0 to 100)")]
    Usage(String),
    /// The firmware printed no solves.
    #[error("the cost firmware printed no solves")]
    NoSolves,
    /// `--write` found no COST that bounds its own run.
    #[error("after {0} rounds the written COST still does not bound every solve of its run")]
    Rounds(usize),
    /// The `COST` item was not found.
    #[error("{0}: no `pub const COST: [u32; TERMS] = [ … ];` to replace")]
    Source(PathBuf),
    /// The integer coefficients leave a solve unbounded.
    #[error("the rounded coefficients do not bound solve {0}, and no raise of a term fixes it")]
    Unbounded(u32),
    /// `cost.rs` could not be read or written.
    #[error("{path}: {why}")]
    File {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        why: String,
    },
    /// The table region's temporary file failed.
    #[error("the table region's temporary file: {0}")]
    Io(#[from] std::io::Error),
}

fn main() {
    if let Err(e) = run() {
        eprintln!("fit_cost: {e}");
        std::process::exit(1);
    }
}

fn run() -> Result<(), Error> {
    let (write, margin) = options(std::env::args().skip(1).collect())?;
    println!("margin: every solve bounded with {margin} % to spare");
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut current: Vec<u64> = COST.iter().map(|&c| u64::from(c)).collect();
    let mut all = vec![];
    for round in 1..=ROUNDS {
        let solves = measure(&repo, &current)?;
        let [least, ..] = fit::ratios(&current, &solves).ok_or(Error::NoSolves)?;
        if round > 1 && least >= 1.0 + margin / 100.0 {
            println!("round {round}: the written COST bounds every solve of its own run");
            return Ok(());
        }
        all.extend(solves);
        let cost = refit(&all, &current, margin)?;
        if !write {
            println!(
                "a new COST changes which steps a budget affords, so it may not bound the \
                 solves it leads to: `-- --write` writes it and refits until it does"
            );
            return Ok(());
        }
        let path = repo.join("shared/src/solve/cost.rs");
        write_cost(&path, &cost)?;
        println!("round {round}: wrote the new COST into {}", path.display());
        current = cost;
    }
    Err(Error::Rounds(ROUNDS))
}

/// Builds and runs both binaries and pairs their solves (the firmware's
/// counts checked against `current`).
fn measure(repo: &Path, current: &[u64]) -> Result<Vec<Solve>, Error> {
    let start = Instant::now();
    let plain_elf = build(repo, &repo.join("firmware/target"), false)?;
    let terms_elf = build(repo, &repo.join("target/cost-terms"), true)?;
    let built = start.elapsed();
    let plain = parse(&run_elf(&plain_elf)?, "cost")?;
    let terms = parse(&run_elf(&terms_elf)?, "cost with cost-terms")?;
    let solves = pair(&plain, &terms, current)?;
    println!(
        "{} solves ({} failed), {TERMS} terms; firmware built in {:.0} s, both runs in {:.0} s",
        solves.len(),
        plain.failed,
        built.as_secs_f64(),
        (start.elapsed() - built).as_secs_f64()
    );
    let mut slower: Vec<f64> = (plain.lines.iter().zip(&terms.lines))
        .map(|(p, t)| f64::from(t.head[1]) / f64::from(p.head[1]))
        .collect();
    slower.sort_by(f64::total_cmp);
    if let Some(median) = slower.get(slower.len() / 2) {
        println!("instructions with cost-terms / without, per solve: median {median:.2}");
    }
    print_ratios("current", current, &solves);
    Ok(solves)
}

/// `--write` and `--margin P` (percent, default [`MARGIN`]).
fn options(args: Vec<String>) -> Result<(bool, f64), Error> {
    let (mut write, mut margin) = (false, MARGIN);
    let mut rest = args.iter();
    while let Some(a) = rest.next() {
        match a.as_str() {
            "--write" => write = true,
            "--margin" => {
                margin = rest
                    .next()
                    .and_then(|v| v.parse::<f64>().ok())
                    .filter(|m| (0.0..100.0).contains(m))
                    .ok_or_else(|| Error::Usage(args.join(" ")))?;
            }
            _ => return Err(Error::Usage(args.join(" "))),
        }
    }
    Ok((write, margin))
}

/// Fits `solves` with their instructions raised by `margin` percent,
/// rounds up, bounds every solve again and reports; terms no solve uses
/// keep their `current` coefficient.
fn refit(solves: &[Solve], current: &[u64], margin: f64) -> Result<Vec<u64>, Error> {
    let start = Instant::now();
    let raised: Vec<Solve> = solves
        .iter()
        .map(|s| Solve {
            instructions: s.instructions * (1.0 + margin / 100.0),
            ..s.clone()
        })
        .collect();
    let (measured, solves) = (solves, raised.as_slice());
    let fitted = fit::fit(solves, TERMS)?;
    let mut cost = fit::round_up(&fitted.exact);
    for &j in &fitted.unused {
        cost[j] = current[j];
    }
    let bumps = fit::bound(&mut cost, solves, &fitted.weight);
    let short = solves
        .iter()
        .find(|s| (fit::counted_int(&cost, &s.units) as f64) < s.instructions);
    if let Some(s) = short {
        return Err(Error::Unbounded(s.id));
    }
    // The ratios against the instructions as measured.
    report(measured, &fitted, current, &cost, &bumps)?;
    println!("fitted in {:.1} s", start.elapsed().as_secs_f64());
    Ok(cost)
}

/// Replaces the `COST` array in `path` (`shared/src/solve/cost.rs`).
fn write_cost(path: &Path, cost: &[u64]) -> Result<(), Error> {
    let file = |e: std::io::Error| Error::File {
        path: path.to_path_buf(),
        why: e.to_string(),
    };
    let text = std::fs::read_to_string(path).map_err(file)?;
    let head = "pub const COST: [u32; TERMS] = [";
    let missing = || Error::Source(path.to_path_buf());
    let start = text.find(head).ok_or_else(missing)?;
    let end = start + text[start..].find("];").ok_or_else(missing)? + 2;
    let new = format!(
        "{}{}{}",
        &text[..start],
        array(&to_u32(cost)?),
        &text[end..]
    );
    std::fs::write(path, new).map_err(file)?;
    Ok(())
}

/// Builds the `cost` binary (with `cost-terms` if `terms`) into
/// `target_dir` and returns its ELF.
fn build(repo: &Path, target_dir: &Path, terms: bool) -> Result<PathBuf, Error> {
    let dir = repo.join("firmware");
    let mut cmd = firmware_cargo(&dir);
    cmd.args(["build", "--quiet", "--release", "--bin", "cost"])
        .arg("--target-dir")
        .arg(target_dir);
    if terms {
        cmd.args(["--features", "cost-terms"]);
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
fn run_elf(elf: &Path) -> Result<String, Error> {
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
#[derive(Debug)]
struct Line {
    /// 1-based line of the console.
    line: usize,
    /// The leading fields ([`FIELDS`]).
    head: [u32; FIELDS.len()],
    /// The units of each term (none without `cost-terms`).
    units: Vec<u32>,
}

/// The `cost` lines of one run, and how many solves failed.
#[derive(Debug)]
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
fn pair(plain: &Run, terms: &Run, current: &[u64]) -> Result<Vec<Solve>, Error> {
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
        let model = fit::counted_int(current, &t.units);
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

/// Prints the per-term table, the raises, the new array and its ratios.
fn report(
    solves: &[Solve],
    fitted: &fit::Fit,
    current: &[u64],
    cost: &[u64],
    bumps: &[Bump],
) -> Result<(), Error> {
    println!(
        "linear program over {} solves: {} pivots, mean counted/(measured with the margin) {:.4}",
        solves.len(),
        fitted.pivots,
        fitted.mean_ratio
    );
    println!("term  solves using it  current  fitted (exact)  new");
    for (j, ((&c, exact), old)) in cost.iter().zip(&fitted.exact).zip(current).enumerate() {
        let using = solves.iter().filter(|s| s.units[j] > 0).count();
        println!("{j:>4}  {using:>14}  {old:>7}  {exact:>14.3}  {c:>4}");
    }
    for &j in &fitted.unused {
        println!(
            "term {j}: no solve has a unit of it; kept at {}",
            current[j]
        );
    }
    for b in bumps {
        println!(
            "rounded up, solve {} was not bounded: term {} raised by {}",
            b.id, b.term, b.by
        );
    }
    println!(
        "\n/// Instructions per unit of each term, in [`Term`] order.\n{}",
        array(&to_u32(cost)?)
    );
    print_ratios("new", cost, solves);
    Ok(())
}

/// Prints the least, median, greatest and mean ratio counted/measured of
/// `cost` over `solves`.
fn print_ratios(name: &str, cost: &[u64], solves: &[Solve]) {
    if let Some([min, median, max]) = fit::ratios(cost, solves) {
        let mean = solves
            .iter()
            .map(|s| fit::counted_int(cost, &s.units) as f64 / s.instructions)
            .sum::<f64>()
            / solves.len() as f64;
        println!(
            "{name:>7} COST: counted/measured over {} solves: min {min:.3}, median {median:.3}, \
             max {max:.3}, mean {mean:.4}",
            solves.len()
        );
    }
}

/// The coefficients as `u32`s, as `COST` holds them.
fn to_u32(cost: &[u64]) -> Result<Vec<u32>, Error> {
    let mut out = Vec::with_capacity(cost.len());
    for (term, &value) in cost.iter().enumerate() {
        out.push(u32::try_from(value).map_err(|_| Error::Overflow { term, value })?);
    }
    Ok(out)
}

/// The `COST` item as rustfmt lays it out (values packed into lines of
/// fewer than 100 columns).
fn array(cost: &[u32]) -> String {
    let mut out = String::from("pub const COST: [u32; TERMS] = [\n");
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
    use super::{COST, Error, TERMS, pair, parse};

    #[test]
    fn a_console_is_read_line_by_line() {
        let run = parse("boot\ncost 1 320 100 2 1 3 4\nfailed 2\n", "t").unwrap();
        assert_eq!(run.failed, 1);
        assert_eq!(run.lines.len(), 1);
        assert_eq!(run.lines[0].line, 2);
        assert_eq!(run.lines[0].head, [1, 320, 100, 2, 1]);
        assert_eq!(run.lines[0].units, [3, 4]);
    }

    #[test]
    fn a_bad_line_names_its_line_and_field() {
        let err = parse("cost 1 320 100 2 1\ncost 3 x 1 1 1\n", "t").unwrap_err();
        assert!(
            matches!(&err, Error::Parse { line: 2, field, .. } if field == "ticks"),
            "{err}"
        );
        let err = parse("cost 1 320\n", "t").unwrap_err();
        assert!(
            matches!(&err, Error::Parse { line: 1, field, .. } if field == "work"),
            "{err}"
        );
    }

    /// One unit of term 0: the work must be `COST[0]`, else the runs were
    /// not built from the same model.
    #[test]
    fn the_runs_must_count_alike() {
        let mut units = vec!["0"; TERMS];
        units[0] = "1";
        let terms = format!("cost 0 9 9 1 1 {}\n", units.join(" "));
        let terms = parse(&terms, "terms").unwrap();
        let current: Vec<u64> = COST.iter().map(|&c| u64::from(c)).collect();
        let ok = parse(&format!("cost 0 32 {} 1 1\n", COST[0]), "plain").unwrap();
        let solves = pair(&ok, &terms, &current).unwrap();
        assert_eq!(solves[0].instructions, 10.0);
        let off = parse(&format!("cost 0 32 {} 1 1\n", COST[0] + 1), "plain").unwrap();
        assert!(matches!(pair(&off, &terms, &current), Err(Error::Runs(_))));
        let other = parse(&format!("cost 0 32 {} 2 1\n", COST[0]), "plain").unwrap();
        assert!(matches!(
            pair(&other, &terms, &current),
            Err(Error::Runs(_))
        ));
    }

    /// The array as rustfmt laid it out in `shared/src/solve/cost.rs`: a
    /// line that would reach 100 columns is wrapped.
    #[test]
    fn the_source_is_laid_out_as_rustfmt_does() {
        let cost = [
            3945, 10, 360, 0, 0, 175, 112, 184, 30, 60, 203, 60, 11, 802, 71, 205, 54, 40, 93, 24,
            100, 483, 183, 59, 33, 0, 0, 187,
        ];
        let want = "pub const COST: [u32; TERMS] = [
    3945, 10, 360, 0, 0, 175, 112, 184, 30, 60, 203, 60, 11, 802, 71, 205, 54, 40, 93, 24, 100,
    483, 183, 59, 33, 0, 0, 187,
];";
        assert_eq!(super::array(&cost), want);
    }
}
