//! The JSON example set: a public contract.
//!
//! ```json
//! {
//!   "segments": ["hips", "hand"],
//!   "axes": [
//!     {"name": "x", "min": -0.5, "max": 0.5, "count": 5, "cyclic": false, "cubic": false}
//!   ],
//!   "examples": [
//!     {"params": [0.1], "pose": [[0, 1, 0, 1, 0, 0, 0], [0.1, 1.2, 0.4, 1, 0, 0, 0]]}
//!   ]
//! }
//! ```
//!
//! - `segments`: 1 to 256 distinct names, at most 24 bytes of UTF-8 each.
//! - `axes`: 1 to 6 parameter axes of the table's grid. A bounded axis
//!   (`"cyclic": false`) has `count ≥ 2` samples from `min` to `max`
//!   inclusive (`step = (max − min)/(count − 1)`); a cyclic one has `count`
//!   samples from `min` with `step = (max − min)/count` and period
//!   `max − min` (`max` is `min` again). `"cubic": true` interpolates along
//!   the axis with Catmull-Rom instead of lerp/slerp. `cyclic` and `cubic`
//!   may be omitted (false).
//! - `examples`: at least one; each has one parameter per axis (`params`,
//!   anywhere in or near the axis range: examples do not need to lie on the
//!   grid) and one `[px, py, pz, qw, qx, qy, qz]` per segment (`pose`):
//!   the segment's absolute position in metres and absolute orientation as a
//!   unit quaternion `[w, x, y, z]` (within 1e-3 of unit length; normalized).
//!
//! Unknown keys are errors. Every error names the file, the line and the
//! field (`examples[3].pose[1]`).

use glam::{DQuat, DVec3};
use serde::Deserialize;
use serde::de::DeserializeOwned;
use serde_json::value::RawValue;

use super::error::{InputError, Source};
use super::{AxisDef, Seg};

/// Most parameter axes (the core's limit).
pub const MAX_AXES: usize = marionette_core::table::MAX_AXES;
/// Most segments (the blob's limit).
pub const MAX_SEGMENTS: usize = marionette_core::table::MAX_SEGMENTS;
/// Longest name in bytes.
pub const NAME_LEN: usize = marionette_core::table::NAME_LEN;

/// A parsed example set.
#[derive(Debug, Clone, PartialEq)]
pub struct ExampleSet {
    /// Segment names.
    pub segments: Vec<String>,
    /// The grid's parameter axes.
    pub axes: Vec<AxisDef>,
    /// The examples.
    pub examples: Vec<Example>,
}

/// One example: parameters and an absolute pose.
#[derive(Debug, Clone, PartialEq)]
pub struct Example {
    /// One value per axis.
    pub params: Vec<f64>,
    /// One (position, rotation) per segment.
    pub pose: Vec<Seg>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSet<'a> {
    #[serde(borrow)]
    segments: Vec<&'a RawValue>,
    #[serde(borrow)]
    axes: Vec<&'a RawValue>,
    #[serde(borrow)]
    examples: Vec<&'a RawValue>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAxis {
    name: String,
    min: f64,
    max: f64,
    count: u16,
    #[serde(default)]
    cyclic: bool,
    #[serde(default)]
    cubic: bool,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawExample<'a> {
    params: Vec<f64>,
    #[serde(borrow)]
    pose: Vec<&'a RawValue>,
}

/// Reads an example set from a file.
pub fn read(path: &std::path::Path) -> Result<ExampleSet, InputError> {
    parse(&Source::read(path)?)
}

/// Parses an example set.
pub fn parse(src: &Source) -> Result<ExampleSet, InputError> {
    let raw: RawSet<'_> =
        serde_json::from_str(&src.text).map_err(|e| json_error(src, 1, e, "example set"))?;
    let segments = segment_names(src, &raw.segments)?;
    let axes = raw
        .axes
        .iter()
        .enumerate()
        .map(|(i, a)| axis(src, a, i))
        .collect::<Result<Vec<_>, _>>()?;
    if axes.is_empty() || axes.len() > MAX_AXES {
        let problem = format!("expected 1 to {MAX_AXES} axes, found {}", axes.len());
        return Err(src.error_line(crate::locate::line(&src.text, "axes"), "axes", problem));
    }
    if raw.examples.is_empty() {
        return Err(src.error_line(
            crate::locate::line(&src.text, "examples"),
            "examples",
            "expected at least one example",
        ));
    }
    let examples = raw
        .examples
        .iter()
        .enumerate()
        .map(|(i, e)| example(src, e, i, axes.len(), segments.len()))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(ExampleSet {
        segments,
        axes,
        examples,
    })
}

