//! [`RigDesc`]: the serialized description of a rig (the postcard schema of
//! the rig blob), and its validation.
//!
//! Every list has a fixed capacity ([`List`]); every cross-reference is an
//! index (segments by position, sensors by id). The host's rig-file reader
//! builds a `RigDesc` from TOML and writes it with [`RigDesc::to_blob`]; the
//! firmware reads it back with [`super::Rig::parse`]. [`RigDesc::validate`] is
//! the one set of rules both sides apply.

use serde::{Deserialize, Serialize};

use super::{Invalid, Place, Problem, RigError};
use crate::body::{self, Dof, Joint};
use crate::math;
use crate::pose::NO_PARENT;
use crate::servo::{Calibration, StepLimits};
use crate::wire::{self, List};
use core::f32::consts::TAU;

/// Most segments of a rig (the pose capacity).
pub const MAX_SEGMENTS: usize = crate::pose::MAX_SEGMENTS;
/// Most servo channels of a rig (as many as a telemetry message reports).
pub const MAX_SERVOS: usize = wire::MAX_SERVOS;
/// Most sensor → parameter entries, and the number of parameters they can
/// address (a table has at most this many axes).
pub const MAX_PARAMS: usize = crate::table::MAX_AXES;
/// Most goals a rig produces per frame (as many as telemetry reports); a goal
/// entry with an orientation weight counts twice.
pub const MAX_GOALS: usize = wire::MAX_GOALS;
/// Sensor ids are below this (the tracker frame's capacity).
pub const MAX_SENSORS: usize = wire::MAX_SENSORS;
/// Longest segment name, bytes of UTF-8 (the table blob's name width).
pub const NAME_LEN: usize = crate::table::NAME_LEN;
/// Longest rig name, bytes of UTF-8.
pub const RIG_NAME_LEN: usize = 32;

/// Frame period bounds, µs (10 kHz .. 10 Hz).
const FRAME_PERIOD_US: (u32, u32) = (100, 100_000);
/// Fail-safe timeout bounds, ms.
const FAILSAFE_MS: (u32, u32) = (1, 60_000);
/// Highest pulse width a channel may be calibrated to, µs (the Maestro's
/// 14-bit quarter-µs target ends at 4095.75 µs).
const PULSE_MAX_US: f32 = 4000.0;
/// Highest position of a serial bus servo, in its own units (12 bits: the
/// Dynamixel X and Feetech STS series turn once in 4096 units).
const POSITION_MAX: f32 = 4095.0;
/// Largest trim, µs.
const TRIM_MAX_US: f32 = 1000.0;
/// A quaternion or axis counts as unit length when `|‖q‖² − 1| ≤` this.
const UNIT_TOLERANCE: f32 = 1e-3;

/// A principal axis of a frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum AxisName {
    /// +X (postcard variant 0).
    #[default]
    X,
    /// +Y (variant 1).
    Y,
    /// +Z (variant 2).
    Z,
}

impl AxisName {
    /// The body module's axis.
    #[inline]
    #[must_use]
    pub const fn to_body(self) -> body::Axis {
        match self {
            AxisName::X => body::Axis::X,
            AxisName::Y => body::Axis::Y,
            AxisName::Z => body::Axis::Z,
        }
    }

    /// The axis from the body module's.
    #[inline]
    #[must_use]
    pub const fn from_body(axis: body::Axis) -> Self {
        match axis {
            body::Axis::X => AxisName::X,
            body::Axis::Y => AxisName::Y,
            body::Axis::Z => AxisName::Z,
        }
    }
}

/// One rotational degree of freedom of a joint.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DofDesc {
    /// The rotation axis, in the segment's rest frame.
    pub axis: AxisName,
    /// Lower limit, radians (≥ −2π).
    pub min: f32,
    /// Upper limit, radians (≥ `min`, ≤ 2π).
    pub max: f32,
}

/// One segment of the skeleton.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SegmentDesc<'a> {
    /// Name, 1 ..= [`NAME_LEN`] bytes, unique in the rig.
    pub name: &'a str,
    /// Parent index: [`NO_PARENT`] for segment 0 (the root), else lower than
    /// the segment's own index.
    pub parent: u8,
    /// Joint origin in the parent's frame, metres (the root's is ignored by
    /// forward kinematics; keep it zero).
    pub origin: [f32; 3],
    /// Touch point in the segment's own frame, metres.
    pub touch: [f32; 3],
    /// The joint's degrees of freedom, applied in order
    /// (`q = R_a(θ₀)·R_b(θ₁)·R_c(θ₂)`); empty for the root, which is free.
    pub dofs: List<DofDesc, 3>,
}

