//! Pictures: a figure in four views (`marionette render`) and curves over time
//! (`marionette plot`).
//!
//! # Four views
//!
//! [`render`] draws a [`Figure`] (a stick figure: bones as lines, touch points
//! as dots, goals as target markers joined to their touch points) the way
//! POSIT's Figure 2 shows the body and its goals: "four simultaneous views:
//! three orthogonal and one perspective" (Badler, Manoochehri & Walters 1987).
//! The panels, in reading order:
//!
//! | panel | horizontal | vertical | looking |
//! |---|---|---|---|
//! | front | +X | +Y | from +Z (the figure faces +Z) towards −Z |
//! | side | +Z | +Y | from −X (the figure's right) towards +X |
//! | top | +X | −Z (front at the bottom) | from +Y down |
//! | perspective | | | from a [`Camera`] above and in front |
//!
//! The three orthographic panels share one scale (metres per pixel is the
//! same horizontally and vertically, and in all three), so lengths compare
//! across them; the floor (`y = 0`, or the lowest point if the figure floats
//! well above or below it) is drawn as a line in the front and side views
//! and as a grid in the perspective view. Left-side segments are blue,
//! right-side ones red, the rest dark grey.
//!
//! A figure is built from a body and a world pose with
//! [`Figure::from_world`] (or [`Figure::from_pose`] for a core
//! [`Pose`]), so `sim`/`emulate` can render frames too.
//!
//! # Curves
//!
//! [`plot`] draws a [`Series`] (a time column and numeric columns, as read by
//! [`Series::parse_csv`]) as lines with a legend and labelled axes.
//!
//! # Output and text
//!
//! The output format follows the extension: `.png` (bitmap) or `.svg`. Text
//! is drawn with a TrueType font found at run time ([`font_available`]):
//! `$MARIONETTE_FONT` if set, otherwise DejaVu Sans or another common sans
//! font from the usual system folders. Without one the pictures are drawn
//! without text, and a warning says so.

use glam::{DQuat, DVec3};
use marionette_core::body::Body;
use marionette_core::pose::Pose;
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Why a picture could not be made.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// The output path has no `.png` or `.svg` extension.
    #[error("{0}: unknown picture format (use a .png or .svg file name)")]
    Format(PathBuf),
    /// The picture size is unusable.
    #[error(
        "picture size {0}x{1} is out of range: each side {MIN_SIDE} to {MAX_SIDE} pixels, \
         at most {MAX_PIXELS} pixels in all"
    )]
    Size(u32, u32),
    /// The pose does not fit the body.
    #[error("pose: {0}")]
    Pose(String),
    /// A CSV file could not be read.
    #[error("CSV line {line}: {reason}")]
    Csv {
        /// 1-based line number (0: the file as a whole).
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// `--columns` names a column the CSV does not have.
    #[error("no column {name:?} (the CSV has: {have})")]
    Column {
        /// The name asked for.
        name: String,
        /// The CSV's data columns, comma-separated.
        have: String,
    },
    /// Nothing to draw.
    #[error("nothing to plot: {0}")]
    Empty(String),
    /// The drawing backend failed (e.g. the file could not be written).
    #[error("drawing {path}: {reason}")]
    Draw {
        /// The output file.
        path: PathBuf,
        /// The backend's message.
        reason: String,
    },
}

// ---------------------------------------------------------------- backends

/// An error from drawing, as text (the backends' error types differ).
type DrawResult = Result<(), String>;

fn de<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// The shortest side of a picture, pixels.
pub const MIN_SIDE: u32 = 200;
/// The longest side of a picture, pixels.
pub const MAX_SIDE: u32 = 8192;
/// The most pixels in a picture: 2²⁵ (a PNG is drawn in memory at 3 bytes a
/// pixel: 96 MiB), checked before any is taken.
pub const MAX_PIXELS: u64 = 1 << 25;

/// Whether a picture of `w` × `h` pixels may be drawn.
pub fn check_size(w: u32, h: u32) -> Result<(), RenderError> {
    let side = MIN_SIDE..=MAX_SIDE;
    if side.contains(&w) && side.contains(&h) && u64::from(w) * u64::from(h) <= MAX_PIXELS {
        Ok(())
    } else {
        Err(RenderError::Size(w, h))
    }
}

/// The picture formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Format {
    Png,
    Svg,
}

impl Format {
    /// The format of `path` by extension; checks the size too.
    fn of(path: &Path, (w, h): (u32, u32)) -> Result<Format, RenderError> {
        check_size(w, h)?;
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("png") => Ok(Format::Png),
            Some("svg") => Ok(Format::Svg),
            _ => Err(RenderError::Format(path.to_path_buf())),
        }
    }
}

/// Runs a drawing function on the PNG or SVG backend for `$path` and writes
/// the file through [`crate::save`]: drawn into a temporary file beside it
/// (folders made), renamed over `$path` only when complete. The body is
/// written once and instantiated for both backends.
macro_rules! with_backend {
    ($format:expr, $path:expr, $size:expr, |$root:ident| $draw:expr) => {{
        let path: &Path = $path;
        let fail = |reason: String| RenderError::Draw {
            path: path.to_path_buf(),
            reason,
        };
        let temp = crate::save::temp_beside(path).map_err(|e| fail(e.to_string()))?;
        match $format {
            Format::Png => {
                let (w, h): (u32, u32) = $size;
                let mut rgb = vec![0u8; w as usize * h as usize * 3];
                {
                    let $root = BitMapBackend::with_buffer(&mut rgb, $size).into_drawing_area();
                    $draw.map_err(fail)?;
                    $root.present().map_err(|e| fail(de(e)))?;
                }
                write_png(temp.path(), &rgb, w, h).map_err(fail)?;
            }
            Format::Svg => {
                let $root = SVGBackend::new(temp.path(), $size).into_drawing_area();
                $draw.map_err(fail)?;
                $root.present().map_err(|e| fail(de(e)))?;
            }
        }
        crate::save::commit(temp, path).map_err(|e| fail(e.to_string()))
    }};
}

/// Writes 8-bit RGB pixels, `w` × `h`, as a PNG file.
fn write_png(path: &Path, rgb: &[u8], w: u32, h: u32) -> Result<(), String> {
    let file = std::fs::File::create(path).map_err(|e| e.to_string())?;
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), w, h);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header().map_err(|e| e.to_string())?;
    writer.write_image_data(rgb).map_err(|e| e.to_string())?;
    writer.finish().map_err(|e| e.to_string())
}

/// Which side of the body a segment is on (it only picks the colour).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// The figure's left (+X at rest).
    Left,
    /// The figure's right (−X at rest).
    Right,
    /// On the midline, or unknown.
    Centre,
}

impl Side {
    /// The side a segment name suggests: `left…`/`…_left…` or CMU's
    /// `LHipJoint`/`LeftArm` style (an `L` or `R` followed by an upper-case
    /// letter), likewise for right. `LowerBack` is not on the left.
    #[must_use]
    pub fn of(name: &str) -> Side {
        let lower = name.to_ascii_lowercase();
        let prefixed = |c: u8| {
            let b = name.as_bytes();
            matches!(b, [first, second, ..] if *first == c && (second.is_ascii_uppercase() || *second == b'_'))
        };
        if lower.contains("left") || prefixed(b'L') || lower.starts_with("l_") {
            Side::Left
        } else if lower.contains("right") || prefixed(b'R') || lower.starts_with("r_") {
            Side::Right
        } else {
            Side::Centre
        }
    }

    fn colour(self) -> RGBColor {
        match self {
            Side::Left => RGBColor(31, 100, 200),
            Side::Right => RGBColor(210, 45, 45),
            Side::Centre => RGBColor(60, 60, 60),
        }
    }
}

