//! `marionette build`: mocap or a JSON example set → a table blob.
//!
//! The pipeline (DESIGN §1 step 3):
//!
//! 1. **Examples.** From a JSON example set ([`examples`], a public
//!    contract) or from mocap clips ([`mocap`]): imported, put through the
//!    core's forward kinematics, **retargeted** to the rig ([`retarget`]),
//!    expressed in the build frame, with their parameters measured (the right
//!    hand's position in the heading frame, the walking speed, ...). Motion
//!    tables time-resample each clip to a common frame count, with the loop
//!    seam blended.
//! 2. **Resampling** onto the regular grid ([`resample`]): the method (IDW,
//!    Gaussian RBF, local linear regression, each with a few settings) is
//!    chosen by cross-validated held-out error, and cells far from every
//!    example are marked invalid. On a grid of one point's x, y and z (the
//!    hand), each resampled pose is then solved so that point sits on its
//!    grid point ([`place`]); the cross-validation scores the methods with
//!    that step included.
//! 3. **Writing** with the one blob writer, [`crate::blob::write`], which
//!    quantizes (12 bytes per segment sample, error bound in the header) and
//!    checksums; the blob is read back with the core reader and the
//!    quantization error is measured against the unquantized table
//!    ([`measure`]).
//!
//! [`measure::holdout`] leaves one clip out, builds from the rest and
//! synthesizes at the held-out clip's parameters with the core, reading the
//! blob in place, beside the nearest-example baseline.

pub mod error;
pub mod examples;
pub mod measure;
pub mod mocap;
pub mod place;
pub mod query;
pub mod resample;
pub mod retarget;
pub mod spec;

use std::cell::Cell;
use std::time::Instant;

use glam::{DQuat, DVec3, Quat, Vec3};
use marionette_core::pose::{self, Pose};
use marionette_core::table::{Interp, Kind, Wrap};

use crate::blob::{self, AxisSpec, TableSpec};
pub use error::{BuildError, InputError};
use resample::{Method, Record, Score, Space, Value};
use retarget::{CAP, Fnv, Rig};
use spec::{Input, ResampleSpec, Spec};

/// One segment of a pose: absolute position (m) and rotation.
pub type Seg = (DVec3, DQuat);

/// A parameter axis with its range (the JSON contract's axis).
#[derive(Debug, Clone, PartialEq)]
pub struct AxisDef {
    /// Name (≤ 24 bytes).
    pub name: String,
    /// First sample.
    pub min: f64,
    /// Last sample (bounded) or `min` + period (cyclic).
    pub max: f64,
    /// Samples (≥ 2).
    pub count: u16,
    /// Cyclic.
    pub cyclic: bool,
    /// Catmull-Rom.
    pub cubic: bool,
}

impl AxisDef {
    /// Checks name, count and range.
    pub fn check(&self) -> Result<(), String> {
        examples::check_name(&self.name)?;
        if self.count < 2 {
            return Err(format!("count must be at least 2, found {}", self.count));
        }
        if !(self.min.is_finite() && self.max.is_finite() && self.max > self.min) {
            return Err(format!(
                "needs finite min < max, found min {} max {}",
                self.min, self.max
            ));
        }
        Ok(())
    }

    /// Spacing of the samples.
    #[must_use]
    pub fn step(&self) -> f64 {
        let n = f64::from(self.count);
        (self.max - self.min) / if self.cyclic { n } else { n - 1.0 }
    }

    /// Number of cells.
    #[must_use]
    pub fn cells(&self) -> usize {
        usize::from(self.count) - usize::from(!self.cyclic)
    }

    /// The writer's axis.
    #[must_use]
    pub fn to_blob(&self) -> AxisSpec {
        let step = self.step() as f32;
        AxisSpec {
            name: self.name.clone(),
            min: self.min as f32,
            step,
            count: self.count,
            wrap: if self.cyclic {
                Wrap::Cyclic {
                    period: f32::from(self.count) * step,
                }
            } else {
                Wrap::Bounded
            },
            interp: if self.cubic {
                Interp::CatmullRom
            } else {
                Interp::Linear
            },
        }
    }
}

/// What the examples' values are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// One pose each.
    Grid,
    /// One time-resampled clip each.
    Clips {
        /// Phases per clip.
        phases: usize,
        /// Frames per phase.
        frames: usize,
        /// One cyclic phase.
        looping: bool,
    },
}

