//! Rig files and the rig blob, against independent references:
//!
//! - the blob's bytes are walked by a decoder written here from the format
//!   documented in `marionette_core::rig` (not by the core's postcard types),
//!   and the skeleton hash is recomputed from those bytes with a textbook
//!   FNV-1a;
//! - `rigs/cmu31.toml` against the BVH file's `HIERARCHY` (parsed here) and
//!   against `body::cmu`;
//! - `rigs/humanoid16.toml` against hand-worked facts (16 servos, one per DOF,
//!   every servo able to reach its joint's whole range, soles on the floor);
//! - the sensor map against closed forms computed in `f64` here;
//! - a table of bad rig files: each error must name `file:line` (the line
//!   found here by searching the file text) and the field;
//! - totality: arbitrary floats into the sensor map, arbitrary and mutated
//!   bytes (with a recomputed CRC, so they reach the decoder) into the parser.

use marionette_core::body;
use marionette_core::crc::crc32;
use marionette_core::goal::{Attach, Frame, GoalSet, PlaneSide, Target};
use marionette_core::rig::{Rig, RigDesc, RigError};
use marionette_core::wire::Sensor;
use marionette_host::rigfile::{self, RigFile, RigFileError};
use proptest::prelude::*;
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn load(name: &str) -> RigFile {
    rigfile::load(&repo().join("rigs").join(name)).unwrap_or_else(|e| panic!("{e}"))
}

fn blob(name: &str) -> Vec<u8> {
    rigfile::to_blob(&load(name)).unwrap()
}

/// The humanoid16 and `MEASURES` blobs, built once (for the property tests).
fn shared_blobs() -> &'static (Vec<u8>, Vec<u8>) {
    static BLOBS: std::sync::OnceLock<(Vec<u8>, Vec<u8>)> = std::sync::OnceLock::new();
    BLOBS.get_or_init(|| {
        let m = rigfile::parse(MEASURES, "m.toml").unwrap();
        (blob("humanoid16.toml"), rigfile::to_blob(&m).unwrap())
    })
}

// ---------------------------------------------------------------------------
// An independent reader of the documented byte layout.

struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn byte(&mut self) -> u8 {
        let v = self.b[self.at];
        self.at += 1;
        v
    }
    fn varint(&mut self) -> u64 {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let b = self.byte();
            v |= u64::from(b & 0x7F) << shift;
            if b & 0x80 == 0 {
                return v;
            }
        }
        panic!("varint too long")
    }
    fn f32(&mut self) -> f32 {
        let v = f32::from_le_bytes(self.b[self.at..self.at + 4].try_into().unwrap());
        self.at += 4;
        v
    }
    fn floats<const N: usize>(&mut self) -> [f32; N] {
        std::array::from_fn(|_| self.f32())
    }
    fn str(&mut self) -> String {
        let n = self.varint() as usize;
        let s = std::str::from_utf8(&self.b[self.at..self.at + n])
            .unwrap()
            .to_string();
        self.at += n;
        s
    }
    fn bool(&mut self) -> bool {
        match self.byte() {
            0 => false,
            1 => true,
            b => panic!("bool byte {b}"),
        }
    }
    fn ref_frame(&mut self) -> (u64, Option<u8>) {
        match self.varint() {
            0 => (0, None),
            v @ (1 | 2) => (v, Some(self.byte())),
            v => panic!("RefFrame variant {v}"),
        }
    }
}

/// One segment as decoded by hand: name, parent, origin, touch, dofs.
type RawSegment = (String, u8, [f32; 3], [f32; 3], Vec<(u64, f32, f32)>);

/// The documented layout, walked field by field. Returns the segments, the
/// servo channels, the byte range of the segments list, and the number of
/// params and goals.
fn walk(
    desc: &[u8],
) -> (
    Vec<RawSegment>,
    Vec<u8>,
    std::ops::Range<usize>,
    usize,
    usize,
) {
    let mut r = Reader { b: desc, at: 0 };
    let _name = r.str();
    let _period = r.varint();
    let _failsafe = r.varint();
    let _root: [f32; 7] = r.floats();
    match r.varint() {
        0 => {
            r.varint();
        }
        1 => {
            r.byte();
            r.varint();
        }
        2 | 3 => {
            r.varint();
        }
        4 => {
            r.varint();
            r.varint();
        }
        v => panic!("output variant {v}"),
    }
    let idle = r.varint();
    assert!(idle <= 1, "idle variant {idle}");
    let seg_start = r.at;
    let n = r.varint();
    let mut segments = Vec::new();
    for _ in 0..n {
        let name = r.str();
        let parent = r.byte();
        let origin = r.floats();
        let touch = r.floats();
        let dofs = (0..r.varint())
            .map(|_| (r.varint(), r.f32(), r.f32()))
            .collect();
        segments.push((name, parent, origin, touch, dofs));
    }
    let seg_range = seg_start..r.at;
    let mut channels = Vec::new();
    for _ in 0..r.varint() {
        channels.push(r.byte());
        let (_segment, _dof) = (r.byte(), r.byte());
        let _cal: [f32; 5] = r.floats();
        let _reversed = r.bool();
        let _rest_speed_accel: [f32; 3] = r.floats();
        let _id = r.byte();
    }
    let params = r.varint() as usize;
    for _ in 0..params {
        let (_param, _sensor) = (r.byte(), r.byte());
        r.ref_frame();
        match r.varint() {
            0 | 2 => {
                r.varint();
            }
            1 => {
                r.varint();
                let _center: [f32; 3] = r.floats();
                r.varint();
            }
            v => panic!("measure variant {v}"),
        }
        let _offset_scale: [f32; 2] = r.floats();
    }
    let goals = r.varint() as usize;
    for _ in 0..goals {
        let _segment = r.byte();
        if r.bool() {
            let _point: [f32; 3] = r.floats();
        }
        let _weight = r.f32();
        if r.bool() {
            r.byte();
        }
        match r.varint() {
            0 => {
                r.byte();
                r.ref_frame();
                let _rest: [f32; 9] = r.floats();
            }
            1 => {
                let _plane: [f32; 4] = r.floats();
                r.bool();
            }
            2 => {
                let _point: [f32; 3] = r.floats();
            }
            v => panic!("goal variant {v}"),
        }
    }
    assert_eq!(r.at, desc.len(), "the description has trailing bytes");
    (segments, channels, seg_range, params, goals)
}

