//! Synthesis from a table blob, read in place by the core: the one path
//! that `marionette synth` and the hold-out measurement share.

use glam::{Quat, Vec3};
use marionette_core::clip::{ClipError, Clips};
use marionette_core::grid::{Adjust, GridError};
use marionette_core::pose::Pose;
use marionette_core::table::{Kind, Table};

use super::retarget::CAP;

/// Why a synthesis failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum QueryError {
    /// Wrong number of parameters.
    #[error("the table has {expected} parameter axes ({names}), got {found} values")]
    ParamCount {
        /// Axes.
        expected: usize,
        /// Their names.
        names: String,
        /// Values given.
        found: usize,
    },
    /// The core's grid refused.
    #[error("synthesis: {0:?}")]
    Grid(GridError),
    /// The core's clip synthesis refused.
    #[error("clip synthesis: {0:?}")]
    Clip(ClipError),
}

impl From<GridError> for QueryError {
    fn from(e: GridError) -> Self {
        QueryError::Grid(e)
    }
}

impl From<ClipError> for QueryError {
    fn from(e: ClipError) -> Self {
        QueryError::Clip(e)
    }
}

/// One pose: (position, rotation) per segment.
pub type PoseVec = Vec<(Vec3, Quat)>;

/// A synthesized pose.
#[derive(Debug, Clone, PartialEq)]
pub struct Synth {
    /// One (position, rotation) per segment, in the table's order.
    pub pose: PoseVec,
    /// Total duration of the synthesized motion, seconds (clip tables).
    pub duration: Option<f32>,
    /// Per-phase durations (clip tables).
    pub durations: Vec<f32>,
    /// A looping clip's root displacement per cycle (x, y, z metres, the
    /// clip frame): the figure advances by it each cycle.
    pub travel: Option<[f32; 3]>,
    /// What the query did to the parameters (or, for a one-shot clip
    /// table, to a phase outside `[0, phases]`: clamped).
    pub adjust: Adjust,
    /// The parameters actually used.
    pub params: Vec<f32>,
}

fn check_params(table: &Table<'_>, params: &[f32]) -> Result<(), QueryError> {
    let axes = table.param_axes();
    if params.len() != axes.len() {
        return Err(QueryError::ParamCount {
            expected: axes.len(),
            names: axes
                .iter()
                .map(|a| a.name().unwrap_or("?"))
                .collect::<Vec<_>>()
                .join(", "),
            found: params.len(),
        });
    }
    Ok(())
}

fn pose_vec(p: &Pose<CAP>) -> PoseVec {
    p.positions()
        .iter()
        .copied()
        .zip(p.rotations().iter().copied())
        .collect()
}

/// The pose at `params` (and, for clip tables, at `phase` in `[0, phases]`,
/// default 0).
pub fn synthesize(
    table: &Table<'_>,
    params: &[f32],
    phase: Option<f32>,
) -> Result<Synth, QueryError> {
    check_params(table, params)?;
    let mut out = Box::new(Pose::<CAP>::default());
    match table.kind() {
        Kind::Grid => {
            let grid = table.grid()?;
            let q = grid.query(params)?;
            q.pose(table, &mut out)?;
            Ok(Synth {
                pose: pose_vec(&out),
                duration: None,
                durations: Vec::new(),
                travel: None,
                adjust: q.adjust(),
                params: q.params().to_vec(),
            })
        }
        Kind::Clips { phases } => {
            let clips = Clips::new(table.grid()?, table.param_grid()?, usize::from(phases))?;
            let motion = clips.motion(table, params)?;
            let phase_adjust = clips.pose(&motion, table, phase.unwrap_or(0.0), &mut out)?;
            // A phase outside a one-shot motion is clamped: say so.
            let adjust = match (motion.adjust(), phase_adjust) {
                (Adjust::None, Adjust::Clamped) => Adjust::Clamped,
                (a, _) => a,
            };
            Ok(Synth {
                pose: pose_vec(&out),
                duration: Some(motion.duration()),
                durations: motion.durations().to_vec(),
                travel: clips.looping().then(|| motion.travel().to_array()),
                adjust,
                params: motion.params().to_vec(),
            })
        }
    }
}

/// Every stored frame of the motion at `params` (clip tables; a grid gives
/// its one pose): frame `j` at phase `j / frames-per-phase`.
pub fn frames(table: &Table<'_>, params: &[f32]) -> Result<(Vec<PoseVec>, Synth), QueryError> {
    let first = synthesize(table, params, None)?;
    let Kind::Clips { .. } = table.kind() else {
        return Ok((vec![first.pose.clone()], first));
    };
    let phase_axis = table.axes().last().copied();
    let (count, step) = phase_axis.map_or((1, 1.0), |a| (usize::from(a.count), a.step));
    let out = (0..count)
        .map(|j| synthesize(table, params, Some(j as f32 * step)).map(|s| s.pose))
        .collect::<Result<Vec<_>, _>>()?;
    Ok((out, first))
}
