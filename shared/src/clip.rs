//! Motion synthesis from clips (Wiley & Hahn 1997, "Motion interpolation
//! synthesis" and "Reach motion interpolation synthesis").
//!
//! # Clips on a grid
//!
//! A clip is a timed sequence of poses. Every example clip is resampled (on
//! the host, with [`resample`]) to the same number of frames over a
//! normalized *phase*, and the clips are laid out on a regular grid of
//! parameters (walk slope, speed, the reached-to hand position…). The frames
//! then form one [`Grid`] whose **last axis is the phase** and whose other
//! axes are the parameters, the layout of the `table` module's clip tables:
//! sample index `param_index + param_samples · frame`.
//!
//! - A motion has `phases ≥ 1` phases spanning phase `[0, phases]`; each
//!   phase of each clip has its own duration (seconds). A walk cycle has one
//!   phase; a reach has two (rest → target, target → rest), split at the reach
//!   pose, which sits exactly on frame `(count − 1)/2` (phase 1).
//! - A looping clip has one phase and a cyclic phase axis of period 1 (`count`
//!   frames at step `1/count`, frame `count` is frame 0 again); a non-looping
//!   motion has a bounded phase axis from 0 to `phases` with `count − 1`
//!   divisible by `phases`, so each phase boundary is a frame.
//!
//! # Synthesis
//!
//! [`Clips::motion`] locates the parameters on the parameter grid once
//! (clamping, projection out of invalid cells and NaN rejection as in
//! [`crate::grid`]) and interpolates each phase's duration with the same
//! weights as the poses (W&H: "we also calculate an interpolated time
//! duration to preserve dynamical realism"). [`Clips::pose`] then gives the
//! pose at a phase: a grid query over the parameters and the phase, reducing
//! the parameter axes first ("interpolate between two walk cycles pose by
//! pose") and the phase axis last (time resampling of the result). At a
//! parameter grid point (interpolation coefficients 0 and 1) every parameter
//! slerp and lerp returns its input bit for bit, so the synthesized motion
//! *is* the stored clip, with the stored durations.
//!
//! [`Motion::phase_at`] maps a time in seconds to the phase: within phase
//! `k`, time advances at `1/duration_k`; a looping motion wraps, a
//! non-looping one clamps to `[0, phases]`. So sampling a reach by time
//! crosses from segment 1 to segment 2 at the first segment's interpolated
//! duration.
//!
//! # Host-side helpers (one implementation for host and core)
//!
//! - [`resample`]: poses at arbitrary, increasing times → `frames` uniform
//!   frames over a time span (lerp positions, slerp rotations between the
//!   bracketing source frames; looping sources wrap from the last frame to
//!   the first one period later).
//! - [`seam_blend`]: makes a loop seamless. Given `K + 1` frames of one
//!   cycle, where frame `K` is the pose one period after frame 0 (equal in
//!   theory, not in recorded data), the mismatch `δ` (`p₀ − p_K`, and the
//!   world rotation `q₀·q_K⁻¹`) is spread over a window of `W` frames at each
//!   end with a smoothstep ramp: the last `W` frames move by up to `+δ/2`, the
//!   first `W` by up to `−δ/2`, so frames `K` and `0` coincide and the motion
//!   is `C¹` at the ramps' inner ends. Frame `K` is then dropped, leaving `K`
//!   frames for a cyclic phase axis. Positions are blended as absolute
//!   positions, so looping clips must be in place (the host removes the net
//!   root travel per cycle first, on all three axes, and stores it in the
//!   table: [`Motion::travel`] interpolates it like the durations, and the
//!   figure advances by it each cycle; any leftover mismatch is blended
//!   away here).

use glam::{Quat, Vec3};

use crate::grid::{Adjust, Grid, GridError, MAX_AXES, Query, Samples, Wrap};
use crate::math::{self, SlerpWeight};
use crate::pose::Pose;

/// Most phases a motion may have.
pub const MAX_PHASES: usize = 8;