/// A line of the stick figure, in world coordinates (metres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bone {
    /// Start (the parent's joint origin).
    pub from: DVec3,
    /// End (the child's joint origin, or a leaf's touch point).
    pub to: DVec3,
    /// Colour group.
    pub side: Side,
}

/// A goal to draw: a target marker, and a line from the point it pulls.
#[derive(Clone, Debug, PartialEq)]
pub struct Mark {
    /// Where the goal wants the point.
    pub target: DVec3,
    /// The body point the goal pulls (its touch point), if known.
    pub from: Option<DVec3>,
    /// Short text drawn beside the target (e.g. `left_hand ×10`).
    pub label: String,
}

/// Everything [`render`] draws, in world coordinates (metres, Y up).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Figure {
    /// Caption above the four views.
    pub title: String,
    /// The stick figure's lines.
    pub bones: Vec<Bone>,
    /// Joint origins (small dots).
    pub joints: Vec<DVec3>,
    /// Touch points (larger dots).
    pub touches: Vec<(DVec3, Side)>,
    /// Goals.
    pub goals: Vec<Mark>,
}

impl Figure {
    /// The stick figure of `body` in a world pose: `world[i]` is segment
    /// `i`'s joint origin and orientation. Bones run from each parent's
    /// origin to its child's; a leaf also gets a bone to its touch point.
    /// Every segment's touch point is a dot.
    pub fn from_world(
        body: &Body<'_>,
        world: &[(DVec3, DQuat)],
        title: impl Into<String>,
    ) -> Result<Figure, RenderError> {
        if world.len() != body.len() {
            return Err(RenderError::Pose(format!(
                "{} segments for a body of {}",
                world.len(),
                body.len()
            )));
        }
        let mut fig = Figure {
            title: title.into(),
            ..Figure::default()
        };
        let mut has_child = vec![false; body.len()];
        for i in 0..body.len() {
            if let Some(flag) = body.parent(i).and_then(|p| has_child.get_mut(p)) {
                *flag = true;
            }
        }
        for (i, (seg, &(origin, _))) in body.segments.iter().zip(world).enumerate() {
            let side = Side::of(seg.name);
            fig.joints.push(origin);
            let touch = touch_point(body, world, i).unwrap_or(origin);
            fig.touches.push((touch, side));
            if let Some((parent_origin, _)) = body.parent(i).and_then(|p| world.get(p)) {
                fig.bones.push(Bone {
                    from: *parent_origin,
                    to: origin,
                    side,
                });
            }
            if !has_child.get(i).copied().unwrap_or(true) && touch != origin {
                fig.bones.push(Bone {
                    from: origin,
                    to: touch,
                    side,
                });
            }
        }
        Ok(fig)
    }

    /// [`Figure::from_world`] for a core pose (f32, as the solver and
    /// synthesis produce it).
    pub fn from_pose<const N: usize>(
        body: &Body<'_>,
        pose: &Pose<N>,
        title: impl Into<String>,
    ) -> Result<Figure, RenderError> {
        let world: Vec<(DVec3, DQuat)> = pose
            .positions()
            .iter()
            .zip(pose.rotations())
            .map(|(p, q)| (p.as_dvec3(), q.as_dquat()))
            .collect();
        Figure::from_world(body, &world, title)
    }

    /// Every point drawn (for framing).
    fn points(&self) -> impl Iterator<Item = DVec3> + '_ {
        self.bones
            .iter()
            .flat_map(|b| [b.from, b.to])
            .chain(self.joints.iter().copied())
            .chain(self.touches.iter().map(|t| t.0))
            .chain(
                self.goals
                    .iter()
                    .flat_map(|g| std::iter::once(g.target).chain(g.from)),
            )
            .filter(|p| p.is_finite())
    }
}

/// The world position of segment `i`'s touch point in a world pose.
#[must_use]
pub fn touch_point(body: &Body<'_>, world: &[(DVec3, DQuat)], i: usize) -> Option<DVec3> {
    let seg = body.segment(i)?;
    let (origin, rotation) = world.get(i)?;
    Some(*origin + *rotation * seg.touch.as_dvec3())
}

/// Where the perspective view looks from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Degrees from the front (+Z) towards the figure's left (+X).
    pub azimuth_deg: f64,
    /// Degrees above the horizon.
    pub elevation_deg: f64,
    /// Vertical field of view, degrees.
    pub fov_deg: f64,
}

impl Default for Camera {
    fn default() -> Self {
        Camera {
            azimuth_deg: 35.0,
            elevation_deg: 20.0,
            fov_deg: 35.0,
        }
    }
}

/// Size and camera of a [`render`]ed picture.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// The perspective view's camera.
    pub camera: Camera,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            width: 1200,
            height: 1200,
            camera: Camera::default(),
        }
    }
}

/// Draws `fig` in four views into `path` (`.png` or `.svg`), 1200×1200.
pub fn render(fig: &Figure, path: &Path) -> Result<(), RenderError> {
    render_with(fig, path, &RenderOptions::default())
}

/// [`render`] with a chosen size and camera.
pub fn render_with(fig: &Figure, path: &Path, opt: &RenderOptions) -> Result<(), RenderError> {
    let format = Format::of(path, (opt.width, opt.height))?;
    with_backend!(format, path, (opt.width, opt.height), |root| draw_figure(
        &root, fig, opt
    ))
}

// ---------------------------------------------------------------- text

/// Font files tried, in order, when `$MARIONETTE_FONT` is not set.
const FONT_PATHS: &[&str] = &[
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu-sans-fonts/DejaVuSans.ttf",
    "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
    "/usr/share/fonts/liberation-sans/LiberationSans-Regular.ttf",
    "/System/Library/Fonts/Supplemental/Arial.ttf",
    "/Library/Fonts/Arial.ttf",
    "C:\\Windows\\Fonts\\arial.ttf",
];

/// The family name text is drawn with.
const FAMILY: &str = "sans-serif";

/// Whether text can be drawn: loads the font on first use (see the module
/// doc) and warns once on standard error if there is none.
pub fn font_available() -> bool {
    static LOADED: OnceLock<bool> = OnceLock::new();
    *LOADED.get_or_init(|| match load_font() {
        Ok(()) => true,
        Err(msg) => {
            eprintln!("marionette: warning: {msg}; pictures are drawn without text");
            false
        }
    })
}

fn load_font() -> Result<(), String> {
    let candidates: Vec<PathBuf> = match std::env::var_os("MARIONETTE_FONT") {
        Some(p) => vec![PathBuf::from(p)],
        None => FONT_PATHS
            .iter()
            .map(PathBuf::from)
            .chain(fc_match())
            .collect(),
    };
    for path in &candidates {
        if let Ok(bytes) = std::fs::read(path) {
            // plotters keeps registered fonts for the life of the process.
            let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
            if plotters::style::register_font(FAMILY, FontStyle::Normal, bytes).is_ok() {
                return Ok(());
            }
        }
    }
    Err(match std::env::var_os("MARIONETTE_FONT") {
        Some(p) => format!(
            "MARIONETTE_FONT={} is not a readable TrueType font",
            Path::new(&p).display()
        ),
        None => "no TrueType font found (install fonts-dejavu-core or set MARIONETTE_FONT)".into(),
    })
}

/// fontconfig's choice of sans font, if `fc-match` is installed.
fn fc_match() -> Option<PathBuf> {
    let out = std::process::Command::new("fc-match")
        .args(["--format=%{file}", FAMILY])
        .output()
        .ok()?;
    let file = String::from_utf8(out.stdout).ok()?;
    (out.status.success() && !file.is_empty()).then(|| PathBuf::from(file))
}

