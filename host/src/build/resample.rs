//! Resampling scattered examples onto the regular grid (Wiley & Hahn:
//! "we resample the data set to a regular grid of the parameter space").
//!
//! # Space
//!
//! Distances are measured in **cell units**: each parameter is mapped to
//! `u = (p − min)/step`, so one grid step is 1 on every axis and axes in
//! different units (metres, m/s, radians) weigh the same; cyclic axes wrap
//! (period `count` cells).
//!
//! # Methods
//!
//! Every method predicts a value at a query `x` as a linear combination
//! `Σ wᵢ(x)·vᵢ` of example values with weights that depend only on the
//! parameters, so one set of weights serves every segment and frame:
//! positions are `Σ wᵢ pᵢ`, rotations are blended in the tangent space of a
//! reference rotation `r` (the example with the largest weight):
//! `r · exp(Σ wᵢ · log(r⁻¹ qᵢ))` with each `qᵢ` on `r`'s hemisphere, which
//! is the weighted rotation mean to first order and accepts the negative
//! weights of the regression methods; scalars (clip durations) are `Σ wᵢ sᵢ`.
//!
//! - [`Method::Idw`]: Shepard's inverse-distance weighting over the `k`
//!   nearest examples, `wᵢ ∝ 1/dᵢ²`. Bounded by the data (a convex
//!   combination), flat between far-apart examples.
//! - [`Method::Rbf`]: Gaussian radial basis function interpolation,
//!   `f(x) = Σ cⱼ exp(−|x − xⱼ|²/(2σ²)) + a + bᵀx`, with ridge `λ` on the
//!   kernel matrix (consecutive mocap frames are near duplicates) and the
//!   affine term (dropped on cyclic axes) so constants and linear trends are
//!   reproduced and the weights sum to 1.
//! - [`Method::LocalLinear`]: local linear regression (LOESS): an affine fit
//!   `a + Bᵀ(xᵢ − x)` to the `k` nearest examples with tricube weights over
//!   the `k`-th distance, ridge-regularized on `B` (neighbours along one
//!   reach trajectory are nearly collinear); the prediction is `a`.
//!
//! An example that lies on a grid point (within 1e-6 cells) is taken as the
//! grid sample exactly, whatever the method, so a table built from examples
//! on the grid gives those examples back.
//!
//! # Choosing the method
//!
//! [`score`] runs cross-validation: each group of examples (one mocap clip,
//! or for a JSON set one example or one tenth of them) is held out in turn,
//! the method is fitted to the rest and predicts the held-out examples; the
//! score is the mean per-segment position error. The candidate with the
//! lowest score wins. Whole clips are held out because neighbouring frames of
//! one clip are almost identical: leaving out single frames would measure
//! nothing but the frame rate.
//!
//! # Validity
//!
//! A cell is valid when data back it: each of its `2^p` corners lies
//! within `radius` cells of some example, or its centre does (default
//! radius `√p / 2`, the half-diagonal of a cell in `p` dimensions: an example
//! inside or touching the cell's circumsphere). So a cell whose corners are
//! all examples (Wiley & Hahn's data captured on a regular grid) is always
//! valid, whatever the radius; a cell that scattered data (a few reach
//! trajectories) cross near its middle is valid too.

use glam::{DQuat, DVec3};

use super::{AxisDef, Seg};

/// A value carried by an example: poses (`frames × segments`, frame-major)
/// and scalars (clip durations).
#[derive(Debug, Clone, PartialEq)]
pub struct Value {
    /// Absolute positions and rotations, `[frame][segment]` flattened.
    pub poses: Vec<Seg>,
    /// Scalars blended with the same weights (clip phase durations).
    pub scalars: Vec<f64>,
}

/// One scattered example.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// Parameters (one per axis, axis units).
    pub params: Vec<f64>,
    /// The value.
    pub value: Value,
    /// Cross-validation group (the source clip).
    pub group: usize,
}

/// A resampling method with its hyper-parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Method {
    /// Inverse-distance weighting over the `k` nearest examples.
    Idw {
        /// Neighbours.
        k: usize,
    },
    /// Gaussian RBF interpolation with an affine term.
    Rbf {
        /// Kernel width, cells.
        sigma: f64,
        /// Ridge on the kernel matrix.
        lambda: f64,
    },
    /// Local linear regression over the `k` nearest examples.
    LocalLinear {
        /// Neighbours.
        k: usize,
    },
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Method::Idw { k } => write!(f, "idw k={k}"),
            Method::Rbf { sigma, lambda } => write!(f, "rbf sigma={sigma} lambda={lambda:e}"),
            Method::LocalLinear { k } => write!(f, "local-linear k={k}"),
        }
    }
}

