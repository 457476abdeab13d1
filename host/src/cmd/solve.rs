//! `marionette solve RIG --goals goals.json [--json]`: position a rig to meet
//! weighted goals with the core solver, from its rest pose or a given pose.
//!
//! # Input (the goals file, JSON; for users: `docs/goals.md`)
//!
//! ```json
//! {
//!   "start": "rest",
//!   "goals": [
//!     { "segment": "r_forearm", "target": [-0.1, 0.6, 0.2], "weight": 10 },
//!     { "segment": "l_forearm", "target": [0.2, 0.5, 0.1], "weight": 5, "point": [0, -0.1, 0] }
//!   ]
//! }
//! ```
//!
//! - `start` (optional, default `"rest"`): `"rest"` (the rig's rest pose: root
//!   at `root_position`, every angle 0 clamped into its limits), or a pose
//!   `{"segments": [{"name", "position": [x,y,z], "rotation": [w,x,y,z]}]}`
//!   in world coordinates. The pose is projected onto the joints' degrees of
//!   freedom within their limits (the warm start); only the root's position
//!   and every listed segment's rotation count (the other positions follow
//!   from the skeleton), and an unlisted segment keeps its rest relation to
//!   its parent. Other keys of the pose are ignored, so the output of
//!   `marionette synth --json` is a start as it is; the segments are checked.
//! - `goals`: each pulls a point of `segment` (its touch point, or `point` in
//!   the segment's frame, m) towards `target` (world, m) with `weight` (≥ 0;
//!   0 = inactive).
//!
//! # Output (`--json`; a public contract: these keys, extended, never removed)
//!
//! ```json
//! {"segments": [{"name", "position", "rotation"}],
//!  "goals": [{"segment", "touch_point", "distance", "active", "met", "reach"}],
//!  "iterations", "converged", "met", "unreachable", "tolerance", "restarts"}
//! ```
//!
//! `segments`: every segment of the rig in rig order, world joint origin (m)
//! and orientation `[w, x, y, z]`; `goals`: in input order, the world position
//! of the pulled point and its distance to the target (m), whether it is
//! `active` (weight > 0) and `met` (active, within the solver's `tolerance`, m),
//! and `reach`: how far the pulled point can get from the fixed root along
//! its chain (the sum of the segment lengths, m; `null` when the root may
//! move); `iterations` and `converged` as the solver reports them
//! (`converged`: the iteration stopped on its own, not on the cap; it says
//! nothing about the goals). `met` counts the met goals; `unreachable` lists
//! the indices of the goals whose target is farther from the root than
//! their `reach` (no pose meets them); `restarts` the solver's restarts
//! (`--restarts`, default [`DEFAULT_RESTARTS`]: when the goals are not all
//! met from the start, it solves again from other starts and keeps the
//! best).
//!
//! Errors name the file, the line and the field: JSON syntax errors with
//! line and column, then `goals.json:7: goals[2].segment: unknown segment
//! "hand"` and so on (the line where the field's value starts, or its
//! object when it is missing); rig-file errors as [`crate::rigfile`] reports them.

use std::path::{Path, PathBuf};

use glam::{Quat, Vec3};
use marionette_core::body::{Angles, Body};
use marionette_core::goal::{Goal, GoalSet, Target};
use marionette_core::pose::{self, LocalPose, MAX_SEGMENTS, NO_PARENT, Pose};
use marionette_core::rig::Rig;
use marionette_core::solve::{self, Method, RootMode, Solver};
use serde::Serialize;
use serde_json::Value;

use super::CmdError;
use crate::rigfile::{self, RigFile};

/// Most goals in one goals file.
pub const MAX_GOALS: usize = 16;

/// Restarts of an offline solve: on 200 random reachable right-arm targets
/// from rest, [`Solver::DEFAULT`] (no restarts) met 174 and stopped in a
/// joint-limit local minimum on 21; with 3 restarts it met 199 (#20).
pub const DEFAULT_RESTARTS: u8 = 3;

