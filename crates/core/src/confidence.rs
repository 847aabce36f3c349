//! Confidence statements: the 95 % quantile of Student's t for the residual degrees of
//! freedom N − k, and the intervals it gives.
//!
//! The standard errors come from s² = ε/(N − k), an estimate of the noise variance with
//! N − k degrees of freedom; the interval estimate ± t_{0.975, N−k}·se then has 95 %
//! coverage for a model linear in its unknowns with Gaussian noise, where ±1.96·se has
//! less (70 % at one degree of freedom). The quantile comes from cdflib, a port of CDFLIB.

use cdflib::traits::ContinuousCdf;
use nalgebra::{DMatrix, DVector};

/// The two-sided 95 % quantile of the standard normal distribution (t with infinitely many
/// degrees of freedom).
pub const Z95: f64 = 1.959_963_984_540_054;

/// t_{0.975, dof}: the half-width of a 95 % interval in standard errors, for `dof` ≥ 1
/// degrees of freedom (`None` for 0).
pub fn t95(dof: usize) -> Option<f64> {
    if dof == 0 {
        return None;
    }
    cdflib::StudentsT::new(dof as f64).inverse_cdf(0.975).ok()
}

/// The half-width of the 95 % band of a predicted quantity q with gradient g = ∂q/∂(values)
/// at the estimate, whose covariance is `covariance`: t·√(gᵀ Cov g) (the delta method), with
/// `quantile` the t quantile of the fit's degrees of freedom ([`t95`]). Every band sysid
/// draws or writes (measured quantities, predicted states) is this one.
pub fn band_half_width(quantile: f64, gradient: &DVector<f64>, covariance: &DMatrix<f64>) -> f64 {
    quantile * gradient.dot(&(covariance * gradient)).max(0.0).sqrt()
}

/// The 95 % interval of a value with standard error `se` and `dof` degrees of freedom. On a
/// log scale (`log`) the interval is formed for ln(value), whose standard error is
/// se/value (the delta method), and mapped back: positive and asymmetric.
pub fn interval(value: f64, se: f64, dof: usize, log: bool) -> Option<[f64; 2]> {
    let t = t95(dof)?;
    if !(se.is_finite() && value.is_finite()) {
        return None;
    }
    Some(if log && value > 0.0 {
        let half = t * se / value;
        [value * (-half).exp(), value * half.exp()]
    } else {
        [value - t * se, value + t * se]
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Closed forms: t_ν(p) for ν = 1 is tan(π(p − ½)), for ν = 2 it is
    /// (2p − 1)/√(2p(1 − p)); for ν = 4, with α = 4p(1 − p), it is
    /// 2 √(cos(arccos(√α)/3)/√α − 1). For large ν the Cornish–Fisher expansion
    /// z + (z³ + z)/(4ν) + (5z⁵ + 16z³ + 3z)/(96ν²) + (3z⁷ + 19z⁵ + 17z³ − 15z)/(384ν³) is
    /// exact to O(ν⁻⁴). cdflib's quantile
    /// is accurate to about 4e-11 relative at small ν (its root finder's tolerance) and to
    /// rounding at large ν.
    #[test]
    fn t95_matches_closed_forms() {
        let p: f64 = 0.975;
        let cases = [
            (1, (std::f64::consts::PI * (p - 0.5)).tan(), 1e-10),
            (2, (2.0 * p - 1.0) / (2.0 * p * (1.0 - p)).sqrt(), 1e-10),
            (
                4,
                {
                    let alpha = 4.0 * p * (1.0 - p);
                    2.0 * (((alpha.sqrt()).acos() / 3.0).cos() / alpha.sqrt() - 1.0).sqrt()
                },
                1e-10,
            ),
        ];
        for (dof, expected, tol) in cases {
            let t = t95(dof).unwrap();
            assert!(((t - expected) / expected).abs() < tol, "ν = {dof}: {t} vs {expected}");
        }
        for dof in [10_000usize, 100_000, 1_000_000] {
            let (z, nu) = (Z95, dof as f64);
            let cf = z
                + (z.powi(3) + z) / (4.0 * nu)
                + (5.0 * z.powi(5) + 16.0 * z.powi(3) + 3.0 * z) / (96.0 * nu * nu)
                + (3.0 * z.powi(7) + 19.0 * z.powi(5) + 17.0 * z.powi(3) - 15.0 * z)
                    / (384.0 * nu.powi(3));
            let t = t95(dof).unwrap();
            assert!(((t - cf) / cf).abs() < 1e-12, "ν = {dof}: {t} vs {cf}");
        }
        assert!(t95(0).is_none());
    }

    #[test]
    fn intervals_are_symmetric_on_values_and_positive_on_a_log_scale() {
        let [lo, hi] = interval(10.0, 1.0, 1, false).unwrap();
        assert!((hi - lo - 2.0 * t95(1).unwrap()).abs() < 1e-12);
        let [lo, hi] = interval(1.0, 0.5, 1, true).unwrap();
        assert!(lo > 0.0 && (lo * hi - 1.0).abs() < 1e-12, "{lo} {hi}");
        assert!(interval(1.0, 0.5, 0, false).is_none());
    }
}
