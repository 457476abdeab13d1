//! The build spec (TOML): what to build a table from and how.
//!
//! ```toml
//! kind = "grid"             # "grid" (static poses) or "clips" (motion table)
//! frame = "heading"         # mocap: frame of the poses and parameters: "heading"
//!                           # (floor below the root, facing +Z), "root" (origin
//!                           # at the root joint, facing +Z), "stand" (grid: the
//!                           # root's own frame, see below) or "world"
//! # examples = "set.json"   # a JSON example set instead of mocap (see `examples`)
//!
//! [mocap]
//! skeleton = "../hdm05_bk/HDM_bk.asf"  # ASF for .amc clips (paths relative to the spec)
//! # scale = 0.056444        # BVH: metres per file unit (default: the CMU unit)
//! # fps = 120               # override the frame rate (AMC default 120, BVH: header)
//! every = 2                 # grid: take every k-th frame
//! # forward = [0, 0, 1]     # the root's forward axis in its own frame
//! # end_sites = false       # keep BVH End Sites / ASF bone tips as segments
//!
//! [[clip]]
//! file = "../hdm05_bk/HDM_bk_grabHighR_005_120.amc"
//! # frames = [[0, 200]]    # grid: inclusive frame ranges (default: all)
//! # cut = [10, 130]        # clips: phase boundaries, first to last frame
//! # params = [1.7]         # explicit parameters (else measured, see [[axis]])
//! # fps = 60               # this clip's frame rate (overrides [mocap] fps and the
//!                          # file's header; a rate that makes the root's speed
//!                          # implausible is warned about, see `mocap`)
//!
//! [rig]                     # retarget: see `retarget`
//! # file = "../../rigs/cmu31.toml"  # a rig file (relative to the spec, or a name in rigs/)
//! # align_rest = false      # with a file: rotation offsets from the rest poses
//! # retarget = "hdm05"      # with a file: its [[retarget.map]] of this name
//! #                         # (default: its [[retarget.joint]] map)
//! scale = 1.0               # without a file: uniform scale of every offset and the root path
//! lengths = { rradius = 1.0 } # without a file: per-segment factor on the offset to the parent
//! # strip_prefix = "CC_Base_" # without a file: joint names lose this prefix
//! # rename = { Hip = "hips" }  # without a file: (stripped) joint name -> segment name
//! # drop = ["*Twist*"]      # without a file: joints left out (globs, `*` = anything);
//! # keep = ["*Thigh", ...]  # if given, only matching joints are kept (the root always)
//!
//! [[axis]]
//! name = "hand_x"
//! segment = "rhand"         # parameter: this segment's position ...
//! component = "x"           # ... component in the build frame
//! # point = [0, -0.15, 0]   # of this point in the segment's frame (default: origin)
//! # measure = "speed"       # clips: the root's mean horizontal speed
//! min = -0.3                # min / max default to the data's range
//! max = 0.5
//! count = 5
//! # cyclic = false
//! # cubic = false
//!
//! [motion]                  # clips only
//! frames = 32               # frames per phase
//! looping = true            # one cyclic phase, seam-blended
//! seam_window = 4           # frames blended at each end of a loop
//! # seam_search = 12        # looping: move each end of a clip's cut up to this
//!                           # many source frames, to the pair whose poses match
//!                           # best (see `mocap::best_cut`); default 0: as given
//!
//! [resample]
//! method = "auto"           # auto | idw | rbf | local-linear
//! # valid_radius = 0.87     # cells; a cell is valid when its centre, or each of
//!                           # its corners, is this close to an example (default √p / 2;
//!                           # a cell whose corners are all examples is always valid)
//! # enforce_lengths = true  # W&H limb-length enforcement of each resampled pose
//! # place_probe = true      # grid of one point's x, y, z (the hand): solve each
//!                           # resampled pose so the point sits on its grid point
//!                           # (see `place`); poses the rig cannot fit stay as resampled
//! ```
//!
//! `frame = "stand"` is for a figure whose root is held by a stand (a
//! puppet's pelvis on its post): each example is expressed in its root's
//! own frame (origin at the root joint, axes turning with the root in yaw,
//! pitch and roll), the parameters are measured there, and the pose is then
//! placed at the rig file's rest root placement (`root_position`,
//! `root_rotation`; the origin without a rig file). So a parameter is "where
//! the hand is relative to the pelvis, in the pelvis' axes" (the quantity a
//! rig's `frame = "sensor:N"` parameter map measures with a tracker on the
//! performer's pelvis), and every synthesized pose has its root exactly
//! where the stand holds it. Grid tables only.
//!
//! Unknown keys are errors; every error names the file, the line and the
//! field.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

use super::AxisDef;
use super::error::{InputError, Source};

/// A parsed, checked build spec.
#[derive(Debug, Clone)]
pub struct Spec {
    /// The spec's own source (for locating errors found later).
    pub source: Source,
    /// The directory relative paths are resolved against.
    pub dir: PathBuf,
    /// Grid or clips.
    pub kind: Kind,
    /// The build frame of mocap poses.
    pub frame: FrameKind,
    /// Where the examples come from.
    pub input: Input,
    /// Parameter axes (empty for a JSON example set, which has its own).
    pub axes: Vec<AxisSpec>,
    /// Retargeting.
    pub rig: RigSpec,
    /// Motion settings (clips).
    pub motion: MotionSpec,
    /// Resampling settings.
    pub resample: ResampleSpec,
}

/// Static grid or motion table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// One pose per grid sample.
    Grid,
    /// One clip per parameter sample.
    Clips,
}

