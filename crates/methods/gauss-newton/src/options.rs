//! Options of the Gauss–Newton baseline.

use serde::{Deserialize, Serialize};

/// Where the Jacobian of the residuals comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum JacobianSource {
    /// The shared forward sensitivities: residuals and Jacobian from one integration.
    #[default]
    Sensitivities,
    /// Forward differences of the residuals, one extra integration per unknown: what a user
    /// without sensitivity equations gets. The step for unknown j is
    /// h_j = √η · max(|z_j|, 1) with η = max(rtol, machine ε), the noise level of a residual
    /// computed by an integrator with relative tolerance rtol.
    FiniteDifferences,
}

/// Options with documented defaults.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GaussNewtonOptions {
    /// Most iterations (default 50).
    pub max_iterations: u64,
    /// argmin's stopping rule: |‖r_prev‖ − ‖r‖| below `tolerance · max(‖r(start)‖, 1)`
    /// (argmin's test is absolute; it is made relative to the starting residual here;
    /// default 1e-12).
    pub tolerance: f64,
    /// Backtracking line search with the Armijo condition (argmin's `GaussNewtonLS`);
    /// default off (argmin's `GaussNewton`, full steps).
    pub line_search: bool,
    /// Armijo constant c of the line search (default 1e-4).
    pub armijo: f64,
    /// The Jacobian (default: sensitivities).
    pub jacobian: JacobianSource,
    /// Condition number of the scaled normal matrix above which a failed solve is reported as
    /// singular (default 1e12; argmin itself only fails on an exactly singular JᵀJ).
    pub max_condition: f64,
}

impl Default for GaussNewtonOptions {
    fn default() -> Self {
        Self {
            max_iterations: 50,
            tolerance: 1e-12,
            line_search: false,
            armijo: 1e-4,
            jacobian: JacobianSource::Sensitivities,
            max_condition: 1e12,
        }
    }
}

impl GaussNewtonOptions {
    /// Checks the options; returns a description of the first problem.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.tolerance > 0.0 && self.tolerance.is_finite()) {
            return Err(format!("tolerance must be positive, got {}", self.tolerance));
        }
        if !(self.armijo > 0.0 && self.armijo < 1.0) {
            return Err(format!("the Armijo constant must lie in (0, 1), got {}", self.armijo));
        }
        Ok(())
    }
}
