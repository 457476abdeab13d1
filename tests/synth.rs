//! Pose synthesis against independent references: the grid (W&H static
//! synthesis), clips (motion synthesis), and forward kinematics, checked
//! against slow `f64` implementations in `marionette_tests::synth_ref` and
//! closed forms.

use glam::{Quat, Vec3};
use marionette_core::grid::{Adjust, Axis, Grid, GridError, Interp, Samples, SliceSamples, Wrap};
use marionette_core::math;
use marionette_core::pose::{self, Hierarchy, LocalPose, NO_PARENT, Pose};
use marionette_tests::synth_ref::{self as r, Q, Rng, V};

fn q32(q: Q) -> Quat {
    Quat::from_xyzw(q[0] as f32, q[1] as f32, q[2] as f32, q[3] as f32)
}
fn q64(q: Quat) -> Q {
    [q.x, q.y, q.z, q.w].map(f64::from)
}
fn v32(v: V) -> Vec3 {
    Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32)
}
fn v64(v: Vec3) -> V {
    [v.x, v.y, v.z].map(f64::from)
}
fn dist(a: V, b: V) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// An axis description for the f64 reference.
#[derive(Clone, Copy)]
struct RefAxis {
    min: f64,
    step: f64,
    count: usize,
    cyclic: bool,
    cubic: bool,
}

impl RefAxis {
    fn core(&self) -> Axis {
        Axis {
            min: self.min as f32,
            step: self.step as f32,
            count: self.count as u32,
            wrap: if self.cyclic {
                Wrap::Cyclic {
                    period: (self.step * self.count as f64) as f32,
                }
            } else {
                Wrap::Bounded
            },
            interp: if self.cubic {
                Interp::CatmullRom
            } else {
                Interp::Linear
            },
        }
    }
}

/// A grid of f64 samples, `[sample][segment]`, axis 0 fastest.
struct RefGrid {
    axes: Vec<RefAxis>,
    segments: usize,
    pos: Vec<V>,
    rot: Vec<Q>,
}

impl RefGrid {
    fn sample_count(&self) -> usize {
        self.axes.iter().map(|a| a.count).product()
    }

    fn core_samples(&self) -> (Vec<Vec3>, Vec<Quat>) {
        (
            self.pos.iter().map(|&p| v32(p)).collect(),
            self.rot.iter().map(|&q| q32(q)).collect(),
        )
    }

    /// The f32 samples read back as f64 (what the core actually sees).
    fn rounded(&self) -> RefGrid {
        RefGrid {
            axes: self.axes.clone(),
            segments: self.segments,
            pos: self.pos.iter().map(|&p| v64(v32(p))).collect(),
            rot: self.rot.iter().map(|&q| q64(q32(q))).collect(),
        }
    }

    /// Straightforward evaluation: locate per axis, gather the window
    /// recursively (last axis outermost), reduce axis 0 first with lerp/slerp or
    /// Catmull-Rom (Hermite form for positions, Barry–Goldman pyramid with exact
    /// slerp for rotations; phantoms built explicitly at bounded ends).
    fn eval(&self, params: &[f64], seg: usize) -> (V, Q) {
        let loc: Vec<(usize, f64)> = self
            .axes
            .iter()
            .zip(params)
            .map(|(a, &p)| {
                let n = a.count as f64;
                let mut u = (p - a.min) / a.step;
                if a.cyclic {
                    u = u.rem_euclid(n);
                } else {
                    u = u.clamp(0.0, n - 1.0);
                }
                let cells = if a.cyclic { a.count } else { a.count - 1 };
                let k = (u.floor() as usize).min(cells - 1);
                (k, u - k as f64)
            })
            .collect();
        self.reduce(self.axes.len(), &loc, &mut vec![0; self.axes.len()], seg)
    }

    fn reduce(
        &self,
        level: usize,
        loc: &[(usize, f64)],
        idx: &mut Vec<usize>,
        seg: usize,
    ) -> (V, Q) {
        if level == 0 {
            let mut i = 0;
            for (a, &k) in self.axes.iter().zip(idx.iter()).rev() {
                i = i * a.count + k;
            }
            let s = i * self.segments + seg;
            return (self.pos[s], self.rot[s]);
        }
        let a = level - 1;
        let ax = self.axes[a];
        let (k, t) = loc[a];
        let wrap = |i: isize| -> Option<usize> {
            let n = ax.count as isize;
            if ax.cyclic {
                Some(i.rem_euclid(n) as usize)
            } else if (0..n).contains(&i) {
                Some(i as usize)
            } else {
                None
            }
        };
        let mut get = |i: isize| -> Option<(V, Q)> {
            let j = wrap(i)?;
            idx[a] = j;
            Some(self.reduce(a, loc, idx, seg))
        };
        let k = k as isize;
        if !ax.cubic {
            let (p0, q0) = get(k).unwrap();
            let (p1, q1) = get(k + 1).unwrap();
            return (r::lerp3(p0, p1, t), r::slerp(q0, q1, t));
        }
        let (p1, q1) = get(k).unwrap();
        let (p2, q2) = get(k + 1).unwrap();
        // Phantoms: linear extrapolation of positions, slerp to ±1 beyond for rotations.
        let (p0, q0) = get(k - 1).unwrap_or((
            [0, 1, 2].map(|i| 2.0 * p1[i] - p2[i]),
            r::slerp(q1, q2, -1.0),
        ));
        let (p3, q3) = get(k + 2).unwrap_or((
            [0, 1, 2].map(|i| 2.0 * p2[i] - p1[i]),
            r::slerp(q1, q2, 2.0),
        ));
        let p = [0, 1, 2].map(|i| r::catmull_rom(p0[i], p1[i], p2[i], p3[i], t));
        (p, r::spherical_catmull_rom([q0, q1, q2, q3], t))
    }
}

/// Random grid with rotations that vary smoothly (each sample is a base
/// rotation times a rotation by up to `spread` rad), positions random in ±1 m.
fn random_grid(axes: Vec<RefAxis>, segments: usize, spread: f64, seed: u64) -> RefGrid {
    let mut rng = Rng::new(seed);
    let n = axes.iter().map(|a| a.count).product::<usize>() * segments;
    let base: Vec<Q> = (0..segments).map(|_| rng.quat()).collect();
    let mut pos = Vec::with_capacity(n);
    let mut rot = Vec::with_capacity(n);
    for i in 0..n {
        pos.push([0; 3].map(|_| rng.range(-1.0, 1.0)));
        let axis = [0; 3].map(|_| rng.range(-1.0, 1.0));
        let d = r::axis_angle(axis, rng.range(0.0, spread));
        let q = r::mul(base[i % segments], d);
        // Random sign: the grid must not care.
        rot.push(if rng.range(0.0, 1.0) < 0.5 {
            q
        } else {
            q.map(|v| -v)
        });
    }
    RefGrid {
        axes,
        segments,
        pos,
        rot,
    }
}

fn lin(min: f64, step: f64, count: usize) -> RefAxis {
    RefAxis {
        min,
        step,
        count,
        cyclic: false,
        cubic: false,
    }
}

fn random_params(rng: &mut Rng, axes: &[RefAxis], margin: f64) -> Vec<f64> {
    axes.iter()
        .map(|a| {
            let span = if a.cyclic {
                a.step * a.count as f64
            } else {
                a.step * (a.count - 1) as f64
            };
            rng.range(a.min - margin * span, a.min + (1.0 + margin) * span)
        })
        .collect()
}