/// Why a clip operation was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClipError {
    /// The grid refused (parameters, samples, capacity).
    Grid(GridError),
    /// The grids do not have the clip layout: the full grid must be the
    /// parameter axes plus one phase axis matching `phases` (see the module doc).
    Layout,
    /// No phases, or more than [`MAX_PHASES`].
    Phases,
    /// A duration is missing, non-finite or not positive.
    Duration,
    /// A time or span is NaN/infinite, or the span is empty.
    Time,
    /// Source times are not increasing, or do not match the source samples.
    SourceTimes,
    /// An output buffer has the wrong length.
    OutputLength,
}

impl From<GridError> for ClipError {
    fn from(e: GridError) -> Self {
        ClipError::Grid(e)
    }
}

/// A source of clip durations: seconds of `phase` of the clip at parameter
/// sample `index`.
pub trait Durations {
    /// The duration, or `None` if absent.
    fn duration(&self, index: usize, phase: usize) -> Option<f32>;

    /// A looping clip's root displacement over one cycle at parameter
    /// sample `index` (clip frame, metres); `None` if not stored.
    fn travel(&self, index: usize) -> Option<Vec3> {
        let _ = index;
        None
    }
}

/// In-memory durations, `[parameter sample][phase]`.
#[derive(Clone, Copy, Debug)]
pub struct SliceDurations<'a> {
    /// Phases per clip.
    pub phases: usize,
    /// The durations, phase fastest.
    pub values: &'a [f32],
}

impl Durations for SliceDurations<'_> {
    fn duration(&self, index: usize, phase: usize) -> Option<f32> {
        if phase >= self.phases {
            return None;
        }
        self.values
            .get(index.checked_mul(self.phases)?.checked_add(phase)?)
            .copied()
    }
}

impl Durations for crate::table::Table<'_> {
    fn duration(&self, index: usize, phase: usize) -> Option<f32> {
        crate::table::Table::duration(self, index, phase)
    }

    fn travel(&self, index: usize) -> Option<Vec3> {
        crate::table::Table::travel(self, index)
    }
}

/// A set of clips on a parameter grid (see the module doc).
#[derive(Clone, Copy, Debug)]
pub struct Clips<'a> {
    grid: Grid<'a>,
    params: Grid<'a>,
    phases: usize,
    looping: bool,
}

/// The motion for one parameter setting: effective parameters and the
/// interpolated duration of each phase.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Motion {
    params: [f32; MAX_AXES],
    param_count: usize,
    durations: [f32; MAX_PHASES],
    phases: usize,
    looping: bool,
    adjust: Adjust,
    travel: Vec3,
    /// The parameter query's work ([`crate::grid::Query::work`], no
    /// segments).
    work: u32,
}

impl<'a> Clips<'a> {
    /// Checks the layout: `grid`'s axes are `params`' axes followed by the
    /// phase axis (min 0; cyclic with period 1 and `phases == 1` for a loop,
    /// or bounded over `[0, phases]` with each phase boundary on a frame).
    pub fn new(grid: Grid<'a>, params: Grid<'a>, phases: usize) -> Result<Self, ClipError> {
        if phases == 0 || phases > MAX_PHASES {
            return Err(ClipError::Phases);
        }
        let (Some((phase, head)), p) = (grid.axes().split_last(), params.axes()) else {
            return Err(ClipError::Layout);
        };
        let same = head.len() == p.len() && head.iter().zip(p).all(|(a, b)| a == b);
        let n = phases as f32;
        let ok = match phase.wrap {
            Wrap::Cyclic { period } => phases == 1 && math::abs(period - 1.0) <= 1e-5,
            Wrap::Bounded => {
                let frames = phase.count - 1;
                math::abs(phase.step * frames as f32 - n) <= 1e-5 * n
                    && frames.checked_rem(phases as u32) == Some(0)
            }
        };
        if !same || !ok || phase.min != 0.0 {
            return Err(ClipError::Layout);
        }
        let looping = matches!(phase.wrap, Wrap::Cyclic { .. });
        Ok(Self {
            grid,
            params,
            phases,
            looping,
        })
    }

    /// Number of phases.
    #[must_use]
    pub fn phases(&self) -> usize {
        self.phases
    }