impl SegmentDesc<'_> {
    /// The body module's joint for these degrees of freedom.
    #[must_use]
    pub fn joint(&self) -> Joint {
        let d = |x: &DofDesc| Dof::new(x.axis.to_body(), x.min, x.max);
        match self.dofs.as_slice() {
            [a] => Joint::one(d(a)),
            [a, b] => Joint::two(d(a), d(b)),
            [a, b, c] => Joint::three(d(a), d(b), d(c)),
            _ => Joint::FIXED,
        }
    }
}

/// One servo channel: which joint DOF it drives and how.
///
/// The "pulse" fields are in the back-end's target unit: µs for the pulse
/// back-ends (PWM, PCA9685, Maestro), position units for the serial bus
/// servos (Dynamixel, Feetech), whose rig-file keys (`center`, `limits`,
/// `units_per_degree`) the host turns into these.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ServoDesc {
    /// Output channel number (unique; below the back-end's channel count).
    pub channel: u8,
    /// The segment whose joint the servo turns (not the root).
    pub segment: u8,
    /// Index of the DOF within that joint.
    pub dof: u8,
    /// Joint angle at `pulse_min_us`, radians.
    pub angle_min: f32,
    /// Joint angle at `pulse_max_us`, radians (> `angle_min`).
    pub angle_max: f32,
    /// Pulse at `angle_min`, µs (before reversal and trim).
    pub pulse_min_us: f32,
    /// Pulse at `angle_max`, µs.
    pub pulse_max_us: f32,
    /// Added to every pulse, µs.
    pub trim_us: f32,
    /// Swaps the ends of the pulse range.
    pub reversed: bool,
    /// Pulse sent at power-up and on fail-safe, µs (within the pulse range).
    pub rest_us: f32,
    /// Fastest joint speed, rad/s (> 0).
    pub max_speed: f32,
    /// Largest joint acceleration, rad/s² (> 0).
    pub max_accel: f32,
    /// The servo's id on a serial bus ([`Output::Dynamixel`]: 0 ..= 252,
    /// [`Output::Feetech`]: 0 ..= 253; unique); ignored by the other
    /// back-ends.
    pub id: u8,
}

impl ServoDesc {
    /// The servo module's calibration.
    #[must_use]
    pub const fn calibration(&self) -> Calibration {
        Calibration {
            angle_min: self.angle_min,
            angle_max: self.angle_max,
            pulse_min_us: self.pulse_min_us,
            pulse_max_us: self.pulse_max_us,
            trim_us: self.trim_us,
            reversed: self.reversed,
        }
    }

    /// Per-frame slew limits for a frame period of `period_s` seconds.
    #[must_use]
    pub fn step_limits(&self, period_s: f32) -> StepLimits {
        StepLimits::from_joint(
            &self.calibration(),
            self.max_speed,
            self.max_accel,
            period_s,
        )
    }
}

/// The servo output back-end.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Output {
    /// On-chip timer PWM, one pin per channel (variant 0).
    Pwm {
        /// Pulse repetition rate, Hz (50 ..= 333).
        freq_hz: u16,
    },
    /// NXP PCA9685 16-channel PWM over I²C (variant 1).
    Pca9685 {
        /// 7-bit I²C address (0x08 ..= 0x7F but not 0x70, the ALLCALL
        /// address; 0x40 with no address pins strapped).
        i2c_addr: u8,
        /// Pulse repetition rate, Hz (50 ..= 400).
        freq_hz: u16,
    },
    /// Pololu Maestro over UART, compact protocol (variant 2).
    Maestro {
        /// UART baud rate (300 ..= 250 000).
        baud: u32,
    },
    /// ROBOTIS Dynamixel, Protocol 2.0, on a half-duplex UART: Sync Write of
    /// Goal Position (variant 3). Targets are positions (0 ..= 4095).
    Dynamixel {
        /// UART baud rate (9600 ..= 4 500 000).
        baud: u32,
    },
    /// Feetech SCS/STS serial bus servos on a half-duplex UART: Sync Write
    /// of Goal Position (variant 4). Targets are positions.
    Feetech {
        /// UART baud rate (38 400 ..= 1 000 000).
        baud: u32,
        /// The byte order of the servo's 2-byte registers.
        series: FeetechSeries,
    },
}

