//! Layers: several synthesis processes at once, blended by body part
//! (Wiley & Hahn: "allowing interpolation synthesis over a subset of the
//! body's degrees of freedom would allow one or more separate interpolation
//! synthesis processes to operate at once").
//!
//! A region may carry a *layer list* (region entry kind 3, [`EntryKind::LAYERS`](crate::region::EntryKind::LAYERS)):
//! up to [`MAX_LAYERS`] layers, each naming
//!
//! - its **table** (the `n`-th table entry of the region: a static grid, or a
//!   clip table played in time);
//! - its **parameters**: one [`Source`] per parameter axis of the table (a
//!   rig parameter, that is the sensor map or a `Params` dial; a constant;
//!   or a ramp over the performed time);
//! - its **mask**: one weight per segment, `0..=255` for `0..=1` (legs 1,
//!   arms 0, a soft 0.5 on the spine…);
//! - its **layer weight**: a [`Source`] too (a rig parameter is a live
//!   dial), clamped to `[0, 1]`, reached through a **cross-fade** of
//!   `fade_s` seconds: the effective weight moves towards the source's value
//!   by at most `dt / fade_s` per frame, so turning a layer on or off
//!   (weight 0 ↔ 1) takes exactly `fade_s`;
//! - its **root** rule ([`Root`]): a looping clip's travel per cycle moves
//!   the figure ([`Root::Apply`]) or is dropped for a puppet on a stand
//!   ([`Root::Drop`]);
//! - its **rate** (format version 2): a [`Source`] too, the clip's playback
//!   rate (1: the table's own durations; clamped to `[0, MAX_RATE]`), for a
//!   puppet whose servos are slower than the captured motion; a static grid
//!   ignores it.
//!
//! # Blend order and rule
//!
//! The layers are blended **per segment, in joint-local space, in list
//! order, each overriding what is below it by its weight**, before solving:
//!
//! ```text
//! out = the rig's rest pose (local rotations, root position)
//! for layer k = 0, 1, …:
//!     w_s = weight_k · mask_k[s] / 255
//!     out.rotation[s] = slerp(out.rotation[s], layer_k.rotation[s], w_s)   (shortest arc)
//!     out.root        = lerp(out.root, layer_k.root, w_0)                  (segment 0 = root)
//! ```
//!
//! Rotations are the segments' rotations relative to their parents (the
//! root's is its world rotation), so a layer that owns the right arm moves
//! the arm relative to whatever the layers below did to the torso. A layer
//! of weight 1 and mask 1 on a segment replaces it exactly (`slerp` returns
//! its second input at `t = 1`); weight 0 leaves it exactly. The result is
//! converted to joint angles, and the goals are solved from it.
//!
//! # Clips in time
//!
//! A clip layer keeps a [`Playhead`]. Each performed frame its phase
//! advances by `rate · dt / duration_k`, where `duration_k` is phase `k`'s duration
//! interpolated at the layer's current parameters ([`crate::clip::Motion`];
//! W&H: "we also calculate an interpolated time duration"), and `dt` is the
//! frame's step (the frame period at a steady tracker rate). The phase is
//! state, not a function of time and parameters, so changing the
//! parameters mid-cycle changes only the rate at which it advances: the
//! phase is continuous and the pose moves only as far as the table's poses
//! differ between neighbouring parameters. A loop wraps; a one-shot motion
//! stops at its end.
//!
//! # Layer list format, version 2 (all integers little-endian)
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `"MLAY"` |
//! | 4 | 2 | version `u16` ([`VERSION`] = 1) |
//! | 6 | 1 | layer count `L` (1 ..= [`MAX_LAYERS`]) |
//! | 7 | 1 | segment count `S` (the rig's) |
//! | 8 | `L · (LAYER_FIXED + align4(S))` | the layers, below |
//! | end − 4 | 4 | CRC-32/ISO-HDLC of every byte before it |
//!
//! One layer ([`LAYER_FIXED`] bytes, then the mask): `table: u8` (index
//! among the region's table entries), `root: u8` (0 drop, 1 apply), `axes:
//! u8` (the table's parameter axis count), `reserved: u8` (0), `fade_s: f32`
//! (finite, ≥ 0), the weight [`Source`], the rate [`Source`], then
//! [`MAX_AXES`] axis sources (the first `axes` used, the rest all
//! zero), then `S` mask bytes, zero-padded to a multiple of 4. A source is
//! 16 bytes: `kind: u8` (0 constant, 1 parameter, 2 ramp), `index: u8`
//! (the parameter, `< MAX_PARAMS`), two zero bytes, then three `f32`
//! (constant: value, 0, 0; parameter: 0, 0, 0; ramp: from, to, seconds > 0).
//!
//! Version 1 is version 2 without the rate source (each layer 16 bytes
//! shorter; the rate is 1). It is still read; [`Layers::write`] writes
//! version 2.

