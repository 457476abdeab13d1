//! `marionette record`: a tracker recording made from a mocap clip.
//!
//! Reads a clip (ASF/AMC or BVH), places virtual trackers on the performer
//! and writes what they would have reported as a tracker CSV
//! (`time_us,sensor,x,y,z,qw,qx,qy,qz`, see [`crate::import::csv`]):
//!
//! - each sensor sits at the mean world position of one or more joints
//!   (`--sensor 0=rhand+rfingers`: midway between the hand bone's two ends,
//!   the palm centre) and turns with the first of them (its world rotation,
//!   identity in the mocap's rest pose);
//! - the clip's frames are put through forward kinematics in `f64` and
//!   resampled to `--rate-hz` (default 1000, the humanoid16 rig's frame
//!   rate): positions linearly, rotations by slerp, between the two nearest
//!   mocap frames;
//! - positions are world metres as the mocap has them. By default each
//!   sample is what the compact tracker frame carries (`wire::compact`:
//!   positions in steps of 2⁻¹³ m, rotations in smallest-three 11-bit
//!   components), written exactly (each `f32` as the shortest decimal that
//!   reads back as the same `f32`), so the recording is what a board
//!   receives; with `--frame f32`, positions are rounded to 0.1 mm and
//!   rotations to 1e-5 (a tracker's resolution, and a small file).
//!
//! Without `--sensor`, the trackers of the humanoid16 rig: 0 = the right
//! palm, 1 = the left palm, 2 = the pelvis (the root joint, which turns
//! with the pelvis: Y up, Z forward in the rest pose), with the joint names
//! of the clip's skeleton (ASF: `rhand+rfingers`, `lhand+lfingers`, `root`;
//! BVH, CMU names: `RightHand`, `LeftHand`, `Hips`).

use super::CmdError;
use crate::import::csv::{HEADER, TrackerSample};
use crate::import::{self, Motion};
use crate::perform::Framing;
use glam::{DQuat, DVec3};
use marionette_core::wire::{Sensor, compact};
use std::path::{Path, PathBuf};

/// Arguments of `marionette record`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The mocap clip (`.amc` with `--skeleton`, or `.bvh`).
    pub clip: PathBuf,
    /// The ASF skeleton of an AMC clip.
    #[arg(long)]
    pub skeleton: Option<PathBuf>,
    /// BVH: metres per file unit (default: the CMU unit).
    #[arg(long)]
    pub scale: Option<f64>,
    /// AMC: the clip's frame rate (HDM05 and CMU: 120).
    #[arg(long, default_value_t = 120.0)]
    pub fps: f64,
    /// The tracker rate, Hz.
    #[arg(long, default_value_t = 1000.0)]
    pub rate_hz: f64,
    /// The first sample's time stamp, µs.
    #[arg(long, default_value_t = 0)]
    pub start_us: u64,
    /// A tracker: `ID=JOINT[+JOINT...]` (repeat for each sensor).
    #[arg(long = "sensor")]
    pub sensors: Vec<String>,
    /// The CSV to write.
    #[arg(short, long)]
    pub output: PathBuf,
    /// The precision of the samples: what the compact tracker frame
    /// carries, or 0.1 mm and 1e-5 (`f32`).
    #[arg(long, value_enum, default_value_t = Framing::Compact)]
    pub frame: Framing,
}

/// One virtual tracker.
#[derive(Clone, Debug, PartialEq)]
pub struct Tracker {
    /// The sensor id it reports as.
    pub sensor: u8,
    /// Joint names: position = their mean, rotation = the first one's.
    pub joints: Vec<String>,
}

impl Tracker {
    /// Parses `ID=JOINT[+JOINT...]`.
    pub fn parse(s: &str) -> Result<Tracker, String> {
        let (id, joints) = s
            .split_once('=')
            .ok_or_else(|| format!("--sensor {s:?}: expected ID=JOINT[+JOINT...]"))?;
        let sensor = id
            .trim()
            .parse::<u8>()
            .map_err(|_| format!("--sensor {s:?}: {id:?} is not a sensor id (0..=255)"))?;
        let joints: Vec<String> = joints.split('+').map(|j| j.trim().to_owned()).collect();
        if joints.iter().any(String::is_empty) {
            return Err(format!("--sensor {s:?}: empty joint name"));
        }
        Ok(Tracker { sensor, joints })
    }
}

/// The default trackers for a clip's skeleton (see the module doc).
#[must_use]
pub fn default_trackers(motion: &Motion) -> Vec<Tracker> {
    let asf = motion.joint_index("rhand").is_some();
    let names: [&str; 3] = if asf {
        ["rhand+rfingers", "lhand+lfingers", "root"]
    } else {
        ["RightHand", "LeftHand", "Hips"]
    };
    names
        .iter()
        .zip(0u8..)
        .map(|(j, sensor)| Tracker {
            sensor,
            joints: j.split('+').map(str::to_owned).collect(),
        })
        .collect()
}