/// A Feetech servo family: the byte order of its 2-byte registers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum FeetechSeries {
    /// STS/SMS (magnetic encoder, 4096 per turn): little-endian (variant 0).
    #[default]
    Sts,
    /// SCS (potentiometer, 1024 per 300°): big-endian (variant 1).
    Scs,
}

/// What the servo outputs do once the servos have eased to their rest
/// targets after a `Disarm` or a fail-safe time-out.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Idle {
    /// Keep driving the rest targets: the figure holds its rest pose
    /// (variant 0).
    #[default]
    Hold,
    /// Stop driving: no pulses (hobby servos go limp), bus servos' torque
    /// off (variant 1).
    Off,
}

impl Default for Output {
    fn default() -> Self {
        Output::Maestro { baud: 115_200 }
    }
}

impl Output {
    /// The number of channels of this back-end (channel numbers are below it).
    #[must_use]
    pub const fn channels(&self) -> u8 {
        match self {
            // One board's worth; cascaded PCA9685s are not modelled.
            Output::Pca9685 { .. } => 16,
            // The Mini Maestro 24 has 24; the rig's capacity too.
            _ => MAX_SERVOS as u8,
        }
    }

    /// Whether the targets are positions of serial bus servos (else pulse
    /// widths, µs).
    #[must_use]
    pub const fn is_bus(&self) -> bool {
        matches!(self, Output::Dynamixel { .. } | Output::Feetech { .. })
    }

    /// The highest servo id on the bus (`None`: not a bus).
    #[must_use]
    pub const fn max_id(&self) -> Option<u8> {
        match self {
            Output::Dynamixel { .. } => Some(252),
            Output::Feetech { .. } => Some(253),
            _ => None,
        }
    }

    /// The pulse period, µs, of the back-ends that repeat pulses at a
    /// rate of their own (PWM, PCA9685).
    #[must_use]
    pub const fn period_us(&self) -> Option<u32> {
        match self {
            Output::Pwm { freq_hz } | Output::Pca9685 { freq_hz, .. } if *freq_hz > 0 => {
                Some(1_000_000 / *freq_hz as u32)
            }
            _ => None,
        }
    }

    /// The range of a target, in the back-end's unit (µs, or positions).
    #[must_use]
    pub const fn target_range(&self) -> (f32, f32) {
        if self.is_bus() {
            (1.0, POSITION_MAX)
        } else {
            (1.0, PULSE_MAX_US)
        }
    }
}

/// The frame a sensor's pose is read in before it is measured.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum RefFrame {
    /// World (tracker) coordinates (variant 0).
    #[default]
    World,
    /// The rest-pose frame of this segment (the rig's root placement and all
    /// angles at rest) (variant 1).
    Segment(u8),
    /// The current frame of another sensor, e.g. one on the performer's pelvis
    /// (variant 2). Entries are skipped while that sensor is missing.
    Sensor(u8),
}

/// A coordinate about an axis through a point (see [`Measure::Cylindrical`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Cylinder {
    /// Distance from the axis, m (variant 0).
    #[default]
    Radius,
    /// Angle about the axis, radians in `[−π, π]` (variant 1): about X from +Y
    /// towards +Z, about Y from +Z towards +X, about Z from +X towards +Y
    /// (right-handed).
    Angle,
    /// Position along the axis, m (variant 2).
    Height,
}

/// What is measured of a sensor pose (already in its reference frame).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Measure {
    /// One coordinate of the position, m (variant 0).
    Position(AxisName),
    /// A cylindrical coordinate of the position about the axis through
    /// `center` parallel to `axis` (variant 1).
    Cylindrical {
        /// The axis direction.
        axis: AxisName,
        /// A point on the axis, m.
        center: [f32; 3],
        /// Which coordinate.
        component: Cylinder,
    },
    /// The twist angle of the orientation about an axis, radians in
    /// `(−π, π]` (variant 2).
    Rotation(AxisName),
}

