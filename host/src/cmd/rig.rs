//! `marionette rig check RIG`: what a rig file describes, whether each
//! board can drive it, and the slips a rig file's rules let through.
//!
//! It prints the rig's summary and **hash** (the hash a table must be built
//! for), the capacity verdict per board (segments, servo back-end, rig
//! blob against the table region; see [`crate::board`]), and:
//!
//! - **errors** (exit status 1): a DOF driven by two servos;
//! - **warnings**: a radians key (`limits`, `angle`) holding a value beyond
//!   ±π (degrees written in the radians key? use `limits_deg`/`angle_deg`),
//!   a segment longer than [`MAX_SEGMENT_M`] (centimetres or millimetres
//!   in a metres key? see `length_unit`), a DOF no servo drives.
//!
//! `--json` prints the same as one object: `file`, `name`, `hash`,
//! `segments`, `dofs`, `servos`, `output`, `frame_period_us`,
//! `failsafe_timeout_ms`, `params`, `goals`, `rig_blob_bytes`, `boards`
//! (`board`, `fits`, `problems`, `region_bytes`), `errors`, `warnings`
//! (each `line`, `field`, `message`).
//!
//! `marionette rig --from-skeleton FILE.bvh|FILE.asf -o rig.toml` writes a
//! rig made from a mocap skeleton ([`crate::skeleton`]): its segments and
//! offsets, DOFs from the skeleton's rotation channels, generous limits and
//! comments marking what to edit. It refuses to write over its input, and
//! over any other existing file without `--force`.

use super::CmdError;
use crate::board::{self, BOARDS};
use crate::build::spec::NameMap;
use crate::rigfile::{self, RigFile};
use crate::skeleton;
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::ops::Range;
use std::path::{Path, PathBuf};
use toml::Spanned;

/// The longest plausible segment (joint origin from its parent), metres.
pub const MAX_SEGMENT_M: f32 = 2.0;

/// Arguments of `marionette rig`.
#[derive(clap::Args, Debug)]
#[command(args_conflicts_with_subcommands = true)]
pub struct Args {
    /// What to do with a rig file.
    #[command(subcommand)]
    pub command: Option<RigCommand>,
    /// Write a rig made from this mocap skeleton (`.bvh` or `.asf`): one
    /// segment per joint, DOFs from its rotation channels, generous limits,
    /// comments marking what to edit (needs `-o`).
    #[arg(long, value_name = "FILE")]
    pub from_skeleton: Option<PathBuf>,
    /// The rig file to write (with `--from-skeleton`).
    #[arg(
        short = 'o',
        long = "output",
        value_name = "RIG.toml",
        requires = "from_skeleton"
    )]
    pub output: Option<PathBuf>,
    /// Overwrite an existing output file (never the skeleton itself).
    #[arg(long, requires = "from_skeleton")]
    pub force: bool,
    /// BVH: metres per file unit (default: the CMU unit 0.056444; 0.01 for
    /// centimetres). An ASF states its own.
    #[arg(long, requires = "from_skeleton")]
    pub scale: Option<f64>,
    /// The rig's name (default: the skeleton file's stem).
    #[arg(long, requires = "from_skeleton")]
    pub name: Option<String>,
    /// Remove this prefix from every joint name that has it.
    #[arg(long, value_name = "PREFIX", requires = "from_skeleton")]
    pub strip_prefix: Option<String>,
    /// Rename a joint (its name after `--strip-prefix`): `OLD=NEW`; repeatable.
    #[arg(long, value_name = "OLD=NEW", requires = "from_skeleton")]
    pub rename: Vec<String>,
    /// Leave out the joints matching this glob (`*` = anything); repeatable.
    #[arg(long, value_name = "PATTERN", requires = "from_skeleton")]
    pub drop: Vec<String>,
    /// Keep only the joints matching this glob (the root always); repeatable.
    #[arg(long, value_name = "PATTERN", requires = "from_skeleton")]
    pub keep: Vec<String>,
}

/// The `rig` subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum RigCommand {
    /// Summary, hash, per-board verdict, and likely unit and wiring slips.
    Check(CheckArgs),
}

