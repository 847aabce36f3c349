//! Options of Goodman's method.

use serde::{Deserialize, Serialize};
use sysid_core::{Driven, DriverOptions, OptionsError};

/// Options with documented defaults. The defaults run the paper's method as published: a
/// full Newton step every iteration, no safeguard.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GoodmanOptions {
    /// The iteration's budgets, step and gradient tolerances and the certificate's
    /// tolerance, shared by every method ([`DriverOptions`]: 3000 iterations, step and gradient
    /// tolerances 1e-10, singular above condition 1e12).
    pub driver: DriverOptions,
    /// Stop when the decrease of ε the next Newton step predicts, δᵀAδ, is at most this
    /// fraction of ε (MINPACK's ftol; default 0: off, the step and gradient tests decide).
    /// ε is then within that fraction of the minimum's: what a fit needs whose only purpose
    /// is the minimum's cost.
    pub cost_tolerance: f64,
    /// Halve the step while the cost rises (default off: the paper's method takes the full
    /// step; the comparison reports show both).
    pub step_halving: bool,
    /// Most halvings of one step (default 30).
    pub max_halvings: usize,
}

impl Default for GoodmanOptions {
    fn default() -> Self {
        Self {
            driver: DriverOptions::default(),
            cost_tolerance: 0.0,
            step_halving: false,
            max_halvings: 30,
        }
    }
}

impl GoodmanOptions {
    /// The same options with step halving on or off.
    pub fn with_step_halving(self, on: bool) -> Self {
        Self { step_halving: on, ..self }
    }

    /// The same options with a cost tolerance (see [`cost_tolerance`](Self::cost_tolerance)).
    pub fn with_cost_tolerance(self, cost_tolerance: f64) -> Self {
        Self { cost_tolerance, ..self }
    }

    /// The same options with at most `max_halvings` halvings of one step.
    pub fn with_max_halvings(self, max_halvings: usize) -> Self {
        Self { max_halvings, ..self }
    }

    /// Checks the method's own options (the driver's are checked by
    /// [`drive`](sysid_core::method::drive), once).
    pub fn validate(&self) -> Result<(), OptionsError> {
        OptionsError::non_negative("cost_tolerance", self.cost_tolerance)
    }
}

impl Driven for GoodmanOptions {
    fn driver_mut(&mut self) -> &mut DriverOptions {
        &mut self.driver
    }
}
