//! A humanoid modelled on the TEMPUS figure of Badler et al. (1987), Figure 13.
//!
//! The paper's TEMPUS body has the lower torso as its root and 18 body nodes
//! (it quotes "18 joints and 48 degrees of freedom"); the figure's exact DOF
//! split is not legible in the text, so the joints here are our own anatomical
//! choice: 18 segments, 41 rotational DOFs plus the free root (6), i.e. 47.
//!
//! Dimensions are those of an adult of about 1.77 m (head top), in metres; at the
//! rest pose (all angles zero) the figure stands upright, facing +Z, arms hanging
//! along −Y, its left side on +X, with the lower-torso origin [`ROOT_HEIGHT`]
//! above the floor and the soles on `y = 0`.
//!
//! | # | segment | parent | joint origin (parent frame) | DOFs (order), limits in degrees | touch point |
//! |---|---|---|---|---|---|
//! | 0 | `lower_torso` | — | root | free | origin (pelvis centre) |
//! | 1 | `upper_torso` | 0 | (0, 0.10, 0) waist | X flex −30..70, Z lateral ±35, Y twist ±40 | (0, 0.42, 0) base of neck |
//! | 2 | `neck` | 1 | (0, 0.42, 0) | X −45..60, Z ±40, Y ±60 | (0, 0.10, 0) |
//! | 3 | `head` | 2 | (0, 0.10, 0) | X ±30, Z ±20, Y ±30 | (0, 0.10, 0) head centre |
//! | 4 | `left_shoulder` (clavicle) | 1 | (0.02, 0.38, 0) | Z elevation −10..30, Y ±25 | (0.16, 0, 0) shoulder joint |
//! | 5 | `left_upper_arm` | 4 | (0.16, 0, 0) | X flex −170..60, Z abduction −30..90, Y twist ±90 | (0, −0.30, 0) elbow |
//! | 6 | `left_lower_arm` | 5 | (0, −0.30, 0) | X flex −150..0, Y pronation ±80 | (0, −0.26, 0) wrist |
//! | 7 | `left_hand` | 6 | (0, −0.26, 0) | Z flex −80..70, X deviation −30..20 | (0, −0.08, 0) palm centre |
//! | 8–11 | `right_*` | | mirrored in X | Z and Y ranges mirrored | mirrored |
//! | 12 | `left_upper_leg` | 0 | (0.09, −0.05, 0) hip | X flex −120..30, Z abduction −30..45, Y twist ±45 | (0, −0.42, 0) knee |
//! | 13 | `left_lower_leg` | 12 | (0, −0.42, 0) | X flex 0..150 | (0, −0.40, 0) ankle |
//! | 14 | `left_foot` | 13 | (0, −0.40, 0) | X plantar −30..50, Z inversion −25..35, Y ±25 | (0, −0.08, 0.14) ball of foot on the sole |
//! | 15–17 | `right_*` | | mirrored | mirrored | mirrored |
//!
//! Signs (right-hand rule, rest frames): +X rotation swings a hanging limb
//! backwards, so shoulder and hip flexion are negative X and knee flexion is
//! positive X; +Z rotation swings a left limb outwards (abduction), a right one
//! inwards. Middle Euler axes stay within ±90° so no limit reaches gimbal lock.

use super::{Axis, Body, Dof, Joint, Segment, offsets_of, parents_of};
use crate::pose::NO_PARENT;
use glam::Vec3;

/// Number of segments.
pub const SEGMENT_COUNT: usize = 18;
/// Height of the lower-torso origin above the floor when standing at rest, m.
pub const ROOT_HEIGHT: f32 = 0.95;

