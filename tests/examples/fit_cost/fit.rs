//! The cost model's fit: the coefficients `c ≥ 0` that minimise the total
//! relative excess `Σᵢ (c·uᵢ)/mᵢ` subject to `c·uᵢ ≥ mᵢ` for every solve
//! `i` (`mᵢ` its measured instructions, `uᵢ` its units of each term), then
//! rounded up to integers that still bound every solve.
//!
//! The linear program is solved through its dual, `max Σᵢ yᵢ s.t.
//! Σᵢ (uᵢⱼ/mᵢ)·yᵢ ≤ fⱼ, y ≥ 0` with `fⱼ = Σᵢ uᵢⱼ/mᵢ ≥ 0`: the slack basis is
//! feasible there, so [`simplex::maximise`] needs no first phase, and the
//! coefficients are the dual's shadow prices. Each term's row is scaled by
//! its largest `uᵢⱼ/mᵢ` first, so that every coefficient of the program is
//! at most 1.

use super::simplex::{self, LpError};

/// The primal's constraints and objective must hold to this relative
/// tolerance for the optimum to be accepted.
const CERTIFY: f64 = 1e-7;

/// One solve: what it cost and what the model counted.
#[derive(Clone, Debug)]
pub struct Solve {
    /// The firmware's id of the solve.
    pub id: u32,
    /// Its instructions on the emulated board (`mᵢ`, > 0).
    pub instructions: f64,
    /// Its units of each term (`uᵢ`).
    pub units: Vec<u32>,
}