impl Layout {
    /// Frames per example value.
    #[must_use]
    pub fn frames(&self) -> usize {
        match *self {
            Layout::Grid => 1,
            Layout::Clips {
                frames,
                looping: true,
                ..
            } => frames,
            Layout::Clips { phases, frames, .. } => phases * frames + 1,
        }
    }
}

/// Everything the resampler needs.
#[derive(Debug, Clone)]
pub struct Dataset {
    /// Segment names.
    pub segments: Vec<String>,
    /// Parameter axes, ranges filled in.
    pub axes: Vec<AxisDef>,
    /// The examples.
    pub records: Vec<Record>,
    /// Group names (clip names, or `examples`).
    pub groups: Vec<String>,
    /// Grid or clips.
    pub layout: Layout,
    /// The rig (mocap), for limb-length enforcement and solving.
    pub rig: Option<Rig>,
    /// The table's rig hash.
    pub rig_hash: u64,
    /// Index into a value's poses of the probe (the hand): the segment the
    /// parameters are measured on, at the frame they are measured at.
    pub probe: Option<usize>,
    /// The segment the parameters are measured on.
    pub probe_segment: Option<usize>,
    /// The point of the probe segment the parameters are measured at, in
    /// the segment's frame (an axis' `point`; zero: its origin).
    pub probe_point: glam::DVec3,
    /// The axes measuring the probe's x, y and z, when the axes are exactly
    /// those three (a hand-position grid; see [`place`]).
    pub probe_axes: Option<[usize; 3]>,
    /// Maps a point given by the parameters into the poses' frame (the
    /// identity but for `frame = "stand"`).
    pub param_frame: mocap::Frame,
    /// Clip tables: each group's normalized source frames with their phases.
    pub originals: Vec<mocap::Originals>,
    /// Looping clip tables: each clip's seam (the cut given and used).
    pub seams: Vec<mocap::Seam>,
    /// Seconds spent importing.
    pub load_seconds: f64,
    /// Import warnings (a clip whose frame rate looks wrong), each naming
    /// the spec file, line and field.
    pub warnings: Vec<String>,
}

pub use crate::progress::Progress;

/// Loads the examples of a spec.
pub fn load(spec: &Spec, progress: &Progress) -> Result<Dataset, BuildError> {
    let start = Instant::now();
    let mut data = match &spec.input {
        Input::Examples(path) => {
            let mut data = from_examples(&examples::read(path)?);
            if let Some(rig) = &spec.rig.file {
                data.rig_hash = examples_rig_hash(spec, rig, path, &data.segments)?;
            }
            data
        }
        Input::Mocap(m) => {
            progress.stage("importing mocap", m.clips.len());
            let mocap = mocap::load(spec, m, &|_| progress.tick())?;
            from_mocap(spec, m, mocap)?
        }
    };
    data.load_seconds = start.elapsed().as_secs_f64();
    Ok(data)
}

/// The hash of the spec's `[rig] file` for an example set, whose segments
/// must be the rig's, in its order (the table is then built for that rig).
fn examples_rig_hash(
    spec: &Spec,
    rig: &std::path::Path,
    set: &std::path::Path,
    segments: &[String],
) -> Result<u64, BuildError> {
    let file = crate::rigfile::load(rig).map_err(|e| {
        spec.source
            .error_line(spec.rig.line, "rig.file", e.to_string())
    })?;
    if file.segment_names() != segments {
        let src = error::Source::read(set)?;
        let line = crate::locate::line(&src.text, "segments");
        return Err(src
            .error_line(
                line,
                "segments",
                format!(
                    "the example set's segments ({}) are not the rig's ({}: {}), in order",
                    segments.join(", "),
                    rig.display(),
                    file.segment_names().join(", ")
                ),
            )
            .into());
    }
    Ok(file.rig_hash())
}