/// The frame mocap poses and parameters are expressed in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameKind {
    /// Per frame (grid) or per clip (clips): origin on the floor below the
    /// root, yaw turned so the root faces +Z; Y stays up.
    Heading,
    /// As `Heading`, with the origin at the root joint (y above the root).
    Root,
    /// Grid: the root's own frame (full rotation, origin at the root joint)
    /// for the parameters; poses placed at the rig's rest root placement.
    Stand,
    /// The mocap's world frame.
    World,
}

/// The example source.
#[derive(Debug, Clone)]
pub enum Input {
    /// A JSON example set.
    Examples(PathBuf),
    /// Mocap clips.
    Mocap(MocapSpec),
}

/// Mocap settings.
#[derive(Debug, Clone)]
pub struct MocapSpec {
    /// ASF skeleton for AMC clips.
    pub skeleton: Option<PathBuf>,
    /// Line of `[mocap] skeleton` (of `[mocap]` without one), for errors
    /// found while reading it.
    pub skeleton_line: usize,
    /// BVH metres per unit.
    pub scale: f64,
    /// Frame rate override.
    pub fps: Option<f64>,
    /// Frame step (grid).
    pub every: usize,
    /// Forward axis of the root.
    pub forward: [f64; 3],
    /// Keep end sites as segments.
    pub end_sites: bool,
    /// The clips.
    pub clips: Vec<ClipSpec>,
}

/// One mocap clip.
#[derive(Debug, Clone)]
pub struct ClipSpec {
    /// The file.
    pub file: PathBuf,
    /// The name used for hold-outs and reports (the file stem).
    pub name: String,
    /// Inclusive frame ranges (grid).
    pub frames: Option<Vec<[usize; 2]>>,
    /// Frame step override.
    pub every: Option<usize>,
    /// Phase boundaries (clips).
    pub cut: Vec<usize>,
    /// Explicit parameters.
    pub params: Option<Vec<f64>>,
    /// This clip's frame rate (overrides `[mocap] fps` and the header).
    pub fps: Option<f64>,
    /// Line of the clip's `file` key (for errors found while loading).
    pub line: usize,
}

/// Where an axis' parameter comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum Measure {
    /// Position component (0 = x, 1 = y, 2 = z) of a point of a segment in
    /// the build frame.
    Position {
        /// Segment name.
        segment: String,
        /// Component index.
        component: usize,
        /// The point, in the segment's frame (metres; zero: its origin).
        point: [f64; 3],
    },
    /// Mean horizontal root speed over the clip (clips).
    Speed,
    /// Given by each clip's `params`.
    Explicit,
}

/// One parameter axis.
#[derive(Debug, Clone)]
pub struct AxisSpec {
    /// Name.
    pub name: String,
    /// Where the parameter comes from.
    pub measure: Measure,
    /// Range (defaults from the data).
    pub min: Option<f64>,
    /// Range (defaults from the data).
    pub max: Option<f64>,
    /// Samples.
    pub count: u16,
    /// Cyclic.
    pub cyclic: bool,
    /// Catmull-Rom.
    pub cubic: bool,
    /// Line of the axis (for errors found later).
    pub line: usize,
}

impl AxisSpec {
    /// The axis with its range filled in.
    #[must_use]
    pub fn def(&self, data_min: f64, data_max: f64) -> AxisDef {
        AxisDef {
            name: self.name.clone(),
            min: self.min.unwrap_or(data_min),
            max: self.max.unwrap_or(data_max),
            count: self.count,
            cyclic: self.cyclic,
            cubic: self.cubic,
        }
    }
}

/// Retargeting settings.
#[derive(Debug, Clone)]
pub struct RigSpec {
    /// A rig file (else the mocap skeleton is the rig).
    pub file: Option<PathBuf>,
    /// Compute missing rotation offsets from the rest poses (rig files).
    pub align_rest: bool,
    /// The rig file's named retarget map to use (`None`: its default map).
    pub retarget: Option<String>,
    /// Uniform scale.
    pub scale: f64,
    /// Per-segment offset factors.
    pub lengths: BTreeMap<String, f64>,
    /// Which skeleton joints become segments and their names (a rig from
    /// the skeleton only).
    pub names: NameMap,
    /// Line of the `[rig]` table.
    pub line: usize,
}

/// Selecting and naming a skeleton's joints (`[rig] strip_prefix`,
/// `rename`, `drop`, `keep`). Patterns are globs (`*` matches any run of
/// characters) on the name after `strip_prefix`; `rename` keys are such
/// names too. A joint is kept when it matches some `keep` pattern (or there
/// is none) and no `drop` pattern; the root is always kept.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NameMap {
    /// Removed from the start of every joint name that has it.
    pub strip_prefix: Option<String>,
    /// Stripped name → segment name.
    pub rename: BTreeMap<String, String>,
    /// Joints to drop.
    pub drop: Vec<String>,
    /// Joints to keep (empty: all).
    pub keep: Vec<String>,
    /// Lines of the fields, for errors: `strip_prefix`, `rename`, `drop`, `keep`.
    pub lines: [usize; 4],
}

