//! Slow, obviously correct `f64` references for the solver tests, independent of
//! the core's code: their own rotation matrices, forward kinematics, goal
//! errors, and a projected-gradient optimiser with numerical gradients.
//!
//! Only the body *tables* (offsets, parents, DOF axes and limits, touch points)
//! are read from the core; they are data, not code.

use marionette_core::body::{Angles, Axis, Body};

/// A 3-vector.
pub type V = [f64; 3];
/// A 3×3 matrix, row major.
pub type M = [[f64; 3]; 3];

pub fn add(a: V, b: V) -> V {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
pub fn sub(a: V, b: V) -> V {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
pub fn scale(a: V, s: f64) -> V {
    [a[0] * s, a[1] * s, a[2] * s]
}
pub fn dot(a: V, b: V) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
pub fn norm(a: V) -> f64 {
    dot(a, a).sqrt()
}
pub fn dist(a: V, b: V) -> f64 {
    norm(sub(a, b))
}
pub fn mv(m: &M, v: V) -> V {
    [dot(m[0], v), dot(m[1], v), dot(m[2], v)]
}
pub fn mm(a: &M, b: &M) -> M {
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    r
}
pub fn transpose(a: &M) -> M {
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = a[j][i];
        }
    }
    r
}
pub const I: M = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// The textbook elementary rotation matrices.
pub fn rot(axis: Axis, t: f64) -> M {
    let (s, c) = t.sin_cos();
    match axis {
        Axis::X => [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]],
        Axis::Y => [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]],
        Axis::Z => [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
    }
}

/// Rotation angle of a rotation matrix, from its trace.
pub fn angle_of(m: &M) -> f64 {
    ((m[0][0] + m[1][1] + m[2][2] - 1.0) / 2.0)
        .clamp(-1.0, 1.0)
        .acos()
}