    /// Whether the clips loop.
    #[must_use]
    pub fn looping(&self) -> bool {
        self.looping
    }

    /// Locates `params` on the parameter grid and interpolates the durations.
    pub fn motion<D: Durations>(&self, durations: &D, params: &[f32]) -> Result<Motion, ClipError> {
        let q = self.params.query(params)?;
        let mut m = Motion {
            params: [0.0; MAX_AXES],
            param_count: q.params().len(),
            durations: [0.0; MAX_PHASES],
            phases: self.phases,
            looping: self.looping,
            adjust: q.adjust(),
            travel: Vec3::ZERO,
            work: q.work(0),
        };
        for (d, &p) in m.params.iter_mut().zip(q.params()) {
            *d = p;
        }
        let window = q.window();
        for (k, slot) in m.durations.iter_mut().enumerate().take(self.phases) {
            let mut acc = 0.0f32;
            for (&index, &w) in window.indices().iter().zip(window.weights()) {
                let d = durations
                    .duration(index as usize, k)
                    .ok_or(ClipError::Duration)?;
                if !(d.is_finite() && d > 0.0) {
                    return Err(ClipError::Duration);
                }
                acc += d * w;
            }
            // Catmull-Rom weights can overshoot; a duration stays positive.
            *slot = acc.max(1e-6);
        }
        if self.looping {
            let mut acc = Vec3::ZERO;
            for (&index, &w) in window.indices().iter().zip(window.weights()) {
                // A table without stored travel (version 1) loops in place.
                acc += durations.travel(index as usize).unwrap_or(Vec3::ZERO) * w;
            }
            m.travel = acc;
        }
        Ok(m)
    }

    /// The pose of `motion` at `phase` (in `[0, phases]`, wrapped if looping,
    /// clamped otherwise). Returns the grid's adjustment of the phase query.
    pub fn pose<S: Samples, const N: usize>(
        &self,
        motion: &Motion,
        samples: &S,
        phase: f32,
        out: &mut Pose<N>,
    ) -> Result<Adjust, ClipError> {
        self.pose_into(motion, samples, phase, (&mut Query::default(), out))
    }

    /// [`Clips::pose`] through an existing [`Query`], which keeps the
    /// phase query (for its [`Query::work`]).
    pub fn pose_into<S: Samples, const N: usize>(
        &self,
        motion: &Motion,
        samples: &S,
        phase: f32,
        (query, out): (&mut Query, &mut Pose<N>),
    ) -> Result<Adjust, ClipError> {
        if !phase.is_finite() {
            return Err(ClipError::Time);
        }
        let mut all = [0.0f32; MAX_AXES];
        let n = motion.param_count;
        for (d, &p) in all.iter_mut().zip(motion.params()) {
            *d = p;
        }
        let slot = all.get_mut(n).ok_or(ClipError::Layout)?;
        *slot = phase;
        self.grid.query_into(all.get(..=n).unwrap_or(&[]), query)?;
        query.pose(samples, out)?;
        Ok(query.adjust())
    }

    /// The pose of `motion` at `time` seconds (see [`Motion::phase_at`]).
    pub fn pose_at_time<S: Samples, const N: usize>(
        &self,
        motion: &Motion,
        samples: &S,
        time: f32,
        out: &mut Pose<N>,
    ) -> Result<(), ClipError> {
        let phase = motion.phase_at(time)?;
        self.pose(motion, samples, phase, out)?;
        Ok(())
    }
}

impl Motion {
    /// The parameters actually used (after clamping / projection).
    #[must_use]
    pub fn params(&self) -> &[f32] {
        self.params.get(..self.param_count).unwrap_or(&[])
    }

    /// What the parameter query did.
    #[must_use]
    pub fn adjust(&self) -> Adjust {
        self.adjust
    }

    /// The parameter query's work ([`Query::work`] without segments: its
    /// location and projection; the durations' blend is not counted).
    #[must_use]
    pub fn work(&self) -> u32 {
        self.work
    }

    /// Whether the motion loops (one cycle, phase in `[0, 1)`).
    #[must_use]
    pub fn looping(&self) -> bool {
        self.looping
    }

