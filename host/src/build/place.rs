//! Placing the probe where the parameters say: the build-time accuracy step
//! of a hand-position grid.
//!
//! A grid whose three axes are the x, y and z of one point of one segment
//! (the hand) stores, at each grid point, a pose whose hand should be *at*
//! that grid point. The resampling methods only come close: they average
//! examples whose hands are elsewhere. Because the core lerps positions with
//! weights that reproduce linear functions, a cell whose eight stored hands
//! sit exactly on its corners synthesizes the hand exactly at the query,
//! anywhere inside it (for a point off the segment's origin, to within the
//! small effect of slerping the segment's rotation). So each resampled grid
//! pose is corrected with the core's default solver (whole-tree damped least
//! squares, root fixed, joint limits of the rig file): the probe goes to its
//! grid point and the rest of the body follows by as little as the damped
//! step allows. Wiley & Hahn: "\[we\] can accommodate higher accuracy or
//! sparse data using iterative optimizations".
//!
//! The same solve measures a held-out pose "after solving" ([`RigBody`]).

use std::f32::consts::PI;

use glam::{DVec3, Quat, Vec3};
use marionette_core::body::{Angles, Axis, Body, Dof, Joint, Segment};
use marionette_core::goal::{Goal, GoalSet};
use marionette_core::pose::{self, LocalPose, Pose};
use marionette_core::solve::{self, Solver};

use super::Dataset;
use super::mocap::Frame;
use super::resample::Value;
use super::retarget::Rig;

/// The rig as a core body for the solver. From a rig file: the file's
/// joints, limits and touch points (through the core's runtime rig).
/// Without one: every joint a 3-DOF ball (Z, Y, X, ±180°).
pub struct RigBody {
    names: Vec<String>,
    parents: Vec<u8>,
    offsets: Vec<Vec3>,
    file: Option<Box<crate::rigfile::RigFile>>,
}

impl RigBody {
    /// The body of `rig` (`None` beyond the core's segment capacity).
    #[must_use]
    pub fn new(rig: &Rig) -> Option<Self> {
        (rig.names.len() <= marionette_core::pose::MAX_SEGMENTS).then(|| Self {
            names: rig.names.clone(),
            parents: rig.parents.clone(),
            offsets: rig.offsets.clone(),
            file: rig.file.clone(),
        })
    }

    /// Solves `point` of `segment` (in its frame) to `target` from `pose`;
    /// `None` if the core refuses.
    #[must_use]
    pub fn solve(
        &self,
        pose: &[(Vec3, Quat)],
        segment: usize,
        point: Vec3,
        target: Vec3,
    ) -> Option<Solved> {
        if let Some(file) = &self.file {
            let desc = file.desc();
            let rig = marionette_core::rig::Rig::from_desc(&desc).ok()?;
            return solve_body(&rig.body(), pose, segment, point, target);
        }
        let ball = Joint::three(
            Dof::new(Axis::Z, -PI, PI),
            Dof::new(Axis::Y, -PI, PI),
            Dof::new(Axis::X, -PI, PI),
        );
        let segments: Vec<Segment<'_>> = self
            .names
            .iter()
            .zip(&self.parents)
            .zip(&self.offsets)
            .enumerate()
            .map(|(i, ((name, &parent), &origin))| Segment {
                name,
                parent,
                origin,
                joint: if i == 0 { Joint::FIXED } else { ball },
                touch: Vec3::ZERO,
            })
            .collect();
        let body = Body {
            segments: &segments,
            parents: &self.parents,
            offsets: &self.offsets,
        };
        solve_body(&body, pose, segment, point, target)
    }
}

/// The core's default solve of one point goal (`point` of the segment at
/// `target`), warm-started from `pose` projected onto the body's joints.
fn solve_body(
    body: &Body<'_>,
    pose: &[(Vec3, Quat)],
    segment: usize,
    point: Vec3,
    target: Vec3,
) -> Option<Solved> {
    let mut p = Pose::<64>::new(pose.len()).ok()?;
    for (i, (pos, rot)) in pose.iter().enumerate() {
        p.set(i, *pos, *rot).ok()?;
    }
    let mut local = LocalPose::<64>::default();
    pose::to_local(&body.hierarchy(), &p, &mut local).ok()?;
    let mut angles = Angles::<64>::from_local(body, &local).ok()?;
    let mut goals = GoalSet::<1>::new();
    let goal = Goal::reach(u8::try_from(segment).ok()?, target, 1.0).at(point);
    goals.push(goal).ok()?;
    let report = solve::solve(&Solver::DEFAULT, body, &goals, &mut angles, &mut p).ok()?;
    let residual = report.residuals.first().copied().unwrap_or(f32::INFINITY);
    Some(Solved {
        residual: f64::from(residual),
        value: Value {
            poses: p
                .positions()
                .iter()
                .zip(p.rotations())
                .map(|(a, b)| (a.as_dvec3(), b.as_dquat()))
                .collect(),
            scalars: Vec::new(),
        },
    })
}

