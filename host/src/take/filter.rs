//! The smoothing filter of `take edit --smooth`: a critically damped
//! second-order low-pass, solved exactly between samples.
//!
//! The output `x` follows the input `u` as a critically damped spring of
//! natural frequency `ω = 2π · hz`:
//!
//! ```text
//! x'' = ω² (u − x) − 2 ω x'
//! ```
//!
//! Each sample `u_k` is held over the interval that ends at its time
//! (`t_{k−1}, t_k]`), over which the equation has the exact solution, with
//! `e = x − u_k`:
//!
//! ```text
//! e(τ) = (e₀ + (v₀ + ω e₀) τ) e^{−ωτ},   v(τ) = (v₀ − ω (v₀ + ω e₀) τ) e^{−ωτ}
//! ```
//!
//! so the filter is exact at any sample spacing (no step-size error, no
//! overshoot: a step in `u` is followed by `1 − (1 + ωt) e^{−ωt}` of it).
//! The first sample starts the output at rest on the input.

/// A critically damped low-pass (see the module doc) for one value.
#[derive(Clone, Copy, Debug)]
pub struct CriticallyDamped {
    omega: f64,
    state: Option<(f64, f64, f64)>,
}

impl CriticallyDamped {
    /// A filter with natural frequency `hz` (Hz; its −6 dB point is about
    /// `0.64 · hz`).
    #[must_use]
    pub fn new(hz: f64) -> Self {
        Self {
            omega: 2.0 * std::f64::consts::PI * hz,
            state: None,
        }
    }

    /// Filters the sample `u` at time `t` (seconds, increasing); returns
    /// the output at `t`.
    pub fn step(&mut self, t: f64, u: f64) -> f64 {
        let Some((t0, x0, v0)) = self.state else {
            self.state = Some((t, u, 0.0));
            return u;
        };
        let tau = (t - t0).max(0.0);
        let e0 = x0 - u;
        let a = v0 + self.omega * e0;
        let decay = (-self.omega * tau).exp();
        let e = (e0 + a * tau) * decay;
        let v = (v0 - self.omega * a * tau) * decay;
        self.state = Some((t, u + e, v));
        u + e
    }
}

/// Filters a series of `(t, u)` samples.
#[must_use]
pub fn smooth(hz: f64, samples: &[(f64, f64)]) -> Vec<f64> {
    let mut f = CriticallyDamped::new(hz);
    samples.iter().map(|&(t, u)| f.step(t, u)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_step_is_followed_as_the_closed_form_says() {
        // 0 until sample 10, then 1, at 1 kHz: the step starts at sample
        // 9's time (the sample is held over the interval ending at it).
        let hz = 3.0;
        let omega = 2.0 * std::f64::consts::PI * hz;
        let samples: Vec<(f64, f64)> = (0..2000)
            .map(|k| (f64::from(k) * 1e-3, if k >= 10 { 1.0 } else { 0.0 }))
            .collect();
        let out = smooth(hz, &samples);
        for (k, x) in out.iter().enumerate() {
            let expected = if k >= 10 {
                let t = (k as f64 - 9.0) * 1e-3;
                1.0 - (1.0 + omega * t) * (-omega * t).exp()
            } else {
                0.0
            };
            assert!(
                (x - expected).abs() < 1e-12,
                "sample {k}: {x} vs {expected}"
            );
        }
    }

    #[test]
    fn a_constant_stays_and_uneven_spacing_changes_nothing() {
        let out = smooth(5.0, &[(0.0, 2.5), (0.001, 2.5), (0.5, 2.5), (0.503, 2.5)]);
        assert_eq!(out, vec![2.5; 4]);
        // Two half steps of a held input are one whole step.
        let mut a = CriticallyDamped::new(2.0);
        let mut b = CriticallyDamped::new(2.0);
        a.step(0.0, 0.0);
        b.step(0.0, 0.0);
        let whole = a.step(0.2, 1.0);
        b.step(0.1, 1.0);
        let halves = b.step(0.2, 1.0);
        assert!((whole - halves).abs() < 1e-12, "{whole} vs {halves}");
    }
}