impl Method {
    /// The method used when cross-validation cannot run (fewer than three
    /// groups and examples): the family's middle setting, IDW `k = 4` for
    /// `auto`.
    #[must_use]
    pub fn fallback(family: &str) -> Method {
        match family {
            "rbf" => Method::Rbf {
                sigma: 1.0,
                lambda: 1e-3,
            },
            "local-linear" => Method::LocalLinear { k: 32 },
            _ => Method::Idw { k: 4 },
        }
    }

    /// The candidates [`score`] compares for a method family name
    /// (`auto` = all families).
    #[must_use]
    pub fn candidates(family: &str) -> Vec<Method> {
        let idw = [1, 4, 16].map(|k| Method::Idw { k });
        let rbf = [0.5, 1.0, 2.0].map(|sigma| Method::Rbf {
            sigma,
            lambda: 1e-3,
        });
        let ll = [16, 32, 64].map(|k| Method::LocalLinear { k });
        match family {
            "idw" => idw.to_vec(),
            "rbf" => rbf.to_vec(),
            "local-linear" => ll.to_vec(),
            _ => idw.into_iter().chain(rbf).chain(ll).collect(),
        }
    }
}

/// The parameter space in cell units.
#[derive(Debug, Clone)]
pub struct Space {
    axes: Vec<AxisDef>,
}

impl Space {
    /// The space of these axes.
    #[must_use]
    pub fn new(axes: &[AxisDef]) -> Self {
        Self {
            axes: axes.to_vec(),
        }
    }

    /// Parameters in cell units.
    #[must_use]
    pub fn cells(&self, params: &[f64]) -> Vec<f64> {
        self.axes
            .iter()
            .zip(params)
            .map(|(a, &p)| (p - a.min) / a.step())
            .collect()
    }

    /// Parameters (axis units) of a point in cell units.
    #[must_use]
    pub fn params(&self, cells: &[f64]) -> Vec<f64> {
        self.axes
            .iter()
            .zip(cells)
            .map(|(a, &u)| a.min + u * a.step())
            .collect()
    }

    /// Per-axis difference `a − b` in cell units (wrapped on cyclic axes).
    fn diff(&self, a: &[f64], b: &[f64], out: &mut [f64]) {
        for (((o, ax), &x), &y) in out.iter_mut().zip(&self.axes).zip(a).zip(b) {
            let mut d = x - y;
            if ax.cyclic {
                let n = f64::from(ax.count);
                d -= n * (d / n).round();
            }
            *o = d;
        }
    }

    /// Squared distance in cell units.
    #[must_use]
    pub fn dist2(&self, a: &[f64], b: &[f64]) -> f64 {
        let mut d = vec![0.0; self.axes.len()];
        self.diff(a, b, &mut d);
        d.iter().map(|v| v * v).sum()
    }

    /// Number of axes.
    #[must_use]
    pub fn dims(&self) -> usize {
        self.axes.len()
    }

    /// Grid point coordinates (cell units) of every grid sample, row-major,
    /// axis 0 fastest.
    #[must_use]
    pub fn grid_points(&self) -> Vec<Vec<f64>> {
        let counts: Vec<usize> = self.axes.iter().map(|a| usize::from(a.count)).collect();
        lattice(&counts, 0.0)
    }

    /// Number of cells.
    #[must_use]
    pub fn cell_count(&self) -> usize {
        self.axes.iter().map(AxisDef::cells).product()
    }

    /// The grid-sample indices of the `2^p` corners of cell `cell` (cells
    /// row-major over the cell counts, axis 0 fastest; a cyclic axis' last
    /// cell wraps to sample 0).
    #[must_use]
    pub fn corners(&self, cell: usize) -> Vec<usize> {
        let mut k = Vec::with_capacity(self.axes.len());
        let mut rest = cell;
        for a in &self.axes {
            let n = a.cells().max(1);
            k.push(rest % n);
            rest /= n;
        }
        (0..1usize << self.axes.len())
            .map(|bits| {
                let mut index = 0;
                let mut stride = 1;
                for (i, (a, &ki)) in self.axes.iter().zip(&k).enumerate() {
                    let count = usize::from(a.count);
                    let j = (ki + (bits >> i & 1)) % count;
                    index += j * stride;
                    stride *= count;
                }
                index
            })
            .collect()
    }