fn core_grid(g: &RefGrid) -> (Vec<Axis>, Vec<Vec3>, Vec<Quat>) {
    let (p, q) = g.core_samples();
    (g.axes.iter().map(RefAxis::core).collect(), p, q)
}

#[test]
fn grid_points_return_samples_exactly() {
    let cr = RefAxis {
        cubic: true,
        ..lin(0.2, 0.2, 5)
    };
    let cyc = RefAxis {
        cyclic: true,
        cubic: true,
        ..lin(-1.0, 0.25, 8)
    };
    for axes in [
        vec![lin(-0.3, 0.1, 5), lin(0.8, 0.15, 4), lin(0.2, 0.2, 3)],
        vec![lin(-0.3, 0.1, 4), cr, cyc],
    ] {
        let g = random_grid(axes, 5, 0.8, 1);
        let (axes, p, q) = core_grid(&g);
        let grid = Grid::new(&axes, None).unwrap();
        let samples = SliceSamples::new(5, &p, &q).unwrap();
        let mut out = Pose::<8>::default();
        for s in 0..g.sample_count() {
            let (mut rest, mut params) = (s, Vec::new());
            for a in &axes {
                params.push(a.min + (rest % a.count as usize) as f32 * a.step);
                rest /= a.count as usize;
            }
            let adj = grid.synthesize(&samples, &params, &mut out).unwrap();
            assert_eq!(adj, Adjust::None);
            assert_eq!(out.len(), 5);
            for seg in 0..5 {
                assert_eq!(out.positions[seg], p[s * 5 + seg], "sample {s} seg {seg}");
                assert_eq!(out.rotations[seg], q[s * 5 + seg], "sample {s} seg {seg}");
            }
        }
    }
}

#[test]
fn affine_positions_are_reproduced() {
    // Positions an affine function of the parameters: every query reproduces
    // it, on linear axes and on Catmull-Rom axes (bounded ends included).
    let mut rng = Rng::new(2);
    let cr = |a: RefAxis| RefAxis { cubic: true, ..a };
    for axes in [
        vec![lin(-0.3, 0.1, 5), lin(0.8, 0.15, 4), lin(0.2, 0.2, 3)],
        vec![
            cr(lin(-0.3, 0.1, 5)),
            lin(0.8, 0.15, 4),
            cr(lin(0.2, 0.2, 4)),
        ],
    ] {
        let m: Vec<[V; 3]> = (0..3)
            .map(|_| [0; 3].map(|_| [0; 3].map(|_| rng.range(-2.0, 2.0))))
            .collect();
        let b: Vec<V> = (0..3)
            .map(|_| [0; 3].map(|_| rng.range(-1.0, 1.0)))
            .collect();
        let affine = |seg: usize, x: &[f64]| -> V {
            [0, 1, 2].map(|i| b[seg][i] + (0..3).map(|j| m[seg][j][i] * x[j]).sum::<f64>())
        };
        let mut g = random_grid(axes.clone(), 3, 0.5, 3);
        for s in 0..g.sample_count() {
            let (mut rest, mut x) = (s, Vec::new());
            for a in &axes {
                x.push(a.min + (rest % a.count) as f64 * a.step);
                rest /= a.count;
            }
            for seg in 0..3 {
                g.pos[s * 3 + seg] = affine(seg, &x);
            }
        }
        let (caxes, p, q) = core_grid(&g);
        let grid = Grid::new(&caxes, None).unwrap();
        let samples = SliceSamples::new(3, &p, &q).unwrap();
        let mut out = Pose::<3>::default();
        let mut max = 0.0f64;
        for _ in 0..5000 {
            let x = random_params(&mut rng, &axes, 0.0);
            let xf: Vec<f32> = x.iter().map(|&v| v as f32).collect();
            grid.synthesize(&samples, &xf, &mut out).unwrap();
            let xe: Vec<f64> = xf.iter().map(|&v| f64::from(v)).collect();
            for seg in 0..3 {
                max = max.max(dist(v64(out.positions[seg]), affine(seg, &xe)));
            }
        }
        println!("affine reproduction max error {max:e} m");
        assert!(max < 2e-5, "{max:e}");
    }
}

/// The W&H hand grid: three linear axes (the trilinear tree).
fn hand_layout() -> Vec<RefAxis> {
    vec![lin(-0.3, 0.1, 5), lin(0.8, 0.15, 4), lin(0.2, 0.2, 3)]
}

/// The W&H pedalling layout: two linear axes and a cyclic Catmull-Rom one.
fn pedal_layout() -> Vec<RefAxis> {
    let crank = lin(0.0, std::f64::consts::TAU / 8.0, 8);
    vec![
        lin(-0.2, 0.1, 3),
        lin(0.1, 0.05, 3),
        RefAxis {
            cubic: true,
            cyclic: true,
            ..crank
        },
    ]
}

#[test]
fn grid_matches_f64_reference_tree() {
    // Trilinear (W&H hand grid), the W&H pedalling layout (2 linear + cyclic
    // Catmull-Rom), and a bounded Catmull-Rom mix, against the f64 tree.
    let cr = |a: RefAxis| RefAxis { cubic: true, ..a };
    let configs = [
        hand_layout(),
        pedal_layout(),
        vec![cr(lin(0.0, 0.5, 6)), lin(1.0, 1.0, 2)],
        vec![
            lin(0.0, 1.0, 3),
            lin(0.0, 1.0, 2),
            lin(0.0, 1.0, 2),
            lin(0.0, 1.0, 2),
            lin(0.0, 1.0, 2),
            lin(0.0, 1.0, 2),
        ],
    ];
    let mut rng = Rng::new(4);
    for (ci, axes) in configs.into_iter().enumerate() {
        let g = random_grid(axes.clone(), 4, 1.2, 10 + ci as u64);
        let gr = g.rounded();
        let (caxes, p, q) = core_grid(&g);
        let grid = Grid::new(&caxes, None).unwrap();
        let samples = SliceSamples::new(4, &p, &q).unwrap();
        let mut out = Pose::<4>::default();
        let (mut ep, mut eq) = (0.0f64, 0.0f64);
        for _ in 0..3000 {
            let x = random_params(&mut rng, &axes, 0.0);
            let xf: Vec<f32> = x.iter().map(|&v| v as f32).collect();
            let query = grid.query(&xf).unwrap();
            query.pose(&samples, &mut out).unwrap();
            // Compare at the parameters the query reports using (grid-point
            // snapping moves them by at most a few ulp).
            for (&a, &b) in query.params().iter().zip(&xf) {
                assert!((a - b).abs() <= 1e-6 * (1.0 + b.abs()), "{a} {b}");
            }
            let xe: Vec<f64> = query.params().iter().map(|&v| f64::from(v)).collect();
            for seg in 0..4 {
                let (pe, qe) = gr.eval(&xe, seg);
                ep = ep.max(dist(v64(out.positions[seg]), pe));
                eq = eq.max(r::angle_between(q64(out.rotations[seg]), qe));
                let (ps, qs) = grid.query(&xf).unwrap().segment(&samples, seg).unwrap();
                assert_eq!((ps, qs), (out.positions[seg], out.rotations[seg]));
            }
        }
        println!("config {ci}: max position error {ep:e} m, rotation {eq:e} rad");
        assert!(ep < 1e-5, "config {ci}: {ep:e}");
        assert!(eq < 5e-5, "config {ci}: {eq:e}");
    }
}