impl Default for Measure {
    fn default() -> Self {
        Measure::Position(AxisName::X)
    }
}

/// One sensor → synthesis parameter entry:
/// `params[param] = offset + scale · measure(sensor in frame)`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ParamMap {
    /// The parameter (table axis) index, `< MAX_PARAMS`, unique in the rig.
    pub param: u8,
    /// The sensor id.
    pub sensor: u8,
    /// The frame the sensor pose is read in.
    pub frame: RefFrame,
    /// What is measured.
    pub measure: Measure,
    /// Added after scaling, in parameter units.
    pub offset: f32,
    /// Parameter units per measured unit.
    pub scale: f32,
}

/// A goal that follows a sensor.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SensorGoal {
    /// The sensor id.
    pub sensor: u8,
    /// The frame the sensor pose is read in.
    pub source: RefFrame,
    /// The target is `offset + scale · p` for the sensor position `p` in
    /// `source`, m (expressed in the goal's frame).
    pub offset: [f32; 3],
    /// Scale from the performer's size to the puppet's.
    pub scale: f32,
    /// Weight of an orientation goal on the same segment (0 = none): the
    /// target orientation is `q · rotation_offset`, `q` the sensor rotation in
    /// `source`.
    pub orientation_weight: f32,
    /// The sensor's mounting rotation on the segment, `[w, x, y, z]`, unit.
    pub rotation_offset: [f32; 4],
}

/// Where a goal's target comes from.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum GoalSource {
    /// A tracked sensor (variant 0).
    Sensor(SensorGoal),
    /// A fixed plane `normal · x = offset` (variant 1): a foot on the floor.
    Plane {
        /// The plane normal (non-zero; normalized when used).
        normal: [f32; 3],
        /// Signed distance of the plane along the normal, m.
        offset: f32,
        /// `true`: the point must only stay above the plane; `false`: on it.
        above: bool,
    },
    /// A fixed point, m (variant 2).
    Point([f32; 3]),
}

/// One goal entry of the rig.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GoalMap {
    /// The segment pulled.
    pub segment: u8,
    /// The attached point in the segment's frame, m; `None` = its touch point.
    pub point: Option<[f32; 3]>,
    /// Importance (≥ 0; 0 = inactive).
    pub weight: f32,
    /// The puppet frame the target is expressed in: `None` = world, else a
    /// segment's current frame.
    pub frame: Option<u8>,
    /// The target.
    pub target: GoalSource,
}

impl Default for GoalMap {
    fn default() -> Self {
        GoalMap {
            segment: 0,
            point: None,
            weight: 0.0,
            frame: None,
            target: GoalSource::Point([0.0; 3]),
        }
    }
}

impl GoalMap {
    /// How many core goals this entry produces (2 with an orientation goal).
    #[must_use]
    pub fn goal_count(&self) -> usize {
        match self.target {
            GoalSource::Sensor(s) if s.orientation_weight > 0.0 => 2,
            _ => 1,
        }
    }
}

/// The whole rig, as serialized in the rig blob (postcard; fields in this
/// order, see [`super`] for the byte layout).
///
/// `N` is the capacity of the segment list (default [`MAX_SEGMENTS`], the
/// format's limit): it does not change the encoding. A firmware that holds
/// smaller rigs decodes into a smaller description (see
/// [`super::Rig::parse_sized`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RigDesc<'a, const N: usize = MAX_SEGMENTS> {
    /// Rig name, ≤ [`RIG_NAME_LEN`] bytes.
    pub name: &'a str,
    /// Control-loop period, µs (100 ..= 100 000).
    pub frame_period_us: u32,
    /// Without a valid tracker frame for this long the outputs go to their
    /// rest pulses, ms (1 ..= 60 000, and at least one frame period).
    pub failsafe_timeout_ms: u32,
    /// World position of the root at rest (e.g. the pelvis on its stand), m.
    pub root_position: [f32; 3],
    /// World orientation of the root at rest, `[w, x, y, z]`, unit.
    pub root_rotation: [f32; 4],
    /// The servo back-end.
    pub output: Output,
    /// What the outputs do at rest after a disarm or fail-safe.
    pub idle: Idle,
    /// The skeleton, root first, parents before children.
    pub segments: List<SegmentDesc<'a>, N>,
    /// The servo channels.
    pub servos: List<ServoDesc, MAX_SERVOS>,
    /// Sensor → parameter entries.
    pub params: List<ParamMap, MAX_PARAMS>,
    /// Goal entries, in the order their goals appear in the goal set.
    pub goals: List<GoalMap, MAX_GOALS>,
}