fn from_examples(set: &examples::ExampleSet) -> Dataset {
    let mut h = Fnv::new();
    for s in &set.segments {
        h.bytes(s.as_bytes());
        h.bytes(&[0]);
    }
    let records = set
        .examples
        .iter()
        .enumerate()
        .map(|(i, e)| Record {
            params: e.params.clone(),
            value: Value {
                poses: e.pose.clone(),
                scalars: Vec::new(),
            },
            group: i,
        })
        .collect();
    Dataset {
        segments: set.segments.clone(),
        axes: set.axes.clone(),
        records,
        groups: (0..set.examples.len())
            .map(|i| format!("examples[{i}]"))
            .collect(),
        layout: Layout::Grid,
        rig: None,
        rig_hash: h.0,
        probe: None,
        probe_segment: None,
        probe_point: glam::DVec3::ZERO,
        probe_axes: None,
        param_frame: mocap::Frame::WORLD,
        originals: Vec::new(),
        seams: Vec::new(),
        load_seconds: 0.0,
        warnings: Vec::new(),
    }
}

fn from_mocap(
    spec: &Spec,
    m: &spec::MocapSpec,
    mocap: mocap::Mocap,
) -> Result<Dataset, BuildError> {
    let layout = match spec.kind {
        spec::Kind::Grid => Layout::Grid,
        spec::Kind::Clips => Layout::Clips {
            phases: m.clips[0].cut.len() - 1,
            frames: spec.motion.frames,
            looping: spec.motion.looping,
        },
    };
    if let Layout::Clips {
        phases,
        looping: true,
        ..
    } = layout
        && phases != 1
    {
        let problem = "a looping motion has one phase: cut = [first, last]";
        return Err(spec
            .source
            .error_line(m.clips[0].line, "clip[0].cut", problem)
            .into());
    }
    let (records, originals, seams) = match layout {
        Layout::Grid => (
            mocap::grid_records(spec, m, &mocap)?,
            Vec::new(),
            Vec::new(),
        ),
        Layout::Clips { .. } => mocap::clip_records(spec, m, &mocap)?,
    };
    let axes = spec
        .axes
        .iter()
        .enumerate()
        .map(|(k, a)| {
            let (lo, hi) = records
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), r| {
                    (lo.min(r.params[k]), hi.max(r.params[k]))
                });
            let def = a.def(lo, hi);
            def.check()
                .map(|()| def)
                .map_err(|p| spec.source.error_line(a.line, &format!("axis[{k}]"), p))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let segs = mocap::measure_segments(spec, &mocap.rig)?;
    let points: Vec<[f64; 3]> = spec
        .axes
        .iter()
        .filter_map(|a| match &a.measure {
            spec::Measure::Position { point, .. } => Some(*point),
            _ => None,
        })
        .collect();
    let probe_point = points.first().copied().unwrap_or_default();
    let probe_segment = match segs.as_slice() {
        [Some(first), rest @ ..]
            if rest.iter().all(|s| *s == Some(*first))
                && points.iter().all(|p| *p == probe_point) =>
        {
            Some(*first)
        }
        _ => None,
    };
    let at_frame = match layout {
        Layout::Clips {
            phases: 2..,
            frames,
            ..
        } => frames,
        _ => 0,
    };
    let segments = mocap.rig.names.len();
    let probe = probe_segment.map(|s| at_frame * segments + s);
    let probe_axes = probe_segment.and_then(|_| probe_axes(spec));
    let param_frame = if spec.frame == spec::FrameKind::Stand {
        let (p, q) = mocap.rig.rest_root();
        mocap::Frame::placing(p, q)
    } else {
        mocap::Frame::WORLD
    };
    Ok(Dataset {
        segments: mocap.rig.names.clone(),
        axes,
        records,
        groups: mocap.clips.iter().map(|c| c.name.clone()).collect(),
        warnings: mocap.warnings,
        layout,
        rig_hash: mocap.rig.hash,
        rig: Some(mocap.rig),
        probe,
        probe_segment,
        probe_point: glam::DVec3::from_array(probe_point),
        probe_axes,
        param_frame,
        originals,
        seams,
        load_seconds: 0.0,
    })
}

/// The axes measuring x, y and z of one probe, when those are all the axes.
fn probe_axes(spec: &Spec) -> Option<[usize; 3]> {
    let mut out = [None; 3];
    for (i, a) in spec.axes.iter().enumerate() {
        let spec::Measure::Position { component, .. } = a.measure else {
            return None;
        };
        let slot = out.get_mut(component)?;
        if slot.replace(i).is_some() {
            return None;
        }
    }
    let [x, y, z] = out;
    Some([x?, y?, z?])
}