/// Textbook 64-bit FNV-1a.
fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// The description bytes of a blob, checking the envelope by hand.
fn envelope(b: &[u8]) -> &[u8] {
    assert_eq!(&b[0..4], b"MRIG");
    assert_eq!(u16::from_le_bytes([b[4], b[5]]), 2);
    let len = u32::from_le_bytes(b[6..10].try_into().unwrap()) as usize;
    let crc = u32::from_le_bytes(b[10 + len..14 + len].try_into().unwrap());
    assert_eq!(crc, crc32(&b[..10 + len]));
    assert_eq!(b.len(), (14 + len).div_ceil(4) * 4, "padding to 4");
    assert!(b[14 + len..].iter().all(|&x| x == 0));
    &b[10..10 + len]
}

#[test]
fn blob_layout_matches_the_documentation() {
    for name in ["humanoid16.toml", "cmu31.toml"] {
        let rig = load(name);
        let b = blob(name);
        let desc = envelope(&b);
        let (segments, channels, seg_range, params, goals) = walk(desc);
        assert_eq!(segments.len(), rig.segment_names().len());
        for ((s, _, _, _, _), n) in segments.iter().zip(rig.segment_names()) {
            assert_eq!(s, n);
        }
        assert_eq!(fnv1a64(&desc[seg_range]), rig.rig_hash(), "{name}");
        let (parsed, rest) = Rig::parse(&b).unwrap();
        assert!(rest.is_empty());
        assert_eq!(parsed.rig_hash(), rig.rig_hash());
        assert_eq!(
            channels,
            parsed
                .servos()
                .iter()
                .map(|s| s.channel)
                .collect::<Vec<_>>()
        );
        assert_eq!(params, parsed.params().len());
        assert_eq!(goals, parsed.goals().len());
    }
}

#[test]
fn blobs_sit_back_to_back() {
    let a = blob("humanoid16.toml");
    let b = blob("cmu31.toml");
    let mut flash = a.clone();
    flash.extend_from_slice(&b);
    flash.extend_from_slice(&[0xFF; 64]); // erased flash
    let (first, rest) = Rig::parse(&flash).unwrap();
    assert_eq!(first.name(), "humanoid16");
    let (second, rest) = Rig::parse(rest).unwrap();
    assert_eq!(second.name(), "cmu31");
    assert_eq!(rest, &[0xFF; 64]);
    assert_eq!(Rig::parse(rest).err(), Some(RigError::Magic));
}

#[test]
fn the_skeleton_hash_ignores_servos_and_mapping() {
    let text = std::fs::read_to_string(repo().join("rigs/humanoid16.toml")).unwrap();
    let base = rigfile::parse(&text, "a.toml").unwrap().rig_hash();
    let trimmed = text.replace("trim_us = 12", "trim_us = 30");
    assert_eq!(rigfile::parse(&trimmed, "b.toml").unwrap().rig_hash(), base);
    let longer = text.replace(
        "origin = [0.0, -0.16, 0.0]      # elbow",
        "origin = [0.0, -0.17, 0.0]",
    );
    assert_ne!(rigfile::parse(&longer, "c.toml").unwrap().rig_hash(), base);
}

// ---------------------------------------------------------------------------
// The shipped rigs.

/// The BVH `HIERARCHY`: (name, parent name, offset) per joint, End Sites skipped.
fn bvh_joints(path: &Path) -> Vec<(String, Option<String>, [f64; 3])> {
    let text = std::fs::read_to_string(path).unwrap();
    let head = text.split("MOTION").next().unwrap();
    let t: Vec<&str> = head.split_whitespace().collect();
    let (mut out, mut stack, mut pending) = (Vec::new(), Vec::<Option<String>>::new(), None);
    let mut i = 0;
    while i < t.len() {
        match t[i] {
            "ROOT" | "JOINT" => {
                pending = Some(t[i + 1].to_string());
                i += 2;
            }
            "End" => {
                pending = None;
                i += 2;
            }
            "{" => {
                stack.push(pending.take());
                i += 1;
            }
            "}" => {
                stack.pop();
                i += 1;
            }
            "OFFSET" => {
                if let Some(Some(name)) = stack.last() {
                    let parent = stack.iter().rev().skip(1).flatten().next().cloned();
                    let v = [1, 2, 3].map(|k| t[i + k].parse::<f64>().unwrap());
                    out.push((name.clone(), parent, v));
                }
                i += 4;
            }
            _ => i += 1,
        }
    }
    out
}

#[test]
fn cmu31_is_the_bvh_skeleton() {
    let b = blob("cmu31.toml");
    let (rig, _) = Rig::parse(&b).unwrap();
    let body = rig.body();
    let joints = bvh_joints(&repo().join("data/cmu_02_01_walk/02_01.bvh"));
    assert_eq!(joints.len(), 31);
    assert_eq!(body.len(), 31);
    const UNIT: f64 = 0.0254 / 0.45;
    for (i, ((name, parent, offset), s)) in joints.iter().zip(body.segments).enumerate() {
        assert_eq!(s.name, name);
        let p = parent.as_ref().map(|p| body.find(p).unwrap());
        assert_eq!(body.parent(i), p.map(usize::from), "{name}");
        for (k, (&got, &file)) in s.origin.to_array().iter().zip(offset).enumerate() {
            assert!((f64::from(got) - file * UNIT).abs() < 1e-6, "{name} {k}");
        }
    }
}

#[test]
fn cmu31_matches_body_cmu() {
    let b = blob("cmu31.toml");
    let (rig, _) = Rig::parse(&b).unwrap();
    let ours = rig.body();
    let theirs = &body::cmu::BODY;
    assert_eq!(ours.len(), theirs.len());
    for (a, b) in ours.segments.iter().zip(theirs.segments) {
        assert_eq!(a.name, b.name);
        assert_eq!(a.parent, b.parent, "{}", a.name);
        assert!(
            (a.origin - b.origin).abs().max_element() < 1e-6,
            "{} origin",
            a.name
        );
        assert!(
            (a.touch - b.touch).abs().max_element() < 1e-6,
            "{} touch",
            a.name
        );
        assert_eq!(a.joint.count(), b.joint.count(), "{}", a.name);
        for (x, y) in a.joint.dofs().iter().zip(b.joint.dofs()) {
            assert_eq!(x.axis, y.axis, "{}", a.name);
            // Same degrees, same f32 conversion: exact.
            assert_eq!((x.min, x.max), (y.min, y.max), "{} limits", a.name);
        }
    }
    // Identity retarget map: every segment from the mocap joint of its name.
    let file = load("cmu31.toml");
    assert_eq!(file.retarget.len(), 31);
    for r in &file.retarget {
        assert_eq!(r.mocap, file.segment_names()[usize::from(r.segment)]);
    }
}