    /// Interpolated duration of each phase, seconds.
    #[must_use]
    pub fn durations(&self) -> &[f32] {
        self.durations.get(..self.phases).unwrap_or(&[])
    }

    /// A loop's root displacement over one cycle (the clip frame, metres),
    /// interpolated like the durations: the figure advances by it each cycle
    /// (zero for a one-shot motion or a table that stores none).
    #[must_use]
    pub fn travel(&self) -> Vec3 {
        self.travel
    }

    /// Total duration (one cycle for a loop), seconds.
    #[must_use]
    pub fn duration(&self) -> f32 {
        self.durations().iter().sum()
    }

    /// Phase in `[0, phases]` at `time` seconds from the start: phase `k`
    /// lasts `durations()[k]`. Looping motions wrap; others clamp.
    pub fn phase_at(&self, time: f32) -> Result<f32, ClipError> {
        if !time.is_finite() {
            return Err(ClipError::Time);
        }
        if self.looping {
            let d = self.duration();
            let cycles = time / d;
            return Ok(cycles - math::floor(cycles));
        }
        let mut t = time.max(0.0);
        for (k, &d) in self.durations().iter().enumerate() {
            if t < d {
                return Ok(k as f32 + t / d);
            }
            t -= d;
        }
        Ok(self.phases as f32)
    }
}

/// A time span `[start, end]` of a source clip.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Span {
    /// Start time, seconds.
    pub start: f32,
    /// End time, seconds (> start).
    pub end: f32,
}

/// Resamples a clip given at increasing `times` (one per source sample,
/// `src.sample(frame, segment)`) to `frames` uniform frames over `span`,
/// written `[frame][segment]` into `out_positions` / `out_rotations`
/// (`frames · segments` each).
///
/// Bounded (`looping == false`): frame `j` is at `start + (end − start)·j/(frames − 1)`
/// (the first and last frames are the span ends); outside the source times
/// the first/last source frame is held. Looping: the source is one cycle of
/// period `end − start` with all times in `[start, end)`; frame `j` is at
/// `start + (end − start)·j/frames`, and between the last source frame and
/// the first one a period later the poses are interpolated across the wrap.
pub fn resample<S: Samples>(
    src: &S,
    times: &[f32],
    span: Span,
    looping: bool,
    frames: usize,
    out_positions: &mut [Vec3],
    out_rotations: &mut [Quat],
) -> Result<(), ClipError> {
    let segments = src.segment_count();
    check_times(src, times, span, looping)?;
    let total = frames
        .checked_mul(segments)
        .ok_or(ClipError::OutputLength)?;
    if frames < 2 || out_positions.len() != total || out_rotations.len() != total {
        return Err(ClipError::OutputLength);
    }
    let steps = if looping { frames } else { frames - 1 } as f32;
    let period = span.end - span.start;
    let mut i = 0usize;
    let rows = out_positions
        .chunks_exact_mut(segments)
        .zip(out_rotations.chunks_exact_mut(segments));
    for (j, (pos, rot)) in rows.enumerate() {
        let tau = math::lerp(span.start, span.end, j as f32 / steps);
        while times.get(i + 1).is_some_and(|&t| t <= tau) {
            i += 1;
        }
        let (a, b, u) = bracket(times, i, tau, looping, period);
        for (s, (p, r)) in pos.iter_mut().zip(rot.iter_mut()).enumerate() {
            let (pa, qa) = src.sample(a, s).ok_or(ClipError::SourceTimes)?;
            let (pb, qb) = src.sample(b, s).ok_or(ClipError::SourceTimes)?;
            *p = math::lerp_vec3(pa, pb, u);
            *r = math::slerp(qa, qb, u);
        }
    }
    Ok(())
}

