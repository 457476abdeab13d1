//! Measurements of a built table: quantization error against the
//! unquantized table, and held-out error on real data.
//!
//! # Quantization
//!
//! [`quantization`] decodes every stored segment sample of the blob with the
//! core reader and compares it with the `f32` sample given to the writer
//! (position per coordinate, rotation as the angle of the relative
//! rotation, in `f64`), and synthesizes at 2,000 pseudo-random parameter
//! points (a fixed LCG) from both the blob and the unquantized samples with
//! the same core grid, comparing every segment of the two poses.
//!
//! # Hold-out
//!
//! [`holdout`] removes one clip (group) from the examples, builds the table
//! from the rest exactly as `marionette build` does (method chosen by
//! cross-validation on the remaining clips), writes and parses the blob, and
//! synthesizes with the core at each held-out example's parameters. It
//! reports, over the held-out examples, the hand (probe segment) position
//! error and the mean per-joint position error, both in the build frame.
//! For a grid table on a rig of at most 64 segments it then solves the hand
//! goal with the core's default solver ([`marionette_core::solve`], whole-tree
//! damped least squares, root fixed, the rig file's joints and limits)
//! starting from the synthesized pose, and reports both errors again.
//!
//! The baseline, measured in the same run on the same held-out examples, is
//! the **nearest example**: each held-out example predicted by the training
//! example (from the other clips) with the nearest parameters (Euclidean, in
//! axis units), its whole pose or clip taken as is ([`Baseline`]). A table is
//! worth its flash only if it beats that.

use glam::{Quat, Vec3};
use marionette_core::grid::{Adjust, SliceSamples};
use marionette_core::pose::Pose;
use marionette_core::table::{Table, Wrap};
use serde::Serialize;

use super::error::BuildError;
use super::place::RigBody;
use super::resample::{self, Value, compare, median};
use super::retarget::CAP;
use super::spec::Spec;
use super::{Dataset, Layout, Progress, query};
use crate::blob::TableSpec;

/// Measured quantization error.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Quantization {
    /// Largest per-coordinate position error of a stored sample, metres.
    pub max_position: f64,
    /// Largest rotation error of a stored sample, radians.
    pub max_rotation: f64,
    /// The header's stated position bound, metres.
    pub position_bound: f64,
    /// The header's stated rotation bound, radians.
    pub rotation_bound: f64,
    /// Parameter points synthesized from both tables.
    pub synth_points: usize,
    /// Largest per-coordinate position difference of synthesized poses, m.
    pub synth_max_position: f64,
    /// Largest rotation difference of synthesized poses, radians.
    pub synth_max_rotation: f64,
}

fn angle(a: Quat, b: Quat) -> f64 {
    resample::rotation_angle(a.as_dquat().normalize(), b.as_dquat().normalize())
}

fn readback(e: impl std::fmt::Debug) -> BuildError {
    BuildError::Readback(format!("{e:?}"))
}

/// Measures the blob against the unquantized table (see the module doc).
pub fn quantization(spec: &TableSpec, blob: &[u8]) -> Result<Quantization, BuildError> {
    let table = Table::parse(blob).map_err(readback)?;
    let mut q = Quantization {
        position_bound: f64::from(table.header().position_bound),
        rotation_bound: f64::from(table.header().rotation_bound),
        ..Quantization::default()
    };
    for (i, sample) in spec.samples.iter().enumerate() {
        for (s, &(p, r)) in sample.iter().enumerate() {
            let (dp, dr) = table
                .sample(i, s)
                .ok_or_else(|| readback("missing sample"))?;
            q.max_position = q.max_position.max(f64::from((dp - p).abs().max_element()));
            q.max_rotation = q.max_rotation.max(angle(dr, r));
        }
    }
    let segments = spec.segment_names.len();
    let positions: Vec<Vec3> = spec.samples.iter().flatten().map(|s| s.0).collect();
    let rotations: Vec<Quat> = spec
        .samples
        .iter()
        .flatten()
        .map(|s| s.1.normalize())
        .collect();
    let exact = SliceSamples::new(segments, &positions, &rotations)
        .ok_or_else(|| readback("sample shape"))?;
    let grid = table.grid().map_err(readback)?;
    let mut rng = Lcg(0x5eed);
    let mut a = Box::new(Pose::<CAP>::default());
    let mut b = Box::new(Pose::<CAP>::default());
    for _ in 0..2000 {
        let params: Vec<f32> = table
            .axes()
            .iter()
            .map(|ax| {
                let span = match ax.wrap {
                    Wrap::Bounded => f32::from(ax.count - 1) * ax.step,
                    Wrap::Cyclic { period } => period,
                };
                ax.min + rng.unit() * span
            })
            .collect();
        let query = grid.query(&params).map_err(readback)?;
        query.pose(&table, &mut a).map_err(readback)?;
        query.pose(&exact, &mut b).map_err(readback)?;
        for ((pa, ra), (pb, rb)) in a
            .positions()
            .iter()
            .zip(a.rotations())
            .zip(b.positions().iter().zip(b.rotations()))
        {
            q.synth_max_position = q
                .synth_max_position
                .max(f64::from((*pa - *pb).abs().max_element()));
            q.synth_max_rotation = q.synth_max_rotation.max(angle(*ra, *rb));
        }
        q.synth_points += 1;
    }
    Ok(q)
}