/// Parameters on a cell face, edge or corner: each axis at a random grid
/// line (`t` exactly 0 or 1 after snapping) with probability ½.
fn face_params(rng: &mut Rng, axes: &[RefAxis]) -> Vec<f32> {
    let inside = random_params(rng, axes, 0.0);
    axes.iter()
        .zip(inside)
        .map(|(a, x)| {
            if rng.range(0.0, 1.0) < 0.5 {
                let i = (rng.range(0.0, a.count as f64) as usize).min(a.count - 1);
                (a.min + i as f64 * a.step) as f32
            } else {
                x as f32
            }
        })
        .collect()
}

#[test]
fn trilinear_tree_on_cell_faces_matches_f64_reference() {
    // The W&H hand grid's own tree (unnormalized blends, one normalization at
    // the root) with some levels at an endpoint: the root may then be an
    // unnormalized blend passed through, and must still come out unit and
    // within the tree's error. 31 segments: full and partial lane groups.
    let axes = vec![lin(-0.3, 0.1, 5), lin(0.8, 0.15, 4), lin(0.2, 0.2, 3)];
    let g = random_grid(axes.clone(), 31, 1.2, 21);
    let gr = g.rounded();
    let (caxes, p, q) = core_grid(&g);
    let grid = Grid::new(&caxes, None).unwrap();
    let samples = SliceSamples::new(31, &p, &q).unwrap();
    let mut out = Pose::<31>::default();
    let mut rng = Rng::new(22);
    let (mut ep, mut eq, mut en) = (0.0f64, 0.0f64, 0.0f64);
    for _ in 0..2000 {
        let xf = face_params(&mut rng, &axes);
        let query = grid.query(&xf).unwrap();
        query.pose(&samples, &mut out).unwrap();
        let xe: Vec<f64> = query.params().iter().map(|&v| f64::from(v)).collect();
        for seg in 0..31 {
            let (pe, qe) = gr.eval(&xe, seg);
            let r = out.rotations[seg];
            ep = ep.max(dist(v64(out.positions[seg]), pe));
            eq = eq.max(r::angle_between(q64(r), qe));
            en = en.max((r::dot(q64(r), q64(r)).sqrt() - 1.0).abs());
            let one = query.segment(&samples, seg).unwrap();
            assert_eq!(one, (out.positions[seg], r), "segment {seg} at {xf:?}");
        }
    }
    println!("cell faces: max position error {ep:e} m, rotation {eq:e} rad, |q| − 1 {en:e}");
    assert!(ep < 1e-5, "{ep:e}");
    assert!(eq < 5e-5, "{eq:e}");
    assert!(en < 1e-6, "{en:e}");
}

/// Samples read one call at a time (no [`Samples::row`]), optionally hinting
/// that they decode: the grid's other read paths.
struct OneByOne<'a> {
    inner: SliceSamples<'a>,
}

impl Samples for OneByOne<'_> {
    fn segment_count(&self) -> usize {
        self.inner.segment_count()
    }
    fn sample_count(&self) -> usize {
        self.inner.sample_count()
    }
    fn sample(&self, index: usize, segment: usize) -> Option<(Vec3, Quat)> {
        self.inner.sample(index, segment)
    }
}

/// [`OneByOne`] with the decoding hint set.
struct Decoding<'a>(OneByOne<'a>);

impl Samples for Decoding<'_> {
    const DECODES: bool = true;
    fn segment_count(&self) -> usize {
        self.0.segment_count()
    }
    fn sample_count(&self) -> usize {
        self.0.sample_count()
    }
    fn sample(&self, index: usize, segment: usize) -> Option<(Vec3, Quat)> {
        self.0.sample(index, segment)
    }
}

#[test]
fn every_read_path_gives_the_same_bits() {
    // Host blocks and the Cortex-M's one-segment-at-a-time path
    // (`pose_scalar`), with rows, one call per sample, or the decoding hint:
    // the same operations in the same order, so the same bits, on the hand
    // grid (its own tree), the pedal layout and a 2-axis grid.
    let configs = [
        hand_layout(),
        pedal_layout(),
        vec![lin(0.0, 0.5, 6), lin(1.0, 1.0, 2)],
    ];
    let bits = |p: &Pose<31>| {
        let pos = p
            .positions
            .iter()
            .flat_map(|v| v.to_array().map(f32::to_bits));
        let rot = p
            .rotations
            .iter()
            .flat_map(|q| q.to_array().map(f32::to_bits));
        pos.chain(rot).collect::<Vec<u32>>()
    };
    let mut rng = Rng::new(31);
    for (ci, axes) in configs.into_iter().enumerate() {
        let g = random_grid(axes.clone(), 31, 1.2, 40 + ci as u64);
        let (caxes, p, q) = core_grid(&g);
        let grid = Grid::new(&caxes, None).unwrap();
        let rows = SliceSamples::new(31, &p, &q).unwrap();
        let calls = OneByOne { inner: rows };
        let decoding = Decoding(OneByOne { inner: rows });
        let (mut a, mut b) = (Pose::<31>::default(), Pose::<31>::default());
        for i in 0..500 {
            let xf = if i % 2 == 0 {
                face_params(&mut rng, &axes)
            } else {
                let x = random_params(&mut rng, &axes, 0.1);
                x.iter().map(|&v| v as f32).collect()
            };
            let query = grid.query(&xf).unwrap();
            query.pose(&rows, &mut a).unwrap();
            let want = bits(&a);
            query.pose_scalar(&rows, &mut b).unwrap();
            assert_eq!(bits(&b), want, "config {ci}, scalar rows, {xf:?}");
            query.pose(&calls, &mut b).unwrap();
            assert_eq!(bits(&b), want, "config {ci}, calls, {xf:?}");
            query.pose_scalar(&calls, &mut b).unwrap();
            assert_eq!(bits(&b), want, "config {ci}, scalar calls, {xf:?}");
            query.pose(&decoding, &mut b).unwrap();
            assert_eq!(bits(&b), want, "config {ci}, decoding, {xf:?}");
            query.pose_scalar(&decoding, &mut b).unwrap();
            assert_eq!(bits(&b), want, "config {ci}, scalar decoding, {xf:?}");
        }
    }
}

#[test]
fn a_query_is_small() {
    // Returned by value every frame (`Grid::query`): per-axis data only, the
    // per-segment coefficients are derived by `Query::pose`.
    let size = std::mem::size_of::<marionette_core::grid::Query>();
    assert!(size <= 320, "{size} bytes");
}

/// One Catmull-Rom axis with `count` samples of scalar data (in x), rotation
/// about Z by the same value (radians).
fn scalar_cr_grid(
    min: f64,
    step: f64,
    count: usize,
    cyclic: bool,
    f: impl Fn(f64) -> f64,
) -> RefGrid {
    let axes = vec![RefAxis {
        min,
        step,
        count,
        cyclic,
        cubic: true,
    }];
    let pos = (0..count)
        .map(|i| [f(min + i as f64 * step), 0.0, 0.0])
        .collect();
    let rot = (0..count)
        .map(|i| r::axis_angle([0.0, 0.0, 1.0], f(min + i as f64 * step)))
        .collect();
    RefGrid {
        axes,
        segments: 1,
        pos,
        rot,
    }
}

