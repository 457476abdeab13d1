//! The CMU 31-joint skeleton (cgspeed BVH conversion), as in
//! `data/cmu_02_01_walk/02_01.bvh`.
//!
//! Offsets are the BVH `OFFSET`s, written here in CMU units exactly as in the
//! file and multiplied by [`UNIT_METRES`] (= 2.54/45 ≈ 0.056444 m, the CMU unit)
//! at compile time. `tests/solve.rs` parses the BVH `HIERARCHY` section itself and
//! checks this copy against it.
//!
//! Every joint keeps the BVH channel order `Zrotation Yrotation Xrotation`
//! (`q = R_z·R_y·R_x`), so a BVH frame projects onto these DOFs exactly. The
//! skeleton's rest frames are world-aligned while its bones are oblique (the
//! thighs splay 20°, the arms are in a T-pose), so anatomical hinges such as the
//! knee and the elbow show up on all three channels in real data; they keep
//! three DOFs here. Limits (degrees, left side; the right side mirrors Z and Y)
//! are human ranges widened to contain every frame of CMU 02_01 (walk) and
//! 16_45 (run):
//!
//! | joint | Z | Y | X |
//! |---|---|---|---|
//! | `LHipJoint` (pelvis offset) | ±20 | ±20 | ±20 |
//! | `LeftUpLeg` (hip) | −60..45 | ±45 | −125..35 (flexion negative) |
//! | `LeftLeg` (knee) | ±30 | ±30 | −5..150 (flexion positive) |
//! | `LeftFoot` (ankle) | ±30 | ±35 | −40..55 |
//! | `LeftToeBase` | ±15 | ±20 | −60..40 |
//! | `LowerBack` | ±30 | ±30 | −30..60 (forward positive) |
//! | `Spine`, `Spine1` | ±20 | ±20 | −20..30 |
//! | `Neck` | ±30 | ±30 | ±45 |
//! | `Neck1` | ±30 | ±35 | ±40 |
//! | `Head` | ±30 | ±45 | ±40 |
//! | `LeftShoulder` (clavicle) | −20..25 | ±25 | ±15 |
//! | `LeftArm` (shoulder) | −100..95 (down negative) | ±85 | ±90 (twist) |
//! | `LeftForeArm` (elbow) | −10..160 | −85..10 | −120..30 (twist) |
//! | `LeftHand` (wrist) | ±30 | ±30 | ±70 |
//! | `LeftFingerBase` | ±40 | ±40 | ±20 |
//! | `LeftHandIndex1` | ±45 (Z only) | — | — |
//! | `LThumb` | ±20 | −10..60 | −10..20 |
//!
//! Touch points are the distal joint (the first child's origin; the origin for
//! leaves, whose BVH end sites are zero), except the hands, whose touch point is
//! the palm centre (half-way to `*HandIndex1`), as in the paper.

use super::{Axis, Body, Dof, Joint, Segment, offsets_of, parents_of};
use crate::pose::NO_PARENT;
use glam::Vec3;

/// One CMU length unit in metres: 1/0.45 inch = 2.54/45 m/100, i.e. 0.056444 m.
pub const UNIT_METRES: f32 = 2.54 / 45.0;
/// Number of segments.
pub const SEGMENT_COUNT: usize = 31;

