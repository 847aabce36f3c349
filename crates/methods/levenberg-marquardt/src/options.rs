//! Options of Levenberg–Marquardt.

use serde::{Deserialize, Serialize};
use sysid_core::{DriverOptions, OptionsError};

/// Options with MINPACK's defaults.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LevenbergMarquardtOptions {
    /// The iteration's budgets and tolerances, shared by every method ([`DriverOptions`]).
    pub driver: DriverOptions,
    /// The first trust-region radius is this multiple of ‖D z₀‖ (or this, when it is 0):
    /// MINPACK's `factor`, default 100.
    pub factor: f64,
    /// Most trial steps rejected in a row before the iteration stops with no descent
    /// (default 30; each halves the radius at least).
    pub max_rejections: usize,
}

impl Default for LevenbergMarquardtOptions {
    fn default() -> Self {
        Self { driver: DriverOptions::default(), factor: 100.0, max_rejections: 30 }
    }
}

impl LevenbergMarquardtOptions {
    /// Checks the options.
    pub fn validate(&self) -> Result<(), OptionsError> {
        self.driver.validate()?;
        OptionsError::positive("factor", self.factor)
    }
}