/// Draws `s` at `at` (anchored by `pos`) if a font is available.
fn text<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    s: &str,
    at: (i32, i32),
    size: f64,
    colour: RGBColor,
    pos: Pos,
) -> DrawResult {
    if s.is_empty() || !font_available() {
        return Ok(());
    }
    let style = (FAMILY, size).into_font().color(&colour).pos(pos);
    area.draw_text(s, &style, at).map_err(de)
}

const LEFT_TOP: Pos = Pos {
    h_pos: HPos::Left,
    v_pos: VPos::Top,
};
const LEFT_CENTRE: Pos = Pos {
    h_pos: HPos::Left,
    v_pos: VPos::Center,
};
const CENTRE: Pos = Pos {
    h_pos: HPos::Center,
    v_pos: VPos::Center,
};

// ---------------------------------------------------------------- four views

/// Colour of goals (markers, lines, labels).
const GOAL: RGBColor = RGBColor(0, 140, 70);
/// Colour of the floor and panel frames.
const FAINT: RGBColor = RGBColor(200, 200, 200);
/// Colour of axis indicators and scale bars.
const GUIDE: RGBColor = RGBColor(120, 120, 120);

/// One of the four panels.
#[derive(Clone, Copy, Debug)]
enum View {
    Front,
    Side,
    Top,
    Perspective(Eye),
}

impl View {
    fn label(self) -> &'static str {
        match self {
            View::Front => "front (XY)",
            View::Side => "side (ZY)",
            View::Top => "top (XZ)",
            View::Perspective(_) => "perspective",
        }
    }

    /// The point in the view's plane, Y of the plane up (metres for the
    /// orthographic views, tangent of the angle for the perspective one).
    fn uv(self, p: DVec3) -> Option<(f64, f64)> {
        match self {
            View::Front => Some((p.x, p.y)),
            View::Side => Some((p.z, p.y)),
            View::Top => Some((p.x, -p.z)),
            View::Perspective(eye) => eye.uv(p),
        }
    }

    /// Names and screen directions (x right, y up) of the view's axes, for
    /// the little axis indicator.
    fn axes(self) -> [(&'static str, (f64, f64)); 2] {
        match self {
            View::Front => [("x", (1.0, 0.0)), ("y", (0.0, 1.0))],
            View::Side => [("z", (1.0, 0.0)), ("y", (0.0, 1.0))],
            View::Top => [("x", (1.0, 0.0)), ("z", (0.0, -1.0))],
            View::Perspective(_) => [("", (0.0, 0.0)); 2],
        }
    }
}

/// A pinhole camera looking at the figure.
#[derive(Clone, Copy, Debug)]
struct Eye {
    position: DVec3,
    right: DVec3,
    up: DVec3,
    forward: DVec3,
}

impl Eye {
    fn new(camera: &Camera, centre: DVec3, radius: f64) -> Eye {
        let az = camera.azimuth_deg.to_radians();
        let el = camera.elevation_deg.clamp(-85.0, 85.0).to_radians();
        let half_fov = (camera.fov_deg.clamp(5.0, 150.0) / 2.0).to_radians();
        let towards_eye = DVec3::new(az.sin() * el.cos(), el.sin(), az.cos() * el.cos());
        let distance = radius.max(0.1) / half_fov.sin() * 1.6;
        let forward = -towards_eye;
        let right = forward.cross(DVec3::Y).normalize();
        Eye {
            position: centre + towards_eye * distance,
            right,
            up: right.cross(forward),
            forward,
        }
    }

    fn uv(&self, p: DVec3) -> Option<(f64, f64)> {
        let d = p - self.position;
        let depth = d.dot(self.forward);
        (depth > 1e-3).then(|| (d.dot(self.right) / depth, d.dot(self.up) / depth))
    }
}

/// The figure's bounding box and floor.
#[derive(Clone, Copy, Debug)]
struct Bounds {
    min: DVec3,
    max: DVec3,
    floor: f64,
}

impl Bounds {
    fn of(fig: &Figure) -> Bounds {
        let (mut min, mut max) = fig.points().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(p), hi.max(p)),
        );
        if !min.is_finite() || !max.is_finite() {
            (min, max) = (DVec3::splat(-0.5), DVec3::splat(0.5));
        }
        // Stand on y = 0 unless the figure is far from it.
        let floor = if (-0.05..0.3).contains(&min.y) {
            0.0
        } else {
            min.y
        };
        min.y = min.y.min(floor);
        Bounds { min, max, floor }
    }

    fn centre(&self) -> DVec3 {
        (self.min + self.max) * 0.5
    }

    /// Half the side of the floor grid, centred under the figure.
    fn floor_half(&self) -> f64 {
        let d = self.max - self.min;
        d.x.max(d.z) * 0.5 + 0.1
    }

    fn floor_step(&self) -> f64 {
        nice(self.floor_half() / 3.0)
    }

    /// The floor grid's square: centre x and z (on the grid), half side, step.
    fn floor_square(&self) -> (f64, f64, f64, f64) {
        let (c, g, step) = (self.centre(), self.floor_half(), self.floor_step());
        let n = (g / step).ceil();
        let (x0, z0) = ((c.x / step).round() * step, (c.z / step).round() * step);
        (x0, z0, n * step, step)
    }

    /// The floor grid's lines (pairs of points).
    fn floor_grid(&self) -> Vec<(DVec3, DVec3)> {
        let (x0, z0, span, step) = self.floor_square();
        let n = (span / step).round() as i32;
        (-n..=n)
            .flat_map(|i| {
                let k = f64::from(i) * step;
                [
                    (
                        DVec3::new(x0 + k, self.floor, z0 - span),
                        DVec3::new(x0 + k, self.floor, z0 + span),
                    ),
                    (
                        DVec3::new(x0 - span, self.floor, z0 + k),
                        DVec3::new(x0 + span, self.floor, z0 + k),
                    ),
                ]
            })
            .collect()
    }
}

/// The smallest of 1, 2, 2.5, 5 × 10ⁿ at least `x`.
fn nice(x: f64) -> f64 {
    if !(x.is_finite() && x > 0.0) {
        return 1.0;
    }
    let decade = 10f64.powf(x.log10().floor());
    [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * decade)
        .find(|v| *v >= x * (1.0 - 1e-9))
        .unwrap_or(10.0 * decade)
}

/// Maps a view's plane onto a panel's pixels: uniform scale, Y up.
#[derive(Clone, Copy, Debug)]
struct Projector {
    view: View,
    /// Pixels per plane unit.
    scale: f64,
    /// Plane point at the centre of the drawing region.
    centre: (f64, f64),
    /// Pixel centre of the drawing region.
    pixel: (f64, f64),
}

impl Projector {
    fn px(&self, p: DVec3) -> Option<(i32, i32)> {
        let (u, v) = self.view.uv(p)?;
        let x = self.pixel.0 + (u - self.centre.0) * self.scale;
        let y = self.pixel.1 - (v - self.centre.1) * self.scale;
        (x.is_finite() && y.is_finite() && x.abs() < 1e6 && y.abs() < 1e6)
            .then(|| (x.round() as i32, y.round() as i32))
    }
}

/// The plane extents (umin, umax, vmin, vmax) of `points` in `view`.
fn extents(view: View, points: impl Iterator<Item = DVec3>) -> Option<[f64; 4]> {
    points.filter_map(|p| view.uv(p)).fold(None, |acc, (u, v)| {
        let [a, b, c, d] = acc.unwrap_or([u, u, v, v]);
        Some([a.min(u), b.max(u), c.min(v), d.max(v)])
    })
}

