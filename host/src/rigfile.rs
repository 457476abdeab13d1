//! Rig files: the TOML description of a physical figure, read into the core's
//! [`RigDesc`] (the schema of the rig blob) plus host-only extras (the
//! retarget map), and written as a rig blob with [`to_blob`].
//!
//! Every error names the file, the 1-based line and the field
//! (`rigs/x.toml:42: servo[3].channel: 7 is used twice`): TOML syntax and
//! type errors through the parser's spans, name lookups here, and every
//! other rule through the core's [`RigDesc::validate`] (the one rule set the
//! firmware applies too), whose error names the entry and the field; the
//! field's span is looked up here.
//!
//! # Format
//!
//! Units are SI (metres, radians, seconds, µs for pulses), axes right-handed
//! with Y up, quaternions `[w, x, y, z]`. Angle pairs may be given in degrees
//! instead with the `_deg` form of the key (`limits_deg`, `angle_deg`).
//! See `rigs/humanoid16.toml` for a commented example.
//!
//! ```toml
//! name = "puppet"                # ≤ 32 bytes
//! frame_period_us = 1000         # control loop period (100 ..= 100000)
//! failsafe_timeout_ms = 100      # no tracker data this long: servos to rest
//! length_unit = 1.0              # metres per unit of segment origin/touch (default 1)
//! root_position = [0, 0.44, 0]   # rest placement of the root, m (default 0)
//! root_rotation = [1, 0, 0, 0]   # (default identity)
//!
//! [output]                       # kind = "pwm" (freq_hz 50-333) | "pca9685" (i2c_addr, freq_hz 50-400)
//! kind = "maestro"               #      | "maestro" (baud) | "dynamixel" (baud) | "feetech" (baud, series)
//! baud = 115200
//! idle = "hold"                  # at rest after a disarm or fail-safe: "hold" (default) | "off"
//! # Serial bus servos (dynamixel, feetech) take positions, not pulses:
//! # units_per_degree = 11.3778   # default 4096/360 (Dynamixel X, Feetech STS); SCS 1024/300
//! # series = "sts"               # feetech only: "sts" (little-endian, default) | "scs" (big-endian)
//!
//! [[segment]]                    # root first, parents before children
//! name = "pelvis"                # ≤ 24 bytes, unique; the root has no parent and no dofs
//! touch = [0, 0, 0]              # touch point, segment frame (default origin)
//! [[segment]]
//! name = "l_shin"
//! parent = "l_thigh"
//! origin = [0, -0.19, 0]         # joint origin in the parent's frame
//! dofs = [{ axis = "x", limits_deg = [0, 130] }]   # 0-3, in order, distinct axes
//!
//! [[servo]]
//! channel = 6                    # unique, below the back-end's channel count
//! joint = "l_shin"               # the segment whose joint it turns
//! axis = "x"                     # which of its DOFs
//! angle_deg = [-25, 155]         # joint angles at the two pulse ends
//! pulse_us = [500, 2500]
//! trim_us = 0                    # default 0
//! reversed = false               # default false
//! rest_us = 1500                 # default: the pulse of the rest angle
//! max_speed = 5.5                # rad/s
//! max_accel = 50                 # rad/s²
//! # A serial bus servo instead of pulse_us, trim_us and rest_us:
//! # id = 3                       # its id on the bus (default: the channel)
//! # center = 2048                # position at joint angle 0 (default: mid-travel, 2048; SCS 512)
//! # limits = [1024, 3072]        # positions it may take (default: 1 ..= 4095; SCS 1 ..= 1023)
//! # rest = 2048                  # default: the position of the rest angle
//! # position = center ± angle · units_per_degree (− when reversed), within limits
//!
//! [[param]]                      # params[param] = offset + scale * measure
//! param = 0
//! sensor = 0
//! frame = "sensor:2"             # "world" (default) | a segment name (its rest frame) | "sensor:N"
//! measure = "position"           # + component = "x" | "y" | "z"
//!                                # "cylindrical": axis, center, component = "radius" | "angle" | "height"
//!                                # "rotation": axis (twist angle about it)
//! component = "x"
//! scale = 0.5                    # default 1
//! offset = 0.0                   # default 0
//!
//! [[goal]]                       # exactly one of sensor / plane / target
//! segment = "r_forearm"
//! weight = 10
//! point = [0, -0.15, 0]          # default: the touch point
//! target_frame = "pelvis"        # puppet frame of the target: "world" (default) or a segment
//! sensor = 0                     # target = offset + scale * (sensor position in `frame`)
//! frame = "sensor:2"
//! scale = 0.5
//! offset = [0, 0, 0]
//! orientation_weight = 0         # > 0 adds an orientation goal (q · rotation_offset)
//! rotation_offset = [1, 0, 0, 0]
//! # plane = { normal = [0, 1, 0], offset = 0, side = "contact" | "above" }
//! # target = [x, y, z]
//!
//! [retarget]                     # host only: mocap joint -> segment
//! identity = false               # true: every segment takes the mocap joint of its own name
//! [[retarget.joint]]
//! mocap = "RightForeArm"
//! segment = "r_forearm"
//! rotation_offset = [1, 0, 0, 0] # optional
//!
//! [[retarget.map]]               # further maps for other mocap skeletons, chosen by
//! name = "hdm05"                 # name in a build spec (`[rig] retarget = "hdm05"`)
//! joint = [{ mocap = "rradius", segment = "r_forearm" }]   # entries as above
//! ```
//!
//! ```toml
//! [live]                         # host only, optional: `marionette live`'s sources
//! [[live.sensor]]                # a VMC bone (Unity humanoid name, /VMC/Ext/Bone/Pos)
//! name = "RightHand"             # or tracker serial (/VMC/Ext/Tra/Pos) -> a sensor id
//! sensor = 0                     # 0 ..= 15, unique; names unique
//! [[live.param]]                 # a plain OSC address -> a parameter, sent as `Params`
//! address = "/marionette/fader1" # starts with '/'; unique
//! param = 0                      # the entries cover params 0 ..= k-1, each once
//! scale = 1.0                    # value = offset + scale * first argument (default 1)
//! offset = 0.0                   # (default 0; also the value until the address is heard)
//! ```
//!
//! Optional `[[layer]]` tables perform several tables at once, blended by
//! body part; see [`LayerSpec`] and [`region`] for their fields.
//!
//! A `[[live.sensor]]` name that is a Unity humanoid bone (`Hips`,
//! `RightHand`, …; see `host/src/live.rs`) reads that bone; any other name
//! reads the tracker of that serial. `Params` overrides parameters `0..k`
//! on the board, so `[[live.param]]` must name each of `0..k` once.
//!
//! `[[retarget.joint]]` is the default map (used when a build spec names
//! none); each `[[retarget.map]]` is a complete alternative map for another
//! mocap skeleton (different joint names or rest pose), with its own
//! entries (`joint = [...]`, or `[[retarget.map.joint]]` tables after it).

use std::ops::Range;
use std::path::{Path, PathBuf};

use marionette_core::pose::NO_PARENT;
use marionette_core::rig::{
    AxisName, Cylinder, DofDesc, FeetechSeries, GoalMap, GoalSource, Idle, Invalid, MAX_GOALS,
    MAX_PARAMS, MAX_SEGMENTS, MAX_SENSORS, MAX_SERVOS, Measure, Output, ParamMap, Place, Problem,
    RefFrame, RigDesc, RigError, SegmentDesc, SensorGoal, ServoDesc,
};
use marionette_core::servo::Calibration;
use marionette_core::wire::List;
use serde::Deserialize;
use toml::Spanned;

mod layer;
pub use layer::{Given, LayerSpec, region, region_of_files};