    /// Cell centres, row-major over the cell counts, axis 0 fastest.
    #[must_use]
    pub fn cell_centres(&self) -> Vec<Vec<f64>> {
        let counts: Vec<usize> = self.axes.iter().map(AxisDef::cells).collect();
        lattice(&counts, 0.5)
    }
}

/// Points `offset + i` of a lattice of `counts`, row-major, axis 0 fastest.
fn lattice(counts: &[usize], offset: f64) -> Vec<Vec<f64>> {
    let total: usize = counts.iter().product();
    (0..total)
        .map(|mut i| {
            counts
                .iter()
                .map(|&n| {
                    let k = i % n.max(1);
                    i /= n.max(1);
                    k as f64 + offset
                })
                .collect()
        })
        .collect()
}

/// A method fitted to a set of example positions (cell units).
pub struct Fitted<'s> {
    space: &'s Space,
    method: Method,
    centres: Vec<Vec<f64>>,
    rbf: Option<Lu>,
    /// Axes with an affine RBF term (the bounded ones).
    linear_axes: Vec<usize>,
}

impl<'s> Fitted<'s> {
    /// Fits `method` to examples at `centres` (cell units).
    #[must_use]
    pub fn new(space: &'s Space, method: Method, centres: Vec<Vec<f64>>) -> Self {
        let linear_axes: Vec<usize> = space
            .axes
            .iter()
            .enumerate()
            .filter(|(_, a)| !a.cyclic)
            .map(|(i, _)| i)
            .collect();
        let rbf = match method {
            Method::Rbf { sigma, lambda } => {
                Some(rbf_system(space, &centres, &linear_axes, sigma, lambda))
            }
            _ => None,
        };
        Self {
            space,
            method,
            centres,
            rbf,
            linear_axes,
        }
    }

    /// Weights of the examples at query `x` (cell units), as `(index, w)`.
    #[must_use]
    pub fn weights(&self, x: &[f64]) -> Vec<(usize, f64)> {
        match self.method {
            Method::Idw { k } => self.idw(x, k),
            Method::Rbf { sigma, .. } => self.rbf_weights(x, sigma),
            Method::LocalLinear { k } => self.local_linear(x, k),
        }
    }

    /// The `k` nearest examples to `x` with their squared distances, nearest first.
    fn nearest(&self, x: &[f64], k: usize) -> Vec<(usize, f64)> {
        let mut d: Vec<(usize, f64)> = self
            .centres
            .iter()
            .enumerate()
            .map(|(i, c)| (i, self.space.dist2(x, c)))
            .collect();
        let k = k.min(d.len());
        if k < d.len() {
            d.select_nth_unstable_by(k, |a, b| a.1.total_cmp(&b.1));
            d.truncate(k);
        }
        d.sort_by(|a, b| a.1.total_cmp(&b.1));
        d
    }

    fn idw(&self, x: &[f64], k: usize) -> Vec<(usize, f64)> {
        let near = self.nearest(x, k);
        if let Some(&(i, d2)) = near.first()
            && d2 < 1e-18
        {
            return vec![(i, 1.0)];
        }
        let mut w: Vec<(usize, f64)> = near.iter().map(|&(i, d2)| (i, 1.0 / d2)).collect();
        normalize(&mut w);
        w
    }

    fn rbf_weights(&self, x: &[f64], sigma: f64) -> Vec<(usize, f64)> {
        let Some(lu) = &self.rbf else {
            return Vec::new();
        };
        let n = self.centres.len();
        let mut b = Vec::with_capacity(lu.n);
        b.extend(
            self.centres
                .iter()
                .map(|c| (-self.space.dist2(x, c) / (2.0 * sigma * sigma)).exp()),
        );
        b.push(1.0);
        b.extend(self.linear_axes.iter().map(|&a| x[a]));
        let w = lu.solve(&b);
        w.into_iter().take(n).enumerate().collect()
    }

