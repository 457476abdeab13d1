//! `marionette render`: a pose and its goals in four views (POSIT, Figure 2).
//!
//! The skeleton comes from a rig file (`--rig`) or a body shipped with the
//! core (`--body tempus|cmu`, the default tempus).
//!
//! The pose is a JSON file of world-space segment placements, the form
//! `marionette synth`/`solve` print:
//!
//! ```json
//! {"segments": [{"name": "lower_torso", "position": [0, 0.95, 0], "rotation": [1, 0, 0, 0]}, ...]}
//! ```
//!
//! `position` is the segment's joint origin (metres), `rotation` its world
//! orientation `[w, x, y, z]`. Every segment of the body must appear once, in
//! any order; other fields are ignored. Without `--pose` the rest pose is
//! drawn: a rig's own (root at its `root_position`, as `marionette solve`
//! starts from), or a shipped body's through core forward kinematics, lifted
//! so that its lowest point is on the floor.
//!
//! Goals are a goals file exactly as `marionette solve` reads it
//! (`docs/goals.md`): `{"goals": [{"segment": "left_hand", "target":
//! [x, y, z], "weight": 10}]}`, with an optional `"point": [x, y, z]`
//! (segment frame) instead of the touch point, and an optional `start`
//! (which only `solve` uses). The drawing joins the pulled point to the
//! target.

use super::CmdError;
use crate::render::{self, Camera, Figure, Mark, RenderOptions};
use crate::rigfile;
use glam::{DQuat, DVec3};
use marionette_core::body::{self, Angles, Body};
use marionette_core::goal::{Attach, Goal, Target};
use marionette_core::pose::{LocalPose, MAX_SEGMENTS, Pose};
use marionette_core::rig::Rig;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// A body shipped with the core.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum BodyName {
    /// The TEMPUS-like 18-segment humanoid (POSIT, Figure 13).
    Tempus,
    /// The CMU 31-joint mocap skeleton.
    Cmu,
}

impl BodyName {
    /// The core body.
    #[must_use]
    pub fn body(self) -> Body<'static> {
        match self {
            BodyName::Tempus => body::tempus::BODY,
            BodyName::Cmu => body::cmu::BODY,
        }
    }

    fn name(self) -> &'static str {
        match self {
            BodyName::Tempus => "tempus",
            BodyName::Cmu => "cmu",
        }
    }
}

/// Arguments of `marionette render`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The rig file whose skeleton the pose belongs to (a path, or a rig
    /// name: `rigs/<name>.toml` here, else a rig built in (humanoid16,
    /// cmu31)); instead of `--body`.
    #[arg(long, conflicts_with = "body")]
    pub rig: Option<PathBuf>,
    /// The shipped body the pose belongs to (without `--rig`).
    #[arg(long, value_enum, default_value = "tempus")]
    pub body: BodyName,
    /// World pose JSON (`{"segments":[{"name","position","rotation"}]}`,
    /// as `synth` prints it; `-` reads standard input); the rest pose if
    /// absent.
    #[arg(long)]
    pub pose: Option<PathBuf>,
    /// Goals JSON, as `solve --goals` reads it (`{"goals": [{"segment",
    /// "target", "weight"}]}`; see docs/goals.md).
    #[arg(long)]
    pub goals: Option<PathBuf>,
    /// Output picture, `.png` or `.svg`.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Caption (default: the pose file and body).
    #[arg(long)]
    pub title: Option<String>,
    /// Width in pixels.
    #[arg(long, default_value_t = 1200)]
    pub width: u32,
    /// Height in pixels.
    #[arg(long, default_value_t = 1200)]
    pub height: u32,
    /// Perspective camera: degrees from the front towards the figure's left.
    #[arg(long, default_value_t = 35.0, allow_negative_numbers = true)]
    pub azimuth: f64,
    /// Perspective camera: degrees above the horizon.
    #[arg(long, default_value_t = 20.0, allow_negative_numbers = true)]
    pub elevation: f64,
}

/// A pose file.
#[derive(Debug, Deserialize)]
pub struct PoseFile {
    /// World placements, one per segment.
    pub segments: Vec<SegmentPlacement>,
}