/// Segment indices, for goals and tests.
pub mod index {
    /// Pelvis, the root.
    pub const LOWER_TORSO: u8 = 0;
    /// Trunk above the waist.
    pub const UPPER_TORSO: u8 = 1;
    /// Neck.
    pub const NECK: u8 = 2;
    /// Head.
    pub const HEAD: u8 = 3;
    /// Left clavicle; its touch point is the left shoulder joint.
    pub const LEFT_SHOULDER: u8 = 4;
    /// Left upper arm; touch point at the elbow.
    pub const LEFT_UPPER_ARM: u8 = 5;
    /// Left forearm; touch point at the wrist.
    pub const LEFT_LOWER_ARM: u8 = 6;
    /// Left hand; touch point at the palm centre.
    pub const LEFT_HAND: u8 = 7;
    /// Right clavicle.
    pub const RIGHT_SHOULDER: u8 = 8;
    /// Right upper arm.
    pub const RIGHT_UPPER_ARM: u8 = 9;
    /// Right forearm.
    pub const RIGHT_LOWER_ARM: u8 = 10;
    /// Right hand.
    pub const RIGHT_HAND: u8 = 11;
    /// Left thigh; touch point at the knee.
    pub const LEFT_UPPER_LEG: u8 = 12;
    /// Left shank; touch point at the ankle.
    pub const LEFT_LOWER_LEG: u8 = 13;
    /// Left foot; touch point at the ball of the foot.
    pub const LEFT_FOOT: u8 = 14;
    /// Right thigh.
    pub const RIGHT_UPPER_LEG: u8 = 15;
    /// Right shank.
    pub const RIGHT_LOWER_LEG: u8 = 16;
    /// Right foot.
    pub const RIGHT_FOOT: u8 = 17;
}

const fn v(x: f32, y: f32, z: f32) -> Vec3 {
    Vec3::new(x, y, z)
}

const fn d(axis: Axis, min: f32, max: f32) -> Dof {
    Dof::degrees(axis, min, max)
}