use glam::{Quat, Vec3};

use crate::clip::Motion;
use crate::crc::crc32;
use crate::math::{self, SlerpWeight};
use crate::pose::LocalPose;
use crate::rig::MAX_PARAMS;
use crate::table::MAX_AXES;
use crate::wire::StatusReason;

/// The layer list's magic.
pub const MAGIC: [u8; 4] = *b"MLAY";
/// The layer list format version written ([`Layers::parse`] reads 1 too).
pub const VERSION: u16 = 2;
/// Most layers a region may carry.
pub const MAX_LAYERS: usize = 3;
/// Bytes before the layers.
pub const PREFIX_LEN: usize = 8;
/// Bytes of one source.
pub const SOURCE_LEN: usize = 16;
/// Bytes of one layer before its mask (format version 2).
pub const LAYER_FIXED: usize = 8 + SOURCE_LEN * (2 + MAX_AXES);
/// The fastest playback rate (a [`Layer::rate`] above it is clamped).
pub const MAX_RATE: f32 = 4.0;
/// Bytes of the trailing CRC.
pub const CRC_LEN: usize = 4;

/// Where a value (a parameter or a layer weight) comes from each frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Source {
    /// A constant.
    Const(f32),
    /// Rig parameter `i` (the sensor map, overridden by `Params` dials).
    Param(u8),
    /// `from + (to − from) · min(t / seconds, 1)`, `t` the time performed
    /// since the loop last started (armed, or back from a fail-safe trip).
    Ramp {
        /// Value at `t = 0`.
        from: f32,
        /// Value from `t = seconds` on.
        to: f32,
        /// Length of the ramp (> 0).
        seconds: f32,
    },
}

impl Source {
    /// The value now, from the rig parameters `params` and the performed
    /// time `t` seconds (NaN for a parameter out of range).
    #[must_use]
    pub fn value(&self, params: &[f32], t: f32) -> f32 {
        match *self {
            Self::Const(v) => v,
            Self::Param(i) => params.get(usize::from(i)).copied().unwrap_or(f32::NAN),
            Self::Ramp { from, to, seconds } => {
                math::lerp(from, to, math::clamp(t / seconds, 0.0, 1.0))
            }
        }
    }
}

/// What a layer does with a looping clip's root travel per cycle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Root {
    /// Dropped: the figure walks on the spot (a puppet on a stand).
    Drop,
    /// Applied: the root advances by the travel, interpolated at the
    /// layer's parameters, times the phase advanced.
    Apply,
}

/// One layer (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Layer<'a> {
    /// Index among the region's table entries.
    pub table: u8,
    /// The root travel rule.
    pub root: Root,
    /// Cross-fade time, seconds (0: weight changes at once).
    pub fade_s: f32,
    /// The layer weight's source (clamped to `[0, 1]`).
    pub weight: Source,
    /// A clip's playback rate's source (clamped to `[0, MAX_RATE]`; 1 in
    /// format version 1).
    pub rate: Source,
    /// The parameter sources, one per parameter axis of the table.
    pub axes: [Source; MAX_AXES],
    /// Parameter axes used.
    pub axis_count: u8,
    /// Per-segment weights, 255 = 1.
    pub mask: &'a [u8],
}

impl Layer<'_> {
    /// The used parameter sources.
    #[must_use]
    pub fn sources(&self) -> &[Source] {
        self.axes.get(..usize::from(self.axis_count)).unwrap_or(&[])
    }

    /// The playback rate now (see [`Source::value`]), clamped to
    /// `[0, MAX_RATE]`; 0 if the source is not a number.
    #[must_use]
    pub fn rate_at(&self, params: &[f32], t: f32) -> f32 {
        let r = self.rate.value(params, t);
        if r.is_finite() {
            math::clamp(r, 0.0, MAX_RATE)
        } else {
            0.0
        }
    }
}

/// Why a layer list (or a layer) was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayerError {
    /// The bytes end early, or the length does not match the count.
    Truncated,
    /// Not `"MLAY"`.
    Magic,
    /// Another format version.
    Version(u16),
    /// The CRC does not match.
    Crc,
    /// No layer, or more than [`MAX_LAYERS`].
    Count,
    /// A field of layer `index` is out of its domain.
    Field {
        /// The layer.
        index: u8,
    },
    /// The output buffer is too small (writer).
    BufferTooSmall,
}