fn eval_scalar(g: &RefGrid, x: f32) -> (f64, Q) {
    let (caxes, p, q) = core_grid(g);
    let grid = Grid::new(&caxes, None).unwrap();
    let samples = SliceSamples::new(1, &p, &q).unwrap();
    let (pp, qq) = grid.query(&[x]).unwrap().segment(&samples, 0).unwrap();
    (f64::from(pp.x), q64(qq))
}

#[test]
fn catmull_rom_reproduces_quadratics_inside_and_lines_everywhere() {
    // Uniform Catmull-Rom's tangents are central differences, exact for
    // quadratics: degree-2 data is reproduced in interior cells. Bounded ends
    // use a linear phantom: lines are reproduced there, quadratics are not.
    let quad = |x: f64| 0.2 + 0.3 * x - 0.25 * x * x;
    let line = |x: f64| -0.4 + 0.7 * x;
    let (gq, gl) = (
        scalar_cr_grid(0.0, 0.5, 7, false, quad),
        scalar_cr_grid(0.0, 0.5, 7, false, line),
    );
    let (mut inner, mut ends, mut lin_err, mut rot_lin, mut rot_quad) =
        (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for i in 0..=3000 {
        let x = (i as f64 * 3.0 / 3000.0) as f32;
        let xe = f64::from(x);
        let (pq, qq) = eval_scalar(&gq, x);
        let (pl, ql) = eval_scalar(&gl, x);
        let interior = (0.5..=2.5).contains(&xe);
        if interior {
            inner = inner.max((pq - quad(xe)).abs());
            rot_quad = rot_quad.max(r::angle_between(
                qq,
                r::axis_angle([0.0, 0.0, 1.0], quad(xe)),
            ));
        } else {
            ends = ends.max((pq - quad(xe)).abs());
        }
        lin_err = lin_err.max((pl - line(xe)).abs());
        rot_lin = rot_lin.max(r::angle_between(
            ql,
            r::axis_angle([0.0, 0.0, 1.0], line(xe)),
        ));
    }
    println!(
        "CR: quadratic interior {inner:e}, quadratic end cells {ends:e}, line {lin_err:e}; rotation line {rot_lin:e}, quadratic interior {rot_quad:e}"
    );
    assert!(inner < 2e-7 && lin_err < 5e-7, "{inner:e} {lin_err:e}");
    assert!(
        rot_lin < 5e-5 && rot_quad < 5e-5,
        "{rot_lin:e} {rot_quad:e}"
    );
    // End cells: the phantom makes the end tangent the chord slope, so the
    // quadratic is missed by a visible amount (about |f''|·h²/16 here).
    assert!(ends > 1e-3, "{ends:e}");
    // Not exact for cubics: the central difference of c·x³ overestimates the
    // slope by δ = c·h², so the Hermite form is off by h·δ·(h10(s) + h11(s))
    // (zero at the cell midpoint, 1.17e-3 at s = 1/4 for c = 0.1, h = 0.5).
    let cube = |x: f64| 0.1 * x * x * x;
    let gc = scalar_cr_grid(0.0, 0.5, 7, false, cube);
    let (pc, _) = eval_scalar(&gc, 1.125);
    let (h, s) = (0.5f64, 0.25f64);
    let predicted = h * 0.1 * h * h * ((s.powi(3) - 2.0 * s * s + s) + (s.powi(3) - s * s));
    assert!(
        ((pc - cube(1.125)) - predicted).abs() < 1e-6,
        "{} vs {predicted}",
        pc - cube(1.125)
    );
}

#[test]
fn cyclic_axis_is_continuous_across_the_wrap() {
    let mut rng = Rng::new(6);
    let axes = vec![
        RefAxis {
            min: 0.5,
            step: 0.25,
            count: 8,
            cyclic: true,
            cubic: true,
        },
        lin(0.0, 1.0, 2),
    ];
    let g = random_grid(axes, 2, 1.0, 7);
    let (caxes, p, q) = core_grid(&g);
    let grid = Grid::new(&caxes, None).unwrap();
    let samples = SliceSamples::new(2, &p, &q).unwrap();
    let y = rng.range(0.0, 1.0) as f32;
    let at = |x: f32| grid.query(&[x, y]).unwrap().segment(&samples, 1).unwrap();
    // Same pose one period apart, and tiny steps give tiny changes everywhere,
    // including across min + period.
    for i in 0..50 {
        let x = 0.5 + i as f32 * 0.04;
        let (p0, q0) = at(x);
        let (p1, q1) = at(x + 2.0);
        assert!((p0 - p1).length() < 1e-5 && r::angle_between(q64(q0), q64(q1)) < 1e-4);
    }
    let (mut jump_p, mut jump_q) = (0.0f32, 0.0f64);
    let mut prev = at(0.4);
    for i in 1..=4000 {
        let cur = at(0.4 + i as f32 * 5e-5);
        jump_p = jump_p.max((cur.0 - prev.0).length());
        jump_q = jump_q.max(r::angle_between(q64(cur.1), q64(prev.1)));
        prev = cur;
    }
    println!("cyclic sweep across the wrap: max step {jump_p:e} m, {jump_q:e} rad per 5e-5");
    assert!(jump_p < 2e-3 && jump_q < 2e-3, "{jump_p:e} {jump_q:e}");
}

#[test]
fn nan_clamp_and_invalid_cell_policies() {
    let axes = vec![lin(0.0, 1.0, 5), lin(0.0, 1.0, 3)];
    let g = random_grid(axes, 1, 0.5, 8);
    let (caxes, p, q) = core_grid(&g);
    let samples = SliceSamples::new(1, &p, &q).unwrap();
    let grid = Grid::new(&caxes, None).unwrap();
    let mut out = Pose::<1>::default();
    assert_eq!(
        grid.synthesize(&samples, &[f32::NAN, 0.0], &mut out),
        Err(GridError::NonFinite { axis: 0 })
    );
    assert_eq!(
        grid.synthesize(&samples, &[0.0, f32::INFINITY], &mut out),
        Err(GridError::NonFinite { axis: 1 })
    );
    // Out of range clamps to the boundary.
    let mut edge = Pose::<1>::default();
    assert_eq!(
        grid.synthesize(&samples, &[7.5, -3.0], &mut out),
        Ok(Adjust::Clamped)
    );
    assert_eq!(
        grid.synthesize(&samples, &[4.0, 0.0], &mut edge),
        Ok(Adjust::None)
    );
    assert_eq!(out, edge);
    // Cells 0..4 along x, 0..2 along y; invalidate the x ≥ 2 half of row y=0.
    // mask bit c = x + 4y: cells 2, 3 invalid.
    let mask = [0b1111_0011u8];
    let grid = Grid::new(&caxes, Some(&mask)).unwrap();
    let query = grid.query(&[3.5, 0.25]).unwrap();
    assert_eq!(query.adjust(), Adjust::Projected);
    // Nearest valid cell to (3.5, 0.25): cell (3, 1) at distance 0.75 (vs 1.5 to (1, 0)).
    assert_eq!(query.params(), &[3.5, 1.0]);
    let unmasked = Grid::new(&caxes, None).unwrap();
    let (pa, qa) = query.segment(&samples, 0).unwrap();
    let (pb, qb) = unmasked
        .query(&[3.5, 1.0])
        .unwrap()
        .segment(&samples, 0)
        .unwrap();
    assert_eq!((pa, qa), (pb, qb));
    // Inside the valid region nothing changes.
    assert_eq!(grid.query(&[1.5, 0.5]).unwrap().adjust(), Adjust::None);
    // Missing samples are an error, not a panic.
    let short = SliceSamples::new(1, &p[..3], &q[..3]).unwrap();
    assert_eq!(
        grid.synthesize(&short, &[1.5, 0.5], &mut out),
        Err(GridError::MissingSample)
    );
    assert_eq!(
        grid.synthesize(&samples, &[1.5, 0.5], &mut Pose::<0>::default()),
        Err(GridError::Capacity)
    );
}

#[test]
fn catmull_rom_ignores_samples_only_invalid_cells_touch() {
    // A Catmull-Rom axis next to an invalid cell uses the linear phantom
    // instead of the far sample, so garbage there cannot leak in.
    let line = |x: f64| 1.0 + 0.5 * x;
    let mut g = scalar_cr_grid(0.0, 1.0, 6, false, line);
    g.pos[5] = [1e6, 1e6, 1e6];
    g.rot[5] = [1.0, 0.0, 0.0, 0.0];
    let (caxes, p, q) = core_grid(&g);
    let samples = SliceSamples::new(1, &p, &q).unwrap();
    // Cells 0..5; cell 4 (between samples 4 and 5) invalid.
    let grid = Grid::new(&caxes, Some(&[0b0_1111])).unwrap();
    for i in 0..=100 {
        let x = 2.0 + i as f32 * 0.02;
        let query = grid.query(&[x]).unwrap();
        assert_eq!(query.adjust(), Adjust::None);
        let (pp, qq) = query.segment(&samples, 0).unwrap();
        assert!(
            (f64::from(pp.x) - line(f64::from(x))).abs() < 1e-5,
            "{x}: {pp}"
        );
        assert!(
            r::angle_between(q64(qq), r::axis_angle([0.0, 0.0, 1.0], line(f64::from(x)))) < 5e-5
        );
    }
}

#[test]
fn slice_samples_layout() {
    let p: Vec<Vec3> = (0..6).map(|i| Vec3::splat(i as f32)).collect();
    let q = vec![Quat::IDENTITY; 6];
    assert!(SliceSamples::new(4, &p, &q).is_none());
    let s = SliceSamples::new(3, &p, &q).unwrap();
    assert_eq!((s.segment_count(), s.sample_count()), (3, 2));
    assert_eq!(s.sample(1, 2).unwrap().0, Vec3::splat(5.0));
    assert!(s.sample(2, 0).is_none() && s.sample(0, 3).is_none());
}

// ---------------------------------------------------------------- pose / FK

/// A random tree of `n` segments (parents before children).
fn random_hierarchy(rng: &mut Rng, n: usize) -> (Vec<u8>, Vec<Vec3>) {
    let parents = (0..n)
        .map(|i| {
            if i == 0 {
                NO_PARENT
            } else {
                (rng.next_u64() % i as u64) as u8
            }
        })
        .collect();
    let offsets = (0..n)
        .map(|_| v32([0; 3].map(|_| rng.range(-0.4, 0.4))))
        .collect();
    (parents, offsets)
}

/// Forward kinematics in f64.
fn fk64(parents: &[u8], offsets: &[Vec3], root: V, local: &[Q]) -> (Vec<V>, Vec<Q>) {
    let (mut p, mut q): (Vec<V>, Vec<Q>) = (Vec::new(), Vec::new());
    for i in 0..parents.len() {
        if parents[i] == NO_PARENT {
            p.push(root);
            q.push(local[i]);
        } else {
            let j = parents[i] as usize;
            let o = r::rotate(q[j], v64(offsets[i]));
            p.push([0, 1, 2].map(|k| p[j][k] + o[k]));
            q.push(r::mul(q[j], local[i]));
        }
    }
    (p, q)
}

#[test]
fn forward_kinematics_matches_f64_and_round_trips() {
    let mut rng = Rng::new(21);
    for _ in 0..200 {
        let n = 1 + (rng.next_u64() % 40) as usize;
        let (parents, offsets) = random_hierarchy(&mut rng, n);
        let h = Hierarchy {
            parents: &parents,
            offsets: &offsets,
        };
        let mut local = LocalPose::<64>::new(n).unwrap();
        local.root_position = v32([0; 3].map(|_| rng.range(-2.0, 2.0)));
        let lq: Vec<Q> = (0..n).map(|_| rng.quat()).collect();
        for (d, q) in local.rotations.iter_mut().zip(&lq) {
            *d = q32(*q);
        }
        let mut world = Pose::<64>::default();
        pose::forward(&h, &local, &mut world).unwrap();
        let lq32: Vec<Q> = local.rotations[..n].iter().map(|&q| q64(q)).collect();
        let (pe, qe) = fk64(&parents, &offsets, v64(local.root_position), &lq32);
        for i in 0..n {
            assert!(dist(v64(world.positions[i]), pe[i]) < 1e-5, "{i}");
            assert!(
                r::angle_between(q64(world.rotations[i]), qe[i]) < 2e-5,
                "{i}"
            );
        }
        // to_local(forward(x)) == x
        let mut back = LocalPose::<64>::default();
        pose::to_local(&h, &world, &mut back).unwrap();
        assert_eq!(back.len(), n);
        assert_eq!(back.root_position, local.root_position);
        for i in 0..n {
            assert!(r::angle_between(q64(back.rotations[i]), q64(local.rotations[i])) < 2e-5);
        }
        // forward(to_local(p)) == p for a consistent p
        let mut again = Pose::<64>::default();
        pose::forward(&h, &back, &mut again).unwrap();
        for i in 0..n {
            assert!((again.positions[i] - world.positions[i]).length() < 1e-5);
        }
    }
}

#[test]
fn enforce_lengths_matches_independent_computation() {
    let mut rng = Rng::new(22);
    for _ in 0..200 {
        let n = 2 + (rng.next_u64() % 30) as usize;
        let (parents, offsets) = random_hierarchy(&mut rng, n);
        let h = Hierarchy {
            parents: &parents,
            offsets: &offsets,
        };
        let mut p = Pose::<32>::new(n).unwrap();
        for i in 0..n {
            p.set(
                i,
                v32([0; 3].map(|_| rng.range(-1.0, 1.0))),
                q32(rng.quat()),
            )
            .unwrap();
        }
        // Reference: new[i] = new[parent] + |offset_i| · unit(old[i] − old[parent]).
        let old: Vec<V> = p.positions().iter().map(|&v| v64(v)).collect();
        let mut expect = old.clone();
        for i in 1..n {
            let j = parents[i] as usize;
            let d = [0, 1, 2].map(|k| old[i][k] - old[j][k]);
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let l = f64::from(offsets[i].length());
            expect[i] = [0, 1, 2].map(|k| expect[j][k] + d[k] / len * l);
        }
        let rots = p.rotations;
        pose::enforce_lengths(&h, &mut p).unwrap();
        assert_eq!(p.rotations, rots);
        for i in 0..n {
            assert!(dist(v64(p.positions[i]), expect[i]) < 1e-5, "{i}");
            if i > 0 {
                let j = parents[i] as usize;
                let l = (p.positions[i] - p.positions[j]).length();
                assert!((l - offsets[i].length()).abs() < 1e-5);
            }
        }
    }
}

#[test]
fn pose_math_is_deterministic_scalar_code() {
    // The same inputs give the same bits through the public entry points used
    // by host and firmware (guards against accidental use of std/libm paths).
    let a = math::from_axis_angle(Vec3::new(0.3, -0.2, 0.9), 1.1);
    let b = math::from_axis_angle(Vec3::new(-0.5, 0.1, 0.2), -0.7);
    let s1 = math::slerp(a, b, 0.37);
    let s2 = math::SlerpWeight::new(0.37).apply(a, b);
    assert_eq!(s1, s2);
    assert!(r::angle_between(q64(s1), r::slerp(q64(a), q64(b), 0.37)) < 2e-5);
}

// ---------------------------------------------------------------- clips

use marionette_core::clip::{self, ClipError, Clips, SliceDurations, Span};

/// Clips on one parameter axis (`params` values) with `frames` frames each,
/// laid out like a clip table (parameter fastest, then frame).
struct ClipSet {
    params: Axis,
    phase: Axis,
    p: Vec<Vec3>,
    q: Vec<Quat>,
    durations: Vec<f32>,
    segments: usize,
}

fn clip_set(looping: bool, phases: usize, frames: u32, seed: u64) -> ClipSet {
    let mut rng = Rng::new(seed);
    let segments = 2;
    let params = Axis::linear(1.0, 0.5, 3);
    let phase = if looping {
        Axis {
            min: 0.0,
            step: 1.0 / frames as f32,
            count: frames,
            wrap: Wrap::Cyclic { period: 1.0 },
            interp: Interp::Linear,
        }
    } else {
        Axis::linear(0.0, phases as f32 / (frames - 1) as f32, frames)
    };
    let n = 3 * frames as usize * segments;
    let base: Vec<Q> = (0..segments).map(|_| rng.quat()).collect();
    let mut p = Vec::with_capacity(n);
    let mut q = Vec::with_capacity(n);
    for i in 0..n {
        p.push(v32([0; 3].map(|_| rng.range(-1.0, 1.0))));
        let d = r::axis_angle([0; 3].map(|_| rng.range(-1.0, 1.0)), rng.range(0.0, 1.0));
        q.push(q32(r::mul(base[i % segments], d)));
    }
    let durations = (0..3 * phases)
        .map(|_| rng.range(0.5, 2.0) as f32)
        .collect();
    ClipSet {
        params,
        phase,
        p,
        q,
        durations,
        segments,
    }
}

impl ClipSet {
    fn clips(&self, phases: usize) -> Clips<'static> {
        let grid = Grid::new(&[self.params, self.phase], None).unwrap();
        let params = Grid::new(&[self.params], None).unwrap();
        Clips::new(grid, params, phases).unwrap()
    }
    fn frame(&self, clip: usize, frame: usize, seg: usize) -> (Vec3, Quat) {
        let i = (clip + 3 * frame) * self.segments + seg;
        (self.p[i], self.q[i])
    }
}