/// A rig-file error: where (file, 1-based line; 0 if unknown), which field,
/// and what is wrong.
#[derive(Debug, thiserror::Error)]
pub enum RigFileError {
    /// The file could not be read.
    #[error("{file}: cannot read: {source}")]
    Io {
        /// The file.
        file: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A syntax, type or rule error at a place in the file.
    #[error("{file}:{line}: {field}: {message}")]
    At {
        /// The file.
        file: String,
        /// 1-based line (0 when no line applies).
        line: usize,
        /// The field, as a dotted path (`servo[3].channel`).
        field: String,
        /// What is wrong.
        message: String,
    },
}

/// One retarget entry: which mocap joint drives which rig segment.
#[derive(Clone, Debug, PartialEq)]
pub struct RetargetJoint {
    /// The joint name in the mocap file.
    pub mocap: String,
    /// The rig segment index.
    pub segment: u8,
    /// Rotation applied after the mocap joint's (`[w, x, y, z]`, unit).
    pub rotation_offset: [f64; 4],
}

/// A named alternative retarget map (`[[retarget.map]]`), for another mocap
/// skeleton.
#[derive(Clone, Debug, PartialEq)]
pub struct RetargetMap {
    /// The name a build spec selects it by (`[rig] retarget = "..."`).
    pub name: String,
    /// Its entries, in segment order of first mention.
    pub joints: Vec<RetargetJoint>,
}

/// `[[live.sensor]]`: a live source's name for a sensor.
#[derive(Clone, Debug, PartialEq)]
pub struct LiveSensor {
    /// The VMC bone name or tracker serial.
    pub name: String,
    /// The sensor id it becomes.
    pub sensor: u8,
}

/// `[[live.param]]`: a plain OSC address driving a parameter.
#[derive(Clone, Debug, PartialEq)]
pub struct LiveParam {
    /// The OSC address.
    pub address: String,
    /// The parameter index.
    pub param: u8,
    /// value = offset + scale · argument.
    pub scale: f32,
    /// The value's offset, and the value until the address is heard.
    pub offset: f32,
}

/// The `[live]` table: how `marionette live` maps a source's names.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LiveMap {
    /// Sensors, in file order.
    pub sensors: Vec<LiveSensor>,
    /// Parameters, sorted by parameter index (`0..k`).
    pub params: Vec<LiveParam>,
}

/// A loaded rig file.
#[derive(Clone, Debug)]
pub struct RigFile {
    /// Where it was read from (as given).
    pub file: String,
    name: String,
    segment_names: Vec<String>,
    desc: RigDesc<'static>,
    /// The default retarget map (`[[retarget.joint]]`), in segment order of
    /// first mention.
    pub retarget: Vec<RetargetJoint>,
    /// The named alternative maps (`[[retarget.map]]`), in file order.
    pub retarget_maps: Vec<RetargetMap>,
    /// `marionette live`'s name map (`[live]`; empty without one).
    pub live: LiveMap,
    /// The layers (`[[layer]]`, in blend order; empty: one table, no
    /// layers). See [`region()`].
    pub layers: Vec<LayerSpec>,
}

impl RigFile {
    /// The description, borrowing the names.
    #[must_use]
    pub fn desc(&self) -> RigDesc<'_> {
        named(&self.desc, &self.name, &self.segment_names)
    }

    /// The rig's name.
    #[must_use]
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The segment names, in order.
    #[must_use]
    pub fn segment_names(&self) -> &[String] {
        &self.segment_names
    }

    /// The skeleton hash (the tables' `rig_hash`).
    #[must_use]
    pub fn rig_hash(&self) -> u64 {
        self.desc().rig_hash()
    }

    /// A retarget map: the default one for `None`, else the named
    /// `[[retarget.map]]` (`None` if there is no such map).
    #[must_use]
    pub fn retarget_map(&self, name: Option<&str>) -> Option<&[RetargetJoint]> {
        match name {
            None => Some(&self.retarget),
            Some(n) => self
                .retarget_maps
                .iter()
                .find(|m| m.name == n)
                .map(|m| m.joints.as_slice()),
        }
    }
}

/// `desc` with its names filled in (the stored one has empty names).
fn named<'a>(desc: &RigDesc<'static>, name: &'a str, segment_names: &'a [String]) -> RigDesc<'a> {
    let mut segments = List::new();
    for (s, n) in desc.segments.iter().zip(segment_names) {
        // Same capacity as the stored list.
        let _ = segments.push(SegmentDesc {
            name: n.as_str(),
            ..*s
        });
    }
    RigDesc {
        name,
        segments,
        ..*desc
    }
}

/// The largest rig file read, bytes: a full rig of [`MAX_SEGMENTS`]
/// segments with every comment fits in a few tens of kilobytes.
pub const MAX_FILE_BYTES: u64 = 1 << 20;

/// Reads and checks a rig file (at most [`MAX_FILE_BYTES`], checked before
/// it is read).
pub fn load(path: &Path) -> Result<RigFile, RigFileError> {
    let file = path.display().to_string();
    let io = |source| RigFileError::Io {
        file: file.clone(),
        source,
    };
    let len = std::fs::metadata(path).map_err(io)?.len();
    if len > MAX_FILE_BYTES {
        return Err(RigFileError::At {
            file,
            line: 0,
            field: "rig".into(),
            message: format!(
                "the file is {len} bytes; a rig file is at most {MAX_FILE_BYTES} (a rig holds at most \
                 {MAX_SEGMENTS} segments)"
            ),
        });
    }
    let text = std::fs::read_to_string(path).map_err(io)?;
    parse(&text, &file)
}

/// Counts the `[[segment]]` and `[[servo]]` table headers before the TOML
/// is parsed, so that a file of far too many is refused before its syntax
/// tree is built; the line of the first one too many is named.
fn check_counts(src: &Source<'_>) -> Result<(), RigFileError> {
    let limits = [("segment", MAX_SEGMENTS), ("servo", MAX_SERVOS)];
    for (table, most) in limits {
        let header = format!("[[{table}]]");
        let mut offset = 0;
        let mut count = 0;
        for line in src.text.split_inclusive('\n') {
            let squeezed: String = line.chars().filter(|c| !c.is_whitespace()).collect();
            if squeezed.starts_with(&header) {
                count += 1;
                if count > most {
                    return Err(src.err(
                        &(offset..offset),
                        format!("{table}[{most}]"),
                        format!("more than {most} [[{table}]] tables (the most a rig holds)"),
                    ));
                }
            }
            offset += line.len();
        }
    }
    Ok(())
}

/// The rig blob of a loaded rig file (see `marionette_core::rig`).
pub fn to_blob(rig: &RigFile) -> Result<Vec<u8>, RigFileError> {
    let mut out = vec![0u8; marionette_core::rig::MAX_BLOB_LEN];
    let n = rig.desc().to_blob(&mut out).map_err(|e| RigFileError::At {
        file: rig.file.clone(),
        line: 0,
        field: "rig".into(),
        message: format!("cannot write the rig blob: {e:?}"),
    })?;
    out.truncate(n);
    Ok(out)
}

/// Writes the rig blob of a rig file to `out`.
pub fn write_blob(rig: &RigFile, out: &Path) -> Result<(), RigFileError> {
    let blob = to_blob(rig)?;
    let file = Path::new(&rig.file);
    crate::save::save(out, &blob, &[("the rig file", file)]).map_err(|e| RigFileError::Io {
        file: out.display().to_string(),
        source: std::io::Error::other(e.to_string()),
    })
}

/// Resolves the path of a rig argument, searching in this order:
///
/// 1. the argument as a path, if it exists;
/// 2. `rigs/<name>.toml` in the current folder;
/// 3. the rigs built into marionette (the repository's `rigs/*.toml`,
///    `humanoid16` and `cmu31`), by name or as `rigs/<name>.toml`, written
///    out to the bundle folder (see [`crate::bundle`]).
///
/// Otherwise the argument as given (loading it then names the missing file).
#[must_use]
pub fn resolve(arg: &Path) -> PathBuf {
    if arg.exists() {
        return arg.to_path_buf();
    }
    let local = Path::new("rigs").join(arg).with_extension("toml");
    if local.exists() {
        return local;
    }
    [arg, local.as_path()]
        .into_iter()
        .find_map(|rel| crate::bundle::file(rel)?.ok())
        .unwrap_or_else(|| arg.to_path_buf())
}

// ---------------------------------------------------------------------------
// The TOML shape.

