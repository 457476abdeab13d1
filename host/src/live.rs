//! Live sources for `marionette live`: the VMC protocol (OSC over UDP, as
//! sent by Virtual Motion Capture, XR Animator, SlimeVR's VMC output and
//! others) for sensors, and plain OSC addresses (faders on a tablet) for
//! parameters. [`Source`] turns UDP payloads into sensors and parameters by
//! the rig file's `[live]` table ([`LiveMap`]); it never fails on a packet:
//! a malformed one is counted and skipped.
//!
//! # VMC messages read
//!
//! | address | arguments | becomes |
//! |---|---|---|
//! | `/VMC/Ext/Tra/Pos` | serial, p.x, p.y, p.z, q.x, q.y, q.z, q.w | the sensor mapped to `serial`, as is (world) |
//! | `/VMC/Ext/Bone/Pos` | name, p.x, …, q.w | the bone's local pose (to its Unity humanoid parent) |
//! | `/VMC/Ext/Root/Pos` | name, p.x, …, q.w (more ignored) | the model root's world pose |
//! | a `[[live.param]]` address | a number (float, int, double or bool) | `offset + scale · value` |
//!
//! Floats may also come as doubles. A bone mapped to a sensor is placed in
//! the world through its chain of humanoid parents ([`humanoid_parent`];
//! a bone not received is skipped, its child hanging from the next one up)
//! and the root: `p = p_parent + q_parent · p_local`, `q = q_parent ·
//! q_local`. Every other address is counted as unused.
//!
//! # From Unity's frame to Marionette's
//!
//! VMC uses Unity's axes: left-handed, Y up, Z forward, X right. Marionette
//! is right-handed with Y up. The two differ by one mirror, `M = diag(−1, 1,
//! 1)` (X negated), which [`unity_to_rig`] applies:
//!
//! - position: `(x, y, z) → (−x, y, z)`;
//! - rotation: a rotation `R` becomes `M R M`. Its axis `a` becomes
//!   `det(M) · M a = (a.x, −a.y, −a.z)` (a mirror flips an axial vector)
//!   and its angle is kept, so a quaternion `(w; x, y, z)` becomes
//!   `(w; x, −y, −z)`.
//!
//! Worked by hand (the unit test `unity_quarter_turn_about_y`): Unity's
//! `Quaternion.Euler(0, 90, 0)` = `(w, x, y, z) = (cos 45°, 0, sin 45°, 0)`
//! turns forward `(0, 0, 1)` to right `(1, 0, 0)`. In Marionette's frame
//! those vectors are `(0, 0, 1)` and `(−1, 0, 0)`; the converted quaternion
//! `(cos 45°, 0, −sin 45°, 0)` is −90° about +Y, which turns `(0, 0, 1)` to
//! `(sin(−90°), 0, cos(−90°)) = (−1, 0, 0)`. The mirror is its own inverse
//! and exact in `f32` (only signs change). Units are metres on both sides.
//!
//! # Frames
//!
//! Each UDP packet (a bundle or a message) that updates a mapped sensor
//! yields one tracker frame carrying every mapped sensor heard so far (the
//! latest pose of each); each packet that updates a mapped address yields
//! one `Params` with every mapped parameter. Senders that split one of
//! their frames over several packets thus give several tracker frames.

use crate::rigfile::{LiveMap, LiveParam};
use glam::{Quat, Vec3};
use marionette_core::wire::{List, MAX_SENSORS, Sensor};
use rosc::{OscMessage, OscPacket, OscType};
use std::collections::HashMap;

/// VMC's default UDP port (the receiving side's).
pub const VMC_PORT: u16 = 39539;
/// `/VMC/Ext/Tra/Pos`: a tracker's world pose.
pub const TRACKER: &str = "/VMC/Ext/Tra/Pos";
/// `/VMC/Ext/Bone/Pos`: a humanoid bone's local pose.
pub const BONE: &str = "/VMC/Ext/Bone/Pos";
/// `/VMC/Ext/Root/Pos`: the model root's world pose.
pub const ROOT: &str = "/VMC/Ext/Root/Pos";

/// A pose: position (m) and rotation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// Position, m.
    pub position: Vec3,
    /// Rotation.
    pub rotation: Quat,
}