/// Segment indices (BVH order), for goals and tests.
pub mod index {
    /// `Hips`, the root.
    pub const HIPS: u8 = 0;
    /// `LeftUpLeg`; touch point at the knee.
    pub const LEFT_UP_LEG: u8 = 2;
    /// `LeftLeg`; touch point at the ankle.
    pub const LEFT_LEG: u8 = 3;
    /// `LeftFoot`; touch point at the toe base.
    pub const LEFT_FOOT: u8 = 4;
    /// `LeftToeBase`.
    pub const LEFT_TOE: u8 = 5;
    /// `RightUpLeg`.
    pub const RIGHT_UP_LEG: u8 = 7;
    /// `RightLeg`.
    pub const RIGHT_LEG: u8 = 8;
    /// `RightFoot`.
    pub const RIGHT_FOOT: u8 = 9;
    /// `RightToeBase`.
    pub const RIGHT_TOE: u8 = 10;
    /// `Spine1`, the upper-torso branch of head and arms.
    pub const SPINE1: u8 = 13;
    /// `Head`.
    pub const HEAD: u8 = 16;
    /// `LeftShoulder` (clavicle); touch point at the shoulder joint.
    pub const LEFT_SHOULDER: u8 = 17;
    /// `LeftArm`; touch point at the elbow.
    pub const LEFT_ARM: u8 = 18;
    /// `LeftForeArm`; touch point at the wrist.
    pub const LEFT_FORE_ARM: u8 = 19;
    /// `LeftHand`; touch point at the palm centre.
    pub const LEFT_HAND: u8 = 20;
    /// `RightShoulder`.
    pub const RIGHT_SHOULDER: u8 = 24;
    /// `RightArm`.
    pub const RIGHT_ARM: u8 = 25;
    /// `RightForeArm`.
    pub const RIGHT_FORE_ARM: u8 = 26;
    /// `RightHand`.
    pub const RIGHT_HAND: u8 = 27;
}

/// A BVH offset in CMU units, converted to metres.
const fn cmu(x: f32, y: f32, z: f32) -> Vec3 {
    Vec3::new(x * UNIT_METRES, y * UNIT_METRES, z * UNIT_METRES)
}

/// Three DOFs in BVH order Z, Y, X with limits in degrees; `right` mirrors Z and Y.
const fn zyx(z: (f32, f32), y: (f32, f32), x: (f32, f32), right: bool) -> Joint {
    let (z, y) = if right {
        ((-z.1, -z.0), (-y.1, -y.0))
    } else {
        (z, y)
    };
    Joint::three(
        Dof::degrees(Axis::Z, z.0, z.1),
        Dof::degrees(Axis::Y, y.0, y.1),
        Dof::degrees(Axis::X, x.0, x.1),
    )
}

const fn seg(
    name: &'static str,
    parent: u8,
    origin: Vec3,
    joint: Joint,
    touch: Vec3,
) -> Segment<'static> {
    Segment {
        name,
        parent,
        origin,
        joint,
        touch,
    }
}

const HIP_JOINT: ((f32, f32), (f32, f32), (f32, f32)) =
    ((-20.0, 20.0), (-20.0, 20.0), (-20.0, 20.0));
const UP_LEG: ((f32, f32), (f32, f32), (f32, f32)) = ((-60.0, 45.0), (-45.0, 45.0), (-125.0, 35.0));
const LEG: ((f32, f32), (f32, f32), (f32, f32)) = ((-30.0, 30.0), (-30.0, 30.0), (-5.0, 150.0));
const FOOT: ((f32, f32), (f32, f32), (f32, f32)) = ((-30.0, 30.0), (-35.0, 35.0), (-40.0, 55.0));
const TOE: ((f32, f32), (f32, f32), (f32, f32)) = ((-15.0, 15.0), (-20.0, 20.0), (-60.0, 40.0));
const SHOULDER: ((f32, f32), (f32, f32), (f32, f32)) =
    ((-20.0, 25.0), (-25.0, 25.0), (-15.0, 15.0));
const ARM: ((f32, f32), (f32, f32), (f32, f32)) = ((-100.0, 95.0), (-85.0, 85.0), (-90.0, 90.0));
const FORE_ARM: ((f32, f32), (f32, f32), (f32, f32)) =
    ((-10.0, 160.0), (-85.0, 10.0), (-120.0, 30.0));
const HAND: ((f32, f32), (f32, f32), (f32, f32)) = ((-30.0, 30.0), (-30.0, 30.0), (-70.0, 70.0));
const FINGER_BASE: ((f32, f32), (f32, f32), (f32, f32)) =
    ((-40.0, 40.0), (-40.0, 40.0), (-20.0, 20.0));