/// The solver algorithm (see `marionette_core::solve::Method`).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum MethodArg {
    /// Weighted damped least squares over the whole reach tree (default).
    TreeDls,
    /// Reach-tree balancing with a damped-least-squares chain solver.
    Dls,
    /// Reach-tree balancing with cyclic coordinate descent.
    Ccd,
    /// The paper's greedy triangle-inequality chain solver.
    Greedy,
}

/// What may move the reach tree's root.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum RootArg {
    /// The body root stays put (a puppet on a stand; default).
    Fixed,
    /// The whole body may translate (the paper).
    Float,
}

/// Arguments of `marionette solve`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The rig file (TOML; docs/rig.md), or a rig name (`humanoid16`):
    /// `rigs/<name>.toml` here, else a rig built in (humanoid16, cmu31).
    pub rig: PathBuf,
    /// The goals file (JSON; the format: docs/goals.md).
    #[arg(long)]
    pub goals: PathBuf,
    /// Print the result as JSON (the public contract) instead of a summary.
    #[arg(long)]
    pub json: bool,
    /// The solver algorithm.
    #[arg(long, value_enum, default_value_t = MethodArg::TreeDls)]
    pub method: MethodArg,
    /// What may move the root.
    #[arg(long, value_enum, default_value_t = RootArg::Fixed)]
    pub root: RootArg,
    /// Iteration cap.
    #[arg(long, default_value_t = 100)]
    pub iterations: u16,
    /// When the goals are not all met, solve again from this many other
    /// starts and keep the best (tree-dls only; 0: one local solve, as the
    /// live loop does).
    #[arg(long, default_value_t = DEFAULT_RESTARTS)]
    pub restarts: u8,
}

impl Args {
    /// The solver configuration these arguments select.
    #[must_use]
    pub fn solver(&self) -> Solver {
        let method = match self.method {
            MethodArg::TreeDls => Method::TreeDls,
            MethodArg::Dls => Method::Dls,
            MethodArg::Ccd => Method::Ccd,
            MethodArg::Greedy => Method::Greedy,
        };
        let root = match self.root {
            RootArg::Fixed => RootMode::Fixed,
            RootArg::Float => RootMode::Float,
        };
        Solver::DEFAULT
            .with_method(method)
            .with_root(root)
            .with_iterations(self.iterations)
            .with_restarts(self.restarts)
    }
}

/// One segment of the result.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SegmentOut {
    /// The segment name.
    pub name: String,
    /// World joint origin, m.
    pub position: [f32; 3],
    /// World orientation `[w, x, y, z]`.
    pub rotation: [f32; 4],
}

/// One goal of the result.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GoalOut {
    /// The segment name.
    pub segment: String,
    /// World position of the pulled point, m.
    pub touch_point: [f32; 3],
    /// Distance from the pulled point to the target, m.
    pub distance: f32,
    /// Active: weight > 0 (an inactive goal pulls nothing and is never met).
    pub active: bool,
    /// Active and within the solver's tolerance.
    pub met: bool,
    /// How far the pulled point can get from the (fixed) root, m: its
    /// chain's segment lengths summed; `None` when the root may move.
    pub reach: Option<f32>,
}

/// The result of `marionette solve` (serialized as the JSON contract).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SolveOutput {
    /// Every segment, rig order.
    pub segments: Vec<SegmentOut>,
    /// Every goal, input order.
    pub goals: Vec<GoalOut>,
    /// Solver iterations.
    pub iterations: u32,
    /// Whether the solver stopped on convergence rather than a cap (not
    /// whether the goals are met: see `met`).
    pub converged: bool,
    /// How many goals are met.
    pub met: usize,
    /// Indices of the goals no pose can meet (target beyond `reach`).
    pub unreachable: Vec<usize>,
    /// The distance within which a goal counts as met, m.
    pub tolerance: f32,
    /// The solver's restarts.
    pub restarts: u8,
}