impl NameMap {
    /// The name after `strip_prefix`.
    #[must_use]
    pub fn stripped<'a>(&self, name: &'a str) -> &'a str {
        self.strip_prefix
            .as_deref()
            .and_then(|p| name.strip_prefix(p))
            .unwrap_or(name)
    }

    /// The segment name of joint `name`.
    #[must_use]
    pub fn segment_name(&self, name: &str) -> String {
        let s = self.stripped(name);
        self.rename.get(s).cloned().unwrap_or_else(|| s.to_owned())
    }

    /// Whether joint `name` becomes a segment (the root always does).
    #[must_use]
    pub fn keeps(&self, name: &str) -> bool {
        let s = self.stripped(name);
        (self.keep.is_empty() || self.keep.iter().any(|p| glob(p, s)))
            && !self.drop.iter().any(|p| glob(p, s))
    }

    /// Whether any selection or naming is asked for.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.strip_prefix.is_none()
            && self.rename.is_empty()
            && self.drop.is_empty()
            && self.keep.is_empty()
    }
}

/// Whether `name` matches `pattern`, where `*` matches any run of characters.
#[must_use]
pub fn glob(pattern: &str, name: &str) -> bool {
    let mut parts = pattern.split('*');
    let first = parts.next().unwrap_or("");
    let Some(mut rest) = name.strip_prefix(first) else {
        return false;
    };
    let parts: Vec<&str> = parts.collect();
    let Some((last, middle)) = parts.split_last() else {
        return rest.is_empty();
    };
    for part in middle {
        match rest.find(part) {
            Some(at) => rest = &rest[at + part.len()..],
            None => return false,
        }
    }
    rest.len() >= last.len() && rest.ends_with(last)
}

/// The farthest `[motion] seam_search` may move a cut end, source frames.
pub const MAX_SEAM_SEARCH: usize = 240;

/// Motion-table settings.
#[derive(Debug, Clone, Copy)]
pub struct MotionSpec {
    /// Frames per phase.
    pub frames: usize,
    /// Looping (one cyclic phase).
    pub looping: bool,
    /// Seam-blend window, frames.
    pub seam_window: usize,
    /// Looping: how far (source frames) each end of a clip's cut may move
    /// to the pair of frames whose poses match best (0: as given).
    pub seam_search: usize,
}