/// Arguments of `marionette rig check`.
#[derive(clap::Args, Debug)]
pub struct CheckArgs {
    /// The rig file (TOML; docs/rig.md), or a rig name: `rigs/<name>.toml`
    /// here, else a rig built in (humanoid16, cmu31).
    pub rig: PathBuf,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

/// One finding, located in the rig file.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Finding {
    /// 1-based line (0: the file as a whole).
    pub line: usize,
    /// The field (`servo[3].angle`).
    pub field: String,
    /// What looks wrong, and what to do.
    pub message: String,
}

/// The report of `rig check`.
#[derive(Debug, Serialize)]
pub struct Report {
    /// The file.
    pub file: String,
    /// The rig's name.
    pub name: String,
    /// The skeleton hash tables are built for (hex).
    pub hash: String,
    /// Segments (the root included).
    pub segments: usize,
    /// Degrees of freedom.
    pub dofs: usize,
    /// Servos.
    pub servos: usize,
    /// The servo back-end.
    pub output: String,
    /// Control-loop period, µs.
    pub frame_period_us: u32,
    /// Fail-safe time-out, ms.
    pub failsafe_timeout_ms: u32,
    /// Sensor → parameter entries.
    pub params: usize,
    /// Goals.
    pub goals: usize,
    /// Bytes of the rig blob (flashed before the table).
    pub rig_blob_bytes: usize,
    /// Per board.
    pub boards: Vec<board::Verdict>,
    /// Problems that stop the rig from working as written.
    pub errors: Vec<Finding>,
    /// Likely slips.
    pub warnings: Vec<Finding>,
}

/// Runs a `rig` subcommand, or `rig --from-skeleton`.
pub fn run(args: &Args) -> Result<(), CmdError> {
    match (&args.command, &args.from_skeleton) {
        (Some(RigCommand::Check(a)), _) => check_command(a),
        (None, Some(skeleton)) => from_skeleton_command(args, skeleton),
        (None, None) => Err(
            "rig: give a subcommand (`rig check RIG`) or `--from-skeleton FILE -o RIG.toml`".into(),
        ),
    }
}

fn from_skeleton_command(args: &Args, skeleton: &Path) -> Result<(), CmdError> {
    let out = args
        .output
        .as_deref()
        .ok_or("rig --from-skeleton: give the rig file to write with -o RIG.toml")?;
    if same_file(skeleton, out) {
        return Err(format!(
            "{}: -o names the skeleton itself; refusing to write over the input",
            out.display()
        )
        .into());
    }
    if out.exists() && !args.force {
        return Err(format!(
            "{}: exists; refusing to overwrite it (--force to replace it)",
            out.display()
        )
        .into());
    }
    let options = skeleton::Options {
        scale: args.scale,
        name: args.name.clone(),
        names: name_map(args)?,
    };
    let (rig, text) = skeleton::rig_text(skeleton, &options, &out.display().to_string())?;
    std::fs::write(out, text).map_err(|e| format!("{}: cannot write: {e}", out.display()))?;
    println!(
        "{}: rig {:?} from {} ({} segments, {} DOFs); edit the lines marked EDIT, then \
         `marionette rig check {}`",
        out.display(),
        rig.name,
        rig.source,
        rig.segments.len(),
        rig.dof_count(),
        out.display()
    );
    Ok(())
}

/// Whether `a` and `b` are the same existing file.
fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

fn name_map(args: &Args) -> Result<NameMap, CmdError> {
    let mut rename = std::collections::BTreeMap::new();
    for r in &args.rename {
        match r.split_once('=') {
            Some((old, new)) if !old.is_empty() && !new.is_empty() => {
                rename.insert(old.to_owned(), new.to_owned());
            }
            _ => return Err(format!("--rename {r:?}: expected OLD=NEW").into()),
        }
    }
    Ok(NameMap {
        strip_prefix: args.strip_prefix.clone(),
        rename,
        drop: args.drop.clone(),
        keep: args.keep.clone(),
        lines: [0; 4],
    })
}