/// World placements of every joint in frame `f` (`f64` forward kinematics).
fn world(motion: &Motion, f: usize) -> Vec<(DVec3, DQuat)> {
    let Some(frame) = motion.frames.get(f) else {
        return Vec::new();
    };
    let mut out: Vec<(DVec3, DQuat)> = Vec::with_capacity(motion.joints.len());
    for (j, joint) in motion.joints.iter().enumerate() {
        let local = frame.rotations.get(j).copied().unwrap_or(DQuat::IDENTITY);
        let placed = match joint.parent.and_then(|p| out.get(p)) {
            Some(&(pp, pq)) => (pp + pq * joint.offset, (pq * local).normalize()),
            None => (frame.root_position, local.normalize()),
        };
        out.push(placed);
    }
    out
}

/// One tracker's placement in a frame's world placements.
fn place(world: &[(DVec3, DQuat)], joints: &[usize]) -> (DVec3, DQuat) {
    let n = joints.len().max(1) as f64;
    let p = joints.iter().map(|&j| world[j].0).sum::<DVec3>() / n;
    (p, world[joints[0]].1)
}

fn round(x: f64, step: f64) -> f64 {
    let r = (x / step).round() * step;
    // Print 0, not -0.
    if r == 0.0 { 0.0 } else { r }
}

/// `x` with at most `decimals` decimals, trailing zeros dropped.
fn fixed(x: f64, decimals: usize) -> String {
    let s = format!("{x:.decimals$}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        &s
    };
    if s == "-0" {
        "0".to_owned()
    } else {
        s.to_owned()
    }
}

/// Writes samples as a tracker CSV, positions to 0.1 mm and rotations to
/// 1e-5 (the precision [`record`] rounds to).
pub fn write_csv<W: std::io::Write>(mut out: W, samples: &[TrackerSample]) -> std::io::Result<()> {
    writeln!(out, "{}", HEADER.join(","))?;
    for s in samples {
        let (p, q) = (s.position, s.orientation);
        let pos = [p.x, p.y, p.z].map(|c| fixed(c, 4));
        let rot = [q.w, q.x, q.y, q.z].map(|c| fixed(c, 5));
        writeln!(
            out,
            "{},{},{},{}",
            s.time_us,
            s.sensor,
            pos.join(","),
            rot.join(",")
        )?;
    }
    out.flush()
}

/// Each sample as the compact tracker frame carries it (a position outside
/// its ±4 m is kept as is: such a frame travels as `f32`).
#[must_use]
pub fn snap_compact(samples: &[TrackerSample]) -> Vec<TrackerSample> {
    samples
        .iter()
        .map(|s| {
            let (p, q) = (s.position.as_vec3(), s.orientation.as_quat());
            let sensor = Sensor {
                id: s.sensor,
                position: p.to_array(),
                rotation: [q.w, q.x, q.y, q.z],
            };
            let Ok(back) = compact::pack_sensor(&sensor).and_then(|b| compact::unpack_sensor(&b))
            else {
                return *s;
            };
            TrackerSample {
                position: back.position().as_dvec3(),
                orientation: back.rotation().as_dquat(),
                ..*s
            }
        })
        .collect()
}

/// Writes samples as a tracker CSV with every value exactly as its `f32`
/// (the shortest decimal of its exact `f64` value: it reads back as the same
/// `f32`).
pub fn write_csv_exact<W: std::io::Write>(
    mut out: W,
    samples: &[TrackerSample],
) -> std::io::Result<()> {
    writeln!(out, "{}", HEADER.join(","))?;
    for s in samples {
        let (p, q) = (s.position, s.orientation);
        let exact = |x: f64| f64::from(x as f32).to_string();
        let pos = [p.x, p.y, p.z].map(exact);
        let rot = [q.w, q.x, q.y, q.z].map(exact);
        writeln!(
            out,
            "{},{},{},{}",
            s.time_us,
            s.sensor,
            pos.join(","),
            rot.join(",")
        )?;
    }
    out.flush()
}

