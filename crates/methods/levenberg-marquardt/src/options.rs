//! Options of Levenberg–Marquardt.

use serde::{Deserialize, Serialize};
use sysid_core::{DriverOptions, Hessian, OptionsError};

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
    /// The curvature of the step's model: JᵀWJ (Levenberg–Marquardt proper, the default), or
    /// Fletcher and Xu's switch between it and the full Hessian of ε (`hybrid-newton`).
    #[serde(default)]
    pub hessian: Hessian,
}

impl Default for LevenbergMarquardtOptions {
    fn default() -> Self {
        Self {
            driver: DriverOptions::default(),
            factor: 100.0,
            max_rejections: 30,
            hessian: Hessian::GaussNewton,
        }
    }
}

impl LevenbergMarquardtOptions {
    /// Checks the options.
    pub fn validate(&self) -> Result<(), OptionsError> {
        self.driver.validate()?;
        OptionsError::positive("factor", self.factor)
    }
}