fn check_times<S: Samples>(
    src: &S,
    times: &[f32],
    span: Span,
    looping: bool,
) -> Result<(), ClipError> {
    if !(span.start.is_finite() && span.end.is_finite() && span.end > span.start) {
        return Err(ClipError::Time);
    }
    if times.is_empty() || times.len() > src.sample_count() || src.segment_count() == 0 {
        return Err(ClipError::SourceTimes);
    }
    let increasing = times.windows(2).all(|w| matches!(w, [a, b] if a < b));
    let finite = times.iter().all(|t| t.is_finite());
    let in_cycle = !looping || times.iter().all(|&t| t >= span.start && t < span.end);
    if increasing && finite && in_cycle {
        Ok(())
    } else {
        Err(ClipError::SourceTimes)
    }
}

/// Source frames around `tau` (with `times[i] ≤ tau < times[i+1]` where
/// possible) and the interpolation parameter between them.
fn bracket(times: &[f32], i: usize, tau: f32, looping: bool, period: f32) -> (usize, usize, f32) {
    let last = times.len() - 1;
    let (Some(&t0), Some(&tl), Some(&ti)) = (times.first(), times.last(), times.get(i)) else {
        return (0, 0, 0.0);
    };
    if tau < t0 {
        // Before the first frame: hold, or wrap from the last frame.
        return if looping {
            let prev = tl - period;
            (last, 0, frac(tau - prev, t0 - prev))
        } else {
            (0, 0, 0.0)
        };
    }
    match times.get(i + 1) {
        Some(&tn) => (i, i + 1, frac(tau - ti, tn - ti)),
        None if looping => (last, 0, frac(tau - tl, t0 + period - tl)),
        None => (last, last, 0.0),
    }
}