/// The tracker samples of a clip, resampled to `rate_hz` from `start_us`
/// (see the module doc), in time order, sensors in the given order.
pub fn record(
    motion: &Motion,
    trackers: &[Tracker],
    rate_hz: f64,
    start_us: u64,
) -> Result<Vec<TrackerSample>, String> {
    if !(rate_hz.is_finite() && rate_hz > 0.0 && rate_hz <= 1e6) {
        return Err(format!("--rate-hz {rate_hz}: expected 0 < rate <= 1e6"));
    }
    let indices = trackers
        .iter()
        .map(|t| {
            t.joints
                .iter()
                .map(|j| {
                    motion.joint_index(j).ok_or_else(|| {
                        format!(
                            "sensor {}: {}: no joint {j:?} (joints: {})",
                            t.sensor,
                            motion.source,
                            motion
                                .joints
                                .iter()
                                .map(|j| j.name.as_str())
                                .collect::<Vec<_>>()
                                .join(", ")
                        )
                    })
                })
                .collect::<Result<Vec<usize>, String>>()
        })
        .collect::<Result<Vec<_>, String>>()?;
    let n = motion.frames.len();
    if n == 0 {
        return Err(format!("{}: no frames", motion.source));
    }
    let worlds: Vec<Vec<(DVec3, DQuat)>> = (0..n).map(|f| world(motion, f)).collect();
    let duration = (n - 1) as f64 * motion.frame_time;
    let steps = (duration * rate_hz + 1e-9).floor() as u64 + 1;
    let mut last: Vec<DQuat> = vec![DQuat::IDENTITY; trackers.len()];
    let mut out = Vec::with_capacity(steps as usize * trackers.len());
    for k in 0..steps {
        let t = k as f64 / rate_hz;
        let x = t / motion.frame_time;
        let i = (x.floor() as usize).min(n - 1);
        let a = x - i as f64;
        let next = (i + 1).min(n - 1);
        for ((tracker, joints), prev) in trackers.iter().zip(&indices).zip(&mut last) {
            let (p0, q0) = place(&worlds[i], joints);
            let (p1, q1) = place(&worlds[next], joints);
            let p = p0.lerp(p1, a);
            let mut q = q0.slerp(q1, a).normalize();
            // Keep the sign continuous from sample to sample.
            if q.dot(*prev) < 0.0 {
                q = -q;
            }
            *prev = q;
            out.push(TrackerSample {
                time_us: start_us + (t * 1e6).round() as u64,
                sensor: tracker.sensor,
                position: DVec3::new(round(p.x, 1e-4), round(p.y, 1e-4), round(p.z, 1e-4)),
                orientation: DQuat::from_xyzw(
                    round(q.x, 1e-5),
                    round(q.y, 1e-5),
                    round(q.z, 1e-5),
                    round(q.w, 1e-5),
                ),
            });
        }
    }
    Ok(out)
}

/// Reads a clip: AMC (with its ASF) or BVH.
pub fn read_clip(
    clip: &Path,
    skeleton: Option<&Path>,
    scale: Option<f64>,
    fps: f64,
) -> Result<Motion, CmdError> {
    let ext = clip
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    match ext.as_deref() {
        Some("amc") => {
            let asf = skeleton.ok_or("an AMC clip needs --skeleton FILE.asf")?;
            if !(fps.is_finite() && fps > 0.0) {
                return Err(format!("--fps {fps}: expected a rate > 0").into());
            }
            Ok(import::amc::read_motion(asf, clip, 1.0 / fps)?)
        }
        Some("bvh") => Ok(import::bvh::read_motion(
            clip,
            scale.unwrap_or(import::CMU_UNIT_METRES),
        )?),
        _ => Err(format!("{}: expected a .amc or .bvh file", clip.display()).into()),
    }
}

