//! Options of Goodman's method.

use serde::{Deserialize, Serialize};

/// Options with documented defaults. The defaults run the paper's method as published: a
/// full Newton step every iteration, no safeguard.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GoodmanOptions {
    /// Most updates of the unknowns (default 50).
    pub max_iterations: usize,
    /// Converged when the Newton step satisfies ‖δz‖ ≤ tol · (‖z‖ + tol), tol not below the
    /// integrator's rtol ([`Problem::resolvable_step`](sysid_core::Problem::resolvable_step);
    /// default 1e-10).
    pub step_tolerance: f64,
    /// Converged when every U_i is small against the residual and the sensitivity it pairs,
    /// max_i |U_i| / √(A_ii ε) ≤ tol: the cosine between the residual and each sensitivity
    /// (MINPACK's gtol; scale-free; default 1e-10).
    pub gradient_tolerance: f64,
    /// Converged when the decrease of ε the next Newton step predicts, δᵀAδ, is at most
    /// this fraction of ε (MINPACK's ftol; default 0: off, the step and gradient tests
    /// decide). ε is then within that fraction of the minimum's: what a fit needs whose
    /// only purpose is the minimum's cost.
    pub cost_tolerance: f64,
    /// Halve the step while the cost rises (default off: the paper's method takes the full
    /// step; the comparison reports show both).
    pub step_halving: bool,
    /// Most halvings of one step (default 30).
    pub max_halvings: usize,
    /// The normal matrix counts as singular when the condition number of its Jacobi-scaled
    /// form exceeds this (default 1e12).
    pub max_condition: f64,
}

impl Default for GoodmanOptions {
    fn default() -> Self {
        Self {
            max_iterations: 50,
            step_tolerance: 1e-10,
            gradient_tolerance: 1e-10,
            cost_tolerance: 0.0,
            step_halving: false,
            max_halvings: 30,
            max_condition: 1e12,
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

    /// The same options with another iteration budget.
    pub fn with_max_iterations(self, max_iterations: usize) -> Self {
        Self { max_iterations, ..self }
    }

    /// Checks the options; returns a description of the first problem.
    pub fn validate(&self) -> Result<(), String> {
        for (name, v) in [
            ("step_tolerance", self.step_tolerance),
            ("gradient_tolerance", self.gradient_tolerance),
            ("cost_tolerance", self.cost_tolerance),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(format!("{name} must be a non-negative number, got {v}"));
            }
        }
        if self.max_condition.is_nan() || self.max_condition <= 1.0 {
            return Err(format!("max_condition must exceed 1, got {}", self.max_condition));
        }
        Ok(())
    }
}