#[test]
fn clip_coefficients_zero_and_one_return_the_stored_clips_exactly() {
    for (looping, phases) in [(true, 1), (false, 1), (false, 2)] {
        let set = clip_set(looping, phases, 9, 30);
        let clips = set.clips(phases);
        let samples = SliceSamples::new(set.segments, &set.p, &set.q).unwrap();
        let durs = SliceDurations {
            phases,
            values: &set.durations,
        };
        let mut out = Pose::<4>::default();
        for c in 0..3 {
            let m = clips.motion(&durs, &[1.0 + 0.5 * c as f32]).unwrap();
            // Durations exactly the stored ones.
            assert_eq!(m.durations(), &set.durations[c * phases..(c + 1) * phases]);
            // Every frame exactly the stored frame.
            for f in 0..9usize {
                let phase = f as f32 * set.phase.step;
                clips.pose(&m, &samples, phase, &mut out).unwrap();
                for s in 0..set.segments {
                    assert_eq!(
                        (out.positions[s], out.rotations[s]),
                        set.frame(c, f, s),
                        "clip {c} frame {f}"
                    );
                }
            }
        }
    }
}

#[test]
fn clip_interpolation_between_clips_and_durations() {
    let set = clip_set(false, 2, 9, 31);
    let clips = set.clips(2);
    let samples = SliceSamples::new(set.segments, &set.p, &set.q).unwrap();
    let durs = SliceDurations {
        phases: 2,
        values: &set.durations,
    };
    let mut out = Pose::<4>::default();
    let mut rng = Rng::new(32);
    for _ in 0..500 {
        let x = rng.range(1.0, 2.0) as f32;
        let m = clips.motion(&durs, &[x]).unwrap();
        let u = (f64::from(x) - 1.0) / 0.5;
        let (c, t) = ((u.floor() as usize).min(1), u - (u.floor()).min(1.0));
        for k in 0..2 {
            let e = f64::from(set.durations[c * 2 + k]) * (1.0 - t)
                + f64::from(set.durations[(c + 1) * 2 + k]) * t;
            assert!((f64::from(m.durations()[k]) - e).abs() < 1e-5, "{k}");
        }
        // At a frame's phase: slerp/lerp between the two clips' frames.
        let f = (rng.next_u64() % 9) as usize;
        clips.pose(&m, &samples, f as f32 * 0.25, &mut out).unwrap();
        for s in 0..set.segments {
            let (pa, qa) = set.frame(c, f, s);
            let (pb, qb) = set.frame(c + 1, f, s);
            assert!(dist(v64(out.positions[s]), r::lerp3(v64(pa), v64(pb), t)) < 1e-5);
            assert!(r::angle_between(q64(out.rotations[s]), r::slerp(q64(qa), q64(qb), t)) < 2e-5);
        }
        // Reach timing: phase 1 (the reach pose) at the first duration.
        let d0 = m.durations()[0];
        assert!((m.phase_at(d0).unwrap() - 1.0).abs() < 1e-6);
        assert!(
            m.phase_at(d0 * 0.5).unwrap() < 1.0
                && m.phase_at(d0 + 0.5 * m.durations()[1]).unwrap() > 1.0
        );
        assert_eq!(m.phase_at(m.duration() + 1.0).unwrap(), 2.0);
    }
    assert_eq!(
        clips.motion(&durs, &[f32::NAN]).err(),
        Some(ClipError::Grid(GridError::NonFinite { axis: 0 }))
    );
    let bad = SliceDurations {
        phases: 2,
        values: &[1.0; 5],
    };
    assert_eq!(clips.motion(&bad, &[1.9]).err(), Some(ClipError::Duration));
    let negative = SliceDurations {
        phases: 2,
        values: &[1.0, 1.0, -1.0, 1.0, 1.0, 1.0],
    };
    assert_eq!(
        clips.motion(&negative, &[1.2]).err(),
        Some(ClipError::Duration)
    );
}