/// Layout of a panel: its drawing region inside the frame and label strip.
struct Region {
    centre: (f64, f64),
    size: (f64, f64),
}

fn region_of<DB: DrawingBackend>(panel: &DrawingArea<DB, Shift>, k: f64) -> Region {
    let (w, h) = panel.dim_in_pixel();
    let (w, h) = (f64::from(w), f64::from(h));
    let (side, top) = (16.0 * k, 36.0 * k);
    Region {
        centre: (w / 2.0, top + (h - top - side) / 2.0),
        size: ((w - 2.0 * side).max(10.0), (h - top - side).max(10.0)),
    }
}

fn draw_figure<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    fig: &Figure,
    opt: &RenderOptions,
) -> DrawResult {
    root.fill(&WHITE).map_err(de)?;
    let (w, h) = root.dim_in_pixel();
    let k = f64::from(w.min(h)) / 1200.0;
    let title_h = (44.0 * k).round() as u32;
    let legend_h = (36.0 * k).round() as u32;
    let (top, rest) = root.split_vertically(title_h);
    let (panels_area, legend) = rest.split_vertically(h.saturating_sub(title_h + legend_h));
    let title = if fig.title.is_empty() {
        "Marionette"
    } else {
        &fig.title
    };
    let at = ((w / 2) as i32, (title_h / 2) as i32);
    text(&top, title, at, 24.0 * k, BLACK, CENTRE)?;

    let bounds = Bounds::of(fig);
    let radius = ((bounds.max - bounds.min) * 0.5).length();
    let eye = Eye::new(&opt.camera, bounds.centre(), radius);
    let views = [View::Front, View::Side, View::Top, View::Perspective(eye)];
    let panels = panels_area.split_evenly((2, 2));
    let region = panels.first().map(|p| region_of(p, k)).ok_or("no panel")?;
    let ortho = ortho_scale(&bounds, &region);
    for (panel, view) in panels.iter().zip(views) {
        let proj = match view {
            View::Perspective(_) => perspective_projector(view, fig, &bounds, &region),
            _ => ortho_projector(view, &bounds, &region, ortho),
        };
        draw_panel(panel, fig, &bounds, proj, k)?;
    }
    draw_legend(&legend, k)
}

/// Pixels per metre shared by the three orthographic views.
fn ortho_scale(b: &Bounds, r: &Region) -> f64 {
    let d = b.max - b.min;
    let pad = |x: f64| x.max(0.3) * 1.12;
    [(d.x, d.y), (d.z, d.y), (d.x, d.z)]
        .iter()
        .map(|&(du, dv)| (r.size.0 / pad(du)).min(r.size.1 / pad(dv)))
        .fold(f64::INFINITY, f64::min)
}

fn ortho_projector(view: View, b: &Bounds, r: &Region, scale: f64) -> Projector {
    let (lo, hi) = (view.uv(b.min), view.uv(b.max));
    let centre = match (lo, hi) {
        (Some(lo), Some(hi)) => ((lo.0 + hi.0) / 2.0, (lo.1 + hi.1) / 2.0),
        _ => (0.0, 0.0),
    };
    Projector {
        view,
        scale,
        centre,
        pixel: r.centre,
    }
}

fn perspective_projector(view: View, fig: &Figure, b: &Bounds, r: &Region) -> Projector {
    let grid = b.floor_grid();
    let points = fig.points().chain(grid.iter().flat_map(|(p, q)| [*p, *q]));
    let [u0, u1, v0, v1] = extents(view, points).unwrap_or([-1.0, 1.0, -1.0, 1.0]);
    let (du, dv) = ((u1 - u0).max(1e-6), (v1 - v0).max(1e-6));
    Projector {
        view,
        scale: (r.size.0 / (du * 1.05)).min(r.size.1 / (dv * 1.05)),
        centre: ((u0 + u1) / 2.0, (v0 + v1) / 2.0),
        pixel: r.centre,
    }
}

fn line<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    proj: &Projector,
    (a, b): (DVec3, DVec3),
    style: ShapeStyle,
) -> DrawResult {
    if let (Some(p), Some(q)) = (proj.px(a), proj.px(b)) {
        area.draw(&PathElement::new(vec![p, q], style))
            .map_err(de)?;
    }
    Ok(())
}

fn draw_panel<DB: DrawingBackend>(
    panel: &DrawingArea<DB, Shift>,
    fig: &Figure,
    b: &Bounds,
    proj: Projector,
    k: f64,
) -> DrawResult {
    let (w, h) = panel.dim_in_pixel();
    let (w, h) = (w as i32, h as i32);
    let inset = (4.0 * k).round() as i32;
    panel
        .draw(&Rectangle::new(
            [(inset, inset), (w - inset, h - inset)],
            FAINT.stroke_width(1),
        ))
        .map_err(de)?;
    let pad = (12.0 * k) as i32;
    text(
        panel,
        proj.view.label(),
        (pad, pad),
        18.0 * k,
        BLACK,
        LEFT_TOP,
    )?;
    let stroke = |c: RGBColor, px: f64| c.stroke_width((px * k).round().max(1.0) as u32);

    // The floor.
    match proj.view {
        View::Front | View::Side => {
            let c = b.centre();
            let half = (b.max - b.min).max_element() + 1.0;
            let (a, z) = (
                DVec3::new(c.x - half, b.floor, c.z - half),
                DVec3::new(c.x + half, b.floor, c.z + half),
            );
            let (a, z) = match proj.view {
                View::Front => (a.with_z(c.z), z.with_z(c.z)),
                _ => (a.with_x(c.x), z.with_x(c.x)),
            };
            if let (Some(p), Some(q)) = (proj.px(a), proj.px(z)) {
                let (x0, x1) = (pad.max(p.0.min(q.0)), (w - pad).min(p.0.max(q.0)));
                panel
                    .draw(&PathElement::new(
                        vec![(x0, p.1), (x1, q.1)],
                        stroke(FAINT, 2.0),
                    ))
                    .map_err(de)?;
            }
        }
        View::Perspective(_) => {
            for seg in b.floor_grid() {
                line(panel, &proj, seg, stroke(FAINT, 1.0))?;
            }
        }
        View::Top => {}
    }

    // Goal lines under the figure, markers on top.
    for g in &fig.goals {
        if let (Some(from), Some(t)) = (g.from.and_then(|f| proj.px(f)), proj.px(g.target)) {
            let dash = (6.0 * k).max(2.0) as i32;
            panel
                .draw(&DashedPathElement::new(
                    vec![from, t],
                    dash,
                    dash,
                    stroke(GOAL, 1.5),
                ))
                .map_err(de)?;
        }
    }
    for bone in &fig.bones {
        line(
            panel,
            &proj,
            (bone.from, bone.to),
            stroke(bone.side.colour(), 3.0),
        )?;
    }
    let r = |px: f64| (px * k).round().max(1.0) as i32;
    for (p, side) in &fig.touches {
        if let Some(c) = proj.px(*p) {
            panel
                .draw(&Circle::new(c, r(4.5), side.colour().filled()))
                .map_err(de)?;
        }
    }
    for p in &fig.joints {
        if let Some(c) = proj.px(*p) {
            panel
                .draw(&Circle::new(c, r(2.0), BLACK.filled()))
                .map_err(de)?;
        }
    }
    let mut placed: Vec<LabelBox> = Vec::new();
    for g in &fig.goals {
        if let Some(c) = proj.px(g.target) {
            panel
                .draw(&Cross::new(c, r(7.0), stroke(GOAL, 2.0)))
                .map_err(de)?;
            panel
                .draw(&Circle::new(c, r(8.0), stroke(GOAL, 1.5)))
                .map_err(de)?;
            let size = 14.0 * k;
            let at = place_label(c, g.label.chars().count(), size, &mut placed);
            text(panel, &g.label, at, size, GOAL, LEFT_CENTRE)?;
        }
    }
    draw_guides(panel, b, &proj, k)
}