fn check_command(args: &CheckArgs) -> Result<(), CmdError> {
    let path = rigfile::resolve(&args.rig);
    let rig = rigfile::load(&path)?;
    let text = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    let report = check(&rig, &text)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report_text(&report));
    }
    match report.errors.len() {
        0 => Ok(()),
        n => Err(format!("{}: {n} error(s)", report.file).into()),
    }
}

/// Checks a loaded rig file (`text` is its source, for lines).
pub fn check(rig: &RigFile, text: &str) -> Result<Report, CmdError> {
    let desc = rig.desc();
    let blob = rigfile::to_blob(rig)?;
    let raw = Raw::parse(text);
    let segments = desc.segments.as_slice();
    let servos = desc.servos.as_slice();
    let mut errors = Vec::new();
    let mut warnings = Vec::new();
    if servos.is_empty() {
        warnings.push(Finding {
            line: 0,
            field: "servo".into(),
            message: "no [[servo]] at all: a skeleton to build tables from, which drives nothing"
                .into(),
        });
    }
    // Each DOF's servos.
    for (si, seg) in segments.iter().enumerate().filter(|_| !servos.is_empty()) {
        for (di, dof) in seg.dofs.as_slice().iter().enumerate() {
            let driving: Vec<usize> = servos
                .iter()
                .enumerate()
                .filter(|(_, s)| usize::from(s.segment) == si && usize::from(s.dof) == di)
                .map(|(k, _)| k)
                .collect();
            let axis = format!("{}.{}", seg.name, axis_word(dof.axis));
            match driving.as_slice() {
                [] => warnings.push(Finding {
                    line: raw.segment_line(si),
                    field: format!("segment[{si}].dofs[{di}]"),
                    message: format!(
                        "{axis} has no servo: nothing drives it (add a [[servo]] with joint = \
                         {:?}, axis = \"{}\", or drop the DOF)",
                        seg.name,
                        axis_word(dof.axis)
                    ),
                }),
                [_] => {}
                [first, rest @ ..] => {
                    for k in rest {
                        errors.push(Finding {
                            line: raw.servo_line(*k),
                            field: format!("servo[{k}]"),
                            message: format!(
                                "drives {axis}, which servo[{first}] (channel {}) drives too: a \
                                 DOF takes one servo",
                                servos.get(*first).map_or(0, |s| s.channel)
                            ),
                        });
                    }
                }
            }
        }
    }
    // Segment lengths.
    for (si, seg) in segments.iter().enumerate().skip(1) {
        let [x, y, z] = seg.origin;
        let len = (x * x + y * y + z * z).sqrt();
        if len > MAX_SEGMENT_M {
            warnings.push(Finding {
                line: raw.segment_line(si),
                field: format!("segment[{si}].origin"),
                message: format!(
                    "{} is {len:.3} m from its parent, longer than {MAX_SEGMENT_M} m: \
                     centimetres or millimetres in a metres key? (see length_unit)",
                    seg.name
                ),
            });
        }
    }
    warnings.extend(raw.radian_slips());
    let dofs = segments.iter().map(|s| s.dofs.len()).sum();
    Ok(Report {
        file: rig.file.clone(),
        name: rig.name().to_owned(),
        hash: format!("{:#018x}", rig.rig_hash()),
        segments: segments.len(),
        dofs,
        servos: servos.len(),
        output: board::describe_output(&desc.output),
        frame_period_us: desc.frame_period_us,
        failsafe_timeout_ms: desc.failsafe_timeout_ms,
        params: desc.params.len(),
        goals: desc.goals.len(),
        rig_blob_bytes: blob.len(),
        boards: BOARDS
            .iter()
            .map(|b| b.verdict(segments.len(), (&desc.output, servos), blob.len(), None))
            .collect(),
        errors,
        warnings,
    })
}

fn axis_word(a: marionette_core::rig::AxisName) -> &'static str {
    match a {
        marionette_core::rig::AxisName::X => "x",
        marionette_core::rig::AxisName::Y => "y",
        marionette_core::rig::AxisName::Z => "z",
    }
}

