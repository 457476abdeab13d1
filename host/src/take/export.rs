//! Exports of a take: its servo curves as CSV, and the solved figure as BVH
//! (to open in Blender or any mocap tool).
//!
//! The BVH's skeleton is the rig's: one joint per segment, named as in the
//! rig, each `OFFSET` its joint origin in the parent's frame (centimetres),
//! End Sites at zero offset on the leaves. Every joint has the channels
//! `Zrotation Xrotation Yrotation` (degrees; the root also
//! `Xposition Yposition Zposition` first): its rotation relative to its
//! parent is `Rz · Rx · Ry`. One BVH frame per tracker frame the figure was
//! solved for, from the native core replayed on the take's session (the
//! pose the board solved: its servo outputs are the same bit for bit), at
//! the mean tracker frame interval.

use super::Take;
use crate::perform::{self, PerformError};
use glam::{EulerRot, Quat, Vec3};
use marionette_core::perform::Cause;
use marionette_core::region::Region;
use std::fmt::Write as _;

/// BVH units per metre.
pub const BVH_UNITS_PER_M: f32 = 100.0;

/// The servo curves: `time_us,ch0,…` (µs, as `servo_sim.csv`), one row
/// per output (frame-driven and easing) at its time; in a take from a port,
/// one per set of targets its telemetry reported ([`Take::curves`]).
#[must_use]
pub fn curves_csv(take: &Take) -> String {
    let mut text = String::from("time_us");
    for c in 0..take.channels {
        let _ = write!(text, ",ch{c}");
    }
    text.push('\n');
    for (t, targets) in take.curves() {
        let _ = write!(text, "{t}");
        for q in targets {
            let _ = write!(text, ",{}", f64::from(q) / 4.0);
        }
        text.push('\n');
    }
    text
}

/// One solved pose: world positions and orientations by segment.
pub type Solved = (Vec<Vec3>, Vec<Quat>);

/// The figure solved for each tracker frame of the take's session (the
/// native core on its region).
pub fn solved_poses(take: &Take) -> Result<Vec<Solved>, PerformError> {
    let mut poses = Vec::new();
    perform::simulate_with(&take.region, &take.session(), &mut |p, u| {
        if let (Some(Cause::Frame(_)), Some(pose)) = (u.outputs, p.pose()) {
            let n = pose.count;
            poses.push((
                pose.positions.iter().take(n).copied().collect(),
                pose.rotations.iter().take(n).copied().collect(),
            ));
        }
    })?;
    Ok(poses)
}

/// The take's solved figure as a BVH file (see the module doc).
pub fn bvh(take: &Take) -> Result<String, PerformError> {
    let region = Region::parse(&take.region);
    let rig = region.rig.as_ref().ok_or(PerformError::NoRig)?;
    let body = rig.body();
    let n = body.len();
    let poses = solved_poses(take)?;
    let times: Vec<u32> = take.outputs().iter().filter(|o| o.1).map(|o| o.0).collect();
    let span = match (times.first(), times.last()) {
        (Some(a), Some(b)) if times.len() > 1 => f64::from(b.wrapping_sub(*a)) / 1e6,
        _ => 0.0,
    };
    let frame_time = if times.len() > 1 {
        span / (times.len() - 1) as f64
    } else {
        f64::from(take.period_us) / 1e6
    };
    let mut text = String::from("HIERARCHY\n");
    let children = |i: usize| (0..n).filter(move |&c| c != i && body.parent(c) == Some(i));
    // Depth-first, in segment order (parents precede children).
    let mut order = Vec::new();
    let mut stack: Vec<(usize, usize, bool)> = (0..n)
        .filter(|&i| body.parent(i).is_none())
        .rev()
        .map(|i| (i, 0, false))
        .collect();
    while let Some((i, depth, closing)) = stack.pop() {
        let pad = "  ".repeat(depth);
        if closing {
            if children(i).next().is_none() {
                let _ = writeln!(
                    text,
                    "{pad}  End Site\n{pad}  {{\n{pad}    OFFSET 0 0 0\n{pad}  }}"
                );
            }
            let _ = writeln!(text, "{pad}}}");
            continue;
        }
        let seg = body.segment(i).ok_or(PerformError::NoRig)?;
        let root = body.parent(i).is_none();
        let o = if root {
            Vec3::ZERO
        } else {
            seg.origin * BVH_UNITS_PER_M
        };
        let _ = writeln!(
            text,
            "{pad}{} {}\n{pad}{{\n{pad}  OFFSET {} {} {}",
            if root { "ROOT" } else { "JOINT" },
            seg.name,
            o.x,
            o.y,
            o.z
        );
        let channels = if root {
            "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"
        } else {
            "CHANNELS 3 Zrotation Xrotation Yrotation"
        };
        let _ = writeln!(text, "{pad}  {channels}");
        order.push(i);
        stack.push((i, depth, true));
        let kids: Vec<usize> = children(i).collect();
        for c in kids.into_iter().rev() {
            stack.push((c, depth + 1, false));
        }
    }
    let _ = writeln!(
        text,
        "MOTION\nFrames: {}\nFrame Time: {frame_time:.6}",
        poses.len()
    );
    for (positions, rotations) in &poses {
        let mut row = Vec::new();
        for &i in &order {
            let q = rotations.get(i).copied().unwrap_or(Quat::IDENTITY);
            let local = match body.parent(i) {
                Some(p) => {
                    rotations
                        .get(p)
                        .copied()
                        .unwrap_or(Quat::IDENTITY)
                        .conjugate()
                        * q
                }
                None => {
                    let p = positions.get(i).copied().unwrap_or(Vec3::ZERO) * BVH_UNITS_PER_M;
                    row.extend([p.x, p.y, p.z]);
                    q
                }
            };
            let (z, x, y) = local.normalize().to_euler(EulerRot::ZXY);
            row.extend([z.to_degrees(), x.to_degrees(), y.to_degrees()]);
        }
        let line: Vec<String> = row.iter().map(|v| format!("{v}")).collect();
        let _ = writeln!(text, "{}", line.join(" "));
    }
    Ok(text)
}