/// One segment's world placement in a pose file.
#[derive(Debug, Deserialize)]
pub struct SegmentPlacement {
    /// Segment name, as in the body.
    pub name: String,
    /// Joint origin, metres.
    pub position: [f64; 3],
    /// Orientation `[w, x, y, z]`.
    pub rotation: [f64; 4],
}

/// The body's rest pose in world space, lifted so its lowest joint origin or
/// touch point is on the floor (`y = 0`).
pub fn rest_pose(body: &Body<'_>) -> Result<Vec<(DVec3, DQuat)>, CmdError> {
    let angles = Angles::<MAX_SEGMENTS>::rest(body).map_err(|e| format!("rest pose: {e:?}"))?;
    let mut local = LocalPose::<MAX_SEGMENTS>::default();
    let mut pose = Pose::<MAX_SEGMENTS>::default();
    angles
        .forward(body, &mut local, &mut pose)
        .map_err(|e| format!("forward kinematics: {e:?}"))?;
    let mut world: Vec<(DVec3, DQuat)> = pose
        .positions()
        .iter()
        .zip(pose.rotations())
        .map(|(p, q)| (p.as_dvec3(), q.as_dquat()))
        .collect();
    let lowest = (0..world.len())
        .filter_map(|i| render::touch_point(body, &world, i))
        .chain(world.iter().map(|w| w.0))
        .map(|p| p.y)
        .fold(f64::INFINITY, f64::min);
    if lowest.is_finite() {
        for (p, _) in &mut world {
            p.y -= lowest;
        }
    }
    Ok(world)
}

/// Reads a pose file (`-`: standard input) and orders its placements as the
/// body's segments.
pub fn read_pose(body: &Body<'_>, path: &Path) -> Result<Vec<(DVec3, DQuat)>, CmdError> {
    let text = if path == Path::new("-") {
        std::io::read_to_string(std::io::stdin()).map_err(|e| format!("standard input: {e}"))?
    } else {
        std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?
    };
    let file: PoseFile =
        serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
    world_from_file(body, &file).map_err(|e| format!("{}: {e}", path.display()).into())
}

/// Orders a pose file's placements as the body's segments; every segment
/// must appear exactly once and no other.
pub fn world_from_file(body: &Body<'_>, file: &PoseFile) -> Result<Vec<(DVec3, DQuat)>, String> {
    let unknown: Vec<&str> = file
        .segments
        .iter()
        .map(|s| s.name.as_str())
        .filter(|n| body.find(n).is_none())
        .collect();
    if !unknown.is_empty() {
        return Err(format!(
            "segments not in the body: {} (wrong --body?)",
            unknown.join(", ")
        ));
    }
    body.segments
        .iter()
        .map(|seg| {
            let mut found = file.segments.iter().filter(|s| s.name == seg.name);
            let s = found
                .next()
                .ok_or_else(|| format!("segment {:?} is missing", seg.name))?;
            if found.next().is_some() {
                return Err(format!("segment {:?} appears twice", seg.name));
            }
            let [w, x, y, z] = s.rotation;
            let q = DQuat::from_xyzw(x, y, z, w);
            let p = DVec3::from_array(s.position);
            if !(p.is_finite() && q.is_finite() && q.length() > 1e-6) {
                return Err(format!("segment {:?}: bad position or rotation", seg.name));
            }
            Ok((p, q.normalize()))
        })
        .collect()
}

/// Reads a goals file (the format `marionette solve` reads, see
/// [`crate::cmd::solve`] and `docs/goals.md`) into marks on a posed body.
pub fn read_goals(
    body: &Body<'_>,
    world: &[(DVec3, DQuat)],
    path: &Path,
) -> Result<Vec<Mark>, CmdError> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let goals = super::solve::read_goals(body, &text, &path.display().to_string())?;
    goals
        .iter()
        .map(|g| mark(body, world, g).map_err(|e| format!("{}: {e}", path.display()).into()))
        .collect()
}