impl LayerError {
    /// The status reason a board reports.
    #[must_use]
    pub const fn reason(self) -> StatusReason {
        match self {
            Self::Magic => StatusReason::BadMagic,
            Self::Version(_) => StatusReason::BadVersion,
            Self::Crc => StatusReason::BadCrc,
            _ => StatusReason::BadBounds,
        }
    }
}

impl core::fmt::Display for LayerError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Truncated => f.write_str("layer list truncated or of the wrong length"),
            Self::Magic => f.write_str("layer list magic is not MLAY"),
            Self::Version(v) => {
                write!(
                    f,
                    "layer list version {v} (this core reads 1 ..= {VERSION})"
                )
            }
            Self::Crc => f.write_str("layer list CRC mismatch"),
            Self::Count => write!(f, "layer count not in 1..={MAX_LAYERS}"),
            Self::Field { index } => write!(f, "layer {index}: a field is out of its domain"),
            Self::BufferTooSmall => f.write_str("layer list buffer too small"),
        }
    }
}

/// A parsed layer list.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Layers<'a> {
    layers: [Layer<'a>; MAX_LAYERS],
    count: usize,
    segments: usize,
}

/// An unused layer slot.
const NO_LAYER: Layer<'static> = Layer {
    table: 0,
    root: Root::Drop,
    fade_s: 0.0,
    weight: Source::Const(0.0),
    rate: Source::Const(1.0),
    axes: [Source::Const(0.0); MAX_AXES],
    axis_count: 0,
    mask: &[],
};

/// Bytes of one layer's fixed part in format `version` (1 or 2).
const fn fixed_len(version: u16) -> usize {
    if version == 1 {
        LAYER_FIXED - SOURCE_LEN
    } else {
        LAYER_FIXED
    }
}

/// Bytes of one layer with `segments` mask bytes, in format `version`.
const fn layer_len(version: u16, segments: usize) -> usize {
    fixed_len(version) + (segments.saturating_add(3) & !3)
}

/// Bytes of a layer list of `count` layers over `segments` segments, as
/// [`Layers::write`] writes it (format [`VERSION`]).
#[must_use]
pub const fn len(count: usize, segments: usize) -> usize {
    len_in(VERSION, count, segments)
}

const fn len_in(version: u16, count: usize, segments: usize) -> usize {
    PREFIX_LEN + count * layer_len(version, segments) + CRC_LEN
}

fn f32_at(b: &[u8], at: usize) -> Option<f32> {
    let s = b.get(at..at.checked_add(4)?)?;
    Some(f32::from_le_bytes(s.try_into().ok()?))
}

fn read_source(b: &[u8]) -> Option<Source> {
    let (kind, index) = (*b.first()?, *b.get(1)?);
    let (a, c, d) = (f32_at(b, 4)?, f32_at(b, 8)?, f32_at(b, 12)?);
    let finite = a.is_finite() && c.is_finite() && d.is_finite();
    if b.get(2..4) != Some(&[0, 0][..]) || !finite {
        return None;
    }
    match kind {
        0 if index == 0 && c == 0.0 && d == 0.0 => Some(Source::Const(a)),
        1 if usize::from(index) < MAX_PARAMS && a == 0.0 && c == 0.0 && d == 0.0 => {
            Some(Source::Param(index))
        }
        2 if index == 0 && d > 0.0 => Some(Source::Ramp {
            from: a,
            to: c,
            seconds: d,
        }),
        _ => None,
    }
}

fn write_source(s: &Source, out: &mut [u8]) {
    let (kind, index, v) = match *s {
        Source::Const(v) => (0, 0, [v, 0.0, 0.0]),
        Source::Param(i) => (1, i, [0.0; 3]),
        Source::Ramp { from, to, seconds } => (2, 0, [from, to, seconds]),
    };
    let [[a0, a1, a2, a3], [b0, b1, b2, b3], [c0, c1, c2, c3]] = v.map(f32::to_le_bytes);
    let bytes = [
        kind, index, 0, 0, a0, a1, a2, a3, b0, b1, b2, b3, c0, c1, c2, c3,
    ];
    if let Some(o) = out.get_mut(..SOURCE_LEN) {
        o.copy_from_slice(&bytes);
    }
}