#[test]
fn humanoid16_is_a_16_servo_puppet() {
    let b = blob("humanoid16.toml");
    let (rig, _) = Rig::parse(&b).unwrap();
    let body = rig.body();
    assert_eq!(body.validate(), Ok(()));
    assert_eq!(body.dof_count(), 16);
    assert_eq!(rig.servos().len(), 16);
    assert!(matches!(
        rig.output(),
        marionette_core::rig::Output::Maestro { baud: 115_200 }
    ));
    let mut channels: Vec<u8> = rig.servos().iter().map(|s| s.channel).collect();
    channels.sort_unstable();
    assert_eq!(channels, (0..16).collect::<Vec<_>>());
    // Every DOF has exactly one servo, which reaches the DOF's whole range.
    for (i, s) in body.segments.iter().enumerate() {
        for (k, d) in s.joint.dofs().iter().enumerate() {
            let servos: Vec<_> = rig
                .servos()
                .iter()
                .filter(|v| usize::from(v.segment) == i && usize::from(v.dof) == k)
                .collect();
            assert_eq!(servos.len(), 1, "{} dof {k}", s.name);
            let v = servos[0];
            assert!(
                v.angle_min <= d.min && d.max <= v.angle_max,
                "{} dof {k}",
                s.name
            );
            // Hobby servos: 500-2500 µs, 1.5-10 rad/s.
            assert!(v.pulse_min_us >= 500.0 && v.pulse_max_us <= 2500.0);
            assert!((1.5..=10.0).contains(&v.max_speed));
            let cal = v.calibration();
            assert!(cal.pulse_low() <= v.rest_us && v.rest_us <= cal.pulse_high());
        }
    }
    // At rest the soles touch the floor: 0.44 - 0.03 - 0.19 - 0.18 - 0.04 = 0.
    let rest = rig.rest_pose();
    for foot in ["l_foot", "r_foot"] {
        let i = usize::from(body.find(foot).unwrap());
        let sole = rest.positions[i] + rest.rotations[i] * body.segments[i].touch;
        assert!(sole.y.abs() < 1e-6, "{foot} {sole}");
    }
    // The head's top (touch 0.09 above the neck + ~0.08) is at ~0.9 m.
    let head = usize::from(body.find("head").unwrap());
    assert!((rest.positions[head].y - (0.44 + 0.05 + 0.27)).abs() < 1e-6);
    // Rest pulses: the servo's pulse of the rest angle (0 here), from the
    // calibration's linear map: 500 + 2000 * (0 - min) / (max - min).
    let l_knee = rig.servos().iter().find(|s| s.channel == 10).unwrap();
    let want = 500.0 + 2000.0 * 25.0 / 180.0;
    assert!((l_knee.rest_us - want).abs() < 1e-3, "{}", l_knee.rest_us);
}

/// Bone name -> `direction` of an ASF file (read here from its text).
fn asf_directions(path: &Path) -> Vec<(String, [f64; 3])> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut out = Vec::new();
    let mut name = None;
    for line in text.lines() {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["name", n] => name = Some((*n).to_owned()),
            ["direction", x, y, z] => {
                let d = [x, y, z].map(|v| v.parse::<f64>().unwrap());
                out.push((name.take().unwrap(), d));
            }
            _ => {}
        }
    }
    out
}

#[test]
fn humanoid16_has_an_hdm05_retarget_map() {
    let file = load("humanoid16.toml");
    let map = file.retarget_map(Some("hdm05")).expect("an hdm05 map");
    assert!(file.retarget_map(Some("nope")).is_none());
    assert_eq!(file.retarget_map(None).unwrap(), file.retarget.as_slice());
    // Every segment driven exactly once, by the root or an ASF bone.
    let n = file.segment_names().len();
    let mut segs: Vec<u8> = map.iter().map(|r| r.segment).collect();
    segs.sort_unstable();
    assert_eq!(segs, (0..n as u8).collect::<Vec<_>>());
    let asf = asf_directions(&repo().join("data/hdm05_bk/HDM_bk.asf"));
    assert_eq!(asf.len(), 30, "30 bones");
    let direction = |bone: &str| asf.iter().find(|(b, _)| b == bone).map(|(_, d)| *d);
    for r in map {
        assert!(
            r.mocap == "root" || direction(&r.mocap).is_some(),
            "{} is not an HDM05 bone",
            r.mocap
        );
    }
    // The offsets turn each rest limb of the puppet (along its child's
    // origin, or a leaf's touch point) onto the ASF bone's rest direction:
    // W_rig = W_mocap · offset, and every ASF rest rotation is the identity.
    let desc = file.desc();
    let entry = |seg: &str| {
        let i = file.segment_names().iter().position(|s| s == seg).unwrap();
        map.iter().find(|r| usize::from(r.segment) == i).unwrap()
    };
    let limbs = [
        ("l_upper_arm", "l_forearm"),
        ("r_upper_arm", "r_forearm"),
        ("l_forearm", ""),
        ("r_forearm", ""),
        ("l_thigh", "l_shin"),
        ("r_thigh", "r_shin"),
        ("l_shin", "l_foot"),
        ("r_shin", "r_foot"),
    ];
    let seg = |name: &str| {
        let i = file.segment_names().iter().position(|s| s == name).unwrap();
        desc.segments.as_slice()[i]
    };
    for (limb, child) in limbs {
        let bone = if child.is_empty() {
            seg(limb).touch
        } else {
            seg(child).origin
        }
        .map(f64::from);
        let r = entry(limb);
        let turned = rotate(r.rotation_offset, bone);
        let want = direction(&r.mocap).unwrap();
        let cos = (turned[0] * want[0] + turned[1] * want[1] + turned[2] * want[2])
            / (turned.iter().map(|c| c * c).sum::<f64>().sqrt()
                * want.iter().map(|c| c * c).sum::<f64>().sqrt());
        assert!(cos > 0.9999, "{limb} ({}): cos {cos}", r.mocap);
    }
    // The feet take their leg's splay, so a straight leg has a level foot.
    assert_eq!(
        entry("l_foot").rotation_offset,
        entry("l_shin").rotation_offset
    );
    assert_eq!(
        entry("r_foot").rotation_offset,
        entry("r_shin").rotation_offset
    );
    // Map names are unique.
    let text = std::fs::read_to_string(repo().join("rigs/humanoid16.toml")).unwrap();
    let twice = format!("{text}\n[[retarget.map]]\nname = \"hdm05\"\n");
    let e = rigfile::parse(&twice, "bad.toml").unwrap_err().to_string();
    let line = twice.lines().count();
    assert!(
        e.starts_with(&format!("bad.toml:{line}: retarget.map[1].name")) && e.contains("twice"),
        "{e}"
    );
}