/// A solved pose and the distance left between its probe and the target.
pub struct Solved {
    /// Metres.
    pub residual: f64,
    /// The pose.
    pub value: Value,
}

/// A placement is kept only if the solver brings the probe this close
/// (metres): a grid point the rig cannot reach keeps its resampled pose
/// rather than one stretched towards it.
pub const REACHED: f64 = 1e-3;

/// Places a grid pose's probe at its grid point (see the module doc).
pub struct Placer {
    body: RigBody,
    segment: usize,
    point: DVec3,
    axes: [usize; 3],
    frame: Frame,
}

impl Placer {
    /// The placer of a grid dataset whose axes are the probe's x, y and z;
    /// `None` for any other dataset.
    #[must_use]
    pub fn new(data: &Dataset) -> Option<Self> {
        if data.layout != super::Layout::Grid {
            return None;
        }
        Some(Self {
            body: RigBody {
                file: None,
                ..RigBody::new(data.rig.as_ref()?)?
            },
            segment: data.probe_segment?,
            point: data.probe_point,
            axes: data.probe_axes?,
            frame: data.param_frame,
        })
    }

    /// Where the probe belongs at `params`, in the poses' frame.
    #[must_use]
    pub fn target(&self, params: &[f64]) -> DVec3 {
        let [x, y, z] = self.axes.map(|a| params.get(a).copied().unwrap_or(0.0));
        self.frame.point(DVec3::new(x, y, z))
    }

    /// Moves `value` (one pose) so the probe is at `params`' point; returns
    /// whether it did (it leaves the pose alone if the solver refuses or
    /// ends farther than [`REACHED`]).
    pub fn place(&self, params: &[f64], value: &mut Value) -> bool {
        let pose: Vec<(Vec3, Quat)> = value
            .poses
            .iter()
            .map(|(p, q)| (p.as_vec3(), q.as_quat()))
            .collect();
        let target = self.target(params).as_vec3();
        if let Some(s) = self
            .body
            .solve(&pose, self.segment, self.point.as_vec3(), target)
            && s.residual <= REACHED
        {
            value.poses = s.value.poses;
            return true;
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DQuat;
    use marionette_core::pose::NO_PARENT;

    /// A root and a two-bone arm hanging from it, 0.3 m + 0.25 m.
    fn arm() -> RigBody {
        RigBody {
            names: vec!["root".into(), "upper".into(), "lower".into()],
            parents: vec![NO_PARENT, 0, 1],
            offsets: vec![
                Vec3::ZERO,
                Vec3::new(0.0, -0.3, 0.0),
                Vec3::new(0.0, -0.25, 0.0),
            ],
            file: None,
        }
    }

    fn rest() -> Value {
        Value {
            poses: vec![
                (DVec3::ZERO, DQuat::IDENTITY),
                (DVec3::new(0.0, -0.3, 0.0), DQuat::IDENTITY),
                (DVec3::new(0.0, -0.55, 0.0), DQuat::IDENTITY),
            ],
            scalars: Vec::new(),
        }
    }

    #[test]
    fn places_a_reachable_point_and_leaves_an_unreachable_one() {
        // The probe: 0.1 m further down the lower bone.
        let placer = Placer {
            body: arm(),
            segment: 2,
            point: DVec3::new(0.0, -0.1, 0.0),
            axes: [0, 1, 2],
            frame: Frame::WORLD,
        };
        let mut v = rest();
        let target = [0.2, -0.4, 0.1];
        assert!(placer.place(&target, &mut v));
        let (p, q) = v.poses[2];
        let tip = p + q * DVec3::new(0.0, -0.1, 0.0);
        assert!(
            (tip - DVec3::from_array(target)).length() <= REACHED,
            "{tip}"
        );
        // The bones keep their lengths (the pose comes from the skeleton).
        assert!(((v.poses[1].0 - v.poses[0].0).length() - 0.3).abs() < 1e-5);
        assert!(((v.poses[2].0 - v.poses[1].0).length() - 0.25).abs() < 1e-5);
        // 0.65 m of arm cannot reach 1 m: the pose stays as it was.
        let mut far = rest();
        assert!(!placer.place(&[0.0, -1.0, 0.0], &mut far));
        assert_eq!(far, rest());
    }
}
