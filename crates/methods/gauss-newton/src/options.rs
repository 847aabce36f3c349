//! Options of the Gauss–Newton baseline.

use serde::{Deserialize, Serialize};
use sysid_core::{Driven, DriverOptions, OptionsError};

/// Where the Jacobian of the residuals comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum JacobianSource {
    /// The shared forward sensitivities: residuals and Jacobian from one integration.
    #[default]
    Sensitivities,
    /// Forward differences of the residuals, one extra integration per unknown: what a user
    /// without sensitivity equations gets. The difference is taken in the coordinate the
    /// unknown is estimated in (ln for a log scale) with the relative step
    /// h_j = √ε_mach · max(|z_j|, typical_j), typical_j = |z_j| at the start (1 where 0),
    /// backwards where the forward step would leave the bounds. The integration's error is a
    /// smooth function of z between changes of the step sequence, so this small step gives
    /// the Jacobian to about √ε_mach where h = √rtol gave it to about √rtol (and left the
    /// exact gradient's cosine at 1e-5 at the fits' ends).
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
    /// The same options with argmin's stopping tolerance.
    pub fn with_tolerance(self, tolerance: f64) -> Self {
        Self { tolerance, ..self }
    }

    /// The same options with the line search on or off.
    pub fn with_line_search(self, line_search: bool) -> Self {
        Self { line_search, ..self }
    }

    /// The same options with the line search's Armijo constant.
    pub fn with_armijo(self, armijo: f64) -> Self {
        Self { armijo, ..self }
    }

    /// The same options with another Jacobian.
    pub fn with_jacobian(self, jacobian: JacobianSource) -> Self {
        Self { jacobian, ..self }
    }

    /// Checks the method's own options (the driver's are checked by
    /// [`drive`](sysid_core::method::drive), once).
    pub fn validate(&self) -> Result<(), OptionsError> {
        OptionsError::positive("tolerance", self.tolerance)?;
        OptionsError::within("armijo", self.armijo, 0.0, 1.0)
    }
}

impl Driven for GaussNewtonOptions {
    fn driver_mut(&mut self) -> &mut DriverOptions {
        &mut self.driver
    }
}
