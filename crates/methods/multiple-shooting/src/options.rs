//! Options of multiple shooting.

use serde::{Deserialize, Serialize};
use sysid_core::{Driven, DriverOptions, OptionsError};

/// Options of [`MultipleShooting`](crate::MultipleShooting).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MultipleShootingOptions {
    /// The iteration's budgets and tolerances, shared by every method ([`DriverOptions`]).
    pub driver: DriverOptions,
    /// Number of shooting intervals M. `None`: chosen from the data, one interval per 5
    /// sample times, at most [`DEFAULT_MAX_INTERVALS`](crate::DEFAULT_MAX_INTERVALS) (and at
    /// most the number of sample times after t0).
    pub intervals: Option<usize>,
}

impl MultipleShootingOptions {
    /// The same options with `intervals` shooting intervals.
    pub fn with_intervals(self, intervals: usize) -> Self {
        Self { intervals: Some(intervals), ..self }
    }

    /// Checks the method's own options (the driver's are checked by
    /// [`drive`](sysid_core::method::drive), once).
    pub fn validate(&self) -> Result<(), OptionsError> {
        if self.intervals == Some(0) {
            return Err(OptionsError::Zero { name: "intervals" });
        }
        Ok(())
    }
}

impl Driven for MultipleShootingOptions {
    fn driver_mut(&mut self) -> &mut DriverOptions {
        &mut self.driver
    }
}