// ---------------------------------------------------------------------------
// The sensor map.

fn sensor(id: u8, p: [f64; 3], q: [f64; 4]) -> Sensor {
    Sensor {
        id,
        position: p.map(|x| x as f32),
        rotation: q.map(|x| x as f32),
    }
}

/// `q` (`[w, x, y, z]`) applied to `v`, in f64.
fn rotate(q: [f64; 4], v: [f64; 3]) -> [f64; 3] {
    let [w, x, y, z] = q;
    let u = [x, y, z];
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let t = cross(u, v).map(|c| 2.0 * c);
    let c = cross(u, t);
    [0, 1, 2].map(|k| v[k] + w * t[k] + c[k])
}

fn axis_angle(axis: [f64; 3], angle: f64) -> [f64; 4] {
    let (s, c) = (angle / 2.0).sin_cos();
    [c, axis[0] * s, axis[1] * s, axis[2] * s]
}

fn qmul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    let [aw, ax, ay, az] = a;
    let [bw, bx, by, bz] = b;
    [
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ]
}

#[test]
fn humanoid16_maps_the_hand_in_the_performers_pelvis_frame() {
    let b = blob("humanoid16.toml");
    let (rig, _) = Rig::parse(&b).unwrap();
    // The performer's pelvis at (1, 1, 2), turned 90° about Y; the right hand
    // at (0.2, 0.1, 0.4) in the pelvis frame.
    let pelvis_q = axis_angle([0.0, 1.0, 0.0], std::f64::consts::FRAC_PI_2);
    let local = [0.2, 0.1, 0.4];
    let r = rotate(pelvis_q, local);
    let hand = [1.0 + r[0], 1.0 + r[1], 2.0 + r[2]];
    let sensors = [
        sensor(2, [1.0, 1.0, 2.0], pelvis_q),
        sensor(0, hand, [1.0, 0.0, 0.0, 0.0]),
    ];
    let mut params = [7.0f32; 6];
    let mut goals = GoalSet::<8>::new();
    let report = rig.map_sensors(&sensors, &mut params, &mut goals);
    for k in 0..3 {
        assert!(
            (f64::from(params[k]) - 0.5 * local[k]).abs() < 1e-6,
            "{params:?}"
        );
    }
    assert_eq!(&params[3..], &[7.0; 3]);
    assert_eq!(goals.len(), 4);
    // Goal 0: the right palm at half the hand offset, in the puppet's pelvis frame.
    let g = goals.get(0).unwrap();
    assert_eq!(g.segment, rig.body().find("r_forearm").unwrap());
    assert_eq!(
        (g.weight, g.attach, g.frame),
        (10.0, Attach::Touch, Frame::Segment(0))
    );
    let Target::Position(t) = g.target else {
        panic!()
    };
    for k in 0..3 {
        assert!((f64::from(t[k]) - 0.5 * local[k]).abs() < 1e-6);
    }
    // Goal 1: the left hand's tracker is missing: inactive, reported.
    assert_eq!(goals.get(1).unwrap().weight, 0.0);
    assert_eq!(report.goals_missing, 0b10);
    // Goals 2, 3: the soles on the floor.
    for i in [2, 3] {
        let g = goals.get(i).unwrap();
        assert_eq!(g.weight, 100.0);
        assert_eq!(
            g.target,
            Target::Plane {
                normal: glam::Vec3::Y,
                offset: 0.0,
                side: PlaneSide::Contact
            }
        );
    }
    // Without the pelvis tracker nothing reads: parameters keep their values.
    let mut params = [7.0f32; 6];
    let report = rig.map_sensors(&sensors[1..], &mut params, &mut goals);
    assert_eq!(params, [7.0; 6]);
    assert_eq!((report.params_missing, report.goals_missing), (0b111, 0b11));
    // A NaN hand: reported as non-finite, parameters kept.
    let mut bad = sensors;
    bad[1].position[1] = f32::NAN;
    let report = rig.map_sensors(&bad, &mut params, &mut goals);
    assert_eq!(params, [7.0; 6]);
    assert_eq!(report.params_non_finite, 0b111);
    assert_eq!(report.goals_non_finite, 0b1);
    // A short output slice: reported, not written.
    let mut two = [0.0f32; 2];
    let report = rig.map_sensors(&sensors, &mut two, &mut goals);
    assert_eq!(report.params_unwritten, 0b100);
}