/// Records the clip and writes the CSV.
pub fn run(args: &Args) -> Result<(), CmdError> {
    let motion = read_clip(&args.clip, args.skeleton.as_deref(), args.scale, args.fps)?;
    let trackers = if args.sensors.is_empty() {
        default_trackers(&motion)
    } else {
        args.sensors
            .iter()
            .map(|s| Tracker::parse(s))
            .collect::<Result<Vec<_>, _>>()?
    };
    let samples = record(&motion, &trackers, args.rate_hz, args.start_us)?;
    if let Some(dir) = args.output.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    let file = std::fs::File::create(&args.output)
        .map_err(|e| format!("{}: {e}", args.output.display()))?;
    let out = std::io::BufWriter::new(file);
    match args.frame {
        Framing::Compact => write_csv_exact(out, &snap_compact(&samples)),
        Framing::F32 => write_csv(out, &samples),
    }
    .map_err(|e| format!("{}: {e}", args.output.display()))?;
    let frames = samples.len() / trackers.len().max(1);
    println!(
        "{}: {} sensors x {} samples at {} Hz ({:.3} s) from {} ({} frames)",
        args.output.display(),
        trackers.len(),
        frames,
        args.rate_hz,
        frames.saturating_sub(1) as f64 / args.rate_hz,
        args.clip.display(),
        motion.frames.len()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::import::{Frame, Joint};

    /// A root and a 1 m bone along +X that turns 90° about Y between two
    /// frames 0.1 s apart, while the root moves 1 m along +Z.
    fn motion() -> Motion {
        let joint = |name: &str, parent, offset| Joint {
            name: name.into(),
            parent,
            offset,
            end_site: false,
        };
        let frame = |z: f64, turn: f64| Frame {
            root_position: DVec3::new(0.0, 1.0, z),
            rotations: vec![DQuat::IDENTITY, DQuat::from_rotation_y(turn)],
        };
        Motion {
            source: "test".into(),
            joints: vec![
                joint("root", None, DVec3::ZERO),
                joint("arm", Some(0), DVec3::X),
                joint("tip", Some(1), DVec3::X),
            ],
            frame_time: 0.1,
            frames: vec![frame(0.0, 0.0), frame(1.0, std::f64::consts::FRAC_PI_2)],
        }
    }

    #[test]
    fn trackers_interpolate_between_frames() {
        let trackers = vec![
            Tracker::parse("0=arm+tip").unwrap(),
            Tracker::parse("2=root").unwrap(),
        ];
        let s = record(&motion(), &trackers, 40.0, 1000).unwrap();
        // 0.1 s at 40 Hz: t = 0, 0.025, 0.05, 0.075, 0.1.
        assert_eq!(s.len(), 10);
        assert_eq!(s[0].time_us, 1000);
        assert_eq!(s[9].time_us, 101_000);
        // Midway (t = 0.05): root at z = 0.5. The mean of the arm's ends is
        // (1.5, 1, 0) in frame 0 and (1, 1, 0.5) in frame 1 (the bone turned
        // to −Z, the root 1 m on): halfway, (1.25, 1, 0.25); its rotation is
        // halfway too, 45° about Y.
        let (arm, root) = (&s[4], &s[5]);
        assert_eq!((arm.sensor, root.sensor), (0, 2));
        assert!((root.position - DVec3::new(0.0, 1.0, 0.5)).length() < 1e-9);
        assert!((arm.position - DVec3::new(1.25, 1.0, 0.25)).length() < 1e-9);
        // A quarter of the way: (1.375, 1, 0.125), rounded to 0.1 mm.
        assert!((s[2].position - DVec3::new(1.375, 1.0, 0.125)).length() < 1e-4);
        let want = DQuat::from_rotation_y(std::f64::consts::FRAC_PI_4);
        // Rounded to 1e-5 per component, so compare normalized.
        assert!(arm.orientation.normalize().dot(want).abs() > 1.0 - 1e-9);
    }

    #[test]
    fn csv_numbers_are_short_and_read_back() {
        assert_eq!(fixed(-0.39080000000000004, 4), "-0.3908");
        assert_eq!(fixed(0.8960, 4), "0.896");
        assert_eq!(fixed(-0.00001, 4), "0");
        assert_eq!(fixed(1.0, 5), "1");
        let s = record(&motion(), &[Tracker::parse("0=arm+tip").unwrap()], 40.0, 0).unwrap();
        let mut text = Vec::new();
        write_csv(&mut text, &s).unwrap();
        let back = crate::import::csv::parse_tracker_csv(text.as_slice(), "t.csv").unwrap();
        assert_eq!(back.len(), s.len());
        for (a, b) in back.iter().zip(&s) {
            assert_eq!((a.time_us, a.sensor), (b.time_us, b.sensor));
            assert!((a.position - b.position).length() < 1e-9);
            assert!(a.orientation.dot(b.orientation.normalize()).abs() > 1.0 - 1e-9);
        }
    }

    /// A compact recording reads back as exactly the values the compact
    /// frame carries: encoding its `f32`s again gives the same bytes.
    #[test]
    fn compact_recordings_are_what_the_board_receives() {
        let s = record(&motion(), &[Tracker::parse("0=arm+tip").unwrap()], 40.0, 0).unwrap();
        let snapped = snap_compact(&s);
        let mut text = Vec::new();
        write_csv_exact(&mut text, &snapped).unwrap();
        let back = crate::import::csv::parse_tracker_csv(text.as_slice(), "t.csv").unwrap();
        let frames = crate::perform::frames(&back).unwrap();
        for (f, orig) in frames.iter().zip(&s) {
            let sensor = f.sensors.as_slice()[0];
            let bytes = compact::pack_sensor(&sensor).unwrap();
            let got = compact::unpack_sensor(&bytes).unwrap();
            assert_eq!(got.position().to_array(), sensor.position);
            assert!((got.position().as_dvec3() - orig.position).length() < 1e-4);
        }
    }

    #[test]
    fn bad_sensors_are_refused() {
        assert!(Tracker::parse("x=root").is_err());
        assert!(Tracker::parse("0=").is_err());
        assert!(Tracker::parse("root").is_err());
        let e = record(&motion(), &[Tracker::parse("0=hand").unwrap()], 1000.0, 0).unwrap_err();
        assert!(e.contains("no joint \"hand\""), "{e}");
    }
}
