//! A dense one-phase simplex method for `max cᵀx s.t. A·x ≤ b, x ≥ 0` with
//! every `bᵢ ≥ 0`, in `f64`.
//!
//! With `b ≥ 0` the slack basis (`x = 0`, every slack `= bᵢ`) is feasible,
//! so no first phase is needed. The entering column is the lowest-indexed
//! one with a positive reduced cost and the leaving row the one whose basic
//! variable has the lowest index among the ties of the ratio test (Bland's
//! rule), so degenerate pivots cannot cycle. The optimum carries the rows'
//! shadow prices: the solution of the dual `min bᵀy s.t. Aᵀy ≥ c, y ≥ 0`.

/// Reduced costs and pivots at most this small count as zero.
const EPS: f64 = 1e-9;
/// Ratios this close are ties of the ratio test.
const TIE: f64 = 1e-12;

/// Why [`maximise`] found no optimum.
#[derive(Debug, PartialEq, thiserror::Error)]
pub enum LpError {
    /// A row of `A` has the wrong length.
    #[error("row {row} of A has {len} coefficients, but c has {columns}")]
    Shape {
        /// The row.
        row: usize,
        /// Its length.
        len: usize,
        /// The length of `c`.
        columns: usize,
    },
    /// `A` and `b` differ in their number of rows.
    #[error("A has {rows} rows but b has {bounds}")]
    Rows {
        /// Rows of `A`.
        rows: usize,
        /// Entries of `b`.
        bounds: usize,
    },
    /// A bound is negative or not finite: the slack basis is not feasible.
    #[error("bound b[{row}] = {value}: the one-phase method needs every bound finite and ≥ 0")]
    Bound {
        /// The row.
        row: usize,
        /// Its bound.
        value: f64,
    },
    /// A coefficient of `A` or `c` is not finite.
    #[error("a coefficient of A or c in column {column} is not finite")]
    NotFinite {
        /// The column.
        column: usize,
    },
    /// The objective grows without limit along column `column`.
    #[error("the objective is unbounded: column {column} can grow without limit")]
    Unbounded {
        /// The entering column (`A`'s columns, then the slacks).
        column: usize,
    },
    /// More pivots than [`maximise`] allows (numerical trouble).
    #[error("no optimum after {0} pivots")]
    Pivots(usize),
}

/// An optimum of [`maximise`].
#[derive(Clone, Debug)]
pub struct Optimum {
    /// The primal solution, one value per column of `A`.
    pub x: Vec<f64>,
    /// The shadow price of each row (the dual solution).
    pub duals: Vec<f64>,
    /// `cᵀx`.
    pub value: f64,
    /// Pivots taken.
    pub pivots: usize,
}

/// The simplex tableau over `A`'s columns and then one slack per row.
struct Tableau {
    /// `B⁻¹·[A I]`, row-major.
    rows: Vec<Vec<f64>>,
    /// `B⁻¹·b`.
    rhs: Vec<f64>,
    /// The column basic in each row.
    basis: Vec<usize>,
    /// Reduced costs `c_j − c_B·B⁻¹·a_j`.
    reduced: Vec<f64>,
    /// `c_B·B⁻¹·b`.
    value: f64,
}

/// Maximises `cᵀx` subject to `a·x ≤ b` (`a` row by row) and `x ≥ 0`,
/// given `b ≥ 0`.
pub fn maximise(a: &[Vec<f64>], b: &[f64], c: &[f64]) -> Result<Optimum, LpError> {
    let mut t = Tableau::new(a, b, c)?;
    let (m, n) = (b.len(), c.len());
    let limit = 100 * (m + n + 10);
    let mut pivots = 0;
    while let Some(enter) = t.reduced.iter().position(|&d| d > EPS) {
        let leave = t
            .leaving(enter)
            .ok_or(LpError::Unbounded { column: enter })?;
        t.pivot(leave, enter);
        pivots += 1;
        if pivots > limit {
            return Err(LpError::Pivots(pivots));
        }
    }
    let mut x = vec![0.0; n];
    for (&column, &value) in t.basis.iter().zip(&t.rhs) {
        if let Some(v) = x.get_mut(column) {
            *v = value;
        }
    }
    let duals = t.reduced.get(n..).unwrap_or_default();
    Ok(Optimum {
        x,
        duals: duals.iter().map(|d| 0.0 - d).collect(),
        value: t.value,
        pivots,
    })
}

impl Tableau {
    /// The slack basis, after checking the shapes and the bounds.
    fn new(a: &[Vec<f64>], b: &[f64], c: &[f64]) -> Result<Self, LpError> {
        let (m, n) = (b.len(), c.len());
        if a.len() != m {
            return Err(LpError::Rows {
                rows: a.len(),
                bounds: m,
            });
        }
        if let Some(column) = c.iter().position(|v| !v.is_finite()) {
            return Err(LpError::NotFinite { column });
        }
        let mut rows = Vec::with_capacity(m);
        for (i, (row, &bound)) in a.iter().zip(b).enumerate() {
            if row.len() != n {
                return Err(LpError::Shape {
                    row: i,
                    len: row.len(),
                    columns: n,
                });
            }
            if let Some(column) = row.iter().position(|v| !v.is_finite()) {
                return Err(LpError::NotFinite { column });
            }
            if !(bound >= 0.0 && bound.is_finite()) {
                return Err(LpError::Bound {
                    row: i,
                    value: bound,
                });
            }
            let mut full = row.clone();
            full.extend((0..m).map(|k| if k == i { 1.0 } else { 0.0 }));
            rows.push(full);
        }
        let mut reduced = c.to_vec();
        reduced.extend(std::iter::repeat_n(0.0, m));
        Ok(Self {
            rows,
            rhs: b.to_vec(),
            basis: (n..n + m).collect(),
            reduced,
            value: 0.0,
        })
    }