/// A placed label's box in pixels: left, top, right, bottom.
type LabelBox = (i32, i32, i32, i32);

/// Where a label of `chars` characters at `size` px goes beside the mark at
/// `c` (its left end, vertically centred): the first of eight places around
/// the mark (up-right first, then down-right, left, and further out) whose
/// box overlaps no label already `placed`; the first place if every one
/// does. The width is estimated at 0.62 em per character (sans-serif).
fn place_label(c: (i32, i32), chars: usize, size: f64, placed: &mut Vec<LabelBox>) -> (i32, i32) {
    let w = (chars as f64 * 0.62 * size).ceil() as i32;
    let h = (size * 1.2).ceil() as i32;
    let gap = (size * 0.8).round() as i32;
    let (right, left) = (c.0 + gap, c.0 - gap - w);
    let candidates = [
        (right, c.1 - gap),
        (right, c.1 + gap),
        (left, c.1 - gap),
        (left, c.1 + gap),
        (right, c.1 - gap - h),
        (right, c.1 + gap + h),
        (left, c.1 - gap - h),
        (left, c.1 + gap + h),
    ];
    let boxed = |(x, y): (i32, i32)| (x, y - h / 2, x + w, y + h / 2);
    let overlaps = |a: LabelBox, b: &LabelBox| a.0 < b.2 && b.0 < a.2 && a.1 < b.3 && b.1 < a.3;
    let at = candidates
        .iter()
        .copied()
        .find(|&p| !placed.iter().any(|q| overlaps(boxed(p), q)))
        .unwrap_or(candidates[0]);
    placed.push(boxed(at));
    at
}

/// Axis indicator (bottom left) and scale bar (bottom right) of an
/// orthographic panel; a world axis triad at the floor of the perspective one.
fn draw_guides<DB: DrawingBackend>(
    panel: &DrawingArea<DB, Shift>,
    b: &Bounds,
    proj: &Projector,
    k: f64,
) -> DrawResult {
    let (w, h) = panel.dim_in_pixel();
    let (w, h) = (w as i32, h as i32);
    let stroke = GUIDE.stroke_width((1.5 * k).round().max(1.0) as u32);
    if let View::Perspective(_) = proj.view {
        // At the grid's far left corner, so all three axes lie over the grid.
        let (x0, z0, span, step) = b.floor_square();
        let corner = DVec3::new(x0 - span, b.floor, z0 - span);
        let len = step * 0.6;
        for (name, axis) in [("x", DVec3::X), ("y", DVec3::Y), ("z", DVec3::Z)] {
            let end = corner + axis * len;
            line(panel, proj, (corner, end), stroke)?;
            if let Some(p) = proj.px(end + axis * len * 0.3) {
                text(panel, name, p, 14.0 * k, GUIDE, CENTRE)?;
            }
        }
        return Ok(());
    }
    let len = 40.0 * k;
    let origin = ((24.0 * k) as i32, h - (24.0 * k) as i32 - len as i32 / 2);
    let origin = match proj.view {
        View::Top => (
            origin.0,
            h - (24.0 * k) as i32 - len as i32 - (10.0 * k) as i32,
        ),
        _ => origin,
    };
    for (name, (dx, dy)) in proj.view.axes() {
        let end = (origin.0 + (dx * len) as i32, origin.1 - (dy * len) as i32);
        panel
            .draw(&PathElement::new(vec![origin, end], stroke))
            .map_err(de)?;
        let label = (
            end.0 + (dx * 10.0 * k) as i32,
            end.1 - (dy * 10.0 * k) as i32,
        );
        text(panel, name, label, 14.0 * k, GUIDE, CENTRE)?;
    }
    // Scale bar: a round length of at most a quarter of the panel.
    let metres = nice(f64::from(w) / 4.0 / proj.scale / 2.0);
    let bar = (metres * proj.scale).round() as i32;
    let y = h - (20.0 * k) as i32;
    let x1 = w - (20.0 * k) as i32;
    let tick = (4.0 * k).max(2.0) as i32;
    panel
        .draw(&PathElement::new(
            vec![(x1 - bar, y - tick), (x1 - bar, y), (x1, y), (x1, y - tick)],
            stroke,
        ))
        .map_err(de)?;
    let label = if metres < 1.0 {
        format!("{} cm", (metres * 100.0).round())
    } else {
        format!("{metres} m")
    };
    let at = (x1 - bar / 2, y - (12.0 * k) as i32);
    text(panel, &label, at, 13.0 * k, GUIDE, CENTRE)
}

fn draw_legend<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, k: f64) -> DrawResult {
    let (_, h) = area.dim_in_pixel();
    let y = (h / 2) as i32;
    let mut x = (20.0 * k) as i32;
    let step = (150.0 * k) as i32;
    let sw = |px: f64| (px * k).round().max(1.0) as u32;
    let entries: [(&str, RGBColor); 3] = [
        ("left", Side::Left.colour()),
        ("right", Side::Right.colour()),
        ("midline", Side::Centre.colour()),
    ];
    let seg = (28.0 * k) as i32;
    let gap = (8.0 * k) as i32;
    for (name, colour) in entries {
        area.draw(&PathElement::new(
            vec![(x, y), (x + seg, y)],
            colour.stroke_width(sw(3.0)),
        ))
        .map_err(de)?;
        text(area, name, (x + seg + gap, y), 15.0 * k, BLACK, LEFT_CENTRE)?;
        x += step;
    }
    let r = |px: f64| (px * k).round().max(1.0) as i32;
    area.draw(&Circle::new((x + seg / 2, y), r(4.5), GUIDE.filled()))
        .map_err(de)?;
    text(
        area,
        "touch point",
        (x + seg + gap, y),
        15.0 * k,
        BLACK,
        LEFT_CENTRE,
    )?;
    x += step;
    area.draw(&DashedPathElement::new(
        vec![(x, y), (x + seg, y)],
        r(6.0),
        r(6.0),
        GOAL.stroke_width(sw(1.5)),
    ))
    .map_err(de)?;
    area.draw(&Cross::new(
        (x + seg, y),
        r(7.0),
        GOAL.stroke_width(sw(2.0)),
    ))
    .map_err(de)?;
    text(
        area,
        "goal (from touch point)",
        (x + seg + gap + r(6.0), y),
        15.0 * k,
        BLACK,
        LEFT_CENTRE,
    )
}

// ---------------------------------------------------------------- curves

/// Numeric series over time, as read from a CSV file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Series {
    /// The time axis' label, e.g. `time (s)`.
    pub time_label: String,
    /// Sample times, in the unit of `time_label`.
    pub time: Vec<f64>,
    /// The series, each with one value per time (NaN where a cell is empty).
    pub columns: Vec<Column>,
}

/// One named series.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Column {
    /// The header name.
    pub name: String,
    /// One value per sample time.
    pub values: Vec<f64>,
}