const MEASURES: &str = r#"
name = "measures"
frame_period_us = 1000
failsafe_timeout_ms = 50
root_position = [0.5, 1.0, -0.25]
root_rotation = [0.8660254037844387, 0.0, 0.0, 0.5]   # 60° about Z
[output]
kind = "pca9685"
i2c_addr = 0x40
freq_hz = 60
[[segment]]
name = "base"
[[segment]]
name = "arm"
parent = "base"
origin = [0.0, 0.2, 0.0]
dofs = [{ axis = "z", limits = [-1, 1] }]
[[param]]
param = 0
sensor = 3
measure = "cylindrical"
axis = "y"
center = [0.1, 0.0, -0.2]
component = "radius"
[[param]]
param = 1
sensor = 3
measure = "cylindrical"
axis = "y"
center = [0.1, 0.0, -0.2]
component = "angle"
offset = 1.0
scale = 2.0
[[param]]
param = 2
sensor = 3
frame = "arm"
measure = "cylindrical"
axis = "x"
component = "height"
[[param]]
param = 3
sensor = 3
measure = "rotation"
axis = "z"
[[param]]
param = 4
sensor = 3
frame = "sensor:4"
measure = "rotation"
axis = "y"
[[param]]
param = 5
sensor = 3
frame = "arm"
measure = "position"
component = "y"
[[goal]]
segment = "arm"
weight = 2
point = [0.0, 0.1, 0.0]
sensor = 3
frame = "sensor:4"
offset = [0.0, 0.0, 0.1]
scale = 2.0
orientation_weight = 0.5
rotation_offset = [0.0, 1.0, 0.0, 0.0]
"#;

#[test]
fn measures_match_closed_forms() {
    let file = rigfile::parse(MEASURES, "measures.toml").unwrap_or_else(|e| panic!("{e}"));
    let b = rigfile::to_blob(&file).unwrap();
    let (rig, _) = Rig::parse(&b).unwrap();
    let (a, bb) = (0.7, 0.3);
    // Twist about Z of R_x(b)·R_z(a) is exactly a.
    let q = qmul(
        axis_angle([1.0, 0.0, 0.0], bb),
        axis_angle([0.0, 0.0, 1.0], a),
    );
    let p = [0.4, 0.9, 0.3];
    let other_q = axis_angle([0.0, 1.0, 0.0], -0.4);
    let sensors = [sensor(3, p, q), sensor(4, [0.0, 0.5, 0.0], other_q)];
    let mut params = [0.0f32; 6];
    let mut goals = GoalSet::<8>::new();
    let report = rig.map_sensors(&sensors, &mut params, &mut goals);
    assert!(report.is_clean(), "{report:?}");
    let (dx, dy, dz) = (p[0] - 0.1, p[1], p[2] + 0.2);
    let _ = dy;
    // About Y the angle runs from +Z towards +X.
    let want_radius = dz.hypot(dx);
    let want_angle = 1.0 + 2.0 * dx.atan2(dz);
    // The arm's rest frame: origin root + R·(0, 0.2, 0), rotation R (60° about Z).
    let root_q = axis_angle([0.0, 0.0, 1.0], std::f64::consts::FRAC_PI_3);
    let o = rotate(root_q, [0.0, 0.2, 0.0]);
    let arm_origin = [0.5 + o[0], 1.0 + o[1], -0.25 + o[2]];
    let rel = [0, 1, 2].map(|k| p[k] - arm_origin[k]);
    let inv = [root_q[0], -root_q[1], -root_q[2], -root_q[3]];
    let local = rotate(inv, rel);
    // Twist about Y of the hand relative to sensor 4 (rotation −0.4 about Y):
    // R_y(0.4)·R_x(b)·R_z(a), decomposed by hand in f64.
    let relq = qmul([other_q[0], -other_q[1], -other_q[2], -other_q[3]], q);
    let relq = if relq[0] < 0.0 {
        relq.map(|x| -x)
    } else {
        relq
    };
    let want_twist_y = 2.0 * relq[2].atan2(relq[0]);
    let want = [want_radius, want_angle, local[0], a, want_twist_y, local[1]];
    for k in 0..6 {
        assert!(
            (f64::from(params[k]) - want[k]).abs() < 2e-5,
            "param {k}: {} vs {}",
            params[k],
            want[k]
        );
    }
    // The goal: position 2·(p relative to sensor 4) + (0, 0, 0.1), and the
    // orientation q_rel · R_x(π) with weight 0.5.
    assert_eq!(goals.len(), 2);
    let g = goals.get(0).unwrap();
    assert_eq!(g.attach, Attach::Point(glam::Vec3::new(0.0, 0.1, 0.0)));
    let Target::Position(t) = g.target else {
        panic!()
    };
    let rel = rotate(
        [other_q[0], -other_q[1], -other_q[2], -other_q[3]],
        [p[0], p[1] - 0.5, p[2]],
    );
    let want_t = [2.0 * rel[0], 2.0 * rel[1], 2.0 * rel[2] + 0.1];
    for k in 0..3 {
        assert!((f64::from(t[k]) - want_t[k]).abs() < 2e-6, "{t} {want_t:?}");
    }
    let o = goals.get(1).unwrap();
    assert_eq!(o.weight, 0.5);
    let Target::Orientation(r) = o.target else {
        panic!()
    };
    let want_r = qmul(relq, [0.0, 1.0, 0.0, 0.0]);
    let dot = f64::from(r.w) * want_r[0]
        + f64::from(r.x) * want_r[1]
        + f64::from(r.y) * want_r[2]
        + f64::from(r.z) * want_r[3];
    assert!(dot.abs() > 1.0 - 1e-6, "{r} {want_r:?}");
    // The rig's own rest frame for "arm" agrees with the f64 one.
    let i = usize::from(rig.body().find("arm").unwrap());
    for (&got, &want) in rig.rest_pose().positions[i]
        .to_array()
        .iter()
        .zip(&arm_origin)
    {
        assert!((f64::from(got) - want).abs() < 1e-6);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn the_sensor_map_is_total(
        bits in proptest::collection::vec((0u8..6, proptest::array::uniform3(any::<u32>()), proptest::array::uniform4(any::<u32>())), 0..8),
    ) {
        let (b, mb) = shared_blobs();
        let (rig, _) = Rig::parse(b).unwrap();
        let (measures, _) = Rig::parse(mb).unwrap();
        let sensors: Vec<Sensor> = bits
            .iter()
            .map(|&(id, p, q)| Sensor { id, position: p.map(f32::from_bits), rotation: q.map(f32::from_bits) })
            .collect();
        for rig in [&rig, &measures] {
            let mut params = [0.0f32; 6];
            let mut goals = GoalSet::<8>::new();
            rig.map_sensors(&sensors, &mut params, &mut goals);
            prop_assert!(params.iter().all(|v| v.is_finite()));
            prop_assert_eq!(goals.len(), rig.goal_count());
            for g in goals.as_slice() {
                let finite = match g.target {
                    Target::Position(t) => t.is_finite(),
                    Target::Plane { normal, offset, .. } => normal.is_finite() && offset.is_finite(),
                    Target::Orientation(q) => q.is_finite(),
                };
                prop_assert!(g.weight == 0.0 || (finite && g.weight.is_finite()));
            }
        }
    }

    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
        let _ = Rig::parse(&bytes);
        let mut with_magic = b"MRIG\x01\x00".to_vec();
        with_magic.extend_from_slice(&bytes);
        let _ = Rig::parse(&with_magic);
    }

    #[test]
    fn mutated_descriptions_are_refused_or_valid(
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
    ) {
        let mut b = shared_blobs().0.clone();
        let len = u32::from_le_bytes(b[6..10].try_into().unwrap()) as usize;
        for (i, v) in edits {
            b[10 + i.index(len)] = v;
        }
        // Recompute the CRC, so the mutation reaches the decoder and validator.
        let crc = crc32(&b[..10 + len]);
        b[10 + len..14 + len].copy_from_slice(&crc.to_le_bytes());
        if let Ok((rig, _)) = Rig::parse(&b) {
            prop_assert_eq!(rig.body().validate(), Ok(()));
            let mut params = [0.0f32; 6];
            let mut goals = GoalSet::<8>::new();
            rig.map_sensors(&[], &mut params, &mut goals);
        }
    }
}

