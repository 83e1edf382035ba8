//! Robust kernels.
//!
//! Convention (Ceres'): a kernel maps the squared whitened residual `s = ‖W r‖²` to `ρ(s)`, and the
//! cost is `½ Σ ρ(s_i)`. Plain least squares is `ρ(s) = s`. Parameters are in whitened units ("number
//! of sigmas"). [`RobustKernel::evaluate`] returns `[ρ(s), ρ'(s), ρ''(s)]`; the solver scales each
//! whitened residual and Jacobian by `sqrt(ρ'(s))` (iteratively reweighted least squares).
//!
//! | kernel | ρ(s) | ρ'(s) |
//! |---|---|---|
//! | L2 | `s` | 1 |
//! | Huber(δ) | `s` if `s ≤ δ²`, else `2δ√s − δ²` | 1, else `δ/√s` |
//! | Cauchy(c) | `c² ln(1 + s/c²)` | `1 / (1 + s/c²)` |
//! | Tukey(c) | `c²/3 (1 − (1 − s/c²)³)` if `s ≤ c²`, else `c²/3` | `(1 − s/c²)²`, else 0 |

/// A robust kernel `ρ(s)` of the squared whitened residual.
pub trait RobustKernel: Send + Sync + std::fmt::Debug {
    /// `[ρ(s), ρ'(s), ρ''(s)]` for `s ≥ 0`.
    fn evaluate(&self, s: f64) -> [f64; 3];
}

/// Plain least squares, `ρ(s) = s`.
#[derive(Debug, Clone, Copy, Default)]
pub struct L2;

impl RobustKernel for L2 {
    fn evaluate(&self, s: f64) -> [f64; 3] {
        [s, 1.0, 0.0]
    }
}

/// Huber kernel with threshold `δ` (whitened units).
#[derive(Debug, Clone, Copy)]
pub struct Huber(pub f64);

impl RobustKernel for Huber {
    fn evaluate(&self, s: f64) -> [f64; 3] {
        let d = self.0;
        if s <= d * d {
            [s, 1.0, 0.0]
        } else {
            let r = s.sqrt();
            [2.0 * d * r - d * d, d / r, -0.5 * d / (s * r)]
        }
    }
}

/// Cauchy kernel with scale `c`.
#[derive(Debug, Clone, Copy)]
pub struct Cauchy(pub f64);

impl RobustKernel for Cauchy {
    fn evaluate(&self, s: f64) -> [f64; 3] {
        let c2 = self.0 * self.0;
        let a = 1.0 + s / c2;
        [c2 * a.ln(), 1.0 / a, -1.0 / (c2 * a * a)]
    }
}

/// Tukey's biweight with scale `c`.
#[derive(Debug, Clone, Copy)]
pub struct Tukey(pub f64);

impl RobustKernel for Tukey {
    fn evaluate(&self, s: f64) -> [f64; 3] {
        let c2 = self.0 * self.0;
        if s <= c2 {
            let a = 1.0 - s / c2;
            [c2 / 3.0 * (1.0 - a * a * a), a * a, -2.0 * a / c2]
        } else {
            [c2 / 3.0, 0.0, 0.0]
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(k: &dyn RobustKernel) {
        let h = 1e-6;
        for &s in &[0.0, 0.3, 0.99, 1.5, 4.0, 8.9, 9.5, 30.0] {
            let [rho, d1, d2] = k.evaluate(s);
            assert!(rho >= 0.0 && (0.0..=1.0 + 1e-12).contains(&d1), "{k:?} s={s}");
            if s > h {
                let [p, dp, _] = k.evaluate(s + h);
                let [m, dm, _] = k.evaluate(s - h);
                assert!(((p - m) / (2.0 * h) - d1).abs() < 1e-5, "{k:?} ρ' at {s}");
                assert!(((dp - dm) / (2.0 * h) - d2).abs() < 1e-5, "{k:?} ρ'' at {s}");
            }
        }
        // ρ(s) ≈ s near zero: all kernels agree with least squares for small residuals
        let [rho, d1, _] = k.evaluate(1e-8);
        assert!((rho - 1e-8).abs() < 1e-12 && (d1 - 1.0).abs() < 1e-6);
    }

    #[test]
    fn kernels_consistent() {
        check(&L2);
        check(&Huber(1.0));
        check(&Huber(2.5));
        check(&Cauchy(1.0));
        check(&Tukey(3.0));
        // Huber cost of a residual of norm 3 with δ = 1: ½ρ = δ|r| − ½δ² = 2.5
        assert!((0.5 * Huber(1.0).evaluate(9.0)[0] - 2.5).abs() < 1e-12);
    }
}