/// A goals-file error.
#[derive(Debug, thiserror::Error)]
pub enum GoalsError {
    /// The file could not be read.
    #[error("{file}: cannot read: {source}")]
    Io {
        /// The file.
        file: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Not JSON.
    #[error("{file}:{line}:{column}: {message}")]
    Syntax {
        /// The file.
        file: String,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// serde_json's message.
        message: String,
    },
    /// A field is missing, of the wrong type, or refers to nothing.
    #[error("{file}:{line}: {field}: {message}")]
    Field {
        /// The file.
        file: String,
        /// 1-based line where the field's value starts (or where its
        /// object starts, when it is missing).
        line: usize,
        /// The field path (`goals[2].target[1]`).
        field: String,
        /// What is wrong.
        message: String,
    },
    /// The solver refused the problem.
    #[error("{file}: {message}")]
    Solve {
        /// The file.
        file: String,
        /// What the solver said.
        message: String,
    },
}

/// Reads the rig and the goals, solves, and prints the result.
pub fn run(args: &Args) -> Result<(), CmdError> {
    let rig = rigfile::load(&rigfile::resolve(&args.rig))?;
    let out = solve_file(&rig, &args.goals, &args.solver())?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        print!("{}", summary(rig.name(), &out));
    }
    Ok(())
}

/// Solves the goals file at `path` on a loaded rig.
pub fn solve_file(rig: &RigFile, path: &Path, solver: &Solver) -> Result<SolveOutput, CmdError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| GoalsError::Io {
        file: file.clone(),
        source,
    })?;
    solve_text(rig, &text, &file, solver)
}

/// Solves a goals document (`file` names it in errors).
pub fn solve_text(
    rig_file: &RigFile,
    text: &str,
    file: &str,
    solver: &Solver,
) -> Result<SolveOutput, CmdError> {
    // The rig goes through its blob, exactly as the firmware reads it.
    let blob = rigfile::to_blob(rig_file)?;
    let (rig, _) = Rig::parse(&blob).map_err(|e| format!("{}: rig blob: {e:?}", rig_file.file))?;
    let rig = Box::new(rig);
    let doc = Doc::parse(text, file)?;
    let body = rig.body();
    let mut angles = doc.start(&rig)?;
    let mut goals = GoalSet::<MAX_GOALS>::new();
    for (i, g) in doc.goals(&body)?.into_iter().enumerate() {
        goals.push(g).map_err(|_| {
            doc.field(
                &format!("goals[{i}]"),
                format!("more than {MAX_GOALS} goals"),
            )
        })?;
    }
    let mut pose = Box::new(Pose::<MAX_SEGMENTS>::default());
    let report = solve::solve(solver, &body, &goals, &mut angles, &mut pose).map_err(|e| {
        GoalsError::Solve {
            file: file.to_string(),
            message: format!("the solver refused the goals: {e:?}"),
        }
    })?;
    let segments = body
        .segments
        .iter()
        .zip(&pose.positions)
        .zip(&pose.rotations)
        .map(|((s, p), q)| SegmentOut {
            name: s.name.to_string(),
            position: p.to_array(),
            rotation: [q.w, q.x, q.y, q.z],
        })
        .collect();
    let root = pose.positions.first().copied().unwrap_or(Vec3::ZERO);
    let goals_out: Vec<GoalOut> = goals
        .as_slice()
        .iter()
        .zip(&report.residuals)
        .map(|(g, &d)| {
            let touch = g.world_point(&body, &pose).unwrap_or(Vec3::NAN);
            GoalOut {
                segment: body
                    .segment(usize::from(g.segment))
                    .map_or_else(String::new, |s| s.name.to_string()),
                touch_point: touch.to_array(),
                distance: d,
                active: g.is_active(),
                met: g.is_active() && d <= solver.tolerance,
                reach: (solver.root == RootMode::Fixed).then(|| reach(&body, &pose, g, touch)),
            }
        })
        .collect();
    let unreachable = goals
        .as_slice()
        .iter()
        .zip(&goals_out)
        .enumerate()
        .filter(|(_, (g, out))| {
            let Target::Position(target) = g.target else {
                return false;
            };
            out.reach
                .is_some_and(|r| g.is_active() && target.distance(root) > r + solver.tolerance)
        })
        .map(|(i, _)| i)
        .collect();
    Ok(SolveOutput {
        segments,
        met: goals_out.iter().filter(|g| g.met).count(),
        goals: goals_out,
        iterations: report.iterations,
        converged: report.converged,
        unreachable,
        tolerance: solver.tolerance,
        restarts: solver.restarts,
    })
}

