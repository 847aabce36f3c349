//! Options of quasilinearization.

use std::sync::Arc;

/// A trajectory of all states as a function of time: `f(t, y)` writes y(t).
pub type StateFunction = Arc<dyn Fn(f64, &mut [f64]) + Send + Sync>;

/// The first trajectory x₀(t) the method linearises around.
#[derive(Clone, Default)]
pub enum Start {
    /// The model integrated from the starting guess (default).
    #[default]
    Guess,
    /// As `Guess`, but every measured state follows its data: linear interpolation of its
    /// samples, or the record itself. This uses what the data say about the trajectory, which
    /// is the freedom that distinguishes the method.
    Data,
    /// A trajectory of all states supplied by the caller: `f(t, y)` writes y(t).
    Trajectory(StateFunction),
}

impl std::fmt::Debug for Start {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Start::Guess => write!(f, "Guess"),
            Start::Data => write!(f, "Data"),
            Start::Trajectory(_) => write!(f, "Trajectory(..)"),
        }
    }
}

/// Options with documented defaults.
#[derive(Clone, Debug)]
pub struct QuasilinearizationOptions {
    /// Most updates of the unknowns (default 50).
    pub max_iterations: usize,
    /// Converged when the update satisfies ‖c_{k+1} − c_k‖ ≤ tol · (‖c_k‖ + tol), tol not
    /// below the integrator's rtol
    /// ([`Problem::resolvable_step`](sysid_core::Problem::resolvable_step); default 1e-10).
    pub step_tolerance: f64,
    /// The first trajectory (default: from the guess).
    pub start: Start,
    /// The least-squares problem counts as singular when the condition number of the
    /// Jacobi-scaled BᵀB exceeds this (default 1e12).
    pub max_condition: f64,
}

impl Default for QuasilinearizationOptions {
    fn default() -> Self {
        Self { max_iterations: 50, step_tolerance: 1e-10, start: Start::Guess, max_condition: 1e12 }
    }
}

impl QuasilinearizationOptions {
    /// The same options with another start.
    pub fn with_start(self, start: Start) -> Self {
        Self { start, ..self }
    }

    /// Checks the options; returns a description of the first problem.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.step_tolerance >= 0.0 && self.step_tolerance.is_finite()) {
            return Err(format!(
                "step_tolerance must be non-negative, got {}",
                self.step_tolerance
            ));
        }
        if self.max_condition.is_nan() || self.max_condition <= 1.0 {
            return Err(format!("max_condition must exceed 1, got {}", self.max_condition));
        }
        Ok(())
    }
}