#[test]
fn a_zeroed_crc_is_refused() {
    let mut b = blob("humanoid16.toml");
    let len = u32::from_le_bytes(b[6..10].try_into().unwrap()) as usize;
    b[10 + len..14 + len].fill(0);
    assert_eq!(Rig::parse(&b).err(), Some(RigError::Crc));
    let mut v = blob("humanoid16.toml");
    v[4] = 3;
    assert_eq!(Rig::parse(&v).err(), Some(RigError::Version(3)));
    // A version 1 blob (before the bus servos) is refused by its version.
    v[4] = 1;
    assert_eq!(Rig::parse(&v).err(), Some(RigError::Version(1)));
    assert!(RigDesc::from_blob(&blob("cmu31.toml")).is_ok());
}

// ---------------------------------------------------------------------------
// Bad rig files.

/// The 1-based line of the `nth` occurrence of `marker` in `text`.
fn line_of(text: &str, marker: &str, nth: usize) -> usize {
    let at = text
        .match_indices(marker)
        .nth(nth)
        .unwrap_or_else(|| panic!("marker {marker:?} #{nth} not in the file"))
        .0;
    text[..at].matches('\n').count() + 1
}

/// A mutation of humanoid16: replace the `nth` occurrence of `from` by `to`;
/// the error must be on the line of `at` (its `at_nth` occurrence in the
/// mutated text) and name `field`.
struct Case {
    from: &'static str,
    nth: usize,
    to: &'static str,
    at: &'static str,
    at_nth: usize,
    field: &'static str,
    says: &'static str,
}