/// How far a goal's pulled point can get from the body root: the lengths of
/// the segments from the goal's segment up to the root, plus the point's
/// distance from its segment's joint (`touch`: the point in `pose`).
fn reach<const N: usize>(body: &Body<'_>, pose: &Pose<N>, goal: &Goal, touch: Vec3) -> f32 {
    let seg = usize::from(goal.segment);
    let joint = pose.positions.get(seg).copied().unwrap_or(touch);
    let mut length = touch.distance(joint);
    let mut i = seg;
    // Parents come before children: at most `len` steps up.
    for _ in 0..body.len() {
        let parent = body.parents.get(i).copied().unwrap_or(NO_PARENT);
        if parent == NO_PARENT {
            break;
        }
        length += body.offsets.get(i).map_or(0.0, |o| o.length());
        i = usize::from(parent);
    }
    length
}

/// The goals of a goals document (`file` names it in errors) on `body`:
/// the one goals format, which `solve` and `render --goals` both read (see
/// the module doc and `docs/goals.md`; `start` is checked by `solve` only).
pub fn read_goals(body: &Body<'_>, text: &str, file: &str) -> Result<Vec<Goal>, GoalsError> {
    Doc::parse(text, file)?.goals(body)
}

/// The short human summary: whether the iteration stopped, how many goals
/// are met, which cannot be, and each goal.
#[must_use]
pub fn summary(rig: &str, out: &SolveOutput) -> String {
    use std::fmt::Write;
    let mut s = format!(
        "{rig}: {} goal(s), {} iteration(s), {}; {} of {} goal(s) met (within {} mm)\n",
        out.goals.len(),
        out.iterations,
        if out.converged {
            "converged (the iteration stopped)"
        } else {
            "not converged (iteration cap)"
        },
        out.met,
        out.goals.len(),
        out.tolerance * 1000.0
    );
    if !out.unreachable.is_empty() {
        let names: Vec<String> = out
            .unreachable
            .iter()
            .filter_map(|&i| {
                out.goals
                    .get(i)
                    .map(|g| format!("goals[{i}] ({})", g.segment))
            })
            .collect();
        let _ = writeln!(
            s,
            "  unreachable: {} (the target is beyond the chain's reach from the root)",
            names.join(", ")
        );
    }
    for (i, g) in out.goals.iter().enumerate() {
        let [x, y, z] = g.touch_point;
        let verdict = if g.met {
            "met".to_owned()
        } else if !g.active {
            "inactive (weight 0)".to_owned()
        } else if out.unreachable.contains(&i) {
            format!("unreachable (reach {:.3} m)", g.reach.unwrap_or(f32::NAN))
        } else {
            "missed".to_owned()
        };
        let _ = writeln!(
            s,
            "  {:<16} at ({x:.4}, {y:.4}, {z:.4}) m, {:.2} mm from its target: {verdict}",
            g.segment,
            g.distance * 1000.0
        );
    }
    s
}

/// A parsed goals document.
struct Doc<'t> {
    file: &'t str,
    text: &'t str,
    root: Value,
}

