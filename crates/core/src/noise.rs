//! Noise models of measured series: the scale the residuals are formed on, the noise's
//! standard deviation σ, and the negative log-likelihood they define.
//!
//! A measurement m of a quantity the model predicts as y has, on the series' scale T (lin, ln
//! or log10), the residual R = (T(y) − T(m))/σ and contributes
//!
//!   ½ ln(2πσ²) + ½ R²  (+ ln m on the log scale, + ln(m ln 10) on log10)
//!
//! to the negative log-likelihood (PEtab's convention; the last terms make it a density of m
//! itself). σ is one of: known (a number or a data column, per sample), a plain unknown
//! scale s times known factors (σ_m = s·f_m, eliminated in closed form: see
//! [`drive`](crate::method::drive)), or a function of time, the states, the quantity's value, the
//! parameters and the unknowns. Series without a noise model keep their weights
//! w = 1/σ² as relative weights (Goodman's eq. 32): the least-squares cost ε is the same, and
//! the covariance is scaled by the residual variance as it always was.

use std::fmt;
use std::sync::Arc;

/// ln(2π).
pub const LN_2PI: f64 = 1.837_877_066_409_345_5;

/// The distribution of a measurement's noise about the model's value, on the series' scale.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum NoiseDistribution {
    /// Normal with standard deviation σ: ½ ln(2πσ²) + ½ R², R = (T(y) − T(m))/σ.
    #[default]
    Normal,
    /// Laplace with scale b (σ is b): ln(2b) + |T(y) − T(m)|/b, written as ½ R² with
    /// R = sign(d)·√(2|d|/b), d = T(y) − T(m). Its Fisher information about T(y) is 1/b², as
    /// a normal one's is 1/σ², and about ln b it is 1 (a normal one's about ln σ is 2).
    Laplace,
}

impl NoiseDistribution {
    /// Its name in model files and PEtab tables: "normal" or "laplace".
    pub fn name(self) -> &'static str {
        match self {
            NoiseDistribution::Normal => "normal",
            NoiseDistribution::Laplace => "laplace",
        }
    }

    /// The part of one sample's negative log-likelihood besides ½ R² and ln σ: ½ ln 2π
    /// (normal), ln 2 (Laplace).
    pub fn constant(self) -> f64 {
        match self {
            NoiseDistribution::Normal => 0.5 * LN_2PI,
            NoiseDistribution::Laplace => std::f64::consts::LN_2,
        }
    }

    /// The residual R of a difference d = T(y) − T(m) at √w = 1/σ, and ∂R/∂d.
    ///
    /// Laplace: R = sign(d)·√(2|d|w) and ∂R/∂d = w/√(2|d|w), which grows without bound as d
    /// goes to 0 (R·∂R/∂d, what the gradient sums, stays w·sign(d)); at d = 0 exactly both
    /// are taken as 0, a subgradient.
    pub fn residual(self, d: f64, sqrt_weight: f64) -> (f64, f64) {
        match self {
            NoiseDistribution::Normal => (sqrt_weight * d, sqrt_weight),
            NoiseDistribution::Laplace => {
                let root = (2.0 * d.abs() * sqrt_weight).sqrt();
                let slope = if root > 0.0 { sqrt_weight / root } else { 0.0 };
                (d.signum() * root, slope)
            }
        }
    }
}

/// The scale residuals are formed on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Transform {
    /// The values themselves.
    #[default]
    Lin,
    /// Natural logarithms.
    Log,
    /// Base-10 logarithms.
    Log10,
}

impl Transform {
    /// T(x); NaN for x ≤ 0 on a log scale.
    pub fn apply(self, x: f64) -> f64 {
        match self {
            Transform::Lin => x,
            Transform::Log if x > 0.0 => x.ln(),
            Transform::Log10 if x > 0.0 => x.log10(),
            _ => f64::NAN,
        }
    }

    /// T⁻¹(y): y, e^y or 10^y.
    pub fn invert(self, y: f64) -> f64 {
        match self {
            Transform::Lin => y,
            Transform::Log => y.exp(),
            Transform::Log10 => 10f64.powf(y),
        }
    }

    /// dT/dx.
    pub fn derivative(self, x: f64) -> f64 {
        match self {
            Transform::Lin => 1.0,
            Transform::Log => 1.0 / x,
            Transform::Log10 => 1.0 / (x * std::f64::consts::LN_10),
        }
    }

    /// The term of a measurement m on this scale that makes the likelihood a density of m
    /// itself: 0, ln m, or ln(m ln 10).
    pub fn jacobian_term(self, m: f64) -> f64 {
        match self {
            Transform::Lin => 0.0,
            Transform::Log => m.ln(),
            Transform::Log10 => (m * std::f64::consts::LN_10).ln(),
        }
    }

