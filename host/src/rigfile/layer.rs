//! The rig file's `[[layer]]` tables: several tables performed at once,
//! blended by body part (the core's [`marionette_core::layer`]), and the
//! region that carries them ([`region`]).
//!
//! A rig without `[[layer]]` performs one table, as before. With layers the
//! tables are given in order (`--tables A.bin --tables B.bin`: table 0, 1,
//! …) and each layer names one by its index:
//!
//! ```toml
//! [[layer]]                       # at most 3, blended in file order, each over those before
//! name = "walk"                   # for messages (default "layer N")
//! table = 1                       # the second table given
//! root = "drop"                   # a looping clip's travel: "drop" (default, on a stand) | "apply"
//! fade_s = 0.25                   # cross-fade when the weight switches, s (default 0.25)
//! weight = 1.0                    # a number | { param = 3 } | { ramp = [from, to, seconds] }
//! rate = 0.5                      # a clip's playback rate, a source too (default 1; 0 ..= 4)
//! params = [{ ramp = [0.82, 1.91, 2.0] }]   # one source per parameter axis of the table
//! mask = { l_thigh = 1, l_shin = 1, torso = 0.5 }   # 0 ..= 1 per segment; the others 0
//! ```
//!
//! A source is a constant (a number), a rig parameter (`{ param = N }`: the
//! sensor map, or a `Params` dial, so a live control), or a ramp over the
//! time performed since arming (`{ ramp = [from, to, seconds] }`). Mask
//! weights are stored in 1/255 steps. Every error names the file, the line
//! and the field (`rig.toml:212: layer[1].mask.l_thig: unknown segment`);
//! the checks that need the tables (an index beyond those given, a
//! parameter count that is not the table's) are made when the region is
//! built, and name the layer's line too.

use super::{RawRig, RigFile, RigFileError, S, Source};
use marionette_core::layer::{self, Layer, Layers, MAX_LAYERS, Root, Source as Value};
use marionette_core::region::{self, Entry};
use marionette_core::rig::MAX_PARAMS;
use marionette_core::table::{MAX_AXES, Table};
use serde::Deserialize;

/// One `[[layer]]` as written.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawLayer {
    name: Option<S<String>>,
    table: S<u8>,
    root: Option<S<String>>,
    fade_s: Option<S<f32>>,
    weight: Option<S<toml::Value>>,
    rate: Option<S<toml::Value>>,
    #[serde(default)]
    params: Vec<S<toml::Value>>,
    mask: S<toml::value::Table>,
}

/// A checked `[[layer]]`.
#[derive(Clone, Debug, PartialEq)]
pub struct LayerSpec {
    /// Its name in messages.
    pub name: String,
    /// The 1-based line of its `table` field (errors found with the tables).
    pub line: usize,
    /// Index among the tables given.
    pub table: u8,
    /// The root travel rule.
    pub root: Root,
    /// Cross-fade time, seconds.
    pub fade_s: f32,
    /// The layer weight's source.
    pub weight: Value,
    /// A clip table's playback rate's source.
    pub rate: Value,
    /// One source per parameter axis of its table.
    pub params: Vec<Value>,
    /// One weight per segment, 255 = 1.
    pub mask: Vec<u8>,
}

/// Reads the `[[layer]]` tables of `raw` (segments named by `names`).
pub(super) fn parse(
    src: &Source<'_>,
    raw: &RawRig,
    names: &[String],
) -> Result<Vec<LayerSpec>, RigFileError> {
    if let Some(extra) = raw.layer.get(MAX_LAYERS) {
        let why = format!("more than {MAX_LAYERS} layers (the most a region carries)");
        return Err(src.err(&extra.span(), format!("layer[{MAX_LAYERS}]"), why));
    }
    raw.layer
        .iter()
        .enumerate()
        .map(|(i, l)| one(src, l.get_ref(), &format!("layer[{i}]"), i, names))
        .collect()
}