type S<T> = Spanned<T>;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRig {
    name: S<String>,
    frame_period_us: S<u32>,
    failsafe_timeout_ms: S<u32>,
    length_unit: Option<S<f32>>,
    root_position: Option<S<[f32; 3]>>,
    root_rotation: Option<S<[f32; 4]>>,
    output: S<RawOutput>,
    #[serde(default)]
    segment: Vec<S<RawSegment>>,
    #[serde(default)]
    servo: Vec<S<RawServo>>,
    #[serde(default)]
    param: Vec<S<RawParam>>,
    #[serde(default)]
    goal: Vec<S<RawGoal>>,
    retarget: Option<S<RawRetarget>>,
    live: Option<S<RawLive>>,
    #[serde(default)]
    layer: Vec<S<layer::RawLayer>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLive {
    #[serde(default)]
    sensor: Vec<S<RawLiveSensor>>,
    #[serde(default)]
    param: Vec<S<RawLiveParam>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLiveSensor {
    name: S<String>,
    sensor: S<u8>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLiveParam {
    address: S<String>,
    param: S<u8>,
    scale: Option<S<f32>>,
    offset: Option<S<f32>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawOutput {
    kind: S<String>,
    freq_hz: Option<S<u16>>,
    i2c_addr: Option<S<u8>>,
    baud: Option<S<u32>>,
    idle: Option<S<String>>,
    series: Option<S<String>>,
    units_per_degree: Option<S<f32>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSegment {
    name: S<String>,
    parent: Option<S<String>>,
    origin: Option<S<[f32; 3]>>,
    touch: Option<S<[f32; 3]>>,
    dofs: Option<S<Vec<S<RawDof>>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDof {
    axis: S<String>,
    limits: Option<S<[f32; 2]>>,
    limits_deg: Option<S<[f32; 2]>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawServo {
    channel: S<u8>,
    joint: S<String>,
    axis: S<String>,
    angle: Option<S<[f32; 2]>>,
    angle_deg: Option<S<[f32; 2]>>,
    pulse_us: Option<S<[f32; 2]>>,
    trim_us: Option<S<f32>>,
    reversed: Option<bool>,
    rest_us: Option<S<f32>>,
    max_speed: S<f32>,
    max_accel: S<f32>,
    id: Option<S<u8>>,
    center: Option<S<f32>>,
    limits: Option<S<[f32; 2]>>,
    rest: Option<S<f32>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawParam {
    param: S<u8>,
    sensor: S<u8>,
    frame: Option<S<String>>,
    measure: S<String>,
    component: Option<S<String>>,
    axis: Option<S<String>>,
    center: Option<S<[f32; 3]>>,
    offset: Option<S<f32>>,
    scale: Option<S<f32>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawGoal {
    segment: S<String>,
    weight: S<f32>,
    point: Option<S<[f32; 3]>>,
    target_frame: Option<S<String>>,
    sensor: Option<S<u8>>,
    frame: Option<S<String>>,
    offset: Option<S<[f32; 3]>>,
    scale: Option<S<f32>>,
    orientation_weight: Option<S<f32>>,
    rotation_offset: Option<S<[f32; 4]>>,
    plane: Option<S<RawPlane>>,
    target: Option<S<[f32; 3]>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPlane {
    normal: S<[f32; 3]>,
    offset: Option<S<f32>>,
    side: Option<S<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRetarget {
    #[serde(default)]
    identity: bool,
    #[serde(default)]
    joint: Vec<S<RawRetargetJoint>>,
    #[serde(default)]
    map: Vec<S<RawRetargetMap>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRetargetMap {
    name: S<String>,
    #[serde(default)]
    joint: Vec<S<RawRetargetJoint>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRetargetJoint {
    mocap: S<String>,
    segment: S<String>,
    rotation_offset: Option<S<[f64; 4]>>,
}

// ---------------------------------------------------------------------------
// Locating errors.

/// Maps byte offsets to lines and dotted field paths.
struct Source<'t> {
    text: &'t str,
    file: &'t str,
}

impl Source<'_> {
    fn line(&self, offset: usize) -> usize {
        let end = offset.min(self.text.len());
        self.text
            .as_bytes()
            .get(..end)
            .map_or(0, |b| b.iter().filter(|&&c| c == b'\n').count())
            + 1
    }

    /// The dotted path of the key at `offset`: the enclosing `[table]` or
    /// `[[array]]` (with its index) and the key on that line.
    fn path_at(&self, offset: usize) -> String {
        let mut counts: Vec<(String, usize)> = Vec::new();
        let mut table = String::new();
        let mut pos = 0;
        for line in self.text.split_inclusive('\n') {
            let start = pos;
            pos += line.len();
            let t = line.trim();
            if let Some(name) = t.strip_prefix("[[").and_then(|r| r.split("]]").next()) {
                let name = name.trim().to_string();
                let n = match counts.iter_mut().find(|(k, _)| *k == name) {
                    Some((_, c)) => {
                        *c += 1;
                        *c - 1
                    }
                    None => {
                        counts.push((name.clone(), 1));
                        0
                    }
                };
                table = format!("{name}[{n}]");
            } else if let Some(name) = t.strip_prefix('[').and_then(|r| r.split(']').next()) {
                table = name.trim().to_string();
            }
            if offset < pos || pos >= self.text.len() {
                let col = offset.saturating_sub(start);
                let before = line.get(..col.min(line.len())).unwrap_or("");
                let key = if t.starts_with('[') {
                    None
                } else {
                    key_before(before)
                };
                return match (table.is_empty(), key) {
                    (true, Some(k)) => k,
                    (false, Some(k)) => format!("{table}.{k}"),
                    (_, None) if table.is_empty() => "(top level)".into(),
                    (_, None) => table,
                };
            }
        }
        "(end of file)".into()
    }

    fn err(
        &self,
        span: &Range<usize>,
        field: impl Into<String>,
        message: impl Into<String>,
    ) -> RigFileError {
        RigFileError::At {
            file: self.file.to_string(),
            line: self.line(span.start),
            field: field.into(),
            message: message.into(),
        }
    }

    fn toml_err(&self, e: &toml::de::Error) -> RigFileError {
        let span = e.span().unwrap_or(0..0);
        let message = e.message().to_string();
        // `missing field` errors point at the table header: the path is the
        // table's; name the field from the message.
        let mut field = self.path_at(span.start);
        if let Some(name) = message
            .strip_prefix("missing field `")
            .and_then(|m| m.strip_suffix('`'))
        {
            field = format!("{field}.{name}");
        }
        if let Some(name) = message
            .strip_prefix("unknown field `")
            .and_then(|m| m.split('`').next())
        {
            field = format!("{field}.{name}");
        }
        self.err(&span, field, message)
    }
}

/// The key a value at the end of `before` belongs to: the line's own key,
/// then (for a value inside an inline table) the innermost key, joined by a
/// dot (`dofs.limits_deg`).
fn key_before(before: &str) -> Option<String> {
    let pieces: Vec<&str> = before.split('=').collect();
    let ident = |piece: &str| -> Option<String> {
        let k = piece
            .trim_end()
            .rsplit(|c: char| c.is_whitespace() || matches!(c, '{' | ',' | '['))
            .next()?
            .trim_matches('"');
        (!k.is_empty()).then(|| k.to_string())
    };
    let keys: Vec<String> = pieces
        .iter()
        .take(pieces.len().saturating_sub(1))
        .filter_map(|p| ident(p))
        .collect();
    let first_is_key = !before.trim_start().starts_with(['{', '[']);
    match (keys.first(), keys.last()) {
        (Some(f), Some(l)) if f != l && first_is_key => Some(format!("{f}.{l}")),
        (_, Some(l)) => Some(l.clone()),
        _ => None,
    }
}

/// Spans of the fields the core validates, keyed as the core names them.
#[derive(Default)]
struct Spans {
    fields: Vec<(Place, &'static str, Range<usize>)>,
    entries: Vec<(Place, Range<usize>, String)>,
}

impl Spans {
    fn field<T>(&mut self, place: Place, field: &'static str, v: &S<T>) {
        self.fields.push((place, field, v.span()));
    }

    fn opt<T>(&mut self, place: Place, field: &'static str, v: &Option<S<T>>) {
        if let Some(v) = v {
            self.field(place, field, v);
        }
    }

    fn entry(&mut self, place: Place, span: Range<usize>, path: String) {
        self.entries.push((place, span, path));
    }

    fn locate(&self, i: &Invalid) -> (Range<usize>, String) {
        let entry = self.entries.iter().find(|(p, ..)| *p == i.place);
        let path = entry.map_or_else(
            || match i.place {
                Place::Output => "output".to_string(),
                _ => String::new(),
            },
            |(.., path)| path.clone(),
        );
        let field = if path.is_empty() {
            i.field.to_string()
        } else {
            format!("{path}.{}", i.field)
        };
        let span = self
            .fields
            .iter()
            .find(|(p, f, _)| *p == i.place && *f == i.field)
            .map(|(.., s)| s.clone())
            .or_else(|| entry.map(|(_, s, _)| s.clone()))
            .unwrap_or(0..0);
        (span, field)
    }
}

/// The message for a core validation problem.
fn describe(i: &Invalid) -> String {
    let hint = match i.field {
        "frame_period_us" => " (100 ..= 100000 µs)",
        "failsafe_timeout_ms" => " (1 ..= 60000 ms, and at least one frame period)",
        "freq_hz" => " (pwm: 50 ..= 333 Hz; pca9685: 50 ..= 400 Hz)",
        "i2c_addr" => " (a 7-bit address 0x08 ..= 0x7F, not 0x70)",
        "baud" => {
            " (maestro 300 ..= 250000, dynamixel 9600 ..= 4500000, feetech 38400 ..= 1000000)"
        }
        "channel" => " (below the output's channel count: 16 for pca9685, 24 otherwise)",
        "pulse_us" => " (1 ..= 4000 µs and shorter than the PWM period, two different values)",
        "trim_us" => " (±1000 µs)",
        "rest_us" => " (within pulse_us)",
        "max_speed" | "max_accel" => " (must be > 0)",
        "limits" => " (within ±2π rad)",
        "name" => " (1 ..= 24 bytes for a segment, ≤ 32 for the rig)",
        "weight" | "orientation_weight" => " (must be ≥ 0)",
        "param" => " (0 ..= 5)",
        "sensor" => " (0 ..= 15)",
        _ => "",
    };
    match i.problem {
        Problem::NonFinite => "not a finite number".into(),
        Problem::OutOfRange => format!("out of range{hint}"),
        Problem::Unordered => "min must be below max".into(),
        Problem::Duplicate => "repeats an earlier entry".into(),
        Problem::NotTopological => "the parent must be an earlier segment".into(),
        Problem::BadReference => "refers to something that does not exist".into(),
        Problem::Empty => "must not be empty (or zero)".into(),
        Problem::NotUnit => "must have unit length".into(),
        Problem::RootDof => "the root segment is free and takes no dofs".into(),
        Problem::Capacity => "more entries than a rig holds".into(),
    }
}

// ---------------------------------------------------------------------------
// Conversion.

/// Reads a rig file's text (`file` names it in errors).
pub fn parse(text: &str, file: &str) -> Result<RigFile, RigFileError> {
    let src = Source { text, file };
    check_counts(&src)?;
    let raw: RawRig = toml::from_str(text).map_err(|e| src.toml_err(&e))?;
    Builder {
        src: &src,
        spans: Spans::default(),
        names: Vec::new(),
        bus: None,
    }
    .build(raw)
}

struct Builder<'s, 't> {
    src: &'s Source<'t>,
    spans: Spans,
    names: Vec<String>,
    /// The position scale of a serial bus output (`None`: pulses).
    bus: Option<BusScale>,
}

/// How a serial bus output turns joint angles into positions.
#[derive(Clone, Copy, Debug)]
struct BusScale {
    /// Position units per radian.
    per_rad: f32,
    /// The default position at joint angle 0.
    center: f32,
    /// The default position limits.
    limits: [f32; 2],
}

fn axis_name(s: &str) -> Option<AxisName> {
    match s.to_ascii_lowercase().as_str() {
        "x" => Some(AxisName::X),
        "y" => Some(AxisName::Y),
        "z" => Some(AxisName::Z),
        _ => None,
    }
}

const DEG: f32 = core::f32::consts::PI / 180.0;

impl Builder<'_, '_> {
    fn err<T>(&self, v: &S<T>, field: &str, message: impl Into<String>) -> RigFileError {
        self.src.err(&v.span(), field, message)
    }

    fn segment(&self, v: &S<String>, field: &str) -> Result<u8, RigFileError> {
        self.names
            .iter()
            .position(|n| n == v.get_ref())
            .and_then(|i| u8::try_from(i).ok())
            .ok_or_else(|| self.err(v, field, format!("unknown segment {:?}", v.get_ref())))
    }

    fn axis(&self, v: &S<String>, field: &str) -> Result<AxisName, RigFileError> {
        axis_name(v.get_ref()).ok_or_else(|| {
            self.err(
                v,
                field,
                format!("expected \"x\", \"y\" or \"z\", found {:?}", v.get_ref()),
            )
        })
    }

    /// A `[min, max]` pair given in radians or degrees (exactly one).
    fn pair(
        &self,
        rad: &Option<S<[f32; 2]>>,
        deg: &Option<S<[f32; 2]>>,
        entry: &Range<usize>,
        path: &str,
        key: &str,
    ) -> Result<(S<[f32; 2]>, [f32; 2]), RigFileError> {
        match (rad, deg) {
            (Some(r), None) => Ok((r.clone(), *r.get_ref())),
            (None, Some(d)) => {
                let [a, b] = *d.get_ref();
                Ok((d.clone(), [a * DEG, b * DEG]))
            }
            (Some(r), Some(_)) => Err(self.err(
                r,
                &format!("{path}.{key}"),
                format!("give {key} or {key}_deg, not both"),
            )),
            (None, None) => Err(self.src.err(
                entry,
                format!("{path}.{key}"),
                format!("missing {key} (radians) or {key}_deg"),
            )),
        }
    }

    /// A reference frame: `"world"`, `"sensor:N"` or a segment name.
    fn ref_frame(&self, v: &Option<S<String>>, path: &str) -> Result<RefFrame, RigFileError> {
        let Some(v) = v else {
            return Ok(RefFrame::World);
        };
        let s = v.get_ref().trim();
        if s == "world" {
            return Ok(RefFrame::World);
        }
        if let Some(id) = s.strip_prefix("sensor:") {
            return id
                .trim()
                .parse::<u8>()
                .ok()
                .filter(|&i| usize::from(i) < MAX_SENSORS)
                .map(RefFrame::Sensor)
                .ok_or_else(|| {
                    self.err(
                        v,
                        &format!("{path}.frame"),
                        format!("bad sensor id in {s:?} (0 ..= 15)"),
                    )
                });
        }
        Ok(RefFrame::Segment(
            self.segment(v, &format!("{path}.frame"))?,
        ))
    }

    fn build(mut self, raw: RawRig) -> Result<RigFile, RigFileError> {
        let output = self.output(&raw.output)?;
        let mut desc = RigDesc::new("", output);
        desc.idle = self.idle(&raw.output)?;
        self.bus = self.bus_scale(&raw.output, &output)?;
        let r = Place::Rig;
        self.spans.field(r, "name", &raw.name);
        self.spans.field(r, "frame_period_us", &raw.frame_period_us);
        self.spans
            .field(r, "failsafe_timeout_ms", &raw.failsafe_timeout_ms);
        self.spans.opt(r, "root_position", &raw.root_position);
        self.spans.opt(r, "root_rotation", &raw.root_rotation);
        desc.frame_period_us = *raw.frame_period_us.get_ref();
        desc.failsafe_timeout_ms = *raw.failsafe_timeout_ms.get_ref();
        desc.root_position = raw
            .root_position
            .as_ref()
            .map_or([0.0; 3], |v| *v.get_ref());
        desc.root_rotation = raw
            .root_rotation
            .as_ref()
            .map_or([1.0, 0.0, 0.0, 0.0], |v| *v.get_ref());
        let unit = match &raw.length_unit {
            Some(u) if u.get_ref().is_finite() && *u.get_ref() > 0.0 => *u.get_ref(),
            Some(u) => return Err(self.err(u, "length_unit", "must be a finite number > 0")),
            None => 1.0,
        };
        if raw.segment.is_empty() {
            return Err(self
                .src
                .err(&(0..0), "segment", "a rig needs at least one [[segment]]"));
        }
        for (i, s) in raw.segment.iter().enumerate() {
            let seg = self.segment_desc(i, s, unit)?;
            if desc.segments.push(seg).is_err() {
                return Err(self.src.err(
                    &s.span(),
                    format!("segment[{i}]"),
                    format!("more than {MAX_SEGMENTS} segments"),
                ));
            }
        }
        // The skeleton's own rules first, so that its errors are not reported
        // as the servos' or goals' that refer to it.
        self.check(&named(&desc, raw.name.get_ref(), &self.names))?;
        desc.servos = self.servos(&raw.servo, &desc)?;
        desc.params = self.params(&raw.param)?;
        desc.goals = self.goals(&raw.goal)?;
        let retarget = self.retarget(raw.retarget.as_ref())?;
        let retarget_maps = self.retarget_maps(raw.retarget.as_ref())?;
        let live = self.live(raw.live.as_ref())?;
        let layers = layer::parse(self.src, &raw, &self.names)?;
        let rig = RigFile {
            file: self.src.file.to_string(),
            name: raw.name.get_ref().clone(),
            segment_names: self.names.clone(),
            desc,
            retarget,
            retarget_maps,
            live,
            layers,
        };
        self.check(&rig.desc())?;
        Ok(rig)
    }

    /// The core's validation of what has been built so far.
    fn check(&self, desc: &RigDesc<'_>) -> Result<(), RigFileError> {
        desc.validate().map_err(|e| self.core_err(e))
    }

    fn core_err(&self, e: RigError) -> RigFileError {
        match e {
            RigError::Invalid(i) if self.bus.is_some() && i.field == "pulse_us" => {
                let (span, field) = self.spans.locate(&i);
                let field = field.replace("pulse_us", "limits");
                let message = match i.problem {
                    Problem::Unordered => "the angle range maps to a single position".into(),
                    _ => "positions out of range (1 ..= 4095)".to_string(),
                };
                self.src.err(&span, field, message)
            }
            RigError::Invalid(i) => {
                let (span, field) = self.spans.locate(&i);
                self.src.err(&span, field, describe(&i))
            }
            other => self.src.err(&(0..0), "rig", format!("{other:?}")),
        }
    }

    fn output(&mut self, o: &S<RawOutput>) -> Result<Output, RigFileError> {
        let raw = o.get_ref();
        let p = Place::Output;
        self.spans.entry(p, o.span(), "output".into());
        self.spans.opt(p, "freq_hz", &raw.freq_hz);
        self.spans.opt(p, "i2c_addr", &raw.i2c_addr);
        self.spans.opt(p, "baud", &raw.baud);
        let need = |v: Option<&S<u32>>, key: &str| -> Result<u32, RigFileError> {
            v.map(|v| *v.get_ref()).ok_or_else(|| {
                self.err(
                    &raw.kind,
                    &format!("output.{key}"),
                    format!("output kind {:?} needs {key}", raw.kind.get_ref()),
                )
            })
        };
        let freq = raw
            .freq_hz
            .as_ref()
            .map(|v| S::new(v.span(), u32::from(*v.get_ref())));
        let addr = raw
            .i2c_addr
            .as_ref()
            .map(|v| S::new(v.span(), u32::from(*v.get_ref())));
        let unused = |v: Option<Range<usize>>, key: &str| match v {
            Some(span) => Err(self.src.err(
                &span,
                format!("output.{key}"),
                format!("not used by output kind {:?}", raw.kind.get_ref()),
            )),
            None => Ok(()),
        };
        let span = |v: &Option<S<u32>>| v.as_ref().map(S::span);
        match raw.kind.get_ref().as_str() {
            "pwm" => {
                unused(span(&addr), "i2c_addr")?;
                unused(span(&raw.baud), "baud")?;
                let f = need(freq.as_ref(), "freq_hz")?;
                Ok(Output::Pwm {
                    freq_hz: u16::try_from(f).unwrap_or(u16::MAX),
                })
            }
            "pca9685" => {
                unused(span(&raw.baud), "baud")?;
                let f = need(freq.as_ref(), "freq_hz")?;
                let a = need(addr.as_ref(), "i2c_addr")?;
                Ok(Output::Pca9685 {
                    i2c_addr: u8::try_from(a).unwrap_or(u8::MAX),
                    freq_hz: u16::try_from(f).unwrap_or(u16::MAX),
                })
            }
            "maestro" => {
                unused(span(&freq), "freq_hz")?;
                unused(span(&addr), "i2c_addr")?;
                Ok(Output::Maestro {
                    baud: need(raw.baud.as_ref(), "baud")?,
                })
            }
            "dynamixel" => {
                unused(span(&freq), "freq_hz")?;
                unused(span(&addr), "i2c_addr")?;
                Ok(Output::Dynamixel {
                    baud: need(raw.baud.as_ref(), "baud")?,
                })
            }
            "feetech" => {
                unused(span(&freq), "freq_hz")?;
                unused(span(&addr), "i2c_addr")?;
                Ok(Output::Feetech {
                    baud: need(raw.baud.as_ref(), "baud")?,
                    series: self.series(raw.series.as_ref())?,
                })
            }
            other => Err(self.err(
                &raw.kind,
                "output.kind",
                format!(
                    "expected \"pwm\", \"pca9685\", \"maestro\", \"dynamixel\" or \"feetech\", \
                     found {other:?}"
                ),
            )),
        }
    }

    /// `output.series` of a Feetech output.
    fn series(&self, v: Option<&S<String>>) -> Result<FeetechSeries, RigFileError> {
        match v.map(|v| (v, v.get_ref().as_str())) {
            None | Some((_, "sts")) => Ok(FeetechSeries::Sts),
            Some((_, "scs")) => Ok(FeetechSeries::Scs),
            Some((v, other)) => Err(self.err(
                v,
                "output.series",
                format!("expected \"sts\" or \"scs\", found {other:?}"),
            )),
        }
    }

    /// `output.idle`.
    fn idle(&self, o: &S<RawOutput>) -> Result<Idle, RigFileError> {
        match o.get_ref().idle.as_ref().map(|v| (v, v.get_ref().as_str())) {
            None | Some((_, "hold")) => Ok(Idle::Hold),
            Some((_, "off")) => Ok(Idle::Off),
            Some((v, other)) => Err(self.err(
                v,
                "output.idle",
                format!("expected \"hold\" or \"off\", found {other:?}"),
            )),
        }
    }

    /// The position scale of a bus output (`units_per_degree` and the
    /// servo family's defaults); `None` for the pulse outputs, which take
    /// neither `units_per_degree` nor `series`.
    fn bus_scale(
        &self,
        o: &S<RawOutput>,
        output: &Output,
    ) -> Result<Option<BusScale>, RigFileError> {
        let raw = o.get_ref();
        if !output.is_bus() {
            let key = match (&raw.units_per_degree, &raw.series) {
                (Some(v), _) => Some((v.span(), "units_per_degree")),
                (None, Some(v)) => Some((v.span(), "series")),
                (None, None) => None,
            };
            return match key {
                Some((span, key)) => Err(self.src.err(
                    &span,
                    format!("output.{key}"),
                    format!("not used by output kind {:?}", raw.kind.get_ref()),
                )),
                None => Ok(None),
            };
        }
        if raw.series.is_some() && matches!(output, Output::Dynamixel { .. }) {
            let v = raw.series.as_ref().map(S::span).unwrap_or(0..0);
            return Err(self
                .src
                .err(&v, "output.series", "not used by output kind \"dynamixel\""));
        }
        let scs = matches!(
            output,
            Output::Feetech {
                series: FeetechSeries::Scs,
                ..
            }
        );
        let (per_degree, center, top) = if scs {
            (1024.0 / 300.0, 512.0, 1023.0)
        } else {
            (4096.0 / 360.0, 2048.0, 4095.0)
        };
        let per_degree = match &raw.units_per_degree {
            Some(v) if v.get_ref().is_finite() && *v.get_ref() > 0.0 => *v.get_ref(),
            Some(v) => {
                return Err(self.err(v, "output.units_per_degree", "must be a finite number > 0"));
            }
            None => per_degree,
        };
        Ok(Some(BusScale {
            per_rad: per_degree / DEG,
            center,
            limits: [1.0, top],
        }))
    }

    fn segment_desc(
        &mut self,
        i: usize,
        s: &S<RawSegment>,
        unit: f32,
    ) -> Result<SegmentDesc<'static>, RigFileError> {
        let raw = s.get_ref();
        let id = u8::try_from(i).unwrap_or(u8::MAX);
        let p = Place::Segment(id);
        let path = format!("segment[{i}]");
        self.spans.entry(p, s.span(), path.clone());
        self.spans.field(p, "name", &raw.name);
        self.spans.opt(p, "origin", &raw.origin);
        self.spans.opt(p, "touch", &raw.touch);
        self.spans.opt(p, "dofs", &raw.dofs);
        let parent = match (&raw.parent, i) {
            (None, 0) => NO_PARENT,
            (Some(v), 0) => {
                return Err(self.err(
                    v,
                    &format!("{path}.parent"),
                    "the first segment is the root and has no parent",
                ));
            }
            (None, _) => {
                return Err(self.src.err(
                    &s.span(),
                    format!("{path}.parent"),
                    "missing parent (only the first segment is the root)",
                ));
            }
            (Some(v), _) => {
                if *v.get_ref() == *raw.name.get_ref() {
                    return Err(self.err(
                        v,
                        &format!("{path}.parent"),
                        "a segment cannot be its own parent",
                    ));
                }
                self.segment(v, &format!("{path}.parent")).map_err(|_| {
                    self.err(
                        v,
                        &format!("{path}.parent"),
                        format!(
                            "unknown segment {:?} (parents must come before their children)",
                            v.get_ref()
                        ),
                    )
                })?
            }
        };
        if self.names.iter().any(|n| n == raw.name.get_ref()) {
            return Err(self.err(
                &raw.name,
                &format!("{path}.name"),
                format!("segment name {:?} is used twice", raw.name.get_ref()),
            ));
        }
        self.names.push(raw.name.get_ref().clone());
        let mut dofs = List::new();
        let no_dofs = Vec::new();
        let raw_dofs = raw.dofs.as_ref().map_or(&no_dofs, |d| d.get_ref());
        for (k, d) in raw_dofs.iter().enumerate() {
            let dp = Place::Dof {
                segment: id,
                dof: u8::try_from(k).unwrap_or(u8::MAX),
            };
            let dpath = format!("{path}.dofs[{k}]");
            self.spans.entry(dp, d.span(), dpath.clone());
            self.spans.field(dp, "axis", &d.get_ref().axis);
            let axis = self.axis(&d.get_ref().axis, &format!("{dpath}.axis"))?;
            let (span, [min, max]) = self.pair(
                &d.get_ref().limits,
                &d.get_ref().limits_deg,
                &d.span(),
                &dpath,
                "limits",
            )?;
            self.spans.field(dp, "limits", &span);
            if dofs.push(DofDesc { axis, min, max }).is_err() {
                return Err(self.err(d, &format!("{path}.dofs"), "at most 3 degrees of freedom"));
            }
        }
        let scaled = |v: &Option<S<[f32; 3]>>| {
            v.as_ref()
                .map_or([0.0; 3], |v| v.get_ref().map(|x| x * unit))
        };
        Ok(SegmentDesc {
            name: "",
            parent,
            origin: scaled(&raw.origin),
            touch: scaled(&raw.touch),
            dofs,
        })
    }

    fn servos(
        &mut self,
        raw: &[S<RawServo>],
        desc: &RigDesc<'_>,
    ) -> Result<List<ServoDesc, MAX_SERVOS>, RigFileError> {
        let mut out = List::new();
        for (i, s) in raw.iter().enumerate() {
            let v = s.get_ref();
            let p = Place::Servo(u8::try_from(i).unwrap_or(u8::MAX));
            let path = format!("servo[{i}]");
            self.spans.entry(p, s.span(), path.clone());
            self.spans.field(p, "channel", &v.channel);
            self.spans.field(p, "joint", &v.joint);
            self.spans.field(p, "axis", &v.axis);
            self.spans.opt(p, "pulse_us", &v.pulse_us);
            self.spans.opt(p, "trim_us", &v.trim_us);
            self.spans.opt(p, "rest_us", &v.rest_us);
            self.spans.opt(p, "pulse_us", &v.limits);
            self.spans.opt(p, "rest_us", &v.rest);
            self.spans.opt(p, "id", &v.id);
            self.spans.field(p, "max_speed", &v.max_speed);
            self.spans.field(p, "max_accel", &v.max_accel);
            let segment = self.segment(&v.joint, &format!("{path}.joint"))?;
            let seg = desc.segments.as_slice().get(usize::from(segment));
            let axis = self.axis(&v.axis, &format!("{path}.axis"))?;
            let dof_index = seg
                .and_then(|sd| sd.dofs.iter().position(|d| d.axis == axis))
                .ok_or_else(|| {
                    self.err(
                        &v.axis,
                        &format!("{path}.axis"),
                        format!(
                            "segment {:?} has no {:?} degree of freedom",
                            v.joint.get_ref(),
                            axis
                        ),
                    )
                })?;
            let (span, [angle_min, angle_max]) =
                self.pair(&v.angle, &v.angle_deg, &s.span(), &path, "angle")?;
            self.spans.field(p, "angle", &span);
            let rest_angle = seg
                .and_then(|sd| sd.dofs.as_slice().get(dof_index))
                .map_or(0.0, |d| 0f32.clamp(d.min.min(d.max), d.max.max(d.min)));
            let base = ServoDesc {
                channel: *v.channel.get_ref(),
                segment,
                dof: u8::try_from(dof_index).unwrap_or(u8::MAX),
                angle_min,
                angle_max,
                reversed: v.reversed.unwrap_or(false),
                max_speed: *v.max_speed.get_ref(),
                max_accel: *v.max_accel.get_ref(),
                ..ServoDesc::default()
            };
            let servo = match self.bus {
                None => self.pulse_servo(s, base, rest_angle, &path)?,
                Some(scale) => self.bus_servo(s, base, scale, rest_angle, &path)?,
            };
            if out.push(servo).is_err() {
                return Err(self.src.err(
                    &s.span(),
                    path,
                    format!("more than {} servos", MAX_SERVOS),
                ));
            }
        }
        Ok(out)
    }

    /// A key that the output kind does not use.
    fn unused_key<T>(&self, v: &Option<S<T>>, path: &str, key: &str) -> Result<(), RigFileError> {
        match v {
            Some(v) => Err(self.err(
                v,
                &format!("{path}.{key}"),
                if self.bus.is_some() {
                    "not used by a serial bus output (it takes id, center, limits, rest)"
                } else {
                    "only for a serial bus output (dynamixel, feetech)"
                },
            )),
            None => Ok(()),
        }
    }

    /// A pulse servo (PWM, PCA9685, Maestro): `pulse_us`, `trim_us`,
    /// `rest_us`.
    fn pulse_servo(
        &self,
        s: &S<RawServo>,
        mut servo: ServoDesc,
        rest_angle: f32,
        path: &str,
    ) -> Result<ServoDesc, RigFileError> {
        let v = s.get_ref();
        self.unused_key(&v.id, path, "id")?;
        self.unused_key(&v.center, path, "center")?;
        self.unused_key(&v.limits, path, "limits")?;
        self.unused_key(&v.rest, path, "rest")?;
        let Some(pulse) = &v.pulse_us else {
            return Err(self
                .src
                .err(&s.span(), format!("{path}.pulse_us"), "missing pulse_us"));
        };
        [servo.pulse_min_us, servo.pulse_max_us] = *pulse.get_ref();
        servo.trim_us = v.trim_us.as_ref().map_or(0.0, |t| *t.get_ref());
        servo.id = servo.channel;
        servo.rest_us = match &v.rest_us {
            Some(r) => *r.get_ref(),
            None => rest_pulse(&servo.calibration(), rest_angle),
        };
        Ok(servo)
    }

    /// A serial bus servo: `position = center ± angle · per_rad` (− when
    /// reversed), its angle range narrowed to where the positions stay
    /// within `limits`.
    fn bus_servo(
        &self,
        s: &S<RawServo>,
        mut servo: ServoDesc,
        scale: BusScale,
        rest_angle: f32,
        path: &str,
    ) -> Result<ServoDesc, RigFileError> {
        let v = s.get_ref();
        self.unused_key(&v.pulse_us, path, "pulse_us")?;
        self.unused_key(&v.trim_us, path, "trim_us")?;
        self.unused_key(&v.rest_us, path, "rest_us")?;
        let center = v.center.as_ref().map_or(scale.center, |c| *c.get_ref());
        let [a, b] = v.limits.as_ref().map_or(scale.limits, |l| *l.get_ref());
        let (lo, hi) = (a.min(b), a.max(b));
        let slope = if servo.reversed {
            -scale.per_rad
        } else {
            scale.per_rad
        };
        let position = |angle: f32| center + slope * angle;
        let angle_at = |p: f32| (p - center) / slope;
        let clamp = |angle: f32| angle_at(position(angle).clamp(lo, hi));
        let (a0, a1) = (clamp(servo.angle_min), clamp(servo.angle_max));
        if a0.partial_cmp(&a1) != Some(std::cmp::Ordering::Less) {
            let span = v.limits.as_ref().map_or(s.span(), S::span);
            return Err(self.src.err(
                &span,
                format!("{path}.limits"),
                format!(
                    "the angle range maps to positions {:.0} ..= {:.0}, outside the limits {lo} ..= {hi}",
                    position(servo.angle_min),
                    position(servo.angle_max)
                ),
            ));
        }
        servo.angle_min = a0;
        servo.angle_max = a1;
        servo.pulse_min_us = position(a0);
        servo.pulse_max_us = position(a1);
        servo.reversed = false;
        servo.id = v.id.as_ref().map_or(servo.channel, |i| *i.get_ref());
        servo.rest_us = match &v.rest {
            Some(r) => *r.get_ref(),
            None => position(rest_angle.clamp(a0, a1)),
        };
        Ok(servo)
    }

    fn params(&mut self, raw: &[S<RawParam>]) -> Result<List<ParamMap, MAX_PARAMS>, RigFileError> {
        let mut out = List::new();
        for (i, s) in raw.iter().enumerate() {
            let v = s.get_ref();
            let p = Place::Param(u8::try_from(i).unwrap_or(u8::MAX));
            let path = format!("param[{i}]");
            self.spans.entry(p, s.span(), path.clone());
            self.spans.field(p, "param", &v.param);
            self.spans.field(p, "sensor", &v.sensor);
            self.spans.opt(p, "frame", &v.frame);
            self.spans.opt(p, "center", &v.center);
            self.spans.opt(p, "offset", &v.offset);
            self.spans.opt(p, "scale", &v.scale);
            let frame = self.ref_frame(&v.frame, &path)?;
            let measure = self.measure(v, &s.span(), &path)?;
            let map = ParamMap {
                param: *v.param.get_ref(),
                sensor: *v.sensor.get_ref(),
                frame,
                measure,
                offset: v.offset.as_ref().map_or(0.0, |x| *x.get_ref()),
                scale: v.scale.as_ref().map_or(1.0, |x| *x.get_ref()),
            };
            if out.push(map).is_err() {
                return Err(self.src.err(
                    &s.span(),
                    path,
                    format!("more than {} parameter entries", MAX_PARAMS),
                ));
            }
        }
        Ok(out)
    }

    fn measure(
        &self,
        v: &RawParam,
        entry: &Range<usize>,
        path: &str,
    ) -> Result<Measure, RigFileError> {
        let need_axis = || {
            v.axis
                .as_ref()
                .ok_or_else(|| {
                    self.src.err(
                        entry,
                        format!("{path}.axis"),
                        format!("measure {:?} needs an axis", v.measure.get_ref()),
                    )
                })
                .and_then(|a| self.axis(a, &format!("{path}.axis")))
        };
        let need_component = || {
            v.component.as_ref().ok_or_else(|| {
                self.src.err(
                    entry,
                    format!("{path}.component"),
                    format!("measure {:?} needs a component", v.measure.get_ref()),
                )
            })
        };
        let reject = |present: bool, key: &str| {
            if present {
                Err(self.src.err(
                    entry,
                    format!("{path}.{key}"),
                    format!("not used by measure {:?}", v.measure.get_ref()),
                ))
            } else {
                Ok(())
            }
        };
        match v.measure.get_ref().as_str() {
            "position" => {
                reject(v.axis.is_some(), "axis")?;
                reject(v.center.is_some(), "center")?;
                let c = need_component()?;
                Ok(Measure::Position(
                    self.axis(c, &format!("{path}.component"))?,
                ))
            }
            "cylindrical" => {
                let axis = need_axis()?;
                let c = need_component()?;
                let component = match c.get_ref().as_str() {
                    "radius" => Cylinder::Radius,
                    "angle" => Cylinder::Angle,
                    "height" => Cylinder::Height,
                    other => {
                        return Err(self.err(
                            c,
                            &format!("{path}.component"),
                            format!(
                                "expected \"radius\", \"angle\" or \"height\", found {other:?}"
                            ),
                        ));
                    }
                };
                let center = v.center.as_ref().map_or([0.0; 3], |c| *c.get_ref());
                Ok(Measure::Cylindrical {
                    axis,
                    center,
                    component,
                })
            }
            "rotation" => {
                reject(v.component.is_some(), "component")?;
                reject(v.center.is_some(), "center")?;
                Ok(Measure::Rotation(need_axis()?))
            }
            other => Err(self.err(
                &v.measure,
                &format!("{path}.measure"),
                format!("expected \"position\", \"cylindrical\" or \"rotation\", found {other:?}"),
            )),
        }
    }

    fn goals(&mut self, raw: &[S<RawGoal>]) -> Result<List<GoalMap, MAX_GOALS>, RigFileError> {
        let mut out = List::new();
        for (i, s) in raw.iter().enumerate() {
            let v = s.get_ref();
            let p = Place::Goal(u8::try_from(i).unwrap_or(u8::MAX));
            let path = format!("goal[{i}]");
            self.spans.entry(p, s.span(), path.clone());
            self.spans.field(p, "segment", &v.segment);
            self.spans.field(p, "weight", &v.weight);
            self.spans.opt(p, "point", &v.point);
            self.spans.opt(p, "target_frame", &v.target_frame);
            self.spans.opt(p, "sensor", &v.sensor);
            self.spans.opt(p, "frame", &v.frame);
            self.spans.opt(p, "offset", &v.offset);
            self.spans.opt(p, "scale", &v.scale);
            self.spans
                .opt(p, "orientation_weight", &v.orientation_weight);
            self.spans.opt(p, "rotation_offset", &v.rotation_offset);
            self.spans.opt(p, "target", &v.target);
            let segment = self.segment(&v.segment, &format!("{path}.segment"))?;
            let frame = match &v.target_frame {
                None => None,
                Some(f) if f.get_ref() == "world" => None,
                Some(f) => Some(self.segment(f, &format!("{path}.target_frame"))?),
            };
            let target = self.goal_source(p, v, &s.span(), &path)?;
            let map = GoalMap {
                segment,
                point: v.point.as_ref().map(|x| *x.get_ref()),
                weight: *v.weight.get_ref(),
                frame,
                target,
            };
            if out.push(map).is_err() {
                return Err(self.src.err(
                    &s.span(),
                    path,
                    format!("more than {} goal entries", MAX_GOALS),
                ));
            }
        }
        Ok(out)
    }

    fn goal_source(
        &mut self,
        place: Place,
        v: &RawGoal,
        entry: &Range<usize>,
        path: &str,
    ) -> Result<GoalSource, RigFileError> {
        let sensor_keys = v.frame.is_some()
            || v.offset.is_some()
            || v.scale.is_some()
            || v.orientation_weight.is_some()
            || v.rotation_offset.is_some();
        match (&v.sensor, &v.plane, &v.target) {
            (Some(sensor), None, None) => Ok(GoalSource::Sensor(SensorGoal {
                sensor: *sensor.get_ref(),
                source: self.ref_frame(&v.frame, path)?,
                offset: v.offset.as_ref().map_or([0.0; 3], |x| *x.get_ref()),
                scale: v.scale.as_ref().map_or(1.0, |x| *x.get_ref()),
                orientation_weight: v.orientation_weight.as_ref().map_or(0.0, |x| *x.get_ref()),
                rotation_offset: v.rotation_offset.as_ref().map_or([1.0, 0.0, 0.0, 0.0], |x| *x.get_ref()),
            })),
            (None, Some(plane), None) if !sensor_keys => {
                let pl = plane.get_ref();
                self.spans.field(place, "normal", &pl.normal);
                self.spans.opt(place, "offset", &pl.offset);
                let above = match pl.side.as_ref().map(|s| (s, s.get_ref().as_str())) {
                    None | Some((_, "contact")) => false,
                    Some((_, "above")) => true,
                    Some((s, other)) => return Err(self.err(s, &format!("{path}.plane.side"), format!("expected \"contact\" or \"above\", found {other:?}"))),
                };
                Ok(GoalSource::Plane { normal: *pl.normal.get_ref(), offset: pl.offset.as_ref().map_or(0.0, |o| *o.get_ref()), above })
            }
            (None, None, Some(t)) if !sensor_keys => Ok(GoalSource::Point(*t.get_ref())),
            (None, None, None) => Err(self.src.err(entry, path.to_string(), "needs one of sensor, plane or target")),
            _ if sensor_keys && v.sensor.is_none() => Err(self.src.err(entry, path.to_string(), "frame, offset, scale, orientation_weight and rotation_offset only apply to a sensor goal")),
            _ => Err(self.src.err(entry, path.to_string(), "give only one of sensor, plane or target")),
        }
    }

    fn retarget(&self, raw: Option<&S<RawRetarget>>) -> Result<Vec<RetargetJoint>, RigFileError> {
        let Some(raw) = raw else {
            return Ok(Vec::new());
        };
        let r = raw.get_ref();
        let mut out: Vec<RetargetJoint> = Vec::new();
        if r.identity {
            for (i, n) in self.names.iter().enumerate() {
                out.push(RetargetJoint {
                    mocap: n.clone(),
                    segment: u8::try_from(i).unwrap_or(u8::MAX),
                    rotation_offset: [1.0, 0.0, 0.0, 0.0],
                });
            }
        }
        self.retarget_joints(&r.joint, "retarget.joint", out)
    }

    /// The `[live]` table: unique non-empty names and sensor ids; OSC
    /// addresses unique and starting with '/'; parameters `0..k` each once,
    /// with finite scale and offset.
    fn live(&self, raw: Option<&S<RawLive>>) -> Result<LiveMap, RigFileError> {
        let Some(raw) = raw else {
            return Ok(LiveMap::default());
        };
        let mut map = LiveMap::default();
        for (i, v) in raw.get_ref().sensor.iter().enumerate() {
            let v = v.get_ref();
            let path = format!("live.sensor[{i}]");
            let name = v.name.get_ref();
            if name.is_empty() || map.sensors.iter().any(|s| &s.name == name) {
                let why = format!("{name:?} is empty or named twice");
                return Err(self.err(&v.name, &format!("{path}.name"), why));
            }
            let id = *v.sensor.get_ref();
            if usize::from(id) >= marionette_core::wire::MAX_SENSORS
                || map.sensors.iter().any(|s| s.sensor == id)
            {
                let why = format!("{id} is out of range (0 ..= 15) or used twice");
                return Err(self.err(&v.sensor, &format!("{path}.sensor"), why));
            }
            map.sensors.push(LiveSensor {
                name: name.clone(),
                sensor: id,
            });
        }
        for (i, v) in raw.get_ref().param.iter().enumerate() {
            let v = v.get_ref();
            let path = format!("live.param[{i}]");
            let address = v.address.get_ref();
            if !address.starts_with('/') || map.params.iter().any(|p| &p.address == address) {
                let why = format!("{address:?} does not start with '/' or is used twice");
                return Err(self.err(&v.address, &format!("{path}.address"), why));
            }
            let param = *v.param.get_ref();
            if usize::from(param) >= MAX_PARAMS || map.params.iter().any(|p| p.param == param) {
                let why = format!(
                    "{param} is out of range (0 ..= {}) or used twice",
                    MAX_PARAMS - 1
                );
                return Err(self.err(&v.param, &format!("{path}.param"), why));
            }
            let number = |f: &Option<S<f32>>, key: &str, default: f32| match f {
                Some(x) if x.get_ref().is_finite() => Ok(*x.get_ref()),
                Some(x) => Err(self.err(x, &format!("{path}.{key}"), "must be finite")),
                None => Ok(default),
            };
            map.params.push(LiveParam {
                address: address.clone(),
                param,
                scale: number(&v.scale, "scale", 1.0)?,
                offset: number(&v.offset, "offset", 0.0)?,
            });
        }
        map.params.sort_by_key(|p| p.param);
        if let Some(k) = map
            .params
            .iter()
            .enumerate()
            .position(|(i, p)| usize::from(p.param) != i)
        {
            return Err(self.src.err(
                &raw.span(),
                "live.param",
                format!(
                    "the entries must cover params 0 ..= {} (Params overrides them in order): \
                     param {k} is missing",
                    map.params.len() - 1
                ),
            ));
        }
        Ok(map)
    }

    /// The named maps (`[[retarget.map]]`): unique, non-empty names.
    fn retarget_maps(
        &self,
        raw: Option<&S<RawRetarget>>,
    ) -> Result<Vec<RetargetMap>, RigFileError> {
        let Some(raw) = raw else {
            return Ok(Vec::new());
        };
        let mut maps: Vec<RetargetMap> = Vec::new();
        for (i, m) in raw.get_ref().map.iter().enumerate() {
            let v = m.get_ref();
            let path = format!("retarget.map[{i}]");
            let name = v.name.get_ref().trim();
            if name.is_empty() {
                return Err(self.err(&v.name, &format!("{path}.name"), "must not be empty"));
            }
            if maps.iter().any(|m| m.name == name) {
                return Err(self.err(
                    &v.name,
                    &format!("{path}.name"),
                    format!("{name:?} is used twice"),
                ));
            }
            let joints = self.retarget_joints(&v.joint, &format!("{path}.joint"), Vec::new())?;
            maps.push(RetargetMap {
                name: name.to_owned(),
                joints,
            });
        }
        Ok(maps)
    }

    /// Entries of one map (`path` names them in errors), added to `out`; a
    /// later entry for the same segment replaces an earlier one.
    fn retarget_joints(
        &self,
        raw: &[S<RawRetargetJoint>],
        path: &str,
        mut out: Vec<RetargetJoint>,
    ) -> Result<Vec<RetargetJoint>, RigFileError> {
        for (i, j) in raw.iter().enumerate() {
            let v = j.get_ref();
            let path = format!("{path}[{i}]");
            let segment = self.segment(&v.segment, &format!("{path}.segment"))?;
            let rotation_offset = match &v.rotation_offset {
                None => [1.0, 0.0, 0.0, 0.0],
                Some(q) => {
                    let a = *q.get_ref();
                    let n2: f64 = a.iter().map(|x| x * x).sum();
                    if !n2.is_finite() || (n2 - 1.0).abs() > 1e-3 {
                        return Err(self.err(
                            q,
                            &format!("{path}.rotation_offset"),
                            "must be a finite unit quaternion [w, x, y, z]",
                        ));
                    }
                    a
                }
            };
            if v.mocap.get_ref().is_empty() {
                return Err(self.err(&v.mocap, &format!("{path}.mocap"), "must not be empty"));
            }
            let entry = RetargetJoint {
                mocap: v.mocap.get_ref().clone(),
                segment,
                rotation_offset,
            };
            match out.iter_mut().find(|e| e.segment == segment) {
                Some(e) => *e = entry,
                None => out.push(entry),
            }
        }
        Ok(out)
    }
}

/// The pulse of a joint angle without trim clamping surprises: the
/// calibration's own mapping.
fn rest_pulse(cal: &Calibration, angle: f32) -> f32 {
    cal.pulse_us(angle)
}