const THUMB: ((f32, f32), (f32, f32), (f32, f32)) = ((-20.0, 20.0), (-10.0, 60.0), (-10.0, 20.0));

const fn side(j: ((f32, f32), (f32, f32), (f32, f32)), right: bool) -> Joint {
    zyx(j.0, j.1, j.2, right)
}

const fn centre(j: ((f32, f32), (f32, f32), (f32, f32))) -> Joint {
    zyx(j.0, j.1, j.2, false)
}

const INDEX: Joint = Joint::one(Dof::degrees(Axis::Z, -45.0, 45.0));
const L: bool = false;
const R: bool = true;

/// The segment table, in BVH order (offsets as printed in the file, hence the
/// digits beyond `f32` precision).
#[allow(clippy::excessive_precision)]
pub const SEGMENTS: [Segment<'static>; SEGMENT_COUNT] = [
    seg(
        "Hips",
        NO_PARENT,
        cmu(0.0, 0.0, 0.0),
        Joint::FIXED,
        cmu(0.0, 0.0, 0.0),
    ),
    seg(
        "LHipJoint",
        0,
        cmu(0.0, 0.0, 0.0),
        side(HIP_JOINT, L),
        cmu(1.363060, -1.794630, 0.839290),
    ),
    seg(
        "LeftUpLeg",
        1,
        cmu(1.363060, -1.794630, 0.839290),
        side(UP_LEG, L),
        cmu(2.448110, -6.726130, 0.0),
    ),
    seg(
        "LeftLeg",
        2,
        cmu(2.448110, -6.726130, 0.0),
        side(LEG, L),
        cmu(2.562200, -7.039590, 0.0),
    ),
    seg(
        "LeftFoot",
        3,
        cmu(2.562200, -7.039590, 0.0),
        side(FOOT, L),
        cmu(0.157640, -0.433110, 2.322550),
    ),
    seg(
        "LeftToeBase",
        4,
        cmu(0.157640, -0.433110, 2.322550),
        side(TOE, L),
        cmu(0.0, 0.0, 0.0),
    ),
    seg(
        "RHipJoint",
        0,
        cmu(0.0, 0.0, 0.0),
        side(HIP_JOINT, R),
        cmu(-1.305520, -1.794630, 0.839290),
    ),
    seg(
        "RightUpLeg",
        6,
        cmu(-1.305520, -1.794630, 0.839290),
        side(UP_LEG, R),
        cmu(-2.542530, -6.985550, 0.0),
    ),
    seg(
        "RightLeg",
        7,
        cmu(-2.542530, -6.985550, 0.0),
        side(LEG, R),
        cmu(-2.568260, -7.056230, 0.0),
    ),
    seg(
        "RightFoot",
        8,
        cmu(-2.568260, -7.056230, 0.0),
        side(FOOT, R),
        cmu(-0.164730, -0.452590, 2.363150),
    ),
    seg(
        "RightToeBase",
        9,
        cmu(-0.164730, -0.452590, 2.363150),
        side(TOE, R),
        cmu(0.0, 0.0, 0.0),
    ),
    seg(
        "LowerBack",
        0,
        cmu(0.0, 0.0, 0.0),
        centre(((-30.0, 30.0), (-30.0, 30.0), (-30.0, 60.0))),
        cmu(0.028270, 2.035590, -0.193380),
    ),
    seg(
        "Spine",
        11,
        cmu(0.028270, 2.035590, -0.193380),
        centre(((-20.0, 20.0), (-20.0, 20.0), (-20.0, 30.0))),
        cmu(0.056720, 2.048850, -0.042750),
    ),
    seg(
        "Spine1",
        12,
        cmu(0.056720, 2.048850, -0.042750),
        centre(((-20.0, 20.0), (-20.0, 20.0), (-20.0, 30.0))),
        cmu(0.0, 0.0, 0.0),
    ),
    seg(
        "Neck",
        13,
        cmu(0.0, 0.0, 0.0),
        centre(((-30.0, 30.0), (-30.0, 30.0), (-45.0, 45.0))),
        cmu(-0.054170, 1.746240, 0.172020),
    ),
    seg(
        "Neck1",
        14,
        cmu(-0.054170, 1.746240, 0.172020),
        centre(((-30.0, 30.0), (-35.0, 35.0), (-40.0, 40.0))),
        cmu(0.104070, 1.761360, -0.123970),
    ),
    seg(
        "Head",
        15,
        cmu(0.104070, 1.761360, -0.123970),
        centre(((-30.0, 30.0), (-45.0, 45.0), (-40.0, 40.0))),
        cmu(0.0, 0.0, 0.0),
    ),
    seg(
        "LeftShoulder",
        13,
        cmu(0.0, 0.0, 0.0),
        side(SHOULDER, L),
        cmu(3.362410, 1.200890, -0.311210),
    ),
    seg(
        "LeftArm",
        17,
        cmu(3.362410, 1.200890, -0.311210),
        side(ARM, L),
        cmu(4.983000, 0.0, 0.0),
    ),
    seg(
        "LeftForeArm",
        18,
        cmu(4.983000, 0.0, 0.0),
        side(FORE_ARM, L),
        cmu(3.483560, 0.0, 0.0),
    ),
    seg(
        "LeftHand",
        19,
        cmu(3.483560, 0.0, 0.0),
        side(HAND, L),
        cmu(0.357630, 0.0, 0.0),
    ),
    seg(
        "LeftFingerBase",
        20,
        cmu(0.0, 0.0, 0.0),
        side(FINGER_BASE, L),
        cmu(0.715260, 0.0, 0.0),
    ),
    seg(
        "LeftHandIndex1",
        21,
        cmu(0.715260, 0.0, 0.0),
        INDEX,
        cmu(0.0, 0.0, 0.0),
    ),
    seg(
        "LThumb",
        20,
        cmu(0.0, 0.0, 0.0),
        side(THUMB, L),
        cmu(0.0, 0.0, 0.0),
    ),
    seg(
        "RightShoulder",
        13,
        cmu(0.0, 0.0, 0.0),
        side(SHOULDER, R),
        cmu(-3.136600, 1.374050, -0.404650),
    ),
    seg(
        "RightArm",
        24,
        cmu(-3.136600, 1.374050, -0.404650),
        side(ARM, R),
        cmu(-5.241900, 0.0, 0.0),
    ),
    seg(
        "RightForeArm",
        25,
        cmu(-5.241900, 0.0, 0.0),
        side(FORE_ARM, R),
        cmu(-3.444170, 0.0, 0.0),
    ),
    seg(
        "RightHand",
        26,
        cmu(-3.444170, 0.0, 0.0),
        side(HAND, R),
        cmu(-0.311265, 0.0, 0.0),
    ),
    seg(
        "RightFingerBase",
        27,
        cmu(0.0, 0.0, 0.0),
        side(FINGER_BASE, R),
        cmu(-0.622530, 0.0, 0.0),
    ),
    seg(
        "RightHandIndex1",
        28,
        cmu(-0.622530, 0.0, 0.0),
        INDEX,
        cmu(0.0, 0.0, 0.0),
    ),
    seg(
        "RThumb",
        27,
        cmu(0.0, 0.0, 0.0),
        side(THUMB, R),
        cmu(0.0, 0.0, 0.0),
    ),
];

const PARENTS: [u8; SEGMENT_COUNT] = parents_of(&SEGMENTS);
const OFFSETS: [Vec3; SEGMENT_COUNT] = offsets_of(&SEGMENTS);

/// The CMU skeleton.
pub const BODY: Body<'static> = Body {
    segments: &SEGMENTS,
    parents: &PARENTS,
    offsets: &OFFSETS,
};