/// A tiny deterministic generator (64-bit LCG, Knuth's constants).
struct Lcg(u64);

impl Lcg {
    fn unit(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// The source clips of a motion table synthesized back from its blob.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Reconstruction {
    /// Source frames compared.
    pub frames: usize,
    /// Mean over frames of the mean per-joint position error, metres.
    pub mean_joint: f64,
    /// Largest per-joint position error, metres.
    pub max_joint: f64,
    /// Mean per-joint rotation error, radians.
    pub mean_rotation: f64,
}

/// Synthesizes each source clip (but `exclude`) at its own parameters and
/// at the phase of each of its original frames, and compares with those
/// frames: what time resampling, the seam blend and quantization lose
/// (`None` for a grid table).
pub fn reconstruction(
    data: &Dataset,
    blob: &[u8],
    exclude: Option<usize>,
) -> Result<Option<Reconstruction>, BuildError> {
    if data.originals.is_empty() {
        return Ok(None);
    }
    let table = Table::parse(blob).map_err(readback)?;
    let mut r = Reconstruction {
        frames: 0,
        mean_joint: 0.0,
        max_joint: 0.0,
        mean_rotation: 0.0,
    };
    for rec in data.records.iter().filter(|r| Some(r.group) != exclude) {
        let params: Vec<f32> = rec.params.iter().map(|&p| p as f32).collect();
        for (phase, truth) in &data.originals[rec.group] {
            let s = query::synthesize(&table, &params, Some(*phase as f32))
                .map_err(|e| BuildError::Data(e.to_string()))?;
            let n = truth.len() as f64;
            for ((p, q), (tp, tq)) in s.pose.iter().zip(truth) {
                let d = (p.as_dvec3() - *tp).length();
                r.mean_joint += d / n;
                r.max_joint = r.max_joint.max(d);
                r.mean_rotation += resample::rotation_angle(q.as_dquat(), *tq) / n;
            }
            r.frames += 1;
        }
    }
    let f = r.frames.max(1) as f64;
    r.mean_joint /= f;
    r.mean_rotation /= f;
    Ok(Some(r))
}

/// Errors after solving the hand goal.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Solved {
    /// Median hand error, metres.
    pub median_probe: f64,
    /// Mean over examples of the mean per-joint position error, metres.
    pub mean_joint: f64,
    /// Examples whose solve the core refused.
    pub failures: usize,
}

/// The result of one hold-out.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Holdout {
    /// The held-out clip.
    pub clip: String,
    /// Held-out examples evaluated.
    pub examples: usize,
    /// The method the build chose without this clip.
    pub method: String,
    /// Median hand (probe) position error, metres.
    pub median_probe: Option<f64>,
    /// Mean over examples of the mean per-joint position error, metres.
    pub mean_joint: f64,
    /// Median over examples of the mean per-joint position error, metres.
    pub median_joint: f64,
    /// Mean per-joint rotation error, radians.
    pub mean_rotation: f64,
    /// Examples whose parameters fell in an invalid cell (projected).
    pub projected: usize,
    /// Examples whose parameters were outside the axes (clamped).
    pub clamped: usize,
    /// Mean relative error of the interpolated durations (clip tables).
    pub duration_error: Option<f64>,
    /// After solving the hand goal (grid tables).
    pub solved: Option<Solved>,
    /// The baseline: each held-out example predicted by the nearest
    /// training example (nearest parameters, whole pose or clip).
    pub nearest: Baseline,
    /// Per held-out example: hand error of the table, metres.
    #[serde(skip)]
    pub probe_errors: Vec<f64>,
    /// Per held-out example: mean per-joint error of the table, metres.
    #[serde(skip)]
    pub joint_errors: Vec<f64>,
}

/// The nearest-example baseline of one hold-out.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Baseline {
    /// Median hand (probe) position error, metres.
    pub median_probe: Option<f64>,
    /// Mean over examples of the mean per-joint position error, metres.
    pub mean_joint: f64,
    /// Per held-out example: hand error, metres.
    #[serde(skip)]
    pub probe_errors: Vec<f64>,
    /// Per held-out example: mean per-joint error, metres.
    #[serde(skip)]
    pub joint_errors: Vec<f64>,
}