/// The measured facts of one build.
#[derive(Debug, Clone)]
pub struct Report {
    /// Examples used.
    pub examples: usize,
    /// Groups (clips) used.
    pub groups: usize,
    /// The method used.
    pub method: Method,
    /// Cross-validation scores of every candidate (empty if not run).
    pub scores: Vec<Score>,
    /// Grid samples (all axes, phase included).
    pub grid_samples: usize,
    /// Valid parameter cells.
    pub valid_cells: usize,
    /// Parameter cells.
    pub cells: usize,
    /// Grid samples taken exactly from an example.
    pub exact: usize,
    /// Grid samples whose probe the build solved onto its grid point
    /// ([`place`]; 0 when the table is not a probe-position grid).
    pub placed: usize,
    /// Grid samples a placement was tried on (the resampled ones).
    pub place_tried: Option<usize>,
    /// Blob size, bytes.
    pub bytes: usize,
    /// Measured quantization error.
    pub quant: measure::Quantization,
    /// Clip tables: the source clips synthesized back from the blob.
    pub reconstruction: Option<measure::Reconstruction>,
    /// Seconds: import, cross-validation, resampling, writing.
    pub seconds: [f64; 4],
}

/// A built table.
#[derive(Debug, Clone)]
pub struct Built {
    /// The unquantized table given to the writer.
    pub table: TableSpec,
    /// The blob.
    pub blob: Vec<u8>,
    /// What was measured.
    pub report: Report,
}

/// The post-processing of a resampled value at `params`: the probe placed
/// on its point ([`place`]) where the spec asks and the rig reaches it,
/// else limb-length enforcement. Counts the placements in `placed`.
fn post<'a>(
    data: &'a Dataset,
    spec: &ResampleSpec,
    placed: &'a Cell<usize>,
) -> impl Fn(&[f64], &mut Value) + 'a {
    let placer = place::Placer::new(data).filter(|_| spec.place_probe);
    let enforce = spec.enforce_lengths;
    move |params: &[f64], v: &mut Value| {
        if placer.as_ref().is_some_and(|p| p.place(params, v)) {
            placed.set(placed.get() + 1);
            return;
        }
        let (Some(rig), true) = (&data.rig, enforce) else {
            return;
        };
        let n = data.segments.len();
        for frame in v.poses.chunks_mut(n) {
            let mut p = Pose::<CAP>::new(n).unwrap_or_default();
            for (i, (pos, rot)) in frame.iter().enumerate() {
                p.positions[i] = pos.as_vec3();
                p.rotations[i] = rot.as_quat();
            }
            if pose::enforce_lengths(&rig.hierarchy(), &mut p).is_ok() {
                for (s, np) in frame.iter_mut().zip(p.positions()) {
                    s.0 = np.as_dvec3();
                }
            }
        }
    }
}