fn one(
    src: &Source<'_>,
    l: &RawLayer,
    path: &str,
    i: usize,
    names: &[String],
) -> Result<LayerSpec, RigFileError> {
    let err = |v: &std::ops::Range<usize>, key: &str, why: String| {
        src.err(v, format!("{path}.{key}"), why)
    };
    let root = match l.root.as_ref().map(|r| (r, r.get_ref().as_str())) {
        None | Some((_, "drop")) => Root::Drop,
        Some((_, "apply")) => Root::Apply,
        Some((r, other)) => {
            let why = format!("expected \"drop\" or \"apply\", found {other:?}");
            return Err(err(&r.span(), "root", why));
        }
    };
    let fade_s = match &l.fade_s {
        None => 0.25,
        Some(f) if f.get_ref().is_finite() && *f.get_ref() >= 0.0 => *f.get_ref(),
        Some(f) => {
            return Err(err(
                &f.span(),
                "fade_s",
                "must be a finite number ≥ 0".into(),
            ));
        }
    };
    let value = |v: &Option<S<toml::Value>>, key: &str| match v {
        None => Ok(Value::Const(1.0)),
        Some(w) => source(w.get_ref()).map_err(|why| err(&w.span(), key, why)),
    };
    let (weight, rate) = (value(&l.weight, "weight")?, value(&l.rate, "rate")?);
    if l.params.len() > MAX_AXES {
        let why = format!("more than {MAX_AXES} sources (a table has at most {MAX_AXES} axes)");
        return Err(err(&l.table.span(), "params", why));
    }
    let params = l
        .params
        .iter()
        .enumerate()
        .map(|(k, p)| {
            source(p.get_ref()).map_err(|why| err(&p.span(), &format!("params[{k}]"), why))
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(LayerSpec {
        name: l
            .name
            .as_ref()
            .map_or_else(|| format!("layer {i}"), |n| n.get_ref().clone()),
        line: src.line(l.table.span().start),
        table: *l.table.get_ref(),
        root,
        fade_s,
        weight,
        rate,
        params,
        mask: mask(l.mask.get_ref(), names)
            .map_err(|(key, why)| err(&l.mask.span(), &format!("mask{key}"), why))?,
    })
}

/// A source: a number, `{ param = N }` or `{ ramp = [from, to, seconds] }`.
fn source(v: &toml::Value) -> Result<Value, String> {
    let number = |v: &toml::Value| match v {
        toml::Value::Float(f) => Some(*f as f32),
        toml::Value::Integer(i) => Some(*i as f32),
        _ => None,
    };
    let expected = "expected a number, { param = N } or { ramp = [from, to, seconds] }";
    if let Some(x) = number(v) {
        return if x.is_finite() {
            Ok(Value::Const(x))
        } else {
            Err("not a finite number".into())
        };
    }
    let toml::Value::Table(t) = v else {
        return Err(expected.into());
    };
    match (t.len(), t.get("param"), t.get("ramp")) {
        (1, Some(toml::Value::Integer(p)), None) => u8::try_from(*p)
            .ok()
            .filter(|&p| usize::from(p) < MAX_PARAMS)
            .map(Value::Param)
            .ok_or_else(|| format!("param {p} is out of range (0 ..= {})", MAX_PARAMS - 1)),
        (1, None, Some(toml::Value::Array(a))) => {
            let v: Vec<f32> = a.iter().filter_map(number).collect();
            match v[..] {
                [from, to, seconds]
                    if a.len() == 3
                        && from.is_finite()
                        && to.is_finite()
                        && seconds.is_finite()
                        && seconds > 0.0 =>
                {
                    Ok(Value::Ramp { from, to, seconds })
                }
                _ => Err("a ramp is [from, to, seconds]: three finite numbers, seconds > 0".into()),
            }
        }
        _ => Err(expected.into()),
    }
}

/// The mask bytes over `names` from `{ segment = weight }` (others 0); an
/// error is `(".segment", why)`.
fn mask(t: &toml::value::Table, names: &[String]) -> Result<Vec<u8>, (String, String)> {
    let mut out = vec![0u8; names.len()];
    for (key, v) in t {
        let at = format!(".{key}");
        let Some(i) = names.iter().position(|n| n == key) else {
            return Err((at, format!("unknown segment {key:?}")));
        };
        let w = match v {
            toml::Value::Float(f) => *f,
            toml::Value::Integer(i) => *i as f64,
            _ => return Err((at, "expected a weight 0 ..= 1".into())),
        };
        if !(0.0..=1.0).contains(&w) {
            return Err((at, format!("{w} is not a weight 0 ..= 1")));
        }
        out[i] = (w * 255.0).round() as u8;
    }
    Ok(out)
}

/// A table given for a region: its name in messages and its blob.
pub struct Given<'a> {
    /// Its name in messages (a path).
    pub name: String,
    /// The table blob of `marionette build`.
    pub blob: &'a [u8],
}

/// The table region of `rig` and `tables`: the rig blob, the tables in
/// order, and (if the rig has `[[layer]]` tables) its layer list. A rig
/// without layers takes at most one table.
pub fn region(rig: &RigFile, tables: &[Given<'_>]) -> Result<Vec<u8>, RigFileError> {
    let at = |line: usize, field: String, message: String| RigFileError::At {
        file: rig.file.clone(),
        line,
        field,
        message,
    };
    if rig.layers.is_empty() && tables.len() > 1 {
        let why = format!(
            "{} tables given; a rig without [[layer]] tables performs one",
            tables.len()
        );
        return Err(at(0, "layer".into(), why));
    }
    for (i, l) in rig.layers.iter().enumerate() {
        let field = |key: &str| format!("layer[{i}].{key}");
        let Some(t) = tables.get(usize::from(l.table)) else {
            let why = format!(
                "table {} of the tables given, but {} given (--tables, in order from 0)",
                l.table,
                tables.len()
            );
            return Err(at(l.line, field("table"), why));
        };
        let axes = Table::parse(t.blob)
            .map_err(|e| at(l.line, field("table"), format!("{}: {e}", t.name)))?
            .param_axes()
            .len();
        if axes != l.params.len() {
            let why = format!(
                "{} has {axes} parameter axes; give one source for each ({} given)",
                t.name,
                l.params.len()
            );
            return Err(at(l.line, field("params"), why));
        }
    }
    write(rig, tables).map_err(|why| at(0, "layer".into(), why))
}

/// [`region()`] of the table blobs in the files `paths` (in order), read
/// here; an unreadable file is named.
pub fn region_of_files(
    rig: &RigFile,
    paths: &[std::path::PathBuf],
) -> Result<Vec<u8>, RigFileError> {
    let blobs = paths
        .iter()
        .map(|p| {
            std::fs::read(p).map_err(|source| RigFileError::Io {
                file: p.display().to_string(),
                source,
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let given: Vec<Given<'_>> = paths
        .iter()
        .zip(&blobs)
        .map(|(p, blob)| Given {
            name: p.display().to_string(),
            blob,
        })
        .collect();
    region(rig, &given)
}

/// Lays out the region (after [`region`]'s checks).
fn write(rig: &RigFile, tables: &[Given<'_>]) -> Result<Vec<u8>, String> {
    let rig_blob = super::to_blob(rig).map_err(|e| e.to_string())?;
    let segments = rig.segment_names().len();
    let layers: Vec<Layer<'_>> = rig
        .layers
        .iter()
        .map(|l| {
            let mut axes = [Value::Const(0.0); MAX_AXES];
            axes[..l.params.len()].copy_from_slice(&l.params);
            Layer {
                table: l.table,
                root: l.root,
                fade_s: l.fade_s,
                weight: l.weight,
                rate: l.rate,
                axes,
                axis_count: l.params.len() as u8,
                mask: &l.mask,
            }
        })
        .collect();
    let mut list = vec![0u8; layer::len(layers.len(), segments)];
    if !layers.is_empty() {
        Layers::write(&layers, segments, &mut list).map_err(|e| e.to_string())?;
    }
    let mut entries = vec![Entry::rig(&rig_blob)];
    entries.extend(tables.iter().map(|t| Entry::table(t.blob)));
    if !layers.is_empty() {
        entries.push(Entry::layers(&list));
    }
    let mut out = vec![0u8; region::len(&entries).map_err(|e| e.to_string())?];
    let n = region::write(&entries, &mut out).map_err(|e| e.to_string())?;
    out.truncate(n);
    Ok(out)
}
