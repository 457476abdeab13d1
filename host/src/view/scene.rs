//! What the live view shows, computed from what the board reports: the
//! figure as its servos place it, the goals and their residuals, each
//! servo's target within its calibrated limits, the link and the board's
//! state. One [`Snapshot`] is one update of the page (sent as JSON).
//!
//! The figure is posed from the servo targets alone (the board's telemetry
//! on a real board, the servo bus on the emulated one): each servo's
//! target, through the inverse of its calibration
//! ([`marionette_core::servo::Calibration::angle_of`]), sets its joint's
//! degree of freedom; every other degree of freedom stays at rest; the
//! core's forward kinematics places the segments; and the bones are drawn
//! from the same [`Figure`] as `marionette render`.

use crate::render::{Figure, Side};
use marionette_core::body::Angles;
use marionette_core::pose::{LocalPose, MAX_SEGMENTS, Pose};
use marionette_core::rig::Rig;
use marionette_core::wire::{State, TrackerFrame};
use serde::{Deserialize, Serialize};

/// One servo's bar: its target within its calibrated pulse range.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ServoBar {
    /// The joint it drives (`r_elbow.x`).
    pub name: String,
    /// Its channel.
    pub channel: u8,
    /// The target, µs.
    pub us: f32,
    /// The lowest pulse it may receive, µs.
    pub low: f32,
    /// The highest pulse it may receive, µs.
    pub high: f32,
}

/// A goal: where it wants its point, and how far the point is.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GoalView {
    /// The goal's label (segment and weight).
    pub name: String,
    /// Its target, metres (world, Y up), if the frame gives one.
    pub target: Option<[f32; 3]>,
    /// The point it pulls on the figure, metres.
    pub from: Option<[f32; 3]>,
    /// The board's residual for it, millimetres, if reported.
    pub residual_mm: Option<f32>,
}

/// The link and the board's state.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkView {
    /// Tracker frames sent so far.
    pub frames: u64,
    /// Frames per second over the session so far.
    pub rate_hz: f64,
    /// Frames dropped by the sender (newest wins).
    pub drops: u64,
    /// Errors the board has counted.
    pub errors: u64,
    /// The board's state (`Armed`, `FailSafe`, …).
    pub state: String,
    /// Fail-safe trips so far.
    pub trips: u32,
    /// Whether the board is connected (false once the session has ended).
    pub connected: bool,
}

/// One update of the page.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Snapshot {
    /// The page's caption (rig and source).
    pub title: String,
    /// Seconds since the session started.
    pub t_s: f64,
    /// The stick figure's bones: `[x0, y0, z0, x1, y1, z1]`, metres.
    pub bones: Vec<[f32; 6]>,
    /// Each bone's colour group: 0 centre, 1 left, 2 right.
    pub sides: Vec<u8>,
    /// The goals.
    pub goals: Vec<GoalView>,
    /// The servos.
    pub servos: Vec<ServoBar>,
    /// The link and the board.
    pub link: LinkView,
}

/// What the board reported last (any part may be missing).
#[derive(Clone, Debug, Default)]
pub struct Reported<'f> {
    /// Servo targets by channel, quarter-µs.
    pub targets: &'f [u16],
    /// The tracker frame these targets answer, for the goals' targets.
    pub frame: Option<&'f TrackerFrame>,
    /// The board's goal residuals, metres, in the rig's goal order.
    pub residuals: &'f [f32],
    /// Seconds since the session started.
    pub t_s: f64,
    /// The link and state.
    pub link: LinkView,
}

/// Turns reports into snapshots for one rig.
pub struct Scene<'r> {
    rig: &'r Rig<'r>,
    title: String,
}

impl<'r> Scene<'r> {
    /// A scene for `rig`, captioned `title`.
    #[must_use]
    pub fn new(rig: &'r Rig<'r>, title: impl Into<String>) -> Self {
        Self {
            rig,
            title: title.into(),
        }
    }

    /// The pose the servo targets give (every other DOF at rest).
    #[must_use]
    pub fn pose(&self, targets: &[u16]) -> Option<Pose<MAX_SEGMENTS>> {
        let body = self.rig.body();
        let mut angles: Angles<MAX_SEGMENTS> = self.rig.rest_angles().ok()?;
        for servo in self.rig.servos() {
            let Some(&q) = targets.get(usize::from(servo.channel)) else {
                continue;
            };
            let angle = servo.calibration().angle_of(f32::from(q) / 4.0);
            if let Some(slot) = angles
                .get_mut(usize::from(servo.segment))
                .and_then(|a| a.get_mut(usize::from(servo.dof)))
            {
                *slot = angle;
            }
        }
        let mut local = LocalPose::new(body.len()).ok()?;
        let mut pose = Pose::new(body.len()).ok()?;
        angles.forward(&body, &mut local, &mut pose).ok()?;
        Some(pose)
    }

    /// The snapshot of a report.
    #[must_use]
    pub fn snapshot(&self, r: &Reported<'_>) -> Snapshot {
        let body = self.rig.body();
        let pose = self.pose(r.targets);
        let figure = pose
            .as_ref()
            .and_then(|p| Figure::from_pose(&body, p, self.title.clone()).ok())
            .unwrap_or_default();
        let marks = match (r.frame, pose.as_ref()) {
            (Some(f), Some(p)) => crate::cmd::demo::marks(self.rig, f, p),
            _ => Vec::new(),
        };
        let point = |v: glam::DVec3| v.as_vec3().to_array();
        let goals = marks
            .iter()
            .enumerate()
            .map(|(i, m)| GoalView {
                name: m.label.clone(),
                target: Some(point(m.target)),
                from: m.from.map(point),
                residual_mm: r.residuals.get(i).map(|x| x * 1000.0),
            })
            .collect();
        Snapshot {
            title: self.title.clone(),
            t_s: r.t_s,
            bones: figure
                .bones
                .iter()
                .map(|b| {
                    let (f, t) = (point(b.from), point(b.to));
                    [f[0], f[1], f[2], t[0], t[1], t[2]]
                })
                .collect(),
            sides: figure.bones.iter().map(|b| side_code(b.side)).collect(),
            goals,
            servos: self.bars(r.targets),
            link: r.link.clone(),
        }
    }

    /// Each servo's bar.
    fn bars(&self, targets: &[u16]) -> Vec<ServoBar> {
        let body = self.rig.body();
        self.rig
            .servos()
            .iter()
            .map(|s| {
                let cal = s.calibration();
                let seg = body.segment(usize::from(s.segment));
                let axis = seg
                    .and_then(|g| g.joint.dofs().get(usize::from(s.dof)))
                    .map_or("?", |d| match d.axis {
                        marionette_core::body::Axis::X => "x",
                        marionette_core::body::Axis::Y => "y",
                        marionette_core::body::Axis::Z => "z",
                    });
                ServoBar {
                    name: format!("{}.{axis}", seg.map_or("?", |g| g.name)),
                    channel: s.channel,
                    us: targets
                        .get(usize::from(s.channel))
                        .map_or(f32::NAN, |&q| f32::from(q) / 4.0),
                    low: cal.pulse_low(),
                    high: cal.pulse_high(),
                }
            })
            .collect()
    }
}

/// The page's colour group of a bone.
fn side_code(side: Side) -> u8 {
    match side {
        Side::Left => 1,
        Side::Right => 2,
        Side::Centre => 0,
    }
}

/// The name of a board state, as the page shows it.
#[must_use]
pub fn state_name(state: State) -> String {
    format!("{state:?}")
}