/// Byte offset of a borrowed raw value inside the source text.
fn offset(src: &Source, raw: &RawValue) -> usize {
    (raw.get().as_ptr() as usize).saturating_sub(src.text.as_ptr() as usize)
}

/// A serde_json error inside a value that starts on `base_line`.
fn json_error(src: &Source, base_line: usize, e: serde_json::Error, field: &str) -> InputError {
    let line = if e.line() == 0 {
        base_line
    } else {
        base_line + e.line() - 1
    };
    let message = e.to_string();
    // serde_json appends " at line L column C", relative to the sub-value.
    let problem = message
        .rsplit_once(" at line ")
        .map_or(message.as_str(), |(m, _)| m)
        .to_owned();
    src.error_line(line, field, problem)
}

/// Parses a raw sub-value, locating errors in the whole file.
fn sub<T: DeserializeOwned>(src: &Source, raw: &RawValue, field: &str) -> Result<T, InputError> {
    let line = src.line_of(offset(src, raw));
    serde_json::from_str(raw.get()).map_err(|e| json_error(src, line, e, field))
}

fn segment_names(src: &Source, raw: &[&RawValue]) -> Result<Vec<String>, InputError> {
    if raw.is_empty() || raw.len() > MAX_SEGMENTS {
        let problem = format!(
            "expected 1 to {MAX_SEGMENTS} segment names, found {}",
            raw.len()
        );
        return Err(src.error_line(
            crate::locate::line(&src.text, "segments"),
            "segments",
            problem,
        ));
    }
    let mut out: Vec<String> = Vec::with_capacity(raw.len());
    for (i, r) in raw.iter().enumerate() {
        let field = format!("segments[{i}]");
        let name: String = sub(src, r, &field)?;
        let at = offset(src, r);
        check_name(&name).map_err(|p| src.error_at(at, &field, p))?;
        if out.contains(&name) {
            return Err(src.error_at(at, &field, format!("duplicate segment name {name:?}")));
        }
        out.push(name);
    }
    Ok(out)
}

/// Checks a table name (segment or axis).
pub fn check_name(name: &str) -> Result<(), String> {
    if name.is_empty() || name.len() > NAME_LEN || name.contains('\0') {
        Err(format!(
            "name {name:?} must be 1 to {NAME_LEN} bytes of UTF-8 without NUL"
        ))
    } else {
        Ok(())
    }
}

fn axis(src: &Source, raw: &RawValue, i: usize) -> Result<AxisDef, InputError> {
    let field = format!("axes[{i}]");
    let a: RawAxis = sub(src, raw, &field)?;
    let def = AxisDef {
        name: a.name,
        min: a.min,
        max: a.max,
        count: a.count,
        cyclic: a.cyclic,
        cubic: a.cubic,
    };
    def.check()
        .map_err(|p| src.error_at(offset(src, raw), &field, p))?;
    Ok(def)
}

fn example(
    src: &Source,
    raw: &RawValue,
    i: usize,
    axes: usize,
    segments: usize,
) -> Result<Example, InputError> {
    let field = format!("examples[{i}]");
    let at = offset(src, raw);
    let e: RawExample<'_> = serde_json::from_str(raw.get())
        .map_err(|err| json_error(src, src.line_of(at), err, &field))?;
    if e.params.len() != axes {
        let problem = format!(
            "expected {axes} parameters (one per axis), found {}",
            e.params.len()
        );
        return Err(src.error_at(at, &format!("{field}.params"), problem));
    }
    if let Some(k) = e.params.iter().position(|p| !p.is_finite()) {
        return Err(src.error_at(at, &format!("{field}.params[{k}]"), "not a finite number"));
    }
    if e.pose.len() != segments {
        let problem = format!(
            "expected {segments} segments (one per name), found {}",
            e.pose.len()
        );
        return Err(src.error_at(at, &format!("{field}.pose"), problem));
    }
    let mut pose = Vec::with_capacity(segments);
    for (s, r) in e.pose.iter().enumerate() {
        let f = format!("{field}.pose[{s}]");
        let v: [f64; 7] = sub(src, r, &f)?;
        pose.push(segment(v).map_err(|p| src.error_at(offset(src, r), &f, p))?);
    }
    Ok(Example {
        params: e.params,
        pose,
    })
}