/// The nearest-example baseline: each held-out record predicted by the
/// training record with the nearest parameters (Euclidean, axis units).
fn nearest_baseline(data: &Dataset, group: usize) -> Baseline {
    let train: Vec<&resample::Record> = data.records.iter().filter(|r| r.group != group).collect();
    let mut b = Baseline {
        median_probe: None,
        mean_joint: f64::NAN,
        probe_errors: Vec::new(),
        joint_errors: Vec::new(),
    };
    let probe = data.probe.map(|i| (i, data.probe_point));
    for r in data.records.iter().filter(|r| r.group == group) {
        let d2 = |t: &resample::Record| -> f64 {
            t.params
                .iter()
                .zip(&r.params)
                .map(|(a, b)| (a - b) * (a - b))
                .sum()
        };
        let Some(near) = train.iter().min_by(|a, b| d2(a).total_cmp(&d2(b))) else {
            continue;
        };
        let e = compare(&near.value, &r.value, probe);
        b.joint_errors.push(e.mean_position);
        b.probe_errors.extend(e.probe);
    }
    b.mean_joint = resample::mean(&b.joint_errors);
    b.median_probe = median(&mut b.probe_errors.clone());
    b
}

/// Leaves group `group` out, builds from the rest, and measures (see the
/// module doc).
pub fn holdout(
    spec: &Spec,
    data: &Dataset,
    group: usize,
    progress: &Progress,
) -> Result<Holdout, BuildError> {
    let built = super::build(spec, data, Some(group), progress)?;
    let table = Table::parse(&built.blob).map_err(readback)?;
    let held: Vec<&resample::Record> = data.records.iter().filter(|r| r.group == group).collect();
    let solver = data
        .rig
        .as_ref()
        .zip(data.probe_segment)
        .filter(|_| data.layout == Layout::Grid);
    let body = solver.and_then(|(rig, _)| RigBody::new(rig));
    let mut probes = Vec::new();
    let mut joints = Vec::new();
    let mut rotations = Vec::new();
    let mut durations = Vec::new();
    let (mut projected, mut clamped) = (0, 0);
    let (mut solved_probe, mut solved_joint, mut failures) = (Vec::new(), Vec::new(), 0);
    progress.stage("synthesizing held-out examples", held.len());
    for r in &held {
        let params: Vec<f32> = r.params.iter().map(|&p| p as f32).collect();
        let (frames, synth) =
            query::frames(&table, &params).map_err(|e| BuildError::Data(e.to_string()))?;
        match synth.adjust {
            Adjust::Projected => projected += 1,
            Adjust::Clamped => clamped += 1,
            Adjust::None => {}
        }
        let pred = Value {
            poses: frames
                .iter()
                .flatten()
                .map(|(p, q)| (p.as_dvec3(), q.as_dquat()))
                .collect(),
            scalars: synth.durations.iter().map(|&d| f64::from(d)).collect(),
        };
        let e = compare(&pred, &r.value, data.probe.map(|i| (i, data.probe_point)));
        joints.push(e.mean_position);
        rotations.push(e.mean_rotation);
        probes.extend(e.probe);
        if !r.value.scalars.is_empty() {
            let rel: f64 = pred
                .scalars
                .iter()
                .zip(&r.value.scalars)
                .map(|(p, t)| ((p - t) / t).abs())
                .sum();
            durations.push(rel / pred.scalars.len().max(1) as f64);
        }
        if let (Some(body), Some((_, seg))) = (&body, solver) {
            let (p, q) = r.value.poses[seg];
            let point = data.probe_point;
            let target = (p + q * point).as_vec3();
            match body.solve(&frames[0], seg, point.as_vec3(), target) {
                Some(solved) => {
                    let e = compare(&solved.value, &r.value, Some((seg, point)));
                    solved_joint.push(e.mean_position);
                    solved_probe.extend(e.probe);
                }
                None => failures += 1,
            }
        }
        progress.tick();
    }
    let probe_errors = probes.clone();
    let joint_errors = joints.clone();
    Ok(Holdout {
        nearest: nearest_baseline(data, group),
        probe_errors,
        joint_errors,
        clip: data.groups.get(group).cloned().unwrap_or_default(),
        examples: held.len(),
        method: built.report.method.to_string(),
        median_probe: median(&mut probes),
        mean_joint: resample::mean(&joints),
        median_joint: median(&mut joints).unwrap_or(f64::NAN),
        mean_rotation: resample::mean(&rotations),
        projected,
        clamped,
        duration_error: (!durations.is_empty()).then(|| resample::mean(&durations)),
        solved: body.map(|_| Solved {
            median_probe: median(&mut solved_probe).unwrap_or(f64::NAN),
            mean_joint: resample::mean(&solved_joint),
            failures,
        }),
    })
}