    fn local_linear(&self, x: &[f64], k: usize) -> Vec<(usize, f64)> {
        let near = self.nearest(x, k.max(self.space.dims() + 2));
        if let Some(&(i, d2)) = near.first()
            && d2 < 1e-18
        {
            return vec![(i, 1.0)];
        }
        let h = near.last().map_or(1.0, |l| l.1.sqrt() * 1.0001).max(1e-9);
        let p = self.space.dims();
        let m = p + 1;
        // Normal equations XᵀGX β = XᵀG y with X rows [1, (xᵢ − x)ᵀ].
        let mut xtgx = vec![0.0; m * m];
        let mut rows = Vec::with_capacity(near.len());
        let mut row = vec![0.0; m];
        let mut diff = vec![0.0; p];
        let mut gsum = 0.0;
        for &(i, d2) in &near {
            let t = (d2.sqrt() / h).min(1.0);
            let g = (1.0 - t * t * t).powi(3);
            self.space.diff(&self.centres[i], x, &mut diff);
            row[0] = 1.0;
            row[1..].copy_from_slice(&diff);
            for r in 0..m {
                for c in 0..m {
                    xtgx[r * m + c] += g * row[r] * row[c];
                }
            }
            gsum += g;
            rows.push((i, g, row.clone()));
        }
        // Ridge on the slopes, relative to the total weight (cell units²).
        for r in 1..m {
            xtgx[r * m + r] += 1e-3 * gsum;
        }
        let lu = Lu::new(xtgx, m);
        // w = e₀ᵀ (XᵀGX)⁻¹ XᵀG: solve the symmetric system for e₀ once.
        let mut e0 = vec![0.0; m];
        e0[0] = 1.0;
        let a = lu.solve(&e0);
        rows.into_iter()
            .map(|(i, g, row)| (i, g * row.iter().zip(&a).map(|(r, c)| r * c).sum::<f64>()))
            .collect()
    }
}

fn normalize(w: &mut [(usize, f64)]) {
    let s: f64 = w.iter().map(|x| x.1).sum();
    if s != 0.0 {
        w.iter_mut().for_each(|x| x.1 /= s);
    }
}

/// The RBF saddle-point system `[Φ + λI, P; Pᵀ, 0]`, factored.
fn rbf_system(
    space: &Space,
    centres: &[Vec<f64>],
    linear: &[usize],
    sigma: f64,
    lambda: f64,
) -> Lu {
    let n = centres.len();
    let m = n + 1 + linear.len();
    let mut a = vec![0.0; m * m];
    for i in 0..n {
        for j in 0..=i {
            let v = (-space.dist2(&centres[i], &centres[j]) / (2.0 * sigma * sigma)).exp();
            a[i * m + j] = v;
            a[j * m + i] = v;
        }
        a[i * m + i] += lambda;
        let mut poly = vec![1.0];
        poly.extend(linear.iter().map(|&k| centres[i][k]));
        for (c, v) in poly.into_iter().enumerate() {
            a[i * m + n + c] = v;
            a[(n + c) * m + i] = v;
        }
    }
    // Tiny ridge on the polynomial block keeps a degenerate layout (all
    // examples on a line) solvable.
    for c in n..m {
        a[c * m + c] = -1e-9;
    }
    Lu::new(a, m)
}

/// Dense LU factorization with partial pivoting (row-major).
struct Lu {
    n: usize,
    a: Vec<f64>,
    perm: Vec<usize>,
}

impl Lu {
    fn new(mut a: Vec<f64>, n: usize) -> Self {
        let mut perm: Vec<usize> = (0..n).collect();
        for k in 0..n {
            let p = (k..n)
                .max_by(|&i, &j| a[i * n + k].abs().total_cmp(&a[j * n + k].abs()))
                .unwrap_or(k);
            if p != k {
                for c in 0..n {
                    a.swap(k * n + c, p * n + c);
                }
                perm.swap(k, p);
            }
            let piv = a[k * n + k];
            if piv.abs() < 1e-300 {
                continue;
            }
            for i in k + 1..n {
                let f = a[i * n + k] / piv;
                a[i * n + k] = f;
                if f != 0.0 {
                    let (top, bottom) = a.split_at_mut(i * n);
                    let src = &top[k * n + k + 1..k * n + n];
                    for (d, s) in bottom[k + 1..n].iter_mut().zip(src) {
                        *d -= f * s;
                    }
                }
            }
        }
        Self { n, a, perm }
    }

