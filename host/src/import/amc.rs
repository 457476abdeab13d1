//! Acclaim ASF (skeleton) and AMC (motion) import, as written by VICON
//! BodyBuilder for HDM05 and the CMU database.
//!
//! # ASF
//!
//! `#` starts a comment; commas and parentheses are whitespace. Sections:
//! `:version`, `:name` (ignored), `:units` (`mass`, `length`, `angle
//! deg|rad`), `:documentation` (skipped up to the next `:` keyword), `:root`
//! (`order`, `axis`, `position`, `orientation`), `:bonedata` (`begin` ... `end`
//! blocks with `id`, `name`, `direction`, `length`, `axis x y z ORDER`, `dof`,
//! `limits`; `bodymass`/`cofmass` are ignored) and `:hierarchy` (`begin`,
//! lines `parent child...`, `end`). Other `:` sections are skipped.
//!
//! **Units.** The Acclaim spec says `length 2.54` means "data in cm, local
//! units in inches": file values divided by `length` are inches. So metres =
//! value × 0.0254 / `length`; for HDM05 and CMU (`length 0.45`) that is
//! [`CMU_UNIT_METRES`](super::CMU_UNIT_METRES) = 0.056444… m, the DESIGN §4
//! factor. [`parse_asf`] uses this unless the caller gives a scale.
//! `angle deg|rad` applies to `axis`, `orientation` and `limits`; AMC angles
//! follow the AMC's own `:DEGREES`/`:RADIANS` header, else the ASF's unit.
//!
//! # Forward kinematics (the standard ASF/AMC semantics)
//!
//! All directions and axes are in the **global** frame of the rest pose.
//! Each bone `b` has an axis frame `C_b`, the rotation given by `axis ax ay az
//! ORDER`, composed about fixed axes in the order of `ORDER` (for `XYZ`,
//! `C = Rz(az)·Ry(ay)·Rx(ax)`). Its AMC values give `M_b`, rotations about
//! the fixed axes of the bone's frame in the order the `dof` line lists them
//! (for `dof rx ry rz`, `M = Rz·Ry·Rx`). Then
//!
//! * the bone's rotation relative to its parent is `L_b = C_b · M_b · C_b⁻¹`,
//! * its world rotation is `W_b = W_parent · L_b` (`W_root` below),
//! * its tip is `tip_b = tip_parent + W_b · (direction_b × length_b)`, where
//!   `tip_root` is the root position; so in the rest pose (all dofs zero)
//!   tips are simply the sums of `direction × length` along the chain.
//!
//! The root's AMC values follow `:root order` (e.g. `TX TY TZ RX RY RZ`):
//! translation `T` and rotations about the fixed global axes in the listed
//! order, giving `M_root`. With the pre-set `position P` and `orientation O`
//! (composed in `:root axis` order) the root is at `P + T` with world
//! rotation `O · M_root`. (VICON always writes `P = O = 0`, so this part of
//! the convention is not exercised by real data.)
//!
//! **As a [`Motion`].** Joint 0 is the root. Each bone becomes a joint whose
//! origin is the bone's *start* (its parent's tip): its offset is the
//! parent bone's `direction × length` (zero for bones attached to the root)
//! and its rotation is `L_b`. Each leaf bone gets an extra end-site joint
//! `<bone>.end` at its tip. Bones are ordered depth-first from the root,
//! children in `:hierarchy` order. Every segment's rest frame is the world
//! frame, so rotations are "rotation away from the ASF rest pose".
//!
//! **Not supported** (rejected with a line number): translation or `l`
//! (length) dofs on bones. AMC files must be fully specified: every bone with
//! dofs appears exactly once per frame, frames numbered consecutively.

use std::io::BufRead;
use std::path::Path;

use glam::{DQuat, DVec3};

use super::{
    Axis, Frame, ImportError, Joint, Lines, MAX_JOINTS, Motion, check_scale, finite, number_error,
    parse_f64,
};

/// HDM05 and CMU AMC files are sampled at 120 frames per second; AMC files
/// do not say so themselves.
pub const HDM05_FRAME_TIME: f64 = 1.0 / 120.0;

/// The angle unit of an ASF or AMC file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AngleUnit {
    /// Degrees.
    Degrees,
    /// Radians.
    Radians,
}

impl AngleUnit {
    fn to_radians(self, value: f64) -> f64 {
        match self {
            Self::Degrees => value.to_radians(),
            Self::Radians => value,
        }
    }
}

/// A degree of freedom of the root or a bone.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dof {
    /// Translation along X (root only).
    Tx,
    /// Translation along Y (root only).
    Ty,
    /// Translation along Z (root only).
    Tz,
    /// Rotation about X.
    Rx,
    /// Rotation about Y.
    Ry,
    /// Rotation about Z.
    Rz,
}

impl Dof {
    fn from_token(token: &str) -> Option<Self> {
        Some(match token.to_ascii_lowercase().as_str() {
            "tx" => Self::Tx,
            "ty" => Self::Ty,
            "tz" => Self::Tz,
            "rx" => Self::Rx,
            "ry" => Self::Ry,
            "rz" => Self::Rz,
            _ => return None,
        })
    }

    /// The rotation axis of a rotation dof.
    #[must_use]
    pub fn rotation_axis(self) -> Option<Axis> {
        match self {
            Self::Rx => Some(Axis::X),
            Self::Ry => Some(Axis::Y),
            Self::Rz => Some(Axis::Z),
            _ => None,
        }
    }

    fn translation_index(self) -> Option<usize> {
        match self {
            Self::Tx => Some(0),
            Self::Ty => Some(1),
            Self::Tz => Some(2),
            _ => None,
        }
    }
}