const CASES: &[Case] = &[
    // Duplicate channel (core rule, span from the host).
    Case {
        from: "channel = 3\n",
        nth: 0,
        to: "channel = 2\n",
        at: "channel = 2\n",
        at_nth: 1,
        field: "servo[3].channel",
        says: "earlier",
    },
    // Unknown parent name.
    Case {
        from: "parent = \"l_upper_arm\"",
        nth: 0,
        to: "parent = \"l_uper_arm\"",
        at: "l_uper_arm",
        at_nth: 0,
        field: "segment[4].parent",
        says: "l_uper_arm",
    },
    // A parent defined later (not topological).
    Case {
        from: "parent = \"pelvis\"\norigin = [0.0, 0.05",
        nth: 0,
        to: "parent = \"head\"\norigin = [0.0, 0.05",
        at: "parent = \"head\"",
        at_nth: 0,
        field: "segment[1].parent",
        says: "before",
    },
    // Limits min > max.
    Case {
        from: "limits_deg = [0, 130]",
        nth: 1,
        to: "limits_deg = [130, 0]",
        at: "[130, 0]",
        at_nth: 0,
        field: "segment[11].dofs[0].limits",
        says: "min",
    },
    // Limits beyond ±2π.
    Case {
        from: "limits_deg = [-80, 80]",
        nth: 0,
        to: "limits = [-7, 7]",
        at: "[-7, 7]",
        at_nth: 0,
        field: "segment[2].dofs[0].limits",
        says: "range",
    },
    // Repeated axis in a joint.
    Case {
        from: "{ axis = \"z\", limits_deg = [-10, 100] }",
        nth: 0,
        to: "{ axis = \"x\", limits_deg = [-10, 100] }",
        at: "{ axis = \"x\", limits_deg = [-10, 100] }",
        at_nth: 0,
        field: "segment[3].dofs[1].axis",
        says: "earlier",
    },
    // A fourth DOF.
    Case {
        from: "{ axis = \"z\", limits_deg = [-10, 100] },",
        nth: 0,
        to: "{ axis = \"z\", limits_deg = [-10, 100] }, { axis = \"y\", limits = [0, 1] }, { axis = \"y\", limits = [0, 1] },",
        at: "{ axis = \"y\", limits = [0, 1] },",
        at_nth: 1,
        field: "segment[3].dofs",
        says: "at most 3",
    },
    // Non-finite origin (TOML has nan).
    Case {
        from: "origin = [0.0, 0.27, 0.0]",
        nth: 0,
        to: "origin = [0.0, nan, 0.0]",
        at: "nan",
        at_nth: 0,
        field: "segment[2].origin",
        says: "finite",
    },
    // Wrong type.
    Case {
        from: "baud = 115200",
        nth: 0,
        to: "baud = \"fast\"",
        at: "\"fast\"",
        at_nth: 0,
        field: "output.baud",
        says: "invalid type",
    },
    // Out of range for the back-end (core rule).
    Case {
        from: "baud = 115200",
        nth: 0,
        to: "baud = 10",
        at: "baud = 10",
        at_nth: 0,
        field: "output.baud",
        says: "out of range",
    },
    // Missing required field: the line of the entry's header.
    Case {
        from: "max_accel = 60.0\n",
        nth: 0,
        to: "",
        at: "[[servo]]",
        at_nth: 0,
        field: "servo[0].max_accel",
        says: "missing field",
    },
    // Misspelt key.
    Case {
        from: "trim_us = 12",
        nth: 0,
        to: "trimm_us = 12",
        at: "trimm_us",
        at_nth: 0,
        field: "trimm_us",
        says: "unknown field",
    },
    // A servo on an axis its joint lacks.
    Case {
        from: "axis = \"y\"\nangle_deg = [-90, 90]",
        nth: 0,
        to: "axis = \"z\"\nangle_deg = [-90, 90]",
        at: "axis = \"z\"\nangle_deg = [-90, 90]",
        at_nth: 0,
        field: "servo[0].axis",
        says: "no Z",
    },
    // Rest pulse outside the pulse range.
    Case {
        from: "channel = 0\n",
        nth: 0,
        to: "channel = 0\nrest_us = 3000\n",
        at: "rest_us = 3000",
        at_nth: 0,
        field: "servo[0].rest_us",
        says: "range",
    },
    // Channel beyond the Maestro's 24.
    Case {
        from: "channel = 15\n",
        nth: 0,
        to: "channel = 30\n",
        at: "channel = 30",
        at_nth: 0,
        field: "servo[15].channel",
        says: "range",
    },
    // Unknown goal segment.
    Case {
        from: "segment = \"r_forearm\"",
        nth: 0,
        to: "segment = \"r_hand\"",
        at: "r_hand",
        at_nth: 0,
        field: "goal[0].segment",
        says: "r_hand",
    },
    // Negative weight (core rule).
    Case {
        from: "weight = 100",
        nth: 0,
        to: "weight = -1",
        at: "weight = -1",
        at_nth: 0,
        field: "goal[2].weight",
        says: "range",
    },
    // Bad sensor frame.
    Case {
        from: "frame = \"sensor:2\"",
        nth: 0,
        to: "frame = \"sensor:99\"",
        at: "sensor:99",
        at_nth: 0,
        field: "param[0].frame",
        says: "sensor",
    },
    // Duplicate parameter index.
    Case {
        from: "param = 1\n",
        nth: 0,
        to: "param = 0\n",
        at: "param = 0\n",
        at_nth: 1,
        field: "param[1].param",
        says: "earlier",
    },
    // Non-unit root rotation.
    Case {
        from: "root_rotation = [1.0, 0.0, 0.0, 0.0]",
        nth: 0,
        to: "root_rotation = [1.0, 0.0, 0.0, 1.0]",
        at: "root_rotation",
        at_nth: 0,
        field: "root_rotation",
        says: "unit",
    },
    // Duplicate segment name.
    Case {
        from: "name = \"r_foot\"",
        nth: 0,
        to: "name = \"l_foot\"",
        at: "name = \"l_foot\"",
        at_nth: 1,
        field: "segment[12].name",
        says: "twice",
    },
    // TOML syntax.
    Case {
        from: "name = \"humanoid16\"",
        nth: 0,
        to: "name = humanoid16",
        at: "name = humanoid16",
        at_nth: 0,
        field: "name",
        says: "",
    },
    // Two goal kinds at once.
    Case {
        from: "plane = { normal = [0, 1, 0], offset = 0, side = \"contact\" }",
        nth: 0,
        to: "plane = { normal = [0, 1, 0], offset = 0, side = \"contact\" }\ntarget = [0, 0, 0]",
        at: "[[goal]]",
        at_nth: 2,
        field: "goal[2]",
        says: "only one",
    },
    // A zero plane normal (core rule).
    Case {
        from: "normal = [0, 1, 0]",
        nth: 1,
        to: "normal = [0, 0, 0]",
        at: "normal = [0, 0, 0]",
        at_nth: 0,
        field: "goal[3].normal",
        says: "empty",
    },
];

#[test]
fn bad_rig_files_name_file_line_and_field() {
    let text = std::fs::read_to_string(repo().join("rigs/humanoid16.toml")).unwrap();
    assert!(rigfile::parse(&text, "rigs/humanoid16.toml").is_ok());
    let mut failures = Vec::new();
    for c in CASES {
        let at = text
            .match_indices(c.from)
            .nth(c.nth)
            .unwrap_or_else(|| panic!("{:?} #{} not found", c.from, c.nth))
            .0;
        let bad = format!("{}{}{}", &text[..at], c.to, &text[at + c.from.len()..]);
        let line = line_of(&bad, c.at, c.at_nth);
        let msg = match rigfile::parse(&bad, "bad.toml") {
            Ok(_) => {
                failures.push(format!("{:?} -> {:?}: accepted", c.from, c.to));
                continue;
            }
            Err(e) => {
                assert!(matches!(e, RigFileError::At { .. }));
                e.to_string()
            }
        };
        let want = format!("bad.toml:{line}: ");
        if !msg.starts_with(&want)
            || !msg.contains(c.field)
            || !msg.to_lowercase().contains(&c.says.to_lowercase())
        {
            failures.push(format!(
                "{:?} -> {:?}: want {want}…{}…{:?}, got {msg}",
                c.from, c.to, c.field, c.says
            ));
        }
    }
    assert!(failures.is_empty(), "\n{}", failures.join("\n"));
}

#[test]
fn io_errors_name_the_file() {
    let e = rigfile::load(Path::new("/nonexistent/rig.toml")).unwrap_err();
    assert!(
        e.to_string()
            .starts_with("/nonexistent/rig.toml: cannot read"),
        "{e}"
    );
}

// ---------------------------------------------------------------------------
// Serial bus servos and the idle policy in rig files.

/// A two-servo arm on the given `[output]` and servo keys.
fn arm_rig(output: &str, servo0: &str, servo1: &str) -> String {
    format!(
        r#"name = "arm"
frame_period_us = 1000
failsafe_timeout_ms = 100
[output]
{output}
[[segment]]
name = "base"
[[segment]]
name = "upper"
parent = "base"
origin = [0, 0.1, 0]
touch = [0, 0.3, 0]
dofs = [{{ axis = "z", limits_deg = [-90, 90] }}, {{ axis = "x", limits_deg = [-45, 45] }}]
[[servo]]
channel = 0
joint = "upper"
axis = "z"
angle_deg = [-90, 90]
max_speed = 5
max_accel = 50
{servo0}
[[servo]]
channel = 1
joint = "upper"
axis = "x"
angle_deg = [-45, 45]
max_speed = 5
max_accel = 50
{servo1}
"#
    )
}