#[test]
fn reach_by_time_crosses_segments_at_the_interpolated_duration() {
    let set = clip_set(false, 2, 9, 33);
    let clips = set.clips(2);
    let samples = SliceSamples::new(set.segments, &set.p, &set.q).unwrap();
    let durs = SliceDurations {
        phases: 2,
        values: &set.durations,
    };
    let m = clips.motion(&durs, &[1.5]).unwrap();
    let (mut a, mut b) = (Pose::<4>::default(), Pose::<4>::default());
    // Time 0, the boundary and the end are frames 0, 4 and 8 of clip 1, exactly.
    for (time, frame) in [(0.0, 0), (m.durations()[0], 4), (m.duration(), 8)] {
        clips.pose_at_time(&m, &samples, time, &mut a).unwrap();
        for s in 0..set.segments {
            assert_eq!(
                (a.positions[s], a.rotations[s]),
                set.frame(1, frame, s),
                "t={time}"
            );
        }
    }
    // Continuous across the boundary.
    let d0 = m.durations()[0];
    clips
        .pose_at_time(&m, &samples, d0 * (1.0 - 1e-4), &mut a)
        .unwrap();
    clips
        .pose_at_time(&m, &samples, d0 * (1.0 + 1e-4), &mut b)
        .unwrap();
    assert!((a.positions[0] - b.positions[0]).length() < 1e-2);
}