/// A validation failure at `place`.
const fn bad(place: Place, field: &'static str, problem: Problem) -> RigError {
    RigError::Invalid(Invalid {
        place,
        field,
        problem,
    })
}

/// `Ok` if every value is finite.
fn finite(values: &[f32], place: Place, field: &'static str) -> Result<(), RigError> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(bad(place, field, Problem::NonFinite))
    }
}

/// `Ok` if `q` is finite and of unit length (within [`UNIT_TOLERANCE`]).
fn unit(q: &[f32], place: Place, field: &'static str) -> Result<(), RigError> {
    finite(q, place, field)?;
    let n2: f32 = q.iter().map(|v| v * v).sum();
    if (n2 - 1.0).abs() <= UNIT_TOLERANCE {
        Ok(())
    } else {
        Err(bad(place, field, Problem::NotUnit))
    }
}

/// `Ok` if `lo <= v <= hi`.
fn within<T: PartialOrd>(
    v: T,
    lo: T,
    hi: T,
    place: Place,
    field: &'static str,
) -> Result<(), RigError> {
    if lo <= v && v <= hi {
        Ok(())
    } else {
        Err(bad(place, field, Problem::OutOfRange))
    }
}

/// `Ok` if `v` is finite and in `[lo, hi]`.
fn finite_within(
    v: f32,
    lo: f32,
    hi: f32,
    place: Place,
    field: &'static str,
) -> Result<(), RigError> {
    finite(&[v], place, field)?;
    within(v, lo, hi, place, field)
}

impl<'a> RigDesc<'a> {
    /// An empty description (no segment: not valid until filled in).
    #[must_use]
    pub fn new(name: &'a str, output: Output) -> Self {
        RigDesc {
            name,
            frame_period_us: 1000,
            failsafe_timeout_ms: 100,
            root_position: [0.0; 3],
            root_rotation: [1.0, 0.0, 0.0, 0.0],
            output,
            idle: Idle::Hold,
            segments: List::new(),
            servos: List::new(),
            params: List::new(),
            goals: List::new(),
        }
    }
}