impl Pose {
    /// No translation, no rotation.
    pub const IDENTITY: Self = Self {
        position: Vec3::ZERO,
        rotation: Quat::IDENTITY,
    };

    /// `child` (given in this pose's frame) in this pose's parent frame.
    #[must_use]
    pub fn then(self, child: Self) -> Self {
        Self {
            position: self.position + self.rotation * child.position,
            rotation: self.rotation * child.rotation,
        }
    }
}

/// A pose in Unity's left-handed frame, in Marionette's right-handed Y-up
/// frame (see the module doc): X mirrored.
#[must_use]
pub fn unity_to_rig(p: Pose) -> Pose {
    let (v, q) = (p.position, p.rotation);
    Pose {
        position: Vec3::new(-v.x, v.y, v.z),
        rotation: Quat::from_xyzw(q.x, -q.y, -q.z, q.w),
    }
}

/// The humanoid bones' parents (Unity's `HumanBodyBones`): `(bone,
/// parent)`; `Hips` hangs from the root.
const HUMANOID: &[(&str, &str)] = &[
    ("Spine", "Hips"),
    ("Chest", "Spine"),
    ("UpperChest", "Chest"),
    ("Neck", "UpperChest"),
    ("Head", "Neck"),
    ("LeftEye", "Head"),
    ("RightEye", "Head"),
    ("Jaw", "Head"),
    ("LeftUpperLeg", "Hips"),
    ("LeftLowerLeg", "LeftUpperLeg"),
    ("LeftFoot", "LeftLowerLeg"),
    ("LeftToes", "LeftFoot"),
    ("RightUpperLeg", "Hips"),
    ("RightLowerLeg", "RightUpperLeg"),
    ("RightFoot", "RightLowerLeg"),
    ("RightToes", "RightFoot"),
    ("LeftShoulder", "UpperChest"),
    ("LeftUpperArm", "LeftShoulder"),
    ("LeftLowerArm", "LeftUpperArm"),
    ("LeftHand", "LeftLowerArm"),
    ("RightShoulder", "UpperChest"),
    ("RightUpperArm", "RightShoulder"),
    ("RightLowerArm", "RightUpperArm"),
    ("RightHand", "RightLowerArm"),
    ("LeftThumbProximal", "LeftHand"),
    ("LeftThumbIntermediate", "LeftThumbProximal"),
    ("LeftThumbDistal", "LeftThumbIntermediate"),
    ("LeftIndexProximal", "LeftHand"),
    ("LeftIndexIntermediate", "LeftIndexProximal"),
    ("LeftIndexDistal", "LeftIndexIntermediate"),
    ("LeftMiddleProximal", "LeftHand"),
    ("LeftMiddleIntermediate", "LeftMiddleProximal"),
    ("LeftMiddleDistal", "LeftMiddleIntermediate"),
    ("LeftRingProximal", "LeftHand"),
    ("LeftRingIntermediate", "LeftRingProximal"),
    ("LeftRingDistal", "LeftRingIntermediate"),
    ("LeftLittleProximal", "LeftHand"),
    ("LeftLittleIntermediate", "LeftLittleProximal"),
    ("LeftLittleDistal", "LeftLittleIntermediate"),
    ("RightThumbProximal", "RightHand"),
    ("RightThumbIntermediate", "RightThumbProximal"),
    ("RightThumbDistal", "RightThumbIntermediate"),
    ("RightIndexProximal", "RightHand"),
    ("RightIndexIntermediate", "RightIndexProximal"),
    ("RightIndexDistal", "RightIndexIntermediate"),
    ("RightMiddleProximal", "RightHand"),
    ("RightMiddleIntermediate", "RightMiddleProximal"),
    ("RightMiddleDistal", "RightMiddleIntermediate"),
    ("RightRingProximal", "RightHand"),
    ("RightRingIntermediate", "RightRingProximal"),
    ("RightRingDistal", "RightRingIntermediate"),
    ("RightLittleProximal", "RightHand"),
    ("RightLittleIntermediate", "RightLittleProximal"),
    ("RightLittleDistal", "RightLittleIntermediate"),
];

/// A humanoid bone's parent (`None` for `Hips`, whose parent is the root,
/// and for a name that is no humanoid bone).
#[must_use]
pub fn humanoid_parent(bone: &str) -> Option<&'static str> {
    HUMANOID.iter().find(|(b, _)| *b == bone).map(|(_, p)| *p)
}