/// `:units` of an ASF file.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Units {
    /// `mass` multiplier (unused).
    pub mass: f64,
    /// `length` multiplier: file values / `length` = inches.
    pub length: f64,
    /// `angle` unit.
    pub angle: AngleUnit,
}

/// `:root` of an ASF file, converted to metres and radians.
#[derive(Clone, Debug, PartialEq)]
pub struct Root {
    /// `order`: the root's AMC values, in file order.
    pub order: Vec<Dof>,
    /// `axis`: composition order of `orientation`.
    pub axis: [Axis; 3],
    /// `position`, metres.
    pub position: DVec3,
    /// `orientation` angles about X, Y, Z, radians.
    pub orientation: DVec3,
}

/// One `:bonedata` block, converted to metres and radians.
#[derive(Clone, Debug, PartialEq)]
pub struct Bone {
    /// `id`, if given.
    pub id: Option<i64>,
    /// `name`.
    pub name: String,
    /// `direction`, normalised, global rest frame.
    pub direction: DVec3,
    /// `length`, metres.
    pub length: f64,
    /// `axis` angles about X, Y, Z, radians.
    pub axis: DVec3,
    /// `axis` composition order.
    pub axis_order: [Axis; 3],
    /// `dof`, in AMC order (rotations only).
    pub dofs: Vec<Dof>,
    /// `limits`, one `(min, max)` per dof, radians (may be infinite).
    pub limits: Vec<(f64, f64)>,
    /// Parent bone index, `None` when attached to the root.
    pub parent: Option<usize>,
    /// Line of the bone's `begin`.
    pub line: usize,
}

impl Bone {
    /// The axis frame `C`.
    #[must_use]
    pub fn axis_frame(&self) -> DQuat {
        euler_fixed(self.axis_order, self.axis)
    }

    /// The rest-pose vector from the bone's start to its tip, metres.
    #[must_use]
    pub fn vector(&self) -> DVec3 {
        self.direction * self.length
    }
}

/// A parsed ASF skeleton.
#[derive(Clone, Debug, PartialEq)]
pub struct Asf {
    /// File name.
    pub source: String,
    /// `:units`.
    pub units: Units,
    /// Metres per file length unit actually applied.
    pub scale: f64,
    /// `:root`.
    pub root: Root,
    /// Bones in `:bonedata` order.
    pub bones: Vec<Bone>,
    /// Bone indices depth-first from the root (children in `:hierarchy` order).
    pub depth_first: Vec<usize>,
}

/// `R_axes[2](angles[axes[2]]) · R_axes[1](..) · R_axes[0](..)`: rotations
/// about fixed axes, `axes[0]` applied first.
fn euler_fixed(axes: [Axis; 3], angles: DVec3) -> DQuat {
    axes.iter().fold(DQuat::IDENTITY, |q, &axis| {
        axis.rotation(component(angles, axis)) * q
    })
}

fn component(v: DVec3, axis: Axis) -> f64 {
    match axis {
        Axis::X => v.x,
        Axis::Y => v.y,
        Axis::Z => v.z,
    }
}

/// Reads an ASF file from disk (see [`parse_asf`]).
///
/// # Errors
/// As [`parse_asf`], plus [`ImportError::Io`].
pub fn read_asf(path: &Path, scale: Option<f64>) -> Result<Asf, ImportError> {
    parse_asf(super::open(path)?, &path.display().to_string(), scale)
}

/// Reads an ASF and an AMC file into the common [`Motion`]; `frame_time`
/// in seconds (AMC files do not state it; HDM05: [`HDM05_FRAME_TIME`]).
///
/// # Errors
/// As [`read_asf`], [`parse_amc`] and [`Asf::to_motion`].
pub fn read_motion(asf: &Path, amc: &Path, frame_time: f64) -> Result<Motion, ImportError> {
    let skeleton = read_asf(asf, None)?;
    let motion = parse_amc(super::open(amc)?, &amc.display().to_string(), &skeleton)?;
    skeleton.to_motion(&motion, frame_time)
}