impl Series {
    /// Reads CSV text: a header line, then one line per sample. The first
    /// column is time: `time_us` (microseconds, shown in seconds), `time_ms`,
    /// or `time_s`/`time`/`t` (seconds); another name is used as it is, as
    /// its own label. The other columns are numbers; an empty cell is a gap.
    /// Blank lines and lines starting with `#` are skipped.
    pub fn parse_csv(text: &str) -> Result<Series, RenderError> {
        let mut lines = text
            .lines()
            .enumerate()
            .map(|(i, l)| (i + 1, l.trim()))
            .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
        let (_, header) = lines.next().ok_or_else(|| RenderError::Csv {
            line: 0,
            reason: "no header line".into(),
        })?;
        let names: Vec<&str> = header.split(',').map(str::trim).collect();
        let Some((time_name, column_names)) = names.split_first() else {
            return Err(RenderError::Csv {
                line: 0,
                reason: "empty header".into(),
            });
        };
        let (time_label, to_seconds) = match time_name.to_ascii_lowercase().as_str() {
            "time_us" | "t_us" => ("time (s)".to_string(), 1e-6),
            "time_ms" | "t_ms" => ("time (s)".to_string(), 1e-3),
            "time_s" | "time" | "t" | "t_s" => ("time (s)".to_string(), 1.0),
            _ => ((*time_name).to_string(), 1.0),
        };
        let mut series = Series {
            time_label,
            time: Vec::new(),
            columns: column_names
                .iter()
                .map(|n| Column {
                    name: (*n).to_string(),
                    values: Vec::new(),
                })
                .collect(),
        };
        for (line, l) in lines {
            let cells: Vec<&str> = l.split(',').map(str::trim).collect();
            if cells.len() != names.len() {
                return Err(RenderError::Csv {
                    line,
                    reason: format!("{} fields, the header has {}", cells.len(), names.len()),
                });
            }
            let number = |cell: &str, name: &str| -> Result<f64, RenderError> {
                if cell.is_empty() {
                    return Ok(f64::NAN);
                }
                cell.parse::<f64>().map_err(|_| RenderError::Csv {
                    line,
                    reason: format!("{name}: {cell:?} is not a number"),
                })
            };
            let t = number(cells.first().copied().unwrap_or(""), time_name)?;
            if !t.is_finite() {
                return Err(RenderError::Csv {
                    line,
                    reason: format!("{time_name}: missing or not finite"),
                });
            }
            series.time.push(t * to_seconds);
            for (col, cell) in series.columns.iter_mut().zip(cells.iter().skip(1)) {
                col.values.push(number(cell, &col.name)?);
            }
        }
        Ok(series)
    }

    /// A long table made wide: a recording with one row per `key` value and
    /// time (a tracker recording's `sensor` column) becomes one column per
    /// key value and other column (`sensor 0: x`), on the recording's
    /// distinct times in order, NaN where a key has no row at a time (a gap
    /// in its line). `None` if there is no column `key`, or a key value is
    /// not a whole number.
    #[must_use]
    pub fn split_by(&self, key: &str) -> Option<Series> {
        let k = self.columns.iter().position(|c| c.name == key)?;
        let keys: Vec<i64> = self.columns[k]
            .values
            .iter()
            .map(|v| (v.fract() == 0.0).then_some(*v as i64))
            .collect::<Option<_>>()?;
        let mut ids = keys.clone();
        ids.sort_unstable();
        ids.dedup();
        let mut time: Vec<f64> = Vec::new();
        let mut slot = Vec::with_capacity(self.time.len());
        for &t in &self.time {
            if time.last().is_none_or(|last| last.to_bits() != t.to_bits()) {
                time.push(t);
            }
            slot.push(time.len() - 1);
        }
        let others: Vec<&Column> = self.columns.iter().filter(|c| c.name != key).collect();
        let mut columns = Vec::new();
        for id in &ids {
            for c in &others {
                let mut values = vec![f64::NAN; time.len()];
                for ((row, v), at) in c.values.iter().enumerate().zip(&slot) {
                    if keys[row] == *id {
                        values[*at] = *v;
                    }
                }
                columns.push(Column {
                    name: format!("{key} {id}: {}", c.name),
                    values,
                });
            }
        }
        Some(Series {
            time_label: self.time_label.clone(),
            time,
            columns,
        })
    }

    /// Keeps only the named columns, in the order given.
    pub fn select(&mut self, names: &[String]) -> Result<(), RenderError> {
        let mut picked = Vec::with_capacity(names.len());
        for name in names {
            let col = self
                .columns
                .iter()
                .find(|c| &c.name == name)
                .ok_or_else(|| RenderError::Column {
                    name: name.clone(),
                    have: self
                        .columns
                        .iter()
                        .map(|c| c.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", "),
                })?;
            picked.push(col.clone());
        }
        self.columns = picked;
        Ok(())
    }
}

/// Size and labels of a [`plot`].
#[derive(Clone, Debug, PartialEq)]
pub struct PlotOptions {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Caption above the plot (none if empty).
    pub title: String,
    /// The vertical axis' label.
    pub y_label: String,
}

impl Default for PlotOptions {
    fn default() -> Self {
        PlotOptions {
            width: 1200,
            height: 700,
            title: String::new(),
            y_label: "value".into(),
        }
    }
}

/// Line colours: Kelly's 22 colours of maximum contrast without white and
/// black (K. L. Kelly, "Twenty-two colors of maximum contrast", 1965; sRGB
/// values as commonly tabulated), light yellow replaced by a darker gold so
/// that every line shows on white; past them, plotters' 99-colour palette.
const PALETTE: [RGBColor; 20] = [
    RGBColor(0xF3, 0x84, 0x00), // orange
    RGBColor(0x87, 0x56, 0x92), // purple
    RGBColor(0xA1, 0xCA, 0xF1), // light blue
    RGBColor(0xBE, 0x00, 0x32), // red
    RGBColor(0xC2, 0xB2, 0x80), // buff
    RGBColor(0x84, 0x84, 0x82), // grey
    RGBColor(0x00, 0x88, 0x56), // green
    RGBColor(0xE6, 0x8F, 0xAC), // purplish pink
    RGBColor(0x00, 0x67, 0xA5), // blue
    RGBColor(0xF9, 0x93, 0x79), // yellowish pink
    RGBColor(0x60, 0x4E, 0x97), // violet
    RGBColor(0xF6, 0xA6, 0x00), // orange yellow
    RGBColor(0xB3, 0x44, 0x6C), // purplish red
    RGBColor(0xB8, 0xA4, 0x00), // gold (for Kelly's greenish yellow)
    RGBColor(0x88, 0x2D, 0x17), // reddish brown
    RGBColor(0x8D, 0xB6, 0x00), // yellow green
    RGBColor(0x65, 0x45, 0x22), // yellowish brown
    RGBColor(0xE2, 0x58, 0x22), // reddish orange
    RGBColor(0x2B, 0x3D, 0x26), // olive green
    RGBColor(0x22, 0x22, 0x22), // near black
];

fn colour(i: usize) -> RGBColor {
    PALETTE.get(i).copied().unwrap_or_else(|| {
        let c = Palette99::pick(i).to_rgba();
        RGBColor(c.0, c.1, c.2)
    })
}

/// The legend column's width in pixels for `names` (beside the plot, so
/// that it never covers a curve): 7.5 px per character at 14 px text, plus
/// the line sample, within [120, width / 3].
fn legend_width(names: &[&str], width: u32) -> u32 {
    let longest = names.iter().map(|n| n.chars().count()).max().unwrap_or(0);
    let w = 48 + (longest as f64 * 7.5).ceil() as u32;
    w.clamp(120, (width / 3).max(120))
}