/// Whether `name` is a humanoid bone.
#[must_use]
pub fn is_humanoid(name: &str) -> bool {
    name == "Hips" || humanoid_parent(name).is_some()
}

/// What a source has received.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct SourceCounts {
    /// UDP packets read.
    pub packets: u64,
    /// Packets that were not OSC, or held a message with bad arguments
    /// (wrong count or type, not finite, not a rotation).
    pub malformed: u64,
    /// Messages used (mapped trackers, bones, root, parameters).
    pub used: u64,
    /// Messages not used (addresses or names not mapped).
    pub unused: u64,
}

/// What one packet changed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Heard {
    /// A mapped sensor (or the bones or root under one) moved.
    pub sensors: bool,
    /// A mapped parameter changed.
    pub params: bool,
}

/// Why a message was malformed.
#[derive(Debug)]
struct Malformed;

/// A live source: the latest of everything heard, mapped by the rig file.
pub struct Source {
    map: LiveMap,
    root: Pose,
    /// Latest local pose of each humanoid bone heard (bounded by
    /// [`HUMANOID`]).
    bones: HashMap<&'static str, Pose>,
    /// Latest world pose (Marionette's frame) of each mapped tracker.
    trackers: HashMap<u8, Pose>,
    params: Vec<f32>,
    /// What it received.
    pub counts: SourceCounts,
}

impl Source {
    /// A source mapped by `map`; parameters start at their offsets.
    #[must_use]
    pub fn new(map: LiveMap) -> Self {
        let params = map.params.iter().map(|p| p.offset).collect();
        Self {
            map,
            root: Pose::IDENTITY,
            bones: HashMap::new(),
            trackers: HashMap::new(),
            params,
            counts: SourceCounts::default(),
        }
    }

    /// Reads one UDP payload; a malformed one is counted (its good
    /// messages are still used).
    pub fn packet(&mut self, bytes: &[u8]) -> Heard {
        self.counts.packets += 1;
        let mut heard = Heard::default();
        let ok = match rosc::decoder::decode_udp(bytes) {
            // Bytes left over: a bundle element cut short.
            Ok((rest, packet)) => self.walk(&packet, &mut heard) && rest.is_empty(),
            Err(_) => false,
        };
        if !ok {
            self.counts.malformed += 1;
        }
        heard
    }

    /// Every message of `packet`; false if one was malformed.
    fn walk(&mut self, packet: &OscPacket, heard: &mut Heard) -> bool {
        match packet {
            OscPacket::Message(m) => match self.message(m, heard) {
                Ok(true) => {
                    self.counts.used += 1;
                    true
                }
                Ok(false) => {
                    self.counts.unused += 1;
                    true
                }
                Err(Malformed) => false,
            },
            OscPacket::Bundle(b) => {
                // Every element is read, even after a malformed one.
                let mut ok = true;
                for p in &b.content {
                    ok &= self.walk(p, heard);
                }
                ok
            }
        }
    }

    /// One message: true if used.
    fn message(&mut self, m: &OscMessage, heard: &mut Heard) -> Result<bool, Malformed> {
        match m.addr.as_str() {
            TRACKER => {
                let (name, pose) = named_pose(&m.args)?;
                let Some(id) = self.sensor_id(name) else {
                    return Ok(false);
                };
                self.trackers.insert(id, unity_to_rig(pose));
                heard.sensors = true;
                Ok(true)
            }
            BONE => {
                let (name, pose) = named_pose(&m.args)?;
                let Some(bone) = HUMANOID
                    .iter()
                    .map(|(b, _)| *b)
                    .chain(["Hips"])
                    .find(|b| *b == name)
                else {
                    return Ok(false);
                };
                self.bones.insert(bone, pose);
                heard.sensors |= self.map.sensors.iter().any(|s| is_humanoid(&s.name));
                Ok(true)
            }
            ROOT => {
                let (_, pose) = named_pose(&m.args)?;
                self.root = pose;
                heard.sensors |= self.map.sensors.iter().any(|s| is_humanoid(&s.name));
                Ok(true)
            }
            addr => {
                let Some(i) = self.map.params.iter().position(|p| p.address == addr) else {
                    return Ok(false);
                };
                let value = number(m.args.first())?;
                let LiveParam { scale, offset, .. } = self.map.params[i];
                let v = offset + scale * value;
                if !v.is_finite() {
                    return Err(Malformed);
                }
                if let Some(slot) = self.params.get_mut(i) {
                    *slot = v;
                }
                heard.params = true;
                Ok(true)
            }
        }
    }