impl<'t> Doc<'t> {
    fn parse(text: &'t str, file: &'t str) -> Result<Self, GoalsError> {
        let root: Value = serde_json::from_str(text).map_err(|e| GoalsError::Syntax {
            file: file.to_string(),
            line: e.line(),
            column: e.column(),
            message: e
                .to_string()
                .split(" at line ")
                .next()
                .unwrap_or_default()
                .to_string(),
        })?;
        let doc = Doc { file, text, root };
        let Some(obj) = doc.root.as_object() else {
            return Err(doc.field("(top level)", "expected an object {\"start\", \"goals\"}"));
        };
        if let Some(k) = obj
            .keys()
            .find(|k| !matches!(k.as_str(), "start" | "goals"))
        {
            return Err(doc.field(k, "unknown field (expected \"start\" or \"goals\")"));
        }
        Ok(doc)
    }

    fn field(&self, field: &str, message: impl Into<String>) -> GoalsError {
        GoalsError::Field {
            file: self.file.to_string(),
            line: crate::locate::line(self.text, field),
            field: field.to_string(),
            message: message.into(),
        }
    }

    fn number(&self, v: Option<&Value>, path: &str) -> Result<f32, GoalsError> {
        let v = v.ok_or_else(|| self.field(path, "missing"))?;
        let x = v
            .as_f64()
            .ok_or_else(|| self.field(path, format!("expected a number, found {v}")))?;
        let x = x as f32;
        if x.is_finite() {
            Ok(x)
        } else {
            Err(self.field(path, format!("not a finite number (as f32): {v}")))
        }
    }

    fn array<const N: usize>(&self, v: Option<&Value>, path: &str) -> Result<[f32; N], GoalsError> {
        let v = v.ok_or_else(|| self.field(path, "missing"))?;
        let a = v.as_array().filter(|a| a.len() == N).ok_or_else(|| {
            self.field(path, format!("expected an array of {N} numbers, found {v}"))
        })?;
        let mut out = [0.0; N];
        for (i, (o, x)) in out.iter_mut().zip(a).enumerate() {
            *o = self.number(Some(x), &format!("{path}[{i}]"))?;
        }
        Ok(out)
    }