/// Draws every column of `series` against time into `path` (`.png` or
/// `.svg`), with a legend and labelled axes.
pub fn plot(series: &Series, path: &Path, opt: &PlotOptions) -> Result<(), RenderError> {
    let format = Format::of(path, (opt.width, opt.height))?;
    if series.columns.is_empty() {
        return Err(RenderError::Empty("no data column".into()));
    }
    let finite = |v: &&f64| v.is_finite();
    let (t0, t1) = range(series.time.iter().filter(finite).copied())
        .ok_or_else(|| RenderError::Empty("no sample".into()))?;
    let values = series.columns.iter().flat_map(|c| c.values.iter());
    let (y0, y1) = range(values.filter(finite).copied())
        .ok_or_else(|| RenderError::Empty("every value is empty".into()))?;
    let pad_t = if t1 > t0 { 0.0 } else { 0.5 };
    let pad_y = if y1 > y0 { (y1 - y0) * 0.05 } else { 1.0 };
    let x = (t0 - pad_t)..(t1 + pad_t);
    let y = (y0 - pad_y)..(y1 + pad_y);
    with_backend!(format, path, (opt.width, opt.height), |root| draw_plot(
        &root,
        series,
        opt,
        (x.clone(), y.clone())
    ))
}

fn range(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    values.fold(None, |acc, v| {
        let (lo, hi) = acc.unwrap_or((v, v));
        Some((lo.min(v), hi.max(v)))
    })
}

type Ranges = (std::ops::Range<f64>, std::ops::Range<f64>);

fn draw_plot<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    series: &Series,
    opt: &PlotOptions,
    (x, y): Ranges,
) -> DrawResult {
    root.fill(&WHITE).map_err(de)?;
    let font = font_available();
    let names: Vec<&str> = series.columns.iter().map(|c| c.name.as_str()).collect();
    let (plot_area, legend) = if font {
        let (w, _) = root.dim_in_pixel();
        root.split_horizontally(w.saturating_sub(legend_width(&names, w)))
    } else {
        // No font, no legend: the whole area plots.
        root.split_horizontally(root.dim_in_pixel().0)
    };
    let mut builder = ChartBuilder::on(&plot_area);
    builder.margin(16);
    if font {
        builder.x_label_area_size(48).y_label_area_size(80);
        if !opt.title.is_empty() {
            builder.caption(&opt.title, (FAMILY, 22));
        }
    }
    let mut chart = builder.build_cartesian_2d(x, y).map_err(de)?;
    let mut mesh = chart.configure_mesh();
    mesh.light_line_style(RGBColor(235, 235, 235));
    if font {
        mesh.x_desc(&series.time_label)
            .y_desc(&opt.y_label)
            .x_label_formatter(&|v| tick(*v))
            .y_label_formatter(&|v| tick(*v))
            .label_style((FAMILY, 14))
            .axis_desc_style((FAMILY, 16));
    } else {
        mesh.x_labels(0).y_labels(0);
    }
    mesh.draw().map_err(de)?;
    for (i, col) in series.columns.iter().enumerate() {
        let style = colour(i).stroke_width(2);
        for run in runs(&series.time, &col.values) {
            chart.draw_series(LineSeries::new(run, style)).map_err(de)?;
        }
    }
    if font {
        draw_series_legend(&legend, &names)?;
    }
    Ok(())
}

/// The series' names, one per row with its line colour, in their own
/// column beside the plot.
fn draw_series_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    names: &[&str],
) -> DrawResult {
    let (_, h) = area.dim_in_pixel();
    let top = 64;
    let row = (i64::from(h.saturating_sub(top as u32 + 64)) / names.len().max(1) as i64)
        .clamp(1, 22) as i32;
    for (i, name) in names.iter().enumerate() {
        let y = top + row * i32::try_from(i).unwrap_or(i32::MAX / 64);
        area.draw(&PathElement::new(
            vec![(4, y), (28, y)],
            colour(i).stroke_width(3),
        ))
        .map_err(de)?;
        text(area, name, (36, y), 14.0, BLACK, LEFT_CENTRE)?;
    }
    Ok(())
}

/// A tick label: at most six decimals, no trailing zeros (`1900`, `0.25`).
fn tick(v: f64) -> String {
    let text = format!("{v:.6}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    if text == "-0" {
        "0".into()
    } else {
        text.into()
    }
}