    fn sensor_id(&self, name: &str) -> Option<u8> {
        self.map
            .sensors
            .iter()
            .find(|s| s.name == name)
            .map(|s| s.sensor)
    }

    /// A humanoid bone's world pose (Unity's frame), if it was heard.
    fn bone_world(&self, bone: &str) -> Option<Pose> {
        let mut pose = *self.bones.get(bone)?;
        let mut at = bone;
        while let Some(parent) = humanoid_parent(at) {
            if let Some(p) = self.bones.get(parent) {
                pose = p.then(pose);
            }
            at = parent;
        }
        Some(self.root.then(pose))
    }

    /// Every mapped sensor heard so far, in Marionette's frame, by id.
    #[must_use]
    pub fn sensors(&self) -> List<Sensor, MAX_SENSORS> {
        let mut found: Vec<(u8, Pose)> = self
            .map
            .sensors
            .iter()
            .filter_map(|s| {
                let pose = if is_humanoid(&s.name) {
                    self.bone_world(&s.name).map(unity_to_rig)
                } else {
                    self.trackers.get(&s.sensor).copied()
                };
                pose.map(|p| (s.sensor, p))
            })
            .collect();
        found.sort_by_key(|(id, _)| *id);
        let mut out = List::new();
        for (id, p) in found {
            let q = p.rotation;
            // At most MAX_SENSORS: the rig file's ids are unique and below it.
            let _ = out.push(Sensor {
                id,
                position: p.position.to_array(),
                rotation: [q.w, q.x, q.y, q.z],
            });
        }
        out
    }

    /// The mapped parameters' values, `0..k`.
    #[must_use]
    pub fn params(&self) -> &[f32] {
        &self.params
    }
}

/// A VMC pose message's arguments: a name and seven numbers (position,
/// then the rotation as x, y, z, w); more are ignored.
fn named_pose(args: &[OscType]) -> Result<(&str, Pose), Malformed> {
    let Some(OscType::String(name)) = args.first() else {
        return Err(Malformed);
    };
    let mut v = [0f32; 7];
    for (slot, arg) in v.iter_mut().zip(args.get(1..8).ok_or(Malformed)?) {
        *slot = match arg {
            OscType::Float(x) => *x,
            OscType::Double(x) => *x as f32,
            _ => return Err(Malformed),
        };
    }
    let rotation = Quat::from_xyzw(v[3], v[4], v[5], v[6]);
    let norm2 = rotation.length_squared();
    if v.iter().any(|x| !x.is_finite()) || !(0.9..=1.1).contains(&norm2) {
        return Err(Malformed);
    }
    let pose = Pose {
        position: Vec3::new(v[0], v[1], v[2]),
        rotation,
    };
    Ok((name, pose))
}