    fn object<'v>(
        &self,
        v: &'v Value,
        path: &str,
        keys: &[&str],
    ) -> Result<&'v serde_json::Map<String, Value>, GoalsError> {
        let o = v
            .as_object()
            .ok_or_else(|| self.field(path, format!("expected an object, found {v}")))?;
        if let Some(k) = o.keys().find(|k| !keys.contains(&k.as_str())) {
            let expected = keys.join(", ");
            return Err(self.field(
                &format!("{path}.{k}"),
                format!("unknown field (expected {expected})"),
            ));
        }
        Ok(o)
    }

    fn segment(&self, body: &Body<'_>, v: Option<&Value>, path: &str) -> Result<u8, GoalsError> {
        let v = v.ok_or_else(|| self.field(path, "missing"))?;
        let name = v
            .as_str()
            .ok_or_else(|| self.field(path, format!("expected a segment name, found {v}")))?;
        body.find(name).ok_or_else(|| {
            let names: Vec<&str> = body.segments.iter().map(|s| s.name).collect();
            self.field(
                path,
                format!(
                    "unknown segment {name:?} (the segments are: {})",
                    names.join(", ")
                ),
            )
        })
    }

    fn goals(&self, body: &Body<'_>) -> Result<Vec<Goal>, GoalsError> {
        let list = self
            .root
            .get("goals")
            .ok_or_else(|| self.field("goals", "missing"))?
            .as_array()
            .ok_or_else(|| self.field("goals", "expected an array of goals"))?;
        let mut out = Vec::with_capacity(list.len());
        for (i, g) in list.iter().enumerate() {
            let path = format!("goals[{i}]");
            let o = self.object(g, &path, &["segment", "target", "weight", "point"])?;
            let segment = self.segment(body, o.get("segment"), &format!("{path}.segment"))?;
            let target =
                Vec3::from_array(self.array::<3>(o.get("target"), &format!("{path}.target"))?);
            let weight = self.number(o.get("weight"), &format!("{path}.weight"))?;
            if weight < 0.0 {
                return Err(self.field(&format!("{path}.weight"), "must be ≥ 0"));
            }
            let mut goal = Goal::reach(segment, target, weight);
            if let Some(p) = o.get("point") {
                goal = goal.at(Vec3::from_array(
                    self.array::<3>(Some(p), &format!("{path}.point"))?,
                ));
            }
            out.push(goal);
        }
        if out.len() > MAX_GOALS {
            return Err(self.field("goals", format!("more than {MAX_GOALS} goals")));
        }
        Ok(out)
    }

    fn start(&self, rig: &Rig<'_>) -> Result<Angles<MAX_SEGMENTS>, GoalsError> {
        let rest = rig
            .rest_angles::<MAX_SEGMENTS>()
            .map_err(|e| self.field("start", format!("the rig has no rest pose: {e:?}")))?;
        match self.root.get("start") {
            None => Ok(rest),
            Some(Value::String(s)) if s == "rest" => Ok(rest),
            Some(Value::String(s)) => {
                Err(self.field("start", format!("expected \"rest\" or a pose, found {s:?}")))
            }
            Some(v) => self.start_pose(rig, v),
        }
    }

    /// The warm start from a world pose (see the module doc).
    fn start_pose(&self, rig: &Rig<'_>, v: &Value) -> Result<Angles<MAX_SEGMENTS>, GoalsError> {
        let body = rig.body();
        // Other keys (`synth --json`'s `duration`, `travel`, ...) are
        // ignored, so a synthesized pose is a start as it is.
        let o = v.as_object().ok_or_else(|| {
            self.field("start", format!("expected \"rest\" or a pose, found {v}"))
        })?;
        let list = o.get("segments").and_then(Value::as_array).ok_or_else(|| {
            self.field(
                "start.segments",
                "expected an array of {name, position, rotation}",
            )
        })?;
        let n = body.len();
        let mut given: Vec<Option<(Vec3, Quat)>> = vec![None; n];
        for (i, s) in list.iter().enumerate() {
            let path = format!("start.segments[{i}]");
            let so = self.object(s, &path, &["name", "position", "rotation"])?;
            let seg = usize::from(self.segment(&body, so.get("name"), &format!("{path}.name"))?);
            let p =
                Vec3::from_array(self.array::<3>(so.get("position"), &format!("{path}.position"))?);
            let [w, x, y, z] = self.array::<4>(so.get("rotation"), &format!("{path}.rotation"))?;
            let q = Quat::from_xyzw(x, y, z, w);
            let n2 = marionette_core::math::quat_dot(q, q);
            if !(1e-6..1e6).contains(&n2) {
                return Err(self.field(&format!("{path}.rotation"), "not a rotation (length 0)"));
            }
            match given.get_mut(seg) {
                Some(slot @ None) => *slot = Some((p, marionette_core::math::normalize_quat(q))),
                _ => return Err(self.field(&format!("{path}.name"), "segment listed twice")),
            }
        }
        let (root_position, root_rotation) = rig.root();
        let mut world =
            Pose::<MAX_SEGMENTS>::new(n).map_err(|e| self.field("start", format!("{e:?}")))?;
        for i in 0..n {
            let parent = body.parents.get(i).copied().unwrap_or(NO_PARENT);
            let inherited = if parent == NO_PARENT {
                root_rotation
            } else {
                world
                    .rotations
                    .get(usize::from(parent))
                    .copied()
                    .unwrap_or(Quat::IDENTITY)
            };
            let (p, q) = given
                .get(i)
                .copied()
                .flatten()
                .unwrap_or((root_position, inherited));
            if let (Some(wp), Some(wq)) = (world.positions.get_mut(i), world.rotations.get_mut(i)) {
                *wp = p;
                *wq = q;
            }
        }
        let mut local = LocalPose::<MAX_SEGMENTS>::default();
        pose::to_local(&body.hierarchy(), &world, &mut local)
            .map_err(|e| self.field("start", format!("{e:?}")))?;
        Angles::from_local(&body, &local).map_err(|e| self.field("start", format!("{e:?}")))
    }
}