/// The stretches of finite samples of one column (a gap splits the line).
fn runs(time: &[f64], values: &[f64]) -> Vec<Vec<(f64, f64)>> {
    let mut out: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
    for (&t, &v) in time.iter().zip(values) {
        if t.is_finite() && v.is_finite() {
            if let Some(run) = out.last_mut() {
                run.push((t, v));
            }
        } else if out.last().is_some_and(|r| !r.is_empty()) {
            out.push(Vec::new());
        }
    }
    out.retain(|r| !r.is_empty());
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn proj(view: View) -> Projector {
        Projector {
            view,
            scale: 100.0,
            centre: (0.0, 0.0),
            pixel: (300.0, 300.0),
        }
    }

    fn px(view: View, x: f64, y: f64, z: f64) -> (i32, i32) {
        proj(view).px(DVec3::new(x, y, z)).unwrap()
    }

    #[test]
    fn orthographic_views_are_y_up_with_one_scale() {
        // Front: +X right, +Y up (pixel y grows downwards).
        assert_eq!(px(View::Front, 0.0, 0.0, 0.0), (300, 300));
        assert_eq!(px(View::Front, 1.0, 0.0, 0.0), (400, 300));
        assert_eq!(px(View::Front, 0.0, 1.0, 0.0), (300, 200));
        assert_eq!(px(View::Front, 0.0, 0.0, 1.0), (300, 300));
        // Side: +Z right, +Y up.
        assert_eq!(px(View::Side, 0.0, 0.0, 1.0), (400, 300));
        assert_eq!(px(View::Side, 0.0, 1.0, 0.0), (300, 200));
        assert_eq!(px(View::Side, 1.0, 0.0, 0.0), (300, 300));
        // Top: +X right, +Z (the figure's front) down.
        assert_eq!(px(View::Top, 1.0, 0.0, 0.0), (400, 300));
        assert_eq!(px(View::Top, 0.0, 0.0, 1.0), (300, 400));
        assert_eq!(px(View::Top, 0.0, 1.0, 0.0), (300, 300));
    }

    #[test]
    fn shared_scale_is_set_by_the_tightest_view() {
        let b = Bounds {
            min: DVec3::new(-0.5, 0.0, -0.1),
            max: DVec3::new(0.5, 2.0, 0.1),
            floor: 0.0,
        };
        let r = Region {
            centre: (200.0, 200.0),
            size: (400.0, 400.0),
        };
        // Height 2 m (+12 %) in 400 px limits front and side; depth 0.2 m is
        // padded to the 0.3 m minimum.
        let want = 400.0 / (2.0 * 1.12);
        assert!((ortho_scale(&b, &r) - want).abs() < 1e-9);
        let front = ortho_projector(View::Front, &b, &r, want);
        // The box centre (0, 1, 0) is drawn at the region centre.
        assert_eq!(front.px(DVec3::new(0.0, 1.0, 0.0)), Some((200, 200)));
    }

    #[test]
    fn perspective_looks_from_the_camera() {
        let camera = Camera {
            azimuth_deg: 0.0,
            elevation_deg: 0.0,
            fov_deg: 40.0,
        };
        let eye = Eye::new(&camera, DVec3::ZERO, 1.0);
        // Straight from the front: like the front view near the centre.
        let (u, v) = eye.uv(DVec3::new(0.1, 0.2, 0.0)).unwrap();
        assert!(u > 0.0 && v > 0.0);
        assert!((v / u - 2.0).abs() < 1e-12);
        // Nearer things look bigger; behind the camera is not drawn.
        let near = eye.uv(DVec3::new(0.1, 0.0, 0.5)).unwrap().0;
        let far = eye.uv(DVec3::new(0.1, 0.0, -0.5)).unwrap().0;
        assert!(near > far && far > 0.0);
        let behind = eye.position + DVec3::Z;
        assert!(eye.uv(behind).is_none());
        // From the figure's left (+X), +Z goes to the right of the screen.
        let side = Eye::new(
            &Camera {
                azimuth_deg: 90.0,
                ..camera
            },
            DVec3::ZERO,
            1.0,
        );
        assert!(side.uv(DVec3::new(0.0, 0.0, -0.1)).unwrap().0 > 0.0);
    }

    #[test]
    fn sides_from_names() {
        for n in ["left_hand", "LeftArm", "LHipJoint", "LThumb", "l_knee"] {
            assert_eq!(Side::of(n), Side::Left, "{n}");
        }
        for n in ["right_foot", "RightUpLeg", "RHipJoint", "r_knee"] {
            assert_eq!(Side::of(n), Side::Right, "{n}");
        }
        for n in [
            "LowerBack",
            "Hips",
            "lower_torso",
            "Head",
            "Spine1",
            "L",
            "",
        ] {
            assert_eq!(Side::of(n), Side::Centre, "{n}");
        }
    }

    #[test]
    fn nice_lengths() {
        let cases = [
            (0.3, 0.5),
            (0.21, 0.25),
            (0.25, 0.25),
            (1.0, 1.0),
            (3.0, 5.0),
            (0.07, 0.1),
            (12.0, 20.0),
        ];
        for (x, want) in cases {
            assert!((nice(x) - want).abs() < 1e-12, "nice({x}) = {}", nice(x));
        }
        assert_eq!(nice(0.0), 1.0);
        assert_eq!(nice(f64::NAN), 1.0);
    }

    #[test]
    fn floor_grid_is_centred_under_the_figure() {
        let b = Bounds {
            min: DVec3::new(-0.3, 0.0, -0.1),
            max: DVec3::new(0.3, 1.8, 0.1),
            floor: 0.0,
        };
        // Half side 0.3 + 0.1 = 0.4, step nice(0.4 / 3) = 0.2, 2 steps each way.
        let (x0, z0, span, step) = b.floor_square();
        assert_eq!((x0, z0, step), (0.0, 0.0, 0.2));
        assert!((span - 0.4).abs() < 1e-12);
        let grid = b.floor_grid();
        assert_eq!(grid.len(), 2 * 5);
        assert!(grid.iter().all(|(p, q)| p.y == 0.0 && q.y == 0.0));
    }

    #[test]
    fn csv_time_units_gaps_and_comments() {
        let text = "# servo targets\ntime_us, ch0 ,ch1\n0,1500,1000\n\n500000,1600,\n1000000,1700.5,1200\n";
        let s = Series::parse_csv(text).unwrap();
        assert_eq!(s.time_label, "time (s)");
        assert_eq!(s.time, vec![0.0, 0.5, 1.0]);
        assert_eq!(s.columns.len(), 2);
        assert_eq!(s.columns[0].name, "ch0");
        assert_eq!(s.columns[0].values, vec![1500.0, 1600.0, 1700.5]);
        assert_eq!(s.columns[1].values[0], 1000.0);
        assert!(s.columns[1].values[1].is_nan());
        let secs = Series::parse_csv("time_s,a\n0.25,1\n").unwrap();
        assert_eq!(secs.time, vec![0.25]);
        let other = Series::parse_csv("frame,a\n7,1\n").unwrap();
        assert_eq!((other.time_label.as_str(), other.time[0]), ("frame", 7.0));
    }

    #[test]
    fn csv_errors_name_the_line() {
        let line = |text: &str| match Series::parse_csv(text) {
            Err(RenderError::Csv { line, .. }) => line,
            other => panic!("{other:?}"),
        };
        assert_eq!(line(""), 0);
        assert_eq!(line("time_us,a\n0,1\n# c\n1,2,3\n"), 4);
        assert_eq!(line("time_us,a\n0,x\n"), 2);
        assert_eq!(line("time_us,a\n,1\n"), 2);
    }

    #[test]
    fn select_keeps_the_order_asked() {
        let mut s = Series::parse_csv("t,a,b,c\n0,1,2,3\n").unwrap();
        s.select(&["c".into(), "a".into()]).unwrap();
        let names: Vec<&str> = s.columns.iter().map(|c| c.name.as_str()).collect();
        assert_eq!(names, ["c", "a"]);
        assert_eq!(s.columns[0].values, vec![3.0]);
        let err = s.select(&["zz".into()]).unwrap_err();
        assert!(err.to_string().contains("\"zz\""), "{err}");
    }

    #[test]
    fn a_recording_splits_by_sensor() {
        // Two sensors at t = 0 and 1 ms, sensor 1 missing at 2 ms.
        let text = "time_us,sensor,x\n0,0,1\n0,1,5\n1000,0,2\n1000,1,6\n2000,0,3\n";
        let wide = Series::parse_csv(text).unwrap().split_by("sensor").unwrap();
        assert_eq!(wide.time, [0.0, 0.001, 0.002]);
        let names: Vec<&str> = wide.columns.iter().map(|c| c.name.as_str()).collect();
        assert_eq!(names, ["sensor 0: x", "sensor 1: x"]);
        assert_eq!(wide.columns[0].values, [1.0, 2.0, 3.0]);
        assert_eq!(&wide.columns[1].values[..2], &[5.0, 6.0]);
        assert!(wide.columns[1].values[2].is_nan());
        // No such column, or a fractional key: not split.
        let s = Series::parse_csv(text).unwrap();
        assert!(s.split_by("id").is_none());
        let frac = Series::parse_csv("t,sensor,x\n0,0.5,1\n").unwrap();
        assert!(frac.split_by("sensor").is_none());
    }

    #[test]
    fn labels_at_one_spot_do_not_overlap() {
        // Four goals on one pixel (two feet seen from the side) and one
        // beside them: every label box is disjoint from the others.
        let mut placed = Vec::new();
        for c in [(100, 100), (100, 100), (100, 100), (100, 100), (104, 98)] {
            place_label(c, 11, 14.0, &mut placed);
        }
        for (i, a) in placed.iter().enumerate() {
            for b in &placed[i + 1..] {
                let overlap = a.0 < b.2 && b.0 < a.2 && a.1 < b.3 && b.1 < a.3;
                assert!(!overlap, "{a:?} overlaps {b:?}");
            }
        }
    }

    #[test]
    fn tick_labels_are_short() {
        let cases = [
            (1900.0, "1900"),
            (0.25, "0.25"),
            (0.1 + 0.2, "0.3"),
            (-0.0, "0"),
            (-1.5, "-1.5"),
            (1e-9, "0"),
        ];
        for (v, want) in cases {
            assert_eq!(tick(v), want);
        }
    }

    #[test]
    fn gaps_split_lines() {
        let t = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0];
        let v = [1.0, 2.0, f64::NAN, f64::NAN, 5.0, 6.0];
        assert_eq!(
            runs(&t, &v),
            vec![vec![(0.0, 1.0), (1.0, 2.0)], vec![(4.0, 5.0), (5.0, 6.0)]]
        );
        assert!(runs(&t, &[f64::NAN; 6]).is_empty());
    }

    #[test]
    fn tempus_rest_figure_has_a_bone_per_joint_and_leaf() {
        let body = marionette_core::body::tempus::BODY;
        let world: Vec<(DVec3, DQuat)> = vec![(DVec3::ZERO, DQuat::IDENTITY); body.len()];
        let fig = Figure::from_world(&body, &world, "t").unwrap();
        // 17 child segments, and 5 leaves (head, hands, feet) with a touch
        // point off their origin.
        assert_eq!(fig.bones.len(), 17 + 5);
        assert_eq!(fig.touches.len(), 18);
        assert!(Figure::from_world(&body, &world[1..], "t").is_err());
    }
}