#[test]
fn looping_clip_is_continuous_across_phase_one() {
    let set = clip_set(true, 1, 12, 34);
    let clips = set.clips(1);
    let samples = SliceSamples::new(set.segments, &set.p, &set.q).unwrap();
    let durs = SliceDurations {
        phases: 1,
        values: &set.durations,
    };
    let m = clips.motion(&durs, &[1.25]).unwrap();
    let (mut a, mut b) = (Pose::<4>::default(), Pose::<4>::default());
    clips.pose(&m, &samples, 1.0 - 1e-6, &mut a).unwrap();
    clips.pose(&m, &samples, 0.0, &mut b).unwrap();
    assert!((a.positions[1] - b.positions[1]).length() < 1e-4);
    assert!(r::angle_between(q64(a.rotations[1]), q64(b.rotations[1])) < 1e-4);
    // A whole cycle later: the same pose.
    clips.pose_at_time(&m, &samples, 0.3, &mut a).unwrap();
    clips
        .pose_at_time(&m, &samples, 0.3 + m.duration(), &mut b)
        .unwrap();
    assert!((a.positions[0] - b.positions[0]).length() < 1e-5);
}

#[test]
fn resample_matches_analytic_motion() {
    // Source: x = sin(t), rotation by 0.8·t about a fixed axis, at uneven
    // times; resampled frames are within the linear/slerp interpolation error
    // of the closed form (rotation: exact up to slerp accuracy, since the
    // rotation is uniform between any two frames).
    let mut rng = Rng::new(35);
    let mut times = vec![0.0f32];
    while *times.last().unwrap() < 2.0 {
        times.push(times.last().unwrap() + rng.range(0.005, 0.02) as f32);
    }
    let axis = [0.3, -0.5, 0.8];
    let p: Vec<Vec3> = times
        .iter()
        .map(|&t| Vec3::new(f64::from(t).sin() as f32, 0.0, 0.0))
        .collect();
    let q: Vec<Quat> = times
        .iter()
        .map(|&t| q32(r::axis_angle(axis, 0.8 * f64::from(t))))
        .collect();
    let src = SliceSamples::new(1, &p, &q).unwrap();
    let frames = 50;
    let (mut op, mut oq) = (vec![Vec3::ZERO; frames], vec![Quat::IDENTITY; frames]);
    clip::resample(
        &src,
        &times,
        Span {
            start: 0.1,
            end: 1.9,
        },
        false,
        frames,
        &mut op,
        &mut oq,
    )
    .unwrap();
    for j in 0..frames {
        let t = 0.1 + 1.8 * j as f64 / (frames - 1) as f64;
        // Linear interpolation error of sin over 0.02 s is below 0.02²/8.
        assert!((f64::from(op[j].x) - t.sin()).abs() < 6e-5, "{j}");
        assert!(
            r::angle_between(q64(oq[j]), r::axis_angle(axis, 0.8 * t)) < 2e-5,
            "{j}"
        );
    }
}

#[test]
fn seam_blend_closes_the_loop_smoothly() {
    // A circle of 41 frames (frame 40 should equal frame 0) with a 3 cm and
    // 0.1 rad seam error added progressively.
    let k = 40;
    let segments = 1;
    let axis = [0.0, 1.0, 0.0];
    let mut p: Vec<Vec3> = (0..=k)
        .map(|i| {
            let a = std::f64::consts::TAU * i as f64 / k as f64;
            v32([a.cos(), a.sin(), 0.0]) + Vec3::new(0.03 * i as f32 / k as f32, 0.0, 0.0)
        })
        .collect();
    let mut q: Vec<Quat> = (0..=k)
        .map(|i| q32(r::axis_angle(axis, 0.1 * i as f64 / k as f64)))
        .collect();
    let original = (p.clone(), q.clone());
    let n = clip::seam_blend(&mut p, &mut q, segments, 8).unwrap();
    assert_eq!(n, k);
    // Frames K and 0 now coincide.
    assert!((p[k] - p[0]).length() < 1e-6);
    assert!(r::angle_between(q64(q[k]), q64(q[0])) < 2e-5);
    // Frames outside both windows are untouched.
    for i in 9..k - 8 {
        assert_eq!((p[i], q[i]), (original.0[i], original.1[i]));
    }
    // The wrap step K−1 → 0 is no larger than an ordinary step, plus a small ramp term.
    let step = |a: Vec3, b: Vec3| (a - b).length();
    let ordinary = step(original.0[20], original.0[21]);
    assert!(
        step(p[k - 1], p[0]) < ordinary * 1.1,
        "{} vs {ordinary}",
        step(p[k - 1], p[0])
    );
    assert_eq!(
        clip::seam_blend(&mut p, &mut q, segments, 30),
        Err(ClipError::OutputLength)
    );
}

// ---------------------------------------------------------------- real data (HDM05)

use marionette_host::import::{EndSites, amc};

/// World poses of every frame of an HDM05 take (bk actor), via the host's
/// ASF/AMC importer and the core's forward kinematics.
fn hdm05(take: &str) -> (Vec<String>, Vec<u8>, Vec<Vec3>, Vec<Pose<64>>, f32) {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/hdm05_bk");
    let motion = amc::read_motion(
        &dir.join("HDM_bk.asf"),
        &dir.join(format!("HDM_bk_{take}_120.amc")),
        1.0 / 120.0,
    )
    .expect("HDM05 take");
    let skel = motion.core_skeleton(EndSites::Drop).expect("skeleton");
    let poses = (0..motion.frames.len())
        .map(|f| {
            let local = motion.local_pose::<64>(&skel, f).expect("frame");
            let mut world = Pose::<64>::default();
            pose::forward(&skel.hierarchy(), &local, &mut world).expect("fk");
            world
        })
        .collect();
    (
        skel.names.clone(),
        skel.parents.clone(),
        skel.offsets.clone(),
        poses,
        motion.frame_time as f32,
    )
}

/// Flattens poses into `[sample][segment]` slices.
fn flatten(poses: &[Pose<64>]) -> (Vec<Vec3>, Vec<Quat>) {
    let p = poses.iter().flat_map(|x| x.positions().to_vec()).collect();
    let q = poses.iter().flat_map(|x| x.rotations().to_vec()).collect();
    (p, q)
}