    fn solve(&self, b: &[f64]) -> Vec<f64> {
        let n = self.n;
        let mut x: Vec<f64> = self.perm.iter().map(|&p| b[p]).collect();
        for i in 0..n {
            let s: f64 = (0..i).map(|j| self.a[i * n + j] * x[j]).sum();
            x[i] -= s;
        }
        for i in (0..n).rev() {
            let s: f64 = (i + 1..n).map(|j| self.a[i * n + j] * x[j]).sum();
            let piv = self.a[i * n + i];
            x[i] = if piv.abs() < 1e-300 {
                0.0
            } else {
                (x[i] - s) / piv
            };
        }
        x
    }
}

/// Blends example values with weights (see the module doc).
#[must_use]
pub fn blend(values: &[&Value], weights: &[(usize, f64)]) -> Value {
    let Some(first) = values.first() else {
        return Value {
            poses: Vec::new(),
            scalars: Vec::new(),
        };
    };
    let reference = weights
        .iter()
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map_or(0, |w| w.0);
    let r = values[reference];
    let mut poses = Vec::with_capacity(first.poses.len());
    for (s, &(_, rq)) in r.poses.iter().enumerate() {
        let mut p = DVec3::ZERO;
        let mut v = DVec3::ZERO;
        let inv = rq.conjugate();
        for &(i, w) in weights {
            let (pi, qi) = values[i].poses[s];
            p += w * pi;
            let mut d = inv * qi;
            if d.w < 0.0 {
                d = -d;
            }
            v += w * d.to_scaled_axis();
        }
        poses.push((p, (rq * DQuat::from_scaled_axis(v)).normalize()));
    }
    let scalars = (0..r.scalars.len())
        .map(|k| weights.iter().map(|&(i, w)| w * values[i].scalars[k]).sum())
        .collect();
    Value { poses, scalars }
}

/// The angle of the rotation between `a` and `b`, radians:
/// `2·atan2(|v|, |w|)` of `conj(a)·b` (accurate for small angles, unlike
/// `acos` of the dot product, and indifferent to the quaternions' signs).
#[must_use]
pub fn rotation_angle(a: DQuat, b: DQuat) -> f64 {
    let r = a.conjugate() * b;
    2.0 * r.xyz().length().atan2(r.w.abs())
}

/// Per-example errors of a prediction.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Errors {
    /// Mean over segments (and frames) of the position error, metres.
    pub mean_position: f64,
    /// Position error of the probe segment (the hand), metres.
    pub probe: Option<f64>,
    /// Mean rotation error over segments (and frames), radians.
    pub mean_rotation: f64,
}

/// Compares a prediction with the truth; `probe` is an index into `poses`
/// and a point in that segment's frame.
#[must_use]
pub fn compare(pred: &Value, truth: &Value, probe: Option<(usize, DVec3)>) -> Errors {
    let n = truth.poses.len().max(1) as f64;
    let mut e = Errors::default();
    for ((pp, pq), (tp, tq)) in pred.poses.iter().zip(&truth.poses) {
        e.mean_position += (*pp - *tp).length() / n;
        e.mean_rotation += rotation_angle(*pq, *tq) / n;
    }
    let at = |s: &Seg, point: DVec3| s.0 + s.1 * point;
    e.probe = probe.and_then(|(i, point)| {
        Some((at(pred.poses.get(i)?, point) - at(truth.poses.get(i)?, point)).length())
    });
    e
}

/// A cross-validation score.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Score {
    /// The method.
    pub method: Method,
    /// Mean over held-out examples of the mean per-segment position error, m.
    pub mean_position: f64,
    /// Median over held-out examples of the probe-segment error, m.
    pub median_probe: Option<f64>,
    /// Mean rotation error, radians.
    pub mean_rotation: f64,
}

/// Cross-validation folds: one per group if there are at least 3 groups,
/// else (one group) ten interleaved blocks of examples.
#[must_use]
pub fn folds(records: &[Record]) -> Vec<Vec<usize>> {
    let mut groups: Vec<usize> = records.iter().map(|r| r.group).collect();
    groups.sort_unstable();
    groups.dedup();
    if groups.len() >= 3 {
        return groups
            .iter()
            .map(|g| {
                (0..records.len())
                    .filter(|&i| records[i].group == *g)
                    .collect()
            })
            .collect();
    }
    let k = records.len().min(10);
    if k < 3 {
        return Vec::new();
    }
    // Contiguous blocks: neighbouring examples of one clip are not split
    // between training and test more than necessary.
    (0..k)
        .map(|f| {
            let lo = f * records.len() / k;
            let hi = (f + 1) * records.len() / k;
            (lo..hi).collect()
        })
        .collect()
}

