//! Options of the Gauss–Newton baseline.

use serde::{Deserialize, Serialize};
use sysid_core::{DriverOptions, OptionsError};

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
    /// The iteration's budgets, step tolerance and the certificate's tolerance, shared by
    /// every method ([`DriverOptions`]; a failed solve counts as singular above its
    /// `max_condition`, where argmin itself only fails on an exactly singular JᵀJ).
    pub driver: DriverOptions,
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
}

impl Default for GaussNewtonOptions {
    fn default() -> Self {
        Self {
            driver: DriverOptions::default(),
            tolerance: 1e-12,
            line_search: false,
            armijo: 1e-4,
            jacobian: JacobianSource::Sensitivities,
        }
    }
}

impl GaussNewtonOptions {
    /// The same options with another iteration budget.
    pub fn with_max_iterations(mut self, max_iterations: usize) -> Self {
        self.driver.max_iterations = max_iterations;
        self
    }

    /// Checks the options.
    pub fn validate(&self) -> Result<(), OptionsError> {
        self.driver.validate()?;
        OptionsError::positive("tolerance", self.tolerance)?;
        OptionsError::within("armijo", self.armijo, 0.0, 1.0)
    }
}