/// Matrix of a unit quaternion given as (x, y, z, w).
pub fn quat_matrix(x: f64, y: f64, z: f64, w: f64) -> M {
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - z * w),
            2.0 * (x * z + y * w),
        ],
        [
            2.0 * (x * y + z * w),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - x * w),
        ],
        [
            2.0 * (x * z - y * w),
            2.0 * (y * z + x * w),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// One DOF of the reference body.
#[derive(Clone, Copy, Debug)]
pub struct RefDof {
    pub axis: Axis,
    pub min: f64,
    pub max: f64,
}

/// The body table in `f64`.
#[derive(Clone, Debug)]
pub struct RefBody {
    pub parents: Vec<Option<usize>>,
    pub offsets: Vec<V>,
    pub dofs: Vec<Vec<RefDof>>,
    pub touch: Vec<V>,
}

fn v3(v: glam::Vec3) -> V {
    [f64::from(v.x), f64::from(v.y), f64::from(v.z)]
}

impl RefBody {
    pub fn of(body: &Body<'_>) -> Self {
        let s = body.segments;
        RefBody {
            parents: s
                .iter()
                .map(|g| (g.parent != u8::MAX).then_some(usize::from(g.parent)))
                .collect(),
            offsets: s.iter().map(|g| v3(g.origin)).collect(),
            dofs: s
                .iter()
                .map(|g| {
                    g.joint
                        .dofs()
                        .iter()
                        .map(|d| RefDof {
                            axis: d.axis,
                            min: f64::from(d.min),
                            max: f64::from(d.max),
                        })
                        .collect()
                })
                .collect(),
            touch: s.iter().map(|g| v3(g.touch)).collect(),
        }
    }

    pub fn len(&self) -> usize {
        self.parents.len()
    }
}

/// A joint state in `f64`.
#[derive(Clone, Debug, PartialEq)]
pub struct RefState {
    pub root: V,
    pub root_rot: M,
    pub angles: Vec<[f64; 3]>,
}

impl RefState {
    pub fn of<const N: usize>(a: &Angles<N>) -> Self {
        let q = a.root_rotation;
        RefState {
            root: v3(a.root_position),
            root_rot: quat_matrix(q.x.into(), q.y.into(), q.z.into(), q.w.into()),
            angles: a
                .values
                .iter()
                .take(a.count)
                .map(|v| v.map(f64::from))
                .collect(),
        }
    }
}

/// World positions and rotations.
pub struct RefPose {
    pub p: Vec<V>,
    pub r: Vec<M>,
}

/// Forward kinematics: `p_i = p_parent + R_parent·offset_i`, `R_i = R_parent·L_i`,
/// `L_i = R_a(θ0)·R_b(θ1)·R_c(θ2)`.
pub fn fk(body: &RefBody, s: &RefState) -> RefPose {
    let n = body.len();
    let mut p = vec![[0.0; 3]; n];
    let mut r = vec![I; n];
    for i in 0..n {
        let mut local = I;
        for (k, d) in body.dofs[i].iter().enumerate() {
            local = mm(&local, &rot(d.axis, s.angles[i][k]));
        }
        match body.parents[i] {
            None => {
                p[i] = s.root;
                r[i] = s.root_rot;
            }
            Some(q) => {
                p[i] = add(p[q], mv(&r[q], body.offsets[i]));
                r[i] = mm(&r[q], &local);
            }
        }
    }
    RefPose { p, r }
}

/// A point of a segment, in world coordinates.
pub fn world(pose: &RefPose, seg: usize, local: V) -> V {
    add(pose.p[seg], mv(&pose.r[seg], local))
}

/// A reference goal target.
#[derive(Clone, Debug)]
pub enum RefTarget {
    /// World point.
    Point(V),
    /// A point in another segment's frame.
    PointIn(usize, V),
    /// World plane `n·x = d` (n unit); `above`: only below counts.
    Plane { n: V, d: f64, above: bool },
    /// World orientation.
    Orient(M),
}

/// A reference goal.
#[derive(Clone, Debug)]
pub struct RefGoal {
    pub seg: usize,
    /// Attached point in the segment frame.
    pub local: V,
    pub target: RefTarget,
    pub weight: f64,
}

/// A goal's residual (m or rad) at a pose.
pub fn residual(pose: &RefPose, g: &RefGoal) -> f64 {
    let x = world(pose, g.seg, g.local);
    match &g.target {
        RefTarget::Point(t) => dist(x, *t),
        RefTarget::PointIn(f, t) => dist(x, world(pose, *f, *t)),
        RefTarget::Plane { n, d, above } => {
            let s = dot(*n, x) - d;
            if *above { (-s).max(0.0) } else { s.abs() }
        }
        RefTarget::Orient(m) => angle_of(&mm(m, &transpose(&pose.r[g.seg]))),
    }
}

/// `Σ w·residual²`.
pub fn energy(body: &RefBody, s: &RefState, goals: &[RefGoal]) -> f64 {
    let pose = fk(body, s);
    goals
        .iter()
        .map(|g| g.weight * residual(&pose, g).powi(2))
        .sum()
}

/// A free variable of the reference optimiser.
#[derive(Clone, Copy, Debug)]
pub enum Var {
    /// Angle `k` of segment `seg`, with limits.
    Dof {
        seg: usize,
        k: usize,
        min: f64,
        max: f64,
    },
    /// Root translation along axis `k`.
    Translation(usize),
}

impl Var {
    fn clamp(&self, x: f64) -> f64 {
        match *self {
            Var::Dof { min, max, .. } => x.clamp(min, max),
            Var::Translation(_) => x,
        }
    }
    /// The variable's value in `s`.
    pub fn get(&self, s: &RefState) -> f64 {
        match *self {
            Var::Dof { seg, k, .. } => s.angles[seg][k],
            Var::Translation(k) => s.root[k],
        }
    }
    /// Sets the variable's value in `s`.
    pub fn set(&self, s: &mut RefState, x: f64) {
        match *self {
            Var::Dof { seg, k, .. } => s.angles[seg][k] = x,
            Var::Translation(k) => s.root[k] = x,
        }
    }
}

/// The variables that may move: every DOF of the segments on the paths from
/// `anchor` (exclusive) to the goal segments, plus the root translation if asked.
pub fn variables(
    body: &RefBody,
    anchor: usize,
    goal_segments: &[usize],
    translation: bool,
) -> Vec<Var> {
    let mut on_path = vec![false; body.len()];
    for &g in goal_segments {
        let mut s = Some(g);
        // Walk up to the anchor; a goal outside the anchor's subtree adds nothing.
        let mut path = vec![];
        let mut reached = false;
        while let Some(x) = s {
            if x == anchor {
                reached = true;
                break;
            }
            path.push(x);
            s = body.parents[x];
        }
        if reached {
            for x in path {
                on_path[x] = true;
            }
        }
    }
    let mut vars: Vec<Var> = if translation {
        (0..3).map(Var::Translation).collect()
    } else {
        vec![]
    };
    for (seg, &on) in on_path.iter().enumerate() {
        if on && body.parents[seg].is_some() {
            for (k, d) in body.dofs[seg].iter().enumerate() {
                vars.push(Var::Dof {
                    seg,
                    k,
                    min: d.min,
                    max: d.max,
                });
            }
        }
    }
    vars
}

/// Minimises [`energy`] over `vars` from `start` by spectral projected gradient
/// (Barzilai–Borwein steps, projection onto the limits, Armijo backtracking),
/// with forward-difference gradients. Returns the final state and energy.
pub fn minimize(
    body: &RefBody,
    goals: &[RefGoal],
    vars: &[Var],
    start: &RefState,
    iterations: usize,
) -> (RefState, f64) {
    let mut s = start.clone();
    for v in vars {
        let x = v.clamp(v.get(&s));
        v.set(&mut s, x);
    }
    let f = |s: &RefState| energy(body, s, goals);
    // Forward differences (one evaluation per variable): at h = 1e-7 in f64
    // the error is far below what the 2% comparison can see.
    let grad = |s: &RefState, fs: f64| -> Vec<f64> {
        let mut t = s.clone();
        vars.iter()
            .map(|v| {
                let x = v.get(s);
                let h = 1e-7;
                v.set(&mut t, x + h);
                let fp = f(&t);
                v.set(&mut t, x);
                (fp - fs) / h
            })
            .collect()
    };
    let mut e = f(&s);
    let mut g = grad(&s, e);
    let mut alpha = 1.0;
    for _ in 0..iterations {
        // Projected direction d = P(x − α g) − x.
        let d: Vec<f64> = vars
            .iter()
            .zip(&g)
            .map(|(v, gi)| v.clamp(v.get(&s) - alpha * gi) - v.get(&s))
            .collect();
        let dmax = d.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        if dmax < 1e-13 {
            break;
        }
        let gd: f64 = g.iter().zip(&d).map(|(a, b)| a * b).sum();
        let mut lambda = 1.0;
        let mut next = s.clone();
        let mut e_next;
        loop {
            for (v, di) in vars.iter().zip(&d) {
                v.set(&mut next, v.get(&s) + lambda * di);
            }
            e_next = f(&next);
            if e_next <= e + 1e-4 * lambda * gd || lambda < 1e-12 {
                break;
            }
            lambda *= 0.5;
        }
        if e_next > e {
            break;
        }
        let g_next = grad(&next, e_next);
        let sv: Vec<f64> = vars.iter().map(|v| v.get(&next) - v.get(&s)).collect();
        let yv: Vec<f64> = g_next.iter().zip(&g).map(|(a, b)| a - b).collect();
        let sy: f64 = sv.iter().zip(&yv).map(|(a, b)| a * b).sum();
        let ss: f64 = sv.iter().map(|a| a * a).sum();
        alpha = if sy > 1e-300 {
            (ss / sy).clamp(1e-8, 1e4)
        } else {
            1e4
        };
        s = next;
        e = e_next;
        g = g_next;
    }
    (s, e)
}