#[test]
fn bus_servo_positions_come_from_center_units_per_degree_and_limits() {
    use marionette_core::rig::{FeetechSeries, Idle, Output};
    let text = arm_rig(
        "kind = \"dynamixel\"\nbaud = 1000000\nidle = \"off\"",
        "id = 7\ncenter = 2000",
        "id = 3\nreversed = true\nlimits = [1900, 4000]",
    );
    let rig = rigfile::parse(&text, "arm.toml").unwrap();
    let d = rig.desc();
    assert_eq!(d.output, Output::Dynamixel { baud: 1_000_000 });
    assert_eq!(d.idle, Idle::Off);
    let (s0, s1) = (d.servos.as_slice()[0], d.servos.as_slice()[1]);
    // X series default: 4096 units per turn, 11.378 per degree. Servo 0:
    // 2000 ± 90 · 11.378 = 976 ..= 3024 over the whole ±90°.
    let per_deg = 4096.0 / 360.0;
    assert_eq!(s0.id, 7);
    assert!(
        (s0.pulse_min_us - (2000.0 - 90.0 * per_deg)).abs() < 0.01,
        "{s0:?}"
    );
    assert!(
        (s0.pulse_max_us - (2000.0 + 90.0 * per_deg)).abs() < 0.01,
        "{s0:?}"
    );
    assert!((s0.angle_min + std::f32::consts::FRAC_PI_2).abs() < 1e-6);
    assert!((s0.rest_us - 2000.0).abs() < 0.01);
    // Servo 1, reversed about the default centre 2048: −45° is
    // 2048 + 512 = 2560, +45° would be 1536, below the limit 1900: the
    // range stops at (2048 − 1900) / 11.378 = 13.0° instead.
    assert_eq!(s1.id, 3);
    assert!(
        (s1.pulse_min_us - (2048.0 + 45.0 * per_deg)).abs() < 0.01,
        "{s1:?}"
    );
    assert!((s1.pulse_max_us - 1900.0).abs() < 0.01, "{s1:?}");
    let limit_deg = (2048.0 - 1900.0) / per_deg;
    assert!(
        (s1.angle_max.to_degrees() - limit_deg).abs() < 1e-3,
        "{s1:?}"
    );
    // Beyond the range, the calibration holds the limit.
    let cal = s1.calibration();
    assert!((cal.pulse_us(1.0) - 1900.0).abs() < 0.01);

    // Feetech SCS: big-endian, 1024 per 300°, centre 512.
    let text = arm_rig(
        "kind = \"feetech\"\nbaud = 1000000\nseries = \"scs\"",
        "",
        "",
    );
    let scs = rigfile::parse(&text, "arm.toml").unwrap();
    let d = scs.desc();
    assert_eq!(
        d.output,
        Output::Feetech {
            baud: 1_000_000,
            series: FeetechSeries::Scs
        }
    );
    let s0 = d.servos.as_slice()[0];
    assert_eq!((s0.id, d.servos.as_slice()[1].id), (0, 1));
    assert!((s0.pulse_max_us - (512.0 + 90.0 * 1024.0 / 300.0)).abs() < 0.01);
    assert_eq!(d.idle, Idle::Hold);
    // The blob carries all of it.
    let blob = rigfile::to_blob(&scs).unwrap();
    let (back, _) = RigDesc::from_blob(&blob).unwrap();
    assert_eq!(back.output, d.output);
    assert_eq!(back.servos.as_slice()[1].id, 1);
}

#[test]
fn bad_bus_servo_keys_name_the_field() {
    let dyn_out = "kind = \"dynamixel\"\nbaud = 1000000";
    let cases: &[(&str, &str, &str, &str, &str)] = &[
        (dyn_out, "id = 5", "id = 5", "servo[1].id", "repeats"),
        (dyn_out, "id = 253", "", "servo[0].id", "out of range"),
        (
            dyn_out,
            "pulse_us = [500, 2500]",
            "",
            "servo[0].pulse_us",
            "not used by a serial bus",
        ),
        (
            dyn_out,
            "limits = [3500, 4000]",
            "",
            "servo[0].limits",
            "outside the limits",
        ),
        (
            "kind = \"maestro\"\nbaud = 115200",
            "pulse_us = [500, 2500]\nid = 2",
            "pulse_us = [500, 2500]",
            "servo[0].id",
            "only for a serial bus",
        ),
        (
            "kind = \"maestro\"\nbaud = 115200",
            "",
            "pulse_us = [500, 2500]",
            "servo[0].pulse_us",
            "missing",
        ),
        (
            "kind = \"maestro\"\nbaud = 115200\nunits_per_degree = 3",
            "",
            "",
            "output.units_per_degree",
            "not used",
        ),
        (
            "kind = \"feetech\"\nbaud = 1000000\nseries = \"xyz\"",
            "",
            "",
            "output.series",
            "sts",
        ),
        (
            "kind = \"dynamixel\"\nbaud = 1000000\nidle = \"limp\"",
            "",
            "",
            "output.idle",
            "hold",
        ),
        (
            "kind = \"dynamixel\"\nbaud = 5000000",
            "",
            "",
            "output.baud",
            "out of range",
        ),
        (
            "kind = \"dynamixel\"\nbaud = 1000000\nunits_per_degree = -1",
            "",
            "",
            "output.units_per_degree",
            "> 0",
        ),
        (
            "kind = \"pwm\"\nfreq_hz = 400",
            "pulse_us = [500, 2500]",
            "pulse_us = [500, 2500]",
            "output.freq_hz",
            "out of range",
        ),
        (
            "kind = \"pca9685\"\nfreq_hz = 400\ni2c_addr = 64",
            "pulse_us = [500, 2500]",
            "pulse_us = [500, 2500]",
            "servo[0].pulse_us",
            "out of range",
        ),
    ];
    for (output, s0, s1, field, says) in cases {
        let text = arm_rig(output, s0, s1);
        match rigfile::parse(&text, "arm.toml") {
            Ok(_) => panic!("accepted: {output} / {s0} / {s1}"),
            Err(e) => {
                let msg = e.to_string();
                assert!(
                    msg.contains(field) && msg.contains(says),
                    "{output} / {s0} / {s1}: {msg}"
                );
            }
        }
    }
}