/// One goal as a mark: its target and the point it pulls.
pub fn mark(body: &Body<'_>, world: &[(DVec3, DQuat)], g: &Goal) -> Result<Mark, String> {
    let index = usize::from(g.segment);
    let seg = body
        .segment(index)
        .ok_or_else(|| format!("goal on segment {index}, the body has {}", body.len()))?;
    let (origin, rotation) = world
        .get(index)
        .copied()
        .ok_or_else(|| format!("no placement for segment {index}"))?;
    let local = match g.attach {
        Attach::Point(p) => p.as_dvec3(),
        Attach::Touch => seg.touch.as_dvec3(),
    };
    let Target::Position(target) = g.target else {
        return Err(format!(
            "goal on {}: only position goals are drawn",
            seg.name
        ));
    };
    let label = if g.is_active() {
        format!("{} ×{}", seg.name, g.weight)
    } else {
        format!("{} (inactive)", seg.name)
    };
    Ok(Mark {
        target: target.as_dvec3(),
        from: Some(origin + rotation * local),
        label,
    })
}

/// Builds the figure the arguments describe.
pub fn figure(args: &Args) -> Result<Figure, CmdError> {
    match &args.rig {
        Some(arg) => {
            let path = rigfile::resolve(arg);
            let file = rigfile::load(&path)?;
            let desc = file.desc();
            let rig = Rig::from_desc(&desc).map_err(|e| format!("{}: {e:?}", path.display()))?;
            let body = rig.body();
            let rest = rig.rest_pose();
            let rest: Vec<(DVec3, DQuat)> = rest
                .positions()
                .iter()
                .zip(rest.rotations())
                .take(body.len())
                .map(|(p, q)| (p.as_dvec3(), q.as_dquat()))
                .collect();
            figure_of(&body, file.name(), rest, args)
        }
        None => {
            let body = args.body.body();
            figure_of(&body, args.body.name(), rest_pose(&body)?, args)
        }
    }
}

/// The figure of `body` in the `--pose` (or `rest`) with the `--goals`.
fn figure_of(
    body: &Body<'_>,
    body_name: &str,
    rest: Vec<(DVec3, DQuat)>,
    args: &Args,
) -> Result<Figure, CmdError> {
    let world = match &args.pose {
        Some(path) => read_pose(body, path)?,
        None => rest,
    };
    let title = args.title.clone().unwrap_or_else(|| match &args.pose {
        Some(p) => format!("{} ({body_name})", p.display()),
        None => format!("{body_name} rest pose"),
    });
    let mut fig = Figure::from_world(body, &world, title)?;
    if let Some(path) = &args.goals {
        fig.goals = read_goals(body, &world, path)?;
    }
    Ok(fig)
}