/// Splits an ASF line into tokens: `#` comments removed, commas and
/// parentheses treated as whitespace.
fn asf_tokens(line: &str) -> Vec<&str> {
    let code = line.split('#').next().unwrap_or("");
    code.split(|c: char| c.is_ascii_whitespace() || c == ',' || c == '(' || c == ')')
        .filter(|t| !t.is_empty())
        .collect()
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Section {
    Start,
    Units,
    Skip,
    Root,
    BoneData,
    Hierarchy,
}

/// A bone while its block is being read (file units).
#[derive(Default)]
struct RawBone {
    line: usize,
    id: Option<i64>,
    name: Option<String>,
    direction: Option<DVec3>,
    length: Option<f64>,
    axis: Option<(DVec3, [Axis; 3])>,
    dofs: Vec<Dof>,
    limits: Vec<(f64, f64)>,
}

struct AsfParser<R> {
    lines: Lines<R>,
    section: Section,
    units: Units,
    saw_length_unit: bool,
    root: Root,
    bones: Vec<(RawBone, Option<Option<usize>>)>,
    open: Option<RawBone>,
    hierarchy_open: bool,
    hierarchy_done: bool,
}

/// Parses an ASF skeleton; `file` names it in errors. `scale` is metres per
/// file length unit; `None` uses 0.0254 / `:units length` (see module docs).
///
/// # Errors
/// Any [`ImportError`] describing the first problem, with its line.
pub fn parse_asf<R: BufRead>(
    reader: R,
    file: &str,
    scale: Option<f64>,
) -> Result<Asf, ImportError> {
    let mut p = AsfParser {
        lines: Lines::new(reader, file),
        section: Section::Start,
        units: Units {
            mass: 1.0,
            length: 1.0,
            angle: AngleUnit::Degrees,
        },
        saw_length_unit: false,
        root: Root {
            order: Vec::new(),
            axis: [Axis::X, Axis::Y, Axis::Z],
            position: DVec3::ZERO,
            orientation: DVec3::ZERO,
        },
        bones: Vec::new(),
        open: None,
        hierarchy_open: false,
        hierarchy_done: false,
    };
    while p.lines.advance()? {
        let tokens: Vec<String> = asf_tokens(p.lines.text())
            .into_iter()
            .map(str::to_owned)
            .collect();
        p.line(&tokens)?;
    }
    p.finish(scale)
}

impl<R: BufRead> AsfParser<R> {
    fn line(&mut self, tokens: &[String]) -> Result<(), ImportError> {
        let Some((first, rest)) = tokens.split_first() else {
            return Ok(());
        };
        if first.starts_with(':') {
            return self.keyword(first);
        }
        match self.section {
            Section::Skip => Ok(()),
            Section::Start => Err(self.lines.syntax("ASF", "a \":\" keyword", Some(first))),
            Section::Units => self.units_line(first, rest),
            Section::Root => self.root_line(first, rest),
            Section::BoneData => self.bone_line(first, rest),
            Section::Hierarchy => self.hierarchy_line(first, rest),
        }
    }

    fn keyword(&mut self, keyword: &str) -> Result<(), ImportError> {
        if let Some(bone) = &self.open {
            let problem = format!("bone block opened on line {} has no \"end\"", bone.line);
            return Err(self.lines.invalid(":bonedata", problem));
        }
        if self.hierarchy_open {
            return Err(self
                .lines
                .invalid(":hierarchy", "\"begin\" without \"end\""));
        }
        self.section = match keyword.to_ascii_lowercase().as_str() {
            ":units" => Section::Units,
            ":root" => Section::Root,
            ":bonedata" => Section::BoneData,
            ":hierarchy" => Section::Hierarchy,
            _ => Section::Skip,
        };
        Ok(())
    }

    fn number(&self, tokens: &[String], index: usize, field: &str) -> Result<f64, ImportError> {
        let token = tokens
            .get(index)
            .ok_or_else(|| self.lines.syntax(field, "a number", None))?;
        self.lines.number_f64(token, field)
    }

    fn vector(&self, tokens: &[String], field: &str) -> Result<DVec3, ImportError> {
        let x = self.number(tokens, 0, &format!("{field} x"))?;
        let y = self.number(tokens, 1, &format!("{field} y"))?;
        let z = self.number(tokens, 2, &format!("{field} z"))?;
        self.no_more(tokens, 3, field)?;
        Ok(DVec3::new(x, y, z))
    }

    fn no_more(&self, tokens: &[String], count: usize, field: &str) -> Result<(), ImportError> {
        match tokens.get(count) {
            None => Ok(()),
            Some(extra) => Err(self.lines.syntax(field, "end of line", Some(extra))),
        }
    }

    fn units_line(&mut self, key: &str, rest: &[String]) -> Result<(), ImportError> {
        match key {
            "mass" => self.units.mass = self.number(rest, 0, "units mass")?,
            "length" => {
                let length = self.number(rest, 0, "units length")?;
                if length <= 0.0 {
                    return Err(self
                        .lines
                        .invalid("units length", format!("must be positive, got {length}")));
                }
                self.units.length = length;
                self.saw_length_unit = true;
            }
            "angle" => {
                self.units.angle = match rest.first().map(|t| t.to_ascii_lowercase()).as_deref() {
                    Some("deg") => AngleUnit::Degrees,
                    Some("rad") => AngleUnit::Radians,
                    _ => {
                        return Err(self.lines.syntax(
                            "units angle",
                            "\"deg\" or \"rad\"",
                            rest.first().map(String::as_str),
                        ));
                    }
                }
            }
            _ => {
                return Err(self
                    .lines
                    .syntax(":units", "mass, length or angle", Some(key)));
            }
        }
        Ok(())
    }

    fn root_line(&mut self, key: &str, rest: &[String]) -> Result<(), ImportError> {
        match key {
            "order" => self.root.order = self.dof_list(rest, "root order", true)?,
            "axis" => {
                self.root.axis = self.axis_order(rest.first().map(String::as_str), "root axis")?
            }
            "position" => self.root.position = self.vector(rest, "root position")?,
            "orientation" => self.root.orientation = self.vector(rest, "root orientation")?,
            _ => {
                return Err(self.lines.syntax(
                    ":root",
                    "order, axis, position or orientation",
                    Some(key),
                ));
            }
        }
        Ok(())
    }

    fn dof_list(
        &self,
        tokens: &[String],
        field: &str,
        translations: bool,
    ) -> Result<Vec<Dof>, ImportError> {
        let mut dofs = Vec::with_capacity(tokens.len());
        for token in tokens {
            let dof = Dof::from_token(token).ok_or_else(|| {
                self.lines
                    .syntax(field, "tx, ty, tz, rx, ry or rz", Some(token))
            })?;
            if !translations && dof.rotation_axis().is_none() {
                let problem =
                    format!("{token}: translation and length dofs on bones are not supported");
                return Err(self.lines.invalid(field, problem));
            }
            if dofs.contains(&dof) {
                return Err(self.lines.invalid(field, format!("{token} listed twice")));
            }
            dofs.push(dof);
        }
        Ok(dofs)
    }

    fn axis_order(&self, token: Option<&str>, field: &str) -> Result<[Axis; 3], ImportError> {
        let expected = "a rotation order such as XYZ";
        let bad = || self.lines.syntax(field, expected, token);
        let text = token.ok_or_else(bad)?.to_ascii_uppercase();
        let mut axes = [Axis::X; 3];
        let mut chars = text.chars();
        for slot in &mut axes {
            *slot = match chars.next() {
                Some('X') => Axis::X,
                Some('Y') => Axis::Y,
                Some('Z') => Axis::Z,
                _ => return Err(bad()),
            };
        }
        let distinct = axes[0] != axes[1] && axes[1] != axes[2] && axes[0] != axes[2];
        if chars.next().is_some() || !distinct {
            return Err(bad());
        }
        Ok(axes)
    }

    fn bone_line(&mut self, key: &str, rest: &[String]) -> Result<(), ImportError> {
        if key == "begin" {
            if self.open.is_some() {
                return Err(self.lines.syntax(
                    ":bonedata",
                    "\"end\" before the next \"begin\"",
                    Some(key),
                ));
            }
            if self.bones.len() >= MAX_JOINTS / 2 {
                return Err(self.lines.too_many("bones", MAX_JOINTS / 2));
            }
            self.open = Some(RawBone {
                line: self.lines.number(),
                ..RawBone::default()
            });
            return Ok(());
        }
        if key == "end" {
            let bone = self
                .open
                .take()
                .ok_or_else(|| self.lines.syntax(":bonedata", "\"begin\"", Some(key)))?;
            return self.close_bone(bone);
        }
        let Some(mut bone) = self.open.take() else {
            return Err(self.lines.syntax(":bonedata", "\"begin\"", Some(key)));
        };
        let result = self.bone_field(&mut bone, key, rest);
        self.open = Some(bone);
        result
    }

    fn bone_field(
        &self,
        bone: &mut RawBone,
        key: &str,
        rest: &[String],
    ) -> Result<(), ImportError> {
        match key {
            "id" => {
                let token = rest.first().map(String::as_str);
                bone.id = Some(
                    token
                        .and_then(|t| t.parse().ok())
                        .ok_or_else(|| self.lines.syntax("bone id", "an integer", token))?,
                );
            }
            "name" => {
                let name = rest
                    .first()
                    .ok_or_else(|| self.lines.syntax("bone name", "a name", None))?;
                bone.name = Some(name.clone());
            }
            "direction" => bone.direction = Some(self.vector(rest, "bone direction")?),
            "length" => {
                let length = self.number(rest, 0, "bone length")?;
                if length < 0.0 {
                    return Err(self
                        .lines
                        .invalid("bone length", format!("must not be negative, got {length}")));
                }
                bone.length = Some(length);
            }
            "axis" => {
                let angles = self.vector(rest.get(..3).unwrap_or(rest), "bone axis")?;
                let order = self.axis_order(rest.get(3).map(String::as_str), "bone axis order")?;
                self.no_more(rest, 4, "bone axis")?;
                bone.axis = Some((angles, order));
            }
            "dof" => bone.dofs = self.dof_list(rest, "bone dof", false)?,
            "limits" => self.limits(bone, rest)?,
            "bodymass" | "cofmass" => {}
            _ if !bone.limits.is_empty() && bone.limits.len() < bone.dofs.len() => {
                let mut pairs = vec![key.to_owned()];
                pairs.extend_from_slice(rest);
                self.limits(bone, &pairs)?;
            }
            _ => {
                return Err(self.lines.syntax(
                    "bone",
                    "id, name, direction, length, axis, dof, limits or end",
                    Some(key),
                ));
            }
        }
        Ok(())
    }

    /// Limit pairs: the first on the `limits` line, the rest on the lines after.
    fn limits(&self, bone: &mut RawBone, tokens: &[String]) -> Result<(), ImportError> {
        for pair in tokens.chunks(2) {
            let index = bone.limits.len().saturating_add(1);
            let field = format!("bone limits pair {index}");
            let (Some(lo), Some(hi)) = (pair.first(), pair.get(1)) else {
                return Err(self.lines.syntax(&field, "(min max)", None));
            };
            let lo = limit_value(self.lines.file(), self.lines.number(), lo, &field)?;
            let hi = limit_value(self.lines.file(), self.lines.number(), hi, &field)?;
            if bone.limits.len() >= bone.dofs.len() {
                return Err(self.lines.invalid(
                    &field,
                    format!("more limit pairs than the {} dofs", bone.dofs.len()),
                ));
            }
            bone.limits.push((lo, hi));
        }
        Ok(())
    }

    fn close_bone(&mut self, bone: RawBone) -> Result<(), ImportError> {
        let missing = |what: &str| {
            self.lines.invalid(
                "bone",
                format!("block from line {} has no {what}", bone.line),
            )
        };
        let name = bone.name.clone().ok_or_else(|| missing("name"))?;
        if bone.direction.is_none() {
            return Err(missing("direction"));
        }
        if bone.length.is_none() {
            return Err(missing("length"));
        }
        if name.eq_ignore_ascii_case("root")
            || self
                .bones
                .iter()
                .any(|(b, _)| b.name.as_deref() == Some(name.as_str()))
        {
            return Err(self
                .lines
                .invalid("bone name", format!("duplicate bone {name:?}")));
        }
        if !bone.limits.is_empty() && bone.limits.len() != bone.dofs.len() {
            let problem = format!(
                "{} limit pairs for {} dofs",
                bone.limits.len(),
                bone.dofs.len()
            );
            return Err(self.lines.invalid(&format!("bone {name} limits"), problem));
        }
        self.bones.push((bone, None));
        Ok(())
    }

    fn bone_index(&self, name: &str) -> Option<usize> {
        self.bones
            .iter()
            .position(|(b, _)| b.name.as_deref() == Some(name))
    }

    fn hierarchy_line(&mut self, key: &str, rest: &[String]) -> Result<(), ImportError> {
        match (key, self.hierarchy_open) {
            ("begin", false) if !self.hierarchy_done => {
                self.hierarchy_open = true;
                return Ok(());
            }
            ("end", true) => {
                self.hierarchy_open = false;
                self.hierarchy_done = true;
                return Ok(());
            }
            (_, false) => return Err(self.lines.syntax(":hierarchy", "\"begin\"", Some(key))),
            _ => {}
        }
        let parent = if key.eq_ignore_ascii_case("root") {
            None
        } else {
            let index = self.bone_index(key);
            Some(index.ok_or_else(|| {
                self.lines
                    .invalid(":hierarchy parent", format!("unknown bone {key:?}"))
            })?)
        };
        for child in rest {
            let index = self.bone_index(child);
            let index = index.ok_or_else(|| {
                self.lines
                    .invalid(":hierarchy child", format!("unknown bone {child:?}"))
            })?;
            let slot = self.bones.get_mut(index).map(|(_, p)| p);
            match slot {
                Some(p @ None) => *p = Some(parent),
                _ => {
                    return Err(self.lines.invalid(
                        ":hierarchy child",
                        format!("bone {child:?} already has a parent"),
                    ));
                }
            }
        }
        Ok(())
    }

    fn finish(self, scale: Option<f64>) -> Result<Asf, ImportError> {
        let file = self.lines.file().to_owned();
        if self.open.is_some() {
            return Err(self.lines.eof("\"end\" of the open bone block"));
        }
        if self.hierarchy_open {
            return Err(self.lines.eof("\"end\" of :hierarchy"));
        }
        if self.root.order.is_empty() {
            return Err(self.lines.eof(":root with an \"order\" line"));
        }
        let scale = scale.unwrap_or(0.0254 / self.units.length);
        check_scale(&file, scale)?;
        let angle = self.units.angle;
        let mut bones = Vec::with_capacity(self.bones.len());
        for (raw, parent) in self.bones {
            let name = raw.name.unwrap_or_default();
            let at = |problem: String| ImportError::Invalid {
                file: file.clone(),
                line: raw.line,
                field: format!("bone {name}"),
                problem,
            };
            let parent =
                parent.ok_or_else(|| at("not attached anywhere in :hierarchy".to_owned()))?;
            let direction = raw.direction.unwrap_or(DVec3::ZERO);
            let norm = direction.length();
            let length = raw.length.unwrap_or(0.0);
            if norm <= 0.0 && length > 0.0 {
                return Err(at("direction is zero".to_owned()));
            }
            let (axis, axis_order) = raw
                .axis
                .unwrap_or((DVec3::ZERO, [Axis::X, Axis::Y, Axis::Z]));
            bones.push(Bone {
                id: raw.id,
                direction: if norm > 0.0 {
                    direction / norm
                } else {
                    DVec3::ZERO
                },
                length: length * scale,
                axis: DVec3::new(
                    angle.to_radians(axis.x),
                    angle.to_radians(axis.y),
                    angle.to_radians(axis.z),
                ),
                axis_order,
                dofs: raw.dofs,
                limits: raw
                    .limits
                    .iter()
                    .map(|&(lo, hi)| (angle.to_radians(lo), angle.to_radians(hi)))
                    .collect(),
                parent,
                line: raw.line,
                name,
            });
        }
        let mut root = self.root;
        root.position *= scale;
        root.orientation = DVec3::new(
            angle.to_radians(root.orientation.x),
            angle.to_radians(root.orientation.y),
            angle.to_radians(root.orientation.z),
        );
        let depth_first = depth_first(&bones);
        if let Some(bone) = bones
            .iter()
            .enumerate()
            .find(|(i, _)| !depth_first.contains(i))
            .map(|(_, b)| b)
        {
            let problem = "not reachable from root (cycle in :hierarchy)".to_owned();
            return Err(ImportError::Invalid {
                file,
                line: bone.line,
                field: format!("bone {}", bone.name),
                problem,
            });
        }
        Ok(Asf {
            source: file,
            units: self.units,
            scale,
            root,
            bones,
            depth_first,
        })
    }
}

/// A limit value: a number, or `inf`/`-inf` (but never NaN).
fn limit_value(file: &str, line: usize, token: &str, field: &str) -> Result<f64, ImportError> {
    match token.to_ascii_lowercase().as_str() {
        "inf" | "+inf" => Ok(f64::INFINITY),
        "-inf" => Ok(f64::NEG_INFINITY),
        _ => parse_f64(file, line, token, field),
    }
}

/// Bone indices depth-first from the root, children in `:hierarchy` order
/// (which is the order their parent lists them, then `:bonedata` order).
fn depth_first(bones: &[Bone]) -> Vec<usize> {
    let mut order = Vec::with_capacity(bones.len());
    let mut stack: Vec<usize> = children_of(bones, None).into_iter().rev().collect();
    while let Some(bone) = stack.pop() {
        if order.contains(&bone) || order.len() >= bones.len() {
            continue;
        }
        order.push(bone);
        stack.extend(children_of(bones, Some(bone)).into_iter().rev());
    }
    order
}

fn children_of(bones: &[Bone], parent: Option<usize>) -> Vec<usize> {
    bones
        .iter()
        .enumerate()
        .filter(|(_, b)| b.parent == parent)
        .map(|(i, _)| i)
        .collect()
}

/// AMC motion: per frame, the root's values then every bone's, in ASF order.
#[derive(Clone, Debug, PartialEq)]
pub struct Amc {
    /// File name.
    pub source: String,
    /// Frame number of the first frame (usually 1).
    pub first_frame: u64,
    /// Values per frame.
    pub stride: usize,
    /// Frames after each other: root values in `:root order` (translations in
    /// metres, rotations in radians), then each bone's dofs (radians) in
    /// `:bonedata` order and `dof` order.
    pub values: Vec<f64>,
}

impl Amc {
    /// Number of frames.
    #[must_use]
    pub fn frame_count(&self) -> usize {
        self.values.len().checked_div(self.stride).unwrap_or(0)
    }

    /// Values of frame `index` (0-based).
    #[must_use]
    pub fn frame(&self, index: usize) -> Option<&[f64]> {
        let start = index.checked_mul(self.stride)?;
        self.values.get(start..start.checked_add(self.stride)?)
    }
}

/// Where each part of an AMC frame lives in [`Amc::values`].
struct Layout {
    /// Start of each bone's values; the root's start at 0.
    starts: Vec<usize>,
    stride: usize,
}

impl Asf {
    fn layout(&self) -> Layout {
        let mut starts = Vec::with_capacity(self.bones.len());
        let mut next = self.root.order.len();
        for bone in &self.bones {
            starts.push(next);
            next = next.saturating_add(bone.dofs.len());
        }
        Layout {
            starts,
            stride: next,
        }
    }

    /// Index of the bone called `name` (AMC names are matched exactly).
    #[must_use]
    pub fn bone_index(&self, name: &str) -> Option<usize> {
        self.bones.iter().position(|b| b.name == name)
    }

    /// Converts AMC frames to the common [`Motion`] (see the module docs for
    /// the joint layout and rotation convention).
    ///
    /// # Errors
    /// [`ImportError::Invalid`] if `frame_time` is not finite and positive,
    /// [`ImportError::Convert`] if `amc` was not parsed against this skeleton.
    pub fn to_motion(&self, amc: &Amc, frame_time: f64) -> Result<Motion, ImportError> {
        if !(frame_time.is_finite() && frame_time > 0.0) {
            let problem = format!("frame time must be finite and positive, got {frame_time}");
            return Err(ImportError::Invalid {
                file: amc.source.clone(),
                line: 0,
                field: "frame_time".into(),
                problem,
            });
        }
        let layout = self.layout();
        if amc.stride != layout.stride {
            let problem = format!(
                "{} values per frame, skeleton {} needs {}",
                amc.stride, self.source, layout.stride
            );
            return Err(ImportError::Convert {
                file: amc.source.clone(),
                frame: 0,
                problem,
            });
        }
        let (joints, joint_of_bone) = self.motion_joints();
        let frames = (0..amc.frame_count()).map(|f| {
            self.motion_frame(
                amc.frame(f).unwrap_or(&[]),
                &layout,
                &joint_of_bone,
                joints.len(),
            )
        });
        Ok(Motion {
            source: amc.source.clone(),
            frame_time,
            frames: frames.collect(),
            joints,
        })
    }

    /// Joints of the [`Motion`] and, per bone, its joint index.
    pub(crate) fn motion_joints(&self) -> (Vec<Joint>, Vec<usize>) {
        let mut joints = vec![Joint {
            name: "root".into(),
            parent: None,
            offset: self.root.position,
            end_site: false,
        }];
        let mut joint_of_bone = vec![0; self.bones.len()];
        for &b in &self.depth_first {
            let Some(bone) = self.bones.get(b) else {
                continue;
            };
            let (parent, offset) = match bone
                .parent
                .and_then(|p| self.bones.get(p).map(|pb| (p, pb)))
            {
                Some((p, parent_bone)) => (
                    joint_of_bone.get(p).copied().unwrap_or(0),
                    parent_bone.vector(),
                ),
                None => (0, DVec3::ZERO),
            };
            if let Some(slot) = joint_of_bone.get_mut(b) {
                *slot = joints.len();
            }
            joints.push(Joint {
                name: bone.name.clone(),
                parent: Some(parent),
                offset,
                end_site: false,
            });
            if !self.bones.iter().any(|c| c.parent == Some(b)) {
                let tip = Joint {
                    name: format!("{}.end", bone.name),
                    parent: Some(joints.len().saturating_sub(1)),
                    offset: bone.vector(),
                    end_site: true,
                };
                joints.push(tip);
            }
        }
        (joints, joint_of_bone)
    }

    fn motion_frame(
        &self,
        values: &[f64],
        layout: &Layout,
        joint_of_bone: &[usize],
        joint_count: usize,
    ) -> Frame {
        let mut rotations = vec![DQuat::IDENTITY; joint_count];
        let mut translation = DVec3::ZERO;
        let mut root_m = DQuat::IDENTITY;
        for (&dof, &value) in self.root.order.iter().zip(values) {
            match (dof.translation_index(), dof.rotation_axis()) {
                (Some(0), _) => translation.x = value,
                (Some(1), _) => translation.y = value,
                (Some(_), _) => translation.z = value,
                (None, Some(axis)) => root_m = axis.rotation(value) * root_m,
                (None, None) => {}
            }
        }
        if let Some(slot) = rotations.first_mut() {
            *slot = euler_fixed(self.root.axis, self.root.orientation) * root_m;
        }
        for ((bone, &start), &joint) in self.bones.iter().zip(&layout.starts).zip(joint_of_bone) {
            let mine = values.get(start..).unwrap_or(&[]);
            let m = bone
                .dofs
                .iter()
                .zip(mine)
                .fold(DQuat::IDENTITY, |q, (dof, &v)| {
                    dof.rotation_axis().map_or(q, |axis| axis.rotation(v) * q)
                });
            let c = bone.axis_frame();
            if let Some(slot) = rotations.get_mut(joint) {
                *slot = c * m * c.conjugate();
            }
        }
        Frame {
            root_position: self.root.position + translation,
            rotations,
        }
    }
}

/// Parses an AMC file against its skeleton `asf`; `file` names it in errors.
///
/// # Errors
/// Any [`ImportError`] describing the first problem, with its line: unknown
/// or repeated bones, wrong value counts, non-numbers, NaN, missing bones,
/// frame numbers out of sequence.
pub fn parse_amc<R: BufRead>(reader: R, file: &str, asf: &Asf) -> Result<Amc, ImportError> {
    let layout = asf.layout();
    let mut p = AmcParser {
        lines: Lines::new(reader, file),
        asf,
        layout,
        angle: asf.units.angle,
        amc: Amc {
            source: file.to_owned(),
            first_frame: 0,
            stride: 0,
            values: Vec::new(),
        },
        frame: None,
        seen: vec![false; asf.bones.len().saturating_add(1)],
    };
    p.amc.stride = p.layout.stride;
    while p.lines.advance()? {
        let code = p.lines.text().split('#').next().unwrap_or("");
        let tokens: Vec<String> = code.split_ascii_whitespace().map(str::to_owned).collect();
        p.line(&tokens)?;
    }
    p.close_frame()?;
    Ok(p.amc)
}

struct AmcParser<'a, R> {
    lines: Lines<R>,
    asf: &'a Asf,
    layout: Layout,
    angle: AngleUnit,
    amc: Amc,
    /// Number and header line of the frame being read.
    frame: Option<(u64, usize)>,
    /// Which of root (0) and bones (1..) the current frame has given.
    seen: Vec<bool>,
}