/// One layer into its `layer_len(segments)` bytes (zeroed); `None` if a
/// field is out of its domain.
fn write_layer(l: &Layer<'_>, segments: usize, o: &mut [u8]) -> Option<()> {
    if l.mask.len() != segments || usize::from(l.axis_count) > MAX_AXES {
        return None;
    }
    let (head, rest) = o.split_at_mut_checked(8)?;
    let [f0, f1, f2, f3] = l.fade_s.to_le_bytes();
    head.copy_from_slice(&[
        l.table,
        u8::from(l.root == Root::Apply),
        l.axis_count,
        0,
        f0,
        f1,
        f2,
        f3,
    ]);
    let (sources, mask) = rest.split_at_mut_checked(LAYER_FIXED - 8)?;
    let mut chunks = sources.chunks_exact_mut(SOURCE_LEN);
    write_source(&l.weight, chunks.next()?);
    write_source(&l.rate, chunks.next()?);
    for (s, c) in l.sources().iter().zip(chunks) {
        write_source(s, c);
    }
    mask.get_mut(..segments)?.copy_from_slice(l.mask);
    Some(())
}

fn read_layer<'a>(
    b: &'a [u8],
    version: u16,
    segments: usize,
    index: u8,
) -> Result<Layer<'a>, LayerError> {
    let bad = LayerError::Field { index };
    let Some(&[table, root, axes, reserved, f0, f1, f2, f3]) = b.first_chunk::<8>() else {
        return Err(LayerError::Truncated);
    };
    let fade_s = f32::from_le_bytes([f0, f1, f2, f3]);
    let root = match root {
        0 => Root::Drop,
        1 => Root::Apply,
        _ => return Err(bad),
    };
    if reserved != 0 || usize::from(axes) > MAX_AXES || !(fade_s.is_finite() && fade_s >= 0.0) {
        return Err(bad);
    }
    let fixed = fixed_len(version);
    let mut sources = b
        .get(8..fixed)
        .ok_or(LayerError::Truncated)?
        .chunks_exact(SOURCE_LEN);
    let weight = sources.next().and_then(read_source).ok_or(bad)?;
    let rate = if version == 1 {
        Source::Const(1.0)
    } else {
        sources.next().and_then(read_source).ok_or(bad)?
    };
    let mut axis_sources = [Source::Const(0.0); MAX_AXES];
    for (k, (slot, raw)) in axis_sources.iter_mut().zip(sources).enumerate() {
        if k < usize::from(axes) {
            *slot = read_source(raw).ok_or(bad)?;
        } else if raw.iter().any(|&x| x != 0) {
            return Err(bad);
        }
    }
    let mask = b
        .get(fixed..fixed + segments)
        .ok_or(LayerError::Truncated)?;
    let pad = b.get(fixed + segments..layer_len(version, segments));
    if pad.is_none_or(|p| p.iter().any(|&x| x != 0)) {
        return Err(bad);
    }
    Ok(Layer {
        table,
        root,
        fade_s,
        weight,
        rate,
        axes: axis_sources,
        axis_count: axes,
        mask,
    })
}

impl<'a> Layers<'a> {
    /// Validates a layer list blob (exactly its length; see the module doc).
    pub fn parse(bytes: &'a [u8]) -> Result<Self, LayerError> {
        let Some(&[m0, m1, m2, m3, v0, v1, count, segments]) = bytes.first_chunk::<PREFIX_LEN>()
        else {
            return Err(LayerError::Truncated);
        };
        if [m0, m1, m2, m3] != MAGIC {
            return Err(LayerError::Magic);
        }
        let version = u16::from_le_bytes([v0, v1]);
        if !(1..=VERSION).contains(&version) {
            return Err(LayerError::Version(version));
        }
        let (count, segments) = (usize::from(count), usize::from(segments));
        if bytes.len() != len_in(version, count, segments) {
            return Err(LayerError::Truncated);
        }
        let (body, crc) = bytes.split_at(bytes.len() - CRC_LEN);
        if crc32(body).to_le_bytes() != crc {
            return Err(LayerError::Crc);
        }
        if count == 0 || count > MAX_LAYERS {
            return Err(LayerError::Count);
        }
        let mut out = Self {
            layers: [NO_LAYER; MAX_LAYERS],
            count,
            segments,
        };
        let chunks = body
            .get(PREFIX_LEN..)
            .unwrap_or(&[])
            .chunks_exact(layer_len(version, segments));
        for (i, (slot, raw)) in out.layers.iter_mut().zip(chunks).enumerate() {
            *slot = read_layer(raw, version, segments, i as u8)?;
        }
        Ok(out)
    }