/// Builds the table from `data`, leaving out group `exclude` (a hold-out).
pub fn build(
    spec: &Spec,
    data: &Dataset,
    exclude: Option<usize>,
    progress: &Progress,
) -> Result<Built, BuildError> {
    let records: Vec<Record> = data
        .records
        .iter()
        .filter(|r| Some(r.group) != exclude)
        .cloned()
        .collect();
    if records.is_empty() {
        return Err(BuildError::Data("no example left to build from".to_owned()));
    }
    let space = Space::new(&data.axes);
    let scored = Cell::new(0);
    let post_cv = post(data, &spec.resample, &scored);
    let t0 = Instant::now();
    let candidates = Method::candidates(&spec.resample.method);
    let folds = resample::folds(&records);
    let scores: Vec<Score> = if folds.is_empty() || candidates.len() == 1 {
        Vec::new()
    } else {
        progress.stage("cross-validating methods", candidates.len());
        candidates
            .iter()
            .map(|&m| {
                let probe = data.probe.map(|i| (i, data.probe_point));
                let s = resample::score(&space, &records, &folds, m, probe, &post_cv);
                progress.tick();
                s
            })
            .collect()
    };
    let method = scores
        .iter()
        .filter(|s| s.mean_position.is_finite())
        .min_by(|a, b| a.mean_position.total_cmp(&b.mean_position))
        .map_or(Method::fallback(&spec.resample.method), |s| s.method);
    let t1 = Instant::now();
    let radius = spec
        .resample
        .valid_radius
        .unwrap_or_else(|| (data.axes.len() as f64).sqrt() / 2.0);
    let points: usize = data.axes.iter().map(|a| usize::from(a.count)).product();
    progress.stage("resampling onto the grid", points);
    let placed = Cell::new(0);
    let post = post(data, &spec.resample, &placed);
    let grid = resample::grid(&space, &records, method, radius, &post, &|| progress.tick());
    let t2 = Instant::now();
    if !grid.valid.iter().any(|v| *v) {
        let (line, field) = match (spec.resample.line, spec.axes.first()) {
            (0, Some(a)) => (a.line, "axis[0]"),
            (l, _) => (l, "resample.valid_radius"),
        };
        let problem =
            "every grid cell is outside the data: widen `valid_radius` or move the axes' ranges";
        return Err(spec.source.error_line(line, field, problem).into());
    }
    let table = table_spec(data, &grid)?;
    let blob = blob::write(&table)?;
    let quant = measure::quantization(&table, &blob)?;
    let reconstruction = measure::reconstruction(data, &blob, exclude)?;
    let t3 = Instant::now();
    let mut groups: Vec<usize> = records.iter().map(|r| r.group).collect();
    groups.dedup();
    let report = Report {
        examples: records.len(),
        groups: groups.len(),
        method,
        scores,
        grid_samples: table.samples.len(),
        valid_cells: grid.valid.iter().filter(|v| **v).count(),
        cells: grid.valid.len(),
        exact: grid.exact,
        placed: placed.get(),
        place_tried: (place::Placer::new(data).is_some() && spec.resample.place_probe)
            .then(|| table.samples.len() - grid.exact),
        bytes: blob.len(),
        quant,
        reconstruction,
        seconds: [
            data.load_seconds,
            (t1 - t0).as_secs_f64(),
            (t2 - t1).as_secs_f64(),
            (t3 - t2).as_secs_f64(),
        ],
    };
    Ok(Built {
        table,
        blob,
        report,
    })
}

/// The writer's table from resampled values.
fn table_spec(data: &Dataset, grid: &resample::Resampled) -> Result<TableSpec, BuildError> {
    let n = data.segments.len();
    let f32_pose = |s: &[Seg]| -> Vec<(Vec3, Quat)> {
        s.iter().map(|(p, q)| (p.as_vec3(), q.as_quat())).collect()
    };
    let mut axes: Vec<AxisSpec> = data.axes.iter().map(AxisDef::to_blob).collect();
    let (kind, samples, durations, travel) = match data.layout {
        Layout::Grid => (
            Kind::Grid,
            grid.values.iter().map(|v| f32_pose(&v.poses)).collect(),
            Vec::new(),
            Vec::new(),
        ),
        Layout::Clips {
            phases,
            frames,
            looping,
        } => {
            let total = data.layout.frames();
            let step = 1.0 / frames as f32;
            axes.push(AxisSpec {
                name: "phase".to_owned(),
                min: 0.0,
                step,
                count: u16::try_from(total)
                    .map_err(|_| BuildError::Data("too many frames".to_owned()))?,
                wrap: if looping {
                    Wrap::Cyclic {
                        period: total as f32 * step,
                    }
                } else {
                    Wrap::Bounded
                },
                interp: Interp::Linear,
            });
            let mut samples = Vec::with_capacity(total * grid.values.len());
            for f in 0..total {
                for v in &grid.values {
                    samples.push(f32_pose(&v.poses[f * n..(f + 1) * n]));
                }
            }
            // Scalars: the phase durations, then a loop's root travel x, y, z.
            let durations = grid
                .values
                .iter()
                .flat_map(|v| v.scalars.iter().take(phases))
                .map(|&d| (d as f32).max(1e-3))
                .collect();
            let travel = if looping {
                grid.values
                    .iter()
                    .map(|v| {
                        let t = |k: usize| v.scalars.get(phases + k).map_or(0.0, |&x| x as f32);
                        [t(0), t(1), t(2)]
                    })
                    .collect()
            } else {
                Vec::new()
            };
            let phases =
                u8::try_from(phases).map_err(|_| BuildError::Data("too many phases".to_owned()))?;
            (Kind::Clips { phases }, samples, durations, travel)
        }
    };
    Ok(TableSpec {
        rig_hash: data.rig_hash,
        kind,
        axes,
        segment_names: data.segments.clone(),
        samples,
        valid: grid.valid.clone(),
        durations,
        travel,
    })
}