/// Scores `method` by cross-validation over `folds`; `post` post-processes
/// each prediction (limb lengths), `probe` picks the hand.
pub fn score(
    space: &Space,
    records: &[Record],
    folds: &[Vec<usize>],
    method: Method,
    probe: Option<(usize, DVec3)>,
    post: &dyn Fn(&[f64], &mut Value),
) -> Score {
    let mut pos = Vec::new();
    let mut rot = Vec::new();
    let mut probes = Vec::new();
    for fold in folds {
        let train: Vec<usize> = (0..records.len()).filter(|i| !fold.contains(i)).collect();
        if train.is_empty() {
            continue;
        }
        let centres = train
            .iter()
            .map(|&i| space.cells(&records[i].params))
            .collect();
        let fitted = Fitted::new(space, method, centres);
        let values: Vec<&Value> = train.iter().map(|&i| &records[i].value).collect();
        for &t in fold {
            let w = fitted.weights(&space.cells(&records[t].params));
            let mut pred = blend(&values, &w);
            post(&records[t].params, &mut pred);
            let e = compare(&pred, &records[t].value, probe);
            pos.push(e.mean_position);
            rot.push(e.mean_rotation);
            if let Some(p) = e.probe {
                probes.push(p);
            }
        }
    }
    Score {
        method,
        mean_position: mean(&pos),
        median_probe: median(&mut probes),
        mean_rotation: mean(&rot),
    }
}

/// The mean (NaN for none).
#[must_use]
pub fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

/// The median (`None` for none).
#[must_use]
pub fn median(v: &mut [f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    })
}

/// The validity of every cell (see the module doc): its centre, or each
/// of its corners, within `radius` cells of an example (distances compared
/// with a relative tolerance of 1e-9, so a distance equal to the radius in
/// exact arithmetic counts as within it).
#[must_use]
pub fn valid_cells(space: &Space, centres: &[Vec<f64>], radius: f64) -> Vec<bool> {
    let r2 = radius * radius * (1.0 + 1e-9);
    let near = |x: &Vec<f64>| centres.iter().any(|e| space.dist2(x, e) <= r2);
    let corner_near: Vec<bool> = space.grid_points().iter().map(near).collect();
    space
        .cell_centres()
        .iter()
        .enumerate()
        .map(|(c, centre)| {
            let corners = space.corners(c);
            corners.iter().all(|&i| corner_near[i]) || near(centre)
        })
        .collect()
}

/// Resampled grid: one value per grid sample, and the cell mask.
#[derive(Debug, Clone)]
pub struct Resampled {
    /// Values at the grid samples, row-major, axis 0 fastest.
    pub values: Vec<Value>,
    /// One flag per cell.
    pub valid: Vec<bool>,
    /// Grid samples taken exactly from an example on the grid point.
    pub exact: usize,
}