impl<R: BufRead> AmcParser<'_, R> {
    fn line(&mut self, tokens: &[String]) -> Result<(), ImportError> {
        let Some((first, rest)) = tokens.split_first() else {
            return Ok(());
        };
        if let Some(keyword) = first.strip_prefix(':') {
            if self.frame.is_some() {
                return Err(self
                    .lines
                    .syntax("AMC", "bone values or a frame number", Some(first)));
            }
            match keyword.to_ascii_uppercase().as_str() {
                "DEGREES" => self.angle = AngleUnit::Degrees,
                "RADIANS" => self.angle = AngleUnit::Radians,
                _ => {}
            }
            return Ok(());
        }
        if first.bytes().all(|b| b.is_ascii_digit()) {
            return self.start_frame(first, rest);
        }
        self.bone_values(first, rest)
    }

    fn start_frame(&mut self, token: &str, rest: &[String]) -> Result<(), ImportError> {
        if let Some(extra) = rest.first() {
            return Err(self
                .lines
                .syntax("frame number", "end of line", Some(extra)));
        }
        let number: u64 = token
            .parse()
            .map_err(|_| self.lines.syntax("frame number", "an integer", Some(token)))?;
        match self.frame {
            None => self.amc.first_frame = number,
            Some((previous, _)) => {
                self.close_frame()?;
                if Some(number) != previous.checked_add(1) {
                    let problem = format!(
                        "expected frame {}, found {number}",
                        previous.saturating_add(1)
                    );
                    return Err(self.lines.invalid("frame number", problem));
                }
            }
        }
        self.frame = Some((number, self.lines.number()));
        self.seen.iter_mut().for_each(|s| *s = false);
        let stride = self.layout.stride;
        self.amc
            .values
            .resize(self.amc.values.len().saturating_add(stride), 0.0);
        Ok(())
    }

    fn bone_values(&mut self, name: &str, values: &[String]) -> Result<(), ImportError> {
        let Some((frame, _)) = self.frame else {
            return Err(self
                .lines
                .syntax("AMC", "a frame number before bone values", Some(name)));
        };
        let (slot, dofs, start) = if name == "root" {
            (0, self.asf.root.order.as_slice(), 0)
        } else {
            let index = self.asf.bone_index(name).ok_or_else(|| {
                self.lines.invalid(
                    "bone name",
                    format!("unknown bone {name:?} in frame {frame}"),
                )
            })?;
            let bone = self
                .asf
                .bones
                .get(index)
                .map_or(&[][..], |b| b.dofs.as_slice());
            (
                index.saturating_add(1),
                bone,
                self.layout.starts.get(index).copied().unwrap_or(0),
            )
        };
        if self.seen.get(slot).copied().unwrap_or(true) {
            return Err(self.lines.invalid(
                "bone name",
                format!("{name:?} given twice in frame {frame}"),
            ));
        }
        if values.len() != dofs.len() {
            let expected = format!("{} values for {name} (its dofs)", dofs.len());
            return Err(self.lines.syntax(
                &format!("frame {frame} {name}"),
                &expected,
                Some(&format!("{} values", values.len())),
            ));
        }
        let base = self
            .amc
            .values
            .len()
            .saturating_sub(self.layout.stride)
            .saturating_add(start);
        for (i, (dof, token)) in dofs.iter().zip(values).enumerate() {
            let Some(raw) = finite(token) else {
                let field = format!("frame {frame} {name} value {}", i.saturating_add(1));
                return Err(number_error(
                    self.lines.file(),
                    self.lines.number(),
                    token,
                    &field,
                ));
            };
            let value = if dof.rotation_axis().is_some() {
                self.angle.to_radians(raw)
            } else {
                raw * self.asf.scale
            };
            if let Some(v) = self.amc.values.get_mut(base.saturating_add(i)) {
                *v = value;
            }
        }
        if let Some(s) = self.seen.get_mut(slot) {
            *s = true;
        }
        Ok(())
    }

    /// Checks that the frame being read gave the root and every bone with dofs.
    fn close_frame(&self) -> Result<(), ImportError> {
        let Some((frame, line)) = self.frame else {
            return Ok(());
        };
        let missing = |name: &str| ImportError::Invalid {
            file: self.lines.file().to_owned(),
            line,
            field: format!("frame {frame}"),
            problem: format!("no values for {name} (AMC must be fully specified)"),
        };
        if !self.seen.first().copied().unwrap_or(false) && !self.asf.root.order.is_empty() {
            return Err(missing("root"));
        }
        for (bone, seen) in self.asf.bones.iter().zip(self.seen.iter().skip(1)) {
            if !seen && !bone.dofs.is_empty() {
                return Err(missing(&bone.name));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ASF: &str = "# test\n:version 1.10\n:name t\n:units\n  mass 1.0\n  length 0.45\n  angle deg\n:documentation\n  free text: with colon\n:root\n   order TX TY TZ RX RY RZ\n   axis XYZ\n   position 0 0 0\n   orientation 0 0 0\n:bonedata\n  begin\n     id 1\n     name a\n     direction 0 1 0\n     length 2\n     axis 0 0 90  XYZ\n    dof rx ry\n    limits (-10.0 20.0)\n           (-inf inf)\n  end\n  begin\n     id 2\n     name b\n     direction 1 0 0\n     length 1\n     axis 0 0 0 XYZ\n  end\n:hierarchy\n  begin\n    root a\n    a b\n  end\n";

    #[test]
    fn asf_units_limits_and_order() {
        let asf = parse_asf(ASF.as_bytes(), "t.asf", None).unwrap();
        assert_eq!(asf.bones.len(), 2);
        assert!((asf.scale - 0.0254 / 0.45).abs() < 1e-15);
        assert!((asf.bones[0].length - 2.0 * 0.0254 / 0.45).abs() < 1e-15);
        assert_eq!(asf.bones[0].limits.len(), 2);
        assert!((asf.bones[0].limits[0].1 - 20f64.to_radians()).abs() < 1e-15);
        assert_eq!(asf.bones[0].limits[1].1, f64::INFINITY);
        assert_eq!(asf.bones[1].parent, Some(0));
        assert_eq!(asf.depth_first, vec![0, 1]);
    }

    #[test]
    fn amc_to_motion_layout_and_rotation() {
        let asf = parse_asf(ASF.as_bytes(), "t.asf", Some(1.0)).unwrap();
        let amc_text = ":FULLY-SPECIFIED\n:DEGREES\n1\nroot 1 2 3 0 0 0\na 90 0\n2\nroot 0 0 0 0 0 90\na 0 0\n";
        let amc = parse_amc(amc_text.as_bytes(), "t.amc", &asf).unwrap();
        assert_eq!(amc.frame_count(), 2);
        let m = asf.to_motion(&amc, 0.5).unwrap();
        let names: Vec<_> = m.joints.iter().map(|j| j.name.as_str()).collect();
        assert_eq!(names, ["root", "a", "b", "b.end"]);
        // b starts at a's tip
        assert_eq!(m.joints[2].offset, DVec3::new(0.0, 2.0, 0.0));
        assert_eq!(m.joints[3].offset, DVec3::new(1.0, 0.0, 0.0));
        assert_eq!(m.frames[0].root_position, DVec3::new(1.0, 2.0, 3.0));
        // Bone a: C = Rz(90); rx = 90 about the bone's local x, which is global +Y.
        // L = C Rx(90) C^-1 is a 90 degree rotation about global +Y: +Z -> +X.
        let v = m.frames[0].rotations[1] * DVec3::Z;
        assert!((v - DVec3::X).length() < 1e-12, "{v}");
        // Root RZ 90: +X -> +Y.
        let r = m.frames[1].rotations[0] * DVec3::X;
        assert!((r - DVec3::Y).length() < 1e-12, "{r}");
    }

    #[test]
    fn dof_order_is_fixed_axes_in_listed_order() {
        // dof rx ry with rx = 90, ry = 90 (C = I): M = Ry(90) * Rx(90).
        // +Y --Rx(90)--> +Z --Ry(90)--> +X.
        let asf_text = ASF.replace("axis 0 0 90  XYZ", "axis 0 0 0 XYZ");
        let asf = parse_asf(asf_text.as_bytes(), "t.asf", Some(1.0)).unwrap();
        let amc = parse_amc("1\nroot 0 0 0 0 0 0\na 90 90\n".as_bytes(), "t.amc", &asf).unwrap();
        let m = asf.to_motion(&amc, 0.5).unwrap();
        let v = m.frames[0].rotations[1] * DVec3::Y;
        assert!((v - DVec3::X).length() < 1e-12, "{v}");
    }

    #[test]
    fn axis_order_composes_about_fixed_axes() {
        // axis 90 90 0 XYZ: C = Ry(90) * Rx(90): +Y -> +Z -> +X.
        let c = euler_fixed(
            [Axis::X, Axis::Y, Axis::Z],
            DVec3::new(90f64.to_radians(), 90f64.to_radians(), 0.0),
        );
        assert!((c * DVec3::Y - DVec3::X).length() < 1e-12);
        // ZYX order: C = Rx(90) * Ry(90): +Y -> +Y -> +Z.
        let c = euler_fixed(
            [Axis::Z, Axis::Y, Axis::X],
            DVec3::new(90f64.to_radians(), 90f64.to_radians(), 0.0),
        );
        assert!((c * DVec3::Y - DVec3::Z).length() < 1e-12);
    }
}