impl<const N: usize> RigDesc<'_, N> {
    /// The number of segments.
    #[must_use]
    pub fn segment_count(&self) -> usize {
        self.segments.len()
    }

    /// The number of core goals the rig produces per frame.
    #[must_use]
    pub fn goal_count(&self) -> usize {
        self.goals.iter().map(GoalMap::goal_count).sum()
    }

    /// Checks every rule of the format; the first failure is returned, naming
    /// the entry and the field (field names are the rig file's keys).
    pub fn validate(&self) -> Result<(), RigError> {
        self.validate_rig()?;
        self.validate_segments()?;
        self.validate_servos()?;
        self.validate_params()?;
        self.validate_goals()
    }

    fn validate_rig(&self) -> Result<(), RigError> {
        let r = Place::Rig;
        within(self.name.len(), 0, RIG_NAME_LEN, r, "name")?;
        let (lo, hi) = FRAME_PERIOD_US;
        within(self.frame_period_us, lo, hi, r, "frame_period_us")?;
        let (lo, hi) = FAILSAFE_MS;
        within(self.failsafe_timeout_ms, lo, hi, r, "failsafe_timeout_ms")?;
        if u64::from(self.failsafe_timeout_ms) * 1000 < u64::from(self.frame_period_us) {
            return Err(bad(r, "failsafe_timeout_ms", Problem::OutOfRange));
        }
        finite(&self.root_position, r, "root_position")?;
        unit(&self.root_rotation, r, "root_rotation")?;
        let o = Place::Output;
        match self.output {
            Output::Pwm { freq_hz } => within(freq_hz, 50, 333, o, "freq_hz"),
            Output::Pca9685 { i2c_addr, freq_hz } => {
                // 0x00-0x07 are reserved, 0x70 is every PCA9685's ALLCALL.
                within(i2c_addr, 0x08, 0x7F, o, "i2c_addr")?;
                if i2c_addr == 0x70 {
                    return Err(bad(o, "i2c_addr", Problem::OutOfRange));
                }
                within(freq_hz, 50, 400, o, "freq_hz")
            }
            Output::Maestro { baud } => within(baud, 300, 250_000, o, "baud"),
            Output::Dynamixel { baud } => within(baud, 9600, 4_500_000, o, "baud"),
            Output::Feetech { baud, .. } => within(baud, 38_400, 1_000_000, o, "baud"),
        }
    }

    fn validate_segments(&self) -> Result<(), RigError> {
        if self.segments.is_empty() {
            return Err(bad(Place::Rig, "segment", Problem::Empty));
        }
        for (i, s) in (0u8..).zip(self.segments.iter()) {
            let p = Place::Segment(i);
            if s.name.is_empty() {
                return Err(bad(p, "name", Problem::Empty));
            }
            within(s.name.len(), 1, NAME_LEN, p, "name")?;
            let earlier = self.segments.as_slice().get(..usize::from(i));
            if earlier.is_some_and(|e| e.iter().any(|o| o.name == s.name)) {
                return Err(bad(p, "name", Problem::Duplicate));
            }
            let parent_ok = if i == 0 {
                s.parent == NO_PARENT
            } else {
                s.parent < i
            };
            if !parent_ok {
                return Err(bad(p, "parent", Problem::NotTopological));
            }
            finite(&s.origin, p, "origin")?;
            finite(&s.touch, p, "touch")?;
            if i == 0 && !s.dofs.is_empty() {
                return Err(bad(p, "dofs", Problem::RootDof));
            }
            Self::validate_dofs(i, s)?;
        }
        Ok(())
    }

    fn validate_dofs(i: u8, s: &SegmentDesc<'_>) -> Result<(), RigError> {
        for (k, d) in (0u8..).zip(s.dofs.iter()) {
            let p = Place::Dof { segment: i, dof: k };
            finite(&[d.min, d.max], p, "limits")?;
            if d.min > d.max {
                return Err(bad(p, "limits", Problem::Unordered));
            }
            within(d.min, -TAU, TAU, p, "limits")?;
            within(d.max, -TAU, TAU, p, "limits")?;
            let earlier = s.dofs.as_slice().get(..usize::from(k));
            if earlier.is_some_and(|e| e.iter().any(|o| o.axis == d.axis)) {
                return Err(bad(p, "axis", Problem::Duplicate));
            }
        }
        Ok(())
    }

    fn segment_ref(&self, s: u8, place: Place, field: &'static str) -> Result<(), RigError> {
        if usize::from(s) < self.segments.len() {
            Ok(())
        } else {
            Err(bad(place, field, Problem::BadReference))
        }
    }

    fn validate_servos(&self) -> Result<(), RigError> {
        for (i, s) in (0u8..).zip(self.servos.iter()) {
            let p = Place::Servo(i);
            if s.channel >= self.output.channels() {
                return Err(bad(p, "channel", Problem::OutOfRange));
            }
            let earlier = self.servos.as_slice().get(..usize::from(i));
            if earlier.is_some_and(|e| e.iter().any(|o| o.channel == s.channel)) {
                return Err(bad(p, "channel", Problem::Duplicate));
            }
            let dofs = self
                .segments
                .as_slice()
                .get(usize::from(s.segment))
                .filter(|_| s.segment != 0)
                .map(|seg| seg.dofs.len())
                .ok_or(bad(p, "joint", Problem::BadReference))?;
            if usize::from(s.dof) >= dofs {
                return Err(bad(p, "axis", Problem::BadReference));
            }
            finite(&[s.angle_min, s.angle_max], p, "angle")?;
            if s.angle_min >= s.angle_max {
                return Err(bad(p, "angle", Problem::Unordered));
            }
            self.validate_targets(i, s, p)?;
            finite_within(s.trim_us, -TRIM_MAX_US, TRIM_MAX_US, p, "trim_us")?;
            let cal = s.calibration();
            finite_within(s.rest_us, cal.pulse_low(), cal.pulse_high(), p, "rest_us")?;
            finite_within(s.max_speed, f32::MIN_POSITIVE, 1e4, p, "max_speed")?;
            finite_within(s.max_accel, f32::MIN_POSITIVE, 1e7, p, "max_accel")?;
        }
        Ok(())
    }

    /// The pulse (or position) range of a servo, and its bus id.
    fn validate_targets(&self, i: u8, s: &ServoDesc, p: Place) -> Result<(), RigError> {
        let (lo, hi) = self.output.target_range();
        let hi = match self.output.period_us() {
            // A pulse must end before the next one starts.
            Some(period) => math::min(hi, period as f32 - 1.0),
            None => hi,
        };
        finite_within(s.pulse_min_us, lo, hi, p, "pulse_us")?;
        finite_within(s.pulse_max_us, lo, hi, p, "pulse_us")?;
        if s.pulse_min_us == s.pulse_max_us {
            return Err(bad(p, "pulse_us", Problem::Unordered));
        }
        let Some(max_id) = self.output.max_id() else {
            return Ok(());
        };
        within(s.id, 0, max_id, p, "id")?;
        let earlier = self.servos.as_slice().get(..usize::from(i));
        if earlier.is_some_and(|e| e.iter().any(|o| o.id == s.id)) {
            return Err(bad(p, "id", Problem::Duplicate));
        }
        Ok(())
    }

    fn validate_frame(&self, f: RefFrame, sensor: u8, place: Place) -> Result<(), RigError> {
        match f {
            RefFrame::World => Ok(()),
            RefFrame::Segment(s) => self.segment_ref(s, place, "frame"),
            RefFrame::Sensor(s) if usize::from(s) >= MAX_SENSORS || s == sensor => {
                Err(bad(place, "frame", Problem::BadReference))
            }
            RefFrame::Sensor(_) => Ok(()),
        }
    }

    fn validate_params(&self) -> Result<(), RigError> {
        for (i, m) in (0u8..).zip(self.params.iter()) {
            let p = Place::Param(i);
            within(usize::from(m.param), 0, MAX_PARAMS - 1, p, "param")?;
            let earlier = self.params.as_slice().get(..usize::from(i));
            if earlier.is_some_and(|e| e.iter().any(|o| o.param == m.param)) {
                return Err(bad(p, "param", Problem::Duplicate));
            }
            within(usize::from(m.sensor), 0, MAX_SENSORS - 1, p, "sensor")?;
            self.validate_frame(m.frame, m.sensor, p)?;
            if let Measure::Cylindrical { center, .. } = m.measure {
                finite(&center, p, "center")?;
            }
            finite(&[m.offset], p, "offset")?;
            finite(&[m.scale], p, "scale")?;
        }
        Ok(())
    }

    fn validate_goals(&self) -> Result<(), RigError> {
        for (i, g) in (0u8..).zip(self.goals.iter()) {
            let p = Place::Goal(i);
            self.segment_ref(g.segment, p, "segment")?;
            if let Some(point) = g.point {
                finite(&point, p, "point")?;
            }
            finite_within(g.weight, 0.0, f32::MAX, p, "weight")?;
            if let Some(f) = g.frame {
                self.segment_ref(f, p, "target_frame")?;
            }
            match g.target {
                GoalSource::Sensor(s) => self.validate_sensor_goal(&s, p)?,
                GoalSource::Plane { normal, offset, .. } => {
                    finite(&normal, p, "normal")?;
                    if normal.iter().map(|v| v * v).sum::<f32>() < 1e-12 {
                        return Err(bad(p, "normal", Problem::Empty));
                    }
                    finite(&[offset], p, "offset")?;
                }
                GoalSource::Point(t) => finite(&t, p, "target")?,
            }
        }
        if self.goal_count() > MAX_GOALS {
            return Err(bad(Place::Rig, "goal", Problem::Capacity));
        }
        Ok(())
    }

    fn validate_sensor_goal(&self, s: &SensorGoal, p: Place) -> Result<(), RigError> {
        within(usize::from(s.sensor), 0, MAX_SENSORS - 1, p, "sensor")?;
        self.validate_frame(s.source, s.sensor, p)?;
        finite(&s.offset, p, "offset")?;
        finite(&[s.scale], p, "scale")?;
        finite_within(s.orientation_weight, 0.0, f32::MAX, p, "orientation_weight")?;
        unit(&s.rotation_offset, p, "rotation_offset")
    }
}