/// The report as text.
#[must_use]
pub fn report_text(r: &Report) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "{}: rig {:?}, hash {}", r.file, r.name, r.hash);
    let _ = writeln!(
        s,
        "  {} segments, {} DOFs, {} servos on {}; {} µs frame period ({} Hz), fail-safe {} ms; \
         {} parameters, {} goals; rig blob {} B",
        r.segments,
        r.dofs,
        r.servos,
        r.output,
        r.frame_period_us,
        1_000_000 / r.frame_period_us.max(1),
        r.failsafe_timeout_ms,
        r.params,
        r.goals,
        r.rig_blob_bytes
    );
    let _ = writeln!(s, "boards:");
    for b in &r.boards {
        if b.fits {
            let _ = writeln!(
                s,
                "  {:<10} can drive it (rig blob {} of its {} B table region; the rest is for the table)",
                b.board, r.rig_blob_bytes, b.region_bytes[1]
            );
        } else {
            let _ = writeln!(s, "  {:<10} cannot: {}", b.board, b.problems.join("; "));
        }
    }
    for (title, list) in [("errors", &r.errors), ("warnings", &r.warnings)] {
        if !list.is_empty() {
            let _ = writeln!(s, "{title}:");
            for f in list {
                let _ = writeln!(s, "  {}:{}: {}: {}", r.file, f.line, f.field, f.message);
            }
        }
    }
    let _ = writeln!(
        s,
        "{} error(s), {} warning(s)",
        r.errors.len(),
        r.warnings.len()
    );
    s
}

// ---------------------------------------------------------------------------
// The rig file's radians keys and entry lines, read a second time with spans
// (the loaded rig keeps values, not which key or line they came from).

#[derive(Deserialize, Default)]
struct RawRig {
    #[serde(default)]
    segment: Vec<Spanned<RawSegment>>,
    #[serde(default)]
    servo: Vec<Spanned<RawServo>>,
}

#[derive(Deserialize)]
struct RawSegment {
    #[serde(default)]
    dofs: Vec<RawDof>,
}

#[derive(Deserialize)]
struct RawDof {
    limits: Option<Spanned<[f64; 2]>>,
}

#[derive(Deserialize)]
struct RawServo {
    angle: Option<Spanned<[f64; 2]>>,
}

struct Raw<'t> {
    text: &'t str,
    rig: RawRig,
}

impl<'t> Raw<'t> {
    fn parse(text: &'t str) -> Self {
        Self {
            text,
            rig: toml::from_str(text).unwrap_or_default(),
        }
    }

    fn line(&self, span: &Range<usize>) -> usize {
        let end = span.start.min(self.text.len());
        1 + self
            .text
            .as_bytes()
            .get(..end)
            .map_or(0, |b| b.iter().filter(|&&c| c == b'\n').count())
    }

    fn segment_line(&self, i: usize) -> usize {
        self.rig.segment.get(i).map_or(0, |s| self.line(&s.span()))
    }

    fn servo_line(&self, i: usize) -> usize {
        self.rig.servo.get(i).map_or(0, |s| self.line(&s.span()))
    }

    /// Radians keys holding values beyond ±π.
    fn radian_slips(&self) -> Vec<Finding> {
        let slip = |v: &Spanned<[f64; 2]>, field: String, key: &str| {
            let [a, b] = *v.get_ref();
            (a.abs() > std::f64::consts::PI || b.abs() > std::f64::consts::PI).then(|| Finding {
                line: self.line(&v.span()),
                field,
                message: format!(
                    "[{a}, {b}] in radians is beyond ±π (±180°): degrees in the radians key? \
                     Write {key}_deg = [{a}, {b}] if they are degrees"
                ),
            })
        };
        let mut out = Vec::new();
        for (si, seg) in self.rig.segment.iter().enumerate() {
            for (di, dof) in seg.get_ref().dofs.iter().enumerate() {
                if let Some(v) = &dof.limits {
                    out.extend(slip(
                        v,
                        format!("segment[{si}].dofs[{di}].limits"),
                        "limits",
                    ));
                }
            }
        }
        for (k, servo) in self.rig.servo.iter().enumerate() {
            if let Some(v) = &servo.get_ref().angle {
                out.extend(slip(v, format!("servo[{k}].angle"), "angle"));
            }
        }
        out
    }
}