    /// The ratio test for column `enter` (Bland's tie-break), or `None` if
    /// nothing limits it.
    fn leaving(&self, enter: usize) -> Option<usize> {
        let mut best: Option<(usize, f64)> = None;
        for (i, row) in self.rows.iter().enumerate() {
            let t = row[enter];
            if t <= EPS {
                continue;
            }
            let ratio = self.rhs[i] / t;
            best = match best {
                Some((l, r))
                    if ratio > r + TIE * r.abs().max(1.0)
                        || (ratio >= r - TIE * r.abs().max(1.0)
                            && self.basis[l] < self.basis[i]) =>
                {
                    Some((l, r))
                }
                _ => Some((i, ratio)),
            };
        }
        best.map(|(i, _)| i)
    }

    /// Makes column `enter` basic in row `leave`.
    fn pivot(&mut self, leave: usize, enter: usize) {
        let p = self.rows[leave][enter];
        for v in &mut self.rows[leave] {
            *v /= p;
        }
        self.rhs[leave] /= p;
        let pivot_row = self.rows[leave].clone();
        let pivot_rhs = self.rhs[leave];
        for (i, row) in self.rows.iter_mut().enumerate() {
            let k = row[enter];
            if i == leave || k == 0.0 {
                continue;
            }
            for (v, pv) in row.iter_mut().zip(&pivot_row) {
                *v -= k * pv;
            }
            row[enter] = 0.0;
            self.rhs[i] = (self.rhs[i] - k * pivot_rhs).max(0.0);
        }
        let k = self.reduced[enter];
        for (d, pv) in self.reduced.iter_mut().zip(&pivot_row) {
            *d -= k * pv;
        }
        self.reduced[enter] = 0.0;
        self.value += k * pivot_rhs;
        self.basis[leave] = enter;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-9 * b.abs().max(1.0)
    }

    /// Hillier & Lieberman's "Wyndor Glass" problem, worked by hand:
    /// max 3x + 5y s.t. x ≤ 4, 2y ≤ 12, 3x + 2y ≤ 18. The last two rows
    /// bind: y = 6, x = 2, value 36; the duals solve 3 = 3·y₃ and
    /// 5 = 2·y₂ + 2·y₃ with y₁ = 0 (x < 4): y₃ = 1, y₂ = 3/2.
    #[test]
    fn wyndor_glass() {
        let a = vec![vec![1.0, 0.0], vec![0.0, 2.0], vec![3.0, 2.0]];
        let o = maximise(&a, &[4.0, 12.0, 18.0], &[3.0, 5.0]).unwrap();
        assert!(close(o.value, 36.0), "{o:?}");
        assert!(close(o.x[0], 2.0) && close(o.x[1], 6.0), "{o:?}");
        assert!(close(o.duals[0], 0.0), "{o:?}");
        assert!(close(o.duals[1], 1.5) && close(o.duals[2], 1.0), "{o:?}");
    }

    /// Beale's example, on which the largest-coefficient rule cycles:
    /// max ¾x₁ − 20x₂ + ½x₃ − 6x₄ s.t. ¼x₁ − 8x₂ − x₃ + 9x₄ ≤ 0,
    /// ½x₁ − 12x₂ − ½x₃ + 3x₄ ≤ 0, x₃ ≤ 1. By hand: x = (1, 0, 1, 0) with
    /// rows 2 and 3 binding, value 5/4; duals y = (0, 3/2, 5/4) from
    /// ½y₂ = ¾ and −½y₂ + y₃ = ½, dual-feasible for x₂ (−12·3/2 = −18 ≥
    /// −20) and x₄ (3·3/2 ≥ −6), and bᵀy = 5/4: optimal.
    #[test]
    fn beale_does_not_cycle() {
        let a = vec![
            vec![0.25, -8.0, -1.0, 9.0],
            vec![0.5, -12.0, -0.5, 3.0],
            vec![0.0, 0.0, 1.0, 0.0],
        ];
        let o = maximise(&a, &[0.0, 0.0, 1.0], &[0.75, -20.0, 0.5, -6.0]).unwrap();
        assert!(close(o.value, 1.25), "{o:?}");
        for (x, want) in o.x.iter().zip([1.0, 0.0, 1.0, 0.0]) {
            assert!(close(*x, want), "{o:?}");
        }
        for (y, want) in o.duals.iter().zip([0.0, 1.5, 1.25]) {
            assert!(close(*y, want), "{o:?}");
        }
    }

    /// max x s.t. −x ≤ 1: nothing limits x.
    #[test]
    fn unbounded_is_an_error() {
        let err = maximise(&[vec![-1.0]], &[1.0], &[1.0]).unwrap_err();
        assert_eq!(err, LpError::Unbounded { column: 0 });
    }

    #[test]
    fn a_negative_bound_is_refused() {
        let err = maximise(&[vec![1.0]], &[-1.0], &[1.0]).unwrap_err();
        assert_eq!(
            err,
            LpError::Bound {
                row: 0,
                value: -1.0
            }
        );
    }
}