/// Draws the figure and says where.
pub fn run(args: &Args) -> Result<(), CmdError> {
    let inputs: Vec<(&str, &Path)> = [
        ("the rig", args.rig.as_deref()),
        ("the pose", args.pose.as_deref()),
        ("the goals", args.goals.as_deref()),
    ]
    .into_iter()
    .filter_map(|(what, p)| Some((what, p?)))
    .collect();
    crate::save::check(&args.output, &inputs)?;
    let fig = figure(args)?;
    let opt = RenderOptions {
        width: args.width,
        height: args.height,
        camera: Camera {
            azimuth_deg: args.azimuth,
            elevation_deg: args.elevation,
            ..Camera::default()
        },
    };
    render::render_with(&fig, &args.output, &opt)?;
    println!(
        "{}: {} bones, {} goals, four views",
        args.output.display(),
        fig.bones.len(),
        fig.goals.len()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use marionette_core::body::tempus::index;

    fn close(a: DVec3, b: DVec3) -> bool {
        (a - b).length() < 1e-5
    }

    #[test]
    fn tempus_rest_pose_stands_on_the_floor() {
        let body = body::tempus::BODY;
        let world = rest_pose(&body).unwrap();
        // From the joint table in body/tempus.rs: pelvis 0.95 m up; left hand
        // palm at x = 0.02 + 0.16, y = 0.95 + 0.10 + 0.38 − 0.30 − 0.26 − 0.08;
        // the foot's touch point on the sole, 0.14 m forward.
        assert!(close(world[0].0, DVec3::new(0.0, 0.95, 0.0)));
        let hand = render::touch_point(&body, &world, index::LEFT_HAND.into()).unwrap();
        assert!(close(hand, DVec3::new(0.18, 0.79, 0.0)), "{hand}");
        let foot = render::touch_point(&body, &world, index::RIGHT_FOOT.into()).unwrap();
        assert!(close(foot, DVec3::new(-0.09, 0.0, 0.14)), "{foot}");
        let head = render::touch_point(&body, &world, index::HEAD.into()).unwrap();
        assert!(close(head, DVec3::new(0.0, 1.67, 0.0)), "{head}");
    }

    fn placement(name: &str, y: f64) -> SegmentPlacement {
        SegmentPlacement {
            name: name.into(),
            position: [0.0, y, 0.0],
            rotation: [1.0, 0.0, 0.0, 0.0],
        }
    }

    #[test]
    fn pose_file_is_matched_by_name() {
        let body = body::tempus::BODY;
        // Reversed order on purpose.
        let segments: Vec<SegmentPlacement> = body
            .segments
            .iter()
            .enumerate()
            .rev()
            .map(|(i, s)| placement(s.name, i as f64))
            .collect();
        let mut file = PoseFile { segments };
        let world = world_from_file(&body, &file).unwrap();
        assert!(world.iter().enumerate().all(|(i, w)| w.0.y == i as f64));

        file.segments[0].rotation = [2.0, 0.0, 0.0, 0.0];
        let world = world_from_file(&body, &file).unwrap();
        assert!((world[17].1.length() - 1.0).abs() < 1e-12, "normalized");

        file.segments.push(placement("tail", 0.0));
        let err = world_from_file(&body, &file).unwrap_err();
        assert!(err.contains("tail") && err.contains("--body"), "{err}");
        file.segments.pop();
        file.segments.push(placement("head", 0.0));
        assert!(world_from_file(&body, &file).unwrap_err().contains("twice"));
        file.segments.pop();
        file.segments.retain(|s| s.name != "neck");
        assert!(
            world_from_file(&body, &file)
                .unwrap_err()
                .contains("\"neck\" is missing")
        );
    }

    #[test]
    fn goals_pull_touch_points_or_given_points() {
        let body = body::tempus::BODY;
        let world = rest_pose(&body).unwrap();
        let json = r#"{"goals": [
            {"segment": "left_hand", "target": [0.3, 1.2, 0.4], "weight": 10},
            {"segment": "right_hand", "target": [0, 0, 0], "weight": 1, "point": [0, -0.26, 0]},
            {"segment": "head", "target": [0, 2, 0], "weight": 0}
        ]}"#;
        let goals = crate::cmd::solve::read_goals(&body, json, "goals.json").unwrap();
        let marks: Vec<Mark> = goals
            .iter()
            .map(|g| mark(&body, &world, g).unwrap())
            .collect();
        assert_eq!(marks[0].label, "left_hand ×10");
        assert!(close(marks[0].from.unwrap(), DVec3::new(0.18, 0.79, 0.0)));
        assert!(close(marks[0].target, DVec3::new(0.3, 1.2, 0.4)));
        // Right hand: its origin is at (−0.18, 0.95 + 0.10 + 0.38 − 0.30 −
        // 0.26, 0) = (−0.18, 0.87, 0), and the given point is 0.26 m below it.
        assert_eq!(marks[1].label, "right_hand ×1");
        assert!(close(marks[1].from.unwrap(), DVec3::new(-0.18, 0.61, 0.0)));
        assert_eq!(marks[2].label, "head (inactive)");
    }

    #[test]
    fn a_bad_goal_names_the_file_the_line_and_the_entry() {
        let body = body::tempus::BODY;
        let world = rest_pose(&body).unwrap();
        let path =
            std::env::temp_dir().join(format!("marionette-goals-{}.json", std::process::id()));
        let json = "{\"goals\": [\n  {\"segment\": \"head\", \"target\": [0, 2, 0], \"weight\": 1},\n  {\"segment\": \"tail\", \"target\": [0, 0, 0], \"weight\": 1}\n]}";
        std::fs::write(&path, json).unwrap();
        let err = read_goals(&body, &world, &path).unwrap_err().to_string();
        let _ = std::fs::remove_file(&path);
        let want = format!(
            "{}:3: goals[1].segment: unknown segment \"tail\"",
            path.display()
        );
        assert!(err.starts_with(&want), "{err}");
    }
}
