//! Options of quasilinearization.

use std::sync::Arc;

use sysid_core::{Driven, DriverOptions, OptionsError};

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
#[derive(Clone, Debug, Default)]
pub struct QuasilinearizationOptions {
    /// The iteration's budgets, step tolerance (on ‖c_{k+1} − c_k‖) and the certificate's
    /// tolerance, shared by every method ([`DriverOptions`]; the least-squares problem of
    /// the linear family counts as singular above its `max_condition`).
    pub driver: DriverOptions,
    /// The first trajectory (default: from the guess).
    pub start: Start,
}

impl QuasilinearizationOptions {
    /// The same options with another start.
    pub fn with_start(self, start: Start) -> Self {
        Self { start, ..self }
    }

    /// Checks the method's own options (the driver's are checked by
    /// [`drive`](sysid_core::method::drive), once).
    pub fn validate(&self) -> Result<(), OptionsError> {
        Ok(())
    }
}

impl Driven for QuasilinearizationOptions {
    fn driver_mut(&mut self) -> &mut DriverOptions {
        &mut self.driver
    }
}