/// Resamples `records` onto the grid of `space` with `method`; `tick` is
/// called once per grid sample (progress).
pub fn grid(
    space: &Space,
    records: &[Record],
    method: Method,
    radius: f64,
    post: &dyn Fn(&[f64], &mut Value),
    tick: &dyn Fn(),
) -> Resampled {
    let centres: Vec<Vec<f64>> = records.iter().map(|r| space.cells(&r.params)).collect();
    let fitted = Fitted::new(space, method, centres.clone());
    let values: Vec<&Value> = records.iter().map(|r| &r.value).collect();
    let mut exact = 0;
    let out = space
        .grid_points()
        .iter()
        .map(|g| {
            let hits: Vec<(usize, f64)> = centres
                .iter()
                .enumerate()
                .filter(|(_, c)| space.dist2(g, c) < 1e-12)
                .map(|(i, _)| (i, 1.0))
                .collect();
            let v = if hits.is_empty() {
                let mut v = blend(&values, &fitted.weights(g));
                post(&space.params(g), &mut v);
                v
            } else {
                exact += 1;
                let mut w = hits;
                normalize(&mut w);
                blend(&values, &w)
            };
            tick();
            v
        })
        .collect();
    let valid = valid_cells(space, &centres, radius);
    Resampled {
        values: out,
        valid,
        exact,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn axis(count: u16) -> AxisDef {
        AxisDef {
            name: "x".into(),
            min: 0.0,
            max: f64::from(count - 1),
            count,
            cyclic: false,
            cubic: false,
        }
    }

    fn scalar(v: f64) -> Value {
        Value {
            poses: vec![(DVec3::new(v, 0.0, 0.0), DQuat::IDENTITY)],
            scalars: vec![v],
        }
    }

    #[test]
    fn every_method_reproduces_a_linear_function_inside_the_data() {
        // f(x, y) = 2x − y + 3 on a jittered 2-D point set.
        let space = Space::new(&[axis(6), axis(6)]);
        let mut centres = Vec::new();
        let mut vals = Vec::new();
        for i in 0..6 {
            for j in 0..6 {
                let (x, y) = (
                    i as f64 + 0.13 * ((i * 7 + j) % 5) as f64,
                    j as f64 + 0.07 * ((i + 3 * j) % 4) as f64,
                );
                centres.push(vec![x, y]);
                vals.push(scalar(2.0 * x - y + 3.0));
            }
        }
        let refs: Vec<&Value> = vals.iter().collect();
        // RBF with its affine term is exact; local linear is exact but for
        // the small ridge on its slopes (1e-3 of the weight: 0.5 % here).
        for (m, tol) in [
            (
                Method::Rbf {
                    sigma: 1.0,
                    lambda: 1e-9,
                },
                1e-6,
            ),
            (Method::LocalLinear { k: 12 }, 0.02),
        ] {
            let f = Fitted::new(&space, m, centres.clone());
            let q = [2.4, 3.3];
            let v = blend(&refs, &f.weights(&q));
            let truth = 2.0 * q[0] - q[1] + 3.0;
            assert!(
                (v.scalars[0] - truth).abs() < tol,
                "{m}: {} vs {truth}",
                v.scalars[0]
            );
            assert!((v.poses[0].0.x - truth).abs() < tol, "{m}");
        }
        // IDW is a convex combination: within the data's range, exact at data.
        let f = Fitted::new(&space, Method::Idw { k: 4 }, centres.clone());
        let v = blend(&refs, &f.weights(&centres[7]));
        assert_eq!(v.scalars[0], vals[7].scalars[0]);
    }

    #[test]
    fn rotations_blend_on_the_short_arc() {
        // Two rotations about Y by ±0.4 rad (one stored with negative w):
        // the equal blend is the identity.
        let a = DQuat::from_rotation_y(0.4);
        let b = -DQuat::from_rotation_y(-0.4);
        let va = Value {
            poses: vec![(DVec3::ZERO, a)],
            scalars: vec![],
        };
        let vb = Value {
            poses: vec![(DVec3::ZERO, b)],
            scalars: vec![],
        };
        let v = blend(&[&va, &vb], &[(0, 0.5), (1, 0.5)]);
        assert!(v.poses[0].1.angle_between(DQuat::IDENTITY) < 1e-12);
    }

    #[test]
    fn cyclic_distance_wraps() {
        let mut a = axis(8);
        a.cyclic = true;
        a.max = 8.0;
        let s = Space::new(&[a]);
        assert!((s.dist2(&[0.5], &[7.5]) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn validity_marks_cells_near_examples() {
        let space = Space::new(&[axis(4)]);
        let records = vec![Record {
            params: vec![0.2],
            value: scalar(0.0),
            group: 0,
        }];
        let r = grid(
            &space,
            &records,
            Method::Idw { k: 1 },
            0.5,
            &|_, _| {},
            &|| {},
        );
        assert_eq!(r.valid, [true, false, false]);
        assert_eq!(r.values.len(), 4);
        // Examples on both corners of the last cell validate it even with a
        // radius far below the centre's distance of 0.5.
        let on = |x: f64| Record {
            params: vec![x],
            value: scalar(x),
            group: 0,
        };
        let r = grid(
            &space,
            &[on(2.0), on(3.0)],
            Method::Idw { k: 1 },
            0.1,
            &|_, _| {},
            &|| {},
        );
        assert_eq!(r.valid, [false, false, true]);
        assert_eq!(r.exact, 2);
        // Corners of a 2-D cell, one cyclic axis wrapping to sample 0.
        let mut cyc = axis(3);
        cyc.cyclic = true;
        let s2 = Space::new(&[axis(3), cyc]);
        assert_eq!(s2.cell_count(), 6);
        assert_eq!(s2.corners(5), [7, 8, 1, 2]);
    }
}