/// Why a fit failed.
#[derive(Debug, thiserror::Error)]
pub enum FitError {
    /// No solves to fit.
    #[error("no solves to fit")]
    Empty,
    /// A solve's units do not have one entry per term.
    #[error("solve {id}: {got} units, but the model has {want} terms")]
    Terms {
        /// The solve.
        id: u32,
        /// Its units.
        got: usize,
        /// The terms.
        want: usize,
    },
    /// A solve measured no instructions.
    #[error("solve {id}: {instructions} instructions; every solve must have some")]
    Instructions {
        /// The solve.
        id: u32,
        /// Its instructions.
        instructions: f64,
    },
    /// The linear program failed.
    #[error("the linear program: {0}")]
    Lp(#[from] LpError),
    /// The optimum failed its certificate (numerical trouble).
    #[error("the optimum is not certified: {0}")]
    Certificate(String),
}

/// A fitted model.
#[derive(Clone, Debug)]
pub struct Fit {
    /// The linear program's coefficients (0 for unused terms).
    pub exact: Vec<f64>,
    /// The terms no solve has a unit of: the fit says nothing about them.
    pub unused: Vec<usize>,
    /// `fⱼ = Σᵢ uᵢⱼ/mᵢ`: what a unit of coefficient `j` adds to the
    /// objective.
    pub weight: Vec<f64>,
    /// The optimum's mean of `(c·uᵢ)/mᵢ` over the solves.
    pub mean_ratio: f64,
    /// The simplex's pivots.
    pub pivots: usize,
}

/// Fits `terms` coefficients to `solves` by the linear program.
pub fn fit(solves: &[Solve], terms: usize) -> Result<Fit, FitError> {
    if solves.is_empty() {
        return Err(FitError::Empty);
    }
    for s in solves {
        if s.units.len() != terms {
            return Err(FitError::Terms {
                id: s.id,
                got: s.units.len(),
                want: terms,
            });
        }
        if !(s.instructions > 0.0 && s.instructions.is_finite()) {
            return Err(FitError::Instructions {
                id: s.id,
                instructions: s.instructions,
            });
        }
    }
    let per = |s: &Solve, j: usize| f64::from(s.units[j]) / s.instructions;
    let weight: Vec<f64> = (0..terms)
        .map(|j| solves.iter().map(|s| per(s, j)).sum())
        .collect();
    let (used, unused): (Vec<usize>, Vec<usize>) = (0..terms).partition(|&j| weight[j] > 0.0);
    let scale: Vec<f64> = used
        .iter()
        .map(|&j| solves.iter().map(|s| per(s, j)).fold(0.0, f64::max))
        .collect();
    let a: Vec<Vec<f64>> = used
        .iter()
        .zip(&scale)
        .map(|(&j, &k)| solves.iter().map(|s| per(s, j) / k).collect())
        .collect();
    let b: Vec<f64> = used
        .iter()
        .zip(&scale)
        .map(|(&j, k)| weight[j] / k)
        .collect();
    let optimum = simplex::maximise(&a, &b, &vec![1.0; solves.len()])?;
    let mut exact = vec![0.0; terms];
    for ((&j, k), y) in used.iter().zip(&scale).zip(&optimum.duals) {
        exact[j] = y / k;
    }
    let n = solves.len() as f64;
    let fit = Fit {
        mean_ratio: optimum.value / n,
        exact,
        unused,
        weight,
        pivots: optimum.pivots,
    };
    certify(&fit, solves, &optimum.x)?;
    Ok(fit)
}

/// Checks the optimum without trusting the simplex: the coefficients are
/// ≥ 0 and bound every solve (primal feasible), the dual solution `y` is ≥ 0
/// with `Σᵢ (uᵢⱼ/mᵢ)·yᵢ ≤ fⱼ` (dual feasible), and the two objectives are
/// equal, which by weak duality makes both optimal.
fn certify(fit: &Fit, solves: &[Solve], y: &[f64]) -> Result<(), FitError> {
    if let Some(j) = fit.exact.iter().position(|&c| c < 0.0) {
        return Err(FitError::Certificate(format!(
            "coefficient {j} is {}",
            fit.exact[j]
        )));
    }
    if let Some(i) = y.iter().position(|&v| v < 0.0) {
        return Err(FitError::Certificate(format!("dual {i} is {}", y[i])));
    }
    for (j, &f) in fit.weight.iter().enumerate() {
        let lhs: f64 = solves
            .iter()
            .zip(y)
            .map(|(s, v)| f64::from(s.units[j]) / s.instructions * v)
            .sum();
        if lhs > f + CERTIFY * f.max(1e-12) {
            return Err(FitError::Certificate(format!(
                "dual constraint {j}: {lhs} > {f}"
            )));
        }
    }
    let dual: f64 = y.iter().sum();
    for s in solves {
        let r = counted(&fit.exact, &s.units) / s.instructions;
        if r < 1.0 - CERTIFY {
            return Err(FitError::Certificate(format!(
                "solve {} is counted {r} of its instructions",
                s.id
            )));
        }
    }
    let primal: f64 = fit.exact.iter().zip(&fit.weight).map(|(c, f)| c * f).sum();
    if (primal - dual).abs() > CERTIFY * dual.abs().max(1.0) {
        return Err(FitError::Certificate(format!(
            "primal objective {primal}, dual {dual}"
        )));
    }
    Ok(())
}

/// `c·u`.
pub fn counted(cost: &[f64], units: &[u32]) -> f64 {
    cost.iter().zip(units).map(|(c, &u)| c * f64::from(u)).sum()
}

/// `c·u` in integers.
pub fn counted_int(cost: &[u64], units: &[u32]) -> u64 {
    cost.iter()
        .zip(units)
        .map(|(c, &u)| c.saturating_mul(u64::from(u)))
        .fold(0, u64::saturating_add)
}

/// The coefficients rounded up (a coefficient within 10⁻⁶ above an integer
/// rounds down to it: [`bound`] raises it again if a solve needs it).
pub fn round_up(exact: &[f64]) -> Vec<u64> {
    exact
        .iter()
        .map(|&c| (c - 1e-6).max(0.0).ceil() as u64)
        .collect()
}

/// A coefficient raised so that a solve is bounded.
#[derive(Clone, Debug, PartialEq)]
pub struct Bump {
    /// The solve that was not bounded.
    pub id: u32,
    /// The term raised.
    pub term: usize,
    /// By how much.
    pub by: u64,
}

/// Raises `cost` until `c·uᵢ ≥ mᵢ` for every solve: for each solve short of
/// it, the term whose raise adds the least to the objective (`fⱼ/uᵢⱼ` per
/// instruction) goes up by just enough; repeated until none is short.
pub fn bound(cost: &mut [u64], solves: &[Solve], weight: &[f64]) -> Vec<Bump> {
    let mut bumps = vec![];
    loop {
        let before = bumps.len();
        for s in solves {
            let short = s.instructions - counted_int(cost, &s.units) as f64;
            if short <= 0.0 {
                continue;
            }
            let cheapest = (0..cost.len())
                .filter(|&j| s.units[j] > 0)
                .min_by(|&j, &k| {
                    let per = |t: usize| weight[t] / f64::from(s.units[t]);
                    per(j).total_cmp(&per(k))
                });
            if let Some(term) = cheapest {
                let by = (short / f64::from(s.units[term])).ceil() as u64;
                cost[term] += by;
                bumps.push(Bump { id: s.id, term, by });
            }
        }
        if bumps.len() == before {
            return bumps;
        }
    }
}

/// The ratios `(c·uᵢ)/mᵢ` of `cost` over the solves: least, median
/// (the upper one of an even count) and greatest.
pub fn ratios(cost: &[u64], solves: &[Solve]) -> Option<[f64; 3]> {
    let mut r: Vec<f64> = solves
        .iter()
        .map(|s| counted_int(cost, &s.units) as f64 / s.instructions)
        .collect();
    r.sort_by(f64::total_cmp);
    Some([*r.first()?, r[r.len() / 2], *r.last()?])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn solves(cases: &[(u32, f64, [u32; 2])]) -> Vec<Solve> {
        cases
            .iter()
            .map(|&(id, instructions, u)| Solve {
                id,
                instructions,
                units: u.to_vec(),
            })
            .collect()
    }

    /// Three solves of two terms, worked by hand: units (1, 0), (1, 1),
    /// (1, 2) and instructions 10, 20, 26. The constraints c₀ ≥ 10,
    /// c₀ + c₁ ≥ 20, c₀ + 2c₁ ≥ 26 have the vertices (10, 10), (14, 6) and
    /// (26, 0); the objective is f·c with f₀ = 1/10 + 1/20 + 1/26 =
    /// 49/260 and f₁ = 1/20 + 2/26 = 33/260, which is 820/260, 884/260
    /// and 1274/260 there: (10, 10) is the optimum, mean ratio 41/39.
    fn three() -> Vec<Solve> {
        solves(&[(0, 10.0, [1, 0]), (1, 20.0, [1, 1]), (2, 26.0, [1, 2])])
    }

    #[test]
    fn a_hand_worked_fit() {
        let f = fit(&three(), 2).unwrap();
        assert!((f.exact[0] - 10.0).abs() < 1e-9, "{f:?}");
        assert!((f.exact[1] - 10.0).abs() < 1e-9, "{f:?}");
        assert!((f.weight[0] - 49.0 / 260.0).abs() < 1e-12, "{f:?}");
        assert!((f.mean_ratio - 41.0 / 39.0).abs() < 1e-9, "{f:?}");
        assert!(f.unused.is_empty());
        let cost = round_up(&f.exact);
        assert_eq!(cost, [10, 10]);
        assert_eq!(ratios(&cost, &three()), Some([1.0, 1.0, 30.0 / 26.0]));
    }

    /// One term, 3 units per solve, 10 instructions: c = 10/3, rounded up
    /// to 4 (12 counted).
    #[test]
    fn a_fraction_rounds_up() {
        let s = vec![Solve {
            id: 7,
            instructions: 10.0,
            units: vec![3],
        }];
        let f = fit(&s, 1).unwrap();
        assert!((f.exact[0] - 10.0 / 3.0).abs() < 1e-9, "{f:?}");
        assert_eq!(round_up(&f.exact), [4]);
    }

    /// A term no solve uses is reported and left at 0.
    #[test]
    fn an_unused_term_is_reported() {
        let s = vec![Solve {
            id: 0,
            instructions: 5.0,
            units: vec![1, 0],
        }];
        let f = fit(&s, 2).unwrap();
        assert_eq!(f.unused, [1]);
        assert_eq!(round_up(&f.exact), [5, 0]);
    }

    /// From (5, 5) on the three solves: solve 0 is 5 short, only term 0
    /// has units, so c₀ = 10; then solve 1 (15 of 20) is 5 short and term 1
    /// is the cheaper raise (f₁ = 33/260 < f₀ = 49/260), so c₁ = 10; solve
    /// 2 then counts 30 ≥ 26.
    #[test]
    fn bound_raises_the_cheapest_term() {
        let s = three();
        let weight = [49.0 / 260.0, 33.0 / 260.0];
        let mut cost = vec![5, 5];
        let bumps = bound(&mut cost, &s, &weight);
        assert_eq!(cost, [10, 10]);
        assert_eq!(
            bumps,
            [
                Bump {
                    id: 0,
                    term: 0,
                    by: 5
                },
                Bump {
                    id: 1,
                    term: 1,
                    by: 5
                }
            ]
        );
        assert!(bound(&mut cost, &s, &weight).is_empty());
    }

    #[test]
    fn units_must_match_the_terms() {
        assert!(matches!(
            fit(&three(), 3),
            Err(FitError::Terms {
                id: 0,
                got: 2,
                want: 3
            })
        ));
    }
}