/// Held-out error of a 1-D grid over time: every `stride`-th frame of a real
/// take is a grid sample; the frames in between are synthesized and compared
/// with the recorded ones (all segments). Linear and Catmull-Rom axes.
#[test]
fn hdm05_held_out_synthesis_error() {
    for take in ["rotateArmsBothBackward1Reps_007", "grabHighR_005"] {
        let (names, _, _, poses, _) = hdm05(take);
        let segs = names.len();
        let stride = 8usize;
        let count = (poses.len() - 1) / stride + 1;
        let kept: Vec<Pose<64>> = (0..count).map(|i| poses[i * stride]).collect();
        let (p, q) = flatten(&kept);
        let samples = SliceSamples::new(segs, &p, &q).unwrap();
        for interp in [Interp::Linear, Interp::CatmullRom] {
            let axis = Axis {
                min: 0.0,
                step: stride as f32,
                count: count as u32,
                wrap: Wrap::Bounded,
                interp,
            };
            let grid = Grid::new(&[axis], None).unwrap();
            let mut out = Pose::<64>::default();
            let (mut sum_p, mut max_p, mut sum_q, mut max_q, mut n) =
                (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0usize);
            for (f, actual) in poses.iter().enumerate().take((count - 1) * stride + 1) {
                grid.synthesize(&samples, &[f as f32], &mut out).unwrap();
                if f % stride == 0 {
                    assert_eq!(out.positions(), actual.positions(), "grid point {f}");
                    continue;
                }
                for s in 0..segs {
                    let ep = dist(v64(out.positions[s]), v64(actual.positions[s]));
                    let eq = r::angle_between(q64(out.rotations[s]), q64(actual.rotations[s]));
                    (sum_p, max_p, sum_q, max_q, n) =
                        (sum_p + ep, max_p.max(ep), sum_q + eq, max_q.max(eq), n + 1);
                }
            }
            let (mean_p, mean_q) = (sum_p / n as f64, sum_q / n as f64);
            println!(
                "HDM05 {take}, {segs} segments, every {stride}th frame kept (15 Hz), {interp:?}: held-out position error mean {:.2} mm max {:.1} mm; rotation mean {:.3}° max {:.2}°",
                mean_p * 1e3,
                max_p * 1e3,
                mean_q.to_degrees(),
                max_q.to_degrees()
            );
            // Loose sanity bounds (15 Hz keyframes of 120 Hz capture).
            assert!(mean_p < 5e-3 && max_p < 0.1, "{mean_p} {max_p}");
            assert!(mean_q < 0.02 && max_q < 0.5, "{mean_q} {max_q}");
        }
    }
}

/// A real reach (grab from a high shelf) as a two-phase clip: split at the
/// highest right-hand frame, each phase resampled to 17 frames; two takes
/// form a one-parameter clip grid. Coefficients 0/1 give each take back at
/// its own timing, the reach pose sits exactly at the first phase's duration,
/// and the held-out error of the resampled clip against the recording is
/// reported.
#[test]
fn hdm05_reach_clips() {
    let takes = ["grabHighR_005", "grabHighR_006"];
    let frames_per_phase = 17usize;
    let count = 2 * (frames_per_phase - 1) + 1;
    let mut clip_p = vec![Vec3::ZERO; 0];
    let mut clip_q = vec![Quat::IDENTITY; 0];
    let mut durations = Vec::new();
    let mut recordings = Vec::new();
    let mut segs = 0;
    // Frames of both clips, resampled: per take, [frame][segment].
    let mut resampled: Vec<(Vec<Vec3>, Vec<Quat>)> = Vec::new();
    for take in takes {
        let (names, _, _, poses, dt) = hdm05(take);
        segs = names.len();
        let hand = names.iter().position(|n| n == "rhand").expect("rhand");
        let reach = (0..poses.len())
            .max_by(|&a, &b| {
                poses[a].positions[hand]
                    .y
                    .total_cmp(&poses[b].positions[hand].y)
            })
            .unwrap();
        let times: Vec<f32> = (0..poses.len()).map(|f| f as f32 * dt).collect();
        let (p, q) = flatten(&poses);
        let src = SliceSamples::new(segs, &p, &q).unwrap();
        let (mut op, mut oq) = (Vec::new(), Vec::new());
        for (k, span) in [
            Span {
                start: 0.0,
                end: times[reach],
            },
            Span {
                start: times[reach],
                end: *times.last().unwrap(),
            },
        ]
        .into_iter()
        .enumerate()
        {
            let (mut pp, mut qq) = (
                vec![Vec3::ZERO; frames_per_phase * segs],
                vec![Quat::IDENTITY; frames_per_phase * segs],
            );
            clip::resample(
                &src,
                &times,
                span,
                false,
                frames_per_phase,
                &mut pp,
                &mut qq,
            )
            .unwrap();
            // The phases share the reach frame.
            let skip = if k == 0 { 0 } else { segs };
            op.extend_from_slice(&pp[skip..]);
            oq.extend_from_slice(&qq[skip..]);
            durations.push(span.end - span.start);
        }
        // The boundary frame is the recorded reach pose, bit for bit.
        let b = (frames_per_phase - 1) * segs;
        assert_eq!(&op[b..b + segs], poses[reach].positions());
        assert_eq!(&oq[b..b + segs], poses[reach].rotations());
        resampled.push((op, oq));
        recordings.push((poses, dt, reach));
    }
    // Clip-table layout: parameter fastest, then frame.
    for f in 0..count {
        for (op, oq) in &resampled {
            clip_p.extend_from_slice(&op[f * segs..(f + 1) * segs]);
            clip_q.extend_from_slice(&oq[f * segs..(f + 1) * segs]);
        }
    }
    let param = Axis::linear(0.0, 1.0, 2);
    let phase = Axis::linear(0.0, 2.0 / (count - 1) as f32, count as u32);
    let clips = Clips::new(
        Grid::new(&[param, phase], None).unwrap(),
        Grid::new(&[param], None).unwrap(),
        2,
    )
    .unwrap();
    let samples = SliceSamples::new(segs, &clip_p, &clip_q).unwrap();
    let durs = SliceDurations {
        phases: 2,
        values: &durations,
    };
    let mut out = Pose::<64>::default();
    for (c, (poses, dt, reach)) in recordings.iter().enumerate() {
        let m = clips.motion(&durs, &[c as f32]).unwrap();
        assert_eq!(m.durations(), &durations[2 * c..2 * c + 2]);
        clips
            .pose_at_time(&m, &samples, m.durations()[0], &mut out)
            .unwrap();
        assert_eq!(out.positions(), poses[*reach].positions());
        assert_eq!(out.rotations(), poses[*reach].rotations());
        // Held-out error: the 2×17-frame clip against all recorded frames.
        let (mut max_p, mut sum_p, mut n) = (0.0f64, 0.0f64, 0usize);
        for (f, actual) in poses.iter().enumerate() {
            clips
                .pose_at_time(&m, &samples, f as f32 * dt, &mut out)
                .unwrap();
            for s in 0..segs {
                let e = dist(v64(out.positions[s]), v64(actual.positions[s]));
                (max_p, sum_p, n) = (max_p.max(e), sum_p + e, n + 1);
            }
        }
        println!(
            "HDM05 {}: reach at {:.2} s of {:.2} s; 2×{frames_per_phase}-frame clip vs {} recorded frames: position error mean {:.2} mm, max {:.1} mm",
            takes[c],
            m.durations()[0],
            m.duration(),
            poses.len(),
            sum_p / n as f64 * 1e3,
            max_p * 1e3
        );
        assert!(
            sum_p / (n as f64) < 0.02 && max_p < 0.25,
            "{} {max_p}",
            sum_p / n as f64
        );
    }
    // Halfway between the takes: duration halfway, pose finite and between.
    let m = clips.motion(&durs, &[0.5]).unwrap();
    assert!((m.durations()[0] - 0.5 * (durations[0] + durations[2])).abs() < 1e-5);
    clips
        .pose_at_time(&m, &samples, 0.5 * m.duration(), &mut out)
        .unwrap();
    assert!(out.positions().iter().all(|p| p.is_finite()));
}