/// A parameter message's value.
fn number(arg: Option<&OscType>) -> Result<f32, Malformed> {
    let v = match arg {
        Some(OscType::Float(x)) => *x,
        Some(OscType::Double(x)) => *x as f32,
        Some(OscType::Int(x)) => *x as f32,
        Some(OscType::Long(x)) => *x as f32,
        Some(OscType::Bool(b)) => f32::from(u8::from(*b)),
        _ => return Err(Malformed),
    };
    if v.is_finite() { Ok(v) } else { Err(Malformed) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rigfile::LiveSensor;
    use rosc::{OscBundle, OscTime};

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).length() < 1e-6
    }

    #[test]
    fn unity_quarter_turn_about_y() {
        // Worked in the module doc: Unity's Euler(0, 90, 0) turns forward
        // to right; in our frame, (0, 0, 1) to (-1, 0, 0).
        let h = std::f32::consts::FRAC_1_SQRT_2;
        let unity = Pose {
            position: Vec3::new(1.0, 2.0, 3.0),
            rotation: Quat::from_xyzw(0.0, h, 0.0, h),
        };
        let rig = unity_to_rig(unity);
        assert_eq!(rig.position, Vec3::new(-1.0, 2.0, 3.0));
        assert_eq!(rig.rotation, Quat::from_xyzw(0.0, -h, 0.0, h));
        assert!(close(rig.rotation * Vec3::Z, Vec3::new(-1.0, 0.0, 0.0)));
        // The right-handed quaternion for -90 degrees about +Y, built
        // independently.
        let expected = Quat::from_axis_angle(Vec3::Y, -std::f32::consts::FRAC_PI_2);
        assert!(rig.rotation.dot(expected).abs() > 1.0 - 1e-6);
    }

    #[test]
    fn unity_quarter_turn_about_x_tips_forward_down() {
        // Unity: Euler(90, 0, 0) turns forward (0, 0, 1) to down (0, -1,
        // 0); the mirror leaves both vectors as they are.
        let h = std::f32::consts::FRAC_1_SQRT_2;
        let rig = unity_to_rig(Pose {
            position: Vec3::ZERO,
            rotation: Quat::from_xyzw(h, 0.0, 0.0, h),
        });
        assert!(close(rig.rotation * Vec3::Z, Vec3::new(0.0, -1.0, 0.0)));
    }

    fn map() -> LiveMap {
        LiveMap {
            sensors: vec![
                LiveSensor {
                    name: "RightHand".into(),
                    sensor: 0,
                },
                LiveSensor {
                    name: "tracker-7".into(),
                    sensor: 3,
                },
            ],
            params: vec![LiveParam {
                address: "/fader".into(),
                param: 0,
                scale: 2.0,
                offset: 0.5,
            }],
        }
    }

    fn pose_msg(addr: &str, name: &str, p: [f32; 3], q: [f32; 4]) -> OscPacket {
        let mut args = vec![OscType::String(name.into())];
        args.extend(p.iter().chain(&q).map(|&x| OscType::Float(x)));
        OscPacket::Message(OscMessage {
            addr: addr.into(),
            args,
        })
    }

    fn bundle(content: Vec<OscPacket>) -> Vec<u8> {
        rosc::encoder::encode(&OscPacket::Bundle(OscBundle {
            timetag: OscTime::from((0, 1)),
            content,
        }))
        .unwrap()
    }

    #[test]
    fn a_bone_is_placed_through_its_chain_and_the_root() {
        let mut src = Source::new(map());
        let id = [0.0, 0.0, 0.0, 1.0];
        let h = std::f32::consts::FRAC_1_SQRT_2;
        // Root 1 m along Unity +Z; hips 1 m up, turned +90 degrees about Y
        // (forward becomes right); lower arm 0.3 m along the hips' forward
        // (no upper arm or shoulder sent: skipped); hand 0.25 m further.
        let bytes = bundle(vec![
            pose_msg(ROOT, "root", [0.0, 0.0, 1.0], id),
            pose_msg(BONE, "Hips", [0.0, 1.0, 0.0], [0.0, h, 0.0, h]),
            pose_msg(BONE, "RightLowerArm", [0.0, 0.0, 0.3], id),
            pose_msg(BONE, "RightHand", [0.0, 0.0, 0.25], id),
            pose_msg(BONE, "NotABone", [0.0, 0.0, 0.0], id),
        ]);
        let heard = src.packet(&bytes);
        assert!(heard.sensors && !heard.params);
        // Unity world: (0, 1, 1) + right (1, 0, 0) * 0.55 = (0.55, 1, 1);
        // ours: (-0.55, 1, 1).
        let sensors = src.sensors();
        let s = sensors.as_slice();
        assert_eq!(s.len(), 1);
        assert_eq!(s[0].id, 0);
        assert!(close(Vec3::from(s[0].position), Vec3::new(-0.55, 1.0, 1.0)));
        assert_eq!(
            src.counts,
            SourceCounts {
                packets: 1,
                malformed: 0,
                used: 4,
                unused: 1
            }
        );
    }

    #[test]
    fn trackers_and_params_map_by_name_and_address() {
        let mut src = Source::new(map());
        assert_eq!(src.params(), [0.5]);
        let bytes = bundle(vec![
            pose_msg(TRACKER, "tracker-7", [1.0, 2.0, 3.0], [0.0, 0.0, 0.0, 1.0]),
            pose_msg(TRACKER, "other", [1.0, 2.0, 3.0], [0.0, 0.0, 0.0, 1.0]),
        ]);
        assert!(src.packet(&bytes).sensors);
        let s = src.sensors();
        assert_eq!(s.as_slice().len(), 1);
        assert_eq!(
            (s.as_slice()[0].id, s.as_slice()[0].position),
            (3, [-1.0, 2.0, 3.0])
        );
        let fader = rosc::encoder::encode(&OscPacket::Message(OscMessage {
            addr: "/fader".into(),
            args: vec![OscType::Int(3)],
        }))
        .unwrap();
        let heard = src.packet(&fader);
        assert!(heard.params && !heard.sensors);
        assert_eq!(src.params(), [6.5]);
    }

    #[test]
    fn malformed_packets_are_counted_and_change_nothing() {
        let mut src = Source::new(map());
        let bad_args = bundle(vec![OscPacket::Message(OscMessage {
            addr: TRACKER.into(),
            args: vec![OscType::String("tracker-7".into()), OscType::Int(1)],
        })]);
        let zero_rotation = bundle(vec![pose_msg(TRACKER, "tracker-7", [0.0; 3], [0.0; 4])]);
        let nan = bundle(vec![pose_msg(
            TRACKER,
            "tracker-7",
            [f32::NAN, 0.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        )]);
        let mut truncated = bundle(vec![pose_msg(
            TRACKER,
            "tracker-7",
            [0.0; 3],
            [0.0, 0.0, 0.0, 1.0],
        )]);
        truncated.truncate(truncated.len() - 5);
        let fader_text = rosc::encoder::encode(&OscPacket::Message(OscMessage {
            addr: "/fader".into(),
            args: vec![OscType::String("loud".into())],
        }))
        .unwrap();
        for bytes in [
            b"not OSC at all".to_vec(),
            Vec::new(),
            bad_args,
            zero_rotation,
            nan,
            truncated,
            fader_text,
        ] {
            let before = src.counts.malformed;
            assert_eq!(src.packet(&bytes), Heard::default());
            assert_eq!(src.counts.malformed, before + 1, "{bytes:?}");
        }
        assert_eq!(src.counts.malformed, 7);
        assert_eq!(src.counts.packets, 7);
        assert!(src.sensors().as_slice().is_empty());
        assert_eq!(src.params(), [0.5]);
    }
}