/// The mirror image (left <-> right) of a DOF: X ranges stay, Y and Z ranges flip.
const fn m(dof: Dof) -> Dof {
    match dof.axis {
        Axis::X => dof,
        _ => Dof::new(dof.axis, -dof.max, -dof.min),
    }
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

const SPINE: Joint = Joint::three(
    d(Axis::X, -30.0, 70.0),
    d(Axis::Z, -35.0, 35.0),
    d(Axis::Y, -40.0, 40.0),
);
const NECK: Joint = Joint::three(
    d(Axis::X, -45.0, 60.0),
    d(Axis::Z, -40.0, 40.0),
    d(Axis::Y, -60.0, 60.0),
);
const HEAD: Joint = Joint::three(
    d(Axis::X, -30.0, 30.0),
    d(Axis::Z, -20.0, 20.0),
    d(Axis::Y, -30.0, 30.0),
);

const CLAVICLE_L: [Dof; 2] = [d(Axis::Z, -10.0, 30.0), d(Axis::Y, -25.0, 25.0)];
const UPPER_ARM_L: [Dof; 3] = [
    d(Axis::X, -170.0, 60.0),
    d(Axis::Z, -30.0, 90.0),
    d(Axis::Y, -90.0, 90.0),
];
const LOWER_ARM_L: [Dof; 2] = [d(Axis::X, -150.0, 0.0), d(Axis::Y, -80.0, 80.0)];
const HAND_L: [Dof; 2] = [d(Axis::Z, -80.0, 70.0), d(Axis::X, -30.0, 20.0)];
const UPPER_LEG_L: [Dof; 3] = [
    d(Axis::X, -120.0, 30.0),
    d(Axis::Z, -30.0, 45.0),
    d(Axis::Y, -45.0, 45.0),
];
const LOWER_LEG: Dof = d(Axis::X, 0.0, 150.0);
const FOOT_L: [Dof; 3] = [
    d(Axis::X, -30.0, 50.0),
    d(Axis::Z, -25.0, 35.0),
    d(Axis::Y, -25.0, 25.0),
];

const fn two(a: [Dof; 2], mirror: bool) -> Joint {
    if mirror {
        Joint::two(m(a[0]), m(a[1]))
    } else {
        Joint::two(a[0], a[1])
    }
}

const fn three(a: [Dof; 3], mirror: bool) -> Joint {
    if mirror {
        Joint::three(m(a[0]), m(a[1]), m(a[2]))
    } else {
        Joint::three(a[0], a[1], a[2])
    }
}

/// The segment table.
pub const SEGMENTS: [Segment<'static>; SEGMENT_COUNT] = [
    seg(
        "lower_torso",
        NO_PARENT,
        v(0.0, 0.0, 0.0),
        Joint::FIXED,
        v(0.0, 0.0, 0.0),
    ),
    seg(
        "upper_torso",
        0,
        v(0.0, 0.10, 0.0),
        SPINE,
        v(0.0, 0.42, 0.0),
    ),
    seg("neck", 1, v(0.0, 0.42, 0.0), NECK, v(0.0, 0.10, 0.0)),
    seg("head", 2, v(0.0, 0.10, 0.0), HEAD, v(0.0, 0.10, 0.0)),
    seg(
        "left_shoulder",
        1,
        v(0.02, 0.38, 0.0),
        two(CLAVICLE_L, false),
        v(0.16, 0.0, 0.0),
    ),
    seg(
        "left_upper_arm",
        4,
        v(0.16, 0.0, 0.0),
        three(UPPER_ARM_L, false),
        v(0.0, -0.30, 0.0),
    ),
    seg(
        "left_lower_arm",
        5,
        v(0.0, -0.30, 0.0),
        two(LOWER_ARM_L, false),
        v(0.0, -0.26, 0.0),
    ),
    seg(
        "left_hand",
        6,
        v(0.0, -0.26, 0.0),
        two(HAND_L, false),
        v(0.0, -0.08, 0.0),
    ),
    seg(
        "right_shoulder",
        1,
        v(-0.02, 0.38, 0.0),
        two(CLAVICLE_L, true),
        v(-0.16, 0.0, 0.0),
    ),
    seg(
        "right_upper_arm",
        8,
        v(-0.16, 0.0, 0.0),
        three(UPPER_ARM_L, true),
        v(0.0, -0.30, 0.0),
    ),
    seg(
        "right_lower_arm",
        9,
        v(0.0, -0.30, 0.0),
        two(LOWER_ARM_L, true),
        v(0.0, -0.26, 0.0),
    ),
    seg(
        "right_hand",
        10,
        v(0.0, -0.26, 0.0),
        two(HAND_L, true),
        v(0.0, -0.08, 0.0),
    ),
    seg(
        "left_upper_leg",
        0,
        v(0.09, -0.05, 0.0),
        three(UPPER_LEG_L, false),
        v(0.0, -0.42, 0.0),
    ),
    seg(
        "left_lower_leg",
        12,
        v(0.0, -0.42, 0.0),
        Joint::one(LOWER_LEG),
        v(0.0, -0.40, 0.0),
    ),
    seg(
        "left_foot",
        13,
        v(0.0, -0.40, 0.0),
        three(FOOT_L, false),
        v(0.0, -0.08, 0.14),
    ),
    seg(
        "right_upper_leg",
        0,
        v(-0.09, -0.05, 0.0),
        three(UPPER_LEG_L, true),
        v(0.0, -0.42, 0.0),
    ),
    seg(
        "right_lower_leg",
        15,
        v(0.0, -0.42, 0.0),
        Joint::one(LOWER_LEG),
        v(0.0, -0.40, 0.0),
    ),
    seg(
        "right_foot",
        16,
        v(0.0, -0.40, 0.0),
        three(FOOT_L, true),
        v(0.0, -0.08, 0.14),
    ),
];

const PARENTS: [u8; SEGMENT_COUNT] = parents_of(&SEGMENTS);
const OFFSETS: [Vec3; SEGMENT_COUNT] = offsets_of(&SEGMENTS);

/// The TEMPUS-like humanoid.
pub const BODY: Body<'static> = Body {
    segments: &SEGMENTS,
    parents: &PARENTS,
    offsets: &OFFSETS,
};