fn frac(num: f32, den: f32) -> f32 {
    if den > 0.0 {
        (num / den).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// Makes a loop seamless (see the module doc): `positions`/`rotations` hold
/// `K + 1` frames `[frame][segment]`, frame `K` being the pose one period
/// after frame 0. Spreads the mismatch over `window` frames at each end
/// (`1 ≤ window ≤ K/2`) and returns `K`: use the first `K` frames.
pub fn seam_blend(
    positions: &mut [Vec3],
    rotations: &mut [Quat],
    segments: usize,
    window: usize,
) -> Result<usize, ClipError> {
    let total = positions.len();
    let frames = total.checked_div(segments).ok_or(ClipError::OutputLength)?;
    if rotations.len() != total || frames * segments != total || frames < 3 {
        return Err(ClipError::OutputLength);
    }
    let k = frames - 1;
    if window == 0 || 2 * window > k {
        return Err(ClipError::OutputLength);
    }
    for s in 0..segments {
        let (Some(&p0), Some(&pk), Some(&q0), Some(&qk)) = (
            positions.get(s),
            positions.get(k * segments + s),
            rotations.get(s),
            rotations.get(k * segments + s),
        ) else {
            return Err(ClipError::OutputLength);
        };
        let dp = (p0 - pk) * 0.5;
        let mut dq = q0 * qk.conjugate();
        if dq.w < 0.0 {
            dq = -dq;
        }
        for i in 0..=window {
            // End ramp: frames k − window ..= k get +ramp·δ/2.
            let ramp = smoothstep(i as f32 / window as f32);
            shift(
                positions,
                rotations,
                (k - window + i) * segments + s,
                dp * ramp,
                dq,
                0.5 * ramp,
            );
            // Start ramp: frames 0 ..= window get −(1 − ramp)·δ/2.
            let ramp = 1.0 - smoothstep(i as f32 / window as f32);
            shift(
                positions,
                rotations,
                i * segments + s,
                -dp * ramp,
                dq.conjugate(),
                0.5 * ramp,
            );
        }
    }
    Ok(k)
}

fn smoothstep(x: f32) -> f32 {
    x * x * (3.0 - 2.0 * x)
}

/// Adds `dp` to a position and pre-rotates the rotation by `slerp(1, dq, f)`.
fn shift(positions: &mut [Vec3], rotations: &mut [Quat], index: usize, dp: Vec3, dq: Quat, f: f32) {
    if let Some(p) = positions.get_mut(index) {
        *p += dp;
    }
    if let Some(r) = rotations.get_mut(index) {
        *r = SlerpWeight::new(f).apply(Quat::IDENTITY, dq) * *r;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{Axis, Interp, SliceSamples};

    #[test]
    fn phase_at_time() {
        let m = Motion {
            params: [0.0; MAX_AXES],
            param_count: 1,
            durations: [1.0, 3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            phases: 2,
            looping: false,
            adjust: Adjust::None,
            travel: Vec3::ZERO,
            work: 0,
        };
        assert_eq!(m.duration(), 4.0);
        assert_eq!(m.phase_at(0.5), Ok(0.5));
        assert_eq!(m.phase_at(2.5), Ok(1.5));
        assert_eq!(m.phase_at(9.0), Ok(2.0));
        assert_eq!(m.phase_at(-1.0), Ok(0.0));
        assert_eq!(m.phase_at(f32::NAN), Err(ClipError::Time));
        let l = Motion {
            durations: [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            phases: 1,
            looping: true,
            ..m
        };
        assert_eq!(l.phase_at(5.0), Ok(0.5));
        assert_eq!(l.phase_at(-0.5), Ok(0.75));
    }

    #[test]
    fn layout_checks() {
        let speed = Axis::linear(1.0, 0.5, 3);
        let params = Grid::new(&[speed], None).unwrap();
        let cyc = Axis {
            min: 0.0,
            step: 0.25,
            count: 4,
            wrap: Wrap::Cyclic { period: 1.0 },
            interp: Interp::Linear,
        };
        let grid = Grid::new(&[speed, cyc], None).unwrap();
        assert!(Clips::new(grid, params, 1).is_ok());
        assert_eq!(Clips::new(grid, params, 2).err(), Some(ClipError::Layout));
        let reach = Axis::linear(0.0, 0.5, 5);
        let grid = Grid::new(&[speed, reach], None).unwrap();
        assert!(Clips::new(grid, params, 2).is_ok());
        assert_eq!(Clips::new(grid, params, 3).err(), Some(ClipError::Layout));
        let other = Grid::new(&[Axis::linear(0.0, 0.5, 3)], None).unwrap();
        assert_eq!(Clips::new(grid, other, 2).err(), Some(ClipError::Layout));
        assert_eq!(Clips::new(grid, params, 0).err(), Some(ClipError::Phases));
    }

    #[test]
    fn resample_bounded_and_looping() {
        // One segment moving along x at 1 m/s, sampled at uneven times.
        let times = [0.0f32, 0.3, 0.5, 1.2, 2.0];
        let p: [Vec3; 5] = times.map(|t| Vec3::new(t, 0.0, 0.0));
        let q = [Quat::IDENTITY; 5];
        let src = SliceSamples::new(1, &p, &q).unwrap();
        let (mut op, mut oq) = ([Vec3::ZERO; 5], [Quat::IDENTITY; 5]);
        resample(
            &src,
            &times,
            Span {
                start: 0.0,
                end: 2.0,
            },
            false,
            5,
            &mut op,
            &mut oq,
        )
        .unwrap();
        for (j, v) in op.iter().enumerate() {
            assert!((v.x - 0.5 * j as f32).abs() < 1e-6, "{j}: {v}");
        }
        // Looping over period 2.5: the last frame interpolates towards frame 0.
        resample(
            &src,
            &times,
            Span {
                start: 0.0,
                end: 2.5,
            },
            true,
            5,
            &mut op,
            &mut oq,
        )
        .unwrap();
        // Frame 4 at t = 2.0 is the last source frame; between 2.0 and 2.5 x goes 2 → 0.
        assert!((op[4].x - 2.0).abs() < 1e-6);
        let (mut op2, mut oq2) = ([Vec3::ZERO; 10], [Quat::IDENTITY; 10]);
        resample(
            &src,
            &times,
            Span {
                start: 0.0,
                end: 2.5,
            },
            true,
            10,
            &mut op2,
            &mut oq2,
        )
        .unwrap();
        assert!((op2[9].x - 1.0).abs() < 1e-6, "{}", op2[9]);
        assert_eq!(
            resample(
                &src,
                &[0.0, 0.0],
                Span {
                    start: 0.0,
                    end: 1.0
                },
                false,
                5,
                &mut op,
                &mut oq
            ),
            Err(ClipError::SourceTimes)
        );
    }
}