#[cfg(test)]
mod rigfile_tests {
    use crate::rigfile::{self, RigFileError};

    fn humanoid16() -> String {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../rigs/humanoid16.toml");
        std::fs::read_to_string(path).unwrap()
    }

    #[test]
    fn the_shipped_rig_maps_vmc_bones_to_its_sensors() {
        let rig = rigfile::parse(&humanoid16(), "humanoid16.toml").unwrap();
        let names: Vec<(&str, u8)> = rig
            .live
            .sensors
            .iter()
            .map(|s| (s.name.as_str(), s.sensor))
            .collect();
        assert_eq!(names, [("RightHand", 0), ("LeftHand", 1), ("Hips", 2)]);
        assert!(rig.live.params.is_empty());
    }

    fn error(extra: &str) -> (usize, String, String) {
        let text = format!("{}\n{extra}", humanoid16());
        match rigfile::parse(&text, "r.toml").unwrap_err() {
            RigFileError::At {
                line,
                field,
                message,
                ..
            } => (line, field, message),
            other => panic!("{other}"),
        }
    }

    #[test]
    fn live_table_errors_name_the_line_and_field() {
        let base = humanoid16().lines().count();
        let (line, field, msg) = error("[[live.sensor]]\nname = \"Head\"\nsensor = 2\n");
        assert_eq!(
            (line, field.as_str()),
            (base + 4, "live.sensor[3].sensor"),
            "{msg}"
        );
        let (line, field, _) = error("[[live.sensor]]\nname = \"Hips\"\nsensor = 5\n");
        assert_eq!((line, field.as_str()), (base + 3, "live.sensor[3].name"));
        let (_, field, msg) = error("[[live.param]]\naddress = \"/fader\"\nparam = 1\n");
        assert_eq!(field, "live.param");
        assert!(msg.contains("param 0 is missing"), "{msg}");
        let (line, field, _) = error("[[live.param]]\naddress = \"fader\"\nparam = 0\n");
        assert_eq!((line, field.as_str()), (base + 3, "live.param[0].address"));
    }
}