/// Resampling settings.
#[derive(Debug, Clone)]
pub struct ResampleSpec {
    /// `auto`, `idw`, `rbf` or `local-linear`.
    pub method: String,
    /// Validity radius, cells.
    pub valid_radius: Option<f64>,
    /// Limb-length enforcement of resampled poses.
    pub enforce_lengths: bool,
    /// Solve each resampled pose of a probe-position grid onto its grid point.
    pub place_probe: bool,
    /// Line of `valid_radius` (of `[resample]` without one; 0 without
    /// either), for errors found while building.
    pub line: usize,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    kind: Option<Spanned<String>>,
    frame: Option<Spanned<String>>,
    examples: Option<Spanned<String>>,
    mocap: Option<Spanned<RawMocap>>,
    #[serde(default)]
    clip: Vec<Spanned<RawClip>>,
    #[serde(default)]
    axis: Vec<Spanned<RawAxis>>,
    rig: Option<Spanned<RawRig>>,
    motion: Option<Spanned<RawMotion>>,
    resample: Option<Spanned<RawResample>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMocap {
    skeleton: Option<Spanned<String>>,
    scale: Option<Spanned<f64>>,
    fps: Option<Spanned<f64>>,
    every: Option<Spanned<usize>>,
    forward: Option<Spanned<[f64; 3]>>,
    end_sites: Option<bool>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawClip {
    file: Spanned<String>,
    frames: Option<Spanned<Vec<[usize; 2]>>>,
    every: Option<Spanned<usize>>,
    cut: Option<Spanned<Vec<usize>>>,
    params: Option<Spanned<Vec<f64>>>,
    fps: Option<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAxis {
    name: Spanned<String>,
    segment: Option<Spanned<String>>,
    component: Option<Spanned<String>>,
    point: Option<Spanned<[f64; 3]>>,
    measure: Option<Spanned<String>>,
    min: Option<f64>,
    max: Option<f64>,
    count: Spanned<u16>,
    #[serde(default)]
    cyclic: bool,
    #[serde(default)]
    cubic: bool,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRig {
    file: Option<Spanned<String>>,
    align_rest: Option<Spanned<bool>>,
    retarget: Option<Spanned<String>>,
    scale: Option<Spanned<f64>>,
    #[serde(default)]
    lengths: BTreeMap<String, Spanned<f64>>,
    strip_prefix: Option<Spanned<String>>,
    #[serde(default)]
    rename: BTreeMap<String, Spanned<String>>,
    drop: Option<Spanned<Vec<String>>>,
    keep: Option<Spanned<Vec<String>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMotion {
    frames: Option<Spanned<usize>>,
    looping: Option<bool>,
    seam_window: Option<Spanned<usize>>,
    seam_search: Option<Spanned<usize>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawResample {
    method: Option<Spanned<String>>,
    valid_radius: Option<Spanned<f64>>,
    enforce_lengths: Option<bool>,
    place_probe: Option<bool>,
}

/// Reads and checks a spec file.
pub fn read(path: &Path) -> Result<Spec, InputError> {
    let source = Source::read(path)?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    parse(source, dir)
}

/// The field a TOML error at byte `at` is about: the key on that line, or
/// the table header.
fn field_at(src: &Source, at: usize) -> String {
    let text = &src.text[..at.min(src.text.len())];
    let start = text.rfind('\n').map_or(0, |i| i + 1);
    let line = src.text[start..].lines().next().unwrap_or("").trim();
    let field = match line.strip_prefix('[') {
        Some(header) => header.trim_matches(|c| c == '[' || c == ']').trim(),
        None => line.split_once('=').map_or("", |(k, _)| k.trim()),
    };
    // A bare `[` or ` = 1` names no key: the spec as a whole.
    if field.is_empty() {
        return "spec".to_owned();
    }
    if line.starts_with('[') {
        return field.to_owned();
    }
    // A key: under the nearest table header above it (`mocap.scale`,
    // `clip[1].file` for the second `[[clip]]`).
    let headers: Vec<&str> = text
        .get(..start)
        .unwrap_or("")
        .lines()
        .map(str::trim)
        .filter(|l| is_header(l))
        .collect();
    match headers.last() {
        Some(h) if h.starts_with("[[") => {
            let name = h.trim_matches(|c| c == '[' || c == ']').trim();
            let index = headers.iter().filter(|o| *o == h).count() - 1;
            format!("{name}[{index}].{field}")
        }
        Some(h) => format!(
            "{}.{field}",
            h.trim_matches(|c| c == '[' || c == ']').trim()
        ),
        None => field.to_owned(),
    }
}

/// Whether `line` (trimmed) is a table header, `[name]` or `[[name]]`
/// (not the continuation of a multi-line array).
fn is_header(line: &str) -> bool {
    let code = line.split('#').next().unwrap_or("").trim_end();
    code.starts_with('[')
        && code.ends_with(']')
        && code
            .trim_matches(|c| c == '[' || c == ']')
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.' | ' '))
}

/// Parses a spec from its text; `dir` resolves relative paths.
pub fn parse(source: Source, dir: PathBuf) -> Result<Spec, InputError> {
    let raw: Raw = toml::from_str(&source.text).map_err(|e| {
        let at = e.span().map_or(0, |s| s.start);
        source.error_at(at, &field_at(&source, at), e.message().trim().to_owned())
    })?;
    let p = Parser {
        src: &source,
        dir: &dir,
    };
    let kind = p.kind(raw.kind.as_ref())?;
    let frame = p.frame(raw.frame.as_ref(), kind)?;
    let input = p.input(&raw, kind)?;
    let axes = p.axes(&raw.axis, &input, kind)?;
    let rig = p.rig(raw.rig.as_ref())?;
    let motion = p.motion(raw.motion.as_ref(), kind)?;
    let resample = p.resample(raw.resample.as_ref())?;
    Ok(Spec {
        source: source.clone(),
        dir,
        kind,
        frame,
        input,
        axes,
        rig,
        motion,
        resample,
    })
}

struct Parser<'a> {
    src: &'a Source,
    dir: &'a Path,
}

impl Parser<'_> {
    fn err<T>(
        &self,
        span: std::ops::Range<usize>,
        field: &str,
        problem: impl Into<String>,
    ) -> Result<T, InputError> {
        Err(self.src.error_at(span.start, field, problem))
    }

    fn line(&self, span: &std::ops::Range<usize>) -> usize {
        self.src.line_of(span.start)
    }

    fn path(&self, s: &str) -> PathBuf {
        self.dir.join(s)
    }

    fn kind(&self, kind: Option<&Spanned<String>>) -> Result<Kind, InputError> {
        match kind.map(|k| (k.get_ref().as_str(), k.span())) {
            None | Some(("grid", _)) => Ok(Kind::Grid),
            Some(("clips", _)) => Ok(Kind::Clips),
            Some((other, span)) => self.err(
                span,
                "kind",
                format!("expected \"grid\" or \"clips\", found {other:?}"),
            ),
        }
    }

    fn frame(&self, frame: Option<&Spanned<String>>, kind: Kind) -> Result<FrameKind, InputError> {
        match frame.map(|k| (k.get_ref().as_str(), k.span())) {
            None | Some(("heading", _)) => Ok(FrameKind::Heading),
            Some(("root", _)) => Ok(FrameKind::Root),
            Some(("stand", span)) if kind == Kind::Clips => self.err(
                span,
                "frame",
                "\"stand\" is for grid tables (kind = \"grid\")",
            ),
            Some(("stand", _)) => Ok(FrameKind::Stand),
            Some(("world", _)) => Ok(FrameKind::World),
            Some((other, span)) => self.err(
                span,
                "frame",
                format!("expected \"heading\", \"root\", \"stand\" or \"world\", found {other:?}"),
            ),
        }
    }

    fn input(&self, raw: &Raw, kind: Kind) -> Result<Input, InputError> {
        match (&raw.examples, &raw.mocap) {
            (Some(e), None) => {
                if kind == Kind::Clips {
                    return self.err(
                        e.span(),
                        "examples",
                        "a JSON example set builds a grid table (kind = \"grid\")",
                    );
                }
                if let Some(c) = raw.clip.first() {
                    return self.err(
                        c.span(),
                        "clip",
                        "[[clip]] needs [mocap], not a JSON example set",
                    );
                }
                Ok(Input::Examples(self.path(e.get_ref())))
            }
            (None, Some(m)) => self.mocap(m, &raw.clip, kind).map(Input::Mocap),
            (Some(e), Some(_)) => self.err(
                e.span(),
                "examples",
                "give either `examples` or [mocap], not both",
            ),
            (None, None) => self.err(
                0..0,
                "spec",
                "expected `examples = \"set.json\"` or a [mocap] table",
            ),
        }
    }

    fn mocap(
        &self,
        m: &Spanned<RawMocap>,
        clips: &[Spanned<RawClip>],
        kind: Kind,
    ) -> Result<MocapSpec, InputError> {
        let r = m.get_ref();
        let positive = |v: &Option<Spanned<f64>>, field: &str| -> Result<Option<f64>, InputError> {
            match v {
                Some(s) if !(s.get_ref().is_finite() && *s.get_ref() > 0.0) => {
                    self.err(s.span(), field, "must be a finite number > 0")
                }
                Some(s) => Ok(Some(*s.get_ref())),
                None => Ok(None),
            }
        };
        let scale = positive(&r.scale, "mocap.scale")?.unwrap_or(crate::import::CMU_UNIT_METRES);
        let fps = positive(&r.fps, "mocap.fps")?;
        let every = self.step(r.every.as_ref(), "mocap.every")?.unwrap_or(1);
        let forward = match &r.forward {
            Some(f) => {
                let v = *f.get_ref();
                if v.iter().all(|c| c.is_finite()) && v[0].hypot(v[2]) > 1e-6 {
                    v
                } else {
                    return self.err(
                        f.span(),
                        "mocap.forward",
                        "needs a finite vector with a horizontal (x or z) part",
                    );
                }
            }
            None => [0.0, 0.0, 1.0],
        };
        if clips.is_empty() {
            return self.err(m.span(), "clip", "[mocap] needs at least one [[clip]]");
        }
        let clips = clips
            .iter()
            .enumerate()
            .map(|(i, c)| self.clip(c, i, kind))
            .collect::<Result<Vec<_>, _>>()?;
        if kind == Kind::Clips {
            let n = clips[0].cut.len();
            if let Some((i, _)) = clips.iter().enumerate().find(|(_, c)| c.cut.len() != n) {
                let span = self.clip_span(i);
                return self.err(
                    span,
                    &format!("clip[{i}].cut"),
                    format!("every clip needs the same number of cuts ({n})"),
                );
            }
        }
        Ok(MocapSpec {
            skeleton: r.skeleton.as_ref().map(|s| self.path(s.get_ref())),
            skeleton_line: r
                .skeleton
                .as_ref()
                .map_or_else(|| self.line(&m.span()), |s| self.line(&s.span())),
            scale,
            fps,
            every,
            forward,
            end_sites: r.end_sites.unwrap_or(false),
            clips,
        })
    }

    fn clip_span(&self, i: usize) -> std::ops::Range<usize> {
        let mut at = 0;
        for _ in 0..=i {
            at = self.src.text[at..]
                .find("[[clip]]")
                .map_or(at, |k| at + k + 1);
        }
        at.saturating_sub(1)..at
    }

    fn step(&self, v: Option<&Spanned<usize>>, field: &str) -> Result<Option<usize>, InputError> {
        match v {
            Some(s) if *s.get_ref() == 0 => self.err(s.span(), field, "must be at least 1"),
            Some(s) => Ok(Some(*s.get_ref())),
            None => Ok(None),
        }
    }

    fn clip(&self, c: &Spanned<RawClip>, i: usize, kind: Kind) -> Result<ClipSpec, InputError> {
        let r = c.get_ref();
        let field = |f: &str| format!("clip[{i}].{f}");
        if let Some(f) = &r.frames {
            if kind == Kind::Clips {
                return self.err(
                    f.span(),
                    &field("frames"),
                    "a motion table cuts clips with `cut`, not `frames`",
                );
            }
            if let Some(bad) = f.get_ref().iter().find(|[a, b]| a > b) {
                return self.err(
                    f.span(),
                    &field("frames"),
                    format!("range [{}, {}] is empty (first > last)", bad[0], bad[1]),
                );
            }
        }
        let cut = match (&r.cut, kind) {
            (Some(cut), Kind::Clips) => {
                let v = cut.get_ref();
                if v.len() < 2 || v.windows(2).any(|w| w[0] >= w[1]) {
                    return self.err(cut.span(), &field("cut"), "needs at least 2 increasing frame numbers (first, [phase boundaries,] last)");
                }
                v.clone()
            }
            (None, Kind::Clips) => {
                return self.err(
                    c.span(),
                    &field("cut"),
                    "a motion table needs each clip's `cut = [first, ..., last]`",
                );
            }
            (Some(cut), Kind::Grid) => {
                return self.err(
                    cut.span(),
                    &field("cut"),
                    "`cut` is for motion tables (kind = \"clips\")",
                );
            }
            (None, Kind::Grid) => Vec::new(),
        };
        let file = self.path(r.file.get_ref());
        let name = file.file_stem().map_or_else(
            || r.file.get_ref().clone(),
            |s| s.to_string_lossy().into_owned(),
        );
        let fps = match &r.fps {
            Some(f) if !(f.get_ref().is_finite() && *f.get_ref() > 0.0) => {
                return self.err(f.span(), &field("fps"), "must be a finite number > 0");
            }
            f => f.as_ref().map(|f| *f.get_ref()),
        };
        Ok(ClipSpec {
            file,
            name,
            fps,
            frames: r.frames.as_ref().map(|f| f.get_ref().clone()),
            every: self.step(r.every.as_ref(), &field("every"))?,
            cut,
            params: r.params.as_ref().map(|p| p.get_ref().clone()),
            line: self.line(&r.file.span()),
        })
    }

    fn axes(
        &self,
        raw: &[Spanned<RawAxis>],
        input: &Input,
        kind: Kind,
    ) -> Result<Vec<AxisSpec>, InputError> {
        if let Input::Examples(_) = input {
            if let Some(a) = raw.first() {
                return self.err(a.span(), "axis", "a JSON example set defines its own axes");
            }
            return Ok(Vec::new());
        }
        let max = if kind == Kind::Clips {
            super::examples::MAX_AXES - 1
        } else {
            super::examples::MAX_AXES
        };
        if raw.is_empty() || raw.len() > max {
            return self.err(
                0..0,
                "axis",
                format!("expected 1 to {max} [[axis]] tables, found {}", raw.len()),
            );
        }
        let axes = raw
            .iter()
            .enumerate()
            .map(|(i, a)| self.axis(a, i, kind))
            .collect::<Result<Vec<_>, _>>()?;
        if let Input::Mocap(m) = input {
            let explicit = axes.iter().any(|a| a.measure == Measure::Explicit);
            for (i, c) in m.clips.iter().enumerate() {
                match &c.params {
                    Some(p) if p.len() != axes.len() => {
                        return Err(self.src.error_line(
                            c.line,
                            &format!("clip[{i}].params"),
                            format!(
                                "expected {} parameters (one per axis), found {}",
                                axes.len(),
                                p.len()
                            ),
                        ));
                    }
                    None if explicit => {
                        return Err(self.src.error_line(
                            c.line,
                            &format!("clip[{i}].params"),
                            "an axis without `segment` or `measure` needs `params` on every clip",
                        ));
                    }
                    _ => {}
                }
            }
        }
        Ok(axes)
    }

    fn axis(&self, a: &Spanned<RawAxis>, i: usize, kind: Kind) -> Result<AxisSpec, InputError> {
        let r = a.get_ref();
        let field = |f: &str| format!("axis[{i}].{f}");
        if let Err(p) = super::examples::check_name(r.name.get_ref()) {
            return self.err(r.name.span(), &field("name"), p);
        }
        let measure = match (&r.segment, &r.component, &r.measure) {
            (Some(s), Some(c), None) => {
                let component = match c.get_ref().as_str() {
                    "x" => 0,
                    "y" => 1,
                    "z" => 2,
                    other => {
                        return self.err(
                            c.span(),
                            &field("component"),
                            format!("expected \"x\", \"y\" or \"z\", found {other:?}"),
                        );
                    }
                };
                let point = match &r.point {
                    Some(p) if !p.get_ref().iter().all(|c| c.is_finite()) => {
                        return self.err(p.span(), &field("point"), "must be finite");
                    }
                    Some(p) => *p.get_ref(),
                    None => [0.0; 3],
                };
                Measure::Position {
                    segment: s.get_ref().clone(),
                    component,
                    point,
                }
            }
            (None, None, Some(m)) if r.point.is_some() => {
                return self.err(m.span(), &field("point"), "`point` needs `segment`");
            }
            (None, None, Some(m)) => match (m.get_ref().as_str(), kind) {
                ("speed", Kind::Clips) => Measure::Speed,
                ("speed", Kind::Grid) => {
                    return self.err(
                        m.span(),
                        &field("measure"),
                        "\"speed\" needs a motion table (kind = \"clips\")",
                    );
                }
                (other, _) => {
                    return self.err(
                        m.span(),
                        &field("measure"),
                        format!("expected \"speed\", found {other:?}"),
                    );
                }
            },
            (None, None, None) if r.point.is_some() => {
                return self.err(a.span(), &field("point"), "`point` needs `segment`");
            }
            (None, None, None) => Measure::Explicit,
            (Some(s), None, _) => {
                return self.err(
                    s.span(),
                    &field("component"),
                    "`segment` needs `component = \"x\" | \"y\" | \"z\"`",
                );
            }
            (None, Some(c), _) => {
                return self.err(c.span(), &field("segment"), "`component` needs `segment`");
            }
            (Some(s), Some(_), Some(_)) => {
                return self.err(
                    s.span(),
                    &field("measure"),
                    "give `segment` + `component` or `measure`, not both",
                );
            }
        };
        let spec = AxisSpec {
            name: r.name.get_ref().clone(),
            measure,
            min: r.min,
            max: r.max,
            count: *r.count.get_ref(),
            cyclic: r.cyclic,
            cubic: r.cubic,
            line: self.line(&a.span()),
        };
        // Check what can be checked before the data fills in the range.
        let probe = spec.def(
            spec.min.unwrap_or(0.0),
            spec.max.unwrap_or(spec.min.unwrap_or(0.0) + 1.0),
        );
        if let Err(p) = probe.check() {
            let span = if spec.count < 2 {
                r.count.span()
            } else {
                a.span()
            };
            return self.err(span, &format!("axis[{i}]"), p);
        }
        Ok(spec)
    }

    fn rig(&self, r: Option<&Spanned<RawRig>>) -> Result<RigSpec, InputError> {
        let Some(r) = r else {
            return Ok(RigSpec {
                file: None,
                align_rest: false,
                retarget: None,
                scale: 1.0,
                lengths: BTreeMap::new(),
                names: NameMap::default(),
                line: 0,
            });
        };
        let g = r.get_ref();
        let file = match &g.file {
            Some(f) if g.scale.is_some() || !g.lengths.is_empty() => {
                return self.err(
                    f.span(),
                    "rig.file",
                    "a rig file has its own proportions: drop `scale` and `lengths`",
                );
            }
            Some(f) => {
                let p = self.path(f.get_ref());
                let p = if p.exists() {
                    p
                } else {
                    crate::rigfile::resolve(Path::new(f.get_ref()))
                };
                if !p.is_file() {
                    let problem = format!(
                        "no rig file {:?} (relative to the spec, or a name in rigs/)",
                        f.get_ref()
                    );
                    return self.err(f.span(), "rig.file", problem);
                }
                Some(p)
            }
            None => None,
        };
        if let (Some(a), None) = (&g.align_rest, &file) {
            return self.err(
                a.span(),
                "rig.align_rest",
                "needs a rig file (`file = ...`)",
            );
        }
        let retarget = match (&g.retarget, &file) {
            (Some(r), None) => {
                return self.err(r.span(), "rig.retarget", "needs a rig file (`file = ...`)");
            }
            (Some(r), Some(_)) if r.get_ref().trim().is_empty() => {
                return self.err(r.span(), "rig.retarget", "must not be empty");
            }
            (r, _) => r.as_ref().map(|r| r.get_ref().trim().to_owned()),
        };
        let scale = match &g.scale {
            Some(s) if !(s.get_ref().is_finite() && *s.get_ref() > 0.0) => {
                return self.err(s.span(), "rig.scale", "must be a finite number > 0");
            }
            Some(s) => *s.get_ref(),
            None => 1.0,
        };
        let mut lengths = BTreeMap::new();
        for (k, v) in &g.lengths {
            if !(v.get_ref().is_finite() && *v.get_ref() > 0.0) {
                return self.err(
                    v.span(),
                    &format!("rig.lengths.{k}"),
                    "must be a finite number > 0",
                );
            }
            lengths.insert(k.clone(), *v.get_ref());
        }
        let line = g
            .file
            .as_ref()
            .map_or_else(|| self.line(&r.span()), |f| self.line(&f.span()));
        let names = self.names(g, line)?;
        if let (Some(_), false) = (&file, names.is_empty()) {
            return self.err(
                r.span(),
                "rig.strip_prefix",
                "`strip_prefix`, `rename`, `drop` and `keep` shape a rig made from the skeleton; a rig file maps names with its [[retarget.map]]",
            );
        }
        Ok(RigSpec {
            names,
            align_rest: g.align_rest.as_ref().is_some_and(|a| *a.get_ref()),
            retarget,
            file,
            scale,
            lengths,
            line,
        })
    }

    fn names(&self, g: &RawRig, line: usize) -> Result<NameMap, InputError> {
        let at = |span: Option<std::ops::Range<usize>>| span.map_or(line, |s| self.line(&s));
        for (k, v) in &g.rename {
            if v.get_ref().is_empty() {
                return self.err(v.span(), &format!("rig.rename.{k}"), "must not be empty");
            }
        }
        let rename_line = g.rename.values().next().map(Spanned::span);
        Ok(NameMap {
            strip_prefix: g.strip_prefix.as_ref().map(|p| p.get_ref().clone()),
            rename: g
                .rename
                .iter()
                .map(|(k, v)| (k.clone(), v.get_ref().clone()))
                .collect(),
            drop: g
                .drop
                .as_ref()
                .map(|d| d.get_ref().clone())
                .unwrap_or_default(),
            keep: g
                .keep
                .as_ref()
                .map(|d| d.get_ref().clone())
                .unwrap_or_default(),
            lines: [
                at(g.strip_prefix.as_ref().map(Spanned::span)),
                at(rename_line),
                at(g.drop.as_ref().map(Spanned::span)),
                at(g.keep.as_ref().map(Spanned::span)),
            ],
        })
    }

    fn motion(&self, m: Option<&Spanned<RawMotion>>, kind: Kind) -> Result<MotionSpec, InputError> {
        if kind == Kind::Grid {
            if let Some(m) = m {
                return self.err(
                    m.span(),
                    "motion",
                    "[motion] is for motion tables (kind = \"clips\")",
                );
            }
            return Ok(MotionSpec {
                frames: 0,
                looping: false,
                seam_window: 0,
                seam_search: 0,
            });
        }
        let r = m.map(Spanned::get_ref);
        let frames = match r.and_then(|r| r.frames.as_ref()) {
            Some(f) if *f.get_ref() < 2 => {
                return self.err(
                    f.span(),
                    "motion.frames",
                    "needs at least 2 frames per phase",
                );
            }
            Some(f) => *f.get_ref(),
            None => 32,
        };
        let looping = r.and_then(|r| r.looping).unwrap_or(false);
        let seam_window = match r.and_then(|r| r.seam_window.as_ref()) {
            Some(w) if *w.get_ref() == 0 || 2 * *w.get_ref() > frames => {
                return self.err(
                    w.span(),
                    "motion.seam_window",
                    format!("must be 1 to frames / 2 = {}", frames / 2),
                );
            }
            Some(w) => *w.get_ref(),
            None => (frames / 8).max(1),
        };
        let seam_search = match r.and_then(|r| r.seam_search.as_ref()) {
            Some(w) if !looping => {
                return self.err(w.span(), "motion.seam_search", "needs looping = true");
            }
            Some(w) if *w.get_ref() > MAX_SEAM_SEARCH => {
                return self.err(
                    w.span(),
                    "motion.seam_search",
                    format!("must be at most {MAX_SEAM_SEARCH} frames"),
                );
            }
            Some(w) => *w.get_ref(),
            None => 0,
        };
        Ok(MotionSpec {
            frames,
            looping,
            seam_window,
            seam_search,
        })
    }

    fn resample(&self, r: Option<&Spanned<RawResample>>) -> Result<ResampleSpec, InputError> {
        let g = r.map(Spanned::get_ref);
        let method = match g.and_then(|g| g.method.as_ref()) {
            Some(m) if ["auto", "idw", "rbf", "local-linear"].contains(&m.get_ref().as_str()) => {
                m.get_ref().clone()
            }
            Some(m) => {
                return self.err(
                    m.span(),
                    "resample.method",
                    format!(
                        "expected \"auto\", \"idw\", \"rbf\" or \"local-linear\", found {:?}",
                        m.get_ref()
                    ),
                );
            }
            None => "auto".to_owned(),
        };
        let valid_radius = match g.and_then(|g| g.valid_radius.as_ref()) {
            Some(v) if !(v.get_ref().is_finite() && *v.get_ref() > 0.0) => {
                return self.err(
                    v.span(),
                    "resample.valid_radius",
                    "must be a finite number > 0 (cells)",
                );
            }
            v => v.map(|v| *v.get_ref()),
        };
        let line = match (g.and_then(|g| g.valid_radius.as_ref()), r) {
            (Some(v), _) => self.line(&v.span()),
            (None, Some(r)) => self.line(&r.span()),
            (None, None) => 0,
        };
        Ok(ResampleSpec {
            method,
            valid_radius,
            line,
            enforce_lengths: g.and_then(|g| g.enforce_lengths).unwrap_or(true),
            place_probe: g.and_then(|g| g.place_probe).unwrap_or(true),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_text(text: &str) -> Result<Spec, InputError> {
        parse(
            Source {
                file: "s.toml".into(),
                text: text.into(),
            },
            PathBuf::from("/d"),
        )
    }

    const GOOD: &str = r#"kind = "grid"
[mocap]
skeleton = "a.asf"
every = 2

[[clip]]
file = "c1.amc"

[[axis]]
name = "x"
segment = "rhand"
component = "x"
count = 4
"#;

    #[test]
    fn parses_a_mocap_grid_spec() {
        let s = parse_text(GOOD).unwrap();
        assert_eq!(s.kind, Kind::Grid);
        let Input::Mocap(m) = &s.input else { panic!() };
        assert_eq!(m.every, 2);
        assert_eq!(m.clips[0].file, PathBuf::from("/d/c1.amc"));
        assert_eq!(m.clips[0].name, "c1");
        assert_eq!(
            s.axes[0].measure,
            Measure::Position {
                segment: "rhand".into(),
                component: 0,
                point: [0.0; 3],
            }
        );
        assert_eq!(s.resample.method, "auto");
    }

    #[test]
    fn stand_frame_point_and_retarget_map() {
        let text = GOOD
            .replace("kind = \"grid\"", "kind = \"grid\"\nframe = \"stand\"")
            .replace("count = 4", "count = 4\npoint = [0, -0.15, 0]");
        let s = parse_text(&format!("{text}[rig]\nfile = \"/\"\n")).unwrap_err();
        assert_eq!(s.field, "rig.file", "{s}");
        let s = parse_text(&text).unwrap();
        assert_eq!(s.frame, FrameKind::Stand);
        assert_eq!(
            s.axes[0].measure,
            Measure::Position {
                segment: "rhand".into(),
                component: 0,
                point: [0.0, -0.15, 0.0],
            }
        );
        let clips = "kind = \"clips\"\nframe = \"stand\"\n";
        let e = parse_text(&format!(
            "{clips}[mocap]\n[[clip]]\nfile = \"a.bvh\"\ncut = [0, 9]\n"
        ))
        .unwrap_err();
        assert_eq!((e.line, e.field.as_str()), (2, "frame"));
        let e = parse_text(&format!("{GOOD}[rig]\nretarget = \"hdm05\"\n")).unwrap_err();
        assert_eq!((e.line, e.field.as_str()), (15, "rig.retarget"));
        let e = parse_text(&GOOD.replace(
            "segment = \"rhand\"\ncomponent = \"x\"",
            "measure = \"speed\"\npoint = [0, 0, 0]",
        ))
        .unwrap_err();
        assert_eq!(e.field, "axis[0].point", "{e}");
    }

    #[test]
    fn errors_name_file_line_and_field() {
        let e = parse_text(&GOOD.replace("count = 4", "count = 1")).unwrap_err();
        assert_eq!(
            (e.file.as_str(), e.line, e.field.as_str()),
            ("s.toml", 13, "axis[0]")
        );
        let e = parse_text(&GOOD.replace("component = \"x\"", "component = \"w\"")).unwrap_err();
        assert_eq!((e.line, e.field.as_str()), (12, "axis[0].component"));
        let e = parse_text(&GOOD.replace("every = 2", "every = \"two\"")).unwrap_err();
        assert_eq!((e.line, e.field.as_str()), (4, "mocap.every"));
        let e = parse_text(&GOOD.replace("every = 2", "evry = 2")).unwrap_err();
        assert_eq!((e.line, e.field.as_str()), (4, "mocap.evry"));
        assert!(e.problem.contains("evry"), "{e}");
        let e = parse_text(&GOOD.replace("kind = \"grid\"", "kind = \"table\"")).unwrap_err();
        assert_eq!((e.line, e.field.as_str()), (1, "kind"));
    }

    #[test]
    fn glob_matches_runs_of_characters() {
        for (p, n) in [
            ("*", ""),
            ("*Twist*", "L_ThighTwist01"),
            ("L_*", "L_Hand"),
            ("*Toe1", "L_BigToe1"),
            ("Head", "Head"),
            ("a*b*c", "abxbc"),
        ] {
            assert!(glob(p, n), "{p} {n}");
        }
        for (p, n) in [
            ("Head", "Heads"),
            ("*Toe1", "L_ToeBase"),
            ("L_*", "R_Hand"),
            ("a*b*c", "acb"),
            ("ab*ba", "aba"),
        ] {
            assert!(!glob(p, n), "{p} {n}");
        }
    }
}