    /// Its name as model files and PEtab spell it: "lin", "log", "log10".
    pub fn name(self) -> &'static str {
        match self {
            Transform::Lin => "lin",
            Transform::Log => "log",
            Transform::Log10 => "log10",
        }
    }
}

/// What a noise function is evaluated at.
#[derive(Clone, Copy, Debug)]
pub struct NoiseArgs<'a> {
    /// Time.
    pub t: f64,
    /// The states.
    pub y: &'a [f64],
    /// The measured quantity's value (untransformed).
    pub h: f64,
    /// The experiment's parameters.
    pub p: &'a [f64],
    /// The values of every unknown of the problem, in their declared order.
    pub v: &'a [f64],
}

/// The gradient of σ with respect to the arguments (slices of the arguments' lengths, zeroed
/// by the caller).
#[derive(Debug)]
pub struct NoiseGradient<'a> {
    /// ∂σ/∂y.
    pub y: &'a mut [f64],
    /// ∂σ/∂h.
    pub h: f64,
    /// ∂σ/∂p.
    pub p: &'a mut [f64],
    /// ∂σ/∂v.
    pub v: &'a mut [f64],
}

/// σ as a function of time, the states, the measured quantity's value, the parameters and
/// the unknowns (a model file's `sigma = "0.1 + 0.05 * Bm"`).
pub trait NoiseFunction: Send + Sync {
    /// σ at `args`, with its gradient written into `gradient`.
    fn eval(&self, args: NoiseArgs<'_>, gradient: &mut NoiseGradient<'_>) -> f64;
    /// The unknowns (declared indices) it depends on directly (not through the model).
    fn uses(&self) -> &[usize];
    /// The function as written, for messages.
    fn describe(&self) -> String;
}

/// The noise model of a measured series.
#[derive(Clone)]
pub enum Noise {
    /// σ of each sample, known (a number, or a column of the data file).
    Known(Vec<f64>),
    /// σ_m = s·f_m: the unknown called `unknown`, used as nothing but this scale, times
    /// known factors f_m (1 for `sigma = "s"`). Eliminated in closed form.
    Scale {
        /// The unknown s.
        unknown: String,
        /// The factors f_m, one per sample.
        factors: Vec<f64>,
    },
    /// σ a function of the model and the unknowns.
    Function(Arc<dyn NoiseFunction>),
}

impl fmt::Debug for Noise {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Noise::Known(s) => write!(f, "Known({} values)", s.len()),
            Noise::Scale { unknown, .. } => write!(f, "Scale({unknown})"),
            Noise::Function(n) => write!(f, "Function({})", n.describe()),
        }
    }
}

/// The constant c of the noise rows √(2 ln σ + c) that keep ε a sum of squares when σ is a
/// function of the unknowns (as Data2Dynamics does): 2 ln σ + c > 0 for every σ above
/// e^{−25} ≈ 1.4e-11. The certificate and the reported likelihood do not depend on it.
pub const NOISE_ROW_SHIFT: f64 = 50.0;

/// The least σ a noise expression may take, e^{−c/2} with c = [`NOISE_ROW_SHIFT`], and why,
/// as the errors that refuse a smaller one say it: "e^-25 ≈ 1.4e-11, the least σ …".
pub fn least_sigma() -> (f64, String) {
    let floor = (-NOISE_ROW_SHIFT / 2.0).exp();
    let why = format!(
        "e^{} ≈ {floor:.1e}, the least σ a noise expression may take (the likelihood's row for ln σ is √(2 ln σ + {NOISE_ROW_SHIFT}))",
        -NOISE_ROW_SHIFT / 2.0
    );
    (floor, why)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transforms_and_their_terms() {
        assert!((Transform::Log10.apply(1000.0) - 3.0).abs() < 1e-15);
        assert!(Transform::Log.apply(-1.0).is_nan());
        let x = 2.5;
        let h = 1e-6;
        for t in [Transform::Lin, Transform::Log, Transform::Log10] {
            let fd = (t.apply(x + h) - t.apply(x - h)) / (2.0 * h);
            assert!((fd - t.derivative(x)).abs() < 1e-9, "{t:?}");
        }
        assert!((LN_2PI - (2.0 * std::f64::consts::PI).ln()).abs() < 1e-15);
        assert!(
            (Transform::Log10.jacobian_term(10.0) - std::f64::consts::LN_10.ln() - 10f64.ln())
                .abs()
                < 1e-14
        );
    }
}