    /// Writes the layer list of `layers` (every mask `segments` long) into
    /// `out`; returns its length ([`len`]).
    pub fn write(
        layers: &[Layer<'_>],
        segments: usize,
        out: &mut [u8],
    ) -> Result<usize, LayerError> {
        let count = u8::try_from(layers.len()).map_err(|_| LayerError::Count)?;
        if count == 0 || layers.len() > MAX_LAYERS {
            return Err(LayerError::Count);
        }
        let n = len(layers.len(), segments);
        let seg = u8::try_from(segments).map_err(|_| LayerError::Field { index: 0 })?;
        let out = out.get_mut(..n).ok_or(LayerError::BufferTooSmall)?;
        out.fill(0);
        let (prefix, rest) = out.split_at_mut(PREFIX_LEN);
        let [v0, v1] = VERSION.to_le_bytes();
        let [m0, m1, m2, m3] = MAGIC;
        prefix.copy_from_slice(&[m0, m1, m2, m3, v0, v1, count, seg]);
        for ((l, o), i) in layers
            .iter()
            .zip(rest.chunks_exact_mut(layer_len(VERSION, segments)))
            .zip(0u8..)
        {
            write_layer(l, segments, o).ok_or(LayerError::Field { index: i })?;
        }
        let (body, crc) = out.split_at_mut(n - CRC_LEN);
        crc.copy_from_slice(&crc32(body).to_le_bytes());
        Ok(n)
    }

    /// The layers, in blend order.
    #[must_use]
    pub fn as_slice(&self) -> &[Layer<'a>] {
        self.layers.get(..self.count).unwrap_or(&[])
    }

    /// The segment count the masks cover.
    #[must_use]
    pub fn segments(&self) -> usize {
        self.segments
    }
}

/// Blends `layer` over `out` by `weight` (clamped to `[0, 1]`) times the
/// per-segment `mask` (255 = 1; a missing byte counts 0): the rule of the
/// module doc, for one layer.
pub fn blend<const N: usize>(
    out: &mut LocalPose<N>,
    layer: &LocalPose<N>,
    mask: &[u8],
    weight: f32,
) {
    let weight = math::clamp(weight, 0.0, 1.0);
    if weight <= 0.0 {
        return;
    }
    let n = out.len().min(layer.len());
    let (Some(dst), Some(src)) = (out.rotations.get_mut(..n), layer.rotations.get(..n)) else {
        return;
    };
    for ((d, &s), &m) in dst.iter_mut().zip(src).zip(mask) {
        *d = blend_rotation(*d, s, weight * f32::from(m) * (1.0 / 255.0), m);
    }
    let root = mask
        .first()
        .map_or(0.0, |&m| weight * f32::from(m) * (1.0 / 255.0));
    out.root_position = math::lerp_vec3(out.root_position, layer.root_position, root);
}

/// One segment's rotation: exact at the ends (mask 0 or full weight).
#[inline]
fn blend_rotation(d: Quat, s: Quat, w: f32, m: u8) -> Quat {
    if m == 0 {
        d
    } else if w >= 1.0 {
        s
    } else {
        SlerpWeight::new(w).apply(d, s)
    }
}

/// A clip layer's place in its motion (see [Clips in time](self#clips-in-time)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Playhead {
    phase: f32,
    /// The root travel accumulated since the start (clip frame, metres).
    travelled: Vec3,
}

impl Playhead {
    /// At phase 0, nothing travelled.
    pub const START: Self = Self {
        phase: 0.0,
        travelled: Vec3::ZERO,
    };

    /// The phase now.
    #[must_use]
    pub fn phase(&self) -> f32 {
        self.phase
    }

    /// The root travel accumulated since the start: each frame adds the
    /// loop's travel per cycle, interpolated at that frame's parameters,
    /// times the fraction of a cycle advanced (so a change of speed changes
    /// the root's velocity, never its position).
    #[must_use]
    pub fn travelled(&self) -> Vec3 {
        self.travelled
    }

    /// Advances by `dt` seconds through `motion` (durations interpolated at
    /// this frame's parameters) and returns the new phase. A loop wraps to
    /// `[0, 1)`; a one-shot motion of `P` phases advances at `1/duration_k`
    /// within phase `k` and stops at `P`.
    pub fn advance(&mut self, motion: &Motion, dt: f32) -> f32 {
        let durations = motion.durations();
        let dt = if dt.is_finite() { dt.max(0.0) } else { 0.0 };
        if motion.looping() {
            let step = dt / motion.duration();
            let p = self.phase + step;
            self.phase = p - math::floor(p);
            self.travelled += motion.travel() * step;
        } else {
            let last = durations.len().saturating_sub(1);
            let k = (math::floor(self.phase).max(0.0) as usize).min(last);
            let d = durations.get(k).copied().unwrap_or(1.0);
            self.phase = math::min(self.phase + dt / d, durations.len() as f32);
        }
        self.phase
    }
}