/// `[px, py, pz, qw, qx, qy, qz]` as a checked, normalized segment.
pub fn segment(v: [f64; 7]) -> Result<Seg, String> {
    let [px, py, pz, w, x, y, z] = v;
    if v.iter().any(|c| !c.is_finite()) {
        return Err("position and rotation must be finite numbers".to_owned());
    }
    let q = DQuat::from_xyzw(x, y, z, w);
    let norm = q.length();
    if (norm - 1.0).abs() > 1e-3 {
        return Err(format!(
            "rotation [w, x, y, z] must be a unit quaternion, its length is {norm}"
        ));
    }
    Ok((DVec3::new(px, py, pz), q / norm))
}

/// Serializes a set in the contract's shape (used to export mocap examples).
#[must_use]
pub fn to_json(set: &ExampleSet) -> serde_json::Value {
    let axes: Vec<_> = set
        .axes
        .iter()
        .map(|a| {
            serde_json::json!({
                "name": a.name, "min": a.min, "max": a.max, "count": a.count,
                "cyclic": a.cyclic, "cubic": a.cubic,
            })
        })
        .collect();
    let examples: Vec<_> = set
        .examples
        .iter()
        .map(|e| {
            let pose: Vec<[f64; 7]> = e
                .pose
                .iter()
                .map(|(p, q)| [p.x, p.y, p.z, q.w, q.x, q.y, q.z])
                .collect();
            serde_json::json!({ "params": e.params, "pose": pose })
        })
        .collect();
    serde_json::json!({ "segments": set.segments, "axes": axes, "examples": examples })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn src(text: &str) -> Source {
        Source {
            file: "set.json".to_owned(),
            text: text.to_owned(),
        }
    }

    const GOOD: &str = r#"{
  "segments": ["a", "b"],
  "axes": [{"name": "x", "min": 0, "max": 1, "count": 2}],
  "examples": [
    {"params": [0], "pose": [[0,0,0,1,0,0,0],[1,0,0,1,0,0,0]]},
    {"params": [1], "pose": [[0,0,0,1,0,0,0],
                             [2,0,0,0,1,0,0]]}
  ]
}"#;

    #[test]
    fn parses_the_contract_shape() {
        let set = parse(&src(GOOD)).unwrap();
        assert_eq!(set.segments, ["a", "b"]);
        assert_eq!(set.axes[0].count, 2);
        assert!(!set.axes[0].cyclic && !set.axes[0].cubic);
        assert_eq!(set.examples[1].pose[1].0, DVec3::new(2.0, 0.0, 0.0));
        assert_eq!(
            set.examples[1].pose[1].1,
            DQuat::from_xyzw(1.0, 0.0, 0.0, 0.0)
        );
    }

    #[test]
    fn errors_name_file_line_and_field() {
        let bad = GOOD.replace("[2,0,0,0,1,0,0]", "[2,0,0,0,1,0]");
        let e = parse(&src(&bad)).unwrap_err();
        assert_eq!(
            (e.file.as_str(), e.line, e.field.as_str()),
            ("set.json", 7, "examples[1].pose[1]")
        );
        let bad = GOOD.replace("[2,0,0,0,1,0,0]", "[2,0,0,0,2,0,0]");
        let e = parse(&src(&bad)).unwrap_err();
        assert_eq!((e.line, e.field.as_str()), (7, "examples[1].pose[1]"));
        assert!(e.problem.contains("unit quaternion"), "{e}");
        let bad = GOOD.replace("\"params\": [1]", "\"params\": [1, 2]");
        let e = parse(&src(&bad)).unwrap_err();
        assert_eq!((e.line, e.field.as_str()), (6, "examples[1].params"));
        let bad = GOOD.replace("\"count\": 2", "\"count\": 1");
        let e = parse(&src(&bad)).unwrap_err();
        assert_eq!((e.line, e.field.as_str()), (3, "axes[0]"));
        let bad = GOOD.replace("\"min\": 0", "\"mni\": 0");
        let e = parse(&src(&bad)).unwrap_err();
        assert_eq!((e.line, e.field.as_str()), (3, "axes[0]"));
        assert!(e.problem.contains("mni"), "{e}");
        let bad = GOOD.replace("[\"a\", \"b\"]", "[\"a\", \"a\"]");
        let e = parse(&src(&bad)).unwrap_err();
        assert_eq!((e.line, e.field.as_str()), (2, "segments[1]"));
    }

    #[test]
    fn round_trips_through_to_json() {
        let set = parse(&src(GOOD)).unwrap();
        let text = serde_json::to_string_pretty(&to_json(&set)).unwrap();
        assert_eq!(parse(&src(&text)).unwrap(), set);
    }
}
